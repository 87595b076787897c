"""The stepping kernel: all axes' sampled servo cascades, with in-loop effects, advanced at the servo period.

Two steps, two costs:

* **analysis** (python-control, slow, once per (AxisServo, dt) in a process):
  :func:`contoursim.servo.check` refuses a loop that is unstable, badly
  damped or too fast for the period; :func:`run` applies it to every axis;
* **packing** (closed-form numpy, fast, per variant): :func:`pack` turns one
  axis's servo, period and :class:`LoopEffects` into a parameter row — the
  exact ZOH plant (:func:`contoursim.servo.zoh`) and the sampled PI
  coefficients of :func:`contoursim.servo.discretize`, plus the effects'
  parameters. `pack` does not check stability: a variant's stability (new
  gains, masses, delays) is the caller's business; :func:`run` checks the
  nominal linear loop of each AxisServo it is given.

One compiled kernel steps every combination of effects and of cross-coupled
control (fixed parameter layouts where zero means off; the coupling's
reference path is data of its own), so switching effects or coupling on or
off never compiles anything; it is cached on disk (:mod:`contoursim._numba`).
:func:`run` steps one variant (:func:`_variant`); :func:`run_batch` steps
blocks of variants together, the variant index innermost (:func:`_lanes`:
the same operations in the same order, lane by lane, but for terms that are
zero by construction: the same numbers).

The plant of one axis (states ``x, v, d, ḋ, i``)::

    carriage (mass m1 = (1 - r)·m) ──spring k, damper c── tool-side mass (m2 = r·m)
    m1·dv/dt = kf·i - damping·v + F + k·d + c·ḋ          (F: disturbance force [N])
    m2·(dv/dt + d²d/dt²) = -k·d - c·ḋ                    (d: tool-side deflection [mm])
    k = m2·(2π·mode_freq_hz)², c = 2·mode_damping_ratio·m2·2π·mode_freq_hz

so `mode_freq_hz` and `mode_damping_ratio` are those of the tool-side mass
on its spring with the carriage held still, and `mode_mass_ratio` is
``r = m2/m``; without a mode ``d ≡ 0`` and ``m1 = m``. An axis with a
compliant screw (:class:`~contoursim.servo.AxisServo` ``motor_mass``,
``screw_stiffness``) has the same states for its two masses: the carriage
is the motor side (``m1 = motor_mass``, what the motor encoder reads), the
other mass the table (``m2 = m - m1``, at ``x + d``) on the screw's spring
``k = 1e6·screw_stiffness`` [N/m] and damper (:mod:`contoursim.servo`):
one mode per axis, so such an axis takes no `mode_freq_hz`. With electrical
dynamics ``L·di/dt = u - R·i - kf·v`` as in :mod:`contoursim.servo`;
with `current_bandwidth_hz` the lag ``di/dt = ω_c·(u - i)`` on the current
command ``u``; without either, ``i`` holds the current command of the period.

Step k of one axis, from the state sampled at ``t_k`` (every controller
output is held over ``[t_k, t_k+1)``):

1. backlash: the table follows the motor/screw position ``x`` with a play of
   width `backlash_mm` (play operator, state: the table position: the limit
   where the table's friction dominates its inertia). With a compliant
   screw the backlash is instead a dead zone of the screw's spring and
   damper: in contact (``|d| > h/2``) they act on ``d ∓ h/2``; with the gap
   open motor side and table are each on their own, each slowed by its
   share ``damping·m_j/m`` of the damping (the force ``F`` stays on the
   motor side); the plant is stepped in step 8 by `M` exact ZOH substeps,
   each in the mode of the gap at its start (``M`` from 32 substeps per
   cycle of the screw's mode: its contacts timed to a substep);
2. the encoders (the servo's ``position_feedback``): the position loop reads
   ``x`` (``"motor"``, semi-closed loop) or the table (``"scale"``, closed
   loop: behind the play, plus a compliant screw's ``d``), rounded to
   `quantum_mm`, plus the measurement noise when it is on the encoder
   (``noise_at="encoder"``); the motor encoder ``x``, rounded, is what the
   velocity difference reads either way (a drive's dual feedback);
3. feedback delay: the position loop reads the encoder and the velocity loop
   the motor velocity (or encoder) `feedback_delay_s` late, linearly interpolated between
   samples (ring buffers in the state, at most :data:`MAX_DELAY_SAMPLES`); with
   ``feedback_delay_on="position"`` the velocity loop reads its signal now
   (an NC's position loop fed over a fieldbus, the drive's velocity loop on
   its own encoder); then, with ``velocity_feedback="difference"`` (:class:`~contoursim.servo.AxisServo`),
   the velocity loop reads instead the backward difference of the fed-back
   positions over `velocity_taps` samples, low-passed when
   `velocity_filter_hz` is set (ring buffer and filter state in the state);
4. recorded: the tool position (table + deflection, plus measurement noise
   of `noise_mm` RMS when it is on the recording), the fed-back encoder
   position, ``v``;
5. a cross-coupled contour controller (:class:`Coupling`), if any, estimates
   the contour error of the fed-back axis positions against its reference
   path and adds a correction to every axis's velocity command;
6. position P + velocity feedforward, velocity PI + acceleration
   feedforward, current clamp with anti-windup; the current command
   computed `computation_delay` periods before reaches the drive (the
   last two commands in the state); current PI (when modelled);
7. the disturbance force: the constant offset minus viscous and stick-slip
   friction (see :class:`LoopEffects`), plus the known external force of
   step k (the `force` argument of :func:`run` and :func:`run_batch`): the
   dry friction is the force that would stop the carriage at ``t_k+1``,
   within its static or kinetic bounds at the velocity sampled at ``t_k``; held;
8. the exact ZOH plant update with the held voltage (or current) and force
   (a screw with a backlash: its substeps, step 1; the stick-slip's
   prediction of step 7 takes the spring's stretch beyond the gap).

The helpers take and return scalars (state goes in and comes back out) or
read the parameter array without branching: an array passed into a helper
that branches keeps numba's reference counting in the loop, ten times slower.
"""

import math
from collections.abc import Mapping
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field

import numpy as np
from numba import get_num_threads

from . import _validate
from ._numba import njit
from .estimators import _arc_parts, _linear_arc, _three_point_arc, distinct_samples, search_params
from .nearest import nearest_knot
from .exceptions import UnstableLoopError
from .servo import VELOCITY_INTEGRATORS, AxisServo, _plant_matrices, zoh

__all__ = [
    "Coupling",
    "COUPLING_ESTIMATORS",
    "LoopEffects",
    "ServoResponse",
    "pack",
    "run",
    "run_batch",
    "spectral_radius",
    "loop_matrices",
    "MAX_DELAY_SAMPLES",
    "LANES",
    "NPAR",
    "BATCH_OUTPUTS",
]

# Per-axis parameter row (float64) -----------------------------------------------------------
_NS = 5  # plant states: x [mm], v [mm/s], d [mm], ḋ [mm/s], i [A]
_AD = 0  # 25 entries: plant Ad (5 x 5, row-major)
_BU = 25  # 5 entries: plant Bd for the voltage u [V] (or the current command [A])
_BF = 30  # 5 entries: plant Bd for the disturbance force F [N]
_KP = 35  # position gain [1/s]
_VFF = 36  # velocity feedforward gain [-]
_AFF = 37  # acceleration feedforward [A per mm/s^2] = aff / force_gain
_AMP = 38  # current per force, 1 / force_constant [A/N]
_VB, _VC, _VD = 39, 40, 41  # velocity controller: z += VB·e; i = VC·z + VD·e
_CB, _CC, _CD = 42, 43, 44  # current controller: z += CB·e; u = CC·z + CD·e
_ILIM = 45  # current limit [A] (the largest float: none, so that a row is finite)
_ELEC = 46  # 1.0 when the current loop is modelled
_HALF_PLAY = 47  # half the backlash [mm]
_SCALE = 48  # 1.0 when the position loop closes on the table (AxisServo.position_feedback = "scale")
_FRICTION = 49  # 1.0 when any friction or offset force is set
_FC, _FV, _FS, _VS, _FA, _F0 = 50, 51, 52, 53, 54, 55  # friction, see LoopEffects
_DELAY_N, _DELAY_F = 56, 57  # feedback delay: whole periods, fraction of a period
_QUANTUM = 58  # encoder resolution [mm] (0: none)
_NOISE = 59  # measurement noise on the tool position [mm RMS]
_SEED = 60  # noise seed
_MODE = 61  # 1.0 when the axis has a structural mode
_VDIFF = 62  # 1.0 when the velocity loop closes on the encoder difference (AxisServo.velocity_feedback)
_VTAPS, _VGAIN, _VPOLE = 63, 64, 65  # its taps n, 1/(n·dt) [1/s] and low-pass pole (0: none)
_CDELAY = 66  # computation delay [servo periods]
_LAGGED = 67  # 1.0 when the current lags its command (AxisServo.current_bandwidth_hz): the plant's row 4 steps it
_SCREW = 68  # 1.0 when the mode is a compliant screw (AxisServo.motor_mass): d is the table's, which a scale reads
_DELAY_POSITION = 69  # 1.0 when the feedback delay is the position loop's only (LoopEffects.feedback_delay_on)
_HALF_GAP = 70  # a compliant screw's backlash: half its dead zone [mm] (0: none; _HALF_PLAY is 0 then)
_SUBSTEPS = 71  # the substeps M of a period that its plant takes (_gap_plant)
_ENGAGED, _OPEN = 72, 107  # 35 entries each: Ad (5 x 5), Bu, BF over dt/M, the gap closed (spring offset) and open
_APPROACH = 142  # the side a backlash's play is closed on at the start (LoopEffects.backlash_approach): +1, -1, 0
NPAR = 143  #: length of one axis's parameter row from :func:`pack`

# Substeps per cycle of the screw's relative mode that a compliant screw with a backlash takes (pack; measured:
# tests/test_kernel_gap.py)
_GAP_SUBSTEPS_PER_CYCLE = 32

# Per-axis state ----------------------------------------------------------------------------
_ZV, _ZC = 5, 6  # velocity / current controller integrators [mm], [A·s]
_TABLE = 7  # table position behind the backlash [mm]
_NBUF = 64  # ring buffer length of the feedback delay
_BUFX = 8  # _NBUF encoder positions [mm]
_BUFV = _BUFX + _NBUF  # _NBUF motor velocities [mm/s]
_PAIR = _BUFV + _NBUF  # index of the pair of noise samples held (-1: none)
_GAUSS = _PAIR + 1  # that pair of standard normal samples
_VEST = _GAUSS + 2  # the velocity fed back at the last step (the low-pass's state) [mm/s]
_SENT = _VEST + 1  # 2 entries: the current commands computed 1 and 2 periods ago [A]
_NHIST = 16  # ring buffer length of the fed-back positions the velocity difference reads
_HIST = _SENT + 2  # _NHIST fed-back positions [mm]
_NSTATE = _HIST + _NHIST

_CLAMPED, _DIVERGED, _BAD_REFERENCE = 0, 1, 2  # per-axis status counters of a run

# Once the plant state is not finite it stays so (x keeps its value plus increments), so the
# divergence check runs every _DIVERGENCE_CHECK steps and at the end only.
_DIVERGENCE_CHECK = 256

#: The longest feedback delay the kernel holds, in servo periods.
MAX_DELAY_SAMPLES = _NBUF - 1

#: Signals :func:`run_batch` can return, each (B, samples, n_axes).
BATCH_OUTPUTS = ("tool", "encoder", "velocity", "current", "saturated")


