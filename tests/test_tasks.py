"""Tasks, gains, inequality tasks and meta-tasks: stacking, signs, bounds, bad input."""

from __future__ import annotations

import math

import numpy as np
import pinocchio as pin
import pytest

from sotpy.dynamics import Dynamic, load_model, load_robot
from sotpy.errors import CommandError, EntityError, SignalTypeError, SotpyError, UnpluggedError
from sotpy.graph import VECTOR, Entity, Output, Plan, plug, pool
from sotpy.solvers import SOT
from sotpy.tasks import (
    FeatureGeneric,
    FeaturePoint6d,
    FeaturePose,
    FeaturePosture,
    Flags,
    GainAdaptive,
    MetaTaskKine6d,
    MetaTaskKineCom,
    MetaTaskKinePosture,
    Task,
    TaskAbstract,
    TaskInequality,
    TaskJointLimits,
    goto6d,
    gotoNd,
    toFlags,
)

EPS = 1e-6


class TasksVectorSource(Entity):
    """Test source: an output holding whatever ``value`` is (NaN allowed)."""

    def __init__(self, name: str) -> None:
        self.payload = np.zeros(1)

    @Output(VECTOR)
    def sout(self) -> np.ndarray:
        return self.payload


def generic(name: str, e, J) -> FeatureGeneric:
    f = FeatureGeneric(name)
    f.errorIN.value = e
    f.jacobianIN.value = J
    return f


@pytest.fixture
def talos():
    model = load_model("talos")[0]
    dyn = Dynamic("dyn", model)
    dyn.createOpPoint("right-wrist", "arm_right_7_joint")
    q = pin.neutral(model)
    q[7:] = np.random.default_rng(0).uniform(-0.3, 0.3, model.nv - 6)
    q = np.clip(q, model.lowerPositionLimit, model.upperPositionLimit)
    q[:7] = [0.1, -0.2, 1.0, 0.0, 0.0, 0.0, 1.0]
    dyn.position.value = q
    return model, dyn, q


# -- Task -----------------------------------------------------------------------------
def test_task_stacks_features_in_order_and_task_is_minus_gain_error():
    rng = np.random.default_rng(0)
    e1, J1 = rng.standard_normal(2), rng.standard_normal((2, 5))
    e2, J2 = rng.standard_normal(3), rng.standard_normal((3, 5))
    generic("f1", e1, J1)
    f2 = generic("f2", e2, J2)
    t = Task("t")
    t.add(f2)
    t.add("f1")  # by name
    assert t.list() == ["f2", "f1"]
    np.testing.assert_array_equal(t.error.value, np.concatenate([e2, e1]))
    np.testing.assert_array_equal(t.jacobian.value, np.vstack([J2, J1]))
    np.testing.assert_array_equal(t.task.value, -np.concatenate([e2, e1]))  # gain 1
    t.controlGain.value = 2.5
    np.testing.assert_allclose(t.task.value, -2.5 * np.concatenate([e2, e1]))
    f2.selec.value = "101"
    np.testing.assert_array_equal(t.error.value, np.concatenate([e2[[0, 2]], e1]))
    assert t.jacobian.value.shape == (4, 5)
    t.remove("f2")
    np.testing.assert_array_equal(t.error.value, e1)
    t.clear()
    assert t.list() == []
    with pytest.raises(SotpyError, match=r"Task\(t\): cannot compute error: .* no feature"):
        t.error.value  # noqa: B018
    assert "-> " not in t.displayText() and "Task t" in t.displayText()


