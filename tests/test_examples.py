"""Every example script runs (examples never rot) and prints what it claims.

Examples that need the measured data beside the repository (../shared) get
it through the ``real_data`` fixture: they fail in CI without it and skip with
a reason elsewhere; run without it, the scripts themselves stop with a message
saying where the data lives.
"""

import re
import runpy
import sys

import numpy as np
import pytest

from conftest import ROOT

from contoursim.output import output_dir

EXAMPLES = ROOT / "examples"
SWEEPS = [EXAMPLES / "tune_ccc.toml"]  # sweep specs: run by contoursim sweep (below)
JOBS = sorted(set(EXAMPLES.glob("*.toml")) - set(SWEEPS))
CHECKED = {"api_tour.py", "estimators_tour.py", "iso230_2_error_table.py", "emps_servo_check.py", "effects_gallery.py",
           "hunting.py", "diagnose_real_traces.py"}  # the last in test_diagnosis.py


def _figure(text, pattern):
    """The number the regular expression `pattern` captures in `text`."""
    match = re.search(pattern, text)
    assert match, f"{pattern!r} not in the output:\n{text}"
    return float(match.group(1))


def test_every_example_script_is_checked_here():
    assert {p.name for p in EXAMPLES.glob("*.py")} == CHECKED


def _contour_within_tracking(folder):
    """Every trace CSV in `folder`: the contour column never above the distance of the tool from its reference."""
    files = sorted(folder.glob("*.csv"))
    for csv in files:
        header, *rows = [line for line in csv.read_text().splitlines() if not line.startswith("#")]
        data = dict(zip(header.split(","), np.loadtxt(rows, delimiter=",", ndmin=2).T))
        axes = [name[: -len("_ref")] for name in data if name.endswith("_ref")]
        tracking = np.sqrt(sum((data[axis] - data[f"{axis}_ref"]) ** 2 for axis in axes))
        assert np.all(data["contour"] <= tracking + 2e-6), csv.name  # the CSV holds positions to the nm
    return files


def _readme_tour():
    page = (ROOT / "docs" / "api.md").read_text(encoding="utf-8")
    return re.search(r"## API tour\n\n```python\n(.*?)```", page, re.S).group(1)


def test_api_tour_agrees_with_the_readme_prints_v_over_kp_and_runs_twice(tmp_path, monkeypatch, capsys):
    tour = (EXAMPLES / "api_tour.py").read_text(encoding="utf-8")
    script_lines = [line.strip() for line in tour.splitlines()]
    readme_lines = [line.strip() for line in _readme_tour().splitlines() if line.strip()]
    missing = [line for line in readme_lines if line not in script_lines and "output_dir(" not in line]
    assert not missing, f"docs/api.md lines not in examples/api_tour.py: {missing}"

    monkeypatch.chdir(tmp_path)
    for _ in range(2):  # the second run replaces its own files
        exec(compile(_readme_tour(), "docs/api.md", "exec"), {})
        monkeypatch.setattr(sys, "argv", ["api_tour.py", str(tmp_path / "out")])
        runpy.run_path(str(EXAMPLES / "api_tour.py"), run_name="__main__")
    assert {"circle.csv", "circle_path.png"} <= {p.name for p in (tmp_path / "contoursim-out").iterdir()}
    assert _contour_within_tracking(tmp_path / "out")
    printed = capsys.readouterr().out
    # the slower axis (y, Kp = 36 1/s) lags v/Kp behind at 3000 mm/min
    assert _figure(printed, r"tracking_max_um:\s+([\d.]+)") == pytest.approx(1e3 * 50 / 36, rel=0.01)
    assert _figure(printed, r"contour_max_um:\s+([\d.]+)") < _figure(printed, r"tracking_max_um:\s+([\d.]+)") / 5
    assert _figure(printed, r"axis x: position-loop bandwidth ([\d.]+) Hz") > 0


def test_estimators_tour_prints_the_accuracy_the_readme_claims(capsys):
    runpy.run_path(str(EXAMPLES / "estimators_tour.py"), run_name="__main__")
    printed = capsys.readouterr().out
    exact = _figure(printed, r"exact contour error: max ([\d.]+) µm")
    assert exact == pytest.approx(98.71, abs=0.01)  # the demo's butterfly row in the README
    assert _figure(printed, r"linear: max \|estimate - exact\| = ([\d.e+-]+) µm") > exact  # 1.7× max ε
    for name in ("three_point", "newton"):
        assert _figure(printed, rf"{name}: max \|estimate - exact\| = ([\d.e+-]+) µm") < 1e-4 * exact


def test_examples_without_their_data_say_where_it_lives(tmp_path):
    for script, arguments in (("iso230_2_error_table.py", (tmp_path / "out", tmp_path / "nodata")),
                              ("emps_servo_check.py", (tmp_path / "nodata.mat",))):
        with pytest.raises(SystemExit, match=f"data is not at {tmp_path / 'nodata'}.*: it ships beside the repository"):
            runpy.run_path(str(EXAMPLES / script))["main"](*arguments)
    assert not (tmp_path / "out").exists()


