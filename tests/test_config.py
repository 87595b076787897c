import pytest

from contoursim.config import TomlFile
from contoursim.exceptions import ConfigError

TEXT = """# a machine
[machine]
servo_period = 2e-4

[axes.x]
kp = 30
kvv = 2

[[body]]
name = "bed"

[[body]]
name = "x"
joint = "linear x"
"""


def test_line_of_walks_tables_and_arrays_of_tables():
    f = TomlFile("m.toml", TEXT)
    assert f.line_of("machine", "servo_period") == 3
    assert f.line_of("axes", "x") == 5
    assert f.line_of("axes", "x", "kvv") == 7
    assert f.line_of("body", 0, "name") == 10
    assert f.line_of("body", 1, "joint") == 14
    assert f.line_of("nothing") is None


def test_unknown_key_is_reported_with_its_line():
    with pytest.raises(ConfigError, match=r"^m.toml, line 7: unknown key 'kvv' in \[axes.x\] \(did you mean 'kv'\?\); expected one of: kp, kv \(see docs/machines-and-files.md, section 'File format'\)$"):
        TomlFile("m.toml", TEXT).table("axes", "x", allowed=["kp", "kv"])


def test_missing_key_and_table():
    f = TomlFile("m.toml", TEXT)
    with pytest.raises(ConfigError, match=r"line 5: missing key 'kv'"):
        f.table("axes", "x", required=["kv"])
    with pytest.raises(ConfigError, match=r"missing \[feed\]"):
        f.table("feed")


def test_syntax_error_names_the_line(tmp_path):
    file = tmp_path / "bad.toml"
    file.write_text("[a]\nx = 1\ny = = 2\n")
    with pytest.raises(ConfigError, match=r"bad.toml, line 3: not valid TOML"):
        TomlFile.read(file)


def test_unreadable_file(tmp_path):
    with pytest.raises(ConfigError, match="cannot read the file"):
        TomlFile.read(tmp_path / "absent.toml")


def test_a_table_its_sub_tables_define_is_placed_at_the_first_of_them():
    """An error about [axes] as a whole (axes named X, c) named no line: [axes] has no header of its own."""
    toml = TomlFile("m.toml", 'name = "m"\n\n[axes.X]\nkp = 1\n\n[[axes.y]]\nkp = 2\n')
    assert toml.line_of("axes") == 3 and toml.error("bad axes", "axes").line == 3
    assert toml.line_of("axes", "y") == 6 and toml.line_of("feed") is None
