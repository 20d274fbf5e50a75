"""The robot tour (``sotpy demo robot``): JointSineVelocity's velocities integrate to the
sine of its documented formula, its amplitudes keep every joint inside its limits, the
joint chains are the joints that move the frames, the tour keeps the feet still and
moves the wrist, the CLI prints the table and returns 0, and with ``--viewer`` no
meshcat server survives the run (nor a Ctrl-C).

The references are independent: the closed form of the Euler sum of cosines, Pinocchio's
forward kinematics at the device's final configuration, and brute-force sums.
"""

from __future__ import annotations

import math
import os
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest

import sotpy.demos.robot_tour as robot_tour
from sotpy.cli import build_parser, main
from sotpy.demos.robot_tour import (
    SAFETY,
    JointSineVelocity,
    chainJoints,
    run_robot_tour,
    sineExcursion,
)
from sotpy.dynamics import load_robot
from sotpy.errors import CommandError, EntityError, SotpyError
from sotpy.graph import Entity, plug, pool
from sotpy.viewer import RobotViewer

DT = 1e-3


class RobotTourUserEntity(Entity):
    """Stands for an entity the user created before running the tour."""


# -- helpers ---------------------------------------------------------------------------
def joint_index(model: pin.Model, name: str) -> tuple[int, int]:
    j = model.joints[model.getJointId(name)]
    return j.idx_q, j.idx_v


def expected_amplitude(model, q0, name, A, f, dt) -> float:
    """A_j = min(A, 0.9 margin / kappa(w dt), 0.9 vmax / w) from the model's limits
    (kappa is checked against brute-force sums by the first test)."""
    iq, iv = joint_index(model, name)
    w = 2 * math.pi * f
    kappa = sineExcursion(w * dt)
    margin = min(q0[iq] - model.lowerPositionLimit[iq], model.upperPositionLimit[iq] - q0[iq])
    return min(A, SAFETY * margin / kappa, SAFETY * model.velocityLimit[iv] / w)


def frame_placement(model: pin.Model, q: np.ndarray, frame: str) -> pin.SE3:
    data = model.createData()
    pin.framesForwardKinematics(model, data, q)
    return data.oMf[model.getFrameId(frame)].copy()


def meshcat_children() -> list[int]:
    """Processes started by this one whose command line mentions meshcat."""
    me, found = os.getpid(), []
    for d in Path("/proc").iterdir():
        if not d.name.isdigit():
            continue
        try:
            stat = (d / "stat").read_text()
            cmd = (d / "cmdline").read_bytes()
        except OSError:
            continue
        ppid = int(stat.rsplit(")", 1)[1].split()[1])
        if ppid == me and b"meshcat" in cmd:
            found.append(int(d.name))
    return found


@pytest.fixture(scope="module")
def nao_model():
    """Nao's model (no entity): loads in a few ms."""
    from sotpy.dynamics import load_model
    from sotpy.dynamics.robot import robot_summary

    model = load_model("nao")[0]
    return model, robot_summary("nao")["halfSitting"]


# -- maths -----------------------------------------------------------------------------
@pytest.mark.parametrize("h", [1e-3, 0.05, 0.5, 1.5, 3.0])
def test_sine_excursion_is_the_sup_of_the_euler_sum(h):
    n = int(40 * math.pi / h) + 50  # twenty periods
    sums = np.concatenate(([0.0], np.cumsum(np.cos(np.arange(n) * h)) * h))
    largest = np.max(np.abs(sums))
    kappa = sineExcursion(h)
    assert largest <= kappa + 1e-12
    assert largest >= kappa - 1e-3 * h  # the bound is reached (to the sampling of N)
    assert kappa == pytest.approx(1 + h / 2 + h**2 / 24, abs=h**3)  # the documented expansion
    for bad in (0.0, -0.1, math.pi, 4.0):
        with pytest.raises(ValueError):
            sineExcursion(bad)


