"""Feed profiles: motion s(t) along a path, planned under feed, acceleration and jerk limits.

A profile is a piecewise cubic s(t) (constant jerk on each piece) from rest at
s = 0 to rest at s = L. :func:`plan` builds it with the standard
forward/backward pass over sections of constant velocity limit:

1. each primitive gets a velocity limit: its block feed, lowered on curved
   primitives to sqrt(a_c / kappa_max) under the centripetal limit a_c (by
   default the acceleration limit: a controller bounds the acceleration
   across the path as well as along it, as an arc feed clamp does); a
   spline piece at its lowest, or where that is more than :data:`PIECE_SPLIT`
   times below its highest, by parts of its 64ths
   (:meth:`~contoursim.paths.Path.curvature_profile`): a tight turn in it
   slows the motion there, not over the whole piece;
2. consecutive intervals with the same limit (to its rounding) and a smooth
   join merge into one section; a join whose tangent turns by more than
   `corner_tolerance` is an exact stop (velocity 0);
3. junction velocities are capped by a forward pass (how fast can we be here
   having accelerated from the previous junction) and a backward pass (how
   fast may we be here and still brake for the next one);
4. each section accelerates to its highest reachable peak, cruises, and
   decelerates, every velocity change being time-optimal: a trapezoidal ramp
   (constant acceleration) without a jerk limit, else a jerk-limited S ramp
   that starts and ends at zero acceleration (reduced to a triangular
   acceleration pulse when the change is too small to reach a_max).

A jerk-limited velocity change from v0 to v1 is symmetric in time, so it covers
exactly (v0 + v1)/2 times its duration; the plan solves the junction velocities
with that closed form (a quadratic or a cubic in the velocity) and the peak
velocities by Newton's method on it. A single-feed, single-segment move is
the simplest instance: one section from rest to rest, which gives the
classical trapezoid (or triangle) and 7-phase S-curve (or its reduced forms).

Limitation: the acceleration is zero at section boundaries (where the limit
changes), which is slower than a plan that carries acceleration across them:
little where sections are long, much on a curve whose limit changes at every
short piece (a spline through a circle's points whose pieces' limits differed
in their rounding ran 1.654 s against the arc's 0.979 s before such limits
were taken as one).
"""

import math
import warnings
from dataclasses import dataclass

import numpy as np

from . import _memory, _validate
from .exceptions import ContoursimWarning, PathError
from .paths import Path
from .trajectory import Trajectory

__all__ = ["FeedProfile", "FeedSettings", "plan", "sample"]

#: Range of a feed [mm/s], acceleration [mm/s^2] and jerk [mm/s^3] of :func:`plan` and :class:`FeedSettings`:
#: beyond, the planning's squares and ratios overflow, and no machine moves so.
SETTING_RANGE = (1e-6, 1e12)
#: A spline piece whose speed limit (feed, centripetal) varies along it by more than this factor runs in parts, each at
#: the lowest limit of its part, within this factor of the highest (:func:`plan`).
PIECE_SPLIT = 2.0
_UNITS = {"feed": "mm/s", "accel": "mm/s^2", "jerk": "mm/s^3", "centripetal_accel": "mm/s^2"}

