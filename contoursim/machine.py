"""A machine: servo axes at a common servo period, and optionally their geometry.

A machine file (TOML) holds both halves; every key carries its unit in its
name (the section "File format" of docs/machines-and-files.md lists them all). The servo half::

    name = "demo mill"
    servo_period_ms = 0.2
    max_feed_mm_min = 30000  # optional: paths planned faster are refused

    [axes.x]                 # file keys -> AxisServo parameters: see SERVO_KEYS
    mass_kg = 300.0
    force_constant_N_per_A = 942.0
    kv_A_s_per_m = 120.0
    ti_s = 0.01
    kp_per_s = 40.0
    travel_mm = [0, 500]     # optional, without bodies: the axis's travel in machine coordinates

and, optionally, the geometric half — bodies, joints and their errors, read
by :func:`contoursim.multibody.chain_from_toml` (see that function for the
keys). Without bodies the machine is an error-free Cartesian one with axes
x, y (, z). With bodies, axes without a ``[axes.*]`` table (rotary tables on
a contouring test, say) follow their commands exactly.
"""

import copy
import os
import re
from collections.abc import Mapping
from dataclasses import MISSING, dataclass
from importlib import resources
from pathlib import Path
from types import MappingProxyType

import numpy as np

from . import _memory, _validate
from .config import TEXT_KEYS, TomlFile, local_file
from .exceptions import ConfigError, PathError, UnstableLoopError
from .multibody import MAX_TRAVEL, MachineChain
from .servo import MIN_SERVO_PERIOD, AxisServo, SamplingError

__all__ = ["CARTESIAN", "CONTROLLER_FIELDS", "SERVO_KEYS", "Machine", "load_machine", "preset_names",
           "read_work_offset", "tables_where_they_lie"]

CARTESIAN = ("x", "y", "z")


