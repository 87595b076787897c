"""Contour error estimators: exact, linear (tangent), circular, three-point arc, cubic Newton.

The contour error of an actual tool position P_a is its shortest distance to the
reference path. The exact value (distance to the continuous path) needs the
path's geometry; a servo controller sees only the interpolator's samples, so it
estimates the error from the reference samples around the current position.

Every offline estimator returns a :class:`contoursim.contour.ContourError`,
the type of the exact result too, with ``foot`` and ``s`` left out (``None``)
and ``index`` and ``method`` saying where and how it was estimated:

- ``magnitude`` -- the estimated contour error [mm], >= 0;
- ``vector`` -- from the actual point to the estimated foot point on the path:
  the correction direction;
- ``normal`` -- the signed in-plane part, (P_a - foot) . (b x T), positive to the
  left of travel (b is the local plane normal, T the unit tangent);
- ``out_of_plane`` -- (P_a - foot) . b.

Two layers
----------
*Step functions* (``linear_step``, ``circular_step``, ``three_point_step``,
``newton_step``) are numba ``@njit`` functions over plain arrays, all with one
signature::

    estimate, index = step(knots, anchor, hint, actual, params)

``knots`` (M, 4) are the distinct reference samples with their chord length
(see :func:`distinct_samples`), ``anchor`` the knot of the commanded sample
(the reference point of the same servo step), ``hint`` the knot the previous
step returned (where the search starts; the result does not depend on it),
``actual`` (3,) the tool position, ``params`` a small float array built by :func:`search_params`
or :func:`circular_params`. ``estimate`` is a :class:`StepEstimate` named
tuple (magnitude, normal, out_of_plane, vx, vy, vz) and ``index`` the knot the
estimate is anchored to, to be passed back as the next step's hint. A
compensator inside the servo kernel calls them once per servo period.

*Offline functions* (:func:`linear`, :func:`circular`, :func:`three_point`,
:func:`newton`) run the same step functions over a whole trace in one compiled
loop; :func:`exact` delegates to :func:`contoursim.contour.exact_contour_error`.

Orientation of the local plane normal b
---------------------------------------
The estimators see only samples, so b is the normal of the local circle (the
osculating plane), turned so that ``b . up >= 0``; on straight stretches, where
the circle degenerates, b is ``up`` made perpendicular to the tangent. The
default ``up = (0, 0, 1)`` makes b = +z for every XY-planar path, as in
:mod:`contoursim.contour`. For a path in a tilted plane pass that plane's
normal as ``up``; on a helix b is the osculating binormal, tilted from the
helix axis by the helix angle, so ``normal``/``out_of_plane`` split the same
magnitude differently from the exact computation (which uses the axis).
"""

from collections import namedtuple

import numpy as np
from ._numba import njit

from . import _validate
from .contour import MAX_ACTUAL, ContourError, exact_contour_error
from .nearest import distinct, nearest_knot

__all__ = [
    "StepEstimate",
    "distinct_samples",
    "search_params",
    "circular_params",
    "linear_step",
    "circular_step",
    "three_point_step",
    "newton_step",
    "exact",
    "linear",
    "circular",
    "three_point",
    "newton",
]

StepEstimate = namedtuple("StepEstimate", "magnitude normal out_of_plane vx vy vz")
StepEstimate.__doc__ = """One sample of a :class:`~contoursim.contour.ContourError`, from a step function.

A tuple of scalars (the vector as vx, vy, vz), so that compiled code makes
and passes it without allocating.

Parameters
----------
magnitude : float
    Contour error [mm], >= 0.
normal : float
    Signed in-plane part, positive to the left of travel [mm].
out_of_plane : float
    Part along the local plane normal b [mm].
vx, vy, vz : float
    Vector from the actual point to the foot point [mm].
"""

