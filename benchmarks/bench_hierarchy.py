"""Cost of ``sotpy.solvers`` per solve on drifting stacks (the microbenchmark; the worst
cases are ``bench_worst_case.py``).

Two stacks on ``n = 40`` variables whose data drift slowly from one solve to the next
(as Jacobians and errors do from one control tick to the next):

* **equality**: 6 equality levels of 12/3/6/6/3/34 rows (level 2 holds a duplicated row
  with an offset target: a conflict inside the level; the last level has more rows
  than free directions);
* **inequalities**: a box on 34 of the variables first (joint limits as the SOT passes
  them), an inequality task of 6 two-sided rows, then equality levels of 12/6/3 rows
  and a 34-row "posture" level. Two variants: ``free`` (bounds wide, none active) and
  ``active`` (bounds that the posture and the inequality task push against: rows held
  at their bounds every tick).
* **box + equalities** (the SOT's stand-and-reach shape): the same box, tight, then the
  equality levels only; bounds are active every tick.

Each variant is timed for the persistent :class:`HierarchySolver` (the SOT's path, with
its default time budget) and for the references of ``tests/reference_hierarchy.py`` in
the same run (the n x n projector + SVD recursion; the plain proxsuite cascade, fewer
solves). Answers at ticks far apart are checked against the references (largest
difference of level residuals) by a solver without a budget (a budgeted one, jumping
between those ticks, would stop at its budget: that is what the worst-case benchmark
measures); the iterations per solve and the budget hits of the timed run are reported.
Usage::

    python benchmarks/bench_hierarchy.py            # full run, prints Markdown
    python benchmarks/bench_hierarchy.py --quick    # fewer solves, for a smoke check
"""

from __future__ import annotations

import os

# the compiled kernels are what is measured: compiled first on a fresh machine, not the
# NumPy twins that a first run uses while they compile in the background
os.environ.setdefault("SOTPY_JIT", "wait")

import argparse
import importlib.util
import time
from pathlib import Path

import numpy as np

from sotpy._bench import machine_line
from sotpy.solvers import HierarchySolver, solve_hierarchy

N = 40