def test_iso230_2_example_prints_the_ecmc_reports_figures(real_data, tmp_path, capsys):
    from test_real_iso230_2 import REPORT  # the ecmc tool's report.md [mm], independent of this code

    runpy.run_path(str(EXAMPLES / "iso230_2_error_table.py"))["main"](tmp_path / "out", real_data / "psi_ess_target_iso230_2")
    printed = capsys.readouterr().out
    for axis, block in zip("xyz", re.split(r"\n[XYZ] axis", printed)[1:]):
        b_avg, b, m, a = (1e3 * v for v in REPORT[axis][:4])
        printed_to_01 = dict(abs=0.05 + 0.006)  # printed to 0.1 µm; the report to 0.01 µm
        assert _figure(block, r"mean reversal B̄\s+([-\d.]+) µm") == pytest.approx(-b_avg, **printed_to_01)  # labels swapped
        assert _figure(block, r"reversal B = max\|B_i\|\s+([-\d.]+) µm") == pytest.approx(b, **printed_to_01)
        assert _figure(block, r"range of x̄ M\s+([-\d.]+) µm") == pytest.approx(m, **printed_to_01)
        assert _figure(block, r"accuracy A\s+([-\d.]+) µm") == pytest.approx(a, **printed_to_01)
        assert _figure(block, r"interpolated x̄\| <= ([\d.e+-]+) µm") < 1e-6  # the chain reproduces the table
    assert (tmp_path / "out" / "x_iso230_2.csv").exists()


def test_emps_example_prints_the_measured_following_error(real_data, capsys):
    runpy.run_path(str(EXAMPLES / "emps_servo_check.py"))["main"](real_data / "emps" / "DATA_EMPS.mat")
    printed = capsys.readouterr().out
    measured = _figure(printed, r"RMS, measured : ([\d.]+) mm")
    assert measured == pytest.approx(0.578, abs=0.001)  # PROVENANCE.md's figure
    assert _figure(printed, r"RMS, simulated: ([\d.]+) mm") == pytest.approx(measured, rel=0.05)
    assert _figure(printed, r"difference\s+: ([\d.]+) µm") < 0.05 * 1e3 * measured


def test_effects_gallery_prints_the_ballbar_sizes_of_the_closed_forms(tmp_path, monkeypatch, capsys):
    monkeypatch.setattr(sys, "argv", ["effects_gallery.py", str(tmp_path / "out")])
    runpy.run_path(str(EXAMPLES / "effects_gallery.py"), run_name="__main__")
    printed = capsys.readouterr().out
    radius = 25.0  # [mm]
    closed_forms = {  # peak-to-peak radial deviation [µm], the same both ways
        "backlash.x": 8.0,  # ±(lost motion / 2)·cos θ: the table lags by half the play either side of the motor
        "squareness.xy": 150e-6 * radius * 1e3,  # −(αR/2)·sin 2θ
        "scale_error.x": 100e-6 * radius * 1e3,  # R·k·cos²θ
    }
    for label, size in closed_forms.items():
        for direction in ("radial deviation CCW", "p-p, CW"):
            assert _figure(printed, rf"{re.escape(label)}\s+.*{direction}\s+([\d.]+) µm") == pytest.approx(size, rel=0.01)
    assert (tmp_path / "out" / "effects_gallery.png").exists()


def test_hunting_needs_static_friction_above_sliding(tmp_path, monkeypatch, capsys):
    monkeypatch.setattr(sys, "argv", ["hunting.py", str(tmp_path / "out")])
    runpy.run_path(str(EXAMPLES / "hunting.py"), run_name="__main__")
    rows = dict(((feedback, float(static)), (float(p2p), float(error)))
                for feedback, static, p2p, error in re.findall(r"^(motor|scale)\s+(\d+) N\s+([\d.]+)\s+(-?[\d.]+)$",
                                                               capsys.readouterr().out, re.M))  # fmt: skip
    assert rows[("motor", 100.0)] == (0.0, -2.0)  # a step smaller than the play: the table stays behind
    assert rows[("scale", 100.0)] == (0.0, 0.0)  # the scale pushes it through the play, onto the target
    assert rows[("scale", 200.0)][0] > 5.0  # stick-slip through the 10 µm play: a limit cycle of most of it
    assert rows[("motor", 200.0)][0] > 1.0  # the motor's own stick-slip cycle, larger than the play here
    assert (tmp_path / "out" / "hunting.png").exists()


def test_example_never_replaces_a_users_file(tmp_path, monkeypatch):
    out = output_dir(tmp_path / "out")  # a folder contoursim made ...
    (tmp_path / "out" / "circle.csv").write_text("mine")  # ... holding a user's file under a name the example writes
    monkeypatch.setattr(sys, "argv", ["api_tour.py", str(out)])
    with pytest.raises(FileExistsError, match="circle.csv exists and contoursim did not write it"):
        runpy.run_path(str(EXAMPLES / "api_tour.py"), run_name="__main__")
    assert (tmp_path / "out" / "circle.csv").read_text() == "mine"


