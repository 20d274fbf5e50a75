"""The active-set path for stacks whose first level is a box (the SOT's joint limits).

The path fixes the variables guessed at a bound, solves the equality rows below and
verifies the guess (primal feasibility, lexicographic multipliers); these tests compare
it with the independent cascade of tests/reference_hierarchy.py (QPs in the full
variable), force wrong guesses, and check that it is the path actually taken.
"""

from __future__ import annotations

import numpy as np
import pytest

from reference_hierarchy import cascade_hierarchy, level_residuals
from sotpy.solvers import HierarchySolver, solve_hierarchy

QP_TOL = 1e-6


def box_stack(rng, n=None, with_inequality=False, contains_zero=False):
    """A box on most variables (tight, so that bounds are active; rows shuffled, scaled
    by +-c), then equality levels: full rank, a rank-deficient one, a conflicting one,
    a last one with more rows than variables; optionally an inequality level."""
    n = n or int(rng.integers(6, 16))
    bounded = rng.permutation(n)[: max(1, n - int(rng.integers(0, 3)))]
    coef = rng.choice([-2.0, -1.0, 0.5, 1.0, 3.0], size=len(bounded))
    A0 = np.zeros((len(bounded), n))
    A0[np.arange(len(bounded)), bounded] = coef
    half = rng.uniform(0.05, 0.6, len(bounded))
    centre = rng.uniform(-0.3, 0.3, len(bounded))
    if contains_zero:
        centre *= half / 0.3
    # bounds on A0 x = coef x_j
    lo = np.minimum(coef * (centre - half), coef * (centre + half))
    up = np.maximum(coef * (centre - half), coef * (centre + half))
    one_sided = rng.random(len(bounded)) < 0.2
    lo[one_sided] = -np.inf
    levels = [(A0, lo, up)]
    for kind in ("full", "deficient", "conflict"):
        m = int(rng.integers(1, 4))
        A = rng.standard_normal((m + 1, n))
        b = 2.0 * rng.standard_normal(m + 1)
        if kind == "deficient":
            A[-1] = 2.0 * A[0]
            b[-1] = 2.0 * b[0]
        elif kind == "conflict":
            A[-1] = A[0]
            b[-1] = b[0] + 0.7
        levels.append((A, b, b.copy()))
    if with_inequality:
        A = rng.standard_normal((2, n))
        levels.append((A, np.full(2, -np.inf), np.full(2, 0.3)))
    A = rng.standard_normal((n + 2, n))
    b = rng.standard_normal(n + 2)
    levels.append((A, b, b.copy()))
    return levels


def check(levels, res, x_ref, optimal):
    scale = 1.0 + float(np.abs(x_ref).max())
    np.testing.assert_allclose(res.residuals, optimal, atol=QP_TOL * scale)
    np.testing.assert_allclose(res.x, x_ref, atol=10 * QP_TOL * scale)
    np.testing.assert_allclose(res.residuals, level_residuals(levels, res.x), atol=1e-12)
    assert res.satisfied[0]


@pytest.mark.parametrize("seed", range(16))
def test_box_stack_matches_cascade_reference(seed):
    rng = np.random.default_rng(700 + seed)
    levels = box_stack(rng, with_inequality=seed % 4 == 3)
    x_ref, optimal = cascade_hierarchy(levels)
    solver = HierarchySolver()
    first = solver.solve(levels)
    check(levels, first, x_ref, optimal)
    # the second call starts from the first one's active set: the box path, verified
    again = solver.solve(levels)
    check(levels, again, x_ref, optimal)
    if seed % 4 != 3:  # (with an active inequality level below, the cascade is right)
        assert again.method in ("active-set", "shortcut"), again.method
        assert again.qp_levels == ()


def test_box_path_is_taken_with_active_bounds():
    rng = np.random.default_rng(3)
    methods = []
    for _ in range(20):
        levels = box_stack(rng)
        solver = HierarchySolver()
        solver.solve(levels)
        methods.append(solver.solve(levels).method)
    # most of these stacks have active bounds; all are solved without a QP the 2nd time
    assert methods.count("active-set") >= 15
    assert "cascade" not in methods


@pytest.mark.parametrize("seed", range(10))
def test_wrong_guesses_are_corrected(seed):
    """Start from a corrupted active set (spurious bounds held, true ones released): the
    verification rejects it and the answer is still the lexicographic optimum."""
    rng = np.random.default_rng(800 + seed)
    levels = box_stack(rng)
    x_ref, optimal = cascade_hierarchy(levels)
    solver = HierarchySolver()
    solver.solve(levels)
    box = solver._structure.box
    n = levels[0][0].shape[1]
    flip = rng.random(n) < 0.5
    finite_lo, finite_hi = np.isfinite(box.lo), np.isfinite(box.hi)
    box.at_lo[:] = (box.at_lo ^ flip) & finite_lo
    box.at_hi[:] = (rng.random(n) < 0.3) & finite_hi & ~box.at_lo
    check(levels, solver.solve(levels), x_ref, optimal)


