"""The output folder: nothing a user keeps there is overwritten."""

import pytest

from contoursim.exceptions import ConfigError
from contoursim.output import output_dir


def test_output_dir_refuses_files_it_did_not_write(tmp_path):
    out = output_dir(tmp_path / "out")
    assert out.file("a.csv") == tmp_path / "out" / "a.csv"
    (tmp_path / "out" / "a.csv").write_text("ours")
    (tmp_path / "out" / "notes.txt").write_text("mine")
    again = output_dir(tmp_path / "out")  # a later run reuses the folder and its record
    assert again.file("a.csv") == tmp_path / "out" / "a.csv"
    with pytest.raises(FileExistsError, match="notes.txt exists and contoursim did not write it"):
        again.file("notes.txt")
    assert (tmp_path / "out" / "notes.txt").read_text() == "mine"
    assert again.written() == {"a.csv"}
    with pytest.raises(ValueError, match="plain file name"):
        again.file("../escape.csv")
    assert output_dir(again) is again


def test_output_dir_refuses_a_file_and_a_users_folder(tmp_path):
    (tmp_path / "somefile").write_text("mine")
    with pytest.raises(ConfigError, match="somefile is a file, not a directory"):
        output_dir(tmp_path / "somefile")
    with pytest.raises(ConfigError, match="cannot create the output directory"):
        output_dir(tmp_path / "somefile" / "out")
    with pytest.raises(ConfigError, match="holds files that contoursim did not write"):
        output_dir(tmp_path)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["somefile"]
