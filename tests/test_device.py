"""The simulated Device: integration on the configuration manifold, torque-level
dynamics with and without contacts, bounds, bad inputs and the order of a tick.

Every expected value is computed independently of the device: with Pinocchio's own
functions (exp6, aba, computeGeneralizedGravity, centerOfMass) or in closed form.
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

from sotpy.dynamics.device import Device
from sotpy.errors import (
    CommandError,
    EntityError,
    SignalTypeError,
    SotpyError,
    SotpyWarning,
    UnpluggedError,
)
from sotpy.graph import VECTOR, Entity, Input, Output, plug, pool

FEET = ["left_sole_link", "right_sole_link"]
DT = 1e-3


@pytest.fixture(scope="module")
def talos():
    example_robot_data = pytest.importorskip("example_robot_data")
    return example_robot_data.load("talos")


@pytest.fixture(scope="module")
def panda():
    example_robot_data = pytest.importorskip("example_robot_data")
    return example_robot_data.load("panda")


def panda_q0(robot) -> np.ndarray:
    """Panda's reference posture with the fingers half open (away from their limits)."""
    q = robot.q0.copy()
    q[7:9] = 0.02
    return q


# -- test-only entities ------------------------------------------------------------------
class DeviceTestGravity(Entity):
    """control = g(q), the generalized gravity torques of a fixed-base model."""

    state = Input(VECTOR)

    def __init__(self, name: str, model: pin.Model) -> None:
        self.model = model
        self.data = model.createData()

    @Output(VECTOR, deps=("state",))
    def control(self, q):
        return pin.computeGeneralizedGravity(self.model, self.data, q).copy()


class DeviceTestHold(Entity):
    """Torques holding a floating-base robot still in rigid multi-contact, plus a PD.

    Solves M 0 + b(q, v) = S^T tau + Jc^T f: f by least squares on the 6 base rows
    (``Jc_base^T f = b_base``), then tau from the joint rows; adds
    ``-Kp (q - q_ref) - Kd v`` on the joints.
    """

    state = Input(VECTOR)
    velocity = Input(VECTOR)

    def __init__(self, name, model, q_ref, frames, kp=10.0, kd=1.0):
        self.model, self.data = model, model.createData()
        self.q_ref = q_ref.copy()
        self.frames = [model.getFrameId(f) for f in frames]
        self.kp, self.kd = kp, kd

    @Output(VECTOR, deps=("state", "velocity"))
    def control(self, q, v):
        m, d = self.model, self.data
        b = pin.rnea(m, d, q, v, np.zeros(m.nv))
        pin.computeJointJacobians(m, d, q)
        pin.updateFramePlacements(m, d)
        jc = np.vstack(
            [pin.getFrameJacobian(m, d, f, pin.LOCAL_WORLD_ALIGNED) for f in self.frames]
        )
        f = np.linalg.lstsq(jc[:, :6].T, b[:6], rcond=None)[0]
        tau = b[6:] - jc[:, 6:].T @ f
        return tau - self.kp * (q[7:] - self.q_ref[7:]) - self.kd * v[6:]


class DeviceTestLogger(Entity):
    """``tick`` logs ('name', t) each time it is computed (time-dependent)."""

    def __init__(self, name, log):
        self.log = log

    @Output(VECTOR, withTime=True)
    def tick(self, t):
        self.log.append((self.name, t))
        return np.array([float(t)])


class DeviceTestController(Entity):
    """control = a constant vector; logs the tick and the state it read."""

    state = Input(VECTOR)

    def __init__(self, name, log, u):
        self.log = log
        self.u = np.asarray(u, dtype=float)

    @Output(VECTOR, deps=("state",), withTime=True)
    def control(self, t, q):
        self.log.append(("control", t, q.copy()))
        return self.u.copy()


class DeviceTestSource(Entity):
    """sout = sin (an output a test can make return anything, e.g. NaN)."""

    sin = Input(VECTOR)

    @Output(VECTOR, deps=("sin",))
    def sout(self, x):
        return self.value if hasattr(self, "value") else x


def base_placement(q: np.ndarray) -> pin.SE3:
    return pin.XYZQUATToSE3(q[:7])


