"""The remote interpreter under abuse: slow, long, many or malformed greetings; huge
replies; a planted connection file; remote code that never ends; a public address.

Each check is bounded (small counts, timeouts of about a second) so that the file runs
in a few seconds.
"""

from __future__ import annotations

import builtins
import logging
import os
import select
import socket
import threading
import time

import numpy as np
import pytest

from sotpy import remote
from sotpy.errors import RemoteError
from sotpy.graph import DOUBLE, VECTOR, Entity, Input, Output, pool
from sotpy.loop import ControlLoop
from sotpy.remote import RemoteClient, RemoteServer, readConnectionFile

AUTH = 1.0  # s: the servers' auth_timeout here


class AbuseDevice(Entity):
    """state(t + 1) = state(t) + control(t)."""

    control = Input(VECTOR)
    state = Output(VECTOR)

    def __init__(self, name: str) -> None:
        self.state.write(np.zeros(1), 0)

    def increment(self, dt: float) -> None:
        t = max(self.state.time, 0)
        self.state.write(self.state(t) + self.control(t), t + 1)


class AbusePair(Entity):
    """Two inputs an edit sets together; counts the ticks that read them different."""

    a = Input(DOUBLE, default=0.0)
    b = Input(DOUBLE, default=0.0)

    def __init__(self, name: str) -> None:
        self.torn = 0

    @Output(VECTOR, deps=("a", "b"), withTime=True, timeDependent=True)
    def sout(self, t, a, b):
        if a != b:
            self.torn += 1
        return np.zeros(1)


def _serve(tmp_path, **kwargs):
    dev = AbuseDevice("dev")
    pair = AbusePair("pair")
    dev.control.value = np.ones(1)
    loop = ControlLoop("loop", dev, 0.002)  # 500 Hz
    ns = {"dev": dev, "loop": loop, "pair": pair, "pool": pool, "time": time}
    server = RemoteServer(ns, auth_timeout=AUTH, **kwargs)
    server.start()
    loop.start()
    return server, loop, pair


@pytest.fixture
def served(tmp_path):
    server, loop, _ = _serve(tmp_path)
    yield server, loop
    server.stop()
    loop.stop()


def _closed_within(s: socket.socket, timeout: float) -> float | None:
    """Seconds until the server closes ``s`` (None: still open after ``timeout``)."""
    t0 = time.monotonic()
    while time.monotonic() - t0 < timeout:
        r, _, _ = select.select([s], [], [], 0.05)
        if r:
            try:
                if s.recv(4096) == b"":
                    return time.monotonic() - t0
            except OSError:
                return time.monotonic() - t0
    return None


# -- 2. greetings --------------------------------------------------------------------------
def test_a_greeting_trickled_byte_by_byte_is_dropped_at_auth_timeout(served, caplog):
    server, loop = served
    with caplog.at_level(logging.WARNING, logger="sotpy.remote"):
        s = socket.create_connection(("127.0.0.1", server.address[1]))
        t0 = time.monotonic()
        closed = None
        while time.monotonic() - t0 < 3 * AUTH:  # one byte every 0.2 s, never a newline
            try:
                s.sendall(b" ")
            except OSError:
                closed = time.monotonic() - t0
                break
            if _closed_within(s, 0.2) is not None:
                closed = time.monotonic() - t0
                break
        s.close()
    assert closed is not None and closed < AUTH + 0.5, closed
    assert "no complete greeting within" in caplog.text
    assert server.clients == 0 and loop.fault is None


def test_a_greeting_too_long_is_refused_at_once(served, caplog):
    server, _ = served
    with caplog.at_level(logging.WARNING, logger="sotpy.remote"):
        s = socket.create_connection(("127.0.0.1", server.address[1]))
        s.sendall(b'{"token": "' + b"a" * 100_000)  # no newline: it would wait for more
        took = _closed_within(s, AUTH)
        s.close()
    assert took is not None and took < AUTH / 2
    assert f"longer than {remote.MAX_GREETING} bytes" in caplog.text


