"""Contour error estimators against closed forms derived by hand.

References: a line at angle theta, epsilon = -(x_a - x_r) sin(theta) + (y_a - y_r) cos(theta)
(DOMAIN.md section 3); a circle, epsilon = R - |P - c|; a circle in a tilted
plane with the point lifted by h out of it, epsilon = sqrt((L - R)^2 + h^2).
The geometry is built here with numpy, independent of contoursim.paths.
"""

import numpy as np
import pytest
from numba import njit

from contoursim import estimators as est

RNG = np.random.default_rng(20240531)


def circle_points(center, radius, angles, normal=(0.0, 0.0, 1.0)):
    """Points of a circle counter-clockwise about `normal`, and its in-plane basis."""
    n = np.asarray(normal, float) / np.linalg.norm(normal)
    e1 = np.cross(n, [1.0, 0.0, 0.0] if abs(n[0]) < 0.9 else [0.0, 1.0, 0.0])
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(n, e1)
    radial = np.cos(angles)[:, None] * e1 + np.sin(angles)[:, None] * e2
    return np.asarray(center, float) + radius * radial, radial, n


# ---------------------------------------------------------------- closed forms


@pytest.mark.parametrize("theta", [0.0, 0.3, 2.0, -2.7])
def test_linear_equals_closed_form_on_a_line(theta):
    direction = np.array([np.cos(theta), np.sin(theta)])
    s = np.repeat(np.linspace(0.0, 10.0, 200), 2)  # duplicated samples, as at standstill
    ref = np.array([3.0, -1.0]) + s[:, None] * direction
    act = ref + RNG.uniform(-0.2, 0.2, ref.shape)  # tracking error with an along-path part
    got = est.linear(ref, act)
    e = act - ref
    want = -e[:, 0] * np.sin(theta) + e[:, 1] * np.cos(theta)
    np.testing.assert_allclose(got.normal, want, rtol=0, atol=1e-13)
    np.testing.assert_allclose(got.magnitude, np.abs(want), rtol=0, atol=1e-13)
    left = np.array([-np.sin(theta), np.cos(theta)])
    np.testing.assert_allclose(got.vector, -want[:, None] * left, rtol=0, atol=1e-13)
    np.testing.assert_array_equal(got.index, np.repeat(np.arange(0, 400, 2), 2))
    assert np.all(got.out_of_plane == 0.0)


def test_linear_in_3d_is_the_tracking_error_normal_to_the_line():
    t = np.array([1.0, 2.0, 2.0]) / 3.0
    ref = np.linspace(0.0, 5.0, 50)[:, None] * t
    act = ref + RNG.normal(0.0, 0.1, ref.shape)
    got = est.linear(ref, act)
    e = act - ref
    perp = e - (e @ t)[:, None] * t
    np.testing.assert_allclose(got.magnitude, np.linalg.norm(perp, axis=1), rtol=0, atol=1e-13)
    np.testing.assert_allclose(got.vector, -perp, rtol=0, atol=1e-13)
    np.testing.assert_allclose(got.normal**2 + got.out_of_plane**2, got.magnitude**2, rtol=1e-12)


@pytest.mark.parametrize("direction", ["ccw", "cw"])
def test_circular_equals_closed_form_in_the_plane(direction):
    center, radius = np.array([10.0, -5.0]), 50.0
    phi = RNG.uniform(0, 2 * np.pi, 500)
    dist = radius + RNG.uniform(-0.1, 0.1, phi.size)
    act = center + dist[:, None] * np.column_stack([np.cos(phi), np.sin(phi)])
    got = est.circular(act, center, radius, direction=direction)
    sign = 1.0 if direction == "ccw" else -1.0
    np.testing.assert_allclose(got.normal, sign * (radius - dist), rtol=0, atol=1e-12)
    np.testing.assert_allclose(got.magnitude, np.abs(radius - dist), rtol=0, atol=1e-12)
    foot = act + got.vector
    np.testing.assert_allclose(np.linalg.norm(foot - center, axis=1), radius, rtol=1e-14)


