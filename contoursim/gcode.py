"""A reader for G-code contouring programs: the moves G0/G1/G2/G3 with F, and what a controller accepts around them.

Words that shape the path: ``G0 G1 G2 G3`` (modal motion), ``G17 G18 G19``
(arc plane XY, ZX, YZ), ``G90 G91`` (absolute / incremental X Y Z), ``X Y Z``,
arc centre ``I J K`` (always relative to the arc's start) or radius ``R``
(negative for the arc over 180°), ``F`` (feed, mm/min, modal, set by any
block, within the planner's range: 6e-5 to 6e13 mm/min), ``M2``/``M30`` (program end: a move in its block runs, the rest is
ignored). An arc with a move along the plane's normal axis is a helix.

The modes the model assumes are accepted: ``G21`` (mm), ``G94`` (feed per
minute), ``G40`` and ``G49`` (no cutter or tool length compensation), ``G80``
(no canned cycle), ``G91.1`` (arc centres relative to the arc's start, as
Mach3-style posts write it; ``G90.1``, absolute centres, is refused). Accepted and ignored, because they move no axis of the
contour: ``%`` lines (a ``%`` after the first block ends the program, as on
Fanuc and LinuxCNC: nothing after it runs), comments ``( ... )`` (a ``;`` inside one is part of the
comment) and ``; ...`` (to the end of the line), sequence numbers
``N``, program numbers ``O``, spindle speed ``S``, tool ``T`` with its offsets
``D``/``H``, M codes other than the program end and the stops (spindle ``M3 M4 M5``, coolant
``M7 M8 M9`` ...; the optional stop ``M1`` is run through, as with its switch off), ``G43`` (tool length
compensation: the path is the tool tip's), work offsets ``G54``-``G59`` (the
path's origin is the work offset), path modes ``G61 G64`` (with LinuxCNC's
``G64 P`` tolerance; the planner's own corner rule applies). The dwell ``G4``
and the tool change ``M6`` stop the motion at the end of the move before
them, which waits there in position as at the end of a rapid
(:attr:`Program.stops`); a move in their block follows. The program stop
``M0`` and the pallet change ``M60`` stop it at the end of the move of their
block (of the move before, in a block without one), as controllers run them.
A dwell's ``P``/``X`` time (milliseconds or seconds, by dialect; ``X`` only
without ``P``), the wait for the operator and the tool change are not moves
and are not simulated: once in position the axes hold it. Home returns and
machine-coordinate moves (``G28 G30 G53``, e.g. a post's ``G28 G91 Z0``
before a tool change) stop the motion at the end of the move before them
and take the axes they name (``G28`` and ``G30`` without axis words: all) to
a machine position contoursim does not know in work coordinates: the tool is
taken to stay where it was (before the first move,
the program's start), and the G0 moves that follow position it from there
(rapids, not scored); a feed move while an axis is still at such a position
is refused (also before the first feed move: a program's
``G28 G91 Z0`` before it cuts would cut at the home height). A block that starts with the
block-delete mark ``/`` (Fanuc's ``/1``–``/9`` too) runs, as with the
controller's block-delete switch off: the program as written, all of it
(the lines are named in a warning). What was ignored (all but ``N``) is
listed in :attr:`Program.ignored` and in one
:class:`~contoursim.exceptions.ContoursimWarning`, grouped by why: path modes
(the planner's corner rule decides the stops), tool length and work offsets
(the path is the tool tip's from the work offset), no contour motion. Refused with a message
naming file and line: inch units (``G20``), cutter radius compensation
(``G41 G42``), feed per revolution or inverse time (``G93 G95``), subprogram
calls (``M98 M99``), canned cycles (``G73``–``G89``, ``G98 G99``: by the cycle's code, not by
its ``Q`` or ``R`` word), a centre word off the arc's plane (``K`` in ``G17``, ``J`` in
``G18``, ``I`` in ``G19``), two words of one modal group in a block (``G2 G3``, ``G17 G19``, ``G90 G91``:
controllers differ on which wins), any other word.

Rapid moves: G0 moves before the first feed move (G1/G2/G3) only position
the tool: the path starts where the first feed move starts. G0 moves after
it are kept as straight segments with role "rapid", travelled at
`rapid_feed` (at most a machine's max feed); the joins around them are sharp corners, so the planner stops
there. G0 moves after the last feed move (the retract) are dropped.
Zero-length moves are skipped (a program whose feed moves all are is refused, said so); a position beyond
±1e6 mm, written or reached by incremental words, is refused at its block.

Arcs whose start and end radii (about the programmed centre) differ by less
than `arc_tolerance` are accepted, the centre moved onto the perpendicular
bisector of the chord so that the arc passes through both points exactly.
An arc over 180° whose radii differ is cut at its middle instead: the first
half about the programmed centre, the second tangent to it through the end
point. (The bisector lies |r_start² - r_end²| / (2 chord) from the programmed
centre: near a full turn the chord is short and that circle strays far from
the programmed one, 6.5 mm for a 359.99° arc of R 10 ending 1 µm off its
radius; the two halves stay within the radii's difference of it, as the
spiral a controller interpolates between the two radii does.)

The dialect is that of Fanuc, LinuxCNC, GRBL and the posts written for
them (Fusion 360, OpenBuilds ...): :data:`DIALECT` says it in a line, and
:data:`SUFFIXES` lists the file name endings read as G-code.

Files are read as UTF-8 (a byte-order mark is dropped) or, failing that, as
Latin-1, so a comment written on an older controller or editor reads too.
"""

