"""Plots of simulation results: magnified path error, ballbar polar plot, errors over time.

Every function draws on a Matplotlib ``Axes`` it is given (or a new figure)
and returns that ``Axes``, like :mod:`control.ctrlplot`; the errors over time
take a ``Figure`` for their three stacked axes. The magnification
factor of an exaggerated plot is always written on the plot; runs drawn side
by side share one. Lines are thinned to what the pixels can show (the data
itself, e.g. in the trace CSV, is untouched): :func:`envelope_indices` keeps
the smallest and largest sample of every pixel column, so no spike is lost.
"""

import os
from collections.abc import Mapping

import numpy as np

from . import _validate
from ._blocks import BLOCK, blocks
from .machine import CARTESIAN
from .output import output_dir

__all__ = [
    "circular_deviation", "deviation_from_nominal", "envelope_indices", "fit_circle_center", "magnification_for",
    "plot_path_error", "plot_polar_deviation",
    "plot_errors_over_time", "save_figures", "figure_files", "plot_compared_paths", "plot_compared_contour_error",
    "plot_compared_figures", "plot_compared_zoom", "save_comparison_figures", "comparison_files", "COMPARISON_FIGURES",
    "RESOLUTION_UM",
]

#: The figures :func:`save_comparison_figures` writes, each as ``<name>_<figure>.png``.
COMPARISON_FIGURES = ("compare_path", "compare_zoom", "compare_contour", "compare_table")

_COLUMNS = 1200  # pixel columns a line is thinned to: more than any plot here is wide (<= 900 px)
_RUN_COLOURS = ("C3", "C0", "C2", "C4")  # runs overlaid: red first, as a single run is drawn
_XY = slice(0, 2)  # the columns of a path's positions most paths are drawn in: x and y


def _axes(ax, **subplot):
    if ax is not None:
        return ax
    import matplotlib.pyplot as plt

    return plt.figure(figsize=(6.4, 6.6), layout="constrained").add_subplot(**subplot)


def _round_125(x):
    """The smallest of 1, 2, 5 times a power of ten that is >= x (x > 0)."""
    decade = 10.0 ** np.floor(np.log10(x))
    return float(next(m * decade for m in (1.0, 2.0, 5.0, 10.0) if m * decade >= x * (1 - 1e-12)))


def _num(value, decimals=2):
    """`value` with `decimals` decimals, never as "-0.00"."""
    return f"{round(float(value), decimals) + 0.0:.{decimals}f}"


#: The nm the trace CSV holds [µm]: the compare plots' floor (errors below it are drawn at it), and no error below
#: it is magnified (:func:`magnification_for`).
RESOLUTION_UM = 1e-3


def magnification_for(size, error, fraction=0.08):
    """A round magnification that draws the largest error as about `fraction` of `size`.

    Parameters
    ----------
    size : float
        Extent of the drawing [mm].
    error : float
        Largest error to show [mm].
    fraction : float
        Share of `size` the magnified largest error should take at most.

    Returns
    -------
    float
        1, 2 or 5 times a power of ten, never below 1: an error already
        larger than `fraction` of `size` is drawn at true scale (1), and
        so is one below :data:`RESOLUTION_UM`, which the traces do not
        hold (the rounding of a path moving along Z only would otherwise
        be drawn ×1e14).

    Examples
    --------
    >>> magnification_for(100.0, 0.01)      # 0.01 mm drawn as ~8 mm
    500.0
    >>> magnification_for(100.0, 40.0)      # no shrinking "×0.2": true scale
    1.0
    >>> magnification_for(1.0, 1e-16)       # rounding: nothing to magnify
    1.0
    """
    if not error >= 1e-3 * RESOLUTION_UM:
        return 1.0
    raw = fraction * size / error
    if raw < 1:
        return 1.0
    decade = 10.0 ** np.floor(np.log10(raw))
    return float(max(m for m in (1.0, 2.0, 5.0) if m * decade <= raw) * decade)


class _Rows:
    """An (N, k) series made from a run's arrays when indexed (a block, or the samples drawn), never whole.

    Parameters
    ----------
    n : int
        Number of samples N.
    rows : callable
        ``rows(index)``: the rows `index` (a slice or an index array) of the series.
    """

    def __init__(self, n, rows):
        self._n, self._rows = n, rows

    def __len__(self):
        return self._n

    def __getitem__(self, index):
        return self._rows(index)


