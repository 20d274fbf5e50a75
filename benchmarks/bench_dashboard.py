"""What the dashboard's page costs the 1 kHz Talos reach loop (issue 22).

The loop is ``sotpy demo talos``'s graph (built by :func:`sotpy.demos.reach.run_reach`
for one tick) ticked by a :class:`~sotpy.loop.ControlLoop` at 1 kHz in real time. The
run alternates four phases of ``--seconds`` each, ``--rounds`` times, in one process (the
order reversed every other round, so that a drift of the machine's speed weighs on every
kind alike):

* **without**: the loop alone (no dashboard);
* **with**: a :class:`~sotpy.dashboard.Dashboard` on the loop and its page open in
  headless Chromium with 5 live plots (the SOT's control, the wrist task's error, the
  posture task's error, the CoM, the device's state: 3 components each) refreshed at 30
  frames/s; the phase is measured once the page receives frames.

* **browser elsewhere** (a control, to tell the browser's CPU from the dashboard's): the
  loop alone, while another process serves a UR5 loop's dashboard to the same headless
  Chromium page with 5 plots: what the browser alone takes from a 2-core machine.

* **client**: the dashboard on the loop, its 5 plots read by a websocket client in
  another process that renders nothing (the page's traffic without the browser's CPU):
  the dashboard's own cost in the loop's process.

The loop runs on a CPU of its own (``ControlLoop(..., cpus={N})``, by default the last
CPU, ``--loop-cpu``), and everything else off it: the dashboard's threads (its
``cpus``), Chromium (``HeadlessPage(..., cpus=loop.otherCpus())``) and this script's
other processes. That is how a 1 kHz loop is run beside a browser on one machine;
``--no-pin`` lets the OS place everything, as before 2026-12-04.

Reported: the tick time (``device.increment``; the dashboard's recorder works between the
ticks, see ``docs/dashboard.md``) median and p99 of each phase, pooled over the rounds,
and their ratios with over without (and the ratio of medians of each round's two
phases); the frames the page received per second and those skipped.
Target (issue 22): median +5 % at most, p99 +10 % at most.

``--parts`` measures instead each part of that cost on its own, in short real-time
phases of the loop alternating in one process, each over the same round's loop alone:
computing after each tick (15 us that touch no memory), writing 512 KB after each tick,
the dashboard's recorder alone, a dashboard whose 5 plots a client reads, and the same
serving code (rows read from a ring in shared memory, sent 30 times a second to a reader
process) run in a thread of the loop's process or in a process of its own. It tells
what costs the loop a tick (BENCHMARKS.md, "What a dashboard costs the loop, part by
part").

Usage::

    python benchmarks/bench_dashboard.py                # 3 rounds of 8 s each
    python benchmarks/bench_dashboard.py --quick        # 1 round of 2 s, a smoke check
    python benchmarks/bench_dashboard.py --parts --rounds 14 --seconds 1.5
"""

from __future__ import annotations

import os

# the compiled kernels are what is measured: compiled first on a fresh machine, not the
# NumPy twins that a first run uses while they compile in the background
os.environ.setdefault("SOTPY_JIT", "wait")

import argparse
import contextlib
import sys
import time
from collections.abc import Callable, Iterator
from typing import Any

import numpy as np

from sotpy._bench import machine_line
from sotpy.graph import pool

PLOTS = (  # (signal, components): 5 plots of 3 lines
    ("{p}_sot.control", [6, 7, 8]),
    ("task_{p}_right-wrist.error", [0, 1, 2]),
    ("task_{p}_posture.error", [0, 1, 2]),
    ("{p}_dynamic.com", [0, 1, 2]),
    ("{p}_device.state", [7, 8, 9]),
)


def _ticks(loop) -> np.ndarray:
    """The tick times (s) of the phase just run: the loop's own record of each tick
    (``LoopStats`` gives mean and p99; the median needs the samples)."""
    tick_ns = loop._stats.tickNs  # the last `window` ticks' durations, a ring
    n = min(loop.ticks, len(tick_ns))
    return tick_ns[:n].astype(float) * 1e-9


