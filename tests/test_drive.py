"""The structure real drives have: velocity from encoder differences, a computation delay, a compliant screw, a
motor encoder or a scale (AxisServo settings).

The kernel is checked against a python-control simulation of the same sampled loop written here from the
equations (not from the kernel's code), against closed forms, and run_batch against run() bit for bit.
"""

from dataclasses import replace

import control as ct
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from contoursim import kernel
from contoursim.exceptions import ConfigError, UnstableLoopError
from contoursim.kernel import LoopEffects, pack, run, run_batch
from contoursim.machine import load_machine
from contoursim.servo import AxisServo
from contoursim.sweep import _job, read_sweep

MASS, KF, KV, KP, TI = 300.0, 900.0, 200.0, 40.0, 0.01
ELECTRICAL = dict(inductance=5e-3, resistance=1.2, kc=5e-3 * 2 * np.pi * 800, ti_current=5e-3 / 1.2)
DT = 1e-4
SCREW = dict(motor_mass=90.0, screw_stiffness=400.0, screw_damping_ratio=0.03)  # its relative mode: 401 Hz


def axis(**kw):
    return AxisServo(**{**dict(mass=MASS, force_constant=KF, kv=KV, kp=KP, ti=TI, damping=800.0), **kw})


def continuous_plant(servo):
    """The axis's mechanics from Newton's law, states (x, v[, x2, v2][, i]): motor side, its velocity[, the table's
    position and velocity on a compliant screw][, the current]; input the current command; outputs x, v, x2 (the
    table: x itself on a rigid axis) [mm, mm/s]."""
    if servo.motor_mass is None:
        A = np.array([[0.0, 1.0], [0.0, -servo.damping / servo.mass]])
        B = np.array([[0.0], [1000.0 * servo.force_constant / servo.mass]])  # mm/s^2 per A
        C = np.array([[1.0, 0.0], [0.0, 1.0], [1.0, 0.0]])
    else:  # two masses: m1·a1 = 1000·kf·i - c_v·v1 - k·(x1 - x2) - c·(v1 - v2), m2·a2 = k·(x1 - x2) + c·(v1 - v2)
        m1, m2 = servo.motor_mass, servo.mass - servo.motor_mass
        k = servo.screw_stiffness * 1e6  # N/m: N/m·mm = mN = kg·mm/s^2
        c = 2 * servo.screw_damping_ratio * np.sqrt(k * m1 * m2 / servo.mass)
        A = np.array([[0.0, 1.0, 0.0, 0.0],
                      [-k / m1, -(servo.damping + c) / m1, k / m1, c / m1],
                      [0.0, 0.0, 0.0, 1.0],
                      [k / m2, c / m2, -k / m2, -c / m2]])  # fmt: skip
        B = np.array([[0.0], [1000.0 * servo.force_constant / m1], [0.0], [0.0]])
        C = np.array([[1.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0]])
    if servo.current_bandwidth_hz is not None:  # the current behind its command: i' = w·(i_cmd - i), drives v
        w = 2 * np.pi * servo.current_bandwidth_hz
        A = np.block([[A, B], [np.zeros((1, A.shape[0])), -w]])
        B = np.zeros((A.shape[0], 1))
        B[-1] = w
        C = np.hstack([C, np.zeros((3, 1))])
    return ct.ss(A, B, C, 0, inputs="i", outputs=["x", "v", "x2"], name="plant")


