"""``sotpy serve`` as a user runs it: a separate process, reached through its connection file.

tests/test_remote.py tests RemoteServer in-process; this file starts the real command
line (``python -m sotpy serve ur5``), so it also covers the argument parsing, the
connection file written by the CLI, the loop started by ``serve``, and the SIGTERM
shutdown (exit status 0, connection file removed).
"""

from __future__ import annotations

import json
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from sotpy.errors import SotpyError
from sotpy.remote import RemoteClient

STARTUP_TIMEOUT = 60.0  # s: importing pinocchio and loading the UR5 takes a few seconds


def _wait_for_file(path: Path, proc: subprocess.Popen, timeout: float) -> dict:
    """Wait until ``serve`` has written a complete connection file; return its content."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if proc.poll() is not None:
            out, err = proc.communicate()
            pytest.fail(f"sotpy serve exited with {proc.returncode}:\n{out}\n{err}")
        if path.exists():
            try:
                return json.loads(path.read_text())
            except json.JSONDecodeError:
                pass  # being written
        time.sleep(0.05)
    pytest.fail(f"sotpy serve wrote no connection file within {timeout} s")


@pytest.fixture
def serve(tmp_path):
    """A ``sotpy serve ur5`` subprocess at 100 Hz; killed if a test leaves it running."""
    conn = tmp_path / "conn.json"
    cmd = [sys.executable, "-m", "sotpy", "serve", "ur5", "--dt", "0.01"]
    cmd += ["--port", "0", "--connection-file", str(conn)]
    proc = subprocess.Popen(
        cmd, cwd=tmp_path, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True
    )
    try:
        yield proc, conn
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()


def _ticks(client: RemoteClient) -> int:
    return int(client.execute("print(loop.stats().ticks)").strip())


def test_serve_subprocess_runs_loop_refuses_wrong_token_and_stops_on_sigterm(serve):
    proc, conn = serve
    info = _wait_for_file(conn, proc, STARTUP_TIMEOUT)
    assert set(info) >= {"host", "port", "token", "pid"}
    assert info["pid"] == proc.pid
    assert info["host"] == "127.0.0.1" and info["port"] > 0
    assert conn.stat().st_mode & 0o777 == 0o600

    with RemoteClient.fromFile(conn, timeout=30.0) as client:
        assert client.execute("print(robot.model.nv)").strip() == "6"
        first = _ticks(client)
        time.sleep(0.5)  # client side: the server's loop ticks meanwhile (100 Hz)
        second = _ticks(client)
        assert second > first, (first, second)
        assert second - first >= 10  # 0.5 s at 100 Hz is 50 ticks: generous bound
        # the tick count the device sees agrees with the loop's
        assert int(client.execute("print(ur5_device.state.time)").strip()) >= second

    with pytest.raises(SotpyError, match=r"refused.*wrong token"):
        RemoteClient(info["host"], info["port"], "not-the-token", timeout=30.0)
    # the refused client did not stop anything: a good token still works
    with RemoteClient.fromFile(conn, timeout=30.0) as client:
        assert _ticks(client) >= second

    proc.send_signal(signal.SIGTERM)
    out, err = proc.communicate(timeout=30)
    assert proc.returncode == 0, (out, err)
    assert not conn.exists()
    assert "sotpy serve: stopped" in out
    assert "running at 100 Hz" in out
    assert "wrong token" in err  # the refusal is logged with the peer's address
