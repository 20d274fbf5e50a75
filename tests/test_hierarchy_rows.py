"""The active-set path with inequality rows below the box (an inequality task under the
joint limits, a CoM kept in its support polygon, ...).

Rows of the levels below level 0 guessed at a bound are held there by the KKT solve of
the path; the guess is verified (the other rows within their bounds, every held
constraint's multiplier pushing against its bound) and corrected. These tests compare
the answers with the independent cascade of tests/reference_hierarchy.py, check that the
path is the one taken when it should be, and that wrong guesses are refused.
"""

from __future__ import annotations

import numpy as np
import pytest

from reference_hierarchy import cascade_hierarchy, level_residuals
from sotpy.solvers import HierarchySolver
from sotpy.solvers._boxset import DualCheck

QP_TOL = 1e-6


def rows_stack(rng, t: float = 0.0, n: int = 20, infeasible: bool = False, conflict: bool = False):
    """A box on the last n - 3 variables (a floating base of 3), an inequality task of
    two-sided rows, equality levels, an inequality level with one-sided rows, and a
    posture with more rows than the variables the levels above leave. ``t`` drifts the
    data smoothly (as from one control tick to the next). ``infeasible``: two rows of
    the inequality task whose intervals do not meet; ``conflict``: the first equality
    level holds one row twice with two targets (a hand out of reach: no single KKT
    solve, the path goes level by level)."""
    nb = n - 3
    box = np.zeros((nb, n))
    box[:, 3:] = np.eye(nb)
    wave = np.sin(0.3 * t + np.arange(nb))
    half = rng.uniform(0.5, 1.5, nb)
    levels = [(box, -half * (1.0 - 0.3 * wave), half * (1.0 + 0.3 * wave))]
    C = rng.standard_normal((4, n)) + 0.1 * np.sin(t) * rng.standard_normal((4, n))
    c = rng.standard_normal(4) + 0.3 * np.cos(t)
    if infeasible:  # two opposite rows whose intervals do not meet
        C[1] = -C[0]
        c[1] = -c[0] - 2.0  # c0 + 1.5 <= a x <= c0 + 2.5 against a x <= c0 + 0.5
    levels.append((C, c - 0.5, c + 0.5))
    for m in (3, 2):
        A = rng.standard_normal((m, n)) + 0.1 * np.sin(t) * rng.standard_normal((m, n))
        b = rng.standard_normal(m)
        if conflict and m == 3:
            A[2] = A[1]
            b[2] = b[1] + 0.5
        levels.append((A, b, b.copy()))
    D = rng.standard_normal((2, n))
    levels.append((D, np.full(2, -np.inf), np.full(2, 0.1 + 0.05 * np.sin(t))))
    posture = np.zeros((nb, n))
    posture[:, 3:] = np.eye(nb)
    target = rng.standard_normal(nb)
    levels.append((posture, target, target.copy()))
    return levels


def _stack_sequence(seed, ticks, **kw):
    out = []
    for t in range(ticks):
        rng = np.random.default_rng(seed)  # the same draws every tick: only t drifts
        out.append(rows_stack(rng, 0.05 * t, **kw))
    return out


def _check(levels, res):
    x_ref, optimal = cascade_hierarchy(levels)
    scale = 1.0 + float(np.abs(x_ref).max())
    np.testing.assert_allclose(res.residuals, optimal, atol=QP_TOL * scale)
    np.testing.assert_allclose(res.x, x_ref, atol=10 * QP_TOL * scale)
    np.testing.assert_allclose(res.residuals, level_residuals(levels, res.x), atol=1e-12)


@pytest.mark.parametrize("seed", range(12))
def test_drifting_rows_match_the_cascade_reference_mostly_without_qp(seed):
    seq = _stack_sequence(900 + seed, 25)
    solver = HierarchySolver()
    methods = []
    for levels in seq:
        res = solver.solve(levels)
        _check(levels, res)
        methods.append(res.method)
    held = methods[1:].count("active-set")
    assert held >= 0.7 * (len(seq) - 1), methods


def test_held_rows_are_used_and_verified():
    """A sequence where rows below the box are at their bounds at the optimum: the
    path holds them (not only box bounds), without QPs."""
    solver = HierarchySolver()
    seen = 0
    for levels in _stack_sequence(905, 20):
        res = solver.solve(levels)
        st = solver._structure
        i_lower = st.eq_bounds[0][3]
        if res.method == "active-set" and st.side[i_lower:].any():
            seen += 1
            assert res.qp_levels == ()
    assert seen >= 10


