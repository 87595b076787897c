"""Path files of the trajectories library: a TOML path description or a G-code program.

A file ending in ``.toml`` is a path description; one ending in a G-code
suffix (:data:`contoursim.gcode.SUFFIXES`: ``.nc``, ``.ngc``, ``.gcode``,
``.tap``, ``.cnc``, ``.mpf``, ``.iso``, ``.eia``) a G-code program.

The TOML format (``[feed]`` and ``[path]`` tables, units in the key names) is
listed in the README section "File format"; trajectories/README.md says which
keys each path type takes. Every error names the file and the line
of the offending key, through :class:`contoursim.config.TomlFile`.
"""

import math
import os
import re
from dataclasses import dataclass, replace
from pathlib import Path as _FilePath

import numpy as np

from . import _validate
from .config import TEXT_KEYS, TomlFile, local_file
from .exceptions import ConfigError
from .feed import SETTING_RANGE, FeedSettings
from .gcode import SUFFIXES, read_gcode
from .paths import MAX_COORDINATE, circle, helix, iso230_4_circle, polyline, spline

__all__ = ["NAME_SUFFIXES", "PathFile", "library_file", "load_path_file", "override_feed", "read_feed_table",
           "read_path_file"]


#: The suffixes tried in turn after a path file's name given without one: a TOML path, then each G-code suffix (the
#: user's ``part.ngc`` for ``part``, not the library's ``pocket.nc`` for a ``pocket.ngc`` here).
NAME_SUFFIXES = (".toml", *SUFFIXES)


def _converted(scale, low, high, check=None):
    """A converter of a key's value to its argument's unit (`scale` of the key's unit), within the argument's range
    [`low`, `high`]: the value checked by `check` (e.g. :func:`contoursim._validate.positive`), then the range, both
    said in the key's unit (:func:`contoursim._validate.within`)."""
    return lambda name, value: _validate.within(name, value if check is None else check(name, value), low, high, scale)


def _tolerance(name, value):
    """A join's turn in [0, 180] [deg] in [rad]."""
    value = _validate.nonnegative(name, value)
    if value > 180:
        raise ValueError(f"{name} must be at most 180 (a reversal), got {value:g}")
    return math.radians(value)


# path type -> (builder, {file key: builder argument}, required file keys)
_PATHS = {
    "circle": (circle, dict(center_mm="center", radius_mm="radius", direction="direction", normal="normal",
                            start_angle_deg="start_angle"), ("center_mm", "radius_mm")),
    "iso230_4_circle": (iso230_4_circle, dict(radius_mm="radius", center_mm="center", direction="direction",
                                              run_angle_deg="run_angle", run_radius_mm="run_radius",
                                              start_angle_deg="start_angle"), ("radius_mm",)),
    "polyline": (polyline, dict(points_mm="points", blend_radius_mm="blend_radius"), ("points_mm",)),
    "spline": (spline, dict(points_mm="points", closed="closed"), ("points_mm",)),
    "helix": (helix, dict(center_mm="center", radius_mm="radius", pitch_mm="pitch", turns="turns",
                          direction="direction", normal="normal", start_angle_deg="start_angle"),
              ("center_mm", "radius_mm", "pitch_mm", "turns")),
}
_RAD_PER_DEG = math.pi / 180.0
# [path] keys in another unit than their builder argument's -> converter raising ValueError on a bad value, in the
# key's unit: the builder's own checks would say it in the argument's ("start_angle holds 1.74533e+298", in rad)
_CONVERTED = dict(start_angle_deg=_converted(_RAD_PER_DEG, -MAX_COORDINATE, MAX_COORDINATE),
                  run_angle_deg=_converted(_RAD_PER_DEG, 1.0 / MAX_COORDINATE, 2 * math.pi, _validate.positive))
# [feed] key -> (FeedSettings argument, converter raising ValueError on a bad value, in the key's unit: within the
# planner's SETTING_RANGE [mm/s, mm/s², mm/s³])
_FEED = dict(feed_mm_min=("feed", _converted(1 / 60.0, *SETTING_RANGE, _validate.positive)),
             accel_mm_s2=("accel", _converted(1.0, *SETTING_RANGE, _validate.positive)),
             jerk_mm_s3=("jerk", _converted(1.0, *SETTING_RANGE, _validate.positive)),
             centripetal_accel_mm_s2=("centripetal_accel", _converted(1.0, *SETTING_RANGE, _validate.positive)),
             corner_tolerance_deg=("corner_tolerance", _tolerance))


