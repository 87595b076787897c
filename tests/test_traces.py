import warnings

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from contoursim.exceptions import TraceFormatError
from contoursim.traces import Trace, read_trace, write_trace


def _trace(n=50, axes=("x", "y")):
    t = np.arange(n) * 1e-3
    ref = np.column_stack([np.sin(t * (i + 1)) for i in range(len(axes))])
    return Trace(t, ref, ref + 1e-3, axes, {"machine": "test"})


@pytest.mark.parametrize("axes", [("x",), ("x", "y"), ("x", "y", "z")])
def test_round_trip(tmp_path, axes):
    trace = _trace(axes=axes)
    write_trace(tmp_path / "a.csv", trace, extra={"contour": np.zeros(50)})
    back = read_trace(tmp_path / "a.csv")
    assert back.axes == axes
    assert back.metadata == {"machine": "test"}
    np.testing.assert_allclose(back.t, trace.t, rtol=0, atol=1e-15)
    # positions are written to the nm: off by at most half a nm
    np.testing.assert_allclose(back.actual, trace.actual, rtol=0, atol=0.5e-6 + 1e-12)
    np.testing.assert_allclose(back.tracking_error, 1e-3, rtol=0, atol=1e-6 + 1e-12)


def _python_fixed(value, decimals):
    """Python's own correctly rounded fixed point, trailing zeros and the sign of zero dropped."""
    text = f"{value:.{decimals}f}"
    text = text.rstrip("0").rstrip(".") if "." in text else text
    return "0" if text in ("-0", "") else text


def test_numbers_are_fixed_point_like_pythons_format(tmp_path):
    rng = np.random.default_rng(7)
    t = np.arange(20_000) * 2e-4
    x = np.concatenate([rng.normal(0, 500, 19_990), [0.0, -0.0, -3.55e-12, 1e-6, -1e-6, 4.9e-7, 123.4560004, -1.4e-6, 999.9999996, -2.5]])
    flag = rng.random(t.size) < 0.5
    write_trace(tmp_path / "f.csv", Trace(t, x[:, None], -x[:, None], ("x",)), extra={"flag": flag, "e": x / 7})
    lines = (tmp_path / "f.csv").read_text().splitlines()
    assert lines[0] == "t,x_ref,x,flag,e"
    cells = [line.split(",") for line in lines[1:]]
    assert [c[0] for c in cells] == [_python_fixed(v, 9) for v in t]
    assert [c[1] for c in cells] == [_python_fixed(v, 6) for v in x]
    assert [c[2] for c in cells] == [_python_fixed(-v, 6) for v in x]
    assert [c[3] for c in cells] == ["1" if f else "0" for f in flag]
    assert [c[4] for c in cells] == [_python_fixed(v, 6) for v in x / 7]
    assert cells[-8][1:3] == ["0", "0"] and cells[-7][1:3] == ["0.000001", "-0.000001"]  # -3.55e-12, 1e-6


def test_every_nth_sample(tmp_path):
    trace = _trace(n=50)
    write_trace(tmp_path / "e.csv", trace, extra={"k": np.arange(50)}, every=7)
    back = read_trace(tmp_path / "e.csv")
    np.testing.assert_allclose(back.t, trace.t[::7], rtol=0, atol=1e-15)
    assert back.dt == pytest.approx(7e-3)
    with pytest.raises(ValueError, match="every must be at least 1"):
        write_trace(tmp_path / "z.csv", trace, every=0)
    # a trace read_trace refuses is not written (it was: 1 row, or a sample every 1.2 s)
    for every, message in ((50, "every = 50 keeps 1 of the 50 samples, one every 0.05 s: a trace holds 2 or more.*"
                                "give every below 50"), (1200, "keeps 1 of the 50 samples")):
        with pytest.raises(ValueError, match=message):
            write_trace(tmp_path / "z.csv", trace, every=every)
    slow = _trace(n=3000)
    with pytest.raises(ValueError, match=r"every = 1000 keeps 3 of the 3000 samples, one every 1 s: a trace holds 2 "
                                         r"or more, less than 1 s apart \(read_trace refuses others\); give every "
                                         r"below 1000"):
        write_trace(tmp_path / "z.csv", slow, every=1000)
    assert not (tmp_path / "z.csv").exists()


def test_values_too_large_for_their_resolution_are_refused(tmp_path):
    trace = Trace(np.arange(3.0), np.zeros((3, 1)), np.zeros((3, 1)), ("x",))
    with pytest.raises(ValueError, match="column 'e': 1e\\+10 is too large to write to 1e-6"):
        write_trace(tmp_path / "big.csv", trace, extra={"e": np.full(3, 1e10)})
    with pytest.raises(ValueError, match="column 't': 1e\\+08 is too large to write to 1e-9"):
        write_trace(tmp_path / "late.csv", Trace(1e8 + np.arange(3.0), trace.reference, trace.actual, ("x",)))
    assert not (tmp_path / "big.csv").exists() and not (tmp_path / "late.csv").exists()


def test_refuses_to_overwrite(tmp_path):
    (tmp_path / "a.csv").write_text("mine")
    with pytest.raises(FileExistsError, match="a.csv"):
        write_trace(tmp_path / "a.csv", _trace())
    assert (tmp_path / "a.csv").read_text() == "mine"


