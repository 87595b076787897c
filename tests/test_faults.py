"""Fault classes of issue 20, through the command line: bad input ends in one line naming the file, exit 2.

Each test injects one class of fault (the output folder, measured traces, memory, effects and machines
out of range) and checks the whole answer: the exit status, one line on stderr naming the file (and line),
no traceback or foreign warning, nothing written where it must not be.
"""

import dataclasses
import gzip
import io
import os
import re
import subprocess
import sys
import threading
import tracemalloc
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from conftest import ROOT
from contoursim import _memory
from contoursim.cli import main
from contoursim.comparison import compare
from contoursim.compensation import STRATEGY_NAMES, Feedforward
from contoursim.contour import exact_contour_error
from contoursim.diagnosis import diagnose
from contoursim.effects import Effect, Parameter
from contoursim.errormotion import read_error_table
from contoursim.exceptions import ConfigError, PathError, TraceFormatError
from contoursim.feed import plan, sample
from contoursim.fleet import diagnose_fleet, trace_files
from contoursim.gcode import read_gcode
from contoursim.machine import Machine, load_machine, preset_file
from contoursim.model import Model
from contoursim.multibody import Body
from contoursim.output import output_dir
from contoursim.pathfile import library_file, load_path_file
from contoursim.paths import circle, line, polyline, spline
from contoursim.plotting import save_comparison_figures, save_figures
from contoursim.servo import closed_loop
from contoursim.simulation import measured_reference, simulate, simulate_batch
from contoursim.sweep import FIGURES, Sweep, best_and_worst, table_text
from contoursim.traces import Trace, read_trace, write_trace
from contoursim.trajectory import Trajectory
from test_cli import SMALL_PATH


def _refused(capsys, argv, *words):
    """Run the command; it must end with status 2 and one line on stderr holding `words`, and print nothing."""
    assert main(argv) == 2
    captured = capsys.readouterr()
    lines = [line for line in captured.err.splitlines() if not line.startswith(("identify:", "no nominal model"))]
    assert len(lines) == 1 and lines[0].startswith(f"contoursim {argv[0]}: error: "), captured.err
    for word in words:
        assert word in lines[0], lines[0]
    assert "Traceback" not in captured.err and "Warning" not in captured.err
    return lines[0]


def _trace(file, t, ref, actual, head=""):
    rows = "\n".join(f"{a:.9g},{b:.9g},{c:.9g}" for a, b, c in zip(t, ref, actual))
    file.write_text(head + "t,x_ref,x\n" + rows + "\n")
    return file


# -- the output folder ---------------------------------------------------------------------------------------------


def test_output_folder_faults_end_in_one_line_and_change_no_users_file(tmp_path, capsys):
    (tmp_path / "small.toml").write_text(SMALL_PATH)
    notes = tmp_path / "notes.txt"
    notes.write_text("mine\n")
    (tmp_path / "linked").mkdir()
    (tmp_path / "linked" / ".contoursim-out").symlink_to(notes)
    _refused(capsys, ["simulate", str(tmp_path / "small.toml"), "--out", str(tmp_path / "linked")],
             f"{tmp_path / 'linked' / '.contoursim-out'} is a symbolic link")
    (tmp_path / "binary").mkdir()
    (tmp_path / "binary" / ".contoursim-out").write_bytes(b"\xff\xfe")
    _refused(capsys, ["simulate", str(tmp_path / "small.toml"), "--out", str(tmp_path / "binary")],
             f"{tmp_path / 'binary' / '.contoursim-out'} is not contoursim's record")
    (tmp_path / "r.json").mkdir()
    _refused(capsys, ["compare", str(tmp_path / "small.toml"), "--json", str(tmp_path / "r.json"), "--out",
                      str(tmp_path / "out")], f"{tmp_path / 'r.json'} is a directory")
    trace = _trace(tmp_path / "m.csv", np.arange(50) * 1e-3, np.zeros(50), np.zeros(50))
    _refused(capsys, ["diagnose", str(trace), "--report", str(tmp_path / "r.json"), "--out", str(tmp_path / "out")],
             f"{tmp_path / 'r.json'} is a directory")
    (tmp_path / "gone").symlink_to(tmp_path / "unmounted" / "results")  # a link to a share not mounted
    _refused(capsys, ["simulate", str(tmp_path / "small.toml"), "--out", str(tmp_path / "gone")],
             f"{tmp_path / 'gone'} is a symbolic link to {tmp_path / 'unmounted' / 'results'}, which does not exist")
    assert notes.read_text() == "mine\n"
    assert sorted(p.name for p in (tmp_path / "linked").iterdir()) == [".contoursim-out"]
    assert not (tmp_path / "out").exists() and not (tmp_path / "unmounted").exists()


# -- measured traces -----------------------------------------------------------------------------------------------


def test_measured_trace_faults_end_in_one_line_naming_the_file(tmp_path, capsys, monkeypatch):
    t = np.arange(2000) * 1e-3
    x = 10 * np.sin(2 * np.pi * t)
    out = ["--out", str(tmp_path / "out")]
    ms = _trace(tmp_path / "ms.csv", 1e3 * t, x, x)  # logged in ms, read as s: a sample a second
    _refused(capsys, ["diagnose", str(ms), *out], f"{ms}, line 1: column 't': a sample every 1 s")
    swapped = _trace(tmp_path / "swapped.csv", t, x, 10 * np.cos(2 * np.pi * t))
    _refused(capsys, ["diagnose", str(swapped), *out], f"{swapped}, line 1: column 'x': the measured x does not follow x_ref")
    two = _trace(tmp_path / "two.csv", t[:2], x[:2], x[:2])
    _refused(capsys, ["diagnose", str(two), *out], f"{two}: a diagnosis needs at least 3 samples")
    degrees = _trace(tmp_path / "deg.csv", t, x, x, head="# units: t [s]; x_ref, x [deg]\n")
    _refused(capsys, ["diagnose", str(degrees), *out], f"{degrees}, line 1: column 'x_ref' is declared in 'deg'")
    pushed = tmp_path / "pushed.csv"
    pushed.write_text("t,x_ref,x,x_force\n" + "\n".join(f"{a:.3f},{b:.6f},{b:.6f},{'5 N' if k == 7 else 5}"
                                                        for k, (a, b) in enumerate(zip(t, x))) + "\n")
    _refused(capsys, ["diagnose", str(pushed), *out], f"{pushed}, line 9: column 'x_force': '5 N' is not a number")
    # declared seconds that are ms: 2000 s to resample at the demo mill's 0.2 ms, refused before it is made
    monkeypatch.setattr(_memory, "available", lambda: 10**9)
    slow = _trace(tmp_path / "slow.csv", 1e3 * t, x, x, head="# units: t [s]\n")
    _refused(capsys, ["diagnose", str(slow), "--model", "demo_mill", *out],
             f"{slow}: the trace lasts 1999 s: every servo period of 0.0002 s that is 9.995e+06 samples, a run of them needs "
             "about 45 GB of memory and 1 GB are available")  # a diagnosis: 4,500 bytes a sample
    with pytest.raises(ValueError, match="that is 9.995e.06 samples, a run of them needs about 4.5 GB"):
        measured_reference(read_trace(slow), 2e-4)  # one simulated run (450 bytes a sample) in Python, refused before
    assert not (tmp_path / "out").exists()


# -- memory --------------------------------------------------------------------------------------------------------


def test_compare_is_refused_before_it_runs_when_its_runs_would_not_fit(tmp_path, capsys, monkeypatch):
    (tmp_path / "small.toml").write_text(SMALL_PATH)
    machine = load_machine("demo_mill")
    path, settings = load_path_file(tmp_path / "small.toml")
    n = len(sample(path, settings.plan(path, max_feed=machine.max_feed), machine.servo_period))  # the file's run
    monkeypatch.setattr(_memory, "available", lambda: 3 * _memory.RUN_BYTES_PER_SAMPLE * n)  # room for one, not six
    _refused(capsys, ["compare", str(tmp_path / "small.toml"), "--out", str(tmp_path / "out")],
             "small.toml runs for", "6 runs of them needs about", "compare fewer strategies (--strategies)")
    assert not (tmp_path / "out").exists()


def test_the_memory_a_compared_run_is_allowed_covers_it(tmp_path):
    """_memory's figures: a comparison of six strategies with its plots allocates less than the estimate."""
    machine = load_machine("demo_mill")
    path = circle((0, 0), 5.0)
    compare(machine, sample(path, plan(path, 20.0, 1000.0), machine.servo_period), STRATEGY_NAMES)  # numba loaded first
    tracemalloc.start()
    try:
        trajectory = sample(path, plan(path, 1.5, 1000.0), machine.servo_period)
        comparison = compare(machine, trajectory, STRATEGY_NAMES)
        del trajectory
        save_comparison_figures(comparison, output_dir(tmp_path / "out"), "run")
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    samples = len(comparison.runs["none"].trajectory)  # held: the settling the command's check counts too
    assert samples > 100_000
    assert peak < samples * (_memory.RUN_BYTES_PER_SAMPLE + 5 * _memory.COMPARED_RUN_BYTES_PER_SAMPLE), peak / samples


# -- effects, feeds and machines out of range ----------------------------------------------------------------------


MACHINE = """
name = "two axes"
servo_period_ms = 0.5
max_feed_mm_min = 5000

[axes.x]
mass_kg = {mass}
force_constant_N_per_A = 942.0
kv_A_s_per_m = 80.0
ti_s = 0.016
kp_per_s = 40.0

[axes.y]
mass_kg = 300.0
force_constant_N_per_A = 942.0
kv_A_s_per_m = 80.0
ti_s = 0.016
kp_per_s = 40.0
"""


@pytest.mark.parametrize("effects, line, words", [
    ('[[effect]]\nname = "time_delay"\naxis = "x"\nkind = "feedback"\ndelay_s = 0.05\n', 8,
     "time_delay.x: a feedback delay is at most 63 servo periods, 0.0315 s on this machine, got delay_s = 0.05 s"),
    ('[[effect]]\nname = "backlash"\naxis = "x"\nlost_motion_um = 5\n'
     '[[effect]]\nname = "backlash"\naxis = "x"\nlost_motion_um = 8\n', 9,
     "backlash.x is given twice in this file (in [[effect]] tables 1 and 2)"),
])
def test_effects_out_of_range_are_refused_by_file_and_line(tmp_path, capsys, effects, line, words):
    (tmp_path / "m.toml").write_text(MACHINE.format(mass=300.0))
    (tmp_path / "small.toml").write_text(SMALL_PATH)
    (tmp_path / "job.toml").write_text(f'machine = "m.toml"\npath = "small.toml"\n\n{effects}')
    _refused(capsys, ["simulate", str(tmp_path / "job.toml"), "--out", str(tmp_path / "out")],
             f"{tmp_path / 'job.toml'}, line {line}: {words}")


def test_a_feed_over_the_machines_max_names_the_file_and_the_line_of_the_block(tmp_path, capsys):
    """The error named the path's segment 2 (its third primitive), not the program's line 5."""
    (tmp_path / "fast.nc").write_text("G21 G90 G17\nG1 X0 Y0 F600\nG1 X10\nG1 Y10\nG1 X0 F99000\nG1 Y0 F600\nM30\n")
    _refused(capsys, ["simulate", str(tmp_path / "fast.nc"), "--out", str(tmp_path / "out")],
             f"{tmp_path / 'fast.nc'}, line 5: feed 1650 mm/s (99000 mm/min, segment 2) exceeds max_feed = 500 mm/s")
    # a path file's [feed] and a job's that overrides it: their feed_mm_min's line (they named no line)
    (tmp_path / "fast.toml").write_text(SMALL_PATH.replace("feed_mm_min = ", "feed_mm_min = 99000  # ", 1))
    line = SMALL_PATH.splitlines().index(next(x for x in SMALL_PATH.splitlines() if x.startswith("feed_mm_min"))) + 1
    _refused(capsys, ["simulate", str(tmp_path / "fast.toml"), "--out", str(tmp_path / "out")],
             f"{tmp_path / 'fast.toml'}, line {line}: feed 1650 mm/s (99000 mm/min, segment 0) exceeds max_feed")
    (tmp_path / "job.toml").write_text('machine = "demo_mill"\npath = "fast.nc"\n[feed]\nfeed_mm_min = 99000\n')
    _refused(capsys, ["simulate", str(tmp_path / "job.toml"), "--out", str(tmp_path / "out")],
             f"{tmp_path / 'job.toml'}, line 4: feed 1650 mm/s (99000 mm/min, segment 0) exceeds max_feed")


def test_a_loop_made_too_fast_or_unstable_by_one_setting_is_said_at_that_setting(tmp_path, capsys):
    """ti_s = 1 µs was told at servo_period_ms's line to lower kv; a current loop of 1 mHz, to raise kv or lengthen ti."""
    (tmp_path / "small.toml").write_text(SMALL_PATH)
    (tmp_path / "m.toml").write_text(MACHINE.format(mass=300.0).replace("ti_s = 0.016", "ti_s = 1e-6", 1))
    command = ["simulate", str(tmp_path / "small.toml"), "--machine", str(tmp_path / "m.toml"), "--out", str(tmp_path / "out")]
    _refused(capsys, command, f"{tmp_path / 'm.toml'}, line 10: ti_s = 1e-06 s is too short for the velocity loop of "
                              "axis 'x' at dt = 0.0005 s", "Lengthen ti_s, or use dt <= 4.96e-05 s.")
    (tmp_path / "m.toml").write_text(MACHINE.format(mass="300.0\ncurrent_bandwidth_hz = 1e-3"))
    _refused(capsys, command, f"{tmp_path / 'm.toml'}, line 6: the velocity loop of axis 'x' is unstable",
             "the current loop is too slow for it (bandwidth 0.001 Hz, below its crossover 0.7361 Hz): raise "
             "current_bandwidth_hz.")
    assert not (tmp_path / "out").exists()


