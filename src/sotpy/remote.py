"""The remote interpreter: Python lines sent over TCP, run in the controller's process.

SoT embeds a Python interpreter in the robot controller and a client (``remote-
interpreter``) sends it lines. ``sotpy serve`` and ``sotpy connect`` do the same::

    server = RemoteServer(namespace)        # 127.0.0.1, a free port, a fresh token
    server.start()                          # background thread; server.address
    ...
    client = RemoteClient.fromFile()        # reads the connection file serve wrote
    print(client.execute("robot_device.state.value"))
    client.close()
    server.stop()

Protocol: JSON lines (UTF-8, one object per ``\\n``-terminated line, at most
:data:`MAX_LINE` bytes), never pickle. The client speaks first:

1. ``{"token": T}``; the server answers ``{"ok": true, "banner": ...}``, or
   ``{"ok": false, "error": ...}`` and closes when the token is missing or wrong (the
   refusal is logged on the ``sotpy.remote`` logger with the peer's address). The
   token is compared with ``hmac.compare_digest``; a client that sends nothing within
   ``auth_timeout`` s is dropped.
2. then requests, each answered by one reply:

   * ``{"line": L}``: ``L`` is pushed to the connection's console, as a line typed at
     ``>>>``; answer ``{"output": text, "more": bool}``: what the code printed on
     stdout and stderr, the ``repr`` of an expression statement, a traceback if it
     raised; ``more`` when the statement is incomplete (a ``for``'s body follows).
   * ``{"source": S}``: run the complete block ``S`` (several lines) at once; answer
     ``{"output": text, "more": false}``.
   * ``{"complete": prefix}`` (optionally ``"before"``: the text before the cursor):
     answer ``{"matches": [...]}`` (:class:`sotpy.shell.Completer`).
   * ``{"reset": true}``: drop a pending incomplete statement; answer ``{"ok": true}``.

Every input runs while holding :attr:`pool.lock <sotpy.graph.pool.Pool.lock>`, so the
control loop never sees half an edit and does not tick while it runs; a long wait that
does not edit the graph can release it: ``with unlocked(): time.sleep(5)``. The loop
never waits on a client's socket: reads and writes happen without the lock. All
connections share one namespace (one interpreter in the controller, as in SoT), each
with its own pending-statement buffer. An exception in remote code is returned as a
traceback; a dropped client ends its connection thread only; ``exit()`` in remote code
closes that connection, never the server.

The connection file (:func:`defaultConnectionFile`: ``$XDG_RUNTIME_DIR/sotpy/remote.json``,
else ``~/.cache/sotpy/remote.json``) holds ``{"host", "port", "token", "pid"}``, mode
0600 in a 0700 directory; ``serve`` removes it when it stops.
"""

from __future__ import annotations

import code
import contextlib
import hmac
import io
import json
import logging
import os
import rlcompleter
import secrets
import socket
import socketserver
import sys
import threading
from pathlib import Path
from typing import Any, TextIO

from .errors import SotpyError
from .graph.pool import pool

__all__ = [
    "DEFAULT_HOST",
    "MAX_LINE",
    "RemoteClient",
    "RemoteServer",
    "defaultConnectionFile",
    "readConnectionFile",
]

log = logging.getLogger("sotpy.remote")

#: The default address ``serve`` listens on: the local machine only.
DEFAULT_HOST = "127.0.0.1"
#: The longest message accepted, in bytes (a longer one closes the connection).
MAX_LINE = 4 * 1024 * 1024


def defaultConnectionFile() -> Path:
    """``$XDG_RUNTIME_DIR/sotpy/remote.json``, else ``~/.cache/sotpy/remote.json``."""
    runtime = os.environ.get("XDG_RUNTIME_DIR")
    base = Path(runtime) if runtime and Path(runtime).is_dir() else Path.home() / ".cache"
    return base / "sotpy" / "remote.json"


def readConnectionFile(path: str | Path | None = None) -> dict[str, Any]:
    """The ``{"host", "port", "token", "pid"}`` a server wrote to ``path``."""
    p = Path(path) if path is not None else defaultConnectionFile()
    try:
        data = json.loads(p.read_text())
        return {"host": str(data["host"]), "port": int(data["port"]), "token": str(data["token"])}
    except FileNotFoundError:
        raise SotpyError(
            f"no connection file {p}: is 'sotpy serve' running (as this user)?"
        ) from None
    except (ValueError, KeyError, TypeError) as exc:
        raise SotpyError(f"connection file {p} is malformed: {exc}") from None