def frame_drift(model, q, frames, refs) -> float:
    """Largest |log6(ref^-1 oMf)| component over the frames (m and rad)."""
    data = model.createData()
    pin.framesForwardKinematics(model, data, q)
    return max(
        np.abs(pin.log6(ref.inverse() * data.oMf[model.getFrameId(f)]).vector).max()
        for f, ref in zip(frames, refs, strict=True)
    )


def frame_placements(model, q, frames) -> list[pin.SE3]:
    data = model.createData()
    pin.framesForwardKinematics(model, data, q)
    return [data.oMf[model.getFrameId(f)].copy() for f in frames]


# -- velocity mode -----------------------------------------------------------------------
def test_velocity_mode_base_follows_the_se3_exponential(talos):
    model = talos.model
    dev = Device("dev", model)
    dev.set(talos.q0)
    v = np.zeros(model.nv)
    v[:6] = [0.1, -0.2, 0.05, 0.3, -0.4, 0.5]  # base twist (m/s, rad/s), base frame
    # a few joints with room to move 0.02 rad both ways
    room = np.minimum(
        talos.q0[7:] - model.lowerPositionLimit[7:], model.upperPositionLimit[7:] - talos.q0[7:]
    )
    joints = np.flatnonzero(room > 0.05)[:5]
    assert joints.size == 5
    v[6 + joints] = [0.02, -0.02, 0.01, -0.01, 0.015]
    dev.control.value = v
    n = 1000
    for _ in range(n):
        dev.increment(DT)
    q = dev.state.value
    expected = base_placement(talos.q0) * pin.exp6(pin.Motion(v[:6] * n * DT))
    assert np.abs(base_placement(q).homogeneous - expected.homogeneous).max() < 1e-10
    assert abs(np.linalg.norm(q[3:7]) - 1.0) < 1e-14
    np.testing.assert_allclose(q[7:], talos.q0[7:] + v[6:] * n * DT, atol=1e-12)
    np.testing.assert_array_equal(dev.velocity.value, v)
    assert dev.state.time == n and dev.velocity.time == n
    assert dev.boundsReport()["position"]["count"] == 0


def random_twist_run(talos, n: int, seed: int = 0) -> None:
    """n ticks with a random base twist each tick (|w| up to ~3 rad/s): the quaternion
    stays unit to 1e-12 and the base follows the product of the exponentials."""
    model = talos.model
    rng = np.random.default_rng(seed)
    dev = Device("dev", model)
    dev.set(talos.q0)
    reference = base_placement(talos.q0)
    v = np.zeros(model.nv)
    worst = 0.0
    for _ in range(n):
        v[:3] = rng.uniform(-0.5, 0.5, 3)
        v[3:6] = rng.uniform(-1.7, 1.7, 3)
        dev.control.value = v
        dev.increment(DT)
        reference = reference * pin.exp6(pin.Motion(v[:6] * DT))
        worst = max(worst, abs(np.linalg.norm(dev.state._value[3:7]) - 1.0))
    assert worst <= 1e-12
    q = dev.state.value
    err = np.abs(base_placement(q).homogeneous - reference.homogeneous).max()
    assert err < 1e-9 * max(1.0, n / 1e4)
    np.testing.assert_array_equal(q[7:], talos.q0[7:])


def test_velocity_mode_random_twists_keep_the_quaternion_unit(talos):
    random_twist_run(talos, 10_000)


@pytest.mark.soak
def test_velocity_mode_random_twists_soak(talos):
    random_twist_run(talos, 100_000, seed=1)


# -- acceleration mode -------------------------------------------------------------------
def test_acceleration_mode_is_semi_implicit_euler(panda):
    model = panda.model
    dev = Device("dev", model)
    dev.setControlType("acceleration")
    q0 = panda_q0(panda)
    v0 = np.r_[0.1, -0.1, 0.05, -0.05, 0.1, -0.1, 0.05, 0.005, -0.005]
    a = np.r_[0.5, -0.3, 0.2, 0.4, -0.5, 0.3, -0.2, 0.01, 0.02]
    dev.set(q0)
    dev.setVelocity(v0)
    dev.control.value = a
    n = 200
    for _ in range(n):
        dev.increment(DT)
    # v_k = v0 + k a dt; q_n = q0 + dt sum_{k=1..n} v_k (revolute/prismatic joints)
    v_n = v0 + n * DT * a
    q_n = q0 + n * DT * v0 + a * DT**2 * n * (n + 1) / 2
    np.testing.assert_allclose(dev.velocity.value, v_n, atol=1e-13)
    np.testing.assert_allclose(dev.state.value, q_n, atol=1e-12)
    # the explicit formula q0 + n dt v0 + a (n dt)^2 / 2 differs by a dt^2 n / 2
    assert np.abs(dev.state.value - (q0 + n * DT * v0 + a * (n * DT) ** 2 / 2)).max() > 1e-5


