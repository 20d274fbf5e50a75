"""The dashboard: a web page generated from the graph, served while the loop runs.

::

    from sotpy.dashboard import Dashboard

    ui = Dashboard(loop, robot=robot)   # 127.0.0.1, a free port, a fresh token
    print(ui.url())                     # http://127.0.0.1:PORT/?token=...
    ...
    ui.save("run.npz")                  # the plotted signals' ring, as Tracer.dump
    ui.close()

The server is Tornado (already a dependency of meshcat), on an asyncio loop in a daemon
thread; the page is static files of this package with two vendored libraries, uPlot (the
plots) and dagre (the graph's layout), so it loads nothing from the network.

**The token rule** (the remote interpreter's): the page, its files, the websocket and the
recordings are served only to a request that presents the token, in the address
(``?token=``, the first time; the server then sets an HttpOnly, SameSite=Strict cookie
and drops it from the address) or in that cookie. A request without it gets 403 and is
logged with the peer's address. The websocket also checks its ``Origin`` (another site's
page in the same browser cannot open it). The server listens on 127.0.0.1; another
address needs ``allowRemote=True`` and is warned about (the page is plain HTTP: the
token crosses the network unencrypted; prefer ``ssh -L``).

**CPUs.** When the loop is pinned (``ControlLoop(..., cpus=...)``), the server's threads
run on the CPUs it leaves (``Dashboard.cpus``), and so does a browser started with
:class:`~sotpy.dashboard.browser.HeadlessPage` given those CPUs: their work then does
not evict the tick's data from the loop's CPU while it sleeps between ticks.

**The loop never waits for the page.** The plotted signals are recorded between two
ticks by the :class:`~sotpy.dashboard.model.Recorder` (the loop's idle call, a few us a
signal; in the tick under ``step``); the server reads the
new rows without a lock and sends each page at most ``rate`` frames a second; while a
page has not taken the previous frame (a slow or frozen browser), its frames are
skipped and the rows wait in the ring (``seconds`` long): the page loses frames, never
ticks. Reading the graph and applying an edit hold ``pool.lock`` between two ticks, as
the shell does for each input, in a worker thread (never on the server's own thread).
A malformed request is refused with a message, logged, and changes nothing.

**Between two ticks.** The server's thread shares the GIL with the loop's: woken in the
middle of a tick, it would take the GIL at the tick's first release (NumPy releases it in
its larger operations) and keep it up to Python's switch interval. So while the loop
ticks in real time, it wakes the server itself, between two ticks, ``rate`` times a
second (:meth:`~sotpy.loop.ControlLoop.addIdleCall`), and the frames and the status are
made then; the server's own timer only checks, twice a second, that the loop still
does, and takes over when it stops.
"""

from __future__ import annotations

import asyncio
import contextlib
import hmac
import ipaddress
import json
import logging
import math
import os
import secrets
import socket
import struct
import threading
import time
import warnings
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import Any
from urllib.parse import urlsplit

import numpy as np

from ..errors import SotpyError, SotpyWarning
from ..graph.pool import pool
from .model import EditError, Recorder, applyEdit, graphSnapshot, signalList, status, valueText

__all__ = ["DEFAULT_RATE", "Dashboard", "isLoopback"]

log = logging.getLogger("sotpy.dashboard")

STATIC = Path(__file__).with_name("static")
#: Frames a second sent to each page (the plots' refresh rate).
DEFAULT_RATE = 30.0
#: How often the status (loop, stack, fresh signals) is sent, in s.
STATUS_PERIOD = 0.25
#: How often (s) the server's own timer checks that a running loop still wakes it.
IDLE_CHECK = 0.5
#: Python's switch interval while a dashboard serves (s; Python's default is 5 ms): the
#: longest a tick that wants the GIL back waits for the server's thread to yield it.
SWITCH_INTERVAL = 0.0005
#: The largest message a page may send (bytes); a longer one closes its connection.
MAX_MESSAGE = 64 * 1024
_COOKIE = "sotpy_dashboard"


def isLoopback(host: str) -> bool:
    """Whether ``host`` names this machine only: an address in 127.0.0.0/8 or ``::1``,
    or a name every address of which is (the remote interpreter's rule, whose helper
    resolves names)."""
    from ..remote import _isLoopback

    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return _isLoopback(host)


