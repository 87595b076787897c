"""Contour error never exceeds tracking error, on any path: generated G-code programs, the library, a real kernel.

The tool's distance to the path can never exceed its distance to the
commanded point, which lies on the path. The programs are generated
property-based (hypothesis): random sequences of G0/G1/G2/G3 in G17/G18/G19
with reversals (straight back along the last move), zero-length and very
short moves, full circles, helices and rapid retracts. The tool follows
each axis through a first-order lag of its own gain (the exact discrete
form, no contoursim kernel), so the actual path cuts inside corners, lags
around arcs and overshoots nothing; then the exact contour error and the
in-loop estimators (three-point arc, Newton, linear) are held to the
invariant: each is a distance to some point of the path (or of the local
curve through the commanded sample), so none may exceed the tracking error.
"""

import math
from importlib import resources

import numpy as np
import pytest
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st
from scipy.signal import lfilter

from contoursim import estimators, paths
from contoursim.contour import exact_contour_error
from contoursim.exceptions import PathError
from contoursim.feed import plan, sample
from contoursim.gcode import read_gcode
from contoursim.machine import load_machine
from contoursim.pathfile import load_path_file
from contoursim.simulation import simulate
from contoursim.trajectory import Trajectory

ROUNDING = 1e-9  # [mm]: the foot point and the sample are the same path point evaluated two ways

_PLANE_AXES = {17: ("X", "Y", "Z", "I", "J"), 18: ("Z", "X", "Y", "K", "I"), 19: ("Y", "Z", "X", "J", "K")}


def _fmt(value):
    return f"{value:.4f}".rstrip("0").rstrip(".") or "0"


@st.composite
def programs(draw):
    """G-code text of a random program that starts with a feed move from the origin."""
    pos = {"X": 0.0, "Y": 0.0, "Z": 0.0}
    previous = dict(pos)
    lines = ["G21 G90 G94", "G0 X0 Y0 Z0", f"G1 X{_fmt(draw(st.floats(0.5, 5)))} F{draw(st.integers(60, 3000))}"]
    pos["X"] = float(lines[-1].split()[1][1:])
    for _ in range(draw(st.integers(1, 7))):
        kind = draw(st.sampled_from(["line", "back", "zero", "tiny", "arc", "circle", "helix", "retract"]))
        plane = draw(st.sampled_from([17, 18, 19]))
        a, b, n, ia, ib = _PLANE_AXES[plane]
        if kind in ("line", "tiny"):
            size = 5.0 if kind == "line" else 0.003
            target = {k: pos[k] + draw(st.floats(-size, size)) for k in "XYZ"}
            words = " ".join(f"{k}{_fmt(v)}" for k, v in target.items())
            lines.append(f"G1 {words}")
        elif kind == "back":  # straight back to where the last move started: the path reverses
            target = dict(previous)
            lines.append("G1 " + " ".join(f"{k}{_fmt(v)}" for k, v in target.items()))
        elif kind == "zero":
            target = dict(pos)
            lines.append("G1 " + " ".join(f"{k}{_fmt(v)}" for k, v in target.items()))
        elif kind == "retract":  # a drilling cycle written as moves: plunge, rapid back up
            depth = draw(st.floats(0.2, 3.0))
            lines.append(f"G1 Z{_fmt(pos['Z'] - depth)}")
            lines.append(f"G0 Z{_fmt(pos['Z'])}")
            target = dict(pos)
        else:  # an arc in the plane: centre at radius r from the start, a sweep, full turns, a rise along n
            radius = draw(st.floats(0.5, 6.0))
            start = draw(st.floats(0, 2 * math.pi))
            sweep = 2 * math.pi if kind == "circle" else draw(st.floats(0.1, 2 * math.pi - 0.1))
            cw = draw(st.booleans())
            center = (pos[a] - radius * math.cos(start), pos[b] - radius * math.sin(start))
            end = start - sweep if cw else start + sweep
            target = dict(pos)
            target[a] = center[0] + radius * math.cos(end)
            target[b] = center[1] + radius * math.sin(end)
            if kind == "circle":
                target[a], target[b] = pos[a], pos[b]
            # rounded ends must stay on the arc: write the centre to 4 decimals and the end as computed from it
            i_off, j_off = round(center[0] - pos[a], 4), round(center[1] - pos[b], 4)
            r_exact = math.hypot(i_off, j_off)
            cx, cy = pos[a] + i_off, pos[b] + j_off
            if kind != "circle":
                target[a] = round(cx + r_exact * math.cos(end), 4)
                target[b] = round(cy + r_exact * math.sin(end), 4)
            rise = draw(st.floats(-2.0, 2.0)) if kind == "helix" else 0.0
            target[n] = pos[n] + rise
            lines.append(f"G{plane} G{2 if cw else 3} {a}{_fmt(target[a])} {b}{_fmt(target[b])} {n}{_fmt(target[n])} "
                         f"{ia}{_fmt(i_off)} {ib}{_fmt(j_off)}")  # fmt: skip
        previous, pos = dict(pos), {k: float(_fmt(v)) for k, v in target.items()}
    lines.append("M30")
    return "\n".join(lines) + "\n"


