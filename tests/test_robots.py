"""Robot descriptions (sotpy/robots/*.toml), the Nao URDF, and load_robot's wiring.

Models are loaded once per process (sotpy.dynamics.robot caches them); the expensive
part is example-robot-data's mesh loading (about 1 s per robot).
"""

from __future__ import annotations

import math
import shutil
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest

from sotpy.cli import main
from sotpy.dynamics import robot as robot_module
from sotpy.dynamics.robot import (
    ROBOTS_DIR,
    Foot,
    RobotDescriptionError,
    RobotError,
    RobotNotFoundError,
    convex_hull_2d,
    list_robots,
    load_model,
    load_robot,
    robot_info,
    robot_summary,
)
from sotpy.graph.pool import pool

HUMANOIDS = ["nao", "romeo", "talos"]
ARMS = ["panda", "ur5"]
SOT_HUMANOID_OPS = {
    "left-ankle",
    "right-ankle",
    "left-wrist",
    "right-wrist",
    "gaze",
    "chest",
    "waist",
}
# nv, joints besides the free flyer, actuated DoF (joints - couplings), as documented in
# docs/robots.md.
DOFS = {
    "nao": (32, 26, 25),
    "romeo": (61, 55, 33),
    "talos": (38, 32, 32),
    "panda": (9, 9, 8),
    "ur5": (6, 6, 6),
}
# Nao's published dimensions (m), Aldebaran documentation.
NAO = {
    "NeckOffsetZ": 0.1265,
    "ShoulderOffsetY": 0.098,
    "ShoulderOffsetZ": 0.100,
    "UpperArmLength": 0.105,
    "ElbowOffsetY": 0.015,
    "LowerArmLength": 0.05595,
    "HandOffsetX": 0.05775,
    "HipOffsetZ": 0.085,
    "HipOffsetY": 0.050,
    "ThighLength": 0.100,
    "TibiaLength": 0.1029,
    "FootHeight": 0.04519,
}


@pytest.fixture(scope="module")
def summaries():
    """robot_summary of every shipped robot (loads each model once)."""
    return {name: robot_summary(name) for name in list_robots()}


def _fk(model, q):
    data = model.createData()
    pin.forwardKinematics(model, data, q)
    pin.updateFramePlacements(model, data)
    return data


def _joint_pos(model, data, name):
    return data.oMi[model.getJointId(name)].translation.copy()


def _frame(model, data, name):
    return data.oMf[model.getFrameId(name)]


# -- descriptions -----------------------------------------------------------------------
def test_list_robots_ships_the_five():
    assert list_robots() == ["nao", "panda", "romeo", "talos", "ur5"]
    for name in list_robots():
        info = robot_info(name)
        assert info["name"] == name
        assert Path(info["path"]) == ROBOTS_DIR / f"{name}.toml"


@pytest.mark.parametrize("name", ["nao", "panda", "romeo", "talos", "ur5"])
def test_model_loads_op_frames_exist_and_dofs(name, summaries):
    model, visual, collision = load_model(name)
    assert load_model(name)[0] is model  # cached per process
    info = robot_info(name)
    ops = info["opPoints"]
    if name in HUMANOIDS:
        assert set(ops) == SOT_HUMANOID_OPS
        assert set(info["feet"]) == {"left", "right"}
    else:
        assert "end-effector" in ops
        assert "feet" not in info
    for frame in ops.values():
        assert model.existFrame(frame), frame
    for foot in info.get("feet", {}).values():
        assert model.existFrame(foot["frame"])
    assert visual.ngeoms > 0 and collision.ngeoms > 0

    nv, joints, actuated = DOFS[name]
    s = summaries[name]
    floating = model.joints[1].shortname() == "JointModelFreeFlyer"
    assert floating == (name in HUMANOIDS) == s["floating_base"]
    assert model.nv == s["nv"] == nv
    # nv = 6 (free flyer) + one per joint: all of these joints are 1-DoF
    assert nv == 6 * floating + joints
    assert sum(j.nv for j in model.joints[1 + floating :]) == joints
    assert (s["joints"], s["actuated"]) == (joints, actuated)


