"""The effects catalogue: named, parameterised deviations from a nominal machine.

An :class:`Effect` is a small frozen object: the contract name of what it
models (DESIGN.md's catalogue, e.g. ``"backlash"``), the axis it acts on
(one letter, or two for a cross-axis effect: ``squareness`` on ``"xy"``),
its :class:`Parameter` values (lmfit-like: value, unit, bounds, typical
range, whether a fit may vary it), a few structural options (``feedback =
"motor"`` or ``"scale"``) and the stage of the data flow where it acts:

=========== ======================================================= ==============================
stage       effects                                                 how it runs
=========== ======================================================= ==============================
command     ``time_delay`` with ``kind = "command"``                shifts the axis commands
servo       ``gain_mismatch``                                       a different servo variant
loop        ``backlash``, ``coulomb_friction``, ``time_delay`` with  the kernel's per-axis
            ``kind = "feedback"`` (both loops read late) or         ``LoopEffects``
            ``"position"`` (the position loop only),
            ``vibration``, ``quantisation``, ``noise``
geometry    ``squareness``, ``scale_error``, ``cyclic_error``,       terms of the multibody chain
            ``straightness``, ``thermal_drift``
=========== ======================================================= ==============================

Nothing else: how a stage is realised is :mod:`contoursim.model`'s business.
Parameter names carry their unit (``lost_motion_um``), as in the diagnosis
report (DESIGN.md) and the ``[[effect]]`` tables of machine and job files::

    [[effect]]
    name = "backlash"
    axis = "x"
    lost_motion_um = 8.0
    feedback = "motor"

Every kind of effect is an :class:`EffectKind` registered under its name
(:func:`effect_kind`); :data:`CATALOGUE` lists the contract names, and
``quantisation`` and ``noise`` are registered besides them.
"""

from dataclasses import dataclass, field, replace

import numpy as np

from . import _validate

__all__ = [
    "CATALOGUE",
    "STAGES",
    "Effect",
    "EffectKind",
    "Parameter",
    "effect_kind",
    "effect_names",
    "read_effects",
]

#: The stages of the data flow where an effect can act, in the order they run.
STAGES = ("command", "servo", "loop", "geometry")

#: Contract names of the effects catalogue (DESIGN.md), in its order.
CATALOGUE = (
    "backlash",
    "coulomb_friction",
    "gain_mismatch",
    "squareness",
    "scale_error",
    "cyclic_error",
    "straightness",
    "time_delay",
    "thermal_drift",
    "vibration",
)

_AXES = "xyz"


@dataclass(frozen=True)
class Parameter:
    """One numeric parameter of an effect (lmfit-like).

    Parameters
    ----------
    name : str
        Unit-suffixed name, as in the report contract (``lost_motion_um``).
    value : float
        The value, in `unit`.
    unit : str
        Unit of `value` (``"µm"``, ``"N"``, ``"-"`` for a ratio ...).
    bounds : tuple of float
        ``(min, max)`` the value must lie in (either may be infinite).
    typical : tuple of float
        The range a machine-tool axis usually shows; for a signed parameter
        (``bounds[0] < 0``) the range of its magnitude.
    vary : bool
        Whether a fit may adjust it.
    doc : str
        One line: what it is.
    """

    name: str
    value: float
    unit: str
    bounds: tuple = (-np.inf, np.inf)
    typical: tuple = None
    vary: bool = True
    doc: str = ""

    def __post_init__(self):
        lo, hi = (float(b) for b in self.bounds)
        if np.isnan(lo) or np.isnan(hi) or not lo < hi:
            raise ValueError(f"{self.name}: bounds must be (min, max) with min < max, got {self.bounds!r}")
        object.__setattr__(self, "bounds", (lo, hi))
        value = float(_validate.finite_array(self.name, self.value, ndim=0))
        if not lo <= value <= hi:
            raise ValueError(f"{self.name} must lie in [{lo:g}, {hi:g}] {self.unit}, got {value:g}")
        object.__setattr__(self, "value", value)
        if self.typical is not None:
            object.__setattr__(self, "typical", tuple(float(v) for v in self.typical))
        object.__setattr__(self, "vary", _validate.flag(f"{self.name}: vary", self.vary))

    @property
    def signed(self):
        """True when the parameter may be negative (its typical range is then one of magnitude)."""
        return self.bounds[0] < 0