def _writePrivate(path: Path, text: str) -> None:
    """Write ``text`` to ``path``, readable and writable by its owner only (0600)."""
    path.parent.mkdir(mode=0o700, parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.{os.getpid()}")
    fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
    try:
        os.fchmod(fd, 0o600)
        os.write(fd, text.encode())
    finally:
        os.close(fd)
    os.replace(tmp, path)


# ---------------------------------------------------------------------------------------
# Output capture: per thread, so that other threads' prints are not captured
# ---------------------------------------------------------------------------------------
class _ThreadStream(io.TextIOBase):
    """Stands for sys.stdout/stderr: writes go to the current thread's capture buffer
    if it has one, else to the original stream."""

    def __init__(self, original: TextIO, local: threading.local) -> None:
        self._original = original
        self._local = local

    def write(self, s: str) -> int:
        buf = getattr(self._local, "buffer", None)
        if buf is not None:
            return buf.write(s)
        return self._original.write(s)

    def flush(self) -> None:
        if getattr(self._local, "buffer", None) is None:
            self._original.flush()

    def isatty(self) -> bool:
        return getattr(self._local, "buffer", None) is None and self._original.isatty()

    def fileno(self) -> int:
        return self._original.fileno()

    @property
    def encoding(self) -> str:  # type: ignore[override]
        return getattr(self._original, "encoding", "utf-8")


_capture = threading.local()
_install_lock = threading.Lock()


def _installCapture() -> None:
    """Make sys.stdout/stderr thread-aware (again, if something replaced them)."""
    if isinstance(sys.stdout, _ThreadStream) and isinstance(sys.stderr, _ThreadStream):
        return
    with _install_lock:
        if not isinstance(sys.stdout, _ThreadStream):
            sys.stdout = _ThreadStream(sys.stdout, _capture)
        if not isinstance(sys.stderr, _ThreadStream):
            sys.stderr = _ThreadStream(sys.stderr, _capture)


@contextlib.contextmanager
def _captured() -> Any:
    _installCapture()
    buf = io.StringIO()
    _capture.buffer = buf
    try:
        yield buf
    finally:
        _capture.buffer = None


class _Console(code.InteractiveConsole):
    """A console whose output goes to the capture buffer (``write`` -> sys.stderr)."""

    def runcode(self, code_obj: Any) -> None:
        try:
            exec(code_obj, self.locals)
        except SystemExit:
            raise
        except BaseException:
            self.showtraceback()


class _ClientGone(Exception):
    pass


# ---------------------------------------------------------------------------------------
# Server
# ---------------------------------------------------------------------------------------
class _Handler(socketserver.StreamRequestHandler):
    server: _TCPServer

    def setup(self) -> None:
        super().setup()
        self.connection.settimeout(self.server.owner.auth_timeout)

    def _send(self, obj: dict[str, Any]) -> None:
        self.wfile.write(json.dumps(obj).encode() + b"\n")
        self.wfile.flush()

    def _recv(self) -> dict[str, Any] | None:
        line = self.rfile.readline(MAX_LINE + 1)
        if not line:
            return None
        if len(line) > MAX_LINE:
            raise _ClientGone("message too long")
        msg = json.loads(line)
        if not isinstance(msg, dict):
            raise ValueError("a message must be a JSON object")
        return msg

    def handle(self) -> None:
        owner = self.server.owner
        peer = f"{self.client_address[0]}:{self.client_address[1]}"
        try:
            hello = self._recv()
        except (OSError, ValueError, _ClientGone) as exc:
            log.warning("refused %s: no valid greeting (%s)", peer, exc)
            return
        token = hello.get("token") if hello else None
        if not isinstance(token, str) or not hmac.compare_digest(
            token.encode(), owner.token.encode()
        ):
            why = "missing token" if not isinstance(token, str) else "wrong token"
            log.warning("refused %s: %s", peer, why)
            with contextlib.suppress(OSError):
                self._send({"ok": False, "error": f"refused: {why}"})
            return
        owner._count(+1)
        log.info("client %s connected", peer)
        try:
            self.connection.settimeout(owner.idle_timeout)
            self._send({"ok": True, "banner": owner.banner})
            console = _Console(owner.namespace, filename="<remote>")
            from .shell import Completer  # names inside strings; signals not as calls

            completer = Completer(owner.namespace)
            while True:
                msg = self._recv()
                if msg is None:
                    break
                self._send(self._answer(msg, console, completer))
        except SystemExit:
            log.info("client %s closed the connection (exit())", peer)
            with contextlib.suppress(OSError):
                self._send({"output": "", "more": False, "exit": True})
        except (OSError, ValueError, _ClientGone) as exc:
            log.info("client %s dropped: %s", peer, exc)
        finally:
            owner._count(-1)
            log.info("client %s disconnected", peer)

    def _answer(
        self, msg: dict[str, Any], console: _Console, completer: rlcompleter.Completer
    ) -> dict[str, Any]:
        if "line" in msg or "source" in msg:
            text = msg.get("line", msg.get("source"))
            if not isinstance(text, str):
                return {"error": "'line'/'source' must be a string"}
            with _captured() as buf, pool.lock:
                if "line" in msg:
                    more = console.push(text)
                else:
                    console.resetbuffer()
                    more = False
                    src = text if text.endswith("\n") else text + "\n"
                    try:
                        code_obj = compile(src, "<remote>", "exec")
                    except (SyntaxError, ValueError, OverflowError):
                        console.showsyntaxerror("<remote>")
                    else:
                        console.runcode(code_obj)
            return {"output": buf.getvalue(), "more": bool(more)}
        if "complete" in msg:
            prefix, line = msg["complete"], msg.get("before")
            if not isinstance(prefix, str) or not isinstance(line, (str, type(None))):
                return {"error": "'complete' and 'before' must be strings"}
            with pool.lock:
                matches = completer.completions(prefix, line)  # type: ignore[attr-defined]
            return {"matches": matches}
        if msg.get("reset"):
            console.resetbuffer()
            return {"ok": True}
        return {"error": f"unknown request (keys {sorted(msg)})"}


class _TCPServer(socketserver.ThreadingTCPServer):
    daemon_threads = True
    allow_reuse_address = True
    owner: RemoteServer


class RemoteServer:
    """A remote interpreter over ``namespace`` (a dict), listening on TCP.

    Args:
        namespace: the globals the remote lines run in (shared by every client).
        host: address to listen on (default 127.0.0.1: this machine only).
        port: TCP port (0: a free port, see :attr:`address`).
        token: the secret clients must send (default ``secrets.token_urlsafe(32)``).
        connectionFile: where to write ``{"host", "port", "token", "pid"}`` (mode 0600)
            when started; None: do not write one.
        auth_timeout: s a new client has to send its token.
        idle_timeout: s a client may stay silent before it is dropped (None: forever).
        banner: text sent to clients when they connect.
    """

    def __init__(
        self,
        namespace: dict[str, Any],
        host: str = DEFAULT_HOST,
        port: int = 0,
        token: str | None = None,
        connectionFile: str | Path | None = None,
        auth_timeout: float = 5.0,
        idle_timeout: float | None = 3600.0,
        banner: str = "sotpy remote interpreter",
    ) -> None:
        self.namespace = namespace
        self.token = token if token is not None else secrets.token_urlsafe(32)
        self.auth_timeout = auth_timeout
        self.idle_timeout = idle_timeout
        self.banner = banner
        self.connectionFile = Path(connectionFile) if connectionFile is not None else None
        self._clients = 0
        self._clientsLock = threading.Lock()
        self._server = _TCPServer((host, port), _Handler, bind_and_activate=True)
        self._server.owner = self
        self._thread: threading.Thread | None = None
        namespace.setdefault("__name__", "__remote__")

    @property
    def address(self) -> tuple[str, int]:
        """(host, port) the server listens on."""
        host, port = self._server.server_address[:2]
        return str(host), int(port)

    @property
    def clients(self) -> int:
        """Number of connected (authenticated) clients."""
        return self._clients

    def _count(self, d: int) -> None:
        with self._clientsLock:
            self._clients += d

    def start(self) -> None:
        """Serve in a background daemon thread; write the connection file."""
        _installCapture()
        if self.connectionFile is not None:
            host, port = self.address
            _writePrivate(
                self.connectionFile,
                json.dumps({"host": host, "port": port, "token": self.token, "pid": os.getpid()}),
            )
        self._thread = threading.Thread(
            target=self._server.serve_forever, name="sotpy remote server", daemon=True
        )
        self._thread.start()
        log.info("remote interpreter listening on %s:%d", *self.address)

    def serveForever(self) -> None:
        """Serve in the calling thread until :meth:`stop` (from another thread) or
        Ctrl-C."""
        _installCapture()
        self._server.serve_forever()

    def stop(self) -> None:
        """Stop accepting clients, close the socket, remove the connection file."""
        if self._thread is not None:
            self._server.shutdown()
            self._thread.join(5.0)
            self._thread = None
        self._server.server_close()
        if self.connectionFile is not None:
            with contextlib.suppress(FileNotFoundError):
                self.connectionFile.unlink()


# ---------------------------------------------------------------------------------------
# Client
# ---------------------------------------------------------------------------------------
class RemoteClient:
    """A connection to a :class:`RemoteServer`; raises SotpyError if refused.

    ``RemoteClient(host, port, token)`` or ``RemoteClient.fromFile(path)``.
    """

    def __init__(self, host: str, port: int, token: str, timeout: float | None = 60.0) -> None:
        try:
            self._sock = socket.create_connection((host, port), timeout=timeout)
        except OSError as exc:
            raise SotpyError(
                f"cannot connect to the remote interpreter at {host}:{port}: {exc}"
            ) from None
        self._rfile = self._sock.makefile("rb")
        self.banner = ""
        hello = self._request({"token": token})
        if not hello.get("ok"):
            self.close()
            raise SotpyError(
                f"the remote interpreter at {host}:{port} refused the connection: "
                f"{hello.get('error', 'no reason given')}"
            )
        self.banner = str(hello.get("banner", ""))

    @classmethod
    def fromFile(cls, path: str | Path | None = None, timeout: float | None = 60.0) -> RemoteClient:
        """Connect with the address and token of a connection file (default
        :func:`defaultConnectionFile`)."""
        c = readConnectionFile(path)
        return cls(c["host"], c["port"], c["token"], timeout=timeout)

    def _request(self, msg: dict[str, Any]) -> dict[str, Any]:
        try:
            self._sock.sendall(json.dumps(msg).encode() + b"\n")
            line = self._rfile.readline(MAX_LINE + 1)
        except OSError as exc:
            raise SotpyError(f"lost the remote interpreter: {exc}") from exc
        if not line:
            raise SotpyError("the remote interpreter closed the connection")
        reply = json.loads(line)
        if "error" in reply and "ok" not in reply:
            raise SotpyError(f"remote interpreter: {reply['error']}")
        return reply

    def push(self, line: str) -> tuple[str, bool]:
        """Send one console line; (output, more): more when the statement goes on."""
        r = self._request({"line": line})
        return str(r.get("output", "")), bool(r.get("more", False))

    def execute(self, source: str) -> str:
        """Run a complete block of code remotely; return what it printed."""
        return str(self._request({"source": source}).get("output", ""))

    def complete(self, prefix: str, line: str | None = None) -> list[str]:
        """Completions of readline's word ``prefix`` in the remote namespace; ``line``:
        the text before the cursor, for names inside strings (``signal("right-w``)."""
        msg: dict[str, Any] = {"complete": prefix}
        if line is not None:
            msg["before"] = line
        return [str(m) for m in self._request(msg).get("matches", [])]

    def reset(self) -> None:
        """Drop a pending incomplete statement."""
        self._request({"reset": True})

    def close(self) -> None:
        """Close the connection."""
        with contextlib.suppress(OSError):
            self._rfile.close()
        with contextlib.suppress(OSError):
            self._sock.close()

    def __enter__(self) -> RemoteClient:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def interact(self) -> None:
        """A console whose lines run remotely (readline editing and remote tab
        completion when readline is available); Ctrl-D leaves, Ctrl-C drops the
        statement being typed."""
        try:
            import readline
        except ImportError:  # pragma: no cover - Windows
            readline = None  # type: ignore[assignment]
        if readline is not None:
            cache: dict[str, list[str]] = {}

            def complete(text: str, state: int) -> str | None:
                if state == 0:
                    try:
                        line = readline.get_line_buffer()[: readline.get_endidx()]
                        cache[text] = self.complete(text, line)
                    except SotpyError:
                        cache[text] = []
                m = cache.get(text, [])
                return m[state] if state < len(m) else None

            readline.set_completer(complete)
            readline.set_completer_delims(" \t\n`~!@#$%^&*()-=+[{]}\\|;:'\",<>/?")
            readline.parse_and_bind("tab: complete")
        print(self.banner)
        more = False
        while True:
            try:
                line = input("... " if more else ">>> ")
            except EOFError:
                print()
                return
            except KeyboardInterrupt:
                print("\nKeyboardInterrupt")
                self.reset()
                more = False
                continue
            r = self._request({"line": line})
            sys.stdout.write(str(r.get("output", "")))
            sys.stdout.flush()
            if r.get("exit"):
                return
            more = bool(r.get("more", False))
