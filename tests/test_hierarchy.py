"""sotpy.solvers.solve_hierarchy / HierarchySolver against independent references.

The references (tests/reference_hierarchy.py) share no code with sotpy: n x n projectors
and numpy's SVD for equality-only stacks, a plain cascade of proxsuite QPs in the full
variable (eps 1e-10) for stacks with inequalities. Stacks are seeded random draws with
the hard cases built in: rank-deficient levels, conflicting rows (duplicated rows with
offset targets), rows that depend on the levels above, infeasible levels, inequalities
at several levels, a box as the first level.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from reference_hierarchy import (
    cascade_hierarchy,
    level_residuals,
    projector_hierarchy,
    violation,
)
from sotpy.errors import SotpyError
from sotpy.solvers import (
    HierarchyResult,
    HierarchySolver,
    SolverError,
    _activeset_jit,
    solve_hierarchy,
)

#: the compiled iteration and its NumPy twin (both are checked against the references)
JITS = (True, False) if _activeset_jit.solve is not None else (False,)
# accuracy of the cascade comparisons: the reference solves QPs to ~1e-9..1e-10
QP_TOL = 1e-6


# ------------------------------------------------------------------ stacks
def equality_stack(rng, n=None, p=None):
    """Random equality levels with a rank-deficient level (consistent duplicate), a
    conflicting pair (same row, different targets), a row depending on level 0 and a
    last level with more rows than directions left."""
    n = n or int(rng.integers(6, 25))
    p = p or int(rng.integers(4, 7))
    levels = []
    for _ in range(p):
        m = int(rng.integers(2, 8))
        levels.append([rng.standard_normal((m, n)), rng.standard_normal(m)])
    A, b = levels[1]
    A[-1] = 2.0 * A[0]  # rank-deficient, consistent
    b[-1] = 2.0 * b[0]
    A, b = levels[2]
    A[1] = A[0]  # conflicting
    b[1] = b[0] + 1.0
    A, b = levels[3]
    A[0] = levels[0][0][0] - 0.5 * levels[0][0][1]  # depends on level 0: rank 0 there
    last = rng.standard_normal((n + 3, n))
    levels.append([last, rng.standard_normal(n + 3)])
    return [(A, b) for A, b in levels]


def mixed_stack(rng, n=None):
    """A box first, then 3-5 levels of equalities, one-sided or two-sided inequalities
    (some levels mixed), duplicated rows, offset duplicates."""
    n = n or int(rng.integers(4, 13))
    levels = [(np.eye(n), -rng.uniform(0.1, 1.0, n), rng.uniform(0.1, 1.0, n))]
    for _ in range(int(rng.integers(3, 6))):
        m = int(rng.integers(1, 7))
        A = rng.standard_normal((m, n))
        c = 2.0 * rng.standard_normal(m)
        kind = rng.integers(0, 3)
        if kind == 0:
            lo, up = c, c.copy()
        elif kind == 1:
            lo, up = np.full(m, -np.inf), c
        else:
            lo, up = c - rng.uniform(0, 1, m), c + rng.uniform(0, 1, m)
            if m > 1:
                lo[0] = up[0] = c[0]
        if m >= 2 and rng.random() < 0.3:
            A[1] = A[0]
            if kind == 0:
                lo[1] = up[1] = lo[0] + 0.5
        levels.append((A, np.asarray(lo, float), np.asarray(up, float)))
    return levels


def three(levels):
    return [lv if len(lv) == 3 else (lv[0], lv[1], lv[1]) for lv in levels]


def scaled(x):
    return 1.0 + float(np.abs(x).max())


# ----------------------------------------------------------- equality stacks
@pytest.mark.parametrize("seed", range(12))
@pytest.mark.parametrize("damping", [0.0, 0.1])
def test_equality_stack_matches_projector_reference(seed, damping):
    rng = np.random.default_rng(seed)
    levels = equality_stack(rng)
    x_ref, optimal = projector_hierarchy(levels, damping=damping)
    res = solve_hierarchy(levels, damping=damping)
    assert res.method == "equality"
    assert np.abs(res.x - x_ref).max() <= 1e-9 * scaled(x_ref)
    # each level's residual is its optimum over the optimal set of the levels above
    np.testing.assert_allclose(res.residuals, optimal, rtol=1e-9, atol=1e-9 * scaled(x_ref))
    np.testing.assert_allclose(res.residuals, level_residuals(three(levels), res.x), atol=1e-12)


def test_equality_known_answer_rank_deficient_and_conflicting():
    # level 0: x0 = 1 and x0 = 3 (conflict); level 1: x0 + x1 = 5 and its double (rank 1);
    # level 2: x0 + x1 = 4 (depends on level 1: nothing left to choose, residual 1)
    levels = [
        (np.array([[1.0, 0, 0], [1.0, 0, 0]]), np.array([1.0, 3.0])),
        (np.array([[1.0, 1, 0], [2.0, 2, 0]]), np.array([5.0, 10.0])),
        (np.array([[1.0, 1, 0]]), np.array([4.0])),
    ]
    res = solve_hierarchy(levels)
    np.testing.assert_allclose(res.x, [2.0, 3.0, 0.0], atol=1e-12)
    np.testing.assert_allclose(res.residuals, [math.sqrt(2.0), 0.0, 1.0], atol=1e-12)
    assert list(res.ranks) == [1, 1, 0]
    assert list(res.satisfied) == [False, True, False]
    assert not res.feasible


def test_equality_minimum_norm_among_optimal_points():
    rng = np.random.default_rng(7)
    n = 12
    levels = [(rng.standard_normal((3, n)), rng.standard_normal(3)) for _ in range(2)]
    res = solve_hierarchy(levels)
    # any other optimal point: x + a null-space direction of both levels
    A = np.vstack([a for a, _ in levels])
    _, s, vt = np.linalg.svd(A)
    null = vt[len(s[s > 1e-12]) :]
    assert null.shape[0] == n - 6
    assert np.abs(null @ res.x).max() < 1e-12  # x is orthogonal to the optimal set's directions
    for y in rng.standard_normal((5, null.shape[0])):
        other = res.x + null.T @ y
        np.testing.assert_allclose(level_residuals(three(levels), other), res.residuals, atol=1e-12)
        assert np.linalg.norm(other) > np.linalg.norm(res.x)


def test_persistent_solver_drifting_equality_stack_with_rank_changes():
    """Warm structure (merged blocks of full-rank levels) gives the cold answers, also when
    a level loses rank in the middle of the sequence (the merged block must split)."""
    rng = np.random.default_rng(3)
    n = 20
    base = [(rng.standard_normal((m, n)), rng.standard_normal(m)) for m in (5, 4, 3, 6, 30)]
    solver = HierarchySolver(time_budget=None)
    for t in range(60):
        levels = []
        for k, (A, b) in enumerate(base):
            A = A + 0.01 * math.sin(0.1 * t + k)
            b = b * (1.0 + 0.05 * math.cos(0.2 * t))
            if k == 2 and 20 <= t < 40:
                A = A.copy()
                A[2] = A[0] + A[1]  # rank deficient for a while
            levels.append((A, b))
        x_ref, optimal = projector_hierarchy(levels)
        warm = solver.solve(levels)
        assert np.abs(warm.x - x_ref).max() <= 1e-9 * scaled(x_ref), t
        np.testing.assert_allclose(warm.residuals, optimal, atol=1e-9 * scaled(x_ref))
        assert warm.ranks[2] == (2 if 20 <= t < 40 else 3)


def test_truncated_equality_stack_keeps_upper_residuals():
    rng = np.random.default_rng(11)
    levels = equality_stack(rng, n=15, p=5)
    full = solve_hierarchy(levels)
    for k in range(1, len(levels)):
        part = solve_hierarchy(levels[:k])
        np.testing.assert_allclose(part.residuals, full.residuals[:k], atol=1e-10)


def test_singular_level_is_bounded():
    """A nearly singular level (a stretched arm): the rank threshold drops the tiny
    direction instead of dividing by it; damping keeps the step small as well."""
    A = np.array([[1.0, 0.0, 0.0], [0.0, 1e-13, 0.0]])
    b = np.array([0.5, 1.0])
    res = solve_hierarchy([(A, b)])
    assert np.abs(res.x).max() < 1.0
    assert res.ranks[0] == 1
    np.testing.assert_allclose(res.x, [0.5, 0.0, 0.0], atol=1e-12)
    A[1, 1] = 1e-6  # above the threshold: exact, large; damped: bounded
    assert abs(solve_hierarchy([(A, b)]).x[1] - 1e6) < 1e-3
    damped = solve_hierarchy([(A, b)], damping=1e-2)
    assert np.abs(damped.x).max() < 1e-3 + 0.5
    x_ref, _ = projector_hierarchy([(A, b)], damping=1e-2)
    np.testing.assert_allclose(damped.x, x_ref, atol=1e-12)


# ----------------------------------------------------- stacks with inequalities
def _check_against_cascade(levels, res, x_ref, optimal):
    tol = QP_TOL * scaled(x_ref)
    np.testing.assert_allclose(res.residuals, optimal, atol=tol)
    np.testing.assert_allclose(res.x, x_ref, atol=10 * tol)
    np.testing.assert_allclose(res.residuals, level_residuals(three(levels), res.x), atol=1e-12)


@pytest.mark.parametrize("jit", JITS)
@pytest.mark.parametrize("seed", range(10))
def test_mixed_stack_matches_cascade_reference(seed, jit):
    rng = np.random.default_rng(100 + seed)
    levels = mixed_stack(rng)
    x_ref, optimal = cascade_hierarchy(levels)
    res = solve_hierarchy(levels, jit=jit)
    assert res.converged and res.solved == len(levels)
    _check_against_cascade(levels, res, x_ref, optimal)
    # the box (first level) is feasible and met
    assert res.satisfied[0]


@pytest.mark.parametrize("seed", range(6))
def test_mixed_stack_damped_matches_damped_cascade(seed):
    rng = np.random.default_rng(200 + seed)
    levels = mixed_stack(rng)
    x_ref, optimal = cascade_hierarchy(levels, damping=0.3)
    for jit in JITS:
        res = solve_hierarchy(levels, damping=0.3, jit=jit)
        assert res.converged
        _check_against_cascade(levels, res, x_ref, optimal)


def test_shortcut_when_inequalities_are_inactive():
    rng = np.random.default_rng(5)
    n = 10
    eq = equality_stack(rng, n=n, p=4)
    wide = [(np.eye(n), -1e3 * np.ones(n), 1e3 * np.ones(n))]
    ineq = (rng.standard_normal((3, n)), np.full(3, -np.inf), np.full(3, 1e4))
    levels = wide + three(eq[:2]) + [ineq] + three(eq[2:])
    res = solve_hierarchy(levels)
    # one equality solve of the equality rows, every inequality row inside its bounds
    assert res.method == "active-set" and res.n_active == 0 and res.iterations == 1
    x_ref, _ = projector_hierarchy(eq)
    np.testing.assert_allclose(res.x, x_ref, atol=1e-9 * scaled(x_ref))


@pytest.mark.parametrize("seed", range(4))
def test_truncated_mixed_stack_keeps_upper_residuals(seed):
    rng = np.random.default_rng(400 + seed)
    levels = mixed_stack(rng)
    full = solve_hierarchy(levels)
    for k in range(1, len(levels)):
        part = solve_hierarchy(levels[:k])
        np.testing.assert_allclose(part.residuals, full.residuals[:k], atol=QP_TOL)


def test_inequality_known_answer():
    # hard box |x_i| <= 1; level 1: x0 + x1 <= -3 (infeasible with the box: best is
    # x0 = x1 = -1, violation 1); level 2: x0 = 0.5 (impossible now: violation 1.5);
    # level 3: x2 >= 0.25 (free: x2 = 0.25 by minimum norm)
    levels = [
        (np.eye(3), -np.ones(3), np.ones(3)),
        (np.array([[1.0, 1.0, 0.0]]), np.array([-np.inf]), np.array([-3.0])),
        (np.array([[1.0, 0.0, 0.0]]), np.array([0.5])),
        (np.array([[0.0, 0.0, 1.0]]), np.array([0.25]), np.array([np.inf])),
    ]
    # the box holds x0 and x1, level 1's row is held beyond its bound, level 3's at its
    # bound (met, kept by the minimum norm)
    for jit in JITS:
        res = HierarchySolver(jit=jit).solve(levels)
        np.testing.assert_allclose(res.x, [-1.0, -1.0, 0.25], atol=1e-12)
        np.testing.assert_allclose(res.residuals, [0.0, 1.0, 1.5, 0.0], atol=1e-12)
        assert list(res.satisfied) == [True, False, False, True]
        assert res.method == "active-set" and res.n_active == 4 and res.converged


def test_infeasible_hard_level_returns_least_violating_point():
    # level 0 asks x0 <= -1 and x0 >= 1: the least violation is x0 = 0 (sqrt(2))
    levels = [
        (np.array([[1.0, 0.0], [1.0, 0.0]]), np.array([-np.inf, 1.0]), np.array([-1.0, np.inf])),
        (np.array([[0.0, 1.0]]), np.array([2.0])),
    ]
    for jit in JITS:
        res = solve_hierarchy(levels, jit=jit)
        np.testing.assert_allclose(res.x, [0.0, 2.0], atol=1e-12)
        assert res.residuals[0] == pytest.approx(math.sqrt(2.0), abs=1e-7)
        assert not res.feasible and not res.satisfied[0] and res.satisfied[1]


def test_degenerate_inequalities():
    """Several inequality rows active at one vertex (more than the free directions), a
    zero row, a free row (both bounds infinite), an equality written as two rows."""
    n = 3
    A1 = np.array([[1.0, 0, 0], [0, 1.0, 0], [1.0, 1.0, 0], [1.0, -1.0, 0], [0, 0, 0.0]])
    levels = [
        (np.eye(n), -np.ones(n), np.ones(n)),
        (A1, np.array([-np.inf, -np.inf, -np.inf, -np.inf, -1.0]), np.array([0, 0, 0, 0, 1.0])),
        (np.array([[1.0, 1.0, 1.0]]), np.array([-np.inf]), np.array([np.inf])),
        (np.array([[1.0, 0, 0], [1.0, 0, 0]]), np.array([2.0, -np.inf]), np.array([np.inf, 2.0])),
        (np.array([[0, 0, 1.0]]), np.array([3.0])),
    ]
    x_ref, optimal = cascade_hierarchy(three(levels))
    for jit in JITS:
        res = solve_hierarchy(levels, jit=jit)
        assert res.converged
        _check_against_cascade(levels, res, x_ref, optimal)
    np.testing.assert_allclose(x_ref, [0.0, 0.0, 1.0], atol=1e-7)


@pytest.mark.parametrize("jit", JITS)
def test_warm_started_drift_matches_cold_solves(jit):
    """A persistent solver over slowly drifting data (box active part of the time, the
    inequality task active or violated) gives the answers of fresh solvers."""
    rng = np.random.default_rng(9)
    n = 12
    C = rng.standard_normal((3, n))
    A1, A2 = rng.standard_normal((4, n)), rng.standard_normal((n + 2, n))
    b1, b2 = rng.standard_normal(4), rng.standard_normal(n + 2)
    qmax = rng.uniform(0.3, 0.8, n)
    solver = HierarchySolver(jit=jit, time_budget=None)
    warm_its = cold_its = active = 0
    for t in range(40):
        s = math.sin(0.15 * t)
        levels = [
            (np.eye(n), -qmax * (1 + 0.5 * s), qmax * (1 - 0.5 * s)),
            (C + 0.01 * s, np.full(3, -np.inf), np.full(3, 0.5 * s)),
            (A1 + 0.02 * s, b1 * (1 + 0.3 * s)),
            (A2, b2 * (2 + s)),
        ]
        warm = solver.solve(levels)
        cold = HierarchySolver(jit=jit, time_budget=None).solve(levels)
        assert warm.converged and cold.converged
        np.testing.assert_allclose(warm.residuals, cold.residuals, atol=1e-10)
        np.testing.assert_allclose(warm.x, cold.x, atol=1e-10)
        assert warm.satisfied[0]
        x = warm.x
        assert (np.abs(x) <= qmax * (1 + 0.5 * abs(s)) + 1e-9).all()
        warm_its += warm.iterations
        cold_its += cold.iterations
        active += warm.n_active
    # the warm start pays: most ticks need the one equality solve of the kept active set
    assert active > 40 and warm_its < 0.6 * cold_its, (warm_its, cold_its)


def test_structure_changes_between_calls():
    rng = np.random.default_rng(21)
    solver = HierarchySolver(time_budget=None)
    for levels in (mixed_stack(rng, 6), equality_stack(rng, 8, 4), mixed_stack(rng, 6)):
        n = levels[0][0].shape[1]
        if n != solver.n:
            solver = HierarchySolver(time_budget=None)
        res = solver.solve(levels)
        fresh = solve_hierarchy(levels)
        np.testing.assert_allclose(res.x, fresh.x, atol=1e-8)
    # same n, other row counts and classes
    solver = HierarchySolver(time_budget=None)
    a = solver.solve([(np.eye(3), -np.ones(3), np.ones(3)), (np.ones((1, 3)), np.array([6.0]))])
    b = solver.solve([(np.ones((2, 3)), np.array([1.0, 1.0]))])
    np.testing.assert_allclose(a.x, [1.0, 1.0, 1.0], atol=1e-7)
    np.testing.assert_allclose(b.x, [1 / 3] * 3, atol=1e-12)


def test_empty_levels_and_free_rows():
    levels = [
        (np.zeros((0, 3)), np.zeros(0)),
        (np.array([[1.0, 0, 0]]), np.array([1.0])),
        (np.zeros((0, 3)), np.zeros(0), np.zeros(0)),
        (np.array([[0, 1.0, 0]]), np.array([-np.inf]), np.array([np.inf])),
    ]
    res = solve_hierarchy(levels)
    np.testing.assert_allclose(res.x, [1.0, 0.0, 0.0], atol=1e-12)
    np.testing.assert_allclose(res.residuals, 0.0, atol=1e-12)
    assert list(res.ranks) == [0, 1, 0, 0]


def test_result_object():
    res = solve_hierarchy([(np.eye(2), np.array([1.0, 2.0]))])
    assert isinstance(res, HierarchyResult)
    assert res.x.shape == (2,) and res.residuals.shape == (1,)
    assert res.tolerances.shape == (1,) and res.all_satisfied and res.feasible
    assert res.iterations == 1 and res.converged and res.status == "optimal"
    assert res.solved == 1 and res.stopped_level is None and not res.budget_hit
    assert "equality" in repr(res)
    # the returned x is a fresh array: the next solve does not change it
    solver = HierarchySolver(time_budget=None)
    first = solver.solve([(np.eye(2), np.array([1.0, 2.0]))])
    solver.solve([(np.eye(2), np.array([5.0, 6.0]))])
    np.testing.assert_allclose(first.x, [1.0, 2.0])


# ------------------------------------------------------------------ bad input
def _stack():
    return [
        (np.eye(3), -np.ones(3), np.ones(3)),
        (np.ones((2, 3)), np.array([1.0, 2.0])),
        (np.array([[1.0, 2.0, 3.0]]), np.array([0.0])),
    ]


@pytest.mark.parametrize("jit", JITS)
@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_non_finite_matrix_is_refused(bad, jit):
    levels = _stack()
    A = levels[1][0].copy()
    A[1, 2] = bad
    levels[1] = (A, levels[1][1])
    with pytest.raises(SolverError, match=r"level 1, row 1: A\[1, 2\]"):
        HierarchySolver(jit=jit).solve(levels)


@pytest.mark.parametrize("jit", JITS)
def test_nan_target_is_refused(jit):
    levels = _stack()
    levels[2] = (levels[2][0], np.array([np.nan]))
    with pytest.raises(SolverError, match=r"level 2, row 0"):
        HierarchySolver(jit=jit).solve(levels)


def test_nan_bound_is_refused():
    levels = _stack()
    levels[0] = (np.eye(3), np.array([-1.0, np.nan, -1.0]), np.ones(3))
    with pytest.raises(SolverError, match=r"level 0, row 1: lower is NaN"):
        solve_hierarchy(levels)


def test_lower_above_upper_is_refused():
    levels = _stack()
    levels[0] = (np.eye(3), np.array([-1.0, -1.0, 2.0]), np.ones(3))
    with pytest.raises(SolverError, match=r"level 0, row 2: lower \(2.0\) > upper \(1.0\)"):
        solve_hierarchy(levels)


def test_infinite_equality_is_refused():
    levels = _stack()
    levels[0] = (np.eye(3), np.array([-1.0, np.inf, -1.0]), np.array([1.0, np.inf, 1.0]))
    with pytest.raises(SolverError, match=r"level 0, row 1"):
        solve_hierarchy(levels)


def test_size_mismatches_are_refused():
    with pytest.raises(SolverError, match=r"level 1: A has 4 columns, expected 3"):
        solve_hierarchy([(np.eye(3), np.ones(3)), (np.ones((1, 4)), np.ones(1))])
    with pytest.raises(SolverError, match=r"level 0: b has shape \(2,\), expected \(3,\)"):
        solve_hierarchy([(np.eye(3), np.ones(2))])
    with pytest.raises(SolverError, match=r"level 0: upper has shape"):
        solve_hierarchy([(np.eye(3), np.ones(3), np.ones(4))])
    with pytest.raises(SolverError, match=r"level 0: A must be 2-D"):
        solve_hierarchy([(np.ones(3), np.ones(3))])
    with pytest.raises(SolverError, match=r"level 0: expected \(A, lower, upper\)"):
        solve_hierarchy([(np.eye(3),)])
    with pytest.raises(SolverError, match="no level"):
        solve_hierarchy([])
    solver = HierarchySolver(n=4)
    with pytest.raises(SolverError, match="expected 4"):
        solver.solve([(np.eye(3), np.ones(3))])
    # a refused call leaves the solver usable
    np.testing.assert_allclose(solver.solve([(np.eye(4), np.ones(4))]).x, np.ones(4))


def test_bad_parameters_are_refused():
    with pytest.raises(SolverError, match="damping"):
        solve_hierarchy([(np.eye(2), np.ones(2))], damping=-1.0)
    with pytest.raises(SolverError, match="damping"):
        HierarchySolver().solve([(np.eye(2), np.ones(2))], damping=float("nan"))
    for bad in (0, -1, 1.5, True, None):
        with pytest.raises(SolverError, match="max_iter must be an integer >= 1"):
            HierarchySolver(max_iter=bad)
    for bad in (0.0, -1e-3, math.nan, math.inf, "fast"):
        with pytest.raises(SolverError, match="time_budget must be a finite number"):
            HierarchySolver(time_budget=bad)
    solver = HierarchySolver(time_budget=1e-3, max_iter=7)
    with pytest.raises(SolverError, match="the setting is unchanged"):
        solver.time_budget = -1.0
    with pytest.raises(SolverError, match="the setting is unchanged"):
        solver.max_iter = 0
    assert solver.time_budget == 1e-3 and solver.max_iter == 7
    assert issubclass(SolverError, SotpyError) and issubclass(SolverError, ValueError)


def test_violation_helper_is_the_documented_definition():
    # guards the reference itself: distance of each row to its interval
    A = np.eye(3)
    v = violation(
        A, np.array([0.0, -np.inf, 1.0]), np.array([1.0, 0.0, 1.0]), np.array([2.0, 3.0, 0.5])
    )
    np.testing.assert_allclose(v, [1.0, 3.0, 0.5])


def test_benchmark_script_runs():
    """benchmarks/bench_hierarchy.py stays runnable; its own checks against the
    references are printed in the table (max differences)."""
    import importlib.util
    from pathlib import Path

    path = Path(__file__).resolve().parents[1] / "benchmarks" / "bench_hierarchy.py"
    spec = importlib.util.spec_from_file_location("bench_hierarchy", path)
    bench = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(bench)
    table = bench.run(25, 3, time_budget=None)  # answers that do not depend on the speed
    assert table.count("| equality") == 4 and table.count("| inequalities") == 4
    # the solver agrees with the reference cascade on the sampled solves
    for line in table.splitlines():
        if "max residual error" in line:
            assert float(line.split("max residual error ")[1].split()[0].rstrip("|")) < 1e-6, line
    eq = bench.EqualityStack().levels(3)
    x_ref, _ = projector_hierarchy(eq)
    np.testing.assert_allclose(
        HierarchySolver(time_budget=None).solve(eq).x, x_ref, atol=1e-9 * scaled(x_ref)
    )


# ------------------------------------------------------------ per-level damping
@pytest.mark.parametrize("seed", range(6))
def test_per_level_damping_matches_the_references(seed):
    """One damping per level (0 for the first ones, as the SOT does for hard levels):
    equality stacks against the projector reference, mixed stacks against the cascade."""
    rng = np.random.default_rng(1000 + seed)
    levels = equality_stack(rng)
    lams = [0.0, 0.0, *rng.uniform(0.0, 0.3, len(levels) - 2)]
    x_ref, optimal = projector_hierarchy(levels, damping=lams)
    res = solve_hierarchy(levels, damping=lams)
    assert np.abs(res.x - x_ref).max() <= 1e-9 * scaled(x_ref)
    np.testing.assert_allclose(res.residuals, optimal, rtol=1e-9, atol=1e-9 * scaled(x_ref))
    mixed = mixed_stack(rng)
    lams = [0.0, *rng.uniform(0.05, 0.3, len(mixed) - 1)]
    x_ref, optimal = cascade_hierarchy(mixed, damping=lams)
    solver = HierarchySolver(time_budget=None)
    for _ in range(2):  # the second call with the first one's warm starts and blocks
        _check_against_cascade(mixed, solver.solve(mixed, damping=lams), x_ref, optimal)


def test_undamped_first_level_keeps_its_exact_answer():
    """Damping the lower levels only leaves the first level exactly met (a damped first
    level would not be)."""
    rng = np.random.default_rng(77)
    A1, b1 = rng.standard_normal((3, 6)), rng.standard_normal(3)
    A2, b2 = rng.standard_normal((6, 6)), rng.standard_normal(6)
    res = solve_hierarchy([(A1, b1), (A2, b2)], damping=[0.0, 0.5])
    assert np.abs(A1 @ res.x - b1).max() < 1e-12
    damped_all = solve_hierarchy([(A1, b1), (A2, b2)], damping=0.5)
    assert np.abs(A1 @ damped_all.x - b1).max() > 1e-3


def test_bad_dampings_are_refused():
    levels = [(np.eye(2), np.ones(2)), (np.ones((1, 2)), np.ones(1))]
    with pytest.raises(SolverError, match="3 dampings for 2 levels"):
        solve_hierarchy(levels, damping=[0.0, 0.1, 0.2])
    with pytest.raises(SolverError, match="damping must be finite and >= 0"):
        solve_hierarchy(levels, damping=[0.0, -0.1])
    with pytest.raises(SolverError, match="one number per level"):
        solve_hierarchy(levels, damping="lots")
