"""A reader for the G-code subset that describes contours: G0/G1/G2/G3 with F.

Supported words: ``G0 G1 G2 G3`` (modal motion), ``G17 G18 G19`` (arc plane
XY, ZX, YZ), ``G90 G91`` (absolute / incremental X Y Z), ``G21`` (mm; ``G20``
is rejected), ``X Y Z``, arc centre ``I J K`` (always relative to the arc's
start) or radius ``R`` (negative for the arc over 180°), ``F`` (feed, mm/min,
modal), ``N`` (line numbers), ``M2``/``M30`` (program end: the rest is
ignored). Comments ``( ... )`` and ``; ...`` and ``%`` lines are skipped.
An arc with a move along the plane's normal axis is a helix.

Rapid moves: G0 moves before the first feed move (G1/G2/G3) only position
the tool: the path starts where the first feed move starts. G0 moves after
it are kept as straight segments with role "rapid", travelled at
`rapid_feed`; the joins around them are sharp corners, so the planner stops
there. G0 moves after the last feed move (the retract) are dropped.
Zero-length moves are skipped.

Arcs whose start and end radii (about the programmed centre) differ by less
than `arc_tolerance` are accepted, the centre moved onto the perpendicular
bisector of the chord so that the arc passes through both points exactly.
"""

import os
import re
from dataclasses import dataclass
from pathlib import Path as _FilePath

import numpy as np

from . import _validate
from .exceptions import ConfigError, PathError
from .paths import Line, Path, _arc_from_point

__all__ = ["Program", "read_gcode"]

_WORD = re.compile(r"([A-Za-z])\s*([-+]?(?:\d+\.?\d*|\.\d+))")
_PLANES = {17: 2, 18: 1, 19: 0}  # G code -> index of the normal axis (Z, Y, X)


@dataclass(frozen=True)
class Program:
    """A G-code program read as a path.

    Parameters
    ----------
    path : contoursim.paths.Path
        One primitive per kept move.
    feeds : ndarray, shape (K,)
        Feed rate of each primitive [mm/s] (rapid feed for G0 segments).
    lines : ndarray of int, shape (K,)
        Source line of each primitive (1-based).
    source : str
        File name, or "<gcode>" for text.
    """

    path: Path
    feeds: np.ndarray
    lines: np.ndarray
    source: str = "<gcode>"

    def __post_init__(self):
        k = len(self.path.primitives)
        feeds = _validate.finite_array("feeds", self.feeds, shape=(k,))
        lines = np.asarray(self.lines, dtype=int)
        if lines.shape != (k,):
            raise ValueError(f"lines must have shape ({k},), got {lines.shape}")
        for name, value in dict(feeds=feeds, lines=lines).items():
            value.flags.writeable = False
            object.__setattr__(self, name, value)


def _text_and_source(file_or_text):
    if isinstance(file_or_text, os.PathLike) or (isinstance(file_or_text, str) and "\n" not in file_or_text):
        file = _FilePath(file_or_text)
        try:
            return file.read_text(), str(file)
        except OSError as exc:
            raise ConfigError(f"cannot read the G-code file: {exc.strerror}", source=str(file)) from None
    if not isinstance(file_or_text, str):
        raise TypeError(f"file_or_text must be a file name or G-code text, got {type(file_or_text).__name__}")
    return file_or_text, "<gcode>"


def _words(raw, fail):
    """Upper-case (letter, value) pairs of one line, comments removed."""
    text = re.sub(r"\([^)]*\)", " ", raw.split(";")[0])
    if "(" in text or ")" in text:
        fail("unbalanced parenthesis in a comment")
    words, pos = [], 0
    for match in _WORD.finditer(text):
        if text[pos:match.start()].strip():
            fail(f"cannot read {text[pos:match.start()].strip()!r}")
        words.append((match.group(1).upper(), float(match.group(2))))
        pos = match.end()
    if text[pos:].strip():
        fail(f"cannot read {text[pos:].strip()!r}")
    return words


