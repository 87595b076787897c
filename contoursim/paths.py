"""Reference path geometry: lines, helical arcs and spline pieces joined into a Path.

Every path is three-dimensional inside (planar paths have z = 0) and remembers
its nominal dimension ``dim`` (2 for paths in the XY plane, 3 otherwise). Each
primitive is parameterised by its own arc length u in [0, length]; a
:class:`Path` is an ordered, G0-continuous tuple of primitives parameterised by
the total arc length s.

Evaluation runs in compiled kernels over a flat encoding of the primitives
(one kind code and one row of parameters each, see ``Path.kinds`` and
``Path.rows``), which the exact contour error (:mod:`contoursim.contour`)
reuses for its foot-point search.

Row layout (``NCOL`` columns, unused entries zero):

- ``LINE``:   start (0:3), unit direction (3:6), length (6)
- ``ARC``:    centre (0:3), in-plane basis e1 (3:6), e2 (6:9), axis (9:12),
  radius (12), start angle (13), signed sweep (14), rise per radian (15),
  sqrt(radius^2 + rise^2) (16), length (17)
- ``SPLINE``: cubic coefficients a, b, c, d of P(w) = a + b w + c w^2 + d w^3,
  w in [0, 1] (0:12), cumulative arc length at w = 0, 1/16, ..., 1 (12:29)
"""

import math
from dataclasses import dataclass, field

import numpy as np
from scipy.linalg import solve_banded  # numba imports scipy.linalg as it compiles or loads anything: no extra cost

from . import _validate
from ._numba import njit
from .exceptions import PathError

__all__ = [
    "Line", "HelicalArc", "SplinePiece", "Path",
    "line", "arc", "circle", "helix", "iso230_4_circle", "polyline", "spline", "join",
    "LINE", "ARC", "SPLINE", "NCOL",
]

LINE, ARC, SPLINE = 0, 1, 2
NCOL = 29
CONTINUITY_TOL = 1e-9  # [mm] gap allowed between consecutive primitives
MAX_COORDINATE = 1e6  # [mm]: largest |coordinate| and size of a path (a kilometre, as a measured trace's positions)
_TABLE = 16  # arc-length table intervals per spline piece
_SAMPLES = 64  # curvature sampling intervals per spline piece: w = 0, 1/64, ..., 1
_GL_X, _GL_W = np.polynomial.legendre.leggauss(8)
_GL_X = 0.5 * (_GL_X + 1.0)  # nodes on [0, 1]
_GL_W = 0.5 * _GL_W


# --------------------------------------------------------------------------- compiled kernels

@njit(cache=True)
def _spline_speed(row, w):
    acc = 0.0
    for i in range(3):
        d = row[3 + i] + 2.0 * row[6 + i] * w + 3.0 * row[9 + i] * w * w
        acc += d * d
    return math.sqrt(acc)


@njit(cache=True)
def _spline_integral(row, w0, w1):
    """Arc length between parameters w0 and w1 (8-point Gauss-Legendre)."""
    h = w1 - w0
    acc = 0.0
    for k in range(_GL_X.size):
        acc += _GL_W[k] * _spline_speed(row, w0 + h * _GL_X[k])
    return acc * h


@njit(cache=True)
def _spline_lengths(rows):
    """Arc length [mm] of spline pieces (K, NCOL) at w = 0, 1/64, ..., 1, shape (K, 65)."""
    u = np.empty((rows.shape[0], _SAMPLES + 1))
    for k in range(rows.shape[0]):
        for m in range(_SAMPLES + 1):
            u[k, m] = _spline_u_of_w(rows[k], m / _SAMPLES)
    return u


@njit(cache=True)
def _spline_u_of_w(row, w):
    j = min(int(w * _TABLE), _TABLE - 1)
    return row[12 + j] + _spline_integral(row, j / _TABLE, w)


@njit(cache=True)
def _spline_w_guess(row, u):
    """Table interval j holding arc length u (0 < u < length) and w interpolated linearly in it."""
    j = 0
    while j < _TABLE - 1 and row[13 + j] <= u:
        j += 1
    return j, (j + (u - row[12 + j]) / (row[13 + j] - row[12 + j])) / _TABLE


@njit(cache=True)
def _spline_w_of_u(row, u):
    """Invert the arc-length map: Newton inside the bracketing table interval, bisection as safeguard."""
    if u <= 0.0:
        return 0.0
    if u >= row[12 + _TABLE]:
        return 1.0
    j, w = _spline_w_guess(row, u)
    lo = j / _TABLE
    a, b = lo, (j + 1) / _TABLE
    for _ in range(60):
        f = row[12 + j] + _spline_integral(row, lo, w) - u
        if f > 0.0:
            b = w
        else:
            a = w
        wn = w - f / _spline_speed(row, w)
        # the error after a Newton step is of the order of its square: below rounding once the step is 1e-10
        # (a tighter test would go on in the rounding noise of f, 12 steps on average instead of 2)
        if abs(wn - w) <= 1e-10:
            return min(max(wn, a), b)
        if not (a < wn < b):
            wn = 0.5 * (a + b)
        w = wn
    return w


@njit(cache=True)
def _spline_tables(coefs):
    """Rows of spline pieces from their (K, 12) coefficients, and which have a cusp.

    Each row holds its cumulative arc-length table. A cusp (or zero length)
    where the speed |P'| = |dP/dw| at w = 0, 1/64, ..., 1 drops to 1e-9 of
    the chord.
    """
    # np.empty, every entry set below: np.zeros would compile three more functions per signature (~0.07 s each)
    rows = np.empty((coefs.shape[0], NCOL))
    cusp = np.empty(coefs.shape[0], np.bool_)
    for k in range(coefs.shape[0]):
        row = rows[k]
        for c in range(12):  # not row[:12] = coefs[k]: numba would compile its shape-mismatch error (~1.5 s)
            row[c] = coefs[k, c]
        row[12] = 0.0
        for j in range(_TABLE):  # integrated over the read-only coefs[k]: the signature of every other call
            row[13 + j] = row[12 + j] + _spline_integral(coefs[k], j / _TABLE, (j + 1) / _TABLE)
        chord2 = 0.0
        for i in range(3):
            chord2 += (row[3 + i] + row[6 + i] + row[9 + i]) ** 2
        slowest = _spline_speed(coefs[k], 0.0)  # the read-only coefs[k] again
        for m in range(1, _SAMPLES + 1):
            slowest = min(slowest, _spline_speed(coefs[k], m / _SAMPLES))
        cusp[k] = slowest**2 <= 1e-18 * max(chord2, 1e-300)
    return rows, cusp


@njit(cache=True)
def _eval_spline_w(row, w, out):
    """Position, unit tangent and curvature vector dT/ds at spline parameter w into out (9,)."""
    speed2 = dot12 = 0.0
    for i in range(3):
        out[i] = row[i] + w * (row[3 + i] + w * (row[6 + i] + w * row[9 + i]))
        out[3 + i] = row[3 + i] + 2.0 * row[6 + i] * w + 3.0 * row[9 + i] * w * w  # dP/dw
        out[6 + i] = 2.0 * row[6 + i] + 6.0 * row[9 + i] * w  # d2P/dw2
        speed2 += out[3 + i] ** 2
        dot12 += out[3 + i] * out[6 + i]
    speed = math.sqrt(speed2)
    for i in range(3):
        out[3 + i] /= speed
        out[6 + i] = (out[6 + i] - dot12 / speed * out[3 + i]) / speed2


