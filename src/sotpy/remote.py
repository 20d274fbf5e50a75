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
:data:`MAX_LINE` bytes each way), never pickle. The client speaks first:

1. ``{"token": T}`` (at most :data:`MAX_GREETING` bytes, whole within ``auth_timeout``
   s of the connection); the server answers ``{"ok": true, "banner": ...}``, or
   ``{"ok": false, "error": ...}`` and closes when the token is missing or wrong. A
   greeting that is late, too long, not JSON, or nested too deeply is refused and the
   connection closed; every refusal is logged on the ``sotpy.remote`` logger with the
   peer's address (never a traceback). The token is compared with
   ``hmac.compare_digest``. At most ``max_pending`` connections may be waiting to
   authenticate; more are closed at once (logged).
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

   A malformed request is answered ``{"error": ...}``; the connection stays usable.
   An output longer than ``max_output`` characters (or than a reply can carry) is
   truncated, with a notice at its end saying how much was printed.

How remote code runs with the control loop: not under the tick's lock. Each call it
makes into sotpy (a command, a signal read or write, a plug, an entity's creation) holds
:attr:`pool.lock <sotpy.graph.pool.Pool.lock>` for that call only, so a tick never sees
half an edit; the rest (a loop, a ``time.sleep``, numpy, printing) runs while the loop
ticks, and yields the interpreter every 0.1 ms so that the loop keeps its rate (see
``_GraphScope``). Edits that must land together go in ``with loop.edit():`` (no
tick runs inside the block). With ``exec_timeout`` set, remote code still running after
that many seconds is interrupted (:class:`~sotpy.errors.RemoteTimeout`, a
``KeyboardInterrupt``); a call into sotpy or a blocking C call finishes first. The loop never
waits on a client's socket. All connections share one namespace (one interpreter in the
controller, as in SoT), each with its own pending-statement buffer, and run at the same
time. An exception in remote code is returned as a traceback; a dropped client ends its
connection thread only; ``exit()`` in remote code closes that connection, never the
server.

The server listens on loopback unless told otherwise: another address needs
``allow_remote=True`` (``sotpy serve --allow-remote``) and is logged as a warning, since
the token and every line travel unencrypted.

The connection file (:func:`defaultConnectionFile`: ``$XDG_RUNTIME_DIR/sotpy/remote.json``,
else ``~/.cache/sotpy/remote.json``) holds ``{"host", "port", "token", "pid"}``, mode
0600. It is written to a temporary file created exclusively, without following links
(``O_EXCL | O_NOFOLLOW``), then renamed over the old one, in a directory that must
belong to the user and be writable by nobody else (a new one is made 0700). ``serve``
removes it when it stops (if it still holds its token). A client refuses a connection
file that another user could have written.
"""

from __future__ import annotations

import code
import contextlib
import hmac
import io
import ipaddress
import json
import logging
import os
import secrets
import socket
import socketserver
import sys
import threading
import time
import traceback
from pathlib import Path
from types import FrameType
from typing import Any, TextIO

from .errors import RemoteError, RemoteTimeout, SotpyError
from .graph.command import BoundCommand
from .graph.pool import pool
from .loop import ControlLoop, unlocked

__all__ = [
    "DEFAULT_HOST",
    "MAX_GREETING",
    "MAX_LINE",
    "MAX_OUTPUT",
    "RemoteClient",
    "RemoteServer",
    "defaultConnectionFile",
    "readConnectionFile",
]

log = logging.getLogger("sotpy.remote")

#: The default address ``serve`` listens on: the local machine only.
DEFAULT_HOST = "127.0.0.1"
#: The longest message accepted, in bytes, each way (a longer request closes the
#: connection; a reply is truncated to fit).
MAX_LINE = 4 * 1024 * 1024
#: The longest greeting (``{"token": ...}``) accepted, in bytes.
MAX_GREETING = 4096
#: Default ``max_output``: characters of output a reply carries before truncation.
MAX_OUTPUT = 1_000_000


def _isLoopback(host: str) -> bool:
    """Whether every address ``host`` resolves to (IPv4) is a loopback address."""
    if host in ("", "0.0.0.0"):  # every interface
        return False
    try:
        infos = socket.getaddrinfo(host, None, socket.AF_INET, socket.SOCK_STREAM)
    except OSError as exc:
        raise RemoteError(f"cannot resolve the address {host!r}: {exc}") from None
    return all(ipaddress.ip_address(info[4][0]).is_loopback for info in infos)


def defaultConnectionFile() -> Path:
    """``$XDG_RUNTIME_DIR/sotpy/remote.json``, else ``~/.cache/sotpy/remote.json``."""
    runtime = os.environ.get("XDG_RUNTIME_DIR")
    base = Path(runtime) if runtime and Path(runtime).is_dir() else Path.home() / ".cache"
    return base / "sotpy" / "remote.json"


def _othersMayWrite(st: os.stat_result) -> str | None:
    """Why a file or directory with status ``st`` is not the user's alone, or None."""
    getuid = getattr(os, "getuid", None)
    if getuid is None:  # pragma: no cover - Windows: no POSIX owners
        return None
    if st.st_uid != getuid():
        return f"it belongs to uid {st.st_uid}, not to you (uid {getuid()})"
    if st.st_mode & 0o022:
        return f"others may write to it (mode {st.st_mode & 0o7777:04o})"
    return None


