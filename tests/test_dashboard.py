"""The dashboard without a browser: the token rule over HTTP and the websocket, the
refusals, the recorder against a real Tracer's files, the edits, the status."""

from __future__ import annotations

import asyncio
import json
import logging
import struct
import time
import urllib.error
import urllib.request

import numpy as np
import pinocchio as pin
import pytest

from sotpy.dashboard import Dashboard, applyEdit, graphSnapshot, isLoopback, status
from sotpy.dashboard.model import EditError, signalList
from sotpy.dynamics import load_robot
from sotpy.errors import SignalTypeError, SotpyError
from sotpy.graph import VECTOR as VECTOR_T
from sotpy.graph import Tracer, plug, pool
from sotpy.loop import ControlLoop
from sotpy.solvers import SOT
from sotpy.tasks import FeaturePose, Task

DT = 0.01


def ur5_reach(forget: bool = False):
    """The debugging tutorial's UR5 graph (with its two forgotten lines when ``forget``)."""
    robot = load_robot("ur5")
    dyn = robot.dynamic
    feature = FeaturePose("feature_ee")
    plug(dyn.signal("end-effector"), feature.position)
    if not forget:
        plug(dyn.signal("Jend-effector"), feature.Jq)
    feature.reference.value = pin.SE3(np.eye(3), np.array([0.3, 0.2, 0.4]))
    feature.selec.value = "111000"
    task = Task("task_ee")
    task.add(feature)
    task.controlGain.value = 2.0
    sot = SOT("sot", dyn)
    if not forget:
        sot.dt.value = DT
    sot.push(task)
    plug(sot.control, robot.device.control)
    return robot, feature, task, sot


def _flagTicks(device) -> list[bool]:
    """``[ticking]``: True while ``device.increment`` runs (it is wrapped)."""
    ticking = [False]
    increment = device.increment

    def flagged(dt):
        ticking[0] = True
        try:
            increment(dt)
        finally:
            ticking[0] = False

    device.increment = flagged
    return ticking


def _pinnedLoop():
    """(the CPUs of this process, the UR5 reach's loop pinned to the last one); skips
    with fewer than 2 CPUs."""
    import os

    cpus = sorted(os.sched_getaffinity(0))
    if len(cpus) < 2:
        pytest.skip("needs 2 CPUs")
    robot, _, _, _ = ur5_reach()
    return cpus, ControlLoop("loop", robot.device, DT, cpus={cpus[-1]})


def _get(url: str, cookie: str | None = None) -> tuple[int, bytes, dict]:
    req = urllib.request.Request(url)
    if cookie:
        req.add_header("Cookie", cookie)

    class NoRedirect(urllib.request.HTTPRedirectHandler):
        def redirect_request(self, *args, **kwargs):
            return None

    opener = urllib.request.build_opener(NoRedirect)
    try:
        with opener.open(req, timeout=10) as r:
            return r.status, r.read(), dict(r.headers)
    except urllib.error.HTTPError as e:
        return e.code, e.read(), dict(e.headers)


def test_token_rule_no_token_no_page_no_data(caplog):
    robot, _, task, _ = ur5_reach()
    loop = ControlLoop("loop", robot.device, DT)
    with Dashboard(loop) as ui, caplog.at_level(logging.WARNING, "sotpy.dashboard"):
        base = f"http://127.0.0.1:{ui.port}"
        for path in ("/", "/static/dashboard.js", "/record.npz", "/?token=wrong"):
            code, body, _ = _get(base + path)
            assert code == 403, path
            assert ui.token.encode() not in body
        assert ui.refused == 4
        assert sum("refused" in r.message for r in caplog.records) == 4
        code, _, headers = _get(ui.url())
        assert code == 302 and headers["Location"] == "/"  # the token leaves the address
        cookie = headers["Set-Cookie"].split(";")[0]
        assert "httponly" in headers["Set-Cookie"].lower()
        assert "samesite=strict" in headers["Set-Cookie"].lower()
        code, body, _ = _get(base + "/", cookie)
        assert code == 200 and b"dashboard.js" in body
        code, body, _ = _get(base + "/static/vendor/uPlot.iife.min.js", cookie)
        assert code == 200 and b"uPlot" in body
        # the websocket: no token, or another site's origin, is refused
        import tornado.httpclient
        import tornado.websocket

        async def ws(headers):
            req = tornado.httpclient.HTTPRequest(f"ws://127.0.0.1:{ui.port}/ws", headers=headers)
            conn = await tornado.websocket.websocket_connect(req)
            conn.close()

        with pytest.raises(tornado.httpclient.HTTPClientError) as no_token:
            asyncio.run(ws({}))
        assert no_token.value.code == 403
        with pytest.raises(tornado.httpclient.HTTPClientError) as bad_origin:
            asyncio.run(ws({"Cookie": cookie, "Origin": "http://evil.example"}))
        assert bad_origin.value.code == 403
        assert ui.refused == 6
        ui.plot(task.error.path)
        robot.device.increment(DT)
        code, body, _ = _get(base + "/record.npz", cookie)
        assert code == 200 and body[:2] == b"PK"  # an npz (a zip)