def reference_loop(servo, quantum, delay, start, play=0.0, position_only=False):
    """The sampled loop as python-control systems: ZOH plant, and the drive as one discrete nlsys.

    The drive at step k: the table behind a play of `play` [mm] around the motor position x (a rigid axis), or
    behind a compliant screw, deflected by ``x2 - x``; the position encoder on the table
    (``position_feedback="scale"``) or on x, ``enc = q·round(·/q)``, read `delay` periods late (``x_fb``);
    velocity from the motor encoder x, quantised and read as late (now with `position_only`: the delay is the
    position loop's alone), ``(m[k] - m[k-n])/(n·dt)`` low-passed
    ``a·y + (1 - a)·raw`` (or the motor velocity ``v`` itself); P position + velocity feedforward; PI velocity
    (its integral as the trapezoidal rule, the backward rectangle or the forward one sums the errors) +
    acceleration feedforward, clamped, the integrator held while clamped and pushed further;
    the command applied `computation_delay` periods later. Inputs xr, vr, ar; outputs the table position,
    x_fb and the applied current.
    """
    plant = ct.sample_system(continuous_plant(servo), DT, method="zoh")
    plant = ct.ss(plant.A, plant.B, plant.C, plant.D, DT, inputs="i", outputs=["x", "v", "x2"], name="plant")
    n = servo.velocity_taps
    a = 0.0 if servo.velocity_filter_hz is None else np.exp(-2 * np.pi * servo.velocity_filter_hz * DT)
    kv = servo.kv / 1000.0  # A per mm/s
    limit = np.inf if servo.current_limit is None else servo.current_limit
    i_ff = servo.aff * servo.mass / (1000.0 * servo.force_constant)
    d = servo.computation_delay
    scale = servo.position_feedback == "scale"
    # states: encoder and motor encoder readings k-1 .. k-delay, the motor's read k-1 .. k-n, y, z, commands k-1,
    # k-2, the table behind the play
    ie, im, ip = 0, delay, 2 * delay
    iy, iz, ic, it = ip + n, ip + n + 1, ip + n + 2, ip + n + 4

    def rounded(position):
        return quantum * np.floor(position / quantum + 0.5) if quantum else position

    def signals(z, u):
        xr, vr, ar, x, v, x2 = u
        table = min(max(z[it], x - play / 2), x + play / 2)
        tool = table + (x2 - x)  # the table behind the play, deflected as the screw is
        readings, motors = np.r_[rounded(tool if scale else x), z[ie:im]], np.r_[rounded(x), z[im:ip]]
        x_fb, m_fb = readings[delay], motors[0 if position_only else delay]
        if servo.velocity_feedback == "difference":
            v_fb = a * z[iy] + (1 - a) * (m_fb - np.r_[m_fb, z[ip:iy]][n]) / (n * DT)
        else:
            v_fb = v
        e_v = servo.kp * (xr - x_fb) + servo.vff * vr - v_fb
        # the integral of the errors up to the last sample, z, and of the present one: half of it (the area of the
        # trapezoid to the next sample's error, taken as this one's), all of it (updated first, then the output),
        # none (the output, then the update)
        integral = z[iz] + {"tustin": DT / 2 * e_v, "backward": DT * e_v, "forward": 0.0}[
            servo.velocity_integrator or "tustin"]
        raw = (kv / servo.ti * integral if servo.ti else 0.0) + kv * e_v + i_ff * ar
        command = np.clip(raw, -limit, limit)
        held = command != raw and e_v * raw > 0
        applied = np.r_[command, z[ic : ic + 2]][d]
        return table, tool, readings, motors, m_fb, v_fb, e_v, held, command, applied

    def update(t, z, u, params):
        table, tool, readings, motors, m_fb, v_fb, e_v, held, command, applied = signals(z, u)
        past = np.r_[m_fb, z[ip:iy]]
        integrator = z[iz] if held or not servo.ti else z[iz] + DT * e_v
        return np.r_[readings[:delay], motors[:delay], past[:n], v_fb, integrator, command, z[ic], table]

    def output(t, z, u, params):
        table, tool, readings, motors, m_fb, v_fb, e_v, held, command, applied = signals(z, u)
        return [applied, readings[delay], tool]

    drive = ct.nlsys(update, output, inputs=["xr", "vr", "ar", "x", "v", "x2"], outputs=["i", "x_fb", "tool"],
                     states=2 * delay + n + 5, dt=DT, name="drive")
    loop = ct.interconnect([plant, drive], inplist=["xr", "vr", "ar"], outlist=["tool", "x_fb", "i"])
    x0 = np.zeros(loop.nstates)  # at rest at `start`: the ZOH plant's states are the continuous ones
    x0[loop.state_labels.index("plant_x[0]")] = start
    if servo.motor_mass is not None:
        x0[loop.state_labels.index("plant_x[2]")] = start
    first = loop.state_labels.index("drive_x[0]")
    x0[first : first + 2 * delay + n] = rounded(start)  # at rest: the encoder histories hold the first reading
    x0[first + it] = start
    return loop, x0


