"""Multibody chain: topology, exact HTM products, first-order model, seed formulas."""

import re
import warnings
from dataclasses import replace

from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from contoursim import multibody
from contoursim._blocks import BLOCK
from contoursim.config import TomlFile
from contoursim.errormotion import Cyclic, ErrorMotion
from contoursim.exceptions import ChainError, ConfigError, ContoursimWarning
from contoursim.machine import load_machine as load_preset
from contoursim.machine import preset_names
from contoursim.multibody import Body, MachineChain, chain_from_toml, lower_body_array, tilted_axis

# Seed 004, Table 1: rows L^0 ... L^7, columns bodies 1..10.
TABLE_1 = [
    [1, 2, 3, 4, 5, 6, 7, 8, 9, 10],
    [0, 1, 2, 3, 4, 5, 6, 9, 10, 0],
    [0, 0, 1, 2, 3, 4, 5, 10, 0, 0],
    [0, 0, 0, 1, 2, 3, 4, 0, 0, 0],
    [0, 0, 0, 0, 1, 2, 3, 0, 0, 0],
    [0, 0, 0, 0, 0, 1, 2, 0, 0, 0],
    [0, 0, 0, 0, 0, 0, 1, 0, 0, 0],
    [0, 0, 0, 0, 0, 0, 0, 0, 0, 0],
]


def load_machine(name):
    return load_preset(name).chain


def travel_grid(chain, n, seed=0):
    rng = np.random.default_rng(seed)
    travel = {b.axis: b.travel for b in chain.bodies if b.axis is not None}
    lo = np.array([travel[a][0] for a in chain.axes])
    hi = np.array([travel[a][1] for a in chain.axes])
    return lo + (hi - lo) * rng.random((n, len(chain.axes)))


# -- topology --------------------------------------------------------------


def test_lower_body_array_reproduces_seed_004_table_1():
    np.testing.assert_array_equal(lower_body_array([0, 1, 2, 3, 4, 5, 6, 9, 10, 0]), TABLE_1)


def test_seed_004_preset_has_the_table_1_topology_and_its_chains():
    chain = load_machine("aircraft_drilling_7axis")
    np.testing.assert_array_equal(chain.lower, TABLE_1)
    assert chain.chain_to(7) == (1, 2, 3, 4, 5, 6, 7)
    assert chain.chain_to(8) == (10, 9, 8)
    np.testing.assert_array_equal(chain.parents, [0, 1, 2, 3, 4, 5, 6, 9, 10, 0])


@pytest.mark.parametrize(
    "parents, match",
    [([0, 3, 2], "own ancestor"), ([0, 5], "not a body"), ([1], "own ancestor"), ([0.5], "integers")],
)
def test_lower_body_array_rejects_non_trees(parents, match):
    with pytest.raises(ValueError, match=match):
        lower_body_array(parents)


# -- exact chain against an independent 4x4 product ----------------------------


def htm(rotvec=(0, 0, 0), d=(0, 0, 0)):
    T = np.eye(4)
    T[:3, :3] = Rotation.from_rotvec(rotvec).as_matrix()
    T[:3, 3] = d
    return T


def test_polishing_platform_exact_pose_equals_explicit_4x4_product():
    # Seed 002 chain written out by hand: T_work = T01 E_X T12 E_C, T_tool = T04 E_Z T45 E_B,
    # P_w = T_work^-1 T_tool (0, 0, 0, 1).
    chain = load_machine("polishing_platform_4axis")
    q = travel_grid(chain, 5, seed=1)
    p, v = chain.tool_pose(q)
    X, Z, B, C = (chain.bodies[i] for i in (0, 3, 4, 1))
    for k, (x, z, b, c) in enumerate(q):
        eX, eZ, eB, eC = (np.array([m(np.array([val]))[0] for m in body.motion]) for body, val in ((X, x), (Z, z), (B, b), (C, c)))
        eZ[0] -= z * Z.squareness[0]
        work = htm(d=(x, 0, 0)) @ htm(eX[3:], eX[:3]) @ htm((0, 0, c)) @ htm(eC[3:], eC[:3])
        tool = htm(d=(0, 0, z)) @ htm(eZ[3:], eZ[:3]) @ htm((0, b, 0)) @ htm(eB[3:], eB[:3])
        T = np.linalg.solve(work, tool)
        np.testing.assert_allclose(p[k], T[:3, 3], atol=1e-12)
        np.testing.assert_allclose(v[k], T[:3, 2], atol=1e-15)


def test_tilted_rotary_axis_is_a_rodrigues_rotation_about_l():
    # C on the bed with s_cx, s_cy; a target on the table at (r, 0, h); tool = target, workpiece = bed.
    tilt = np.array([0.02, -0.03, 0.0])
    bodies = (Body("C", 0, "rotary", 2, axis="c", tilt=tilt), Body("target", 1, offset=[120.0, 0, 30.0]))
    chain = MachineChain(bodies, tool=2, workpiece=0)
    theta = np.linspace(0, 2 * np.pi, 7)
    p, _ = chain.tool_pose(theta[:, None])
    l_c = tilted_axis(2, tilt)
    expect = Rotation.from_rotvec(theta[:, None] * l_c).apply([120.0, 0, 30.0])
    np.testing.assert_allclose(p, expect, atol=1e-12)


def test_rotation_is_exact_on_both_sides_of_the_series_threshold():
    """Angles from 1e-9 to 0.1 rad (the series serves below 0.01) rotate as scipy's rotation matrices do."""
    rng = np.random.default_rng(8)
    w = rng.normal(size=(400, 3))
    w *= (np.geomspace(1e-9, 0.1, 400) / np.linalg.norm(w, axis=1))[:, None]
    v = rng.uniform(-500, 500, (400, 3))
    np.testing.assert_allclose(multibody._rotate(v, w), Rotation.from_rotvec(w).apply(v), rtol=0, atol=1e-15 * 500 * 4)


# -- seed 001 axis vectors ---------------------------------------------------------


@pytest.mark.parametrize("direction", [0, 1, 2])
def test_tilted_axes_are_unit_vectors_equal_to_the_ideal_axis_at_zero(direction):
    rng = np.random.default_rng(direction)
    for tilt in rng.uniform(-0.3, 0.3, (5, 3)):
        assert np.linalg.norm(tilted_axis(direction, tilt)) == pytest.approx(1.0, abs=1e-15)
    np.testing.assert_array_equal(tilted_axis(direction, np.zeros(3)), np.eye(3)[direction])