@njit(cache=True)
def _eval_prim(kind, row, u, out):
    """Position, unit tangent and curvature vector dT/ds at arc length u of one primitive into out (9,)."""
    if kind == LINE:
        for i in range(3):
            out[i] = row[i] + u * row[3 + i]
            out[3 + i] = row[3 + i]
            out[6 + i] = 0.0
    elif kind == ARC:
        radius, theta0, sweep, rise, rho = row[12], row[13], row[14], row[15], row[16]
        sgn = 1.0 if sweep >= 0.0 else -1.0
        turned = u / rho
        c = math.cos(theta0 + sgn * turned)
        s = math.sin(theta0 + sgn * turned)
        for i in range(3):
            radial = c * row[3 + i] + s * row[6 + i]
            across = -s * row[3 + i] + c * row[6 + i]
            out[i] = row[i] + radius * radial + rise * turned * row[9 + i]
            out[3 + i] = (sgn * radius * across + rise * row[9 + i]) / rho
            out[6 + i] = -radius * radial / (rho * rho)
    else:
        _eval_spline_w(row, _spline_w_of_u(row, u), out)


@njit(cache=True)
def _primitive_at(breaks, s):
    """Index of the primitive holding arc length s (the later one at a junction)."""
    # bisection for np.searchsorted(breaks, s, side="right") - 1 (a NaN s sorting last, as in numpy):
    # numba's searchsorted compiles comparisons for every dtype (~0.3 s of a first run)
    lo, hi = 0, breaks.size
    while lo < hi:
        mid = (lo + hi) // 2
        if s < breaks[mid]:
            hi = mid
        else:
            lo = mid + 1
    return min(max(lo - 1, 0), breaks.size - 2)


@njit(cache=True)
def _evaluate_local(kinds, rows, index, u):
    """Position, tangent and curvature vector at arc length u[m] of primitive index[m], shape (M, 9)."""
    out = np.empty((u.size, 9))
    for m in range(u.size):
        k = index[m]
        length = rows[k, 6] if kinds[k] == LINE else rows[k, 17] if kinds[k] == ARC else rows[k, 12 + _TABLE]
        _eval_prim(kinds[k], rows[k], min(max(u[m], 0.0), length), out[m])
    return out


def _evaluate(kinds, rows, breaks, s):
    """Position, tangent and curvature vector at path arc lengths `s`, shape (M, 9): primitive k holds [breaks[k], breaks[k+1])."""
    k = np.clip(np.searchsorted(breaks, s, side="right") - 1, 0, breaks.size - 2)
    kinds, rows = kinds.view(), rows.view()
    kinds.flags.writeable = rows.flags.writeable = False  # as a Path holds them: one compiled signature
    return _evaluate_local(kinds, rows, k, np.clip(s - breaks[k], 0.0, breaks[k + 1] - breaks[k]))


# --------------------------------------------------------------------------- primitives

def _vector(name, value):
    """A 2- or 3-vector as a float (3,) array (z = 0 for 2-vectors)."""
    try:
        v = _validate.finite_array(name, value, ndim=1, limit=MAX_COORDINATE)
    except ValueError as exc:
        raise PathError(str(exc)) from None
    if v.size not in (2, 3):
        raise PathError(f"{name} must have 2 or 3 coordinates, got {v.size}")
    return np.append(v, 0.0) if v.size == 2 else v


def _scalar(check, name, value):
    try:
        value = check(name, value)
    except ValueError as exc:
        raise PathError(str(exc)) from None
    # 1e308 hangs, 1e-300 divides by 0; the bounds to rounding (a radius of 1e-6 from a centre word I0.000001)
    if not (1.0 - 1e-9) / MAX_COORDINATE <= abs(value) <= MAX_COORDINATE and value != 0:
        raise PathError(f"{name} = {value:.10g} is outside [{1.0 / MAX_COORDINATE:g}, {MAX_COORDINATE:g}], "
                        "not a path a machine follows")
    return value


def _number(name, value):
    """A finite float of any sign, within ±:data:`MAX_COORDINATE`."""
    try:
        return float(_validate.finite_array(name, value, ndim=0, limit=MAX_COORDINATE))
    except ValueError as exc:
        raise PathError(str(exc)) from None


def _unit(name, value):
    """A direction in space as a unit (3,) vector: 3 coordinates, as its z is not to be guessed."""
    v = _vector(name, value)
    if np.size(value) != 3:
        raise PathError(f"{name} must have 3 coordinates (a direction: [0, 0, 1] is normal to XY), got "
                        f"{np.size(value)}")
    n = np.linalg.norm(v)
    if n < 1e-12:
        raise PathError(f"{name} must be a non-zero vector")
    return v / n


def _frozen(obj, **arrays):
    for name, value in arrays.items():
        value = np.array(value, dtype=float)
        value.flags.writeable = False
        object.__setattr__(obj, name, value)


class _Primitive:
    """Shared behaviour: evaluation through the compiled kernel on this primitive's row."""

    def evaluate(self, u):
        """Position, unit tangent and curvature vector at arc lengths `u` [mm] of this primitive.

        Parameters
        ----------
        u : array_like, shape (M,)
            Arc length from the primitive's start [mm], clamped to [0, length].

        Returns
        -------
        position, tangent, curvature_vector : ndarray, shape (M, 3)
            Point [mm], unit tangent [-] and dT/du [1/mm].
        """
        u = _validate.finite_array("u", u, ndim=1)
        out = _evaluate(np.array([self.kind]), self.row[None, :], np.array([0.0, self.length]), u)
        return out[:, :3], out[:, 3:6], out[:, 6:9]

    @property
    def start(self):
        """First point [mm], shape (3,)."""
        return self.evaluate([0.0])[0][0]

    @property
    def end(self):
        """Last point [mm], shape (3,)."""
        return self.evaluate([self.length])[0][0]


@dataclass(frozen=True, eq=False)
class Line(_Primitive):
    """Straight segment.

    Parameters
    ----------
    p0, p1 : array_like, shape (2,) or (3,)
        Start and end point [mm].
    role : str
        Tag such as "run-in", "test", "run-out", "rapid" or "path".
    """

    p0: np.ndarray
    p1: np.ndarray
    role: str = "path"
    kind = LINE

    def __post_init__(self):
        p0, p1 = _vector("p0", self.p0), _vector("p1", self.p1)
        length = float(np.linalg.norm(p1 - p0))
        if length < CONTINUITY_TOL:
            raise PathError(f"line from {p0.tolist()} to {p1.tolist()} has zero length")
        _frozen(self, p0=p0, p1=p1)
        row = np.zeros(NCOL)
        row[0:3], row[3:6], row[6] = p0, (p1 - p0) / length, length
        _frozen(self, row=row)
        object.__setattr__(self, "length", length)

    @property
    def in_xy_plane(self):
        """True if the segment lies in z = 0."""
        return abs(self.p0[2]) < 1e-12 and abs(self.p1[2]) < 1e-12


