"""Round trip of the Zenoh bridge, and what a publisher costs a Talos tick (issue 23).

* **Round trip**: a controller process publishes a 38-vector control at tick ``k``
  (``ZenohPublish.trigger``), a device process (this script run with ``--device``)
  waits for it (``ZenohSubscribe`` in lock-step), publishes a 38-vector state of tick
  ``k``, and the controller waits for that state: the time from before the control's
  ``trigger`` to the state's arrival in the controller's graph. 10^4 ticks paced at
  1 kHz, over TCP on loopback, then with both publishers in Zenoh's shared memory; each
  with the samples put by the publishers' send threads (the default), then on the
  ticks' threads (``setSendThread(False)``). Reported: p50, p99 and worst, in us.
* **Publisher cost**: a Talos reach tick (``device.increment`` of the stack of ``sotpy
  demo talos``) paced at 1 kHz, followed in each tick by the ``trigger`` of a
  ``ZenohPublish`` in the device's ``after`` list, sending the state just written to a
  subscriber in another process: the device's velocity (a 38-vector) with and without
  the send thread, then its state (39) and velocity (38), as the device process of
  ``examples/zenoh_reach.py`` does. The trigger's time as a ratio to the tick's, median
  over median and p99 over p99, both measured in the same ticks, by the wall clock and
  by the thread's CPU clock (which leaves out the time other processes ran instead).
  The round trip's ``trigger`` times are larger: each follows a wait, and runs on cold
  caches.

Usage::

    python benchmarks/bench_zenoh.py            # 10^4 ticks per transport
    python benchmarks/bench_zenoh.py --quick    # 500 ticks, a smoke check
"""

from __future__ import annotations

import os

# the compiled kernels are what is measured: compiled first on a fresh machine, not the
# NumPy twins that a first run uses while they compile in the background
os.environ.setdefault("SOTPY_JIT", "wait")

import argparse
import contextlib
import socket
import subprocess
import sys
import time

import numpy as np

from sotpy._bench import machine_line
from sotpy.bridge import ZenohPublish, ZenohSubscribe, loopbackConfig
from sotpy.errors import StaleSignalError
from sotpy.graph import Plan, plug, pool

N = 38  # Talos' nv: the size of the state and of the control
_SIZES = {"state": 39, "velocity": 38}
# the publishers whose cost is measured: a 38-vector, and the device process of
# examples/zenoh_reach.py (its state and its velocity)
_COST_KEYS = ((("velocity",), True), (("velocity",), False), (("state", "velocity"), True))
_MODE = {True: "send thread", False: "tick's thread"}


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def device(port: int, ticks: int, shm: bool, thread: bool) -> int:
    """The device side: at each tick, wait for the control of the tick, send a state."""
    config = loopbackConfig(connect=[f"tcp/127.0.0.1:{port}"])
    sub = ZenohSubscribe("dev_sub", config)
    sub.add("vector", "control", "bench/control", size=N)
    sub.setSync("control", 30.0)
    pub = ZenohPublish("dev_pub", config)
    pub.add("vector", "state", "bench/state", size=N)
    pub.setSharedMemory(shm)
    pub.setSendThread(thread)
    plug(sub.control, pub.state)  # the state sent: the control received (an echo)
    if not pub.waitForSubscribers(60):
        return 3
    for k in range(ticks):
        pub.trigger(k)
    time.sleep(0.5)
    return 0


def round_trip(ticks: int, shm: bool, thread: bool = True) -> dict[str, np.ndarray]:
    """Round-trip times and trigger costs (ns) of ``ticks`` ticks paced at 1 kHz."""
    pool.clear()
    port = free_port()
    config = loopbackConfig(listen=[f"tcp/127.0.0.1:{port}"])
    pub = ZenohPublish("ctl_pub", config)
    pub.add("vector", "control", "bench/control", size=N)
    pub.setSharedMemory(shm)
    pub.setSendThread(thread)
    sub = ZenohSubscribe("ctl_sub", config)
    sub.add("vector", "state", "bench/state", size=N)
    sub.setSync("state", 5.0)
    cmd = [sys.executable, __file__, "--device", str(port), str(ticks)]
    if shm:
        cmd.append("--shm")
    if not thread:
        cmd.append("--inline")
    proc = subprocess.Popen(cmd)
    try:
        if not pub.waitForSubscribers(60):
            raise RuntimeError("the device process did not subscribe")
        clock = time.perf_counter_ns
        rtt = np.empty(ticks, dtype=np.int64)
        cost = np.empty(ticks, dtype=np.int64)
        u = np.zeros(N)
        period = 1_000_000
        deadline = clock() + 50 * period
        for k in range(ticks):
            while clock() < deadline - 200_000:
                time.sleep(1e-4)
            while clock() < deadline:
                time.sleep(0)
            u[0] = k
            pub.control.value = u
            t0 = clock()
            pub.trigger(k)
            t1 = clock()
            x = sub.state(k)
            t2 = clock()
            if x[0] != k:
                raise RuntimeError(f"tick {k}: received the state of {x[0]}")
            cost[k] = t1 - t0
            rtt[k] = t2 - t0
            deadline += period
            if clock() > deadline:  # late: keep the 1 ms grid, skip the missed deadline
                deadline += (clock() - deadline) // period * period + period
    finally:
        proc.wait(timeout=60)
        pool.clear()
    return {"rtt": rtt, "cost": cost}