def test_seed_001_formulas_for_l_a_l_b_l_c():
    s1, s2 = 0.1, -0.2
    c, s = np.cos, np.sin
    np.testing.assert_allclose(tilted_axis(0, [0, s1, s2]), [c(s2) * c(s1), -c(s2) * s(s1), -s(s2)])
    np.testing.assert_allclose(tilted_axis(1, [s1, 0, s2]), [-s(s1), c(s1) * c(s2), -c(s1) * s(s2)])
    np.testing.assert_allclose(tilted_axis(2, [s1, s2, 0]), [-s(s1), -c(s1) * s(s2), c(s1) * c(s2)])


def test_c_axis_squareness_minus_10_deg_gives_a_circle_normal_to_l_c():
    # Seed 001's validation: s_cy = -10 deg built in; a target on the C table sweeps a circle in the plane normal to l_c.
    tilt = np.array([0.0, np.deg2rad(-10.0), 0.0])
    chain = MachineChain((Body("C", 0, "rotary", 2, axis="c", tilt=tilt), Body("target", 1, offset=[200.0, 50.0, 80.0])), 2, 0)
    p, _ = chain.tool_pose(np.linspace(0, 2 * np.pi, 72, endpoint=False)[:, None])
    l_c = tilted_axis(2, tilt)
    np.testing.assert_allclose(l_c, [0, np.sin(np.deg2rad(10)), np.cos(np.deg2rad(10))], atol=1e-15)
    centred = p - p.mean(axis=0)
    normal = np.linalg.svd(centred)[2][-1]
    assert abs(abs(normal @ l_c) - 1) < 1e-12
    np.testing.assert_allclose(centred @ l_c, 0, atol=1e-10)
    radius = np.linalg.norm(centred, axis=1)
    np.testing.assert_allclose(radius, radius[0], rtol=1e-12)


# -- first-order model ---------------------------------------------------------------


@pytest.mark.parametrize("name", ["vertical_mill_3axis", "polishing_platform_4axis", "table_tilting_5axis", "diamond_lathe", "aircraft_drilling_7axis"])
def test_full_product_agrees_with_first_order_to_second_order(name):
    chain = load_machine(name)
    assert_first_order_to_second_order(chain, travel_grid(chain, 200), np.linspace(0, 900, 200))


def assert_first_order_to_second_order(chain, q, t):
    """Full product minus first order shrinks fourfold when every error halves."""
    diffs = []
    for factor in (1.0, 0.5):
        c = chain.scaled(factor)
        dp, dv = c.volumetric_error(q, t)
        diffs.append(np.abs(np.c_[dp, dv] - c.first_order_error(q, t)).max())
    assert diffs[0] / diffs[1] == pytest.approx(4.0, rel=0.05)


@pytest.mark.parametrize("name", ["polishing_platform_4axis", "table_tilting_5axis", "aircraft_drilling_7axis"])
def test_error_jacobian_times_parameters_is_the_first_order_error(name):
    chain = load_machine(name)  # no tabulated errors in these presets
    q = travel_grid(chain, 50, seed=3)
    t = np.linspace(0, 300, 50)
    params = chain.parameters()
    J = chain.error_jacobian(q, list(params), t)
    np.testing.assert_allclose(J @ np.array(list(params.values())), chain.first_order_error(q, t), atol=1e-12)


def test_error_jacobian_matches_finite_differences_of_the_exact_chain():
    chain = load_machine("table_tilting_5axis").ideal()
    q = travel_grid(chain, 20, seed=4)
    t = np.linspace(10, 100, 20)
    names = ["C.tilt.x", "C.tilt.y", "A.tilt.y", "A.tilt.z", "A.dx.p0", "X.ey.p1", "Z.squareness.x", "A.static.ex", "tool.static.dy", "Y.thermal.ez"]
    J = chain.error_jacobian(q, names, t)
    h = 1e-7
    for k, name in enumerate(names):
        plus = chain.with_parameters({name: h}).tool_pose(q, t)
        minus = chain.with_parameters({name: -h}).tool_pose(q, t)
        fd = np.c_[plus[0] - minus[0], plus[1] - minus[1]] / (2 * h)
        np.testing.assert_allclose(J[:, :, k], fd, atol=1e-6 * max(1.0, np.abs(fd).max()), err_msg=name)


def test_axis_jacobian_matches_finite_differences():
    chain = load_machine("table_tilting_5axis")
    q = travel_grid(chain, 10, seed=5)
    J = chain.axis_jacobian(q)
    h = 1e-6
    for k in range(len(chain.axes)):
        dq = np.zeros(len(chain.axes))
        dq[k] = h
        plus, minus = chain.tool_pose(q + dq, ideal=True), chain.tool_pose(q - dq, ideal=True)
        fd = np.c_[plus[0] - minus[0], plus[1] - minus[1]] / (2 * h)
        np.testing.assert_allclose(J[:, :, k], fd, atol=1e-6)


