"""The sampled reference every loop, estimator and plot consumes."""

from dataclasses import dataclass, field

import numpy as np

from . import _memory, _validate
from ._blocks import blocks
from .paths import MAX_COORDINATE, Path

#: Samples of a trajectory checked to lie on its path at their arc length (evenly spread, the ends among them) [-] ...
CHECKED = 257
#: ... within this distance [mm] (the interpolator's samples lie on it to rounding).
ON_PATH = 1e-6

__all__ = ["Trajectory"]

_AT_REST = 1e-9  # an end velocity (acceleration) within this share of the largest is rest, to rounding



@dataclass(frozen=True, eq=False)
class Trajectory:
    """A reference path sampled at the servo period.

    Its arrays are read-only; an array the caller passes is copied
    (:func:`contoursim._validate.read_only`), so it stays the caller's, writeable.

    Parameters
    ----------
    t : ndarray, shape (N,)
        Sample times [s], uniform.
    position : ndarray, shape (N, d)
        Reference (interpolator) positions [mm], d = 2 or 3 (1 for a
        single-axis measured reference).
    velocity : ndarray, shape (N, d)
        Reference velocity [mm/s] (used by velocity feedforward).
    acceleration : ndarray, shape (N, d)
        Reference acceleration [mm/s^2] (used by acceleration feedforward).
    s : ndarray, shape (N,)
        Arc length along the path [mm].
    path : contoursim.paths.Path, optional
        The continuous geometry the samples were taken from; the exact contour
        error is the distance to it. ``None`` for a reference known only by
        its samples (a measured trace). The samples must be the path's
        points at their `s` (checked at up to :data:`CHECKED` samples, to
        :data:`ON_PATH`): the exact error searches the path from them.
    measuring : ndarray of bool, shape (N,), optional
        The test proper, the samples that are scored
        (:func:`contoursim.feed.sample`): those whose reference lies on the
        path's primitives with role ``"test"``, e.g. the data-collection
        circle of an ISO 230-4 test without its run-in, overrun and run-out
        arcs; on a path without them, on every primitive but the rapids (role
        ``"rapid"``: the G0 moves of a G-code program), i.e. on the cutting
        moves. All samples when omitted. The one definition the summary
        table, the trace CSV (column ``measuring``) and the polar plot use.
    """

    t: np.ndarray
    position: np.ndarray
    velocity: np.ndarray
    acceleration: np.ndarray
    s: np.ndarray
    path: object = None
    measuring: np.ndarray = field(default=None)

    def __post_init__(self):
        t, dt = _validate.time_base("t", self.t)
        n = t.size
        pos = _validate.finite_array("position", self.position, ndim=2, limit=MAX_COORDINATE)
        if pos.shape[0] != n or pos.shape[1] not in (1, 2, 3):
            raise ValueError(f"position must have shape (N, d), d = 1, 2 or 3, with N = {n}, got {pos.shape}")
        d = pos.shape[1]
        if self.path is not None and not isinstance(self.path, Path):
            raise TypeError(f"path must be a contoursim.paths.Path or None, got {type(self.path).__name__}")
        vel = _validate.finite_array("velocity", self.velocity, shape=(n, d))
        acc = _validate.finite_array("acceleration", self.acceleration, shape=(n, d))
        s = _validate.finite_array("s", self.s, shape=(n,))
        measuring = np.ones(n, bool) if self.measuring is None else _validate.mask("measuring", self.measuring, (n,))
        if not measuring.any():
            raise ValueError(f"measuring must mark at least one of the {n} samples, got none")
        if self.path is not None:
            _on_path(self.path, pos, s)
        for name, value in dict(t=t, position=pos, velocity=vel, acceleration=acc, s=s, measuring=measuring).items():
            object.__setattr__(self, name, _validate.read_only(value, getattr(self, name)))
        object.__setattr__(self, "dt", dt)

    def __len__(self):
        return self.t.size

    def held(self, duration):
        """This trajectory followed by a standstill at its last point.

        Parameters
        ----------
        duration : float
            How long to hold [s]; rounded up to whole samples.

        Returns
        -------
        Trajectory
            The extra samples have zero velocity and acceleration and are
            `measuring` as the last sample is (the tool still comes to rest on
            the end of a cut, not on a run-out). Raises ValueError unless the reference ends at rest
            (or `duration` rounds to no sample).
        """
        duration = _validate.nonnegative("duration", duration)
        n = int(np.ceil(duration / self.dt - 1e-9))
        if n == 0:
            return self
        _memory.check(len(self) + n, f"a hold of {duration:.6g} s: at dt = {self.dt:.6g} s", "check the duration")
        # at rest to rounding: a spline through measured positions ends at 1e-41 mm/s, not 0
        moving = [np.abs(x[-1]).max() > _AT_REST * np.abs(x).max() for x in (self.velocity, self.acceleration)]
        if any(moving):
            raise ValueError(f"only a reference that ends at rest can be held; this one ends at "
                             f"{np.abs(self.velocity[-1]).max():.3g} mm/s, {np.abs(self.acceleration[-1]).max():.3g} mm/s²")
        tail = np.zeros((n, self.dim))
        return Trajectory(
            np.concatenate([self.t, self.t[-1] + self.dt * np.arange(1, n + 1)]),
            np.concatenate([self.position, np.broadcast_to(self.position[-1], (n, self.dim))]),
            np.concatenate([self.velocity, tail]),
            np.concatenate([self.acceleration, tail]),
            np.concatenate([self.s, np.full(n, self.s[-1])]),
            self.path,
            np.concatenate([self.measuring, np.full(n, self.measuring[-1])]),
        )

    def preceded(self, samples):
        """This trajectory after a standstill of `samples` servo periods at its first point.

        Parameters
        ----------
        samples : int
            How many samples to put before the first one (their times run
            back from ``t[0]``).

        Returns
        -------
        Trajectory
            The extra samples have zero velocity and acceleration and are
            not `measuring`.
        """
        n = _validate.nonnegative("samples", samples)
        if n != int(n):
            raise ValueError(f"samples must be a whole number, got {samples!r}")
        n = int(n)
        if n == 0:
            return self
        _memory.check(len(self) + n, f"a standstill of {n} samples before the start, at dt = {self.dt:.6g} s:",
                      "check samples")
        head = np.zeros((n, self.dim))
        return Trajectory(
            np.concatenate([self.t[0] - self.dt * np.arange(n, 0, -1), self.t]),
            np.concatenate([np.broadcast_to(self.position[0], (n, self.dim)), self.position]),
            np.concatenate([head, self.velocity]),
            np.concatenate([head, self.acceleration]),
            np.concatenate([np.full(n, self.s[0]), self.s]),
            self.path,
            np.concatenate([np.zeros(n, bool), self.measuring]),
        )

    @property
    def dim(self):
        """Number of coordinates, 1, 2 or 3."""
        return self.position.shape[1]

    @property
    def primitive(self):
        """Index of the path's primitive each sample's reference lies on, shape (N,) int.

        At a junction the later one, but for a sample at rest there: the stop
        (or in-position dwell) at the end of the earlier one
        (:meth:`contoursim.paths.Path.segment_index`). Raises ValueError without a path.
        """
        if self.path is None:
            raise ValueError("a trajectory without a path (a measured reference) has no primitives")
        return self.path.segment_index(self.s, at_rest=self.speed == 0)

    @property
    def rapid(self):
        """Samples whose reference lies on a rapid (a primitive with role ``"rapid"``), shape (N,) bool; none without a path."""
        if self.path is None or "rapid" not in self.path.roles:
            return np.zeros(len(self), bool)
        return np.array(self.path.roles)[self.primitive] == "rapid"

    @property
    def speed(self):
        """Path speed |v| [mm/s], shape (N,)."""
        return np.linalg.norm(self.velocity, axis=1)

    @property
    def feed(self):
        """Highest path speed over the test proper (`measuring`) [mm/s]: the programmed feed where the plan reaches it."""
        return max(float(np.linalg.norm(self.velocity[part][self.measuring[part]], axis=1).max(initial=0.0))
                   for part in blocks(len(self)))  # |v| block by block: no (N, d) temporaries beside a finished run

    @property
    def tangent(self):
        """Unit tangent, shape (N, d); zero where the reference stands still."""
        v = self.speed[:, None]
        return np.divide(self.velocity, v, out=np.zeros_like(self.velocity), where=v > 0)

    @property
    def curvature(self):
        """Path curvature |v x a| / |v|^3 [1/mm], shape (N,); zero at standstill."""
        v, a = _validate.as_xyz(self.velocity), _validate.as_xyz(self.acceleration)
        speed = self.speed
        cross = np.linalg.norm(np.cross(v, a), axis=1)
        return np.divide(cross, speed**3, out=np.zeros_like(speed), where=speed > 0)


def _on_path(path, position, s):
    """Refuse samples that are not `path`'s points at their arc lengths `s` (:data:`CHECKED` of them, to :data:`ON_PATH`):
    the exact contour error, which searches the path from them, would measure to the wrong part of it."""
    k = np.unique(np.linspace(0, len(s) - 1, min(CHECKED, len(s))).round().astype(int))
    on = path.evaluate(s[k])[0][:, : position.shape[1]]
    off = np.linalg.norm(on - position[k], axis=1)
    bad = np.flatnonzero(off > ON_PATH + 1e-12 * np.abs(position[k]).max(axis=1))
    if bad.size:
        i = k[bad[0]]
        raise ValueError(f"position[{i}] lies {off[bad[0]]:.6g} mm from its path at its s = {s[i]:.6g} mm: a "
                         "trajectory's samples are its path's points at their arc length (contoursim.feed.sample "
                         "makes them so)")
