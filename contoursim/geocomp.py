"""Geometric compensation: pre-correct the axis commands from the error model.

Given the axis commands the interpolator would send to an error-free
machine, find the commands that bring the *actual* machine's tool tip (and
tool axis) to where the ideal machine would have put it. The target is the
ideal chain's pose; the commands come from the actual chain's inverse
kinematics by Gauss-Newton iteration (:meth:`MachineChain.inverse`).

Like every compensation strategy (:mod:`contoursim.compensation`) it is an
object passed to the simulation; it acts on the target of the axes, before
the loop, and has no state between calls.
"""

from dataclasses import dataclass

import numpy as np

from . import _validate
from .compensation import Strategy
from .multibody import MachineChain

__all__ = ["GeometricCompensation"]


@dataclass(frozen=True)
class GeometricCompensation(Strategy):
    """Pre-correct axis commands with a model of the machine's geometric errors.

    Parameters
    ----------
    chain : MachineChain
        The machine model (errors as identified or measured).
    tol : float
        Stop iterating when no axis command changes by more than this, or
        when the changes still to come are estimated below it [mm or rad]
        (see :meth:`MachineChain.inverse`).
    max_iter : int
        Iteration limit.

    Notes
    -----
    The tool tip is matched first; the tool axis only with the freedom left
    (a 3-axis machine cannot correct its angular errors, a 5-axis machine
    cannot near its singular pose).

    Examples
    --------
    >>> import numpy as np
    >>> from contoursim.machine import load_machine
    >>> chain = load_machine("vertical_mill_3axis").chain
    >>> q = np.array([[200.0, 100.0, -50.0]])            # ideal commands x, y, z [mm]
    >>> q_cmd = GeometricCompensation(chain).commands(q)
    >>> target = chain.tool_pose(q, ideal=True)[0]       # where an error-free machine puts the tool
    >>> print(f"{1e3 * np.abs(chain.tool_pose(q)[0] - target).max():.1f} µm")      # uncompensated
    8.1 µm
    >>> bool(np.abs(chain.tool_pose(q_cmd)[0] - target).max() < 1e-9)               # compensated
    True
    """

    chain: MachineChain
    tol: float = 1e-10
    max_iter: int = 10

    name = "geometric"
    kind = "target"

    def __post_init__(self):
        if not isinstance(self.chain, MachineChain):
            raise TypeError(f"chain must be a MachineChain, got {type(self.chain).__name__}")
        object.__setattr__(self, "tol", _validate.positive("tol", self.tol))
        object.__setattr__(self, "max_iter", _validate.positive_int("max_iter", self.max_iter))

    def commands(self, q, t=None):
        """Pre-corrected axis commands.

        Parameters
        ----------
        q : ndarray, shape (N, n_axes)
            Ideal axis commands, columns in the order of ``chain.axes``
            [mm for linear, rad for rotary axes].
        t : ndarray, shape (N,), optional
            Times [s], for the thermal drift.

        Returns
        -------
        ndarray, shape (N, n_axes)
            Commands that put the actual machine's tool where the ideal
            machine would put it for `q` [mm, rad].
        """
        position, axis = self.chain.tool_pose(q, t, ideal=True)
        return self.chain.inverse(
            position,
            axis,
            q0=q,
            t=t,
            free=self.chain.axes,
            tol=self.tol,
            max_iter=self.max_iter,
        )

    def target(self, q, v, a, t):
        """The pre-corrected commands, with the correction's derivatives added to `v` and `a`.

        Parameters
        ----------
        q, v, a : ndarray, shape (N, n_axes)
            Ideal axis positions [mm, rad], velocities and accelerations.
        t : ndarray, shape (N,)
            Times [s] (uniform).

        Returns
        -------
        q, v, a : ndarray, shape (N, n_axes)
            So that feedforward sees the corrected motion.
        """
        corrected = self.commands(q, t)
        dq = np.gradient(corrected - q, t, axis=0) if len(t) > 1 else np.zeros_like(q)
        ddq = np.gradient(dq, t, axis=0) if len(t) > 1 else np.zeros_like(q)
        return corrected, v + dq, a + ddq
