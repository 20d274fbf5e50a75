"""``Dynamic``: op points, CoM and dynamics of Pinocchio models, checked against finite
differences on the manifold and against Pinocchio's own RNEA; shared passes, fresh
copies, and the errors a user can cause."""

from __future__ import annotations

import copy

import numpy as np
import pinocchio as pin
import pytest

from sotpy.dynamics.dynamic import Dynamic
from sotpy.dynamics.robot import list_robots, load_model
from sotpy.dynamics.types import SE3
from sotpy.errors import CommandError, EntityError, SignalNotFoundError, SignalTypeError, SotpyError
from sotpy.graph import VECTOR, Entity, Output, Plan, plug

# Frames per robot: feet, wrists, head, chest (humanoids); end effector and a middle
# link (arms). Joint names are frames too.
FRAMES = {
    "talos": [
        "left_sole_link",
        "right_sole_link",
        "arm_left_7_joint",
        "arm_right_7_joint",
        "rgbd_joint",
        "torso_2_joint",
    ],
    "romeo": ["l_ankle", "r_ankle", "LWristPitch", "RWristPitch", "gaze", "torso"],
    "panda": ["panda_hand_tcp", "panda_link4", "panda_joint2"],
    "ur5": ["tool0", "wrist_2_link", "ee_link"],
    "nao": ["l_sole", "r_sole", "l_gripper", "r_gripper", "gaze", "torso"],
}
ROBOTS = list(FRAMES)
FREE_FLYERS = ["talos", "romeo", "nao"]
EPS = 1e-5  # central finite-difference step


class DynamicTestSource(Entity):
    """A state signal written each tick (as a device's ``state``)."""

    state = Output(VECTOR)


@pytest.fixture(scope="module")
def models() -> dict[str, pin.Model]:
    """Each robot's model, loaded once for the module."""
    # every shipped robot: example-robot-data's, and the Nao-class URDF shipped in sotpy
    assert sorted(ROBOTS) == sorted(list_robots())
    return {name: load_model(name)[0] for name in ROBOTS}


def random_q(model: pin.Model, rng: np.random.Generator) -> np.ndarray:
    """A random configuration within the model's position limits, the joints
    clipped to [-pi, pi], the free-flyer's base position within [-1, 1] m (its limits)
    and its quaternion drawn in [-1, 1]^4 and normalised."""
    lo = np.clip(model.lowerPositionLimit, -np.pi, np.pi)
    hi = np.clip(model.upperPositionLimit, -np.pi, np.pi)
    return pin.normalize(model, rng.uniform(lo, hi))


class Driver:
    """Feeds ``dyn.position`` from a state source, one tick per configuration."""

    def __init__(self, dyn: Dynamic) -> None:
        self.dyn = dyn
        self.src = DynamicTestSource("src")
        plug(self.src.state, dyn.position)
        self.t = 0

    def at(self, q: np.ndarray) -> int:
        """Write ``q`` at a new tick and return the tick."""
        self.t += 1
        self.src.state.write(np.array(q), self.t)
        return self.t


def make(models, robot: str, name: str = "dyn") -> tuple[Dynamic, Driver]:
    dyn = Dynamic(name, models[robot])
    for f in FRAMES[robot]:
        dyn.createOpPoint(f, f)
    return dyn, Driver(dyn)


