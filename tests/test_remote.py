"""Remote interpreter: token, output capture, drops, many clients; the loop keeps running."""

from __future__ import annotations

import json
import logging
import os
import socket
import stat
import time

import numpy as np
import pytest

from sotpy.errors import SotpyError
from sotpy.graph import VECTOR, Entity, Input, Output, pool
from sotpy.loop import ControlLoop, unlocked
from sotpy.remote import RemoteClient, RemoteServer, readConnectionFile


class RemoteTestDevice(Entity):
    """state(t + 1) = state(t) + control(t)."""

    control = Input(VECTOR)
    state = Output(VECTOR)

    def __init__(self, name: str) -> None:
        self.state.write(np.zeros(1), 0)

    def increment(self, dt: float) -> None:
        t = max(self.state.time, 0)
        self.state.write(self.state(t) + self.control(t), t + 1)


@pytest.fixture
def served(tmp_path):
    dev = RemoteTestDevice("dev")
    dev.control.value = np.ones(1)
    loop = ControlLoop("loop", dev, 0.002)
    ns = {"dev": dev, "loop": loop, "pool": pool, "unlocked": unlocked, "time": time}
    server = RemoteServer(ns, connectionFile=tmp_path / "remote.json", auth_timeout=2.0)
    server.start()
    loop.start()
    yield server, loop
    server.stop()
    loop.stop()


def _ticking(loop: ControlLoop) -> bool:
    n = loop.ticks
    time.sleep(0.05)
    return loop.running and loop.ticks > n


def test_connection_file_is_private_and_correct_token_works(served, tmp_path):
    server, loop = served
    path = tmp_path / "remote.json"
    assert stat.S_IMODE(os.stat(path).st_mode) == 0o600
    info = readConnectionFile(path)
    assert (info["host"], info["port"]) == server.address and info["host"] == "127.0.0.1"
    assert info["token"] == server.token and len(server.token) >= 40
    with RemoteClient.fromFile(path) as c:
        assert c.execute("x = 6 * 7\nprint(x)") == "42\n"
        assert c.push("x + 1") == ("43\n", False)  # the repr of an expression
        assert c.push("for i in range(2):") == ("", True)
        assert c.push("    print(i)") == ("", True)
        assert c.push("") == ("0\n1\n", False)
        out = c.execute("dev.state.value[0]")  # 'exec' mode prints nothing
        assert out == ""
        t = float(c.push("float(dev.state.value[0])")[0])
        assert t >= 1.0
        assert "state" in " ".join(c.complete("dev.st"))
    assert _ticking(loop)


def test_exception_in_remote_code_is_returned_and_loop_runs(served):
    server, loop = served
    with RemoteClient("127.0.0.1", server.address[1], server.token) as c:
        out, more = c.push("1 / 0")
        assert "ZeroDivisionError" in out and not more
        assert "SyntaxError" in c.execute("def (")
        assert "NameError" in c.push("undefined_name")[0]
        assert c.push("print('still here')")[0] == "still here\n"
    assert _ticking(loop)


def test_remote_code_runs_beside_the_loop_and_loop_edit_is_atomic(served):
    server, _ = served
    with RemoteClient("127.0.0.1", server.address[1], server.token) as c:
        # an input does not hold the loop: it ticks during a plain sleep
        out = c.execute("n0 = loop.ticks\ntime.sleep(0.1)\nprint(loop.ticks - n0)")
        assert int(out) > 10  # 0.1 s at 500 Hz is 50 ticks
        # no tick inside loop.edit(), nor inside one call into sotpy
        out = c.execute(
            "with loop.edit():\n"
            "    n0 = loop.ticks\n"
            "    time.sleep(0.05)\n"
            "    print(loop.ticks - n0)"
        )
        assert out == "0\n"
        out = c.execute(
            "n0 = loop.ticks\nwith unlocked(): time.sleep(0.05)\nprint(loop.ticks - n0)"
        )
        assert int(out) > 5