@dataclass(frozen=True)
class Machine:
    """Servo axes at a common servo period, and optionally their geometry.

    Parameters
    ----------
    axes : mapping str -> AxisServo
        The servo-controlled axes.
    servo_period : float
        Period the position/velocity controllers run at [s].
    chain : contoursim.multibody.MachineChain, optional
        Geometry with its errors: maps axis positions to the tool tip in
        workpiece coordinates. Without it the machine is an error-free
        Cartesian one whose axes are x, y (, z) in that order.
    name : str
        A label for reports.
    max_feed : float, optional
        Largest path feed the machine allows [mm/s]; a path planned faster
        is refused.
    work_offset : mapping str -> float, optional
        Axis positions at which the tool tip is at the path's origin (the
        work offset, as G54 sets it) [mm, rad]. Axes not given sit at the
        middle of their travel (0 without one). Only with a `chain`.
    uncertain : mapping str -> tuple of str, optional
        Per axis, the controller settings (:data:`CONTROLLER_FIELDS`) that
        are not known exactly: the diagnosis's nominal refit may move them
        (it trusts the others, and doubts the plant).
    axis_travel : mapping str -> (float, float), optional
        Travel (min, max) of servo axes [mm] on a machine without a chain
        (with one, the bodies give it). Its positions are the trace's: the
        path's origin stays at the axes' zero.
    """

    axes: dict
    servo_period: float
    chain: object = None
    name: str = ""
    max_feed: float = None
    work_offset: dict = None
    uncertain: dict = None
    axis_travel: dict = None

    def __post_init__(self):
        if not isinstance(self.axes, Mapping):  # a list of servos has no names
            raise TypeError(f"axes must be a mapping of axis name -> AxisServo ({{'x': servo, ...}}), got "
                            f"{type(self.axes).__name__}")
        axes = dict(self.axes)
        if not axes:
            raise ValueError("a machine needs at least one servo axis")
        for name, servo in axes.items():
            if not isinstance(servo, AxisServo):
                raise TypeError(f"axis {name!r} must be an AxisServo, got {type(servo).__name__}")
        if self.chain is not None and not isinstance(self.chain, MachineChain):
            raise TypeError(f"chain must be a MachineChain (a machine's geometry) or None, got "
                            f"{type(self.chain).__name__}")
        for key, example in (("work_offset", "250.0"), ("uncertain", "('kp',)"), ("axis_travel", "(0.0, 500.0)")):
            if getattr(self, key) is not None and not isinstance(getattr(self, key), Mapping):  # a list read otherwise
                raise TypeError(f"{key} must map axis names to values ({{'x': {example}}}), got "
                                f"{type(getattr(self, key)).__name__}")
        if self.chain is None:
            if tuple(axes) != CARTESIAN[: len(axes)]:
                raise ValueError(f"a machine without a chain has the axes x; x, y; or x, y, z (in that order), got "
                                 f"{tuple(axes)}")
        else:
            unknown = [a for a in axes if a not in self.chain.axes]
            if unknown:
                raise ValueError(f"servo axes {unknown} are not axes of the chain {tuple(self.chain.axes)}")
            rotary = [a for a in axes if self.chain.axis_kind(a) == "rotary"]
            if rotary:
                raise ValueError(f"servo axes {rotary} are rotary: the servo model is a linear feed drive (mass, mm); "
                                 "rotary axes follow their commands")
        offset = dict(self.work_offset or {})
        if offset and self.chain is None:
            raise ValueError("work_offset needs a machine with geometry (bodies); without one the path origin is the axes' zero")
        unknown = [a for a in offset if self.chain is None or a not in self.chain.axes]
        if unknown:
            raise ValueError(f"work_offset names axes {unknown} that the machine does not have")
        offset = {a: _validate.finite_array(f"work_offset[{a!r}]", v, ndim=0).item() for a, v in offset.items()}
        object.__setattr__(self, "work_offset", _validate.Frozen(offset))
        uncertain = {a: tuple(fields) for a, fields in (self.uncertain or {}).items() if fields}
        for a, fields in uncertain.items():
            if isinstance(self.uncertain[a], str):  # its letters would be the settings: 'k' of axis x
                raise TypeError(f"uncertain[{a!r}] must be a sequence of controller settings, got the string "
                                f"{self.uncertain[a]!r}: give ({self.uncertain[a]!r},)")
            if a not in axes:
                raise ValueError(f"uncertain names axis {a!r}, which the machine does not have")
            bad = [f for f in fields if f not in CONTROLLER_FIELDS or getattr(axes[a], f) is None]
            if bad:
                raise ValueError(f"uncertain: {bad[0]!r} of axis {a} is not a controller setting the axis has; "
                                 f"controller settings: {', '.join(CONTROLLER_FIELDS)}")
        object.__setattr__(self, "uncertain", _validate.Frozen(uncertain))
        travel = dict(self.axis_travel or {})
        if travel and self.chain is not None:
            raise ValueError("axis_travel is for a machine without geometry: with bodies, a body's travel gives its axis's")
        for a, span in travel.items():
            if a not in axes:
                raise ValueError(f"axis_travel names axis {a!r}, which the machine does not have")
            lo, hi = _validate.finite_array(f"travel of axis {a}", span, shape=(2,), limit=MAX_TRAVEL)
            if not lo < hi:
                raise ValueError(f"the travel of axis {a} must be [min, max] with min < max, got [{lo:g}, {hi:g}]")
            travel[a] = (float(lo), float(hi))
        object.__setattr__(self, "axis_travel", _validate.Frozen(travel))
        object.__setattr__(self, "axes", _validate.Frozen(axes))
        object.__setattr__(self, "servo_period", _servo_period("servo_period", self.servo_period))
        if self.max_feed is not None:
            object.__setattr__(self, "max_feed", _validate.positive("max_feed", self.max_feed))

    @property
    def axis_names(self):
        """All commanded axes in column order: the chain's, else the servo axes."""
        return tuple(self.axes) if self.chain is None else tuple(self.chain.axes)

    @property
    def slowest_axis(self):
        """The servo axis of the slowest position loop (the least kp)."""
        return min(self.axes, key=lambda axis: self.axes[axis].kp)

    @property
    def settle(self):
        """Five time constants of the slowest position loop, ``5 / min(kp)`` [s]: the standstill :func:`simulate`
        appends to a path's reference by default (:func:`~contoursim.simulation.default_settle`)."""
        return 5.0 / self.axes[self.slowest_axis].kp

    def check_settle(self):
        """Refuse a :attr:`settle` whose run of servo periods would not fit in the memory available (ValueError,
        naming the slowest axis and its kp)."""
        axis = self.slowest_axis
        servo = self.axes[axis]
        _memory.check(self.settle / self.servo_period, f"axis {axis}: kp_per_s = {servo.kp:.6g} 1/s settles in 5/kp "
                      f"= {self.settle:.6g} s after the path: at the servo period of {self.servo_period:.6g} s",
                      "a position loop that slow follows no path; check kp_per_s")

    @property
    def servo_columns(self):
        """Columns of :attr:`axis_names` that are servo-controlled, shape (n_servo,)."""
        return np.array([self.axis_names.index(a) for a in self.axes])

    @property
    def travel(self):
        """Travel (min, max) of each axis that has one [mm, rad]: the chain's bodies', else :attr:`axis_travel`."""
        if self.chain is None:
            return dict(self.axis_travel)
        return {b.axis: b.travel for b in self.chain.bodies if b.axis is not None and b.travel is not None}

    def home(self):
        """Axis positions at the path's origin, shape (n_axes,) [mm, rad].

        The work offset where given; else the middle of a linear axis's travel
        and 0 for a rotary axis (clipped into its travel), 0 without a travel.
        Without a chain the path's origin is the axes' zero.
        """
        if self.chain is None:
            return np.zeros(len(self.axis_names))
        travel, rotary = self.travel, self.chain is not None and self.chain.rotary_axes
        home = []
        for i, axis in enumerate(self.axis_names):
            if axis in self.work_offset:
                home.append(self.work_offset[axis])
            elif axis in travel:
                lo, hi = travel[axis]
                home.append(min(max(0.0, lo), hi) if rotary[i] else (lo + hi) / 2)
            else:
                home.append(0.0)
        return np.array(home)

    def axis_commands(self, trajectory):
        """Axis position, velocity and acceleration commands for a tool-tip reference.

        With a chain, the path's origin is put where the tool tip is at
        :meth:`home`; the linear axes move and the rotary ones hold their
        angle, so the ideal chain is affine in the axis positions and its
        position Jacobian maps the path exactly:
        ``q = q_home + J⁺ p``, ``q' = J⁺ v``, ``q'' = J⁺ a``.

        Parameters
        ----------
        trajectory : Trajectory
            Tool-tip reference in workpiece coordinates.

        Returns
        -------
        position, velocity, acceleration : ndarray, shape (N, n_axes)
            One column per :attr:`axis_names` [mm, mm/s, mm/s^2] (rad for
            rotary axes, which hold their angle).

        Raises
        ------
        ValueError
            The path needs more axes than the machine has.
        PathError
            An axis would leave its travel (``primitive``: the path's
            primitive where it first does).
        """
        p, v, a = trajectory.position, trajectory.velocity, trajectory.acceleration  # read-only
        if self.chain is None and trajectory.dim == len(self.axes):  # the path's coordinates are the axes'
            self._check_travel(p, trajectory)
            return p, v, a
        p, v, a = (_validate.as_xyz(x) for x in (p, v, a))
        if self.chain is None:
            n = len(self.axes)
            if np.abs(p[:, n:]).max(initial=0.0) > 0:
                beyond = ", ".join(f"{c} {p[:, i].min():.6g} .. {p[:, i].max():.6g}" for i, c in enumerate("xyz") if i >= n
                                   and np.any(p[:, i] != 0))  # a constant height (Z5) too: no axis takes it
                raise ValueError(f"the path moves in {trajectory.dim} coordinates but the machine has only {n} "
                                 f"{'axis' if n == 1 else 'axes'} ({', '.join(self.axes)}): it has {beyond} [mm], "
                                 "where the machine's coordinates are zero (without bodies they are the axes')")
            self._check_travel(p[:, :n], trajectory)
            return p[:, :n], v[:, :n], a[:, :n]
        home = self.home()
        linear = ~self.chain.rotary_axes
        moves = self.chain.axis_jacobian(home[None])[0, :3][:, linear]
        jac = np.linalg.pinv(moves)
        unreachable = p - p @ (moves @ jac).T
        if np.abs(unreachable).max(initial=0.0) > 1e-9:
            worst = np.abs(unreachable).max(axis=0)
            raise ValueError(
                f"the machine's linear axes ({', '.join(np.array(self.axis_names)[linear])}) cannot move the tool along the path: "
                f"it leaves their span by up to ({worst[0]:.3g}, {worst[1]:.3g}, {worst[2]:.3g}) mm in x, y, z"
            )
        q = np.tile(home, (len(p), 1))
        qv, qa = np.zeros_like(q), np.zeros_like(q)
        q[:, linear] += p @ jac.T
        qv[:, linear] = v @ jac.T
        qa[:, linear] = a @ jac.T
        self._check_travel(q, trajectory)
        return q, qv, qa

    def origin(self):
        """Where the ideal machine's tool tip is at :meth:`home`, in workpiece coordinates [mm], shape (3,)."""
        if self.chain is None:
            return np.zeros(3)
        return self.chain.tool_pose(self.home()[None], ideal=True)[0][0]

    def refusal(self, axes=None):
        """What the loop check (:func:`contoursim.servo.check`) says of the first servo loop of `axes` (default: all)
        it refuses at this machine's servo period (unstable, badly damped, too fast for the period), or ``None``."""
        try:
            for axis in self.axes if axes is None else axes:
                self.axes[axis].check(self.servo_period, axis)
        except ValueError as exc:  # UnstableLoopError, or the period too long for a loop
            return str(exc)
        return None

    def _check_travel(self, q, trajectory):
        """Refuse commands `q` (of `trajectory`'s samples) that leave an axis's travel, naming the path's primitive
        where they first do (none for a measured reference, which has no path)."""
        for axis, (lo, hi) in self.travel.items():
            column = q[:, self.axis_names.index(axis)]
            outside = (column < lo - 1e-9) | (column > hi + 1e-9)
            if outside.any():
                rotary = self.chain is not None and self.chain.axis_kind(axis) == "rotary"
                unit, shown = ("deg", np.degrees) if rotary else ("mm", float)
                raise PathError(
                    f"axis {axis} would move over {shown(column.min()):.6g} .. {shown(column.max()):.6g}, outside its "
                    f"travel {shown(lo):.6g} .. {shown(hi):.6g} [{unit}]: "
                    + ("move the path with work_offset or make it smaller" if self.chain is not None else
                       "place the path inside it or make it smaller (without bodies the path's coordinates are the axes')"),
                    None if trajectory.path is None else int(trajectory.primitive[np.argmax(outside)]), axis,
                )

    def tool_position(self, q, t, dim):
        """Tool tip in the path's coordinates: workpiece coordinates from the path's origin (:meth:`origin`).

        Parameters
        ----------
        q : ndarray, shape (N, n_axes)
            Actual axis positions, columns as :attr:`axis_names` [mm, rad].
        t : ndarray, shape (N,)
            Times [s] (thermal drift).
        dim : int
            Coordinates to return, 2 or 3.

        Returns
        -------
        ndarray, shape (N, dim)
            [mm]
        """
        if self.chain is None:  # the axes' positions are the tool's (a view), padded with z = 0 where dim asks for it
            q = np.asarray(q, dtype=float)
            return q[:, :dim] if q.shape[1] >= dim else _validate.as_xyz(q)[:, :dim]
        return (self.chain.tool_pose(q, t)[0] - self.origin())[:, :dim]