@dataclass(frozen=True)
class FeedProfile:
    """Piecewise-cubic motion along arc length, from rest at s = 0 to rest at s = length.

    Parameters
    ----------
    t0 : ndarray, shape (P,)
        Start time of each piece [s], increasing from 0.
    s0, v0, a0 : ndarray, shape (P,)
        Arc length [mm], path speed [mm/s] and acceleration [mm/s^2] at each piece's start.
    jerk : ndarray, shape (P,)
        Constant jerk on each piece [mm/s^3].
    duration : float
        End of the motion [s].
    length : float
        Distance travelled [mm].
    """

    t0: np.ndarray
    s0: np.ndarray
    v0: np.ndarray
    a0: np.ndarray
    jerk: np.ndarray
    duration: float
    length: float

    def __post_init__(self):
        t0 = _validate.finite_array("t0", self.t0, ndim=1)
        for name in ("t0", "s0", "v0", "a0", "jerk"):
            value = _validate.finite_array(name, getattr(self, name), shape=(t0.size,))
            value.flags.writeable = False
            object.__setattr__(self, name, value)
        if t0.size and (t0[0] != 0 or np.any(np.diff(t0) < 0)):
            raise ValueError("t0 must start at 0 and not decrease")
        object.__setattr__(self, "duration", _validate.positive("duration", self.duration))
        object.__setattr__(self, "length", _validate.positive("length", self.length))

    def evaluate(self, t):
        """Arc length, speed and acceleration along the path at times `t`.

        Parameters
        ----------
        t : array_like, shape (M,)
            Time [s]; before 0 the motion has not started, after `duration` it has ended.

        Returns
        -------
        s : ndarray, shape (M,)
            Arc length [mm], in [0, length].
        sdot : ndarray, shape (M,)
            Path speed [mm/s].
        sddot : ndarray, shape (M,)
            Path acceleration [mm/s^2].
        """
        t = _validate.finite_array("t", t, ndim=1)
        k = np.clip(np.searchsorted(self.t0, t, side="right") - 1, 0, self.t0.size - 1)
        tau = t - self.t0[k]
        a0, j = self.a0[k], self.jerk[k]
        s = self.s0[k] + tau * (self.v0[k] + tau * (a0 / 2 + tau * j / 6))
        v = self.v0[k] + tau * (a0 + tau * j / 2)
        a = a0 + tau * j
        moving = (t >= 0) & (t < self.duration)
        s = np.where(t >= self.duration, self.length, np.where(moving, np.clip(s, 0.0, self.length), 0.0))
        return s, np.where(moving, v, 0.0), np.where(moving, a, 0.0)


# --------------------------------------------------------------------------- velocity changes
# Plain Python in closed form (a program's first run compiles nothing): a G-code program or a
# spline has one section per block or piece, a few microseconds each.

def _ramp_pieces(v0, v1, accel, jerk):
    """Time-optimal velocity change v0 -> v1 as (duration, a_start, jerk) pieces."""
    dv = abs(v1 - v0)
    if dv == 0.0:
        return []
    sign = 1.0 if v1 > v0 else -1.0
    if jerk is None:
        return [(dv / accel, sign * accel, 0.0)]
    if dv >= accel**2 / jerk:
        tj = accel / jerk
        return [(tj, 0.0, sign * jerk), (dv / accel - tj, sign * accel, 0.0), (tj, sign * accel, -sign * jerk)]
    tj = math.sqrt(dv / jerk)
    return [(tj, 0.0, sign * jerk), (tj, sign * jerk * tj, -sign * jerk)]


def _ramp_distance(v0, v1, accel, jerk):
    """Distance of the time-optimal change v0 -> v1: (v0 + v1)/2 times its duration."""
    dv = abs(v1 - v0)
    if jerk is None:
        duration = dv / accel
    elif dv >= accel**2 / jerk:
        duration = dv / accel + accel / jerk
    else:
        duration = 2.0 * math.sqrt(dv / jerk)
    return 0.5 * (v0 + v1) * duration


def _ramp_slope(v, x, r, y, accel, jerk):
    """d/dy of :func:`_ramp_distance` between v and x = x0 + y² (x > v), with r = sqrt(x − v).

    ``2y (T/2 + (v + x) T'/2)``, T the ramp's duration; for a jerk-limited
    ramp short of a_max T = 2r/√j and 2y T' = 2y/(r √j), finite where r = y.
    """
    if jerk is None or r * r >= accel**2 / jerk:
        duration = r * r / accel + (0.0 if jerk is None else accel / jerk)
        return y * duration + (v + x) * y / accel
    return 2.0 * y * r / math.sqrt(jerk) + (v + x) * (y / r if r > 0 else 1.0) / math.sqrt(jerk)


def _ramps(x, v0, v1, accel, jerk):
    """Distance of the ramps v0 -> x and, unless `v1` is None, x -> v1."""
    distance = _ramp_distance(v0, x, accel, jerk)
    return distance if v1 is None else distance + _ramp_distance(x, v1, accel, jerk)


