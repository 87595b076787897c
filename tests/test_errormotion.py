"""Error motions: polynomial, cyclic, tabulated terms, parameters, laser tables."""

import numpy as np
import pytest

from contoursim.errormotion import Cyclic, ErrorMotion, read_error_table
from contoursim.exceptions import ConfigError


def test_terms_add_up():
    q = np.linspace(-10, 60, 141)
    motion = ErrorMotion(
        poly=(1e-3, 2e-5, -1e-7),
        cyclic=(Cyclic.from_amplitude(3e-3, 5.0, np.deg2rad(30)),),
        table=([0.0, 50.0], [0.0, 5e-3]),
    )
    expected = (
        1e-3 + 2e-5 * q - 1e-7 * q**2
        + 3e-3 * np.sin(2 * np.pi * q / 5.0 + np.deg2rad(30))
        + np.clip(q, 0, 50) * 1e-4  # linear table, held constant outside
    )
    np.testing.assert_allclose(motion(q), expected, atol=1e-15)


def test_zero_motion():
    assert ErrorMotion().is_zero
    np.testing.assert_array_equal(ErrorMotion()(np.arange(3.0)), 0)
    assert not ErrorMotion(poly=(0, 1e-6)).is_zero


def test_repeats_every_a_turn_only_when_every_term_does():
    """A constant and cyclic terms 1, 3 and 7 times a turn repeat every turn (checked against the values a turn on);
    a slope, a table, a period of 144° (2.5 a turn) or of two turns do not."""
    turn = 2 * np.pi
    motion = ErrorMotion((1e-3,), tuple(Cyclic(turn / n, 1e-3, 2e-3) for n in (1, 3, 7)))
    q = np.linspace(-turn, turn, 37)
    np.testing.assert_allclose(motion(q + 5 * turn), motion(q), atol=1e-15)
    assert motion.repeats_every(turn) and ErrorMotion().repeats_every(turn)
    assert ErrorMotion(cyclic=(Cyclic(np.deg2rad(120.0), 1e-3),)).repeats_every(turn)  # 3.0000000000000004 a turn
    for other in (ErrorMotion((0.0, 1e-6)), ErrorMotion(table=([0.0, turn], [0.0, 1e-3])),
                  ErrorMotion(cyclic=(Cyclic(np.deg2rad(144.0), 1e-3),)),
                  ErrorMotion(cyclic=(Cyclic(2 * turn, 0.0, 1e-3),))):
        assert not other.repeats_every(turn)
    assert ErrorMotion(cyclic=(Cyclic(2 * turn, 0.0, 0.0),)).repeats_every(turn)  # a term of size 0 is no term


def test_basis_is_the_derivative_and_with_parameter_sets_it():
    motion = ErrorMotion(poly=(1e-3, 2e-5), cyclic=(Cyclic(7.0, 1e-3, -2e-3),))
    q = np.linspace(0, 30, 31)
    for name in ["p0", "p1", "p3", "cyclic0.sin", "cyclic0.cos"]:
        value = motion.parameters().get(name, 0.0)
        h = 1e-6
        fd = (motion.with_parameter(name, value + h)(q) - motion.with_parameter(name, value - h)(q)) / (2 * h)
        np.testing.assert_allclose(motion.basis(name, q), fd, atol=1e-8, err_msg=name)
    assert set(motion.parameters()) == {"p0", "p1", "cyclic0.sin", "cyclic0.cos"}
    with pytest.raises(ValueError, match="only 1 cyclic"):
        motion.basis("cyclic1.sin", q)
    with pytest.raises(ValueError, match="unknown error-motion parameter"):
        motion.with_parameter("amplitude", 1.0)


def test_scaled_scales_every_term():
    motion = ErrorMotion((1e-3, 1e-5), (Cyclic(5.0, 1e-3, 0.0),), ([0.0, 10.0], [0.0, 1e-3]))
    q = np.linspace(-5, 15, 21)
    np.testing.assert_allclose(motion.scaled(0.5)(q), 0.5 * motion(q), atol=1e-18)


def test_bad_values_are_rejected():
    with pytest.raises(ValueError, match="period must be positive"):
        Cyclic(0.0, 1.0)
    with pytest.raises(ValueError, match="strictly increasing"):
        ErrorMotion(table=([0.0, 0.0], [1.0, 2.0]))
    with pytest.raises(ValueError, match="poly contains a non-finite"):
        ErrorMotion(poly=(np.nan,))


def test_read_error_table_converts_units(tmp_path):
    f = tmp_path / "x.csv"
    rows = "0,0.0,1\n100,1.5,2\n200,2.0,-1\n"
    f.write_text("# laser run\nposition_mm,dx_um,ey_urad\n" + rows)
    table = read_error_table(f)
    np.testing.assert_allclose(table["dx"][0], [0, 100, 200])
    np.testing.assert_allclose(table["dx"][1], [0, 1.5e-3, 2e-3])
    np.testing.assert_allclose(table["ey"][1], [1e-6, 2e-6, -1e-6])
    f.write_text("# laser run\nposition_deg,dx_um,ey_urad\n" + rows)
    rotary = read_error_table(f, rotary=True)
    np.testing.assert_allclose(rotary["dx"][0], np.deg2rad([0, 100, 200]))


@pytest.mark.parametrize(
    "text, line, match",
    [
        ("position_mm,dq_um\n0,1\n1,2\n", 1, "header must hold"),
        ("position_mm,dx_um\n0,1\n1,x\n", 3, "column 'dx_um' is not a number"),
        ("position_mm,dx_um\n0,1\n1,1_000\n", 3, "column 'dx_um': '1_000' is not a number"),  # float() read 1000
        ("position_mm,dx_um\n0,1\n１,2\n", 3, "column 'position_mm': '１' is not a number"),  # full-width: read 1
        ("position_mm,dx_um\n0,1\n2,2\n1,3\n", 4, "strictly increasing"),
        ("# c\nposition_mm,dx_um\n0,1\n1,2,3\n", 4, "expected 2 cells"),
        ("position_mm,dx_um\n0,1\n1,nan\n", 3, "not finite"),
        ("# old\nposition,dx\n0,1\n1,2\n", 2, "column 'position' is now 'position_mm'"),
        ("# laser run\n# units: dx_um [mm]\nposition_mm,dx_um\n0,0\n500,0.006\n", 2,  # was read as µm, not said
         "an error table's units are its columns'"),
        ("position_mm,ey\n0,1\n1,2\n", 1, "column 'ey' is now 'ey_urad'"),
        ("position_deg,dx_um\n0,1\n1,2\n", 1, "header must hold 'position_mm'"),
    ],
)
def test_read_error_table_names_file_and_line(tmp_path, text, line, match):
    f = tmp_path / "t.csv"
    f.write_text(text)
    with pytest.raises(ConfigError, match=rf"t.csv, line {line}: .*{match}"):
        read_error_table(f)