def test_task_dependencies_follow_the_features_and_plans_recompile():
    f1 = generic("f1", [1.0], [[1.0, 0.0]])
    f2 = generic("f2", [2.0, 3.0], [[0.0, 1.0], [1.0, 1.0]])
    t = Task("t")
    t.add(f1)
    assert t.error.dependencies == [f1.error]
    assert t.jacobian.dependencies == [t.controlSelec, t.error, f1.jacobian]
    assert t.task.dependencies == [t.controlGain, t.error]
    plan = Plan([t.task, t.jacobian])
    plan.run(1)
    np.testing.assert_array_equal(t.task.value, [-1.0])
    t.add(f2)  # while "running"
    plan.run(2)
    np.testing.assert_array_equal(t.task.value, [-1.0, -2.0, -3.0])
    assert t.jacobian.value.shape == (3, 2)
    t.setWithDerivative(True)
    assert t.task.dependencies == [t.controlGain, t.error, t.errorTimeDerivative]
    assert t.getWithDerivative() is True


def test_task_with_derivative_subtracts_errordot():
    f = generic("f", [1.0, 2.0], np.eye(2))
    fdes = generic("fdes", [0.5, 0.5], np.eye(2))
    f.setReference(fdes)
    fdes.errordotIN.value = [0.3, -0.1]  # the reference moves: de/dt|q = -(0.3, -0.1)
    t = Task("t")
    t.add(f)
    t.controlGain.value = 2.0
    np.testing.assert_allclose(t.errorTimeDerivative.value, [-0.3, 0.1])
    np.testing.assert_allclose(t.task.value, [-1.0, -3.0])  # without derivative
    t.setWithDerivative(True)
    np.testing.assert_allclose(t.task.value, [-1.0 + 0.3, -3.0 - 0.1])


def test_task_with_derivative_tracks_a_moving_pose_reference(talos):
    """With J qdot = task (the derivative on), the error rate is exactly -gain e: checked
    by finite differences while the robot and the reference both move."""
    model, dyn, q = talos
    rng = np.random.default_rng(1)
    f = FeaturePose("f")
    plug(dyn.signal("right-wrist"), f.position)
    plug(dyn.signal("Jright-wrist"), f.Jq)
    Mdes = dyn.signal("right-wrist").value * pin.exp6(0.1 * rng.standard_normal(6))
    nu = rng.standard_normal(6)
    f.reference.value = Mdes
    f.referenceVelocity.value = nu
    t = Task("t")
    t.add(f)
    t.controlGain.value = 3.0
    t.setWithDerivative(True)
    e, J = t.error.value.copy(), t.jacobian.value
    qdot = np.linalg.lstsq(J, t.task.value, rcond=None)[0]
    np.testing.assert_allclose(J @ qdot, t.task.value, atol=1e-10)  # reachable

    def error_at(h):
        f.reference.value = Mdes * pin.exp6(h * nu)
        dyn.position.value = pin.integrate(model, q, h * qdot)
        return f.error.value.copy()

    rate = (error_at(EPS) - error_at(-EPS)) / (2 * EPS)
    np.testing.assert_allclose(rate, -3.0 * e, atol=1e-6)
    # without the feed-forward the reference's motion is not compensated
    t.setWithDerivative(False)
    error_at(0.0)
    qdot = np.linalg.lstsq(t.jacobian.value, t.task.value, rcond=None)[0]
    rate = (error_at(EPS) - error_at(-EPS)) / (2 * EPS)
    assert np.abs(rate + 3.0 * e).max() > 0.1


def test_task_control_selec_zeroes_columns():
    f = generic("f", [1.0, 2.0], [[1.0, 2.0, 3.0], [4.0, 5.0, 6.0]])
    t = Task("t")
    t.add(f)
    t.controlSelec.value = "101"
    np.testing.assert_array_equal(t.jacobian.value, [[1.0, 0.0, 3.0], [4.0, 0.0, 6.0]])
    np.testing.assert_array_equal(f.jacobian.value, [[1.0, 2.0, 3.0], [4.0, 5.0, 6.0]])


