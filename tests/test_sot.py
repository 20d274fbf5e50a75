"""The SOT entity: strict priorities over tasks read from the graph, joint limits as a
hard level, stack edits, bad input, and the closed loop on Talos."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

from reference_hierarchy import cascade_hierarchy
from sotpy.dynamics import load_robot
from sotpy.errors import CommandError, EntityError, SignalTypeError, SotpyError, SotpyWarning
from sotpy.graph import MATRIX, VECTOR, Entity, Input, Output, graphDot, plug
from sotpy.solvers.sot import SOT
from sotpy.tasks import (
    FeatureGeneric,
    MetaTaskKine6d,
    MetaTaskKineCom,
    MetaTaskKinePosture,
    Task,
    TaskInequality,
)


@pytest.fixture
def talos():
    return load_robot("talos", prefix="sot_talos")


class SotTestFixedTask(Entity):
    """Outputs a constant Jacobian and target, as a task's signals would."""

    J = Input(MATRIX)
    b = Input(VECTOR)

    @Output(MATRIX, deps=("J",))
    def jacobian(self, J):
        return J

    @Output(VECTOR, deps=("b",))
    def out(self, b):
        return b


def generic_task(name: str, J: np.ndarray, e: np.ndarray, gain: float = 1.0) -> Task:
    """A Task whose feature has a fixed error ``e`` and Jacobian ``J``: task = -gain e."""
    f = FeatureGeneric(f"f_{name}")
    f.errorIN.value = e
    f.jacobianIN.value = J
    t = Task(name)
    t.add(f)
    t.controlGain.value = gain
    return t


def test_two_levels_match_the_nullspace_projector_formula(talos):
    rng = np.random.default_rng(0)
    nv = talos.model.nv
    J1, e1 = rng.standard_normal((6, nv)), rng.standard_normal(6)
    J2, e2 = rng.standard_normal((8, nv)), rng.standard_normal(8)
    sot = SOT("sot", talos.dynamic)
    sot.setJointLimits(False)
    sot.push(generic_task("t1", J1, e1, 2.0))
    sot.push(generic_task("t2", J2, e2, 3.0))
    qdot = sot.control.value
    # independent: qdot = J1+ b1 + (J2 P1)+ (b2 - J2 J1+ b1), P1 = I - J1+ J1
    b1, b2 = -2.0 * e1, -3.0 * e2
    J1p = np.linalg.pinv(J1)
    x1 = J1p @ b1
    P1 = np.eye(nv) - J1p @ J1
    ref = x1 + np.linalg.pinv(J2 @ P1) @ (b2 - J2 @ x1)
    np.testing.assert_allclose(qdot, ref, atol=1e-9)
    np.testing.assert_allclose(J1 @ qdot, b1, atol=1e-9)  # level 1 exact


def test_priority_order_decides_a_conflict(talos):
    nv = talos.model.nv
    row = np.zeros((1, nv))
    row[0, 10] = 1.0
    sot = SOT("sot", talos.dynamic)
    sot.setJointLimits(False)
    a = generic_task("a", row, np.array([-1.0]))  # wants qdot_10 = 1
    b = generic_task("b", row, np.array([2.0]))  # wants qdot_10 = -2
    sot.push(a)
    sot.push(b)
    assert sot.control.value[10] == pytest.approx(1.0)
    sot.down(a)  # same tick: the edit takes effect at the next read
    assert sot.list() == ["b", "a"]
    assert sot.control.value[10] == pytest.approx(-2.0)
    sot.up(a)
    assert sot.control.value[10] == pytest.approx(1.0)
    sot.remove(a)
    assert sot.control.value[10] == pytest.approx(-2.0)
    sot.clear()
    assert sot.list() == []
    np.testing.assert_array_equal(sot.control.value, np.zeros(nv))


def test_joint_limits_are_a_hard_level(talos):
    model = talos.model
    sot = SOT("sot", talos.dynamic)
    dt = 0.01
    sot.dt.value = dt
    j = model.getJointId("arm_right_4_joint")
    iq, iv = model.joints[j].idx_q, model.joints[j].idx_v
    row = np.zeros((1, model.nv))
    row[0, iv] = 1.0
    push_up = generic_task("up", row, np.array([-100.0]))  # asks for +100 rad/s
    sot.push(push_up)
    q = talos.device.state.value
    qdot = sot.control.value
    bound = min(model.velocityLimit[iv], (model.upperPositionLimit[iq] - q[iq]) / dt)
    assert qdot[iv] == pytest.approx(bound, rel=1e-6)
    assert q[iq] + dt * qdot[iv] <= model.upperPositionLimit[iq] + 1e-9
    sot.setJointLimits(False)
    assert sot.control.value[iv] == pytest.approx(100.0)


