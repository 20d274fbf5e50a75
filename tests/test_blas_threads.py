"""sotpy limits BLAS to one thread when its first solver is created (sotpy._blas)."""

from __future__ import annotations

import json
import os
import subprocess
import sys

import pytest

SCRIPT = """
import json
from threadpoolctl import threadpool_info
import numpy, scipy.linalg
before = [p["num_threads"] for p in threadpool_info() if p["user_api"] == "blas"]
from sotpy.solvers import HierarchySolver
try:
    HierarchySolver()
    error = None
except Exception as exc:
    error = f"{type(exc).__name__}: {exc}"
after = [p["num_threads"] for p in threadpool_info() if p["user_api"] == "blas"]
print(json.dumps({"before": before, "after": after, "error": error}))
"""


def run(setting: str | None) -> dict:
    env = dict(os.environ)
    env.pop("SOTPY_BLAS_THREADS", None)
    env["OPENBLAS_NUM_THREADS"] = "2"  # a multi-threaded start, whatever the machine
    if setting is not None:
        env["SOTPY_BLAS_THREADS"] = setting
    out = subprocess.run(
        [sys.executable, "-c", SCRIPT], env=env, capture_output=True, text=True, check=True
    )
    return json.loads(out.stdout.strip().splitlines()[-1])


def test_first_solver_limits_blas_to_one_thread():
    r = run(None)
    assert r["error"] is None
    assert r["before"] and max(r["before"]) == 2
    assert r["after"] == [1] * len(r["after"])


def test_setting_zero_leaves_blas_alone_and_n_sets_n():
    r = run("0")
    assert r["after"] == r["before"]
    r = run("2")
    assert r["after"] == [2] * len(r["after"])


@pytest.mark.parametrize("bad", ["one"])
def test_bad_setting_is_a_clear_error(bad):
    r = run(bad)
    assert r["error"] is not None and "SotpyError" in r["error"]
    assert "SOTPY_BLAS_THREADS" in r["error"]
