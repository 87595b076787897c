"""Exact contour error: distance from actual tool positions to the continuous reference path.

For each actual point P, taken when the reference was at sample R:

1. the package's nearest-sample search (:func:`contoursim.nearest.nearest_knot`)
   over the distinct reference samples (the repeats of a standstill removed)
   on the part of the path connected to R inside the ball of radius 2|P - R|
   about R (a stretch outside it no longer than its radius connecting):
   every path point nearer to P than R lies there, so the contour
   error is never larger than the tracking error |P - R|, wherever the path
   turns back on itself, and a branch that only comes near P elsewhere (a
   figure-eight's crossing) is not taken;
2. refinement on the primitives spanned by that sample's two neighbours:
   closed form on lines and plain arcs, Newton's method on the arc length of
   helices and on the parameter of spline pieces, never farther than the
   sample itself; then on every stretch between two samples of R's part of
   the ball that may hold a nearer point (another branch at a corner or a
   zig-zag, whose samples straddle its foot while a sample of the first
   branch is nearer: up to half a sample spacing nearer); when the foot
   point is clamped at a primitive end, the neighbouring primitive is tried.

A closed path sampled from its start round to it (a contour whose program ends
where it began) is a loop: R's part of the ball, walked in step 2, goes on
across the seam, so that where the program starts does not change the error
(the first step's search stops at the seam; the walk from its sample does not).
On a square whose seam was a corner, a tool 0.05 mm beside the last side and
0.4 mm before the seam, the commanded point 0.5 mm past it, had 0.4 mm, the
distance to the seam, and 0.05 mm with the seam moved.

The result is independent of the order of the points, and of the sample
spacing (the samples only seed the search) but where the path leaves the ball
for about its radius of length: whether such a stretch connects is judged on
the samples, the last one inside before it and the last one outside, within a
sample spacing of its ends (at a narrow 3-D corner sampled every 0.049 mm a
branch 0.056 mm away was not taken and 0.253 mm reported, the distance on R's
side; every 0.02 mm it was taken).
"""

import math
from dataclasses import dataclass

import numpy as np
from ._numba import njit

from . import _validate
from ._blocks import blocks
from .nearest import _along, _beyond, _real, moved, nearest_knots
from .paths import ARC, LINE, _eval_prim, _eval_spline_w, _primitive_at, _spline_u_of_w, _spline_w_of_u
from .trajectory import Trajectory

__all__ = ["ContourError", "exact_contour_error"]

#: Largest |coordinate| of an actual tool position [mm] the contour error is taken of (a thousand km; paths, traces and
#: axis travels lie within ±1e6 mm): a point of 1e300 made the error's squares overflow, said of ``magnitude``.
MAX_ACTUAL = 1e9


class _Correction:
    """The `vector` field of :class:`ContourError`: the array given, or ``foot - actual`` when ``None`` was given.

    A data descriptor: the dataclass's ``__init__`` stores the value given
    through it; its class access raises AttributeError, so the field has no
    default and stays a required argument.
    """

    def __get__(self, error, owner=None):
        if error is None:
            raise AttributeError("vector")
        vector = error.__dict__["_vector"]
        if vector is None:  # the correction the refinement found, -(actual - foot), to the sign of a zero
            vector = error.foot - error.actual
            vector.flags.writeable = False
        return vector

    def __set__(self, error, value):
        error.__dict__["_vector"] = value


