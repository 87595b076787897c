"""Feed profiles against closed forms worked out by hand; sampling on the path."""

import tracemalloc
import warnings

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from contoursim import _memory, paths
from contoursim.exceptions import PathError
from contoursim.feed import FeedSettings, plan, sample
from contoursim.machine import load_machine
from contoursim.output import output_dir
from contoursim.plotting import save_figures
from contoursim.simulation import default_settle, simulate


def _differences(profile, dt):
    t = np.arange(0.0, profile.duration + 4 * dt, dt)
    s = profile.evaluate(t)[0]
    return s, np.diff(s, 2) / dt**2, np.diff(s, 3) / dt**3


def test_trapezoid_closed_form():
    # F = 20 mm/s, a = 100 mm/s^2: ramps of F/a = 0.2 s over F^2/2a = 2 mm; 96 mm at 20 mm/s
    profile = plan(paths.line((0, 0), (100, 0)), 20.0, 100.0)
    assert profile.duration == pytest.approx(0.2 + 96 / 20 + 0.2, rel=1e-12)
    s, v, a = profile.evaluate(np.array([0.1, 0.2, 2.6, 5.1, 5.2, 6.0]))
    np.testing.assert_allclose(s, [0.5, 2.0, 50.0, 99.5, 100.0, 100.0], rtol=1e-12)
    np.testing.assert_allclose(v, [10.0, 20.0, 20.0, 10.0, 0.0, 0.0], atol=1e-9)


def test_triangle_when_feed_is_not_reached():
    # 1 mm at a = 100: peak sqrt(a L) = 10 mm/s < F, duration 2 sqrt(L/a) = 0.2 s
    profile = plan(paths.line((0, 0), (1, 0)), 20.0, 100.0)
    assert profile.duration == pytest.approx(0.2, rel=1e-12)
    assert profile.evaluate([0.1])[1][0] == pytest.approx(10.0, rel=1e-12)


def test_scurve_closed_form_and_bounds():
    # F = 20, a = 100, j = 1000: F reached with a_max (F >= a^2/j = 10): T = L/F + F/a + a/j
    profile = plan(paths.line((0, 0), (100, 0)), 20.0, 100.0, 1000.0)
    assert profile.duration == pytest.approx(5.0 + 0.2 + 0.1, rel=1e-12)
    s, acc, jerk = _differences(profile, 1e-3)
    assert s[-1] == 100.0
    assert np.abs(acc).max() <= 100.0 * (1 + 1e-6) and np.abs(acc).max() > 99.0
    assert np.abs(jerk).max() <= 1000.0 * (1 + 1e-6)


def test_scurve_reduced_profile_for_short_moves():
    # neither a_max nor F reached: each half is a triangular acceleration pulse,
    # peak v = (L^2 j / 4)^(1/3), duration 4 sqrt(v / j)
    length, jerk = 0.5, 1000.0
    peak = (length**2 * jerk / 4) ** (1 / 3)
    profile = plan(paths.line((0, 0), (length, 0)), 20.0, 100.0, jerk)
    assert profile.duration == pytest.approx(4 * np.sqrt(peak / jerk), rel=1e-12)
    assert profile.evaluate([profile.duration / 2])[1][0] == pytest.approx(peak, rel=1e-12)
    s, acc, jerks = _differences(profile, 1e-4)
    assert s[-1] == length
    assert np.abs(acc).max() <= np.sqrt(peak * jerk) * (1 + 1e-6)
    assert np.abs(jerks).max() <= jerk * (1 + 1e-6)


@pytest.mark.parametrize(
    "first, jerk, want",
    [
        (1.0, None, np.sqrt(2 * 100.0 * 1.0)),  # v² = 2 a L
        (0.5, 1000.0, (0.5**2 * 1000.0) ** (1 / 3)),  # a_max not reached: L = v sqrt(v/j)
        (10.0, 1000.0, 40.0),  # a_max reached: v²/2a + v a/2j = L, i.e. v² + 10 v - 2000 = 0
    ],
)
def test_junction_speed_is_what_the_first_block_can_reach(first, jerk, want):
    # a short block at 3000 mm/min, then a long one at 3600 mm/min along the same line (a = 100 mm/s²):
    # the junction is passed at the speed reached from rest over the first block
    path = paths.polyline([[0, 0], [first, 0]]) + paths.polyline([[first, 0], [first + 100, 0]])
    profile = plan(path, [50.0, 60.0], 100.0, jerk)
    at_junction = profile.v0[np.flatnonzero(profile.s0 >= first)[0]]
    assert at_junction == pytest.approx(want, rel=1e-12)


