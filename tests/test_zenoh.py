"""ZenohPublish / ZenohSubscribe over loopback: in one process (two sessions) for the
commands, and with a peer process started by the test (this file run as a script) for
the order of arrival, a killed peer, malformed samples and a lock-step ``sotpy serve``.

Every peer is bounded: it exits by itself after a few seconds at most, and the test
kills it in its ``finally``.
"""

from __future__ import annotations

import contextlib
import socket
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("zenoh")

from sotpy.bridge import (
    ZenohPublish,
    ZenohSubscribe,
    encode,
    loopbackConfig,
    openSession,
)
from sotpy.errors import BridgeError, SignalTypeError, StaleSignalError
from sotpy.graph import VECTOR, Entity, Input, Output, plug, pool
from sotpy.loop import ControlLoop

HERE = Path(__file__).resolve()
PEER_LIFETIME = 20.0  # s: a peer that runs "forever" exits after this anyway


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _wait_until(cond, timeout, step=0.002):
    deadline = time.monotonic() + timeout
    while not cond():
        if time.monotonic() > deadline:
            return False
        time.sleep(step)
    return True


@contextlib.contextmanager
def peer(role: str, endpoint: str, key: str, n: int):
    """This file run as a script in a new process (see _peer); killed on exit."""
    proc = subprocess.Popen(
        [sys.executable, str(HERE), role, endpoint, key, str(n)],
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
    )
    try:
        yield proc
    finally:
        if proc.poll() is None:
            proc.kill()
        proc.communicate(timeout=10)


def _pair():
    """(config that listens, config that connects, endpoint) on a free loopback port."""
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    return loopbackConfig(listen=[endpoint]), loopbackConfig(connect=[endpoint]), endpoint


def _arm_device():
    """A Device over Pinocchio's 6-joint sample manipulator, velocity control."""
    import pinocchio as pin

    from sotpy.dynamics import Device

    device = Device("arm", pin.buildSampleModelManipulator())
    device.setControlType("velocity")
    return device


class _Source(Entity):
    """An output that returns whatever ``value`` holds (a trusted callback)."""

    @Output(VECTOR, timeDependent=True)
    def out(self):
        return self.value


# -- in one process ----------------------------------------------------------------------
def test_commands_follow_sots_bridge():
    a, b, _ = _pair()
    pub = ZenohPublish("pub", a)
    sub = ZenohSubscribe("sub", b)
    pub.add("vector", "q", "t/q")
    pub.add("double", "gain", "t/gain")
    sub.add("vector", "q", "t/q", size=3)
    sub.add("matrixHomo", "pose", "t/pose")  # SoT's type name for an SE3
    assert pub.list() == ["q", "gain"] and sub.list() == ["q", "pose"]
    assert pub.q.name == "ZenohPublish(pub)::input(vector)::q"
    assert sub.pose.name == "ZenohSubscribe(sub)::output(SE3)::pose"
    assert pub.trigger.dependencies == [pub.q, pub.gain]
    pub.rm("q")
    assert pub.list() == ["gain"] and not pub.hasSignal("q")
    assert pub.trigger.dependencies == [pub.gain]
    for call, match in (
        (lambda: sub.add("vector", "q", "t/other"), "already exists"),
        (lambda: sub.add("quaternion", "x", "t/x"), "unknown type"),
        (lambda: sub.add("vector", "x", "/t/x"), "not a Zenoh key"),
        (lambda: sub.rm("nothing"), "no key for signal"),
        (lambda: sub.setMaxAge("q", -1.0), "seconds > 0"),
    ):
        with pytest.raises(BridgeError, match=match):
            call()
    sub.clear()
    assert sub.list() == [] and not sub.hasSignal("pose")


