"""A model: a nominal machine plus effects, and what each stage of the data flow makes of them.

A :class:`Model` is structure (the :class:`~contoursim.machine.Machine`)
plus a tuple of :class:`~contoursim.effects.Effect`. Its parameters have flat
names ``<effect>.<axis>.<parameter>`` (``backlash.x.lost_motion_um``);
:meth:`Model.with_values` makes a variant cheaply (no python-control
analysis: that runs once per nominal servo), which is what a fit or a batch of
variants needs.

How each stage realises its effects (:data:`contoursim.effects.STAGES`):

- command: :meth:`Model.commands` delays an axis's position, velocity and
  acceleration commands by ``delay_s`` (linear interpolation between
  samples for fractions of the servo period);
- servo: :meth:`Model.servos` scales an axis's position gain by ``kp_ratio``;
- loop: :meth:`Model.loop_effects` fills the kernel's per-axis
  :class:`contoursim.kernel.LoopEffects`;
- geometry: :meth:`Model.geometry` adds terms to the multibody chain's error
  motions, squareness and thermal drift (on top of what the machine has; a
  machine without bodies gets :func:`~contoursim.multibody.cartesian_chain`).
  How a geometric effect maps onto a body of axis ``a`` (``s`` = the body's
  sign, ``side`` = +1 on the tool branch, −1 on the workpiece branch, so that
  the tool tip relative to the workpiece moves as the effect says):

  ============== ========================================================================
  effect         term added to the body driven by the axis
  ============== ========================================================================
  squareness ab  ``squareness[dir(b)] += angle``: the tool moves along (1, −angle) in
                 (a, b) for a motion of a, the angle between +a and +b exceeds 90°
  scale_error    positioning error ``p1 += s·ppm·1e-6``: tool travel q·(1 + ppm·1e-6)
  cyclic_error   ``s·amplitude·sin(2π·q/period + phase)`` on the positioning error
  straightness   ``side·peak·(1 − (2(q − start)/span − 1)²)`` on the error motion along
                 error_direction: zero at both ends of the travel [start, start + span],
                 peak in its middle, wherever the path lies
  thermal_drift  ``thermal[dir] += s·rate``, ``thermal_growth[dir] += s·growth`` from
                 ``reference_mm`` (with ``time_constant_s`` the body's first-order time
                 constant): the drift ``τ(t)·(rate + growth·(q − reference))``
  ============== ========================================================================
"""

from collections.abc import Mapping
from dataclasses import dataclass, replace
from functools import cached_property

import numpy as np

from . import kernel
from .config import TomlFile
from .effects import Effect, read_effects
from .errormotion import _MM_PER_UM, _RAD_PER_URAD, Cyclic
from .machine import Machine, load_machine, preset_file
from .multibody import cartesian_chain

__all__ = ["Model", "as_model", "load_model", "with_file_effects"]


