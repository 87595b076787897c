"""The cross-coupled loop, linearised: its matrices, margins along a path, and the design of its gains.

A cross-coupled controller (:class:`contoursim.compensation.CrossCoupled`,
:class:`contoursim.kernel.Coupling`) closes a PID of the estimated contour
error around the axes' sampled loops. Frozen at a point of the path, the
estimate is linear in the fed-back positions, with the path's frame there
as its gradient (:func:`path_frames`), and the coupled loop is the axes'
loops (:func:`contoursim.kernel.loop_matrices`) with the PID closed across
that frame (:func:`coupled_margins`, :func:`coupled_spectral_radius`).
:func:`designed_gains` chooses the coupling gains on it; the strategy
checks a run's gains on it as :func:`contoursim.servo.check` checks an
axis loop.
"""

import dataclasses
import hashlib
import math
import sys
from functools import lru_cache
from pathlib import Path

import numpy as np

from . import kernel
from ._numba import njit
from .estimators import _three_point_arc, distinct_samples, search_params

__all__ = [
    "DESIGN_DAMPING_RATIO",
    "FRAME_KNOTS",
    "coupled_margins",
    "coupled_spectral_radius",
    "designed_gains",
    "margins_along",
    "path_frames",
]


#: The closed-loop damping ratio the coupling's default gains are designed for [-].
DESIGN_DAMPING_RATIO = 0.7


def designed_gains(servos, dt, kd=0.0, kp=None):
    """Coupling gains ``(kp, ki)`` designed on the sampled loops for :data:`DESIGN_DAMPING_RATIO`.

    ``ki = K^2/4`` with ``K = Kp + kp`` (``Kp`` the smallest position gain
    of the coupled axes): the PI corner ``ki/K`` a quarter of the contour
    loop's gain. ``kp`` is the largest gain for which the least damped
    pole of the sampled coupled loop (:func:`coupled_margins`), closed
    across every straight line of :func:`_directions`, has a damping ratio
    of at least :data:`DESIGN_DAMPING_RATIO` (bisection to 1e-6 relative),
    among the poles that last longer than a servo period (``|z| > 1/e``:
    faster ones, such as the alternating poles of a drive's velocity
    filter, ``z ≈ -0.1`` for two taps, have settled before they could
    ring); a given `kp` is kept and only ``ki`` follows from it.

    Parameters
    ----------
    servos : mapping str -> AxisServo
        The coupled axes' model.
    dt : float
        Servo period [s].
    kd : float
        Derivative gain [-].
    kp : float, optional
        A coupling gain to keep [1/s].

    Returns
    -------
    tuple of float
        ``(kp, ki)`` [1/s], [1/s^2].

    Raises
    ------
    ValueError
        Even a coupling gain of 1 % of ``Kp`` leaves the loop damped below
        the design ratio (the axes' own loops are).
    """
    servos = list(servos.values())
    position_gain = min(servo.kp for servo in servos)
    if kp is not None:
        return kp, (position_gain + kp) ** 2 / 4.0
    rows = _loop_rows([kernel.pack(servo, dt) for servo in servos])
    kp = _designed_kp(rows.tobytes(), rows.shape, position_gain, dt, kd)
    return kp, (position_gain + kp) ** 2 / 4.0


def _loop_rows(rows):
    """Packed rows (n, NPAR) as the loop analyses key them: the feedforward gains, which act on the reference and not
    on the loop, zeroed, so that a strategy with feedforward shares the analyses of the same loop without it."""
    rows = np.array(rows, float)
    rows[:, [kernel._VFF, kernel._AFF]] = 0.0
    return rows


@lru_cache(maxsize=256)
def _designed_kp(rows, shape, position_gain, dt, kd):
    """The bisection of :func:`designed_gains` for packed rows given as bytes: once per set of axes, stored on disk."""
    from .servo import _stored

    key = hashlib.sha256(repr((rows, shape, position_gain, dt, kd, _code())).encode()).hexdigest()
    return _stored("coupling_gains", key, lambda: _bisected_kp(np.frombuffer(rows).reshape(shape), position_gain, dt, kd))