def readConnectionFile(path: str | Path | None = None) -> dict[str, Any]:
    """The ``{"host", "port", "token", "pid"}`` a server wrote to ``path``.

    Refused (:class:`~sotpy.errors.RemoteError`) if the file belongs to another user or
    others may write to it: it could send the token to someone else's server.
    """
    p = Path(path) if path is not None else defaultConnectionFile()
    try:
        why = _othersMayWrite(os.stat(p))
        if why is not None:
            raise RemoteError(f"connection file {p} is not trusted: {why}")
        data = json.loads(p.read_text())
        return {"host": str(data["host"]), "port": int(data["port"]), "token": str(data["token"])}
    except FileNotFoundError:
        raise RemoteError(
            f"no connection file {p}: is 'sotpy serve' running (as this user)?"
        ) from None
    except (ValueError, KeyError, TypeError) as exc:
        raise RemoteError(f"connection file {p} is malformed: {exc}") from None


def _privateDirectory(directory: Path) -> None:
    """Make ``directory`` (0700) if missing; refuse one that is not the user's alone."""
    try:
        directory.mkdir(mode=0o700, parents=True, exist_ok=True)
        st = os.stat(directory)
    except OSError as exc:
        raise RemoteError(f"cannot use the directory {directory}: {exc}") from None
    why = _othersMayWrite(st)
    if why is not None:
        raise RemoteError(
            f"refusing to write the connection file in {directory}: {why}; give a "
            "connection file in a directory only you can write"
        )


def _writePrivate(path: Path, text: str) -> None:
    """Write ``text`` to ``path``, readable and writable by its owner only (0600).

    The text goes to a temporary file of a random name created with ``O_EXCL |
    O_NOFOLLOW`` (never an existing file, never through a link), then renamed over
    ``path`` (a link at ``path`` is replaced, not followed), in a directory that must be
    the user's alone.
    """
    _privateDirectory(path.parent)
    tmp = path.with_name(f".{path.name}.{secrets.token_hex(8)}.tmp")
    flags = os.O_WRONLY | os.O_CREAT | os.O_EXCL
    flags |= getattr(os, "O_NOFOLLOW", 0) | getattr(os, "O_CLOEXEC", 0)
    try:
        fd = os.open(tmp, flags, 0o600)
    except OSError as exc:
        raise RemoteError(f"cannot create the connection file {tmp}: {exc}") from None
    try:
        try:
            data = text.encode()
            while data:
                data = data[os.write(fd, data) :]
        finally:
            os.close(fd)
        os.replace(tmp, path)
    except OSError as exc:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        raise RemoteError(f"cannot write the connection file {path}: {exc}") from None


# ---------------------------------------------------------------------------------------
# Framing: JSON lines of bounded size
# ---------------------------------------------------------------------------------------
class _TooLong(Exception):
    pass


