"""The torque-level whole-body QP core (sotpy.solvers.wbc), against independent
computations: Pinocchio's own accelerations, finite differences, numpy KKT solves."""

from __future__ import annotations

import example_robot_data as erd
import numpy as np
import pinocchio as pin
import pytest

from sotpy.errors import SotpyError, SotpyWarning
from sotpy.solvers.wbc import (
    CartesianAccelerationTask,
    CoMAccelerationTask,
    ContactSpec,
    JointAccelerationLimit,
    JointAccelerationTask,
    JointPositionLimit,
    JointTorqueLimit,
    JointVelocityLimit,
    WholeBodyController,
    WrenchTask,
    friction_rows,
    min_jerk,
    min_jerk_scalar,
    pose_error,
    pose_pd,
)

EE = "panda_hand_tcp"


@pytest.fixture(scope="module")
def panda():
    return erd.load("panda")


@pytest.fixture(scope="module")
def talos():
    return erd.load("talos")


def _state(model, q0, seed=0):
    rng = np.random.default_rng(seed)
    v = rng.normal(size=model.nv) * 0.5
    return q0.copy(), v


def _feet():
    return [
        ContactSpec(f, 6, 0.4, 0.205, 0.122, (-0.005, 0.0))
        for f in ("left_sole_link", "right_sole_link")
    ]


def _talos_wbc(talos, strategy):
    w = WholeBodyController(talos.model, strategy)
    w.setContacts(_feet())
    com = w.addTask(CoMAccelerationTask("com", 10.0, 0))
    hand = w.addTask(CartesianAccelerationTask("hand", "arm_right_7_link", 1.0, 1))
    w.addTask(JointAccelerationTask("posture", w.robot.na, 1e-2, 2))
    w.addConstraint(JointTorqueLimit("tau", w.robot))
    w.activateTasksAndConstraints()
    com.setDesired([0.0, 0.3, 0.0])
    hand.setDesired([0.5, 0.0, 0.5, 0.0, 0.0, 0.0])
    return w


def _check_talos(talos, sol, feet, q, v, standing=True):
    """The solution against Pinocchio: the equations of motion with the contacts
    ``feet``, no foot acceleration, friction pyramids and CoP rectangles, torque limits."""
    data = talos.model.createData()
    M = pin.crba(talos.model, data, q)
    M = np.triu(M) + np.triu(M, 1).T
    b = pin.nonLinearEffects(talos.model, data, q, v)
    pin.computeJointJacobians(talos.model, data, q)
    pin.updateFramePlacements(talos.model, data)
    assert sol.f.shape == (6 * len(feet),)
    rhs = np.concatenate([np.zeros(6), sol.tau])
    for i, c in enumerate(feet):
        J = pin.getFrameJacobian(talos.model, data, talos.model.getFrameId(c.frame), pin.LOCAL)
        rhs += J.T @ sol.f[6 * i : 6 * i + 6]
        # the feet do not accelerate (LOCAL spatial acceleration at a, v)
        pin.forwardKinematics(talos.model, data, q, v, sol.a)
        acc = pin.getFrameAcceleration(
            talos.model, data, talos.model.getFrameId(c.frame), pin.LOCAL
        )
        assert np.max(np.abs(acc.vector)) < 1e-8
        # friction pyramid and CoP rectangle
        G, h = friction_rows(c)
        fc = sol.f[6 * i : 6 * i + 6]
        assert np.all(G @ fc <= h + 1e-6)
        if standing:
            assert fc[2] > 100.0  # standing: carries weight
        cop_x, cop_y = -fc[4] / fc[2], fc[3] / fc[2]
        assert -0.1075 - 1e-6 <= cop_x <= 0.0975 + 1e-6 and abs(cop_y) <= 0.061 + 1e-6
    assert np.max(np.abs(M @ sol.a + b - rhs)) < 1e-8
    lim = talos.model.effortLimit[6:]
    assert np.all(np.abs(sol.tau) <= lim + 1e-6)