def test_task_refuses_bad_input_naming_the_task_and_stays_unchanged():
    f1 = generic("f1", [1.0], [[1.0, 0.0, 0.0]])
    f2 = generic("f2", [2.0], [[1.0, 0.0]])  # 2 columns instead of 3
    t = Task("t")
    t.add(f1)
    t.add(f2)
    with pytest.raises(SotpyError, match=r"Task\(t\): the Jacobian of feature f2 has 2 col"):
        t.jacobian.value  # noqa: B018
    assert t.list() == ["f1", "f2"]
    f2.jacobianIN.value = [[1.0, 0.0, 0.0]]
    assert t.jacobian.value.shape == (2, 3)  # fixed: works again
    # unknown feature, not a feature, duplicate: refused, list unchanged
    with pytest.raises(CommandError, match=r"Task\(t\)\.add: no feature named 'nope'.*f1, f2"):
        t.add("nope")
    with pytest.raises(CommandError, match=r"Task\(t\)\.add: .*is not a feature"):
        t.add("t")
    with pytest.raises(CommandError, match=r"Task\(t\)\.add:"):
        t.add(GainAdaptive("g"))
    with pytest.raises(CommandError, match="f1 is already in the task"):
        t.add(f1)
    with pytest.raises(CommandError, match=r"remove: feature f3 is not in the task"):
        t.remove(generic("f3", [0.0], [[0.0, 0.0, 0.0]]))
    assert t.list() == ["f1", "f2"]
    # rows of the Jacobian and the error disagree
    f2.jacobianIN.value = np.zeros((2, 3))
    with pytest.raises(SotpyError, match="feature f2 has an error of 1 rows but a Jacobian of 2"):
        t.jacobian.value  # noqa: B018
    f2.jacobianIN.value = [[0.0, 1.0, 0.0]]
    # infinite error, infinite Jacobian
    f1.errorIN.value = [np.inf]
    with pytest.raises(SotpyError, match=r"Task\(t\): the error of feature f1 contains infin"):
        t.task.value  # noqa: B018
    f1.errorIN.value = [1.0]
    f2.jacobianIN.value = [[0.0, -np.inf, 0.0]]
    with pytest.raises(SotpyError, match=r"Task\(t\): the jacobian of feature f2 contains inf"):
        t.jacobian.value  # noqa: B018


def test_task_refuses_nan_from_an_upstream_output():
    src = TasksVectorSource("src")
    f = FeatureGeneric("f")
    plug(src.sout, f.errorIN)
    f.jacobianIN.value = [[1.0]]
    t = Task("t")
    t.add(f)
    np.testing.assert_array_equal(t.task.value, [0.0])
    src.payload = np.array([np.nan])
    src.sout.setReady()
    with pytest.raises(SotpyError, match=r"Task\(t\): the error of feature f contains NaN"):
        t.task.value  # noqa: B018
    t.controlGain.value = math.inf
    src.payload = np.array([1.0])
    src.sout.setReady()
    with pytest.raises(SignalTypeError, match=r"Task\(t\)::input\(double\)::controlGain"):
        t.task.value  # noqa: B018


def test_task_abstract_is_abstract_and_task_kinds():
    with pytest.raises(EntityError, match="abstract"):
        TaskAbstract("ta")
    assert Task.isInequality is False and TaskInequality.isInequality is True
    assert isinstance(Task("t"), TaskAbstract) and isinstance(TaskInequality("ti"), TaskAbstract)


# -- TaskInequality -------------------------------------------------------------------
def test_task_inequality_bounds_over_the_control_period():
    f = generic("f", [0.2, -0.5, 1.0], np.eye(3))
    t = TaskInequality("ti")
    t.add(f)
    with pytest.raises(UnpluggedError, match=r"TaskInequality\(ti\)::input\(double\)::dt"):
        t.lower.value  # noqa: B018
    t.dt.value = 0.01
    np.testing.assert_array_equal(t.lower.value, [-np.inf] * 3)  # no bounds given
    np.testing.assert_array_equal(t.upper.value, [np.inf] * 3)
    t.referenceInf.value = [0.0, -1.0, -np.inf]
    t.referenceSup.value = [0.5, 0.0, 1.0]
    e = np.array([0.2, -0.5, 1.0])
    np.testing.assert_allclose(t.lower.value, (np.array([0.0, -1.0, -np.inf]) - e) / 0.01)
    np.testing.assert_allclose(t.upper.value, (np.array([0.5, 0.0, 1.0]) - e) / 0.01)
    # one period at a bound lands exactly on it (a linear feature, J = I)
    for bound, ref in ((t.lower.value, [0.0, -1.0]), (t.upper.value, [0.5, 0.0])):
        np.testing.assert_allclose(e[:2] + bound[:2] * 0.01, ref, atol=1e-12)
    t.controlGain.value = 0.5  # half the distance per period
    np.testing.assert_allclose(t.upper.value, 0.5 * (np.array([0.5, 0.0, 1.0]) - e) / 0.01)
    assert t.jacobian.value.shape == (3, 3)
    f.errordotIN.value = [1.0, 2.0, 3.0]
    t.setWithDerivative(True)
    np.testing.assert_allclose(
        t.upper.value, 0.5 * (np.array([0.5, 0.0, 1.0]) - e) / 0.01 - [1.0, 2.0, 3.0]
    )


