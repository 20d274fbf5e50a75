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
    JointAccelerationTask,
    JointPositionLimit,
    JointTorqueLimit,
    WholeBodyController,
    WrenchTask,
    friction_rows,
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
    ctrl.addJointTask("posture", 1e-2, 1)  # below: the wrench task's level is not the last
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


# -- the contacts that keep a foot on a floor ---------------------------------------------
@pytest.mark.parametrize("facets,loss", [(4, 1 - np.sqrt(0.5)), (8, 1 - np.cos(np.pi / 8))])
def test_friction_pyramid_facets_by_linear_programming(facets, loss):
    """The largest tangential force the pyramid allows in each direction (an LP, not the
    rows' formula): mu at its edges, ``mu cos(pi/n)`` at worst, never beyond the cone."""
    from scipy.optimize import linprog

    c = ContactSpec("left_sole_link", 3, 0.6, facets=facets)
    G, h = friction_rows(c)
    best = []
    for theta in np.linspace(0.0, 2 * np.pi, 721):  # every 0.5 deg: the edges included
        d = np.array([np.cos(theta), np.sin(theta)])
        # max d . f_t subject to G f <= h and f_z = 1
        res = linprog(
            -np.r_[d, 0.0], A_ub=G, b_ub=h, A_eq=[[0, 0, 1]], b_eq=[1.0], bounds=[(None, None)] * 3
        )
        assert res.status == 0
        best.append(-res.fun)
    best = np.array(best) / c.mu
    assert best.max() == pytest.approx(1.0, abs=1e-9)  # inscribed: its edges on the cone
    assert best.min() == pytest.approx(1.0 - loss, abs=1e-6)


def test_cop_margin_and_contact_settings_are_checked(talos):
    from scipy.optimize import linprog

    c = ContactSpec("left_sole_link", 6, 0.5, 0.205, 0.122, (-0.005, 0.0), margin=0.01)
    G, h = friction_rows(c)
    for sign, axis in ((1, 4), (-1, 4), (1, 3), (-1, 3)):  # extreme CoPs, f_z = 1
        obj = np.zeros(6)
        obj[axis] = -sign
        res = linprog(obj, A_ub=G, b_ub=h, A_eq=[[0, 0, 1, 0, 0, 0]], b_eq=[1.0],
                      bounds=[(None, None)] * 6)  # fmt: skip
        tau = res.x[axis]  # CoP x = -tau_y / f_z (from the centre at -5 mm), y = tau_x / f_z
        if axis == 4:
            assert abs(-tau + 0.005) == pytest.approx(0.205 / 2 - 0.01)
        else:
            assert abs(tau) == pytest.approx(0.122 / 2 - 0.01)
    w = WholeBodyController(talos.model)
    for bad, what in (
        (dict(margin=0.07), "margin"),
        (dict(facets=2), "facets"),
        (dict(facets=4.5), "facets"),
        (dict(kp=-1.0), "gains"),
        (dict(kd=float("nan")), "gains"),
    ):
        with pytest.raises(SotpyError, match=what):
            w.setContacts([ContactSpec("left_sole_link", 6, 0.5, 0.205, 0.122, **bad)])
    assert w.contacts == []