@dataclass(frozen=True, eq=False)
class HelicalArc(_Primitive):
    """Circular arc or helix: P(θ) = c + R (cos θ e1 + sin θ e2) + rise |θ - θ0| a, a = e1 x e2.

    Parameters
    ----------
    center : array_like, shape (3,)
        Centre at the start's axial level [mm].
    e1, e2 : array_like, shape (3,)
        Orthonormal in-plane basis; the axis (plane normal) is e1 x e2.
    radius : float
        Radius [mm].
    start_angle : float
        θ0, measured from e1 towards e2 [rad].
    sweep : float
        Signed angle travelled, counter-clockwise about the axis positive [rad]; may exceed 2π.
    rise : float
        Travel along the axis per radian turned [mm/rad]; 0 for a plain arc.
    role : str
        Tag, see :class:`Line`.
    """

    center: np.ndarray
    e1: np.ndarray
    e2: np.ndarray
    radius: float
    start_angle: float
    sweep: float
    rise: float = 0.0
    role: str = "path"
    kind = ARC

    def __post_init__(self):
        c, e1, e2 = _vector("center", self.center), _vector("e1", self.e1), _vector("e2", self.e2)
        if abs(e1 @ e1 - 1) > 1e-9 or abs(e2 @ e2 - 1) > 1e-9 or abs(e1 @ e2) > 1e-9:
            raise PathError("e1 and e2 must be orthonormal")
        radius = _scalar(_validate.positive, "radius", self.radius)
        theta0 = _number("start_angle", self.start_angle)
        sweep = _number("sweep", self.sweep)
        if abs(sweep) <= 1e-12:
            raise PathError(f"arc sweep must be non-zero, got {self.sweep!r}")
        rise = _number("rise", self.rise)
        rho = math.hypot(radius, rise)
        length = abs(sweep) * rho
        _frozen(self, center=c, e1=e1, e2=e2)
        for name, value in dict(radius=radius, start_angle=theta0, sweep=sweep, rise=rise, length=length).items():
            object.__setattr__(self, name, value)
        row = np.zeros(NCOL)
        row[0:3], row[3:6], row[6:9], row[9:12] = c, e1, e2, np.cross(e1, e2)
        row[12:18] = radius, theta0, sweep, rise, rho, length
        _frozen(self, row=row)

    @property
    def axis(self):
        """Unit axis e1 x e2, shape (3,)."""
        return self.row[9:12]

    @property
    def in_xy_plane(self):
        """True for a plain arc in z = 0 about the z axis."""
        return self.rise == 0 and abs(self.center[2]) < 1e-12 and np.linalg.norm(self.axis[:2]) < 1e-12


@dataclass(frozen=True, eq=False)
class SplinePiece(_Primitive):
    """One cubic piece P(w) = a + b w + c w^2 + d w^3, w in [0, 1], of a C2 spline.

    Parameters
    ----------
    coefficients : array_like, shape (4, 3)
        Rows a, b, c, d [mm].
    role : str
        Tag, see :class:`Line`.

    Attributes
    ----------
    max_curvature : float
        Largest curvature |P' × P''| / |P'|³ on the piece [1/mm] (at its
        ends or where it is stationary: a root of a polynomial of degree 7).

    Notes
    -----
    The arc length is not linear in w: a table of cumulative arc length at 17
    values of w (8-point Gauss-Legendre per interval) brackets the inverse
    map, which Newton's method then solves to machine precision.
    """

    coefficients: np.ndarray
    role: str = "path"
    kind = SPLINE

    def __post_init__(self):
        try:
            coef = _validate.finite_array("coefficients", self.coefficients, shape=(4, 3))
        except ValueError as exc:
            raise PathError(str(exc)) from None
        rows, curvature, cusps = _spline_rows(coef[None])
        if cusps.size:
            raise PathError(_CUSP)
        self._set(*self._frozen_rows(coef[None], rows), curvature, 0)

    @staticmethod
    def _frozen_rows(coefs, rows):
        """Read-only coefficients (K, 4, 3) and rows (K, NCOL), and whether each piece lies in z = 0."""
        coefs, rows = np.array(coefs, dtype=float), np.array(rows, dtype=float)
        coefs.flags.writeable = False
        rows.flags.writeable = False
        return coefs, rows, np.all(np.abs(coefs[:, :, 2]) < 1e-12, axis=1)

    def _set(self, coefs, rows, in_xy, curvature, k):
        object.__setattr__(self, "coefficients", coefs[k])
        object.__setattr__(self, "row", rows[k])
        object.__setattr__(self, "length", float(rows[k, 12 + _TABLE]))
        object.__setattr__(self, "_in_xy", bool(in_xy[k]))
        object.__setattr__(self, "max_curvature", float(curvature[k]))

    @classmethod
    def _pieces(cls, coefs, rows, curvature, role):
        """Pieces from coefficients (K, 4, 3), their rows and largest curvatures from :func:`_spline_rows` (checked there)."""
        frozen = (*cls._frozen_rows(coefs, rows), curvature)
        pieces = []
        for k in range(len(coefs)):
            piece = object.__new__(cls)
            object.__setattr__(piece, "role", role)
            piece._set(*frozen, k)
            pieces.append(piece)
        return pieces

    @property
    def in_xy_plane(self):
        """True if the piece lies in z = 0."""
        return self._in_xy


_PRIMITIVES = (Line, HelicalArc, SplinePiece)


_CUSP = "spline piece has a cusp or zero length (duplicate control points?)"


def _spline_rows(coefs):
    """Rows (K, NCOL) of spline pieces with coefficients (K, 4, 3), their largest curvatures (K,) [1/mm], and the
    indices of pieces with a cusp (:func:`_spline_tables`)."""
    flat = np.ascontiguousarray(coefs.reshape(len(coefs), 12))  # a new view: the caller's array keeps its flags
    flat.flags.writeable = False  # read-only as a Path's rows are: one compiled signature of the spline helpers
    rows, cusp = _spline_tables(flat)
    cusps = np.flatnonzero(cusp)
    if cusps.size:
        return rows, None, cusps
    ends = np.zeros((len(coefs), 2))
    ends[:, 1] = 1.0
    curvature = _spline_curvature(coefs, np.hstack([ends, np.nan_to_num(_spline_curvature_peaks(coefs))])).max(axis=1)
    return rows, curvature, cusps


def _spline_curvature(coefs, w):
    """Curvature |P' × P''| / |P'|³ [1/mm] of spline pieces with coefficients (K, 4, 3) at parameters w, shape (K, M)."""
    b, c, d = (coefs[:, None, i] for i in (1, 2, 3))
    w = w[..., None]
    velocity = b + w * (2 * c + 3 * w * d)
    cross = np.cross(velocity, 2 * c + 6 * w * d)
    return np.sqrt(np.sum(cross**2, axis=-1) / np.sum(velocity**2, axis=-1) ** 3)  # no cusp: |P'| > 0


