"""The SOT entity: strict priorities over tasks read from the graph, joint limits as a
hard level, stack edits, bad input, and the closed loop on Talos."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

from sotpy.dynamics import load_robot
from sotpy.errors import EntityError, SignalTypeError, SotpyError
from sotpy.graph import MATRIX, VECTOR, Entity, Input, Output, graphDot, plug
from sotpy.solvers.sot import SOT
from sotpy.tasks import FeatureGeneric, MetaTaskKine6d, Task


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