# -- torque mode, fixed base -------------------------------------------------------------
def test_torque_mode_gravity_compensation_keeps_the_arm_still(panda):
    model = panda.model
    q0 = panda_q0(panda)
    dev = Device("dev", model)
    dev.setControlType("torque")
    assert dev.getControlSize() == model.nv
    dev.set(q0)
    grav = DeviceTestGravity("grav", model)
    plug(dev.state, grav.state)
    plug(grav.control, dev.control)
    for _ in range(1000):  # 1 s
        dev.increment(DT)
    assert np.abs(dev.state.value - q0).max() < 1e-6
    assert np.abs(dev.velocity.value).max() < 1e-6
    assert dev.boundsReport()["torque"]["count"] == 0


def test_torque_mode_zero_torque_follows_aba(panda):
    model = panda.model
    q0 = panda_q0(panda)
    v0 = np.r_[0.1, -0.1, 0.05, -0.05, 0.1, -0.1, 0.05, 0.0, 0.0]
    dev = Device("dev", model)
    dev.setControlType("torque")
    dev.set(q0)
    dev.setVelocity(v0)
    dev.control.value = np.zeros(model.nv)
    dev.increment(DT)
    a = pin.aba(model, model.createData(), q0, v0, np.zeros(model.nv))
    assert np.abs(a).max() > 1.0  # the arm does fall
    v1 = v0 + a * DT
    np.testing.assert_allclose(dev.velocity.value, v1, atol=1e-12)
    np.testing.assert_allclose(dev.state.value, q0 + v1 * DT, atol=1e-14)


# -- torque mode, floating base ----------------------------------------------------------
def test_talos_has_the_sole_frames(talos):
    for f in FEET:
        assert talos.model.existFrame(f)


def test_torque_mode_double_support_holds_talos_still(talos):
    model = talos.model
    q0 = talos.q0
    dev = Device("dev", model)
    assert dev.hasFreeFlyer
    dev.setControlType("torque")
    assert dev.getControlSize() == model.nv - 6
    dev.set(q0)
    dev.setContacts(FEET)
    assert dev.getContacts() == FEET
    hold = DeviceTestHold("hold", model, q0, FEET)
    plug(dev.state, hold.state)
    plug(dev.velocity, hold.velocity)
    plug(hold.control, dev.control)
    refs = frame_placements(model, q0, FEET)
    for _ in range(1000):  # 1 s
        dev.increment(DT)
    q = dev.state.value
    assert np.linalg.norm(q[:3] - q0[:3]) < 1e-3
    assert frame_drift(model, q, FEET, refs) < 1e-4
    forces = dev.contactForces()
    assert sorted(forces) == sorted(FEET)
    weight = pin.computeTotalMass(model) * 9.81
    fz = [forces[f][2] for f in FEET]
    assert min(fz) > 0.0
    assert abs(sum(fz) - weight) < 0.01 * weight
    assert all(c["count"] == 0 for c in dev.boundsReport().values())


def test_torque_mode_contacts_do_not_drift_when_the_robot_collapses(talos):
    """Zero torques: Talos sags on its knees (the base drops), the welded feet stay; the
    Baumgarte gains matter (without them the feet drift ten times more)."""
    model = talos.model
    refs = frame_placements(model, talos.q0, FEET)
    drift = {}
    for gains in ((100.0, 20.0), (0.0, 0.0)):
        pool.clear()
        dev = Device("dev", model)
        dev.setControlType("torque")
        dev.set(talos.q0)
        dev.setContacts(FEET)
        dev.setContactGains(*gains)
        dev.control.value = np.zeros(model.nv - 6)
        for _ in range(150):
            dev.increment(DT)
        q = dev.state.value
        assert q[2] < talos.q0[2] - 0.05  # the base dropped by more than 5 cm
        drift[gains] = frame_drift(model, q, FEET, refs)
    assert drift[(100.0, 20.0)] < 2e-5
    assert drift[(0.0, 0.0)] > 5 * drift[(100.0, 20.0)]


