"""The command line: the demo, simulate on job and path files, and what bad input gives."""

import io
import os
import re
import subprocess
import sys

import numpy as np
import pytest

from conftest import ROOT, ReaderGone
from contoursim.cli import main
from contoursim.diagnosis import REPORT_FORM, REPORT_OPTIONAL
from contoursim.output import has_form
from contoursim.simulation import SimResult
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
mass_kg = 300.0
force_constant_N_per_A = 942.0
kv_A_s_per_m = 80.0
ti_s = 0.016
kp_per_s = {kp}

[axes.y]
mass_kg = 300.0
force_constant_N_per_A = 942.0
kv_A_s_per_m = 80.0
ti_s = 0.016
kp_per_s = 40.0
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
    # the compact comparison on the free-form run: its none row is the butterfly run itself
    butterfly = next(line for line in table.splitlines() if line.startswith("butterfly "))
    none = next(line for line in table.splitlines() if line.startswith("none "))
    assert float(none.split()[1]) == pytest.approx(float(butterfly.split()[3]), rel=1e-3)
    both = next(line for line in table.splitlines() if line.startswith("feedforward+ccc_arc "))
    assert float(both.split()[1]) < 0.01 * float(none.split()[1])
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
    assert ("# units: t [s]; x_ref, x, y_ref, y, contour, contour_normal [mm]; measuring [1 = test proper, 0 = not]; "
            "rapid [1 = G0, 0 = not]") in lines
    # a second run reuses its own output directory; --every thins the CSV, not the table
    assert main(["demo", "--out", str(tmp_path / "out"), "--every", "10"]) == 0
    assert capsys.readouterr().out == table
    thinned = read_trace(tmp_path / "out" / "iso230_4_circle_ccw.csv")
    assert len(thinned.t) == -(-len(data) // 10) and thinned.dt == pytest.approx(10 * (data[1, 0] - data[0, 0]))
    with pytest.raises(SystemExit) as exit_:
        main(["demo", "--out", str(tmp_path / "out"), "--every", "0"])
    assert exit_.value.code == 2
    assert "--every: must be a whole number of samples, at least 1; got '0'" in capsys.readouterr().err
    assert main(["demo", "--out", str(tmp_path / "new"), "--every", "20000"]) == 2  # a CSV of 2 rows 4 s apart
    assert "every = 20000 keeps" in capsys.readouterr().err
    assert not (tmp_path / "new").exists()  # refused before the folder was made (it held a record of nothing)


# a fresh process with an empty numba cache (a function loaded from the cache does not compile its callees) and no
# stored loop analyses (read back, they compile nothing): the compiled functions the demo uses, and how many
# machine-code versions of each it made
DEMO_SIGNATURES = """
import contextlib, io, os, sys
from numba.core.registry import CPUDispatcher
import contoursim.cli
sys.argv[1:] = ["demo", "--out", sys.argv[1]]
codes = []
os._exit = codes.append  # the program's hard exit, held off for the list below
with contextlib.redirect_stdout(io.StringIO()):
    contoursim.cli.run()  # the program itself, as `contoursim demo` runs it
print("exit", *codes)
for name, module in list(sys.modules.items()):
    if name.startswith("contoursim"):
        for value in vars(module).values():
            if isinstance(value, CPUDispatcher) and value.__module__ == name and value.signatures:
                print(f"{name}.{value.__name__}", len(value.signatures))
"""


def test_demo_compiles_each_function_once_and_says_so(tmp_path):
    """No copy per literal argument (a row number, a flag) or per writeable/read-only array: a first run compiles less.

    The first run says on stderr that it compiles, once, and how long that took; a second run (a warm cache) says nothing.
    """
    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path / "numba_cache"), CONTOURSIM_CACHE_DIR=str(tmp_path / "analyses"))
    done = subprocess.run([sys.executable, "-c", DEMO_SIGNATURES, str(tmp_path / "out")], cwd=ROOT, env=env,
                          capture_output=True, text=True, check=True)
    assert done.stdout.startswith("exit 0\n")
    counts = dict(line.rsplit(" ", 1) for line in done.stdout.splitlines()[1:])
    assert "contoursim.kernel._variant" in counts and "contoursim.kernel._plant_row" in counts  # the kernel ran
    assert {name: n for name, n in counts.items() if n != "1"} == {}
    said = done.stderr.splitlines()
    assert said[0] == ("contoursim demo: compiling the numba functions of the simulation, once (later runs load them "
                       "from the cache) ...")
    assert re.fullmatch(r"contoursim demo: compiled in \d+\.\d s", said[-1]) and len(said) == 2
    again = subprocess.run([sys.executable, "-m", "contoursim", "demo", "--out", str(tmp_path / "out")], cwd=ROOT,
                           env=env, capture_output=True, text=True)
    assert again.returncode == 0 and again.stderr == ""


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


def test_a_long_run_is_said_before_it_starts(tmp_path, capsys, monkeypatch):
    """A slow feed on a small circle (8,900 s of motion, 44 M servo periods) ran for minutes and 20 GB without a
    word. Beyond a threshold (lowered here below this run's 9,520 periods) its length, periods and memory are said
    first."""
    import contoursim.cli

    (tmp_path / "small.toml").write_text(SMALL_PATH)
    monkeypatch.setattr(contoursim.cli, "_LONG_RUN", 1000)
    assert main(["simulate", str(tmp_path / "small.toml"), "--machine", "demo_mill", "--out", str(tmp_path / "o")]) == 0
    said = [line for line in capsys.readouterr().err.splitlines() if "servo periods of" in line]
    assert len(said) == 1 and said[0].startswith("contoursim: the run lasts ") and said[0].endswith(
        "GB of memory: this takes minutes"), said
    monkeypatch.setattr(contoursim.cli, "_LONG_RUN", 10**9)
    assert main(["simulate", str(tmp_path / "small.toml"), "--machine", "demo_mill", "--out", str(tmp_path / "p")]) == 0
    assert "servo periods of" not in capsys.readouterr().err


def test_unknown_job_key_names_file_and_line(tmp_path, capsys):
    (tmp_path / "job.toml").write_text('machine = "demo_mill"\npath = "rounded_square"\nspeed = 3\n')
    assert main(["simulate", str(tmp_path / "job.toml"), "--out", str(tmp_path / "o")]) == 2
    assert f"{tmp_path / 'job.toml'}, line 3: unknown key 'speed'" in capsys.readouterr().err


