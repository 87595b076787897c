"""Compensation strategies against python-control, Koren's steady state and Tomizuka's zero phase."""

import control as ct
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.optimize import brentq

from contoursim import compensation as cp
from contoursim import kernel, paths
from contoursim.exceptions import UnstableLoopError
from contoursim.feed import plan, sample
from contoursim.effects import Effect
from contoursim.machine import Machine
from contoursim.model import Model
from contoursim.servo import AxisServo
from contoursim.simulation import simulate

DT = 2e-4
AXIS = dict(mass=300.0, force_constant=942.0, kv=80.0, ti=0.016, damping=500.0)


def _line_reference(angle, speed, n_steps):
    """A ramp at `speed` [mm/s] along `angle` from the origin: positions, velocities, accelerations."""
    t = np.arange(n_steps) * DT
    direction = np.array([np.cos(angle), np.sin(angle)])
    return speed * t[:, None] * direction, np.tile(speed * direction, (n_steps, 1)), np.zeros((n_steps, 2))


def _python_control_coupled_loop(servos, normal, kp, ki, kd):
    """Both axes' sampled cascades (python-control) with Koren's PID coupling across a line, wired by name.

    The axes have vff = 1, so their ``v_ref`` input is the velocity command:
    the coupling's output is added to the reference velocity there.
    """
    blocks = []
    for axis, servo in servos.items():
        loop = servo.discretize(DT).closed_loop
        blocks.append(ct.ss(loop.A, loop.B, loop.C, loop.D, DT, inputs=[f"r{axis}", f"vc{axis}", f"a{axis}"],
                            outputs=[f"x{axis}", f"v{axis}", f"i{axis}"], name=f"axis_{axis}"))
        blocks.append(ct.summing_junction([f"vr{axis}", f"w{axis}"], f"vc{axis}", dt=DT, name=f"sum_{axis}"))
    # ε = n·(x - r); states: integral of ε, previous ε; u = kp ε + ki (z + dt/2 ε) + kd (ε - ε_prev)/dt; w = -n u
    n = np.asarray(normal)
    eps = np.concatenate([n, -n])  # over inputs x_x, x_y, r_x, r_y
    A = np.array([[1.0, 0.0], [0.0, 0.0]])
    B = np.vstack([DT * eps, eps])
    c_u = np.array([[ki, -kd / DT]])
    d_u = (kp + ki * DT / 2 + kd / DT) * eps[None, :]
    coupling = ct.ss(A, B, -n[:, None] * c_u, -n[:, None] * d_u, DT, inputs=["xx", "xy", "rx", "ry"],
                     outputs=["wx", "wy"], name="coupling")
    inputs = ["rx", "ry", "vrx", "vry", "ax", "ay"]
    return ct.interconnect(blocks + [coupling], inplist=inputs, inputs=inputs, outlist=["xx", "xy"],
                           outputs=["xx", "xy"], ignore_outputs=["vx", "vy", "ix", "iy"])


def test_coupled_loop_equals_python_control_interconnection():
    servos = {"x": AxisServo(kp=40.0, vff=1.0, **AXIS), "y": AxisServo(kp=30.0, vff=1.0, **AXIS)}
    angle, kp, ki, kd = np.radians(30.0), 60.0, 2000.0, 0.05
    ref = _line_reference(angle, 50.0, 3000)
    ref[1][:200] = 0.0  # the velocity feedforward starts late: a contour error to correct
    normal = np.array([-np.sin(angle), np.cos(angle)])  # left of travel
    coupled = kernel.run(servos, DT, *ref, coupling=kernel.Coupling("linear", ref[0], kp, ki, kd))
    system = _python_control_coupled_loop(servos, normal, kp, ki, kd)
    u = np.column_stack([ref[0], ref[1], ref[2]]).T
    expected = ct.forced_response(system, np.arange(len(ref[0])) * DT, u).outputs.T
    plain = kernel.run(servos, DT, *ref)
    assert np.abs(plain.position @ normal).max() > 1e-3  # the coupling has something to do
    np.testing.assert_allclose(coupled.position, expected, rtol=0, atol=1e-9)
    # the linear check is the same loop's largest pole
    rows = [kernel.pack(servo, DT) for servo in servos.values()]
    assert cp.coupled_spectral_radius(rows, kp, ki, kd, DT, normal) == pytest.approx(
        np.abs(system.poles()).max(), rel=1e-9)