def test_a_machine_files_axis_no_machine_has_or_a_loop_too_slow_to_settle_is_refused_at_its_line(tmp_path, capsys):
    """[axes.q] on a machine without bodies was reported at [axes.x]'s line, "in that order" (the tables may come in
    any order); kp_per_s = 1e-6 (inside its range) was refused as "a hold of 5e+06 s ... check the duration", naming
    the path file, which holds no hold nor duration: the settle after the path is 5/kp."""
    (tmp_path / "small.toml").write_text(SMALL_PATH)
    command = ["simulate", str(tmp_path / "small.toml"), "--machine", str(tmp_path / "m.toml"), "--out", str(tmp_path / "out")]
    (tmp_path / "m.toml").write_text(MACHINE.format(mass=300.0).replace("[axes.y]", "[axes.q]"))
    _refused(capsys, command, f"{tmp_path / 'm.toml'}, line 13: unknown axis 'q' ([axes.q]): a machine without bodies "
                              "has the axes x, y (, z)")
    (tmp_path / "m.toml").write_text(MACHINE.format(mass=300.0).replace("kp_per_s = 40.0", "kp_per_s = 1e-6", 1))
    _refused(capsys, command, f"{tmp_path / 'm.toml'}, line 11: axis x: kp_per_s = 1e-06 1/s settles in 5/kp = 5e+06 s "
                              "after the path: at the servo period of 0.0005 s", "check kp_per_s")
    assert not (tmp_path / "out").exists()


def test_a_huge_machine_is_refused_in_one_line_without_nan(tmp_path, capsys):
    (tmp_path / "m.toml").write_text(MACHINE.format(mass=1e11))  # a heavy axis: the loop gain never reaches 1
    (tmp_path / "small.toml").write_text(SMALL_PATH)
    message = _refused(capsys, ["simulate", str(tmp_path / "small.toml"), "--machine", str(tmp_path / "m.toml"),
                                "--out", str(tmp_path / "out")],
                       f"{tmp_path / 'm.toml'}, line 6: the velocity loop of axis 'x' is badly damped",
                       "no gain crossover (the loop gain never reaches 1)", "raise kv_A_s_per_m, or check the mass")
    assert "nan" not in message and "inf deg" not in message
    (tmp_path / "m.toml").write_text(MACHINE.format(mass=1e20))  # beyond any machine
    _refused(capsys, ["simulate", str(tmp_path / "small.toml"), "--machine", str(tmp_path / "m.toml"), "--out",
                      str(tmp_path / "out")], f"{tmp_path / 'm.toml'}, line 7: axis x: mass_kg must lie within [1e-12, 1e+12]")
    preset = preset_file("vertical_mill_3axis").read_text()
    table = preset_file("vertical_mill_3axis").parent / "vertical_mill_x_laser.csv"  # the X body's error table, beside it
    (tmp_path / table.name).write_text(table.read_text())
    body = preset.splitlines().index("[[body]]") + 1  # the first [[body]], Y's (1-based)
    for old, new, line, words in (
        ("travel_mm = [0, 400]", "travel_mm = [0, 4e9]", body + 5, "travel_mm must lie within ±1e+06, got 4e+09"),
        ("travel_mm = [0, 400]", "travel_mm = [0, 4e13]", body + 5, "travel_mm: 4e+13 is beyond ±1e+12, not a value a machine has"),
        ("travel_mm = [0, 400]", "travel_mm = [0, 4e5]", body, "its error motion dx reaches 7.992e+06 µm at 400000 mm of "
                                                               "its travel: beyond the small errors a machine's model is "
                                                               "for (0.01 of the travel's length)"),
        ("dx_um = { poly = [0, 0.02, -5e-5] }", "dx_um = { poly = [0, 1e308] }", body + 7, "errors.dx_um: 1e+308 is beyond ±1e+12"),
    ):
        (tmp_path / "big.toml").write_text(preset.replace(old, new, 1))
        _refused(capsys, ["volumetric", str(tmp_path / "big.toml"), "--out", str(tmp_path / "out")],
                 f"{tmp_path / 'big.toml'}, line {line}: body 'Y': {words}")
    # a squareness in mrad, not µrad: blamed on the error motion dy, a 4 µm bow (an outside probe); said by its line
    (tmp_path / "big.toml").write_text(preset.replace("squareness = { y_urad = 25 }", "squareness = { y_urad = 25000 }"))
    line = preset.splitlines().index("squareness = { y_urad = 25 }            # S_XY") + 1
    _refused(capsys, ["volumetric", str(tmp_path / "big.toml"), "--out", str(tmp_path / "out")],
             f"{tmp_path / 'big.toml'}, line {line}: body 'X': its error motion dy reaches 1.25e+04 µm at 500 mm of its "
             "travel (1.25e+04 µm of it from its squareness y_urad = 2.5e+04)", "check the squareness' units")


def test_compare_on_a_move_along_one_axis_has_no_change_relative_to_none(tmp_path, capsys):
    """none's contour error is exactly 0 on a move along one axis (a path file's line: 0, not 1e-12 as on the G-code's):
    a strategy's overshoot at the end is warned of without a ratio to it (it was a ZeroDivisionError)."""
    (tmp_path / "line.nc").write_text("G21 G90 G17\nG1 X0 Y0 F1000\nG1 X20\nG1 X0\nM30\n")
    assert main(["compare", str(tmp_path / "line.nc"), "--strategies", "none,ccc_arc", "--out", str(tmp_path / "out")]) == 0
    captured = capsys.readouterr()
    assert not captured.err
    (tmp_path / "line.toml").write_text('[feed]\nfeed_mm_min = 1000\n[path]\ntype = "polyline"\n'
                                        'points_mm = [[0, 0], [100, 0]]\n')
    assert main(["compare", str(tmp_path / "line.toml"), "--strategies", "none,feedforward",
                 "--out", str(tmp_path / "out2")]) == 0
    said = capsys.readouterr().err
    assert re.search(r"strategy feedforward: its max contour error, 0\.\d+ µm, exceeds that without compensation "
                     r"\(<0\.001 µm\)", said), said
    none = next(line for line in captured.out.splitlines() if line.startswith("none "))
    fields = none.split()  # strategy, 4 errors, peak current, clamped: no margins, and vs none empty
    assert fields[1] in ("<0.001", "0.000") and len(fields) == 7, none
    arc = next(line for line in captured.out.splitlines() if line.startswith("ccc_arc "))
    assert len(arc.split()) == 9  # its loop's PM and ζ, and no change relative to a zero


@pytest.mark.parametrize("key, value, line, words", [
    ("servo_period_ms = 0.5", "servo_period_ms = 1e-300", 3, "servo_period_ms must lie in [0.001, 1000] ms"),
    ("ti_s = 0.016", "ti_s = 1e-300", 10, "axis x: ti_s must lie within [1e-12, 1e+12] (in its SI unit), got 1e-300"),
    ("kv_A_s_per_m = 80.0", "kv_A_s_per_m = 1e-300", 9, "axis x: kv_A_s_per_m must lie within [1e-12, 1e+12]"),
    ("force_constant_N_per_A = 942.0", "force_constant_N_per_A = 1e308", 8, "force_constant_N_per_A must lie within"),
    ("kv_A_s_per_m = 80.0", "kv_A_s_per_m = 1e-9", 6, "no gain crossover (the loop gain never reaches 1)"),
    # a sampled pole e^-500, balanced by 2^371: scipy's matrix_balance warned "invalid value encountered in cast"
    ("kp_per_s = 40.0", "kp_per_s = 40.0\ninductance_H = 1e-6\nresistance_ohm = 1.0\nkc_V_per_A = 1e6\n"
                        "ti_current_s = 1e-6", 6, "the current loop of axis 'x' is unstable at dt = 0.0005 s"),
])
def test_machine_values_far_out_of_range_end_in_one_line_without_a_warning(tmp_path, capsys, key, value, line, words):
    (tmp_path / "m.toml").write_text(MACHINE.format(mass=300.0).replace(key, value, 1))
    (tmp_path / "small.toml").write_text(SMALL_PATH)
    _refused(capsys, ["simulate", str(tmp_path / "small.toml"), "--machine", str(tmp_path / "m.toml"), "--out",
                      str(tmp_path / "out")], f"{tmp_path / 'm.toml'}, line {line}: ", words)


def test_a_machine_built_in_python_takes_the_servo_periods_a_machine_file_takes():
    # Machine(axes, 10.0) and Machine(axes, 1e-9) were built, where a machine file's servo_period_ms of 1e4 or 1e-6
    # is refused
    axes = dict(load_machine("demo_mill").axes)
    for period, shown in ((10.0, "10"), (1e-9, "1e-09")):
        with pytest.raises(ValueError, match=re.escape(f"servo_period must lie in [1e-06, 1] s (servo loops from 1 MHz "
                                                       f"down to 1 Hz), got {shown}")):
            Machine(axes, period)
    assert [Machine(axes, period).servo_period for period in (1e-6, 1.0)] == [1e-6, 1.0]


@pytest.mark.parametrize("n, dt, noise", [(20, 1e-3, 0.0), (50, 0.1, 1e-3), (500, 1e-4, 1e-6)])
def test_a_trace_that_stands_still_is_diagnosed_without_a_numpy_warning(tmp_path, capsys, n, dt, noise):
    t = np.arange(n) * dt
    x = np.full(n, 420.735492)  # rounded as a logger writes it: its mean differs from it in the last bit
    _trace(tmp_path / "still.csv", t, x, x + np.random.default_rng(3).normal(0, noise, n))
    assert main(["diagnose", str(tmp_path / "still.csv"), "--out", str(tmp_path / "out")]) == 0
    err = capsys.readouterr().err
    assert "Warning" not in err and "error" not in err, err


@pytest.mark.parametrize("old, new, words", [
    ("center_mm = [0, 0, 0]", "center_mm = [1e308, 0, 0]", "line 12: bad helix [path]: center_mm holds 1e+308"),  # hung
    ("radius_mm = 20", "radius_mm = 1e-300", "line 13: bad helix [path]: radius_mm = 1e-300 is outside [1e-06, 1e+06]"),
    # in the key's unit at its line (it was the planner's: "feed must lie within [1e-06, 1e+12] (mm/s, ...)", at [feed])
    ("feed_mm_min = 1000", "feed_mm_min = 1e-300", "feed_mm_min must lie within [6e-05, 6e+13], got 1e-300"),
    ("accel_mm_s2 = 1000", "accel_mm_s2 = 1e308", "accel_mm_s2 must lie within [1e-06, 1e+12], got 1e+308"),
])
def test_path_numbers_far_out_of_range_end_in_one_line(tmp_path, capsys, old, new, words):
    helix = (ROOT / "trajectories" / "helix.toml").read_text()
    assert old in helix
    (tmp_path / "h.toml").write_text(helix.replace(old, new, 1))
    _refused(capsys, ["simulate", str(tmp_path / "h.toml"), "--out", str(tmp_path / "out")], f"{tmp_path / 'h.toml'}, ", words)


# -- found by fuzzing the command line (issue 18, item 8) ----------------------------------------------------------


@pytest.mark.parametrize("model", [[], ["--model", "demo_mill"]])
def test_a_trace_over_less_than_a_mm_is_diagnosed_without_a_straightness_over_it(tmp_path, capsys, model):
    """Twenty samples over 0.22 mm of travel: a guideway's bow over less than 1 mm (straightness's shortest span) is
    no candidate; it was the end of the run ('straightness.x: span_mm must lie in [1, 100000] mm')."""
    rows = [f"{k * 1e-3:.3f},{100 + 0.011 * k:.6f},{100 + 0.011 * k - 0.0003:.6f},20,20" for k in range(21)]
    (tmp_path / "short.csv").write_text("t,x_ref,x,y_ref,y\n" + "\n".join(rows) + "\n")
    assert main(["diagnose", str(tmp_path / "short.csv"), *model, "--out", str(tmp_path / "out")]) == 0
    err = capsys.readouterr().err
    assert "error" not in err and "Warning" not in err, err


@pytest.mark.parametrize("name", ["a.json", "fleet.png"])
def test_a_fleet_summary_on_a_file_the_fleet_writes_into_its_folder_is_refused_before_it_runs(tmp_path, capsys, name):
    """The summary replaced trace a's report (out/a.json) after the run said the reports were written to out/."""
    t = np.arange(50) * 1e-3
    traces = [str(_trace(tmp_path / f"{stem}.csv", t, np.zeros(50), np.zeros(50))) for stem in "ab"]
    summary = tmp_path / "out" / name
    _refused(capsys, ["diagnose", *traces, "--summary", str(summary), "--out", str(tmp_path / "out")],
             f"{summary} is a file this run writes into its output directory (--out); name another file")
    assert not (tmp_path / "out").exists()