@dataclass(frozen=True)
class Model:
    """A nominal machine plus effects.

    Parameters
    ----------
    machine : Machine
        The nominal machine.
    effects : tuple of Effect
        At most one effect of a name per axis (labels ``name.axis`` unique);
        in-loop, servo and command effects act on servo axes, geometric ones
        on linear axes of the chain (any of x, y, z without one). A feedback
        ``time_delay`` is at most :data:`contoursim.kernel.MAX_DELAY_SAMPLES`
        servo periods.

    Examples
    --------
    >>> from contoursim.machine import load_machine
    >>> model = Model(load_machine("demo_mill"), (Effect("backlash", "x", lost_motion_um=8.0),))
    >>> model.values()
    {'backlash.x.lost_motion_um': 8.0}
    >>> model.with_values({"backlash.x.lost_motion_um": 12.0}).effects[0]["lost_motion_um"]
    12.0
    """

    machine: Machine
    effects: tuple = ()

    def __post_init__(self):
        if not isinstance(self.machine, Machine):
            raise TypeError(f"machine must be a Machine, got {type(self.machine).__name__}")
        if isinstance(self.effects, Effect):  # iterable by its __getitem__: it would fail as 'no parameter 0'
            raise TypeError(f"effects must be a sequence of Effect objects: give ({self.effects!r},), not the effect alone")
        try:
            effects = tuple(self.effects)
        except TypeError:  # None, a number
            raise TypeError(f"effects must be a sequence of Effect objects, e.g. (Effect('backlash', 'x', "
                            f"lost_motion_um=5.0),), got {type(self.effects).__name__}") from None
        for e in effects:
            if not isinstance(e, Effect):
                raise TypeError(f"effects must be Effect objects, got {type(e).__name__}")
        labels = [e.label for e in effects]
        repeated = sorted({label for label in labels if labels.count(label) > 1})
        if repeated:
            raise ValueError(f"one effect of a name per axis: {', '.join(repeated)} given more than once")
        servo_axes = tuple(self.machine.axes)
        chain = self.machine.chain
        linear = tuple(servo_axes) if chain is None else tuple(a for a in chain.axes if chain.axis_kind(a) == "linear")
        for e in effects:
            allowed = linear if e.stage == "geometry" else servo_axes
            direction = e.options.get("error_direction", "")  # a straightness's: an axis too
            missing = [a for a in e.axis + direction if a not in allowed]
            if missing:
                what = "linear axes" if e.stage == "geometry" else "servo axes"
                which = f"error_direction {direction!r}: " if missing[0] not in e.axis else ""
                raise ValueError(f"{e.label}: {which}the machine has no axis {missing[0]!r} among its {what} "
                                 f"({', '.join(allowed)})")
            if _delay_problem(e, self.machine):
                raise ValueError(_delay_problem(e, self.machine))
        for e in effects:
            if e.name == "vibration" and self.machine.axes[e.axis].compliant:
                raise ValueError(f"{e.label}: axis {e.axis} has a compliant screw (motor_mass, screw_stiffness), whose "
                                 "mode is the one structural mode the kernel holds per axis: no vibration beside it")
        machine = self.machine
        for e in effects:  # a backlash's feedback, given, is where its axis's position loop reads
            servo = machine.axes.get(e.axis) if e.name == "backlash" else None
            if servo is not None and e.options["feedback"] not in (None, servo.position_feedback):
                machine = replace(machine, axes={**machine.axes, e.axis: replace(servo, position_feedback=e.options["feedback"])})
        effects = tuple(_bound_feedback(e, machine) for e in effects)
        object.__setattr__(self, "machine", machine)
        object.__setattr__(self, "effects", effects)

    # -- parameters --------------------------------------------------------------------------

    def parameters(self):
        """Every effect parameter by flat name ``<effect>.<axis>.<parameter>``, dict of :class:`Parameter`."""
        return {f"{e.label}.{p.name}": p for e in self.effects for p in e.parameters}

    def values(self):
        """Every effect parameter's value by flat name [its unit]."""
        return {name: p.value for name, p in self.parameters().items()}

    def with_values(self, values):
        """A variant with some parameter values changed (cheap: no loop analysis).

        Parameters
        ----------
        values : mapping str -> float
            Flat names (:meth:`parameters`) -> new values [their units].

        Returns
        -------
        Model
        """
        if not isinstance(values, Mapping):
            raise TypeError(f"values must be a mapping of flat parameter names to values, got {type(values).__name__}")
        by_label = {e.label: i for i, e in enumerate(self.effects)}
        changes = {}
        for name, value in values.items():
            label, _, key = str(name).rpartition(".")
            if label not in by_label or key not in self.effects[by_label[label]].kind.parameter_names:
                known = ", ".join(self.parameters()) or "none (the model has no effects)"
                raise ValueError(f"unknown model parameter {name!r}; the model's parameters are: {known}")
            changes.setdefault(label, {})[key] = value
        effects = list(self.effects)
        for label, change in changes.items():
            i = by_label[label]
            effects[i] = _keep_vary(effects[i].with_values(**change), effects[i])
        return Model(self.machine, tuple(effects))

    def with_effect(self, effect):
        """A model with `effect` added, replacing an effect of the same name on the same axis."""
        if not isinstance(effect, Effect):  # its .label, not found, said nothing of what an effect is
            raise TypeError(f"effect must be an Effect, e.g. Effect('backlash', 'x', lost_motion_um=5.0), got "
                            f"{type(effect).__name__}")
        kept = tuple(e for e in self.effects if e.label != effect.label)
        return Model(self.machine, kept + (effect,))

    def variants(self, rows):
        """Variants of this model, one per mapping of flat parameter names to values (:meth:`with_values`)."""
        if isinstance(rows, (Mapping, str)):  # its keys would be taken for the rows
            raise TypeError(f"rows must be a sequence of mappings of flat parameter names to values, e.g. "
                            f"[{{'backlash.x.lost_motion_um': 8.0}}], got a {type(rows).__name__}: put it in a list")
        return [self.with_values(row) for row in rows]

    def stage(self, stage):
        """The effects acting at `stage` (one of :data:`contoursim.effects.STAGES`)."""
        return tuple(e for e in self.effects if e.stage == stage)

    # -- the stages ------------------------------------------------------------------------

    def servos(self):
        """Servo axes with the servo-stage effects applied (``gain_mismatch``), dict axis -> AxisServo."""
        servos = dict(self.machine.axes)
        for e in self.stage("servo"):
            servos[e.axis] = replace(servos[e.axis], kp=servos[e.axis].kp * e["kp_ratio"])
        return servos

    def loop_effects(self):
        """The in-loop effects of each servo axis, dict axis -> :class:`contoursim.kernel.LoopEffects`.

        Axes without in-loop effects get the all-off default.
        """
        fields = {axis: {} for axis in self.machine.axes}
        for e in self.stage("loop"):
            fields[e.axis].update(_LOOP[e.name](e))
        return {axis: kernel.LoopEffects(**f) if f else _NO_LOOP_EFFECTS for axis, f in fields.items()}

    def commands(self, q, v, a):
        """Axis commands after the command stage (``time_delay`` with ``kind = "command"``).

        Parameters
        ----------
        q, v, a : ndarray, shape (N, n_axes)
            Position, velocity, acceleration commands, columns as
            ``machine.axis_names`` [mm, mm/s, mm/s^2], sampled at the servo period.

        Returns
        -------
        q, v, a : ndarray, shape (N, n_axes)
            Each delayed axis's columns shifted late by ``delay_s``: the value at
            ``t − delay``, interpolated linearly between samples, the first
            sample held before the start. Other columns unchanged (the same arrays
            when nothing is delayed).
        """
        delays = self.stage("command")
        if not delays:
            return q, v, a
        q, v, a = q.copy(), v.copy(), a.copy()
        names = self.machine.axis_names
        for e in delays:
            shift = e["delay_s"] / self.machine.servo_period
            col = names.index(e.axis)
            for x in (q, v, a):
                x[:, col] = _delayed(x[:, col], shift)
        return q, v, a

    @cached_property
    def geometry(self):
        """The machine with the geometric effects added to its chain (the machine itself without any)."""
        effects = self.stage("geometry")
        if not effects:
            return self.machine
        chain = self.machine.chain or cartesian_chain(tuple(self.machine.axes))
        bodies = list(chain.bodies)
        for e in effects:
            try:
                j = _linear_body(chain, e.axis[0])
                side = 1.0 if j in chain.tool_chain else -1.0
                bodies[j - 1] = _GEOMETRY[e.name](e, bodies[j - 1], side, chain)
            except ValueError as exc:
                raise ValueError(f"{e.label}: {exc}") from None
        # a machine without bodies keeps its coordinates: the Cartesian chain's origin at the axes' zero, travel aside
        return replace(self.machine, chain=replace(chain, bodies=tuple(bodies)), axis_travel=None)


