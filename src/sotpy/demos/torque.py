"""``run_panda_torque``: the Panda follows a minimum-jerk Cartesian trajectory in torque
mode, with torque, position and velocity limits (the ORCA-style ``Controller``)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pinocchio as pin

__all__ = ["run_callbacks", "run_panda_torque", "run_talos_torque"]


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
    from ..solvers.controller import Controller, JointServo

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

    traj = _servoed_pose(
        f"{prefix}_traj", f"{prefix}_servo", dt, 400.0, ctrl, "ee", "eePose", "eeVelocity"
    )
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
        "joint_names": list(robot.model.names)[-len(limits) :],
        "torque_limits": np.array(limits),
        "plot": None,
    }
    if plot is not None:
        from ..plotting import plot_panda_torque

        plot_panda_torque(out, plot)
        out["plot"] = str(plot)
    return out


def _local_wrench(R: np.ndarray, w: np.ndarray) -> np.ndarray:
    """A wrench at a frame's origin from world-aligned axes to the frame's own axes."""
    return np.concatenate([R.T @ w[:3], R.T @ w[3:]])


def run_talos_torque(
    duration: float = 1.5,
    settle: float = 0.5,
    dt: float = 0.001,
    side: str = "left",
    hand_offset: tuple[float, float, float] = (0.15, 0.1, 0.1),
    mu: float = 0.5,
    sole_margin: float = 0.01,
    hand_weight: float = 10.0,
    strategy: str = "OneLevelWeighted",
    plot: str | Path | None = None,
    prefix: str = "talos_torque",
) -> dict[str, Any]:
    """Talos stands on both feet, shifts its CoM over one foot and reaches with its right
    hand, in torque mode (the Device simulates the feet as welded 6-D contacts).

    The controller (``strategy``, ``OneLevelWeighted`` by default) has two unilateral
    6-D foot contacts (friction pyramid ``mu``; the CoP inside the soles of
    ``robot.feet`` shrunk by ``sole_margin`` (m) on every side, a safety margin), a CoM
    task (weight 10, min-jerk reference from the start to the ``side`` sole's centre,
    same height, in ``duration`` s, PD ``Kp = 100 1/s^2``), a right-wrist Cartesian task
    (weight ``hand_weight``, min-jerk from the start to start + ``hand_offset`` (m,
    world), orientation kept, PD ``Kp = 100``), a posture task (weight 1e-2, half-sitting
    clipped 1 mrad inside the joint limits (the grippers rest on theirs), ``Kp = 25``),
    torque limits and joint position limits (horizon 0.05 s); then ``settle`` s at the
    goals. ``dt``: control period and simulation step (s).

    The returned checks are computed from the simulation, independently of the
    controller's own rows (``tests/test_wbc_talos.py`` asserts them):

    * ``feet_drift`` (m, largest translation of a sole from its start) and
      ``feet_rotation`` (rad): the sole placements by Pinocchio from the device's state;
    * from the Device's contact wrenches (the simulated ones, world axes at the sole
      origin, rotated into the sole frame), over the whole run: ``min_fz`` (N),
      ``friction_ratio`` (max of ``sqrt(fx^2 + fy^2) / (mu fz)``, <= 1 inside the
      cone), ``cop_margin`` (m, the smallest distance of a CoP inside its *real* sole
      rectangle, < 0 outside), ``torsion_ratio`` (max ``|tz| / (mu min(L, W)/2 fz)``);
    * ``com_error`` (m, horizontal distance of the CoM to its goal at the end),
      ``hand_error`` (m, wrist position to its goal at the end);
    * ``max_torque_ratio`` (max ``|tau| / effort limit``), ``solution_found`` (at every
      tick), ``max_wrench_mismatch`` (N or N m: the controller's wrenches vs the
      simulated ones of the same tick).

    Returns these and the arrays ``times`` (n, s), ``com`` (n x 3, m), ``com_goal`` (3),
    ``wrenches`` (n x 2 x 6: left then right sole, sole frame, force then torque),
    ``torques`` (n x na, N m), and ``plot`` (the PNG path or None: normal and
    tangential forces, CoPs, CoM).
    """
    from ..dynamics import load_robot
    from ..errors import SotpyError
    from ..graph import plug
    from ..operators import MatrixHomoToPose, Selec_of_vector
    from ..solvers.controller import ComServo, Controller, JointServo, MinJerk

    if side not in ("left", "right"):
        raise SotpyError(f"run_talos_torque: side must be 'left' or 'right', got {side!r}")
    robot = load_robot("talos", prefix=prefix)
    device, dyn = robot.device, robot.dynamic
    model = robot.model
    ctrl = Controller(f"{prefix}_ctrl", dyn)
    ctrl.dt.value = dt
    feet = [robot.feet["left"], robot.feet["right"]]
    for foot in feet:
        ctrl.addContact(
            foot.frame,
            mu,
            foot.length - 2 * sole_margin,
            foot.width - 2 * sole_margin,
            foot.offset[0],
            foot.offset[1],
            6,
            0.0,
        )
    ctrl.addComTask("comTask", 10.0, 0)
    ctrl.addCartesianTask("hand", robot.opPoints["right-wrist"], hand_weight, 0)
    ctrl.addJointTask("posture", 1e-2, 0)
    ctrl.addTorqueLimits("torque")
    ctrl.addJointPositionLimits("qlim", 0.05)
    ctrl.setResolutionStrategy(strategy)

    # CoM: min-jerk of a placement whose translation is the CoM
    com0 = np.array(ctrl.com.value)
    data = model.createData()
    q0 = np.array(device.state.value)
    pin.framesForwardKinematics(model, data, q0)
    fids = [model.getFrameId(f.frame) for f in feet]
    sole0 = [pin.SE3(data.oMf[i]) for i in fids]
    target_foot = feet[0] if side == "left" else feet[1]
    M_foot = sole0[0] if side == "left" else sole0[1]
    centre = M_foot.act(np.array([*target_foot.offset[:2], 0.0]))
    com_goal = np.array([centre[0], centre[1], com0[2]])
    com_traj = MinJerk(f"{prefix}_comTraj")
    com_traj.dt.value = dt
    com_traj.setTrajectory(pin.SE3(np.eye(3), com0), pin.SE3(np.eye(3), com_goal), duration, 0)
    com_pos = MatrixHomoToPose(f"{prefix}_comPos")
    plug(com_traj.pose, com_pos.sin)
    com_vel = Selec_of_vector(f"{prefix}_comVel")
    com_vel.selec(0, 3)
    plug(com_traj.velocity, com_vel.sin)
    com_acc = Selec_of_vector(f"{prefix}_comAcc")
    com_acc.selec(0, 3)
    plug(com_traj.acceleration, com_acc.sin)
    com_servo = ComServo(f"{prefix}_comServo")
    com_servo.Kp.value = np.array([100.0])
    plug(ctrl.com, com_servo.position)
    plug(ctrl.comVelocity, com_servo.velocity)
    plug(com_pos.sout, com_servo.reference)
    plug(com_vel.sout, com_servo.referenceVelocity)
    plug(com_acc.sout, com_servo.referenceAcceleration)
    plug(com_servo.desiredAcceleration, ctrl.comTask)

    # right hand
    hand_traj = _servoed_pose(
        f"{prefix}_handTraj",
        f"{prefix}_handServo",
        dt,
        100.0,
        ctrl,
        "hand",
        "handPose",
        "handVelocity",
    )
    hand0 = pin.SE3(ctrl.handPose.value)
    hand_goal = pin.SE3(hand0.rotation, hand0.translation + np.asarray(hand_offset, float))
    hand_traj.setTrajectory(hand0, hand_goal, duration, 0)

    # posture
    jservo = JointServo(f"{prefix}_jservo")
    plug(ctrl.jointPosition, jservo.position)
    plug(ctrl.jointVelocity, jservo.velocity)
    iq = robot.model.nq - ctrl.core.robot.na
    lo, hi = model.lowerPositionLimit[iq:], model.upperPositionLimit[iq:]
    jservo.reference.value = np.clip(ctrl.jointPosition.value, lo + 1e-3, hi - 1e-3)
    jservo.Kp.value = np.array([25.0])
    plug(jservo.desiredAcceleration, ctrl.posture)

    ctrl.activateTasksAndConstraints()
    device.setControlType("torque")
    device.setContacts([f.frame for f in feet])
    plug(ctrl.torque, device.control)

    n = round((duration + settle) / dt)
    limits = model.effortLimit[6:]
    k_pyr = [(f.length, f.width, f.offset) for f in feet]
    times = np.empty(n)
    coms = np.empty((n, 3))
    wrenches = np.empty((n, 2, 6))
    ctrl_wrenches = np.empty((n, 2, 6))
    torques = np.empty((n, len(limits)))
    found = True
    drift = rot = 0.0
    for k in range(n):
        # the controller's outputs at the tick the device is about to apply (pool.time)
        found = found and bool(ctrl.solutionFound.value)
        torques[k] = ctrl.torque.value
        ctrl_wrenches[k] = ctrl.wrenches.value.reshape(2, 6)
        device.increment(dt)
        q = device.state.value
        pin.framesForwardKinematics(model, data, q)
        forces = device.contactForces()  # of the step just taken, world axes
        for i, (foot, fid) in enumerate(zip(feet, fids, strict=True)):
            M = data.oMf[fid]
            wrenches[k, i] = _local_wrench(M.rotation, forces[foot.frame])
            drift = max(drift, float(np.linalg.norm(M.translation - sole0[i].translation)))
            rot = max(rot, float(np.linalg.norm(pin.log3(sole0[i].rotation.T @ M.rotation))))
        coms[k] = pin.centerOfMass(model, data, q)
        times[k] = (k + 1) * dt
    # independent checks on the simulated wrenches (sole frames)
    fz = wrenches[:, :, 2]
    fxy = np.hypot(wrenches[:, :, 0], wrenches[:, :, 1])
    friction = float(np.max(fxy / (mu * fz)))
    cop_margin = np.inf
    torsion = 0.0
    for i, (length, width, off) in enumerate(k_pyr):
        cx = -wrenches[:, i, 4] / fz[:, i] - off[0]
        cy = wrenches[:, i, 3] / fz[:, i] - off[1]
        m = np.minimum(length / 2 - np.abs(cx), width / 2 - np.abs(cy))
        cop_margin = min(cop_margin, float(np.min(m)))
        torsion = max(
            torsion,
            float(np.max(np.abs(wrenches[:, i, 5]) / (mu * min(length, width) / 2 * fz[:, i]))),
        )
    hand = pin.SE3(ctrl.handPose.value)
    out: dict[str, Any] = {
        "feet_drift": drift,
        "feet_rotation": rot,
        "min_fz": float(np.min(fz)),
        "friction_ratio": friction,
        "cop_margin": cop_margin,
        "torsion_ratio": torsion,
        "com_error": float(np.linalg.norm(coms[-1, :2] - com_goal[:2])),
        "hand_error": float(np.linalg.norm(hand.translation - hand_goal.translation)),
        "max_torque_ratio": float(np.max(np.abs(torques) / limits)),
        "solution_found": found,
        "max_wrench_mismatch": float(np.max(np.abs(ctrl_wrenches - wrenches))),
        "times": times,
        "com": coms,
        "com_goal": com_goal,
        "wrenches": wrenches,
        "torques": torques,
        "side": side,
        "soles": [{"length": f.length, "width": f.width, "offset": f.offset[:2]} for f in feet],
        "plot": None,
    }
    if plot is not None:
        from ..plotting import plot_talos_torque

        plot_talos_torque(out, plot)
        out["plot"] = str(plot)
    return out


def run_callbacks(
    ramps: dict[str, float] | None = None,
    dt: float = 0.001,
    compute: bool = True,
    echo: bool = True,
    prefix: str = "torque_callbacks",
) -> list[str]:
    """The life cycle of tasks and constraints, printed: the Panda in torque mode with a
    hand task ``ee``, a posture task ``posture`` and a torque limit ``torque``, each with
    its ramp duration (``ramps``: name -> s; default ``ee`` 0.002, ``posture`` 0.003,
    ``torque`` 0). Every callback prints one line::

        tick 2  t=0.002 s  ee       onComputeEnd    ramp 1.00

    ``tick`` is the device's tick since the start, ``t`` the controller's time since the
    start (``tick * dt``), ``ramp``
    the object's ramp when the callback runs. The story: ``activateTasksAndConstraints()``
    at tick 0, ticks until every object is active, ``deactivateTasksAndConstraints()``,
    ticks until ``tasksAndConstraintsDeactivated()``. ``onActivation`` and
    ``onDeactivation`` run inside those calls (before any tick of the ramp);
    ``onComputeBegin`` / ``onComputeEnd`` around each tick's solve of every object that
    is not inactive (shown if ``compute``), in the order the objects were added (tasks
    first, then constraints); ``onActivated`` (``onDeactivated``) right after the
    ``onComputeEnd`` of the tick whose ramp reaches 1 (0).

    Returns the lines (printed as well if ``echo``).
    """
    from ..dynamics import load_robot
    from ..graph import plug
    from ..solvers.controller import Controller

    ramps = {"ee": 0.002, "posture": 0.003, "torque": 0.0} if ramps is None else ramps
    robot = load_robot("panda", prefix=prefix)
    device = robot.device
    ctrl = Controller(f"{prefix}_ctrl", robot.dynamic)
    ctrl.dt.value = dt
    ctrl.addCartesianTask("ee", robot.opPoints["end-effector"], 1.0, 0)
    ctrl.addJointTask("posture", 1e-3, 0)
    ctrl.addTorqueLimits("torque")
    lines: list[str] = []
    core = ctrl.core

    def item(name: str) -> Any:
        return core.tasks.get(name) or core.constraints[name]

    tick0 = max(device.state.time, 0)

    def log(name: str, event: str, t: float | None = None) -> None:
        tick = max(device.state.time, 0) - tick0
        tt = tick * dt if t is None else t - tick0 * dt
        line = f"tick {tick}  t={tt:.3f} s  {name:<8} {event:<15} ramp {item(name).ramp:.2f}"
        lines.append(line)
        if echo:
            print(line)

    events = ["onActivation", "onActivated", "onDeactivation", "onDeactivated"]
    if compute:
        events += ["onComputeBegin", "onComputeEnd"]
    for name in ("ee", "posture", "torque"):
        ctrl.setRampDuration(name, ramps.get(name, 0.0))
        for ev in events:
            if ev.startswith("onCompute"):
                ctrl.setCallback(name, ev, lambda t, _dt, n=name, e=ev: log(n, e, t))
            else:
                ctrl.setCallback(name, ev, lambda n=name, e=ev: log(n, e))
    device.setControlType("torque")
    plug(ctrl.torque, device.control)
    ctrl.activateTasksAndConstraints()
    limit = 10_000
    while not all(item(n).isActivated for n in ("ee", "posture", "torque")) and limit:
        device.increment(dt)
        limit -= 1
    ctrl.deactivateTasksAndConstraints()
    while not ctrl.tasksAndConstraintsDeactivated() and limit:
        device.increment(dt)
        limit -= 1
    return lines


def _servoed_pose(traj_name, servo_name, dt, kp, ctrl, task, pose, velocity):
    """A minimum-jerk trajectory followed by a pose servo (gains ``kp`` on every axis)
    that drives the controller's Cartesian task ``task`` from its ``pose`` and
    ``velocity`` outputs; returns the trajectory (the caller sets it)."""
    from ..graph import plug
    from ..solvers.controller import MinJerk, PoseServo

    traj = MinJerk(traj_name)
    traj.dt.value = dt
    servo = PoseServo(servo_name)
    servo.Kp.value = np.full(6, kp)
    plug(getattr(ctrl, pose), servo.position)
    plug(getattr(ctrl, velocity), servo.velocity)
    plug(traj.pose, servo.reference)
    plug(traj.velocity, servo.referenceVelocity)
    plug(traj.acceleration, servo.referenceAcceleration)
    plug(servo.desiredAcceleration, getattr(ctrl, task))
    return traj
