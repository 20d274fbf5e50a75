"""sotpy shell: the namespace, its helpers, the console holding the pool lock."""

from __future__ import annotations

import io
from contextlib import redirect_stderr, redirect_stdout

import numpy as np

from sotpy.cli import build_parser
from sotpy.graph import pool
from sotpy.loop import ControlLoop
from sotpy.shell import LockedConsole, makeNamespace


def test_namespace_has_robot_loop_entities_and_helpers():
    ns = makeNamespace("ur5", dt=0.01)
    loop = ns["loop"]
    assert isinstance(loop, ControlLoop) and not loop.running  # started paused
    dev = ns["robot"].device
    assert ns[dev.name] is dev and ns[ns["robot"].dynamic.name] is ns["robot"].dynamic
    q0 = dev.state.value.copy()
    ns["step"](5)
    assert loop.ticks == 5 and dev.state.time == 5
    np.testing.assert_array_equal(dev.state.value, q0)  # zero velocity: holds still
    assert ns["stats"]().ticks == 5
    ns["start"]()
    assert loop.running
    ns["stop"]()
    assert not loop.running


def test_console_runs_each_input_holding_the_lock_and_reports_faults(tmp_path):
    ns = makeNamespace("ur5", dt=0.01)
    console = LockedConsole(ns)
    out, err = io.StringIO(), io.StringIO()
    with redirect_stdout(out), redirect_stderr(err):
        console.push("owned = pool.lock._is_owned()")
        console.push(f"path = writeGraph({str(tmp_path / 'g.dot')!r})")
        dev = ns["robot"].device
        console.push(f"{dev.name}.control.value = np.zeros({dev.model.nv + 1})")
        console.push("step(1)")  # the device refuses the size: a fault
    assert ns["owned"] is True
    assert "digraph" in (tmp_path / "g.dot").read_text()
    assert "SotpyError" in err.getvalue()
    assert "loop FAULT: tick 0" in err.getvalue()
    assert ns["loop"].fault is not None and not pool.lock._is_owned()


def test_cli_has_shell_serve_connect():
    p = build_parser()
    a = p.parse_args(["shell", "ur5", "--dt", "0.002", "--no-ipython"])
    assert (a.robot, a.dt, a.no_ipython) == ("ur5", 0.002, True)
    a = p.parse_args(["serve"])
    assert (a.robot, a.host, a.port, a.paused) == ("talos", "127.0.0.1", 0, False)
    a = p.parse_args(["connect", "--connection-file", "x.json"])
    assert a.connection_file == "x.json"
