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

* kernel, every in-loop effect on every axis (backlash with scale feedback,
  Coulomb + viscous + Stribeck friction with asymmetry and offset, a
  1.3-period feedback delay, a 90 Hz structural mode, a 0.1 µm encoder),
  same reference, ``run()`` end to end, best of 15 (these runs and the
  bare inner loop below take turns, so that they share the machine's load):
  ``kernel_all_effects_slowdown`` is its time over the plain run's; the
  same with 1 µm measurement noise on the recorded position too (outside
  the loop) is printed in the table;
* ``variant_pack_ms``: ``pack`` of one new 3-axis variant (a new kv and new
  friction and backlash values per axis, so nothing is cached), best of 200;
* ``kernel_batch_axis_steps_per_s``: ``run_batch`` of 64 variants (friction
  and backlash on every axis, values varying per variant) on the first
  50,000 steps of the helix, tool position only (float64), all cores, best of 3
  (also printed: axis-steps per CPU-second of all threads, for a loaded machine,
  and the system time of a call). Not timed: the first two such calls of
  the process, printed apart: on the 2-core virtual machine these figures
  come from, each of the first two 77 MB outputs (huge pages: numpy asks
  for them for large arrays) costs 0.08-0.27 s of system time, where later
  calls, given the pages an earlier one freed, spend 7-27 ms (no compaction:
  /proc/vmstat's compact_stall stays 0; presumably the host backing pages
  the guest had not used lately); that, not the steps, made this figure vary
  from run to run;
* ``kernel_batch_vs_reference``: ``run_batch`` of 128 variants (kv and
  Coulomb friction varying per variant, tool position only, float64) on the
  first 20,000 steps of the helix, over a reference written here from the
  physics and not from the kernel (:func:`cascade_reference`: the same P-PI
  cascades with Coulomb stick-slip friction, the ZOH plant from
  ``scipy.linalg.expm``, variants innermost, ``prange`` over blocks of
  variants, positions written in blocks to a new (B, N, 3) array),
  axis-steps/s over axis-steps/s, both on
  all cores, taking turns, best of 15 (target >= 0.5; their largest
  position difference is printed);
* ``kernel_batch_parallel_efficiency``: the same batch on all cores over
  cores x its rate on one thread (``numba.set_num_threads``), taking turns,
  best of 15 (target >= 0.8; on a machine shared with other processes it
  measures what the cores had to spare too: the reference's own figure,
  measured the same way, is printed beside it);
* ``kernel_run_vs_inner_loop``: the plain run's ``run()`` end to end
  throughput over the compiled inner loop's alone (same packed rows,
  outputs preallocated, no argument checks), best of 15 each; the same
  ratios by thread CPU time are printed too (they do not count time the
  process waits for a core on a loaded machine).