def test_exact_stop_at_a_sharp_corner():
    # two rest-to-rest 10 mm moves: 2 (L/F + F/a) = 2 (0.5 + 0.2)
    path = paths.polyline([[0, 0], [10, 0], [10, 10]])
    profile = plan(path, 20.0, 100.0)
    assert profile.duration == pytest.approx(1.4, rel=1e-12)
    assert profile.evaluate([0.7])[:2] == pytest.approx((10.0, 0.0), abs=1e-9)


def test_per_block_feeds():
    # 50 mm at 20 then 50 mm at 10 (a = 100): 0.2 s ramp-up over 2 mm, brake 20 -> 10 in 0.1 s
    # over 1.5 mm, 46.5 mm cruise; then 49.5 mm at 10 and 0.1 s stop over 0.5 mm
    path = paths.line((0, 0), (50, 0)) + paths.line((50, 0), (100, 0))
    profile = plan(path, [20.0, 10.0], 100.0)
    assert profile.duration == pytest.approx(0.2 + 46.5 / 20 + 0.1 + 49.5 / 10 + 0.1, rel=1e-12)
    traj = sample(path, profile, 1e-3)
    second = traj.s > 50.0
    assert traj.speed[second].max() <= 10.0 + 1e-9 and traj.speed.max() == pytest.approx(20.0)


def test_a_rapid_ends_at_rest_and_waits_in_position():
    # a 10 mm rapid at 100 mm/s straight into a 10 mm cut at 10 mm/s (a = 1000): no corner, but the motion stops
    # at the rapid's end: a triangle 2 sqrt(L/a) = 0.2 s; then 0.01 s ramps over 0.05 mm and 9.9 mm at 10 mm/s
    path = paths.Path((paths.Line((0, 0, 0), (10, 0, 0), "rapid"), paths.Line((10, 0, 0), (20, 0, 0))))
    moves = 0.2 + 0.01 + 9.9 / 10 + 0.01
    assert plan(path, [100.0, 10.0], 1000.0).duration == pytest.approx(moves, rel=1e-12)
    profile = plan(path, [100.0, 10.0], 1000.0, in_position=0.05)
    assert profile.duration == pytest.approx(moves + 0.05, rel=1e-12)
    s, v, _ = profile.evaluate(np.array([0.2, 0.22, 0.249]))
    assert s.tolist() == [10.0, 10.0, 10.0] and v.tolist() == [0.0, 0.0, 0.0]  # waiting at the rapid's end
    # the samples of the wait belong to the rapid (not scored); the cut's are the test proper
    traj = sample(path, profile, 1e-3)
    waiting = (traj.t > 0.2 + 1e-9) & (traj.t < 0.25 - 1e-9)
    assert traj.rapid[waiting].all() and not traj.measuring[waiting].any()
    np.testing.assert_array_equal(traj.measuring, ~traj.rapid)
    apart = np.abs(traj.t - 0.25) > 1e-9  # the sample where the cut starts from rest may be either
    np.testing.assert_array_equal(traj.rapid[apart], traj.t[apart] < 0.25)
    with pytest.raises(ValueError, match="in_position"):
        plan(path, [100.0, 10.0], 1000.0, in_position=-1.0)


@pytest.mark.parametrize("shift", [(-133.76642301382856, 0.5), (-133.76642301382856, -198.17826002502937), (100.0, 0.0)])
def test_a_path_moved_is_sampled_as_it_was(shift):
    """Moved by (-133.77, 0.5) mm, a path's length came out 3.460000000000008 mm for 3.46: 7022 samples for 7021,
    the moved run's errors no longer sample for sample those of the first."""
    corners = np.array([(-4.0, 0.0), (-3.528, 0.0), (-0.54, 0.0)])
    here, there = (sample(path, plan(path, 5.0, 500.0), 1e-4)
                   for path in (paths.polyline(corners), paths.polyline(corners + shift)))
    assert len(here) == len(there)
    np.testing.assert_allclose(there.position - here.position, np.broadcast_to(shift, here.position.shape), atol=1e-9)
    np.testing.assert_allclose(there.velocity, here.velocity, atol=1e-9)