def test_polishing_platform_first_order_expressions_term_by_term():
    # DOMAIN.md §1 / seed 002 with θB = θC = 0, the z term re-derived as -δzX:
    # Δx = δxZ - z εyX - z SxZ - δxX,  Δy = δyZ + z εxX + x εzX - δyX,  Δz = δzZ - x εyX - δzX,
    # Δε = εZ - εX, i.e. tool-axis error ΔV = Δε × e_z = (Δεy, -Δεx, 0).
    chain = load_machine("polishing_platform_4axis").ideal()
    x, z = np.meshgrid(np.linspace(0, 200, 5), np.linspace(0, 200, 5))
    x, z = x.ravel(), z.ravel()
    q = np.c_[x, z, np.zeros_like(x), np.zeros_like(x)]
    one, zero = np.ones_like(x), np.zeros_like(x)
    expected = {  # name: (Δx, Δy, Δz, ΔVx, ΔVy, ΔVz)
        "Z.dx.p0": (one, zero, zero, zero, zero, zero),
        "X.dx.p0": (-one, zero, zero, zero, zero, zero),
        "X.ey.p0": (-z, zero, -x, -one, zero, zero),
        "Z.squareness.x": (-z, zero, zero, zero, zero, zero),
        "Z.dy.p0": (zero, one, zero, zero, zero, zero),
        "X.ex.p0": (zero, z, zero, zero, one, zero),
        "X.ez.p0": (zero, x, zero, zero, zero, zero),
        "X.dy.p0": (zero, -one, zero, zero, zero, zero),
        "Z.dz.p0": (zero, zero, one, zero, zero, zero),
        "X.dz.p0": (zero, zero, -one, zero, zero, zero),
        "Z.ex.p0": (zero, zero, zero, zero, -one, zero),
        "Z.ey.p0": (zero, zero, zero, one, zero, zero),
        "Z.ez.p0": (zero, zero, zero, zero, zero, zero),
    }
    J = chain.error_jacobian(q, list(expected))
    for k, (name, cols) in enumerate(expected.items()):
        np.testing.assert_allclose(J[:, :, k], np.stack(cols, axis=1), atol=1e-12, err_msg=name)
    # the exact chain with all of them set agrees with the sum to second order
    diffs = []
    for size in (1e-5, 5e-6):
        dp, dv = chain.with_parameters({name: size for name in expected}).volumetric_error(q)
        diffs.append(np.abs(np.c_[dp, dv] - size * J.sum(axis=2)).max())
    assert diffs[0] < 1e-4 * 200 * 1e-5 and diffs[0] / diffs[1] == pytest.approx(4.0, rel=0.01)


# -- thermal drift growing with the axis position (seed 004) ------------------------------------


def drift_time(t, tau):
    """What seed 004's drift rates multiply: t, or the first-order τ·(1 − exp(−t/τ)) [s]."""
    return t if tau == 0 else tau * (1 - np.exp(-t / tau))


def poly(c, q):
    return sum(ck * q**k for k, ck in enumerate(c))


@pytest.mark.parametrize("tau", [0.0, 600.0])
def test_x_on_y_with_thermal_growth_is_seed_004_eq_9(tau):
    """Seed 004 eqs. 6-9: ideal · thermal drift · geometric error per axis, multiplied out by hand.

    Y on the bed (eq. 7): translation column (δx(y) + δxt(y), y + δy(y) + δyt(y), δz(y) + δzt(y));
    X on Y (eq. 9): (x + δx(x) + δxt(x), δy(x) + δyt(x) − x·S_XY, δz(x) + δzt(x)); the rotation
    block of each is its angular error motions ε (exact rotations here, first order in the seed).
    The thermal drifts grow with the axis position: δt(q) = τ(t)·(rate + growth·(q − q_ref)).
    """
    per_min = 1 / 60.0
    S_XY = 30e-6
    geo = {  # body: polynomial coefficients of dx, dy, dz [mm], ex, ey, ez [rad] in q [mm]
        "X": [(0, 6e-6), (0, 4e-6, -1e-9), (2e-3,), (0, 1e-8), (5e-6,), (1e-6, 2e-9)],
        "Y": [(0, 4e-6, -2e-9), (0, 8e-6), (0, 6e-6), (0, 4e-9), (-3e-6,), (5e-6,)],
    }
    rate = {"X": np.array([2.0, -1.0, 0.5]) * 1e-3 * per_min, "Y": np.array([0.7, 3.0, -1.5]) * 1e-3 * per_min}  # [mm/s]
    growth = {"X": np.array([3.0, 1.0, -2.0]) * 1e-6 * per_min, "Y": np.array([-1.0, 2.5, 0.5]) * 1e-6 * per_min}  # [1/s]
    ref = {"X": 150.0, "Y": -40.0}

    def body(name, parent, direction, squareness=(0, 0, 0)):
        return Body(name, parent, "linear", direction, axis=name.lower(), motion=tuple(ErrorMotion(c) for c in geo[name]),
                    squareness=squareness, thermal=np.r_[rate[name], 0, 0, 0], thermal_growth=growth[name],
                    thermal_reference=ref[name], thermal_time_constant=tau)

    tip = np.array([10.0, -20.0, 80.0])
    chain = MachineChain((body("Y", 0, 1), body("X", 1, 0, squareness=(0, S_XY, 0))), tool=2, workpiece=0, axes=("x", "y"), tool_tip=tip)
    rng = np.random.default_rng(9)
    q = rng.uniform([-300, -200], [400, 250], (12, 2))
    t = rng.uniform(0, 3600, 12)
    p, v = chain.tool_pose(q, t)

    def seed_matrix(name, qj, tj, ideal_translation):
        e = [poly(c, qj) for c in geo[name]]
        thermal = drift_time(tj, tau) * (rate[name] + growth[name] * (qj - ref[name]))  # δxt, δyt, δzt
        T = np.eye(4)
        T[:3, :3] = Rotation.from_rotvec(e[3:]).as_matrix()
        T[:3, 3] = ideal_translation + np.array(e[:3]) + thermal
        return T

    for k, ((x, y), tk) in enumerate(zip(q, t)):
        T_Y = seed_matrix("Y", y, tk, [0.0, y, 0.0])  # eq. (7)
        T_X = seed_matrix("X", x, tk, [x, -x * S_XY, 0.0])  # eq. (9)
        T = T_Y @ T_X
        np.testing.assert_allclose(p[k], T[:3, :3] @ tip + T[:3, 3], rtol=0, atol=1e-11)
        np.testing.assert_allclose(v[k], T[:3, 2], rtol=0, atol=1e-15)
    # the growth is what makes the difference: without it the pose moves by micrometres
    still = replace(chain, bodies=tuple(replace(b, thermal_growth=np.zeros(3)) for b in chain.bodies))
    assert np.abs(still.tool_pose(q, t)[0] - p).max() > 1e-3


def with_growth(chain, reference=0.0, tau=0.0):
    """`chain` with a thermal growth (all three directions, 1-4 ppm/min) on every linear body, from `reference`."""
    bodies = []
    for i, b in enumerate(chain.bodies):
        if b.joint == "linear":
            b = replace(b, thermal_growth=np.array([4.0, -1.0, 2.0])[np.roll(np.arange(3), i)] * 1e-6 / 60,
                        thermal_reference=reference, thermal_time_constant=tau)
        bodies.append(b)
    return replace(chain, bodies=tuple(bodies))


