"""Nominal servo identification from a measured trace: what a diagnosis compares against without a model.

Users often do not know their drives' parameters. From the commanded and
measured positions alone, :func:`identify_machine` fits a cascade of a P
position loop around a P or PI velocity loop with velocity feedforward:

- ONE position gain ``kp`` [1/s] shared by all axes (NC position gains are
  normally set equal; a gain identified per axis would silently absorb a
  ``gain_mismatch``, which the diagnosis must be able to name), at least
  5 1/s (an NC's is 10–100);
- ONE velocity-feedforward fraction ``vff`` [-] shared by all axes (set in
  the NC, like the gain);
- per axis, the velocity-loop bandwidth ``ω_v`` [rad/s]: with the plant's
  mass and force constant fixed at :data:`MASS` and :data:`FORCE_CONSTANT`,
  ``kv = ω_v·MASS/FORCE_CONSTANT``, at most a fifth of the Nyquist
  frequency (a faster loop is beyond what the sampled controller can do);
  the position loop's damping follows from ``kp/ω_v``;
- per axis, where the trace shows it, the velocity loop's integral time
  ``ti`` (as ``ti·ω_v``, between 1.5 and 50): most drives run PI velocity
  loops, which a P loop can only imitate with an unbounded ``ω_v``;
- per axis, behind a PI loop and where the trace shows it, the viscous
  damping, as the mechanical pole ``c/m`` (0.01–100 /s): the integrator
  holds the steady speed against it, the pole shows in the transients;
- an axis whose reference never moves shows nothing of its loop: it takes
  that of the first axis that moves, its own parameters held out of the fit
  (an effect-free YZ circle of an independent simulator, X standing still,
  was left at 24.9 µm RMS in 0.35 µm of noise by a fit stuck where X's free
  loop had wandered; 0.348 µm now, as with the idle axis second);
- ONE drive structure for all axes (:data:`STATE` or one of
  :data:`DRIVES`): the velocity loop closed on the motor velocity itself,
  or, as real drives do, on the backward difference of the encoder over 1
  or 2 servo periods with the command applied 0 or 1 period late. Each is
  a different lag in the velocity loop, which ``ω_v`` alone cannot
  imitate at the same time in the steady lag and the transients.

A position trace carries no force, so the mass is not identifiable: forces
of in-loop effects fitted on an identified machine (``force_N`` of
``coulomb_friction``) are in the units of this assumed axis and say only
how the effect compares between axes and runs.

The fit: starting values from a regression of the tracking error on the
commanded velocity and acceleration (a P/P cascade lags by
``e ≈ (1 − vff)·v/kp + (1/(kp·ω_v) − (1 − vff)²/kp²)·a``), then
:func:`scipy.optimize.least_squares` on the tracking error through the
simulator (each axis's mean taken out: a trace's zero is not its loop's,
and an offset left in would correlate the residual over the whole run),
each finite-difference Jacobian one :func:`simulate_batch` call: first
without feedforward, then with it, kept only when it is significant
(:func:`delta_bic`): kp and vff set the steady lag together, and only the
transients tell them apart. The fit with it starts from both ends of that
valley, the fit without it and a feedforward of 0.9 at the same lag (a
start at one end can stop there), and keeps the better, unless its kp ran
to the lower bound: a position loop all but open leaves each axis's lag to
its own velocity loop, which then absorbs a difference of the axes'
position gains or delays. Then with a PI velocity loop, kept likewise
(or when the P loop's bandwidth ran to its bound: it was imitating an
integrator); then with the damping, kept likewise. These stages run on the state
structure; each drive structure of :data:`DRIVES` is then fitted from
there with the PI loop and the damping free, kept or not on the state
structure (behind a sampled loop's lags the mechanical pole can show
where on the state structure it did not). Each stage starts from the last
one's fit, so all of them can stay in the valley the regression's start
lies in: the point of least residual on a coarse grid over kp, vff,
``ω_v/kp``, P or PI loop (with or without damping) and structure (one
batch a structure) is fitted too where it fits better than they do (an
independent two-mass trefoil, a velocity loop 1.5 times as fast as its
position loop behind a feedforward of 0.8, was left at 84.6 µm RMS in
0.3 µm of noise; 2.5 µm now). The fit of most
:func:`delta_bic` over the state structure's kept one replaces it when
that is significant (the choice of structure counted as one parameter,
and each parameter the state structure did not keep as one). The structures are those of a sampled loop at the
identified servo period (:func:`servo_period_for`, the trace's own up to
1 ms): a drive that runs faster than it logs is identified by the
structure whose lags match its own best at that period, not necessarily
by its own. The fits that do not depend on each other, the valley's two
ends and the drive structures, run side by side in forked processes, one
a core (:func:`contoursim._parallel.fork_map`; the same machine, to the
last bit, as one after the other).
A backlash held in place (`effects`, as a diagnosis holds one) is a play in the screw between the
motor and a table of its own: its axis is identified as two masses, 0.3 of :data:`MASS` on the
motor side of a screw whose mode is at 1.5 kHz (damped at 0.2: the play, not a mode the loops
cannot pin, is what they are identified around), read where the backlash is, and the loops at a
servo period of 0.25 ms or less (the trace's divided), its velocity loop's bandwidth bounded so
that on the motor side alone, which the loop drives across the play, it is within a fifth of the
Nyquist frequency (unbounded, loops refitted around a backlash of an outside tester's Z went
unstable). On a rigid axis a play stops the table as the motor turns back, where a table coasts
until the screw's force on it turns; and the motor crosses the play in a fraction of a
millisecond, which loops sampled at a 1 ms log do not follow.
An independent rigid axis with a 15.7 µm play read by the motor's encoder, on a square logged at
1 ms (its drive at 0.25 ms; 6.30 µm RMS left by the loops identified without it): loops
identified with a 15 µm play held left 9.72 µm on a rigid axis at 1 ms, 9.71 at 0.25 ms, 9.32 on
two masses at 1 ms, and 0.41 µm on two masses at 0.25 ms.
With a feedforward near 1 the steady lag is gone and kp shows only in the
transients: :func:`identify_machine` is then weakly determined in kp
(:data:`WEAK_KP_VFF`; the diagnosis says so).
"""

