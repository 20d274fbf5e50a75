"""``run_panda_torque``: the Panda follows a minimum-jerk Cartesian trajectory in torque
mode, with torque, position and velocity limits (the ORCA-style ``Controller``)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pinocchio as pin

from ..loop import frozenHeap

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

    traj, _servo = _servoed_pose(
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
    traj.setTrajectory(start, goal, duration, max(device.state.time, 0))  # from now
    ctrl.activateTasksAndConstraints()
    device.setControlType("torque")
    plug(ctrl.torque, device.control)

    n = round((duration + settle) / dt)
    times, torques, errors, found = [], [], [], True
    limits = robot.model.effortLimit
    ratio = 0.0
    with frozenHeap():
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


#: Phases of ``run_talos_torque``: (name, what happens).
TALOS_PHASES = (
    ("shift", "the CoM moves over the stance foot (min-jerk)"),
    ("ramp", "the hand task is activated (ramped in) where the hand is"),
    ("reach", "the right hand reaches by hand_offset (min-jerk), the CoM stays"),
    ("back", "the CoM moves back to its start, the hand stays at its goal"),
    ("settle", "everything holds"),
)


def run_talos_torque(
    duration: float = 1.0,
    settle: float = 0.5,
    dt: float = 0.001,
    side: str = "left",
    hand_offset: tuple[float, float, float] = (0.15, 0.0, 0.05),
    mu: float = 0.5,
    sole_margin: float = 0.01,
    fmin: float = 40.0,
    contact_gains: tuple[float, float] = (100.0, 20.0),
    hand_weight: float = 10.0,
    hand_ramp: float = 0.2,
    pid: tuple[float, float] = (300.0, 1e-3),
    strategy: str = "OneLevelWeighted",
    contacts: str = "floor",
    floor: Any = None,
    plot: str | Path | None = None,
    prefix: str = "talos_torque",
) -> dict[str, Any]:
    """Talos on both feet, in torque mode on a floor: it shifts its CoM over one foot,
    reaches with its right hand, and shifts back.

    The story (``TALOS_PHASES``): the CoM moves in ``duration`` s from its start to the
    ``side`` sole's centre (same height); the hand task, off until then, is activated
    with a ramp of ``hand_ramp`` s where the hand is; the hand moves by ``hand_offset``
    (m, world, orientation kept) in ``duration`` s; the CoM moves back in ``duration``
    s; then ``settle`` s. ``dt``: control period and simulation step (s).

    The robot: ``contacts="floor"`` (default) stands the Device on a floor
    (:class:`~sotpy.dynamics.contact.Floor`, ``floor`` or ``Floor()``: friction 0.8;
    the soles' four corners touch it, MuJoCo simulates it); ``"welded"`` welds the feet
    (Pinocchio's constrained dynamics, the previous simulation).

    The controller (``strategy``): two unilateral 6-D foot contacts (friction ``mu``,
    8-facet pyramids, the CoP ``sole_margin`` (m) inside the real soles of
    ``robot.feet``, normal force >= ``fmin`` (N), the soles' pose and velocity fed back
    with ``contact_gains`` (Kp 1/s^2, Kd 1/s)), the default contact wrench distribution
    cost, a CoM task (weight 10, min-jerk reference, PID Kp = 100 1/s^2 with ``pid`` =
    (Ki 1/s^3, anti-windup clamp m s); ``(0, 0)``: a PD), a right-wrist task (weight
    ``hand_weight``, the same servo), a posture task (weight 1e-2, half-sitting clipped
    1 mrad inside the joint limits, Kp = 25), torque limits and joint position limits
    (horizon 0.05 s, 1e-4 rad inside the model's); transitions bounded in torque rate
    (the default, each joint's effort limit per 0.1 s). The robot starts with flat soles
    (the SRDF's half-sitting rolls the ankles by 1.7 mrad) and its joints 1 mrad inside
    their limits.

    The returned checks are computed from the simulation, independently of the
    controller's rows (``tests/test_wbc_talos.py`` asserts them):

    * ``feet_slide`` (m, largest horizontal displacement of a sole from its start),
      ``feet_lift`` (m, largest vertical one), ``feet_tilt`` (rad, largest rotation):
      the sole placements by Pinocchio from the device's state, every tick;
    * from the simulator's own contact forces (each sole's wrench, rotated into the sole
      frame), every tick: ``min_fz`` (N, smallest normal force of a sole),
      ``min_point_force`` (N, smallest normal force of a corner; floor only),
      ``friction_ratio`` (max ``|f_t| / (mu f_z)``, ``mu`` the controller's),
      ``cop_margin`` (m, the smallest distance of a CoP inside its real sole, < 0
      outside);
    * ``max_rate_ratio``: the largest ``|tau_k - tau_{k-1}| / (rate dt)`` over the
      ticks of the hand's activation ramp, ``rate`` each joint's effort limit per 0.1 s
      (Pinocchio's model, the documented bound): <= 1;
    * ``com_tracking`` and ``hand_tracking`` (m): the largest distance to the moving
      reference (CoM: horizontal, over the run; hand: from the end of its ramp);
      ``com_error`` (m, horizontal CoM to its start at the end) and ``hand_error``
      (m, wrist to its goal at the end);
    * ``max_torque_ratio`` (max ``|tau| / effort limit``), ``solution_found`` (at every
      tick), ``max_wrench_mismatch`` (N or N m, the controller's wrenches against the
      simulated ones of the same tick; ``wrench_mismatch`` per tick), ``ok`` (the
      ``TALOS_TOLERANCES``) and ``summary`` (one line).

    Returns these and the raw arrays the checks come from: ``times`` (n, s), ``com``
    and ``com_ref`` (n x 3, m), ``hand`` and ``hand_ref`` (n x 3, m; NaN before the
    hand's task is activated), ``wrenches`` (n x 2 x 6: left then right sole, sole
    frame, force then torque, simulated), ``corner_fz`` (n x 8, the floor's corner
    normal forces, left sole's then right's, 0 for a corner off the floor; None with
    welded feet), ``sole_motion`` (n x 2 x 4: each sole's displacement x, y, z in m and
    rotation in rad from its start), ``torques`` (n x na, N m), ``torque_limits`` (na),
    ``joint_names``, ``ramp_ticks`` (the hand's ramp, first and last tick),
    ``com_goal`` (3, the shift's goal), ``phases`` (name -> (start, end) s), and
    ``plot`` (the PNG path or None: contact forces, CoPs, torques against their limits,
    CoM).
    """
    from ..dynamics import load_robot
    from ..dynamics.contact import Floor
    from ..errors import SotpyError
    from ..graph import plug
    from ..operators import MatrixHomoToPose, Selec_of_vector
    from ..solvers.controller import ComPidServo, Controller, JointServo, MinJerk

    if side not in ("left", "right"):
        raise SotpyError(f"run_talos_torque: side must be 'left' or 'right', got {side!r}")
    if contacts not in ("floor", "welded"):
        raise SotpyError(
            f"run_talos_torque: contacts must be 'floor' or 'welded', got {contacts!r}"
        )
    robot = load_robot("talos", prefix=prefix)
    device, dyn = robot.device, robot.dynamic
    model = robot.model
    # flat soles: the SRDF's half-sitting rolls the ankles by -1.7 mrad (the soles' inner
    # and outer edges 0.2 mm apart), which a floor shows as a first-tick rocking; and the
    # joints 1 mrad inside their limits (the grippers rest on theirs)
    q_start = np.array(device.state.value)
    for joint in ("leg_left_6_joint", "leg_right_6_joint"):
        q_start[model.joints[model.getJointId(joint)].idx_q] = 0.0
    iq0 = model.nq - (model.nv - 6)
    q_start[iq0:] = np.clip(
        q_start[iq0:], model.lowerPositionLimit[iq0:] + 1e-3, model.upperPositionLimit[iq0:] - 1e-3
    )
    device.set(q_start)
    ctrl = Controller(f"{prefix}_ctrl", dyn)
    ctrl.dt.value = dt
    feet = [robot.feet["left"], robot.feet["right"]]
    kp_c, kd_c = contact_gains
    for foot in feet:
        ctrl.addContact(
            foot.frame, mu, foot.length, foot.width, foot.offset[0], foot.offset[1], 6,
            fmin, sole_margin, 8, kp_c, kd_c,
        )  # fmt: skip
    ctrl.addComTask("comTask", 10.0, 0)
    ctrl.addCartesianTask("hand", robot.opPoints["right-wrist"], hand_weight, 0)
    ctrl.addJointTask("posture", 1e-2, 0)
    ctrl.addTorqueLimits("torque")
    ctrl.addJointPositionLimits("qlim", 0.05, 1e-4)
    ctrl.setResolutionStrategy(strategy)
    ctrl.setRampDuration("hand", hand_ramp)

    # CoM: a min-jerk placement whose translation is the CoM reference
    com0 = np.array(ctrl.com.value)
    data = model.createData()
    q0 = np.array(device.state.value)
    pin.framesForwardKinematics(model, data, q0)
    fids = [model.getFrameId(f.frame) for f in feet]
    sole0 = [pin.SE3(data.oMf[i]) for i in fids]
    stance = 0 if side == "left" else 1
    centre = sole0[stance].act(np.array([*feet[stance].offset[:2], 0.0]))
    com_goal = np.array([centre[0], centre[1], com0[2]])
    com_traj = MinJerk(f"{prefix}_comTraj")
    com_traj.dt.value = dt
    tick0 = max(device.state.time, 0)  # the trajectories start now (a run may follow another)
    com_traj.setTrajectory(pin.SE3(np.eye(3), com0), pin.SE3(np.eye(3), com_goal), duration, tick0)
    com_pos = MatrixHomoToPose(f"{prefix}_comPos")
    plug(com_traj.pose, com_pos.sin)
    com_vel = Selec_of_vector(f"{prefix}_comVel")
    com_vel.selec(0, 3)
    plug(com_traj.velocity, com_vel.sin)
    com_acc = Selec_of_vector(f"{prefix}_comAcc")
    com_acc.selec(0, 3)
    plug(com_traj.acceleration, com_acc.sin)
    com_servo = ComPidServo(f"{prefix}_comServo")
    com_servo.Kp.value = np.array([100.0])
    com_servo.Ki.value = np.array([pid[0]])
    com_servo.integralLimit.value = np.array([pid[1]])
    com_servo.dt.value = dt
    plug(ctrl.com, com_servo.position)
    plug(ctrl.comVelocity, com_servo.velocity)
    plug(com_pos.sout, com_servo.reference)
    plug(com_vel.sout, com_servo.referenceVelocity)
    plug(com_acc.sout, com_servo.referenceAcceleration)
    plug(com_servo.desiredAcceleration, ctrl.comTask)

    # right hand: its trajectory is set when its task is activated
    hand_traj, hand_servo = _servoed_pose(
        f"{prefix}_handTraj", f"{prefix}_handServo", dt, 100.0, ctrl, "hand", "handPose",
        "handVelocity", *pid,
    )  # fmt: skip
    hand_now = pin.SE3(ctrl.handPose.value)
    hand_traj.setTrajectory(hand_now, hand_now, duration, tick0)

    # posture
    jservo = JointServo(f"{prefix}_jservo")
    plug(ctrl.jointPosition, jservo.position)
    plug(ctrl.jointVelocity, jservo.velocity)
    iq = robot.model.nq - ctrl.core.robot.na
    lo, hi = model.lowerPositionLimit[iq:], model.upperPositionLimit[iq:]
    jservo.reference.value = np.clip(ctrl.jointPosition.value, lo + 1e-3, hi - 1e-3)
    jservo.Kp.value = np.array([25.0])
    plug(jservo.desiredAcceleration, ctrl.posture)

    for name in ("comTask", "posture", "torque", "qlim"):
        ctrl.activate(name)
    device.setControlType("torque")
    if contacts == "floor":
        device.setFloor(feet, floor if floor is not None else Floor())
    else:
        device.setContacts([f.frame for f in feet])
    plug(ctrl.torque, device.control)

    # the schedule, in ticks
    k_shift = round(duration / dt)
    k_ramp = k_shift + round(hand_ramp / dt)
    k_reach = k_ramp + round(duration / dt)
    k_back = k_reach + round(duration / dt)
    n = k_back + round(settle / dt)
    phases = {
        "shift": (0.0, k_shift * dt),
        "ramp": (k_shift * dt, k_ramp * dt),
        "reach": (k_ramp * dt, k_reach * dt),
        "back": (k_reach * dt, k_back * dt),
        "settle": (k_back * dt, n * dt),
    }
    hand_goal = None
    limits = model.effortLimit[6:]
    times = np.empty(n)
    coms = np.empty((n, 3))
    com_ref = np.empty((n, 3))
    hands = np.full((n, 3), np.nan)
    hand_ref = np.full((n, 3), np.nan)
    wrenches = np.empty((n, 2, 6))
    ctrl_wrenches = np.empty((n, 2, 6))
    torques = np.empty((n, len(limits)))
    corner_fz = np.zeros((n, 8))  # the floor's corner forces, left sole's then right's
    placements = np.empty((n, 2, 4))  # per sole: x, y, z displacement, rotation angle
    found = True
    with frozenHeap():
        for k in range(n):
            t = tick0 + k
            if k == k_shift:  # the hand task ramps in where the hand is
                hand_now = pin.SE3(ctrl.handPose.value)
                hand_traj.setTrajectory(hand_now, hand_now, hand_ramp, t)
                if pid[0] > 0:
                    hand_servo.resetIntegral()  # the PID starts from the hand where it is
                ctrl.activate("hand")
            if k == k_ramp:
                hand_goal = pin.SE3(
                    hand_now.rotation, hand_now.translation + np.asarray(hand_offset, float)
                )
                hand_traj.setTrajectory(hand_now, hand_goal, duration, t)
            if k == k_reach:
                com_traj.setTrajectory(
                    pin.SE3(np.eye(3), com_goal), pin.SE3(np.eye(3), com0), duration, t
                )
            # the controller's outputs at the tick the device is about to apply (pool.time)
            found = found and bool(ctrl.solutionFound.value)
            torques[k] = ctrl.torque.value
            ctrl_wrenches[k] = ctrl.wrenches.value.reshape(2, 6)
            com_ref[k] = com_traj.pose.value.translation
            if k >= k_shift:
                hand_ref[k] = hand_traj.pose.value.translation
                hands[k] = ctrl.handPose.value.translation
            device.increment(dt)
            q = device.state.value
            pin.framesForwardKinematics(model, data, q)
            forces = device.contactForces()  # of the step just taken, world axes
            for i, (foot, fid) in enumerate(zip(feet, fids, strict=True)):
                M = data.oMf[fid]
                wrenches[k, i] = _local_wrench(M.rotation, forces[foot.frame])
                placements[k, i, :3] = M.translation - sole0[i].translation
                placements[k, i, 3] = np.linalg.norm(pin.log3(sole0[i].rotation.T @ M.rotation))
            for p in device.contactPoints():  # a corner off the floor is not listed: 0
                corner_fz[k, 4 * (p.frame == feet[1].frame) + p.index] = p.force[2]
            coms[k] = pin.centerOfMass(model, data, q)
            times[k] = (k + 1) * dt

    out = _talos_checks(
        times, coms, com_ref, hands, hand_ref, wrenches, ctrl_wrenches, torques, placements,
        corner_fz if contacts == "floor" else None, feet, mu, dt, limits, (k_shift, k_ramp),
    )  # fmt: skip
    out.update(
        {
            "solution_found": found,
            "com_error": float(np.linalg.norm(coms[-1, :2] - com0[:2])),
            "hand_error": float(np.linalg.norm(hands[-1] - hand_goal.translation)),
            "com_goal": com_goal,
            "side": side,
            "contacts": contacts,
            "strategy": strategy,
            "joint_names": list(model.names)[-len(limits) :],
            "phases": phases,
            "soles": [{"length": f.length, "width": f.width, "offset": f.offset[:2]} for f in feet],
            "sole_margin": sole_margin,
            "plot": None,
        }
    )
    _talos_verdict(out, contacts)
    if plot is not None:
        from ..plotting import plot_talos_torque

        plot_talos_torque(out, plot)
        out["plot"] = str(plot)
    return out


#: The tolerances of ``run_talos_torque``'s verdict (m, rad, N).
TALOS_TOLERANCES = {"slide": 1e-3, "tilt": 1e-2, "tracking": 1e-3, "cop_margin": 5e-3}


def _talos_checks(
    times, coms, com_ref, hands, hand_ref, wrenches, ctrl_wrenches, torques, placements,
    corner_fz, feet, mu, dt, limits, ramp_window,
) -> dict[str, Any]:  # fmt: skip
    """The checks of ``run_talos_torque`` from its recorded arrays (see its doc)."""
    fz = wrenches[:, :, 2]
    fxy = np.hypot(wrenches[:, :, 0], wrenches[:, :, 1])
    with np.errstate(divide="ignore", invalid="ignore"):
        friction = float(np.max(fxy / (mu * fz)))
    cop_margin = np.inf
    for i, foot in enumerate(feet):
        off = foot.offset
        with np.errstate(divide="ignore", invalid="ignore"):
            cx = -wrenches[:, i, 4] / fz[:, i] - off[0]
            cy = wrenches[:, i, 3] / fz[:, i] - off[1]
        m = np.minimum(foot.length / 2 - np.abs(cx), foot.width / 2 - np.abs(cy))
        cop_margin = min(cop_margin, float(np.min(np.where(fz[:, i] > 0, m, -np.inf))))
    from ..solvers.wbc.solver import RATE_TIME

    k0, k1 = ramp_window
    step = np.asarray(limits, dtype=float) / RATE_TIME * dt  # the documented bound (N m/tick)
    dtau = np.abs(np.diff(torques[k0 - 1 : k1 + 1], axis=0))
    tracked = ~np.isnan(hand_ref[:, 0])
    ramp_end = k0 + int(np.argmax(tracked[k0:])) if tracked.any() else len(times)
    hand_err = np.linalg.norm(hands - hand_ref, axis=1)
    return {
        "times": times,
        "com": coms,
        "com_ref": com_ref,
        "hand": hands,
        "hand_ref": hand_ref,
        "wrenches": wrenches,
        "sole_motion": placements,
        "corner_fz": corner_fz,
        "ramp_ticks": (k0, k1),
        "torques": torques,
        "torque_limits": np.asarray(limits, dtype=float),
        "feet_slide": float(np.max(np.linalg.norm(placements[:, :, :2], axis=2))),
        "feet_lift": float(np.max(np.abs(placements[:, :, 2]))),
        "feet_tilt": float(np.max(placements[:, :, 3])),
        "min_fz": float(np.min(fz)),
        "min_point_force": np.nan if corner_fz is None else float(np.min(corner_fz)),
        "friction_ratio": friction,
        "cop_margin": cop_margin,
        "max_rate_ratio": float(np.max(dtau / step)),
        "rate_bound": step,
        "com_tracking": float(np.max(np.linalg.norm(coms[:, :2] - com_ref[:, :2], axis=1))),
        "hand_tracking": float(np.nanmax(hand_err[ramp_end:])),
        "max_torque_ratio": float(np.max(np.abs(torques) / limits)),
        "max_wrench_mismatch": float(np.max(np.abs(ctrl_wrenches - wrenches))),
        "wrench_mismatch": np.abs(ctrl_wrenches - wrenches).max(axis=(1, 2)),
    }


def _talos_verdict(out: dict[str, Any], contacts: str) -> None:
    """``out["ok"]`` and ``out["summary"]`` (the demo's one-line report)."""
    tol = TALOS_TOLERANCES
    ok = (
        out["solution_found"]
        and out["feet_slide"] <= tol["slide"]
        and out["feet_tilt"] <= tol["tilt"]
        and out["min_fz"] > 0
        and not out["min_point_force"] <= 0  # a corner off the floor (NaN: welded feet)
        and out["cop_margin"] >= tol["cop_margin"]
        and out["friction_ratio"] <= 1.0
        and out["max_rate_ratio"] <= 1.0 + 1e-6
        and out["com_tracking"] <= tol["tracking"]
        and out["hand_tracking"] <= tol["tracking"]
        and out["com_error"] <= tol["tracking"]
        and out["hand_error"] <= tol["tracking"]
        and out["max_torque_ratio"] <= 1.0
    )
    out["ok"] = bool(ok)
    out["summary"] = (
        f"talos-torque {'OK' if ok else 'FAILED'} ({contacts}):"
        f" feet slide {1e3 * out['feet_slide']:.3f} mm, tilt {1e3 * out['feet_tilt']:.2f} mrad,"
        f" min f_z {out['min_fz']:.0f} N, min corner f_z {out['min_point_force']:.0f} N,"
        f" min CoP margin {1e3 * out['cop_margin']:.1f} mm,"
        f" max |f_t|/(mu f_z) {out['friction_ratio']:.2f},"
        f" max torque step {out['max_rate_ratio']:.2f} of its bound in the ramp,"
        f" CoM / hand tracking {1e3 * out['com_tracking']:.2f} / {1e3 * out['hand_tracking']:.2f}"
        f" mm, final {1e3 * out['com_error']:.2f} / {1e3 * out['hand_error']:.2f} mm,"
        f" max |tau|/limit {out['max_torque_ratio']:.2f},"
        f" solution every tick: {out['solution_found']}"
    )


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


def _servoed_pose(traj_name, servo_name, dt, kp, ctrl, task, pose, velocity, ki=0.0, limit=0.0):
    """A minimum-jerk trajectory followed by a pose servo (gains ``kp`` on every axis;
    with ``ki > 0`` a PID, integral gains ``ki`` clamped to ``limit``) that drives the
    controller's Cartesian task ``task`` from its ``pose`` and ``velocity`` outputs;
    returns the trajectory (the caller sets it) and the servo."""
    from ..graph import plug
    from ..solvers.controller import MinJerk, PosePidServo, PoseServo

    traj = MinJerk(traj_name)
    traj.dt.value = dt
    if ki > 0:
        servo = PosePidServo(servo_name)
        servo.Ki.value = np.full(6, ki)
        servo.integralLimit.value = np.full(6, limit)
        servo.dt.value = dt
    else:
        servo = PoseServo(servo_name)
    servo.Kp.value = np.full(6, kp)
    plug(getattr(ctrl, pose), servo.position)
    plug(getattr(ctrl, velocity), servo.velocity)
    plug(traj.pose, servo.reference)
    plug(traj.velocity, servo.referenceVelocity)
    plug(traj.acceleration, servo.referenceAcceleration)
    plug(servo.desiredAcceleration, getattr(ctrl, task))
    return traj, servo