def _lagged(reference, gains, dt):
    """Each axis behind its reference through a first-order lag, exact discrete form, starting on it [mm]."""
    out = np.empty_like(reference)
    for axis, kp in enumerate(gains):
        a = math.exp(-kp * dt)
        out[:, axis] = lfilter([0.0, 1.0 - a], [1.0, -a], reference[:, axis], zi=reference[:1, axis])[0]
    return out


def _check(trajectory, actual):
    tracking = np.linalg.norm(actual - trajectory.position, axis=1)
    exact = exact_contour_error(trajectory, actual)
    worst = int(np.argmax(exact.magnitude - tracking))
    assert exact.magnitude[worst] <= tracking[worst] + ROUNDING, (
        f"contour {exact.magnitude[worst]:.6g} mm > tracking {tracking[worst]:.6g} mm at sample {worst}")
    for method in (estimators.three_point, estimators.newton, estimators.linear):
        estimate = method(trajectory.position, actual)
        assert np.all(estimate.magnitude <= tracking + ROUNDING), method.__name__
    return exact, tracking


@settings(max_examples=1000, deadline=None, derandomize=True, suppress_health_check=[HealthCheck.too_slow])
@given(programs(), st.tuples(*[st.floats(15.0, 80.0)] * 3))
def test_contour_error_never_exceeds_tracking_on_generated_programs(text, gains):
    """1,000 programs (hypothesis, derandomized: the same 1,000 every run), servo period 1 ms."""
    program = read_gcode(text)
    dt = 1e-3
    trajectory = sample(program.path, plan(program.path, program.feeds, 2000.0), dt)
    _check(trajectory, _lagged(trajectory.position, gains[: trajectory.dim], dt))


def test_the_retract_that_broke_it():
    """Out and back along X, then up Y (issue 17): contour was 9.77 mm with tracking 0.28 mm."""
    program = read_gcode("G21 G90 G17\nG0 X0 Y0\nG1 X10 F600\nG1 X0\nG1 Y10\nM30\n")
    dt = 2e-4
    trajectory = sample(program.path, plan(program.path, program.feeds, 1000.0), dt)
    exact, tracking = _check(trajectory, _lagged(trajectory.position, (40.0, 36.0), dt))
    # on the way back the tool rides the line it came along: no contour error beyond rounding there
    back = (trajectory.s > 10.5) & (trajectory.s < 19.5)
    assert exact.magnitude[back].max() < 1e-9 < tracking[back].min()


def test_a_loop_whose_start_passes_near_the_tool_is_not_taken():
    """A 330° arc: the tool lags 0.55 mm behind its end, right beside the arc's start, 0.05 mm away.

    The start is not connected to the commanded end inside the ball (the arc leaves it around 250°): the contour
    error is the distance to the end, not the 0.05 mm to the start it was (the arc's foot, clamped, took the end
    nearer in angle, across the point farthest from the tool).
    """
    program = read_gcode("G0 X1 Y0\nG3 X0.866025 Y-0.5 R-1 F600\n")
    trajectory = sample(program.path, plan(program.path, 10.0, 1000.0), 1e-3)
    tool = np.array([1.05, 0.02])
    exact = exact_contour_error(trajectory, [tool], at=[len(trajectory) - 1])
    np.testing.assert_allclose(exact.foot[0], [0.866025, -0.5], atol=1e-12)
    assert exact.magnitude[0] == pytest.approx(np.linalg.norm(tool - [0.866025, -0.5]), abs=1e-12)


