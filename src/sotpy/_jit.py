"""Compiled kernels: numba when it is installed and not disabled.

A few per-tick numerical kernels (the hierarchical solver's iteration, the task rows, the
whole-body QP's reduction, the device's checks) are small dense linear algebra that would
take dozens of NumPy calls; at 1 kHz the calls cost more than the arithmetic. With numba
each runs as one compiled function. Every kernel has a NumPy twin, used when numba is
missing or ``SOTPY_JIT=0`` is set, and the tests compare the two.

Kernels are cached on disk (numba's ``cache=True``: next to the module, or in numba's
user cache when that is not writable; ``NUMBA_CACHE_DIR`` moves it). Compiling them takes
tens of seconds, so the first use on a machine does not wait for it (``SOTPY_JIT``
unset, ``1`` or ``auto``): a kernel module whose compiled code is not in the cache yet
(no *ready mark*, below) gives ``None`` kernels at import, so its owner runs the NumPy
twins for the whole process, and :func:`prepare` starts compiling it in a background
process for the next runs, saying so on stderr first; at exit, the process says how far
that compile got. ``SOTPY_JIT=wait`` (and ``sotpy compile``, for a robot's install)
compiles before running instead: :func:`prepare` says so with the expected time,
compiles the missing modules in parallel child processes and reports each one as it is
done. Either way the compile runs at LLVM optimisation level 1 (measured: about half the
compile time of the default level 3, and the same speed on these loops), one compile at
a time per install (a lock file: a run that waits for kernels another run is compiling
waits for that compile rather than doing it twice), and only the modules a run uses are
compiled (each owner prepares its own: the solver when a ``HierarchySolver`` is made, the
task rows with the first ``SOT``, the device's checks with the first ``Device``).

The ready mark of a module (``<module>.sotpy-ready.json`` in its numba cache directory)
is written once all its kernels are compiled and cached; it records the module source's
size and modification time and the numba and Python versions, so that an edited module,
another numba or another Python counts as not compiled.
"""

from __future__ import annotations

import atexit
import contextlib
import hashlib
import importlib
import json
import os
import subprocess
import sys
import tempfile
import threading
import time
import warnings
from collections.abc import Callable, Iterator, Sequence
from pathlib import Path
from typing import Any, TypeVar

import numpy as np

F = TypeVar("F", bound=Callable[..., Any])

try:  # pragma: no cover - exercised by the environment, not by a test
    import numba as _numba
except ImportError:  # pragma: no cover
    _numba = None

try:  # pragma: no cover - POSIX; elsewhere compiles are not serialised across runs
    import fcntl as _fcntl
except ImportError:  # pragma: no cover
    _fcntl = None


def _mode(value: str | None) -> str:
    """``SOTPY_JIT`` as one of ``"off"``, ``"wait"``, ``"auto"``."""
    value = (value or "auto").strip().lower()
    if value == "0":
        return "off"
    if value in ("wait", "auto", "1"):
        return "auto" if value == "1" else value
    print(f"sotpy: SOTPY_JIT={value!r} is not 0, 1, auto or wait; using auto", file=sys.stderr)
    return "auto"


#: What ``SOTPY_JIT`` asks for: ``"off"`` (``0``: the NumPy twins), ``"wait"`` (compile
#: before running) or ``"auto"`` (unset, ``1``: compiled kernels when cached, else the
#: NumPy twins for this run and a compile in the background).
MODE: str = _mode(os.environ.get("SOTPY_JIT"))

#: Whether compiled kernels can be used (numba importable and ``SOTPY_JIT`` not ``0``).
#: In ``auto`` mode a module not compiled yet still has ``None`` kernels.
ENABLED: bool = _numba is not None and MODE != "off"

#: compile time of each module's kernels at optimisation level 1 on this project's 2-core
#: machine, in seconds (what the announcement quotes; a faster machine takes less)
EXPECTED_SECONDS = {
    "sotpy.solvers._activeset_jit": 35.0,
    "sotpy.tasks._rowkernels": 5.0,
    "sotpy.dynamics.device": 3.0,
    "sotpy.solvers.wbc._kernels": 12.0,
    "sotpy.tasks._collisionkernels": 5.0,
}