def _bisected_kp(rows, position_gain, dt, kd):
    """The coupling's kp [1/s] that damps the coupled loop at :data:`DESIGN_DAMPING_RATIO` on its worst line (bisection)."""
    from .servo import _damping_ratio

    directions = _directions(len(rows))

    def damping(kp):
        ki = (position_gain + kp) ** 2 / 4.0
        poles = (np.linalg.eigvals(a + b @ c) for a, b, c in (_coupled_system(rows, kp, ki, kd, dt, d) for d in directions))
        return min(_damping_ratio(p, dt) for p in poles)

    low, high = 0.01 * position_gain, position_gain
    if damping(low) < DESIGN_DAMPING_RATIO:
        why = (f"with kd = {kd:g}: lower it" if kd else "the axes' own loops are that little damped")
        raise ValueError(f"the coupled loop is damped at {damping(low):.3g} < {DESIGN_DAMPING_RATIO:g} even with "
                         f"kp = {low:g} 1/s ({why}): set the coupling gains kp, ki")
    while damping(high) >= DESIGN_DAMPING_RATIO:
        low, high = high, 2.0 * high
    while high - low > 1e-6 * high:
        middle = 0.5 * (low + high)
        low, high = (middle, high) if damping(middle) >= DESIGN_DAMPING_RATIO else (low, middle)
    return low


def _directions(n):
    """Unit normals of the straight lines the stability check closes the coupling across."""
    angles = np.radians(np.arange(0.0, 180.0, 15.0))
    if n == 2:
        return [np.array([math.cos(a), math.sin(a)]) for a in angles]
    return [np.array([math.cos(a) * math.cos(e), math.sin(a) * math.cos(e), math.sin(e)])
            for a in angles for e in np.radians((0.0, 30.0, 60.0))] + [np.array([0.0, 0.0, 1.0])]  # fmt: skip


def coupled_spectral_radius(rows, kp, ki, kd, dt, normal):
    """Spectral radius of the sampled axis loops with the cross-coupled controller closed across a line.

    On a straight line of unit normal `normal` the coupling is linear and
    time-invariant: ``ε = normal · (x_fb - x_ref)``, ``u = kp·ε + ki·∫ε dt +
    kd·dε/dt`` (trapezoidal integral, backward difference, as in the
    kernel) and every axis's velocity command gets ``-normal_a · u``.

    Parameters
    ----------
    rows : sequence of ndarray, shape (NPAR,)
        The coupled axes' packed rows (:func:`contoursim.kernel.pack`).
    kp, ki, kd : float
        Coupling gains [1/s], [1/s^2], [-].
    dt : float
        Servo period [s].
    normal : array_like, shape (len(rows),)
        Unit normal of the line in the coupled axes [-].

    Returns
    -------
    float
        ``max |λ|`` of the coupled loop's transition matrix; < 1 is stable.
    """
    A, B, C = _coupled_system(rows, kp, ki, kd, dt, normal)
    return float(np.abs(np.linalg.eigvals(A + B @ C)).max())


def _coupled_system(rows, kp, ki, kd, dt, normals):
    """The sampled axis loops with the coupling's PID on each error channel, the channels open.

    State: the axes' loop states (:func:`contoursim.kernel.loop_matrices`),
    then per channel the integral of its error (when ``ki > 0``) and its
    previous error. Input ``e`` (k,): what each channel's PID reads; output
    ``ε = N·x_fb`` (k,) [mm], the linearised contour error of the channels
    (rows of `normals`). ``e = ε`` closes the coupling.

    Returns
    -------
    A : ndarray, shape (S, S)
    B : ndarray, shape (S, k)
    C : ndarray, shape (k, S)
    """
    normals = np.atleast_2d(np.asarray(normals, float))
    k = normals.shape[0]
    loops = [kernel.loop_matrices(row) for row in rows]
    sizes = [phi.shape[0] for phi, _, _ in loops]
    n_axes = sum(sizes)
    B_w = np.zeros((n_axes, len(rows)))  # the extra velocity command of each axis
    C_x = np.zeros((len(rows), n_axes))  # each axis's fed-back position
    A = np.zeros((n_axes, n_axes))
    start = 0
    for a, ((phi_a, b_a, c_a), size) in enumerate(zip(loops, sizes)):
        A[start : start + size, start : start + size] = phi_a
        B_w[start : start + size, a], C_x[a, start : start + size] = b_a, c_a
        start += size
    # u = g0·e + ki·z - kd/dt·e_prev (trapezoidal integral, backward difference, as in the kernel); w = -Nᵀ·u
    push = -B_w @ normals.T  # (n_axes, k): the axes' response to the channels' outputs
    integral = ki != 0.0  # without an integrator its state (an eigenvalue 1 nothing reads) is not part of the loop
    size = n_axes + (1 + integral) * k
    z, prev = n_axes, n_axes + integral * k
    A_full, B_full, C_full = np.zeros((size, size)), np.zeros((size, k)), np.zeros((k, size))
    A_full[:n_axes, :n_axes] = A
    if integral:
        A_full[:n_axes, z : z + k] = ki * push
        A_full[z : z + k, z : z + k] = np.eye(k)
        B_full[z : z + k] = dt * np.eye(k)
    A_full[:n_axes, prev : prev + k] = -(kd / dt) * push
    B_full[:n_axes] = (kp + 0.5 * ki * dt + kd / dt) * push
    B_full[prev : prev + k] = np.eye(k)
    C_full[:, :n_axes] = normals @ C_x
    return A_full, B_full, C_full