@pytest.mark.parametrize("estimator", ["linear", "arc"])
def test_koren_integral_coupling_removes_the_steady_contour_error_on_a_45_degree_line(estimator):
    """Mismatched position gains skew the lag off the line: v·(1/kp_y - 1/kp_x)·sin 45°·cos 45°.

    The integrating coupling drives the contour error to zero while the
    tracking error (the lag along the line, v/kp) stays.
    """
    kp_x, kp_y, speed = 40.0, 30.0, 50.0
    servos = {"x": AxisServo(kp=kp_x, **AXIS), "y": AxisServo(kp=kp_y, **AXIS)}
    ref = _line_reference(np.pi / 4, speed, 15000)
    normal = np.array([-1.0, 1.0]) / np.sqrt(2)
    plain = kernel.run(servos, DT, *ref)
    coupling = cp.CrossCoupled(estimator, kp=40.0, ki=400.0).coupling(ref[0], servos, DT)
    coupled = kernel.run(servos, DT, *ref, coupling=coupling)
    skew = speed * (1 / kp_y - 1 / kp_x) / 2  # |n·e| in steady state without coupling [mm]
    assert np.abs((plain.position - ref[0])[-1] @ normal) == pytest.approx(skew, rel=1e-3)
    assert np.abs((coupled.position - ref[0])[-1] @ normal) < 1e-6 * skew
    tracking = np.linalg.norm(coupled.position[-1] - ref[0][-1])
    assert tracking > 0.5 * speed / kp_x  # the lag along the line stays


def test_proportional_coupling_only_shrinks_the_steady_contour_error():
    servos = {"x": AxisServo(kp=40.0, **AXIS), "y": AxisServo(kp=30.0, **AXIS)}
    ref = _line_reference(np.pi / 4, 50.0, 15000)
    normal = np.array([-1.0, 1.0]) / np.sqrt(2)
    coupling = cp.CrossCoupled("linear", kp=40.0, ki=0.0).coupling(ref[0], servos, DT)
    plain, coupled = kernel.run(servos, DT, *ref), kernel.run(servos, DT, *ref, coupling=coupling)
    before, after = (abs((r.position[-1] - ref[0][-1]) @ normal) for r in (plain, coupled))
    assert 0.1 * before < after < 0.9 * before


def _circle_machine_and_trajectory(feed=100.0):
    machine = Machine({"x": AxisServo(kp=40.0, **AXIS), "y": AxisServo(kp=36.0, **AXIS)}, DT)
    path = paths.circle(center=(0, 0), radius=10.0, direction="ccw", start_angle=0.0)
    return machine, sample(path, plan(path, feed=feed, accel=2000.0, jerk=50000.0), DT)


def test_zpetc_tracking_error_falls_by_orders_of_magnitude():
    machine, trajectory = _circle_machine_and_trajectory()
    none = simulate(machine, trajectory).summary()
    zpetc = simulate(machine, trajectory, [cp.ZPETC()]).summary()
    assert zpetc["tracking_max_um"] < 1e-3 * none["tracking_max_um"]
    assert zpetc["contour_max_um"] < 1e-2 * none["contour_max_um"]