def test_a_report_is_not_written_when_the_output_folder_is_refused(tmp_path, capsys):
    """The --out folder is checked before the report is written: a run that ends in exit 2 leaves no report."""
    t = np.arange(50) * 1e-3
    trace = _trace(tmp_path / "m.csv", t, np.zeros(50), np.zeros(50))
    (tmp_path / "mine").mkdir()
    (tmp_path / "mine" / "notes.txt").write_text("mine\n")
    assert main(["diagnose", str(trace), "--report", str(tmp_path / "r.json"), "--out", str(tmp_path / "mine")]) == 2
    errors = [line for line in capsys.readouterr().err.splitlines() if ": error: " in line]
    assert errors == [f"contoursim diagnose: error: {tmp_path / 'mine'} holds files that contoursim did not write; "
                      "choose another output directory"]
    assert not (tmp_path / "r.json").exists()
    assert sorted(p.name for p in (tmp_path / "mine").iterdir()) == ["notes.txt"]


def test_a_program_along_z_only_is_plotted_without_a_numpy_warning(tmp_path, capsys):
    """A plunge and retract: nothing moves in XY, the plane the path plots draw (it divided by its zero extent)."""
    (tmp_path / "plunge.nc").write_text("G21 G90\nG0 X0 Y0 Z0\nG1 Z-5 F300\nG1 Z0\nM30\n")
    assert main(["simulate", str(tmp_path / "plunge.nc"), "--out", str(tmp_path / "out")]) == 0
    err = capsys.readouterr().err
    assert "Warning" not in err, err
    assert (tmp_path / "out" / "plunge_path.png").stat().st_size > 0


@pytest.mark.parametrize("start", [0.0, 5e5])
def test_a_trace_stamped_by_a_clock_running_for_days_is_diagnosed(tmp_path, capsys, start):
    """Time stamps since a controller's power-on (5e5 s: six days) step in multiples of their resolution (1e-10 s):
    the reference made from them is at the servo period to that resolution, not to 1e-9 of it (it was refused: 'the
    trajectory is sampled every 0.0002 s but the servo period is 0.0002 s')."""
    t = np.arange(400) * 1e-3
    x = 2.0 * (1.0 - np.cos(np.pi * t / t[-1]))
    trace = _trace(tmp_path / "clock.csv", start + t, x, x, head="# units: t [s]\n")
    assert main(["diagnose", str(trace), "--model", "demo_mill", "--out", str(tmp_path / "out")]) == 0
    out, err = capsys.readouterr()
    assert "error" not in err and "Warning" not in err, err
    spans = next(line for line in out.splitlines() if line.startswith("where (nominal model's residual): the residual"))
    assert "e+05" not in spans and (start == 0 or "5000" in spans), spans  # its times to the ms, not '5e+05–5e+05 s'


def test_the_diagnosis_table_keeps_its_columns_apart_for_a_residual_of_metres(tmp_path, capsys):
    """A known force of 1e8 N pushes the simulated axis metres away: its RMS and max still read as two numbers."""
    t = np.arange(300) * 1e-3
    x = 2.0 * (1.0 - np.cos(np.pi * t / t[-1]))
    rows = "\n".join(f"{a:.3f},{b:.6f},{b:.6f},1e8" for a, b in zip(t, x))
    (tmp_path / "pushed.csv").write_text("t,x_ref,x,x_force\n" + rows + "\n")
    assert main(["diagnose", str(tmp_path / "pushed.csv"), "--model", "demo_mill", "--out", str(tmp_path / "out")]) == 0
    line = next(line for line in capsys.readouterr().out.splitlines() if line.startswith("nominal model "))
    label, rms, largest = line[:27], *line[27:].split()
    assert label.strip() == "nominal model" and 1e6 < float(rms) <= float(largest), line


@pytest.mark.parametrize("command", [["simulate"], ["compare", "--strategies", "none,feedforward"]])
def test_a_path_with_more_coordinates_than_the_machine_has_axes_names_the_path_file(tmp_path, capsys, command):
    (tmp_path / "m.toml").write_text(MACHINE.format(mass=300.0).split("[axes.y]")[0])  # x alone
    (tmp_path / "small.toml").write_text(SMALL_PATH)
    _refused(capsys, [command[0], str(tmp_path / "small.toml"), *command[1:], "--machine", str(tmp_path / "m.toml"),
                      "--out", str(tmp_path / "out")],
             f"{tmp_path / 'small.toml'}: the path moves in 2 coordinates but the machine has only 1 axis (x): it has "
             "y -2 .. 2 [mm], where the machine's coordinates are zero")
    assert not (tmp_path / "out").exists()
    # a constant height on a machine without z: "moves in 3 coordinates", the Z5 it meant not said
    (tmp_path / "xy.toml").write_text(MACHINE.format(mass=300.0))
    (tmp_path / "p.nc").write_text("G0 X0 Y0 Z5\nG1 X10 F1000\n")
    _refused(capsys, [command[0], str(tmp_path / "p.nc"), *command[1:], "--machine", str(tmp_path / "xy.toml"),
                      "--out", str(tmp_path / "out")], "only 2 axes (x, y): it has z 5 .. 5 [mm]")


def test_a_machine_drifting_metres_within_the_run_is_refused(tmp_path, capsys):
    """A thermal drift rate of 1e9 µm/min (a unit slip) moved the tool 26 m within a 2-s run: figures of a model made
    for small errors, printed as a result."""
    text = preset_file("vertical_mill_3axis").read_text().replace(
        "squareness = { x_urad = -30, y_urad = 15 }", "squareness = { x_urad = -30, y_urad = 15 }\nthermal = { dx_um_per_min = 1e9 }")
    (tmp_path / "m.toml").write_text(text)
    (tmp_path / "vertical_mill_x_laser.csv").write_text(preset_file("vertical_mill_3axis").with_name(
        "vertical_mill_x_laser.csv").read_text())
    (tmp_path / "small.toml").write_text(SMALL_PATH)
    for command in (["simulate"], ["compare", "--strategies", "none"]):
        _refused(capsys, [command[0], str(tmp_path / "small.toml"), *command[1:], "--machine", str(tmp_path / "m.toml"),
                          "--out", str(tmp_path / "out")],
                 "the machine's body 'Z': its thermal drift dx reaches", "beyond the small errors")
    assert not (tmp_path / "out").exists()


def test_a_machine_whose_axis_has_no_travel_is_refused_by_volumetric_naming_its_file(tmp_path, capsys):
    text = preset_file("vertical_mill_3axis").read_text().replace("travel_mm = [-300, 0]\n", "")  # Z's travel
    (tmp_path / "m.toml").write_text(text)
    (tmp_path / "vertical_mill_x_laser.csv").write_text(preset_file("vertical_mill_3axis").with_name(
        "vertical_mill_x_laser.csv").read_text())
    _refused(capsys, ["volumetric", str(tmp_path / "m.toml"), "--out", str(tmp_path / "out")],
             f"{tmp_path / 'm.toml'}: axis 'z' has no travel: give its body travel_mm")
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("job, line, words", [
    ('machine = "demo_mil"\npath = "small.toml"\n', 1, "no machine file 'demo_mil' and no preset of that name"),
    ('machine = "demo_mill"\npath = "smal.toml"\n', 2, "no path file 'smal.toml' in the trajectories library"),
    ('machine = "demo_mill"\npath = "small.toml"\ngeometric_compensation = true\n', 3,
     "demo mill (3 servo axes) has no geometric model ([[body]] tables) to compensate with"),
    ('machine = "demo_mill"\npath = ""\n', 2, "path = '' names the folder"),  # the job's own folder: said so, by its line
    ('machine = "."\npath = "small.toml"\n', 1, "machine = '.' names the folder"),
    # a job named job.toml beside the library's paths, running itself: "this is a job file, not a path file"
    ('machine = "demo_mill"\npath = "job"\n', 2, "path = 'job' names this job file itself: a job named as a path it runs "
                                               "hides that path; rename the job file (e.g. job_job.toml)"),
])
@pytest.mark.parametrize("command", [["simulate"], ["compare", "--strategies", "none"]])
def test_a_job_naming_what_is_not_there_is_refused_by_its_line(tmp_path, capsys, job, line, words, command):
    """A misspelt machine or path, a compensation the machine cannot make: the job file's line (they named no file;
    compare said 'the geometric strategy needs a machine with a geometric error model', naming no file)."""
    (tmp_path / "small.toml").write_text(SMALL_PATH)
    (tmp_path / "job.toml").write_text(job)
    _refused(capsys, [command[0], str(tmp_path / "job.toml"), *command[1:], "--out", str(tmp_path / "out")],
             f"{tmp_path / 'job.toml'}, line {line}: {words}")


@pytest.mark.parametrize("key, job", [("machine", 'machine = "mine.toml"\npath = "butterfly"\n'),
                                      ("path", 'machine = "demo_mill"\npath = "small"\n')])
def test_a_job_reads_its_files_beside_it_never_from_the_current_folder(tmp_path, capsys, monkeypatch, key, job):
    """A job in a folder naming a file that lies only in the folder it is run from (an outside probe): it ran that file,
    so the same job ran differently from elsewhere. Refused by its line, saying where a job's files are looked for;
    with the file beside the job, that one runs."""
    (tmp_path / "mine.toml").write_text(preset_file("demo_mill").read_text())
    (tmp_path / "small.toml").write_text(SMALL_PATH)
    (tmp_path / "jobs").mkdir()
    (tmp_path / "jobs" / "job.toml").write_text(job)
    monkeypatch.chdir(tmp_path)
    _refused(capsys, ["simulate", str(Path("jobs") / "job.toml"), "--out", "out"],
             f"{Path('jobs') / 'job.toml'}, line {1 if key == 'machine' else 2}: no ",
             f"(a job's files are looked for beside it, in {tmp_path / 'jobs'})")
    for name in ("mine.toml", "small.toml"):
        (tmp_path / "jobs" / name).write_text((tmp_path / name).read_text())
    assert main(["simulate", str(Path("jobs") / "job.toml"), "--every", "50", "--out", "out"]) == 0


# -- the third pass (issue 18, item 8): files that are not files, the Python API ----------------------------------------


def _pipe(file):
    """A named pipe at `file`, and a function that lets a reader blocked on it go (EOF) if one is."""
    os.mkfifo(file)

    def release():
        try:
            os.close(os.open(file, os.O_WRONLY | os.O_NONBLOCK))  # a writer that closes: the reader sees the end
        except OSError:  # no reader: nothing blocked
            pass
    return release


def _within(seconds, call):
    """`call()`'s outcome ("ok", value) or ("raised", exception); ("blocked", None) if it has not ended in `seconds`."""
    outcome = []

    def run():
        try:
            outcome.append(("ok", call()))
        except Exception as exc:  # noqa: BLE001 -- the test judges it
            outcome.append(("raised", exc))
    worker = threading.Thread(target=run, daemon=True)
    worker.start()
    worker.join(seconds)
    return outcome[0] if outcome else ("blocked", None)


@pytest.mark.parametrize("reader, suffix", [(read_trace, ".csv"), (load_machine, ".toml"), (read_gcode, ".nc"),
                                            (read_error_table, ".csv")],
                         ids=["read_trace", "load_machine", "read_gcode", "read_error_table"])
def test_a_pipe_a_device_a_folder_or_a_packed_file_is_refused_before_it_is_read(tmp_path, reader, suffix):
    """A pipe would block the read until some program writes, /dev/zero would fill the memory: refused by what they are."""
    pipe = tmp_path / f"pipe{suffix}"
    release = _pipe(pipe)
    try:
        kind, value = _within(10, lambda: reader(pipe))
    finally:
        release()
    assert kind == "raised" and isinstance(value, ConfigError), (kind, value)
    assert str(value) == f"{pipe}: cannot read the file: it is a named pipe (FIFO), not a regular file"
    (tmp_path / f"device{suffix}").symlink_to("/dev/null")  # as /dev/zero, without its endless read on the old code
    with pytest.raises(ConfigError, match=rf"device\{suffix}: cannot read the file: it is a device, not a regular file$"):
        reader(tmp_path / f"device{suffix}")
    (tmp_path / f"folder{suffix}").mkdir()
    with pytest.raises(ConfigError, match=rf"folder\{suffix}: cannot read the file: it is a directory, not a regular "
                                          r"file$"):
        reader(tmp_path / f"folder{suffix}")
    (tmp_path / f"packed{suffix}").write_bytes(gzip.compress(b"t,x_ref,x\n0,0,0\n0.001,0,0\n"))
    with pytest.raises(ConfigError, match=rf"packed\{suffix}, line 1: the file is gzip-compressed, not text: unpack it "
                                          r"first$"):
        reader(tmp_path / f"packed{suffix}")


@pytest.mark.parametrize("encoding, words", [
    ("utf-16", "line 1: the file is UTF-16 text (by its byte-order mark): save it as UTF-8"),
    ("utf-16-le", "line 1: byte 0x00 (NUL) is not text (UTF-16 without a byte-order mark, or a binary file?): save the "
                  "file as UTF-8 text"),
])
def test_a_utf16_trace_is_named_so(tmp_path, encoding, words):
    """Excel's 'Unicode text' and Windows loggers write UTF-16: said so, not 'missing column 't' in '\\x00t\\x00,...'."""
    file = tmp_path / "log.csv"
    file.write_bytes("t,x_ref,x\n0,0,0\n0.001,0,0\n".encode(encoding))
    with pytest.raises(TraceFormatError) as info:
        read_trace(file)
    assert str(info.value) == f"{file}, {words}"