import csv
import os
import re
import warnings
from dataclasses import dataclass
from pathlib import Path as _FilePath

import numpy as np

from . import _validate
from .config import read_bytes, text_lines, text_only
from .exceptions import ConfigError, ContoursimWarning, PathError
from .feed import SETTING_RANGE
from .paths import MAX_COORDINATE, Line, Path, _arc_from_point
from .simulation import SimResult

__all__ = ["BLOCK_COLUMNS", "DIALECT", "SUFFIXES", "BlockErrors", "Program", "block_errors", "read_gcode"]

#: The columns of a program's per-block table (:meth:`BlockErrors.save_csv`, ``NAME_blocks.csv`` beside a run's trace).
BLOCK_COLUMNS = ("line", "rapid", "feed_mm_min", "contour_max_um", "tracking_max_um", "block")

_WORD = re.compile(r"([A-Za-z])\s*([-+]?(?:\d+\.?\d*|\.\d+))", re.ASCII)  # 0-9 only: \d and float() take "１"
_EXPONENT = re.compile(r"[eE][-+]?\d+", re.ASCII)  # right after a number: its exponent
_LARGEST = 1e9  # largest |number| in a word [mm, mm/min, s]: a km-long axis is 1e6 mm
_PLANES = {17: 2, 18: 1, 19: 0}  # G code -> index of the normal axis (Z, Y, X)
_PLANE_NAMES = {2: "G17 (XY)", 1: "G18 (ZX)", 0: "G19 (YZ)"}  # normal axis -> the plane's code and name
_MODEL_G = (21, 40, 49, 80, 91.1, 94)  # mm, no cutter/tool length compensation, no canned cycle, I/J/K relative, F/min
_IGNORED_G = {43: "G43", 54: "G54", 55: "G55", 56: "G56", 57: "G57", 58: "G58", 59: "G59",
              61: "G61", 64: "G64"}
_MACHINE_MOVES = (28, 30, 53)  # home returns, machine coordinates: ignored outside the contour
_REFUSED_G = {20: "inch programs are not supported (G20): convert to mm and use G21",
              90.1: "absolute arc centres (G90.1) are not supported: program I/J/K relative to the arc's start (G91.1)",
              41: "cutter radius compensation (G41) is not supported: program the tool-centre path with G40",
              42: "cutter radius compensation (G42) is not supported: program the tool-centre path with G40",
              93: "inverse-time feed (G93) is not supported: program F in mm/min (G94)",
              95: "feed per revolution (G95) is not supported: program F in mm/min (G94)",
              **{g: f"canned cycles (G{g}: a cycle or its return level) are not supported: write the cycle's moves "
                    "out as G0/G1 blocks" for g in (73, 74, 76, 81, 82, 83, 84, 85, 86, 87, 88, 89, 98, 99)}}