# -- kinematics against finite differences ------------------------------------------------
@pytest.mark.parametrize("robot", ROBOTS)
def test_op_point_jacobians_match_finite_differences_on_the_manifold(models, robot):
    # J dv = (log6(M(q)^-1 M(q + eps dv)) - log6(M(q)^-1 M(q - eps dv))) / (2 eps)
    model = models[robot]
    dyn, drv = make(models, robot)
    rng = np.random.default_rng(1)
    checked = 0
    for _ in range(3):
        q = random_q(model, rng)
        t = drv.at(q)
        M0 = {f: dyn.signal(f)(t) for f in FRAMES[robot]}
        J = {f: dyn.signal("J" + f)(t) for f in FRAMES[robot]}
        for _ in range(2):
            dv = rng.standard_normal(model.nv)
            dv /= np.linalg.norm(dv)
            tp = drv.at(pin.integrate(model, q, EPS * dv))
            plus = {f: dyn.signal(f)(tp) for f in FRAMES[robot]}
            tm = drv.at(pin.integrate(model, q, -EPS * dv))
            minus = {f: dyn.signal(f)(tm) for f in FRAMES[robot]}
            for f in FRAMES[robot]:
                fd = (
                    pin.log6(M0[f].inverse() * plus[f]).vector
                    - pin.log6(M0[f].inverse() * minus[f]).vector
                ) / (2 * EPS)
                Jdv = J[f] @ dv
                assert np.linalg.norm(Jdv) > 1e-6
                err = np.linalg.norm(Jdv - fd) / max(1.0, np.linalg.norm(Jdv))
                assert err < 1e-6, (robot, f, err)
                checked += 1
    assert checked == 6 * len(FRAMES[robot])


@pytest.mark.parametrize("robot", ROBOTS)
def test_placements_match_an_independent_pinocchio_data(models, robot):
    model = models[robot]
    dyn, drv = make(models, robot)
    data = model.createData()
    q = random_q(model, np.random.default_rng(2))
    t = drv.at(q)
    pin.framesForwardKinematics(model, data, q)
    for f in FRAMES[robot]:
        M = dyn.signal(f)(t)
        assert isinstance(M, pin.SE3)
        assert M.isApprox(data.oMf[model.getFrameId(f)], 1e-12)
        J = dyn.signal("J" + f)(t)
        assert J.shape == (6, model.nv)


@pytest.mark.parametrize("robot", ROBOTS)
def test_jcom_matches_finite_differences_of_com(models, robot):
    model = models[robot]
    dyn, drv = make(models, robot)
    rng = np.random.default_rng(3)
    for _ in range(3):
        q = random_q(model, rng)
        t = drv.at(q)
        com, Jcom = dyn.com(t), dyn.Jcom(t)
        assert com.shape == (3,) and Jcom.shape == (3, model.nv)
        assert np.allclose(com, pin.centerOfMass(model, model.createData(), q), atol=1e-12)
        dv = rng.standard_normal(model.nv)
        dv /= np.linalg.norm(dv)
        plus = dyn.com(drv.at(pin.integrate(model, q, EPS * dv)))
        minus = dyn.com(drv.at(pin.integrate(model, q, -EPS * dv)))
        fd = (plus - minus) / (2 * EPS)
        assert np.linalg.norm(Jcom @ dv - fd) < 1e-6 * max(1.0, np.linalg.norm(fd))


@pytest.mark.parametrize("robot", ["talos", "panda"])
def test_world_and_local_world_aligned_jacobians(models, robot):
    # WORLD: spatial velocity at the world origin = oMf.action J_local; LOCAL_WORLD_ALIGNED:
    # the frame's origin velocity and angular velocity in world axes = diag(R, R) J_local.
    model = models[robot]
    frame = FRAMES[robot][0]
    dyn, drv = make(models, robot)
    dyn.createJacobian("Jw", frame, "world")
    dyn.createJacobian("Jlwa", frame, "local_world_aligned")
    dyn.createJacobian("Jl", frame)
    dyn.createPosition("p", frame)
    t = drv.at(random_q(model, np.random.default_rng(4)))
    M, J = dyn.signal(frame)(t), dyn.signal("J" + frame)(t)
    R = M.rotation
    np.testing.assert_allclose(dyn.Jw(t), M.action @ J, atol=1e-12)
    np.testing.assert_allclose(dyn.Jlwa(t), np.block([[R, 0 * R], [0 * R, R]]) @ J, atol=1e-12)
    np.testing.assert_array_equal(dyn.Jl(t), J)
    assert dyn.p(t).isApprox(M, 1e-15)
    assert not dyn.hasSignal("Jp") and not dyn.hasSignal("JJw")