def test_bad_pushes_leave_the_stack_unchanged(talos):
    sot = SOT("sot", talos.dynamic)
    t = generic_task("ok", np.ones((1, talos.model.nv)), np.array([1.0]))
    sot.push(t)
    with pytest.raises(SotpyError, match=r"SOT\(sot\)\.push: no entity named 'nope'"):
        sot.push("nope")
    with pytest.raises(SotpyError, match="is not a task"):
        sot.push(talos.device)
    with pytest.raises(SotpyError, match="already in the stack"):
        sot.push(t)
    narrow = generic_task("narrow", np.ones((2, 5)), np.ones(2))
    with pytest.raises(SignalTypeError, match=r"SOT\(sot\)\.push: .*shape \(2, 5\)"):
        sot.push(narrow)
    assert sot.list() == ["ok"]
    with pytest.raises(SotpyError, match="not in the stack"):
        sot.remove(narrow)
    with pytest.raises(EntityError, match="expected a Dynamic"):
        SOT("sot2", t)


def test_nan_in_a_task_is_refused_naming_it(talos):
    sot = SOT("sot", talos.dynamic)
    sot.setJointLimits(False)
    f = FeatureGeneric("f_nan")
    f.jacobianIN.value = np.ones((1, talos.model.nv))
    f.errorIN.value = [1.0]
    t = Task("t_nan")
    t.add(f)
    sot.push(t)
    sot.control.value  # noqa: B018
    bad = np.ones((1, talos.model.nv))
    bad[0, 3] = np.inf
    f.jacobianIN.value = bad
    with pytest.raises(SotpyError, match="t_nan"):
        sot.control.value  # noqa: B018


def test_writegraph_draws_the_stack_in_order(talos):
    sot = SOT("sot", talos.dynamic)
    for name in ("first", "second", "third"):
        sot.push(generic_task(name, np.ones((1, talos.model.nv)), np.array([0.0])))
    dot = graphDot()
    assert '"first" -> "second" [color=red' in dot
    assert '"second" -> "third" [color=red' in dot
    assert 'label="SOT sot"' in dot


def test_talos_reaches_with_the_right_wrist_keeping_its_feet(talos):
    """The slides' example (without the CoM level): feet fixed, then the right wrist to a
    target 20 cm away; closed loop through the device in velocity mode."""
    dyn, dev = talos.dynamic, talos.device
    sot = SOT("sot", dyn)
    dt = 0.005
    sot.dt.value = dt
    feet = []
    for op in ("left-ankle", "right-ankle"):
        m = MetaTaskKine6d(op.replace("-", "_"), dyn, op)
        m.keep()
        m.gain.setConstant(50.0)
        feet.append(m)
        sot.push(m.task)
    rh = MetaTaskKine6d("rh", dyn, "right-wrist")
    start = dyn.signal("right-wrist").value.translation.copy()
    target = start + np.array([0.13, -0.1, 0.12])
    assert 0.2 <= np.linalg.norm(target - start) <= 0.3
    rh.gotoNd(target, "111000", gain=5.0)
    sot.push(rh.task)
    plug(sot.control, dev.control)
    feet0 = [dyn.signal(op).value.copy() for op in ("left-ankle", "right-ankle")]
    for _ in range(600):  # 3 s
        dev.increment(dt)
    reached = dyn.signal("right-wrist").value.translation
    assert np.linalg.norm(reached - target) < 1e-3
    for op, M0 in zip(("left-ankle", "right-ankle"), feet0, strict=True):
        M = dyn.signal(op).value
        assert np.linalg.norm(pin.log6(M0.inverse() * M).vector) < 1e-6
    q = dev.state.value
    model = talos.model
    for j in range(2, model.njoints):  # every joint within its limits
        jt = model.joints[j]
        if jt.nq == 1:
            assert model.lowerPositionLimit[jt.idx_q] - 1e-9 <= q[jt.idx_q]
            assert q[jt.idx_q] <= model.upperPositionLimit[jt.idx_q] + 1e-9
    assert sot.lastResult.feasible


