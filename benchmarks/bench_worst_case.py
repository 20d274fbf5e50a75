"""The worst cases of the hierarchical solver: a 1 kHz controller is judged by its
slowest tick.

**Kinematic stacks** (``sotpy._bench.adversarial_stack``, seeded): ``n`` from 8 to 40 variables,
2 to 5 levels, often a box first; each level of rank-deficient rows (``U V^T``, rank below
the row count) scaled by 1 to 100, its rows equalities, one-sided bounds (lower or upper)
or two-sided; in most levels a pair of one-sided bounds that conflict along the same
direction (``a x >= c`` and ``-s a x >= c'``). Two ways to meet them:

* **cold**: each stack solved once by a new solver (no warm start), as a user's first
  tick or a stack just edited;
* **drifting**: each stack's data move a little at each of :data:`TICKS` ticks (matrix,
  bounds) and one persistent solver follows, as a control loop does.

**The SOT** (Talos, the tutorial's graph: feet and balance polygon in one
``TaskInequality``, wrist, posture): 2,000 ticks, its velocity limits cut to 5 % at
tick 500 (most joints reach them at once) and given back at tick 1,200.

**The torque level**: ``sotpy demo talos-torque``'s motion on the floor with the
hierarchical strategy (``MultiLevelWeighted``): the CoM shift in 1 s, the same in
0.18 s (aggressive), the hand reach; joint position and torque limits and the friction
pyramids in its hard level.

Each solve runs with its default budget (0.5 ms of CPU time a call, 1.5 ms at the torque
level; 2 ms for a solver's first call and the first after the level sizes changed), on a
frozen heap as a real-time
``ControlLoop`` runs (``sotpy.loop.frozenHeap``); reported: median, p99 and worst wall
time, the worst CPU time of the calling thread (what the budget counts: wall time adds
the pre-emptions by other processes of a shared machine), the budget hits, the iterations,
at the torque level the whole controller tick (Pinocchio's passes, the rows, the solve;
its wall times and its worst CPU time),
and for kinematic stacks the largest distance of a non-hit answer's level residuals to
those of the same stack solved with no budget (0 when the budget is the only
difference). Usage::

    python benchmarks/bench_worst_case.py            # full run, prints Markdown
    python benchmarks/bench_worst_case.py --quick    # fewer stacks and ticks
"""

from __future__ import annotations

import os

# the compiled kernels are what is measured: compiled first on a fresh machine, not the
# NumPy twins that a first run uses while they compile in the background
os.environ.setdefault("SOTPY_JIT", "wait")

import argparse
import math
import time
from typing import Any

import numpy as np

from sotpy._bench import adversarial_stack, machine_line
from sotpy.loop import frozenHeap
from sotpy.solvers import HierarchySolver

#: ticks of a drifting stack
TICKS = 40


def drifted(levels, rng: np.random.Generator, t: int):
    """``levels`` at tick ``t`` of a slow drift (each matrix and bound by a smooth
    multiple of a fixed random direction)."""
    out = []
    for k, (A, lo, up) in enumerate(levels):
        s = 0.02 * np.sin(0.2 * t + k)
        dA = np.random.default_rng(1000 + k).standard_normal(A.shape)
        db = np.random.default_rng(2000 + k).standard_normal(len(lo))
        out.append((A + s * np.abs(A).max() * dA, lo + s * db, up + s * db))
    return out


def _summary(times_us, hits, its, cpu_us, first) -> dict[str, Any]:
    """Wall-time statistics; the worst CPU time of the calls with the cold budget (a
    solver's first call, the first after a change of the level sizes) and of the others."""
    t = np.asarray(times_us)
    cpu, first = np.asarray(cpu_us), np.asarray(first, dtype=bool)
    return {
        "n": len(t),
        "median": float(np.median(t)),
        "p99": float(np.percentile(t, 99)),
        "worst": float(t.max()),
        "worst_cpu_first": float(cpu[first].max()) if first.any() else float("nan"),
        "worst_cpu": float(cpu[~first].max()) if (~first).any() else float("nan"),
        "hits": int(sum(hits)),
        "its": float(np.mean(its)),
        "its_max": int(max(its)),
    }


def _cold(solver: HierarchySolver, sizes: tuple[int, ...] | None = None) -> bool:
    """Whether the solver's next call gets the cold budget (``cold_time_budget``: no
    buffers yet, no warm start, or level sizes other than ``sizes``)."""
    buf = solver._buf
    return buf is None or not buf.warm or (sizes is not None and buf.sizes != sizes)