def test_the_command_line_refuses_a_pipe_as_input_and_leaves_a_pipe_named_as_report_alone(tmp_path, capsys):
    release = _pipe(tmp_path / "trace.csv")
    try:
        kind, code = _within(60, lambda: main(["diagnose", str(tmp_path / "trace.csv"), "--model", "demo_mill", "--out",
                                               str(tmp_path / "out")]))
    finally:
        release()
    assert (kind, code) == ("ok", 2)
    err = capsys.readouterr().err
    assert err == f"contoursim diagnose: error: {tmp_path / 'trace.csv'}: cannot read the file: it is a named pipe (FIFO), " \
                  "not a regular file\n"
    (tmp_path / "small.toml").write_text(SMALL_PATH)
    release = _pipe(tmp_path / "r.json")
    try:
        kind, code = _within(60, lambda: main(["compare", str(tmp_path / "small.toml"), "--strategies", "none", "--out",
                                               str(tmp_path / "out"), "--json", str(tmp_path / "r.json")]))
    finally:
        release()
    assert (kind, code) == ("ok", 2)
    assert "r.json exists and is not a comparison JSON; refusing to overwrite it" in capsys.readouterr().err
    assert (tmp_path / "r.json").is_fifo()


def test_a_fleets_trace_that_is_a_pipe_or_a_folder_is_that_traces_failure_named(tmp_path):
    release = _pipe(tmp_path / "b.csv")
    (tmp_path / "c.csv").mkdir()
    (tmp_path / "d.csv").write_bytes(gzip.compress(b"t,x_ref,x\n"))
    try:
        kind, outcomes = _within(30, lambda: diagnose_fleet([tmp_path / "b.csv", tmp_path / "c.csv", tmp_path / "d.csv"]))
    finally:
        release()
    assert kind == "ok", (kind, outcomes)
    assert [o["error"] for o in outcomes] == [
        "b.csv: cannot read the file: it is a named pipe (FIFO), not a regular file",
        "c.csv: cannot read the file: it is a directory, not a regular file",
        "d.csv, line 1: the file is gzip-compressed, not text: unpack it first"]


def _trajectory_with(trajectory, **arrays):
    """A Trajectory of `trajectory`'s arrays (copies: writeable, as a user's), some replaced by `arrays`."""
    keys = ("t", "position", "velocity", "acceleration", "s", "measuring")
    given = {k: np.array(getattr(trajectory, k)) for k in keys} | arrays
    return Trajectory(**given)


@pytest.mark.parametrize("kind", ["Trajectory", "Trace"])
def test_the_callers_arrays_stay_as_they_were_and_the_objects_arrays_do_not_change_with_them(api, kind):
    """Trajectory(t, position, ...) made the caller's own arrays read-only (a user's next ``position[0] = ...`` raised
    'assignment destination is read-only'); the object keeps read-only arrays of its own."""
    if kind == "Trajectory":
        arrays = {k: np.array(getattr(api.trajectory, k)) for k in ("t", "position", "velocity", "acceleration", "s",
                                                                    "measuring")}
        made = Trajectory(**arrays)
        kept = {k: getattr(made, k) for k in arrays}
    else:
        arrays = {"t": np.array(api.trace.t), "reference": np.array(api.trace.reference),
                  "actual": np.array(api.trace.actual), "force": np.linspace(0.0, 1.0, len(api.trace.t))}
        made = Trace(arrays["t"], arrays["reference"], arrays["actual"], ("x", "y"), force={"x": arrays["force"]})
        kept = {"t": made.t, "reference": made.reference, "actual": made.actual, "force": made.force["x"]}
    for name, array in arrays.items():
        assert array.flags.writeable and not kept[name].flags.writeable, name
        before = kept[name].copy()
        array[...] = array[::-1]
        np.testing.assert_array_equal(kept[name], before)


@pytest.fixture(scope="module")
def api():
    """What a researcher holds in the API tour: the demo mill, a sampled circle, a trace of it."""
    machine = load_machine("demo_mill")
    path = circle((0, 0), 2.0)
    profile = plan(path, 10.0, 500.0)
    trajectory = sample(path, profile, machine.servo_period)
    t = np.arange(50) * 1e-3
    ref = np.column_stack([np.sin(t), np.cos(t)])
    trace = Trace(t, ref, ref + 1e-4, ("x", "y"))
    return SimpleNamespace(machine=machine, path=path, profile=profile, trajectory=trajectory, trace=trace)


@pytest.mark.parametrize("call, error, words", [
    (lambda a: read_trace(3), TypeError, "expected a file name (str or Path), got int"),
    (lambda a: load_machine(None), TypeError, "a machine is a preset name or a machine file (str or Path), got NoneType"),
    (lambda a: plan([[0, 0], [1, 1]], 10.0, 500.0), TypeError, "path must be a contoursim.paths.Path"),
    (lambda a: sample([[0, 0], [1, 1]], a.profile, 1e-3), TypeError, "path must be a contoursim.paths.Path"),
    (lambda a: sample(a.path, 10.0, 1e-3), TypeError, "profile must be a FeedProfile (from plan), got float"),
    (lambda a: Trajectory(*(getattr(a.trajectory, k) for k in ("t", "position", "velocity", "acceleration", "s")),
                          path="circle"), TypeError, "path must be a contoursim.paths.Path or None, got str"),
    (lambda a: diagnose("trace.csv", a.machine), TypeError, "trace must be a Trace (contoursim.read_trace reads one"),
    (lambda a: diagnose(a.trace, a.machine, max_effects=-1), ValueError, "max_effects must be zero or more, got -1"),
    (lambda a: diagnose(a.trace, a.machine, max_effects=1.5), TypeError, "max_effects must be a whole number, got 1.5"),
    (lambda a: Model(a.machine, Effect("backlash", "x", lost_motion_um=5.0)), TypeError,
     "give (Effect('backlash', 'x', lost_motion_um=5.0, feedback=None, approach='none'),), not the effect alone"),
    (lambda a: Model(a.machine, (Effect("backlash", "x", lost_motion_um=5.0),)).with_values([("backlash.x.lost_motion_um", 3)]),
     TypeError, "values must be a mapping of flat parameter names to values, got list"),
    # a dict of one variant: "values must be a mapping ..., got str", a mapping given
    (lambda a: Model(a.machine, (Effect("backlash", "x", lost_motion_um=5.0),)).variants({"backlash.x.lost_motion_um": 3}),
     TypeError, "rows must be a sequence of mappings of flat parameter names to values, e.g. "),
    # read as '.': ".: cannot read the file: it is a directory", ". holds files that contoursim did not write"
    (lambda a: load_machine(""), ConfigError, "the machine's name is empty: name a preset (aircraft_drilling_7axis"),
    (lambda a: output_dir(""), ConfigError, "the output folder's name is empty: contoursim writes its plots"),
    (lambda a: Trace(a.trace.t, a.trace.reference, a.trace.actual, 2), TypeError,
     "axes must be a sequence of axis names like ('x', 'y'), got 2"),
    (lambda a: Trace(a.trace.t, a.trace.reference, a.trace.actual, ("x", "y"), force=np.ones(50)), TypeError,
     "force must map axis names to arrays ({'x': ...}), got ndarray"),
    (lambda a: simulate(a.machine, a.trajectory, force=np.ones(len(a.trajectory))), TypeError,
     "force must map servo axis names to arrays ({'x': ...}), got ndarray"),
    (lambda a: simulate(a.machine, a.trajectory, force={"x": np.full(len(a.trajectory), 1e15)}), ValueError,
     "force['x'] holds 1e+15 at index 0, beyond ±1e+09"),
    (lambda a: simulate(a.machine, a.trajectory, settle=-1.0), ValueError, "settle must be zero or positive, got -1.0"),
    (lambda a: simulate(a.machine, a.trajectory, settle=1e7), ValueError,
     "settle = 1e+07 s: at the servo period of 0.0002 s that is 5e+10 samples, a run of them needs about"),
    (lambda a: write_trace(io.StringIO(), a.trace, extra={"a,b": np.ones(50)}), ValueError,
     "extra column 'a,b' is not a CSV column name"),
    (lambda a: write_trace(io.StringIO(), Trace(a.trace.t, a.trace.reference, a.trace.actual, ("x", "y"),
                                                 {"note": "one\nt,x_ref,x"})), ValueError,
     "metadata 'note': 'one\\nt,x_ref,x' is not one '# key: value' line"),
    (lambda a: compare(a.machine, a.trajectory, names="none,ccc_arc"), TypeError,
     "names must be a sequence of strategy names, e.g. ('none', 'ccc_arc'), got the string 'none,ccc_arc'"),
    (lambda a: compare(a.machine, a.trajectory, names=("ccc_arc",), settings=[1]), TypeError,
     "settings must map strategy names to their settings, got list"),
    (lambda a: compare(a.machine, a.trajectory, names=("none", "feedforward"), settings={"ccc_arc": {"kp_per_s": 9.0}}),
     ValueError, "settings of 'ccc_arc', which none of the strategies none, feedforward has: run it, or drop"),
    (lambda a: save_figures([a.trace], io.StringIO(), "x"), TypeError, "runs must map run names to SimResults"),
    (lambda a: save_figures({}, io.StringIO(), "x"), ValueError, "runs is empty: save_figures draws at least one run"),
    (lambda a: output_dir(None), TypeError, "the output folder is a folder name (str or Path), got NoneType"),
    (lambda a: load_path_file(3), TypeError, "a path file is a file or library name (str or Path), got int"),
    (lambda a: write_trace(io.StringIO(), a.trajectory), TypeError, "trace must be a Trace (read_trace reads one"),
    (lambda a: simulate(a.machine, a.trajectory, Feedforward()), TypeError,
     "strategies must be a sequence of compensation Strategy objects, e.g. (Feedforward(),)"),
    (lambda a: simulate_batch([a.machine], a.trajectory, strategies=Feedforward()), TypeError,
     "strategies must be a sequence of compensation Strategy objects, e.g. (Feedforward(),)"),
    (lambda a: Trace(a.trace.t, a.trace.reference, a.trace.actual, ("x", "y"), metadata=["mill 3"]), TypeError,
     "metadata must map keys to values ({'machine': 'mill 3'}), got list"),
    (lambda a: _trajectory_with(a.trajectory, measuring=np.where(np.arange(len(a.trajectory)) == 3, np.nan, 1.0)),
     ValueError, "measuring must be booleans (or 0 and 1), got nan at index 3"),
    (lambda a: _trajectory_with(a.trajectory, measuring=np.arange(len(a.trajectory)) % 3), ValueError,
     "measuring must be booleans (or 0 and 1), got 2 at index 2"),
    (lambda a: _trajectory_with(a.trajectory, measuring=["no"] * len(a.trajectory)), TypeError,
     "measuring must be booleans (or 0 and 1), got <U2 values"),
    # an outside probe's API pass: a list of servos, one model for a batch, no trajectory, a 3-D start with a 2-D end
    (lambda a: Machine([a.machine.axes["x"]] * 2, 2e-4), TypeError,
     "axes must be a mapping of axis name -> AxisServo ({'x': servo, ...}), got list"),
    (lambda a: simulate_batch(a.machine, a.trajectory), TypeError, "models must be a list of models or machines (one "
                                                                   "per variant), got a Machine: give [model] for one"),
    (lambda a: exact_contour_error(None, np.zeros((10, 2))), TypeError, "trajectory must be a Trajectory"),
    (lambda a: line((0, 0, 5), (1, 1)), PathError, "start has 3 coordinates and end 2"),
    # samples off their own path or beyond any machine: the contour error exceeded the tracking error, 3.7 mm
    (lambda a: Trajectory(a.trajectory.t, a.trajectory.position + [1.0, 0.0], a.trajectory.velocity,
                          a.trajectory.acceleration, a.trajectory.s, a.trajectory.path), ValueError,
     "position[0] lies 1 mm from its path at its s = 0 mm"),
    (lambda a: Trajectory(a.trajectory.t, a.trajectory.position, a.trajectory.velocity, a.trajectory.acceleration,
                          a.trajectory.s[::-1], a.trajectory.path), ValueError, "from its path at its s = "),
    (lambda a: Trajectory(a.trajectory.t, a.trajectory.position + 1e12, a.trajectory.velocity,
                          a.trajectory.acceleration, a.trajectory.s), ValueError, "position"),
])
def test_the_api_refuses_what_it_cannot_use_naming_the_argument(api, call, error, words):
    """Wrong types, a bare effect, a settle of years, a column name with a comma: the argument named, not numpy's error."""
    with pytest.raises(error) as info:
        call(api)
    assert words in str(info.value)


def test_results_and_machines_pickle_and_copy_and_a_result_cannot_be_written_into(api):
    """An outside probe's API pass: Machine, Model, Effect and SimResult did not pickle nor deep-copy ('cannot pickle
    mappingproxy'), == on a Trajectory raised numpy's 'truth value ... ambiguous', and a write into a result's
    static_tool_position or axis_command changed what summary() said (0 -> 707 µm volumetric)."""
    import copy
    import pickle

    mill = load_machine("vertical_mill_3axis")
    model = Model(api.machine, (Effect("backlash", "x", lost_motion_um=8.0),))
    result = simulate(model, api.trajectory)
    for thing in (mill, model, model.effects[0], result):
        for again in (pickle.loads(pickle.dumps(thing)), copy.deepcopy(thing)):
            assert type(again) is type(thing)
    assert pickle.loads(pickle.dumps(model)) == model and hash(pickle.loads(pickle.dumps(model))) == hash(model)
    assert pickle.loads(pickle.dumps(result)).summary() == result.summary()
    assert api.trajectory == api.trajectory and api.trajectory != _trajectory_with(api.trajectory)  # as objects
    before = result.summary()
    for name in ("axis_command", "static_tool_position", "tool_position"):
        with pytest.raises(ValueError, match="read-only"):
            getattr(result, name)[:] += 0.5
    assert result.summary() == before