def test_loopback_only_unless_asked():
    assert isLoopback("127.0.0.1") and isLoopback("::1") and isLoopback("localhost")
    assert not isLoopback("0.0.0.0") and not isLoopback("192.168.1.4")
    with pytest.raises(SotpyError, match=r"not a loopback address.*allowRemote"):
        Dashboard(None, host="0.0.0.0")


def test_recorder_writes_the_tracers_files(tmp_path):
    robot, _feature, task, sot = ur5_reach()
    loop = ControlLoop("loop", robot.device, DT)
    tracer = Tracer("tracer")
    paths = [task.error.path, sot.control.path, robot.device.state.path]
    for p in paths:
        tracer.add(p)
    tracer.setTimeStep(DT)
    tracer.start()
    robot.device.after.addSignal(tracer.trigger)
    with Dashboard(loop, seconds=1.0) as ui:
        ui.plot(*paths)
        loop.step(40)
        ours, theirs = ui.data(), tracer.data()
        assert len(ours["tick"]) == 40
        for key in ("time", "tick", *paths):
            np.testing.assert_array_equal(ours[key], theirs[key])
        ui.save(tmp_path / "ours.csv")
        tracer.dump(str(tmp_path / "theirs.csv"))
        assert (tmp_path / "ours.csv").read_bytes() == (tmp_path / "theirs.csv").read_bytes()
        ui.saveFiles(tmp_path / "ours", "dg_", ".dat")
        tracer.open(str(tmp_path / "theirs"), "dg_", ".dat")
        tracer.dump()
        for name in ("error", "control", "state"):
            mine = (tmp_path / "ours" / f"dg_{name}.dat").read_bytes()
            assert mine == (tmp_path / "theirs" / f"dg_{name}.dat").read_bytes()
            assert mine.count(b"\n") == 40
        ui.save(tmp_path / "ours.npz")
        from sotpy.plotting import recording  # the tracer's reader

        back = recording(tmp_path / "ours.npz")
        np.testing.assert_array_equal(back[task.error.path], theirs[task.error.path])


def test_ring_is_bounded_and_keeps_the_newest_rows():
    robot, _, task, _ = ur5_reach()
    loop = ControlLoop("loop", robot.device, DT)
    with Dashboard(loop, seconds=0.1) as ui:  # 10 rows
        ui.plot(task.error.path)
        errors = []
        for _ in range(25):
            loop.step(1)
            errors.append(task.error(robot.device.state.time).copy())
        data = ui.data()
        n = len(data["tick"])
        assert n == ui.recorder.size - 1 == 9
        np.testing.assert_array_equal(data["tick"], np.arange(26 - n, 26))
        np.testing.assert_array_equal(data[task.error.path], np.array(errors[-n:]))
        # what a page reads: the rows after its cursor, the components it asked for (a
        # component beyond the signal's size is left out, not an error)
        cursor, ticks, (block, none) = ui.recorder.since(20, [(task.error.path, [2, 0, 7]),
                                                              ("nobody.x", None)])  # fmt: skip
        assert cursor == 25 and ticks.tolist() == [21, 22, 23, 24, 25] and none is None
        np.testing.assert_array_equal(block, np.array(errors[-5:])[:, [2, 0]])


def test_a_plot_that_raises_stops_alone_and_the_loop_goes_on(caplog):
    robot, _feature, task, _sot = ur5_reach()
    loose = FeaturePose("loose")  # its position is unplugged: reading its error raises
    loop = ControlLoop("loop", robot.device, DT)
    with Dashboard(loop) as ui, caplog.at_level(logging.WARNING, "sotpy.dashboard"):
        ui.plot(task.error.path, loose.error.path)
        loop.step(5)
        assert loop.fault is None and loop.ticks == 5
        errors = ui.recorder.errors()
        assert list(errors) == [loose.error.path]
        assert "UnpluggedError" in errors[loose.error.path]
        assert "position" in errors[loose.error.path]
        assert ui.data()[task.error.path].shape == (5, 3)  # selec "111000"
        assert any("stopped recording" in r.message for r in caplog.records)