def test_task_inequality_refuses_bad_bounds():
    t = TaskInequality("ti")
    t.add(generic("f", [0.0, 0.0], np.eye(2)))
    t.dt.value = 0.001
    t.referenceInf.value = [0.0, 1.0]
    t.referenceSup.value = [1.0, 0.5]
    with pytest.raises(SignalTypeError, match=r"referenceInf\[1\] = 1 > referenceSup\[1\] = 0.5"):
        t.lower.value  # noqa: B018
    t.referenceSup.value = [1.0, 2.0, 3.0]
    with pytest.raises(SignalTypeError, match=r"::referenceSup: expected a vector of size 2"):
        t.upper.value  # noqa: B018
    t.referenceSup.value = [1.0, 2.0]
    t.dt.value = 0.0
    with pytest.raises(SignalTypeError, match=r"::dt: expected a control period > 0"):
        t.upper.value  # noqa: B018


# -- GainAdaptive ---------------------------------------------------------------------
def test_gain_adaptive_formula_and_slope():
    g = GainAdaptive("g")
    g.error.value = [3.0, 4.0]  # |e| = 5
    assert g.gain.value == pytest.approx(0.1)  # SoT's default: constant 0.1
    g.set(10.0, 1.0, 90.0)
    a, b, c = g.getCoefficients()
    assert (a, b, c) == pytest.approx((9.0, 10.0, 1.0))
    assert g.gain.value == pytest.approx(9.0 * math.exp(-10.0 * 5.0) + 1.0)
    g.error.value = [0.0, 0.0]
    assert g.gain.value == pytest.approx(10.0)  # value at 0
    g.error.value = [1e3, 0.0]
    assert g.gain.value == pytest.approx(1.0)  # value at infinity
    h = 1e-7  # slope at 0: d gain / d|e| = -tanAt0
    g.error.value = [h, 0.0]
    assert (g.gain.value - 10.0) / h == pytest.approx(-90.0, rel=1e-5)
    g.setConstant(2.0)
    assert g.gain.value == 2.0
    g.setByPoint(5.0, 1.0, 0.1, 0.25)  # at |e| = 0.1, a quarter of the way left
    g.error.value = [0.1]
    assert g.gain.value == pytest.approx(1.0 + 0.25 * 4.0)
    g.set(0.3, 0.3, 125e3)  # equal values: constant, whatever the slope (SoT)
    assert g.gain.value == pytest.approx(0.3)
    assert GainAdaptive("g2", 0.7).value(12.0) == pytest.approx(0.7)
    assert GainAdaptive("g3", 2.0, 1.0, 3.0).getCoefficients() == pytest.approx((1.0, 3.0, 1.0))