def test_samples_arrive_stamped_with_their_tick_of_arrival():
    a, b, _ = _pair()
    pub = ZenohPublish("pub", a)
    pub.add("vector", "x", "t/x")
    sub = ZenohSubscribe("sub", b)
    sub.add("vector", "x", "t/x", size=2)
    assert pub.waitForSubscribers(10)
    with pytest.raises(StaleSignalError, match="no sample received yet") as info:
        sub.x(0)
    assert info.value.key == "t/x" and info.value.age == float("inf")
    pub.x.value = [1.0, 2.0]
    assert pub.trigger(5) == 1
    pool.time = 7
    assert sub.wait("x", 5)  # reads at the current tick until a sample came
    assert sub.arrivalTick("x") == 7
    assert sub.x.time == 7  # the output's time is the tick the sample arrived at
    assert np.array_equal(sub.x(10), [1.0, 2.0]) and sub.x.time == 7  # no new sample
    assert sub.stats()["x"]["senderTick"] == 5
    assert 0 <= sub.age("x") < 5.0


def test_publisher_refuses_a_nan_and_sends_every_kth_tick():
    a, b, _ = _pair()
    pub = ZenohPublish("pub", a)
    pub.add("vector", "x", "t/x")
    sub = ZenohSubscribe("sub", b)
    sub.add("vector", "x", "t/x")
    assert pub.waitForSubscribers(10)
    nan = _Source("nan")
    nan.value = np.array([np.nan])  # a callback's result is not converted: it reaches pub
    plug(nan.out, pub.x)
    with pytest.raises(BridgeError, match="NaN"):
        pub.trigger(0)
    assert pub.stats()["x"]["sent"] == 0
    pub.x.value = [1.0]
    pub.setPeriod(3)
    loop = ControlLoop("loop", pub, 1e-3)  # a publisher ticks as a device would
    seen = []
    for _ in range(10):
        loop.step(1)
        time.sleep(0.003)
        with contextlib.suppress(StaleSignalError):
            sub.x(pub.getTime())
            seen.append(sub.stats()["x"]["senderTick"])
    assert pub.stats()["x"]["sent"] == 4  # ticks 0, 3, 6, 9

    reads = iter(range(pub.getTime(), 10**9))

    def last_arrived():  # delivery can take longer than a tick on a loaded machine
        with contextlib.suppress(StaleSignalError):
            sub.x(next(reads))  # a later tick each time: a read within a tick is cached
            seen.append(sub.stats()["x"]["senderTick"])
        return bool(seen) and seen[-1] == 9

    assert _wait_until(last_arrived, 10.0)
    assert set(seen) <= {0, 3, 6, 9}


@pytest.mark.parametrize("thread", [True, False])
def test_shared_memory_and_either_sender_carry_every_bit(thread):
    a, b, _ = _pair()
    pub = ZenohPublish("pub", a)
    pub.setSharedMemory(True)  # before add: the keys added later use it too
    pub.setSendThread(thread)
    pub.add("matrix", "m", "t/m")
    sub = ZenohSubscribe("sub", b)
    sub.add("matrix", "m", "t/m", size=(3, 4))
    assert pub.waitForSubscribers(10)
    m = np.random.default_rng(1).standard_normal((3, 4))
    pub.m.value = m
    pub.trigger(0)
    assert sub.wait("m", 10)
    assert sub.m.value.tobytes() == m.tobytes()


def test_serve_configuration_is_checked(tmp_path):
    from sotpy.bridge.serve import ServeBridge, loadServeConfig

    def load(text):
        path = tmp_path / "z.toml"
        path.write_text(text)
        return loadServeConfig(path)

    for text, match in (
        ("colour = 1\n", "unknown entries"),
        ("wait = -1\n", "wait is a number"),
        ('[[publish]]\nkey = "a"\n', "signal .a string. is missing"),
        ('[[publish]]\nsignal = "d.state"\nkey = "a"\ncall = "during"\n', "call is"),
        ('[[subscribe]]\nsignal = "d.control"\nkey = "a"\nrate = 3\n', "unknown keys"),
        ("wait = [\n", "not valid TOML"),
    ):
        with pytest.raises(BridgeError, match=match):
            load(text)
    with pytest.raises(BridgeError, match="cannot read"):
        loadServeConfig(tmp_path / "missing.toml")
    device = _arm_device()
    session = (
        '[session]\n"scouting/multicast/enabled" = false\n'
        f'"listen/endpoints" = ["tcp/127.0.0.1:{free_port()}"]\n'
    )
    cfg = load(session + '[[publish]]\nsignal = "arm.control"\nkey = "t/a"\n')  # an input
    with pytest.raises(BridgeError, match="is not an output"):
        ServeBridge(cfg, device)
    assert not pool.hasEntity("zenoh_pub")  # nothing left half-built
    cfg = load(session + '[[subscribe]]\nsignal = "arm.state"\nkey = "t/a"\n')
    with pytest.raises(BridgeError, match="is not an input"):
        ServeBridge(cfg, device)
    assert not pool.hasEntity("zenoh_sub")


