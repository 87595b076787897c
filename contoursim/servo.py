"""One axis of a CNC feed drive: the P / PI / PI servo cascade as python-control systems.

Block diagram (signal names as used by :func:`control.interconnect`)::

    x_ref ─▶(+)─ e_x ─▶[kp]─ v_p ─▶(+)─ v_cmd ─▶(+)─ e_v ─▶[velocity PI]─ i_pi ─▶(+)─ i_cmd ─▶ ...
             ▲ -                    ▲ v_ff         ▲ -                            ▲ i_ff
             x          v_ref ─▶[vff]              v              a_ref ─▶[aff m/kf]

    ... i_cmd ─▶(+)─ e_i ─▶[current PI]─ u ─▶[plant: electrical + mechanical]─▶ x, v, i
                 ▲ -
                 i

Without electrical dynamics (no ``inductance``) the current loop is taken as
ideal: the plant's input is the current command ``i_cmd`` itself, or, with
``current_bandwidth_hz``, the current follows it as the first-order lag the
closed current loop of a drive is (``di/dt = ω_c·(i_cmd - i)``, continuous
time: exact at any bandwidth, however close to the servo rate). The
velocity loop compares ``v_cmd`` with ``v_fb``, the output of the block
``estimator``: ``v`` itself, or, in the sampled loop of a drive with
``velocity_feedback="difference"``, the filtered difference of ``x``; and
``i_cmd`` leaves ``current_command_sum`` ``computation_delay`` periods late.

Units inside are mm, s, A, V. The parameters are SI (kg, N, N·s/m, A·s/m,
H, Ω) and are converted once, in the properties ``force_gain``,
``damping_rate``, ``kv_mm`` and ``emf_mm``.

The plant (a rigid translating mass ``m`` driven by the force ``kf·i``)::

    dx/dt = v                                        [mm/s]
    dv/dt = -(c/m)·v + (1000·kf/m)·i                 [mm/s^2]   (1000 mm per m)
    di/dt = (u - R·i - kf·v/1000) / L                [A/s]      (back-EMF constant = kf in SI)
    di/dt = ω_c·(i_cmd - i),  ω_c = 2π·current_bandwidth_hz        (instead: the closed current loop as a lag)

With a compliant screw (``motor_mass``, ``screw_stiffness``) the axis is two
masses: the motor side ``m1 = motor_mass`` (rotor and screw inertia
reflected; state ``x, v``, what the motor encoder reads) drives the table
``m2 = mass - motor_mass`` through the screw's axial stiffness ``k`` and a
damper ``c``; ``d`` is the table's deflection from the motor side (the
table is at ``x + d``)::

    m1·dv/dt = 1000·kf·i - c_v·v + k·d + c·ḋ          [kg·mm/s^2 = mN]   (c_v: `damping`, on the motor side)
    m2·(dv/dt + d²d/dt²) = -k·d - c·ḋ
    k = 1e6·screw_stiffness [N/m],  c = 2·ζ·sqrt(k·μ) [N·s/m],  μ = m1·m2/m

(the relative mode, the two masses swinging against each other, is at
``ω = sqrt(k/μ)`` [rad/s], damped ``ζ`` = `screw_damping_ratio`).

The position loop reads ``x`` (``position_feedback="motor"``) or the table
``x + d`` (``"scale"``, a linear scale); the velocity loop's difference reads
the motor encoder ``x`` always (a drive's dual feedback).

The sampled loop (:func:`discretize`) is what the kernel steps: the plant is
discretised exactly for a zero-order-hold input, the PI controllers by the
trapezoidal (Tustin) rule (the velocity PI by the rule ``velocity_integrator``
names, where given), and every controller reads the state sampled at
``t_k`` and holds its output over ``[t_k, t_k + dt)``.
"""

import dataclasses
import hashlib
import importlib.util
import json
import os
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

import numpy as np

from . import _validate
from ._numba import njit
from .exceptions import UnstableLoopError

__all__ = [
    "AxisServo",
    "DiscreteServo",
    "plant",
    "velocity_loop",
    "closed_loop",
    "sensitivity",
    "discretize",
    "zoh",
    "bandwidth",
    "margins",
    "check",
    "SamplingError",
    "MIN_PHASE_MARGIN_DEG",
    "MIN_DAMPING_RATIO",
    "MAX_CROSSOVER_FRACTION",
    "VELOCITY_FEEDBACK",
    "VELOCITY_INTEGRATORS",
    "POSITION_FEEDBACK",
    "SCREW_DAMPING_RATIO",
    "MAX_VELOCITY_TAPS",
    "MAX_COMPUTATION_DELAY",
]


class SamplingError(ValueError):
    """A servo loop too fast to simulate at its servo period (:func:`check`'s sampling criterion).

    Parameters
    ----------
    message : str
        Which axis and loop, and what to change.
    parameter : str
        The setting at fault: ``"dt"``, or the servo parameter (``"ti"``, ...) that makes the loop so fast.
    """

    def __init__(self, message, parameter):
        self.parameter = parameter
        super().__init__(message)


class _LazyControl:
    """python-control, imported on first use: the kernel imports this module, python-control is slow to import."""

    def __getattr__(self, name):
        import control

        return getattr(control, name)


ct = _LazyControl()

#: Largest value of a servo parameter in its SI unit (kg, N/A, A·s/m, s, 1/s, N·s/m, H, Ω, ...), and the inverse of
#: the smallest nonzero one (the feedforward fractions vff, aff aside): beyond, products of parameters in the loop
#: analysis overflow, and no machine has them.
MAX_PARAMETER = 1e12

#: A loop whose phase margin [deg] is below this is rejected as badly damped.
MIN_PHASE_MARGIN_DEG = 30.0
#: A loop whose closed-loop poles have a damping ratio below this is rejected.
MIN_DAMPING_RATIO = 0.2
#: A loop's gain crossover must stay below this fraction of the Nyquist frequency.
MAX_CROSSOVER_FRACTION = 0.25

#: Where the velocity loop's feedback comes from (:class:`AxisServo` ``velocity_feedback``).
VELOCITY_FEEDBACK = ("state", "difference")
#: How a sampled PI integrates (``velocity_integrator``), with the share of the present sample's error its integral
#: adds to the output: the trapezoidal (Tustin) rule half of it, the backward rectangle (``integral += e·dt/ti``, then
#: ``y = k·(e + integral)``) all of it, the forward rectangle (the sum up to the last sample) none.
VELOCITY_INTEGRATORS = {"tustin": 0.5, "backward": 1.0, "forward": 0.0}
#: Where the position loop's encoder is (:class:`AxisServo` ``position_feedback``).
POSITION_FEEDBACK = ("motor", "scale")
#: Damping ratio of a compliant screw's relative mode when a machine does not give it [-].
SCREW_DAMPING_RATIO = 0.03
#: Most taps of the moving average on the position before the velocity difference.
MAX_VELOCITY_TAPS = 8
#: Longest computation delay [servo periods].
MAX_COMPUTATION_DELAY = 2