def test_circular_in_a_tilted_plane_with_out_of_plane_offset():
    center, radius, normal = np.array([1.0, 2.0, 3.0]), 20.0, (1.0, 2.0, 2.0)
    phi = RNG.uniform(0, 2 * np.pi, 300)
    delta, h = RNG.uniform(-0.1, 0.1, phi.size), RNG.uniform(-0.05, 0.05, phi.size)
    on, radial, n = circle_points(center, radius, phi, normal)
    act = on + delta[:, None] * radial + h[:, None] * n
    got = est.circular(act, center, radius, normal=normal)
    np.testing.assert_allclose(got.magnitude, np.hypot(delta, h), rtol=0, atol=1e-12)
    np.testing.assert_allclose(got.normal, -delta, rtol=0, atol=1e-12)
    np.testing.assert_allclose(got.out_of_plane, h, rtol=0, atol=1e-12)


@pytest.mark.parametrize("turn", [1.0, -1.0])
def test_three_point_equals_closed_form_on_a_circle(turn):
    center, radius = np.array([-3.0, 7.0]), 50.0
    theta = turn * np.linspace(0.0, 2.2 * np.pi, 2000)  # more than a full turn: passes its own start
    ref = center + radius * np.column_stack([np.cos(theta), np.sin(theta)])
    phi = turn * np.sort(RNG.uniform(0.0, 2.2 * np.pi, 3000))
    dist = radius + RNG.uniform(-0.2, 0.2, phi.size)
    act = center + dist[:, None] * np.column_stack([np.cos(phi), np.sin(phi)])
    nearest = np.argmin(np.abs(phi[:, None] - theta[None, :]), axis=1)  # on the same turn
    got = est.three_point(ref, act, at=nearest)
    np.testing.assert_allclose(got.normal, turn * (radius - dist), rtol=0, atol=1e-11)
    np.testing.assert_allclose(got.magnitude, np.abs(radius - dist), rtol=0, atol=1e-11)
    assert np.all(np.diff(got.index) >= 0)  # followed the turn, never jumped back to the start
    assert np.all(np.abs(got.index - nearest) <= 1)


def test_three_point_in_a_tilted_plane_with_out_of_plane_offset():
    center, radius, normal = np.array([5.0, -2.0, 8.0]), 30.0, (0.3, -0.5, 0.8)
    theta = np.linspace(0.0, 2 * np.pi, 1500)
    ref, _, n = circle_points(center, radius, theta, normal)
    phi = np.sort(RNG.uniform(0.01, 2 * np.pi - 0.01, 2000))
    delta, h = RNG.uniform(-0.2, 0.2, phi.size), RNG.uniform(-0.1, 0.1, phi.size)
    on, radial, _ = circle_points(center, radius, phi, normal)
    act = on + delta[:, None] * radial + h[:, None] * n
    at = np.searchsorted(theta, phi)
    got = est.three_point(ref, act, up=normal, at=at)
    L = np.linalg.norm((act - center) - ((act - center) @ n)[:, None] * n, axis=1)
    np.testing.assert_allclose(got.magnitude, np.sqrt((L - radius) ** 2 + h**2), rtol=0, atol=1e-11)
    np.testing.assert_allclose(got.normal, radius - L, rtol=0, atol=1e-11)
    np.testing.assert_allclose(got.out_of_plane, h, rtol=0, atol=1e-11)
    np.testing.assert_allclose(act + got.vector, on, rtol=0, atol=1e-11)
    flipped = est.three_point(ref, act, up=-n, at=at)  # b turned over: both signed parts flip
    np.testing.assert_allclose(flipped.normal, L - radius, rtol=0, atol=1e-11)
    np.testing.assert_allclose(flipped.out_of_plane, -h, rtol=0, atol=1e-11)


# ---------------------------------------------------------------- convergence


