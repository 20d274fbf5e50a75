"""Transitions that are smooth in torque: the activation ramps' shape, the torque-rate
bound of transitions (activation, deactivation, re-activation, a strategy switch at run
time), its fallback, and the warnings when nothing holds the robot. The torques are
those sent to the simulated robot (Talos on the floor, in closed loop); the bound is
the documented one, rebuilt here from the model's effort limits."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from sotpy.dynamics import load_robot
from sotpy.dynamics.contact import Floor
from sotpy.errors import SotpyError, SotpyWarning
from sotpy.solvers.wbc import (
    RAMP_FLOOR,
    CartesianAccelerationTask,
    CoMAccelerationTask,
    ContactSpec,
    JointAccelerationTask,
    JointTorqueLimit,
    WholeBodyController,
    ramp_weight,
)

DT = 1e-3
RATE_TIME = 0.1  # docs/torque-control.md: the default bound, each effort limit per 0.1 s
HAND = "arm_right_7_joint"


def test_ramp_weight_is_smooth_and_spread_over_its_decades():
    r = np.linspace(0.0, 1.0, 2001)
    rho = np.array([ramp_weight(x) for x in r])
    assert rho[0] == 0.0 and rho[-1] == 1.0
    assert np.all(np.diff(rho) > 0)  # increasing
    h = 1e-6  # flat at both ends (smoothstep)
    assert ramp_weight(h) / h < 1e-3 and (1.0 - ramp_weight(1.0 - h)) / h < 1e-3
    # in the logarithm: at mid-ramp the weight is half-way through its decades
    assert ramp_weight(0.5) == pytest.approx(0.5 * RAMP_FLOOR**0.5)
    logs = np.log10(rho[1:-1])
    assert logs.min() < -6 and np.all(np.diff(logs) > 0)


class TalosOnFloor:
    """Talos on the floor in closed loop, with a CoM task (weight 10, held), a posture
    (1e-2), torque limits and two 6-D contacts (feedback on), driven tick by tick by the
    core controller (no graph); ``hand``: a right-wrist task (weight 10) pulled 7 cm away
    when active."""

    def __init__(self, prefix: str, strategy: str = "OneLevelWeighted") -> None:
        robot = load_robot("talos", prefix=prefix)
        m = robot.model
        q = robot.device.state.value.copy()
        for j in ("leg_left_6_joint", "leg_right_6_joint"):  # flat soles
            q[m.joints[m.getJointId(j)].idx_q] = 0.0
        iq = m.nq - (m.nv - 6)
        q[iq:] = np.clip(q[iq:], m.lowerPositionLimit[iq:] + 1e-3, m.upperPositionLimit[iq:] - 1e-3)
        self.model, self.device = m, robot.device
        self.device.set(q)
        self.device.setControlType("torque")
        self.device.setFloor(list(robot.feet.values()), Floor())
        self.feet = list(robot.feet.values())
        w = self.wbc = self.controller(strategy)
        self.com, self.post, self.hand = (w.tasks[k] for k in ("com", "post", "hand"))
        self.qref = q[7:].copy()
        self.fid = m.getFrameId(HAND)
        self.com0 = self.target = None
        self.torques: list[np.ndarray] = []
        self.limited: list[bool] = []
        self.bound = m.effortLimit[6:] / RATE_TIME * DT

    def controller(self, strategy: str) -> WholeBodyController:
        """The controller, its CoM task, posture and torque limits active."""
        w = WholeBodyController(self.model, strategy)
        w.setContacts(
            [
                ContactSpec(f.frame, 6, 0.5, f.length, f.width, f.offset[:2], 40.0, 0.01, 8, 100.0)
                for f in self.feet
            ]
        )
        w.addTask(CoMAccelerationTask("com", 10.0))
        w.addTask(JointAccelerationTask("post", w.robot.na, 1e-2))
        w.addTask(CartesianAccelerationTask("hand", HAND, 10.0)).setRampDuration(0.05)
        w.addConstraint(JointTorqueLimit("tau", w.robot))
        for name in ("com", "post", "tau"):
            w.activate(name)
        return w

    def run(self, ticks: int) -> None:
        w, dev = self.wbc, self.device
        for _ in range(ticks):
            q, v = dev.state.value, dev.velocity.value
            w.robot.update(q, v)
            if self.com0 is None:
                self.com0 = w.robot.com.copy()
            self.com.setDesired(-100 * (w.robot.com - self.com0) - 20 * w.robot.com_velocity)
            self.post.setDesired(-25 * (q[7:] - self.qref) - 10 * v[6:])
            M = w.robot.frame_placement(self.fid)
            if self.target is None:
                self.target = M.translation + np.array([0.05, 0.0, 0.05])
            e = np.concatenate([M.translation - self.target, np.zeros(3)])
            self.hand.setDesired(-100 * e - 20 * w.robot.frame_velocity(self.fid))
            sol = w.tick(len(self.torques) * DT, DT)
            assert sol.found, sol.reason
            self.torques.append(sol.tau.copy())
            self.limited.append(sol.rate_limited)
            dev.control.value = sol.tau
            dev.increment(DT)

    def steps(self, k0: int, k1: int) -> np.ndarray:
        """|tau_k - tau_{k-1}| for the ticks k0..k1-1 (n x na, N m)."""
        tau = np.array(self.torques)
        return np.abs(np.diff(tau[k0 - 1 : k1], axis=0))


def test_activation_deactivation_reactivation_are_bounded_in_torque():
    """The issue's case, a weight-10 task ramped in over a 1e-2 posture in 50 ticks: the
    torques move by at most the documented bound per tick (a linear ramp without it sent
    55 N m in one tick here, 28 N m on re-activation), and the transition ends."""
    sim = TalosOnFloor("ramp_a")
    sim.run(100)
    assert not sim.wbc.transition  # the start's transition has settled
    for event in ("activate", "deactivate", "activate"):
        k0 = len(sim.torques)
        getattr(sim.wbc, event)("hand")
        assert sim.wbc.transition
        sim.run(200)
        steps = sim.steps(k0, k0 + 200)
        assert np.all(steps <= sim.bound * (1 + 1e-9)), (event, (steps / sim.bound).max())
        assert all(sim.limited[k0 : k0 + 50])  # the rate rows during the ramp
        assert not sim.wbc.transition and not sim.limited[-1]  # settled, rows gone
        assert steps.sum(axis=0).max() > 10.0  # the task did move the torques


def test_the_ramp_shape_alone_spreads_the_torque_change():
    """Without the rate bound, the smooth ramp spreads the change over its ticks: no tick
    carries more than 15 % of a joint's change (a linear ramp: 58 to 71 %)."""
    sim = TalosOnFloor("ramp_b")
    sim.wbc.setTorqueRateLimit(np.inf)
    sim.run(100)
    k0 = len(sim.torques)
    sim.wbc.activate("hand")
    sim.run(60)
    steps = sim.steps(k0, k0 + 50)
    total = steps.sum(axis=0)
    j = np.argmax(total)
    assert total[j] > 10.0 and steps[:, j].max() / total[j] < 0.15
    assert not any(sim.limited[k0:])