@pytest.mark.parametrize("name", ["vertical_mill_3axis", "aircraft_drilling_7axis"])
def test_thermal_growth_full_product_agrees_with_first_order_to_second_order(name):
    chain = with_growth(load_machine(name), reference=100.0, tau=900.0)
    q = travel_grid(chain, 200, seed=7)
    t = np.linspace(0, 3600, 200)
    assert_first_order_to_second_order(chain, q, t)
    growth = {k: v for k, v in chain.parameters().items() if ".thermal_growth." in k}
    without = chain.with_parameters(dict.fromkeys(growth, 0.0))
    J = chain.error_jacobian(q, list(growth), t)
    np.testing.assert_allclose(J @ np.array(list(growth.values())), chain.first_order_error(q, t) - without.first_order_error(q, t),
                               atol=1e-12)


def test_thermal_growth_jacobian_matches_finite_differences_of_the_exact_chain():
    """Tool and workpiece branch (the mill's X and Y carry the table, sign −1), first-order and linear drift."""
    chain = with_growth(load_machine("vertical_mill_3axis").ideal(), reference=120.0)
    chain = replace(chain, bodies=tuple(replace(b, thermal_time_constant=600.0) if b.name == "Y" else b for b in chain.bodies))
    q = travel_grid(chain, 20, seed=4)
    t = np.linspace(10, 1800, 20)
    names = [f"{b}.thermal_growth.{c}" for b in ("X", "Y", "Z") for c in ("dx", "dy", "dz")]
    J = chain.error_jacobian(q, names, t)
    h = 1e-7
    for k, name in enumerate(names):
        plus = chain.with_parameters({name: chain.parameters()[name] + h}).tool_pose(q, t)
        minus = chain.with_parameters({name: chain.parameters()[name] - h}).tool_pose(q, t)
        fd = np.c_[plus[0] - minus[0], plus[1] - minus[1]] / (2 * h)
        assert np.abs(fd).max() > 1.0, name  # (q − 120 mm)·t of hundreds of mm·s
        np.testing.assert_allclose(J[:, :, k], fd, atol=1e-6 * np.abs(fd).max(), err_msg=name)


def test_thermal_growth_needs_a_linear_joint_and_names_its_components():
    with pytest.raises(ValueError, match="C: thermal growth applies to a linear joint"):
        Body("C", 0, "rotary", 2, axis="c", thermal_growth=[1e-8, 0, 0])
    chain = load_machine("vertical_mill_3axis")
    with pytest.raises(ValueError, match="thermal growth is dx, dy, dz of a linear joint"):
        chain.error_jacobian(np.zeros((1, 3)), ["X.thermal_growth.ex"], np.zeros(1))
    with pytest.raises(ValueError, match="thermal growth is dx, dy, dz of a linear joint"):
        chain.error_jacobian(np.zeros((1, 3)), ["tool.thermal_growth.dx"], np.zeros(1))
    with pytest.raises(ValueError, match="thermal parameters need the times t"):
        chain.error_jacobian(np.zeros((1, 3)), ["X.thermal_growth.dx"])


# -- ISO 230-4 circle signatures ---------------------------------------------------------


def xy_machine(x_motion=None, squareness=0.0):
    motion = [ErrorMotion()] * 6
    if x_motion is not None:
        motion[0] = x_motion
    x = Body("X", 0, "linear", 0, axis="x", motion=tuple(motion), squareness=[0, squareness, 0])
    y = Body("Y", 1, "linear", 1, axis="y")
    return MachineChain((x, y, Body("tool", 2)), tool=3, workpiece=0)


def circle(R=100.0, n=720):
    theta = np.linspace(0, 2 * np.pi, n, endpoint=False)
    return theta, np.c_[R * np.cos(theta), R * np.sin(theta)]


def test_squareness_gives_a_45_degree_ellipse():
    alpha, R = 50e-6, 100.0
    theta, q = circle(R)
    p, _ = xy_machine(squareness=alpha).tool_pose(q)
    dr = np.hypot(p[:, 0], p[:, 1]) - R
    # X tilted towards -y (angle between +X and +Y is 90° + α): Δr = -(αR/2) sin 2θ
    np.testing.assert_allclose(dr, -(alpha * R / 2) * np.sin(2 * theta), atol=alpha**2 * R)
    assert abs(np.rad2deg(theta[np.argmax(dr)]) % 180 - 135) < 0.5


def test_scale_error_gives_an_axis_aligned_ellipse():
    k, R = 30e-6, 100.0
    theta, q = circle(R)
    p, _ = xy_machine(ErrorMotion(poly=(0.0, k))).tool_pose(q)
    dr = np.hypot(p[:, 0], p[:, 1]) - R
    np.testing.assert_allclose(dr, R * np.sqrt((1 + k) ** 2 * np.cos(theta) ** 2 + np.sin(theta) ** 2) - R, atol=1e-12)
    assert theta[np.argmax(dr)] in (0.0, np.pi) and abs(dr[np.argmin(dr)]) < 1e-12


def test_cyclic_error_gives_ripple_with_the_lead_period():
    lead, amp = 5.0, 2e-3
    x = np.linspace(0, 200, 4000, endpoint=False)
    q = np.c_[x, np.zeros_like(x)]
    p, _ = xy_machine(ErrorMotion(cyclic=(Cyclic.from_amplitude(amp, lead, 0.3),))).tool_pose(q)
    ripple = p[:, 0] - x
    spectrum = np.abs(np.fft.rfft(ripple))
    wavelength = 1 / np.fft.rfftfreq(x.size, x[1] - x[0])[np.argmax(spectrum)]
    assert wavelength == pytest.approx(lead)
    assert np.ptp(ripple) == pytest.approx(2 * amp, rel=1e-3)


# -- inverse kinematics ---------------------------------------------------------------


def test_ideal_inverse_of_the_cartesian_mill_is_an_offset_map():
    chain = load_machine("vertical_mill_3axis")
    target = np.random.default_rng(0).uniform(0, 300, (20, 3))
    q = chain.inverse(target, ideal=True)
    np.testing.assert_allclose(q, target - [0, 0, 300], atol=1e-12)


