"""Effects, models, batches of variants, [[effect]] tables and the simulated run of a measured reference."""

import numpy as np
import pytest

from contoursim import paths
from contoursim.config import TomlFile
from contoursim.effects import CATALOGUE, STAGES, Effect, effect_kind, effect_names, read_effects
from contoursim.exceptions import ConfigError
from contoursim.feed import plan, sample
from contoursim.kernel import LoopEffects
from contoursim.machine import Machine, load_machine, preset_file
from contoursim.model import Model, load_model
from contoursim.servo import AxisServo
from contoursim.simulation import measured_reference, simulate, simulate_batch
from contoursim.traces import Trace, read_trace

DT = 1e-3
AXIS = dict(mass=300.0, force_constant=942.0, kv=80.0, ti=0.016, kp=40.0, damping=500.0)
MACHINE = Machine({"x": AxisServo(**AXIS), "y": AxisServo(**AXIS)}, DT)


def _circle(direction="ccw", radius=10.0, feed=20.0):
    path = paths.iso230_4_circle(radius, direction=direction, start_angle=np.pi / 4)
    return sample(path, plan(path, feed=feed, accel=1000.0, jerk=5e4), DT)


# -- Effect ------------------------------------------------------------------------------------


def test_the_catalogue_is_the_contracts():
    assert CATALOGUE == ("backlash", "coulomb_friction", "gain_mismatch", "squareness", "scale_error", "cyclic_error",
                         "straightness", "time_delay", "thermal_drift", "vibration")
    assert effect_names() == CATALOGUE + ("quantisation", "noise")
    sizes = {name: effect_kind(name).parameters[0].name for name in CATALOGUE}
    assert sizes == dict(backlash="lost_motion_um", coulomb_friction="force_N", gain_mismatch="kp_ratio",
                         squareness="angle_urad", scale_error="ppm", cyclic_error="amplitude_um", straightness="peak_um",
                         time_delay="delay_s", thermal_drift="rate_um_per_min", vibration="freq_hz")
    for name in effect_names():
        for p in effect_kind(name).parameters:
            assert p.unit and p.doc and p.bounds[0] <= p.value <= p.bounds[1]


def test_an_effect_knows_its_parameters_stage_and_label():
    e = Effect("time_delay", "y", delay_s=1e-3, kind="feedback")
    assert (e.label, e.stage, e["delay_s"], e.options["kind"]) == ("time_delay.y", "loop", 1e-3, "feedback")
    assert Effect("time_delay", "y", delay_s=1e-3).stage == "command"
    assert Effect("time_delay", "y", delay_s=1e-3, kind="position").stage == "loop"
    sizes = {n: effect_kind(n).parameters[0] for n in effect_names()}
    assert {Effect(n, "xy" if n == "squareness" else "x", **{p.name: p.typical[0]}).stage
            for n, p in sizes.items()} == set(STAGES)
    p = Effect("cyclic_error", "x", amplitude_um=2.0).parameters
    assert [(q.name, q.value, q.unit, q.vary) for q in p] == [
        ("amplitude_um", 2.0, "µm", True), ("period_mm", 10.0, "mm", False), ("phase_deg", 0.0, "deg", True)]
    assert Effect("squareness", "xy", angle_urad=-30.0).parameters[0].signed
    same, other = Effect("backlash", "x", lost_motion_um=8.0), Effect("backlash", "x", lost_motion_um=8.0, feedback="scale")
    assert len({same, Effect("backlash", "x", lost_motion_um=8.0), other}) == 2  # hashable, equal by value


@pytest.mark.parametrize("args, kwargs, message", [
    (("ballscrew", "x"), {}, "unknown effect 'ballscrew'; the effects are: backlash, coulomb_friction"),
    (("backlash", "x"), {"lost_motion": 8.0},
     r"unknown parameter 'lost_motion' \(did you mean 'lost_motion_um'\?\); its parameters are lost_motion_um, feedback"),
    (("backlash", "x"), {}, r"missing 'lost_motion_um' \[µm\]"),
    (("backlash", "x"), {"lost_motion_um": -1.0}, r"lost_motion_um must lie in \[0, 1000\] µm, got -1"),
    (("backlash", "x"), {"lost_motion_um": 8.0, "feedback": "encoder"}, "feedback must be one of 'motor', 'scale'"),
    (("backlash", "xy"), {"lost_motion_um": 8.0}, "axis must be one axis letter"),
    (("squareness", "x"), {"angle_urad": 8.0}, "axis must be 2 different axis letters"),
    (("squareness", "xx"), {"angle_urad": 8.0}, "axis must be 2 different axis letters"),
    (("straightness", "x"), {"peak_um": 3.0, "error_direction": "x"}, "error_direction must be one of 'y', 'z'"),
    (("noise", "x"), {"rms_um": 0.1, "seed": -1}, "seed must be a whole number from 0 to 2"),
    # was refused by the kernel at the run, naming the path file
    (("noise", "x"), {"rms_um": 0.1, "seed": 2**53}, "seed must be a whole number from 0 to 2"),
    (("time_delay", "x"), {"delay_s": 1e-3, "kind": "velocity"},
     "kind must be one of 'command', 'feedback', 'position', got 'velocity'"),
    # a friction's forces ran to 1e300 N, the axis standing still in a run that read as an ordinary one
    (("coulomb_friction", "x"), {"force_N": 1e300}, r"force_N must lie in \[0, 100000\] N, got 1e\+300"),
    (("coulomb_friction", "x"), {"force_N": 30.0, "stribeck_N": 2e5}, r"stribeck_N must lie in \[0, 100000\] N"),
    (("coulomb_friction", "x"), {"force_N": 30.0, "viscous_N_s_per_m": 2e6},
     r"viscous_N_s_per_m must lie in \[0, 1e\+06\] N·s/m"),
    (("coulomb_friction", "x"), {"force_N": 30.0, "asymmetry_N": -2e5},
     r"asymmetry_N must lie in \[-100000, 100000\] N"),
    (("coulomb_friction", "x"), {"force_N": 30.0, "offset_N": 1e300}, r"offset_N must lie in \[-100000, 100000\] N"),
])
def test_a_bad_effect_says_what_is_wrong(args, kwargs, message):
    with pytest.raises(ValueError, match=message):
        Effect(*args, **kwargs)


