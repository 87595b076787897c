"""Compensation strategies on the free-form butterfly and the 3-D helix: seed 003's trend, ideal and realistic.

Seed 003 (DOMAIN.md section 3): cross-coupled compensation driven by the
three-point arc estimate took a free-form path's contour error from about
1e-1 mm to about 1e-6 mm in a Simulink study. Here: a realistic machine
(position gains 45, 38 and 40 1/s, velocity loops 100, 70 and 80 Hz, P-PI
cascades, 5 kHz servo rate) on the butterfly (x, y) and the helix (x, y, z:
the arc estimator's out-of-plane part) of trajectories/, each at its file's
feed (1000 mm/min).

For each path, four tables (``Comparison.table``: the header gives the axes'
loop margins and every strategy's settings; ``PM`` and ``ζ`` are the coupled
loop's along the path, checked like an axis loop):

1. ideal, designed gains: the strategies know the machine exactly; no
   friction, noise or current limit; the coupling gains are designed for
   ζ = 0.7 on the sampled coupled loop, common to ccc_linear and ccc_arc;
2. ideal, tuned gains: each cross-coupled strategy's kp, ki tuned on the
   path (``comparison.tune``: the lowest max contour error under the
   coupled-loop check);
3. realistic at the designed gains and 4. at the gains tuned on the ideal
   machine (a strategy whose gains the coupled-loop check refuses on this
   machine is left out, with the check's message): the strategies design from the nominal servos while the machine
   has +10 % mass on x and -10 % force constant on y; Coulomb friction (40,
   60, 50 N); 0.1 µm RMS noise on every encoder, inside the loop (the
   position loops and the coupling close on it); and a current limit per
   axis that leaves the drive the force to move (the largest damping ×
   velocity + friction of the reference) and 90 % of the force of the
   reference's peak acceleration (mass × acceleration), over the force
   constant: it binds where the reference accelerates hardest, as a drive
   sized to the planned acceleration does; the ``clamped`` column says on
   what share of the samples.

The last lines are the ideal butterfly's reductions of the max contour error
of ``ccc_arc`` and ``feedforward+ccc_arc`` at the designed gains [%].

Run:  python benchmarks/bench_compensation.py
"""

import dataclasses
import warnings

import numpy as np

from contoursim.comparison import Comparison, compare, tune
from contoursim.effects import Effect
from contoursim.exceptions import ContoursimWarning, UnstableLoopError
from contoursim.feed import sample
from contoursim.machine import Machine
from contoursim.model import Model
from contoursim.pathfile import load_path_file
from contoursim.servo import AxisServo

DT = 2e-4  # servo period [s]
FORCE_CONSTANT = 942.0  # [N/A]
FRICTION_N = {"x": 40.0, "y": 60.0, "z": 50.0}  # realistic Coulomb friction [N]
NOISE_UM = 0.1  # realistic encoder noise, in the loop [µm RMS]
LIMIT_FRACTION = 0.9  # realistic current limit: the moving force + this share of the peak acceleration's [-]
COUPLED = ("ccc_linear", "ccc_arc", "feedforward+ccc_arc")


def axis(mass, velocity_hz, kp, ti, **kw):
    """A P-PI axis whose velocity loop crosses over near `velocity_hz` (kv·kf/m = 2π·f)."""
    kv = 2 * np.pi * velocity_hz * mass / FORCE_CONSTANT
    return AxisServo(mass=mass, force_constant=FORCE_CONSTANT, kv=kv, ti=ti, kp=kp, damping=500.0, **kw)


NOMINAL = {"x": axis(300.0, 100.0, 45.0, 0.010), "y": axis(450.0, 70.0, 38.0, 0.012),
           "z": axis(250.0, 80.0, 40.0, 0.010)}