@dataclass(frozen=True)
class EffectKind:
    """What an effect of one name is: its parameters, options, axes and stage.

    Parameters
    ----------
    name : str
        Contract name.
    stage : str or tuple
        One of :data:`STAGES`, or ``(option, {option value: stage})`` when an
        option decides it (``time_delay``'s ``kind``).
    parameters : tuple of Parameter
        The parameters with their default values; the first is the effect's
        size, which a file or a constructor must always give.
    options : mapping str -> tuple
        Structural choices: option name -> allowed values, the first being
        the default (``None``: decided by the machine, see :class:`Effect`).
        ``int`` instead of a tuple: any integer, default 0.
        ``"axes"``: any axis letter other than the effect's own.
    n_axes : int
        Letters in the effect's axis: 1, or 2 for a cross-axis effect.
    doc : str
        One line: what it models.
    """

    name: str
    stage: object
    parameters: tuple
    options: dict = field(default_factory=dict)
    n_axes: int = 1
    doc: str = ""

    def __post_init__(self):
        stages = [self.stage] if isinstance(self.stage, str) else list(self.stage[1].values())
        if any(s not in STAGES for s in stages):
            raise ValueError(f"{self.name}: stage must be one of {STAGES}, got {self.stage!r}")
        object.__setattr__(self, "parameters", tuple(self.parameters))
        object.__setattr__(self, "options", _validate.Frozen(self.options))

    @property
    def parameter_names(self):
        """Names of the numeric parameters, in order."""
        return tuple(p.name for p in self.parameters)


_REGISTRY = {}


def _register(kind):
    """Register an :class:`EffectKind` under its name (a name is registered once); how each
    stage realises it lives in :mod:`contoursim.model`."""
    if not isinstance(kind, EffectKind):
        raise TypeError(f"register takes an EffectKind, got {type(kind).__name__}")
    if kind.name in _REGISTRY:
        raise ValueError(f"an effect named {kind.name!r} is already registered")
    _REGISTRY[kind.name] = kind
    return kind


def effect_names():
    """Names of every registered effect: the catalogue's first, then the others."""
    return CATALOGUE + tuple(n for n in _REGISTRY if n not in CATALOGUE)


def effect_kind(name):
    """The :class:`EffectKind` registered as `name`.

    Parameters
    ----------
    name : str
        An effect name; an unknown one raises ValueError listing the names there are.

    Returns
    -------
    EffectKind
    """
    try:
        return _REGISTRY[name]
    except (KeyError, TypeError):
        raise ValueError(f"unknown effect {name!r}{_validate.closest(name, effect_names())}; the effects are: "
                         f"{', '.join(effect_names())}") from None