def _spline_curvature_peaks(coefs):
    """Parameters w in (0, 1) where the curvature of spline pieces with coefficients (K, 4, 3) is stationary, shape
    (K, 7), NaN where there is none.

    With V = P' and C = P' × P'' = 2 b×c + 6 b×d w + 6 c×d w² (quadratics in
    w), the squared curvature |C|² / |V|⁶ is stationary where
    (|C|²)'·|V|² − 3 |C|²·(|V|²)' = 0, a polynomial of degree 7.
    """
    b, c, d = coefs[:, 1], coefs[:, 2], coefs[:, 3]
    velocity = np.stack([b, 2 * c, 3 * d], axis=1)  # in ascending powers of w
    cross = np.stack([2 * np.cross(b, c), 6 * np.cross(b, d), 6 * np.cross(c, d)], axis=1)
    n, v = _polynomial_product(cross, cross), _polynomial_product(velocity, velocity)  # |C|², |V|², degree 4
    powers = np.arange(1, 5)
    stationary = _polynomial_product(n[:, 1:] * powers, v) - 3 * _polynomial_product(n, v[:, 1:] * powers)
    return _roots_inside(stationary)


def _roots_inside(coefficients):
    """The real parts in (0, 1) of the roots of polynomials in ascending powers, shape (K, n + 1): shape (K, n), NaN
    where there is none (a root rounded off the real axis is kept near it). One eigenvalue call per degree, leading
    coefficients within rounding of the largest dropped."""
    n = coefficients.shape[1] - 1
    inside = np.full((len(coefficients), n), np.nan)
    scale = np.abs(coefficients).max(axis=1, keepdims=True)
    degree = n - np.cumprod(np.abs(coefficients[:, ::-1]) <= 1e-14 * scale, axis=1).sum(axis=1)
    for m in range(1, n + 1):
        rows = np.flatnonzero(degree == m)
        if rows.size:  # the companion matrices of the monic polynomials: their eigenvalues are the roots
            companion = np.zeros((rows.size, m, m))
            companion[:, 1:, :-1] = np.eye(m - 1)
            companion[:, :, -1] = -coefficients[rows, :m] / coefficients[rows, m:m + 1]
            w = np.linalg.eigvals(companion).real
            inside[rows, :m] = np.where((w > 0) & (w < 1), w, np.nan)
    return inside


def _polynomial_product(a, b):
    """The product of polynomials in ascending powers, shapes (K, m, ...) and (K, n, ...), with any trailing axes
    summed over (the dot product of two vector polynomials): shape (K, m + n - 1)."""
    out = np.zeros((a.shape[0], a.shape[1] + b.shape[1] - 1))
    for i in range(a.shape[1]):
        for j in range(b.shape[1]):
            out[:, i + j] += (a[:, i] * b[:, j]).reshape(len(a), -1).sum(axis=1)
    return out


# --------------------------------------------------------------------------- path