def test_bad_servo_value_names_file_line_and_axis(tmp_path, capsys):
    (tmp_path / "m.toml").write_text(MACHINE.format(kp=-1.0))
    assert main(["simulate", "rounded_square", "--machine", str(tmp_path / "m.toml"), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert f"{tmp_path / 'm.toml'}, line 11: axis x: kp_per_s must be positive" in err


def test_keys_without_their_unit_are_refused_with_the_new_name(tmp_path, capsys):
    (tmp_path / "m.toml").write_text(MACHINE.format(kp=40.0).replace("mass_kg", "mass"))
    assert main(["simulate", "rounded_square", "--machine", str(tmp_path / "m.toml"), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert f"{tmp_path / 'm.toml'}, line 7: key 'mass' in [axes.x] is now 'mass_kg' (units in the key name): rename it" in err
    assert "docs/machines-and-files.md, section 'File format'" in err
    job = tmp_path / "job.toml"
    job.write_text('machine = "vertical_mill_3axis"\npath = "iso230_4_circle_ccw"\nwork_offset = { x = 250 }\n')
    assert main(["simulate", str(job), "--out", str(tmp_path / "o")]) == 2
    assert f"{job}, line 3: key 'x' in [work_offset] is now 'x_mm'" in capsys.readouterr().err
    assert not (tmp_path / "o").exists()


def test_unstable_gains_are_reported_with_margins(tmp_path, capsys):
    (tmp_path / "m.toml").write_text(MACHINE.format(kp=900.0))
    assert main(["simulate", "rounded_square", "--machine", str(tmp_path / "m.toml"), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert f"{tmp_path / 'm.toml'}, line 6: the position loop of axis 'x'" in err
    assert "phase margin 16.6 deg" in err and "(kp_per_s = 900): the velocity loop is too slow for it" in err
    assert "none may cross over above 250 Hz: lower kp_per_s, to " in err  # raising kv cannot help at 0.5 ms


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
    assert f"{tmp_path / 'm.toml'}, line 11: axis x: kp_per_s must be a number, got '40'" in capsys.readouterr().err


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
    (tmp_path / "third.toml").write_text(SMALL_PATH)
    (out / "third_errors.png").write_text("mine")  # a plot's name: refused before the run's CSV was written
    assert main(["simulate", str(tmp_path / "third.toml"), "--out", str(out)]) == 2
    assert f"{out / 'third_errors.png'} exists and contoursim did not write it" in capsys.readouterr().err
    assert not (out / "third.csv").exists() and not (out / "third_path.png").exists()


def test_a_program_leaving_the_travel_is_refused_by_the_block_that_leaves_it(tmp_path, capsys):
    """The refusal named the program but not the block (an outside probe)."""
    program = tmp_path / "p.nc"
    program.write_text("G21 G90\nG0 X0 Y0\nG1 X100 F3000\nG1 X2000\nM30\n")
    assert main(["simulate", str(program), "--machine", "vertical_mill_3axis", "--out", str(tmp_path / "o")]) == 2
    assert f"{program}, line 4: axis x would move over" in capsys.readouterr().err
    assert not (tmp_path / "o").exists()
    assert main(["compare", str(program), "--machine", "vertical_mill_3axis", "--out", str(tmp_path / "o")]) == 2
    assert f"{program}, line 4: axis x would move over" in capsys.readouterr().err


def test_a_job_work_offset_beyond_the_travel_is_said_at_its_line_in_its_unit(tmp_path, capsys):
    """It blamed the path file, and gave a rotary axis's travel in radians ('-1.91986 .. 1.91986 [mm or rad]')."""
    job = tmp_path / "job.toml"
    for command in ("simulate", "compare"):
        job.write_text('machine = "table_tilting_5axis"\npath = "iso230_4_circle_ccw"\nwork_offset = { a_deg = 1000 }\n')
        assert main([command, str(job), "--out", str(tmp_path / "o")]) == 2
        assert (f"{job}, line 3: work_offset.a_deg = 1000: axis a would move over 1000 .. 1000, outside its travel "
                "-110 .. 110 [deg]: move the path with work_offset") in capsys.readouterr().err
        job.write_text('machine = "vertical_mill_3axis"\npath = "iso230_4_circle_ccw"\n\nwork_offset = { x_mm = 1e7 }\n')
        assert main([command, str(job), "--out", str(tmp_path / "o")]) == 2
        assert (f"{job}, line 4: work_offset.x_mm = 1e+07: axis x would move over 9.99995e+06 .. 1e+07, "
                "outside its travel 0 .. 500 [mm]") in capsys.readouterr().err
    assert not (tmp_path / "o").exists()


def test_job_work_offset_moves_the_path_on_the_machine(tmp_path, capsys):
    job = tmp_path / "job.toml"
    job.write_text('machine = "vertical_mill_3axis"\npath = "iso230_4_circle_ccw"\nwork_offset = { x_mm = 470 }\n')
    assert main(["simulate", str(job), "--out", str(tmp_path / "o")]) == 2
    assert "axis x would move over 420 .. 520, outside its travel 0 .. 500" in capsys.readouterr().err
    job.write_text('machine = "vertical_mill_3axis"\npath = "iso230_4_circle_ccw"\nwork_offset = { w_mm = 1 }\n')
    assert main(["simulate", str(job), "--out", str(tmp_path / "o")]) == 2
    assert f"{job}, line 3: unknown key 'w_mm' in [work_offset]" in capsys.readouterr().err


def test_unwritable_output_gives_one_line(tmp_path, capsys, monkeypatch):
    (tmp_path / "small.toml").write_text(SMALL_PATH)

    def denied(file, *args, **kwargs):
        raise PermissionError(13, "Permission denied", str(file))

    monkeypatch.setattr("contoursim.output.open", denied, raising=False)  # a read-only folder, even for root
    assert main(["simulate", str(tmp_path / "small.toml"), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert err.strip().splitlines() == [f"contoursim simulate: error: cannot write {tmp_path / 'o' / 'small.csv'}: "
                                        "Permission denied"]


def test_ctrl_c_gives_one_line_exit_130_and_no_half_written_file(tmp_path, capsys, monkeypatch):
    (tmp_path / "small.toml").write_text(SMALL_PATH)
    out = tmp_path / "out"

    def interrupted(self, file, metadata=None, every=1):
        file.write("t,x_ref,x\n0,0,0\n")  # a truncated trace that ends on a whole row
        raise KeyboardInterrupt

    monkeypatch.setattr(SimResult, "save_csv", interrupted)
    assert main(["simulate", str(tmp_path / "small.toml"), "--out", str(out)]) == 130
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and err.startswith("contoursim simulate: interrupted")
    assert sorted(p.name for p in out.iterdir()) == [".contoursim-out"]  # nothing half-written, nothing listed
    assert "small.csv" not in (out / ".contoursim-out").read_text()


def test_real_gcode_runs_and_says_in_one_line_what_it_ignored(tmp_path, capsys):
    (tmp_path / "part.nc").write_text("%\nO1234\nN10 G21 G90 G54\nN20 T1 M6\nN30 S12000 M3\nN40 G0 X0 Y0 M8\n"
                                      "N50 G1 X2 F600\nN60 G2 X4 Y0 I1 J0\nN70 M30\n%\n")
    assert main(["simulate", str(tmp_path / "part.nc"), "--out", str(tmp_path / "o")]) == 0
    captured = capsys.readouterr()
    assert captured.err.splitlines() == [f"contoursim simulate: warning: {tmp_path / 'part.nc'}: ignored: G54 (tool "
                                         "length and work offsets: the path is the tool tip's, from the work offset); "
                                         "O1234 T1 S12000 M3 M8 (no contour motion)"]
    assert "part " in captured.out


def test_each_kind_of_file_where_another_is_expected_says_what_was_expected(tmp_path, capsys):
    job, path, machine = tmp_path / "job.toml", tmp_path / "path.toml", tmp_path / "m.toml"
    job.write_text('path = "iso230_4_circle_ccw"\n')  # a job file that forgot its machine
    path.write_text(SMALL_PATH)
    machine.write_text(MACHINE.format(kp=40.0))
    out = ["--out", str(tmp_path / "o")]
    assert main(["simulate", str(job), *out]) == 2
    assert f"{job}: a job file names its machine: add machine = " in capsys.readouterr().err
    assert main(["simulate", "rounded_square", "--machine", str(path), *out]) == 2
    err = capsys.readouterr().err
    assert f"{path}: this is a path file, not a machine file; a machine file describes a machine: " in err
    assert main(["simulate", str(machine), *out]) == 2
    assert f"{machine}: this is a machine file, not a path file; a path file describes a path: " in capsys.readouterr().err
    assert main(["simulate", "rounded_square", "--machine", str(job), *out]) == 2
    assert f"{job}: this is a job file, not a machine file" in capsys.readouterr().err
    spec = ROOT / "examples" / "tune_ccc.toml"  # it was: unknown key 'strategies' (did you mean 'strategy'?)
    assert main(["compare", str(spec), *out]) == 2
    assert f"{spec}, line 14: this is a sweep spec ([sweep] and [[vary]] tables): run it with contoursim sweep" in (
        capsys.readouterr().err)
    job.write_text("")
    assert main(["simulate", "rounded_square", "--machine", str(job), *out]) == 2
    assert f"{job}: the file is empty; a machine file describes a machine" in capsys.readouterr().err
    machine.write_bytes('# Maschine für Prüfung\nname = "x"\n'.encode("latin-1"))
    assert main(["simulate", "rounded_square", "--machine", str(machine), *out]) == 2
    assert f"{machine}, line 1: byte 0xFC is not UTF-8 text" in capsys.readouterr().err
    assert not (tmp_path / "o").exists()


def test_saturation_is_a_warning_naming_run_axis_and_fraction(tmp_path, capsys):
    (tmp_path / "small.toml").write_text(SMALL_PATH)
    (tmp_path / "m.toml").write_text(MACHINE.format(kp="40.0\ncurrent_limit_A = 0.01"))
    assert main(["simulate", str(tmp_path / "small.toml"), "--machine", str(tmp_path / "m.toml"),
                 "--out", str(tmp_path / "o")]) == 0
    err = capsys.readouterr().err.splitlines()
    assert len(err) == 1 and err[0].startswith("contoursim simulate: warning: small: the current command hit its "
                                               "limit on axis x in ")
    assert err[0].endswith("% of the samples (limit ±0.01 A): the errors include the saturation")


def _but_compiling(stderr):
    """The lines of `stderr` but the ones saying that numba compiles (a first run, the cache cold)."""
    return [line for line in stderr.splitlines() if not re.match(r"contoursim \w+: compil(ing|ed) ", line)]


@pytest.mark.parametrize("where", ["root", "elsewhere"])
def test_the_command_as_a_user_runs_it(where, tmp_path):
    """``python -m contoursim`` in a fresh process, from the repository root and from another folder."""
    cwd = ROOT if where == "root" else tmp_path
    env = {**os.environ, "PYTHONPATH": str(ROOT)}  # this checkout's contoursim, as if installed
    env.pop("PYTHONUNBUFFERED", None)  # output buffered, as in a user's pipe
    run = lambda *args: subprocess.run([sys.executable, "-m", "contoursim", *args], cwd=cwd, env=env,  # noqa: E731
                                       capture_output=True, text=True, timeout=300)
    helped = run("--help")
    assert helped.returncode == 0 and "simulate" in helped.stdout and not helped.stderr
    (tmp_path / "small.toml").write_text(SMALL_PATH)
    done = run("simulate", str(tmp_path / "small.toml"), "--out", str(tmp_path / "out"))
    assert done.returncode == 0, done.stderr
    # the whole table and the last line through a pipe: the program flushes before its hard exit (cli.run)
    assert "small " in done.stdout and not _but_compiling(done.stderr)  # a first run (a cold cache) says it compiles
    assert done.stdout.endswith(f"plots and traces written to {tmp_path / 'out'}/\n")
    failed = run("simulate", str(tmp_path / "missing.toml"), "--out", str(tmp_path / "out2"))
    assert failed.returncode == 2 and failed.stderr.startswith("contoursim simulate: error: ") and not failed.stdout
    # the reader of the output gone before the first line (as in `contoursim simulate ... | head`), each line
    # written at once (python -u): no traceback
    piped = subprocess.Popen([sys.executable, "-u", "-m", "contoursim", "simulate", str(tmp_path / "small.toml"),
                              "--out", str(tmp_path / "out3")], cwd=cwd, env=env, stdout=subprocess.PIPE,
                             stderr=subprocess.PIPE)  # fmt: skip
    piped.stdout.close()
    assert piped.wait(timeout=300) == 1 and piped.stderr.read() == b""
    assert (tmp_path / "out3" / "small.csv").exists()  # written before the table is printed
    closed = subprocess.run([sys.executable, "-m", "contoursim", "simulate", str(tmp_path / "small.toml"), "--out",
                             str(tmp_path / "out4")], cwd=cwd, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                            preexec_fn=lambda: os.close(1), timeout=300)  # started without a stdout
    assert closed.returncode == 0 and closed.stderr == b"" and (tmp_path / "out4" / "small.csv").exists()
    if os.path.exists("/dev/full"):  # the table to a file on a full disk, buffered as a user's is: said, no traceback
        with open("/dev/full", "w") as full:
            lost = subprocess.run([sys.executable, "-m", "contoursim", "simulate", str(tmp_path / "small.toml"), "--out",
                                   str(tmp_path / "out6")], cwd=cwd, env=env, stdout=full, stderr=subprocess.PIPE,
                                  timeout=300)  # fmt: skip
        assert lost.returncode == 2 and (tmp_path / "out6" / "small.csv").exists()
        assert _but_compiling(lost.stderr.decode()) == ["contoursim: error: cannot write to standard output: No space "
                                                        "left on device; the files written are complete"]
    # a terminal that cannot show µ or — (an ASCII or C locale): their escapes, not an error after the work
    ascii_env = {**env, "PYTHONIOENCODING": "ascii"}
    plain = subprocess.run([sys.executable, "-m", "contoursim", "simulate", str(tmp_path / "small.toml"), "--out",
                            str(tmp_path / "out5")], cwd=cwd, env=ascii_env, capture_output=True, timeout=300)
    assert plain.returncode == 0 and not _but_compiling(plain.stderr.decode("ascii"))
    assert plain.stdout.decode("ascii").startswith("contoursim simulate \\u2014 machine: ")
    assert read_trace(tmp_path / "out" / "small.csv").axes == ("x", "y")
    imported = subprocess.run([sys.executable, "-c", "import contoursim; print(contoursim.__file__)"], cwd=cwd, env=env,
                              capture_output=True, text=True, timeout=60)
    assert imported.stdout.strip() == str(ROOT / "contoursim" / "__init__.py")  # this checkout was tested


def test_help_and_import_leave_the_heavy_libraries_unloaded():
    """``contoursim --help`` and ``import contoursim`` answer at once: no python-control, scipy, numba or matplotlib."""
    heavy = ("control", "scipy", "numba", "matplotlib")
    code = ("import sys\nfrom contoursim.cli import main\nimport contoursim\n"
            "try:\n    main(['--help'])\nexcept SystemExit:\n    pass\n"
            f"print([m for m in {heavy!r} if m in sys.modules])\n"
            "from contoursim import simulate, Machine\n"
            "import contoursim.simulation\n"
            "print(contoursim.simulate is contoursim.simulation.simulate, Machine.__name__)\n")
    done = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    assert done.stdout.splitlines()[-2:] == ["[]", "True Machine"]  # lazy names are the objects, not submodules


def test_compare_prints_the_table_and_writes_the_json_and_plots(tmp_path, capsys):
    import json

    from contoursim.compensation import STRATEGY_NAMES

    path = tmp_path / "small.toml"
    path.write_text(SMALL_PATH)
    report = tmp_path / "r.json"
    assert main(["compare", str(path), "--json", str(report), "--out", str(tmp_path / "out")]) == 0
    table = capsys.readouterr().out
    runs = json.loads(report.read_text())["runs"]
    assert list(runs) == list(STRATEGY_NAMES)  # the contract's names, in order
    contract = {"contour_max_um", "contour_rms_um", "tracking_max_um", "tracking_rms_um", "peak_current_A", "saturated"}
    for name, figures in runs.items():
        assert contract <= set(figures)  # the contract's keys stay; fields are only added
        assert isinstance(figures["saturated"], bool) and figures["peak_current_A"] > 0
        row = next(line for line in table.splitlines() if line.split()[:1] == [name])
        shown = row.split()[1]  # to the nm; below half a nm the table says so (zpetc's 0.49999 nm on this circle)
        assert (figures["contour_max_um"] < 5e-4 if shown == "<0.001"
                else float(shown) == pytest.approx(figures["contour_max_um"], abs=5e-4))
        assert figures["clamped_pct"] == 0.0  # the demo mill has no current limit
    assert runs["feedforward+ccc_arc"]["contour_max_um"] < 0.1 * runs["none"]["contour_max_um"]
    # the settings each strategy ran with, and the coupled loop's margins beside the axes'
    assert runs["zpetc"]["settings"] == {"zpetc": {"negative_zero_radius": 0.5, "preview_samples": 2}}
    arc = runs["ccc_arc"]
    assert arc["gains"] == "designed" and arc["coupled_loop"]["damping_ratio"] >= 0.2
    assert set(arc["settings"]["ccc_arc"]) == {"kp_per_s", "ki_per_s2", "kd"}
    assert f"kp_per_s = {arc['settings']['ccc_arc']['kp_per_s']:.4g}" in table
    assert "axis position loops (sampled): x: phase margin" in table
    assert set(json.loads(report.read_text())["axes"]) == {"x", "y", "z"}
    for kind in ("path", "zoom", "contour", "table"):
        assert (tmp_path / "out" / f"small_compare_{kind}.png").stat().st_size > 10_000
    # a second run replaces its own JSON; a file that is not a comparison is never overwritten
    assert main(["compare", str(path), "--strategies", "none, ccc_arc", "--json", str(report),
                 "--out", str(tmp_path / "out")]) == 0
    assert list(json.loads(report.read_text())["runs"]) == ["none", "ccc_arc"]
    keep = tmp_path / "notes.json"
    keep.write_text('{"mine": 1}')
    capsys.readouterr()
    assert main(["compare", str(path), "--json", str(keep), "--out", str(tmp_path / "out")]) == 2
    assert "notes.json exists and is not a comparison JSON" in capsys.readouterr().err
    assert keep.read_text() == '{"mine": 1}'


def test_compare_writes_its_files_before_a_reader_can_go(tmp_path, monkeypatch):
    """``contoursim compare ... | head -1``: the JSON and the plots are written before the table is printed."""
    import json

    path = tmp_path / "small.toml"
    path.write_text(SMALL_PATH)
    report = tmp_path / "r.json"
    monkeypatch.setattr(sys, "stdout", reader_gone := ReaderGone())
    with pytest.raises(BrokenPipeError):
        main(["compare", str(path), "--strategies", "none,ccc_arc", "--json", str(report), "--out", str(tmp_path / "o")])
    assert reader_gone.text.startswith("contoursim compare — machine: ")
    assert list(json.loads(report.read_text())["runs"]) == ["none", "ccc_arc"]
    assert {p.name for p in (tmp_path / "o").glob("*.png")} == {f"small_compare_{k}.png"
                                                                 for k in ("path", "zoom", "contour", "table")}


def test_a_coupled_loop_without_a_gain_crossover_is_null_in_a_strict_comparison_json(tmp_path, capsys):
    """A coupling gain too small for its loop gain to reach 1 has no phase margin (infinite): the JSON said
    ``Infinity``, which strict readers (JSON.parse, jq) refuse."""
    import json

    path = tmp_path / "small.toml"
    path.write_text(SMALL_PATH)
    report = tmp_path / "r.json"
    assert main(["compare", str(path), "--strategies", "none,ccc_arc", "--set", "ccc_arc.kp_per_s=0.01",
                 "--set", "ccc_arc.ki_per_s2=0", "--json", str(report), "--out", str(tmp_path / "out")]) == 0
    assert " inf " in capsys.readouterr().out  # the table shows it as it is

    def refuse(constant):
        raise ValueError(f"not strict JSON: {constant}")

    loop = json.loads(report.read_text(), parse_constant=refuse)["runs"]["ccc_arc"]["coupled_loop"]
    assert loop["phase_margin_deg"] is None and loop["frames"] > 0


def test_a_json_with_a_reports_key_but_not_its_form_is_the_users_and_never_replaced(tmp_path, capsys):
    """r.json = {"runs": {"my": "notes"}} was replaced by compare --json r.json, the key alone taken for a comparison
    JSON's (and likewise residual_rms_before_um for diagnose --report, failed for --summary)."""
    import json

    (tmp_path / "small.toml").write_text(SMALL_PATH)
    night, other = (ROOT / "examples" / "fleet" / f"night_2026-10-{day}.csv" for day in ("05", "12"))
    compare = ["compare", str(tmp_path / "small.toml"), "--strategies", "none", "--json"]
    report = tmp_path / "r.json"
    assert main([*compare, str(report), "--out", str(tmp_path / "out")]) == 0
    ours = json.loads(report.read_text())
    cases = [(compare, {"runs": {"my": "notes"}}, "a comparison JSON"),
             (compare, {**ours, "runs": {"none": {"my": "notes"}}}, "a comparison JSON"),  # not a run of its
             (["diagnose", str(night), "--report"], {"residual_rms_before_um": 1.0, "my": "notes"},
              "a diagnosis report"),
             (["diagnose", str(night), str(other), "--summary"], {"failed": [], "my": "notes"}, "a fleet summary")]
    for argv, mine, what in cases:
        report.write_text(json.dumps(mine))
        assert main([*argv, str(report), "--out", str(tmp_path / "out")]) == 2
        assert f"r.json exists and is not {what}; refusing to overwrite it" in capsys.readouterr().err
        assert json.loads(report.read_text()) == mine
    # its own report with the user's notes added is theirs now (an outside probe: the notes were lost)
    report.write_text(json.dumps({**ours, "notes": "operator: bob, spindle warm"}))
    assert main([*compare, str(report), "--out", str(tmp_path / "out")]) == 2
    assert ("r.json exists and is not a comparison JSON as contoursim writes it (it holds 'notes' besides); refusing "
            "to overwrite it") in capsys.readouterr().err
    report.write_text(json.dumps(ours))  # its own is replaced
    assert main([*compare, str(report), "--out", str(tmp_path / "out")]) == 0
    # so is a diagnosis report as diagnose writes it (its keys kept in step with the form its --report replaces), not
    # with a note added
    diagnosis = tmp_path / "d.json"
    argv = ["diagnose", str(night), "--model", str(night.parent / "nightly_mill.toml"), "--report", str(diagnosis)]
    assert main([*argv, "--out", str(tmp_path / "d")]) == 0
    written = json.loads(diagnosis.read_text())
    assert has_form(written, REPORT_FORM, REPORT_OPTIONAL)
    diagnosis.write_text(json.dumps({**written, "my_notes": "spindle warm"}))
    assert main([*argv, "--out", str(tmp_path / "d2")]) == 2
    assert "(it holds 'my_notes' besides)" in capsys.readouterr().err


def test_a_coupling_on_one_axis_or_two_couplings_are_refused_without_advice_on_gains(tmp_path, capsys):
    """On a one-axis machine a coupling's design ended in numpy's 'matmul: Input operand 1 has a mismatch in its core
    dimension 0', and two couplings in one composition were told to set their gains or tune them (an outside probe)."""
    (tmp_path / "m.toml").write_text(MACHINE.format(kp=40.0).split("[axes.y]")[0])
    (tmp_path / "line.toml").write_text('[feed]\nfeed_mm_min = 1200\n[path]\ntype = "polyline"\n'
                                        'points_mm = [[0, 0], [50, 0]]\n')
    argv = ["compare", str(tmp_path / "line.toml"), "--machine", str(tmp_path / "m.toml")]
    assert main([*argv, "--strategies", "ccc_arc", "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert err.strip().endswith("error: --strategies ccc_arc: ccc_arc: cross-coupled control needs 2 or 3 servo axes, "
                                "the machine has 1 (x)"), err
    assert main([*argv, "--out", str(tmp_path / "out2")]) == 0
    assert ("left out: ccc_linear, ccc_arc, feedforward+ccc_arc — ccc_linear: cross-coupled control needs 2 or 3 servo "
            "axes, the machine has 1 (x)\n") in capsys.readouterr().out
    assert main(["compare", str(tmp_path / "line.toml"), "--strategies", "ccc_arc+ccc_linear",
                 "--out", str(tmp_path / "out3")]) == 2
    assert capsys.readouterr().err.strip().endswith("strategies ccc_arc and ccc_linear are both a coupling: choose one")


def test_compare_leaves_out_the_couplings_a_machine_allows_no_designed_gains_and_runs_the_rest(tmp_path, capsys):
    """Axis loops damped below 0.7 (kp 80/s on the 0.5 ms machine: 0.64) leave the coupling no designed gains: the
    whole comparison ended in 'set the coupling gains kp, ki' (an outside probe). The default set runs the other
    strategies and says what it left out and how to give the gains; asked for by name, a coupling is refused so."""
    (tmp_path / "m.toml").write_text(MACHINE.format(kp=80.0).replace("kp_per_s = 40.0", "kp_per_s = 80.0"))
    (tmp_path / "small.toml").write_text(SMALL_PATH)
    argv = ["compare", str(tmp_path / "small.toml"), "--machine", str(tmp_path / "m.toml")]
    assert main([*argv, "--out", str(tmp_path / "out")]) == 0
    out = capsys.readouterr().out
    assert ("left out: ccc_linear, ccc_arc, feedforward+ccc_arc — the coupled loop is damped at 0.6" in out
            and "(--set ccc_linear.kp_per_s=... --set ccc_linear.ki_per_s2=..., or a [[strategy]] table), or tune them"
            in out)
    rows = [line.split()[0] for line in out.splitlines()[out.splitlines().index(next(
        x for x in out.splitlines() if x.startswith("---"))) + 1:] if line and not line.startswith("plots")]
    assert rows == ["none", "feedforward", "zpetc"]
    assert main([*argv, "--strategies", "none,ccc_arc", "--out", str(tmp_path / "out")]) == 2
    assert "error: --strategies ccc_arc: the coupled loop is damped at 0.6" in capsys.readouterr().err
    assert main([*argv, "--strategies", "none,ccc_arc", "--set", "ccc_arc.kp_per_s=20", "--set",
                 "ccc_arc.ki_per_s2=900", "--out", str(tmp_path / "out")]) == 0  # given gains: run


def test_compare_takes_strategy_settings_from_the_job_file_and_the_command_line(tmp_path, capsys):
    import json

    (tmp_path / "small.toml").write_text(SMALL_PATH)
    job = tmp_path / "job.toml"
    job.write_text('machine = "demo_mill"\npath = "small.toml"\n\n[[strategy]]\nname = "ccc_arc"\n'
                   'kp_per_s = 30.0\n')
    report = tmp_path / "r.json"
    assert main(["compare", str(job), "--strategies", "ccc_arc,ccc_linear", "--set", "ccc_arc.ki_per_s2=500",
                 "--set", "ccc_linear.kp_per_s=40", "--set", "ccc_linear.ki_per_s2=0", "--json", str(report),
                 "--out", str(tmp_path / "out")]) == 0
    table = capsys.readouterr().out
    runs = json.loads(report.read_text())["runs"]
    assert runs["ccc_arc"]["settings"]["ccc_arc"] == {"kp_per_s": 30.0, "ki_per_s2": 500, "kd": 0.0}
    assert runs["ccc_linear"]["settings"]["ccc_linear"] == {"kp_per_s": 40, "ki_per_s2": 0, "kd": 0.0}
    assert runs["ccc_arc"]["gains"] == runs["ccc_linear"]["gains"] == "set"
    assert "ccc_arc, ccc_linear set by the job file or --set" in table
    assert "ccc_arc: kp_per_s = 30, ki_per_s2 = 500, kd = 0" in table


@pytest.mark.parametrize("tables, options, message", [
    ('[[strategy]]\nname = "ccc_arc"\nkp = 30.0\n', [], "job.toml, line 6: unknown key 'kp' in the 1st [[strategy]]"),
    ('[[strategy]]\nname = "ccc_arc"\nkp_per_s = -3.0\n', [], "job.toml, line 6: [[strategy]] ccc_arc: kp_per_s must be"),
    ('[[strategy]]\nname = "pid"\n', [], "job.toml, line 5: [[strategy]] needs name = one of 'feedforward', 'zpetc'"),
    ("", ["--set", "ccc_arc.kp=3"], "--set ccc_arc.kp=3: unknown setting 'kp' of ccc_arc; expected one of kp_per_s"),
    ("", ["--set", "ccc_arc.kp_per_s=fast"], "--set ccc_arc.kp_per_s=fast: 'fast' is not a number"),
    ("", ["--set", "zpetc.negative_zero_radius=2"], "negative_zero_radius must be between 0 and 1"),
    ("", ["--set", "ccc_arc.kp_per_s=3", "--tune"], "tuning sets the coupling's kp_per_s and ki_per_s2: ccc_arc.kp_per_s is set"),
    ("", ["--set", "ccc_arc.kp_per_s=3000"], "the coupled loop of axes x, y, z is unstable"),
    # "(the axes' own loops are that little damped)": the kd set was the cause
    ("", ["--set", "ccc_arc.kd=5"], "even with kp = 0.36 1/s (with kd = 5: lower it): set the coupling gains"),
    # the first dropped without a word
    ("", ["--set", "ccc_arc.kp_per_s=50", "--set", "ccc_arc. kp_per_s = 60"],
     "--set ccc_arc.kp_per_s is given twice (ccc_arc.kp_per_s=50, ccc_arc. kp_per_s = 60): give it once"),
    # a setting or a tuning of a strategy that does not run was dropped without a word
    ("", ["--set", "feedforward.velocity_fraction=0.5"], "--set feedforward.velocity_fraction=0.5: no strategy run here "
                                                         "has 'feedforward' (--strategies none,ccc_arc): run it, or drop"),
    ("", ["--strategies", "none,feedforward", "--tune"], "--tune tunes a cross-coupled strategy's gains; none runs here "
                                                         "(--strategies none,feedforward)"),
    ('[[strategy]]\nname = "feedforward"\nvelocity_fraction = 0.5\n', [],
     "job.toml, line 5: [[strategy]] feedforward: no strategy run here has it (strategies none,ccc_arc): run it, or drop"),
])
def test_compare_refuses_bad_strategy_settings_naming_the_place(tmp_path, capsys, tables, options, message):
    (tmp_path / "small.toml").write_text(SMALL_PATH)
    job = tmp_path / "job.toml"
    job.write_text(f'machine = "demo_mill"\npath = "small.toml"\n\n{tables}')
    assert main(["compare", str(job), "--strategies", "none,ccc_arc", *options, "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert message in err and "Traceback" not in err
    assert not (tmp_path / "out").exists()


def test_compare_tune_tunes_each_coupled_strategy_under_the_check(tmp_path, capsys):
    import json

    from contoursim.comparison import TUNE_KP_START

    (tmp_path / "small.toml").write_text(SMALL_PATH)
    report = tmp_path / "r.json"
    assert main(["compare", str(tmp_path / "small.toml"), "--strategies", "none,ccc_linear", "--tune",
                 "--json", str(report), "--out", str(tmp_path / "out")]) == 0
    table = capsys.readouterr().out
    run = json.loads(report.read_text())["runs"]["ccc_linear"]
    assert run["gains"] == "tuned" and "ccc_linear tuned on this path" in table
    assert run["coupled_loop"]["phase_margin_deg"] >= 30 and run["coupled_loop"]["damping_ratio"] >= 0.2
    assert run["settings"]["ccc_linear"]["kp_per_s"] >= TUNE_KP_START * 36.0 / 2**0.5  # from the search's grid


@pytest.mark.parametrize("strategies, message", [
    ("none,pid", "unknown strategy 'pid'"),
    ("feedforward+zpetc", "feedforward and zpetc are both a feedforward"),
    ("none,none", "strategy 'none' is named twice"),
    ("none+none", "strategy 'none' is named twice in 'none+none'"),  # ran as a strategy called 'none+none'
    ("feedforward+ccc_arc,ccc_arc+feedforward", "strategy 'ccc_arc+feedforward' is 'feedforward+ccc_arc', named "
                                                "twice"),  # the same run twice, two rows alike
    ("none+feedforward", "'none' in 'none+feedforward': none is no compensation"),  # ran labelled so, feedforward alone
    ("geometric", "needs a machine with a geometric error model"),
    (" , ", "argument --strategies: names no strategy; got ' , '"),  # the API's message named no option
])
def test_compare_refuses_bad_strategy_names(tmp_path, capsys, strategies, message):
    path = tmp_path / "small.toml"
    path.write_text(SMALL_PATH)
    try:
        code = main(["compare", str(path), "--strategies", strategies, "--out", str(tmp_path / "out")])
    except SystemExit as exit_:  # argparse's refusal of the option itself
        code = exit_.code
    assert code == 2
    assert message in capsys.readouterr().err
    assert not (tmp_path / "out").exists()


# Post-processor output as shops run it (written here after the posts' style): header comments with ';' inside,
# '%' lines, a program number, N numbers, G53/G28 G91 Z0 homing, tool changes, M codes, drilling written out as
# G1 plunges and G0 retracts. On the demo machine (Kp: X 40, Y 36, Z 40 1/s) the tracking error of a cut at
# feed v along one axis is v/Kp once the loop has settled (a ramp into a type-1 loop).
FUSION_CONTOUR = """%
O1001 (CONTOUR TEST PART)
(Machine)
(  vendor: Autodesk ; post: fanuc.cps)
(T1 D=6. CR=0. - ZMIN=-5. - flat end mill)
N10 G90 G94 G17
N15 G21
N20 G53 G0 Z0.
(2D Contour1 ; outside profile, climb)
N25 T1 M6
N30 S8000 M3
N35 G54
N40 M8
N45 G0 X-38. Y-10.
N50 G43 Z15. H1
N55 G0 Z5.
N60 G1 Z1. F1000.
N65 Z-5. F300.
N70 G1 X-35. F600.
N75 Y10.
N80 G2 X-25. Y20. I10. J0.
N85 G1 X25.
N90 G2 X35. Y10. I0. J-10.
N95 G1 Y-10.
N100 G2 X25. Y-20. I-10. J0.
N105 G1 X-25.
N110 G2 X-35. Y-10. I0. J10.
N115 G1 X-38.
N120 Z5. F1000.
N125 G0 Z15.
N130 M9
N135 M5
N140 G53 G0 Z0.
N145 M30
%
"""

FUSION_DRILL_CONTOUR = """%
O1002 (DRILL AND CONTOUR)
(T2 D=5. CR=0. TAPER=118deg - ZMIN=-8. - drill)
(T1 D=6. CR=0. - ZMIN=-3. - flat end mill)
N10 G90 G94 G17 G49 G40 G80
N15 G21
N20 G28 G91 Z0.
N25 G90
(Drill1 ; 4 holes, expanded: G1 plunges and G0 retracts)
N30 T2 M6
N35 S3000 M3
N40 G54
N45 M8
N50 G0 X-20. Y-10.
N55 G43 Z15. H2
N60 G0 Z5.
N65 G1 Z-8. F150.
N70 G0 Z5.
N75 X20.
N80 G1 Z-8. F150.
N85 G0 Z5.
N90 Y10.
N95 G1 Z-8. F150.
N100 G0 Z5.
N105 X-20.
N110 G1 Z-8. F150.
N115 G0 Z5.
N120 Z15.
N125 M9
N130 M5
N135 G28 G91 Z0.
N140 G90
M1
(2D Contour2 ; pocket wall)
N145 T1 M6
N150 S10000 M3
N155 G54
N160 M8
N165 G0 X0. Y-15.
N170 G43 Z15. H1
N175 G0 Z5.
N180 G1 Z1. F1000.
N185 Z-3. F250.
N190 G1 X25. F800.
N195 G3 X30. Y-10. I0. J5.
N200 G1 Y10.
N205 G3 X25. Y15. I-5. J0.
N210 G1 X-25.
N215 G3 X-30. Y10. I0. J-5.
N220 G1 Y-10.
N225 G3 X-25. Y-15. I5. J0.
N230 G1 X0.
N235 Z5. F1000.
N240 G0 Z15.
N245 M9
N250 M5
N255 G28 G91 Z0.
N260 G90
N265 G28 G91 X0. Y0.
N270 G90
N275 M30
%
"""

OPENBUILDS_SPOILBOARD = """; OpenBuilds CAM - spoilboard surfacing 80 x 40 mm
; Tool: 25 mm surfacing bit (T1 ; flat) - Feed 1500 mm/min, two passes
G21 ; mm
G90 ; absolute
(Operation 0: Pocket ; spoilboard, stepover 20 mm)
M3 S18000
G4 P1 ; spindle spin-up
G0 Z10
G0 X0 Y0
; pass 1 of 2 (z -0.5)
G1 Z-0.5 F300
G1 X80 F1500
G1 Y20
G1 X0
G1 Y40
G1 X80
G0 Z10
G0 X0 Y0
; pass 2 of 2 (z -1)
G1 Z-1 F300
G1 X80 F1500
G1 Y20
G1 X0
G1 Y40
G1 X80
G0 Z10
G0 X0 Y0
M5
M30
"""


def _blocks_csv(file):
    import csv

    with open(file, newline="", encoding="utf-8") as stream:
        return list(csv.DictReader(stream))


@pytest.mark.parametrize("name, program, tracking_um, steady, rapids", [
    # the largest cutting feed on an axis: the retracts G1 Z5. F1000. on Z, 16.67 mm/s / 40; one operation,
    # positioned before its first cut and left after its last: no rapid in between
    ("contour.nc", FUSION_CONTOUR, 1000 / 60 / 40, {"N85 G1 X25.": 10 / 40, "N95 G1 Y-10.": 10 / 36}, False),
    ("drill_contour.tap", FUSION_DRILL_CONTOUR, 1000 / 60 / 40,
     {"N65 G1 Z-8. F150.": 2.5 / 40, "N110 G1 Z-8. F150.": 2.5 / 40, "N210 G1 X-25.": 800 / 60 / 40,
      "N200 G1 Y10.": 800 / 60 / 36}, True),
    # 25 mm/s along Y: 25 / 36
    ("spoilboard.gcode", OPENBUILDS_SPOILBOARD, 25 / 36, {"G1 X0": 25 / 40, "G1 Y40": 25 / 36}, True),
])
def test_post_processor_programs_score_their_cutting_moves(tmp_path, capsys, name, program, tracking_um, steady, rapids):
    """Tracking error over the cutting moves is v/Kp at the cutting feeds; the rapids (~4 mm behind) are not scored."""
    file = tmp_path / name
    file.write_text(program)
    out = tmp_path / "out"
    assert main(["simulate", str(file), "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    stem = file.stem
    row = next(line for line in printed.splitlines() if line.startswith(f"{stem} "))
    assert float(row.split()[1]) == pytest.approx(1e3 * tracking_um, rel=1e-3)
    assert "G-code: Fanuc/LinuxCNC/GRBL mill dialect" in printed and "the rapids (G0, rapid = 1) are not scored" in printed
    # every block in NAME_blocks.csv (listed in the marker), cutting blocks first, worst contour error first
    assert f"{stem}_blocks.csv" in (out / ".contoursim-out").read_text().splitlines()
    blocks = _blocks_csv(out / f"{stem}_blocks.csv")
    cutting = [b for b in blocks if b["rapid"] == "0"]
    assert [b["rapid"] for b in blocks] == sorted(b["rapid"] for b in blocks)
    contour = [float(b["contour_max_um"]) for b in cutting]
    assert contour == sorted(contour, reverse=True)
    texts = [line.strip() for line in program.splitlines()]
    for b in blocks:
        assert texts[int(b["line"]) - 1] == b["block"]
    by_text = {b["block"]: b for b in cutting}
    for text, expected in steady.items():  # long moves at one feed along one axis reach v/Kp
        assert float(by_text[text]["tracking_max_um"]) == pytest.approx(1e3 * expected, rel=1e-3)
    assert max(float(b["tracking_max_um"]) for b in cutting) == pytest.approx(1e3 * tracking_um, rel=1e-3)
    rapid = [float(b["tracking_max_um"]) for b in blocks if b["rapid"] == "1"]
    assert (max(rapid, default=0.0) > 2000) == rapids  # 10,000 mm/min: ~4 mm behind, where nothing cuts
    # the table's first block row is the CSV's first
    head = printed.split(f"every block in {stem}_blocks.csv)\n")[1].splitlines()
    assert head[1].split()[0] == cutting[0]["line"] and head[1].endswith(cutting[0]["block"])
    # the trace marks the rapids: the summary is over measuring = 1, never on a rapid
    lines = [line for line in (out / f"{stem}.csv").read_text().splitlines() if not line.startswith("#")]
    data = np.genfromtxt(lines, delimiter=",", names=True)
    assert data["rapid"].any() == rapids and not (data["rapid"].astype(bool) & data["measuring"].astype(bool)).any()
    tracking = np.hypot(np.hypot(data["x"] - data["x_ref"], data["y"] - data["y_ref"]), data["z"] - data["z_ref"])
    assert tracking[data["measuring"] == 1].max() == pytest.approx(tracking_um, abs=2e-6)
    assert tracking[data["rapid"] == 1].max(initial=0.0) > 2.0 if rapids else tracking.max() < 1.0


def test_a_jobs_feed_overrides_the_programs_f_words_and_every_output_says_the_feed_that_ran(tmp_path, capsys):
    """A job's feed_mm_min on a G-code program is a feed override of its cutting blocks: the rapids keep the rapid feed,
    the block listing gives the feed that ran (it gave the F words while the job's feed ran), the table says so."""
    (tmp_path / "p.nc").write_text("G21 G90 G17\nG1 X10 F600\nG0 X70\nG1 Y10 F1200\nG2 X60 Y10 I-5 J0\nM30\n")
    (tmp_path / "job.toml").write_text('machine = "demo_mill"\npath = "p.nc"\n[feed]\nfeed_mm_min = 300\n')
    for command in ("simulate", "compare"):
        assert main([command, str(tmp_path / "job.toml"), "--out", str(tmp_path / command)]) == 0
        assert ("feed: 300 mm/min from job.toml's [feed], overriding the program's F words on every cutting block"
                in capsys.readouterr().out)
    blocks = _blocks_csv(tmp_path / "simulate" / "p_blocks.csv")
    assert {(b["rapid"], b["feed_mm_min"]) for b in blocks} == {("0", "300"), ("1", "10000")}
    lines = [line for line in (tmp_path / "simulate" / "p.csv").read_text().splitlines() if not line.startswith("#")]
    data = np.genfromtxt(lines, delimiter=",", names=True)
    speed = np.r_[0.0, np.hypot(np.diff(data["x_ref"]), np.diff(data["y_ref"])) / np.diff(data["t"])]
    assert speed[data["measuring"] == 1].max() == pytest.approx(300 / 60, abs=0.02)  # positions to the nm, dt 0.2 ms
    assert speed[data["rapid"] == 1].max() == pytest.approx(10000 / 60, rel=1e-3)


def test_compare_runs_a_job_with_geometric_compensation(tmp_path, capsys):
    """The README's own job (examples/iso_circle_on_mill.toml): its geometric compensation is one more strategy."""
    import json

    report = tmp_path / "r.json"
    job = ROOT / "examples" / "iso_circle_on_mill.toml"
    assert main(["compare", str(job), "--strategies", "none,feedforward", "--json", str(report),
                 "--out", str(tmp_path / "out")]) == 0
    runs = json.loads(report.read_text())["runs"]
    assert list(runs) == ["none", "feedforward", "geometric"]
    assert runs["geometric"]["contour_max_um"] < runs["none"]["contour_max_um"]
    # a strategy that composes it already: not added twice
    assert main(["compare", str(job), "--strategies", "none,geometric+feedforward", "--json", str(report),
                 "--out", str(tmp_path / "out")]) == 0
    assert list(json.loads(report.read_text())["runs"]) == ["none", "geometric+feedforward"]
    # a composition's name longer than the column keeps the table in line (it pushed its row's figures right)
    capsys.readouterr()
    assert main(["compare", str(job), "--strategies", "none,feedforward+ccc_linear+geometric",
                 "--out", str(tmp_path / "out")]) == 0
    lines = capsys.readouterr().out.splitlines()
    head = next(line for line in lines if line.startswith("strategy"))
    rows = [line for line in lines if line.split()[:1] in (["none"], ["feedforward+ccc_linear+geometric"])]
    end = head.index("contour max") + len("contour max")
    assert len(rows) == 2 and all(row[end - 1] != " " and row[end] == " " for row in rows)


def test_a_ballbar_job_runs_the_circle_both_ways_and_subtracts_the_nominal_run(tmp_path, capsys):
    """The job's circle CCW and CW: one polar plot of both, one of each minus the run without the job's effects.

    On the machine without effects the difference is zero (the nominal run is that run); a 100 µrad
    squareness on the 2 mm circle adds R·α = 0.2 µm peak to peak, both ways (closed form, as in
    examples/effects_gallery.py).
    """
    (tmp_path / "small.toml").write_text(SMALL_PATH)
    (tmp_path / "two.toml").write_text(MACHINE.format(kp=36.0))  # a gain mismatch: an ellipse both runs share
    job = 'machine = "two.toml"\npath = "small.toml"\n[ballbar]\nsubtract_nominal = true\n'
    square = '[[effect]]\nname = "squareness"\naxis = "xy"\nangle_urad = 100.0\n'
    for name, text in (("plain", job), ("square", job + square)):
        (tmp_path / f"{name}.toml").write_text(text)
        assert main(["simulate", str(tmp_path / f"{name}.toml"), "--out", str(tmp_path / name)]) == 0
        out = capsys.readouterr().out
        assert {"small_ccw.csv", "small_cw.csv", "small_polar.png", "small_polar_difference.png", "small_cw_path.png"} \
            <= {p.name for p in (tmp_path / name).iterdir()}
        for direction in ("ccw", "cw"):
            circularity = float(re.search(rf"small_{direction} \({direction.upper()}\): circularity ([\d.]+) µm", out)[1])
            difference = float(re.search(rf"small_{direction} .*minus the nominal run: range ([\d.]+) µm", out)[1])
            assert circularity > 1.0  # the gain mismatch's ellipse
            assert difference == pytest.approx(0.0 if name == "plain" else 0.2, abs=0.01)


@pytest.mark.parametrize("text, message", [
    ('path = "small.toml"\n[ballbar]\ndirections = ["up"]\n', r"job.toml, line 4: directions must be a list of \"ccw\""),
    ('path = "small.toml"\n[ballbar]\nsubtract_nominal = 1\n', r"job.toml, line 4: subtract_nominal must be true or false"),
    ('path = "small.toml"\n[ballbar]\nturns = 2\n', r"job.toml, line 4: unknown key 'turns'"),
    ('path = "rounded_square"\n[ballbar]\n', r"job.toml, line 3: \[ballbar\] needs a circular test: rounded_square.toml"),
])  # fmt: skip
def test_a_bad_ballbar_table_names_file_and_line(tmp_path, capsys, text, message):
    (tmp_path / "small.toml").write_text(SMALL_PATH)
    (tmp_path / "job.toml").write_text('machine = "demo_mill"\n' + text)
    assert main(["simulate", str(tmp_path / "job.toml"), "--out", str(tmp_path / "o")]) == 2
    assert re.search(message, capsys.readouterr().err)
    assert not (tmp_path / "o").exists()


class _Terminal(io.StringIO):
    """A standard error that is a terminal: the progress of a diagnosis rewrites one line there."""

    def isatty(self):
        return True


def test_a_warning_during_a_diagnosis_on_a_terminal_takes_a_line_of_its_own(tmp_path, monkeypatch):
    """The progress line is cleared before a warning (or the compile notice) is printed: it was glued to its end."""
    import warnings

    import contoursim.diagnosis
    from contoursim.exceptions import ContoursimWarning

    def diagnose(trace, model, progress):
        progress("identify: kp = 30.00 1/s")
        warnings.warn("the current command hit its limit", ContoursimWarning)
        raise ValueError("stopped here")

    t = np.arange(50) * 1e-3
    (tmp_path / "m.csv").write_text("t,x_ref,x\n" + "".join(f"{v:.3f},{v:.3f},{v:.3f}\n" for v in t))
    monkeypatch.setattr(contoursim.diagnosis, "diagnose", diagnose)
    monkeypatch.setattr(sys, "stderr", terminal := _Terminal())
    assert main(["diagnose", str(tmp_path / "m.csv"), "--model", "demo_mill", "--out", str(tmp_path / "out")]) == 2
    assert terminal.getvalue().split("\n")[0] == \
        "\ridentify: kp = 30.00 1/s\x1b[K\r\x1b[Kcontoursim diagnose: warning: the current command hit its limit"


def test_strategy_names_are_read_with_spaces_around_commas_and_pluses():
    """Spaces around ',' were stripped, around '+' kept: 'feedforward + ccc_arc' was an unknown strategy."""
    from contoursim.cli import _names

    assert _names(" none , feedforward + ccc_arc ") == ["none", "feedforward+ccc_arc"]
