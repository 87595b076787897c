"""Sweeps: the spec, the draws, each row against its own single run, and the same table on any number of workers."""

import dataclasses
import io
import os
import re
import signal

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from contoursim.cli import main
from contoursim.comparison import Comparison, compare
from contoursim.exceptions import ConfigError
from contoursim.simulation import simulate
from contoursim.sweep import FIGURES, _job, read_sweep, run_sweep, table_text

JOB = """machine = "demo_mill"
path = "rounded_square"
strategies = "{strategies}"

[feed]
feed_mm_min = 3000

[sweep]
{sweep}
"""


def _spec(tmp_path, varies, sweep='method = "grid"', strategies="ccc_linear", name="spec.toml"):
    text = JOB.format(strategies=strategies, sweep=sweep)
    for v in varies:
        text += "\n[[vary]]\n" + "\n".join(f"{k} = {value}" for k, value in v.items()) + "\n"
    (tmp_path / name).write_text(text)
    return tmp_path / name


def test_a_grid_is_the_full_product_in_order(tmp_path):
    spec = _spec(tmp_path, [{"name": '"axes.x.kp_per_s"', "min": 30.0, "max": 50.0, "count": 3},
                            {"name": '"effect.backlash.x.lost_motion_um"', "values": "[0.0, 8.0]"}])
    sweep = read_sweep(spec)
    assert sweep.names == ("axes.x.kp_per_s", "effect.backlash.x.lost_motion_um")
    np.testing.assert_array_equal(sweep.values, [[30, 0], [30, 8], [40, 0], [40, 8], [50, 0], [50, 8]])


@pytest.mark.parametrize("method", ["random", "lhs"])
def test_draws_are_seeded_within_their_ranges_and_a_latin_hypercube_fills_every_stratum(tmp_path, method):
    varies = [{"name": '"strategy.ccc_linear.kp_per_s"', "min": 10.0, "max": 1000.0, "log": "true"},
              {"name": '"axes.y.kp_per_s"', "min": 30.0, "max": 40.0}]
    one = read_sweep(_spec(tmp_path, varies, f'method = "{method}"\ncount = 50\nseed = 3', name="a.toml")).values
    same = read_sweep(_spec(tmp_path, varies, f'method = "{method}"\ncount = 50\nseed = 3', name="b.toml")).values
    other = read_sweep(_spec(tmp_path, varies, f'method = "{method}"\ncount = 50\nseed = 4', name="c.toml")).values
    np.testing.assert_array_equal(one, same)
    assert not np.array_equal(one, other)
    assert one.shape == (50, 2) and (one[:, 0] >= 10).all() and (one[:, 0] <= 1000).all()
    assert (one[:, 1] >= 30).all() and (one[:, 1] <= 40).all()
    if method == "lhs":  # each of the 50 strata of each parameter (in log for the first) holds one draw
        strata = [np.floor(50 * np.log(one[:, 0] / 10) / np.log(100)), np.floor(50 * (one[:, 1] - 30) / 10)]
        for s in strata:
            assert sorted(s) == list(range(50))


@settings(max_examples=40, deadline=None)
@given(count=st.integers(1, 200), seed=st.integers(0, 2**32), low=st.floats(-1e3, 1e3), span=st.floats(1e-3, 1e3))
def test_a_latin_hypercube_puts_one_draw_in_each_stratum_of_each_parameter(count, seed, low, span):
    from contoursim.sweep import _draw

    tables = [{"name": "a", "min": low, "max": low + span}, {"name": "b", "min": 1.0, "max": 1e4, "log": True}]
    values = _draw(None, tables, "lhs", count, seed)
    strata = [np.floor(count * (values[:, 0] - low) / span), np.floor(count * np.log10(values[:, 1]) / 4)]
    for s in strata:
        assert sorted(np.clip(s, 0, count - 1)) == list(range(count))  # clip: a draw on the upper edge by rounding
    np.testing.assert_array_equal(values, _draw(None, tables, "lhs", count, seed))


@pytest.mark.parametrize(("vary", "message"), [
    ({"name": '"axes.w.kp_per_s"', "min": 1.0, "max": 2.0}, r"spec.toml, line 12: vary 'axes.w.kp_per_s': the machine "
                                                           r"has no servo axis 'w'; its axes: x, y, z"),
    ({"name": '"axes.x.kp"', "min": 1.0, "max": 2.0}, r"line 12: vary 'axes.x.kp': no axis key 'kp'; the keys: mass_kg"),
    ({"name": '"strategy.ccc_arc.kp_per_s"', "min": 1.0, "max": 2.0}, r"runs no strategy 'ccc_arc' \(strategies = \"ccc_linear\"\)"),
    ({"name": '"strategy.ccc_linear.gain"', "min": 1.0, "max": 2.0}, r"no setting 'gain'; its settings: kp_per_s, ki_per_s2, kd"),
    ({"name": '"strategy.ccc_linear.kp_per_s"', "min": -1.0, "max": 2.0},  # was the API's name: "kp must be ..."
     r"line 12: vary 'strategy.ccc_linear.kp_per_s': kp_per_s must be zero or positive, got -1.0"),
    ({"name": '"effect.backlash.x.lost_motion_um"', "min": -5.0, "max": 2.0}, r"line 12: vary 'effect.backlash.x.lost_motion_um': "),
    ({"name": '"axes.x.kp_per_s"', "min": 50.0, "max": 2.0, "count": 2}, r"line 13: vary 'axes.x.kp_per_s': min must not exceed max"),
    ({"name": '"axes.x.kp_per_s"', "min": 5.0}, r"line 11: vary 'axes.x.kp_per_s' needs max = <number>"),
    # "values contains a non-finite value (nan) at index (0, 0)", naming no file: the grid's step overflowed
    ({"name": '"axes.x.kp_per_s"', "min": -1.7e308, "max": 1.7e308},
     r"line 13: vary 'axes.x.kp_per_s': min = -1.7e\+308 and max = 1.7e\+308 lie too far apart to draw between: their "
     r"difference is beyond ±1.798e\+308"),
    ({"name": '"axes.x.kp_per_s"', "min": 1e-300, "max": 1e300, "log": "true"},  # a log draw's ratio overflowed
     r"line 13: vary 'axes.x.kp_per_s': min = 1e-300 and max = 1e\+300 .* their ratio is beyond"),
    ({"name": '"axes.x.kp_per_s"', "min": 5.0, "max": 9.0, "count": 0}, r"line 15: vary.count must be a whole number, "
                                                                         r"at least 1; got 0"),  # it was a TypeError's
    ({"name": '"axes.x.kp_per_s"', "min": 5.0, "max": 9.0, "count": 1},  # it ran kp 5 alone
     r"line 15: vary 'axes.x.kp_per_s': count = 1 is min = 5 alone, max = 9 never runs"),
    ({"name": '"axes.x.kp_per_s"', "min": 5.0, "max": 5.0, "count": 3},  # it ran kp 5 three times
     r"line 15: vary 'axes.x.kp_per_s': min = max = 5: count = 3 would run that one value 3 times"),
    ({"name": '"axes.x.kp_per_s"', "values": "[30, 40, 30.0]"},  # it ran kp 30 twice, two rows of the same figures
     r"line 13: vary 'axes.x.kp_per_s': values lists 30.0 more than once: each would run again; list each value once"),
])
def test_bad_varies_name_the_file_line_and_what_is_there(tmp_path, vary, message):
    if "values" not in vary:
        vary.setdefault("count", 2)
    with pytest.raises(ConfigError, match=message):
        read_sweep(_spec(tmp_path, [vary]))


