"""HierarchySolver.stacked / solve_stacked: a stack written in place into the solver's
buffers gives what solve() gives for the same levels (the same arithmetic: the results
are compared exactly), with the same errors; the buffers follow the level sizes."""

from __future__ import annotations

import numpy as np
import pytest

from sotpy.solvers import HierarchySolver, SolverError
from test_hierarchy import equality_stack, mixed_stack, three


def write(solver: HierarchySolver, levels) -> None:
    """Write ``levels`` (``(A, b)`` or ``(A, lower, upper)``) into ``solver``'s buffers."""
    A, lo, up, starts = solver.stacked([len(level[0]) for level in levels])
    for k, level in enumerate(levels):
        s, e = starts[k], starts[k + 1]
        A[s:e] = level[0]
        lo[s:e] = level[1]
        up[s:e] = level[-1]


def assert_identical(a, b) -> None:
    np.testing.assert_array_equal(a.x, b.x)
    np.testing.assert_array_equal(a.residuals, b.residuals)
    np.testing.assert_array_equal(a.ranks, b.ranks)
    assert (a.method, a.status, a.iterations, a.n_active, a.feasible) == (
        b.method,
        b.status,
        b.iterations,
        b.n_active,
        b.feasible,
    )


@pytest.mark.parametrize("seed", range(8))
@pytest.mark.parametrize("kind", ["mixed", "equality", "equality as bounds", "box-reach"])
def test_stacked_solve_is_the_solve_of_the_same_levels(seed, kind):
    """Over a few ticks of a drifting stack (the warm starts and the remembered active
    set matter), each of two solvers fed the same levels, one through solve(levels),
    one written in place: the same results, bit for bit."""
    rng = np.random.default_rng(6100 + seed)
    if kind == "box-reach":
        n = int(rng.integers(8, 16))
        half = rng.uniform(0.2, 0.6, n)
        upper = rng.standard_normal((5, n))
        last = rng.standard_normal((n, n))
        target = 2.0 * rng.standard_normal(n)
        base = [(np.eye(n), -half, half), (upper, np.zeros(5), np.zeros(5)), (last, target)]
    else:
        base = mixed_stack(rng) if kind == "mixed" else equality_stack(rng)
        n = base[0][0].shape[1]
    by_levels, in_place = HierarchySolver(n), HierarchySolver(n)
    for t in range(4):
        drift = 1.0 + 0.1 * t
        levels = [(lv[0], *(drift * v for v in lv[1:])) for lv in base]
        if kind == "equality as bounds":
            levels = three(levels)
        expected = by_levels.solve(levels)
        write(in_place, levels)
        got = in_place.solve_stacked(equality=kind == "equality")
        assert_identical(got, expected)
        if kind == "box-reach" and t > 0:
            assert got.method == "active-set"  # the compiled box path, from its guess


def test_per_level_damping_as_in_solve():
    rng = np.random.default_rng(6200)
    levels = equality_stack(rng)
    damping = [0.0] + [0.05] * (len(levels) - 1)
    n = levels[0][0].shape[1]
    expected = HierarchySolver(n).solve(levels, damping)
    solver = HierarchySolver(n)
    write(solver, levels)
    assert_identical(solver.solve_stacked(damping, equality=True), expected)


def _bad_stacks():
    base = [
        (np.eye(3), -np.ones(3), np.ones(3)),
        (np.ones((2, 3)), np.array([1.0, 2.0]), np.array([1.0, 2.0])),
        (np.array([[1.0, 2.0, 3.0]]), np.array([0.0]), np.array([0.0])),
    ]
    nan_A = [lv for lv in base]
    A = base[1][0].copy()
    A[1, 2] = np.nan
    nan_A[1] = (A, base[1][1], base[1][2])
    nan_bound = list(base)
    nan_bound[0] = (np.eye(3), np.array([-1.0, np.nan, -1.0]), np.ones(3))
    crossed = list(base)
    crossed[0] = (np.eye(3), np.array([-1.0, -1.0, 2.0]), np.ones(3))
    inf_eq = list(base)
    inf_eq[2] = (base[2][0], np.array([np.inf]), np.array([np.inf]))
    return {"nan A": nan_A, "nan bound": nan_bound, "lower > upper": crossed, "inf eq": inf_eq}


@pytest.mark.parametrize("case", list(_bad_stacks()))
def test_bad_rows_raise_what_solve_raises(case):
    levels = _bad_stacks()[case]
    with pytest.raises(SolverError) as expected:
        HierarchySolver(3).solve(levels)
    solver = HierarchySolver(3)
    write(solver, levels)
    with pytest.raises(SolverError) as got:
        solver.solve_stacked()
    assert str(got.value) == str(expected.value)
    assert "level" in str(got.value) and "row" in str(got.value)


def test_nan_target_of_an_equality_stack_is_named():
    levels = [(np.eye(2), np.array([1.0, 2.0])), (np.ones((1, 2)), np.array([np.nan]))]
    with pytest.raises(SolverError) as expected:
        HierarchySolver(2).solve(levels)
    solver = HierarchySolver(2)
    write(solver, levels)
    with pytest.raises(SolverError) as got:
        solver.solve_stacked(equality=True)
    assert str(got.value) == str(expected.value)
    assert "level 1, row 0" in str(got.value)


def test_buffers_follow_the_sizes():
    solver = HierarchySolver(4)
    A, lo, up, starts = solver.stacked((2, 3))
    assert A.shape == (5, 4) and lo.shape == up.shape == (5,) and list(starts) == [0, 2, 5]
    again = solver.stacked([2, 3])
    assert again[0].base is A.base and again[1] is lo  # the same sizes: the same buffers
    other = solver.stacked((3, 3))
    assert other[0].shape == (6, 4) and other[1] is not lo
    # a solve() with other sizes replaces them too: what was written is gone
    solver.solve([(np.eye(4), np.zeros(4))])
    assert solver.stacked((4,))[0].shape == (4, 4)


def test_stacked_needs_the_number_of_variables_and_sizes():
    with pytest.raises(SolverError, match="number of variables is unknown"):
        HierarchySolver().stacked((2,))
    with pytest.raises(SolverError, match="negative level size"):
        HierarchySolver(3).stacked((2, -1))
    with pytest.raises(SolverError, match="call stacked"):
        HierarchySolver(3).solve_stacked()
