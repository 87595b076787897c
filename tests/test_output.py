"""The output folder: nothing a user keeps there is overwritten, nothing is left half-written."""

import os

import pytest

from contoursim import output
from contoursim.exceptions import ConfigError, OutputError
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