_LINEAR, _CIRCULAR, _THREE_POINT, _NEWTON = 0, 1, 2, 3
_STRAIGHT = 1e-10  # |a x b| <= _STRAIGHT |a||b|: the three points are collinear [rad]


# --------------------------------------------------------------------------
# 3-vector helpers on tuples (no allocation inside the compiled loops); compiled once each and inlined by LLVM:
# inlined into numba's IR (inline="always") at every call, they would be typed and compiled again each time


@njit(cache=True, inline="always")  # inlined: compiled as a function, it would be compiled per literal row
def _row(a, i):
    return (a[i, 0], a[i, 1], a[i, 2])


@njit(cache=True)
def _sub(a, b):
    return (a[0] - b[0], a[1] - b[1], a[2] - b[2])


@njit(cache=True)
def _axpy(s, x, y):
    return (s * x[0] + y[0], s * x[1] + y[1], s * x[2] + y[2])


@njit(cache=True)
def _scale(s, a):
    return (s * a[0], s * a[1], s * a[2])


@njit(cache=True)
def _dot(a, b):
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


@njit(cache=True)
def _cross(a, b):
    return (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])


@njit(cache=True)
def _norm(a):
    return np.sqrt(_dot(a, a))


@njit(cache=True)
def _unit(a, fallback):
    n = _norm(a)
    if n > 0.0:
        return (a[0] / n, a[1] / n, a[2] / n)
    return fallback


@njit(cache=True)
def _perpendicular(t):
    """A unit vector perpendicular to the unit vector t."""
    ax = (1.0, 0.0, 0.0) if abs(t[0]) < 0.9 else (0.0, 1.0, 0.0)
    return _unit(_axpy(-_dot(ax, t), t, ax), (0.0, 0.0, 1.0))


@njit(cache=True)
def _binormal(t, x, straight, up):
    """Unit plane normal b perpendicular to the unit tangent t, with b . up >= 0.

    b is along x (the normal of the local circle) unless the path is straight
    there; then it is `up` made perpendicular to t.
    """
    if straight:
        b = _axpy(-_dot(up, t), t, up)
        nb = _norm(b)
        b = _perpendicular(t) if nb <= 1e-12 else (b[0] / nb, b[1] / nb, b[2] / nb)
    else:
        b = _unit(x, (0.0, 0.0, 1.0))
    if _dot(b, up) < 0.0:
        b = (-b[0], -b[1], -b[2])
    return b


@njit(cache=True)
def _arc_parts(anchor, t, b, kappa, p):
    """Signed in-plane distance, out-of-plane distance and in-plane unit normal at the foot.

    Distance from p to the circle through `anchor` with tangent t, plane
    normal b; kappa [1/mm] is the curvature signed about b (> 0: centre to
    the left of travel, on the side of b x t); kappa = 0 is the straight line.
    With d = in-plane offset of p from the anchor and l = b x t, the signed
    in-plane distance r - L (L = |O - P'|, O = anchor + l / kappa) is written as

        normal = (2 d.l - kappa |d|^2) / (1 + |l - kappa d|),

    which is r - L multiplied out so that it stays exact as kappa -> 0 (no
    cancellation between two large radii, no threshold between arc and line).
    The foot point lies along lf = (l - kappa d) / |l - kappa d|, the in-plane
    normal at the foot; p = foot + normal·lf + h·b.

    Returns
    -------
    normal, h : float
        [mm]
    lf : tuple of 3 floats
        Unit in-plane normal at the foot, pointing to the left of travel [-].
    """
    e = _sub(p, anchor)
    h = _dot(e, b)
    d = _axpy(-h, b, e)
    left = _cross(b, t)
    q = _axpy(-kappa, d, left)
    nq = _norm(q)
    normal = (2.0 * _dot(d, left) - kappa * _dot(d, d)) / (1.0 + nq)
    lf = _scale(1.0 / nq, q) if nq > 0.0 else left
    return normal, h, lf