_PRESETS = "presets"

#: ``[axes.<name>]`` file key -> :class:`~contoursim.servo.AxisServo` parameter (SI, the key's unit).
SERVO_KEYS = MappingProxyType({
    "mass_kg": "mass",
    "force_constant_N_per_A": "force_constant",
    "kv_A_s_per_m": "kv",
    "kp_per_s": "kp",
    "ti_s": "ti",
    "damping_N_s_per_m": "damping",
    "current_limit_A": "current_limit",
    "vff": "vff",
    "aff": "aff",
    "inductance_H": "inductance",
    "resistance_ohm": "resistance",
    "kc_V_per_A": "kc",
    "ti_current_s": "ti_current",
    "current_bandwidth_hz": "current_bandwidth_hz",
    "velocity_feedback": "velocity_feedback",
    "velocity_taps": "velocity_taps",
    "velocity_filter_hz": "velocity_filter_hz",
    "computation_delay_periods": "computation_delay",
    "velocity_integrator": "velocity_integrator",
    "position_feedback": "position_feedback",
    "motor_mass_kg": "motor_mass",
    "screw_stiffness_N_per_um": "screw_stiffness",
    "screw_damping_ratio": "screw_damping_ratio",
})
#: The controller's settings among the servo parameters (the rest is the plant): what ``uncertain`` may list. The
#: drive's structure (velocity_feedback, velocity_taps, computation_delay, velocity_integrator: names and whole numbers)
#: is the controller too, trusted always: a refit cannot step it (a diagnosis chooses a velocity_integrator not given).
CONTROLLER_FIELDS = ("kp", "kv", "ti", "vff", "aff", "kc", "ti_current", "current_bandwidth_hz", "velocity_filter_hz")
#: Keys of earlier versions -> the keys that replaced them.
_RENAMED = {field: key for key, field in SERVO_KEYS.items() if field != key}
# a parameter name where a message uses it as one ("kp must be", "lower kp = 40"), not in prose ("damping ratio")
_SERVO_NAME = re.compile(r"\b(" + "|".join(_RENAMED) + r")\b(?=( =| must| is| \(| \[|,| given| as well|\.|$))")
#: Servo periods a machine may have [s]: servo loops from 1 MHz down to 1 Hz.
SERVO_PERIOD_RANGE = (MIN_SERVO_PERIOD, 1.0)
_SERVO_KEYS = ("name", "description", "servo_period_ms", "max_feed_mm_min", "work_offset", "axes", "effect")
#: Keys of an ``[axes.<name>]`` table besides the servo parameters.
_AXIS_KEYS = ("uncertain", "travel_mm")


