"""The one-level weighted QP (sotpy.solvers.wbc.qp): torque elimination, the guessed
active set, its compiled kernels, against an independent QP over chi solved by
proxsuite with the equations of motion as equalities."""

from __future__ import annotations

import example_robot_data as erd
import numpy as np
import proxsuite
import pytest

from sotpy.solvers.wbc import (
    CartesianAccelerationTask,
    CoMAccelerationTask,
    ContactSpec,
    JointAccelerationTask,
    JointTorqueLimit,
    TorqueTask,
    WholeBodyController,
    _kernels,
)
from sotpy.solvers.wbc.qp import WeightedQP

NO_NUMBA = pytest.mark.skipif(_kernels.reduce is None, reason="numba missing or SOTPY_JIT=0")
JIT = [False, pytest.param(True, marks=NO_NUMBA)]


@pytest.fixture(scope="module")
def talos():
    return erd.load("talos")


@pytest.fixture(scope="module")
def panda():
    return erd.load("panda")


def reference_chi(w: WholeBodyController) -> tuple[np.ndarray, float]:
    """The QP over chi (dynamics as equalities), by proxsuite; returns (chi, objective)."""
    (A, c), (C, lo, hi), tasks = w.problem()
    n = w.layout.n
    H = w.regularisation * np.eye(n)
    g = np.zeros(n)
    for _l, E, f, wt in tasks:
        H += E.T @ (wt[:, None] * E)
        g -= E.T @ (wt * f)
    qp = proxsuite.proxqp.dense.QP(n, A.shape[0], C.shape[0])
    qp.settings.eps_abs = 1e-11
    qp.settings.eps_rel = 0.0
    qp.settings.max_iter = 100000
    qp.init(H, g, A, c, C, np.maximum(lo, -1e20), np.minimum(hi, 1e20))
    qp.solve()
    x = qp.results.x
    return x, 0.5 * x @ H @ x + g @ x


def objective(w: WholeBodyController, chi: np.ndarray) -> float:
    _dyn, _cons, tasks = w.problem()
    val = 0.5 * w.regularisation * chi @ chi
    for _l, E, f, wt in tasks:
        r = E @ chi - f
        val += 0.5 * r @ (wt * r)
    return val - 0.5 * sum(f @ (wt * f) for _l, E, f, wt in tasks)


def _talos(talos, jit: bool, effort_scale: float = 1.0) -> WholeBodyController:
    w = WholeBodyController(talos.model)
    w.weighted_qp = WeightedQP(w.robot.actuated, w._unactuated, jit=jit)
    w.setContacts(
        [
            ContactSpec(f, 6, 0.4, 0.205, 0.122, (-0.005, 0.0))
            for f in ("left_sole_link", "right_sole_link")
        ]
    )
    w.addTask(CoMAccelerationTask("com", 10.0)).setDesired([0.0, 0.5, 0.0])
    w.addTask(CartesianAccelerationTask("hand", "arm_right_7_link", 1.0)).setDesired(
        [3.0, 0.0, 2.0, 0.0, 0.0, 0.0]
    )
    w.addTask(JointAccelerationTask("posture", w.robot.na, 1e-2))
    eff = talos.model.effortLimit[6:] * effort_scale
    w.addConstraint(JointTorqueLimit("tau", w.robot, -eff, eff))
    w.activateTasksAndConstraints()
    return w


def _check_against_reference(w, chi):
    ref, fref = reference_chi(w)
    (A, c), (C, lo, hi), _ = w.problem()
    scale = 1.0 + np.abs(ref).max()
    assert np.abs(A @ chi - c).max() < 1e-8 * scale
    v = C @ chi
    assert np.all(v <= hi + 1e-7 * (1 + np.abs(hi))) and np.all(v >= lo - 1e-7 * (1 + np.abs(lo)))
    # the same optimum: objective within the reference's accuracy, same point
    assert objective(w, chi) <= objective(w, ref) + 1e-7 * (1.0 + abs(fref))
    assert np.abs(chi - ref).max() < 1e-5 * scale


@pytest.mark.parametrize("jit", JIT)
def test_talos_sequence_matches_reference_with_active_torque_limits(talos, jit):
    """A drifting sequence with torque limits that bind: the guess answers most ticks,
    each answer the reference optimum."""
    w = _talos(talos, jit, effort_scale=0.12)
    q, v = talos.q0.copy(), np.zeros(talos.model.nv)
    qp = w.weighted_qp
    active_hits = 0
    for k in range(12):
        v[6:] = 0.05 * np.sin(0.3 * k + np.arange(talos.model.nv - 6))
        sol = w.update(q, v)
        assert sol.found, sol.reason
        if qp.last_method == "guess" and len(qp._active):
            active_hits += 1
        if k % 4 == 0 or k == 11:
            _check_against_reference(w, sol.chi)
    assert qp.guess_hits >= 8
    assert active_hits >= 8  # the guess held with inequality rows at their bounds
    tau_lim = 0.12 * talos.model.effortLimit[6:]
    assert np.any(np.abs(sol.tau) >= tau_lim - 1e-6)  # some limit binds


