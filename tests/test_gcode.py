"""G-code reader: geometry of the moves worked out by hand, errors naming file and line."""

import io
import warnings

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from contoursim.exceptions import ConfigError, ContoursimWarning
from contoursim.gcode import block_errors, read_gcode
from contoursim.pathfile import load_path_file, read_path_file

POCKET = """%
(a closed contour: lines, I/J arc, R arc, incremental arc)
N10 G21 G17 G90
N20 G0 X-30 Y0 ; positioning only
N30 G1 Y-12 F600
N40 G3 X-22 Y-20 I8 J0
N50 G1 X22 F1200
N60 G3 X30 Y-12 R8
N70 G1 Y12
N80 G91 G3 X-8 Y8 I-8
N90 G90 G1 X-30 (back along the top)
N100 Y0
N110 G0 Z50
M30
"""


def test_contour_program():
    program = read_gcode(POCKET)
    path = program.path
    assert path.dim == 2 and path.closed and program.source == "<gcode>"
    assert program.lines.tolist() == [5, 6, 7, 8, 9, 10, 11, 12]  # G0 before and after the cut left out
    np.testing.assert_allclose(program.feeds * 60, [600, 600, 1200, 1200, 1200, 1200, 1200, 1200])
    np.testing.assert_allclose(path.start, [-30, 0, 0])
    corners = [path.primitives[i] for i in (1, 3, 5)]
    np.testing.assert_allclose([c.center for c in corners], [[-22, -12, 0], [22, -12, 0], [22, 12, 0]], atol=1e-12)
    np.testing.assert_allclose([c.sweep for c in corners], np.pi / 2, rtol=1e-12)
    np.testing.assert_allclose(path.corner_angles(), [0, 0, 0, 0, 0, 0, np.pi / 2], atol=1e-7)  # tangent joins
    straight = 12 + 44 + 24 + 52 + 20  # then a sharp corner at (-30, 20)
    assert path.length == pytest.approx(straight + 3 * np.pi / 2 * 8, rel=1e-13)


def test_r_word_major_arc_and_helix():
    # R < 0: the arc over 180°; chord 10 on R 10 subtends 60°, so the major arc turns 300° (clockwise)
    program = read_gcode("G17 G90 G0 X0 Y0\nG2 X10 Y0 R-10 F100\nG3 X10 Y0 Z6 I-5\n")
    major, turn = program.path.primitives
    assert major.sweep == pytest.approx(-np.radians(300), rel=1e-12) and major.radius == pytest.approx(10)
    np.testing.assert_allclose(major.end, [10, 0, 0], atol=1e-12)
    # start = end in the plane with I/J: a full turn, here rising 6 mm along Z: a helix
    assert turn.sweep == pytest.approx(2 * np.pi) and turn.rise == pytest.approx(6 / (2 * np.pi))
    np.testing.assert_allclose(turn.end, [10, 0, 6], atol=1e-12)
    assert program.path.dim == 3


@pytest.mark.parametrize("word, middle", [("G2", [np.sqrt(50), 0, np.sqrt(50)]), ("G3", [-np.sqrt(50), 0, -np.sqrt(50)])])
def test_g18_arc_turns_about_y(word, middle):
    # G18: the ZX plane, G3 counter-clockwise about +Y, which turns +X towards -Z: from (10, 0, 0)
    # to (0, 0, 10) G2 turns 90° (midpoint at 45°), G3 turns 270° (midpoint at 135° towards -Z)
    program = read_gcode(f"G18 G0 X10 Z0\n{word} X0 Z10 I-10 K0 F100\n")
    arc = program.path.primitives[0]
    np.testing.assert_allclose(arc.axis, [0, 1, 0])
    np.testing.assert_allclose(program.path.evaluate([program.path.length / 2])[0][0], middle, atol=1e-12)


def test_rapid_between_cuts_is_kept():
    program = read_gcode("G0 X0 Y0\nG1 X10 F600\nG0 X10 Y10\nG1 X0\n", rapid_feed=100.0)
    assert program.path.roles == ("path", "rapid", "path")
    np.testing.assert_allclose(program.feeds, [10.0, 100.0, 10.0])


def test_arc_centre_is_moved_onto_the_bisector():
    # radii 10 and 10.001 (within the 0.002 mm tolerance): the arc still ends exactly at the target
    arc = read_gcode("G0 X10 Y0\nG3 X0 Y10.001 I-10 J0 F100\n").path.primitives[0]
    np.testing.assert_allclose(arc.end, [0, 10.001, 0], atol=1e-12)
    np.testing.assert_allclose(np.linalg.norm(arc.start - arc.center), np.linalg.norm(arc.end - arc.center))


