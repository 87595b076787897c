"""Nearest reference sample to a moving tool position: the one windowed search of the package.

Both the exact contour error (:mod:`contoursim.contour`, which refines the
sample it finds on the continuous path) and the online estimators
(:mod:`contoursim.estimators`, which build their local curve around it) start
from the reference sample nearest to the actual tool position. The search

- runs over the *knots*, the reference samples with the repeats of a
  standstill removed (:func:`distinct`): at an exact stop the interpolator
  repeats the corner sample for many servo periods, and a window counted in
  samples would sit inside that run and never see the outgoing edge;
- starts at a *hint*, the knot found for the previous tool position, so it
  follows the branch being travelled where a closed curve comes back near its
  start or a figure-eight crosses itself, and the cost is linear in the length
  of the trace;
- never searches the whole path.
"""

import numpy as np
from ._numba import njit

__all__ = ["distinct", "moved", "nearest_knot", "nearest_knots"]

REACH = 2048  # most knots the search scans forward before walking on [-]


def distinct(points):
    """Drop consecutive duplicate points (a standstill of the reference).

    Parameters
    ----------
    points : ndarray, shape (N, 3)
        Reference samples in path order [mm], N >= 1, finite (checked by the caller).

    Returns
    -------
    knots : ndarray, shape (M, 3)
        The distinct samples in order [mm], C-contiguous.
    first_sample : ndarray of int, shape (M,)
        Index of the first sample of each knot.
    knot_of_sample : ndarray of int, shape (N,)
        Knot holding each sample.
    """
    keep = moved(points)
    return np.ascontiguousarray(points[keep]), np.flatnonzero(keep), np.cumsum(keep) - 1


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
def nearest_knot(knots, hint, p, window):
    """Index of the knot nearest to p, searched around `hint`.

    Scans `window` knots back from the hint, and forward at least `window`
    knots and on while the knots stay within d_hint + d_best of the hint (at
    most :data:`REACH` knots; no knot nearer to p than d_best lies outside
    that ball): at a concave corner, or wherever the tool cuts inside a sharp
    turn, the distance along the incoming segment has a local minimum of its
    own, and the outgoing segment is found across it. When the best knot lies
    on the edge of the scanned range the search walks on that way while the
    distance decreases. The cost is bounded by how far the foot point really
    moves and by the size of the error, and a branch of the path that comes
    back close to p far along the path (a closed curve's start, the other lobe
    of a figure-eight) is never reached by jumping.

    Parameters
    ----------
    knots : ndarray, shape (M, 3)
        Distinct reference samples [mm] (:func:`distinct`), M >= 1.
    hint : int
        Knot to start from: the one found for the previous tool position
        (0 at the start of the path); clipped to [0, M - 1].
    p : tuple of 3 float
        Tool position [mm].
    window : int
        Knots scanned either side of the hint before walking on [-], >= 1.

    Returns
    -------
    int
        Index of the nearest knot found.
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
    return best


@njit(cache=True)
def nearest_knots(knots, points, window, hint):
    """Nearest knot to each of a sequence of tool positions, each search hinted by the previous one.

    Parameters
    ----------
    knots : ndarray, shape (M, 3)
        Distinct reference samples [mm] (:func:`distinct`), M >= 1.
    points : ndarray, shape (K, 3)
        Tool positions in time order, starting near the knot `hint` [mm].
    window : int
        As in :func:`nearest_knot` [-].
    hint : int
        Knot to start the first search from: 0 at the path start, or the
        last knot found for the positions before `points` (a trace searched
        block by block).

    Returns
    -------
    ndarray of int, shape (K,)
        Index of the nearest knot found for each position.
    """
    idx = np.empty(points.shape[0], np.int64)
    j = np.int64(hint)  # an int64 whatever the caller passes: numba compiles nearest_knot for one hint type
    for k in range(points.shape[0]):
        j = nearest_knot(knots, j, (points[k, 0], points[k, 1], points[k, 2]), window)
        idx[k] = j
    return idx
