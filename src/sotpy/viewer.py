"""A 3-D view of a robot in a web browser, refreshed from the control loop (meshcat).

::

    import example_robot_data
    from sotpy.viewer import RobotViewer

    r = example_robot_data.load("talos")
    viewer = RobotViewer("viewer", r.model, r.visual_model, period=20)
    plug(device.state, viewer.state)
    device.after.addSignal(viewer.display)
    print(viewer.url())  # open it in a browser
    ...
    viewer.close()  # stops the sender thread and the meshcat server

:class:`RobotViewer` draws a Pinocchio model with ``pinocchio.visualize.MeshcatVisualizer``
in a meshcat server process that it starts (and stops with :meth:`RobotViewer.close`).

**The control loop is never made to wait for the viewer.** Reading the ``display`` output
(every ``period`` ticks) checks the configuration, copies it and hands it to a
background daemon thread (about 6 us); that thread sends the latest configuration to
meshcat (``viz.display(q)``: forward kinematics, then one ``set_transform`` message per
geometry over ZeroMQ). While it is busy, newer configurations replace the pending one
(the intermediate ones are dropped and counted). What the loop may still feel is the
sender's CPU time through Python's GIL: the messages are encoded with numpy (the same
bytes as Pinocchio's pure-Python msgpack path, in 1.4 ms of CPU per Talos frame instead
of 6.4 ms). ``docs/viewer.md`` gives the figures measured.

Nothing waits forever: the server must print its addresses within ``timeout`` seconds,
every ZeroMQ exchange times out, and a failure raises :class:`~sotpy.errors.SotpyError`
naming the entity (at creation), or warns once and stops sending (in the loop: a dead
viewer must not stop a controller).

:meth:`RobotViewer.snapshot` renders the page in headless Chromium (``chromium`` on the
PATH, e.g. installed by ``tools/install-browser.sh``) and saves a PNG, for machines
without a display.
"""

from __future__ import annotations

import base64
import contextlib
import fcntl
import json
import math
import os
import re
import select
import shutil
import signal
import subprocess
import sys
import tempfile
import threading
import time
import warnings
import weakref
import webbrowser
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pinocchio as pin

from .errors import EntityError, SignalTypeError, SotpyError, SotpyWarning
from .graph import INT, VECTOR, Entity, Input, Output, command

__all__ = ["RobotViewer", "findChromium"]

# meshcat's server (``python -m meshcat.servers.zmqserver``, which prints ``zmq_url=...``
# then ``web_url=...``), with a watchdog thread that ends it when the process that
# started it is gone: a viewer whose Python was killed leaves no server behind.
_SERVER_MAIN = """
import os, sys, threading, time
parent = os.getppid()
def watchdog():
    while os.getppid() == parent:
        time.sleep(0.5)
    os._exit(0)
threading.Thread(target=watchdog, daemon=True).start()
import warnings
warnings.simplefilter("ignore", DeprecationWarning)
from meshcat.servers.zmqserver import main
sys.argv = ["meshcat-server"]
main()
"""
#: The command that starts a meshcat server.
_SERVER_COMMAND = [sys.executable, "-u", "-c", _SERVER_MAIN]
#: meshcat's default perspective camera: vertical field of view, degrees.
_FOV_DEGREES = 75.0
#: Where :meth:`RobotViewer.frameRobot` puts the camera from the robot's centre (world
#: axes; x forward, y left, z up): in front, a little to the left and above.
_CAMERA_DIRECTION = (1.0, 0.45, 0.35)
#: Repetitions of a repeated animation (three.js plays a finite number).
_REPEAT = 1_000_000