# -- dynamics against RNEA ----------------------------------------------------------------
@pytest.mark.parametrize("robot", ROBOTS)
def test_inertia_drift_and_gravity_match_rnea(models, robot):
    # M a + b = rnea(q, v, a), b = rnea(q, v, 0), g = rnea(q, 0, 0)
    model = models[robot]
    dyn, drv = make(models, robot)
    data = model.createData()
    rng = np.random.default_rng(5)
    zero = np.zeros(model.nv)
    for _ in range(3):
        q = random_q(model, rng)
        v, a = rng.standard_normal(model.nv), rng.standard_normal(model.nv)
        dyn.velocity.value = v
        t = drv.at(q)
        M, b, g = dyn.inertia(t), dyn.dynamicDrift(t), dyn.gravity(t)
        assert M.shape == (model.nv, model.nv) and b.shape == g.shape == (model.nv,)
        np.testing.assert_array_equal(M, M.T)
        eig = np.linalg.eigvalsh(M)  # positive semi-definite (Romeo has massless links)
        assert eig.min() > -1e-12 * eig.max()
        tau = pin.rnea(model, data, q, v, a)
        scale = max(1.0, np.abs(tau).max())
        np.testing.assert_allclose(M @ a + b, tau, rtol=0, atol=1e-9 * scale)
        np.testing.assert_allclose(b, pin.rnea(model, data, q, v, zero), rtol=0, atol=1e-9 * scale)
        np.testing.assert_allclose(
            g, pin.rnea(model, data, q, zero, zero), rtol=0, atol=1e-9 * scale
        )
        assert np.abs(b - g).max() > 1e-6  # v matters: b is not g


@pytest.mark.parametrize("robot", ["talos", "ur5"])
def test_momenta_match_mass_times_com_velocity_and_the_centroidal_map(models, robot):
    model = models[robot]
    dyn, drv = make(models, robot)
    rng = np.random.default_rng(6)
    q, v = random_q(model, rng), rng.standard_normal(model.nv)
    dyn.velocity.value = v
    t = drv.at(q)
    h = dyn.momenta(t)
    mass = pin.computeTotalMass(model)  # the moving bodies (UR5's base link is fixed)
    np.testing.assert_allclose(h[:3], mass * dyn.Jcom(t) @ v, atol=1e-9)
    np.testing.assert_allclose(
        h, pin.computeCentroidalMap(model, model.createData(), q) @ v, atol=1e-9
    )
    np.testing.assert_array_equal(dyn.angularmomentum(t), h[3:])
    assert np.linalg.norm(h[3:]) > 1e-3


@pytest.mark.parametrize("robot", FREE_FLYERS)
def test_zmp_matches_the_base_wrench_from_rnea(models, robot):
    # The contact wrench is the base wrench rnea asks for, moved to the world origin:
    # f, n; the ZMP on z = 0 is (-n_y / f_z, n_x / f_z, 0).
    model = models[robot]
    dyn, drv = make(models, robot)
    data = model.createData()
    rng = np.random.default_rng(7)
    q = random_q(model, rng)
    t = drv.at(q)
    zmp, com = dyn.zmp(t), dyn.com(t)  # static: the CoM's projection
    np.testing.assert_allclose(zmp, [com[0], com[1], 0.0], atol=1e-12)
    v, a = 0.3 * rng.standard_normal(model.nv), 0.3 * rng.standard_normal(model.nv)
    dyn.velocity.value, dyn.acceleration.value = v, a
    t = drv.at(q)
    tau = pin.rnea(model, data, q, v, a)
    pin.forwardKinematics(model, data, q)  # rnea does not fill data.oMi
    f = data.oMi[1].act(pin.Force(tau[:6]))
    expected = [-f.angular[1] / f.linear[2], f.angular[0] / f.linear[2], 0.0]
    np.testing.assert_allclose(dyn.zmp(t), expected, atol=1e-9)
    assert np.abs(dyn.zmp(t)[:2] - com[:2]).max() > 1e-4  # the motion moved it
    # falling faster than gravity: no contact force, no ZMP
    pin.forwardKinematics(model, data, q)
    a = np.zeros(model.nv)
    a[:3] = data.oMi[1].rotation.T @ np.array([0.0, 0.0, -20.0])
    dyn.velocity.value, dyn.acceleration.value = np.zeros(model.nv), a
    with pytest.raises(SotpyError, match=r"Dynamic\(dyn\)::output\(vector\)::zmp.*f_z"):
        dyn.zmp(drv.at(q))