@njit(cache=True)
def _arc_estimate(anchor, t, b, kappa, p):
    """Distance from p to the circle through `anchor` with tangent t, plane normal b (see ``_arc_parts``)."""
    normal, h, lf = _arc_parts(anchor, t, b, kappa, p)
    return StepEstimate(
        np.sqrt(normal * normal + h * h),
        normal,
        h,
        -(normal * lf[0] + h * b[0]),
        -(normal * lf[1] + h * b[1]),
        -(normal * lf[2] + h * b[2]),
    )


@njit(cache=True)
def _point_estimate(anchor, p, up):
    """Distance from p to a single point (a reference that never moves)."""
    e = _sub(p, anchor)
    h = _dot(e, up)
    return StepEstimate(_norm(e), _norm(_axpy(-h, up, e)), h, -e[0], -e[1], -e[2])


@njit(cache=True)
def _cubic(tau, p0, a1, a2, a3):
    """Position, first and second derivative of p0 + a1 tau + a2 tau^2 + a3 tau^3."""
    pos = _axpy(tau, _axpy(tau, _axpy(tau, a3, a2), a1), p0)
    d1 = _axpy(tau, _axpy(3.0 * tau, a3, _scale(2.0, a2)), a1)
    dd = _axpy(6.0 * tau, a3, _scale(2.0, a2))
    return pos, d1, dd


@njit(cache=True)
def _up(params):
    return (params[0], params[1], params[2])


# --------------------------------------------------------------------------
# step functions


@njit(cache=True)
def linear_step(knots, anchor, hint, actual, params):
    """Linear (tangent) estimate: the tracking error's component normal to the path.

    Koren's classic estimate behind cross-coupled control: with the tracking
    error e = P_a - P_r (actual minus the commanded sample) and the reference
    tangent T, the estimate is e minus its component along T. In the plane,
    normal = -e_x sin(theta) + e_y cos(theta). T is the direction of the
    central difference of the knots around P_r.

    Parameters
    ----------
    knots : ndarray, shape (M, 4)
        Distinct reference samples [mm] (:func:`distinct_samples`).
    anchor : int
        Knot of the commanded sample P_r (``knot_of_sample[k]`` from
        :func:`distinct_samples` at servo step k).
    hint : int
        Not used.
    actual : ndarray, shape (3,)
        Actual tool position [mm].
    params : ndarray, shape (4,)
        From :func:`search_params` (only ``up`` is used).

    Returns
    -------
    estimate : StepEstimate
    index : int
        `anchor`, clipped to the knots.
    """
    m = knots.shape[0]
    up = _up(params)
    p = (actual[0], actual[1], actual[2])
    j = min(max(anchor, 0), m - 1)
    if m == 1:
        return _point_estimate(_row(knots, j), p, up), j
    anchor, t, b, kappa = _linear_arc(knots, j, up)
    return _arc_estimate(anchor, t, b, kappa, p), j


@njit(cache=True)
def _linear_arc(knots, j, up):
    """``(anchor, t, b, kappa)`` of the linear estimate at knot j (of M >= 2): the tangent line there."""
    m = knots.shape[0]
    pj = _row(knots, j)
    a = _sub(pj, _row(knots, max(j - 1, 0)))
    c = _sub(_row(knots, min(j + 1, m - 1)), pj)
    chord = _axpy(1.0, a, c)
    nc = _norm(chord)
    t = _scale(1.0 / nc, chord) if nc > 0.0 else _unit(a, (1.0, 0.0, 0.0))  # a cusp: incoming direction
    x = _cross(a, c)
    straight = _dot(x, x) <= _STRAIGHT**2 * _dot(a, a) * _dot(c, c)
    return pj, t, _binormal(t, x, straight, up), 0.0