@pytest.mark.parametrize(("vary", "message"), [
    # "kd must be zero or positive, got -0.6591149647904255": a value drawn, which the user never wrote
    ({"name": '"strategy.ccc_linear.kd"', "min": -1.0, "max": 1.0}, r"kd must be zero or positive, got -1\.0$"),
    # "... must be a whole number of servo periods, got 0.28831922543926747"
    ({"name": '"axes.x.computation_delay_periods"', "min": 0.0, "max": 2.0},
     r"got 0\.\d+; its min and max are taken, a value drawn between them not: vary it on a grid with values = \[\.\.\.\]"),
])
def test_a_drawn_range_the_parameter_cannot_take_is_said_by_its_bound_or_as_a_grids(tmp_path, vary, message):
    with pytest.raises(ConfigError, match=rf"spec.toml, line 14: vary '{vary['name'][1:-1]}': .*{message}"):
        read_sweep(_spec(tmp_path, [vary], 'method = "lhs"\ncount = 3\nseed = 4'))


@pytest.mark.parametrize("method", ["random", "lhs"])
def test_a_drawn_range_of_one_value_is_refused_by_its_line(tmp_path, method):
    """min = max drew that one value in every variant: three rows of the same figures (a grid refuses it)."""
    spec = _spec(tmp_path, [{"name": '"axes.x.kp_per_s"', "min": 40.0, "max": 40.0}],
                 f'method = "{method}"\ncount = 3\nseed = 4')
    line = spec.read_text().splitlines().index("max = 40.0") + 1
    with pytest.raises(ConfigError, match=rf"spec.toml, line {line}: vary 'axes.x.kp_per_s': min = max = 40: every "
                                          r"variant would draw that one value; set it in the job \(or its machine "
                                          r"file\) instead, or give a max above min$"):
        read_sweep(spec)


def test_parameters_valid_only_together_are_checked_and_varied_together(tmp_path):
    """A cyclic error's period_mm beside the amplitude_um it is added with was refused, "cyclic_error: missing
    'amplitude_um'", though the other table varied it: each name was checked alone (run_sweep ran the pair)."""
    from contoursim.effects import Effect

    spec = _spec(tmp_path, [{"name": '"effect.cyclic_error.x.amplitude_um"', "values": "[3.0]"},
                            {"name": '"effect.cyclic_error.x.period_mm"', "values": "[5.0, 20.0]"}], strategies="none")
    sweep = read_sweep(spec)
    table = run_sweep(sweep)
    job = _job(sweep)
    volumetric = FIGURES.index("volumetric_rms_um")
    for i, (amplitude, period) in enumerate(sweep.values):  # each row the run of the job given that effect
        model = job.model.with_effect(Effect("cyclic_error", "x", amplitude_um=amplitude, period_mm=period))
        single = simulate(model, job.trajectory, job.strategies, settle=0.0).summary()
        assert table[i, volumetric] == single["volumetric_rms_um"] > 1.0
    assert table[0, volumetric] != table[1, volumetric]  # the period reached the effect


def test_a_compliant_screws_motor_mass_and_stiffness_are_varied_together(tmp_path):
    """motor_mass_kg and screw_stiffness_N_per_um, each needing the other, were set on the servo one at a time:
    "motor_mass_kg is given, so the compliant screw needs screw_stiffness_N_per_um as well"."""
    spec = _spec(tmp_path, [{"name": '"axes.x.motor_mass_kg"', "values": "[60.0]"},
                            {"name": '"axes.x.screw_stiffness_N_per_um"', "values": "[100.0, 400.0]"}],
                 strategies="none")
    sweep = read_sweep(spec)
    table = run_sweep(sweep)
    job = _job(sweep)
    contour = FIGURES.index("contour_max_um")
    for i, (motor, stiffness) in enumerate(sweep.values):  # each row the run of the machine given that screw
        axes = {**job.model.machine.axes}
        axes["x"] = dataclasses.replace(axes["x"], motor_mass=motor, screw_stiffness=stiffness)
        model = dataclasses.replace(job.model, machine=dataclasses.replace(job.model.machine, axes=axes))
        single = simulate(model, job.trajectory, job.strategies, settle=0.0).summary()
        assert table[i, contour] == single["contour_max_um"]
    assert table[0, contour] != table[1, contour] and not table[:, FIGURES.index("diverged")].any()


@pytest.mark.parametrize(("varies", "bad", "message"), [
    # period_mm's range beside amplitude_um: was "cyclic_error: missing 'amplitude_um'"
    ([("effect.cyclic_error.x.amplitude_um", 1.0, 3.0), ("effect.cyclic_error.x.period_mm", 0.01, 20.0)], 1,
     r"cyclic_error.x: period_mm must lie in \[0.1, 1000\] mm, got 0.01$"),
    # amplitude_um's range, period_mm before it: was said at period_mm's table ("missing 'amplitude_um'")
    ([("effect.cyclic_error.x.period_mm", 5.0, 20.0), ("effect.cyclic_error.x.amplitude_um", -1.0, 3.0)], 1,
     r"cyclic_error.x: amplitude_um must lie in \[0, 1000\] µm, got -1$"),
    ([("axes.x.screw_stiffness_N_per_um", 100.0, 400.0), ("axes.x.motor_mass_kg", 60.0, 400.0)], 1,
     r"motor_mass_kg must be less than mass_kg \(300 kg\)"),
    # one range the job cannot take beside a good one: at its own table, not at the other's checked with its draws
    ([("axes.x.kp_per_s", 30.0, 50.0), ("effect.backlash.x.lost_motion_um", -5.0, 2.0)], 1,
     r"backlash.x: lost_motion_um must lie in \[0, 1000\] µm, got -5$"),
    ([("effect.backlash.x.lost_motion_um", -5.0, 2.0), ("axes.x.kp_per_s", 30.0, 50.0)], 0,
     r"backlash.x: lost_motion_um must lie in \[0, 1000\] µm, got -5$"),
    ([("axes.x.kp_per_s", 30.0, 50.0), ("axes.w.kp_per_s", 30.0, 50.0)], 1, r"the machine has no servo axis 'w'"),
    # a name the job has no place for after a pair: not "missing 'amplitude_um'" at period_mm's table
    ([("effect.cyclic_error.x.amplitude_um", 1.0, 3.0), ("effect.cyclic_error.x.period_mm", 5.0, 20.0),
      ("axes.x.kp", 1.0, 2.0)], 2, r"no axis key 'kp'"),
])  # fmt: skip
def test_a_value_refused_beside_the_other_varied_names_is_said_at_its_own_table(tmp_path, varies, bad, message):
    spec = _spec(tmp_path, [{"name": f'"{name}"', "min": low, "max": high} for name, low, high in varies],
                 'method = "lhs"\ncount = 4\nseed = 2')
    line = spec.read_text().splitlines().index(f'name = "{varies[bad][0]}"') + 1
    with pytest.raises(ConfigError, match=rf"spec.toml, line {line}: vary '{varies[bad][0]}': {message}"):
        read_sweep(spec)


