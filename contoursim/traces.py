"""Measured-trace CSV files: the contract outside tools read and write.

Format (DESIGN.md): optional leading ``#`` lines (free text or ``# key: value``
metadata), a header row, numeric rows. Required columns: ``t`` [s], strictly
increasing and uniform (to the decimals it is printed to: a 3 kHz clock printed
to the µs, steps of 333 and 334 µs, is read as the uniform grid it was rounded
from), and for each axis the pair ``<axis>_ref``, ``<axis>``
[mm] for the axis sets ``x``, ``x, y`` or ``x, y, z``. ``*_ref`` are the
commanded (interpolator) positions, the others the measured tool positions.
Optional measured inputs, per axis: ``<axis>_force`` [N], a known external
force on the axis (test pulses, a cutting force), and ``<axis>_current`` [A],
the measured motor current; read and checked like the positions. Other
columns are ignored on reading; one whose name is close to an input's
(``x_force_N``, ``X_current``, ``x_curent``) is said in a warning.

Values must be physically meaningful: positions within ±1e6 mm
(:data:`MAX_POSITION`, a kilometre, far beyond any machine's travel) and
times within ±1e9 s (:data:`MAX_TIME`, about 30 years), so that differences of
positions stay exact to the nm and never overflow; forces within ±1e9 N
(:data:`MAX_FORCE`) and currents within ±1e6 A (:data:`MAX_CURRENT`).

Units: a ``# units:`` line declares them column by column, as contoursim
writes it: ``# units: t [s]; x_ref, x, y_ref, y [mm]`` (groups separated by
``;``, each a list of columns and a unit in brackets; a bare unit, ``# units:
m``, is that of all the position columns; ``# Units:`` and ``# unit:`` too). The reader converts ``t`` from
:data:`TIME_UNITS` to s, positions from :data:`LENGTH_UNITS` to mm, forces
from :data:`FORCE_UNITS` to N and currents from :data:`CURRENT_UNITS` to A,
and refuses any other unit of a column it reads (the units of the header's other columns are not read), a
column the header does not have (a typo, a line of another trace), a column declared twice and a second
``# units:`` line (one of the two would be ignored).
Without a declared time unit, a sample period outside
:data:`PLAUSIBLE_SAMPLE_PERIOD` is refused as no servo trace's (a time column
in ms, µs or ns read as seconds): declaring ``t [s]`` accepts it. A measured
column that does not follow its reference (:data:`FOLLOWING_GAIN`: swapped
columns, a column in other units) is refused.
"""

import io
import math
import re
import warnings
from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np

from . import _validate
from .config import named_as, read_text, text_lines, unique_columns
from .exceptions import ContoursimWarning, TraceFormatError
from .output import writing

__all__ = ["Trace", "check_every", "read_trace", "write_trace"]

AXIS_SETS = (("x",), ("x", "y"), ("x", "y", "z"))
MAX_POSITION = 1e6  # [mm]: largest |position| in a trace
MAX_TIME = 1e9  # [s]: largest |t| in a trace
MAX_FORCE = 1e9  # [N]: largest |force| in a trace
MAX_CURRENT = 1e6  # [A]: largest |current| in a trace
TIME_UNITS = {"s": 1.0, "ms": 1e-3, "us": 1e-6, "µs": 1e-6, "ns": 1e-9}
"""Units of ``t`` a ``# units:`` line may declare, and their size [s]."""
LENGTH_UNITS = {"mm": 1.0, "m": 1e3, "um": 1e-3, "µm": 1e-3, "nm": 1e-6, "in": 25.4}
"""Units of the positions a ``# units:`` line may declare, and their size [mm]."""
FORCE_UNITS = {"N": 1.0, "kN": 1e3}
"""Units of the ``<axis>_force`` columns a ``# units:`` line may declare, and their size [N]."""
CURRENT_UNITS = {"A": 1.0, "mA": 1e-3}
"""Units of the ``<axis>_current`` columns a ``# units:`` line may declare, and their size [A]."""
INPUTS = {"force": (FORCE_UNITS, "N", MAX_FORCE), "current": (CURRENT_UNITS, "A", MAX_CURRENT)}
"""The optional measured inputs ``<axis>_<kind>``: kind -> (units, the unit read by default, the largest magnitude)."""
FOLLOWING_GAIN = (0.2, 5.0)
"""Range of the slope of each measured column regressed on its reference [mm/mm] the reader accepts: about 1 for
an axis that follows its command (less where it lags a fast motion), 0 for swapped columns of a circle, 1e-3 or
1e3 for a column in m or µm read as mm, -1 for a reversed sign. Axes whose reference moves less than 1 µm RMS
are not checked by it, but by :data:`STANDSTILL_MOTION`."""
STANDSTILL_MOTION = 0.1
"""Most an axis whose reference stands still (moves less than 1 µm RMS) may move [mm RMS]: hunting, a disturbance's
response or a drift move µm to tens of µm; a measured column that moves millimetres is not that axis's, or its
reference is not logged."""
FOLLOWING_SPAN = 0.5
"""A trace shorter than this [s] whose measured column hardly moves may have ended before the axis followed its
command (a lag of 1/Kp is 10-100 ms): its error says so beside the columns and units."""
PLAUSIBLE_SAMPLE_PERIOD = (1e-6, 1.0)
"""Sample periods [s] of a servo trace, from 1 MHz up to (not including) 1 Hz: outside, a time column without
a declared unit is refused."""