@njit(cache=True)
def circular_step(knots, anchor, hint, actual, params):
    """Circular estimate: radial deviation from a circle of known centre.

    With h the offset of P_a along the circle's axis and L its distance from
    the axis, normal = R - L for travel counter-clockwise about the axis
    (L - R clockwise), out_of_plane = h, magnitude = sqrt((L - R)^2 + h^2).

    Parameters
    ----------
    knots : ndarray, shape (M, 4)
        Not used (the circle is given by `params`); any array, e.g. ``np.empty((0, 4))``.
    anchor : int
        Not used.
    hint : int
        Not used; returned unchanged.
    actual : ndarray, shape (3,)
        Actual tool position [mm].
    params : ndarray, shape (8,)
        From :func:`circular_params`: centre [mm], unit axis, radius [mm],
        +1 (counter-clockwise about the axis) or -1.

    Returns
    -------
    estimate : StepEstimate
    index : int
        `hint`, unchanged.
    """
    c = (params[0], params[1], params[2])
    n = (params[3], params[4], params[5])
    radius, turn = params[6], params[7]
    p = (actual[0], actual[1], actual[2])
    e = _sub(p, c)
    q = _axpy(-_dot(e, n), n, e)
    nq = _norm(q)
    u = _perpendicular(n) if nq == 0.0 else _scale(1.0 / nq, q)  # on the axis every foot is as near
    anchor = _axpy(radius, u, c)
    t = _cross(n, u)
    t = _scale(turn, t)
    return _arc_estimate(anchor, t, n, turn / radius, p), hint


@njit(cache=True)
def three_point_step(knots, anchor, hint, actual, params):
    """Three-point circumscribed-arc estimate with out-of-plane projection.

    The method of DOMAIN.md section 3 (seed 003): find the knot P_n nearest to
    P_a on the stretch of the path around the commanded knot
    (:func:`contoursim.nearest.nearest_knot`: never farther than it); take the circle through
    P_{n-1}, P_n, P_{n+1} (centre O, radius r, plane normal b); project P_a
    onto the circle's plane (P_a'), h = |P_a - P_a'|, L = |O - P_a'|; the estimate is
    sqrt((L - r)^2 + h^2), reported as its in-plane part (``normal``, r - L when
    the centre is to the left of travel) and its out-of-plane part h.
    Collinear knots give the line through them (r -> infinity, continuously:
    see ``_arc_estimate``).

    The circle is built from the edge vectors a = P_n - P_{n-1}, c = P_{n+1} - P_n:
    with X = a x c and W = |a|^2 c + |c|^2 a, the tangent at P_n is W / |W|, the
    centre is P_n + (X x W) / (2 |X|^2) and the curvature 1 / r = 2 |X| / |W|.

    Parameters
    ----------
    knots : ndarray, shape (M, 4)
        Distinct reference samples [mm] with their chord length (:func:`distinct_samples`).
    anchor : int
        Knot of the commanded sample (``knot_of_sample[k]`` at servo step k).
    hint : int
        Where the search starts: the index this function returned at the
        previous step (the anchor at the first); speed only.
    actual : ndarray, shape (3,)
        Actual tool position [mm].
    params : ndarray, shape (4,)
        From :func:`search_params`: ``up`` (3,) and the search window [knots].

    Returns
    -------
    estimate : StepEstimate
    index : int
        The nearest knot, P_n.
    """
    m = knots.shape[0]
    up = _up(params)
    p = (actual[0], actual[1], actual[2])
    n = nearest_knot(knots, anchor, hint, p, int(params[3]))
    if m == 1:
        return _point_estimate(_row(knots, 0), p, up), n
    anchor, t, b, kappa = _three_point_arc(knots, n, up)
    return _arc_estimate(anchor, t, b, kappa, p), n