def test_actual_inverse_with_tool_axis_reaches_the_pose():
    chain = load_machine("table_tilting_5axis")
    q_true = travel_grid(chain, 30, seed=6)
    q_true[:, 3] = np.where(np.abs(q_true[:, 3]) < 0.2, 0.5, q_true[:, 3])  # away from the A = 0 singularity
    p, v = chain.tool_pose(q_true)
    q = chain.inverse(p, v, q0=q_true + 1e-3)
    pa, va = chain.tool_pose(q)
    np.testing.assert_allclose(pa, p, atol=1e-10)
    np.testing.assert_allclose(va, v, atol=1e-12)


def test_inverse_of_more_than_two_blocks_reaches_every_pose():
    # 2 full blocks of the iteration and a short one; the thermal drift reads each block's own times
    chain = load_machine("aircraft_drilling_7axis")
    n = 2 * BLOCK + 100
    q_true = travel_grid(chain, n, seed=7)
    t = np.linspace(0.0, 600.0, n)
    p, v = chain.tool_pose(q_true, t, ideal=True)
    q = chain.inverse(p, v, q0=q_true, t=t)
    pa, va = chain.tool_pose(q, t)
    assert np.abs(chain.tool_pose(q_true, t)[0] - p).max() > 1e-2  # the errors to cancel, up to tens of µm
    np.testing.assert_allclose(pa, p, atol=1e-9)
    np.testing.assert_allclose(va, v, atol=1e-12)


def test_inverse_errors_name_the_whole_input_not_a_block():
    chain = load_machine("vertical_mill_3axis")
    n = BLOCK + 10
    q_true = travel_grid(chain, n, seed=8)
    p, _ = chain.tool_pose(q_true, ideal=True)
    q0 = q_true.copy()
    q0[n - 3] += 1.0  # every other sample starts at its solution: the first block stops at once
    with pytest.raises(ValueError, match=f"did not converge in 1 steps \\(sample {n - 3}, last step 1"):
        chain.inverse(p, q0=q0, ideal=True, max_iter=1)
    with pytest.raises(ValueError, match=f"t must have shape \\({n},\\)"):  # the whole input's length, not a block's
        chain.inverse(p, q0=q_true, t=np.zeros(n - 1))


# -- validation and loading -----------------------------------------------------------------


def test_inverse_leaves_the_tool_axis_alone_at_the_singular_pose():
    # A = 0: C is parallel to the tool; a tilt about y cannot be made without a large C swing.
    chain = load_machine("table_tilting_5axis")
    q_true = np.array([[10.0, 20.0, -100.0, 1e-7, 0.3]])
    p, v = chain.tool_pose(q_true, ideal=True)
    q = chain.inverse(p, v, q0=q_true)
    np.testing.assert_allclose(chain.tool_pose(q)[0], p, atol=1e-10)
    assert abs(q[0, 4] - 0.3) < 1e-3


def test_tool_pose_rejects_bad_shapes_and_values():
    chain = load_machine("vertical_mill_3axis")
    with pytest.raises(ValueError, match=r"q must have shape \(N, 3\)"):
        chain.tool_pose(np.zeros((4, 2)))
    with pytest.raises(ValueError, match="non-finite"):
        chain.tool_pose(np.full((2, 3), np.nan))
    with pytest.raises(ValueError, match="unknown parameter"):
        chain.error_jacobian(np.zeros((1, 3)), ["X.bogus.p0"])


def test_all_presets_load():
    assert set(preset_names()) >= {"vertical_mill_3axis", "polishing_platform_4axis", "table_tilting_5axis", "diamond_lathe", "aircraft_drilling_7axis"}
    assert len(load_machine("vertical_mill_3axis").parameters()) >= 21


MACHINE = """name = "test"
tool = "tool"
workpiece = "bed"

[[body]]
name = "X"
joint = "linear x"
axis = "x"
squareness = { y_urad = 10 }
[body.errors]
dx_um = { poly = [1, 0.01], cyclic = { amplitude_um = 2, period_mm = 5 } }

[[body]]
name = "tool"
parent = "X"
"""


def test_toml_units_are_converted_at_the_edge():
    chain = chain_from_toml(TomlFile("m.toml", MACHINE))
    x = chain.bodies[0]
    assert x.squareness[1] == pytest.approx(10e-6)
    assert x.motion[0].poly == pytest.approx((1e-3, 1e-5))
    assert x.motion[0].cyclic[0].sin == pytest.approx(2e-3) and x.motion[0].cyclic[0].period == 5


def test_toml_thermal_growth_reference_and_time_constant():
    text = MACHINE.replace('squareness = { y_urad = 10 }', 'squareness = { y_urad = 10 }\nthermal = { dy_um_per_min = 3 }\n'
                           'thermal_growth = { dx_ppm_per_min = 1.5, dz_ppm_per_min = -0.6 }\n'
                           'thermal_reference_mm = 250\nthermal_time_constant_s = 1800')
    x = chain_from_toml(TomlFile("m.toml", text)).bodies[0]
    np.testing.assert_allclose(x.thermal_growth, np.array([1.5, 0.0, -0.6]) * 1e-6 / 60, rtol=1e-15)  # [mm/s per mm]
    np.testing.assert_allclose(x.thermal, [0, 3e-3 / 60, 0, 0, 0, 0], rtol=1e-15)
    assert (x.thermal_reference, x.thermal_time_constant) == (250.0, 1800.0)


