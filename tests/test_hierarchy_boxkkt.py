"""The box path as one compiled call (sotpy.solvers._boxkkt): a box first, equality
levels below whose upper levels are met exactly. Every answer is compared with the
independent reference cascade and with the NumPy path (``jit=False``); the statuses
are counted to check which path answered, and what it refuses goes to the NumPy path
with the same answer."""

from __future__ import annotations

import numpy as np
import pytest

from reference_hierarchy import cascade_hierarchy, level_residuals
from sotpy.solvers import HierarchySolver, _boxkkt

pytestmark = pytest.mark.skipif(_boxkkt.box_kkt is None, reason="numba missing or SOTPY_JIT=0")

QP_TOL = 1e-6


@pytest.fixture
def statuses(monkeypatch):
    """Count the compiled box path's statuses (OK, REFUSED, UNDECIDED, NOT_CONVERGED;
    LEFT: the lane's, after which the usual path calls box_kkt), over both of its
    entries (box_kkt, and the lane that the call after an answered one takes)."""
    counts = {s: 0 for s in range(5)}

    def spy_on(real):
        def spy(*args):
            out = real(*args)
            counts[int(out[0])] += 1
            return out

        return spy

    for name in ("box_kkt", "lane"):
        monkeypatch.setattr(_boxkkt, name, spy_on(getattr(_boxkkt, name)))
    return counts


def reach_like(rng, n, last_rows):
    """A box on every variable, full-rank upper levels (feet-, hand-like) met by a
    point well inside the box, a last level of ``last_rows`` rows whose target pulls
    some variables onto their bounds."""
    half = rng.uniform(0.2, 0.8, n)
    box = (np.eye(n), -half, half)
    inside = rng.uniform(-0.3, 0.3, n) * half
    levels = [box]
    for m in (4, 2):
        A = rng.standard_normal((m, n))
        b = A @ inside
        levels.append((A, b, b))
    A = rng.standard_normal((last_rows, n))
    b = rng.standard_normal(last_rows)
    levels.append((A, b, b))
    return levels


def assert_same(levels, res, x_ref, optimal):
    scale = 1.0 + float(np.abs(x_ref).max())
    np.testing.assert_allclose(res.residuals, optimal, atol=QP_TOL * scale)
    np.testing.assert_allclose(res.x, x_ref, atol=10 * QP_TOL * scale)
    # the kernel's residuals are those of its point
    np.testing.assert_allclose(res.residuals, level_residuals(levels, res.x), atol=1e-12)


@pytest.mark.parametrize("seed", range(12))
@pytest.mark.parametrize("last", ["least-squares", "min-norm"])
def test_compiled_box_path_gives_the_cascade_answer(seed, last, statuses):
    rng = np.random.default_rng(4100 + seed)
    n = int(rng.integers(8, 20))
    # least squares: more rows than the directions the upper levels leave; min-norm:
    # every level fits (the minimum-norm rule decides what is left)
    rows = n + 3 if last == "least-squares" else max(1, n - 10)
    levels = reach_like(rng, n, rows)
    x_ref, optimal = cascade_hierarchy(levels)
    solver = HierarchySolver()
    numpy_path = HierarchySolver(jit=False)
    for _ in range(2):  # the first call from an empty guess, the second from its own
        res = solver.solve(levels)
        assert_same(levels, res, x_ref, optimal)
        other = numpy_path.solve(levels)
    # the second call is proved by the kernel, as the NumPy path proves it
    assert statuses[_boxkkt.OK] >= 1 and res.method in ("active-set", "shortcut"), statuses
    np.testing.assert_allclose(res.x, other.x, atol=1e-9 * (1 + np.abs(other.x).max()))
    np.testing.assert_array_equal(res.ranks, other.ranks)
    assert res.method == other.method