from dataclasses import replace

import numpy as np
from scipy.optimize import least_squares
from threadpoolctl import threadpool_limits

from . import _validate
from ._parallel import fork_map
from .machine import Machine
from .model import Model
from .servo import AxisServo
from .simulation import measured_reference, simulate_batch
from .traces import Trace

__all__ = ["DRIVES", "FORCE_CONSTANT", "MASS", "SIGNIFICANT", "STATE", "WEAK_KP_VFF", "autocorrelation_time", "delta_bic",
           "identification_warnings", "identify_machine", "servo_period_for"]

#: ΔBIC a parameter or an effect must add to be kept (2·ln Bayes factor > 10: "very strong", Kass & Raftery 1995).
SIGNIFICANT = 10.0
#: Moving mass assumed for an identified axis [kg] (not identifiable from positions).
MASS = 100.0
#: Force constant assumed for an identified axis [N/A]: with MASS, kv [A·s/m] = ω_v [rad/s].
FORCE_CONSTANT = 100.0

#: An identified velocity feedforward at or above this leaves almost no steady lag: kp is weakly identifiable.
WEAK_KP_VFF = 0.9

#: A drive structure, as :class:`AxisServo` fields ``(velocity_feedback, velocity_taps, computation_delay)``: the
#: velocity loop closed on the motor velocity itself, no computation delay.
STATE = ("state", 1, 0)
#: The sampled drive structures identification tries beside :data:`STATE` (one for all axes): the velocity from the
#: backward difference of the encoder over 1 or 2 periods, the command applied 0 or 1 period late.
DRIVES = tuple(("difference", n, k) for n in (1, 2) for k in (0, 1))