@njit(cache=True)
def _three_point_arc(knots, n, up):
    """``(anchor, t, b, kappa)`` of the circle through the knots n-1, n, n+1 (of M >= 2), see :func:`three_point_step`."""
    m = knots.shape[0]
    if m == 2:
        t = _unit(_sub(_row(knots, 1), _row(knots, 0)), (1.0, 0.0, 0.0))
        # np.bool_(True), not the literal True: numba would compile _binormal for it besides bool
        return _row(knots, n), t, _binormal(t, t, np.bool_(True), up), 0.0
    i = min(max(n, 1), m - 2)
    pn = _row(knots, i)
    a = _sub(pn, _row(knots, i - 1))
    c = _sub(_row(knots, i + 1), pn)
    aa, cc = _dot(a, a), _dot(c, c)
    w = (aa * c[0] + cc * a[0], aa * c[1] + cc * a[1], aa * c[2] + cc * a[2])
    ww = _dot(w, w)
    x = _cross(a, c)
    if ww <= 1e-24 * aa * cc * (aa + cc):
        # a cusp: P_{n+1} = P_{n-1}, the path reverses at P_n; use the incoming line
        t = _unit(a, (1.0, 0.0, 0.0))
        return pn, t, _binormal(t, x, np.bool_(True), up), 0.0
    nw = np.sqrt(ww)
    t = _scale(1.0 / nw, w)
    straight = _dot(x, x) <= _STRAIGHT**2 * aa * cc
    b = _binormal(t, x, straight, up)
    return pn, t, b, 2.0 * _dot(x, b) / nw


@njit(cache=True)
def newton_step(knots, anchor, hint, actual, params):
    """Foot point by Newton's method on a local cubic through four knots.

    The accuracy ceiling of the online family. The reference around the
    nearest knot is replaced by the cubic C(tau) interpolating the four knots
    around the segment that holds the foot, parameterised by cumulative chord
    length, which keeps it fourth-order accurate in the sample spacing (as for
    chordal cubic splines: Floater, "Chordal cubic spline interpolation is
    fourth order accurate", IMA J. Numer. Anal. 26, 2006). The foot
    parameter solves (C(tau) - P_a) . C'(tau) = 0 by Newton's method from the
    projection onto the chord -- the second-order (Taylor) foot-point
    refinement of Zhu, Zhao and Ding, "Real-time contouring error estimation for
    multi-axis motion systems using the second-order approximation", Int. J.
    Machine Tools and Manufacture 68 (2013), applied to the sampled reference
    instead of the parametric curve. The estimate is then taken against the
    osculating circle of the cubic at the foot.

    Fewer than four knots fall back to :func:`three_point_step`.

    Parameters
    ----------
    knots : ndarray, shape (M, 4)
        Distinct reference samples [mm] with their chord length (:func:`distinct_samples`).
    anchor : int
        Knot of the commanded sample (``knot_of_sample[k]`` at servo step k).
    hint : int
        Where the search starts: the index this function returned at the
        previous step (the anchor at the first); speed only.
    actual : ndarray, shape (3,)
        Actual tool position [mm].
    params : ndarray, shape (4,)
        From :func:`search_params`: ``up`` (3,) and the search window [knots].

    Returns
    -------
    estimate : StepEstimate
    index : int
        The nearest knot.
    """
    m = knots.shape[0]
    if m < 4:
        return three_point_step(knots, anchor, hint, actual, params)
    up = _up(params)
    p = (actual[0], actual[1], actual[2])
    n = nearest_knot(knots, anchor, hint, p, int(params[3]))
    # the segment [i, i+1] holding the foot, and its neighbours i-1 and i+2
    ahead = _dot(_sub(p, _row(knots, n)), _sub(_row(knots, min(n + 1, m - 1)), _row(knots, max(n - 1, 0))))
    i = min(max(n if ahead >= 0.0 else n - 1, 1), m - 3)
    p0, p1, pm, p2 = _row(knots, i), _row(knots, i + 1), _row(knots, i - 1), _row(knots, i + 2)
    x1 = _norm(_sub(p1, p0))
    x2 = -_norm(_sub(p0, pm))
    x3 = x1 + _norm(_sub(p2, p1))
    # Newton divided differences on the nodes 0, x1, x2, x3, then monomials in tau
    c1 = _scale(1.0 / x1, _sub(p1, p0))
    d12 = _scale(1.0 / (x2 - x1), _sub(pm, p1))
    c2 = _scale(1.0 / x2, _sub(d12, c1))
    d23 = _scale(1.0 / (x3 - x2), _sub(p2, pm))
    d123 = _scale(1.0 / (x3 - x1), _sub(d23, d12))
    a3 = _scale(1.0 / x3, _sub(d123, c2))
    a2 = _axpy(-(x1 + x2), a3, c2)
    a1 = _axpy(x1 * x2, a3, _axpy(-x1, c2, c1))
    tau = min(max(_dot(_sub(p, p0), c1), x2), x3)
    for _ in range(8):
        pos, d1, dd = _cubic(tau, p0, a1, a2, a3)
        r = _sub(pos, p)
        slope = _dot(d1, d1) + _dot(r, dd)
        if slope <= 0.0:  # beyond the centre of curvature: Gauss-Newton step
            slope = _dot(d1, d1)
        step = _dot(r, d1) / slope
        new = min(max(tau - step, x2), x3)
        converged = abs(new - tau) <= 1e-8 * (x3 - x2)  # the next step would be ~1e-16 of it
        tau = new
        if converged:
            break
    foot, d1, dd = _cubic(tau, p0, a1, a2, a3)
    speed = _norm(d1)
    t = _unit(d1, c1)
    x = _cross(d1, dd)
    straight = _norm(x) <= _STRAIGHT * speed * _norm(dd) or speed == 0.0
    b = _binormal(t, x, straight, up)
    kappa = 0.0 if speed == 0.0 else _dot(x, b) / speed**3
    return _arc_estimate(foot, t, b, kappa, p), n