DRIVES = {
    "difference": (dict(velocity_feedback="difference"), 0.0, 0),
    "fir2": (dict(velocity_feedback="difference", velocity_taps=2), 0.0, 0),
    "fir2_backlash_motor": (dict(velocity_feedback="difference", velocity_taps=2, computation_delay=1), 0.0, 0,
                            dict(backlash_mm=0.004)),
    "fir2_backlash_scale": (dict(velocity_feedback="difference", velocity_taps=2, velocity_filter_hz=1000.0,
                                 position_feedback="scale"), 2e-4, 1, dict(backlash_mm=0.004)),
    "fir3_lowpass_delay1": (dict(velocity_feedback="difference", velocity_taps=3, velocity_filter_hz=600.0,
                                 computation_delay=1), 0.0, 0),
    "quantised_delayed_delay2": (dict(velocity_feedback="difference", velocity_taps=2, velocity_filter_hz=1500.0,
                                      computation_delay=2), 5e-4, 2),
    "state_delay2": (dict(computation_delay=2), 0.0, 0),
    "p_velocity_clamped": (dict(ti=None, kv=300.0, velocity_feedback="difference", velocity_taps=2,
                                computation_delay=1, current_limit=4.0, vff=1.0, aff=0.7), 2e-4, 1),
    "pi_clamped": (dict(velocity_feedback="difference", velocity_taps=2, computation_delay=1,
                        current_limit=3.0, vff=0.5), 0.0, 0),
    "pi_backward": (dict(velocity_integrator="backward", velocity_feedback="difference", velocity_filter_hz=800.0,
                         vff=1.0), 0.0, 0),
    "pi_forward_clamped_delay1": (dict(velocity_integrator="forward", velocity_feedback="difference",
                                       computation_delay=1, current_limit=3.0, vff=0.5), 0.0, 0),
    "pi_backward_screw_scale": (dict(SCREW, velocity_integrator="backward", position_feedback="scale",
                                     velocity_feedback="difference", current_bandwidth_hz=1500.0), 2e-4, 1),
    "current_lag": (dict(current_bandwidth_hz=1200.0), 0.0, 0),
    "current_lag_fir2_delay1_clamped": (dict(current_bandwidth_hz=800.0, velocity_feedback="difference",
                                             velocity_taps=2, computation_delay=1, current_limit=2.0, vff=0.5), 2e-4, 1),
    "screw_motor": (dict(SCREW, velocity_feedback="difference", computation_delay=1, vff=1.0), 0.0, 0),
    "screw_scale": (dict(SCREW, position_feedback="scale", velocity_feedback="difference", computation_delay=1,
                         vff=1.0), 0.0, 0),
    "screw_state_scale_lag": (dict(SCREW, position_feedback="scale", current_bandwidth_hz=1500.0, aff=0.5), 0.0, 0),
    "screw_scale_quantised_delayed_clamped": (dict(SCREW, position_feedback="scale", velocity_feedback="difference",
                                                   velocity_taps=2, velocity_filter_hz=2000.0, current_limit=0.6,
                                                   current_bandwidth_hz=1500.0), 2e-4, 1),
}  # a backlash in a compliant screw is a dead zone in the screw, not a play: tests/test_kernel_gap.py


@pytest.mark.parametrize("name", list(DRIVES))
def test_kernel_equals_python_control_reference(name):
    kw, quantum, delay, *backlash = DRIVES[name]
    backlash = backlash[0] if backlash else {}
    servo = axis(**kw)
    n = 400
    t = np.arange(n) * DT
    w = 2 * np.pi * 40.0  # a 0.2 mm sine: reverses after 6.25 ms
    pos, vel, acc = 0.2 * np.sin(w * t), 0.2 * w * np.cos(w * t), -0.2 * w**2 * np.sin(w * t)
    effects = LoopEffects(quantum_mm=quantum, feedback_delay_s=delay * DT, **backlash)
    result = run({"x": servo}, DT, pos[:, None], vel[:, None], acc[:, None], effects={"x": effects})
    loop, x0 = reference_loop(servo, quantum, delay, pos[0], backlash.get("backlash_mm", 0.0))
    ref = ct.input_output_response(loop, t, np.vstack([pos, vel, acc]), X0=x0).outputs
    np.testing.assert_allclose(result.position[:, 0], ref[0], rtol=0, atol=1e-9)
    np.testing.assert_allclose(result.encoder[:, 0], ref[1], rtol=0, atol=1e-9)
    np.testing.assert_allclose(result.current[:, 0], ref[2], rtol=0, atol=1e-9 * np.abs(ref[2]).max())
    if servo.current_limit is not None:
        assert result.saturated.any()  # the clamp and its anti-windup are exercised
    plant = ("ti", "kv", "current_limit", "vff", "aff", "motor_mass", "screw_stiffness", "position_feedback")
    plain = run({"x": axis(**{k: v for k, v in kw.items() if k in plant})},
                DT, pos[:, None], vel[:, None], acc[:, None], effects={"x": effects})
    assert np.abs(result.position - plain.position).max() > 1e-7  # the drive's structure shows in 400 steps


@pytest.mark.parametrize("name", ["difference", "fir3_lowpass_delay1", "quantised_delayed_delay2", "state_delay2",
                                  "screw_scale_quantised_delayed_clamped"])
