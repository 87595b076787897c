"""Speed of the servo stepping kernel against python-control simulating the same loop.

Three axes (P-PI cascade each: m = 300 kg, kf = 900 N/A, kv = 200 A·s/m,
Ti = 10 ms, Kp = 40 1/s) follow a helix (R = 50 mm, F = 5 m/min, 1 mm pitch
per turn) sampled at 5 kHz:

* kernel, plain cascade: ``contoursim.kernel.run`` end to end (argument
  checks, packing, stepping, result), 300,000 steps = 60 s, after a warm-up
  call so that compile time and the per-axis loop checks are excluded; best
  of 5;
* kernel, with a 5 A current limit (clamping at the start) and full velocity
  and acceleration feedforward: the same;
* python-control: ``control.input_output_response`` at its default settings
  on a ``control.interconnect`` of the same sampled loop — the discrete
  plant and Tustin PI blocks of ``AxisServo.discretize``, the velocity
  controller with saturation and anti-windup as a discrete ``nlsys`` — for
  the first 1,000 steps (best of 2); its axis positions are compared with
  the kernel's to show that it is the same loop.

Figures are axis-steps per second: simulated samples x axes / wall seconds.
Run: python benchmarks/bench_kernel.py
"""

import time

import control as ct
import numpy as np

from contoursim.kernel import run
from contoursim.servo import AxisServo

DT = 2e-4  # 5 kHz
N = 300_000  # 60 s
N_PYTHON_CONTROL = 1_000
AXES = ("x", "y", "z")
BASE = dict(mass=300.0, force_constant=900.0, kv=200.0, ti=0.01, kp=40.0)


def helix(n):
    """Reference position, velocity, acceleration, shape (n, 3) [mm, mm/s, mm/s^2]."""
    radius, feed, pitch = 50.0, 5000.0 / 60.0, 1.0
    w = feed / radius
    t = np.arange(n) * DT
    c, s = np.cos(w * t), np.sin(w * t)
    vz = pitch * w / (2 * np.pi)
    pos = np.column_stack([radius * c, radius * s, vz * t])
    vel = np.column_stack([-radius * w * s, radius * w * c, np.full(n, vz)])
    acc = np.column_stack([-radius * w**2 * c, -radius * w**2 * s, np.zeros(n)])
    return pos, vel, acc


def best_of(fn, repeat):
    times = []
    for _ in range(repeat):
        start = time.perf_counter()
        result = fn()
        times.append(time.perf_counter() - start)
    return min(times), result


def gain(k, inp, out):
    return ct.ss(np.zeros((0, 0)), np.zeros((0, 1)), np.zeros((1, 0)), [[k]], DT, inputs=inp, outputs=out)


def velocity_controller(servo, name):
    """Discrete PI + acceleration feedforward with current clamp and conditional integration, as an nlsys."""
    block = servo.discretize(DT).velocity_controller
    b, c, d = block.B[0, 0], block.C[0, 0], block.D[0, 0]
    limit = servo.current_limit

    def unclamped(z, u):
        return c * z[0] + d * u[0] + u[1]

    def update(t, z, u, params):
        raw = unclamped(z, u)
        clamped = abs(raw) > limit
        return z if clamped and u[0] * raw > 0 else z + b * u[0]

    def output(t, z, u, params):
        return np.clip(unclamped(z, u), -limit, limit)

    return ct.nlsys(update, output, inputs=[f"{name}_e_v", f"{name}_i_ff"], outputs=f"{name}_i_cmd",
                    states=1, dt=DT, name=f"{name}_velocity")  # fmt: skip