def _reference():
    path = Path(__file__).resolve().parents[1] / "tests" / "reference_hierarchy.py"
    spec = importlib.util.spec_from_file_location("reference_hierarchy", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


class EqualityStack:
    """6 drifting equality levels, 12/3/6/6/3/34 rows, one conflicting row pair."""

    rows = (12, 3, 6, 6, 3, 34)

    def __init__(self, seed: int = 0):
        rng = np.random.default_rng(seed)
        self.A = [rng.standard_normal((m, N)) for m in self.rows]
        self.b = [rng.standard_normal(m) for m in self.rows]
        self.dA = [rng.standard_normal((m, N)) for m in self.rows]
        self.db = [rng.standard_normal(m) for m in self.rows]

    def levels(self, t: int):
        out = []
        s = 0.02 * np.sin(0.01 * t)
        c = 0.1 * np.cos(0.013 * t)
        for k in range(len(self.rows)):
            A = self.A[k] + s * self.dA[k]
            b = self.b[k] + c * self.db[k]
            if k == 2:  # conflict: the same row twice, two targets
                A[1] = A[0]
                b[1] = b[0] + 0.5
            out.append((A, b))
        return out


class InequalityStack:
    """Box on the 34 joint variables, a 6-row inequality task, equality levels."""

    def __init__(self, active: bool, seed: int = 1):
        rng = np.random.default_rng(seed)
        self.active = active
        self.box = np.zeros((N - 6, N))
        self.box[:, 6:] = np.eye(N - 6)
        self.qmax = rng.uniform(0.5, 1.0, N - 6) * (0.6 if active else 50.0)
        self.C = rng.standard_normal((6, N))
        self.c = rng.standard_normal(6) * 0.5
        self.width = 1.0 if active else 100.0
        self.A = [rng.standard_normal((m, N)) for m in (12, 6, 3)]
        self.b = [rng.standard_normal(m) for m in (12, 6, 3)]
        self.post = np.zeros((N - 6, N))
        self.post[:, 6:] = np.eye(N - 6)
        self.target = rng.standard_normal(N - 6)
        self.dA = [rng.standard_normal(a.shape) for a in self.A]

    def levels(self, t: int):
        s = 0.02 * np.sin(0.01 * t)
        wave = np.sin(0.02 * t + np.arange(N - 6))
        hi = self.qmax * (1.0 + 0.3 * wave)
        lo = -self.qmax * (1.0 - 0.3 * wave)
        out = [(self.box, lo, hi)]
        C = self.C + s * self.A[0][:6]
        out.append((C, self.c - self.width, self.c + self.width))
        for A, dA, b in zip(self.A, self.dA, self.b, strict=True):
            out.append((A + s * dA, b * (1.0 + 0.1 * np.sin(0.005 * t))))
        out.append((self.post, self.target * (1.0 + 0.2 * wave)))
        return out


class BoxStack(InequalityStack):
    """The box, tight, then equality levels only (no inequality task)."""

    def __init__(self, seed: int = 1):
        super().__init__(active=True, seed=seed)

    def levels(self, t: int):
        out = super().levels(t)
        return [out[0], *out[2:]]


def _timed(fn, inputs):
    times = np.empty(len(inputs))
    out = None
    for i, levels in enumerate(inputs):
        t0 = time.perf_counter()
        out = fn(levels)
        times[i] = time.perf_counter() - t0
    return times * 1e6, out


def _row(name, times, extra=""):
    return (
        f"| {name} | {np.median(times):.0f} | {np.percentile(times, 99):.0f} |"
        f" {times.max():.0f} | {extra} |"
    )


def run(n_solves: int, n_ref: int, **budget: float | None) -> str:
    ref = _reference()
    lines = [
        "## sotpy.solvers: hierarchical least squares, n = 40",
        "",
        machine_line(),
        "",
        "Times in us per solve (median / p99 / max over the drifting sequence).",
        "",
        "| case | median | p99 | max | notes |",
        "|---|---|---|---|---|",
    ]
    # ---------------------------------------------------------------- equality
    eq = EqualityStack()
    inputs = [eq.levels(t) for t in range(n_solves)]
    solver = HierarchySolver(**budget)
    for levels in inputs[:20]:  # warm-up (buffers, merge plan)
        solver.solve(levels)
    t_solver, _ = _timed(solver.solve, inputs)
    t_oneshot, _ = _timed(solve_hierarchy, inputs[:n_ref])
    t_ref, _ = _timed(ref.projector_hierarchy, inputs[:n_ref])
    worst = 0.0
    check = HierarchySolver(time_budget=None)
    for levels in inputs[:: max(1, n_solves // 50)]:
        x_ref, _ = ref.projector_hierarchy(levels)
        worst = max(worst, float(np.abs(check.solve(levels).x - x_ref).max()))
    damped = HierarchySolver(damping=0.05, **budget)
    t_damped, _ = _timed(damped.solve, inputs)
    lines += [
        _row("equality, HierarchySolver.solve", t_solver, f"max abs(x - ref) {worst:.1e}"),
        _row("equality, solve_hierarchy (one-shot)", t_oneshot),
        _row("equality, damped 0.05", t_damped),
        _row("equality, reference: projectors + SVD", t_ref),
    ]
    # ------------------------------------------------------------ inequalities
    for active in (False, True):
        name = "active" if active else "free"
        ineq = InequalityStack(active)
        inputs = [ineq.levels(t) for t in range(n_solves)]
        solver = HierarchySolver(**budget)
        for levels in inputs[:20]:
            solver.solve(levels)
        its: list[int] = []
        hits: list[bool] = []

        def solve(levels, solver=solver, its=its, hits=hits):
            r = solver.solve(levels)
            its.append(r.iterations)
            hits.append(r.budget_hit)
            return r

        times, _ = _timed(solve, inputs)
        worst = 0.0
        check = HierarchySolver(time_budget=None)
        for levels in inputs[:: max(1, n_solves // 10)][:n_ref]:
            _, opt = ref.cascade_hierarchy([_three(lv) for lv in levels])
            res = check.solve(levels).residuals
            worst = max(worst, float(np.abs(res - np.array(opt)).max()))
        note = (
            f"iterations per solve {np.mean(its):.2f} (max {max(its)}), budget hits"
            f" {sum(hits)}, max residual error {worst:.1e}"
        )
        lines.append(_row(f"inequalities {name}, HierarchySolver.solve", times, note))
        t_ref, _ = _timed(
            lambda levels: ref.cascade_hierarchy([_three(lv) for lv in levels]),
            inputs[: max(3, n_ref // 10)],
        )
        lines.append(_row(f"inequalities {name}, reference: plain proxsuite cascade", t_ref))
    # ------------------------------------------------------- box + equalities
    box = BoxStack()
    inputs = [box.levels(t) for t in range(n_solves)]
    solver = HierarchySolver(**budget)
    for levels in inputs[:20]:
        solver.solve(levels)
    its = []

    def solve_box(levels):
        r = solver.solve(levels)
        its.append(r.iterations)
        return r

    t_box, _ = _timed(solve_box, inputs)
    worst = 0.0
    check = HierarchySolver(time_budget=None)
    for levels in inputs[:: max(1, n_solves // 10)][:n_ref]:
        _, opt = ref.cascade_hierarchy([_three(lv) for lv in levels])
        worst = max(worst, float(np.abs(check.solve(levels).residuals - np.array(opt)).max()))
    lines.append(
        _row(
            "box + equalities, HierarchySolver.solve",
            t_box,
            f"iterations per solve {np.mean(its):.2f}; max residual error {worst:.1e}",
        )
    )
    return "\n".join(lines)


def _three(level):
    return level if len(level) == 3 else (level[0], level[1], level[1])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="fewer solves (smoke check)")
    args = parser.parse_args()
    print(run(200, 20) if args.quick else run(3000, 200))


if __name__ == "__main__":
    main()