@pytest.mark.parametrize("delay", [1, 3])
def test_position_loop_delay_equals_python_control_reference(name, delay):
    # The NC's position loop reads the encoder `delay` periods late (a fieldbus), the drive's velocity loop its own
    # motor encoder now: z^-delay on the position reading alone.
    kw, quantum = DRIVES[name][:2]
    servo = axis(**kw)
    n = 400
    t = np.arange(n) * DT
    w = 2 * np.pi * 40.0
    pos, vel, acc = 0.2 * np.sin(w * t), 0.2 * w * np.cos(w * t), -0.2 * w**2 * np.sin(w * t)
    runs = {on: run({"x": servo}, DT, pos[:, None], vel[:, None], acc[:, None],
                    effects={"x": LoopEffects(quantum_mm=quantum, feedback_delay_s=delay * DT, feedback_delay_on=on)})
            for on in ("position", "both")}  # fmt: skip
    loop, x0 = reference_loop(servo, quantum, delay, pos[0], position_only=True)
    ref = ct.input_output_response(loop, t, np.vstack([pos, vel, acc]), X0=x0).outputs
    result = runs["position"]
    np.testing.assert_allclose(result.position[:, 0], ref[0], rtol=0, atol=1e-9)
    np.testing.assert_allclose(result.encoder[:, 0], ref[1], rtol=0, atol=1e-9)
    np.testing.assert_allclose(result.current[:, 0], ref[2], rtol=0, atol=1e-9 * np.abs(ref[2]).max())
    assert np.abs(result.position - runs["both"].position).max() > 1e-7  # not the delay of both loops


@pytest.mark.parametrize("kw", [dict(velocity_feedback="difference", velocity_taps=2),
                                dict(velocity_feedback="difference", velocity_taps=4, velocity_filter_hz=300.0,
                                     computation_delay=2),
                                dict(velocity_feedback="difference", velocity_taps=2, current_bandwidth_hz=900.0)])
def test_ramp_error_is_still_v_over_kp(kw):
    # A constant velocity's difference is that velocity exactly (any taps, the low-pass has unit DC gain): with a PI
    # velocity loop and no damping the current settles to 0, so the following error is v/kp, as with a tachometer.
    servo = axis(damping=0.0, **kw)
    t = np.arange(6000) * DT
    ramp = (10.0 * t)[:, None]
    r = run([servo], DT, ramp, np.full_like(ramp, 10.0), np.zeros_like(ramp))
    assert ramp[-1, 0] - r.position[-1, 0] == pytest.approx(10.0 / KP, abs=1e-9)


@pytest.mark.parametrize("kw", [dict(velocity_feedback="difference"),
                                dict(velocity_feedback="difference", velocity_taps=2, computation_delay=1),
                                dict(velocity_feedback="difference", velocity_taps=3, velocity_filter_hz=800.0,
                                     computation_delay=2, ti=None),
                                dict(computation_delay=2, **ELECTRICAL),
                                dict(velocity_feedback="difference", velocity_taps=2, velocity_filter_hz=2000.0,
                                     computation_delay=1, **ELECTRICAL),
                                dict(velocity_feedback="difference", velocity_taps=2, computation_delay=1,
                                     current_bandwidth_hz=700.0),
                                dict(SCREW, velocity_feedback="difference", computation_delay=1),
                                dict(SCREW, position_feedback="scale", velocity_feedback="difference", velocity_taps=2,
                                     velocity_filter_hz=1500.0, current_bandwidth_hz=1200.0),
                                dict(SCREW, position_feedback="scale", computation_delay=2),
                                dict(SCREW, position_feedback="scale", **ELECTRICAL)])
def test_spectral_radius_equals_python_control_closed_loop_poles(kw):
    # The kernel's linearised loop (loop_matrices) and servo.discretize's python-control interconnection of the
    # estimator and delay blocks: the same poles.
    servo = axis(**kw)
    want = np.abs(servo.discretize(DT).closed_loop.poles()).max()
    assert kernel.spectral_radius(pack(servo, DT)) == pytest.approx(want, abs=1e-12)


@settings(max_examples=15, deadline=None)
@given(taps=st.integers(1, 8), filter_hz=st.one_of(st.none(), st.floats(50.0, 5000.0)), delay=st.integers(0, 2),
       feedback_delay=st.floats(0.0, 3.0), on=st.sampled_from(["both", "position"]),
       screw=st.sampled_from([{}, dict(SCREW), dict(SCREW, position_feedback="scale")]))