@pytest.mark.parametrize("name", ["nao", "panda", "romeo", "talos", "ur5"])
def test_half_sitting_within_limits_and_couplings(name, summaries):
    model = load_model(name)[0]
    q = summaries[name]["halfSitting"]
    assert q.shape == (model.nq,)
    assert pin.isNormalized(model, q, 1e-12)
    for j in range(1, model.njoints):
        jm = model.joints[j]
        if jm.shortname() == "JointModelFreeFlyer":
            continue
        sl = slice(jm.idx_q, jm.idx_q + jm.nq)
        assert np.all(model.lowerPositionLimit[sl] <= q[sl]), model.names[j]
        assert np.all(q[sl] <= model.upperPositionLimit[sl]), model.names[j]
    p = robot_module._prepare(name)
    for c in p.couplings.values():
        qi = q[model.joints[model.getJointId(c.joint)].idx_q]
        qm = q[model.joints[model.getJointId(c.master)].idx_q]
        assert qi == pytest.approx(c.multiplier * qm + c.offset, abs=1e-12)


def test_reference_half_sitting_is_the_srdf_one():
    """talos: "reference" = example-robot-data's q0 (the SRDF's half_sitting)."""
    import example_robot_data

    q = robot_summary("talos")["halfSitting"]
    ref = load_model("talos")[0].referenceConfigurations["half_sitting"]
    np.testing.assert_array_equal(q, ref)
    assert q[2] == pytest.approx(1.01927)
    # panda: the SRDF's 'default' with the mimic finger made equal to the first one
    panda = example_robot_data.load("panda").q0
    q = robot_summary("panda")["halfSitting"]
    np.testing.assert_array_equal(q[:8], panda[:8])
    assert q[8] == q[7] != panda[8]


# -- humanoids standing -----------------------------------------------------------------
# Talos' SRDF half-sitting has ankle rolls of -0.001708 rad: its soles tilt by 1.7 mrad
# (the corners stay within 0.2 mm of the ground). The postures written for sotpy (nao,
# romeo) are flat to 1e-3 as required.
TILT = {"nao": 1e-3, "romeo": 1e-3, "talos": 2e-3}


@pytest.mark.parametrize("name", HUMANOIDS)
def test_humanoid_soles_flat_on_the_ground(name, summaries):
    model = load_model(name)[0]
    q = summaries[name]["halfSitting"]
    data = _fk(model, q)
    for foot in robot_module._prepare(name).feet.values():
        oMs = _frame(model, data, foot.frame)
        assert abs(oMs.translation[2]) < 1e-3
        tilt = math.acos(min(1.0, oMs.rotation[2, 2]))
        assert tilt < TILT[name]
        corners = foot.corners @ oMs.rotation.T + oMs.translation
        assert np.all(np.abs(corners[:, 2]) < 1e-3)


def _area(polygon):
    """Signed area (shoelace formula): positive for a counter-clockwise polygon (m^2)."""
    x, y = polygon[:, 0], polygon[:, 1]
    return 0.5 * float(np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y))


def _inside(point, polygon, margin):
    """Whether point is inside the CCW convex polygon by at least margin (m)."""
    n = len(polygon)
    for i in range(n):
        a, b = polygon[i], polygon[(i + 1) % n]
        edge = b - a
        normal = np.array([-edge[1], edge[0]]) / np.linalg.norm(edge)  # inward for CCW
        if (point - a) @ normal < margin:
            return False
    return True


