import math
import tomllib

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from contoursim.config import TomlFile, toml_text
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


def test_a_header_or_key_written_inside_a_multi_line_string_or_array_is_not_the_files():
    """A description's notes ('[axes.x]', 'kp_per_s = 35 was too soft') were taken for the table and key: a bad
    kp_per_s was said at the description's line 5, not at its own line 13."""
    f = TomlFile("m.toml", 'name = "m"\ndescription = """\nRetuned in 2024:\n[axes.x]\nkp_per_s = 35 was too soft\n'
                           "\\\"\"\" quoted, and a [bracket]\"\"\"\nnotes = '''\n[axes.x]'''\n"
                           'points = [\n  [1],\n]\n[axes.x]\nkp_per_s = -40 # """ [\n[axes]\n')
    assert f.data["axes"]["x"]["kp_per_s"] == -40
    assert f.line_of("axes", "x") == 12
    assert f.line_of("axes", "x", "kp_per_s") == 13
    assert f.line_of("points") == 9


def test_unknown_key_is_reported_with_its_line():
    with pytest.raises(ConfigError, match=r"^m.toml, line 7: unknown key 'kvv' in \[axes.x\] \(did you mean 'kv'\?\); expected one of: kp, kv \(see docs/machines-and-files.md, section 'File format'\)$"):
        TomlFile("m.toml", TEXT).table("axes", "x", allowed=["kp", "kv"])


def test_missing_key_and_table():
    f = TomlFile("m.toml", TEXT)
    with pytest.raises(ConfigError, match=r"line 5: missing key 'kv'"):
        f.table("axes", "x", required=["kv"])
    with pytest.raises(ConfigError, match=r"missing \[feed\]"):
        f.table("feed")


def test_a_name_with_a_line_break_is_refused_by_its_line():
    """It reached the trace files' '# machine: ...' line: refused at write time, no line, an empty out folder left."""
    f = TomlFile("m.toml", 'servo_period_ms = 0.5\nname = "two\\naxes"\n[[body]]\nname = "x\\r"\n')
    with pytest.raises(ConfigError, match=r"^m.toml, line 2: name must be one line, got 'two\\naxes'$"):
        f.table(text={"name": "text"})
    with pytest.raises(ConfigError, match=r"^m.toml, line 4: name in the 1st \[\[body\]\] must be one line"):
        f.table("body", 0, text={"name": "a body's name"})


def test_syntax_error_names_the_line(tmp_path):
    file = tmp_path / "bad.toml"
    file.write_text("[a]\nx = 1\ny = = 2\n")
    with pytest.raises(ConfigError, match=r"bad.toml, line 3: not valid TOML"):
        TomlFile.read(file)


@pytest.mark.parametrize("value", ["[" * 1000, "[" * 1000 + "]" * 1000, "{a = " * 1000 + "1" + "}" * 1000])
def test_values_nested_too_deeply_are_refused_by_their_line(tmp_path, value):
    """tomllib recurses into each array and inline table: 500 nested ended in a RecursionError traceback."""
    file = tmp_path / "deep.toml"
    file.write_text(f'[a]\nx = 1\ny = {value}\nz = 2\n')
    with pytest.raises(ConfigError) as info:
        TomlFile.read(file)
    assert str(info.value) == f"{file}, line 3: not valid TOML: arrays or inline tables nested too deeply"


def test_unreadable_file(tmp_path):
    with pytest.raises(ConfigError, match="cannot read the file"):
        TomlFile.read(tmp_path / "absent.toml")


def test_a_table_its_sub_tables_define_is_placed_at_the_first_of_them():
    """An error about [axes] as a whole (axes named X, c) named no line: [axes] has no header of its own."""
    toml = TomlFile("m.toml", 'name = "m"\n\n[axes.X]\nkp = 1\n\n[[axes.y]]\nkp = 2\n')
    assert toml.line_of("axes") == 3 and toml.error("bad axes", "axes").line == 3
    assert toml.line_of("axes", "y") == 6 and toml.line_of("feed") is None


_KEYS = st.text(st.characters(codec="utf-8", exclude_categories=("Cs",)), max_size=6) | st.sampled_from(
    ["x", "kp_per_s", "dx_um", "a-b", "1"])
_SCALARS = (st.text(st.characters(codec="utf-8", exclude_categories=("Cs",)), max_size=8) | st.booleans()
            | st.integers(-2**63, 2**63 - 1) | st.floats(allow_nan=False))
_VALUES = st.recursive(_SCALARS, lambda inner: st.lists(inner, max_size=3) | st.dictionaries(_KEYS, inner, max_size=3),
                       max_leaves=12)
_TABLES = st.recursive(st.dictionaries(_KEYS, _VALUES, max_size=4),
                       lambda inner: st.dictionaries(_KEYS, inner | st.lists(inner, min_size=1, max_size=2), max_size=3),
                       max_leaves=8)


@settings(max_examples=300, deadline=None)
@given(_TABLES)
def test_toml_text_is_read_back_by_tomllib_as_the_table_written(data):
    """The corrected model's writer, checked by the standard library's reader: tables, lists of tables (a [[body]]
    with its [body.errors]), inline tables within lists, any key text, infinities."""
    assert tomllib.loads(toml_text(data)) == data


def test_toml_text_writes_infinities_and_refuses_what_toml_has_not():
    assert tomllib.loads(toml_text({"a": math.inf, "b": [-math.inf]})) == {"a": math.inf, "b": [-math.inf]}
    with pytest.raises(TypeError, match="a TOML value is text, a boolean, a number, a list or a table, got NoneType"):
        toml_text({"a": None})