_ENDS = st.one_of(st.floats(0.0, 0.1), st.floats(0.9, 1.0), st.floats(0.0, 1.0))  # a path's ends come near each other


@settings(max_examples=300, deadline=None, derandomize=True)
@given(st.sampled_from(["G2", "G3"]), st.floats(0.2, 2 * math.pi - 0.01), st.floats(-1.0, 1.0), _ENDS, _ENDS,
       st.floats(0.0, 2 * math.pi), st.floats(0.0, 0.5))
def test_the_foot_is_connected_to_the_commanded_point_inside_the_ball(word, sweep, rise, where, near, bearing, off):
    """An arc or helix of R 1 (one primitive), the commanded point anywhere on it, the tool beside any other point of it.

    The module's contract (contoursim.nearest): the foot lies on the part of the path connected to the commanded
    point R inside the ball of radius 2|P - R| about R: the path between them leaves that ball for no more than its
    radius of length at a time (the tip of a corner the ball clips), within two samples' spacing.
    """
    turn = -sweep if word == "G2" else sweep  # R, not I/J: read_gcode cuts an arc over 180° off its radius in two
    program = read_gcode(f"G17 G0 X1 Y0 Z0\n{word} X{math.cos(turn):.12f} Y{math.sin(turn):.12f} Z{rise:.6f} "
                         f"R{-1 if sweep > math.pi else 1} F600\n")
    trajectory = sample(program.path, plan(program.path, 10.0, 1000.0), 1e-3)
    commanded = int(where * (len(trajectory) - 1))
    reference = trajectory.position[commanded]
    beside = program.path.evaluate([near * program.path.length])[0][0, :trajectory.dim]
    tool = beside + off * np.array([math.cos(bearing), math.sin(bearing), 0.3 * math.sin(3 * bearing)])[:trajectory.dim]
    exact = exact_contour_error(trajectory, [tool], at=[commanded])
    tracking = np.linalg.norm(tool - reference)
    assert exact.magnitude[0] <= tracking + ROUNDING
    between = np.linspace(exact.s[0], trajectory.s[commanded], 4001)
    outside = np.linalg.norm(program.path.evaluate(between)[0][:, :trajectory.dim] - reference, axis=1) > 2 * tracking
    spacing = np.diff(trajectory.s).max()
    for run in np.split(between, np.flatnonzero(np.diff(outside.astype(int))) + 1)[0 if outside[0] else 1::2]:
        away = abs(run[-1] - run[0]) + 2 * abs(between[1] - between[0])  # the run's ends are a step inside the ball
        assert away <= 2 * tracking + 2 * spacing, f"the path between foot and commanded point leaves the ball for {away:.3g} mm"


def _hand_sampled(path, s):
    """A reference of the samples at arc lengths `s` [mm] of `path`, one per servo period of 1 ms."""
    position = path.evaluate(s)[0][:, : path.dim]
    n = len(s)
    return Trajectory(np.arange(n) * 1e-3, position, np.zeros_like(position), np.zeros_like(position), s, path=path)


def test_a_branch_nearer_than_the_nearest_sample_is_found():
    """A narrow V sampled every 1 mm: the tool 0.1 mm from the way back, between two of its samples (0.51 mm away).

    The nearest sample is one of the way out, 0.30 mm below the tool, and the foot on the way out is as far: the
    refinement around that sample alone missed the way back (0.30 mm reported for 0.1 mm). The commanded point,
    2 mm before the corner, is 2.01 mm from the tool: both branches are connected to it inside the ball.
    """
    path = paths.polyline([(0.0, 0.0), (10.0, 0.0), (0.0, 1.0)])
    back = np.array([-10.0, 1.0]) / math.hypot(10.0, 1.0)  # direction of the way back
    s = np.concatenate([np.arange(0.0, 10.0, 1.0), 10.0 + np.arange(0.5, path.length - 10.0, 1.0), [path.length]])
    trajectory = _hand_sampled(path, s)
    tool = np.array([10.0, 0.0]) + 4.0 * back + 0.1 * np.array([-back[1], back[0]])  # 4 mm back, 0.1 mm inside
    samples = np.linalg.norm(trajectory.position - tool, axis=1)
    assert trajectory.position[np.argmin(samples), 1] == 0.0 and samples.min() < 0.3  # the premise
    exact = exact_contour_error(trajectory, [tool], at=[8])  # the sample at (8, 0)
    assert exact.magnitude[0] == pytest.approx(0.1, abs=1e-12)
    np.testing.assert_allclose(exact.foot[0], [10.0, 0.0] + 4.0 * back, atol=1e-12)