_PLANE_WORDS = {17: ("X", "Y", "Z", "I", "J"), 18: ("Z", "X", "Y", "K", "I"), 19: ("Y", "Z", "X", "J", "K")}


@settings(max_examples=200, deadline=None)
@given(st.sampled_from([17, 18, 19]), st.sampled_from(["G2", "G3"]), st.floats(0.5, 200.0), st.floats(0.05, 2 * np.pi - 1e-4),
       st.floats(-1.9e-3, 1.9e-3), st.floats(-5.0, 5.0).map(lambda rise: round(rise, 6)))
def test_an_arc_whose_end_is_off_its_radius_stays_between_the_two_radii(plane, word, radius, sweep, off, rise):
    """Any sweep, end point off the radius within the tolerance: the path keeps to the programmed centre's band.

    A 359.99° arc of R 10 ending 1 µm off its radius was cut about a centre 5 mm away (the chord's bisector),
    6.45 mm from the programmed circle.
    """
    a, b, n, i, j = _PLANE_WORDS[plane]
    turn = -sweep if word == "G2" else sweep
    end = (radius + off) * np.array([np.cos(turn), np.sin(turn)])
    program = read_gcode(f"G{plane} G0 {a}{radius:.12f} {b}0 {n}0\n{word} {a}{end[0]:.12f} {b}{end[1]:.12f} "
                         f"{n}{rise:.6f} {i}{-radius:.12f} {j}0 F600\n")
    axes = ["XYZ".index(a), "XYZ".index(b)]
    points = program.path.evaluate(np.linspace(0, program.path.length, 2001))[0]
    distance = np.linalg.norm(points[:, axes], axis=1)  # from the programmed centre, the origin of the plane
    r_end = np.hypot(*end)
    assert min(radius, r_end) - 1e-9 <= distance.min() and distance.max() <= max(radius, r_end) + 1e-9
    np.testing.assert_allclose(program.path.end[axes], end, atol=1e-9)
    assert program.path.end["XYZ".index(n)] == pytest.approx(rise, abs=1e-9)
    assert np.all(program.path.corner_angles() < 1e-6)  # the halves join tangentially
    assert set(program.lines) == {2}


def test_an_arc_cut_at_its_middle_is_one_block():
    from contoursim.feed import FeedSettings, sample
    from contoursim.machine import load_machine
    from contoursim.simulation import simulate

    program = read_gcode("G0 X10 Y0\nG3 X9.9885 Y-0.5 I-10 J0 F1200\nG1 X20\n")
    assert len(program.path.primitives) == 3 and program.lines.tolist() == [2, 2, 3]
    machine = load_machine("demo_mill")
    trajectory = sample(program.path, FeedSettings(tuple(program.feeds)).plan(program.path), machine.servo_period)
    result = simulate(machine, trajectory)
    errors = block_errors(program, result)
    assert sorted(errors.line.tolist()) == [2, 3]
    k = errors.line.tolist().index(2)
    assert errors.text[k] == "G3 X9.9885 Y-0.5 I-10 J0 F1200" and errors.feed[k] * 60 == pytest.approx(1200)
    on_arc = (result.trajectory.primitive <= 1) & result.trajectory.measuring
    assert errors.contour_max[k] == result.contour.magnitude[on_arc].max()