def test_edits_go_through_the_lock_and_refusals_change_nothing():
    robot, feature, task, sot = ur5_reach()
    loop = ControlLoop("loop", robot.device, DT)
    assert applyEdit({"kind": "set", "signal": "task_ee.controlGain", "text": "5"})["ok"]
    assert task.controlGain.value == 5.0
    with pytest.raises(SignalTypeError, match=r"Task\(task_ee\)::input\(double\)::controlGain"):
        applyEdit({"kind": "set", "signal": "task_ee.controlGain", "text": "[1, 2]"})
    assert task.controlGain.value == 5.0
    with pytest.raises(SotpyError, match=r"is plugged to.*unplug it from the shell"):
        applyEdit({"kind": "set", "signal": "feature_ee.position", "value": 1.0})
    assert feature.position.source is not None
    with pytest.raises(SotpyError, match="has no command 'nope'"):
        applyEdit({"kind": "call", "entity": "sot", "command": "nope"})
    applyEdit({"kind": "call", "entity": "sot", "command": "remove", "args": ["task_ee"]})
    assert sot.list() == []
    with pytest.raises(SotpyError, match=r"not in the stack|is not"):
        applyEdit({"kind": "call", "entity": "sot", "command": "remove", "args": ["task_ee"]})
    applyEdit({"kind": "call", "entity": "sot", "command": "push", "args": ["task_ee"]})
    assert sot.list() == ["task_ee"]
    applyEdit({"kind": "call", "entity": "loop", "command": "step", "args": [3]})
    assert loop.ticks == 3
    for bad in ([], {"kind": 3}, {"kind": "set"}, {"kind": "call", "entity": "sot"},
                {"kind": "call", "entity": "sot", "command": "push", "args": "x"},
                {"kind": "teleport"}):  # fmt: skip
        with pytest.raises(EditError):
            applyEdit(bad)


def test_graph_snapshot_and_status_show_what_is_missing_and_fresh():
    robot, feature, _task, sot = ur5_reach(forget=True)
    g = graphSnapshot(robot.device)
    assert g["unplugged"] == ["feature_ee.Jq", "sot.dt"]
    names = {e["name"]: e for e in g["entities"]}
    assert names["sot"]["kind"] == "sot" and names["task_ee"]["kind"] == "task"
    plugged = [s for e in pool.entities() for s in e.signals() if getattr(s, "source", None)]
    assert len(g["edges"]) == len(plugged)
    assert {"from": "ur5_dynamic.end-effector", "to": "feature_ee.position"} in g["edges"]
    assert [(c["owner"], c["members"]) for c in g["clusters"]] == [("sot", ["task_ee"])]
    plug(robot.dynamic.signal("Jend-effector"), feature.Jq)
    sot.dt.value = DT
    loop = ControlLoop("loop", robot.device, DT)
    loop.step(2)
    sigs = signalList()
    st = status(loop, sigs)
    fresh = {sigs[i].path for i in st["fresh"]}
    # (the task's own signals may be skipped: the SOT's fused rows read its features)
    assert {"sot.control", "ur5_dynamic.end-effector", "ur5_device.state"} <= fresh
    assert "feature_ee.errordot" not in fresh  # nobody read it at the last tick
    (level0, level1) = st["sots"][0]["levels"]
    assert level0["task"] == "joint limits" and level0["kind"] == "hard"
    assert level1["task"] == "task_ee" and level1["rows"] == 3 and level1["gain"] == 2.0
    np.testing.assert_allclose(level1["residual"], sot.lastResult.residuals[1])
    assert level1["rank"] == sot.lastResult.ranks[1] == 3
    assert st["loop"]["ticks"] == 2 and not st["loop"]["running"]
    sot.lastResult = object()  # a result without any of the attributes: the tasks alone
    (level,) = status(loop, sigs)["sots"][0]["levels"]
    assert level["task"] == "task_ee" and level["residual"] is None and level["rank"] is None
    assert "active" not in level

    class Result:  # the solver being rewritten reports active rows per level
        residuals = np.array([0.0, 1e-3])
        ranks = np.array([0, 3])
        active = [np.array([True, False, True]), np.array([], dtype=int)]
        status = "optimal"

    sot.lastResult = Result()
    st = status(loop, sigs)["sots"][0]
    assert st["levels"][0]["active"] == 2 and st["levels"][0]["activeRows"] == [0, 2]
    assert st["levels"][1]["active"] == 0 and st["status"] == "optimal"


