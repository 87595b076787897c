"""Plots: round shared magnifications, thinning that keeps every pixel column's extremes, the ISO 230-4 evaluation."""

import numpy as np
import pytest

from contoursim import paths
from contoursim.feed import plan, sample
from contoursim.machine import load_machine
from contoursim.plotting import (_Rows, _drawn_curve, _thin_curve, circular_deviation, envelope_indices,
                                 magnification_for, plot_path_error, plot_polar_deviation, save_figures)
from contoursim.simulation import simulate


@pytest.mark.parametrize("size, error", [(100.0, 0.01), (100.0, 0.0123), (4000.0, 0.15), (50.0, 3.0), (10.0, 40.0),
                                         (1.0, 1e-7)])
def test_magnification_is_round_at_least_one_and_fits(size, error):
    k = magnification_for(size, error)
    mantissa = k / 10 ** np.floor(np.log10(k))
    assert k >= 1 and min(abs(mantissa - m) for m in (1, 2, 5)) < 1e-9
    if k > 1:  # magnified: the largest error drawn at most 8 % of the size, and more than 8 / 2.5 %
        assert 0.08 / 2.5 * size < k * error <= 0.08 * size * (1 + 1e-12)


def test_a_path_along_z_only_has_nothing_to_magnify():
    """A plunge: x and y stand still, so the in-plane contour error is the rounding of the foot points (~1e-16 mm),
    which a magnification fitted to it drew ×1e14."""
    machine = load_machine("demo_mill")
    plunge = paths.polyline([[0, 0, 0], [0, 0, -5]])
    result = simulate(machine, sample(plunge, plan(plunge, 5.0, 500.0, 50_000.0), machine.servo_period))
    assert float(result.contour.magnitude.max()) < 1e-9  # [mm]: nothing in the plane
    assert magnification_for(1.0, float(result.contour.magnitude.max())) == 1.0
    assert magnification_for(1.0, 1e-16) == magnification_for(1.0, 0.9e-6) == 1.0  # below the traces' nm: true scale
    assert magnification_for(1.0, 1e-6) == 50_000.0
    ax = plot_path_error(result)
    assert "nothing to magnify" in ax.get_title() and "×" not in ax.get_title()
    ax.figure.clf()


@pytest.mark.parametrize("program, labels, note", [
    ("G18\nG1 X10 F2000\nG2 X30 Z0 I10 K0\nG1 X40", ("x [mm]", "z [mm]"), False),  # an arc in XZ: drawn there
    ("G19\nG1 Y10 F2000\nG3 Y30 Z0 J10 K0\nG1 Y40", ("y [mm]", "z [mm]"), False),  # an arc in YZ
    ("G17\nG1 X10 F2000\nG3 X10 Y0 Z-4 I-10 J0", ("x [mm]", "y [mm]"), True),  # a helix: in XY, z not drawn
])
def test_a_path_in_the_xz_or_yz_plane_is_drawn_in_its_plane(program, labels, note):
    """An XZ (G18) arc was drawn in XY, a straight line on which no error showed, under a title giving its max."""
    from contoursim.gcode import read_gcode

    machine = load_machine("demo_mill")
    read = read_gcode("G21 G90\nG0 X0 Y0 Z0\n" + program + "\nM30\n")
    profile = plan(read.path, read.feeds, 1000.0, 50_000.0)
    result = simulate(machine, sample(read.path, profile, machine.servo_period))
    ax = plot_path_error(result)
    assert (ax.get_xlabel(), ax.get_ylabel()) == labels
    assert ("z not drawn" in ax.get_title()) == note
    reference = ax.get_lines()[0].get_xydata()
    assert np.nanmax(reference[:, 1]) - np.nanmin(reference[:, 1]) >= 8  # the arc's 10 mm bulge, the helix's circle
    ax.figure.clf()