@dataclass(frozen=True, kw_only=True)
class AxisServo:
    """Parameters of one feed-drive axis (SI at the edge, keyword-only).

    Parameters
    ----------
    mass : float
        Moving mass [kg], including the rotor and screw inertia reflected to
        the table (``J·(2π/lead)^2``).
    force_constant : float
        Feed force per motor current [N/A]; for a rotary motor on a ball screw
        ``kt·2π/lead``. Also the back-EMF constant [V·s/m] in SI.
    kv : float
        Velocity-controller proportional gain [A·s/m]: current command per
        velocity error. The velocity loop crosses over near
        ``kv·force_constant/mass`` [rad/s].
    kp : float, default 40
        Position-loop gain [1/s] (the "Kv factor": 1 (m/min)/mm = 16.67 1/s).
    ti : float, optional
        Velocity-controller integral time [s]. ``None`` (default): pure P
        velocity controller, as on many drives.
    damping : float, default 0
        Viscous damping of the slide [N·s/m].
    current_limit : float, optional
        Amplifier current limit [A]; the current command is clamped to
        ``±current_limit`` and the velocity integrator stops integrating
        while it is clamped (anti-windup). ``None`` (default): no limit.
    vff : float, default 0
        Velocity feedforward gain [-], 0..1, on the reference velocity.
    aff : float, default 0
        Acceleration feedforward gain [-], 0..1, on
        ``mass · reference acceleration / force_constant`` (a current [A]).
    inductance : float, optional
        Motor winding inductance [H]. When given, the electrical dynamics
        (with back-EMF) and an inner PI current loop are modelled, and
        `resistance`, `kc` and `ti_current` are required.
    resistance : float, optional
        Winding resistance [Ω].
    kc : float, optional
        Current-controller proportional gain [V/A]. The current loop crosses
        over near ``kc/inductance`` [rad/s].
    ti_current : float, optional
        Current-controller integral time [s]; ``inductance/resistance``
        cancels the electrical pole.
    current_bandwidth_hz : float, optional
        Bandwidth [Hz] of the closed current loop taken as a first-order lag
        of the current behind its command, ``ω_c/(s + ω_c)`` with ``ω_c =
        2π·f``: what a drive's data sheet quotes (typically 0.5–3 kHz).
        Part of the continuous plant (discretised exactly with it), so it
        may be as fast as it is, unlike the sampled current PI of
        `inductance`, which it replaces. ``None`` (default): an ideal
        current loop.
    velocity_feedback : {"state", "difference"}, default "state"
        What the velocity loop closes on: ``"state"``, the motor velocity
        itself (an ideal tachometer); ``"difference"``, as real drives do,
        the backward difference of the encoder position the position loop
        reads (quantised and delayed as it is), after a moving average of
        `velocity_taps` samples: ``(x_fb[k] - x_fb[k-n])/(n·dt)``.
    velocity_taps : int, default 1
        Taps ``n`` of that moving average (1: none; 2: the ``0.5/0.5`` FIR,
        ``(x[k] - x[k-2])/(2·dt)``), at most :data:`MAX_VELOCITY_TAPS`.
        Only with ``velocity_feedback="difference"``.
    velocity_filter_hz : float, optional
        Corner [Hz] of a first-order low-pass on the velocity difference,
        discretised with its pole mapped exactly and unit gain at DC:
        ``v_fb[k] = a·v_fb[k-1] + (1 - a)·raw[k]``, ``a = exp(-2π·f·dt)``
        (``None``: no filter). Only with ``velocity_feedback="difference"``.
    computation_delay : int, default 0
        Whole servo periods (0, 1 or 2) between sampling and the current
        command reaching the drive: the command computed from the samples
        at ``t_k`` is applied over ``[t_k+d, t_k+d+1)``.
    velocity_integrator : {"tustin", "backward", "forward"}, optional
        How the sampled velocity PI integrates (:data:`VELOCITY_INTEGRATORS`):
        ``y[k] = kv·(e[k] + (z[k] + s·dt·e[k])/ti)``, ``z`` the sum of the
        past errors times ``dt``, ``s`` = 1/2 for the trapezoidal rule, 1
        for the backward rectangle drive firmware often runs (the integral
        updated with the present error, then the output), 0 for the
        forward one. Drives differ and data sheets rarely say: ``None``
        (default) is not stated, simulated by the trapezoidal rule, and a
        diagnosis against the machine chooses it by the fit.
    position_feedback : {"motor", "scale"}, default "motor"
        Where the position loop's encoder is: the motor encoder
        (semi-closed loop) or a linear scale on the table (closed loop: it
        reads the table behind a compliant screw and behind a backlash).
        The velocity loop's difference reads the motor encoder either way,
        as drives with a direct measuring system do (dual feedback).
    motor_mass : float, optional
        The part of `mass` on the motor side of a compliant screw [kg]
        (rotor and screw inertia reflected to the table), ``0 < motor_mass
        < mass``. ``None`` (default): a rigid axis.
    screw_stiffness : float, optional
        Axial stiffness of the screw, nut and bearings between the motor
        side and the table [N/µm], the unit data sheets quote it in; given
        with `motor_mass` and only with it.
    screw_damping_ratio : float, optional
        Damping ratio of the two masses' relative mode [-], ``0 < ζ < 1``;
        only with `motor_mass`. ``None`` (default): :data:`SCREW_DAMPING_RATIO`
        (0.03, typical of ball screws: 0.02–0.05), on a compliant axis.

    Notes
    -----
    `velocity_feedback`, `velocity_taps`, `velocity_filter_hz` and
    `computation_delay` are the drive's structure: the sampled loop
    (:func:`discretize`, :func:`margins` with ``dt``) and the kernel have
    them; the continuous analyses take the difference as the derivative
    (with its low-pass) and no computation delay. The screw's relative
    mode is at ``sqrt(1e6·screw_stiffness·mass/(m1·m2))/2π`` [Hz]
    (:attr:`screw_mode_hz`).

    Examples
    --------
    >>> axis = AxisServo(mass=300.0, force_constant=900.0, kv=200.0)
    >>> round(axis.force_gain)                     # 1000·900/300 [mm/s^2 per A]
    3000
    """

    mass: float
    force_constant: float
    kv: float
    kp: float = 40.0
    ti: float | None = None
    damping: float = 0.0
    current_limit: float | None = None
    vff: float = 0.0
    aff: float = 0.0
    inductance: float | None = None
    resistance: float | None = None
    kc: float | None = None
    ti_current: float | None = None
    current_bandwidth_hz: float | None = None
    velocity_feedback: str = "state"
    velocity_taps: int = 1
    velocity_filter_hz: float | None = None
    computation_delay: int = 0
    velocity_integrator: str | None = None
    position_feedback: str = "motor"
    motor_mass: float | None = None
    screw_stiffness: float | None = None
    screw_damping_ratio: float | None = None

    def __post_init__(self):
        required = ("mass", "force_constant", "kv", "kp")
        checked = {name: _validate.positive(name, getattr(self, name)) for name in required}
        checked["damping"] = _validate.nonnegative("damping", self.damping)
        for name in ("vff", "aff"):
            gain = _validate.nonnegative(name, getattr(self, name))
            if gain > 1:
                raise ValueError(f"{name} must be between 0 and 1 (a fraction of full feedforward), got {gain!r}")
            checked[name] = gain
        for name in ("ti", "current_limit"):
            if getattr(self, name) is not None:
                checked[name] = _validate.positive(name, getattr(self, name))
        electrical = ("resistance", "kc", "ti_current")
        if self.inductance is None:
            given = [name for name in electrical if getattr(self, name) is not None]
            if given:
                raise ValueError(
                    f"{', '.join(given)} given without inductance: give inductance [H] to model the current "
                    "loop, or drop the current-loop parameters for an ideal current loop"
                )
        else:
            checked["inductance"] = _validate.positive("inductance", self.inductance)
            missing = [name for name in electrical if getattr(self, name) is None]
            if missing:
                raise ValueError(f"inductance is given, so the current loop needs {', '.join(missing)} as well")
            checked["resistance"] = _validate.nonnegative("resistance", self.resistance)
            checked["kc"] = _validate.positive("kc", self.kc)
            checked["ti_current"] = _validate.positive("ti_current", self.ti_current)
        if self.current_bandwidth_hz is not None:
            if self.inductance is not None:
                raise ValueError("current_bandwidth_hz takes the closed current loop as a lag and inductance models "
                                 "it in detail: give one or the other")
            checked["current_bandwidth_hz"] = _validate.positive("current_bandwidth_hz", self.current_bandwidth_hz)
        checked.update(self._drive_structure())
        checked.update(self._screw())
        for name, value in checked.items():
            if name not in ("vff", "aff") and value != 0 and not 1.0 / MAX_PARAMETER <= value <= MAX_PARAMETER:
                raise ValueError(f"{name} must lie within [{1.0 / MAX_PARAMETER:g}, {MAX_PARAMETER:g}] (in its SI unit), "
                                 f"got {value:g}: not a physical value")
            object.__setattr__(self, name, value)

    def _drive_structure(self):
        """The velocity feedback, integrator and computation delay settings, checked: ``{name: value}``."""
        if self.velocity_feedback not in VELOCITY_FEEDBACK:
            raise ValueError(f'velocity_feedback must be "state" or "difference", got {self.velocity_feedback!r}')
        checked = {"velocity_taps": _validate.positive_int("velocity_taps", self.velocity_taps)}
        if checked["velocity_taps"] > MAX_VELOCITY_TAPS:
            raise ValueError(f"velocity_taps must be at most {MAX_VELOCITY_TAPS}, got {self.velocity_taps}")
        delay = self.computation_delay
        if isinstance(delay, (bool, np.bool_)) or not isinstance(delay, (int, np.integer)):
            raise TypeError(f"computation_delay must be a whole number of servo periods, got {delay!r}")
        if not 0 <= delay <= MAX_COMPUTATION_DELAY:
            raise ValueError(f"computation_delay must be 0, 1 or {MAX_COMPUTATION_DELAY} servo periods, got {delay}")
        if self.velocity_filter_hz is not None:
            checked["velocity_filter_hz"] = _validate.positive("velocity_filter_hz", self.velocity_filter_hz)
        if self.velocity_integrator is not None and self.velocity_integrator not in VELOCITY_INTEGRATORS:
            raise ValueError(f"velocity_integrator must be one of {', '.join(map(repr, VELOCITY_INTEGRATORS))} (or "
                             f"not given), got {self.velocity_integrator!r}")
        if self.velocity_integrator is not None and self.ti is None:  # a P loop's: accepted, without effect
            raise ValueError("velocity_integrator says how the velocity PI integrates: it needs ti (a P velocity loop, "
                             "without ti, has no integral)")
        if self.velocity_feedback == "state" and (checked["velocity_taps"] != 1 or self.velocity_filter_hz is not None):
            raise ValueError('velocity_taps and velocity_filter_hz filter the encoder difference: they need '
                             'velocity_feedback = "difference"')
        return checked | {"computation_delay": int(delay)}

    def _screw(self):
        """The position feedback and the compliant screw, checked: ``{name: value}``."""
        if self.position_feedback not in POSITION_FEEDBACK:
            raise ValueError(f'position_feedback must be "motor" or "scale", got {self.position_feedback!r}')
        if self.motor_mass is None:
            given = [name for name in ("screw_stiffness", "screw_damping_ratio") if getattr(self, name) is not None]
            if given:
                raise ValueError(f"{', '.join(given)} given without motor_mass, the part of mass on the motor side: "
                                 "a compliant screw needs both")
            return {}
        if self.screw_stiffness is None:
            raise ValueError("motor_mass is given, so the compliant screw needs screw_stiffness [N/µm] as well")
        ratio = SCREW_DAMPING_RATIO if self.screw_damping_ratio is None else self.screw_damping_ratio
        ratio = _validate.positive("screw_damping_ratio", ratio)
        if ratio >= 1:
            raise ValueError(f"screw_damping_ratio must be between 0 and 1 (exclusive), got {ratio!r}")
        motor = _validate.positive("motor_mass", self.motor_mass)
        if motor >= self.mass:
            raise ValueError(f"motor_mass must be less than mass ({self.mass:g} kg): the part of it on the motor "
                             f"side, got {motor:g}")
        return dict(motor_mass=motor, screw_stiffness=_validate.positive("screw_stiffness", self.screw_stiffness),
                    screw_damping_ratio=ratio)

    # -- SI -> internal units (mm, s, A, V), the one place they are converted --------------

    @property
    def force_gain(self):
        """Acceleration per motor current, ``1000·force_constant/mass`` [mm/s^2 per A]."""
        return 1000.0 * self.force_constant / self.mass

    @property
    def damping_rate(self):
        """Viscous damping per mass, ``damping/mass`` [1/s]."""
        return self.damping / self.mass

    @property
    def kv_mm(self):
        """Velocity-controller gain in internal units, ``kv/1000`` [A per mm/s]."""
        return self.kv / 1000.0

    @property
    def integrator_share(self):
        """The share of the present sample's error the sampled velocity PI's integral adds to its output
        (:data:`VELOCITY_INTEGRATORS`; the trapezoidal rule's where `velocity_integrator` is not given)."""
        return VELOCITY_INTEGRATORS[self.velocity_integrator or "tustin"]

    @property
    def emf_mm(self):
        """Back-EMF per velocity in internal units, ``force_constant/1000`` [V per mm/s]."""
        return self.force_constant / 1000.0

    @property
    def compliant(self):
        """True when a compliant screw joins the motor side to the table (:attr:`motor_mass` given)."""
        return self.motor_mass is not None

    @property
    def screw_mode_hz(self):
        """Frequency of the screw's relative mode [Hz] (the two masses against each other); None when rigid."""
        if not self.compliant:
            return None
        reduced = self.motor_mass * (self.mass - self.motor_mass) / self.mass
        return float(np.sqrt(1e6 * self.screw_stiffness / reduced) / (2.0 * np.pi))

    @property
    def electrical(self):
        """True when the electrical dynamics and the current loop are modelled."""
        return self.inductance is not None

    # -- thin methods; the module functions do the work -------------------------------------

    def plant(self):
        """Continuous plant, see :func:`plant`."""
        return plant(self)

    def velocity_loop(self):
        """Closed velocity loop ``v_cmd -> v``, see :func:`velocity_loop`."""
        return velocity_loop(self)

    def closed_loop(self, feedforward=True):
        """Closed position loop ``x_ref -> x``, see :func:`closed_loop`."""
        return closed_loop(self, feedforward=feedforward)

    def sensitivity(self):
        """Sensitivity of the position loop ``x_ref -> e_x``, see :func:`sensitivity`."""
        return sensitivity(self)

    def discretize(self, dt):
        """Sampled loop for the kernel, see :func:`discretize`."""
        return discretize(self, dt)

    def bandwidth(self):
        """Half-power bandwidth of the closed position loop [Hz], see :func:`bandwidth`."""
        return bandwidth(self)

    def margins(self, dt=None):
        """Gain/phase margins of each loop, see :func:`margins`."""
        return margins(self, dt)

    def check(self, dt, axis="x"):
        """Reject a loop that cannot be simulated at `dt`, see :func:`check`."""
        return check(self, dt, axis)