def _visualBox(
    model: pin.Model, visual: pin.GeometryModel, q: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """The world axis-aligned box (lower, upper corners, m) around the visual
    geometries at ``q``: each geometry's local box (scaled as drawn) at its placement;
    a geometry without a box counts as its origin. The origin alone if there is none."""
    data = model.createData()
    geometry_data = pin.GeometryData(visual)
    pin.forwardKinematics(model, data, q)
    pin.updateGeometryPlacements(model, data, visual, geometry_data)
    lo, hi = np.full(3, np.inf), np.full(3, -np.inf)
    unit = np.array([[x, y, z] for x in (0, 1) for y in (0, 1) for z in (0, 1)], dtype=float)
    for obj, M in zip(visual.geometryObjects, geometry_data.oMg, strict=True):
        try:
            obj.geometry.computeLocalAABB()
            box = obj.geometry.aabb_local
            scale = np.asarray(obj.meshScale, dtype=float)
            a, b = np.asarray(box.min_) * scale, np.asarray(box.max_) * scale
        except (AttributeError, RuntimeError, TypeError):
            a = b = np.zeros(3)
        if not (np.isfinite(a).all() and np.isfinite(b).all()):
            a = b = np.zeros(3)
        corners = a + unit * (b - a)
        world = corners @ M.rotation.T + M.translation
        lo, hi = np.minimum(lo, world.min(axis=0)), np.maximum(hi, world.max(axis=0))
    if not np.isfinite(lo).all():
        return np.zeros(3), np.zeros(3)
    return lo, hi


# ---------------------------------------------------------------------------------------
# The meshcat server process and the ZeroMQ client
# ---------------------------------------------------------------------------------------
class _Server:
    """A meshcat server subprocess, started with a deadline, stopped by :meth:`stop`.

    Its output goes to a log file (never to a pipe nobody reads, which would block the
    server once full); the addresses are read from that file.
    """

    def __init__(self, who: str, timeout: float) -> None:
        self.proc: subprocess.Popen[bytes] | None = None
        self._dir = tempfile.mkdtemp(prefix="sotpy-meshcat-")
        self.log = Path(self._dir) / "server.log"
        with open(self.log, "wb") as log:
            try:
                self.proc = subprocess.Popen(
                    _SERVER_COMMAND,
                    stdin=subprocess.DEVNULL,
                    stdout=log,
                    stderr=subprocess.STDOUT,
                    start_new_session=True,
                )
            except OSError as exc:
                self.stop()
                raise SotpyError(
                    f"{who}: cannot start the meshcat server ({_SERVER_COMMAND[0]}): {exc}"
                ) from exc
        deadline = time.monotonic() + timeout
        while True:
            text = self.log.read_text(errors="replace")
            zmq_url = re.search(r"^zmq_url=(\S+)$", text, re.MULTILINE)
            web_url = re.search(r"^web_url=(\S+)$", text, re.MULTILINE)
            if zmq_url and web_url:
                self.zmq_url, self.web_url = zmq_url.group(1), web_url.group(1)
                return
            code = self.proc.poll()
            if code is not None:
                self.stop()
                raise SotpyError(
                    f"{who}: the meshcat server exited with code {code} before giving its "
                    f"address; its output:\n{_tail(text)}"
                )
            if time.monotonic() > deadline:
                self.stop()
                raise SotpyError(
                    f"{who}: the meshcat server did not give its address within {timeout:g} s "
                    f"(stopped it); its output:\n{_tail(text)}"
                )
            time.sleep(0.02)

    def stop(self) -> None:
        """Terminate the server (SIGTERM, then SIGKILL after 5 s) and remove its log."""
        proc = self.proc
        if proc is not None and proc.poll() is None:
            proc.terminate()
            try:
                proc.wait(5.0)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait(5.0)
        shutil.rmtree(self._dir, ignore_errors=True)


def _tail(text: str, lines: int = 20) -> str:
    return "\n".join(text.strip().splitlines()[-lines:]) or "(nothing)"


def _meshcat() -> Any:
    """The meshcat module, imported without its pyzmq deprecation warning."""
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", "zmq.eventloop.ioloop", DeprecationWarning)
        import meshcat
    return meshcat


def _window(server: _Server, timeout: float) -> Any:
    """A meshcat ``ViewerWindow`` connected to ``server`` whose exchanges time out."""
    import zmq

    meshcat = _meshcat()

    class Window(meshcat.visualizer.ViewerWindow):
        """meshcat's client window, without a second server start, print or blocking
        ``recv``: each exchange raises ``zmq.Again`` after ``timeout``."""

        def __init__(self) -> None:  # no super().__init__: it starts its own server
            self.server_proc = server.proc
            self.zmq_url = server.zmq_url
            self.web_url = server.web_url
            self.zmq_socket = None
            self.connect_zmq()

        def connect_zmq(self) -> None:
            if self.zmq_socket is not None:
                self.zmq_socket.close(linger=0)
            sock = self.context.socket(zmq.REQ)
            ms = max(1, int(timeout * 1000))
            sock.setsockopt(zmq.RCVTIMEO, ms)
            sock.setsockopt(zmq.SNDTIMEO, ms)
            sock.setsockopt(zmq.LINGER, 0)
            sock.connect(self.zmq_url)
            self.zmq_socket = sock

        def close(self) -> None:  # meshcat's Visualizer.close calls it; 0.3.2 lacks it
            if self.zmq_socket is not None:
                self.zmq_socket.close(linger=0)
                self.zmq_socket = None

    return Window()


_VISUALIZER: Any = None


def _visualizer_class() -> Any:
    """``pinocchio.visualize.MeshcatVisualizer`` with a faster ``updatePlacements``."""
    global _VISUALIZER
    if _VISUALIZER is not None:
        return _VISUALIZER
    _meshcat()
    import umsgpack
    from pinocchio.visualize import MeshcatVisualizer

    # a float64 packed as msgpack does it: the 0xcb tag, then big-endian IEEE 754
    packed_float = np.dtype([("tag", "u1"), ("value", ">f8")])

    class FastMeshcatVisualizer(MeshcatVisualizer):
        """Sends the same ``set_transform`` messages as Pinocchio's, byte for byte
        (``tests/test_viewer.py`` compares them), encoded at once for all geometries:
        the msgpack prefix of each message is computed once, the 16 floats of every
        matrix by one numpy operation. Pinocchio's loop, with its pure-Python msgpack,
        took 6.4 ms of CPU per Talos frame (52 visuals), held under the GIL the control
        loop needs; this one 1.4 ms. Planes, half-spaces and static objects go through
        Pinocchio's loop."""

        def _fastPlan(self, geometry_type: Any) -> Any:
            plans = self.__dict__.setdefault("_sotpy_plans", {})
            if geometry_type not in plans:
                visual = geometry_type == pin.GeometryType.VISUAL
                geom_model = self.visual_model if visual else self.collision_model
                names, prefixes, scales, special = [], [], [], False
                for obj in geom_model.geometryObjects:
                    node = self.viewer[self.getViewerNodeName(obj, geometry_type)].path
                    names.append(node.lower().encode("utf-8"))
                    head = umsgpack.packb(
                        {"type": "set_transform", "path": node.lower(), "matrix": []}
                    )
                    prefixes.append(head[:-1] + b"\xdc\x00\x10")  # array of 16
                    scales.append(np.asarray(obj.meshScale, dtype=np.float64).ravel())
                    special |= type(obj.geometry).__name__ in ("Plane", "Halfspace")
                n = len(names)
                buffer = np.empty((n, 16), dtype=packed_float)
                buffer["tag"] = 0xCB
                plans[geometry_type] = (
                    None if special else (names, prefixes, np.array(scales).reshape(n, 3), buffer)
                )
            return plans[geometry_type]

        def updatePlacements(self, geometry_type: Any) -> None:
            plan = self._fastPlan(geometry_type)
            if plan is None or self.static_objects:  # planes, static objects: Pinocchio's
                return super().updatePlacements(geometry_type)
            names, prefixes, scales, buffer = plan
            if not names:
                return None
            visual = geometry_type == pin.GeometryType.VISUAL
            geom_model = self.visual_model if visual else self.collision_model
            geom_data = self.visual_data if visual else self.collision_data
            pin.updateGeometryPlacements(self.model, self.data, geom_model, geom_data)
            T = np.array([M.homogeneous for M in geom_data.oMg])  # (n, 4, 4)
            T[:, :, :3] *= scales[:, None, :]  # T diag(scale, 1), as Pinocchio's T @ S,
            T += 0.0  # whose sums also turn -0.0 into 0.0
            buffer["value"] = T.transpose(0, 2, 1).reshape(len(names), 16)  # column-major
            rows = buffer.tobytes()
            size = 16 * packed_float.itemsize
            sock = self.viewer.window.zmq_socket
            for i, (name, prefix) in enumerate(zip(names, prefixes, strict=True)):
                sock.send_multipart(
                    [b"set_transform", name, prefix + rows[i * size : (i + 1) * size]]
                )
                sock.recv()
            return None

    _VISUALIZER = FastMeshcatVisualizer
    return _VISUALIZER


# ---------------------------------------------------------------------------------------
# The sender thread
# ---------------------------------------------------------------------------------------
class _Sender:
    """A daemon thread that sends the latest submitted configuration.

    :meth:`submit` (the loop side) never waits for a send: it replaces the pending
    configuration, if any (counted in ``dropped``), and wakes the thread.
    """

    def __init__(self, who: str, send: Callable[[np.ndarray], None]) -> None:
        self._send = send
        self._cond = threading.Condition(threading.Lock())
        self._pending: np.ndarray | None = None
        self._busy = False
        self._stop = False
        self.submitted = 0
        self.sent = 0
        self.dropped = 0
        self.error: BaseException | None = None
        self.thread = threading.Thread(target=self._run, name=f"{who} sender", daemon=True)
        self.thread.start()

    def submit(self, q: np.ndarray) -> None:
        """Hand ``q`` (a copy the caller will not touch again) to the thread."""
        with self._cond:
            if self._pending is not None:
                self.dropped += 1
            self._pending = q
            self.submitted += 1
            self._cond.notify()

    def _run(self) -> None:
        cond = self._cond
        while True:
            with cond:
                while self._pending is None and not self._stop:
                    cond.wait()
                if self._stop:
                    return
                q, self._pending = self._pending, None
                self._busy = True
            try:
                self._send(q)
            except BaseException as exc:  # reported by the entity, in the loop's thread
                with cond:
                    self.error = exc
                    self._busy = False
                    self._stop = True
                    cond.notify_all()
                return
            with cond:
                self.sent += 1
                self._busy = False
                cond.notify_all()

    def flush(self, timeout: float) -> bool:
        """Wait until nothing is pending nor being sent; false on timeout or error."""
        deadline = time.monotonic() + timeout
        with self._cond:
            while (self._pending is not None or self._busy) and self.error is None:
                left = deadline - time.monotonic()
                if left <= 0 or self._stop:
                    return False
                self._cond.wait(left)
            return self.error is None

    def stop(self, timeout: float) -> None:
        """Stop the thread (after the send in progress, if any); the pending
        configuration is discarded."""
        with self._cond:
            self._stop = True
            self._cond.notify_all()
        if self.thread is not threading.current_thread():
            self.thread.join(timeout)


# ---------------------------------------------------------------------------------------
# The entity
# ---------------------------------------------------------------------------------------
class RobotViewer(Entity):
    """A 3-D view of a robot in a web browser (meshcat), refreshed every ``period`` ticks.

    ``RobotViewer(name, model, visual_model, collision_model=None, period=20,
    open=False, timeout=20.0)``: ``model`` is a ``pinocchio.Model``, ``visual_model``
    (and ``collision_model``, drawn hidden) a ``pinocchio.GeometryModel``. The robot is
    drawn at the neutral configuration until ``state`` is read.

    Plug ``state`` to the device's configuration and hook ``display`` on the device's
    ``after`` list: ``device.after.addSignal(viewer.display)``. Open :meth:`url` in a
    browser. Reading ``display`` hands a copy of ``q`` to a background thread, which
    sends it to meshcat; the loop never waits for the browser nor the server.
    """

    state = Input(VECTOR, doc="robot configuration q (Pinocchio, size nq; m and rad)")

    @Output(INT, deps=("state",), period=20)
    def display(self, q: np.ndarray) -> int:
        """Number of configurations handed to the sender so far (each sent, or dropped
        when a newer one replaced it before the sender was free)."""
        sender = self._sender
        if sender is None:  # closed
            return self._count
        if not isinstance(q, np.ndarray) or q.shape != (self._nq,):
            raise SignalTypeError(
                f"{self.state.name}: expected a configuration of size nq={self._nq} for "
                f"model {self._modelName!r}, got {_shape(q)}"
            )
        if not np.isfinite(q).all():
            raise SignalTypeError(
                f"{self.state.name}: the configuration is not finite: {q!r} (nothing sent)"
            )
        if sender.error is not None:
            if not self._warned:
                self._warned = True
                warnings.warn(
                    f"{self.className}({self.name}): the viewer stopped sending after "
                    f"{sender.sent} frames: {sender.error!r}; the control loop goes on",
                    SotpyWarning,
                    stacklevel=2,
                )
            return self._count
        q = np.array(q, dtype=np.float64)
        sender.submit(q)
        self._lastQ = q
        self._count += 1
        return self._count

    def __init__(
        self,
        name: str,
        model: pin.Model,
        visual_model: pin.GeometryModel,
        collision_model: pin.GeometryModel | None = None,
        period: int = 20,
        open: bool = False,
        *,
        timeout: float = 20.0,
    ) -> None:
        who = f"{self.className}({name})"
        self._sender: _Sender | None = None  # None once closed
        self._stats: _Sender | None = None  # kept after close, for the counts
        self._server: _Server | None = None
        self._window: Any = None
        self._count = 0
        self._warned = False
        self._lastQ: np.ndarray | None = None
        self._centre = np.zeros(3)
        self._cameraPosition = np.array([3.0, 0.0, 1.0])  # meshcat's default
        self._io = threading.Lock()  # one ZeroMQ exchange at a time (REQ socket)
        if not isinstance(model, pin.Model):
            raise EntityError(f"{who}: model must be a pinocchio.Model, got {type(model)}")
        for what, geometry in (
            ("visual_model", visual_model),
            ("collision_model", collision_model),
        ):
            if geometry is not None and not isinstance(geometry, pin.GeometryModel):
                raise EntityError(
                    f"{who}: {what} must be a pinocchio.GeometryModel, got {type(geometry)}"
                )
        if visual_model is None:
            raise EntityError(f"{who}: visual_model is required (a pinocchio.GeometryModel)")
        if isinstance(timeout, bool) or not isinstance(timeout, (int, float)) or not timeout > 0:
            raise EntityError(f"{who}: timeout must be a positive number of s, got {timeout!r}")
        self.display.setPeriod(period)
        self._nq = model.nq
        self._model = model
        self._visual = visual_model
        self._modelName = model.name
        self._timeout = float(timeout)
        self._meshes = len(visual_model.geometryObjects) + (
            0 if collision_model is None else len(collision_model.geometryObjects)
        )

        meshcat = _meshcat()
        visualizer = _visualizer_class()

        self._server = _Server(who, self._timeout)
        # stop the server at exit if close() is never called (holds no reference to self)
        self._finalizer = weakref.finalize(self, _shutdown, None, self._server)
        try:
            self._window = _window(self._server, self._timeout)
            self._viz = visualizer(model, collision_model, visual_model)
            with warnings.catch_warnings():  # "no get_image" in older meshcat: irrelevant
                warnings.filterwarnings("ignore", message=".*get_image.*")
                self._viz.initViewer(viewer=meshcat.Visualizer(window=self._window))
            self._viz.loadViewerModel()
            self._viz.display(pin.neutral(model))
        except Exception as exc:
            self._finalizer()
            raise SotpyError(f"{who}: cannot load the model into meshcat: {exc!r}") from exc
        self._sender = self._stats = _Sender(who, self._sendFrame)
        self._finalizer.detach()
        self._finalizer = weakref.finalize(self, _shutdown, self._sender, self._server)
        if open:
            self.openBrowser()

    # -- sending ------------------------------------------------------------------------
    def _sendFrame(self, q: np.ndarray) -> None:
        """Runs in the sender thread."""
        with self._io:
            self._viz.display(q)

    @property
    def viz(self) -> Any:
        """The ``pinocchio.visualize.MeshcatVisualizer``. Its calls share one ZeroMQ socket
        with the sender thread: make them inside ``with viewer.lock:``."""
        return self._viz

    @property
    def lock(self) -> threading.Lock:
        """Held while a message is exchanged with the meshcat server."""
        return self._io

    @property
    def sent(self) -> int:
        """Configurations sent to meshcat so far."""
        return 0 if self._stats is None else self._stats.sent

    @property
    def dropped(self) -> int:
        """Configurations replaced by a newer one before the sender was free."""
        return 0 if self._stats is None else self._stats.dropped

    @property
    def error(self) -> BaseException | None:
        """The exception that stopped the sender, if any."""
        return None if self._stats is None else self._stats.error

    @property
    def serverProcess(self) -> subprocess.Popen[bytes] | None:
        """The meshcat server process (None once closed)."""
        return None if self._server is None else self._server.proc

    @property
    def senderThread(self) -> threading.Thread | None:
        """The sender thread (None once closed)."""
        return None if self._sender is None else self._sender.thread

    # -- commands -------------------------------------------------------------------------
    @command
    def url(self) -> str:
        """The address of the page that shows the robot (open it in a browser)."""
        self._checkOpen("url")
        return self._server.web_url  # type: ignore[union-attr]

    @command
    def setPeriod(self, k: int) -> None:
        """Refresh the view every ``k`` ticks (``k`` >= 1; the signal period of
        ``display``)."""
        self.display.setPeriod(k)

    @command
    def getPeriod(self) -> int:
        """The refresh period of the view, in ticks."""
        return self.display.period

    @command
    def flush(self, timeout: float = 5.0) -> bool:
        """Wait until the latest configuration handed over has been sent (at most
        ``timeout`` s); false on timeout, if the sender failed or the viewer is closed."""
        if self._sender is None:
            return False
        return self._sender.flush(timeout)

    @command
    def openBrowser(self) -> bool:
        """Open :meth:`url` in the desktop's web browser; false (with a warning giving
        the address) when there is no display or no browser."""
        url = self.url()
        graphical = sys.platform in ("darwin", "win32") or bool(
            os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")
        )
        # without a display, webbrowser would run a text browser in this terminal
        opened = graphical and webbrowser.open(url, new=2)
        if not opened:
            warnings.warn(
                f"{self.className}({self.name}): cannot open a browser here; open {url}",
                SotpyWarning,
                stacklevel=2,
            )
        return bool(opened)

    @command
    def setCameraPosition(self, position: np.ndarray) -> None:
        """Place the browser's camera at ``position`` (m, world axes) from the point it
        looks at: the world origin (meshcat 0.3 cannot move that point), or the robot's
        centre after :meth:`frameRobot`. The user can still turn it with the mouse.
        meshcat's default is (3, 0, 1)."""
        self._checkOpen("setCameraPosition")
        if position.shape != (3,):
            raise SotpyError(
                f"{self.className}({self.name}).setCameraPosition: position must be a "
                f"3-vector, got {_shape(position)}"
            )
        x, y, z = (float(c) for c in position)
        with self._io:  # meshcat's camera lives in a y-up frame: (x, y, z) -> (x, z, -y)
            self._viz.viewer["/Cameras/default/rotated/<object>"].set_property(
                "position", [x, z, -y]
            )

    @command
    def frameRobot(self, q: np.ndarray | None = None, fill: float = 0.8) -> np.ndarray:
        """Point the browser's camera at the robot at configuration ``q`` (default: the
        last one handed over, else the neutral one), so that it fills about ``fill`` of
        the view's height; returns the centre of the robot's bounding box (world, m).

        meshcat 0.3's camera always looks at the scene's origin, so the scene is moved
        instead: the robot, the floor grid and the world axes are translated by minus
        that centre (the robot stands on the grid as before), and the camera is put in
        front of the robot, a little to its left and above, at the distance where the
        box's bounding sphere spans ``fill`` of meshcat's 75 degree field of view.
        The box is that of the visual geometries (their meshes' axis-aligned boxes, at
        their placements in ``q``). The user can still turn and zoom with the mouse."""
        self._checkOpen("frameRobot")
        who = f"{self.className}({self.name}).frameRobot"
        if q is None:
            q = self._lastQ if self._lastQ is not None else pin.neutral(self._model)
        q = np.asarray(q, dtype=np.float64)
        if q.shape != (self._nq,) or not np.isfinite(q).all():
            raise SotpyError(f"{who}: q must be a finite configuration of size nq={self._nq}")
        if not (isinstance(fill, (int, float)) and 0.05 <= fill <= 1.0):
            raise SotpyError(f"{who}: fill must be a fraction in [0.05, 1], got {fill!r}")
        lo, hi = _visualBox(self._model, self._visual, q)
        centre = 0.5 * (lo + hi)
        radius = max(0.5 * float(np.linalg.norm(hi - lo)), 0.05)
        distance = radius / math.tan(math.radians(0.5 * _FOV_DEGREES * fill))
        direction = np.array(_CAMERA_DIRECTION) / np.linalg.norm(_CAMERA_DIRECTION)
        shift = pin.SE3(np.eye(3), -centre).homogeneous
        viewer = self._viz.viewer
        with self._io:
            for node in (self._viz.viewerRootNodeName, "/Grid", "/Axes"):
                viewer[node].set_transform(shift)
        self._centre = centre
        self._cameraPosition = distance * direction
        self.setCameraPosition(self._cameraPosition)
        return centre

    @command
    def animate(self, configurations: np.ndarray, dt: float, repeat: bool = True) -> float:
        """Send the motion ``configurations`` (k x nq, one row every ``dt`` seconds) to
        the page, which plays it at real time (a meshcat animation: the page's
        "Animations" menu pauses, resets and scrubs it, and ``timeScale`` slows it
        down); ``repeat``: again and again, else once. A page opened later gets it too.
        Returns the motion's duration, ``(k - 1) dt`` s.

        The placements are computed here (forward kinematics of each row, as
        ``display`` does) and sent once; nothing is sent while the page plays."""
        self._checkOpen("animate")
        who = f"{self.className}({self.name}).animate"
        qs = np.asarray(configurations, dtype=np.float64)
        if qs.ndim != 2 or qs.shape[1] != self._nq or len(qs) < 1 or not np.isfinite(qs).all():
            raise SotpyError(
                f"{who}: configurations must be finite, k x nq = k x {self._nq}, got "
                f"{_shape(configurations)}"
            )
        if not (isinstance(dt, (int, float)) and math.isfinite(dt) and dt > 0):
            raise SotpyError(f"{who}: dt must be a finite number of s > 0, got {dt!r}")
        animation = _meshcat().animation.Animation(default_framerate=1.0 / dt)
        viz = self._viz
        model, data = self._model, self._model.createData()
        visual = self._visual
        geometry_data = pin.GeometryData(visual)
        root = viz.viewer
        nodes = [viz.getViewerNodeName(o, pin.GeometryType.VISUAL) for o in visual.geometryObjects]
        for k, q in enumerate(qs):
            pin.forwardKinematics(model, data, q)
            pin.updateGeometryPlacements(model, data, visual, geometry_data)
            with animation.at_frame(root, k) as frame:
                for node, M in zip(nodes, geometry_data.oMg, strict=True):
                    frame[node].set_transform(M.homogeneous)
        with self._io:
            root.set_animation(animation, play=True, repetitions=_REPEAT if repeat else 1)
        self._lastQ = qs[-1].copy()
        return (len(qs) - 1) * float(dt)

    @command
    def pages(self) -> int:
        """How many browser pages show the viewer now (meshcat's server logs each page
        that connects and leaves)."""
        opened, closed = self._pageEvents()
        return opened - closed

    def _pageEvents(self) -> tuple[int, int]:
        """(pages that connected, pages that left) since the server started."""
        if self._server is None:
            return 0, 0
        try:
            text = self._server.log.read_text(errors="replace")
        except OSError:
            return 0, 0
        opened = len(re.findall(r"^opened:", text, re.MULTILINE))
        closed = len(re.findall(r"^closed:", text, re.MULTILINE))
        return opened, closed

    @command
    def waitPages(self, timeout: float | None = None, poll: float = 0.2) -> bool:
        """Wait until a page has been opened and every page opened is closed again, at
        most ``timeout`` s (None: no limit); true when that happened, false on timeout.
        Ctrl-C interrupts it (KeyboardInterrupt)."""
        self._checkOpen("waitPages")
        deadline = None if timeout is None else time.monotonic() + timeout
        while True:
            opened, closed = self._pageEvents()
            if opened and closed >= opened:
                return True
            if deadline is not None and time.monotonic() >= deadline:
                return False
            wait = poll if deadline is None else min(poll, max(0.0, deadline - time.monotonic()))
            time.sleep(wait)

    @command
    def snapshot(
        self, path: str | os.PathLike, width: int = 800, height: int = 600, timeout: float = 60.0
    ) -> str:
        """Render the page in headless Chromium and save it as a PNG at ``path``
        (``width`` x ``height`` pixels); returns the path.

        Waits (at most ``timeout`` s) until the configuration handed over last is sent
        and the browser has received every mesh of the model.
        Raises SotpyError if Chromium is missing or the page does not load in time.
        """
        self._checkOpen("snapshot")
        who = f"{self.className}({self.name}).snapshot"
        if width < 1 or height < 1:
            raise SotpyError(f"{who}: width and height must be positive, got {width}x{height}")
        deadline = time.monotonic() + timeout
        if not self.flush(timeout):
            raise SotpyError(f"{who}: the latest configuration was not sent: {self.error!r}")
        png, _ = _renderPage(
            who, self.url(), width, height, self._meshes, deadline - time.monotonic()
        )
        Path(path).write_bytes(png)
        return str(path)

    @command
    def close(self) -> None:
        """Stop the sender thread and the meshcat server process (the page goes dark).
        The ``display`` output keeps its value and sends nothing more. Idempotent."""
        sender, self._sender = self._sender, None
        server, self._server = self._server, None
        window, self._window = self._window, None
        finalizer = getattr(self, "_finalizer", None)
        if finalizer is not None:
            finalizer.detach()
        if sender is not None:
            sender.stop(self._timeout)  # after the send in progress (ms)
        if server is not None:
            server.stop()
        if window is not None:
            with contextlib.suppress(Exception):
                window.close()

    @command
    def isOpen(self) -> bool:
        """Whether the viewer runs (not closed)."""
        return self._server is not None

    def _checkOpen(self, cmd: str) -> None:
        if self._server is None:
            raise SotpyError(f"{self.className}({self.name}).{cmd}: the viewer is closed")

    def onRemove(self) -> None:
        # the entity leaves the pool (pool.remove, pool.clear, failed construction):
        # nothing of it may keep running
        if "_io" in self.__dict__:
            self.close()


def _shutdown(sender: _Sender | None, server: _Server) -> None:
    """Stop the thread and the server of a viewer nobody closed (at exit, or collected)."""
    if sender is not None:
        sender.stop(1.0)
    server.stop()


def _shape(v: Any) -> str:
    shape = getattr(v, "shape", None)
    return f"shape {shape}" if shape is not None else f"{type(v).__name__} {v!r}"


# ---------------------------------------------------------------------------------------
# Headless Chromium
# ---------------------------------------------------------------------------------------
def findChromium() -> str | None:
    """The path of a Chromium (or Chrome) executable on the PATH, or None."""
    for name in ("chromium", "chromium-browser", "google-chrome", "google-chrome-stable"):
        found = shutil.which(name)
        if found:
            return found
    return None


#: Flags of every Chromium run: headless, no sandbox (root in containers), no GPU (WebGL
#: through SwiftShader), nothing fetched from the network but the page.
CHROMIUM_FLAGS = (
    "--headless",
    "--no-sandbox",
    "--disable-gpu",
    "--enable-unsafe-swiftshader",
    "--disable-quic",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--disable-dev-shm-usage",
)

# number of meshes in the three.js scene of meshcat's page (-1 before it is set up)
_COUNT_MESHES = (
    "(() => { try { let n = 0; viewer.scene.traverse(o => { if (o.isMesh) n++; });"
    " return n; } catch (e) { return -1; } })()"
)
# runs Chromium with the pipe ends given as arguments on fds 3 (commands) and 4 (replies)
_TRAMPOLINE = (
    "import os, sys; a, b = int(sys.argv[1]), int(sys.argv[2]); "
    "os.dup2(a, 3); os.dup2(b, 4); os.close(a); os.close(b); "
    "os.execv(sys.argv[3], sys.argv[3:])"
)
_TWO_FRAMES = "new Promise(r => requestAnimationFrame(() => requestAnimationFrame(() => r(1))))"


def _renderPage(
    who: str,
    url: str,
    width: int,
    height: int,
    meshes: int,
    timeout: float,
    probe: str | None = None,
) -> tuple[bytes, Any]:
    """Load ``url`` in headless Chromium, wait until its scene holds ``meshes`` meshes,
    and return a ``width`` x ``height`` PNG screenshot, with the value of the JavaScript
    expression ``probe`` evaluated in the page just before it (None without one).

    Chromium is driven through the DevTools protocol over a pipe (``--remote-debugging-
    pipe``: fd 3 in, fd 4 out, messages separated by NUL): a ``--screenshot`` run cannot
    wait for the scene, which meshcat streams over a websocket after the page loaded
    (measured: a ``--virtual-time-budget=8000`` shot showed the legs only, or nothing).
    """
    exe = findChromium()
    if exe is None:
        raise SotpyError(
            f"{who}: no Chromium found (looked for 'chromium', 'chromium-browser' and "
            "'google-chrome' on the PATH); install it with 'bash tools/install-browser.sh'"
        )
    deadline = time.monotonic() + timeout
    profile = tempfile.mkdtemp(prefix="sotpy-chromium-")
    # the child's pipe ends above fd 9, so that moving them to 3 and 4 clobbers neither
    to_r, to_w = os.pipe()
    from_r, from_w = os.pipe()
    child_in = fcntl.fcntl(to_r, fcntl.F_DUPFD, 10)
    child_out = fcntl.fcntl(from_w, fcntl.F_DUPFD, 10)
    for fd in (to_r, from_w):
        os.close(fd)
    stderr = open(Path(profile) / "stderr.log", "wb")  # noqa: SIM115 - closed below
    args = [
        *CHROMIUM_FLAGS,
        f"--user-data-dir={profile}",
        f"--window-size={width},{height}",
        "--remote-debugging-pipe",
        "about:blank",
    ]
    proc = None
    try:
        proc = subprocess.Popen(
            [sys.executable, "-c", _TRAMPOLINE, str(child_in), str(child_out), exe, *args],
            stdin=subprocess.DEVNULL,
            stdout=stderr,
            stderr=stderr,
            pass_fds=(child_in, child_out),
            start_new_session=True,
        )
        os.close(child_in)
        os.close(child_out)
        child_in = child_out = -1
        cdp = _Devtools(who, to_w, from_r, deadline)
        target = cdp.call("Target.createTarget", {"url": "about:blank"})["targetId"]
        session = cdp.call("Target.attachToTarget", {"targetId": target, "flatten": True})[
            "sessionId"
        ]
        cdp.call(
            "Emulation.setDeviceMetricsOverride",
            {"width": width, "height": height, "deviceScaleFactor": 1, "mobile": False},
            session,
        )
        cdp.call("Page.navigate", {"url": url}, session)
        count = -1
        while True:
            reply = cdp.call(
                "Runtime.evaluate", {"expression": _COUNT_MESHES, "returnByValue": True}, session
            )
            count = reply.get("result", {}).get("value", -1)
            if count >= meshes:
                break
            if time.monotonic() > deadline:
                raise SotpyError(
                    f"{who}: the page {url} showed {max(count, 0)} of the {meshes} meshes "
                    f"within {timeout:.0f} s"
                )
            time.sleep(0.2)
        cdp.call("Runtime.evaluate", {"expression": _TWO_FRAMES, "awaitPromise": True}, session)
        value = None
        if probe is not None:
            reply = cdp.call(
                "Runtime.evaluate", {"expression": probe, "returnByValue": True}, session
            )
            value = reply.get("result", {}).get("value")
        data = cdp.call("Page.captureScreenshot", {"format": "png"}, session)["data"]
        with contextlib.suppress(SotpyError):
            cdp.call("Browser.close")
        return base64.b64decode(data), value
    except (OSError, ValueError) as exc:
        raise SotpyError(f"{who}: Chromium failed: {exc!r}{_log(profile)}") from exc
    except SotpyError as exc:
        raise SotpyError(f"{exc}{_log(profile)}") from None
    finally:
        for fd in (to_w, from_r, child_in, child_out):
            if fd >= 0:
                with contextlib.suppress(OSError):
                    os.close(fd)
        if proc is not None:
            _endSession(proc)
        stderr.close()
        shutil.rmtree(profile, ignore_errors=True)


def _endSession(proc: subprocess.Popen[bytes], grace: float = 10.0) -> None:
    """Wait (at most ``grace`` s) for the Chromium started here to exit, then kill what
    is left of its session (its helper processes), then reap it. Its pid is not reaped
    before the kill, so the process group id cannot have been reused."""
    deadline = time.monotonic() + grace
    with contextlib.suppress(ChildProcessError):
        while time.monotonic() < deadline:
            if os.waitid(os.P_PID, proc.pid, os.WEXITED | os.WNOWAIT | os.WNOHANG):
                break
            time.sleep(0.05)
    with contextlib.suppress(ProcessLookupError, PermissionError):
        os.killpg(proc.pid, signal.SIGKILL)
    proc.wait()


def _log(profile: str) -> str:
    try:
        text = (Path(profile) / "stderr.log").read_text(errors="replace")
    except OSError:
        return ""
    return f"\nChromium's output (end):\n{_tail(text, 10)}" if text.strip() else ""


class _Devtools:
    """A minimal client of Chromium's DevTools protocol over ``--remote-debugging-pipe``."""

    def __init__(self, who: str, out_fd: int, in_fd: int, deadline: float) -> None:
        self._who = who
        self._out = out_fd
        self._in = in_fd
        self._deadline = deadline
        self._buf = b""
        self._id = 0

    def call(self, method: str, params: dict[str, Any] | None = None, session: str = "") -> Any:
        """Send a command and return its result (raising SotpyError on error or timeout)."""
        self._id += 1
        msg: dict[str, Any] = {"id": self._id, "method": method, "params": params or {}}
        if session:
            msg["sessionId"] = session
        data = json.dumps(msg).encode() + b"\0"
        while data:
            data = data[os.write(self._out, data) :]
        while True:
            while b"\0" in self._buf:
                raw, self._buf = self._buf.split(b"\0", 1)
                reply = json.loads(raw)
                if reply.get("id") == self._id:
                    if "error" in reply:
                        raise SotpyError(f"{self._who}: Chromium: {method}: {reply['error']}")
                    return reply.get("result", {})
            left = self._deadline - time.monotonic()
            if left <= 0:
                raise SotpyError(f"{self._who}: Chromium did not answer {method} in time")
            ready, _, _ = select.select([self._in], [], [], left)
            if ready:
                chunk = os.read(self._in, 1 << 20)
                if not chunk:
                    raise SotpyError(f"{self._who}: Chromium exited (during {method})")
                self._buf += chunk