def test_a_corner_the_ball_clips_is_part_of_the_path_searched():
    """A zig-zag of narrow Vs at 31.2 mm/s, the commanded point 0.1 mm past a corner, the tool 4.5 µm from the way in.

    The corner lies 0.4 µm outside the ball of twice the tracking error (99.2 µm from the commanded point, the
    ball's radius 98.8 µm): the way in was cut off and the contour error was 26.7 µm, the distance to the way out,
    one sample after 4.5 µm. It is the distance to the nearest segment (closed form) at both samples.
    """
    corners = [(0.0, 0.0), (0.27697346393363714, 2.5134313031118176), (0.5539469278672743, 0.0),
               (0.8309203918009114, 2.5134313031118176), (1.1078938557345486, 0.0)]
    path = paths.polyline(corners)
    trajectory = sample(path, plan(path, 31.2144153823481, 500.0), 1e-4)
    tools = np.array([[0.5427141152616279, 0.14307223325140478], [0.5428019743699176, 0.14288353475759677]])
    exact = exact_contour_error(trajectory, tools, at=[3067, 3068])
    corner = np.array(corners[2])
    assert 2 * np.linalg.norm(tools[1] - trajectory.position[3068]) < np.linalg.norm(corner - trajectory.position[3068])
    a, b = np.array(corners[:-1]), np.array(corners[1:])
    along = np.clip(np.einsum("nkd,kd->nk", tools[:, None] - a, b - a) / np.einsum("kd,kd->k", b - a, b - a), 0, 1)
    segments = np.linalg.norm(tools[:, None] - (a + along[..., None] * (b - a)), axis=2).min(axis=1)
    np.testing.assert_allclose(exact.magnitude, segments, atol=1e-12)
    assert exact.magnitude.max() < 5e-3


def _connected_distance(path, dim, tool, commanded_s, radius, step, bridge=0.0):
    """Brute force: the smallest distance from the tool to the path sampled every `step` mm, over the run of those
    points around the commanded one (at arc length `commanded_s`) inside the ball of `radius` about it [mm], its
    stretches outside the ball of no more than `bridge` mm of length between two points inside taken as connecting.
    """
    s = np.union1d(np.append(np.arange(0.0, path.length, step), path.length), [commanded_s])
    points = path.evaluate(s)[0][:, :dim]
    k = int(np.searchsorted(s, commanded_s))
    inside = np.flatnonzero(np.linalg.norm(points - points[k], axis=1) <= radius)
    cut = (np.diff(inside) > 1) & (np.diff(s[inside]) > bridge)  # between two inside points: outside ones, too long
    part = np.split(inside, np.flatnonzero(cut) + 1)
    run = next(r for r in part if r[0] <= k <= r[-1])
    return np.linalg.norm(points[run] - tool, axis=1).min()


_CORNER = st.tuples(*[st.floats(-3.0, 3.0)] * 3)


@settings(max_examples=300, deadline=None, derandomize=True)
@given(st.lists(_CORNER, min_size=3, max_size=6), st.sampled_from([2, 3]), st.sampled_from([0.0, 0.0, 0.2]),
       st.floats(0.05, 1.0), st.integers(0, 2**32 - 1), st.floats(0.0, 1.0), st.tuples(*[st.floats(-1.0, 1.0)] * 3),
       st.integers(-10, 10))
