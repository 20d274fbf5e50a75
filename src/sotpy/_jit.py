"""Compiled kernels: numba when it is installed and not disabled.

A few per-tick numerical kernels (the hierarchical solver's iteration, the task rows, the
whole-body QP's reduction, the device's checks) are small dense linear algebra that would
take dozens of NumPy calls; at 1 kHz the calls cost more than the arithmetic. With numba
each runs as one compiled function. Every kernel has a NumPy twin, used when numba is
missing or ``SOTPY_JIT=0`` is set, and the tests compare the two.

Kernels are cached on disk (numba's ``cache=True``: next to the module, or in numba's
user cache when that is not writable; ``NUMBA_CACHE_DIR`` moves it). The first use on a
machine compiles them: :func:`prepare` says so on stderr *before* it starts, with the
expected time, compiles the missing modules in parallel child processes at LLVM
optimisation level 1 (measured: about half the compile time of the default level 3, and
the same speed on these loops), reports each one as it is done, then the process loads
them from the cache. Only the modules a run uses are compiled (each owner prepares its
own: the solver when a ``HierarchySolver`` is made, the task rows with the first ``SOT``,
the device's checks with the first ``Device``).
"""

from __future__ import annotations

import importlib
import os
import subprocess
import sys
import threading
import time
import warnings
from collections.abc import Callable, Sequence
from typing import Any, TypeVar

import numpy as np

F = TypeVar("F", bound=Callable[..., Any])

try:  # pragma: no cover - exercised by the environment, not by a test
    import numba as _numba
except ImportError:  # pragma: no cover
    _numba = None

#: Whether compiled kernels are used (numba importable and ``SOTPY_JIT`` not ``0``).
ENABLED: bool = _numba is not None and os.environ.get("SOTPY_JIT", "1") != "0"

#: compile time of each module's kernels at optimisation level 1 on this project's 2-core
#: machine, in seconds (what the announcement quotes; a faster machine takes less)
EXPECTED_SECONDS = {
    "sotpy.solvers._activeset_jit": 30.0,
    "sotpy.tasks._rowkernels": 8.0,
    "sotpy.dynamics.device": 3.0,
    "sotpy.solvers.wbc._kernels": 12.0,
    "sotpy.tasks._collisionkernels": 5.0,
}

_prepared: set[str] = set()
_lock = threading.Lock()


def kernel(fn: F | None = None, *, fast: bool = False) -> Any:
    """``numba.njit(cache=True, nogil=True, error_model="numpy")`` of ``fn`` when
    :data:`ENABLED`, else ``None`` (the caller then uses its NumPy twin). ``fast=True``
    lets sums be reassociated and multiply-adds fused (``fastmath={"reassoc",
    "contract"}``: vectorised dot products; no assumption about NaN or infinity)."""

    def wrap(f: F) -> F | None:
        if not ENABLED:
            return None
        options: dict[str, Any] = {"cache": True, "nogil": True, "error_model": "numpy"}
        if fast:
            options["fastmath"] = {"reassoc", "contract"}
        return _numba.njit(**options)(f)

    return wrap if fn is None else wrap(fn)


def _dispatchers(module: Any) -> list[Any]:
    return [v for v in vars(module).values() if isinstance(v, _numba.core.dispatcher.Dispatcher)]


def _cached(module: Any) -> bool:
    """Whether every kernel of ``module`` has an up-to-date entry in numba's disk cache
    (numba's index files; anything unexpected counts as not cached)."""
    try:
        kernels = _dispatchers(module)
        return bool(kernels) and all(k._cache._cache_file._load_index() for k in kernels)
    except Exception:  # pragma: no cover - another numba version
        return False


