"""ISO 230-2 figures of the ESS target drive unit, and its error table in the machine chain.

References, both independent of this code:

- PROVENANCE.md of ../shared/data/real/psi_ess_target_iso230_2, whose
  figures were verified by hand. They are quoted as "≈" to the last digit
  shown, so each is checked to half a unit of that digit (25 µm → ±0.5 µm,
  1.6 µm → ±0.05 µm): the tolerance is the quoted rounding, nothing more.
- The ecmc tool's own report.md, where it applies the ISO formulas (reversal,
  M, A, per-target bidirectional repeatability), printed to 1e-5 mm. Its
  direction labels are swapped relative to the .dat (its "forward" table is
  REF_DATA_BWD), so its B_avg has the opposite sign and its R_fwd is our R↓;
  its bold E is a unidirectional figure and its bold R is max(R_fwd, R_bwd),
  neither the ISO bidirectional value, so those two are not compared.
"""

import re
import runpy

import numpy as np
import pytest

from conftest import ROOT
from contoursim.exceptions import ConfigError
from contoursim.output import output_dir
from contoursim.iso230_2 import positioning_figures, write_error_table

EXAMPLE = runpy.run_path(str(ROOT / "examples" / "iso230_2_error_table.py"))
FOLDER = "psi_ess_target_iso230_2"
UM_PER_MM = 1e3  # [µm/mm]


def figures_of(real_data, axis):
    return positioning_figures(EXAMPLE["read_iso230_dat"](real_data / FOLDER / EXAMPLE["FILES"][axis]))


# axis: PROVENANCE's B̄, E, 4σ repeatability as (value, rounding) [µm], and the
# intervals its quoted range of |B_i| allows for the smallest and largest |B_i|
# [µm]. X's "15–34 µm" starts at 15.97 µm cut down, not rounded: [15, 16).
PROVENANCE = {
    "x": dict(B=(25, 0.5), E=(123, 0.5), R=(28, 0.5), B_range=((15, 16), (33.5, 34.5))),
    "y": dict(B=(13, 0.5), E=(100, 0.5), R=(38, 0.5), B_range=((7.5, 8.5), (19.5, 20.5))),
    "z": dict(B=(1.6, 0.05), E=(35, 0.5), R=(6, 0.5), B_range=None),
}
# axis: report.md's B_avg, B, M, A, max R(i), and its R_fwd, R_bwd (= our R↓, R↑) [mm]
REPORT = {
    "x": (0.02537, 0.03358, 0.09365, 0.13527, 0.05516, 0.02831, 0.01937),
    "y": (0.01277, 0.02002, 0.08426, 0.12572, None, 0.03254, 0.03807),
    "z": (0.00161, 0.00236, 0.03336, 0.03685, None, 0.00642, 0.00338),
}


@pytest.mark.parametrize("axis", "xyz")
def test_figures_match_provenance(real_data, axis):
    s = figures_of(real_data, axis)
    ref = PROVENANCE[axis]
    # ↑ is REF_DATA_FWD (test steps 1xxx on rising targets in the raw log), so
    # B_i = x̄↑ − x̄↓ is negative: the slide stops short in the direction it
    # comes from (lost motion). PROVENANCE quotes the magnitude.
    assert np.all(s.reversal < 0)
    assert UM_PER_MM * abs(s.reversal_mean) == pytest.approx(ref["B"][0], abs=ref["B"][1])
    assert UM_PER_MM * s.systematic == pytest.approx(ref["E"][0], abs=ref["E"][1])
    assert UM_PER_MM * max(s.repeatability_up, s.repeatability_down) == pytest.approx(ref["R"][0], abs=ref["R"][1])
    if ref["B_range"]:
        (lo_min, lo_max), (hi_min, hi_max) = ref["B_range"]
        b = UM_PER_MM * np.abs(s.reversal)
        assert lo_min <= b.min() < lo_max and hi_min <= b.max() < hi_max


@pytest.mark.parametrize("axis", "xyz")
def test_figures_match_the_ecmc_report(real_data, axis):
    s = figures_of(real_data, axis)
    b_avg, b, m, a, r, r_fwd, r_bwd = REPORT[axis]
    printed = dict(abs=6e-6)  # 5 decimals [mm]
    assert -s.reversal_mean == pytest.approx(b_avg, **printed)  # swapped labels: opposite sign
    assert s.reversal_max == pytest.approx(b, **printed)
    assert s.mean_range == pytest.approx(m, **printed)
    assert s.accuracy == pytest.approx(a, **printed)
    assert s.repeatability_down == pytest.approx(r_fwd, **printed)
    assert s.repeatability_up == pytest.approx(r_bwd, **printed)
    if r is not None:
        assert s.repeatability == pytest.approx(r, **printed)