def test_loop_matrices_match_the_simulated_growth_of_any_drive(taps, filter_hz, delay, feedback_delay, on, screw):
    # Without a nonlinearity in play the kernel is linear: its response to an initial offset is phi^k applied to it.
    servo = axis(velocity_feedback="difference", velocity_taps=taps, velocity_filter_hz=filter_hz,
                 computation_delay=delay, damping=0.0, **screw)
    row = pack(servo, DT, LoopEffects(feedback_delay_s=feedback_delay * DT, feedback_delay_on=on))
    phi, b, c = kernel.loop_matrices(row)
    n = 300
    ref = np.full((n, 1), 1e-3)  # a step of 1 µm from rest at 0: the response from the loop's matrices
    ref[0] = 0.0
    x = run_batch(row[None, None], DT, ref, np.zeros_like(ref), np.zeros_like(ref), outputs=("encoder",))
    s = np.zeros(phi.shape[0])
    want = []
    for k in range(n):  # the step as w = kp·1e-3 on the velocity command (x_ref enters through kp only)
        want.append(c @ s)
        s = phi @ s + b * (servo.kp * ref[k, 0])
    np.testing.assert_allclose(x["encoder"][0, :, 0], want, rtol=0, atol=1e-12)


def test_batch_rows_with_drive_structures_equal_their_single_runs_bit_for_bit():
    rng = np.random.default_rng(18)
    t = np.arange(1200) * DT
    w = 2 * np.pi * 30.0
    refs = tuple(np.column_stack([r, 0.5 * r]) for r in (0.3 * np.sin(w * t), 0.3 * w * np.cos(w * t),
                                                           -0.3 * w**2 * np.sin(w * t)))
    variants = []
    for b in range(12):
        servos, effects = {}, {}
        for name in ("x", "y"):
            kw = dict(computation_delay=int(rng.integers(3)), current_limit=float(rng.choice([2.0, 50.0])))
            if rng.random() < 0.3:
                kw.update(ELECTRICAL)
            elif rng.random() < 0.4:
                kw.update(current_bandwidth_hz=float(rng.uniform(300.0, 3000.0)))
            if rng.random() < 0.7:
                kw.update(velocity_feedback="difference", velocity_taps=int(rng.integers(1, 9)),
                          velocity_filter_hz=rng.choice([None, float(rng.uniform(200.0, 3000.0))]))
            servos[name] = axis(**kw, position_feedback=str(rng.choice(["motor", "scale"])))
            if rng.random() < 0.6:  # a compliant screw, where the drawn drive keeps it stable
                compliant = replace(servos[name], motor_mass=float(rng.uniform(60.0, 120.0)),
                                    screw_stiffness=float(rng.uniform(300.0, 1500.0)))
                try:
                    servos[name] = compliant if compliant.check(DT) else servos[name]
                except UnstableLoopError:
                    pass
            effects[name] = LoopEffects(quantum_mm=float(rng.choice([0.0, 2e-4])),
                                        feedback_delay_s=float(rng.choice([0.0, 1.5 * DT, 2 * DT])),
                                        coulomb_N=float(rng.choice([0.0, 60.0])),
                                        backlash_mm=float(rng.choice([0.0, 0.003])))
        variants.append((servos, effects))
    variants[0] = ({name: axis() for name in ("x", "y")}, {})  # one variant as before the drive's structure
    rows = np.array([[pack(s, DT, e.get(name, LoopEffects())) for name, s in servos.items()]
                     for servos, e in variants])
    for chosen in (slice(None), slice(0, 3)):  # blocks in lanes; a narrow block one variant at a time
        batch = run_batch(rows[chosen], DT, *refs, outputs=kernel.BATCH_OUTPUTS)
        for b, (servos, effects) in enumerate(variants[chosen]):
            single = run(servos, DT, *refs, effects=effects)
            for name, field in [("tool", "position"), ("encoder", "encoder"), ("velocity", "velocity"),
                                ("current", "current"), ("saturated", "saturated")]:
                np.testing.assert_array_equal(batch[name][b], getattr(single, field), err_msg=f"{name}, variant {b}")
    assert {s.computation_delay for servos, _ in variants for s in servos.values()} == {0, 1, 2}
    assert any(s.electrical for servos, _ in variants for s in servos.values())
    assert any(s.current_bandwidth_hz for servos, _ in variants for s in servos.values())
    assert {(s.compliant, s.position_feedback) for servos, _ in variants for s in servos.values()} == {
        (c, f) for c in (False, True) for f in ("motor", "scale")}


@pytest.mark.parametrize("kw", [dict(), dict(velocity_feedback="difference", velocity_taps=2, computation_delay=1,
                                             current_bandwidth_hz=1500.0)])
