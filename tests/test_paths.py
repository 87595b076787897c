"""Path geometry against closed forms; path files of the library."""

from importlib.resources import files

import numpy as np
import pytest
from scipy.integrate import quad

from contoursim import paths
from contoursim.exceptions import ConfigError, PathError
from contoursim.feed import sample
from contoursim.pathfile import load_path_file


def test_circle_positions_tangent_curvature():
    path = paths.circle((1.0, 2.0), 50.0, direction="cw", start_angle=np.pi / 2)
    assert path.dim == 2 and path.closed
    assert path.length == pytest.approx(2 * np.pi * 50.0, rel=1e-15)
    s = np.linspace(0, path.length, 37)
    pos, tan, kappa = path.evaluate(s)
    phi = np.pi / 2 - s / 50.0  # clockwise from the top
    np.testing.assert_allclose(pos[:, :2], [1, 2] + 50.0 * np.column_stack([np.cos(phi), np.sin(phi)]), atol=1e-12)
    np.testing.assert_allclose(tan[:, :2], np.column_stack([np.sin(phi), -np.cos(phi)]), atol=1e-14)
    np.testing.assert_allclose(kappa, 1 / 50.0, rtol=1e-13)


def test_arc_end_angle_and_direction():
    # from 0 to 90°: a quarter turn counter-clockwise, three quarters clockwise
    ccw = paths.arc((0, 0), 10.0, 0.0, np.pi / 2).primitives[0]
    cw = paths.arc((0, 0), 10.0, 0.0, np.pi / 2, direction="cw").primitives[0]
    assert ccw.sweep == pytest.approx(np.pi / 2) and cw.sweep == pytest.approx(-1.5 * np.pi)
    np.testing.assert_allclose([ccw.end, cw.end], [[0, 10, 0], [0, 10, 0]], atol=1e-12)
    joined = paths.line((20, 0), (10, 0)) + paths.arc((0, 0), 10.0, 0.0, sweep=np.pi)
    assert len(joined) == 2 and joined.length == pytest.approx(10 + 10 * np.pi)
    with pytest.raises(PathError, match="exactly one of end_angle and sweep"):
        paths.arc((0, 0), 10.0, 0.0)
    # with sweep the direction was passed over, misspelt or contradicting it: a ccw arc for direction="cw"
    with pytest.raises(PathError, match="direction must be 'ccw' or 'cw', got 'left'"):
        paths.arc((0, 0), 10.0, 0.0, sweep=1.0, direction="left")
    with pytest.raises(PathError, match="direction 'cw' and sweep 1 > 0 \\(counter-clockwise\\) disagree"):
        paths.arc((0, 0), 10.0, 0.0, sweep=1.0, direction="cw")
    assert paths.arc((0, 0), 10.0, 0.0, sweep=-1.0, direction="cw").primitives[0].sweep == -1.0


def test_a_direction_argument_of_a_path_file_is_said_of_the_argument(tmp_path):
    # direction="left" was reported at the file's [path] line, as if the file said it
    file = tmp_path / "c.toml"
    file.write_text('[feed]\nfeed_mm_min = 1000\n[path]\ntype = "circle"\ncenter_mm = [0, 0]\nradius_mm = 5\n')
    with pytest.raises(ValueError, match="^direction must be 'ccw', 'cw' or None \\(the file's\\), got 'left'$"):
        load_path_file(file, direction="left")
    assert load_path_file(file, direction="cw")[0].primitives[0].sweep < 0


def test_tilted_circle_lies_in_its_plane():
    n = np.array([1.0, 1.0, 1.0]) / np.sqrt(3)
    path = paths.circle((5.0, 0.0, -3.0), 20.0, normal=n)
    assert path.dim == 3
    np.testing.assert_allclose(path.plane_normal, n, atol=1e-15)
    pos, tan, kappa = path.evaluate(np.linspace(0, path.length, 50))
    np.testing.assert_allclose((pos - [5, 0, -3]) @ n, 0, atol=1e-12)
    np.testing.assert_allclose(np.linalg.norm(pos - [5, 0, -3], axis=1), 20.0, rtol=1e-14)
    np.testing.assert_allclose(np.cross(pos - [5, 0, -3], tan) @ n, 20.0, rtol=1e-13)  # CCW about n


