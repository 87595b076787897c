"""Online contour-error estimators against the exact contour error, on a simulated trace.

The compensator of a CNC sees only the interpolator's samples, not the path,
so it must estimate the contour error. Here the demo machine follows the
free-form butterfly curve; each estimator is compared with the exact value.

python examples/estimators_tour.py
"""

import numpy as np

from contoursim import estimators, load_machine, simulate
from contoursim.feed import sample
from contoursim.pathfile import load_path_file


def main():
    machine = load_machine("demo_mill")
    path, feed = load_path_file("butterfly")
    trajectory = sample(path, feed.plan(path), machine.servo_period)
    result = simulate(machine, trajectory)
    reference, actual = result.trajectory.position, result.tool_position

    exact = result.contour.magnitude
    print(f"exact contour error: max {1e3 * exact.max():.2f} µm over {len(exact)} samples")
    for name in ("linear", "three_point", "newton"):
        estimate = getattr(estimators, name)(reference, actual)
        gap = np.abs(estimate.magnitude - exact)
        print(f"{name:>12}: max |estimate - exact| = {1e3 * gap.max():.3g} µm")


if __name__ == "__main__":
    main()