@dataclasses.dataclass(frozen=True)
class _Loop:
    """A sampled SISO loop gain as :func:`contoursim.servo.margins` analyses one (without importing python-control)."""

    A: np.ndarray
    B: np.ndarray
    C: np.ndarray
    D: np.ndarray
    dt: float

    @property
    def nstates(self):
        return self.A.shape[0]


@lru_cache(maxsize=4096)
def _stored_margins(rows, shape, kp, ki, kd, dt, normals, k):
    """:func:`coupled_margins` of rows and normals given as bytes: analysed once per loop and frame, and stored on disk
    like an axis loop's margins (:func:`contoursim.servo._stored`, keyed by the inputs and the code that analyses)."""
    from .servo import _stored

    key = hashlib.sha256(repr((rows, shape, kp, ki, kd, dt, normals, k, _code())).encode()).hexdigest()
    return _stored("coupled_margins", key, lambda: coupled_margins(
        np.frombuffer(rows).reshape(shape), kp, ki, kd, dt, np.frombuffer(normals).reshape(k, -1)))


@lru_cache(maxsize=1)
def _code():
    """Digest of the modules a coupled loop's analysis runs: this one, the kernel's loop matrices, the servo's margins."""
    from . import servo

    return hashlib.sha256(b"".join(Path(m.__file__).read_bytes() for m in (sys.modules[__name__], kernel, servo))).hexdigest()


def coupled_margins(rows, kp, ki, kd, dt, normals):
    """Margins of the coupled sampled loop linearised across one frame of the path, as an axis loop's (:func:`~.servo.margins`).

    The coupling's error channels are the rows of `normals` (the in-plane
    normal, and for three axes the plane normal): the estimator's
    linearisation at a point of the path. Each channel's loop gain is
    broken at its PID's input with the other channels closed (loop at a
    time); the damping ratio and the spectral radius are those of the
    whole closed loop.

    Parameters
    ----------
    rows : sequence of ndarray, shape (NPAR,)
        The coupled axes' packed rows (:func:`contoursim.kernel.pack`).
    kp, ki, kd : float
        Coupling gains [1/s], [1/s^2], [-].
    dt : float
        Servo period [s].
    normals : array_like, shape (k, len(rows))
        Unit error directions of the channels in the coupled axes [-].

    Returns
    -------
    dict
        ``spectral_radius`` [-], ``damping_ratio`` [-] (the least damped
        closed-loop pole), ``stable``, and over the channels the smallest
        ``phase_margin`` [deg] and ``gain_margin`` [-] with the
        ``gain_crossover`` [rad/s] of the phase margin.
    """
    from .servo import _damping_ratio, _loop_margins

    A, B, C = _coupled_system(rows, kp, ki, kd, dt, normals)
    poles = np.linalg.eigvals(A + B @ C)
    radius = float(np.abs(poles).max())
    result = dict(spectral_radius=radius, damping_ratio=_damping_ratio(poles, dt), stable=radius < 1.0,
                  phase_margin=np.inf, gain_margin=np.inf, gain_crossover=np.nan)
    for j in range(C.shape[0]):
        others = [i for i in range(C.shape[0]) if i != j]
        m = _loop_margins(_Loop(A + B[:, others] @ C[others], B[:, [j]], -C[[j]], np.zeros((1, 1)), dt))  # 1 + L = 0
        if m["phase_margin"] < result["phase_margin"]:
            result["phase_margin"], result["gain_crossover"] = m["phase_margin"], m["gain_crossover"]
        result["gain_margin"] = min(result["gain_margin"], m["gain_margin"])
    return result


#: The most knots of a path whose frames :func:`path_frames` computes (evenly spread).
FRAME_KNOTS = 20_000