def test_centripetal_limit():
    path = paths.circle((0, 0), 50.0)
    traj = sample(path, plan(path, 100.0, 1000.0, centripetal_accel=50.0), 1e-3)
    assert traj.speed.max() == pytest.approx(np.sqrt(50.0 * 50.0), rel=1e-12)


@settings(max_examples=40, deadline=None, derandomize=True)
@given(st.lists(st.tuples(st.integers(-40, 40), st.integers(-40, 40)), min_size=3, max_size=9, unique=True),
       st.sampled_from([0.01, 0.1, 1.0]))
def test_a_spline_is_run_within_the_centripetal_limit_everywhere(points, scale):
    """v² κ ≤ a_c on every sample of any spline: the limit was set from the curvature at 65 values of w on each piece,
    which a tight turn between two of them passed at up to 53 times the limit (30 random splines)."""
    try:
        path = paths.spline(scale * np.array(points, float))
    except PathError:  # a cusp: refused, said so
        return
    traj = sample(path, plan(path, 50.0, 1000.0, 50000.0, centripetal_accel=500.0), 1e-4)
    curvature = np.linalg.norm(path.derivatives(traj.s)[2], axis=1)
    assert np.max(traj.speed**2 * curvature) <= 500.0 * (1 + 1e-6)


def test_a_tight_turn_in_a_spline_piece_slows_the_motion_there_not_over_the_whole_piece():
    """A spline out 10 mm and back 1 µm aside: its tip's curvature (about 1e8 1/mm) set the feed of both 10-mm pieces
    (a run of 5657 s); planned by the curvature along each piece, the motion slows for the tip alone."""
    path = paths.spline([[0, 0], [10, 0], [0, 0.001]])
    profile = plan(path, 1000 / 60, 1000.0, 50000.0)
    assert profile.duration < 10.0
    traj = sample(path, profile, 1e-5)
    assert traj.speed.max() == pytest.approx(1000 / 60, rel=1e-9)  # at the feed on most of the way out and back
    curvature = np.linalg.norm(path.derivatives(traj.s)[2], axis=1)
    assert np.max(traj.speed**2 * curvature) <= 1000.0 * (1 + 1e-6)


def test_a_spline_through_a_circles_points_is_run_as_the_circle():
    """A closed spline through 400 points of a 10-mm circle, at a feed the centripetal limit lowers to √(a_c R): its
    run lasts as the arc's (within 0.5 %). Its pieces' limits, apart in their rounding, made 400 sections, each from
    and to zero acceleration: 1.654 s against the arc's 0.979 s."""
    t = np.linspace(0.0, 2 * np.pi, 400, endpoint=False)
    spline = paths.spline(10.0 * np.column_stack([np.cos(t), np.sin(t)]), closed=True)
    circle = paths.circle((0, 0), 10.0)
    durations = [plan(path, 200.0, 1000.0, 50000.0, centripetal_accel=500.0).duration for path in (spline, circle)]
    assert durations[0] == pytest.approx(durations[1], rel=5e-3)


def test_an_arc_is_run_within_the_acceleration_limit_across_the_path_by_default():
    """A G-code corner rounded by a 0.5 mm fillet at F3000: its 50 mm/s turned through v²/R = 5000 mm/s² under a limit
    of 1000, the corner's contour error twice a control's (an outside probe). v ≤ √(a·R) on the arc, as a control's
    arc feed clamp holds it; the straight blocks keep their feed."""
    from contoursim.gcode import read_gcode

    program = read_gcode("G90 G21 G17\nG1 X29.5 Y0 F3000\nG3 X30 Y0.5 R0.5\nG1 X30 Y30\n")
    settings = FeedSettings(tuple(program.feeds), accel=1000.0)
    traj = sample(program.path, settings.plan(program.path), 1e-4)
    on_arc = (traj.position[:, 0] > 29.5 + 1e-9) & (traj.position[:, 1] < 0.5 - 1e-9)  # the fillet's quarter
    assert traj.speed[on_arc].max() == pytest.approx(np.sqrt(1000.0 * 0.5), rel=1e-9)
    assert traj.speed.max() == pytest.approx(50.0, rel=1e-12)


