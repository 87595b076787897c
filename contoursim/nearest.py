"""Nearest reference sample to a tool position: the one search of the package.

Both the exact contour error (:mod:`contoursim.contour`, which refines the
sample it finds on the continuous path) and the online estimators
(:mod:`contoursim.estimators`, which build their local curve around it) start
from the reference sample nearest to the actual tool position P. Which part of
the path is searched is fixed by the *commanded* sample R, the reference
point of the same instant, not by the history of the search:

    the part of the path that is connected to R inside the ball of radius
    2|P - R| about R, where a stretch that leaves the ball for no more than
    its radius of length along the path (``L`` below) connects too.

Every path point nearer to P than R lies in that ball, so the distance
found is never larger than the tracking error |P - R| (R itself is a
candidate), whatever the path does elsewhere: where it turns back on itself
(a retract, a drilling cycle, back-and-forth passes, a circle cut twice) the
search looks at the stretch around R and the reversal point is part of it,
also where the ball clips the tip of a narrow corner (the way in, cut off
by a fraction of a µm, was not taken: the error jumped from 4.5 to 26.7 µm
between two samples); where a figure-eight crosses itself, the other branch
is connected to R only by a stretch far outside the ball and is not taken.
The search runs over the knots in path order and stops at the path's ends,
also at the seam of a closed one (:mod:`contoursim.contour`'s walk goes on
across it).

The search runs over the *knots*, the reference samples with the repeats of a
standstill removed (:func:`distinct`): at an exact stop the interpolator
repeats the corner sample for many servo periods. Each knot carries its
length along the path, ``L``: the cumulative chord length of the knots up to
it, or (:func:`contoursim.contour.exact_contour_error`, which knows the path)
their arc length; since |K_i - K_j| <= |L_i - L_j| (the triangle inequality),
a knot whose distance to R leaves a slack below the ball's radius, and whose
distance to P exceeds the best one found by a margin, rules out every knot
within that slack and margin of ``L``, which are skipped by a galloping search on ``L`` (sphere
tracing along the path). The knot found for the previous tool position, the
*hint*, seeds the best distance: a short descent from it (a few knots) finds
the foot point of a tool that follows the path, so that the scan of the ball
mostly skips; the result does not depend on the hint (a hint outside R's part
of the ball is discarded and the ball scanned again without it).
"""

import numpy as np
from ._numba import njit

__all__ = ["distinct", "fill_chord", "moved", "nearest_knot", "nearest_knots", "with_chord"]

REACH = 2048  # most knots the descent from the hint scans forward before walking on [-]


def distinct(points):
    """Drop consecutive duplicate points (a standstill of the reference).

    Parameters
    ----------
    points : ndarray, shape (N, 3)
        Reference samples in path order [mm], N >= 1, finite (checked by the caller).

    Returns
    -------
    knots : ndarray, shape (M, 4)
        The distinct samples in order [mm] and, in the last column, the
        cumulative chord length from the first [mm] (see the module docstring); C-contiguous, read-only.
    first_sample : ndarray of int, shape (M,)
        Index of the first sample of each knot.
    knot_of_sample : ndarray of int, shape (N,)
        Knot holding each sample.
    """
    keep = moved(points)
    return with_chord(points[keep]), np.flatnonzero(keep), np.cumsum(keep) - 1


def with_chord(knots):
    """Knots (M, 3) with their cumulative chord length as a fourth column [mm], C-contiguous (M, 4), read-only.

    Parameters
    ----------
    knots : ndarray, shape (M, 3)
        Distinct points in path order [mm], M >= 1.

    Returns
    -------
    ndarray, shape (M, 4)

    Examples
    --------
    >>> with_chord(np.array([[0.0, 0, 0], [3, 4, 0], [3, 4, 1]]))[:, 3].tolist()
    [0.0, 5.0, 6.0]
    """
    out = np.empty((len(knots), 4))
    out[:, :3] = knots
    fill_chord(out)
    out.flags.writeable = False  # every knots array the search takes is: one compiled signature (see _beyond)
    return out


@njit(cache=True)
def fill_chord(knots):
    """Write the cumulative chord length of the points in columns 0-2 of `knots` into column 3 [mm].

    Parameters
    ----------
    knots : ndarray, shape (M, 4)
        Distinct points in path order [mm] in columns 0-2; column 3 is overwritten.
    """
    total = 0.0
    for i in range(knots.shape[0]):
        if i:
            total += np.sqrt((knots[i, 0] - knots[i - 1, 0]) ** 2 + (knots[i, 1] - knots[i - 1, 1]) ** 2
                             + (knots[i, 2] - knots[i - 1, 2]) ** 2)  # fmt: skip
        knots[i, 3] = total