def _phase(loop, seconds: float) -> np.ndarray:
    loop.start()
    time.sleep(seconds)
    loop.stop()
    return _ticks(loop)


_ELSEWHERE = """
import sys, time
sys.path.insert(0, {tests!r})
from test_dashboard import DT, ur5_reach
from sotpy.dashboard import Dashboard
from sotpy.loop import ControlLoop
robot, feature, task, sot = ur5_reach()
loop = ControlLoop("loop", robot.device, 0.001)
ui = Dashboard(loop)
print(ui.url(), flush=True)
loop.start()
sys.stdin.read()
"""


_CLIENT = """
import asyncio, json, sys, urllib.request, urllib.error
import tornado.httpclient, tornado.websocket
url, port, series = sys.argv[1], sys.argv[2], json.loads(sys.argv[3])
class NoRedirect(urllib.request.HTTPRedirectHandler):
    def redirect_request(self, *a, **k):
        return None
try:
    urllib.request.build_opener(NoRedirect).open(url)
except urllib.error.HTTPError as e:
    cookie = e.headers["Set-Cookie"].split(";")[0]
async def main():
    req = tornado.httpclient.HTTPRequest(f"ws://127.0.0.1:{port}/ws",
        headers={"Cookie": cookie, "Origin": f"http://127.0.0.1:{port}"})
    ws = await tornado.websocket.websocket_connect(req)
    for i, (path, comps) in enumerate(series):
        await ws.write_message(json.dumps({"id": i, "kind": "plot", "signal": path}))
    await ws.write_message(json.dumps({"id": 99, "kind": "series",
        "series": [[i, p, c] for i, (p, c) in enumerate(series)]}))
    n = 0
    while True:
        m = await ws.read_message()
        if m is None:
            break
        if isinstance(m, bytes):
            n += 1
            if n == 10:
                print("streaming", flush=True)
asyncio.run(main())
"""


@contextlib.contextmanager
def _reader(url: str, port: int, series: list) -> Iterator[None]:
    """A websocket client in another process that plots ``series`` on the dashboard at
    ``url`` and reads its frames, drawing nothing (the page's traffic without a
    browser's CPU); entered once it has read 10 frames (a loop must be ticking)."""
    import json
    import subprocess

    proc = subprocess.Popen(
        [sys.executable, "-c", _CLIENT, url, str(port), json.dumps(series)],
        stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True,
    )  # fmt: skip
    try:
        assert proc.stdout.readline().strip() == "streaming"
        yield
    finally:
        proc.kill()
        proc.wait()


@contextlib.contextmanager
def _served(loop, series: list) -> Iterator[Any]:
    """A dashboard on the loop (yielded), ``series`` plotted by a client in another
    process that reads its frames."""
    from sotpy.dashboard import Dashboard

    ui = Dashboard(loop, seconds=5.0)
    try:
        loop.start()
        with _reader(ui.url(), ui.port, series):
            loop.stop()
            yield ui
    finally:
        loop.stop()
        ui.close()


def _client(loop, seconds: float, p: str) -> tuple[np.ndarray, float]:
    """The loop with the dashboard, its 5 plots read by a client in another process."""
    with _served(loop, [(sig.format(p=p), comps) for sig, comps in PLOTS]) as ui:
        f0 = sum(f for f, _ in ui.frameCounts())
        t0 = time.monotonic()
        ticks = _phase(loop, seconds)
        rate = (sum(f for f, _ in ui.frameCounts()) - f0) / (time.monotonic() - t0)
        return ticks, rate


