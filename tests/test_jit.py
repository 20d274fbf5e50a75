"""sotpy._jit: the switch, the first-compile notice, the background compile."""

from __future__ import annotations

import ast
import os
import subprocess
import sys
import time
import types

import pytest

from sotpy import _jit


def _enabled_with(value: str | None) -> str:
    env = dict(os.environ)
    env.pop("SOTPY_JIT", None)
    if value is not None:
        env["SOTPY_JIT"] = value
    code = (
        "import sotpy._jit as j, sotpy.solvers._activeset_jit as e;"
        "print(j.ENABLED, e.solve is None)"
    )
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True)
    assert out.returncode == 0, out.stderr
    return out.stdout.strip()


def test_sotpy_jit_0_turns_the_kernels_off():
    assert _enabled_with("0") == "False True"
    try:
        import numba  # noqa: F401
    except ImportError:
        return
    assert _enabled_with("wait") == "True False"


def test_first_compile_is_reported_on_stderr(capsys):
    _jit.report_compile("the kernels", 12.4)
    assert "compiled the kernels in 12 s" in capsys.readouterr().err
    _jit.report_compile("the kernels", 0.5)  # a cache load: nothing said
    assert capsys.readouterr().err == ""


TINY = """
import numpy as np
from sotpy._jit import kernel


@kernel
def twice(a):
    return 2.0 * a[0]


def warm_up():
    twice(np.ones(1))
    twice.disable_compile()
"""


def test_prepare_announces_a_compile_before_it_and_is_silent_once_cached(tmp_path):
    try:
        import numba  # noqa: F401
    except ImportError:
        return
    (tmp_path / "sotpy_tiny_kernels.py").write_text(TINY)
    code = (
        f"import sys; sys.path.insert(0, {str(tmp_path)!r});"
        "from sotpy import _jit; _jit.prepare('the tiny kernel', ['sotpy_tiny_kernels']);"
        "import sotpy_tiny_kernels as m, numpy as np; print(m.twice(np.full(1, 4.0)))"
    )
    env = dict(os.environ, SOTPY_JIT="wait")
    env.pop("NUMBA_CACHE_DIR", None)
    runs = [
        subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True)
        for _ in range(2)
    ]
    for out in runs:
        assert out.returncode == 0, out.stderr
        assert out.stdout.strip() == "8.0"
    first = runs[0].stderr.splitlines()
    # said first, with what and why; then the module's progress line
    assert first[0].startswith("sotpy: compiling the tiny kernel (first use on this machine")
    assert "[1/1] sotpy_tiny_kernels: done" in first[-1]
    assert list(tmp_path.glob("__pycache__/sotpy_tiny_kernels.twice-*.nbi"))
    assert runs[1].stderr == ""  # loaded from the cache: nothing said
    assert (tmp_path / "__pycache__" / "sotpy_tiny_kernels.sotpy-ready.json").exists()


TINY_AUTO = """
import numpy as np
from sotpy._jit import kernel


def _twice(a):
    return 2.0 * a[0]


twice_k = kernel(_twice)
twice = twice_k or _twice


def warm_up():
    if twice_k is not None:
        twice_k(np.ones(1))
        twice_k.disable_compile()
"""


def _run_auto(tmp_path, env):
    code = (
        f"import sys; sys.path.insert(0, {str(tmp_path)!r});"
        "from sotpy import _jit; import sotpy_auto_kernels as m;"
        "_jit.prepare('the tiny kernel', ['sotpy_auto_kernels']);"
        "import numpy as np; print(m.twice_k is not None, m.twice(np.full(1, 4.0)))"
    )
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True)
    assert out.returncode == 0, out.stderr
    return out


def _wait_for(path, seconds=120.0):
    end = time.monotonic() + seconds
    while not path.exists() and time.monotonic() < end:
        time.sleep(0.2)
    assert path.exists(), f"no {path.name} after {seconds} s"


