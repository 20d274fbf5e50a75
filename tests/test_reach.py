"""The humanoid reaching demo (``sotpy demo talos|romeo|nao``) and the robots' ready tasks.

Each robot runs the demo headless once (module fixture, 1 s of simulated time at 1 ms);
the run's configurations are then checked against independent computations: Pinocchio's
forward kinematics and centre of mass at every tick, the support polygon rebuilt from
``Robot.soleCorners`` with scipy's convex hull, the model's joint limits, the scalar
recursion of the wrist's adaptive gain, and (soak) scipy's SLSQP for a target out of
reach.
"""

from __future__ import annotations

import math
import subprocess
import sys

import numpy as np
import pinocchio as pin
import pytest
from scipy.optimize import minimize
from scipy.spatial import ConvexHull

from sotpy.cli import main
from sotpy.demos.reach import (
    FEET_TOLERANCE,
    REACH_OFFSETS,
    REACH_TOLERANCE,
    run_reach,
    wristDecay,
)
from sotpy.dynamics import load_model, load_robot
from sotpy.dynamics.robot import robot_info
from sotpy.errors import CommandError, EntityError, RobotError, SotpyError
from sotpy.graph import pool
from sotpy.tasks import (
    FeaturePose,
    Flags,
    MetaTaskKine6d,
    MetaTaskKineCom,
    MetaTaskKinePosture,
)
from sotpy.tasks.ready import (
    BALANCE_MARGIN,
    MetaTaskKineBalance,
    MetaTaskKineCouplings,
    SupportPolygon,
    polygonHalfPlanes,
)

ROBOTS = ("talos", "romeo", "nao")
DURATION = 1.0  # s: the wrist's gain brings 0.25 m to 4e-4 m (wristDecay)
DT = 1e-3


# -- helpers ---------------------------------------------------------------------------
def frame_of(robot: str, op: str) -> str:
    return robot_info(robot)["opPoints"][op]


def sole_frames(robot: str) -> dict[str, str]:
    return {side: f["frame"] for side, f in robot_info(robot)["feet"].items()}


def placements(model, q, frames):
    data = model.createData()
    pin.framesForwardKinematics(model, data, q)
    return {f: data.oMf[model.getFrameId(f)].copy() for f in frames}


def hull_ccw(points: np.ndarray) -> np.ndarray:
    """The convex hull's vertices, counter-clockwise (scipy, independent of sotpy)."""
    h = ConvexHull(points)
    return points[h.vertices]  # 2-D hulls come counter-clockwise


def edge_distances(vertices: np.ndarray, p: np.ndarray) -> np.ndarray:
    """Signed distance of ``p`` to each edge's line (positive inside), by cross products."""
    a = vertices
    e = np.roll(vertices, -1, axis=0) - a
    cross = e[:, 0] * (p[1] - a[:, 1]) - e[:, 1] * (p[0] - a[:, 0])
    return cross / np.linalg.norm(e, axis=1)


# -- the demo on each robot ------------------------------------------------------------
@pytest.fixture(scope="module", params=ROBOTS)
def reach(request):
    """(robot name, result of run_reach, model, half-sitting) for one headless run."""
    name = request.param
    result = run_reach(name, duration=DURATION, dt=DT, quiet=True)
    pool.clear()  # the checks below use the recorded configurations only
    model = load_model(name)[0]
    q0 = result["q"][0]
    return name, result, model, q0


def test_demo_checks_pass(reach):
    _, r, model, _ = reach
    assert r["ok"], r["table"]
    assert r["checks"] == dict.fromkeys(
        ("wrist", "feet", "com", "limits", "level1", "couplings"), True
    )
    assert r["ticks"] == round(DURATION / DT) and r["q"].shape == (r["ticks"] + 1, model.nq)
    assert r["levels"][0].startswith("joint limits") and len(r["residuals"][0]) == 4
    # the summary table: a row at 0, 0.1, 0.25, 0.5 s and at the end
    rows = [line.split() for line in r["summary"].splitlines()[1:]]
    assert [row[0] for row in rows] == ["0.000", "0.100", "0.250", "0.500", "1.000"]
    assert float(rows[-1][1]) == pytest.approx(r["wrist_final"], rel=1e-2)


