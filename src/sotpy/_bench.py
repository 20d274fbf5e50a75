"""Helpers shared by the scripts in ``benchmarks/`` (not a public API)."""

from __future__ import annotations

import os
import platform


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
