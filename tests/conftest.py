"""Shared fixtures: every test starts and ends with an empty pool at tick 0."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

import pytest

from sotpy.graph.pool import pool


@pytest.fixture(autouse=True)
def _clear_pool():
    """Clear the pool (entities, clock) before and after each test."""
    pool.clear()
    yield
    pool.clear()


@pytest.fixture(scope="module")
def bench_sot():
    """``benchmarks/bench_sot.py`` as a module (registered in ``sys.modules`` while the
    test module runs: its dataclasses look their module up there)."""
    path = Path(__file__).resolve().parents[1] / "benchmarks" / "bench_sot.py"
    spec = importlib.util.spec_from_file_location("bench_sot", path)
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module
    try:
        spec.loader.exec_module(module)
        yield module
    finally:
        sys.modules.pop(spec.name, None)