Figures are axis-steps per second: simulated samples x axes / wall seconds.
Run: python benchmarks/bench_kernel.py
"""

import resource
import time
from dataclasses import replace

import control as ct
import numba
import numpy as np
import scipy.linalg

from contoursim import kernel
from contoursim.kernel import LoopEffects, pack, run, run_batch
from contoursim.servo import AxisServo

DT = 2e-4  # 5 kHz
N = 300_000  # 60 s
N_PYTHON_CONTROL = 1_000
N_BATCH, B = 50_000, 64
N_REF, B_REF = 20_000, 128
REF_LANES, REF_CHUNK = 32, 128  # the reference's variants per block, samples per write
ALL_EFFECTS = LoopEffects(backlash_mm=0.005, coulomb_N=120.0, viscous_N_s_per_m=300.0,
                          stribeck_N=40.0, stribeck_velocity_mm_s=2.0, asymmetry_N=15.0, offset_N=-30.0,
                          feedback_delay_s=1.3 * DT, mode_freq_hz=90.0, mode_damping_ratio=0.05, mode_mass_ratio=0.1,
                          quantum_mm=1e-4)  # fmt: skip
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


def best_of(fn, repeat, clock=time.perf_counter):
    times = []
    for _ in range(repeat):
        start = clock()
        result = fn()
        times.append(clock() - start)
    return min(times), result


def system_seconds(since):
    """System CPU time of this process since the `resource.getrusage` result `since` [s] (page faults, mostly)."""
    return resource.getrusage(resource.RUSAGE_SELF).ru_stime - since.ru_stime


def side_by_side(fns, repeat):
    """Best wall and thread-CPU times of each function, calling them in turn `repeat` times after a warm-up."""
    wall, cpu = [np.inf] * len(fns), [np.inf] * len(fns)
    for r in range(repeat + 1):
        for i, fn in enumerate(fns):
            start, start_cpu = time.perf_counter(), time.thread_time()
            fn()
            if r:
                wall[i] = min(wall[i], time.perf_counter() - start)
                cpu[i] = min(cpu[i], time.thread_time() - start_cpu)
    return wall, cpu


def reference_coefficients(servos, coulomb):
    """The reference's numbers per axis and variant, shape (n_axes, 10, B), from the physics.

    Each servo (P position loop, PI velocity loop, ideal current loop, rigid
    mass m [kg] with viscous damping c [N·s/m] and force constant kf [N/A])
    is a row of `servos` (B, n_axes); `coulomb` (B, n_axes) the Coulomb
    friction [N]. Plant in mm and mm/s, inputs the current i [A] and the
    friction force F [N]: ``dx/dt = v``, ``dv/dt = 1000·(kf·i + F)/m - c·v/m``,
    held over a period: its exact sampled form from the matrix exponential
    of the augmented system.
    """
    n_variants, n_axes = len(servos), len(servos[0])
    coef = np.empty((n_axes, 10, n_variants))
    for b, row in enumerate(servos):
        for a, s in enumerate(row):
            augmented = np.zeros((4, 4))
            augmented[0, 1] = 1.0
            augmented[1, 1] = -s.damping / s.mass
            augmented[1, 2], augmented[1, 3] = 1000.0 * s.force_constant / s.mass, 1000.0 / s.mass
            step = scipy.linalg.expm(augmented * DT)
            # kp [1/s], PI gain [A per mm/s], 1/ti [1/s], then the plant's
            # x+ = x + Pxv·v + Pxi·i + PxF·F, v+ = Pvv·v + Pvi·i + PvF·F
            coef[a, :9, b] = (s.kp, s.kv / 1000.0, 1.0 / s.ti, step[0, 1], step[0, 2], step[0, 3], step[1, 1],
                              step[1, 2], step[1, 3])  # fmt: skip
            coef[a, 9, b] = coulomb[b, a]
    return coef


@numba.njit(parallel=True, error_model="numpy")
def cascade_reference(coef, ref_pos, out):
    """Positions [mm] of B P-PI cascades with Coulomb friction on `ref_pos` (N, n_axes), into `out` (B, N, n_axes).

    Each step, per axis and variant: velocity error ``e = kp·(x_ref - x) - v``;
    PI current ``i = g·(e + s/ti)`` with the trapezoidal integral
    ``s += dt/2·(e + e_previous)``; the friction force that would stop the
    carriage at the end of the period, ``-v_free / PvF`` (``v_free``: the
    velocity it reaches without friction), clipped to ±Coulomb (sticking
    inside, kinetic friction outside); the sampled plant. The variants are
    the inner loop (state laid out (axis, variant) per block of
    REF_LANES), ``prange`` over the blocks.
    """
    n_steps, n_axes = ref_pos.shape
    n_variants = coef.shape[2]
    for block in numba.prange((n_variants + REF_LANES - 1) // REF_LANES):
        lo = block * REF_LANES
        n = min(REF_LANES, n_variants - lo)
        c = np.empty((n_axes, 10, REF_LANES))  # the block's coefficients
        x, v = np.empty((n_axes, REF_LANES)), np.empty((n_axes, REF_LANES))
        s, e_last = np.empty((n_axes, REF_LANES)), np.empty((n_axes, REF_LANES))
        kept = np.empty((REF_CHUNK, n_axes, REF_LANES))
        for a in range(n_axes):
            for j in range(n):
                c[a, :, j] = coef[a, :, lo + j]
                x[a, j], v[a, j], s[a, j], e_last[a, j] = ref_pos[0, a], 0.0, 0.0, 0.0
        for k0 in range(0, n_steps, REF_CHUNK):
            for k in range(k0, min(k0 + REF_CHUNK, n_steps)):
                for a in range(n_axes):
                    x_ref = ref_pos[k, a]
                    for j in range(n):
                        kept[k - k0, a, j] = x[a, j]
                        e = c[a, 0, j] * (x_ref - x[a, j]) - v[a, j]
                        s[a, j] += 0.5 * DT * (e + e_last[a, j])
                        e_last[a, j] = e
                        i = c[a, 1, j] * (e + c[a, 2, j] * s[a, j])
                        v_free = c[a, 6, j] * v[a, j] + c[a, 7, j] * i
                        f = min(max(-v_free / c[a, 8, j], -c[a, 9, j]), c[a, 9, j])
                        x[a, j] += c[a, 3, j] * v[a, j] + c[a, 4, j] * i + c[a, 5, j] * f
                        v[a, j] = v_free + c[a, 8, j] * f
            for j in range(n):
                for k in range(k0, min(k0 + REF_CHUNK, n_steps)):
                    for a in range(n_axes):
                        out[lo + j, k, a] = kept[k - k0, a, j]
    return out


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
    scaled = [AxisServo(**BASE, position_feedback="scale")] * 3  # the backlash of ALL_EFFECTS behind a scale
    axis_steps = N * len(AXES)

    run(plain, DT, pos, vel, acc)  # warm-up: compile (or load the cache) and check the loops
    run(loaded, DT, pos, vel, acc)
    effects = dict.fromkeys(AXES, ALL_EFFECTS)
    noisy = dict.fromkeys(AXES, replace(ALL_EFFECTS, noise_mm=1e-3))

    # the bare inner loop of the plain run: packed rows, outputs allocated beforehand
    rows = np.array([pack(servo, DT) for servo in plain])
    refs = kernel._reference(3, pos, vel, acc, finite=False)  # read-only views, as run() passes them
    coupling_off = kernel._no_coupling()
    outputs = [np.empty((N, 3)) for _ in range(4)] + [np.empty((N, 3), bool), np.empty((0, 3)), np.empty((3, 3), np.int64)]

    def inner_loop():
        state = kernel._initial_state(rows, pos[0])
        kernel._variant(rows, state, *refs, *coupling_off, np.empty((0, 3)), np.empty((0, 3)), 1, *outputs)

    (t_plain, t_effects, t_noisy, t_inner), cpu = side_by_side([
        lambda: run(plain, DT, pos, vel, acc),
        lambda: run(scaled, DT, pos, vel, acc, effects=effects),
        lambda: run(scaled, DT, pos, vel, acc, effects=noisy),
        inner_loop,
    ], 15)  # fmt: skip

    counter = iter(range(10**9))

    def pack_variant():
        i = next(counter)
        effects = LoopEffects(coulomb_N=100.0 + i, backlash_mm=0.004 + 1e-6 * i)
        return [pack(AxisServo(**{**BASE, "kv": 200.0 + 1e-3 * i}), DT, effects) for _ in AXES]

    t_pack, _ = best_of(pack_variant, 200)

    batch_rows = np.array([
        [pack(servo, DT, LoopEffects(coulomb_N=50.0 + b, backlash_mm=0.002 + 1e-4 * b)) for servo in plain]
        for b in range(B)
    ])  # fmt: skip
    refs = (pos[:N_BATCH], vel[:N_BATCH], acc[:N_BATCH])
    run_batch(batch_rows[:2], DT, *refs)  # compile or load
    first = []  # the process's first two outputs of this size (best_of holds one while it makes the next): new pages
    for _ in range(2):
        usage, start = resource.getrusage(resource.RUSAGE_SELF), time.perf_counter()
        held = run_batch(batch_rows, DT, *refs)
        first.append((time.perf_counter() - start, system_seconds(usage)))
    del held
    t_batch = best_of(lambda: run_batch(batch_rows, DT, *refs), 3)[0]  # (no result kept: a third output's new pages)
    usage = resource.getrusage(resource.RUSAGE_SELF)
    cpu_batch = best_of(lambda: run_batch(batch_rows, DT, *refs), 3, clock=time.process_time)[0]
    batch_sys = system_seconds(usage) / 3
    t_loaded, kernel_result = best_of(lambda: run(loaded, DT, pos, vel, acc), 5)

    # the batch against the reference written here, then on one thread against all
    rng = np.random.default_rng(0)
    variants = [[AxisServo(**{**BASE, "kv": kv})] * len(AXES) for kv in rng.uniform(150.0, 250.0, B_REF)]
    coulomb = rng.uniform(20.0, 200.0, (B_REF, len(AXES)))
    ref_rows = np.array([[pack(servo, DT, LoopEffects(coulomb_N=f)) for servo, f in zip(row, fc)]
                         for row, fc in zip(variants, coulomb)])  # fmt: skip
    coef = reference_coefficients(variants, coulomb)
    short = (pos[:N_REF], vel[:N_REF], acc[:N_REF])

    def reference():
        return cascade_reference(coef, short[0], np.empty((B_REF, N_REF, len(AXES))))

    def batch():
        return run_batch(ref_rows, DT, *short)["tool"]

    deviation_ref = np.abs(reference() - batch()).max()  # (and compiles the reference)
    (t_kernel_ref, t_reference), _ = side_by_side([batch, reference], 15)
    cores = numba.get_num_threads()

    def on(threads):
        def fn():
            numba.set_num_threads(threads)
            batch()

        return fn

    def reference_on(threads):
        def fn():
            numba.set_num_threads(threads)
            reference()

        return fn

    (t_one, t_all, t_ref_one, t_ref_all), _ = side_by_side([on(1), on(cores), reference_on(1), reference_on(cores)], 15)
    numba.set_num_threads(cores)

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
    print(f"{'kernel, every in-loop effect on (run() end to end)':58s} {N:8d} {t_effects:10.4f} {axis_steps / t_effects:14.4g}")
    print(f"{'kernel, every in-loop effect + measurement noise':58s} {N:8d} {t_noisy:10.4f} {axis_steps / t_noisy:14.4g}")
    print(f"{'kernel, plain, bare inner loop (outputs preallocated)':58s} {N:8d} {t_inner:10.4f} {axis_steps / t_inner:14.4g}")
    print(f"{'kernel, batch of 64 variants, friction + backlash':58s} {N_BATCH:8d} {t_batch:10.4f} "
          f"{B * N_BATCH * 3 / t_batch:14.4g}")  # fmt: skip
    print(f"  the same batch per CPU-second of all its threads: {B * N_BATCH * 3 / cpu_batch:.4g} axis-steps "
          f"({numba.get_num_threads()} threads; the wall figure is lower when other processes share the cores); "
          f"{1e3 * batch_sys:.0f} ms of system time per call (the fresh output's page faults)")
    print(f"  its first two calls in this process (excluded above: pages new to it): {first[0][0]:.4f} and "
          f"{first[1][0]:.4f} s, {1e3 * first[0][1]:.0f} and {1e3 * first[1][1]:.0f} ms of them system time")
    ref_steps = B_REF * N_REF * len(AXES)
    print(f"{'kernel, batch of 128 variants, kv + Coulomb friction':58s} {N_REF:8d} {t_kernel_ref:10.4f} "
          f"{ref_steps / t_kernel_ref:14.4g}")  # fmt: skip
    print(f"{'reference written here (P-PI + Coulomb), same variants':58s} {N_REF:8d} {t_reference:10.4f} "
          f"{ref_steps / t_reference:14.4g}")  # fmt: skip
    print(f"  same positions: max |kernel - reference| = {deviation_ref:.3g} mm")
    print(f"{'kernel, the same batch on 1 thread':58s} {N_REF:8d} {t_one:10.4f} {ref_steps / t_one:14.4g}")
    print(f"{f'kernel, the same batch on {cores} threads':58s} {N_REF:8d} {t_all:10.4f} {ref_steps / t_all:14.4g}")
    print(f"  the same four by CPU time of the thread: {cpu[0]:.4f} {cpu[1]:.4f} {cpu[2]:.4f} {cpu[3]:.4f} s: "
          f"effects slowdown {cpu[1] / cpu[0]:.2f}, run() / inner loop {cpu[3] / cpu[0]:.2f}")
    print(f"kernel_all_effects_slowdown: {t_effects / t_plain:.2f}")
    print(f"variant_pack_ms: {1e3 * t_pack:.3f}")
    print(f"kernel_batch_axis_steps_per_s: {B * N_BATCH * 3 / t_batch:.3g}")
    print(f"kernel_run_vs_inner_loop: {t_inner / t_plain:.2f}")
    print(f"kernel_batch_vs_reference: {t_reference / t_kernel_ref:.2f}")
    print(f"kernel_batch_parallel_efficiency: {t_one / (cores * t_all):.2f}")
    print(f"reference_parallel_efficiency: {t_ref_one / (cores * t_ref_all):.2f}")
    print(f"kernel_speedup_vs_python_control: {rate_loaded / rate_pc:.0f}")


if __name__ == "__main__":
    main()