def _matches(token: str | None, expected: str) -> bool:
    return isinstance(token, str) and hmac.compare_digest(token.encode(), expected.encode())


class _Client:
    """One open page: its websocket, its cursor in the recorder, its plotted series."""

    def __init__(self, ws: Any) -> None:
        self.ws = ws
        self.cursor = 0
        self.series: list[tuple[int, str, list[int] | None]] = []  # (id, path, comps)
        self.watch: set[str] = set()  # entities whose values the page shows
        self.version = -1
        self.pending: Any = None  # the future of the frame being written
        self.frames = 0
        self.skipped = 0


class Dashboard:
    """A live web page over the graph of ``loop`` (a :class:`~sotpy.loop.ControlLoop`).

    Args:
        loop: the control loop (its device is recorded; its commands start, stop and
            step it from the page). None: the graph only, nothing recorded.
        robot: the robot ``load_robot`` gave (its ``model`` and ``visual_model``), for
            the 3-D view (a :class:`~sotpy.viewer.RobotViewer` started on demand);
            None: no 3-D view.
        host: the address to listen on (127.0.0.1).
        port: the TCP port (0: a free one).
        token: the secret the page must present (default ``secrets.token_urlsafe(32)``).
        allowRemote: required (True) to listen on an address other than loopback; a
            :class:`~sotpy.errors.SotpyWarning` says the page is then reachable from
            the network over plain HTTP.
        seconds: the recorder's history, s (the ring of the plotted signals).
        rate: frames a second sent to each page.
        name: the dashboard's name (its hook signal is ``Dashboard(name)::output(int)::record``).
    """

    def __init__(
        self,
        loop: Any = None,
        robot: Any = None,
        *,
        host: str = "127.0.0.1",
        port: int = 0,
        token: str | None = None,
        allowRemote: bool = False,
        seconds: float = 10.0,
        rate: float = DEFAULT_RATE,
        name: str = "dashboard",
    ) -> None:
        who = f"Dashboard({name})"
        if not isLoopback(host):
            if not allowRemote:
                raise SotpyError(
                    f"{who}: {host!r} is not a loopback address; the page would be reachable "
                    "from the network: pass allowRemote=True (sotpy: --ui-allow-remote) to do it "
                    "anyway, or forward the port (ssh -L PORT:127.0.0.1:PORT robot-pc)"
                )
            msg = (
                f"{who}: listening on {host}, reachable from the network over plain HTTP: the "
                "token and the data cross it unencrypted"
            )
            log.warning(msg)
            warnings.warn(msg, SotpyWarning, stacklevel=2)
        if not (isinstance(rate, (int, float)) and math.isfinite(rate) and 0 < rate <= 200):
            raise SotpyError(f"{who}: rate must be in (0, 200] frames/s, got {rate!r}")
        self.name = name
        self.loop = loop
        self.robot = robot
        self.token = token if token is not None else secrets.token_urlsafe(32)
        self.rate = float(rate)
        device = getattr(loop, "device", None)
        self.device = device
        dt = float(getattr(loop, "dt", 1e-3))
        self.recorder = Recorder(name, device, seconds, dt) if device is not None else None
        self.viewer: Any = None
        self._clients: set[_Client] = set()
        self._graph: dict[str, Any] | None = None
        self._signals: list[Any] = []
        self._status: dict[str, Any] | None = None
        self._refused = 0
        self._closed = False
        self._graphPending = False
        self._stats: Any = None
        self._statsAt = 0.0
        self._nextFrame = self._nextStatus = 0.0
        self._pumpedByLoop = -math.inf  # when the loop last woke the server (monotonic s)
        others = loop.otherCpus() if callable(getattr(loop, "otherCpus", None)) else None
        self.cpus: frozenset[int] | None = others
        self._work = ThreadPoolExecutor(
            1, thread_name_prefix=f"{who} edits", initializer=self._keepOffTheLoop
        )
        self._graphLock = threading.Lock()
        self._ready = threading.Event()
        self._error: BaseException | None = None
        self._sock = socket.socket(
            socket.AF_INET6 if ":" in host else socket.AF_INET, socket.SOCK_STREAM
        )
        try:
            self._sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
            self._sock.bind((host, port))
            self._sock.listen(16)
            self._sock.setblocking(False)
        except OSError as exc:
            self._sock.close()
            raise SotpyError(f"{who}: cannot listen on {host}:{port}: {exc}") from None
        self.host = host
        self.port = int(self._sock.getsockname()[1])
        if self.recorder is not None:
            self.recorder.attach()
        _switchInterval(+1)
        if callable(getattr(loop, "addIdleCall", None)):  # frames between the loop's ticks
            loop.addIdleCall(self._loopWakes, max(1, round(1.0 / (self.rate * dt))))
            if self.recorder is not None:  # the recorder's rows, between two ticks
                self.recorder.loop = loop
                loop.addIdleCall(self.recorder.finishRow)
        self._thread = threading.Thread(target=self._serve, name=f"{who} server", daemon=True)
        self._thread.start()
        if not self._ready.wait(20.0) or self._error is not None:
            self.close()
            raise SotpyError(f"{who}: the web server did not start: {self._error!r}")
        log.info("dashboard on http://%s:%d/", host, self.port)

    # -- public --------------------------------------------------------------------------
    def url(self) -> str:
        """The page's address, with the token (open it in a browser)."""
        host = f"[{self.host}]" if ":" in self.host else self.host
        return f"http://{host}:{self.port}/?token={self.token}"

    def plot(self, *paths: str) -> None:
        """Record ``paths`` (``entity.signal``) and show them in a new plot of every page."""
        for p in paths:
            self._recorderOrRaise().add(p)
        self._broadcast({"type": "plot", "signals": list(paths)})

    def save(self, path: str | Path) -> str:
        """Write the recorded signals (the ring) as ``Tracer.dump``: ``.npz`` or ``.csv``."""
        return self._recorderOrRaise().save(path)

    def saveFiles(self, dirname: str | Path, prefix: str = "", suffix: str = ".txt") -> list[str]:
        """Write SoT's tracer text files of the recorded signals (one per signal)."""
        return self._recorderOrRaise().saveFiles(dirname, prefix, suffix)

    def data(self) -> dict[str, np.ndarray]:
        """The recorded rows (``Tracer.data()``'s form, ``time`` in s)."""
        return self._recorderOrRaise().data()

    @property
    def pages(self) -> int:
        """Pages connected now."""
        return len(self._clients)

    @property
    def refused(self) -> int:
        """Requests refused so far (no token, a bad origin, a malformed message)."""
        return self._refused

    def frameCounts(self) -> list[tuple[int, int]]:
        """(frames sent, frames skipped because the page was busy) of each page."""
        return [(c.frames, c.skipped) for c in list(self._clients)]

    def close(self) -> None:
        """Stop the server, take the recorder out of the tick, close the 3-D view.
        Idempotent."""
        if self._closed:
            return
        self._closed = True
        aio = getattr(self, "_aio", None)
        if aio is not None and aio.is_running():
            with contextlib.suppress(RuntimeError):
                aio.call_soon_threadsafe(self._stopServing)
            self._thread.join(10.0)
        with contextlib.suppress(OSError):
            self._sock.close()
        _switchInterval(-1)
        if callable(getattr(self.loop, "rmIdleCall", None)):
            self.loop.rmIdleCall(self._loopWakes)
            if self.recorder is not None:
                self.loop.rmIdleCall(self.recorder.finishRow)
        if self.recorder is not None:
            with contextlib.suppress(Exception):
                self.recorder.detach()
        viewer, self.viewer = self.viewer, None
        if viewer is not None:
            with contextlib.suppress(Exception), pool.lock:
                self.device.after.rmSignal(viewer.display, missing_ok=True)
                if pool.hasEntity(viewer.name):
                    pool.remove(viewer)
                viewer.close()
        self._work.shutdown(wait=False, cancel_futures=True)

    def __enter__(self) -> Dashboard:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # -- helpers -------------------------------------------------------------------------
    def _recorderOrRaise(self) -> Recorder:
        if self.recorder is None:
            raise SotpyError(f"Dashboard({self.name}): no loop, so nothing is recorded")
        return self.recorder

    def _refuse(self, handler: Any, why: str) -> None:
        self._refused += 1
        peer = handler.request.remote_ip
        log.warning("dashboard: refused %s %s from %s: %s", handler.request.method,
                    handler.request.path, peer, why)  # fmt: skip

    def _authorised(self, handler: Any) -> bool:
        token = handler.get_query_argument("token", None)
        if token is None:
            token = handler.get_cookie(f"{_COOKIE}_{self.port}")
        return _matches(token, self.token)

    def graph(self) -> dict[str, Any]:
        """The graph's snapshot (recomputed when the topology changed), read holding
        ``pool.lock``."""
        with self._graphLock:
            if self._graph is None or self._graph["version"] != pool.version:
                with pool.lock:
                    self._graph = graphSnapshot(self.device)
                    self._signals = signalList()
            return self._graph

    def _statusNow(self) -> dict[str, Any]:
        signals = self._signals
        now = time.monotonic()
        if self.loop is not None and (self._stats is None or now - self._statsAt > 1.0):
            self._stats, self._statsAt = self.loop.stats(), now  # percentiles: once a second
        st = status(self.loop, signals, stats=self._stats)
        rec = self.recorder
        if rec is not None:
            st["recording"] = {
                "signals": rec.paths(),
                "errors": rec.errors(),
                "rows": min(rec.count, rec.size),
                "seconds": rec.seconds,
            }
        watched = set().union(*(c.watch for c in list(self._clients))) if self._clients else set()
        values = {}
        for name in sorted(watched):
            e = pool._entities.get(name)
            if e is not None:
                for sig in e.signals():
                    values[sig.path] = valueText(sig)
        st["values"] = values
        st["pages"] = len(self._clients)
        st["viewer"] = None if self.viewer is None else self.viewer.url()
        st["viewerAvailable"] = self.robot is not None and self.device is not None
        return st

    def _broadcast(self, msg: dict[str, Any]) -> None:
        aio = getattr(self, "_aio", None)
        if aio is None or self._closed:
            return
        text = json.dumps(msg)

        def send() -> None:
            for c in list(self._clients):
                with contextlib.suppress(Exception):
                    c.ws.write_message(text)

        with contextlib.suppress(RuntimeError):
            aio.call_soon_threadsafe(send)

    # -- the server thread ---------------------------------------------------------------
    def _keepOffTheLoop(self) -> None:
        """Run the calling thread on the CPUs the loop leaves (when it is pinned)."""
        if self.cpus is not None:
            os.sched_setaffinity(0, self.cpus)

    def _serve(self) -> None:
        try:
            self._keepOffTheLoop()
            aio = asyncio.new_event_loop()
            asyncio.set_event_loop(aio)
            self._aio = aio
            from tornado.httpserver import HTTPServer

            self._app = _application(self)
            self._http = HTTPServer(
                self._app, max_body_size=MAX_MESSAGE, idle_connection_timeout=60
            )
            self._http.add_sockets([self._sock])
            self._timer = aio.call_soon(self._timerPump)
        except BaseException as exc:
            self._error = exc
            self._ready.set()
            return
        self._ready.set()
        try:
            aio.run_forever()
        finally:
            with contextlib.suppress(Exception):
                aio.run_until_complete(aio.shutdown_asyncgens())
            aio.close()

    # -- the pump: frames and status, between two ticks of a running loop ----------------
    def _pump(self) -> None:
        """Send what is due: each page's frame (``rate`` a second) and the status (every
        ``STATUS_PERIOD`` s)."""
        now = time.monotonic()
        # the status first: it is not sent to a page whose last frame is still being
        # written, as the frame just sent would be (a wakeup a little early is on time)
        if now >= self._nextStatus:
            self._nextStatus = now + 0.9 * STATUS_PERIOD
            self._sendStatus()
        if now >= self._nextFrame:
            self._nextFrame = now + 0.8 / self.rate
            self._sendFrames()

    def _loopWakes(self) -> None:
        """The loop's idle call (its thread, between two ticks): wake the server's thread
        to pump, when a page is open. A few us: one ``call_soon_threadsafe``."""
        if self._clients and not self._closed:
            self._pumpedByLoop = time.monotonic()
            with contextlib.suppress(RuntimeError):  # closed meanwhile
                self._aio.call_soon_threadsafe(self._pump)

    def _timerPump(self) -> None:
        """The server's own timer: it pumps while the loop is not ticking in real time;
        while the loop wakes the server between its ticks, or while no page is open, it
        only checks twice a second (its own wakeups would fall anywhere, inside ticks
        too)."""
        if not self._clients or time.monotonic() - self._pumpedByLoop < 0.25:
            self._timer = self._aio.call_later(IDLE_CHECK, self._timerPump)
            return
        self._pump()
        self._timer = self._aio.call_later(1.0 / self.rate, self._timerPump)

    def _stopServing(self) -> None:
        self._timer.cancel()
        self._http.stop()
        for c in list(self._clients):
            with contextlib.suppress(Exception):
                c.ws.close()
        self._aio.call_later(0.05, self._aio.stop)

    def _sendFrames(self) -> None:
        rec = self.recorder
        if rec is None:
            return
        for c in list(self._clients):
            if not c.series:
                c.cursor = rec.count
                continue
            if c.pending is not None and not c.pending.done():
                c.skipped += 1  # the page has not taken the last frame: skip this one
                continue
            if rec.count == c.cursor:
                continue
            try:
                frame, c.cursor = _frame(rec, c)
            except Exception as exc:  # never let one page's request stop the others'
                log.warning("dashboard: cannot build a frame for a page: %r", exc)
                c.series, c.cursor = [], rec.count
                continue
            try:
                c.pending = c.ws.write_message(frame, binary=True)
                c.frames += 1
            except Exception:  # the page went away: its handler removes it
                c.pending = None

    def _sendStatus(self) -> None:
        if not self._clients:
            return
        version = pool.version
        need = [c for c in self._clients if c.version != version]
        if need or self._graph is None:
            if not self._graphPending:
                self._graphPending = True
                self._work.submit(self._refreshGraph)
            return  # the status follows the graph (its fresh indices refer to it)
        try:
            text = json.dumps({"type": "status", **self._statusNow()})
        except Exception as exc:  # a value that cannot be shown: log, keep serving
            log.warning("dashboard: status failed: %r", exc)
            return
        for c in list(self._clients):
            if c.pending is None or c.pending.done():
                with contextlib.suppress(Exception):
                    c.ws.write_message(text)

    def _refreshGraph(self) -> None:
        try:
            graph = self.graph()
            text = json.dumps({"type": "graph", **graph})
        except Exception as exc:
            log.warning("dashboard: reading the graph failed: %r", exc)
            return
        finally:
            self._graphPending = False

        def send() -> None:
            for c in list(self._clients):
                if c.version != graph["version"]:
                    c.version = graph["version"]
                    with contextlib.suppress(Exception):
                        c.ws.write_message(text)

        with contextlib.suppress(RuntimeError):
            self._aio.call_soon_threadsafe(send)

    async def _handle(self, client: _Client, message: Any) -> None:
        """One message of a page: a request, answered with its ``id``."""
        peer = client.ws.request.remote_ip
        rid = None
        try:
            if isinstance(message, bytes):
                raise EditError("a dashboard request is a JSON text message, got bytes")
            try:
                msg = json.loads(message)
            except ValueError as exc:
                raise EditError(f"a dashboard request must be JSON: {exc}") from None
            if not isinstance(msg, dict):
                raise EditError("a dashboard request must be a JSON object")
            rid = msg.get("id")
            kind = msg.get("kind")
            if kind == "series":
                reply = self._setSeries(client, msg)
            elif kind == "watch":
                names = msg.get("entities")
                if not (isinstance(names, list) and all(isinstance(n, str) for n in names)):
                    raise EditError("'entities' must be a list of entity names")
                client.watch = set(names[:20])
                reply = {"ok": True, "result": len(client.watch)}
            elif kind == "viewer":
                reply = await asyncio.wrap_future(self._work.submit(self._startViewer))
            else:
                reply = await asyncio.wrap_future(self._work.submit(applyEdit, msg, self.recorder))
                if kind in ("plot", "unplot", "set", "call"):
                    self._work.submit(self._pushStatus)
        except EditError as exc:
            self._refused += 1
            log.warning("dashboard: refused a malformed request from %s: %s", peer, exc)
            reply = {"ok": False, "error": str(exc), "malformed": True}
        except SotpyError as exc:
            log.info("dashboard: edit refused: %s", exc)
            reply = {"ok": False, "error": str(exc), "errorType": type(exc).__name__}
        except Exception as exc:  # anything else a command raised: shown, not fatal
            log.info("dashboard: edit failed: %r", exc)
            reply = {
                "ok": False,
                "error": f"{type(exc).__name__}: {exc}",
                "errorType": type(exc).__name__,
            }
        reply = {"type": "reply", "id": rid if isinstance(rid, (int, str)) else None, **reply}
        with contextlib.suppress(Exception):
            client.ws.write_message(json.dumps(reply))

    def _pushStatus(self) -> None:
        """Send the status now (after an edit), so the page shows its effect at once."""
        self._graphLockedStatus()

    def _graphLockedStatus(self) -> None:
        try:
            self.graph()
        except Exception:
            return
        with contextlib.suppress(RuntimeError):
            self._aio.call_soon_threadsafe(self._sendStatus)

    def _setSeries(self, client: _Client, msg: dict[str, Any]) -> dict[str, Any]:
        """``{"kind": "series", "series": [[id, path, [components] or null], ...]}``: what
        the page plots; its next frames carry their rows (the whole ring first)."""
        series = msg.get("series")
        if not isinstance(series, list):
            raise EditError("'series' must be a list of [id, path, components]")
        out = []
        for item in series:
            if not (isinstance(item, list) and len(item) == 3):
                raise EditError(f"a series is [id, path, components], got {item!r}")
            sid, path, comps = item
            if not isinstance(sid, int) or not isinstance(path, str):
                raise EditError(f"a series is [int id, str path, components], got {item!r}")
            if comps is not None and not (
                isinstance(comps, list)
                and all(isinstance(k, int) and not isinstance(k, bool) and k >= 0 for k in comps)
            ):
                raise EditError(f"components must be a list of indices >= 0, got {comps!r}")
            out.append((sid, path, comps))
        client.series = out
        client.cursor = 0  # resend the ring
        return {"ok": True, "result": len(out)}

    def _startViewer(self) -> dict[str, Any]:
        """Start the 3-D view (a RobotViewer refreshed from the device every 20 ticks)."""
        if self.viewer is not None:
            return {"ok": True, "result": self.viewer.url()}
        robot = self.robot
        if robot is None or getattr(robot, "visual_model", None) is None or self.device is None:
            raise SotpyError(
                f"Dashboard({self.name}): no 3-D view: the dashboard was made without a robot "
                "(Dashboard(loop, robot=robot))"
            )
        from ..graph import plug
        from ..viewer import RobotViewer

        name = f"{self.name}_viewer"
        with pool.lock:
            viewer = RobotViewer(name, robot.model, robot.visual_model, period=20)
            plug(self.device.state, viewer.state)
            self.device.after.addSignal(viewer.display)
        with viewer.lock:
            viewer.viz.display(self.device.state.value)
        viewer.frameRobot(self.device.state.value)
        self.viewer = viewer
        return {"ok": True, "result": viewer.url()}


