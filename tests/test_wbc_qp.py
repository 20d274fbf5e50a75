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
from sotpy.solvers.wbc.model import Layout
from sotpy.solvers.wbc.qp import DUAL_TOL, PRIMAL_TOL, WeightedQP, pack

NO_NUMBA = pytest.mark.skipif(_kernels.solve is None, reason="numba missing or SOTPY_JIT=0")
JIT = [False, pytest.param(True, marks=NO_NUMBA)]


@pytest.fixture(scope="module")
def talos():
    return erd.load("talos")


@pytest.fixture(scope="module")
def panda():
    return erd.load("panda")


def _reg(w: WholeBodyController) -> np.ndarray:
    """The regularisation's diagonal over chi: eps on (a, f), 0 on the torques."""
    d = np.full(w.layout.n, w.regularisation)
    d[w.layout.tau] = 0.0
    return d


def reference_chi(w: WholeBodyController) -> tuple[np.ndarray, float]:
    """The QP over chi (dynamics as equalities), by proxsuite; returns (chi, objective)."""
    (A, c), (C, lo, hi), tasks = w.problem()
    n = w.layout.n
    H = np.diag(_reg(w))
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
    val = 0.5 * chi @ (_reg(w) * chi)
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
    w.setTorqueRateLimit(np.inf)  # the QP alone: no transition rows (test_wbc_ramps.py)
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


def _compiled(layout, A, c, E, f, w, C, lo, hi, reg, act=(), up=(), guess=True, unit=()):
    """The compiled kernel on these rows: (status, ok, {name: array}) of its workspace
    (``unit``: the rows of the identity, see ``_kernels.solve``)."""
    m, mc = E.shape[0], C.shape[0]
    data = pack(layout, A, c, E, f, w, C, lo, hi)
    lay = _kernels.work_layout(layout.nv, layout.na, layout.n, m, mc)
    ws = np.zeros(lay["size"][0])
    act = np.asarray(act, dtype=np.intp)
    up = np.asarray(up, dtype=bool)
    status, ok = _kernels.solve(
        data, ws, act, up, np.asarray(unit, dtype=np.intp), True, layout.nv, layout.na,
        layout.n, m, mc, reg, guess, PRIMAL_TOL, DUAL_TOL, 1e6,
    )  # fmt: skip
    views = {k: ws[o : o + int(np.prod(sh))].reshape(sh) for k, (o, sh) in lay.items() if sh}
    return status, ok, views


_REDUCED = ("H", "g", "Au", "cu", "Cy", "lo_y", "hi_y", "Tt", "tt")


def _assert_same(ref, got):
    for a, name in zip(ref, _REDUCED, strict=True):
        b = got[name]
        assert a.shape == b.shape, name
        assert np.array_equal(np.isinf(a), np.isinf(b)), name  # one-sided rows stay so
        fa, fb = a[np.isfinite(a)], b[np.isfinite(a)]
        assert np.allclose(fa, fb, rtol=1e-12, atol=1e-12 * (1 + np.abs(fa).max(initial=0))), name