def test_torque_mode_floating_base_without_contacts_falls(talos):
    """No contact, zero torques: the centre of mass falls freely. With semi-implicit
    Euler the linear momentum gains m g dt each step, so the CoM height after n steps is
    z0 - g dt^2 n (n + 1) / 2, and it does not move horizontally."""
    model = talos.model
    data = model.createData()
    dev = Device("dev", model)
    dev.setControlType("torque")
    dev.set(talos.q0)
    dev.control.value = np.zeros(model.nv - 6)
    c0 = pin.centerOfMass(model, data, talos.q0).copy()
    n = 100
    for _ in range(n):
        dev.increment(DT)
    c = pin.centerOfMass(model, data, dev.state.value)
    g = -model.gravity.linear[2]
    assert abs(c[2] - (c0[2] - g * DT**2 * n * (n + 1) / 2)) < 1e-9
    assert np.abs(c[:2] - c0[:2]).max() < 1e-12
    assert dev.contactForces() == {}


# -- bounds ------------------------------------------------------------------------------
def test_velocity_clamp_is_used_counted_and_warned_once(panda):
    model = panda.model
    q0 = panda_q0(panda)
    dev = Device("dev", model)
    dev.set(q0)
    limit = model.velocityLimit[0]
    v = np.zeros(model.nv)
    v[0] = limit + 1.0
    dev.control.value = v
    with pytest.warns(SotpyWarning, match=r"Device\(dev\).*velocity.*panda_joint1") as rec:
        dev.increment(DT)
    assert len(rec) == 1
    assert dev.velocity.value[0] == limit
    assert dev.state.value[0] == pytest.approx(q0[0] + limit * DT, abs=1e-15)
    dev.increment(DT)  # counted, not warned again (a warning would be an error here)
    report = dev.boundsReport()
    assert report["velocity"] == {"count": 2, "joints": {"panda_joint1": 2}}
    assert report["torque"]["count"] == report["position"]["count"] == 0
    dev.resetBoundsReport()
    assert dev.boundsReport()["velocity"]["count"] == 0
    with pytest.warns(SotpyWarning, match="velocity"):
        dev.increment(DT)


def test_torque_clamp_is_used_counted_and_warned(panda):
    model = panda.model
    q0 = panda_q0(panda)
    dev = Device("dev", model)
    dev.setControlType("torque")
    dev.set(q0)
    tau = pin.computeGeneralizedGravity(model, model.createData(), q0).copy()
    tau[3] = -(model.effortLimit[3] + 50.0)
    dev.control.value = tau
    with pytest.warns(SotpyWarning, match=r"torque bounds.*panda_joint4") as rec:
        dev.increment(DT)
    assert len(rec) == 1
    used = tau.copy()
    used[3] = -model.effortLimit[3]
    a = pin.aba(model, model.createData(), q0, np.zeros(model.nv), used)
    np.testing.assert_allclose(dev.velocity.value, a * DT, atol=1e-12)
    assert dev.boundsReport()["torque"] == {"count": 1, "joints": {"panda_joint4": 1}}


def test_position_clamp_zeroes_the_pushing_velocity(panda):
    model = panda.model
    q = panda_q0(panda)
    upper = model.upperPositionLimit[1]
    q[1] = upper - 1e-4
    dev = Device("dev", model)
    dev.set(q)
    v = np.zeros(model.nv)
    v[1] = 1.0  # 1 mm of travel in a tick, 0.1 mm of room
    v[2] = 0.5
    dev.control.value = v
    with pytest.warns(SotpyWarning, match=r"position bounds.*panda_joint2"):
        dev.increment(DT)
    assert dev.state.value[1] == upper
    assert dev.velocity.value[1] == 0.0
    assert dev.velocity.value[2] == 0.5
    assert dev.state.value[2] == pytest.approx(q[2] + 0.5 * DT, abs=1e-15)
    assert dev.boundsReport()["position"]["joints"] == {"panda_joint2": 1}