def test_zpetc_error_on_a_circle_is_the_filters_steady_state():
    """At the circle's frequency ω = v/R the loop with its pre-filter is a real gain H_a per axis (zero phase):
    the axis draws R·H_a·cos, R·H_a·sin, so the tracking error is R·(H_a − 1) along each axis and the radial
    error R·((H_x − 1)·cos²θ + (H_y − 1)·sin²θ). H_a from the filter's polynomials times python-control's
    response of the sampled loop. The dwell at the start while the filter fills leaves no start-up error:
    the max contour error over the whole circle is the steady state's."""
    servos = {"x": AxisServo(kp=40.0, **AXIS), "y": AxisServo(kp=36.0, **AXIS)}
    radius, feed = 50.0, 250.0
    circle = paths.circle(center=(0, 0), radius=radius, direction="ccw", start_angle=0.0)
    result = simulate(Machine(servos, DT), sample(circle, plan(circle, feed=feed, accel=5000.0, jerk=2e5), DT),
                      [cp.ZPETC()])
    omega, gain = feed / radius, {}
    for axis, servo in servos.items():
        den, num, fir, delay = cp._zpetc_filter(servo, DT)
        z = np.exp(1j * omega * DT)
        filt = np.polyval(num[::-1], 1 / z) / np.polyval(den[::-1], 1 / z) * np.polyval(fir[::-1], z) * z**delay
        loop = servo.discretize(DT).closed_loop
        G = ct.frequency_response(ct.ss(loop.A, loop.B[:, [0]], loop.C[[0]], loop.D[[0]][:, [0]], DT), [omega])
        gain[axis] = (G.complex.ravel()[0] * filt).real
    steady = np.flatnonzero(np.abs(result.trajectory.speed - feed) < 1e-9 * feed)
    keep = slice(steady[0] + 1500, steady[-1])  # 0.3 s after the feed is reached: the ramp's transient is gone
    reference = result.trajectory.position[keep]
    theta = np.arctan2(reference[:, 1], reference[:, 0])
    expected = radius * np.column_stack([(gain["x"] - 1) * np.cos(theta), (gain["y"] - 1) * np.sin(theta)])
    assert np.abs(expected).max() > 1e-5  # 0.0125 µm: something to predict
    np.testing.assert_allclose(result.tracking_error[keep], expected, rtol=0, atol=1e-3 * np.abs(expected).max())
    radial = radius * ((gain["x"] - 1) * np.cos(theta) ** 2 + (gain["y"] - 1) * np.sin(theta) ** 2)
    np.testing.assert_allclose(result.contour.normal[keep], -radial, rtol=1e-3)  # normal: positive to the left, inwards
    assert result.summary()["contour_max_um"] == pytest.approx(1e3 * np.abs(radial).max(), rel=1e-3)
    assert np.array_equal(result.servo_response.position[0], result.trajectory.position[0])  # the first command: the start
    preview = cp.ZPETC().preview(servos, DT)
    assert preview == 2 and not result.trajectory.measuring[:preview].any()  # the dwell while the filter fills
    assert result.trajectory.t[preview] == 0.0 and not result.trajectory.velocity[:preview].any()


@pytest.mark.parametrize("velocity_loop", [dict(ti=AXIS["ti"]), dict(ti=None)], ids=["PI", "P"])
def test_zpetc_times_the_python_control_loop_has_zero_phase_and_unit_dc_gain(velocity_loop):
    """Also on a P velocity loop, whose sampled closed loop has no zeros at all (no polynomial to cancel)."""
    servo = AxisServo(kp=40.0, **(AXIS | velocity_loop))
    den, num, fir, delay = cp._zpetc_filter(servo, DT)
    omega = np.linspace(1.0, 0.9 * np.pi / DT, 200)
    z = np.exp(1j * omega * DT)
    filt = (np.polyval(num[::-1], 1 / z) / np.polyval(den[::-1], 1 / z)) * np.polyval(fir[::-1], z) * z**delay
    loop = servo.discretize(DT).closed_loop
    G = ct.frequency_response(ct.ss(loop.A, loop.B[:, [0]], loop.C[[0]], loop.D[[0]][:, [0]], DT), omega)
    product = G.complex.ravel() * filt
    np.testing.assert_allclose(product.imag, 0.0, atol=1e-9)
    assert product.real.min() > 0.0
    assert product[0].real == pytest.approx(1.0, abs=1e-6)


def test_feedforward_sets_the_drive_gains_from_its_model():
    servo = AxisServo(kp=40.0, **AXIS)
    heavier = AxisServo(kp=40.0, **{**AXIS, "mass": 1.1 * AXIS["mass"]})
    driven = cp.Feedforward(model={"x": servo}).drive({"x": heavier})["x"]
    assert driven.vff == 1.0 and driven.aff == pytest.approx(1 / 1.1)
    with pytest.raises(ValueError, match="acceleration feedforward would be 1.1 > 1"):
        cp.Feedforward(model={"x": heavier}).drive({"x": servo})


def _damping(poles):
    """Smallest damping ratio of sampled poles, from s = ln(z)/dt (z = 0: a pure delay, left out)."""
    s = np.log(poles[np.abs(poles) > 1e-12].astype(complex)) / DT
    s = s[np.abs(s) > 0]
    return float(np.min(-s.real / np.abs(s)))


