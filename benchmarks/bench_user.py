"""The waits a user sees (issue 8), each measured in a fresh process, in one run.

Prints one ``name: value`` line per target:

- ``demo_warm_s``: CPU seconds of ``contoursim demo`` with a warm numba cache;
- ``help_s``: CPU seconds of ``contoursim --help``;
- ``first_run_s``: CPU seconds of ``contoursim demo`` with an empty numba cache
  and no stored loop analysis (``NUMBA_CACHE_DIR`` and ``CONTOURSIM_CACHE_DIR``
  set to fresh folders for that process); Python's bytecode cache is left as
  it is: the very first run of a fresh clone also compiles contoursim's
  sources to bytecode, 0.09 s more on this machine;
- ``bytes_per_step``: peak memory (max RSS) of a 1 M-step CLI simulate
  minus the resident memory just before it, divided by the steps it wrote;
  the process ran a 10 k-step simulate first, so what a run costs once
  (numba's compiled functions loaded from the cache, matplotlib's fonts,
  the modules imported on first use) is in that baseline, not the figure;
- ``cli_1M_s``: CPU seconds of ``contoursim simulate`` of a 1 M-step circle,
  CSV and plots included;
- ``geocomp_7axis_300k_s``, ``geocomp_3axis_300k_s``: CPU seconds of one
  geometric compensation of 300 k samples (7-axis and 3-axis presets), a
  warm call: the process compensated 100 samples first, so loading the
  compiled functions from numba's cache (0.16–0.18 s measured on this
  machine, once per process) is not in the figure;
- ``spline_20k_s``: CPU seconds to build and plan a 20 k-point spline;
- ``gcode_plan_us_per_block``: CPU µs per block to plan a 5,000-block G-code
  program (G1 moves around a 100 mm polygon, the feed changing every block,
  jerk-limited).

CLI figures are the children's CPU time (``resource.getrusage(RUSAGE_CHILDREN)``,
user + system), import included, as a user waits for them; library figures are
the CPU time of the call inside a fresh process, the second of two such
processes (the first fills the numba cache). Run from the repository root:
``python benchmarks/bench_user.py``.
"""

import os
import resource
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

# A circle at a slow feed: 2π·50 mm at 94.25 mm/min is 200 s, 1 M steps of the demo machine's 0.2 ms.
CIRCLE_1M = """
[feed]
feed_mm_min = 94.25
accel_mm_s2 = 1000
jerk_mm_s3 = 50000

[path]
type = "circle"
center_mm = [0, 0]
radius_mm = 50
"""

MEMORY = """
import resource, sys
import contoursim.cli
assert contoursim.cli.main(["simulate", sys.argv[1], "--out", sys.argv[2] + "_small"]) == 0  # what a run costs once
with open("/proc/self/status") as status:
    before = next(int(line.split()[1]) for line in status if line.startswith("VmRSS:"))  # resident now [KiB]
assert contoursim.cli.main(["simulate", sys.argv[3], "--out", sys.argv[2]]) == 0
print(1024 * (resource.getrusage(resource.RUSAGE_SELF).ru_maxrss - before))  # ru_maxrss is in KiB on Linux
"""

GEOCOMP = """
import sys, time
import numpy as np
from contoursim.geocomp import GeometricCompensation
from contoursim.machine import load_machine

chain = load_machine(sys.argv[1]).chain
n = 300_000
travel = {b.axis: b.travel for b in chain.bodies if b.axis is not None}
lo, hi = (np.array([travel[a][k] for a in chain.axes]) for k in (0, 1))
s = np.linspace(0, 1, n)[:, None]
q = lo + (hi - lo) * (0.5 + 0.45 * np.sin(2 * np.pi * (3 + np.arange(len(chain.axes))) * s))
t = np.linspace(0, 60, n)
compensation = GeometricCompensation(chain)
compensation.commands(q[:100], t[:100])  # loads the compiled functions: not timed
start = time.process_time()
compensation.commands(q, t)
print(time.process_time() - start)
"""

