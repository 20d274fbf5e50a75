"""The one-KKT-solve path (sotpy.solvers._kkt): used when every level but the last is of
full row rank (the usual SOT tick), checked against the independent references, and
refused (the null-space recursion answers) when the system is ill-conditioned. For
equality-only stacks and on the box path it belongs to the NumPy path (``jit=False``):
the compiled paths solve these stacks in one call of their own (tested in
``test_hierarchy_jit.py`` and ``test_hierarchy_boxkkt.py``)."""

from __future__ import annotations

import numpy as np
import pytest

import sotpy.solvers.hierarchy as hierarchy
from reference_hierarchy import cascade_hierarchy, projector_hierarchy
from sotpy.solvers import HierarchySolver, _boxkkt
from sotpy.solvers._kkt import RCOND_MIN, kkt_solve


@pytest.fixture
def kkt_calls(monkeypatch):
    """Count the KKT solves that succeed / are refused."""
    calls = {"ok": 0, "refused": 0}

    def spy(*args):
        out = kkt_solve(*args)
        calls["ok" if out is not None else "refused"] += 1
        return out

    monkeypatch.setattr(hierarchy, "kkt_solve", spy)
    return calls


def full_rank_stack(rng, n, with_last=True):
    """Upper levels of full row rank (together < n rows), a last level with more rows
    than the directions they leave (a posture-like level)."""
    levels = []
    for m in rng.integers(1, 5, size=3):
        levels.append((rng.standard_normal((int(m), n)), rng.standard_normal(int(m))))
    if with_last:
        levels.append((rng.standard_normal((n + 2, n)), rng.standard_normal(n + 2)))
    return levels


@pytest.mark.parametrize("seed", range(10))
@pytest.mark.parametrize("with_last", [True, False])
def test_equality_stacks_of_the_usual_shape_use_one_kkt_solve(seed, with_last, kkt_calls):
    rng = np.random.default_rng(1200 + seed)
    n = int(rng.integers(12, 30))
    levels = full_rank_stack(rng, n, with_last)
    x_ref, optimal = projector_hierarchy(levels)
    # the NumPy path (the compiled equality path has no KKT shortcut: it is faster)
    solver = HierarchySolver(jit=False)
    first = solver.solve(levels)  # null-space recursion, learns the shape
    assert kkt_calls["ok"] == 0
    second = solver.solve(levels)
    assert kkt_calls["ok"] == 1
    for res in (first, second):
        assert np.abs(res.x - x_ref).max() <= 1e-9 * (1 + np.abs(x_ref).max())
        np.testing.assert_allclose(res.residuals, optimal, rtol=1e-9, atol=1e-9)
    upper = sum(A.shape[0] for A, _ in levels[:-1]) if with_last else None
    if with_last:
        assert second.ranks[-1] == n - upper


def test_ill_conditioned_upper_level_is_left_to_the_null_space_path(kkt_calls):
    """Two nearly parallel rows in an upper level (angle 1e-12): the KKT matrix is
    refused by its condition number and the rank threshold of the null-space recursion
    drops the direction, as the projector reference does."""
    rng = np.random.default_rng(5)
    n = 10
    levels = full_rank_stack(rng, n)
    solver = HierarchySolver(jit=False)
    solver.solve(levels)  # the shape: full-rank uppers, a least-squares last level
    A, b = levels[0]
    A = np.vstack([A, A[0] + 1e-12 * rng.standard_normal(n)])
    levels[0] = (A, np.append(b, b[0] + 0.5))
    x_ref, optimal = projector_hierarchy(levels)
    # same row counts as before? no: a new shape; force the KKT attempt on it directly
    upper = np.hstack(
        [
            np.vstack([lv[0] for lv in levels[:-1]]),
            -np.concatenate([lv[1] for lv in levels[:-1]])[:, None],
        ]
    )
    last = np.hstack([levels[-1][0], -levels[-1][1][:, None]])
    assert kkt_solve(upper, last, n, np.zeros(0, dtype=int), np.zeros(0)) is None
    res = solver.solve(levels)
    assert np.abs(res.x - x_ref).max() <= 1e-6 * (1 + np.abs(x_ref).max())
    np.testing.assert_allclose(res.residuals, optimal, atol=1e-6)
    assert RCOND_MIN > 0


