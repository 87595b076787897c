"""Fleets: every trace diagnosed, a summary of the effects named, the failures with why, here or on a cluster."""

import json
import re
import runpy
import sys
from pathlib import Path

import pytest

from conftest import ROOT

from contoursim.cli import main
from contoursim.exceptions import ConfigError
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


def test_one_trace_keeps_the_single_report_and_fleet_options_need_several(tmp_path, capsys, monkeypatch):
    trace = FLEET / "night_2026-10-05.csv"
    assert main(["diagnose", str(trace), "--summary", str(tmp_path / "s.json"), "--out", str(tmp_path / "o")]) == 2
    assert "--summary and --scheduler are for several traces" in capsys.readouterr().err
    assert main(["diagnose", str(FLEET), "--report", str(tmp_path / "r.json"), "--out", str(tmp_path / "o")]) == 2
    assert "--report names one trace's report" in capsys.readouterr().err
    with pytest.raises(ValueError, match="holds no .csv trace$"):
        trace_files([tmp_path])
    (tmp_path / "mill_a").mkdir()
    (tmp_path / "mill_a" / "night.csv").write_text("t,x_ref,x\n")
    with pytest.raises(ValueError, match=r"holds no .csv trace \(its subfolders, not searched, hold 1: in mill_a; name "
                                         r"them\)$"):  # was "holds no .csv trace" (an outside probe)
        trace_files([tmp_path])
    with pytest.raises(ValueError, match="no trace file"):
        trace_files([tmp_path / "missing.csv"])
    # simulate's folder of a G-code run: its per-block table is no trace (an outside probe: "1 of 2 traces diagnosed")
    (tmp_path / "p.nc").write_text("G0 X0 Y0\nG1 X10 F1000\nG1 Y5\n")
    assert main(["simulate", str(tmp_path / "p.nc"), "--machine", "demo_mill", "--out", str(tmp_path / "run")]) == 0
    assert sorted(p.name for p in (tmp_path / "run").glob("*.csv")) == ["p.csv", "p_blocks.csv"]
    assert trace_files([tmp_path / "run"]) == [tmp_path / "run" / "p.csv"]
    # a folder of the user's as --out: refused before the fleet is diagnosed, not after
    import contoursim.fleet

    (tmp_path / "mine").mkdir()
    (tmp_path / "mine" / "notes.txt").write_text("mine")
    monkeypatch.setattr(contoursim.fleet, "diagnose_fleet", lambda *a, **k: pytest.fail("diagnosed before the refusal"))
    capsys.readouterr()
    assert main(["diagnose", str(tmp_path / "run"), str(trace), "--out", str(tmp_path / "mine")]) == 2
    assert "holds files that contoursim did not write" in capsys.readouterr().err
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


