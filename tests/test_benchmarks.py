"""Benchmark scripts do not rot: each one loads (its imports resolve) without running its measurements."""

import runpy
import sys

import pytest

from conftest import ROOT

BENCHMARKS = sorted((ROOT / "benchmarks").glob("bench_*.py"))


@pytest.mark.parametrize("script", BENCHMARKS, ids=[p.name for p in BENCHMARKS])
def test_benchmark_script_loads(script, monkeypatch):
    monkeypatch.syspath_prepend(str(script.parent))  # scripts import their neighbours, as when run from there
    namespace = runpy.run_path(str(script), run_name="benchmark_under_test")
    assert callable(namespace.get("main")), f"{script.name} has no main()"
    monkeypatch.delitem(sys.modules, "bench_chain", raising=False)