@pytest.mark.parametrize("args, kwargs, message", [
    (("noise", "x"), {"rms_um": 0.1, "seed": 1.5}, "seed must be a whole number from 0 to 2"),
    (("backlash", 1), {"lost_motion_um": 8.0}, "axis must be a string of axis letters"),
])
def test_an_effect_of_the_wrong_type_says_so(args, kwargs, message):
    with pytest.raises(TypeError, match=message):
        Effect(*args, **kwargs)


# -- Model -------------------------------------------------------------------------------------


def test_a_model_names_its_parameters_flat_and_makes_variants():
    model = Model(MACHINE, (Effect("backlash", "x", lost_motion_um=8.0),
                            Effect("coulomb_friction", "y", force_N=30.0).with_vary(viscous_N_s_per_m=True)))
    names = list(model.parameters())
    assert names[:2] == ["backlash.x.lost_motion_um", "coulomb_friction.y.force_N"]
    variant = model.with_values({"backlash.x.lost_motion_um": 12.0, "coulomb_friction.y.viscous_N_s_per_m": 100.0})
    assert variant.values()["backlash.x.lost_motion_um"] == 12.0
    assert variant.values()["coulomb_friction.y.viscous_N_s_per_m"] == 100.0
    assert model.values()["backlash.x.lost_motion_um"] == 8.0  # the model itself is unchanged
    assert variant.parameters()["coulomb_friction.y.viscous_N_s_per_m"].vary  # vary flags survive
    assert variant.machine is model.machine
    assert model.effects[0].options["feedback"] == MACHINE.axes["x"].position_feedback == "motor"  # the axis's
    replaced = model.with_effect(Effect("backlash", "x", lost_motion_um=3.0, feedback="motor"))
    assert [e.label for e in replaced.effects] == ["coulomb_friction.y", "backlash.x"]
    assert replaced.effects[1]["lost_motion_um"] == 3.0
    scale = model.with_effect(Effect("backlash", "x", lost_motion_um=3.0, feedback="scale"))  # given: the axis reads there
    assert scale.machine.axes["x"].position_feedback == "scale" and scale.effects[1].options["feedback"] == "scale"
    assert scale.machine.axes["y"] == model.machine.axes["y"] and model.machine.axes["x"].position_feedback == "motor"
    with pytest.raises(ValueError, match="unknown model parameter 'backlash.y.lost_motion_um'; the model's parameters are: backlash.x"):
        model.with_values({"backlash.y.lost_motion_um": 1.0})


def test_a_model_refuses_repeated_effects_and_missing_axes():
    with pytest.raises(ValueError, match="backlash.x given more than once"):
        Model(MACHINE, (Effect("backlash", "x", lost_motion_um=1.0), Effect("backlash", "x", lost_motion_um=2.0)))
    with pytest.raises(ValueError, match=r"backlash.z: the machine has no axis 'z' among its servo axes \(x, y\)"):
        Model(MACHINE, (Effect("backlash", "z", lost_motion_um=1.0),))
    with pytest.raises(ValueError, match="squareness.xz: the machine has no axis 'z' among its linear axes"):
        Model(MACHINE, (Effect("squareness", "xz", angle_urad=10.0),))
    # a bow of X in the z direction on an x, y machine: taken, and it changed nothing (an outside probe)
    with pytest.raises(ValueError, match=r"straightness.x: error_direction 'z': the machine has no axis 'z' among its "
                                         r"linear axes \(x, y\)"):
        Model(MACHINE, (Effect("straightness", "x", peak_um=5.0, span_mm=100.0, start_mm=0.0, error_direction="z"),))


