"""Every example script runs (examples never rot) and says what it claims."""

import runpy
import sys

import numpy as np
import pytest

from conftest import ROOT

from contoursim.output import output_dir

EXAMPLES = sorted((ROOT / "examples").glob("*.py"))
JOBS = sorted((ROOT / "examples").glob("*.toml"))


@pytest.mark.parametrize("script", EXAMPLES, ids=[p.name for p in EXAMPLES])
def test_example_runs(script, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr(sys, "argv", [str(script), str(tmp_path / "out")])
    runpy.run_path(str(script), run_name="__main__")


@pytest.mark.parametrize("script, written", [("api_tour.py", "api_tour_circle_path.png"), ("iso230_2_error_table.py", "x_iso230_2.csv")])
def test_example_never_replaces_a_users_file(script, written, tmp_path, monkeypatch, request):
    if script.startswith("iso230_2"):
        request.getfixturevalue("real_data")  # that example needs the measured data
    out = output_dir(tmp_path / "out")  # a folder contoursim made ...
    (tmp_path / "out" / written).write_text("mine")  # ... holding a user's file under a name the example writes
    monkeypatch.setattr(sys, "argv", [script, str(out)])
    with pytest.raises(FileExistsError, match=f"{written} exists and contoursim did not write it"):
        runpy.run_path(str(ROOT / "examples" / script), run_name="__main__")
    assert (tmp_path / "out" / written).read_text() == "mine"


@pytest.mark.parametrize("job", JOBS, ids=[p.name for p in JOBS])
def test_example_job_runs(job, tmp_path, capsys):
    from contoursim.cli import main

    assert main(["simulate", str(job), "--out", str(tmp_path)]) == 0
    assert "contoursim simulate" in capsys.readouterr().out


def test_emps_model_matches_the_measured_axis(real_data):
    """The P-P loop rebuilt from EMPS's documented parameters reproduces its measured following error.

    Independent reference: the benchmark's own measurement. The residual is
    the Coulomb friction the nominal model leaves out (PROVENANCE: ≈0.02 mm
    sign(v) term).
    """
    module = runpy.run_path(str(ROOT / "examples" / "emps_servo_check.py"))
    simulated, measured = module["compare"](real_data / "emps" / "DATA_EMPS.mat")
    rms = lambda x: np.sqrt(np.mean(x**2))  # noqa: E731
    assert rms(measured) == pytest.approx(0.578, abs=0.001)  # PROVENANCE.md's figure
    assert rms(simulated) == pytest.approx(rms(measured), rel=0.05)
    assert rms(simulated - measured) < 0.05 * rms(measured)