@pytest.mark.parametrize("seed", range(4))
def test_damped_box_stack_uses_the_cascade_and_matches_it(seed):
    """Damped, each level starts from the previous level's point, so a bound can be
    active at one level and not at another: no single active set; the cascade is used."""
    rng = np.random.default_rng(900 + seed)
    levels = box_stack(rng, contains_zero=True)
    x_ref, optimal = cascade_hierarchy(levels, damping=0.3)
    solver = HierarchySolver(damping=0.3)
    solver.solve(levels)
    res = solver.solve(levels)
    check(levels, res, x_ref, optimal)
    assert res.method != "active-set"


def test_damped_box_without_zero_follows_the_damping_definition():
    """Damped, the first level is damped least squares too: a box that excludes 0 is
    then not met exactly (the definition), so the box path must not be used."""
    rng = np.random.default_rng(950)
    n = 5
    levels = [
        (np.eye(n), np.full(n, 0.5), np.full(n, 1.0)),
        (rng.standard_normal((2, n)), np.ones(2), np.ones(2)),
    ]
    x_ref, optimal = cascade_hierarchy(levels, damping=0.3)
    res = solve_hierarchy(levels, damping=0.3)
    assert res.method == "cascade" and optimal[0] > 0.01
    check_damped = np.testing.assert_allclose
    check_damped(res.residuals, optimal, atol=QP_TOL)
    check_damped(res.x, x_ref, atol=10 * QP_TOL)


def test_drifting_box_gives_the_cold_answers_mostly_without_qp():
    """Bounds moving tick by tick (variables reaching and leaving them): a persistent
    solver agrees with fresh ones and rarely needs a QP."""
    rng = np.random.default_rng(11)
    n = 14
    A1, A2 = rng.standard_normal((5, n)), rng.standard_normal((n + 2, n))
    b1, b2 = rng.standard_normal(5), rng.standard_normal(n + 2)
    qmax = rng.uniform(0.2, 0.6, n)
    solver = HierarchySolver()
    methods = []
    for t in range(60):
        s = np.sin(0.1 * t)
        levels = [
            (np.eye(n), -qmax * (1 + 0.5 * s), qmax * (1 - 0.5 * s)),
            (A1, b1 * (1 + 0.5 * s)),
            (A2, b2 * (2 + s)),
        ]
        warm = solver.solve(levels)
        cold = solve_hierarchy(levels, shortcut=False)  # QP cascade, no box path
        np.testing.assert_allclose(warm.residuals, cold.residuals, atol=QP_TOL)
        np.testing.assert_allclose(warm.x, cold.x, atol=10 * QP_TOL)
        methods.append(warm.method)
    assert methods.count("active-set") >= 40, methods
    assert methods.count("cascade") <= 5, methods


def test_not_a_box_goes_to_the_cascade():
    rng = np.random.default_rng(5)
    n = 6
    A0 = np.eye(n)
    A0[0, 1] = 0.5  # two nonzeros in a row: not a box
    b = 5.0 * np.ones(3)
    levels = [
        (A0, -0.1 * np.ones(n), 0.1 * np.ones(n)),
        (rng.standard_normal((3, n)), b, b),
    ]
    x_ref, optimal = cascade_hierarchy(levels)
    res = solve_hierarchy(levels)
    assert res.method == "cascade"
    np.testing.assert_allclose(res.x, x_ref, atol=1e-5)
    np.testing.assert_allclose(res.residuals, optimal, atol=1e-6)


def test_two_rows_on_one_variable_is_not_a_box():
    n = 3
    A0 = np.array([[1.0, 0, 0], [2.0, 0, 0], [0, 1.0, 0]])
    levels = [
        (A0, np.array([-1.0, -1.0, -1.0]), np.array([1.0, 1.0, 1.0])),
        (np.ones((1, n)), np.array([10.0])),
    ]
    x_ref, optimal = cascade_hierarchy([levels[0], (levels[1][0], levels[1][1], levels[1][1])])
    res = solve_hierarchy(levels)
    assert res.method == "cascade"
    np.testing.assert_allclose(res.x, x_ref, atol=1e-5)
    np.testing.assert_allclose(res.residuals, optimal, atol=1e-6)