GOOD = "# free text\n# rate: 1 kHz\nt,x_ref,x,extra\n0,0,0,a\n0.001,1,0.9,b\n0.002,2,1.9,c\n"


def test_reads_metadata_and_ignores_extra_columns(tmp_path):
    (tmp_path / "m.csv").write_text(GOOD.replace(",a", ",1").replace(",b", ",2").replace(",c", ",3"))
    trace = read_trace(tmp_path / "m.csv")
    assert trace.metadata == {"rate": "1 kHz"}
    assert trace.axes == ("x",)
    np.testing.assert_array_equal(trace.reference[:, 0], [0, 1, 2])


@pytest.mark.parametrize("column, meant", [("x_force_N", "x_force"), ("X_current", "x_current"),
                                           ("x_curent", "x_current")])
def test_an_input_column_under_another_name_is_said_not_read(tmp_path, column, meant):
    """A known force with its unit in its name, a current in capitals or misspelt: ignored like any other column, the
    diagnosis then ran as if no force acted. Said; the columns contoursim writes beside the positions are not."""
    from contoursim.exceptions import ContoursimWarning

    (tmp_path / "f.csv").write_text(f"t,x_ref,x,{column},contour,measuring\n0,0,0,100,0,1\n0.001,1,1,100,0,1\n")
    with pytest.warns(ContoursimWarning, match=rf"f.csv, line 1: column '{column}' is not read \(did you mean "
                                               rf"'{meant}'\?\)"):
        trace = read_trace(tmp_path / "f.csv")
    assert not trace.force and not trace.current
    (tmp_path / "g.csv").write_text("t,x_ref,x,x_force,contour,contour_normal,measuring,rapid\n0,0,0,1,0,0,1,0\n"
                                    "0.001,1,1,1,0,0,1,0\n")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert set(read_trace(tmp_path / "g.csv").force) == {"x"}


@pytest.mark.parametrize(
    "text, line, words",
    [
        ("t,x_ref\n0,0\n0.001,1\n", 1, "missing column 'x'"),
        ("x_ref,x\n0,0\n1,1\n", 1, "missing column 't'"),
        ("t,y_ref,y\n0,0,0\n0.001,1,1\n", 1, "x, x+y or x+y+z"),
        ("t,x_ref,x\n0,0,0\n0.001,abc,1\n", 3, "column 'x_ref': 'abc' is not a number"),
        ("t,x_ref,x\n0,0,0\n0.001,1,nan\n", 3, "column 'x': value nan is not finite"),
        # numbers Python reads and numpy does not: named, not 'the data rows could not be parsed' (found by fuzzing)
        ("t,x_ref,x\n0,0,0\n0.001,1_0,1\n", 3, "column 'x_ref': '1_0' is not a number"),
        ("t,x_ref,x\n0,0,0\n0.001,1,\uff11\n", 3, "column 'x': '\uff11' is not a number"),
        ("t,x_ref,x\n0,0,0\n\n0.002,1,1\n", 3, "a blank line among the data rows: expected 3 cells"),
        ("t,x_ref,x\n0,0,0\n0.001,1\n", 3, "expected 3 cells (as in the header), found 2"),
        ("t,x_ref,x\n0,0,0\n0.001,1,1,7\n", 3, "expected 3 cells (as in the header), found 4"),
        ("t,x_ref,x\n0,0,0\n0,001,1,25,1,5\n", 3, "found 6, all whole numbers: decimal commas? the decimal separator "
                                                  "is a point ('0.25')"),
        # quoted cells with decimal commas (an outside probe: "expected 3 cells, found 5", nothing said of why)
        ('t,x_ref,x\n"0","0","0"\n"0,001","1,25","1"\n', 3, "found 5 counting the commas inside quotes: decimal "
                                                            "commas in quoted cells?"),
        ("t,x_ref,x\n0,0,0\n0.001,1e308,1\n", 3, "column 'x_ref': value 1e308 is beyond ±1e+06 mm"),
        ("t,x_ref,x\n0,0,0\n0.001,1,-2e6\n", 3, "column 'x': value -2e6 is beyond ±1e+06 mm"),
        ("t,x_ref,x\n0,0,0\n1e300,1,1\n", 3, "column 't': value 1e300 is beyond ±1e+09 s"),
        ("t;x_ref;x\n0;0;0\n0.001;1;1\n", 1, "the header 't;x_ref;x' is separated by semicolons; expected "
                                               "comma-separated column names t, x_ref, x"),
        ("T,X_REF,X\n0,0,0\n0.001,1,1\n", 1, "column names are case-sensitive: the header has 'T', 'X_REF', 'X'; "
                                              "expected comma-separated column names t, x_ref, x"),
        # 't' in lower case, the axes not (an outside probe: "the axes present (none) must be x, x+y or x+y+z")
        ("t,X_ref,X,Y_ref,Y\n0,0,0,0,0\n0.001,1,1,1,1\n", 1, "column names are case-sensitive: the header has 'X_ref', "
                                                          "'X', 'Y_ref', 'Y'; expected comma-separated column names t"),
        ("time,x_ref,x\n0,0,0\n0.001,1,1\n", 1, "missing column 't' in the header 'time,x_ref,x'; expected"),
        # a drive's export names (an outside probe: "the axes present (none) must be x, x+y or x+y+z")
        ("t,x_cmd,x_act\n0,0,0\n0.001,1,1\n", 1, "no axis columns in the header 't,x_cmd,x_act'; expected x_ref, x "
                                                "(then y_ref, y, z_ref, z)"),
        ("# c\nt,x_ref,x\n0,0,0\n0.002,1,1\n0.001,1,1\n", 5, "column 't' must be strictly increasing"),
        # steps 1, 1, 2, 1 ms: step 2 (rows 2 -> 3) is off, row 3 is on line 1 + 1 + 3
        ("t,x_ref,x\n0,0,0\n0.001,1,1\n0.002,1,1\n0.004,1,1\n0.005,1,1\n", 5, "column 't' must be uniformly sampled: step 2"),
        ("# c\n\nt,x_ref,x\n0,0,0\n0.001,1,1\n0.002,1,1\n0.0025,1,1\n", 7, "column 't' must be uniformly sampled: step 2"),
        ("t,x_ref,x,x\n0,0,0,0\n0.001,1,1,1\n", 1, "'x' appear more than once"),
        ("t,x_ref,x\n\n", 1, "needs at least 2 data rows, found 0"),
    ],
)
def test_rejects_bad_files_naming_line_and_column(tmp_path, text, line, words):
    file = tmp_path / "bad.csv"
    file.write_text(text)
    with pytest.raises(TraceFormatError) as info:
        read_trace(file)
    message = str(info.value)
    assert message.startswith(f"{file}, line {line}: "), message
    assert words in message


