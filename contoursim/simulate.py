"""A machine follows a path: servo loops, geometric errors, tracking and contour error.

The data flow of DESIGN.md, as one pure function::

    trajectory ─▶ axis commands (ideal inverse kinematics) ─▶ strategies: target (geometric
        compensation), drive settings (feedforward), pre-filter (ZPETC) ─▶ servo kernel, with a
        cross-coupled controller in the loop ─▶ axis positions ─▶ multibody chain ─▶ tool tip in workpiece
        coordinates ─▶ tracking error, exact contour error
"""

import warnings
from dataclasses import dataclass, field

import numpy as np

from . import kernel
from .compensation import Composition
from ._version import __version__
from .contour import exact_contour_error
from .exceptions import ContoursimWarning
from .traces import Trace, write_trace
from .machine import CARTESIAN, Machine

__all__ = ["SimResult", "simulate"]


@dataclass(frozen=True)
class SimResult:
    """Everything a simulation produced, time first.

    Parameters
    ----------
    trajectory : Trajectory
        The tool-tip reference.
    machine : Machine
    axis_command : ndarray, shape (N, n_axes)
        Where the strategies want the axes: the axis commands after the
        target stages (geometric compensation), before a feedforward
        pre-filter (ZPETC) [mm].
    servo_response : contoursim.kernel.ServoResponse
        Servo axes' positions, velocities, currents.
    tool_position : ndarray, shape (N, d)
        Actual tool tip in workpiece coordinates [mm].
    static_tool_position : ndarray, shape (N, d)
        Where the tool tip would be if every axis followed its command
        exactly: the reference plus the machine's volumetric (geometric)
        error, or what is left of it after compensation [mm].
    contour : contoursim.contour.ContourError
        Exact contour error of `tool_position` w.r.t. the reference path.
    strategies : tuple
        The compensation strategies that were applied.
    """

    trajectory: object
    machine: Machine
    axis_command: np.ndarray
    servo_response: object
    tool_position: np.ndarray
    static_tool_position: np.ndarray
    contour: object
    strategies: tuple = field(default=())

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
            ``contour_rms_um``, ``volumetric_max_um``, ``volumetric_rms_um``.
        """
        keep = self.trajectory.measuring if measuring_only else slice(None)
        errors = dict(
            tracking=np.linalg.norm(self.tracking_error[keep], axis=1),
            contour=self.contour.magnitude[keep],
            volumetric=np.linalg.norm(self.volumetric_error[keep], axis=1),
        )
        summary = {}
        for name, e in errors.items():
            summary[f"{name}_max_um"] = 1e3 * float(e.max())
            summary[f"{name}_rms_um"] = 1e3 * float(np.sqrt(np.mean(e**2)))
        return summary

    def to_trace(self, metadata=None):
        """The result in the measured-trace format: reference vs actual tool position."""
        axes = CARTESIAN[: self.trajectory.dim]
        return Trace(self.trajectory.t, self.trajectory.position, self.tool_position, axes, dict(metadata or {}))

    def save_csv(self, file, metadata=None, overwrite=False, every=1):
        """Write the trace CSV (DESIGN.md contract) with the contour error and the test proper.

        Besides ``t`` [s] and the positions ``<axis>_ref``, ``<axis>`` [mm],
        the columns ``contour`` (distance to the path) and ``contour_normal``
        (its signed in-plane component, positive to the left of travel) [mm],
        and ``measuring``: 1 on the test proper (``trajectory.measuring``),
        the rows the summary table's max and RMS are taken over. Positions and
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
        columns = ", ".join(f"{a}_ref, {a}" for a in CARTESIAN[: self.trajectory.dim])
        standard = {
            "contoursim": __version__,
            "machine": self.machine.name,
            "servo_period_s": f"{self.machine.servo_period:g}",
            "every_nth_sample": every,
            "feed_mm_min": f"{60 * self.trajectory.feed:.6g}",
            "units": f"t [s]; {columns}, contour, contour_normal [mm]; measuring [1 = test proper, 0 = not]",
        }
        extra = {"contour": self.contour.magnitude, "contour_normal": self.contour.normal,
                 "measuring": self.trajectory.measuring}
        write_trace(file, self.to_trace({**standard, **(metadata or {})}), extra=extra, overwrite=overwrite, every=every)