def test_controller_tasks_weights_and_ramps():
    from sotpy.solvers.controller import Controller

    robot = load_robot("panda")
    ctrl = Controller("ctrl", robot.dynamic)
    ctrl.addJointTask("posture", 1e-3, 0)
    ctrl.addTorqueLimits("torque")
    ctrl.setRampDuration("posture", 0.5)
    ctrl.activateTasksAndConstraints()
    st = status(None, [])["controllers"][0]
    (posture,) = st["tasks"]
    assert posture["name"] == "posture" and posture["weight"] == 1e-3
    assert posture["state"] == "activating" and posture["ramp"] == 0.0
    assert posture["rampDuration"] == 0.5
    assert st["constraints"][0]["name"] == "torque"
    applyEdit(
        {"kind": "call", "entity": "ctrl", "command": "setTaskWeight", "args": ["posture", 0.1]}
    )
    assert status(None, [])["controllers"][0]["tasks"][0]["weight"] == 0.1


def test_malformed_websocket_requests_are_refused_logged_and_the_loop_runs(caplog):
    import tornado.httpclient
    import tornado.websocket

    robot, _feature, task, _sot = ur5_reach()
    loop = ControlLoop("loop", robot.device, DT)
    with Dashboard(loop) as ui, caplog.at_level(logging.INFO, "sotpy.dashboard"):
        _, _, headers = _get(ui.url())
        cookie = headers["Set-Cookie"].split(";")[0]
        loop.start()

        async def session():
            req = tornado.httpclient.HTTPRequest(
                f"ws://127.0.0.1:{ui.port}/ws",
                headers={"Cookie": cookie, "Origin": f"http://127.0.0.1:{ui.port}"},
            )
            conn = await tornado.websocket.websocket_connect(req)
            replies = []
            for text in ("not json", "[1, 2]", json.dumps({"id": 7, "kind": "teleport"}),
                         json.dumps({"id": 8, "kind": "series", "series": "x"}),
                         json.dumps({"id": 9, "kind": "set", "signal": "task_ee.controlGain",
                                     "text": "abc"}),
                         json.dumps({"id": 10, "kind": "set", "signal": "task_ee.controlGain",
                                     "text": "3"})):  # fmt: skip
                await conn.write_message(text)
                while True:
                    msg = await asyncio.wait_for(conn.read_message(), 10)
                    if isinstance(msg, str) and json.loads(msg)["type"] == "reply":
                        replies.append(json.loads(msg))
                        break
            await conn.write_message(b"\x00" * 10)  # bytes: refused too
            conn.close()
            return replies

        replies = asyncio.run(session())
        ticks = loop.ticks
        time.sleep(0.2)
        assert loop.running and loop.ticks > ticks and loop.fault is None
        loop.stop()
    assert [r["ok"] for r in replies] == [False] * 5 + [True]
    assert all(r.get("malformed") for r in replies[:4])
    assert [r["id"] for r in replies[2:]] == [7, 8, 9, 10]
    assert "cannot read 'abc' as a value" in replies[4]["error"]
    assert "controlGain" in replies[4]["error"]
    assert task.controlGain.value == 3.0
    assert ui.refused >= 4
    assert sum("malformed" in r.message for r in caplog.records) >= 4


def test_a_busy_page_loses_frames_not_ticks():
    from concurrent.futures import Future

    from sotpy.dashboard.server import _Client

    robot, _feature, task, _sot = ur5_reach()
    loop = ControlLoop("loop", robot.device, DT)
    with Dashboard(loop) as ui:
        ui.plot(task.error.path)

        class FrozenPage:  # takes the first frame and never finishes writing it
            def __init__(self):
                self.frames = []

            def write_message(self, data, binary=False):
                self.frames.append(data)
                return Future()  # never done: the browser does not read

        page = _Client(FrozenPage())
        page.series = [(1, task.error.path, [0, 1, 2])]
        ui._clients.add(page)

        def onServer(fn):  # in the server's thread, as its own sends: never two at once
            done = Future()
            ui._aio.call_soon_threadsafe(lambda: done.set_result(fn()))
            return done.result(10)

        try:
            for _ in range(5):
                loop.step(10)
                onServer(ui._sendFrames)
        finally:
            ui._clients.discard(page)
        binary = [f for f in page.ws.frames if isinstance(f, bytes)]  # (the plot's notice)
        assert len(binary) == 1 and page.skipped >= 4  # (the server's timer skips too)
        assert loop.ticks == 50 and loop.fault is None
        # the rows after the one frame it took wait in the ring for the next frame (the
        # server's own timer may have sent it before the test's first call)
        hlen = struct.unpack("<I", binary[0][:4])[0]
        head = json.loads(binary[0][4 : 4 + hlen])
        assert 1 <= page.cursor == head["count"] == head["n"] <= 10
        assert len(ui.data()["tick"]) == 50