@dataclass(frozen=True)
class DiscreteServo:
    """The sampled loop of one axis, as stepped by :mod:`contoursim.kernel`.

    Parameters
    ----------
    servo : AxisServo
        The continuous axis it was built from.
    dt : float
        Servo period [s].
    plant : control.StateSpace
        Exact ZOH plant, input ``'i_cmd'`` [A] (or ``'u'`` [V] with electrical
        dynamics), outputs ``'x'`` [mm], ``'v'`` [mm/s] (and ``'i'`` [A]).
    velocity_controller : control.StateSpace
        Velocity PI (its ``velocity_integrator``'s rule) or P, ``'e_v'`` [mm/s] -> ``'i_pi'`` [A].
    current_controller : control.StateSpace or None
        Current PI (Tustin), ``'e_i'`` [A] -> ``'u'`` [V]; ``None`` without
        electrical dynamics.
    closed_loop : control.StateSpace
        The whole sampled cascade, inputs ``'x_ref'`` [mm], ``'v_ref'``
        [mm/s], ``'a_ref'`` [mm/s^2], outputs ``'x'``, ``'v'``, ``'i_cmd'``
        (the command applied, after any computation delay).
    """

    servo: AxisServo
    dt: float
    plant: "control.StateSpace"
    velocity_controller: "control.StateSpace"
    current_controller: "control.StateSpace | None"
    closed_loop: "control.StateSpace"


# ---------------------------------------------------------------------------------------------
# Blocks


def _plant_matrices(servo, mode=None, gap_open=False):
    """The continuous plant ``(A, B, states)``: ``dq/dt = A q + B [u, F]`` over the states present.

    ``states`` lists which of ``x`` [mm], ``v`` [mm/s], ``d`` [mm], ``ḋ``
    [mm/s], ``i`` [A] (0 .. 4) the plant has: ``d, ḋ`` with a compliant
    screw or a `mode`, ``i`` with electrical dynamics or a current lag. The
    inputs are the voltage ``u`` [V] (electrical dynamics) or the current
    command [A], and a force ``F`` [N] on the motor side (the carriage).

    Parameters
    ----------
    servo : AxisServo
    mode : tuple, optional
        ``(m2, k, c)``: a mass [kg] of the axis's `mass` on a spring [N/m]
        and damper [N·s/m] against the rest (the kernel's structural mode);
        default: the servo's compliant screw, if any. Not both.
    gap_open : bool, default False
        A compliant screw's backlash gap open (the kernel's dead zone): no
        spring or damper between the motor side and the table, each mass
        slowed by its share of the `damping` (``damping·m_j/mass``: each
        decelerates as the whole axis would).
    """
    if servo.compliant and mode is not None:
        raise ValueError("an axis with a compliant screw (motor_mass) has its one mode: no other structural mode")
    m1 = servo.mass
    if servo.compliant:
        m1 = servo.motor_mass
        k = 1e6 * servo.screw_stiffness
        mode = (servo.mass - m1, k, 2.0 * servo.screw_damping_ratio * np.sqrt(k * m1 * (servo.mass - m1) / servo.mass))
        mode = (mode[0], 0.0, 0.0) if gap_open else mode
    elif mode is not None:
        m1 = servo.mass - mode[0]
    lagged = servo.current_bandwidth_hz is not None
    states = [0, 1] + ([2, 3] if mode else []) + ([4] if servo.electrical or lagged else [])
    A, B = np.zeros((5, 5)), np.zeros((5, 2))
    per_amp, per_newton = 1000.0 * servo.force_constant / m1, 1000.0 / m1
    carriage = np.zeros(5)  # dv/dt per state, without the current (an input without electrical dynamics)
    carriage[1] = -servo.damping / (servo.mass if gap_open else m1)
    A[0, 1] = 1.0
    B[1, 1] = per_newton
    if mode:
        m2, k, c = mode
        carriage[2], carriage[3] = k / m1, c / m1
        A[2, 3] = 1.0
        A[3] = -carriage  # d²d/dt² = -dv/dt - (k·d + c·ḋ)/m2
        A[3, 2] -= k / m2
        A[3, 3] -= c / m2
        if gap_open:  # the table's share of the damping on its velocity v + ḋ
            A[3, 1] -= servo.damping / servo.mass
            A[3, 3] -= servo.damping / servo.mass
        B[3, 1] = -per_newton
    A[1] += carriage
    if servo.electrical or lagged:
        A[1, 4] = per_amp
        A[3, 4] = -per_amp if mode else 0.0
    if servo.electrical:
        L = servo.inductance
        A[4, 1], A[4, 4] = -servo.emf_mm / L, -servo.resistance / L
        B[4, 0] = 1.0 / L
    elif lagged:
        w = 2.0 * np.pi * servo.current_bandwidth_hz
        A[4, 4], B[4, 0] = -w, w
    else:
        B[1, 0] = per_amp
        B[3, 0] = -per_amp if mode else 0.0
    return A[np.ix_(states, states)], B[states], states