@pytest.mark.parametrize("text, line, message", [
    ("G21\nG20 G1 X1 F100\n", 2, "inch programs are not supported"),
    ("G1 X1 F100\nE5\n", 2, "unknown word E5"),
    ("G1 X1 F100\nG1 X1e-3\n", 2, "X1e-3: a number in exponent notation is not G-code; write it in decimals"),
    ("G1 X1 F100\nG10 L2 P1 X0\n", 2, "unknown word G10"),  # the block's G code, not its L word
    # a canned cycle's own words were blamed ("unknown word Q2"), as were a subprogram call's (an outside probe)
    ("G0 X0 Y0 Z5\nG99 G83 X5 Y5 Z-10 R2 Q2 F200\n", 2, "canned cycles \\(G99: a cycle or its return level\\)"),
    ("G0 X0 Y0 Z5\nG83 X5 Y5 Z-10 R2 Q2 F200\n", 2, "canned cycles \\(G83: a cycle or its return level\\) are not"),
    ("G1 X1 F100\nM98 P2000 L2\n", 2, "subprogram calls \\(M98\\)"),
    ("G1 X1 F100\nG7\n", 2, "unknown word G7"),
    ("G1 X1 F100\nG41 D1 X2\n", 2, "cutter radius compensation \\(G41\\) is not supported"),
    ("G1 X1 F100\nG95 X2 F0.1\n", 2, "feed per revolution"),
    ("G90.1\nG1 X1 F100\n", 1, "absolute arc centres \\(G90.1\\) are not supported"),
    ("G1 X1 F100\nM98 P1000\n", 2, "subprogram calls \\(M98\\)"),
    ("G1 X1 F100\nG1 X2 P3\n", 2, "P belongs to a dwell"),
    # LinuxCNC's turns and o-word subroutines: said as a dwell's P and as "cannot read 'sub'" (an outside probe)
    ("G0 X10 Y0\nG3 X10 Y0 I-10 J0 P3 F500\n", 2, "P3 on an arc \\(LinuxCNC: its number of turns\\) is not supported"),
    ("G21 G90\no100 sub\nG1 X10 F100\no100 endsub\n", 2, "cannot read 'sub': LinuxCNC's o-word subroutines and "
                                                         "control flow"),
    ("G1 X1 F100\nO200 IF [1 GT 0]\n", 2, "cannot read 'IF \\[1 G': LinuxCNC's o-word"),
    ("G1 X1 F100\nG91 G28 Z0\nG1 X2\n", 3, "from a machine position is not supported: line 2 \\(G28/G30/G53\\) took Z there; "
                                         "position Z with G0 first"),
    ("G1 X1 F100\nG28\nG0 X0 Y0\nG1 X2\n", 4, "line 2 \\(G28/G30/G53\\) took Z there"),  # G28 alone: all axes
    # one modal group twice in a block: which wins depends on the controller (it was G3, silently)
    ("G1 X1 F100\nG2 G3 X11 Y0 R5\n", 2, "G2 and G3 in one block belong to one modal group"),
    ("G17 G19 G1 X1 F100\n", 1, "G17 and G19 in one block"),
    ("G1 X1 F100\nG90 G91 X2\n", 2, "G90 and G91 in one block"),
    ("G1 X1 F100\nG28 G91 Z0\nG0 Z-5\nG1 X2\n", 4, "line 2 \\(G28/G30/G53\\) took Z there"),  # still unknown
    ("G1 X1 F100\nG53 G0 Z0\nG1 X2\n", 3, "line 2 \\(G28/G30/G53\\) took Z there"),
    # before the first feed move too (it cut at the home height, silently; an outside probe)
    ("G90\nG28 G91 Z0\nG90\nG1 X5 F3000\n", 4, "line 2 \\(G28/G30/G53\\) took Z there; position Z with G0 first"),
    ("G0 X10 Y0\nG2 X20 Y0 F100\n", 2, "the arc centre is missing: give I/J \\(relative to the arc's start\\) or R"),
    # a centre word off the arc's plane (it was read as 0: another arc, silently)
    ("G18 G0 X10 Y0\nG2 X20 Y0 J5 F100\n", 2, "J is not a centre word of the G18 \\(ZX\\) arc: give I/K"),
    ("G18 G0 X10 Z0\nG2 X20 Z0 I5 J3 F100\n", 2, "J is not a centre word of the G18"),
    ("G0 X10 Y0\nG2 X20 Y0 I5 K2 F100\n", 2, "K is not a centre word of the G17 \\(XY\\) arc: give I/J"),
    ("G19 G0 Y10 Z0\nG3 Y20 Z0 I1 J5 F100\n", 2, "I is not a centre word of the G19 \\(YZ\\) arc"),
    ("G0 X1\n\nG1 X2\n", 3, "missing F before the first feed move"),
    ("G0 X10\nG2 X0 Y10.1 I-10 F100\n", 2, "start radius 10 mm and end radius 10.1 mm differ"),
    ("G0 X10\nG2 X0 Y10.0021 I-10 F100\n", 2, "end radius 10.0021 mm differ by more than 0.002 mm"),
    ("G1 X1 F100\nG1 X2 I3\n", 2, r"I belongs to arc moves \(G2/G3\) only"),
    ("G1 X1 F100\nG1 X2 X3\n", 2, "appears twice"),
    ("X1\n", 1, "needs a motion mode"),
    ("G1 X1 F100 (open comment\n", 1, "unbalanced parenthesis"),
    ("G1 X1 F100\n(open ; comment\n", 2, "unbalanced parenthesis"),  # the ; is inside the open comment
    ("G1 X1 F100 (nested (comment) here)\n", 1, "unbalanced parenthesis"),
    ("G0 X1\nG0 X2\n", None, "no feed move"),
    # G1 blocks that move nothing were said to be no feed move at all (an outside probe)
    ("G0 X0 Y0\nG1 X0 Y0 F600\nG1 X0\n", None, r"the program's feed moves \(G1, G2 or G3\) all have zero length"),
    # F0.000001 was "feed must lie within [1e-06, 1e+12] (mm/s, ...), got 1.66667e-08": no line, and in mm/s
    ("G0 X0\nG1 X5 F0.000001\n", 2, r"F1e-06 must lie within \[6e-05, 6e\+13\] mm/min"),
    ("G1 X5 F0\n", 1, r"F0 must lie within \[6e-05, 6e\+13\] mm/min"),
    ("G1 X10,5 F100\n", 1, "cannot read ',5': a decimal comma\\? write the number with a point"),
    ("G1 X 1 0 F100\n", 1, r"cannot read '0': a space inside a number \(X 1 0\)\? write the number without one"),
    ("G1 X１0 F100\n", 1, r"cannot read 'X１0': a digit other than 0-9 \(a full-width one\?\)"),  # was read as X10
    ("#100=5\nG1 X#100 F100\n", 1, "cannot read '#100=5': macro variables and expressions"),
    ("G1 X[1+2] F100\n", 1, r"cannot read 'X\[1\+2\]': macro variables"),
])
def test_errors_name_the_line(text, line, message):
    with pytest.raises(ConfigError, match=message) as info:
        read_gcode(text)
    assert info.value.line == line and info.value.source == "<gcode>"


