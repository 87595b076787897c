"""The output folder: nothing a user keeps there is overwritten, nothing is left half-written."""

import json
import os
import signal
import subprocess
import sys
import time

import pytest

from contoursim import output
from contoursim.comparison import JSON_FORM, JSON_KEYS
from contoursim.exceptions import ConfigError, OutputError
from contoursim.fleet import SUMMARY_FORM, fleet_summary
from contoursim.output import atomic_write, output_dir


def test_output_dir_refuses_files_it_did_not_write(tmp_path):
    out = output_dir(tmp_path / "out")
    assert out.file("a.csv") == tmp_path / "out" / "a.csv"
    assert out.written() == set()  # checking a name does not claim it
    with out.write("a.csv") as stream:
        stream.write("ours")
    (tmp_path / "out" / "notes.txt").write_text("mine")
    again = output_dir(tmp_path / "out")  # a later run reuses the folder and its record
    with again.write("a.csv") as stream:
        stream.write("ours again")
    assert (tmp_path / "out" / "a.csv").read_text() == "ours again"
    with pytest.raises(FileExistsError, match="notes.txt exists and contoursim did not write it"):
        again.file("notes.txt")
    with pytest.raises(FileExistsError, match="notes.txt exists and contoursim did not write it"):
        with again.write("notes.txt") as stream:
            stream.write("lost")
    assert (tmp_path / "out" / "notes.txt").read_text() == "mine"
    assert again.written() == {"a.csv"}
    assert (tmp_path / "out" / ".contoursim-out").read_text().count("a.csv") == 1  # listed once
    with pytest.raises(ValueError, match="plain file name"):
        again.file("../escape.csv")
    assert output_dir(again) is again


def test_the_record_says_which_command_wrote_each_file_in_comments_an_earlier_reader_skips(tmp_path):
    """A sweep took every sweep_*.png of its folder for an earlier sweep's (simulate's of a path sweep_a too)."""
    marker = tmp_path / "out" / ".contoursim-out"
    plain = output_dir(tmp_path / "out")
    marker.write_text(marker.read_text() + "old.png\n")  # an earlier contoursim's record: the name alone
    sweep = output.OutputDir(tmp_path / "out", by="sweep")
    for out, name in ((plain, "sweep_a_path.png"), (sweep, "sweep.csv"), (sweep, "best.csv"), (plain, "best.csv"),
                      (sweep, "best.csv"), (sweep, "sweep_x.png"), (plain, "sweep_a_path.png")):
        with out.write(name) as stream:
            stream.write(name)
    assert sweep.written_by("sweep") == {"sweep.csv", "best.csv", "sweep_x.png"}
    plain.remove("best.csv")  # the last writer of best.csv was the sweep; simulate writes it again
    with plain.write("best.csv") as stream:
        stream.write("simulate's")
    assert plain.written_by("sweep") == {"sweep.csv", "sweep_x.png"}  # old.png, of an earlier contoursim: no one's
    assert sweep.written() == {"old.png", "sweep_a_path.png", "sweep.csv", "best.csv", "sweep_x.png"}
    names = [line for line in marker.read_text().splitlines() if not line.startswith("#")]  # as a reader of names
    assert names == ["old.png", "sweep_a_path.png", "sweep.csv", "sweep_x.png", "best.csv"]  # best.csv: off, then on
    assert [line for line in marker.read_text().splitlines() if line.startswith("#by ")] == [
        "#by sweep sweep.csv", "#by sweep sweep_x.png"]  # a line when the writer changes: sweep_a_path.png, never a
    # sweep's, has none, nor best.csv, off the record when removed and written again by no command
    for by in ("", "-", "two words", 3):
        with pytest.raises(ValueError, match="by names the command writing"):
            output.OutputDir(tmp_path / "out", by=by)


def test_a_removed_file_leaves_the_record_so_a_users_file_of_its_name_is_kept(tmp_path):
    """A file a sweep removed stayed on the record: a user's file saved later under its name was replaced."""
    sweep = output.OutputDir(tmp_path / "out", by="sweep")
    for name in ("sweep.csv", "best.csv"):
        with sweep.write(name) as stream:
            stream.write("contoursim's")
    sweep.remove("best.csv")
    assert sweep.written() == sweep.written_by("sweep") == {"sweep.csv"}
    (tmp_path / "out" / "best.csv").write_text("mine")
    with pytest.raises(FileExistsError, match="best.csv exists and contoursim did not write it"):
        with sweep.write("best.csv") as stream:
            stream.write("contoursim's again")
    assert (tmp_path / "out" / "best.csv").read_text() == "mine"
    assert (tmp_path / "out" / ".contoursim-out").read_text().startswith("# written by contoursim")


