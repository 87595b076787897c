"""The stepping kernel: all axes' sampled servo cascades advanced together at the servo period.

At step k, for every axis, the controllers read the state sampled at ``t_k``
and compute their outputs, which are held (zero-order hold) over
``[t_k, t_k+1)``; the plant then advances one period with the exact ZOH
matrices of :func:`contoursim.servo.discretize`. The discrete controllers are
exactly those of ``discretize(dt)`` (Tustin PI, state ``z = ∫e dt``), read
from its state-space blocks, so the unsaturated kernel reproduces
python-control's simulation of that discrete interconnection.

One step of one axis is a chain of small ``@njit`` helpers, each the one
place an in-loop element belongs (the effects catalogue's backlash and delay
act on the fed-back position and the command, Coulomb friction on the plant's
force — none is modelled yet):

* the fed-back position ``x_fb`` (the sampled load position), read once per
  step for every axis before the compensator sees it;
* :func:`_velocity_command` — position controller plus velocity
  feedforward (the compensator's corrections are added around it);
* :func:`_velocity_controller` — velocity PI, acceleration feedforward,
  current saturation with anti-windup;
* :func:`_current_controller` — the current PI (skipped for an ideal
  current loop);
* :func:`_plant_step` — the exact ZOH plant update.

The helpers take and return scalars (state goes in and comes back out) or
read the parameter array without branching: an array passed into a helper
that branches keeps numba's reference counting in the loop, ten times slower.

A compensator that sees every axis each step plugs in through
:class:`Compensator`.
"""

from collections.abc import Mapping
from dataclasses import dataclass
from functools import lru_cache

import numpy as np
from ._numba import njit
from numba.core.dispatcher import Dispatcher

from . import _validate
from .servo import AxisServo, discretize

__all__ = ["Compensator", "ServoResponse", "run"]

# Per-axis parameter row (float64) -----------------------------------------------------------
_AD = 0  # 9 entries: plant Ad (3 x 3, row-major), states x [mm], v [mm/s], i [A]
_BD = 9  # 3 entries: plant Bd, input u [V] (or the current command [A])
_KP = 12  # position gain [1/s]
_VFF = 13  # velocity feedforward gain [-]
_AFF = 14  # acceleration feedforward [A per mm/s^2] = aff · mass / force_constant / 1000 (aff / force_gain)
_VB, _VC, _VD = 15, 16, 17  # velocity controller: z += VB·e; i = VC·z + VD·e
_CB, _CC, _CD = 18, 19, 20  # current controller: z += CB·e; u = CC·z + CD·e
_ILIM = 21  # current limit [A] (inf: none)
_ELEC = 22  # 1.0 when the current loop is modelled
_NPAR = 23

# Per-axis state ----------------------------------------------------------------------------
_X, _V, _I = 0, 1, 2  # plant: position [mm], velocity [mm/s], motor current [A]
_ZV, _ZC = 3, 4  # velocity / current controller integrators [mm], [A·s]
_NSTATE = 5


@dataclass(frozen=True)
class Compensator:
    """A controller that sees every axis each step (cross-coupled contour control, ...).

    Parameters
    ----------
    step : numba-jitted function
        ``step(k, ref_pos, ref_vel, ref_acc, position, state, params, dpos, dvel)``,
        called once per servo period before the axis controllers, with the
        step index ``k``, the full reference arrays (shape (N, n), [mm],
        [mm/s], [mm/s^2]) and the fed-back axis positions ``position``
        (shape (n,), [mm]) sampled at ``t_k``. It writes per-axis corrections
        to the position commands ``dpos`` [mm] and velocity commands ``dvel``
        [mm/s] (shape (n,), zeroed before each call) and may update its own
        ``state`` array in place. It must not keep state anywhere else.
    state : ndarray of float
        Initial state (any shape). The kernel works on a copy and returns the
        final state in :attr:`ServoResponse.compensator_state`.
    params : ndarray of float
        Parameters (any shape), read only.
    """

    step: Dispatcher
    state: np.ndarray
    params: np.ndarray

    def __post_init__(self):
        if not isinstance(self.step, Dispatcher):
            raise TypeError(f"compensator step must be a numba @njit function, got {type(self.step).__name__}")
        state = _validate.finite_array("compensator state", self.state)
        params = _validate.finite_array("compensator params", self.params)
        params.flags.writeable = False
        object.__setattr__(self, "state", state)
        object.__setattr__(self, "params", params)