class _LineReader:
    """Reads ``\\n``-terminated lines from a socket, each at most ``limit`` bytes."""

    def __init__(self, sock: socket.socket) -> None:
        self._sock = sock
        self._buf = bytearray()

    def readline(self, limit: int, deadline: float | None = None) -> bytes:
        """The next line, newline included (b"": the peer closed). ``_TooLong`` once more
        than ``limit`` bytes came without a newline (no more is read); ``TimeoutError``
        at ``deadline`` (``time.monotonic``) or after the socket's timeout without data.
        """
        scanned = 0
        while True:
            i = self._buf.find(b"\n", scanned)
            if i >= 0:
                line = bytes(self._buf[: i + 1])
                del self._buf[: i + 1]
                return line
            if len(self._buf) > limit:
                raise _TooLong(f"a message longer than {limit} bytes")
            scanned = len(self._buf)
            if deadline is not None:
                remaining = deadline - time.monotonic()
                if remaining <= 0:
                    raise TimeoutError("timed out")
                self._sock.settimeout(remaining)
            chunk = self._sock.recv(min(65536, limit + 1 - len(self._buf)))
            if not chunk:
                return b""
            self._buf += chunk

    def skipline(self) -> None:
        """Drop what is left of the current line, up to and including its newline."""
        while True:
            i = self._buf.find(b"\n")
            if i >= 0:
                del self._buf[: i + 1]
                return
            self._buf.clear()
            chunk = self._sock.recv(65536)
            if not chunk:
                return
            self._buf += chunk


def _parse(line: bytes) -> dict[str, Any]:
    """The JSON object in ``line``; ValueError (with a short reason) otherwise."""
    try:
        msg = json.loads(line)
    except RecursionError:
        raise ValueError("JSON nested too deeply") from None
    if not isinstance(msg, dict):
        raise ValueError("a message must be a JSON object")
    return msg


def _encodeReply(reply: dict[str, Any]) -> bytes:
    """``reply`` as one JSON line of at most MAX_LINE bytes (its output cut if needed)."""
    data = json.dumps(reply).encode() + b"\n"
    out = reply.get("output")
    while len(data) > MAX_LINE and isinstance(out, str) and out:
        keep = len(out) * MAX_LINE // len(data) * 9 // 10
        out = (
            f"{out[:keep]}\n[sotpy remote: output truncated to {keep} of {len(out)} "
            "characters: a reply carries at most MAX_LINE bytes]\n"
        )
        reply = {**reply, "output": out}
        data = json.dumps(reply).encode() + b"\n"
    return data


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


class _CappedText(io.TextIOBase):
    """A capture buffer keeping the first ``limit`` characters written (and counting the
    others), so that a runaway print cannot fill the server's memory."""

    def __init__(self, limit: int) -> None:
        self._parts: list[str] = []
        self._kept = 0
        self._total = 0
        self._limit = limit

    def write(self, s: str) -> int:
        n = len(s)
        self._total += n
        room = self._limit - self._kept
        if room > 0:
            part = s if n <= room else s[:room]
            self._parts.append(part)
            self._kept += len(part)
        return n

    def getvalue(self) -> str:
        text = "".join(self._parts)
        if self._total > self._kept:
            text += (
                f"\n[sotpy remote: output truncated: {self._total} characters printed, "
                f"the first {self._kept} shown (RemoteServer max_output)]\n"
            )
        return text


@contextlib.contextmanager
def _captured(limit: int = MAX_OUTPUT) -> Any:
    _installCapture()
    buf = _CappedText(limit)
    _capture.buffer = buf
    try:
        yield buf
    finally:
        _capture.buffer = None


# ---------------------------------------------------------------------------------------
# Running remote code beside the loop
# ---------------------------------------------------------------------------------------
_PACKAGE = os.path.dirname(os.path.abspath(__file__)) + os.sep
_THIS_FILE = os.path.abspath(__file__)
#: sotpy functions remote code calls without the lock: they wait, they do not edit
#: (``unlocked()`` releases the lock itself; ``loop.wait()`` waits for the loop thread,
#: which needs the lock to end its tick).
_WAITS = frozenset({unlocked.__wrapped__.__code__, ControlLoop.wait.fn.__code__})  # type: ignore[attr-defined]
_COMMAND_CALL = BoundCommand.__call__.__code__
#: Remote code yields the interpreter (``time.sleep(0)``) after running this long, in ns.
_YIELD_NS = 100_000
#: Lines of remote code between two looks at the clock.
_CLOCK_LINES = 32
#: A call into sotpy that holds the lock longer than this (s) is logged (the loop waited).
_SLOW_CALL = 0.1