#: Why a compiled path asked for explicitly is not there (for the owners' errors).
UNAVAILABLE = (
    "numba missing, SOTPY_JIT=0, or not compiled on this machine yet: `sotpy compile`"
    " or SOTPY_JIT=wait compiles before running"
)

_prepared: set[str] = set()
_lock = threading.Lock()
#: module -> numba's cache directory of its kernels (recorded as they are made)
_cache_dirs: dict[str, Path] = {}
#: module -> whether its ready mark was valid when it was imported (``auto`` mode)
_ready_at_import: dict[str, bool] = {}
#: the background compiles started by this process: (modules, process, start, log,
#: whether another run's compile held the lock when it started)
_background: list[tuple[list[str], subprocess.Popen[bytes], float, Path, bool]] = []


def kernel(fn: F | None = None, *, fast: bool = False) -> Any:
    """``numba.njit(cache=True, nogil=True, error_model="numpy")`` of ``fn`` when
    :data:`ENABLED`, else ``None`` (the caller then uses its NumPy twin); ``None`` too in
    ``auto`` mode when ``fn``'s module is not compiled yet (no valid ready mark: every
    kernel of a module is compiled or none is). ``fast=True`` lets sums be reassociated
    and multiply-adds fused (``fastmath={"reassoc", "contract"}``: vectorised dot
    products; no assumption about NaN or infinity)."""

    def wrap(f: F) -> F | None:
        if not ENABLED:
            return None
        options: dict[str, Any] = {"cache": True, "nogil": True, "error_model": "numpy"}
        if fast:
            options["fastmath"] = {"reassoc", "contract"}
        dispatcher = _numba.njit(**options)(f)
        module = f.__module__
        if module not in _cache_dirs:
            # another numba version: no cache directory known, compiled as asked
            with contextlib.suppress(Exception):
                _cache_dirs[module] = Path(dispatcher._cache._cache_path)
        if MODE == "auto":
            if module not in _ready_at_import:
                # unknown cache layout (another numba): the owner compiles in the foreground
                _ready_at_import[module] = module not in _cache_dirs or ready(module)
            if not _ready_at_import[module]:
                return None
        return dispatcher

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


def _stamp(name: str) -> dict[str, Any]:
    """What a ready mark of module ``name`` must match: its source, numba, Python."""
    st = os.stat(sys.modules[name].__file__)
    return {
        "source": [st.st_mtime_ns, st.st_size],
        "numba": _numba.__version__,
        "python": sys.version,
    }


def _mark_path(name: str) -> Path:
    return _cache_dirs[name] / f"{name}.sotpy-ready.json"


def ready(name: str) -> bool:
    """Whether module ``name`` (imported, with kernels) has a valid ready mark: all its
    kernels compiled and cached for this source, numba and Python."""
    try:
        return json.loads(_mark_path(name).read_text()) == _stamp(name)
    except (OSError, KeyError, ValueError, TypeError):
        return False


def mark_ready(name: str) -> None:
    """Write module ``name``'s ready mark (after its ``warm_up()`` compiled or loaded
    every kernel); a cache directory that cannot be written is left as it is."""
    if name not in _cache_dirs:
        return
    path = _mark_path(name)
    tmp = path.with_suffix(f".{os.getpid()}.tmp")
    with contextlib.suppress(OSError):
        tmp.write_text(json.dumps(_stamp(name)))
        os.replace(tmp, path)


def _lock_path() -> Path:
    """The lock file that serialises compiles of this install's kernels."""
    where = f"{sys.executable}|{Path(__file__).parent}|{os.environ.get('NUMBA_CACHE_DIR', '')}"
    key = hashlib.sha1(where.encode()).hexdigest()[:12]
    return Path(tempfile.gettempdir()) / f"sotpy-jit-{key}.lock"