def test_gain_adaptive_refuses_bad_parameters():
    g = GainAdaptive("g")
    g.error.value = [1.0]
    with pytest.raises(CommandError, match=r"GainAdaptive\(g\)\.set: argument 'tanAt0'.*> 0"):
        g.set(2.0, 1.0, -1.0)  # would grow without bound
    with pytest.raises(CommandError, match="'valueAt0'"):
        g.set(-1.0, 1.0, 1.0)
    with pytest.raises(CommandError, match="'p'"):
        g.setByPoint(2.0, 1.0, 0.1, 1.5)
    with pytest.raises(CommandError, match="'xref'"):
        g.setByPoint(2.0, 1.0, 0.0, 0.5)
    with pytest.raises(CommandError, match="value"):
        g.setConstant(math.inf)
    with pytest.raises(CommandError, match="parameters"):
        GainAdaptive("g4", 1.0, 2.0)
    assert g.gain.value == pytest.approx(0.1)  # unchanged


def test_gain_adaptive_drives_a_task():
    f = generic("f", [3.0, 4.0], np.eye(2))
    t = Task("t")
    t.add(f)
    g = GainAdaptive("g", 2.0, 0.5, 1.5)
    plug(t.error, g.error)
    plug(g.gain, t.controlGain)
    lam = 1.5 * math.exp(-1.0 * 5.0) + 0.5
    np.testing.assert_allclose(t.task.value, -lam * np.array([3.0, 4.0]))


# -- meta-tasks -----------------------------------------------------------------------
def test_meta_task_kine6d_keep_and_goto(talos):
    _, dyn, _ = talos
    rh = MetaTaskKine6d("rh", dyn, "right-wrist")
    assert (rh.feature.name, rh.task.name, rh.gain.name) == ("featurerh", "taskrh", "gainrh")
    assert rh.feature.position.source is dyn.signal("right-wrist")
    assert rh.gain.error.source is rh.task.error and rh.task.controlGain.source is rh.gain.gain
    assert rh.task.list() == ["featurerh"]
    with pytest.raises(UnpluggedError, match="reference"):
        rh.task.task.value  # noqa: B018
    rh.keep()
    np.testing.assert_allclose(rh.task.error.value, np.zeros(6), atol=1e-12)
    M = dyn.signal("right-wrist").value
    target = pin.SE3(
        pin.rpy.rpyToMatrix(0.1, -0.2, 0.3), M.translation + np.array([0.2, -0.1, 0.05])
    )
    rh.gotoNd(target, gain=2.0)
    rel = target.inverse() * M
    np.testing.assert_allclose(
        rh.task.error.value, np.concatenate([rel.translation, pin.log3(rel.rotation)]), atol=1e-12
    )
    np.testing.assert_allclose(rh.task.task.value, -2.0 * rh.task.error.value)
    # position only: a 3-vector keeps the reference's orientation
    p = M.translation + np.array([0.0, 0.0, 0.1])
    rh.gotoNd(p, "111000", (1.0, 0.5, 10.0))
    np.testing.assert_allclose(rh.task.error.value, target.rotation.T @ (M.translation - p))
    assert rh.gain.getCoefficients() == pytest.approx((0.5, 20.0, 0.5))
    rh.gotoNd([0.3, -0.3, 0.9, 0.1, 0.2, 0.3], "111111")  # xyz rpy
    np.testing.assert_allclose(rh.ref.rotation, pin.rpy.rpyToMatrix(0.1, 0.2, 0.3))
    rh.ref = np.eye(4)
    assert rh.ref.isIdentity()
    with pytest.raises(CommandError, match="not a homogeneous"):
        rh.gotoNd(2 * np.eye(4))
    with pytest.raises(CommandError, match="got shape"):
        rh.gotoNd([1.0, 2.0])


def test_meta_task_kine6d_converges_with_a_resolved_rate_loop(talos):
    """J qdot = task, integrated: the error decays as exp(-gain t) (contract check)."""
    model, dyn, q = talos
    rh = MetaTaskKine6d("rh", dyn, "right-wrist")
    M = dyn.signal("right-wrist").value
    rh.gotoNd(M * pin.SE3(pin.exp3(np.array([0.1, 0.0, 0.1])), np.array([0.05, 0.02, -0.03])))
    rh.gain.setConstant(2.0)
    dt, e0 = 0.001, np.linalg.norm(rh.task.error.value)
    for _ in range(100):
        qdot = np.linalg.lstsq(rh.task.jacobian.value, rh.task.task.value, rcond=None)[0]
        q = pin.integrate(model, q, qdot * dt)
        dyn.position.value = q
    assert np.linalg.norm(rh.task.error.value) == pytest.approx(e0 * math.exp(-0.2), rel=1e-2)


