"""Measured-trace CSV files: the contract outside tools read and write.

Format (DESIGN.md): optional leading ``#`` lines (free text or ``# key: value``
metadata), a header row, numeric rows. Required columns: ``t`` [s], strictly
increasing and uniform, and for each axis the pair ``<axis>_ref``, ``<axis>``
[mm] for the axis sets ``x``, ``x, y`` or ``x, y, z``. ``*_ref`` are the
commanded (interpolator) positions, the others the measured tool positions.
Extra columns are ignored on reading.

:func:`output_dir` prepares the folder such files are written into.
"""

import io as _io
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from . import _validate
from .exceptions import ConfigError, TraceFormatError

__all__ = ["Trace", "output_dir", "read_trace", "write_trace"]

AXIS_SETS = (("x",), ("x", "y"), ("x", "y", "z"))
_MARKER = ".contoursim-out"


@dataclass(frozen=True)
class Trace:
    """A trace: commanded and measured positions over time.

    Parameters
    ----------
    t : ndarray, shape (N,)
        Sample times [s], strictly increasing and uniform.
    reference : ndarray, shape (N, d)
        Commanded positions [mm].
    actual : ndarray, shape (N, d)
        Measured tool positions [mm].
    axes : tuple of str
        Axis names of the d columns: ``("x",)``, ``("x", "y")`` or ``("x", "y", "z")``.
    metadata : dict
        ``# key: value`` header lines.
    """

    t: np.ndarray
    reference: np.ndarray
    actual: np.ndarray
    axes: tuple
    metadata: dict = field(default_factory=dict)

    def __post_init__(self):
        t, dt = _validate.time_base("t", self.t)
        axes = tuple(self.axes)
        if axes not in AXIS_SETS:
            raise ValueError(f"axes must be one of {AXIS_SETS}, got {axes}")
        shape = (t.size, len(axes))
        object.__setattr__(self, "t", t)
        object.__setattr__(self, "axes", axes)
        object.__setattr__(self, "reference", _validate.finite_array("reference", self.reference, shape=shape))
        object.__setattr__(self, "actual", _validate.finite_array("actual", self.actual, shape=shape))
        object.__setattr__(self, "dt", dt)

    @property
    def tracking_error(self):
        """Actual minus commanded position [mm], shape (N, d)."""
        return self.actual - self.reference


def output_dir(out):
    """Create or reuse the output folder `out`; refuse a non-empty folder contoursim did not make.

    A marker file records that contoursim made the folder, so a later run may
    replace its files there; a folder holding anything else is never written
    into, so nothing a user keeps there is overwritten.

    Parameters
    ----------
    out : str or Path
        The folder; created with its parents if missing.

    Returns
    -------
    Path
        `out`, existing and marked.

    Raises
    ------
    ConfigError
        `out` holds files and no marker.
    """
    out = Path(out)
    if out.exists() and any(out.iterdir()) and not (out / _MARKER).exists():
        raise ConfigError(f"{out} holds files that contoursim did not write; choose another output directory")
    out.mkdir(parents=True, exist_ok=True)
    (out / _MARKER).write_text("written by contoursim; its files here are replaced on each run\n")
    return out


def write_trace(file, trace, extra=None, overwrite=False):
    """Write `trace` as CSV in the measured-trace format.

    Parameters
    ----------
    file : str or Path
        Destination. An existing file is only replaced when `overwrite` is true.
    trace : Trace
        What to write.
    extra : dict of str -> ndarray, shape (N,), optional
        Further columns (e.g. contour error); readers ignore them.
    overwrite : bool
        Replace an existing file.
    """
    file = Path(file)
    if file.exists() and not overwrite:
        raise FileExistsError(f"{file} exists; refusing to overwrite it")
    columns = {"t": trace.t}
    for i, axis in enumerate(trace.axes):
        columns[f"{axis}_ref"] = trace.reference[:, i]
        columns[axis] = trace.actual[:, i]
    for name, values in (extra or {}).items():
        if name in columns:
            raise ValueError(f"extra column {name!r} clashes with a trace column")
        columns[name] = _validate.finite_array(name, values, shape=(trace.t.size,))
    header = "".join(f"# {key}: {value}\n" for key, value in trace.metadata.items())
    with open(file, "w", encoding="utf-8", newline="") as out:
        out.write(header)
        np.savetxt(out, np.column_stack(list(columns.values())), delimiter=",", fmt="%.12g",
                   header=",".join(columns), comments="")