def test_a_fleet_none_of_whose_traces_is_diagnosed_ends_in_an_error_and_claims_no_report(tmp_path, capsys):
    """Every trace failed: the command ended with status 0 and 'reports, fleet.json and fleet.png written'. A trace
    that failed kept the report an earlier run had written of it."""
    (tmp_path / "tr").mkdir()
    (tmp_path / "tr" / "a.csv").write_text("t,x_ref,x\n0,0,0\n0.001,nan,0\n")
    (tmp_path / "tr" / "b.csv").write_text("t,x_ref,x\n0,0,0\n0.001,0,inf\n")
    out = tmp_path / "out"
    assert main(["diagnose", str(tmp_path / "tr"), "--out", str(out), "--summary", str(tmp_path / "s.json")]) == 2
    captured = capsys.readouterr()
    assert captured.out.splitlines()[-1] == f"no report; fleet.json and fleet.png (the failures) written to {out}/; " \
                                            f"summary to {tmp_path / 's.json'}"
    assert captured.err.splitlines()[-1] == "contoursim diagnose: error: none of the 2 traces could be diagnosed: " \
                                            f"why, above and in {out / 'fleet.json'}"
    assert sorted(p.name for p in out.iterdir()) == [".contoursim-out", "fleet.json", "fleet.png"]
    summary = json.loads((out / "fleet.json").read_text())
    assert summary["diagnosed"] == 0 and [Path(f["trace"]).name for f in summary["failed"]] == ["a.csv", "b.csv"]
    assert json.loads((tmp_path / "s.json").read_text()) == summary
    # one of two diagnosed: its report, and no claim of the other's
    night, broken = FLEET / "night_2026-10-05.csv", FLEET / "night_2026-11-02.csv"
    assert main(["diagnose", str(night), str(broken), "--model", str(FLEET / "nightly_mill.toml"), "--out",
                 str(tmp_path / "one")]) == 0
    closing = capsys.readouterr().out.splitlines()[-1]
    assert closing == f"1 report (one per trace diagnosed), fleet.json and fleet.png written to {tmp_path / 'one'}/"
    assert {p.name for p in (tmp_path / "one").iterdir()} == {".contoursim-out", "night_2026-10-05.json", "fleet.json",
                                                            "fleet.png"}
    # run again with that trace broken: its earlier report is removed, not left to stand for it
    (tmp_path / "night_2026-10-05.csv").write_text("t,x_ref,x\n0,0,0\n0.001,nan,0\n")
    assert main(["diagnose", str(tmp_path / "night_2026-10-05.csv"), str(broken), "--model",
                 str(FLEET / "nightly_mill.toml"), "--out", str(tmp_path / "one")]) == 2
    assert {p.name for p in (tmp_path / "one").iterdir()} == {".contoursim-out", "fleet.json", "fleet.png"}
    # a fleet run again without a trace it had: that trace's report went on standing beside the new fleet.json (an
    # outside probe); a file of the user's in the folder stays
    other = FLEET / "night_2026-10-12.csv"
    assert main(["diagnose", str(night), str(other), "--model", str(FLEET / "nightly_mill.toml"), "--out",
                 str(tmp_path / "two")]) == 0
    (tmp_path / "two" / "notes.txt").write_text("mine")
    assert main(["diagnose", str(night), str(broken), "--model", str(FLEET / "nightly_mill.toml"), "--out",
                 str(tmp_path / "two")]) == 0
    assert {p.name for p in (tmp_path / "two").iterdir()} == {".contoursim-out", "night_2026-10-05.json", "fleet.json",
                                                            "fleet.png", "notes.txt"}


def test_a_single_file_name_is_refused_where_a_sequence_of_traces_is_wanted(tmp_path):
    # trace_files("night.csv") took each character for a trace ("/ holds no .csv trace"); diagnose_fleet diagnosed
    # each character and returned one failure per character
    trace = tmp_path / "night.csv"
    trace.write_text("t,x_ref,x\n0,0,0\n0.001,0.1,0.1\n")
    with pytest.raises(TypeError, match=r"paths must be a sequence of file names, got the single name .*night.csv"):
        trace_files(str(trace))
    with pytest.raises(TypeError, match=r"files must be a sequence of file names, got the single name"):
        diagnose_fleet(trace)
    assert trace_files([trace]) == [trace]


def test_a_fleet_summary_of_what_diagnose_fleet_does_not_return_is_refused_naming_it():
    # one outcome (a dict) or a file name failed as "string indices must be integers", a string of the name's
    # characters was 5 traces, [] a fleet of none, an outcome of neither report nor error a trace neither diagnosed
    # nor failed, one without its trace a KeyError 'trace', a report without its effects a KeyError 'effects'
    failed = {"trace": "a.csv", "error": "a.csv, line 3: column 'x': value nan is not finite"}
    for outcomes, error, words in (
        (failed, TypeError, r"outcomes must be a list of diagnose_fleet's outcomes \(one dict per trace\), got dict"),
        ("a.csv", TypeError, r"outcomes must be a list of diagnose_fleet's outcomes .*, got str"),
        (None, TypeError, r"outcomes must be a list of diagnose_fleet's outcomes .*, got NoneType"),
        ([], ValueError, r"outcomes is empty: a fleet summary needs the outcome of one trace or more"),
        ([failed, "b.csv"], TypeError, r"outcomes\[1\] must be a dict \(diagnose_text's outcome\), got str"),
        ([{"trace": "b.csv"}], ValueError, r"outcomes\[0\] must hold 'trace' and either 'report' or 'error' "
                                           r"\(diagnose_text's outcome\), got the keys \['trace'\]"),
        ([{"error": "x"}], ValueError, r"outcomes\[0\] must hold 'trace' and either .*, got the keys \['error'\]"),
        ([{"trace": "b.csv", "report": {}}], ValueError, r"outcomes\[0\]\['report'\] must be a diagnosis report "
                                                         r"\(Diagnosis.to_dict\) with its 'effects'"),
        ([{"trace": "b.csv", "report": {"effects": []}}], ValueError,
         r"with its 'effects' \(where it names none, its 'noise_um', 'steps', 'unexplained' too\)"),
    ):
        with pytest.raises(error, match=words):
            fleet_summary(outcomes)
    assert fleet_summary([failed])["failed"] == [failed]


