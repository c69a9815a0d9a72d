"""Every benchmark script still imports: a refactoring that moves a module must move the benchmarks'
imports with it (bench_pt_traversal.py imported two modules the restructuring had moved, and nothing
noticed until it was run). The scripts run nothing at import (their work is under ``__main__``)."""
import importlib.util
from pathlib import Path

import pytest

BENCH = Path(__file__).resolve().parents[1] / "benchmarks"


@pytest.mark.parametrize("path", sorted(BENCH.glob("*.py")), ids=lambda p: p.name)
def test_benchmark_imports(path):
    spec = importlib.util.spec_from_file_location(f"_bench_{path.stem}", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    assert callable(module.main)                # every script has its entry point