_SWITCH = {"count": 0, "saved": None}
_SWITCH_LOCK = threading.Lock()


def _switchInterval(d: int) -> None:
    """While a dashboard serves, Python's switch interval is :data:`SWITCH_INTERVAL`
    (restored when the last one closes). The server's thread shares the GIL with the
    loop's: with Python's 5 ms, a tick that released the GIL (in NumPy, BLAS) could wait
    up to 5 ms for the server to give it back; with 0.5 ms, 0.5 ms at most."""
    import sys

    with _SWITCH_LOCK:
        if d > 0:
            if _SWITCH["count"] == 0:
                _SWITCH["saved"] = sys.getswitchinterval()
                sys.setswitchinterval(min(SWITCH_INTERVAL, _SWITCH["saved"]))
            _SWITCH["count"] += 1
        else:
            _SWITCH["count"] -= 1
            if _SWITCH["count"] == 0 and _SWITCH["saved"] is not None:
                sys.setswitchinterval(_SWITCH["saved"])


def _frame(rec: Recorder, c: _Client) -> tuple[bytes, int]:
    """A binary frame of the rows after ``c.cursor``: a 4-byte length, a JSON header
    (``n`` rows, ``series``: ``[id, components]`` each), padding to 8 bytes, then the
    ticks' times (s) and each series' values (row-major), as float64."""
    cursor, ticks, blocks = rec.since(c.cursor, [(p, k) for _, p, k in c.series])
    parts = [ticks.astype(np.float64) * rec.dt]
    series = []
    for (sid, _path, _comps), block in zip(c.series, blocks, strict=True):
        if block is None:
            series.append([sid, 0])
            continue
        series.append([sid, int(block.shape[1])])
        parts.append(block)
    header = json.dumps({"n": len(ticks), "series": series, "count": cursor}).encode()
    pad = (-(4 + len(header))) % 8
    body = b"".join(np.ascontiguousarray(p, dtype=np.float64).tobytes() for p in parts)
    return struct.pack("<I", len(header)) + header + b" " * pad + body, cursor