@pytest.mark.parametrize("name", HUMANOIDS)
def test_com_inside_support_polygon(name):
    robot = load_robot(name)
    q = robot.halfSitting
    com = pin.centerOfMass(robot.model, robot.model.createData(), q)
    poly = robot.supportPolygon()
    np.testing.assert_allclose(poly, robot.supportPolygon(q))
    assert len(poly) >= 4
    assert _area(poly) > 0.01  # counter-clockwise, two feet (m^2)
    assert _inside(com[:2], poly, margin=0.01)
    # and the polygon is the hull of the 8 corners: every corner inside or on it
    for corners in robot.soleCorners(q).values():
        for c in corners:
            assert _inside(c[:2], poly, margin=-1e-12)
    # a point beyond the feet is outside
    assert not _inside(np.array([poly[:, 0].max() + 0.01, 0.0]), poly, margin=0.0)


def test_nao_support_polygon_from_published_numbers():
    """Half-sitting Nao: the polygon is the rectangle spanned by both feet."""
    robot = load_robot("nao")
    data = _fk(robot.model, robot.halfSitting)
    ankle_x = _joint_pos(robot.model, data, "LAnkleRoll")[0]
    y_out = NAO["HipOffsetY"] + 0.0044 + 0.088 / 2
    expected = {
        (round(ankle_x + 0.02 + sx * 0.08, 9), round(sy * y_out, 9))
        for sx in (-1, 1)
        for sy in (-1, 1)
    }
    got = {(round(x, 9), round(y, 9)) for x, y in robot.supportPolygon()}
    assert got == expected


def test_arm_has_no_support_polygon():
    with pytest.raises(RobotError, match="no feet"):
        load_robot("ur5").supportPolygon()


# -- the Nao model ----------------------------------------------------------------------
def test_nao_mass_and_per_link_masses():
    model = load_model("nao")[0]
    mass = pin.computeTotalMass(model)
    assert abs(mass - 5.3) / 5.3 < 0.10
    # published link masses land on their joints' bodies (fixed links merged)
    for joint, m in [
        ("root_joint", 1.0496),  # torso
        ("HeadPitch", 0.60533),
        ("LHipPitch", 0.38968),  # thigh
        ("RKneePitch", 0.30142),  # tibia
        ("LShoulderRoll", 0.15777),  # upper arm
        ("LElbowRoll", 0.07761),  # forearm
        ("LAnkleRoll", 0.17184),  # foot
    ]:
        assert model.inertias[model.getJointId(joint)].mass == pytest.approx(m, abs=1e-9)


def _valid_inertia(inertia: np.ndarray) -> bool:
    ev = np.linalg.eigvalsh(inertia)
    a, b, c = ev
    return bool(np.allclose(inertia, inertia.T) and ev.min() > 0 and a + b >= c * (1 - 1e-12))


def test_nao_inertias_physically_valid():
    model = load_model("nao")[0]
    for i in range(1, model.njoints):  # Pinocchio's body inertias (merged links)
        Y = model.inertias[i]
        assert Y.mass > 0, model.names[i]
        assert _valid_inertia(Y.inertia), model.names[i]
    # and every link of the URDF: principal moments positive, triangle inequality
    links = ET.parse(ROBOTS_DIR / "nao.urdf").getroot().findall("link")
    checked = 0
    for link in links:
        inertial = link.find("inertial")
        if inertial is None:
            continue
        t = inertial.find("inertia").attrib
        inertia = np.array(
            [
                [float(t["ixx"]), float(t["ixy"]), float(t["ixz"])],
                [float(t["ixy"]), float(t["iyy"]), float(t["iyz"])],
                [float(t["ixz"]), float(t["iyz"]), float(t["izz"])],
            ]
        )
        assert _valid_inertia(inertia), link.get("name")
        checked += 1
    assert checked == 27


def _shape_inertia(mass, geometry, rpy):
    """Inertia of the URDF primitive about its centre, in the link frame."""
    (g,) = list(geometry)
    if g.tag == "box":
        x, y, z = (float(v) for v in g.get("size").split())
        inertia = mass / 12 * np.diag([y * y + z * z, x * x + z * z, x * x + y * y])
    elif g.tag == "cylinder":
        r, h = float(g.get("radius")), float(g.get("length"))
        perp = mass * (3 * r * r + h * h) / 12
        inertia = np.diag([perp, perp, mass * r * r / 2])  # axis z of the shape frame
    else:
        assert g.tag == "sphere"
        inertia = 2 / 5 * mass * float(g.get("radius")) ** 2 * np.eye(3)
    Rm = pin.rpy.rpyToMatrix(*rpy)
    return Rm @ inertia @ Rm.T


