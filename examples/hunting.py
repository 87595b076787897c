"""Hunting at standstill: lost motion and static friction inside the position loop.

The demo mill's X axis (P position loop, PI velocity loop) makes a 2 µm
positioning step from rest, with 10 µm of lost motion and Coulomb friction of
100 N, and then holds. Four cases: the loop closed on the motor encoder or on
a linear scale on the table, each with no extra static friction and with a
static level twice the Coulomb one (``stribeck_N = 100`` N decaying within
0.1 mm/s). What a servo-tuning tool would show over the hold:

- motor encoder, no extra static friction: the motor turns 2 µm inside the
  play and the table does not move (2 µm short);
- linear scale, no extra static friction: the loop pushes the table through
  the play and settles on target;
- with static friction above the sliding level the velocity integrator winds
  up while the axis sticks, breaks it away and overshoots, again and again: a
  limit cycle. On the scale the loop also has to cross the play at each
  reversal, and the table hunts by most of the lost motion; on the motor
  encoder the motor's own stick-slip cycle is larger than the play here and
  drags the table along.

python examples/hunting.py [OUT_DIR]
"""

import sys
from pathlib import Path

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt
import numpy as np

from contoursim import kernel
from contoursim.effects import Effect
from contoursim.machine import load_machine
from contoursim.model import Model
from contoursim.output import output_dir

STEP_UM, LOST_MOTION_UM, COULOMB_N = 2.0, 10.0, 100.0
DURATION_S, STEP_AT_S = 4.0, 0.1
CASES = [(feedback, static) for feedback in ("motor", "scale") for static in (0.0, 100.0)]  # static: stribeck_N [N]


def table_positions(machine):
    """Time [s] and the table position of each case [µm], shape (len(CASES), N)."""
    dt = machine.servo_period
    t = np.arange(int(DURATION_S / dt)) * dt
    command = np.where(t >= STEP_AT_S, 1e-3 * STEP_UM, 0.0)[:, None]  # [mm]
    at_rest = np.zeros_like(command)  # no velocity or acceleration feedforward for a step
    table = []
    for feedback, static in CASES:
        model = Model(machine, (
            Effect("backlash", "x", lost_motion_um=LOST_MOTION_UM, feedback=feedback),
            Effect("coulomb_friction", "x", force_N=COULOMB_N, stribeck_N=static, stribeck_velocity_mm_s=0.1),
        ))  # fmt: skip
        response = kernel.run({"x": model.servos()["x"]}, dt, command, at_rest, at_rest,
                              effects={"x": model.loop_effects()["x"]})  # fmt: skip
        table.append(1e3 * response.position[:, 0])
    return t, np.array(table)


def main(out):
    machine = load_machine("demo_mill")
    t, table = table_positions(machine)
    hold = t >= DURATION_S / 2  # the second half: transients over
    fig, axes = plt.subplots(len(CASES), 1, sharex=True, figsize=(8.0, 8.0), layout="constrained")
    print(f"X of {machine.name}: {STEP_UM:g} µm step, {LOST_MOTION_UM:g} µm lost motion, Coulomb {COULOMB_N:g} N")
    print(f"{'feedback':9s} {'static friction':>16s} {'table p2p [µm]':>15s} {'mean error [µm]':>16s}")
    for ax, (feedback, static), x in zip(axes, CASES, table):
        p2p, error = np.ptp(x[hold]), np.mean(x[hold]) - STEP_UM
        print(f"{feedback:9s} {COULOMB_N + static:14.0f} N {p2p:15.3f} {error:16.3f}")
        ax.plot(t, x, lw=0.9, color="C3" if static else "C0")
        ax.axhline(STEP_UM, color="0.5", lw=0.6, ls="--")
        ax.set_ylabel("table [µm]")
        ax.set_title(f"{feedback} encoder, static friction {COULOMB_N + static:g} N: table {p2p:.2f} µm p2p over the hold",
                     fontsize="medium")  # fmt: skip
        ax.grid(True, alpha=0.3)
    axes[-1].set_xlabel("t [s]")
    fig.suptitle(f"{STEP_UM:g} µm step with {LOST_MOTION_UM:g} µm lost motion: hunting needs static friction above sliding")
    out = output_dir(out)
    with out.write("hunting.png", binary=True) as stream:
        fig.savefig(stream, format="png", dpi=110)
    plt.close(fig)
    return t, table


if __name__ == "__main__":
    main(Path(sys.argv[1]) if len(sys.argv) > 1 else Path("contoursim-out"))