@pytest.mark.parametrize("axis", "xyz")
def test_chain_reproduces_the_mean_bidirectional_deviation(real_data, tmp_path, axis):
    s = figures_of(real_data, axis)
    out = output_dir(tmp_path)
    with out.write("table.csv") as stream:
        write_error_table(stream, axis, s, source=EXAMPLE["FILES"][axis])
    _, chain = EXAMPLE["axis_machine"](out, axis, "table.csv", (s.targets[0], s.targets[-1]))
    k = "xyz".index(axis)

    at = EXAMPLE["positioning_error"](chain, s.targets)
    np.testing.assert_allclose(at[:, k], s.mean_bidirectional, rtol=0, atol=1e-12)  # [mm], round-off

    between = np.random.default_rng(1).uniform(s.targets[0], s.targets[-1], 50)
    between = np.concatenate([between, 0.5 * (s.targets[1:] + s.targets[:-1])])
    error = EXAMPLE["positioning_error"](chain, between)
    np.testing.assert_allclose(error[:, k], np.interp(between, s.targets, s.mean_bidirectional), rtol=0, atol=1e-12)
    assert not np.delete(error, k, axis=1).any()  # a pure positioning error moves the tip along the axis only


def test_main_writes_tables_and_machines(real_data, tmp_path, capsys):
    EXAMPLE["main"](tmp_path / "out")
    printed = capsys.readouterr().out
    assert "skipped" not in printed and "mean reversal B̄" in printed
    assert sorted(p.name for p in (tmp_path / "out").glob("*_iso230_2*")) == [
        f"{a}_iso230_2{suffix}" for a in "xyz" for suffix in (".csv", "_axis.toml")
    ]


DAT = """TEST_DATA=# a comment that holds = signs
# a comment line
UNIT=mm
CYCLES=2
POSITIONS=2
TGT_DATA[1]=0
TGT_DATA[2]=10
REF_DATA_FWD[1,1]=.001
REF_DATA_FWD[2,1]=10.002
REF_DATA_FWD[1,2]=.003
REF_DATA_FWD[2,2]=10.004
REF_DATA_BWD[1,1]=-.001
REF_DATA_BWD[2,1]=9.998
REF_DATA_BWD[1,2]=-.003
REF_DATA_BWD[2,2]=9.996
"""


def test_reader_on_a_small_file(tmp_path):
    file = tmp_path / "ok.dat"
    file.write_text(DAT)
    test = EXAMPLE["read_iso230_dat"](file)
    np.testing.assert_array_equal(test.targets, [0, 10])
    np.testing.assert_array_equal(test.up, [[0.001, 0.003], [10.002, 10.004]])  # REF_DATA_FWD
    np.testing.assert_array_equal(test.down, [[-0.001, -0.003], [9.998, 9.996]])  # REF_DATA_BWD


@pytest.mark.parametrize(
    "old, new, line, message",
    [
        ("TGT_DATA[2]=10", "TGT_DATA[2]=ten", 7, "not a finite number"),
        ("TGT_DATA[2]=10", "TGT_DATA[2] 10", 7, "expected KEY=VALUE"),
        ("REF_DATA_BWD[2,2]=9.996", "REF_DATA_BWD[1,1]=9.996", 15, "given twice"),
        ("REF_DATA_BWD[2,2]=9.996", "REF_DATA_BWD[2]=9.996", 15, "unknown indexed entry"),
        ("REF_DATA_BWD[2,2]=9.996", "REF_DATA_BWD[2,3]=9.996", 15, "beyond 2 positions x 2 cycles"),
        ("UNIT=mm", "UNIT=um", 3, "UNIT must be mm"),
        ("TGT_DATA[2]=10", "TGT_DATA[2]=0", None, "targets must be at least 2 strictly increasing"),
        ("REF_DATA_BWD[2,2]=9.996", "", None, "missing REF_DATA_BWD[2,2]"),
    ],
)
def test_reader_names_file_and_line(tmp_path, old, new, line, message):
    file = tmp_path / "bad.dat"
    file.write_text(DAT.replace(old, new))
    with pytest.raises(ConfigError, match=re.escape(message)) as info:
        EXAMPLE["read_iso230_dat"](file)
    assert info.value.source == str(file) and info.value.line == line