def test_chains_are_the_joints_that_move_the_frames(nao_model):
    model, q0 = nao_model
    frames = ["r_gripper", "gaze", "l_sole"]
    assert chainJoints(model, ["r_gripper"]) == [
        "RShoulderPitch",
        "RShoulderRoll",
        "RElbowYaw",
        "RElbowRoll",
        "RWristYaw",
    ]
    # independent: a 1-DoF joint is on a frame's chain iff moving it moves the frame
    for frame in frames:
        before = frame_placement(model, q0, frame)
        moving = []
        for j in range(1, model.njoints):
            if model.joints[j].nq != 1:
                continue
            q = q0.copy()
            q[model.joints[j].idx_q] += 1e-3
            after = frame_placement(model, q, frame)
            if not after.isApprox(before, 1e-12):
                moving.append(model.names[j])
        assert chainJoints(model, [frame]) == moving, frame
    union = chainJoints(model, frames)
    assert set(union) == set().union(*(chainJoints(model, [f]) for f in frames))
    with pytest.raises(KeyError, match=r"r_griper.*r_gripper"):
        chainJoints(model, ["r_griper"])


# -- the control entity ----------------------------------------------------------------
def test_velocities_integrate_to_the_expected_sine():
    robot = load_robot("nao", prefix="sine")
    model, device, q0 = robot.model, robot.device, robot.halfSitting
    device.setControlType("velocity")
    A, f = 0.2, 0.7
    sine = JointSineVelocity("sine_control", model, q0, DT)
    joints = sine.selectJoints(["*Shoulder*", "HeadYaw"], ["LShoulderRoll"])
    assert joints == ["HeadYaw", "LShoulderPitch", "RShoulderPitch", "RShoulderRoll"]
    sine.setAmplitude(A)
    sine.setFrequency(f)
    plug(sine.control, device.control)
    # start at tick 25 (the device idles before): the phase counts from the start tick
    sine.setAmplitude(0.0)
    for _ in range(25):
        device.increment(DT)
    assert np.array_equal(device.state.value, q0)
    sine.setStartTick(device.state.time)
    sine.setAmplitude(A)

    amps = sine.getAmplitudes()
    w, h, N = 2 * math.pi * f, 2 * math.pi * f * DT, 900
    for _ in range(N):
        device.increment(DT)
    q = device.state.value
    moved = np.zeros(model.nq, dtype=bool)
    for name in joints:
        iq, iv = joint_index(model, name)
        moved[iq] = True
        a = expected_amplitude(model, q0, name, A, f, DT)
        assert amps[iv] == pytest.approx(a, rel=1e-12)
        # the closed form of the Euler sum: A h sin(N h / 2) cos((N - 1) h / 2) / sin(h / 2)
        exact = a * h * math.sin(N * h / 2) * math.cos((N - 1) * h / 2) / math.sin(h / 2)
        assert q[iq] - q0[iq] == pytest.approx(exact, abs=1e-12)
        # the continuous sine, to the integration error A h (1 + h^2 / 100), h = w dt
        err = q[iq] - (q0[iq] + a * math.sin(w * N * DT))
        assert abs(err) <= a * h * (1 + h**2 / 100)
        assert abs(err) >= 0.1 * a * h  # (it is an Euler error, not zero)
    assert amps[joint_index(model, "HeadYaw")[1]] == A  # far from its limits: the full A
    # everything else, the free-flyer included, did not move at all
    assert np.array_equal(q[~moved], q0[~moved])
    assert np.count_nonzero(amps) == len(joints)
    assert device.boundsReport()["position"]["count"] == 0


def test_amplitudes_keep_every_joint_inside_its_limits(nao_model):
    """A = 3 rad on every joint of Nao for one full period at 1 Hz: each joint uses at
    most 0.9 of its distance to its limits (and the limiting ones nearly all of it)."""
    robot = load_robot("nao", prefix="wide")
    model, device, q0 = robot.model, robot.device, robot.halfSitting
    device.setControlType("velocity")
    sine = JointSineVelocity("wide_control", model, q0, DT)
    assert len(sine.getJoints()) == 26  # every 1-DoF joint by default
    sine.setAmplitude(3.0)
    sine.setFrequency(1.0)
    plug(sine.control, device.control)
    lo, hi = model.lowerPositionLimit, model.upperPositionLimit
    names = list(model.names[2:])  # after the universe and the free-flyer
    iq = np.array([joint_index(model, n)[0] for n in names])
    iv = np.array([joint_index(model, n)[1] for n in names])
    margin = np.minimum(q0[iq] - lo[iq], hi[iq] - q0[iq])
    expected = np.array([expected_amplitude(model, q0, n, 3.0, 1.0, DT) for n in names])
    np.testing.assert_allclose(sine.getAmplitudes()[iv], expected, rtol=1e-12)
    excursion = np.zeros(len(iq))
    for _ in range(1000):
        device.increment(DT)  # a clamp would warn, and pytest turns warnings into errors
        excursion = np.maximum(excursion, np.abs(device.state.value[iq] - q0[iq]))
    assert all(b["count"] == 0 for b in device.boundsReport().values())
    assert np.all(excursion <= SAFETY * margin + 1e-12)
    assert np.all(excursion >= expected * (1 - 2 * math.pi * DT))  # sin reached +-1
    # most joints are cut by their position limits, and then use 0.9 of their margin
    kappa = sineExcursion(2 * math.pi * DT)
    by_margin = np.isclose(expected, SAFETY * margin / kappa, rtol=1e-12)
    assert by_margin.sum() >= 10 and (expected < 3.0).all()
    assert np.all(excursion[by_margin] >= 0.99 * SAFETY * margin[by_margin])