def _stretched_arm(talos, elbow: float, name: str):
    """Talos with the right elbow at ``elbow`` rad (0: straight, on its limit) and a
    right-wrist task asking for a point 1 m further along the forearm."""
    model, dyn, dev = talos.model, talos.dynamic, talos.device
    q = talos.halfSitting.copy()
    j = model.getJointId("arm_right_4_joint")
    q[model.joints[j].idx_q] = elbow
    dev.set(q)
    rh = MetaTaskKine6d(name, dyn, "right-wrist")
    M = dyn.signal("right-wrist").value
    data = model.createData()
    pin.forwardKinematics(model, data, q)
    shoulder = data.oMi[model.getJointId("arm_right_3_joint")].translation
    forearm = M.translation - shoulder
    forearm /= np.linalg.norm(forearm)
    rh.gotoNd(M.translation + 1.0 * forearm, "111000", gain=1.0)
    # only the right arm's joints (no free flyer, no torso): the arm alone must reach
    arm = np.zeros(model.nv, dtype=bool)
    for k in range(1, 8):
        arm[model.joints[model.getJointId(f"arm_right_{k}_joint")].idx_v] = True
    rh.task.controlSelec.value = arm
    return rh


def test_stretched_arm_gives_a_bounded_control(talos):
    """A stretched arm (elbow straight, on its limit) asked to reach 1 m further, with
    the arm's joints only: the Jacobian is nearly singular and undamped least squares
    explodes; damping bounds the control by ||task|| / (2 lambda), and the joint-limit
    level bounds each joint by its velocity limit."""
    sot = SOT("sot", talos.dynamic)
    sot.setJointLimits(False)
    rh = _stretched_arm(talos, 0.0, "rh")
    sot.push(rh.task)
    J = rh.task.jacobian.value
    sigma = np.linalg.svd(J, compute_uv=False)
    assert sigma[-1] < 0.05 * sigma[0]  # nearly singular indeed (condition > 20)
    undamped = sot.control.value
    assert np.linalg.norm(undamped) > 30.0  # the explosion the next two cases prevent
    lam = 0.05
    sot.damping.value = lam
    damped = sot.control.value
    task = rh.task.task.value
    assert np.linalg.norm(damped) <= np.linalg.norm(task) / (2 * lam) + 1e-9
    # the damped step is the damped least-squares formula J^T (J J^T + lam^2 I)^-1 b
    expected = J.T @ np.linalg.solve(J @ J.T + lam**2 * np.eye(len(task)), task)
    np.testing.assert_allclose(damped, expected, atol=1e-9)
    sot.damping.value = 0.0
    sot.setJointLimits(True)
    sot.dt.value = 0.005
    limited = sot.control.value
    vmax = talos.model.velocityLimit
    iv = sot._iv
    assert (np.abs(limited[iv]) <= vmax[iv] + 1e-9).all()
    assert np.isfinite(limited).all() and np.linalg.norm(limited) < np.linalg.norm(undamped)


def test_infeasible_hard_level_warns_and_returns_the_least_violating_control(talos):
    nv = talos.model.nv
    sot = SOT("sot", talos.dynamic)
    sot.setJointLimits(False)
    f = FeatureGeneric("f_conflict")
    J = np.zeros((2, nv))
    J[:, 10] = 1.0
    f.jacobianIN.value = J
    f.errorIN.value = np.zeros(2)
    hard = TaskInequality("hard")
    hard.add(f)
    hard.dt.value = 0.01
    # qdot_10 >= 1 (row 0) and qdot_10 <= -1 (row 1): infeasible; best qdot_10 = 0
    hard.referenceInf.value = np.array([0.01, -np.inf])
    hard.referenceSup.value = np.array([np.inf, -0.01])
    sot.push(hard)
    sot.push(generic_task("below", np.eye(nv)[[11]], np.array([-2.0])))
    with pytest.warns(SotpyWarning, match="hard level .*hard.* cannot be satisfied"):
        qdot = sot.control.value
    assert not sot.lastResult.feasible
    assert sot.lastResult.residuals[0] == pytest.approx(np.sqrt(2.0), abs=1e-6)
    assert qdot[10] == pytest.approx(0.0, abs=1e-6)
    assert qdot[11] == pytest.approx(2.0, abs=1e-6)  # the level below still met


