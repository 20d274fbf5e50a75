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
from sotpy.solvers import hierarchy as hierarchy_module

QP_TOL = 1e-6


def rows_stack(rng, t: float = 0.0, n: int = 20, infeasible: bool = False):
    """A box on the last n - 3 variables (a floating base of 3), an inequality task of
    two-sided rows, equality levels, an inequality level with one-sided rows, and a
    posture with more rows than the variables the levels above leave. ``t`` drifts the
    data smoothly (as from one control tick to the next)."""
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


def test_infeasible_level_below_the_box_goes_to_the_cascade_and_waits():
    """A level that cannot be met: not representable by held rows; the cascade answers
    and the path is not retried at every call."""
    seq = _stack_sequence(907, 6, infeasible=True)
    solver = HierarchySolver()
    calls = {"n": 0}
    real = solver._rows_kkt

    def spy(*args):
        calls["n"] += 1
        return real(*args)

    solver._rows_kkt = spy
    for levels in seq:
        res = solver.solve(levels)
        _check(levels, res)
        assert res.residuals[1] > 1e-3  # the level's conflict is reported
    assert calls["n"] <= 2 * hierarchy_module._BOX_ITERATIONS


@pytest.mark.parametrize("seed", range(6))
def test_wrong_held_rows_are_released(seed):
    """Every row below the box guessed held, at a random side: the verification
    releases or refuses the wrong ones, and the answer is the reference's."""
    levels = rows_stack(np.random.default_rng(920 + seed))
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


def test_a_wrong_sign_multiplier_is_refused(monkeypatch):
    """Mutation check of the dual test: a held row whose multiplier says "leave the
    bound" must not be accepted. With the sign test switched off, a wrong guess is
    accepted and the answer is wrong; with it, the answer is right."""
    levels = rows_stack(np.random.default_rng(931))
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