@pytest.mark.parametrize("jit", JIT)
def test_wrong_guess_is_refused(talos, jit):
    w = _talos(talos, jit, effort_scale=0.12)
    q, v = talos.q0.copy(), np.zeros(talos.model.nv)
    w.update(q, v)
    qp = w.weighted_qp
    good = qp._active.copy()
    assert len(good)
    # rows that are not at a bound (inactive torque limits), guessed active at their
    # upper bounds: the point violates other rows or a multiplier has the wrong sign
    _dyn, (_C, lo, hi), _ = w.problem()
    free = np.setdiff1d(np.flatnonzero(lo != hi), good)
    qp._active = np.concatenate([good, free[:3]])
    qp._upper = np.concatenate([qp._upper, [True, True, True]])
    sol = w.update(q, v)
    assert qp.last_method == "daqp"
    _check_against_reference(w, sol.chi)
    # a guess missing a binding row: the point violates it -> DAQP
    qp._active = good[1:]
    qp._upper = qp._upper[1 : len(good)]
    sol = w.update(q, v)
    assert qp.last_method == "daqp"
    _check_against_reference(w, sol.chi)
    assert np.array_equal(np.sort(qp._active), np.sort(good))


@NO_NUMBA
def test_kernels_match_numpy(panda, talos):
    """The compiled reduction and guess equal the NumPy code (torque task included)."""
    w = _talos(talos, False, effort_scale=0.12)
    w.addTask(TorqueTask("tq", w.robot.na, 1e-3)).activate()
    w.tasks["tq"].setDesired(np.linspace(-5.0, 5.0, w.robot.na))
    w.update(talos.q0.copy(), np.zeros(talos.model.nv))
    w.update(talos.q0.copy(), np.zeros(talos.model.nv))
    dyn, cons, tasks = w.problem()
    qp_np = w.weighted_qp
    qp_jit = WeightedQP(w.robot.actuated, w._unactuated, jit=True)
    ref = qp_np.reduce(w.layout, dyn, cons, tasks, w.regularisation)
    status, got = qp_jit._reduce_compiled(w.layout, dyn, cons, tasks, w.regularisation)
    assert status == 0
    for a, b in zip(ref, got, strict=True):
        assert a.shape == b.shape
        assert np.array_equal(np.isinf(a), np.isinf(b))  # one-sided rows stay so
        fa, fb = a[np.isfinite(a)], b[np.isfinite(a)]
        assert np.allclose(fa, fb, rtol=1e-12, atol=1e-12 * (1 + np.abs(fa).max(initial=0)))
    H, g, Au, cu, Cy, lo, hi, _Tt, _tt = ref
    y_np = qp_np._try_guess(H, g, Au, cu, Cy, lo, hi, lo == hi)
    ok, y_jit = _kernels.guess(
        H, g, Au, cu, Cy, lo, hi, qp_np._active, qp_np._upper, 1e-9, 1e-9, 1e6
    )
    assert y_np is not None and ok
    assert np.allclose(y_np, y_jit, rtol=1e-10, atol=1e-10 * (1 + np.abs(y_np).max()))


@pytest.mark.parametrize("jit", JIT)
def test_fixed_base_and_bad_bounds(panda, jit):
    model = panda.model
    w = WholeBodyController(model)
    w.weighted_qp = WeightedQP(w.robot.actuated, w._unactuated, jit=jit)
    w.addTask(CartesianAccelerationTask("ee", "panda_hand_tcp")).setDesired([50.0, 0, 0, 0, 0, 0])
    lim = w.addConstraint(JointTorqueLimit("tau", w.robot, -np.full(9, 5.0), np.full(9, 5.0)))
    w.activateTasksAndConstraints()
    q, v = panda.q0.copy(), np.zeros(model.nv)
    for _ in range(3):
        sol = w.update(q, v)
        assert sol.found
    assert w.weighted_qp.guess_hits >= 1
    _check_against_reference(w, sol.chi)
    assert np.isclose(np.abs(sol.tau).max(), 5.0)
    lim.lower[0] = np.nan  # bypassing the setter: the solver still refuses it
    sol = w.update(q, v)
    assert not sol.found and "NaN" in sol.reason


def _guess(jit: bool, H, g, Au, cu, Cy, lo, hi, act, up):
    """(accepted, y) of the guessed active set, NumPy or compiled."""
    act = np.asarray(act, dtype=np.intp)
    up = np.asarray(up, dtype=bool)
    if jit:
        try:
            return _kernels.guess(H, g, Au, cu, Cy, lo, hi, act, up, 1e-9, 1e-9, 1e6)
        except np.linalg.LinAlgError:
            return False, None
    qp = WeightedQP(np.arange(0), np.arange(0), jit=False)
    qp._active, qp._upper = act, up
    y = qp._try_guess(H, g, Au, cu, Cy, lo, hi, lo == hi)
    return y is not None, y