def test_designed_coupling_gains_damp_the_sampled_coupled_loop_at_the_stated_ratio():
    """python-control's poles of the two sampled cascades with the coupling closed: ζ = 0.7 at the design, on the worst line."""
    servos = {"x": AxisServo(kp=40.0, vff=1.0, **AXIS), "y": AxisServo(kp=36.0, vff=1.0, **AXIS)}
    kp, ki, kd = cp.CrossCoupled().gains(servos, DT)
    assert ki == pytest.approx((36.0 + kp) ** 2 / 4) and kd == 0.0

    def worst(kp):
        angles = np.radians(np.arange(0.0, 180.0, 15.0))
        ki = (36.0 + kp) ** 2 / 4
        return min(_damping(_python_control_coupled_loop(servos, (np.cos(a), np.sin(a)), kp, ki, 0.0).poles())
                   for a in angles)

    assert cp.DESIGN_DAMPING_RATIO == 0.7
    assert worst(kp) == pytest.approx(0.7, abs=1e-5)
    assert worst(1.01 * kp) < 0.7 - 1e-4  # the largest gain that keeps it
    slow = {"x": servos["x"], "y": AxisServo(kp=36.0, **{**AXIS, "kv": 60.0})}  # its own loop: ζ = 0.68
    with pytest.raises(ValueError, match=r"damped at 0.682 < 0.7 even with kp = 0.36 1/s.*set the coupling gains"):
        cp.CrossCoupled().gains(slow, DT)
    assert cp.CrossCoupled(kp=50.0).gains(slow, DT) == (50.0, 86.0**2 / 4, 0.0)


def test_designed_coupling_gains_for_drives_that_filter_their_velocity_difference():
    """Two-tap velocity filters (as the EMPS drive's) add alternating poles near z = -0.1 to each axis's own loop,
    damped at 0.6 by the ratio's formula but settled within a servo period: the design holds the 0.7 on the poles
    that last (python-control's, |z| > 1/e), where it used to refuse the axes outright."""
    servos = {a: AxisServo(kp=kp, vff=1.0, velocity_feedback="difference", velocity_taps=2, **AXIS)
              for a, kp in (("x", 40.0), ("y", 36.0))}
    kp, ki, kd = cp.CrossCoupled().gains(servos, DT)
    angles = np.radians(np.arange(0.0, 180.0, 15.0))
    poles = [_python_control_coupled_loop(servos, (np.cos(a), np.sin(a)), kp, ki, kd).poles() for a in angles]
    fast = np.concatenate([p[(np.abs(p) <= np.exp(-1.0)) & (np.abs(p) > 1e-12)] for p in poles])
    assert fast.size and _damping(fast) < 0.7  # the filter's poles, which the ratio alone would count
    assert min(_damping(p[np.abs(p) > np.exp(-1.0)]) for p in poles) == pytest.approx(0.7, abs=1e-5)
    # the ζ given of the coupled loop (compare's table) and of each axis's own is the design's: 0.6 said "designed
    # for ζ = 0.7" beside 0.60
    theta = np.linspace(0.0, 2 * np.pi, 721)  # a circle: every direction of the normal, binned at 5°
    circle = 10.0 * np.column_stack([np.cos(theta), np.sin(theta)])
    assert cp.CrossCoupled().margins(circle, servos, DT)["damping_ratio"] == pytest.approx(0.7, abs=1e-3)
    for servo in servos.values():
        own = servo.discretize(DT).closed_loop.poles()
        assert servo.margins(DT)["position"]["damping_ratio"] == pytest.approx(_damping(own[np.abs(own) > np.exp(-1.0)]))


def test_coupled_margins_equal_python_control_on_the_loop_gain():
    """Phase margin and damping of the coupled loop across a line, from python-control's loop gain C(z)·Σ n_a² G_a(z)."""
    servos = {"x": AxisServo(kp=40.0, vff=1.0, **AXIS), "y": AxisServo(kp=30.0, vff=1.0, **AXIS)}
    kp, ki, kd, angle = 150.0, 9000.0, 0.02, np.radians(30.0)
    normal = np.array([-np.sin(angle), np.cos(angle)])
    plants = []
    for servo in servos.values():  # velocity command -> position (vff = 1: the v_ref input is the velocity command)
        loop = servo.discretize(DT).closed_loop
        plants.append(ct.ss(loop.A, loop.B[:, [1]], loop.C[[0]], loop.D[[0]][:, [1]], DT))
    z = ct.tf([1, 0], [1], DT)
    pid = kp + ki * DT / 2 * (z + 1) / (z - 1) + kd / DT * (1 - 1 / z)
    gain = ct.ss(pid) * (normal[0] ** 2 * plants[0] + normal[1] ** 2 * plants[1])
    gm, pm, _, _, wg, _ = ct.stability_margins(gain, method="frd")  # on a grid: refined below
    response = lambda w: complex(gain(np.exp(1j * w * DT)))  # noqa: E731
    wg = brentq(lambda w: abs(response(w)) - 1.0, 0.9 * wg, 1.1 * wg, xtol=1e-12)
    pm = 180.0 + np.degrees(np.angle(response(wg)))
    rows = [kernel.pack(servo, DT) for servo in servos.values()]
    m = cp.coupled_margins(rows, kp, ki, kd, DT, [normal])
    assert m["phase_margin"] == pytest.approx(pm, abs=1e-6) and m["gain_crossover"] == pytest.approx(wg, rel=1e-9)
    assert m["gain_margin"] == pytest.approx(gm, rel=1e-3)
    assert m["damping_ratio"] == pytest.approx(_damping(ct.feedback(gain, 1).poles()), abs=1e-9)
    assert m["spectral_radius"] == pytest.approx(cp.coupled_spectral_radius(rows, kp, ki, kd, DT, normal), rel=1e-12)