# --------------------------------------------------------------------------
# offline: the step functions in one compiled loop


@njit(cache=True)
def _trace(method, knots, anchors, actual, params, out, index):
    """Run one step function over every actual point, anchored at its commanded knot, hinted by the step before."""
    idx = anchors[0]
    for k in range(actual.shape[0]):
        p = actual[k]
        if method == _LINEAR:
            est, idx = linear_step(knots, anchors[k], idx, p, params)
        elif method == _CIRCULAR:
            est, idx = circular_step(knots, anchors[k], idx, p, params)
        elif method == _THREE_POINT:
            est, idx = three_point_step(knots, anchors[k], idx, p, params)
        else:
            est, idx = newton_step(knots, anchors[k], idx, p, params)
        out[k, 0] = est.magnitude
        out[k, 1] = est.normal
        out[k, 2] = est.out_of_plane
        out[k, 3] = est.vx
        out[k, 4] = est.vy
        out[k, 5] = est.vz
        index[k] = idx


def distinct_samples(reference):
    """Drop consecutive duplicate samples (standstill) from a reference.

    Parameters
    ----------
    reference : array_like, shape (N, d)
        Reference samples [mm], d = 2 or 3.

    Returns
    -------
    knots : ndarray, shape (M, 4)
        The distinct samples in order, z = 0 added for d = 2 [mm], and their
        cumulative chord length [mm] (:func:`contoursim.nearest.distinct`).
    first_sample : ndarray of int, shape (M,)
        Index of the first reference sample of each knot.
    knot_of_sample : ndarray of int, shape (N,)
        Knot holding each reference sample (the hint for :func:`linear_step`).
    """
    return distinct(np.ascontiguousarray(_validate.as_xyz(_points("reference", reference))))