def _servo_period(name, value, unit="s"):
    """`value` as a servo period [s], after checking it lies in :data:`SERVO_PERIOD_RANGE`: the one check of
    :class:`Machine`'s `servo_period` and of a machine file's ``servo_period_ms``.

    Parameters
    ----------
    name : str
        The parameter or file key, as messages name it.
    value : float
        The period in `unit`.
    unit : {"s", "ms"}
        The unit of `value` (and of the range as the message says it).

    Returns
    -------
    float
        The period [s].

    Raises
    ------
    TypeError
        `value` is not a number.
    ValueError
        `value` is not finite, not positive, or outside the range.
    """
    scale = {"s": 1.0, "ms": 1e-3}[unit]
    period = _validate.positive(name, value) * scale
    low, high = SERVO_PERIOD_RANGE
    if not low <= period <= high:
        raise ValueError(f"{name} must lie in [{low / scale:g}, {high / scale:g}] {unit} (servo loops from 1 MHz "
                         f"down to 1 Hz), got {value:g}")
    return period


def preset_names():
    """Names of the machine files shipped with contoursim (``contoursim/presets``)."""
    folder = resources.files("contoursim").joinpath(_PRESETS)
    return sorted(p.name[:-5] for p in folder.iterdir() if p.name.endswith(".toml"))