def test_a_first_run_uses_numpy_and_compiles_in_the_background(tmp_path):
    """``auto`` (the default): a module not compiled yet runs its NumPy twin at once, a
    background process compiles it, the next run uses the compiled kernel; editing the
    module's source makes it count as not compiled again."""
    pytest.importorskip("numba")
    source = tmp_path / "sotpy_auto_kernels.py"
    source.write_text(TINY_AUTO)
    env = dict(os.environ)
    env.pop("SOTPY_JIT", None)  # the default
    env.pop("NUMBA_CACHE_DIR", None)
    mark = tmp_path / "__pycache__" / "sotpy_auto_kernels.sotpy-ready.json"
    first = _run_auto(tmp_path, env)
    assert first.stdout.split() == ["False", "8.0"]  # the NumPy twin, at once
    lines = first.stderr.splitlines()
    assert lines[0].startswith("sotpy: the tiny kernel: not compiled on this machine yet;")
    assert "in the background" in lines[0]
    assert lines[-1].startswith("sotpy: the background compile of sotpy_auto_kernels:")
    _wait_for(mark)
    second = _run_auto(tmp_path, env)
    assert second.stdout.split() == ["True", "8.0"]  # compiled, loaded from the cache
    assert second.stderr == ""
    # an edited module is not the one compiled: NumPy again, and a compile again
    source.write_text(TINY_AUTO + "\n# edited\n")
    third = _run_auto(tmp_path, env)
    assert third.stdout.split() == ["False", "8.0"]
    assert "not compiled on this machine yet" in third.stderr
    _wait_for(mark)  # (rewritten when the compile ends; a leftover process would lock)
    deadline = time.monotonic() + 120
    while _run_auto(tmp_path, env).stdout.split()[0] != "True":
        assert time.monotonic() < deadline, "the edited module was never compiled"
        time.sleep(1.0)


def test_a_compile_waits_for_the_one_running(tmp_path, capsys):
    """One compile at a time per install: while another process holds the compile lock,
    taking it says so and waits until it is released."""
    if _jit._fcntl is None:
        pytest.skip("no fcntl: compiles are not serialised on this platform")
    path = _jit._lock_path()
    holder = subprocess.Popen(
        [
            sys.executable,
            "-c",
            "import fcntl, sys, time; f = open(sys.argv[1], 'a+b');"
            "fcntl.flock(f, fcntl.LOCK_EX); print('held', flush=True); time.sleep(1.5)",
            str(path),
        ],
        stdout=subprocess.PIPE,
        text=True,
    )
    try:
        assert holder.stdout.readline().strip() == "held"
        start = time.monotonic()
        with _jit._compile_lock("sotpy: waiting for the other compile"):
            waited = time.monotonic() - start  # the holder lets go when it ends
    finally:
        holder.wait(timeout=30)
    assert waited > 0.5
    assert "waiting for the other compile" in capsys.readouterr().err
    with _jit._compile_lock("sotpy: waiting"):  # free: taken at once, nothing said
        pass
    assert capsys.readouterr().err == ""


def test_sotpy_jit_values():
    assert _jit._mode(None) == _jit._mode("1") == _jit._mode(" AUTO ") == "auto"
    assert _jit._mode("0") == "off"
    assert _jit._mode("wait") == "wait"


def test_an_unknown_sotpy_jit_value_is_said_and_means_auto(capsys):
    assert _jit._mode("fast") == "auto"
    assert "SOTPY_JIT='fast' is not 0, 1, auto or wait" in capsys.readouterr().err


def _literal_int(node) -> bool:
    if isinstance(node, ast.UnaryOp) and isinstance(node.op, ast.USub):
        node = node.operand
    return (
        isinstance(node, ast.Constant)
        and isinstance(node.value, int)
        and not isinstance(node.value, bool)
    )