def test_stages_realise_the_effects():
    model = Model(MACHINE, (Effect("gain_mismatch", "y", kp_ratio=0.9), Effect("backlash", "x", lost_motion_um=8.0),
                            Effect("coulomb_friction", "x", force_N=20.0), Effect("time_delay", "x", delay_s=2.5e-3)))
    servos = model.servos()
    assert servos["y"].kp == pytest.approx(0.9 * AXIS["kp"]) and servos["x"] is MACHINE.axes["x"]
    loop = model.loop_effects()
    assert (loop["x"].backlash_mm, loop["x"].coulomb_N, loop["y"].backlash_mm) == (8e-3, 20.0, 0.0)
    # command delay: 2.5 periods late, linear interpolation between samples, the first sample held
    q = np.column_stack([np.arange(10.0) ** 2, np.zeros(10)])
    qd, vd, ad = model.commands(q, q, q)
    t = np.arange(10.0) - 2.5
    expected = np.where(t < 0, 0.0, np.floor(t) ** 2 + (t - np.floor(t)) * (np.ceil(t) ** 2 - np.floor(t) ** 2))
    np.testing.assert_allclose(qd[:, 0], expected)
    assert np.array_equal(qd[:, 1], q[:, 1])


def test_geometric_effects_land_in_the_chain_of_a_machine_with_bodies():
    """Effects on a machine whose tables move opposite to the tool: the tool still moves as the effect says.

    Checked against the chain's own first-order model of the terms added,
    through the machine's tool position (the table axes have sign −1).
    """
    machine = load_machine("vertical_mill_3axis")
    q = machine.home() + np.array([[30.0, -20.0, -10.0], [-40.0, 25.0, -60.0]])
    t = np.array([0.0, 60.0])
    start, end = machine.travel["x"]
    base = machine.tool_position(q, t, 3)
    cases = [
        (Effect("scale_error", "x", ppm=100.0), lambda d: 100e-6 * q[:, 0], 0),  # from the axis's zero
        (Effect("thermal_drift", "y", rate_um_per_min=6.0), lambda d: 6e-3 / 60 * t, 1),
        (Effect("thermal_drift", "x", rate_um_per_min=2.0, growth_ppm_per_min=3.0, reference_mm=100.0),
         lambda d: (2e-3 + 3e-6 * (q[:, 0] - 100.0)) / 60 * t, 0),  # from the axis position reference_mm
        (Effect("straightness", "x", peak_um=5.0, span_mm=end - start, start_mm=start, error_direction="z"),
         lambda d: 5e-3 * (1.0 - (2 * (q[:, 0] - start) / (end - start) - 1.0) ** 2), 2),  # over the travel of X
    ]
    for effect, shift, column in cases:
        moved = Model(machine, (effect,)).geometry.tool_position(q, t, 3)
        d = q - machine.home()  # positions from the path origin
        np.testing.assert_allclose(moved[:, column] - base[:, column], shift(d), atol=2e-7)  # first order in the errors


def test_thermal_drift_runs_from_the_references_first_sample_after_a_strategys_dwell():
    """With ZPETC's two-sample dwell before the reference, the drift's clock started at the dwell (an outside probe:
    0.04 µm at the reference's first sample, 100.04 µm at 1 s for 100 µm/s)."""
    from contoursim.compensation import ZPETC

    machine = load_machine("demo_mill")
    path = paths.circle(center=(0.0, 0.0), radius=10.0, direction="ccw")
    reference = sample(path, plan(path, feed=50.0, accel=2000.0), machine.servo_period)
    model = Model(machine, (Effect("thermal_drift", "x", rate_um_per_min=6000.0),))
    for strategies in ((), (ZPETC(),)):
        result = simulate(model, reference, strategies)
        drift = result.static_tool_position[:, 0] - result.axis_command[:, 0]  # mm
        t = result.trajectory.t
        np.testing.assert_allclose(drift[t <= reference.t[0]], 0.0, atol=1e-12)
        at = np.searchsorted(t, reference.t[0] + 1.0)
        assert drift[at] == pytest.approx(0.1 * (t[at] - reference.t[0]), rel=1e-9)


