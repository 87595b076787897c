"""Compiled per-sample loops of the multibody chain: tool pose, axis Jacobian, least-squares step.

:class:`contoursim.multibody.MachineChain` describes the chain; these loops
walk it one sample at a time so that nothing of size (N, 3, 3) or (N, k, k)
is ever stacked. The chain reaches them as flat arrays: a program of steps
for the tool pose, one entry per body (``MachineChain.arrays``) for the
Jacobian. Body kinds: 0 fixed, 1 linear, 2 rotary.
"""

import numpy as np

from ._numba import njit

__all__ = ["rotation", "rotated", "CONSTANT", "LINEAR", "ROTARY", "THERMAL", "ERROR", "tool_pose", "axis_jacobian", "prioritized_inverse", "newton_update"]


@njit(cache=True)
def rotation(wx, wy, wz):
    """The coefficients (a, b) of :func:`rotated` for the rotation vector w: a = sin θ/θ, b = (1 − cos θ)/θ², θ = |w|.

    Below θ = 0.01 (every error motion, most steps of a chain) by their
    series to θ⁴: the first term left out, θ⁶/5040, is below 2e-16 there,
    and no sine, cosine or root is taken.
    """
    th2 = wx * wx + wy * wy + wz * wz
    if th2 < 1e-4:
        return 1.0 - th2 / 6.0 * (1.0 - th2 / 20.0), 0.5 - th2 / 24.0 * (1.0 - th2 / 30.0)
    th = np.sqrt(th2)
    return np.sin(th) / th, (1.0 - np.cos(th)) / th2


@njit(cache=True)
def rotated(vx, vy, vz, wx, wy, wz, a, b):
    """The vector v rotated by the rotation vector w (exact, Rodrigues), with (a, b) = :func:`rotation` (w).

    ``v + a (w × v) + b w × (w × v)``; one :func:`rotation` serves every
    vector turned by the same w.
    """
    cx, cy, cz = wy * vz - wz * vy, wz * vx - wx * vz, wx * vy - wy * vx
    return vx + a * cx + b * (wy * cz - wz * cy), vy + a * cy + b * (wz * cx - wx * cz), vz + a * cz + b * (wx * cy - wy * cx)


#: Step kinds of a program (see :func:`tool_pose`).
CONSTANT, LINEAR, ROTARY, THERMAL, ERROR = range(5)


@njit(cache=True)
def tool_pose(q, times, err, tip, axis, kind, inverse, column, vector):
    """Tool tip and tool axis in workpiece coordinates, each shape (N, 3).

    The chain is a program of S steps, applied in order to the tool tip and
    tool axis (from the tool frame out to the bed, then in to the
    workpiece frame). Step i is a rotation w then a translation d,
    ``x -> R(w) x + d``, or when ``inverse[i]`` its inverse
    ``x -> R(-w)(x - d)``; its ``kind[i]`` says where (w, d) come from, with
    ``vector[i]`` (6,) and the axis ``column[i]``:

    - CONSTANT: w = vector[:3], d = vector[3:];
    - LINEAR: d = q[n, column]·vector[3:] (vector holds sign × direction);
    - ROTARY: w = q[n, column]·vector[:3];
    - THERMAL: w = τ·vector[:3], d = τ·vector[3:] with τ = times[column, n]
      (the time, or its first-order form, :meth:`Body.thermal_time`);
    - ERROR: (d, w) = err[column, :, n] (a twist dx, dy, dz, ex, ey, ez).

    Rotations are exact (Rodrigues).
    """
    size = q.shape[0]
    out = np.empty((size, 6))
    for n in range(size):
        px, py, pz = tip[0], tip[1], tip[2]
        vx, vy, vz = axis[0], axis[1], axis[2]
        for i in range(kind.size):
            k = kind[i]
            c = vector[i]
            if k == CONSTANT:
                wx, wy, wz, dx, dy, dz = c[0], c[1], c[2], c[3], c[4], c[5]
            elif k == LINEAR:
                x = q[n, column[i]]
                wx, wy, wz, dx, dy, dz = 0.0, 0.0, 0.0, x * c[3], x * c[4], x * c[5]
            elif k == ROTARY:
                x = q[n, column[i]]
                wx, wy, wz, dx, dy, dz = x * c[0], x * c[1], x * c[2], 0.0, 0.0, 0.0
            elif k == THERMAL:
                x = times[column[i], n]
                wx, wy, wz, dx, dy, dz = x * c[0], x * c[1], x * c[2], x * c[3], x * c[4], x * c[5]
            else:
                e = err[column[i]]
                wx, wy, wz, dx, dy, dz = e[3, n], e[4, n], e[5, n], e[0, n], e[1, n], e[2, n]
            if inverse[i]:
                px, py, pz = px - dx, py - dy, pz - dz
                wx, wy, wz = -wx, -wy, -wz
            if wx != 0.0 or wy != 0.0 or wz != 0.0:
                a, b = rotation(wx, wy, wz)
                px, py, pz = rotated(px, py, pz, wx, wy, wz, a, b)
                vx, vy, vz = rotated(vx, vy, vz, wx, wy, wz, a, b)
            if not inverse[i]:
                px, py, pz = px + dx, py + dy, pz + dz
        out[n, 0], out[n, 1], out[n, 2] = px, py, pz
        out[n, 3], out[n, 4], out[n, 5] = vx, vy, vz
    return out