def test_bad_commands_are_refused_and_change_nothing(nao_model):
    model, q0 = nao_model
    sine = JointSineVelocity("bad_control", model, q0, DT)
    sine.setAmplitude(0.25)
    before = sine.getAmplitudes()
    for call, match in (
        (lambda: sine.setAmplitude(-0.1), "amplitude must be a finite value >= 0"),
        (lambda: sine.setAmplitude(math.inf), "amplitude"),
        (lambda: sine.setFrequency(0.0), "frequency must be"),
        (lambda: sine.setFrequency(500.0), "Nyquist frequency 1 / \\(2 dt\\) = 500 Hz"),
        (lambda: sine.setTimeStep(2.0), "Nyquist"),
        (lambda: sine.setTimeStep(-1e-3), "dt must be"),
        (lambda: sine.selectJoints(["LElbow*", "LWristPich"]), "'LWristPich'.*LWristYaw"),
        (lambda: sine.selectJoints(3), "expected a list of strings"),
        (lambda: sine.selectChains(["r_griper"]), "no frame 'r_griper'.*r_gripper"),
        (lambda: sine.setReference(q0[:-1]), "size nq = 33"),
    ):
        with pytest.raises(CommandError, match=match) as info:
            call()
        assert "JointSineVelocity(bad_control)" in str(info.value)
    assert sine.getAmplitude() == 0.25 and sine.getFrequency() == 0.4
    assert sine.getTimeStep() == DT
    assert np.array_equal(sine.getAmplitudes(), before)
    assert len(sine.getJoints()) == 26
    out = q0.copy()
    out[joint_index(model, "LKneePitch")[0]] = 3.0
    with pytest.raises(EntityError, match="LKneePitch = 3 not in"):
        JointSineVelocity("out_control", model, out, DT)
    assert not pool.hasEntity("out_control")


def test_control_follows_the_formula_at_any_tick(nao_model):
    model, q0 = nao_model
    sine = JointSineVelocity("formula_control", model, q0, 2e-3)
    sine.selectJoints(["HeadYaw"])
    sine.setFrequency(0.3)
    sine.setAmplitude(0.5)
    sine.setStartTick(7)
    iv = joint_index(model, "HeadYaw")[1]
    w = 2 * math.pi * 0.3
    for t in (7, 8, 100, 1234):
        v = sine.control(t)
        assert v.shape == (model.nv,)
        assert v[iv] == pytest.approx(0.5 * w * math.cos(w * (t - 7) * 2e-3), abs=1e-15)
        assert np.count_nonzero(v) == 1
    sine.setAmplitude(0.1)  # takes effect at the same tick
    assert sine.control(1234)[iv] == pytest.approx(0.1 * w * math.cos(w * 1227 * 2e-3))


