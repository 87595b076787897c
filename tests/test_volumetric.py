"""The volumetric job: worst errors over the workspace and error-field plots."""

import numpy as np
import pytest

from contoursim.config import TomlFile
from contoursim.exceptions import ConfigError
from contoursim.machine import load_machine as load_preset
from contoursim.machine import preset_file
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
    text = volumetric_report("polishing_platform_4axis", tmp_path / "out", grid=5, fixed={"b": 0.0, "c": 0.0})
    assert "rotary axes held: b = 0°, c = 0°" in text
    # independent check, from the preset's numbers: the worst Δx is at x = 0, z = 200 mm (b = c = 0),
    # where the tool tip sits on the Z slide's frame origin (no Abbe offset) and X's errors vanish,
    # so Δx = -z·S_xZ + dx_Z(z); the Z slide's horizontal straightness poly is zero at 200 mm
    z_slide = next(b for b in TomlFile.read(preset_file("polishing_platform_4axis")).data["body"] if b["name"] == "Z")
    z = z_slide["travel_mm"][1]
    squareness = 1e-6 * z_slide["squareness"]["x_urad"]  # [rad]
    straightness = np.polynomial.polynomial.polyval(z, z_slide["errors"]["dx_um"]["poly"])  # [µm]
    want = -z * squareness * 1e3 + straightness  # [µm]
    assert z == 200 and straightness == pytest.approx(0.0, abs=1e-12)
    chain = load_machine("polishing_platform_4axis")
    q, _ = volumetric_grid(chain, points=5)
    dp, _ = chain.volumetric_error(q)
    k = np.argmax(np.abs(dp[:, 0]))
    np.testing.assert_allclose(q[k], [0.0, z, 0.0, 0.0])
    assert dp[k, 0] * 1e3 == pytest.approx(want, rel=1e-12)
    row = next(line for line in text.splitlines() if line.startswith("position x [µm]"))
    assert row.split()[3] == f"{want:+.3f}"
    assert row.endswith("x=0.0 mm, z=200.0 mm, b=0.0°, c=0.0°")  # the "at" column, with units
    assert (tmp_path / "out" / "volumetric_xz.png").stat().st_size > 10_000
    assert "position |Δ| [µm]" in text and "tool axis y [µrad]" in text


def test_each_plane_of_four_linear_axes_is_plotted(tmp_path):
    """The 7-axis driller's linear axes x, y, z, z1: the planes y-z, y-z1 and z-z1 were left out without a word (the
    first three pairs kept), where the page promises each plane (an outside probe)."""
    volumetric_report("aircraft_drilling_7axis", tmp_path / "out", grid=3)
    assert sorted(p.name for p in (tmp_path / "out").glob("*.png")) == [
        f"volumetric_{plane}.png" for plane in ("xy", "xz", "xz1", "yz", "yz1", "zz1")]


def test_a_component_that_is_zero_to_rounding_is_printed_as_zero(tmp_path):
    """The 3-axis mill turns its tool axis about z by nothing, to rounding: +0.000, not -0.000."""
    text = volumetric_report("vertical_mill_3axis", tmp_path, grid=3)
    row = next(line for line in text.splitlines() if line.startswith("tool axis z [µrad]"))
    assert row.split()[4:7] == ["+0.000"] * 3, row
    # the machine a user holds maps as its file does (it was refused: "str or Path, got Machine")
    assert volumetric_report(load_preset("vertical_mill_3axis"), grid=3) == volumetric_report("vertical_mill_3axis",
                                                                                              grid=3)
    with pytest.raises(ConfigError, match="the machine has no geometric half"):
        volumetric_report(load_preset("demo_mill"))


def test_report_never_replaces_a_file_it_did_not_write(tmp_path):
    volumetric_report("polishing_platform_4axis", tmp_path, grid=2, sweep=["x"])  # takes the empty folder
    volumetric_report("polishing_platform_4axis", tmp_path, grid=2, sweep=["x"])  # and replaces its own plot
    assert sorted(p.name for p in tmp_path.iterdir()) == [".contoursim-out", "volumetric_x.png"]
    (tmp_path / "volumetric_xz.png").write_text("mine")  # a user's file in contoursim's folder
    with pytest.raises(FileExistsError, match="volumetric_xz.png exists and contoursim did not write it"):
        volumetric_report("polishing_platform_4axis", tmp_path, grid=2)
    assert (tmp_path / "volumetric_xz.png").read_text() == "mine"