@contextlib.contextmanager
def _compile_lock(waiting: str | None = None) -> Iterator[None]:
    """Hold this install's compile lock; when another process holds it, print
    ``waiting`` (if given) and wait for it."""
    if _fcntl is None:  # pragma: no cover
        yield
        return
    with open(_lock_path(), "a+b") as f:
        try:
            _fcntl.flock(f, _fcntl.LOCK_EX | _fcntl.LOCK_NB)
        except OSError:
            if waiting:
                print(waiting, file=sys.stderr, flush=True)
            _fcntl.flock(f, _fcntl.LOCK_EX)
        try:
            yield
        finally:
            _fcntl.flock(f, _fcntl.LOCK_UN)


def _lock_busy() -> bool:
    """Whether another process holds this install's compile lock now (a compile runs)."""
    if _fcntl is None:  # pragma: no cover
        return False
    with open(_lock_path(), "a+b") as f:
        try:
            _fcntl.flock(f, _fcntl.LOCK_EX | _fcntl.LOCK_NB)
        except OSError:
            return True
        _fcntl.flock(f, _fcntl.LOCK_UN)
        return False


def _expected(names: Sequence[str]) -> float:
    """The expected wall time of compiling ``names`` in parallel on this machine (s)."""
    workers = min(len(names), max(1, os.cpu_count() or 1))
    seconds = [EXPECTED_SECONDS.get(n, 10.0) for n in names]
    return max(max(seconds), sum(seconds) / workers)


def prepare(what: str, modules: Sequence[str]) -> None:
    """Make the kernels of ``modules`` (each with a ``warm_up()``) ready for this process.

    Modules compiled already are loaded from the cache (``warm_up()``). In ``auto`` mode,
    the modules that were not compiled when imported (their kernels are ``None``: the
    owner runs the NumPy twins) are compiled by a background process, announced first
    on stderr; in ``wait`` mode they are compiled now, in child processes, announced
    first with the expected time and reported as each one is done."""
    if not ENABLED:
        return
    with _lock:
        todo = [m for m in modules if m not in _prepared]
        if not todo:
            return
        mods = {name: importlib.import_module(name) for name in todo}
        cold = [name for name in todo if not _ready_at_import.get(name, True)]
        if cold:
            _compile_in_background(what, cold)
        warm = {name: mod for name, mod in mods.items() if name not in cold}
        missing = [name for name, mod in warm.items() if not _cached(mod)]
        if missing:
            waiting = f"sotpy: waiting for {what}, being compiled by another sotpy run"
            with _compile_lock(waiting):
                missing = [n for n in missing if not _cached(warm[n])]
                if missing:
                    _compile_children(what, missing)
        for name, mod in warm.items():
            start = time.perf_counter()
            mod.warm_up()
            seconds = time.perf_counter() - start
            if seconds > 3.0:  # compiled here after all (the children failed)
                print(f"sotpy: compiled {name} in {seconds:.0f} s", file=sys.stderr)
            if not ready(name):
                mark_ready(name)
        _prepared.update(todo)


def _compile_in_background(what: str, names: list[str]) -> None:
    """Start a detached process that compiles ``names`` for the next runs (after any
    compile already running for this install), and say so first."""
    _prepared.update(names)  # once per process: this run keeps the NumPy twins
    log = _lock_path().with_suffix(".log")
    # a compile another run started (usually of these very modules): the one started
    # here waits for it and then compiles only what it left not ready
    busy = _lock_busy()
    when = (
        "another sotpy run is compiling kernels for this install: the background compile"
        " waits for it, then compiles what it leaves"
        if busy
        else f"about {_expected(names):.0f} s"
    )
    print(
        f"sotpy: {what}: not compiled on this machine yet; this run uses their NumPy"
        " kernels (slower per tick) and compiles them in the background for the next"
        f" runs ({when}; `sotpy compile` or SOTPY_JIT=wait compiles before running"
        " instead)",
        file=sys.stderr,
        flush=True,
    )
    path = os.pathsep.join(p for p in sys.path if p)
    env = dict(os.environ, SOTPY_JIT="wait", PYTHONPATH=path)
    code = f"from sotpy import _jit; _jit.compile_modules({names!r}, quiet=True)"
    with contextlib.suppress(OSError):  # keep the log of the last compiles only
        if log.stat().st_size > 1_000_000:
            log.unlink()
    with open(log, "ab") as out:
        proc = subprocess.Popen(
            [sys.executable, "-c", code],
            env=env,
            stdin=subprocess.DEVNULL,
            stdout=out,
            stderr=out,
            start_new_session=True,  # a Ctrl-C of this run does not stop it
        )
    if not _background:
        atexit.register(_report_background)
    _background.append((names, proc, time.perf_counter(), log, busy))