def test_kernels_call_their_helpers_without_integer_literals():
    """numba compiles a helper once per integer literal it is called with (its type is
    ``Literal[int](0)``, not ``int64``): the solver's module compiled four of its
    helpers two or three times, about 9 s of its 39 s compile on the 2-core machine. Inside a
    kernel module, a call to another kernel of the module passes no integer literal."""
    import pathlib

    root = pathlib.Path(_jit.__file__).parent
    modules = [
        root / "solvers" / "_activeset_jit.py",
        root / "solvers" / "wbc" / "_kernels.py",
        root / "tasks" / "_rowkernels.py",
        root / "tasks" / "_collisionkernels.py",
    ]
    found = []
    for path in modules:
        tree = ast.parse(path.read_text())
        kernels = {  # functions decorated with @kernel(...) or wrapped as kernel(f)
            f.name
            for f in ast.walk(tree)
            if isinstance(f, ast.FunctionDef)
            and any("kernel" in ast.unparse(d) for d in f.decorator_list)
        }
        for a in ast.walk(tree):  # name = kernel(f): both names are the kernel's
            if (
                isinstance(a, ast.Assign)
                and isinstance(a.value, ast.Call)
                and ast.unparse(a.value.func) == "kernel"
            ):
                kernels |= {ast.unparse(a.targets[0]), ast.unparse(a.value.args[0])}
        assert kernels, path
        for f in ast.walk(tree):
            if not (isinstance(f, ast.FunctionDef) and f.name in kernels):
                continue
            for call in ast.walk(f):
                if (
                    isinstance(call, ast.Call)
                    and isinstance(call.func, ast.Name)
                    and call.func.id in kernels
                    and any(_literal_int(a) for a in call.args)
                ):
                    found.append(f"{path.name}:{call.lineno} {ast.unparse(call)[:60]}")
    assert not found, found


def test_compile_modules_compiles_what_is_not_ready_once(tmp_path):
    """What ``sotpy compile`` runs: the modules without a ready mark are compiled (in a
    child process) and marked; a second call has nothing to do."""
    pytest.importorskip("numba")
    (tmp_path / "sotpy_cm_kernels.py").write_text(TINY_AUTO)
    code = (
        f"import sys; sys.path.insert(0, {str(tmp_path)!r});"
        "from sotpy import _jit;"
        "print(_jit.compile_modules(['sotpy_cm_kernels'], quiet=True),"
        " _jit.compile_modules(['sotpy_cm_kernels'], quiet=True),"
        " _jit.ready('sotpy_cm_kernels'))"
    )
    env = dict(os.environ)
    env.pop("SOTPY_JIT", None)  # as `sotpy compile` runs: the default mode
    env.pop("NUMBA_CACHE_DIR", None)
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True)
    assert out.returncode == 0, out.stderr
    assert out.stdout.split("\n")[-2] == "['sotpy_cm_kernels'] [] True"
    assert list(tmp_path.glob("__pycache__/sotpy_cm_kernels._twice-*.nbi"))


def test_sotpy_compile_leaves_every_kernel_module_ready():
    pytest.importorskip("numba")
    env = dict(os.environ)
    env.pop("SOTPY_JIT", None)
    out = subprocess.run(
        [sys.executable, "-m", "sotpy", "compile"], env=env, capture_output=True, text=True
    )
    assert out.returncode == 0, out.stderr
    assert "every kernel module is ready" in out.stdout
    code = (
        "import importlib; from sotpy import _jit;"
        "[importlib.import_module(n) for n in _jit.EXPECTED_SECONDS];"
        "print(all(_jit.ready(n) for n in _jit.EXPECTED_SECONDS))"
    )
    check = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True)
    assert check.stdout.strip() == "True", check.stderr


def _owners():
    import numpy as np

    from sotpy.solvers import _activeset_jit
    from sotpy.solvers.hierarchy import HierarchySolver
    from sotpy.solvers.wbc import _kernels
    from sotpy.solvers.wbc.qp import WeightedQP

    return [
        (lambda jit: WeightedQP(np.arange(6, 10), np.arange(6), jit=jit), _kernels, "solve"),
        (lambda jit: HierarchySolver(jit=jit), _activeset_jit, "solve"),
    ]