def moved(points):
    """Which points differ from the one before (the first always): the knots among them.

    Parameters
    ----------
    points : ndarray, shape (N, d)
        Reference samples in path order [mm], N >= 1, any number of columns d.

    Returns
    -------
    ndarray of bool, shape (N,)
    """
    keep = np.ones(len(points), bool)
    changed = points[1:] != points[:-1]
    keep[1:] = changed[:, 0]
    for column in range(1, points.shape[1]):  # np.any(axis=1) is several times slower on 2 or 3 columns
        keep[1:] |= changed[:, column]
    return keep


@njit(cache=True)
def _distance(knots, i, p):
    return np.sqrt((p[0] - knots[i, 0]) ** 2 + (p[1] - knots[i, 1]) ** 2 + (p[2] - knots[i, 2]) ** 2)


@njit(cache=True)
def _descend(knots, hint, p, window):
    """Knot nearest to p around `hint`: the local minimum of the distance the hint leads to.

    Scans `window` knots back from the hint, and forward at least `window`
    knots and on while the knots stay within d_hint + d_best of the hint (at
    most :data:`REACH`): at a concave corner the distance along the incoming
    segment has a local minimum of its own, and the outgoing segment is
    found across it. When the best knot lies on the edge of the scanned
    range the search walks on that way while the distance decreases.

    Returns the knot and the range [lo, hi] of knots looked at, none of
    them nearer to p than it.
    """
    m = knots.shape[0]
    h = min(max(hint, 0), m - 1)
    hx, hy, hz = knots[h, 0], knots[h, 1], knots[h, 2]
    best, dbest = h, (p[0] - hx) ** 2 + (p[1] - hy) ** 2 + (p[2] - hz) ** 2
    dh = np.sqrt(dbest)
    ball = 4.0 * dbest  # (d_hint + d_best)^2
    hi = h
    for i in range(h + 1, min(h + REACH, m - 1) + 1):
        if i > h + window and (knots[i, 0] - hx) ** 2 + (knots[i, 1] - hy) ** 2 + (knots[i, 2] - hz) ** 2 > ball:
            break
        hi = i
        d = (p[0] - knots[i, 0]) ** 2 + (p[1] - knots[i, 1]) ** 2 + (p[2] - knots[i, 2]) ** 2
        if d < dbest:
            best, dbest = i, d
            ball = (dh + np.sqrt(d)) ** 2
    lo = max(h - window, 0)
    for i in range(h - 1, lo - 1, -1):
        d = (p[0] - knots[i, 0]) ** 2 + (p[1] - knots[i, 1]) ** 2 + (p[2] - knots[i, 2]) ** 2
        if d < dbest:
            best, dbest = i, d
    step = 1 if best == hi and hi > h else (-1 if best == lo and lo < h else 0)
    i = best + step
    while step != 0 and 0 <= i < m:
        d = (p[0] - knots[i, 0]) ** 2 + (p[1] - knots[i, 1]) ** 2 + (p[2] - knots[i, 2]) ** 2
        if d >= dbest:
            break
        best, dbest = i, d
        i += step
    if step == 1:
        hi = min(i, m - 1)
    elif step == -1:
        lo = max(i, 0)
    return best, lo, hi


