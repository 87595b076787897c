"""A machine follows a path: servo loops, effects, geometric errors, tracking and contour error.

The data flow of DESIGN.md, as one pure function::

    reference ─▶ axis commands (ideal inverse kinematics) ─▶ strategies (target: geometric
        compensation; drive settings: feedforward; pre-filter: ZPETC)
        ─▶ command-stage effects ─▶ servo kernel (servo-stage and in-loop effects; a
        cross-coupled controller in the loop)
        ─▶ axis positions ─▶ multibody chain (geometric effects) ─▶ tool tip in workpiece
        coordinates ─▶ tracking error, contour error

The reference is a sampled path (:class:`Trajectory`) or a measured trace's
commanded positions (:class:`~contoursim.traces.Trace`,
:func:`measured_reference`). :func:`simulate` runs one model;
:func:`simulate_batch` runs many variants of one structure in one kernel call.
"""

import os
import warnings
from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np

from . import _memory, _validate, estimators, kernel
from ._blocks import blocks
from .compensation import Composition, Strategy, strategy_sequence
from ._version import __version__
from .contour import exact_contour_error
from .exceptions import ContoursimWarning, UnstableLoopError
from .traces import MAX_FORCE, Trace, write_trace
from .machine import CARTESIAN, Machine
from .multibody import MAX_TRAVEL, check_drift
from .model import as_model
from .trajectory import Trajectory

__all__ = ["SimResult", "SUMMARY_KEYS", "default_settle", "measured_force", "measured_reference", "simulate",
           "simulate_batch"]



@dataclass(frozen=True, eq=False)
class SimResult:
    """Everything a simulation produced, time first.

    Parameters
    ----------
    trajectory : Trajectory
        The tool-tip reference.
    machine : Machine
        The nominal machine (``model.machine``).
    axis_command : ndarray, shape (N, n_axes)
        Where the strategies want the axes: the interpolator's commands
        after the target stages (geometric compensation), before a
        feedforward pre-filter (ZPETC) and command-stage effects (a command
        delay) [mm].
    servo_response : contoursim.kernel.ServoResponse
        Servo axes' positions, velocities, currents.
    tool_position : ndarray, shape (N, d)
        Actual tool tip in workpiece coordinates [mm]; read-only (:func:`simulate`
        shares it with the contour error as its ``actual`` points).
    static_tool_position : ndarray, shape (N, d)
        Where the tool tip would be if every axis followed its command
        exactly: the reference plus the volumetric (geometric) error of the
        machine and the model's geometric effects, or what is left of it
        after compensation [mm].
    contour : contoursim.contour.ContourError or None
        Contour error of `tool_position`: exact, w.r.t. the reference path;
        for a measured reference (no path) the three-point estimate
        (:func:`contoursim.estimators.three_point`); ``None`` for a
        single-axis reference or when not asked for.
    strategies : tuple
        The compensation strategies that were applied.
    model : contoursim.model.Model
        The model simulated (the machine and its effects).
    force : dict of str -> ndarray, shape (N,)
        The known external force applied per servo axis [N] (the `force`
        of :func:`simulate`, or the trace's own), held over the dwell and
        the hold; empty without one.
    """

    trajectory: object
    machine: Machine
    axis_command: np.ndarray
    servo_response: object
    tool_position: np.ndarray
    static_tool_position: np.ndarray
    contour: object
    strategies: tuple = field(default=())
    model: object = None
    force: dict = field(default_factory=dict)

    def __post_init__(self):
        # read-only as the servo response and the contour error are: a write would change what summary() says
        for array in (self.axis_command, self.tool_position, self.static_tool_position, *self.force.values()):
            array.flags.writeable = False

    @property
    def tracking_error(self):
        """Actual minus reference tool position at the same instant [mm], shape (N, d)."""
        return self.tool_position - self.trajectory.position

    @property
    def saturation(self):
        """Fraction of the samples [0..1] in which each servo axis's current command was clipped at its limit.

        Returns
        -------
        dict
            Servo axis name -> fraction; 0 for an axis without a current limit.
        """
        fractions = self.servo_response.saturated.mean(axis=0)
        return {axis: float(f) for axis, f in zip(self.machine.axes, fractions)}

    @property
    def volumetric_error(self):
        """Geometric part of the tool-tip error: static tool position minus reference [mm], shape (N, d)."""
        return self.static_tool_position - self.trajectory.position

    def summary(self, measuring_only=True):
        """Max and RMS of tracking and contour error [µm].

        Parameters
        ----------
        measuring_only : bool
            Restrict to the test proper (``trajectory.measuring``), e.g. the
            full circle of an ISO 230-4 test without its run-in and run-out.

        Returns
        -------
        dict
            ``tracking_max_um``, ``tracking_rms_um``, ``contour_max_um``,
            ``contour_rms_um`` (without a contour error: not there),
            ``volumetric_max_um``, ``volumetric_rms_um``.
        """
        measuring_only = _validate.flag("measuring_only", measuring_only)
        return _error_figures(self.trajectory, self.tool_position, self.contour, self.static_tool_position, measuring_only)

    def to_trace(self, metadata=None):
        """The result in the measured-trace format: reference vs actual tool position, and the known forces applied."""
        axes = CARTESIAN[: self.trajectory.dim]
        force = {axis: values for axis, values in self.force.items() if axis in axes}
        return Trace(self.trajectory.t, self.trajectory.position, self.tool_position, axes, _metadata(metadata), force=force)

    def save_csv(self, file, metadata=None, overwrite=False, every=1):
        """Write the trace CSV (DESIGN.md contract) with the contour error (if any) and the test proper.

        Besides ``t`` [s] and the positions ``<axis>_ref``, ``<axis>`` [mm],
        the known forces applied ``<axis>_force`` [N] (:attr:`force`, on the
        Cartesian axes), the columns ``contour`` (distance to the path) and ``contour_normal``
        (its signed in-plane component, positive to the left of travel) [mm],
        (without a contour error, as for a single-axis measured reference:
        not there), ``measuring``: 1 on the test proper (``trajectory.measuring``),
        the rows the summary table's max and RMS are taken over, and ``rapid``:
        1 on a rapid (``trajectory.rapid``, a G0 move). Positions and
        contour error are written to the nm, ``t`` to the ns
        (:func:`contoursim.traces.write_trace`). The metadata lines give the
        contoursim version, machine, servo period, feed, sampling and units,
        then `metadata`.

        Parameters
        ----------
        file : str, Path or text file object
            Destination, written atomically; see :func:`contoursim.traces.write_trace`.
        metadata : dict, optional
            Further ``# key: value`` lines (e.g. the path file).
        overwrite : bool
            Replace an existing file.
        every : int
            Write every `every`-th sample (1: all, at the servo period).
        """
        metadata = _metadata(metadata)
        columns = ", ".join(f"{a}_ref, {a}" for a in CARTESIAN[: self.trajectory.dim])
        contour = "" if self.contour is None else ", contour, contour_normal"
        force = "".join(f"; {axis}_force [N]" for axis in self.force if axis in CARTESIAN[: self.trajectory.dim])
        standard = {
            "contoursim": __version__,
            "machine": self.machine.name,
            "servo_period_s": f"{self.machine.servo_period:g}",
            "every_nth_sample": every,
            "feed_mm_min": f"{60 * self.trajectory.feed:.6g}",
            "units": f"t [s]; {columns}{contour} [mm]{force}; measuring [1 = test proper, 0 = not]; rapid [1 = G0, 0 = not]",
        }
        extra = {} if self.contour is None else {"contour": self.contour.magnitude, "contour_normal": self.contour.normal}
        extra["measuring"] = self.trajectory.measuring
        extra["rapid"] = self.trajectory.rapid
        write_trace(file, self.to_trace({**standard, **metadata}), extra=extra, overwrite=overwrite, every=every)


