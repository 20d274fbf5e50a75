"""Shared fixtures: every test starts and ends with an empty pool at tick 0."""

from __future__ import annotations

import pytest

from sotpy.graph.pool import pool


@pytest.fixture(autouse=True)
def _clear_pool():
    """Clear the pool (entities, clock) before and after each test."""
    pool.clear()
    yield
    pool.clear()