@dataclass(frozen=True, kw_only=True)
class LoopEffects:
    """In-loop and sensor effects of one axis, in physical units; every one off by default.

    Parameters
    ----------
    backlash_mm : float, default 0
        Lost motion between the motor/screw and the table [mm]: the table
        stands still after a reversal until the screw has moved this far.
        Where the position loop reads (the motor, which does not see it, or
        the table, which does: hunting risk with integral action) is the
        servo's ``position_feedback``. On an axis with a compliant screw, a
        dead zone of this width in the screw's spring and damper: the
        table, with its mass, coasts across the gap when the force on it
        reverses (step 1 of :mod:`contoursim.kernel`).
    backlash_approach : {0, 1, -1}, default 0
        Where the play stands at the start: ``0`` centred (the table, or
        the compliant screw's dead zone, midway), ``1`` closed as a move
        in + leaves it (the table behind the motor by half the play: a
        first move in + takes it along at once, one in − crosses the whole
        play first), ``-1`` as a move in − leaves it. A machine at the
        start of a logged move came there by some move, which closed the
        play on its side (ISO 230-2's approach direction).
    coulomb_N : float, default 0
        Coulomb friction level [N].
    viscous_N_s_per_m : float, default 0
        Viscous friction [N·s/m] (on top of the servo's `damping`).
    stribeck_N : float, default 0
        Extra static friction at standstill [N], decaying as
        ``exp(-(v/stribeck_velocity)^2)``.
    stribeck_velocity_mm_s : float, default 1
        Stribeck velocity [mm/s].
    asymmetry_N : float, default 0
        Force [N] pushing towards negative positions while the axis moves in
        either direction: friction is ``coulomb_N + asymmetry_N`` moving
        forward and ``coulomb_N - asymmetry_N`` moving back (and the
        break-away levels at rest shift the same way).
    offset_N : float, default 0
        Constant force [N] on the carriage, always (e.g. an unbalanced weight).
    feedback_delay_s : float, default 0
        The loop reads the encoder (and the motor velocity) this late [s];
        fractions of a period are interpolated linearly. At most
        :data:`MAX_DELAY_SAMPLES` servo periods.
    feedback_delay_on : {"both", "position"}, default "both"
        ``"both"``: the position loop reads the encoder and the velocity
        loop its signal (the motor velocity, or the encoder it differences)
        `feedback_delay_s` late; ``"position"``: the position loop only, the
        velocity loop reads now (a position loop in the NC fed over a
        fieldbus, the drive's velocity loop on its own encoder).
    mode_freq_hz : float, optional
        Natural frequency [Hz] of a structural mode (the tool-side mass on
        its spring, carriage held); ``None``: rigid axis.
    mode_damping_ratio : float, default 0.05
        Damping ratio of the mode [-], ζ > 0 (1: critically damped).
    mode_mass_ratio : float, default 0.2
        Tool-side mass / total moving mass [-], 0 < r < 1.
    quantum_mm : float, default 0
        Encoder resolution [mm]: the loop sees the encoder rounded to it.
    noise_mm : float, default 0
        Gaussian measurement noise [mm RMS], where `noise_at` says.
    noise_at : {"recorded", "encoder"}, default "recorded"
        ``"recorded"``: on the recorded tool position, outside the loop;
        ``"encoder"``: on the encoder reading the loop (and a cross-coupled
        controller) closes on, before any feedback delay; the recorded tool
        position is then the true one.
    seed : int, default 0
        Seed of the noise; the same seed gives the same noise.

    Notes
    -----
    Friction is stick-slip in discrete time (the idea of Kikuuwe et al.,
    "A friction model for discrete-time simulation", IROS 2005, for the
    exact ZOH plant). The disturbance force on the carriage, held over a
    servo period, is ``offset_N - viscous·v + f`` with ``v`` the carriage
    velocity at the start of the period [mm/s] and the dry friction

        f = clip(F_stop, -(L + asymmetry_N), L - asymmetry_N),
        L = coulomb_N + stribeck_N·exp(-(v/stribeck_velocity)^2),

    where ``F_stop = -v_free / (∂v_{k+1}/∂F)`` [N] is the force that stops
    the carriage at the end of the period, ``v_free`` the velocity it would
    have then under every other force (drive, viscous, offset; structural
    mode and current dynamics included). Within the bounds the axis sticks
    (``v_{k+1} = 0``) until the other forces exceed the static level
    ``coulomb_N + stribeck_N`` (break-away); sliding, ``F_stop`` is large
    and the clip gives the kinetic friction ``L ± asymmetry_N`` opposing the
    motion.
    """

    backlash_mm: float = 0.0
    backlash_approach: int = 0
    coulomb_N: float = 0.0
    viscous_N_s_per_m: float = 0.0
    stribeck_N: float = 0.0
    stribeck_velocity_mm_s: float = 1.0
    asymmetry_N: float = 0.0
    offset_N: float = 0.0
    feedback_delay_s: float = 0.0
    feedback_delay_on: str = "both"
    mode_freq_hz: float | None = None
    mode_damping_ratio: float = 0.05
    mode_mass_ratio: float = 0.2
    quantum_mm: float = 0.0
    noise_mm: float = 0.0
    noise_at: str = "recorded"
    seed: int = 0

    def __post_init__(self):
        nonnegative = ("backlash_mm", "coulomb_N", "viscous_N_s_per_m", "stribeck_N", "feedback_delay_s",
                       "quantum_mm", "noise_mm")  # fmt: skip
        checked = {name: _validate.nonnegative(name, getattr(self, name)) for name in nonnegative}
        checked["stribeck_velocity_mm_s"] = _validate.positive("stribeck_velocity_mm_s", self.stribeck_velocity_mm_s)
        for name in ("asymmetry_N", "offset_N"):
            checked[name] = _validate.finite(name, getattr(self, name))
        if self.backlash_approach not in (0, 1, -1) or isinstance(self.backlash_approach, bool):
            raise ValueError(f"backlash_approach must be 0 (the play centred), 1 or -1 (closed as a move in + or - "
                             f"leaves it), got {self.backlash_approach!r}")
        if self.noise_at not in ("recorded", "encoder"):
            raise ValueError(f'noise_at must be "recorded" or "encoder", got {self.noise_at!r}')
        if self.feedback_delay_on not in ("both", "position"):
            raise ValueError(f'feedback_delay_on must be "both" or "position", got {self.feedback_delay_on!r}')
        if self.mode_freq_hz is not None:
            checked["mode_freq_hz"] = _validate.positive("mode_freq_hz", self.mode_freq_hz)
        checked["mode_damping_ratio"] = _validate.positive("mode_damping_ratio", self.mode_damping_ratio)
        ratio = _validate.positive("mode_mass_ratio", self.mode_mass_ratio)
        if ratio >= 1:
            raise ValueError(f"mode_mass_ratio must be between 0 and 1 (exclusive), got {ratio!r}")
        checked["mode_mass_ratio"] = ratio
        checked["seed"] = _validate.seed("seed", self.seed)
        for name, value in checked.items():
            object.__setattr__(self, name, value)


#: Contour-error estimators a :class:`Coupling` can run every servo period.
COUPLING_ESTIMATORS = ("linear", "arc")

# Coupling parameter layout (float64) and state
_C_KIND = 0  # 0: none, 1: linear (tangent at the commanded sample), 2: three-point arc (searched)
_C_KP, _C_KI, _C_KD = 1, 2, 3  # coupling PID: [1/s], [1/s^2], [-]
_C_UP = 4  # 3 entries: the direction that orients the plane normal
_C_WINDOW = 7  # search window [knots]
_C_DT = 8  # servo period [s] (set by run)
_C_NPAR = 9
_C_ZN, _C_ZH, _C_EN, _C_EH, _C_HINT = 0, 1, 2, 3, 4  # integrators, previous errors [mm·s], [mm], knot
_C_NSTATE = 5


@dataclass(frozen=True)
class Coupling:
    """A cross-coupled contour controller acting inside the loop every servo period (Koren's CCC).

    Each step it estimates the contour error of the fed-back axis positions
    ``P`` (the first 2 or 3 axes as x, y, z) against its reference path,
    ``P = foot + ε_n·n + ε_h·b`` (``n`` the in-plane normal at the foot, to
    the left of travel; ``b`` the local plane normal; :mod:`contoursim.estimators`),
    and adds to the axes' velocity commands [mm/s]

        Δv = -(u_n·n + u_h·b),   u = kp·ε + ki·∫ε dt + kd·dε/dt

    for each of the two components (integrator by the trapezoidal rule,
    like the kernel's PI; derivative by the backward difference). With the
    linear estimator ``n = (-sin θ, cos θ)`` in the plane: Koren's variable
    gains ``Cx = -sin θ``, ``Cy = cos θ``.

    Parameters
    ----------
    estimator : {"linear", "arc"}
        ``"linear"``: the tangent line at the commanded sample (Koren);
        ``"arc"``: the three-point circumscribed arc around the nearest
        reference sample, searched from the previous one (seed 003), with
        its out-of-plane part.
    path : array_like, shape (N, n)
        Where the axes should be at each servo step [mm] (the target path,
        without feedforward pre-filtering), one row per reference sample.
    kp : float
        Coupling gain [1/s].
    ki : float, default 0
        Integral gain [1/s^2].
    kd : float, default 0
        Derivative gain [-].
    up : array_like, shape (3,), default (0, 0, 1)
        Orients the local plane normal (:func:`contoursim.estimators.search_params`).
    window : int, default 4
        Search window of the arc estimator [samples].

    Notes
    -----
    The path's distinct samples (``knots``) and the sample each servo step
    commands (``knot_of_sample``) are computed once here and passed to the
    compiled kernel as arrays of their own.
    """

    estimator: str
    path: np.ndarray
    kp: float
    ki: float = 0.0
    kd: float = 0.0
    up: tuple = (0.0, 0.0, 1.0)
    window: int = 4

    def __post_init__(self):
        if self.estimator not in COUPLING_ESTIMATORS:
            raise ValueError(f"estimator must be one of {', '.join(COUPLING_ESTIMATORS)}, got {self.estimator!r}")
        path = _validate.finite_array("coupling path", self.path, ndim=2).copy()  # ours to make read-only
        if path.shape[1] not in (2, 3):
            raise ValueError(f"a coupling needs 2 or 3 axes (x, y[, z]), got a path with {path.shape[1]} columns")
        for name in ("kp", "ki", "kd"):
            object.__setattr__(self, name, _validate.nonnegative(name, getattr(self, name)))
        params = np.zeros(_C_NPAR)
        params[_C_KIND] = 1.0 + COUPLING_ESTIMATORS.index(self.estimator)
        params[_C_KP], params[_C_KI], params[_C_KD] = self.kp, self.ki, self.kd
        params[_C_UP : _C_WINDOW + 1] = search_params(self.up, self.window)
        knots, _, knot_of_sample = distinct_samples(path)
        if len(knots) < 3:
            raise ValueError("the coupling's path must pass through at least 3 distinct positions")
        for name, value in (("path", path), ("params", params), ("knots", knots), ("knot_of_sample", knot_of_sample)):
            value = np.ascontiguousarray(value)
            value.flags.writeable = False
            object.__setattr__(self, name, value)


@dataclass(frozen=True)
class ServoResponse:
    """What the kernel returns: the sampled axis signals, time first.

    Parameters
    ----------
    dt : float
        Servo period [s]: the samples are at ``t = k·dt`` (:attr:`t`).
    position : ndarray, shape (N, n)
        Tool position of each axis at ``t_k`` [mm]: the table (behind any
        backlash) plus the tool-side deflection of a structural mode, plus
        measurement noise; the axis position without effects.
    encoder : ndarray, shape (N, n)
        The position the position loop closed on at ``t_k`` [mm]: motor
        encoder or linear scale, quantised and delayed.
    velocity : ndarray, shape (N, n)
        Motor (carriage) velocities at ``t_k`` [mm/s] (the plant's, not a
        drive's estimate of it).
    current : ndarray, shape (N, n)
        Current command held over ``[t_k, t_k+1)`` [A]: velocity-controller
        output plus acceleration feedforward, after saturation (computed
        ``computation_delay`` periods before, when the servo has one).
    saturated : ndarray of bool, shape (N, n)
        True where the current command computed at ``t_k`` was clamped at
        the current limit.
    contour_estimate : ndarray, shape (N, 3), or None
        The contour error the :class:`Coupling` estimated at each step: the
        vector from the fed-back axis position to the foot point [mm];
        ``None`` without a coupling.

    Notes
    -----
    Types and shapes are checked, values are not: :func:`run` refuses a
    simulation whose state stopped being finite.
    """

    dt: float
    position: np.ndarray
    encoder: np.ndarray
    velocity: np.ndarray
    current: np.ndarray
    saturated: np.ndarray
    contour_estimate: np.ndarray | None = None

    def __post_init__(self):
        object.__setattr__(self, "dt", _validate.positive("dt", self.dt))
        shape = _validate.float_array("position", self.position, ndim=2).shape
        arrays = dict(saturated=np.asarray(self.saturated, bool))
        for name in ("position", "encoder", "velocity", "current"):
            arrays[name] = _validate.float_array(name, getattr(self, name), shape=shape)
        if arrays["saturated"].shape != shape:
            raise ValueError(f"saturated must have shape {shape}, got {arrays['saturated'].shape}")
        if self.contour_estimate is not None:
            arrays["contour_estimate"] = _validate.float_array("contour_estimate", self.contour_estimate,
                                                               shape=(shape[0], 3))
        for name, value in arrays.items():
            value.flags.writeable = False
            object.__setattr__(self, name, value)

    @property
    def t(self):
        """Sample times ``k·dt`` [s], shape (N,): made on each call, not kept (8 bytes a step)."""
        return np.arange(self.position.shape[0]) * self.dt