def _fitting(v, lo, v0, v1, length, accel, jerk):
    """`v` stepped down to the largest value whose :func:`_ramps` fit in `length` (rounding), not below `lo`.

    Plain arguments, no closure: a function object made per block is garbage
    the collector has to walk (G-code planning once took 40 % longer so).
    """
    for _ in range(64):
        if v <= lo or _ramps(v, v0, v1, accel, jerk) <= length:
            return max(v, lo)
        v = max(v - 4e-16 * max(v, 1.0), lo)
    return lo


def _reach(v0, length, vmax, accel, jerk):
    """Largest v in [v0, vmax] reached from v0 within `length`: ``_ramp_distance(v0, v) <= length``, in closed form.

    Without a jerk limit ``v² = v0² + 2 a L``. With one, a ramp that reaches
    a_max (dv >= a²/j) covers ``(v² − v0²)/(2a) + (v0 + v) a/(2j)``, a
    quadratic in v; a shorter one covers ``(2 v0 + y²) y / √j`` with
    y = √(v − v0), a cubic in y (Cardano, one real root).
    """
    if _ramp_distance(v0, vmax, accel, jerk) <= length:
        return vmax
    if jerk is None:
        v = math.sqrt(v0 * v0 + 2.0 * accel * length)
    elif _ramp_distance(v0, v0 + accel**2 / jerk, accel, jerk) <= length:
        a2, b = 0.5 / accel, 0.5 * accel / jerk
        c = b * v0 - a2 * v0 * v0 - length
        v = -2.0 * c / (b + math.sqrt(b * b - 4.0 * a2 * c))  # the positive root, without cancellation
    else:
        p, q = 2.0 * v0, length * math.sqrt(jerk)  # y³ + p y = q
        u = (0.5 * q + math.sqrt(0.25 * q * q + p**3 / 27.0)) ** (1.0 / 3.0)
        y = u - p / (3.0 * u)
        v = v0 + y * y
    return _fitting(min(max(v, v0), vmax), v0, v0, None, length, accel, jerk)


def _peak(v0, v1, length, vmax, accel, jerk):
    """Largest peak in [max(v0, v1), vmax] with both ramps within `length`.

    Equal ends are the closed form of :func:`_reach` over half the length;
    two trapezoidal ramps, or two that reach a_max, a quadratic. Otherwise
    (a jerk-limited ramp short of a_max) Newton's method on the distance as a function of
    y = sqrt(peak − max(v0, v1)), which keeps it smooth where the ramp from
    the faster end starts (a jerk-limited ramp covers (2v + y²) y / √j),
    inside a bracket that bisection shrinks where Newton would leave it.
    """
    top, other = max(v0, v1), min(v0, v1)
    if _ramps(vmax, v0, v1, accel, jerk) <= length:
        return vmax
    if _ramps(top, v0, v1, accel, jerk) >= length:
        return top
    if v0 == v1:
        return _fitting(_reach(v0, 0.5 * length, vmax, accel, jerk), top, v0, v1, length, accel, jerk)
    # both ramps trapezoidal, or both reaching a_max: (2x² − v0² − v1²)/(2a) [+ (v0 + v1 + 2x) a/(2j)] = L
    b = 0.0 if jerk is None else 0.5 * accel / jerk
    c = b * (v0 + v1) - (v0 * v0 + v1 * v1) / (2.0 * accel) - length
    x = -2.0 * c / (2.0 * b + math.sqrt(4.0 * b * b - 4.0 * c / accel))  # root of x²/a + 2b x + c, no cancellation
    if jerk is None or x - top >= accel**2 / jerk:
        return _fitting(min(max(x, top), vmax), top, v0, v1, length, accel, jerk)
    lo, hi = 0.0, math.sqrt(vmax - top)  # bracket on y: total fits at lo, not at hi
    y = 0.5 * hi
    for _ in range(100):
        x = top + y * y
        f = _ramps(x, v0, v1, accel, jerk) - length
        if f <= 0:
            lo = y
        else:
            hi = y
        slope = _ramp_slope(top, x, y, y, accel, jerk) + _ramp_slope(other, x, math.sqrt(x - other), y, accel, jerk)
        step = f / slope if slope > 0 else math.inf
        new = y - step if lo < y - step < hi else 0.5 * (lo + hi)
        if abs(new - y) * (new + y) <= 2e-16 * max(top, 1.0) or new in (lo, hi):  # x = top + y² settled
            break
        y = new
    return _fitting(top + y * y, top + lo * lo, v0, v1, length, accel, jerk)