_O_WORD = r"(end)?(sub|if|while|repeat)\b|call\b|else(if)?\b|do\b|return\b|break\b|continue\b"  # after o100
_STOPS_BEFORE = (6,)  # tool change: the motion stops before the move of its block, as at a dwell
_STOPS_AFTER = (0, 60)  # program stop, pallet change and stop: after the move of its block
_IGNORED_LETTERS = "ONSTDH"  # program and sequence numbers, spindle, tool and its offsets
#: File name endings read as G-code (lower case).
SUFFIXES = (".nc", ".ngc", ".gcode", ".tap", ".cnc", ".mpf", ".iso", ".eia")
#: The assumptions :func:`read_gcode` makes, in one line (the command line prints it with a G-code file's table).
DIALECT = ("Fanuc/LinuxCNC/GRBL mill dialect: mm (G21), feed per minute (G94), absolute unless G91, arc centres "
           "I/J/K relative to the arc's start, comments ( ) and ;, G28/G30/G53 positioning outside the contour, "
           "block delete / off (its blocks run), a coordinate without a decimal point in mm (X100 is 100 mm, which a "
           "Fanuc without decimal point input reads as 0.1 mm)")
_BLOCK_DELETE = re.compile(r"^\s*/[1-9]?")  # optional-block skip, with Fanuc's level
_COMMENT = re.compile(r"\([^)]*\)|;.*")  # the leftmost first: a ( ) comment may hold a ;, a ; comment a ( or )
_SUPPORTED = ("G0-G3, G4, G17-G19, G21, G28, G30, G40, G43, G49, G53-G59, G61, G64, G80, G90, G91, G91.1, G94, "
              "X Y Z I J K R F, O N S T D H, M codes but M98/M99")


@dataclass(frozen=True)
class Program:
    """A G-code program read as a path.

    Parameters
    ----------
    path : contoursim.paths.Path
        One primitive per kept move (two for an arc cut at its middle, see
        :func:`read_gcode`).
    feeds : ndarray, shape (K,)
        Feed rate of each primitive [mm/s] (rapid feed for G0 segments).
    lines : ndarray of int, shape (K,)
        Source line of each primitive (1-based).
    texts : tuple of str
        The source text of each primitive's block (its line, stripped).
    source : str
        File name, or "<gcode>" for text.
    ignored : tuple of str
        The words ignored (``"S12000"``, ``"M3"``, ``"G54"``, ``"G64 P0.01"``
        ...), each once, in the order they first appear.
    stops : tuple of int
        The primitives after which the program dwells (G4), stops (M0, M60),
        changes the tool (M6) or moves home (G28, G30, G53): the motion stops
        at their end (:class:`contoursim.feed.FeedSettings`).
    """

    path: Path
    feeds: np.ndarray
    lines: np.ndarray
    texts: tuple
    source: str = "<gcode>"
    ignored: tuple = ()
    stops: tuple = ()

    def __post_init__(self):
        k = len(self.path.primitives)
        feeds = _validate.finite_array("feeds", self.feeds, shape=(k,))
        lines = np.asarray(self.lines, dtype=int)
        if lines.shape != (k,):
            raise ValueError(f"lines must have shape ({k},), got {lines.shape}")
        if len(self.texts) != k or not all(isinstance(text, str) for text in self.texts):
            raise ValueError(f"texts must be {k} strings, got {self.texts!r}")
        object.__setattr__(self, "texts", tuple(self.texts))
        for name, value in dict(feeds=feeds, lines=lines).items():
            value.flags.writeable = False
            object.__setattr__(self, name, value)


def _text_and_source(file_or_text):
    if isinstance(file_or_text, os.PathLike) or (isinstance(file_or_text, str) and "\n" not in file_or_text):
        file = _FilePath(file_or_text)
        raw = read_bytes(file)
        if raw.startswith((b"\xff\xfe", b"\xfe\xff")):  # UTF-16's byte-order marks: Latin-1 would read it as words
            raise ConfigError("the file is UTF-16 text (by its byte-order mark): save it as UTF-8", str(file), 1)
        try:
            text = raw.decode("utf-8-sig")
        except UnicodeDecodeError:  # an older controller's program (a degree sign in a comment)
            text = raw.decode("latin-1")
        return text_only(text, file), str(file)
    if not isinstance(file_or_text, str):
        raise TypeError(f"file_or_text must be a file name or G-code text, got {type(file_or_text).__name__}")
    return file_or_text.removeprefix("\ufeff"), "<gcode>"