def test_active_joint_limits_solved_without_qp_on_talos(talos):
    """Stand and reach on Talos: the grippers sit on their upper limit (0) and the CoM
    level moves them, so the joint-limit level is active; the SOT solves it by the box
    active-set path, and the control equals the QP cascade's."""
    dyn, dev = talos.dynamic, talos.device
    sot = SOT("sot", dyn)
    sot.dt.value = 0.005
    for op in ("left-ankle", "right-ankle"):
        m = MetaTaskKine6d(op.replace("-", "_"), dyn, op)
        m.keep()
        sot.push(m.task)
    com = MetaTaskKineCom(dyn)
    com.keep()
    com.feature.selec.value = "11"
    sot.push(com.task)
    rh = MetaTaskKine6d("rh", dyn, "right-wrist")
    rh.gotoNd(
        dyn.signal("right-wrist").value.translation + np.array([0.2, 0.0, 0.1]), "111000", 1.0
    )
    sot.push(rh.task)
    posture = MetaTaskKinePosture(dyn, dev)
    posture.gotoq(talos.halfSitting, 0.5)
    sot.push(posture.task)
    plug(sot.control, dev.control)
    captured = {}
    solver = sot._solver
    solve, solve_stacked = solver.solve, solver.solve_stacked

    def spy(levels, damping=None):
        captured["levels"] = [tuple(np.array(a) for a in lv) for lv in levels]
        return solve(levels, damping)

    def spy_stacked(damping=None, *, equality=False):  # the rows the SOT wrote in place
        buf = solver._buf
        bounds = list(zip(buf.starts[:-1], buf.starts[1:], strict=True))
        captured["levels"] = [
            (buf.A[s:e].copy(), buf.lo[s:e].copy(), (buf.lo if equality else buf.up)[s:e].copy())
            for s, e in bounds
        ]
        return solve_stacked(damping, equality=equality)

    solver.solve, solver.solve_stacked = spy, spy_stacked
    methods = []
    for _ in range(40):
        dev.increment(0.005)
        methods.append(sot.lastResult.method)
    assert methods[-10:] == ["active-set"] * 10
    levels = captured["levels"]
    x_ref, optimal = cascade_hierarchy(levels)  # an independent cascade of QPs
    res = sot.lastResult
    np.testing.assert_allclose(res.residuals, optimal, atol=1e-7)
    np.testing.assert_allclose(res.x, x_ref, atol=1e-6)
    A0, lo, up = levels[0]
    v = A0 @ res.x
    assert ((v >= lo - 1e-9) & (v <= up + 1e-9)).all()
    assert (np.abs(v - up) < 1e-12).any()  # a bound is indeed active


def test_task_damping_damps_only_that_level(talos):
    """setTaskDamping: the first task stays exact, the second is damped least squares in
    the first one's null space (the projector formula with lambda on level 2 only)."""
    rng = np.random.default_rng(4)
    nv = talos.model.nv
    J1, e1 = rng.standard_normal((6, nv)), rng.standard_normal(6)
    J2, e2 = rng.standard_normal((8, nv)), rng.standard_normal(8)
    sot = SOT("sot", talos.dynamic)
    sot.setJointLimits(False)
    t1, t2 = generic_task("t1", J1, e1), generic_task("t2", J2, e2)
    sot.push(t1)
    sot.push(t2)
    lam = 0.3
    sot.setTaskDamping(t2, lam)
    assert sot.getTaskDamping(t2) == lam and sot.getTaskDamping(t1) == 0.0
    qdot = sot.control.value
    b1, b2 = -e1, -e2
    x1 = np.linalg.pinv(J1) @ b1
    P = np.eye(nv) - np.linalg.pinv(J1) @ J1
    M = J2 @ P
    expected = x1 + M.T @ np.linalg.solve(M @ M.T + lam**2 * np.eye(8), b2 - J2 @ x1)
    np.testing.assert_allclose(qdot, expected, atol=1e-9)
    np.testing.assert_allclose(J1 @ qdot, b1, atol=1e-10)  # level 1 exact
    sot.unsetTaskDamping(t2)
    undamped = sot.control.value
    assert np.linalg.norm(undamped - expected) > 1e-3
    with pytest.raises(SotpyError, match="must be finite and >= 0"):
        sot.setTaskDamping(t2, -1.0)
    with pytest.raises(SignalTypeError, match="NaN"):  # refused by the signal type
        sot.damping.value = float("nan")
    sot.damping.value = -0.1
    with pytest.raises(SignalTypeError, match=r"damping: expected a finite damping >= 0"):
        sot.control.value  # noqa: B018


