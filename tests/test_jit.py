"""sotpy._jit: the switch and the first-compile notice."""

from __future__ import annotations

import ast
import os
import subprocess
import sys

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
    assert _enabled_with(None) == "True False"


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
    env = dict(os.environ)
    env.pop("SOTPY_JIT", None)
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
