"""The SoT compatibility layer (``sotpy run``): SoT scripts run unmodified, and do what
they do under the SoT.

The scripts of ``tests/sot_scripts`` are written as SoT users write theirs (they import
``dynamic_graph...`` and nothing from sotpy): the tutorial's pendulum (``simu.py``), a
Talos reaching script in the style of sot-talos (``talos_reach.py``) and a script with
its own robot class over a URDF and sot-application's solver (``romeo_application.py``).
Their physics is checked against independent computations: the C++ pendulum's step,
Pinocchio's forward kinematics of the final state, the traced files read back.
"""

from __future__ import annotations

import math
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest

import sotpy.compat as compat
from sotpy.cli import main
from sotpy.compat import UnsupportedFeature, UnsupportedModule
from sotpy.dynamics import load_model
from sotpy.graph import pool

SCRIPTS = Path(__file__).resolve().parent / "sot_scripts"
ROOT = Path(__file__).resolve().parents[1]


def _env() -> dict[str, str]:
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([str(ROOT / "src"), env.get("PYTHONPATH", "")])
    return env


def _sotpy_run(*args: str, timeout: float = 600) -> subprocess.CompletedProcess:
    """``sotpy run ...`` in a fresh interpreter (the CLI entry point)."""
    cmd = [sys.executable, "-m", "sotpy", "run", *args]
    return subprocess.run(cmd, capture_output=True, text=True, timeout=timeout, env=_env())


@pytest.fixture
def hook():
    """The hook installed for one test, removed after (and the pool cleared)."""
    compat.install()
    yield
    compat.uninstall()


def cpp_step(s, F, dt, M=1.0, m=1.0, ell=1.0, lam=0.1, g=9.81):
    """dynamic-graph-tutorial's InvertedPendulum step, from its equations."""
    x, th, dx, dth = s
    b1 = F - m * ell * dth**2 * math.sin(th) - lam * dx
    b2 = m * ell * g * math.sin(th) - lam * dth
    det = m * ell**2 * (M + m * math.sin(th) ** 2)
    ddx = (b1 * m * ell**2 + b2 * m * ell * math.cos(th)) / det
    ddth = ((M + m) * b2 + m * ell * math.cos(th) * b1) / det
    h = 0.5 * dt * dt
    return np.array(
        [x + dx * dt + ddx * h, th + dth * dt + ddth * h, dx + ddx * dt, dth + ddth * dt]
    )


# -- the hook --------------------------------------------------------------------------
def test_import_sotpy_does_not_install_the_hook(tmp_path):
    """A plain ``import sotpy`` leaves ``dynamic_graph`` alone: a real SoT installed beside
    it (here a stand-in package) is the one imported; ``install`` sets it aside for a run
    and ``uninstall`` brings it back."""
    fake = tmp_path / "site" / "dynamic_graph"
    fake.mkdir(parents=True)
    (fake / "__init__.py").write_text("REAL_SOT = True\n")
    code = textwrap.dedent(
        """
        import sys
        import sotpy, sotpy.graph, sotpy.dynamics, sotpy.tasks, sotpy.solvers, sotpy.cli
        import sotpy.compat
        assert not sotpy.compat.installed()
        assert not any(type(f).__name__ == "SoTFinder" for f in sys.meta_path)
        import dynamic_graph
        assert dynamic_graph.REAL_SOT
        sotpy.compat.install()
        import dynamic_graph as served
        assert not hasattr(served, "REAL_SOT") and served.plug is sotpy.graph.plug
        sotpy.compat.uninstall()
        import dynamic_graph as back
        assert back.REAL_SOT and not sotpy.compat.installed()
        print("ok")
        """
    )
    env = _env()
    env["PYTHONPATH"] = os.pathsep.join([str(tmp_path / "site"), env["PYTHONPATH"]])
    r = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, timeout=120, env=env
    )
    assert r.returncode == 0, r.stderr
    assert r.stdout.strip() == "ok"