def test_a_rapid_traverses_at_most_at_the_machines_max_feed():
    """A G0 between two cuts on a machine of max_feed 3000 mm/min was refused at its line, feed 10000 mm/min, a feed
    the program never wrote: no program with a rapid between cuts could run there (an outside probe)."""
    from contoursim.gcode import read_gcode

    program = read_gcode("G0 X0 Y0\nG1 X5 F1000\nG0 X20\nG1 X25\n")
    settings = FeedSettings(tuple(program.feeds), stops=tuple(program.stops))
    traj = sample(program.path, settings.plan(program.path, max_feed=50.0), 1e-3)
    rapid = (traj.s > 5.0) & (traj.s < 20.0)
    assert traj.speed[rapid].max() == pytest.approx(50.0, rel=1e-9)
    assert traj.speed[~rapid].max() == pytest.approx(1000 / 60, rel=1e-9)
    with pytest.raises(ValueError, match="exceeds max_feed"):  # a cutting feed above it is still refused
        settings.plan(program.path, max_feed=10.0)


def test_a_join_passed_at_a_velocity_step_beyond_the_acceleration_is_warned_of():
    """A reversal under corner_tolerance_deg = 180 was passed at 50 mm/s, the reference turning its velocity by 100
    mm/s in one servo period (5e5 mm/s² against accel = 1000), without a word (an outside probe)."""
    from contoursim.exceptions import ContoursimWarning

    out_and_back = paths.line((0, 0), (10, 0)) + paths.line((10, 0), (0, 0))
    with pytest.warns(ContoursimWarning, match=r"^1 join under corner_tolerance_deg = 180 is passed at speed: the "
                                               r"velocity turns by up to 100 mm/s within a servo period \(a join of "
                                               r"180° at 50 mm/s\), 5e\+05 mm/s² against accel = 1000"):
        plan(out_and_back, 50.0, 1000.0, corner_tolerance=np.pi, servo_period=2e-4)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        plan(out_and_back, 50.0, 1000.0, corner_tolerance=np.pi)  # no period, no sampled step to judge
        plan(out_and_back, 50.0, 1000.0, servo_period=2e-4)  # stopped at the reversal
        gentle = paths.polyline([(0, 0), (10, 0), (20, 0.005)])  # 0.029°, under the default: a step of 0.025 mm/s
        plan(gentle, 50.0, 1000.0, servo_period=2e-4)


def test_many_slight_joins_that_stop_exactly_are_warned_of_with_the_time_they_cost():
    """A circle of 20,000 G1 segments to 6 decimals: rounding turned 5,268 joins over the default tolerance; the run
    took 17.6 s at 64 mm/min on average for F1000, without a word (an outside probe)."""
    from contoursim.exceptions import ContoursimWarning

    angles = np.radians(np.cumsum(np.r_[0.0, np.full(20, 0.1)]))  # 20 joins of 0.1°
    zig = paths.polyline(np.column_stack([np.cumsum(np.cos(angles)), np.cumsum(np.sin(angles))]))
    with pytest.warns(ContoursimWarning, match=r"^19 joins stop exactly though each turns by less than 1° "
                                               r"\(corner_tolerance_deg = 0.0573; up to 0.1° here\): the path takes"):
        stopping = plan(zig, 50.0, 1000.0)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        passing = plan(zig, 50.0, 1000.0, corner_tolerance=np.radians(0.2))
    assert stopping.duration > 2 * passing.duration


def test_bad_values_name_the_parameter():
    path = paths.line((0, 0), (10, 0))
    with pytest.raises(ValueError, match="exceeds max_feed"):
        plan(path, 30.0, 100.0, max_feed=20.0)
    with pytest.raises(ValueError, match="accel must be positive"):
        plan(path, 10.0, -1.0)
    with pytest.raises(ValueError, match=r"feed\[1\] = 0"):
        plan(path + paths.line((10, 0), (20, 0)), [10.0, 0.0], 100.0)
    with pytest.raises(ValueError, match="jerk must be positive"):
        FeedSettings(10.0, jerk=0.0)
    for tolerance in (4.0, 720.0):  # no join turns more than π: a reversal
        with pytest.raises(ValueError, match=r"corner_tolerance must be at most π rad \(180°, a reversal\)"):
            FeedSettings(10.0, corner_tolerance=tolerance)
        with pytest.raises(ValueError, match="corner_tolerance must be at most π rad"):
            plan(path, 10.0, 100.0, corner_tolerance=tolerance)
    with pytest.raises(ValueError, match="dt must be positive"):
        sample(path, plan(path, 10.0, 100.0), 0.0)