def test_helix_closed_form():
    # P(θ) = (R cos θ, R sin θ, pitch θ / 2π): length per turn sqrt((2πR)^2 + pitch^2),
    # curvature R / (R^2 + h^2) with h = pitch / 2π
    path = paths.helix((0, 0, 1.0), 20.0, 5.0, 3)
    h = 5.0 / (2 * np.pi)
    assert path.length == pytest.approx(3 * np.hypot(2 * np.pi * 20.0, 5.0), rel=1e-14)
    assert path.plane_normal is None
    s = np.linspace(0, path.length, 41)
    pos, tan, kappa = path.evaluate(s)
    theta = s / np.hypot(20.0, h)
    np.testing.assert_allclose(pos, np.column_stack([20 * np.cos(theta), 20 * np.sin(theta), 1 + h * theta]),
                               atol=1e-12)
    np.testing.assert_allclose(kappa, 20.0 / (20.0**2 + h**2), rtol=1e-12)
    np.testing.assert_allclose(np.linalg.norm(tan, axis=1), 1.0, rtol=1e-14)
    # turns beyond what its sweep may be [rad] were said as "sweep must lie within ±1e+06, got 6.28319e+06"
    with pytest.raises(PathError, match=r"^turns = 1000000 is outside \[1e-06, 159155\], not a path a machine follows$"):
        paths.helix((0, 0, 0), 1.0, 0.001, 1e6)


def test_iso230_4_circle_geometry():
    path = paths.iso230_4_circle(50.0, center=(10.0, 0.0), direction="cw")
    assert path.roles == ("run-in", "run-in", "test", "run-out", "run-out")
    assert path.breaks[3] - path.breaks[2] == pytest.approx(2 * np.pi * 50, rel=1e-15)
    np.testing.assert_allclose(np.diff(path.breaks)[[1, 3]], np.pi / 4 * 50, rtol=1e-14)  # 45° overruns
    # CW: the run-in arc (radius R/2, 90°) joins the circle 45° before the test's start point (R, 0)
    join = np.array([10.0, 0.0]) + 50 * np.array([np.cos(np.pi / 4), np.sin(np.pi / 4)])
    np.testing.assert_allclose(path.primitives[1].start[:2], join, atol=1e-12)
    np.testing.assert_allclose(path.primitives[2].start[:2], [60.0, 0.0], atol=1e-12)
    np.testing.assert_allclose(path.start[:2], [10.0, 25 * np.sqrt(2)], atol=1e-12)  # 90° on from the join, radius 25
    np.testing.assert_allclose(path.end[:2], [10.0, -25 * np.sqrt(2)], atol=1e-12)
    np.testing.assert_allclose(path.corner_angles(), 0.0, atol=1e-7)  # tangential joins
    s = np.linspace(path.breaks[1], path.breaks[4], 9)
    np.testing.assert_allclose(np.linalg.norm(path.evaluate(s)[0][:, :2] - [10, 0], axis=1), 50.0, rtol=1e-14)
    test = path.test_circle()
    assert test is path.primitives[2] and test.sweep == pytest.approx(-2 * np.pi) and test.radius == 50.0
    bare = paths.iso230_4_circle(50.0, overrun=0.0)
    assert bare.roles == ("run-in", "test", "run-out")
    np.testing.assert_allclose(bare.start[:2], [25.0, -25.0], atol=1e-12)
    assert paths.circle((0, 0), 5.0).test_circle() is None  # no primitive with role "test"
    assert paths.helix((0, 0, 0), 5.0, 1.0, 1, role="test").test_circle() is None  # not a flat circle
    with pytest.raises(PathError, match="overrun must be at most π"):
        paths.iso230_4_circle(50.0, overrun=4.0)