def test_a_strategy_switch_at_run_time_is_bounded_in_torque():
    sim = TalosOnFloor("ramp_s")
    sim.run(60)
    k0 = len(sim.torques)
    sim.wbc.setStrategy("MultiLevelWeighted")
    assert sim.wbc.transition
    sim.run(60)
    assert np.all(sim.steps(k0, k0 + 60) <= sim.bound * (1 + 1e-9))
    assert sim.limited[k0]
    sim.run(60)
    assert not sim.wbc.transition
    # settled: the torque is the hierarchy's own answer at this state (a fresh
    # controller, without a previous torque to move from, the same rows: the desired
    # values, the loads of the wrench cost, the contacts' references)
    w = sim.wbc
    fresh = sim.controller("MultiLevelWeighted")
    for name, t in w.tasks.items():
        fresh.tasks[name].setDesired(t.desired)
    fresh.contact_cost.loads = dict(w.contact_cost.loads)
    for name, st in w.contact_states.items():
        fresh.contact_states[name].reference = st.reference
    q, v = sim.device.state.value, sim.device.velocity.value
    ours = w.update(q, v, 0.0, DT)
    theirs = fresh.update(q, v, 0.0, DT)
    assert ours.found and theirs.found and not ours.rate_limited
    assert np.abs(ours.tau - theirs.tau).max() < 1e-6 * (1 + np.abs(theirs.tau).max())