def test_a_feed_slower_than_any_machine_moves_is_refused_by_plan_as_by_feed_settings():
    # plan(path, 1e-300, ...) planned a motion of 1e301 s, which sample then refused for the memory its run needs
    # (FeedSettings(1e-300) was refused at once)
    path = paths.line((0, 0), (10, 0))
    two = path + paths.line((10, 0), (20, 0))
    for call, words in ((lambda: plan(path, 1e-300, 100.0), r"feed must lie within \[1e-06, 1e\+12\] mm/s, got 1e-300: "
                                                           r"no machine moves so slowly or so fast"),
                        (lambda: plan(two, [10.0, 1e-9], 100.0), r"feed\[1\] must lie within \[1e-06, 1e\+12\] mm/s, "
                                                                  "got 1e-09"),
                        (lambda: plan(path, 10.0, 1e-300), r"accel must lie within \[1e-06, 1e\+12\] mm/s\^2"),
                        (lambda: FeedSettings(1e-300), r"feed must lie within \[1e-06, 1e\+12\] mm/s, got 1e-300")):
        with pytest.raises(ValueError, match=words):
            call()
    assert plan(path, 1e-6, 100.0).duration == pytest.approx(1e7)


def test_servo_period_and_stops_are_checked_where_given():
    # a servo period of 0, NaN or -1 was taken (-1 warned of a velocity step "against -0.001 mm/s²"), one of text
    # failed inside the corner check; a stop at 1.5 was cut to primitive 1, one at -3 or of text failed elsewhere
    path = paths.polyline([(0, 0), (1, 0), (2, 1e-4)])
    for period in (0.0, float("nan"), -1.0):
        with pytest.raises(ValueError, match="servo_period must be"):
            plan(path, 10.0, 100.0, servo_period=period)
    with pytest.raises(TypeError, match="servo_period must be a number"):
        plan(path, 10.0, 100.0, servo_period="a")
    for stops, want in (([1.5], r"stops\[0\] must be a whole number, got 1.5"), ([True], r"stops\[0\] must be a whole"),
                        ([0, -3], r"stops\[1\] must be at least 0, got -3"), ("ab", "stops must be a sequence")):
        with pytest.raises((TypeError, ValueError), match=want):
            FeedSettings(10.0, stops=stops)
        with pytest.raises((TypeError, ValueError), match=want):
            plan(path, 10.0, 100.0, stops=stops)
    with pytest.raises(ValueError, match=r"stops must be primitive indices in \[0, 1\], got \[2\]"):
        plan(path, 10.0, 100.0, stops=[2])
    assert FeedSettings(10.0, stops=[np.int64(1)]).stops == (1,)
    assert plan(path, 10.0, 100.0, stops=[0]).duration > plan(path, 10.0, 100.0).duration


def test_sampled_circle_lies_on_the_path_with_analytic_derivatives():
    radius, feed, dt = 50.0, 1000 / 60, 1e-3
    path = paths.iso230_4_circle(radius)
    traj = sample(path, plan(path, feed, 1000.0, 50000.0), dt)
    assert traj.dim == 2 and np.all(np.diff(traj.t) == pytest.approx(dt))
    assert traj.s[-1] == path.length and traj.speed[-1] == 0.0
    on = traj.measuring
    assert np.all(path.segment_index(traj.s[on]) == 2) and on.sum() == pytest.approx(2 * np.pi * radius / feed / dt, abs=2)
    np.testing.assert_allclose(np.linalg.norm(traj.position[on], axis=1), radius, atol=1e-9)
    # on the test circle (cruise): |a| = v^2 / R, velocity matches central differences
    np.testing.assert_allclose(np.linalg.norm(traj.acceleration[on], axis=1), feed**2 / radius, rtol=1e-9)
    # central difference error at constant speed: v^3 dt^2 / (6 R^2)
    inside = np.flatnonzero(on)[1:-1]
    central = (traj.position[inside + 1] - traj.position[inside - 1]) / (2 * dt)
    np.testing.assert_allclose(central, traj.velocity[inside], rtol=0, atol=1.01 * feed**3 * dt**2 / (6 * radius**2))


