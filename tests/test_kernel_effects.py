"""In-loop effects of the kernel: packed rows, python-control references, physical signatures, batches."""

import subprocess
import sys
from dataclasses import replace

import control as ct
import numba
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from contoursim import kernel
from contoursim.exceptions import UnstableLoopError
from contoursim.kernel import MAX_DELAY_SAMPLES, NPAR, LoopEffects, pack, run, run_batch
from contoursim.servo import AxisServo

MASS, KF, KV = 300.0, 900.0, 200.0
ELECTRICAL = dict(inductance=5e-3, resistance=1.2, kc=5e-3 * 2 * np.pi * 800, ti_current=5e-3 / 1.2)
DT = 1e-4


def axis(**kw):
    return AxisServo(**{**dict(mass=MASS, force_constant=KF, kv=KV, kp=40.0, ti=0.01), **kw})


# --- the plant written here, in its own coordinates: carriage x1 and tool-side mass x2 ----------


def two_mass_plant(servo, effects):
    """Continuous plant, states (x1, v1[, x2, v2][, i]) [mm, mm/s, A]; inputs (i_cmd or u, F [N]).

    Outputs x1, v1, the tool position (x2, or x1 when rigid) [and i].
    """
    m, c_slide = servo.mass, servo.damping
    mode = effects.mode_freq_hz is not None
    m2 = effects.mode_mass_ratio * m if mode else 0.0
    m1 = m - m2
    n_mech = 4 if mode else 2
    n = n_mech + servo.electrical
    A, B = np.zeros((n, n)), np.zeros((n, 2))
    # carriage: m1·a1 = kf·i + F - c_slide·v1 + k·(x2 - x1) + c·(v2 - v1); SI forces, mm inside (x 1000)
    A[0, 1] = 1.0
    A[1, 1] = -c_slide / m1
    B[1, 1] = 1000.0 / m1
    if mode:
        w = 2 * np.pi * effects.mode_freq_hz
        k, c = m2 * w**2, 2 * effects.mode_damping_ratio * m2 * w  # [N/m], [N·s/m]
        A[1, 0] += -k / m1
        A[1, 2] += k / m1
        A[1, 1] += -c / m1
        A[1, 3] += c / m1
        A[2, 3] = 1.0
        A[3, :4] = [k / m2, c / m2, -k / m2, -c / m2]
    if servo.electrical:
        L = servo.inductance
        A[1, n - 1] = 1000.0 * servo.force_constant / m1
        A[n - 1, 1] = -servo.force_constant / 1000.0 / L
        A[n - 1, n - 1] = -servo.resistance / L
        B[n - 1, 0] = 1.0 / L
    else:
        B[1, 0] = 1000.0 * servo.force_constant / m1
    C = np.zeros((3 + servo.electrical, n))
    C[0, 0] = C[1, 1] = 1.0
    C[2, 2 if mode else 0] = 1.0
    if servo.electrical:
        C[3, n - 1] = 1.0
    outputs = ["x", "v", "xt"] + (["i"] if servo.electrical else [])
    return ct.ss(A, B, C, 0, inputs=["drive", "F"], outputs=outputs)


def packed_plant(row, servo, effects):
    """The packed (Ad, Bd) over the present states, in the two-mass coordinates of `two_mass_plant`."""
    Ad = row[:25].reshape(5, 5)
    Bd = np.column_stack([row[25:30], row[30:35]])
    mode = effects.mode_freq_hz is not None
    states = [0, 1] + ([2, 3] if mode else []) + ([4] if servo.electrical else [])
    Ad, Bd = Ad[np.ix_(states, states)], Bd[states]
    T = np.eye(len(states))  # kernel coordinates (x, v, d, ḋ) = T (x1, v1, x2, v2)
    if mode:
        T[2, 0] = T[3, 1] = -1.0
    Ti = np.linalg.inv(T)
    return Ti @ Ad @ T, Ti @ Bd


MODE = dict(mode_freq_hz=80.0, mode_damping_ratio=0.03, mode_mass_ratio=0.25)


@pytest.mark.parametrize("extra", [dict(damping=1500.0), dict(damping=1500.0, **ELECTRICAL), dict(ti=None)])
@pytest.mark.parametrize("effects", [LoopEffects(), LoopEffects(**MODE), LoopEffects(**{**MODE, "mode_damping_ratio": 1.0})],
                         ids=["rigid", "mode", "critically damped mode"])  # the catalogue's damping reaches 1