@dataclass(frozen=True)
class ServoResponse:
    """What the kernel returns: the sampled axis signals, time first.

    Parameters
    ----------
    t : ndarray, shape (N,)
        Sample times ``k·dt`` [s].
    position : ndarray, shape (N, n)
        Actual axis positions at ``t_k`` [mm].
    velocity : ndarray, shape (N, n)
        Actual axis velocities at ``t_k`` [mm/s].
    current : ndarray, shape (N, n)
        Current command held over ``[t_k, t_k+1)`` [A]: velocity-controller
        output plus acceleration feedforward, after saturation.
    saturated : ndarray of bool, shape (N, n)
        True where the current command was clamped at the current limit.
    compensator_state : ndarray or None
        The compensator's state after the last step; ``None`` without one.
    """

    t: np.ndarray
    position: np.ndarray
    velocity: np.ndarray
    current: np.ndarray
    saturated: np.ndarray
    compensator_state: np.ndarray | None = None

    def __post_init__(self):
        t = _validate.finite_array("t", self.t, ndim=1)
        position = _validate.finite_array("position", self.position, ndim=2)
        shape = (t.size, position.shape[1])
        arrays = dict(
            t=t,
            position=position,
            velocity=_validate.finite_array("velocity", self.velocity, shape=shape),
            current=_validate.finite_array("current", self.current, shape=shape),
            saturated=np.asarray(self.saturated, bool),
        )
        if arrays["position"].shape != shape or arrays["saturated"].shape != shape:
            raise ValueError(f"position and saturated must have shape {shape}")
        for name, value in arrays.items():
            value.flags.writeable = False
            object.__setattr__(self, name, value)


# ---------------------------------------------------------------------------------------------
# One axis, one step


@njit(cache=True)
def _velocity_command(p, a, x_ref, v_ref, x_fb):
    """Position P controller plus velocity feedforward [mm/s] (reads `p` without branching)."""
    return p[a, _KP] * (x_ref - x_fb) + p[a, _VFF] * v_ref