def test_errors_name_the_file(tmp_path):
    file = tmp_path / "part.nc"
    file.write_text("G21\nG1 X1 Y1\n")
    with pytest.raises(ConfigError, match="part.nc, line 2: missing F") as info:
        read_gcode(file)
    assert info.value.source == str(file)


REAL = """%
O1234 (POCKET FINISH)
N10 G21 G17 G40 G49 G80 G90 G94
N20 G91 G28 Z0
N30 G90 G54 T1 M6
N40 S12000 M3
N50 G0 G43 H1 Z50. M8
N60 G0 X-30. Y0
N70 G1 Y-12. F600
N80 G3 X-22. Y-20. I8. J0
N90 G4 P500 ; dwell 0.5 s (X would be the time too, not a move)
N100 G04 X0.5
N110 G1 X22.
N120 G0 Z50. M9
N130 M5
N140 G91 G28 Z0
N150 M30
%
"""


def test_a_real_program_reads_and_lists_what_it_ignored():
    words = "O1234 G28 T1 G54 S12000 M3 H1 M8 G43 M9 M5".split()  # M6 is a stop, before the first cut here
    with pytest.warns(ContoursimWarning) as record:
        program = read_gcode(REAL)
    # grouped by why the path is as if they were not there: G54 and G43 change where it is, as the path says
    assert [str(w.message) for w in record] == ["<gcode>: ignored: G54 G43 (tool length and work offsets: the path is "
                                                "the tool tip's, from the work offset); O1234 G28 T1 S12000 M3 H1 M8 "
                                                "M9 M5 (no contour motion)"]
    assert program.ignored == tuple(words)
    # G91 in the G28 block stays modal: G90 on N30 restores absolute; the dwell's X is a time, not a move
    assert program.lines.tolist() == [9, 10, 13]
    np.testing.assert_allclose(program.path.start, [-30, 0, 50])
    np.testing.assert_allclose(program.path.end, [22, -20, 50])
    assert program.stops == (1,)  # the two dwells after the arc


def test_a_word_set_in_every_block_is_listed_at_its_first_values_and_counted():
    """A spindle speed set in each of 5000 blocks: the warning listed every value in one line of 131 KB."""
    blocks = "".join(f"G1 X{i + 1} S{10000 + i} T{i % 7} F600\n" for i in range(5000))
    with pytest.warns(ContoursimWarning) as record:
        program = read_gcode(f"G0 X0 Y0 M3\n{blocks}")
    assert [str(w.message) for w in record] == ["<gcode>: ignored: M3 S10000 S10001 S10002 … (5000 S words) "
                                                "T0 T1 T2 … (7 T words) (no contour motion)"]
    assert len(program.ignored) == 5008  # all of them, as read


def test_a_dwell_stops_the_motion_and_waits_in_position(tmp_path):
    """G4 between two moves in line: the motion stops there (it ran on through at full feed) and waits in position."""
    from contoursim.feed import FeedSettings, sample

    (tmp_path / "dwell.nc").write_text("G0 X0 Y0\nG1 X10 F1200\nG4 P0.5\nG1 X20\nG4 P1\nG0 Y5\nG1 X30\nG4 P1\n")
    read = read_path_file(tmp_path / "dwell.nc")
    assert read.program.stops == read.feed.stops == (0, 1)  # not after the last move: the path ends at rest
    trajectory = sample(read.path, read.feed.plan(read.path, in_position=0.1), 1e-3)
    at = np.abs(trajectory.position[:, 0] - 10) < 1e-12
    assert at.sum() >= 100 and np.abs(trajectory.velocity[at]).max() < 1e-9  # 0.1 s in position at X10
    plain = sample(read.path, FeedSettings(read.feed.feed).plan(read.path, in_position=0.1), 1e-3)
    assert np.abs(plain.velocity[np.abs(plain.position[:, 0] - 10) < 0.01, 0]).min() == pytest.approx(20.0)


