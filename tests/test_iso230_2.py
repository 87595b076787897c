"""ISO 230-2 figures on a small test worked out by hand, and the error table they give.

The test: targets 0, 10, 20 mm, 3 cycles; deviations (measured − target) in µm

    target   ↑ (cycles 1..3)   x̄↑  s↑    ↓ (cycles 1..3)   x̄↓  s↓
     0 mm     3,  4,  5         4   1     -2,  0,  2         0   2
    10 mm     8, 10, 12        10   2      6,  7,  8         7   1
    20 mm    -1,  2,  5         2   3      4,  5,  6         5   1

(three values a, a ± d have mean a and s = d with n − 1 = 2 in the
denominator). By hand, in µm:

- B_i = x̄↑ − x̄↓ = 4, 3, −3; B̄ = 4/3 (signed), B = max |B_i| = 4;
- x̄_i = (x̄↑ + x̄↓)/2 = 2, 8.5, 3.5; M = 8.5 − 2 = 6.5;
- E = max(4, 10, 2, 0, 7, 5) − min(...) = 10 − 0 = 10 (≠ M: E spans the
  unidirectional means);
- R↑ = 4·max s↑ = 12, R↓ = 4·max s↓ = 8;
- R_i = max(2s↑ + 2s↓ + |B_i|, 4s↑, 4s↓) = max(10, 4, 8), max(9, 8, 4),
  max(11, 12, 4) = 10, 9, 12, so R = 12, set at 20 mm by 4s↑ alone (the
  bidirectional term alone would give 11);
- A: upper ends x̄ + 2s = 6, 14, 8 (↑) and 4, 9, 7 (↓), lower ends
  x̄ − 2s = 2, 6, −4 (↑) and −4, 5, 3 (↓): A = 14 − (−4) = 18;
- drift (last − first cycle, both directions): (2 + 4 + 6 + 4 + 2 + 2)/6 = 10/3.
"""

import re

import numpy as np
import pytest

from contoursim.errormotion import read_error_table
from contoursim.iso230_2 import PositioningTest, positioning_figures, write_error_table

UM_PER_MM = 1e3  # [µm/mm]
TARGETS = np.array([0.0, 10.0, 20.0])
UP_UM = np.array([[3, 4, 5], [8, 10, 12], [-1, 2, 5]], float)
DOWN_UM = np.array([[-2, 0, 2], [6, 7, 8], [4, 5, 6]], float)
HAND = 1e-9  # [µm]: the figures are exact; this is round-off of mm values near 20 mm


def hand_test():
    return PositioningTest(TARGETS, TARGETS[:, None] + UP_UM / UM_PER_MM, TARGETS[:, None] + DOWN_UM / UM_PER_MM)


def test_per_target_figures_by_hand():
    f = positioning_figures(hand_test())
    np.testing.assert_array_equal(f.targets, TARGETS)
    np.testing.assert_allclose(UM_PER_MM * f.mean_up, [4, 10, 2], rtol=0, atol=HAND)
    np.testing.assert_allclose(UM_PER_MM * f.mean_down, [0, 7, 5], rtol=0, atol=HAND)
    np.testing.assert_allclose(UM_PER_MM * f.s_up, [1, 2, 3], rtol=0, atol=HAND)
    np.testing.assert_allclose(UM_PER_MM * f.s_down, [2, 1, 1], rtol=0, atol=HAND)
    np.testing.assert_allclose(UM_PER_MM * f.reversal, [4, 3, -3], rtol=0, atol=HAND)
    np.testing.assert_allclose(UM_PER_MM * f.mean_bidirectional, [2, 8.5, 3.5], rtol=0, atol=HAND)
    np.testing.assert_allclose(UM_PER_MM * f.deviation_down, DOWN_UM, rtol=0, atol=HAND)


@pytest.mark.parametrize(
    "name, by_hand",
    [
        ("reversal_mean", 4 / 3),
        ("reversal_max", 4),
        ("mean_range", 6.5),
        ("systematic", 10),
        ("repeatability_up", 12),
        ("repeatability_down", 8),
        ("repeatability", 12),
        ("accuracy", 18),
        ("drift", 10 / 3),
    ],
)
def test_axis_figures_by_hand(name, by_hand):
    assert UM_PER_MM * getattr(positioning_figures(hand_test()), name) == pytest.approx(by_hand, abs=HAND)