def test_nao_inertias_are_those_of_the_drawn_primitives():
    """The URDF says each inertia is its collision primitive's, of the link's mass."""
    for link in ET.parse(ROBOTS_DIR / "nao.urdf").getroot().findall("link"):
        inertial = link.find("inertial")
        if inertial is None:
            assert link.find("visual") is None
            continue
        mass = float(inertial.find("mass").get("value"))
        t = inertial.find("inertia").attrib
        inertia = np.diag([float(t["ixx"]), float(t["iyy"]), float(t["izz"])])
        col = link.find("collision")
        rpy = [float(v) for v in col.find("origin").get("rpy").split()]
        np.testing.assert_allclose(
            inertia, _shape_inertia(mass, col.find("geometry"), rpy), rtol=1e-5, atol=1e-10
        )
        assert link.find("visual/geometry")[0].tag == col.find("geometry")[0].tag


def test_nao_lengths_match_published_numbers():
    model = load_model("nao")[0]
    q = robot_summary("nao")["halfSitting"]
    data = _fk(model, q)
    for s, sign in (("L", 1), ("R", -1)):
        pos = {j: _joint_pos(model, data, s + j) for j in R_NAO_JOINTS}
        hip, knee, ankle = pos["HipPitch"], pos["KneePitch"], pos["AnklePitch"]
        assert np.linalg.norm(knee - hip) == pytest.approx(NAO["ThighLength"], abs=1e-9)
        assert np.linalg.norm(ankle - knee) == pytest.approx(NAO["TibiaLength"], abs=1e-9)
        sole = _frame(model, data, f"{s.lower()}_sole").translation
        assert np.linalg.norm(sole - ankle) == pytest.approx(NAO["FootHeight"], abs=1e-9)
        upper = np.hypot(NAO["UpperArmLength"], NAO["ElbowOffsetY"])
        assert np.linalg.norm(pos["ElbowYaw"] - pos["ShoulderPitch"]) == pytest.approx(upper)
        assert np.linalg.norm(pos["WristYaw"] - pos["ElbowYaw"]) == pytest.approx(
            NAO["LowerArmLength"]
        )
        # offsets from the torso (the free-flyer body), in the torso frame
        oMt = data.oMi[1]
        hip_t = oMt.actInv(pos["HipYawPitch"])
        np.testing.assert_allclose(
            hip_t, [0, sign * NAO["HipOffsetY"], -NAO["HipOffsetZ"]], atol=1e-12
        )
        shoulder_t = oMt.actInv(pos["ShoulderPitch"])
        np.testing.assert_allclose(
            shoulder_t, [0, sign * NAO["ShoulderOffsetY"], NAO["ShoulderOffsetZ"]], atol=1e-12
        )
        wMg = data.oMi[model.getJointId(s + "WristYaw")].actInv(
            _frame(model, data, f"{s.lower()}_gripper").translation
        )
        np.testing.assert_allclose(wMg, [NAO["HandOffsetX"], 0, -0.01231], atol=1e-12)
    neck = data.oMi[1].actInv(_joint_pos(model, data, "HeadYaw"))
    np.testing.assert_allclose(neck, [0, 0, NAO["NeckOffsetZ"]], atol=1e-12)


R_NAO_JOINTS = (
    "HipYawPitch",
    "HipPitch",
    "KneePitch",
    "AnklePitch",
    "ShoulderPitch",
    "ElbowYaw",
    "WristYaw",
)


