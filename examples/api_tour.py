"""A short tour of the contoursim API: machine, path, feed, simulation, trace and plots.

The API tour of docs/api.md is this script without its prints; a test checks that
they agree and that both run twice in a row.

python examples/api_tour.py [OUT_DIR]
"""

import sys

import matplotlib

matplotlib.use("Agg")

from contoursim import paths
from contoursim.feed import plan, sample
from contoursim.machine import load_machine
from contoursim.output import output_dir
from contoursim.plotting import save_figures
from contoursim.simulation import simulate


def main(out="contoursim-out"):
    machine = load_machine("demo_mill")
    axis = machine.axes["x"]                 # an AxisServo
    axis.closed_loop()                       # python-control StateSpace: x_ref -> x
    axis.bandwidth(), axis.margins(machine.servo_period)
    for name, servo in machine.axes.items():
        print(f"axis {name}: position-loop bandwidth {servo.bandwidth():.1f} Hz")

    path = paths.circle(center=(0, 0), radius=20.0, direction="ccw")
    profile = plan(path, feed=3000 / 60, accel=2000.0, jerk=1e5, max_feed=machine.max_feed)  # [mm/s], [mm/s²], [mm/s³]
    trajectory = sample(path, profile, machine.servo_period)
    result = simulate(machine, trajectory)   # pure function of its inputs
    result.summary()                         # max / RMS tracking and contour error [µm]
    result.saturation                        # fraction of samples each axis's current was clipped at
    result.contour.magnitude, result.contour.normal   # exact contour error [mm], signed
    for key, value in result.summary().items():
        print(f"{key:>18}: {value:8.2f}")

    out = output_dir(out)                    # made by contoursim: a rerun replaces only its own files
    with out.write("circle.csv") as stream:  # the measured-trace format, written atomically
        result.save_csv(stream)
    files = save_figures({"circle": result}, out, "circle")   # runs by name: one magnification for all
    print("wrote", out.path / "circle.csv", *files)
    return result


if __name__ == "__main__":
    main(*sys.argv[1:2])