def test_without_zenoh_the_entities_name_the_extra(monkeypatch):
    monkeypatch.setitem(sys.modules, "zenoh", None)  # import zenoh now fails
    with pytest.raises(BridgeError, match=r"pip install 'sotpy\[zenoh\]'"):
        ZenohPublish("pub")
    with pytest.raises(BridgeError, match=r"sotpy\[zenoh\]"):
        ZenohSubscribe("sub")
    assert pool.list() == []  # nothing left half-built


# -- with a peer process -----------------------------------------------------------------
def test_values_arrive_in_order():
    listen, _, endpoint = _pair()
    sub = ZenohSubscribe("sub", listen)
    sub.add("vector", "x", "t/order", size=3)
    n = 1500
    held = []
    with peer("count", endpoint, "t/order", n) as proc:
        assert sub.wait("x", 30), "the peer sent nothing"
        t = 0
        while proc.poll() is None or sub.stats()["x"]["seq"] < n - 1:
            t += 1
            held.append((sub.x(t).copy(), sub.x.time, sub.stats()["x"]["seq"]))
            time.sleep(0.0005)
            assert t < 200_000, "the peer did not finish"
        assert proc.returncode == 0
    st = sub.stats()["x"]
    values = np.array([v[0] for v, _, _ in held])
    seqs = np.array([s for _, _, s in held])
    assert np.all(np.diff(values) >= 0) and np.all(np.diff(seqs) >= 0)  # never backwards
    assert np.array_equal(values, seqs)  # the value sent with number i is [i, i/2, -i]
    assert all(np.array_equal(v, [s, 0.5 * s, -s]) for v, _, s in held)
    assert st["seq"] == n - 1 and st["reordered"] == 0 and st["refused"] == {}
    assert st["received"] + st["lost"] == n  # every sample came, or is counted as lost
    stamps = np.array([tm for _, tm, _ in held])
    assert np.all(np.diff(stamps) >= 0)


def test_a_killed_peer_makes_the_age_grow_and_stops_the_device_safely():
    listen, _, endpoint = _pair()
    device = _arm_device()
    sub = ZenohSubscribe("sub", listen)
    sub.add("vector", "control", "t/control", size=6)
    limit = 0.2  # s: generous for a loaded machine; 200 ticks at 1 kHz
    sub.setMaxAge("control", limit)
    plug(sub.control, device.control)
    loop = ControlLoop("loop", device, 1e-3)
    with peer("forever", endpoint, "t/control", 6) as proc:
        assert sub.wait("control", 30)
        loop.start()
        time.sleep(0.3)
        ages = [sub.age("control") for _ in range(20) if not time.sleep(0.005)]
        assert loop.fault is None and loop.running, loop.fault
        assert max(ages) < limit
        ticks_before = loop.ticks
        killed = time.monotonic()
        proc.kill()
        assert loop.wait(timeout=10), "the loop did not stop"
        stopped = time.monotonic()
    fault = loop.fault
    assert isinstance(fault.exception, StaleSignalError), fault
    assert fault.exception.key == "t/control" and fault.exception.age > limit
    assert fault.signal == "ZenohSubscribe(sub)::output(vector)::control"
    assert "zero velocity" in fault.safe
    assert device.control.source is None  # unplugged from the stale key
    assert np.array_equal(device.control.value, np.zeros(6))
    assert loop.ticks > ticks_before
    assert stopped - killed < limit + 5.0  # the limit, plus a loaded machine's slack
    a1 = sub.age("control")
    time.sleep(0.05)
    assert sub.age("control") > a1 > limit  # the age keeps growing