def test_meta_task_kine6d_names_and_op_points(talos):
    _, dyn, _ = talos
    before = pool.list()
    with pytest.raises(EntityError, match=r"no op point 'left-wrist'.*'frame'"):
        MetaTaskKine6d("lh", dyn, "left-wrist")
    assert pool.list() == before
    lh = MetaTaskKine6d("lh", dyn, "left-wrist", "arm_left_7_joint")
    assert dyn.hasSignal("left-wrist") and dyn.hasSignal("Jleft-wrist")
    lh.keep()
    np.testing.assert_allclose(lh.task.error.value, np.zeros(6), atol=1e-12)
    before = pool.list()
    with pytest.raises(EntityError, match="featurelh, tasklh, gainlh, opmodiflh already exist"):
        MetaTaskKine6d("lh", dyn, "left-wrist")
    assert pool.list() == before
    Task("taskx")  # a clash on one name only: nothing is created
    with pytest.raises(EntityError, match="taskx already exist"):
        MetaTaskKine6d("x", dyn, "right-wrist")
    assert pool.list() == [*before, "taskx"]


def test_meta_task_kine_com(talos):
    _, dyn, _ = talos
    com = MetaTaskKineCom(dyn)
    assert [e.name for e in com.entities()] == ["featurecom", "featureDescom", "taskcom", "gaincom"]
    com.keep()
    np.testing.assert_allclose(com.task.error.value, np.zeros(3), atol=1e-12)
    c = dyn.com.value
    com.gotoNd([0.0, 0.0, 0.5], "11", 1.0)
    np.testing.assert_allclose(com.task.error.value, c[:2])
    np.testing.assert_allclose(com.task.jacobian.value, dyn.Jcom.value[:2])
    np.testing.assert_allclose(com.ref, [0.0, 0.0, 0.5])
    with pytest.raises(EntityError, match="already exist"):
        MetaTaskKineCom(dyn)
    other = MetaTaskKineCom(dyn, "com2")
    assert other.task.name == "taskcom2"


def test_meta_task_kine_posture():
    robot = load_robot("talos")
    model = robot.model
    post = MetaTaskKinePosture(robot.dynamic, robot.device)
    assert post.feature.state.source is robot.device.state
    post.keep()
    np.testing.assert_allclose(post.task.error.value, np.zeros(model.nv - 6), atol=1e-12)
    q = robot.device.state.value
    post.gotoq(gain=0.5, joints={"arm_left_4_joint": -1.0})
    idx_q = model.idx_qs[model.getJointId("arm_left_4_joint")]
    e = post.task.error.value
    assert e[idx_q - 7] == pytest.approx(q[idx_q] + 1.0)
    assert np.count_nonzero(e) == 1
    np.testing.assert_allclose(post.task.task.value, -0.5 * e)
    with pytest.raises(CommandError, match="no joint named 'elbow'"):
        post.gotoq(joints={"elbow": 0.0})
    with pytest.raises(CommandError, match="size nq = 39"):
        post.gotoq(np.zeros(3))
    # from a model: the state comes from what feeds the Dynamic, or stays unplugged
    p2 = MetaTaskKinePosture(robot.dynamic, name="p2")
    assert p2.feature.state.source is robot.device.state
    p3 = MetaTaskKinePosture(model, name="p3")
    assert not p3.feature.state.isPlugged
    assert isinstance(p3.feature, FeaturePosture)
    with pytest.raises(EntityError, match=r"Dynamic or a pinocchio\.Model"):
        MetaTaskKinePosture("talos", name="p4")