def test_waiting_connections_are_bounded_and_freed(served, caplog):
    server, loop = served
    port = server.address[1]
    n = server.max_pending if hasattr(server, "max_pending") else 16
    with caplog.at_level(logging.WARNING, logger="sotpy.remote"):
        waiting = [socket.create_connection(("127.0.0.1", port)) for _ in range(n)]
        deadline = time.monotonic() + AUTH / 2
        while getattr(server, "pending", n) < n and time.monotonic() < deadline:
            time.sleep(0.01)
        extra = socket.create_connection(("127.0.0.1", port))
        took = _closed_within(extra, AUTH / 2)  # closed at once, not at auth_timeout
        extra.close()
        for s in waiting:
            s.close()
    assert took is not None
    assert "already wait to authenticate" in caplog.text
    deadline = time.monotonic() + 2.0
    while server.pending and time.monotonic() < deadline:
        time.sleep(0.02)
    assert server.pending == 0
    with RemoteClient("127.0.0.1", port, server.token) as c:  # room again
        assert c.push("1 + 1")[0] == "2\n"
    assert loop.fault is None


# -- 5. nested JSON ------------------------------------------------------------------------
def test_deeply_nested_json_is_a_logged_refusal_not_a_traceback(served, caplog, capfd):
    server, _ = served
    port = server.address[1]
    with caplog.at_level(logging.INFO, logger="sotpy.remote"):
        for payload in (b"[" * 3000 + b"\n", b"[" * 200_000 + b"\n"):
            s = socket.create_connection(("127.0.0.1", port))
            s.sendall(payload)
            assert _closed_within(s, AUTH) is not None
            s.close()
        # after authentication: an error reply, and the connection goes on
        with RemoteClient("127.0.0.1", port, server.token) as c:
            c._sock.sendall(b'{"line": ' + b"[" * 3000 + b"\n")
            assert "nested too deeply" in c._reader.readline(10_000).decode()
            assert c.push("6 * 7")[0] == "42\n"
        time.sleep(0.1)
    err = capfd.readouterr().err
    assert "Traceback" not in err and "RecursionError" not in err
    assert "JSON nested too deeply" in caplog.text
    assert f"longer than {remote.MAX_GREETING} bytes" in caplog.text


# -- 3. large replies ----------------------------------------------------------------------
def test_a_huge_output_is_truncated_with_a_notice_and_the_connection_goes_on(served):
    server, _ = served
    with RemoteClient("127.0.0.1", server.address[1], server.token) as c:
        out = c.execute("print('x' * 5_000_000)")
        assert out.startswith("x" * 100_000)
        assert "truncated" in out and "5000001 characters printed" in out
        assert c.push("1 + 1")[0] == "2\n"  # the same connection still works
        out = c.execute("print('y' * 900_000)")  # below max_output: whole
        assert out == "y" * 900_000 + "\n"


class _FakeServer:
    """Accepts one client, says ok, then answers each request with the next reply."""

    def __init__(self, replies: list[bytes]) -> None:
        self.sock = socket.create_server(("127.0.0.1", 0))
        self.port = self.sock.getsockname()[1]
        self.replies = replies
        self.thread = threading.Thread(target=self._run, daemon=True)
        self.thread.start()

    def _run(self) -> None:
        conn, _ = self.sock.accept()
        f = conn.makefile("rb")
        f.readline()
        conn.sendall(b'{"ok": true, "banner": "fake"}\n')
        for reply in self.replies:
            if not f.readline():
                break
            conn.sendall(reply)
        f.readline()
        conn.close()


def test_the_client_survives_replies_it_cannot_read(monkeypatch):
    monkeypatch.setattr(remote, "MAX_LINE", 1000)
    fake = _FakeServer(
        [b"not json\n", b"{" + b'"a": 1, ' * 500 + b'"b": 2}\n', b'{"output": "ok\\n"}\n']
    )
    c = RemoteClient("127.0.0.1", fake.port, "t", timeout=5.0)
    with pytest.raises(RemoteError, match=r"unreadable reply.*still usable"):
        c.push("x")
    with pytest.raises(RemoteError, match=r"longer than 1000 bytes.*still usable"):
        c.push("y")
    assert c.push("z") == ("ok\n", False) and not c.lost
    with pytest.raises(RemoteError, match="request not sent"):
        c.execute("#" * 2000)
    c.close()