# -- faults4: wrong TOML types, '-' for a file, flags given text, numbers too large, strategy keys -----------------


@pytest.mark.parametrize("preset, old, new, line, words", [
    ("demo_mill", 'name = "demo mill (3 servo axes)"', "name = 3", 9, "name must be text in quotes, got 3"),
    ("demo_mill", "servo_period_ms = 0.2", "description = true\nservo_period_ms = 0.2", 10,
     "description must be text in quotes, got True"),
    ("table_tilting_5axis", 'name = "5-axis table-tilting A/C"', "name = 3.5", 13, "name must be text in quotes, got 3.5"),
    ("table_tilting_5axis", 'tool = "tool"', "tool = 1", 15, "tool must be a body's name in quotes, got 1"),
    ("table_tilting_5axis", 'name = "X"', 'name = ["X"]', 51, "name in the 1st [[body]] must be text in quotes, got ['X']"),
    ("table_tilting_5axis", 'parent = "X"', "parent = 1", 65, "parent in the 2nd [[body]] must be a body's name in quotes, got 1"),
    ("table_tilting_5axis", 'axis = "x"', "axis = 0", 54, "axis in the 1st [[body]] must be an axis name in quotes, got 0"),
    ("table_tilting_5axis", 'joint = "linear x"', "joint = 1", 53, "joint in the 1st [[body]] must be a joint in quotes, got 1"),
    ("demo_mill", None, '[[effect]]\nname = 3\naxis = "x"', 38, "name in the 1st [[effect]] must be an effect's name in quotes, got 3"),
    ("demo_mill", None, '[[effect]]\nname = "backlash"\naxis = 1', 39, "axis in the 1st [[effect]] must be axis letters in quotes, got 1"),
])
def test_a_number_where_a_machine_file_wants_text_is_refused_naming_its_line_and_key(tmp_path, preset, old, new, line,
                                                                                   words):
    """TOML reads ``name = 3`` as a number: a machine's name, a body's, an effect's axis are text, said where."""
    from contoursim.model import load_model

    text = preset_file(preset).read_text()
    assert old is None or old in text
    (tmp_path / "m.toml").write_text(text + "\n" + new if old is None else text.replace(old, new, 1))
    with pytest.raises(ConfigError) as info:
        load_model(tmp_path / "m.toml")
    assert str(info.value) == f"{tmp_path / 'm.toml'}, line {line}: {words}"


def test_a_number_where_a_path_file_wants_text_is_refused_naming_its_line(tmp_path, capsys):
    (tmp_path / "p.toml").write_text("description = 4\n" + SMALL_PATH)
    _refused(capsys, ["simulate", str(tmp_path / "p.toml"), "--out", str(tmp_path / "out")],
             f"{tmp_path / 'p.toml'}, line 1: description must be text in quotes, got 4")
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("argv, words", [
    (["simulate", "{path}", "--out", "-"], "argument --out: contoursim writes its plots and files into a folder, not to "
                                            "standard output ('-'): name one, e.g. --out results"),
    (["compare", "{path}", "--json", "-"], "argument --json: contoursim writes the comparison JSON to a file, not to"),
    (["diagnose", "{path}", "--report", " -"], "argument --report: contoursim writes the diagnosis report to a file"),
    (["diagnose", "{path}", "{path}", "--summary", "-"], "argument --summary: contoursim writes the fleet summary"),
])
def test_a_dash_for_where_contoursim_writes_is_refused_not_made_a_folder_or_file(tmp_path, monkeypatch, capsys, argv,
                                                                                  words):
    """``--out -`` made a folder named '-' (a command-line user means standard output), ``--json -`` a file '-'."""
    (tmp_path / "small.toml").write_text(SMALL_PATH)
    monkeypatch.chdir(tmp_path)
    with pytest.raises(SystemExit) as info:  # argparse's refusal of the option itself
        main([arg.format(path="small.toml") for arg in argv])
    assert info.value.code == 2
    assert words in capsys.readouterr().err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["small.toml"]


@pytest.mark.parametrize("name, words", [
    ("", "the path file's name is empty: name a path file or a library path"),  # ".: unknown path file type ''"
    ("sub", "sub is a folder, not a path file"),  # "sub: unknown path file type ''"
    ("butterfly", None),  # a folder of a library path's name does not hide it
])
def test_an_empty_or_folder_path_argument_is_said_so(tmp_path, monkeypatch, capsys, name, words):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "sub").mkdir()
    (tmp_path / "butterfly").mkdir()
    if words is None:
        assert library_file(name).name == "butterfly.toml"
        return
    _refused(capsys, ["simulate", name, "--out", str(tmp_path / "out")], words)


@pytest.mark.parametrize("call, words", [
    (lambda a: simulate(a.machine, a.trajectory).summary(measuring_only="no"), "measuring_only must be True or False, got 'no'"),
    (lambda a: simulate(a.machine, a.trajectory, contour="no"), "contour must be True or False, got 'no'"),
    (lambda a: write_trace(a.mine, a.trace, overwrite="no"), "overwrite must be True or False, got 'no'"),
    (lambda a: write_trace(a.mine, a.trace, overwrite=1), "overwrite must be True or False, got 1"),
    (lambda a: load_machine("demo_mill", geometry="no"), "geometry must be True or False, got 'no'"),
    (lambda a: load_machine("demo_mill", check=None), "check must be True or False, got None"),
    (lambda a: spline([[0, 0], [1, 1], [2, 0]], closed="no"), "closed must be True or False, got 'no'"),
    (lambda a: closed_loop(a.machine.axes["x"], feedforward="no"), "feedforward must be True or False, got 'no'"),
    (lambda a: Parameter("p", 1.0, "um", vary="no"), "p: vary must be True or False, got 'no'"),
    (lambda a: compare(a.machine, a.trajectory, names=("none",), tuned="yes"),
     "tuned must be True, False or a mapping of strategy names to tuned settings, got 'yes'"),
    (lambda a: load_machine("vertical_mill_3axis").chain.tool_pose(np.zeros((1, 3)), ideal="no"),
     "ideal must be True or False, got 'no'"),
])
def test_a_flag_given_text_or_a_number_is_refused_naming_it(api, tmp_path, call, words):
    """``summary(measuring_only="no")`` was read as true, ``write_trace(..., overwrite="no")`` replaced the user's file."""
    mine = tmp_path / "mine.csv"
    mine.write_text("mine\n")
    with pytest.raises(TypeError) as info:
        call(SimpleNamespace(**vars(api), mine=mine))
    assert str(info.value) == words
    assert mine.read_text() == "mine\n"


@pytest.mark.parametrize("cell, words", [
    ("9" * 5000, "line 4: column 'x_ref': value 999999999999… (5000 characters) is beyond ±1e+06 mm"),
    ("-1e400", "line 4: column 'x_ref': value -1e400 is beyond ±1e+06 mm"),
    ("inf", "line 4: column 'x_ref': value inf is not finite"),
])
def test_a_trace_cell_too_large_for_a_float_is_said_to_be_so_not_infinite(tmp_path, cell, words):
    """A cell of 5000 digits was read as inf and said to be "not finite": it is a number beyond the trace's range."""
    t = np.arange(50) * 1e-3
    lines = _trace(tmp_path / "m.csv", t, np.sin(t), np.sin(t)).read_text().splitlines()
    lines[3] = f"{t[2]:.9g},{cell},{np.sin(t[2]):.9g}"
    (tmp_path / "m.csv").write_text("\n".join(lines) + "\n")
    with pytest.raises(TraceFormatError) as info:
        read_trace(tmp_path / "m.csv")
    assert str(info.value).startswith(f"{tmp_path / 'm.csv'}, {words}")


@pytest.mark.parametrize("value, words", [
    ("1e400", "line 11: axes.x.kp_per_s = 1e400 is too large a number: beyond ±1.798e+308"),
    ("1" + "0" * 400, "line 11: axes.x.kp_per_s = 100000000000… (401 characters) is too large a number"),
    ("1" + "0" * 5000, "line 11: a whole number of more than 4300 digits is too large a number"),
    ("[1, -1e999]", "line 11: axes.x.kp_per_s[1] = -1e999 is too large a number"),
])
def test_a_toml_number_too_large_for_a_float_is_refused_by_its_line(tmp_path, capsys, value, words):
    """TOML reads 1e400 as inf ("must be finite, got inf"); a whole number of 400 digits ended in an OverflowError."""
    text = MACHINE.format(mass=300.0).replace("kp_per_s = 40.0", f"kp_per_s = {value}", 1)
    (tmp_path / "m.toml").write_text(text)
    (tmp_path / "small.toml").write_text(SMALL_PATH)
    _refused(capsys, ["simulate", str(tmp_path / "small.toml"), "--machine", str(tmp_path / "m.toml"), "--out",
                      str(tmp_path / "out")], f"{tmp_path / 'm.toml'}, {words}")


def test_other_numbers_too_large_for_a_float_are_refused_naming_them(tmp_path, capsys):
    from contoursim import _validate

    (tmp_path / "small.toml").write_text(SMALL_PATH)
    _refused(capsys, ["compare", str(tmp_path / "small.toml"), "--strategies", "none,ccc_arc", "--set",
                      "ccc_arc.kp_per_s=1e400", "--out", str(tmp_path / "out")],
             "--set ccc_arc.kp_per_s=1e400: too large a number, beyond ±1.798e+308")
    (tmp_path / "x.csv").write_text("position_mm,dx_um\n0,0\n50,1e400\n100,1\n")
    with pytest.raises(ConfigError, match=r"x.csv, line 3: column 'dx_um': 1e400 is too large a number"):
        read_error_table(tmp_path / "x.csv")
    with pytest.raises(ValueError, match=r"kp must be finite, got 100000000000… \(401 characters\): beyond"):
        _validate.positive("kp", 10**400)
    with pytest.raises(ValueError, match="position holds a number beyond"):
        _validate.finite_array("position", [1.0, 10**400])


def test_strategy_settings_have_one_set_of_keys_in_the_api_the_files_and_the_json(api):
    """compare(settings=...) took {"ccc_arc": {"kp": ...}} where the job file, --set and the JSON say kp_per_s."""
    from contoursim.compensation import strategies_named

    comparison = compare(api.machine, api.trajectory, names=("ccc_arc",), settings={"ccc_arc": {"kp_per_s": 30.0}})
    assert comparison.settings["ccc_arc"]["ccc_arc"]["kp_per_s"] == 30.0
    assert comparison.gains["ccc_arc"] == "kp_per_s set, ki_per_s2 designed"
    assert strategies_named("ccc_arc", settings={"ccc_arc": {"kp_per_s": 30.0, "ki_per_s2": 0.0}})[0].kp == 30.0
    for settings, words in [
        ({"ccc_arc": {"kp": 30.0}}, "unknown setting 'kp' of ccc_arc; expected one of kp_per_s, ki_per_s2, kd"),
        ({"ccc_arcc": {"kp_per_s": 30.0}}, "no settings for strategy 'ccc_arcc': strategies with settings are feedforward"),
        ({"ccc_arc": {"kp_per_s": -3.0}}, "kp_per_s must be"),
        ({"ccc_arc": {"kp_per_s": "30"}}, "kp_per_s must be a number, got '30'"),
    ]:
        with pytest.raises(ValueError) as info:
            compare(api.machine, api.trajectory, names=("none", "ccc_arc"), settings=settings)
        assert str(info.value).startswith(words), str(info.value)
    with pytest.raises(ValueError, match="tuning sets the coupling's kp_per_s and ki_per_s2: ccc_arc.ki_per_s2 is set"):
        compare(api.machine, api.trajectory, names=("ccc_arc",), settings={"ccc_arc": {"ki_per_s2": 3.0}}, tuned=True)


def test_a_batchs_every_is_a_whole_number(api):
    """simulate_batch took every = "2" and every = 2.5 (as 2) where its other counts are checked."""
    for every, error in (("2", TypeError), (2.5, TypeError), (0, ValueError)):
        with pytest.raises(error, match="every must be"):
            simulate_batch([api.machine], api.trajectory, every=every)


def test_where_a_run_writes_is_refused_before_anything_is_written(tmp_path, monkeypatch, capsys):
    """--out '' named the working folder ('. holds files ...'); --json naming --out's folder failed after the plots."""
    (tmp_path / "small.toml").write_text(SMALL_PATH)
    monkeypatch.chdir(tmp_path)
    with pytest.raises(SystemExit):
        main(["simulate", str(tmp_path / "small.toml"), "--out", " "])
    assert "argument --out: names nothing; contoursim writes its plots and files into a folder" in capsys.readouterr().err
    _refused(capsys, ["compare", str(tmp_path / "small.toml"), "--strategies", "none", "--json", str(tmp_path / "o"),
                      "--out", str(tmp_path / "o")], f"{tmp_path / 'o'} is the output directory (--out); name a file")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["small.toml"]


