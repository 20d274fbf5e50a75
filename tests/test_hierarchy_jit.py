"""The compiled equality recursion (sotpy.solvers._eqkernel) against the NumPy
NullspaceStepper path of the same solver (jit=False) and the projector reference, on
the random stacks of test_hierarchy (rank-deficient, conflicting, dependent rows,
over-determined last level), damped and undamped, and over drifting sequences in which
the plan of merged blocks changes."""

from __future__ import annotations

import numpy as np
import pytest

from reference_hierarchy import level_residuals, projector_hierarchy
from sotpy.solvers import HierarchySolver, SolverError, _eqkernel
from test_hierarchy import equality_stack, mixed_stack

pytestmark = pytest.mark.skipif(
    _eqkernel.equality_stack is None, reason="numba missing or SOTPY_JIT=0"
)


@pytest.mark.parametrize("seed", range(12))
@pytest.mark.parametrize("damping", [0.0, 0.03])
def test_compiled_equals_numpy_and_reference(seed, damping):
    rng = np.random.default_rng(seed)
    levels = equality_stack(rng)
    a = HierarchySolver(jit=True, shortcut=True).solve(levels, damping)
    b = HierarchySolver(jit=False).solve(levels, damping)
    assert np.array_equal(a.ranks, b.ranks)
    assert np.allclose(a.x, b.x, rtol=0, atol=1e-10 * (1 + np.abs(b.x).max()))
    assert np.allclose(a.residuals, b.residuals, rtol=1e-9, atol=1e-10)
    ref, optimal = projector_hierarchy(levels, damping=damping)
    assert np.allclose(a.x, ref, rtol=0, atol=1e-9 * (1 + np.abs(ref).max()))
    assert np.allclose(a.residuals, optimal, rtol=1e-9, atol=1e-9 * (1 + np.abs(ref).max()))


def test_drifting_sequence_with_merged_blocks_and_rank_changes():
    """Consecutive solves: the full-rank levels found at one call are stepped together
    at the next (one block); a level that loses rank splits the block again."""
    rng = np.random.default_rng(7)
    n = 14
    base = [rng.standard_normal((m, n)) for m in (3, 4, 2, 20)]
    targets = [rng.standard_normal(A.shape[0]) for A in base]
    fast, slow = HierarchySolver(n, jit=True), HierarchySolver(n, jit=False)
    for t in range(30):
        levels = []
        for k, (A, b) in enumerate(zip(base, targets, strict=True)):
            A = A + 0.01 * np.sin(0.3 * t + k) * np.ones_like(A)
            if k == 1 and 10 <= t < 20:  # rank drops for a while
                A = A.copy()
                A[1] = A[0]
            levels.append((A, b + 0.1 * np.cos(0.2 * t)))
        a, b = fast.solve(levels), slow.solve(levels)
        assert np.array_equal(a.ranks, b.ranks), t
        assert np.allclose(a.x, b.x, rtol=0, atol=1e-10 * (1 + np.abs(b.x).max())), t
    assert any(k1 - k0 > 1 for k0, k1 in fast._structure.blocks)  # merging happened


def test_damped_call_after_undamped_ones():
    """A persistent solver plans merged blocks from undamped calls; a damped call
    afterwards must step its damped levels one by one, as the NumPy path does."""
    rng = np.random.default_rng(3)
    n = 12
    levels = [(rng.standard_normal((m, n)), rng.standard_normal(m)) for m in (3, 4, 2, 15)]
    fast, slow = HierarchySolver(n, jit=True), HierarchySolver(n, jit=False)
    for damping in (0.0, 0.0, 0.05, [0.0, 0.1, 0.0, 0.02], 0.0):
        a, b = fast.solve(levels, damping), slow.solve(levels, damping)
        assert np.allclose(a.x, b.x, rtol=0, atol=1e-10 * (1 + np.abs(b.x).max())), damping
        ref, _ = projector_hierarchy(levels, damping=damping)
        assert np.allclose(a.x, ref, rtol=0, atol=1e-9 * (1 + np.abs(ref).max())), damping


@pytest.mark.parametrize("seed", range(8))
def test_shortcut_path_uses_the_kernel_alike(seed):
    """Stacks with inequalities: the shortcut's equality steps compiled or not give the
    same answers (and the same method)."""
    rng = np.random.default_rng(100 + seed)
    levels = mixed_stack(rng)
    for active_set in (False, True):
        a = HierarchySolver(jit=True, active_set=active_set).solve(levels)
        b = HierarchySolver(jit=False, active_set=active_set).solve(levels)
        assert a.method == b.method
        assert np.allclose(a.x, b.x, rtol=0, atol=1e-7 * (1 + np.abs(b.x).max()))
        # the residuals (violations), compiled or not, at the same point
        np.testing.assert_allclose(a.residuals, violation_levels(levels, a.x), atol=1e-12)


def violation_levels(levels, x):
    """Each level's violation norm at x, by the reference's definition."""
    return level_residuals([lv if len(lv) == 3 else (lv[0], lv[1], lv[1]) for lv in levels], x)


def test_jit_flag():
    assert HierarchySolver(jit=None).jit is True
    assert HierarchySolver(jit=False).jit is False


def test_jit_refused_without_kernels(monkeypatch):
    monkeypatch.setattr(_eqkernel, "equality_stack", None)
    with pytest.raises(SolverError, match="compiled kernels"):
        HierarchySolver(jit=True)
    assert HierarchySolver().jit is False