SPLINE = """
import time
import numpy as np
from contoursim import paths
from contoursim.feed import plan

u = np.linspace(0, 2 * np.pi, 20_000, endpoint=False)
points = np.column_stack([100 * np.cos(u) + 10 * np.cos(7 * u), 80 * np.sin(u) + 10 * np.sin(5 * u)])
start = time.process_time()
path = paths.spline(points, closed=True)
plan(path, feed=50.0, accel=1000.0, jerk=50_000.0)
print(time.process_time() - start)
"""


GCODE = """
import time
import numpy as np
from contoursim.feed import plan
from contoursim.gcode import read_gcode

u = np.linspace(0, 2 * np.pi, 5_001)
blocks = [f"G1 X{50 * np.cos(a):.4f} Y{50 * np.sin(a):.4f} F{1000 + 500 * (k % 3)}" for k, a in enumerate(u[1:])]
program = read_gcode("\\n".join(["G21 G90 G17", "G0 X50 Y0", *blocks, "M30", ""]))
start = time.process_time()
plan(program.path, program.feeds, 1000.0, 50_000.0)
print(1e6 * (time.process_time() - start) / len(program.feeds))
"""


def cli_cpu(args, env=None):
    """CPU seconds (user + system) of ``python -m contoursim ARGS`` in a fresh process."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    subprocess.run([sys.executable, "-m", "contoursim", *args], cwd=ROOT, env=env, check=True,
                   stdout=subprocess.DEVNULL)
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    return (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)


def script_output(code, *args, warm=False):
    """What a fresh ``python -c CODE ARGS`` prints; with `warm`, of a second run after a first one."""
    for _ in range(2 if warm else 1):
        done = subprocess.run([sys.executable, "-c", code, *map(str, args)], cwd=ROOT, check=True,
                              capture_output=True, text=True)
    return float(done.stdout.split()[-1])


def main():
    with tempfile.TemporaryDirectory(prefix="bench_user_") as tmp:
        tmp = Path(tmp)
        cli_cpu(["demo", "--out", str(tmp / "warmup")])  # fills the numba cache
        print(f"demo_warm_s: {cli_cpu(['demo', '--out', str(tmp / 'demo')]):.2f}")
        print(f"help_s: {cli_cpu(['--help']):.2f}")
        cold = dict(os.environ, NUMBA_CACHE_DIR=str(tmp / "empty_numba_cache"),
                    CONTOURSIM_CACHE_DIR=str(tmp / "empty_contoursim_cache"))
        print(f"first_run_s: {cli_cpu(['demo', '--out', str(tmp / 'first')], env=cold):.2f}")

        circle = tmp / "circle_1M.toml"
        circle.write_text(CIRCLE_1M)
        small = tmp / "circle_10k.toml"  # the same circle 100 times as fast: 10 k steps
        small.write_text(CIRCLE_1M.replace("feed_mm_min = 94.25", "feed_mm_min = 9425"))
        growth = script_output(MEMORY, small, tmp / "memory", circle)
        with open(tmp / "memory" / "circle_1M.csv") as trace:
            steps = sum(1 for line in trace if line[:1] not in "#t")  # data rows: not metadata, not the header
        print(f"bytes_per_step: {growth / steps:.0f}")
        print(f"cli_1M_s: {cli_cpu(['simulate', str(circle), '--out', str(tmp / 'cli')]):.2f}")

        print(f"geocomp_7axis_300k_s: {script_output(GEOCOMP, 'aircraft_drilling_7axis', warm=True):.3f}")
        print(f"geocomp_3axis_300k_s: {script_output(GEOCOMP, 'vertical_mill_3axis', warm=True):.3f}")
        print(f"spline_20k_s: {script_output(SPLINE, warm=True):.3f}")
        print(f"gcode_plan_us_per_block: {script_output(GCODE, warm=True):.1f}")


if __name__ == "__main__":
    main()