def _setAsyncExc(thread: int, exc: type[BaseException]) -> None:
    """Raise ``exc`` in ``thread`` at its next check of pending events."""
    import ctypes

    ctypes.pythonapi.PyThreadState_SetAsyncExc(ctypes.c_ulong(thread), ctypes.py_object(exc))


class _GraphScope:
    """Runs one remote input in the calling thread, beside the control loop.

    * **Lock scoping** (``sys.settrace``, call events only): a call into sotpy (a frame
      of a module of the package other than this one) made from remote code holds
      ``pool.lock`` until it returns; what it calls runs untraced, under that lock. The
      rest of the remote code runs without the lock and without line tracing.
    * **The loop gets the interpreter**: the lines of remote code (not of sotpy) are
      traced, and after :data:`_YIELD_NS` of running the thread yields the interpreter
      (``time.sleep(0)``), so that a loop thread waking for a tick gets it within about
      0.1 ms instead of after the switch interval (5 ms). Measured: a 1 kHz loop keeps
      its rate against a spinning client, where waiting for the switch interval leaves
      it near 350 Hz (``docs/shell.md``). The price is the line tracing: a tight loop of
      pure Python in remote code runs several times slower than in a script.
    * **exec_timeout**: a watchdog timer raises :class:`~sotpy.errors.RemoteTimeout` in
      the thread (``PyThreadState_SetAsyncExc``) at the deadline, then every second
      while the input runs, never while the thread is in a call into sotpy (``_gate``
      makes the check and the raise atomic with entering one): the exception starts,
      at the latest, at the first instruction of the next sotpy function, before it
      changed anything. A call into sotpy, or a blocking call in C, finishes first.

    An interrupt that lands in a trace function (often: one runs at every line) unsets
    it (CPython's rule): code that catches that one runs the rest of its input without
    lock scoping, and is not interrupted again (the next interrupt could land inside a
    call into sotpy, now unguarded); one seen landing in remote code (an ``exception``
    event) is repeated every second while the input runs.
    Whatever the input leaves held of ``pool.lock`` is released when it ends.
    """

    def __init__(self, timeout: float | None, peer: str) -> None:
        self._timeout = timeout
        self._peer = peer
        self._frame: FrameType | None = None  # the sotpy frame holding the lock
        self._since = 0.0
        self._gate = threading.Lock()  # the watchdog's check and raise vs entering sotpy
        self._running = False
        self._thread = 0
        self._timer: threading.Timer | None = None
        self._lines = 0
        self._yielded = 0
        self._delivered = True

    def run(self, fn: Any, *args: Any) -> Any:
        self._frame = None
        self._thread = threading.get_ident()
        self._running = True
        self._lines = 0
        self._yielded = time.perf_counter_ns()
        self._delivered = True  # no interrupt on its way
        if self._timeout is not None:
            self._arm(self._timeout)
        previous = sys.gettrace()
        sys.settrace(self._call)
        try:
            return fn(*args)
        finally:
            self._finish(previous)

    def _finish(self, previous: Any) -> None:
        # An interrupt set just before the flag went down is raised at this thread's next
        # check, inside this loop: caught, and none can follow. (Cancelling it with
        # PyThreadState_SetAsyncExc(id, NULL) instead can leave the thread spinning at
        # its next function entry on CPython 3.11.)
        while True:
            try:
                with self._gate:
                    self._running = False
                break
            except RemoteTimeout:
                continue
        if self._timer is not None:
            self._timer.cancel()
            self._timer = None
        sys.settrace(previous)
        self._frame = None
        lock = pool.lock
        while lock._is_owned():  # type: ignore[attr-defined]
            lock.release()

    def _arm(self, delay: float) -> None:
        self._timer = threading.Timer(delay, self._watchdog)
        self._timer.daemon = True
        self._timer.start()

    def _watchdog(self) -> None:
        with self._gate:
            if not self._running:
                return
            if not self._delivered:
                # the last one landed in a trace function: tracing, and so the lock
                # scoping, is gone; another could land inside a call into sotpy
                return
            if self._frame is None:
                self._delivered = False
                _setAsyncExc(self._thread, RemoteTimeout)
                log.warning(
                    "client %s: remote input interrupted after %g s (exec_timeout)",
                    self._peer,
                    self._timeout,
                )
            self._arm(1.0)  # again while it runs: it was in sotpy, or it caught the last

    def _call(self, frame: FrameType, event: str, arg: Any) -> Any:
        if self._frame is not None:
            return None  # inside a sotpy call, under the lock: not traced
        code_obj = frame.f_code
        filename = code_obj.co_filename
        if not filename.startswith(_PACKAGE):
            return self._line
        if filename == _THIS_FILE or code_obj in _WAITS:
            return None
        if code_obj is _COMMAND_CALL:
            cmd = frame.f_locals.get("self")
            if isinstance(cmd, BoundCommand) and cmd.command.fn.__code__ in _WAITS:
                return None
        with self._gate:
            pool.lock.acquire()
            self._frame = frame
        self._since = time.monotonic()
        frame.f_trace_lines = False
        return self._graph

    def _graph(self, frame: FrameType, event: str, arg: Any) -> Any:
        if event == "return" and frame is self._frame:
            self._frame = None
            pool.lock.release()
            held = time.monotonic() - self._since
            if held > _SLOW_CALL:
                code_obj = frame.f_code
                log.warning(
                    "client %s: %s (%s:%d) held the graph lock for %.2f s: the loop waited",
                    self._peer,
                    getattr(code_obj, "co_qualname", code_obj.co_name),
                    os.path.relpath(code_obj.co_filename, _PACKAGE),
                    code_obj.co_firstlineno,
                    held,
                )
        return self._graph

    def _line(self, frame: FrameType, event: str, arg: Any) -> Any:
        if event == "exception" and isinstance(arg[1], RemoteTimeout):
            self._delivered = True  # it landed in remote code: tracing goes on
        elif event == "line":
            self._lines += 1
            if self._lines >= _CLOCK_LINES:
                self._lines = 0
                now = time.perf_counter_ns()
                if now - self._yielded >= _YIELD_NS:
                    time.sleep(0)  # a loop thread waiting for the interpreter runs now
                    self._yielded = time.perf_counter_ns()
        return self._line