def test_header_only_file_is_refused_without_a_numpy_warning(tmp_path):
    (tmp_path / "h.csv").write_text("# rate: 1 kHz\nt,x_ref,x\n")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with pytest.raises(TraceFormatError, match="line 2: needs at least 2 data rows, found 0"):
            read_trace(tmp_path / "h.csv")


def test_text_that_is_not_utf8_names_file_and_line(tmp_path):
    (tmp_path / "l1.csv").write_bytes("# Messung, Maschine Nr. 3\n# Prüfling: Kreis\nt,x_ref,x\n".encode("latin-1"))
    with pytest.raises(TraceFormatError, match=f"{tmp_path / 'l1.csv'}, line 2: byte 0xFC is not UTF-8 text"):
        read_trace(tmp_path / "l1.csv")


def test_trace_refuses_positions_no_machine_has():
    t = np.arange(3) * 1e-3
    with pytest.raises(ValueError, match=r"actual holds 1e\+308 at index \(1, 0\), beyond ±1e\+06"):
        Trace(t, np.zeros((3, 1)), [[0.0], [1e308], [0.0]], ("x",))


def test_byte_order_mark_before_the_header_is_accepted(tmp_path):
    (tmp_path / "bom.csv").write_bytes("t,x_ref,x\n0,0,0\n0.001,1,0.9\n".encode("utf-8-sig"))
    trace = read_trace(tmp_path / "bom.csv")
    np.testing.assert_array_equal(trace.t, [0.0, 0.001])


def test_a_header_whose_names_are_in_double_quotes_is_read_as_those_names(tmp_path):
    """R's write.csv quotes the header's names, not the numbers."""
    (tmp_path / "r.csv").write_text('"t","x_ref","x","y_ref","y"\n0,0,0,0,0\n0.001,1,0.9,2,1.9\n')
    trace = read_trace(tmp_path / "r.csv")
    assert trace.axes == ("x", "y")
    np.testing.assert_array_equal(trace.actual, [[0, 0], [0.9, 1.9]])


def test_trace_arrays_are_read_only_and_the_callers_are_not():
    t = np.arange(5) * 1e-3
    ref = np.zeros((5, 1))
    trace = Trace(t, ref, ref, ("x",))
    for name in ("t", "reference", "actual"):
        with pytest.raises(ValueError, match="read-only"):
            getattr(trace, name)[0] = 1.0
    ref[0] = 1.0  # the caller's array is theirs
    assert trace.reference[0, 0] == 0.0


def test_read_only_arrays_are_shared_not_copied(tmp_path):
    t = np.arange(5) * 1e-3
    ref = np.zeros((5, 1))
    for array in (t, ref):
        array.flags.writeable = False  # e.g. a Trajectory's: nobody can change them, so a trace shares them
    trace = Trace(t, ref, ref, ("x",))
    assert trace.t is t and trace.reference is ref and trace.actual is ref
    write_trace(tmp_path / "a.csv", trace, extra={"measuring": np.array([0, 1, 1, 0, 1], bool)})
    assert (tmp_path / "a.csv").read_text().splitlines()[1:3] == ["0,0,0,0", "0.001,0,0,1"]
    with pytest.raises(ValueError, match=r"measuring must have shape \(5,\)"):
        write_trace(tmp_path / "b.csv", trace, extra={"measuring": np.ones(4, bool)})


# -- units, time base, columns that do not follow: honoured or refused, naming the file and line ------------------

SINE = "\n".join(f"{k * 1e-3:.3f},{np.sin(k / 5):.6f},{np.sin((k - 1) / 5):.6f}" for k in range(40))


