"""Exact contour error against closed forms and brute-force minimisation, on coarsely sampled references."""

import numpy as np
import pytest
from scipy.optimize import minimize_scalar
from scipy.signal import lfilter

from contoursim import paths
from contoursim.contour import ContourError, exact_contour_error
from contoursim.nearest import nearest_knots, with_chord
from contoursim.feed import plan, sample
from contoursim.trajectory import Trajectory

rng = np.random.default_rng(1)


def _coarse(path, spacing=1.0):
    """Reference sampled every ~`spacing` mm (100 mm/s at dt = spacing / 100)."""
    return sample(path, plan(path, 100.0, 1e4), spacing / 100.0)


def _at(ref, s):
    """The reference sample commanded at each of the arc lengths `s` [mm]: the one nearest along the path."""
    i = np.clip(np.searchsorted(ref.s, s), 1, len(ref.s) - 1)
    return np.where(np.abs(ref.s[i - 1] - s) < np.abs(ref.s[i] - s), i - 1, i)


def test_circle_in_plane_closed_form():
    center, radius = np.array([3.0, -2.0]), 50.0
    ref = _coarse(paths.circle(center, radius))
    phi = np.linspace(0.0, 2 * np.pi, 3001)[1:-1]
    r = radius + rng.uniform(-0.5, 0.5, phi.size)
    actual = center + r[:, None] * np.column_stack([np.cos(phi), np.sin(phi)])
    err = exact_contour_error(ref, actual, at=_at(ref, radius * phi))
    # DOMAIN.md §3: ε = R - |P - c| for a CCW circle; foot on the ray through P
    np.testing.assert_allclose(err.normal, radius - r, rtol=0, atol=1e-9)
    np.testing.assert_allclose(err.magnitude, np.abs(radius - r), rtol=0, atol=1e-9)
    np.testing.assert_allclose(err.foot, center + radius * np.column_stack([np.cos(phi), np.sin(phi)]), atol=1e-9)
    np.testing.assert_allclose(err.vector, err.foot - actual, atol=1e-15)
    np.testing.assert_allclose(err.s, radius * phi, atol=1e-9)
    np.testing.assert_allclose(err.out_of_plane, 0.0, atol=1e-15)


def test_tilted_circle_with_out_of_plane_offset():
    n = np.array([1.0, 2.0, 3.0]) / np.sqrt(14)
    center, radius = np.array([10.0, 0.0, 5.0]), 50.0
    path = paths.circle(center, radius, normal=n)
    e1, e2 = path.primitives[0].e1, path.primitives[0].e2
    ref = _coarse(path)
    phi = np.linspace(0.1, 2 * np.pi - 0.1, 500)
    dr, h = rng.uniform(-0.2, 0.2, phi.size), rng.uniform(-0.3, 0.3, phi.size)
    radial = np.cos(phi)[:, None] * e1 + np.sin(phi)[:, None] * e2
    actual = center + (radius + dr)[:, None] * radial + h[:, None] * n
    err = exact_contour_error(ref, actual, at=_at(ref, radius * phi))
    np.testing.assert_allclose(err.magnitude, np.hypot(dr, h), atol=1e-9)
    np.testing.assert_allclose(err.normal, -dr, atol=1e-9)
    np.testing.assert_allclose(err.out_of_plane, h, atol=1e-9)
    np.testing.assert_allclose(err.foot, center + radius * radial, atol=1e-9)


@pytest.mark.parametrize("theta", np.radians([0.0, 30.0, 135.0, -100.0]))
def test_line_at_an_angle(theta):
    start = np.array([5.0, -7.0])
    direction = np.array([np.cos(theta), np.sin(theta)])
    ref = _coarse(paths.line(start, start + 80 * direction), spacing=3.0)
    along = np.linspace(-2.0, 82.0, 400)
    offset = rng.uniform(-1, 1, (along.size, 2))
    actual = start + along[:, None] * direction + offset
    err = exact_contour_error(ref, actual, at=_at(ref, along))
    # DOMAIN.md §3: ε = -(x_a - x_r) sin θ + (y_a - y_r) cos θ for any point r of the line
    expected = -(actual[:, 0] - start[0]) * np.sin(theta) + (actual[:, 1] - start[1]) * np.cos(theta)
    inside = (offset @ direction + along > 0) & (offset @ direction + along < 80)
    np.testing.assert_allclose(err.normal[inside], expected[inside], atol=1e-12)
    np.testing.assert_allclose(err.magnitude[inside], np.abs(expected[inside]), atol=1e-12)
    # beyond the ends the nearest point is the end point
    ends = np.where(offset @ direction + along <= 0, 0.0, 80.0)[~inside]
    np.testing.assert_allclose(err.s[~inside], ends, atol=1e-12)
    np.testing.assert_allclose(err.foot[~inside], start + ends[:, None] * direction, atol=1e-12)