def test_plot_shows_each_check_with_its_tolerance(reach, figure_check, tmp_path):
    """The figure of --plot: distances (m) and angles (rad) on separate axes, each
    tolerance a labelled line at its value, the CoM path in the polygon."""
    from sotpy.plotting import plot_reach

    name, r, _, _ = reach
    fig = plot_reach(r, tmp_path / "reach.png")
    assert (tmp_path / "reach.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    axes = figure_check(fig, f"{name} reaching")
    m, rad, com = axes["distances"], axes["angles"], axes["CoM over the support polygon"]
    assert m["ylabel"] == "distance [m]" and rad["ylabel"] == "angle [rad]"
    assert list(m["lines"]["reach tolerance 0.001 m"].get_ydata()) == [1e-3, 1e-3]
    assert list(m["lines"]["feet tolerance 1e-06 m"].get_ydata()) == [1e-6, 1e-6]
    assert list(rad["lines"]["feet tolerance 1e-06 rad"].get_ydata()) == [1e-6, 1e-6]
    np.testing.assert_array_equal(m["lines"]["wrist to target"].get_ydata(), r["errors"]["wrist"])
    assert ("coupling residual" in rad["lines"]) == (r["errors"]["couplings"] is not None)
    assert name != "nao" or "coupling residual" in rad["lines"]
    assert {"support polygon", "margin 0.01 m", "CoM projection", "start", "end"} <= set(
        com["lines"]
    )
    np.testing.assert_array_equal(com["lines"]["CoM projection"].get_xdata(), r["com"][:, 0])


def test_example_is_the_demo_as_a_script(capsys, monkeypatch):
    """examples/humanoid_reach.py builds the same graph in plain sight: it prints the
    demo's table, number for number."""
    import runpy
    from pathlib import Path

    script = Path(__file__).resolve().parents[1] / "examples" / "humanoid_reach.py"
    monkeypatch.setattr(sys, "argv", [str(script), "--robot", "nao", "--duration", "0.3"])
    with pytest.raises(SystemExit):
        runpy.run_path(str(script), run_name="__main__")
    example = capsys.readouterr().out
    pool.clear()
    demo = run_reach("nao", duration=0.3, quiet=True)
    assert demo["summary"] in example
    assert demo["table"].split("\n", 1)[1] in example  # the header names the robot's prefix


def test_wrist_reaches_the_target(reach):
    """Independent FK: the wrist starts 0.21-0.25 m from the target and ends within
    REACH_TOLERANCE (1 mm). Why that tolerance: with the wrist's task met every period,
    its distance follows the scalar recursion x' = (1 - g(x) dt) x of the adaptive gain
    (wristDecay), 4e-4 m after 1 s from 0.25 m; the closed loop follows it to 1 %
    (the difference is the second-order term of the integration), so 1 mm leaves a
    factor 2.5 and would catch a wrist slowed or stopped by a level above."""
    name, r, model, q0 = reach
    wrist = frame_of(name, "right-wrist")
    start = placements(model, q0, [wrist])[wrist].translation
    target = start + np.array(REACH_OFFSETS[name])
    np.testing.assert_allclose(r["target"], target, atol=1e-12)
    assert 0.2 <= np.linalg.norm(target - start) <= 0.3
    end = placements(model, r["q"][-1], [wrist])[wrist].translation
    final = np.linalg.norm(end - target)
    assert final == pytest.approx(r["wrist_final"], abs=1e-12)
    assert final <= REACH_TOLERANCE
    ode = wristDecay(np.linalg.norm(target - start), r["ticks"], DT)
    assert np.all(np.abs(r["errors"]["wrist"] - ode) <= 1e-2 * ode + 1e-9)
    assert ode[-1] <= 0.4 * REACH_TOLERANCE


def test_feet_stay_fixed(reach):
    """Independent FK of both soles at every tick: they stay within 1e-6 m and 1e-6 rad
    of where they started (measured: 2e-8 to 6e-8 m, 9e-8 rad)."""
    name, r, model, q0 = reach
    frames = list(sole_frames(name).values())
    start = placements(model, q0, frames)
    worst = np.zeros(2)
    data = model.createData()
    for q in r["q"]:
        pin.framesForwardKinematics(model, data, q)
        for f in frames:
            M, M0 = data.oMf[model.getFrameId(f)], start[f]
            worst = np.maximum(
                worst,
                [
                    np.linalg.norm(M.translation - M0.translation),
                    np.linalg.norm(pin.log3(M0.rotation.T @ M.rotation)),
                ],
            )
    assert worst[0] <= FEET_TOLERANCE and worst[1] <= FEET_TOLERANCE
    assert worst[0] == pytest.approx(r["feet_drift"][0], rel=1e-6, abs=1e-15)
    assert worst[0] > 0  # the legs moved (the base follows the arm), the soles did not


def test_com_stays_over_the_support_polygon(reach):
    """Independent: the polygon is scipy's hull of Robot.soleCorners at the start, the
    CoM is Pinocchio's centerOfMass of every recorded configuration; its projection
    stays at least the margin (1 cm) inside every edge, to the integration's 1e-6 m."""
    name, r, model, q0 = reach
    robot = load_robot(name, prefix="check")
    corners = robot.soleCorners(q0)
    polygon = hull_ccw(np.vstack([c[:, :2] for c in corners.values()]))
    data = model.createData()
    smallest = np.inf
    for q in r["q"]:
        c = pin.centerOfMass(model, data, q)
        smallest = min(smallest, edge_distances(polygon, c[:2]).min())
    assert smallest >= r["margin"] - 1e-6
    assert smallest == pytest.approx(r["com_distance"].min(), abs=1e-9)


def test_joints_stay_within_their_limits(reach):
    """Every one-DoF joint within model.lowerPositionLimit/upperPositionLimit at every
    tick, and every joint velocity within model.velocityLimit."""
    _, r, model, _ = reach
    iq, iv = [], []
    for j in range(1, model.njoints):
        jm = model.joints[j]
        if jm.nq == 1:
            iq.append(jm.idx_q)
            iv.append(jm.idx_v)
    q = r["q"][:, iq]
    assert np.all(q >= model.lowerPositionLimit[iq] - 1e-12)
    assert np.all(q <= model.upperPositionLimit[iq] + 1e-12)
    speed = np.abs(np.diff(q, axis=0)) / DT
    assert np.all(speed <= model.velocityLimit[iv] * (1 + 1e-9))
    assert np.all(r["joint_margin"] >= 0)


def test_level_one_is_met_all_along(reach):
    """Level 1 (feet, couplings, CoM) has no residual at any tick (it is an equality for
    the feet: any residual would move a sole), nor the hard joint-limit level."""
    name, r, model, _ = reach
    res = r["residuals"]
    assert np.isfinite(res).all()
    assert res[:, 0].max() <= 1e-9 and res[:, 1].max() <= 1e-9
    assert res[:, 2].max() <= 1e-9  # the wrist's level too (hence wristDecay)
    assert res[-1, 3] > 1e-3  # the posture cannot be: the arm is away from half-sitting
    if name == "nao":  # the HipYawPitch pair moved together
        iL = model.joints[model.getJointId("LHipYawPitch")].idx_q
        iR = model.joints[model.getJointId("RHipYawPitch")].idx_q
        assert np.abs(r["q"][:, iR] - r["q"][:, iL]).max() <= 1e-12
        assert np.ptp(r["q"][:, iL]) > 1e-5  # it moved (by 1e-4 rad: the wrist uses it a little)


# -- the CoM constraint when it is active -------------------------------------------------
def test_com_bound_holds_when_active():
    """Nao with a 6 cm margin: the CoM's projection reaches the shrunk polygon while the
    arm reaches (it starts 7 cm inside), stays on it (the balance rows are active: the
    solver's QP path), and the wrist still gets to the target."""
    r = run_reach("nao", duration=DURATION, margin=0.06, quiet=True)
    assert r["ok"], r["table"]
    d = r["com_distance"].min(axis=1)
    assert d[0] > 0.065
    assert d.min() >= 0.06 - 1e-6 and d.min() <= 0.06 + 1e-9  # active
    assert np.mean(np.abs(d - 0.06) < 1e-6) > 0.3  # on the bound for a third of the run
    assert r["wrist_final"] <= REACH_TOLERANCE


# -- bad arguments ---------------------------------------------------------------------
def test_bad_arguments_create_nothing():
    for kwargs in (
        {"duration": 0.0},
        {"dt": -1.0},
        {"margin": -0.01},
        {"contact_gain": 1.5},
        {"wrist_gain": (1.0, 2.0)},
    ):
        with pytest.raises(ValueError):
            run_reach("nao", quiet=True, **kwargs)
    assert pool.list() == []
    with pytest.raises(ValueError, match="target_offset"):
        run_reach("nao", quiet=True, target_offset=(0.1, 0.0))
    assert pool.list() == []
    with pytest.raises(RobotError, match="needs two feet"):
        run_reach("panda", quiet=True)
    assert pool.list() == []


# -- command line ----------------------------------------------------------------------
def test_cli_runs_the_demo_and_saves_a_plot(tmp_path, capsys):
    png = tmp_path / "reach.png"
    code = main(
        [
            "demo",
            "nao",
            "--duration",
            "0.6",
            "--target-offset",
            "0.05",
            "0",
            "0.05",
            "--plot",
            str(png),
        ]
    )
    out = capsys.readouterr().out
    assert code == 0, out
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and png.stat().st_size > 10_000
    assert "level 1: contact: both feet fixed + couplings + CoM" in out
    assert "wrist: reached the target" in out and "reach OK: nao, 600 ticks" in out
    # too short to get there: the check fails, exit code 1
    assert main(["demo", "nao", "--duration", "0.05"]) == 1
    assert "wrist: NOT reached" in capsys.readouterr().out
    assert main(["demo", "nao", "--dt", "0"]) == 2  # argparse refuses it
    assert main(["demo", "romeo", "--target-offset", "1", "2"]) == 2


# -- ready tasks -----------------------------------------------------------------------
def test_ready_tasks_are_created_once_on_access():
    robot = load_robot("nao", prefix="rt")
    before = set(pool.list())
    tasks = robot.tasks
    assert robot.tasks is tasks
    assert list(tasks) == [
        *robot.opPoints,
        "com",
        "posture",
        "balance",
        "couplings",
    ]
    assert "left-ankle" in tasks and "nope" not in tasks and len(tasks) == 11
    assert set(pool.list()) == before and tasks.created() == {}  # nothing created yet
    lf = tasks["left-ankle"]
    assert isinstance(lf, MetaTaskKine6d) and tasks["left-ankle"] is lf
    assert tasks.get("left-ankle") is lf and tasks.get("nope") is None
    assert set(pool.list()) - before == {
        "feature_rt_left-ankle",
        "task_rt_left-ankle",
        "gain_rt_left-ankle",
        "opmodif_rt_left-ankle",
    }
    assert isinstance(tasks["com"], MetaTaskKineCom)
    assert isinstance(tasks["posture"], MetaTaskKinePosture)
    assert isinstance(tasks["balance"], MetaTaskKineBalance)
    assert isinstance(tasks["couplings"], MetaTaskKineCouplings)
    assert list(tasks.created()) == ["left-ankle", "com", "posture", "balance", "couplings"]
    assert isinstance(lf.feature, FeaturePose) and lf.feature.selec.value == Flags("111111")
    assert lf.task.controlGain.value == pytest.approx(0.1)  # the meta-tasks' default


def test_ready_tasks_hold_what_there_is_when_created():
    """keep(): zero error at creation, the reference equal to Pinocchio's placement of
    the op point's frame then; a task created later holds the later placement."""
    robot = load_robot("talos", prefix="keep")
    model, device = robot.model, robot.device
    q0 = robot.halfSitting
    for key in ("left-ankle", "right-wrist", "gaze"):
        meta = robot.tasks[key]
        np.testing.assert_allclose(meta.task.error.value, np.zeros(6), atol=1e-15)
        frame = robot.opPoints[key]
        M = placements(model, q0, [frame])[frame]
        assert meta.ref.isApprox(M, 1e-12)
    com = robot.tasks["com"]
    np.testing.assert_allclose(com.task.error.value, np.zeros(2), atol=1e-15)  # x, y
    np.testing.assert_allclose(com.ref, pin.centerOfMass(model, model.createData(), q0))
    np.testing.assert_allclose(robot.tasks["posture"].task.error.value, 0.0, atol=1e-15)
    # move the robot: the tasks created before keep their reference, a new one holds now
    q1 = q0.copy()
    j = model.joints[model.getJointId("arm_left_4_joint")]
    q1[j.idx_q] -= 0.3
    device.set(q1)
    assert np.linalg.norm(robot.tasks["gaze"].task.error.value) <= 1e-15  # head: same place
    lw = robot.tasks["left-wrist"]
    np.testing.assert_allclose(lw.task.error.value, np.zeros(6), atol=1e-15)
    frame = robot.opPoints["left-wrist"]
    assert lw.ref.isApprox(placements(model, q1, [frame])[frame], 1e-12)
    assert not lw.ref.isApprox(placements(model, q0, [frame])[frame], 1e-6)
    assert np.linalg.norm(robot.tasks["com"].task.error.value) > 1e-4  # the CoM moved
    posture = robot.tasks["posture"].task.error.value
    assert posture[j.idx_v - 6] == pytest.approx(-0.3)  # q - q*, towards half-sitting


def test_two_robots_do_not_collide():
    a = load_robot("nao", prefix="nao_a")
    b = load_robot("nao", prefix="nao_b")
    la, lb = a.tasks["left-wrist"], b.tasks["left-wrist"]
    assert la is not lb and la.task.name == "task_nao_a_left-wrist"
    assert lb.task.name == "task_nao_b_left-wrist"
    assert a.tasks["com"].featureDes.name == "featureDes_nao_a_com"
    assert a.tasks["balance"].polygon.name == "polygon_nao_a_balance"
    assert b.tasks["balance"].task.name == "task_nao_b_balance"
    # each task follows its own robot
    q = a.halfSitting.copy()
    q[a.model.joints[a.model.getJointId("LShoulderPitch")].idx_q] -= 0.5
    a.device.set(q)
    assert np.linalg.norm(la.task.error.value) > 0.01
    assert np.linalg.norm(lb.task.error.value) <= 1e-15


def test_unknown_key_is_an_error_listing_the_keys():
    robot = load_robot("panda", prefix="arm")
    before = pool.list()
    with pytest.raises(RobotError) as info:
        robot.tasks["left-ankle"]
    msg = str(info.value)
    assert "'panda'" in msg and "'left-ankle'" in msg
    assert "available: end-effector, wrist, com, posture, couplings" in msg
    assert "balance" not in msg  # no feet; the fingers' mimic joint is a coupling
    assert pool.list() == before
    # an arm still has its op points, CoM and posture
    assert robot.tasks["end-effector"].task.error.value.shape == (6,)


def test_dynamics_does_not_import_tasks():
    """The layers of docs/architecture.md: loading a robot imports no task module;
    robot.tasks does."""
    code = (
        "import sys\n"
        "from sotpy.dynamics import load_robot\n"
        "r = load_robot('nao')\n"
        "assert not any(m.startswith('sotpy.tasks') for m in sys.modules), 'imported'\n"
        "r.tasks\n"
        "assert 'sotpy.tasks.ready' in sys.modules\n"
    )
    subprocess.run([sys.executable, "-c", code], check=True, timeout=120)


# -- the entities of balance and couplings ---------------------------------------------
def test_balance_is_the_com_against_the_polygon_edges():
    """SupportPolygon's value and Jacobian: N c_xy against an independent hull and
    centre of mass, and the Jacobian against central differences of it."""
    robot = load_robot("nao", prefix="bal")
    model, q0 = robot.model, robot.halfSitting
    balance = robot.tasks["balance"]
    assert balance.margin == BALANCE_MARGIN
    polygon = hull_ccw(np.vstack([c[:, :2] for c in robot.soleCorners(q0).values()]))
    data = model.createData()
    c = pin.centerOfMass(model, data, q0)
    d = balance.distances()
    assert np.sort(d) == pytest.approx(np.sort(edge_distances(polygon, c[:2])), abs=1e-12)
    np.testing.assert_allclose(
        balance.task.referenceSup.value, balance.polygon.getOffsets() - BALANCE_MARGIN
    )
    # the Jacobian, at a configuration away from half-sitting, along random directions
    rng = np.random.default_rng(7)
    q = pin.integrate(model, q0, 0.2 * rng.standard_normal(model.nv))
    robot.device.set(q)
    N = balance.polygon.getNormals()
    J = balance.feature.jacobian.value
    np.testing.assert_allclose(
        balance.feature.error.value, N @ pin.centerOfMass(model, data, q)[:2]
    )
    eps = 1e-6
    for _ in range(3):
        v = rng.standard_normal(model.nv)
        plus = N @ pin.centerOfMass(model, data, pin.integrate(model, q, eps * v))[:2]
        minus = N @ pin.centerOfMass(model, data, pin.integrate(model, q, -eps * v))[:2]
        np.testing.assert_allclose(J @ v, (plus - minus) / (2 * eps), atol=1e-7)
    balance.setMargin(0.03)
    np.testing.assert_allclose(balance.task.referenceSup.value, balance.polygon.getOffsets() - 0.03)
    with pytest.raises(CommandError, match="margin"):
        balance.setMargin(-1.0)


def test_couplings_task_is_the_residual():
    robot = load_robot("nao", prefix="cpl")
    model = robot.model
    meta = robot.tasks["couplings"]
    assert meta.couplings.list() == ["RHipYawPitch = 1 * LHipYawPitch + 0"]
    iL = model.joints[model.getJointId("LHipYawPitch")]
    iR = model.joints[model.getJointId("RHipYawPitch")]
    J = meta.task.jacobian.value
    expected = np.zeros((1, model.nv))
    expected[0, iR.idx_v], expected[0, iL.idx_v] = 1.0, -1.0
    np.testing.assert_array_equal(J, expected)
    q = robot.halfSitting.copy()
    q[iR.idx_q] += 0.2
    robot.device.set(q)
    assert meta.task.error.value == pytest.approx([0.2])
    assert meta.task.task.value == pytest.approx([-0.2])  # gain 1 1/s


def test_polygon_half_planes():
    square = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])
    N, b = polygonHalfPlanes(square)
    np.testing.assert_allclose(N, [[0, -1], [1, 0], [0, 1], [-1, 0]], atol=1e-15)
    np.testing.assert_allclose(b, [0, 1, 1, 0], atol=1e-15)
    for bad, match in (
        (square[::-1], "counter-clockwise"),
        (square[:2], "k >= 3"),
        (np.array([[0, 0], [1, 0], [1, 0], [0, 1.0]]), "zero length"),
        (np.array([[0, 0], [2, 0], [1, 0.2], [2, 1], [0, 1.0]]), "convex"),
    ):
        with pytest.raises(ValueError, match=match):
            polygonHalfPlanes(bad)
    p = SupportPolygon("reach_polygon")
    with pytest.raises(CommandError, match=r"SupportPolygon\(reach_polygon\).setPolygon"):
        p.setPolygon(square[::-1])
    p.com.value = [0.5, 0.25, 1.0]
    p.Jcom.value = np.eye(3)
    with pytest.raises(SotpyError, match="no polygon set"):
        p.value.value  # noqa: B018
    p.setPolygon(square)
    np.testing.assert_allclose(p.distances.value, [0.25, 0.5, 0.75, 0.5])
    dyn = load_robot("nao", prefix="dup").dynamic
    MetaTaskKineBalance(dyn, square, name="_dup_x")
    with pytest.raises(EntityError, match="already exist"):
        MetaTaskKineBalance(dyn, square, name="_dup_x")