def _plan_sections(breaks, vmax, vjunction, accel, jerk, dwell):
    """Profile over sections [breaks[i], breaks[i+1]]: speed limits vmax[i], junction caps, a standstill dwell[i] after each."""
    lengths = np.diff(breaks).tolist()
    vmax = np.asarray(vmax, float).tolist()
    v = np.array(vjunction, dtype=float).tolist()
    n = len(lengths)
    for i in range(n):  # forward: reachable from the previous junction
        v[i + 1] = min(v[i + 1], _reach(v[i], lengths[i], vmax[i], accel, jerk))
    for i in reversed(range(n)):  # backward: can still brake for the next junction
        v[i] = min(v[i], _reach(v[i + 1], lengths[i], vmax[i], accel, jerk))
    rows, t = [], 0.0
    for i in range(n):
        v0, v1, length = v[i], v[i + 1], lengths[i]
        peak = _peak(v0, v1, length, vmax[i], accel, jerk)
        cruise = length - _ramp_distance(v0, peak, accel, jerk) - _ramp_distance(peak, v1, accel, jerk)
        pieces = _ramp_pieces(v0, peak, accel, jerk)
        if cruise > 0 and peak > 0:
            pieces.append((cruise / peak, 0.0, 0.0))
        pieces += _ramp_pieces(peak, v1, accel, jerk)
        s, vel = float(breaks[i]), v0
        for duration, a0, j in pieces:
            if duration <= 0:
                continue
            rows += (t, s, vel, a0, j)  # flat: a tuple kept per piece would be garbage for the collector to count
            s += duration * (vel + duration * (a0 / 2 + duration * j / 6))
            vel += duration * (a0 + duration * j / 2)
            t += duration
        if dwell[i] > 0:  # at rest (v1 = 0 there) exactly at the section's end
            rows += (t, float(breaks[i + 1]), 0.0, 0.0, 0.0)
            t += dwell[i]
    t0, s0, v0, a0, j = np.array(rows).reshape(-1, 5).T
    return FeedProfile(t0, s0, np.maximum(v0, 0.0), a0, j, t, float(breaks[-1]))


# --------------------------------------------------------------------------- planning

def _feed_values(feed):
    """A positive feed [mm/s], or a 1-D array of them."""
    values = _validate.finite_array("feed", feed)
    if values.ndim == 0:
        return _validate.positive("feed", feed)
    if values.ndim != 1 or values.size == 0 or np.any(values <= 0):
        bad = values.ravel() <= 0
        detail = f"feed[{int(np.argmax(bad))}] = {values.ravel()[np.argmax(bad)]:g}" if bad.any() else f"shape {values.shape}"
        raise ValueError(f"feed must be a positive value or a list of them, got {detail}")
    return values