_FD_STEP = 1e-3
_FEWEST_SAMPLES = 16  # fewer samples than this leave the noise floor (from second differences) unknown; 3 gave kp 311
_KP_MIN = 5.0  # lowest identified position gain [1/s]: an NC's is 10-100 (1-6 m/min/mm)
_VALLEY_VFF = 0.9  # the feedforward the second search of the (kp, vff) valley starts from [-]
_AT_BOUND = 0.01  # a fitted log-parameter this close to its bound ran to it
_DIVERGED = 1e6  # a residual entry beyond this many tracking errors (its RMS) is a loop that diverged
_BANDWIDTH_FRACTION = 0.2  # highest identified velocity-loop bandwidth, a fraction of the Nyquist frequency
_TI_RANGE = (1.5, 50.0)  # range of ti·ω_v of an identified PI velocity loop [-]
_POLE_RANGE = (0.01, 100.0)  # range of the mechanical pole c/m of an identified viscous damping [1/s]
# an axis with a backlash held in place: two masses, the play in the screw between them (see identify_machine)
_PLAY_MOTOR_SHARE = 0.3  # share of MASS on the motor side (rotor and screw inertia: 0.2-0.4 of a ball-screw axis's)
_PLAY_SCREW_HZ = 1500.0  # the screw's relative mode [Hz] (a stiff ball-screw drive's: 1-2.5 kHz)
_PLAY_SCREW_DAMPING = 0.2  # ... damped well beyond a screw's 0.02-0.05: the play, not the mode the loops cannot pin
_PLAY_SERVO_PERIOD = 2.5e-4  # longest servo period [s] the loops are identified at with a backlash held


def _parameters(machine, axes, like):
    """``(structure, x)`` of :func:`_machine` nearest `machine`'s loops of `axes`, with a PI loop and a damping on
    every axis (``ti·ω_v`` 4 and a mechanical pole of 0.01 /s where an axis has none: held in place, an effect may
    need what the loops without it did not, a friction an integrator); kp, vff and the drive structure those of axis
    ``like[0]`` (the first that moves)."""
    servos = [machine.axes[a] for a in axes]
    first = servos[like[0]]
    w = np.array([s.kv * s.force_constant / s.mass for s in servos])
    x = [np.log(first.kp), first.vff, *np.log(w)]
    x += [np.log(4.0 if s.ti is None else s.ti * wi) for s, wi in zip(servos, w)]
    x += [np.log(max(s.damping / s.mass, _POLE_RANGE[0])) for s in servos]
    return (first.velocity_feedback, first.velocity_taps, first.computation_delay), np.array(x)


def servo_period_for(dt):
    """The servo period to simulate a trace sampled every `dt`: `dt` up to 1 ms, else `dt` divided to 1 ms or less.

    A `dt` within a millionth of 1 ms (or of a whole number of ms) is taken for it: a clock's rounding.

    Parameters
    ----------
    dt : float
        The trace's sample period [s].

    Returns
    -------
    float
        The servo period [s].
    """
    return dt / max(1, int(np.ceil(dt / 1e-3 - 1e-6)))


def _machine(axes, period, x, structure=STATE, like=None, play=None):
    """The machine of ``x = (log kp, vff, log ω_v per axis[, log(ti·ω_v) per axis[, log(c/m) per axis]])`` (a PI
    velocity loop; the viscous damping as the mechanical pole ``c/m`` [1/s]) with the drive `structure` on every axis,
    axis i with the loop of axis ``like[i]`` (default its own); the axes of `play` (``{axis: where its position loop
    reads}``) two masses with a screw between them (:data:`_PLAY_MOTOR_SHARE`, :data:`_PLAY_SCREW_HZ`)."""
    kp, vff = float(np.exp(x[0])), float(x[1])
    d = len(axes)
    servos = {}
    for i, a in enumerate(axes):
        j = i if like is None else like[i]
        w = float(np.exp(x[2 + j]))
        ti = float(np.exp(x[2 + d + j])) / w if len(x) > 2 + d else None
        damping = float(np.exp(x[2 + 2 * d + j])) * MASS if len(x) > 2 + 2 * d else 0.0
        servos[a] = AxisServo(mass=MASS, force_constant=FORCE_CONSTANT, kv=w * MASS / FORCE_CONSTANT, kp=kp, vff=vff, ti=ti,
                              damping=damping, velocity_feedback=structure[0], velocity_taps=structure[1],
                              computation_delay=structure[2])
    for a, feedback in (play or {}).items():
        motor = _PLAY_MOTOR_SHARE * MASS
        reduced = motor * (MASS - motor) / MASS
        stiffness = 1e-6 * reduced * (2 * np.pi * _PLAY_SCREW_HZ) ** 2  # [N/µm]
        servos[a] = replace(servos[a], motor_mass=motor, screw_stiffness=stiffness,
                            screw_damping_ratio=_PLAY_SCREW_DAMPING, position_feedback=feedback)
    return Machine(servos, period, name="identified from the trace")