def test_nao_joint_limits_are_the_documented_ones():
    model = load_model("nao")[0]

    def limits(j):
        i = model.joints[model.getJointId(j)].idx_q
        return model.lowerPositionLimit[i], model.upperPositionLimit[i]

    assert limits("HeadYaw") == pytest.approx((-2.0857, 2.0857))
    assert limits("HeadPitch") == pytest.approx((-0.6720, 0.5149))
    assert limits("LShoulderRoll") == pytest.approx((-0.3142, 1.3265))
    assert limits("RShoulderRoll") == pytest.approx((-1.3265, 0.3142))
    assert limits("LElbowRoll") == pytest.approx((-1.5446, -0.0349))
    assert limits("RElbowRoll") == pytest.approx((0.0349, 1.5446))
    assert limits("LHipYawPitch") == limits("RHipYawPitch") == pytest.approx((-1.145303, 0.74081))
    assert limits("LHipRoll") == pytest.approx((-0.379472, 0.790477))
    assert limits("RHipRoll") == pytest.approx((-0.790477, 0.379472))
    assert limits("LKneePitch") == pytest.approx((-0.092346, 2.112528))
    assert limits("RAnkleRoll") == pytest.approx((-0.769001, 0.39788))
    assert np.all(model.velocityLimit[6:] > 0) and np.all(model.effortLimit[6:] > 0)


def test_nao_coupled_hip_yaw_pitch_moves_the_legs_symmetrically():
    info = robot_info("nao")
    assert info["couplings"] == {"RHipYawPitch": "LHipYawPitch"}
    model = load_model("nao")[0]
    q = robot_summary("nao")["halfSitting"].copy()
    for j in ("LHipYawPitch", "RHipYawPitch"):
        q[model.joints[model.getJointId(j)].idx_q] = -0.5
    data = _fk(model, q)
    left = data.oMi[1].actInv(_frame(model, data, "l_sole").translation)
    right = data.oMi[1].actInv(_frame(model, data, "r_sole").translation)
    np.testing.assert_allclose(right, left * [1, -1, 1], atol=1e-12)
    assert abs(left[0] - right[0]) < 1e-12 and left[1] > 0
    # the equal angles move the feet (the axes are not aligned with y)
    q0 = robot_summary("nao")["halfSitting"]
    left0 = _fk(model, q0).oMf[model.getFrameId("l_sole")].translation
    assert np.linalg.norm(data.oMf[model.getFrameId("l_sole")].translation - left0) > 0.01


def test_nao_visuals_are_primitives():
    _, visual, collision = load_model("nao")
    assert visual.ngeoms == collision.ngeoms == 27
    kinds = {type(g.geometry).__name__ for g in visual.geometryObjects}
    assert kinds <= {"Box", "Cylinder", "Sphere"}


# -- load_robot -------------------------------------------------------------------------
def test_load_robot_wires_device_to_dynamic():
    robot = load_robot("nao")
    assert robot.dynamic.name == "nao_dynamic" and robot.device.name == "nao_device"
    assert robot.dynamic.position.source is robot.device.state
    assert robot.dynamic.velocity.source is robot.device.velocity
    np.testing.assert_array_equal(robot.device.state.value, robot.halfSitting)
    assert robot.nActuated == 25
    model = robot.model
    data = model.createData()
    np.testing.assert_allclose(
        robot.dynamic.com.value, pin.centerOfMass(model, data, robot.halfSitting), atol=1e-12
    )
    rng = np.random.default_rng(3)
    lo, hi = model.lowerPositionLimit.copy(), model.upperPositionLimit.copy()
    lo[:3], hi[:3] = -1.0, 1.0
    for _ in range(3):
        q = pin.randomConfiguration(model, lo, hi)
        robot.device.set(q)
        np.testing.assert_allclose(
            robot.dynamic.com.value, pin.centerOfMass(model, data, q), atol=1e-12
        )
        pin.framesForwardKinematics(model, data, q)
        for op, frame in robot.opPoints.items():
            M = robot.dynamic.signal(op).value
            np.testing.assert_allclose(
                M.homogeneous, data.oMf[model.getFrameId(frame)].homogeneous, atol=1e-12
            )
        # supportPolygon() follows the device's state
        np.testing.assert_allclose(robot.supportPolygon(), robot.supportPolygon(q))
    v = rng.standard_normal(model.nv)
    robot.device.setVelocity(v)
    np.testing.assert_array_equal(robot.dynamic.velocity.value, v)