def test_the_contour_error_is_the_distance_to_the_connected_part_of_the_ball(corners, dim, blend, spacing, seed,
                                                                            where, offset, lag):  # fmt: skip
    """Zig-zags of 2-5 segments (2-D or 3-D, sharp or blended corners) sampled by hand every ~`spacing` mm (spacing
    jittered by up to 30 %), the tool anywhere near the path, the commanded sample up to 10 samples from it.

    Against the brute force on the path sampled every spacing/200: the part of the path the search may take ends
    within a sample spacing h of the ball's surface, and a stretch outside the ball connects when no longer than its
    radius along the path between the samples either side of it (up to 2h longer than the stretch), so the contour error lies
    between the brute force over the ball of radius 2|P - R| + h connected across stretches of 2|P - R| + 6h and
    that over the ball of radius 2|P - R| - h connected across stretches of 2|P - R| - 3h (the same distance
    wherever the nearest point is not at the surface or beyond a stretch of about the radius), within the brute
    force's own sampling error.
    """
    corners = np.array(corners)[:, :dim]
    try:
        path = paths.polyline(corners, blend_radius=blend)
    except PathError:  # points too close, a reversal, a blend that does not fit
        assume(False)
    assume(not path.closed)  # the search does not cross a closed path's seam; the brute force would
    dim = path.dim  # 2 for 3-D corners in the xy plane
    assume(np.linalg.norm(np.diff(corners, axis=0), axis=1).min() > 0.2)
    rng = np.random.default_rng(seed)
    n = max(2, math.ceil(path.length / spacing))
    s = np.linspace(0.0, path.length, n + 1)
    s[1:-1] += rng.uniform(-0.3, 0.3, n - 1) * (path.length / n)
    trajectory = _hand_sampled(path, s)
    h = np.diff(s).max()
    foot = path.evaluate([where * path.length])[0][0, :dim]
    tool = foot + np.array(offset)[:dim]
    commanded = int(np.clip(np.searchsorted(s, where * path.length) + lag, 0, n))
    tracking = np.linalg.norm(tool - trajectory.position[commanded])
    exact = exact_contour_error(trajectory, [tool], at=[commanded]).magnitude[0]
    step = spacing / 200
    inner = _connected_distance(path, dim, tool, s[commanded], max(2 * tracking - h, 0.0), step,
                                bridge=max(2 * tracking - 3 * h, 0.0))
    outer = _connected_distance(path, dim, tool, s[commanded], 2 * tracking + h, step, bridge=2 * tracking + 6 * h)
    assert outer - step / 2 - ROUNDING <= exact <= inner + ROUNDING, (exact, outer, inner)


LIBRARY = sorted(f.name for f in resources.files("contoursim.trajectories").iterdir() if f.name.endswith((".toml", ".nc")))


@pytest.mark.parametrize("name", LIBRARY)
def test_contour_error_never_exceeds_tracking_on_the_library_through_the_kernel(name):
    """Every path of trajectories/ on the demo mill, stepped by contoursim's own kernel."""
    machine = load_machine("demo_mill")
    path, feed = load_path_file(name)
    result = simulate(machine, sample(path, feed.plan(path, machine.max_feed), machine.servo_period))
    tracking = np.linalg.norm(result.tool_position - result.trajectory.position, axis=1)
    assert np.all(result.contour.magnitude <= tracking + ROUNDING)


@settings(max_examples=60, deadline=None)
@given(corners=st.integers(3, 6), seam=st.integers(0, 5), radius=st.floats(5.0, 20.0), wobble=st.floats(0.0, 0.3),
       u=st.floats(0.05, 0.3), v=st.floats(0.05, 0.3), offset=st.floats(-0.04, 0.04), mid=st.booleans())
def test_a_closed_path_is_a_loop_whatever_its_seam(corners, seam, radius, wobble, u, v, offset, mid):
    """The commanded point a fraction u of the first side past the seam, the tool beside the last side a fraction v
    before it: the contour error is the distance to the polygon, wherever the seam lies (a corner or mid-side). The
    walk stopped at the seam: 0.4 mm against 0.05 mm on a square whose seam is a corner, 0.05 mm once it was moved
    (an outside probe)."""
    angles = 2 * np.pi * (np.arange(corners) + wobble * np.sin(np.arange(corners) * 2.3)) / corners
    ring = np.column_stack([radius * np.cos(angles), radius * np.sin(angles)])
    ring = np.roll(ring, -(seam % corners), axis=0)
    if mid:  # the seam half-way along a side
        ring = np.vstack([(ring[-1] + ring[0]) / 2, ring])
    points = np.vstack([ring, ring[:1]])
    path = paths.polyline(points)
    reference = sample(path, plan(path, 10.0, 1000.0), 0.001)
    first, last = points[1] - points[0], points[-2] - points[-1]  # from the seam along the first side, the last one
    r = points[0] + u * first
    normal = np.array([-last[1], last[0]]) / np.linalg.norm(last)
    tool = points[-1] + v * last + offset * normal
    assume(np.linalg.norm(u * first) + np.linalg.norm(v * last) < 1.5 * np.linalg.norm(tool - r))  # the way in the ball
    at = int(np.argmin(np.linalg.norm(reference.position - r, axis=1)))
    found = exact_contour_error(reference, tool[None], at=[at]).magnitude[0]
    a, b = points[:-1], points[1:]
    t = np.clip(np.einsum("ij,ij->i", tool - a, b - a) / np.einsum("ij,ij->i", b - a, b - a), 0.0, 1.0)
    assert found == pytest.approx(np.min(np.linalg.norm(tool - a - t[:, None] * (b - a), axis=1)), abs=1e-9)


