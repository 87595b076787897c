"""Property-based: whatever text the G-code reader is given, it reads a program or refuses it in one clean line."""

import re
import warnings

from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st

from contoursim.exceptions import ConfigError
from contoursim.gcode import Program, read_gcode

_WORDS = st.sampled_from(["G0", "G1", "G2", "G3", "G17", "G18", "G19", "G20", "G21", "G90", "G91", "G4", "G28", "G41",
                          "G54", "G94", "M3", "M30", "M98", "F", "X", "Y", "Z", "I", "J", "K", "R", "P", "N", "S", "T",
                          "(", ")", ";", "%", "Q", "x", " "])
_NUMBERS = st.one_of(st.sampled_from(["", "-", ".", "0", "1e5", "9" * 400, "-0", "+.5", "1.2.3", "1e-300", "0.000001", "1" + "0" * 300, "123456789012"]),
                     st.integers(-10**6, 10**6).map(str),
                     st.floats(allow_nan=False, allow_infinity=False).map(lambda v: f"{v:.4f}"))
_BLOCK = st.lists(st.tuples(_WORDS, _NUMBERS).map("".join), max_size=8).map(" ".join)
_PROGRAM = st.lists(_BLOCK, min_size=1, max_size=12).map(lambda blocks: "\n".join(["G21 G90 G17", "G1 F600", *blocks]))
_WHERE = re.compile(r"<gcode>(, line [0-9]+)?: \S")


def _read(text):
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # a numpy warning would end here as an exception
        warnings.filterwarnings("ignore", message=".*: ignored: ")  # the reader's own, by design
        warnings.filterwarnings("ignore", message=".*: the program ends on line")
        try:
            return read_gcode(text)
        except ConfigError as exc:
            message = str(exc)
            assert _WHERE.match(message), message
            assert "\n" not in message, message
            return exc


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(_PROGRAM)
@example("G1 F600\nG1 F" + "9" * 400 + " X5")  # found by hand: an F that overflows to inf
@example("G1 F600\nG2 X1 Y1 R1" + "0" * 300)  # an arc whose geometry overflows
def test_programs_of_gcode_words_read_or_are_refused_naming_the_line(text):
    assert isinstance(_read(text), (Program, ConfigError))


@settings(max_examples=300, deadline=None)
@given(st.text(max_size=200).map(lambda text: "G1 F600\n" + text + "\n"))
def test_any_text_reads_or_is_refused_naming_the_line(text):
    assert isinstance(_read(text), (Program, ConfigError))