def test_load_robot_prefix_and_name_clash():
    load_robot("ur5")
    before = pool.list()
    with pytest.raises(RobotError, match=r"ur5_dynamic.*already exists.*prefix"):
        load_robot("ur5")
    assert pool.list() == before
    other = load_robot("ur5", prefix="ur5b")
    assert other.dynamic.name == "ur5b_dynamic" and other.device.name == "ur5b_device"
    assert set(pool.list()) == set(before) | {"ur5b_dynamic", "ur5b_device"}


def test_unknown_robot_lists_the_known_ones():
    with pytest.raises(RobotNotFoundError) as exc:
        load_robot("hrp2")
    for name in list_robots():
        assert name in str(exc.value)
    with pytest.raises(RobotNotFoundError, match="did you mean 'talos'"):
        robot_info("tallos")
    assert pool.list() == []


# -- descriptions from files, broken ones -----------------------------------------------
def _nao_copy(tmp_path: Path, toml_edit=None, urdf_text: str | None = None) -> Path:
    """nao.toml and nao.urdf copied to tmp_path, optionally edited."""
    toml = (ROBOTS_DIR / "nao.toml").read_text()
    if toml_edit is not None:
        toml = toml_edit(toml)
    (tmp_path / "mynao.toml").write_text(toml)
    if urdf_text is None:
        shutil.copy(ROBOTS_DIR / "nao.urdf", tmp_path / "nao.urdf")
    else:
        (tmp_path / "nao.urdf").write_text(urdf_text)
    return tmp_path / "mynao.toml"


def test_load_robot_from_a_description_path(tmp_path):
    path = _nao_copy(tmp_path, lambda t: t.replace('name = "nao"', 'name = "mynao"'))
    robot = load_robot(path)
    assert robot.name == "mynao" and robot.dynamic.name == "mynao_dynamic"
    assert robot.model.nv == 32
    assert robot_info(str(path))["path"] == str(path.resolve())


@pytest.mark.parametrize(
    ("urdf", "expected"),
    [
        ("<robot name='nao'><link name='a'></robot>", "malformed XML"),
        ("<model/>", r"root element is <model>, expected <robot>"),
        (
            "<robot name='x'><link name='a'/><joint name='j' type='revolute'>"
            "<parent link='a'/><child link='missing'/><axis xyz='0 0 1'/>"
            "<limit lower='0' upper='1' effort='1' velocity='1'/></joint></robot>",
            r"Pinocchio cannot load it.*missing",
        ),
    ],
)
def test_broken_urdf_is_a_clear_error(tmp_path, urdf, expected):
    path = _nao_copy(tmp_path, urdf_text=urdf)
    with pytest.raises(RobotDescriptionError, match=expected) as exc:
        load_robot(path)
    assert str(path) in str(exc.value) and str(tmp_path / "nao.urdf") in str(exc.value)
    assert pool.list() == []


def _replace(old, new):
    def edit(text):
        assert old in text
        return text.replace(old, new)

    return edit