def test_sotpy_connect_reports_a_bad_reply_and_goes_on(monkeypatch, capsys):
    monkeypatch.setattr(remote, "MAX_LINE", 1000)
    fake = _FakeServer([b"\x00garbage\n", b"z" * 3000 + b"\n", b'{"output": "fine\\n"}\n'])
    c = RemoteClient("127.0.0.1", fake.port, "t", timeout=5.0)
    lines = iter(["a", "b", "c"])

    def fake_input(prompt: str = "") -> str:
        try:
            return next(lines)
        except StopIteration:
            raise EOFError from None

    monkeypatch.setattr(builtins, "input", fake_input)
    c.interact()  # returns at EOF: no exception
    out, err = capsys.readouterr()
    assert "fine\n" in out
    assert err.count("sotpy connect: ") == 2 and "Traceback" not in err
    c.close()


def test_a_reply_may_take_longer_than_the_connect_timeout(served):
    server, loop = served
    with RemoteClient("127.0.0.1", server.address[1], server.token, timeout=0.3) as c:
        assert c.execute("time.sleep(0.8)\nprint('slept')") == "slept\n"
        assert c.push("3 * 3")[0] == "9\n"
    assert loop.fault is None


def test_ctrl_c_in_sotpy_connect_while_a_line_runs_closes_cleanly(served, monkeypatch):
    server, _ = served
    c = RemoteClient("127.0.0.1", server.address[1], server.token)
    monkeypatch.setattr(builtins, "input", lambda prompt="": "time.sleep(0.3)")

    def interrupted(limit, deadline=None):
        raise KeyboardInterrupt

    monkeypatch.setattr(c._reader, "readline", interrupted)
    with pytest.raises(RemoteError, match="interrupted while the remote input ran"):
        c.interact()
    assert c.lost
    with pytest.raises(RemoteError, match="was lost"):
        c.push("1")


# -- 4. the connection file ----------------------------------------------------------------
def test_a_symlink_planted_at_the_old_temporary_name_is_not_followed(tmp_path):
    victim = tmp_path / "victim"
    victim.write_text("precious")
    victim.chmod(0o644)
    conn = tmp_path / "remote.json"
    (tmp_path / f".{conn.name}.{os.getpid()}").symlink_to(victim)
    server = RemoteServer({}, connectionFile=conn)
    server.start()
    try:
        assert victim.read_text() == "precious"
        assert victim.stat().st_mode & 0o777 == 0o644
        assert readConnectionFile(conn)["token"] == server.token
        assert not conn.is_symlink() and conn.stat().st_mode & 0o777 == 0o600
    finally:
        server.stop()
    assert not conn.exists()


def test_the_temporary_file_is_created_exclusively_without_following_links(tmp_path, monkeypatch):
    victim = tmp_path / "victim"
    victim.write_text("precious")
    conn = tmp_path / "remote.json"
    monkeypatch.setattr(remote.secrets, "token_hex", lambda n=8: "fixed")
    (tmp_path / ".remote.json.fixed.tmp").symlink_to(victim)
    with pytest.raises(RemoteError, match="cannot create the connection file"):
        remote._writePrivate(conn, '{"token": "secret"}')
    assert victim.read_text() == "precious" and not conn.exists()


def test_a_directory_others_may_write_is_refused(tmp_path):
    shared = tmp_path / "shared"
    shared.mkdir()
    shared.chmod(0o777)
    with pytest.raises(RemoteError, match="others may write to it"):
        remote._writePrivate(shared / "remote.json", "{}")
    assert list(shared.iterdir()) == []
    server = RemoteServer({}, connectionFile=shared / "remote.json")
    with pytest.raises(RemoteError, match=r"refusing to write the connection file"):
        server.start()
    server.stop()
    # and a client refuses a connection file others may have written
    (tmp_path / "c.json").write_text('{"host": "127.0.0.1", "port": 1, "token": "t"}')
    (tmp_path / "c.json").chmod(0o666)
    with pytest.raises(RemoteError, match="not trusted: others may write"):
        readConnectionFile(tmp_path / "c.json")


# -- 6. remote code and the loop -----------------------------------------------------------
def _rate_during(loop: ControlLoop, client: RemoteClient, source: str) -> tuple[float, str]:
    """Ticks per second of ``loop`` while ``client`` executes ``source``, and its output."""
    n0, t0 = loop.ticks, time.monotonic()
    out = client.execute(source)
    return (loop.ticks - n0) / (time.monotonic() - t0), out


