"""The hierarchical solver's budget contract, and its answers on adversarial stacks.

A stopped call (``status`` "iterations" or "time") must return a finite point that is
optimal on the levels it reports as solved; the next calls continue from its active
rows and reach the optimum. Without a budget, every stack of the adversarial class
(rank-deficient rows, conflicting one-sided bounds, rows scaled by 1 to 100) reaches the
lexicographic optimum of the independent QP cascade, in both twins.
"""

from __future__ import annotations

import functools
import itertools
import warnings
from pathlib import Path

import numpy as np
import pytest

from reference_hierarchy import cascade_hierarchy, level_residuals
from sotpy._bench import adversarial_stack
from sotpy.errors import BudgetWarning, CommandError, SotpyWarning
from sotpy.graph import Entity
from sotpy.loop import ControlLoop
from sotpy.solvers import HierarchySolver
from sotpy.solvers._activeset_jit import solve as compiled
from sotpy.solvers.hierarchy import RETURN_SHARE, SolverError
from sotpy.solvers.sot import SOT
from sotpy.tasks import FeatureGeneric, Task, TaskInequality

JITS = [False, True] if compiled is not None else [False]


def adversarial(seed: int):
    """A seeded stack of the solver's hard class (``sotpy._bench.adversarial_stack``), at
    sizes the reference cascade solves quickly: n 6 to 24, 2 to 4 levels."""
    return adversarial_stack(np.random.default_rng(seed), n_range=(6, 25), p_range=(2, 5))


#: seeds of the comparisons with the QP cascade (its proxsuite QPs stall on the degenerate
#: sets of seeds 10 and 22, for seconds to minutes; the solver's answers there are
#: compared between the twins)
SEEDS = [s for s in range(26) if s not in (10, 22)]


def _scale(optimal) -> float:
    return 1.0 + float(np.max(np.abs(optimal)))


@pytest.mark.parametrize("jit", JITS)
@pytest.mark.parametrize("seed", SEEDS)
def test_adversarial_stacks_reach_the_cascade_optimum(seed, jit):
    levels = adversarial(seed)
    res = HierarchySolver(jit=jit, time_budget=None, max_iter=1000).solve(levels)
    assert res.converged and res.status == "optimal" and res.solved == len(levels)
    x_ref, optimal = cascade_hierarchy(levels)
    got = level_residuals(levels, res.x)
    np.testing.assert_allclose(got, optimal, atol=1e-6 * _scale(optimal))
    # the minimum-norm point of the last optimal set: the cascade's
    assert np.linalg.norm(res.x - x_ref) <= 1e-5 * (1.0 + np.linalg.norm(x_ref))


@pytest.mark.parametrize("seed", range(40))
def test_both_twins_take_the_same_decisions(seed):
    if compiled is None:
        pytest.skip("numba is not installed")
    levels = adversarial(seed)
    a = HierarchySolver(jit=False, time_budget=None, max_iter=1000).solve(levels)
    b = HierarchySolver(jit=True, time_budget=None, max_iter=1000).solve(levels)
    # the same path: LAPACK's pivoted QR (NumPy twin) and the compiled one can break a
    # tie between two directions of equal norm differently (it depends on the BLAS), and
    # a rank decided one sub-level later costs or saves one iteration; never more
    assert abs(a.iterations - b.iterations) <= 1
    np.testing.assert_allclose(a.x, b.x, atol=1e-8 * (1.0 + np.abs(a.x).max()))


def _lapack_pivoted_qr(M):
    """LAPACK's ``dgeqp3`` of ``M^T`` (scipy): the permutation and ``|diag R|``."""
    import scipy.linalg

    R, piv = scipy.linalg.qr(M.T, mode="r", pivoting=True)
    return piv, np.abs(np.diag(R))