def test_a_machine_without_bodies_takes_each_axis_travel_from_its_axes_table(tmp_path):
    """``travel_mm`` in ``[axes.x]``: the travel a straightness bows over; commands leaving it are refused; the
    trace's coordinates stay the axes' (the path's origin at their zero)."""
    servo = "mass_kg = 300\nforce_constant_N_per_A = 942\nkv_A_s_per_m = 80\nti_s = 0.016\nkp_per_s = 40\n"
    text = f"servo_period_ms = 0.5\n[axes.x]\n{servo}travel_mm = [0, 400]\n[axes.y]\n{servo}"
    (tmp_path / "m.toml").write_text(text)
    machine = load_machine(tmp_path / "m.toml")
    assert machine.travel == {"x": (0.0, 400.0)} and machine.home().tolist() == [0.0, 0.0]
    q = np.array([[0.0, 5.0], [200.0, 5.0], [400.0, 5.0]])
    effect = Effect("straightness", "x", peak_um=6.0, span_mm=400.0, error_direction="y")
    dy = Model(machine, (effect,)).geometry.tool_position(q, np.zeros(3), 2)[:, 1] - q[:, 1]
    np.testing.assert_allclose(1e3 * dy, [0.0, 6.0, 0.0], atol=1e-9)
    line = paths.line((390.0, 0.0), (410.0, 0.0))
    with pytest.raises(ValueError, match=r"axis x would move over 390 \.\. 410, outside its travel 0 \.\. 400 .*: place the path inside"):
        simulate(machine, sample(line, plan(line, feed=50.0, accel=2000.0), 5e-4))
    (tmp_path / "bad.toml").write_text(text.replace("[0, 400]", "[400, 0]"))
    with pytest.raises(ConfigError, match=r"bad.toml, line 8: axis x: travel_mm must be \[min, max\] with min < max"):
        load_machine(tmp_path / "bad.toml")
    bodies = (tmp_path / "bodies.toml")
    bodies.write_text(GROWING_MILL.replace('axis = "x"', 'axis = "x"\ntravel_mm = [0, 300]', 1)
                      .replace("[axes.x]", "[axes.x]\ntravel_mm = [0, 300]", 1))
    with pytest.raises(ConfigError, match=r"axis x: a machine with bodies gives the travel on the axis's \[\[body\]\]"):
        load_model(bodies)


GROWING_MILL = """
name = "growing"
servo_period_ms = 1.0
tool = "tool"
workpiece = "bed"

[axes.x]
mass_kg = 300.0
force_constant_N_per_A = 942.0
kv_A_s_per_m = 80.0

[axes.y]
mass_kg = 300.0
force_constant_N_per_A = 942.0
kv_A_s_per_m = 80.0

[[body]]
name = "X"
joint = "linear x"
axis = "x"
thermal_growth = { dx_ppm_per_min = 2.0 }
thermal_reference_mm = 50

[[body]]
name = "Y"
parent = "X"
joint = "linear y"
axis = "y"

[[body]]
name = "tool"
parent = "Y"

[[effect]]
name = "thermal_drift"
axis = "x"
rate_um_per_min = 1.0
growth_ppm_per_min = 3.0
reference_mm = -100
"""


def test_a_files_thermal_growth_adds_to_the_machines_own_each_from_its_reference(tmp_path):
    """The body's growth (2 ppm/min from 50 mm) and the effect's (3 ppm/min from −100 mm) add exactly (pure translations)."""
    file = tmp_path / "growing.toml"
    file.write_text(GROWING_MILL)
    model = load_model(file)
    assert model.values() == {"thermal_drift.x.rate_um_per_min": 1.0, "thermal_drift.x.time_constant_s": 0.0,
                              "thermal_drift.x.growth_ppm_per_min": 3.0, "thermal_drift.x.reference_mm": -100.0}
    q = np.column_stack([np.linspace(-200.0, 300.0, 11), np.linspace(0.0, 50.0, 11)])
    t = np.linspace(0.0, 600.0, 11)
    moved = model.geometry.tool_position(q, t, 2) - model.geometry.tool_position(q, np.zeros(11), 2)
    x = q[:, 0]
    expected = (1e-3 + 2e-6 * (x - 50.0) + 3e-6 * (x + 100.0)) / 60 * t  # [mm]
    np.testing.assert_allclose(moved[:, 0], expected, rtol=0, atol=1e-13)  # rounding of 300 mm positions
    np.testing.assert_array_equal(moved[:, 1], 0.0)
    with pytest.raises(ValueError, match="body 'X' already drifts with time constant 0 s; a drift with 60 s cannot be added"):
        _ = model.with_values({"thermal_drift.x.time_constant_s": 60.0}).geometry


def test_a_machine_without_bodies_gets_a_cartesian_chain_only_for_geometric_effects():
    assert Model(MACHINE, (Effect("backlash", "x", lost_motion_um=1.0),)).geometry is MACHINE
    geometry = Model(MACHINE, (Effect("squareness", "xy", angle_urad=100.0),)).geometry
    assert geometry.chain.axes == ("x", "y")
    np.testing.assert_allclose(geometry.tool_position(np.array([[10.0, 0.0]]), None, 2), [[10.0, -1e-3]], atol=1e-12)


# -- simulate and simulate_batch ---------------------------------------------------------------


def test_a_machine_is_a_model_without_effects():
    reference = _circle()
    a, b = simulate(MACHINE, reference), simulate(Model(MACHINE), reference)
    assert np.array_equal(a.tool_position, b.tool_position)


def _variants():
    model = Model(MACHINE, (Effect("backlash", "x", lost_motion_um=8.0), Effect("coulomb_friction", "x", force_N=30.0),
                            Effect("gain_mismatch", "y", kp_ratio=0.9), Effect("time_delay", "y", delay_s=1.5e-3),
                            Effect("squareness", "xy", angle_urad=80.0), Effect("cyclic_error", "y", amplitude_um=2.0)))
    steps = {name: 0.1 * abs(p.value) or 10.0 for name, p in model.parameters().items() if p.vary}
    rows = [{}] + [{name: model.parameters()[name].value + step} for name, step in steps.items()]  # a Jacobian's P + 1
    return model.variants(rows), len(steps)