def test_path_frames_are_the_normals_the_path_takes():
    circle = paths.circle(center=(0, 0), radius=10.0, direction="ccw", start_angle=0.0)
    trajectory = sample(circle, plan(circle, feed=100.0, accel=2000.0, jerk=50000.0), DT)
    frames = cp.path_frames(trajectory.position)
    assert len(frames) == 36  # every 5° bin of the normal's direction (mod 180°) once
    for sample_index, normals in frames:
        radial = trajectory.position[sample_index] / 10.0
        assert abs(abs(normals[0] @ radial) - 1.0) < 1e-6  # the normal of a circle is radial
    line = np.column_stack([np.linspace(0.0, 10.0, 500), np.linspace(0.0, 5.0, 500)])
    (_, normals), = cp.path_frames(line)
    np.testing.assert_allclose(abs(normals[0] @ np.array([2.0, 1.0]) / np.sqrt(5.0)), 0.0, atol=1e-12)


def test_strategies_compose_and_refuse_two_of_a_kind():
    machine, trajectory = _circle_machine_and_trajectory()
    both = simulate(machine, trajectory, cp.strategies_named("feedforward+ccc_arc")).summary()
    ff = simulate(machine, trajectory, cp.strategies_named("feedforward")).summary()
    assert both["contour_max_um"] < 0.5 * ff["contour_max_um"]
    with pytest.raises(ValueError, match="feedforward and zpetc are both a feedforward"):
        cp.strategies_named("feedforward+zpetc")
    with pytest.raises(ValueError, match="ccc_linear and ccc_arc are both a coupling"):
        cp.Composition([cp.CrossCoupled("linear"), cp.CrossCoupled("arc")])
    with pytest.raises(ValueError, match="unknown strategy 'pid'"):
        cp.strategies_named("none+pid")
    with pytest.raises(TypeError, match=r"strategies\[0\] must be a compensation Strategy"):
        simulate(machine, trajectory, ["ccc_arc"])
    assert [cp.Composition(cp.strategies_named(name)).name for name in cp.STRATEGY_NAMES] == list(cp.STRATEGY_NAMES)


def test_cross_coupling_needs_two_axes():
    with pytest.raises(ValueError, match=r"^ccc_arc: cross-coupled control needs 2 or 3 servo axes, the machine has 1 \(x\)"):
        cp.CrossCoupled().coupling(np.zeros((10, 1)), {"x": AxisServo(kp=40.0, **AXIS)}, DT)


def _helix_machine_and_trajectory():
    axes = {"x": AxisServo(kp=40.0, **AXIS), "y": AxisServo(kp=36.0, **AXIS), "z": AxisServo(kp=30.0, **AXIS)}
    path = paths.helix(center=(0, 0, 0), radius=10.0, pitch=5.0, turns=1.0)
    return Machine(axes, DT), sample(path, plan(path, feed=50.0, accel=1000.0, jerk=50000.0), DT)


def test_arc_coupling_in_3d_corrects_the_out_of_plane_part_and_estimates_as_offline():
    from contoursim import estimators as est

    machine, trajectory = _helix_machine_and_trajectory()
    none = simulate(machine, trajectory)
    coupled = simulate(machine, trajectory, [cp.CrossCoupled("arc")])
    measuring = none.trajectory.measuring  # with the settling time held at the end
    for part in ("out_of_plane", "normal"):  # both components of the error vector fall
        before = np.abs(getattr(none.contour, part)[measuring]).max()
        after = np.abs(getattr(coupled.contour, part)[measuring]).max()
        assert before > 1e-3 and after < 0.4 * before  # at the gains designed for ζ = 0.7 (0.33 of it)
    response = coupled.servo_response
    offline = est.three_point(coupled.axis_command, response.encoder)
    np.testing.assert_allclose(response.contour_estimate, offline.vector, rtol=0, atol=1e-15)
    assert np.abs(offline.out_of_plane).max() > 1e-5  # the vector has an out-of-plane part