def test_output_dir_refuses_a_file_and_a_users_folder(tmp_path):
    (tmp_path / "somefile").write_text("mine")
    with pytest.raises(ConfigError, match="somefile is a file, not a directory"):
        output_dir(tmp_path / "somefile")
    with pytest.raises(OutputError, match="cannot create the output directory .*somefile/out"):
        output_dir(tmp_path / "somefile" / "out")
    with pytest.raises(ConfigError, match="holds files that contoursim did not write"):
        output_dir(tmp_path)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["somefile"]


def test_an_interrupted_write_leaves_the_old_file_and_no_trace(tmp_path):
    out = output_dir(tmp_path / "out")
    with out.write("a.csv") as stream:
        stream.write("t,x_ref,x\n0,0,0\n1,1,1\n")
    for interrupt in (KeyboardInterrupt, RuntimeError):
        with pytest.raises(interrupt):
            with out.write("a.csv") as stream:
                stream.write("t,x_ref,x\n0,0,0\n")  # a truncated file that ends on a whole row ...
                raise interrupt
        with pytest.raises(interrupt):
            with out.write("b.csv") as stream:
                stream.write("t,x_ref,x\n")
                raise interrupt
    assert (tmp_path / "out" / "a.csv").read_text() == "t,x_ref,x\n0,0,0\n1,1,1\n"  # ... never replaces the old one
    assert sorted(p.name for p in (tmp_path / "out").iterdir()) == [".contoursim-out", "a.csv"]
    assert out.written() == {"a.csv"}  # b.csv was never complete, so it is not listed


def test_a_file_that_cannot_be_written_is_named(tmp_path, monkeypatch):
    with pytest.raises(OutputError, match=f"cannot write {tmp_path / 'missing' / 'a.csv'}: No such file"):
        with atomic_write(tmp_path / "missing" / "a.csv") as stream:
            stream.write("x")
    (tmp_path / "a.csv").mkdir()  # the rename onto a directory fails: the temporary file goes
    with pytest.raises(OutputError, match=f"cannot write {tmp_path / 'a.csv'}: Is a directory"):
        with atomic_write(tmp_path / "a.csv") as stream:
            stream.write("x")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.csv"]


def test_a_read_only_folder_gives_one_line(tmp_path):
    out = output_dir(tmp_path / "out")
    os.chmod(tmp_path / "out", 0o555)
    try:
        if os.access(tmp_path / "out", os.W_OK):
            pytest.skip("permissions do not apply to this user (root)")
        with pytest.raises(OutputError, match="cannot write .*a.csv: Permission denied"):
            with out.write("a.csv") as stream:
                stream.write("x")
    finally:
        os.chmod(tmp_path / "out", 0o755)


def test_write_modes(tmp_path):
    out = output_dir(tmp_path)
    with out.write("a.png", binary=True) as stream:
        stream.write(b"\x89PNG")
    with out.write("b.txt") as stream:
        stream.write("µm\r\n")  # UTF-8, newlines as given
    assert (tmp_path / "a.png").read_bytes() == b"\x89PNG"
    assert (tmp_path / "b.txt").read_bytes() == "µm\r\n".encode()
    assert output.writing(stream).__enter__() is stream  # an open file object is written as is


# -- faults: links, a marker that is not contoursim's or cannot be written, killed writers --------------------


def test_a_linked_marker_is_refused_and_its_target_left_as_it_was(tmp_path):
    notes = tmp_path / "notes.txt"
    notes.write_text("mine\n")
    for target in (notes, tmp_path / "missing.txt"):  # a user's file; a dangling link (never created through)
        out = tmp_path / f"out_{target.stem}"
        out.mkdir()
        (out / ".contoursim-out").symlink_to(target)
        with pytest.raises(ConfigError, match="contoursim-out is a symbolic link"):
            output_dir(out)
    assert notes.read_text() == "mine\n"
    assert not (tmp_path / "missing.txt").exists()
    out = output_dir(tmp_path / "later")  # a marker replaced by a link after the folder was opened
    (tmp_path / "later" / ".contoursim-out").unlink()
    (tmp_path / "later" / ".contoursim-out").symlink_to(notes)
    with pytest.raises(ConfigError, match="symbolic link"):
        with out.write("a.csv") as stream:
            stream.write("x")
    assert notes.read_text() == "mine\n"
    assert sorted(p.name for p in (tmp_path / "later").iterdir()) == [".contoursim-out"]


