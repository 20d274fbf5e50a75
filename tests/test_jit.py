"""sotpy._jit: the switch and the first-compile notice."""

from __future__ import annotations

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
