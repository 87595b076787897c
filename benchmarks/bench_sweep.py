"""Sweeps and fleets: variants per second here and on a local dask cluster, the cost of a task, traces per minute.

The sweep: the demo mill on the ISO 230-4 circle (trajectories/iso230_4_circle_ccw.toml,
its own feed) with ``ccc_arc``, its gains ``kp`` (20–300 1/s) and ``ki``
(100–5,000 1/s², both log-uniform) drawn by a Latin hypercube (seed 1), every
variant stable (the coupled loop runs away from kp ≈ 500 1/s, and at kp 20–40
1/s from ki 10,000 1/s²); 1,000 variants by default. Printed, one ``name: value`` line each:

- ``sweep_variants_per_s_local``: :func:`contoursim.sweep.run_sweep` in this
  process (numba's threads on all cores), job built and kernels compiled
  before the clock starts (a first sweep of 8 variants);
  each of the three sweeps analyses its variants' coupled loops afresh, as a
  first sweep does (their stored analyses in a folder of its own: a sweep run
  again reads them back, and is faster);
- ``sweep_variants_per_s_cluster1``, ``sweep_variants_per_s_cluster2``: the
  same sweep on ``local:1`` and ``local:2`` (LocalClusters on 127.0.0.1, one
  single-threaded worker process per core share), from the moment the
  workers are warm (``client.run``) to the last row; the cluster's start and
  warm-up are printed apart (``sweep_cluster2_start_s``);
- ``sweep_scaling_efficiency_2``: cluster2 / (2 × cluster1);
- ``sweep_task_overhead_ms``: wall time per task of 200 tasks carrying a
  sweep's payload (the job's files and 32 variants' values) and returning 32
  rows, without simulating, on ``local:1``: what a task costs besides its
  variants;
- ``sweep_estimate_64_workers_variants_per_s`` (an ESTIMATE, not a
  measurement): 64 × the per-worker rate of cluster2 × t / (t + overhead),
  t the compute time of a 32-variant task at that rate;
- ``fleet_traces_per_min``: ``contoursim diagnose`` of 20 generated nightly
  circle tests (examples/fleet/make_nightly.py, X backlash 2–20 µm) with the
  nominal machine given, in this process; ``fleet_traces_per_min_cluster2``
  on local:2.

The machine this ran on has 2 cores (shared with other work: figures vary
from run to run). Run:  python benchmarks/bench_sweep.py [--variants 1000] [--traces 20]
"""

import argparse
import os
import runpy
import sys
import tempfile
import time
from pathlib import Path
from unittest import mock

import numpy as np

from contoursim.sweep import FIGURES, read_sweep, run_sweep, table_text

ROOT = Path(__file__).resolve().parents[1]
SPEC = """machine = "demo_mill"
path = "iso230_4_circle_ccw"
strategies = "ccc_arc"

[sweep]
method = "lhs"
count = {count}
seed = 1

[[vary]]
name = "strategy.ccc_arc.kp_per_s"
min = 20.0
max = 300.0
log = true

[[vary]]
name = "strategy.ccc_arc.ki_per_s2"
min = 100.0
max = 5000.0
log = true
"""
TASK = 32  # variants per task on the clusters


def _echo(files, names, rows):
    """A task with a sweep's payload that simulates nothing: one row of zeros per variant."""
    return [[0.0] * len(FIGURES) for _ in rows]


