"""Bilateral contacts between two links, the contact life cycle (ramped release and
landing), the wrench PI servo, and the next-tick position limit."""

from __future__ import annotations

import example_robot_data as erd
import numpy as np
import pinocchio as pin
import pytest

from sotpy.dynamics import load_robot
from sotpy.errors import SotpyError
from sotpy.graph import plug
from sotpy.solvers.controller import Controller, WrenchServo
from sotpy.solvers.wbc import (
    BilateralContactSpec,
    CartesianAccelerationTask,
    CoMAccelerationTask,
    ContactSpec,
    JointPositionLimit,
    JointTorqueLimit,
    WholeBodyController,
    WrenchTask,
    wrench_pi,
)

HANDS = ("arm_left_7_link", "arm_right_7_link")
FEET = ("left_sole_link", "right_sole_link")


@pytest.fixture(scope="module")
def talos():
    return erd.load("talos")


def _feet():
    return [ContactSpec(f, 6, 0.5, 0.205, 0.122, (-0.005, 0.0)) for f in FEET]


def _rel_twist(model, data, q, v, fa, fb):
    pin.forwardKinematics(model, data, q, v)
    pin.updateFramePlacements(model, data)
    M = data.oMf[fb].actInv(data.oMf[fa])
    na = pin.getFrameVelocity(model, data, fa, pin.LOCAL)
    nb = pin.getFrameVelocity(model, data, fb, pin.LOCAL)
    return (nb - M.act(na)).vector


def test_bilateral_rows_match_finite_differences(talos):
    """J_rel a + drift_rel = d/dt (relative twist), with a nonzero relative velocity."""
    model = talos.model
    w = WholeBodyController(model)
    spec = BilateralContactSpec(*HANDS)
    rng = np.random.default_rng(7)
    q = talos.q0.copy()
    v, a = rng.normal(size=(2, model.nv)) * 0.5
    w.robot.update(q, v)
    pred = w.robot.contact_jacobian(spec) @ a + w.robot.contact_drift(spec)
    data = model.createData()
    fa, fb = (model.getFrameId(f) for f in HANDS)

    def nu(t):
        qt = pin.integrate(model, q, v * t + 0.5 * a * t * t)
        return _rel_twist(model, data, qt, v + a * t, fa, fb)

    h = 1e-5
    fd = (nu(h) - nu(-h)) / (2 * h)
    assert np.abs(nu(0.0)).max() > 0.1  # the frames do move relative to each other
    assert np.allclose(pred, fd, atol=1e-5 * (1 + np.abs(fd).max()))


def _loop_wbc(talos, strategy="OneLevelWeighted"):
    w = WholeBodyController(talos.model, strategy)
    w.setContacts([*_feet(), BilateralContactSpec(*HANDS, name="hands")])
    com = w.addTask(CoMAccelerationTask("com", 1.0, 0))
    hand = w.addTask(CartesianAccelerationTask("hand", "arm_right_7_joint", 1.0, 0))
    w.addConstraint(JointTorqueLimit("tau", w.robot))
    w.activateTasksAndConstraints()
    com.setDesired([0.0, 0.0, 0.0])
    hand.setDesired([0.0, 0.0, 2.0, 0.0, 0.0, 0.0])  # pull the right hand up
    return w


@pytest.mark.parametrize("strategy", ["OneLevelWeighted", "MultiLevelWeighted"])
def test_bilateral_contact_against_pinocchio_constraint_dynamics(talos, strategy):
    """Pinocchio's constrained forward dynamics, with the hands' loop and the feet as
    rigid constraints, applied to the controller's torques gives its accelerations; the
    loop's interaction wrench is what makes the equations of motion hold."""
    model = talos.model
    w = _loop_wbc(talos, strategy)
    q = talos.q0.copy()
    v = np.zeros(model.nv)
    sol = w.update(q, v)
    assert sol.found, sol.reason
    data = model.createData()
    pin.framesForwardKinematics(model, data, q)
    models = []
    for f in FEET:
        fr = model.frames[model.getFrameId(f)]
        models.append(
            pin.RigidConstraintModel(
                pin.ContactType.CONTACT_6D, model, fr.parentJoint, fr.placement, pin.LOCAL
            )
        )
    fa, fb = (model.frames[model.getFrameId(f)] for f in HANDS)
    # the loop: A's frame, seen from B's joint at q (the two contact frames coincide)
    oMb = data.oMi[fb.parentJoint]
    placement_b = oMb.actInv(data.oMf[model.getFrameId(HANDS[0])])
    models.append(
        pin.RigidConstraintModel(
            pin.ContactType.CONTACT_6D,
            model,
            fa.parentJoint,
            fa.placement,
            fb.parentJoint,
            placement_b,
            pin.LOCAL,
        )
    )
    datas = [cm.createData() for cm in models]
    pin.initConstraintDynamics(model, data, models, datas)
    prox = pin.ProximalSettings(1e-12, 1e-12, 50)
    tau_full = np.concatenate([np.zeros(6), sol.tau])
    a = pin.constraintDynamics(model, data, q, v, tau_full, models, datas, prox)
    assert np.allclose(a, sol.a, atol=1e-6 * (1 + np.abs(a).max()))
    # the interaction wrench (whatever split of the internal force the regularisation
    # chose: the loop is statically indeterminate) closes the equations of motion
    f_loop = sol.f[12:18]
    M = pin.crba(model, data, q)
    M = np.triu(M) + np.triu(M, 1).T
    b = pin.nonLinearEffects(model, data, q, v)
    rhs = tau_full.copy()
    pin.computeJointJacobians(model, data, q)
    pin.updateFramePlacements(model, data)
    for i, f in enumerate(FEET):
        J = pin.getFrameJacobian(model, data, model.getFrameId(f), pin.LOCAL)
        rhs += J.T @ sol.f[6 * i : 6 * i + 6]
    Ja, Jb = (pin.getFrameJacobian(model, data, model.getFrameId(f), pin.LOCAL) for f in HANDS)
    Mab = data.oMf[model.getFrameId(HANDS[1])].actInv(data.oMf[model.getFrameId(HANDS[0])])
    # on B: +f (B's frame); on A: -Ad_M^T f, expressed in A's frame
    rhs += Jb.T @ f_loop - Ja.T @ (Mab.action.T @ f_loop)
    assert np.max(np.abs(M @ sol.a + b - rhs)) < 1e-8