@pytest.mark.parametrize(("log", "message"), [
    # it ran, the table plotting its 0 µm point nowhere on the log scale it was asked for
    ("true", r"line 14: vary 'effect.backlash.x.lost_motion_um': log = true plots the values on a log scale, which 0.0 "
             r"is not on: give positive values, or log = false"),
    ('"yes"', r"line 14: log must be true or false, got 'yes'"),  # beside values it was not read
])
def test_a_grids_values_plotted_on_a_log_scale_are_positive(tmp_path, log, message):
    with pytest.raises(ConfigError, match=message):
        read_sweep(_spec(tmp_path, [{"name": '"effect.backlash.x.lost_motion_um"', "values": "[0.0, 8.0]", "log": log}]))
    sweep = read_sweep(_spec(tmp_path, [{"name": '"effect.backlash.x.lost_motion_um"', "values": "[2.0, 8.0]",
                                         "log": "true"}]))
    assert sweep.log == (True,)


def test_a_value_the_parameter_cannot_take_is_said_by_its_file_key(tmp_path):
    """A grid's value of kp_per_s below zero was refused as "kp must be positive", the servo's own name."""
    with pytest.raises(ConfigError, match=r"spec.toml, line 12: vary 'axes.x.kp_per_s': kp_per_s must be positive, "
                                          r"got -35.0$"):
        read_sweep(_spec(tmp_path, [{"name": '"axes.x.kp_per_s"', "values": "[-35.0, 40.0]"}]))


def test_a_single_vary_table_is_told_to_be_an_array_of_tables(tmp_path):
    """[vary] (one table) was told "a sweep needs at least one [[vary]] table", with no line and no hint."""
    spec = _spec(tmp_path, [{"name": '"axes.x.kp_per_s"', "values": "[40.0]"}])
    spec.write_text(spec.read_text().replace("[[vary]]", "[vary]"))
    line = spec.read_text().splitlines().index("[vary]") + 1
    with pytest.raises(ConfigError, match=rf"spec.toml, line {line}: \[vary\] is one table: a sweep's parameters are "
                                          r"each a \[\[vary\]\] table \(double brackets\)"):
        read_sweep(spec)


@pytest.mark.parametrize(("vary", "sweep", "message"), [
    # was "vary.count must be a whole number, at least 1; got None"
    ({"name": '"axes.x.kp_per_s"', "min": 5.0, "max": 9.0}, 'method = "grid"', r"spec.toml, line 11: vary.count is "
                                                                              r"missing: give count = "),
    ({"name": '"axes.x.kp_per_s"', "min": 5.0, "max": 9.0}, 'method = "lhs"', r"spec.toml, line 8: sweep.count is missing: "
                                                                             r"give count = "),
])
def test_a_missing_count_is_said_missing_by_its_key_and_line(tmp_path, vary, sweep, message):
    with pytest.raises(ConfigError, match=message) as info:
        read_sweep(_spec(tmp_path, [vary], sweep))
    assert "None" not in str(info.value)


def test_a_strategy_table_of_a_strategy_the_sweep_does_not_run_is_refused_by_its_line(tmp_path):
    """A spec's [[strategy]] table for feedforward beside strategies = "ccc_linear" was dropped without a word."""
    spec = _spec(tmp_path, [{"name": '"axes.x.kp_per_s"', "values": "[40.0]"}])
    spec.write_text(spec.read_text() + '\n[[strategy]]\nname = "feedforward"\nvelocity_fraction = 0.5\n')
    line = spec.read_text().splitlines().index('name = "feedforward"') + 1
    with pytest.raises(ConfigError, match=rf"spec.toml, line {line}: \[\[strategy\]\] feedforward: no strategy run "
                                          r"here has it \(strategies ccc_linear\)"):
        read_sweep(spec)


def test_a_comparison_list_as_a_sweeps_strategies_is_refused_saying_what_a_sweep_runs(tmp_path):
    """'none,feedforward', compare's list, read as one unknown strategy of that name (did you mean 'feedforward'?)."""
    spec = _spec(tmp_path, [{"name": '"axes.x.kp_per_s"', "values": "[40.0]"}], strategies="none,feedforward")
    line = spec.read_text().splitlines().index('strategies = "none,feedforward"') + 1
    with pytest.raises(ConfigError, match=rf"spec.toml, line {line}: strategies = 'none,feedforward': a sweep runs one "
                                          r"composition on every variant, its parts joined by '\+'"):
        read_sweep(spec)


@pytest.mark.parametrize(("text", "key", "message"), [
    # a traceback
    ('\n[ballbar]\ndirections = ["ccw", "cw"]\n', "[ballbar]", r"\[ballbar\] is for contoursim simulate; sweep runs"),
    # read, checked and dropped without a word: the table held the uncompensated figures
    ("geometric_compensation = true\n", "geometric_compensation = true",
     r'a sweep runs its strategies on every variant: name geometric compensation there \(strategies = "geometric"')])
def test_a_jobs_ballbar_or_geometric_switch_in_a_spec_is_refused_by_its_line(tmp_path, text, key, message):
    spec = _spec(tmp_path, [{"name": '"axes.x.kp_per_s"', "values": "[40.0]"}], strategies="none")
    job = spec.read_text().replace("demo_mill", "vertical_mill_3axis")
    spec.write_text(text + job if key.startswith("geo") else job + text)
    line = spec.read_text().splitlines().index(key) + 1
    with pytest.raises(ConfigError, match=rf"spec.toml, line {line}: {message}"):
        read_sweep(spec)


@pytest.mark.parametrize("key", ["count = 7", "seed = 3"])
def test_a_grids_count_or_seed_in_the_sweep_table_is_refused_by_its_line(tmp_path, key):
    """A grid's points are its vary tables' (it ran 2 variants, the 7 asked for ignored)."""
    spec = _spec(tmp_path, [{"name": '"axes.x.kp_per_s"', "min": 30.0, "max": 50.0, "count": 2}],
                 sweep=f'method = "grid"\n{key}')
    with pytest.raises(ConfigError, match=rf"spec.toml, line 10: sweep.{key.split()[0]} is for random and lhs draws: "
                                          r"a grid's points are each \[\[vary\]\] table's count or values"):
        read_sweep(spec)