def test_contact_feedback_asks_the_foot_back_to_its_reference(talos):
    """With gains, the contact row asks the foot's LOCAL spatial acceleration to be
    ``-kp e - kd nu``: checked with Pinocchio's own acceleration of the frame at the
    solution, the foot moved 2 mm and 5 mrad off its reference and moving."""
    model = talos.model
    kp, kd = 100.0, 15.0
    w = WholeBodyController(model)
    w.setContacts([ContactSpec(f, 6, 0.5, 0.205, 0.122, (-0.005, 0.0), kp=kp, kd=kd) for f in FEET])
    w.addTask(CoMAccelerationTask("com", 1.0)).activate()
    w.setTorqueRateLimit(np.inf)
    q = talos.q0.copy()
    w.update(q, np.zeros(model.nv))  # the references: the feet where they are
    rng = np.random.default_rng(2)
    dq = np.zeros(model.nv)
    dq[6:] = rng.normal(size=model.nv - 6) * 2e-3
    q2 = pin.integrate(model, q, dq)
    v = rng.normal(size=model.nv) * 0.05
    sol = w.update(q2, v)
    assert sol.found
    data = model.createData()
    pin.forwardKinematics(model, data, q2, v, sol.a)
    pin.updateFramePlacements(model, data)
    for f in FEET:
        fid = model.getFrameId(f)
        ref = w.contact_states[f].reference
        e = pin.log6(ref.actInv(data.oMf[fid])).vector
        nu = pin.getFrameVelocity(model, data, fid, pin.LOCAL).vector
        acc = pin.getFrameAcceleration(model, data, fid, pin.LOCAL).vector
        assert np.abs(e).max() > 1e-3  # off its reference
        assert np.allclose(acc, -kp * e - kd * nu, atol=1e-7)
    # activating a contact anew takes its reference where the foot is then
    w.deactivate(FEET[0])
    while w.contact_states[FEET[0]].state != "inactive":
        w.update(q2, v)
    w.activate(FEET[0])
    w.update(q2, v)
    data2 = model.createData()
    pin.framesForwardKinematics(model, data2, q2)
    assert w.contact_states[FEET[0]].reference.isApprox(data2.oMf[model.getFrameId(FEET[0])])


def test_wrench_cost_keeps_a_light_foot_centred(talos):
    """The CoM accelerated to the right (the ZMP goes left, over the left foot), 40 N
    left on the right foot: without the cost,
    the least-norm split puts the light foot on the edges of its polyhedron (friction and
    CoP at their bounds); with it, the light foot's wrench is centred."""

    def solve(weight):
        w = WholeBodyController(talos.model)
        w.setContacts(
            [ContactSpec(f, 6, 0.5, 0.205, 0.122, (-0.005, 0.0), 40.0, 0.01) for f in FEET]
        )
        w.setContactCostWeight(weight)
        w.setTorqueRateLimit(np.inf)  # one state, solved again: no transition to slow it
        w.addTask(CoMAccelerationTask("com", 10.0)).setDesired([0.0, -1.0, 0.0])
        w.addTask(JointAccelerationTask("post", w.robot.na, 1e-2))
        w.activateTasksAndConstraints()
        q, v = talos.q0.copy(), np.zeros(talos.model.nv)
        for _ in range(3):  # the cost's loads come from the previous solution
            sol = w.update(q, v)
        assert sol.found
        return sol.f.reshape(2, 6)

    def utilisation(f):  # |f_t| / (mu cos(pi/8) f_z) and |CoP| / half-size, per foot
        fz = f[:, 2]
        fric = np.hypot(f[:, 0], f[:, 1]) / (0.5 * np.cos(np.pi / 8) * fz)
        cop = np.maximum(np.abs(-f[:, 4] / fz + 0.005) / 0.0925, np.abs(f[:, 3] / fz) / 0.051)
        return fric, cop

    bare, cost = solve(0.0), solve(0.1)
    light = int(np.argmin(cost[:, 2]))
    assert cost[light, 2] == pytest.approx(40.0, rel=1e-6)
    fric0, cop0 = utilisation(bare)
    fric1, cop1 = utilisation(cost)
    assert max(fric0[light], cop0[light]) > 0.99  # on an edge
    assert fric1[light] < 0.05 and cop1[light] < 0.05  # centred


def test_wrench_cost_rows_are_the_ratios_at_their_load():
    from sotpy.solvers.wbc import ContactWrenchCost

    c = ContactSpec("left_sole_link", 6, 0.7, 0.2, 0.1, (0.01, -0.02), margin=0.005)
    F = 300.0
    f = np.array([20.0, -15.0, F, 4.0, -6.0, 1.5])  # a wrench with f_z = F
    r = ContactWrenchCost.contact_rows(c, F) @ f
    X, Y = 0.1 - 0.005, 0.05 - 0.005
    cop = np.array([-f[4] / f[2], f[3] / f[2]])
    assert np.allclose(r[:2], [-(cop[0] - 0.01) / X, (cop[1] + 0.02) / Y])
    assert np.allclose(r[2:4], f[:2] / (0.7 * F)) and np.isclose(r[4], f[5] / (0.7 * Y * F))