def _metadata(metadata):
    """`metadata` (``None`` or a mapping) as a dict, refused when it is not a mapping (a list of lines)."""
    if metadata is not None and not isinstance(metadata, Mapping):
        raise TypeError(f"metadata must map keys to values ({{'path': 'circle.toml'}}), got {type(metadata).__name__}")
    return dict(metadata or {})


def _error_figures(trajectory, tool, contour, static=None, measuring_only=True):
    """Max and RMS [µm] of the tracking error, the contour error (if any) and the volumetric error (given `static`)."""
    keep = trajectory.measuring if measuring_only else np.ones(len(trajectory), bool)
    reference = trajectory.position
    errors = dict(  # made one at a time, each an (n,) array: a finished run holds everything else already
        tracking=lambda: _distances(tool, reference, keep),
        contour=None if contour is None else lambda: contour.magnitude[keep],
        volumetric=None if static is None else lambda: _distances(static, reference, keep),
    )
    summary = {}
    for name, error in errors.items():
        if error is None:
            continue
        e = error()
        summary[f"{name}_max_um"] = 1e3 * float(e.max())
        summary[f"{name}_rms_um"] = 1e3 * float(np.sqrt(np.mean(np.square(e, out=e))))
        del e  # before the next one is made
    return summary


def _contour_error(trajectory, tool):
    """The contour error of `tool` (N, d): exact on a path, the three-point estimate on a measured reference, or None."""
    if trajectory.path is not None:
        return exact_contour_error(trajectory, tool)
    if trajectory.dim > 1:
        return estimators.three_point(trajectory.position, tool)
    return None


def _distances(points, reference, keep):
    """``|points - reference|`` of the rows `keep` [mm], shape (keep.sum(),): made in blocks, no (N, d) temporaries."""
    out = np.empty(np.count_nonzero(keep))
    done = 0
    for part in blocks(len(keep)):
        diff = points[part] - reference[part]
        distances = np.sqrt(np.einsum("ij,ij->i", diff, diff))[keep[part]]  # all rows, then the kept: 3x faster
        out[done : done + distances.size] = distances
        done += distances.size
    return out


def measured_reference(trace, servo_period):
    """A measured trace's commanded positions as a reference at the servo period.

    The trace's samples are taken as they are when it was logged at the
    servo period (within the 0.1 % jitter a logger's time stamps may carry;
    the times become ``t[0] + k·servo_period``); otherwise a cubic spline
    (not-a-knot) through them is sampled every servo period from ``t[0]``
    to the last sample. Velocity and acceleration are the spline's first
    and second derivatives in both cases. The reference need not start or
    end at rest; it has no continuous path (``path = None``).

    Parameters
    ----------
    trace : contoursim.traces.Trace
        The measured trace (its ``reference`` columns are used).
    servo_period : float
        The servo period [s].

    Returns
    -------
    Trajectory
        ``dim`` = the trace's number of axes.

    Raises
    ------
    ValueError
        A run of the reference's samples would not fit in the memory
        available (:func:`contoursim._memory.check`), checked before it is made.

    Examples
    --------
    >>> from contoursim.traces import Trace
    >>> t = np.arange(5) * 1e-3
    >>> trace = Trace(t, (3.0 * t)[:, None], (3.0 * t)[:, None], ("x",))
    >>> ref = measured_reference(trace, 5e-4)          # logged at 1 ms, servo at 0.5 ms
    >>> ref.position[:3, 0].round(6).tolist(), ref.velocity[:3, 0].round(6).tolist()
    ([0.0, 0.0015, 0.003], [3.0, 3.0, 3.0])
    """
    from scipy.interpolate import CubicSpline  # ~0.25 s to import: only measured traces need it

    if not isinstance(trace, Trace):
        raise TypeError(f"trace must be a Trace, got {type(trace).__name__}")
    servo_period = _validate.positive("servo_period", servo_period)
    logged = _logged(trace, servo_period)
    duration = trace.t[-1] - trace.t[0]
    n = _servo_samples(trace, servo_period)
    _memory.check(n, f"the trace lasts {duration:.6g} s: every servo period of {servo_period:.6g} s",
                  "check the unit of the trace's time column (e.g. a line '# units: t [ms]') and the servo period")
    if logged:
        t = trace.t[0] + servo_period * np.arange(trace.t.size)
        spline = CubicSpline(t, trace.reference)
        position = trace.reference
    else:
        t = trace.t[0] + servo_period * np.arange(n)
        spline = CubicSpline(trace.t, trace.reference)
        position = spline(t)
    s = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(position, axis=0), axis=1))])
    return Trajectory(t, position, spline(t, 1), spline(t, 2), s)