def _motor_signal(servo):
    """The plant output the velocity difference reads: ``'x'``, or ``'x_motor'`` when the loop reads the table."""
    return "x_motor" if servo.compliant and servo.position_feedback == "scale" else "x"


def _plant_system(servo, A, B, states, dt):
    """The plant as a python-control system: input ``'u'`` or ``'i_cmd'``; outputs ``'x'`` (the position the loop
    closes on), ``'v'``, ``'i'`` (read by the current controller) and ``'x_motor'`` (see :func:`_motor_signal`)."""
    names = [("x", "v", "d", "w", "i")[j] for j in states]
    C = {"x": np.eye(len(states))[0], "v": np.eye(len(states))[1]}
    if _motor_signal(servo) == "x_motor":
        C["x_motor"] = C["x"]
        C["x"] = C["x"] + np.eye(len(states))[2]  # the scale reads the table, x + d
    if servo.electrical:
        C["i"] = np.eye(len(states))[-1]
    inputs = "u" if servo.electrical else "i_cmd"
    return ct.ss(A, B[:, :1], np.array(list(C.values())), 0.0, dt, inputs=inputs, outputs=list(C), states=names,
                 name="plant")


def zoh(A, B, dt):
    """Exact zero-order-hold discretisation ``(Ad, Bd)`` of ``dx/dt = A x + B u``.

    With ``u`` held constant over a step,
    ``x(t + dt) = e^{A dt} x(t) + (∫_0^dt e^{A τ} dτ) B u``. Both terms come
    from one matrix exponential: the augmented system
    ``d/dt [x; u] = [[A, B], [0, 0]] [x; u]`` (u constant) has the transition
    matrix ``expm([[A, B], [0, 0]] dt) = [[Ad, Bd], [0, I]]``, whose upper
    blocks are ``Ad = e^{A dt}`` and ``Bd = ∫_0^dt e^{A τ} dτ B``.

    Parameters
    ----------
    A : ndarray, shape (n, n)
    B : ndarray, shape (n, m)
    dt : float
        Sample period [s].

    Returns
    -------
    Ad : ndarray, shape (n, n)
    Bd : ndarray, shape (n, m)

    Examples
    --------
    A double integrator: ``Ad = [[1, dt], [0, 1]]``, ``Bd = [[dt²/2], [dt]]``.

    >>> Ad, Bd = zoh(np.array([[0.0, 1.0], [0.0, 0.0]]), np.array([[0.0], [1.0]]), 0.5)
    >>> Bd.ravel().tolist()
    [0.125, 0.5]
    """
    n, m = B.shape
    M = np.zeros((n + m, n + m))
    M[:n, :n], M[:n, n:] = A, B
    Phi = _expm(M * dt)
    return Phi[:n, :n], Phi[:n, n:]


#: Coefficients c_0 .. c_6 of the [6/6] Padé approximant of e^x, numerator sum(c_k x^k), denominator sum(c_k (-x)^k).
_PADE6 = (1.0, 1.0 / 2.0, 5.0 / 44.0, 1.0 / 66.0, 1.0 / 792.0, 1.0 / 15840.0, 1.0 / 665280.0)


def _expm(M):
    """Matrix exponential of a small matrix: [6/6] Padé approximant after scaling, then squaring.

    ``e^M = (e^{M/2^s})^{2^s}`` with ``||M/2^s||_1 <= 1/2``, where the [6/6]
    Padé approximant's relative error is below ``(6!)^2/(12!·13!)·0.5^13 ≈
    2e-17`` (Higham, SIAM J. Matrix Anal. Appl. 26, 2005): numpy only, a
    few small products and one solve (no scipy to import, nothing to compile).
    """
    c = _PADE6
    X = np.asarray(M, float)
    squarings = 0
    norm = np.abs(X).sum(axis=0).max()
    while norm > 0.5:
        norm /= 2.0
        squarings += 1
    X = X / 2.0**squarings
    eye = np.eye(X.shape[0])
    X2 = X @ X
    X4 = X2 @ X2
    even = c[0] * eye + c[2] * X2 + c[4] * X4 + c[6] * (X4 @ X2)
    odd = X @ (c[1] * eye + c[3] * X2 + c[5] * X4)
    E = np.linalg.solve(even - odd, even + odd)
    for _ in range(squarings):
        E = E @ E
    return E


def _gain(k, inp, out, dt):
    return ct.ss(np.zeros((0, 0)), np.zeros((0, 1)), np.zeros((1, 0)), [[k]], dt, inputs=inp, outputs=out)


def _pi(k, ti, inp, out, dt, name, share=VELOCITY_INTEGRATORS["tustin"]):
    """PI ``k·(1 + 1/(ti·s))`` (or P when ti is None), state ``z = ∫e dt`` [input unit · s].

    Continuous: ``dz/dt = e``, ``y = (k/ti)·z + k·e``.
    Discrete: ``z[k+1] = z[k] + dt·e[k]`` and ``y[k] = (k/ti)·(z[k] +
    share·dt·e[k]) + k·e[k]``; by the trapezoidal (Tustin) rule, ``share`` =
    1/2, ``C(z) = k·(1 + dt/(2·ti)·(z + 1)/(z - 1))`` — ``1/s`` replaced by
    ``dt/2·(z + 1)/(z - 1)`` (:data:`VELOCITY_INTEGRATORS`: the other rules).
    """
    if ti is None:
        return _gain(k, inp, out, dt).copy(name=name)
    if dt:
        D = k * (1.0 + share * dt / ti)
        return ct.ss([[1.0]], [[dt]], [[k / ti]], [[D]], dt, inputs=inp, outputs=out, states="z", name=name)
    return ct.ss([[0.0]], [[1.0]], [[k / ti]], [[k]], 0, inputs=inp, outputs=out, states="z", name=name)


def _blocks(servo, dt):
    """All blocks of the cascade, keyed by role; ``dt = 0`` for continuous time."""
    A, B, states = _plant_matrices(servo)
    if dt:
        A, B = zoh(A, B, dt)
    blocks = {
        "plant": _plant_system(servo, A, B, states, dt),
        "velocity": _pi(servo.kv_mm, servo.ti, "e_v", "i_pi", dt, "velocity_controller", servo.integrator_share),
        "position": _gain(servo.kp, "e_x", "v_p", dt),
        "position_sum": ct.summing_junction(["x_ref", "-x"], "e_x"),
        "vff": _gain(servo.vff, "v_ref", "v_ff", dt),
        "command_sum": ct.summing_junction(["v_p", "v_ff"], "v_cmd"),
        "estimator": _velocity_estimator(servo, dt),
        "velocity_sum": ct.summing_junction(["v_cmd", "-v_fb"], "e_v"),
        "aff": _gain(servo.aff / servo.force_gain, "a_ref", "i_ff", dt),
        "current_command_sum": _command_sum(servo, dt),
    }
    if servo.electrical:
        blocks["current"] = _pi(servo.kc, servo.ti_current, "e_i", "u", dt, "current_controller")
        blocks["current_sum"] = ct.summing_junction(["i_cmd", "-i"], "e_i")
        # The winding with the rotor blocked (back-EMF taken as a disturbance), as drives tune
        # their current loop; only the current-loop margins use it.
        L, R = servo.inductance, servo.resistance
        Aw, Bw = np.array([[-R / L]]), np.array([[1.0 / L]])
        if dt:
            Aw, Bw = zoh(Aw, Bw, dt)
        blocks["winding"] = ct.ss(Aw, Bw, [[1.0]], 0.0, dt, inputs="u", outputs="i", name="winding")
    return blocks


def _difference(servo, dt):
    """True when the velocity loop closes on the encoder difference at the period `dt` (0: continuous)."""
    return bool(dt) and servo.velocity_feedback == "difference"