@pytest.mark.parametrize("block, stops", [
    ("M0", (0,)),  # a program stop in a block of its own: at the end of the move before it
    ("M60", (0,)),  # a pallet change and stop
    ("M6", (0,)),  # a tool change
    ("G1 X10 Y10 M0", (1,)),  # at the end of the move of its block, not before it
    ("M6 G1 X10 Y10", (0,)),  # a tool change before the move of its block, as a dwell
    ("G1 X10 M0", (0,)),  # a move of no length: at the end of the move before
])
def test_a_program_stop_or_a_tool_change_stops_the_motion_as_a_dwell_does(tmp_path, block, stops):
    """M0, M6 and M60 were ignored: the motion ran on through them at full feed, as no controller runs it."""
    from contoursim.feed import sample

    def run(program):
        (tmp_path / "part.nc").write_text(f"G0 X0 Y0\nG1 X10 F1200\n{program}G1 X20 Y10\nG1 X30\n")
        read = read_path_file(tmp_path / "part.nc")
        return read, sample(read.path, read.feed.plan(read.path), 1e-3)

    read, stopped = run(f"{block}\n")
    assert read.program.stops == read.feed.stops == stops
    moves = "".join(f"{line}\n" for line in ("G1 X10", "G1 X10 Y10") if line in block)
    dwelled = run(f"{moves}G4 P0\n" if block.startswith("G1") else f"G4 P0\n{moves}")[1]  # the same motion
    np.testing.assert_array_equal(stopped.position, dwelled.position)


@pytest.mark.parametrize("block", ["G53 G0 Z0 M0", "G91 G28 Z0 M0", "G53 G0 Z0", "G91 G28 Z0"])
def test_a_move_home_stops_the_motion(block):
    """The axes leave for a machine position: the motion stops at the end of the move before. It ran through at the
    feed, as if the tool had not left (the G0 back, of no length in work coordinates, was skipped); and an M0 beside
    the move home was dropped without a word."""
    with pytest.warns(ContoursimWarning, match="ignored: G"):
        program = read_gcode(f"G1 X10 F100\n{block}\nG90 G0 Z0\nG1 X20\n")
    assert program.stops == (0,)


def test_the_optional_stop_is_run_through_as_with_its_switch_off():
    with pytest.warns(ContoursimWarning, match=r"ignored: M1 \(optional stop: run through, as with its switch off\)$"):
        program = read_gcode("G0 X0 Y0\nG1 X10 F1200\nM1\nG1 X20 Y10\n")
    assert program.stops == ()


@pytest.mark.parametrize("block, line, feed, stops", [
    ("G1 Y10 M30\nG1 X0", 4, 600, ()),  # the program ends after the move of its block: G1 X0 is not run
    ("G1 Y10 M2\nG1 X0", 4, 600, ()),
    ("G4 P0.5 G1 Y10", 4, 600, (0,)),  # the dwell, then the move of its block
    ("G4 P0.5 F300\nG1 Y10", 5, 300, (0,)),  # an F in a dwell's block sets the feed
    ("G4 X0.5\nG1 Y10 F300", 5, 300, (0,)),  # X without P is the dwell's time (Fanuc), not a move
])
@pytest.mark.filterwarnings("ignore:.*the program ends on line 4")  # the G1 X0 after M30/M2: said, not run
def test_a_move_in_a_block_that_ends_the_program_or_dwells_is_run(block, line, feed, stops):
    """A move in the block of M30/M2 or of a G4 was dropped without a word (as if the block held no move)."""
    program = read_gcode(f"G17 G90\nG0 X0 Y0\nG1 X10 F600\n{block}\n")
    np.testing.assert_allclose(program.path.end, [10, 10, 0])
    assert program.lines.tolist() == [3, line]
    np.testing.assert_allclose(program.feeds * 60.0, [600, feed])
    assert program.stops == stops


