"""The meshcat viewer (``sotpy.viewer.RobotViewer``): refresh every ``period`` ticks, a
sender thread that never makes the loop wait (latest configuration sent, the others
dropped), clean shutdown of the thread and the server process, clear errors, the cost
seen by the loop, and the page rendered by headless Chromium (Talos at half-sitting).

Every viewer is closed by the ``viewers`` fixture, so no server process survives a test.
"""

from __future__ import annotations

import os
import subprocess
import sys
import threading
import time
import urllib.error
import urllib.request
import warnings

import numpy as np
import pinocchio as pin
import pytest

import sotpy.viewer as viewer_module
from sotpy.errors import EntityError, SignalTypeError, SotpyError, SotpyWarning
from sotpy.graph import VECTOR, Entity, Output, PeriodicCall, plug, pool
from sotpy.viewer import RobotViewer


class ViewerTestSource(Entity):
    """Stands for a device: writes a configuration on ``state`` at each tick."""

    state = Output(VECTOR, doc="configuration q")


@pytest.fixture
def viewers():
    """Create viewers with ``viewers(name, model, visual, ...)``; all closed at the end."""
    made: list[RobotViewer] = []

    def make(*args, **kwargs) -> RobotViewer:
        v = RobotViewer(*args, **kwargs)
        made.append(v)
        return v

    yield make
    for v in made:
        proc = v.serverProcess
        v.close()
        assert proc is None or proc.poll() is not None


@pytest.fixture(scope="module")
def humanoid():
    """Pinocchio's sample humanoid (nq = 35) with primitive shapes: starts fast."""
    model = pin.buildSampleModelHumanoid()
    return model, pin.buildSampleGeometryModelHumanoid(model)


@pytest.fixture(scope="module")
def talos():
    example_robot_data = pytest.importorskip("example_robot_data")
    return example_robot_data.load("talos")


def record_display(viewer: RobotViewer, delay: float = 0.0, fail: bool = False) -> list:
    """Wrap ``viewer.viz.display`` (the real one still runs unless ``fail``): returns the
    list of (q, thread) it is called with."""
    calls: list = []
    real = viewer.viz.display

    def display(q=None):
        calls.append((np.array(q), threading.current_thread()))
        if fail:
            raise RuntimeError("boom: meshcat is gone")
        if delay:
            time.sleep(delay)
        real(q)

    viewer.viz.display = display
    return calls


def configuration(model: pin.Model, t: int) -> np.ndarray:
    """A distinct valid configuration per tick (joints after the free-flyer move)."""
    q = pin.neutral(model)
    q[7:] = 1e-3 * t * np.arange(1, model.nq - 6)
    return q


def due_ticks(ticks: range, period: int, last: int | None = None) -> list[int]:
    """The ticks at which an output of this period is recomputed, written out."""
    out = []
    for t in ticks:
        if last is None or t >= last + period:
            out.append(t)
            last = t
    return out


# ---------------------------------------------------------------------------------------
def test_display_refreshes_every_period_ticks(viewers, humanoid):
    model, geometry = humanoid
    v = viewers("viewer", model, geometry)  # period 20 by default
    assert v.getPeriod() == 20
    calls = record_display(v)
    src = ViewerTestSource("src")
    plug(src.state, v.state)
    after = PeriodicCall("src.after")
    after.addSignal(v.display)

    def run(ticks: range) -> None:
        for t in ticks:
            src.state.write(configuration(model, t), t)
            after.run(t)
            assert v.flush(5.0)  # each handed configuration is sent before the next tick

    run(range(1, 101))
    expected = due_ticks(range(1, 101), 20)
    assert expected == [1, 21, 41, 61, 81]
    assert v.display.value == 5
    v.setPeriod(7)
    run(range(101, 148))
    expected += due_ticks(range(101, 148), 7, last=expected[-1])
    assert v.display.value == len(expected) == 5 + 7  # then 101, 108, ..., 143
    assert v.sent == len(expected) and v.dropped == 0
    assert len(calls) == len(expected)
    for (q, thread), t in zip(calls, expected, strict=True):
        np.testing.assert_array_equal(q, configuration(model, t))
        assert thread is v.senderThread and thread is not threading.main_thread()
    # the lazy pull obeys the same period: nothing new before tick 143 + 7
    src.state.write(configuration(model, 149), 149)
    assert v.display(149) == len(expected)
    src.state.write(configuration(model, 150), 150)
    assert v.display(150) == len(expected) + 1
    # a state that did not change is not sent again
    assert v.display(157) == len(expected) + 1