def _start(trace, reference, period):
    """Starting parameters from the regression of the tracking error on commanded v and a."""
    n = len(trace.t)
    v, a = (_on_trace(trace, reference.t, x) for x in (reference.velocity, reference.acceleration))
    error = -trace.tracking_error  # lag: reference − actual [mm]
    slopes, curv = [], []
    for i in range(trace.reference.shape[1]):
        design = np.column_stack([v[:, i], a[:, i], np.ones(n)])
        coef = np.linalg.lstsq(design, error[:, i], rcond=None)[0]
        slopes.append(coef[0])
        curv.append(coef[1])
    slope = float(np.median(slopes))
    nyquist = np.pi / period
    kp = 1.0 / slope if 1.0 / nyquist < slope < 10.0 else 30.0
    x = [np.log(kp), 0.0]
    for b in curv:
        inv = b + 1.0 / kp**2  # 1/(kp·ω_v)
        w = 1.0 / (kp * inv) if inv > 0 else 10.0 * kp
        x.append(np.log(np.clip(w, 3.0 * kp, _BANDWIDTH_FRACTION * nyquist)))
    return np.array(x)


def _coarse_start(outputs, residual, x0, d, lower, upper):
    """The point of least residual on a coarse grid around the regression's start `x0`: ``(rss, structure, x)``.

    The grid: position gains from 10 1/s to the bound, each with the feedforward that keeps `x0`'s steady lag and
    with a feedforward of 1; velocity-loop bandwidths 1.5, 3 and 8 times the position gain; a P velocity loop, a PI
    one (``ti·ω_v = 4``) and a PI one with a mechanical pole ``c/m`` of 3 /s; each structure. `outputs(xs,
    structure)` simulates the points `xs`, `residual(y)` is the fit's residual of one output.
    """
    lag = np.exp(-x0[0])  # (1 − vff)/kp
    best = (np.inf, STATE, x0)
    for structure in (STATE,) + DRIVES:
        xs = []
        for kp in np.geomspace(10.0, np.exp(upper[0]), 6):
            for vff in sorted({float(np.clip(1.0 - kp * lag, 0.0, 1.0)), 1.0}):
                for ratio in (1.5, 3.0, 8.0):
                    w = np.clip(np.log(ratio * kp), lower[2], upper[2] - 1e-6)
                    p = [np.log(kp), vff] + [w] * d
                    pi = p + [np.log(4.0)] * d
                    xs += [np.array(p), np.array(pi), np.array(pi + [np.log(3.0)] * d)]
        for x, y in zip(xs, outputs(xs, structure)):
            r = residual(y)
            cost = float(r @ r) if np.all(np.isfinite(r)) else np.inf
            if cost < best[0]:
                best = (cost, structure, x)
    cost, structure, x = best
    return cost, structure, np.clip(x, lower[: x.size] + 1e-6, upper[: x.size] - 1e-6)


#: Runs a function with one BLAS thread. Identification's and diagnosis's least squares work on tall, thin Jacobians
#: (10⁴ residuals × at most a dozen parameters), too small for threads to share; and numpy and scipy each load their own
#: OpenBLAS, whose idle threads spin against each other's work: with their default threads an identification on 2
#: cores took 2.5 times as long (7.3 s against 2.9 s, the same fit).
one_blas_thread = threadpool_limits.wrap(limits=1, user_api="blas")