# -- shared passes --------------------------------------------------------------------------
COUNTED = [
    "computeJointJacobians",
    "updateFramePlacements",
    "forwardKinematics",
    "framesForwardKinematics",
    "jacobianCenterOfMass",
    "centerOfMass",
    "crba",
    "nonLinearEffects",
    "rnea",
    "computeGeneralizedGravity",
    "computeCentroidalMomentum",
    "computeCentroidalMomentumTimeVariation",
]


class Calls(dict):
    """Calls of each counted Pinocchio algorithm."""

    def reset(self) -> None:
        """Forget the calls so far (construction runs CRBA once to probe it)."""
        self.update(dict.fromkeys(self, 0))


@pytest.fixture
def calls(monkeypatch) -> Calls:
    """Count the calls of Pinocchio's algorithms (Dynamic calls them as ``pin.<name>``)."""
    counts = Calls.fromkeys(COUNTED, 0)
    for name in COUNTED:
        original = getattr(pin, name)

        def counting(*args, _name=name, _original=original):
            counts[_name] += 1
            return _original(*args)

        monkeypatch.setattr(pin, name, counting)
    return counts


def test_one_kinematics_pass_per_tick_for_every_op_point_com_and_jcom(models, calls):
    model = models["talos"]
    dyn, drv = make(models, "talos")
    calls.reset()
    rng = np.random.default_rng(8)
    sinks = [dyn.signal(n) for f in FRAMES["talos"] for n in (f, "J" + f)] + [dyn.com, dyn.Jcom]
    assert len(sinks) == 14
    # lazy reads
    t = drv.at(random_q(model, rng))
    for s in sinks:
        s(t)
    for s in sinks:  # reading again at the same tick computes nothing
        s(t)
    expected = dict.fromkeys(COUNTED, 0)
    expected.update(computeJointJacobians=1, updateFramePlacements=1, jacobianCenterOfMass=1)
    assert calls == expected
    # a plan
    plan = Plan(sinks)
    for k in range(2, 5):
        plan.run(drv.at(random_q(model, rng)))
        assert calls["computeJointJacobians"] == calls["updateFramePlacements"] == k
        assert calls["jacobianCenterOfMass"] == k
    assert calls["forwardKinematics"] == calls["crba"] == calls["nonLinearEffects"] == 0
    assert all(s.time == drv.t for s in sinks)


def test_reading_com_runs_neither_crba_nor_the_dynamics(models, calls):
    model = models["talos"]
    dyn, drv = make(models, "talos")
    calls.reset()
    rng = np.random.default_rng(9)
    t = drv.at(random_q(model, rng))
    dyn.com(t)
    assert calls["computeJointJacobians"] == calls["jacobianCenterOfMass"] == 1
    assert sum(calls.values()) == 3  # and updateFramePlacements
    dyn.inertia(t)
    assert calls["crba"] == 1 and calls["computeJointJacobians"] == 1
    dyn.momenta(t)
    dyn.angularmomentum(t)
    assert calls["computeCentroidalMomentum"] == 1
    assert calls["nonLinearEffects"] == calls["computeGeneralizedGravity"] == 0
    # a new velocity at the same tick: the passes that read it run again, the others not
    dyn.velocity.value = np.ones(model.nv)
    dyn.momenta(t), dyn.inertia(t), dyn.com(t)
    assert calls["computeCentroidalMomentum"] == 2
    assert calls["crba"] == calls["computeJointJacobians"] == 1