def search_params(up=(0.0, 0.0, 1.0), window=4):
    """Parameters of the linear, three-point and Newton step functions.

    Parameters
    ----------
    up : array_like, shape (3,)
        Direction that orients the local plane normal b (b . up >= 0) and
        gives b on straight stretches [-]; default +z.
    window : int
        Knots searched either side of the hint before walking on [-].

    Returns
    -------
    params : ndarray, shape (4,)
        ``up`` normalised, then ``window``.
    """
    up = _validate.finite_array("up", up, shape=(3,))
    norm = float(np.linalg.norm(up))
    if norm == 0.0:
        raise ValueError("up must be a nonzero direction, got (0, 0, 0)")
    window = _validate.positive_int("window", window)
    return np.append(up / norm, float(window))


def circular_params(center, radius, normal=(0.0, 0.0, 1.0), direction="ccw"):
    """Parameters of :func:`circular_step`.

    Parameters
    ----------
    center : array_like, shape (2,) or (3,)
        Circle centre [mm].
    radius : float
        Nominal radius [mm].
    normal : array_like, shape (3,)
        Axis of the circle (its plane normal); the in-plane part is signed
        about it [-].
    direction : {"ccw", "cw"}
        Direction of travel about `normal`.

    Returns
    -------
    params : ndarray, shape (8,)
    """
    center = _validate.finite_array("center", center, ndim=1, limit=MAX_ACTUAL)
    if center.size not in (2, 3):
        raise ValueError(f"center must have 2 or 3 coordinates, got {center.size}")
    radius = _validate.positive("radius", radius)
    normal = _validate.finite_array("normal", normal, shape=(3,))
    norm = float(np.linalg.norm(normal))
    if norm == 0.0:
        raise ValueError("normal must be a nonzero direction, got (0, 0, 0)")
    if direction not in ("ccw", "cw"):
        raise ValueError(f'direction must be "ccw" or "cw", got {direction!r}')
    turn = 1.0 if direction == "ccw" else -1.0
    return np.concatenate([np.append(center, 0.0)[:3], normal / norm, [radius, turn]])


# --------------------------------------------------------------------------
# offline estimators


def exact(trajectory, actual):
    """Exact contour error: distance to the continuous reference path.

    Delegates to :func:`contoursim.contour.exact_contour_error`; the yardstick
    for the estimators.

    Parameters
    ----------
    trajectory : contoursim.Trajectory
        Reference with its ``path``.
    actual : array_like, shape (N, d)
        Actual tool positions [mm].

    Returns
    -------
    contoursim.contour.ContourError
        With ``foot`` and ``s``, ``method="exact"``.
    """
    return exact_contour_error(trajectory, actual)


def linear(reference, actual, up=(0.0, 0.0, 1.0)):
    """Linear (tangent) estimate over a trace (Koren); see :func:`linear_step`.

    Parameters
    ----------
    reference : array_like, shape (N, d)
        Commanded positions at the servo period [mm].
    actual : array_like, shape (N, d)
        Actual tool positions at the same instants [mm].
    up : array_like, shape (3,)
        Orients the local plane normal (:func:`search_params`).

    Returns
    -------
    contoursim.contour.ContourError
        ``index`` is the commanded sample k itself.
    """
    ref = _points("reference", reference)
    act = _points("actual", actual, like=ref)
    if len(act) != len(ref):
        raise ValueError(f"actual must have one row per reference sample ({len(ref)}), got {len(act)}")
    knots, first, knot_of = distinct_samples(ref)
    out, idx = _run(_LINEAR, knots, knot_of, act, search_params(up))
    return _result(out, first[idx], act.shape[1], "linear")


def circular(actual, center, radius, normal=(0.0, 0.0, 1.0), direction="ccw"):
    """Circular estimate over a trace: radial deviation from a known circle.

    Parameters
    ----------
    actual : array_like, shape (N, d)
        Actual tool positions [mm].
    center, radius, normal, direction
        The circle, as in :func:`circular_params`; `center` of shape (d,).

    Returns
    -------
    contoursim.contour.ContourError
        For travel counter-clockwise about `normal`, ``normal`` = R - |P - c|
        in the plane.
    """
    act = _points("actual", actual)
    params = circular_params(center, radius, normal, direction)
    if np.shape(center) != act.shape[1:]:  # the missing coordinate would be 0: an offset added to every magnitude
        raise ValueError(f"center has shape {np.shape(center)} but actual has shape {act.shape}: give the centre in the "
                         f"{act.shape[1]} coordinates of the points")
    out, _ = _run(_CIRCULAR, np.empty((0, 4)), np.zeros(len(act), np.int64), act, params)
    return _result(out, None, act.shape[1], "circular")