def test_bilateral_wrench_task_and_bad_input(talos):
    w = WholeBodyController(talos.model, "MultiLevelWeighted")
    w.setContacts([*_feet(), BilateralContactSpec(*HANDS, name="hands")])
    sq = w.addTask(WrenchTask("squeeze", "hands", 6, 1.0, 0))
    w.activateTasksAndConstraints()
    target = np.array([0.0, 30.0, 0.0, 0.0, 0.0, 1.0])
    sq.setDesired(target)
    sol = w.update(talos.q0.copy(), np.zeros(talos.model.nv))
    assert sol.found and np.allclose(sol.f[12:18], target, atol=1e-7)
    with pytest.raises(SotpyError, match="must differ"):
        w.setContacts([BilateralContactSpec(HANDS[0], HANDS[0])])
    with pytest.raises(SotpyError, match="no frame"):
        w.setContacts([BilateralContactSpec(HANDS[0], "nowhere")])
    with pytest.raises(SotpyError, match="twice"):
        w.setContacts([BilateralContactSpec(*HANDS), BilateralContactSpec(*HANDS)])


def test_contact_release_and_landing_are_ramped(talos):
    model = talos.model
    w = WholeBodyController(model)
    w.setContacts(_feet())
    com = w.addTask(CoMAccelerationTask("com", 1.0, 0))
    w.activateTasksAndConstraints()
    com.setDesired([0.0, 0.0, 0.0])
    q, v = talos.q0.copy(), np.zeros(model.nv)
    sol = w.update(q, v)
    F = sol.f[8]  # the right foot's normal force before the release
    assert F > 100.0
    log = []
    st = w.contact_states["right_sole_link"]
    for ev in ("onDeactivation", "onDeactivated", "onActivation", "onActivated"):
        st.setCallback(ev, lambda ev=ev: log.append(ev))
    st.setRampDuration(0.004)
    w.deactivate("right_sole_link")
    assert np.allclose(st.scale, sol.f[6:12])
    fz = []
    for _ in range(5):
        s = w.update(q, v)
        assert s.found, s.reason
        fz.append(s.f[8])
    # bound r F with r = 3/4, 1/2, 1/4, then released: f = 0 and the foot may move
    assert np.all(np.array(fz[:3]) <= np.array([0.75, 0.5, 0.25]) * F + 1e-6)
    assert np.all(np.abs(s.f[6:12]) < 1e-9)  # f = 0 rows, held to the QP's rounding
    assert st.state == "inactive" and log == ["onDeactivation", "onDeactivated"]
    A = w.robot.contact_jacobian(_feet()[1])
    assert np.linalg.norm(A @ s.a + w.robot.contact_drift(_feet()[1])) > 1e-3
    # landing: the foot held at once, its force bounded by r m g while the ramp rises
    w.activate("right_sole_link")
    mg = pin.computeTotalMass(model) * 9.81
    for k in range(4):
        s = w.update(q, v)
        assert s.found
        assert s.f[8] <= (k + 1) / 4 * mg + 1e-6
        data = model.createData()
        pin.forwardKinematics(model, data, q, v, s.a)
        acc = pin.getFrameAcceleration(model, data, model.getFrameId(FEET[1]), pin.LOCAL)
        assert np.abs(acc.vector).max() < 1e-8
    assert st.isActivated and log[-1] == "onActivated"