def test_passes_in_any_order_give_the_same_values(models):
    # The passes share one pinocchio.Data: reading the outputs in one order at a tick,
    # then in the reverse order at a later tick with the same (q, v), gives the same values.
    model = models["talos"]
    dyn, drv = make(models, "talos")
    rng = np.random.default_rng(10)
    q, v = random_q(model, rng), rng.standard_normal(model.nv)
    dyn.velocity.value = v
    names = ["inertia", "dynamicDrift", "momenta", "left_sole_link", "Jarm_left_7_joint"]
    names += ["com", "Jcom", "gravity", "zmp", "Jrgbd_joint", "torso_2_joint"]
    t = drv.at(q)
    first = {n: dyn.signal(n)(t) for n in names}
    t = drv.at(random_q(model, rng))
    for n in names:
        dyn.signal(n)(t)
    t = drv.at(q)
    second = {n: dyn.signal(n)(t) for n in reversed(names)}
    for n in names:
        if isinstance(first[n], pin.SE3):
            np.testing.assert_array_equal(first[n].homogeneous, second[n].homogeneous)
        else:
            np.testing.assert_array_equal(first[n], second[n], err_msg=n)


def test_cached_values_do_not_change_when_the_next_tick_is_computed(models):
    model = models["talos"]
    dyn, drv = make(models, "talos")
    rng = np.random.default_rng(11)
    names = [
        "left_sole_link",
        "Jleft_sole_link",
        "com",
        "Jcom",
        "inertia",
        "dynamicDrift",
        "gravity",
        "momenta",
        "angularmomentum",
        "zmp",
    ]
    dyn.velocity.value = 0.1 * rng.standard_normal(model.nv)
    t = drv.at(random_q(model, rng))
    old = {n: dyn.signal(n)(t) for n in names}
    snapshot = copy.deepcopy(
        {n: (x.homogeneous if isinstance(x, pin.SE3) else x) for n, x in old.items()}
    )
    dyn.velocity.value = 0.1 * rng.standard_normal(model.nv)
    t = drv.at(random_q(model, rng))
    new = {n: dyn.signal(n)(t) for n in names}
    for n in names:
        then = old[n].homogeneous if isinstance(old[n], pin.SE3) else old[n]
        now = new[n].homogeneous if isinstance(new[n], pin.SE3) else new[n]
        np.testing.assert_array_equal(then, snapshot[n], err_msg=n)
        assert np.abs(now - then).max() > 1e-6, n  # the new tick did change the value


# -- limits and commands ------------------------------------------------------------------
@pytest.mark.parametrize("robot", ["romeo", "panda"])
def test_limits_are_the_model_limits_computed_once_and_read_only(models, robot):
    model = models[robot]
    dyn, drv = make(models, robot)
    rng = np.random.default_rng(12)
    drv.at(random_q(model, rng))
    expected = {
        "lowerJl": model.lowerPositionLimit,
        "upperJl": model.upperPositionLimit,
        "upperVl": model.velocityLimit,
        "lowerVl": -model.velocityLimit,
        "upperTl": model.effortLimit,
        "lowerTl": -model.effortLimit,
    }
    first = {}
    for n, e in expected.items():
        first[n] = dyn.signal(n).value
        np.testing.assert_array_equal(first[n], e)
        with pytest.raises(ValueError):
            first[n][0] = 0.0
    t = drv.at(random_q(model, rng))
    for n in expected:
        assert dyn.signal(n)(t) is first[n]  # not recomputed at a later tick
    assert dyn.getDimension() == model.nv
    assert dyn.frames() == [f.name for f in model.frames]


def test_velocity_and_acceleration_default_to_zero_and_unplug_restores_it(models):
    model = models["ur5"]
    dyn = Dynamic("dyn", model)
    for sig in (dyn.velocity, dyn.acceleration):
        np.testing.assert_array_equal(sig.value, np.zeros(model.nv))
        sig.value = np.ones(model.nv)
        sig.unplug()
        np.testing.assert_array_equal(sig.value, np.zeros(model.nv))
    dyn.position.value = pin.neutral(model)
    np.testing.assert_allclose(dyn.dynamicDrift.value, dyn.gravity.value, atol=1e-12)