@pytest.mark.parametrize("jit", JIT)
def test_guess_accepts_only_the_optimum(jit):
    """min 1/2 |y - (2, 0)|^2 s.t. y0 + y1 = 1 (equality), y0 <= 1.2, y1 >= -0.5:
    optimum (1.2, -0.2) with the first inequality active at its upper bound."""
    H = np.eye(2)
    g = np.array([-2.0, 0.0])
    Au = np.array([[1.0, 1.0]])
    cu = np.array([1.0])
    Cy = np.array([[1.0, 0.0], [0.0, 1.0], [1.0, 0.0]])
    lo = np.array([-np.inf, -0.5, -5.0])
    hi = np.array([1.2, np.inf, 5.0])
    ok, y = _guess(jit, H, g, Au, cu, Cy, lo, hi, [0], [True])
    assert ok and np.allclose(y, [1.2, -0.2])
    # nothing active: y = (1.5, -0.5) violates y0 <= 1.2 (primal test)
    ok, _ = _guess(jit, H, g, Au, cu, Cy, lo, hi, [], [])
    assert not ok
    # y1 >= -0.5 guessed active: y = (1.5, -0.5) violates row 0 (primal) -> refused
    ok, _ = _guess(jit, H, g, Au, cu, Cy, lo, hi, [1], [False])
    assert not ok
    # row 2 (y0 <= 5) guessed active: y = (5, -4) violates y1 >= -0.5 (primal) -> refused
    ok, _ = _guess(jit, H, g, Au, cu, Cy, lo, hi, [2], [True])
    assert not ok
    # a feasible point that is not the optimum: with y0 >= 1 (row 2) guessed active,
    # y = (1, 0) meets every row (1 <= 1.2, 0 >= -0.5) but the objective pushes y0 up:
    # the multiplier at that lower bound has the wrong sign (dual test) -> refused
    lo2 = lo.copy()
    lo2[2] = 1.0
    yk = np.array([1.0, 0.0])
    assert np.all(Cy @ yk <= hi) and np.all(Cy @ yk >= lo2) and np.isclose(Au @ yk, cu).all()
    ok, _ = _guess(jit, H, g, Au, cu, Cy, lo2, hi, [2], [False])
    assert not ok
    # the same guess on the upper side of row 0 at 1.2: the optimum
    ok, _ = _guess(jit, H, g, Au, cu, Cy, lo2, hi, [0], [True])
    assert ok
    # the same row twice: singular KKT matrix -> refused (never a garbage point)
    ok, _ = _guess(jit, H, g, Au, cu, Cy, lo, hi, [0, 0], [True, True])
    assert not ok


@NO_NUMBA
@pytest.mark.parametrize("dense", [False, True])
def test_compiled_reduction_of_random_rows(dense):
    """Random dynamics, tasks and constraints (torque columns sparse or dense): the
    compiled reduction equals the NumPy one."""
    from sotpy.solvers.wbc.model import Layout

    rng = np.random.default_rng(5 + dense)
    nv, na = 9, 6
    layout = Layout(nv, na, [])
    n = layout.n
    A = rng.standard_normal((nv, n))
    c = rng.standard_normal(nv)
    E = rng.standard_normal((7, n))
    C = rng.standard_normal((5, n))
    if not dense:
        E[:, nv : nv + na] = 0.0
        E[2, nv + 1] = 1.5  # one torque entry
        C[:, nv : nv + na] = 0.0
        C[np.arange(3), nv + np.arange(3)] = 1.0  # torque-limit-like rows
    tasks = [(0, E[:4], rng.standard_normal(4), rng.uniform(0.1, 2.0, 4)),
             (1, E[4:], rng.standard_normal(3), rng.uniform(0.1, 2.0, 3))]  # fmt: skip
    lo = -rng.uniform(0.5, 1.0, 5)
    hi = rng.uniform(0.5, 1.0, 5)
    lo[4] = -np.inf
    qp = WeightedQP(np.arange(nv - na, nv), np.arange(nv - na), jit=True)
    ref = qp.reduce(layout, (A, c), (C, lo, hi), tasks, 1e-3)
    status, got = qp._reduce_compiled(layout, (A, c), (C, lo, hi), tasks, 1e-3)
    assert status == 0
    for a, b in zip(ref, got, strict=True):
        assert np.array_equal(np.isinf(a), np.isinf(b))
        fa, fb = a[np.isfinite(a)], b[np.isfinite(a)]
        np.testing.assert_allclose(fb, fa, rtol=1e-12, atol=1e-12 * (1 + np.abs(fa).max()))