def test_a_batch_row_is_the_single_run_bit_for_bit():
    models, n_params = _variants()
    assert len(models) == n_params + 1 == 8
    reference = _circle()
    batch = simulate_batch(models, reference, outputs=("tool_position", "axis_position"))
    for i, model in enumerate(models):
        single = simulate(model, reference)
        assert np.array_equal(batch["tool_position"][i], single.tool_position), models[i].values()
        assert np.array_equal(batch["axis_position"][i][:, single.machine.servo_columns],
                              single.servo_response.position)
    assert np.array_equal(batch["t"], single.trajectory.t)
    # every parameter moves the result: the Jacobian has no empty column
    assert all(np.abs(batch["tool_position"][i] - batch["tool_position"][0]).max() > 1e-6 for i in range(1, len(models)))


def test_a_decimated_float32_batch_keeps_every_nth_sample():
    models, _ = _variants()
    reference = _circle()
    batch = simulate_batch(models[:3], reference, every=7, dtype=np.float32)
    assert batch["tool_position"].dtype == np.float32
    for i in range(3):
        single = simulate(models[i], reference).tool_position[::7]
        np.testing.assert_allclose(batch["tool_position"][i], single.astype(np.float32), rtol=0, atol=1e-12)


def test_a_batch_is_of_one_structure():
    other = Machine({"x": AxisServo(**AXIS), "y": AxisServo(**AXIS)}, 2 * DT)
    with pytest.raises(ValueError, match=r"models\[1\] has another structure than models\[0\]"):
        simulate_batch([MACHINE, other], _circle())
    with pytest.raises(ValueError, match="outputs must be some of tool_position, axis_position"):
        simulate_batch([MACHINE], _circle(), outputs=("contour",))


# -- a measured reference ----------------------------------------------------------------------


def test_a_measured_reference_at_the_servo_rate_is_taken_as_it_is():
    t = 0.5 + np.arange(200) * DT + 1e-9 * np.sin(np.arange(200))  # a logger's jitter
    x = 5.0 * np.sin(3.0 * t)
    reference = measured_reference(Trace(t, x[:, None], x[:, None], ("x",)), DT)
    assert np.array_equal(reference.position[:, 0], x)
    np.testing.assert_allclose(reference.t, 0.5 + np.arange(200) * DT, rtol=0, atol=1e-12)
    np.testing.assert_allclose(reference.velocity[5:-5, 0], 15.0 * np.cos(3.0 * t[5:-5]), rtol=1e-4)
    np.testing.assert_allclose(reference.acceleration[5:-5, 0], -45.0 * np.sin(3.0 * t[5:-5]), rtol=1e-3)


def test_a_coarser_measured_reference_is_resampled_by_a_cubic_spline():
    t = np.arange(101) * 4 * DT  # logged every 4 ms
    xy = np.column_stack([5.0 * np.cos(2.0 * t), 5.0 * np.sin(2.0 * t)])
    reference = measured_reference(Trace(t, xy, xy, ("x", "y")), DT)
    assert len(reference) == 401 and reference.dt == pytest.approx(DT)
    fine = reference.t
    exact = np.column_stack([5.0 * np.cos(2.0 * fine), 5.0 * np.sin(2.0 * fine)])
    np.testing.assert_allclose(reference.position, exact, atol=1e-8)


@pytest.mark.parametrize("start, every", [(1e7, 2 * DT), (12345678.0, 2 * DT), (0.0, 0.7 * DT)])
def test_a_measured_reference_reaches_the_traces_last_sample_whatever_its_clock_reads(start, every):
    """A clock at 1e7 s holds 2 ns: the periods a trace spans can come out a hair short of a whole number, and a
    logger's samples can fall between servo periods; either way the last sample lies within the simulation, not a
    period's motion past it (a circle cut off in motion was diagnosed differently with its clock shifted)."""
    logged = np.round(start + np.arange(300) * every, 3 if every == 2 * DT else 9)  # as a CSV with ms prints them
    xy = np.column_stack([5.0 * np.cos(20.0 * (logged - start)), 5.0 * np.sin(20.0 * (logged - start))])
    reference = measured_reference(Trace(logged, xy, xy, ("x", "y")), DT / 2)
    assert reference.t[-1] >= logged[-1] - 1e-9
    assert reference.t[-1] < logged[-1] + DT / 2

def test_simulating_a_runs_own_trace_reproduces_the_run():
    """Without feedforward the loops see only positions: a run replayed from its trace is the same run.

    Its contour error, without the path, is the three-point estimate: close to the exact one.
    """
    reference = _circle(radius=5.0)
    run = simulate(MACHINE, reference, settle=0.0)
    replay = simulate(MACHINE, run.to_trace())
    assert replay.trajectory.path is None
    np.testing.assert_allclose(replay.tool_position, run.tool_position, rtol=0, atol=1e-12)
    keep = reference.measuring
    np.testing.assert_allclose(replay.contour.magnitude[keep], run.contour.magnitude[keep], atol=1e-5)