def test_min_norm_and_least_squares_ranks():
    """Ranks as the level-by-level path reports them: each upper level its rows; a
    least-squares last level the directions left after the upper levels and the fixed
    variables; in min-norm mode every level its rows."""
    rng = np.random.default_rng(7)
    n = 12
    for rows in (n + 3, 2):
        levels = reach_like(rng, n, rows)
        res = HierarchySolver().solve(levels)
        held = int(np.sum(np.isclose(np.abs(res.x), levels[0][2], rtol=0, atol=1e-12)))
        expected = [0, 4, 2, n - 6 - held if rows > n else rows]
        np.testing.assert_array_equal(res.ranks, expected)


@pytest.mark.parametrize("wrong", ["dropped", "added"])
def test_wrong_guesses_are_corrected_in_the_kernel(wrong, statuses):
    """The right active set with one of its bounds dropped (the point crosses it: added
    back) or with a wrong one added (its multiplier has the wrong sign: released). Every
    answer is the cascade's; the kernel corrects most guesses itself (a correction can
    move other variables across their bounds, which takes more of its few iterations:
    then the NumPy path goes on from its guess)."""
    proved = 0
    for seed in range(8):
        rng = np.random.default_rng(4200 + seed)
        n = 14
        levels = reach_like(rng, n, n + 2)
        A0, lo, hi = levels[0]
        levels[0] = (A0, 0.5 * lo, 0.5 * hi)  # narrower: several bounds active
        x_ref, optimal = cascade_hierarchy(levels)
        solver = HierarchySolver()
        for _ in range(2):
            solver.solve(levels)
        box = solver._structure.box
        held = np.flatnonzero(box.at_lo | box.at_hi)
        assert 1 <= len(held) < n - 6
        ok = statuses[_boxkkt.OK]
        if wrong == "dropped":
            j = rng.choice(held)
            box.at_lo[j] = box.at_hi[j] = False
        else:
            # the free variable nearest to a bound held at it (as a bound that the
            # previous tick held and this one leaves)
            x = x_ref / (0.5 * hi)
            x[held] = 0.0
            j = int(np.argmax(np.abs(x)))
            (box.at_hi if x[j] > 0 else box.at_lo)[j] = True
        res = solver.solve(levels)
        assert_same(levels, res, x_ref, optimal)
        proved += statuses[_boxkkt.OK] == ok + 1
    assert proved >= 6, proved


def test_a_wrong_bound_is_released_by_the_sign_of_its_multiplier(statuses):
    """x_0 held at its upper bound although the last level pulls it inside: released in
    the kernel (no fallback), the answer is the cascade's."""
    n = 4
    box = (np.eye(n), -np.ones(n), np.ones(n))
    target = np.array([0.5, -0.2, 0.3, 0.1])
    levels = [box, (np.ones((1, n)), np.array([0.7]), np.array([0.7])), (np.eye(n), target, target)]
    x_ref, _ = cascade_hierarchy(levels)
    solver = HierarchySolver()
    solver.solve(levels)
    solver._structure.box.at_hi[0] = True
    res = solver.solve(levels)
    np.testing.assert_allclose(res.x, x_ref, atol=1e-9)
    assert not solver._structure.box.at_hi[0]
    assert statuses[_boxkkt.OK] == 2


def test_a_crossed_bound_is_added_in_the_kernel(statuses):
    """From an empty guess the unconstrained point leaves the box: the variables it
    crosses are fixed at their bounds, and the answer is the cascade's."""
    n = 4
    box = (np.eye(n), -np.full(n, 0.2), np.full(n, 0.2))
    target = np.array([0.9, -0.1, -0.8, 0.05])
    levels = [box, (np.eye(n), target, target)]
    x_ref, _ = cascade_hierarchy(levels)
    res = HierarchySolver().solve(levels)
    np.testing.assert_allclose(res.x, x_ref, atol=1e-9)
    np.testing.assert_allclose(res.x, np.clip(target, -0.2, 0.2), atol=1e-12)
    assert res.method == "active-set"
    assert statuses[_boxkkt.OK] == 1