@pytest.mark.parametrize("command, option", [("compare", "--json"), ("diagnose", "--report"), ("fleet", "--summary")])
def test_a_report_into_a_folder_that_does_not_exist_is_refused_before_the_run(tmp_path, capsys, command, option):
    """compare --json nodir/r.json ran every strategy and wrote its plots, then ended in 'cannot write nodir/r.json'
    (a fleet's summary after every trace's diagnosis); a report in --out, which the run makes, is written there."""
    (tmp_path / "small.toml").write_text(SMALL_PATH)
    t = np.arange(400) * 1e-3
    for name in ("a.csv", "b.csv"):
        _trace(tmp_path / name, t, np.sin(t), np.sin(t) + 1e-4)
    inputs = {"compare": [str(tmp_path / "small.toml"), "--strategies", "none"], "diagnose": [str(tmp_path / "a.csv")],
              "fleet": [str(tmp_path / "a.csv"), str(tmp_path / "b.csv")]}[command]
    argv = ["compare" if command == "compare" else "diagnose", *inputs, "--out", str(tmp_path / "out")]
    _refused(capsys, [*argv, option, str(tmp_path / "nodir" / "r.json")],
             f"{tmp_path / 'nodir' / 'r.json'}: there is no folder {tmp_path / 'nodir'} to write the")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.csv", "b.csv", "small.toml"]
    if command == "compare":
        assert main([*argv, option, str(tmp_path / "out" / "r.json")]) == 0
        assert (tmp_path / "out" / "r.json").is_file()


def test_a_negative_dwell_is_refused_by_its_line(tmp_path, capsys):
    (tmp_path / "p.nc").write_text("G21 G90\nG0 X0 Y0\nG1 X10 F600\nG4 P-1\nG1 Y10\nM30\n")
    _refused(capsys, ["simulate", str(tmp_path / "p.nc"), "--out", str(tmp_path / "out")],
             f"{tmp_path / 'p.nc'}, line 4: a dwell's time (G4 P or X) must be zero or positive, got -1")


def test_a_sweep_whose_variants_are_all_unstable_says_why_in_the_specs_names(tmp_path, capsys):
    (tmp_path / "s.toml").write_text(SMALL_PATH)
    (tmp_path / "w.toml").write_text('machine = "demo_mill"\npath = "s.toml"\n[sweep]\nmethod = "grid"\n[[vary]]\n'
                                     'name = "axes.x.kp_per_s"\nvalues = [3000, 5000]\n')
    assert main(["sweep", str(tmp_path / "w.toml"), "--out", str(tmp_path / "out")]) == 0
    out = capsys.readouterr().out
    assert "2 of 2 variants diverged or were refused by a loop check" in out
    assert "(kp_per_s = 3000): the velocity loop is too slow for it" in out and "lower kp_per_s, to " in out
    assert f"table, plots written to {tmp_path / 'out'}/" in out  # no best and worst run said written: there is none
    rows = (tmp_path / "out" / "sweep.csv").read_text().splitlines()[1:]
    assert [row.split(",")[-3] for row in rows] == ["True", "True"] and all("nan,nan" in row for row in rows)


@pytest.mark.parametrize("call, error, words", [
    (lambda a: compare(a.machine, a.trajectory, names=["none", 3]), TypeError,
     "a strategy name is text such as 'ccc_arc' or 'feedforward+ccc_arc', got 3"),  # an AttributeError from inside
    (lambda a: simulate_batch([a.machine], a.trajectory, outputs="summary"), TypeError,
     "outputs must be a sequence of output names, e.g. ('summary',), got the string 'summary'"),  # its letters, refused
])
def test_a_name_where_names_are_wanted_and_a_number_where_a_name_is_are_refused(api, call, error, words):
    with pytest.raises(error) as info:
        call(api)
    assert str(info.value) == words


def test_a_count_given_as_a_fraction_or_text_is_refused_not_truncated(api):
    """volumetric_grid(points=2.9) ran 2 points, exact_contour_error(window="8") 8, inverse(max_iter=2.5) 2: a count is a
    whole number."""
    from contoursim.contour import exact_contour_error
    from contoursim.volumetric import volumetric_grid, volumetric_report

    chain = load_machine("polishing_platform_4axis").chain
    for call, words in [
        (lambda: volumetric_grid(chain, points=2.9), "points must be a whole number, got 2.9"),
        (lambda: volumetric_report("polishing_platform_4axis", grid=3, rotary_grid=2.5), "rotary_grid must be a whole number"),
        (lambda: exact_contour_error(api.trajectory, api.trajectory.position, window="8"), "window must be a whole number"),
        (lambda: chain.inverse(np.zeros((1, 3)), max_iter=2.5), "max_iter must be a whole number, got 2.5"),
    ]:
        with pytest.raises(TypeError, match=words):
            call()


def test_a_second_units_line_is_refused_not_one_of_them_ignored(tmp_path):
    """Two '# units:' lines: the second was honoured and the first ignored (positions in mm read as µm, silently)."""
    t = np.arange(50) * 1e-3
    trace = _trace(tmp_path / "m.csv", t, np.sin(t), np.sin(t), head="# units: t [s]; x_ref, x [mm]\n# units: x_ref, x [um]\n")
    with pytest.raises(TraceFormatError) as info:
        read_trace(trace)
    assert str(info.value) == f"{trace}, line 2: a second '# units:' line (the first is line 1): declare the units once"


@pytest.mark.parametrize("dtype", [np.float16, "float16", np.int32, int, object, np.complex128, "no such type"])
def test_a_batchs_results_are_kept_in_float64_or_float32_only(api, dtype):
    """dtype = float16 returned positions to 0.49 µm on a 2 mm circle (0.25 mm at 500 mm), int32 to whole millimetres,
    object and complex as they came: each a wrong answer without a word, where run_batch refused them."""
    with pytest.raises(ValueError, match="dtype must be float64 or float32, got"):
        simulate_batch([api.machine], api.trajectory, dtype=dtype)


@pytest.mark.parametrize("cast", [lambda a: a.astype(np.float16), lambda a: a.astype(np.float32), lambda a: a.astype(int),
                                  lambda a: a.astype(object), lambda a: a.tolist()])
def test_references_and_parameters_of_any_numeric_type_run_in_float64(api, cast):
    """A reference, a force and parameters given as float16, float32, int, object arrays or lists run in float64: the
    same positions, bit for bit, as the same values turned into float64 first (float16 arithmetic would differ)."""
    exact = lambda a: np.asarray(cast(np.asarray(a)), dtype=float)  # noqa: E731
    one = lambda value: cast(np.array([value]))[0]  # noqa: E731
    trajectory, machine = api.trajectory, api.machine
    fields = dict(position=trajectory.position * 40.0, velocity=trajectory.velocity * 40.0,
                  acceleration=trajectory.acceleration * 40.0, s=trajectory.s * 40.0)  # 80 mm: float16 to 0.06 mm
    force = np.linspace(0.0, 30.0, len(trajectory))

    def run(value, array, batch=False):
        reference = Trajectory(trajectory.t, **{k: array(v) for k, v in fields.items()}, measuring=trajectory.measuring)
        axes = {**machine.axes, "x": dataclasses.replace(machine.axes["x"], kp=value(machine.axes["x"].kp * 1.01))}
        model = Model(dataclasses.replace(machine, axes=axes), (Effect("backlash", "x", lost_motion_um=value(7.3)),))
        if batch:
            return simulate_batch([model], reference, force={"x": array(force)})["tool_position"][0]
        return simulate(model, reference, force={"x": array(force)}).tool_position

    expected = run(lambda v: float(exact([v])[0]), exact)
    for batch in (False, True):
        ran = run(one, cast, batch)
        assert ran.dtype == np.float64 and np.array_equal(ran, expected[: len(ran)])


def test_a_file_name_of_bytes_that_are_not_utf8_runs_and_runs_again_into_its_folder(tmp_path):
    """A program named in Latin-1 (p\\xff.nc, from a Windows share): simulate failed on the trace CSV's '# path:' line
    ('utf-8' codec can't encode character '\\udcff'), the marker's record of p\\xff.csv and the plots' titles."""
    program = os.fsdecode(os.fsencode(tmp_path) + b"/p\xff.nc")
    Path(program).write_text("G21 G90 G17\nG1 X10 F600\nG1 Y10\nM30\n")
    for _ in range(2):  # the second run reads the folder's record of the first; printed as the program prints it
        done = subprocess.run([sys.executable, "-m", "contoursim", "simulate", os.fsencode(program), "--out",
                               str(tmp_path / "out")], cwd=ROOT, capture_output=True, timeout=300)
        assert done.returncode == 0 and b"path: p\\udcff.nc" in done.stdout, done.stderr
    assert {b"p\xff.csv", b"p\xff_blocks.csv", b"p\xff_path.png"} <= set(os.listdir(os.fsencode(tmp_path / "out")))
    trace = read_trace(os.fsdecode(os.fsencode(tmp_path) + b"/out/p\xff.csv"))
    assert trace.metadata["path"] == "p\\udcff.nc" and trace.axes == ("x", "y")


@pytest.mark.parametrize("files, argv, meant", [
    ({"m.toml": MACHINE.format(mass=300.0).replace("kp_per_s", "kp_per_sec", 1)},
     ["simulate", "rounded_square", "--machine", "{d}/m.toml"], "(did you mean 'kp_per_s'?)"),
    ({"j.toml": 'machine = "demo_mill"\npath = "rounded_square"\n[feed]\nfeed_mm_minute = 300\n'},
     ["simulate", "{d}/j.toml"], "(did you mean 'feed_mm_min'?)"),
    ({"j.toml": 'machine = "demo_mill"\npath = "rounded_square"\n[[effect]]\nname = "backlsh"\naxis = "x"\n'},
     ["simulate", "{d}/j.toml"], "(did you mean 'backlash'?)"),
    ({"j.toml": 'machine = "demo_mill"\npath = "rounded_square"\n[[effect]]\nname = "backlash"\naxis = "x"\n'
                "lost_motion = 3\n"}, ["simulate", "{d}/j.toml"], "(did you mean 'lost_motion_um'?)"),
    ({}, ["simulate", "rounded_square", "--machine", "demo_mil"], "(did you mean 'demo_mill'?)"),
    ({}, ["simulate", "rounded_sqare"], "(did you mean 'rounded_square'?)"),
    ({"s.toml": SMALL_PATH.replace('"iso230_4_circle"', '"iso230_4_circl"')}, ["simulate", "{d}/s.toml"],
     "(did you mean 'iso230_4_circle'?)"),
    ({"w.toml": 'machine = "demo_mill"\npath = "rounded_square"\n[sweep]\nmethod = "grid"\n[[vary]]\n'
                'name = "axes.x.kp_per_sec"\nvalues = [30, 40]\n'}, ["sweep", "{d}/w.toml"], "(did you mean 'kp_per_s'?)"),
    ({}, ["compare", "rounded_square", "--strategies", "none,ccc_arcc"], "(did you mean 'ccc_arc'?)"),
    ({"j.toml": 'machin = "demo_mill"\npath = "rounded_square"\n'}, ["simulate", "{d}/j.toml"],
     "line 1: unknown key 'machin' in the file's top level (did you mean 'machine'?)"),
])
def test_a_misspelt_name_is_refused_suggesting_the_name_meant(tmp_path, capsys, files, argv, meant):
    """A typo among 24 axis keys, 12 effects or the presets was refused listing them all, the one meant not said."""
    for name, text in files.items():
        (tmp_path / name).write_text(text)
    _refused(capsys, [*(a.format(d=tmp_path) for a in argv), "--out", str(tmp_path / "out")], meant)


@pytest.mark.parametrize("where", [3, 6])  # mid-way, last
def test_a_comment_among_a_traces_rows_is_said_to_be_one(tmp_path, where):
    """A log closed by '# end of log' (or a remark mid-way) was refused as 'expected 3 cells (as in the header),
    found 1'."""
    rows = [f"{k * 1e-3:.3f},{k * 0.01:.3f},{k * 0.01:.3f}" for k in range(4)]
    rows.insert(where - 2, "# end of log")
    (tmp_path / "t.csv").write_text("t,x_ref,x\n" + "\n".join(rows) + "\n")
    with pytest.raises(TraceFormatError, match=rf"t.csv, line {where}: a comment among the data rows: comment lines "):
        read_trace(tmp_path / "t.csv")


def test_a_diagnosis_does_not_replace_the_model_it_reads(tmp_path, capsys):
    """Identified on one experiment into out/, validated on another with --model out/corrected_model.toml --out out: the
    model validated against was replaced by the second trace's corrected model without a word."""
    with output_dir(tmp_path / "out").write("corrected_model.toml") as stream:  # as a first diagnosis leaves it
        stream.write(preset_file("demo_mill").read_text())
    model = tmp_path / "out" / "corrected_model.toml"
    before = model.read_bytes()
    t = np.arange(400) * 1e-3
    trace = _trace(tmp_path / "t.csv", t, np.sin(t), np.sin(t) + 1e-4)
    _refused(capsys, ["diagnose", str(trace), "--model", str(model), "--out", str(tmp_path / "out")],
             f"--out {tmp_path / 'out'} would replace {model}, the model this run reads")
    assert model.read_bytes() == before


@pytest.mark.parametrize("name", ["diagnosis_trace.png", "corrected_model.toml"])
def test_a_diagnosis_report_onto_a_file_the_run_writes_is_refused_before_it_runs(tmp_path, capsys, name):
    """--report out/diagnosis_trace.png --out out: the report was written, then the plot replaced it (or the report
    replaced the corrected model): refused before the diagnosis, nothing written."""
    t = np.arange(400) * 1e-3
    trace = _trace(tmp_path / "t.csv", t, np.sin(t), np.sin(t) + 1e-4)
    out = tmp_path / "out"
    _refused(capsys, ["diagnose", str(trace), "--out", str(out), "--report", str(out / name)],
             f"{out / name} is a file this run writes into its output directory")
    assert not out.exists()