def _words(raw, fail):
    """Upper-case (letter, value) pairs of one line, comments removed."""
    text = _COMMENT.sub(" ", raw)
    if "(" in text or ")" in text:
        fail("unbalanced parenthesis in a comment")

    def unread(rest):
        rest = rest.strip()
        hint = (": a decimal comma? write the number with a point" if rest.startswith(",") else
                ": LinuxCNC's o-word subroutines and control flow (o100 sub, call, if, while) are not supported: write "
                "the moves out in one program" if re.match(_O_WORD, rest, re.IGNORECASE) else
                ": macro variables and expressions (# [ ]) are not supported: write the numbers out"
                if any(c in rest for c in "#[") else
                ": a digit other than 0-9 (a full-width one?): write the number in ASCII digits"
                if any(c.isdigit() and not c.isascii() for c in rest) else
                ": a space inside a number (X 1 0)? write the number without one" if rest[:1].isdigit() else "")
        fail(f"cannot read {rest!r}{hint}")

    words, pos = [], 0
    for match in _WORD.finditer(text):
        if text[pos:match.start()].strip():
            unread(text[pos:match.start()])
        exponent = _EXPONENT.match(text, match.end())
        if exponent:  # 1e-12 would read as the number 1 and a word E-12
            fail(f"{match.group(0).strip()}{exponent.group(0)}: a number in exponent notation is not G-code; write it "
                 "in decimals")
        value = float(match.group(2))
        if not abs(value) <= _LARGEST:  # 400 digits are inf, 300 overflow an arc's geometry
            fail(f"{match.group(1)}{match.group(2)[:10]}...: the number is beyond ±{_LARGEST:g}")
        words.append((match.group(1).upper(), value))
        pos = match.end()
    if text[pos:].strip():
        unread(text[pos:])
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
        of each primitive [mm/s], its source line and text, and the ignored words.

    Raises
    ------
    ConfigError
        Naming the file and line: unknown or repeated word, inch units, arc
        without its centre or with radii that disagree, missing F before the
        first feed move, a feed move from a machine position (G28/G30/G53), ...

    Warns
    -----
    ContoursimWarning
        Listing, in one line, the words that move no axis and were ignored;
        and, in another, the lines marked for block delete (``/``), which run.
    """
    text, source = _text_and_source(file_or_text)
    rapid_feed = _validate.positive("rapid_feed", rapid_feed)
    arc_tolerance = _validate.positive("arc_tolerance", arc_tolerance)
    here = _validate.finite_array("start", start, shape=(3,))
    motion, plane, absolute, feed, cutting, fed = None, 2, True, None, False, False  # fed: a feed move read, if of no length
    prims, feeds, lines, texts, ignored, stops, optional = [], [], [], [], {}, {}, []
    away = {}  # axis -> line of the G28/G30/G53 that took it to a machine position, after the first feed move

    ended = False  # M2/M30: the program ends after its block
    started = False  # a block was read: a '%' line now ends the tape
    rows = text_lines(text)
    for number, raw in enumerate(rows, 1):
        if ended:  # a controller reads nothing after it: said, if a block follows
            after = [k for k, rest in enumerate(rows[number - 1:], number) if rest.strip()[:1] not in ("", "(", ";", "%")]
            if after:
                warnings.warn(f"{source}: the program ends on line {number - 1}: the {len(after)} line(s) after it "
                              f"(from line {after[0]}) are not run, as on a controller", ContoursimWarning, stacklevel=2)
            break

        def fail(message):
            raise ConfigError(message, source=source, line=number)

        if raw.strip().startswith("%"):  # the tape's start; after a block, its end: as M30, nothing after it runs
            ended = started
            continue
        mark = _BLOCK_DELETE.match(raw)
        if mark:
            optional.append(number)
        words = _words(raw[mark.end():] if mark else raw, fail)
        started = started or bool(words)
        values, gcodes, mcodes, unknown = {}, [], [], []
        for letter, value in words:
            if letter == "G":
                gcodes.append(value)
            elif letter == "M":
                mcodes.append(value)
            elif letter in "XYZIJKRFP" + _IGNORED_LETTERS:
                if letter in values:
                    fail(f"word {letter} appears twice in one block")
                if letter in "XYZIJKR" and abs(value) > MAX_COORDINATE:
                    fail(f"{letter}{value:g} is beyond ±{MAX_COORDINATE:g} mm, not a position a machine reaches")
                values[letter] = value
            else:  # said after the block's G and M codes: a cycle's Q word is the cycle's (G83) to refuse
                unknown.append(f"{letter}{value:g}")
        for letter in _IGNORED_LETTERS:
            if letter in values and letter != "N":
                ignored.setdefault(f"{letter}{values.pop(letter):g}", None)
        values.pop("N", None)
        for m in mcodes:
            if m in (98, 99):
                fail(f"subprogram calls (M{m:g}) are not supported: write the moves out in one program")
            if m not in (2, 30, *_STOPS_BEFORE, *_STOPS_AFTER):
                ignored.setdefault(f"M{m:g}", None)
        ended = any(m in (2, 30) for m in mcodes)  # a move in its block runs first, as on Fanuc and LinuxCNC
        for group in ((0, 1, 2, 3), tuple(_PLANES), (90, 91)):  # a modal group twice: Fanuc takes the last, others refuse
            twice = [f"G{g:g}" for g in gcodes if g in group]
            if len(twice) > 1:
                fail(f"{' and '.join(twice)} in one block belong to one modal group (controllers differ: Fanuc takes the "
                     "last, LinuxCNC and GRBL refuse the block): keep the one meant")
        nonmodal = None  # G4, G28, G30, G53: this block moves no axis of the contour
        for g in gcodes:
            if g in (0, 1, 2, 3):
                motion = int(g)
            elif g in _PLANES:
                plane = _PLANES[int(g)]
            elif g in (90, 91):
                absolute = g == 90
            elif g in _MODEL_G:
                pass
            elif g in _REFUSED_G:
                fail(_REFUSED_G[g])
            elif g == 4:
                nonmodal = g
            elif g in _IGNORED_G or g in _MACHINE_MOVES:
                tolerance = f" P{values['P']:g}" if g == 64 and "P" in values else ""  # a blend tolerance, not kept
                ignored.setdefault(_IGNORED_G.get(g, f"G{g:g}") + tolerance, None)
                nonmodal = g if g in _MACHINE_MOVES else nonmodal
            else:
                fail(f"unknown word G{g:g} (supported: {_SUPPORTED})")
        if unknown:
            fail(f"unknown word {unknown[0]} (supported: {_SUPPORTED})")
        if "F" in values:  # the feed is set first, in any block
            low, high = (60.0 * limit for limit in SETTING_RANGE)  # [mm/min]
            if not low <= values["F"] <= high:
                fail(f"F{values['F']:g} must lie within [{low:g}, {high:g}] mm/min")
            feed = values["F"] / 60.0
        if nonmodal == 4:  # the dwell: its time is P, or X (Fanuc) when there is no P; a move in its block follows it
            time = "P" if "P" in values else "X"
            if values.get(time, 0.0) < 0:
                fail(f"a dwell's time (G4 P or X) must be zero or positive, got {values[time]:g}")
            values.pop(time, None)
        halt_after = any(m in _STOPS_AFTER for m in mcodes)  # after the move of its block, if it has one
        moves = nonmodal in (None, 4) and any(a in values for a in "XYZIJKR")  # a move along the contour
        if cutting and (nonmodal is not None or any(m in _STOPS_BEFORE for m in mcodes) or halt_after and not moves):
            stops[len(prims) - 1] = None  # the motion stops at the end of the last move (a rapid's end already)
        if nonmodal not in (None, 4):
            moved = [a for a in "XYZ" if a in values] or (list("XYZ") if nonmodal in (28, 30) else [])
            away.update(dict.fromkeys(moved, number))
            continue
        if "P" in values and 64 not in gcodes:
            if motion in (2, 3) and moves:
                fail(f"P{values['P']:g} on an arc (LinuxCNC: its number of turns) is not supported: write each turn "
                     "as an arc of its own")
            fail("P belongs to a dwell (G4)")
        axes = [a for a in "XYZ" if a in values]
        arc_words = [a for a in "IJKR" if a in values]
        if not axes and not arc_words:
            continue
        if motion is None:
            fail("a move needs a motion mode first (G0, G1, G2 or G3)")
        if arc_words and motion in (0, 1):
            fail(f"{'/'.join(arc_words)} {'belongs' if len(arc_words) == 1 else 'belong'} to arc moves (G2/G3) only")
        target = here.copy()
        for i, a in enumerate("XYZ"):
            if a in values:
                target[i] = values[a] if absolute else here[i] + values[a]
                if abs(target[i]) > MAX_COORDINATE:  # incremental words (G91) adding up beyond what a machine reaches
                    fail(f"G91 {a}{values[a]:g} takes {a} to {target[i]:g} mm, beyond ±{MAX_COORDINATE:g} mm")
        if motion > 0 and feed is None:
            fail("missing F before the first feed move")
        if motion > 0 and away:
            axis, at = next(iter(away.items()))
            fail(f"a feed move from a machine position is not supported: line {at} (G28/G30/G53) took {axis} "
                 f"there; position {axis} with G0 first")
        for a in axes if absolute else ():  # an incremental move from an unknown position stays unknown
            away.pop(a, None)
        if motion == 0 and not cutting:
            here = target
            continue
        fed = fed or motion > 0
        try:
            if motion in (0, 1):
                if np.linalg.norm(target - here) > 1e-9:
                    prims.append(Line(here, target, "rapid" if motion == 0 else "path"))
            else:
                prims += _arc(here, target, values, plane, motion == 3, arc_tolerance, fail)
        except PathError as exc:
            fail(str(exc))
        if len(prims) > len(feeds):  # one primitive a block, two for an arc cut at its middle
            added = len(prims) - len(feeds)
            feeds += [rapid_feed if motion == 0 else feed] * added
            lines += [number] * added
            texts += [raw.strip()] * added
            cutting = cutting or motion > 0
        if halt_after and cutting:  # at the end of its move (of the last, if of no length)
            stops[len(prims) - 1] = None
        here = target

    if not cutting:
        raise ConfigError("the program's feed moves (G1, G2 or G3) all have zero length" if fed else
                          "the program has no feed move (G1, G2 or G3)", source=source)
    while prims[-1].role == "rapid":
        prims.pop(), feeds.pop(), lines.pop(), texts.pop()
    stops = tuple(k for k in stops if k < len(prims) - 1)  # the path's end is a stop of its own
    if ignored:
        warnings.warn(f"{source}: ignored: {_ignored_text(ignored)}", ContoursimWarning, stacklevel=2)
    if optional:
        shown = ", ".join(map(str, optional[:10])) + (f" … ({len(optional)} in all)" if len(optional) > 10 else "")
        warnings.warn(f"{source}: block delete (/) on line{'s' if len(optional) > 1 else ''} {shown}: run, as with the "
                      "switch off", ContoursimWarning, stacklevel=2)
    return Program(Path(tuple(prims)), np.array(feeds), np.array(lines), tuple(texts), source, tuple(ignored), stops)


def _ignored_text(ignored):
    """The words a program's reading ignored, grouped by why the path is as if they were not there."""
    why = {"mode": "path modes: the planner's corner_tolerance_deg decides where the motion stops",
           "frame": "tool length and work offsets: the path is the tool tip's, from the work offset",
           "switch": "optional stop: run through, as with its switch off",
           "other": "no contour motion"}
    groups = {kind: [] for kind in why}
    for word in ignored:
        head = word.split()[0]
        groups["mode" if head in ("G61", "G64") else "frame" if head in ("G43", *(f"G{g}" for g in range(54, 60)))
               else "switch" if head == "M1" else "other"].append(word)
    return "; ".join(f"{_listed(words)} ({why[kind]})" for kind, words in groups.items() if words)