def kinematic(n_stacks: int, ticks: int) -> dict[str, dict[str, Any]]:
    """The cold and drifting runs over ``n_stacks`` seeded stacks, on a frozen heap (as a
    ControlLoop runs)."""
    with frozenHeap():
        return {mode: _kinematic(mode, n_stacks, ticks) for mode in ("cold", "drifting")}


def _kinematic(mode: str, n_stacks: int, ticks: int) -> dict[str, Any]:
    """One mode (``"cold"``: a new solver per stack; ``"drifting"``: one solver along
    the ticks) over ``n_stacks`` seeded stacks."""
    times, cpus, hits, its, gaps, first = [], [], [], [], [], []
    for seed in range(n_stacks):
        rng = np.random.default_rng(seed)
        base = adversarial_stack(rng)
        solver = HierarchySolver()
        steps = [base] if mode == "cold" else [drifted(base, rng, t) for t in range(ticks)]
        for levels in steps:
            if mode == "cold":
                solver = HierarchySolver()
            first.append(_cold(solver))
            t0, c0 = time.perf_counter(), time.thread_time()
            r = solver.solve(levels)
            times.append((time.perf_counter() - t0) * 1e6)
            cpus.append((time.thread_time() - c0) * 1e6)
            hits.append(r.budget_hit)
            its.append(r.iterations)
            if not r.budget_hit and len(gaps) < 300:
                exact = HierarchySolver(time_budget=None, max_iter=10_000).solve(levels)
                if not exact.converged:
                    raise RuntimeError(f"stack {seed}: no optimum without a budget either")
                scale = 1.0 + float(np.abs(exact.residuals).max())
                gaps.append(float(np.abs(r.residuals - exact.residuals).max()) / scale)
    s = _summary(times, hits, its, cpus, first)
    s["gap"] = max(gaps) if gaps else 0.0
    return s


def sot_limits(ticks: int) -> dict[str, Any]:
    """The tutorial's Talos graph with its velocity limits cut and given back."""
    import importlib.util
    from pathlib import Path

    from sotpy.graph import pool

    spec = importlib.util.spec_from_file_location(
        "bench_sot", Path(__file__).with_name("bench_sot.py")
    )
    bench_sot = importlib.util.module_from_spec(spec)
    import sys

    sys.modules["bench_sot"] = bench_sot
    spec.loader.exec_module(bench_sot)
    pool.clear()
    scene = bench_sot.reach_scene("talos")
    c = bench_sot.build_sotpy_tutorial(scene)
    solver = c.sot._solver
    calls: list[tuple[float, float, bool]] = []
    for name in ("solve", "solve_stacked"):
        real = getattr(solver, name)

        def timed(*a, real=real, **k):
            cold = _cold(solver)  # solve_stacked: stacked() has made the buffers
            t0, c0 = time.perf_counter(), time.thread_time()
            try:
                return real(*a, **k)
            finally:
                wall, cpu = (time.perf_counter() - t0) * 1e6, (time.thread_time() - c0) * 1e6
                calls.append((wall, cpu, cold))

        setattr(solver, name, timed)
    vmax = np.asarray(c.sot.upperVl.value).copy()
    c.sot.upperVl.value = vmax
    times, cpus, hits, its, first = [], [], [], [], []
    with frozenHeap():  # as a ControlLoop runs it
        for k in range(ticks):
            if k == ticks // 4:
                c.sot.upperVl.value = 0.05 * vmax
            if k == (3 * ticks) // 5:
                c.sot.upperVl.value = vmax
            n = len(calls)
            c.device.increment(bench_sot.DT)
            times.append(sum(w for w, _, _ in calls[n:]))
            cpus.append(sum(u for _, u, _ in calls[n:]))
            first.append(any(cold for _, _, cold in calls[n:]))
            r = c.sot.lastResult
            hits.append(r.budget_hit)
            its.append(r.iterations)
    pool.clear()
    return _summary(times, hits, its, cpus, first)


