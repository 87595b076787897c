"""Speed of the multibody chain on a 300,000-sample trace, side by side.

Prints, for each preset, the wall time of the exact tool pose (actual and
ideal), the volumetric error, the first-order error and one
geometric-compensation call (after a warm-up call on 10 samples, so numba's
compilation is excluded; ``bench_user.py`` prints the compensation's figures
for issue 8). Run: python benchmarks/bench_chain.py
"""

import time

import numpy as np

from contoursim.geocomp import GeometricCompensation
from contoursim.machine import load_machine, preset_names

N = 300_000


def best_of(fn, repeat=3):
    times = []
    for _ in range(repeat):
        start = time.perf_counter()
        fn()
        times.append(time.perf_counter() - start)
    return min(times)


def trace(chain):
    """Axis positions sweeping each axis's travel at its own frequency, and times over 60 s, N samples."""
    travel = {b.axis: b.travel for b in chain.bodies if b.axis is not None}
    lo = np.array([travel[a][0] for a in chain.axes])
    hi = np.array([travel[a][1] for a in chain.axes])
    s = np.linspace(0, 1, N)[:, None]
    q = lo + (hi - lo) * (0.5 + 0.45 * np.sin(2 * np.pi * (3 + np.arange(len(chain.axes))) * s))
    return q, np.linspace(0, 60, N)


def main():
    print(f"{'preset':28s} {'axes':>4s} {'tool_pose':>10s} {'ideal':>8s} {'vol.err':>8s} {'1st-ord':>8s} {'geocomp':>8s}  [s, N = {N}]")
    for name in preset_names():
        chain = load_machine(name).chain
        if chain is None:
            continue
        q, t = trace(chain)
        comp = GeometricCompensation(chain)
        comp.commands(q[:10], t[:10])
        row = [
            best_of(lambda: chain.tool_pose(q, t)),
            best_of(lambda: chain.tool_pose(q, t, ideal=True)),
            best_of(lambda: chain.volumetric_error(q, t)),
            best_of(lambda: chain.first_order_error(q, t), repeat=1),
            best_of(lambda: comp.commands(q, t), repeat=1),
        ]
        print(f"{name:28s} {len(chain.axes):4d} " + " ".join(f"{x:8.3f}" for x in row).replace(" ", " ", 1))


if __name__ == "__main__":
    main()