def test_packed_plant_equals_python_control_zoh(extra, effects):
    servo = axis(**extra)
    row = pack(servo, DT, effects)
    Ad, Bd = packed_plant(row, servo, effects)
    ref = ct.sample_system(two_mass_plant(servo, effects), DT, method="zoh")
    np.testing.assert_allclose(Ad, ref.A, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(Bd, ref.B, rtol=1e-12, atol=1e-12 * np.abs(ref.B).max())
    if not effects.mode_freq_hz:  # and the rigid plant is the one discretize() gives python-control
        blocks = servo.discretize(DT)
        np.testing.assert_allclose(Ad, blocks.plant.A, rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(Bd[:, :1], blocks.plant.B, rtol=1e-12, atol=1e-12 * np.abs(blocks.plant.B).max())


def test_variants_packed_in_turn_each_get_their_own_plants_zoh():
    """A fit's variants share their plant's ZOH (packed once, kernel._ZOHS): variants alternating two masses, two
    dampings and two gains, a mode on and off, each row's plant is python-control's sampling of its own plant."""
    variants = [(MASS, 0.0, 40.0, LoopEffects()), (MASS, 0.0, 80.0, LoopEffects()), (1.01 * MASS, 0.0, 40.0, LoopEffects()),
                (MASS, 1500.0, 40.0, LoopEffects(**MODE)), (MASS, 0.0, 40.0, LoopEffects()), (MASS, 1500.0, 80.0, LoopEffects())]
    for mass, damping, kp, effects in variants * 2:
        servo = axis(mass=mass, damping=damping, kp=kp)
        row = pack(servo, DT, effects)
        assert row.flags.writeable and row[kernel._KP] == kp  # the caller's own row
        Ad, Bd = packed_plant(row, servo, effects)
        ref = ct.sample_system(two_mass_plant(servo, effects), DT, method="zoh")
        np.testing.assert_allclose(Ad, ref.A, rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(Bd, ref.B, rtol=1e-12, atol=1e-12 * np.abs(ref.B).max())


@pytest.mark.parametrize("extra", [dict(), dict(ti=None), dict(**ELECTRICAL)])
def test_packed_controllers_equal_discretize_blocks(extra):
    servo = axis(**extra)
    row = pack(servo, DT)
    d = servo.discretize(DT)
    names = ["velocity_controller"] + (["current_controller"] if servo.electrical else [])
    for name, base in zip(names, (kernel._VB, kernel._CB)):
        block = getattr(d, name)
        want = (0.0, 0.0, block.D[0, 0]) if block.nstates == 0 else (block.B[0, 0], block.C[0, 0], block.D[0, 0])
        np.testing.assert_allclose(row[base : base + 3], want, rtol=1e-12, atol=0)
    assert row[kernel._KP] == servo.kp and row[kernel._ELEC] == float(servo.electrical)


# --- kernel = python-control's simulation of the same sampled loop with the same effects -------


def reference_loop(servo, effects, start):
    """One axis: plant (ZOH of `two_mass_plant`), discretize()'s controllers, effects as discrete nlsys.

    Returns the interconnection (inputs xr, vr, ar; outputs tool, x_fb, i_cmd) and its initial state.
    """
    plant = ct.sample_system(two_mass_plant(servo, effects), DT, method="zoh")
    n_plant = plant.nstates  # the full state is an output too: the stick-slip friction needs it
    states = [f"s{j}" for j in range(n_plant)]
    plant = ct.ss(plant.A, plant.B, np.vstack([plant.C, np.eye(n_plant)]), np.zeros((plant.noutputs + n_plant, 2)),
                  DT, inputs=["drive", "F"], outputs=plant.output_labels + states, name="plant")  # fmt: skip
    d = servo.discretize(DT)
    h, q = effects.backlash_mm / 2, effects.quantum_mm
    delay = effects.feedback_delay_s / DT
    n, f = int(np.floor(delay + 1e-9)), delay - np.floor(delay + 1e-9)
    m = n + 2  # remembered past samples

    def history(z, u):
        """Table, encoder, and the (current, past...) encoder and velocity histories."""
        x, v = u[0], u[1]
        table = min(max(z[0], x - h), x + h)
        enc = table if servo.position_feedback == "scale" else x
        if q:
            enc = q * np.floor(enc / q + 0.5)
        return table, enc, np.concatenate([[enc], z[1 : 1 + m]]), np.concatenate([[v], z[1 + m :]])

    def sensors_update(t, z, u, params):
        table, enc, hx, hv = history(z, u)
        return np.concatenate([[table], hx[:m], hv[:m]])

    def sensors_output(t, z, u, params):
        table, enc, hx, hv = history(z, u)
        v_fb = hv[0] if effects.feedback_delay_on == "position" else (1 - f) * hv[n] + f * hv[n + 1]
        return [(1 - f) * hx[n] + f * hx[n + 1], v_fb, table + (u[2] - u[0])]

    sensors = ct.nlsys(sensors_update, sensors_output, inputs=["x", "v", "xt"], outputs=["x_fb", "v_fb", "tool"],
                       states=1 + 2 * m, dt=DT, name="sensors")  # fmt: skip

    def friction_output(t, z, u, params):
        """Stick-slip (Kikuuwe): the force stopping the carriage (v1) at the next sample, within the bounds."""
        e, s, drive = effects, u[:n_plant], u[n_plant]
        v = s[1]
        other = e.offset_N - e.viscous_N_s_per_m / 1000 * v
        v_free = plant.A[1] @ s + plant.B[1, 0] * drive + plant.B[1, 1] * other
        level = e.coulomb_N + e.stribeck_N * np.exp(-((v / e.stribeck_velocity_mm_s) ** 2))
        return [other + np.clip(-v_free / plant.B[1, 1], -(level + e.asymmetry_N), level - e.asymmetry_N)]

    friction = ct.nlsys(None, friction_output, inputs=states + ["drive"], outputs=["F"], dt=DT, name="friction")
    vb = d.velocity_controller
    b, c, dd = (vb.B[0, 0], vb.C[0, 0], vb.D[0, 0]) if vb.nstates else (0.0, 0.0, vb.D[0, 0])
    limit = np.inf if servo.current_limit is None else servo.current_limit

    def velocity_update(t, z, u, params):
        raw = c * z[0] + dd * u[0] + u[1]
        return z if abs(raw) > limit and u[0] * raw > 0 else z + b * u[0]

    def velocity_output(t, z, u, params):
        return np.clip(c * z[0] + dd * u[0] + u[1], -limit, limit)

    velocity = ct.nlsys(velocity_update, velocity_output, inputs=["e_v", "i_ff"], outputs=["i_cmd"], states=1,
                        dt=DT, name="velocity")  # fmt: skip

    def gain(k, inp, out):
        return ct.ss(np.zeros((0, 0)), np.zeros((0, 1)), np.zeros((1, 0)), [[k]], DT, inputs=inp, outputs=out)

    blocks = [
        plant, sensors, friction, velocity,
        ct.summing_junction(["xr", "-x_fb"], "e_x"),
        gain(servo.kp, "e_x", "v_p"),
        gain(servo.vff, "vr", "v_ff"),
        ct.summing_junction(["v_p", "v_ff", "-v_fb"], "e_v"),
        gain(servo.aff * servo.mass / (1000 * servo.force_constant), "ar", "i_ff"),
    ]  # fmt: skip
    if servo.electrical:
        cc = d.current_controller
        blocks += [
            ct.ss(cc.A, cc.B, cc.C, cc.D, DT, inputs="e_i", outputs="drive", name="current"),
            ct.summing_junction(["i_cmd", "-i"], "e_i"),
        ]
    else:
        blocks.append(gain(1.0, "i_cmd", "drive"))
    loop = ct.interconnect(blocks, inplist=["xr", "vr", "ar"], outlist=["tool", "x_fb", "i_cmd"])
    x0 = np.zeros(loop.nstates)
    plant_states = [i for i, label in enumerate(loop.state_labels) if label.startswith("plant_")]
    # at rest in position at the first command, the loop holding what it reads there: the motor, or on a scale the
    # table, the motor then beyond it by half the play on the side the approach closed
    motor = start + effects.backlash_approach * h if servo.position_feedback == "scale" else start
    x0[plant_states[0]] = motor  # x1 (and x2)
    if effects.mode_freq_hz is not None:
        x0[plant_states[2]] = motor
    first = loop.state_labels.index("sensors_x[0]")
    x0[first] = motor - effects.backlash_approach * h  # the table, behind the motor after a move in +
    x0[first + 1 : first + 1 + m] = start  # the encoder history
    return loop, x0


REVERSING = dict(coulomb_N=150.0, viscous_N_s_per_m=400.0, stribeck_N=60.0, stribeck_velocity_mm_s=2.0,
                 asymmetry_N=25.0, offset_N=-40.0)  # fmt: skip
EFFECTS = {
    "none": LoopEffects(),
    "friction": LoopEffects(**REVERSING),
    "backlash_motor": LoopEffects(backlash_mm=0.004),
    "backlash_scale": LoopEffects(backlash_mm=0.004),  # on a scale: SCALE
    # the play closed at the start by a move in + (the table behind the motor), or on a scale by a move in -
    "backlash_motor_approached": LoopEffects(backlash_mm=0.004, backlash_approach=1),
    "backlash_scale_approached": LoopEffects(backlash_mm=0.004, backlash_approach=-1),  # SCALE
    "delay_whole": LoopEffects(feedback_delay_s=3 * DT),
    "delay_fraction": LoopEffects(feedback_delay_s=2.37 * DT),
    # the position loop late, the velocity loop on the motor now: z^-3 on the position reading alone, or interpolated
    "position_delay_whole": LoopEffects(feedback_delay_s=3 * DT, feedback_delay_on="position"),
    "position_delay_fraction": LoopEffects(feedback_delay_s=2.37 * DT, feedback_delay_on="position"),
    "mode": LoopEffects(**MODE),
    "quantisation": LoopEffects(quantum_mm=0.0005),
    "all": LoopEffects(backlash_mm=0.003, **REVERSING, feedback_delay_s=1.6 * DT, **MODE, quantum_mm=0.0002),
    "all_position_delay": LoopEffects(backlash_mm=0.003, **REVERSING, feedback_delay_s=1.6 * DT,
                                      feedback_delay_on="position", **MODE, quantum_mm=0.0002),
}


SCALE = ("backlash_scale", "backlash_scale_approached")  # the effects whose axis closes its position loop on a scale


@pytest.mark.parametrize("name", list(EFFECTS))
@pytest.mark.parametrize("extra", [dict(current_limit=3.0, vff=1.0, aff=0.8), dict(**ELECTRICAL)])
def test_kernel_equals_python_control_reference(name, extra):
    effects, servo = EFFECTS[name], axis(**extra, position_feedback="scale" if name in SCALE else "motor")
    n = 300
    t = np.arange(n) * DT
    w = 2 * np.pi * 40.0  # a 0.2 mm sine: reverses after 6.25 ms
    pos, vel, acc = 0.2 * np.sin(w * t), 0.2 * w * np.cos(w * t), -0.2 * w**2 * np.sin(w * t)
    result = run({"x": servo}, DT, pos[:, None], vel[:, None], acc[:, None], effects={"x": effects})
    loop, x0 = reference_loop(servo, effects, pos[0])
    ref = ct.input_output_response(loop, t, np.vstack([pos, vel, acc]), X0=x0).outputs
    np.testing.assert_allclose(result.position[:, 0], ref[0], rtol=0, atol=1e-9)
    np.testing.assert_allclose(result.encoder[:, 0], ref[1], rtol=0, atol=1e-9)
    np.testing.assert_allclose(result.current[:, 0], ref[2], rtol=0, atol=1e-9 * np.abs(ref[2]).max())
    if name != "none":
        plain = run({"x": servo}, DT, pos[:, None], vel[:, None], acc[:, None])
        assert np.abs(result.position - plain.position).max() > 1e-6  # the effect shows in 300 steps
    if effects.feedback_delay_on == "position":  # and it is not the delay of both loops
        both = run({"x": servo}, DT, pos[:, None], vel[:, None], acc[:, None],
                   effects={"x": replace(effects, feedback_delay_on="both")})
        assert np.abs(result.position - both.position).max() > 1e-6


STICKY = dict(coulomb_N=100.0, stribeck_N=80.0, stribeck_velocity_mm_s=1.0, asymmetry_N=10.0, offset_N=-20.0)


@pytest.mark.parametrize("effects", [LoopEffects(**STICKY), LoopEffects(**STICKY, **MODE)])
@pytest.mark.parametrize("extra", [dict(), dict(**ELECTRICAL)])
def test_kernel_equals_python_control_reference_sticking_and_breaking_away(effects, extra):
    # A 2 mm/s ramp from rest: the axis sticks until the loop's force passes the static friction, then slides.
    servo, n = axis(**extra), 400
    t = np.arange(n) * DT
    refs = 2.0 * t, np.full(n, 2.0), np.zeros(n)
    result = run({"x": servo}, DT, *(r[:, None] for r in refs), effects={"x": effects})
    stuck = np.abs(result.velocity[:, 0]) < 1e-9  # [mm/s]: stopped but for rounding
    assert 50 < np.argmin(stuck) < 200 and not stuck[np.argmin(stuck) :].any()  # sticks, breaks away, slides
    loop, x0 = reference_loop(servo, effects, 0.0)
    ref = ct.input_output_response(loop, t, np.vstack(refs), X0=x0).outputs
    np.testing.assert_allclose(result.position[:, 0], ref[0], rtol=0, atol=1e-9)
    np.testing.assert_allclose(result.current[:, 0], ref[2], rtol=0, atol=1e-9 * np.abs(ref[2]).max())


# --- physical signatures, measured from the simulated traces --------------------------------


def circle(radius, feed, turns, dt):
    """CCW circle from (R, 0) at `feed` [mm/s]: t, position, velocity, acceleration (N, 2)."""
    w = feed / radius
    t = np.arange(int(turns * 2 * np.pi / w / dt)) * dt
    u = np.column_stack([np.cos(w * t), np.sin(w * t)])
    return w, t, radius * u, radius * w * np.column_stack([-u[:, 1], u[:, 0]]), -radius * w**2 * u


def friction_bulge_peaks(coulomb, ti_values=(0.02, 0.01, 0.005)):
    """Peak radial bulge [mm] after X's reversal at 180° on a circle with Coulomb friction on X, per ti.

    X reverses at 180°: the velocity integrator must rebuild the friction force, so the radius bulges
    just after the reversal; away from reversals PI removes the friction offset entirely.
    """
    dt = 2e-4
    w, t, pos, vel, acc = circle(10.0, 2000 / 60, 1.25, dt)
    theta = np.degrees(w * t) % 360
    after = (t > 1.0) & (theta > 180) & (theta < 200)
    quiet = (t > 1.0) & (theta > 60) & (theta < 120)
    peaks = []
    for ti in ti_values:
        servo = axis(ti=ti)
        plain = run([servo, servo], dt, pos, vel, acc)
        rough = run([servo, servo], dt, pos, vel, acc, effects={"x": LoopEffects(coulomb_N=coulomb)})
        bulge = np.hypot(*rough.position.T) - np.hypot(*plain.position.T)
        peaks.append(np.abs(bulge[after]).max())
        assert peaks[-1] == np.abs(bulge[(t > 1.0) & (theta > 170) & (theta < 260)]).max()  # right after 180°
        assert np.abs(bulge[quiet]).max() < 0.02 * peaks[-1]
    return np.array(peaks)


def test_friction_spike_after_reversal_shrinks_with_integral_gain():
    peaks = friction_bulge_peaks(150.0)
    assert peaks[0] > peaks[1] > peaks[2] > 1e-3  # a few µm, shrinking with shorter ti


def test_friction_spike_grows_with_friction_level():
    np.testing.assert_array_less(friction_bulge_peaks(75.0, (0.01,)), friction_bulge_peaks(150.0, (0.01,)))


@pytest.mark.parametrize("direction", [1.0, -1.0])
def test_stuck_axis_breaks_away_at_the_static_friction(direction):
    # P-only loops at rest: the drive force is kf·kv·kp·(r - x). A slow command ramp raises it; the axis
    # stays exactly where it is while it is within the static bounds -(fc + fs + fa) .. fc + fs - fa and
    # moves the sample after it passes them, in the direction of the force.
    fc, fs, fa = 100.0, 60.0, 15.0
    servo = axis(ti=None)
    per_mm = servo.force_constant * servo.kv_mm * servo.kp  # drive force per mm of position error [N/mm]
    n = 2000
    ramp = direction * 0.05 * np.arange(n) / n  # 50 µm in 2000 steps: up to 360 N
    r = run([servo], DT, ramp[:, None], np.zeros((n, 1)), np.zeros((n, 1)),
            effects={"x": LoopEffects(coulomb_N=fc, stribeck_N=fs, stribeck_velocity_mm_s=1.0, asymmetry_N=fa)})
    static = fc + fs + direction * fa
    first = int(np.argmax(per_mm * np.abs(ramp) > static))  # the first sample whose force breaks away
    assert 100 < first < n - 100
    x = r.position[:, 0]
    assert np.abs(x[: first + 1]).max() < 1e-15  # stuck, but for rounding [mm]
    assert direction * x[first + 1] > 1e-10  # broken away


def test_p_only_velocity_loop_stops_short_by_the_friction_over_the_loop_stiffness():
    # A P velocity loop at rest pushes kf·kv·kp·e [N] for a position error e; the axis slides while that
    # exceeds Coulomb friction, so it settles e = fc / (kf·kv·kp) short of a step and stays (it would
    # creep on with a friction that does not stick).
    fc, servo = 150.0, axis(ti=None)
    short = fc / (servo.force_constant * servo.kv_mm * servo.kp)  # [mm]: 20.8 µm
    n = 10000
    step = np.full((n, 1), 1.0)
    step[:10] = 0.0  # at rest at 0, then a 1 mm step
    r = run([servo], DT, step, np.zeros((n, 1)), np.zeros((n, 1)), effects={"x": LoopEffects(coulomb_N=fc)})
    error = 1.0 - r.position[:, 0]
    assert error[-1] == pytest.approx(short, rel=1e-3)
    assert np.ptp(error[n // 2 :]) < 1e-6 * short  # stopped
    assert run([servo], DT, step, np.zeros((n, 1)), np.zeros((n, 1))).position[-1, 0] == pytest.approx(1.0, abs=1e-9)


@pytest.mark.parametrize("feedback", ["motor", "scale"])
def test_backlash_with_scale_feedback_and_stiction_hunts(feedback):
    # A 2 µm step at rest, PI velocity loop, static friction twice the Coulomb level, 10 µm of play.
    # On the scale the loop sees the table stop while the motor crosses the play: the integrator winds
    # up, the axis breaks away and overshoots, again and again (measured: 5.29 µm p2p every second).
    # On the motor encoder the motor hunts inside the play and the table stays put.
    dt, lost, n = 2e-4, 0.010, 15000
    step = np.where(np.arange(n) * dt > 0.1, 0.002, 0.0)[:, None]
    effects = LoopEffects(backlash_mm=lost, coulomb_N=100.0, stribeck_N=100.0, stribeck_velocity_mm_s=0.1)
    servo = axis(position_feedback=feedback)
    table = run([servo], dt, step, np.zeros_like(step), np.zeros_like(step), effects={"x": effects}).position[:, 0]
    p2p = [np.ptp(table[int(a / dt) : int((a + 1) / dt)]) for a in (1.0, 2.0)]
    if feedback == "scale":
        assert min(p2p) > 0.3 * lost and max(p2p) < lost  # a limit cycle of the order of the play
    else:
        assert max(p2p) < 1e-12


def back_and_forth(dt, stroke=1.0, move=0.3, dwell=0.6):
    """Forward `stroke` [mm] in `move` [s], dwell, back, dwell: position, velocity; index of both dwells' ends."""
    ramp = np.linspace(0.0, stroke, int(move / dt))
    n_dwell = int(dwell / dt)
    pos = np.concatenate([np.zeros(n_dwell), ramp, np.full(n_dwell, stroke), ramp[::-1], np.zeros(n_dwell)])
    return pos, np.gradient(pos, dt), 2 * n_dwell + ramp.size - 1, pos.size - 1


@pytest.mark.parametrize("feedback", ["motor", "scale"])
def test_backlash_lost_motion_at_reversal(feedback):
    dt, lost = 2e-4, 0.010
    pos, vel, forward_end, back_end = back_and_forth(dt)
    effects = {"x": LoopEffects(backlash_mm=lost)}
    r = run([axis(position_feedback=feedback)], dt, pos[:, None], vel[:, None], np.zeros((pos.size, 1)), effects=effects)
    table_error = r.position[:, 0] - pos
    encoder_error = r.encoder[:, 0] - pos
    # the loop settles what it sees onto the command in both dwells
    assert np.abs(encoder_error[[forward_end, back_end]]).max() < 1e-8
    if feedback == "motor":  # the table lags by half the play each way: a step of the lost motion between them
        assert table_error[back_end] - table_error[forward_end] == pytest.approx(lost, abs=1e-8)
    else:  # the scale sees the table, so the loop takes up the play
        assert np.abs(table_error[[forward_end, back_end]]).max() < 1e-8
    # after the reversal the table stands still until the motor has crossed the play
    reverse = int(np.argmax(vel < 0))
    table = r.position[reverse:, 0]
    stuck = int(np.argmax(table < table[0] - 1e-12))
    assert stuck > 5
    motor_travel = r.encoder[reverse, 0] - r.encoder[reverse + stuck, 0] if feedback == "motor" else None
    if motor_travel is not None:
        assert motor_travel == pytest.approx(lost, rel=0.05)


@settings(max_examples=20, deadline=None)
@given(periods=st.floats(0.0, 3.0), on=st.sampled_from(["both", "position"]), v=st.floats(-100.0, 100.0),
       kp=st.floats(20.0, 80.0))
def test_feedback_delay_ramp(periods, on, v, kp):
    # Steady ramp, P-PI: the velocity loop's integrator settles where the velocity read is v (a constant velocity
    # read late is still v), so the position loop drives what it sees to kp·(r - x_fb) = v: the encoder it reads
    # lags by v/kp. That reading is `delay` old, so the axis itself is v·delay further on: lag v/kp - v·delay, a
    # position gain kp/(1 - kp·delay), whether the velocity loop reads late too or not.
    dt, delay = 1e-4, periods * 1e-4
    t = np.arange(20000) * dt
    ramp = (v * t)[:, None]
    r = run([axis(kp=kp)], dt, ramp, np.full_like(ramp, v), np.zeros_like(ramp),
            effects={"x": LoopEffects(feedback_delay_s=delay, feedback_delay_on=on)})  # fmt: skip
    assert ramp[-1, 0] - r.encoder[-1, 0] == pytest.approx(v / kp, rel=1e-9, abs=1e-12)
    assert ramp[-1, 0] - r.position[-1, 0] == pytest.approx(v / kp - v * delay, rel=1e-9, abs=1e-12)


def fft_peak_hz(signal, dt, above_hz):
    """Frequency [Hz] of the largest spectral peak above `above_hz`, cubic trend removed, Hann window."""
    k = np.arange(signal.size)
    signal = signal - np.polyval(np.polyfit(k, signal, 3), k)
    pad = 64 * signal.size
    spectrum = np.abs(np.fft.rfft(signal * np.hanning(signal.size), pad))
    freq = np.fft.rfftfreq(pad, dt)
    spectrum[freq < above_hz] = 0.0
    return freq[np.argmax(spectrum)]


@pytest.mark.parametrize("freq", [60.0, 120.0])
def test_mode_rings_at_its_frequency_after_acceleration(freq):
    # Accelerate at 2 m/s² for 25 ms, then cruise: the tool-side mass rings. Its frequency lies between
    # the mode with the carriage held (f·sqrt(1 - ζ²)) and with the carriage free (f/sqrt(1 - r)).
    dt, a, t1, zeta, ratio = 1e-4, 2000.0, 0.025, 0.02, 0.02
    t = np.arange(6000) * dt
    acc = np.where(t < t1, a, 0.0)
    vel = np.where(t < t1, a * t, a * t1)
    pos = np.where(t < t1, a * t**2 / 2, a * t1**2 / 2 + a * t1 * (t - t1))
    refs = pos[:, None], vel[:, None], acc[:, None]
    effects = LoopEffects(mode_freq_hz=freq, mode_damping_ratio=zeta, mode_mass_ratio=ratio)
    ringing = run([axis()], dt, *refs, effects={"x": effects}).position[:, 0] - run([axis()], dt, *refs).position[:, 0]
    measured = fft_peak_hz(ringing[t > t1], dt, above_hz=20.0)
    assert freq * np.sqrt(1 - zeta**2) * 0.995 < measured < freq / np.sqrt(1 - ratio) * 1.005
    assert np.abs(ringing[t > t1]).max() > 0.5 * a / (2 * np.pi * freq) ** 2  # about a/ω² [mm]


def slow_ramp(n=30000, v=7.3):
    t = np.arange(n) * DT
    ramp = (v * t)[:, None]
    return ramp, np.full_like(ramp, v), np.zeros_like(ramp)


def test_quantised_encoder():
    # The loop sees the encoder rounded to the quantum: an error uniform on ±q/2, RMS q/√12.
    q = 0.001
    r = run([axis()], DT, *slow_ramp(), effects={"x": LoopEffects(quantum_mm=q)})
    np.testing.assert_allclose(r.encoder / q, np.round(r.encoder / q), rtol=0, atol=1e-6)
    error = (r.encoder - r.position)[1000:, 0]
    assert np.abs(error).max() <= q / 2 * (1 + 1e-9)
    assert np.sqrt(np.mean(error**2)) == pytest.approx(q / np.sqrt(12), rel=0.02)


def test_measurement_noise_rms_and_determinism():
    noise = 0.002
    plain = run([axis(), axis()], DT, *(np.tile(r, 2) for r in slow_ramp()))
    noisy = [
        run([axis(), axis()], DT, *(np.tile(r, 2) for r in slow_ramp()),
            effects={"x": LoopEffects(noise_mm=noise, seed=seed), "y": LoopEffects(noise_mm=noise, seed=seed)})
        for seed in (7, 7, 8)
    ]  # fmt: skip
    recorded = noisy[0].position - plain.position
    assert np.sqrt(np.mean(recorded**2, axis=0)) == pytest.approx([noise, noise], rel=0.02)
    assert np.abs(recorded.mean(axis=0)).max() < 0.03 * noise
    assert abs(np.corrcoef(recorded.T)[0, 1]) < 0.03  # the axes' noise is independent
    np.testing.assert_array_equal(noisy[0].encoder, plain.encoder)  # outside the loop
    np.testing.assert_array_equal(noisy[0].position, noisy[1].position)  # same seed, same noise
    assert np.abs(noisy[2].position - noisy[0].position).max() > noise


def test_encoder_noise_is_inside_the_loop_as_python_control_says():
    """Noise n on the encoder the loop closes on: x_fb = x + n, so the axis follows x_ref − n through its
    closed loop (python-control's response of the sampled cascade to −n), and the recorded position is x itself."""
    noise, n_steps = 0.002, 4000
    servo = axis()
    ref = np.zeros((n_steps, 1))
    r = run([servo], DT, ref, ref, ref, effects={"x": LoopEffects(noise_mm=noise, noise_at="encoder", seed=5)})
    n = r.encoder[:, 0] - r.position[:, 0]  # what the loop read beyond the axis position
    assert np.sqrt(np.mean(n**2)) == pytest.approx(noise, rel=0.05) and abs(np.corrcoef(n[1:], n[:-1])[0, 1]) < 0.05
    loop = servo.discretize(DT).closed_loop
    position_loop = ct.ss(loop.A, loop.B[:, [0]], loop.C[[0]], loop.D[[0]][:, [0]], DT)
    expected = ct.forced_response(position_loop, np.arange(n_steps) * DT, -n).outputs
    assert np.abs(r.position[:, 0]).max() > 0.02 * noise  # the axis moves with the noise it is fed back
    np.testing.assert_allclose(r.position[:, 0], expected, rtol=0, atol=1e-12)
    again = run([servo], DT, ref, ref, ref, effects={"x": LoopEffects(noise_mm=noise, noise_at="encoder", seed=5)})
    np.testing.assert_array_equal(again.encoder, r.encoder)  # the same seed, the same noise
    with pytest.raises(ValueError, match='noise_at must be "recorded" or "encoder"'):
        LoopEffects(noise_mm=noise, noise_at="loop")


@pytest.mark.parametrize("effects, y, separate", [
    ({}, {}, False),
    ({"y": LoopEffects(backlash_mm=0.004, coulomb_N=50.0)}, dict(position_feedback="scale"), False),  # the scale reads the table
    ({"y": LoopEffects(backlash_mm=0.004)}, {}, True),  # the motor encoder does not
    ({"y": LoopEffects(quantum_mm=1e-4)}, {}, True),
    ({"x": LoopEffects(feedback_delay_s=0.5 * DT)}, {}, True),
    ({"x": LoopEffects(mode_freq_hz=80.0)}, {}, True),
    ({"x": LoopEffects(noise_mm=1e-4)}, {}, True),
])  # fmt: skip
def test_the_encoder_reads_the_tool_position_only_without_a_sensor_effect_between(effects, y, separate):
    pos, vel = back_and_forth(DT)[:2]
    refs = [np.column_stack([r, 0.5 * r]) for r in (pos, vel, np.gradient(vel, DT))]
    servos = {"x": axis(), "y": axis(**y)}
    r = run(servos, DT, *refs, effects=effects)
    assert np.array_equal(r.encoder, r.position) != separate
    # the batch writes the two signals apart, as run() does: the same bits
    rows = np.array([[pack(servos[name], DT, effects.get(name, LoopEffects())) for name in ("x", "y")]])
    batch = run_batch(rows, DT, *refs, outputs=("tool", "encoder"))
    assert np.array_equal(batch["tool"][0], batch["encoder"][0]) != separate
    np.testing.assert_array_equal(batch["encoder"][0].view(np.uint64), r.encoder.view(np.uint64))
    np.testing.assert_array_equal(batch["tool"][0].view(np.uint64), r.position.view(np.uint64))


# --- batches ---------------------------------------------------------------------------------


def batch_case():
    servos = {"x": axis(**ELECTRICAL), "y": axis(kp=30.0, vff=1.0, current_limit=4.0), "z": axis(ti=None)}
    variants = [
        {},
        {"x": EFFECTS["all"], "y": LoopEffects(backlash_mm=0.005, coulomb_N=80.0, noise_mm=0.001, seed=3)},
        {"y": LoopEffects(feedback_delay_s=5.5 * DT, **MODE), "z": LoopEffects(quantum_mm=0.0001, noise_mm=0.002)},
    ]
    w, t, pos, vel, acc = circle(5.0, 3000 / 60, 0.3, DT)
    refs = tuple(np.column_stack([r, 0.1 * r[:, 0]]) for r in (pos, vel, acc))
    return servos, variants, refs


def test_batch_row_equals_single_run_bit_for_bit():
    servos, variants, refs = batch_case()
    rows = np.array([[pack(s, DT, v.get(name, LoopEffects())) for name, s in servos.items()] for v in variants])
    assert rows.shape == (3, 3, NPAR)
    batch = run_batch(rows, DT, *refs, outputs=kernel.BATCH_OUTPUTS)
    decimated = run_batch(rows, DT, *refs, outputs=("tool", "current"), every=7, dtype=np.float32)
    for b, effects in enumerate(variants):
        single = run(servos, DT, *refs, effects=effects)
        for name, field in [("tool", "position"), ("encoder", "encoder"), ("velocity", "velocity"),
                            ("current", "current"), ("saturated", "saturated")]:  # fmt: skip
            np.testing.assert_array_equal(batch[name][b], getattr(single, field), err_msg=name)
        np.testing.assert_array_equal(batch["saturated_count"][b], single.saturated.sum(axis=0))
        np.testing.assert_array_equal(decimated["tool"][b], single.position[::7].astype(np.float32))
        np.testing.assert_array_equal(decimated["current"][b], single.current[::7].astype(np.float32))
    np.testing.assert_array_equal(decimated["t"], np.arange(refs[0].shape[0])[::7] * DT)
    assert set(decimated) == {"t", "tool", "current", "saturated_count", "diverged_step"}
    assert (batch["diverged_step"] == -1).all()
    assert batch["saturated_count"][:, 1].min() > 0  # the limit is reached: anti-windup is exercised


def random_effects(rng):
    """In-loop and sensor effects of one axis, each on or off and of random size (a lane of its own), and where its
    position loop reads: ``(position_feedback, LoopEffects)``."""
    kw, feedback = {}, "motor"
    if rng.random() < 0.5:
        kw.update(backlash_mm=rng.uniform(0.001, 0.01), backlash_approach=int(rng.choice([0, 1, -1])))
        feedback = str(rng.choice(["motor", "scale"]))
    if rng.random() < 0.6:
        kw.update(coulomb_N=rng.uniform(10.0, 150.0), viscous_N_s_per_m=rng.choice([0.0, rng.uniform(0.0, 500.0)]),
                  asymmetry_N=rng.choice([0.0, rng.uniform(-10.0, 10.0)]),
                  offset_N=rng.choice([0.0, rng.uniform(-30.0, 30.0)]))  # fmt: skip
        if rng.random() < 0.5:
            kw.update(stribeck_N=rng.uniform(5.0, 60.0), stribeck_velocity_mm_s=rng.uniform(0.5, 5.0))
    elif rng.random() < 0.2:
        kw.update(offset_N=rng.uniform(-30.0, 30.0))
    if rng.random() < 0.4:
        kw.update(feedback_delay_s=rng.choice([rng.integers(1, 6), rng.uniform(0.1, 5.0)]) * DT,
                  feedback_delay_on=str(rng.choice(["both", "position"])))
    if rng.random() < 0.4:
        kw.update(mode_freq_hz=rng.uniform(40.0, 200.0), mode_damping_ratio=rng.uniform(0.02, 0.2),
                  mode_mass_ratio=rng.uniform(0.05, 0.4))
    if rng.random() < 0.4:
        kw.update(quantum_mm=rng.choice([1e-4, 5e-4, 1e-3]))
    if rng.random() < 0.4:
        kw.update(noise_mm=rng.uniform(1e-4, 2e-3), seed=int(rng.integers(2**53)))
    return feedback, LoopEffects(**kw)


@pytest.mark.parametrize("threads, n_variants, pushed", [
    (1, 5, False), (1, 64, True), (1, 70, False), (2, 5, True), (2, 64, False), (2, 70, True)])  # fmt: skip
def test_every_batch_row_equals_its_single_run_bit_for_bit(threads, n_variants, pushed):
    # Variants in the lanes of blocks (64: blocks of kernel.LANES = 32; 70: narrower ones; 5: a small one per thread):
    # each lane mixes effects and values with its neighbours', and a block skips only what none of its lanes has;
    # every row must still be run() of that row exactly, with and without a known external force.
    servos, _, refs = batch_case()
    refs = tuple(r[:1500] for r in refs)
    force = None
    if pushed:  # pulses of ±200 N on every axis, plus a ramp of force on x: the stick-slip sees them
        force = 200.0 * np.sign(np.sin(np.arange(1500)[:, None] * DT * 2 * np.pi * np.array([7.0, 11.0, 13.0])))
        force[:, 0] += np.linspace(0.0, 150.0, 1500)
    rng = np.random.default_rng(n_variants)
    drawn = [{name: random_effects(rng) for name in servos} for _ in range(n_variants)]
    drawn[0] = dict.fromkeys(servos, ("motor", LoopEffects()))  # one variant without any effect
    variants = [{name: e for name, (_, e) in v.items()} for v in drawn]
    axes = [{name: replace(s, position_feedback=v[name][0]) for name, s in servos.items()} for v in drawn]
    rows = np.array([[pack(s, DT, v[name]) for name, s in a.items()] for a, v in zip(axes, variants)])
    previous = numba.get_num_threads()
    numba.set_num_threads(min(threads, numba.config.NUMBA_NUM_THREADS))
    try:
        batch = run_batch(rows, DT, *refs, outputs=kernel.BATCH_OUTPUTS, force=force)
        decimated = run_batch(rows, DT, *refs, outputs=("tool", "encoder"), every=3, dtype=np.float32, force=force)
    finally:
        numba.set_num_threads(previous)
    for b, effects in enumerate(variants):
        single = run(axes[b], DT, *refs, effects=effects, force=force)
        for name, field in [("tool", "position"), ("encoder", "encoder"), ("velocity", "velocity"),
                            ("current", "current"), ("saturated", "saturated")]:  # fmt: skip
            np.testing.assert_array_equal(batch[name][b], getattr(single, field), err_msg=f"{name}, variant {b}")
        np.testing.assert_array_equal(batch["saturated_count"][b], single.saturated.sum(axis=0))
        np.testing.assert_array_equal(decimated["tool"][b], single.position[::3].astype(np.float32))
        np.testing.assert_array_equal(decimated["encoder"][b], single.encoder[::3].astype(np.float32))
    assert (batch["diverged_step"] == -1).all()
    every_effect = ("backlash_mm", "coulomb_N", "stribeck_N", "feedback_delay_s", "mode_freq_hz", "quantum_mm",
                    "noise_mm")  # fmt: skip
    for effect in every_effect:
        assert any(getattr(e, effect) for v in variants[1:] for e in v.values()), effect  # every effect is there
    assert {e.feedback_delay_on for v in variants for e in v.values() if e.feedback_delay_s} == {"both", "position"}


def test_rigid_lanes_equal_single_runs_to_the_last_bit_and_the_sign_of_zero():
    # Blocks whose axes have no structural mode and no current loop in any lane step the plant rows without their
    # zero terms (kernel._rigid_row): still run() exactly, down to the sign of a zero (compared as bit patterns);
    # the reference stands at -0.0 first, where the signs of zeros are at stake.
    servos = {"x": axis(), "y": axis(kp=30.0, vff=1.0, current_limit=4.0), "z": axis(ti=None)}
    _, _, refs = batch_case()
    refs = tuple(r[:1200].copy() for r in refs)
    for r in refs:
        r[:300] = -0.0
        r[300:] -= r[300]
    rng = np.random.default_rng(7)
    drawn = [{name: random_effects(rng) for name in servos} for _ in range(9)]
    drawn[0] = dict.fromkeys(servos, ("motor", LoopEffects()))
    variants = [{name: replace(e, mode_freq_hz=None) for name, (_, e) in v.items()} for v in drawn]
    axes = [{name: replace(s, position_feedback=v[name][0]) for name, s in servos.items()} for v in drawn]
    rows = np.array([[pack(s, DT, v[name]) for name, s in a.items()] for a, v in zip(axes, variants)])
    batch = run_batch(rows, DT, *refs, outputs=kernel.BATCH_OUTPUTS)
    for b, effects in enumerate(variants):
        single = run(axes[b], DT, *refs, effects=effects)
        for name, field in [("tool", "position"), ("encoder", "encoder"), ("velocity", "velocity"),
                            ("current", "current")]:  # fmt: skip
            got, want = batch[name][b], getattr(single, field)
            np.testing.assert_array_equal(got.view(np.uint64), want.view(np.uint64), err_msg=f"{name}, variant {b}")
        np.testing.assert_array_equal(batch["saturated"][b], single.saturated)
    assert ((batch["encoder"] == 0.0) & np.signbit(batch["encoder"])).any()  # there were signs of zeros to get right
    # where the encoder reads the tool exactly, it reads -0 where the tool stands at +0 (the table plus the
    # deflection's +0): run() keeps the two apart as the lanes do
    assert ((batch["encoder"] == 0.0) & np.signbit(batch["encoder"]) & ~np.signbit(batch["tool"])).any()


def test_switching_effects_and_coupling_does_not_compile():
    servos, variants, refs = batch_case()
    run(servos, DT, *refs)
    compiled = len(kernel._variant.signatures)
    for effects in variants:
        run(servos, DT, *refs, effects=effects)
        for estimator in kernel.COUPLING_ESTIMATORS:
            run(servos, DT, *refs, coupling=kernel.Coupling(estimator, refs[0], kp=20.0, ki=100.0), effects=effects)
    assert len(kernel._variant.signatures) == compiled


def test_importing_the_kernel_does_not_import_python_control():
    code = "import sys, contoursim.kernel; print('control' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"


# --- bad input -------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "kw, message",
    [
        (dict(backlash_mm=-0.001), "backlash_mm"),
        (dict(coulomb_N=float("nan")), "coulomb_N"),
        (dict(stribeck_velocity_mm_s=0.0), "stribeck_velocity_mm_s"),
        (dict(mode_freq_hz=-5.0), "mode_freq_hz"),
        (dict(mode_damping_ratio=0.0), "mode_damping_ratio"),
        (dict(mode_mass_ratio=1.0), "mode_mass_ratio"),
        (dict(mode_mass_ratio=0.0), "mode_mass_ratio"),
        (dict(noise_mm=-1.0), "noise_mm"),
        (dict(seed=-1), "seed"),
        (dict(feedback_delay_on="velocity"), "feedback_delay_on"),
    ],
)
def test_bad_effects_name_the_parameter(kw, message):
    with pytest.raises(ValueError, match=message):
        LoopEffects(**kw)


@pytest.mark.parametrize("kw, message", [(dict(asymmetry_N="10"), "asymmetry_N"), (dict(seed=1.5), "seed")])
def test_wrong_types_of_effects_are_type_errors(kw, message):
    with pytest.raises(TypeError, match=message):
        LoopEffects(**kw)


def test_delay_beyond_the_buffer_is_refused():
    pack(axis(), DT, LoopEffects(feedback_delay_s=MAX_DELAY_SAMPLES * DT))
    with pytest.raises(ValueError, match=rf"feedback_delay_s = 0.0064 s is 64 servo periods.*at most {MAX_DELAY_SAMPLES}"):
        pack(axis(), DT, LoopEffects(feedback_delay_s=64 * DT))


def test_bad_run_and_batch_arguments():
    ref = np.zeros((10, 1))
    with pytest.raises(ValueError, match="effects name axis 'y', which is not one of the axes x"):
        run([axis()], DT, ref, ref, ref, effects={"y": LoopEffects()})
    with pytest.raises(TypeError, match="effects must be a LoopEffects"):
        run([axis()], DT, ref, ref, ref, effects={"x": dict(backlash_mm=0.01)})
    rows = pack(axis(), DT)[None, None, :]
    with pytest.raises(ValueError, match=rf"rows must have shape \(B, n_axes, {NPAR}\)"):
        run_batch(rows[..., :-1], DT, ref, ref, ref)
    with pytest.raises(ValueError, match="outputs must name signals from tool"):
        run_batch(rows, DT, ref, ref, ref, outputs=("position",))
    with pytest.raises(ValueError, match="every must be positive"):
        run_batch(rows, DT, ref, ref, ref, every=0)
    with pytest.raises(TypeError, match="every must be an integer"):
        run_batch(rows, DT, ref, ref, ref, every=2.0)
    with pytest.raises(ValueError, match="dtype must be float64 or float32"):
        run_batch(rows, DT, ref, ref, ref, dtype=np.int32)
    with pytest.raises(ValueError, match=r"ref_vel must have shape \(10, 1\)"):
        run_batch(rows, DT, ref, ref[:5], ref)


@pytest.mark.parametrize("lanes", [0, kernel.LANES + 1])
def test_lanes_refuse_a_lane_count_their_arrays_do_not_hold(lanes):
    # _lanes holds its lanes' states in arrays of LANES lanes: more rows would be stepped beyond them (numba checks no
    # bounds), none would leave the outputs unwritten.
    ref = np.zeros((10, 1))
    rows = np.tile(pack(axis(), DT), (lanes, 1, 1))
    tool, none = np.empty((lanes, 10, 1)), np.empty((lanes, 0, 1))
    with pytest.raises(ValueError, match=rf"_lanes steps 1 to {kernel.LANES} variants"):
        kernel._lanes(rows, ref, ref, ref, np.empty((0, 1)), 1, tool, none, none, none, np.empty((lanes, 0, 1), bool),
                      np.empty((lanes, 1, 3), np.int64))  # fmt: skip


def test_lanes_refuse_outputs_of_another_lane_count():
    ref = np.zeros((10, 1))
    rows = np.tile(pack(axis(), DT), (4, 1, 1))
    none = np.empty((4, 0, 1))
    for tool, status in [(np.empty((3, 10, 1)), np.empty((4, 1, 3), np.int64)),
                         (np.empty((4, 10, 1)), np.empty((5, 1, 3), np.int64))]:  # fmt: skip
        with pytest.raises(ValueError, match="with as many rows of status and of each output"):
            kernel._lanes(rows, ref, ref, ref, np.empty((0, 1)), 1, tool, none, none, none, np.empty((4, 0, 1), bool),
                          status)  # fmt: skip


def test_diverging_variants_are_reported():
    ref = np.zeros((80000, 1))  # the delayed loop grows by about 1e12 per 0.2 s: inf within 8 s
    ref[1:] = 0.01
    with pytest.raises(UnstableLoopError, match=r"simulation of axis 'x' diverged by t = .* s \(step \d+\)"):
        run([axis()], DT, ref, np.zeros_like(ref), np.zeros_like(ref),
            effects={"x": LoopEffects(feedback_delay_s=MAX_DELAY_SAMPLES * DT)})  # fmt: skip
    rows = np.array([[pack(axis(), DT)], [pack(axis(kv=100 * KV), DT)]])  # pack does not check: kv far too high
    result = run_batch(rows, DT, ref, np.zeros_like(ref), np.zeros_like(ref))
    assert result["diverged_step"][0, 0] == -1 and result["diverged_step"][1, 0] > 0
    assert np.isfinite(result["tool"][0]).all()


# --- the cheap stability check of a packed variant --------------------------------------------


@pytest.mark.parametrize("extra", [dict(), dict(ti=None), dict(**ELECTRICAL), dict(kp=2000.0)])
def test_spectral_radius_equals_python_control_closed_loop_poles(extra):
    servo = axis(**extra)
    want = np.abs(servo.discretize(DT).closed_loop.poles()).max()
    assert kernel.spectral_radius(pack(servo, DT)) == pytest.approx(want, abs=1e-12)


@pytest.mark.parametrize("delay", [30.0, 37.5, 45.0])
@pytest.mark.parametrize("kp, on", [(40.0, "both"), (400.0, "position")])
def test_spectral_radius_with_delay_is_the_simulated_growth_rate(delay, kp, on):
    # A loop made unstable by the feedback delay: its simulated oscillation grows by the radius per step. (Late on
    # the position loop only, the velocity loop stays stable: it takes a stiffer position loop to ring.)
    row = pack(axis(kp=kp), DT, LoopEffects(feedback_delay_s=delay * DT, feedback_delay_on=on))
    rho = kernel.spectral_radius(row)
    assert rho > 1.0
    ref = np.full((12000, 1), 1e-6)
    ref[0] = 0.0
    x = run_batch(row[None, None], DT, ref, np.zeros_like(ref), np.zeros_like(ref))["tool"][0, :, 0] - 1e-6
    window, k1, k2 = 500, 6000, 11000
    growth = (np.abs(x[k2 : k2 + window]).max() / np.abs(x[k1 : k1 + window]).max()) ** (1 / (k2 - k1))
    assert growth == pytest.approx(rho, rel=2e-4)
    assert kernel.spectral_radius(pack(axis(), DT, LoopEffects(feedback_delay_s=3 * DT))) < 1.0