def prepare(what: str, modules: Sequence[str]) -> None:
    """Make sure the kernels of ``modules`` (each with a ``warm_up()``) are in the disk
    cache, compiling the missing ones in child processes, in parallel, and saying so
    first; then ``warm_up()`` each in this process (a load from the cache)."""
    if not ENABLED:
        return
    with _lock:
        todo = [m for m in modules if m not in _prepared]
        if not todo:
            return
        mods = {name: importlib.import_module(name) for name in todo}
        missing = [name for name, mod in mods.items() if not _cached(mod)]
        if missing:
            _compile_children(what, missing)
        for name, mod in mods.items():
            start = time.perf_counter()
            mod.warm_up()
            seconds = time.perf_counter() - start
            if seconds > 3.0:  # compiled here after all (the children failed)
                print(f"sotpy: compiled {name} in {seconds:.0f} s", file=sys.stderr)
            _prepared.add(name)


def _compile_children(what: str, names: list[str]) -> None:
    expected = max(EXPECTED_SECONDS.get(n, 10.0) for n in names)
    total = sum(EXPECTED_SECONDS.get(n, 10.0) for n in names)
    workers = min(len(names), max(1, os.cpu_count() or 1))
    guess = max(expected, total / workers)
    print(
        f"sotpy: compiling {what} (first use on this machine, cached afterwards;"
        f" about {guess:.0f} s, {len(names)} module{'s' if len(names) > 1 else ''}"
        f" in {workers} process{'es' if workers > 1 else ''})",
        file=sys.stderr,
        flush=True,
    )
    # the children import the modules as this process does (its sys.path: a source tree,
    # a path added at run time)
    path = os.pathsep.join(p for p in sys.path if p)
    env = dict(os.environ, NUMBA_OPT="1", PYTHONPATH=path)
    start = time.perf_counter()
    running: list[tuple[str, subprocess.Popen[bytes]]] = []
    pending = list(names)
    done = 0
    tty = sys.stderr.isatty()
    while pending or running:
        while pending and len(running) < workers:
            name = pending.pop(0)
            code = f"import {name} as m; m.warm_up()"
            proc = subprocess.Popen(
                [sys.executable, "-c", code],
                env=env,
                stderr=subprocess.PIPE,
                stdout=subprocess.DEVNULL,
            )
            running.append((name, proc))
        time.sleep(0.05)
        if tty:
            print(
                f"\rsotpy:   {time.perf_counter() - start:.0f} s ",
                end="",
                file=sys.stderr,
                flush=True,
            )
        for name, proc in list(running):
            if proc.poll() is None:
                continue
            running.remove((name, proc))
            done += 1
            err = ""
            if proc.stderr:
                err = proc.stderr.read().decode(errors="replace")
                proc.stderr.close()
            state = "done" if proc.returncode == 0 else f"failed ({err.strip()[-200:]})"
            print(
                f"{chr(13) if tty else ''}sotpy:   [{done}/{len(names)}] {name}: {state},"
                f" {time.perf_counter() - start:.0f} s",
                file=sys.stderr,
                flush=True,
            )


def report_compile(what: str, seconds: float) -> None:
    """Say on stderr that ``what`` was compiled in this process (not loaded from the
    cache) when that took long enough to be noticed (for kernels not yet prepared with
    :func:`prepare`)."""
    if seconds > 3.0:
        print(
            f"sotpy: compiled {what} in {seconds:.0f} s (cached for the next runs)", file=sys.stderr
        )


def refused(owner: str, exc: Exception) -> None:
    """Warn that ``owner``'s compiled kernels refused their arguments (types they were
    not compiled for, compilation being frozen after the warm-up) and that it uses its
    NumPy path from now on."""
    from .errors import SotpyWarning

    warnings.warn(
        f"{owner}: compiled kernels refused the data ({exc}); NumPy from now on",
        SotpyWarning,
        stacklevel=4,
    )


def c_float64(a: np.ndarray) -> np.ndarray:
    """``a`` as a C-contiguous float64 array (itself when it already is: the usual case,
    checked without a copy), the layout the kernels were compiled for."""
    if a.dtype == np.float64 and a.flags.c_contiguous:
        return a
    return np.ascontiguousarray(a, dtype=np.float64)