# ---------------------------------------------------------------------------------------------
# One axis, one step


@njit(cache=True)
def _sensors(x, d, table, half_play, scale, quantum):
    """Table behind the play and the position loop's reading: ``(table, encoder)`` [mm].

    The motor encoder reads `x`, a scale the table plus `d` (a compliant screw's deflection; 0 else).
    """
    table = _play(x, table, half_play)
    return table, _quantised(table + d if scale else x, quantum)


@njit(cache=True)
def _at_rest(start, approach, half_play, half_gap, scale):
    """An axis at rest in position at `start` [mm], its play closed on the side of its `approach` (+1, -1; 0:
    centred): ``(motor x, table, a compliant screw's stretch d)``. The position loop holds what it reads at `start`:
    the motor (the table behind it by half the play, or the screw's stretch at the dead zone's edge), or, on a scale,
    the table (the motor beyond it)."""
    x = start + approach * (half_play + half_gap) if scale else start
    return x, x - approach * half_play, -approach * half_gap


@njit(cache=True)
def _play(x, table, half_play):
    """The table behind a play of ``±half_play`` around the motor position `x` [mm]."""
    return min(max(table, x - half_play), x + half_play)


@njit(cache=True, error_model="numpy")
def _quantised(encoder, quantum):
    """The encoder reading rounded to `quantum` [mm] (none when 0; no division check, so that lanes vectorise)."""
    if quantum > 0.0:
        return quantum * math.floor(encoder / quantum + 0.5)
    return encoder


@njit(cache=True)
def _delayed(buf, a, base, k, n, f):
    """The ring buffer `buf[a, base:base + _NBUF]` read ``n + f`` samples before step `k`."""
    return _between(buf[a, base + (k - n) % _NBUF], buf[a, base + (k - n - 1) % _NBUF], f)


@njit(cache=True)
def _between(now, before, f):
    """Linear interpolation a fraction `f` of a period back from the sample `now` towards `before`."""
    return (1.0 - f) * now + f * before


@njit(cache=True)
def _difference(x_fb, x_past, gain, pole, previous):
    """The drive's velocity [mm/s]: ``(x_fb - x_past)·gain`` low-passed by ``pole`` (0: none) from `previous`."""
    return pole * previous + (1.0 - pole) * ((x_fb - x_past) * gain)


@njit(cache=True)
def _applied(delay, now, last, before):
    """The current command reaching the drive [A]: the one computed `delay` (0, 1 or 2) periods ago."""
    return now if delay == 0.0 else (last if delay == 1.0 else before)


@njit(cache=True)
def _velocity_command(kp, vff, x_ref, v_ref, x_fb):
    """Position P controller plus velocity feedforward [mm/s]."""
    return kp * (x_ref - x_fb) + vff * v_ref


@njit(cache=True)
def _velocity_controller(b, c, d, limit, z, e_v, i_ff):
    """Velocity PI (or P) + feedforward current, clamped to ``±limit``.

    Anti-windup by conditional integration: the integrator `z` holds while
    the command is clamped and the velocity error would drive it further
    into the limit. Returns the current command [A], whether it was clamped,
    and the next integrator state.
    """
    unclamped = c * z + d * e_v + i_ff
    command = min(max(unclamped, -limit), limit)
    clamped = command != unclamped
    if clamped and e_v * unclamped > 0.0:
        return command, clamped, z
    return command, clamped, z + b * e_v


@njit(cache=True)
def _current_controller(b, c, d, z, e_i):
    """Current PI: the voltage [V] and the next integrator state."""
    return c * z + d * e_i, z + b * e_i


@njit(cache=True)
def _plant_row(p, a, r, x, v, d, w, i, u, force):
    """Row `r` of the plant update ``Ad [x, v, d, ḋ, i] + Bu u + BF F`` (reads `p` without branching)."""
    base = _AD + _NS * r
    return _affine(p[a, base], p[a, base + 1], p[a, base + 2], p[a, base + 3], p[a, base + 4], p[a, _BU + r],
                   p[a, _BF + r], x, v, d, w, i, u, force)  # fmt: skip


@njit(cache=True)
def _affine(c0, c1, c2, c3, c4, bu, bf, x, v, d, w, i, u, force):
    """One plant row's sum, always in this order (:func:`run` and :func:`run_batch` agree bit for bit)."""
    return c0 * x + c1 * v + c2 * d + c3 * w + c4 * i + bu * u + bf * force


@njit(cache=True)
def _gap_plant(q, a, x, v, d, w, i, u, force):
    """A compliant screw with a backlash over one period: ``(x, v, d, ḋ, i)`` after `M` exact ZOH substeps.

    Each substep takes the plant of the gap's state at its start: closed
    (``|d| > h/2``: the screw's spring and damper on ``d ∓ h/2``) or open
    (no coupling). `q` (n, NPAR): the rows of the axes (`a`: this one's);
    `u` and `force` held over the period. Called alike by :func:`_variant`
    and :func:`_lanes` (bit for bit the same).
    """
    half = q[a, _HALF_GAP]
    for _ in range(int(q[a, _SUBSTEPS])):
        offset = half if d > half else (-half if d < -half else 0.0)
        base = _OPEN if offset == 0.0 else _ENGAGED
        e = d - offset
        # (rows as np.int64: one compiled _substep_row, not one per literal row number)
        x, v, e, w, i = (_substep_row(q, a, base, np.int64(0), x, v, e, w, i, u, force),
                         _substep_row(q, a, base, np.int64(1), x, v, e, w, i, u, force),
                         _substep_row(q, a, base, np.int64(2), x, v, e, w, i, u, force),
                         _substep_row(q, a, base, np.int64(3), x, v, e, w, i, u, force),
                         _substep_row(q, a, base, np.int64(4), x, v, e, w, i, u, force))  # fmt: skip
        d = e + offset
    return x, v, d, w, i


@njit(cache=True)
def _substep_row(q, a, base, r, x, v, d, w, i, u, force):
    """Row `r` of the substep plant from entry `base` of `q`'s row `a` (Ad, then Bu, BF)."""
    c = base + _NS * r
    return _affine(q[a, c], q[a, c + 1], q[a, c + 2], q[a, c + 3], q[a, c + 4], q[a, base + 25 + r],
                   q[a, base + 30 + r], x, v, d, w, i, u, force)  # fmt: skip


@njit(cache=True)
def _sprung(d, half):
    """The screw's stretch beyond the backlash's dead zone ``±half`` [mm] (`d` itself without one)."""
    return d - min(max(d, -half), half)


@njit(cache=True, error_model="numpy")
def _friction_level(fc, fs, vs, v):
    """Kinetic plus Stribeck friction level [N] at velocity `v` [mm/s]."""
    level = fc
    r2 = (v / vs) ** 2
    if fs != 0.0 and r2 < 36.0:  # beyond, exp(-r2) < 2.4e-16: below float64 resolution of the static level
        level += fs * math.exp(-r2)
    return level


@njit(cache=True)
def _dry_friction(level, fa, f_stop):
    """Stick-slip friction force [N]: `f_stop` [N] clipped to the friction bounds of `level` and asymmetry `fa`."""
    lower, upper = _friction_bounds(level, fa)
    return min(max(f_stop, lower), upper)


@njit(cache=True)
def _friction_bounds(level, fa):
    """The dry friction's range ``(lower, upper)`` [N] at friction level `level` [N] with asymmetry `fa` [N]."""
    return -(level + fa), level - fa


_GOLDEN = np.uint64(0x9E3779B97F4A7C15)