def test_a_measured_single_axis_run_needs_neither_rest_nor_settling(tmp_path):
    t = np.arange(300) * DT
    x = 2.0 * t + 0.1  # moving from the first sample to the last
    result = simulate(Model(Machine({"x": AxisServo(**AXIS)}, DT)), Trace(t, x[:, None], x[:, None], ("x",)))
    assert len(result.trajectory) == 300 and result.contour is None
    assert set(result.summary()) == {"tracking_max_um", "tracking_rms_um", "volumetric_max_um", "volumetric_rms_um"}
    result.save_csv(tmp_path / "run.csv")
    saved = read_trace(tmp_path / "run.csv")
    assert saved.axes == ("x",)
    np.testing.assert_allclose(saved.reference[:, 0], x, rtol=0, atol=1e-6)  # written to the nm


# -- files -------------------------------------------------------------------------------------


def test_effect_tables_are_read_from_a_file():
    toml = TomlFile("job.toml", """
machine = "demo_mill"

[[effect]]
name = "backlash"
axis = "x"
lost_motion_um = 8.0
feedback = "scale"

[[effect]]
name = "squareness"
axis = "xy"
angle_urad = -40
""")
    effects = read_effects(toml)
    assert [e.label for e in effects] == ["backlash.x", "squareness.xy"]
    assert effects[0].options["feedback"] == "scale" and effects[1]["angle_urad"] == -40.0


@pytest.mark.parametrize("body, message", [
    ('name = "ballscrew"\naxis = "x"', "line 3: unknown effect 'ballscrew'; the effects are: backlash,"),
    ('name = "backlash"\naxis = "x"\nlost_motion = 8',
     r"line 5: .*unknown parameter 'lost_motion' \(did you mean 'lost_motion_um'\?\); its parameters are lost_motion_um, feedback"),
    ('name = "backlash"\naxis = "x"\nlost_motion_um = -8', r"line 5: .*lost_motion_um must lie in \[0, 1000\] µm"),
    ('name = "backlash"\nlost_motion_um = 8', r"line 2: \[\[effect\]\] needs 'axis'"),
    # was the table's line 2, the other keys' at their own (a corrected model edited by hand)
    ('name = "backlash"\naxis = "X"\nlost_motion_um = 8', r"line 4: \[\[effect\]\] backlash: axis must be one axis "
                                                           r"letter of x, y, z, got 'X'"),
    ('name = "time_delay"\naxis = "x"\ndelay_s = 1e-3\nkind = "velocity"',
     "line 6: .*kind must be one of 'command', 'feedback', 'position', got 'velocity'"),
])
def test_a_bad_effect_table_names_the_file_and_line(body, message):
    with pytest.raises(ConfigError, match="job.toml, " + message):
        read_effects(TomlFile("job.toml", "\n[[effect]]\n" + body + "\n"))


def test_a_machine_file_with_effects_loads_as_a_model(tmp_path):
    text = preset_file("demo_mill").read_text()
    file = tmp_path / "mill.toml"
    file.write_text(text + '\n[[effect]]\nname = "gain_mismatch"\naxis = "y"\nkp_ratio = 0.8\n')
    model = load_model(file)
    assert model.values() == {"gain_mismatch.y.kp_ratio": 0.8}
    with pytest.raises(ConfigError, match="has \\[\\[effect\\]\\] tables: load it with contoursim.model.load_model"):
        load_machine(file)
    file.write_text(text + '\n[[effect]]\nname = "backlash"\naxis = "w"\nlost_motion_um = 1\n')
    with pytest.raises(ConfigError, match="mill.toml, line .*axis must be one axis letter of x, y, z, got 'w'"):
        load_model(file)


def test_a_machine_files_backlash_reads_where_the_file_says_its_axis_reads(tmp_path):
    """A file whose X says position_feedback = "scale" and whose backlash on X says feedback = "motor" ran as if X
    read on its motor, silently: refused, naming both lines. Left out or the same, the backlash reads on the scale;
    on Y, which the file does not say (the motor by default), a backlash read on a scale (a diagnosis's hypothesis)
    makes Y read there."""
    text = preset_file("demo_mill").read_text()
    header = text.splitlines().index(next(s for s in text.splitlines() if s.startswith("[axes.x]")))
    text = text.replace("[axes.x]", '[axes.x]\nposition_feedback = "scale"', 1)
    file = tmp_path / "mill.toml"

    def with_backlash(axis, feedback=""):
        file.write_text(text + f'\n[[effect]]\nname = "backlash"\naxis = "{axis}"\nlost_motion_um = 5\n{feedback}\n')
        return load_model(file)

    effect_line = text.count("\n") + 6  # the feedback line of the [[effect]] appended
    with pytest.raises(ConfigError, match=rf"mill\.toml, line {effect_line}: backlash\.x: feedback = 'motor', but this "
                                          rf"file's axis x says where its position loop reads: position_feedback = "
                                          rf"'scale' \(line {header + 2}\); .* leave feedback out"):
        with_backlash("x", 'feedback = "motor"')
    for given in ("", 'feedback = "scale"'):
        model = with_backlash("x", given)
        assert model.effects[0].options["feedback"] == model.machine.axes["x"].position_feedback == "scale"
    model = with_backlash("y", 'feedback = "scale"')
    assert model.machine.axes["y"].position_feedback == "scale" and model.effects[0].options["feedback"] == "scale"