@one_blas_thread
def identify_machine(trace, servo_period=None, progress=None, effects=(), start=None):
    """Identify the nominal servo loop of each axis of a trace (see the module docstring).

    Parameters
    ----------
    trace : contoursim.traces.Trace
        The measured trace.
    servo_period : float, optional
        Servo period of the identified machine [s]; default
        :func:`servo_period_for` the trace's sample period.
    progress : callable, optional
        Called with one line of text per fit iteration.
    effects : sequence of Effect, optional
        Effects held in place while the loops are fitted (what a diagnosis
        named: a loop identified without them bends to them, one shared
        position gain to one axis's gain mismatch or delay). A backlash's
        axis is identified as two masses, read where the backlash is, and
        the loops at 0.25 ms or less unless `servo_period` is given (see
        the module docstring).
    start : Machine, optional
        Loops to fit from, with the trace's axes: one fit of every
        parameter from them, a PI velocity loop and a damping on every
        axis, on their drive structure and on each of :data:`STATE` and
        :data:`DRIVES`, the closest kept, in place of the staged search
        over starts and parameters kept (a diagnosis's held search ranks
        effects held in place so, from the loops identified without
        them). Its first moving axis's ``kp``, ``vff`` and structure are
        taken for all.

    Returns
    -------
    Machine
        Axes named as the trace's, each an :class:`AxisServo` with
        ``mass = MASS``, ``force_constant = FORCE_CONSTANT``, the shared
        ``kp`` and ``vff`` and its own ``kv`` (and ``ti`` where a PI
        velocity loop explains the trace significantly better, and behind
        it the ``damping`` where that does too). A trace
        whose reference never moves leaves them at their starting values.
    """
    if not isinstance(trace, Trace):
        raise TypeError(f"trace must be a Trace (contoursim.read_trace reads one from its CSV file), got "
                        f"{type(trace).__name__}")
    if len(trace.t) < _FEWEST_SAMPLES:
        raise ValueError(f"identifying the servo loops needs at least {_FEWEST_SAMPLES} samples, the trace has "
                         f"{len(trace.t)}: log a longer run, or give the nominal model (--model)")
    progress = _validate.callback("progress", progress)
    if start is not None and not (isinstance(start, Machine) and set(trace.axes) <= set(start.axes)):
        raise TypeError(f"start must be a Machine with the trace's axes {', '.join(trace.axes)}, got "
                        + (f"one with {', '.join(start.axes)}" if isinstance(start, Machine) else type(start).__name__))
    play = {e.axis: e.options["feedback"] or "motor" for e in effects if e.name == "backlash"}
    period = servo_period_for(trace.dt) if servo_period is None else _validate.positive("servo_period", servo_period)
    if play and servo_period is None:
        period /= np.ceil(period / _PLAY_SERVO_PERIOD - 1e-9)
    reference = measured_reference(trace, period)
    axes = trace.axes
    x0 = _start(trace, reference, period)
    nyquist = np.pi / period
    d = len(axes)
    top = _BANDWIDTH_FRACTION * nyquist
    lower = np.array([np.log(_KP_MIN), 0.0] + [np.log(1.0)] * d + [np.log(_TI_RANGE[0])] * d
                     + [np.log(_POLE_RANGE[0])] * d)
    # on two masses the velocity loop drives the motor side alone across the play: its bandwidth there, ω_v·m/m1, is
    # held to the same fraction of the Nyquist frequency (beyond it, refitted loops went unstable on a trace)
    reach = [top * (_PLAY_MOTOR_SHARE if a in play else 1.0) for a in axes]
    upper = np.array([np.log(0.5 * top), 1.0] + list(np.log(reach)) + [np.log(_TI_RANGE[1])] * d
                     + [np.log(_POLE_RANGE[1])] * d)
    x0 = np.clip(x0, lower[: x0.size] + 1e-6, upper[: x0.size] - 1e-6)
    measured = trace.actual
    scale = max(float(np.std(trace.tracking_error)), 1e-6)
    # an axis whose reference never moves shows nothing of its loop: it takes the loop of the first axis that moves,
    # its own parameters held (left free, they wandered, and on an outside tester's trace the others' fit stuck there)
    moving = np.ptp(trace.reference, axis=0) > 0
    like = [i if moving[i] or not moving.any() else int(np.argmax(moving)) for i in range(len(axes))]
    shown = np.concatenate([[True, True], np.tile([like[i] == i for i in range(len(axes))], 3)])
    cache = {}
    reached = {}  # per structure, the last point a fit's Jacobian was taken at (where a diverging fit stops)

    def outputs(xs, structure):
        tool = simulate_batch([Model(_machine(axes, period, x, structure, like, play), effects) for x in xs], reference,
                              settle=0.0, check=False)["tool_position"]
        return [_on_trace(trace, reference.t, y) for y in tool]

    def fun(x, structure):
        key = (x.tobytes(), structure)
        if key not in cache:
            cache.clear()
            cache[key] = residual(outputs([x], structure)[0])
        return cache[key]

    def residual(y):
        """The whitened residual of simulated positions `y`, each axis's mean taken out (the trace's zero is not the
        loop's: an instrument's zero or a geometric error at the path's place offsets it); NaN where the loop
        diverged (or all but: beyond :data:`_DIVERGED` tracking errors, a residual whose square overflows)."""
        r = (measured - y) / scale
        return (r - r.mean(axis=0)).ravel() if np.all(np.abs(r) < _DIVERGED) else np.full(r.size, np.nan)

    def jac(x, free, structure):
        steps = {j: _FD_STEP * (1 if x[j] + _FD_STEP <= upper[j] else -1) for j in np.flatnonzero(free)}
        r0 = fun(x, structure)
        if not np.all(np.isfinite(r0)):
            raise FloatingPointError("the identified loop diverged on this trace")
        rows = [x + h * np.eye(x.size)[j] for j, h in steps.items()]
        cols = [residual(y) for y in outputs(rows, structure)]
        if not all(np.all(np.isfinite(c)) for c in cols):
            raise FloatingPointError("a step of the identified loop diverged on this trace")
        reached[structure] = x
        if progress is not None:
            progress(f"identify: kp = {np.exp(x[0]):.2f} 1/s, vff = {x[1]:.3f}, "
                     f"RMS {1e3 * scale * np.sqrt(np.mean(r0**2)):.3g} µm")
        return np.column_stack([(c - r0) / h for c, h in zip(cols, steps.values())])

    def fitted(x, free, structure):
        """Least squares over the coordinates `free` of `x`, the others held; where the loop diverges, the last point
        reached."""
        free = free & shown[: x.size]

        def part(z):
            full = x.copy()
            full[free] = z
            return full

        lo, hi = lower[: x.size][free], upper[: x.size][free]
        reached[structure] = x
        try:
            fit = least_squares(lambda z: fun(part(z), structure), x[free], jac=lambda z: jac(part(z), free, structure),
                                bounds=(lo, hi), x_scale=1.0, max_nfev=40)
        except FloatingPointError:  # a fit that drives the loop unstable on this trace stops at its last stable point
            return reached[structure]
        return part(fit.x)

    def rss(x, structure):
        r = fun(x, structure)
        return float(r @ r) if np.all(np.isfinite(r)) else np.inf, autocorrelation_time(r.reshape(len(trace.t), d))

    if start is not None:  # one fit from `start` on its structure and on each other, the closest kept
        own, x = _parameters(start, axes, like)
        x = np.clip(x, lower[: x.size] + 1e-6, upper[: x.size] - 1e-6)
        free = np.ones(x.size, bool)
        free[1] = x[1] > 0.0
        structures = list(dict.fromkeys((own, STATE) + DRIVES))
        fits = zip(structures, fork_map(lambda structure: fitted(x, free, structure), structures))
        structure, x = min(fits, key=lambda fit: rss(fit[1], fit[0])[0])
        return _machine(axes, period, x, structure, like, play)

    # kp and vff set the steady lag together, (1 − vff)/kp: the feedforward is kept only when the
    # transients show it (ΔBIC over the fit without it), else a valley of (kp, vff) pairs fits alike
    start = x0.copy()
    start[1] = 0.0
    x1 = fitted(start, np.array([j != 1 for j in range(x0.size)]), STATE)
    # the valley is searched from both its ends: from the fit without feedforward, and from a feedforward of
    # _VALLEY_VFF with the same steady lag (a fit started at vff = 0 stops short of a feedforward near 1); a fit
    # whose kp ran to its lower bound is not one: a position loop all but open leaves each axis's lag to its
    # velocity loop, whose bandwidth per axis absorbs any difference of the axes' position gains
    valley = x1.copy()
    valley[0], valley[1] = max(x1[0] + np.log(1.0 - _VALLEY_VFF), lower[0] + 1e-6), _VALLEY_VFF
    fits = fork_map(lambda x: fitted(x, np.ones(x0.size, bool), STATE), (x1, valley))
    x2 = min((x for x in fits if x[0] > lower[0] + _AT_BOUND), key=lambda x: rss(x, STATE)[0], default=x1)
    (rss1, _), (rss2, tau) = rss(x1, STATE), rss(x2, STATE)
    feedforward = delta_bic(rss1, rss2, measured.size, 1, tau) > SIGNIFICANT
    best, rss0 = (x2, rss2) if feedforward else (x1, rss1)
    # a PI velocity loop, started where its integrator can act (ti·ω_v = 4, ω_v within reach of the P fit's)
    x3 = np.concatenate([best, np.full(d, np.log(4.0))])
    x3[2: 2 + d] = np.minimum(x3[2: 2 + d], np.log(0.5 * top))
    free = np.ones(x3.size, bool)
    free[1] = feedforward
    x3 = fitted(x3, free, STATE)
    rss3, tau = rss(x3, STATE)
    # a P loop pressed against the bandwidth bound is imitating an integrator: the PI loop is kept then too
    pressed = bool(np.any(best[2: 2 + d] > np.log(top) - _AT_BOUND))
    added = d  # the parameters the PI loop adds to the fit kept so far
    if delta_bic(rss0, rss3, measured.size, d, tau) > SIGNIFICANT or (pressed and rss3 <= rss0):
        best, rss0, added = x3, rss3, 0
    # the viscous damping behind the PI loop (its integrator holds the steady speed, the mechanical pole c/m shows in
    # the transients), started at a mechanical time constant of a second; kept likewise, counted with the PI loop
    # where that alone was not kept
    x4 = fitted(np.concatenate([x3, np.zeros(d)]), np.concatenate([free, np.ones(d, bool)]), STATE)
    rss4, tau = rss(x4, STATE)
    if delta_bic(rss0, rss4, measured.size, d + added, tau) > SIGNIFICANT:
        best, rss0 = x4, rss4
    # the sampled drive structures, each fitted from the state structure's fit with the PI loop and the damping free,
    # kept or not there: behind a sampled velocity loop's lags the mechanical pole can show where on the state
    # structure it did not (an effect-free trace was left at 8 times its noise)
    free = np.ones(x4.size, bool)
    free[1] = feedforward
    damped = x4.copy()  # started where a sampled velocity loop is well damped: ω_v within half its bound
    damped[2: 2 + d] = np.minimum(damped[2: 2 + d], np.log(0.5 * top))
    found = [(STATE, best, rss0), (STATE, x4, rss4)]
    found += [(drive, x, rss(x, drive)[0])
              for drive, x in zip(DRIVES, fork_map(lambda drive: fitted(damped, free, drive), DRIVES))]

    # each stage starts from the last one's fit: a trace whose loops lie far from the regression's start (a velocity
    # loop barely faster than its position loop, behind a feedforward) can leave them all in another valley (an
    # independent two-mass trefoil: 84.6 µm RMS left in 0.3 µm of noise). The best point of a coarse grid over the
    # loops and structures (one batch a structure) is fitted too where it fits better than they do, and competes as
    # they do unless its kp ran to the lower bound (as in the valley's search)
    cost, structure, x = _coarse_start(outputs, residual, x0, d, lower, upper)
    if cost < min(low for _, _, low in found):
        free = np.ones(x.size, bool)
        free[1] = x[1] > 0.0
        x = fitted(x, free, structure)
        if x[0] > lower[0] + _AT_BOUND:
            found.append((structure, x, rss(x, structure)[0]))

    def gain(fit):
        """ΔBIC of a fit over the state structure's kept one (a drive structure's choice counted as one parameter)."""
        structure, x, low = fit
        if not np.isfinite(low):  # a fit whose loop diverged on the trace
            return -np.inf
        return delta_bic(rss0, low, measured.size, x.size - best.size + (structure != STATE), rss(x, structure)[1])

    gains = [gain(fit) for fit in found]  # each one simulation (its residual's autocorrelation time)
    structure, x, _ = found[int(np.argmax(gains))] if max(gains) > SIGNIFICANT else found[0]
    return _machine(axes, period, x, structure, like, play)