def path_frames(path, up=(0.0, 0.0, 1.0), resolution_deg=5.0):
    """The arc estimator's linearisation along a path: its error directions, one representative per direction bin.

    At a knot of the path the estimate's gradient with respect to the
    position is the frame of the three-point arc there (the in-plane
    normal ``l = b × t`` and, for three axes, the plane normal ``b``),
    whatever the curvature; the linear estimator's is the same frame. The
    frames at up to :data:`FRAME_KNOTS` knots evenly spread along the path
    are binned at `resolution_deg`.

    Parameters
    ----------
    path : array_like, shape (N, n)
        The coupled axes' target path [mm], n = 2 or 3.
    up : array_like, shape (3,)
        Orients the plane normal (as :class:`~contoursim.compensation.CrossCoupled`'s `up`).
    resolution_deg : float
        Bin width of the directions [deg].

    Returns
    -------
    list of tuple
        ``(sample, normals)``: the first reference sample of each bin and
        its error directions, shape (1, 2) for two axes, (2, 3) for three.
    """
    path = np.asarray(path, float)
    n = path.shape[1]
    knots, first, _ = distinct_samples(path)
    up = tuple(float(c) for c in search_params(up)[:3])
    taken = np.arange(0, len(knots), max(1, len(knots) // FRAME_KNOTS))
    t, b = _arc_frames(knots, taken, up)
    normals = np.cross(b, t)[:, None, :2] if n == 2 else np.stack([np.cross(b, t), b], axis=1)  # (M, k, n)
    if n == 2:  # the normal's direction modulo 180° (±normal: the same loop)
        bins = round(180.0 / resolution_deg)
        angle = np.degrees(np.arctan2(normals[:, 0, 1], normals[:, 0, 0])) % 180.0
        keys = (np.round(angle / resolution_deg).astype(np.int64) % bins)[:, None]
    else:  # each direction with its largest component positive (±: the same loop), binned by its components
        flip = np.take_along_axis(normals, np.abs(normals).argmax(axis=2)[..., None], axis=2) < 0
        angles = np.degrees(np.arcsin(np.clip(np.where(flip, -normals, normals), -1.0, 1.0)))
        keys = np.round(angles.reshape(len(taken), -1) / resolution_deg).astype(np.int64)
    _, representative = np.unique(keys, axis=0, return_index=True)
    return [(int(first[taken[j]]), normals[j]) for j in np.sort(representative)]


@njit(cache=True)
def _arc_frames(knots, taken, up):
    """Tangents and binormals of the three-point arcs at the knots `taken`, shape (len(taken), 3) each."""
    t, b = np.empty((taken.size, 3)), np.empty((taken.size, 3))
    for j in range(taken.size):
        _, tj, bj, _ = _three_point_arc(knots, taken[j], up)
        t[j, 0], t[j, 1], t[j, 2] = tj
        b[j, 0], b[j, 1], b[j, 2] = bj
    return t, b


def margins_along(rows, kp, ki, kd, dt, path, up=(0.0, 0.0, 1.0)):
    """The worst of the coupled loop's margins over the frames of a path (:func:`path_frames`, :func:`coupled_margins`).

    Parameters
    ----------
    rows : sequence of ndarray, shape (NPAR,)
        The coupled axes' packed rows (:func:`contoursim.kernel.pack`).
    kp, ki, kd : float
        Coupling gains [1/s], [1/s^2], [-].
    dt : float
        Servo period [s].
    path : array_like, shape (N, len(rows))
        The coupled axes' target path [mm].
    up : array_like, shape (3,)
        Orients the plane normal.

    Returns
    -------
    dict
        ``spectral_radius``, ``damping_ratio``, ``phase_margin`` [deg],
        ``gain_margin`` [-] as :func:`coupled_margins` gives them, each the
        worst over the frames; ``frames`` (how many) and ``sample`` (the
        reference sample of the frame with the least phase margin).
    """
    rows = _loop_rows(rows)
    worst = dict(spectral_radius=0.0, damping_ratio=np.inf, phase_margin=np.inf, gain_margin=np.inf, sample=0)
    frames = path_frames(path, up)
    for sample, normals in frames:
        m = _stored_margins(rows.tobytes(), rows.shape, kp, ki, kd, dt, normals.tobytes(), normals.shape[0])
        if m["phase_margin"] < worst["phase_margin"]:
            worst["phase_margin"], worst["sample"] = m["phase_margin"], sample
        worst["spectral_radius"] = max(worst["spectral_radius"], m["spectral_radius"])
        worst["damping_ratio"] = min(worst["damping_ratio"], m["damping_ratio"])
        worst["gain_margin"] = min(worst["gain_margin"], m["gain_margin"])
    worst["frames"] = len(frames)
    return worst