def _velocity_estimator(servo, dt):
    """The velocity the loop feeds back, ``'v_fb'`` [mm/s], from the motor encoder (the difference) or ``'v'``.

    Sampled with ``velocity_feedback="difference"``: ``(x[k] - x[k-n])/(n·dt)``
    (the moving average of n taps, then the backward difference), then the
    low-pass ``a·y[k-1] + (1 - a)·raw[k]``, ``a = exp(-2π·f·dt)``. Otherwise
    ``v`` itself, through the continuous low-pass ``ω/(s + ω)`` when the
    difference has one and ``dt = 0``.
    """
    f = servo.velocity_filter_hz
    if _difference(servo, dt):  # states: x[k-1] .. x[k-n], then the low-passed velocity of the last step
        n, gain = servo.velocity_taps, 1.0 / (servo.velocity_taps * dt)
        a = 0.0 if f is None else np.exp(-2.0 * np.pi * f * dt)
        m = n + (f is not None)
        A, B, C = np.zeros((m, m)), np.zeros((m, 1)), np.zeros((1, m))
        A[1:n, : n - 1] = np.eye(n - 1)
        B[0, 0] = 1.0
        C[0, n - 1], D = -(1.0 - a) * gain, (1.0 - a) * gain
        if f is not None:
            C[0, n] = a
            A[n], B[n] = C[0], D
        states = [f"past{j}" for j in range(1, n + 1)] + (["lowpass"] if f is not None else [])
        return ct.ss(A, B, C, D, dt, inputs=_motor_signal(servo), outputs="v_fb", states=states, name="estimator")
    if f is not None and not dt:
        return ct.ss(ct.tf([2.0 * np.pi * f], [1.0, 2.0 * np.pi * f]), inputs="v", outputs="v_fb", name="estimator")
    return _gain(1.0, "v", "v_fb", dt).copy(name="estimator")


def _command_sum(servo, dt):
    """``'i_cmd'`` [A] = ``'i_pi' + 'i_ff'``, applied `computation_delay` periods late when sampled."""
    n = servo.computation_delay if dt else 0
    if n == 0:
        return ct.summing_junction(["i_pi", "i_ff"], "i_cmd")
    B = np.zeros((n, 2))
    B[0] = 1.0
    C = np.zeros((1, n))
    C[0, -1] = 1.0  # states: the sums of the last n periods, newest first
    return ct.ss(np.eye(n, k=-1), B, C, np.zeros((1, 2)), dt, inputs=["i_pi", "i_ff"], outputs="i_cmd",
                 name="computation_delay")


def _connect(blocks, roles, inputs, outputs, unused_inputs=(), unused_outputs=()):
    """Interconnect the blocks named in `roles` (skipping absent current-loop blocks) by signal name.

    ``unused_*`` name the signals deliberately left open (python-control
    warns about any other unconnected signal).
    """
    syslist = [blocks[r] for r in roles if r in blocks]
    return ct.interconnect(
        syslist, inplist=inputs, outlist=outputs, inputs=inputs, outputs=outputs,
        ignore_inputs=list(unused_inputs), ignore_outputs=list(unused_outputs),
    )


_INNER = ("current_sum", "current", "plant")  # the current loop (or the bare plant)


def _unread(blocks, *outputs):
    """The plant's outputs that neither the velocity estimator nor the current loop reads, nor `outputs` lists."""
    read = set(blocks["estimator"].input_labels) | {"i"} | set(outputs)
    return [name for name in blocks["plant"].output_labels if name not in read]


def _cascade(blocks):
    """The whole closed cascade: inputs x_ref, v_ref, a_ref; outputs x, v, i_cmd."""
    roles = ("position_sum", "position", "vff", "command_sum", "velocity_sum", "velocity", "aff", "current_command_sum",
             "estimator")
    roles += _INNER
    return _connect(blocks, roles, ["x_ref", "v_ref", "a_ref"], ["x", "v", "i_cmd"],
                    unused_outputs=_unread(blocks, "x", "v"))


def _drop_unread_states(sys):
    """Remove states no output and no other state reads (e.g. position in the velocity loop).

    Such a state is unobservable by construction: removing it leaves the
    transfer function unchanged and keeps its pole (an integrator at s = 0,
    z = 1) out of the loop's closed-loop poles.
    """
    A, B, C = sys.A, sys.B, sys.C
    keep = np.ones(sys.nstates, bool)
    while True:
        off_diagonal = np.abs(A - np.diag(np.diag(A)))[keep][:, keep].sum(axis=0)
        read = (off_diagonal > 0) | (np.abs(C[:, keep]).sum(axis=0) > 0)
        if read.all():
            break
        keep[np.flatnonzero(keep)[~read]] = False
    A, B, C = A[keep][:, keep], B[keep], C[:, keep]
    return ct.ss(A, B, C, sys.D, sys.dt, inputs=sys.input_labels, outputs=sys.output_labels)


def _differences_of_x(loop):
    """`loop` with the estimator's past positions as differences ``x - x[k-j]``, so that x alone is unread.

    The velocity difference reads x only through such differences: in these
    coordinates the plant's position integrator (z = 1, cancelled by the
    difference's zero at z = 1) is a state nothing reads, which
    :func:`_drop_unread_states` removes, as it does without the difference.
    """
    labels = loop.state_labels
    past = [i for i, label in enumerate(labels) if label.startswith("estimator_past")]
    if not past:
        return loop
    T = np.eye(loop.nstates)  # its own inverse
    T[past, labels.index("plant_x")], T[past, past] = 1.0, -1.0
    return ct.ss(T @ loop.A @ T, T @ loop.B, loop.C @ T, loop.D, loop.dt, inputs=loop.input_labels,
                 outputs=loop.output_labels, states=labels)


def _loop_gains(blocks):
    """Loop transfer functions, innermost first, each broken at its own error signal.

    Standard cascade analysis: the loop being examined sees its inner loops
    closed and its outer loops open; the current loop sees the winding with
    the rotor blocked. Feedforward does not enter a loop gain.
    """
    velocity_chain = ("velocity", "current_command_sum", "estimator") + _INNER
    loops = {}
    if "current" in blocks:
        loops["current"] = _connect(blocks, ("current", "winding"), ["e_i"], ["i"])
    loops["velocity"] = _connect(blocks, velocity_chain, ["e_v"], ["v_fb"], unused_inputs=["i_ff"],
                                 unused_outputs=_unread(blocks))
    loops = {name: _drop_unread_states(_differences_of_x(loop)) for name, loop in loops.items()}
    position_chain = ("position", "command_sum", "velocity_sum") + velocity_chain
    loops["position"] = _connect(blocks, position_chain, ["e_x"], ["x"], unused_inputs=["i_ff", "v_ff"],
                                 unused_outputs=_unread(blocks, "x"))
    return loops


# ---------------------------------------------------------------------------------------------
# Continuous-time systems


def plant(servo):
    """Continuous plant of one axis.

    Parameters
    ----------
    servo : AxisServo

    Returns
    -------
    control.StateSpace
        Input ``'i_cmd'`` [A] (ideal or lagged current loop) or ``'u'`` [V]
        (electrical dynamics modelled); outputs and states ``'x'`` [mm],
        ``'v'`` [mm/s] (and ``'i'`` [A]: a state only, with the lag).
    """
    return _plant_system(servo, *_plant_matrices(servo), 0)


def velocity_loop(servo):
    """Closed velocity loop (current loop closed inside), ``'v_cmd'`` [mm/s] -> ``'v'`` [mm/s].

    Parameters
    ----------
    servo : AxisServo

    Returns
    -------
    control.StateSpace
    """
    roles = ("velocity_sum", "velocity", "current_command_sum", "estimator") + _INNER
    blocks = _blocks(servo, 0)
    return _connect(blocks, roles, ["v_cmd"], ["v"], unused_inputs=["i_ff"], unused_outputs=_unread(blocks, "v"))


def _derivative_inputs(sys):
    """SISO realisation of ``y = G_r·r + G_v·dr/dt + G_a·d²r/dt²`` from the 3-input `sys`.

    With ``dx/dt = A x + b_r r + b_v r' + b_a r''`` and ``y = C x`` (``C b_a = 0``:
    the acceleration command reaches position through at least two
    integrations), the state ``q = x - (A b_a + b_v) r - b_a r'`` obeys
    ``dq/dt = A q + (b_r + A (A b_a + b_v)) r`` and
    ``y = C q + C (A b_a + b_v) r`` — a proper system in r alone.
    """
    A, B, C = sys.A, sys.B, sys.C
    b_r, b_v, b_a = B[:, [0]], B[:, [1]], B[:, [2]]
    w = A @ b_a + b_v
    return ct.ss(A, b_r + A @ w, C, C @ w, inputs="x_ref", outputs="x", name="closed_loop")