def _report_background() -> None:
    """At exit: how far the background compiles this process started have got."""
    for names, proc, start, log, busy in _background:
        seconds = time.perf_counter() - start
        code = proc.poll()
        if code is None and busy:
            state = (
                f"still running, behind the compile another sotpy run started ({seconds:.0f}"
                f" s so far, pid {proc.pid}); the runs started after it ends use the compiled"
                " kernels"
            )
        elif code is None:
            state = (
                f"still running ({seconds:.0f} s of about {_expected(names):.0f}, pid"
                f" {proc.pid}); the runs started after it ends use the compiled kernels"
            )
        elif code == 0:
            state = "done: the next runs use the compiled kernels"
        else:
            state = f"failed (exit code {code}; its output is in {log})"
        print(f"sotpy: the background compile of {', '.join(names)}: {state}", file=sys.stderr)


def compile_modules(names: Sequence[str] | None = None, quiet: bool = False) -> list[str]:
    """Compile the kernels of ``names`` (default: every module of
    :data:`EXPECTED_SECONDS`) that are not ready, after any compile running for this
    install, and mark them ready; what ``sotpy compile`` and a background compile run.
    Returns the modules compiled (empty when every one was ready)."""
    if _numba is None or MODE == "off":
        return []
    names = list(EXPECTED_SECONDS) if names is None else list(names)
    for name in names:
        importlib.import_module(name)
    waiting = None if quiet else "sotpy: waiting for a compile started by another sotpy run"
    with _compile_lock(waiting):
        todo = [n for n in names if n in _cache_dirs and not ready(n)]
        if todo:
            why = "not marked ready: a module already in numba's cache loads in seconds"
            _compile_children("the per-tick kernels", todo, quiet=quiet, why=why)
    return todo


def _compile_children(
    what: str,
    names: list[str],
    quiet: bool = False,
    why: str = "first use on this machine, cached afterwards",
) -> None:
    """Compile (``warm_up()``) each of ``names`` in a child process, as many at once as
    there are cores, and write their ready marks; unless ``quiet``, say so on stderr
    first and report each module as it is done."""
    workers = min(len(names), max(1, os.cpu_count() or 1))
    say = (lambda *a, **k: None) if quiet else print
    say(
        f"sotpy: compiling {what} ({why};"
        f" about {_expected(names):.0f} s, {len(names)} module{'s' if len(names) > 1 else ''}"
        f" in {workers} process{'es' if workers > 1 else ''})",
        file=sys.stderr,
        flush=True,
    )
    # the children import the modules as this process does (its sys.path: a source tree,
    # a path added at run time)
    path = os.pathsep.join(p for p in sys.path if p)
    env = dict(os.environ, NUMBA_OPT="1", PYTHONPATH=path, SOTPY_JIT="wait")
    start = time.perf_counter()
    running: list[tuple[str, subprocess.Popen[bytes]]] = []
    pending = list(names)
    done = 0
    tty = sys.stderr.isatty() and not quiet
    while pending or running:
        while pending and len(running) < workers:
            name = pending.pop(0)
            code = f"import {name} as m, sotpy._jit as j; m.warm_up(); j.mark_ready({name!r})"
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
                file=sys.stdout if quiet else sys.stderr,
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


def any_layout(ndim: int, dtype: type = np.float64) -> np.ndarray:
    """A read-only array of layout ``A`` (a strided view) of ``ndim`` dimensions: a
    kernel compiled for it (``warm_up`` calls it with such arrays) takes any array of
    that dtype and dimension, C or Fortran, writable or not, with one compiled version
    (numba converts the argument's type at the call). Also what a call pads its unused
    array positions with."""
    a = np.zeros((3, 4) if ndim == 2 else 4, dtype=dtype)[..., ::2]
    a.setflags(write=False)
    return a