@pytest.mark.parametrize("name", ["line_compare_path.png", ".contoursim-out"])
def test_a_comparison_json_onto_a_file_the_run_writes_is_refused_before_it_runs(tmp_path, capsys, name):
    """--json out/line_compare_path.png --out out: the plot was written, then the JSON replaced it; --json
    out/.contoursim-out replaced the folder's record, and the next run into it refused its own plots."""
    (tmp_path / "line.nc").write_text("G21 G90 G17\nG1 X0 Y0 F1000\nG1 X20\nG1 X0\nM30\n")
    out = tmp_path / "out"
    _refused(capsys, ["compare", str(tmp_path / "line.nc"), "--strategies", "none", "--out", str(out), "--json",
                      str(out / name)],
             f"{out / name} is a file this run writes into its output directory")
    assert not out.exists()


@pytest.mark.parametrize("named", ["command line", "job file"])
def test_a_users_copy_of_a_library_path_or_a_preset_named_without_its_suffix_is_the_one_read(tmp_path, monkeypatch,
                                                                                            named):
    """``rounded_square`` ran the library's square while the user's edited rounded_square.toml lay beside the job (and
    ``demo_mill`` the preset for a demo_mill.toml): the table said 'path: rounded_square.toml' all the same."""
    from contoursim.cli import _job

    folder = tmp_path / "job"
    folder.mkdir()
    (folder / "rounded_square.toml").write_text(SMALL_PATH)
    mill = preset_file("demo_mill").read_text()
    (folder / "demo_mill.toml").write_text(mill.replace("kp_per_s = 40.0", "kp_per_s = 30.0"))
    (folder / "j.toml").write_text('machine = "demo_mill"\npath = "rounded_square"\n')
    monkeypatch.chdir(folder if named == "command line" else tmp_path)
    args = (SimpleNamespace(file="rounded_square", machine="demo_mill", command="simulate") if named == "command line"
            else SimpleNamespace(file=str(folder / "j.toml"), machine=None, command="simulate"))
    model, path_file, _, _ = _job(args)
    assert path_file.resolve() == (folder / "rounded_square.toml").resolve()
    assert model.machine.axes["x"].kp == 30.0
    # a machine the user did not name is the shipped demo mill, whatever lies here
    monkeypatch.chdir(folder)
    model, _, _, _ = _job(SimpleNamespace(file="rounded_square", machine=None, command="simulate"))
    assert model.machine.axes["x"].kp == 40.0


@pytest.mark.parametrize("named", ["command line", "job file"])
def test_a_users_program_of_any_gcode_suffix_named_without_it_is_the_one_read(tmp_path, monkeypatch, named):
    """``pocket`` ran the library's pocket.nc while the user's pocket.ngc lay here (the table said 'path: pocket.nc'),
    and ``part`` for a part.gcode was "no path file 'part' here nor in the trajectories library"."""
    from contoursim.cli import _job

    folder = tmp_path / "job"
    folder.mkdir()
    for name in ("pocket.ngc", "part.gcode"):
        (folder / name).write_text("G21 G90\nG1 X0 Y0 F600\nG1 X10\n")
    monkeypatch.chdir(folder if named == "command line" else tmp_path)
    for name in ("pocket", "part"):
        (folder / "j.toml").write_text(f'machine = "demo_mill"\npath = "{name}"\n')
        args = (SimpleNamespace(file=name, machine=None, command="simulate") if named == "command line"
                else SimpleNamespace(file=str(folder / "j.toml"), machine=None, command="simulate"))
        assert _job(args)[1].resolve() == next(folder.glob(f"{name}.*")).resolve()


def test_a_folders_traces_whose_suffix_is_upper_case_are_in_the_fleet(tmp_path):
    """NIGHT_2.CSV (as a Windows controller names it) was left out of the fleet without a word; alone, the folder was
    said to hold no .csv trace."""
    for name in ("night_1.csv", "NIGHT_2.CSV", "night_3.Csv", "notes.txt"):
        (tmp_path / name).write_text("t,x_ref,x\n")
    assert [f.name for f in trace_files([tmp_path])] == ["NIGHT_2.CSV", "night_1.csv", "night_3.Csv"]


def test_a_warning_of_a_file_read_for_each_run_is_said_once(tmp_path, capsys):
    """--geometric-compensation runs the program twice: its ignored words were listed twice."""
    (tmp_path / "p.nc").write_text("G21 G90 G17\nM3 S8000\nG1 X0 Y0 F1000\nG1 X5\nG1 Y5\nM30\n")
    assert main(["simulate", str(tmp_path / "p.nc"), "--machine", "vertical_mill_3axis", "--geometric-compensation",
                 "--out", str(tmp_path / "out")]) == 0
    err = capsys.readouterr().err
    assert err.count("ignored: S8000 M3 (no contour motion)") == 1, err


def test_a_loop_its_effects_make_unstable_is_said_so_naming_them_not_the_path_file(tmp_path, capsys):
    """A feedback delay of 12.6 ms (within the effect's range) makes X's loop unstable: the error blamed the path file
    ('small.toml: the simulation of axis 'x' ran away ...') and did not say which effect."""
    (tmp_path / "small.toml").write_text(SMALL_PATH)
    (tmp_path / "job.toml").write_text('machine = "demo_mill"\npath = "small.toml"\n\n[[effect]]\nname = "time_delay"\n'
                                       'axis = "x"\ndelay_s = 0.0126\nkind = "feedback"\n')
    line = _refused(capsys, ["simulate", str(tmp_path / "job.toml"), "--out", str(tmp_path / "out")],
                    "the simulation of axis 'x' ran away", "(on x: time_delay.x) or this coupling is unstable")
    assert "small.toml" not in line


def test_a_path_file_whose_name_has_a_line_break_is_refused_before_anything_is_written(tmp_path, capsys):
    """Its stem names the files written: it was refused at write time ('name must be a plain file name'), no file or
    line said, an empty output folder left."""
    (tmp_path / "nl\nname.toml").write_text(SMALL_PATH)
    _refused(capsys, ["simulate", str(tmp_path / "nl\nname.toml"), "--out", str(tmp_path / "out")],
             "the path file's name", "has a line break, which no file written from it may have: rename it")
    assert not (tmp_path / "out").exists()


def test_an_existing_report_nested_too_deeply_to_read_is_not_overwritten(tmp_path, capsys):
    """json.loads of a user's file named as --json recursed past the stack: a RecursionError traceback."""
    (tmp_path / "small.toml").write_text(SMALL_PATH)
    (tmp_path / "r.json").write_text("[" * 100_000 + "]" * 100_000)
    _refused(capsys, ["compare", str(tmp_path / "small.toml"), "--strategies", "none", "--json", str(tmp_path / "r.json"),
                      "--out", str(tmp_path / "out")], "r.json exists and is not a")
    assert (tmp_path / "r.json").read_text().startswith("[[[")


# -- faults5: a jerk-limited start, error tables' columns, a loop gain too high, a default run-in, arc radii ---------


def test_a_jerk_limited_start_whose_first_steps_are_below_rounding_runs(tmp_path, capsys):
    """jerk_mm_s3 = 3e-6 (within its range) on the 2 mm ISO circle: the first samples advance in arc length by 1e-18 mm,
    below their positions' rounding, and the contour error's search divided by the zero chord between two of them
    (a ZeroDivisionError traceback). Far from the origin, 1e-3 mm/s³ does the same on a short circle."""
    (tmp_path / "slow.toml").write_text('[feed]\nfeed_mm_min = 600\naccel_mm_s2 = 500\njerk_mm_s3 = 1e-3\n\n[path]\n'
                                        'type = "circle"\ncenter_mm = [1000, 1000]\nradius_mm = 0.01\n'
                                        'start_angle_deg = 45\n')
    assert main(["simulate", str(tmp_path / "slow.toml"), "--out", str(tmp_path / "out")]) == 0
    out, err = capsys.readouterr()
    assert "error" not in err and "Traceback" not in err, err
    assert re.search(r"^slow +\d", out, re.M), out


@pytest.mark.parametrize("header, words", [
    ("position_mm,dx_um,dx_um", "column name(s) 'dx_um' appear more than once in the header"),  # the last copy won
    ("position_mm,dx_um,position_mm", "column name(s) 'position_mm' appear more than once in the header"),  # the first
    ("position_mm", "the error table has no error column, only 'position_mm': add one or more of dx_um, dy_um"),
])
def test_an_error_tables_header_naming_a_column_twice_or_no_error_is_refused_at_its_line(tmp_path, capsys, header,
                                                                                        words):
    """A table's repeated column was read as its last copy (its first, for position_mm), and a table of positions only
    contributed nothing: each without a word, as a trace's repeated column is not."""
    preset = preset_file("vertical_mill_3axis")
    (tmp_path / "m.toml").write_text(preset.read_text())
    table = tmp_path / "vertical_mill_x_laser.csv"  # the X body's error table, beside it
    cells = ",".join(["0"] * len(header.split(",")))
    table.write_text(f"{header}\n{cells}\n{cells.replace('0', '500', 1)}\n")
    _refused(capsys, ["volumetric", str(tmp_path / "m.toml"), "--out", str(tmp_path / "out")], f"{table}, line 1: {words}")
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("key, value", [("kv_A_s_per_m = 80.0", "kv_A_s_per_m = 20000"),
                                        ("mass_kg = {mass}", "mass_kg = 1e-3"),
                                        ("force_constant_N_per_A = 942.0", "force_constant_N_per_A = 1e6")])
def test_a_velocity_loop_gain_far_too_high_is_told_to_come_down(tmp_path, capsys, key, value):
    """The sampled loop's phase reaches -180° at the Nyquist frequency, where its gain is 15.7 (kv = 20000): that phase
    crossover, at the grid's end, went unseen, the gain margin read inf and the loop 'never reaches 1 ... raise kv'."""
    (tmp_path / "m.toml").write_text(MACHINE.replace(key, value, 1).format(mass=300.0))
    (tmp_path / "small.toml").write_text(SMALL_PATH)
    _refused(capsys, ["simulate", str(tmp_path / "small.toml"), "--machine", str(tmp_path / "m.toml"), "--out",
                      str(tmp_path / "out")], f"{tmp_path / 'm.toml'}, line 6: the velocity loop of axis 'x' is unstable",
             "no gain crossover (the loop gain stays above 1 up to the Nyquist frequency)",
             "lower kv_A_s_per_m, or check the mass_kg", "and force_constant_N_per_A")


def test_a_test_circle_too_small_for_its_default_run_in_is_said_so_in_the_files_terms(tmp_path, capsys):
    """radius_mm = 1e-6 was refused quoting 'radius_mm = 5e-07 is outside [1e-06, 1e+06]': its default run-in radius
    (R/2), a value the file does not hold, under the name of the one it does."""
    (tmp_path / "tiny.toml").write_text('[feed]\nfeed_mm_min = 600\n\n[path]\ntype = "iso230_4_circle"\nradius_mm = 1e-6\n')
    _refused(capsys, ["simulate", str(tmp_path / "tiny.toml"), "--out", str(tmp_path / "out")],
             f"{tmp_path / 'tiny.toml'}, line 6: bad iso230_4_circle [path]: run_radius_mm (by default radius_mm (1e-06 mm) "
             "/ 2 = 5e-07 mm) is below 1e-06 mm, the least radius of an arc: give a larger radius_mm (at least 2e-06 mm), "
             "or run_radius_mm (at least 1e-06 mm and below the test radius)")
    assert not (tmp_path / "out").exists()


def test_an_arcs_radii_that_differ_are_shown_differing(tmp_path, capsys):
    """Radii of 1e6 mm 1 mm apart were both shown as 1.00499e+06 mm."""
    (tmp_path / "big.nc").write_text("G21 G90 G17\nG1 X0 Y0 F600\nG2 X10 Y0 I100000 J-1000000\nM30\n")
    _refused(capsys, ["simulate", str(tmp_path / "big.nc"), "--out", str(tmp_path / "out")],
             f"{tmp_path / 'big.nc'}, line 3: arc start radius 1004987.56 mm and end radius 1004986.57 mm differ by more "
             "than 0.002 mm")


# -- faults6: a run made long by its settle, a job's [feed] too long for the memory, a user's file where a run writes --


def test_a_run_made_long_by_the_settle_after_the_path_is_said_before_it_starts(tmp_path, capsys, monkeypatch):
    """kp_per_s = 0.001 (within its range) held a 2-s path for 5/kp = 5000 s: 10 M servo periods and 4.5 GB without the
    notice, which counted the motion only. Here kp_per_s = 1 holds a 3,810-period motion for 10,000 periods, beyond a
    threshold (lowered from 5 M) that the motion alone stays below."""
    import contoursim.cli

    (tmp_path / "small.toml").write_text(SMALL_PATH)
    (tmp_path / "m.toml").write_text(MACHINE.format(mass=300.0).replace("kp_per_s = 40.0", "kp_per_s = 1.0", 1))
    monkeypatch.setattr(contoursim.cli, "_LONG_RUN", 10_000)
    assert main(["simulate", str(tmp_path / "small.toml"), "--machine", str(tmp_path / "m.toml"), "--out",
                 str(tmp_path / "out")]) == 0
    said = [line for line in capsys.readouterr().err.splitlines() if "servo periods of" in line]
    assert len(said) == 1 and said[0].startswith("contoursim: the run lasts 6.9"), said
    assert (", of which 5 s the settle after the path, 5/kp of axis x (kp_per_s = 1): 1.38e+04 servo periods of "
            "0.0005 s to simulate") in said[0], said