def test_rank_deficient_upper_level_is_refused_and_waits(statuses):
    """Two parallel rows in an upper level: the QR of the upper rows is singular, the
    kernel refuses, the level-by-level path answers (the cascade's answer) and the
    kernel is not tried again for a while."""
    rng = np.random.default_rng(11)
    n = 10
    levels = reach_like(rng, n, n + 2)
    A, b, _ = levels[1]
    A = np.vstack([A, 2.0 * A[0]])
    b = np.append(b, 2.0 * b[0])
    levels[1] = (A, b, b)
    x_ref, optimal = cascade_hierarchy(levels)
    solver = HierarchySolver()
    for _ in range(5):
        res = solver.solve(levels)
        assert_same(levels, res, x_ref, optimal)
    assert statuses[_boxkkt.REFUSED] == 1 and statuses[_boxkkt.OK] == 0
    assert solver._structure.kkt_wait > 0


def test_last_level_blind_to_some_directions_is_refused(statuses):
    """A posture without the free flyer's columns: the last level leaves directions
    free (the minimum-norm rule must decide them), the kernel refuses."""
    rng = np.random.default_rng(12)
    n = 12
    posture = np.zeros((n - 6, n))
    posture[:, 6:] = np.eye(n - 6)
    target = rng.standard_normal(n - 6)
    levels = [(np.eye(n), -np.ones(n), np.ones(n)), (posture, target, target)]
    x_ref, optimal = cascade_hierarchy(levels)
    res = HierarchySolver().solve(levels)
    assert_same(levels, res, x_ref, optimal)
    assert statuses[_boxkkt.REFUSED] == 1 and statuses[_boxkkt.OK] == 0


def test_bound_not_pushed_against_is_left_to_the_level_by_level_path(statuses):
    """The last level's optimum sits exactly on a bound: held there, its multiplier is
    zero; the kernel does not decide it (UNDECIDED) and the NumPy path does."""
    n = 3
    box = (np.eye(n), -np.ones(n), np.ones(n))
    target = np.array([1.0, 0.2, -0.3])  # x_0 wants exactly its upper bound
    levels = [box, (np.eye(n), target, target)]
    solver = HierarchySolver()
    solver.solve(levels)
    solver._structure.box.at_hi[0] = True
    res = solver.solve(levels)
    np.testing.assert_allclose(res.x, target, atol=1e-12)
    assert statuses[_boxkkt.UNDECIDED] == 1


def test_fixed_variables_and_empty_levels(statuses):
    """Bounds that coincide (a variable fixed, never released) and an empty level
    between the upper ones and the last one."""
    rng = np.random.default_rng(13)
    n = 10
    levels = reach_like(rng, n, n + 1)
    lo, hi = levels[0][1].copy(), levels[0][2].copy()
    lo[3] = hi[3] = 0.05
    levels[0] = (levels[0][0], lo, hi)
    levels.insert(2, (np.zeros((0, n)), np.zeros(0), np.zeros(0)))
    x_ref, optimal = cascade_hierarchy(levels)
    solver = HierarchySolver()
    for _ in range(2):
        res = solver.solve(levels)
        assert_same(levels, res, x_ref, optimal)
    assert res.x[3] == 0.05
    assert statuses[_boxkkt.OK] == 2


def test_drifting_stack_stays_on_the_compiled_path(statuses):
    """A stack that drifts tick by tick (the upper levels' point moving inside the box,
    the last target sweeping, bounds entering and leaving the active set): every answer
    is the cascade's and the compiled path gives almost all of them."""
    rng = np.random.default_rng(14)
    n = 12
    half = rng.uniform(0.3, 0.8, n)
    box = (np.eye(n), -half, half)
    upper = [rng.standard_normal((4, n)), rng.standard_normal((2, n))]
    last = rng.standard_normal((n + 2, n))
    target = rng.standard_normal(n + 2)
    solver = HierarchySolver()
    active = set()
    for t in range(30):
        inside = 0.3 * half * np.sin(0.1 * t + np.arange(n))
        stack = [box] + [(A, A @ inside, A @ inside) for A in upper]
        b = (1.0 + 0.05 * t) * target
        stack.append((last, b, b))
        x_ref, optimal = cascade_hierarchy(stack)
        res = solver.solve(stack)
        assert_same(stack, res, x_ref, optimal)
        active.add(int(np.sum(np.isclose(np.abs(res.x), half, rtol=0, atol=1e-12))))
    assert len(active) >= 3, active  # the active set changed along the way
    assert statuses[_boxkkt.OK] >= 28, statuses