def read_gcode(file_or_text, *, rapid_feed=10000.0 / 60.0, start=(0.0, 0.0, 0.0), arc_tolerance=2e-3):
    """Read a G-code program (subset described in the module docstring) as a path with block feeds.

    Parameters
    ----------
    file_or_text : str or os.PathLike
        A file name, or the program text itself (a string with a newline).
    rapid_feed : float
        Feed for G0 segments kept in the path [mm/s].
    start : array_like, shape (3,)
        Tool position before the first block [mm].
    arc_tolerance : float
        Largest difference between an arc's start and end radius [mm].

    Returns
    -------
    Program
        The path (dimension 2 if it stays in the XY plane at Z = 0), the feed
        of each primitive [mm/s] and its source line.

    Raises
    ------
    ConfigError
        Naming the file and line: unknown or repeated word, inch units, arc
        radii that disagree, missing F before the first feed move, ...
    """
    text, source = _text_and_source(file_or_text)
    rapid_feed = _validate.positive("rapid_feed", rapid_feed)
    arc_tolerance = _validate.positive("arc_tolerance", arc_tolerance)
    here = _validate.finite_array("start", start, shape=(3,))
    motion, plane, absolute, feed, cutting = None, 2, True, None, False
    prims, feeds, lines = [], [], []

    for number, raw in enumerate(text.splitlines(), 1):
        def fail(message):
            raise ConfigError(message, source=source, line=number)

        if raw.strip().startswith("%"):
            continue
        words = _words(raw, fail)
        values, gcodes = {}, []
        for letter, value in words:
            if letter == "G":
                gcodes.append(value)
            elif letter in "XYZIJKRFNM":
                if letter in values:
                    fail(f"word {letter} appears twice in one block")
                values[letter] = value
            else:
                fail(f"unknown word {letter}{value:g} (supported: G0-G3, G17-G19, G21, G90, G91, "
                     "X Y Z I J K R F N, M2, M30)")
        if "M" in values:
            if values["M"] not in (2, 30):
                fail(f"unknown word M{values['M']:g} (only M2 and M30, program end, are supported)")
            break
        for g in gcodes:
            if g in (0, 1, 2, 3):
                motion = int(g)
            elif g in _PLANES:
                plane = _PLANES[int(g)]
            elif g in (90, 91):
                absolute = g == 90
            elif g == 20:
                fail("inch programs are not supported (G20): convert to mm and use G21")
            elif g != 21:
                fail(f"unknown word G{g:g} (supported: G0-G3, G17-G19, G21, G90, G91)")
        if "F" in values:
            if values["F"] <= 0:
                fail(f"F must be positive, got {values['F']:g}")
            feed = values["F"] / 60.0
        axes = [a for a in "XYZ" if a in values]
        arc_words = [a for a in "IJKR" if a in values]
        if not axes and not arc_words:
            continue
        if motion is None:
            fail("a move needs a motion mode first (G0, G1, G2 or G3)")
        if arc_words and motion in (0, 1):
            fail(f"{'/'.join(arc_words)} only belong to arc moves (G2/G3)")
        target = here.copy()
        for i, a in enumerate("XYZ"):
            if a in values:
                target[i] = values[a] if absolute else here[i] + values[a]
        if motion > 0 and feed is None:
            fail("missing F before the first feed move")
        if motion == 0 and not cutting:
            here = target
            continue
        try:
            if motion in (0, 1):
                if np.linalg.norm(target - here) > 1e-9:
                    prims.append(Line(here, target, "rapid" if motion == 0 else "path"))
            else:
                prims.append(_arc(here, target, values, plane, motion == 3, arc_tolerance, fail))
        except PathError as exc:
            fail(str(exc))
        if len(prims) > len(feeds):
            feeds.append(rapid_feed if motion == 0 else feed)
            lines.append(number)
            cutting = cutting or motion > 0
        here = target

    if not cutting:
        raise ConfigError("the program has no feed move (G1, G2 or G3)", source=source)
    while prims[-1].role == "rapid":
        prims.pop(), feeds.pop(), lines.pop()
    return Program(Path(tuple(prims)), np.array(feeds), np.array(lines), source)


def _arc(start, end, values, normal_axis, ccw, tolerance, fail):
    """Arc (or helix) from start to end, from I/J/K or R, in the plane normal to axis `normal_axis`."""
    axis = np.eye(3)[normal_axis]
    inplane = np.ones(3)
    inplane[normal_axis] = 0.0
    chord = (end - start) * inplane
    if "R" in values:
        if any(a in values for a in "IJK"):
            fail("give either R or I/J/K, not both")
        r = values["R"]
        half = np.linalg.norm(chord) / 2
        if half < 1e-9:
            fail("a full circle cannot be given with R: use I/J/K")
        if abs(r) < half - tolerance:
            fail(f"arc radius R{r:g} is smaller than half the chord ({half:.6g} mm)")
        height = np.sqrt(max(r * r - half * half, 0.0))
        left = np.cross(axis, chord / (2 * half))
        center = start + chord / 2 + (1 if ccw else -1) * np.sign(r) * height * left
    else:
        offset = np.array([values.get(a, 0.0) for a in "IJK"]) * inplane
        center = start + offset
        r_start = np.linalg.norm(offset)
        r_end = np.linalg.norm((end - center) * inplane)
        if abs(r_start - r_end) > tolerance:
            fail(f"arc start radius {r_start:.6g} mm and end radius {r_end:.6g} mm differ by more than "
                 f"{tolerance:g} mm")
        length = np.linalg.norm(chord)
        if length > 1e-9:  # centre onto the chord's bisector: the arc then ends exactly at `end`
            across = np.cross(axis, chord / length)
            center = start + chord / 2 + ((center - start - chord / 2) @ across) * across
    a = (start - center) * inplane
    b = (end - center) * inplane
    turn = np.arctan2(np.cross(a, b) @ axis, a @ b)
    sweep = turn % (2 * np.pi) if ccw else -((-turn) % (2 * np.pi))
    if abs(sweep) < 1e-12:
        sweep = 2 * np.pi if ccw else -2 * np.pi
    rise = ((end - start) @ axis) / abs(sweep)
    return _arc_from_point(center, start, axis, sweep, rise)