def preset_file(name_or_file, here=True):
    """The file of a machine given as a preset name or a path (``demo_mill.toml`` here before the preset ``demo_mill``).

    With ``here=False``, the shipped preset of that name only (a default the user did not name).
    """
    if not isinstance(name_or_file, (str, os.PathLike)):
        raise TypeError(f"a machine is a preset name or a machine file (str or Path), got {type(name_or_file).__name__}")
    if isinstance(name_or_file, str) and not name_or_file.strip():  # Path('') would be '.': a folder
        raise ConfigError(f"the machine's name is empty: name a preset ({', '.join(preset_names())}) or a machine file")
    path = local_file(name_or_file, suffixes=(".toml",)) if here else None  # a user's copy of a preset is the one meant
    if path is not None:
        return path
    if str(name_or_file) in preset_names():
        return Path(str(resources.files("contoursim").joinpath(_PRESETS, f"{name_or_file}.toml")))
    raise ConfigError(f"no machine file {str(name_or_file)!r} and no preset of that name"
                      f"{_validate.closest(str(name_or_file), preset_names())}; presets: {', '.join(preset_names())}")


def tables_where_they_lie(toml):
    """The data of the machine file `toml` (a :class:`~contoursim.config.TomlFile`) with each error table it names
    (``[body.errors] table``, relative to the file) named where it lies: read from another folder, it names the
    same tables.

    Parameters
    ----------
    toml : contoursim.config.TomlFile
        A machine file as read.

    Returns
    -------
    dict
        A copy of ``toml.data``; equal to it where no table is named relative to the file.
    """
    data = copy.deepcopy(dict(toml.data))
    for body in data.get("body", []):
        if "table" in body.get("errors", {}):
            body["errors"]["table"] = str((Path(toml.source).parent / body["errors"]["table"]).resolve())
    return data


