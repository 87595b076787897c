"""Plots: round shared magnifications, thinning that keeps every pixel column's extremes, the ISO 230-4 evaluation."""

import numpy as np
import pytest

from contoursim import paths
from contoursim.feed import plan, sample
from contoursim.machine import load_machine
from contoursim.plotting import (_Rows, _thin_curve, circular_deviation, envelope_indices, magnification_for,
                                 plot_polar_deviation, save_figures)
from contoursim.simulation import simulate


@pytest.mark.parametrize("size, error", [(100.0, 0.01), (100.0, 0.0123), (4000.0, 0.15), (50.0, 3.0), (10.0, 40.0),
                                         (1.0, 1e-7)])
def test_magnification_is_round_at_least_one_and_fits(size, error):
    k = magnification_for(size, error)
    mantissa = k / 10 ** np.floor(np.log10(k))
    assert k >= 1 and min(abs(mantissa - m) for m in (1, 2, 5)) < 1e-9
    if k > 1:  # magnified: the largest error drawn at most 8 % of the size, and more than 8 / 2.5 %
        assert 0.08 / 2.5 * size < k * error <= 0.08 * size * (1 + 1e-12)


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