class _Console(code.InteractiveConsole):
    """A console whose output goes to the capture buffer (``write`` -> sys.stderr) and
    whose code runs in a ``_GraphScope``."""

    def __init__(self, namespace: dict[str, Any], scope: _GraphScope) -> None:
        super().__init__(namespace, filename="<remote>")
        self._scope = scope

    def runcode(self, code_obj: Any) -> None:
        try:
            self._scope.run(exec, code_obj, self.locals)
        except SystemExit:
            raise
        except BaseException as exc:
            if isinstance(exc, RemoteTimeout) and self._scope._timeout is not None:
                exc.args = (
                    "remote input interrupted: it ran longer than the server's exec_timeout "
                    f"({self._scope._timeout:g} s)",
                )
            tb = exc.__traceback__  # from the remote code on: not the server's frames
            while tb is not None and tb.tb_frame.f_code.co_filename != self.filename:
                tb = tb.tb_next
            self.write("".join(traceback.format_exception(type(exc), exc, tb or exc.__traceback__)))


class _ClientGone(Exception):
    pass


# ---------------------------------------------------------------------------------------
# Server
# ---------------------------------------------------------------------------------------
class _Handler(socketserver.BaseRequestHandler):
    server: _TCPServer

    def _send(self, obj: dict[str, Any]) -> None:
        self.request.sendall(_encodeReply(obj))

    def handle(self) -> None:
        owner = self.server.owner
        peer = f"{self.client_address[0]}:{self.client_address[1]}"
        reader = _LineReader(self.request)
        try:
            if not self._greet(owner, peer, reader):
                return
        finally:
            owner._admitted(-1)
        owner._count(+1)
        log.info("client %s connected", peer)
        try:
            self.request.settimeout(owner.idle_timeout)
            self._send({"ok": True, "banner": owner.banner})
            scope = _GraphScope(owner.exec_timeout, peer)
            console = _Console(owner.namespace, scope)
            from .shell import Completer  # names inside strings; signals not as calls

            completer = Completer(owner.namespace)
            while True:
                try:
                    line = reader.readline(MAX_LINE)
                except _TooLong as exc:
                    raise _ClientGone(f"{exc} (MAX_LINE)") from None
                if not line:
                    break
                try:
                    msg = _parse(line)
                except ValueError as exc:
                    log.info("client %s: malformed request refused (%s)", peer, exc)
                    self._send({"error": f"malformed request: {exc}"})
                    continue
                self._send(self._answer(msg, console, completer))
        except SystemExit:
            log.info("client %s closed the connection (exit())", peer)
            with contextlib.suppress(OSError):
                self._send({"output": "", "more": False, "exit": True})
        except (OSError, _ClientGone) as exc:
            log.info("client %s dropped: %s", peer, exc)
        finally:
            owner._count(-1)
            log.info("client %s disconnected", peer)

    def _greet(self, owner: RemoteServer, peer: str, reader: _LineReader) -> bool:
        """Read the greeting (whole within auth_timeout, at most MAX_GREETING bytes) and
        check the token; False (logged, answered when it makes sense) if refused."""
        deadline = time.monotonic() + owner.auth_timeout
        try:
            line = reader.readline(MAX_GREETING, deadline)
            if not line:
                raise ValueError("closed before sending a token")
            hello = _parse(line)
        except TimeoutError:
            log.warning(
                "refused %s: no valid greeting (no complete greeting within %g s)",
                peer,
                owner.auth_timeout,
            )
            return False
        except _TooLong:
            log.warning("refused %s: no valid greeting (longer than %d bytes)", peer, MAX_GREETING)
            return False
        except (OSError, ValueError) as exc:
            log.warning("refused %s: no valid greeting (%s)", peer, exc)
            return False
        token = hello.get("token")
        if not isinstance(token, str) or not hmac.compare_digest(
            token.encode(), owner.token.encode()
        ):
            why = "missing token" if not isinstance(token, str) else "wrong token"
            log.warning("refused %s: %s", peer, why)
            with contextlib.suppress(OSError):
                self._send({"ok": False, "error": f"refused: {why}"})
            return False
        return True

    def _answer(self, msg: dict[str, Any], console: _Console, completer: Any) -> dict[str, Any]:
        owner = self.server.owner
        if "line" in msg or "source" in msg:
            text = msg.get("line", msg.get("source"))
            if not isinstance(text, str):
                return {"error": "'line'/'source' must be a string"}
            with _captured(owner.max_output) as buf:
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
    request_queue_size = 64  # listen backlog: a burst of connections is accepted, then judged
    owner: RemoteServer

    def verify_request(self, request: Any, client_address: Any) -> bool:
        return self.owner._admit(client_address)

    def handle_error(self, request: Any, client_address: Any) -> None:
        # a logged line, not socketserver's traceback on stderr
        exc = sys.exc_info()[1]
        log.error(
            "connection from %s:%s failed: %s: %s",
            *client_address[:2],
            type(exc).__name__,
            exc,
        )
        log.debug("traceback", exc_info=True)


