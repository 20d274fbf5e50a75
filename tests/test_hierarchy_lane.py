"""The box lane (sotpy.solvers._boxkkt.lane): the call after one that the compiled box
path answered, with the same row classes, runs the bookkeeping, the box and the solve
as one compiled call. It must give the usual path's answer bit for bit, leave to the
usual path (untouched) whatever it cannot prove or check, and so keep its errors.
Each test runs a solver with the lane and one without it side by side."""

from __future__ import annotations

import numpy as np
import pytest

from reference_hierarchy import cascade_hierarchy
from sotpy.errors import SolverError
from sotpy.solvers import HierarchySolver, _boxkkt
from test_hierarchy_boxkkt import reach_like

pytestmark = pytest.mark.skipif(_boxkkt.lane is None, reason="numba missing or SOTPY_JIT=0")


def statuses_of(monkeypatch, name: str) -> list[int]:
    """The statuses of the kernel ``_boxkkt.<name>``, in call order."""
    calls: list[int] = []
    real = getattr(_boxkkt, name)

    def spy(*args):
        out = real(*args)
        calls.append(int(out[0]))
        return out

    monkeypatch.setattr(_boxkkt, name, spy)
    return calls


@pytest.fixture
def lane_calls(monkeypatch):
    return statuses_of(monkeypatch, "lane")


def pair(n: int | None = None) -> tuple[HierarchySolver, HierarchySolver]:
    """A solver with the lane and one whose lane never applies."""
    without = HierarchySolver(n)
    without._lane_solve = lambda st, damping: None
    return HierarchySolver(n), without


def drifting(seed: int, n: int = 16, ticks: int = 12):
    """A box stack whose matrices and targets drift from call to call."""
    rng = np.random.default_rng(seed)
    base = reach_like(rng, n, n + 3)
    dA = [rng.standard_normal(A.shape) for A, _, _ in base]
    for t in range(ticks):
        s = 0.02 * np.sin(0.3 * t)
        levels = [base[0]]
        for (A, lo, _), D in zip(base[1:], dA[1:], strict=True):
            b = lo + s
            levels.append((A + s * D, b, b))
        yield levels


def same(a, b) -> None:
    assert np.array_equal(a.x, b.x)
    assert np.array_equal(a.residuals, b.residuals)
    assert np.array_equal(a.ranks, b.ranks)
    assert a.method == b.method


def same_guess(a: HierarchySolver, b: HierarchySolver) -> None:
    ba, bb = a._structure.box, b._structure.box
    assert np.array_equal(ba.at_lo, bb.at_lo)
    assert np.array_equal(ba.at_hi, bb.at_hi)


def same_error(fast: HierarchySolver, slow: HierarchySolver, levels) -> str:
    """Both solvers refuse ``levels`` with the same message; the message."""
    messages = []
    for solver in (fast, slow):
        with pytest.raises(SolverError) as info:
            solver.solve(levels)
        messages.append(str(info.value))
    assert messages[0] == messages[1]
    return messages[0]


def warmed(seed: int, ticks: int):
    """A pair of solvers (:func:`pair`) after the first three calls of a drifting
    sequence (the lane is in use from the second), and the whole sequence."""
    fast, slow = pair()
    seq = list(drifting(seed, ticks=ticks))
    for levels in seq[:3]:
        same(fast.solve(levels), slow.solve(levels))
    return fast, slow, seq


@pytest.mark.parametrize("seed", range(6))
def test_the_lane_gives_the_usual_answer_bit_for_bit(seed, lane_calls):
    fast, slow = pair()
    for levels in drifting(5100 + seed):
        same(fast.solve(levels), slow.solve(levels))
        same_guess(fast, slow)
    # every call after the first answered one goes through the lane
    assert lane_calls.count(_boxkkt.OK) >= 9, lane_calls
    x_ref, _ = cascade_hierarchy(levels)
    np.testing.assert_allclose(fast.solve(levels).x, x_ref, atol=1e-5)


def test_the_lane_through_the_stacked_buffers(lane_calls):
    """solve_stacked takes the lane as solve does; the same answers."""
    fast, slow = pair(16)
    for levels in drifting(5200):
        sizes = [A.shape[0] for A, _, _ in levels]
        A, lo, up, starts = fast.stacked(sizes)
        for k, (Ak, lk, uk) in enumerate(levels):
            A[starts[k] : starts[k + 1]] = Ak
            lo[starts[k] : starts[k + 1]] = lk
            up[starts[k] : starts[k + 1]] = uk
        same(fast.solve_stacked(), slow.solve(levels))
    assert lane_calls.count(_boxkkt.OK) >= 9