@pytest.mark.parametrize(("varies", "sweep", "message"), [
    ([{"name": '"axes.x.kp_per_s"', "min": 30.0, "max": 50.0, "count": 10**30}], 'method = "grid"',
     r"spec.toml, line 15: vary.count of 'axes.x.kp_per_s': a grid of 10{30} points, 1e\+30 variants, needs about "
     r"7e\+23 GB of memory and .* GB are available; sweep fewer variants"),
    ([{"name": '"axes.x.kp_per_s"', "min": 30.0, "max": 50.0, "count": 10**5},
      {"name": '"axes.y.kp_per_s"', "values": "[30, 40]"},
      {"name": '"axes.x.vff"', "min": 0.0, "max": 1.0, "count": 10**14}], 'method = "grid"',
     r"spec.toml, line 25: vary.count of 'axes.x.vff': a grid of 100000 x 2 x 10{14} points, 2e\+19 variants"),
    ([{"name": '"axes.x.kp_per_s"', "min": 30.0, "max": 50.0}], 'method = "lhs"\ncount = 100000000000000\nseed = 1',
     r"spec.toml, line 10: sweep.count = 10{14}, 1e\+14 variants, needs about 7e\+07 GB"),
])  # fmt: skip
def test_a_sweep_too_large_for_the_memory_is_refused_before_anything_is_drawn(tmp_path, varies, sweep, message):
    # (count = 1e8 took the values' 800 MB and more before anything was said; 1e30 ended in numpy's own error)
    with pytest.raises(ConfigError, match=message):
        read_sweep(_spec(tmp_path, varies, sweep))


def test_the_sweep_limit_is_the_memory_its_variants_take(tmp_path, monkeypatch):
    from contoursim import _memory

    spec = _spec(tmp_path, [{"name": '"axes.x.kp_per_s"', "min": 30.0, "max": 50.0, "count": 2000},
                            {"name": '"axes.y.kp_per_s"', "values": "[30, 40]"}])
    monkeypatch.setattr(_memory, "available", lambda: 10**9)
    monkeypatch.setattr(_memory, "SWEEP_BYTES_PER_VALUE", 10**9 / 8000)  # 4000 variants of 2 values fit, no more
    assert read_sweep(spec).values.shape == (4000, 2)
    monkeypatch.setattr(_memory, "SWEEP_BYTES_PER_VALUE", 10**9 / 8000 + 1)
    with pytest.raises(ConfigError, match=r"line 15: vary.count of 'axes.x.kp_per_s': a grid of 2000 x 2 points"):
        read_sweep(spec)


def test_each_row_is_the_single_run_of_its_variant(tmp_path):
    spec = _spec(tmp_path, [{"name": '"strategy.ccc_linear.kp_per_s"', "values": "[30.0, 90.0]"},
                            {"name": '"axes.y.kp_per_s"', "values": "[30.0]"},
                            {"name": '"effect.gain_mismatch.x.kp_ratio"', "values": "[0.9]"}])
    sweep = read_sweep(spec)
    table = run_sweep(sweep)
    job = _job(sweep)
    for i, (kp_ccc, kp_y, ratio) in enumerate(sweep.values):
        model, strategies = job.variant(dict(zip(sweep.names, sweep.values[i])))
        assert model.machine.axes["y"].kp == kp_y and model.values() == {"gain_mismatch.x.kp_ratio": ratio}
        assert strategies[0].kp == kp_ccc and strategies[0].estimator == "linear"
        # the job's trajectory holds its settle already, as the sweep runs it (simulate's default would hold it again)
        figures = Comparison({"run": simulate(model, job.trajectory, strategies, settle=0.0)}).figures["run"]
        for j, key in enumerate(FIGURES[:5]):
            assert table[i, j] == figures[key]
        assert table[i, FIGURES.index("diverged")] == 0.0
    assert table[1, 0] < table[0, 0]  # a stiffer coupling: a smaller contour error


def test_a_pre_filter_sweep_runs_variants_one_by_one_each_designed_from_its_own_servos(tmp_path):
    spec = _spec(tmp_path, [{"name": '"axes.x.kp_per_s"', "values": "[30.0, 50.0]"}], strategies="zpetc")
    sweep = read_sweep(spec)
    table = run_sweep(sweep)
    job = _job(sweep)
    for i in range(2):
        model, strategies = job.variant({"axes.x.kp_per_s": sweep.values[i, 0]})
        assert table[i, 0] == compare(model, job.trajectory, ["zpetc"]).figures["zpetc"]["contour_max_um"]


def test_the_table_does_not_depend_on_how_the_variants_are_split(tmp_path):
    spec = _spec(tmp_path, [{"name": '"strategy.ccc_linear.kp_per_s"', "min": 10.0, "max": 300.0}],
                 'method = "random"\ncount = 5\nseed = 1')
    sweep = read_sweep(spec)
    whole = table_text(sweep, run_sweep(sweep))
    for size in (1, 2):
        split = read_sweep(spec)
        object.__setattr__(split, "task_size", size)
        assert table_text(split, run_sweep(split)) == whole


def test_scheduler_without_dask_says_how_to_get_it(tmp_path, monkeypatch, capsys):
    import builtins

    real_import = builtins.__import__

    def no_dask(name, *args, **kwargs):
        if name.startswith("distributed"):
            raise ImportError(name)
        return real_import(name, *args, **kwargs)

    monkeypatch.setattr(builtins, "__import__", no_dask)
    spec = _spec(tmp_path, [{"name": '"axes.x.kp_per_s"', "values": "[40.0]"}])
    assert main(["sweep", str(spec), "--scheduler", "local:2", "--out", str(tmp_path / "o")]) == 2
    assert 'pip install "contoursim[distributed]"' in capsys.readouterr().err


def test_bad_local_scheduler_is_refused(tmp_path, capsys):
    pytest.importorskip("distributed", reason="dask.distributed not installed (pip install \"contoursim[distributed]\")")
    spec = _spec(tmp_path, [{"name": '"axes.x.kp_per_s"', "values": "[40.0]"}])
    assert main(["sweep", str(spec), "--scheduler", "local:zero", "--out", str(tmp_path / "o")]) == 2
    assert "local:N needs a whole number of workers, at least 1; got 'local:zero'" in capsys.readouterr().err


def test_a_local_cluster_too_large_for_the_memory_is_refused_before_a_process_starts(tmp_path, monkeypatch, capsys):
    """local:1000 (a typo for local:10) started worker after worker until the machine's memory ran out."""
    pytest.importorskip("distributed", reason="dask.distributed not installed (pip install \"contoursim[distributed]\")")
    import psutil  # a dependency of distributed

    from contoursim import _memory

    monkeypatch.setattr(_memory, "available", lambda: 3 * _memory.WORKER_BYTES)
    spec = _spec(tmp_path, [{"name": '"axes.x.kp_per_s"', "values": "[40.0]"}])
    before = len(psutil.Process().children(recursive=True))
    assert main(["sweep", str(spec), "--scheduler", "local:4", "--out", str(tmp_path / "o")]) == 2
    assert "--scheduler local:4: 4 worker processes need about 1.6 GB of memory and 1.2 GB are available; start " \
           "fewer" in capsys.readouterr().err
    assert len(psutil.Process().children(recursive=True)) == before and not (tmp_path / "o").exists()