@dataclass(frozen=True)
class ContourError:
    """Contour error of N actual points against a reference path: exact, or estimated from samples.

    The one result type of :func:`exact_contour_error` and of every offline
    estimator in :mod:`contoursim.estimators` (whose step functions return
    one sample of it as a :class:`~contoursim.estimators.StepEstimate` tuple).

    Parameters
    ----------
    magnitude : ndarray, shape (N,)
        Distance to the path [mm], >= 0.
    vector : ndarray, shape (N, d), or None
        From the actual point to its (estimated) foot point on the path: the
        correction [mm]; d is 2 or 3. ``None`` when `foot` and `actual` are
        given: it is then ``foot - actual``, made on each access and not
        stored (an exact result's, 8·d bytes a point less).
    normal : ndarray, shape (N,)
        Signed in-plane component (P_a - foot) . n_left [mm], n_left = b x T
        normalised: positive to the left of the direction of travel, so a CCW
        circle gives R - |P_a - c|.
    out_of_plane : ndarray, shape (N,)
        Component (P_a - foot) . b [mm] along the path's plane normal b (for
        helices and 3-D curves, b made orthogonal to T, so that
        normal^2 + out_of_plane^2 = magnitude^2 wherever the foot is not a
        path end or a corner); zero for planar paths and estimates (a 2-D
        exact result holds one zero, read-only, broadcast to shape (N,)).
        At a corner, T, n_left and b are those of the side the point is
        closest to square to (the smaller |(P_a - foot) . T|).
    foot : ndarray, shape (N, d), optional
        Nearest path points [mm]. Exact only (``None`` for estimates).
    s : ndarray, shape (N,), optional
        Arc length of the foot points [mm]. Exact only.
    index : ndarray of int, shape (N,), optional
        The reference sample each estimate is anchored to: the nearest sample
        found by the windowed search (three-point, Newton) or the commanded
        sample (linear). ``None`` for the exact and circular results.
    method : str
        What produced it: ``"exact"``, ``"linear"``, ``"circular"``,
        ``"three_point"`` or ``"newton"``.
    actual : ndarray, shape (N, d), optional
        The actual points [mm]. Exact only (:func:`exact_contour_error`
        keeps them, without a copy when they are read-only, as a
        simulation's tool positions are).
    """

    magnitude: np.ndarray
    vector: np.ndarray = _Correction()  # a required field, stored through the descriptor
    normal: np.ndarray
    out_of_plane: np.ndarray
    foot: np.ndarray = None
    s: np.ndarray = None
    index: np.ndarray = None
    method: str = "exact"
    actual: np.ndarray = None

    def __post_init__(self):
        magnitude = _validate.finite_array("magnitude", self.magnitude, ndim=1)
        n = magnitude.size
        values = dict(magnitude=magnitude)
        given = self.__dict__["_vector"]
        if given is None and (self.foot is None or self.actual is None):
            raise ValueError("vector may be None only when foot and actual are given (it is foot - actual then)")
        if given is not None:
            values["vector"] = _validate.finite_array("vector", given, ndim=2)
        shape = (values["vector"] if given is not None else _validate.float_array("actual", self.actual, ndim=2)).shape
        if shape[0] != n or shape[1] not in (2, 3):
            raise ValueError(f"{'vector' if given is not None else 'actual'} must have shape ({n}, 2) or ({n}, 3), "
                             f"got {shape}")
        shapes = dict(normal=(n,), out_of_plane=(n,), foot=(n, shape[1]), s=(n,), actual=(n, shape[1]))
        for name, shape in shapes.items():
            if getattr(self, name) is not None or name in ("normal", "out_of_plane"):
                values[name] = _validate.finite_array(name, getattr(self, name), shape=shape)
        if self.index is not None:
            index = np.asarray(self.index)
            if index.shape != (n,) or index.dtype.kind not in "iu":
                raise TypeError(f"index must be an integer array of shape ({n},), got {index.dtype} {index.shape}")
            values["index"] = index
        if np.any(magnitude < 0):
            raise ValueError("magnitude must be non-negative")
        if not isinstance(self.method, str):
            raise TypeError(f"method must be a string, got {type(self.method).__name__}")
        for name, value in values.items():
            value.flags.writeable = False
            object.__setattr__(self, name, value)

    def __len__(self):
        return self.magnitude.size


# --------------------------------------------------------------------------- compiled refinement