@njit(cache=True)
def _mix(z):
    """splitmix64's output function: a well-mixed 64-bit hash of `z`."""
    z = (z ^ (z >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
    z = (z ^ (z >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
    return z ^ (z >> np.uint64(31))


@njit(cache=True)
def _gauss_pair(key, pair):
    """Standard normal samples ``2·pair`` and ``2·pair + 1`` of the stream `key` (counter-based, Box-Muller)."""
    c = np.uint64(2) * np.uint64(pair)
    u1 = (float(_mix(key + (c + np.uint64(1)) * _GOLDEN) >> np.uint64(11)) + 0.5) * 2.0**-53
    u2 = (float(_mix(key + (c + np.uint64(2)) * _GOLDEN) >> np.uint64(11)) + 0.5) * 2.0**-53
    radius, angle = math.sqrt(-2.0 * math.log(u1)), 2.0 * math.pi * u2
    return radius * math.cos(angle), radius * math.sin(angle)


# ---------------------------------------------------------------------------------------------
# All axes, all steps


@njit(cache=True)
def _coupling_step(k, cpar, knots, knot_of_sample, cstate, x_fb, dvel):
    """One step of the cross-coupled controller (see :class:`Coupling`).

    Writes the velocity corrections into `dvel`, advances `cstate` and
    returns the estimated contour-error vector (from the fed-back position
    to the foot point) [mm].
    """
    n_axes = x_fb.shape[0]
    p = (x_fb[0], x_fb[1], x_fb[2] if n_axes > 2 else 0.0)
    up = (cpar[_C_UP], cpar[_C_UP + 1], cpar[_C_UP + 2])
    if cpar[_C_KIND] == 1.0:
        anchor, t, b, kappa = _linear_arc(knots, knot_of_sample[k], up)
    else:
        j = nearest_knot(knots, knot_of_sample[k], int(cstate[_C_HINT]), p, int(cpar[_C_WINDOW]))
        cstate[_C_HINT] = j
        anchor, t, b, kappa = _three_point_arc(knots, j, up)
    e_n, e_h, lf = _arc_parts(anchor, t, b, kappa, p)
    dt = cpar[_C_DT]
    kp, ki, kd = cpar[_C_KP], cpar[_C_KI], cpar[_C_KD]
    u_n = kp * e_n + ki * (cstate[_C_ZN] + 0.5 * dt * e_n) + kd * (e_n - cstate[_C_EN]) / dt
    u_h = kp * e_h + ki * (cstate[_C_ZH] + 0.5 * dt * e_h) + kd * (e_h - cstate[_C_EH]) / dt
    cstate[_C_ZN] += dt * e_n
    cstate[_C_ZH] += dt * e_h
    cstate[_C_EN], cstate[_C_EH] = e_n, e_h
    for a in range(min(n_axes, 3)):
        dvel[a] = -(u_n * lf[a] + u_h * b[a])
    return -(e_n * lf[0] + e_h * b[0]), -(e_n * lf[1] + e_h * b[1]), -(e_n * lf[2] + e_h * b[2])


@njit(cache=True, nogil=True)
def _variant(par, state, ref_pos, ref_vel, ref_acc, cpar, knots, knot_of_sample, cstate, encoder_noise, external,
             every, tool, encoder, velocity, current, saturated, estimate, status):  # fmt: skip
    """Step all axes of one variant over the reference, advancing `state` and `cstate` in place.

    ``par`` (n, NPAR) and ``state`` (n, _NSTATE) follow the layouts above;
    ``cpar`` (_C_NPAR,), ``knots`` (M, 4) (the path's distinct samples [mm] and their cumulative chord
    length [mm], :func:`contoursim.nearest.distinct_samples`), ``knot_of_sample`` (N,) and
    ``cstate`` (_C_NSTATE,) are the coupling's (kind 0: none);
    ``encoder_noise`` (N, n) is added to the encoder readings and
    ``external`` (N, n) to the disturbance forces [N] (no rows: none). Samples
    ``k = 0, every, 2·every, …`` go to the outputs of shape
    (ceil(N / every), n) (`estimate`: (ceil(N / every), 3)) that have rows
    (an output with no rows is not asked for). `status` (n, 3) gets per
    axis the number of clamped steps, the step at which the plant state was found not finite (checked every
    _DIVERGENCE_CHECK steps; -1: never) and the first step whose reference
    values are not all finite (-1: none; the caller checks the reference
    in detail then, so that a valid reference costs no separate pass).
    """
    n_steps, n_axes = ref_pos.shape
    write_tool, write_encoder = tool.shape[0] > 0, encoder.shape[0] > 0
    write_velocity, write_current, write_saturated = velocity.shape[0] > 0, current.shape[0] > 0, saturated.shape[0] > 0
    write_estimate, coupled = estimate.shape[0] > 0, cpar[_C_KIND] != 0.0
    noisy_encoder, pushed = encoder_noise.shape[0] > 0, external.shape[0] > 0
    x_fb = np.empty(n_axes)
    v_fb = np.empty(n_axes)
    dvel = np.empty(n_axes)  # zeroed below: np.zeros would compile three more functions (~0.07 s)
    keys = np.empty(n_axes, np.uint64)
    for a in range(n_axes):  # at rest: the delay buffers hold the first encoder reading
        dvel[a] = 0.0
        keys[a] = _mix(np.uint64(par[a, _SEED]) * np.uint64(n_axes + 1) + np.uint64(a))
        scale, screw = par[a, _SCALE] != 0.0, par[a, _SCREW] != 0.0
        state[a, _TABLE], enc = _sensors(state[a, 0], state[a, 2] if screw else 0.0, state[a, _TABLE],
                                         par[a, _HALF_PLAY], scale, par[a, _QUANTUM])  # fmt: skip
        motor = _quantised(state[a, 0], par[a, _QUANTUM]) if scale else enc
        state[a, _BUFX : _BUFX + _NBUF] = enc
        state[a, _BUFV : _BUFV + _NBUF] = motor if par[a, _VDIFF] != 0.0 else state[a, 1]
        state[a, _HIST : _HIST + _NHIST] = motor
        status[a, _CLAMPED] = 0
        status[a, _DIVERGED] = -1
        status[a, _BAD_REFERENCE] = -1
    for k in range(n_steps):
        j = k // every
        record = k - j * every == 0
        for a in range(n_axes):
            scale, difference = par[a, _SCALE] != 0.0, par[a, _VDIFF] != 0.0
            table, enc = _sensors(state[a, 0], state[a, 2] if par[a, _SCREW] != 0.0 else 0.0, state[a, _TABLE],
                                  par[a, _HALF_PLAY], scale, par[a, _QUANTUM])  # fmt: skip
            state[a, _TABLE] = table
            if noisy_encoder:
                enc += encoder_noise[k, a]
            # what the velocity loop reads: the motor encoder (its difference, below), else the motor velocity
            motor = (_quantised(state[a, 0], par[a, _QUANTUM]) if scale else enc) if difference else state[a, 1]
            n, f = int(par[a, _DELAY_N]), par[a, _DELAY_F]
            if n == 0 and f == 0.0:
                x_fb[a], v_fb[a] = enc, motor
            else:
                slot = k % _NBUF
                state[a, _BUFX + slot] = enc
                state[a, _BUFV + slot] = motor
                # np.int64(constant): numba compiles a callee once per literal argument, once per type otherwise
                x_fb[a] = _delayed(state, a, np.int64(_BUFX), k, n, f)
                v_fb[a] = motor if par[a, _DELAY_POSITION] != 0.0 else _delayed(state, a, np.int64(_BUFV), k, n, f)
            if difference:  # the drive's velocity: the difference of the motor encoder's (delayed) readings
                state[a, _HIST + k % _NHIST] = v_fb[a]
                past = state[a, _HIST + (k - int(par[a, _VTAPS])) % _NHIST]
                v_fb[a] = _difference(v_fb[a], past, par[a, _VGAIN], par[a, _VPOLE], state[a, _VEST])
                state[a, _VEST] = v_fb[a]
            if record:
                if write_tool:
                    y = table + state[a, 2]
                    if par[a, _NOISE] > 0.0:  # sample k of the axis's stream; a pair is drawn at a time
                        if state[a, _PAIR] != k >> 1:
                            state[a, _PAIR] = k >> 1
                            state[a, _GAUSS], state[a, _GAUSS + 1] = _gauss_pair(keys[a], k >> 1)
                        y += par[a, _NOISE] * state[a, _GAUSS + (k & 1)]
                    tool[j, a] = y
                if write_encoder:
                    encoder[j, a] = x_fb[a]
                if write_velocity:
                    velocity[j, a] = state[a, 1]
        if coupled:
            ex, ey, ez = _coupling_step(k, cpar, knots, knot_of_sample, cstate, x_fb, dvel)
            if record and write_estimate:
                estimate[j, 0], estimate[j, 1], estimate[j, 2] = ex, ey, ez
        for a in range(n_axes):
            x, v, d, w, i = state[a, 0], state[a, 1], state[a, 2], state[a, 3], state[a, 4]
            v_cmd = _velocity_command(par[a, _KP], par[a, _VFF], ref_pos[k, a], ref_vel[k, a], x_fb[a]) + dvel[a]
            i_ff = par[a, _AFF] * ref_acc[k, a]
            i_cmd, clamped, state[a, _ZV] = _velocity_controller(
                par[a, _VB], par[a, _VC], par[a, _VD], par[a, _ILIM], state[a, _ZV], v_cmd - v_fb[a], i_ff
            )
            status[a, _CLAMPED] += clamped
            computed = i_cmd
            i_cmd = _applied(par[a, _CDELAY], computed, state[a, _SENT], state[a, _SENT + 1])
            state[a, _SENT + 1], state[a, _SENT] = state[a, _SENT], computed
            if status[a, _BAD_REFERENCE] < 0 and not math.isfinite(ref_pos[k, a] + ref_vel[k, a] + ref_acc[k, a]):
                status[a, _BAD_REFERENCE] = k
            if record:
                if write_current:
                    current[j, a] = i_cmd
                if write_saturated:
                    saturated[j, a] = clamped
            electrical = par[a, _ELEC] != 0.0
            if electrical:
                u, state[a, _ZC] = _current_controller(par[a, _CB], par[a, _CC], par[a, _CD], state[a, _ZC], i_cmd - i)
            else:
                u = i_cmd
            # plant: Ad [x, v, d, ḋ, i] + Bu u + BF F, skipping the rows that are zero by construction
            # (a rigid axis has no d, ḋ; without electrical dynamics or a lag i is the held command u)
            # (rows as np.int64: one compiled _plant_row, not one per literal row number)
            friction = par[a, _FRICTION] != 0.0
            gapped = par[a, _HALF_GAP] != 0.0
            force = (par[a, _F0] - par[a, _FV] * v if friction else 0.0) + (external[k, a] if pushed else 0.0)
            # (a backlash in the screw: the stick-slip's prediction takes the spring's stretch beyond the gap)
            v_next = _plant_row(par, a, np.int64(1), x, v, _sprung(d, par[a, _HALF_GAP]) if gapped else d, w, i, u,
                                force)  # fmt: skip
            if friction:  # stick-slip: the force that stops the carriage at t_k+1, within the friction bounds
                level = _friction_level(par[a, _FC], par[a, _FS], par[a, _VS], v)
                dry = _dry_friction(level, par[a, _FA], -v_next / par[a, _BF + 1])
                force += dry
                v_next += par[a, _BF + 1] * dry
            if gapped:
                state[a, 0], state[a, 1], state[a, 2], state[a, 3], state[a, 4] = _gap_plant(par, a, x, v, d, w, i, u,
                                                                                             force)  # fmt: skip
                continue
            state[a, 0] = _plant_row(par, a, np.int64(0), x, v, d, w, i, u, force)
            state[a, 1] = v_next
            if par[a, _MODE] != 0.0:
                state[a, 2] = _plant_row(par, a, np.int64(2), x, v, d, w, i, u, force)
                state[a, 3] = _plant_row(par, a, np.int64(3), x, v, d, w, i, u, force)
            stepped = electrical or par[a, _LAGGED] != 0.0
            state[a, 4] = _plant_row(par, a, np.int64(4), x, v, d, w, i, u, force) if stepped else u
        if k % _DIVERGENCE_CHECK == 0 or k == n_steps - 1:
            for a in range(n_axes):
                if status[a, _DIVERGED] < 0 and not math.isfinite(state[a, 0] + state[a, 1] + state[a, 4]):
                    status[a, _DIVERGED] = k


def _no_coupling():
    """Coupling arguments of :func:`_variant` that switch it off (kind 0); the knots read-only, as a coupling's."""
    knots = np.zeros((1, 4))  # the shape of a coupling's knots (M, 4)
    knots.flags.writeable = False
    return np.zeros(_C_NPAR), knots, np.zeros(1, np.int64), np.zeros(_C_NSTATE)


# ---------------------------------------------------------------------------------------------
# Many variants, all axes, all steps: variants in the lanes


#: Most variants one thread steps together (the lanes of a block).
LANES = 32
_CHUNK = 128  # kept samples a block holds before writing them to the outputs
_MIN_LANES = 4  # narrower blocks step one variant at a time (faster below 4 lanes: 1 lane 0.6x, 2 lanes 0.9x, 4 lanes 2x)
_LANE_COUNT = (f"_lanes steps 1 to {LANES} variants (its rows' first dimension), with as many rows of status and of "
               "each output asked for")
# A block's numbers per axis and lane, in one array (axis, row, lane) of LANES lanes: a compile-time distance
# between any two rows, which lets LLVM see that the lanes' loads and stores do not overlap (and vectorise).
# Rows 0 .. NPAR - 1: the parameter row of pack(); then the state and the values passed between loops:
_LX, _LV, _LD, _LW, _LI = range(NPAR, NPAR + _NS)  # plant state (as _variant's state 0 .. 4)
_LZV, _LZC, _LTABLE = NPAR + _ZV, NPAR + _ZC, NPAR + _TABLE  # integrators, table behind the play
_LXFB, _LVFB = NPAR + 8, NPAR + 9  # fed-back position [mm] and velocity [mm/s] of the step
_LDRIVE, _LCLAMPED, _LCLAMPS = NPAR + 10, NPAR + 11, NPAR + 12  # current command, clamped (0/1), clamped steps so
# far (exact as a float up to 2**53)
_LLOWER, _LUPPER = NPAR + 13, NPAR + 14  # the dry friction's range of the step (_friction_bounds)
_LVEST, _LSENT = NPAR + 15, NPAR + 16  # as _variant's _VEST and (2 entries) _SENT
_LU, _LFORCE = NPAR + 18, NPAR + 19  # the plant's held input [V or A] and force [N] of the step (a non-rigid axis)
_LROWS = NPAR + 20
# Effects a block's axis has in any lane (the steps of the others are skipped for the whole block)
_ANY_QUANTUM, _ANY_DELAY, _ANY_NOISE, _ANY_STRIBECK, _ANY_MODE_OR_CURRENT_LOOP, _ANY_DIFFERENCE, _ANY_GAP = range(7)


def _lanes(rows, ref_pos, ref_vel, ref_acc, external, every, tool, encoder, velocity, current, saturated, status):
    """:func:`_step_lanes` of `rows` (L, n, NPAR), once its lane count is checked here: ``L`` outside 1 .. LANES, or
    status and outputs of another, raises ValueError (the lanes' arrays hold LANES lanes; numba checks no bounds).

    In Python, not in the compiled steps: there the same checks made ``run_batch`` of 128 variants 3x slower
    (``kernel_batch_vs_reference`` 0.53 -> 0.18, bench_kernel, b5c14f9 against d9cecd8).
    """
    n_lanes = rows.shape[0]
    if not 1 <= n_lanes <= LANES or status.shape[0] != n_lanes or any(
            a.shape[1] > 0 and a.shape[0] != n_lanes for a in (tool, encoder, velocity, current, saturated)):
        raise ValueError(_LANE_COUNT)
    _step_lanes(rows, ref_pos, ref_vel, ref_acc, external, every, tool, encoder, velocity, current, saturated, status)


@njit(cache=True, nogil=True, error_model="numpy")
def _step_lanes(rows, ref_pos, ref_vel, ref_acc, external, every, tool, encoder, velocity, current, saturated, status):
    """Step up to :data:`LANES` variants `rows` (L, n, NPAR) together, the variant index innermost.

    What :func:`_variant` does (coupling off), with the same operations in
    the same order for each lane (:func:`_rigid_row` leaves out terms that
    change nothing): bit for bit equal. The loops over the
    lanes vectorise: every lane computes every branch of the controllers
    and the plant and a select keeps its own; an effect that no lane of an
    axis has is skipped for the block, and the steps that do not vectorise
    (noise, the Stribeck exponential, the delay's reads) run only for the
    axes that have them. Outputs (L, ceil(N / every), n) with no rows are
    not asked for; the kept samples go to them :data:`_CHUNK` at a time.
    `external` (N, n): the known external forces [N] every lane gets (no rows: none).
    `status` (L, n, 3) as for :func:`_variant` (the reference is checked
    before; the lane count, by :func:`_lanes`).

    Where a new per-lane effect goes: its parameters are entries of the
    packed row (copied into ``p`` whole); a state of its own is a row of
    ``s`` after the others (``_LROWS`` grows; set in the loop that starts
    the lanes at rest); what it does each step goes into :func:`_advance`'s
    loop, branch-free (``x if on else y``: both computed, a select keeps
    one) so that it stays vectorised, or, when it does not vectorise (a
    call like ``math.exp``, a data-dependent read), into a loop of its own
    over the lanes before :func:`_advance`, run only when
    ``has[a, _ANY_...]`` (found from the rows before the steps) says a lane
    of the axis has it. An input sampled like the reference is read once
    per step and axis, like ``x_ref``, and passed to :func:`_advance` as a
    number shared by the lanes.
    """
    n_lanes, n_axes = rows.shape[0], rows.shape[1]
    n_steps, pushed = ref_pos.shape[0], external.shape[0] > 0
    s = np.empty((n_axes, _LROWS, LANES))  # see _LROWS; `p` where parameters are read
    p = s
    has = np.empty((n_axes, 7), np.bool_)
    for a in range(n_axes):
        for j in range(NPAR):
            for l in range(n_lanes):
                p[a, j, l] = rows[l, a, j]
        for e in range(7):
            has[a, e] = False
        for l in range(n_lanes):
            has[a, _ANY_QUANTUM] |= p[a, _QUANTUM, l] != 0.0
            has[a, _ANY_DELAY] |= p[a, _DELAY_N, l] != 0.0 or p[a, _DELAY_F, l] != 0.0
            has[a, _ANY_NOISE] |= p[a, _NOISE, l] > 0.0
            has[a, _ANY_STRIBECK] |= p[a, _FRICTION, l] != 0.0 and p[a, _FS, l] != 0.0
            has[a, _ANY_MODE_OR_CURRENT_LOOP] |= p[a, _MODE, l] != 0.0 or p[a, _ELEC, l] != 0.0 or p[a, _LAGGED, l] != 0.0
            has[a, _ANY_DIFFERENCE] |= p[a, _VDIFF, l] != 0.0
            has[a, _ANY_GAP] |= p[a, _HALF_GAP, l] != 0.0
            for q in (_AD + 2, _AD + 3, _AD + 4, _AD + _NS + 2, _AD + _NS + 3, _AD + _NS + 4):
                # x and v do not depend on d, ḋ, i (pack's +0.0; see _rigid_row)
                has[a, _ANY_MODE_OR_CURRENT_LOOP] |= p[a, q, l] != 0.0 or math.copysign(1.0, p[a, q, l]) < 0.0
    buf_x = np.empty((n_axes, _NBUF, LANES))
    before = np.empty((_NS, LANES))
    hist = np.empty((n_axes, _NHIST, LANES))
    buf_v = np.empty((n_axes, _NBUF, LANES))
    gauss = np.empty((n_axes, 2, LANES))
    keys = np.empty((n_axes, LANES), np.uint64)
    diverged = np.empty((n_axes, LANES), np.int64)
    write_tool, write_encoder, write_velocity = tool.shape[1] > 0, encoder.shape[1] > 0, velocity.shape[1] > 0
    write_current, write_saturated = current.shape[1] > 0, saturated.shape[1] > 0
    kept_tool = np.empty((_CHUNK if write_tool else 0, n_axes, LANES))
    kept_encoder = np.empty((_CHUNK if write_encoder else 0, n_axes, LANES))
    kept_velocity = np.empty((_CHUNK if write_velocity else 0, n_axes, LANES))
    kept_current = np.empty((_CHUNK if write_current else 0, n_axes, LANES))
    kept_saturated = np.empty((_CHUNK if write_saturated else 0, n_axes, LANES))
    for a in range(n_axes):  # at rest at the first reference position; the delay buffers hold the first reading
        for l in range(n_lanes):
            for q in range(NPAR, _LROWS):
                s[a, q, l] = 0.0
            scale, difference = p[a, _SCALE, l] != 0.0, p[a, _VDIFF, l] != 0.0
            start, table, s[a, _LD, l] = _at_rest(ref_pos[0, a], p[a, _APPROACH, l], p[a, _HALF_PLAY, l],
                                                  p[a, _HALF_GAP, l], scale)  # fmt: skip
            s[a, _LX, l] = start
            s[a, _LLOWER, l], s[a, _LUPPER, l] = _friction_bounds(p[a, _FC, l], p[a, _FA, l])
            table, enc = _sensors(start, s[a, _LD, l], table, p[a, _HALF_PLAY, l], scale, p[a, _QUANTUM, l])
            motor = _quantised(start, p[a, _QUANTUM, l]) if scale else enc
            s[a, _LTABLE, l] = table
            s[a, _LXFB, l] = table + s[a, _LD, l] if scale else start  # quantised in the first step
            s[a, _LVFB, l] = start if difference else 0.0  # the motor encoder (the difference's), or the velocity
            for q in range(_NBUF):
                buf_x[a, q, l] = enc
                buf_v[a, q, l] = motor if difference else 0.0
            for q in range(_NHIST):
                hist[a, q, l] = motor
            keys[a, l] = _mix(np.uint64(p[a, _SEED, l]) * np.uint64(n_axes + 1) + np.uint64(a))
            diverged[a, l] = -1
    pair = -1  # the pair of noise samples held (the same for every lane)
    first = 0  # the first kept sample held in kept_*
    for k in range(n_steps):
        j = k // every
        record = k - j * every == 0
        row = j - first
        if record and row == _CHUNK:
            _flush(kept_tool, tool, first, row)
            _flush(kept_encoder, encoder, first, row)
            _flush(kept_velocity, velocity, first, row)
            _flush(kept_current, current, first, row)
            _flush(kept_saturated, saturated, first, row)
            first, row = j, 0
        draw = record and write_tool and pair != k >> 1
        if draw:
            pair = k >> 1
        for a in range(n_axes):
            # the play and the encoder of this step were found at the end of the last one
            if has[a, _ANY_QUANTUM]:
                for l in range(n_lanes):
                    s[a, _LXFB, l] = _quantised(s[a, _LXFB, l], p[a, _QUANTUM, l])
                    motor = _quantised(s[a, _LVFB, l], p[a, _QUANTUM, l])
                    s[a, _LVFB, l] = motor if p[a, _VDIFF, l] != 0.0 else s[a, _LVFB, l]
            if has[a, _ANY_DELAY]:
                slot = k % _NBUF
                for l in range(n_lanes):
                    buf_x[a, slot, l] = s[a, _LXFB, l]
                    buf_v[a, slot, l] = s[a, _LVFB, l]
                    n, f = int(p[a, _DELAY_N, l]), p[a, _DELAY_F, l]
                    if n != 0 or f != 0.0:
                        i0, i1 = (k - n) % _NBUF, (k - n - 1) % _NBUF
                        s[a, _LXFB, l] = _between(buf_x[a, i0, l], buf_x[a, i1, l], f)
                        late = _between(buf_v[a, i0, l], buf_v[a, i1, l], f)
                        s[a, _LVFB, l] = s[a, _LVFB, l] if p[a, _DELAY_POSITION, l] != 0.0 else late
            if has[a, _ANY_DIFFERENCE]:  # the drive's velocity, as in _variant (_LVFB: the motor encoder's reading)
                slot = k % _NHIST
                for l in range(n_lanes):
                    hist[a, slot, l] = s[a, _LVFB, l]
                    past = hist[a, (k - int(p[a, _VTAPS, l])) % _NHIST, l]
                    estimate = _difference(s[a, _LVFB, l], past, p[a, _VGAIN, l], p[a, _VPOLE, l], s[a, _LVEST, l])
                    s[a, _LVEST, l] = estimate
                    s[a, _LVFB, l] = estimate if p[a, _VDIFF, l] != 0.0 else s[a, _LVFB, l]
            if record and write_tool:
                for l in range(n_lanes):
                    kept_tool[row, a, l] = s[a, _LTABLE, l] + s[a, _LD, l]
                if has[a, _ANY_NOISE]:  # sample k of each lane's stream; a pair is drawn at a time
                    for l in range(n_lanes):
                        if p[a, _NOISE, l] > 0.0:
                            if draw:
                                gauss[a, 0, l], gauss[a, 1, l] = _gauss_pair(keys[a, l], k >> 1)
                            kept_tool[row, a, l] += p[a, _NOISE, l] * gauss[a, k & 1, l]
            if record and write_encoder:
                for l in range(n_lanes):
                    kept_encoder[row, a, l] = s[a, _LXFB, l]
            if record and write_velocity:
                for l in range(n_lanes):
                    kept_velocity[row, a, l] = s[a, _LV, l]
            if has[a, _ANY_STRIBECK]:  # math.exp does not vectorise: apart, for the axes that need it (else: fc's)
                for l in range(n_lanes):
                    level = _friction_level(p[a, _FC, l], p[a, _FS, l], p[a, _VS, l], s[a, _LV, l])
                    s[a, _LLOWER, l], s[a, _LUPPER, l] = _friction_bounds(level, p[a, _FA, l])
            x_ref, v_ref, a_ref = ref_pos[k, a], ref_vel[k, a], ref_acc[k, a]
            pushing = external[k, a] if pushed else 0.0
            if has[a, _ANY_GAP]:  # the state the gap's substeps start from (a loop of their own: they do not vectorise)
                for q in range(_NS):
                    for l in range(n_lanes):
                        before[q, l] = s[a, _LX + q, l]
            if has[a, _ANY_MODE_OR_CURRENT_LOOP]:  # two versions of the step, compiled apart
                _advance(s, a, n_lanes, x_ref, v_ref, a_ref, pushing, False)
            else:
                _advance(s, a, n_lanes, x_ref, v_ref, a_ref, pushing, True)
            if has[a, _ANY_GAP]:  # a backlash in a compliant screw: its plant, from the step's input and force
                for l in range(n_lanes):
                    if p[a, _HALF_GAP, l] != 0.0:
                        x_next, v_next, s[a, _LD, l], s[a, _LW, l], s[a, _LI, l] = _gap_plant(
                            rows[l], a, before[0, l], before[1, l], before[2, l], before[3, l], before[4, l],
                            s[a, _LU, l], s[a, _LFORCE, l])  # fmt: skip
                        s[a, _LX, l], s[a, _LV, l] = x_next, v_next
                        _readings(s, a, l, x_next, v_next)
            if record and write_current:
                for l in range(n_lanes):
                    kept_current[row, a, l] = s[a, _LDRIVE, l]
            if record and write_saturated:
                for l in range(n_lanes):
                    kept_saturated[row, a, l] = s[a, _LCLAMPED, l]
        if k % _DIVERGENCE_CHECK == 0 or k == n_steps - 1:
            for a in range(n_axes):
                for l in range(n_lanes):
                    if diverged[a, l] < 0 and not math.isfinite(s[a, _LX, l] + s[a, _LV, l] + s[a, _LI, l]):
                        diverged[a, l] = k
    row = (n_steps - 1) // every + 1 - first
    _flush(kept_tool, tool, first, row)
    _flush(kept_encoder, encoder, first, row)
    _flush(kept_velocity, velocity, first, row)
    _flush(kept_current, current, first, row)
    _flush(kept_saturated, saturated, first, row)
    for l in range(n_lanes):
        for a in range(n_axes):
            status[l, a, _CLAMPED] = int(s[a, _LCLAMPS, l])
            status[l, a, _DIVERGED] = diverged[a, l]
            status[l, a, _BAD_REFERENCE] = -1


@njit(cache=True, error_model="numpy", inline="always")
def _advance(s, a, n_lanes, x_ref, v_ref, a_ref, pushing, rigid):
    """Controllers and plant of axis `a` of the lanes of :func:`_step_lanes` for one step, and the next step's encoder.

    Every lane computes every branch and a select keeps its own, so that the
    loop vectorises. ``rigid`` (a constant where this is inlined): no lane
    has a structural mode or a current loop, whose rows are then skipped;
    else the plant's input and force are kept for a compliant screw's
    backlash, whose plant :func:`_step_lanes` steps after this.
    `pushing`: the known external force of the step [N], the same for every lane.
    """
    p = s
    for l in range(n_lanes):
        v_cmd = _velocity_command(p[a, _KP, l], p[a, _VFF, l], x_ref, v_ref, s[a, _LXFB, l]) + 0.0  # no coupling
        i_cmd, sat, s[a, _LZV, l] = _velocity_controller(p[a, _VB, l], p[a, _VC, l], p[a, _VD, l],
                                                         p[a, _ILIM, l], s[a, _LZV, l], v_cmd - s[a, _LVFB, l],
                                                         p[a, _AFF, l] * a_ref)  # fmt: skip
        applied = _applied(p[a, _CDELAY, l], i_cmd, s[a, _LSENT, l], s[a, _LSENT + 1, l])
        s[a, _LSENT + 1, l] = s[a, _LSENT, l]
        s[a, _LSENT, l] = i_cmd
        i_cmd = applied
        s[a, _LDRIVE, l] = i_cmd
        s[a, _LCLAMPED, l] = 1.0 if sat else 0.0
        s[a, _LCLAMPS, l] += 1.0 if sat else 0.0
        x, v, d, w, i = s[a, _LX, l], s[a, _LV, l], s[a, _LD, l], s[a, _LW, l], s[a, _LI, l]
        electrical = p[a, _ELEC, l] != 0.0
        u = i_cmd
        if not rigid:
            u, zc = _current_controller(p[a, _CB, l], p[a, _CC, l], p[a, _CD, l], s[a, _LZC, l], i_cmd - i)
            u = u if electrical else i_cmd
            s[a, _LZC, l] = zc if electrical else s[a, _LZC, l]
        rubbing = p[a, _FRICTION, l] != 0.0
        force = (p[a, _F0, l] - p[a, _FV, l] * v if rubbing else 0.0) + pushing
        sprung = d
        if not rigid:  # as in _variant
            sprung = _sprung(d, p[a, _HALF_GAP, l]) if p[a, _HALF_GAP, l] != 0.0 else d
        v_next = _rigid_row(p, a, l, 1, x, v, u, force) if rigid else _lane_row(p, a, l, 1, x, v, sprung, w, i, u, force)
        bf = p[a, _BF + 1, l]
        dry = min(max(-v_next / bf, s[a, _LLOWER, l]), s[a, _LUPPER, l])  # _dry_friction, its bounds found before
        force = force + dry if rubbing else force
        v_next = v_next + bf * dry if rubbing else v_next
        x_next = _rigid_row(p, a, l, 0, x, v, u, force) if rigid else _lane_row(p, a, l, 0, x, v, d, w, i, u, force)
        s[a, _LX, l] = x_next
        s[a, _LV, l] = v_next
        if rigid:
            s[a, _LI, l] = u
        else:
            mode = p[a, _MODE, l] != 0.0
            s[a, _LD, l] = _lane_row(p, a, l, 2, x, v, d, w, i, u, force) if mode else d
            s[a, _LW, l] = _lane_row(p, a, l, 3, x, v, d, w, i, u, force) if mode else w
            stepped = electrical or p[a, _LAGGED, l] != 0.0
            s[a, _LI, l] = _lane_row(p, a, l, 4, x, v, d, w, i, u, force) if stepped else u
            s[a, _LU, l], s[a, _LFORCE, l] = u, force
        _readings(s, a, l, x_next, v_next)


@njit(cache=True)
def _readings(s, a, l, x_next, v_next):
    """Lane `l`'s next play and encoder readings from its next motor position and velocity (:func:`_advance`).

    `s` holds the lanes' parameter rows and states (:func:`_step_lanes`).
    """
    table = _play(x_next, s[a, _LTABLE, l], s[a, _HALF_PLAY, l])
    s[a, _LTABLE, l] = table
    deflection = s[a, _LD, l] if s[a, _SCREW, l] != 0.0 else 0.0  # what a scale reads beyond the table
    s[a, _LXFB, l] = table + deflection if s[a, _SCALE, l] != 0.0 else x_next
    s[a, _LVFB, l] = x_next if s[a, _VDIFF, l] != 0.0 else v_next


@njit(cache=True)
def _lane_row(p, a, l, r, x, v, d, w, i, u, force):
    """Row `r` of lane `l`'s plant update, as :func:`_plant_row` (`p`: axis, quantity, lane)."""
    base = _AD + _NS * r
    return _affine(p[a, base, l], p[a, base + 1, l], p[a, base + 2, l], p[a, base + 3, l], p[a, base + 4, l],
                   p[a, _BU + r, l], p[a, _BF + r, l], x, v, d, w, i, u, force)  # fmt: skip


@njit(cache=True)
def _rigid_row(p, a, l, r, x, v, u, force):
    """Row `r` (0: x, 1: v) of a rigid axis without current loop: :func:`_lane_row` without its zero terms, bit for bit.

    There ``d = ḋ = +0`` always and the row's coefficients of ``d, ḋ, i`` are
    +0.0 (:func:`_step_lanes` checks), so :func:`_affine` adds ``+0, +0, ±0`` (``±0·i``,
    `i` finite; a NaN `i` has made `x` and `v` NaN already) after
    ``c0·x + c1·v``: the first turns a -0 into +0 and the others change
    nothing, which is what ``+ 0.0`` does.
    """
    base = _AD + _NS * r
    return ((p[a, base, l] * x + p[a, base + 1, l] * v) + 0.0) + p[a, _BU + r, l] * u + p[a, _BF + r, l] * force


@njit(cache=True)
def _flush(kept, out, first, count):
    """Write the first `count` kept samples (sample, axis, lane) to `out` (lane, sample, axis) from sample `first`.

    ``out[...] = kept`` converts a float to bool as numpy does (nonzero: True).
    """
    if kept.shape[0] == 0:
        return
    for j in range(count):  # this order writes faster than lane by lane (float64 1.3x, float32 1.2x, bool 1.9x)
        for a in range(out.shape[2]):
            for l in range(out.shape[0]):
                out[l, first + j, a] = kept[j, a, l]


# ---------------------------------------------------------------------------------------------
# Packing


def _continuous_plant(servo, effects, gap_open=False):
    """``(A, B, states)``: the plant's continuous matrices over its present states, inputs (u or i, F).

    The servo's (:func:`contoursim.servo._plant_matrices`, with its `gap_open`), with the structural mode of
    `effects` if any.
    """
    mode = None
    if effects.mode_freq_hz is not None:
        if servo.compliant:
            raise ValueError("a structural mode (vibration) on an axis with a compliant screw (motor_mass, "
                             "screw_stiffness): the kernel holds one mode per axis, the screw's")
        m2 = servo.mass * effects.mode_mass_ratio
        wn = 2.0 * np.pi * effects.mode_freq_hz
        mode = (m2, m2 * wn * wn, 2.0 * effects.mode_damping_ratio * m2 * wn)
    return _plant_matrices(servo, mode, gap_open)


def _padded_zoh(servo, effects, dt, gap_open=False):
    """The plant's exact ZOH over `dt` on all five states: ``Ad`` (25, row-major), ``Bu`` (5), ``BF`` (5) in one array
    (read-only: it may be shared, see :data:`_ZOHS`).

    Without a current state the current holds the command of the period (its ``Bu`` entry 1).
    """
    A, B, states = _continuous_plant(servo, effects, gap_open)
    key = (A.tobytes(), B.tobytes(), tuple(states), float(dt))
    padded = _ZOHS.get(key)
    if padded is None:
        Ad, Bd = zoh(A, B, dt)
        full_Ad, full_Bd = np.zeros((_NS, _NS)), np.zeros((_NS, 2))
        full_Ad[np.ix_(states, states)], full_Bd[states] = Ad, Bd
        if 4 not in states:
            full_Bd[4, 0] = 1.0  # ideal current loop: the current state holds the command of the period
        padded = _read_only(np.concatenate([full_Ad.ravel(), full_Bd[:, 0], full_Bd[:, 1]]))
        if len(_ZOHS) >= _ZOHS_KEPT:
            _ZOHS.clear()
        _ZOHS[key] = padded
    return padded


#: The plants' ZOHs packed lately, by their continuous matrices and period: a fit's variants of the controller (a
#: finite-difference Jacobian's steps of its gains) share one plant, whose matrix exponentials are then taken once.
_ZOHS = {}
_ZOHS_KEPT = 4096


def _pi_row(gain, ti, dt, share=VELOCITY_INTEGRATORS["tustin"]):
    """``(B, C, D)`` of the sampled PI of :func:`contoursim.servo.discretize` (``(0, 0, gain)`` for a P), its integral
    adding `share` of the present sample's error (:data:`~contoursim.servo.VELOCITY_INTEGRATORS`)."""
    if ti is None:
        return 0.0, 0.0, gain
    return dt, gain / ti, gain * (1.0 + share * dt / ti)


def pack(servo, dt, effects=LoopEffects()):
    """One axis's parameter row for the kernel: closed-form numbers, no python-control, no check.

    Parameters
    ----------
    servo : AxisServo
    dt : float
        Servo period [s].
    effects : LoopEffects, optional
        The axis's in-loop and sensor effects (default: none).

    Returns
    -------
    ndarray, shape (NPAR,)
        The exact ZOH plant (:func:`contoursim.servo.zoh`), the sampled
        controllers of :func:`contoursim.servo.discretize`, gains, limit,
        the drive's velocity difference and computation delay, and the
        effects' parameters (a backlash in a compliant screw: the ZOH
        plants of its substeps, the gap closed and open, step 1 of the
        module docstring).

    Raises
    ------
    TypeError
        `servo` is not an AxisServo or `effects` not a LoopEffects.
    ValueError
        A bad `dt`, or a feedback delay beyond :data:`MAX_DELAY_SAMPLES`.

    Notes
    -----
    `pack` does not check the loop (that is what makes a variant cheap): a
    variant with new gains, masses or effects may be unstable, and its
    stability is the caller's business. :func:`run` checks each AxisServo's
    nominal linear loop (:func:`contoursim.servo.check`, once per servo);
    :func:`spectral_radius` is a cheap check of a packed row. Noise on the
    encoder (``noise_at="encoder"``) is not in the row: :func:`run` draws
    it, and a batch of rows has none.
    """
    if not isinstance(servo, AxisServo):
        raise TypeError(f"servo must be an AxisServo, got {type(servo).__name__}")
    if not isinstance(effects, LoopEffects):
        raise TypeError(f"effects must be a LoopEffects, got {type(effects).__name__}")
    dt = _validate.positive("dt", dt)
    delay = effects.feedback_delay_s / dt
    if delay > MAX_DELAY_SAMPLES * (1 + 1e-12):
        raise ValueError(
            f"feedback_delay_s = {effects.feedback_delay_s:g} s is {delay:.4g} servo periods of {dt:g} s; "
            f"the kernel holds at most {MAX_DELAY_SAMPLES} periods ({MAX_DELAY_SAMPLES * dt:g} s)"
        )
    row = np.zeros(NPAR)
    row[_MODE] = float(effects.mode_freq_hz is not None or servo.compliant)
    row[_SCREW] = float(servo.compliant)
    row[_AD : _BF + _NS] = _padded_zoh(servo, effects, dt)
    row[_KP], row[_VFF], row[_AFF] = servo.kp, servo.vff, servo.aff / servo.force_gain
    row[_AMP] = 1.0 / servo.force_constant
    row[_VB : _VD + 1] = _pi_row(servo.kv_mm, servo.ti, dt, servo.integrator_share)
    if servo.electrical:
        row[_CB : _CD + 1] = _pi_row(servo.kc, servo.ti_current, dt)
        row[_ELEC] = 1.0
    row[_ILIM] = np.finfo(float).max if servo.current_limit is None else servo.current_limit
    e = effects
    if servo.compliant and e.backlash_mm > 0.0:  # the screw's dead zone, its contacts timed within substeps
        substeps = math.ceil(_GAP_SUBSTEPS_PER_CYCLE * servo.screw_mode_hz * dt)
        row[_HALF_GAP], row[_SUBSTEPS] = e.backlash_mm / 2.0, substeps
        row[_ENGAGED : _ENGAGED + 35] = _padded_zoh(servo, effects, dt / substeps)
        row[_OPEN : _OPEN + 35] = _padded_zoh(servo, effects, dt / substeps, gap_open=True)
    else:
        row[_HALF_PLAY] = e.backlash_mm / 2.0
    row[_APPROACH] = e.backlash_approach
    row[_SCALE] = float(servo.position_feedback == "scale")
    friction = (e.coulomb_N, e.viscous_N_s_per_m / 1000.0, e.stribeck_N, e.stribeck_velocity_mm_s, e.asymmetry_N,
                e.offset_N)  # fmt: skip
    row[_FRICTION] = float(any(friction[i] != 0.0 for i in (0, 1, 2, 4, 5)))
    row[_FC : _F0 + 1] = friction
    whole = math.floor(delay + 1e-9)
    row[_DELAY_N], row[_DELAY_F] = whole, max(delay - whole, 0.0)
    row[_DELAY_POSITION] = float(e.feedback_delay_on == "position")
    row[_QUANTUM], row[_NOISE], row[_SEED] = e.quantum_mm, e.noise_mm if e.noise_at == "recorded" else 0.0, e.seed
    row[_VDIFF] = float(servo.velocity_feedback == "difference")
    row[_VTAPS], row[_VGAIN] = servo.velocity_taps, 1.0 / (servo.velocity_taps * dt)
    row[_VPOLE] = 0.0 if servo.velocity_filter_hz is None else math.exp(-2.0 * math.pi * servo.velocity_filter_hz * dt)
    row[_CDELAY] = servo.computation_delay
    row[_LAGGED] = float(servo.current_bandwidth_hz is not None)
    return row


def loop_matrices(row):
    """The linear sampled loop of a packed axis, with an extra velocity command as its input.

    The plant (with its structural mode and current loop), the controllers,
    the feedback delay, the drive's velocity difference and computation
    delay, without saturation, backlash, friction and quantisation:
    ``s_{k+1} = phi·s_k + b·w_k`` and ``x_fb,k = c·s_k``, with ``w`` added
    to the velocity command [mm/s] (what a :class:`Coupling` does) and
    ``x_fb`` the position the loop closes on [mm].

    Parameters
    ----------
    row : array_like, shape (NPAR,)
        One axis's row from :func:`pack`.

    Returns
    -------
    phi : ndarray, shape (S, S)
        State transition: plant, integrators in use, delayed samples,
        velocity low-pass, commands not yet applied [-].
    b : ndarray, shape (S,)
        Input vector of the extra velocity command.
    c : ndarray, shape (S,)
        Output row of the fed-back position.
    """
    p = _validate.finite_array("row", row, shape=(NPAR,))
    electrical, integral = p[_ELEC] != 0.0, p[_VC] != 0.0
    n_delay, f = int(p[_DELAY_N]), p[_DELAY_F]
    delayed, difference = bool(n_delay or f), p[_VDIFF] != 0.0
    n_v, f_v = (0, 0.0) if p[_DELAY_POSITION] != 0.0 else (n_delay, f)  # the velocity loop's delay
    taps, filtered, n_sent = int(p[_VTAPS]), difference and p[_VPOLE] != 0.0, int(p[_CDELAY])
    table = p[_SCREW] != 0.0 and p[_SCALE] != 0.0  # the position loop reads the table x + d, the difference x
    # past samples of x, x + d and v the loop reads (x_fb = (1 - f)·x[k - n] + f·x[k - n - 1], and `taps` steps before)
    depth_x = max(n_delay + 1 if delayed and not table else 0, n_v + taps + (f_v != 0.0) if difference else 0)
    depth_s = n_delay + 1 if delayed and table else 0
    depth_v = n_v + 1 if (n_v or f_v) and not difference else 0
    # state: plant (5), then the integrators in use, the delayed x, x + d and v samples (k-1 .. k-depth), the
    # low-passed velocity of the last step, the commands computed 1 (.. n_sent) periods ago; the input w rides along
    # as entry `size` of every row vector
    zv, zc = _NS, _NS + integral
    hx = zc + electrical
    hs = hx + depth_x
    hv = hs + depth_s
    vf = hv + depth_v
    sent = vf + filtered
    size = sent + n_sent
    Ad = p[_AD : _AD + _NS * _NS].reshape(_NS, _NS)
    Bu = p[_BU : _BU + _NS]

    def unit(index):
        r = np.zeros(size + 1)
        r[index] = 1.0
        return r

    def sample(now, history, back):
        """Row picking the signal whose row is `now` now (x, x + d or v) `back` samples ago."""
        return now if back == 0 else unit(history + back - 1)

    def fed_back(now, history, n, f, back=0):
        """Row of the signal `now` read ``n + f`` samples late, `back` samples before that."""
        back += n
        return (1.0 - f) * sample(now, history, back) + (f * sample(now, history, back + 1) if f else 0.0)

    x_now, v_now = unit(0), unit(1)
    reading, h_reading = (x_now + unit(2), hs) if table else (x_now, hx)  # what the position loop reads
    if difference:
        v_fb = (fed_back(x_now, hx, n_v, f_v) - fed_back(x_now, hx, n_v, f_v, taps)) * p[_VGAIN]
        if filtered:
            v_fb = p[_VPOLE] * unit(vf) + (1.0 - p[_VPOLE]) * v_fb
    else:
        v_fb = fed_back(v_now, hv, n_v, f_v)
    x_fb = fed_back(reading, h_reading, n_delay, f)
    e_v = -p[_KP] * x_fb - v_fb
    e_v[size] = 1.0
    i_cmd = p[_VD] * e_v
    if integral:
        i_cmd[zv] += p[_VC]
    u = unit(sent + n_sent - 1) if n_sent else i_cmd  # the command reaching the drive
    if electrical:
        e_i = u.copy()
        e_i[4] -= 1.0
        u = p[_CD] * e_i
        u[zc] += p[_CC]
    phi = np.zeros((size, size + 1))
    phi[:_NS, :_NS] = Ad
    phi[:_NS] += Bu[:, None] * u
    if integral:
        phi[zv] = p[_VB] * e_v
        phi[zv, zv] += 1.0
    if electrical:
        phi[zc] = p[_CB] * e_i
        phi[zc, zc] += 1.0
    for history, now, depth in ((hx, x_now, depth_x), (hs, reading, depth_s), (hv, v_now, depth_v)):
        for j in range(depth):
            phi[history + j] = sample(now, history, j)
    if filtered:
        phi[vf] = v_fb
    for j in range(n_sent):
        phi[sent + j] = i_cmd if j == 0 else unit(sent + j - 1)
    return phi[:, :size], phi[:, size], x_fb[:size]


def spectral_radius(row):
    """Largest closed-loop eigenvalue modulus of a packed axis's linear sampled loop: < 1 is stable.

    The cheap stability check of a variant (no python-control): the loop of
    :func:`loop_matrices`.

    Parameters
    ----------
    row : array_like, shape (NPAR,)
        One axis's row from :func:`pack`.

    Returns
    -------
    float
        ``max |λ|`` of the loop's state-transition matrix [-].
    """
    return float(np.abs(np.linalg.eigvals(loop_matrices(row)[0])).max())


# ---------------------------------------------------------------------------------------------
# Runs


def _axes(servos):
    """``(names, servos)`` from a sequence (named x, y, z, axis3, ...) or a mapping name -> AxisServo."""
    if isinstance(servos, Mapping):
        names, servos = list(servos.keys()), list(servos.values())
    else:
        servos = list(servos)
        names = [("x", "y", "z")[i] if i < 3 else f"axis{i}" for i in range(len(servos))]
    if not servos:
        raise ValueError("servos must hold at least one AxisServo")
    for name, servo in zip(names, servos):
        if not isinstance(servo, AxisServo):
            raise TypeError(f"servos[{name!r}] must be an AxisServo, got {type(servo).__name__}")
    return names, servos


def _reference(n_axes, ref_pos, ref_vel, ref_acc, finite):
    """The three reference arrays checked, as read-only C-contiguous float64 views, shape (N, n_axes).

    Read-only always (a view costs nothing), so that the compiled kernel has one
    signature whether the caller's arrays are writeable or not (numba types them apart).
    ``finite=False`` checks types and shapes only (:func:`run` has the kernel
    flag non-finite values as it reads them, and calls this again then).
    """
    check = _validate.finite_array if finite else _validate.float_array
    ref_pos = check("ref_pos", ref_pos, shape=(None, n_axes))
    n_steps = ref_pos.shape[0]
    if n_steps < 1:
        raise ValueError("ref_pos must hold at least one sample")
    ref_vel = check("ref_vel", ref_vel, shape=(n_steps, n_axes))
    ref_acc = check("ref_acc", ref_acc, shape=(n_steps, n_axes))
    return tuple(_read_only(np.ascontiguousarray(r)) for r in (ref_pos, ref_vel, ref_acc))


def _external(force, n_steps, n):
    """The known external forces checked, shape (n_steps, n) [N], as a writeable C-contiguous copy (no rows: none).

    Writeable always (the compiled kernel has one signature: numba types read-only arrays apart).
    """
    if force is None:
        return np.empty((0, n))
    return np.array(_validate.finite_array("force", force, shape=(n_steps, n)), order="C")


def _read_only(array):
    view = array.view()
    view.flags.writeable = False
    return view


def _initial_state(par, start):
    """At rest at the first reference position (:func:`_at_rest`): zero velocity, current, integrators."""
    state = np.zeros(par.shape[:-1] + (_NSTATE,))
    for a in range(par.shape[0]):
        state[a, 0], state[a, _TABLE], state[a, 2] = _at_rest(start[a], par[a, _APPROACH], par[a, _HALF_PLAY],
                                                               par[a, _HALF_GAP], par[a, _SCALE] != 0.0)
    state[..., _PAIR] = -1.0
    return state


def _encoder_noise(effects, n_steps):
    """The noise on the encoder readings, shape (n_steps, n) [mm] (no rows when no axis has any).

    Axis a's samples are numpy's standard normal stream seeded ``(seed, a)``
    times its `noise_mm`; an axis without encoder noise gets zeros.
    """
    if not any(e.noise_at == "encoder" and e.noise_mm > 0.0 for e in effects):
        return np.empty((0, len(effects)))
    noise = np.zeros((n_steps, len(effects)))
    for a, e in enumerate(effects):
        if e.noise_at == "encoder" and e.noise_mm > 0.0:
            noise[:, a] = e.noise_mm * np.random.default_rng((e.seed, a)).standard_normal(n_steps)
    return noise


def run(servos, dt, ref_pos, ref_vel, ref_acc, coupling=None, effects=None, force=None):
    """Simulate all axes' servo loops, with their in-loop effects, on a sampled reference.

    Every axis's nominal loop is checked first (:func:`contoursim.servo.check`:
    ``dt`` short enough, sampled loop stable and well damped; analysed once
    per servo in a process). The axes start at rest at the first reference
    position, with zero current and empty integrators.

    Parameters
    ----------
    servos : sequence of AxisServo or mapping str -> AxisServo
        One servo per axis, in the column order of the reference arrays
        (a sequence names them x, y, z).
    dt : float
        Servo period [s]; the reference is sampled at ``k·dt``.
    ref_pos : array_like, shape (N, n)
        Position commands [mm].
    ref_vel : array_like, shape (N, n)
        Velocity commands [mm/s] (used by velocity feedforward).
    ref_acc : array_like, shape (N, n)
        Acceleration commands [mm/s^2] (used by acceleration feedforward).
    coupling : Coupling, optional
        Cross-coupled contour controller: estimates the contour error every
        step and corrects the velocity commands of the first 2 or 3 axes.
    effects : mapping str -> LoopEffects, optional
        In-loop and sensor effects by axis name (axes not named, or named
        with ``None``, have none).
    force : array_like, shape (N, n), optional
        A known external force on each axis's carriage [N], positive towards
        positive positions, held over each servo period (step 7 of the
        module docstring: added to the disturbance force); none by default.

    Returns
    -------
    ServoResponse

    Raises
    ------
    TypeError
        A servo that is not an :class:`~contoursim.servo.AxisServo`, a
        coupling that is not a :class:`Coupling`, effects that are not
        :class:`LoopEffects`.
    ValueError
        Bad shapes or values, `dt` too long for a loop, or effects naming an
        unknown axis.
    UnstableLoopError
        An axis's sampled loop is unstable or badly damped, or the simulation
        with its effects or coupling diverged.

    Examples
    --------
    A ramp at 10 mm/s with a P-PI loop settles to the following error v/kp:

    >>> axis = AxisServo(mass=300.0, force_constant=900.0, kv=200.0, ti=0.01, kp=40.0)
    >>> t = np.arange(4000) * 2e-4
    >>> ramp = (10.0 * t)[:, None]
    >>> r = run([axis], 2e-4, ramp, np.full_like(ramp, 10.0), np.zeros_like(ramp))
    >>> round(float(ramp[-1, 0] - r.position[-1, 0]), 6)     # 10 / 40 [mm]
    0.25
    """
    names, servos = _axes(servos)
    dt = _validate.positive("dt", dt)
    n = len(servos)
    ref_pos, ref_vel, ref_acc = _reference(n, ref_pos, ref_vel, ref_acc, finite=False)
    if coupling is not None and not isinstance(coupling, Coupling):
        raise TypeError(f"coupling must be a Coupling, got {type(coupling).__name__}")
    if coupling is not None and coupling.path.shape != (ref_pos.shape[0], min(n, 3)):
        raise ValueError(f"the coupling's path must have shape ({ref_pos.shape[0]}, {min(n, 3)}) "
                         f"(one row per reference sample, the first {min(n, 3)} axes), got {coupling.path.shape}")
    effects = {} if effects is None else dict(effects)
    unknown = [name for name in effects if name not in names]
    if unknown:
        raise ValueError(f"effects name axis {unknown[0]!r}, which is not one of the axes {', '.join(names)}")
    for name, servo in zip(names, servos):
        servo.check(dt, name)
    par = np.array([pack(servo, dt, effects.get(name) or LoopEffects()) for name, servo in zip(names, servos)])

    n_steps = ref_pos.shape[0]
    external = _external(force, n_steps, n)
    state = _initial_state(par, ref_pos[0])
    noise = _encoder_noise([effects.get(name) or LoopEffects() for name in names], n_steps)
    # An array each, also where the encoder reads the tool position exactly: it reads -0 where the tool stands at +0
    # (the table plus a rigid axis's +0 deflection), as run_batch's are.
    signals = np.empty((4, n_steps, n))  # one block, which malloc keeps for the next run
    position, encoder, velocity, current = signals
    saturated = np.empty((n_steps, n), bool)
    status = np.empty((n, 3), np.int64)
    if coupling is None:
        cpar, knots, knot_of_sample, cstate = _no_coupling()
        estimate = np.empty((0, 3))
    else:
        # the kernel compiles for one array type (a read-only array is another): writeable copies, but the knots
        # read-only as all knots are (nearest.distinct's: one compiled search with the exact contour error's)
        cpar, knots, knot_of_sample = coupling.params.copy(), coupling.knots, coupling.knot_of_sample.copy()
        cpar[_C_DT], cstate = dt, np.zeros(_C_NSTATE)
        estimate = np.empty((n_steps, 3))
    outputs = (position, encoder, velocity, current, saturated, estimate, status)
    _variant(par, state, ref_pos, ref_vel, ref_acc, cpar, knots, knot_of_sample, cstate, noise, external, 1, *outputs)
    if status[:, _BAD_REFERENCE].max() >= 0:
        _reference(n, ref_pos, ref_vel, ref_acc, finite=True)  # names the first non-finite value
    diverged = status[:, _DIVERGED]
    if diverged.max() >= 0:
        a = int(np.argmax(diverged >= 0))
        raise UnstableLoopError(
            f"the simulation of axis {names[a]!r} diverged by t = {diverged[a] * dt:.6g} s (step {diverged[a]}): "
            "its loop with these effects (or this coupling) is unstable"
        )
    return ServoResponse(dt, *outputs[:5], contour_estimate=None if coupling is None else estimate)


def run_batch(rows, dt, ref_pos, ref_vel, ref_acc, outputs=("tool",), every=1, dtype=np.float64, couplings=None,
              force=None):
    """Run B variants of one machine on one reference, the variants side by side in SIMD lanes.

    Each variant is a stack of :func:`pack` rows (one per axis); row ``b``
    gives exactly (bit for bit) what :func:`run` gives for the same packed
    axes. Blocks of up to :data:`LANES` variants step together, the variant
    index innermost (numba vectorises the loops over them; an effect that
    no variant of a block has costs that block nothing), the reference
    read once per step for all of them (blocks of fewer than 4 variants
    step them one at a time, as :func:`run`). The compiled steps release
    the GIL: ``numba.get_num_threads()`` threads step a block each at a
    time (a pool of threads, not a ``prange``: no parallel-loop compile
    on the first run).
    Nothing is checked about the variants' stability (see :func:`pack`).
    Memory stays bounded by asking only for the outputs
    needed, keeping every `every`-th sample and/or storing float32: 500
    variants x 50,000 samples x 3 axes of tool position is 600 MB in
    float64, 300 MB in float32, 30 MB in float32 with ``every=10``.

    Parameters
    ----------
    rows : array_like, shape (B, n, NPAR)
        Packed variants.
    dt : float
        Servo period [s] the rows were packed for (used for the time base only).
    ref_pos : array_like, shape (N, n)
        Position commands [mm], shared by all variants.
    ref_vel : array_like, shape (N, n)
        Velocity commands [mm/s].
    ref_acc : array_like, shape (N, n)
        Acceleration commands [mm/s^2].
    outputs : sequence of str, default ("tool",)
        Signals to return, from :data:`BATCH_OUTPUTS`: ``"tool"`` (recorded
        tool position [mm]), ``"encoder"`` (fed-back position [mm]),
        ``"velocity"`` [mm/s], ``"current"`` (current command [A]),
        ``"saturated"`` (bool, current command clamped).
    every : int, default 1
        Keep the samples ``k = 0, every, 2·every, …`` only.
    dtype : {numpy.float64, numpy.float32}, default float64
        Storage type of the float outputs (the simulation runs in float64).
    couplings : sequence of Coupling, optional
        One cross-coupled controller per variant (gains may differ), all on
        one path (equal ``path`` arrays); none by default.
    force : array_like, shape (N, n), optional
        A known external force on each axis [N], shared by all variants
        (see :func:`run`); none by default.

    Returns
    -------
    dict
        ``"t"``: the kept sample times, shape (M,) [s], with
        ``M = ceil(N / every)``; one array (B, M, n) per requested output;
        ``"saturated_count"``: clamped steps per variant and axis over all
        N steps, shape (B, n); ``"diverged_step"``: the step by which the
        plant state was found not finite (checked every 256 steps: an
        unstable variant, whose outputs mean nothing from up to 256 steps
        before), -1 for none, shape (B, n).
    """
    rows = _validate.finite_array("rows", rows, ndim=3)
    rows = np.ascontiguousarray(rows)
    n_variants, n, width = rows.shape
    if width != NPAR:
        raise ValueError(f"rows must have shape (B, n_axes, {NPAR}) (rows from pack()), got {rows.shape}")
    dt = _validate.positive("dt", dt)
    ref_pos, ref_vel, ref_acc = _reference(n, ref_pos, ref_vel, ref_acc, finite=True)
    unknown = [name for name in outputs if name not in BATCH_OUTPUTS]
    if isinstance(outputs, str) or unknown:
        raise ValueError(f"outputs must name signals from {', '.join(BATCH_OUTPUTS)}, got {outputs!r}")
    if isinstance(every, bool) or not isinstance(every, (int, np.integer)):
        raise TypeError(f"every must be an integer, got {every!r}")
    if every < 1:
        raise ValueError(f"every must be positive, got {every!r}")
    dtype = _validate.float_dtype("dtype", dtype)
    n_steps = ref_pos.shape[0]
    kept = -(-n_steps // every)
    external = _external(force, n_steps, n)

    def out(name, kind):
        # Not touched here: the blocks write their rows whole, _CHUNK samples at a time, so the page faults of a
        # fresh array are taken by the threads in parallel (a serial fill first cost more than the steps in
        # simulate_batch's sweeps on the loaded 2-core machine: 0.1-0.3 s per 130 MB).
        return np.empty((n_variants, kept if name in outputs else 0, n), kind)

    arrays = {name: out(name, dtype) for name in BATCH_OUTPUTS[:4]}
    arrays["saturated"] = out("saturated", bool)
    status = np.empty((n_variants, n, 3), np.int64)
    cpar, knots, knot_of_sample, cstate = _no_coupling()
    cpars = np.tile(cpar, (n_variants, 1))
    if couplings is not None:
        couplings = list(couplings)
        if len(couplings) != n_variants or not all(isinstance(c, Coupling) for c in couplings):
            raise ValueError(f"couplings must be {n_variants} Coupling objects, one per variant")
        first = couplings[0]
        if first.path.shape != (n_steps, min(n, 3)) or any(
                c.path is not first.path and not np.array_equal(c.path, first.path) for c in couplings):
            raise ValueError(f"the couplings must share one path of shape ({n_steps}, {min(n, 3)})")
        cpars = np.array([c.params for c in couplings])
        cpars[:, _C_DT] = dt
        knots, knot_of_sample = first.knots, first.knot_of_sample.copy()  # one compiled type: as run()'s
    threads = get_num_threads()
    blocks = threads * max(1, -(-n_variants // (threads * LANES)))  # as few as fill the lanes, as many for every thread
    lanes = max(1, -(-n_variants // blocks))
    signals = list(arrays.values())
    every = _validate.positive_int("every", every)

    def block(lo):
        # Blocks narrower than _MIN_LANES, and cross-coupled variants (the lanes run no coupling), step one variant at
        # a time (_variant, as run() does: the same numbers).
        hi = min(lo + lanes, n_variants)
        if lanes >= _MIN_LANES and couplings is None:
            _lanes(rows[lo:hi], ref_pos, ref_vel, ref_acc, external, every, *(a[lo:hi] for a in signals), status[lo:hi])
            return
        no_noise, no_estimate = np.empty((0, n)), np.empty((0, 3))
        for b in range(lo, hi):
            state = _initial_state(rows[b], ref_pos[0])
            _variant(rows[b], state, ref_pos, ref_vel, ref_acc, cpars[b], knots, knot_of_sample, cstate.copy(),
                     no_noise, external, every, *(a[b] for a in signals), no_estimate, status[b])  # fmt: skip

    starts = range(0, n_variants, lanes)
    if len(starts) == 1 or threads == 1:
        for lo in starts:
            block(lo)
    else:  # the compiled steps release the GIL: a thread per core steps its blocks
        with ThreadPoolExecutor(min(threads, len(starts))) as pool:
            list(pool.map(block, starts))
    result = {"t": np.arange(kept) * every * dt}
    result.update((name, arrays[name]) for name in outputs)
    result["saturated_count"] = status[..., _CLAMPED]
    result["diverged_step"] = status[..., _DIVERGED]
    return result
