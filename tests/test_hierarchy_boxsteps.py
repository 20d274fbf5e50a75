"""The box path's level-by-level variant as one compiled call
(sotpy.solvers._eqkernel.box_steps): the recursion below the box from the fixed
variables, with the lexicographic dual check of the undecided bounds at each level and
the minimum-norm criterion at the end. It must give what HierarchySolver._box_steps and
its DualCheck give: the point, the ranks and the verdict (which bound to release), on
right and wrong guesses; and the whole solve must still be the reference cascade's."""

from __future__ import annotations

import numpy as np
import pytest

from reference_hierarchy import cascade_hierarchy
from sotpy.solvers import HierarchySolver, _eqkernel
from sotpy.solvers._boxset import DualCheck
from test_hierarchy_boxkkt import assert_same, narrowed, rank_deficient_below_box

pytestmark = pytest.mark.skipif(_eqkernel.box_steps is None, reason="numba missing or SOTPY_JIT=0")


@pytest.fixture
def kernel_calls(monkeypatch):
    calls = {"n": 0}
    real = _eqkernel.box_steps

    def spy(*args):
        calls["n"] += 1
        return real(*args)

    monkeypatch.setattr(_eqkernel, "box_steps", spy)
    return calls


def both(solver: HierarchySolver, W, values, s):
    """``_box_steps`` with a DualCheck (finished at its point) and the compiled call,
    from the same state: ``((x, ranks, failed, worst), (x, ranks, failed, worst))``."""
    st, stepper = solver._structure, solver._stepper
    plan = st.box_blocks, st.box_full
    out = []
    for compiled in (False, True):
        st.box_blocks, st.box_full = plan
        stepper.reset()
        stepper.fix(W, values)
        if compiled:
            ranks, dual = solver._box_steps_compiled(st, stepper, W, values, s)
        else:
            dual = DualCheck(solver.n, W, s)
            ranks = solver._box_steps(st, stepper, dual)
            dual.finish(stepper.x)
        out.append((stepper.x.copy(), ranks, dual.failed, dual.worst))
    return out


def mixed_ranks(rng, n: int, half: float):
    """A box of half-width ``half``, then a full-rank level, a level with a repeated
    row (another target: rank deficient), a full-rank level and a short last level
    (fewer rows than the directions left: the minimum norm decides the rest)."""
    A1 = rng.standard_normal((3, n))
    A2 = rng.standard_normal((3, n))
    A2[2] = A2[0]
    A3 = rng.standard_normal((2, n))
    A4 = rng.standard_normal((2, n))
    levels = [(np.eye(n), -half * np.ones(n), half * np.ones(n))]
    for A in (A1, A2, A3, A4):
        b = rng.standard_normal(A.shape[0])
        levels.append((A, b, b))
    return levels


def compare_guesses(levels, rng) -> set[bool]:
    """The optimum's bounds (a right guess) and random ones (mostly wrong): point,
    ranks and verdict of both paths agree; the verdicts met."""
    n = levels[0][0].shape[1]
    solver = HierarchySolver()
    solver.solve(levels)  # the buffers, the row classes, the box, its active set
    box = solver._structure.box
    guesses = [box.fixed()]
    for _ in range(12):
        k = int(rng.integers(1, n - 2))
        W = np.sort(rng.choice(n, k, replace=False)).astype(np.intp)
        upper = rng.random(k) < 0.5
        s = np.where(upper, -1.0, 1.0)
        s[rng.random(k) < 0.2] = 0.0  # bounds that coincide are never released
        guesses.append((W, np.where(upper, box.hi[W], box.lo[W]), s))
    verdicts = set()
    for W, values, s in guesses:
        (x0, r0, f0, w0), (x1, r1, f1, w1) = both(solver, W, values, s)
        np.testing.assert_allclose(x1, x0, rtol=0, atol=1e-10 * (1 + np.abs(x0).max()))
        np.testing.assert_array_equal(r1, r0)
        assert (f1, w1) == (f0, w0)
        verdicts.add(f0)
    return verdicts