@dataclass(frozen=True, eq=False)
class Path:
    """An ordered, G0-continuous sequence of primitives, parameterised by arc length s [mm].

    Parameters
    ----------
    primitives : sequence of Line, HelicalArc, SplinePiece
        Consecutive ends and starts must coincide within 1e-9 mm.
    dim : {2, 3}, optional
        Nominal dimension; 2 by default when every primitive lies in the XY
        plane (z = 0), else 3.

    Attributes
    ----------
    length : float
        Total arc length [mm].
    breaks : ndarray, shape (K + 1,)
        Arc length at the start of each primitive, then the total [mm].
    kinds : ndarray of int, shape (K,)
        ``LINE``, ``ARC`` or ``SPLINE`` per primitive.
    rows : ndarray, shape (K, NCOL)
        Flat parameters per primitive (layout in the module docstring).
    roles : tuple of str
        The primitives' roles.
    closed : bool
        True if the path ends where it starts.
    plane_normal : ndarray, shape (3,), or None
        Unit normal of the path's plane: +z for XY paths, the first arc's axis
        for paths with arcs in one plane, else the plane's normal with its
        first non-zero component among (z, y, x) positive. None for paths
        that are not planar (helices, 3-D curves) or are straight lines in 3-D.
    """

    primitives: tuple
    dim: int = None
    length: float = field(init=False)

    def __post_init__(self):
        prims = tuple(self.primitives)
        if not prims:
            raise PathError("a path needs at least one primitive")
        for k, p in enumerate(prims):
            if not isinstance(p, _PRIMITIVES):
                raise PathError(f"segment {k} is a {type(p).__name__}, not a Line, HelicalArc or SplinePiece")
        kinds = np.array([p.kind for p in prims], dtype=np.int64)
        rows = np.array([p.row for p in prims])
        kinds.flags.writeable = rows.flags.writeable = False  # read-only before the compiled evaluation: one signature
        lengths = np.array([p.length for p in prims])
        index = np.arange(len(prims))
        ends = _evaluate_local(kinds, rows, np.repeat(index, 2), np.column_stack([np.zeros(len(prims)), lengths]).ravel())
        ends = ends.reshape(len(prims), 2, 9)  # start and end of each primitive: position, tangent, curvature vector
        gaps = np.linalg.norm(ends[1:, 0, :3] - ends[:-1, 1, :3], axis=1)
        if np.any(gaps > CONTINUITY_TOL):
            k = int(np.argmax(gaps > CONTINUITY_TOL)) + 1
            raise PathError(f"segment {k} starts {gaps[k - 1]:.3g} mm away from the end of segment {k - 1}")
        planar_xy = all(p.in_xy_plane for p in prims)
        dim = 2 if (self.dim is None and planar_xy) else 3 if self.dim is None else self.dim
        if dim not in (2, 3) or (dim == 2 and not planar_xy):
            raise PathError(f"dim must be 3, or 2 for a path in the XY plane, got {self.dim!r}")
        breaks = np.concatenate([[0.0], np.cumsum(lengths)])
        for name, value in dict(kinds=kinds, rows=rows, breaks=breaks, _ends=ends).items():
            value.flags.writeable = False
            object.__setattr__(self, name, value)
        object.__setattr__(self, "primitives", prims)
        object.__setattr__(self, "dim", dim)
        object.__setattr__(self, "length", float(breaks[-1]))
        object.__setattr__(self, "roles", tuple(p.role for p in prims))
        object.__setattr__(self, "closed", bool(np.linalg.norm(ends[-1, 1, :3] - ends[0, 0, :3]) <= CONTINUITY_TOL))
        object.__setattr__(self, "plane_normal", np.array([0.0, 0.0, 1.0]) if planar_xy else self._plane())

    def _plane(self):
        lengths = np.diff(self.breaks)
        index = np.repeat(np.arange(len(lengths)), 9)
        pts = _evaluate_local(self.kinds, self.rows, index, np.tile(np.linspace(0.0, 1.0, 9), len(lengths)) * lengths[index])[:, :3]
        pts = pts - pts.mean(axis=0)
        _, sv, vt = np.linalg.svd(pts, full_matrices=False)
        extent = max(sv[0], 1e-300)
        normal = vt[2]
        if sv[1] <= 1e-12 * extent or np.abs(pts @ normal).max() > 1e-9 * max(1.0, np.abs(pts).max()):
            return None
        arcs = [p.axis for p in self.primitives if isinstance(p, HelicalArc)]
        if arcs:
            return normal * np.sign(normal @ arcs[0])
        first = next(normal[i] for i in (2, 1, 0) if abs(normal[i]) > 1e-12)
        return normal * np.sign(first)

    def __add__(self, other):
        return join(self, other)

    def __len__(self):
        return len(self.primitives)

    @property
    def start(self):
        """First point [mm], shape (3,)."""
        return self._ends[0, 0, :3].copy()

    @property
    def end(self):
        """Last point [mm], shape (3,)."""
        return self._ends[-1, 1, :3].copy()

    def derivatives(self, s):
        """Position, unit tangent and curvature vector at arc lengths `s`.

        Parameters
        ----------
        s : array_like, shape (M,)
            Arc length [mm], clamped to [0, length].

        Returns
        -------
        position : ndarray, shape (M, 3)
            Point on the path [mm].
        tangent : ndarray, shape (M, 3)
            Unit tangent dP/ds [-].
        curvature_vector : ndarray, shape (M, 3)
            dT/ds = kappa N [1/mm]; zero on lines.
        """
        s = _validate.finite_array("s", s, ndim=1)
        out = _evaluate(self.kinds, self.rows, self.breaks, s)
        return out[:, :3], out[:, 3:6], out[:, 6:9]

    def evaluate(self, s):
        """Position, unit tangent and curvature at arc lengths `s`.

        Parameters
        ----------
        s : array_like, shape (M,)
            Arc length [mm], clamped to [0, length].

        Returns
        -------
        position : ndarray, shape (M, 3)
            Point on the path [mm].
        tangent : ndarray, shape (M, 3)
            Unit tangent [-].
        curvature : ndarray, shape (M,)
            Curvature [1/mm].
        """
        pos, tan, kvec = self.derivatives(s)
        return pos, tan, np.linalg.norm(kvec, axis=1)

    def segment_index(self, s, at_rest=None):
        """Index of the primitive holding each arc length (the later one at a junction).

        Parameters
        ----------
        s : array_like, shape (M,)
            Arc length [mm].
        at_rest : array_like of bool, shape (M,), optional
            Which samples of a motion stand still: one at rest at a junction
            belongs to the earlier primitive, whose stop (or dwell) it is.

        Returns
        -------
        ndarray of int, shape (M,)
        """
        s = _validate.finite_array("s", s, ndim=1)
        index = np.clip(np.searchsorted(self.breaks, s, side="right") - 1, 0, len(self.primitives) - 1)
        if at_rest is not None:
            index -= (index > 0) & (s <= self.breaks[index]) & np.asarray(at_rest, bool)
        return index

    def test_circle(self):
        """The full test circle of a circular test (ISO 230-4), or ``None``.

        Returns
        -------
        HelicalArc or None
            The path's one primitive with role ``"test"`` when it is a full
            circle (``|sweep| = 2π``, no rise) in a plane parallel to XY, at
            any height; its ``center``, ``radius`` and the sign of ``sweep``
            times ``axis[2]`` (counter-clockwise seen from +z positive)
            describe the test.
        """
        tests = [p for p in self.primitives if p.role == "test"]
        if len(tests) == 1 and isinstance(tests[0], HelicalArc):
            arc = tests[0]
            if arc.rise == 0 and np.linalg.norm(arc.axis[:2]) < 1e-12 and abs(abs(arc.sweep) - 2 * np.pi) < 1e-9:
                return arc
        return None

    def corner_angles(self):
        """Angle between the end tangent of each primitive and the start tangent of the next [rad].

        Returns
        -------
        ndarray, shape (K - 1,)
        """
        a, b = self._ends[:-1, 1, 3:6], self._ends[1:, 0, 3:6]
        # atan2 of |a×b| and a·b: arccos of the dot product reads tangent joints 1e-8 rad off (its slope is infinite at 1)
        return np.arctan2(np.linalg.norm(np.cross(a, b), axis=1), np.sum(a * b, axis=1))

    def max_curvature(self):
        """Largest curvature of each primitive [1/mm] (on a spline piece at its ends or where it is stationary).

        Returns
        -------
        ndarray, shape (K,)
        """
        result = np.zeros(len(self.primitives))
        arcs = self.kinds == ARC
        result[arcs] = self.rows[arcs, 12] / self.rows[arcs, 16] ** 2  # radius / (radius² + rise²)
        pieces = self.kinds == SPLINE
        result[pieces] = [p.max_curvature for p in self.primitives if p.kind == SPLINE]
        return result

    def curvature_profile(self):
        """The largest curvature along the path, by intervals: one a line or an arc, 64 a spline piece.

        A spline piece's curvature varies along it: its intervals are those
        between the parameters w = 0, 1/64, ..., 1, each with the largest
        curvature on it (at its ends or where it is stationary inside).

        Returns
        -------
        edges : ndarray, shape (C + 1,)
            Arc length at the intervals' starts, then the path's length [mm].
        curvature : ndarray, shape (C,)
            Largest curvature on each interval [1/mm].
        primitive : ndarray of int, shape (C,)
            The primitive each interval lies on.
        """
        pieces = self.kinds == SPLINE
        primitive = np.repeat(np.arange(len(self.primitives)), np.where(pieces, _SAMPLES, 1))
        edges, curvature = self.breaks[primitive], self.max_curvature()[primitive]  # copies, by the fancy index
        if pieces.any():
            rows = self.rows[pieces]
            rows.flags.writeable = False  # the signature the spline helpers are compiled for
            coefs = rows[:, :12].reshape(-1, 4, 3)
            inside = pieces[primitive]
            edges[inside] += _spline_lengths(rows)[:, :-1].ravel()
            w = np.broadcast_to(np.linspace(0.0, 1.0, _SAMPLES + 1), (len(rows), _SAMPLES + 1))
            at_edges = _spline_curvature(coefs, w)
            largest = np.maximum(at_edges[:, :-1], at_edges[:, 1:])
            peaks = _spline_curvature_peaks(coefs)
            k, i = np.nonzero(np.isfinite(peaks))
            np.maximum.at(largest, (k, np.minimum((peaks[k, i] * _SAMPLES).astype(int), _SAMPLES - 1)),
                          _spline_curvature(coefs[k], peaks[k, i, None])[:, 0])
            curvature[inside] = largest.ravel()
        return np.append(edges, self.length), curvature, primitive


def join(*paths):
    """Concatenate paths end to start.

    Parameters
    ----------
    *paths : Path
        Each must start where the previous one ends (within 1e-9 mm).

    Returns
    -------
    Path
        Dimension 2 if every piece lies in the XY plane, else 3.
    """
    prims = []
    for k, p in enumerate(paths):
        if not isinstance(p, Path):
            raise PathError(f"argument {k} of join is a {type(p).__name__}, not a Path")
        prims.extend(p.primitives)
    return Path(tuple(prims))