def test_batch_applies_the_drive_and_prefilter_stages_like_simulate():
    from contoursim.simulation import simulate_batch

    machine, trajectory = _circle_machine_and_trajectory()
    for strategies in ([cp.Feedforward()], [cp.ZPETC()]):
        single = simulate(machine, trajectory, strategies).tool_position
        batch = simulate_batch([machine], trajectory, strategies=strategies)["tool_position"][0]
        np.testing.assert_array_equal(batch, single)
    noisy = Model(machine, (Effect("noise", "y", rms_um=0.1, at="encoder"),))
    with pytest.raises(ValueError, match=r"simulate_batch runs no noise on the encoder \(models\[0\] axis y\)"):
        simulate_batch([noisy], trajectory)


def test_the_coupling_closes_on_the_noisy_encoder():
    """With the noise on the encoder, the coupling's estimate is that of the noisy reading, not of the axis."""
    from contoursim import estimators as est

    machine, trajectory = _circle_machine_and_trajectory()
    noisy = Model(machine, (Effect("noise", "x", rms_um=0.1, seed=1, at="encoder"),
                            Effect("noise", "y", rms_um=0.1, seed=2, at="encoder")))
    result = simulate(noisy, trajectory, [cp.CrossCoupled("arc")])
    response = result.servo_response
    read = response.encoder - response.position
    assert np.sqrt(np.mean(read**2)) == pytest.approx(1e-4, rel=0.05)  # 0.1 µm RMS on what the loop reads
    offline = est.three_point(result.axis_command, response.encoder)
    np.testing.assert_allclose(response.contour_estimate[:, :2], offline.vector, rtol=0, atol=1e-15)


def test_tune_keeps_the_best_candidate_the_check_lets_run():
    from contoursim.comparison import TUNE_KP_STEP, tune

    machine, trajectory = _circle_machine_and_trajectory()
    tuned = tune(machine, trajectory, "ccc_arc")
    errors = [error for _, _, error in tuned["tried"] if error is not None]
    assert tuned["max_contour_um"] == min(errors)
    assert tuned["tried"][-6][2] is None  # the kp search ran up to the first gain the check refuses ...
    refused_kp = tuned["tried"][-6][0]
    assert tuned["tried"][-7][0] == pytest.approx(refused_kp / TUNE_KP_STEP)  # ... one step above the last it let run
    assert set(tuned["settings"]["ccc_arc"]) == {"kp_per_s", "ki_per_s2"}  # the keys of the job file and the JSON
    again = simulate(machine, trajectory, cp.strategies_named("ccc_arc", settings=tuned["settings"])).summary()["contour_max_um"]
    assert again == tuned["max_contour_um"]  # the tuned gains run, and give what the search saw
    designed = simulate(machine, trajectory, [cp.CrossCoupled("arc")]).summary()["contour_max_um"]
    assert tuned["max_contour_um"] <= designed


@settings(max_examples=10, deadline=None, derandomize=True)
@given(kp_x=st.floats(25.0, 45.0), kp_y=st.floats(25.0, 45.0), kv_x=st.floats(80.0, 160.0), kv_y=st.floats(80.0, 160.0),
       angle=st.floats(0.0, 180.0))
def test_designed_gains_and_margins_hold_for_any_axes_against_python_control(kp_x, kp_y, kv_x, kv_y, angle):
    """For two axes drawn at random (loops damped at 0.78 or more on their own): the design's worst line is damped at 0.7 (python-control's poles), and on any
    line the coupled loop's damping and spectral radius are those of python-control's interconnection."""
    servos = {"x": AxisServo(kp=kp_x, vff=1.0, **{**AXIS, "kv": kv_x}),
              "y": AxisServo(kp=kp_y, vff=1.0, **{**AXIS, "kv": kv_y})}
    kp, ki, kd = cp.CrossCoupled().gains(servos, DT)
    lines = np.radians(np.arange(0.0, 180.0, 15.0))
    worst = min(_damping(_python_control_coupled_loop(servos, (np.cos(a), np.sin(a)), kp, ki, kd).poles())
                for a in lines)
    assert worst == pytest.approx(cp.DESIGN_DAMPING_RATIO, abs=1e-5)
    normal = np.array([np.cos(np.radians(angle)), np.sin(np.radians(angle))])
    poles = _python_control_coupled_loop(servos, normal, kp, ki, kd).poles()
    m = cp.coupled_margins([kernel.pack(s, DT) for s in servos.values()], kp, ki, kd, DT, [normal])
    assert m["damping_ratio"] == pytest.approx(_damping(poles), abs=1e-7)
    assert m["spectral_radius"] == pytest.approx(np.abs(poles).max(), rel=1e-9)