def load_machine(name_or_file, geometry=True, effects=False, check=True):
    """Load a machine from a preset name or a machine TOML file.

    Parameters
    ----------
    name_or_file : str or Path
        A preset name (see :func:`preset_names`) or a machine file.
    geometry : bool
        Read the geometric half (bodies) when the file has one; ``False``
        gives the error-free Cartesian machine of the servo axes.
    effects : bool
        The caller reads the file's ``[[effect]]`` tables
        (:func:`contoursim.model.load_model` does); otherwise a file that has
        them is refused rather than loaded without them.
    check : bool
        Refuse an axis whose sampled loop is unstable or badly damped.
        ``False`` loads it as the file gives it (a diagnosis does: the
        measured trace, not the loop check, says whether the machine is
        stable; :func:`contoursim.diagnosis.diagnose`). A servo period too
        long for a loop is refused either way.

    Returns
    -------
    Machine

    Raises
    ------
    ConfigError
        Naming the file and line of an unknown key or a bad value, or of the
        servo period when it is too long for an axis's loops (of the axis's
        integral time when its integral action makes the loop too fast).
    UnstableLoopError
        With `check`, an axis's sampled loop is unstable or badly damped: the
        message names the file, the line of its ``[axes.*]`` table, the loop
        and its margins.
    """
    from .multibody import chain_from_toml

    geometry, effects, check = (_validate.flag(name, value) for name, value in
                                (("geometry", geometry), ("effects", effects), ("check", check)))
    toml = TomlFile.read(preset_file(name_or_file))
    toml.expect("machine")
    data = toml.data
    if "effect" in data and not effects:
        raise toml.error("this machine file has [[effect]] tables: load it with contoursim.model.load_model", "effect")
    chain = None
    if "body" in data:
        chain = chain_from_toml(toml, extra=_SERVO_KEYS)
    else:
        toml.table(allowed=_SERVO_KEYS, text=TEXT_KEYS)
    if "axes" not in data:
        raise toml.error("missing [axes.<name>] tables: the servo parameters of each axis")
    if "servo_period_ms" not in data:
        raise toml.error("missing key 'servo_period_ms': the servo period [ms]")
    try:
        period = _servo_period("servo_period_ms", data["servo_period_ms"], unit="ms")
        max_feed = data.get("max_feed_mm_min")
        max_feed = None if max_feed is None else _validate.positive("max_feed_mm_min", max_feed) / 60.0
    except (TypeError, ValueError) as exc:
        raise toml.error(str(exc), str(exc).split()[0]) from None
    fields = AxisServo.__dataclass_fields__
    required = [key for key, name in SERVO_KEYS.items() if fields[name].default is MISSING]
    servos, uncertain, travel = {}, {}, {}
    for axis in toml.table("axes"):
        table = dict(toml.table("axes", axis, allowed=(*SERVO_KEYS, *_AXIS_KEYS), required=required, renamed=_RENAMED))
        listed = table.pop("uncertain", [])
        if "travel_mm" in table:
            travel[axis] = _axis_travel(toml, axis, table.pop("travel_mm"), chain)
        controller = {key for key, name in SERVO_KEYS.items() if name in CONTROLLER_FIELDS}
        if not isinstance(listed, list) or any(key not in controller or key not in table for key in listed):
            raise toml.error(f"axis {axis}: uncertain must list controller keys given in [axes.{axis}] "
                             f"(of {', '.join(sorted(controller))}), got {listed!r}", "axes", axis, "uncertain")
        uncertain[axis] = tuple(SERVO_KEYS[key] for key in listed)
        try:
            servos[axis] = AxisServo(**{SERVO_KEYS[key]: value for key, value in table.items()})
        except (TypeError, ValueError) as exc:
            bad = next((key for key in table if str(exc).startswith(SERVO_KEYS[key])), None)
            keys = ("axes", axis, bad) if bad else ("axes", axis)
            raise toml.error(f"axis {axis}: {_file_names(exc)}", *keys) from None
    if chain is None:
        unknown = next((axis for axis in servos if axis not in CARTESIAN), None)
        if unknown is not None:
            raise toml.error(f"unknown axis {unknown!r} ([axes.{unknown}]): a machine without bodies has the axes x, y "
                             "(, z)", "axes", unknown)
    if set(servos) <= set(CARTESIAN):  # [axes.y] before [axes.x]: TOML's tables have no order, the machine's axes do
        servos = {axis: servos[axis] for axis in CARTESIAN if axis in servos}
    offset = read_work_offset(toml, chain) if "work_offset" in data and geometry else None
    for axis, servo in servos.items():  # refuse loops that cannot run at this period, pointing at the file
        try:
            servo.check(period, axis)
        except UnstableLoopError as exc:
            if check:
                raise UnstableLoopError(f"{toml.source}, line {toml.line_of('axes', axis)}: {_file_names(exc)}",
                                        exc.margins) from None
        except SamplingError as exc:  # the period, or the parameter making the loop too fast for it
            keys = ("servo_period_ms",) if exc.parameter == "dt" else ("axes", axis, _RENAMED[exc.parameter])
            raise toml.error(_file_names(exc), *keys) from None
    try:
        machine = Machine(servos, period, chain if geometry else None, name=data.get("name", str(name_or_file)),
                          max_feed=max_feed, work_offset=offset, uncertain=uncertain,
                          axis_travel=travel if geometry else None)
    except (TypeError, ValueError) as exc:
        raise toml.error(str(exc), "axes") from None
    try:
        machine.check_settle()  # a position loop so slow that the settle after a path cannot be run: at its line
    except ValueError as exc:
        raise toml.error(str(exc), "axes", machine.slowest_axis, "kp_per_s") from None
    return machine