# --------------------------------------------------------------------------- builders

def _direction(direction):
    if direction not in ("ccw", "cw"):
        raise PathError(f"direction must be 'ccw' or 'cw', got {direction!r}")
    return 1.0 if direction == "ccw" else -1.0


def _plane_basis(normal):
    """In-plane basis (e1, e2) for a unit normal: e1 is the x axis projected onto the plane (y if normal ~ x)."""
    ref = np.array([1.0, 0.0, 0.0]) if abs(normal[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    e1 = ref - (ref @ normal) * normal
    e1 /= np.linalg.norm(e1)
    return e1, np.cross(normal, e1)


def _arc_from_point(center, start, axis, sweep, rise=0.0, role="path"):
    """Arc (or helix) about `axis` through `start`, turning `sweep` [rad] about the axis line through `center`."""
    radial = start - center
    radial = radial - (radial @ axis) * axis
    radius = np.linalg.norm(radial)
    if radius < CONTINUITY_TOL:
        raise PathError("arc start point lies on the arc's axis (zero radius)")
    e1 = radial / radius
    return HelicalArc(start - radial, e1, np.cross(axis, e1), radius, 0.0, sweep, rise, role)


def line(start, end, role="path"):
    """A straight path.

    Parameters
    ----------
    start, end : array_like, shape (2,) or (3,)
        End points [mm].
    role : str
        Role tag of the segment.

    Returns
    -------
    Path
    """
    a, b = _vector("start", start), _vector("end", end)
    if np.size(start) != np.size(end):  # a 2-D end read as z = 0 would take a 3-D start down to it
        raise PathError(f"start has {np.size(start)} coordinates and end {np.size(end)}: give both in 2-D or both in 3-D")
    return Path((Line(a, b, role),))


def arc(center, radius, start_angle, end_angle=None, *, sweep=None, direction="ccw", normal=(0, 0, 1), role="path"):
    """A circular arc.

    Angles are measured in the plane normal to `normal`, from the x axis
    projected onto that plane (from the y axis if `normal` is close to x).

    Parameters
    ----------
    center : array_like, shape (2,) or (3,)
        Centre [mm].
    radius : float
        Radius [mm].
    start_angle : float
        Start angle [rad].
    end_angle : float, optional
        End angle [rad]; the arc runs from start to end in `direction`
        (a full turn when they are equal). Give this or `sweep`.
    sweep : float, optional
        Signed angle travelled about `normal`, counter-clockwise positive [rad].
    direction : {"ccw", "cw"}
        Turning direction about `normal`, used with `end_angle` (with
        `sweep`, its sign gives the direction: "cw" with a positive one is
        refused).
    normal : array_like, shape (3,)
        Plane normal (arc axis).
    role : str
        Role tag.

    Returns
    -------
    Path
    """
    c, n = _vector("center", center), _unit("normal", normal)
    radius = _scalar(_validate.positive, "radius", radius)
    start_angle = _number("start_angle", start_angle)
    if (end_angle is None) == (sweep is None):
        raise PathError("give exactly one of end_angle and sweep")
    sign = _direction(direction)  # checked with sweep too: a misspelt direction was passed over
    if sweep is None:
        end_angle = _number("end_angle", end_angle)
        sweep = (sign * (end_angle - start_angle)) % (2 * np.pi)
        sweep = sign * (sweep if sweep > 1e-12 else 2 * np.pi)
    else:
        sweep = _number("sweep", sweep)
        if sign < 0 < sweep:  # the arc ran counter-clockwise, the direction given passed over
            raise PathError(f"direction 'cw' and sweep {sweep:g} > 0 (counter-clockwise) disagree: with sweep, its "
                            "sign gives the direction (negative: clockwise); direction goes with end_angle")
    e1, e2 = _plane_basis(n)
    return Path((HelicalArc(c, e1, e2, radius, start_angle, sweep, 0.0, role),))


def circle(center, radius, direction="ccw", normal=(0, 0, 1), start_angle=0.0, role="path"):
    """A full circle starting and ending at `start_angle`.

    Parameters
    ----------
    center : array_like, shape (2,) or (3,)
        Centre [mm].
    radius : float
        Radius [mm].
    direction : {"ccw", "cw"}
        Turning direction about `normal`.
    normal : array_like, shape (3,)
        Plane normal; (0, 0, 1) gives a circle in the XY plane.
    start_angle : float
        Start angle [rad], measured as in :func:`arc`.
    role : str
        Role tag.

    Returns
    -------
    Path
    """
    return arc(center, radius, start_angle, sweep=2 * np.pi * _direction(direction), normal=normal, role=role)


def helix(center, radius, pitch, turns, direction="ccw", normal=(0, 0, 1), start_angle=0.0, role="path"):
    """A helix rising along `normal`.

    Parameters
    ----------
    center : array_like, shape (3,)
        Centre of the first turn [mm] (the helix starts at this axial level).
    radius : float
        Radius [mm].
    pitch : float
        Axial rise per turn [mm]; negative descends.
    turns : float
        Number of turns (> 0).
    direction : {"ccw", "cw"}
        Turning direction about `normal`.
    normal : array_like, shape (3,)
        Helix axis.
    start_angle : float
        Start angle [rad], measured as in :func:`arc`.
    role : str
        Role tag.

    Returns
    -------
    Path
    """
    c, n = _vector("center", center), _unit("normal", normal)
    radius = _scalar(_validate.positive, "radius", radius)
    turns = _scalar(_validate.positive, "turns", turns)
    if 2 * np.pi * turns > MAX_COORDINATE:  # its sweep [rad] is held within that (said of turns, not of a sweep)
        raise PathError(f"turns = {turns:.10g} is outside [{1.0 / MAX_COORDINATE:g}, "
                        f"{MAX_COORDINATE / (2 * np.pi):.6g}], not a path a machine follows")
    pitch = _number("pitch", pitch)
    start_angle = _number("start_angle", start_angle)
    e1, e2 = _plane_basis(n)
    sweep = 2 * np.pi * turns * _direction(direction)
    return Path((HelicalArc(c, e1, e2, radius, start_angle, sweep, pitch / (2 * np.pi), role),))


def iso230_4_circle(radius, center=(0.0, 0.0), direction="ccw", run_angle=np.pi / 2, run_radius=None, start_angle=0.0,
                    overrun=np.pi / 4):
    """ISO 230-4 circular test: run-in, overrun, the full test circle, overrun, run-out.

    The run-in and run-out are arcs of radius `run_radius` inside the test
    circle, internally tangent to it and turning in the same direction, so the
    tangent is continuous at both joins (the curvature steps from
    1/run_radius to 1/radius). The run-in turns `run_angle` onto the circle
    `overrun` before the test's start point; the circle is then followed for
    `overrun`, the full 360° (role "test": the data-collection arc), and
    `overrun` again before the run-out turns `run_angle` off it. As a
    ballbar test's overshoot arcs do, the overruns keep the transient of the
    curvature step at the joins out of the data-collection arc. With the
    defaults (start at angle 0, run radius R/2, 90° run arcs, 45° overruns) a
    CCW test about (0, 0) joins the circle at -45°, measures from 0° to 360°
    and leaves it at 45°.

    Parameters
    ----------
    radius : float
        Test circle radius R [mm].
    center : array_like, shape (2,)
        Test circle centre [mm].
    direction : {"ccw", "cw"}
        Turning direction.
    run_angle : float
        Angle turned on the run-in and run-out arcs [rad], in (0, 2π].
    run_radius : float, optional
        Radius of the run-in and run-out arcs [mm], below R; R/2 by default.
    start_angle : float
        Angle of the point where the test circle starts and ends [rad].
    overrun : float
        Angle travelled on the test circle before and after the full 360°
        [rad], in [0, π].

    Returns
    -------
    Path
        Roles "run-in" (run-in arc, overrun), "test", "run-out" (overrun,
        run-out arc); without overruns when `overrun` is 0.
    """
    c = _vector("center", center)
    radius = _scalar(_validate.positive, "radius", radius)
    if run_radius is None:
        try:
            run_radius = _scalar(_validate.positive, "run_radius", radius / 2)
        except PathError:  # said as what the caller gave: the radius, not a run_radius
            least = 1.0 / MAX_COORDINATE
            raise PathError(f"run_radius (by default radius ({radius:g} mm) / 2 = {radius / 2:g} mm) is below {least:g} "
                            f"mm, the least radius of an arc: give a larger radius (at least {2 * least:g} mm), or "
                            f"run_radius (at least {least:g} mm and below the test radius)") from None
    else:
        run_radius = _scalar(_validate.positive, "run_radius", run_radius)
    if run_radius >= radius:
        raise PathError(f"run_radius ({run_radius} mm) must be below the test radius ({radius} mm)")
    run_angle = _scalar(_validate.positive, "run_angle", run_angle)
    if run_angle > 2 * np.pi:
        raise PathError(f"run_angle must be at most 2π rad, got {run_angle}")
    overrun = _scalar(_validate.nonnegative, "overrun", overrun)
    if overrun > np.pi:
        raise PathError(f"overrun must be at most π rad, got {overrun}")
    start_angle = _number("start_angle", start_angle)
    sign = _direction(direction)
    e1, e2 = np.eye(3)[0], np.eye(3)[1]
    join_in, join_out = start_angle - sign * overrun, start_angle + sign * overrun
    run_in = c + (radius - run_radius) * np.array([np.cos(join_in), np.sin(join_in), 0.0])
    run_out = c + (radius - run_radius) * np.array([np.cos(join_out), np.sin(join_out), 0.0])
    overruns = (
        (HelicalArc(c, e1, e2, radius, join_in, sign * overrun, 0.0, "run-in"),),
        (HelicalArc(c, e1, e2, radius, start_angle, sign * overrun, 0.0, "run-out"),),
    ) if overrun > 0 else ((), ())
    return Path((
        HelicalArc(run_in, e1, e2, run_radius, join_in - sign * run_angle, sign * run_angle, 0.0, "run-in"),
        *overruns[0],
        HelicalArc(c, e1, e2, radius, start_angle, sign * 2 * np.pi, 0.0, "test"),
        *overruns[1],
        HelicalArc(run_out, e1, e2, run_radius, join_out, sign * run_angle, 0.0, "run-out"),
    ))


def _ragged(name, points):
    """What makes the list `points` no (n, d) table (``"points[1] has 3 coordinates, the others 2"``), or None."""
    if not isinstance(points, (list, tuple)):
        return None
    sizes = [len(p) if isinstance(p, (list, tuple)) or np.ndim(p) == 1 else None for p in points]
    odd = next((i for i, size in enumerate(sizes) if size is None), None)
    if odd is not None:  # a number, a name: no point
        value = points[odd]
        shown = _validate.shown(repr(value) if isinstance(value, str) else str(value))
        return f"{name}[{odd}] is {shown}, not a point [x, y] or [x, y, z]"
    usual = max(sizes, key=sizes.count, default=None)  # the most points' (the first's among as many)
    odd = [i for i, size in enumerate(sizes) if size != usual]
    if not odd:
        return None
    others = "the others" if len(odd) == 1 else f"{name}[{sizes.index(usual)}]"
    return f"{name}[{odd[0]}] has {sizes[odd[0]]} coordinate{'s' * (sizes[odd[0]] != 1)}, {others} {usual}"


def _point_rows(name, points, minimum):
    ragged = _ragged(name, points)
    if ragged:
        raise PathError(ragged)
    try:
        pts = _validate.finite_array(name, points, ndim=2, limit=MAX_COORDINATE)
    except ValueError as exc:
        raise PathError(str(exc)) from None
    if pts.shape[1] not in (2, 3) or pts.shape[0] < minimum:
        raise PathError(f"{name} must have shape (n, 2) or (n, 3) with n >= {minimum}, got {pts.shape}")
    if pts.shape[1] == 2:
        pts = np.column_stack([pts, np.zeros(len(pts))])
    gaps = np.linalg.norm(np.diff(pts, axis=0), axis=1)
    if np.any(gaps < CONTINUITY_TOL):
        i = int(np.argmax(gaps < CONTINUITY_TOL))
        raise PathError(f"{name}[{i}] and {name}[{i + 1}] coincide")
    return pts, gaps


def polyline(points, blend_radius=0.0, role="path"):
    """Straight segments through `points`, corners rounded by tangent fillet arcs.

    Parameters
    ----------
    points : array_like, shape (n, 2) or (n, 3)
        Corner points [mm], n >= 2. Repeat the first point last for a closed
        contour (start it mid-edge to have no corner at the start).
    blend_radius : float
        Fillet radius [mm]; 0 keeps sharp corners.
    role : str
        Role tag of every segment.

    Returns
    -------
    Path

    Raises
    ------
    PathError
        If points coincide, the path reverses at a corner to be rounded, or
        a fillet does not fit: the tangent lengths r tan(φ/2) of a segment's
        two corners exceed its length.
    """
    pts, lengths = _point_rows("points", points, 2)
    r = _scalar(_validate.nonnegative, "blend_radius", blend_radius)
    d = np.diff(pts, axis=0) / lengths[:, None]
    # atan2(|sin|, cos), not arccos(cos): exact near 0, where arccos made a straight-through point (1 - cos ~ 1e-16)
    # a corner of 2e-8 rad, whose fillet had no inward direction (a NaN centre)
    turn = np.arctan2(np.linalg.norm(np.cross(d[:-1], d[1:]), axis=1), np.sum(d[:-1] * d[1:], axis=1))
    if r > 0 and np.any(turn > np.pi - 1e-9):  # a sharp reversal (blend_radius 0) is a stop, as in G-code
        i = int(np.argmax(turn > np.pi - 1e-9)) + 1
        raise PathError(f"polyline reverses direction at points[{i}]: no corner blend (blend_radius {r:g} mm) can "
                        "round a reversal; give blend_radius = 0, the corner then a stop")
    blend = (turn > 1e-9) & (r > 0)
    back = np.where(blend, r * np.tan(turn / 2), 0.0)
    need = np.concatenate([[0.0], back]) + np.concatenate([back, [0.0]])
    if np.any(need > lengths * (1 + 1e-12)):
        i = int(np.argmax(need > lengths * (1 + 1e-12)))
        raise PathError(
            f"blend_radius {r} mm does not fit segment {i} (points[{i}] to points[{i + 1}], "
            f"{lengths[i]:.6g} mm long): its corner blends need {need[i]:.6g} mm"
        )
    planar_xy = bool(np.all(pts[:, 2] == 0.0))
    prims, here = [], pts[0]
    for i in range(len(d)):
        stop = pts[i + 1] - (back[i] if i < len(back) else 0.0) * d[i]
        if np.linalg.norm(stop - here) > CONTINUITY_TOL:
            prims.append(Line(here, stop, role))
        here = stop
        if i < len(back) and blend[i]:
            inward = d[i + 1] - (d[i + 1] @ d[i]) * d[i]
            axis = np.cross(d[i], d[i + 1])
            axis /= np.linalg.norm(axis)
            sweep = turn[i]
            if planar_xy and axis[2] < 0:
                axis, sweep = -axis, -sweep
            center = here + r * inward / np.linalg.norm(inward)
            prims.append(_arc_from_point(center, here, axis, sweep, 0.0, role))
            here = pts[i + 1] + back[i] * d[i + 1]
    return Path(tuple(prims))


def _spline_slopes(chord, slope, closed):
    """First derivatives dP/ds at the knots of a C2 cubic spline, shape (n, 3).

    The tridiagonal system of scipy's ``CubicSpline`` (``bc_type``
    ``"natural"`` or ``"periodic"``), solved as it does
    (``scipy.linalg.solve_banded``; ``scipy.interpolate`` would cost a
    quarter of a second more to import). For the interior knots
    ``dx[i]·s[i-1] + 2(dx[i-1] + dx[i])·s[i] + dx[i-1]·s[i+1] = 3(dx[i]·slope[i-1] + dx[i-1]·slope[i])``;
    a natural end has no curvature: ``2·s[0] + s[1] = 3·slope[0]``.

    Parameters
    ----------
    chord : ndarray, shape (n,)
        Knots: cumulative chord length [mm].
    slope : ndarray, shape (n - 1, 3)
        Chord slopes ``ΔP / dx`` [-].
    closed : bool
        Periodic (the last knot repeats the first; n >= 4) or natural ends.
    """
    n, dx = chord.size, np.diff(chord)
    band = np.zeros((3, n))  # upper diagonal, diagonal, lower diagonal (solve_banded's layout)
    band[1, 1:-1] = 2 * (dx[:-1] + dx[1:])
    band[0, 2:] = dx[:-1]
    band[2, :-2] = dx[1:]
    rhs = np.empty((n, 3))
    rhs[1:-1] = 3 * (dx[1:, None] * slope[:-1] + dx[:-1, None] * slope[1:])
    if not closed:  # the end rows scaled by their interval, as the others are
        band[1, 0], band[0, 1], rhs[0] = 2 * dx[0], dx[0], 3 * dx[0] * slope[0]
        band[1, -1], band[2, -2], rhs[-1] = 2 * dx[-1], dx[-1], 3 * dx[-1] * slope[-1]
        return solve_banded((1, 1), band, rhs, overwrite_ab=True, overwrite_b=True, check_finite=False)
    # Periodic: unknowns s[0] .. s[n-2] (s[n-1] = s[0]), a cyclic system. With the last unknown s[n-2] taken out,
    # the n - 2 rows left are tridiagonal: solved for the right-hand side (s1) and for the column of s[n-2] (s2),
    # s = s1 + s[n-2]·s2, and s[n-2] from the last row.
    band[1, 0], band[0, 1] = 2 * (dx[-1] + dx[0]), dx[-1]
    rhs[0] = 3 * (dx[0] * slope[-1] + dx[-1] * slope[0])
    m = n - 2
    column = np.zeros((m, 1))
    column[0], column[-1] = -dx[0], -dx[-3]
    s1, s2 = (solve_banded((1, 1), band[:, :m], b, check_finite=False) for b in (rhs[:m], column))
    last = (rhs[m] - dx[-2] * s1[0] - dx[-1] * s1[-1]) / (2 * (dx[-1] + dx[-2]) + dx[-2] * s2[0] + dx[-1] * s2[-1])
    return np.vstack([s1 + last * s2, last, s1[0] + last * s2[0]])


def spline(points, closed=False, role="path"):
    """C2 cubic spline through `points`, chord-length parameterised.

    An open spline has natural ends (no curvature at its first and last
    point). Not-a-knot ends (scipy's default) make the first and last piece
    the same cubic as their neighbour: where a long piece meets a tight turn
    that cubic, carried over the long piece, swings far out (a 106-mm hairpin,
    ``[[0, 0], [50, 0], [52, 2], [50, 4], [0, 4]]``, became a 407-mm loop out
    to x = -74 mm; with natural ends it stays within x 0 to 52 mm, 110 mm long).

    Parameters
    ----------
    points : array_like, shape (n, 2) or (n, 3)
        Points the curve passes through [mm]; n >= 2 (open) or n >= 3 (closed).
    closed : bool
        Periodic spline back to the first point (C2 there too). A repeated
        first point at the end is accepted and dropped.
    role : str
        Role tag of every piece.

    Returns
    -------
    Path
        One :class:`SplinePiece` per interval.
    """
    closed = _validate.flag("closed", closed)
    pts, _ = _point_rows("points", points, 3 if closed else 2)
    if closed:
        if np.linalg.norm(pts[-1] - pts[0]) > CONTINUITY_TOL:
            pts = np.vstack([pts, pts[:1]])
        pts[-1] = pts[0]
        if len(pts) < 4:
            raise PathError("a closed spline needs at least 3 distinct points")
    chord = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(pts, axis=0), axis=1))])
    h = np.diff(chord)[:, None]
    delta = np.diff(pts, axis=0) / h  # chord slopes
    slopes = _spline_slopes(chord, delta, closed)
    # the Hermite cubic of each interval in powers of (s - s_i), as scipy's CubicHermiteSpline writes it, then in w
    t = (slopes[:-1] + slopes[1:] - 2 * delta) / h
    c1, c2, c3 = slopes[:-1], (delta - slopes[:-1]) / h - t, t / h
    coefs = np.stack([pts[:-1], c1 * h, c2 * h**2, c3 * h**3], axis=1)  # (K, 4, 3): a, b, c, d of P(w)
    # snap each piece's end onto the next start (rounding of the polynomial sum)
    coefs[:-1, 3] += pts[1:-1] - coefs[:-1].sum(axis=1)
    rows, curvature, cusps = _spline_rows(coefs)
    if cusps.size:
        i = int(cusps[0])
        raise PathError(f"spline piece {i} (points[{i}] to points[{i + 1}]): {_CUSP}")
    return Path(tuple(SplinePiece._pieces(coefs, rows, curvature, role)))