@pytest.mark.parametrize("seed", range(12))
def test_numpy_path_keeps_priorities_when_a_merged_block_exceeds_the_free_directions(seed):
    """Regression (found by comparing the two paths): the NumPy box path factors the
    levels found of full rank at the previous call as one block; when the guess fixes
    more variables and the block, which includes the last level, has more rows than free
    directions, the block must be split, not solved as one least-squares fit (which
    traded the upper levels against the last one)."""
    rng = np.random.default_rng(4100 + seed)
    n = int(rng.integers(8, 20))
    levels = reach_like(rng, n, max(1, n - 10))
    x_ref, optimal = cascade_hierarchy(levels)
    solver = HierarchySolver(jit=False)
    for _ in range(3):
        assert_same(levels, solver.solve(levels), x_ref, optimal)


def rank_deficient_below_box(rng, n, scale):
    """A box on every variable of half-width ``scale``; below it a level with a
    repeated row (rank deficient: the compiled box call refuses it), a conflicting
    level, and a least-squares last level; the targets small enough for the optimum to
    lie inside a wide box."""
    A1 = rng.standard_normal((4, n))
    A1[3] = A1[1]
    b1 = 0.1 * rng.standard_normal(4)
    A2 = rng.standard_normal((3, n))
    A2[2] = A2[0]
    b2 = 0.1 * rng.standard_normal(3)
    b2[2] = b2[0] + 0.05  # the same row, two targets: in conflict
    A3 = rng.standard_normal((n + 2, n))
    b3 = 0.1 * rng.standard_normal(n + 2)
    return [
        (np.eye(n), -scale * np.ones(n), scale * np.ones(n)),
        (A1, b1, b1),
        (A2, b2, b2),
        (A3, b3, b3),
    ]


def narrowed(levels, half: float):
    """``levels`` with the box (level 0, on every variable) of half-width ``half``."""
    n = levels[0][0].shape[1]
    return [(levels[0][0], -half * np.ones(n), half * np.ones(n)), *levels[1:]]


@pytest.fixture
def free_calls(monkeypatch):
    """Count the answers of the compiled equality recursion with no bound fixed (on
    the usual path, and through the free lane that the calls after one take)."""
    calls = {"answered": 0}
    real = HierarchySolver._box_free_compiled
    real_lane = _boxkkt.free_lane

    def spy(self, st, stepper):
        out = real(self, st, stepper)
        calls["answered"] += out is not None
        return out

    def spy_lane(*args):
        out = real_lane(*args)
        calls["answered"] += int(out[0]) == _boxkkt.OK
        return out

    monkeypatch.setattr(HierarchySolver, "_box_free_compiled", spy)
    monkeypatch.setattr(_boxkkt, "free_lane", spy_lane)
    return calls


@pytest.mark.parametrize("seed", range(8))
def test_rank_deficient_levels_inside_the_box_take_the_compiled_recursion(
    seed, statuses, free_calls
):
    """Rank-deficient levels below a box that no bound of the optimum touches: the
    compiled box call refuses the shape, the compiled equality recursion answers, and
    the answer is the reference cascade's and the NumPy path's (ranks included)."""
    rng = np.random.default_rng(4700 + seed)
    n = int(rng.integers(8, 16))
    levels = rank_deficient_below_box(rng, n, 100.0)
    x_ref, optimal = cascade_hierarchy(levels)
    assert np.abs(x_ref).max() < 100.0  # the box is not active
    solver = HierarchySolver()
    for _ in range(3):
        res = solver.solve(levels)
        assert_same(levels, res, x_ref, optimal)
    assert statuses[_boxkkt.REFUSED] >= 1 and statuses[_boxkkt.OK] == 0, statuses
    assert free_calls["answered"] == 3
    other = HierarchySolver(jit=False).solve(levels)
    np.testing.assert_allclose(res.x, other.x, atol=1e-9 * (1 + np.abs(other.x).max()))
    np.testing.assert_array_equal(res.ranks, other.ranks)
    assert res.method == other.method == "shortcut"
    assert res.ranks[1] == 3 and res.ranks[2] == 2  # the repeated rows counted once


