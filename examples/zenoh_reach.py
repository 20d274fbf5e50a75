"""The reaching demo split across two processes: Talos' simulator in one, its controller
in another, exchanging the state and the control over Zenoh.

The device process is ``sotpy serve talos --zenoh device.toml`` (this script writes the
file and starts it): its loop runs at 1 kHz, publishes ``talos_device.state`` and
``talos_device.velocity`` after each tick (``device.after``) and takes its control from
the key ``sotpy/talos/control``, waiting at each tick for the control of that tick
(lock-step, at most 1 s: then the loop stops the robot safely).

This process builds the reach controller of ``sotpy demo talos`` in plain sight, on a
``Dynamic`` fed by the subscribed state instead of a local device::

    sub = ZenohSubscribe("ctrl_sub", config)
    sub.add("vector", "state", "sotpy/talos/state", size=nq)
    sub.add("vector", "velocity", "sotpy/talos/velocity", size=nv)
    plug(sub.state, dyn.position); plug(sub.velocity, dyn.velocity)
    ... the contact, wrist and posture levels, the SOT ...
    pub = ZenohPublish("ctrl_pub", config)
    pub.add("vector", "control", "sotpy/talos/control", size=nv)
    plug(sot.control, pub.control)
    ControlLoop("ctrl_loop", pub, dt).run(ticks, realtime=False)  # each tick waits for
                                                                  # the state of its tick

Lock-step, each tick computes what the single-process graph computes: ``--compare``
runs ``sotpy demo talos`` here after and prints the largest difference between the two
trajectories (0 when the encoding carries every bit, as it does).

Run it with ``python examples/zenoh_reach.py [--duration 2] [--compare]``; needs
``pip install 'sotpy[zenoh]'``. See docs/zenoh.md.
"""

from __future__ import annotations

import argparse
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

from sotpy.bridge import ZenohPublish, ZenohSubscribe, loopbackConfig
from sotpy.demos.reach import (
    CONTACT_GAIN,
    MARGIN,
    POSTURE_GAIN,
    REACH_OFFSETS,
    REACH_TOLERANCE,
    WRIST_GAIN,
    run_reach,
)
from sotpy.dynamics import load_robot
from sotpy.graph import InputSignal, plug, pool
from sotpy.loop import ControlLoop
from sotpy.solvers.sot import SOT
from sotpy.tasks import TaskInequality

DEVICE_TOML = """\
wait = 120

[session]
mode = "peer"
"listen/endpoints" = ["tcp/127.0.0.1:{port}"]
"scouting/multicast/enabled" = false

[[publish]]
signal = "talos_device.state"
key = "sotpy/talos/state"

[[publish]]
signal = "talos_device.velocity"
key = "sotpy/talos/velocity"

[[subscribe]]
signal = "talos_device.control"
key = "sotpy/talos/control"
size = 38
sync = 1.0
"""