# -- the tour --------------------------------------------------------------------------
def test_nao_tour_keeps_the_feet_still_and_moves_the_wrist(nao_model):
    model, q0 = nao_model
    user = RobotTourUserEntity("mine")
    first = run_robot_tour("nao", duration=0.5, quiet=True)
    second = run_robot_tour("nao", duration=0.5, quiet=True)  # same pool, later ticks
    assert pool.getEntity("mine") is user  # the user's pool is not cleared
    assert (first["prefix"], second["prefix"]) == ("tour_nao", "tour_nao_2")
    assert first["ok"] and second["ok"]
    assert first["feet_fixed"] and first["feet_drift"] <= 1e-9
    assert first["bounds_ok"] and first["couplings_ok"]
    legs = chainJoints(model, ["l_sole", "r_sole"])
    assert not set(first["joints"]) & set(legs)
    assert {"HeadYaw", "HeadPitch", "LWristYaw", "RShoulderPitch"} <= set(first["joints"])

    for result in (first, second):
        device = pool.getEntity(f"{result['prefix']}_device")
        q = device.state.value
        # independent kinematics: soles where they were, wrist moved by more than 1 cm
        for sole in ("l_sole", "r_sole"):
            a, b = frame_placement(model, q0, sole), frame_placement(model, q, sole)
            assert np.linalg.norm(b.translation - a.translation) <= 1e-9
            assert np.linalg.norm(pin.log3(a.rotation.T @ b.rotation)) <= 1e-9
        wrist = frame_placement(model, q, "RWristYaw").translation
        start = frame_placement(model, q0, "RWristYaw").translation
        assert np.linalg.norm(wrist - start) > 0.01
        assert result["wrist_travel"] >= np.linalg.norm(wrist - start) - 1e-12
        np.testing.assert_allclose(result["path"][-1, 1:4], wrist, atol=1e-12)
    # the second tour started at a later tick and still swung from phase 0
    q1 = pool.getEntity("tour_nao_device").state.value
    q2 = pool.getEntity("tour_nao_2_device").state.value
    np.testing.assert_allclose(q2, q1, atol=1e-12)