def test_envelope_keeps_the_extremes_of_every_pixel_column():
    rng = np.random.default_rng(3)
    n, columns = 100_003, 700
    values = np.column_stack([np.cumsum(rng.normal(size=n)), rng.normal(size=n)])
    values[[17, 5_000, 99_999], 1] = [40.0, -40.0, 40.0]  # one-sample spikes
    keep = envelope_indices(values, columns)
    assert len(keep) <= 4 * columns + n // columns + 2 and keep[0] == 0 and keep[-1] == n - 1
    assert {17, 5_000, 99_999} <= set(keep)
    size = -(-n // columns)  # the runs the function promises to keep the extremes of, cut here on their own
    kept = np.zeros(n, bool)
    kept[keep] = True
    for start in range(0, n, size):
        run = slice(start, start + size)
        for j in range(2):
            assert values[run, j][kept[run]].min() == values[run, j].min()
            assert values[run, j][kept[run]].max() == values[run, j].max()
    np.testing.assert_array_equal(envelope_indices(np.arange(50.0), columns), np.arange(50))


def _iso_circle(machine, overrun):
    path = paths.iso230_4_circle(50.0, overrun=overrun)
    return simulate(machine, sample(path, plan(path, 1000 / 60, 1000.0, 50_000.0), machine.servo_period))


def test_circular_test_leaves_the_run_in_transient_out():
    """ISO 230-4: the data-collection circle, not the transition from the run-in arc.

    Where the run-in arc (radius R/2) joins the circle, the curvature steps and
    the servo error has a transient. With the 45° overrun it has died out before
    the test proper starts: the circularity equals that behind a 180° overrun;
    joining the circle right at the test's start puts the transient into it.
    """
    machine = load_machine("vertical_mill_3axis")
    default, long, none = (circular_deviation(_iso_circle(machine, a)) for a in (np.pi / 4, np.pi, 0.0))
    assert default["circularity"] == pytest.approx(long["circularity"], abs=1e-3)
    assert none["circularity"] > default["circularity"] + 1.0
    theta = np.unwrap(default["theta"])
    assert abs(theta[-1] - theta[0]) == pytest.approx(2 * np.pi, abs=0.02)  # the full circle, once


def test_polar_plot_only_for_circular_tests(tmp_path):
    machine = load_machine("demo_mill")
    square = paths.polyline([[0, 0], [20, 0], [20, 20], [0, 20], [0, 0]], blend_radius=2.0)
    other = simulate(machine, sample(square, plan(square, 20.0, 1000.0, 50_000.0), machine.servo_period))
    with pytest.raises(ValueError, match="full test circle"):
        plot_polar_deviation(other)
    circle = _iso_circle(machine, np.pi / 4)
    files = save_figures({"a": circle, "b": other}, tmp_path, "ab")
    assert [f.name for f in files] == ["a_path.png", "b_path.png", "a_errors.png", "b_errors.png"]  # no polar
    files = save_figures({"a": circle}, tmp_path, "a")
    assert files[-1].name == "a_polar.png" and all(f.stat().st_size > 10_000 for f in files)


def test_curve_thinned_block_by_block_keeps_one_point_per_step_travelled():
    u = np.linspace(0.0, 6 * np.pi, 150_001)  # longer than a block
    points = np.column_stack([(10 + u) * np.cos(u), (10 + u) * np.sin(u)])  # a spiral [mm]
    step = 0.37
    travelled = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(points, axis=0), axis=1))])
    cell = np.floor(travelled / step)
    want = np.union1d(np.concatenate([[0], 1 + np.flatnonzero(cell[1:] > cell[:-1])]), [len(points) - 1])
    np.testing.assert_array_equal(_thin_curve(points, step), want)
    np.testing.assert_array_equal(_thin_curve(_Rows(len(points), lambda i: points[i]), step), want)  # made on demand
    y = np.sin(u)
    np.testing.assert_array_equal(envelope_indices(_Rows(len(y), lambda i: y[i][:, None])), envelope_indices(y))


