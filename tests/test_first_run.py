"""A first run on a machine uses the NumPy twins (the kernels compile in the
background, ``sotpy._jit``): the demos must pass their own checks on that path too, with
the twins' default budgets."""

from __future__ import annotations

import os
import subprocess
import sys

import pytest


@pytest.mark.parametrize(
    "demo, verdict",
    [
        ("talos", "reach OK: talos"),
        ("talos-collision", "talos-collision OK"),
        ("talos-torque", "talos-torque OK"),
    ],
)
def test_the_demos_pass_their_checks_on_the_numpy_twins(demo, verdict):
    """The demos run as a fresh machine's first run does (``SOTPY_JIT=0``: the same NumPy
    kernels as a module not compiled yet); each prints its verdict after checking its own
    run (wrist, feet, CoM, limits; distances, chatter; the feet on the floor, forces,
    CoPs, torque steps, tracking)."""
    env = dict(os.environ, SOTPY_JIT="0")
    out = subprocess.run(
        [sys.executable, "-m", "sotpy", "demo", demo],
        env=env,
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert out.returncode == 0, out.stdout[-2000:] + out.stderr[-2000:]
    assert verdict in out.stdout