def test_the_model_is_copied_at_construction(models):
    model = models["panda"].copy()
    dyn = Dynamic("dyn", model)
    limit = model.lowerPositionLimit.copy()
    limit[0] = -100.0
    model.lowerPositionLimit = limit
    assert model.lowerPositionLimit[0] == -100.0
    assert dyn.lowerJl.value[0] == models["panda"].lowerPositionLimit[0] != -100.0
    assert dyn.model.nq == model.nq
    with pytest.raises(EntityError, match=r"Dynamic\(bad\).*pinocchio.Model"):
        Dynamic("bad", "talos.urdf")


# -- errors ---------------------------------------------------------------------------------
@pytest.mark.parametrize("robot", ["talos", "panda"])
def test_wrong_size_position_raises_naming_entity_signal_and_sizes(models, robot, calls):
    model = models[robot]
    dyn, drv = make(models, robot)
    calls.reset()
    t = drv.at(np.zeros(model.nq + 1))
    for out in ("com", FRAMES[robot][0], "inertia", "dynamicDrift", "gravity", "momenta"):
        with pytest.raises(SignalTypeError) as err:
            dyn.signal(out)(t)
        msg = str(err.value)
        assert "Dynamic(dyn)::input(vector)::position" in msg
        assert f"nq = {model.nq}" in msg and f"received size {model.nq + 1}" in msg
    with pytest.raises(SignalTypeError, match="position"):
        Plan([dyn.com]).run(t)
    assert sum(calls.values()) == 0  # nothing reached Pinocchio
    q = random_q(model, np.random.default_rng(13))
    t = drv.at(q)  # a good configuration at the next tick computes again
    np.testing.assert_allclose(
        dyn.com(t), pin.centerOfMass(model, model.createData(), q), atol=1e-12
    )


def test_wrong_size_velocity_and_acceleration_raise(models, calls):
    model = models["talos"]
    dyn, drv = make(models, "talos")
    calls.reset()
    t = drv.at(random_q(model, np.random.default_rng(14)))
    dyn.velocity.value = np.zeros(3)
    for out in ("dynamicDrift", "momenta", "zmp"):
        with pytest.raises(
            SignalTypeError,
            match=r"Dynamic\(dyn\)::input\(vector\)::velocity.*nv = 38.*received size 3",
        ):
            dyn.signal(out)(t)
    dyn.velocity.unplug()
    dyn.acceleration.value = np.zeros(39)
    with pytest.raises(SignalTypeError, match=r"::acceleration.*nv = 38.*received size 39"):
        dyn.zmp(t)
    assert calls["nonLinearEffects"] == calls["computeCentroidalMomentum"] == 0
    dyn.com(t)  # the kinematics do not read the velocity


def test_unnormalised_quaternion_raises_naming_the_joint(models, calls):
    model = models["talos"]
    dyn, drv = make(models, "talos")
    calls.reset()
    q = pin.neutral(model)
    q[3:7] = 0.0
    with pytest.raises(
        SignalTypeError, match=r"::position: the configuration is not normalised.*root_joint"
    ):
        dyn.com(drv.at(q))
    q[3:7] = [0.0, 0.0, 0.0, 1.01]
    with pytest.raises(SignalTypeError, match="root_joint"):
        dyn.inertia(drv.at(q))
    assert sum(calls.values()) == 0


def test_unknown_frame_lists_close_names_and_leaves_the_entity_unchanged(models):
    dyn, _ = make(models, "talos")
    before = [s.name for s in dyn.signals()]
    with pytest.raises(CommandError) as err:
        dyn.createOpPoint("lw", "arm_left_7_jiont")
    assert "Dynamic(dyn).createOpPoint" in str(err.value)
    assert "'arm_left_7_jiont'" in str(err.value) and "arm_left_7_joint" in str(err.value)
    for cmd in (dyn.createJacobian, dyn.createPosition):
        with pytest.raises(CommandError, match="no frame named"):
            cmd("lw", "nowhere")
    with pytest.raises(CommandError, match="reference"):
        dyn.createJacobian("lw", "arm_left_7_joint", "global")
    assert [s.name for s in dyn.signals()] == before
    assert not hasattr(dyn, "lw")