@njit(cache=True)
def _velocity_controller(b, c, d, limit, z, e_v, i_ff):
    """Velocity PI (or P) + acceleration feedforward, clamped to ``±limit``.

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
def _plant_step(p, a, x, v, i, u):
    """The plant state one period later, ``Ad [x, v, i] + Bd u`` (reads `p` without branching)."""
    return (
        p[a, _AD + 0] * x + p[a, _AD + 1] * v + p[a, _AD + 2] * i + p[a, _BD + 0] * u,
        p[a, _AD + 3] * x + p[a, _AD + 4] * v + p[a, _AD + 5] * i + p[a, _BD + 1] * u,
        p[a, _AD + 6] * x + p[a, _AD + 7] * v + p[a, _AD + 8] * i + p[a, _BD + 2] * u,
    )


# ---------------------------------------------------------------------------------------------
# All axes, all steps


def _simulate(
    par, state, ref_pos, ref_vel, ref_acc, comp_step, comp_state, comp_params, position, velocity, current, saturated
):
    """Step all axes over the reference; fills the output arrays and advances `state`, `comp_state` in place.

    ``par`` (n, _NPAR) and ``state`` (n, _NSTATE) follow the layouts above;
    ``comp_step`` is ``None`` (pruned at compile time) or a compensator step
    function; the outputs have shape (N, n).
    """
    n_steps, n_axes = ref_pos.shape
    x_fb = np.empty(n_axes)
    dpos = np.zeros(n_axes)
    dvel = np.zeros(n_axes)
    for k in range(n_steps):
        for a in range(n_axes):
            x_fb[a] = state[a, _X]
        if comp_step is not None:
            dpos[:] = 0.0
            dvel[:] = 0.0
            comp_step(k, ref_pos, ref_vel, ref_acc, x_fb, comp_state, comp_params, dpos, dvel)
        for a in range(n_axes):
            x, v, i = state[a, _X], state[a, _V], state[a, _I]
            position[k, a] = x
            velocity[k, a] = v
            v_cmd = _velocity_command(par, a, ref_pos[k, a] + dpos[a], ref_vel[k, a], x_fb[a]) + dvel[a]
            i_ff = par[a, _AFF] * ref_acc[k, a]
            i_cmd, clamped, state[a, _ZV] = _velocity_controller(
                par[a, _VB], par[a, _VC], par[a, _VD], par[a, _ILIM], state[a, _ZV], v_cmd - v, i_ff
            )
            current[k, a] = i_cmd
            saturated[k, a] = clamped
            if par[a, _ELEC] == 0.0:
                u = i_cmd
            else:
                u, state[a, _ZC] = _current_controller(par[a, _CB], par[a, _CC], par[a, _CD], state[a, _ZC], i_cmd - i)
            state[a, _X], state[a, _V], state[a, _I] = _plant_step(par, a, x, v, i, u)


# Without a compensator the loop compiles once and is cached on disk. A compensator's step
# function is a type of its own, which numba cannot cache across sessions (the cache would
# grow by one entry per session), so that variant compiles in memory, once per function.
_simulate_plain = njit(cache=True)(_simulate)
_simulate_compensated = njit(_simulate)


def _pi_coefficients(block):
    """``(B, C, D)`` of a Tustin PI block (``A = 1``) or ``(0, 0, D)`` of a P block."""
    if block.nstates == 0:
        return 0.0, 0.0, float(block.D[0, 0])
    return float(block.B[0, 0]), float(block.C[0, 0]), float(block.D[0, 0])


@lru_cache(maxsize=256)
def _parameters(servo, dt, axis):
    """Check one axis at `dt` and pack its sampled loop into a kernel parameter row."""
    servo.check(dt, axis)
    d = discretize(servo, dt)
    n = d.plant.nstates
    Ad, Bd = np.zeros((3, 3)), np.zeros(3)
    Ad[:n, :n], Bd[:n] = d.plant.A, d.plant.B[:, 0]
    if n == 2:
        Bd[_I] = 1.0  # ideal current loop: the current state holds the command of the period
    row = np.zeros(_NPAR)
    row[_AD : _AD + 9] = Ad.ravel()
    row[_BD : _BD + 3] = Bd
    row[_KP], row[_VFF], row[_AFF] = servo.kp, servo.vff, servo.aff / servo.force_gain
    row[_VB], row[_VC], row[_VD] = _pi_coefficients(d.velocity_controller)
    if d.current_controller is not None:
        row[_CB], row[_CC], row[_CD] = _pi_coefficients(d.current_controller)
        row[_ELEC] = 1.0
    row[_ILIM] = np.inf if servo.current_limit is None else servo.current_limit
    row.flags.writeable = False
    return row


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


def run(servos, dt, ref_pos, ref_vel, ref_acc, compensator=None):
    """Simulate all axes' servo loops on a sampled reference.

    Every axis is checked first (:func:`contoursim.servo.check`: ``dt`` short
    enough, sampled loop stable and well damped). The axes start at rest at
    the first reference position, with zero current and empty integrators.

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
    compensator : Compensator, optional
        Sees every axis each step and corrects the position/velocity commands.

    Returns
    -------
    ServoResponse

    Raises
    ------
    TypeError
        A servo that is not an :class:`~contoursim.servo.AxisServo`, a
        compensator that is not a :class:`Compensator`.
    ValueError
        Bad shapes or values, or `dt` too long for a loop.
    UnstableLoopError
        An axis's sampled loop is unstable or badly damped.

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
    ref_pos = _validate.finite_array("ref_pos", ref_pos, shape=(None, n))
    n_steps = ref_pos.shape[0]
    if n_steps < 1:
        raise ValueError("ref_pos must hold at least one sample")
    ref_vel = _validate.finite_array("ref_vel", ref_vel, shape=(n_steps, n))
    ref_acc = _validate.finite_array("ref_acc", ref_acc, shape=(n_steps, n))
    if compensator is not None and not isinstance(compensator, Compensator):
        raise TypeError(f"compensator must be a Compensator, got {type(compensator).__name__}")

    par = np.array([_parameters(servo, dt, name) for name, servo in zip(names, servos)])
    state = np.zeros((n, _NSTATE))
    state[:, _X] = ref_pos[0]
    position, velocity, current = (np.empty((n_steps, n)) for _ in range(3))
    saturated = np.empty((n_steps, n), bool)
    arrays = (position, velocity, current, saturated)
    if compensator is None:
        empty = np.zeros(0)
        _simulate_plain(par, state, ref_pos, ref_vel, ref_acc, None, empty, empty, *arrays)
        comp_state = None
    else:
        comp_state = compensator.state.copy()
        step, params = compensator.step, compensator.params
        _simulate_compensated(par, state, ref_pos, ref_vel, ref_acc, step, comp_state, params, *arrays)
    return ServoResponse(np.arange(n_steps) * dt, *arrays, compensator_state=comp_state)