def _ellipse_case():
    a, b = 50.0, 30.0
    phi = np.sort(RNG.uniform(0.2, 2 * np.pi - 0.2, 2000))
    eps = RNG.uniform(-0.05, 0.05, phi.size)
    tangent = np.column_stack([-a * np.sin(phi), b * np.cos(phi)])
    tangent /= np.linalg.norm(tangent, axis=1, keepdims=True)
    left = np.column_stack([-tangent[:, 1], tangent[:, 0]])
    act = np.column_stack([a * np.cos(phi), b * np.sin(phi)]) + eps[:, None] * left
    return a, b, act, eps, phi  # the exact contour error is eps: |eps| < b^2/a, the smallest radius


@pytest.mark.parametrize("method, order", [(est.three_point, 3.0), (est.newton, 4.0)])
def test_order_of_convergence_on_an_ellipse(method, order):
    a, b, act, eps, phi = _ellipse_case()
    sizes = np.array([200, 400, 800, 1600])
    errors = []
    for n in sizes:  # uniform in the parameter: unequal spacing along the curve
        theta = np.linspace(0.0, 2 * np.pi, n + 1)
        ref = np.column_stack([a * np.cos(theta), b * np.sin(theta)])
        errors.append(np.abs(method(ref, act, at=np.searchsorted(theta, phi)).normal - eps).max())
    measured = np.polyfit(np.log(2 * np.pi / sizes), np.log(errors), 1)[0]  # log-log slope
    assert measured == pytest.approx(order, abs=0.3)
    assert errors[-1] < 1e-6


def test_three_point_beats_linear_on_a_circle_with_lag():
    # a first-order lag on a circle: the actual lies on a smaller circle, behind in phase
    radius, omega, kp = 50.0, 1.0 / 3.0, 35.0
    theta = np.linspace(0.0, 2 * np.pi, 20001)
    ref = radius * np.column_stack([np.cos(theta), np.sin(theta)])
    gain, lag = 1 / np.hypot(1, omega / kp), np.arctan(omega / kp)
    act = gain * radius * np.column_stack([np.cos(theta - lag), np.sin(theta - lag)])
    exact_normal = radius * (1 - gain)
    err_linear = np.abs(est.linear(ref, act).normal - exact_normal).max()
    err_three = np.abs(est.three_point(ref, act).normal - exact_normal).max()
    assert err_three < 1e-9 < err_linear / 1000


# ---------------------------------------------------------------- robustness


def test_figure_eight_search_follows_the_travelled_branch():
    # lemniscate of Gerono x = 40 sin t, y = 20 sin 2t: crosses itself at the origin at t = 0, pi
    t = np.linspace(-0.5, 2 * np.pi + 0.5, 6000)
    ref = np.column_stack([40 * np.sin(t), 20 * np.sin(2 * t)])
    tf = np.sort(RNG.uniform(-0.4, 2 * np.pi + 0.4, 4000))
    tangent = np.column_stack([40 * np.cos(tf), 40 * np.cos(2 * tf)])
    tangent /= np.linalg.norm(tangent, axis=1, keepdims=True)
    left = np.column_stack([-tangent[:, 1], tangent[:, 0]])
    eps = 0.3
    act = np.column_stack([40 * np.sin(tf), 20 * np.sin(2 * tf)]) + eps * left
    for method in (est.three_point, est.newton):
        got = method(ref, act, at=np.searchsorted(t, tf))
        assert np.all(np.diff(got.index) >= 0)
        np.testing.assert_allclose(got.normal, eps, rtol=0, atol=1e-6)
    # near the crossing the other branch is closer than eps: a global search would jump to it
    other = np.min(np.linalg.norm(act[:, None, :] - ref[None, ::7, :], axis=2), axis=1)
    assert other.min() < 0.8 * eps