def as_model(model_or_machine):
    """A :class:`Model` as given, or a :class:`Machine` as a model without effects.

    Parameters
    ----------
    model_or_machine : Model or Machine

    Returns
    -------
    Model
    """
    if isinstance(model_or_machine, Model):
        return model_or_machine
    if isinstance(model_or_machine, Machine):
        return Model(model_or_machine)
    raise TypeError(f"expected a Model or a Machine, got {type(model_or_machine).__name__}")


def load_model(name_or_file, geometry=True, check=True):
    """A machine file (or preset) with its ``[[effect]]`` tables, as a :class:`Model`.

    Parameters
    ----------
    name_or_file : str or Path
        As for :func:`contoursim.machine.load_machine`.
    geometry, check : bool
        As for :func:`contoursim.machine.load_machine`.

    Returns
    -------
    Model

    Raises
    ------
    ConfigError
        Naming the file and line of a bad machine key or ``[[effect]]`` table,
        or of an effect on an axis the machine lacks.
    UnstableLoopError
        As for :func:`contoursim.machine.load_machine`.
    """
    file = preset_file(name_or_file)
    machine = load_machine(file, geometry=geometry, effects=True, check=check)
    return with_file_effects(Model(machine), TomlFile.read(file))


def with_file_effects(model, toml):
    """`model` with the ``[[effect]]`` tables of a machine or job file added.

    An effect of the same name and axis as one of `model` replaces it (a job
    file's effect overrides its machine file's); the same effect twice in
    one file is refused, and so is a backlash whose ``feedback`` differs
    from the ``position_feedback`` the same file gives its axis (the file
    says where that loop reads; a backlash's ``feedback`` is for a file that
    does not, see :class:`~contoursim.effects.Effect`).

    Parameters
    ----------
    model : Model
    toml : contoursim.config.TomlFile
        The parsed file.

    Returns
    -------
    Model

    Raises
    ------
    ConfigError
        Naming the file and line of a bad table, of an effect on an axis the
        machine lacks or beyond what it allows, of an effect given twice, or
        of a backlash's feedback against its axis's in the file.
    """
    first = {}
    for i, effect in enumerate(read_effects(toml)):
        if effect.label in first:
            raise toml.error(f"{effect.label} is given twice in this file (in [[effect]] tables {first[effect.label] + 1} "
                             f"and {i + 1}): one effect of a name per axis; merge the two", "effect", i, "name")
        first[effect.label] = i
        if _delay_problem(effect, model.machine):
            raise toml.error(_delay_problem(effect, model.machine), "effect", i, "delay_s")
        axis = toml.data.get("axes", {}).get(effect.axis, {})  # the file's own axis table (a job file has none)
        said = axis.get("position_feedback") if effect.name == "backlash" else None
        if said is not None and effect.options["feedback"] not in (None, said):
            raise toml.error(f"{effect.label}: feedback = {effect.options['feedback']!r}, but this file's axis "
                             f"{effect.axis} says where its position loop reads: position_feedback = {said!r} (line "
                             f"{toml.line_of('axes', effect.axis, 'position_feedback')}); a backlash is read where its "
                             "axis's loop reads: leave feedback out, or change the axis's position_feedback",
                             "effect", i, "feedback")
        try:
            model = model.with_effect(effect)
        except (TypeError, ValueError) as exc:
            raise toml.error(str(exc), "effect", i, "axis") from None
    return model