def test_the_table_lags_the_motor_by_m2_a_over_k_under_constant_acceleration(kw):
    # Closed form: under a constant acceleration a the screw carries the table's inertia force m2·a, so once the
    # mode has died out the table (the tool position) trails the motor encoder by m2·a/k, whatever the controller.
    servo = axis(**SCREW, vff=1.0, aff=1.0, **kw)
    accel = 2000.0  # [mm/s^2]
    t = np.arange(4000) * DT
    pos = 0.5 * accel * t**2
    r = run([servo], DT, pos[:, None], (accel * t)[:, None], np.full((t.size, 1), accel))
    lag = r.encoder[-1, 0] - r.position[-1, 0]
    m2, k = MASS - SCREW["motor_mass"], SCREW["screw_stiffness"] * 1e6  # [kg], [N/m]
    assert lag == pytest.approx(m2 * accel / k, rel=1e-6)  # [mm]: 1.05 µm (the loop's slowest poles, 6 Hz, leave 1e-9)
    stiff = run([axis(vff=1.0, aff=1.0, **kw)], DT, pos[:, None], (accel * t)[:, None], np.full((t.size, 1), accel))
    np.testing.assert_array_equal(stiff.encoder, stiff.position)  # a rigid axis's encoder reads the tool position


def test_a_loop_the_screw_destabilises_is_refused_with_its_margins():
    # A 63 Hz screw (10 N/µm) inside a 190 Hz velocity loop: on the scale the whole loop is unstable, refused
    # at its velocity loop; on a 400 N/µm screw (401 Hz) the same drive passes.
    drive = dict(kv=400.0, velocity_feedback="difference", computation_delay=1, position_feedback="scale")
    soft = axis(**drive, motor_mass=90.0, screw_stiffness=10.0)
    with pytest.raises(UnstableLoopError, match=r"the velocity loop of axis 'x' is badly damped \(needs .*\) at "
                                                r"dt = 0.0001 s: gain margin [\d.]+, phase margin") as info:
        soft.check(DT)
    assert info.value.margins["damping_ratio"] < 0.2
    assert kernel.spectral_radius(pack(soft, DT)) > 1.0
    stiff = axis(**drive, **SCREW)
    margins = stiff.check(DT)
    assert margins["velocity"]["stable"] and margins["velocity"]["phase_margin"] > 30
    assert kernel.spectral_radius(pack(stiff, DT)) < 1.0

@pytest.mark.parametrize("stiffness, within", [(0.5, ", within 4 times the crossover 6.832 Hz"), (0.01, "")])
def test_a_screw_whose_mode_lies_in_the_velocity_loops_band_is_named_in_the_refusal(stiffness, within):
    """A 0.5 N/µm screw (in N/mm, a real one's number) under a 250 kg table: the velocity loop badly damped by the
    screw's mode was told to raise kv or lengthen ti, or to check the mass; the screw was never named (an outside
    probe)."""
    soft = AxisServo(mass=300.0, force_constant=942.0, kv=80.0, ti=0.016, kp=40.0, damping=500.0, motor_mass=50.0,
                     screw_stiffness=stiffness)
    with pytest.raises(UnstableLoopError, match=r"the velocity loop of axis 'x' is badly damped") as err:
        soft.check(2e-4)
    assert str(err.value).endswith(
        f"the screw's mode lies in the loop's band (its antiresonance {np.sqrt(stiffness * 4e3) / (2 * np.pi):.4g} "
        f"Hz{within}): check screw_stiffness ({stiffness:g} N/µm: one in N/mm reads a thousand times too soft), or "
        "lower kv."), str(err.value)


def test_an_integrator_rule_on_a_p_velocity_loop_is_refused():
    """velocity_integrator on an axis without ti ran without effect, the results the same for every rule, while
    velocity_taps without difference feedback was refused (an outside probe)."""
    with pytest.raises(ValueError, match=r"^velocity_integrator says how the velocity PI integrates: it needs ti"):
        axis(ti=None, velocity_integrator="backward")
    assert axis(velocity_integrator="backward").velocity_integrator == "backward"


def test_the_state_feedback_default_is_the_loop_of_before():
    servo = axis()
    assert (servo.velocity_feedback, servo.velocity_taps, servo.velocity_filter_hz, servo.computation_delay) == (
        "state", 1, None, 0)
    row = pack(servo, DT)
    assert row[kernel._VDIFF] == 0.0 and row[kernel._CDELAY] == 0.0