def test_local_local1_local2_and_a_killed_worker_give_the_same_table_bit_for_bit(tmp_path):
    distributed = pytest.importorskip("distributed", reason="dask.distributed not installed "
                                                            "(pip install \"contoursim[distributed]\")")
    spec = _spec(tmp_path, [{"name": '"strategy.ccc_linear.kp_per_s"', "min": 10.0, "max": 300.0},
                            {"name": '"effect.backlash.x.lost_motion_um"', "min": 0.0, "max": 10.0}],
                 'method = "lhs"\ncount = 12\nseed = 5\ntask_size = 2')
    sweep = read_sweep(spec)
    local = table_text(sweep, run_sweep(sweep))
    assert table_text(sweep, run_sweep(sweep, "local:1")) == local
    assert table_text(sweep, run_sweep(sweep, "local:2")) == local

    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, host="127.0.0.1", dashboard_address=None,
                                  env={"NUMBA_NUM_THREADS": "1"}) as cluster, distributed.Client(cluster) as client:
        pids = client.run(os.getpid)
        killed = []

        def kill_one(done, total):  # the first results are in: end a worker's process by its pid
            if done > 0 and not killed:
                pid = next(iter(pids.values()))
                os.kill(pid, signal.SIGKILL)
                killed.append(pid)

        table = run_sweep(sweep, client, progress=kill_one)
        assert killed and table_text(sweep, table) == local

        # a machine file in a folder below the spec's: the workers get its text and rebuild it
        own = _own_machine_spec(tmp_path / "own")
        assert table_text(own, run_sweep(own, client)) == table_text(own, run_sweep(own))


def _own_machine_spec(folder):
    from contoursim.machine import preset_file

    (folder / "machines").mkdir(parents=True)
    text = preset_file("demo_mill").read_text().replace("kp_per_s = 36.0", "kp_per_s = 30.0")
    (folder / "machines" / "mill.toml").write_text(text)
    spec = _spec(folder, [{"name": '"axes.x.kp_per_s"', "values": "[35.0, 45.0]"}])
    spec.write_text(spec.read_text().replace('machine = "demo_mill"', 'machine = "machines/mill.toml"'))
    sweep = read_sweep(spec)
    assert sorted(sweep.files) == ["machines/mill.toml", "spec.toml"] and not sweep.elsewhere
    assert _job(sweep).model.machine.axes["y"].kp == 30.0
    return sweep


def test_a_file_outside_the_specs_folder_runs_here_but_not_on_a_cluster(tmp_path):
    from contoursim.machine import preset_file

    (tmp_path / "mill.toml").write_text(preset_file("demo_mill").read_text())
    (tmp_path / "specs").mkdir()
    spec = _spec(tmp_path / "specs", [{"name": '"axes.x.kp_per_s"', "values": "[35.0]"}])
    spec.write_text(spec.read_text().replace('machine = "demo_mill"', 'machine = "../mill.toml"'))
    sweep = read_sweep(spec)
    assert sweep.elsewhere == (str(tmp_path / "mill.toml"),)
    assert run_sweep(sweep)[0, FIGURES.index("diverged")] == 0.0
    with pytest.raises(ValueError, match=r"names .*mill.toml, outside its folder: .* copy the file next to the spec"):
        run_sweep(sweep, "local:1")


def test_files_the_spec_names_without_their_suffix_go_to_the_workers(tmp_path):
    """``machine = "demo_mill"``, ``path = "rounded_square"`` with the user's demo_mill.toml and rounded_square.toml
    beside the spec ran them here, but were not sent to a cluster's workers, which ran the preset and the library's
    square: another table, without a word."""
    from contoursim import sweep as module
    from contoursim.machine import preset_file

    (tmp_path / "demo_mill.toml").write_text(preset_file("demo_mill").read_text().replace("kp_per_s = 36.0",
                                                                                         "kp_per_s = 30.0"))
    (tmp_path / "rounded_square.toml").write_text(SMALL_SQUARE)
    spec = _spec(tmp_path, [{"name": '"axes.x.kp_per_s"', "values": "[35.0]"}])
    spec.write_text(spec.read_text().replace("[feed]\nfeed_mm_min = 3000\n", ""))
    sweep = read_sweep(spec)
    assert sorted(sweep.files) == ["demo_mill.toml", "rounded_square.toml", "spec.toml"] and not sweep.elsewhere
    module._JOBS.clear()  # as on a worker: the job rebuilt from the files sent
    job = _job(sweep.files)
    assert job.model.machine.axes["y"].kp == 30.0 and job.trajectory.path.length < 200


SMALL_SQUARE = """[feed]
feed_mm_min = 2000

[path]
type = "polyline"
blend_radius_mm = 5
points_mm = [[0, -20], [20, -20], [20, 20], [-20, 20], [-20, -20], [0, -20]]
"""


def test_a_local_cluster_listens_on_the_loopback_only_and_a_bad_address_is_one_line(tmp_path):
    pytest.importorskip("distributed", reason="dask.distributed not installed (pip install \"contoursim[distributed]\")")
    from contoursim.cluster import connected

    import psutil  # a dependency of distributed

    with connected("local:2") as client:
        addresses = [client.scheduler.address] + list(client.scheduler_info()["workers"])
        assert len(addresses) == 3 and all(a.startswith("tcp://127.0.0.1:") for a in addresses)
        processes = [os.getpid()] + list(client.run(os.getpid).values())  # scheduler and nannies here, workers there
        listening = [c.laddr for pid in processes for c in psutil.Process(pid).net_connections(kind="inet")
                     if c.status == psutil.CONN_LISTEN]
        assert len(listening) >= 5 and {address.ip for address in listening} == {"127.0.0.1"}
    with pytest.raises(ValueError, match=r"cannot reach a dask scheduler at 'tcp://127.0.0.1:1'"):
        with connected("tcp://127.0.0.1:1"):
            pass


@pytest.mark.parametrize("address, words", [
    ("tcp://host", "'tcp://host' lacks a host and port"),
    ("tcp://:8786", "'tcp://:8786' lacks a host and port"),
    ("tcp://host:abc", "'tcp://host:abc': its port 'abc' is not a port number (1 to 65535)"),  # int()'s words
    ("host:99999", "'host:99999': its port '99999' is not a port number (1 to 65535)"),  # waited 10 s for it
])
def test_an_address_without_a_port_is_refused_naming_it(address, words):
    pytest.importorskip("distributed", reason="dask.distributed not installed (pip install \"contoursim[distributed]\")")
    from contoursim.cluster import connected

    with pytest.raises(ValueError, match=re.escape(f"--scheduler {words}; give its address as tcp://host:8786")):
        with connected(address):
            pass


@pytest.mark.parametrize("answer", [None, b"HTTP/1.0 400 Bad Request\r\nContent-Length: 0\r\n\r\n"],
                         ids=["silent", "a web server"])