def test_polyline_blends_are_tangent_fillets():
    r = 10.0
    path = paths.polyline([[0, -50], [50, -50], [50, 50], [-50, 50]], blend_radius=r)
    assert len(path) == 5  # line, arc, line, arc, line
    np.testing.assert_allclose(path.corner_angles(), 0.0, atol=1e-7)
    fillet = path.primitives[1]
    np.testing.assert_allclose(fillet.start[:2], [40, -50], atol=1e-12)  # r tan(45°) before the corner
    np.testing.assert_allclose(fillet.end[:2], [50, -40], atol=1e-12)
    np.testing.assert_allclose(fillet.center[:2], [40, -40], atol=1e-12)
    assert fillet.radius == r and fillet.sweep == pytest.approx(np.pi / 2)
    assert path.length == pytest.approx(50 + 100 + 100 - 4 * r + 2 * (np.pi / 2) * r, rel=1e-14)


@pytest.mark.parametrize("points", [[[20, -20], [10, -10], [0, 0], [-10, 10]], [[0, 0], [0.1, 0.3], [0.2, 0.6], [0.3, 0.9]]])
def test_a_polyline_going_straight_through_its_points_has_no_fillet_at_them(points):
    # arccos of a cosine rounded to 1 - 1e-16 made a 2e-8 rad corner there, whose fillet had no inward direction:
    # 'center contains a non-finite value (nan)' for points the user put on a straight line
    path = paths.polyline(points, blend_radius=0.05)
    assert {type(p).__name__ for p in path.primitives} == {"Line"}
    assert path.length == pytest.approx(np.linalg.norm(np.subtract(points[-1], points[0])), rel=1e-14)


def test_polyline_errors_name_the_problem():
    with pytest.raises(PathError, match="does not fit segment 1"):
        paths.polyline([[0, 0], [10, 0], [10, 5], [20, 5]], blend_radius=3.0)
    with pytest.raises(PathError, match=r"points\[1\] and points\[2\] coincide"):
        paths.polyline([[0, 0], [1, 0], [1, 0]])
    with pytest.raises(PathError, match=r"reverses direction at points\[1\]: no corner blend \(blend_radius 0.1 mm\)"):
        paths.polyline([[0, 0], [1, 0], [0, 0]], blend_radius=0.1)
    # with sharp corners a reversal is a stop, as the same moves in G-code (it was refused: "no corner blend")
    there_and_back = paths.polyline([[0, 0], [1, 0], [0, 0]])
    assert there_and_back.length == pytest.approx(2.0) and len(there_and_back.primitives) == 2
    with pytest.raises(PathError, match="non-finite"):
        paths.polyline([[0, 0], [np.nan, 1]])


def test_spline_arc_length_matches_quadrature():
    pts = [[0, 0], [10, 5], [20, -3], [35, 8], [40, 0]]
    path = paths.spline(pts)
    for piece in path.primitives:
        a, b, c, d = piece.coefficients
        length, _ = quad(lambda w: np.linalg.norm(b + 2 * c * w + 3 * d * w * w), 0, 1, epsabs=1e-13)
        assert piece.length == pytest.approx(length, rel=1e-12)
    # evaluation by arc length: the chord of small steps adds up to the step in s
    s = np.linspace(0, path.length, 20001)
    pos = path.evaluate(s)[0]
    assert np.sum(np.linalg.norm(np.diff(pos, axis=0), axis=1)) == pytest.approx(path.length, rel=1e-8)
    np.testing.assert_allclose(path.evaluate(path.breaks)[0][:, :2], pts, atol=1e-12)


def test_spline_arc_length_inverted_to_rounding():
    """The parameter found for an arc length gives that length back under quadrature, to 1e-13 of the piece."""
    from contoursim.paths import _spline_w_of_u

    path = paths.spline([[0, 0], [10, 5], [20, -3], [35, 8], [40, 0]])
    for row, piece in zip(path.rows, path.primitives):
        a, b, c, d = piece.coefficients
        for u in np.linspace(0, piece.length, 41)[1:-1]:
            w = _spline_w_of_u(row, u)
            back, _ = quad(lambda v: np.linalg.norm(b + 2 * c * v + 3 * d * v * v), 0, w, epsabs=1e-14, epsrel=1e-13)
            assert back == pytest.approx(u, abs=1e-13 * piece.length)