def identification_warnings(machine, refitted=None):
    """What a diagnosis on an identified `machine` says of it: the drive structure chosen, an axis identified as two
    masses, a weakly determined kp.

    Parameters
    ----------
    machine : Machine
        A machine of :func:`identify_machine` (one kp, vff and structure for all axes).
    refitted : Machine, optional
        The diagnosis's refit of `machine`, the loops the report gives: kp is weakly determined where the velocity
        feedforward reaches :data:`WEAK_KP_VFF` as identified or as refitted.

    Returns
    -------
    list of str
    """
    servo = next(iter(machine.axes.values()))
    refit = max(s.vff for s in (refitted or machine).axes.values())
    period_ms = 1e3 * machine.servo_period
    if servo.velocity_feedback == "difference":
        drive = (f"velocity loops on the encoder's backward difference over {servo.velocity_taps} period(s), the command "
                 f"{servo.computation_delay} period(s) late, at a servo period of {period_ms:.3g} ms")
    else:
        drive = f"velocity loops on the motor velocity, at a servo period of {period_ms:.3g} ms"
    said = [f"identified drive structure: {drive} (chosen among the candidate structures by the fit)"]
    said += [f"axis {a} identified as two masses around the backlash held in place, the play in the screw between "
             f"them: {s.motor_mass / s.mass:.2g} of its mass on the motor side and the screw's mode at "
             f"{s.screw_mode_hz:.4g} Hz assumed, not fitted (on a rigid axis the play stops the table as the motor "
             "turns back)" for a, s in machine.axes.items() if s.compliant]
    if max(servo.vff, refit) >= WEAK_KP_VFF:
        vff = f"{servo.vff:.3g}" + (f" ({refit:.3g} as refitted)" if f"{refit:.3g}" != f"{servo.vff:.3g}" else "")
        said.append(f"the identified velocity feedforward is {vff}: with almost no steady lag left, the "
                    f"position gain kp = {servo.kp:.4g} 1/s shows only in the transients and is weakly determined "
                    "(a gain_mismatch or time_delay named on it is as uncertain)")
    return said