@pytest.mark.parametrize("head", ["%\n", "%\n(a comment alone)\n%\n", ""])
def test_a_percent_line_after_a_block_ends_the_program(head):
    """A G1 Y10 after the closing '%' of a tape was run and scored (Fanuc and LinuxCNC read nothing after it);
    the blocks not run are said (they went without a word)."""
    with pytest.warns(ContoursimWarning, match=r"the program ends on line \d+: the 1 line\(s\) after it \(from line "
                                               r"\d+\) are not run"):
        program = read_gcode(f"{head}G0 X0 Y0\nG1 X10 F1000\n%\nG1 Y10\n")
    np.testing.assert_allclose(program.path.end, [10, 0, 0])
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # nothing but comments and blank lines after M30: nothing to say
        read_gcode("G0 X0 Y0\nG1 X10 F1000\nM30\n\n(end)\n%\n")


@pytest.mark.parametrize("separator", ["\x85", "\x0c", "\u2028"])
def test_lines_are_numbered_as_an_editor_numbers_them(tmp_path, separator):
    """A Latin-1 '…' (byte 0x85, U+0085 read as Latin-1), a form feed or U+2028 split a line: the lines after it were
    numbered one too far, and a comment holding one was refused as unbalanced."""
    program = read_gcode(f"G17 (Fr\xe4se {separator} 1)\nG0 X0 Y0 ; caf{separator}\nG1 X10 F600\nG1 Y10 F300\n")
    assert program.lines.tolist() == [3, 4]
    with pytest.raises(ConfigError, match="^<gcode>, line 4: unknown word Q5"):
        read_gcode(f"G17\nG0 X0 Y0 ; {separator}\nG1 X10 F600\nG1 Y10 Q5\n")
    if separator == "\x85":  # as a Latin-1 file holds it
        (tmp_path / "p.nc").write_bytes(b"G17 (Fr\xe4se \x85)\nG0 X0 Y0\nG1 X10 F600\nG1 Y10 Q5\n")
        with pytest.raises(ConfigError, match=r"p.nc, line 4: unknown word Q5"):
            read_gcode(tmp_path / "p.nc")


def test_a_program_that_ignores_nothing_warns_nothing(recwarn):
    read_gcode("G0 X0 Y0\nG1 X10 F600\n")
    assert not recwarn.list


def test_a_block_marked_for_block_delete_runs_and_its_line_is_named():
    """'/' (Fanuc's '/1'-'/9' too) is the controller's optional-block skip: the program as written runs, switch off."""
    with pytest.warns(ContoursimWarning, match=r"<gcode>: block delete \(/\) on lines 3, 4: run, as with the switch off"):
        program = read_gcode("G0 X0 Y0\nG1 X10 F600\n/G1 Y10\n  /2 G1 X0 (level 2)\nG1 Y0\n")
    assert program.lines.tolist() == [2, 3, 4, 5]
    np.testing.assert_allclose(program.path.end, [0, 0, 0])
    with pytest.warns(ContoursimWarning, match=r"on lines 2, 3, 4, 5, 6, 7, 8, 9, 10, 11 … \(12 in all\): run"):
        read_gcode("G1 X0 F600\n" + "/G1 X1\n/G1 X0\n" * 6)
    with pytest.raises(ConfigError, match="line 2: cannot read '/'"):  # the mark starts a block, it is no word
        read_gcode("G0 X0 Y0\nG1 X10 / Y10 F600\n")


def test_latin1_comment_and_byte_order_mark_are_read(tmp_path):
    (tmp_path / "l1.nc").write_bytes("(Kontur für Prüfteil)\nG0 X0 Y0\nG1 X10 F600\n".encode("latin-1"))
    (tmp_path / "bom.nc").write_bytes("G0 X0 Y0\nG1 X10 F600 (µm)\n".encode("utf-8-sig"))
    for name in ("l1.nc", "bom.nc"):
        np.testing.assert_allclose(read_gcode(tmp_path / name).path.end, [10, 0, 0])
    with pytest.raises(ConfigError, match=f"{tmp_path / 'l1.nc'}, line 3: cannot read 'Gü'"):
        (tmp_path / "l1.nc").write_bytes("G0 X0 Y0\nG1 X10 F600\nGü\n".encode("latin-1"))
        read_gcode(tmp_path / "l1.nc")


def test_a_semicolon_inside_a_parenthesis_comment_belongs_to_the_comment():
    """Fusion 360 and OpenBuilds posts write ``(T1 D=6. CR=0. - ZMIN=-5. - flat end mill ; note)``."""
    program = read_gcode("(T1 D=6. CR=0. - ZMIN=-5. - flat end mill ; climb)\n"
                         "G0 X0 Y0 (rapid ; to start) G90\n"
                         "G1 X10 F600 ; a ; comment may hold ( or ) too\n")
    np.testing.assert_allclose(program.path.end, [10, 0, 0])
    assert program.texts == ("G1 X10 F600 ; a ; comment may hold ( or ) too",)