def _axis_travel(toml, axis, value, chain):
    """The ``travel_mm = [min, max]`` of ``[axes.<axis>]`` [mm], checked against the file."""
    if chain is not None:
        raise toml.error(f"axis {axis}: a machine with bodies gives the travel on the axis's [[body]] (travel_mm), "
                         "not in [axes]", "axes", axis, "travel_mm")
    if not isinstance(value, list) or len(value) != 2 or any(isinstance(v, bool) or not isinstance(v, (int, float)) for v in value):
        raise toml.error(f"axis {axis}: travel_mm must be [min, max] in mm, got {value!r}", "axes", axis, "travel_mm")
    lo, hi = (float(v) for v in value)
    if not (np.isfinite(lo) and np.isfinite(hi) and -MAX_TRAVEL <= lo < hi <= MAX_TRAVEL):
        raise toml.error(f"axis {axis}: travel_mm must be [min, max] with min < max within ±{MAX_TRAVEL:g} mm, got {value!r}",
                         "axes", axis, "travel_mm")
    return lo, hi


def _file_names(exc):
    """The message of `exc` with AxisServo parameter names replaced by the file keys."""
    return _SERVO_NAME.sub(lambda match: _RENAMED[match.group(0)], str(exc))


def read_work_offset(toml, chain):
    """The ``work_offset = { x_mm = 250, c_deg = 90 }`` table of a machine or job file.

    Parameters
    ----------
    toml : contoursim.config.TomlFile
        The file holding a top-level ``work_offset`` table: one key per axis,
        its name and unit, ``<axis>_mm`` (linear) or ``<axis>_deg`` (rotary).
    chain : contoursim.multibody.MachineChain or None
        The machine's geometry; a work offset needs one.

    Returns
    -------
    dict
        Axis name -> position [mm, rad].
    """
    if chain is None:
        raise toml.error("work_offset needs a machine with geometry ([[body]] tables)", "work_offset")
    keys = {f"{axis}_deg" if chain.axis_kind(axis) == "rotary" else f"{axis}_mm": axis for axis in chain.axes}
    table = toml.table("work_offset", allowed=keys, renamed={axis: key for key, axis in keys.items()})
    offset = {}
    for key, value in table.items():
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not np.isfinite(value):
            raise toml.error(f"work_offset.{key} must be a finite number, got {value!r}", "work_offset", key)
        offset[keys[key]] = np.radians(value) if key.endswith("_deg") else float(value)
    return offset