@pytest.mark.parametrize("strategy", ["OneLevelWeighted", "MultiLevelWeighted"])
def test_talos_dynamics_contacts_and_bounds(talos, strategy):
    w = _talos_wbc(talos, strategy)
    q, v = talos.q0.copy(), np.zeros(talos.model.nv)
    sol = w.update(q, v)
    assert sol.found, sol.reason
    _check_talos(talos, sol, _feet(), q, v)


@pytest.mark.parametrize("strategy", ["OneLevelWeighted", "MultiLevelWeighted"])
def test_talos_contacts_changed_at_run_time(talos, strategy):
    """One foot, then both again: the problem has other variables each time (6 wrench
    components fewer, then more), and each answer meets that tick's contacts."""
    w = _talos_wbc(talos, strategy)
    q, v = talos.q0.copy(), np.zeros(talos.model.nv)
    assert w.update(q, v).found
    for feet in (_feet()[:1], _feet()):
        w.setContacts(feet)
        sol = w.update(q, v)
        assert sol.found, sol.reason
        _check_talos(talos, sol, feet, q, v, standing=len(feet) == 2)


def test_cartesian_drift_matches_finite_differences(panda):
    """J a + drift = d/dt (origin velocity, angular velocity) in world axes."""
    model = panda.model
    w = WholeBodyController(model)
    rng = np.random.default_rng(1)
    q = pin.randomConfiguration(model)
    v = rng.normal(size=model.nv)
    a = rng.normal(size=model.nv)
    w.robot.update(q, v)
    fid = model.getFrameId(EE)
    pred = w.robot.frame_jacobian(fid) @ a + w.robot.frame_drift(fid)
    data = model.createData()

    def nu(t):
        qt = pin.integrate(model, q, v * t + 0.5 * a * t * t)
        pin.forwardKinematics(model, data, qt, v + a * t)
        pin.updateFramePlacements(model, data)
        return pin.getFrameVelocity(model, data, fid, pin.LOCAL_WORLD_ALIGNED).vector

    h = 1e-5
    fd = (nu(h) - nu(-h)) / (2 * h)
    assert np.allclose(pred, fd, atol=1e-5 * (1 + np.abs(fd).max()))


def test_com_drift_matches_finite_differences(talos):
    model = talos.model
    w = WholeBodyController(model)
    rng = np.random.default_rng(2)
    q = talos.q0.copy()
    v, a = rng.normal(size=model.nv) * 0.3, rng.normal(size=model.nv) * 0.3
    w.robot.update(q, v)
    pred = w.robot.Jcom @ a + w.robot.com_drift
    data = model.createData()

    def vcom(t):
        qt = pin.integrate(model, q, v * t + 0.5 * a * t * t)
        return pin.jacobianCenterOfMass(model, data, qt) @ (v + a * t)

    h = 1e-5
    assert np.allclose(pred, (vcom(h) - vcom(-h)) / (2 * h), atol=1e-5)


@pytest.mark.parametrize("strategy,tol", [("MultiLevelWeighted", 1e-8), ("OneLevelWeighted", 1e-5)])
def test_task_alone_tracks_exactly(panda, strategy, tol):
    model = panda.model
    w = WholeBodyController(model, strategy)
    task = w.addTask(CartesianAccelerationTask("ee", EE))
    w.activateTasksAndConstraints()
    a_des = np.array([0.3, -0.2, 0.1, 0.5, -0.4, 0.2])
    task.setDesired(a_des)
    q, v = _state(model, panda.q0, 3)
    sol = w.update(q, v)
    assert sol.found
    data = model.createData()
    pin.forwardKinematics(model, data, q, v, sol.a)
    acc = pin.getFrameClassicalAcceleration(
        model, data, model.getFrameId(EE), pin.LOCAL_WORLD_ALIGNED
    )
    assert np.max(np.abs(acc.vector - a_des)) < tol
    # the torque is the inverse dynamics of that acceleration
    assert np.allclose(sol.tau, pin.rnea(model, data, q, v, sol.a), atol=1e-8)


