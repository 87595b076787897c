"""The command line: the demo, simulate on job and path files, and what bad input gives."""

import numpy as np
import pytest

from contoursim.cli import main
from contoursim.traces import read_trace

SMALL_PATH = """
[feed]
feed_mm_min = 600
accel_mm_s2 = 500

[path]
type = "iso230_4_circle"
radius_mm = 2
"""

MACHINE = """
name = "two axes"
servo_period_ms = 0.5
max_feed_mm_min = 5000

[axes.x]
mass = 300.0
force_constant = 942.0
kv = 80.0
ti = 0.016
kp = {kp}

[axes.y]
mass = 300.0
force_constant = 942.0
kv = 80.0
ti = 0.016
kp = 40.0
"""


def test_demo_writes_its_table_plots_and_traces(tmp_path, capsys):
    assert main(["demo", "--out", str(tmp_path / "out")]) == 0
    table = capsys.readouterr().out
    for run in ("iso230_4_circle_ccw", "iso230_4_circle_cw", "butterfly"):
        assert run in table
        for kind in ("path", "errors"):
            assert (tmp_path / "out" / f"{run}_{kind}.png").stat().st_size > 10_000
        trace = read_trace(tmp_path / "out" / f"{run}.csv")
        assert trace.axes == ("x", "y")
    assert (tmp_path / "out" / "iso230_4_circle_polar.png").stat().st_size > 10_000  # CCW and CW overlaid
    # the circle row: tracking ≈ v/Kp = (1000/60)/36 mm on the slower axis, contour far smaller
    row = next(line for line in table.splitlines() if line.startswith("iso230_4_circle_ccw"))
    tracking_max, _, contour_max, _, volumetric_max = map(float, row.split()[1:])
    assert volumetric_max == 0.0  # the demo machine has no geometric errors
    assert tracking_max == pytest.approx(1e3 * (1000 / 60) / 36, rel=0.02)
    assert contour_max < tracking_max / 10
    # the CSV tells the same story: its contour column [mm] over the measuring rows gives the table's max
    lines = (tmp_path / "out" / "iso230_4_circle_ccw.csv").read_text().splitlines()
    header = next(i for i, line in enumerate(lines) if not line.startswith("#"))
    names = lines[header].split(",")
    data = np.loadtxt(lines[header + 1:], delimiter=",")
    measuring = data[:, names.index("measuring")] == 1
    assert 0 < measuring.sum() < len(data)  # the test circle, without run-in, overruns, run-out and settling
    assert f"{1e3 * data[measuring, names.index('contour')].max():.2f}" == f"{contour_max:.2f}"
    assert "# units: t [s]; x_ref, x, y_ref, y, contour, contour_normal [mm]; measuring [1 = test proper, 0 = not]" in lines
    # a second run reuses its own output directory; --every thins the CSV, not the table
    assert main(["demo", "--out", str(tmp_path / "out"), "--every", "10"]) == 0
    assert capsys.readouterr().out == table
    thinned = read_trace(tmp_path / "out" / "iso230_4_circle_ccw.csv")
    assert len(thinned.t) == -(-len(data) // 10) and thinned.dt == pytest.approx(10 * (data[1, 0] - data[0, 0]))
    with pytest.raises(SystemExit) as exit_:
        main(["demo", "--out", str(tmp_path / "out"), "--every", "0"])
    assert exit_.value.code == 2
    assert "--every: must be a whole number of samples, at least 1; got '0'" in capsys.readouterr().err


def test_never_writes_into_a_users_directory(tmp_path, capsys):
    (tmp_path / "notes.txt").write_text("mine")
    assert main(["demo", "--out", str(tmp_path)]) == 2
    assert "did not write; choose another output directory" in capsys.readouterr().err
    assert [p.name for p in tmp_path.iterdir()] == ["notes.txt"]
    assert (tmp_path / "notes.txt").read_text() == "mine"


def test_simulate_a_job_file(tmp_path, capsys):
    (tmp_path / "small.toml").write_text(SMALL_PATH)
    (tmp_path / "two.toml").write_text(MACHINE.format(kp=40.0))
    (tmp_path / "job.toml").write_text('machine = "two.toml"\npath = "small.toml"\n[feed]\nfeed_mm_min = 300\n')
    assert main(["simulate", str(tmp_path / "job.toml"), "--out", str(tmp_path / "out")]) == 0
    out = capsys.readouterr().out
    assert "machine: two axes, path: small.toml" in out
    trace = read_trace(tmp_path / "out" / "small.csv")
    assert trace.dt == pytest.approx(5e-4)
    speed = np.linalg.norm(np.diff(trace.reference, axis=0), axis=1) / trace.dt
    assert speed.max() == pytest.approx(300 / 60, rel=1e-3)


def test_simulate_a_library_path_on_a_named_machine(tmp_path, capsys):
    (tmp_path / "two.toml").write_text(MACHINE.format(kp=40.0))
    assert main(["simulate", "rounded_square", "--machine", str(tmp_path / "two.toml"), "--out", str(tmp_path / "o")]) == 0
    assert "rounded_square" in capsys.readouterr().out


def test_unknown_job_key_names_file_and_line(tmp_path, capsys):
    (tmp_path / "job.toml").write_text('machine = "demo_mill"\npath = "rounded_square"\nspeed = 3\n')
    assert main(["simulate", str(tmp_path / "job.toml"), "--out", str(tmp_path / "o")]) == 2
    assert f"{tmp_path / 'job.toml'}, line 3: unknown key 'speed'" in capsys.readouterr().err


def test_bad_servo_value_names_file_line_and_axis(tmp_path, capsys):
    (tmp_path / "m.toml").write_text(MACHINE.format(kp=-1.0))
    assert main(["simulate", "rounded_square", "--machine", str(tmp_path / "m.toml"), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert f"{tmp_path / 'm.toml'}, line 11: axis x: kp must be positive" in err


def test_unstable_gains_are_reported_with_margins(tmp_path, capsys):
    (tmp_path / "m.toml").write_text(MACHINE.format(kp=900.0))
    assert main(["simulate", "rounded_square", "--machine", str(tmp_path / "m.toml"), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert f"{tmp_path / 'm.toml'}, line 6: the position loop of axis 'x'" in err
    assert "phase margin 16.6 deg" in err and "lower kp" in err


def test_servo_period_too_long_names_the_key(tmp_path, capsys):
    (tmp_path / "m.toml").write_text(MACHINE.format(kp=40.0).replace("servo_period_ms = 0.5", "servo_period_ms = 5"))
    assert main(["simulate", "rounded_square", "--machine", str(tmp_path / "m.toml"), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert f"{tmp_path / 'm.toml'}, line 3: dt = 0.005 s is too long for the velocity loop of axis 'x'" in err


def test_feed_override_is_checked_and_limited_by_the_machine(tmp_path, capsys):
    (tmp_path / "two.toml").write_text(MACHINE.format(kp=40.0))
    job = tmp_path / "job.toml"
    job.write_text('machine = "two.toml"\npath = "rounded_square"\n\n[feed]\naccel_mm_s2 = -5\n')
    assert main(["simulate", str(job), "--out", str(tmp_path / "o")]) == 2
    assert f"{job}, line 5: accel_mm_s2 must be positive" in capsys.readouterr().err
    job.write_text('machine = "two.toml"\npath = "rounded_square"\n\n[feed]\nfeed_mm_min = 6000\n')
    assert main(["simulate", str(job), "--out", str(tmp_path / "o")]) == 2
    assert "max_feed" in capsys.readouterr().err


@pytest.mark.parametrize("key, line", [("machine", 1), ("path", 2)])
def test_job_names_that_are_not_text_are_reported_and_nothing_is_written(tmp_path, capsys, key, line):
    job = tmp_path / "job.toml"
    job.write_text('machine = "demo_mill"\npath = "rounded_square"\n'.replace(f'{key} = "', f'{key} = 5 #"'))
    assert main(["simulate", str(job), "--out", str(tmp_path / "o")]) == 2
    assert f"{job}, line {line}: {key} must be a name or a file name in quotes, got 5" in capsys.readouterr().err
    assert not (tmp_path / "o").exists()


def test_machine_option_with_a_job_file_is_an_error(tmp_path, capsys):
    job = tmp_path / "job.toml"
    job.write_text('path = "rounded_square"\nmachine = "demo_mill"\n')
    assert main(["simulate", str(job), "--machine", "vertical_mill_3axis", "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert f"{job}, line 2: --machine vertical_mill_3axis is not used with a job file" in err
    assert not (tmp_path / "o").exists()


def test_bad_machine_leaves_no_output_directory(tmp_path, capsys):
    (tmp_path / "m.toml").write_text(MACHINE.format(kp=-1.0))
    assert main(["simulate", "rounded_square", "--machine", str(tmp_path / "m.toml"), "--out", str(tmp_path / "o")]) == 2
    assert not (tmp_path / "o").exists()


def test_text_for_a_number_names_file_and_line(tmp_path, capsys):
    (tmp_path / "m.toml").write_text(MACHINE.format(kp='"40"'))
    assert main(["simulate", "rounded_square", "--machine", str(tmp_path / "m.toml"), "--out", str(tmp_path / "o")]) == 2
    assert f"{tmp_path / 'm.toml'}, line 11: axis x: kp must be a number, got '40'" in capsys.readouterr().err


def test_out_must_be_a_directory(tmp_path, capsys):
    (tmp_path / "somefile").write_text("mine")
    assert main(["simulate", "rounded_square", "--out", str(tmp_path / "somefile")]) == 2
    assert f"{tmp_path / 'somefile'} is a file, not a directory" in capsys.readouterr().err
    assert (tmp_path / "somefile").read_text() == "mine"


def test_never_replaces_a_users_file_inside_its_own_directory(tmp_path, capsys):
    (tmp_path / "small.toml").write_text(SMALL_PATH)
    out = tmp_path / "out"
    assert main(["simulate", str(tmp_path / "small.toml"), "--out", str(out)]) == 0
    (out / "notes.txt").write_text("mine")  # beside contoursim's files: its own are replaced ...
    assert main(["simulate", str(tmp_path / "small.toml"), "--out", str(out)]) == 0
    (tmp_path / "other.toml").write_text(SMALL_PATH)
    (out / "other.csv").write_text("mine")  # ... a user's file with a name it would write is not
    assert main(["simulate", str(tmp_path / "other.toml"), "--out", str(out)]) == 2
    assert f"{out / 'other.csv'} exists and contoursim did not write it" in capsys.readouterr().err
    assert (out / "other.csv").read_text() == "mine" and (out / "notes.txt").read_text() == "mine"
    assert not (out / "other_path.png").exists()


def test_job_work_offset_moves_the_path_on_the_machine(tmp_path, capsys):
    job = tmp_path / "job.toml"
    job.write_text('machine = "vertical_mill_3axis"\npath = "iso230_4_circle_ccw"\nwork_offset = { x = 470 }\n')
    assert main(["simulate", str(job), "--out", str(tmp_path / "o")]) == 2
    assert "axis x would move over 420 .. 520, outside its travel 0 .. 500" in capsys.readouterr().err
    job.write_text('machine = "vertical_mill_3axis"\npath = "iso230_4_circle_ccw"\nwork_offset = { w = 1 }\n')
    assert main(["simulate", str(job), "--out", str(tmp_path / "o")]) == 2
    assert f"{job}, line 3: unknown key 'w' in [work_offset]" in capsys.readouterr().err