def test_malformed_and_oversized_samples_are_refused_without_stopping_the_loop():
    listen, _, endpoint = _pair()
    device = _arm_device()
    sub = ZenohSubscribe("sub", listen)
    sub.add("vector", "control", "t/bad", size=6)
    sub.setMaxAge("control", 5.0)
    plug(sub.control, device.control)
    loop = ControlLoop("loop", device, 1e-3)
    with peer("garbage", endpoint, "t/bad", 6) as proc:
        assert sub.wait("control", 30)
        loop.start()
        proc.wait(timeout=30)
        assert proc.returncode == 0
        assert _wait_until(lambda: sub.stats()["control"]["seq"] == 1, 5)
        time.sleep(0.05)
        assert loop.fault is None and loop.running, loop.fault
        loop.stop()
    st = sub.stats()["control"]
    assert st["refused"] == {
        "header": 1,
        "version": 1,
        "type": 1,
        "size": 2,
        "value": 1,
        "oversized": 1,
    }
    assert st["received"] == 9 and st["lost"] == 0
    assert np.array_equal(sub.control.value, np.full(6, 0.02))  # the last good sample


class _PGain(Entity):
    """u = k (q_ref - q): the test's controller."""

    q = Input(VECTOR)
    ref = Input(VECTOR)

    @Output(VECTOR, deps=("q", "ref"))
    def u(self, q, ref):
        return 2.0 * (ref - q)


def test_sotpy_serve_in_lock_step_computes_what_one_process_computes(tmp_path):
    from sotpy.dynamics import load_robot

    port = free_port()
    cfg = tmp_path / "device.toml"
    cfg.write_text(
        "wait = 60\n"
        "[session]\n"
        'mode = "peer"\n'
        f'"listen/endpoints" = ["tcp/127.0.0.1:{port}"]\n'
        '"scouting/multicast/enabled" = false\n'
        "[[publish]]\n"
        'signal = "ur5_device.state"\n'
        'key = "t/ur5/state"\n'
        "[[subscribe]]\n"
        'signal = "ur5_device.control"\n'
        'key = "t/ur5/control"\n'
        "size = 6\n"
        "sync = 0.5\n"
    )
    cmd = [sys.executable, "-m", "sotpy", "serve", "ur5", "--zenoh", str(cfg)]
    cmd += ["--connection-file", str(tmp_path / "c.json")]
    config = loopbackConfig(connect=[f"tcp/127.0.0.1:{port}"])
    n = 150
    serve = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    try:
        sub = ZenohSubscribe("sub", config)
        sub.add("vector", "state", "t/ur5/state", size=6)
        sub.setSync("state", 30.0)
        pub = ZenohPublish("pub", config)
        pub.add("vector", "control", "t/ur5/control", size=6)
        ctrl = _PGain("ctrl")
        plug(sub.state, ctrl.q)
        plug(ctrl.u, pub.control)
        assert pub.waitForSubscribers(60) and sub.wait("state", 60)
        q0 = sub.state(0).copy()
        ctrl.ref.value = q0 + 0.1
        loop = ControlLoop("loop", pub, 1e-3)
        qs = []
        for k in range(n):
            loop.step(1)
            qs.append(sub.state(k).copy())
        time.sleep(1.0)  # the device's next tick waits 0.5 s for a control, then stops
    finally:
        serve.terminate()
        out, _ = serve.communicate(timeout=30)
    assert "StaleSignalError" in out and "no sample of tick" in out, out
    assert "device.control set to zero velocity" in out, out
    # the same law in one process
    pool.clear()
    ref = load_robot("ur5", prefix="ref").device
    ref.setControlType("velocity")
    expected = []
    for k in range(n):
        q = ref.state(k)
        expected.append(q.copy())
        ref.control.value = 2.0 * ((q0 + 0.1) - q)
        ref.increment(1e-3)
    assert np.array_equal(np.array(qs), np.array(expected))


def test_a_subscribed_output_set_to_a_constant_ignores_its_key():
    _, b, _ = _pair()
    sub = ZenohSubscribe("sub", b)
    sub.add("double", "x", "t/x")
    sub.x.value = 2.0  # a constant, as any output: the key is then ignored
    assert sub.x.value == 2.0
    sub.x.resetCallback()
    with pytest.raises(StaleSignalError):
        sub.x(pool.time + 1)
    with pytest.raises(SignalTypeError):
        sub.x.value = "two"


