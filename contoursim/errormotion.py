"""Error motions of a machine axis as functions of its position.

An axis moving along (or about) one direction deviates from its ideal motion
by six small error motions (ISO 230-1): three translations ``dx, dy, dz``
(positioning and two straightnesses) and three rotations ``ex, ey, ez`` (roll,
pitch, yaw for a linear axis; two tilts and the angular positioning error for
a rotary one). Each is a function of the axis position q: a sum of a
polynomial (constant, scale error, bow), cyclic terms (the periodic error of a
screw whose period is its lead) and a table measured by a laser run
(ISO 230-2), interpolated linearly.

Inside, q is in mm (linear axis) or rad (rotary axis) and the error motions
are in mm (translations) or rad (rotations).

The polynomial and cyclic coefficients are the *parameters* a fit can adjust:
each has a stable name (``p0``, ``p1``, ``cyclic0.sin`` ...), the error motion
is linear in them, and :meth:`ErrorMotion.basis` gives the derivative.
"""

import csv
import re
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from . import _validate
from .config import read_text, text_lines, unique_columns
from .exceptions import ConfigError

__all__ = ["COMPONENTS", "ERROR_COLUMNS", "ERROR_UNITS", "Cyclic", "ErrorMotion", "read_error_table"]

#: The six error motions, in the order of every (..., 6) error array.
COMPONENTS = ("dx", "dy", "dz", "ex", "ey", "ez")
_MM_PER_UM, _RAD_PER_URAD = 1e-3, 1e-6
#: Unit of each error motion in files (the suffix of its key or column) and its scale to mm or rad.
ERROR_UNITS = (("um", _MM_PER_UM),) * 3 + (("urad", _RAD_PER_URAD),) * 3

_TERM = re.compile(r"^(?:p(\d+)|cyclic(\d+)\.(sin|cos))$")


@dataclass(frozen=True)
class Cyclic:
    """A periodic error term ``s·sin(2πq/period) + c·cos(2πq/period)``.

    Parameters
    ----------
    period : float
        Period [mm] (the screw lead) or [rad] for a rotary axis.
    sin, cos : float
        Coefficients [mm] or [rad]. Amplitude A and phase φ of
        ``A·sin(2πq/period + φ)`` give ``sin = A cos φ``, ``cos = A sin φ``.
    """

    period: float
    sin: float = 0.0
    cos: float = 0.0

    def __post_init__(self):
        object.__setattr__(self, "period", _validate.positive("period", self.period))
        object.__setattr__(self, "sin", float(_validate.finite_array("sin", self.sin, ndim=0)))
        object.__setattr__(self, "cos", float(_validate.finite_array("cos", self.cos, ndim=0)))

    @classmethod
    def from_amplitude(cls, amplitude, period, phase=0.0):
        """The term ``amplitude·sin(2πq/period + phase)``; phase [rad]."""
        amplitude = float(_validate.finite_array("amplitude", amplitude, ndim=0))
        phase = float(_validate.finite_array("phase", phase, ndim=0))
        return cls(period, amplitude * np.cos(phase), amplitude * np.sin(phase))