@njit(cache=True)
def _closest(kind, row, p, u0, length, out):
    """Arc length of the point of one primitive nearest to p, from the guess u0; fills out (9,) there."""
    if kind == LINE:
        u = (p[0] - row[0]) * row[3] + (p[1] - row[1]) * row[4] + (p[2] - row[2]) * row[5]
        u = min(max(u, 0.0), length)
    elif kind == ARC and row[15] == 0.0:
        x = y = 0.0
        for i in range(3):
            x += (p[i] - row[i]) * row[3 + i]
            y += (p[i] - row[i]) * row[6 + i]
        u = u0
        if x * x + y * y > 1e-24:
            radius, sweep = row[12], abs(row[14])
            sgn = 1.0 if row[14] >= 0.0 else -1.0
            turned = (sgn * (math.atan2(y, x) - row[13])) % (2 * math.pi)
            # downhill from the guess: the distance falls towards the angle of p's foot within half a turn, so
            # the image of it nearest the guess, clamped to the arc (the end that way). Another image, or the
            # other end, lies past the farthest point from p: a part of the arc the search's ball may not hold.
            m = math.floor((u0 / radius - turned) / (2 * math.pi) + 0.5)
            u = min(max(turned + 2 * math.pi * m, 0.0), sweep) * radius
    elif kind == ARC:
        u = u0
        for _ in range(50):
            _eval_prim(kind, row, u, out)
            f = fp = 0.0
            for i in range(3):
                r = out[i] - p[i]
                f += r * out[3 + i]
                fp += r * out[6 + i]
            fp = 1.0 + fp if 1.0 + fp > 0.1 else 1.0
            un = min(max(u - f / fp, 0.0), length)
            if abs(un - u) < 1e-13:
                u = un
                break
            u = un
    else:
        # seed at u0's own parameter (the table's linear guess near a tight turn could lie on the turn's other leg,
        # and Newton stay there); the distance Newton below does the rest
        w = _spline_w_of_u(row, u0)
        for _ in range(50):
            g = gp = speed2 = 0.0
            for i in range(3):
                c = row[i] + w * (row[3 + i] + w * (row[6 + i] + w * row[9 + i])) - p[i]
                d1 = row[3 + i] + 2.0 * row[6 + i] * w + 3.0 * row[9 + i] * w * w
                d2 = 2.0 * row[6 + i] + 6.0 * row[9 + i] * w
                g += c * d1
                speed2 += d1 * d1
                gp += d1 * d1 + c * d2
            newton = gp >= 0.1 * speed2  # else Gauss-Newton: linear convergence
            wn = min(max(w - g / (gp if newton else speed2), 0.0), 1.0)
            # a Newton step leaves an error of the order of its square: below rounding once the step is 1e-10
            if abs(wn - w) <= (1e-10 if newton else 1e-15):
                w = wn
                break
            w = wn
        _eval_spline_w(row, w, out)
        return min(_spline_u_of_w(row, w), length)
    _eval_prim(kind, row, u, out)
    return u


@njit(cache=True)
def _refine(kinds, rows, breaks, p, s_lo, s_hi, s0, best_d, best_k, best_u, out, frame):
    """Try the primitives spanning arc lengths [s_lo, s_hi] for a foot point nearer to p than the best one.

    Each from the guess s0 (clamped to it) [mm]. ``best_d, best_k, best_u``:
    the best foot so far (squared distance [mm^2], its primitive, -1 for
    none, and its arc length on it [mm]); returned, updated, with `frame`
    filled at it (`out`: scratch).
    """
    for k in range(_primitive_at(breaks, s_lo), _primitive_at(breaks, s_hi) + 1):
        length = breaks[k + 1] - breaks[k]
        u = _closest(kinds[k], rows[k], p, min(max(s0 - breaks[k], 0.0), length), length, out)
        dist = (out[0] - p[0]) ** 2 + (out[1] - p[1]) ** 2 + (out[2] - p[2]) ** 2
        if dist < best_d or (best_k < 0 and dist <= best_d):
            best_d, best_k, best_u = dist, k, u
            for c in range(9):  # not frame[:] = out: numba compiles its shape-mismatch error (~2 s)
                frame[c] = out[c]
    return best_d, best_k, best_u