@pytest.mark.parametrize(
    "old, new, line, match",
    [
        ('squareness = { y_urad = 10 }', 'thermal_growth = { ex_ppm_per_min = 1 }', 9, "unknown key 'ex_ppm_per_min'"),
        ('squareness = { y_urad = 10 }', 'thermal_time_constant_s = -5', 9, "thermal_time_constant_s must be 0 .* or positive"),
        ('squareness = { y_urad = 10 }', 'thermal_reference_mm = "a"', 9, "expected a finite number"),
        ('parent = "X"', 'parent = "X"\nthermal_growth = { dx_ppm_per_min = 1 }', 16, "thermal_growth applies to a linear joint"),
        ('squareness = { y_urad = 10 }', 'squarenes = { y_urad = 10 }', 9, "unknown key 'squarenes'"),
        ('joint = "linear x"', 'joint = "linear w"', 7, "joint must be"),
        ('parent = "X"', 'parent = "Y"', 15, "'Y' is not a body"),
        ("dx_um = { poly = [1, 0.01],", 'dx_um = { poly = [1, "a"],', 11, "expected a finite number"),
        ("dx_um = { poly", "dq_um = { poly", 11, "unknown key 'dq_um'"),
        ('squareness = { y_urad = 10 }', 'squareness = { x_urad = 10 }', 9, "squareness applies"),
        # the chain's rotations are first-order: 1e8 µrad (100 rad) of tilt or static angle was taken as given
        ('parent = "X"', 'parent = "X"\nstatic = { ez_urad = 2e4 }', 16, r"its static angle ez is 2e\+04 µrad: beyond the small "),
        ('parent = "X"', 'parent = "X"\nstatic = { dx_um = 1, ex_urad = -1.5e4 }', 16, r"static angle ex is -1.5e\+04 µrad"),
        ('[[body]]\nname = "tool"', '[[body]]\nname = "C"\nparent = "X"\njoint = "rotary z"\naxis = "c"\ntilt = { x_urad = 3e4 }\n\n'
         '[[body]]\nname = "tool"', 18, r"body 'C': its tilt angle x is 3e\+04 µrad: beyond the small errors"),
        ("period_mm = 5", "period_deg = 5", 11, r"cyclic terms are \{ amplitude_um, period_mm, phase_deg \}"),
        # a travel beyond the chain's ±1e6 (mm or rad): said by the key and in its unit, not "C.travel holds 1.74533e+06
        # at index (1,), beyond ±1e+06" (rad) at the body's line
        ('axis = "x"', 'axis = "x"\ntravel_mm = [0, 4e9]', 9, r"body 'X': travel_mm must lie within ±1e\+06, got 4e\+09"),
        ('[[body]]\nname = "tool"', '[[body]]\nname = "C"\nparent = "X"\njoint = "rotary z"\naxis = "c"\ntravel_deg = [0, 1e8]\n\n'
         '[[body]]\nname = "tool"', 18, r"body 'C': travel_deg must lie within ±5.72958e\+07, got 1e\+08"),
        ('axis = "x"', 'axis = "x"\ntravel_mm = [10, 0]', 9, r"body 'X': travel_mm must be \[min, max\] with min < max, got \[10, 0\]"),
        ('axis = "x"', 'axis = "x"\ntravel_deg = [0, 1]', 9, "the travel of a linear joint is 'travel_mm'"),
        # keys without their unit (earlier versions) name the key that replaced them
        ('axis = "x"', 'axis = "x"\ntravel = [0, 1]', 9, r"key 'travel' in the 1st \[\[body\]\] is now 'travel_mm'"),
        ('squareness = { y_urad = 10 }', 'squareness = { y = 10 }', 9, "key 'y' .* is now 'y_urad'"),
        ("dx_um = { poly", "dx = { poly", 11, "key 'dx' .* is now 'dx_um'"),
        ('parent = "X"', 'parent = "X"\noffset = [0, 0, 1]', 16, "key 'offset' .* is now 'offset_mm'"),
    ],
)
def test_toml_errors_name_file_and_line(old, new, line, match):
    with pytest.raises(ConfigError, match=rf"^m.toml, line {line}: .*{match}"):
        chain_from_toml(TomlFile("m.toml", MACHINE.replace(old, new)))


@pytest.mark.parametrize(
    "old, new, match",
    [
        ('workpiece = "bed"', 'workpiece = "tool"', r"^m.toml: tool and workpiece must be different bodies"),
        # an axis no body drives: its kind was looked up with next() (a StopIteration out of Machine)
        ('workpiece = "bed"', 'workpiece = "bed"\naxis_order = ["x", "y"]', r"^m.toml, line 4: axis_order lists 'y', which "
                                                                             r"no body drives \(the bodies drive x\)"),
        ('workpiece = "bed"', 'workpiece = "bed"\ntool_axis = [0, 0, 0]', r"^m.toml, line 4: tool_axis must be a non-zero"),
        # were "m.toml: could not convert string to float: 'a'" and "m.toml: tool_tip_mm must have shape (3)": no line
        ('workpiece = "bed"', 'workpiece = "bed"\ntool_axis = ["a", 0, 1]', r"^m.toml, line 4: tool_axis: expected a finite "
                                                                           r"number, got 'a'"),
        ('workpiece = "bed"', 'workpiece = "bed"\ntool_tip_mm = [0, 0]', r"^m.toml, line 4: tool_tip_mm must be \[x, y, z\], "
                                                                        r"got \[0, 0\]"),
    ],
)
def test_toml_chain_errors_name_the_file(old, new, match):
    with pytest.raises(ConfigError, match=match):
        chain_from_toml(TomlFile("m.toml", MACHINE.replace(old, new)))


@pytest.mark.parametrize("old, new, words", [
    # was "m.toml: parents: body 4 is its own ancestor (the bodies do not form a tree)": no line, no name
    ('name = "column"\nparent = "bed"', 'name = "column"\nparent = "tool"',
     "body 'column': parent = \"tool\" makes a cycle, column → tool → Z → column (each body's parent after it)"),
    ('name = "column"\nparent = "bed"', 'name = "column"\nparent = "column"', "body 'column': parent = \"column\" makes a "
                                                                             "cycle, column → column"),
    # was "m.toml: axes ('x', 'y') must list each driven axis once; missing: ['z']": the API's name, no line
    ('axis_order = ["x", "y", "z"]', 'axis_order = ["x", "y"]', "axis_order lacks 'z' (driven by body 'Z'): it lists each "
                                                                "axis a body drives, once"),
    ('axis_order = ["x", "y", "z"]', 'axis_order = ["x", "y", "z", "x"]', "axis_order lists 'x' more than once"),
    ('axis_order = ["x", "y", "z"]', 'axis_order = ["x", "y", "z", "w"]', "axis_order lists 'w', which no body drives "
                                                                          "(the bodies drive y, x, z)"),
    ('axis_order = ["x", "y", "z"]', 'axis_order = "xyz"', "axis_order must be a list of axis names in quotes"),
    # was "m.toml: axes ('x', 'y', 'z') lists 'z', which no body's joint drives": Y and Z both on y, z idle
    ('joint = "linear z"\naxis = "z"', 'joint = "linear z"\naxis = "y"', "axis 'y' drives two bodies, 'Y' and 'Z': each "
                                                                         "axis drives one body"),
])
def test_a_machine_files_tree_and_axes_are_refused_at_the_line_of_the_key_naming_the_bodies(tmp_path, old, new, words):
    text = (Path(__file__).parents[1] / "contoursim" / "presets" / "vertical_mill_3axis.toml").read_text()
    (tmp_path / "vertical_mill_x_laser.csv").write_text(
        (Path(__file__).parents[1] / "contoursim" / "presets" / "vertical_mill_x_laser.csv").read_text())
    assert text.count(old) == 1
    text = text.replace(old, new)
    (tmp_path / "m.toml").write_text(text)
    line = text[: text.index(new)].count("\n") + new.count("\n") + 1  # the key changed: new's last line
    with pytest.raises(ConfigError) as info:
        load_preset(tmp_path / "m.toml")
    assert str(info.value).startswith(f"{tmp_path / 'm.toml'}, line {line}: {words}"), str(info.value)