def free_port() -> int:
    """A TCP port free on 127.0.0.1 now."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def start_device(port: int, workdir: Path) -> subprocess.Popen:
    """``sotpy serve talos --zenoh device.toml`` in a new process."""
    toml = workdir / "device.toml"
    toml.write_text(DEVICE_TOML.format(port=port))
    cmd = [sys.executable, "-m", "sotpy", "serve", "talos", "--zenoh", str(toml)]
    cmd += ["--connection-file", str(workdir / "connection.json")]
    return subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)


def run_controller(port: int, duration: float = 2.0, dt: float = 1e-3) -> dict[str, Any]:
    """The reach controller of ``sotpy demo talos``, on the state received from the
    device process at tcp/127.0.0.1:port; runs ``duration / dt`` lock-step ticks and
    returns the states it received (``q``: ticks + 1 rows), the target and the wrist's
    final distance to it."""
    config = loopbackConfig(connect=[f"tcp/127.0.0.1:{port}"])
    r = load_robot("talos", prefix="reach_talos")  # the model (its Device is removed below)
    dyn, model = r.dynamic, r.model
    sub = ZenohSubscribe("ctrl_sub", config)
    sub.add("vector", "state", "sotpy/talos/state", size=model.nq)
    sub.add("vector", "velocity", "sotpy/talos/velocity", size=model.nv)
    for name in ("state", "velocity"):
        sub.setSync(name, 120.0)  # the device may still be loading Talos
    plug(sub.state, dyn.position)
    plug(sub.velocity, dyn.velocity)
    pub = ZenohPublish("ctrl_pub", config)
    pub.add("vector", "control", "sotpy/talos/control", size=model.nv)
    if not (pub.waitForSubscribers(120) and sub.wait("state", 120)):
        raise RuntimeError("the device process did not come up")
    t0 = 0

    # level 1: both feet fixed and the CoM over the support polygon (one TaskInequality)
    feet = [r.tasks["left-ankle"], r.tasks["right-ankle"]]
    balance = r.tasks["balance"]
    balance.setMargin(MARGIN)
    balance.task.dt.value = dt
    contact = TaskInequality("task_reach_talos_contact")
    for f in [m.feature for m in feet]:
        contact.add(f)
    contact.add(balance.feature)
    neq = sum(int(m.feature.error(t0).shape[0]) for m in feet)
    bounds = balance.bounds()
    contact.referenceInf.value = np.concatenate((np.zeros(neq), np.full(len(bounds), -np.inf)))
    contact.referenceSup.value = np.concatenate((np.zeros(neq), bounds))
    contact.dt.value = dt
    contact.controlGain.value = CONTACT_GAIN
    # level 2: the right wrist to its target; level 3: half-sitting
    wrist = r.tasks["right-wrist"]
    target = dyn.signal("right-wrist")(t0).translation + np.array(REACH_OFFSETS["talos"])
    wrist.gotoNd(target, "111000", gain=WRIST_GAIN)
    r.tasks["posture"].gain.setConstant(POSTURE_GAIN)
    sot = SOT("reach_talos_sot", dyn)
    sot.dt.value = dt
    for task in (contact, wrist.task, r.tasks["posture"].task):
        sot.push(task)
    for task in (wrist.task, r.tasks["posture"].task):
        sot.setTaskDamping(task, 0.0)
    plug(sot.control, pub.control)
    # the ready tasks that read the device's state (the posture) read the received one;
    # the local device leaves the graph, so that nothing can read it unnoticed
    for entity in pool.entities():
        for sig in entity.signals():
            if isinstance(sig, InputSignal) and sig.source is r.device.state:
                plug(sub.state, sig)
            elif isinstance(sig, InputSignal) and sig.source is r.device.velocity:
                plug(sub.velocity, sig)
    pool.remove(r.device)

    # the tick now waits for the device's state of the same tick, at most 1 s
    for name in ("state", "velocity"):
        sub.setSync(name, 1.0)
    steps = max(1, round(duration / dt))
    qs = np.empty((steps + 1, model.nq))
    us = np.empty((steps + 1, model.nv))
    loop = ControlLoop("ctrl_loop", pub, dt)
    wall = time.perf_counter()
    for k in range(steps + 1):  # tick k: the state of tick k in, the control of tick k out
        loop.step(1)
        qs[k] = sub.state(k)
        us[k] = pub.control(k)
    wall = time.perf_counter() - wall
    error = float(np.linalg.norm(dyn.signal("right-wrist")(steps).translation - target))
    return {
        "q": qs,
        "control": us,
        "target": target,
        "wrist_final": error,
        "ticks": steps,
        "wall": wall,
    }


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n", 1)[0])
    parser.add_argument("--duration", type=float, default=2.0, help="simulated time, s")
    parser.add_argument("--compare", action="store_true", help="run sotpy demo talos after")
    args = parser.parse_args()
    port = free_port()
    with tempfile.TemporaryDirectory() as tmp:
        device = start_device(port, Path(tmp))
        try:
            result = run_controller(port, args.duration)
        finally:
            time.sleep(1.5)  # the device's next tick waits 1 s, then stops safely
            device.terminate()
            out, _ = device.communicate(timeout=30)
    print("device process:\n  " + "\n  ".join(out.strip().splitlines()[-8:]))
    n, err = result["ticks"], result["wrist_final"]
    reached = err <= REACH_TOLERANCE
    print(
        f"controller process: {n} lock-step ticks in {result['wall']:.2f} s; the wrist "
        f"{'reached' if reached else 'did NOT reach'} its target ({err:.1e} m, tolerance "
        f"{REACH_TOLERANCE:g} m)"
    )
    ok = reached
    if args.compare:
        single = run_reach("talos", duration=n * 1e-3, quiet=True)
        diff = float(np.abs(single["q"] - result["q"]).max())
        print(
            f"single process (sotpy demo talos): wrist {single['wrist_final']:.1e} m; largest "
            f"difference between the two trajectories {diff:.1e}"
        )
        ok = ok and diff <= 1e-12
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
