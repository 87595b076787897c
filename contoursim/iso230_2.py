"""ISO 230-2 bidirectional positioning tests: the figures, and an error table for the chain.

A linear axis is driven to m target positions P_i, n cycles, each target
approached from both directions, while a reference (laser interferometer,
triangulation sensor) measures where the axis really is.
:func:`positioning_figures` evaluates such a :class:`PositioningTest`;
:func:`write_error_table` writes its mean bidirectional positional deviation
as the error table :func:`contoursim.errormotion.read_error_table` reads, so
a machine chain can carry the measured positioning error.

ISO 230-2 (2014) definitions used; i = target, j = cycle (n cycles),
↑ = target approached in the positive direction, ↓ = in the negative one:

- positional deviation ``x_ij = P_ij − P_i``: measured (reference) position
  minus target, so a positive deviation means the axis went too far in +;
- mean unidirectional positional deviation ``x̄_i↑ = (1/n) Σ_j x_ij↑``
  (and ``x̄_i↓``);
- mean bidirectional positional deviation ``x̄_i = (x̄_i↑ + x̄_i↓) / 2``;
- reversal value ``B_i = x̄_i↑ − x̄_i↓``; of the axis ``B = max |B_i|``;
  mean reversal value ``B̄ = (1/m) Σ_i B_i`` (signed);
- standard uncertainty ``s_i↑ = sqrt(Σ_j (x_ij↑ − x̄_i↑)² / (n − 1))``;
  unidirectional repeatability ``R_i↑ = 4 s_i↑``, ``R↑ = max R_i↑``;
  bidirectional repeatability ``R_i = max(2 s_i↑ + 2 s_i↓ + |B_i|, R_i↑, R_i↓)``,
  ``R = max R_i``;
- bidirectional systematic positional deviation
  ``E = max(x̄_i↑, x̄_i↓) − min(x̄_i↑, x̄_i↓)``;
- range of the mean bidirectional positional deviation
  ``M = max x̄_i − min x̄_i``;
- bidirectional accuracy
  ``A = max(x̄_i↑ + 2 s_i↑, x̄_i↓ + 2 s_i↓) − min(x̄_i↑ − 2 s_i↑, x̄_i↓ − 2 s_i↓)``.

Everything is in mm; the error table's deviation column is in µm, as the
table format asks.
"""

from dataclasses import dataclass

import numpy as np

from . import _validate
from .output import writing
from .traces import MAX_POSITION

__all__ = ["PositioningFigures", "PositioningTest", "positioning_figures", "write_error_table"]

_UM_PER_MM = 1e3  # [µm/mm]


@dataclass(frozen=True)
class PositioningTest:
    """The measurements of one ISO 230-2 bidirectional positioning test.

    Parameters
    ----------
    targets : ndarray, shape (m,)
        Target positions P_i, at least 2, strictly increasing [mm].
    up : ndarray, shape (m, n)
        Measured positions P_ij↑ reached approaching target i in the positive
        direction, cycle j in column j, n >= 2 [mm].
    down : ndarray, shape (m, n)
        Measured positions P_ij↓ reached approaching in the negative
        direction [mm].

    Examples
    --------
    >>> test = PositioningTest([0.0, 10.0], [[0.003, 0.005], [10.0, 10.002]],
    ...                        [[-0.001, 0.001], [9.998, 9.998]])
    >>> round(positioning_figures(test).reversal_max * 1e3, 9)  # B [µm]
    4.0
    """

    targets: np.ndarray
    up: np.ndarray
    down: np.ndarray

    def __post_init__(self):
        # a position of 1e300 mm made the figures inf (their squares overflow): one beyond a trace's is refused
        targets = _validate.finite_array("targets", self.targets, ndim=1, limit=MAX_POSITION)
        if targets.size < 2 or np.any(np.diff(targets) <= 0):
            raise ValueError(f"targets must be at least 2 strictly increasing positions, got {targets}")
        up = _validate.finite_array("up", self.up, shape=(targets.size, None), limit=MAX_POSITION)
        down = _validate.finite_array("down", self.down, shape=up.shape, limit=MAX_POSITION)
        if up.shape[1] < 2:
            raise ValueError(f"up and down need at least 2 cycles (columns) each, got {up.shape[1]}")
        for name, arr in (("targets", targets), ("up", up), ("down", down)):
            arr.flags.writeable = False
            object.__setattr__(self, name, arr)


@dataclass(frozen=True)
class PositioningFigures:
    """The ISO 230-2 figures of one axis (definitions in :mod:`contoursim.iso230_2`).

    Made by :func:`positioning_figures`; every value is in [mm].

    Parameters
    ----------
    targets : ndarray, shape (m,)
        Target positions P_i [mm].
    deviation_up, deviation_down : ndarray, shape (m, n)
        Positional deviations x_ij↑, x_ij↓ = measured − target [mm].
    mean_up, mean_down : ndarray, shape (m,)
        Mean unidirectional positional deviations x̄_i↑, x̄_i↓ [mm].
    mean_bidirectional : ndarray, shape (m,)
        Mean bidirectional positional deviation x̄_i [mm].
    reversal : ndarray, shape (m,)
        Reversal values B_i = x̄_i↑ − x̄_i↓ [mm].
    s_up, s_down : ndarray, shape (m,)
        Standard uncertainties s_i↑, s_i↓ (n − 1 in the denominator) [mm].
    reversal_mean : float
        Mean reversal value B̄, signed [mm].
    reversal_max : float
        Reversal value of the axis B = max |B_i| [mm].
    repeatability_up, repeatability_down : float
        Unidirectional repeatabilities R↑ = max 4 s_i↑, R↓ = max 4 s_i↓ [mm].
    repeatability : float
        Bidirectional repeatability R [mm].
    systematic : float
        Bidirectional systematic positional deviation E [mm].
    mean_range : float
        Range of the mean bidirectional positional deviation M [mm].
    accuracy : float
        Bidirectional accuracy A [mm].
    drift : float
        Mean change of the deviation from the first to the last cycle, both
        directions [mm]; not an ISO 230-2 figure, a hint of thermal drift.
    """

    targets: np.ndarray
    deviation_up: np.ndarray
    deviation_down: np.ndarray
    mean_up: np.ndarray
    mean_down: np.ndarray
    mean_bidirectional: np.ndarray
    reversal: np.ndarray
    s_up: np.ndarray
    s_down: np.ndarray
    reversal_mean: float
    reversal_max: float
    repeatability_up: float
    repeatability_down: float
    repeatability: float
    systematic: float
    mean_range: float
    accuracy: float
    drift: float