def test_contact_life_cycle_through_the_entity():
    robot = load_robot("talos")
    ctrl = Controller("lcCtrl", robot.dynamic)
    for f in robot.feet.values():
        ctrl.addContact(f.frame, 0.5, f.length, f.width, f.offset[0], f.offset[1], 6, 0.0)
    ctrl.addBilateralContact("hands", *HANDS)
    assert ctrl.getContacts() == [*FEET, "hands"]
    ctrl.addComTask("comTask", 1.0, 0)
    ctrl.activateTasksAndConstraints()
    _ = ctrl.solution.value
    ctrl.setRampDuration("hands", 0.0)
    ctrl.deactivate("hands")
    robot.device.setControlType("torque")
    robot.device.setContacts(list(FEET))
    plug(ctrl.torque, robot.device.control)
    robot.device.increment(0.001)
    assert ctrl.core.contact_states["hands"].state == "inactive"
    assert np.all(np.abs(ctrl.wrenches.value[12:18]) < 1e-9)
    with pytest.raises(SotpyError, match="no task, constraint or contact"):
        ctrl.deactivate("nope")
    with pytest.raises(SotpyError, match="exists"):
        ctrl.addBilateralContact("hands", *HANDS)


def test_wrench_pi_against_a_hand_rolled_loop():
    ws = WrenchServo("ws")
    ws.dt.value = 0.01
    wd = np.array([0.0, 0.0, 100.0, 0.0, 0.0, 0.0])
    w = np.array([1.0, -2.0, 90.0, 0.5, 0.0, 0.0])
    ws.reference.value = wd
    ws.measured.value = w
    ws.Kp.value = [0.5]
    ws.Ki.value = [2.0]
    lim = np.array([1.0, 1.0, 0.25, 1.0, 1.0, 1.0])
    ws.integralLimit.value = lim
    integral = np.zeros(6)
    for t in range(1, 7):
        out = ws.desiredWrench(t)
        e = wd - w
        integral = np.minimum(np.maximum(integral + 0.01 * e, -lim), lim)
        assert np.allclose(out, wd + 0.5 * e + 2.0 * integral)
    # anti-windup: the z integral stopped at its clamp (6 ticks of 0.1 N s > 0.25)
    assert np.isclose(ws.getIntegral()[2], 0.25)
    assert np.allclose(ws.getIntegral()[[0, 1]], 0.06 * (wd - w)[[0, 1]])
    ws.resetIntegral()
    assert np.allclose(ws.desiredWrench(10), wd + 0.5 * (wd - w) + 2.0 * 0.01 * (wd - w))
    out, integ = wrench_pi(w, wd, np.zeros(6), 0.01, 0.5, 2.0, np.full(6, np.inf))
    assert np.allclose(integ, 0.01 * (wd - w))
    ws.Ki.value = [-1.0]
    with pytest.raises(SotpyError, match="Ki"):
        ws.desiredWrench(11)
    ws.Ki.value = [1.0]
    ws.measured.value = np.zeros(5)
    with pytest.raises(SotpyError, match="measured"):
        ws.desiredWrench(12)


def test_wrench_servo_drives_a_wrench_task():
    robot = load_robot("talos")
    ctrl = Controller("wsCtrl", robot.dynamic)
    for f in robot.feet.values():
        ctrl.addContact(f.frame, 0.5, f.length, f.width, f.offset[0], f.offset[1], 6, 0.0)
    ctrl.addWrenchTask("leftWrench", FEET[0], 1.0, 0)
    ctrl.setResolutionStrategy("MultiLevelWeighted")
    ctrl.activateTasksAndConstraints()
    ws = WrenchServo("wsServo")
    ws.reference.value = np.array([0.0, 0.0, 500.0, 0.0, 0.0, 0.0])
    ws.measured.value = np.array([0.0, 0.0, 480.0, 0.0, 0.0, 0.0])
    ws.Kp.value = [0.1]
    plug(ws.desiredWrench, ctrl.leftWrench)
    assert np.allclose(ctrl.wrenches.value[:6], [0, 0, 502.0, 0, 0, 0], atol=1e-6)


def test_position_limit_holds_at_the_next_tick():
    """The next tick's semi-implicit Euler step q + dt v + dt^2 a stays within the
    limits although the horizon row alone would let it through."""
    model = erd.load("panda").model
    w = WholeBodyController(model)
    ee = w.addTask(CartesianAccelerationTask("ee", "panda_hand_tcp"))
    w.addConstraint(JointPositionLimit("qlim", w.robot, 0.05))
    w.activateTasksAndConstraints()
    ee.setDesired([0.0, 0.0, -50.0, 0.0, 0.0, 0.0])
    q = pin.neutral(model)
    j = 3
    q[j] = model.upperPositionLimit[j] - 1e-4
    v = np.zeros(model.nv)
    v[j] = 0.2  # fast towards the limit: the 0.05 s horizon alone allows a step past it
    dt = 0.001
    sol = w.update(q, v, dt=dt)
    assert sol.found
    step = q + dt * v + dt * dt * sol.a
    assert np.all(step <= model.upperPositionLimit + 1e-12)
    assert np.all(step >= model.lowerPositionLimit - 1e-12)
    assert np.all(q + 0.05 * v + 0.5 * 0.05**2 * sol.a <= model.upperPositionLimit + 1e-9)