@NO_NUMBA
def test_kernels_match_numpy(panda, talos):
    """The compiled reduction and guess equal the NumPy code (torque task included: its
    rows couple the forces to the accelerations, so the Hessian has no zero block)."""
    w = _talos(talos, False, effort_scale=0.12)
    w.addTask(TorqueTask("tq", w.robot.na, 1e-3)).activate()
    w.tasks["tq"].setDesired(np.linspace(-5.0, 5.0, w.robot.na))
    w.update(talos.q0.copy(), np.zeros(talos.model.nv))
    w.update(talos.q0.copy(), np.zeros(talos.model.nv))
    (A, c), (C, lo, hi), tasks = w.problem()
    qp_np = w.weighted_qp
    E = np.vstack([t[1] for t in tasks])
    f = np.concatenate([t[2] for t in tasks])
    wt = np.concatenate([t[3] for t in tasks])
    ref = qp_np.reduce(w.layout, (A, c), (C, lo, hi), tasks, w.regularisation)
    status, ok, got = _compiled(
        w.layout, A, c, E, f, wt, C, lo, hi, w.regularisation, qp_np._active, qp_np._upper
    )
    assert status == 0 and ok
    # an accepted guess leaves H's lower triangle (all the guess reads); a refused one,
    # or none asked for, the whole symmetric H (DAQP reads it)
    _assert_same((np.tril(ref[0]), *ref[1:]), {**got, "H": np.tril(got["H"])})
    _status, refused, whole = _compiled(
        w.layout, A, c, E, f, wt, C, lo, hi, w.regularisation, guess=False
    )
    assert not refused
    _assert_same(ref, whole)
    H, g, Au, cu, Cy, lo_y, hi_y, _Tt, _tt = ref
    y_np = qp_np._try_guess(H, g, Au, cu, Cy, lo_y, hi_y, lo == hi)
    assert y_np is not None and ok and len(qp_np._active)
    assert np.allclose(y_np, got["y"], rtol=1e-10, atol=1e-10 * (1 + np.abs(y_np).max()))


@pytest.mark.parametrize("jit", JIT)
def test_fixed_base_and_bad_bounds(panda, jit):
    model = panda.model
    w = WholeBodyController(model)
    w.weighted_qp = WeightedQP(w.robot.actuated, w._unactuated, jit=jit)
    w.addTask(CartesianAccelerationTask("ee", "panda_hand_tcp")).setDesired([50.0, 0, 0, 0, 0, 0])
    lim = w.addConstraint(JointTorqueLimit("tau", w.robot, -np.full(9, 5.0), np.full(9, 5.0)))
    w.setTorqueRateLimit(np.inf)
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


class _Var:
    """A one-dimensional 'contact' of a toy layout: its variable is y's second entry."""

    key = frame = "x"
    dim = 1
    bilateral = True


def _guess(jit: bool, H, g, Au, cu, Cy, lo, hi, act, up):
    """(accepted, y) of the guessed active set, NumPy or compiled. The toy problems have
    two variables and one equality: as a layout, nv = 1 (one unactuated velocity), no
    torque, one 'contact' variable; the dynamics row is the equality, a task of weight 1
    on each variable gives ``H = I`` and ``g`` (plus eps = 1e-14)."""
    act = np.asarray(act, dtype=np.intp)
    up = np.asarray(up, dtype=bool)
    if jit:
        assert np.allclose(H, np.eye(2)) and Au.shape == (1, 2)
        layout = Layout(1, 0, [_Var()])
        _status, ok, got = _compiled(
            layout, Au, cu, np.eye(2), -g, np.ones(2), Cy, lo, hi, 1e-14, act, up
        )
        return ok, got["y"].copy()
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
    # the same row twice: a singular KKT matrix; refused, or (the compiled range-space
    # solve, whose multipliers split between the copies) the optimum: never another point
    ok, y = _guess(jit, H, g, Au, cu, Cy, lo, hi, [0, 0], [True, True])
    assert not ok or np.allclose(y, [1.2, -0.2], atol=1e-9)


@NO_NUMBA
@pytest.mark.parametrize("dense", [False, True])
def test_compiled_reduction_of_random_rows(dense):
    """Random dynamics, tasks and constraints (torque columns sparse or dense): the
    compiled reduction equals the NumPy one."""
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
    f = rng.standard_normal(7)
    wt = rng.uniform(0.1, 2.0, 7)
    lo = -rng.uniform(0.5, 1.0, 5)
    hi = rng.uniform(0.5, 1.0, 5)
    lo[4] = -np.inf
    qp = WeightedQP(np.arange(nv - na, nv), np.arange(nv - na), jit=False)
    ref = qp.reduce(
        layout, (A, c), (C, lo, hi), [(0, E[:4], f[:4], wt[:4]), (1, E[4:], f[4:], wt[4:])], 1e-3
    )
    status, _ok, got = _compiled(layout, A, c, E, f, wt, C, lo, hi, 1e-3, guess=False)
    assert status == 0
    _assert_same(ref, got)