def test_box_stacks_of_the_usual_shape_use_one_kkt_solve(kkt_calls):
    """A box first (some bounds active), full-rank levels, a posture-like last level:
    after the first call the active bounds are fixed and the stack solved by one KKT
    solve, the bounds judged by their multipliers; the answer is the cascade's."""
    used = held = 0
    for seed in range(10):
        rng = np.random.default_rng(1300 + seed)
        n = int(rng.integers(12, 20))
        box = (np.eye(n), -rng.uniform(0.2, 1.5, n), rng.uniform(0.2, 1.5, n))
        levels = [box] + [(A, b, b) for A, b in full_rank_stack(rng, n)]
        x_ref, optimal = cascade_hierarchy(levels)
        solver = HierarchySolver(jit=False)
        solver.solve(levels)
        before = kkt_calls["ok"]
        res = solver.solve(levels)
        used += kkt_calls["ok"] > before
        scale = 1 + np.abs(x_ref).max()
        np.testing.assert_allclose(res.residuals, optimal, atol=1e-6 * scale)
        np.testing.assert_allclose(res.x, x_ref, atol=1e-5 * scale)
        assert res.method in ("active-set", "shortcut")
        held += res.method == "active-set"
    # 6 of 10: in seed 1303 the first call ends in the QP cascade after a guess that
    # held every variable, so its levels fixed no direction and the plan waits
    assert used >= 6, used
    assert held >= 3, held  # bounds were indeed held in several of them


def test_wrong_bound_is_released_by_its_multiplier(kkt_calls):
    """A bound held although the last level pulls the variable inside: the KKT
    multiplier has the wrong sign, the bound is released, the answer is the cascade's."""
    n = 4
    box = (np.eye(n), -np.ones(n), np.ones(n))
    last = (np.eye(n), np.array([0.5, -0.2, 0.3, 0.1]))
    levels = [box, (np.ones((1, n)), np.array([0.7]), np.array([0.7])), (*last, last[1])]
    x_ref, _ = cascade_hierarchy(levels)
    solver = HierarchySolver(jit=False)
    solver.solve(levels)
    solver._structure.box.at_hi[0] = True  # a wrong guess: x_0 held at 1
    res = solver.solve(levels)
    np.testing.assert_allclose(res.x, x_ref, atol=1e-7)
    assert not solver._structure.box.at_hi[0]


def test_refused_shape_is_not_retried_every_call(kkt_calls):
    """A last level that leaves directions free (a posture without the free flyer's
    columns): the KKT matrix is singular; after one refusal the next calls go straight
    to the null-space recursion (retried after a while), with the same answer."""
    rng = np.random.default_rng(8)
    n = 12
    posture = np.zeros((n - 6, n))
    posture[:, 6:] = np.eye(n - 6)
    b = rng.standard_normal(n - 6)
    levels = [(np.eye(n), -np.ones(n), np.ones(n)), (posture, b, b)]
    x_ref, _ = cascade_hierarchy(levels)
    solver = HierarchySolver(jit=False)
    for _ in range(10):
        res = solver.solve(levels)
        np.testing.assert_allclose(res.x, x_ref, atol=1e-6)
    # one refusal on a corrected guess of the first call, one that starts the wait
    assert kkt_calls["refused"] <= 2 and kkt_calls["ok"] == 0


@pytest.mark.skipif(_boxkkt.kkt is None, reason="numba missing or SOTPY_JIT=0")
@pytest.mark.parametrize("seed", range(6))
def test_compiled_kkt_equals_numpy(seed):
    """The compiled null-space solve gives the NumPy path's answer (the assembled
    system by dgesv), refusals included (a singular system, an ill-conditioned one)."""
    rng = np.random.default_rng(300 + seed)
    n = int(rng.integers(8, 20))
    upper = rng.standard_normal((int(rng.integers(1, 5)), n + 1))
    last = rng.standard_normal((n + 3, n + 1)) if seed % 2 else None
    fixed = rng.choice(n, size=int(rng.integers(0, 4)), replace=False)
    values = rng.standard_normal(len(fixed))
    a = kkt_solve(upper, last, n, fixed, values, compiled=True)
    b = kkt_solve(upper, last, n, fixed, values, compiled=False)
    assert a is not None and b is not None
    for u, v in zip(a, b, strict=True):
        np.testing.assert_allclose(u, v, rtol=1e-12, atol=1e-12 * (1 + np.abs(v).max(initial=0)))
    # a duplicated upper row: singular, refused by both
    dup = np.vstack([upper, upper[:1]])
    assert kkt_solve(dup, last, n, fixed, values, compiled=True) is None
    assert kkt_solve(dup, last, n, fixed, values, compiled=False) is None
    # nearly parallel rows: refused by the condition number, by both
    near = np.vstack([upper, upper[:1] + 1e-13 * rng.standard_normal(n + 1)])
    assert kkt_solve(near, last, n, fixed, values, compiled=True) is None
    assert kkt_solve(near, last, n, fixed, values, compiled=False) is None
    if last is not None:  # fewer last-level rows than the directions left: singular
        short = last[: n - len(fixed) - len(upper) - 1]
        assert kkt_solve(upper, short, n, fixed, values, compiled=True) is None
        assert kkt_solve(upper, short, n, fixed, values, compiled=False) is None
    # more upper rows than free variables: singular
    crowded = rng.standard_normal((n - len(fixed) + 1, n + 1))
    assert kkt_solve(crowded, last, n, fixed, values, compiled=True) is None
    assert kkt_solve(crowded, last, n, fixed, values, compiled=False) is None