def plan(path, feed, accel, jerk=None, *, centripetal_accel=None, corner_tolerance=1e-3, max_feed=None,
         in_position=0.0, stops=(), servo_period=None):
    """Plan the motion along a path under feed, acceleration and jerk limits.

    Parameters
    ----------
    path : contoursim.paths.Path
        The path to travel.
    feed : float or array_like, shape (K,)
        Feed rate [mm/s], one value or one per primitive (G-code blocks);
        it, `accel`, `jerk` and `centripetal_accel` within :data:`SETTING_RANGE`.
    accel : float
        Path acceleration limit [mm/s^2].
    jerk : float, optional
        Path jerk limit [mm/s^3]; None gives trapezoidal profiles.
    centripetal_accel : float, optional
        Limit on v^2 kappa [mm/s^2]: v <= sqrt(a_c / kappa) with kappa the largest curvature of each curved
        primitive (of each 64th of a spline piece); default `accel` (a G-code
        fillet of 0.5 mm at 3000 mm/min ran through at 5000 mm/s^2 under a limit of 1000).
    corner_tolerance : float
        Tangent turn at a join above which the motion stops exactly [rad].
    max_feed : float, optional
        Largest feed allowed [mm/s]; a larger `feed` raises ValueError,
        but a rapid's (a primitive with role ``"rapid"``, G0) is lowered to it.
    in_position : float
        Standstill at the end of each rapid (a primitive with role
        ``"rapid"``, a G0 move) [s]: the motion always stops there, and waits
        for the axes to reach the position (a controller's in-position check)
        before the next block.
    stops : sequence of int
        Primitives at whose end the motion stops and waits `in_position` as
        at the end of a rapid (a G-code dwell, G4).
    servo_period : float, optional
        The period the motion will be sampled at [s]: a join passed at speed
        (its turn under `corner_tolerance`) turns the velocity within one
        period, which is warned of where that exceeds `accel`.

    Returns
    -------
    FeedProfile
        Rest to rest over the path length.

    Warns
    -----
    ContoursimWarning
        Joins passed at speed whose velocity step exceeds `accel` over a
        `servo_period`; ten or more joins that stop exactly though they turn
        by less than a degree (a program of short segments, CAM output, runs
        well below its feed: a tolerance a little higher passes them).

    Examples
    --------
    A 100 mm line at 20 mm/s with 100 mm/s^2: 0.2 s ramps over 2 mm each,
    96 mm cruise in 4.8 s, 5.2 s in all.

    >>> from contoursim.paths import line
    >>> round(plan(line((0, 0), (100, 0)), 20.0, 100.0).duration, 9)
    5.2
    """
    k = len(_path(path).primitives)
    feeds = _feed_values(feed)
    if np.ndim(feeds) == 0:
        feeds = np.full(k, feeds)
    elif feeds.shape != (k,):
        raise ValueError(f"feed must be one value or one per primitive ({k}), got {feeds.size} values")
    _setting("feed", feeds)
    accel = _setting("accel", _validate.positive("accel", accel))
    jerk = None if jerk is None else _setting("jerk", _validate.positive("jerk", jerk))
    tolerance = _corner_tolerance(corner_tolerance)
    waits = np.array(path.roles) == "rapid"
    if max_feed is not None:
        max_feed = _validate.positive("max_feed", max_feed)
        feeds = np.where(waits, np.minimum(feeds, max_feed), feeds)  # a rapid traverses at the machine's fastest
        if feeds.max() > max_feed:
            i = int(np.argmax(feeds))
            raise PathError(f"feed {feeds[i]:.6g} mm/s ({feeds[i] * 60:.6g} mm/min, segment {i}) exceeds "
                            f"max_feed = {max_feed:.6g} mm/s ({max_feed * 60:.6g} mm/min)", primitive=i)
    ac = accel if centripetal_accel is None else _setting("centripetal_accel", _validate.positive("centripetal_accel",
                                                                                                  centripetal_accel))
    edges, kappa, primitive = path.curvature_profile()  # intervals: a line or an arc each, 64 a spline piece
    limits = feeds[primitive]
    curved = kappa > 0
    limits[curved] = np.minimum(limits[curved], np.sqrt(ac / kappa[curved]))
    heads, limits = _runs(limits, primitive)
    edges, primitive = np.append(edges[heads], path.length), primitive[heads]
    in_position = _validate.nonnegative("in_position", in_position)
    servo_period = None if servo_period is None else _validate.positive("servo_period", servo_period)
    stops = np.array(_stops(stops), dtype=int)
    if np.any(stops >= k):
        raise ValueError(f"stops must be primitive indices in [0, {k - 1}], got {stops.tolist()}")
    waits[stops] = True
    waits = waits[:-1]  # the path's end is a stop of its own
    stop = (path.corner_angles() > tolerance) | waits
    joins = np.flatnonzero(np.diff(primitive))  # the intervals that end a primitive (not the last)
    halts, rests = np.zeros((2, len(primitive) - 1), bool)
    halts[joins], rests[joins] = stop, waits
    # limits apart by their rounding alone are one (a spline through a circle's points: its pieces' curvatures)
    split = halts | ~np.isclose(limits[1:], limits[:-1], rtol=1e-9, atol=0.0)
    first = np.concatenate([[0], np.flatnonzero(split) + 1])
    breaks = np.append(edges[first], path.length)
    vmax = np.minimum.reduceat(limits, first)
    inner = np.where(halts[first[1:] - 1], 0.0, np.minimum(vmax[:-1], vmax[1:]))
    vjunction = np.concatenate([[0.0], inner, [0.0]])
    dwell = np.append(np.where(rests[first[1:] - 1], in_position, 0.0), 0.0)
    profile = _plan_sections(breaks, vmax, vjunction, accel, jerk, dwell)
    _warn_corners(path, profile, stop, waits, tolerance, accel, servo_period)
    return profile