# -- SoT's API: opmodif, gotoNd as a function, toFlags, FeaturePoint6d, TaskJointLimits
def test_meta_task_kine6d_opmodif_controls_a_point_attached_to_the_op_point(talos):
    model, dyn, q = talos
    rh = MetaTaskKine6d("rh", dyn, "right-wrist")
    assert rh.opmodif is False
    aMb = pin.SE3(pin.exp3(np.array([0.0, 0.3, 0.0])), np.array([0.1, 0.0, -0.02]))
    rh.opmodif = aMb.homogeneous  # SoT writes a 4 x 4 matrix (or matrixToTuple's rows)
    np.testing.assert_allclose(rh.opmodif, aMb.homogeneous, atol=1e-15)
    assert rh.feature.position.source is rh.opPointModif.position
    data = model.createData()
    pin.framesForwardKinematics(model, data, q)
    oMb = data.oMf[model.getFrameId("arm_right_7_joint")] * aMb
    assert rh.feature.position.value.isApprox(oMb, 1e-12)
    # the controlled point's Jacobian: the error's rate along a random velocity
    rh.gotoNd(oMb.translation + np.array([0.05, 0.0, 0.0]), "111000")
    v = np.random.default_rng(5).standard_normal(model.nv)
    e0 = rh.task.error.value.copy()
    J = rh.task.jacobian.value
    dyn.position.value = pin.integrate(model, q, EPS * v)
    np.testing.assert_allclose((rh.task.error.value - e0) / EPS, J @ v, atol=1e-4)
    dyn.position.value = q
    rh.opmodif = False  # back to the op point itself
    assert rh.opmodif is False and rh.feature.position.source is dyn.signal("right-wrist")
    with pytest.raises(CommandError, match=r"MetaTaskKine6d\('rh'\)\.opmodif.*rotation"):
        rh.opmodif = np.diag([2.0, 1.0, 1.0, 1.0])
    with pytest.raises(CommandError, match="True is not a placement"):
        rh.opmodif = True
    assert rh.opmodif is False  # left unchanged


def test_meta_tasks_refuse_attributes_they_do_not_have(talos):
    _, dyn, _ = talos
    com = MetaTaskKineCom(dyn)
    with pytest.raises(
        AttributeError, match=r"MetaTaskKineCom\('com'\) has no attribute 'opmodif'"
    ):
        com.opmodif = np.eye(4)  # a SoT 6-D task's attribute: never silently stored
    com.ref = [0.0, 0.0, 0.8]  # its own attributes are fine
    np.testing.assert_array_equal(com.featureDes.errorIN.value, [0.0, 0.0, 0.8])


def test_goto_nd_function_to_flags_and_goto6d(talos):
    _, dyn, _ = talos
    rh = MetaTaskKine6d("rh", dyn, "right-wrist")
    rh.keep()
    M = rh.ref
    gotoNd(rh, M.translation + np.array([0.0, 0.0, 0.1]), "111", 2.0)
    assert rh.feature.selec.value == Flags("111")
    np.testing.assert_allclose(rh.ref.translation, M.translation + np.array([0.0, 0.0, 0.1]))
    np.testing.assert_allclose(rh.ref.rotation, M.rotation)  # sotpy's: orientation kept
    assert rh.task.controlGain.value == pytest.approx(2.0)
    goto6d(rh, M)
    assert rh.feature.selec.value == Flags("111111") and rh.ref.isApprox(M)
    with pytest.raises(CommandError, match="not a meta-task with a target"):
        gotoNd(rh.task, M)
    assert toFlags("0011") == Flags("0011")
    assert toFlags([True, False, True]) == Flags("101")
    assert toFlags(range(6, 9)) == Flags("000000111")  # row indices (old SoT scripts)
    assert toFlags([0, 1]) == Flags("01") and toFlags([3]) == Flags("0001")