@dataclass(frozen=True, init=False)
class Effect:
    """A named, parameterised deviation from the nominal machine.

    Parameters
    ----------
    name : str
        A registered effect name (:func:`effect_names`).
    axis : str
        The axis it acts on (``"x"``), or two axis letters for a cross-axis
        effect (``squareness``: ``"xy"``).
    **values
        Parameter values in their units (``lost_motion_um=8.0``) and options
        (``feedback="scale"``); the effect's first parameter is required, the
        others and the options have defaults (:func:`effect_kind` lists them).

    Attributes
    ----------
    parameters : tuple of Parameter
        The effect's parameters with their values.
    options : mapping str -> str or int
        The structural options, defaults filled in.

    Examples
    --------
    >>> e = Effect("backlash", "x", lost_motion_um=8.0, feedback="motor")
    >>> e.label, e["lost_motion_um"], e.options["feedback"], e.stage
    ('backlash.x', 8.0, 'motor', 'loop')

    A backlash's ``feedback`` says where the position loop's encoder is,
    which is the axis's setting (``position_feedback``): left out
    (``None``), a :class:`~contoursim.model.Model` fills in the axis's;
    given, the model's axis reads there, the effect's setting winning (a
    machine file that does not say where its encoder is, with a backlash
    found on a scale). A file that gives its axis's ``position_feedback``
    and a backlash's other ``feedback`` is refused
    (:func:`~contoursim.model.with_file_effects`).
    """

    name: str
    axis: str
    parameters: tuple
    options: dict

    def __init__(self, name, axis, **values):
        kind = effect_kind(name)
        if not isinstance(axis, str):
            raise TypeError(f"{name}: axis must be a string of axis letters, got {axis!r}")
        if len(axis) != kind.n_axes or set(axis) - set(_AXES) or len(set(axis)) != len(axis):
            wanted = "one axis letter" if kind.n_axes == 1 else f"{kind.n_axes} different axis letters (like 'xy')"
            raise ValueError(f"{name}: axis must be {wanted} of x, y, z, got {axis!r}")
        unknown = [k for k in values if k not in kind.parameter_names and k not in kind.options]
        if unknown:
            raise ValueError(
                f"{name}: unknown parameter {unknown[0]!r}"
                f"{_validate.closest(unknown[0], kind.parameter_names + tuple(kind.options))}; its parameters are "
                f"{', '.join(kind.parameter_names + tuple(kind.options))}"
            )
        size = kind.parameters[0].name
        if size not in values:
            raise ValueError(f"{name}: missing {size!r} [{kind.parameters[0].unit}]: {kind.parameters[0].doc}")
        params = []
        for p in kind.parameters:
            try:
                params.append(replace(p, value=values.get(p.name, p.value)))
            except (TypeError, ValueError) as exc:
                raise type(exc)(f"{name}.{axis}: {exc}") from None
        options = {}
        for key, allowed in kind.options.items():
            value = values.get(key)
            options[key] = _option(name, axis, key, allowed, value)
        object.__setattr__(self, "name", name)
        object.__setattr__(self, "axis", axis)
        object.__setattr__(self, "parameters", tuple(params))
        object.__setattr__(self, "options", _validate.Frozen(options))

    @property
    def kind(self):
        """The registered :class:`EffectKind`."""
        return _REGISTRY[self.name]

    @property
    def stage(self):
        """Where in the data flow it acts: one of :data:`STAGES`."""
        stage = self.kind.stage
        return stage if isinstance(stage, str) else stage[1][self.options[stage[0]]]

    @property
    def label(self):
        """``<name>.<axis>``, the prefix of its parameters' flat names in a model."""
        return f"{self.name}.{self.axis}"

    def __getitem__(self, name):
        """The value of parameter `name` [its unit]."""
        for p in self.parameters:
            if p.name == name:
                return p.value
        raise KeyError(f"{self.name} has no parameter {name!r}; its parameters are {', '.join(self.kind.parameter_names)}")

    def values(self):
        """``{parameter name: value}`` in the parameters' units."""
        return {p.name: p.value for p in self.parameters}

    def set_options(self):
        """``{option: value}`` of the options not at their default (what a report needs to say of them)."""
        return {key: value for key, value in self.options.items()
                if value != _option(self.name, self.axis, key, self.kind.options[key], None)}

    def with_values(self, **values):
        """A copy with some parameter values (or options) changed."""
        return Effect(self.name, self.axis, **{**self.values(), **self.options, **values})

    def with_vary(self, **vary):
        """A copy where the named parameters may (True) or may not (False) be varied by a fit."""
        unknown = [k for k in vary if k not in self.kind.parameter_names]
        if unknown:
            raise ValueError(f"{self.name} has no parameter {unknown[0]!r}; its parameters are {', '.join(self.kind.parameter_names)}")
        params = tuple(replace(p, vary=vary.get(p.name, p.vary)) for p in self.parameters)
        copy = Effect(self.name, self.axis, **{**self.values(), **self.options})
        object.__setattr__(copy, "parameters", params)
        return copy

    def __hash__(self):
        return hash((self.name, self.axis, self.parameters, tuple(self.options.items())))

    def __repr__(self):
        args = [f"{k}={v!r}" for k, v in {**self.values(), **self.options}.items()]
        return f"Effect({self.name!r}, {self.axis!r}, {', '.join(args)})"


def _option(name, axis, key, allowed, value):
    """An option's value checked against what it allows (default when `value` is None)."""
    if allowed is int:  # a seed
        return 0 if value is None else _validate.seed(f"{name}.{axis}: {key}", value)
    if allowed == "axes":
        choices = tuple(a for a in _AXES if a not in axis)
        default = next(a for a in choices)
    else:
        choices, default = tuple(allowed), allowed[0]
    if value is None:
        return default
    if value not in choices:
        listed = ", ".join(repr(c) for c in choices if c is not None)
        raise ValueError(f"{name}.{axis}: {key} must be one of {listed}, got {value!r}")
    return value


# -- the catalogue -----------------------------------------------------------------------------

_INF = np.inf
#: Largest friction force [N]: beyond what the biggest machine-tool feed drives push (tens of kN), 500 times
#: the top of a typical friction; the viscous part's, 1e6 N·s/m, gives as much at 0.1 m/s.
_MAX_FRICTION_N = 1e5


def _p(name, value, unit, bounds, typical=None, vary=True, doc=""):
    return Parameter(name, value, unit, bounds, typical, vary, doc)