@pytest.mark.parametrize("seed", range(10))
def test_compiled_steps_and_verdicts_equal_the_numpy_ones(seed):
    """Random guesses on stacks whose levels below the box are rank deficient (the
    last one a least-squares fit), then with full-rank levels between and a
    minimum-norm end: some bounds right, some wrong (a multiplier of the wrong sign,
    found at a level or by the minimum-norm criterion); point, ranks and verdict
    agree."""
    rng = np.random.default_rng(7100 + seed)
    n = int(rng.integers(9, 16))
    assert compare_guesses(rank_deficient_below_box(rng, n, 0.05), rng) == {True, False}
    assert compare_guesses(mixed_ranks(rng, n, 0.3), rng) == {True, False}


@pytest.mark.parametrize("seed", range(6))
def test_tight_box_over_deficient_levels_is_the_cascade_answer(seed, kernel_calls):
    """The whole solve with bounds active and deficient levels below (the compiled box
    call refuses): the compiled steps run, the answer is the reference cascade's and
    the NumPy path's."""
    rng = np.random.default_rng(7200 + seed)
    n = int(rng.integers(8, 16))
    wide = rank_deficient_below_box(rng, n, 100.0)
    levels = narrowed(wide, 0.6 * np.abs(cascade_hierarchy(wide)[0]).max())
    x_ref, optimal = cascade_hierarchy(levels)
    fast, slow = HierarchySolver(), HierarchySolver(jit=False)
    for _ in range(3):
        a, b = fast.solve(levels), slow.solve(levels)
        assert_same(levels, a, x_ref, optimal)
        np.testing.assert_allclose(a.x, b.x, rtol=0, atol=1e-9 * (1 + np.abs(b.x).max()))
        np.testing.assert_array_equal(a.ranks, b.ranks)
        assert a.method == b.method != "shortcut"  # bounds held
    assert kernel_calls["n"] >= 3


def test_without_a_level_below_the_box_the_numpy_steps_run():
    n = 5
    solver = HierarchySolver()
    solver.solve([(np.eye(n), -np.ones(n), np.ones(n))])
    st, stepper = solver._structure, solver._stepper
    W = np.array([1], dtype=np.intp)
    assert solver._box_steps_compiled(st, stepper, W, np.ones(1), np.ones(1)) is None


@pytest.mark.parametrize("seed", range(6))
def test_one_level_of_the_dual_check_equals_the_numpy_one(seed):
    """One level of the check on a direct case: two release directions the level
    pushes against (decided: they leave the check), one it does not see through its
    residual (carried into the level's null space); compiled and NumPy agree on which
    stay and on the carried directions."""
    rng = np.random.default_rng(7300 + seed)
    n, m = 7, 3
    rows = rng.standard_normal((m, n + 1))
    W = np.asfortranarray(np.eye(n + 1))
    W[:n, n] = rng.standard_normal(n)  # the point x
    x_aug = W[:, n]
    res = rows @ x_aug  # A x - b
    A = rows[:, :n]
    D = rng.standard_normal((n, 3))
    for a in range(2):  # pushed against: r . (A d) > 0
        if res @ (A @ D[:, a]) < 0:
            D[:, a] = -D[:, a]
    # not seen through the residual: A d orthogonal to r
    d = D[:, 2]
    g = A.T @ res
    D[:, 2] = d - (g @ d) / (g @ g) * g
    dual = DualCheck(n, np.arange(3, dtype=np.intp), np.ones(3))
    dual.D = D.copy()
    basis = W[:n, :n]
    dual.level(rows, x_aug, basis, -1, None)
    alive = np.ones(3, dtype=np.bool_)
    Dc = D.copy()
    state = np.array([0, -1], dtype=np.int64)
    jpvt = np.arange(1, m + 1, dtype=np.int32)
    keep = np.zeros((m, m)).T
    _eqkernel._dual_level(
        np.ascontiguousarray(rows), W, 0, -1, keep, jpvt, Dc, alive, np.arange(3), state, 1e-10
    )
    assert not dual.failed and state[0] == 0
    np.testing.assert_array_equal(np.flatnonzero(alive), dual.idx)
    assert list(dual.idx) == [2]  # the two pushed against are decided
    np.testing.assert_allclose(Dc[:, alive], dual.D, atol=1e-12)