def test_report_sweeps_rotary_axes_over_given_ranges():
    out = volumetric_report("diamond_lathe", grid=4, sweep=["x", "c"], ranges={"c": (0.0, np.pi)}, fixed={"z": 10.0})
    assert "c 0..180°" in out and "16 points" in out
    assert out.splitlines()[-1].endswith("z=10.0 mm, c=180.0°")  # rotary positions in degrees


def test_machine_without_geometry_is_refused(tmp_path):
    with pytest.raises(ConfigError, match="no geometric half"):
        volumetric_report("demo_mill")


def test_report_turns_the_rotary_axes_over_their_travels_and_says_so(tmp_path):
    """The worst errors of the whole workspace: the same as over one grid of all five axes, built here
    on its own; larger than with A and C held at 0°, as the output then says; the plots show where."""
    chain = load_machine("table_tilting_5axis")
    text = volumetric_report("table_tilting_5axis", tmp_path, grid=3, rotary_grid=3)
    # C turns a whole turn, 0..360°, and its errors repeat every turn: 0, 120, 240° (360° is 0° again)
    q, _ = volumetric_grid(chain, sweep=list(chain.axes), points=3, ranges={"c": (0.0, np.deg2rad(240.0))})
    dp, _ = chain.volumetric_error(q)
    norm = 1e3 * np.linalg.norm(dp, axis=1)
    row = next(line for line in text.splitlines() if line.startswith("position |Δ| [µm]"))
    assert float(row.split()[3]) == pytest.approx(norm.max(), abs=1e-3)
    assert "243 points" in text and ("rotary axes a -110..110° at 3 positions; c 0..240° at 3 positions (one turn of "
                                     "its travel 0..360°: its errors repeat every turn)") in text
    held = volumetric_report("table_tilting_5axis", grid=3, rotary_grid=0)
    assert "rotary axes held: a = 0°, c = 0°" in held
    held_row = next(line for line in held.splitlines() if line.startswith("position |Δ| [µm]"))
    assert float(held_row.split()[3]) < float(row.split()[3])
    a, c = np.degrees(q[np.argmax(norm), 3:])
    assert f"plots at a = {a:g}°, c = {c:g}°, where |Δ| is worst: {tmp_path / 'volumetric_xy.png'}" in text
    with pytest.raises(ValueError, match="rotary_grid must be 0"):
        volumetric_report("table_tilting_5axis", grid=3, rotary_grid=1)


def _c_travel(tmp_path, travel_deg, errors=""):
    """The 5-axis preset with C's travel (and error motions added to C's) changed, as a file."""
    text = preset_file("table_tilting_5axis").read_text()
    old = "travel_deg = [0, 360]\noffset_mm = [0, 0, -150]"
    assert text.count(old) == 1
    text = text.replace(old, f"travel_deg = {travel_deg}\noffset_mm = [0, 0, -150]")
    if errors:  # after C's last error motion
        last = "# angular positioning, twice per turn\n"
        text = text.replace(last, last + errors + "\n")
    path = tmp_path / "c.toml"
    path.write_text(text)
    return path


def test_a_rotary_axis_turning_many_times_is_looked_at_over_one_turn_or_every_turn(tmp_path):
    """C over 100 turns at 4 positions: 0, 12000, 24000, 36000° are all C = 0°. Its errors repeat every turn, so one
    turn, at 0, 90, 180, 270°: the worst |Δ| that of a grid built here on its own at those angles, well above
    C = 0°'s. With an error growing with the angle (a polynomial in it: no turn is the one before), every turn, 4
    positions a turn; over more turns than MAX_ROTARY_POSITIONS allows, refused naming the file, body and travel."""
    chain = load_machine("table_tilting_5axis")

    def worst(text):  # the worst |Δ| the report gives [µm]
        return float(next(s for s in text.splitlines() if s.startswith("position |Δ| [µm]")).split()[3])

    def grid(chain, c_deg):  # the linear axes over their travels at 3 points, A at 4 over its travel, C at `c_deg`
        axes = [np.linspace(-300, 300, 3), np.linspace(-250, 250, 3), np.linspace(-400, 0, 3),
                np.deg2rad(np.linspace(-110, 110, 4)), np.deg2rad(c_deg)]
        dp, _ = chain.volumetric_error(np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 5))
        return 1e3 * np.linalg.norm(dp, axis=1).max()

    many = volumetric_report(_c_travel(tmp_path, "[0, 36000]"), grid=3, rotary_grid=4)
    assert "c 0..270° at 4 positions (one turn of its travel 0..36000°: its errors repeat every turn)" in many
    assert worst(many) == pytest.approx(grid(chain, [0.0, 90.0, 180.0, 270.0]), abs=1e-3)
    assert worst(many) > grid(chain, [0.0]) + 5.0  # what C = 0° alone missed

    growing = _c_travel(tmp_path, "[0, 36000]", "ex_urad = { poly = [0, 0.01] }")
    text = volumetric_report(growing, grid=3, rotary_grid=4)
    assert "c 0..36000° at 401 positions (4 a turn: its errors do not repeat every turn)" in text
    assert worst(text) == pytest.approx(grid(load_preset(growing).chain, np.arange(0.0, 36000.1, 90.0)), abs=1e-3)
    with pytest.raises(ConfigError, match=r"c\.toml: axis 'c' \(body 'C'\): its errors do not repeat every turn .* "
                                          r"2777\.78 turns of its travel 0\.\.1e\+06°.* 11113 positions, more than "
                                          r"10000; give it a shorter travel_deg"):
        volumetric_report(_c_travel(tmp_path, "[0, 1e6]", "ex_urad = { poly = [0, 1e-6] }"), grid=2, rotary_grid=4)