def test_a_trace_named_fleet_is_told_apart_from_two_of_a_name(tmp_path, capsys, monkeypatch):
    # a folder with one fleet.csv was refused as "two traces named fleet.csv (or one named fleet.csv)"
    import contoursim.fleet

    monkeypatch.setattr(contoursim.fleet, "diagnose_fleet", lambda *a, **k: pytest.fail("diagnosed before the refusal"))
    (tmp_path / "logs").mkdir()
    for name in ("fleet.csv", "night.csv"):
        (tmp_path / "logs" / name).write_text("t,x_ref,x\n0,0,0\n0.001,0.1,0.1\n")
    assert main(["diagnose", str(tmp_path / "logs"), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert f"the trace {tmp_path / 'logs' / 'fleet.csv'}'s report would be fleet.json, the fleet summary's" in err
    assert "two traces" not in err
    (tmp_path / "more").mkdir()
    (tmp_path / "more" / "night.csv").write_text("t,x_ref,x\n0,0,0\n0.001,0.1,0.1\n")
    assert main(["diagnose", str(tmp_path / "logs" / "night.csv"), str(tmp_path / "more"), "--out", str(tmp_path / "o")]) == 2
    assert "two traces named night.csv: their reports would share a file name; rename one" in capsys.readouterr().err


def test_a_trace_too_long_for_the_memory_is_that_traces_failure_as_diagnose_says_it(tmp_path, monkeypatch):
    """A single trace is refused by the memory its diagnosis needs before it starts; in a fleet the trace was
    diagnosed anyway (an out-of-memory error ended the whole fleet, naming no trace)."""
    import numpy as np

    from contoursim import _memory

    t = np.arange(4001) * 5e-3  # 20 s: 40,000 servo periods of the nightly mill's 0.5 ms, 180 MB to diagnose
    x = 5 * np.sin(2 * np.pi * t / 10)
    long = tmp_path / "long.csv"
    long.write_text("t,x_ref,x\n" + "".join(f"{a:.3f},{b:.6f},{b:.6f}\n" for a, b in zip(t, x)))
    night = FLEET / "night_2026-10-05.csv"  # 9.7 s: 88 MB
    monkeypatch.setattr(_memory, "available", lambda: 1.2e8)
    failed, diagnosed = diagnose_fleet([long, night], FLEET / "nightly_mill.toml")
    assert failed == {"trace": str(long), "error": "long.csv: the trace lasts 20 s: every servo period of 0.0005 s "
                      "that is 4e+04 samples, a run of them needs about 0.18 GB of memory and 0.12 GB are available; "
                      "check the unit of the trace's time column (e.g. a line '# units: t [ms]') and the servo period"}
    assert diagnosed["report"]["effects"][0]["name"] == "backlash"


def test_a_fleet_reads_the_error_tables_of_its_machine_file_and_a_machine_file_named_without_its_suffix(
        tmp_path, monkeypatch):
    """The machine file was copied alone into each task's folder: every trace failed with its ISO 230-2 table 'not
    found (relative to /tmp/contoursim-fleet-...)', where diagnose of one trace read it; a machine file named without
    .toml went to the tasks as a preset's name (on a cluster's workers: the shipped preset, or none)."""
    import shutil

    import numpy as np

    from contoursim.machine import preset_file

    shipped = preset_file("vertical_mill_3axis", here=False)
    (tmp_path / "mill").mkdir()
    for name in (shipped.name, "vertical_mill_x_laser.csv"):  # the table named beside it
        shutil.copy(shipped.parent / name, tmp_path / "mill" / name)
    t = np.arange(301) * 1e-3
    x = 5 * np.sin(2 * np.pi * t / 0.3)
    trace = tmp_path / "a.csv"
    rows = "".join(f"{a:.3f},{b:.6f},{b:.6f},{b:.6f},{b:.6f}\n" for a, b in zip(t, x))
    trace.write_text("t,x_ref,x,y_ref,y\n" + rows)
    (outcome,) = diagnose_fleet([trace], tmp_path / "mill" / shipped.name)
    assert "report" in outcome, outcome["error"]
    monkeypatch.chdir(tmp_path / "mill")
    import contoursim.fleet

    tasks = []
    monkeypatch.setattr(contoursim.fleet, "diagnose_text", lambda *task: tasks.append(task) or outcome)
    diagnose_fleet([trace], "vertical_mill_3axis")  # the file here, before the preset of that name
    assert list(tasks[0][2]) == [shipped.name, "vertical_mill_x_laser.csv"]  # the file and its table, as texts
    # a machine file the tasks cannot read is refused once, at its line, before any trace (each trace failed with it)
    (tmp_path / "bad.toml").write_text('name = "bad"\nservo_period_ms = 0.2\n[axes.x]\nmass_kg = 300\n')
    with pytest.raises(ConfigError, match=r"bad.toml, line 3: missing key 'force_constant_N_per_A' in \[axes.x\]"):
        diagnose_fleet([trace], tmp_path / "bad.toml")
    assert len(tasks) == 1


def test_a_fleets_tasks_carry_the_error_tables_so_that_a_worker_seeing_none_of_the_users_files_reads_them(
        tmp_path, monkeypatch):
    """A task named the machine file's error tables where they lie (an absolute path): a worker of a remote cluster,
    which cannot see that path, failed every trace with the table 'not found'. A task carries the tables' texts, as a
    sweep's carries its job's files (rebuilt here as on a worker: the user's folders renamed)."""
    import shutil

    import numpy as np

    import contoursim.fleet
    from contoursim.fleet import diagnose_text
    from contoursim.machine import preset_file

    shipped = preset_file("vertical_mill_3axis", here=False)
    mill, logs = tmp_path / "mill", tmp_path / "logs"
    (mill / "laser").mkdir(parents=True)
    logs.mkdir()
    (mill / "mine.toml").write_text(shipped.read_text().replace('table = "vertical_mill_x_laser.csv"',
                                                                'table = "laser/x.csv"'))
    shutil.copy(shipped.parent / "vertical_mill_x_laser.csv", mill / "laser" / "x.csv")
    t = np.arange(301) * 1e-3
    x = 5 * np.sin(2 * np.pi * t / 0.3)
    (logs / "a.csv").write_text("t,x_ref,x,y_ref,y\n" + "".join(f"{a:.3f},{b:.6f},{b:.6f},{b:.6f},{b:.6f}\n"
                                                                 for a, b in zip(t, x)))
    tasks = []
    monkeypatch.setattr(contoursim.fleet, "diagnose_text", lambda *task: tasks.append(task) or {"trace": task[0]})
    diagnose_fleet([logs / "a.csv"], mill / "mine.toml")
    (task,) = tasks
    mill.rename(tmp_path / "moved")  # as on a worker: neither the machine file, its table nor the trace where named
    logs.rename(tmp_path / "gone")
    outcome = diagnose_text(*task)
    assert "report" in outcome, outcome["error"]  # was "error table '/tmp/.../mill/laser/x.csv' not found"
    assert task[2] == {"mine.toml": (tmp_path / "moved" / "mine.toml").read_text(),
                       "laser/x.csv": (tmp_path / "moved" / "laser" / "x.csv").read_text()}
    # a table outside the machine file's folder: read where it lies here, refused on a cluster before one starts
    (tmp_path / "moved" / "mine.toml").write_text(task[2]["mine.toml"].replace('"laser/x.csv"', '"../x.csv"'))
    shutil.copy(tmp_path / "moved" / "laser" / "x.csv", tmp_path / "x.csv")
    diagnose_fleet([tmp_path / "gone" / "a.csv"], tmp_path / "moved" / "mine.toml")
    assert tasks[-1][2] == str(tmp_path / "moved" / "mine.toml") and "report" in diagnose_text(*tasks[-1])
    with pytest.raises(ValueError, match=rf"^{re.escape(str(tmp_path / 'moved' / 'mine.toml'))} names "
                                         rf"{re.escape(str(tmp_path / 'x.csv'))}, outside its folder: a cluster's "
                                         r"workers get the machine file's folder only"):
        diagnose_fleet([tmp_path / "gone" / "a.csv"], tmp_path / "moved" / "mine.toml", "local:1")


def test_a_fleet_counts_as_explained_by_the_nominal_model_only_what_its_report_says_is_within_noise():
    """Two traces with 1444 µm RMS of drift left and nothing named were printed as 'explained by the nominal model: 2'
    (an outside probe). The summary now follows the report's own verdict (diagnosis.within_noise)."""
    from contoursim.diagnosis import NOISE_FLOOR

    def outcome(name, rms_um, unexplained=()):
        steps = [{"label": "nominal model", "rms_um": rms_um, "max_um": rms_um}]
        return {"trace": name, "report": {"effects": [], "unexplained": list(unexplained), "steps": steps,
                                          "noise_um": {"x": 0.3, "y": 0.4}}}

    summary = fleet_summary([outcome("clean.csv", 0.5), outcome("drift.csv", 1444.0, [{"axis": "x", "signature":
                                                                                        "drift", "rms_um": 1444.0}]),
                             outcome("above.csv", 1.01 * NOISE_FLOOR * 0.5), outcome("edge.csv", NOISE_FLOOR * 0.5)])
    assert summary["nominal"] == ["clean.csv", "edge.csv"]
    assert summary["unexplained"] == ["drift.csv", "above.csv"]


@pytest.mark.skipif(not hasattr(__import__("os"), "mkfifo"), reason="named pipes are POSIX")
def test_a_named_pipe_among_a_folders_traces_is_a_failed_trace_not_a_fleet_that_waits_for_ever(tmp_path):
    """Listing a folder's traces opened each .csv to tell a G-code run's block table from a trace; a named pipe with no
    writer blocked that open for ever (an outside probe)."""
    import os

    os.mkfifo(tmp_path / "b.csv")
    assert trace_files([tmp_path]) == [tmp_path / "b.csv"]
    (outcome,) = diagnose_fleet([tmp_path / "b.csv"], "demo_mill")
    assert outcome["error"] == "b.csv: cannot read the file: it is a named pipe (FIFO), not a regular file"


def test_a_trace_whose_report_could_not_be_written_is_refused_before_the_fleet_runs(tmp_path, capsys, monkeypatch):
    """A trace named with a line break: every trace was diagnosed, then the run ended in 'name must be a plain file
    name', no report written and an empty output folder left (an outside probe)."""
    import contoursim.fleet

    (tmp_path / "f").mkdir()
    for name in ("a\nb.csv", "c.csv"):
        (tmp_path / "f" / name).write_text("t,x_ref,x\n0,0,0\n")
    monkeypatch.setattr(contoursim.fleet, "diagnose_fleet", lambda *a, **k: pytest.fail("diagnosed before the refusal"))
    assert main(["diagnose", str(tmp_path / "f"), "--model", "demo_mill", "--out", str(tmp_path / "new")]) == 2
    assert "cannot write 'a\\nb.json' into" in capsys.readouterr().err
    assert not (tmp_path / "new").exists()


def test_a_task_takes_the_machine_file_as_a_path_and_refuses_what_is_no_machine_naming_model(tmp_path):
    from contoursim.fleet import diagnose_text
    from contoursim.machine import preset_file

    text = "t,x_ref,x\n" + "".join(f"{k * 1e-3:.3f},{k * 1e-3:.6f},{k * 1e-3 - 1e-4:.6f}\n" for k in range(3))
    via_path = diagnose_text("a.csv", text, preset_file("demo_mill"))
    assert via_path == diagnose_text("a.csv", text, str(preset_file("demo_mill")))  # was AttributeError: 'PosixPath'
    with pytest.raises(TypeError, match=r"^model must be a preset's name, a machine file or its files .*, got int$"):
        diagnose_text("a.csv", text, 3)