def closed_loop(servo, feedforward=True):
    """Closed position loop, position command -> actual position.

    Parameters
    ----------
    servo : AxisServo
    feedforward : bool, default True
        Include the velocity and acceleration feedforward paths (active when
        ``vff``/``aff`` are set), driven by the derivatives of the command.

    Returns
    -------
    control.StateSpace
        ``'x_ref'`` [mm] -> ``'x'`` [mm], ``T(s) = G_r + s·G_v + s²·G_a``
        where ``G_r, G_v, G_a`` are the closed cascade's responses to the
        position, velocity and acceleration commands.
    """
    blocks = _blocks(servo, 0)
    if not _validate.flag("feedforward", feedforward):
        blocks["vff"] = _gain(0.0, "v_ref", "v_ff", 0)
        blocks["aff"] = _gain(0.0, "a_ref", "i_ff", 0)
    return _derivative_inputs(_cascade(blocks)[0, :])


def sensitivity(servo):
    """Sensitivity ``S = 1/(1 + L)`` of the position loop (feedback only).

    It is the response of the following error ``e_x = x_ref - x`` to the
    position command without feedforward; ``|S(jω)|`` is the relative
    tracking error of a sine of frequency ω.

    Parameters
    ----------
    servo : AxisServo

    Returns
    -------
    control.StateSpace
        ``'x_ref'`` [mm] -> ``'e_x'`` [mm].
    """
    roles = ("position_sum", "position", "command_sum", "velocity_sum", "velocity", "current_command_sum",
             "estimator") + _INNER
    blocks = _blocks(servo, 0)
    return _connect(blocks, roles, ["x_ref"], ["e_x"], unused_inputs=["v_ff", "i_ff"], unused_outputs=_unread(blocks, "x"))


def bandwidth(servo):
    """Bandwidth of the closed position loop without feedforward [Hz].

    The lowest frequency where ``|T|`` falls to ``1/√2`` (half power, -3.01 dB).

    Parameters
    ----------
    servo : AxisServo

    Returns
    -------
    float
        About ``kp/2π`` when the velocity loop is much faster than the position loop.
    """
    half_power_db = 20 * np.log10(np.sqrt(0.5))
    return float(ct.bandwidth(closed_loop(servo, feedforward=False), dbdrop=half_power_db)) / (2 * np.pi)


# ---------------------------------------------------------------------------------------------
# Sampled loop


def discretize(servo, dt):
    """The sampled cascade the kernel steps, built from discrete blocks.

    Parameters
    ----------
    servo : AxisServo
    dt : float
        Servo period [s].

    Returns
    -------
    DiscreteServo
        Exact ZOH plant (see :func:`zoh`), sampled PI controllers (see the
        module docstring), and their closed interconnection.
    """
    dt = _validate.positive("dt", dt)
    blocks = _blocks(servo, dt)
    return DiscreteServo(
        servo=servo,
        dt=dt,
        plant=blocks["plant"],
        velocity_controller=blocks["velocity"],
        current_controller=blocks.get("current"),
        closed_loop=_cascade(blocks),
    )


# a sampled pole at most this far from 0 decays by e within a servo period [-]: it has settled before it could ring
# (a drive's two-tap velocity filter's alternating pole, z ≈ -0.1), whatever the damping ratio's formula gives it
# (at least 1/√(1 + π²) = 0.30, above the check's floor: it decides no check)
_SETTLED = np.exp(-1.0)


def _damping_ratio(poles, dt, below=np.inf):
    """Smallest damping ratio of continuous (`dt` = 0) or discrete poles slower than `below` [rad/s]; 1 for none.

    Of discrete poles, those that last longer than a servo period (``|z| > 1/e``).
    """
    poles = np.asarray(poles, complex)
    if dt:
        poles = np.log(poles[np.abs(poles) > _SETTLED]) / dt
    poles = poles[(np.abs(poles) > 0) & (np.abs(poles) < below)]
    if poles.size == 0:
        return 1.0
    return float(np.min(-poles.real / np.abs(poles)))


def _loop_response(loop):
    """The complex frequency response of a SISO state-space `loop`: a function of ω [rad/s].

    Evaluated as ``C (sI - A)^-1 B + D`` with ``s = jω`` (or ``z = e^{jω dt}``),
    which stays accurate where the transfer-function polynomials of a sampled
    loop with poles near z = 1 lose all their digits; on A's Hessenberg form
    ``A = Q H Qᵀ``, reduced once, each frequency costs O(n²) instead of a
    dense solve's O(n³) (Laub, "Efficient multivariable frequency response
    computations", IEEE TAC 26, 1981).
    """
    from scipy.linalg import hessenberg  # slow to import; only the analysis needs it
    from scipy.linalg.lapack import dgebal

    # A = T Ab T⁻¹, T = diag(scale) (powers of 2), by LAPACK itself: scipy's matrix_balance casts the scales to int
    # with its permutation, invalid past 2^63 (a stiff current loop's sampled pole e^-500 is balanced by 2^371)
    A, _, _, scale, _ = dgebal(np.asarray(loop.A, float), scale=1)
    H, Q = hessenberg(A, calc_q=True)
    H = np.ascontiguousarray(H)  # for n <= 2 scipy returns dgebal's Fortran-ordered A: one compiled version, not two
    b, c = Q.T @ (np.asarray(loop.B, float)[:, 0] / scale), (np.asarray(loop.C, float)[0] * scale) @ Q
    d, dt = float(np.asarray(loop.D)[0, 0]), loop.dt

    def response(omega):
        omega = np.asarray(omega, float)
        return _hessenberg_gain(H, b, c, np.exp(1j * omega * dt) if dt else 1j * omega) + d

    return response


@njit(cache=True)
def _hessenberg_gain(H, b, c, s):
    """``c (s_k I - H)^-1 b`` for each `s_k`, H upper Hessenberg: Gaussian elimination with partial pivoting,
    where a column has one entry below the diagonal to eliminate. A pole exactly at an `s_k` (the matrix singular
    there) raises ZeroDivisionError, as a dense solve raises LinAlgError."""
    n = H.shape[0]
    out = np.empty(s.size, np.complex128)
    M = np.empty((n, n), np.complex128)
    x = np.empty(n, np.complex128)
    for f in range(s.size):
        for i in range(n):
            for j in range(n):
                M[i, j] = -H[i, j]
            M[i, i] += s[f]
            x[i] = b[i]
        for k in range(n - 1):
            if abs(M[k + 1, k]) > abs(M[k, k]):  # rows k and k + 1 are zero left of column k: swap from there
                for j in range(k, n):
                    M[k, j], M[k + 1, j] = M[k + 1, j], M[k, j]
                x[k], x[k + 1] = x[k + 1], x[k]
            if M[k + 1, k] != 0:
                m = M[k + 1, k] / M[k, k]
                for j in range(k + 1, n):
                    M[k + 1, j] -= m * M[k, j]
                x[k + 1] -= m * x[k]
        total = 0j
        for i in range(n - 1, -1, -1):
            for j in range(i + 1, n):
                x[i] -= M[i, j] * x[j]
            x[i] /= M[i, i]
            total += c[i] * x[i]
        out[f] = total
    return out


def _frequency_grid(loop):
    """100 points per decade from 0.1 rad/s to the Nyquist frequency (or far beyond the fastest pole)."""
    if loop.dt:
        top = np.pi / loop.dt
    else:
        top = 1e3 * max(1.0, np.abs(loop.poles()).max(initial=0.0), np.abs(loop.zeros()).max(initial=0.0))
    return np.logspace(-1, np.log10(top), int(100 * (np.log10(top) + 1)) + 1)


def _crossings(response, omega, grid, f):
    """Frequencies [rad/s] where ``f(L(jω))`` changes sign on the grid `omega` (`grid`: L there), refined on the
    exact response (:func:`_loop_response`)."""
    from scipy.optimize import brentq  # slow to import; only the analysis needs it

    def g(w):
        return f(response(np.array([w])))[0]

    values = f(grid)
    i = np.flatnonzero(np.sign(values[:-1]) * np.sign(values[1:]) < 0)
    return np.array([brentq(g, omega[j], omega[j + 1], xtol=1e-12 * omega[j], rtol=1e-14) for j in i])