def test_a_range_given_max_first_or_of_one_position_is_refused_naming_its_axis():
    # ranges {"x": (100, 0)} made a grid running backwards (x = 100, 50, 0), (5, 5) one position `points` times
    from contoursim.machine import load_machine

    chain = load_machine("table_tilting_5axis").chain
    for span, shown in (((100.0, 0.0), r"\(100, 0\)"), ((5.0, 5.0), r"\(5, 5\)")):
        with pytest.raises(ValueError, match=rf"ranges\['x'\] must be \(min, max\) of axis x with min < max, "
                                             rf"got {shown}"):
            volumetric_grid(chain, sweep=["x"], points=3, ranges={"x": span})
    _, (x,) = volumetric_grid(chain, sweep=["x"], points=3, ranges={"x": (0.0, 100.0)})
    assert x.tolist() == [0.0, 50.0, 100.0]


def test_ranges_fixed_time_and_points_are_checked_naming_them(monkeypatch):
    # ranges {"x": (nan, 1)} made a grid of NaN positions ("q contains a non-finite value" in the report), a range of
    # text a numpy DTypePromotionError, of a number "'int' object is not subscriptable", a range of an axis not swept
    # and the position of a swept one were ignored, fixed = 100 rad on a ±120° axis was mapped as "a = 5729.58°",
    # time NaN was said of "t", points = 10**4 was a MemoryError of 7.28 TiB and a chain of None an AttributeError
    from contoursim import _memory
    from contoursim.machine import load_machine

    chain = load_machine("table_tilting_5axis").chain
    for kwargs, error, words in (
        (dict(ranges={"x": (float("nan"), 1.0)}), ValueError, r"ranges\['x'\] contains a non-finite value \(nan\)"),
        (dict(ranges={"x": "ab"}), TypeError, r"ranges\['x'\] must be numeric"),
        (dict(ranges={"x": 5.0}), ValueError, r"ranges\['x'\] must have shape \(2,\)"),
        (dict(ranges={"x": (0.0, 1e300)}), ValueError, r"ranges\['x'\] holds 1e\+300 at index 1, beyond ±1e\+06"),
        (dict(ranges={"a": (0.0, 1.0)}), ValueError, r"ranges: axis 'a' is not swept \(sweep: x, y, z\)"),
        (dict(fixed={"a": float("nan")}), ValueError, r"fixed\['a'\] must be finite"),
        (dict(fixed={"a": "a"}), TypeError, r"fixed\['a'\] must be a number"),
        (dict(fixed={"x": 5.0}), ValueError, r"fixed: axis 'x' is swept \(sweep: x, y, z\)"),
        (dict(fixed={"a": 100.0}), ValueError, r"fixed\['a'\] = 100 rad \(5729.58°\) lies outside the travel of axis a"),
    ):
        with pytest.raises(error, match=words):
            volumetric_grid(chain, points=2, **kwargs)
        with pytest.raises(error, match=words):
            volumetric_report(chain, grid=2, **kwargs)
    with pytest.raises(ValueError, match="time must be finite, got nan"):
        volumetric_report(chain, grid=2, time=float("nan"))
    with pytest.raises(TypeError, match="chain must be a MachineChain"):
        volumetric_grid(None)
    monkeypatch.setattr(_memory, "available", lambda: 2**30)
    with pytest.raises(ValueError, match=r"points = 10000: a grid of 10000 x 10000 x 10000 positions: that is 1e\+12"):
        volumetric_grid(chain, points=10**4)
    assert volumetric_grid(chain, points=2, fixed={"a": 0.1})[0].shape == (8, 5)