@pytest.mark.parametrize("parents, axes, key, body, words", [
    ((0, 1, 2), ("y", "y"), "axis", 2, "axis 'y' drives two bodies, 'Y' and 'Z': each axis drives one body"),
    ((3, 1, 2), ("y", "z"), "parent", 1, "body 'Y': parent = \"tool\" makes a cycle, Y → tool → Z → Y"),
    ((0, 3, 2), ("y", "z"), "parent", 2, "body 'Z': parent = \"tool\" makes a cycle, Z → tool → Z"),
    ((0, 2, 2), ("y", "z"), "parent", 2, "body 'Z': parent = \"Z\" makes a cycle, Z → Z"),
    ((0, 4, 2), ("y", "z"), "parent", 2, "body 'Z': parent 4 is not a body 0..3"),
])
def test_a_chain_that_is_not_a_tree_on_its_axes_is_refused_naming_the_bodies(parents, axes, key, body, words):
    bodies = (Body("Y", parents[0], "linear", 1, axis=axes[0]), Body("Z", parents[1], "linear", 2, axis=axes[1]),
              Body("tool", parents[2]))
    with pytest.raises(ChainError) as info:
        MachineChain(bodies, tool=3, workpiece=0)
    assert str(info.value).startswith(words), str(info.value)
    assert (info.value.key, info.value.body) == (key, body)


@pytest.mark.parametrize("axes, words", [
    (("y",), "axes lacks 'z' (driven by body 'Z'): it lists each axis a body drives, once (y, z)"),
    (("y", "z", "y"), "axes lists 'y' more than once"),
    (("y", "z", "w"), "axes lists 'w', which no body drives (the bodies drive y, z)"),
])
def test_a_chains_axes_must_list_each_driven_axis_once(axes, words):
    bodies = (Body("Y", 0, "linear", 1, axis="y"), Body("Z", 1, "linear", 2, axis="z"), Body("tool", 2))
    assert MachineChain(bodies, tool=3, workpiece=0, axes=("z", "y")).axes == ("z", "y")
    with pytest.raises(ChainError, match=re.escape(words)) as info:
        MachineChain(bodies, tool=3, workpiece=0, axes=axes)
    assert (info.value.key, info.value.body) == ("axes", None)


@pytest.mark.parametrize(
    "rows, warned",
    [
        ("0,0\n100,3\n", ""),  # the whole travel
        ("-10,0\n50,1\n110,3\n", ""),  # beyond it
        ("20,0\n100,3\n", "covers 20 .. 100 mm of the travel 0 .. 100 mm"),  # short at the start
        ("0,0\n60,3\n", "covers 0 .. 60 mm of the travel 0 .. 100 mm"),  # and at the end
    ],
)
def test_an_error_table_shorter_than_the_travel_is_warned_of_naming_the_table_and_line(tmp_path, rows, warned):
    # beyond its ends a table's end values are held (np.interp): an error a laser run did not give, taken without a word
    (tmp_path / "x.csv").write_text("position_mm,dx_um\n" + rows)
    (tmp_path / "m.toml").write_text(MACHINE.replace("[body.errors]\n", 'travel_mm = [0, 100]\n[body.errors]\ntable = "x.csv"\n'))
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        chain_from_toml(TomlFile.read(tmp_path / "m.toml"))
    messages = [str(w.message) for w in caught if issubclass(w.category, ContoursimWarning)]
    if not warned:
        assert messages == []
        return
    assert messages == [f"{tmp_path / 'm.toml'}, line 12: body 'X': error table 'x.csv' {warned}: its first and last values "
                        "are held beyond its ends (add rows at the travel's ends to give the errors there)"]


def test_an_error_table_outside_the_travel_is_refused_naming_the_table_and_line(tmp_path):
    """A table of -1000 .. -900 mm on a travel of 0 .. 100 mm: warned of as covering part of the travel, its last row's
    errors held over all of it (an outside probe)."""
    (tmp_path / "x.csv").write_text("position_mm,dx_um\n-1000,0\n-900,3\n")
    (tmp_path / "m.toml").write_text(MACHINE.replace("[body.errors]\n", 'travel_mm = [0, 100]\n[body.errors]\ntable = "x.csv"\n'))
    with pytest.raises(ConfigError, match=re.escape(f"{tmp_path / 'm.toml'}, line 12: body 'X': error table 'x.csv' covers "
                                                    "-1000 .. -900 mm, none of the travel 0 .. 100 mm: positions of")):
        chain_from_toml(TomlFile.read(tmp_path / "m.toml"))


@pytest.mark.parametrize("rows, words", [
    ("0,0\n50000,3\n100000,6\n", "spans 0 .. 100000 mm, 1e+03 times the travel 0 .. 100 mm: positions in µm"),
    ("0,0\n1e300,6\n", "holds positions up to 1e+300 mm, beyond any travel (±1e+06 mm)"),
])
def test_an_error_table_in_micrometres_or_beyond_any_travel_is_refused(tmp_path, rows, words):
    """A laser table whose positions are in µm covers the travel with its first interval: its 6 µm became 0.006 µm
    without a word (an outside probe); rows at 1e300 mm ran as well."""
    (tmp_path / "x.csv").write_text("position_mm,dx_um\n" + rows)
    (tmp_path / "m.toml").write_text(MACHINE.replace("[body.errors]\n", 'travel_mm = [0, 100]\n[body.errors]\ntable = "x.csv"\n'))
    with pytest.raises(ConfigError, match=re.escape(f"{tmp_path / 'm.toml'}, line 12: body 'X': error table 'x.csv' {words}")):
        chain_from_toml(TomlFile.read(tmp_path / "m.toml"))