def test_exact_stop_at_every_sharp_corner():
    """At each sharp corner the feed comes to rest, so the velocity vector never jumps."""
    square = paths.polyline([[0, 0], [20, 0], [20, 20], [0, 20], [0, 0]], 0.0)
    dt, accel = 1e-3, 1000.0
    trajectory = sample(square, plan(square, 2000 / 60, accel), dt)
    dv = np.linalg.norm(np.diff(trajectory.velocity, axis=0), axis=1) / dt
    assert dv.max() <= accel * (1 + 1e-9)
    for corner in (20.0, 40.0, 60.0):
        near = np.abs(trajectory.s - corner) < 0.5
        assert trajectory.speed[near].min() < accel * dt


def test_refuses_a_motion_whose_run_needs_more_memory_than_is_available(monkeypatch):
    # 100 mm at 0.001 mm/min lasts 6e6 s: 6e9 samples at 1 ms (48 GB per column), refused before allocating
    path = paths.line((0, 0), (100, 0))
    profile = plan(path, 1e-3 / 60, 100.0)
    assert profile.duration == pytest.approx(100 / (1e-3 / 60), rel=1e-6)
    with pytest.raises(ValueError, match=r"lasts 6e\+06 s: at dt = 0\.001 s that is 6e\+09 samples, a run of them "
                                         r"needs about 2\.7e\+03 GB of memory and [0-9.e+]+ GB are available"):
        sample(path, profile, 1e-3)
    # 1.00001 s of a line at 1 ms: 1002 samples, 451 kB; refused with 400 kB available, sampled with 500 kB
    line = paths.line((0, 0), (10, 0))
    profile = plan(line, 10.0, 1e6)
    assert profile.duration == pytest.approx(1.0, abs=1e-3)
    monkeypatch.setattr(_memory, "available", lambda: 400_000)
    with pytest.raises(ValueError, match=r"that is 1002 samples, a run of them needs about 0\.000451 GB of memory "
                                         r"and 0\.0004 GB are available"):
        sample(line, profile, 1e-3)
    monkeypatch.setattr(_memory, "available", lambda: 500_000)
    assert len(sample(line, profile, 1e-3)) == 1002
    monkeypatch.setattr(_memory, "available", lambda: None)  # unknown: not refused
    assert len(sample(line, profile, 1e-3)) == 1002


@pytest.mark.parametrize("path", [paths.circle((0, 0), 5.0), paths.helix((0, 0, 0), 5.0, 2.0, 1.0)],
                         ids=["circle", "helix"])
def test_the_memory_a_sample_is_allowed_covers_a_run(path, tmp_path):
    """sample's limit: a run (reference, simulation, exact contour error, trace CSV, plots) allocates less than the figure."""
    machine = load_machine("demo_mill")
    profile = plan(path, 0.5, 1000.0)
    simulate(machine, sample(path, profile, machine.servo_period))  # numba functions loaded before measuring
    tracemalloc.start()
    try:
        trajectory = sample(path, profile, machine.servo_period).held(default_settle(machine))
        result = simulate(machine, trajectory, settle=0.0)
        del trajectory
        result.save_csv(tmp_path / "run.csv")
        save_figures({"run": result}, output_dir(tmp_path / "out"), "run")
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert len(result.trajectory) > 100_000
    assert peak < _memory.RUN_BYTES_PER_SAMPLE * len(result.trajectory)


@pytest.mark.parametrize("jerk", [None, 2000.0, 50000.0])
def test_section_peak_is_the_largest_that_fits(jerk):
    """Between junction speeds v0, v1 the peak is the largest speed whose two ramps fit the section."""
    from contoursim.feed import _peak, _ramp_distance

    rng = np.random.default_rng(7)
    for _ in range(500):
        v0, v1 = rng.uniform(0, 30, 2) * (rng.random(2) > 0.2)
        vmax = max(v0, v1) + rng.uniform(0, 30)
        top = max(v0, v1)
        length = _ramp_distance(v0, top, 100.0, jerk) + _ramp_distance(top, v1, 100.0, jerk) + rng.uniform(0, 3) ** 3

        def total(x):
            return _ramp_distance(v0, x, 100.0, jerk) + _ramp_distance(x, v1, 100.0, jerk)

        peak = _peak(v0, v1, length, vmax, 100.0, jerk)
        assert top <= peak <= vmax and total(peak) <= length
        assert peak == vmax or total(peak * (1 + 1e-12)) > length