_register(EffectKind(
    "backlash", "loop",
    (_p("lost_motion_um", 0.0, "µm", (0.0, 1000.0), (2.0, 20.0), doc="lost motion between motor/screw and table"),),
    options={"feedback": (None, "motor", "scale"), "approach": ("none", "+", "-")},
    doc="lost motion at reversal; feedback 'motor': the table lags, 'scale': the loop sees it (hunting risk); "
        "the axis's position_feedback when not given, and the axis's when given (refused against the position_feedback "
        "its file gives the axis); on an axis with a compliant screw "
        "a dead zone in the screw (the table, with its mass, crosses it when the force on it reverses), else a play "
        "(the table stops when the motor reverses); approach '+' or '-': the axis came to its start moving that way, "
        "which closed the play on that side (a first move the same way takes the table along at once), 'none': the "
        "play centred, as a simulation starts",
))
_register(EffectKind(
    "coulomb_friction", "loop",
    (
        _p("force_N", 0.0, "N", (0.0, _MAX_FRICTION_N), (5.0, 200.0), doc="Coulomb friction level while sliding"),
        _p("viscous_N_s_per_m", 0.0, "N·s/m", (0.0, 10 * _MAX_FRICTION_N), (0.0, 2000.0), vary=False,
           doc="viscous friction on top of the machine's damping"),
        _p("stribeck_N", 0.0, "N", (0.0, _MAX_FRICTION_N), (0.0, 50.0), vary=False, doc="extra static (breakaway) friction decaying with speed"),
        _p("stribeck_velocity_mm_s", 1.0, "mm/s", (1e-3, _INF), (0.1, 10.0), vary=False, doc="speed scale of the Stribeck decay"),
        _p("asymmetry_N", 0.0, "N", (-_MAX_FRICTION_N, _MAX_FRICTION_N), (0.0, 10.0), vary=False,
           doc="added to the friction force while moving, whatever the direction"),
        _p("offset_N", 0.0, "N", (-_MAX_FRICTION_N, _MAX_FRICTION_N), (0.0, 10.0), vary=False,
           doc="constant force (gravity on an inclined axis, cable drag)"),
    ),
    doc="friction force opposing motion in the loop: reversal spikes (quadrant glitches)",
))
_register(EffectKind(
    "gain_mismatch", "servo",
    (_p("kp_ratio", 1.0, "-", (0.1, 10.0), (0.7, 1.3), doc="the axis's actual position gain over its nominal one"),),
    doc="one axis's position gain differs from the others",
))
_register(EffectKind(
    "squareness", "geometry",
    (_p("angle_urad", 0.0, "µrad", (-1e5, 1e5), (20.0, 200.0), doc="out-of-squareness; positive: the angle between the positive axes exceeds 90°"),),
    n_axes=2,
    doc="out-of-squareness of two axes",
))
_register(EffectKind(
    "scale_error", "geometry",
    (_p("ppm", 0.0, "µm/m", (-1e5, 1e5), (10.0, 100.0), doc="linear positioning error per travel"),),
    doc="linear positioning error of an axis",
))
_register(EffectKind(
    "cyclic_error", "geometry",
    (
        _p("amplitude_um", 0.0, "µm", (0.0, 1000.0), (1.0, 5.0), doc="amplitude of the periodic positioning error"),
        _p("period_mm", 10.0, "mm", (0.1, 1000.0), (4.0, 40.0), vary=False, doc="its spatial period (the screw lead)"),
        _p("phase_deg", 0.0, "deg", (-360.0, 360.0), doc="phase of amplitude·sin(2π·q/period + phase) at axis position q"),
    ),
    doc="periodic positioning error along the axis, period = screw lead",
))
_register(EffectKind(
    "straightness", "geometry",
    (
        _p("peak_um", 0.0, "µm", (-1e4, 1e4), (2.0, 15.0),
           doc="deviation perpendicular to the motion at the middle of the travel, off the line through its ends"),
        # where a trace's positions and a machine's travel may lie, ±1e6 mm (a bow over the trace's own extent)
        _p("span_mm", 100.0, "mm", (1.0, 2e6), vary=False, doc="length of the axis's travel, over which the bow rises from 0 to peak_um and back"),
        _p("start_mm", 0.0, "mm", (-1e6, 1e6), vary=False, doc="axis position (machine coordinates) where the travel starts"),
    ),
    options={"error_direction": "axes"},
    doc="bow of one axis's guideway over its travel: peak·(1 − (2(q − start)/span − 1)²) at axis position q",
))
_register(EffectKind(
    "time_delay", ("kind", {"command": "command", "feedback": "loop", "position": "loop"}),
    (_p("delay_s", 0.0, "s", (0.0, 0.1), (1e-4, 3e-3), doc="extra delay, fractions of the servo period interpolated"),),
    options={"kind": ("command", "feedback", "position")},
    doc="extra delay on one axis: of its command, of its position and velocity loops' feedback, or of its "
        "position loop's only",
))
_register(EffectKind(
    "thermal_drift", "geometry",
    (
        _p("rate_um_per_min", 0.0, "µm/min", (-1e4, 1e4), (1.0, 10.0), doc="drift rate along the axis at the start, at reference_mm"),
        _p("time_constant_s", 0.0, "s", (0.0, 1e6), vary=False, doc="0: linear in time; else first-order, rate·τ·(1 − exp(−t/τ))"),
        _p("growth_ppm_per_min", 0.0, "ppm/min", (-1e4, 1e4), (0.5, 5.0),
           doc="thermal growth: the drift rate grows by this many µm/min per m of axis position from reference_mm"),
        _p("reference_mm", 0.0, "mm", (-1e6, 1e6), vary=False, doc="axis position where the growth is zero (the screw's fixed end, or the axis zero)"),
    ),
    doc="slow drift of an axis's position in time, growing with the distance from reference_mm (seed 004's δt(q))",
))
_register(EffectKind(
    "vibration", "loop",
    (
        _p("freq_hz", 50.0, "Hz", (1.0, 1e4), (30.0, 150.0), doc="frequency of the structural mode (tool side on a spring)"),
        _p("damping_ratio", 0.05, "-", (1e-4, 1.0), (0.01, 0.2), doc="its damping ratio"),
        _p("mass_ratio", 0.2, "-", (1e-3, 0.999), (0.05, 0.5), vary=False, doc="tool-side mass over the axis's total mass"),
    ),
    doc="lightly damped structural mode excited by acceleration",
))
_register(EffectKind(
    "quantisation", "loop",
    (_p("resolution_um", 0.0, "µm", (0.0, 1000.0), (0.01, 1.0), doc="encoder resolution the loop sees"),),
    doc="encoder quantisation (outside the catalogue)",
))
_register(EffectKind(
    "noise", "loop",
    (_p("rms_um", 0.0, "µm", (0.0, 1000.0), (0.05, 0.5),
        doc="measurement noise on the recorded tool position, or on the encoder the loop closes on"),),
    options={"seed": int, "at": ("recorded", "encoder")},
    doc="measurement noise, deterministic per seed (outside the catalogue)",
))


