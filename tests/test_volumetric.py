"""The volumetric job: worst errors over the workspace and error-field plots."""

import numpy as np
import pytest

from contoursim.exceptions import ConfigError
from contoursim.machine import load_machine as load_preset
from contoursim.volumetric import volumetric_grid, volumetric_report


def load_machine(name):
    return load_preset(name).chain


def test_grid_spans_the_travels_and_holds_fixed_axes():
    chain = load_machine("table_tilting_5axis")
    q, values = volumetric_grid(chain, points=3, fixed={"c": 0.5})
    assert q.shape == (27, 5)
    np.testing.assert_allclose(values[0], [-300, 0, 300])
    np.testing.assert_allclose(q[:, 4], 0.5)
    np.testing.assert_allclose(q[:, 3], 0.0)
    with pytest.raises(ValueError, match="points must be at least 2"):
        volumetric_grid(chain, points=1)


def test_report_gives_the_worst_errors_and_plots(tmp_path):
    text = volumetric_report("polishing_platform_4axis", tmp_path / "out", grid=5)
    # independent check: Δx of the polishing platform at b = c = 0 is dominated by -z·SxZ, z = 200 mm
    chain = load_machine("polishing_platform_4axis")
    q, _ = volumetric_grid(chain, points=5)
    dp, _ = chain.volumetric_error(q)
    worst = dp[np.argmax(np.abs(dp[:, 0])), 0] * 1e3
    assert f"{worst:+10.3f}" in text
    assert worst == pytest.approx(103.6429e-6 * 200 * 1e3, abs=1.0)
    assert (tmp_path / "out" / "volumetric_xz.png").stat().st_size > 10_000
    assert "position |Δ| [µm]" in text and "tool axis y [µrad]" in text


def test_report_sweeps_rotary_axes_over_given_ranges():
    out = volumetric_report("diamond_lathe", grid=4, sweep=["x", "c"], ranges={"c": (0.0, np.pi)}, fixed={"z": 10.0})
    assert "c 0..180°" in out and "16 points" in out


def test_machine_without_geometry_is_refused(tmp_path):
    with pytest.raises(ConfigError, match="no geometric half"):
        volumetric_report("demo_mill")