@pytest.mark.parametrize("seed", range(4))
def test_a_point_outside_the_box_goes_on_with_its_bounds_fixed(seed, free_calls):
    """The same shape with a box the unconstrained point leaves: the compiled recursion
    answers the first try, the crossing variables are fixed, and the NumPy path ends at
    the cascade's answer. Back in a wide box, the recursion answers again once the
    bounds are released."""
    rng = np.random.default_rng(4800 + seed)
    n = int(rng.integers(8, 16))
    wide = rank_deficient_below_box(rng, n, 100.0)
    x_wide, opt_wide = cascade_hierarchy(wide)
    tight = narrowed(wide, 0.8 * np.abs(x_wide).max())
    x_tight, opt_tight = cascade_hierarchy(tight)
    solver = HierarchySolver()
    res = solver.solve(tight)
    assert free_calls["answered"] == 1  # the first try, then the crossing bounds fixed
    assert_same(tight, res, x_tight, opt_tight)
    assert res.method != "shortcut"
    for _ in range(2):
        res = solver.solve(wide)
        assert_same(wide, res, x_wide, opt_wide)
    assert res.method == "shortcut" and free_calls["answered"] >= 2


# ------------------------------------------------------------ posture-shaped last level
def posture_stack(rng, n_base, n_joints, selected, tight=0.5, upper=None):
    """An SOT-like stack: joint limits on the joints (the first ``n_base`` variables,
    a free flyer, unbounded), upper levels of ``upper`` rows (default ``n_base + 5``
    and 3) met inside the box, and a posture on the joints ``selected`` (rows of the
    identity, in a shuffled order) whose target pulls some joints onto their limits."""
    n = n_base + n_joints
    half = rng.uniform(0.2, 0.8, n_joints)
    box = (np.hstack([np.zeros((n_joints, n_base)), np.eye(n_joints)]), -half, half)
    inside = np.concatenate([rng.standard_normal(n_base), rng.uniform(-0.3, 0.3, n_joints) * half])
    levels = [box]
    for m in upper or (n_base + 5, 3):
        A = rng.standard_normal((m, n))
        b = A @ inside
        levels.append((A, b, b))
    cols = n_base + rng.permutation(np.asarray(selected))
    P = np.zeros((len(cols), n))
    P[np.arange(len(cols)), cols] = 1.0
    target = rng.uniform(-1.5, 1.5, len(cols)) * half[cols - n_base] / tight
    levels.append((P, target, target))
    return levels


def kernel_inputs(levels, at_lo, at_hi):
    """The compiled kernel's inputs for ``levels`` (as the solver stacks them) and the
    fixed/free split of the guess ``at_lo | at_hi``."""
    solver = HierarchySolver()
    st, parsed, general = solver._prepare(levels)
    solver._bookkeep(st, parsed, general)
    box = solver._box(st)
    held = at_lo | at_hi
    W = np.flatnonzero(held).astype(np.int64)
    F = np.flatnonzero(~held).astype(np.int64)
    vals = np.where(at_lo, box.lo, box.hi)[W]
    return st.A, int(st.starts[1]), int(st.starts[st.last]), W, vals, F


def posture_split(levels, at_lo, at_hi):
    """The kernel's posture split on ``levels`` with the guess ``at_lo | at_hi``:
    ``(answered, x_aug, mu_U, inputs)``, ``x_aug`` starting as ones (to see what is
    written), ``inputs`` those of :func:`kernel_inputs`."""
    inputs = kernel_inputs(levels, at_lo, at_hi)
    A, s1, split, W, vals, F = inputs
    row_of = _boxkkt._posture_columns(A, split)
    x, mu = np.ones(A.shape[1]), np.zeros(split - s1)
    ok = _boxkkt._posture_solve(A, s1, split - s1, row_of, W, vals, F, x, mu, 1e-9)
    return ok, x, mu, inputs