def torque(duration: float) -> dict[str, Any]:
    """The Talos torque demo, hierarchical strategy, each hierarchy solve timed, and each
    controller tick (``RobotModel.update``, Pinocchio's passes at the state, plus
    ``WholeBodyController.tick``: the rows and the solve) as ``tick_*``."""
    from sotpy.demos.torque import run_talos_torque
    from sotpy.graph import pool
    from sotpy.solvers.wbc.model import RobotModel
    from sotpy.solvers.wbc.solver import WholeBodyController

    times, cpus, hits, its, first = [], [], [], [], []
    ticks: list[float] = []
    tick_cpus: list[float] = []
    pending = [0.0, 0.0]  # the wall and CPU time of the last model update, added to its tick
    real = HierarchySolver.solve_stacked  # the controller writes its levels in place
    real_update, real_tick = RobotModel.update, WholeBodyController.tick

    def timed_update(self, *a, **k):
        t0, c0 = time.perf_counter(), time.thread_time()
        try:
            return real_update(self, *a, **k)
        finally:
            pending[0] += time.perf_counter() - t0
            pending[1] += time.thread_time() - c0

    def timed_tick(self, *a, **k):
        t0, c0 = time.perf_counter(), time.thread_time()
        try:
            return real_tick(self, *a, **k)
        finally:
            ticks.append((time.perf_counter() - t0 + pending[0]) * 1e6)
            tick_cpus.append((time.thread_time() - c0 + pending[1]) * 1e6)
            pending[0] = pending[1] = 0.0

    def timed(self, *a, **k):
        first.append(_cold(self))  # stacked() has made the buffers for this call's sizes
        t0, c0 = time.perf_counter(), time.thread_time()
        r = real(self, *a, **k)
        times.append((time.perf_counter() - t0) * 1e6)
        cpus.append((time.thread_time() - c0) * 1e6)
        hits.append(r.budget_hit)
        its.append(r.iterations)
        return r

    HierarchySolver.solve_stacked = timed  # type: ignore[method-assign]
    RobotModel.update = timed_update  # type: ignore[method-assign]
    WholeBodyController.tick = timed_tick  # type: ignore[method-assign]
    try:
        pool.clear()
        out = run_talos_torque(duration=duration, strategy="MultiLevelWeighted", prefix="wc")
    finally:
        HierarchySolver.solve_stacked = real  # type: ignore[method-assign]
        RobotModel.update = real_update  # type: ignore[method-assign]
        WholeBodyController.tick = real_tick  # type: ignore[method-assign]
        pool.clear()
    s = _summary(times, hits, its, cpus, first)
    s["ok"] = bool(out.get("ok", out.get("passed", True)))
    t = np.asarray(ticks)
    s["tick"] = (float(np.median(t)), float(np.percentile(t, 99)), float(t.max()))
    s["tick_cpu"] = float(max(tick_cpus))
    return s


def _us(value: float) -> str:
    """A time in us for the table, ``-`` where there was no such call."""
    return "-" if math.isnan(value) else f"{value:.0f}"


def table(rows: list[tuple[str, dict[str, Any]]]) -> str:
    lines = [
        "| case | solves | median us | p99 us | worst us | worst CPU us: cold calls / others"
        " | budget hits | iterations mean (max) | notes |",
        "|---|---:|---:|---:|---:|---:|---:|---|---|",
    ]
    for name, s in rows:
        note = ""
        if "gap" in s:
            note = f"non-hit answers vs no budget: {s['gap']:.1e}"
        if "ok" in s:
            note = "the demo's floor checks: " + ("met" if s["ok"] else "FAILED")
        if "tick" in s:
            note += "; controller tick median / p99 / worst {:.0f} / {:.0f} / {:.0f} us".format(
                *s["tick"]
            )
            note += f" (worst CPU {s['tick_cpu']:.0f} us)"
        lines.append(
            f"| {name} | {s['n']} | {s['median']:.0f} | {s['p99']:.0f} | {s['worst']:.0f}"
            f" | {_us(s['worst_cpu_first'])} / {_us(s['worst_cpu'])} | {s['hits']}"
            f" | {s['its']:.1f} ({s['its_max']}) | {note} |"
        )
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> list[tuple[str, dict[str, Any]]]:
    parser = argparse.ArgumentParser(description=__doc__.split("\n", 1)[0])
    parser.add_argument("--quick", action="store_true", help="fewer stacks and ticks")
    args = parser.parse_args(argv)
    stacks, ticks, sot_ticks = (30, 10, 600) if args.quick else (300, TICKS, 2000)
    print(machine_line())
    print(f"load average at start: {os.getloadavg()[0]:.2f}")
    print()
    rows: list[tuple[str, dict[str, Any]]] = []
    k = kinematic(stacks, ticks)
    rows.append((f"kinematic, cold ({stacks} stacks, n 8-40)", k["cold"]))
    rows.append((f"kinematic, drifting ({stacks} x {ticks} ticks)", k["drifting"]))
    rows.append(
        ("SOT Talos tutorial graph, velocity limits cut and restored", sot_limits(sot_ticks))
    )
    for d, name in ((1.0, "1 s"), (0.18, "0.18 s, aggressive")):
        rows.append((f"torque Talos hierarchical, CoM shift {name}", torque(d)))
    print(table(rows))
    return rows


if __name__ == "__main__":
    main()