class RecordingSocket:
    """Stands for the ZeroMQ socket: records the frames of each message, answers ok."""

    def __init__(self) -> None:
        self.messages: list[list[bytes]] = []

    def send_multipart(self, frames) -> None:
        self.messages.append([bytes(f) for f in frames])

    def recv(self) -> bytes:
        return b"ok"


def test_fast_placements_are_pinocchios_messages_byte_for_byte(viewers, humanoid):
    from pinocchio.visualize import MeshcatVisualizer

    model, geometry = humanoid
    geometry = geometry.copy()
    for k, obj in enumerate(geometry.geometryObjects):  # scaled meshes too
        obj.meshScale = np.array([1.0 + 0.1 * k, 0.5, 2.0])
    v = viewers("viewer", model, geometry)
    viz = v.viz
    assert isinstance(viz, MeshcatVisualizer)
    rng = np.random.default_rng(7)
    with v.lock:
        window = viz.viewer.window
        real = window.zmq_socket
        try:
            for _ in range(3):
                q = pin.integrate(model, pin.neutral(model), rng.normal(size=model.nv))
                pin.forwardKinematics(viz.model, viz.data, q)
                fast, reference = RecordingSocket(), RecordingSocket()
                window.zmq_socket = fast
                viz.updatePlacements(pin.GeometryType.VISUAL)
                window.zmq_socket = reference
                MeshcatVisualizer.updatePlacements(viz, pin.GeometryType.VISUAL)
                assert len(fast.messages) == len(geometry.geometryObjects)
                assert fast.messages == reference.messages
        finally:
            window.zmq_socket = real


def test_set_camera_position_sends_meshcats_y_up_coordinates(viewers, humanoid):
    import umsgpack

    model, geometry = humanoid
    v = viewers("viewer", model, geometry)
    window = v.viz.viewer.window
    with v.lock:
        real, window.zmq_socket = window.zmq_socket, RecordingSocket()
        recorder = window.zmq_socket
    try:
        v.setCameraPosition([1.0, 2.0, 3.0])  # world x, y, z (z up)
    finally:
        with v.lock:
            window.zmq_socket = real
    [(kind, path, data)] = recorder.messages
    assert kind == b"set_property" and path == b"/Cameras/default/rotated/<object>"
    message = umsgpack.unpackb(data)
    assert message["property"] == "position" and message["value"] == [1.0, 3.0, -2.0]
    with pytest.raises(SotpyError, match=r"setCameraPosition: position must be a 3-vector"):
        v.setCameraPosition([1.0, 2.0])


def test_sender_sends_the_latest_and_drops_the_rest_without_blocking(viewers, humanoid):
    model, geometry = humanoid
    v = viewers("viewer", model, geometry, period=1)
    calls = record_display(v, delay=0.05)  # a slow browser link: 50 ms per frame
    src = ViewerTestSource("src")
    plug(src.state, v.state)
    after = PeriodicCall("src.after")
    after.addSignal(v.display)
    buffer = pin.neutral(model)  # a device that reuses its state buffer
    n = 40
    start = time.perf_counter()
    for t in range(1, n + 1):
        buffer[:] = configuration(model, t)
        src.state.write(buffer, t)
        after.run(t)
    loop_time = time.perf_counter() - start
    assert loop_time < 0.5  # sending each one in the loop would take >= 40 * 50 ms
    assert v.display.value == n
    assert v.flush(10.0)
    assert v.sent + v.dropped == n
    assert v.dropped > 0 and 1 <= len(calls) == v.sent < n
    sent = [q for q, _ in calls]
    np.testing.assert_array_equal(sent[-1], configuration(model, n))  # the latest one
    # the copies were taken at hand-over time: each is the configuration of one tick,
    # in increasing tick order, although the source overwrote its buffer since
    ticks = [round(float(q[7]) / 1e-3) for q in sent]
    assert ticks == sorted(set(ticks))
    for q, t in zip(sent, ticks, strict=True):
        np.testing.assert_array_equal(q, configuration(model, t))