def test_served_modules_are_sotpys_own(hook):
    import dynamic_graph
    import dynamic_graph.sot.core.meta_tasks_kine as mtk
    from dynamic_graph.sot.core.feature_point6d import FeaturePoint6d
    from dynamic_graph.sot.core.sot import SOT, Task

    import sotpy.solvers
    import sotpy.tasks

    assert SOT is sotpy.solvers.SOT and Task is sotpy.tasks.Task
    assert FeaturePoint6d is sotpy.tasks.FeaturePoint6d
    assert sys.modules["dynamic_graph.sot.core.meta_tasks_kine"] is mtk
    assert mtk is sys.modules["sotpy.compat.dynamic_graph.sot.core.meta_tasks_kine"]
    assert dynamic_graph.plug is sotpy.graph.plug


def test_what_is_not_served_raises_naming_the_sot_feature_and_the_equivalent(hook):
    with pytest.raises(UnsupportedModule, match=r"dynamic_graph\.ros.*sotpy serve") as info:
        import dynamic_graph.ros
    assert isinstance(info.value, ImportError)
    with pytest.raises(ImportError, match=r"dynamic_graph\.sot\.nope.*dynamic_graph\.sot\.core"):
        import dynamic_graph.sot.nope
    import dynamic_graph

    with pytest.raises(UnsupportedFeature, match=r"dynamic_graph\.enableTrace.*logging"):
        dynamic_graph.enableTrace(True, "/tmp/x")
    from dynamic_graph.sot.core.feature_posture import FeaturePosture
    from dynamic_graph.sot.pyrene.robot import Robot

    with pytest.raises(UnsupportedFeature, match=r"FeaturePosture\('fp'\) without a model"):
        FeaturePosture("fp")
    with pytest.raises(UnsupportedFeature, match=r"fromRosParam.*load_robot\('talos'\)"):
        Robot("talos", fromRosParam=True)
    assert not pool.hasEntity("talos_dynamic")
    from dynamic_graph.sot.core.meta_task_posture import MetaTaskKinePosture

    from sotpy.dynamics import load_robot

    robot = load_robot("talos")
    posture = MetaTaskKinePosture(robot.dynamic)
    with pytest.raises(UnsupportedFeature, match="HRP-2's velocity ranges"):
        posture.gotoq(1.0, None, rarm=[])


def test_entity_map_and_signal_names(hook):
    from dynamic_graph.entity import Entity
    from dynamic_graph.tutorial import InvertedPendulum

    a = InvertedPendulum("IP")
    assert Entity.entities["IP"] is a and "IP" in a.entities
    assert a.signal("state").getName() == "InvertedPendulum(IP)::output(vector)::state"
    with pytest.raises(TypeError):
        Entity.entities["x"] = a  # read-only


# -- the tutorial ----------------------------------------------------------------------
def test_tutorial_simu_stabilises_the_pendulum(tmp_path, capsys):
    """simu.py under ``sotpy run`` (in this process, through the CLI): its trajectory
    is the C++ model's with the tutorial's gain, and the pendulum is balanced."""
    out = tmp_path / "simu.npz"
    assert main(["run", str(SCRIPTS / "simu.py"), "3000", str(out)]) == 0
    assert "theta after 3 s:" in capsys.readouterr().out
    assert not compat.installed()  # removed after the run
    with np.load(out) as f:
        t, states, forces = f["time"], f["state"], f["force"]
    assert states.shape == (3000, 4) and t[-1] == pytest.approx(2.999)
    K = np.array([0.0, 27.0, 0.001, 0.001])
    s = np.array([0.0, 0.1, 0.0, 0.0])
    for k in range(3000):
        np.testing.assert_allclose(states[k], s, rtol=1e-9, atol=1e-12)
        assert forces[k] == pytest.approx(-K @ s)
        s = cpp_step(s, -K @ s, 1e-3)
    assert np.abs(states[:, 1]).max() <= 0.1  # it never leaned further than at the start
    assert abs(states[-1, 1]) < 0.01  # and is back upright after 3 s


def test_python_dash_m_sotpy_compat_runs_a_script():
    r = subprocess.run(
        [sys.executable, "-m", "sotpy.compat", str(SCRIPTS / "simu.py"), "100"],
        capture_output=True,
        text=True,
        timeout=300,
        env=_env(),
    )
    assert r.returncode == 0, r.stderr
    theta = float(r.stdout.split(":")[1].split()[0])
    assert 0.09 < theta < 0.1  # 0.1 s: still leaning, coming back
    r = subprocess.run(
        [sys.executable, "-m", "sotpy.compat"],
        capture_output=True,
        text=True,
        timeout=120,
        env=_env(),
    )
    assert r.returncode == 2 and "usage" in r.stdout


