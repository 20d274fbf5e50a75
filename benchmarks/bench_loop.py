"""The real-time loop's tick against the same tick run back to back: how the wait between
ticks changes the tick.

The graph is ``sotpy demo talos``'s reach (built by :func:`sotpy.demos.reach.run_reach`
for one tick), ticked by a :class:`~sotpy.loop.ControlLoop` at 1 kHz in real time, in
phases of ``--seconds`` that alternate ``--rounds`` times in one process:

* **sleep only** (``spin=0``): the thread sleeps until each deadline;
* **default** (``spin=200 us``): it sleeps until 200 us before the deadline, then yields;
* **never idle** (``spin=dt``): it yields for the whole period, so its CPU never idles;
* **default, not pinned**: the default wait, the thread wherever the OS puts it.

The first three run on a CPU of their own (``cpus={N}``, the last CPU by default) with this
script's other threads on the others. The reference is the tick run back to back
(``loop.step``, as fast as possible, hot caches), measured between the phases.

Reported per phase, pooled over the rounds: the tick time (``device.increment``) median,
p99 and worst, and the latency (how late each tick started after its deadline) median,
p99 and worst, and the deadline misses.

Usage::

    python benchmarks/bench_loop.py               # 3 rounds of 4 s
    python benchmarks/bench_loop.py --quick       # 1 round of 1 s, a smoke check
"""

from __future__ import annotations

import os

# the compiled kernels are what is measured: compiled first on a fresh machine, not the
# NumPy twins that a first run uses while they compile in the background
os.environ.setdefault("SOTPY_JIT", "wait")

import argparse
import sys
import time

import numpy as np

from sotpy._bench import machine_line
from sotpy.graph import pool


def _phase(loop, seconds: float) -> tuple[np.ndarray, np.ndarray, int]:
    """Run ``loop`` in real time for ``seconds``: (tick times, latencies, misses)."""
    loop.start()
    time.sleep(seconds)
    loop.stop()
    st = loop._stats  # the last `window` ticks, a ring (LoopStats gives mean and p99)
    n = min(loop.ticks, len(st.tickNs))
    return st.tickNs[:n].astype(float) * 1e-9, st.latNs[:n].astype(float) * 1e-9, st.misses


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seconds", type=float, default=4.0, help="length of each phase, s")
    ap.add_argument("--rounds", type=int, default=3, help="phases of each kind")
    ap.add_argument("--quick", action="store_true", help="1 round of 1 s")
    ap.add_argument("--cpu", type=int, default=None, help="the loop's CPU (default: the last)")
    args = ap.parse_args()
    if args.quick:
        args.seconds, args.rounds = 1.0, 1
    from sotpy.demos.reach import run_reach
    from sotpy.loop import DEFAULT_SPIN, ControlLoop

    print("building the Talos reach graph (and compiling its kernels)...", flush=True)
    result = run_reach("talos", duration=0.001, dt=0.001, quiet=True)
    device = pool.getEntity(f"{result['prefix']}_device")
    dt = 1e-3
    cpus = sorted(os.sched_getaffinity(0))
    mine = {args.cpu if args.cpu is not None else cpus[-1]}
    modes = {  # name: (spin, cpus)
        "sleep only (spin 0)": (0.0, mine),
        f"default (spin {DEFAULT_SPIN * 1e6:.0f} us)": (DEFAULT_SPIN, mine),
        "never idle (spin = dt)": (dt, mine),
        "default, not pinned": (DEFAULT_SPIN, None),
    }
    loops = {
        name: ControlLoop(f"bench_loop_{k}", device, dt, spin=spin, cpus=where)
        for k, (name, (spin, where)) in enumerate(modes.items())
    }
    rest = set(cpus) - mine
    if rest:  # this thread off the loop's CPU (the unpinned loop may still go anywhere)
        os.sched_setaffinity(0, rest)
    reference = next(iter(loops.values()))
    reference.step(200)  # warm: plans compiled, caches filled
    got: dict[str, list[tuple[np.ndarray, np.ndarray, int]]] = {name: [] for name in modes}
    back: list[float] = []
    for r in range(args.rounds):
        for name, loop in loops.items():
            got[name].append(_phase(loop, args.seconds))
        for _ in range(2000):
            t0 = time.perf_counter_ns()
            device.increment(dt)
            back.append((time.perf_counter_ns() - t0) * 1e-9)
        print(f"round {r + 1}/{args.rounds} done", flush=True)
    print(machine_line(f"numpy {np.__version__}"))
    print(
        f"Talos reach loop at 1 kHz, {args.rounds} x {args.seconds:g} s per phase; pinned "
        f"phases on CPU {sorted(mine)}, this script's threads on {sorted(rest) or 'the same'}"
    )
    us = 1e6
    b = np.asarray(back)
    print(
        f"back to back (device.increment in a loop): median {np.median(b) * us:.1f} us, "
        f"p99 {np.percentile(b, 99) * us:.1f} us\n"
    )
    print("| wait | tick median / p99 / worst (us) | latency median / p99 / worst (us) | misses |")
    print("|---|---:|---:|---:|")
    for name, runs in got.items():
        tick = np.concatenate([x[0] for x in runs])
        lat = np.concatenate([x[1] for x in runs])
        misses = sum(x[2] for x in runs)
        print(
            f"| {name} | {np.median(tick) * us:.1f} / {np.percentile(tick, 99) * us:.1f} / "
            f"{tick.max() * us:.0f} | {np.median(lat) * us:.1f} / "
            f"{np.percentile(lat, 99) * us:.1f} / {lat.max() * us:.0f} | {misses} |"
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
