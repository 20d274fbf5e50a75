"""Cost of the data-flow core per signal per tick (issue 2's benchmark).

For layered random DAGs of 10, 100, 1,000 and 10,000 signals (each callback a trivial
add of two parents, the first layer reading one state signal written every tick):

* **floor**: a straight-line Python function, generated once, that calls the same
  callbacks in the same order with the values in local variables: the work itself,
  with no framework at all;
* **plan**: ``Plan(sinks).run(t)``, the tick loop's path;
* **lazy**: reading every sink with ``sink(t)``, the scripts' and shell's path;
* **re-read**: ``sig.value`` of an up-to-date signal.

Every measure is a median over repeats, in ns per signal per tick, and the ratios are
taken within the same run. Usage::

    python benchmarks/bench_graph.py            # full run, prints a Markdown table
    python benchmarks/bench_graph.py --quick    # smaller sizes, for a smoke check
"""

from __future__ import annotations

import argparse
import random
import statistics
import time

from sotpy._bench import machine_line
from sotpy.graph import DOUBLE, Entity, Input, Output, Plan, plug, pool


class BenchAdd(Entity):
    """s = a + b."""

    a = Input(DOUBLE)
    b = Input(DOUBLE)

    @Output(DOUBLE, deps=("a", "b"))
    def s(self, a: float, b: float) -> float:
        return a + b


class BenchSource(Entity):
    """A state signal written every tick (like a device's state)."""

    state = Output(DOUBLE, initial=0.0)


def build(n: int, width: int = 10, seed: int = 0):
    """A layered DAG of ``n`` adders; returns (source, adders in topological order, sinks).

    The sinks are every output no adder reads, so a tick evaluates all ``n`` signals."""
    pool.clear()
    rng = random.Random(seed)
    src = BenchSource("src")
    layers = [[src.state]]
    nodes: list[BenchAdd] = []
    while len(nodes) < n:
        layer = []
        for _ in range(min(width, n - len(nodes))):
            e = BenchAdd(f"n{len(nodes)}")
            plug(rng.choice(layers[-1]), e.a)
            plug(rng.choice(layers[max(0, len(layers) - 2)]), e.b)
            layer.append(e.s)
            nodes.append(e)
        layers.append(layer)
    sinks = [e.s for e in nodes if not e.s._dependants]
    return src, nodes, sinks


def floor_function(src: BenchSource, nodes: list[BenchAdd]):
    """Generate the straight-line code that does the same adds with locals."""
    names = {id(src.state): "x_src"}
    ns = {}
    lines = ["def floor(x_src):"]
    for i, e in enumerate(nodes):
        a = names[id(e.a.source)]
        b = names[id(e.b.source)]
        ns[f"f{i}"] = e.s._fn
        lines.append(f" x{i} = f{i}({a}, {b})")
        names[id(e.s)] = f"x{i}"
    lines.append(f" return x{len(nodes) - 1}")
    exec(compile("\n".join(lines), "<floor>", "exec"), ns)
    return ns["floor"]


def _time_ns(fn, ticks: int, n: int) -> float:
    t0 = time.perf_counter()
    fn(ticks)
    return (time.perf_counter() - t0) / ticks / n * 1e9


def measure(n: int, repeats: int = 7) -> dict[str, float]:
    src, nodes, sinks = build(n)
    plan = Plan(sinks)
    ticks = max(5, 20_000 // n)
    state = src.state
    clock = [0]

    def run_plan(k: int) -> None:
        t = clock[0]
        for _ in range(k):
            t += 1
            state.write(float(t), t)
            plan.run(t)
        clock[0] = t

    def run_lazy(k: int) -> None:
        t = clock[0]
        for _ in range(k):
            t += 1
            state.write(float(t), t)
            for s in sinks:
                s(t)
        clock[0] = t

    floor = floor_function(src, nodes)

    def run_floor(k: int) -> None:
        for i in range(k):
            floor(float(i))

    last = nodes[-1].s

    def run_reread(k: int) -> None:
        for _ in range(k):
            last.value  # noqa: B018

    run_plan(2)  # compile, warm up
    # correctness: the three paths agree on the last sink
    run_plan(1)
    t = clock[0]
    assert floor(float(t)) == last.value, "plan and floor disagree"
    assert all(e.s.time == t for e in nodes), "the plan left a signal outdated"
    run_lazy(1)
    assert floor(float(clock[0])) == last.value, "lazy pull and floor disagree"
    assert all(e.s.time == clock[0] for e in nodes), "the lazy pull left a signal outdated"
    # Interleave the paths in each repeat and take ratios within a repeat: the machine's
    # speed drifts between repeats, much less within one.
    samples: dict[str, list[float]] = {"floor": [], "plan": [], "lazy": [], "reread": []}
    ratios: dict[str, list[float]] = {"plan": [], "lazy": []}
    for _ in range(repeats):
        f = _time_ns(run_floor, ticks, n)
        p = _time_ns(run_plan, ticks, n)
        lz = _time_ns(run_lazy, ticks, n)
        samples["floor"].append(f)
        samples["plan"].append(p)
        samples["lazy"].append(lz)
        samples["reread"].append(_time_ns(run_reread, 20_000, 1))
        ratios["plan"].append(p / f)
        ratios["lazy"].append(lz / f)
    row = {key: statistics.median(v) for key, v in samples.items()}
    row["n"] = n
    row["plan/floor"] = statistics.median(ratios["plan"])
    row["lazy/floor"] = statistics.median(ratios["lazy"])
    row["compile_us"] = _compile_us(sinks, n)
    return row


def _compile_us(sinks, n: int) -> float:
    """Microseconds per signal to compile a plan (sort and group the steps)."""
    best = float("inf")
    for _ in range(3):
        plan = Plan(sinks)
        t0 = time.perf_counter()
        plan.compile()
        best = min(best, (time.perf_counter() - t0) / n * 1e6)
    return best


def main(argv: list[str] | None = None) -> list[dict[str, float]]:
    parser = argparse.ArgumentParser(description=__doc__.split("\n", 1)[0])
    parser.add_argument("--quick", action="store_true", help="sizes 10 and 100 only")
    args = parser.parse_args(argv)
    sizes = (10, 100) if args.quick else (10, 100, 1000, 10_000)
    rows = [measure(n, repeats=3 if args.quick else 9) for n in sizes]
    print(machine_line())
    print(
        "| signals | floor ns | plan ns | plan/floor | lazy ns | lazy/floor | re-read ns "
        "| plan compile us/signal |"
    )
    print("|---:|---:|---:|---:|---:|---:|---:|---:|")
    for r in rows:
        print(
            f"| {r['n']:,} | {r['floor']:.0f} | {r['plan']:.0f} | {r['plan/floor']:.2f} "
            f"| {r['lazy']:.0f} | {r['lazy/floor']:.2f} | {r['reread']:.0f} "
            f"| {r['compile_us']:.1f} |"
        )
    return rows


if __name__ == "__main__":
    main()