def test_bounds_can_be_overridden_and_are_checked(talos, panda):
    model = panda.model
    dev = Device("dev", model)
    dev.set(panda_q0(panda))
    lo, hi = -0.1 * np.ones(model.nv), 0.1 * np.ones(model.nv)
    dev.setVelocityBounds(lo, hi)
    dev.control.value = 0.05 * np.ones(model.nv)
    dev.increment(DT)  # within the new bounds: no warning
    dev.control.value = 0.2 * np.ones(model.nv)
    with pytest.warns(SotpyWarning, match="velocity"):
        dev.increment(DT)
    np.testing.assert_array_equal(dev.velocity.value, hi)
    with pytest.raises(CommandError, match=r"Device\(dev\)\.setVelocityBounds.*size 9"):
        dev.setVelocityBounds(lo[:3], hi[:3])
    with pytest.raises(CommandError, match="lower > upper"):
        dev.setVelocityBounds(hi, lo)
    with pytest.raises(CommandError, match="setPositionBounds"):
        dev.setPositionBounds(np.zeros(3), np.ones(3))
    np.testing.assert_array_equal(dev.getVelocityBounds()[1], hi)
    # free-flyer: torque bounds of size nv - 6 or nv; position bounds skip the base
    tal = Device("tal", talos.model)
    nv = talos.model.nv
    tal.setTorqueBounds(-np.ones(nv - 6), np.ones(nv - 6))
    tal.setTorqueBounds(-2 * np.ones(nv), 2 * np.ones(nv))
    np.testing.assert_array_equal(tal.getTorqueBounds()[1], 2 * np.ones(nv - 6))
    with pytest.raises(CommandError, match=f"size {nv - 6} or {nv}"):
        tal.setTorqueBounds(np.zeros(5), np.ones(5))
    lo_q, hi_q = tal.getPositionBounds()
    assert np.isinf(lo_q[:7]).all() and np.isinf(hi_q[:7]).all()
    np.testing.assert_array_equal(hi_q[7:], talos.model.upperPositionLimit[7:])
    assert np.isinf(tal.getVelocityBounds()[1][:6]).all()


# -- bad input ---------------------------------------------------------------------------
def snapshot(dev):
    return dev.state.value.copy(), dev.velocity.value.copy(), dev.state.time, dev.velocity.time


def assert_unchanged(dev, before):
    q, v, tq, tv = before
    np.testing.assert_array_equal(dev.state.value, q)
    np.testing.assert_array_equal(dev.velocity.value, v)
    assert (dev.state.time, dev.velocity.time) == (tq, tv)


def test_wrong_control_size_is_refused(panda):
    dev = Device("dev", panda.model)
    dev.set(panda_q0(panda))
    dev.control.value = np.zeros(7)
    before = snapshot(dev)
    with pytest.raises(SignalTypeError, match=r"Device\(dev\)::input\(vector\)::control.*size 9"):
        dev.increment(DT)
    assert_unchanged(dev, before)


def test_nan_control_is_never_integrated(talos):
    model = talos.model
    dev = Device("dev", model)
    dev.setControlType("torque")
    dev.set(talos.q0)
    src = DeviceTestSource("src")
    src.sin.value = np.zeros(model.nv - 6)
    plug(src.sout, dev.control)
    dev.increment(DT)
    before = snapshot(dev)
    bad = np.zeros(model.nv - 6)
    bad[2] = np.nan
    src.value = bad
    src.sout.setReady()
    with pytest.raises(
        SignalTypeError, match=r"Device\(dev\).*control.*non-finite.*leg_left_3_joint"
    ):
        dev.increment(DT)
    assert_unchanged(dev, before)


def test_diverging_simulation_raises_and_keeps_the_state(talos):
    dev = Device("dev", talos.model)
    dev.setControlType("acceleration")
    dev.set(talos.q0)
    dev.control.value = np.full(talos.model.nv, 1e300)
    dev.setVelocityBounds(np.full(talos.model.nv, -np.inf), np.full(talos.model.nv, np.inf))
    before = snapshot(dev)
    with pytest.raises(SotpyError, match=r"Device\(dev\).*diverged"):
        dev.increment(1e10)
    assert_unchanged(dev, before)