def test_a_level_below_the_box_that_cannot_be_met_is_held_level_by_level():
    """Two rows of the inequality task whose intervals do not meet: the level is solved
    in the least-squares sense with both held at their bounds (violated, each pushing
    its own way), level by level; the reference cascade's answer, mostly without QP."""
    solver = HierarchySolver()
    methods = []
    for levels in _stack_sequence(907, 12, infeasible=True):
        res = solver.solve(levels)
        _check(levels, res)
        assert res.residuals[1] > 1e-3  # the level's conflict is reported
        methods.append(res.method)
    assert methods[1:].count("active-set") >= 8, methods


def _run_conflict(seed, ticks=15, monkeypatch=None):
    """The conflicting sequence of ``seed``; returns the methods and how many held
    rows met exactly got a release direction, carried to the levels below."""
    solver = HierarchySolver()
    methods = []
    added = 0
    if monkeypatch is not None:
        real = DualCheck.add

        def spy(self, A, basis, rows, s, ids):
            nonlocal added
            ok = real(self, A, basis, rows, s, ids)
            added += len(rows) if ok else 0
            return ok

        monkeypatch.setattr(DualCheck, "add", spy)
    for levels in _stack_sequence(940 + seed, ticks, conflict=True):
        res = solver.solve(levels)
        _check(levels, res)
        assert res.residuals[2] > 0.1  # the conflict
        methods.append(res.method)
    return methods, added


@pytest.mark.parametrize("seed", range(8))
def test_held_rows_above_a_conflicting_level_match_the_reference(seed):
    """A conflicting equality level below the inequality task: no single KKT solve;
    level by level, held rows met exactly are judged by the levels below (their
    release directions carried down as the fixed variables' are). The reference
    cascade's answer, mostly without QP."""
    methods, _ = _run_conflict(seed)
    assert methods[1:].count("active-set") >= 10, methods


def test_release_directions_of_held_rows_are_used(monkeypatch):
    """Over these sequences the level-by-level path does judge held rows met exactly
    (not only fixed variables and rows beyond their bounds)."""
    assert sum(_run_conflict(seed, 8, monkeypatch)[1] for seed in range(4)) >= 3


@pytest.mark.parametrize("variant", ["plain", "conflict", "infeasible"])
@pytest.mark.parametrize("seed", range(6))
def test_wrong_held_rows_are_released(seed, variant):
    """Every row below the box guessed held, at a random side: the verification
    releases or refuses the wrong ones, and the answer is the reference's (one KKT
    solve; level by level above a conflicting level; a level whose rows cannot all be
    met, where a row held at the wrong bound is pulled inside its interval)."""
    levels = rows_stack(
        np.random.default_rng(920 + seed),
        conflict=variant == "conflict",
        infeasible=variant == "infeasible",
    )
    solver = HierarchySolver()
    solver.solve(levels)
    st = solver._structure
    i_lower = st.eq_bounds[0][3]
    rng = np.random.default_rng(seed)
    st.side[i_lower:] = rng.choice([-1, 1], size=len(st.side) - i_lower)
    # one-sided rows cannot be held at their infinite side
    st.side[i_lower:][~np.isfinite(st.loin[i_lower:]) & (st.side[i_lower:] < 0)] = 1
    res = solver.solve(levels)
    _check(levels, res)


@pytest.mark.parametrize("conflict", [False, True])
def test_a_held_row_inside_its_interval_is_released(conflict):
    """A row that is strictly inside its interval at the optimum, guessed held at its
    nearer bound: the multiplier test (one KKT solve) or the level's own verdict and
    the release directions (level by level) must release it."""
    levels = rows_stack(np.random.default_rng(931), conflict=conflict)
    x_ref, _ = cascade_hierarchy(levels)
    solver = HierarchySolver()
    solver.solve(levels)
    st = solver._structure
    i_lower = st.eq_bounds[0][3]
    # hold an inequality-task row that is inside its interval at the optimum
    v = st.Ain[i_lower:] @ np.append(x_ref, 1.0)
    inside = np.flatnonzero((v > st.loin[i_lower:] + 1e-3) & (v < st.upin[i_lower:] - 1e-3))
    assert len(inside)
    j = i_lower + int(inside[0])
    st.side[:] = 0
    st.side[j] = 1 if v[j - i_lower] > 0.5 * (st.loin[j] + st.upin[j]) else -1
    res = solver.solve(levels)
    np.testing.assert_allclose(res.x, x_ref, atol=1e-5)


@pytest.mark.parametrize(("seed", "variant"), [(31, "conflict"), (62, "infeasible")])
def test_levels_after_every_direction_is_used_judge_with_their_true_violation(seed, variant):
    """8 variables: the levels above the last inequality level use every direction.
    A row of that level guessed held at a bound it is far inside of must not count in
    the level's verdict on the held rows above (it once made a wrong guess pass)."""
    solver = HierarchySolver()
    for t in (0.0, 0.9):
        levels = rows_stack(
            np.random.default_rng(seed),
            t,
            n=8,
            conflict=variant == "conflict",
            infeasible=variant == "infeasible",
        )
        _check(levels, solver.solve(levels))
