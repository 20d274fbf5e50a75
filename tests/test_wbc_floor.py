"""The floor of the Device's torque mode (sotpy.dynamics.contact, MuJoCo), against
independent computations: Pinocchio's own mass matrix and forward dynamics, statics,
Coulomb's law of sliding, the tipping threshold of a box; and its refusals of bad
input."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

from sotpy.dynamics import Device, load_robot
from sotpy.dynamics.contact import Floor, FloorSimulator, FootPatch
from sotpy.errors import CommandError, ContactError

G = 9.81
MASS, SIZE = 10.0, (0.2, 0.1, 0.1)  # a box: kg, m (length x width x height)
DT = 1e-3


def box_model(top: float = 0.5) -> pin.Model:
    """A free box of MASS and SIZE; frames: "centre" (its centre of mass), "sole" (the
    centre of its bottom face, z up) and "top" (``top`` m above the sole)."""
    model = pin.Model()
    model.gravity.linear = np.array([0.0, 0.0, -G])
    jid = model.addJoint(0, pin.JointModelFreeFlyer(), pin.SE3.Identity(), "root")
    model.appendBodyToJoint(jid, pin.Inertia.FromBox(MASS, *SIZE), pin.SE3.Identity())
    for name, z in (("centre", 0.0), ("sole", -SIZE[2] / 2), ("top", top - SIZE[2] / 2)):
        placement = pin.SE3(np.eye(3), np.array([0.0, 0.0, z]))
        model.addFrame(pin.Frame(name, jid, placement, pin.FrameType.OP_FRAME))
    return model


def box_on_floor(floor: Floor, name: str = "box", settle: int = 200) -> Device:
    """The box resting on ``floor`` (its four bottom corners), settled for ``settle``
    ticks with no torque (it has none: it is not actuated)."""
    model = box_model()
    dev = Device(name, model)
    dev.setControlType("torque")
    dev.control.value = np.zeros(0)
    q = pin.neutral(model)
    q[2] = SIZE[2] / 2
    dev.set(q)
    dev.setFloor([FootPatch("sole", SIZE[0], SIZE[1])], floor)
    for _ in range(settle):
        dev.increment(DT)
    return dev


def _run(dev: Device, ticks: int) -> np.ndarray:
    out = []
    for _ in range(ticks):
        dev.increment(DT)
        out.append(dev.state.value.copy())
    return np.array(out)


def _angle(q0: np.ndarray, q1: np.ndarray) -> float:
    R0 = pin.Quaternion(q0[6], *q0[3:6]).toRotationMatrix()
    R1 = pin.Quaternion(q1[6], *q1[3:6]).toRotationMatrix()
    return float(np.linalg.norm(pin.log3(R0.T @ R1)))


# -- the model MuJoCo simulates is Pinocchio's ---------------------------------------
@pytest.fixture(scope="module")
def talos_sim():
    robot = load_robot("talos", prefix="floor_talos")
    patches = [FootPatch.from_foot(f) for f in robot.feet.values()]
    return robot, FloorSimulator(robot.model, patches, Floor())


def test_mujoco_model_has_pinocchio_mass_matrix_and_dynamics(talos_sim):
    robot, sim = talos_sim
    model = robot.model
    data = model.createData()
    rng = np.random.default_rng(3)
    q = pin.integrate(model, robot.halfSitting, rng.normal(size=model.nv) * 0.3)
    M = pin.crba(model, data, q)
    M = np.triu(M) + np.triu(M, 1).T
    assert np.allclose(sim.mass_matrix(q), M, atol=1e-10 * np.abs(M).max())
    # forward dynamics in the air (1 m up: no contact), MuJoCo's qacc in Pinocchio's
    # convention: the base's linear acceleration in MuJoCo is the origin's, in world
    # axes; Pinocchio's is the spatial one, in the base frame: a = R^T a_w - w x v
    q[2] += 1.0
    v = rng.normal(size=model.nv)
    tau = rng.normal(size=model.nv) * 5.0
    tau[:6] = 0.0
    import mujoco

    qpos, qvel = sim.to_mujoco(q, v)
    sim.mjdata.qpos[:] = qpos
    sim.mjdata.qvel[:] = qvel
    sim.mjdata.qfrc_applied[:] = tau
    mujoco.mj_forward(sim.mjmodel, sim.mjdata)
    assert sim.mjdata.ncon == 0
    qacc = np.array(sim.mjdata.qacc)
    R = pin.Quaternion(q[6], *q[3:6]).normalized().toRotationMatrix()
    a = qacc.copy()
    a[:3] = R.T @ qacc[:3] - np.cross(v[3:6], v[:3])
    a_pin = pin.aba(model, data, q, v, tau)
    assert np.allclose(a, a_pin, atol=1e-8 * (1 + np.abs(a_pin).max()))
    # and the state conversions are inverse of each other
    q2, v2 = sim.from_mujoco(qpos, qvel)
    assert np.allclose(q2, q) and np.allclose(v2, v)


# -- contacts: statics, unilateral, Coulomb, tipping, stiffness -----------------------
def test_resting_box_carries_its_weight_on_its_corners():
    dev = box_on_floor(Floor())
    for _ in range(50):
        dev.increment(DT)
    w = dev.contactForces()["sole"]  # world axes, at the sole's centre
    # statics: the floor carries the weight, no horizontal force, the CoP at the centre
    assert w[2] == pytest.approx(MASS * G, rel=1e-6)
    assert np.abs(w[[0, 1, 3, 4, 5]]).max() < 1e-4 * MASS * G
    points = dev.contactPoints()
    assert len(points) == 4 and all(p.force[2] > 0 for p in points)
    assert np.allclose(sum(p.force for p in points), w[:3])
    assert np.allclose([p.force[2] for p in points], MASS * G / 4, rtol=1e-3)
    assert abs(dev.state.value[2] - SIZE[2] / 2) < 1e-4  # it sinks by micrometres


def test_unilateral_a_pulled_box_lifts_without_being_held():
    dev = box_on_floor(Floor(), "box_lift")
    dev.setExternalWrench("centre", [0.0, 0.0, 2.0 * MASS * G, 0.0, 0.0, 0.0])
    xs = _run(dev, 100)
    assert dev.contactPoints() == [] and not np.any(dev.contactForces()["sole"])
    # free flight: z rises as G t^2 / 2 (net upward acceleration G)
    t = 0.1
    assert xs[-1, 2] - SIZE[2] / 2 == pytest.approx(0.5 * G * t * t, rel=0.05)


@pytest.mark.parametrize("push", [30.0, 45.0, 55.0, 80.0])
def test_coulomb_friction_sticks_below_and_slides_above_mu_m_g(push):
    mu = 0.5
    dev = box_on_floor(Floor(friction=mu), f"box_slide_{int(push)}")
    q0 = dev.state.value.copy()
    dev.setExternalWrench("centre", [push, 0.0, 0.0, 0.0, 0.0, 0.0])
    xs = _run(dev, 300)
    x = xs[:, 0] - q0[0]
    limit = mu * MASS * G
    if push < limit:
        assert abs(x[-1]) < 1e-5  # sticks (the noslip iterations: no creep)
        assert _angle(q0, xs[-1]) < 1e-3
    else:  # slides with Coulomb's acceleration (F - mu m g) / m
        t = np.arange(1, len(x) + 1) * DT
        acc = 2.0 * np.polyfit(t[50:], x[50:], 2)[0]
        assert acc == pytest.approx((push - limit) / MASS, rel=0.02)
        w = dev.contactForces()["sole"]
        assert np.hypot(w[0], w[1]) == pytest.approx(mu * w[2], rel=1e-3)


@pytest.mark.parametrize("push", [15.0, 25.0])
def test_a_box_pushed_high_tilts_above_its_tipping_force(push):
    """Pushed at 0.5 m above its sole with friction that holds, the box tips over its
    front edge when ``F h > m g L / 2``: at 19.6 N."""
    dev = box_on_floor(Floor(friction=1.5), f"box_tip_{int(push)}")
    q0 = dev.state.value.copy()
    dev.setExternalWrench("top", [push, 0.0, 0.0, 0.0, 0.0, 0.0])
    xs = _run(dev, 300)
    tipping = MASS * G * (SIZE[0] / 2) / 0.5
    if push < tipping:
        assert _angle(q0, xs[-1]) < 1e-3 and len(dev.contactPoints()) == 4
    else:
        assert _angle(q0, xs[-1]) > 0.1


def test_the_floor_stiffness_is_its_time_constant():
    """MuJoCo's soft contact: the penetration of a resting box grows with the square of
    the contact's time constant."""
    depth = {}
    for T in (0.005, 0.02):
        dev = box_on_floor(Floor(time_constant=T), f"box_k{int(1e3 * T)}", settle=400)
        depth[T] = np.mean([p.depth for p in dev.contactPoints()])
        assert depth[T] > 0
    assert depth[0.02] / depth[0.005] == pytest.approx(16.0, rel=0.2)
    assert depth[0.005] < 1e-4