@njit(cache=True)
def _rotate_columns(R, w):
    """R <- Rot(w) R (exact), for a 3x3 R."""
    if w[0] == 0.0 and w[1] == 0.0 and w[2] == 0.0:
        return
    a, b = rotation(w[0], w[1], w[2])
    for c in range(3):
        R[0, c], R[1, c], R[2, c] = rotated(R[0, c], R[1, c], R[2, c], w[0], w[1], w[2], a, b)


@njit(cache=True)
def axis_jacobian(q, n_axes, tool, workpiece, tip, axis, order, parent, kind, column, direction, sign, offset, side):
    """d(P_w, V_w)/dq of the ideal chain, shape (N, 6, n_axes).

    Every body's static and motion frames (R, o) in bed coordinates are
    built in `order` (parents first); a unit twist of a moving joint at its
    static frame moves the tool by ``side · R_wᵀ (d + e × (p − o), e × v)``.
    """
    size = q.shape[0]
    nb = parent.size
    out = np.zeros((size, 6, n_axes))
    Rs = np.empty((nb + 1, 3, 3))  # static frames (index = body number, 0 = bed)
    os_ = np.empty((nb + 1, 3))
    Rm = np.zeros((nb + 1, 3, 3))  # motion frames
    om = np.zeros((nb + 1, 3))
    for r in range(3):
        Rm[0, r, r] = 1.0
    w = np.empty(3)
    p = np.empty(3)
    v = np.empty(3)
    dp = np.empty(3)
    dv = np.empty(3)
    for n in range(size):
        for i in range(nb):
            j = order[i] + 1
            b = j - 1
            par = parent[b]
            for r in range(3):
                os_[j, r] = om[par, r] + Rm[par, r, 0] * offset[b, 0] + Rm[par, r, 1] * offset[b, 1] + Rm[par, r, 2] * offset[b, 2]
                om[j, r] = os_[j, r]
                for c in range(3):
                    Rs[j, r, c] = Rm[par, r, c]
                    Rm[j, r, c] = Rm[par, r, c]
            if kind[b] != 0:
                xi = sign[b] * q[n, column[b]]
                d = direction[b]
                if kind[b] == 1:
                    for r in range(3):
                        om[j, r] += xi * Rs[j, r, d]
                else:
                    for r in range(3):
                        w[r] = xi * Rs[j, r, d]
                    _rotate_columns(Rm[j], w)
        for r in range(3):
            p[r] = om[tool, r] + Rm[tool, r, 0] * tip[0] + Rm[tool, r, 1] * tip[1] + Rm[tool, r, 2] * tip[2]
            v[r] = Rm[tool, r, 0] * axis[0] + Rm[tool, r, 1] * axis[1] + Rm[tool, r, 2] * axis[2]
        for b in range(nb):
            if kind[b] == 0 or side[b] == 0.0:
                continue
            j = b + 1
            d = direction[b]
            ex, ey, ez = Rs[j, 0, d] * sign[b], Rs[j, 1, d] * sign[b], Rs[j, 2, d] * sign[b]
            if kind[b] == 1:
                dp[0], dp[1], dp[2] = ex, ey, ez
                dv[:] = 0.0
            else:
                rx, ry, rz = p[0] - os_[j, 0], p[1] - os_[j, 1], p[2] - os_[j, 2]
                dp[0], dp[1], dp[2] = ey * rz - ez * ry, ez * rx - ex * rz, ex * ry - ey * rx
                dv[0], dv[1], dv[2] = ey * v[2] - ez * v[1], ez * v[0] - ex * v[2], ex * v[1] - ey * v[0]
            c = column[b]
            for r in range(3):
                out[n, r, c] += side[b] * (Rm[workpiece, 0, r] * dp[0] + Rm[workpiece, 1, r] * dp[1] + Rm[workpiece, 2, r] * dp[2])
                out[n, 3 + r, c] += side[b] * (Rm[workpiece, 0, r] * dv[0] + Rm[workpiece, 1, r] * dv[1] + Rm[workpiece, 2, r] * dv[2])
    return out