def test_the_3d_view_starts_on_demand_and_leaves_with_the_dashboard():
    robot, _feature, _task, _sot = ur5_reach()
    loop = ControlLoop("loop", robot.device, DT)
    ui = Dashboard(loop, robot=robot)
    try:
        reply = ui._startViewer()
        viewer = ui.viewer
        assert reply["ok"] and reply["result"] == viewer.url()
        assert any(viewer.display.path in s for s in robot.device.after.list())
        for k in (1, 2):  # the view follows every 20 ticks; a frame handed over while
            loop.step(20)  # the sender is busy replaces the one waiting: flush each
            assert viewer.flush(10.0) and viewer.sent >= k
    finally:
        ui.close()
    assert not viewer.isOpen() and not pool.hasEntity(viewer.name)
    assert robot.device.after.list() == []
    with Dashboard(loop) as bare, pytest.raises(SotpyError, match="without a robot"):
        bare._startViewer()


def test_sotpy_serve_ui_prints_the_page_and_keeps_the_token_rule(tmp_path):
    import os
    import re
    import signal
    import subprocess
    import sys

    env = {**os.environ, "SOTPY_JIT": os.environ.get("SOTPY_JIT", "0")}
    conn = tmp_path / "conn.json"
    proc = subprocess.Popen(
        [sys.executable, "-m", "sotpy", "serve", "ur5", "--paused", "--ui",
         "--connection-file", str(conn)],
        stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True, env=env,
    )  # fmt: skip
    try:
        url = None
        for line in proc.stdout:
            m = re.match(r"dashboard: (http://127\.0\.0\.1:\d+/\?token=\S+)", line)
            if m:
                url = m.group(1)
            if line.startswith("sotpy serve:"):
                break
        assert url is not None
        token = url.split("token=")[1]
        assert json.loads(conn.read_text())["token"] == token  # one secret for both
        base = url.split("?")[0]
        assert _get(base)[0] == 403
        assert _get(url)[0] == 302
    finally:
        proc.send_signal(signal.SIGTERM)
        proc.wait(30)
    assert proc.returncode == 0
    with pytest.raises(SotpyError, match="not a loopback"):
        Dashboard(None, host="10.1.2.3")  # refused before anything listens


def test_sotpy_demo_ui_builds_the_graph_and_serves_it():
    import os
    import subprocess
    import sys

    env = {**os.environ, "SOTPY_JIT": os.environ.get("SOTPY_JIT", "0")}
    last = max(os.sched_getaffinity(0))
    out = subprocess.run(
        [sys.executable, "-m", "sotpy", "demo", "nao", "--ui", "--hold", "0.5",
         "--loop-cpu", str(last), "--loop-never-idle"],
        capture_output=True, text=True, env=env, timeout=300,
    )  # fmt: skip
    assert out.returncode == 0, out.stderr[-2000:]
    assert f"the loop's thread runs on CPU [{last}]" in out.stdout
    assert "the loop yields for the whole period" in out.stdout
    assert "paused at tick 1" in out.stdout
    assert "http://127.0.0.1:" in out.stdout and "?token=" in out.stdout
    assert "stopped; loop statistics" in out.stdout
    bad = subprocess.run(
        [sys.executable, "-m", "sotpy", "demo", "nao", "--ui", "--hold", "0.5",
         "--loop-cpu", "100000"],
        capture_output=True, text=True, env=env, timeout=300,
    )  # fmt: skip
    assert bad.returncode == 1
    assert "cpus [100000] are not CPUs of this machine" in bad.stderr