def test_a_machine_files_axis_tables_in_any_order_are_its_axes_x_y_z(tmp_path):
    """TOML's tables have no order: a file with [axes.y] before [axes.x] was refused ('axes x, y (, z) in that
    order, got ('y', 'x')')."""
    file = tmp_path / "yx.toml"
    body = "mass_kg = 300\nforce_constant_N_per_A = 942\nkv_A_s_per_m = 80\nti_s = 0.016\nkp_per_s = {kp}\n"
    file.write_text('name = "yx"\nservo_period_ms = 0.5\n\n[axes.y]\n' + body.format(kp=35) + "\n[axes.x]\n"
                    + body.format(kp=40))
    machine = load_machine(file)
    assert tuple(machine.axes) == ("x", "y") and (machine.axes["x"].kp, machine.axes["y"].kp) == (40.0, 35.0)


@pytest.mark.parametrize("kind, delay_on", [("feedback", "both"), ("position", "position")])
def test_a_feedback_delay_of_a_machine_file_reaches_the_loops_it_names(tmp_path, kind, delay_on):
    # kind = "position": the position loop alone reads late (LoopEffects.feedback_delay_on), "feedback" both loops
    text = preset_file("demo_mill").read_text()
    file = tmp_path / "mill.toml"
    file.write_text(text + f'\n[[effect]]\nname = "time_delay"\naxis = "y"\ndelay_s = 1e-3\nkind = "{kind}"\n')
    model = load_model(file)
    q = np.ones((3, len(model.machine.axis_names)))
    assert model.effects[0].stage == "loop" and model.commands(q, q, q)[0] is q  # the commands are not delayed
    loop = model.loop_effects()
    assert (loop["y"].feedback_delay_s, loop["y"].feedback_delay_on) == (1e-3, delay_on)
    assert loop["x"] == LoopEffects()


def test_thermal_drift_runs_from_the_start_of_a_measured_run():
    t = 100.0 + np.arange(300) * DT  # the logger's clock started long before
    xy = np.column_stack([2.0 * (t - t[0]), np.zeros_like(t)])
    model = Model(MACHINE, (Effect("thermal_drift", "y", rate_um_per_min=60.0),))
    result = simulate(model, Trace(t, xy, xy, ("x", "y")))
    np.testing.assert_allclose(result.tool_position[:, 1], 1e-3 * (t - t[0]), rtol=1e-12, atol=1e-15)


def test_the_command_line_runs_a_jobs_effects(tmp_path, capsys):
    from contoursim.cli import main

    job = tmp_path / "job.toml"
    job.write_text('machine = "demo_mill"\npath = "iso230_4_circle_ccw"\n')
    assert main(["simulate", str(job), "--out", str(tmp_path / "plain")]) == 0
    plain = capsys.readouterr().out
    job.write_text(job.read_text() + '\n[[effect]]\nname = "squareness"\naxis = "xy"\nangle_urad = 200.0\n')
    assert main(["simulate", str(job), "--out", str(tmp_path / "skewed")]) == 0
    skewed = capsys.readouterr().out
    assert "effects: none" in plain and "effects: squareness.xy (angle_urad = 200)" in skewed
    volumetric = [float(out.splitlines()[3].split()[-1]) for out in (plain, skewed)]
    assert volumetric == [0.0, pytest.approx(200e-6 * 50.0 * 1e3, rel=1e-6)]  # |(0, −αx)| at x = ±R = 50 mm [µm]
    grows = tmp_path / "grows.toml"
    grows.write_text(job.read_text() + '\n[[effect]]\nname = "thermal_drift"\naxis = "x"\nrate_um_per_min = 0\n'
                     'growth_ppm_per_min = 2\n\n[[effect]]\nname = "backlash"\naxis = "y"\nlost_motion_um = 8\n'
                     'feedback = "motor"\n')  # fmt: skip
    assert main(["simulate", str(grows), "--out", str(tmp_path / "grows")]) == 0
    assert ("thermal_drift.x (rate_um_per_min = 0, growth_ppm_per_min = 2); backlash.y (lost_motion_um = 8, "
            "feedback = 'motor')") in capsys.readouterr().out  # the values set, not the defaults
    job.write_text(job.read_text() + '\n[[effect]]\nname = "backlash"\naxis = "x"\nlost_motion_um = 8\nfeedback = "linear"\n')
    assert main(["simulate", str(job), "--out", str(tmp_path / "bad")]) == 2
    assert f"{job}, line 13: [[effect]] backlash.x: feedback must be one of 'motor', 'scale'" in capsys.readouterr().err