def test_bidirectional_repeatability_term_can_decide():
    # Narrow ↑ at 20 mm to 1, 2, 3 (x̄↑ = 2, s↑ = 1): R_i there is
    # max(2 + 2 + 3, 4, 4) = 7, and R = 10 comes from 0 mm's
    # 2s↑ + 2s↓ + |B_i| = 2 + 4 + 4, above every 4s (R↑ = R↓ = 8).
    up = UP_UM.copy()
    up[2] = [1, 2, 3]
    f = positioning_figures(PositioningTest(TARGETS, TARGETS[:, None] + up / UM_PER_MM, TARGETS[:, None] + DOWN_UM / UM_PER_MM))
    assert UM_PER_MM * f.repeatability == pytest.approx(10, abs=HAND)
    assert UM_PER_MM * max(f.repeatability_up, f.repeatability_down) == pytest.approx(8, abs=HAND)


def test_results_are_read_only():
    test = hand_test()
    f = positioning_figures(test)
    for arr in (test.up, f.mean_bidirectional, f.deviation_up):
        with pytest.raises(ValueError, match="read-only"):
            arr[0] = 1.0


@pytest.mark.parametrize(
    "targets, up, down, message",
    [
        ([0.0, 20.0, 10.0], None, None, "targets must be at least 2 strictly increasing"),
        ([0.0], np.zeros((1, 3)), np.zeros((1, 3)), "targets must be at least 2 strictly increasing"),
        (None, np.zeros((2, 3)), None, "up must have shape (3, N)"),
        (None, None, np.zeros((3, 2)), "down must have shape (3, 3)"),
        (None, np.zeros((3, 1)), np.zeros((3, 1)), "at least 2 cycles"),
        (None, None, [[0, 0, 0], [0, np.nan, 0], [0, 0, 0]], "down contains a non-finite value (nan) at index (1, 1)"),
        ([[0.0, 10.0, 20.0]], None, None, "targets must have 1 dimension"),
        # a position of 1e300 made the accuracy inf (an overflow warning)
        (None, [[1e300, 0, 0], [10, 10, 10], [20, 20, 20]], None, "up holds 1e+300 at index (0, 0), beyond ±1e+06"),
    ],
)
def test_bad_measurements_are_named(targets, up, down, message):
    test = hand_test()
    with pytest.raises(ValueError, match=re.escape(message)):
        PositioningTest(
            test.targets if targets is None else targets,
            test.up if up is None else up,
            test.down if down is None else down,
        )


def test_figures_need_a_positioning_test():
    with pytest.raises(TypeError, match="PositioningTest"):
        positioning_figures({"targets": TARGETS})


def test_error_table_reads_back_as_the_mean_bidirectional_deviation(tmp_path):
    file = tmp_path / "y.csv"
    write_error_table(file, "y", positioning_figures(hand_test()), source="run 7")
    text = file.read_text(encoding="utf-8")
    assert "run 7" in text and "Y axis" in text
    assert "B_mean = 1.33, B = 4.00, E = 10.00, M = 6.50, R = 12.00, A = 18.00 µm" in text
    assert list(read_error_table(file)) == ["dy"]
    position, dy = read_error_table(file)["dy"]
    np.testing.assert_array_equal(position, TARGETS)
    np.testing.assert_allclose(UM_PER_MM * dy, [2, 8.5, 3.5], rtol=0, atol=HAND)  # x̄_i by hand [µm]


def test_error_table_refuses_to_overwrite(tmp_path):
    file = tmp_path / "x.csv"
    file.write_text("kept\n")
    f = positioning_figures(hand_test())
    with pytest.raises(FileExistsError, match="refusing to overwrite"):
        write_error_table(file, "x", f)
    assert file.read_text() == "kept\n"
    write_error_table(str(file), "x", f, overwrite=True)
    assert read_error_table(file)["dx"][1] == pytest.approx(np.array([2, 8.5, 3.5]) / UM_PER_MM, abs=HAND / UM_PER_MM)


@pytest.mark.parametrize("axis, figures, error", [("a", None, ValueError), ("X", None, ValueError), ("x", "table", TypeError)])
def test_error_table_rejects_bad_arguments(tmp_path, axis, figures, error):
    with pytest.raises(error, match="axis must be|figures must be"):
        write_error_table(tmp_path / "t.csv", axis, figures or positioning_figures(hand_test()))
    assert not (tmp_path / "t.csv").exists()


def test_a_source_of_more_than_one_line_is_refused(tmp_path):
    # source = "a\nb,c" wrote "b,c" as a line of its own, which read_error_table then took for the header
    figures = positioning_figures(hand_test())
    for source in ("bench\nb,c", "bench\r"):
        with pytest.raises(ValueError, match="source must be one line of text"):
            write_error_table(tmp_path / "x.csv", "x", figures, source=source)
    assert not (tmp_path / "x.csv").exists()
    write_error_table(tmp_path / "x.csv", "x", figures, source="laser run 3")
    assert read_error_table(tmp_path / "x.csv") is not None