def test_a_linked_output_file_is_replaced_not_written_through(tmp_path):
    notes = tmp_path / "notes.txt"
    notes.write_text("mine\n")
    out = output_dir(tmp_path / "out")
    with out.write("a.csv") as stream:
        stream.write("first")
    (tmp_path / "out" / "a.csv").unlink()
    (tmp_path / "out" / "a.csv").symlink_to(notes)
    with out.write("a.csv") as stream:
        stream.write("second")
    assert notes.read_text() == "mine\n"
    assert not (tmp_path / "out" / "a.csv").is_symlink() and (tmp_path / "out" / "a.csv").read_text() == "second"


def test_a_marker_that_cannot_be_recorded_in_leaves_no_unlisted_file(tmp_path, monkeypatch):
    out = output_dir(tmp_path / "out")
    real_open = os.open

    def read_only_marker(path, flags, *args):  # as chmod 444 does for a user who is not root
        if str(path).endswith(".contoursim-out") and flags & os.O_APPEND:
            raise PermissionError(13, "Permission denied")
        return real_open(path, flags, *args)

    monkeypatch.setattr(output.os, "open", read_only_marker)
    with pytest.raises(OutputError, match=r"cannot record .*a\.csv in .*\.contoursim-out: Permission denied"):
        with out.write("a.csv") as stream:
            stream.write("x")
    assert sorted(p.name for p in (tmp_path / "out").iterdir()) == [".contoursim-out"]  # nothing it does not list
    monkeypatch.undo()  # the marker writable again: the next run is not refused
    with output_dir(tmp_path / "out").write("a.csv") as stream:
        stream.write("y")
    assert output_dir(tmp_path / "out").written() == {"a.csv"}


def test_a_marker_that_is_not_text_is_named(tmp_path):
    (tmp_path / "out").mkdir()
    (tmp_path / "out" / ".contoursim-out").write_bytes(b"# written by contoursim\n\xff\xfe\n")
    with pytest.raises(ConfigError, match=r"out/\.contoursim-out is not contoursim's record .*byte 24 is not UTF-8"):
        output_dir(tmp_path / "out")


def test_a_report_file_that_is_a_directory_or_the_users_is_refused(tmp_path):
    (tmp_path / "r.json").mkdir()
    with pytest.raises(ConfigError, match=r"r\.json is a directory; name a file to write the comparison JSON to"):
        output.report_file(tmp_path / "r.json", JSON_FORM, "comparison JSON")
    run = dict.fromkeys(JSON_KEYS, 1.0)
    axes = {"x": {"phase_margin_deg": 80.0, "damping_ratio": 0.8}}
    for mine in (["runs"], "runs", {"other": 1}, {"runs": {"my": "notes"}}, {"runs": {"my": "notes"}, "axes": axes},
                 {"runs": {"none": run}}, {"runs": {"none": run}, "axes": {"x": "notes"}}, {"runs": "notes", "axes": axes}):
        (tmp_path / "mine.json").write_text(json.dumps(mine))
        with pytest.raises(FileExistsError, match="mine.json exists and is not a comparison JSON"):
            output.report_file(tmp_path / "mine.json", JSON_FORM, "comparison JSON")
    (tmp_path / "ours.json").write_text(json.dumps({"runs": {"none": run | {"settings": {}}}, "axes": axes}))
    assert output.report_file(tmp_path / "ours.json", JSON_FORM, "comparison JSON") == tmp_path / "ours.json"
    assert output.report_file(None, JSON_FORM, "comparison JSON") is None
    # a fleet's summary, as fleet_summary makes it, of no trace diagnosed and of one
    failed = {"trace": "a.csv", "error": "a.csv, line 3: column 'x': value nan is not finite"}
    diagnosed = {"trace": "b.csv", "report": {"effects": [{"name": "backlash", "axis": "x",
                                                           "parameters": {"lost_motion_um": 4.0}}]}}
    for outcomes in ([failed], [failed, diagnosed]):
        assert output.has_form(json.loads(json.dumps(fleet_summary(outcomes))), SUMMARY_FORM)
    assert not output.has_form({"failed": [], "my": "notes"}, SUMMARY_FORM)