@pytest.mark.parametrize("job", JOBS, ids=[p.name for p in JOBS])
def test_example_job_runs(job, tmp_path, capsys):
    from contoursim.cli import main

    assert main(["simulate", str(job), "--out", str(tmp_path)]) == 0
    assert "contoursim simulate" in capsys.readouterr().out
    assert _contour_within_tracking(tmp_path)


def test_router_ballbar_shows_its_backlash_step_and_squareness(tmp_path, capsys):
    """examples/router: the rings follow the data, so the 10 µm backlash (its lost motion) and the
    squareness's R·α = 5 µm (closed forms) take 40 % and 20 % of the ring band at least; the servo's
    ~49 µm radius loss put them at 50 µm/div, ±2 rings, before (5 % and 2.5 %). CW and CCW are named
    on their path plots; the titles list the effects.
    """
    import argparse

    from matplotlib.figure import Figure

    from contoursim.cli import _job, main, run_job
    from contoursim.model import Model
    from contoursim.plotting import circular_deviation, plot_path_error, plot_polar_deviation

    job_file = EXAMPLES / "router" / "ballbar.toml"
    assert main(["simulate", str(job_file), "--out", str(tmp_path)]) == 0
    assert "circularity" in capsys.readouterr().out
    assert {"iso230_4_circle_polar.png", "iso230_4_circle_polar_difference.png", "iso230_4_circle_cw_path.png"} \
        <= {p.name for p in tmp_path.iterdir()}

    model, path_file, job, _ = _job(argparse.Namespace(file=str(job_file), machine=None, command="simulate"))
    runs = {d: run_job(model, path_file, job, direction=d)[2] for d in ("ccw", "cw")}
    ax = plot_polar_deviation(runs, Figure().add_subplot(projection="polar"))
    band = np.ptp(ax.get_ylim())  # [µm] from the inner to the outer ring

    def signature(effect):  # [µm] p-p of what `effect` adds to the CCW run's ballbar deviation
        without = Model(model.machine, tuple(e for e in model.effects if e.name != effect))
        rest = circular_deviation(run_job(without, path_file, job, direction="ccw")[2])["deviation"]
        return np.ptp(circular_deviation(runs["ccw"])["deviation"] - rest)

    backlash, squareness = signature("backlash"), signature("squareness")
    assert backlash == pytest.approx(10.0, rel=0.1)  # the lost motion (closed form, see effects_gallery)
    assert squareness == pytest.approx(1e3 * 100e-6 * 50.0, rel=0.1)  # R·α [µm]
    assert backlash >= 0.4 * band and squareness >= 0.2 * band  # at ±2 rings of 50 µm: 5 % and 2.5 %
    assert "backlash.x 10 µm, squareness.xy 100 µrad" in ax.get_title() and "CCW and CW" in ax.get_title()
    difference = plot_polar_deviation(runs, Figure().add_subplot(projection="polar"),
                                      {d: run_job(Model(model.machine), path_file, job, direction=d)[2] for d in runs})
    assert np.ptp(difference.get_ylim()) <= band and "minus the nominal run" in difference.get_title()
    for d, result in runs.items():
        title = plot_path_error(result, Figure().add_subplot(), name=f"router_{d}").get_title()
        assert title.startswith(f"router_{d} ({d.upper()}) on gantry router\neffects: backlash.x 10 µm")


def test_tune_ccc_sweep_picks_gains_better_than_the_default_and_refuses_unstable_ones(tmp_path, capsys):
    import csv

    from contoursim.cli import main
    from contoursim.comparison import compare
    from contoursim.compensation import CrossCoupled
    from contoursim.exceptions import UnstableLoopError
    from contoursim.simulation import simulate
    from contoursim.sweep import _job, read_sweep

    assert main(["sweep", str(SWEEPS[0]), "--out", str(tmp_path)]) == 0
    printed = capsys.readouterr().out
    rows = list(csv.DictReader((tmp_path / "sweep.csv").open()))
    assert len(rows) == 24
    refused = [r for r in rows if r["diverged"] == "True"]
    stable = [r for r in rows if r["diverged"] == "False"]
    assert refused and len(stable) >= 12  # the coupled-loop check refuses the high gains
    job = _job(read_sweep(SWEEPS[0]))
    for row in refused:  # refused by the check a single run makes, before it runs
        gains = dict(kp=float(row["strategy.ccc_arc.kp_per_s"]), ki=float(row["strategy.ccc_arc.ki_per_s2"]))
        with pytest.raises(UnstableLoopError, match="coupled loop"):
            simulate(job.model, job.trajectory, [CrossCoupled("arc", **gains)])
    best = min(stable, key=lambda r: float(r["contour_max_um"]))
    assert f"best   variant {best['variant']}:" in printed
    # the default gains (CrossCoupled's own design) on the same job
    default = compare(job.model, job.trajectory, ["ccc_arc"]).figures["ccc_arc"]["contour_max_um"]
    assert float(best["contour_max_um"]) < default
    assert {"best.csv", "worst.csv", "best_worst_polar.png", "sweep_map.png"} <= {p.name for p in tmp_path.iterdir()}