def python_control_model(servos):
    """The three sampled axes wired by signal name; inputs per axis x_ref, v_ref, a_ref; outputs x."""
    blocks, inputs, outputs = [], [], []
    for name, servo in zip(AXES, servos):
        plant = servo.discretize(DT).plant
        blocks += [
            ct.ss(plant.A, plant.B, plant.C, plant.D, DT, inputs=f"{name}_i_cmd", outputs=[f"{name}_x", f"{name}_v"],
                  states=["x", "v"], name=f"{name}_plant"),
            velocity_controller(servo, name),
            ct.summing_junction([f"{name}_x_ref", f"-{name}_x"], f"{name}_e_x"),
            gain(servo.kp, f"{name}_e_x", f"{name}_v_p"),
            gain(servo.vff, f"{name}_v_ref", f"{name}_v_ff"),
            ct.summing_junction([f"{name}_v_p", f"{name}_v_ff", f"-{name}_v"], f"{name}_e_v"),
            gain(servo.aff * servo.mass / (1000.0 * servo.force_constant), f"{name}_a_ref", f"{name}_i_ff"),
        ]
        inputs += [f"{name}_x_ref", f"{name}_v_ref", f"{name}_a_ref"]
        outputs.append(f"{name}_x")
    return ct.interconnect(blocks, inplist=inputs, outlist=outputs)


def main():
    pos, vel, acc = helix(N)
    plain = [AxisServo(**BASE)] * 3
    loaded = [AxisServo(**BASE, current_limit=5.0, vff=1.0, aff=1.0)] * 3
    axis_steps = N * len(AXES)

    run(plain, DT, pos, vel, acc)  # warm-up: compile (or load the cache) and check the loops
    run(loaded, DT, pos, vel, acc)
    t_plain, _ = best_of(lambda: run(plain, DT, pos, vel, acc), 5)
    t_loaded, kernel_result = best_of(lambda: run(loaded, DT, pos, vel, acc), 5)

    model = python_control_model(loaded)
    n = N_PYTHON_CONTROL
    t = np.arange(n) * DT
    u = np.column_stack([pos[:n], vel[:n], acc[:n]])[:, [0, 3, 6, 1, 4, 7, 2, 5, 8]].T  # per axis x_ref, v_ref, a_ref
    x0 = np.zeros(model.nstates)
    for name, start in zip(AXES, pos[0]):
        x0[model.state_labels.index(f"{name}_plant_x")] = start  # at rest at the first command, like the kernel
    t_pc, pc = best_of(lambda: ct.input_output_response(model, t, u, X0=x0), 2)
    deviation = np.max(np.abs(pc.outputs.T - kernel_result.position[:n]))
    clamped = int(kernel_result.saturated[:n].sum())

    rate_plain = axis_steps / t_plain
    rate_loaded = axis_steps / t_loaded
    rate_pc = n * len(AXES) / t_pc
    print("Each figure: simulated samples x axes / wall-clock seconds (axis-steps/s); servo period 0.2 ms, 3 axes.")
    print(f"{'simulation':58s} {'steps':>8s} {'wall [s]':>10s} {'axis-steps/s':>14s}")
    print(f"{'kernel, plain P-PI cascade (run() end to end)':58s} {N:8d} {t_plain:10.4f} {rate_plain:14.4g}")
    print(f"{'kernel, + current limit, velocity + acceleration ff':58s} {N:8d} {t_loaded:10.4f} {rate_loaded:14.4g}")
    print(f"{'python-control input_output_response, same loop as above':58s} {n:8d} {t_pc:10.4f} {rate_pc:14.4g}")
    print(f"same loop: python-control vs kernel max |x difference| over {n} steps = {deviation:.3g} mm "
          f"({clamped} axis-steps clamped at the current limit)")  # fmt: skip
    print(f"plain cascade: {rate_plain / 1e6:.1f} M axis-steps/s (target >= 20 M)")
    print(f"kernel (limit + feedforward) / python-control (same loop) = {rate_loaded / rate_pc:.0f} (target >= 1000)")
    print(f"kernel_speedup_vs_python_control: {rate_loaded / rate_pc:.0f}")


if __name__ == "__main__":
    main()