@pytest.mark.parametrize("feed, words", [
    ("centripetal_accel_mm_s2 = 1e-6", "[feed] centripetal_accel_mm_s2 = 1e-06, overriding small.toml's: the motion "
                                       "lasts 14248.8 s: at dt = 0.0002 s"),  # blamed on small.toml, without a line
    ("feed_mm_min = 0.01", "[feed] feed_mm_min = 0.01, overriding small.toml's: the motion lasts 113097 s"),  # no line
])
def test_a_jobs_feed_that_makes_the_motion_too_long_for_the_memory_is_refused_at_its_line(tmp_path, capsys, monkeypatch,
                                                                                          feed, words):
    """A job's [feed] override that lengthens the path file's motion beyond the memory was refused naming the path file,
    which the user did not change (or the job without a line); a path file too long of its own keeps its name."""
    monkeypatch.setattr(_memory, "available", lambda: 10**9)
    (tmp_path / "small.toml").write_text(SMALL_PATH)
    (tmp_path / "job.toml").write_text(f'machine = "demo_mill"\npath = "small.toml"\n[feed]\n{feed}\n')
    _refused(capsys, ["simulate", str(tmp_path / "job.toml"), "--out", str(tmp_path / "out")],
             f"{tmp_path / 'job.toml'}, line 4: {words}", "and 1 GB are available")
    (tmp_path / "slow.toml").write_text(SMALL_PATH.replace("feed_mm_min = 600", "feed_mm_min = 0.01", 1))
    (tmp_path / "job.toml").write_text('machine = "demo_mill"\npath = "slow.toml"\n[feed]\naccel_mm_s2 = 1000\n')
    _refused(capsys, ["simulate", str(tmp_path / "job.toml"), "--out", str(tmp_path / "out")],
             f"{tmp_path / 'slow.toml'}: the motion lasts 113097 s")
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("command, name", [("sweep", "sweep_axes.x.ti_s.png"), ("sweep", "sweep.csv"),
                                           ("compare", "small_compare_zoom.png")])
def test_a_users_file_where_a_sweep_or_compare_writes_is_refused_before_it_runs(tmp_path, capsys, monkeypatch,
                                                                                command, name):
    """A user's file in an earlier run's folder, under a name the sweep (the comparison) writes, was refused only once
    every variant (strategy) had run, and their results were thrown away."""
    import contoursim.comparison
    import contoursim.sweep

    def ran(*args, **kwargs):
        raise AssertionError("the run started")

    monkeypatch.setattr(contoursim.sweep, "run_sweep", ran)
    monkeypatch.setattr(contoursim.comparison, "compare", ran)
    (tmp_path / "small.toml").write_text(SMALL_PATH)
    (tmp_path / "s.toml").write_text('machine = "demo_mill"\npath = "small.toml"\n[sweep]\nmethod = "grid"\n[[vary]]\n'
                                     'name = "axes.x.ti_s"\nvalues = [0.016, 0.02]\n')
    out = output_dir(tmp_path / "out").path  # contoursim's folder, an earlier run's
    (out / name).write_text("mine\n")
    argv = (["sweep", str(tmp_path / "s.toml")] if command == "sweep"
            else ["compare", str(tmp_path / "small.toml"), "--strategies", "none"])
    _refused(capsys, [*argv, "--out", str(out)],
             f"{out / name} exists and contoursim did not write it; refusing to overwrite it")
    assert (out / name).read_text() == "mine\n"


# -- faults6: the public API from a notebook; where simulate and demo write -------------------------------------------


@pytest.mark.parametrize("command, mine", [("simulate", "f.txt"), ("demo", "f.txt"), ("simulate", "out/small.csv"),
                                           ("demo", "out/butterfly.csv")])
def test_an_out_that_simulate_or_demo_cannot_write_is_refused_before_the_runs(tmp_path, capsys, monkeypatch, command,
                                                                              mine):
    """``simulate PATH --out FILE`` (and demo's) ran every run, then said 'FILE is a file, not a directory'; a user's
    file of a trace's name in an earlier run's folder was refused after the runs as well."""
    import contoursim.cli

    def ran(*args, **kwargs):
        raise AssertionError("the run started")

    monkeypatch.setattr(contoursim.cli, "run_job", ran)
    (tmp_path / "small.toml").write_text(SMALL_PATH)
    output_dir(tmp_path / "out")  # contoursim's folder, an earlier run's
    (tmp_path / mine).write_text("mine\n")
    out = tmp_path / ("f.txt" if mine == "f.txt" else "out")
    argv = ["simulate", str(tmp_path / "small.toml")] if command == "simulate" else ["demo"]
    words = (f"{out} is a file, not a directory" if mine == "f.txt"
             else f"{tmp_path / mine} exists and contoursim did not write it; refusing to overwrite it")
    _refused(capsys, [*argv, "--out", str(out)], words)
    assert (tmp_path / mine).read_text() == "mine\n"


@pytest.mark.parametrize("call, error, words", [
    # pathlib's "expected str, bytes or os.PathLike object, not int", from inside
    (lambda a: write_trace(3, a.trace), TypeError,
     "expected a file name (str or Path) or a file object to write to, got int"),
    (lambda a: simulate(a.machine, a.trajectory).save_csv(None), TypeError,
     "expected a file name (str or Path) or a file object to write to, got NoneType"),
    # 'str' object has no attribute 'label'
    (lambda a: Model(a.machine).with_effect("backlash"), TypeError,
     "effect must be an Effect, e.g. Effect('backlash', 'x', lost_motion_um=5.0), got str"),
    # 'str' object has no attribute 'axes'; 'list' object has no attribute 'items'; 'k' is not a controller setting
    (lambda a: Machine(dict(a.machine.axes), 2e-4, chain="vertical_mill_3axis"), TypeError,
     "chain must be a MachineChain (a machine's geometry) or None, got str"),
    (lambda a: Machine(dict(a.machine.axes), 2e-4, uncertain=["x"]), TypeError,
     "uncertain must map axis names to values ({'x': ('kp',)}), got list"),
    (lambda a: Machine(dict(a.machine.axes), 2e-4, uncertain={"x": "kp"}), TypeError,
     "uncertain['x'] must be a sequence of controller settings, got the string 'kp': give ('kp',)"),
    (lambda a: Machine(dict(a.machine.axes), 2e-4, axis_travel=[(0.0, 500.0)]), TypeError,  # 'names axis 0'
     "axis_travel must map axis names to values ({'x': (0.0, 500.0)}), got list"),
    # a target tool axis of length 2 or 0 was matched as it was, the answer moved without a word; a negative tol
    # ended in 'did not converge in 20 steps', a tol of text in a comparison's TypeError
    (lambda a: load_machine("table_tilting_5axis").chain.inverse(np.zeros((2, 3)), tool_axis=[[0, 0, 1], [0, 0, 2]]),
     ValueError, "tool_axis must hold unit vectors, got [0. 0. 2.] (length 2) at row 1"),
    (lambda a: load_machine("table_tilting_5axis").chain.inverse(np.zeros((1, 3)), tool_axis=np.zeros((1, 3))),
     ValueError, "tool_axis must hold unit vectors, got [0. 0. 0.] (length 0) at row 0"),
    (lambda a: load_machine("table_tilting_5axis").chain.inverse(np.zeros((1, 3)), tol=-1.0), ValueError,
     "tol must be positive, got -1.0"),
    (lambda a: load_machine("table_tilting_5axis").chain.inverse(np.zeros((1, 3)), tol="1e-9"), TypeError,
     "tol must be a number, got '1e-9'"),
    # an axis or a body the chain lacks: StopIteration, IndexError (chain_to(-1) answered another body's chain)
    (lambda a: load_machine("vertical_mill_3axis").chain.axis_kind("q"), ValueError,
     "axis must be one of the chain's axes (x, y, z), got 'q'"),
    (lambda a: load_machine("vertical_mill_3axis").chain.chain_to(99), ValueError,
     "j must be a body index 0..6 (0 the bed), got 99"),
    (lambda a: load_machine("vertical_mill_3axis").chain.chain_to(-1), ValueError, "j must be at least 0, got -1"),
    # numpy's UFuncTypeError; 'poly contains a non-finite value (nan)' (or 'sin must be finite'), not the factor
    (lambda a: load_machine("vertical_mill_3axis").chain.scaled("2"), TypeError, "factor must be a number, got '2'"),
    (lambda a: load_machine("vertical_mill_3axis").chain.scaled(np.nan), ValueError, "factor must be finite, got nan"),
    # numpy's 'truth value of an array with more than one element is ambiguous'
    (lambda a: Body("b", joint="linear", axis="x", direction=True), TypeError,
     "b.direction must be a whole number, got True"),
    (lambda a: Body("b", joint="linear", axis="x", direction=3), ValueError,
     "b.direction must be 0, 1 or 2 (x, y, z), got 3"),
    (lambda a: Body("b", joint="linear", axis="x", sign=np.array([1, 1])), TypeError,
     "b.sign must be a number, got array([1, 1])"),
    (lambda a: Body("b", joint="linear", axis="x", sign=0.5), ValueError, "b.sign must be 1 or -1, got 0.5"),
    # NaN with only numpy's overflow warning: positions beyond the chain's range, refused as a Trajectory's are
    (lambda a: load_machine("vertical_mill_3axis").chain.tool_pose(np.array([[0.0, 0.0, 0.0], [0.0, 0.0, 1e300]])),
     ValueError, "q holds 1e+300 at index (1, 2), beyond ±1e+12"),
    (lambda a: load_machine("vertical_mill_3axis").chain.inverse(np.zeros((1, 3)), q0=np.full((1, 3), 2e13)), ValueError,
     "q0 holds 2e+13 at index (0, 0), beyond ±1e+12"),
    # a 2-sample trajectory, the circle's start and end, without a word
    (lambda a: sample(a.path, a.profile, 100.0), ValueError,
     "dt = 100 s is not shorter than the motion, which lasts 1.27664 s: no sample would lie on the path between its "
     "start and its end; sample it at a shorter dt (the servo period), or plan a longer or slower motion"),
    # "'NoneType' object is not iterable"
    (lambda a: Model(a.machine, None), TypeError,
     "effects must be a sequence of Effect objects, e.g. (Effect('backlash', 'x', lost_motion_um=5.0),), got NoneType"),
    # "'int' object has no attribute 'names'", "unhashable type: 'slice'", a table of another sweep zipped short
    (lambda a: table_text(3, 3), TypeError, "sweep must be a Sweep (read_sweep reads one from its spec), got int"),
    (lambda a: table_text(Sweep("s.toml", {"s.toml": ""}, "none", ("a",), [[1.0]]), np.zeros((2, len(FIGURES)))),
     ValueError, f"table must have shape (1, {len(FIGURES)}), got (2, {len(FIGURES)})"),
    (lambda a: best_and_worst({}), TypeError, "table must be numeric (not text, booleans or complex numbers)"),
    # a one-element shape was written "(2)"
    (lambda a: load_machine("table_tilting_5axis").chain.inverse(np.zeros((2, 3)), t=np.zeros(1)), ValueError,
     "t must have shape (2,), got (1,)"),
])
def test_the_api_from_a_notebook_refuses_naming_the_argument_not_from_inside(api, call, error, words):
    with pytest.raises(error) as info:
        call(api)
    assert str(info.value) == words


def test_a_servo_period_as_long_as_a_curved_motion_is_refused_and_one_just_shorter_samples_between(api):
    """sample(path, profile, dt=100.0) returned the circle's start and its end, a 2-sample trajectory straight across.
    A straight move shorter than the period is the step a controller makes of a block shorter than its period."""
    with pytest.raises(ValueError, match=r"^dt = 1.27664 s is not shorter than the motion, which lasts 1.27664 s: "):
        sample(api.path, api.profile, api.profile.duration)
    trajectory = sample(api.path, api.profile, 0.99 * api.profile.duration)
    assert len(trajectory) == 3 and 0 < trajectory.s[1] < api.path.length
    jog = polyline([[0.0, 0.0], [0.002, 0.0]])
    step = sample(jog, plan(jog, 10.0, 500.0), 0.01)  # the 2 µm move takes 4 ms
    np.testing.assert_array_equal(step.position, [[0.0, 0.0], [0.002, 0.0]])


@pytest.mark.parametrize("call, words", [
    (lambda a: simulate_batch([a.machine] * 10**4, a.trajectory), "10000 models, 7080 samples of each kept: that is "),
    (lambda a: a.trajectory.preceded(10**12), "a standstill of 1000000000000 samples before the start, at dt = 0.0002"),
])
def test_a_huge_count_is_refused_by_the_memory_it_needs_not_numpys_memoryerror(api, monkeypatch, call, words):
    """A batch of 10000 models, a trajectory preceded by 1e12 samples: numpy's 'Unable to allocate 1.05 GiB'."""
    monkeypatch.setattr(_memory, "available", lambda: 10**8)
    with pytest.raises(ValueError) as info:
        call(api)
    assert str(info.value).startswith(words) and "GB of memory and 0.1 GB are available" in str(info.value)