def test_recorder_follows_a_replug_and_converts_what_is_not_a_plain_vector():
    """The recorder reads an up-to-date value where it is held (a plugged input's source)
    and finds that holder again when a plug changes; a type whose numeric form is not its
    value flattened goes through the type's ``to_array``."""
    from sotpy.graph import Entity, Input, Output, SignalType

    halves = SignalType("halves", lambda v: np.asarray(v, dtype=float), lambda v: 0.5 * v)

    class RecSource(Entity):
        def __init__(self, name, k):
            self.k = k

        @Output(VECTOR_T, withTime=True, timeDependent=True)
        def out(self, t):
            return np.array([self.k, float(t)])

        @Output(halves, withTime=True, timeDependent=True)
        def half(self, t):
            return np.array([self.k, 2.0 * t])

    class RecSink(Entity):
        inp = Input(VECTOR_T)

    robot, _, _, _ = ur5_reach()
    loop = ControlLoop("loop", robot.device, DT)
    a, b, sink = RecSource("rec_a", 1.0), RecSource("rec_b", 2.0), RecSink("rec_sink")
    plug(a.out, sink.inp)
    with Dashboard(loop, seconds=1.0) as ui:
        ui.plot(sink.inp.path, a.half.path, a.out.path)  # a.out stays up to date
        loop.step(3)
        with pool.lock:
            plug(b.out, sink.inp)
        loop.step(3)
        data = ui.data()
        ticks = data["tick"]
        got = data[sink.inp.path]
        np.testing.assert_array_equal(got[:, 1], ticks)
        np.testing.assert_array_equal(got[:, 0], [1.0, 1.0, 1.0, 2.0, 2.0, 2.0])
        np.testing.assert_array_equal(data[a.half.path], np.c_[np.full(6, 0.5), ticks])


def test_a_pinned_loop_keeps_the_dashboards_threads_off_its_cpu():
    import os
    import threading

    cpus, loop = _pinnedLoop()
    assert loop.otherCpus() == frozenset(cpus[:-1])
    with Dashboard(loop, seconds=1.0) as ui:
        assert ui.cpus == frozenset(cpus[:-1])
        ui._work.submit(lambda: None).result(10)  # the edits' worker thread exists
        mine = [t for t in threading.enumerate() if t.name.startswith("Dashboard(dashboard)")]
        assert len(mine) >= 2  # the server and the edits' worker
        for t in mine:
            assert os.sched_getaffinity(t.native_id) == set(cpus[:-1]), t.name
    unpinned = ControlLoop("loop2", loop.device, DT)
    assert unpinned.otherCpus() is None
    with Dashboard(unpinned, seconds=1.0) as ui:
        assert ui.cpus is None


def test_a_running_loop_wakes_the_server_between_its_ticks():
    """While the loop ticks in real time, the page's frames are built when the loop wakes
    the server between two ticks (never during one), at about the dashboard's rate; the
    server's own timer then only checks that the loop still does."""
    from concurrent.futures import Future

    from sotpy.dashboard.server import _Client

    robot, _feature, task, _sot = ur5_reach()
    loop = ControlLoop("loop", robot.device, 0.002)
    inTick = []

    class Page:
        def __init__(self):
            self.frames = []
            self.status = []

        def write_message(self, data, binary=False):
            if binary:
                self.frames.append(data)
                inTick.append(ticking[0])
            elif json.loads(data)["type"] == "status":
                self.status.append(json.loads(data)["tick"])
            done = Future()  # written at the server's next turn, as a socket's write is
            self.aio.call_soon(done.set_result, None)
            return done

    ticking = _flagTicks(robot.device)
    with Dashboard(loop, rate=25.0) as ui:
        ui.plot(task.error.path)
        page = _Client(Page())
        page.ws.aio = ui._aio
        page.series = [(1, task.error.path, None)]
        ui._clients.add(page)
        loop.start()
        time.sleep(1.0)
        loop.stop()
        woken = ui._pumpedByLoop
        ui._clients.discard(page)
    assert 15 <= len(page.ws.frames) <= 35, len(page.ws.frames)  # 25 a second
    assert not any(inTick)  # none built while a tick ran
    assert time.monotonic() - woken < 0.5
    frames = [struct.unpack("<I", f[:4])[0] for f in page.ws.frames]
    assert all(n > 0 for n in frames)
    # the status too (about 4 a second), each at a later tick: not starved by the frames
    ticks = page.ws.status
    assert len(ticks) >= 3 and ticks == sorted(ticks) and ticks[-1] > ticks[0], ticks