def test_rate_rows_that_cannot_be_met_are_dropped():
    """A torque limit activated below the present torque: the bound and the limit
    conflict; the weighted strategy solves without the rate rows (and says so)."""
    sim = TalosOnFloor("ramp_c")
    sim.run(30)
    w = sim.wbc
    tau = sim.torques[-1]
    j = int(np.argmax(np.abs(tau)))
    lo, hi = -np.abs(sim.model.effortLimit[6:]), np.abs(sim.model.effortLimit[6:])
    lo[j], hi[j] = -0.5, 0.5  # the joint of the largest torque must drop near 0 at once
    w.addConstraint(JointTorqueLimit("tight", w.robot, lo, hi)).activate()  # a ramp: rate rows
    sim.run(1)
    assert not sim.limited[-1] and abs(sim.torques[-1][j]) <= 0.5 + 1e-9


def test_a_tick_without_a_solution_steps_from_the_last_torque_towards_gravity():
    """The fallback of a tick without a solution (here the QP made to fail): from the
    torques sent at the tick before, at most the rate bound per tick towards gravity
    compensation ``S g(q)`` (Pinocchio's generalised gravity, computed here); ``S g``
    itself with no previous torque or no rate bound."""
    import pinocchio as pin

    sim = TalosOnFloor("ramp_f")
    sim.run(60)
    w, dev = sim.wbc, sim.device
    w._weighted = lambda *a: (None, False, "forced for the test")
    data = sim.model.createData()
    prev = sim.torques[-1]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", SotpyWarning)  # "no solution", said once
        for _ in range(5):
            q, v = dev.state.value.copy(), dev.velocity.value.copy()
            sol = w.update(q, v, 0.0, DT)
            assert not sol.found and sol.reason == "forced for the test"
            g = pin.computeGeneralizedGravity(sim.model, data, q)[6:]
            expected = prev + np.clip(g - prev, -sim.bound, sim.bound)
            np.testing.assert_allclose(sol.tau, expected, rtol=0, atol=1e-9)
            assert np.abs(sol.tau - prev).max() <= sim.bound.max() * (1 + 1e-12)
            assert np.abs(g - prev).max() > 2 * sim.bound.max()  # the step is the bound's
            prev = sol.tau.copy()
            dev.control.value = sol.tau
            dev.increment(DT)
        # no rate bound, or no previous torque: gravity compensation at once
        w.setTorqueRateLimit(np.inf)
        q, v = dev.state.value.copy(), dev.velocity.value.copy()
        g = pin.computeGeneralizedGravity(sim.model, data, q)[6:]
        np.testing.assert_allclose(w.update(q, v, 0.0, DT).tau, g, rtol=0, atol=1e-9)
        fresh = sim.controller("OneLevelWeighted")
        fresh._weighted = w._weighted
        np.testing.assert_allclose(fresh.update(q, v, 0.0, DT).tau, g, rtol=0, atol=1e-9)


def test_rate_limit_settings_are_checked():
    w = WholeBodyController(load_robot("talos", prefix="ramp_d").model)
    with pytest.raises(SotpyError, match="torque rate limit"):
        w.setTorqueRateLimit(-1.0)
    with pytest.raises(SotpyError, match="torque rate limit"):
        w.setTorqueRateLimit(np.ones(3))
    w.setTorqueRateLimit(200.0)
    assert np.all(w.torque_rate == 200.0)


def test_warnings_when_nothing_holds_the_robot():
    robot = load_robot("talos", prefix="ramp_w")
    model = robot.model
    q, v = robot.halfSitting.copy(), np.zeros(model.nv)
    w = WholeBodyController(model)
    com = w.addTask(CoMAccelerationTask("com", 1.0))
    com.activate()
    with pytest.warns(SotpyWarning, match="no contact is active: the floating base"):
        w.update(q, v)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        w.update(q, v)  # once per streak
    w.setContacts([ContactSpec(f.frame, 6, 0.5, f.length, f.width) for f in robot.feet.values()])
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        w.update(q, v)  # held: no warning
    for f in robot.feet.values():
        w.deactivate(f.frame)
    w.contact_states["left_sole_link"].setRampDuration(0.0)
    while any(st.state != "inactive" for st in w.contact_states.values()):
        w.update(q, v)
    with pytest.warns(SotpyWarning, match="floating base is unconstrained"):
        w.update(q, v)  # a new streak
    com.deactivate()
    with pytest.warns(SotpyWarning, match="nothing is active"):
        w.update(q, v)
        w.update(q, v)