def test_batch_runs_cross_coupled_variants_each_equal_to_its_single_run():
    from contoursim.comparison import compare
    from contoursim.simulation import SUMMARY_KEYS, simulate_batch

    machine, trajectory = _circle_machine_and_trajectory()
    per_variant = [[cp.CrossCoupled("arc", kp=20.0)], [cp.CrossCoupled("linear", kp=60.0, ki=0.0)],
                   [cp.Feedforward(), cp.CrossCoupled("arc")], [cp.CrossCoupled("arc", kp=1e5)]]  # the last: unstable
    batch = simulate_batch([machine] * 4, trajectory, outputs=("tool_position", "summary"), strategies=per_variant,
                           check=False)
    for b, strategies in enumerate(per_variant[:3]):
        single = simulate(machine, trajectory, strategies)
        np.testing.assert_array_equal(batch["tool_position"][b], single.tool_position)
        assert not batch["summary"]["diverged"][b]
    figures = compare(machine, trajectory, ["feedforward+ccc_arc"]).figures["feedforward+ccc_arc"]
    for key in SUMMARY_KEYS[:5]:
        assert batch["summary"][key][2] == figures[key]
    assert batch["summary"]["saturated"][2] == 0.0 and not figures["saturated"]
    # refused by the coupled-loop check: not run, diverged, no figures; with check=True it is an error
    assert batch["summary"]["diverged"][3] and np.isnan(batch["summary"]["contour_max_um"][3])
    assert np.isnan(batch["tool_position"][3]).all()
    with pytest.raises(UnstableLoopError, match=r"models\[0\]: cross-coupled control with kp = 100000"):
        simulate_batch([machine], trajectory, strategies=[cp.CrossCoupled("arc", kp=1e5)])
    with pytest.raises(ValueError, match="one sequence per model: 2 models, 4 sequences"):
        simulate_batch([machine] * 2, trajectory, strategies=per_variant)


def test_the_coupled_loop_analyses_are_stored_and_read_back(tmp_path, monkeypatch):
    """margins_along's per-frame analyses go to the cache folder as the axis loops' do, and a later call reads them back."""
    import json

    from contoursim import coupled_loop

    monkeypatch.setenv("CONTOURSIM_CACHE_DIR", str(tmp_path))
    coupled_loop._stored_margins.cache_clear()  # analysed here, not remembered from another test
    servos = [AxisServo(kp=40.0, **AXIS), AxisServo(kp=40.0, **{**AXIS, "kv": AXIS["kv"] * 1.3})]
    rows = [kernel.pack(s, DT) for s in servos]
    path = sample(paths.iso230_4_circle(10.0), plan(paths.iso230_4_circle(10.0), feed=25.0, accel=500.0), DT).position
    first = coupled_loop.margins_along(rows, 50.0, 600.0, 0.0, DT, path)
    stored = sorted((tmp_path / "coupled_margins").glob("*.json"))
    assert len(stored) == first["frames"] > 1
    coupled_loop._stored_margins.cache_clear()
    assert coupled_loop.margins_along(rows, 50.0, 600.0, 0.0, DT, path) == first
    for file in stored:  # what is on disk is what a later call returns: read back, not analysed again
        file.write_text(json.dumps({**json.loads(file.read_text()), "phase_margin": 12.5}))
    coupled_loop._stored_margins.cache_clear()
    assert coupled_loop.margins_along(rows, 50.0, 600.0, 0.0, DT, path)["phase_margin"] == 12.5