def test_plot_shows_the_joints_between_their_limits(figure_check, tmp_path):
    from sotpy.plotting import plot_robot_tour

    result = run_robot_tour("nao", duration=0.5, quiet=True, plot=tmp_path / "tour.png")
    assert result["plot"] == str(tmp_path / "tour.png")
    assert (tmp_path / "tour.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    axes = figure_check(plot_robot_tour(result), "nao tour")
    joints = axes["swinging joints, between their limits"]
    assert set(result["joints"]) | {"position limits"} == set(joints["lines"])
    assert list(joints["lines"]["position limits"].get_ydata()) == [0.0, 0.0]
    # each joint's curve is its position as a fraction of its range (model's limits)
    from sotpy.dynamics import load_model

    model = load_model("nao")[0]
    iq = model.joints[model.getJointId("HeadYaw")].idx_q
    lo, hi = model.lowerPositionLimit[iq], model.upperPositionLimit[iq]
    q = result["q"][:, iq]
    np.testing.assert_allclose(joints["lines"]["HeadYaw"].get_ydata(), (q - lo) / (hi - lo))
    wrist = axes["right-wrist (world)"]
    np.testing.assert_array_equal(wrist["lines"]["right-wrist z"].get_ydata(), result["path"][:, 3])


def test_talos_and_panda_tours():
    talos = run_robot_tour("talos", duration=0.3, quiet=True)
    assert talos["ok"] and talos["feet_fixed"]
    assert not any(j.startswith("leg_") for j in talos["joints"])
    assert {"head_1_joint", "head_2_joint", "arm_left_1_joint", "arm_right_7_joint"} <= set(
        talos["joints"]
    )
    assert talos["wrist"] == "right-wrist" and talos["wrist_travel"] > 0.01
    panda = run_robot_tour("panda", duration=0.3, quiet=True)
    assert panda["ok"] and panda["feet_fixed"] is None and panda["feet_drift"] is None
    assert panda["wrist"] == "end-effector"
    assert np.all(panda["amplitudes"] > 0)  # every joint of an arm moves
    assert panda["coupling_error"] <= 1e-12  # the mimic fingers move together
    assert "feet: none (fixed base)" in panda["table"]


def test_bad_arguments():
    bad = (
        {"duration": 0.0},
        {"duration": math.nan},
        {"dt": -1e-3},
        {"dt": True},
        {"amplitude": -0.1},
        {"frequency": 500.0},
        {"frequency": 0.0},
    )
    for kwargs in bad:
        with pytest.raises(ValueError):
            run_robot_tour("nao", quiet=True, **kwargs)
    assert pool.list() == []  # refused before anything was created
    with pytest.raises(SotpyError, match=r"unknown robot 'naoo'.*'nao'"):
        run_robot_tour("naoo", quiet=True)


# -- command line ----------------------------------------------------------------------
def test_cli_runs_the_demo_and_prints_the_table(capsys):
    assert main(["demo", "robot", "--robot", "nao", "--duration", "0.5"]) == 0
    out = capsys.readouterr().out
    lines = out.splitlines()
    header = next(i for i, line in enumerate(lines) if line.split()[:3] == ["tick", "t", "[s]"])
    assert "right-wrist x y z [m]" in lines[header] and "CoM x y z [m]" in lines[header]
    rows = [line.split() for line in lines[header + 1 : header + 3]]
    assert [r[:2] for r in rows] == [["0", "0.000"], ["500", "0.500"]]
    assert all(len(r) == 8 for r in rows)  # tick, t, wrist xyz, CoM xyz
    assert "feet: left sole and right sole did not move" in out
    assert "limits: no joint left its limits (boundsReport empty)" in out
    assert "robot tour OK: nao, 500 ticks" in out
    # the printed wrist position is the one of the Dynamic at the last tick
    dyn = pool.getEntity("tour_nao_dynamic")
    printed = np.array([float(x) for x in rows[1][2:5]])
    np.testing.assert_allclose(printed, dyn.signal("right-wrist").value.translation, atol=1e-4)


def test_cli_defaults_and_errors(capsys, monkeypatch):
    parser = build_parser()
    assert parser.parse_args(["demo", "pendulum"]).duration == 10.0  # untouched
    assert main(["demo", "robot", "--robot", "nao"]) == 0  # 3 s by default
    assert "robot tour OK: nao, 3000 ticks" in capsys.readouterr().out
    assert main(["demo", "robot", "--robot", "nao", "--dt", "0.01", "--duration", "0.2"]) == 0
    assert "robot tour OK: nao, 20 ticks" in capsys.readouterr().out
    assert main(["demo", "robot", "--robot", "naoo", "--duration", "0.1"]) == 1
    assert "sotpy demo robot: unknown robot 'naoo'" in capsys.readouterr().err
    assert main(["demo", "robot", "--duration", "-1"]) == 2

    def interrupted(**kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(robot_tour, "run_robot_tour", interrupted)
    assert main(["demo", "robot", "--robot", "nao"]) == 130
    assert "interrupted" in capsys.readouterr().err


# -- the viewer ------------------------------------------------------------------------
def _tour_with_viewer(**kwargs):
    pytest.importorskip("meshcat")
    try:
        return run_robot_tour("nao", viewer=True, quiet=True, **kwargs)
    except SotpyError as exc:
        if "RobotViewer" in str(exc):
            pytest.skip(f"meshcat cannot start here: {exc}")
        raise


def test_viewer_tour_replays_the_motion_and_leaves_no_server(capsys):
    assert meshcat_children() == []
    result = _tour_with_viewer(duration=0.3)
    assert result["ok"]
    assert result["viewer_url"].startswith("http://127.0.0.1:")
    assert "viewer: the page replays the 0.30 s motion at real time" in result["table"]
    viewer = pool.getEntity(f"{result['prefix']}_viewer")
    assert not viewer.isOpen()
    assert not Path(f"/proc/{result['viewer_pid']}").exists()
    assert meshcat_children() == []
    device = pool.getEntity(f"{result['prefix']}_device")
    assert device.after.list() == []  # the viewer never slowed the run

    args = ["demo", "robot", "--robot", "nao", "--duration", "0.3", "--viewer", "--hold", "0"]
    assert main(args) == 0
    out = capsys.readouterr().out
    assert "viewer: open http://127.0.0.1:" in out and "robot tour OK" in out
    assert "closing now (--hold 0)" in out
    assert meshcat_children() == []


def test_viewer_holds_until_the_page_is_closed_or_ctrl_c(monkeypatch):
    """--hold: None waits for the page (here Ctrl-C ends the wait: the run still ends
    normally), a number at most that long; Ctrl-C during the run closes the viewer."""
    waits = []

    def wait(self, timeout=None, poll=0.2):
        waits.append(timeout)
        raise KeyboardInterrupt

    monkeypatch.setattr(RobotViewer, "waitPages", wait)
    result = _tour_with_viewer(duration=0.05, hold=None)
    assert result["ok"] and waits == [None]
    assert "close the page or press Ctrl-C to quit" in result["table"]
    assert result["table"].endswith("viewer: closed")
    monkeypatch.setattr(RobotViewer, "waitPages", lambda self, timeout=None, poll=0.2: False)
    result = _tour_with_viewer(duration=0.05, hold=2.5)
    assert "closing in 2.5 s" in result["table"]

    def interrupt(self, *args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(RobotViewer, "animate", interrupt)
    with pytest.raises(KeyboardInterrupt):
        _tour_with_viewer(duration=0.05)
    viewers = [e for e in pool.entities() if e.name.endswith("_viewer")]
    assert len(viewers) == 3 and not any(v.isOpen() for v in viewers)
    assert meshcat_children() == []
