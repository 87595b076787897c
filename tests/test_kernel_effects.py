"""In-loop effects of the kernel: packed rows, python-control references, physical signatures, batches."""

import subprocess
import sys

import control as ct
import numpy as np
import pytest

from contoursim import kernel
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
@pytest.mark.parametrize("effects", [LoopEffects(), LoopEffects(**MODE)])
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
    plant = ct.ss(plant.A, plant.B, plant.C, plant.D, DT, inputs=["drive", "F"], outputs=plant.output_labels,
                  name="plant")  # fmt: skip
    d = servo.discretize(DT)
    h, q = effects.backlash_mm / 2, effects.quantum_mm
    delay = effects.feedback_delay_s / DT
    n, f = int(np.floor(delay + 1e-9)), delay - np.floor(delay + 1e-9)
    m = n + 2  # remembered past samples

    def history(z, u):
        """Table, encoder, and the (current, past...) encoder and velocity histories."""
        x, v = u[0], u[1]
        table = min(max(z[0], x - h), x + h)
        enc = table if effects.backlash_feedback == "scale" else x
        if q:
            enc = q * np.floor(enc / q + 0.5)
        return table, enc, np.concatenate([[enc], z[1 : 1 + m]]), np.concatenate([[v], z[1 + m :]])

    def sensors_update(t, z, u, params):
        table, enc, hx, hv = history(z, u)
        return np.concatenate([[table], hx[:m], hv[:m]])

    def sensors_output(t, z, u, params):
        table, enc, hx, hv = history(z, u)
        return [(1 - f) * hx[n] + f * hx[n + 1], (1 - f) * hv[n] + f * hv[n + 1], table + (u[2] - u[0])]

    sensors = ct.nlsys(sensors_update, sensors_output, inputs=["x", "v", "xt"], outputs=["x_fb", "v_fb", "tool"],
                       states=1 + 2 * m, dt=DT, name="sensors")  # fmt: skip

    def friction_output(t, z, u, params):
        e = effects
        v_eps = max(kernel.FRICTION_VELOCITY_MM_S, 2000 * (e.coulomb_N + e.stribeck_N + abs(e.asymmetry_N)) * DT
                    / (servo.mass * (1 - e.mode_mass_ratio) if e.mode_freq_hz else servo.mass))  # fmt: skip
        s = np.tanh(u[0] / v_eps)
        level = e.coulomb_N + e.stribeck_N * np.exp(-((u[0] / e.stribeck_velocity_mm_s) ** 2))
        return [e.offset_N - level * s - e.viscous_N_s_per_m / 1000 * u[0] - e.asymmetry_N * abs(s)]

    friction = ct.nlsys(None, friction_output, inputs=["v"], outputs=["F"], dt=DT, name="friction")
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
    x0[plant_states[0]] = start  # at rest at the first command: x1 (and x2)
    if effects.mode_freq_hz is not None:
        x0[plant_states[2]] = start
    first = loop.state_labels.index("sensors_x[0]")
    x0[first : first + 1 + m] = start  # the table and the encoder history
    return loop, x0


REVERSING = dict(coulomb_N=150.0, viscous_N_s_per_m=400.0, stribeck_N=60.0, stribeck_velocity_mm_s=2.0,
                 asymmetry_N=25.0, offset_N=-40.0)  # fmt: skip
EFFECTS = {
    "none": LoopEffects(),
    "friction": LoopEffects(**REVERSING),
    "backlash_motor": LoopEffects(backlash_mm=0.004),
    "backlash_scale": LoopEffects(backlash_mm=0.004, backlash_feedback="scale"),
    "delay_whole": LoopEffects(feedback_delay_s=3 * DT),
    "delay_fraction": LoopEffects(feedback_delay_s=2.37 * DT),
    "mode": LoopEffects(**MODE),
    "quantisation": LoopEffects(quantum_mm=0.0005),
    "all": LoopEffects(backlash_mm=0.003, **REVERSING, feedback_delay_s=1.6 * DT, **MODE, quantum_mm=0.0002),
}


@pytest.mark.parametrize("name", list(EFFECTS))
@pytest.mark.parametrize("extra", [dict(current_limit=3.0, vff=1.0, aff=0.8), dict(**ELECTRICAL)])
def test_kernel_equals_python_control_reference(name, extra):
    effects, servo = EFFECTS[name], axis(**extra)
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