def test_a_retraced_curve_is_drawn_from_the_cells_it_covers_and_keeps_its_peaks():
    """A circle passed 20 and 200 times, one sample 0.5 mm off it in the last pass: the same drawing.

    The drawn data does not grow with the passes, the spike is in it, and every sample lies within
    two cells of the drawn points (nothing of the curve is left out).
    """
    step = 100 / 1200  # [mm], a 100 mm drawing at 1200 cells
    drawn = {}
    for turns in (20, 200):
        u = np.linspace(0.0, 2 * np.pi * turns, 5_000 * turns + 1)
        points = np.column_stack([50 * np.cos(u), 50 * np.sin(u)])
        points[-1234] *= 50.5 / 50  # [mm] a spike of one sample
        drawn[turns] = _drawn_curve(_Rows(len(points), lambda i: points[i]), step)
        assert np.any(np.all(drawn[turns] == points[-1234], axis=1))
    assert len(drawn[200]) <= len(drawn[20]) + 10 and len(drawn[20]) < 20_000
    pts = drawn[200][~np.isnan(drawn[200][:, 0])]
    angle = np.sort(np.arctan2(pts[:, 1], pts[:, 0]))
    assert np.diff(angle).max() < 2 * step / 50 and angle[0] + 2 * np.pi - angle[-1] < 2 * step / 50


def test_a_200000_block_program_is_plotted_in_bounded_memory_with_its_worst_error():
    """20 turns of a circle written as 200,000 straight blocks (as a post writes a contour), on the router example.

    Every block end is a corner: the plot used to compare each of its 38,009 drawn samples with each of
    the 199,999 corners (a 57 GiB float64 temporary, more with its masks). Measured with tracemalloc: the plot's peak stays below 64 MB, the lines hold
    what the pixels can show (fewer than 5 points per cell the circle passes, whatever the number of
    turns: see the test above), and the largest contour error is both marked and on the drawn line.
    """
    import tracemalloc

    from matplotlib.figure import Figure

    from conftest import ROOT

    turns, per_turn = 20, 10_000
    u = np.linspace(0.0, 2 * np.pi * turns, turns * per_turn + 1)
    path = paths.polyline(np.column_stack([50 * np.cos(u), 50 * np.sin(u)]))
    machine = load_machine(ROOT / "examples" / "router" / "router.toml")
    result = simulate(machine, sample(path, plan(path, 20_000 / 60, 2000.0, 50_000.0), machine.servo_period))
    tracemalloc.start()
    try:
        ax = plot_path_error(result, Figure().add_subplot(), name="program")
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 64e6
    reference, actual, _, worst = ax.lines
    cells = 2 * np.pi * 50 / (100 / 1200)  # the cells of the 1200-cell drawing the circle passes
    assert max(len(reference.get_xdata()), len(actual.get_xdata())) < 5 * cells < len(result.trajectory) / 2
    k = float(ax.get_title().split("contour error ×")[1].split(":")[0])
    i = int(np.argmax(result.contour.magnitude))
    point = result.contour.foot[i, :2] + k * (result.tool_position[i, :2] - result.contour.foot[i, :2])
    np.testing.assert_allclose(worst.get_xydata()[0], point)
    drawn = actual.get_xydata()
    assert np.nanmin(np.hypot(*(drawn - point).T)) < 2 * 100 / 1200  # within two cells of the 100 mm drawing
    assert f"max {1e3 * result.contour.magnitude[i]:.2f} µm" in ax.get_title()