@dataclass(frozen=True)
class ErrorMotion:
    """One error motion as a function of the axis position.

    Parameters
    ----------
    poly : tuple of float
        Polynomial coefficients in ascending powers of q: ``p0`` [mm or rad]
        (a constant), ``p1`` [mm/mm, rad/mm, ... per unit of q] (a scale error
        for a positioning error, a slope for a straightness), ...
    cyclic : tuple of Cyclic
        Periodic terms.
    table : tuple (positions, values), optional
        A measured table: positions, shape (M,), strictly increasing [mm or
        rad], and error values, shape (M,) [mm or rad]; interpolated linearly,
        held constant beyond its ends.
    """

    poly: tuple = ()
    cyclic: tuple = ()
    table: tuple = field(default=None)

    def __post_init__(self):
        poly = tuple(float(c) for c in _validate.finite_array("poly", self.poly, ndim=1))
        object.__setattr__(self, "poly", poly)
        cyclic = tuple(self.cyclic)
        if not all(isinstance(c, Cyclic) for c in cyclic):
            raise ValueError("cyclic must be a sequence of Cyclic terms")
        object.__setattr__(self, "cyclic", cyclic)
        if self.table is not None:
            try:
                pos, val = self.table
            except (TypeError, ValueError):
                raise ValueError("table must be a pair (positions, values)") from None
            pos = _validate.finite_array("table positions", pos, ndim=1)
            val = _validate.finite_array("table values", val, shape=(pos.size,))
            if pos.size < 2 or np.any(np.diff(pos) <= 0):
                raise ValueError("table positions must be at least 2 strictly increasing values")
            pos.flags.writeable = False
            val.flags.writeable = False
            object.__setattr__(self, "table", (pos, val))

    def __call__(self, q, out=None):
        """Error motion at positions `q`.

        Parameters
        ----------
        q : ndarray, shape (N,)
            Axis positions [mm] or [rad].
        out : ndarray, shape (N,), optional
            Where to write the result.

        Returns
        -------
        ndarray, shape (N,)
            The error motion [mm] or [rad].
        """
        q = np.ascontiguousarray(q, dtype=float)
        out = np.empty_like(q) if out is None else out
        out[...] = self.poly[-1] if self.poly else 0.0
        for c in self.poly[-2::-1]:  # Horner, in place
            out *= q
            out += c
        for term in self.cyclic:
            phase = (2 * np.pi / term.period) * q
            if term.sin:
                out += term.sin * np.sin(phase)
            if term.cos:
                out += term.cos * np.cos(phase)
        if self.table is not None:
            out += np.interp(q, *self.table)
        return out

    @property
    def is_zero(self):
        """True when the error motion is identically zero."""
        return (
            not any(self.poly)
            and not any(t.sin or t.cos for t in self.cyclic)
            and (self.table is None or not self.table[1].any())
        )

    def repeats_every(self, period):
        """True when the error motion repeats every `period` [mm or rad]: no polynomial term beyond the
        constant, no table (held beyond its ends, it never repeats) and every cyclic term's period a whole
        fraction of `period` (a rotary axis's error motions over a turn, 2π: its bearing's and encoder's)."""
        turns = [period / t.period for t in self.cyclic if t.sin or t.cos]
        return (
            not any(self.poly[1:])
            and (self.table is None or not self.table[1].any())
            and all(abs(n - round(n)) <= 1e-9 * n for n in turns)
        )

    def parameters(self):
        """The adjustable coefficients as ``{name: value}`` [mm or rad per unit of q^k]."""
        out = {f"p{k}": c for k, c in enumerate(self.poly)}
        for i, term in enumerate(self.cyclic):
            out[f"cyclic{i}.sin"] = term.sin
            out[f"cyclic{i}.cos"] = term.cos
        return out

    def basis(self, name, q):
        """Derivative of the error motion with respect to parameter `name`.

        Parameters
        ----------
        name : str
            ``p<k>`` (any k, present or not) or ``cyclic<i>.sin|cos`` (an
            existing cyclic term).
        q : ndarray, shape (N,)
            Axis positions [mm] or [rad].

        Returns
        -------
        ndarray, shape (N,)
        """
        k, i, kind = self._parse(name)
        q = np.asarray(q, dtype=float)
        if k is not None:
            return q**k
        phase = (2 * np.pi / self.cyclic[i].period) * q
        return np.sin(phase) if kind == "sin" else np.cos(phase)

    def with_parameter(self, name, value):
        """A copy with parameter `name` set to `value` (a missing ``p<k>`` is added)."""
        k, i, kind = self._parse(name)
        value = float(_validate.finite_array(name, value, ndim=0))
        if k is not None:
            poly = list(self.poly) + [0.0] * max(0, k + 1 - len(self.poly))
            poly[k] = value
            return replace(self, poly=tuple(poly))
        cyclic = list(self.cyclic)
        cyclic[i] = replace(cyclic[i], **{kind: value})
        return replace(self, cyclic=tuple(cyclic))

    def scaled(self, factor):
        """A copy with every term (table included) multiplied by `factor`."""
        factor = _validate.finite("factor", factor)
        table = None if self.table is None else (self.table[0], factor * self.table[1])
        return ErrorMotion(
            tuple(factor * c for c in self.poly),
            tuple(Cyclic(t.period, factor * t.sin, factor * t.cos) for t in self.cyclic),
            table,
        )

    def _parse(self, name):
        match = _TERM.match(name)
        if not match:
            raise ValueError(f"unknown error-motion parameter {name!r}; expected p<k> or cyclic<i>.sin/cos")
        if match.group(1) is not None:
            return int(match.group(1)), None, None
        i = int(match.group(2))
        if i >= len(self.cyclic):
            raise ValueError(f"{name!r}: there are only {len(self.cyclic)} cyclic term(s)")
        return None, i, match.group(3)


#: Error-table column -> (error motion, scale to mm or rad): ``dx_um`` ... ``ez_urad``.
ERROR_COLUMNS = {f"{comp}_{unit}": (comp, scale) for comp, (unit, scale) in zip(COMPONENTS, ERROR_UNITS)}