@pytest.mark.parametrize("index", [0, 1], ids=["WeightedQP", "HierarchySolver"])
def test_an_owner_of_a_module_not_compiled_yet_starts_its_compile(monkeypatch, index):
    """A first run on a machine: the module's kernels are ``None`` (not compiled), the
    owner runs the NumPy code and asks ``prepare`` for its module, which compiles it in
    the background for the next runs; asked for NumPy (``jit=False``), it asks nothing."""
    make, module, name = _owners()[index]
    calls: list[list[str]] = []
    monkeypatch.setattr(_jit, "prepare", lambda what, modules: calls.append(list(modules)))
    monkeypatch.setattr(module, name, None)  # as imported before the first compile
    owner = make(None)
    assert owner.jit is False
    assert calls == [[module.__name__]]
    calls.clear()
    assert make(False).jit is False
    assert calls == []


def test_a_weighted_controller_leaves_the_hierarchical_kernels_alone(monkeypatch):
    """Nothing is compiled that the run does not use: a ``OneLevelWeighted`` controller
    asks only for the whole-body QP kernel and the row writers (its problem's); its
    hierarchical solver is made (and its kernels asked for) when ``MultiLevelWeighted``
    is chosen, at construction or later."""
    import example_robot_data as erd

    from sotpy.solvers.wbc import WholeBodyController

    model = erd.load("panda").model
    calls: list[str] = []
    monkeypatch.setattr(_jit, "prepare", lambda what, modules: calls.extend(modules))
    w = WholeBodyController(model)
    assert w._hierarchy is None
    weighted = {"sotpy.solvers.wbc._kernels", "sotpy.tasks._rowkernels"}
    assert set(calls) == weighted
    w.setStrategy("MultiLevelWeighted")
    assert w._hierarchy is not None
    assert set(calls) == weighted | {"sotpy.solvers._activeset_jit"}
    calls.clear()
    h = WholeBodyController(model, "MultiLevelWeighted")._hierarchy
    assert h is not None
    assert "sotpy.solvers._activeset_jit" in calls


def test_a_background_compile_behind_another_says_so(monkeypatch, capsys):
    """A second run started while a first one's background compile holds the lock: its
    own background compile waits behind it, and both messages say so instead of
    promising the compile's usual length."""
    if _jit._fcntl is None:
        pytest.skip("no fcntl: compiles are not serialised on this platform")

    class Pending:  # the background process, still running at exit
        pid = 4242

        def poll(self):
            return None

    fake = types.SimpleNamespace(Popen=lambda *a, **k: Pending(), DEVNULL=subprocess.DEVNULL)
    monkeypatch.setattr(_jit, "subprocess", fake)  # this module's subprocess is untouched
    monkeypatch.setattr(_jit, "_background", [])
    monkeypatch.setattr(_jit.atexit, "register", lambda fn: None)
    monkeypatch.setattr(_jit, "_prepared", set())
    assert not _jit._lock_busy()
    _jit._compile_in_background("the kernels", ["sotpy.tasks._rowkernels"])
    _jit._report_background()
    err = capsys.readouterr().err
    assert "(about " in err and "s of about" in err and "behind" not in err
    path = _jit._lock_path()
    holder = subprocess.Popen(
        [
            sys.executable,
            "-c",
            "import fcntl, sys, time; f = open(sys.argv[1], 'a+b');"
            "fcntl.flock(f, fcntl.LOCK_EX); print('held', flush=True); sys.stdin.read()",
            str(path),
        ],
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        text=True,
    )
    try:
        assert holder.stdout.readline().strip() == "held"
        assert _jit._lock_busy()
        _jit._background.clear()
        _jit._compile_in_background("the kernels", ["sotpy.tasks._rowkernels"])
        _jit._report_background()
    finally:
        holder.stdin.close()
        holder.wait(timeout=30)
    err = capsys.readouterr().err
    assert "another sotpy run is compiling kernels for this install" in err
    assert "behind the compile another sotpy run started" in err and "pid 4242" in err
    assert not _jit._lock_busy()  # released with its holder