@dataclass(frozen=True, eq=False)
class Trace:
    """A trace: commanded and measured positions over time.

    Parameters
    ----------
    t : ndarray, shape (N,)
        Sample times [s], strictly increasing and uniform, within ±:data:`MAX_TIME`.
    reference : ndarray, shape (N, d)
        Commanded positions [mm], within ±:data:`MAX_POSITION`.
    actual : ndarray, shape (N, d)
        Measured tool positions [mm], within ±:data:`MAX_POSITION`.
    axes : tuple of str
        Axis names of the d columns: ``("x",)``, ``("x", "y")`` or ``("x", "y", "z")``.
    metadata : dict
        ``# key: value`` header lines.
    force : dict of str -> ndarray, shape (N,), optional
        A known external force on an axis [N] (positive pushing it towards
        positive positions), sampled at `t`, by axis name; axes not named
        have none.
    current : dict of str -> ndarray, shape (N,), optional
        The measured motor current of an axis [A], by axis name.
    """

    t: np.ndarray
    reference: np.ndarray
    actual: np.ndarray
    axes: tuple
    metadata: dict = field(default_factory=dict)
    force: dict = field(default_factory=dict)
    current: dict = field(default_factory=dict)

    def __post_init__(self):
        t, dt = _validate.time_base("t", _validate.finite_array("t", self.t, ndim=1, limit=MAX_TIME))
        try:
            axes = tuple(self.axes)
        except TypeError:
            raise TypeError(f"axes must be a sequence of axis names like ('x', 'y'), got {self.axes!r}") from None
        if axes not in AXIS_SETS:
            raise ValueError(f"axes must be one of {AXIS_SETS}, got {axes}")
        shape = (t.size, len(axes))
        reference = _validate.finite_array("reference", self.reference, shape=shape, limit=MAX_POSITION)
        actual = _validate.finite_array("actual", self.actual, shape=shape, limit=MAX_POSITION)
        for name, value in dict(t=t, reference=reference, actual=actual).items():
            object.__setattr__(self, name, _validate.read_only(value, getattr(self, name)))
        object.__setattr__(self, "axes", axes)
        object.__setattr__(self, "dt", dt)
        if not isinstance(self.metadata, Mapping):  # written as '# key: value' lines
            raise TypeError(f"metadata must map keys to values ({{'machine': 'mill 3'}}), got "
                            f"{type(self.metadata).__name__}")
        for kind, (_, unit, limit) in INPUTS.items():
            columns = {}
            if not isinstance(getattr(self, kind), Mapping):
                raise TypeError(f"{kind} must map axis names to arrays ({{'x': ...}}), got {type(getattr(self, kind)).__name__}")
            for axis, values in dict(getattr(self, kind)).items():
                if axis not in axes:
                    raise ValueError(f"{kind} names axis {axis!r}, which is not one of the trace's axes {', '.join(axes)}")
                checked = _validate.finite_array(f"{axis}_{kind}", values, shape=(t.size,), limit=limit)
                columns[axis] = _validate.read_only(checked, values)
            object.__setattr__(self, kind, columns)

    @property
    def tracking_error(self):
        """Actual minus commanded position [mm], shape (N, d)."""
        return self.actual - self.reference


