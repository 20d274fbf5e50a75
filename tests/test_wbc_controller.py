"""The Controller entity and its servos in the graph; the Panda demo converges."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

from sotpy.demos.torque import run_panda_torque
from sotpy.dynamics import load_robot
from sotpy.errors import CommandError, SotpyError, SotpyWarning
from sotpy.graph import plug
from sotpy.solvers.controller import Controller, JointServo, MinJerk, PoseServo


def _panda():
    robot = load_robot("panda")
    ctrl = Controller("ctrl", robot.dynamic)
    return robot, ctrl


def test_outputs_and_removed_terms():
    robot, ctrl = _panda()
    ctrl.addCartesianTask("ee", "panda_hand_tcp", 1.0, 0)
    ctrl.activateTasksAndConstraints()
    ctrl.ee.value = np.array([0.1, 0, 0, 0, 0, 0])
    q = robot.device.state.value
    tau = ctrl.torque.value.copy()
    assert ctrl.solutionFound.value
    data = robot.model.createData()
    assert np.allclose(
        tau, pin.rnea(robot.model, data, q, np.zeros(9), ctrl.acceleration.value), atol=1e-8
    )
    g = pin.computeGeneralizedGravity(robot.model, data, q)
    ctrl.setRemoveGravityTorques(True)
    assert np.allclose(ctrl.torque.value, tau - g, atol=1e-10)
    assert np.allclose(ctrl.solution.value[9:18], tau)  # solution keeps the full torque
    pose = ctrl.eePose.value
    assert pose.isApprox(robot.dynamic.signal("end-effector").value)


def test_no_solution_warns_once_and_falls_back():
    robot, ctrl = _panda()
    ctrl.addCartesianTask("ee", "panda_hand_tcp", 1.0, 0)
    ctrl.addTorqueLimits("tau", np.full(9, -0.01), np.full(9, 0.01))
    ctrl.addJointAccelerationLimits("alim", np.full(9, -0.01), np.full(9, 0.01))
    ctrl.activateTasksAndConstraints()
    robot.device.setControlType("torque")
    plug(ctrl.torque, robot.device.control)
    with pytest.warns(SotpyWarning, match="no solution"):
        robot.device.increment(0.001)
    assert not ctrl.solutionFound.value
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("error")
        robot.device.increment(0.001)  # no second warning while still infeasible
    assert np.all(np.abs(ctrl.torque.value) <= 0.01 + 1e-12)


def test_bad_input_is_reported():
    _robot, ctrl = _panda()
    with pytest.raises(SotpyError, match="no frame"):
        ctrl.addCartesianTask("ee", "nowhere", 1.0, 0)
    ctrl.addCartesianTask("ee", "panda_hand_tcp", 1.0, 0)
    with pytest.raises(SotpyError, match=r"exists|taken"):
        ctrl.addJointTask("ee", 1.0, 0)
    with pytest.raises(SotpyError, match="weight"):
        ctrl.setTaskWeight("ee", -1.0)
    with pytest.raises(CommandError):
        ctrl.setTaskWeight("ee", float("nan"))
    with pytest.raises(SotpyError, match="no task"):
        ctrl.setTaskWeight("nope", 1.0)
    with pytest.raises(SotpyError, match="strategy"):
        ctrl.setResolutionStrategy("Generalized")
    ctrl.activateTasksAndConstraints()
    ctrl.ee.value = np.zeros(4)
    with pytest.raises(SotpyError, match=r"ee.*size 6"):
        _ = ctrl.solution.value
    servo = PoseServo("servo")
    servo.position.value = pin.SE3.Identity()
    servo.reference.value = pin.SE3.Identity()
    servo.velocity.value = np.zeros(6)
    servo.Kp.value = -np.ones(6)
    with pytest.raises(SotpyError, match="Kp"):
        _ = servo.desiredAcceleration.value


def test_servo_entities():
    js = JointServo("js")
    js.position.value = [1.0, 2.0]
    js.velocity.value = [0.5, 0.0]
    js.reference.value = [0.0, 0.0]
    js.Kp.value = [4.0]
    assert np.allclose(js.desiredAcceleration.value, [-4 - 4 * 0.5, -8.0])
    mj = MinJerk("mj")
    M0, M1 = pin.SE3.Identity(), pin.SE3(np.eye(3), np.array([1.0, 0, 0]))
    mj.setTrajectory(M0, M1, 1.0, 0)
    assert mj.pose.value.isApprox(M0)
    with pytest.raises(SotpyError, match="duration"):
        mj.setTrajectory(M0, M1, -1.0, 0)


def test_multilevel_callbacks_through_entity():
    robot, ctrl = _panda()
    ctrl.addCartesianTask("ee", "panda_hand_tcp", 1.0, 0)
    ctrl.addJointTask("posture", 1.0, 1)
    ctrl.setResolutionStrategy("MultiLevelWeighted")
    log = []
    ctrl.setCallback("ee", "onActivated", lambda: log.append("activated"))
    ctrl.setRampDuration("ee", 0.002)
    ctrl.activateTasksAndConstraints()
    robot.device.setControlType("torque")
    plug(ctrl.torque, robot.device.control)
    for _ in range(3):
        robot.device.increment(0.001)
    assert log == ["activated"]
    ctrl.deactivateTasksAndConstraints()
    with pytest.warns(SotpyWarning, match="nothing is active"):  # once everything is off
        for _ in range(3):
            robot.device.increment(0.001)
    assert ctrl.tasksAndConstraintsDeactivated()


def test_panda_converges_in_simulation(tmp_path):
    out = run_panda_torque(duration=1.0, settle=0.3, plot=tmp_path / "p.png")
    assert out["solution_found"]
    assert out["final_error"] < 1e-3
    assert out["max_tracking_error"] < 5e-3
    assert out["max_torque_ratio"] <= 1.0 + 1e-9
    assert (tmp_path / "p.png").stat().st_size > 1000


def test_cli_demo_panda_torque(tmp_path, capsys):
    from sotpy.cli import main

    png = tmp_path / "panda.png"
    assert main(["demo", "panda-torque", "--duration", "0.5", "--plot", str(png)]) == 0
    out = capsys.readouterr().out
    assert "panda-torque OK" in out
    assert png.stat().st_size > 10_000
    assert main(["demo", "panda-torque", "--strategy", "Nope"]) == 2  # usage error
    assert "invalid choice: 'Nope'" in capsys.readouterr().err


def test_pid_servos_against_a_hand_rolled_loop():
    """JointPidServo / ComPidServo / PosePidServo: the PD plus ``-Ki I``, ``I`` the error
    integrated once per tick and clamped per axis (anti-windup), reset on demand."""
    from sotpy.graph.pool import pool
    from sotpy.solvers.controller import ComPidServo, JointPidServo, PosePidServo

    dt, kp, ki, lim = 0.002, 9.0, 30.0, 0.004
    s = JointPidServo("jpid")
    s.dt.value = dt
    s.Kp.value = [kp]
    s.Ki.value = [ki]
    s.integralLimit.value = [lim]
    s.reference.value = np.zeros(2)
    s.velocity.value = np.zeros(2)
    integral = np.zeros(2)
    for k in range(40):
        x = np.array([0.1, -0.02 * k])  # a constant error and a growing one
        s.position.value = x
        integral = np.clip(integral + x * dt, -lim, lim)
        expected = -kp * x - 2 * np.sqrt(kp) * 0.0 - ki * integral
        pool.time = k
        assert np.allclose(s.desiredAcceleration(k), expected), k
    assert np.allclose(s.getIntegral(), integral) and np.all(np.abs(integral) == lim)  # wound up
    s.resetIntegral()
    pool.time = 40
    s.position.value = np.array([0.1, 0.0])
    assert np.allclose(
        s.desiredAcceleration(40), -kp * np.array([0.1, 0.0]) - ki * dt * np.array([0.1, 0.0])
    )
    c = ComPidServo("cpid")
    assert c.className == "ComPidServo" and c.hasSignal("integralLimit")
    p = PosePidServo("ppid")
    p.dt.value = dt
    p.Ki.value = np.full(6, ki)
    M = pin.SE3(pin.exp3(np.array([0.0, 0.0, 0.1])), np.array([0.01, 0.0, 0.0]))
    p.position.value = M
    p.reference.value = pin.SE3.Identity()
    p.velocity.value = np.zeros(6)
    e = np.concatenate([M.translation, pin.log3(M.rotation)])
    pool.time = 41
    assert np.allclose(p.desiredAcceleration(41), -100.0 * e - ki * e * dt)  # default Kp 100
    for bad in (("Ki", [-1.0]), ("integralLimit", [-1.0]), ("dt", 0.0)):
        q = JointPidServo(f"bad_{bad[0]}")
        q.position.value, q.velocity.value, q.reference.value = [0.1], [0.0], [0.0]
        q.signal(bad[0]).value = bad[1]
        with pytest.raises(SotpyError, match=bad[0]):
            _ = q.desiredAcceleration.value


def test_a_demo_run_twice_in_one_session():
    """The trajectories start when the run starts, not at tick 0 (a shell session runs
    a demo after other ticks)."""
    first = run_panda_torque(duration=0.6, settle=0.3, prefix="p1")
    second = run_panda_torque(duration=0.6, settle=0.3, prefix="p2")
    assert first["final_error"] < 1e-3 and second["final_error"] < 1e-3
    assert second["max_tracking_error"] < 2 * first["max_tracking_error"] + 1e-3