def _probes(robot, sot):
    """Three probes on the UR5 graph, each output recording ``(tick, in a tick?)`` of
    its calls: ``late.twice = 2 q`` (shares no step with the control), ``own.twice =
    2 u`` (its own step over the control) and ``mixed.sum = u + q[:6]`` (its own step
    over the control and the state the tick writes)."""
    from sotpy.graph import Entity, Input, Output

    ticking = _flagTicks(robot.device)
    calls: dict[str, list[tuple[int, bool]]] = {"late": [], "own": [], "mixed": []}

    class Probe(Entity):
        a = Input(VECTOR_T)
        b = Input(VECTOR_T)

        @Output(VECTOR_T, deps=("a",), withTime=True, timeDependent=True)
        def twice(self, t, a):
            calls[self.name].append((t, ticking[0]))
            return 2.0 * a

        @Output(VECTOR_T, deps=("a", "b"), withTime=True, timeDependent=True)
        def sum(self, t, a, b):
            calls[self.name].append((t, ticking[0]))
            return a + b[: a.shape[0]]

    late, own, mixed = Probe("late"), Probe("own"), Probe("mixed")
    plug(robot.device.state, late.a)
    plug(sot.control, own.a)
    plug(sot.control, mixed.a)
    plug(robot.device.state, mixed.b)
    return late, own, mixed, calls


def test_a_real_time_run_records_nothing_in_the_tick():
    """In a real-time run the row of tick T is made by the loop's idle calls, from the
    values the graph holds for T: the state and what shares no step with the control
    after tick T - 1; the control's values, and the steps of their own over them, after
    tick T. No probe runs in a tick, and each row is one tick's: its control moved its
    state to the next row's (velocity control), and every probe is its function of the
    row's values. ``step`` records the whole row in the tick, as before."""
    robot, _feature, task, sot = ur5_reach()
    late, own, _mixed, calls = _probes(robot, sot)
    loop = ControlLoop("loop", robot.device, DT)
    state, control = robot.device.state.path, sot.control.path
    with Dashboard(loop, rate=25.0) as ui:
        ui.plot(late.twice.path, own.twice.path, control, state, task.error.path)
        rec = ui.recorder
        hook = f"{rec.hook.path} (every 1)"
        assert hook in robot.device.after.list()
        loop.start()
        time.sleep(0.3)
        assert hook not in robot.device.after.list()  # no work in the tick, not even a call
        loop.stop()
        assert hook in robot.device.after.list()  # back for step
        assert rec._sharedAfter and [c.signal for c in rec._late] == [late.twice]
        assert {c.signal for c in rec._shared} == {own.twice, sot.control, task.error}
        # every row published but the last, which waits for the next tick's control
        assert rec.count == loop.ticks - 1 and rec._open is not None
        assert calls["late"] and calls["own"]
        assert not any(f for k in ("late", "own") for _, f in calls[k])  # none in a tick
        loop.step(1)  # that tick's hook finishes the waiting row, then makes its own
        assert rec._open is None and rec.count == loop.ticks
        assert all(f for _, f in calls["own"][-2:])  # closing the row, then its own
        data = ui.data()
        q, u = data[state], data[control]
        np.testing.assert_array_equal(data[late.twice.path], 2.0 * q)
        np.testing.assert_array_equal(data[own.twice.path], 2.0 * u)
        assert np.all(np.diff(data["tick"]) == 1)
        for k in range(len(q) - 1):  # the row's control took the row's state to the next
            np.testing.assert_allclose(q[k + 1], q[k] + DT * u[k], rtol=0, atol=1e-12)
        # the task's error, computed after the tick from the features' cached values, is
        # the error of the row's state (Pinocchio's forward kinematics, independently)
        model = robot.model
        data_pin = model.createData()
        frame = model.getFrameId(robot.opPoints["end-effector"])
        ref = np.array([0.3, 0.2, 0.4])
        for k in range(0, len(q), 37):
            pin.framesForwardKinematics(model, data_pin, q[k])
            np.testing.assert_allclose(
                data[task.error.path][k], data_pin.oMf[frame].translation - ref, atol=1e-12
            )