def _runs(limits, primitive):
    """The intervals of a curvature profile that start a run, and each run's speed limit (its lowest).

    A primitive's intervals run as one at their lowest limit, unless that is
    more than :data:`PIECE_SPLIT` times below their highest: then in runs
    within that factor, from the start. A limit that changed at every 64th
    of a piece would brake and accelerate there (a section starts and ends
    at zero acceleration): a spiral of 10 000 pieces ran 481 s against 307 s
    on one limit a piece, and its planning took 100 times as long.
    """
    start = np.concatenate([[True], primitive[1:] != primitive[:-1]])
    first = np.flatnonzero(start)
    ends = np.append(first[1:], limits.size)
    low, high = np.minimum.reduceat(limits, first), np.maximum.reduceat(limits, first)
    for a, b in zip(first[high > PIECE_SPLIT * low], ends[high > PIECE_SPLIT * low]):
        least = most = limits[a]
        for c in range(a + 1, b):
            least, most = min(least, limits[c]), max(most, limits[c])
            if most > PIECE_SPLIT * least:
                start[c], least, most = True, limits[c], limits[c]
    heads = np.flatnonzero(start)
    return heads, np.minimum.reduceat(limits, heads)


def _warn_corners(path, profile, stop, waits, tolerance, accel, servo_period):
    """:func:`plan`'s warnings of its joins (`stop`: those it stops at, `waits` among them a rapid's end or a dwell):
    passed at a velocity step beyond `accel`, stopped at a slight turn."""
    turns = path.corner_angles()
    slight = stop & ~waits & (turns < math.radians(1.0))
    if slight.sum() >= 10:
        speed = 60.0 * profile.length / profile.duration
        warnings.warn(f"{slight.sum()} joins stop exactly though each turns by less than 1° (corner_tolerance_deg = "
                      f"{math.degrees(tolerance):.3g}; up to {math.degrees(turns[slight].max()):.3g}° here): the path "
                      f"takes {profile.duration:.4g} s, {speed:.4g} mm/min on average; a program of short segments "
                      "(CAM output) is passed at its feed with corner_tolerance_deg a little above its turns",
                      ContoursimWarning, stacklevel=3)
    passed = (turns > 0.0) & ~stop
    if servo_period is None or not passed.any():
        return
    piece = np.searchsorted(profile.s0, path.breaks[1:-1], side="right") - 1  # the motion's piece at each join
    speed = np.maximum(profile.v0[piece], profile.v0[np.minimum(piece + 1, profile.v0.size - 1)])  # at most
    step = np.where(passed, 2.0 * speed * np.sin(turns / 2.0), 0.0)  # the velocity's turn at the join [mm/s]
    worst = int(np.argmax(step))
    if step[worst] > accel * servo_period:
        count = int((step > accel * servo_period).sum())
        warnings.warn(f"{count} join{'s' * (count > 1)} under corner_tolerance_deg = {math.degrees(tolerance):.3g} "
                      f"{'are' if count > 1 else 'is'} passed at speed: the velocity turns by up to "
                      f"{step[worst]:.3g} mm/s within a servo period (a join of {math.degrees(turns[worst]):.3g}° at "
                      f"{speed[worst]:.4g} mm/s), {step[worst] / servo_period:.4g} mm/s² against accel = {accel:.4g}; "
                      "a lower corner_tolerance_deg stops there", ContoursimWarning, stacklevel=3)