# -- options and refusals -----------------------------------------------------------------
def test_bad_input_is_refused_and_changes_nothing():
    with pytest.raises(ContactError, match="friction"):
        Floor(friction=-0.1)
    with pytest.raises(ContactError, match="time constant"):
        Floor(time_constant=0.0)
    with pytest.raises(ContactError, match="cone"):
        Floor(cone="round")
    with pytest.raises(ContactError, match="noslip"):
        Floor(noslip_iterations=-1)
    with pytest.raises(ContactError, match="length"):
        FootPatch("sole", -0.2, 0.1)
    with pytest.raises(ContactError, match="grid"):
        FootPatch("sole", 0.2, 0.1, grid=(1, 2))
    dev = box_on_floor(Floor(), "box_bad", settle=10)
    floor, patches = dev.getFloor(), dev.getFloorPatches()
    for bad in ([np.nan, 0, 0, 0, 0, 0], [0, 0, np.inf, 0, 0, 0], [1.0, 2.0], "push"):
        with pytest.raises(ContactError, match=r"box_bad.*wrench must be 6 finite"):
            dev.setExternalWrench("centre", bad)
    with pytest.raises(ContactError, match="not a frame"):
        dev.setExternalWrench("nowhere", np.zeros(6))
    with pytest.raises(ContactError, match="not a frame"):
        dev.setFloor([FootPatch("nowhere", 0.1, 0.1)])
    with pytest.raises(CommandError, match="list of FootPatch"):
        dev.setFloor(FootPatch("sole", 0.1, 0.1))
    assert dev.getExternalWrenches() == {}
    assert dev.getFloor() is floor and dev.getFloorPatches() == patches
    q = dev.state.value.copy()
    dev.increment(DT)  # still standing on the same floor
    assert np.allclose(dev.state.value, q, atol=1e-6) and len(dev.contactPoints()) == 4


def test_welded_feet_stay_an_option():
    robot = load_robot("talos", prefix="floor_weld")
    dev = robot.device
    dev.setControlType("torque")
    dev.setFloor(list(robot.feet.values()))
    assert dev.getFloor() == Floor() and dev.getContacts() == []
    frames = [f.frame for f in robot.feet.values()]
    dev.setContacts(frames)  # welded: replaces the floor
    assert dev.getFloor() is None and dev.getContacts() == frames
    dev.setFloor(list(robot.feet.values()), Floor(friction=0.6))
    assert dev.getContacts() == [] and dev.getFloor().friction == 0.6
    dev.setFloor([])
    assert dev.getFloor() is None and dev.contactPoints() == []