_TIGHT = [[-3.5213736593918465, 6.968132795158194], [7.719785577338502, 8.812039086058007],
          [5.97962911736685, 8.974134096312937], [6.761597686091811, -5.180153742329008],
          [-3.9169419405422268, 8.374327852506351], [-8.704995158764149, 6.83121731803751]]


@settings(max_examples=60, deadline=None, derandomize=True)
@given(st.one_of(st.just(_TIGHT), st.lists(st.tuples(st.integers(-9, 9), st.integers(-9, 9)), min_size=3, max_size=7,
                                           unique=True)),
       st.sampled_from([1e-6, 1e-4]))
def test_a_tool_off_a_splines_tightest_turn_is_no_farther_from_the_path_than_from_where_it_stands_off(points, off):
    """Tools `off` along the normal from points within 0.05 mm of a spline's tightest turn, each commanded at the
    sample nearest its point: the distance to the path is at most `off`. The foot's search started from the arc-length
    table's linear guess, which near a tight turn lies on the turn's other leg, and kept the sample: up to 5.7e-4 mm
    for 1e-6 mm on the first case."""
    try:
        path = paths.spline(np.array(points, float))
    except PathError:  # a cusp: refused
        return
    grid = np.linspace(0.0, path.length, 200001)
    peak = grid[np.argmax(np.linalg.norm(path.derivatives(grid)[2], axis=1))]
    s = np.clip(peak + np.linspace(-0.05, 0.05, 201), 0.0, path.length)
    position, tangent, bend = path.derivatives(s)
    off = min(off, 0.1 / np.linalg.norm(bend, axis=1).max())  # within the turn's radius of curvature
    tools = position[:, :2] + off * np.column_stack([-tangent[:, 1], tangent[:, 0]])
    trajectory = sample(path, plan(path, 50.0, 2000.0), 2e-4)
    nearest = np.argmin(np.abs(trajectory.s[:, None] - s), axis=0)
    error = exact_contour_error(trajectory, tools, at=nearest)
    assert error.magnitude.max() <= off + 1e-12  # [mm]: rounding of positions of some mm


def test_the_signed_error_at_a_corner_is_the_same_on_the_path_turned_about_its_origin():
    """A foot on a polyline's corner: the side whose frame splits the error was the one rounding chose (−1.452 µm here,
    +0.077 µm on the path turned by 2.028 rad, the same 1.453 µm away); now the side the tool is square to."""
    from contoursim.compensation import Feedforward
    from contoursim.machine import Machine

    demo = load_machine("demo_mill")
    machine = Machine(axes={"x": demo.axes["x"], "y": demo.axes["x"]}, servo_period=demo.servo_period,
                      max_feed=demo.max_feed)
    points = np.array([[6.470882675530811, 0.5159391555058832], [-7.0236488790564895, 1.6746993313415537],
                       [-3.9747489987726983, -4.575832385520284], [6.914288586762648, 1.9107718754767706],
                       [-0.8953676003693101, -6.997458262629381], [-2.0540576223518325, 5.823730396178751]])
    turn = 2.0281762337878626
    rotation = np.array([[np.cos(turn), -np.sin(turn)], [np.sin(turn), np.cos(turn)]])
    errors = []
    for corners in (points, points @ rotation.T):
        path = paths.polyline(corners)
        trajectory = sample(path, plan(path, 38.37708367462769, 980.7798322754218), machine.servo_period)
        errors.append(simulate(machine, trajectory, strategies=[Feedforward()]).contour)
    np.testing.assert_allclose(errors[1].magnitude, errors[0].magnitude, rtol=0, atol=1e-11)
    np.testing.assert_allclose(errors[1].normal, errors[0].normal, rtol=0, atol=1e-11)