def positioning_figures(test):
    """The ISO 230-2 figures of a bidirectional positioning test.

    Parameters
    ----------
    test : PositioningTest
        The measurements [mm].

    Returns
    -------
    PositioningFigures
        Per-target means, standard uncertainties and reversal values, and the
        axis figures B̄, B, R↑, R↓, R, E, M, A [mm].
    """
    if not isinstance(test, PositioningTest):
        raise TypeError(f"test must be a PositioningTest, got {type(test).__name__}")
    up = test.up - test.targets[:, None]
    down = test.down - test.targets[:, None]
    mean_up, mean_down = up.mean(axis=1), down.mean(axis=1)
    s_up, s_down = up.std(axis=1, ddof=1), down.std(axis=1, ddof=1)
    reversal = mean_up - mean_down
    means = np.concatenate([mean_up, mean_down])
    high = np.concatenate([mean_up + 2 * s_up, mean_down + 2 * s_down])
    low = np.concatenate([mean_up - 2 * s_up, mean_down - 2 * s_down])
    per_target_r = np.maximum.reduce([2 * s_up + 2 * s_down + np.abs(reversal), 4 * s_up, 4 * s_down])
    arrays = {
        "targets": test.targets, "deviation_up": up, "deviation_down": down, "mean_up": mean_up,
        "mean_down": mean_down, "mean_bidirectional": 0.5 * (mean_up + mean_down), "reversal": reversal,
        "s_up": s_up, "s_down": s_down,
    }
    for arr in arrays.values():
        arr.flags.writeable = False
    return PositioningFigures(
        **arrays,
        reversal_mean=float(reversal.mean()),
        reversal_max=float(np.abs(reversal).max()),
        repeatability_up=float(4 * s_up.max()),
        repeatability_down=float(4 * s_down.max()),
        repeatability=float(per_target_r.max()),
        systematic=float(means.max() - means.min()),
        mean_range=float(np.ptp(arrays["mean_bidirectional"])),
        accuracy=float(high.max() - low.min()),
        drift=float(np.mean(np.concatenate([up[:, -1] - up[:, 0], down[:, -1] - down[:, 0]]))),
    )


def write_error_table(file, axis, figures, source=None, overwrite=False):
    """Write the mean bidirectional positional deviation x̄_i as an error table.

    The CSV has ``#`` header lines (what it is, the axis figures in µm), then
    columns ``position_mm`` and ``d<axis>_um``, one row per target: the
    format :func:`contoursim.errormotion.read_error_table` reads, so a machine
    body's ``[body.errors] table = ...`` carries the measured positioning
    error, interpolated linearly between the targets.

    Parameters
    ----------
    file : str, Path or text file object
        The CSV to write (atomically, see :func:`contoursim.output.atomic_write`).
        An existing file is only replaced when `overwrite` is true.
    axis : str
        ``"x"``, ``"y"`` or ``"z"``: the column is this axis's positioning
        error ``d<axis>``.
    figures : PositioningFigures
        The test's figures, from :func:`positioning_figures`.
    source : str, optional
        Where the measurements came from, named in a header line.
    overwrite : bool
        Replace an existing file.

    Raises
    ------
    FileExistsError
        `file` exists and `overwrite` is false.
    """
    if axis not in ("x", "y", "z"):
        raise ValueError(f"axis must be 'x', 'y' or 'z', got {axis!r}")
    if not isinstance(figures, PositioningFigures):
        raise TypeError(f"figures must be PositioningFigures, got {type(figures).__name__}")
    if source is not None and (not isinstance(source, str) or any(c in source for c in "\r\n")):
        # its line break began a line of its own: the header's, and the table read_error_table refuses
        raise ValueError(f"source must be one line of text, got {source!r}")
    f = figures
    summary = ", ".join(
        f"{label} = {_UM_PER_MM * value:.2f}"
        for label, value in (("B_mean", f.reversal_mean), ("B", f.reversal_max), ("E", f.systematic),
                             ("M", f.mean_range), ("R", f.repeatability), ("A", f.accuracy))
    )
    rows = "".join(f"{float(p)!r},{float(_UM_PER_MM * d)!r}\n" for p, d in zip(f.targets, f.mean_bidirectional))
    origin = f", from {source}" if source else ""
    with writing(file, overwrite=overwrite) as out:
        out.write(
            f"# ISO 230-2 positioning test, {axis.upper()} axis: mean bidirectional positional deviation\n"
            f"# (measured - target){origin}\n"
            f"# {summary} µm\n"
            f"position_mm,d{axis}_um\n" + rows
        )
