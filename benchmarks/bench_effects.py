"""Cost of the effects layer on top of the kernel: variants, batches, a Jacobian's batch.

A 2-axis machine (P-PI cascades: m = 300 kg, kf = 942 N/A, kv = 80 A·s/m,
Ti = 16 ms, Kp = 40 1/s) at a 1 ms servo period, with six effects of every
stage (backlash and friction on X, gain mismatch and command delay on Y,
squareness of X and Y, cyclic error on Y), follows a 30-s measured-style
reference (a trace of circles, R = 20 mm, 1 kHz):

* ``model_with_values_us``: ``Model.with_values`` of one parameter, best of 200;
* ``variant_rows_ms``: the kernel rows of one 2-axis variant (servo-stage and
  in-loop effects realised, ``kernel.pack`` per axis), best of 200;
* ``batch_layer_fraction``: the throughput of ``simulate_batch`` of 64
  variants of the model's servo and in-loop effects (packing, one
  ``run_batch``, the tool positions) as a fraction of the bare
  ``kernel.run_batch`` of the same packed rows, tool position only, best of 3
  each — what the layer costs; ``..._with_geometry``: the same with all six
  effects, where each row's tool positions go through the multibody chain
  (``MachineChain.tool_pose``);
* ``jacobian_batch_s``: one finite-difference Jacobian of the model's 6
  varied parameters (P + 1 = 7 rows; the command delay's step makes a
  second kernel call) on the 30-s trace, best of 3.

Run: python benchmarks/bench_effects.py
"""

import numpy as np
from bench_chain import best_of as best

from contoursim import kernel
from contoursim.effects import Effect
from contoursim.machine import Machine
from contoursim.model import Model
from contoursim.servo import AxisServo
from contoursim.simulation import measured_reference, simulate_batch
from contoursim.traces import Trace

DT = 1e-3
AXIS = dict(mass=300.0, force_constant=942.0, kv=80.0, ti=0.016, kp=40.0, damping=500.0)


def rows(model):
    """The kernel rows of one variant: servo-stage and in-loop effects realised, ``kernel.pack`` per axis."""
    loop = model.loop_effects()
    return [kernel.pack(servo, DT, loop[axis]) for axis, servo in model.servos().items()]


def main():
    machine = Machine({"x": AxisServo(**AXIS), "y": AxisServo(**AXIS)}, DT)
    model = Model(machine, (
        Effect("backlash", "x", lost_motion_um=8.0), Effect("coulomb_friction", "x", force_N=40.0),
        Effect("gain_mismatch", "y", kp_ratio=0.95), Effect("time_delay", "y", delay_s=5e-4),
        Effect("squareness", "xy", angle_urad=80.0), Effect("cyclic_error", "y", amplitude_um=2.0),
    ))
    t = np.arange(30000) * DT
    ref = 20.0 * np.column_stack([np.cos(t), np.sin(t)])
    trace = Trace(t, ref, ref, ("x", "y"))

    print(f"model_with_values_us: {1e6 * best(lambda: model.with_values({'backlash.x.lost_motion_um': 9.0}), 200):.1f}")
    variant = model.with_values({"backlash.x.lost_motion_um": 9.0})
    print(f"variant_rows_ms: {1e3 * best(lambda: rows(variant), 200):.3f}")

    sizes = np.linspace(2.0, 20.0, 64)
    in_loop = Model(machine, model.stage("servo") + model.stage("loop"))
    for label, base in (("batch_layer_fraction", in_loop), ("batch_layer_fraction_with_geometry", model)):
        variants = [base.with_values({"backlash.x.lost_motion_um": b}) for b in sizes]
        simulate_batch(variants[:2], trace)  # compile, check the loops
        layer = best(lambda: simulate_batch(variants, trace), 3)
        q, v, a = variants[0].commands(*machine.axis_commands(measured_reference(trace, DT)))
        packed = np.array([rows(m) for m in variants])
        bare = best(lambda: kernel.run_batch(packed, DT, q, v, a, outputs=("tool",)), 3)
        print(f"{label}: {bare / layer:.2f}")

    steps = {name: 0.1 * abs(p.value) for name, p in model.parameters().items() if p.vary and p.value}
    jacobian = model.variants([{}] + [{name: model.values()[name] + step} for name, step in steps.items()])
    print(f"jacobian_parameters: {len(steps)}")
    print(f"jacobian_batch_s: {best(lambda: simulate_batch(jacobian, trace), 3):.3f}")


if __name__ == "__main__":
    main()