def sink(port: int, seconds: float) -> int:
    """A subscriber to the publisher-cost keys, reading them every ms for ``seconds``."""
    config = loopbackConfig(connect=[f"tcp/127.0.0.1:{port}"])
    sub = ZenohSubscribe("sink", config)
    sub.add("vector", "state", "bench/talos/state")
    sub.add("vector", "velocity", "bench/talos/velocity")
    end = time.monotonic() + seconds
    t = 0
    while time.monotonic() < end:
        t += 1
        for name in ("state", "velocity"):
            with contextlib.suppress(StaleSignalError):
                sub.signal(name)(t)
        time.sleep(1e-3)
    return 0


def publisher_cost(ticks: int, keys: tuple[str, ...], thread: bool) -> dict[str, np.ndarray]:
    """Per tick of the stack of ``sotpy demo talos`` paced at 1 kHz: the time (ns) of the
    trigger of a publisher of the device's ``keys`` (``state``: 39, ``velocity``: 38) to
    a subscriber in another process, and of ``device.increment``."""
    from sotpy.demos.reach import (
        CONTACT_GAIN,
        MARGIN,
        POSTURE_GAIN,
        REACH_OFFSETS,
        WRIST_GAIN,
    )
    from sotpy.dynamics import load_robot
    from sotpy.solvers.sot import SOT
    from sotpy.tasks import TaskInequality

    pool.clear()
    dt = 1e-3
    r = load_robot("talos", prefix="reach_talos")
    dyn, dev = r.dynamic, r.device
    dev.setControlType("velocity")
    feet = [r.tasks["left-ankle"], r.tasks["right-ankle"]]
    balance = r.tasks["balance"]
    balance.setMargin(MARGIN)
    balance.task.dt.value = dt
    contact = TaskInequality("task_reach_talos_contact")
    for m in feet:
        contact.add(m.feature)
    contact.add(balance.feature)
    neq = sum(int(m.feature.error(0).shape[0]) for m in feet)
    bounds = balance.bounds()
    contact.referenceInf.value = np.concatenate((np.zeros(neq), np.full(len(bounds), -np.inf)))
    contact.referenceSup.value = np.concatenate((np.zeros(neq), bounds))
    contact.dt.value = dt
    contact.controlGain.value = CONTACT_GAIN
    wrist = r.tasks["right-wrist"]
    target = dyn.signal("right-wrist")(0).translation + np.array(REACH_OFFSETS["talos"])
    wrist.gotoNd(target, "111000", gain=WRIST_GAIN)
    r.tasks["posture"].gain.setConstant(POSTURE_GAIN)
    sot = SOT("reach_talos_sot", dyn)
    sot.dt.value = dt
    for task in (contact, wrist.task, r.tasks["posture"].task):
        sot.push(task)
    plug(sot.control, dev.control)
    port = free_port()
    pub = ZenohPublish("pub", loopbackConfig(listen=[f"tcp/127.0.0.1:{port}"]))
    pub.setSendThread(thread)
    for name in keys:
        pub.add("vector", name, f"bench/talos/{name}")
        plug(dev.signal(name), pub.signal(name))
    proc = subprocess.Popen([sys.executable, __file__, "--sink", str(port), str(ticks / 1e3 + 30)])
    try:
        if not pub.waitForSubscribers(60):
            raise RuntimeError("the subscriber process did not come up")
        after = Plan([pub.trigger])  # what device.after.addSignal(pub.trigger) runs
        for _ in range(100):  # warm up: the first solves, the plans' compilation
            dev.increment(dt)
            after.run(dev.state.time)
        clock = time.perf_counter_ns
        cpu = time.thread_time_ns  # the CPU time of this thread: preemption excluded
        trig, tick, trig_cpu, tick_cpu = (np.empty(ticks, dtype=np.int64) for _ in range(4))
        deadline = clock() + 1_000_000
        for k in range(ticks):
            while clock() < deadline - 200_000:
                time.sleep(1e-4)
            while clock() < deadline:
                time.sleep(0)
            c0, t0 = cpu(), clock()
            dev.increment(dt)
            c1, t1 = cpu(), clock()
            after.run(dev.state.time)  # the state just written, sent
            c2, t2 = cpu(), clock()
            tick[k], trig[k] = t1 - t0, t2 - t1
            tick_cpu[k], trig_cpu[k] = c1 - c0, c2 - c1
            deadline += 1_000_000
            if clock() > deadline:
                deadline += (clock() - deadline) // 1_000_000 * 1_000_000 + 1_000_000
    finally:
        proc.kill()
        proc.wait(timeout=30)
        pool.clear()
    return {"trigger": trig, "tick": tick, "trigger_cpu": trig_cpu, "tick_cpu": tick_cpu}