@pytest.mark.parametrize("n, closed", [
    (2, False), (3, False), (4, False), (9, False), (4, True), (5, True), (13, True),
])
def test_spline_is_scipys_cubic_spline(n, closed):
    # the same curve as scipy's CubicSpline through the points over their cumulative chord length
    from scipy.interpolate import CubicSpline

    points = np.random.default_rng(n).normal(scale=20.0, size=(n, 3))
    if closed:
        points[-1] = points[0]
    chord = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(points, axis=0), axis=1))])
    reference = CubicSpline(chord, points, bc_type="periodic" if closed else "natural")
    path = paths.spline(points[:-1] if closed else points, closed=closed)
    w = np.linspace(0.0, 1.0, 7)[:, None]
    for i, piece in enumerate(path.primitives):
        a, b, c, d = piece.coefficients
        h = chord[i + 1] - chord[i]
        s = chord[i] + w[:, 0] * h
        np.testing.assert_allclose(a + w * (b + w * (c + w * d)), reference(s), rtol=0, atol=1e-12 * 20.0)
        np.testing.assert_allclose((b + w * (2 * c + 3 * w * d)) / h, reference(s, 1), rtol=0, atol=1e-12)


def test_closed_spline_is_c2_at_the_seam():
    t = np.linspace(0, 2 * np.pi, 12, endpoint=False)
    path = paths.spline(np.column_stack([30 * np.cos(t), 20 * np.sin(2 * t)]), closed=True)
    assert path.closed and len(path) == 12
    _, t0, k0 = path.derivatives([0.0])
    _, t1, k1 = path.derivatives([path.length])
    np.testing.assert_allclose(t0, t1, atol=1e-12)
    np.testing.assert_allclose(k0, k1, atol=1e-10)


def test_max_curvature_of_each_primitive():
    """Lines 0, arcs r/(r² + p²) (p = rise per radian), spline pieces the largest |P' × P''| / |P'|³ on them: the most
    of 100001 values of w, to its rounding; never less (it was the most of 65 values: 0.15 of it on the near cusp of
    the last piece)."""
    rng = np.random.default_rng(1)
    curve = paths.spline(np.vstack([10 * rng.normal(size=(40, 3)), [[0, 0, 0], [0.3, 0, 0], [0, 0.001, 0]]]))
    w = np.linspace(0, 1, 100001)[:, None]
    want = []
    for piece in curve.primitives:
        a, b, c, d = piece.coefficients
        d1, d2 = b + 2 * c * w + 3 * d * w**2, 2 * c + 6 * d * w
        want.append(np.max(np.linalg.norm(np.cross(d1, d2), axis=1) / np.linalg.norm(d1, axis=1) ** 3))
    np.testing.assert_allclose(curve.max_curvature(), want, rtol=1e-7)
    assert np.all(curve.max_curvature() >= np.array(want) * (1 - 1e-12))
    helix = paths.helix((0, 0, 0), 5.0, pitch=2 * np.pi, turns=1.0)  # rises 1 mm per radian
    line = paths.line((0, 0), (3, 4))
    np.testing.assert_allclose([helix.max_curvature()[0], line.max_curvature()[0]], [5 / 26, 0.0], rtol=1e-12)


def test_spline_piece_that_stops_is_refused():
    """dP/dw = 3(w - 1/2)^2 (1, 2, 0): the piece stops at w = 1/2 (a cusp); a little faster there, it is a piece."""
    stops = [[0, 0, 0], [0.75, 1.5, 0], [-1.5, -3, 0], [1, 2, 0]]
    with pytest.raises(PathError, match="cusp"):
        paths.SplinePiece(stops)
    moving = np.array(stops) + [[0, 0, 0], [1e-6, 0, 0], [0, 0, 0], [0, 0, 0]]
    assert paths.SplinePiece(moving).length == pytest.approx(np.sqrt(5) * 0.25, rel=1e-5)


def test_degenerate_input_raises_path_error():
    with pytest.raises(PathError, match="zero length"):
        paths.line((1, 1), (1, 1))
    with pytest.raises(PathError, match="radius must be positive"):
        paths.circle((0, 0), 0.0)
    with pytest.raises(PathError, match=r"points\[2\] and points\[3\] coincide"):
        paths.spline([[0, 0], [1, 0], [2, 1], [2, 1]])
    with pytest.raises(PathError, match="center contains a non-finite"):
        paths.arc((np.nan, 0), 1.0, 0.0, 1.0)
    with pytest.raises(PathError, match="segment 1 starts"):
        paths.line((0, 0), (1, 0)) + paths.line((1, 1e-6), (2, 0))
    with pytest.raises(PathError, match="direction"):
        paths.circle((0, 0), 1.0, direction="clockwise")