def test_kernel_refusing_its_arguments_falls_back_to_numpy(monkeypatch):
    """Compilation is frozen after the warm-up: a kernel that meets argument types it
    was not compiled for raises TypeError; the solver warns once and answers with the
    NumPy path from then on (never a stall, never a wrong value)."""
    from sotpy.errors import SotpyWarning

    def refuse(*_args):
        raise TypeError("No matching definition for argument type(s)")

    rng = np.random.default_rng(11)
    levels = equality_stack(rng)
    expected = HierarchySolver(jit=False).solve(levels)
    solver = HierarchySolver(jit=True)
    monkeypatch.setattr(_eqkernel, "equality_all", refuse)
    with pytest.warns(SotpyWarning, match="NumPy from now on"):
        res = solver.solve(levels)
    assert solver.jit is False
    np.testing.assert_allclose(res.x, expected.x, rtol=0, atol=1e-12)
    res = solver.solve(levels)  # no second warning, same answer
    np.testing.assert_allclose(res.x, expected.x, rtol=0, atol=1e-12)


def test_kernels_do_not_compile_after_the_warm_up():
    HierarchySolver(jit=True)
    with pytest.raises(TypeError):
        _eqkernel.equality_all(  # float32 matrix: a new signature, refused
            np.zeros((2, 3), dtype=np.float32),
            np.array([0, 2], dtype=np.int64),
            np.zeros((1, 2), dtype=np.int64),
            np.zeros(1),
            1e-9,
            0,
        )


def test_box_update_compiled_equals_numpy():
    """BoxActiveSet.set_box: the compiled update (a box of the remembered structure, read
    from a column slice of a stacked buffer as the solver passes it) equals the NumPy
    reading, negative coefficients, one-sided and equal bounds included; a changed
    structure is refused by the kernel and read by NumPy."""
    from sotpy.solvers._boxset import BoxActiveSet

    rng = np.random.default_rng(4)
    n = 7
    buf = np.zeros((n, n + 1))
    perm = rng.permutation(n)
    coef = rng.choice([-2.0, -1.0, 1.0, 3.0], size=n)
    buf[np.arange(n), perm] = coef
    A0 = buf[:, :n]  # not contiguous
    lo = -rng.uniform(0.1, 1.0, n)
    hi = rng.uniform(0.1, 1.0, n)
    lo[1] = -np.inf
    hi[2] = np.inf
    lo[3] = hi[3] = 0.25
    boxes = [BoxActiveSet(n), BoxActiveSet(n)]
    for b in boxes:
        assert b.set_box(A0, lo, hi)  # first reading: NumPy for both (structure learnt)
        b.at_lo[:] = rng.random(n) < 0.5
        b.at_hi[:] = ~b.at_lo & (rng.random(n) < 0.5)
    boxes[1].at_lo[:] = boxes[0].at_lo
    boxes[1].at_hi[:] = boxes[0].at_hi
    lo2, hi2 = lo * 1.1, hi * 0.9
    assert _eqkernel.box_update(
        A0,
        n,
        n,
        boxes[0].cols,
        boxes[0].coef,
        lo2,
        hi2,
        boxes[0].lo.copy(),
        boxes[0].hi.copy(),
        boxes[0].at_lo.copy(),
        boxes[0].at_hi.copy(),
    )  # fmt: skip  (the kernel accepts the solver's argument types)
    assert boxes[0].set_box(A0, lo2, hi2, jit=True)
    assert boxes[1].set_box(A0, lo2, hi2, jit=False)
    for attr in ("lo", "hi", "at_lo", "at_hi"):
        np.testing.assert_array_equal(getattr(boxes[0], attr), getattr(boxes[1], attr))
    # a changed structure: the kernel says so, NumPy reads the new box
    buf[0, perm[0]] = 0.0
    buf[0, perm[1]] = 5.0
    assert not _eqkernel.box_update(
        A0, n, n, boxes[0].cols, boxes[0].coef, lo2, hi2,
        boxes[0].lo, boxes[0].hi, boxes[0].at_lo, boxes[0].at_hi,
    )  # fmt: skip
    assert not boxes[0].set_box(A0, lo2, hi2, jit=True)  # two rows on one variable


def test_row_classes_change_between_calls_compiled_and_numpy():
    """The compiled bookkeeping of the general path keeps the row classes (equality or
    inequality) in step when a row's bounds open and close again, and after an
    equality-only call in between."""
    rng = np.random.default_rng(21)
    n = 6
    box = (np.eye(n), -np.ones(n), np.ones(n))
    A1 = rng.standard_normal((3, n))
    A2 = rng.standard_normal((n + 2, n))
    b2 = rng.standard_normal(n + 2)
    fast, slow = HierarchySolver(n, jit=True), HierarchySolver(n, jit=False)
    for t in range(8):
        c = rng.standard_normal(3)
        lo, up = c.copy(), c.copy()
        if t % 3 == 1:
            up[1] += 0.5  # row 1 becomes an inequality
        if t % 3 == 2:
            lo[0] = -np.inf  # one-sided
        levels = [box, (A1, lo, up), (A2, b2)] if t != 5 else [(A1, c), (A2, b2)]
        a, b = fast.solve(levels), slow.solve(levels)
        assert a.method == b.method, t
        np.testing.assert_allclose(a.x, b.x, rtol=0, atol=1e-7 * (1 + np.abs(b.x).max()))
        np.testing.assert_allclose(a.residuals, b.residuals, rtol=1e-7, atol=1e-9)
