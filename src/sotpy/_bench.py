"""Helpers shared by the scripts in ``benchmarks/`` and the tests (not a public API)."""

from __future__ import annotations

import os
import platform

import numpy as np


def cpu_name() -> str:
    """The CPU model, as /proc/cpuinfo names it (else what ``platform`` knows)."""
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                if line.startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def machine_line(*extra: str) -> str:
    """``machine: <cpu>, <n> cores, Python <version>[, extra...]`` for a benchmark's
    output, so every recorded figure names the machine it was measured on."""
    parts = [cpu_name(), f"{os.cpu_count()} cores", f"Python {platform.python_version()}"]
    return "machine: " + ", ".join([*parts, *extra])


def adversarial_stack(
    rng: np.random.Generator,
    n: int | None = None,
    p: int | None = None,
    n_range: tuple[int, int] = (8, 41),
    p_range: tuple[int, int] = (2, 6),
) -> list[tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """A random hierarchical stack of the solver's hard class, as levels ``(A, lower,
    upper)``: ``n`` variables (drawn in ``n_range``), often a box first, then ``p``
    levels (drawn in ``p_range``) of rank-deficient rows (``U V^T``, rank below the row
    count) scaled by 1 to 100, mixing equalities, one-sided and two-sided bounds, and in
    most levels two one-sided bounds that conflict along one direction (``a x >= c`` and
    ``-s a x >= c'``)."""
    n = n or int(rng.integers(*n_range))
    p = p or int(rng.integers(*p_range))
    levels = []
    if rng.random() < 0.5:
        levels.append((np.eye(n), -rng.uniform(0.05, 1.0, n), rng.uniform(0.05, 1.0, n)))
    for _ in range(p):
        m = int(rng.integers(2, max(3, n // 2)))
        r = int(rng.integers(1, m + 1))
        A = rng.standard_normal((m, r)) @ rng.standard_normal((r, n))
        A *= 10.0 ** rng.uniform(0, 2, (m, 1))
        c = A @ rng.standard_normal(n) * 0.5 + rng.standard_normal(m)
        kind = rng.integers(0, 4, m)
        lo = np.where(kind <= 1, c, -np.inf)
        up = np.where((kind == 0) | (kind == 2), c, np.inf)
        both = kind == 3
        lo[both] = c[both] - rng.uniform(0, 1, both.sum())
        up[both] = c[both] + rng.uniform(0, 1, both.sum())
        if rng.random() < 0.6:  # two one-sided bounds that conflict
            A[1] = -A[0] * rng.uniform(0.5, 2.0)
            lo[0], up[0] = 0.1 * np.linalg.norm(A[0]), np.inf
            lo[1], up[1] = 0.1 * np.linalg.norm(A[1]), np.inf
        levels.append((A, lo.astype(float), up.astype(float)))
    return levels