def read_error_table(path, rotary=False):
    """Read a laser-run error table (ISO 230-2 style) from a CSV file.

    Format: optional leading ``#`` lines, a header row with a
    ``position_mm`` column (``position_deg`` for a rotary axis) and one or
    more of the columns ``dx_um, dy_um, dz_um, ex_urad, ey_urad, ez_urad``,
    each named once; one numeric row per target position, positions
    strictly increasing.

    Parameters
    ----------
    path : str or Path
        The CSV file.
    rotary : bool
        The table belongs to a rotary axis (positions in degrees).

    Returns
    -------
    dict
        ``{component: (positions [mm or rad], values [mm or rad])}``.

    Raises
    ------
    ConfigError
        Naming the file, line and column of the problem (a column named
        twice, a header without an error column); a column of an earlier
        version (``position``, ``dx``) with the name that replaced it.
    """
    path = Path(path)
    source, rotary = str(path), _validate.flag("rotary", rotary)
    lines = text_lines(read_text(path))
    start = next((i for i, line in enumerate(lines) if line.strip() and not line.lstrip().startswith("#")), None)
    if start is None:
        raise ConfigError("the error table has no header row", source)
    for number, line in enumerate(lines[:start], start=1):
        key, colon, _ = line.lstrip()[1:].partition(":")
        if colon and key.strip().lower() in ("units", "unit"):  # read as a trace's would be: not ignored, refused
            raise ConfigError("an error table's units are its columns' (position_mm or position_deg, dx_um .. dz_um, "
                              "ex_urad .. ez_urad): a '# units:' line is not read; drop it, converting the columns to "
                              "those units", source, number)
    header = [h.strip() for h in next(csv.reader([lines[start]]))]
    unique_columns(header, source, start + 1)
    position = "position_deg" if rotary else "position_mm"
    renamed = {"position": position, **{comp: column for column, (comp, _) in ERROR_COLUMNS.items()}}
    old = [h for h in header if h in renamed]
    if old:
        raise ConfigError(f"column '{old[0]}' is now '{renamed[old[0]]}' (units in the column name): rename it", source, start + 1)
    unknown = [h for h in header if h != position and h not in ERROR_COLUMNS]
    if position not in header or unknown:
        raise ConfigError(
            f"the header must hold '{position}' and one or more of {', '.join(ERROR_COLUMNS)}; got {', '.join(header)}",
            source,
            start + 1,
        )
    if header == [position]:
        raise ConfigError(f"the error table has no error column, only '{position}': add one or more of "
                          f"{', '.join(ERROR_COLUMNS)}", source, start + 1)
    rows = []
    for number, row in enumerate(csv.reader(lines[start + 1 :]), start=start + 2):
        if not row or not "".join(row).strip():
            continue
        if len(row) != len(header):
            raise ConfigError(f"expected {len(header)} cells, got {len(row)}", source, number)
        odd = next((h for h, cell in zip(header, row) if "_" in cell or not cell.isascii()), None)
        if odd is not None:  # float() reads "1_000" and a full-width "１" as numbers
            cell = row[header.index(odd)]
            raise ConfigError(f"column '{odd}': {_validate.shown(repr(cell.strip()))} is not a number as a table writes one: "
                              "write it with the digits 0-9 and no '_'", source, number)
        try:
            values = [float(cell) for cell in row]
        except ValueError:
            col = next(h for h, cell in zip(header, row) if not _is_number(cell))
            raise ConfigError(f"column '{col}' is not a number", source, number) from None
        bad = [(h, cell) for h, cell, v in zip(header, row, values) if not np.isfinite(v)]
        if bad:
            column, cell = bad[0]
            spelled = any(word in cell.lower() for word in ("inf", "nan"))  # else written too large for a float (1e400)
            raise ConfigError(f"column '{column}' is not finite" if spelled else
                              f"column '{column}': {_validate.shown(cell.strip())} is too large a number: beyond "
                              f"±{_validate.FLOAT_MAX:.4g}", source, number)
        rows.append((number, values))
    if len(rows) < 2:
        raise ConfigError("the error table needs at least 2 rows", source)
    data = np.array([v for _, v in rows])
    pos = data[:, header.index(position)]
    step = np.diff(pos)
    if np.any(step <= 0):
        i = int(np.argmax(step <= 0)) + 1
        raise ConfigError("positions must be strictly increasing", source, rows[i][0])
    pos = np.deg2rad(pos) if rotary else pos
    return {ERROR_COLUMNS[h][0]: (pos, data[:, j] * ERROR_COLUMNS[h][1]) for j, h in enumerate(header) if h != position}


def _is_number(text):
    try:
        float(text)
    except ValueError:
        return False
    return True