def test_existing_op_point_names_are_refused(models):
    dyn, _ = make(models, "talos")
    before = [s.name for s in dyn.signals()]
    with pytest.raises(EntityError, match="op point named 'left_sole_link' already exists"):
        dyn.createOpPoint("left_sole_link", "right_sole_link")
    with pytest.raises(EntityError, match="'com'"):
        dyn.createOpPoint("com", "right_sole_link")  # clashes with an output
    with pytest.raises(EntityError, match="'Jcom'"):
        dyn.createJacobian("Jcom", "right_sole_link")
    dyn.createPosition("x", "right_sole_link")
    with pytest.raises(EntityError):
        dyn.createJacobian("x", "right_sole_link")
    assert [s.name for s in dyn.signals() if s.shortName != "x"] == before


def test_op_points_are_attributes_signals_displayed_and_destroyable(models, capsys):
    model = models["talos"]
    dyn = Dynamic("dyn", model)
    dyn.createOpPoint("left-wrist", "arm_left_7_joint")
    dyn.createOpPoint("rf", "right_sole_link")
    assert dyn.rf is dyn.signal("rf") and dyn.Jrf is dyn.signal("Jrf")
    assert dyn.rf.type is SE3
    assert dyn.signal("left-wrist").type is SE3
    dyn.displaySignals()
    out = capsys.readouterr().out
    assert "<Sig:Dynamic(dyn)::output(SE3)::left-wrist (Type Fun)" in out
    assert "<Sig:Dynamic(dyn)::output(matrix)::Jleft-wrist (Type Fun)" in out
    assert "<Sig:Dynamic(dyn)::output(SE3)::rf (Type Fun)" in out
    dyn.position.value = pin.neutral(model)
    assert dyn.signal("Jleft-wrist").value.shape == (6, model.nv)
    dyn.destroyOpPoint("rf")
    assert not dyn.hasSignal("rf") and not dyn.hasSignal("Jrf")
    with pytest.raises(SignalNotFoundError):
        dyn.rf  # noqa: B018
    with pytest.raises(SignalNotFoundError, match="op points: left-wrist"):
        dyn.destroyOpPoint("rf")
    dyn.createOpPoint("rf", "left_sole_link")  # the name is free again
    data = model.createData()
    pin.framesForwardKinematics(model, data, pin.neutral(model))
    assert dyn.rf.value.isApprox(data.oMf[model.getFrameId("left_sole_link")], 1e-12)


def test_inertia_is_symmetrised_if_crba_fills_only_the_upper_triangle(models, monkeypatch):
    # Pinocchio's C++ CRBA computes the upper triangle; its Python binding copies it to the
    # lower one. Dynamic checks that once and symmetrises itself otherwise.
    model = models["panda"]
    original = pin.crba
    lower = np.tril_indices(model.nv, -1)

    def upper_only(m, d, q, *rest):
        original(m, d, q, *rest)
        d.M[lower] = 0.0  # data.M is a view: what the C++ algorithm alone leaves
        return d.M

    monkeypatch.setattr(pin, "crba", upper_only)
    dyn = Dynamic("dyn", model)
    q = random_q(model, np.random.default_rng(15))
    dyn.position.value = q
    M = dyn.inertia.value
    assert np.all(dyn.data.M[lower] == 0.0)  # the stub did run
    np.testing.assert_array_equal(M, M.T)
    np.testing.assert_allclose(M, original(model, model.createData(), q), atol=1e-14)


def test_benchmark_paths_agree_with_bare_pinocchio():
    # bench_dynamic.measure asserts that the plan, the lazy pull and the bare Pinocchio
    # floor give the same 18 values; the timings are only sanity-checked here.
    import importlib.util
    from pathlib import Path

    path = Path(__file__).resolve().parents[1] / "benchmarks" / "bench_dynamic.py"
    spec = importlib.util.spec_from_file_location("bench_dynamic", path)
    bench = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(bench)
    row = bench.measure("talos", dynamics=True, ticks=20, repeats=1)
    assert row["outputs"] == 18 and row["steps"] == 24
    for key in ("floor", "plan", "lazy"):
        assert 0 < row[key] < 1e5, (key, row[key])