@njit(cache=True)
def _eigh3(A, lam, U):
    """Eigenvalues `lam` and eigenvectors (columns of `U`) of a symmetric 3x3 `A` (cyclic Jacobi; `A` is overwritten)."""
    U[:] = 0.0
    for i in range(3):
        U[i, i] = 1.0
    for _ in range(50):
        off = A[0, 1] * A[0, 1] + A[0, 2] * A[0, 2] + A[1, 2] * A[1, 2]
        scale = A[0, 0] * A[0, 0] + A[1, 1] * A[1, 1] + A[2, 2] * A[2, 2]
        if off <= 1e-36 * scale:
            break
        for p, r in ((0, 1), (0, 2), (1, 2)):
            if A[p, r] == 0.0:
                continue
            theta = (A[r, r] - A[p, p]) / (2.0 * A[p, r])
            tan = (1.0 if theta >= 0 else -1.0) / (abs(theta) + np.sqrt(theta * theta + 1.0))
            c = 1.0 / np.sqrt(tan * tan + 1.0)
            s = tan * c
            for k in range(3):  # A <- Jᵀ A J, U <- U J
                akp, akr = A[k, p], A[k, r]
                A[k, p] = c * akp - s * akr
                A[k, r] = s * akp + c * akr
            for k in range(3):
                apk, ark = A[p, k], A[r, k]
                A[p, k] = c * apk - s * ark
                A[r, k] = s * apk + c * ark
            for k in range(3):
                ukp, ukr = U[k, p], U[k, r]
                U[k, p] = c * ukp - s * ukr
                U[k, r] = s * ukp + c * ukr
    for i in range(3):
        lam[i] = A[i, i]


@njit(cache=True)
def _adjugate3(M):
    """The adjugate of a symmetric 3x3 `M` (its cofactors): entries 00, 11, 22, 01, 02, 12."""
    return (
        M[1, 1] * M[2, 2] - M[1, 2] * M[1, 2],
        M[0, 0] * M[2, 2] - M[0, 2] * M[0, 2],
        M[0, 0] * M[1, 1] - M[0, 1] * M[0, 1],
        M[0, 2] * M[1, 2] - M[0, 1] * M[2, 2],
        M[0, 1] * M[1, 2] - M[0, 2] * M[1, 1],
        M[0, 1] * M[0, 2] - M[0, 0] * M[1, 2],
    )