def _logged(trace, servo_period):
    """Whether `trace` was logged at the servo period (its samples are the servo steps, within 0.1 % jitter)."""
    return abs(trace.dt - servo_period) <= 1e-3 * servo_period


def _servo_samples(trace, servo_period):
    """The samples of `trace`'s measured reference: its own when logged at the servo period, else every period up to
    the first at or after its last sample.

    A trace's last sample never lies past the simulation: there it would be given the last period's position, a
    period's motion off. That happens to a trace whose samples fall between servo periods, and to one whose clock
    reads large (t ~ 1e7 s holds 2 ns, and the duration of periods it spans can come out a hair short of a whole
    number): within a millionth of a period a whole number of periods is that number.
    """
    if _logged(trace, servo_period):
        return trace.t.size
    return int(np.ceil((trace.t[-1] - trace.t[0]) / servo_period - 1e-6)) + 1


def measured_force(trace, servo_period):
    """A measured trace's known external forces at the servo period, on the samples of :func:`measured_reference`.

    A force column is a sampled input: each of its samples holds from its
    time to the next (zero-order hold), the last to the end. A trace logged
    at the servo period gives its own samples.

    Parameters
    ----------
    trace : contoursim.traces.Trace
        The measured trace (its ``force`` columns are used).
    servo_period : float
        The servo period [s].

    Returns
    -------
    dict of str -> ndarray, shape (M,)
        The force on each axis that has one [N], M the samples of
        ``measured_reference(trace, servo_period)``; empty without a force column.

    Examples
    --------
    >>> from contoursim.traces import Trace
    >>> t = np.arange(4) * 1e-3
    >>> trace = Trace(t, t[:, None], t[:, None], ("x",), force={"x": [0.0, 5.0, 5.0, 0.0]})
    >>> measured_force(trace, 5e-4)["x"].tolist()           # logged at 1 ms, servo at 0.5 ms
    [0.0, 0.0, 5.0, 5.0, 5.0, 5.0, 0.0]
    """
    if not isinstance(trace, Trace):
        raise TypeError(f"trace must be a Trace, got {type(trace).__name__}")
    servo_period = _validate.positive("servo_period", servo_period)
    if _logged(trace, servo_period) or not trace.force:
        return dict(trace.force)
    t = trace.t[0] + servo_period * np.arange(_servo_samples(trace, servo_period))
    held = np.searchsorted(trace.t, t + 1e-6 * trace.dt, side="right") - 1  # the last sample at or before each t
    return {axis: values[held] for axis, values in trace.force.items()}


def _reference(machine, reference, settle, preview=0, force=None):
    """The reference as a Trajectory at the servo period, after a dwell of `preview` samples and held `settle` seconds.

    Also returns the known external forces on the servo axes at its samples, shape (N, n_servo) [N], or ``None``
    (`force`: by axis name, on the reference's samples; a trace's own by default), held over the dwell and the hold,
    and the names of the axes that have one.
    """
    if settle is not None:  # the caller's: named, and held to the memory a run of it takes
        settle = _validate.nonnegative("settle", settle)
    if settle:
        _memory.check(settle / machine.servo_period, f"settle = {settle:.6g} s: at the servo period of "
                      f"{machine.servo_period:.6g} s", "settle for less (a few time constants of the slowest loop)")
    if isinstance(reference, Trace):
        force = measured_force(reference, machine.servo_period) if force is None else force
        reference = measured_reference(reference, machine.servo_period)
        settle = 0.0 if settle is None else settle
    elif not isinstance(reference, Trajectory):
        raise TypeError(f"the reference must be a Trajectory or a Trace, got {type(reference).__name__}")
    elif machine.max_feed is not None:
        speed = _speeds(reference.velocity)
        if speed.max() > machine.max_feed * (1 + 1e-9):
            k = int(np.argmax(speed))
            raise ValueError(
                f"the trajectory reaches {60 * speed[k]:.6g} mm/min ({speed[k]:.6g} mm/s) at t = {reference.t[k]:.6g} s, "
                f"above the machine's max feed {60 * machine.max_feed:.6g} mm/min: plan the path with a lower feed "
                "(plan(..., max_feed=machine.max_feed) checks it)"
            )
    # to the resolution of its time stamps too: a trace's clock since power-on (t ~ 1e6 s) steps in multiples of 1e-10 s
    resolution = 4 * float(np.spacing(max(abs(reference.t[0]), abs(reference.t[-1]))))
    if abs(reference.dt - machine.servo_period) > 1e-9 * machine.servo_period + resolution:
        raise ValueError(
            f"the trajectory is sampled every {reference.dt:g} s but the servo period is "
            f"{machine.servo_period:g} s: sample the path at the servo period"
        )
    trajectory = reference.preceded(preview).held(default_settle(machine) if settle is None else settle)
    pushing = _held_force(machine, force, len(reference), preview, len(trajectory) - preview - len(reference))
    return trajectory, pushing, tuple(force or ())


def _held_force(machine, force, n, before, after):
    """The forces `force` (axis -> (n,) [N]) as an array (before + n + after, n_servo), edges held; None for none."""
    if force is not None and not isinstance(force, Mapping):
        raise TypeError(f"force must map servo axis names to arrays ({{'x': ...}}), got {type(force).__name__}")
    if not force:
        return None
    unknown = [axis for axis in force if axis not in machine.axes]
    if unknown:
        raise ValueError(f"force names axis {unknown[0]!r}, which is not a servo axis of the machine "
                         f"({', '.join(machine.axes)})")
    columns = np.zeros((n, len(machine.axes)))
    for i, axis in enumerate(machine.axes):
        if axis in force:
            columns[:, i] = _validate.finite_array(f"force[{axis!r}]", force[axis], shape=(n,), limit=MAX_FORCE)
    return np.pad(columns, ((before, after), (0, 0)), mode="edge")


def default_settle(machine):
    """The standstill :func:`simulate` appends to a path's reference by default [s].

    Parameters
    ----------
    machine : Machine

    Returns
    -------
    float
        Five time constants of the machine's slowest position loop, ``5 / min(kp)`` [s].

    Raises
    ------
    ValueError
        A run of that many servo periods would not fit in the memory available (:meth:`Machine.check_settle`).
    """
    if not isinstance(machine, Machine):
        raise TypeError(f"machine must be a Machine (load_machine loads one), got {type(machine).__name__}")
    machine.check_settle()
    return machine.settle


