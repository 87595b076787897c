"""A short tour of the contoursim API: machine, path, feed, simulation, plots.

python examples/api_tour.py [OUT_DIR]
"""

import sys
from pathlib import Path

import matplotlib

matplotlib.use("Agg")

from contoursim import paths
from contoursim.feed import plan, sample
from contoursim.output import output_dir
from contoursim.machine import load_machine
from contoursim.plotting import save_figures
from contoursim.simulate import simulate


def main(out=Path("contoursim-out")):
    machine = load_machine("demo_mill")                     # servo axes x, y, z at 5 kHz
    for name, servo in machine.axes.items():                # python-control models behind each axis
        print(f"axis {name}: position-loop bandwidth {servo.bandwidth():.1f} Hz")

    path = paths.circle(center=(0, 0), radius=20.0, direction="ccw")
    profile = plan(path, feed=3000 / 60, accel=2000.0, jerk=1e5)   # mm/s, mm/s^2, mm/s^3
    trajectory = sample(path, profile, machine.servo_period)

    result = simulate(machine, trajectory)
    for key, value in result.summary().items():
        print(f"{key:>16}: {value:8.2f}")

    files = save_figures({"api_tour_circle": result}, output_dir(out), "api_tour_circle")  # replaces only its own files
    print("wrote", ", ".join(str(f) for f in files))
    return result


if __name__ == "__main__":
    main(Path(sys.argv[1]) if len(sys.argv) > 1 else Path("contoursim-out"))