def _conflict(panda, strategy):
    model = panda.model
    w = WholeBodyController(model, strategy)
    ee = w.addTask(CartesianAccelerationTask("ee", EE, 1.0, 0))
    post = w.addTask(JointAccelerationTask("posture", w.robot.na, 0.5, 1))
    w.activateTasksAndConstraints()
    ee.setDesired([1.0, 0.0, 0.0, 0.0, 0.0, 0.0])
    post.setDesired(np.full(w.robot.na, 2.0))
    q, v = _state(model, panda.q0, 4)
    return w, w.update(q, v), q, v


def test_multilevel_meets_top_level_exactly(panda):
    w, sol, _q, _v = _conflict(panda, "MultiLevelWeighted")
    E, f = w.tasks["ee"].rows(w.robot, w.layout)
    assert np.max(np.abs(E @ sol.chi - f)) < 1e-9
    # and the posture is met as well as possible in the null space: not exactly
    E2, f2 = w.tasks["posture"].rows(w.robot, w.layout)
    assert np.linalg.norm(E2 @ sol.chi - f2) > 1e-3


def test_weighted_equals_closed_form(panda):
    w, sol, _q, _v = _conflict(panda, "OneLevelWeighted")
    (A, c), _cons, tasks = w.problem()
    n = w.layout.n
    H = w.regularisation * np.eye(n)
    g = np.zeros(n)
    for _l, E, f, wt in tasks:
        H += E.T @ np.diag(wt) @ E
        g -= E.T @ np.diag(wt) @ f
    K = np.block([[H, A.T], [A, np.zeros((len(c), len(c)))]])
    x = np.linalg.solve(K, np.concatenate([-g, c]))[:n]
    assert np.allclose(sol.chi, x, atol=1e-6 * (1 + np.abs(x).max()))
    # the top task is not met exactly in the weighted answer (it is traded off)
    E, f = w.tasks["ee"].rows(w.robot, w.layout)
    assert np.linalg.norm(E @ sol.chi - f) > 1e-4


@pytest.mark.parametrize("strategy", ["OneLevelWeighted", "MultiLevelWeighted"])
def test_limits_hold(panda, strategy):
    model = panda.model
    w = WholeBodyController(model, strategy)
    ee = w.addTask(CartesianAccelerationTask("ee", EE))
    w.addConstraint(JointTorqueLimit("tau", w.robot, -np.full(9, 5.0), np.full(9, 5.0)))
    h = 0.05
    w.addConstraint(JointPositionLimit("qlim", w.robot, h))
    w.addConstraint(JointVelocityLimit("vlim", w.robot, 0.01))
    w.activateTasksAndConstraints()
    ee.setDesired([50.0, 0, 0, 0, 0, 0])  # far beyond what the limits allow
    q = panda.q0.copy()
    q[3] = model.upperPositionLimit[3] - 0.01
    v = np.zeros(model.nv)
    v[3] = 0.1
    sol = w.update(q, v)
    assert sol.found, sol.reason
    assert np.all(np.abs(sol.tau) <= 5.0 + 1e-7)
    pred = q + h * v + 0.5 * h * h * sol.a
    assert np.all(pred <= model.upperPositionLimit + 1e-7) and np.all(
        pred >= model.lowerPositionLimit - 1e-7
    )
    vn = v + 0.01 * sol.a
    assert np.all(np.abs(vn) <= model.velocityLimit + 1e-7)
    assert sol.dynamics_residual < 1e-8


@pytest.mark.parametrize("strategy", ["OneLevelWeighted", "MultiLevelWeighted"])
def test_infeasible_reports_and_falls_back(panda, strategy):
    model = panda.model
    w = WholeBodyController(model, strategy)
    w.addTask(CartesianAccelerationTask("ee", EE))
    w.addConstraint(JointTorqueLimit("tau", w.robot, -np.full(9, 0.01), np.full(9, 0.01)))
    w.addConstraint(JointAccelerationLimit("alim", w.robot, -np.full(9, 0.01), np.full(9, 0.01)))
    w.activateTasksAndConstraints()
    q = panda.q0.copy()
    sol = w.update(q, np.zeros(model.nv))
    assert not sol.found and sol.reason
    g = pin.computeGeneralizedGravity(model, model.createData(), q)
    assert np.allclose(sol.tau, np.clip(g, -0.01, 0.01))
    assert np.all(sol.a == 0) and np.all(np.isfinite(sol.chi))