def test_an_address_that_does_not_answer_as_a_dask_scheduler_is_refused_within_seconds(monkeypatch, answer):
    """A port that takes the connection and says nothing kept contoursim waiting forever (dask bounds the connecting,
    not the greeting); a web server's answer (the dashboard's port) was read as a frame of 3 EiB: 'out of memory'."""
    pytest.importorskip("distributed", reason="dask.distributed not installed (pip install \"contoursim[distributed]\")")
    import socket
    import threading
    import time

    from contoursim import cluster

    monkeypatch.setattr(cluster, "CONNECT_TIMEOUT_S", 2.0)
    server = socket.create_server(("127.0.0.1", 0))
    held = []

    def serve():
        connection, _ = server.accept()
        held.append(connection)
        if answer is not None:
            connection.recv(1 << 16)
            connection.sendall(answer)

    threading.Thread(target=serve, daemon=True).start()
    address = f"tcp://127.0.0.1:{server.getsockname()[1]}"
    start = time.monotonic()
    words = f"cannot reach a dask scheduler at '{address}' (" + ("no dask scheduler answered in 2 s)" if answer is None
                                                                else "Unable to allocate")
    with pytest.raises(ValueError, match=re.escape(words)):
        with cluster.connected(address):
            pass
    assert time.monotonic() - start < 8.0
    server.close()
    for connection in held:
        connection.close()


def test_a_sweep_interrupted_says_so_on_a_line_of_its_own(tmp_path, monkeypatch, capsys):
    """Ctrl-C mid-sweep: 'contoursim sweep: interrupted' was written on the end of the progress bar's line."""
    import contoursim.sweep

    def interrupted(files, names, rows):
        raise KeyboardInterrupt

    monkeypatch.setattr(contoursim.sweep, "run_variants", interrupted)
    spec = _spec(tmp_path, [{"name": '"axes.x.kp_per_s"', "values": "[35.0, 45.0]"}])
    assert main(["sweep", str(spec), "--out", str(tmp_path / "out")]) == 130
    lines = capsys.readouterr().err.split("\n")  # not a terminal: the bar's lines are lines, no "\r"
    assert lines[0].startswith("sweep: [....................] 0/2 variants") and lines[1].startswith(
        "contoursim sweep: interrupted; files already complete are kept"), lines
    assert not (tmp_path / "out").exists()


def test_a_sweep_in_this_process_reports_progress_before_its_last_batch_and_the_table_does_not_depend_on_it(tmp_path):
    """In this process the variants ran in batches of 32: a sweep of 30 showed 0/30, then 30/30 half a minute later
    (an outside probe). The batches double from one variant while they are short; the rows are those of one batch of
    all."""
    spec = _spec(tmp_path, [{"name": '"axes.x.kp_per_s"', "min": 30.0, "max": 50.0, "count": 6}], strategies="none")
    calls = []
    table = run_sweep(read_sweep(spec), progress=lambda done, total: calls.append((done, total)))
    assert calls[0] == (0, 6) and calls[1] == (1, 6) and calls[-1] == (6, 6)
    assert [done for done, _ in calls] == sorted(done for done, _ in calls)
    whole = read_sweep(spec)
    np.testing.assert_array_equal(table, run_sweep(dataclasses.replace(whole, task_size=6)))


def test_a_warning_of_the_best_or_worst_run_names_its_variant(tmp_path, capsys):
    """'the current command hit its limit on x in 6.36 %' came from the re-run of the best or worst variant and said not
    which (an outside probe)."""
    spec = _spec(tmp_path, [{"name": '"axes.x.current_limit_A"', "values": "[0.05, 5.0]"}], strategies="none")
    assert main(["sweep", str(spec), "--out", str(tmp_path / "out")]) == 0
    said = [line for line in capsys.readouterr().err.splitlines() if "hit its limit" in line]
    assert said and all(re.search(r"the (best|worst) variant, [01]: the current command hit its limit", s) for s in said)


class _Terminal(io.StringIO):
    """A stream that says it is a terminal: Progress redraws its line in place on it."""

    def isatty(self):
        return True


def test_progress_redraws_one_line_on_a_terminal_and_writes_a_line_now_and_then_to_a_file(monkeypatch):
    """A sweep's progress sent to a log file was one line of thousands of carriage-return redrawings."""
    from contoursim.sweep import Progress

    clock = iter(np.arange(0.0, 100.0, 0.25))
    monkeypatch.setattr("contoursim.sweep.time.monotonic", lambda: next(clock))
    log = io.StringIO()
    with Progress(stream=log) as progress:
        for done in range(101):
            progress(done, 100)
    lines = log.getvalue().splitlines()
    assert "\r" not in log.getvalue() and 3 <= len(lines) <= 5, lines  # 25 s: one line each 10 s and the last
    assert lines[-1].startswith("sweep: [####################] 100/100 variants")

    clock = iter(np.arange(0.0, 100.0, 0.25))
    screen = _Terminal()
    with Progress(stream=screen) as progress:
        for done in range(101):
            progress(done, 100)
    assert screen.getvalue().count("\n") == 1 and screen.getvalue().count("\r") > 40


def test_progress_counts_its_rate_from_the_work_done_when_it_starts(monkeypatch):
    """A fleet counts its traces that failed on reading as done before the first is diagnosed: its first line said
    '1/8 traces, 1e+09/s, 0 s left' with 7 traces to do (the clock started at the bar's making, or on a call with
    done 0, which a fleet never made). The rate counts from the first call, from its done."""
    from contoursim.sweep import Progress

    now = [100.0]
    monkeypatch.setattr("contoursim.sweep.time.monotonic", lambda: now[0])
    screen = _Terminal()
    with Progress("diagnose", "traces", stream=screen) as progress:
        for now[0], done in ((100.0, 1), (102.0, 2), (106.0, 8)):  # one failed on reading, then 1 in 2 s, 6 in 4 s
            progress(done, 8)
    assert screen.getvalue().split("\r") == ["", "diagnose: [##..................] 1/8 traces",
                                             "diagnose: [#####...............] 2/8 traces, 0.5/s, 12 s left",
                                             "diagnose: [####################] 8/8 traces, 1.17/s, 0 s left\n"]
    log = io.StringIO()  # a sweep's: from 0, as before
    with Progress(stream=log) as progress:
        for now[0], done in ((200.0, 0), (230.0, 60), (300.0, 200)):
            progress(done, 200)
    assert log.getvalue().splitlines() == ["sweep: [....................] 0/200 variants",
                                           "sweep: [######..............] 60/200 variants, 2/s, 1.2 min left",
                                           "sweep: [####################] 200/200 variants, 2/s, 0 s left"]


def test_progress_redrawn_in_place_covers_all_of_the_line_before_it(monkeypatch):
    """A line drawn over a longer one was padded by three spaces: where the line shrank by more ('0.01/s, 165.0 min
    left' to '0.99/s, 0 s left'), the end of the old line stayed on the screen after the new one."""
    from contoursim.sweep import Progress

    now = [0.0]
    monkeypatch.setattr("contoursim.sweep.time.monotonic", lambda: now[0])
    screen = _Terminal()
    with Progress(stream=screen) as progress:
        for now[0], done in ((0.0, 0), (100.0, 1), (101.0, 100)):
            progress(done, 100)
    shown = ""
    for drawn in screen.getvalue().rstrip("\n").split("\r"):  # what a terminal shows: each drawing over the last
        shown = drawn + shown[len(drawn):]
    assert shown.rstrip() == "sweep: [####################] 100/100 variants, 0.99/s, 0 s left", repr(shown)
    assert "165.0 min left" in screen.getvalue()  # the longer line it had to cover