def _elsewhere(loop, seconds: float) -> np.ndarray:
    """The loop alone while another process's dashboard feeds the browser 5 plots."""
    import subprocess
    from pathlib import Path

    from sotpy.dashboard.browser import HeadlessPage

    tests = str(Path(__file__).resolve().parents[1] / "tests")
    proc = subprocess.Popen(
        [sys.executable, "-c", _ELSEWHERE.format(tests=tests)],
        stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True,
    )  # fmt: skip
    try:
        url = proc.stdout.readline().strip()
        with HeadlessPage(url, 1600, 1000, cpus=loop.otherCpus()) as page:
            page.waitFor("document.querySelectorAll('#graph .node').length > 0", 60)
            for k in range(5):
                comps = [k % 4, k % 4 + 1, k % 4 + 2]
                page.evaluate(
                    "(() => { const q = newPlot(); "
                    f"addSeries('ur5_device.state', {comps}, q); }})()"
                )
            page.waitFor("sotpyDashboard.frames > 10", 30)
            return _phase(loop, seconds)
    finally:
        proc.stdin.close()
        proc.kill()
        proc.wait()


# -- --parts: where the cost comes from ------------------------------------------------
@contextlib.contextmanager
def _idleCall(loop, fn: Callable[[], None]) -> Iterator[None]:
    loop.addIdleCall(fn)
    try:
        yield
    finally:
        loop.rmIdleCall(fn)


def _busy() -> Callable[[], None]:
    """15 us of computing that touches no memory (a clock read in a loop)."""

    def fn() -> None:
        end = time.perf_counter_ns() + 15_000
        while time.perf_counter_ns() < end:
            pass

    return fn


def _memory() -> Callable[[], None]:
    """Writing 512 KB (about as long as ``_busy``, 13-15 us here)."""
    block = np.zeros(1 << 16)

    def fn() -> None:
        block[:] += 1.0

    return fn


@contextlib.contextmanager
def _recording(loop, series: list) -> Iterator[Any]:
    """A :class:`~sotpy.dashboard.model.Recorder` of ``series``, rows made by the loop's
    idle call as a dashboard's are (no server)."""
    from sotpy.dashboard.model import Recorder

    rec = Recorder("bench_rec", loop.device, 5.0, loop.dt)
    for path, _ in series:
        rec.add(path)
    rec.loop = loop
    rec.attach()
    try:
        with _idleCall(loop, rec.finishRow):
            yield rec
    finally:
        rec.detach()


# The same serving code in a thread of the loop's process or in a process of its own:
# every 1/30 s, the rows written since the last frame (3 components of each plotted
# signal) are read from a ring in shared memory and sent to a reader process.
_SERVE = r"""
import os, socket, time
from multiprocessing import shared_memory
import numpy as np

def serve(names, widths, size, port, cpus, stop):
    os.sched_setaffinity(0, cpus)
    shms = [shared_memory.SharedMemory(name=n) for n in names]
    count = np.ndarray((1,), np.int64, buffer=shms[0].buf)
    cols = [np.ndarray((size, w), np.float64, buffer=m.buf) for m, w in zip(shms[1:], widths)]
    sock = socket.create_connection(("127.0.0.1", port))
    last = int(count[0])
    while not stop():
        time.sleep(1 / 30)
        n = int(count[0])
        if n > last:
            rows = np.arange(last, n) % size
            frame = np.concatenate([c[rows, :3].ravel() for c in cols]).tobytes()
            sock.sendall(len(frame).to_bytes(4, "little") + frame)
            last = n
    sock.close()
    del count, cols
    for m in shms:
        m.close()
"""

_SERVE_PROCESS = (
    _SERVE
    + r"""
import json, sys
from multiprocessing import resource_tracker
resource_tracker.register = lambda *a, **k: None  # the loop's process owns the memory
a = json.loads(sys.argv[1])
serve(a["names"], a["widths"], a["size"], a["port"], set(a["cpus"]), lambda: False)
"""
)

