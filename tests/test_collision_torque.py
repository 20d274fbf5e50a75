"""The acceleration-level collision constraint of the torque-level controller: its drift
against finite differences, its bound, bad input, and a torque loop that stops short of
an obstacle."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

from sotpy.dynamics import load_robot
from sotpy.errors import SotpyError
from sotpy.graph import plug
from sotpy.solvers.controller import Controller
from sotpy.solvers.wbc.collision import CollisionConstraint
from sotpy.solvers.wbc.model import RobotModel

RNG = np.random.default_rng(7)


def _sphere_pair(r):
    """A constraint on one pair: a sphere on the right wrist against one in the world."""
    model = r.model
    rm = RobotModel(model)
    c = CollisionConstraint("cc", rm, r.collision_model, influence=0.3, safety=0.0)
    wrist = model.getFrameId("arm_right_7_joint")
    data = model.createData()
    pin.framesForwardKinematics(model, data, r.halfSitting)
    centre0 = data.oMf[wrist].act(np.array([0.0, 0.0, -0.1]))
    ball = centre0 + np.array([0.06, -0.05, 0.03])
    P = c.pairs
    P.addObstacle("hand", "sphere", 0.02, (0.0, 0.0, -0.1), frame="arm_right_7_joint")
    P.addObstacle("ball", "sphere", 0.01, ball)
    P.clearPairs()
    P.addPair("hand", "ball")
    return rm, c, wrist, ball


def test_drift_matches_the_second_derivative_of_a_sphere_pair():
    r = load_robot("talos", prefix="acc")
    model = r.model
    rm, c, wrist, ball = _sphere_pair(r)
    data = model.createData()

    def centre(q):
        pin.framesForwardKinematics(model, data, q)
        return data.oMf[wrist].act(np.array([0.0, 0.0, -0.1]))

    q0 = r.halfSitting
    for _ in range(3):
        v, a = RNG.normal(size=model.nv) * 0.5, RNG.normal(size=model.nv)
        rm.update(q0, v)
        assert c.count(rm, None) == 1
        predicted = float(c.pairs.rowJ[0] @ a + c.drift(rm)[0])
        # d(t) = |c(t) - ball| - 0.03 along q0 (+) (v t + a t^2 / 2): its acceleration at 0
        eps = 1e-3

        def d(t, v=v, a=a):
            return np.linalg.norm(centre(pin.integrate(model, q0, v * t + a * t * t / 2)) - ball)

        fd = (d(eps) - 2 * d(0.0) + d(-eps)) / eps**2
        # what the constraint neglects, for two spheres: the normal's rate, |v_t|^2 / D,
        # and the witness point's motion on the hand's sphere of radius 0.02 (the
        # rotation's centripetal term along n, -0.02 |w_perp|^2, is in the prediction)
        cv = (
            centre(pin.integrate(model, q0, v * 1e-6)) - centre(pin.integrate(model, q0, -v * 1e-6))
        ) / 2e-6
        u = centre(q0) - ball
        D = np.linalg.norm(u)
        n = u / D
        vt = cv - (cv @ n) * n
        pin.forwardKinematics(model, data, q0, v)
        w = pin.getFrameVelocity(model, data, wrist, pin.LOCAL_WORLD_ALIGNED).angular
        w_perp = w - (w @ n) * n
        exact = predicted + vt @ vt / D - 0.02 * (w_perp @ w_perp)
        assert exact == pytest.approx(fd, abs=1e-4 * (1 + abs(fd)))
        assert predicted != pytest.approx(fd, abs=1e-4 * (1 + abs(fd)))  # it is neglected


def test_bound_is_the_damper_one_horizon_ahead():
    r = load_robot("talos", prefix="acc")
    rm, c, _, _ = _sphere_pair(r)
    v = RNG.normal(size=r.model.nv) * 0.3
    rm.update(r.halfSitting, v)
    c.count(rm, None)
    d, ddot = c.pairs.rowD[0], c.pairs.rowJ[0] @ v
    k = c.gain / (c.influence - c.safety)
    h = c.horizon
    expected = (-k * (d - c.safety) - (1 + k * h) * ddot) / h - c.drift(rm)[0]
    assert c.bounds(rm)[0] == pytest.approx(expected)
    # met with equality, the damper holds one horizon ahead (to first order)
    dddot = expected + c.drift(rm)[0]
    assert ddot + h * dddot == pytest.approx(-k * (d + h * ddot - c.safety))


def test_bad_settings_are_refused_and_add_nothing():
    r = load_robot("panda", prefix="bad")
    ctrl = Controller("ctrl_bad", r.dynamic)
    with pytest.raises(SotpyError, match=r"addCollisionAvoidance.*safety distance d_s >= 0"):
        ctrl.addCollisionAvoidance("coll", r.collision_model, None, 0.05, -0.01)
    with pytest.raises(SotpyError, match=r"horizon h > 0"):
        ctrl.addCollisionAvoidance("coll", r.collision_model, None, 0.0)
    with pytest.raises(SotpyError, match=r"no collision constraint named 'coll'"):
        ctrl.getCollisionPairs("coll")


def test_torque_loop_stops_the_hand_short_of_an_obstacle():
    def run(avoid):
        from sotpy.graph.pool import pool

        pool.clear()
        r = load_robot("panda", prefix="tq")
        ctrl = Controller("ctrl", r.dynamic)
        ctrl.addCartesianTask("ee", "panda_hand_tcp", 1.0, 0)
        ctrl.addRegularisationTask("reg", 1e-4, 0)
        ctrl.addTorqueLimits("tau")
        ctrl.addJointVelocityLimits("vlim", 0.05)
        ctrl.addJointPositionLimits("qlim", 0.05)
        if avoid:
            ctrl.addCollisionAvoidance("coll", r.collision_model, None, 0.05, 0.02, 0.08, 0.3)
            pairs = ctrl.getCollisionPairs("coll")
            pairs.clearPairs()
        else:
            from sotpy.tasks.collision import CollisionPairs

            pairs = CollisionPairs(r.model, r.collision_model)
            pairs.clearPairs()
        data = r.model.createData()
        fid = r.model.getFrameId("panda_hand_tcp")
        pin.framesForwardKinematics(r.model, data, r.device.state.value)
        ball = data.oMf[fid].translation + np.array([0.10, 0.0, 0.0])
        pairs.addObstacle("ball", "sphere", 0.04, ball)
        # not the fingers: they rest on their joint limits, and a collision row that can
        # only be met by moving them past a limit makes the QP infeasible
        for name in pairs.listPairs():
            if "finger" in name:
                pairs.removePair(*name.split(" : "))
        ctrl.activateTasksAndConstraints()
        r.device.setControlType("torque")
        plug(ctrl.torque, r.device.control)
        ctrl.ee.value = np.array([1.5, 0.0, 0.0, 0.0, 0.0, 0.0])  # m/s^2 into the ball
        lowest = np.inf
        for _ in range(350):
            r.device.increment(0.001)
            d = pin.Data(r.model)
            pin.computeJointJacobians(r.model, d, r.device.state.value)
            lowest = min(lowest, float(pairs.distances(d).min()))
        assert ctrl.solutionFound.value
        return lowest

    free, avoided = run(False), run(True)
    assert free < 0.0  # without the constraint the hand goes into the ball
    assert avoided >= 0.02 - 1e-3