@pytest.mark.parametrize("key, units, t_scale, x_scale", [
    ("units", "t [s]; x_ref, x [mm]", 1.0, 1.0),
    ("units", "t [ms]; x_ref, x [m]", 1e-3, 1e3),
    ("units", "t [µs]; x_ref, x [um]", 1e-6, 1e-3),
    ("units", "t [\u03bcs]; x_ref, x [\u03bcm]", 1e-6, 1e-3),  # the Greek mu: refused, naming a µ that looks the same
    ("units", "t [ns]; x_ref, x [in]", 1e-9, 25.4),
    ("units", "m", 1.0, 1e3),  # a bare unit: the positions'
    ("units", "t [s]; x_ref, x [nm]; contour [mm]; measuring [1 = test proper, 0 = not]", 1.0, 1e-6),  # others' not read
    # the key as people write it: these were metadata, the ms read as s and the µm as mm without a word
    ("Units", "t [ms]; x_ref, x [um]", 1e-3, 1e-3),
    ("UNITS", "t [ms]; x_ref, x [um]", 1e-3, 1e-3),
    ("unit", "t [ms]; x_ref, x [um]", 1e-3, 1e-3),
])
def test_declared_units_are_honoured(tmp_path, key, units, t_scale, x_scale):
    rows = SINE.splitlines()
    others, cells = (",contour,measuring", ",0,1") if "contour" in units else ("", "")  # columns not read, units kept
    (tmp_path / "u.csv").write_text(f"# {key}: {units}\nt,x_ref,x{others}\n" + "\n".join(
        ",".join(f"{float(v) / scale:.12g}" for v, scale in zip(row.split(","), (t_scale, x_scale, x_scale))) + cells
        for row in rows))
    (tmp_path / "mm.csv").write_text("t,x_ref,x\n" + SINE)
    trace, plain = read_trace(tmp_path / "u.csv"), read_trace(tmp_path / "mm.csv")
    np.testing.assert_allclose(trace.t, plain.t, rtol=1e-9, atol=1e-15)
    np.testing.assert_allclose(trace.reference, plain.reference, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(trace.actual, plain.actual, rtol=1e-9, atol=1e-12)
    # the metadata says what the arrays hold, so that the trace written back reads the same
    assert trace.metadata["units"].startswith("t [s]; x_ref, x [mm]")
    if "contour" in units:  # the groups of columns not read stay as declared
        assert trace.metadata["units"].endswith("; contour [mm]; measuring [1 = test proper, 0 = not]")
    write_trace(tmp_path / "back.csv", trace)  # without those columns: their units are not written either
    assert (tmp_path / "back.csv").read_text().startswith("# units: t [s]; x_ref, x [mm]\nt,x_ref,x\n")
    again = read_trace(tmp_path / "back.csv")
    np.testing.assert_array_equal(again.t, np.round(trace.t, 9))
    np.testing.assert_allclose(again.actual, trace.actual, rtol=0, atol=6e-7)


@pytest.mark.parametrize("head, line, words", [
    ("# units: t [s]; x_ref, x [deg]\n", 1, "column 'x_ref' is declared in 'deg'; the position columns are read in mm, m"),
    ("# units: t [min]\n", 1, "column 't' is declared in 'min'; column 't' is read in s, ms"),
    ("# c\n# units: metric\n", 2, "the units 'metric' cannot be read: write them as contoursim does, "
                                  "'# units: t [s]; x_ref, x [mm]'"),
    ("# units: t [ms]\n# Units: t [s]\n", 2, "a second '# units:' line (the first is line 1): declare the units once"),
    ("# units:\n", 1, "'# units:' declares no unit: write them as contoursim does"),  # was passed over without a word
    # a column declared twice: the last was honoured without a word (the positions read in µm, 1000 times too small)
    ("# units: x_ref, x [mm]; x_ref, x [um]\n", 1, "'# units:' declares column 'x_ref' twice, in 'mm' and in 'um': "
                                                   "declare each column's unit once"),
    ("# units: t [s]; t [ms]\n", 1, "'# units:' declares column 't' twice, in 's' and in 'ms'"),
    ("# units: t [s]; t [s]\n", 1, "'# units:' declares column 't' twice, in 's' both times"),
    ("# units: m; x [mm]\n", 1, "'# units:' declares column 'x' twice, in 'm' and in 'mm' (a bare unit is that of all "
                                "the position columns)"),
])
def test_units_that_cannot_be_honoured_are_refused(tmp_path, head, line, words):
    (tmp_path / "u.csv").write_text(head + "t,x_ref,x\n" + SINE)
    with pytest.raises(TraceFormatError) as info:
        read_trace(tmp_path / "u.csv")
    assert str(info.value).startswith(f"{tmp_path / 'u.csv'}, line {line}: {words}"), str(info.value)


@pytest.mark.parametrize("units, words", [
    # a 3-axis line on a 2-axis trace was ignored without a word
    ("z_ref, z [m]", "'# units:' names columns 'z_ref', 'z', which the trace does not have (its columns: t, x_ref, x, y_ref, y)"),
    # a typo: the data were blamed ("column 'y': the measured y does not follow y_ref"), the y column read in mm
    ("x_ref, x, y_ref, yy [m]", "'# units:' names column 'yy', which the trace does not have (its columns: t, x_ref, x"),
    ("t [ms]; X [m]", "'# units:' names column 'X', which the trace does not have"),
])
def test_a_units_line_naming_columns_the_trace_lacks_is_refused_at_its_line(tmp_path, units, words):
    t = np.arange(200) * 1e-3
    x, y = 10 * np.sin(2 * np.pi * t), 10 * np.cos(2 * np.pi * t)
    rows = "\n".join(f"{a:.3f},{b:.9f},{b:.9f},{c:.9f},{c:.9f}" for a, b, c in zip(t, x, y))
    (tmp_path / "u.csv").write_text(f"# night run\n# units: {units}\nt,x_ref,x,y_ref,y\n{rows}")
    with pytest.raises(TraceFormatError) as info:
        read_trace(tmp_path / "u.csv")
    assert str(info.value).startswith(f"{tmp_path / 'u.csv'}, line 2: {words}"), str(info.value)


def test_a_time_base_no_servo_trace_has_is_refused_unless_declared(tmp_path):
    in_ms = "\n".join(",".join([f"{1000 * float(t):g}", x, a]) for t, x, a in (r.split(",") for r in SINE.splitlines()))
    (tmp_path / "ms.csv").write_text("# logged at 1 kHz\nt,x_ref,x\n" + in_ms)
    with pytest.raises(TraceFormatError, match=r"ms\.csv, line 2: column 't': a sample every 1 s \(1 Hz\) is no servo "
                                               r"trace's \(from 1 Hz to 1 MHz\): is the time column in ms, µs or ns\?"):
        read_trace(tmp_path / "ms.csv")
    (tmp_path / "ms.csv").write_text("# units: t [s]\nt,x_ref,x\n" + in_ms)  # seconds, declared: as the user says
    assert read_trace(tmp_path / "ms.csv").dt == 1.0
    in_ns = "\n".join(f"{k * 1e8:.0f},0,0" for k in range(40))  # 0.1 s a sample in ns: beyond the time limit
    (tmp_path / "ns.csv").write_text("t,x_ref,x\n" + in_ns)
    with pytest.raises(TraceFormatError, match=r"line 13: column 't': value 1100000000 is beyond ±1e\+09 s, not a "
                                               r"position or time a trace can hold; is the time column in ns "):
        read_trace(tmp_path / "ns.csv")
    (tmp_path / "ns.csv").write_text("# units: t [ns]\nt,x_ref,x\n" + in_ns)
    assert read_trace(tmp_path / "ns.csv").dt == pytest.approx(0.1)
    # a logger's clock: shown as written ('1e+09' read as within ±1e+09), the time since the log's start asked for
    clock = "\n".join(f"{1e9 + k * 1e-3:.3f},0,0" for k in range(40))
    (tmp_path / "clock.csv").write_text("t,x_ref,x\n" + clock)
    with pytest.raises(TraceFormatError, match=r"line 3: column 't': value 1000000000\.001 is beyond ±1e\+09 s, .* or a "
                                               r"clock's \(seconds since 1970: write the time since the log's start\)\?$"):
        read_trace(tmp_path / "clock.csv")


@pytest.mark.parametrize("rate, head, scale, decimals", [
    (3000, "", 1.0, 6), (4096, "", 1.0, 6), (30000, "", 1.0, 6), (3000, "# units: t [ms]\n", 1e3, 3)])
def test_times_printed_short_of_their_step_are_read_as_the_grid_they_were_rounded_from(tmp_path, rate, head, scale,
                                                                                        decimals):
    """A 3 kHz log printed to the µs steps 333 and 334 µs: it was refused as not uniformly sampled."""
    t = np.arange(1500) / rate
    x = 10 * np.sin(2 * np.pi * t)
    cells = [f"{scale * a:.{decimals}f}" for a in t]

    def written(times):
        rows = "\n".join(f"{a},{b:.6f},{b:.6f}" for a, b in zip(times, x))
        (tmp_path / "r.csv").write_text(f"{head}t,x_ref,x\n{rows}\n")
        return tmp_path / "r.csv"

    trace = read_trace(written(cells))
    assert trace.dt == pytest.approx(1 / rate, rel=1e-12)  # the grid's period, not a rounded step
    np.testing.assert_allclose(trace.t, t, rtol=0, atol=1e-12)
    # a time the rounding does not explain is refused as before: a sample late by 2 units of the last decimal
    cells[700] = f"{float(cells[700]) + 2 * 10.0**-decimals:.{decimals}f}"
    with pytest.raises(TraceFormatError, match=r"line \d+: column 't' must be uniformly sampled: step (699|700) is"):
        read_trace(written(cells))


def test_a_clock_that_jitters_is_refused_saying_so_not_blaming_one_step(tmp_path):
    """A logger's times printed with ±20 µs of jitter on 2 ms steps: refused as before (the diagnosis needs a uniform
    grid), but the message named only the worst step, 4354, as though the other 4353 were even; now it says how many
    are off and what to do. One step off is still named alone."""
    rng = np.random.default_rng(3)
    t = np.arange(2000) * 2e-3 + rng.uniform(-2e-5, 2e-5, 2000)
    rows = "\n".join(f"{a:.6f},{b:.4f},{b:.4f}" for a, b in zip(t, np.linspace(0.0, 10.0, t.size)))
    (tmp_path / "j.csv").write_text(f"t,x_ref,x\n{rows}\n")
    with pytest.raises(TraceFormatError, match=r"of its 1999 steps are off the median by more than 0\.1%.*a clock that "
                                               r"jitters; resample to a uniform grid"):
        read_trace(tmp_path / "j.csv")
    one = np.arange(2000) * 2e-3
    one[700] += 3e-5
    (tmp_path / "j.csv").write_text("t,x_ref,x\n" + "\n".join(f"{a:.6f},0,0" for a in one) + "\n")
    with pytest.raises(TraceFormatError, match=r"median step is 0\.002 s$"):
        read_trace(tmp_path / "j.csv")


@pytest.mark.parametrize("actual, words", [
    (lambda x, y: (y, x), "the measured x does not follow x_ref: it moves 0 mm per mm"),  # swapped columns of a circle
    (lambda x, y: (x / 1e3, y / 1e3), "it moves 0.001 mm per mm of x_ref"),  # in m, read as mm
    (lambda x, y: (-x, y), "it moves -1 mm per mm of x_ref"),
])
def test_a_measured_column_that_does_not_follow_its_reference_is_refused(tmp_path, actual, words):
    t = np.arange(2000) * 1e-3
    x, y = 10 * np.sin(2 * np.pi * t), 10 * np.cos(2 * np.pi * t)
    ax, ay = actual(x, y)
    rows = "\n".join(f"{a:.3f},{b:.9f},{c:.9f},{d:.9f},{e:.9f}" for a, b, c, d, e in zip(t, x, ax, y, ay))
    (tmp_path / "s.csv").write_text("t,x_ref,x,y_ref,y\n" + rows)
    with pytest.raises(TraceFormatError) as info:
        read_trace(tmp_path / "s.csv")
    assert str(info.value).startswith(f"{tmp_path / 's.csv'}, line 1: column 'x': "), str(info.value)
    assert words in str(info.value) and "columns swapped or units wrong?" in str(info.value)


def test_a_short_trace_whose_axis_has_not_yet_followed_is_said_maybe_too_short(tmp_path):
    """Five rows of a start: the reference moved 3 µm in 4 ms, the axis not yet; the error blamed the columns or the
    units alone (an outside probe)."""
    t = np.arange(5) * 1e-3
    rows = "\n".join(f"{a:.3f},{b:.6f},{c:.6f}" for a, b, c in zip(t, 2e-4 * np.arange(5) ** 2, [0, 0, 0, -1e-6, 0]))
    (tmp_path / "s.csv").write_text("t,x_ref,x\n" + rows)
    with pytest.raises(TraceFormatError, match=r"line 1: column 'x': the measured x does not follow x_ref: .* the trace "
                                               r"lasts 0\.004 s, maybe too short for the axis to have started to follow"):
        read_trace(tmp_path / "s.csv")


def test_a_reference_that_does_not_move_is_not_judged_by_its_slope(tmp_path):
    rows = "\n".join(f"{k * 1e-3:.3f},5,{5 + 20e-3 * np.sin(k):.6f}" for k in range(100))  # hunting ±20 µm, still
    (tmp_path / "h.csv").write_text("t,x_ref,x\n" + rows)
    assert read_trace(tmp_path / "h.csv").axes == ("x",)


def test_a_measured_column_that_moves_millimetres_against_a_reference_standing_still_is_refused(tmp_path):
    """x moving 5 mm while x_ref stands at 0 (an outside probe): read, and diagnosed as 1444 µm RMS of 'drift' that a
    fleet counted as explained by the nominal model."""
    t = np.arange(2000) * 2e-4
    rows = "\n".join(f"{a:.4f},0,{b:.6f},0,0" for a, b in zip(t, np.linspace(0.0, 5.0, t.size)))
    (tmp_path / "still.csv").write_text("t,x_ref,x,y_ref,y\n" + rows)
    with pytest.raises(TraceFormatError, match=r"line 1: column 'x': the measured x moves 1\.44 mm RMS while x_ref "
                                               r"stands still .*x_ref not logged\?"):
        read_trace(tmp_path / "still.csv")


# -- property-based: any text is read or refused in one line naming the file; what is read is what was written ------

_CELLS = st.one_of(st.sampled_from(["", "nan", "inf", "-inf", "1e308", "-1e400", "abc", " 1", "0x1", "1,5", "１"]),
                   st.floats(allow_nan=False, allow_infinity=False).map(repr),
                   st.integers(-10**7, 10**7).map(str))
_HEADERS = st.sampled_from(["t,x_ref,x", "t,x_ref,x,y_ref,y", "t,x_ref,x,y_ref,y,z_ref,z", "t,x_ref,x,extra", "x_ref,x,t",
                            "t,y_ref,y", "t;x_ref;x", "T,X_REF,X", "t,x_ref,x,x", "t,x_ref", "t,x_ref,x,x_force,x_current",
                            "t,x_ref,x,y_force", ""])
_HEADS = st.lists(st.sampled_from(["# units: t [ms]", "# units: t [s]; x_ref, x [m]", "# units: furlong", "# c", "",
                                   "# units: t [s]; x_ref, x [deg]", "# key: value", "# units: x_force [kN]; x_current [V]"]),
                  max_size=3)


def _outcome(file):
    """read_trace's result: a Trace, or a TraceFormatError whose one line starts with the file (and line); nothing else."""
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # a numpy warning would end here as an exception
        try:
            return read_trace(file)
        except TraceFormatError as exc:
            message = str(exc)
            assert message.startswith(f"{file}: ") or message.startswith(f"{file}, line "), message
            assert "\n" not in message, message
            return exc


@settings(max_examples=200, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(head=_HEADS, header=_HEADERS, rows=st.lists(st.lists(_CELLS, min_size=2, max_size=8).map(",".join), max_size=6),
       times=st.booleans())
def test_any_csv_is_read_or_refused_in_one_line_naming_the_file(tmp_path, head, header, rows, times):
    if times:  # rows with a uniform time column, so that the parse gets past the time base
        rows = [f"{k * 1e-3:g}," + row for k, row in enumerate(rows)]
    file = tmp_path / "p.csv"
    file.write_text("\n".join([*head, header, *rows]) + "\n", encoding="utf-8")
    assert isinstance(_outcome(file), (Trace, TraceFormatError))


@settings(max_examples=200, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(st.binary(max_size=300))
def test_any_bytes_are_read_or_refused_in_one_line_naming_the_file(tmp_path, data):
    file = tmp_path / "b.csv"
    file.write_bytes(data)
    assert isinstance(_outcome(file), (Trace, TraceFormatError))


_POSITIONS = st.floats(-1e5, 1e5, allow_nan=False)


@settings(max_examples=100, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(n=st.integers(2, 30), dim=st.integers(1, 3), dt=st.sampled_from([1e-5, 2e-4, 1e-3, 0.1]),
       t0=st.floats(-1e3, 1e3), data=st.data())
def test_a_written_trace_reads_back_to_the_nm(tmp_path, n, dim, dt, t0, data):
    reference = np.array(data.draw(st.lists(st.lists(_POSITIONS, min_size=dim, max_size=dim), min_size=n, max_size=n)))
    offset = np.array(data.draw(st.lists(st.floats(-0.1, 0.1), min_size=dim, max_size=dim)))
    trace = Trace(round(t0, 3) + dt * np.arange(n), reference, reference + offset, ("x", "y", "z")[:dim])
    write_trace(tmp_path / "w.csv", trace, overwrite=True)
    back = read_trace(tmp_path / "w.csv")
    assert back.axes == trace.axes and back.t.size == n
    np.testing.assert_allclose(back.t, trace.t, rtol=0, atol=0.5e-9 + 1e-12 * abs(t0))
    np.testing.assert_allclose(back.reference, trace.reference, rtol=0, atol=0.5e-6 + 1e-11)
    np.testing.assert_allclose(back.actual, trace.actual, rtol=0, atol=0.5e-6 + 1e-11)


# -- measured inputs: a known force and the motor current per axis ----------------------------------------------------


def test_force_and_current_columns_are_read_and_written(tmp_path):
    t = np.arange(40) * 1e-3
    ref = np.column_stack([np.sin(t), np.cos(t)])
    trace = Trace(t, ref, ref + 1e-3, ("x", "y"), force={"y": np.where(t > 0.02, 178.2, 0.0)},
                  current={"x": 0.5 * np.sin(3 * t), "y": np.full(40, -1.25)})
    write_trace(tmp_path / "f.csv", trace)
    assert (tmp_path / "f.csv").read_text().splitlines()[0] == "t,x_ref,x,y_ref,y,y_force,x_current,y_current"
    back = read_trace(tmp_path / "f.csv")
    assert set(back.force) == {"y"} and set(back.current) == {"x", "y"}
    np.testing.assert_array_equal(back.force["y"], trace.force["y"])
    np.testing.assert_allclose(back.current["x"], trace.current["x"], rtol=0, atol=0.5e-6)
    assert not back.force["y"].flags.writeable
    plain = Trace(t, ref, ref, ("x", "y"))
    assert plain.force == {} and plain.current == {}


@pytest.mark.parametrize("units, force_scale, current_scale", [
    ("t [s]; x_ref, x [mm]; x_force [kN]; x_current [mA]", 1e3, 1e-3),
    ("m; x_force [N]", 1.0, 1.0),  # a bare unit is the positions' only
    ("t [s]; x_current, x_force [A]", None, None),  # a force in A: refused below
])
def test_force_and_current_units_are_honoured_or_refused(tmp_path, units, force_scale, current_scale):
    rows = "\n".join(f"{k * 1e-3:.3f},{np.sin(k / 5):.6f},{np.sin((k - 1) / 5):.6f},2.5,{0.1 * k:.1f}" for k in range(40))
    (tmp_path / "u.csv").write_text(f"# units: {units}\nt,x_ref,x,x_force,x_current\n{rows}")
    if force_scale is None:
        with pytest.raises(TraceFormatError) as info:
            read_trace(tmp_path / "u.csv")
        assert str(info.value) == f"{tmp_path / 'u.csv'}, line 1: column 'x_force' is declared in 'A'; the force columns are read in N, kN"
        return
    trace = read_trace(tmp_path / "u.csv")
    np.testing.assert_allclose(trace.force["x"], 2.5 * force_scale, rtol=1e-12)
    np.testing.assert_allclose(trace.current["x"], 0.1 * np.arange(40) * current_scale, rtol=1e-12)


@pytest.mark.parametrize("cell, words", [
    ("nan", "column 'x_force': value nan is not finite"),
    ("5 N", "column 'x_force': '5 N' is not a number"),
    ("2e9", "column 'x_force': value 2e9 is beyond ±1e+09 N, not a force a trace can hold"),
])
def test_a_bad_force_cell_is_refused_naming_file_line_and_column(tmp_path, cell, words):
    rows = [f"{k * 1e-3:.3f},{k * 1e-3:.3f},{k * 1e-3:.3f},0,1" for k in range(10)]
    rows[6] = rows[6].rsplit(",", 2)[0] + f",{cell},1"
    (tmp_path / "b.csv").write_text("# pulses\nt,x_ref,x,x_force,x_current\n" + "\n".join(rows))
    with pytest.raises(TraceFormatError) as info:
        read_trace(tmp_path / "b.csv")
    assert str(info.value).startswith(f"{tmp_path / 'b.csv'}, line 9: {words}"), str(info.value)


def test_an_input_of_an_axis_the_trace_does_not_cover_is_refused(tmp_path):
    (tmp_path / "y.csv").write_text("t,x_ref,x,y_force\n0,0,0,1\n0.001,0,0,1\n")
    with pytest.raises(TraceFormatError) as info:
        read_trace(tmp_path / "y.csv")
    assert str(info.value) == (f"{tmp_path / 'y.csv'}, line 1: column 'y_force' is an input of axis 'y', which the "
                               "trace does not cover (no y_ref, y columns)")


def test_a_trace_checks_its_inputs():
    t = np.arange(5) * 1e-3
    with pytest.raises(ValueError, match="force names axis 'y', which is not one of the trace's axes x"):
        Trace(t, t[:, None], t[:, None], ("x",), force={"y": np.zeros(5)})
    with pytest.raises(ValueError, match=r"x_current must have shape \(5,\), got \(4,\)"):
        Trace(t, t[:, None], t[:, None], ("x",), current={"x": np.zeros(4)})
    with pytest.raises(ValueError, match="x_force contains a non-finite value"):
        Trace(t, t[:, None], t[:, None], ("x",), force={"x": [0, 1, np.inf, 0, 0]})


def test_a_units_line_in_the_metadata_declares_the_units_the_trace_holds(tmp_path):
    # a Trace holds s and mm: metadata {"units": "t [ms]"} wrote its times in s under "t [ms]", read back a thousand
    # times off (dt 1e-6 s for 1e-3 s), " units" or "unit" the same; "Units" beside "units" wrote a file read_trace
    # refuses
    trace = _trace(axes=("x",))
    for metadata, words in (({"units": "t [ms]"}, r"metadata 'units': declares column 't' in 'ms', but the trace holds "
                              r"it in s.*scale it by 0.001"),
                            ({" units": "m"}, r"metadata ' units': declares column 'x_ref' in 'm'.*scale it by 1000"),
                            ({"unit": "x_ref, x [in]"}, "declares column 'x_ref' in 'in'"),
                            ({"Units": "x [mm]", "units": "t [s]"}, "'Units' and 'units' are both a '# units:' line")):
        with pytest.raises(ValueError, match=words):
            write_trace(tmp_path / "a.csv", Trace(trace.t, trace.reference, trace.actual, ("x",), metadata))
    assert not (tmp_path / "a.csv").exists()
    write_trace(tmp_path / "a.csv", Trace(trace.t, trace.reference, trace.actual, ("x",), {"units": "t [s]; x [mm]"}))
    assert read_trace(tmp_path / "a.csv").dt == pytest.approx(1e-3)


@pytest.mark.parametrize("name, what", [("y_ref", "axis y's reference"), ("y", "axis y's measured position"),
                                        ("x_force", "a measured force of axis x"), ("z_current", "a measured current")])
def test_an_extra_column_read_back_as_the_traces_own_is_refused(tmp_path, name, what):
    # extra={"y_ref": ..., "y": ...} made an x trace read back as an x, y trace; "x_force" as a force it never had
    with pytest.raises(ValueError, match=f"extra column {name!r} is a column read_trace reads \\({what}"):
        write_trace(tmp_path / "a.csv", _trace(axes=("x",)), extra={name: np.zeros(50)})
    with pytest.raises(TypeError, match="extra must map column names to arrays"):
        write_trace(tmp_path / "a.csv", _trace(axes=("x",)), extra=[np.zeros(50)])


def test_a_file_of_another_kind_is_refused_by_its_name(tmp_path):
    """A G-code program given as the trace or as the model was refused by the other format's first complaint: "missing
    column 't' in the header '%'", "not valid TOML" (an outside probe)."""
    from contoursim.config import ConfigError
    from contoursim.model import load_model

    program = tmp_path / "pocket.nc"
    program.write_text("%\nG1 X10 F100\n%\n")
    with pytest.raises(TraceFormatError, match=r"pocket.nc: this is a G-code program \(by its name\), not a measured "
                                               r"trace \(a CSV table\)$"):
        read_trace(program)
    with pytest.raises(ConfigError, match=r"pocket.nc: this is a G-code program \(by its name\), not a TOML file"):
        load_model(program)
    (tmp_path / "t.csv").write_text("t,x_ref,x\n0,0,0\n0.001,1,1\n")
    with pytest.raises(ConfigError, match=r"t.csv: this is a CSV table \(by its name\), not a TOML file"):
        load_model(tmp_path / "t.csv")