def test_a_tool_change_between_cuts_is_positioning_with_rapids():
    # G28 G91 Z0 takes Z to a machine position; the G0 moves after it are rapids from where the tool was,
    # and the G0 with Z (G43 Z5 H2, zero length here) brings Z back into work coordinates
    with pytest.warns(ContoursimWarning, match="ignored"):
        program = read_gcode("G0 X0 Y0 Z5\nG1 Z-1 F100\nG1 X10\nG0 Z5\nG28 G91 Z0\nG90\nT2 M6\nG0 X20 Y0\n"
                             "G43 Z5 H2\nG1 Z-1 F200\nG0 Z5\nG28 G91 Z0\nM30\n")
    assert program.path.roles == ("path", "path", "rapid", "rapid", "path")
    assert program.lines.tolist() == [2, 3, 4, 8, 10]
    assert program.texts[3:] == ("G0 X20 Y0", "G1 Z-1 F200")
    np.testing.assert_allclose([p.end for p in program.path.primitives][2:],
                               [[10, 0, 5], [20, 0, 5], [20, 0, -1]])


def test_mach3_arc_centre_mode_is_the_one_assumed():
    np.testing.assert_allclose(read_gcode("G91.1 G90 G0 X10 Y0\nG3 X0 Y10 I-10 J0 F100\n").path.primitives[0].center,
                               [0, 0, 0], atol=1e-12)


def test_linuxcnc_path_tolerance_is_accepted():
    # said as a path mode, with its tolerance; it was "ignored (no contour motion): G64", P0.01 not named
    with pytest.warns(ContoursimWarning, match=r"ignored: G64 P0.01 \(path modes: the planner's corner_tolerance_deg "
                                               r"decides where the motion stops\)$"):
        assert read_gcode("G64 P0.01\nG0 X0 Y0\nG1 X1 F100\n").ignored == ("G64 P0.01",)


@pytest.mark.parametrize("suffix", [".nc", ".ngc", ".gcode", ".tap", ".cnc", ".mpf", ".iso", ".EIA"])
def test_the_usual_gcode_file_names_are_read_as_gcode(tmp_path, suffix):
    file = tmp_path / f"part{suffix}"
    file.write_text("G0 X0 Y0\nG1 X10 F600\n")
    read = read_path_file(file)
    assert read.program.source == str(file) and read.feed.feed == (10.0,)
    np.testing.assert_allclose(load_path_file(file)[0].end, [10, 0, 0])


def test_another_file_type_is_refused_with_the_types_read(tmp_path):
    (tmp_path / "part.txt").write_text("G0 X0 Y0\nG1 X10 F600\n")
    with pytest.raises(ConfigError, match=r"part.txt: unknown path file type '.txt': use .toml, or G-code .nc .ngc "
                                          r".gcode .tap .cnc .mpf .iso .eia"):
        read_path_file(tmp_path / "part.txt")


def test_block_errors_are_each_blocks_worst_samples_worst_block_first():
    from contoursim.feed import FeedSettings, sample
    from contoursim.machine import load_machine
    from contoursim.simulation import simulate

    # line 3 is 0.1 µm long, passed between two samples 2 µm apart: no sample, no figure, last of the cutting blocks
    program = read_gcode("G0 X0 Y0\nG1 X9.9991 F600\nG1 X9.9992\nG1 X20\nG0 Y10\nG1 X0 F1200 (back ; faster)\n")
    machine = load_machine("demo_mill")
    settings = FeedSettings(tuple(program.feeds))
    trajectory = sample(program.path, settings.plan(program.path, in_position=0.1), machine.servo_period)
    result = simulate(machine, trajectory)
    assert not (result.trajectory.primitive == 1).any()
    errors = block_errors(program, result)
    assert errors.line.tolist()[-2:] == [3, 5] and errors.rapid.tolist() == [False] * 4 + [True]
    assert np.isnan(errors.contour_max[3]) and np.isnan(errors.tracking_max[3])
    assert errors.line[0] == 6 and errors.text[0] == "G1 X0 F1200 (back ; faster)"
    np.testing.assert_array_equal(errors.feed * 60, [1200, 600, 600, 600, 10000])
    # each block's figure is the largest over the samples whose reference lies on it (the stop at its end included)
    on = np.searchsorted([0, 9.9991, 9.9992, 20, 30], result.trajectory.s, side="left")  # 1-based block of each sample
    tracking = np.linalg.norm(result.tracking_error, axis=1)
    keep = result.trajectory.measuring | result.trajectory.rapid
    for line, block in ((2, 1), (4, 3), (5, 4), (6, 5)):
        k = errors.line.tolist().index(line)
        mine = keep & (on == block)
        assert errors.tracking_max[k] == tracking[mine].max()
        assert errors.contour_max[k] == result.contour.magnitude[mine].max()
    assert 1e3 * np.nanmax(errors.tracking_max[~errors.rapid]) == pytest.approx(result.summary()["tracking_max_um"])
    assert result.summary()["tracking_max_um"] == pytest.approx(1e3 * 20 / 40)  # F1200 along X: v/Kp
    stream = io.StringIO()
    errors.save_csv(stream)
    rows = stream.getvalue().splitlines()
    assert rows[0] == "line,rapid,feed_mm_min,contour_max_um,tracking_max_um,block"
    assert rows[1].startswith("6,0,1200,") and rows[1].endswith(",G1 X0 F1200 (back ; faster)")
    assert rows[4] == "3,0,600,,,G1 X9.9992" and rows[5].startswith("5,1,10000,")
    table = errors.table(top=4).splitlines()
    assert table[0].split() == ["line", "contour", "max", "tracking", "max", "block"] and len(table) == 5
    assert table[1].split()[0] == "6" and table[4].split() == ["3", "-", "-", "G1", "X9.9992"]
    # were an AttributeError from inside, and every row but the last
    with pytest.raises(TypeError, match="program must be a Program"):
        block_errors(None, result)
    with pytest.raises(TypeError, match="result must be a SimResult"):
        block_errors(program, None)
    with pytest.raises(ValueError, match="top must be at least 1, got -1"):
        errors.table(top=-1)