class RemoteServer:
    """A remote interpreter over ``namespace`` (a dict), listening on TCP.

    Args:
        namespace: the globals the remote lines run in (shared by every client).
        host: address to listen on (default 127.0.0.1: this machine only).
        port: TCP port (0: a free port, see :attr:`address`).
        token: the secret clients must send (default ``secrets.token_urlsafe(32)``).
        connectionFile: where to write ``{"host", "port", "token", "pid"}`` (mode 0600)
            when started; None: do not write one.
        auth_timeout: s a new client has, from connecting, to send its whole greeting.
        idle_timeout: s a client may stay silent before it is dropped (None: forever).
        banner: text sent to clients when they connect.
        max_pending: connections allowed to wait for authentication at once; more are
            closed when they connect.
        max_output: characters of output a reply carries; more are dropped, with a
            notice (what a reply can carry, :data:`MAX_LINE` bytes, may cut it shorter).
        exec_timeout: s after which remote code still running is interrupted (None:
            never); see the module doc.
        allow_remote: listen on an address that is not loopback (the token and the
            lines travel unencrypted: a warning is logged). Without it, such a ``host``
            is refused with :class:`~sotpy.errors.RemoteError`.
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
        max_pending: int = 16,
        max_output: int = MAX_OUTPUT,
        exec_timeout: float | None = None,
        allow_remote: bool = False,
    ) -> None:
        if not _isLoopback(host):
            if not allow_remote:
                raise RemoteError(
                    f"refusing to listen on {host!r}: not a loopback address, and the token "
                    "and every line travel unencrypted; pass allow_remote=True (sotpy serve "
                    "--allow-remote) to do it anyway, or keep 127.0.0.1 and reach it "
                    "through an SSH tunnel"
                )
            log.warning(
                "listening on %s, not a loopback address: the token and every line travel "
                "UNENCRYPTED on the network; prefer 127.0.0.1 with an SSH tunnel",
                host,
            )
        for what, value in (("auth_timeout", auth_timeout), ("max_output", max_output)):
            if not (isinstance(value, (int, float)) and value > 0):
                raise RemoteError(f"RemoteServer: {what} must be > 0, got {value!r}")
        if isinstance(max_pending, bool) or not isinstance(max_pending, int) or max_pending < 1:
            raise RemoteError(
                f"RemoteServer: max_pending must be an integer >= 1, got {max_pending!r}"
            )
        if exec_timeout is not None and not exec_timeout > 0:
            raise RemoteError(
                f"RemoteServer: exec_timeout must be > 0 or None, got {exec_timeout!r}"
            )
        self.namespace = namespace
        self.token = token if token is not None else secrets.token_urlsafe(32)
        self.auth_timeout = auth_timeout
        self.idle_timeout = idle_timeout
        self.banner = banner
        self.max_pending = max_pending
        self.max_output = int(max_output)
        self.exec_timeout = exec_timeout
        self.connectionFile = Path(connectionFile) if connectionFile is not None else None
        self._clients = 0
        self._pending = 0
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

    @property
    def pending(self) -> int:
        """Number of connections waiting to authenticate."""
        return self._pending

    def _count(self, d: int) -> None:
        with self._clientsLock:
            self._clients += d

    def _admit(self, client_address: Any) -> bool:
        """Count a new connection as pending, or refuse it if max_pending are."""
        with self._clientsLock:
            if self._pending >= self.max_pending:
                log.warning(
                    "refused %s:%s: %d connections already wait to authenticate (max_pending)",
                    *client_address[:2],
                    self._pending,
                )
                return False
            self._pending += 1
            return True

    def _admitted(self, d: int) -> None:
        with self._clientsLock:
            self._pending += d

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
        """Stop accepting clients, close the socket, remove the connection file (if it
        still holds this server's token: another server may have replaced it)."""
        if self._thread is not None:
            self._server.shutdown()
            self._thread.join(5.0)
            self._thread = None
        self._server.server_close()
        if self.connectionFile is not None:
            with contextlib.suppress(OSError, ValueError, KeyError):
                if json.loads(self.connectionFile.read_text())["token"] == self.token:
                    self.connectionFile.unlink()


# ---------------------------------------------------------------------------------------
# Client
# ---------------------------------------------------------------------------------------
class RemoteClient:
    """A connection to a :class:`RemoteServer`; raises
    :class:`~sotpy.errors.RemoteError` if refused.

    ``RemoteClient(host, port, token)`` or ``RemoteClient.fromFile(path)``; ``timeout``
    (s) bounds connecting and the greeting, ``reply_timeout`` (s, None: no bound) the
    wait for each reply (remote code may run long). A request that cannot be sent
    (longer than :data:`MAX_LINE`) or a reply that cannot be read (too long, not JSON)
    raises ``RemoteError`` and leaves the connection usable; a lost connection (or a
    reply that timed out) raises ``RemoteError`` and sets ``lost``.
    """

    def __init__(
        self,
        host: str,
        port: int,
        token: str,
        timeout: float | None = 60.0,
        reply_timeout: float | None = None,
    ) -> None:
        self.lost = False
        try:
            self._sock = socket.create_connection((host, port), timeout=timeout)
        except OSError as exc:
            raise RemoteError(
                f"cannot connect to the remote interpreter at {host}:{port}: {exc}"
            ) from None
        self._reader = _LineReader(self._sock)
        self.banner = ""
        try:
            hello = self._request({"token": token})
        except RemoteError:
            self.close()
            raise
        if not hello.get("ok"):
            self.close()
            raise RemoteError(
                f"the remote interpreter at {host}:{port} refused the connection: "
                f"{hello.get('error', 'no reason given')}"
            )
        self.banner = str(hello.get("banner", ""))
        self._sock.settimeout(reply_timeout)  # remote code may run long, beside the loop

    @classmethod
    def fromFile(
        cls,
        path: str | Path | None = None,
        timeout: float | None = 60.0,
        reply_timeout: float | None = None,
    ) -> RemoteClient:
        """Connect with the address and token of a connection file (default
        :func:`defaultConnectionFile`)."""
        c = readConnectionFile(path)
        return cls(c["host"], c["port"], c["token"], timeout=timeout, reply_timeout=reply_timeout)

    def _lose(self, why: str) -> RemoteError:
        self.lost = True
        self.close()
        return RemoteError(why)

    def _request(self, msg: dict[str, Any]) -> dict[str, Any]:
        if self.lost:
            raise RemoteError("the connection to the remote interpreter was lost")
        data = json.dumps(msg).encode() + b"\n"
        if len(data) > MAX_LINE:
            raise RemoteError(
                f"request not sent: {len(data)} bytes, longer than the {MAX_LINE} a message "
                "may have (MAX_LINE); send the code in smaller parts"
            )
        try:
            self._sock.sendall(data)
            line = self._reader.readline(MAX_LINE)
        except _TooLong:
            try:
                self._reader.skipline()
            except OSError as exc:
                raise self._lose(f"lost the remote interpreter: {exc}") from exc
            raise RemoteError(
                f"the remote interpreter's reply is longer than {MAX_LINE} bytes (MAX_LINE): "
                "dropped; the connection is still usable"
            ) from None
        except OSError as exc:
            raise self._lose(f"lost the remote interpreter: {exc}") from exc
        if not line:
            raise self._lose("the remote interpreter closed the connection")
        try:
            reply = _parse(line)
        except ValueError as exc:
            raise RemoteError(
                f"unreadable reply from the remote interpreter ({exc}): dropped; the "
                "connection is still usable"
            ) from None
        if "error" in reply and "ok" not in reply:
            raise RemoteError(f"remote interpreter: {reply['error']}")
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
            self._sock.close()

    def __enter__(self) -> RemoteClient:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def interact(self) -> None:
        """A console whose lines run remotely (readline editing and remote tab
        completion when readline is available); Ctrl-D leaves, Ctrl-C drops the
        statement being typed. A reply that cannot be read is reported and the console
        goes on; Ctrl-C while a line runs closes the connection (RemoteError; the line
        goes on in the server)."""
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
            try:
                r = self._request({"line": line})
            except RemoteError as exc:
                if self.lost:
                    raise
                print(f"sotpy connect: {exc}", file=sys.stderr)  # and go on
                more = False
                continue
            except KeyboardInterrupt:  # the reply is still to come: the connection ends
                raise self._lose(
                    "interrupted while the remote input ran; it goes on in the server "
                    "(RemoteServer's exec_timeout bounds inputs); connection closed"
                ) from None
            sys.stdout.write(str(r.get("output", "")))
            sys.stdout.flush()
            if r.get("exit"):
                return
            more = bool(r.get("more", False))