def test_helix_against_brute_force_minimisation():
    radius, pitch = 20.0, 5.0
    path = paths.helix((0, 0, 0), radius, pitch, 2.0)
    ref = _coarse(path)
    h = pitch / (2 * np.pi)

    def point(theta):
        return np.array([radius * np.cos(theta), radius * np.sin(theta), h * theta])

    theta = np.linspace(0.05, 4 * np.pi - 0.05, 60)
    actual = np.array([point(t) for t in theta]) + rng.uniform(-0.3, 0.3, (theta.size, 3))
    err = exact_contour_error(ref, actual, at=_at(ref, np.hypot(radius, h) * theta))
    grid = np.linspace(0, 4 * np.pi, 20001)
    dense = np.array([point(g) for g in grid])
    step = grid[1]
    for i, p in enumerate(actual):
        t = grid[np.argmin(np.sum((dense - p) ** 2, axis=1))]  # global, dense, then refined locally
        best = minimize_scalar(lambda x: np.sum((point(t + x) - p) ** 2), bounds=(-step, step), method="bounded",
                               options=dict(xatol=1e-12))
        assert err.magnitude[i] == pytest.approx(np.sqrt(best.fun), abs=1e-9)
        np.testing.assert_allclose(err.foot[i], point(t + best.x), atol=1e-7)  # Brent's x resolution
    np.testing.assert_allclose(err.normal**2 + err.out_of_plane**2, err.magnitude**2, rtol=1e-9)


def test_figure_eight_follows_the_travelled_branch():
    t = np.linspace(0, 2 * np.pi, 40, endpoint=False)
    path = paths.spline(np.column_stack([40 * np.sin(t), 25 * np.sin(2 * t)]), closed=True)
    ref = _coarse(path)
    s_true = np.linspace(1.0, path.length - 1.0, 4000)
    pos, tangent, _ = path.derivatives(s_true)
    left = np.column_stack([-tangent[:, 1], tangent[:, 0]])
    d = 0.3 * np.sin(2 * np.pi * s_true / 37.0)
    actual = pos[:, :2] + d[:, None] * left
    err = exact_contour_error(ref, actual, at=_at(ref, s_true))
    np.testing.assert_allclose(err.s, s_true, atol=1e-9)
    np.testing.assert_allclose(err.normal, d, atol=1e-10)
    # near the crossing the other branch is nearer for some points: a global search would jump to it
    dense = path.evaluate(np.linspace(0, path.length, 200001))[0][:, :2]
    crossing = np.linalg.norm(actual, axis=1) < 1.0
    nearest = np.array([np.min(np.linalg.norm(dense - p, axis=1)) for p in actual[crossing]])
    assert np.any(nearest < np.abs(d[crossing]) - 0.05)


def test_rounded_square_offset_sampled_coarser_than_its_fillets():
    # outward offset of a convex contour by 0.5 mm: constant distance, on the right of the travel
    path = paths.polyline([[0, -50], [50, -50], [50, 50], [-50, 50], [-50, -50], [0, -50]], blend_radius=2.0)
    ref = _coarse(path, spacing=5.0)  # fillets are 3.1 mm long
    s = np.linspace(0, path.length, 5000)
    pos, tangent, _ = path.derivatives(s)
    actual = pos[:, :2] + 0.5 * np.column_stack([tangent[:, 1], -tangent[:, 0]])
    err = exact_contour_error(ref, actual, at=_at(ref, s))
    np.testing.assert_allclose(err.magnitude, 0.5, atol=1e-12)
    np.testing.assert_allclose(err.normal, -0.5, atol=1e-12)


def test_sharp_corners_with_exact_stops_against_the_polygon():
    # a square without blending: the feed stops at every corner, so the reference repeats its corner
    # sample for a while, and the lagging tool cuts inside each corner, nearer the outgoing edge than
    # the incoming one, whose own distance minimum lies behind the corner
    corners = np.array([[0, -50], [50, -50], [50, 50], [-50, 50], [-50, -50], [0, -50]], float)
    path = paths.polyline(corners, 0.0)
    dt, kp = 2e-4, 35.0
    ref = sample(path, plan(path, 2000 / 60, 1000.0, 50000.0), dt)
    # first-order lag per axis, exact discrete form: q[k+1] = a q[k] + (1 - a) r[k], a = exp(-kp dt), q[0] = r[0]
    a = np.exp(-kp * dt)
    actual = lfilter([0.0, 1.0 - a], [1.0, -a], ref.position, axis=0, zi=ref.position[:1])[0]
    err = exact_contour_error(ref, actual)
    # brute force: the distance to the nearest of the five segments, on every 5th point
    p = actual[::5]
    start, edge = corners[:-1], np.diff(corners, axis=0)
    u = np.clip(np.einsum("nkd,kd->nk", p[:, None] - start, edge) / np.sum(edge**2, axis=1), 0.0, 1.0)
    distance = np.min(np.linalg.norm(p[:, None] - (start + u[..., None] * edge), axis=2), axis=1)
    assert distance.max() > 0.1  # the corners are cut by about 0.11 mm
    np.testing.assert_allclose(err.magnitude[::5], distance, rtol=0, atol=1e-9)
    # the lag cuts inside the counter-clockwise square: to the left of the travel
    np.testing.assert_allclose(err.normal[::5], distance, rtol=0, atol=1e-9)