def test_a_batch_on_a_coarser_trace_returns_the_traces_instants():
    t = 2.0 + np.arange(200) * 5 * DT  # logged every fifth servo period
    xy = np.column_stack([3.0 * np.cos(t), 3.0 * np.sin(t)])
    trace = Trace(t, xy, xy, ("x", "y"))
    batch = simulate_batch([MACHINE, Model(MACHINE, (Effect("backlash", "x", lost_motion_um=5.0),))], trace, every=5)
    np.testing.assert_allclose(batch["t"], t, rtol=0, atol=1e-9)
    single = simulate(MACHINE, trace)
    assert np.array_equal(batch["tool_position"][0], single.tool_position[::5])


@pytest.mark.parametrize("name", effect_names())
def test_every_effect_is_realised_by_its_stage(name):
    size = effect_kind(name).parameters[0]
    effect = Effect(name, "xy" if name == "squareness" else "y", **{size.name: size.typical[1]})
    model = Model(MACHINE, (effect,))
    q = np.column_stack([np.linspace(0, 1, 20), np.linspace(0, 2, 20)])
    changed = {
        "command": lambda: not np.array_equal(model.commands(q, q, q)[0], q),
        "servo": lambda: model.servos() != dict(MACHINE.axes),
        "loop": lambda: model.loop_effects()["y"] != model.loop_effects()["x"],
        "geometry": lambda: not np.array_equal(model.geometry.tool_position(q, np.arange(20.0), 2), q),
    }
    assert changed[effect.stage]()


def test_geometric_effects_change_only_the_body_of_their_axis():
    machine = load_machine("vertical_mill_3axis")
    model = Model(machine, (Effect("straightness", "z", peak_um=3.0),))
    assert model.effects[0].options["error_direction"] == "x"  # the default: the first other axis
    changed = [a.name for a, b in zip(machine.chain.bodies, model.geometry.chain.bodies) if a is not b]
    assert changed == ["Z"]
    assert model.geometry.chain.bodies[4].motion[0].poly != machine.chain.bodies[4].motion[0].poly


def test_a_batch_reports_an_unstable_variant_and_runs_the_others():
    model = Model(MACHINE, (Effect("gain_mismatch", "x", kp_ratio=1.0), Effect("squareness", "xy", angle_urad=50.0),
                            Effect("time_delay", "x", delay_s=5e-3, kind="feedback")))
    variants = model.variants([{"time_delay.x.delay_s": 0.0}, {"gain_mismatch.x.kp_ratio": 10.0}])
    reference = _circle(feed=10.0)  # 8,000 steps: the unstable loop (|λ| = 1.15) overflows
    batch = simulate_batch(variants, reference)
    assert batch["diverged_step"][0].tolist() == [-1, -1]
    assert batch["diverged_step"][1, 0] > 0 and batch["diverged_step"][1, 1] == -1
    assert np.isnan(batch["tool_position"][1]).all()
    assert np.array_equal(batch["tool_position"][0], simulate(variants[0], reference).tool_position)


def test_a_jobs_effects_add_to_and_replace_the_machine_files(tmp_path):
    from contoursim.model import with_file_effects

    text = preset_file("demo_mill").read_text()
    file = tmp_path / "mill.toml"
    file.write_text(text + '\n[[effect]]\nname = "backlash"\naxis = "x"\nlost_motion_um = 4\n'
                    '\n[[effect]]\nname = "scale_error"\naxis = "y"\nppm = 20\n')
    job = TomlFile("job.toml", '[[effect]]\nname = "backlash"\naxis = "x"\nlost_motion_um = 9\n'
                               '\n[[effect]]\nname = "noise"\naxis = "z"\nrms_um = 0.2\n')
    model = with_file_effects(load_model(file), job)
    assert model.values() == {"scale_error.y.ppm": 20.0, "backlash.x.lost_motion_um": 9.0, "noise.z.rms_um": 0.2}


def test_a_position_parameter_holds_any_position_a_trace_or_a_travel_may_have():
    """A trace 100 m from its axes' zero (within a trace's ±1e6 mm) ended its diagnosis in an error: the straightness
    candidate over its extent had start_mm = -100043, beyond the effect's ±1e5 mm."""
    from contoursim.multibody import MAX_TRAVEL
    from contoursim.traces import MAX_POSITION

    def bounds(effect, name):
        return next(p.bounds for p in effect_kind(effect).parameters if p.name == name)

    reach = max(MAX_POSITION, MAX_TRAVEL)
    for effect, name in (("straightness", "start_mm"), ("thermal_drift", "reference_mm")):
        assert bounds(effect, name)[0] <= -reach and bounds(effect, name)[1] >= reach
    assert bounds("straightness", "span_mm")[1] >= 2 * reach
    Effect("straightness", "y", peak_um=1.0, span_mm=300.0, start_mm=-100043.0, error_direction="x")