@njit(cache=True)
def _pinv3(A, rcond, floor, X, s, As, G, lam, U, v):
    """Least-squares operator X (k, 3) of A x = b for a (3, k) A (x = X b).

    Columns are divided by their norm, but at least by `floor`; directions
    whose eigenvalue of the scaled normal equations is below `rcond` are
    dropped. The nonzero eigenvalues of AᵀA (k x k) are those of AAᵀ
    (3 x 3): with AAᵀ = U Λ Uᵀ the kept eigenvectors of AᵀA are Aᵀu/√λ, so
    ``X = Σ Aᵀu uᵀ/λ`` (scaled variables), that is ``X = Aᵀ G⁺`` with
    G = AAᵀ and G⁺ the inverse of its kept part, taken without the
    eigenvectors in the common cases (a margin of two for rounding in each
    bound):

    - all three kept (a well-conditioned position): G⁺ = G⁻¹, where
      λ_min ≥ 4 det G / (tr G)² > `rcond` (the two larger eigenvalues'
      product is at most (tr G / 2)²);
    - one eigenvalue zero to rounding, the other two kept (the tool axis:
      a unit vector turns in a plane): with m the sum of G's principal
      minors (= λ₁λ₂ there) and ``P = adj G / m`` the projector onto the
      zero one's eigenvector, G⁺ = (G + P)⁻¹ − P, where
      det G ≤ 1e-13 m tr G and λ_min ≥ m / tr G > `rcond`;
    - two eigenvalues zero to rounding, one kept (the tool axis with one
      turn left to it): G = λ u uᵀ with λ = tr G, so G⁺ = G / (tr G)²,
      where m ≤ 1e-13 (tr G)² and tr G > `rcond`;
    - none kept, where tr G ≤ `rcond` / 2 (no eigenvalue exceeds the
      trace): X = 0.

    The projector onto the directions left free is ``I − X A``: in the
    scaled variables ``I − Σ Aᵀu uᵀA/λ``, and scaling by ``S = diag(s)``
    turns it into ``S⁻¹ (I − Xs As) S = I − X A``. `s`, `As`, `G`, `lam`,
    `U`, `v` are work arrays.
    """
    k = A.shape[1]
    for c in range(k):
        s[c] = max(np.sqrt(A[0, c] ** 2 + A[1, c] ** 2 + A[2, c] ** 2), floor)
        for r in range(3):
            As[r, c] = A[r, c] / s[c]
    for r in range(3):
        for q in range(3):
            g = 0.0
            for c in range(k):
                g += As[r, c] * As[q, c]
            G[r, q] = g
    X[:] = 0.0
    a00, a11, a22, a01, a02, a12 = _adjugate3(G)
    det = G[0, 0] * a00 + G[0, 1] * a01 + G[0, 2] * a02
    trace = G[0, 0] + G[1, 1] + G[2, 2]
    minors = a00 + a11 + a22
    full = det > 0.5 * rcond * trace * trace  # all three kept
    plane = det <= 1e-13 * minors * trace and minors > 2.0 * rcond * trace  # one zero, two kept
    line = minors <= 1e-13 * trace * trace and trace > 2.0 * rcond  # two zero, one kept
    if full or plane or line:  # U <- G⁺
        if full:
            b00, b11, b22, b01, b02, b12 = a00 / det, a11 / det, a22 / det, a01 / det, a02 / det, a12 / det
        elif plane:
            a00, a11, a22, a01, a02, a12 = a00 / minors, a11 / minors, a22 / minors, a01 / minors, a02 / minors, a12 / minors  # P
            U[0, 0], U[1, 1], U[2, 2] = G[0, 0] + a00, G[1, 1] + a11, G[2, 2] + a22  # G + P
            U[0, 1], U[0, 2], U[1, 2] = G[0, 1] + a01, G[0, 2] + a02, G[1, 2] + a12
            U[1, 0], U[2, 0], U[2, 1] = U[0, 1], U[0, 2], U[1, 2]
            b00, b11, b22, b01, b02, b12 = _adjugate3(U)
            det = U[0, 0] * b00 + U[0, 1] * b01 + U[0, 2] * b02
            b00, b11, b22 = b00 / det - a00, b11 / det - a11, b22 / det - a22
            b01, b02, b12 = b01 / det - a01, b02 / det - a02, b12 / det - a12
        else:
            t2 = trace * trace
            b00, b11, b22, b01, b02, b12 = G[0, 0] / t2, G[1, 1] / t2, G[2, 2] / t2, G[0, 1] / t2, G[0, 2] / t2, G[1, 2] / t2
        U[0, 0], U[1, 1], U[2, 2] = b00, b11, b22
        U[0, 1], U[0, 2], U[1, 2] = b01, b02, b12
        U[1, 0], U[2, 0], U[2, 1] = b01, b02, b12
        for c in range(k):
            for r in range(3):
                X[c, r] = As[0, c] * U[0, r] + As[1, c] * U[1, r] + As[2, c] * U[2, r]
    elif trace > 0.5 * rcond:  # else none kept: X = 0 as it is
        _eigh3(G, lam, U)
        for i in range(3):
            if lam[i] <= rcond:
                continue
            for c in range(k):  # Aᵀu = √λ · (eigenvector of AᵀA)
                v[c] = As[0, c] * U[0, i] + As[1, c] * U[1, i] + As[2, c] * U[2, i]
            for c in range(k):
                for r in range(3):
                    X[c, r] += v[c] * U[r, i] / lam[i]
    for c in range(k):  # back to unscaled variables
        for r in range(3):
            X[c, r] /= s[c]