_SINK = r"""
import os, socket, sys
os.sched_setaffinity(0, set(map(int, sys.argv[1].split(","))))
server = socket.socket()
server.bind(("127.0.0.1", 0))
server.listen(1)
print(server.getsockname()[1], flush=True)
conn, _ = server.accept()
while conn.recv(1 << 16):
    pass
"""


@contextlib.contextmanager
def _ringServed(loop, series: list, where: str) -> Iterator[None]:
    """The recorder of ``series`` with its columns in shared memory (the row count
    published after each tick), served by :data:`_SERVE` in a ``"thread"`` of this
    process or a ``"process"`` of its own, to a reader process that discards the
    frames."""
    import json
    import subprocess
    import threading
    from multiprocessing import shared_memory

    cpus = sorted(loop.otherCpus() or os.sched_getaffinity(0))
    with _recording(loop, series) as rec:
        loop.step(2)  # (under step, rows in the tick) the columns get their widths
        cols = [rec._columns[path] for path, _ in series]
        widths = [c.data.shape[1] for c in cols]
        shms = [shared_memory.SharedMemory(create=True, size=8)] + [
            shared_memory.SharedMemory(create=True, size=rec.size * w * 8) for w in widths
        ]
        count = [np.ndarray((1,), np.int64, buffer=shms[0].buf)]  # views, dropped at the end
        for c, m in zip(cols, shms[1:], strict=True):
            ring = np.ndarray(c.data.shape, np.float64, buffer=m.buf)
            ring[:] = c.data
            c.data = ring
        del ring

        def publish() -> None:
            count[0][0] = rec._count

        sink = subprocess.Popen(
            [sys.executable, "-c", _SINK, ",".join(map(str, cpus))],
            stdout=subprocess.PIPE, text=True,
        )  # fmt: skip
        stop = threading.Event()
        thread = server = None
        try:
            port = int(sink.stdout.readline())
            names = [m.name for m in shms]
            if where == "thread":
                scope: dict = {}
                exec(_SERVE, scope)
                thread = threading.Thread(
                    target=scope["serve"],
                    args=(names, widths, rec.size, port, set(cpus), stop.is_set),
                    daemon=True,
                )
                thread.start()
            else:
                args = {"names": names, "widths": widths, "size": rec.size, "port": port}
                args["cpus"] = cpus
                server = subprocess.Popen([sys.executable, "-c", _SERVE_PROCESS, json.dumps(args)])
            with _idleCall(loop, publish):
                yield
        finally:
            stop.set()
            if thread is not None:
                thread.join()
            for proc in (server, sink):
                if proc is not None:
                    proc.kill()
                    proc.wait()
            for c in cols:
                c.data = None
            count.clear()
            for m in shms:
                m.close()
                m.unlink()