def test_bad_input(panda, talos):
    w = WholeBodyController(panda.model)
    with pytest.raises(SotpyError, match="no frame"):
        w.addTask(CartesianAccelerationTask("x", "no_such_frame"))
    for bad in (-1.0, float("nan"), float("inf")):
        with pytest.raises(SotpyError, match="weight"):
            CartesianAccelerationTask("x", EE, weight=bad)
    t = CartesianAccelerationTask("x", EE)
    with pytest.raises(SotpyError, match="size 6"):
        t.setDesired(np.zeros(5))
    with pytest.raises(SotpyError, match="not finite"):
        t.setDesired([np.nan] * 6)
    with pytest.raises(SotpyError, match="selection"):
        t.setSelection([0.5] * 6)
    with pytest.raises(SotpyError, match="row weights"):
        t.setRowWeights([-1.0] * 6)
    with pytest.raises(SotpyError, match="size"):
        JointTorqueLimit("tau", w.robot, np.zeros(3), np.zeros(3))
    with pytest.raises(SotpyError, match="lower <= upper"):
        JointTorqueLimit("tau", w.robot, np.ones(9), -np.ones(9))
    with pytest.raises(SotpyError, match="horizon"):
        JointPositionLimit("q", w.robot, -0.1)
    with pytest.raises(SotpyError, match="strategy"):
        w.setStrategy("Generalized")
    with pytest.raises(SotpyError, match="expected q"):
        w.update(np.zeros(3), np.zeros(9))
    wt = WholeBodyController(talos.model)
    with pytest.raises(SotpyError, match="no frame"):
        wt.setContacts([ContactSpec("nowhere")])
    with pytest.raises(SotpyError, match="mu"):
        wt.setContacts([ContactSpec("left_sole_link", mu=-1.0)])
    with pytest.raises(SotpyError, match="no contact"):
        wt.addTask(WrenchTask("w", "left_sole_link", 6))


def test_wrench_task_sets_the_force(talos):
    """A wrench task above the last level is met exactly; in the last level it shares
    the level with the contact wrench cost (docs/torque-control.md), which pulls the
    force towards the soles' centres (the target's CoP is 3 cm off the centre line)."""
    target = np.array([20.0, 0.0, 300.0, 10.0, 0.0, 0.0])
    forces = {}
    for below in (True, False):
        w = WholeBodyController(talos.model, "MultiLevelWeighted")
        w.setContacts(_feet())
        wr = w.addTask(WrenchTask("lw", "left_sole_link", 6, 1.0, 0))
        if below:
            w.addTask(JointAccelerationTask("posture", w.robot.na, 1e-2, 1))
        w.activateTasksAndConstraints()
        wr.setDesired(target)
        sol = w.update(talos.q0.copy(), np.zeros(talos.model.nv))
        assert sol.found
        forces[below] = sol.f[:6].copy()
    assert np.allclose(forces[True], target, atol=1e-7)
    assert not np.allclose(forces[False], target, atol=1e-3)


def test_activation_ramp_and_callbacks(panda):
    w = WholeBodyController(panda.model)
    t = w.addTask(CartesianAccelerationTask("ee", EE, weight=2.0))
    t.setRampDuration(0.003)
    log = []
    for ev in ("onActivation", "onActivated", "onDeactivation", "onDeactivated"):
        t.setCallback(ev, lambda ev=ev: log.append(ev))
    t.setCallback("onComputeBegin", lambda tt, dt: log.append("begin"))
    t.setCallback("onComputeEnd", lambda tt, dt: log.append("end"))
    q, v = panda.q0.copy(), np.zeros(9)
    with pytest.warns(SotpyWarning, match="nothing is active"):
        w.update(q, v)  # inactive: no callback, and a warning
    assert log == [] and t.ramp == 0.0
    w.activateTasksAndConstraints()
    ramps = []
    for _ in range(4):
        w.update(q, v, dt=0.001)
        ramps.append(t.ramp)
    assert np.allclose(ramps, [1 / 3, 2 / 3, 1.0, 1.0])
    assert np.allclose(t.row_weight_vector(), 2.0)
    assert log[:7] == ["onActivation", "begin", "end", "begin", "end", "begin", "end"]
    assert log[7] == "onActivated" and log.count("onActivated") == 1
    w.deactivateTasksAndConstraints()
    while not w.tasksAndConstraintsDeactivated():
        w.update(q, v, dt=0.001)
    with pytest.warns(SotpyWarning, match="nothing is active"):
        w.update(q, v, dt=0.001)
    assert log[-1] == "onDeactivated" and "onDeactivation" in log and t.ramp == 0.0
    with pytest.raises(SotpyError, match="unknown callback"):
        t.setCallback("onFoo", print)