def test_close_stops_the_thread_and_the_server(viewers, humanoid):
    model, geometry = humanoid
    v = viewers("viewer", model, geometry)
    url = v.url()
    with urllib.request.urlopen(url, timeout=10) as page:
        assert page.status == 200 and b"MeshCat" in page.read()
    thread, proc = v.senderThread, v.serverProcess
    assert thread.is_alive() and proc.poll() is None
    v.state.value = pin.neutral(model)
    assert v.display(1) == 1
    assert v.flush(5.0)
    v.close()
    assert not thread.is_alive()
    assert proc.poll() is not None
    with pytest.raises(urllib.error.URLError):
        urllib.request.urlopen(url, timeout=5)
    assert not v.isOpen()
    assert v.sent == 1 and v.dropped == 0  # the counts stay readable
    with pytest.raises(SotpyError, match=r"RobotViewer\(viewer\)\.url: the viewer is closed"):
        v.url()
    v.close()  # idempotent
    v.state.value = configuration(model, 2)
    assert v.display(2) == 1  # a closed viewer sends nothing and keeps its count
    assert not v.flush(0.1)


def test_pool_clear_closes_a_viewer_left_open(humanoid):
    model, geometry = humanoid
    v = RobotViewer("forgotten", model, geometry)
    thread, proc = v.senderThread, v.serverProcess
    pool.clear()
    assert not thread.is_alive() and proc.poll() is not None


def alive(pid: int) -> bool:
    """Whether process ``pid`` runs (a zombie waiting to be reaped does not)."""
    try:
        with open(f"/proc/{pid}/stat") as f:
            return f.read().rsplit(")", 1)[1].split()[0] != "Z"
    except FileNotFoundError:
        return False


def test_server_ends_when_the_python_that_started_it_dies(tmp_path):
    script = tmp_path / "crash.py"
    script.write_text(
        "import os, pinocchio as pin\n"
        "from sotpy.viewer import RobotViewer\n"
        "m = pin.buildSampleModelHumanoid()\n"
        "v = RobotViewer('v', m, pin.buildSampleGeometryModelHumanoid(m))\n"
        "print(v.serverProcess.pid, flush=True)\n"
        "os._exit(1)  # no close(), no atexit: as if killed\n"
    )
    out = subprocess.run(
        [sys.executable, str(script)], capture_output=True, text=True, timeout=60, check=False
    )
    pid = int(out.stdout.split()[0])
    deadline = time.monotonic() + 10
    while alive(pid) and time.monotonic() < deadline:
        time.sleep(0.1)
    assert not alive(pid)


def test_server_that_exits_raises_naming_the_entity(monkeypatch, humanoid):
    model, geometry = humanoid
    monkeypatch.setattr(
        viewer_module, "_SERVER_COMMAND", [sys.executable, "-c", "print('no port'); exit(3)"]
    )
    with pytest.raises(SotpyError, match=r"(?s)RobotViewer\(bad\).*exited with code 3.*no port"):
        RobotViewer("bad", model, geometry)
    assert not pool.hasEntity("bad")