def test_a_row_that_changes_class_goes_through_the_usual_path(lane_calls):
    """A box row whose bounds meet (lower == upper: an equality) is another row class:
    the lane leaves the call, the usual path reclassifies; the same answers."""
    fast, slow, seq = warmed(5300, 6)
    key = fast._structure.key
    A0, lo, hi = seq[3][0]
    lo, hi = lo.copy(), hi.copy()
    lo[2] = hi[2] = 0.1
    seq[3][0] = (A0, lo, hi)
    before = len(lane_calls)
    keys = []
    for levels in seq[3:]:
        same(fast.solve(levels), slow.solve(levels))
        same_guess(fast, slow)
        keys.append(fast._structure.key)
    # the row is an equality at one call, an inequality again at the next
    assert lane_calls[before : before + 2] == [_boxkkt.LEFT, _boxkkt.LEFT]
    assert keys[0] != key and keys[1] == key
    assert lane_calls[-1] == _boxkkt.OK


def test_a_box_of_another_structure_goes_through_the_usual_path(lane_calls):
    fast, slow, seq = warmed(5400, 5)
    A0, lo, hi = seq[3][0]
    A0 = A0.copy()
    A0[4, 4] = 2.0  # the same pattern, another coefficient: 2 x_4 within [lo, hi]
    seq[3][0] = (A0, lo, hi)
    before = len(lane_calls)
    for levels in seq[3:]:
        same(fast.solve(levels), slow.solve(levels))
        same_guess(fast, slow)
    assert lane_calls[before] == _boxkkt.LEFT


@pytest.mark.parametrize("wrong", ["dropped", "added", "many"])
def test_a_guess_the_lane_cannot_prove_is_left_as_it_came(wrong, lane_calls):
    """The same wrong guess given to both solvers: whatever the lane does with it, the
    answer and the guess after the call are the usual path's. ``many``: six free
    variables held at a bound, more corrections than the kernel makes (it stops and
    the usual path goes on)."""
    for seed in range(6):
        fast, slow, seq = warmed(5500 + seed, 4)
        box = fast._structure.box
        held = np.flatnonzero(box.at_lo | box.at_hi)
        free = np.flatnonzero(~(box.at_lo | box.at_hi))
        for solver in (fast, slow):
            box = solver._structure.box
            if wrong == "dropped":
                box.at_lo[held[:1]] = box.at_hi[held[:1]] = False
            elif wrong == "added":
                box.at_hi[free[:1]] = True
            else:
                box.at_hi[free[:6]] = True
        same(fast.solve(seq[3]), slow.solve(seq[3]))
        same_guess(fast, slow)
    if wrong == "many":
        assert _boxkkt.LEFT in lane_calls
    else:  # a bound crossed or released within the kernel's corrections
        assert lane_calls.count(_boxkkt.OK) == 6 * 2 + 6, lane_calls


def test_the_usual_path_starts_from_the_guess_the_lane_was_given(monkeypatch):
    """After the lane leaves a call, box_kkt sees the guess the lane saw, not the one
    the lane's own corrections made of it."""
    seen: list[tuple[str, int, np.ndarray]] = []

    def spy_on(name, real, at):  # at: where the guess at_lo, at_hi is in the arguments
        def spy(*args):
            guess = np.concatenate(args[at : at + 2])
            out = real(*args)
            seen.append((name, int(out[0]), guess))
            return out

        return spy

    monkeypatch.setattr(_boxkkt, "lane", spy_on("lane", _boxkkt.lane, 13))
    monkeypatch.setattr(_boxkkt, "box_kkt", spy_on("box_kkt", _boxkkt.box_kkt, 8))
    left = 0
    for seed in range(6):
        fast, _, seq = warmed(5500 + seed, 4)
        box = fast._structure.box
        # wrong bounds to release, one per correction: more than the kernel makes
        box.at_hi[np.flatnonzero(~(box.at_lo | box.at_hi))[:6]] = True
        seen.clear()
        fast.solve(seq[3])
        assert seen[0][0] == "lane"
        if seen[0][1] == _boxkkt.LEFT:
            left += 1
            assert seen[1][0] == "box_kkt"
            assert np.array_equal(seen[1][2], seen[0][2])
    assert left >= 3


@pytest.mark.parametrize("fault", ["nan", "order"])
def test_bad_input_at_a_lane_call_raises_the_usual_error(fault, lane_calls):
    fast, slow, seq = warmed(5600, 4)
    A, lo, up = seq[3][2]
    if fault == "nan":
        A = A.copy()
        A[1, 3] = np.nan
    else:
        lo, up = lo.copy(), lo.copy()
        up[1] = lo[1] - 1.0  # lower > upper
    seq[3][2] = (A, lo, up)
    assert "level 2, row 1" in same_error(fast, slow, seq[3])
    assert lane_calls[-1] == _boxkkt.LEFT