@dataclass(frozen=True)
class FeedSettings:
    """Feed, acceleration and jerk limits of a path file.

    Parameters
    ----------
    feed : float or tuple of float
        Feed rate [mm/s], one value or one per primitive.
    accel : float
        Path acceleration limit [mm/s^2].
    jerk : float, optional
        Path jerk limit [mm/s^3]; None for trapezoidal profiles.
    centripetal_accel : float, optional
        Centripetal acceleration limit [mm/s^2]; None for `accel`.
    corner_tolerance : float
        Exact-stop threshold on the tangent turn at joins [rad].
    stops : tuple of int
        Primitives at whose end the motion stops and waits in position (a
        G-code program's dwells, see :func:`plan`).
    """

    feed: object
    accel: float = 1000.0
    jerk: float = None
    centripetal_accel: float = None
    corner_tolerance: float = 1e-3
    stops: tuple = ()

    def __post_init__(self):
        feed = _feed_values(self.feed)
        object.__setattr__(self, "feed", feed if np.ndim(feed) == 0 else tuple(feed.tolist()))
        object.__setattr__(self, "accel", _validate.positive("accel", self.accel))
        for name in ("jerk", "centripetal_accel"):
            if getattr(self, name) is not None:
                object.__setattr__(self, name, _validate.positive(name, getattr(self, name)))
        object.__setattr__(self, "corner_tolerance", _corner_tolerance(self.corner_tolerance))
        object.__setattr__(self, "stops", _stops(self.stops))
        for name in ("feed", "accel", "jerk", "centripetal_accel"):
            if getattr(self, name) is not None:
                _setting(name, getattr(self, name))

    def plan(self, path, max_feed=None, in_position=0.0, servo_period=None):
        """:func:`plan` with these settings.

        Parameters
        ----------
        path : contoursim.paths.Path
            The path to travel.
        max_feed : float, optional
            Largest feed allowed [mm/s].
        in_position : float
            Standstill at the end of each rapid and at each of `stops` [s] (see :func:`plan`).
        servo_period : float, optional
            The period the motion will be sampled at [s] (see :func:`plan`).

        Returns
        -------
        FeedProfile
        """
        return plan(path, self.feed, self.accel, self.jerk, centripetal_accel=self.centripetal_accel,
                    corner_tolerance=self.corner_tolerance, max_feed=max_feed, in_position=in_position,
                    stops=self.stops, servo_period=servo_period)


def _setting(name, value):
    """`value`, a feed (or one per primitive), acceleration or jerk limit, after checking it lies within
    :data:`SETTING_RANGE` in the unit of `name`: 1e-300 or 1e308 overflow the planning (a feed of 1e-300 mm/s plans a
    motion of 1e301 s that no servo period samples)."""
    values = np.atleast_1d(np.asarray(value, dtype=float))
    low, high = SETTING_RANGE
    outside = (values < low) | (values > high)
    if outside.any():
        i = int(np.argmax(outside))
        where = f"{name}[{i}]" if values.size > 1 else name
        raise ValueError(f"{where} must lie within [{low:g}, {high:g}] {_UNITS[name]}, got {values[i]:g}: no machine "
                         "moves so slowly or so fast, and beyond the range the planning's squares and ratios overflow")
    return value


def _corner_tolerance(value):
    """`value` [rad] after checking it is a turn a join can make, in [0, π] (above π no join would ever stop)."""
    value = _validate.nonnegative("corner_tolerance", value)
    if value > np.pi:
        raise ValueError(f"corner_tolerance must be at most π rad (180°, a reversal), got {value:g} rad "
                         f"({np.degrees(value):g}°)")
    return value