def test_server_that_hangs_times_out_and_is_stopped(monkeypatch, tmp_path, humanoid):
    model, geometry = humanoid
    pid_file = tmp_path / "pid"
    hang = f"import os, time; open({str(pid_file)!r}, 'w').write(str(os.getpid())); time.sleep(60)"
    monkeypatch.setattr(viewer_module, "_SERVER_COMMAND", [sys.executable, "-c", hang])
    start = time.monotonic()
    with pytest.raises(SotpyError, match=r"RobotViewer\(slow\).*within 0.5 s"):
        RobotViewer("slow", model, geometry, timeout=0.5)
    assert time.monotonic() - start < 10
    assert not pool.hasEntity("slow")
    pid = int(pid_file.read_text())
    with pytest.raises(ProcessLookupError):  # stopped and reaped
        os.kill(pid, 0)


def test_bad_arguments_are_refused_before_starting_anything(monkeypatch, humanoid):
    model, geometry = humanoid
    # a server start would fail with "cannot start the meshcat server"
    monkeypatch.setattr(viewer_module, "_SERVER_COMMAND", ["/nonexistent/meshcat-server"])
    with pytest.raises(EntityError, match=r"RobotViewer\(v\): model must be a pinocchio.Model"):
        RobotViewer("v", "talos", geometry)
    with pytest.raises(EntityError, match=r"visual_model must be a pinocchio.GeometryModel"):
        RobotViewer("v", model, model)
    with pytest.raises(SignalTypeError, match=r"RobotViewer\(v\)::output\(int\)::display"):
        RobotViewer("v", model, geometry, period=0)
    with pytest.raises(EntityError, match="timeout must be a positive number"):
        RobotViewer("v", model, geometry, timeout=0)
    with pytest.raises(SotpyError, match=r"RobotViewer\(v\): cannot start the meshcat server"):
        RobotViewer("v", model, geometry)
    assert pool.list() == []


def test_wrong_configurations_are_refused_in_the_loop(viewers, humanoid):
    model, geometry = humanoid
    v = viewers("viewer", model, geometry)
    calls = record_display(v)
    v.state.value = np.zeros(model.nq - 1)
    with pytest.raises(
        SignalTypeError, match=r"RobotViewer\(viewer\)::input\(vector\)::state: .*nq=35"
    ):
        v.display(1)
    src = ViewerTestSource("src")
    plug(src.state, v.state)
    q = pin.neutral(model)
    q[10] = np.nan
    src.state.write(q, 2)
    with pytest.raises(SignalTypeError, match="not finite"):
        v.display(2)
    v.flush(1.0)
    assert calls == [] and v.sent == 0


def test_a_failing_sender_warns_once_and_the_loop_goes_on(viewers, humanoid):
    model, geometry = humanoid
    v = viewers("viewer", model, geometry, period=1)
    record_display(v, fail=True)
    src = ViewerTestSource("src")
    plug(src.state, v.state)
    src.state.write(configuration(model, 1), 1)
    assert v.display(1) == 1
    assert not v.flush(5.0)  # the send failed
    assert isinstance(v.error, RuntimeError)
    src.state.write(configuration(model, 2), 2)
    with pytest.warns(SotpyWarning, match=r"RobotViewer\(viewer\): the viewer stopped.*boom"):
        assert v.display(2) == 1
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # once only
        src.state.write(configuration(model, 3), 3)
        assert v.display(3) == 1