@pytest.mark.parametrize(
    ("edit", "expected"),
    [
        (_replace('file = "nao.urdf"', 'file = "none.urdf"'), r"none\.urdf: no such file"),
        (_replace('gaze = "gaze"', 'gaze = "gazer"'), r"\[opPoints\] gaze: frame 'gazer'.*gaze"),
        (_replace('frame = "l_sole"', 'frame = "l_foot"'), r"\[feet.left\]: frame 'l_foot'"),
        (_replace("LKneePitch = 0.8", "LKneePitch = 2.5"), r"LKneePitch = 2\.5 is outside"),
        (_replace("LKneePitch = 0.8\n", ""), r"misses joint\(s\) LKneePitch"),
        (_replace("HeadYaw = 0.0", "HeadYow = 0.0"), r"'HeadYow' is not a 1-DoF joint.*HeadYaw"),
        (
            _replace("RHipYawPitch = 0.0", "RHipYawPitch = 0.1"),
            r"RHipYawPitch = 0\.1 violates the coupling",
        ),
        (_replace('RHipYawPitch = "LHipYawPitch"', 'RHipYawPitch = "LHip"'), "not a 1-DoF"),
        (_replace("[opPoints]", "[opPoint]"), r"unknown key\(s\) \['opPoint'\]"),
        (_replace('source = "urdf"', 'source = "sdf"'), "source must be one of"),
        (_replace("floating_base = true", "floating_base = 1"), "floating_base must be"),
        (_replace("0.0, 0.0, 0.0, 1.0]", "0.0, 0.0, 0.0, 2.0]"), "quaternion.*norm 2"),
        (_replace("length = 0.16\n", "length = -0.16\n"), r"\[feet.left\] length must be > 0"),
        (_replace("[halfSitting]\n", "[halfSitting\n"), "invalid TOML"),
        (
            _replace("[halfSitting]\nbase = [", 'halfSitting = "reference"\n[x]\nbase = ['),
            "unknown key",
        ),
    ],
)
def test_broken_description_is_a_clear_error(tmp_path, edit, expected):
    path = _nao_copy(tmp_path, edit)
    with pytest.raises(RobotDescriptionError, match=expected) as exc:
        load_robot(path)
    assert str(path) in str(exc.value)
    assert pool.list() == []


@pytest.mark.parametrize(
    ("robot", "edit", "expected"),
    [
        (
            "ur5",
            _replace('loader = "ur5"', 'loader = "ur6"'),
            "example-robot-data has no loader 'ur6'",
        ),
        (
            "panda",
            _replace("floating_base = false", "floating_base = true"),
            "floating_base = true but example-robot-data's 'panda' model has a fixed base",
        ),
    ],
)
def test_broken_example_robot_data_description(tmp_path, robot, edit, expected):
    path = tmp_path / "arm.toml"
    path.write_text(edit((ROBOTS_DIR / f"{robot}.toml").read_text()))
    with pytest.raises(RobotDescriptionError, match=expected):
        load_robot(path)
    assert pool.list() == []


def test_reference_posture_needs_an_srdf(tmp_path):
    def edit(text):
        head, rest = text.split("[halfSitting]", 1)
        rest = rest.split("[opPoints]", 1)[1]
        return head.replace("[model]", 'halfSitting = "reference"\n\n[model]') + "[opPoints]" + rest

    with pytest.raises(RobotDescriptionError, match="no SRDF reference configuration"):
        robot_summary(_nao_copy(tmp_path, edit))


def test_missing_description_file(tmp_path):
    with pytest.raises(RobotDescriptionError, match="no such file"):
        robot_info(tmp_path / "nothere.toml")


# -- geometry helpers -------------------------------------------------------------------
def test_convex_hull_matches_scipy():
    from scipy.spatial import ConvexHull

    rng = np.random.default_rng(0)
    for n in (3, 8, 30):
        for _ in range(20):
            pts = rng.standard_normal((n, 2))
            hull = convex_hull_2d(pts)
            ref = pts[ConvexHull(pts).vertices]  # counter-clockwise too
            assert {tuple(p) for p in hull} == {tuple(p) for p in ref}
            assert _area(hull) == pytest.approx(ConvexHull(pts).volume)
    # collinear points are dropped
    square = np.array([[0, 0], [1, 0], [0.5, 0], [1, 1], [0, 1], [0.5, 0.5]])
    assert {tuple(p) for p in convex_hull_2d(square)} == {(0, 0), (1, 0), (1, 1), (0, 1)}


def test_foot_corners():
    foot = Foot("left", "sole", length=0.2, width=0.1, offset=(0.01, -0.02, 0.0))
    c = foot.corners
    assert c.shape == (4, 3)
    np.testing.assert_allclose(c.mean(axis=0), [0.01, -0.02, 0.0])
    np.testing.assert_allclose(np.ptp(c, axis=0), [0.2, 0.1, 0.0])