def test_joint_limit_level_is_never_damped(talos):
    """A joint beyond its limit: the joint-limit level asks qdot_j >= (ql - q) / dt > 0
    (0 outside the box). Damped, the level would not be met; the SOT keeps it exact."""
    model = talos.model
    j = model.getJointId("arm_right_4_joint")
    iq, iv = model.joints[j].idx_q, model.joints[j].idx_v
    q = talos.halfSitting.copy()
    q[iq] = model.lowerPositionLimit[iq] - 0.001  # 1 mrad below the lower limit
    talos.device.set(q)
    sot = SOT("sot", talos.dynamic)
    sot.dt.value = 0.01
    sot.damping.value = 0.5
    row = np.zeros((1, model.nv))
    row[0, iv + 1] = 1.0
    sot.push(generic_task("other", row, np.array([0.1])))
    qdot = sot.control.value
    assert qdot[iv] >= 0.001 / 0.01 - 1e-9  # back inside within one period
    assert sot.lastResult.feasible


# -- SoT's construction: SOT(name), setSize, and the stack commands --------------------
def test_sot_without_a_dynamic_takes_its_size_from_setsize_or_the_first_task():
    rng = np.random.default_rng(3)
    sot = SOT("sot")
    with pytest.raises(
        SotpyError, match=r"SOT\(sot\): the size of the control is not known.*setSize"
    ):
        sot.getSize()
    J, e = rng.standard_normal((3, 7)), rng.standard_normal(3)
    t = generic_task("t", J, e, 2.0)
    sot.push(t)  # the size is the task's Jacobian's width
    assert sot.getSize() == 7 and sot.list() == ["t"]
    # SoT's SOT has no joint-limit level: the control is the least-norm solution
    np.testing.assert_allclose(sot.control.value, np.linalg.pinv(J) @ (-2.0 * e), atol=1e-10)
    with pytest.raises(CommandError, match="the tasks in the stack have 7 columns"):
        sot.setSize(9)
    sot.clear()
    sot.setSize(9)
    assert sot.getSize() == 9
    with pytest.raises(SignalTypeError, match=r"has shape \(3, 7\), expected \(m, 9\)"):
        sot.push(t)
    other = SOT("other")
    other.setSize(7)
    other.push(t)
    assert other.getSize() == 7
    with pytest.raises(CommandError, match="expected a size > 0"):
        SOT("third").setSize(0)


def test_set_size_on_a_sot_built_on_a_dynamic_accepts_only_the_models_nv(talos):
    sot = SOT("sot", talos.dynamic)
    sot.setSize(talos.model.nv)  # SoT scripts call it: accepted
    with pytest.raises(CommandError, match=r"the size is nv = 38, the model's"):
        sot.setSize(39)
    assert sot.getSize() == 38


def test_rm_pop_and_dispstack(talos):
    rng = np.random.default_rng(4)
    nv = talos.model.nv
    sot = SOT("sot", talos.dynamic)
    tasks = [
        generic_task(f"t{i}", rng.standard_normal((2, nv)), rng.standard_normal(2))
        for i in range(3)
    ]
    for t in tasks:
        sot.push(t.name)
    text = sot.dispStack()
    # the format sot-dyninv scripts parse: split on '|', strip one character each side
    assert [x[1:-1] for x in text.split("|")[1:]] == ["t0", "t1", "t2"]
    assert sot.pop() == "t2" and sot.list() == ["t0", "t1"]
    sot.rm("t0")
    assert sot.list() == ["t1"]
    with pytest.raises(SotpyError, match="t0 is not in the stack"):
        sot.rm("t0")
    sot.pop()
    with pytest.raises(SotpyError, match=r"SOT\(sot\)\.pop: the stack is empty"):
        sot.pop()