# -- a target out of reach (soak: the QP path costs ~10 ms per tick here) ---------------
@pytest.mark.soak
def test_out_of_reach_stops_at_the_best_reachable_point():
    """Nao asked for a point 0.36 m away, forward and low: the CoM reaches its bound and
    the wrist stops 2.8 cm short. scipy's SLSQP, minimising the wrist's distance subject
    to both soles at their start placements, the coupling, the CoM inside the shrunk
    polygon and the joint limits, cannot do better from the final configuration (or the
    closest one it converges from: SLSQP sometimes stalls on rounding noise) and finds
    the same value from a configuration of the way there."""
    offset = (0.35, 0.0, 0.1)
    r = run_reach("nao", duration=2.0, target_offset=offset, damping=1e-2, quiet=True)
    assert r["out_of_reach"] and not r["reached"]
    assert r["checks"]["wrist"] and r["checks"]["com"] and r["checks"]["limits"]
    # measured: 1.3e-6 m and 3e-6 rad while the CoM hits its bound at full arm speed
    assert r["feet_drift"][0] <= 1e-5 and r["feet_drift"][1] <= 1e-5
    model = load_model("nao")[0]
    data = model.createData()
    q0, qs = r["q"][0], r["q"]
    soles = list(sole_frames("nao").values())
    wrist = model.getFrameId(frame_of("nao", "right-wrist"))
    start = placements(model, q0, soles)
    robot = load_robot("nao", prefix="oor")
    polygon = hull_ccw(np.vstack([c[:, :2] for c in robot.soleCorners(q0).values()]))
    iL = model.joints[model.getJointId("LHipYawPitch")].idx_q
    iR = model.joints[model.getJointId("RHipYawPitch")].idx_q
    target = r["target"]

    def best_from(base: np.ndarray) -> float | None:
        """SLSQP's best distance from ``base``, or None when it stops without
        convergence (e.g. "Positive directional derivative for linesearch": a stall on
        rounding noise that the last bits of the start decide)."""

        def q_of(dq):
            return pin.integrate(model, base, dq)

        def distance2(dq):
            pin.framesForwardKinematics(model, data, q_of(dq))
            e = data.oMf[wrist].translation - target
            return float(e @ e)

        def equalities(dq):
            q = q_of(dq)
            pin.framesForwardKinematics(model, data, q)
            rows = [
                pin.log6(start[f].inverse() * data.oMf[model.getFrameId(f)]).vector for f in soles
            ]
            return np.concatenate([*rows, [q[iR] - q[iL]]])

        def inside(dq):
            c = pin.centerOfMass(model, data, q_of(dq))
            return edge_distances(polygon, c[:2]) - r["margin"]

        bounds = [(None, None)] * model.nv
        for j in range(2, model.njoints):
            jm = model.joints[j]
            lo = model.lowerPositionLimit[jm.idx_q] - base[jm.idx_q]
            bounds[jm.idx_v] = (lo, model.upperPositionLimit[jm.idx_q] - base[jm.idx_q])
        res = minimize(
            distance2,
            np.zeros(model.nv),
            method="SLSQP",
            bounds=bounds,
            constraints=[{"type": "eq", "fun": equalities}, {"type": "ineq", "fun": inside}],
            options={"maxiter": 500, "ftol": 1e-14},
        )
        if not res.success:
            return None
        assert np.abs(equalities(res.x)).max() <= 1e-9 and inside(res.x).min() >= -1e-9
        return math.sqrt(res.fun)

    def best_near(index: int) -> float:
        """From the configuration of tick ``index``, or the closest earlier ones on which
        SLSQP converges (each a point of the run, all near the same local optimum)."""
        for k in (index, index - 1, index - 3, index - 10):
            value = best_from(qs[k])
            if value is not None:
                return value
        pytest.fail(f"SLSQP did not converge from the configurations near tick {index}")

    best = best_near(len(qs) - 1)
    assert r["wrist_final"] <= best + 1e-4  # the demo's point is (locally) the best
    assert best <= r["wrist_final"] + 1e-9
    assert best_near(300) == pytest.approx(best, abs=1e-5)


def test_viewer_is_closed_at_the_end():
    pytest.importorskip("meshcat")
    try:
        r = run_reach("nao", duration=0.05, viewer=True, quiet=True)
    except SotpyError as exc:
        if "RobotViewer" in str(exc):
            pytest.skip(f"meshcat cannot start here: {exc}")
        raise
    assert r["viewer_url"].startswith("http://127.0.0.1:")
    assert "viewer: the page replays the 0.05 s motion at real time" in r["table"]
    viewer = pool.getEntity(f"{r['prefix']}_viewer")
    assert not viewer.isOpen()
    assert pool.getEntity(f"{r['prefix']}_device").after.list() == []
    with pytest.raises(OSError):
        open(f"/proc/{r['viewer_pid']}/cmdline").close()  # the server process has ended