def test_iso_circle_trajectory_and_input_checks():
    path = paths.iso230_4_circle(50.0, direction="cw")
    ref = sample(path, plan(path, 1000 / 60, 1000.0), 0.01)
    actual = ref.position * (1 + 2e-5)  # 1 µm outward on the test circle
    err = exact_contour_error(ref, actual)
    # clockwise: the left normal points outward, so normal = |P - c| - R
    np.testing.assert_allclose(err.normal[ref.measuring], 1e-3, atol=1e-12)
    with pytest.raises(ValueError, match=r"actual must have shape \(N, 2\)"):
        exact_contour_error(ref, np.zeros((3, 3)))
    with pytest.raises(ValueError, match="give `at`, the sample commanded at each actual point"):
        exact_contour_error(ref, actual[:10])
    n = len(ref.t)
    with pytest.raises(ValueError, match=rf"at\[0\] = {n} is not a sample index of the reference's {n} samples"):
        exact_contour_error(ref, actual[:10], at=np.arange(10) + n)
    # each fault said as itself (an outside probe: 'at must hold 0 sample indices ..., got float64 (0,)' for none)
    with pytest.raises(ValueError, match=r"at must hold one sample index per actual point \(10\), got shape \(9,\)"):
        exact_contour_error(ref, actual[:10], at=np.arange(9))
    with pytest.raises(ValueError, match="at must hold whole sample indices, got float64 values"):
        exact_contour_error(ref, actual[:10], at=np.arange(10) + 0.5)
    assert exact_contour_error(ref, actual[:0], at=[]).magnitude.shape == (0,)
    from contoursim.estimators import three_point
    with pytest.raises(ValueError, match="give `at`"):
        three_point(ref.position, actual[:10])
    bare = Trajectory(ref.t, ref.position, ref.velocity, ref.acceleration, ref.s)
    with pytest.raises(ValueError, match="trajectory has no path"):
        exact_contour_error(bare, actual)


def test_exact_result_derives_its_vector_and_shares_the_actual_points():
    ref = _coarse(paths.circle((0.0, 0.0), 50.0))
    phi = np.linspace(0.0, 2 * np.pi, 40_001)[1:-1]  # more points than one block of the search
    actual = (50.0 + 0.01 * np.sin(7 * phi))[:, None] * np.column_stack([np.cos(phi), np.sin(phi)])
    at = _at(ref, 50.0 * phi)
    np.testing.assert_allclose(exact_contour_error(ref, actual, at).normal, -0.01 * np.sin(7 * phi), rtol=0, atol=1e-12)
    actual.flags.writeable = False  # as a simulation's tool positions are: kept without a copy
    err = exact_contour_error(ref, actual, at)
    assert np.shares_memory(err.actual, actual)
    np.testing.assert_array_equal(err.vector, err.foot - actual)  # the correction, from foot and actual points
    assert not err.vector.flags.writeable
    assert err.out_of_plane.shape == (phi.size,) and not err.out_of_plane.any() and err.out_of_plane.strides == (0,)
    mine = actual.copy()  # writeable: the caller's, copied and left writeable
    assert not np.shares_memory(exact_contour_error(ref, mine, at).actual, mine) and mine.flags.writeable
    with pytest.raises(ValueError, match="foot and actual"):
        ContourError(err.magnitude, None, err.normal, err.out_of_plane)


def test_nearest_knot_does_not_depend_on_the_hint():
    """The search's result is fixed by the commanded knot: hinted by the previous point, by itself, or by any knot."""
    ref = _coarse(paths.circle((0.0, 0.0), 50.0), spacing=0.5)
    knots = with_chord(np.column_stack([ref.position, np.zeros(len(ref))]))
    phi = np.linspace(0.0, 2 * np.pi, 5_000)[:-1]  # one turn, as the reference
    points = np.ascontiguousarray(np.column_stack([50.1 * np.cos(phi), 50.1 * np.sin(phi), np.zeros(phi.size)]))
    anchors = np.clip(_at(ref, 50.0 * phi) + 3, 0, len(ref.s) - 1)  # the tool lags a little
    whole = nearest_knots(knots, anchors, points, 8, 0)
    alone = [nearest_knots(knots, anchors[i : i + 1], points[i : i + 1], 8, int(anchors[i])) for i in range(0, 4999, 7)]
    far = [nearest_knots(knots, anchors[i : i + 1], points[i : i + 1], 8, (i + 300) % 600) for i in range(0, 4999, 7)]
    np.testing.assert_array_equal(np.concatenate(alone), whole[::7])
    np.testing.assert_array_equal(np.concatenate(far), whole[::7])
    np.testing.assert_allclose(np.hypot(*knots[whole, :2].T), 50.0, rtol=1e-12)  # on the circle, nearest in angle
    assert np.abs(np.angle(np.exp(1j * (np.arctan2(knots[whole, 1], knots[whole, 0]) - phi)))).max() < 0.5 / 50.0