def _delay_problem(effect, machine):
    """What is wrong with `effect` as a feedback delay of `machine` (beyond the kernel's ring buffer), or None."""
    most = kernel.MAX_DELAY_SAMPLES * machine.servo_period
    if effect.name == "time_delay" and effect.stage == "loop" and effect["delay_s"] > most * (1 + 1e-12):
        return (f"{effect.label}: a feedback delay is at most {kernel.MAX_DELAY_SAMPLES} servo periods, {most:.6g} s "
                f"on this machine, got delay_s = {effect['delay_s']:g} s; a command delay (kind = \"command\") may be up to 0.1 s")
    return None


def _bound_feedback(effect, machine):
    """`effect`, a backlash's ``feedback`` filled in with where its axis's position loop reads."""
    if effect.name != "backlash" or effect.options["feedback"] is not None:
        return effect
    return _keep_vary(effect.with_values(feedback=machine.axes[effect.axis].position_feedback), effect)


def _keep_vary(new, old):
    """`new` with the vary flags of `old`'s parameters."""
    return new.with_vary(**{p.name: p.vary for p in old.parameters})


def _delayed(x, shift):
    """``x`` sampled `shift` samples late (fractions interpolated linearly), the first sample held before the start."""
    whole = int(np.floor(shift))
    frac = shift - whole
    index = np.arange(x.size) - whole
    now = x[np.clip(index, 0, None)]
    before = x[np.clip(index - 1, 0, None)]
    return now if frac == 0 else (1.0 - frac) * now + frac * before


def _linear_body(chain, axis):
    """Index of the one linear body driven by `axis`."""
    found = [j for j, b in enumerate(chain.bodies, start=1) if b.axis == axis and b.joint == "linear"]
    if len(found) != 1:
        raise ValueError(f"a geometric effect needs exactly one linear body driven by axis {axis!r}, found {len(found)}")
    j = found[0]
    if (j in chain.tool_chain) == (j in chain.work_chain):
        raise ValueError(f"the body of axis {axis!r} moves neither the tool nor the workpiece alone")
    return j