def test_unplugged_control_raises_unplugged_error(panda):
    dev = Device("dev", panda.model)
    before = snapshot(dev)
    with pytest.raises(UnpluggedError, match="control"):
        dev.increment(DT)
    src = DeviceTestSource("src")
    plug(src.sout, dev.control)
    with pytest.raises(UnpluggedError) as info:
        dev.increment(DT)
    assert info.value.signals == [src.sin.name]
    assert_unchanged(dev, before)


def test_control_types_and_aliases(talos, panda):
    dev = Device("dev", panda.model)
    assert dev.getControlType() == "velocity"
    with pytest.raises(CommandError, match=r"'velocity', 'acceleration', 'torque'"):
        dev.setControlType("position")
    with pytest.raises(CommandError, match=r"noInteg.*not simulated"):
        dev.setControlType("noInteg")
    assert dev.getControlType() == "velocity"
    dev.setControlType("twoInteg")
    assert dev.getControlType() == "acceleration"
    dev.setControlInputType("oneInteg")
    assert dev.getControlType() == "velocity"
    dev.setControlType("torque")
    assert dev.getControlSize() == panda.model.nv  # fixed base: every joint actuated
    with pytest.raises(CommandError):
        dev.setControlType(3)


def test_set_checks_normalises_and_invalidates(talos):
    model = talos.model
    dev = Device("dev", model)
    np.testing.assert_array_equal(dev.state.value, pin.neutral(model))
    reader = DeviceTestSource("reader")
    plug(dev.state, reader.sin)
    before = snapshot(dev)
    with pytest.raises(CommandError, match=rf"Device\(dev\)\.set.*nq = {model.nq}"):
        dev.set(np.zeros(model.nq - 2))  # (nq - 1 = nv is SoT's roll-pitch-yaw size)
    zero_quat = talos.q0.copy()
    zero_quat[3:7] = 0.0
    with pytest.raises(CommandError, match="quaternion"):
        dev.set(zero_quat)
    with pytest.raises(CommandError):
        dev.setVelocity(np.zeros(3))
    assert_unchanged(dev, before)
    pool.advance(5)
    assert reader.sout.value[2] == 0.0  # neutral base height, computed at tick 5
    q = talos.q0.copy()
    q[3:7] = [0.0, 0.0, 0.6, 0.8]
    q[3:7] *= 3.0
    dev.set(q)
    assert dev.state.time == 5
    np.testing.assert_allclose(dev.state.value[3:7], [0.0, 0.0, 0.6, 0.8], atol=1e-15)
    assert reader.sout.value[2] == talos.q0[2]  # same tick, recomputed
    with pytest.raises(EntityError, match=r"pinocchio\.Model"):
        Device("other", "talos")
    with pytest.raises(CommandError, match="dt"):
        dev.increment(0.0)
    with pytest.raises(CommandError, match="not a frame"):
        dev.setContacts(["no_such_frame"])
    with pytest.raises(CommandError, match="twice"):
        dev.setContacts([FEET[0], FEET[0]])
    with pytest.raises(SotpyError, match="getTimeStep"):
        dev.getTimeStep()


# -- the order of a tick -----------------------------------------------------------------
def test_increment_order_and_ticks(panda):
    model = panda.model
    log: list = []
    dev = Device("dev", model)
    q0 = panda_q0(panda)
    dev.set(q0)
    u = np.full(model.nv, 0.01)
    ctrl = DeviceTestController("ctrl", log, u)
    plug(dev.state, ctrl.state)
    plug(ctrl.control, dev.control)
    before = DeviceTestLogger("before", log)
    after = DeviceTestLogger("after", log)
    dev.before.addSignal(before.tick)
    dev.after.addSignal(after.tick)
    states = [dev.state.value.copy()]
    for k in range(3):
        dev.increment(DT)
        assert dev.state.time == k + 1 and dev.velocity.time == k + 1
        assert pool.time == k + 1
        states.append(dev.state.value.copy())
    names = [e[0] for e in log]
    assert names == ["before", "control", "after"] * 3
    assert [e[1] for e in log] == [0, 0, 1, 1, 1, 2, 2, 2, 3]
    for k, entry in enumerate(e for e in log if e[0] == "control"):
        np.testing.assert_array_equal(entry[2], states[k])  # the state at t, not t + 1
    np.testing.assert_allclose(states[3], q0 + 3 * DT * u, atol=1e-15)
    assert dev.getTimeStep() == DT