def test_search_crosses_a_sharp_corner_cut_on_the_inside():
    # an exact stop at the corner (0, 0): the samples crowd into it along y, then leave along x.
    # The tool passes 1 µm inside the corner, so along the incoming edge its distance has a
    # local minimum of its own, and the outgoing edge lies across many crowded samples.
    u = np.linspace(0.0, 1.0, 201)
    ref = np.concatenate([np.column_stack([0 * u, 10 * (1 - u) ** 3]), np.column_stack([10 * u**3, 0 * u])[1:]])
    inside = 1e-3
    y = np.linspace(10.0, inside, 300)
    down = np.column_stack([np.full_like(y, inside), y])  # 1 µm inside the incoming edge x = 0
    act = np.concatenate([down, down[::-1, ::-1]])  # then along the outgoing edge y = 0
    # commanded where the tool is: the sample at the same height on the way in, the same x on the way out
    at = np.concatenate([np.rint(200 * (1 - (y / 10) ** (1 / 3))), 200 + np.rint(200 * (y[::-1] / 10) ** (1 / 3))])
    for method in (est.three_point, est.newton):
        got = method(ref, act, at=at.astype(int))
        np.testing.assert_allclose(got.magnitude, inside, rtol=1e-9)
        assert got.index[-1] == len(ref) - 1


def test_duplicates_give_the_same_result_as_distinct_samples():
    theta = np.linspace(0.0, np.pi, 400)
    ref = 20 * np.column_stack([np.cos(theta), np.sin(theta), 0.01 * theta])
    counts = RNG.integers(1, 5, len(ref))
    counts[[0, 150, -1]] = 300  # standstill at the start, in the middle, at the end
    dup = np.repeat(ref, counts, axis=0)
    act = dup + RNG.normal(0.0, 0.01, dup.shape)
    for method in (est.three_point, est.newton):
        plain, with_dup = method(ref, act, at=np.repeat(np.arange(len(ref)), counts)), method(dup, act)
        np.testing.assert_allclose(with_dup.magnitude, plain.magnitude, rtol=0, atol=1e-15)
        np.testing.assert_array_equal(with_dup.index, np.cumsum(counts)[plain.index] - counts[plain.index])
    # the linear estimate with the same standstills, on a line at angle a: -e_x sin a + e_y cos a
    angle = 0.7
    line = np.linspace(0.0, 20.0, len(ref))[:, None] * [np.cos(angle), np.sin(angle), 0.0]
    dup_line = np.repeat(line, counts, axis=0)
    e = RNG.normal(0.0, 0.01, dup_line.shape) * [1.0, 1.0, 0.0]
    lin = est.linear(dup_line, dup_line + e)
    want = -e[:, 0] * np.sin(angle) + e[:, 1] * np.cos(angle)
    np.testing.assert_allclose(lin.normal, want, rtol=0, atol=1e-13)
    np.testing.assert_allclose(lin.magnitude, np.abs(want), rtol=0, atol=1e-13)
    np.testing.assert_array_equal(lin.index, np.repeat(np.cumsum(counts) - counts, counts))


def test_standstill_reference_gives_the_distance_to_the_point():
    ref = np.tile([1.0, 2.0, 3.0], (50, 1))
    act = ref + RNG.normal(0.0, 0.01, ref.shape)
    want = np.linalg.norm(act - ref, axis=1)
    for method in (est.linear, est.three_point, est.newton):
        got = method(ref, act)
        np.testing.assert_allclose(got.magnitude, want, rtol=1e-14)
        np.testing.assert_allclose(got.vector, ref - act, rtol=1e-14)