# -- CLI --------------------------------------------------------------------------------
def test_cli_robots_prints_every_robot(capsys, summaries):
    assert main(["robots"]) == 0
    out = capsys.readouterr().out
    lines = {line.split()[0]: line for line in out.splitlines() if line.strip()}
    for name, (nv, _, actuated) in DOFS.items():
        assert name in lines
        cols = lines[name].split()
        assert cols[1:4] == [str(nv), str(actuated), "floating" if name in HUMANOIDS else "fixed"]
        for op, frame in robot_info(name)["opPoints"].items():
            assert f"{op}={frame}" in lines[name]
    assert "urdf:nao.urdf" in lines["nao"]
    assert "example-robot-data:talos" in lines["talos"]


# -- SoT's humanoid robot class: attributes and tracer helpers ---------------------------
def test_robot_has_the_humanoid_robot_class_attributes(tmp_path):
    from sotpy.dynamics import load_robot

    robot = load_robot("talos", prefix="h")
    assert robot.dimension == robot.model.nv == 38
    assert robot.OperationalPointsMap is robot.opPoints
    assert robot.OperationalPointsMap["left-ankle"] == "leg_left_6_joint"
    assert robot.OperationalPoints == tuple(robot.opPoints)
    with pytest.raises(AttributeError):
        robot.OperationalPoints.append("x")  # a tuple: not a silently lost list
    assert robot.pinocchioModel is robot.model and robot.pinocchioData is robot.dynamic.data
    robot.timeStep = 0.002
    assert robot.timeStep == robot.device.getTimeStep() == 0.002
    with pytest.raises(RobotError, match="dimension is nv = 38"):
        robot.dimension = 39
    assert list(robot.getActuatedJoints()) == list(range(6, 38))
    q = robot.halfSitting.copy()
    robot.setJointValueInConfig(q, ["arm_left_4_joint"], [-1.0])
    assert q[robot.model.joints[robot.model.getJointId("arm_left_4_joint")].idx_q] == -1.0
    with pytest.raises(RobotError, match="no joint named 'nope'"):
        robot.setJointValueInConfig(q, ["nope"], [0.0])
    robot.reset(q)
    np.testing.assert_allclose(robot.device.state.value, q)
    robot.initializeRobot()
    np.testing.assert_allclose(robot.device.state.value, robot.halfSitting)
    # the tracer: files named <entity>-<signal>, one row per increment, then forgotten
    robot.addTrace("h_device", "state")  # no tracer yet: nothing (SoT's rule)
    tr = robot.initializeTracer(str(tmp_path), "dg_", ".dat")
    robot.addTrace("h_device", "state")
    robot.addTrace("h_dynamic", "com")
    robot.startTracer()
    u = np.zeros(38)
    u[6:18] = 0.01  # the legs move: the rows differ from tick to tick
    robot.device.control.value = u
    for _ in range(3):
        robot.device.increment(0.002)
    robot.stopTracer()
    assert robot.tracer is None and tr.columns() == []
    state = np.loadtxt(tmp_path / "dg_h_device-state.dat", ndmin=2)
    com = np.loadtxt(tmp_path / "dg_h_dynamic-com.dat", ndmin=2)
    np.testing.assert_array_equal(state[:, 0], [1, 2, 3])
    np.testing.assert_allclose(state[-1, 1:], robot.device.state.value, atol=1e-15)
    np.testing.assert_allclose(com[-1, 1:], robot.dynamic.com.value, atol=1e-15)
    frame = robot.createFrame("tool", pin.SE3(np.eye(3), np.array([0.0, 0.0, 0.1])), "right-wrist")
    assert frame.position.value.isApprox(
        robot.dynamic.signal("right-wrist").value * pin.SE3(np.eye(3), np.array([0, 0, 0.1]))
    )
