"""Speed of path building and feed planning for long free-form paths and G-code programs.

* ``spline_20k_s``: a closed C2 spline through 20,000 points (a wavy circle,
  R = 50 ± 5 mm, 7 waves) built with ``paths.spline`` and planned with
  ``feed.plan`` (50 mm/s, 1000 mm/s², jerk 5e4 mm/s³, centripetal
  1000 mm/s²), CPU seconds, best of 3 after a warm-up on a small spline;
* ``gcode_plan_us_per_block``: ``feed.plan`` of a 5,000-block G-code
  program (G1 moves around a 100 mm polygon, a feed change at every block,
  jerk-limited) divided by the blocks, CPU µs, best of 3.

Run: python benchmarks/bench_paths.py
"""

import time

import numpy as np

from contoursim import paths
from contoursim.feed import plan
from contoursim.gcode import read_gcode


def best_cpu(fn, repeat=3):
    times = []
    for _ in range(repeat):
        start = time.process_time()
        fn()
        times.append(time.process_time() - start)
    return min(times)


def wavy_circle(n):
    th = np.linspace(0, 2 * np.pi, n, endpoint=False)
    r = 50 + 5 * np.sin(7 * th)
    return np.column_stack([r * np.cos(th), r * np.sin(th)])


def program(blocks):
    th = np.linspace(0, 2 * np.pi, blocks + 1)
    lines = ["G21 G90 G17", f"G0 X{50:.4f} Y0"]
    for k in range(1, blocks + 1):
        lines.append(f"G1 X{50 * np.cos(th[k]):.4f} Y{50 * np.sin(th[k]):.4f} F{1000 + 500 * (k % 3)}")
    return "\n".join(lines + ["M30", ""])


def main():
    settings = dict(feed=50.0, accel=1000.0, jerk=5e4, centripetal_accel=1000.0)
    points = wavy_circle(20_000)
    plan(paths.spline(points[::400], closed=True), **settings)  # compile
    print(f"spline_20k_s: {best_cpu(lambda: plan(paths.spline(points, closed=True), **settings)):.3f}")
    blocks = 5_000
    gcode = read_gcode(program(blocks))
    plan(read_gcode(program(20)).path, read_gcode(program(20)).feeds, 1000.0, 5e4)  # compile
    seconds = best_cpu(lambda: plan(gcode.path, gcode.feeds, 1000.0, 5e4))
    print(f"gcode_plan_us_per_block: {1e6 * seconds / len(gcode.feeds):.1f}")


if __name__ == "__main__":
    main()