def test_cusp_and_short_references_are_defined():
    out_and_back = np.array([[0.0, 0.0], [1.0, 0.0], [2.0, 0.0], [1.0, 0.0], [0.0, 0.0]])
    act = np.array([[0.0, 0.1], [1.0, -0.2], [2.3, 0.1], [2.0, 0.5], [1.5, -0.1], [0.2, 0.3]])
    for method in (est.linear, est.three_point, est.newton):
        for ref in (out_and_back, out_and_back[:2], out_and_back[:1]):
            if method is est.linear:
                got = method(ref, act[: len(ref)])
            else:
                got = method(ref, act, at=np.arange(len(act)) * len(ref) // len(act))
            assert np.all(np.isfinite(got.magnitude)) and np.all(np.isfinite(got.vector))
    # the cusp tip at (2, 0): the incoming line y = 0
    tip = est.three_point(out_and_back, np.array([[0.0, 0.1], [1.0, 0.1], [2.0, 0.25]]), at=[0, 1, 2])
    np.testing.assert_allclose(tip.magnitude, [0.1, 0.1, 0.25], rtol=1e-12)
    two = est.three_point(out_and_back[:2], np.array([[0.5, 0.3]]), at=[0])
    np.testing.assert_allclose(two.normal, [0.3], rtol=1e-12)


# ---------------------------------------------------------------- step functions


@njit
def _kernel_like(knots, knot_of_sample, actual, params):
    """What a compensator does inside the servo loop: one step per period, anchored at the commanded knot."""
    index = 0
    out = np.empty(actual.shape[0])
    for k in range(actual.shape[0]):
        estimate, index = est.three_point_step(knots, knot_of_sample[k], index, actual[k], params)
        out[k] = estimate.normal
    return out


def test_step_function_inside_a_compiled_loop_matches_the_offline_estimate():
    theta = np.linspace(0.0, 2 * np.pi, 1000)
    ref = np.column_stack([30 * np.cos(theta), 20 * np.sin(theta), np.zeros_like(theta)])
    act = ref * 1.001
    knots, _, knot_of_sample = est.distinct_samples(ref)
    online = _kernel_like(knots, knot_of_sample, act, est.search_params())
    np.testing.assert_array_equal(online, est.three_point(ref, act).normal)
    estimate, index = est.circular_step(knots, 3, 7, np.array([0.0, 49.0, 0.0]), est.circular_params((0, 0), 50.0))
    assert index == 7 and estimate.normal == pytest.approx(1.0) and estimate.vy == pytest.approx(1.0)


# ---------------------------------------------------------------- input checks


@pytest.mark.parametrize(
    "call, message",
    [
        (lambda: est.three_point(np.zeros((5, 2)), np.zeros((5, 3))), "actual must have 2 columns"),
        (lambda: est.linear(np.zeros((5, 2)), np.zeros((4, 2))), "one row per reference sample"),
        (lambda: est.three_point(np.zeros((5, 2)), [[np.nan, 0.0]]), "actual contains a non-finite"),
        (lambda: est.three_point(np.zeros((0, 2)), np.zeros((1, 2))), "reference must have shape"),
        (lambda: est.three_point(np.zeros((5, 2)), np.zeros((1, 2)), window=0), "window must be at least 1"),
        (lambda: est.newton(np.zeros((5, 2)), np.zeros((1, 2)), up=(0, 0, 0)), "up must be a nonzero"),
        (lambda: est.circular(np.zeros((1, 2)), (0, 0), -1.0), "radius must be positive"),
        (lambda: est.circular(np.zeros((1, 2)), (0, 0), 1.0, direction="left"), "direction must be"),
    ],
)
def test_bad_input_is_rejected_with_a_message_naming_it(call, message):
    with pytest.raises(ValueError, match=message):
        call()


def test_circular_refuses_a_centre_of_other_dimensions_than_the_points():
    # a 3-D centre with planar points took the centre's z as an out-of-plane offset of every point (a circle of
    # radius 10 about (0, 0, 5) read 5 mm off), as did points at z = 5 about a planar centre
    phi = np.linspace(0.0, 2 * np.pi, 8)
    planar = 10.0 * np.column_stack([np.cos(phi), np.sin(phi)])
    lifted = np.column_stack([planar, np.full(phi.size, 5.0)])
    for act, center, words in ((planar, (0.0, 0.0, 5.0), r"center has shape \(3,\) but actual has shape \(8, 2\)"),
                               (lifted, (0.0, 0.0), r"center has shape \(2,\) but actual has shape \(8, 3\)")):
        with pytest.raises(ValueError, match=words):
            est.circular(act, center, 10.0)
    np.testing.assert_allclose(est.circular(lifted, (0.0, 0.0, 5.0), 10.0).magnitude, 0.0, atol=1e-12)


def test_result_is_read_only_and_time_first():
    ref = np.column_stack([np.linspace(0, 1, 10), np.zeros(10)])
    got = est.three_point(ref, ref + [0.0, 0.01])
    assert got.vector.shape == (10, 2) and got.magnitude.shape == (10,) and got.method == "three_point"
    with pytest.raises(ValueError):
        got.magnitude[0] = 1.0


# ---------------------------------------------------------------- the yardstick


def test_exact_delegates_to_the_continuous_path():
    from contoursim.feed import plan, sample
    from contoursim.paths import circle

    path = circle((0.0, 0.0), 50.0)
    ref = sample(path, plan(path, 50.0, 1000.0), 0.01)
    act = ref.position * (1 - 2e-5)  # 1 µm inside
    got = est.exact(ref, act)
    np.testing.assert_allclose(got.normal, 50.0 * 2e-5, rtol=1e-6)
    np.testing.assert_allclose(est.three_point(ref.position, act).normal, got.normal, rtol=0, atol=1e-12)


def test_bad_window_and_far_actual_points_are_refused_naming_them():
    # window NaN: "cannot convert float NaN to integer", inf: an OverflowError, "a": "invalid literal for int()"; 2.5e12
    # and True were taken; actual points of 1e200 mm were refused as a non-finite "magnitude"
    from contoursim.feed import plan, sample
    from contoursim.paths import circle

    path = circle((0.0, 0.0), 5.0)
    ref = sample(path, plan(path, 20.0, 500.0), 2e-3)
    act = ref.position * 1.001
    for window, error in ((float("nan"), TypeError), (float("inf"), TypeError), ("a", TypeError), (True, TypeError),
                          (1.5, TypeError), (0, ValueError)):
        with pytest.raises(error, match="window must be"):
            est.three_point(ref.position, act, window=window)
        with pytest.raises(error, match="window must be"):
            est.search_params(window=window)
    far = act.copy()
    far[3] = 1e200
    for call in (lambda: est.exact(ref, far), lambda: est.linear(ref.position, far), lambda: est.newton(ref.position, far),
                 lambda: est.three_point(ref.position, far), lambda: est.circular(far, (0, 0), 5.0)):
        with pytest.raises(ValueError, match=r"actual holds 1e\+200 at index \(3, 0\), beyond ±1e\+09"):
            call()
    with pytest.raises(ValueError, match=r"center holds 1e\+300 at index 0"):
        est.circular(act, (1e300, 0.0), 5.0)
    assert est.linear(ref.position, act + 1e6).magnitude.max() == pytest.approx(1e6 * 2**0.5, rel=1e-6)


def test_in_loop_arc_estimate_equals_the_offline_estimator():
    """The kernel's cross-coupled controller estimates what the offline estimator does on the same samples.

    A coupling with zero gains only observes: every servo period it runs the
    three-point arc estimate on the fed-back axis positions and logs it; the
    log equals the offline estimate over the kernel's output trace, and the
    loop is the uncoupled one bit for bit.
    """
    from contoursim import paths
    from contoursim.feed import plan, sample
    from contoursim.kernel import Coupling, run
    from contoursim.servo import AxisServo

    dt = 2e-4
    path = paths.circle(center=(0, 0), radius=10.0, direction="ccw")
    trajectory = sample(path, plan(path, feed=30.0, accel=1000.0), dt)
    n = len(trajectory)
    axis = AxisServo(mass=300.0, force_constant=942.0, kv=80.0, ti=0.016, kp=40.0)
    refs = (trajectory.position, trajectory.velocity, trajectory.acceleration)
    for estimator, offline in (("arc", est.three_point), ("linear", est.linear)):
        response = run([axis, axis], dt, *refs, coupling=Coupling(estimator, trajectory.position, kp=0.0))
        reference = np.column_stack([trajectory.position, np.zeros(n)])
        expected = offline(reference, np.column_stack([response.encoder, np.zeros(n)]))
        np.testing.assert_allclose(response.contour_estimate, expected.vector, rtol=0, atol=1e-15)
        np.testing.assert_array_equal(response.position, run([axis, axis], dt, *refs).position)
        assert expected.magnitude.max() > 1e-3  # there is an error to estimate
