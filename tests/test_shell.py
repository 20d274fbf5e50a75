"""sotpy shell: the namespace, its helpers, the console holding the pool lock."""

from __future__ import annotations

import io
from contextlib import redirect_stderr, redirect_stdout

import numpy as np
import pytest

from sotpy.cli import build_parser
from sotpy.graph import pool
from sotpy.loop import ControlLoop
from sotpy.remote import RemoteClient, RemoteServer
from sotpy.shell import Completer, LockedConsole, ipythonShell, makeNamespace, stringCompletions


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


# -- completion: dashed names inside strings, signals not offered as calls ---------------
def test_completer_offers_dashed_signal_names_and_no_signal_calls():
    ns = makeNamespace("nao")
    c = Completer(ns)
    # readline's word stops at the dash: "w" of "right-w"; the match is the rest
    assert c.completions("w", 'nao_dynamic.signal("right-w') == ["wrist"]
    assert c.completions("", "nao_dynamic.signal('right-") == ["ankle", "wrist"]
    assert c.completions("Jright", 'nao_dynamic.signal("Jright') == ["Jright-ankle", "Jright-wrist"]
    # every signal of the entity, checked against the entity itself
    signals = sorted(s.shortName for s in ns["nao_dynamic"].signals())
    assert c.completions("", 'nao_dynamic.signal("') == signals
    assert stringCompletions(ns, 'pool.getEntity("nao_d') == (
        "nao_d",
        ["nao_device", "nao_dynamic"],
    )
    assert stringCompletions(ns, 'robot.opPoints["left-') == ("left-", ["left-ankle", "left-wrist"])
    assert stringCompletions(ns, "x = 1") is None
    # a signal is a name (read it with .value), a command is a call
    attrs = c.completions("nao_dynamic.co")
    assert "nao_dynamic.com" in attrs and "nao_dynamic.com(" not in attrs
    assert "nao_dynamic.createOpPoint(" in c.completions("nao_dynamic.createOp")
    # outside strings, Python's completion as before
    assert "while " in c.completions("whi")


def test_ipython_completer_completes_dashed_signal_names():
    pytest.importorskip("IPython")
    from IPython.core.completer import provisionalcompleter

    ns = makeNamespace("nao")
    shell = ipythonShell(ns)
    text = 'nao_dynamic.signal("right-w'
    with provisionalcompleter():
        found = list(shell.Completer.completions(text, len(text)))
    assert [(c.text, c.start, c.end) for c in found] == [
        ("right-wrist", len(text) - len("right-w"), len(text))
    ]
    text = 'pool.getEntity("nao_dy'
    with provisionalcompleter():
        assert [c.text for c in shell.Completer.completions(text, len(text))] == ["nao_dynamic"]
    # the banner ends before IPython's own line, which no longer sticks to it
    assert "between ticks.\n\n" in shell.banner


def test_remote_completion_completes_dashed_signal_names():
    ns = makeNamespace("nao")
    server = RemoteServer(ns)
    server.start()
    try:
        host, port = server.address
        with RemoteClient(host, port, server.token, timeout=30.0) as client:
            assert client.complete("w", 'nao_dynamic.signal("right-w') == ["wrist"]
            assert "nao_dynamic.com" in client.complete("nao_dynamic.co")
            assert "nao_dynamic.com(" not in client.complete("nao_dynamic.co")
            assert "while " in client.complete("whi")  # without a line: the word alone
    finally:
        server.stop()


def test_shell_help_shows_the_defaults(capsys):
    from sotpy.cli import main

    assert main(["shell", "--help"]) == 0
    text = " ".join(capsys.readouterr().out.split())
    assert "(default talos)" in text and "(default 0.001: 1 kHz)" in text
    assert "default: IPython when installed" in text


def test_the_namespace_loop_takes_its_cpus_and_spin():
    import os

    last = max(os.sched_getaffinity(0))
    ns = makeNamespace("ur5", dt=0.01, cpus={last}, spin=0.01)
    loop = ns["loop"]
    assert loop.cpus == frozenset({last})
    assert loop.spin == pytest.approx(0.01) and loop.spin >= loop.dt
    pool.clear()
    plain = makeNamespace("ur5", dt=0.01)["loop"]
    assert plain.cpus is None and plain.spin < plain.dt