def autocorrelation_time(x):
    """Integrated autocorrelation time of a residual, in samples: the largest of its axes' (at least 1).

    ``τ = 1 + 2·Σ ρ_k``, summed until the autocorrelation ρ first turns
    negative; N/τ is the residual's number of effectively independent samples.

    Parameters
    ----------
    x : ndarray, shape (N, d)

    Returns
    -------
    float
        Between 1 and N/10.
    """
    taus = []
    for y in np.asarray(x, dtype=float).T:
        y = y - y.mean()
        n = len(y)
        f = np.fft.rfft(y, 2 * n)
        acf = np.fft.irfft(f * np.conj(f))[:n]
        if acf[0] <= 0:
            continue
        acf = acf / acf[0]
        negative = np.flatnonzero(acf <= 0)
        stop = negative[0] if negative.size else n
        taus.append(1.0 + 2.0 * acf[1:stop].sum())
    return float(np.clip(max(taus, default=1.0), 1.0, len(x) / 10))


def delta_bic(rss0, rss1, n, k, tau):
    """BIC gain of a model with `k` more parameters: ``n_eff·ln(rss0/rss1) − k·ln(n_eff)``, ``n_eff = n/tau``.

    Parameters
    ----------
    rss0, rss1 : float
        Residual sums of squares without and with the parameters.
    n : int
        Residual entries.
    k : int
        Parameters added.
    tau : float
        Autocorrelation time of the residual (:func:`autocorrelation_time`).

    Returns
    -------
    float
    """
    n_eff = n / tau
    # rss0 = 0: a trace followed exactly; rss1 = inf: a model that diverged (the ratio would underflow to 0)
    return n_eff * (np.log(max(rss0, 1e-300)) - np.log(max(rss1, 1e-300))) - k * np.log(n_eff)


def _on_trace(trace, t_sim, y):
    """Simulated outputs `y` (M, d) on the servo grid `t_sim`, at the trace's samples, shape (N, d)."""
    n = len(trace.t)
    if len(t_sim) == n and abs((t_sim[-1] - t_sim[0]) - (trace.t[-1] - trace.t[0])) <= 1e-3 * trace.dt * n:
        return y[:n]
    t = np.clip(trace.t, t_sim[0], t_sim[-1])
    return np.column_stack([np.interp(t, t_sim, y[:, i]) for i in range(y.shape[1])])