def three_point(reference, actual, up=(0.0, 0.0, 1.0), window=4, at=None):
    """Three-point circumscribed-arc estimate over a trace; see :func:`three_point_step`.

    Parameters
    ----------
    reference : array_like, shape (N, d)
        Commanded positions at the servo period [mm]; duplicates (standstill) allowed.
    actual : array_like, shape (K, d)
        Actual tool positions in time order [mm].
    up : array_like, shape (3,)
        Orients the local plane normal (:func:`search_params`).
    window : int
        Knots the search's descent from the previous step scans either side (:func:`search_params`; speed only).
    at : array_like of int, shape (K,), optional
        The reference sample commanded when each actual point was taken
        (the search's anchor, :func:`contoursim.nearest.nearest_knot`);
        default sample k for point k, `actual` then having one row per
        reference sample.

    Returns
    -------
    contoursim.contour.ContourError
        ``index`` is the nearest reference sample found for each actual point.
    """
    return _searching(_THREE_POINT, "three_point", reference, actual, up, window, at)


def newton(reference, actual, up=(0.0, 0.0, 1.0), window=4, at=None):
    """Cubic Newton foot-point estimate over a trace; see :func:`newton_step`.

    Parameters
    ----------
    reference : array_like, shape (N, d)
        Commanded positions at the servo period [mm]; duplicates (standstill) allowed.
    actual : array_like, shape (K, d)
        Actual tool positions in time order [mm].
    up : array_like, shape (3,)
        Orients the local plane normal (:func:`search_params`).
    window : int
        Knots the search's descent from the previous step scans either side (:func:`search_params`; speed only).
    at : array_like of int, shape (K,), optional
        The reference sample commanded when each actual point was taken
        (the search's anchor, :func:`contoursim.nearest.nearest_knot`);
        default sample k for point k, `actual` then having one row per
        reference sample.

    Returns
    -------
    contoursim.contour.ContourError
        ``index`` is the nearest reference sample found for each actual point.
    """
    return _searching(_NEWTON, "newton", reference, actual, up, window, at)


def _searching(method, name, reference, actual, up, window, at):
    ref = _points("reference", reference)
    act = _points("actual", actual, like=ref)
    params = search_params(up, window)
    knots, first, knot_of = distinct_samples(ref)
    at = _validate.commanded(at, len(act), len(ref))
    out, idx = _run(method, knots, knot_of if at is None else knot_of[at], act, params)
    return _result(out, first[idx], act.shape[1], name)


def _run(method, knots, anchors, actual, params):
    out = np.empty((len(actual), 6))
    index = np.empty(len(actual), np.int64)
    _trace(method, knots, anchors.astype(np.int64), np.ascontiguousarray(_validate.as_xyz(actual)), params, out, index)
    return out, index


def _result(out, index, dim, method):
    return ContourError(out[:, 0], out[:, 3 : 3 + dim], out[:, 1], out[:, 2], index=index, method=method)


def _points(name, value, like=None):
    pts = _validate.finite_array(name, value, ndim=2, limit=MAX_ACTUAL)
    if pts.shape[1] not in (2, 3) or len(pts) == 0:
        raise ValueError(f"{name} must have shape (N, 2) or (N, 3) with N >= 1, got {pts.shape}")
    if like is not None and pts.shape[1] != like.shape[1]:
        raise ValueError(f"{name} must have {like.shape[1]} columns like the reference, got {pts.shape[1]}")
    return pts