def test_a_coupling_that_holds_the_tool_past_a_corner_that_turns_back_is_warned_of():
    """A zig-zag whose two rows lie 5 mm apart, on the demo mill at Kp 15 1/s: ccc_arc at its designed gains passes the
    coupled loop's check (PM 79.7°, ζ 0.70), then at the corner where the path turns 117° it holds the tool on the
    first row's line, the position loops pull it back along that row, and it crosses to the second row late: a max
    contour error of 9.8 mm against 0.43 mm without it, and nothing said."""
    from dataclasses import replace

    from contoursim.comparison import WORSE, compare
    from contoursim.exceptions import ContoursimWarning
    from contoursim.feed import FeedSettings
    from contoursim.gcode import read_gcode
    from contoursim.machine import load_machine

    mill = load_machine("demo_mill")
    machine = replace(mill, axes={a: replace(s, kp=15.0) for a, s in mill.axes.items()})
    program = read_gcode("G21 G17 G90\nG0 X0 Y0\nG1 X10 Y5 F1500\nG1 X20 Y0\nG1 X30 Y5\nG1 X40 Y0\nG1 X40 Y10\n"
                         "G1 X30 Y15\nG1 X20 Y10\nG1 X10 Y15\nG1 X0 Y10\n")
    trajectory = sample(program.path, FeedSettings(tuple(program.feeds)).plan(program.path, in_position=0.1),
                        machine.servo_period)
    with pytest.warns(ContoursimWarning, match=r"strategy ccc_arc: its max contour error, .* times that without "
                                               r"compensation .*pull it back along the path") as record:
        comparison = compare(machine, trajectory, ("none", "ccc_arc", "feedforward"))
    worst = {name: run.summary()["contour_max_um"] for name, run in comparison.runs.items()}
    assert worst["ccc_arc"] > WORSE * worst["none"] > WORSE * worst["feedforward"]
    assert [str(w.message).split(":")[0] for w in record] == ["strategy ccc_arc"]  # feedforward is not warned of
    # what the warning says: the tool's foot point goes back along the path (the exact contour error's arc length)
    # while the commanded point goes on
    foot, commanded = comparison.runs["ccc_arc"].contour.s, trajectory.s
    furthest = np.maximum.accumulate(foot)
    back = int(np.argmax(furthest - foot))
    assert furthest[back] - foot[back] > 20.0 and commanded[back] > furthest[back] + 20.0
    assert np.all(np.maximum.accumulate(comparison.runs["none"].contour.s) - comparison.runs["none"].contour.s < 0.1)


def test_zpetc_commands_and_coupling_settings_are_checked_where_given():
    # zpetc_commands turned NaN targets into NaN commands, an empty q into an IndexError, (N, 3) targets into a
    # numpy broadcast error, a servo's name into dataclasses' TypeError, and took negative_radius = 5 (ZPETC refuses it);
    # CrossCoupled took up = (0, 0, 0) until the run, and kp = 1e300 overflowed its default ki in a traceback
    servo = AxisServo(mass=300.0, force_constant=942.0, kv=80.0, kp=40.0)
    q = np.concatenate([np.zeros(50), np.ones(50)])
    for call, error, words in (
        (lambda: cp.zpetc_commands(servo, 2e-4, np.where(np.arange(100) == 7, np.nan, q)), ValueError,
         r"q contains a non-finite value \(nan\) at index 7"),
        (lambda: cp.zpetc_commands(servo, 2e-4, q[:0]), ValueError, "q must hold at least one target position"),
        (lambda: cp.zpetc_commands(servo, 2e-4, np.zeros((100, 3))), ValueError, "q must have 1 dimension"),
        (lambda: cp.zpetc_commands("x", 2e-4, q), TypeError, "servo must be an AxisServo, got str"),
        (lambda: cp.zpetc_commands(servo, 2e-4, q, negative_radius=5.0), ValueError, "negative_radius must be between 0 and 1"),
        (lambda: cp.zpetc_commands(servo, float("nan"), q), ValueError, "dt must be finite"),
        (lambda: cp.CrossCoupled(up=(0, 0, 0)), ValueError, "up must be a nonzero direction"),
        (lambda: cp.CrossCoupled(up=(0, 1)), ValueError, r"up must have shape \(3,\)"),
        (lambda: cp.CrossCoupled(kp=1e300), ValueError, r"kp must be at most 1e\+09, got 1e\+300"),
        (lambda: cp.CrossCoupled(kd=float("inf")), ValueError, "kd must be finite"),
        (lambda: cp.strategies_named("ccc_arc", settings={"ccc_arc": {"kp_per_s": 1e300}}), ValueError,
         r"kp_per_s must be at most 1e\+09"),
    ):
        with pytest.raises(error, match=words):
            call()
    assert cp.zpetc_commands(servo, 2e-4, q[:1]).tolist() == [0.0]
    assert cp.CrossCoupled(up=(0, 0, 2)).up == (0.0, 0.0, 1.0)