def test_an_error_table_that_is_a_folder_is_refused_at_the_line_naming_it(tmp_path):
    """The folder's own name was said, not the machine file's line that named it (an outside probe)."""
    (tmp_path / "x.csv").mkdir()
    (tmp_path / "m.toml").write_text(MACHINE.replace("[body.errors]\n", 'travel_mm = [0, 100]\n[body.errors]\ntable = "x.csv"\n'))
    with pytest.raises(ConfigError, match=re.escape(f"{tmp_path / 'm.toml'}, line 12: body 'X': error table 'x.csv': "
                                                    f"{tmp_path / 'x.csv'}: cannot read the file: it is a directory")):
        chain_from_toml(TomlFile.read(tmp_path / "m.toml"))


def test_a_thermal_drift_beyond_the_small_errors_within_a_run_is_refused():
    # X travels 0..100 mm (MACHINE has no travel: given here); the small errors allow 1 mm of drift along it, 10 mrad.
    text = MACHINE.replace('squareness = { y_urad = 10 }', 'squareness = { y_urad = 10 }\ntravel_mm = [0, 100]\n'
                           'thermal = { dy_um_per_min = 600 }')  # 10 µm/s: 1 mm after 100 s
    chain = chain_from_toml(TomlFile("m.toml", text))
    multibody.check_drift(chain, 99.9)
    with pytest.raises(ValueError, match=r"^the machine's body 'X': its thermal drift dy reaches 1001 µm after the "
                                         r"run's 100.1 s: beyond the small errors .* \(0.01 of the travel's length\)"):
        multibody.check_drift(chain, 100.1)
    # a growth drifts most at the far end of the travel: 1000 ppm/min from 0 is 100 µm/min at 100 mm
    grown = chain_from_toml(TomlFile("m.toml", text.replace("thermal = { dy_um_per_min = 600 }",
                                                           "thermal_growth = { dx_ppm_per_min = 1000 }")))
    multibody.check_drift(grown, 599.0)
    with pytest.raises(ValueError, match=r"thermal drift dx reaches 1002 µm after the run's 601 s"):
        multibody.check_drift(grown, 601.0)
    tilted = chain_from_toml(TomlFile("m.toml", text.replace("dy_um_per_min = 600", "ez_urad_per_min = 6e5")))
    with pytest.raises(ValueError, match=r"thermal drift ez reaches 1.1e\+04 µrad after the run's 1.1 s: .* \(0.01 an angle"):
        multibody.check_drift(tilted, 1.1)


def _scaled_pinv(A, floor, rcond=1e-4):
    """Least-squares operator of A x = b, columns scaled by max(norm, floor), by numpy's SVD; and the dropped directions.

    Singular values with σ² <= rcond are dropped (the eigenvalue threshold of
    the scaled normal equations).
    """
    s = np.maximum(np.linalg.norm(A, axis=0), floor)
    U, sigma, Vt = np.linalg.svd(A / s)
    keep = sigma**2 > rcond
    V = Vt[: len(sigma)][keep].T
    X = V @ np.diag(1 / sigma[keep]) @ U[:, keep].T
    null = np.eye(A.shape[1]) - V @ V.T
    return X / s[:, None], null * s[None, :] / s[:, None]


def test_prioritized_inverse_equals_the_svd_pseudo_inverse():
    """Position rows by the column-scaled pseudo-inverse, tool-axis rows in the null space the position leaves."""
    rng = np.random.default_rng(3)
    J = rng.normal(size=(50, 6, 5)) * np.array([1.0, 1.0, 1.0, 1e-3, 1e-3, 1e-3])[None, :, None] * rng.uniform(0.5, 300, (50, 1, 5))
    # Positions of rank 2 (one direction dropped, by the projector), of rank 3 with one direction
    # below rcond and of rank 1: the eigenvector path; the tool axis by the projector where the
    # position has full rank (the null space it leaves, and so Jo·N, of rank 2), else by the inverse.
    J[::5, 2] = J[::5, 1]
    J[1::5, 2] = J[1::5, 1] * (1 + 1e-3 * np.arange(5))
    J[2::5, 1] = J[2::5, 2] = J[2::5, 0]
    P = multibody._prioritized_inverse(J)
    P3 = multibody._prioritized_inverse(np.ascontiguousarray(J[:, :3]))
    for n in range(len(J)):
        X1, null = _scaled_pinv(J[n, :3], 1.0)
        Jo = J[n, 3:]
        X2, _ = _scaled_pinv(Jo @ null, np.linalg.norm(Jo, axis=0).max())
        want = np.hstack([X1 - null @ X2 @ Jo @ X1, null @ X2])
        np.testing.assert_allclose(P[n], want, rtol=0, atol=1e-10 * np.abs(want).max())
        np.testing.assert_allclose(P3[n], X1, rtol=0, atol=1e-10 * np.abs(X1).max())
        if n % 5 > 2:
            np.testing.assert_allclose(J[n, :3] @ P[n, :, :3], np.eye(3), atol=1e-9)  # the position is met exactly


def test_prioritized_inverse_keeps_a_tool_axis_turn_just_above_the_threshold():
    """A turn left to the tool axis is used when its scaled eigenvalue exceeds rcond = 1e-4, else dropped."""
    eigenvalue = np.array([3e-4, 1.5e-4, 1.01e-4, 0.99e-4, 0.7e-4, 0.4e-4, 0.0])
    J = np.zeros((eigenvalue.size, 6, 4))
    J[:, :3, :3] = np.eye(3)  # the position takes axes 0-2 ...
    J[:, 3, 0] = 1.0  # ... and with them the strongest turn of the tool axis (the column scale)
    J[:, 5, 3] = np.sqrt(eigenvalue)  # axis 3, free, turns the tool axis about the rest: by √λ per unit
    P = multibody._prioritized_inverse(J)
    # kept: a unit residual of that component moves axis 3 by 1/√λ; dropped: not at all
    np.testing.assert_allclose(P[:, 3, 5] * np.sqrt(eigenvalue), eigenvalue > 1e-4, rtol=1e-12, atol=0)