def test_a_local_clusters_workers_leave_a_ctrl_c_to_the_command():
    """A Ctrl-C in a terminal reaches every process of the command: each worker of local:N ended in a traceback of
    its own (KeyboardInterrupt, and the nanny's errors) under the command's one line."""
    pytest.importorskip("distributed", reason="dask.distributed not installed (pip install \"contoursim[distributed]\")")
    from contoursim.cluster import connected

    # as in a terminal, whatever started the tests (a shell's background job ignores SIGINT from its start)
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        with connected("local:1") as client:
            assert list(client.run(signal.getsignal, signal.SIGINT).values()) == [signal.SIG_IGN]
        assert signal.getsignal(signal.SIGINT) is signal.default_int_handler  # the command's own, back
    finally:
        signal.signal(signal.SIGINT, previous)


def test_results_csv_parquet_plots_and_the_best_and_worst_runs(tmp_path, capsys):
    spec = _spec(tmp_path, [{"name": '"strategy.ccc_linear.kp_per_s"', "values": "[20.0, 80.0]"},
                            {"name": '"axes.x.kp_per_s"', "values": "[35.0, 45.0]"}])
    assert main(["sweep", str(spec), "--out", str(tmp_path / "out")]) == 0
    out = tmp_path / "out"
    sweep = read_sweep(spec)
    text = (out / "sweep.csv").read_text()
    table = np.array([[float(c) if c not in ("True", "False") else float(c == "True") for c in line.split(",")[3:]]
                      for line in text.splitlines()[1:]])
    assert text == table_text(sweep, table)  # the figures read back exactly
    best, worst = np.argmin(table[:, 0]), np.argmax(table[:, 0])
    assert f"best   variant {best}:" in capsys.readouterr().out
    for label, i in (("best", best), ("worst", worst)):
        head = (out / f"{label}.csv").read_text().splitlines()[:12]
        assert f"# variant: {i}" in head
    assert {"sweep_map.png", "sweep_axes.x.kp_per_s.png", "best_path.png", "worst_errors.png"} <= {p.name for p in out.iterdir()}
    pq = pytest.importorskip("pyarrow.parquet", reason="pyarrow not installed: no Parquet table")
    parquet = pq.read_table(out / "sweep.parquet").to_pydict()
    assert list(parquet) == ["variant", *sweep.names, *FIGURES]
    assert parquet["contour_max_um"] == table[:, 0].tolist() and parquet["diverged"] == [False] * 4


def test_a_tolerance_sweep_gives_the_volumetric_error_linear_in_the_squareness(tmp_path):
    spec = _spec(tmp_path, [{"name": '"effect.squareness.xy.angle_urad"', "values": "[50.0, 100.0, -100.0]"}],
                 strategies="none")
    sweep = read_sweep(spec)
    table = run_sweep(sweep)
    job = _job(sweep)
    volumetric = table[:, FIGURES.index("volumetric_max_um")]
    assert volumetric[0] > 1.0 and volumetric[1] == pytest.approx(2 * volumetric[0], rel=1e-9)
    assert volumetric[2] == pytest.approx(volumetric[1], rel=1e-9)  # the same magnitude, the other way
    model, strategies = job.variant({"effect.squareness.xy.angle_urad": 100.0})
    single = simulate(model, job.trajectory, strategies, settle=0.0).summary()
    assert table[1, FIGURES.index("volumetric_rms_um")] == single["volumetric_rms_um"]
    assert table[1, FIGURES.index("contour_max_um")] == single["contour_max_um"]


def test_a_sweep_into_an_earlier_sweeps_folder_leaves_none_of_the_earlier_sweeps_files(tmp_path):
    """Every variant of the second sweep diverged: best.csv and worst.csv of the first one stayed beside its table (and
    the plots of a parameter it did not vary), taken for its own; a user's file there is left."""
    two = _spec(tmp_path, [{"name": '"axes.x.kp_per_s"', "values": "[35.0, 45.0]"},
                           {"name": '"axes.y.kp_per_s"', "values": "[35.0]"}], strategies="none")
    assert main(["sweep", str(two), "--out", str(tmp_path / "out")]) == 0
    assert {"best.csv", "worst_errors.png", "sweep_axes.y.kp_per_s.png", "sweep_map.png"} <= set(
        os.listdir(tmp_path / "out"))
    (tmp_path / "out" / "notes.txt").write_text("mine\n")
    one = _spec(tmp_path, [{"name": '"axes.x.kp_per_s"', "values": "[9000.0]"}], strategies="none", name="one.toml")
    assert main(["sweep", str(one), "--out", str(tmp_path / "out")]) == 0
    kept = sorted(name for name in os.listdir(tmp_path / "out") if name != "sweep.parquet")  # with pyarrow
    assert kept == [".contoursim-out", "notes.txt", "sweep.csv", "sweep_axes.x.kp_per_s.png"]


def test_a_sweep_leaves_the_files_another_command_wrote_into_its_folder(tmp_path):
    """simulate's plots of a path named sweep_a (sweep_a_path.png) and its run of a path named best (best.csv) were
    removed by a sweep into the same folder, taken by their names for an earlier sweep's."""
    for name in ("sweep_a", "best"):
        (tmp_path / f"{name}.toml").write_text('[feed]\nfeed_mm_min = 1000\n[path]\ntype = "polyline"\n'
                                               "points_mm = [[0, 0], [5, 0], [5, 5]]\n")
        assert main(["simulate", str(tmp_path / f"{name}.toml"), "--out", str(tmp_path / "out")]) == 0
    simulated = set(os.listdir(tmp_path / "out"))
    assert {"sweep_a.csv", "sweep_a_path.png", "sweep_a_errors.png", "best.csv", "best_path.png"} <= simulated
    diverged = _spec(tmp_path, [{"name": '"axes.x.kp_per_s"', "values": "[9000.0]"}], strategies="none")
    assert main(["sweep", str(diverged), "--out", str(tmp_path / "out")]) == 0  # no best or worst run of its own
    assert simulated <= set(os.listdir(tmp_path / "out"))


def test_a_variant_the_coupled_loops_check_refuses_is_said_so_with_its_margins(tmp_path, capsys):
    """kp = 1e5/s of a CCC among good gains: 'a cross-coupled loop's check refused it, or its run left ±1e+06 mm',
    neither which nor how far."""
    spec = _spec(tmp_path, [{"name": '"strategy.ccc_arc.kp_per_s"', "values": "[60.0, 100000.0]"}], strategies="ccc_arc")
    assert main(["sweep", str(spec), "--out", str(tmp_path / "out")]) == 0
    out = capsys.readouterr().out
    assert ("the first, variant 1 (strategy.ccc_arc.kp_per_s = 100000): cross-coupled control with kp = 100000 1/s"
            in out and "is unstable (spectral radius" in out and "phase margin" in out), out