def _timed_sweep(sweep, scheduler):
    """Variants per second from the first ``progress(0, n)`` (workers warm) to the end, and the seconds before it.

    The loops' analyses (the coupled loop's margins along the path, a fifth of a variant's cost) are stored in a
    folder of this sweep's own (``CONTOURSIM_CACHE_DIR``, which a cluster's workers started here inherit): each
    sweep analyses every variant, as a first sweep does, not reads what the one before it stored.
    """
    marks = {}

    def progress(done, total):
        marks.setdefault(done, time.perf_counter())

    with tempfile.TemporaryDirectory(prefix="bench-sweep-analyses-") as analyses, \
            mock.patch.dict(os.environ, CONTOURSIM_CACHE_DIR=analyses):
        start = time.perf_counter()
        table = run_sweep(sweep, scheduler, progress=progress)
        end = time.perf_counter()
    return len(table) / (end - marks[0]), marks[0] - start, table


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--variants", type=int, default=1000)
    parser.add_argument("--traces", type=int, default=20)
    args = parser.parse_args()
    from contoursim.cluster import connected, run_tasks
    from contoursim.fleet import diagnose_fleet

    with tempfile.TemporaryDirectory() as folder:
        spec = Path(folder) / "bench.toml"
        spec.write_text(SPEC.format(count=8))
        run_sweep(read_sweep(spec))  # build the job, compile
        spec.write_text(SPEC.format(count=args.variants))
        sweep = read_sweep(spec)
        object.__setattr__(sweep, "task_size", TASK)
        local, _, table = _timed_sweep(sweep, None)
        assert not table[:, FIGURES.index("diverged")].any(), "a variant diverged: the benchmark's gains should all be stable"
        print(f"sweep_variants_per_s_local: {local:.4g}", flush=True)
        one, _, table1 = _timed_sweep(sweep, "local:1")
        two, start2, table2 = _timed_sweep(sweep, "local:2")
        same = table_text(sweep, table1) == table_text(sweep, table) == table_text(sweep, table2)
        print(f"sweep_variants_per_s_cluster1: {one:.4g}")
        print(f"sweep_variants_per_s_cluster2: {two:.4g}")
        print(f"sweep_cluster2_start_s: {start2:.3g}  (cluster start, job build and kernel warm-up on each worker)")
        print(f"sweep_scaling_efficiency_2: {two / (2 * one):.3g}")
        print(f"sweep_tables_identical: {same}")

        payload = (sweep.files, sweep.names, sweep.values[:TASK].tolist())
        with connected("local:1") as client:
            list(run_tasks(client, _echo, [payload] * 20, "warm"))
            start = time.perf_counter()
            list(run_tasks(client, _echo, [payload] * 200, "echo"))
            overhead = (time.perf_counter() - start) / 200
        print(f"sweep_task_overhead_ms: {1e3 * overhead:.3g}")
        compute = TASK / (two / 2)  # one task's variants on one single-core worker [s]
        estimate = 64 * (two / 2) * compute / (compute + overhead)
        print(f"sweep_estimate_64_workers_variants_per_s: {estimate:.4g}  (ESTIMATE: 64 x the per-worker rate of "
              f"cluster2 x {compute:.3g} s / ({compute:.3g} s + the task overhead); not measured)")

        nights = {f"day{d:02d}": float(v) for d, v in enumerate(np.linspace(2.0, 20.0, args.traces))}
        make = runpy.run_path(str(ROOT / "examples" / "fleet" / "make_nightly.py"))
        files = make["write_nights"](folder, nights)
        model = ROOT / "examples" / "fleet" / "nightly_mill.toml"
        diagnose_fleet(files[:1], model)  # compile
        start = time.perf_counter()
        here = diagnose_fleet(files, model)
        print(f"fleet_traces_per_min: {60 * len(files) / (time.perf_counter() - start):.3g}")
        marks = {}
        start = time.perf_counter()
        there = diagnose_fleet(files, model, "local:2", progress=lambda done, total: marks.setdefault(done, time.perf_counter()))
        print(f"fleet_traces_per_min_cluster2: {60 * len(files) / (time.perf_counter() - marks[0]):.3g}  "
              f"(from the cluster's start: {60 * len(files) / (time.perf_counter() - start):.3g})")
        named = sum(1 for o in here if "report" in o and o["report"]["effects"][:1]
                    and o["report"]["effects"][0]["name"] == "backlash")
        print(f"fleet_backlash_named: {named} of {len(files)}; same reports on local:2: {here == there}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