SHAPES = {
    # free flyer and joints; some joints without a posture row (in N with the base)
    "humanoid": (6, None, False),
    "humanoid, posture on some joints": (6, None, True),
    # the upper rows only fix the free flyer (one foot): M is empty, x_P = c
    "one foot": (6, (6,), False),
    # a fixed base: N is empty, Q_N = I
    "fixed base": (0, (5, 3), False),
}


@pytest.mark.parametrize("seed", range(4))
@pytest.mark.parametrize("shape", list(SHAPES))
def test_posture_split_gives_the_general_solve(seed, shape):
    """The posture-shaped solve (free flyer ``N`` from a QR of its upper columns, the
    joints by a minimum-norm correction) against the general null-space solve on the
    same kernel inputs: the same point and the same upper multipliers, for random
    guesses of the fixed joints."""
    rng = np.random.default_rng(5100 + seed)
    n_base, upper, some = SHAPES[shape]
    n_joints = int(rng.integers(14, 30))
    selected = rng.permutation(n_joints)[: n_joints - 2] if some else np.arange(n_joints)
    levels = posture_stack(rng, n_base, n_joints, selected, upper=upper)
    n = n_base + n_joints
    at_lo = np.zeros(n, dtype=bool)
    at_hi = np.zeros(n, dtype=bool)
    fixed = n_base + rng.choice(n_joints, size=int(rng.integers(0, 5)), replace=False)
    at_lo[fixed[::2]] = True
    at_hi[fixed[1::2]] = True
    ok, x_p, mu_p, inputs = posture_split(levels, at_lo, at_hi)
    assert ok
    A, s1, split, W, vals, F = inputs
    mu_ = split - s1
    assert len(_boxkkt._posture_columns(A, split)) == n  # recognised as a posture
    x_g, mu_g, g = np.ones(n + 1), np.zeros(mu_), np.empty(n)
    ml = A.shape[0] - split
    scratch = _boxkkt._lapack_scratch(n, A.shape[0])
    assert _boxkkt._general_solve(
        A, s1, split, mu_, ml, False, W, vals, F, x_g, g, mu_g, 1e-9, *scratch
    )
    np.testing.assert_allclose(x_p, x_g, atol=1e-11 * (1 + np.abs(x_g).max()))
    np.testing.assert_allclose(mu_p, mu_g, atol=1e-10 * (1 + np.abs(mu_g).max()))
    # and both are the KKT point: upper rows met, stationarity on the free variables
    U = A[s1:split]
    np.testing.assert_allclose(U @ x_p, 0.0, atol=1e-10 * (1 + np.abs(x_p).max()))
    np.testing.assert_allclose((g + U[:, :n].T @ mu_p)[F], 0.0, atol=1e-9)


def test_posture_columns_recognises_only_rows_of_the_identity():
    n = 6
    P = np.zeros((3, n))
    P[[0, 1, 2], [4, 2, 5]] = 1.0
    A = np.hstack([np.vstack([np.ones((2, n)), P]), np.zeros((5, 1))])
    np.testing.assert_array_equal(_boxkkt._posture_columns(A, 2), [-1, -1, 3, -1, 2, 4])
    for spoil in ("scaled", "two entries", "same column", "empty row"):
        B = A.copy()
        if spoil == "scaled":
            B[3, 2] = 2.0
        elif spoil == "two entries":
            B[3, 0] = 0.5
        elif spoil == "same column":
            B[4] = B[3]
        else:
            B[4, :n] = 0.0
        assert len(_boxkkt._posture_columns(B, 2)) == 0, spoil