def _library():
    root = files("contoursim.trajectories")
    return sorted(f for f in root.iterdir() if f.name.endswith((".toml", ".nc")))


@pytest.mark.parametrize("file", _library(), ids=lambda f: f.name)
def test_every_library_file_loads_and_samples(file):
    path, feed = load_path_file(file)
    trajectory = sample(path, feed.plan(path), 0.002)
    assert trajectory.dim == path.dim
    assert trajectory.s[-1] == path.length
    np.testing.assert_allclose(trajectory.speed.max(), np.max(feed.feed), rtol=1e-9)


def test_library_contents():
    names = {f.name for f in _library()}
    assert {"iso230_4_circle_ccw.toml", "iso230_4_circle_cw.toml", "rounded_square.toml", "butterfly.toml",
            "helix.toml", "pocket.nc"} <= names
    path, feed = load_path_file(files("contoursim.trajectories") / "iso230_4_circle_cw.toml")
    assert feed.feed == pytest.approx(1000 / 60)
    assert path.primitives[1].radius == 50 and path.primitives[1].sweep < 0


@pytest.mark.parametrize("text, line, message", [
    ('[feed]\nfeed_mm_min = 100\n[path]\ntype = "circle"\ncenter_mm = [0, 0]\nradius_mm = 5\ncolour = 1\n',
     7, "unknown key 'colour'"),
    ('[feed]\nfeed_mm_min = 100\nspeed = 3\n[path]\ntype = "circle"\ncenter_mm = [0, 0]\nradius_mm = 5\n',
     3, "unknown key 'speed' in \\[feed\\]"),
    ('[feed]\nfeed_mm_min = 100\n[path]\ntype = "circle"\ncenter_mm = [0, 0]\nradius_mm = -5\n',
     6, "radius_mm must be positive"),  # the key, not the builder's argument (radius)
    ('[feed]\nfeed_mm_min = 0\n[path]\ntype = "circle"\ncenter_mm = [0, 0]\nradius_mm = 5\n',
     2, "feed_mm_min must be positive"),
    ('[feed]\nfeed_mm_min = 100\n[path]\ntype = "polyline"\npoints_mm = [[0, 0], [1, 0], [1, 1]]\n'
     'blend_radius_mm = 2\n', 6, "does not fit"),
    ('[feed]\nfeed_mm_min = 100\n[path]\ntype = "square"\n', 4, "type must be one of"),
    ('[feed]\nfeed_mm_min = 100\n[path\n', 3, "not valid TOML"),
    ('[feed]\nfeed_mm_min = 100\n[path]\ntype = "helix"\ncenter_mm = [0, 0]\nradius_mm = 5\nturns = 2\n',
     3, "missing key 'pitch_mm' in \\[path\\]"),
    ('name = "x"\nnotes = "y"\n[feed]\nfeed_mm_min = 100\n', 2, "unknown key 'notes'"),
    ('[feed]\nfeed_mm_min = 100\ncorner_tolerance_deg = -1\n[path]\ntype = "spline"\npoints_mm = [[0, 0], [1, 1]]\n',
     3, "corner_tolerance_deg must be zero or positive"),
    # above 180° no join stops: read as 180° it was another planner than the one written
    ('[feed]\nfeed_mm_min = 100\ncorner_tolerance_deg = 720\n[path]\ntype = "spline"\npoints_mm = [[0, 0], [1, 1]]\n',
     3, "corner_tolerance_deg must be at most 180 \\(a reversal\\), got 720"),
    # a normal of 2 coordinates was taken as lying in XY: the circle stood upright
    ('[feed]\nfeed_mm_min = 100\n[path]\ntype = "circle"\ncenter_mm = [0, 0]\nradius_mm = 5\nnormal = [0, 1]\n',
     7, "normal must have 3 coordinates \\(a direction: \\[0, 0, 1\\] is normal to XY\\), got 2"),
    ('[path]\ntype = "circle"\ncenter_mm = [0, 0]\nstart_angle_deg = "north"\nradius_mm = 5\n[feed]\n',
     4, "start_angle_deg must be a number"),
    # a point of 3 coordinates among points of 2 was "points must be numeric (not text, booleans or complex numbers)"
    ('[path]\ntype = "polyline"\npoints_mm = [[0, 0], [5, 0, 1], [5, 5]]\n[feed]\nfeed_mm_min = 1000\n',
     3, r"bad polyline \[path\]: points_mm\[1\] has 3 coordinates, the others 2"),
    ('[path]\ntype = "spline"\npoints_mm = [[0, 0, 0], [5, 0], [5, 5, 1], [0, 5, 1]]\n[feed]\nfeed_mm_min = 1000\n',
     3, r"points_mm\[1\] has 2 coordinates, the others 3"),
    ('[path]\ntype = "polyline"\npoints_mm = [[0, 0], 5, [5, 5]]\n[feed]\nfeed_mm_min = 1000\n',
     3, r"points_mm\[1\] is 5, not a point \[x, y\] or \[x, y, z\]"),
    # the builder's names were the message's ("radius", "points[1] and points[2]"): the file's keys are
    ('[path]\ntype = "polyline"\npoints_mm = [[0, 0], [5, 0], [5, 0]]\n[feed]\nfeed_mm_min = 1000\n',
     3, r"points_mm\[1\] and points_mm\[2\] coincide"),
    ('[path]\ntype = "iso230_4_circle"\nradius_mm = 50\nrun_radius_mm = 60\n[feed]\nfeed_mm_min = 1000\n',
     4, r"run_radius_mm \(60.0 mm\) must be below the test radius_mm \(50.0 mm\)"),
])
def test_path_file_errors_name_file_and_line(tmp_path, text, line, message):
    file = tmp_path / "bad.toml"
    file.write_text(text)
    with pytest.raises(ConfigError, match=message) as info:
        load_path_file(file)
    assert info.value.source == str(file) and info.value.line == line