def _library():
    """The trajectories library folder.

    Installed, it is the package folder ``contoursim/trajectories``. Run from a
    source checkout (``python -m contoursim`` at the repository root imports the
    source folder ``contoursim/``), it is the top-level ``trajectories/`` beside it.
    """
    package = _FilePath(__file__).parent
    return next(f for f in (package / "trajectories", package.parent / "trajectories") if f.is_dir())


def library_file(name, here=True):
    """The path file `name`: an existing file, else an entry of the trajectories library.

    Parameters
    ----------
    name : str or os.PathLike
        A file name, or a library entry with or without its suffix
        (``"butterfly"``, ``"pocket.nc"``; without a suffix, ``.toml`` then each G-code suffix is tried
        (:data:`NAME_SUFFIXES`), here first: a file here is read rather than the library's of that name).
    here : bool
        ``False``: the library's entry only (a job file's name not found beside the job).

    Returns
    -------
    pathlib.Path
    """
    if not isinstance(name, (str, os.PathLike)):
        raise TypeError(f"a path file is a file or library name (str or Path), got {type(name).__name__}")
    if isinstance(name, str) and not name.strip():  # Path('') would be '.', a folder
        raise ConfigError("the path file's name is empty: name a path file or a library path (e.g. butterfly)")
    if any(c in os.fspath(name) for c in "\r\n"):  # its stem names the files written: refused there, after the run
        raise ConfigError(f"the path file's name {os.fspath(name)!r} has a line break, which no file written from it "
                          "may have: rename it")
    found = local_file(name, suffixes=NAME_SUFFIXES) if here else None  # a user's copy of a library entry is meant
    if found is not None and not found.is_dir():
        return found
    library = _library()
    for candidate in (str(name), *(f"{name}{suffix}" for suffix in NAME_SUFFIXES)):
        if library.joinpath(candidate).is_file():
            return library / candidate
    if found is not None:  # a folder of that name, and no library entry
        raise ConfigError(f"{found} is a folder, not a path file: name a path file (.toml or G-code) or a library path")
    known = sorted(p.name for p in library.iterdir() if p.suffix.lower() in (".toml", *SUFFIXES))
    meant = _validate.closest(str(name), [*known, *(_FilePath(k).stem for k in known)])
    raise ConfigError(f"no path file {str(name)!r} {'here nor ' if here else ''}in the trajectories library{meant}; "
                      f"the library: {', '.join(known)}")


@dataclass(frozen=True)
class PathFile:
    """A path file as read.

    Parameters
    ----------
    path : contoursim.paths.Path
    feed : contoursim.feed.FeedSettings
        Feed rate(s) [mm/s], acceleration and jerk limits of the file.
    program : contoursim.gcode.Program or None
        The G-code program (its blocks' lines and text) of a G-code file; None for a TOML file.
    """

    path: object
    feed: FeedSettings
    program: object = None


def read_path_file(file, direction=None):
    """Read a path file, or an entry of the trajectories library by name.

    Parameters
    ----------
    file : str or os.PathLike
        A ``.toml`` path file (keys in docs/machines-and-files.md, "File format"), a
        G-code program (a suffix of :data:`contoursim.gcode.SUFFIXES`; see
        :func:`contoursim.gcode.read_gcode`), or the name of either in the
        trajectories library (see :func:`library_file`).
    direction : {"ccw", "cw"}, optional
        Instead of the ``[path]`` table's ``direction``: the same circle,
        ISO 230-4 circle or helix the other way round.

    Returns
    -------
    PathFile

    Raises
    ------
    ConfigError
        Naming the file and line of an unknown or missing key or a bad value,
        a file of another type, or a `direction` for a path that has none.
    """
    if direction is not None and direction not in ("ccw", "cw"):  # not the file's: said of the argument, not its line
        raise ValueError(f"direction must be 'ccw', 'cw' or None (the file's), got {direction!r}")
    file = library_file(file)
    if direction is not None and file.suffix.lower() != ".toml":
        raise ConfigError("only a circle, iso230_4_circle or helix path file can be run in another direction",
                          source=str(file))
    if file.suffix.lower() in SUFFIXES:
        program = read_gcode(file)
        return PathFile(program.path, FeedSettings(tuple(program.feeds), stops=tuple(program.stops)), program)
    if file.suffix.lower() != ".toml":
        raise ConfigError(f"unknown path file type {file.suffix!r}: use .toml, or G-code {' '.join(SUFFIXES)}",
                          source=str(file))
    toml = TomlFile.read(file)
    toml.expect("path")
    toml.table(allowed=("name", "description", "path", "feed"), text=TEXT_KEYS)
    return PathFile(_path(toml, direction), read_feed_table(toml))