_WRITER = """
import sys, time
from contoursim.output import output_dir
with output_dir(sys.argv[1]).write("a.csv") as stream:
    stream.write("half")
    stream.flush()
    time.sleep(60)
"""


def test_the_part_file_of_a_killed_writer_is_removed_by_the_next_run(tmp_path):
    out = output_dir(tmp_path / "out")
    writer = subprocess.Popen([sys.executable, "-c", _WRITER, str(tmp_path / "out")])
    try:
        for _ in range(600):  # the writer has its temporary file (a fresh interpreter: within a few seconds)
            parts = [p.name for p in (tmp_path / "out").iterdir() if p.name.endswith(".part")]
            if parts or writer.poll() is not None:
                break
            time.sleep(0.05)
        live = output_dir(tmp_path / "out")  # a concurrent run leaves a running writer's file alone
        assert [p.name for p in (tmp_path / "out").iterdir() if p.name.endswith(".part")] == parts
    finally:
        writer.send_signal(signal.SIGKILL)
        writer.wait()
    assert len(parts) == 1 and parts[0].startswith(f".a.csv.{writer.pid}-")
    keep = [".notes.part", f".a.csv.{writer.pid}-notahex!.part"]  # not named as contoursim names its files
    for name in keep:
        (tmp_path / "out" / name).write_text("mine")
    (tmp_path / "out" / f".b.csv.{writer.pid}-0123abcd.part").symlink_to(tmp_path / "out" / ".notes.part")
    with live.write("c.csv") as stream:  # a write removes the stale files of its own name only ...
        stream.write("c")
    assert (tmp_path / "out" / parts[0]).exists()
    output_dir(tmp_path / "out")  # ... a later run the folder's
    assert sorted(p.name for p in (tmp_path / "out").iterdir()) == sorted(
        [".contoursim-out", "c.csv", *keep, f".b.csv.{writer.pid}-0123abcd.part"])
    assert out.written() == {"c.csv"}
    report = tmp_path / "r.json"  # a report outside any output folder: its own stale files
    (tmp_path / f".r.json.{writer.pid}-0123abcd.part").write_text("half")
    with atomic_write(report) as stream:
        stream.write("{}")
    assert sorted(p.name for p in tmp_path.iterdir() if p.is_file()) == ["r.json"]


@pytest.mark.parametrize("entry", ["../victim.txt", "#by sweep ../victim.txt", "sub/plot.png"])
def test_a_record_naming_a_file_outside_the_folder_is_refused_by_its_line_before_anything_is_written(tmp_path, entry):
    """A record with a line '../victim.txt': a sweep into the folder wrote its table and plots, then ended in 'name
    must be a plain file name, got '../victim.txt'', naming neither the record nor its line (an outside probe)."""
    out = output_dir(tmp_path / "out")
    with out.write("a.csv") as stream:
        stream.write("mine")
    marker = tmp_path / "out" / ".contoursim-out"
    marker.write_text(marker.read_text() + entry + "\n")
    line = len(marker.read_text().splitlines())
    with pytest.raises(ConfigError, match=rf"\.contoursim-out, line {line}: '(\.\./victim\.txt|sub/plot\.png)' is not a "
                                          r"plain file name: this is not a record contoursim wrote"):
        output_dir(tmp_path / "out")
    assert (tmp_path / "victim.txt").exists() is False and sorted(os.listdir(tmp_path / "out")) == [".contoursim-out",
                                                                                                    "a.csv"]


def test_a_folder_given_for_a_file_is_said_to_be_one(tmp_path):
    """SimResult.save_csv on an existing folder said it 'exists; refusing to overwrite it', which overwrite=True would
    not have helped (an outside probe)."""
    for overwrite in (False, True):
        with pytest.raises(IsADirectoryError, match=f"{tmp_path} is a folder: give a file name in it"):
            output.writing(tmp_path, overwrite=overwrite)