_SHAPES = {"circle": "center_mm = [0, 0]\nradius_mm = 10", "iso230_4_circle": "radius_mm = 50",
           "helix": "center_mm = [0, 0]\nradius_mm = 10\npitch_mm = 1\nturns = 2"}


@pytest.mark.parametrize("shape, key, value, words", [
    # was "bad circle [path]: start_angle holds 1.74533e+298 at index (), beyond ±1e+06": the builder's name, rad
    ("circle", "start_angle_deg", "1e300", "start_angle_deg must lie within ±5.72958e+07, got 1e+300"),
    ("helix", "start_angle_deg", "-1e20", "start_angle_deg must lie within ±5.72958e+07, got -1e+20"),
    ("iso230_4_circle", "start_angle_deg", "1e300", "start_angle_deg must lie within ±5.72958e+07, got 1e+300"),
    # was "run_angle must be at most 2π rad, got 6.981317007977318"
    ("iso230_4_circle", "run_angle_deg", "400", "run_angle_deg must lie within [5.72958e-05, 360], got 400"),
    ("iso230_4_circle", "run_angle_deg", "-5", "run_angle_deg must be positive, got -5"),
    # was "feed must lie within [1e-06, 1e+12] (mm/s, mm/s^2, mm/s^3), got 1.66667e+298", at the [feed] line
    ("circle", "feed_mm_min", "1e300", "feed_mm_min must lie within [6e-05, 6e+13], got 1e+300"),
    ("circle", "feed_mm_min", "1e-20", "feed_mm_min must lie within [6e-05, 6e+13], got 1e-20"),
    ("circle", "accel_mm_s2", "1e300", "accel_mm_s2 must lie within [1e-06, 1e+12], got 1e+300"),  # was "accel must ..."
    ("circle", "jerk_mm_s3", "1e-20", "jerk_mm_s3 must lie within [1e-06, 1e+12], got 1e-20"),
    ("circle", "centripetal_accel_mm_s2", "1e300", "centripetal_accel_mm_s2 must lie within [1e-06, 1e+12], got 1e+300"),
])
def test_a_value_out_of_range_is_said_in_its_keys_unit_at_its_line(tmp_path, shape, key, value, words):
    keys = {"feed_mm_min": "1000", key: value}
    feed = "".join(f"{k} = {v}\n" for k, v in keys.items() if not k.endswith("_deg"))
    path = "".join(f"{k} = {v}\n" for k, v in keys.items() if k.endswith("_deg"))
    text = f'[feed]\n{feed}[path]\ntype = "{shape}"\n{_SHAPES[shape]}\n{path}'
    file = tmp_path / "bad.toml"
    file.write_text(text)
    with pytest.raises(ConfigError) as info:
        load_path_file(file)
    line = text.splitlines().index(f"{key} = {value}") + 1
    assert str(info.value).startswith(f"{file}, line {line}: {words}"), str(info.value)
    assert "index" not in str(info.value) and "rad" not in str(info.value)


