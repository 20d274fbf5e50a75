"""The benchmarks stay runnable, and what they check holds (evaluation paths agree,
answers are right)."""

import importlib.util
from pathlib import Path

import numpy as np
import pytest

from sotpy.graph import pool

BENCH = Path(__file__).resolve().parents[1] / "benchmarks" / "bench_graph.py"


@pytest.fixture(scope="module")
def bench():
    spec = importlib.util.spec_from_file_location("bench_graph", BENCH)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.mark.parametrize("n", [10, 300])
def test_plan_lazy_and_floor_agree(bench, n):
    # measure() asserts that the plan, the lazy pull and the generated floor give the same
    # value for the last sink; the timings themselves are only sanity-checked here.
    row = bench.measure(n, repeats=1)
    assert row["n"] == n
    for key in ("floor", "plan", "lazy", "reread"):
        assert 0 < row[key] < 1e6, (key, row[key])


COLLISION_BENCH = BENCH.with_name("bench_collision.py")


def test_collision_benchmark_runs_and_both_stacks_reach():
    spec = importlib.util.spec_from_file_location("bench_collision", COLLISION_BENCH)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    result = module.run(ticks=60, repeats=1)
    assert result["pairs"] > 800
    assert result["rows_end"][0] > 0 and result["narrow_end"][0] >= result["rows_end"][0]
    for name in ("without", "with"):
        s = result[name]
        assert 0 < s["median"] <= s["p99"] <= s["worst"] < 1e6, (name, s)
    assert result["ratio"] > 0
    # the collision level does not change where the wrist goes on this reach
    ((a, b),) = result["wrist_error"]
    assert abs(a - b) < 1e-3
    assert "ratio of medians" in module.table(result)


def test_collision_benchmark_floors_keep_their_first_rows():
    """The floors (``--floor``) keep the rows of their first tick while the robot
    moves; the coal floor still runs coal's queries, the rows floor does not."""
    spec = importlib.util.spec_from_file_location("bench_collision", COLLISION_BENCH)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    bench = module._bench_sot()
    scene = bench.reach_scene("talos")
    pool.clear()
    try:
        floors = {}
        for i, kind in enumerate(("coal", "rows")):
            c, f = module.build(bench, scene, True, f"floor{i}_")
            module.frozenPass(f, kind == "coal")
            floors[kind] = (c, f)
        first = {}
        for kind, (c, f) in floors.items():
            c.device.increment(0.001)
            first[kind] = (
                f.error.value.copy(),
                f.core._gdata.distanceResults[int(f.core.rowPairs[0])].min_distance,
            )
        for _ in range(40):  # the wrist moves, and the legs with the CoM
            for c, _f in floors.values():
                c.device.increment(0.001)
        for kind, (_c, f) in floors.items():
            rows, d0 = first[kind]
            np.testing.assert_array_equal(f.error.value, rows)  # the first tick's rows
            d = f.core._gdata.distanceResults[int(f.core.rowPairs[0])].min_distance
            assert (d != d0) == (kind == "coal"), (kind, d, d0)
    finally:
        pool.clear()


WORST_CASE_BENCH = BENCH.with_name("bench_worst_case.py")


def test_worst_case_benchmark_answers_are_the_unbudgeted_optimum():
    """kinematic() raises if a stack has no optimum without a budget, and records how far
    each answer that did not hit the budget is from that optimum."""
    spec = importlib.util.spec_from_file_location("bench_worst_case", WORST_CASE_BENCH)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    out = module.kinematic(n_stacks=4, ticks=3)
    assert out["cold"]["n"] == 4 and out["drifting"]["n"] == 12
    for mode, s in out.items():
        assert s["gap"] <= 1e-8, (mode, s)
        assert 0 < s["median"] <= s["p99"] <= s["worst"] < 1e7, (mode, s)
        assert s["its_max"] >= 1