def test_a_loop_the_computation_delay_destabilises_is_refused_with_its_margins():
    # 95 Hz velocity crossover at 1 ms: stable on the tachometer, not once the difference and 2 periods of
    # computation add 2.5 periods of lag (120 deg at the crossover).
    dt, fast = 1e-3, dict(ti=None, damping=0.0)
    margins = axis(**fast).check(dt)
    assert margins["velocity"]["stable"] and margins["velocity"]["phase_margin"] > 30
    slow = axis(**fast, velocity_feedback="difference", computation_delay=2)
    with pytest.raises(UnstableLoopError, match=r"the velocity loop of axis 'x' is unstable at dt = 0.001 s") as info:
        slow.check(dt)
    assert info.value.margins["phase_margin"] < 0
    assert kernel.spectral_radius(pack(slow, dt)) > 1.0 > kernel.spectral_radius(pack(axis(**fast), dt))
    lagging = slow.margins(dt)["velocity"]["phase_margin"]
    assert lagging < axis(**fast, velocity_feedback="difference").margins(dt)["velocity"]["phase_margin"]


@pytest.mark.parametrize("kw, error, message", [
    (dict(velocity_feedback="tacho"), ValueError, 'velocity_feedback must be "state" or "difference"'),
    (dict(velocity_feedback="difference", velocity_taps=0), ValueError, "velocity_taps must be at least 1"),
    (dict(velocity_feedback="difference", velocity_taps=9), ValueError, "velocity_taps must be at most 8"),
    (dict(velocity_feedback="difference", velocity_taps=2.0), TypeError, "velocity_taps must be a whole number"),
    (dict(velocity_feedback="difference", velocity_filter_hz=-1.0), ValueError, "velocity_filter_hz"),
    (dict(velocity_taps=2), ValueError, 'they need velocity_feedback = "difference"'),
    (dict(velocity_filter_hz=500.0), ValueError, 'they need velocity_feedback = "difference"'),
    (dict(computation_delay=3), ValueError, "computation_delay must be 0, 1 or 2"),
    (dict(computation_delay=True), TypeError, "computation_delay must be a whole number"),
    (dict(velocity_integrator="trapezoidal"), ValueError, "velocity_integrator must be one of 'tustin', 'backward', "
                                                          "'forward'"),
    (dict(current_bandwidth_hz=0.0), ValueError, "current_bandwidth_hz must be"),
    (dict(current_bandwidth_hz=1000.0, **ELECTRICAL), ValueError, "give one or the other"),
    (dict(position_feedback="table"), ValueError, 'position_feedback must be "motor" or "scale"'),
    (dict(motor_mass=90.0), ValueError, "needs screw_stiffness"),
    (dict(screw_stiffness=400.0), ValueError, "screw_stiffness given without motor_mass"),
    (dict(screw_damping_ratio=0.03), ValueError, "screw_damping_ratio given without motor_mass"),
    (dict(motor_mass=300.0, screw_stiffness=400.0), ValueError, "motor_mass must be less than mass"),
    (dict(motor_mass=90.0, screw_stiffness=-1.0), ValueError, "screw_stiffness must be"),
    (dict(SCREW, screw_damping_ratio=1.0), ValueError, "screw_damping_ratio must be between 0 and 1"),
])
def test_bad_drive_settings_name_the_parameter(kw, error, message):
    with pytest.raises(error, match=message):
        axis(**kw)


MACHINE = """name = "drive"
servo_period_ms = 0.1
[axes.x]
mass_kg = 300.0
force_constant_N_per_A = 900.0
kv_A_s_per_m = 200.0
ti_s = 0.01
{extra}
"""


def test_machine_file_keys_and_what_uncertain_may_list(tmp_path):
    file = tmp_path / "m.toml"
    file.write_text(MACHINE.format(extra='velocity_feedback = "difference"\nvelocity_taps = 2\n'
                                         'velocity_filter_hz = 900.0\ncomputation_delay_periods = 1\n'
                                         'current_bandwidth_hz = 1500.0\nvelocity_integrator = "backward"\n'
                                         'uncertain = ["velocity_filter_hz", "current_bandwidth_hz"]'))
    machine = load_machine(file)
    servo = machine.axes["x"]
    assert (servo.velocity_feedback, servo.velocity_taps, servo.velocity_filter_hz, servo.computation_delay,
            servo.velocity_integrator) == ("difference", 2, 900.0, 1, "backward")
    assert servo.current_bandwidth_hz == 1500.0
    assert machine.uncertain["x"] == ("velocity_filter_hz", "current_bandwidth_hz")
    file.write_text(MACHINE.format(extra="computation_delay_periods = 3"))
    with pytest.raises(ConfigError, match=r"m.toml, line 8: axis x: computation_delay_periods must be 0, 1 or 2"):
        load_machine(file)
    file.write_text(MACHINE.format(extra='velocity_feedback = "difference"\ncomputation_delay_periods = 1\n'
                                         'uncertain = ["computation_delay_periods"]'))
    with pytest.raises(ConfigError, match=r"line \d+: axis x: uncertain must list controller keys"):
        load_machine(file)