def _listed(words, most=3):
    """`words` in one line, a letter that takes a value a block (``S``, ``T`` ...) at its first `most` values and
    counted: a program setting the spindle speed in every block warned in one line of 131 KB."""
    alike = {}
    for word in words:
        alike.setdefault(word[0] if word[0] in _IGNORED_LETTERS else word, []).append(word)
    return " ".join(" ".join(same[:most]) + (f" … ({len(same)} {same[0][0]} words)" if len(same) > most else "")
                    for same in alike.values())


@dataclass(frozen=True)
class BlockErrors:
    """The largest contour and tracking error of each block of a G-code program, worst blocks first.

    Cutting blocks (G1/G2/G3) come first, by largest contour error, then
    tracking error; then the rapids (G0), in the same order. A block shorter
    than a servo period may hold no sample: its errors are NaN and it comes
    last among its kind.

    Parameters
    ----------
    line : ndarray of int, shape (K,)
        Source line of each block (1-based).
    text : tuple of str
        Source text of each block.
    rapid : ndarray of bool, shape (K,)
        True for a rapid (G0).
    feed : ndarray, shape (K,)
        Programmed feed [mm/s] (the rapid feed for a rapid).
    contour_max : ndarray, shape (K,)
        Largest contour error over the block's samples [mm].
    tracking_max : ndarray, shape (K,)
        Largest tracking error over the block's samples [mm].
    """

    line: np.ndarray
    text: tuple
    rapid: np.ndarray
    feed: np.ndarray
    contour_max: np.ndarray
    tracking_max: np.ndarray

    def table(self, top=5):
        """The `top` worst cutting blocks as a text table: line, largest contour and tracking error [µm] ("-" for none), text.

        Parameters
        ----------
        top : int
            Number of blocks shown.

        Returns
        -------
        str
        """
        top = _validate.positive_int("top", top)
        um = lambda value: f"{'-':>14}" if np.isnan(value) else f"{1e3 * value:>14.2f}"  # noqa: E731
        rows = [f"{self.line[k]:>6}{um(self.contour_max[k])}{um(self.tracking_max[k])}  {self.text[k]}"
                for k in np.flatnonzero(~self.rapid)[:top]]
        return "\n".join([f"{'line':>6}{'contour max':>14}{'tracking max':>14}  block", *rows])

    def save_csv(self, stream):
        """Write every block that moves as CSV: ``line, rapid, feed_mm_min, contour_max_um, tracking_max_um, block``.

        Zero-length moves are skipped when the program is read: they have no row.

        Errors to the nm (3 decimals of a µm), empty for a block without a
        sample; ``rapid`` is 1 for a G0 block; ``block`` is the source text.

        Parameters
        ----------
        stream : text file object
            Open for writing, with ``newline=""``.
        """
        um = lambda value: "" if np.isnan(value) else f"{1e3 * value:.3f}"  # noqa: E731
        writer = csv.writer(stream, lineterminator="\n")
        writer.writerow(BLOCK_COLUMNS)
        for row in zip(self.line, self.rapid, self.feed, self.contour_max, self.tracking_max, self.text):
            line, rapid, feed, contour, tracking, text = row
            writer.writerow([line, int(rapid), f"{60 * feed:g}", um(contour), um(tracking), text])