def test_diagnosis_plots_keep_zero_labels_legend_and_both_runs_visible():
    """The polar residual: zero dashed over the data, no ring label where the data runs, the legend
    below the rings, "before" a wide band under the thin "after" line; the other two figures too."""
    from matplotlib.figure import Figure

    from contoursim.diagnosis import Diagnosis, plot_magnified, plot_polar, plot_residuals
    from contoursim.model import Model
    from contoursim.traces import Trace

    machine = load_machine("demo_mill")
    t = np.arange(0.0, 10.0, 1e-3)
    theta = 2 * np.pi * t / 5.0  # two turns
    radial = np.column_stack([np.cos(theta), np.sin(theta)])
    reference = 50.0 * radial
    before = 1e-3 * (3.0 * np.cos(2 * theta) + 0.5)[:, None] * radial  # [mm] what the nominal model misses
    after = 1e-3 * (0.2 * np.sin(3 * theta))[:, None] * radial  # [mm] what is left
    trace = Trace(t, reference, reference + before, ("x", "y"))
    diagnosis = Diagnosis(trace, Model(machine), False, np.array([0.05, 0.05]), np.zeros(2), (), reference, reference + before - after,
                          np.ones(len(t), bool), Model(machine))
    ax = plot_polar(diagnosis, Figure(figsize=(6.4, 7.4)).add_subplot(projection="polar"))
    zero, band, line = ax.lines
    assert zero.get_zorder() > line.get_zorder() and not np.any(zero.get_ydata())
    assert band.get_linewidth() > 2 * line.get_linewidth() and band.get_alpha() < 1
    ax.figure.canvas.draw()
    legend, rings = ax.get_legend().get_window_extent(), ax.get_window_extent()
    assert legend.y1 <= rings.y0 + 0.05 * rings.height  # below the rings, not over the data
    ray = np.radians(ax.get_rlabel_position())
    division = float(np.diff(ax.get_yticks())[0])
    drawn = np.concatenate([np.column_stack([a.get_xdata(), a.get_ydata()]) for a in (band, line)])
    near = drawn[np.abs((drawn[:, 0] - ray + np.pi) % (2 * np.pi) - np.pi) < np.radians(6.0), 1]
    labelled = [tick for tick, label in zip(ax.get_yticks(), ax.get_yticklabels()) if label.get_text()]
    assert len(labelled) >= 3
    assert all(np.abs(near - tick).min() > 0.45 * division for tick in labelled)
    fig = plot_residuals(diagnosis, Figure(figsize=(9.0, 6.0), layout="constrained"))
    fig.canvas.draw()
    legend = fig.axes[0].get_legend().get_window_extent()
    assert legend.x0 >= fig.axes[0].get_window_extent().x1  # beside the axes
    ax = plot_magnified(diagnosis, Figure(figsize=(7.0, 7.0), layout="constrained").add_subplot())
    ax.figure.canvas.draw()
    assert ax.get_legend().get_window_extent().y1 <= ax.get_window_extent().y0


def test_a_test_circle_at_a_height_or_about_minus_z_is_read_as_seen_from_above():
    """An ISO 230-4 circle centred at z = 10 mm was no test circle ("use a path of type = iso230_4_circle"); a
    circle about −z that runs clockwise seen from above would have been called CCW by the sign of its sweep."""
    machine = load_machine("vertical_mill_3axis")
    runs = []
    for center in ((0.0, 0.0, 0.0), (0.0, 0.0, 10.0)):
        path = paths.iso230_4_circle(50.0, center=center)
        runs.append(circular_deviation(simulate(machine, sample(path, plan(path, 1000 / 60, 1000.0, 50_000.0),
                                                                machine.servo_period))))
    assert runs[0]["direction"] == runs[1]["direction"] == "CCW"
    assert runs[1]["circularity"] == pytest.approx(runs[0]["circularity"], abs=0.05)
    below = paths.circle((0.0, 0.0, 0.0), 20.0, direction="ccw", normal=(0, 0, -1), role="test")
    assert below.test_circle() is below.primitives[0]
    run = circular_deviation(simulate(machine, sample(below, plan(below, 1000 / 60, 1000.0, 50_000.0),
                                                      machine.servo_period)))
    assert run["direction"] == "CW"
    assert np.all(np.diff(np.unwrap(run["theta"])) <= 1e-9)  # clockwise seen from +z, as it says