def envelope_indices(values, columns=_COLUMNS):
    """Indices of the samples that draw `values` as it looks at `columns` pixel columns.

    The samples are cut into `columns` equal runs; of each run the smallest
    and the largest value (of every series) are kept, with the first and
    last sample, so spikes survive and the line looks as the full data does.
    The runs are read a block of them at a time.

    Parameters
    ----------
    values : ndarray, shape (N,) or (N, k)
        One series or k series over the same samples, in drawing order (or
        an object of that length whose slices are such arrays).
    columns : int
        Number of runs (about the plot's width in pixels or more).

    Returns
    -------
    ndarray of int
        Sorted sample indices; all of them when N <= 2 columns.

    Examples
    --------
    >>> y = np.zeros(10_000); y[1234] = 5.0
    >>> i = envelope_indices(y, columns=100)
    >>> len(i) <= 202 and 1234 in i
    True
    """
    n = len(values)
    if n <= 2 * columns:
        return np.arange(n)
    size = -(-n // columns)
    whole = n // size * size
    block = size * max(1, BLOCK // size)  # whole runs
    picked = [[0, n - 1], np.arange(whole, n)]
    for lo in range(0, whole, block):
        part = np.asarray(values[lo : min(lo + block, whole)], float)
        runs = part.reshape(-1, size, part.size // len(part))
        start = np.arange(lo, lo + len(part), size)[:, None]
        picked += [start + runs.argmin(axis=1), start + runs.argmax(axis=1)]
    return np.unique(np.concatenate([np.ravel(p) for p in picked]))


def _thin_curve(points, step):
    """Indices of points along a curve, about `step` apart along it (and the last one) [same units].

    `points` is an (N, d) array, or an object of that length whose slices are
    such arrays (:class:`_Rows`); it is read a block at a time.
    """
    n = len(points)
    first = [[0]]
    travelled = 0.0  # along the curve up to the block's first point
    for part in blocks(n - 1):
        squares = np.diff(np.asarray(points[part.start : part.stop + 1]), axis=0)
        squares *= squares  # the segment lengths as np.linalg.norm computes them
        cell = np.empty(len(squares) + 1)  # the travelled distance, then the step it is in, in place
        cell[0] = travelled
        np.sqrt(squares.sum(axis=1), out=cell[1:])
        np.cumsum(cell, out=cell)  # sequential: the sums of one cumsum over the whole curve
        travelled = cell[-1]
        cell /= step
        np.floor(cell, out=cell)
        first.append(part.start + 1 + np.flatnonzero(cell[1:] > cell[:-1]))
    first = np.concatenate(first)  # increasing
    return first if first[-1] == n - 1 else np.append(first, n - 1)


def _drawn_curve(points, step):
    """The polyline that draws `points` on a grid of cells `step` wide: what a plot of them holds [same units].

    The curve is thinned to about two points per `step` travelled
    (:func:`_thin_curve`); of its steps from one cell to another, each pair
    of cells is drawn once, however often the curve passes between them (a
    program that retraces its path, back-and-forth passes), so the drawn data
    is bounded by the cells the curve covers, not by its length. Pairs are
    told apart by a 64-bit hash of their cells (two pairs sharing one, a
    chance of 3e-8 among a million pairs, would leave a step undrawn).

    Parameters
    ----------
    points : ndarray, shape (N, 2)
        Points in drawing order (or an object of that length whose slices are
        such arrays, :class:`_Rows`); read a block at a time.
    step : float
        Cell size: about a pixel or less.

    Returns
    -------
    ndarray, shape (M, 2)
        The pieces of the curve, in order, separated by rows of NaN.
    """
    keep = _thin_curve(points, step / 2)
    seen = np.empty(0, np.uint64)  # the pairs of cells drawn so far, sorted
    pieces, last = [], None  # last: the index of the previous block's last kept point
    for part in blocks(len(keep)):
        index = keep[part] if last is None else np.concatenate([[last], keep[part]])
        xy = np.asarray(points[index], float)
        cell = np.floor(xy / step).astype(np.int64)
        cell = (cell[:, 0] << 32) ^ (cell[:, 1] & 0xFFFFFFFF)  # one id per cell
        moved = np.flatnonzero(cell[1:] != cell[:-1])  # step m: from point moved[m] to the next one
        a, b = np.minimum(cell[moved], cell[moved + 1]), np.maximum(cell[moved], cell[moved + 1])
        with np.errstate(over="ignore"):
            key = (a.view(np.uint64) * np.uint64(0x9E3779B97F4A7C15)) ^ b.view(np.uint64)
        _, first = np.unique(key, return_index=True)
        new = np.zeros(len(key), bool)
        new[first[~np.isin(key[first], seen, assume_unique=True)]] = True  # the first of its pair, never drawn before
        seen = np.sort(np.concatenate([seen, key[new]]))
        edges = np.diff(np.concatenate([[False], new, [False]]).astype(np.int8))
        for lo, hi in zip(np.flatnonzero(edges > 0), np.flatnonzero(edges < 0)):  # runs of steps drawn: one piece each
            pieces += [xy[moved[lo] : moved[hi - 1] + 2], np.full((1, 2), np.nan)]
        last = index[-1]
    if not pieces:  # the whole curve in one cell
        return np.asarray(points[np.array([0, len(points) - 1])], float)
    return np.concatenate(pieces[:-1])


def _magnified(result, k):
    """The path with its contour error magnified, ``foot + k·(actual − foot)`` in its drawing plane
    (:func:`_drawn_axes`) [mm], as :class:`_Rows`."""
    tool, foot = result.tool_position, result.contour.foot
    drawn = _drawn_axes(result.trajectory)

    def rows(index):
        shown = tool[index, drawn] - foot[index, drawn]
        shown *= k
        shown += foot[index, drawn]
        return shown

    return _Rows(len(tool), rows)


def _drawn_axes(trajectory):
    """The two coordinates a path is drawn in, as a slice of its positions' columns (a view, never a copy of a
    run's length): x and y, or x and z (y and z) for a path in a plane y = c (x = c), as a G18 (G19) program's; a
    3-D path that leaves every such plane is drawn in XY."""
    position = trajectory.position
    if position.shape[1] < 3 or np.ptp(position[:, 2]) == 0:
        return _XY
    flat = [i for i in (1, 0) if np.ptp(position[:, i]) == 0]
    return _XY if not flat else slice(0, 3, 2) if flat[0] == 1 else slice(1, 3)


def _drawn_labels(ax, drawn):
    """Label the axes of a drawing in the coordinates `drawn` (:func:`_drawn_axes`)."""
    first, second = range(3)[drawn]
    ax.set_xlabel(f"{CARTESIAN[first]} [mm]")
    ax.set_ylabel(f"{CARTESIAN[second]} [mm]")


def _has_test(trajectory):
    """True when the path marks a test proper (primitives with role "test") to tell apart from the rest."""
    return trajectory.path is not None and "test" in trajectory.path.roles


def _drawing_size(points):
    """The extent [mm] of a drawing of `points` (N, 2) in their plane: their largest extent, or 1 mm for a path that
    moves less than 1 µm in it (one along Z only), whose drawing is then a point at the centre of a 1 mm frame."""
    size = float(np.ptp(points, axis=0).max())
    return size if size >= 1e-3 else 1.0


def _shared_magnification(results):
    """One magnification for `results` drawn side by side: from the largest contour error of all."""
    size = max(_drawing_size(r.trajectory.position[:, _drawn_axes(r.trajectory)]) for r in results)
    return magnification_for(size, max(float(r.contour.magnitude.max()) for r in results))


def _effects_text(result):
    """The effects and compensation a run has switched on, e.g. ``effects: backlash.x 10 µm, squareness.xy 100 µrad``."""
    effects = []
    for e in getattr(result.model, "effects", ()):
        size = e.parameters[0]
        value = f"{size.name} = {size.value:g}" if size.unit == "-" else f"{size.value:g} {size.unit}"
        effects.append(f"{e.label} {value}")
    text = f"effects: {', '.join(effects)}" if effects else "no effects"
    strategies = [s.name for s in result.strategies]
    return text + (f"; compensation: {', '.join(strategies)}" if strategies else "")


def _direction(result):
    """``"CCW"`` or ``"CW"`` for a run on a path with a test circle, else ``None``."""
    path = result.trajectory.path
    circle = path.test_circle() if path is not None else None
    return None if circle is None else "CCW" if circle.sweep * circle.axis[2] > 0 else "CW"


def _drawable(name):
    """A run's name as text a figure can draw: the bytes of a file name that are not UTF-8 escaped (``p\\xff``)."""
    return os.fsencode(name).decode("utf-8", "backslashreplace")


def _run_title(result, name=None):
    """Two lines naming a run: ``name (CW) on machine``, then the effects and compensation switched on."""
    direction = _direction(result)
    head = _drawable(name or "run") + (f" ({direction})" if direction else "")
    return f"{head} on {result.machine.name or 'the machine'}\n{_effects_text(result)}"


def _worst(result):
    """Index of the sample with the largest contour error on the test proper (read a block at a time)."""
    magnitude, measuring = result.contour.magnitude, result.trajectory.measuring
    best, at = -1.0, 0
    for part in blocks(len(magnitude)):
        shown = np.where(measuring[part], magnitude[part], -1.0)
        i = int(np.argmax(shown))
        if shown[i] > best:
            best, at = float(shown[i]), part.start + i
    return at


def plot_path_error(result, ax=None, magnification=None, name=None):
    """Reference path and the actual path with its contour error magnified.

    The magnified path is ``foot + k·(actual − foot)``: each actual point is
    moved away from its nearest path point, along the path's normal, by `k`
    times its contour error. Where ``k·ε`` exceeds the path's local radius of
    curvature on the inside of a bend (tight lobes), the drawn curve loops:
    the title says so, as such loops are not overshoot. The start is marked,
    an arrow gives the direction of travel and a triangle the largest contour
    error of the test proper; a path in a plane y = c or x = c (G18, G19) is
    drawn in that plane, another 3-D path in XY. The title names the run, its
    direction on a circular test (CW or CCW), the machine and the effects and
    compensation switched on. The lines hold what the pixels can
    show (:func:`_drawn_curve`): a path retraced many times is drawn once.

    Parameters
    ----------
    result : contoursim.simulation.SimResult
    ax : matplotlib.axes.Axes, optional
    magnification : float, optional
        Factor k [-], at least 1; chosen by :func:`magnification_for` when omitted.
    name : str, optional
        The run's name, for the title.
    """
    ax = _axes(ax)
    traj, contour = result.trajectory, result.contour
    drawn = _drawn_axes(traj)
    ref = traj.position[:, drawn]
    size = _drawing_size(ref)
    k = magnification_for(size, float(contour.magnitude.max())) if magnification is None else \
        _validate.positive("magnification", magnification)
    if k < 1:
        raise ValueError(f"magnification must be at least 1 (true scale), got {k:g}")
    step = size / _COLUMNS
    shown = _magnified(result, k)
    ax.plot(*_drawn_curve(ref, step).T, color="0.6", lw=1.0, label="reference")
    label = f"actual, contour error ×{k:g} along the path normal" if k > 1 else "actual (true scale)"
    ax.plot(*_drawn_curve(shown, step).T, color="C3", lw=1.0, label=label)
    ax.plot(*ref[0], "o", color="k", ms=5, label="start")
    worst = _worst(result)
    largest = 1e3 * contour.magnitude[worst]
    ax.plot(*shown[[worst]].T, "v", color="k", ms=6, mfc="none", label=f"max {largest:.2f} µm")
    ahead = int(np.searchsorted(traj.s, traj.s[0] + 0.04 * size))
    if 0 < ahead < len(ref):
        ax.annotate("", xy=ref[ahead], xytext=ref[0], arrowprops=dict(arrowstyle="-|>", color="k", lw=1.0))
    ax.set_aspect("equal", adjustable="datalim")
    _drawn_labels(ax, drawn)
    if k == 1 and largest < RESOLUTION_UM:
        title = f"contour error below the traces' {RESOLUTION_UM * 1e3:g} nm: nothing to magnify"
    else:
        title = f"contour error {f'×{k:g}' if k > 1 else 'at true scale'}: max {largest:.2f} µm"
    if _has_test(traj):
        title += " on the test proper"
    notes = []
    if drawn == _XY and traj.dim == 3 and np.ptp(traj.position[:, 2]) > 0:
        notes.append("3-D path shown in XY (z not drawn)")
    if k > 1 and traj.path is not None:
        loops, fans = _loops_and_fans(result, k)
        if loops:
            notes.append(f"loops: ×{k:g} error exceeds the bend radius, not overshoot")
        if fans:  # the foot switches between the two sides' normals there
            notes.append(f"near sharp corners the ×{k:g} offset turns between two normals: fans, not overshoot")
    ax.set_title("\n".join([_run_title(result, name), title, *notes]), fontsize="medium")
    ax.legend(loc="upper center", bbox_to_anchor=(0.5, -0.1), ncol=2, fontsize="small", frameon=False)
    return ax


def _loops_and_fans(result, k):
    """Whether the ×k drawing loops (k·ε beyond the bend radius) and fans (an error near a sharp corner).

    Read a block of samples at a time.
    """
    path, contour = result.trajectory.path, result.contour
    dim = result.trajectory.dim
    corners = path.breaks[1:-1][path.corner_angles() > 1e-6]  # arc length of sharp corners, increasing
    loops = fans = False
    for part in blocks(len(contour.s)):
        s, error = contour.s[part], contour.magnitude[part]
        _, _, bend = path.derivatives(s)  # curvature vector, towards the centre of the bend
        offset = result.tool_position[part] - contour.foot[part]
        loops = loops or bool(np.any(k * np.einsum("ij,ij->i", offset, bend[:, :dim]) > 1))
        if len(corners) and not fans:
            i = np.searchsorted(corners, s)  # the corners either side of each sample
            before, after = corners[np.maximum(i - 1, 0)], corners[np.minimum(i, len(corners) - 1)]
            nearest = np.minimum(np.abs(s - before), np.abs(s - after))
            fans = bool(np.any(nearest < 5 * error))
        if loops and fans:
            break
    return loops, fans


def fit_circle_center(points):
    """Least-squares centre of points near a circle (algebraic fit), shape (2,) [mm].

    Parameters
    ----------
    points : ndarray, shape (N, 2)
        Points [mm].

    Examples
    --------
    >>> theta = np.linspace(0, 2 * np.pi, 50)
    >>> fit_circle_center(np.column_stack([3 + 2 * np.cos(theta), -1 + 2 * np.sin(theta)])).round(12)
    array([ 3., -1.])
    """
    # |p|^2 = 2 c.p + (R^2 - |c|^2) is linear in c and the constant
    basis = np.column_stack([2 * points, np.ones(len(points))])
    solution, *_ = np.linalg.lstsq(basis, (points**2).sum(axis=1), rcond=None)
    return solution[:2]


def circular_deviation(result):
    """Ballbar evaluation of a circular test over its test proper (``trajectory.measuring``).

    As ISO 230-4 and a ballbar's software do: the data-collection circle only
    (the samples whose reference lies on the test circle, so no run-in or
    overrun transient), the least-squares centre of the measured points
    removed, the circularity the range of the radial deviation about it.

    Parameters
    ----------
    result : contoursim.simulation.SimResult
        A run on a path with a test circle (:meth:`contoursim.paths.Path.test_circle`).

    Returns
    -------
    dict
        ``theta`` [rad] and ``deviation`` |p − c| − R [µm] of the measured
        points about the least-squares centre c, the ``offset`` c − nominal
        centre [µm], ``circularity`` max − min deviation [µm], ``radius`` R
        [mm] and ``direction`` ("CCW" or "CW").
    """
    circle = result.trajectory.path.test_circle()
    points = result.tool_position[result.trajectory.measuring, :2]
    fitted = fit_circle_center(points)
    rel = points - fitted
    deviation = 1e3 * (np.hypot(rel[:, 0], rel[:, 1]) - circle.radius)
    return dict(theta=np.arctan2(rel[:, 1], rel[:, 0]), deviation=deviation, offset=1e3 * (fitted - circle.center[:2]),
                circularity=float(np.ptp(deviation)), radius=circle.radius, direction=_direction(result))


def deviation_from_nominal(result, nominal):
    """Ballbar evaluation of `result` minus that of the `nominal` run at the same angles.

    Both runs are evaluated as by :func:`circular_deviation` (each about its
    own least-squares centre); the nominal deviation is interpolated at the
    run's angles. What the run has and the nominal run has not (an effect
    switched on) is left; what both share (the servo's radius loss, a gain
    mismatch between the axes) cancels.

    Parameters
    ----------
    result, nominal : contoursim.simulation.SimResult
        Runs on the same test circle in the same direction.

    Returns
    -------
    dict
        As :func:`circular_deviation`: ``theta`` [rad], ``deviation`` [µm]
        (the difference), ``offset`` (the difference of the centres) [µm],
        ``circularity`` (range of the difference) [µm], ``radius`` [mm],
        ``direction``.

    Raises
    ------
    ValueError
        The runs are circular tests in different directions.
    """
    run, base = circular_deviation(result), circular_deviation(nominal)
    if run["direction"] != base["direction"]:
        raise ValueError(f"a {run['direction']} run cannot be compared with a {base['direction']} nominal run")
    order = np.argsort(base["theta"])
    deviation = run["deviation"] - np.interp(run["theta"], base["theta"][order], base["deviation"][order], period=2 * np.pi)
    return dict(run, deviation=deviation, offset=run["offset"] - base["offset"], circularity=float(np.ptp(deviation)))


def _polar_frame(ax, curves):
    """Rings that follow the data of `curves` (``(theta [rad], values [µm])``) on a polar `ax`.

    The rings span the data's range in 2 to 6 round divisions (zero need not
    be among them: a radius loss of 50 µm does not hide a 2 µm ellipse); the
    blank centre keeps the shape of a circle. The ring labels sit on a white
    ground on the ray, off the angle labels, where the data keeps farthest
    from them, a ring the data passes there unlabelled; the dashed zero
    circle is drawn over the data when it is in range.

    Returns
    -------
    division : float
        Ring spacing [µm].
    zero : bool
        Whether the zero circle is in range (and drawn).
    """
    values = np.concatenate([v for _, v in curves])
    theta = np.concatenate([t for t, _ in curves])
    lo, hi = float(values.min()), float(values.max())
    division = _round_125(max(hi - lo, 1e-3) / 5)
    lo, hi = np.floor(lo / division) * division, np.ceil(hi / division) * division
    if hi - lo < 2 * division:
        lo, hi = lo - division, hi + division
    rings = division * np.arange(round(lo / division), round(hi / division) + 1)
    ax.set_rorigin(lo - 0.75 * (hi - lo))
    ax.set_ylim(lo, hi)
    ax.set_yticks(rings)
    # the labels go on the ray (every 5°, 10° or more off the angle labels at each 45°, which the outer ring's would
    # print over) where the data within ±6° keeps clear of most of them, then farthest; a ring the data passes there
    # within 0.45 division goes unlabelled (the title gives the spacing)
    degrees = np.arange(0.0, 360.0, 5.0)
    rays = np.radians(degrees[np.minimum(degrees % 45, 45 - degrees % 45) >= 10])
    near = np.abs((theta[None, :] - rays[:, None] + np.pi) % (2 * np.pi) - np.pi) < np.radians(6.0)
    gap = np.abs(values[:, None] - rings[None, :])  # (samples, rings)
    clearance = np.array([gap[ray].min(axis=0) if ray.any() else np.full(len(rings), np.inf) for ray in near])
    clear = clearance > 0.45 * division
    best = int(np.argmax(clear.sum(axis=1) + np.minimum(clearance.min(axis=1), division) / (2 * division)))
    ax.set_yticklabels([f"{v:g}" if shown else "" for v, shown in zip(rings, clear[best])],
                       fontsize="small", color="0.3", bbox=dict(facecolor="white", edgecolor="none", alpha=0.85, pad=0.6))
    ax.set_rlabel_position(np.degrees(rays[best]))
    ax.grid(True, color="0.85", lw=0.6)
    for spine in ax.spines.values():  # no solid circle that could be read as a reference
        spine.set_edgecolor("none")  # (the inner one is made visible again at each draw)
    zero = bool(lo <= 0.0 <= hi)
    if zero:
        ax.plot(np.linspace(0, 2 * np.pi, 361), np.zeros(361), "k--", lw=0.8, zorder=4, label="zero")
    return division, zero


def plot_polar_deviation(runs, ax=None, nominal=None):
    """Ballbar polar plot of circular tests, runs overlaid (e.g. CW and CCW), or their difference from nominal runs.

    Each run is evaluated over its test proper (``trajectory.measuring``: the
    data-collection circle of an ISO 230-4 test, without run-in, overruns and
    run-out) as a ballbar's software does: the least-squares centre of the
    measured points is removed (offset in the legend) and the radial axis is
    the deviation |p − c| − R [µm]. The circularity is the range of that
    deviation (max − min). The rings follow the data: a round number of µm
    apart (in the title) from its smallest to its largest value, so that a
    radius loss of the servo does not squeeze a 10 µm backlash step or a
    5 µm squareness ellipse into a fraction of a ring; the mean deviation is
    in the legend, and zero (the nominal radius) is the dashed circle when
    in range. The title names the runs, the machine and the effects and
    compensation switched on.

    With `nominal`, each run is drawn minus the nominal run of the same name
    (:func:`deviation_from_nominal`): a "difference from nominal" view, in
    which the servo's own signature (radius loss, gain mismatch) cancels and
    what the run adds (squareness, backlash) is left.

    Parameters
    ----------
    runs : SimResult or dict of str -> SimResult
        One run, or runs by name, whose path has a test circle
        (:meth:`contoursim.paths.Path.test_circle`). Runs of different
        directions are labelled by direction, others by name too.
    ax : matplotlib.axes.Axes with polar projection, optional
    nominal : SimResult or dict of str -> SimResult, optional
        The nominal run of each run (by the same name): the same path on the
        machine without the effects.

    Raises
    ------
    ValueError
        A run's path has no test circle, a run has no nominal run, or a
        nominal run goes the other way round.
    """
    runs = dict(runs) if isinstance(runs, dict) else {"": runs}
    if nominal is not None:
        nominal = dict(nominal) if isinstance(nominal, dict) else {"": nominal}
        missing = [name for name in runs if name not in nominal]
        if missing:
            raise ValueError(f"no nominal run for {missing[0]!r}")
    results = list(runs.values())
    for r in results + list((nominal or {}).values()):
        if r.trajectory.path is None or r.trajectory.path.test_circle() is None:
            raise ValueError("a polar plot needs runs on a path with a full test circle (role 'test')")
    ax = _axes(ax, projection="polar")
    tests = [circular_deviation(r) if nominal is None else deviation_from_nominal(r, nominal[name])
             for name, r in runs.items()]
    keeps = [envelope_indices(test["deviation"]) for test in tests]
    division, zero = _polar_frame(ax, [(test["theta"][keep], test["deviation"][keep]) for test, keep in zip(tests, keeps)])
    directions = [test["direction"] for test in tests]
    by_direction = len(set(directions)) == len(tests)
    effects = [_effects_text(r) for r in results]
    shared = len(set(effects)) == 1
    for i, (name, test, keep) in enumerate(zip(runs, tests, keeps)):
        label = test["direction"] if by_direction else f"{name} ({test['direction']})"
        what = "circularity" if nominal is None else "range"
        ax.plot(test["theta"][keep], test["deviation"][keep], color=_RUN_COLOURS[i % len(_RUN_COLOURS)], lw=1.0,
                label=f"{label}: {what} {test['circularity']:.2f} µm, mean {_num(test['deviation'].mean())} µm"
                      + ("" if shared else f"\n{effects[i]}")
                      + f"\ncentre offset ({_num(test['offset'][0])}, {_num(test['offset'][1])}) µm removed")
    first = results[0]
    feeds = sorted({f"{60 * r.trajectory.feed:.4g}" for r in results})
    radii = sorted({f"{test['radius']:g}" for test in tests})
    names = ", ".join(_drawable(n) for n in runs if n) or "circular test"
    if len(names) > 60:  # long: named in the legend
        names = f"{len(runs)} runs"
    lines = [f"{names} on {first.machine.name or 'the machine'}"]
    if shared:
        lines.append(effects[0])
    if nominal is not None:
        base = list(nominal.values())[0]
        lines.append(f"minus the nominal run: {base.machine.name or 'the machine'}, {_effects_text(base)}")
    lines.append(f"R = {', '.join(radii)} mm, F = {', '.join(feeds)} mm/min, {' and '.join(dict.fromkeys(directions))}: "
                 f"{'radial deviation' if nominal is None else 'difference'} [µm], {division:g} µm/div"
                 + ("" if zero else ", zero off the scale"))
    ax.set_title("\n".join(lines), fontsize="medium")
    ax.legend(loc="upper center", bbox_to_anchor=(0.5, -0.04), fontsize="small", frameon=False)
    return ax


def plot_errors_over_time(result, fig=None, name=None):
    """Signed contour error, per-axis following error and motor current over time.

    What a servo-tuning tool shows, on linear axes: the signed in-plane
    contour error [µm] (positive to the left of travel; for a 3-D path also
    the part out of the path's plane), each servo axis's
    following error (command − actual position) [µm] and motor current
    command [A]. The test proper is shaded. The title names the run (its
    direction on a circular test), the machine and the effects and
    compensation switched on.

    Parameters
    ----------
    result : contoursim.simulation.SimResult
    fig : matplotlib.figure.Figure, optional
        Where to draw three stacked axes; a new figure when omitted.
    name : str, optional
        The run's name, for the title.

    Returns
    -------
    ndarray of matplotlib.axes.Axes, shape (3,)
    """
    if fig is None:
        import matplotlib.pyplot as plt

        fig = plt.figure(figsize=(8.0, 7.5), layout="constrained")
    axes = fig.subplots(3, 1, sharex=True)
    t = result.trajectory.t
    response, columns, error = result.servo_response, result.machine.servo_columns, result.contour
    following = _Rows(len(t), lambda i: (np.take(result.axis_command[i], columns, axis=1) - response.position[i]) * 1e3)
    names = list(result.machine.axes)
    contour, labels = _Rows(len(t), lambda i: 1e3 * error.normal[i][:, None]), ["contour error"]
    if result.trajectory.dim == 3:  # a 3-D path: the part out of the path's plane too
        contour = _Rows(len(t), lambda i: 1e3 * np.column_stack([error.normal[i], error.out_of_plane[i]]))
        labels = ["in plane", "out of plane"]
    series = [  # [µm]; the errors made block by block and at the samples drawn, not whole
        (axes[0], contour, labels, "contour error [µm]"),
        (axes[1], following, names, "following error [µm]"),
        (axes[2], response.current, names, "motor current [A]"),
    ]
    measuring = result.trajectory.measuring
    test = t[np.argmax(measuring)], t[len(measuring) - 1 - np.argmax(measuring[::-1])]  # its first and last sample
    for ax, values, labels, ylabel in series:
        keep = envelope_indices(values)
        drawn = values[keep]
        for j, label in enumerate(labels):
            ax.plot(t[keep], drawn[:, j], lw=0.9, label=label, color="C3" if ax is axes[0] and j == 0 else f"C{j}")
        if _has_test(result.trajectory):
            ax.axvspan(*test, color="0.93", zorder=0, label="test proper")
        ax.axhline(0.0, color="0.5", lw=0.6)
        ax.set_ylabel(ylabel)
        ax.grid(True, alpha=0.3)
        ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize="small", frameon=False)
    axes[0].set_title(f"{_run_title(result, name)}\ncontour error (signed, + left of travel), following error and current",
                      fontsize="medium")
    axes[-1].set_xlabel("t [s]")
    return axes


def save_figures(runs, out_dir, name, nominal=None):
    """Write the standard plots of runs shown side by side as PNG files into `out_dir`.

    Per run ``<run>_path.png`` (:func:`plot_path_error`, one magnification
    for all `runs`) and ``<run>_errors.png`` (:func:`plot_errors_over_time`);
    when the runs are circular tests, one ``<name>_polar.png`` with all of
    them overlaid (:func:`plot_polar_deviation`) and, with `nominal` runs,
    ``<name>_polar_difference.png``: each run minus its nominal run.

    Parameters
    ----------
    runs : dict of str -> contoursim.simulation.SimResult
        The runs, by file name stem.
    out_dir : str, pathlib.Path or contoursim.output.OutputDir
        The output folder (see :func:`contoursim.output.output_dir`): created if
        missing; a file there that contoursim did not write is never replaced.
    name : str
        File name stem of the polar plot.
    nominal : dict of str -> contoursim.simulation.SimResult, optional
        The nominal run of each circular test, by the run's name.

    Returns
    -------
    list of pathlib.Path
        The files written.

    Raises
    ------
    FileExistsError
        A plot's file exists and contoursim did not write it.
    """
    return _draw(_drawings(runs, name, nominal), out_dir)


def figure_files(runs, name, nominal=None):
    """The names of the files :func:`save_figures` writes for these arguments, drawing none of them.

    For a command that writes other files beside the plots: it refuses
    the whole set (:meth:`contoursim.output.OutputDir.file`) before writing any.

    Parameters
    ----------
    runs, name, nominal
        As :func:`save_figures`'s.

    Returns
    -------
    list of str
    """
    return [file for file, *_ in _drawings(runs, name, nominal)]


def _drawings(runs, name, nominal):
    """:func:`save_figures`'s plots as ``(file, size [in], margins, drawing)``, for :func:`_draw`."""
    if not isinstance(runs, Mapping):
        raise TypeError(f"runs must map run names to SimResults ({{'circle': result}}), got {type(runs).__name__}")
    if not runs:
        raise ValueError("runs is empty: save_figures draws at least one run")
    results = list(runs.values())
    k = _shared_magnification(results)
    # (file, size [in], margins, drawing): fixed margins that leave room for the legends, no layout search
    path_margins = dict(left=0.12, right=0.96, top=0.84, bottom=0.15)
    drawings = [(f"{run}_path.png", (6.4, 7.2), path_margins,
                 lambda fig, r=r, run=run: plot_path_error(r, fig.add_subplot(), k, name=run)) for run, r in runs.items()]
    errors_margins = dict(left=0.1, right=0.84, top=0.91, bottom=0.07, hspace=0.12)
    drawings += [(f"{run}_errors.png", (8.0, 7.8), errors_margins,
                  lambda fig, r=r, run=run: plot_errors_over_time(r, fig, run)) for run, r in runs.items()]
    if all(r.trajectory.path is not None and r.trajectory.path.test_circle() is not None for r in results):
        legend = 0.5 + 0.55 * len(runs)  # [in] below the rings: two or three lines a run
        size = (7.0, 6.9 + legend)
        polar_margins = dict(left=0.08, right=0.92, top=1 - 1.2 / size[1], bottom=legend / size[1])
        drawings.append((f"{name}_polar.png", size, polar_margins,
                         lambda fig: plot_polar_deviation(runs, fig.add_subplot(projection="polar"))))
        if nominal is not None:
            drawings.append((f"{name}_polar_difference.png", size, polar_margins,
                             lambda fig: plot_polar_deviation(runs, fig.add_subplot(projection="polar"), nominal)))
    return drawings


def _draw(drawings, out_dir):
    """Draw and write ``(file, size [in], margins, drawing)`` PNGs; all refused before any is drawn."""
    from matplotlib.figure import Figure

    out_dir = output_dir(out_dir)
    files = [out_dir.file(file) for file, *_ in drawings]
    for file, (_, size, margins, draw) in zip(files, drawings):
        fig = Figure(figsize=size)
        fig.subplots_adjust(**margins)
        draw(fig)
        with out_dir.write(file.name, binary=True) as stream:
            # zlib level 3, not PIL's 6: the same pixels, 5 ms less per figure, files 1-10 % larger
            fig.savefig(stream, format="png", dpi=110, pil_kwargs={"compress_level": 3})
    return files


# ---------------------------------------------------------------------------------------------
# Strategies compared (contoursim compare)


def _grid(fig, n):
    """`n` axes of small multiples on `fig`, three to a row, and the unused cells hidden."""
    columns = min(3, n)
    rows = -(-n // columns)
    axes = np.atleast_1d(fig.subplots(rows, columns, squeeze=False).ravel())
    for ax in axes[n:]:
        ax.set_visible(False)
    return axes[:n]


def plot_compared_paths(runs, fig=None, magnification=None):
    """Each run's path (strategy) in a panel of its own, contour errors magnified by one factor for all.

    Each run is drawn as in :func:`plot_path_error` (``foot + k·(actual − foot)``)
    with one factor k for all, chosen from the largest contour error of all
    runs: a run whose error is orders of magnitude smaller lies on the
    reference at that scale, which is the comparison. Small multiples, so
    that no run hides under another.

    Parameters
    ----------
    runs : dict of str -> contoursim.simulation.SimResult
        Runs on the same reference, by name.
    fig : matplotlib.figure.Figure, optional
    magnification : float, optional
        Factor k [-], at least 1.

    Returns
    -------
    ndarray of matplotlib.axes.Axes
        One per run.
    """
    if fig is None:
        import matplotlib.pyplot as plt

        fig = plt.figure(figsize=(10.0, 7.0), layout="constrained")
    results = list(runs.values())
    first = results[0]
    drawn = _drawn_axes(first.trajectory)
    ref = first.trajectory.position[:, drawn]
    size = _drawing_size(ref)
    k = _shared_magnification(results) if magnification is None else _validate.positive("magnification", magnification)
    step = size / (2 * _COLUMNS)
    ir = _thin_curve(ref, step)
    axes = _grid(fig, len(runs))
    for i, (ax, (name, result)) in enumerate(zip(axes, runs.items())):
        ax.plot(ref[ir, 0], ref[ir, 1], color="0.6", lw=2.0)
        shown = _magnified(result, k)
        ia = _thin_curve(shown, step)
        largest = 1e3 * result.contour.magnitude[result.trajectory.measuring].max()
        ax.plot(*shown[ia].T, color=f"C{i}", lw=0.9)
        ax.set_aspect("equal", adjustable="datalim")
        ax.set_title(f"{name}: max {_um(largest)}", fontsize="small")
        ax.tick_params(labelsize="x-small")
    scale = f"×{k:g} along the path normal" if k > 1 else "at true scale"
    fig.suptitle(f"Contour error of each strategy, {scale} (one factor for all; grey: the reference; "
                 f"{', '.join(CARTESIAN[i] for i in range(3)[drawn])} [mm])",
                 fontsize="medium")
    return axes


def _um(value):
    """An error [µm] as the table and the CSV hold it: to the nm, "< 0.001 µm" below."""
    return f"< {RESOLUTION_UM:g} µm" if value < 0.5 * RESOLUTION_UM else f"{value:.3f} µm"


def plot_compared_zoom(runs, fig=None):
    """Each run's worst spot at true scale: the path and the actual positions around it [µm].

    The window is centred on the foot point of the run's largest contour
    error over the test proper, with the path's tangent there across and
    the direction of that error up (in-plane and out-of-plane parts alike),
    both in µm and at one scale (equal axes, nothing magnified). Its half
    width is four times that error, at least 1 µm (a few samples of the
    path at a usual feed; below it the straight lines between samples are
    no longer the motion). Dots: the actual positions sampled at the servo
    period; grey: their foot points on the path.

    Parameters
    ----------
    runs : dict of str -> contoursim.simulation.SimResult
    fig : matplotlib.figure.Figure, optional

    Returns
    -------
    ndarray of matplotlib.axes.Axes
        One per run.
    """
    if fig is None:
        import matplotlib.pyplot as plt

        fig = plt.figure(figsize=(10.0, 7.0), layout="constrained")
    axes = _grid(fig, len(runs))
    for i, (ax, (name, result)) in enumerate(zip(axes, runs.items())):
        error, measuring = result.contour, result.trajectory.measuring
        worst = int(np.flatnonzero(measuring)[np.argmax(error.magnitude[measuring])])
        largest = 1e3 * float(error.magnitude[worst])
        half = max(4.0 * largest, 1.0)  # [µm]
        foot, actual = error.foot, result.tool_position
        centre = foot[worst]
        other = np.flatnonzero(np.any(foot != centre, axis=1))  # the path's direction: to the nearest other foot point
        nearest = other[np.argmin(np.abs(other - worst))]
        tangent = (centre - foot[nearest]) * np.sign(worst - nearest)
        tangent /= np.linalg.norm(tangent)
        up = actual[worst] - centre
        up = up - (up @ tangent) * tangent
        if np.linalg.norm(up) <= 1e-12 * max(1.0, np.linalg.norm(centre)):  # no error across the path (none at all,
            up = np.eye(tangent.size)[np.argmin(np.abs(tangent))]           # or along it at a path end): any direction
            up = up - (up @ tangent) * tangent
        up /= np.linalg.norm(up)
        reach = 1e-3 * 3 * half
        near = np.flatnonzero(np.linalg.norm(foot - centre, axis=1) < reach + 1e-3 * 10)  # samples around the spot
        frame = np.array([tangent, up])
        path_um = 1e3 * (foot[near] - centre) @ frame.T
        actual_um = 1e3 * (actual[near] - centre) @ frame.T
        ax.plot(*path_um.T, color="0.6", lw=2.0, marker=".", ms=3)
        ax.plot(*actual_um.T, color=f"C{i}", lw=0.8, marker="o", ms=3)
        ax.annotate("", xy=1e3 * (actual[worst] - centre) @ frame.T, xytext=(0.0, 0.0),
                    arrowprops=dict(arrowstyle="->", color="k", lw=0.8))
        ax.set_xlim(-half, half)
        ax.set_ylim(-half, half)
        ax.set_aspect("equal")
        t = result.trajectory.t[worst]
        ax.set_title(f"{name}: {_um(largest)} at t = {t:.3f} s", fontsize="small")
        ax.set_xlabel("along the path [µm]", fontsize="x-small")
        ax.set_ylabel("toward the error [µm]", fontsize="x-small")
        ax.tick_params(labelsize="x-small")
        ax.grid(True, alpha=0.3)
    fig.suptitle("Worst spot of each strategy at true scale (grey: the path; dots: the actual positions, "
                 "every servo period; arrow: the largest contour error)", fontsize="medium")
    return axes


def plot_compared_contour_error(runs, ax=None):
    """Contour error magnitude over time of several runs, on a log scale from the CSV's resolution [µm].

    Errors below :data:`RESOLUTION_UM` are drawn at it.

    Parameters
    ----------
    runs : dict of str -> contoursim.simulation.SimResult
    ax : matplotlib.axes.Axes, optional

    Returns
    -------
    matplotlib.axes.Axes
    """
    ax = _axes(ax)
    for i, (name, result) in enumerate(runs.items()):
        t, error = result.trajectory.t, 1e3 * result.contour.magnitude
        keep = envelope_indices(error)
        ax.plot(t[keep], np.maximum(error[keep], RESOLUTION_UM), lw=0.8, color=f"C{i}", label=name)
    ax.set_yscale("log")
    ax.set_ylim(bottom=RESOLUTION_UM)
    ax.set_xlabel("t [s]")
    ax.set_ylabel("contour error [µm] (log, from the CSV's nm)")
    ax.grid(True, which="both", alpha=0.3)
    ax.set_title("Contour error over time", fontsize="medium")
    ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize="small", frameon=False)
    return ax


def plot_compared_figures(figures, fig=None):
    """Bar chart of a comparison's table: errors [µm] on a log scale from the CSV's nm, and the peak current [A].

    Every bar is labelled with its value (as in the table: to the nm);
    errors below :data:`RESOLUTION_UM` are drawn at it.

    Parameters
    ----------
    figures : dict of str -> dict
        Strategy name -> :attr:`contoursim.comparison.Comparison.figures` entry.
    fig : matplotlib.figure.Figure, optional

    Returns
    -------
    ndarray of matplotlib.axes.Axes, shape (2,)
    """
    if fig is None:
        import matplotlib.pyplot as plt

        fig = plt.figure(figsize=(9.0, 6.5), layout="constrained")
    errors_ax, current_ax = fig.subplots(2, 1, height_ratios=(2, 1))
    names = list(figures)
    x = np.arange(len(names))
    keys = (("contour_max_um", "contour max"), ("contour_rms_um", "contour RMS"),
            ("tracking_max_um", "tracking max"), ("tracking_rms_um", "tracking RMS"))  # fmt: skip
    width = 0.8 / len(keys)
    top = max(max(figures[n][key] for n in names) for key, _ in keys)
    for j, (key, label) in enumerate(keys):
        values = np.array([figures[n][key] for n in names])
        bars = errors_ax.bar(x + (j - (len(keys) - 1) / 2) * width, np.maximum(values, RESOLUTION_UM), width,
                             label=label, color=f"C{j}")
        errors_ax.bar_label(bars, [_um(v).replace(" µm", "") for v in values], rotation=90, padding=2,
                            fontsize="xx-small")
    errors_ax.set_yscale("log")
    errors_ax.set_ylim(RESOLUTION_UM, max(top, RESOLUTION_UM) * 300)  # room for the labels above the bars
    errors_ax.set_ylabel("error [µm] (log, from the CSV's nm)")
    errors_ax.set_xticks(x, names, rotation=12, fontsize="small")
    errors_ax.grid(True, axis="y", which="both", alpha=0.3)
    errors_ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize="small", frameon=False)
    errors_ax.set_title("Errors over the test proper and peak current, by strategy", fontsize="medium")
    currents = [figures[n]["peak_current_A"] for n in names]
    hatches = ["//" if figures[n]["saturated"] else "" for n in names]
    bars = current_ax.bar(x, currents, 0.5, color="0.55", hatch=hatches)
    current_ax.bar_label(bars, [f"{c:.3g}" for c in currents], padding=2, fontsize="x-small")
    current_ax.set_ylim(0.0, 1.25 * max(currents))
    current_ax.set_ylabel("peak current [A]")
    current_ax.set_xticks(x, names, rotation=12, fontsize="small")
    current_ax.grid(True, axis="y", alpha=0.3)
    current_ax.set_title("Peak current command (hatched: the current limit bound)", fontsize="medium")
    return np.array([errors_ax, current_ax])


def comparison_files(name):
    """The names of the files :func:`save_comparison_figures` writes for the file name stem `name`, drawing none.

    For a command to refuse them (:func:`contoursim.output.refused_early`) before its comparison runs.

    Parameters
    ----------
    name : str
        File name stem.

    Returns
    -------
    list of str
        ``<name>_<figure>.png`` for each of :data:`COMPARISON_FIGURES`.
    """
    return [f"{name}_{figure}.png" for figure in COMPARISON_FIGURES]


def save_comparison_figures(comparison, out_dir, name):
    """Write ``<name>_compare_path.png``, ``_compare_zoom.png``, ``_compare_contour.png`` and ``_compare_table.png``.

    Parameters
    ----------
    comparison : contoursim.comparison.Comparison
    out_dir : str, pathlib.Path or contoursim.output.OutputDir
        As for :func:`save_figures`.
    name : str
        File name stem.

    Returns
    -------
    list of pathlib.Path
        The files written.
    """
    runs = comparison.runs
    grid = dict(left=0.07, right=0.98, top=0.9, bottom=0.08, hspace=0.35, wspace=0.3)
    path, zoom, contour, table = comparison_files(name)
    drawings = [
        (path, (10.0, 7.0), grid, lambda fig: plot_compared_paths(runs, fig)),
        (zoom, (10.0, 7.4), grid, lambda fig: plot_compared_zoom(runs, fig)),
        (contour, (9.0, 4.8), dict(left=0.09, right=0.78, top=0.92, bottom=0.11),
         lambda fig: plot_compared_contour_error(runs, fig.add_subplot())),
        (table, (9.5, 7.0), dict(left=0.08, right=0.8, top=0.94, bottom=0.07, hspace=0.35),
         lambda fig: plot_compared_figures(comparison.figures, fig)),
    ]  # fmt: skip
    return _draw(drawings, out_dir)
