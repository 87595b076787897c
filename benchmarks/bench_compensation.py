"""Compensation strategies on the free-form (butterfly) path: seed 003's trend, nominal and realistic.

Seed 003 (DOMAIN.md section 3): cross-coupled compensation driven by the
three-point arc estimate took a free-form path's contour error from about
1e-1 mm to about 1e-6 mm in a Simulink study. Here: a realistic two-axis
machine (position gains 45 and 38 1/s, velocity loops 100 and 70 Hz, P-PI
cascades, 5 kHz servo rate) on the butterfly of trajectories/ at the file's
feed (1000 mm/min), where the uncompensated contour error is about 0.1 mm.

Table 1, nominal: the strategies know the machine exactly; no friction, no
noise, no current limit. Each row gives the max and RMS contour error over
the path, the max tracking error, the peak current and the reduction of the
max contour error relative to ``none``.

Table 2, realistic: the strategies design from the nominal servos, while
the machine has +10 % mass on x and -10 % force constant on y (its model
is 10 % off), Coulomb friction (40 N on x, 60 N on y), 0.1 µm RMS
measurement noise on the recorded positions, and an amplifier current
limit that the feedforward runs reach at the tight turns.

The last lines are the nominal reductions of ``ccc_arc`` and
``feedforward+ccc_arc`` [%].

Run:  python benchmarks/bench_compensation.py
"""

import dataclasses
import warnings

import numpy as np

from contoursim.comparison import compare
from contoursim.effects import Effect
from contoursim.exceptions import ContoursimWarning
from contoursim.feed import sample
from contoursim.machine import Machine
from contoursim.model import Model
from contoursim.pathfile import load_path_file
from contoursim.servo import AxisServo

DT = 2e-4  # servo period [s]
FORCE_CONSTANT = 942.0  # [N/A]
CURRENT_LIMIT_A = 0.38  # realistic row's amplifier limit [A]


def axis(mass, velocity_hz, kp, ti, **kw):
    """A P-PI axis whose velocity loop crosses over near `velocity_hz` (kv·kf/m = 2π·f)."""
    kv = 2 * np.pi * velocity_hz * mass / FORCE_CONSTANT
    return AxisServo(mass=mass, force_constant=FORCE_CONSTANT, kv=kv, ti=ti, kp=kp, damping=500.0, **kw)


NOMINAL = {"x": axis(300.0, 100.0, 45.0, 0.010), "y": axis(450.0, 70.0, 38.0, 0.012)}


def table(title, comparison):
    """Print a comparison as a table with the reduction of the max contour error vs none [%]."""
    figures = comparison.figures
    base = figures["none"]["contour_max_um"]
    print(f"\n{title}")
    print(f"{'strategy':<22}{'contour max':>13}{'contour RMS':>13}{'tracking max':>14}{'peak current':>14}"
          f"{'saturated':>11}{'reduction':>12}")
    print(f"{'':<22}{'[µm]':>13}{'[µm]':>13}{'[µm]':>14}{'[A]':>14}{'':>11}{'[%]':>12}")
    for name, f in figures.items():
        reduction = 100 * (1 - f["contour_max_um"] / base)
        print(f"{name:<22}{f['contour_max_um']:>13.4g}{f['contour_rms_um']:>13.4g}{f['tracking_max_um']:>14.4g}"
              f"{f['peak_current_A']:>14.4g}{'yes' if f['saturated'] else 'no':>11}{reduction:>12.4f}")
    return {name: 100 * (1 - f["contour_max_um"] / base) for name, f in figures.items()}


def main():
    path, settings = load_path_file("butterfly")
    trajectory = sample(path, settings.plan(path), DT)
    print(f"butterfly at {60 * settings.feed:g} mm/min: {len(trajectory)} samples, {trajectory.t[-1]:.1f} s; "
          f"axes x: Kp 45 1/s, velocity loop 100 Hz; y: Kp 38 1/s, 70 Hz; servo period {1e3 * DT:g} ms")
    nominal = table("Table 1 — nominal (exact model, no friction, noise or current limit)",
                    compare(Machine(NOMINAL, DT), trajectory))

    machine = Machine({"x": dataclasses.replace(NOMINAL["x"], mass=1.1 * NOMINAL["x"].mass, current_limit=CURRENT_LIMIT_A),
                       "y": dataclasses.replace(NOMINAL["y"], force_constant=0.9 * FORCE_CONSTANT,
                                                current_limit=CURRENT_LIMIT_A)}, DT)  # fmt: skip
    effects = (Effect("coulomb_friction", "x", force_N=40.0), Effect("coulomb_friction", "y", force_N=60.0),
               Effect("noise", "x", rms_um=0.1, seed=1), Effect("noise", "y", rms_um=0.1, seed=2))  # fmt: skip
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ContoursimWarning)  # saturation: the table says it
        realistic = compare(Model(machine, effects), trajectory, design=NOMINAL)
    table("Table 2 — realistic (model 10 % off, Coulomb friction 40/60 N, 0.1 µm noise, "
          f"current limit ±{CURRENT_LIMIT_A:g} A)", realistic)
    print()
    print(f"compensation_reduction_ccc_arc_pct: {nominal['ccc_arc']:.4f}")
    print(f"compensation_reduction_ff_ccc_arc_pct: {nominal['feedforward+ccc_arc']:.4f}")


if __name__ == "__main__":
    main()