# ---------------------------------------------------------------------------------------
# Tornado handlers
# ---------------------------------------------------------------------------------------
def _application(ui: Dashboard) -> Any:
    import tornado.web
    import tornado.websocket

    cookie = f"{_COOKIE}_{ui.port}"

    class Guarded(tornado.web.RequestHandler):
        def prepare(self) -> None:
            if not ui._authorised(self):
                ui._refuse(self, "no valid token")
                raise tornado.web.HTTPError(403, "token required")

        def set_default_headers(self) -> None:
            self.set_header("Cache-Control", "no-store")
            self.set_header("X-Frame-Options", "SAMEORIGIN")
            self.set_header("Referrer-Policy", "no-referrer")

        def write_error(self, status_code: int, **kwargs: Any) -> None:
            self.set_header("Content-Type", "text/plain; charset=utf-8")
            self.finish(f"{status_code}: {self._reason}\n")

    class Index(Guarded):
        def get(self) -> None:
            if self.get_query_argument("token", None) is not None:
                self.set_cookie(cookie, ui.token, httponly=True, samesite="Strict")
                self.redirect("/")  # the token leaves the address bar and the history
                return
            self.set_header("Content-Type", "text/html; charset=utf-8")
            self.finish((STATIC / "index.html").read_bytes())

    class Static(Guarded, tornado.web.StaticFileHandler):
        pass

    class Record(Guarded):
        def get(self, fmt: str) -> None:
            import tempfile

            rec = ui._recorderOrRaise()
            with tempfile.TemporaryDirectory() as d:
                path = Path(d) / f"dashboard.{fmt}"
                rec.save(path)
                data = path.read_bytes()
            kind = "text/csv" if fmt == "csv" else "application/octet-stream"
            self.set_header("Content-Type", kind)
            stamp = time.strftime("%Y%m%d-%H%M%S")
            self.set_header("Content-Disposition", f'attachment; filename="sotpy-{stamp}.{fmt}"')
            self.finish(data)

    class NoIcon(tornado.web.RequestHandler):
        def get(self) -> None:
            self.set_status(204)  # no favicon: say so instead of a logged 404

    class Socket(tornado.websocket.WebSocketHandler):
        client: _Client | None = None

        async def get(self, *args: Any, **kwargs: Any) -> None:
            if not ui._authorised(self):
                ui._refuse(self, "no valid token")
                self.set_status(403)
                self.finish("403: token required\n")
                return
            await super().get(*args, **kwargs)

        def check_origin(self, origin: str) -> bool:
            host = self.request.headers.get("Host", "")
            ok = urlsplit(origin).netloc == host
            if not ok:
                ui._refuse(self, f"origin {origin!r} is not {host!r}")
            return ok

        def get_compression_options(self) -> None:
            return None

        def open(self, *args: Any) -> None:
            self.client = _Client(self)
            ui._clients.add(self.client)
            self.set_nodelay(True)
            log.info("dashboard: page opened from %s", self.request.remote_ip)
            ui._work.submit(ui._refreshGraph)

        async def on_message(self, message: Any) -> None:
            if self.client is not None:
                await ui._handle(self.client, message)

        def on_close(self) -> None:
            if self.client is not None:
                ui._clients.discard(self.client)
                log.info("dashboard: page closed (%s)", self.request.remote_ip)

    return tornado.web.Application(
        [
            (r"/", Index),
            (r"/ws", Socket),
            (r"/favicon\.ico", NoIcon),
            (r"/record\.(npz|csv)", Record),
            (r"/static/(.*)", Static, {"path": str(STATIC)}),
        ],
        websocket_max_message_size=MAX_MESSAGE,
        compress_response=False,
        xsrf_cookies=False,
    )