def test_compiled_step_checks_are_their_numpy_twins():
    """The step's per-tick checks (compiled with numba) against the NumPy expressions
    they replace: entries below, above, at the bounds, NaN, infinite, infinite bounds."""
    from sotpy.dynamics import device as dev

    rng = np.random.default_rng(3)
    specials = [np.nan, np.inf, -np.inf, 1.0, -1.0]
    for trial in range(300):
        n = int(rng.integers(1, 12))
        lo = rng.uniform(-1.0, 0.0, n)
        hi = rng.uniform(0.0, 1.0, n)
        lo[rng.random(n) < 0.2] = -np.inf
        hi[rng.random(n) < 0.2] = np.inf
        x = rng.uniform(-1.2, 1.2, n) * (trial % 3 != 0)  # a third: all zero, inside
        k = int(rng.integers(0, n))
        if trial % 4 == 1:
            x[k] = specials[trial % len(specials)]
        if trial % 5 == 2:
            x[k] = lo[k]  # at the bound: inside
        assert dev._inside_c(x, lo, hi) == dev._inside_np(x, lo, hi)
        assert dev._finite_c(x) == dev._finite_np(x)
    assert dev._inside_c(np.array([np.nan]), np.zeros(1), np.ones(1))  # as the comparisons
    assert not dev._finite_c(np.array([0.0, np.inf]))


# -- SoT's names: RobotSimu, resize, zmp, setTimeStep, roll-pitch-yaw configurations --
def test_sot_names_of_the_device(talos):
    from sotpy.dynamics import RobotSimu

    model = talos.model
    d = RobotSimu("rs", model)
    assert isinstance(d, Device) and d.className == "RobotSimu"
    with pytest.raises(EntityError, match=r"RobotSimu\(bare\): a simulated device needs"):
        RobotSimu("bare")
    d.resize(model.nv)  # SoT scripts size the device: the model's sizes are accepted
    d.resize(model.nq)
    with pytest.raises(CommandError, match=r"nq = 39, nv = 38\), got 12"):
        d.resize(12)
    np.testing.assert_array_equal(d.zmp.value, np.zeros(3))
    d.zmp.value = (0.01, -0.02, 0.0)  # an input for a real robot's stabiliser
    with pytest.raises(SotpyError, match="increment has not been called yet"):
        d.getTimeStep()
    d.setTimeStep(0.005)
    assert d.getTimeStep() == 0.005
    with pytest.raises(CommandError, match="dt must be a finite value > 0"):
        d.setTimeStep(0.0)


def test_device_set_takes_sots_roll_pitch_yaw_configuration(talos):
    model = talos.model
    d = Device("d", model)
    rng = np.random.default_rng(6)
    q_sot = np.r_[
        rng.uniform(-1, 1, 3), rng.uniform(-1, 1, 3), rng.uniform(-0.2, 0.2, model.nv - 6)
    ]
    d.set(q_sot)  # size nv: x, y, z, roll, pitch, yaw, joints
    q = d.state.value
    assert q.shape == (model.nq,)
    np.testing.assert_allclose(q[:3], q_sot[:3])
    np.testing.assert_allclose(q[7:], q_sot[6:])
    R = pin.Quaternion(q[3:7]).toRotationMatrix()  # (x, y, z, w)
    Rz, Ry, Rx = (pin.utils.rotate(a, x) for a, x in zip("zyx", q_sot[5:2:-1], strict=True))
    np.testing.assert_allclose(R, Rz @ Ry @ Rx, atol=1e-12)  # R = Rz(yaw) Ry(pitch) Rx(roll)
    with pytest.raises(CommandError, match=r"nq = 39 \(or SoT's nv = 38, roll-pitch-yaw\)"):
        d.set(np.zeros(10))