def load_path_file(file, direction=None):
    """The path and feed settings of a path file (:func:`read_path_file`).

    Parameters
    ----------
    file : str or os.PathLike
        As for :func:`read_path_file`.
    direction : {"ccw", "cw"}, optional
        As for :func:`read_path_file`.

    Returns
    -------
    path : contoursim.paths.Path
    feed : contoursim.feed.FeedSettings
        Feed rate(s) [mm/s], acceleration and jerk limits of the file.
    """
    read = read_path_file(file, direction)
    return read.path, read.feed


def _path(toml, direction=None):
    """The :class:`~contoursim.paths.Path` described by the ``[path]`` table (in `direction` when given)."""
    kind = toml.table("path", required=("type",))["type"]
    if not isinstance(kind, str) or kind not in _PATHS:
        raise toml.error(f"[path] type must be one of {', '.join(sorted(_PATHS))}, got {kind!r}"
                         f"{_validate.closest(kind, _PATHS)}", "path", "type")
    build, arguments, required = _PATHS[kind]
    spec = toml.table("path", allowed=("type", *arguments), required=required)
    if direction is not None:
        if "direction" not in arguments:
            raise toml.error(f"a {kind} path has no direction: only a circle, iso230_4_circle or helix can be run "
                             "the other way round", "path", "type")
        spec = {**spec, "direction": direction}
    kwargs = {}
    for key, value in spec.items():
        if key == "type":
            continue
        try:
            kwargs[arguments[key]] = _CONVERTED[key](key, value) if key in _CONVERTED else value
        except (TypeError, ValueError) as exc:
            raise toml.error(str(exc), "path", key) from None
    try:
        return build(**kwargs)
    except (ValueError, TypeError) as exc:
        message, blamed = _file_names(str(exc), arguments, spec)
        raise toml.error(f"bad {kind} [path]: {message}", "path", *blamed) from None


def _file_names(message, arguments, spec):
    """A builder's `message` with the names of its arguments replaced by their file keys (``points`` -> ``points_mm``;
    where used as a name, not in prose: "3 distinct points"), and the key given in `spec` it names first as a 0- or
    1-tuple (the error's line; a default's argument has none)."""
    keys = {arg: key for key, arg in arguments.items()}
    named = re.compile(rf"\b({'|'.join(keys)})\b(?=\[| must| =| holds| contains| \(| \d)")
    given = [keys[match.group(0)] for match in named.finditer(message) if keys[match.group(0)] in spec]
    return named.sub(lambda match: keys[match.group(0)], message), tuple(given[:1])


def override_feed(read, job):
    """A path file as a job runs it: the job's ``[feed]`` table overrides the file's key by key.

    A G-code program's F words are its programmed feeds; a job's
    ``feed_mm_min`` overrides them on every cutting block (G1/G2/G3), as a
    controller's feed override does, and the rapids (G0) keep the rapid feed.
    The program's feeds become those that run, so that every output reading
    them (the block listing, ``NAME_blocks.csv``) says what ran.

    Parameters
    ----------
    read : PathFile
        The path file as read (:func:`read_path_file`).
    job : contoursim.config.TomlFile
        The job file, with a ``[feed]`` table.

    Returns
    -------
    PathFile
    """
    settings = read_feed_table(job, base=read.feed)
    if read.program is None or "feed_mm_min" not in job.data["feed"]:
        return replace(read, feed=settings)
    feeds = np.where(np.array(read.path.roles) == "rapid", read.program.feeds, settings.feed)
    return replace(read, feed=replace(settings, feed=tuple(feeds.tolist())), program=replace(read.program, feeds=feeds))


def read_feed_table(toml, base=None):
    """The feed settings of a file's ``[feed]`` table.

    Parameters
    ----------
    toml : contoursim.config.TomlFile
        A path file, or a job file whose ``[feed]`` overrides a path file's.
    base : contoursim.feed.FeedSettings, optional
        Settings the table overrides key by key; without them
        ``feed_mm_min`` is required.

    Returns
    -------
    contoursim.feed.FeedSettings
    """
    spec = toml.table("feed", allowed=_FEED, required=() if base else ("feed_mm_min",))
    settings = {} if base is None else dict(vars(base))
    for key, value in spec.items():
        argument, convert = _FEED[key]
        try:
            settings[argument] = convert(key, value)
        except (TypeError, ValueError) as exc:
            raise toml.error(str(exc), "feed", key) from None
    try:
        return FeedSettings(**settings)
    except (TypeError, ValueError) as exc:  # a value out of the planner's range
        raise toml.error(str(exc), "feed") from None