def _loop_margins(loop, below=np.inf):
    """Margins of one loop gain from its frequency response (python-control's selection rules).

    The phase margin is the smallest at the gain crossovers below `below` [rad/s].
    """
    omega = _frequency_grid(loop)
    at = _loop_response(loop)
    response = at(omega)
    # gain crossovers: |L| = 1; phase crossovers: L crosses the negative real axis
    with np.errstate(divide="ignore"):  # |L| = 0 (a loop gain below 1e-308): -inf, no crossing there
        w_gain = _crossings(at, omega, response, lambda L: np.log(np.abs(L)))
    w_gain = w_gain[w_gain < below]
    w_phase = _crossings(at, omega, response, lambda L: L.imag)
    if loop.dt:  # L is real at the Nyquist frequency, the grid's end: a phase crossover there if negative, which a
        w_phase = np.append(w_phase, omega[-1])  # sign change on the grid finds by its rounding only
    w_phase = w_phase[at(w_phase).real < 0] if w_phase.size else w_phase
    gm, pm, wpc, wgc = np.inf, np.inf, np.nan, np.nan
    if w_phase.size:
        with np.errstate(divide="ignore", over="ignore"):  # a loop gain below 1e-308 there: an infinite margin
            gains = 1.0 / np.abs(at(w_phase))
        best = np.argmin(np.abs(np.log(gains)))  # the gain margin closest to 1
        gm, wpc = gains[best], w_phase[best]
    if w_gain.size:
        phases = np.remainder(np.angle(at(w_gain), deg=True), 360.0) - 180.0
        best = np.argmin(np.abs(phases))  # the smallest phase margin
        pm, wgc = phases[best], w_gain[best]
    return dict(
        gain_margin=float(gm),
        phase_margin=float(pm),
        stability_margin=float(np.min(np.abs(1.0 + response))),
        gain_crossover=float(wgc),
        phase_crossover=float(wpc),
    )


def _largest_kp(servo, dt, rule):
    """The largest kp at which the position loop of `servo` passes the check at `dt` [s], rounded down to 3 digits
    (as said, it passes), or None where
    the check's bound lies below `rule` [1/s] (the rule of thumb, then said alone): a refusal had said the rule's
    64.6 1/s where 400 passed. Bisected in log kp (the margins fall as kp rises), on the analysis not stored."""
    def passes(kp):
        m = _analysed(dataclasses.replace(servo, kp=kp, vff=0.0, aff=0.0), dt)["position"]
        return m["stable"] and m["phase_margin"] >= MIN_PHASE_MARGIN_DEG and m["damping_ratio"] >= MIN_DAMPING_RATIO

    low, high = rule, servo.kp
    if not low < high or not passes(low):
        return None
    while high / low > 1.0 + 1e-4:
        middle = np.sqrt(low * high)
        low, high = (middle, high) if passes(middle) else (low, middle)
    unit = 10.0 ** (np.floor(np.log10(low)) - 2)
    return float(np.floor(low / unit) * unit)


#: The shortest servo period a drive has [s] (a machine's range: :data:`contoursim.machine.SERVO_PERIOD_RANGE`).
MIN_SERVO_PERIOD = 1e-6
#: On an axis with a compliant screw the loop criteria apply below this fraction of its antiresonance (:func:`margins`).
_MODE_BAND = 1.0 - 1e-3


def _analysed(servo, dt):
    """:func:`margins` for ``dt`` [s] (0: continuous), analysed with python-control."""
    result = {}
    below = np.inf
    if servo.compliant:  # the screw's antiresonance, the table swinging with the motor side held [rad/s]: the mode
        # lies above it, or, on a screw far softer than the loop holding the motor side, within rounding under it
        # (which side of the antiresonance rounding put a 1e-12 N/µm screw's mode decided the check)
        below = _MODE_BAND * np.sqrt(1e6 * servo.screw_stiffness / (servo.mass - servo.motor_mass))
    for name, loop in _loop_gains(_blocks(servo, dt)).items():
        poles = ct.feedback(loop, 1).poles()
        stable = bool(np.all(np.abs(poles) < 1)) if dt else bool(np.all(poles.real < 0))
        result[name] = _loop_margins(loop, below) | dict(damping_ratio=_damping_ratio(poles, dt, below), stable=stable)
    return result


def _cache_dir():
    """Folder of contoursim's stored loop analyses: ``CONTOURSIM_CACHE_DIR``, else ``contoursim`` in the user cache folder.

    The user cache folder is ``XDG_CACHE_HOME`` when set, else ``~/.cache``.
    """
    if os.environ.get("CONTOURSIM_CACHE_DIR"):
        return Path(os.environ["CONTOURSIM_CACHE_DIR"])
    return Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "contoursim"


def _analysis_key(servo, dt):
    """What an analysis depends on: the servo's parameters, `dt`, this module's code and the python-control installed."""
    control = importlib.util.find_spec("control")
    stat = os.stat(control.origin)
    source = Path(__file__).read_bytes()
    text = repr((servo, float(dt), hashlib.sha256(source).hexdigest(), control.origin, stat.st_size, stat.st_mtime_ns))
    return hashlib.sha256(text.encode()).hexdigest()


@lru_cache(maxsize=1024)
def _margins(servo, dt):
    """:func:`margins` for ``dt`` [s] (0: continuous), analysed once per (servo, dt) and stored (:func:`_stored`).

    A stored analysis is read back only under its key (:func:`_analysis_key`):
    other parameters, another version of this module or of python-control
    analyse anew.
    """
    return _stored("margins", _analysis_key(servo, dt), lambda: _analysed(servo, dt))


