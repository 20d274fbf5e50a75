"""What the dashboard's page costs the 1 kHz Talos reach loop (issue 22).

The loop is ``sotpy demo talos``'s graph (built by :func:`sotpy.demos.reach.run_reach`
for one tick) ticked by a :class:`~sotpy.loop.ControlLoop` at 1 kHz in real time. The
run alternates two phases of ``--seconds`` each, ``--rounds`` times, in one process:

* **without**: the loop alone (no dashboard);
* **with**: a :class:`~sotpy.dashboard.Dashboard` on the loop and its page open in
  headless Chromium with 5 live plots (the SOT's control, the wrist task's error, the
  posture task's error, the CoM, the device's state: 3 components each) refreshed at 30
  frames/s; the phase is measured once the page receives frames.

Reported: the tick time (``device.increment``, which includes the dashboard's recorder:
it runs in the tick) median and p99 of each phase, pooled over the rounds, and their
ratios with over without; the frames the page received per second and those skipped.
Target (issue 22): median +5 % at most, p99 +10 % at most.

Usage::

    python benchmarks/bench_dashboard.py                # 3 rounds of 8 s each
    python benchmarks/bench_dashboard.py --quick        # 1 round of 2 s, a smoke check
"""

from __future__ import annotations

import argparse
import sys
import time

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
    n = min(loop.ticks, len(loop._tickNs))
    return loop._tickNs[:n].astype(float) * 1e-9


def _phase(loop, seconds: float) -> np.ndarray:
    loop.start()
    time.sleep(seconds)
    loop.stop()
    return _ticks(loop)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seconds", type=float, default=8.0, help="length of each phase, s")
    ap.add_argument("--rounds", type=int, default=3, help="phases of each kind")
    ap.add_argument("--quick", action="store_true", help="1 round of 2 s")
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
    loop = ControlLoop("bench_loop", device, 0.001)
    loop.step(200)  # warm: plans compiled, caches filled
    without, with_, frames = [], [], []
    for r in range(args.rounds):
        without.append(_phase(loop, args.seconds))
        ui = Dashboard(loop, seconds=5.0)
        try:
            with HeadlessPage(ui.url(), 1600, 1000) as page:
                page.waitFor("document.querySelectorAll('#graph .node').length > 0", 60)
                for sig, comps in PLOTS:
                    path = sig.format(p=p)
                    page.evaluate(f"(() => {{ const q = newPlot(); addSeries({path!r}, {comps}, q); }})()")
                page.waitFor(f"sotpyDashboard.plots.filter(q => q.series.length).length == {len(PLOTS)}", 30)
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
        print(f"round {r + 1}/{args.rounds} done", flush=True)
    a, b = np.concatenate(without), np.concatenate(with_)
    med_a, med_b = np.median(a), np.median(b)
    p99_a, p99_b = np.percentile(a, 99), np.percentile(b, 99)
    print(machine_line(f"numpy {np.__version__}"))
    print(
        f"Talos reach loop at 1 kHz, {args.rounds} x {args.seconds:g} s per phase, "
        f"{len(a)} ticks without the page, {len(b)} with it"
    )
    print(f"{'':28s} {'median':>10s} {'p99':>10s}")
    print(f"{'without the dashboard':28s} {med_a * 1e6:8.1f}us {p99_a * 1e6:8.1f}us")
    print(f"{'with the page, 5 plots':28s} {med_b * 1e6:8.1f}us {p99_b * 1e6:8.1f}us")
    print(
        f"{'ratio (target 1.05 / 1.10)':28s} {med_b / med_a:10.3f} {p99_b / p99_a:10.3f}"
    )
    rate = np.mean([f for f, _ in frames])
    print(f"page: {rate:.1f} frames/s received, {sum(s for _, s in frames)} skipped (busy page)")
    ok = med_b / med_a <= 1.05 and p99_b / p99_a <= 1.10
    print("target met" if ok else "target NOT met")
    return 0


if __name__ == "__main__":
    sys.exit(main())