def _target(model, trajectory, composition, preview):
    """Axis commands of the interpolator after the strategies' target stages, shape (N, n_axes) each (the reference
    from sample `preview` on)."""
    return composition.target(*model.machine.axis_commands(trajectory), _elapsed(trajectory, preview))


def _sent(model, composition, servos, target):
    """The commands the servo axes get: the strategies' pre-filter, then the command-stage effects."""
    if not composition.prefilters:
        return model.commands(*target)
    q, v, a = (x.copy() for x in target)
    columns, dt = model.machine.servo_columns, model.machine.servo_period
    q[:, columns], v[:, columns], a[:, columns] = composition.prefilter(q[:, columns], v[:, columns], a[:, columns],
                                                                        servos, dt)  # fmt: skip
    return model.commands(q, v, a)


def _servo_run(model, composition, trajectory, force, preview):
    """Target commands (N, n_axes), the servo kernel's response to what is sent, and the servos with the drive settings.

    `force`: the known external forces on the servo axes, shape (N, n_servo) [N], or None; the reference from sample
    `preview` on. Commands that do not start at rest are stepped after a run-in (:func:`_lead`), left out of the
    response.

    The velocity and acceleration commands and what is sent are freed on return.
    """
    q, v, a = _target(model, trajectory, composition, preview)
    dt = model.machine.servo_period
    servos = composition.drive(model.servos())
    lead = _lead(model.machine, *(_servo_part(model, x) for x in (v, a)))
    path = _run_in(*(_servo_part(model, x) for x in (q, v, a)), lead, dt)[0]
    coupling = composition.coupling(path, servos, dt)
    sent = _run_in(*(_servo_part(model, x) for x in _sent(model, composition, servos, (q, v, a))), lead, dt)
    force = None if force is None else np.pad(force, ((lead, 0), (0, 0)), mode="edge")
    response = kernel.run(servos, dt, *sent, coupling=coupling, effects=model.loop_effects(), force=force)
    if lead:
        estimate = None if response.contour_estimate is None else response.contour_estimate[lead:]
        response = kernel.ServoResponse(dt, response.position[lead:], response.encoder[lead:], response.velocity[lead:],
                                        response.current[lead:], response.saturated[lead:], estimate)  # fmt: skip
    return q, response, servos


def _lead(machine, v, a):
    """Servo periods of run-in the kernel steps before servo commands that do not start at rest (0 when they do).

    The kernel starts at rest on its first command; a measured trace may
    start with the axes moving. Taken as the machine did it before: each
    axis moved at its first acceleration (:func:`_run_in`), back to where
    it stood still if that is within :func:`default_settle`, else over
    that long (the loops settle on the run-in).

    Parameters
    ----------
    machine : Machine
    v, a : ndarray, shape (N, n_servo)
        Velocity [mm/s] and acceleration [mm/s^2] commands of the servo axes.
    """
    speed = _speeds(v)
    if not speed[0] > 1e-3 * speed.max():  # at rest, or within the measured reference's wiggle of it
        return 0
    back = min(float(_to_rest(v[0], a[0]).max()), default_settle(machine))  # [s]
    return int(np.ceil(back / machine.servo_period)) + 1


def _speeds(v):
    """|v| of each row of `v` (N, d): numpy's norm along rows to rounding (to the bit for d = 2), in a fifth of its
    time, which a batch of variants' checks had spent on every call."""
    return np.sqrt(np.einsum("ij,ij->i", v, v))


def _to_rest(v0, a0):
    """How long ago [s] axes at velocity `v0` [mm/s] accelerating at `a0` [mm/s^2] stood still (inf: never)."""
    accelerating = v0 * a0 > 0
    return np.where(accelerating, np.abs(v0) / np.where(accelerating, np.abs(a0), 1.0), np.where(v0 == 0, 0.0, np.inf))


def _run_in(q, v, a, lead, dt):
    """Commands `q`, `v`, `a` (N, n) [mm, mm/s, mm/s^2] preceded by `lead` rows of run-in (:func:`_lead`), new arrays.

    Back from the first row at the first acceleration, each axis standing
    still before the time it was at rest (:func:`_to_rest`).
    """
    if not lead:
        return q, v, a
    back = dt * np.arange(lead, 0, -1)[:, None]  # [s] before the first row, (lead, 1)
    v0, a0 = v[0], a[0]
    rest = _to_rest(v0, a0)
    moving = back < rest
    u = np.minimum(back, rest)
    head = (q[0] - v0 * u + 0.5 * a0 * u**2, np.where(moving, v0 - a0 * u, 0.0), np.where(moving, a0, 0.0))
    return tuple(np.concatenate([h, x]) for h, x in zip(head, (q, v, a)))


def _elapsed(trajectory, preview):
    """Time since the reference's first sample, sample `preview` of `trajectory` (after a strategy's dwell) [s],
    shape (N,), 0 over the dwell: the clock of thermal drift and strategies."""
    return np.maximum(trajectory.t - trajectory.t[preview], 0.0)