def test_pose_pd_and_error():
    rng = np.random.default_rng(5)
    M = pin.SE3.Random()
    Md = pin.SE3.Random()
    e = pose_error(M, Md)
    assert np.allclose(e[:3], M.translation - Md.translation)
    assert np.allclose(pin.exp3(e[3:]) @ Md.rotation, M.rotation)  # R = exp(e_R) R_d
    nu, nud, ad = rng.normal(size=(3, 6))
    kp = np.arange(1.0, 7.0)
    kd = 2 * np.sqrt(kp)
    assert np.allclose(pose_pd(M, nu, Md, nud, ad, kp, kd), ad - kp * e - kd * (nu - nud))


def test_min_jerk_closed_form_and_derivatives():
    T = 2.0
    for t in (0.3, 1.0, 1.7):
        s, ds, dds = min_jerk_scalar(t, T)
        x = t / T
        assert np.isclose(s, 10 * x**3 - 15 * x**4 + 6 * x**5)
        assert np.isclose(ds, (30 * x**2 - 60 * x**3 + 30 * x**4) / T)
        assert np.isclose(dds, (60 * x - 180 * x**2 + 120 * x**3) / T**2)
    assert min_jerk_scalar(-1, T) == (0.0, 0.0, 0.0) and min_jerk_scalar(3, T) == (1.0, 0.0, 0.0)
    M0, M1 = pin.SE3.Random(), pin.SE3.Random()
    M, vel, acc = min_jerk(M0, M1, T, 0.0)
    assert M.isApprox(M0)
    assert min_jerk(M0, M1, T, T)[0].isApprox(M1, 1e-9)
    t, h = 0.8, 1e-6
    Mp, vp, _ = min_jerk(M0, M1, T, t + h)
    Mm, vm, _ = min_jerk(M0, M1, T, t - h)
    M, vel, acc = min_jerk(M0, M1, T, t)
    assert np.allclose(vel[:3], (Mp.translation - Mm.translation) / (2 * h), atol=1e-6)
    w_fd = pin.log3(Mp.rotation @ Mm.rotation.T) / (2 * h)  # world angular velocity
    assert np.allclose(vel[3:], w_fd, atol=1e-6)
    assert np.allclose(acc, (vp - vm) / (2 * h), atol=1e-5)


def test_the_model_update_leaves_the_zero_acceleration_kinematics(talos):
    """``RobotModel.update`` runs ``computeAllTerms`` only: the joints' velocities and
    accelerations it leaves must be Pinocchio's ``forwardKinematics(q, v, 0)`` (the
    drifts ``Jdot v`` and the CoM's are read from them)."""
    model = talos.model
    w = WholeBodyController(model)
    ref = model.createData()
    for seed in range(3):
        q, v = _state(model, pin.randomConfiguration(model), seed)
        q[3:7] = pin.Quaternion(pin.rpy.rpyToMatrix(0.1 * seed, 0.2, -0.3)).coeffs()
        w.robot.update(q, v)
        pin.forwardKinematics(model, ref, q, v, np.zeros(model.nv))
        pin.centerOfMass(model, ref, pin.KinematicLevel.ACCELERATION, False)
        for i in range(1, model.njoints):
            assert np.allclose(w.robot.data.v[i].vector, ref.v[i].vector, atol=1e-12)
            assert np.allclose(w.robot.data.a[i].vector, ref.a[i].vector, atol=1e-12)
        assert np.allclose(w.robot.com_drift, ref.acom[0], atol=1e-12)