def test_the_loop_keeps_its_rate_while_a_client_computes_or_sleeps(served):
    server, loop = served
    port = server.address[1]
    with RemoteClient("127.0.0.1", port, server.token) as a:
        busy = "t0 = time.monotonic()\nwhile time.monotonic() - t0 < 1.0:\n    pass\nprint('done')"
        rate, out = _rate_during(loop, a, busy)
        assert out == "done\n"
        assert rate > 0.4 * 500, rate  # 500 Hz nominal: a generous bound
        rate, _ = _rate_during(loop, a, "time.sleep(0.5)")
        assert rate > 0.4 * 500, rate
        # another client is served while one runs a long input
        done = threading.Event()

        def long_input() -> None:
            a.execute("time.sleep(1.0)")
            done.set()

        th = threading.Thread(target=long_input)
        th.start()
        time.sleep(0.1)
        with RemoteClient("127.0.0.1", port, server.token) as b:
            t0 = time.monotonic()
            assert b.push("2 + 2")[0] == "4\n"
            assert time.monotonic() - t0 < 0.5 and not done.is_set()
        th.join()
    assert loop.fault is None


def test_remote_edits_in_loop_edit_are_never_seen_half_done(served):
    server, loop = served
    with RemoteClient("127.0.0.1", server.address[1], server.token) as c:
        c.execute("from sotpy.graph import plug\nplug(pair.sout, dev.control)")
        out = c.execute(
            "n0 = loop.ticks\n"
            "for i in range(3000):\n"
            "    with loop.edit():\n"
            "        pair.a.value = float(i)\n"
            "        pair.b.value = float(i)\n"
            "print(loop.ticks - n0, pair.torn)"
        )
        ticks, torn = map(int, out.split())
        assert torn == 0 and ticks > 0  # ticks ran between the edits, none inside
    assert loop.fault is None


def test_a_runaway_input_is_interrupted_after_exec_timeout(tmp_path, caplog):
    server, loop, _ = _serve(tmp_path, exec_timeout=1.0)
    try:
        with (
            caplog.at_level(logging.WARNING, logger="sotpy.remote"),
            RemoteClient("127.0.0.1", server.address[1], server.token) as c,
        ):
            n0, t0 = loop.ticks, time.monotonic()
            out = c.execute("while True:\n    pass")
            wall = time.monotonic() - t0
            assert "RemoteTimeout" in out and "exec_timeout (1 s)" in out
            assert 0.9 < wall < 3.0
            assert (loop.ticks - n0) / wall > 0.4 * 500
            # an exception handler in the code does not swallow it
            out = c.execute("try:\n    while True: pass\nexcept Exception:\n    print('caught')")
            assert "RemoteTimeout" in out and "caught" not in out
            assert c.push("'alive'")[0] == "'alive'\n"
        assert "interrupted after 1 s" in caplog.text
        assert loop.fault is None and loop.running
    finally:
        server.stop()
        loop.stop()


# -- 9. the address ------------------------------------------------------------------------
def test_a_public_address_needs_allow_remote_and_is_warned_about(caplog):
    with pytest.raises(RemoteError, match=r"not a loopback address.*allow_remote=True"):
        RemoteServer({}, host="0.0.0.0")
    with caplog.at_level(logging.WARNING, logger="sotpy.remote"):
        server = RemoteServer({}, host="0.0.0.0", allow_remote=True)
    server.stop()
    assert "UNENCRYPTED" in caplog.text
    server = RemoteServer({}, host="localhost")  # loopback by name: no flag needed
    server.stop()


def test_sotpy_serve_refuses_a_public_host_without_the_flag(capsys):
    from sotpy.cli import main

    assert main(["serve", "nosuchrobot", "--host", "0.0.0.0"]) == 2
    err = capsys.readouterr().err
    assert "--allow-remote" in err and "unencrypted" in err
    # with the flag: the warning first, then the (here failing) robot load
    assert main(["serve", "nosuchrobot", "--host", "0.0.0.0", "--allow-remote"]) == 1
    err = capsys.readouterr().err
    assert "WARNING" in err and "unencrypted" in err and "nosuchrobot" in err