def _stops(stops):
    """`stops` as a tuple of primitive indices, after checking each is a whole number >= 0 (1.5 is no primitive, and
    would be cut to 1)."""
    if isinstance(stops, (str, bytes)) or not np.iterable(stops):
        raise TypeError(f"stops must be a sequence of primitive indices, got {stops!r}")
    return tuple(_validate.positive_int(f"stops[{i}]", k, least=0) for i, k in enumerate(stops))


def _path(path):
    """`path`, refused unless it is a :class:`~contoursim.paths.Path`."""
    if not isinstance(path, Path):
        raise TypeError(f"path must be a contoursim.paths.Path (paths.polyline makes one from points), got "
                        f"{type(path).__name__}")
    return path


def sample(path, profile, dt):
    """Sample the motion at the servo period.

    Parameters
    ----------
    path : contoursim.paths.Path
        The path.
    profile : FeedProfile
        Motion along it (from :func:`plan`).
    dt : float
        Servo period [s].

    Returns
    -------
    Trajectory
        t = 0, dt, ... up to the first sample at or after the end of the
        motion (a standstill sample at s = L). Velocity T sdot [mm/s] and
        acceleration T sddot + kappa N sdot^2 [mm/s^2] are analytic;
        position has ``path.dim`` columns; ``measuring`` marks samples on
        primitives with role "test", on a path without them the samples on
        every primitive but the rapids (role "rapid"); a sample at rest at a
        junction (a stop, an in-position dwell) is on the primitive ending there.

    Raises
    ------
    ValueError
        The profile does not fit the path, `dt` is not shorter than the
        motion (no sample between its start and end), or a run of the
        motion's samples would need more memory than is available
        (:func:`contoursim._memory.check`; a very long path or a very slow feed).
    """
    dt = _validate.positive("dt", dt)
    if not isinstance(profile, FeedProfile):
        raise TypeError(f"profile must be a FeedProfile (from plan), got {type(profile).__name__}")
    if abs(profile.length - _path(path).length) > 1e-9 * max(1.0, path.length):
        raise ValueError(f"profile length {profile.length} mm differs from the path length {path.length} mm")
    periods = profile.duration / dt  # a whole number to rounding (a path moved: 7020.0000000000016) is that number
    n = round(periods) if abs(periods - round(periods)) <= 1e-9 * max(periods, 1.0) else math.ceil(periods)
    if n < 2:  # its start and its end only: a step from one to the other, as a controller runs a block shorter than
        # its period; but a path that is no straight line between them would be skipped, whatever it is
        ends = path.derivatives(np.array([0.0, path.length]))[0][:, :path.dim]
        if path.length > (1 + 1e-9) * np.linalg.norm(ends[1] - ends[0]):
            raise ValueError(f"dt = {dt:.6g} s is not shorter than the motion, which lasts {profile.duration:.6g} s: "
                             "no sample would lie on the path between its start and its end; sample it at a shorter "
                             "dt (the servo period), or plan a longer or slower motion")
    _memory.check(n + 1, f"the motion lasts {profile.duration:.6g} s: at dt = {dt:.6g} s",
                  "check the path length, the feed and the servo period")
    t = np.arange(n + 1) * dt
    s, sdot, sddot = profile.evaluate(t)
    s[-1], sdot[-1], sddot[-1] = path.length, 0.0, 0.0
    d = path.dim
    pos, tangent, kvec = (x[:, :d] for x in path.derivatives(s))
    vel = tangent * sdot[:, None]
    acc = tangent * sddot[:, None] + kvec * (sdot**2)[:, None]
    roles = np.array(path.roles)
    on = roles[path.segment_index(s, at_rest=sdot == 0)]  # the role of each sample's primitive (a stop: the one ending)
    measuring = on == "test" if "test" in path.roles else on != "rapid"
    # a copy of the positions, so that the (N, 9) evaluation the three came from is freed
    return Trajectory(t, pos.copy(), vel, acc, s, path=path, measuring=measuring)