@pytest.mark.parametrize("seed", range(3))
@pytest.mark.parametrize("shape", list(SHAPES))
def test_posture_stack_is_answered_by_the_kernel(seed, shape, statuses):
    """SOT-shaped stacks (joint limits, a free flyer or a fixed base, a posture on all
    or some joints): every answer is the reference cascade's and the NumPy path's,
    ranks included, and the compiled call proves it."""
    rng = np.random.default_rng(5200 + seed)
    n_base, upper, some = SHAPES[shape]
    n_joints = int(rng.integers(12, 32))
    selected = np.arange(3, n_joints) if some else np.arange(n_joints)  # 3 left out
    levels = posture_stack(rng, n_base, n_joints, selected, upper=upper)
    x_ref, optimal = cascade_hierarchy(levels)
    solver = HierarchySolver()
    numpy_path = HierarchySolver(jit=False)
    for _ in range(2):  # the second call from the guess of the first (as tick to tick)
        res = solver.solve(levels)
        assert_same(levels, res, x_ref, optimal)
        other = numpy_path.solve(levels)
    np.testing.assert_allclose(res.x, other.x, atol=1e-9 * (1 + np.abs(other.x).max()))
    np.testing.assert_array_equal(res.ranks, other.ranks)
    assert res.method == other.method == "active-set"
    assert statuses[_boxkkt.OK] >= 1, statuses
    held = np.isclose(np.abs(res.x[n_base:]), levels[0][2], rtol=0, atol=1e-12)
    assert held.any()  # the posture pulled joints onto their limits


def test_posture_split_refuses_a_free_flyer_the_upper_levels_do_not_see():
    """A free-flyer direction that no upper row moves: the posture leaves it free
    (rank-deficient ``U_N``), the split refuses, and so does the general solve (the
    minimum-norm rule must decide that direction): the NumPy path answers, with the
    cascade's answer."""
    rng = np.random.default_rng(5300)
    levels = posture_stack(rng, 6, 14, np.arange(14))
    for k in (1, 2):
        A, b, _ = levels[k]
        A = A.copy()
        A[:, 2] = 0.0
        levels[k] = (A, b, b)
    none = np.zeros(20, dtype=bool)
    assert not posture_split(levels, none, none)[0]
    x_ref, optimal = cascade_hierarchy(levels)
    assert_same(levels, HierarchySolver().solve(levels), x_ref, optimal)


def test_posture_split_refuses_dependent_upper_rows():
    """Upper rows that repeat each other (``M`` of deficient row rank): the split
    refuses rather than dividing by a vanishing pivot."""
    rng = np.random.default_rng(5400)
    levels = posture_stack(rng, 6, 14, np.arange(14))
    A, b, _ = levels[1]
    A = np.vstack([A, A[0]])
    b = np.append(b, b[0])
    levels[1] = (A, b, b)
    none = np.zeros(20, dtype=bool)
    answered, x, _, _ = posture_split(levels, none, none)
    assert not answered
    np.testing.assert_array_equal(x, 1.0)  # nothing written


@pytest.mark.parametrize("seed", range(4))
def test_one_foot_and_a_reachable_posture_is_the_square_solve(seed, statuses):
    """One 6-row level on the free flyer, a posture on every joint inside its limits:
    as many rows as variables, every level met, nothing at a bound. The kernel's
    posture split gives the only point (the joints at their targets, the free flyer
    from the foot rows): the cascade's answer and the NumPy path's."""
    rng = np.random.default_rng(5500 + seed)
    n_joints = int(rng.integers(12, 32))
    levels = posture_stack(rng, 6, n_joints, np.arange(n_joints), tight=4.0, upper=(6,))
    P, target, _ = levels[-1]
    assert np.all(np.abs(target) < levels[0][2][P.argmax(axis=1) - 6])  # inside the box
    x_ref, optimal = cascade_hierarchy(levels)
    solver = HierarchySolver()
    for _ in range(2):
        res = solver.solve(levels)
        assert_same(levels, res, x_ref, optimal)
    other = HierarchySolver(jit=False).solve(levels)
    np.testing.assert_allclose(res.x, other.x, atol=1e-10 * (1 + np.abs(other.x).max()))
    np.testing.assert_array_equal(res.ranks, other.ranks)
    assert res.method == other.method == "shortcut"
    np.testing.assert_allclose(P @ res.x, target, rtol=0, atol=1e-13)
    assert statuses[_boxkkt.OK] == 2 and statuses[_boxkkt.REFUSED] == 0