TIME_DECIMALS = 9
"""Decimals of ``t`` in a written trace [s]: to the ns."""
POSITION_DECIMALS = 6
"""Decimals of positions (and other float columns) in a written trace [mm]: to the nm."""
_CHUNK = 1 << 14  # rows formatted at once: bounds the formatter's memory (its buffers, ~0.5 kB a row)


def check_every(every, size, dt):
    """`every` as a whole number, if writing every `every`-th of `size` samples `dt` apart makes a trace.

    Parameters
    ----------
    every : int
        Write every `every`-th sample.
    size : int
        The samples there are.
    dt : float
        Their period [s].

    Returns
    -------
    int

    Raises
    ------
    ValueError
        `every` is not a whole number >= 1, leaves fewer than 2 samples or
        samples further apart than :data:`PLAUSIBLE_SAMPLE_PERIOD` allows
        (:func:`read_trace` refuses such a trace).
    """
    every = _validate.positive_int("every", every)
    kept = -(-size // every)
    if kept < 2 or (every > 1 and every * dt >= PLAUSIBLE_SAMPLE_PERIOD[1]):
        below = min(size, math.ceil(PLAUSIBLE_SAMPLE_PERIOD[1] / dt))
        raise ValueError(f"every = {every} keeps {kept} of the {size} samples, one every {every * dt:.6g} s: a trace "
                         f"holds 2 or more, less than {PLAUSIBLE_SAMPLE_PERIOD[1]:g} s apart (read_trace refuses "
                         f"others); give every below {below}")
    return every


def write_trace(file, trace, extra=None, overwrite=False, every=1):
    """Write `trace` as CSV in the measured-trace format.

    Numbers are written in fixed point without trailing zeros: ``t`` to the
    ns (:data:`TIME_DECIMALS`), positions and float `extra` columns to the nm
    (:data:`POSITION_DECIMALS` decimals of a mm; the trace's forces and
    currents to as many decimals of a N, an A), integer and boolean `extra`
    columns as whole numbers (``1``/``0``). A value that rounds to zero is
    written ``0``, never ``-0`` or ``3.55e-12``.

    Parameters
    ----------
    file : str, Path or text file object
        Destination. A file is written atomically (see
        :func:`contoursim.output.atomic_write`); an existing one is only
        replaced when `overwrite` is true.
    trace : Trace
        What to write.
    extra : dict of str -> ndarray, shape (N,), optional
        Further columns (e.g. contour error [mm]); readers ignore them.
    overwrite : bool
        Replace an existing file.
    every : int
        Write every `every`-th sample, starting with the first (1: all); the
        time base stays uniform.

    Raises
    ------
    FileExistsError
        `file` exists and `overwrite` is false.
    ValueError
        `every` leaves fewer than 2 samples, or samples further apart than
        :data:`PLAUSIBLE_SAMPLE_PERIOD` allows; an extra column has the
        wrong shape, is not finite, is not a CSV
        column name or clashes with a trace column; a metadata entry is not
        one ``# key: value`` line; a value is too large to write to its
        resolution.
    """
    if not isinstance(trace, Trace):
        raise TypeError(f"trace must be a Trace (read_trace reads one; SimResult.save_csv writes a run), got "
                        f"{type(trace).__name__}")
    every = check_every(every, trace.t.size, trace.dt)
    columns = {"t": (trace.t, TIME_DECIMALS)}
    for i, axis in enumerate(trace.axes):
        columns[f"{axis}_ref"] = (trace.reference[:, i], POSITION_DECIMALS)
        columns[axis] = (trace.actual[:, i], POSITION_DECIMALS)
    for kind in INPUTS:
        columns.update((f"{axis}_{kind}", (values, POSITION_DECIMALS)) for axis, values in getattr(trace, kind).items())
    for key, value in trace.metadata.items():  # one '# key: value' line each, read back as written
        if not str(key).strip() or ":" in str(key) or re.search(r"[\r\n]", f"{key}{value}"):
            raise ValueError(f"metadata {key!r}: {value!r} is not one '# key: value' line (a key without ':', "
                             "no line breaks)")
    if extra is not None and not isinstance(extra, Mapping):
        raise TypeError(f"extra must map column names to arrays ({{'contour': ...}}), got {type(extra).__name__}")
    for name, values in (extra or {}).items():
        if name in columns:
            raise ValueError(f"extra column {name!r} clashes with a trace column")
        if name in _READ_COLUMNS:  # read back as the trace's own: another axis, a force, a current
            raise ValueError(f"extra column {name!r} is a column read_trace reads ({_READ_COLUMNS[name]}): the file "
                             "would read back as another trace; name it otherwise")
        if not isinstance(name, str) or name != name.strip() or not name or re.search(r'[,"#\r\n]', name):
            raise ValueError(f"extra column {name!r} is not a CSV column name (one without commas, quotes, '#', line "
                             "breaks or surrounding spaces)")
        values = np.asarray(values)
        whole = values.dtype.kind in "bui"
        if values.dtype.kind != "b":
            values = _validate.finite_array(name, values, shape=(trace.t.size,))
        elif values.shape != (trace.t.size,):  # booleans (written 1 and 0) are finite: no float copy to check
            raise ValueError(f"{name} must have shape ({trace.t.size},), got {values.shape}")
        columns[name] = (values, 0 if whole else POSITION_DECIMALS)
    for name, (values, decimals) in columns.items():
        largest = max(float(values.max()), -float(values.min()))  # |values|.max() without an (N,) temporary
        if largest * 10.0**decimals >= 2.0**53:
            raise ValueError(f"column {name!r}: {largest:g} is too large to write to 1e-{decimals}")
    metadata = dict(trace.metadata)
    for key in _units_keys(metadata):  # a trace read from a file with more columns: the units of those written
        metadata[key] = _units_written(str(metadata[key]), columns)  # (read_trace refuses a column the header lacks)
        _check_units_written(key, metadata[key], columns, trace)
    header = "".join(f"# {key}: {value}\n" for key, value in metadata.items()) + ",".join(columns) + "\n"
    values = [v[::every] for v, _ in columns.values()]
    decimals = [d for _, d in columns.values()]
    from ._fixedpoint import csv_rows  # numba, only when a trace is written

    with writing(file, overwrite=overwrite) as out:
        out.write(header)
        for start in range(0, values[0].size, _CHUNK):
            out.write(csv_rows([v[start : start + _CHUNK] for v in values], decimals).decode("ascii"))


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
        column (saying what the header holds), a non-numeric, non-finite or
        out-of-range cell (see :data:`MAX_POSITION`, :data:`MAX_TIME`), a row
        with more or fewer cells than the header, non-monotonic time or time
        non-uniform beyond the rounding of its printed decimals (within it,
        read as the uniform grid it was rounded from), text that is not UTF-8, a ``# units:`` line that cannot be read,
        names a column the header does not have or a column twice, or
        declares a unit the reader does not convert, a sample period
        outside :data:`PLAUSIBLE_SAMPLE_PERIOD` without a declared time unit,
        a measured column that does not follow its reference (:data:`FOLLOWING_GAIN`).
    """
    source = str(file)
    named_as(file, ".csv", "a measured trace (a CSV table)", TraceFormatError)
    lines = text_lines(read_text(file, TraceFormatError))  # a leading BOM (Excel) is dropped

    metadata = {}
    units_line = units_key = None
    first = 0
    while first < len(lines) and (lines[first].startswith("#") or not lines[first].strip()):
        key, colon, value = lines[first][1:].partition(":")
        key = key.strip()
        is_units = key.lower() in ("units", "unit")  # '# Units:', '# unit:' declare units too: honoured, never ignored
        if colon and is_units and units_line is not None:  # one of them would be ignored
            raise TraceFormatError(f"a second '# units:' line (the first is line {units_line}): declare the units once",
                                   source, first + 1)
        if colon and key:
            metadata["units" if is_units else key] = value.strip()
            units_line, units_key = (first + 1, key) if is_units else (units_line, units_key)
        first += 1
    if first == len(lines):
        raise TraceFormatError("no header row", source)
    # a name in double quotes is that name (R's write.csv quotes the header, not the numbers)
    names = [re.sub(r'^"(.*)"$', r"\1", name.strip()) for name in lines[first].split(",")]
    header_line = first + 1

    def fail(message, line=header_line):
        return TraceFormatError(message, source, line)

    unique_columns(names, source, header_line, TraceFormatError)

    axes = tuple(a for a in ("x", "y", "z") if a in names or f"{a}_ref" in names)
    if "t" not in names:
        raise fail(_header_problem(names))
    if axes not in AXIS_SETS:
        upper = [name for name in names if name != name.lower() and name.lower() in _POSITION_COLUMNS]
        if upper:  # 't' in lower case, the axes not: said as for a header without 't'
            raise fail(_header_problem(names))
        if not axes:  # 't,x_cmd,x_act,...': said as "the axes present (none) must be ..."
            raise fail(f"no axis columns in the header {','.join(names)!r}; expected x_ref, x (then y_ref, y, z_ref, "
                       "z): the commanded and the measured position of each axis [mm] (x_cmd, x_act: rename them)")
        raise fail(f"the axes present ({', '.join(axes)}) must be x, x+y or x+y+z")
    for axis in axes:
        for name in (f"{axis}_ref", axis):
            if name not in names:
                raise fail(f"missing column '{name}' in the header")
    stray = [f"{axis}_{kind}" for kind in INPUTS for axis in ("x", "y", "z") if f"{axis}_{kind}" in names and axis not in axes]
    if stray:
        raise fail(f"column {stray[0]!r} is an input of axis {stray[0][0]!r}, which the trace does not cover "
                   f"(no {stray[0][0]}_ref, {stray[0][0]} columns)")
    positions = [name for axis in axes for name in (f"{axis}_ref", axis)]
    inputs = {f"{axis}_{kind}": kind for kind in INPUTS for axis in axes if f"{axis}_{kind}" in names}
    wanted = ["t"] + positions + list(inputs)
    index = [names.index(name) for name in wanted]
    unread = [f"{axis}_{kind}" for kind in INPUTS for axis in axes if f"{axis}_{kind}" not in inputs]
    for name in names:  # an input's column under another name is not read: a known force lost without a word
        near = _validate.closest(name.lower(), unread) if name not in wanted else ""
        if near:
            warnings.warn(f"{source}, line {header_line}: column {name!r} is not read{near}: a known force is read "
                          "from '<axis>_force', a measured current from '<axis>_current' (their units on a '# units:' "
                          "line)", ContoursimWarning, stacklevel=2)
    units = {} if units_line is None else _declared_units(metadata["units"], units_key, names, wanted, inputs,
                                                          lambda msg: fail(msg, units_line))
    if units_line is not None:  # the trace holds s, mm, N, A: its metadata says so, and a trace written back reads the same
        metadata["units"] = _units_as_read(metadata["units"], positions, inputs)
    default = {"t": "s", **dict.fromkeys(positions, "mm"), **{name: INPUTS[kind][1] for name, kind in inputs.items()}}
    written = [units.get(name, default[name]) for name in wanted]  # the units of the cells
    scale = np.array([TIME_UNITS[written[0]]] + [LENGTH_UNITS[u] for u in written[1 : 1 + len(positions)]]
                     + [INPUTS[kind][0][u] for kind, u in zip(inputs.values(), written[1 + len(positions) :])])

    body = lines[header_line:]
    while body and not body[-1].strip():
        body = body[:-1]
    if len(body) < 2:
        raise fail(f"needs at least 2 data rows, found {len(body)}")
    limits = np.array([MAX_TIME] + [MAX_POSITION] * len(positions) + [INPUTS[kind][2] for kind in inputs.values()])
    data = _parse_rows(body, len(names), index, names, limits / scale, written, lambda msg, row: fail(msg, header_line + 1 + row))
    if (scale != 1.0).any():
        data *= scale
    try:
        _, dt = _validate.time_base("column 't'", data[:, 0])
    except _validate.TimeStepError as exc:  # step k ends on data row k + 1
        grid = _validate.rounded_grid(data[:, 0], scale[0] * _printed_unit(body, index[0]))
        if grid is None:
            raise fail(str(exc), header_line + 2 + exc.step) from None
        data[:, 0], dt = grid  # a 3 kHz clock printed to the µs (steps of 333 and 334 µs): read as its grid
    low, high = PLAUSIBLE_SAMPLE_PERIOD
    if "t" not in units and not low <= dt < high:
        raise fail(f"column 't': a sample every {dt:.6g} s ({1 / dt:.6g} Hz) is no servo trace's (from {1 / high:g} Hz "
                   f"to {1e-6 / low:g} MHz): is the time column in ms, µs or ns? Declare its unit on a line "
                   "'# units: t [ms]' before the header ('t [s]' if seconds are right)")
    for i, axis in enumerate(axes):
        gain = _following_gain(data[:, 1 + 2 * i], data[:, 2 + 2 * i])
        moved = float(np.std(data[:, 2 + 2 * i]))
        if gain is None and moved > STANDSTILL_MOTION:
            raise fail(f"column {axis!r}: the measured {axis} moves {moved:.3g} mm RMS while {axis}_ref stands still "
                       f"(a servo axis at standstill moves µm): columns swapped, units wrong or {axis}_ref not "
                       "logged?")
        if gain is not None and not FOLLOWING_GAIN[0] <= gain <= FOLLOWING_GAIN[1]:
            gain = gain if abs(gain) >= 1e-3 else 0.0  # not -3.8e-18 for a swapped circle
            duration = data[-1, 0] - data[0, 0]
            why = ("columns swapped or units wrong?" if abs(gain) >= FOLLOWING_GAIN[0] or duration >= FOLLOWING_SPAN else
                   f"the trace lasts {duration:.3g} s, maybe too short for the axis to have started to follow "
                   "(a longer trace tells), or columns swapped or units wrong")
            raise fail(f"column {axis!r}: the measured {axis} does not follow {axis}_ref: it moves {gain:.3g} mm per mm of "
                       f"{axis}_ref (a servo axis following its command moves about 1): {why}")
    measured = {kind: {} for kind in INPUTS}
    for column, name in enumerate(inputs, start=1 + len(positions)):
        measured[inputs[name]][name.partition("_")[0]] = data[:, column]
    d = len(axes)
    return Trace(data[:, 0], data[:, 1 : 1 + 2 * d : 2], data[:, 2 : 2 + 2 * d : 2], axes, metadata, **measured)


def _following_gain(reference, actual):
    """The slope of `actual` regressed on `reference` [mm/mm]: about 1 for an axis that follows (None if its reference
    stands still)."""
    motion = reference - reference.mean()
    spread = float(motion @ motion)
    if spread <= (1e-3) ** 2 * reference.size:  # moves less than 1 µm RMS: nothing to tell
        return None
    return float(motion @ (actual - actual.mean())) / spread


_GROUP = re.compile(r"(?P<columns>[^\[\]]*?)\s*\[(?P<unit>[^\[\]]*)\]")  # one group of a units line: "x_ref, x [mm]"


def _declared_units(text, key, names, wanted, inputs, fail):
    """The units a ``# units:`` line declares for the columns `wanted` (a dict: column -> unit; others left out).

    `key` is the line's key as written (``units``, ``Units``), `names` the header's columns, `wanted` those
    read; `inputs` maps the measured-input columns among `wanted` to their kind (a key of :data:`INPUTS`); a
    bare unit is the positions'. `fail` makes the error of a line that cannot be read, names a column the
    header does not have or a column twice (one of the two would be ignored; in the same unit too, as a second
    ``# units:`` line is refused), or declares a unit the reader does not convert.
    """
    declared, lacking, bare = {}, [], ()
    text = text.replace("\u03bc", "\u00b5")  # the Greek letter mu, as keyboards give it, for the micro sign
    if not text.strip(" ;"):  # a units line is honoured or refused, never passed over
        raise fail(f"'# {key}:' declares no unit: write them as contoursim does, '# units: t [s]; x_ref, x [mm]', "
                   "or drop the line")
    for group in filter(None, (g.strip() for g in text.split(";"))):
        match = _GROUP.fullmatch(group)
        columns = [] if match is None else [c.strip() for c in match["columns"].split(",")]
        if match is None and group in LENGTH_UNITS:  # a bare unit: all the positions'
            columns = bare = [name for name in wanted[1:] if name not in inputs]
            unit = group
        elif match is None or not all(columns):  # "[mm]", "x_ref,, x [mm]": a unit of no column
            raise fail(f"the units {group!r} cannot be read: write them as contoursim does, "
                       "'# units: t [s]; x_ref, x [mm]' (columns, then the unit in brackets)")
        else:
            unit = match["unit"].strip()
            lacking += [name for name in columns if name not in names]  # a typo ('yy'), another trace's line
        for name in columns:
            if name in declared:
                first = declared[name]
                twice = f"in {first!r} and in {unit!r}" if first != unit else f"in {unit!r} both times"
                aside = " (a bare unit is that of all the position columns)" if name in bare else ""
                raise fail(f"'# {key}:' declares column {name!r} twice, {twice}{aside}: declare each column's unit "
                           "once")
            declared[name] = unit
    if lacking:
        raise fail(f"'# {key}:' names column{'s' * (len(lacking) > 1)} {', '.join(map(repr, lacking))}, which the "
                   f"trace does not have (its columns: {', '.join(names)})")
    units = {name: unit for name, unit in declared.items() if name in wanted}
    for name, unit in units.items():
        if name in inputs:
            known, read = INPUTS[inputs[name]][0], f"the {inputs[name]} columns are"
        else:
            known = TIME_UNITS if name == "t" else LENGTH_UNITS
            read = "column 't' is" if name == "t" else "the position columns are"
        if unit not in known:
            raise fail(f"column {name!r} is declared in {unit!r}; {read} read in {', '.join(known)}")
    return units


def _units_as_read(text, positions, inputs):
    """The ``# units:`` line of a trace as read: its columns in s, mm, N and A, the groups of columns not read as declared."""
    read = {"t", *positions, *inputs}
    groups = [f"t [s]; {', '.join(positions)} [mm]"]
    for kind, (_, unit, _) in INPUTS.items():
        names = [name for name, k in inputs.items() if k == kind]
        if names:
            groups.append(f"{', '.join(names)} [{unit}]")
    for group in filter(None, (g.strip() for g in text.split(";"))):
        match = _GROUP.fullmatch(group)
        others = [] if match is None else [c.strip() for c in match["columns"].split(",") if c.strip() not in read]
        if others:
            groups.append(f"{', '.join(others)} [{match['unit'].strip()}]")
    return "; ".join(groups)


def _units_keys(metadata):
    """The keys of `metadata` that :func:`read_trace` reads as its ``# units:`` line (``units``, ``Units``, ``unit``),
    checked to be one: a second such line is refused by the reader."""
    keys = [key for key in metadata if str(key).strip().lower() in ("units", "unit")]
    if len(keys) > 1:
        raise ValueError(f"metadata {keys[0]!r} and {keys[1]!r} are both a '# units:' line: read_trace refuses a "
                         "second; give one")
    return keys


def _check_units_written(key, text, columns, trace):
    """Refuse a units line `text` (metadata `key`) that declares a written column of `trace` in other units than it
    holds (s, mm, N, A): the file would be read converted, 1000 times off for ``t [ms]``."""
    inputs = {f"{axis}_{kind}": kind for kind in INPUTS for axis in getattr(trace, kind)}
    wanted = [name for name in columns if name in ("t", *_POSITION_COLUMNS) or name in inputs]

    def fail(message):
        return ValueError(f"metadata {key!r}: {message}")

    units = _declared_units(text, str(key).strip(), list(columns), wanted, inputs, fail)
    for name, unit in units.items():
        size = (INPUTS[inputs[name]][0] if name in inputs else TIME_UNITS if name == "t" else LENGTH_UNITS)[unit]
        if size != 1:
            held = INPUTS[inputs[name]][1] if name in inputs else "s" if name == "t" else "mm"
            raise fail(f"declares column {name!r} in {unit!r}, but the trace holds it in {held}, as it is written: "
                       f"read_trace would scale it by {size:g}; declare [{held}] or leave the line out")


def _units_written(text, columns):
    """The ``# units:`` line `text` for a file of `columns`: its groups' other columns left out (and groups left
    empty)."""
    groups = []
    for group in filter(None, (g.strip() for g in text.split(";"))):
        match = _GROUP.fullmatch(group)
        kept = None if match is None else [c.strip() for c in match["columns"].split(",") if c.strip() in columns]
        if kept is None:  # a bare unit, or what the reader refuses as it is
            groups.append(group)
        elif kept:
            groups.append(f"{', '.join(kept)} [{match['unit'].strip()}]")
    return "; ".join(groups)


_POSITION_COLUMNS = ("x_ref", "x", "y_ref", "y", "z_ref", "z")
#: Every column :func:`read_trace` reads, but ``t``, and what it is: no extra column of :func:`write_trace` may be one.
_READ_COLUMNS = {
    **{f"{axis}_ref": f"axis {axis}'s reference" for axis in "xyz"},
    **{axis: f"axis {axis}'s measured position" for axis in "xyz"},
    **{f"{axis}_{kind}": f"a measured {kind} of axis {axis}" for kind in INPUTS for axis in "xyz"},
}


def _header_problem(names):
    """What is wrong with a header that has no column 't', or no axis in lower case, saying what was found and what is
    expected."""
    expected = "expected comma-separated column names t, x_ref, x (then y_ref, y, z_ref, z), in lower case"
    found = ",".join(names)
    for separator, label in ((";", "semicolons"), ("\t", "tabs")):
        if separator in found:
            return f"the header {found!r} is separated by {label}; {expected}"
    if any(name.lower() in ("t", *_POSITION_COLUMNS) and name != name.lower() for name in names):
        upper = [name for name in names if name != name.lower()]
        return f"column names are case-sensitive: the header has {', '.join(map(repr, upper))}; {expected}"
    return f"missing column 't' in the header {found!r}; {expected}"


_DIGITS = re.compile(r"[^.eE]*(?:\.(\d*))?(?:[eE]([-+]?\d+))?")  # a number's fraction digits and exponent


def _printed_unit(body, col):
    """The unit of the last decimal that column `col` of the rows `body` is printed to, its finest cell's (``0.000333``
    and ``3.33e-4``: 1e-6); 0 or infinite past a float's range (no unit :func:`_validate.rounded_grid` takes)."""
    cells = (_DIGITS.match(row.split(",", col + 1)[col].strip()) for row in body)
    return float(f"1e{min(int(match[2] or 0) - len(match[1] or '') for match in cells)}")


_WHOLE = re.compile(r"\s*[-+]?\d+\s*")  # a cell a decimal comma leaves of a number: its whole or its fraction digits


def _parse_rows(body, width, index, names, limits, units, fail):
    """Parse the numeric rows; on any problem, name the first bad cell.

    `limits` are the largest magnitudes allowed in the columns `index`, in
    their `units` (the names of the file's units, for the messages).
    """
    def beyond(row, col):
        """The error of the cell (`row`, `col`), shown as written, that is beyond its column's limit."""
        cell = body[row].split(",")[index[col]].strip()
        hint = ("; is the time column in ns (declare it: '# units: t [ns]') or a clock's (seconds since 1970: write "
                "the time since the log's start)?") if col == 0 and units[0] == "s" else ""
        what = next((kind for kind, (known, _, _) in INPUTS.items() if units[col] in known), "position or time")
        return fail(f"column '{names[index[col]]}': value {_validate.shown(cell)} is beyond ±{limits[col]:g} "
                    f"{units[col]}, not a {what} a trace can hold{hint}", row)

    cells = np.array([text.count(",") + 1 for text in body])
    if np.any(cells != width):
        row = int(np.argmax(cells != width))
        if not body[row].strip():
            raise fail(f"a blank line among the data rows: expected {width} cells (as in the header)", row)
        if body[row].lstrip().startswith("#"):  # a log's closing "# end of log"
            raise fail("a comment among the data rows: comment lines ('# ...') come before the header", row)
        if cells[row] > width and all(_WHOLE.fullmatch(cell) for cell in body[row].split(",")):
            raise fail(f"expected {width} cells (as in the header), found {cells[row]}, all whole numbers: decimal "
                       "commas? the decimal separator is a point ('0.25'), the cells are separated by commas", row)
        if cells[row] > width and re.search(r'"[^",]*,[^",]*"', body[row]):  # "0,0002": a comma inside quotes
            raise fail(f"expected {width} cells (as in the header), found {cells[row]} counting the commas inside "
                       "quotes: decimal commas in quoted cells? the decimal separator is a point ('0.25'), the cells "
                       "are separated by commas (quotes are not needed)", row)
        raise fail(f"expected {width} cells (as in the header), found {cells[row]}", row)
    try:
        data = np.loadtxt(io.StringIO("\n".join(body)), delimiter=",", ndmin=2, usecols=index)
    except ValueError:
        data = None
    if data is None or data.shape[0] != len(body):
        for row, text in enumerate(body):
            cells = text.split(",")
            for col in index:
                cell = cells[col]
                try:  # as numpy's parser reads numbers: no digit separators (1_000), no digits but ASCII ones
                    if "_" in cell or not cell.isascii():
                        raise ValueError(cell)
                    float(cell)
                except ValueError:
                    raise fail(f"column '{names[col]}': {cell.strip()!r} is not a number", row) from None
        raise fail("the data rows could not be parsed", 0)
    bad = ~np.isfinite(data)
    if bad.any():
        row, col = np.unravel_index(np.argmax(bad), data.shape)
        cell = body[row].split(",")[index[col]].strip()
        if re.search("inf|nan", cell, re.IGNORECASE):
            raise fail(f"column '{names[index[col]]}': value {data[row, col]} is not finite", row)
        raise beyond(row, col)  # a number written too large for a float (1e400): infinite once read
    bad = np.abs(data) > limits
    if bad.any():
        row, col = np.unravel_index(np.argmax(bad), data.shape)
        raise beyond(row, col)
    return data