def _us(a: np.ndarray, q: float) -> float:
    return float(np.percentile(a, q)) * 1e-3


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n", 1)[0])
    parser.add_argument("--quick", action="store_true", help="500 ticks per transport")
    parser.add_argument("--device", nargs=2, type=int, metavar=("PORT", "TICKS"))
    parser.add_argument("--shm", action="store_true")
    parser.add_argument("--inline", action="store_true")
    parser.add_argument("--sink", nargs=2, type=float, metavar=("PORT", "SECONDS"))
    args = parser.parse_args()
    if args.device:
        return device(args.device[0], args.device[1], args.shm, not args.inline)
    if args.sink:
        return sink(int(args.sink[0]), args.sink[1])
    ticks = 500 if args.quick else 10_000
    print(machine_line(f"eclipse-zenoh {_zenoh_version()}"))
    rows = []
    for name, shm in (("TCP loopback", False), ("shared memory", True)):
        for thread in (True, False):
            rows.append((f"{name}, {_MODE[thread]}", round_trip(ticks, shm, thread)))
    costs = [
        (keys, thread, publisher_cost(min(ticks, 5000), keys, thread))
        for keys, thread in _COST_KEYS
    ]
    print(f"\nround trip, {ticks} ticks at 1 kHz, 38-vector control out, 38-vector state back")
    print("| transport | p50 | p99 | worst | its trigger p50 / p99 |")
    print("|---|---|---|---|---|")
    for name, r in rows:
        print(
            f"| {name} | {_us(r['rtt'], 50):.0f} us | {_us(r['rtt'], 99):.0f} us | "
            f"{r['rtt'].max() * 1e-3:.0f} us | {_us(r['cost'], 50):.0f} / "
            f"{_us(r['cost'], 99):.0f} us |"
        )
    print("\npublisher in a Talos reach tick (at 1 kHz; a subscriber in another process)")
    print("| keys | put | clock | trigger p50 / p99 | tick p50 / p99 | ratio p50 / p99 |")
    print("|---|---|---|---|---|---|")
    for keys, thread, cost in costs:
        what = " + ".join(f"{k} ({_SIZES[k]})" for k in keys) + f" | {_MODE[thread]}"
        for clock, suffix in (("wall", ""), ("thread CPU", "_cpu")):
            trig, tick = cost["trigger" + suffix], cost["tick" + suffix]
            c50, c99 = _us(trig, 50), _us(trig, 99)
            t50, t99 = _us(tick, 50), _us(tick, 99)
            print(
                f"| {what} | {clock} | {c50:.1f} / {c99:.1f} us | {t50:.0f} / {t99:.0f} us | "
                f"{100 * c50 / t50:.1f} / {100 * c99 / t99:.1f} % |"
            )
    n = len(costs[0][2]["tick"])
    print(f"({n} ticks each; thread CPU: time.thread_time_ns, what the tick's thread ran)")
    print("target: below 5 %")
    return 0


def _zenoh_version() -> str:
    from importlib.metadata import version

    return version("eclipse-zenoh")


if __name__ == "__main__":
    sys.exit(main())