def realistic(nominal, trajectory):
    """The machine the strategies do not know exactly, with friction, encoder noise and a current limit that binds."""
    off = {"x": dict(mass=1.1 * nominal["x"].mass), "y": dict(force_constant=0.9 * nominal["y"].force_constant)}
    servos, limits = {}, {}
    for i, (name, servo) in enumerate(nominal.items()):
        servo = dataclasses.replace(servo, **off.get(name, {}))
        v, a = 1e-3 * trajectory.velocity[:, i], 1e-3 * trajectory.acceleration[:, i]  # [m/s], [m/s^2]
        moving = np.abs(servo.damping * v + FRICTION_N[name] * np.sign(v)).max()  # [N]
        limits[name] = (moving + LIMIT_FRACTION * servo.mass * np.abs(a).max()) / servo.force_constant
        servos[name] = dataclasses.replace(servo, current_limit=limits[name])
    effects = [Effect("coulomb_friction", name, force_N=FRICTION_N[name]) for name in servos]
    effects += [Effect("noise", name, rms_um=NOISE_UM, seed=i + 1, at="encoder") for i, name in enumerate(servos)]
    return Model(Machine(servos, DT), tuple(effects)), limits


def show(title, comparison):
    print(f"\n{title}")
    print(comparison.table())


def bench(file):
    """Print the four tables of one path; the ideal comparison at the designed gains is returned."""
    path, settings = load_path_file(file)
    trajectory = sample(path, settings.plan(path), DT)
    nominal = dict(list(NOMINAL.items())[: trajectory.dim])
    print(f"\n=== {file} at {60 * settings.feed:g} mm/min: {len(trajectory)} samples, {trajectory.t[-1]:.1f} s; axes "
          + "; ".join(f"{a}: Kp {s.kp:g} 1/s, velocity loop {s.kv_mm * s.force_gain / (2 * np.pi):.0f} Hz"
                      for a, s in nominal.items()) + f"; servo period {1e3 * DT:g} ms")
    ideal = compare(Machine(nominal, DT), trajectory)
    show("1 — ideal (exact model, no friction, noise or current limit), coupling gains designed", ideal)
    tuned = {name: tune(Machine(nominal, DT), trajectory, name)["settings"] for name in COUPLED}
    show("2 — ideal, coupling gains tuned on this path",
         compare(Machine(nominal, DT), trajectory, ("none", *COUPLED), tuned=tuned))
    model, limits = realistic(nominal, trajectory)
    conditions = (f"model 10 % off, Coulomb friction {', '.join(f'{FRICTION_N[a]:g}' for a in nominal)} N, "
                  f"{NOISE_UM:g} µm RMS encoder noise in the loop, current limit "
                  + ", ".join(f"{a} ±{limit:.3g} A" for a, limit in limits.items())
                  + f" (moving force + {100 * LIMIT_FRACTION:g} % of the peak acceleration's)")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ContoursimWarning)  # the current limit binds: the clamped column says where
        show(f"3 — realistic ({conditions}), coupling gains designed", compare(model, trajectory, design=nominal))
        runs, gains = {}, {}
        for name in ("none", *COUPLED):  # the ideal machine's gains, some at the edge of the check there, here
            try:
                one = compare(model, trajectory, (name,), design=nominal, tuned=tuned)
            except UnstableLoopError as exc:
                print(f"\ntable 4 leaves out {exc}")
                continue
            runs.update(one.runs)
            gains.update(one.gains)
        show("4 — realistic, coupling gains tuned on the ideal machine (table 2)", Comparison(runs, gains))
    return ideal


def main():
    butterfly = bench("butterfly").figures
    bench("helix")
    base = butterfly["none"]["contour_max_um"]
    print()
    print(f"compensation_reduction_ccc_arc_pct: {100 * (1 - butterfly['ccc_arc']['contour_max_um'] / base):.4f}")
    both = butterfly["feedforward+ccc_arc"]["contour_max_um"]
    print(f"compensation_reduction_ff_ccc_arc_pct: {100 * (1 - both / base):.4f}")


if __name__ == "__main__":
    main()