def _add_motion(body, component, poly=(), cyclic=()):
    """`body` with polynomial coefficients and cyclic terms added to one error motion."""
    motion = list(body.motion)
    old = motion[component]
    coeffs = np.zeros(max(len(old.poly), len(poly)))
    coeffs[: len(old.poly)] += old.poly
    coeffs[: len(poly)] += poly
    motion[component] = replace(old, poly=tuple(coeffs), cyclic=old.cyclic + tuple(cyclic))
    return replace(body, motion=tuple(motion))


def _squareness(e, body, side, chain):
    towards = chain.bodies[_linear_body(chain, e.axis[1]) - 1].direction
    squareness = body.squareness.copy()
    squareness[towards] += e["angle_urad"] * _RAD_PER_URAD
    return replace(body, squareness=squareness)


def _scale_error(e, body, side, chain):
    return _add_motion(body, body.direction, poly=(0.0, body.sign * e["ppm"] * 1e-6))


def _cyclic_error(e, body, side, chain):
    term = Cyclic.from_amplitude(body.sign * e["amplitude_um"] * _MM_PER_UM, e["period_mm"], np.radians(e["phase_deg"]))
    return _add_motion(body, body.direction, cyclic=(term,))


def _straightness(e, body, side, chain):
    direction = "xyz".index(e.options["error_direction"])
    if direction == body.direction:
        raise ValueError(f"error_direction {e.options['error_direction']!r} is the axis's own direction of motion")
    peak = side * e["peak_um"] * _MM_PER_UM
    middle = e["start_mm"] + e["span_mm"] / 2
    c = -peak * (2.0 / e["span_mm"]) ** 2  # peak·(1 − (2(q − middle)/span)²) = peak + c·(q − middle)²
    return _add_motion(body, direction, poly=(peak + c * middle**2, -2.0 * c * middle, c))


def _thermal_drift(e, body, side, chain):
    tau = e["time_constant_s"]
    if body.drifts and body.thermal_time_constant != tau:
        raise ValueError(
            f"body {body.name!r} already drifts with time constant {body.thermal_time_constant:g} s; "
            f"a drift with {tau:g} s cannot be added to it"
        )
    growth = e["growth_ppm_per_min"] * 1e-6 / 60.0  # [mm/s per mm]
    # a body that grows already keeps its reference: growth·(q − r_e) = growth·(q − r_b) + growth·(r_b − r_e)
    reference = body.thermal_reference if body.thermal_growth.any() else e["reference_mm"]
    thermal = body.thermal.copy()
    thermal[body.direction] += body.sign * (e["rate_um_per_min"] * _MM_PER_UM / 60.0 + growth * (reference - e["reference_mm"]))
    thermal_growth = body.thermal_growth.copy()
    thermal_growth[body.direction] += body.sign * growth
    return replace(body, thermal=thermal, thermal_growth=thermal_growth, thermal_reference=reference, thermal_time_constant=tau)


_GEOMETRY = {
    "squareness": _squareness,
    "scale_error": _scale_error,
    "cyclic_error": _cyclic_error,
    "straightness": _straightness,
    "thermal_drift": _thermal_drift,
}

_NO_LOOP_EFFECTS = kernel.LoopEffects()  # frozen: shared by the axes without any

_LOOP = {
    "backlash": lambda e: dict(backlash_mm=e["lost_motion_um"] * _MM_PER_UM,  # feedback: the servo's, bound by Model
                               backlash_approach={"none": 0, "+": 1, "-": -1}[e.options["approach"]]),
    "coulomb_friction": lambda e: dict(
        coulomb_N=e["force_N"],
        viscous_N_s_per_m=e["viscous_N_s_per_m"],
        stribeck_N=e["stribeck_N"],
        stribeck_velocity_mm_s=e["stribeck_velocity_mm_s"],
        asymmetry_N=e["asymmetry_N"],
        offset_N=e["offset_N"],
    ),
    "time_delay": lambda e: dict(feedback_delay_s=e["delay_s"],
                                 feedback_delay_on="position" if e.options["kind"] == "position" else "both"),
    "vibration": lambda e: dict(
        mode_freq_hz=e["freq_hz"], mode_damping_ratio=e["damping_ratio"], mode_mass_ratio=e["mass_ratio"]
    ),
    "quantisation": lambda e: dict(quantum_mm=e["resolution_um"] * _MM_PER_UM),
    "noise": lambda e: dict(noise_mm=e["rms_um"] * _MM_PER_UM, noise_at=e.options["at"], seed=e.options["seed"]),
}