@njit(cache=True)
def _across(breaks, k, u, step, closed):
    """The primitive after (`step` 1) or before (-1) primitive k, when arc length u on k is at that end of it (on a
    closed path the first follows the last); else -1."""
    k_count = breaks.size - 1
    at_end = u >= breaks[k + 1] - breaks[k] - 1e-12 if step == 1 else u <= 1e-12
    nk = (k + step) % k_count if closed else k + step
    return nk if at_end and 0 <= nk < k_count else -1


@njit(cache=True)
def _least(kind, row, p, length, out):
    """Squared distance from p to the nearest point of a line or a plain arc, anywhere on it [mm^2]; -1 for others."""
    if kind == LINE:
        u = _closest(kind, row, p, 0.0, length, out)
    elif kind == ARC and row[15] == 0.0:
        x = y = 0.0
        for i in range(3):
            x += (p[i] - row[i]) * row[3 + i]
            y += (p[i] - row[i]) * row[6 + i]
        turned = 0.0
        if x * x + y * y > 1e-24:  # else every point of the arc is as near
            turned = ((1.0 if row[14] >= 0.0 else -1.0) * (math.atan2(y, x) - row[13])) % (2 * math.pi)
        # the distance grows with the angle from p's foot either way, up to half a turn
        sweep = abs(row[14])
        if turned <= sweep:
            u = turned * row[12]
        else:
            u = 0.0 if 2 * math.pi - turned < turned - sweep else length
        _eval_prim(kind, row, u, out)
    else:
        return -1.0
    return (out[0] - p[0]) ** 2 + (out[1] - p[1]) ** 2 + (out[2] - p[2]) ** 2


@njit(cache=True)
def _stretch_bound(sample_pos, i, j, length, q):
    """Least distance from q (3,) to the path between samples i and j, `length` apart along it [mm].

    Every such point is within `length` of the two together, in the ellipsoid of foci the samples: within
    half its minor axis, sqrt(length^2 - chord^2) / 2, of the chord. That far from the chord's nearest point.
    Two samples apart in arc length may share their position (a jerk-limited start, whose first steps are
    below its rounding): the ellipsoid is then the ball of radius length / 2 about it.
    """
    chord2 = along = 0.0
    for c in range(sample_pos.shape[1]):
        chord2 += (sample_pos[j, c] - sample_pos[i, c]) ** 2
        along += (q[c] - sample_pos[i, c]) * (sample_pos[j, c] - sample_pos[i, c])
    t = min(max(along / chord2, 0.0), 1.0) if chord2 > 0.0 else 0.0
    d2 = q[2] ** 2 if sample_pos.shape[1] == 2 else 0.0
    for c in range(sample_pos.shape[1]):
        d2 += (q[c] - sample_pos[i, c] - t * (sample_pos[j, c] - sample_pos[i, c])) ** 2
    return math.sqrt(d2) - 0.5 * math.sqrt(max(length * length - chord2, 0.0))


@njit(cache=True)
def _squared(sample_pos, i, q):
    """Squared distance from sample i (d columns, z = 0 for d = 2) to the point q (3,) [mm^2]."""
    d2 = 0.0
    for c in range(sample_pos.shape[1]):
        d2 += (sample_pos[i, c] - q[c]) ** 2
    return d2 + q[2] ** 2 if sample_pos.shape[1] == 2 else d2