@pytest.mark.parametrize("seed", range(16))
def test_compiled_pivoted_qr_matches_lapack(seed):
    """The compiled factor downdates the rows' norms between pivots (as ``dgeqp3``
    does) instead of summing them again: the same pivots and the same ``R`` as LAPACK's,
    on full, rank-deficient, wide and tall matrices whose rows are scaled from 1e-3 to
    1e3, and on rows in pairs of near-copies (once one is a pivot, the other's
    downdated norm has lost its digits and must be summed again); ``Q`` orthogonal."""
    if compiled is None:
        pytest.skip("numba is not installed")
    from sotpy.solvers import _activeset_jit as kernels

    rng = np.random.default_rng(seed)
    mk, f = [(32, 23), (12, 38), (23, 32), (20, 20)][seed % 4]
    if seed < 12:
        rank = min(mk, f) - (seed % 3) * 3  # full rank, or 3 or 6 short of it
        M = rng.standard_normal((mk, rank)) @ rng.standard_normal((rank, f))
        M *= 10.0 ** rng.uniform(-3.0, 3.0, size=(mk, 1))
    else:  # pairs of near-copies: once a row is a pivot, its copy's norm is all
        # cancellation unless it is summed again
        rank = min(mk, f)
        half = rng.standard_normal((mk - mk // 2, f))
        near = half[: mk // 2] + 10.0 ** rng.uniform(-8.5, -7.0, size=(mk // 2, 1)) * (
            rng.standard_normal((mk // 2, f))
        )
        M = np.vstack([half, near])[rng.permutation(mk)]
    piv_ref, diag_ref = _lapack_pivoted_qr(M)
    W = M.copy()
    tau, piv = np.zeros(f), np.zeros(mk, dtype=np.int64)
    kmin = kernels._pivoted_qr(W, mk, f, tau, piv, np.empty(mk), np.empty(mk))
    assert kmin == min(mk, f)
    diag = np.abs(np.diag(W[:kmin, :kmin]))
    # the pivots decide the rank: the same rows in the same order where R is not
    # round-off (below the rank, the order among round-off rows is arbitrary)
    scale = diag_ref[0]
    sure = diag_ref > 1e-11 * scale
    assert sure.sum() == rank
    np.testing.assert_array_equal(piv[:rank], piv_ref[:rank])
    np.testing.assert_allclose(diag[:rank], diag_ref[:rank], rtol=1e-8, atol=1e-13 * scale)
    assert np.all(diag[rank:] <= 1e-11 * scale)
    # Q^T M^T P = R: the reflectors (rows of W after the diagonal) reproduce M^T's
    # permuted columns from R, and keep the norms
    Q = np.eye(f)
    for s in reversed(range(kmin)):
        v = np.zeros(f)
        v[s] = 1.0
        v[s + 1 :] = W[s, s + 1 :]
        Q -= tau[s] * np.outer(v, v @ Q)
    R = np.zeros((f, mk))
    for j in range(mk):
        R[: min(j, kmin - 1) + 1, j] = W[j, : min(j, kmin - 1) + 1]
    np.testing.assert_allclose(Q.T @ Q, np.eye(f), atol=1e-12)
    np.testing.assert_allclose(Q @ R, M[piv].T, atol=1e-10 * np.abs(M).max())


def _structured(seed: int):
    """A humanoid-like stack: a box on the joints, contacts on the first columns only (a
    floating base and the legs), a task on some middle columns, a posture on the last
    ones (unit rows), all with random targets; rows of one level may conflict."""
    rng = np.random.default_rng(seed)
    n = int(rng.integers(12, 40))
    base = int(rng.integers(3, n // 2))  # the contacts' columns: 0..base-1
    box = np.eye(n)[base:]
    lim = rng.uniform(0.2, 2.0, n - base)
    contact = np.zeros((int(rng.integers(2, base + 3)), n))
    contact[:, :base] = rng.standard_normal((contact.shape[0], base))
    mid = rng.permutation(n)[: int(rng.integers(2, n))]
    task = np.zeros((3, n))
    task[:, mid] = rng.standard_normal((3, len(mid)))
    posture = np.eye(n)[int(rng.integers(base // 2, base + 1)) :]
    return [
        (box, -lim, lim),
        _eq(contact, rng.standard_normal(contact.shape[0])),
        _eq(task, 3.0 * rng.standard_normal(3)),
        _eq(posture, rng.standard_normal(posture.shape[0])),
    ]


def _eq(A, b):
    return A, b, b


@pytest.mark.parametrize("seed", range(20))
def test_sparse_first_level_reaches_the_cascade_optimum(seed):
    """When the first level with active rows touches few columns, the compiled twin
    moves only that block of the basis (the rest is the identity): the same answer as
    the NumPy twin and the QP cascade."""
    levels = _structured(seed)
    x_ref, optimal = cascade_hierarchy(levels)
    for jit in JITS:
        res = HierarchySolver(jit=jit, time_budget=None, max_iter=1000).solve(levels)
        assert res.converged and res.solved == len(levels)
        got = level_residuals(levels, res.x)
        np.testing.assert_allclose(got, optimal, atol=1e-6 * _scale(optimal))
        assert np.linalg.norm(res.x - x_ref) <= 1e-5 * (1.0 + np.linalg.norm(x_ref))


@pytest.mark.parametrize("seed", [72, 146, 244, 245])
def test_held_rows_updated_in_place_give_the_refactored_answer(seed):
    """The benchmark's largest stacks (n up to 40, a box first): dozens of box rows join
    the held rows of a lower level one at a time, and the compiled twin updates that
    factor in place (``_append_held``) where the NumPy twin refactors it with LAPACK.
    Same decisions, same answer."""
    if compiled is None:
        pytest.skip("numba is not installed")
    levels = adversarial_stack(np.random.default_rng(seed))
    a = HierarchySolver(jit=False, time_budget=None, max_iter=1000).solve(levels)
    b = HierarchySolver(jit=True, time_budget=None, max_iter=1000).solve(levels)
    assert a.converged and b.converged and a.iterations >= 60
    assert abs(a.iterations - b.iterations) <= 1
    np.testing.assert_allclose(b.residuals, a.residuals, atol=1e-9 * _scale(a.residuals))
    np.testing.assert_allclose(b.x, a.x, atol=1e-8 * (1.0 + np.abs(a.x).max()))


@pytest.mark.parametrize("jit", JITS)
@pytest.mark.parametrize("seed", range(6))
def test_a_stack_of_other_sizes_starts_from_an_unrelated_answer(seed, jit):
    """Level sizes that change keep the last answer as the first level's start (a point
    of the same variables); from another problem's answer, the optimum is the same."""
    rng = np.random.default_rng(100 + seed)
    first, second = (adversarial_stack(rng, n=12, p_range=(2, 4)) for _ in range(2))
    if [len(A) for A, _, _ in first] == [len(A) for A, _, _ in second]:
        second = [*second, (np.ones((1, 12)), np.ones(1), np.ones(1))]
    solver = HierarchySolver(jit=jit, time_budget=None, max_iter=1000)
    solver.solve(first)
    res = solver.solve(second)
    assert res.converged
    x_ref, optimal = cascade_hierarchy(second)
    np.testing.assert_allclose(level_residuals(second, res.x), optimal, atol=1e-6 * _scale(optimal))
    assert np.linalg.norm(res.x - x_ref) <= 1e-5 * (1.0 + np.linalg.norm(x_ref))


@pytest.mark.parametrize("seed", range(8))
def test_both_twins_follow_a_drifting_stack_alike(seed):
    """Warm calls (the previous answer and active rows as the start): the twins give the
    same answers, tick by tick, for about the same work. (Their paths can part: a tie
    broken differently in one tick, see above, is a different warm start for the
    next.)"""
    if compiled is None:
        pytest.skip("numba is not installed")
    rng = np.random.default_rng(200 + seed)
    base = adversarial(200 + seed)
    dA = [rng.standard_normal(A.shape) for A, _, _ in base]
    db = [rng.standard_normal(len(lo)) for _, lo, _ in base]
    twins = [HierarchySolver(jit=j, time_budget=None, max_iter=1000) for j in (False, True)]
    work = np.zeros(2)
    for t in range(8):
        s = 0.02 * np.sin(0.3 * t)
        levels = [
            (A + s * np.abs(A).max() * a, lo + s * b, up + s * b)
            for (A, lo, up), a, b in zip(base, dA, db, strict=True)
        ]
        a, b = (solver.solve(levels) for solver in twins)
        assert a.converged and b.converged
        np.testing.assert_allclose(a.x, b.x, atol=1e-7 * (1.0 + np.abs(a.x).max()))
        work += (a.iterations, b.iterations)
    assert 0.8 <= work[0] / work[1] <= 1.25


@pytest.mark.parametrize("jit", JITS)
def test_a_refused_call_keeps_the_warm_start(jit):
    """A stack refused for a NaN (same sizes, so the same buffers) leaves the last answer
    and the active rows as they were: the next good call starts from them."""
    levels = adversarial(3)
    solver = HierarchySolver(jit=jit, time_budget=None, max_iter=1000)
    first = solver.solve(levels)
    bad = [(A.copy(), lo, up) for A, lo, up in levels]
    bad[-1][0][0, 0] = np.nan
    with pytest.raises(SolverError, match="not finite"):
        solver.solve(bad)
    np.testing.assert_array_equal(solver._buf.x, first.x)  # the kernel's next start
    again = solver.solve(levels)
    assert again.iterations == 1  # the warm start was kept: its eHQP is the answer
    np.testing.assert_allclose(again.x, first.x, atol=1e-9 * (1.0 + np.abs(first.x).max()))


#: three ticks of the Talos torque hierarchy (``sotpy demo talos-torque``, strategy
#: ``MultiLevelWeighted``, 1 s CoM shift, t = 0.75 to 0.98 s: the right foot unloading),
#: each with the previous tick's active rows and answer: levels [144, 35, 10] over y =
#: (a, f), 50 variables
UNLOADING = Path(__file__).parent / "data" / "talos_torque_unloading.npz"


@functools.cache
def _unloading(k: int):
    d = np.load(UNLOADING)
    A, lo, up, starts = d[f"A{k}"], d[f"lo{k}"], d[f"up{k}"], d[f"starts{k}"]
    levels = [(A[a:b], lo[a:b], up[a:b]) for a, b in itertools.pairwise(starts)]
    reference = cascade_hierarchy(levels)  # seconds: once per tick
    problem = (A, lo, up, starts.astype(np.int64))
    return problem, d[f"status{k}"], d[f"attach{k}"], d[f"xprev{k}"], levels, reference


def _kernel_solve(jit: bool, problem, status, attach, x):
    from sotpy.solvers import _activeset, _activeset_jit

    A, lo, up, starts = problem
    m, n = A.shape
    p = len(starts) - 1
    status, attach, x = status.copy(), attach.copy(), x.copy()
    res, ranks, fro = np.zeros(p), np.zeros(p, dtype=np.int64), np.zeros(p)
    info = np.zeros(8, dtype=np.int64)
    args = (A, lo, up, starts, status, attach, np.zeros(p), 1e-9, 1e-9, 1e-9, 1000, np.inf,
            x, res, ranks, fro, info)  # fmt: skip
    if jit:
        _activeset_jit.solve(*args, *_activeset_jit.workspace(m, n, p))
    else:
        _activeset.solve(*args)
    assert info[1] == _activeset.OPTIMAL and info[3] == _activeset.OK
    return x, int(info[0])


@pytest.mark.parametrize("jit", JITS)
@pytest.mark.parametrize("k", range(3))
def test_a_contact_unloading_starts_from_the_previous_answer(k, jit):
    """The previous active rows' eHQP point lies past the unloading foot's cone apex
    (dozens of level-0 rows violated); from the previous answer, corrected onto level 0's
    active rows, a few steps reach the cascade's optimum."""
    problem, status, attach, xprev, levels, (x_ref, optimal) = _unloading(k)
    x, its = _kernel_solve(jit, problem, status, attach, xprev)
    scale = 1.0 + np.linalg.norm(x_ref)  # |y| ~ 850: accelerations and newtons
    np.testing.assert_allclose(level_residuals(levels, x), optimal, atol=1e-7 * scale)
    assert np.linalg.norm(x - x_ref) <= 1e-6 * scale  # the cascade: to about 1e-7
    # without the previous answer (NaN: none), the same active rows start at their eHQP
    # point, and minimising level 0's violation from there walks row by row
    _x, its_cold = _kernel_solve(jit, problem, status, attach, np.full_like(xprev, np.nan))
    assert its <= 12
    assert 3 * its <= its_cold


def test_rank_one_lower_bounds_give_the_minimum_norm_point():
    """One level, a rank-1 4 x 4 matrix, lower bounds only (the case where a QP back-end
    once answered with |x| = 6.6e6): the answer is the cascade's minimum-norm point."""
    rng = np.random.default_rng(7)
    u, v = rng.standard_normal(4), rng.standard_normal(4)
    A = np.outer(u, v)
    lower = np.abs(u) * 0.3 * np.linalg.norm(v) * np.sign(u)
    levels = [(A, lower, np.full(4, np.inf))]
    x_ref, optimal = cascade_hierarchy(levels)
    for jit in JITS:
        res = HierarchySolver(jit=jit).solve(levels)
        assert res.converged
        np.testing.assert_allclose(level_residuals(levels, res.x), optimal, atol=1e-9)
        np.testing.assert_allclose(res.x, x_ref, atol=1e-7)
        # the point lies along v: the only direction the rows see
        assert np.linalg.norm(res.x - v * (v @ res.x) / (v @ v)) < 1e-9


def _hard_stacks(count: int):
    """Adversarial stacks whose cold solve takes several iterations."""
    out = []
    for seed in SEEDS:
        levels = adversarial(seed)
        if HierarchySolver(time_budget=None).solve(levels).iterations >= 4:
            out.append(levels)
            if len(out) == count:
                break
    return out


@pytest.mark.parametrize("jit", JITS)
def test_an_iteration_budget_keeps_the_levels_it_solved(jit):
    for levels in _hard_stacks(10):
        _, optimal = cascade_hierarchy(levels)
        tol = 1e-6 * _scale(optimal)
        for budget in (1, 2, 3):
            res = HierarchySolver(jit=jit, time_budget=None, max_iter=budget).solve(levels)
            if res.converged:
                continue
            assert res.status == "iterations" and res.budget_hit
            assert res.iterations <= budget + 1  # the completing step is one more eHQP
            assert np.isfinite(res.x).all()
            assert 0 <= res.solved < len(levels) and res.stopped_level == res.solved
            # the levels it proved are at their optimum (the levels below may be anywhere)
            got = level_residuals(levels, res.x)
            np.testing.assert_allclose(got[: res.solved], optimal[: res.solved], atol=tol)


@pytest.mark.parametrize("jit", JITS)
def test_calls_stopped_by_the_budget_continue_to_the_optimum(jit):
    """The next call starts from the previous call's active rows: a loop whose every
    call stops at a small budget still reaches the optimum of a fixed stack."""
    for levels in _hard_stacks(6):
        _, optimal = cascade_hierarchy(levels)
        solver = HierarchySolver(jit=jit, time_budget=None, max_iter=2)
        for _ in range(200):
            res = solver.solve(levels)
            if res.converged:
                break
        assert res.converged
        np.testing.assert_allclose(
            level_residuals(levels, res.x), optimal, atol=1e-6 * _scale(optimal)
        )


@pytest.mark.parametrize("jit", JITS)
def test_a_tiny_time_budget_stops_with_status_time(jit):
    levels = _hard_stacks(1)[0]
    res = HierarchySolver(jit=jit, time_budget=1e-9, cold_time_budget=None).solve(levels)
    assert res.status == "time" and res.budget_hit and not res.converged
    assert np.isfinite(res.x).all() and res.solved < len(levels)
    assert res.iterations >= 1  # a call always makes progress


@pytest.mark.parametrize("jit", JITS)
def test_a_cold_call_gets_the_cold_budget_and_a_warm_one_the_plain_budget(jit):
    """The first call (no active rows to start from) runs on ``cold_time_budget``; the
    next, on the same level sizes, on ``time_budget``; after ``reset()``, cold again."""
    levels = _hard_stacks(1)[0]
    solver = HierarchySolver(jit=jit, time_budget=1e-9, cold_time_budget=60.0)
    assert solver.solve(levels).status == "optimal"
    moved = [(A, lo - 0.5, up + 0.5 * np.sign(up)) for A, lo, up in levels]
    again = solver.solve(levels[:1] + moved[1:])
    assert again.status == "time" or again.iterations == 1  # the guess may be right
    other = [(A[::-1].copy(), lo[::-1].copy(), up[::-1].copy()) for A, lo, up in levels]
    assert solver.solve(other).status == "time"  # warm start from a wrong set
    solver.reset()
    assert solver.solve(other).status == "optimal"
    with pytest.raises(SolverError, match="cold_time_budget must be a finite number"):
        solver.cold_time_budget = -1.0
    with pytest.raises(SolverError, match="cold_time_budget must be a finite number"):
        solver.cold_time_budget = float("inf")
    assert solver.cold_time_budget == 60.0


@pytest.mark.parametrize("jit", JITS)
@pytest.mark.parametrize("budget", [None, 1e-9])
def test_a_warm_row_whose_bound_became_infinite_is_no_warm_start(jit, budget):
    """A row active at its upper bound in one call, with that bound +inf in the next (a
    reference set to inf, or other rows in the same places): its old target would be inf
    and the start point NaN. The answer stays finite and, unbudgeted, optimal."""
    box = (np.eye(2), np.array([-np.inf, -1.0]), np.array([1.0, 1.0]))
    goal = (np.eye(2), np.array([3.0, 0.5]), np.array([3.0, 0.5]))
    solver = HierarchySolver(jit=jit, time_budget=budget, cold_time_budget=None)
    first = HierarchySolver(jit=jit, time_budget=None).solve([box, goal])
    np.testing.assert_allclose(first.x, [1.0, 0.5], atol=1e-12)
    assert solver.solve([box, goal]).x is not None
    freed = (np.eye(2), np.array([-10.0, -1.0]), np.array([np.inf, 1.0]))
    res = solver.solve([freed, goal])
    assert np.isfinite(res.x).all()
    if budget is None:
        np.testing.assert_allclose(res.x, [3.0, 0.5], atol=1e-12)
    # the same on an adversarial stack whose rows trade places
    levels = _hard_stacks(1)[0]
    solver = HierarchySolver(jit=jit, time_budget=budget, cold_time_budget=None)
    solver.solve(levels)
    other = [(A[::-1].copy(), lo[::-1].copy(), up[::-1].copy()) for A, lo, up in levels]
    assert np.isfinite(solver.solve(other).x).all()


def _unit_clock(monkeypatch) -> list[int]:
    """A thread CPU clock that advances one unit per eHQP of the NumPy twin (every
    iteration costs the same), read by the kernel and by the solver's entry; returns its
    counter (add to it to make other work cost time)."""
    from sotpy.solvers import _activeset, hierarchy

    done = [0]
    real_ehqp = _activeset._ehqp

    def counted(*a, **k):
        done[0] += 1
        return real_ehqp(*a, **k)

    class Clock:
        @staticmethod
        def thread_time() -> float:
            return float(done[0])

    monkeypatch.setattr(_activeset, "_ehqp", counted)
    monkeypatch.setattr(_activeset, "time", Clock)
    monkeypatch.setattr(hierarchy, "time", Clock)  # the call's entry, where the budget starts
    return done


def test_a_stopped_call_ends_within_its_budget_when_iterations_cost_the_same(monkeypatch):
    """The budget rule: go on only if one more iteration of the longest cost so far and
    the stopped call's last step (one more eHQP) still fit. On a clock that advances one
    unit per eHQP (every iteration costs the same), a call given ``B`` units does at most
    ``B`` eHQPs, and uses its budget (at least ``B - 1``: one more would not have fit),
    less the share kept for the return."""
    done = _unit_clock(monkeypatch)
    levels = next(lv for lv in _hard_stacks(10) if _iterations(lv) >= 9)
    for budget in range(3, 9):
        done[0] = 0
        res = HierarchySolver(jit=False, time_budget=budget, cold_time_budget=None).solve(levels)
        assert res.status == "time" and res.budget_hit
        usable = (1.0 - RETURN_SHARE) * budget
        assert usable - 1 <= done[0] <= usable, (budget, done[0])
        assert res.iterations == done[0]  # every eHQP is counted, the last step's too


def test_the_budget_counts_the_work_before_the_kernel(monkeypatch):
    """The budget is the whole call's, from its entry: when copying the levels costs
    ``c`` units of the clock, ``B - c`` are left for the eHQPs (and the call, entry to
    return, still ends within ``B``)."""
    from sotpy.solvers import hierarchy

    done = _unit_clock(monkeypatch)
    real_copy = hierarchy.HierarchySolver._copy
    cost = 3

    def slow_copy(self, levels):
        done[0] += cost
        return real_copy(self, levels)

    monkeypatch.setattr(hierarchy.HierarchySolver, "_copy", slow_copy)
    levels = next(lv for lv in _hard_stacks(10) if _iterations(lv) >= 9)
    for budget in range(cost + 3, cost + 8):
        done[0] = 0
        res = HierarchySolver(jit=False, time_budget=budget, cold_time_budget=None).solve(levels)
        assert res.status == "time" and res.budget_hit
        usable = (1.0 - RETURN_SHARE) * budget
        assert usable - 1 <= done[0] <= usable, (budget, done[0])
        assert res.iterations == done[0] - cost


def _iterations(levels) -> int:
    return HierarchySolver(jit=False, time_budget=None).solve(levels).iterations


# ---------------------------------------------------------------- SOT and Controller
N = 8


class BudgetTestDevice(Entity):
    """Pulls the SOT's control at each tick and flips the tracked target's sign, so that
    the previous tick's active rows are always wrong."""

    def __init__(self, name: str, sot: SOT, feature: FeatureGeneric) -> None:
        super().__init__(name)
        self.sot, self.feature, self.t = sot, feature, 0

    def increment(self, dt: float) -> None:
        self.t += 1
        self.feature.errorIN.value = (-1.0) ** self.t * np.linspace(1.0, 2.0, N)
        self.sot.control.recompute(self.t)


def _flipping_sot(prefix: str) -> tuple[SOT, FeatureGeneric]:
    rng = np.random.default_rng(3)
    box = FeatureGeneric(prefix + "fbox")
    box.errorIN.value = np.zeros(N)
    box.jacobianIN.value = np.eye(N)
    limits = TaskInequality(prefix + "box")
    limits.add(box)
    limits.referenceInf.value = np.full(N, -0.1)
    limits.referenceSup.value = np.full(N, 0.1)
    limits.dt.value = 1.0
    reach = FeatureGeneric(prefix + "freach")
    reach.errorIN.value = np.linspace(1.0, 2.0, N)
    reach.jacobianIN.value = rng.standard_normal((N, N))
    task = Task(prefix + "reach")
    task.add(reach)
    task.controlGain.value = 1.0
    sot = SOT(prefix + "sot")
    sot.setSize(N)
    sot.push(limits)
    sot.push(task)
    return sot, reach


def test_sot_budget_hits_warn_once_and_are_counted_by_the_loop():
    sot, reach = _flipping_sot("budget_")
    sot.setMaxIterations(1)
    dev = BudgetTestDevice("budget_dev", sot, reach)
    loop = ControlLoop("budget_loop", dev, 0.001)
    with pytest.warns(BudgetWarning, match=r"SOT\(budget_sot\): the solver stopped at its"):
        loop.run(1, realtime=False)
    with warnings.catch_warnings():
        warnings.simplefilter("error", BudgetWarning)  # said once while it keeps hitting
        loop.run(9, realtime=False)
    assert sot.budgetHits == 10
    assert loop.stats().budget_hits == 9  # the statistics of the last run
    # every answer stays inside the box (the hard level), budget or not
    x = sot.control.value
    assert np.all(np.abs(x) <= 0.1 + 1e-9)
    # with room to converge: no more hits, and the next hit warns again
    sot.setMaxIterations(200)
    loop.run(3, realtime=False)
    assert sot.budgetHits == 10
    sot.setMaxIterations(1)
    with pytest.warns(BudgetWarning):
        loop.run(1, realtime=False)


def test_sot_refuses_bad_budgets_and_keeps_its_settings():
    sot, _ = _flipping_sot("badbudget_")
    sot.setTimeBudget(2e-3)
    sot.setMaxIterations(50)
    for bad in (0.0, -1.0, float("nan"), float("inf"), "fast"):
        with pytest.raises(CommandError, match=r"SOT\(badbudget_sot\)\.setTimeBudget"):
            sot.setTimeBudget(bad)
    for bad in (0, -3, 2.5, True):
        with pytest.raises(CommandError, match=r"SOT\(badbudget_sot\)\.setMaxIterations"):
            sot.setMaxIterations(bad)
    assert sot.getTimeBudget() == 2e-3 and sot.getMaxIterations() == 50
    sot.setTimeBudget(None)
    assert sot.getTimeBudget() is None


def test_controller_budget_hits_warn_once_and_a_stop_before_the_constraints_falls_back():
    from sotpy.dynamics import load_robot
    from sotpy.graph import plug
    from sotpy.solvers.controller import Controller

    robot = load_robot("panda", prefix="budget_")
    ctrl = Controller("budget_ctrl", robot.dynamic)
    ctrl.addCartesianTask("ee", "panda_hand_tcp", 1.0, 1)
    ctrl.addJointTask("posture", 1.0, 2)
    lim = np.minimum(robot.model.effortLimit[-9:], 30.0)  # within the device's own
    ctrl.addTorqueLimits("tau", -lim, lim)
    ctrl.setResolutionStrategy("MultiLevelWeighted")
    ctrl.activateTasksAndConstraints()
    ctrl.ee.value = np.array([20.0, -20.0, 20.0, 0, 0, 0])  # far: the limits bind
    ctrl.setMaxIterations(1)
    robot.device.setControlType("torque")
    plug(ctrl.torque, robot.device.control)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        robot.device.increment(0.001)
    said = [str(w.message) for w in caught if issubclass(w.category, SotpyWarning)]
    # one iteration does not reach the torque limits from a cold start: the controller
    # says why and sends its fallback (gravity compensation, within the limits)
    assert any("stopped at its iterations budget before it met the constraints" in m for m in said)
    assert sum(issubclass(w.category, BudgetWarning) for w in caught) == 1
    assert ctrl.budgetHits == 1 and not ctrl.solutionFound.value
    with warnings.catch_warnings():
        warnings.simplefilter("error", BudgetWarning)  # said once while it keeps hitting
        robot.device.increment(0.001)
        robot.device.increment(0.001)
    assert ctrl.budgetHits == 3
    assert np.all(np.abs(ctrl.torque.value) <= lim + 1e-6)
    # room to converge: the limits hold, found, no more hits
    hits = ctrl.budgetHits  # (reading torque.value above may have solved once more)
    ctrl.setMaxIterations(200)
    ctrl.setTimeBudget(None)  # a loaded test machine must not decide this one
    with warnings.catch_warnings():  # the far target drives the fingers to their speed
        warnings.filterwarnings("ignore", r"Device\(budget__device\): velocity bounds")
        robot.device.increment(0.001)
    assert ctrl.solutionFound.value and ctrl.budgetHits == hits
    tau = ctrl.torque.value
    assert np.all(np.abs(tau) <= lim + 1e-6)
    assert np.any(np.abs(tau) >= lim - 1e-6)  # they bind
    with pytest.raises(CommandError, match=r"Controller\(budget_ctrl\)\.setMaxIterations"):
        ctrl.setMaxIterations(0)
    assert ctrl.getMaxIterations() == 200