def _lacks(chain, model, q, samples=256):
    """Whether the error model `chain` of a geometric compensation puts the tool elsewhere than `model`'s geometry
    (its machine with the geometric effects) does, at up to `samples` of the run's axis positions `q` (by a nm)."""
    q = q[:: max(1, len(q) // samples)]
    return bool(np.abs(chain.tool_pose(q)[0] - model.geometry.chain.tool_pose(q)[0]).max() > 1e-6)


def _ran_away(position):
    """Per column of `position` (N, n) [mm] the first row beyond ±:data:`MAX_TRAVEL` or not finite, -1 for none.

    An unstable loop whose state is still finite (the kernel's divergence check) can be kilometres away already: its
    positions mean nothing, and the geometric stage's polynomials overflow on them.
    """
    if np.abs(position).max(initial=0.0) <= MAX_TRAVEL:  # all within (NaN is not): one reduction, 20 times as fast
        return np.full(position.shape[1], -1)
    far = ~(np.abs(position) <= MAX_TRAVEL)
    return np.where(far.any(axis=0), far.argmax(axis=0), -1)


def _every_axis_servo(model):
    """Whether every axis of the machine is a servo axis, in order (the servo columns are all columns)."""
    columns = model.machine.servo_columns
    return np.array_equal(columns, np.arange(len(model.machine.axis_names)))


def _servo_part(model, x):
    """The servo axes' columns of axis signals `x` (N, n_axes): `x` itself when they are all its columns, else a
    C-contiguous copy (the kernel's layout; ``x[:, columns]`` is Fortran-ordered, copied again for it)."""
    return x if _every_axis_servo(model) else np.take(x, model.machine.servo_columns, axis=1)


def _actual(model, q, servo_position):
    """All axes' actual positions: the commands `q` with the servo axes at `servo_position` [mm, rad]."""
    if _every_axis_servo(model):
        return servo_position
    columns = model.machine.servo_columns
    actual = q.copy()
    actual[:, columns] = servo_position
    return actual


def simulate(model, reference, strategies=(), settle=None, contour=True, force=None):
    """Simulate a machine, or a model (machine + effects), following a reference.

    Parameters
    ----------
    model : Model or Machine
        What to simulate; a Machine is a model without effects.
    reference : Trajectory or Trace
        A tool-tip reference in workpiece coordinates [mm] sampled at the
        machine's servo period, its path speed [mm/s] not above the machine's
        ``max_feed`` [mm/s]; or a measured trace whose commanded positions
        are the reference (:func:`measured_reference`: resampled to the servo
        period where needed; what the machine did is not refused).
    strategies : sequence of contoursim.compensation.Strategy
        Compensation strategies, composed by
        :class:`contoursim.compensation.Composition` (e.g.
        :class:`~contoursim.compensation.Feedforward`,
        :class:`~contoursim.compensation.ZPETC`,
        :class:`~contoursim.compensation.CrossCoupled`,
        :class:`~contoursim.geocomp.GeometricCompensation`).
    settle : float, optional
        Standstill appended after the reference ends, so the axes settle [s];
        default five time constants of the slowest position loop
        (:func:`default_settle`), and none for a measured trace. The result's trajectory includes it.
    contour : bool
        Compute the contour error (exact on a path; the three-point estimate
        on a measured reference of 2 or 3 axes).
    force : dict of str -> array_like, shape (N,), optional
        A known external force on servo axes [N] by axis name, one value per
        sample of the reference, positive towards positive positions (the
        disturbance input of :func:`contoursim.kernel.run`), held over a
        dwell before and the settle after the reference. Default: a measured
        trace's own force columns (:func:`measured_force`); none otherwise.

    Returns
    -------
    SimResult

    Raises
    ------
    UnstableLoopError
        An axis loop (with its servo-stage effects) is unstable or badly
        damped at this servo period, or a cross-coupled controller
        destabilises it.
    TypeError
        `model` is not a Model or a Machine, `reference` not a Trajectory or
        a Trace, `force` not a mapping.
    ValueError
        The trajectory's sampling differs from the servo period, it is faster
        than the machine's max feed, the path does not fit the machine's
        axes, or a reference to be held does not end at rest; `settle` is
        negative or its run would not fit in memory; a force is beyond
        ±:data:`contoursim.traces.MAX_FORCE`.

    Warns
    -----
    ContoursimWarning
        An axis's current command hit its limit: the message names the axis
        and the fraction of samples (see :attr:`SimResult.saturation`), and
        says so when the axis never moved (a friction or force beyond what
        its drive pushes at the limit held it); a
        geometric compensation runs beside geometric effects, which its
        error model (the machine's bodies) does not hold.

    Notes
    -----
    Thermal drift, the machine's and the ``thermal_drift`` effects', runs
    from the reference's first sample (a measured trace's clock may start
    anywhere); strategies see that time too.

    A reference that does not start at rest (a measured trace that begins
    in motion) is entered as the machine entered it: the kernel first steps
    a run-in, back from the first sample at its first acceleration to
    rest, over :func:`default_settle` at most, which
    the result leaves out; without it the simulation would start at rest on a
    moving command, a transient the machine never had.

    A pre-filter reads some samples ahead (ZPETC,
    :meth:`contoursim.compensation.Strategy.preview`): the machine dwells
    that long at the start point while the filter fills, as a controller
    does; the result's trajectory begins with the dwell (not `measuring`,
    its times before the reference's first).
    """
    model = as_model(model)
    contour = _validate.flag("contour", contour)
    machine = model.machine
    composition = Composition(strategies)
    preview = composition.preview(composition.drive(model.servos()), machine.servo_period)
    trajectory, pushing, pushed = _reference(machine, reference, settle, preview, force)
    if machine.chain is not None:  # before the run: the machine file's drift over it within the chain's small errors
        check_drift(machine.chain, trajectory.t[-1] - trajectory.t[0])
    try:
        q, response, servos = _servo_run(model, composition, trajectory, pushing, preview)
    except UnstableLoopError as exc:  # the loop check passed the axes alone: name what acts on their loops
        loop = [e.label for e in model.effects if e.stage == "loop"]
        if not loop:
            raise
        raise UnstableLoopError(f"{exc} (the model's loop effects: {', '.join(loop)})", exc.margins) from None
    for said in _bows_beyond_their_span(model, dict(zip(servos, _servo_part(model, q).T))):
        warnings.warn(said, ContoursimWarning, stacklevel=2)
    away = _ran_away(response.position)
    if away.max() >= 0:
        a = int(np.argmax(away >= 0))
        axis = list(servos)[a]
        effects = [e.label for e in model.effects if axis in e.axis] or ["none"]
        raise UnstableLoopError(f"the simulation of axis {axis!r} ran away beyond ±{MAX_TRAVEL:g} mm by "
                                f"t = {trajectory.t[away[a]]:.6g} s: its loop with these effects (on {axis}: "
                                f"{', '.join(effects)}) or this coupling is unstable")
    elapsed = _elapsed(trajectory, preview)
    tool = model.geometry.tool_position(_actual(model, q, response.position), elapsed, trajectory.dim)
    far = np.abs(tool) > MAX_TRAVEL
    if far.any():  # not the loops (they stayed within it): the geometry, a bow extrapolated far beyond its span
        k, j = np.unravel_index(int(np.argmax(far)), far.shape)
        geometric = [e.label for e in model.stage("geometry")] or ["none"]
        raise ValueError(f"the tool position reaches {tool[k, j]:.6g} mm on {'xyz'[j]} at t = {trajectory.t[k]:.6g} s, "
                         f"beyond ±{MAX_TRAVEL:g} mm, the axes within it: the geometric effects "
                         f"({', '.join(geometric)}) or the machine's error model put it there")
    static = model.geometry.tool_position(q, elapsed, trajectory.dim)
    del elapsed  # before the contour error is computed
    tool.flags.writeable = False  # the contour error keeps it as its actual points, without a copy
    error = _contour_error(trajectory, tool) if contour else None
    known = {axis: pushing[:, list(machine.axes).index(axis)] for axis in pushed}
    result = SimResult(trajectory, machine, q, response, tool, static, error, composition.strategies, model, known)
    uncompensated = [e.label for e in model.stage("geometry")]
    if uncompensated and any(s.name == "geometric" and _lacks(s.chain, model, q) for s in composition.strategies):
        warnings.warn(f"geometric compensation corrects the errors of {machine.name}'s own error model (its [[body]] "
                      f"tables), as a controller corrects what it was calibrated with; the effects "
                      f"{', '.join(uncompensated)} are not in it and stay uncompensated", ContoursimWarning, stacklevel=2)
    clipped = {axis: f for axis, f in result.saturation.items() if f > 0}
    if clipped:  # an axis commanded to move that stood still to rounding: its drive at the limit cannot push it
        spans = zip(servos, np.ptp(_servo_part(model, q), axis=0), np.ptp(response.position, axis=0))
        held = {axis: commanded for axis, commanded, moved in spans if commanded > 0 and moved <= 1e-9 * commanded}
        axes = ", ".join(f"axis {axis} in {100 * f:.3g} % of the samples (limit ±{servos[axis].current_limit:g} A"
                         + (f"; it never moved, commanded over {held[axis]:.4g} mm: the most its drive pushes, "
                            f"{servos[axis].force_constant * servos[axis].current_limit:.4g} N, does not overcome what "
                            "holds it" if axis in held else "") + ")"
                         for axis, f in clipped.items())
        warnings.warn(f"the current command hit its limit on {axes}: the errors include the saturation",
                      ContoursimWarning, stacklevel=2)
    for axis, commanded, moved in zip(servos, np.ptp(_servo_part(model, q), axis=0), np.ptp(response.position, axis=0)):
        screw = servos[axis].screw_stiffness
        if screw is not None and commanded > 0 and moved < 1e-3 * commanded:  # its motor turned, the table stayed
            warnings.warn(f"axis {axis} was commanded over {commanded:.4g} mm and its table moved {moved:.4g} mm: its "
                          f"screw (screw_stiffness_N_per_um = {screw:.4g}, {1e6 * screw * commanded * 1e-3:.4g} N "
                          f"stretched over the whole command) does not carry the motor's motion to it",
                          ContoursimWarning, stacklevel=2)
    return result


def _bows_beyond_their_span(model, q):
    """What to say of each straightness of `model` whose axis runs outside the bow's span (the travel it is given
    over), where its parabola is extrapolated; `q`: the commanded positions by servo axis [mm]."""
    said = []
    for e in model.effects:
        if e.name != "straightness" or e.axis not in q:
            continue
        start, end, low, high = e["start_mm"], e["start_mm"] + e["span_mm"], q[e.axis].min(), q[e.axis].max()
        if low < start - 1e-9 * e["span_mm"] or high > end + 1e-9 * e["span_mm"]:
            u = 2.0 * (np.array([low, high]) - (start + end) / 2) / e["span_mm"]
            reach = float(np.abs(e["peak_um"] * (1.0 - u**2)).max())
            said.append(f"{e.label}: axis {e.axis} runs over {low:.6g} .. {high:.6g} mm, beyond the bow's span "
                        f"{start:.6g} .. {end:.6g} mm (start_mm, span_mm: the guideway's travel), where its parabola is "
                        f"extrapolated: up to {reach:.4g} µm for a peak_um of {e['peak_um']:.4g}")
    return said


#: Largest kernel output one chunk of a batch may hold [bytes].
BATCH_CHUNK_BYTES = 2**27

_BATCH_OUTPUTS = ("tool_position", "axis_position", "current", "summary")

#: Figures of a batch's ``"summary"`` output, one value per variant.
SUMMARY_KEYS = ("contour_max_um", "contour_rms_um", "tracking_max_um", "tracking_rms_um", "peak_current_A", "saturated",
                "diverged", "volumetric_max_um", "volumetric_rms_um")


def simulate_batch(models, reference, outputs=("tool_position",), strategies=(), settle=None, every=1, dtype=np.float64,
                   check=True, force=None):
    """Simulate B variants of one structure on one reference, in as few kernel calls as possible.

    The variants may differ in any effect value, and in which effects they
    have, in their servo settings and in their strategies' gains, but share
    the machine's axes, servo period, work offset and chain
    (``model.with_values``, ``model.with_effect`` and ``dataclasses.replace``
    of the machine's axes make such variants). A finite-difference Jacobian
    of P parameters is one batch of P + 1 models.
    Variants with the same command-stage effects share one
    :func:`contoursim.kernel.run_batch` call, made in chunks of rows so that
    the kernel's output stays below :data:`BATCH_CHUNK_BYTES`, and variants
    that differ only in geometric effects share one kernel row; each row then
    goes through its own geometric stage exactly as :func:`simulate` does it,
    so row b equals ``simulate(models[b], reference, ...)`` bit for bit
    (with ``every > 1`` the kernel keeps every `every`-th sample and the
    geometric stage runs on those only: equal to the single run's samples
    to rounding, 1e-12 mm).

    Unlike :func:`simulate`, only the nominal machines' loops are checked
    for stability (:func:`contoursim.servo.check`, analysed once per servo
    in a process), not the variants' (a ``gain_mismatch`` makes a new
    servo): a variant far from the nominal one is the caller's business.
    A cross-coupled controller's coupled-loop check runs for every variant.

    Parameters
    ----------
    models : sequence of Model or Machine
        The B variants.
    reference : Trajectory or Trace
        As for :func:`simulate`.
    outputs : tuple of str
        Any of ``"tool_position"`` (shape (B, M, d)) [mm],
        ``"axis_position"`` (the actual positions of all the machine's axes,
        shape (B, M, n_axes)) [mm, rad], ``"current"`` (the servo axes'
        current commands, shape (B, M, n_servo)) [A] and ``"summary"``: per variant the
        figures of :data:`SUMMARY_KEYS`, each an array (B,): contour and
        tracking error max and RMS over the test proper [µm] as in
        :meth:`SimResult.summary` (NaN without a contour error), the peak
        |current command| over the whole run [A], ``saturated`` the largest
        fraction of the samples in which an axis's current command was
        clipped [0..1], ``diverged`` (bool), the volumetric (geometric)
        error's max and RMS over the test proper [µm]; a diverged variant's
        figures are NaN. Only the summary: no trace is kept beyond a chunk of rows.
    strategies : sequence of Strategy, or sequence of B such sequences
        As for :func:`simulate`, shared by the variants; or one sequence per
        variant, differing only in their drive settings and cross-coupled
        controllers (gains): the target stage is the first variant's, and the
        pre-filter is designed from the first variant of each group.
    settle : float, optional
        As for :func:`simulate`.
    every : int
        Keep the samples ``k = 0, every, 2·every, …`` only (M = ceil(N / every)),
        to bound memory; the summary is taken over every sample all the same.
        It must be below N, the run's samples (the reference held `settle`).
        For a trace logged every k-th servo period, ``every = k`` gives the
        trace's own instants.
    dtype : {numpy.float64, numpy.float32}
        Of the returned arrays (``np.float32`` halves their memory; the
        simulation and the geometric stage run in float64).
    check : bool
        Check the nominal machines' loops and raise when a variant's
        cross-coupled controller fails its coupled-loop check (``False``:
        the machines are themselves variants of a checked one, e.g. a fit's
        nominal parameters moved by a few %, or a sweep; a diverged row says
        what failed, and a variant whose coupled-loop check fails is not run
        and counts as diverged).
    force : dict of str -> array_like, shape (N,), optional
        A known external force on servo axes [N], shared by the variants, as
        for :func:`simulate` (a measured trace's own by default).

    Returns
    -------
    dict
        ``"t"`` (M,) [s], each output asked for, and ``"diverged_step"``
        (B, n_servo): per variant and servo axis the first step whose state
        was not finite, or whose position was beyond ±1e6 mm (an unstable
        variant; 0 on every axis for a variant refused by the coupled-loop
        check), -1 for none; a diverged variant's ``tool_position`` is NaN
        throughout.

    Raises
    ------
    ValueError
        The variants do not share one structure; an unknown output; `every`
        keeping the first sample alone; a `dtype` other than float64 or
        float32; per-variant strategies that are not B sequences; noise on an
        encoder (``noise`` with ``at = "encoder"``); the outputs kept would
        not fit in the memory available.
    UnstableLoopError
        A nominal machine's loop is unstable or badly damped, or (with
        `check`) a variant's cross-coupled controller fails its check.
    """
    if not isinstance(models, (list, tuple)):  # one model: the batch is a list of them
        raise TypeError(f"models must be a list of models or machines (one per variant), got a "
                        f"{type(models).__name__}: give [model] for one")
    models = [as_model(m) for m in models]
    check = _validate.flag("check", check)
    if not models:
        raise ValueError("simulate_batch needs at least one model")
    compositions = _compositions(strategies, len(models))
    loops = [m.loop_effects() for m in models]
    noisy = [f"models[{i}] axis {axis}" for i, loop in enumerate(loops) for axis, e in loop.items()
             if e.noise_at == "encoder" and e.noise_mm > 0.0]
    if noisy:
        raise ValueError(f"simulate_batch runs no noise on the encoder ({noisy[0]}): use simulate")
    if isinstance(outputs, str):  # its letters would be the names
        raise TypeError(f"outputs must be a sequence of output names, e.g. ('summary',), got the string {outputs!r}")
    unknown = [o for o in outputs if o not in _BATCH_OUTPUTS]
    if unknown or not outputs:
        raise ValueError(f"outputs must be some of {', '.join(_BATCH_OUTPUTS)}, got {tuple(outputs)!r}")
    every = _validate.positive_int("every", every)
    dtype = _validate.float_dtype("dtype", dtype)
    first = models[0].machine
    for i, m in enumerate(models):
        machine = m.machine
        if (machine.chain is not first.chain or machine.axis_names != first.axis_names
                or machine.servo_period != first.servo_period or dict(machine.work_offset) != dict(first.work_offset)):
            raise ValueError(f"models[{i}] has another structure than models[0] (axes, servo period, work offset or chain): "
                             "a batch runs variants of one machine")
    dt, servo = first.servo_period, first.servo_columns
    preview = compositions[0].preview(compositions[0].drive(models[0].servos()), dt)  # the first variant's, as the pre-filter
    for machine in {id(m.machine): m.machine for m in models}.values() if check else ():
        for axis, nominal in machine.axes.items():
            nominal.check(dt, axis)  # analysed once per servo in a process
    trajectory, pushing, _ = _reference(first, reference, settle, preview, force)
    if every > 1 and every >= len(trajectory):  # t and every trace asked for would be the first sample alone
        raise ValueError(f"every = {every} keeps only the first of the run's {len(trajectory)} samples: give every "
                         f"below {len(trajectory)} (1 keeps them all)")
    if first.chain is not None:  # one chain for all (simulate's check)
        check_drift(first.chain, trajectory.t[-1] - trajectory.t[0])
    q, v, a = _target(models[0], trajectory, compositions[0], preview)
    summary = "summary" in outputs
    traces = [name for name in outputs if name != "summary"]
    keep = slice(None, None, every)
    n_keep = len(range(*keep.indices(len(trajectory))))
    width = {"tool_position": trajectory.dim, "axis_position": q.shape[1], "current": servo.size}
    _memory.check(len(models) * n_keep, f"{len(models)} models, {n_keep} samples of each kept:",
                  "give fewer models, every > 1, or outputs=('summary',)",
                  per_sample=dtype.itemsize * sum(width[name] for name in traces))  # numpy's MemoryError otherwise
    result = {"t": trajectory.t[keep].copy()}
    result.update({name: np.empty((len(models), n_keep, width[name]), dtype) for name in traces})
    result["diverged_step"] = np.empty((len(models), servo.size), np.int64)
    if summary:
        result["summary"] = {key: np.full(len(models), np.nan) for key in SUMMARY_KEYS}
        result["summary"]["diverged"] = np.zeros(len(models), bool)
    groups = {}
    for i, m in enumerate(models):
        groups.setdefault(tuple((e.axis, e["delay_s"]) for e in m.stage("command")), []).append(i)
    # commands that do not start at rest: the kernel steps a run-in first, left out of the outputs (see _servo_run)
    lead = _lead(first, *(_servo_part(models[0], x) for x in (v, a)))
    # the summary is over every sample; the kernel keeps every `every`-th from its first, so from the reference's first
    # only after a run-in of whole `every`s (else all, and the reference's every `every`-th taken here)
    kernel_every = 1 if summary or lead % every else every
    taken = slice(lead // kernel_every, None, 1 if summary else every // kernel_every)
    kernel_outputs = ("tool",) + (("current",) if summary or "current" in outputs else ()) + (("saturated",) if summary else ())
    n_kernel = len(range(0, lead + len(trajectory), kernel_every))
    chunk = max(os.cpu_count() or 1, BATCH_CHUNK_BYTES // (8 * len(kernel_outputs) * n_kernel * servo.size))
    elapsed = _elapsed(trajectory, preview)
    pushing = None if pushing is None else np.pad(pushing, ((lead, 0), (0, 0)), mode="edge")
    path = _run_in(*(_servo_part(models[0], x) for x in (q, v, a)), lead, dt)[0]
    couplings = {}
    for rows in groups.values():
        # the pre-filter designs from the first variant of the group (pass a `model` to the strategy to fix it)
        composition = compositions[rows[0]]
        sent = _sent(models[rows[0]], composition, composition.drive(models[rows[0]].servos()), (q, v, a))
        qd, vd, ad = _run_in(*(_servo_part(models[rows[0]], x) for x in sent), lead, dt)
        # variants that differ only in their geometry share one kernel run
        runs = {}
        for i in rows:
            servos = compositions[i].drive(models[i].servos())
            packed = np.array([kernel.pack(servo, dt, loops[i][axis]) for axis, servo in servos.items()])
            coupling = _coupling(couplings, compositions[i], path, servos, dt, i, check)
            key = packed.tobytes() + (coupling.params.tobytes() if isinstance(coupling, kernel.Coupling) else b"")
            runs.setdefault(key, (packed, coupling, []))[2].append(i)
        distinct = list(runs.values())
        refused = [part for part in distinct if part[1] is _REFUSED]
        for _, _, same in refused:
            result["diverged_step"][same] = 0
            for name in traces:
                result[name][same] = np.nan
            if summary:
                result["summary"]["diverged"][same] = True
        distinct = [part for part in distinct if part[1] is not _REFUSED]
        coupled = any(c is not None for _, c, _ in distinct)
        for start in range(0, len(distinct), chunk):
            part = distinct[start : start + chunk]
            packed = np.array([p for p, _, _ in part])
            run = kernel.run_batch(packed, dt, qd, vd, ad, outputs=kernel_outputs, every=kernel_every,
                                   couplings=[c for _, c, _ in part] if coupled else None, force=pushing)
            for name in kernel_outputs:
                run[name] = run[name][:, taken]
            for b, (_, _, same) in enumerate(part):
                diverged = np.where(run["diverged_step"][b] >= 0, np.maximum(run["diverged_step"][b] - lead, 0), -1)
                away = _ran_away(run["tool"][b])
                away = np.where(away >= 0, away * (1 if summary else every), -1)  # the step of the sample kept
                diverged = np.where((diverged < 0) | ((away >= 0) & (away < diverged)), away, diverged)
                for i in same:
                    result["diverged_step"][i] = diverged
                    if (diverged >= 0).any():  # an unstable variant: no positions, no figures
                        for name in traces:
                            result[name][i] = np.nan
                        if summary:
                            result["summary"]["diverged"][i] = True
                        continue
                    actual = _actual(models[i], q, run["tool"][b]) if summary else _actual(models[i], q[keep], run["tool"][b])
                    tool = models[i].geometry.tool_position(actual, elapsed if summary else elapsed[keep], trajectory.dim)
                    if "axis_position" in result:
                        result["axis_position"][i] = actual[::every] if summary else actual
                    if "tool_position" in result:
                        result["tool_position"][i] = tool[::every] if summary else tool
                    if "current" in result:
                        result["current"][i] = run["current"][b][::every] if summary else run["current"][b]
                    if summary:
                        static = models[i].geometry.tool_position(q, elapsed, trajectory.dim)
                        figures = _error_figures(trajectory, tool, _contour_error(trajectory, tool), static)
                        figures["peak_current_A"] = float(np.abs(run["current"][b]).max())
                        figures["saturated"] = float(run["saturated"][b].sum(axis=0).max()) / len(trajectory)
                        for key, value in figures.items():
                            if key in result["summary"]:
                                result["summary"][key][i] = value
            del run
    return result


_REFUSED = object()  # a variant whose cross-coupled controller fails the coupled-loop check (check=False)


def _compositions(strategies, n):
    """One :class:`Composition` per variant: `strategies` shared, or one sequence per variant."""
    strategies = strategy_sequence(strategies)
    if not strategies or isinstance(strategies[0], Strategy):
        return [Composition(strategies)] * n
    if len(strategies) != n:
        raise ValueError(f"per-variant strategies must be one sequence per model: {n} models, {len(strategies)} sequences")
    return [Composition(s) for s in strategies]


def _coupling(cache, composition, path, servos, dt, i, check):
    """The variant's :class:`~contoursim.kernel.Coupling` (or None, or _REFUSED), made once per controller and servos."""
    key = (tuple(repr(s) for s in composition.strategies if s.kind == "coupling"), tuple(servos.items()))  # by value
    if key not in cache:
        try:
            cache[key] = composition.coupling(path, servos, dt)
        except UnstableLoopError as exc:
            if check:
                raise UnstableLoopError(f"models[{i}]: {exc}", margins=exc.margins) from None
            cache[key] = _REFUSED
    return cache[key]