@njit(cache=True)
def _foot_points(kinds, rows, breaks, lap, sample_s, sample_pos, first, anchors, idx, act, plane, magnitude,
                 s_out, normal, out_of_plane, foot):  # fmt: skip
    """Foot point of each actual point, its arc length and the contour error's parts, into the outputs.

    sample_s, sample_pos : arc length and position (N, d) of the reference samples; first : the first
    sample of each knot (distinct sample); anchors : the knot commanded at each actual point; idx : the
    knot nearest to each actual point (on the anchor's part of the ball); act : the actual points
    (N, 3), z = 0 for a 2-D path; plane : the path's plane normal, zero when it has none. Fills
    magnitude, s_out, normal (N,), foot (N, d) and, for d = 3, out_of_plane (N,).
    """
    n, ns, k_count, d = first.size, sample_s.size, kinds.size, foot.shape[1]
    out, frame = np.empty(9), np.empty(9)  # frame: position, tangent, curvature vector at the foot
    r = np.zeros(3)  # the commanded point
    for i in range(act.shape[0]):
        p = act[i]
        # sample indices as int64, as the walk's (`first` is int32 to save memory): one compiled _squared, _beyond
        j, anchor = np.int64(first[idx[i]]), np.int64(first[anchors[i]])  # the nearest and the commanded sample
        s_prev, s_next = sample_s[first[max(idx[i] - 1, 0)]], sample_s[first[min(idx[i] + 1, n - 1)]]
        # the sample itself is the first candidate: the refinement never ends farther from p than it
        best_d = _squared(sample_pos, j, p)
        # no primitive yet: an int64 -1, as the best primitive the walk passes (a literal -1 compiles _refine again)
        best_d, best_k, best_u = _refine(kinds, rows, breaks, p, s_prev, s_next, sample_s[j], best_d, np.int64(-1),
                                         0.0, out, frame)  # fmt: skip
        if best_k < 0:  # no primitive's refinement came nearer than the sample (a Newton step astray): the sample
            best_k = _primitive_at(breaks, sample_s[j])
            best_u = min(max(sample_s[j] - breaks[best_k], 0.0), breaks[best_k + 1] - breaks[best_k])
            _eval_prim(kinds[best_k], rows[best_k], best_u, frame)
        # A nearer point elsewhere on the anchor's part of the ball (another branch at a corner, whose samples
        # straddle its foot while one of this branch is nearer): walk that part's samples both ways from j, across
        # a stretch outside the ball no longer than its radius as the search does. No path point within arc
        # length |P - K| - best of a sample K is nearer than the best, nor leaves the ball within 2|P - R| - |K - R|
        # of it (nor, K outside, enters it within |K - R| - 2|P - R|: a point outside is farther from P than R);
        # the stretches between two samples that leaves uncovered are refined.
        for c in range(d):
            r[c] = sample_pos[anchor, c]
        radius = 2.0 * math.sqrt(_squared(sample_pos, anchor, p))
        for step in (-1, 1):  # a, b: indices along the path (on a closed one any integer, :func:`_real` the sample's)
            a, dr, k_here, whole, outside, left_at = j, math.sqrt(_squared(sample_pos, j, r)), -1, False, False, 0.0
            s_a = sample_s[j]  # a's arc length along the path (beyond [0, L] on a closed one)
            free = math.sqrt(_squared(sample_pos, j, p)) - math.sqrt(best_d)  # excluded arc length about a
            while True:
                if dr > radius:  # a outside the ball (left at `left_at`, less than the radius ago): no point
                    free = max(free, dr - radius)  # within dr - radius of it is inside, nor nearer than the best
                    b = _beyond(sample_s[::1], a, step, dr - radius, lap)
                else:
                    on = sample_s[_real(a, ns, lap)]  # a's arc length on the path's primitives
                    k = _primitive_at(breaks, on)
                    if k != k_here:  # a line or plain arc no nearer anywhere than the best: excluded up to its end
                        if k == best_k:  # the best foot is the nearest point of a line, of a plain arc if not at an end
                            end = breaks[k + 1] - breaks[k]
                            whole = kinds[k] == LINE or (kinds[k] == ARC and rows[k, 15] == 0.0 and 0.0 < best_u < end)
                        else:
                            whole = _least(kinds[k], rows[k], p, breaks[k + 1] - breaks[k], out) >= best_d
                        k_here = k
                    reach = radius - dr  # arc length within which the path stays in the ball
                    if whole:
                        rest = breaks[k + 1] - on if step == 1 else on - breaks[k]  # to its end
                        free = max(free, rest)
                        if kinds[k] == LINE:  # in the ball up to its end if that end is (convex)
                            # kinds[k], not LINE: a module constant is a literal to numba, typed apart (a second
                            # _eval_prim)
                            _eval_prim(kinds[k], rows[k], breaks[k + 1] - breaks[k] if step == 1 else 0.0, out)
                            if (out[0] - r[0]) ** 2 + (out[1] - r[1]) ** 2 + (out[2] - r[2]) ** 2 <= radius * radius:
                                reach = max(reach, rest)
                    # past the repeats of a standstill (the same arc length) at least
                    # sample_s[::1]: a strided view to numba, as the knots' length column the search passes (one _beyond)
                    b = _beyond(sample_s[::1], a, step, max(min(reach, free), 1e-300), lap)
                if lap == 0.0 and (b < 0 or b >= sample_s.size):
                    break
                s_b = _along(sample_s[::1], b, lap)
                if lap != 0.0 and abs(s_b - sample_s[j]) > lap:  # round a closed path once
                    break
                rb, rb_prev = _real(b, ns, lap), _real(b - step, ns, lap)
                dp, dr = math.sqrt(_squared(sample_pos, rb, p)), math.sqrt(_squared(sample_pos, rb, r))
                if outside and abs(s_b - left_at) > radius:
                    break  # away from the ball longer than a clipped corner: the anchor's part of it ended at left_at
                # the stretch between b and the sample before it: two distinct samples (b is the first of its run), the
                # upper one the closed path's last sample where it ends a lap
                lo, hi = (rb_prev, rb) if step == 1 else (rb, rb_prev)
                hi = ns - 1 if lap != 0.0 and hi == 0 else hi
                if (free + dp - math.sqrt(best_d) < abs(s_b - s_a)
                        and not (s_prev <= sample_s[lo] and sample_s[hi] <= s_next)  # refined above
                        and _stretch_bound(sample_pos, lo, hi, sample_s[hi] - sample_s[lo], p) < math.sqrt(best_d)):
                    nearer = dp * dp <= _squared(sample_pos, rb_prev, p)
                    guess = sample_s[hi if (step == 1) == nearer else lo]  # the end at b if nearer, else the other
                    best_d, best_k, best_u = _refine(kinds, rows, breaks, p, sample_s[lo], sample_s[hi], guess, best_d,
                                                     best_k, best_u, out, frame)  # fmt: skip
                if dr > radius:  # b outside the ball: the anchor's part of it ends where the path left it, unless back
                    if not outside:  # within the radius (the tip of a corner the ball clips); a step from inside stays
                        outside, left_at = True, _along(sample_s[::1], b - step, lap)  # in the ball up to its last sample
                    if abs(s_b - left_at) > radius:
                        break
                else:
                    outside = False
                a, s_a, free = b, s_b, dp - math.sqrt(best_d)
        for step in (-1, 1):  # foot clamped at a primitive end: try the neighbour
            k, u = best_k, best_u
            for _ in range(k_count):
                nk = _across(breaks, k, u, step, lap != 0.0)
                if nk < 0:
                    break
                length = breaks[nk + 1] - breaks[nk]
                u = _closest(kinds[nk], rows[nk], p, length if step == -1 else 0.0, length, out)
                dist = (out[0] - p[0]) ** 2 + (out[1] - p[1]) ** 2 + (out[2] - p[2]) ** 2
                if dist >= best_d:
                    break
                best_d, best_k, best_u, k = dist, nk, u, nk
                for c in range(9):
                    frame[c] = out[c]
        s_out[i] = breaks[best_k] + best_u
        dx, dy, dz = p[0] - frame[0], p[1] - frame[1], p[2] - frame[2]
        fk = best_k  # the primitive whose frame the error is split in
        for step in (-1, 1):  # a foot on a corner: the side the tool is square to, not the one rounding chose
            nk = _across(breaks, best_k, best_u, step, lap != 0.0)
            if nk < 0:
                continue
            _eval_prim(kinds[nk], rows[nk], 0.0 if step == 1 else breaks[nk + 1] - breaks[nk], out)
            if abs(dx * out[3] + dy * out[4] + dz * out[5]) < abs(dx * frame[3] + dy * frame[4] + dz * frame[5]):
                fk = nk
                for c in range(9):
                    frame[c] = out[c]
        # the plane normal b at the foot: the path's plane, an arc's axis, the osculating binormal, else z
        tx, ty, tz = frame[3], frame[4], frame[5]
        if plane[0] != 0.0 or plane[1] != 0.0 or plane[2] != 0.0:
            bx, by, bz = plane[0], plane[1], plane[2]
        elif kinds[fk] == ARC:
            bx, by, bz = rows[fk, 9], rows[fk, 10], rows[fk, 11]
        else:
            bx, by, bz = ty * frame[8] - tz * frame[7], tz * frame[6] - tx * frame[8], tx * frame[7] - ty * frame[6]
            nb = math.sqrt(bx * bx + by * by + bz * bz)
            if nb < 1e-9:  # straight here: z (x for a tangent near z) made perpendicular to t
                bx, by, bz = (0.0, 0.0, 1.0) if abs(tz) < 0.9 else (1.0, 0.0, 0.0)
                along = bx * tx + by * ty + bz * tz
                bx, by, bz = bx - along * tx, by - along * ty, bz - along * tz
                nb = math.sqrt(bx * bx + by * by + bz * bz)
            bx, by, bz = bx / nb, by / nb, bz / nb
        lx, ly, lz = by * tz - bz * ty, bz * tx - bx * tz, bx * ty - by * tx  # left of travel: b x t
        nl = math.sqrt(lx * lx + ly * ly + lz * lz)
        lx, ly, lz = lx / nl, ly / nl, lz / nl
        magnitude[i] = math.sqrt(dx * dx + dy * dy + dz * dz)
        normal[i] = dx * lx + dy * ly + dz * lz
        if d == 3:  # along t x l
            out_of_plane[i] = dx * (ty * lz - tz * ly) + dy * (tz * lx - tx * lz) + dz * (tx * ly - ty * lx)
        for c in range(d):
            foot[i, c] = frame[c]