def test_cost_per_tick_seen_by_the_loop_on_talos(viewers, talos):
    """The loop-side cost of the viewer (period 20, real meshcat sends in the thread,
    the loop running flat out): a generous bound of 1 ms per tick; the figures are
    printed (``pytest -s``)."""
    model = talos.model
    v = viewers("viewer", model, talos.visual_model)
    src = ViewerTestSource("src")
    plug(src.state, v.state)
    q0 = model.referenceConfigurations["half_sitting"].copy()
    data = model.createData()
    clock = [0]

    def loop(after: PeriodicCall, duration: float) -> float:
        """Run ticks for ``duration`` s; the mean time of a tick, in s."""
        q = q0.copy()
        n = 0
        start = time.perf_counter()
        while time.perf_counter() - start < duration:
            clock[0] += 1
            q[7:] = q0[7:] + 0.1 * np.sin(1e-3 * clock[0])
            pin.forwardKinematics(model, data, q)  # some control work
            src.state.write(q.copy(), clock[0])
            after.run(clock[0])
            n += 1
        return (time.perf_counter() - start) / n

    bare = PeriodicCall("bare")
    hooked = PeriodicCall("hooked")
    hooked.addSignal(v.display)
    loop(hooked, 0.05)  # warm up (the plan, the first frame)
    assert v.flush(10.0)
    sent0, dropped0 = v.sent, v.dropped
    base, with_viewer = [], []
    for _ in range(3):  # interleaved
        base.append(loop(bare, 0.3))
        with_viewer.append(loop(hooked, 0.3))
    sent, dropped = v.sent - sent0, v.dropped - dropped0
    assert v.flush(10.0)
    cost = np.mean(with_viewer) - np.mean(base)
    print(  # shown with pytest -s
        f"\n[viewer] Talos, period 20, flat out: {np.mean(base) * 1e6:.1f} us/tick "
        f"without the viewer, {np.mean(with_viewer) * 1e6:.1f} us/tick with it "
        f"({cost * 1e6:+.1f} us/tick); {sent} frames sent, {dropped} dropped in 0.9 s"
    )
    # every configuration handed over was sent or replaced by a newer one
    assert v.sent > sent0 and v.sent + v.dropped == v.display.value
    assert cost < 1e-3


@pytest.mark.needs("chromium")
def test_page_renders_talos_at_half_sitting(viewers, talos, tmp_path):
    from matplotlib.image import imread

    model = talos.model
    v = viewers("talos_viewer", model, talos.visual_model)
    v.state.value = model.referenceConfigurations["half_sitting"]
    assert v.display(1) == 1
    shot = v.snapshot(str(tmp_path / "shot.png"), timeout=120.0)
    assert os.path.getsize(shot) > 1000
    img = imread(shot)[:, :, :3]  # floats in [0, 1]
    assert img.shape == (600, 800, 3)
    assert img.std() > 0.05
    colours = np.unique((img * 255).round().astype(np.uint8).reshape(-1, 3), axis=0)
    assert len(colours) > 100
    # meshcat's empty scene (same background, grid and axes) differs where the robot is
    empty = viewers("empty_viewer", model, pin.GeometryModel())
    reference = imread(empty.snapshot(str(tmp_path / "empty.png"), timeout=60.0))[:, :, :3]
    differs = np.abs(img - reference).max(axis=2) > 0.1
    assert differs.mean() > 0.01  # the robot covers about 5 % of the picture
    rows, cols = np.nonzero(differs)
    assert 250 < cols.mean() < 550 and 100 < rows.mean() < 400  # around the centre
    # the robot is mostly grey and black, the background blue
    red, blue = img[differs][:, 0], img[differs][:, 2]
    assert np.mean(np.abs(red - blue) < 0.1) > 0.5


# -- watching a demo: the camera on the robot, the motion replayed, the page's life ------
def test_frame_robot_and_animate_check_their_arguments(viewers, humanoid):
    model, geometry = humanoid
    v = viewers("viewer", model, geometry)
    with pytest.raises(SotpyError, match=r"RobotViewer\(viewer\)\.frameRobot: q must be"):
        v.frameRobot(np.zeros(3))
    with pytest.raises(SotpyError, match="fill must be a fraction"):
        v.frameRobot(None, 2.0)
    with pytest.raises(SotpyError, match=r"animate: configurations must be .* k x 35"):
        v.animate(np.zeros((4, 3)), 0.02)
    with pytest.raises(SotpyError, match="dt must be"):
        v.animate(np.tile(pin.neutral(model), (2, 1)), 0.0)
    # the centre is the middle of the geometries' box at q (here the neutral posture)
    centre = v.frameRobot()
    lo, hi = viewer_module._visualBox(model, geometry, pin.neutral(model))
    np.testing.assert_allclose(centre, 0.5 * (lo + hi))
    assert v.animate(np.tile(pin.neutral(model), (6, 1)), 0.02) == pytest.approx(0.1)
    assert v.pages() == 0 and not v.waitPages(timeout=0.1)  # no page was ever opened