def test_corner_angles_at_every_junction():
    """Each junction's turn, from the incoming primitive's end tangent to the outgoing start tangent."""
    square = paths.polyline([[0, 0], [10, 0], [10, 10], [0, 10], [0, 0]], 0.0)
    np.testing.assert_allclose(square.corner_angles(), [np.pi / 2] * 3, atol=1e-12)
    zigzag = paths.polyline([[0, 0], [10, 0], [20, 10], [30, 10]], 0.0)
    np.testing.assert_allclose(zigzag.corner_angles(), [np.pi / 4] * 2, atol=1e-12)
    # a line into a quarter arc that leaves tangentially: 0, then the arc into a line going back: π/2
    joined = paths.join(paths.line((0, 0), (10, 0)),
                        paths.arc(center=(10, 5), radius=5, start_angle=-np.pi / 2, sweep=np.pi / 2),
                        paths.line((15, 5), (15, 0)))
    np.testing.assert_allclose(joined.corner_angles(), [0.0, np.pi], atol=1e-9)
    # straight on along a slope whose unit tangents' dot product rounds to 1 - 1 ulp (arccos read 1.5e-8 rad there)
    for a, b in ((3, 7), (1, 3), (5, 11)):
        assert paths.join(paths.line((0, 0), (a, b)), paths.line((a, b), (2 * a, 2 * b))).corner_angles() == [0.0]


def test_a_sample_at_rest_at_a_junction_belongs_to_the_primitive_ending_there():
    path = paths.polyline([[0, 0], [10, 0], [10, 10]])
    s = np.array([0.0, 5.0, 10.0, 10.0, 15.0, 20.0])
    assert path.segment_index(s).tolist() == [0, 0, 1, 1, 1, 1]  # the later one at the junction
    at_rest = np.array([True, False, True, False, False, True])
    assert path.segment_index(s, at_rest=at_rest).tolist() == [0, 0, 0, 1, 1, 1]


def test_building_and_evaluating_paths_compiles_one_signature():
    """Primitives are evaluated read-only, as a path holds them: building, a primitive and the path share one signature."""
    spline = paths.spline(np.array([[0.0, 0.0], [5.0, 2.0], [10.0, 0.0], [15.0, 3.0]]))
    for path in (paths.join(paths.line((-5, 0), (0, 0)), spline), paths.helix((0, 0, 0), 5.0, 2.0, 1.0)):
        path.derivatives(np.linspace(0.0, path.length, 50))
        path.primitives[0].evaluate(np.array([0.0, 1.0]))
    assert len(paths._evaluate_local.signatures) == 1


def test_an_open_spline_stays_near_its_points_where_a_long_piece_meets_a_tight_turn():
    """Not-a-knot ends carried the hairpin's cubic over the 50-mm legs: a 407-mm loop out to x = -74 mm."""
    points = np.array([[0, 0], [50, 0], [52, 2], [50, 4], [0, 4]], float)
    path = paths.spline(points)
    position = path.evaluate(np.linspace(0.0, path.length, 20001))[0]
    assert position[:, 0].min() > -1e-9 and position[:, 0].max() < 52 + 1e-9
    polygon = np.linalg.norm(np.diff(points, axis=0), axis=1).sum()
    assert path.length < 1.05 * polygon
    _, _, curvature = path.derivatives([0.0, path.length])  # natural ends: no curvature at the first and last point
    np.testing.assert_allclose(curvature, 0.0, atol=1e-12)