def _stored(kind, key, analyse):
    """The JSON result of `analyse()` stored as `kind`/`key` in :func:`_cache_dir`: read back if there, else made and stored.

    A folder that cannot be written stores nothing; a file is complete or
    absent when processes analyse at once.
    """
    file = _cache_dir() / kind / f"{key}.json"
    try:
        return json.loads(file.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        pass
    result = analyse()
    try:
        file.parent.mkdir(parents=True, exist_ok=True)
        partial = file.with_name(f"{file.stem}.{os.getpid()}.tmp")
        partial.write_text(json.dumps(result), encoding="utf-8")
        os.replace(partial, file)
    except OSError:
        pass
    return result


def margins(servo, dt=None):
    """Gain and phase margins of each loop of the cascade.

    Each loop gain (see the block diagram in the module docstring) is broken
    at its own error signal with the inner loops closed and the outer loops
    open; the current loop sees the winding with the rotor blocked. The
    crossovers are found on the loop's frequency response on a dense grid
    (100 points per decade up to the Nyquist frequency) and refined on the
    exact response; where there are several, the gain margin closest to 1
    and the smallest phase margin are reported, as
    :func:`control.stability_margins` does. The analysis runs once per
    (servo, dt) and is stored on disk (``CONTOURSIM_CACHE_DIR``, else ``~/.cache/contoursim``; a later process reads it
    back without importing python-control); later calls return a copy of it.

    Parameters
    ----------
    servo : AxisServo
    dt : float, optional
        Servo period [s]. When given, the margins are those of the sampled
        loop (ZOH plant, sampled PI controllers), which includes the sampling
        delay; otherwise of the continuous loop.

    Returns
    -------
    dict
        ``{loop: {...}}`` for the loops ``'current'`` (when modelled),
        ``'velocity'`` and ``'position'``, innermost first, each with
        ``gain_margin`` [-] (inf when the phase never reaches -180°),
        ``phase_margin`` [deg] (inf when the gain never crosses 1),
        ``gain_crossover`` and ``phase_crossover`` [rad/s] (NaN when there
        is none), ``stability_margin`` [-] (the smallest distance of the
        Nyquist curve to -1 on the grid), plus ``damping_ratio`` [-] (the
        smallest of the loop's closed-loop poles) and ``stable`` (all
        closed-loop poles strictly inside the stability region).

    Notes
    -----
    On an axis with a compliant screw the loop's own dynamics lie below
    the screw's antiresonance ``sqrt(k/m2)`` (the table swinging with the
    motor side held), its lightly damped mode above (or, on a screw far
    softer than the loop, within 0.1 % under it): ``phase_margin`` (and its
    crossover) and ``damping_ratio`` are those below the antiresonance,
    and the mode must only stay stable (``stable``;
    ``gain_margin`` and ``stability_margin`` show how near it comes), as
    a drive is commissioned: a screw's 2–5 % damping is its own, not the
    loop's to give.
    """
    dt = 0.0 if dt is None else _validate.positive("dt", dt)
    if servo.vff or servo.aff:  # feedforward does not enter a loop gain: one analysis per feedback loop
        servo = dataclasses.replace(servo, vff=0.0, aff=0.0)
    return {name: dict(m) for name, m in _margins(servo, dt).items()}


_GAIN_OF = {"current": "kc", "velocity": "kv", "position": "kp"}
_INTEGRAL_OF = {"current": "ti_current", "velocity": "ti"}
#: How many times its position gain kp [1/s] a velocity loop's crossover [rad/s] should be at least (the cascade's rule
#: of thumb: an inner loop 3 to 5 times faster than the loop around it); :func:`check` tells a position loop that
#: fails for a slower one to raise kv, not kp.
CASCADE_RATIO = 4.0


def _remedy(loop, servo, dt, m, inner):
    """What to change in a loop that fails :func:`check`, read from its margins `m` and those of the loop inside it.

    Parameters
    ----------
    loop : {"current", "velocity", "position"}
    servo : AxisServo
    dt : float
        Servo period [s].
    m : dict
        The loop's sampled margins (:func:`margins`).
    inner : dict or None
        The sampled margins of the loop inside it (none for the innermost).

    Returns
    -------
    str
        A sentence naming the settings to change, and which way.
    """
    gain, crossover = _GAIN_OF[loop], m["gain_crossover"]
    if loop == "position":  # its phase is the velocity loop's: too slow a one is the cause, whatever kp's size
        inner_crossover = inner["gain_crossover"]
        if not inner_crossover >= CASCADE_RATIO * servo.kp:  # NaN: a velocity loop whose gain never reaches 1
            speed = (f"crossover {inner_crossover / (2 * np.pi):.4g} Hz, {inner_crossover / servo.kp:.3g} times"
                     if np.isfinite(inner_crossover) else "its gain never reaches 1, against")
            slow = (f"the velocity loop is too slow for it ({speed} kp = {servo.kp:.6g} 1/s; a position loop needs one "
                    f"at least {CASCADE_RATIO:g} times faster)")
            if not np.isfinite(inner_crossover):
                return f"{slow}: raise kv"
            rule = inner_crossover / CASCADE_RATIO
            largest = _largest_kp(servo, dt, rule)
            lower = (f"lower kp, to {largest:.3g} 1/s or less (the check's bound; a velocity loop {CASCADE_RATIO:g} "
                     f"times faster, the rule of thumb, allows {rule:.3g} 1/s)" if largest is not None else
                     f"lower kp, to {rule:.3g} 1/s or less")
            ceiling = np.pi * MAX_CROSSOVER_FRACTION / dt  # the fastest velocity loop the check lets run at dt [rad/s]
            if CASCADE_RATIO * servo.kp > ceiling:
                return f"{slow}, and at dt = {dt:.6g} s none may cross over above {ceiling / (2 * np.pi):.4g} Hz: {lower}"
            return f"{slow}: raise kv, or {lower}"
    if servo.compliant and loop != "current" and m["damping_ratio"] < MIN_DAMPING_RATIO:
        mode = np.sqrt(1e6 * servo.screw_stiffness / (servo.mass - servo.motor_mass))  # antiresonance [rad/s]
        if not mode > CASCADE_RATIO * crossover:  # in the loop's band: the screw's 2-5 % damping is the pole's
            within = (f", within {CASCADE_RATIO:g} times the crossover {crossover / (2 * np.pi):.4g} Hz"
                      if np.isfinite(crossover) else "")
            return (f"the screw's mode lies in the loop's band (its antiresonance {mode / (2 * np.pi):.4g} "
                    f"Hz{within}): check screw_stiffness ({servo.screw_stiffness:.6g} N/µm: one in N/mm reads a thousand times too "
                    f"soft), or lower {gain}")
    integral = getattr(servo, _INTEGRAL_OF.get(loop, ""), None)
    if loop == "velocity" and np.isfinite(crossover):  # the current's lag: a current loop as slow is the cause
        current, bandwidth = (("current_bandwidth_hz", 2 * np.pi * servo.current_bandwidth_hz)
                              if servo.current_bandwidth_hz is not None else
                              ("kc", inner["gain_crossover"]) if inner is not None else (None, np.inf))
        if not bandwidth > crossover:  # its lag at the crossover is over 45° (NaN: a current loop never reaching 1)
            return (f"the current loop is too slow for it (bandwidth {bandwidth / (2 * np.pi):.4g} Hz, below its "
                    f"crossover {crossover / (2 * np.pi):.4g} Hz): raise {current}")
    if np.isfinite(crossover):
        if integral and crossover * integral < 1.0:  # the PI's phase lag at the crossover is over 45°
            return (f"its crossover lies below the integral action's corner 1/(2π·{_INTEGRAL_OF[loop]}) = "
                    f"{1 / (2 * np.pi * integral):.4g} Hz: raise {gain}, or lengthen {_INTEGRAL_OF[loop]}")
        return f"lower {gain}" + (f", or lengthen {_INTEGRAL_OF[loop]}" if integral else "")
    if m["gain_margin"] < 1:  # above 1 at the phase crossover and crossing 1 nowhere: above 1 up to Nyquist
        return (f"lower {gain}, or check the mass ({servo.mass:.6g} kg) and force_constant "
                f"({servo.force_constant:.6g} N/A)")
    return f"raise {gain}, or check the mass ({servo.mass:.6g} kg)"


def check(servo, dt, axis="x"):
    """Reject a servo loop that cannot be simulated faithfully at the period `dt`.

    Criteria, applied loop by loop from the innermost outwards:

    1. sampling: the continuous loop's gain crossover must stay below
       ``MAX_CROSSOVER_FRACTION`` (1/4) of the Nyquist frequency ``1/(2 dt)``,
       so the sampling delay costs at most ``π/8`` (22.5°) of phase there —
       otherwise :class:`SamplingError` naming ``dt`` and the loop's gain, or
       the loop's integral time when its integral action sets the crossover;
    2. stability of the sampled loop: every closed-loop pole strictly inside
       the unit circle, phase margin >= ``MIN_PHASE_MARGIN_DEG`` (30°) and
       closed-loop damping ratio >= ``MIN_DAMPING_RATIO`` (0.2) — otherwise
       :class:`~contoursim.exceptions.UnstableLoopError` naming the axis, the
       loop and its margins (on an axis with a compliant screw the phase
       margin and damping criteria apply below its antiresonance, the mode
       above must only be stable: see :func:`margins`).

    Parameters
    ----------
    servo : AxisServo
    dt : float
        Servo period [s].
    axis : str, default "x"
        Axis name used in the messages.

    Returns
    -------
    dict
        The sampled loop's margins, as :func:`margins` with `dt`.

    Raises
    ------
    SamplingError
        `dt` is too long for a loop (or its integral time too short for `dt`).
    UnstableLoopError
        A sampled loop is unstable or badly damped.
    """
    dt = _validate.positive("dt", dt)
    f_max = MAX_CROSSOVER_FRACTION / (2.0 * dt)
    for loop, m in margins(servo).items():
        f_c = m["gain_crossover"] / (2 * np.pi)
        if f_c > f_max:
            gain, integral = _GAIN_OF[loop], _INTEGRAL_OF.get(loop)
            use = f"dt <= {MAX_CROSSOVER_FRACTION / (2 * f_c):.3g} s"
            if integral and getattr(servo, integral) and m["gain_crossover"] * getattr(servo, integral) < 1.0:
                raise SamplingError(  # the integral action sets the crossover, beyond its corner 1/(2π ti)
                    f"{integral} = {getattr(servo, integral):.6g} s is too short for the {loop} loop of axis {axis!r} at "
                    f"dt = {dt:.6g} s: its integral action lifts the crossover to {f_c:.4g} Hz, above 1/4 of the "
                    f"Nyquist frequency ({f_max:.4g} Hz). Lengthen {integral}, or use {use}.", integral)
            physical = MAX_CROSSOVER_FRACTION / (2 * f_c) >= MIN_SERVO_PERIOD  # else no drive samples that fast
            units = ("" if physical else f" (a crossover no drive has: check the mass, {servo.mass:.6g} kg, and "
                                         f"force_constant, {servo.force_constant:.6g} N/A, for their units)")
            raise SamplingError(
                f"dt = {dt:.6g} s is too long for the {loop} loop of axis {axis!r}: its crossover "
                f"{f_c:.4g} Hz is above 1/4 of the Nyquist frequency ({f_max:.4g} Hz){units}. Use "
                f"{use}, or lower {gain} = {getattr(servo, gain):.6g}.", "dt" if physical else "mass")
    sampled = margins(servo, dt)
    inner = None  # the margins of the loop inside the one checked (innermost first)
    for loop, m in sampled.items():
        if not m["stable"]:
            problem = "is unstable"
        elif m["phase_margin"] < MIN_PHASE_MARGIN_DEG or m["damping_ratio"] < MIN_DAMPING_RATIO:
            problem = (
                f"is badly damped (needs phase margin >= {MIN_PHASE_MARGIN_DEG:g} deg and "
                f"closed-loop damping ratio >= {MIN_DAMPING_RATIO:g})"
            )
        else:
            inner = m
            continue
        gain = _GAIN_OF[loop]
        if np.isfinite(m["gain_crossover"]):
            crossing = f"phase margin {m['phase_margin']:.3g} deg at {m['gain_crossover'] / (2 * np.pi):.4g} Hz"
        elif m["gain_margin"] < 1:
            crossing = "no gain crossover (the loop gain stays above 1 up to the Nyquist frequency)"
        else:
            crossing = "no gain crossover (the loop gain never reaches 1)"
        raise UnstableLoopError(
            f"the {loop} loop of axis {axis!r} {problem} at dt = {dt:.6g} s: gain margin "
            f"{m['gain_margin']:.3g}, {crossing}, damping ratio {m['damping_ratio']:.3g} "
            f"({gain} = {getattr(servo, gain):.6g}): {_remedy(loop, servo, dt, m, inner)}.",
            margins=m,
        )
    return sampled