def block_errors(program, result):
    """The largest contour and tracking error of each block of `program` in a simulation of it.

    A block's samples are those whose reference lies on its move
    (:attr:`contoursim.trajectory.Trajectory.primitive`: a stop at a
    junction belongs to the block that ends there); the standstill appended
    after the program's end (neither measuring nor rapid) is left out.

    Parameters
    ----------
    program : Program
        The program simulated.
    result : contoursim.simulation.SimResult
        A simulation of ``program.path``, with its contour error.

    Returns
    -------
    BlockErrors
        Worst blocks first.

    Raises
    ------
    TypeError
        `program` is not a :class:`Program`, or `result` not a simulation result.
    ValueError
        `result` is not a simulation of the program's path, or has no contour error.
    """
    if not isinstance(program, Program):
        raise TypeError(f"program must be a Program (read_gcode), got {type(program).__name__}")
    if not isinstance(result, SimResult):
        raise TypeError(f"result must be a SimResult (simulate), got {type(result).__name__}")
    trajectory = result.trajectory
    if trajectory.path is not program.path or result.contour is None:
        raise ValueError("result must be a simulation of the program's path, with its contour error")
    keep = trajectory.measuring | trajectory.rapid
    lines, first, of_primitive = np.unique(program.lines, return_index=True, return_inverse=True)  # a block a line
    block = of_primitive[trajectory.primitive[keep]]
    worst = {}
    for name, error in (("contour", result.contour.magnitude[keep]),
                        ("tracking", np.linalg.norm(result.tool_position[keep] - trajectory.position[keep], axis=1))):
        worst[name] = np.full(lines.size, np.nan)
        np.fmax.at(worst[name], block, error)
    rapid = (np.array(program.path.roles) == "rapid")[first]
    order = np.lexsort((-np.nan_to_num(worst["tracking"], nan=-1.0), -np.nan_to_num(worst["contour"], nan=-1.0), rapid))
    return BlockErrors(lines[order], tuple(program.texts[first[k]] for k in order), rapid[order],
                       program.feeds[first][order], worst["contour"][order], worst["tracking"][order])


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
        centre = [a for a, i in zip("IJK", inplane) if i]
        offplane = "IJK"[normal_axis]
        if offplane in values:  # LinuxCNC refuses it too; read as 0 the arc would not be the one meant
            fail(f"{offplane} is not a centre word of the {_PLANE_NAMES[normal_axis]} arc: give {'/'.join(centre)} "
                 "(a helix's rise is the end point's move along the plane's normal)")
        if not any(a in values for a in centre):
            fail(f"the arc centre is missing: give {'/'.join(centre)} (relative to the arc's start) or R")
        offset = np.array([values.get(a, 0.0) for a in "IJK"]) * inplane
        center = start + offset
        r_start = np.linalg.norm(offset)
        r_end = np.linalg.norm((end - center) * inplane)
        if abs(r_start - r_end) > tolerance * (1 + 1e-9):  # radii written exactly the tolerance apart are within it
            # to the digit where they differ: a 1 mm difference shows on radii of 1e6 mm (1.00499e+06 both, in 6 digits)
            digits = max(6, int(np.log10(max(r_start, r_end)) - np.log10(abs(r_start - r_end))) + 3)
            fail(f"arc start radius {r_start:.{digits}g} mm and end radius {r_end:.{digits}g} mm differ by more than "
                 f"{tolerance:g} mm")
        sweep = _sweep(start - center, end - center, axis, ccw)
        if abs(sweep) > np.pi and r_start != r_end:  # half about the programmed centre, half tangent to the end
            middle = _arc_from_point(center, start, axis, sweep / 2).end  # in the start's plane
            radial = (center - middle) / r_start
            across = (end - middle) * inplane  # the second centre: on `radial`, as far from `end` as from `middle`
            r_second = (across @ across) / (2 * (across @ radial))
            second = _sweep(middle - (middle + r_second * radial), end - (middle + r_second * radial), axis, ccw)
            # one rise per mm along the plane (a helix's lead angle) on both halves: they join tangentially
            lead = ((end - start) @ axis) / (r_start * abs(sweep) / 2 + r_second * abs(second))
            first = _arc_from_point(center, start, axis, sweep / 2, lead * r_start)
            return [first, _arc_from_point(middle + r_second * radial, first.end, axis, second, lead * r_second)]
        length = np.linalg.norm(chord)
        if length > 1e-9:  # centre onto the chord's bisector: the arc then ends exactly at `end`
            across = np.cross(axis, chord / length)
            center = start + chord / 2 + ((center - start - chord / 2) @ across) * across
    sweep = _sweep(start - center, end - center, axis, ccw)
    return [_arc_from_point(center, start, axis, sweep, ((end - start) @ axis) / abs(sweep))]


def _sweep(a, b, axis, ccw):
    """Turn [rad] from `a` to `b` about `axis`, in (0, 2π] counter-clockwise, [-2π, 0) clockwise (a full turn if they agree)."""
    a, b = a - (a @ axis) * axis, b - (b @ axis) * axis
    turn = np.arctan2(np.cross(a, b) @ axis, a @ b)
    sweep = turn % (2 * np.pi) if ccw else -((-turn) % (2 * np.pi))
    if abs(sweep) < 1e-12:
        sweep = 2 * np.pi if ccw else -2 * np.pi
    return sweep
