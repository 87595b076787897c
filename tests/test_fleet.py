"""Fleets: every trace diagnosed, a summary of the effects named, the failures with why, here or on a cluster."""

import json
import re
import runpy
import sys

import pytest

from conftest import ROOT

from contoursim.cli import main
from contoursim.fleet import diagnose_fleet, fleet_summary, trace_files

FLEET = ROOT / "examples" / "fleet"
NIGHTS = runpy.run_path(str(FLEET / "make_nightly.py"))["NIGHTS"]  # the backlash hidden in each night's trace [µm]


def test_the_nightly_fleet_names_the_drifting_backlash_and_the_broken_log(tmp_path, capsys):
    summary_file = tmp_path / "fleet.json"
    argv = ["diagnose", str(FLEET), "--model", str(FLEET / "nightly_mill.toml"), "--out", str(tmp_path / "out"),
            "--summary", str(summary_file)]
    assert main(argv) == 0
    printed = capsys.readouterr().out
    summary = json.loads(summary_file.read_text())
    assert (summary["traces"], summary["diagnosed"]) == (5, 4)
    assert list(summary["effects"]) == ["backlash.x"]
    backlash = summary["effects"]["backlash.x"]
    assert backlash["count"] == 4 and [p.rsplit("/", 1)[1] for p in backlash["traces"]] == [f"night_{d}.csv" for d in NIGHTS]
    found = backlash["parameters"]["lost_motion_um"]
    assert found["values"] == pytest.approx(list(NIGHTS.values()), abs=0.2)  # the drift, night by night
    assert found["min"] == min(found["values"]) and found["max"] == max(found["values"])
    (failed,) = summary["failed"]
    assert failed["trace"].endswith("night_2026-11-02.csv")
    assert failed["error"] == "night_2026-11-02.csv, line 201: expected 5 cells (as in the header), found 3"
    shown = re.search(r"backlash.x +on +4 of 5 traces: lost_motion_um ([\d.]+) … ([\d.]+)", printed)
    assert [float(v) for v in shown.groups()] == pytest.approx([4.0, 10.0], abs=0.2)
    written = {p.name for p in (tmp_path / "out").iterdir()}
    assert {"fleet.json", "fleet.png"} | {f"night_{d}.json" for d in NIGHTS} <= written
    report = json.loads((tmp_path / "out" / "night_2026-10-05.json").read_text())
    assert report["effects"][0]["name"] == "backlash" and "residual_rms_before_um" in report  # the contract report
    assert json.loads((tmp_path / "out" / "fleet.json").read_text()) == summary


def test_one_trace_keeps_the_single_report_and_fleet_options_need_several(tmp_path, capsys):
    trace = FLEET / "night_2026-10-05.csv"
    assert main(["diagnose", str(trace), "--summary", str(tmp_path / "s.json"), "--out", str(tmp_path / "o")]) == 2
    assert "--summary and --scheduler are for several traces" in capsys.readouterr().err
    assert main(["diagnose", str(FLEET), "--report", str(tmp_path / "r.json"), "--out", str(tmp_path / "o")]) == 2
    assert "--report names one trace's report" in capsys.readouterr().err
    with pytest.raises(ValueError, match="holds no .csv trace"):
        trace_files([tmp_path])
    with pytest.raises(ValueError, match="no trace file"):
        trace_files([tmp_path / "missing.csv"])
    with pytest.raises(ValueError, match=f"^{trace} is given twice: name each trace once$"):  # it was 'rename one'
        trace_files([trace, FLEET])
    (tmp_path / "logs").symlink_to(FLEET)
    with pytest.raises(ValueError, match=rf"^{trace} is given twice \(also as {tmp_path / 'logs' / trace.name}\)"):
        trace_files([trace, tmp_path / "logs" / trace.name])


def test_generated_traces_diagnose_the_same_on_a_local_cluster(tmp_path, monkeypatch):
    pytest.importorskip("distributed", reason="dask.distributed not installed (pip install \"contoursim[distributed]\")")
    monkeypatch.setattr(sys, "argv", ["make_nightly.py", str(tmp_path)])
    runpy.run_path(str(FLEET / "make_nightly.py"), run_name="__main__")
    files = trace_files([tmp_path])[-2:]  # the last good night and the broken log
    model = FLEET / "nightly_mill.toml"
    here = diagnose_fleet(files, model)
    assert diagnose_fleet(files, model, "local:2") == here
    summary = fleet_summary(here)
    assert summary["effects"]["backlash.x"]["parameters"]["lost_motion_um"]["values"] == pytest.approx([10.0], abs=0.2)
    assert len(summary["failed"]) == 1