def test_machine_file_keys_of_a_compliant_screw_and_a_scale(tmp_path):
    file = tmp_path / "m.toml"
    file.write_text(MACHINE.format(extra='position_feedback = "scale"\nmotor_mass_kg = 90.0\n'
                                         'screw_stiffness_N_per_um = 400.0\nscrew_damping_ratio = 0.04'))
    servo = load_machine(file).axes["x"]
    assert (servo.position_feedback, servo.motor_mass, servo.screw_stiffness, servo.screw_damping_ratio) == (
        "scale", 90.0, 400.0, 0.04)
    assert servo.screw_mode_hz == pytest.approx(np.sqrt(400e6 * 300.0 / (90.0 * 210.0)) / (2 * np.pi))
    file.write_text(MACHINE.format(extra="motor_mass_kg = 90.0\nscrew_stiffness_N_per_um = 400.0"))
    assert load_machine(file).axes["x"].screw_damping_ratio == 0.03  # the typical value, said in the docs
    for extra, message in [
        ("motor_mass_kg = 90.0", r"m.toml, line 8: axis x: motor_mass_kg is given, so the compliant screw needs "
                                 r"screw_stiffness_N_per_um"),
        ("motor_mass_kg = 300.0\nscrew_stiffness_N_per_um = 400.0", r"m.toml, line 8: axis x: motor_mass_kg must be "
                                                                      r"less than mass"),
        ('position_feedback = "encoder"', r"m.toml, line 8: axis x: position_feedback must be"),
        ("screw_stiffness_N_per_um = 400.0", r"m.toml, line 8: axis x: screw_stiffness_N_per_um given without "
                                             r"motor_mass_kg, the part of mass"),
        ("motor_mass_kg = 90.0\nscrew_stiffness_N_per_um = 0.0", r"m.toml, line 9: axis x: screw_stiffness_N_per_um "
                                                                   r"must be"),
    ]:
        file.write_text(MACHINE.format(extra=extra))
        with pytest.raises(ConfigError, match=message):
            load_machine(file)


def test_one_mode_per_axis_and_one_place_for_the_encoder():
    from contoursim.effects import Effect
    from contoursim.machine import Machine
    from contoursim.model import Model

    with pytest.raises(ValueError, match=r"a structural mode \(vibration\) on an axis with a compliant screw"):
        pack(axis(**SCREW), DT, LoopEffects(mode_freq_hz=80.0))
    machine = Machine({"x": axis(**SCREW, position_feedback="scale")}, DT)
    with pytest.raises(ValueError, match=r"vibration.x: axis x has a compliant screw .* no vibration beside it"):
        Model(machine, (Effect("vibration", "x", freq_hz=80.0),))
    bound = Model(machine, (Effect("backlash", "x", lost_motion_um=5.0),)).effects[0]
    assert bound.options["feedback"] == "scale"  # left out: the axis's
    motor = Model(machine, (Effect("backlash", "x", lost_motion_um=5.0, feedback="motor"),))  # given: read there
    assert motor.machine.axes["x"].position_feedback == "motor" and motor.machine.axes["x"].compliant


SWEEP = """machine = "demo_mill"
path = "rounded_square"
[feed]
feed_mm_min = 3000
[sweep]
method = "{method}"
{count}
[[vary]]
name = "axes.x.computation_delay_periods"
{values}
"""


def test_a_sweep_varies_the_computation_delay_over_whole_periods(tmp_path):
    spec = tmp_path / "spec.toml"
    spec.write_text(SWEEP.format(method="grid", count="", values="values = [0, 1, 2]"))
    sweep = read_sweep(spec)
    job = _job(sweep)
    delays = [job.variant({"axes.x.computation_delay_periods": v})[0].machine.axes["x"].computation_delay
              for v in sweep.values[:, 0]]
    assert delays == [0, 1, 2] and all(isinstance(d, int) for d in delays)
    spec.write_text(SWEEP.format(method="random", count="count = 4", values="min = 0.0\nmax = 2.0"))
    with pytest.raises(ConfigError, match=r"vary 'axes.x.computation_delay_periods': computation_delay_periods must "
                                          r"be a whole"):  # the file's key, not the servo's computation_delay
        read_sweep(spec)