def test_visual_box_holds_every_mesh_vertex(talos):
    """The box of frameRobot, against the vertices of Talos's meshes placed by
    Pinocchio (independent of the AABBs it is computed from): every vertex inside, and
    the box no more than 5 cm larger than the vertices' own box (a mesh's local box,
    turned by its placement, is larger than the mesh: 3 cm on Talos's arms)."""
    model, visual = talos.model, talos.visual_model
    q = model.referenceConfigurations["half_sitting"]
    lo, hi = viewer_module._visualBox(model, visual, q)
    data, gdata = model.createData(), pin.GeometryData(visual)
    pin.forwardKinematics(model, data, q)
    pin.updateGeometryPlacements(model, data, visual, gdata)
    points = []
    for obj, M in zip(visual.geometryObjects, gdata.oMg, strict=True):
        vertices = getattr(obj.geometry, "vertices", None)
        if vertices is None:
            continue
        local = np.asarray(obj.geometry.vertices()) * np.asarray(obj.meshScale)
        points.append(local @ M.rotation.T + M.translation)
    points = np.vstack(points)
    assert len(points) > 1000
    assert (points >= lo - 1e-9).all() and (points <= hi + 1e-9).all()
    np.testing.assert_allclose(lo, points.min(axis=0), atol=0.05)
    np.testing.assert_allclose(hi, points.max(axis=0), atol=0.05)
    assert 1.6 < hi[2] - lo[2] < 1.8  # Talos is 1.7 m tall at half-sitting


# the page's state: how many animation tracks it plays, for how long, whether it plays
_ANIMATION = (
    "(() => { const a = viewer.animator; return {actions: a.actions.length,"
    " duration: a.duration, playing: a.playing}; })()"
)


@pytest.mark.needs("chromium")
def test_page_frames_nao_and_plays_the_motion(viewers, tmp_path):
    """What a user sees in the browser: Nao framed by frameRobot (it filled 70 px of a
    600 px view with meshcat's default camera), the motion sent by animate playing in
    the page, and the page's visit seen by the server (waitPages)."""
    from matplotlib.image import imread

    from sotpy.dynamics import load_robot

    robot = load_robot("nao")
    model, visual = robot.model, robot.visual_model
    v = viewers("nao_viewer", model, visual)
    q0 = robot.halfSitting
    with v.lock:
        v.viz.display(q0)
    v.frameRobot(q0)
    motion = np.tile(q0, (51, 1))
    motion[:, model.joints[model.getJointId("HeadYaw")].idx_q] += np.linspace(0, 0.5, 51)
    assert v.animate(motion, 0.02) == pytest.approx(1.0)
    png, state = viewer_module._renderPage(
        "test", v.url(), 800, 600, len(visual.geometryObjects), 90.0, probe=_ANIMATION
    )
    assert state["actions"] == len(visual.geometryObjects)  # one track per mesh
    assert state["duration"] == pytest.approx(1.0, abs=1e-6) and state["playing"]
    assert v.waitPages(timeout=10.0)  # Chromium opened the page and left it
    # Nao against an empty scene framed the same way: its height on the screen
    (tmp_path / "nao.png").write_bytes(png)
    empty = viewers("empty_viewer", model, pin.GeometryModel())
    with empty.lock:  # the empty scene has no box: moved and seen as Nao's
        for node in (empty.viz.viewerRootNodeName, "/Grid", "/Axes"):
            empty.viz.viewer[node].set_transform(pin.SE3(np.eye(3), -v._centre).homogeneous)
    empty.setCameraPosition(v._cameraPosition)
    reference = imread(empty.snapshot(str(tmp_path / "empty.png"), timeout=60.0))[:, :, :3]
    img = imread(str(tmp_path / "nao.png"))[:, :, :3]
    differs = np.abs(img - reference).max(axis=2) > 0.1
    rows = np.nonzero(differs.any(axis=1))[0]
    assert rows.max() - rows.min() > 0.5 * 600  # more than half the view's height