# -- soak (bash .ci/run soak) -----------------------------------------------------------
@pytest.mark.soak
def test_the_split_reach_example_reaches_as_the_single_process_demo():
    root = HERE.parents[1]
    cmd = [sys.executable, str(root / "examples" / "zenoh_reach.py"), "--compare"]
    out = subprocess.run(cmd, capture_output=True, text=True, timeout=900, cwd=root)
    assert out.returncode == 0, out.stdout + out.stderr
    assert "the wrist reached its target" in out.stdout, out.stdout
    assert "difference between the two trajectories 0.0e+00" in out.stdout, out.stdout


@pytest.mark.soak
def test_a_minute_of_lock_step_round_trips_at_1khz_loses_nothing():
    import importlib.util

    path = HERE.parents[1] / "benchmarks" / "bench_zenoh.py"
    spec = importlib.util.spec_from_file_location("bench_zenoh", path)
    bench = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(bench)
    ticks = 60_000
    r = bench.round_trip(ticks, shm=False)  # raises if a state is not its tick's
    assert len(r["rtt"]) == ticks and (r["rtt"] > 0).all()
    assert np.percentile(r["rtt"], 50) < 5e6  # ns: a sanity bound, not a target


# -- the peer ----------------------------------------------------------------------------
def _pace(t0: float, i: int, period: float = 1e-3) -> None:
    while time.perf_counter() < t0 + (i + 1) * period:
        time.sleep(0.0002)


def _peer(role: str, endpoint: str, key: str, n: int) -> int:
    cfg = loopbackConfig(connect=[endpoint])
    deadline = time.monotonic() + PEER_LIFETIME
    if role == "count":  # vectors [i, i/2, -i], i = 0 .. n-1, at 1 kHz
        pub = ZenohPublish("peer", cfg)
        pub.add("vector", "x", key)
        if not pub.waitForSubscribers(20):
            return 3
        t0 = time.perf_counter()
        for i in range(n):
            pub.x.value = np.array([i, 0.5 * i, -i], dtype=float)
            pub.trigger(i)
            _pace(t0, i)
        # the last samples leave the send thread and Zenoh's batches before the session
        # closes at exit (a sample lost at the end has no later one to reveal the gap)
        time.sleep(0.5)
        return 0
    if role == "forever":  # a small constant velocity at 1 kHz until killed
        pub = ZenohPublish("peer", cfg)
        pub.add("vector", "u", key)
        pub.u.value = np.full(n, 0.01)
        if not pub.waitForSubscribers(20):
            return 3
        t0 = time.perf_counter()
        i = 0
        while time.monotonic() < deadline:
            pub.trigger(i)
            _pace(t0, i)
            i += 1
        return 0
    if role == "garbage":  # two good samples around seven bad ones, 20 ms apart
        session = openSession(cfg)
        raw = session.declare_publisher(key)
        if not _wait_until(lambda: raw.matching_status.matching, 20):
            return 3
        good0 = encode("vector", np.full(n, 0.01), 0, 0)
        vec = encode("vector", np.zeros(n), 1, 1)
        nan = bytearray(vec)
        nan[-8:] = np.array([np.nan]).tobytes()
        samples = [
            good0,
            b"garbage!",  # header
            vec[:4] + b"\x09" + vec[5:],  # version 9
            encode("double", 1.0, 1, 1),  # type
            vec[:-3],  # size: truncated
            encode("vector", np.zeros(n - 1), 1, 1),  # size: not the declared 6
            bytes(nan),  # value
            encode("vector", np.zeros(200_000), 1, 1, limit=1 << 22),  # 1.6 MB: oversized
            encode("vector", np.full(n, 0.02), 1, 2),
        ]
        for s in samples:
            raw.put(s)
            time.sleep(0.02)
        time.sleep(0.3)
        return 0
    return 2


if __name__ == "__main__":
    sys.exit(_peer(sys.argv[1], sys.argv[2], sys.argv[3], int(sys.argv[4])))