def test_a_step_over_the_state_keeps_the_control_values_in_the_tick():
    """A plotted signal whose own step reads both the control and the state the tick
    writes cannot be computed after the tick (it would read the next state): every
    signal sharing a step with the control is then recorded in the tick, at the tick's
    state, and what shares none after it. Rows stay consistent."""
    robot, _feature, _task, sot = ur5_reach()
    late, _own, mixed, calls = _probes(robot, sot)
    loop = ControlLoop("loop", robot.device, DT)
    state, control = robot.device.state.path, sot.control.path
    with Dashboard(loop, rate=25.0) as ui:
        ui.plot(mixed.sum.path, late.twice.path, control, state)
        loop.start()
        time.sleep(0.3)
        loop.stop()
        rec = ui.recorder
        assert not rec._sharedAfter
        assert rec.count == loop.ticks and rec._open is None  # every row published
        assert calls["mixed"] and all(f for _, f in calls["mixed"])  # in the tick
        assert not any(f for _, f in calls["late"])  # after it
        data = ui.data()
        q, u = data[state], data[control]
        np.testing.assert_array_equal(data[mixed.sum.path], u + q[:, :6])
        np.testing.assert_array_equal(data[late.twice.path], 2.0 * q)


@pytest.mark.parametrize(
    ("cpus", "why"),
    [([], "non-empty"), ([True], "CPU numbers"), ([0, 10_000], "not CPUs of this machine")],
)
def test_a_headless_page_refuses_cpus_that_are_not_the_machines(cpus, why):
    """Checked as a loop's CPUs are, before any browser starts (no Chromium needed)."""
    from sotpy.dashboard.browser import HeadlessPage

    with pytest.raises(SotpyError, match=why):
        HeadlessPage("http://127.0.0.1:1/", cpus=cpus)


def test_the_split_follows_the_plots_while_the_loop_runs():
    """Plotting, then removing, a signal whose own step reads the state while the loop
    runs moves the control's plots into the tick and back out: the rows stay each one
    tick's (increasing ticks, each row's control taking its state to the next row's,
    each probe its function of its row), none duplicated and none with a hole."""
    robot, _feature, _task, sot = ur5_reach()
    _late, own, mixed, calls = _probes(robot, sot)
    loop = ControlLoop("loop", robot.device, DT)
    state, control = robot.device.state.path, sot.control.path
    with Dashboard(loop, rate=25.0) as ui:
        rec = ui.recorder
        ui.plot(own.twice.path, control, state)
        loop.start()
        time.sleep(0.15)
        ui.plot(mixed.sum.path)
        time.sleep(0.15)
        inTick = rec._sharedAfter
        mixedRows = ui.data()[mixed.sum.path]
        rec.remove(mixed.sum.path)
        time.sleep(0.15)
        loop.stop()
        assert inTick is False and rec._sharedAfter
        assert calls["mixed"] and all(f for _, f in calls["mixed"])  # in the tick
        loop.step(1)  # the waiting row
        data = ui.data()
    ticks = data["tick"]
    assert len(ticks) > 20 and np.all(np.diff(ticks) >= 1)  # increasing, none twice
    q, u, twice = data[state], data[control], data[own.twice.path]
    assert not np.isnan(q).any() and not np.isnan(u).any() and not np.isnan(twice).any()
    np.testing.assert_array_equal(twice, 2.0 * u)
    for k in np.flatnonzero(np.diff(ticks) == 1):
        np.testing.assert_allclose(q[k + 1], q[k] + DT * u[k], rtol=0, atol=1e-12)
    recorded = ~np.isnan(mixedRows).all(axis=1)
    assert recorded.sum() > 5
    n = len(mixedRows)
    np.testing.assert_array_equal(mixedRows[recorded], (u[:n] + q[:n, :6])[recorded])


def test_a_row_whose_idle_call_did_not_come_is_not_filled_from_a_later_state():
    """A row waiting for the values of its tick gets NaN for them when the graph no
    longer holds them (the state moved on by more than that tick), never a later
    tick's values under its tick."""
    robot, _feature, _task, sot = ur5_reach()
    _late, own, _mixed, _calls = _probes(robot, sot)
    loop = ControlLoop("loop", robot.device, DT)
    with Dashboard(loop) as ui:
        ui.plot(own.twice.path, robot.device.state.path)
        loop.start()
        time.sleep(0.1)
        loop.stop()
        rec = ui.recorder
        i, t, part, *_ = rec._open
        assert part == "shared"
        with pool.lock:  # two ticks that the recorder does not see
            robot.device.after.rmSignal(rec.hook)
            robot.device.increment(DT)
            robot.device.increment(DT)
            robot.device.after.addSignal(rec.hook)
        n = rec.count
        with pool.lock:
            rec._closeOpen()
        assert rec.count == n + 1 and rec._ticks[i] == t
        data = ui.data()
        assert np.isnan(data[own.twice.path][-1]).all()
        assert not np.isnan(data[robot.device.state.path][-1]).any()
        assert not np.isnan(data[own.twice.path][:-1]).any()