def test_feature_point6d_with_a_reference_feature(talos):
    _, dyn, _ = talos
    f = FeaturePoint6d("f")
    des = FeaturePoint6d("f_ref")
    plug(dyn.signal("right-wrist"), f.position)
    plug(dyn.signal("Jright-wrist"), f.Jq)
    f.setReference(des)
    assert f.getReference() == "f_ref"
    with pytest.raises(UnpluggedError, match=r"FeaturePoint6d\(f_ref\)::input\(SE3\)::position"):
        _ = f.error.value
    M = dyn.signal("right-wrist").value
    target = M * pin.SE3(np.eye(3), np.array([0.0, 0.1, 0.0]))
    des.position.value = target.homogeneous  # SoT's: the desired placement in featureDes
    np.testing.assert_allclose(f.error.value, [0.0, -0.1, 0.0, 0.0, 0.0, 0.0], atol=1e-12)
    f.keep()  # writes the current placement into featureDes.position
    assert des.position.value.isApprox(M, 1e-12)
    np.testing.assert_allclose(f.error.value, np.zeros(6), atol=1e-12)
    f.unsetReference()
    assert f.reference.source is None


def test_task_joint_limits_bounds_and_rows():
    robot = load_robot("talos", prefix="tjl")
    model = robot.model
    t = TaskJointLimits("tjl")
    plug(robot.dynamic.position, t.position)
    plug(robot.dynamic.lowerJl, t.referenceInf)
    plug(robot.dynamic.upperJl, t.referenceSup)
    t.dt.value = 0.005
    t.controlGain.value = 4.0
    t.selec.value = toFlags(range(6, 12))  # the left leg's six DoFs
    q = robot.device.state.value
    J, lo, up = t.jacobian.value, t.lower.value, t.upper.value
    assert J.shape == (6, model.nv) and t.activeSize.value == 6
    for r, i in enumerate(range(6, 12)):
        joint = model.joints[next(j for j in range(1, model.njoints) if model.joints[j].idx_v == i)]
        k = joint.idx_q
        expected = [0.0] * model.nv
        expected[i] = 1.0
        np.testing.assert_array_equal(J[r], expected)
        lq, uq = model.lowerPositionLimit[k], model.upperPositionLimit[k]
        assert lo[r] == pytest.approx((lq - q[k]) / (0.005 * 4.0))
        assert up[r] == pytest.approx((uq - q[k]) / (0.005 * 4.0))
        assert t.normalizedPosition.value[r] == pytest.approx((q[k] - lq) / (uq - lq))
    with pytest.raises(CommandError, match="has no feature"):
        t.add(FeatureGeneric("g"))
    t.selec.value = "1"  # a free flyer's DoF: no joint limit
    with pytest.raises(SignalTypeError, match="DoF 0 is not a one-DoF joint"):
        _ = t.jacobian.value


def test_task_joint_limits_keep_a_driven_joint_inside_its_range():
    """A task pushing a joint past its limit, below TaskJointLimits: the joint stops at
    the limit (within one period's rounding) instead of going through."""
    robot = load_robot("talos", prefix="tjl")
    model = robot.model
    sot = SOT("sot")
    sot.setSize(model.nv)
    plug(sot.control, robot.device.control)
    t = TaskJointLimits("tjl")
    plug(robot.dynamic.position, t.position)
    plug(robot.dynamic.lowerJl, t.referenceInf)
    plug(robot.dynamic.upperJl, t.referenceSup)
    t.dt.value = 0.01
    elbow = model.joints[model.getJointId("arm_right_4_joint")]
    posture = MetaTaskKinePosture(robot.dynamic, robot.device)
    q = robot.halfSitting.copy()
    q[elbow.idx_q] = model.upperPositionLimit[elbow.idx_q] + 0.5  # beyond the limit
    posture.feature.posture.value = q
    posture.gain.setConstant(2.0)  # 1/s: within the elbow's velocity limit
    sot.push(t)
    sot.push(posture.task)
    for _ in range(200):
        robot.device.increment(0.01)
    qe = robot.device.state.value[elbow.idx_q]
    assert qe == pytest.approx(model.upperPositionLimit[elbow.idx_q], abs=1e-6)
    report = robot.device.boundsReport()
    assert report["position"]["count"] == 0  # the device never had to clamp