def test_a_damped_call_does_not_take_the_lane(lane_calls):
    fast, slow, seq = warmed(5700, 4)
    before = len(lane_calls)
    for damping in (0.01, [0.0, 0.0, 0.0, 0.01]):
        same(fast.solve(seq[3], damping), slow.solve(seq[3], damping))
    assert len(lane_calls) == before


# -- the free lane: no bound in the guess, levels below the box of any rank -------------
@pytest.fixture
def free_calls(monkeypatch):
    return statuses_of(monkeypatch, "free_lane")


def deficient(seed: int, ticks: int = 12, half: float = 1e4, drop: int = 10**9):
    """A wide box, then levels below it that the compiled box call refuses: level 2
    repeats a row of level 1 with another target (a conflict: rank deficient in the
    null space of level 1); from call ``drop`` on, the last level repeats one of its
    rows (its rank drops); the data drift from call to call."""
    rng = np.random.default_rng(seed)
    n = 12
    A1 = rng.standard_normal((4, n))
    A2 = np.vstack([A1[:1], rng.standard_normal((2, n))])
    A3 = rng.standard_normal((6, n))
    b = [rng.standard_normal(4), rng.standard_normal(3), rng.standard_normal(6)]
    for t in range(ticks):
        s = 0.05 * np.sin(0.4 * t)
        levels = [(np.eye(n), -half * np.ones(n), half * np.ones(n))]
        for k, (A, bk) in enumerate(zip((A1, A2, A3), b, strict=True)):
            A = A + s * np.ones_like(A)
            if k == 2 and t >= drop:
                A[5] = A[4]
            target = bk + s
            levels.append((A, target, target))
        yield levels


def warmed_free(seed: int, ticks: int, drop: int = 10**9):
    """:func:`warmed` for :func:`deficient` sequences, both lanes of ``slow`` off."""
    fast, slow = pair()
    slow._free_lane_solve = lambda st, damping: None
    seq = list(deficient(seed, ticks, drop=drop))
    for levels in seq[:3]:
        same(fast.solve(levels), slow.solve(levels))
    return fast, slow, seq


@pytest.mark.parametrize("seed", range(4))
def test_the_free_lane_gives_the_usual_answer_bit_for_bit(seed, free_calls):
    """Also when a level's rank drops on the way: the plans the box path keeps for its
    next calls (blocks of full-rank levels) follow, as on the usual path."""
    fast, slow, seq = warmed_free(6100 + seed, 12, drop=7)
    ranks = []
    for levels in seq[3:]:
        a = fast.solve(levels)
        same(a, slow.solve(levels))
        assert a.method == "shortcut"
        assert fast._structure.box_blocks == slow._structure.box_blocks
        assert fast._structure.box_full == slow._structure.box_full
        ranks.append(a.ranks[3])
    assert ranks[0] == 6 and ranks[-1] == 5
    assert free_calls.count(_boxkkt.OK) >= 9, free_calls
    x_ref, optimal = cascade_hierarchy(levels)
    np.testing.assert_allclose(a.x, x_ref, atol=1e-6)
    np.testing.assert_allclose(a.residuals, optimal, atol=1e-6)


def test_a_point_out_of_the_box_goes_through_the_usual_path(free_calls):
    """The box narrowed at one call: the recursion's point leaves it, the lane leaves
    the call (the guess untouched), the usual path holds the bounds; the lane is off
    until the free path answers again."""
    fast, slow, seq = warmed_free(6200, 8)
    A0, _, _ = seq[3][0]
    half = 0.5 * np.abs(fast.solve(seq[2]).x) + 0.01  # the point of the last call is out
    seq[3][0] = (A0, -half, half)
    before = len(free_calls)
    methods = []
    for levels in seq[3:]:
        a = fast.solve(levels)
        same(a, slow.solve(levels))
        same_guess(fast, slow)
        methods.append(a.method)
    assert free_calls[before] == _boxkkt.LEFT
    assert methods[0] != "shortcut"  # bounds held
    assert free_calls[-1] == _boxkkt.OK  # the wide box again, without a bound


def test_bad_input_at_a_free_lane_call_raises_the_usual_error(free_calls):
    fast, slow, seq = warmed_free(6300, 4)
    A, lo, up = seq[3][3]
    A = A.copy()
    A[2, 5] = np.inf
    seq[3][3] = (A, lo, up)
    assert "level 3, row 2" in same_error(fast, slow, seq[3])
    assert free_calls[-1] == _boxkkt.LEFT