def parts(loop, p: str, rounds: int, seconds: float) -> None:
    """Each part of a dashboard's cost on its own: real-time phases of ``seconds``, in
    one process, every kind once a round (the order reversed every other round), each
    phase's median tick over the same round's loop alone."""
    series = [(sig.format(p=p), comps) for sig, comps in PLOTS]
    kinds: list[tuple[str, Callable[[], contextlib.AbstractContextManager[None]]]] = [
        ("the loop alone", contextlib.nullcontext),
        ("15 us of computing after each tick", lambda: _idleCall(loop, _busy())),
        ("512 KB written after each tick", lambda: _idleCall(loop, _memory())),
        ("the recorder of the 5 plots", lambda: _recording(loop, series)),
        ("a dashboard, 5 plots read by a client", lambda: _served(loop, series)),
        ("the recorder, its rows served by a thread", lambda: _ringServed(loop, series, "thread")),
        ("the same, served by a process", lambda: _ringServed(loop, series, "process")),
    ]
    ticks: dict[str, list[np.ndarray]] = {name: [] for name, _ in kinds}
    for r in range(rounds):
        for name, make in kinds if r % 2 == 0 else kinds[::-1]:
            with make():
                loop.start()  # a first second unmeasured: every part settled
                time.sleep(min(1.0, seconds))
                loop.stop()
                ticks[name].append(_phase(loop, seconds))
        print(f"round {r + 1}/{rounds} done", flush=True)
    print(machine_line(f"numpy {np.__version__}"))
    print(f"Talos reach loop at 1 kHz, {rounds} x {seconds:g} s per part")
    print(f"{'':44s} {'median':>8s} {'ratio':>6s} {'(quartiles)':>14s}")
    alone = ticks[kinds[0][0]]
    for name, _ in kinds:
        r = [np.median(a) / np.median(b) for a, b in zip(ticks[name], alone, strict=True)]
        q1, q2, q3 = np.percentile(r, [25, 50, 75])
        med = np.median(np.concatenate(ticks[name])) * 1e6
        print(f"{name:44s} {med:6.1f}us {q2:6.3f}  ({q1:.3f}-{q3:.3f})")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seconds", type=float, default=8.0, help="length of each phase, s")
    ap.add_argument("--rounds", type=int, default=3, help="phases of each kind")
    ap.add_argument("--quick", action="store_true", help="1 round of 2 s")
    ap.add_argument(
        "--loop-cpu", type=int, default=None, help="the loop's CPU (default: the last one)"
    )
    ap.add_argument("--no-pin", action="store_true", help="let the OS place every thread")
    ap.add_argument(
        "--never-idle",
        action="store_true",
        help="the loop spins through the whole period (spin = dt): its CPU never idles",
    )
    ap.add_argument(
        "--parts",
        action="store_true",
        help="measure each part of the cost on its own instead (short phases, many rounds)",
    )
    args = ap.parse_args()
    if args.quick:
        args.seconds, args.rounds = 2.0, 1
    from sotpy.dashboard import Dashboard
    from sotpy.dashboard.browser import HeadlessPage
    from sotpy.demos.reach import run_reach
    from sotpy.loop import ControlLoop

    print("building the Talos reach graph (and compiling its kernels)...", flush=True)
    result = run_reach("talos", duration=0.001, dt=0.001, quiet=True)
    p = result["prefix"]
    device = pool.getEntity(f"{p}_device")
    cpus = sorted(os.sched_getaffinity(0))
    pin = not args.no_pin and len(cpus) > 1
    mine = {args.loop_cpu if args.loop_cpu is not None else cpus[-1]} if pin else None
    spin = {"spin": 0.001} if args.never_idle else {}
    loop = ControlLoop("bench_loop", device, 0.001, cpus=mine, **spin)
    others = loop.otherCpus()
    if others is not None:  # this thread, and the processes it starts: off the loop's CPU
        os.sched_setaffinity(0, others)
    placement = f"the loop on CPU {sorted(mine)}, the rest on {sorted(others)}" if pin else (
        "not pinned: the OS places every thread"
    )  # fmt: skip
    if args.never_idle:
        placement += "; the loop never idles (spin = dt)"
    loop.step(200)  # warm: plans compiled, caches filled
    if args.parts:
        parts(loop, p, args.rounds, args.seconds)
        return 0
    without, with_, frames, elsewhere, client, rates = [], [], [], [], [], []

    def page() -> None:
        ui = Dashboard(loop, seconds=5.0)
        try:
            with HeadlessPage(ui.url(), 1600, 1000, cpus=loop.otherCpus()) as page:
                page.waitFor("document.querySelectorAll('#graph .node').length > 0", 60)
                for sig, comps in PLOTS:
                    path = sig.format(p=p)
                    page.evaluate(
                        f"(() => {{ const q = newPlot(); addSeries({path!r}, {comps}, q); }})()"
                    )
                page.waitFor(
                    f"sotpyDashboard.plots.filter(q => q.series.length).length == {len(PLOTS)}", 30
                )
                loop.start()
                page.waitFor("sotpyDashboard.frames > 10", 30)
                loop.stop()
                f0 = page.evaluate("sotpyDashboard.frames")
                t0 = time.monotonic()
                with_.append(_phase(loop, args.seconds))
                dt = time.monotonic() - t0
                f1 = page.evaluate("sotpyDashboard.frames")
                skipped = sum(s for _, s in ui.frameCounts())
                frames.append(((f1 - f0) / dt, skipped))
                lines = page.evaluate("document.querySelectorAll('.plot .u-series').length")
                assert lines == len(PLOTS) * 4, lines  # each plot: time + 3 lines
        finally:
            ui.close()

    def withClient() -> None:
        ticks, rate = _client(loop, args.seconds, p)
        client.append(ticks)
        rates.append(rate)

    phases = [
        lambda: elsewhere.append(_elsewhere(loop, args.seconds)),
        withClient,
        lambda: without.append(_phase(loop, args.seconds)),
        page,
    ]
    for r in range(args.rounds):
        # the order reversed every other round: a drift of the machine over a round
        # weighs on every kind of phase alike
        for phase in phases if r % 2 == 0 else phases[::-1]:
            phase()
        print(f"round {r + 1}/{args.rounds} done", flush=True)
    a, b, c = np.concatenate(without), np.concatenate(with_), np.concatenate(elsewhere)
    med_a, med_b = np.median(a), np.median(b)
    p99_a, p99_b = np.percentile(a, 99), np.percentile(b, 99)
    print(machine_line(f"numpy {np.__version__}"))
    print(
        f"Talos reach loop at 1 kHz, {args.rounds} x {args.seconds:g} s per phase, "
        f"{len(a)} ticks without the page, {len(b)} with it; {placement}"
    )
    print(f"{'':28s} {'median':>10s} {'p99':>10s}")
    print(f"{'without the dashboard':28s} {med_a * 1e6:8.1f}us {p99_a * 1e6:8.1f}us")
    print(f"{'with the page, 5 plots':28s} {med_b * 1e6:8.1f}us {p99_b * 1e6:8.1f}us")
    print(f"{'ratio (target 1.05 / 1.10)':28s} {med_b / med_a:10.3f} {p99_b / p99_a:10.3f}")
    per = [np.median(w) / np.median(o) for w, o in zip(with_, without, strict=True)]
    print(f"{'  per round (median)':28s} " + ", ".join(f"{x:.3f}" for x in per))
    med_c, p99_c = np.median(c), np.percentile(c, 99)
    print(f"{'browser elsewhere (control)':28s} {med_c * 1e6:8.1f}us {p99_c * 1e6:8.1f}us")
    print(f"{'  ratio to without':28s} {med_c / med_a:10.3f} {p99_c / p99_a:10.3f}")
    print(f"{'with the page / elsewhere':28s} {med_b / med_c:10.3f} {p99_b / p99_c:10.3f}")
    d = np.concatenate(client)
    med_d, p99_d = np.median(d), np.percentile(d, 99)
    print(f"{'client in another process':28s} {med_d * 1e6:8.1f}us {p99_d * 1e6:8.1f}us")
    print(f"{'  ratio to without':28s} {med_d / med_a:10.3f} {p99_d / p99_a:10.3f}")
    print(f"  (the client received {np.mean(rates):.1f} frames/s)")
    print(
        f"ticks achieved per second: without {len(a) / (args.rounds * args.seconds):.0f}, "
        f"with {len(b) / (args.rounds * args.seconds):.0f}, elsewhere "
        f"{len(c) / (args.rounds * args.seconds):.0f}"
    )
    rate = np.mean([f for f, _ in frames])
    print(f"page: {rate:.1f} frames/s received, {sum(s for _, s in frames)} skipped (busy page)")
    ok = med_b / med_a <= 1.05 and p99_b / p99_a <= 1.10
    print("target met" if ok else "target NOT met")
    return 0


if __name__ == "__main__":
    sys.exit(main())