def read_trace(file):
    """Read a measured-trace CSV file.

    Parameters
    ----------
    file : str or Path
        The CSV file.

    Returns
    -------
    Trace

    Raises
    ------
    TraceFormatError
        Naming the file, line and column of the first problem: a missing
        column, a non-numeric or non-finite cell, a ragged row, non-monotonic
        or non-uniform time.
    """
    source = str(file)
    try:
        lines = Path(file).read_text(encoding="utf-8").splitlines()
    except OSError as exc:
        raise TraceFormatError(f"cannot read the file: {exc.strerror}", source) from None
    except UnicodeDecodeError:
        raise TraceFormatError("not a text file", source) from None

    metadata = {}
    first = 0
    while first < len(lines) and (lines[first].startswith("#") or not lines[first].strip()):
        key, colon, value = lines[first][1:].partition(":")
        if colon and key.strip():
            metadata[key.strip()] = value.strip()
        first += 1
    if first == len(lines):
        raise TraceFormatError("no header row", source)
    names = [name.strip() for name in lines[first].split(",")]
    header_line = first + 1

    def fail(message, line=header_line):
        return TraceFormatError(message, source, line)

    axes = tuple(a for a in ("x", "y", "z") if a in names or f"{a}_ref" in names)
    if "t" not in names:
        raise fail("missing column 't' in the header")
    if axes not in AXIS_SETS:
        raise fail(f"the axes present ({', '.join(axes) or 'none'}) must be x, x+y or x+y+z")
    for axis in axes:
        for name in (f"{axis}_ref", axis):
            if name not in names:
                raise fail(f"missing column '{name}' in the header")
    wanted = ["t"] + [name for axis in axes for name in (f"{axis}_ref", axis)]
    index = [names.index(name) for name in wanted]

    body = lines[header_line:]
    data = _parse_rows(body, len(names), index, names, lambda msg, row: fail(msg, header_line + 1 + row))
    if data.shape[0] < 2:
        raise fail("needs at least 2 data rows", header_line)
    t = data[:, 0]
    step = np.diff(t)
    if np.any(step <= 0):
        row = int(np.argmax(step <= 0)) + 1
        raise fail(f"column 't': time must be strictly increasing ({t[row]} after {t[row - 1]})",
                   header_line + 1 + row)
    try:
        _validate.time_base("t", t)
    except ValueError as exc:
        raise fail(f"column 't': {exc}", header_line + 1) from None
    return Trace(t, data[:, 1::2], data[:, 2::2], axes, metadata)


def _parse_rows(body, width, index, names, fail):
    """Parse the numeric rows; on any problem, name the first bad cell."""
    while body and not body[-1].strip():
        body = body[:-1]
    try:
        data = np.loadtxt(_io.StringIO("\n".join(body)), delimiter=",", ndmin=2, usecols=index)
    except ValueError:
        data = None
    if data is None or data.shape[0] != len(body):
        for row, text in enumerate(body):
            cells = text.split(",")
            if len(cells) != width:
                raise fail(f"expected {width} cells, found {len(cells)}", row)
            for col in index:
                try:
                    float(cells[col])
                except ValueError:
                    raise fail(f"column '{names[col]}': {cells[col].strip()!r} is not a number", row) from None
        raise fail("the data rows could not be parsed", 0)
    bad = ~np.isfinite(data)
    if bad.any():
        row, col = np.unravel_index(np.argmax(bad), data.shape)
        raise fail(f"column '{names[index[col]]}': value {data[row, col]} is not finite", row)
    return data