def test_a_word_beyond_the_coordinate_limit_is_named_and_the_smallest_radius_is_taken():
    """'p1 holds 2e+06 at index 0, beyond ±1e+06' named the builder's argument, not the word; a full circle of radius
    I0.000001, the smallest the docs allow, was 'outside [1e-06, 1e+06]' by rounding (an outside probe)."""
    with pytest.raises(ConfigError, match=r"^<gcode>, line 2: X2e\+06 is beyond ±1e\+06 mm"):
        read_gcode("G0 X0 Y0\nG1 X2000000 F1000\n")
    # words within it adding up beyond it (G91) were 'p1 holds 1.1e+06 at index 0, beyond ±1e+06' too
    with pytest.raises(ConfigError, match=r"^<gcode>, line 4: G91 X600000 takes X to 1\.2e\+06 mm, beyond ±1e\+06 mm$"):
        read_gcode("G91 G0 X0 Y0\nG1 X600000 F1000\nG1 Y5\nG1 X600000\n")
    program = read_gcode("G0 X0 Y0\nG1 X10 F1000\nG2 X10 Y0 I0.000001\n")
    assert program.path.length == pytest.approx(10 + 2e-6 * np.pi, abs=1e-12)


def test_a_utf16_program_is_named_so(tmp_path):
    """A program saved as UTF-16 was read as Latin-1: "line 1: cannot read 'ÿþG\\x000\\x00 ...'" (an outside probe)."""
    (tmp_path / "p.nc").write_bytes("G0 X0 Y0\nG1 X10 F1000\n".encode("utf-16"))
    with pytest.raises(ConfigError, match=r"p.nc, line 1: the file is UTF-16 text \(by its byte-order mark\): save it as "
                                          r"UTF-8$"):
        read_gcode(tmp_path / "p.nc")


def test_a_binary_file_given_as_a_program_is_said_not_to_be_text(tmp_path):
    """A binary file (here a PNG's start) was read as Latin-1 words: "line 1: unbalanced parenthesis in a comment"."""
    (tmp_path / "p.nc").write_bytes(b"\x89PNG\r\n\x1a\n\x00\x00\x00\rIHDR(")
    with pytest.raises(ConfigError, match=r"p.nc, line 3: byte 0x00 \(NUL\) is not text \(UTF-16 without a byte-order "
                                          r"mark, or a binary file\?\): save the file as UTF-8 text$"):
        read_gcode(tmp_path / "p.nc")
    (tmp_path / "q.nc").write_bytes(b"G0 X0 Y0 (\xb0 Latin-1)\nG1 X10 F1000\n")  # an older controller's degree sign
    assert read_gcode(tmp_path / "q.nc").path.length == pytest.approx(10.0)


def test_an_arc_whose_radii_differ_by_the_tolerance_exactly_is_within_it():
    """Radii written 0.002 mm apart were said to "differ by more than 0.002 mm" (their difference in floating point is
    2.0000000000000018e-3; an outside probe)."""
    program = read_gcode("G0 X10 Y0\nG2 X0 Y10.002 I-10 J0 F600\n")
    assert np.linalg.norm(program.path.end[:2] - [0.0, 10.002]) < 1e-12