@njit(cache=True)
def prioritized_inverse(J, rcond):
    """Per-sample operator P, shape (N, k, rows), of the step ``P·r`` for ``J·step = r``.

    Position rows first (x = X1 r_p); the tool axis (rows 3-5 of a
    (N, 6, k) `J`) only in the null space N = I − X1 Jp the position leaves:
    x += N X2 (r_o − Jo x) with X2 the operator of ``(Jo N) x2 = b``, so
    ``P = [X1 − N X2 Jo X1 | N X2]``. N is applied as ``y − X1 (Jp y)``,
    never formed (k x 3 x 3 products instead of k x k x 3). See
    :func:`contoursim.multibody._prioritized_inverse`.
    """
    size, rows, k = J.shape
    out = np.zeros((size, k, rows))
    X1 = np.empty((k, 3))
    X2 = np.empty((k, 3))
    A = np.empty((3, k))
    NX2 = np.empty((k, 3))
    JoX1 = np.empty((3, 3))
    JpX2 = np.empty((3, 3))
    s, As, G, lam, U, v = np.empty(k), np.empty((3, k)), np.empty((3, 3)), np.empty(3), np.empty((3, 3)), np.empty(k)
    for n in range(size):
        Jp = J[n, :3]
        _pinv3(Jp, rcond, 1.0, X1, s, As, G, lam, U, v)
        strongest = 0.0
        if rows == 6:
            for c in range(k):
                strongest = max(strongest, np.sqrt(J[n, 3, c] ** 2 + J[n, 4, c] ** 2 + J[n, 5, c] ** 2))
        if strongest == 0.0:
            for c in range(k):
                for r in range(3):
                    out[n, c, r] = X1[c, r]
            continue
        Jo = J[n, 3:]
        for i in range(3):  # JoX1 = Jo·X1, then A = Jo·N = Jo − JoX1·Jp
            for r in range(3):
                a = 0.0
                for d in range(k):
                    a += Jo[i, d] * X1[d, r]
                JoX1[i, r] = a
            for c in range(k):
                A[i, c] = Jo[i, c] - (JoX1[i, 0] * Jp[0, c] + JoX1[i, 1] * Jp[1, c] + JoX1[i, 2] * Jp[2, c])
        _pinv3(A, rcond, strongest + 1e-300, X2, s, As, G, lam, U, v)
        for i in range(3):  # JpX2 = Jp·X2, then N·X2 = X2 − X1·JpX2
            for r in range(3):
                a = 0.0
                for d in range(k):
                    a += Jp[i, d] * X2[d, r]
                JpX2[i, r] = a
        for c in range(k):
            for r in range(3):
                NX2[c, r] = X2[c, r] - (X1[c, 0] * JpX2[0, r] + X1[c, 1] * JpX2[1, r] + X1[c, 2] * JpX2[2, r])
        for c in range(k):
            for r in range(3):
                out[n, c, r] = X1[c, r] - (NX2[c, 0] * JoX1[0, r] + NX2[c, 1] * JoX1[1, r] + NX2[c, 2] * JoX1[2, r])
                out[n, c, 3 + r] = NX2[c, r]
    return out


@njit(cache=True)
def newton_update(q, columns, P, position, direction, target, target_direction):
    """One step ``q[:, columns] -= P r`` with the residual r = (position − target, direction − target_direction).

    `target_direction` of shape (0, 3) leaves the tool axis out (P then has
    3 columns); a P of one sample serves every sample. Returns the largest
    |step| and its sample.
    """
    size = q.shape[0]
    _, k, rows = P.shape
    each = P.shape[0] > 1
    largest = 0.0
    worst = 0
    r = np.empty(rows)
    for n in range(size):
        for i in range(3):
            r[i] = position[n, i] - target[n, i]
        if rows == 6:
            for i in range(3):
                r[3 + i] = direction[n, i] - target_direction[n, i]
        m = n if each else 0
        for c in range(k):
            step = 0.0
            for i in range(rows):
                step += P[m, c, i] * r[i]
            q[n, columns[c]] -= step
            if abs(step) > largest:
                largest, worst = abs(step), n
    return largest, worst