@njit(cache=True)
def _along(length, v, lap):
    """The length along the path of index v of `length` (M,): ``length[v]``; on a closed path (`lap` > 0, its length
    [mm], ``length[M - 1]`` at the start again) any integer v, taken modulo M - 1 with a lap added per turn."""
    if lap == 0.0:
        return length[v]
    period = length.shape[0] - 1
    return length[v % period] + lap * (v // period)


@njit(cache=True)
def _real(v, m, lap):
    """The index into an array of M entries of index v along the path (:func:`_along`)."""
    return v if lap == 0.0 else v % (m - 1)


@njit(cache=True)
def _beyond(length, j, step, slack, lap):
    """The first knot past j (in direction step = ±1) whose cumulative `length` differs from j's by >= slack.

    `length` (M,) is non-decreasing [mm]: the knots' ``L`` (the last
    column of read-only knots, a strided view) or the samples' arc length
    (:mod:`contoursim.contour` passes it as such a view: one compiled version). Returns an index outside [0, M) when there is
    none; on a closed path (`lap` > 0, :func:`_along`) an index of any sign, at most a lap away. Galloping: doubling
    steps, then bisection, O(log k) probes for a jump of k knots.
    """
    m = length.shape[0]
    left = (j if step == -1 else m - 1 - j) if lap == 0.0 else m - 1  # knots that way (closed: a lap's)
    c0 = _along(length, j, lap)
    good, k = 0, 1  # gap < slack up to good; k: the probe
    while k <= left and step * (_along(length, j + step * k, lap) - c0) < slack:
        good = k
        k *= 2
    bad = min(k, left + 1)  # gap >= slack there, or past the end
    while bad - good > 1:
        mid = (good + bad) // 2
        if step * (_along(length, j + step * mid, lap) - c0) < slack:
            good = mid
        else:
            bad = mid
    return j + step * bad


@njit(cache=True)
def _scan(knots, a, p, radius, best, dbest, seen_lo, seen_hi):
    """Nearest knot to p among those connected to knot a inside the ball of `radius` about it.

    A stretch of the path that leaves the ball for no more than `radius` of
    ``L`` (the tip of a corner the ball clips) connects too (see the module docstring).
    ``best, dbest`` seed the search (a knot and its distance to p; a and
    its distance when there is no other): knots not nearer than dbest are
    skipped, and so is the range [seen_lo, seen_hi] of knots known to be no
    nearer (empty when seen_lo > seen_hi). Returns the best knot and its
    distance, and the index range [lo, hi] of a's part of the ball.
    """
    m = knots.shape[0]
    r = (knots[a, 0], knots[a, 1], knots[a, 2])
    length = knots[:, 3]
    lo, hi = 0, m - 1
    for step in (-1, 1):
        j, out = a, -1  # out: the last knot inside the ball before the walk left it (-1: the walk is inside)
        while True:
            if out >= 0 and step * (length[j] - length[out]) > radius:  # away longer than a clipped corner: a's part
                break  # of the ball ends at out
            dr = _distance(knots, j, r)
            if dr > radius:  # outside: no knot within dr - radius of length is inside
                if out < 0:
                    out = j - step  # skips inside the ball stop at its edge: the knot before j is inside
                j = _beyond(length, j, step, dr - radius, 0.0)
            else:
                out = -1
                dp = _distance(knots, j, p)
                if dp < dbest:
                    best, dbest = j, dp
                if seen_lo <= j <= seen_hi:  # no nearer knot up to the end of the seen range: the ball decides alone
                    past = seen_hi + 1 if step == 1 else seen_lo - 1
                    ball = _beyond(length, j, step, radius - dr, 0.0)
                    j = past if step * (ball - past) >= 0 else ball
                else:  # every knot within this much length of j is inside the ball and no nearer to p than dbest
                    j = _beyond(length, j, step, min(radius - dr, dp - dbest), 0.0)
            if j < 0 or j >= m:
                break
        if out >= 0:
            if step == -1:
                lo = out
            else:
                hi = out
    return best, dbest, lo, hi


@njit(cache=True)
def nearest_knot(knots, anchor, hint, p, window):
    """Index of the knot nearest to p on the part of the path around the commanded knot.

    The part of the path connected to the `anchor` knot R inside the ball
    of radius 2|p - R| about it (see the module docstring): the knot found
    is never farther from p than R, and a branch of the path that only
    comes near p elsewhere is never taken.

    Parameters
    ----------
    knots : ndarray, shape (M, 4)
        Distinct reference samples [mm] and their length along the path ``L`` [mm] (:func:`distinct`: the chord
        length), M >= 1.
    anchor : int
        Knot of the commanded sample: the reference point of the instant at which p was taken; clipped to [0, M - 1].
    hint : int
        Knot found for the previous tool position (an accelerator only:
        the result does not depend on it); clipped to [0, M - 1].
    p : tuple of 3 float
        Tool position [mm].
    window : int
        Knots the descent from the hint scans either side before walking on [-], >= 1.

    Returns
    -------
    int
        Index of the nearest knot.
    """
    m = knots.shape[0]
    a = min(max(anchor, 0), m - 1)
    e = _distance(knots, a, p)
    h, seen_lo, seen_hi = _descend(knots, hint, p, window)
    dh = _distance(knots, h, p)
    if dh < e:
        best, dbest, lo, hi = _scan(knots, a, p, 2.0 * e, h, dh, seen_lo, seen_hi)
        if lo <= h <= hi:  # the hint's descent ended on a's part of the ball: its seed was fair
            return best
    return _scan(knots, a, p, 2.0 * e, a, e, a + 1, a)[0]  # (a + 1, a): no range seen, typed as the other call's


@njit(cache=True)
def nearest_knots(knots, anchors, points, window, hint):
    """Nearest knot to each of a sequence of tool positions (:func:`nearest_knot`), each hinted by the previous one.

    Parameters
    ----------
    knots : ndarray, shape (M, 4)
        Distinct reference samples [mm] with their length along the path (:func:`distinct`), M >= 1.
    anchors : ndarray of int, shape (K,)
        Knot of the commanded sample of each position.
    points : ndarray, shape (K, 3)
        Tool positions in time order [mm].
    window : int
        As in :func:`nearest_knot` [-].
    hint : int
        Hint of the first search: the last knot found for the positions
        before `points` (a trace searched block by block), else its anchor.

    Returns
    -------
    ndarray of int, shape (K,)
        Index of the nearest knot found for each position.
    """
    idx = np.empty(points.shape[0], np.int64)
    j = np.int64(hint)  # an int64 whatever the caller passes: numba compiles nearest_knot for one hint type
    for k in range(points.shape[0]):
        j = nearest_knot(knots, np.int64(anchors[k]), j, (points[k, 0], points[k, 1], points[k, 2]), window)
        idx[k] = j
    return idx
