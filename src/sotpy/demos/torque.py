"""``run_panda_torque``: the Panda follows a minimum-jerk Cartesian trajectory in torque
mode, with torque, position and velocity limits (the ORCA-style ``Controller``)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pinocchio as pin

__all__ = ["run_panda_torque"]


def run_panda_torque(
    duration: float = 2.0,
    settle: float = 0.5,
    dt: float = 0.001,
    offset: tuple[float, float, float] = (0.1, -0.1, -0.1),
    strategy: str = "OneLevelWeighted",
    plot: str | Path | None = None,
    prefix: str = "panda_torque",
) -> dict[str, Any]:
    """Simulate the Panda tracking a minimum-jerk move of its hand by ``offset`` (m,
    world) in ``duration`` s, then ``settle`` s at the goal.

    Returns a dict: ``final_error`` (m, position error at the end), ``max_tracking_error``
    (m), ``solution_found`` (all ticks), ``max_torque_ratio`` (max |tau|/limit),
    ``times``, ``torques``, ``errors`` (arrays), ``plot`` (path or None).
    """
    from ..dynamics import load_robot
    from ..graph import plug
    from ..solvers.controller import Controller, JointServo, MinJerk, PoseServo

    robot = load_robot("panda", prefix=prefix)
    device, dyn = robot.device, robot.dynamic
    ctrl = Controller(f"{prefix}_ctrl", dyn)
    ctrl.dt.value = dt
    frame = robot.opPoints["end-effector"]
    ctrl.addCartesianTask("ee", frame, 1.0, 0)
    ctrl.addJointTask("posture", 1e-3, 0)
    ctrl.addTorqueLimits("torque")
    ctrl.addJointPositionLimits("qlim", 0.05)
    ctrl.addJointVelocityLimits("vlim", 0.02)
    ctrl.setResolutionStrategy(strategy)

    traj = MinJerk(f"{prefix}_traj")
    traj.dt.value = dt
    servo = PoseServo(f"{prefix}_servo")
    servo.Kp.value = np.full(6, 400.0)
    plug(ctrl.eePose, servo.position)
    plug(ctrl.eeVelocity, servo.velocity)
    plug(traj.pose, servo.reference)
    plug(traj.velocity, servo.referenceVelocity)
    plug(traj.acceleration, servo.referenceAcceleration)
    plug(servo.desiredAcceleration, ctrl.ee)
    jservo = JointServo(f"{prefix}_jservo")
    q0 = robot.halfSitting.copy()
    plug(ctrl.jointPosition, jservo.position)
    plug(ctrl.jointVelocity, jservo.velocity)
    jservo.reference.value = q0[robot.model.nq - ctrl.core.robot.na :]
    jservo.Kp.value = np.array([25.0])
    plug(jservo.desiredAcceleration, ctrl.posture)

    start = pin.SE3(ctrl.eePose.value)
    goal = pin.SE3(start.rotation, start.translation + np.asarray(offset, float))
    traj.setTrajectory(start, goal, duration, 0)
    ctrl.activateTasksAndConstraints()
    device.setControlType("torque")
    plug(ctrl.torque, device.control)

    n = round((duration + settle) / dt)
    times, torques, errors, found = [], [], [], True
    limits = robot.model.effortLimit
    ratio = 0.0
    for k in range(n):
        device.increment(dt)
        tau = ctrl.torque.value
        ratio = max(ratio, float(np.max(np.abs(tau) / limits)))
        found = found and bool(ctrl.solutionFound.value)
        M = ctrl.eePose.value
        ref = traj.pose.value
        times.append(k * dt)
        torques.append(tau)
        errors.append(float(np.linalg.norm(M.translation - ref.translation)))
    M = ctrl.eePose.value
    final = float(np.linalg.norm(M.translation - goal.translation))
    out: dict[str, Any] = {
        "final_error": final,
        "max_tracking_error": float(max(errors)),
        "solution_found": found,
        "max_torque_ratio": ratio,
        "times": np.array(times),
        "torques": np.array(torques),
        "errors": np.array(errors),
        "plot": None,
    }
    if plot is not None:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        fig, ax = plt.subplots(2, 1, figsize=(8, 6), sharex=True)
        ax[0].plot(out["times"], out["torques"])
        ax[0].set_ylabel("torque (N m)")
        ax[1].plot(out["times"], 1e3 * out["errors"])
        ax[1].set_ylabel("tracking error (mm)")
        ax[1].set_xlabel("time (s)")
        fig.tight_layout()
        fig.savefig(plot)
        plt.close(fig)
        out["plot"] = str(plot)
    return out