# --------------------------------------------------------------------------- public function


def exact_contour_error(trajectory, actual, at=None, window=8):
    """Distance from actual tool positions to the continuous reference path.

    Parameters
    ----------
    trajectory : Trajectory
        Reference samples with their `path` (the search seeds on the samples).
    actual : array_like, shape (N, d)
        Actual tool positions [mm], d = trajectory.dim.
    at : array_like of int, shape (N,), optional
        The reference sample commanded when each actual point was taken
        (its tracking error is measured from it); default: sample i for
        point i, `actual` then having one row per reference sample. The
        contour error is searched on the part of the path connected to that
        sample inside the ball of twice the tracking error about it (module
        docstring), so it never exceeds the tracking error.
    window : int
        Distinct reference samples the search's descent from the previous
        point's foot scans either side before walking on [samples]
        (:func:`contoursim.nearest.nearest_knot`; speed only, not the result).

    Returns
    -------
    ContourError

    Examples
    --------
    >>> from contoursim.paths import circle
    >>> from contoursim.feed import plan, sample
    >>> path = circle((0, 0), 50.0)
    >>> ref = sample(path, plan(path, 100.0, 1000.0), 0.01)
    >>> quarter = int(np.argmax(ref.position[:, 1]))   # the sample at (0, 50)
    >>> err = exact_contour_error(ref, [[50.002, 0.0], [0.0, 49.999]], at=[0, quarter])
    >>> np.round(err.normal * 1e3, 6).tolist()   # R - |P - c| [µm]
    [-2.0, 1.0]
    """
    if not isinstance(trajectory, Trajectory):
        raise TypeError(f"trajectory must be a Trajectory (its path and samples), got {type(trajectory).__name__}")
    path = trajectory.path
    if path is None:
        raise ValueError("trajectory has no path: the exact contour error needs the continuous reference geometry")
    d = trajectory.dim
    act = _validate.finite_array("actual", actual, ndim=2, limit=MAX_ACTUAL)
    if act.shape[1] != d:
        raise ValueError(f"actual must have shape (N, {d}) like the trajectory's positions, got {act.shape}")
    position, window, n = trajectory.position, _validate.positive_int("window", window), act.shape[0]
    at = _validate.commanded(at, n, len(position))  # None: no (N,) array of sample indices
    # the knots, the distinct reference samples: their first samples and, while the search needs them, positions
    first = np.flatnonzero(moved(position)).astype(np.int32)  # int32 (as idx): 2**31 samples would need ~1 TB
    knots = np.zeros((first.size, 4))  # x, y, z and the arc length: the search's length along the path, as the walk's
    for part in blocks(first.size):
        knots[part, :d] = position[first[part]]
        knots[part, 3] = trajectory.s[first[part]]
    knots.flags.writeable = False  # as distinct()'s: one compiled signature of the search
    idx = np.empty(n, np.int32)  # the nearest knot to each actual point
    for part in blocks(n):  # as below: no (N, 3) copy of the actual points, no (N,) array of anchors
        anchors = _anchors(first, at, part)
        hint = int(idx[part.start - 1]) if part.start else int(anchors[0])
        idx[part] = nearest_knots(knots, anchors, _xyz(act[part]), window, hint)
    del knots  # before the results are filled
    magnitude, s, normal = np.empty((3, n))
    foot = np.empty((n, d))
    out_of_plane = np.empty(n if d == 3 else 0)
    plane = np.zeros(3) if path.plane_normal is None else np.asarray(path.plane_normal, dtype=float)
    # a closed path sampled from its start round to it is a loop: the walk goes on across the seam
    s_all = trajectory.s
    looped = (path.closed and len(s_all) > 2 and s_all[0] == 0.0
              and abs(s_all[-1] - path.length) <= 1e-9 * max(path.length, 1.0))
    for part in blocks(n):  # the actual points as (block, 3) copies: one compiled signature, no (N, 3) copy
        _foot_points(path.kinds, path.rows, path.breaks, path.length if looped else 0.0, s_all, position, first,
                     _anchors(first, at, part), idx[part], _xyz(act[part]), plane, magnitude[part], s[part],
                     normal[part], out_of_plane[part], foot[part])  # fmt: skip
    if d == 2:  # a 2-D path: (P_a - foot) . z = 0
        out_of_plane = np.broadcast_to(0.0, (n,))
    if act.flags.writeable:  # the caller's array: a copy, so that it stays writeable
        act = act.copy()
    return ContourError(magnitude=magnitude, vector=None, foot=foot, s=s, normal=normal, out_of_plane=out_of_plane,
                        actual=act)


def _anchors(first, at, part):
    """The knot holding the sample commanded at each actual point of the block `part` (int32, as `first`)."""
    commanded = np.arange(part.start, part.stop, dtype=np.int32) if at is None else at[part].astype(np.int32)
    # both int32: searchsorted would otherwise convert all of `first` for each block
    return np.searchsorted(first, commanded, side="right") - 1


def _xyz(points):
    """Points (M, 2) or (M, 3) as a C-contiguous (M, 3) array, z = 0 added to 2-D ones [mm]."""
    return np.ascontiguousarray(_validate.as_xyz(points))