def test_wrong_or_missing_token_is_refused_and_logged(served, caplog):
    server, loop = served
    port = server.address[1]
    with caplog.at_level(logging.WARNING, logger="sotpy.remote"):
        with pytest.raises(SotpyError, match=r"refused.*wrong token"):
            RemoteClient("127.0.0.1", port, server.token[:-1] + "x")
        s = socket.create_connection(("127.0.0.1", port))
        s.sendall(b'{"hello": 1}\n')
        reply = json.loads(s.makefile("rb").readline())
        s.close()
        assert reply == {"ok": False, "error": "refused: missing token"}
        s = socket.create_connection(("127.0.0.1", port))
        s.sendall(b"not json\n")
        assert s.makefile("rb").readline() == b""  # closed without a word
        s.close()
        time.sleep(0.1)
    assert "wrong token" in caplog.text and "missing token" in caplog.text
    assert "no valid greeting" in caplog.text
    assert server.clients == 0
    assert _ticking(loop)


def test_silent_client_is_dropped_after_auth_timeout(served, caplog):
    server, loop = served
    with caplog.at_level(logging.WARNING, logger="sotpy.remote"):
        s = socket.create_connection(("127.0.0.1", server.address[1]))
        s.settimeout(5.0)
        t0 = time.monotonic()
        assert s.recv(100) == b""  # the server hangs up
        assert time.monotonic() - t0 < 4.0
        s.close()
    assert "refused" in caplog.text
    assert _ticking(loop)


def test_100_connect_disconnect_cycles(served):
    server, loop = served
    port = server.address[1]
    for i in range(100):
        c = RemoteClient("127.0.0.1", port, server.token)
        if i % 10 == 0:
            assert c.push(f"{i} + 1")[0] == f"{i + 1}\n"
        c.close()
    deadline = time.monotonic() + 2.0
    while server.clients and time.monotonic() < deadline:
        time.sleep(0.01)
    assert server.clients == 0
    assert _ticking(loop) and loop.fault is None


def test_client_killed_mid_command_leaves_loop_running(served):
    server, loop = served
    port = server.address[1]
    for command in (
        "with unlocked(): time.sleep(0.5)",  # a wait that lets the loop tick
        "time.sleep(0.3); done_locked = True",  # holds the loop for 0.3 s
    ):
        s = socket.create_connection(("127.0.0.1", port))
        f = s.makefile("rb")
        s.sendall(json.dumps({"token": server.token}).encode() + b"\n")
        assert json.loads(f.readline())["ok"]
        s.sendall(json.dumps({"line": command}).encode() + b"\n")
        time.sleep(0.1)
        s.setsockopt(socket.SOL_SOCKET, socket.SO_LINGER, b"\x01\x00\x00\x00\x00\x00\x00\x00")
        f.close()
        s.close()  # RST while the command runs
    time.sleep(0.6)
    assert _ticking(loop) and loop.fault is None
    with RemoteClient("127.0.0.1", port, server.token) as c:
        assert c.push("done_locked")[0] == "True\n"  # the command completed
    assert server.clients == 0 or server.clients == 1


def test_several_clients_share_the_namespace_and_exit_closes_one(served):
    server, loop = served
    port = server.address[1]
    a = RemoteClient("127.0.0.1", port, server.token)
    b = RemoteClient("127.0.0.1", port, server.token)
    a.execute("shared = 'from a'")
    assert b.push("shared")[0] == "'from a'\n"
    b.push("exit()")
    with pytest.raises(SotpyError):
        b.push("1")
    assert a.push("2")[0] == "2\n"
    a.close()
    b.close()
    assert _ticking(loop)


def test_remote_edit_is_applied_between_ticks(served):
    server, loop = served
    with RemoteClient("127.0.0.1", server.address[1], server.token) as c:
        c.execute("import numpy as np\ndev.control.value = np.zeros(1)\nx0 = dev.state.value[0]")
        time.sleep(0.05)
        assert c.push("bool(dev.state.value[0] == x0)")[0] == "True\n"
    assert _ticking(loop)


def test_stop_removes_connection_file(tmp_path):
    path = tmp_path / "sub" / "c.json"
    server = RemoteServer({}, connectionFile=path)
    server.start()
    assert stat.S_IMODE(os.stat(path.parent).st_mode) == 0o700
    server.stop()
    assert not path.exists()
    with pytest.raises(SotpyError, match="no connection file"):
        RemoteClient.fromFile(path)