# -- files -------------------------------------------------------------------------------------


def read_effects(toml, *keys):
    """The ``[[effect]]`` tables of a machine or job file.

    Parameters
    ----------
    toml : contoursim.config.TomlFile
        The parsed file.
    *keys : str
        Path of the table holding ``effect`` (none: the top level).

    Returns
    -------
    tuple of Effect
        In file order; empty without ``[[effect]]`` tables.

    Raises
    ------
    ConfigError
        Naming the file and line: an unknown effect name (listing the
        catalogue), an unknown parameter (listing the effect's), a bad value.
    """
    table = toml.table(*keys) if keys else toml.data
    raw = table.get("effect", [])
    if not isinstance(raw, list):
        raise toml.error("effect must be an array of tables ([[effect]])", *keys, "effect")
    effects = []
    for i, item in enumerate(raw):
        where = (*keys, "effect", i)
        if not isinstance(item, dict):
            raise toml.error("effect must be an array of tables ([[effect]])", *keys, "effect")
        for key in ("name", "axis"):
            if key not in item:
                raise toml.error(f"[[effect]] needs '{key}'", *where)
        toml.table(*where, text={"name": "an effect's name", "axis": "axis letters"})
        try:
            kind = effect_kind(item["name"])
        except ValueError as exc:
            raise toml.error(str(exc), *where, "name") from None
        values = {k: v for k, v in item.items() if k not in ("name", "axis")}
        try:
            effects.append(Effect(kind.name, item["axis"], **values))
        except (TypeError, ValueError) as exc:
            message = str(exc)
            said = message.split(": ", 1)[-1]
            bad = next((k for k in (*values, "axis") if repr(k) in message or said.startswith(k)), None)
            raise toml.error(f"[[effect]] {message}", *where, *((bad,) if bad else ())) from None
    return tuple(effects)