@pytest.mark.parametrize("strategies", ["none", "ccc_arc"])
def test_a_variant_the_loop_check_refuses_counts_as_diverged_and_is_not_rerun(tmp_path, capsys, strategies):
    """kp = 2000/s: the batch ran it unchecked and the re-run of the worst variant (simulate, checked) ended the sweep
    in an error after its table was written; it is refused like a coupled loop the check refuses. With a coupling's
    designed gains the whole sweep ended in "the coupled loop is damped at ... set the coupling gains" (an outside
    probe): the refused variant is not run, so nothing is designed on its loops."""
    spec = _spec(tmp_path, [{"name": '"axes.x.kp_per_s"', "values": "[35.0, 45.0, 2000.0]"}], strategies=strategies)
    assert main(["sweep", str(spec), "--out", str(tmp_path / "out")]) == 0
    out = capsys.readouterr().out
    table = run_sweep(read_sweep(spec))
    np.testing.assert_array_equal(table[:, FIGURES.index("diverged")], [0, 0, 1])
    assert np.isnan(table[2, FIGURES.index("contour_max_um")])
    assert "1 of 3 variants diverged or were refused by a loop check" in out and "worst  variant 1:" in out
    assert ("the first, variant 2 (axes.x.kp_per_s = 2000): the position loop of axis 'x' is badly damped" in out
            and "gain margin 3.79, phase margin 11.5 deg at 112.5 Hz" in out)  # how far it is, in its margins


def test_a_variant_whose_loops_allow_no_designed_coupling_gains_is_named(tmp_path):
    """kp = 64/s passes the axis check (damped at 0.696) but leaves the coupling no gain damped at 0.7: the sweep's
    error named no variant."""
    spec = _spec(tmp_path, [{"name": '"axes.x.kp_per_s"', "values": "[40.0, 64.0]"}], strategies="ccc_arc")
    with pytest.raises(ValueError, match=r"^the variant axes.x.kp_per_s = 64: the coupled loop is damped at 0.696 < "
                                         r"0.7 .* \(in the spec: a \[\[strategy\]\] table's kp_per_s and ki_per_s2"):
        run_sweep(read_sweep(spec))


def test_a_sweep_refused_by_a_users_file_of_one_of_its_names_writes_nothing(tmp_path, capsys):
    """A user's file named as one of the second sweep's plots: sweep.csv had already been replaced by the second
    sweep's table, the best and worst runs left from the first, when the run ended in the refusal (an outside probe)."""
    first = _spec(tmp_path, [{"name": '"axes.x.kp_per_s"', "values": "[35.0, 45.0]"}], strategies="none")
    assert main(["sweep", str(first), "--out", str(tmp_path / "out")]) == 0
    before = {name: (tmp_path / "out" / name).read_bytes() for name in os.listdir(tmp_path / "out")}
    (tmp_path / "out" / "sweep_axes.y.kp_per_s.png").write_text("mine\n")
    second = _spec(tmp_path, [{"name": '"axes.y.kp_per_s"', "values": "[35.0, 45.0]"}], strategies="none", name="b.toml")
    assert main(["sweep", str(second), "--out", str(tmp_path / "out")]) == 2
    assert "sweep_axes.y.kp_per_s.png exists and contoursim did not write it" in capsys.readouterr().err
    after = {name: (tmp_path / "out" / name).read_bytes() for name in os.listdir(tmp_path / "out")}
    assert after == {**before, "sweep_axes.y.kp_per_s.png": b"mine\n"}


def test_a_sweep_made_in_python_is_refused_where_its_names_values_and_options_do_not_fit(tmp_path):
    # values of one column for two names ran the first parameter alone (zip cut the second), a name given alone was
    # its characters, no values a table of none, log = () (the default) an IndexError in plot_sweep, task_size = 0 or
    # files = {} were taken
    sweep = read_sweep(_spec(tmp_path, [{"name": '"axes.x.kp_per_s"', "min": 30.0, "max": 50.0, "count": 2},
                                        {"name": '"axes.y.kp_per_s"', "values": "[30.0, 40.0]"}]))
    for change, error, words in (
        (dict(values=sweep.values[:, :1]), ValueError, r"values must have shape \(N, 2\), got \(4, 1\)"),
        (dict(values=sweep.values[:, 0]), ValueError, r"values must have shape \(N, 2\), got \(4,\)"),
        (dict(values=np.empty((0, 2))), ValueError, r"values holds no variant: a sweep needs one row or more"),
        (dict(values=np.full((1, 2), np.nan)), ValueError, r"values contains a non-finite value \(nan\)"),
        (dict(names="axes.x.kp_per_s"), TypeError, r"names must be a sequence of parameter names, got the single name "
                                                   r"'axes.x.kp_per_s': give \('axes.x.kp_per_s',\)"),
        (dict(names=("axes.x.kp_per_s", 3)), TypeError, r"names\[1\] must be a parameter name \(text\), got 3"),
        (dict(names=("axes.x.kp_per_s",) * 2), ValueError, r"names\[1\] 'axes.x.kp_per_s' is varied twice"),
        (dict(strategies=["none"]), TypeError, r"strategies must be a comparison name \(\"ccc_arc\", "),
        (dict(files={}), ValueError, r"files must map the spec's file name to its text, first, then the files it "
                                     r"names; got \{\}"),
        (dict(task_size=0), ValueError, r"task_size must be at least 1, got 0"),
        (dict(log=(True,)), ValueError, r"log must hold one flag per name \(2\), got 1"),
    ):
        with pytest.raises(error, match=words):
            dataclasses.replace(sweep, **change)
    assert dataclasses.replace(sweep, log=()).log == (False, False)  # none on a log scale, as the default
    assert dataclasses.replace(sweep, names=list(sweep.names)).names == sweep.names


def test_run_sweep_of_a_spec_file_name_says_to_read_it_first():
    # run_sweep("spec.toml") was an AttributeError ('str' object has no attribute 'values')
    with pytest.raises(TypeError, match="sweep must be a Sweep \\(read_sweep reads one from its spec\\), got str"):
        run_sweep("spec.toml")


def test_run_variants_takes_a_row_of_values_per_variant_and_says_so_of_a_flat_one(tmp_path):
    """rows = np.array([40.0]), one variant's values given flat, ended in "TypeError: 'numpy.float64' object is not
    iterable", naming no argument; two values for one name ran the first alone (zip cut the second)."""
    from contoursim.sweep import run_variants

    sweep = read_sweep(_spec(tmp_path, [{"name": '"axes.x.kp_per_s"', "values": "[40.0]"}], strategies="none"))
    for rows, shape in ((np.array([40.0]), r"\(1,\)"), ([[40.0, 5.0]], r"\(1, 2\)"), (40.0, r"\(\)")):
        with pytest.raises(ValueError, match=rf"^rows must have shape \(N, 1\), got {shape}: a row per variant, its "
                                             r"values in the order of names \('axes.x.kp_per_s',\)$"):
            run_variants(sweep.files, sweep.names, rows)
    assert run_variants(sweep.files, sweep.names, np.array([[40.0]])) == run_sweep(sweep).tolist()