def simulate(machine, trajectory, strategies=(), settle=None):
    """Simulate `machine` following `trajectory`.

    Parameters
    ----------
    machine : Machine
    trajectory : Trajectory
        Tool-tip reference in workpiece coordinates [mm], sampled at the
        machine's servo period; its path speed [mm/s] must not exceed the
        machine's ``max_feed`` [mm/s].
    strategies : sequence of contoursim.compensation.Strategy
        Compensation strategies, composed by
        :class:`contoursim.compensation.Composition` (e.g.
        :class:`~contoursim.compensation.Feedforward`,
        :class:`~contoursim.compensation.ZPETC`,
        :class:`~contoursim.compensation.CrossCoupled`,
        :class:`~contoursim.geocomp.GeometricCompensation`).
    settle : float, optional
        Standstill appended after the reference ends, so the axes settle [s];
        default five time constants of the slowest position loop, ``5 / min(kp)``.
        The result's trajectory includes it.

    Returns
    -------
    SimResult

    Raises
    ------
    UnstableLoopError
        An axis loop is unstable or badly damped at this servo period, or a
        cross-coupled controller destabilises it.
    ValueError
        The trajectory's sampling differs from the servo period, it is faster
        than the machine's max feed, or the path does not fit the machine's axes.

    Warns
    -----
    ContoursimWarning
        An axis's current command hit its limit: the message names the axis
        and the fraction of samples (see :attr:`SimResult.saturation`).
    """
    if abs(trajectory.dt - machine.servo_period) > 1e-9 * machine.servo_period:
        raise ValueError(
            f"the trajectory is sampled every {trajectory.dt:g} s but the servo period is "
            f"{machine.servo_period:g} s: sample the path at the servo period"
        )
    speed = trajectory.speed
    if machine.max_feed is not None and speed.max() > machine.max_feed * (1 + 1e-9):
        k = int(np.argmax(speed))
        raise ValueError(
            f"the trajectory reaches {60 * speed[k]:.6g} mm/min ({speed[k]:.6g} mm/s) at t = {trajectory.t[k]:.6g} s, "
            f"above the machine's max feed {60 * machine.max_feed:.6g} mm/min: plan the path with a lower feed "
            "(plan(..., max_feed=machine.max_feed) checks it)"
        )
    if settle is None:
        settle = 5.0 / min(servo.kp for servo in machine.axes.values())
    trajectory = trajectory.held(settle)
    composition = Composition(strategies)
    q, v, a = composition.target(*machine.axis_commands(trajectory), trajectory.t)
    servo, dt = machine.servo_columns, machine.servo_period
    servos = composition.drive(machine.axes)
    coupling = composition.coupling(q[:, servo], servos, dt)
    commands = composition.prefilter(q[:, servo], v[:, servo], a[:, servo], servos, dt)
    response = kernel.run(servos, dt, *commands, coupling=coupling)
    actual = q.copy()
    actual[:, servo] = response.position
    tool = machine.tool_position(actual, trajectory.t, trajectory.dim)
    static = machine.tool_position(q, trajectory.t, trajectory.dim)
    contour = exact_contour_error(trajectory, tool)
    result = SimResult(trajectory, machine, q, response, tool, static, contour, composition.strategies)
    clipped = {axis: f for axis, f in result.saturation.items() if f > 0}
    if clipped:
        axes = ", ".join(f"axis {axis} in {100 * f:.3g} % of the samples (limit ±{machine.axes[axis].current_limit:g} A)"
                         for axis, f in clipped.items())
        warnings.warn(f"the current command hit its limit on {axes}: the errors include the saturation",
                      ContoursimWarning, stacklevel=2)
    return result