def test_run_reports_the_scripts_errors_and_exit_code(tmp_path, capsys):
    bad = tmp_path / "bad.py"
    bad.write_text("import dynamic_graph.ros\n")
    assert main(["run", str(bad)]) == 1
    assert "sotpy serve" in capsys.readouterr().err
    quits = tmp_path / "quits.py"
    quits.write_text("import sys\nsys.exit(3)\n")
    assert main(["run", str(quits)]) == 3
    assert main(["run", str(tmp_path / "missing.py")]) == 2
    assert not compat.installed()


# -- robot scripts ---------------------------------------------------------------------
def _read_trace(path: Path) -> np.ndarray:
    rows = np.loadtxt(path, delimiter="\t", ndmin=2)
    return rows


def test_talos_reaching_script(tmp_path):
    """talos_reach.py: the grip point (the opmodif, 10 cm along the wrist's x) at its
    target, the feet where they were, the CoM over them, the stack as edited, the
    traced files as the state went."""
    steps = 600
    r = _sotpy_run(str(SCRIPTS / "talos_reach.py"), str(tmp_path), str(steps))
    assert r.returncode == 0, r.stderr
    assert "stack: taskcontactRF taskcontactLF taskcom taskrh taskposture" in r.stdout
    res = np.load(tmp_path / "result.npz")
    # the grip point, from the final state by Pinocchio: wrist placement times the offset
    model = load_model("talos")[0]
    data = model.createData()
    q = res["state"]
    pin.framesForwardKinematics(model, data, q)
    wrist = data.oMf[model.getFrameId("arm_right_7_joint")]
    grip = wrist * pin.SE3(np.eye(3), np.array([0.1, 0.0, 0.0]))
    np.testing.assert_allclose(grip.homogeneous, res["grip"], atol=1e-12)
    assert np.linalg.norm(grip.translation - res["target"]) < 1e-4
    # without the offset the wrist itself is 10 cm away: opmodif was not ignored
    assert np.linalg.norm(wrist.translation - res["target"]) > 0.09
    # the feet held (their placements from Pinocchio too)
    for i, frame in enumerate(("leg_left_6_joint", "leg_right_6_joint")):
        M = data.oMf[model.getFrameId(frame)]
        np.testing.assert_allclose(M.homogeneous, res["feetBefore"][i], atol=1e-6)
    pin.centerOfMass(model, data, q)
    np.testing.assert_allclose(data.com[0][:2], res["comRef"][:2], atol=1e-6)
    # the traced files: one row per tick (ticks 1..steps), the last one the final state
    state = _read_trace(tmp_path / "dg_state.dat")
    com = _read_trace(tmp_path / "dg_com.dat")
    gripRows = _read_trace(tmp_path / "dg_grip.dat")
    for rows, width in ((state, model.nq), (com, 3), (gripRows, 16)):
        assert rows.shape == (steps, 1 + width)
        np.testing.assert_array_equal(rows[:, 0], np.arange(1, steps + 1))
    np.testing.assert_allclose(state[-1, 1:], q, rtol=0, atol=1e-15)
    np.testing.assert_allclose(gripRows[-1, 1:].reshape(4, 4), res["grip"], atol=1e-15)
    # each traced CoM is the CoM of the traced state (they were recorded together)
    for k in (0, steps // 2, steps - 1):
        pin.centerOfMass(model, data, state[k, 1:])
        np.testing.assert_allclose(com[k, 1:], data.com[0], atol=1e-12)


def test_romeo_application_script(tmp_path):
    """romeo_application.py: the user's robot class over the URDF, sot-application's
    solver through a JointLimitator, TaskJointLimits at the top, the left hand at its
    pose, the feet held, the joints within their limits, the robot's tracer files."""
    steps = 500
    r = _sotpy_run(str(SCRIPTS / "romeo_application.py"), str(tmp_path), str(steps))
    assert r.returncode == 0, r.stderr
    res = np.load(tmp_path / "result.npz")
    expected = ["taskJL", "taskcontactLF", "taskcontactRF", "taskcom", "tasklh", "taskposture"]
    assert list(res["stack"]) == expected and str(res["popped"]) == "taskposture"
    import xml.etree.ElementTree as ET

    import example_robot_data

    # the script's model, built here from the URDF: Romeo with its mimic joints locked
    urdf = example_robot_data.load_full("romeo")[2]
    full = pin.buildModelFromUrdf(urdf, pin.JointModelFreeFlyer())
    mimic = [
        j.get("name") for j in ET.parse(urdf).getroot().iter("joint") if j.find("mimic") is not None
    ]
    model = pin.buildReducedModel(full, [full.getJointId(n) for n in mimic], pin.neutral(full))
    assert mimic and model.nq == full.nq - len(mimic)
    data = model.createData()
    q = res["state"]
    assert q.shape == (model.nq,)
    pin.framesForwardKinematics(model, data, q)
    hand = data.oMf[model.getFrameId("LWristPitch")]
    np.testing.assert_allclose(hand.homogeneous, res["handM"], atol=1e-12)
    # the goal: x, y, z, roll, pitch, yaw with R = Rz(yaw) Ry(pitch) Rx(roll)
    goal = res["goal"]
    G = pin.SE3(pin.rpy.rpyToMatrix(*goal[3:]), goal[:3])
    np.testing.assert_allclose(res["goalM"], G.homogeneous, atol=1e-12)
    err = pin.log6(G.actInv(hand)).vector
    assert np.abs(err).max() < 1e-4
    for i, frame in enumerate(("LAnkleRoll", "RAnkleRoll")):
        M = data.oMf[model.getFrameId(frame)]
        np.testing.assert_allclose(M.homogeneous, res["feetBefore"][i], atol=1e-6)
    lo, up = res["lower"], res["upper"]
    joints = slice(7, model.nq)
    assert (q[joints] >= lo[joints] - 1e-9).all() and (q[joints] <= up[joints] + 1e-9).all()
    # the robot's tracer: <entity>-<signal> files of one row per tick
    state = _read_trace(tmp_path / "dg_romeo_device-state.dat")
    lh = _read_trace(tmp_path / "dg_romeo_dynamic-lh.dat")
    control = _read_trace(tmp_path / "dg_joint_limitator-control.dat")
    assert state.shape == (steps, 1 + model.nq) and lh.shape == (steps, 17)
    assert control.shape == (steps, 1 + model.nv)
    np.testing.assert_allclose(state[-1, 1:], q, atol=1e-15)
    np.testing.assert_allclose(lh[-1, 1:].reshape(4, 4), res["handM"], atol=1e-15)
    # each row's state follows the previous one by the traced control over one period
    dt = 0.005
    for k in (10, steps - 1):
        nxt = pin.integrate(model, state[k - 1, 1:], control[k - 1, 1:] * dt)
        np.testing.assert_allclose(nxt, state[k, 1:], atol=1e-9)


# -- the modules, one by one -----------------------------------------------------------
def test_matrix_util_against_pinocchio(hook):
    from dynamic_graph.sot.core import matrix_util as mu

    rng = np.random.default_rng(8)
    for k in range(5):
        tilt = 1e-9 * rng.standard_normal(3)
        r, p, y = rng.uniform(-1.5, 1.5, 3)
        M = np.array(mu.rpy2tr(r, p, y))
        np.testing.assert_allclose(M[:3, :3], pin.rpy.rpyToMatrix(r, p, y), atol=1e-14)
        pose = [*rng.uniform(-1, 1, 3), r, p, y]
        H = mu.RPYToMatrix(pose)
        np.testing.assert_allclose(H[:3, 3], pose[:3])
        np.testing.assert_allclose(mu.matrixToRPY(H), pose, atol=1e-12)
        np.testing.assert_allclose(mu.tr2rpy(H), [y, p, r], atol=1e-12)  # sot-core's order
        se3 = pin.SE3(H[:3, :3], H[:3, 3])
        assert mu.matrixToTuple(se3) == mu.matrixToTuple(H)  # a pinocchio.SE3 is a matrix
        for axis, R in (("x", pin.utils.rotate("x", r)), ("z", pin.utils.rotate("z", y))):
            np.testing.assert_allclose(
                np.array(mu.rotate(axis, r if axis == "x" else y))[:3, :3], R
            )
        q = rng.standard_normal(4)
        q /= np.linalg.norm(q)
        np.testing.assert_allclose(
            mu.quaternionToMatrix(q), pin.Quaternion(q[3], *q[:3]).toRotationMatrix(), atol=1e-14
        )
        # a random direction, a coordinate axis and directions within 1e-9 rad of one
        for v in (rng.standard_normal(3), np.eye(3)[k % 3], np.eye(3)[k % 3] + tilt):
            Q = np.array(mu.generateOrthonormalM(v))
            np.testing.assert_allclose(Q.T @ Q, np.eye(3), atol=1e-15)
            np.testing.assert_allclose(Q[:, 0], v / np.linalg.norm(v), atol=1e-15)
            assert np.linalg.det(Q) == pytest.approx(1.0, abs=1e-15)
            assert mu.generateOrthonormalM(v) == mu.generateOrthonormalM(v)  # not random
    for bad in ([0.0, 0.0, 0.0], [1.0, np.nan, 0.0], [1.0, 2.0]):
        with pytest.raises(ValueError, match="generateOrthonormalM: v1 must be"):
            mu.generateOrthonormalM(bad)
    assert mu.vectorToTuple(np.array([[1.0], [2.0]])) == (1.0, 2.0)
    assert mu.vectorToTuple(np.array([[1.0, 2.0]])) == (1.0, 2.0)
    assert mu.matrixToTuple(np.eye(2)) == ((1.0, 0.0), (0.0, 1.0))
    assert mu.distVector(np.eye(4), mu.RPYToMatrix([1, 2, 3, 0, 0, 0])) == [1.0, 2.0, 3.0]
    # at pitch = pi/2 the angles are not unique: yaw is 0, roll takes the rotation
    gimbal = mu.rpy2tr(0.0, math.pi / 2, 0.4)
    back = mu.matrixToRPY(gimbal)
    assert back[5] == 0.0 and back[4] == pytest.approx(math.pi / 2)
    np.testing.assert_allclose(mu.RPYToMatrix(back), gimbal, atol=1e-9)
    with pytest.raises(ValueError, match="axis"):
        mu.rotate("w", 1.0)


def test_sot_meta_tasks_semantics(hook):
    """SoT's MetaTaskKine6d: a FeaturePoint6d in the current frame whose reference is
    featureDes; gotoNd's 3-vector has the identity orientation; the posture's gotoq
    takes SoT's order and selects the joints it names."""
    from dynamic_graph.sot.core.meta_task_posture import MetaTaskKinePosture
    from dynamic_graph.sot.core.meta_tasks_kine import MetaTaskKine6d, gotoNd

    from sotpy.dynamics import load_robot
    from sotpy.tasks import FeaturePoint6d, Flags

    robot = load_robot("talos")
    rh = MetaTaskKine6d("rh", robot.dynamic, "rh", "arm_right_7_joint")
    assert rh.dynamic.hasSignal("rh") and isinstance(rh.featureDes, FeaturePoint6d)
    assert rh.featureDes.name == "featurerh_ref" and rh.feature.getFrame() == "current"
    assert rh.feature.reference.source is rh.featureDes.position
    gotoNd(rh, (0.4, -0.3, 1.0), "111", 1.0)
    M = rh.featureDes.position.value
    np.testing.assert_array_equal(M.rotation, np.eye(3))  # SoT's generic6dReference
    np.testing.assert_array_equal(M.translation, [0.4, -0.3, 1.0])
    assert rh.feature.selec.value == Flags("111") and rh.ref.isApprox(M)
    # current frame: the target seen from the hand, in the hand's axes
    W = robot.dynamic.signal("rh").value
    np.testing.assert_allclose(rh.feature.error.value, W.actInv(M).translation, atol=1e-12)
    rh.keep()
    assert rh.featureDes.position.value.isApprox(W)
    posture = MetaTaskKinePosture(robot.dynamic)
    q = robot.halfSitting.copy()
    posture.gotoq(2.0, q, arm_left_4_joint=-1.0, arm_left_1_joint=[])
    model = robot.model
    iv = [model.joints[model.getJointId(n)].idx_v for n in ("arm_left_1_joint", "arm_left_4_joint")]
    assert posture.feature.selec.value.rows(model.nv).tolist() == sorted(iv)
    k = model.joints[model.getJointId("arm_left_4_joint")].idx_q
    assert posture.ref[k] == -1.0 and posture.gain.gain.value == pytest.approx(2.0)
    q_sot = np.r_[q[:3], 0.0, 0.0, 0.1, q[7:]]  # SoT's roll-pitch-yaw configuration
    posture.featureDes.errorIN.value = q
    posture.ref = q_sot
    np.testing.assert_allclose(
        posture.ref[3:7], pin.Quaternion(pin.rpy.rpyToMatrix(0, 0, 0.1)).coeffs()
    )


def test_tracer_real_time_buffer_in_bytes(hook, tmp_path):
    from dynamic_graph.tracer_real_time import TracerRealTime
    from dynamic_graph.tutorial import InvertedPendulum

    a = InvertedPendulum("IP")
    tr = TracerRealTime("trace")
    assert tr.getBufferSize() == 1 << 20
    tr.setBufferSize(8 * 4 * 10)  # bytes per signal: 10 rows of 4 values
    tr.add("IP.state", "state")
    tr.open(str(tmp_path), "dg_", ".dat")
    tr.start()
    tr.triger.recompute(0)
    assert "1/10 rows" in tr.status()  # 10 rows: the bytes over 8-byte values of width 4
    tr.close()
    assert np.loadtxt(tmp_path / "dg_state.dat").shape == (5,)
    assert a.state.value.shape == (4,)


def test_dynamic_pinocchio_and_the_older_humanoid_robot(hook):
    from dynamic_graph.sot.dynamic_pinocchio import DynamicPinocchio, fromSotToPinocchio
    from dynamic_graph.sot.dynamic_pinocchio.humanoid_robot import HumanoidRobot

    model = load_model("talos")[0]
    d = DynamicPinocchio("d")
    with pytest.raises(UnsupportedFeature, match=r"before setModel.*d\.setModel"):
        d.position  # noqa: B018
    d.setModel(model)
    d.setData(model.createData())
    assert d.getDimension() == 38 and d.position is pool.getEntity("d").position
    q_sot = np.zeros(38)
    q_sot[2], q_sot[3:6] = 1.0, (0.1, -0.2, 0.3)
    q = fromSotToPinocchio(q_sot)
    R = pin.Quaternion(q[3:7]).toRotationMatrix()
    np.testing.assert_allclose(pin.rpy.matrixToRpy(R), [0.1, -0.2, 0.3], atol=1e-12)
    robot = HumanoidRobot("old", model, None, q_sot, {"left-wrist": "arm_left_7_joint"})
    np.testing.assert_allclose(robot.device.state.value, q, atol=1e-12)
    assert robot.dynamic.hasSignal("left-wrist") and robot.OperationalPoints == ["left-wrist"]
    assert robot.timeStep == 0.005


def test_the_sot_script_of_the_porting_page_runs(tmp_path, capsys):
    """docs/porting.md's SoT script, as printed there, under ``sotpy run``: the grip
    point reaches its target."""
    import ast
    import re
    import warnings

    from sotpy.errors import SotpyWarning

    page = (ROOT / "docs" / "porting.md").read_text()
    script = re.findall(r"```python\n(.*?)```", page, re.S)[0]
    assert script.startswith("from numpy import eye\n\nfrom dynamic_graph import plug")
    check = "\nprint([float(x) for x in taskRH.opPointModif.position.value.translation])\n"
    path = tmp_path / "appli.py"
    path.write_text(script + check)
    with warnings.catch_warnings():  # Talos' grippers rest on their limit: reported
        warnings.simplefilter("ignore", SotpyWarning)
        assert main(["run", str(path)]) == 0
    grip = np.array(ast.literal_eval(capsys.readouterr().out.strip().splitlines()[-1]))
    np.testing.assert_allclose(grip, [0.45, -0.3, 0.95], atol=1e-4)


def test_dynamic_graph_tools_add_trace(hook):
    from dynamic_graph.sot.pyrene.robot import Robot
    from dynamic_graph.tools import addTrace
    from dynamic_graph.tracer import Tracer

    robot = Robot("talos")
    tr = Tracer("tr")
    addTrace(robot, tr, "talos_dynamic", "com")
    assert tr.columns() == ["talos_dynamic-com"]  # the file name <entity>-<signal>
    assert "talos_dynamic.com" in robot.device.after.list()[-1]
    addTrace(robot, tr, "talos_device", "state", autoRecompute=False)
    assert tr.columns()[-1] == "talos_device-state" and len(robot.device.after.list()) == 1
