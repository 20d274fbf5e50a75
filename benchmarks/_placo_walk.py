"""PlaCo's walking inverse-kinematics tick on Talos, for a comparison with sotpy's.

:func:`placo_walk_ik` replays a walk's references (one dict per 1 ms tick: the CoM, both
ankles, the waist's attitude) through PlaCo's ``KinematicsSolver`` on the reduced Talos of
example-robot-data (the model sotpy's ``load_robot("talos")`` loads) and times the IK tick
PlaCo users run: ``solver.solve(True)`` then ``robot.update_kinematics()``.

The stack, as close to sotpy's walking SOT (``sotpy.demos.walk.build_walk``) as PlaCo's
two priorities (hard: equality constraints of the QP; soft: weighted least squares) allow:

* both ankles (``leg_left_6_joint``, ``leg_right_6_joint``): 6D frame tasks, hard;
* the CoM (x, y, z): hard;
* the waist (the ``root_joint`` frame): orientation task, soft, weight 1;
* the posture (half-sitting, every actuated joint): joints task, soft, weight 1e-3;
* joint position and velocity limits on (sotpy's SOT, built on the robot's Dynamic, has
  its joint-limit level); the free-flyer is floating (not masked).

PlaCo 0.10 pins ``pin==3.8.0`` and sotpy needs ``pin>=4.0``: they cannot share an
environment (PlaCo's extension links the libpinocchio 3.8 that pin 4 replaces). When
``import placo`` fails here, the replay runs in a child process of the interpreter given as
``python=`` or by ``$PLACO_PYTHON`` (a venv with ``pip install placo``); this process
resolves the URDF and the half-sitting configuration with example-robot-data and sends
them with the references; the ticks are timed inside the child, where PlaCo runs.
"""

from __future__ import annotations

import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

LEFT = "leg_left_6_joint"
RIGHT = "leg_right_6_joint"
WAIST = "root_joint"
WAIST_WEIGHT = 1.0
POSTURE_WEIGHT = 1e-3


def _talos() -> dict:
    """The reduced Talos URDF of example-robot-data and its SRDF's half-sitting: the
    free-flyer's pose (4x4) and the actuated joints' values by name."""
    import pinocchio as pin
    from example_robot_data.robots_loader import TalosLoader

    loader = TalosLoader()
    model, q0 = loader.robot.model, np.asarray(loader.robot.q0, dtype=float)
    names = [model.names[j] for j in range(2, model.njoints)]
    values = [float(q0[model.joints[j].idx_q]) for j in range(2, model.njoints)]
    base = pin.XYZQUATToSE3(q0[:7]).homogeneous
    return {"urdf": loader.df_path, "base": base, "names": names, "values": values}


def _stack(refs: list[dict]) -> dict[str, np.ndarray]:
    return {
        "com": np.array([np.asarray(r["com"], dtype=float).reshape(3) for r in refs]),
        "left": np.array([np.asarray(r["left"], dtype=float) for r in refs]),
        "right": np.array([np.asarray(r["right"], dtype=float) for r in refs]),
        "waist": np.array([np.asarray(r["waist"], dtype=float) for r in refs]),
    }


def _robot(placo, urdf: str):
    """PlaCo's RobotWrapper of ``urdf``: its meshes' ``package://example-robot-data/robots``
    resolved to the data directory (PlaCo loads the visual meshes; collisions ignored)."""
    root = os.path.normpath(os.path.join(os.path.dirname(urdf), "..", ".."))
    text = Path(urdf).read_text().replace("package://example-robot-data/robots", root)
    return placo.RobotWrapper(urdf, placo.Flags.ignore_collisions, text)


def _build(talos: dict, refs: dict[str, np.ndarray], dt: float):
    """PlaCo's robot at half-sitting, its solver and the tasks (left, right, com, waist,
    posture) of the module doc, aimed at the first references."""
    import placo

    robot = _robot(placo, talos["urdf"])
    frames = set(robot.frame_names())
    missing = [f for f in (LEFT, RIGHT, WAIST) if f not in frames]
    if missing:
        raise RuntimeError(f"PlaCo's model of {talos['urdf']} has no frame {missing}")
    robot.set_T_world_fbase(np.asarray(talos["base"], dtype=float))
    half_sitting = dict(zip(talos["names"], talos["values"], strict=True))
    for name, value in half_sitting.items():
        robot.set_joint(name, value)
    robot.update_kinematics()

    solver = placo.KinematicsSolver(robot)
    solver.mask_fbase(False)
    solver.enable_joint_limits(True)
    solver.enable_velocity_limits(True)
    solver.dt = dt
    left = solver.add_frame_task(LEFT, refs["left"][0])
    left.configure("left_ankle", "hard", 1.0, 1.0)
    right = solver.add_frame_task(RIGHT, refs["right"][0])
    right.configure("right_ankle", "hard", 1.0, 1.0)
    com = solver.add_com_task(refs["com"][0])
    com.configure("com", "hard", 1.0)
    waist = solver.add_orientation_task(WAIST, refs["waist"][0])
    waist.configure("waist", "soft", WAIST_WEIGHT)
    posture = solver.add_joints_task()
    posture.set_joints(half_sitting)
    posture.configure("posture", "soft", POSTURE_WEIGHT)
    return robot, solver, (left, right, com, waist, posture)


def _replay(talos: dict, refs: dict[str, np.ndarray], dt: float, warmup: int) -> dict:
    """The replay itself, in a process where ``placo`` imports."""
    robot, solver, (left, right, com, waist, _) = _build(talos, refs, dt)
    n = len(refs["com"])
    times = np.empty(n)
    com_err = np.empty(n)
    feet_err = np.empty(n)
    clock = time.perf_counter
    for k in range(n):
        left.T_world_frame = refs["left"][k]
        right.T_world_frame = refs["right"][k]
        com.target_world = refs["com"][k]
        waist.R_world_frame = refs["waist"][k]
        t0 = clock()
        solver.solve(True)
        robot.update_kinematics()
        times[k] = clock() - t0
        com_err[k] = np.linalg.norm(robot.com_world() - refs["com"][k])
        feet_err[k] = max(
            np.linalg.norm(robot.get_T_world_frame(LEFT)[:3, 3] - refs["left"][k][:3, 3]),
            np.linalg.norm(robot.get_T_world_frame(RIGHT)[:3, 3] - refs["right"][k][:3, 3]),
        )
    return {
        "times": times[warmup:],
        "com_error": float(com_err.max()),
        "feet_error": float(feet_err.max()),
        "placo_version": _version(),
    }


def _version() -> str:
    from importlib.metadata import version

    return version("placo")


def _child(python: str, talos: dict, refs: dict[str, np.ndarray], dt: float, warmup: int):
    with tempfile.TemporaryDirectory(prefix="placo_walk_") as tmp:
        inp, out = os.path.join(tmp, "in.npz"), os.path.join(tmp, "out.npz")
        np.savez(
            inp,
            urdf=talos["urdf"],
            base=talos["base"],
            names=np.array(talos["names"]),
            values=np.array(talos["values"]),
            dt=dt,
            warmup=warmup,
            **refs,
        )
        subprocess.run([python, os.path.abspath(__file__), inp, out], check=True)
        with np.load(out) as r:
            return {
                "times": r["times"],
                "com_error": float(r["com_error"]),
                "feet_error": float(r["feet_error"]),
                "placo_version": str(r["placo_version"]),
            }


def placo_walk_ik(references, dt=1e-3, warmup=50, python=None):
    """references: list, one per tick, of dicts {"com": (3,) array (m, world),
    "left": 4x4 homogeneous matrix of the frame 'leg_left_6_joint' (the left ankle op point;
    world), "right": 4x4 of 'leg_right_6_joint', "waist": 3x3 rotation of the 'root_joint'
    frame (world)}.

    Builds PlaCo's KinematicsSolver on example-robot-data's reduced Talos at half-sitting
    with the stack of the module doc, ``solver.dt = dt``; each tick sets the targets from
    ``references[k]`` and times ``solver.solve(True)`` plus ``robot.update_kinematics()``.
    ``python``: the interpreter that runs PlaCo when ``placo`` does not import here
    (default ``$PLACO_PYTHON``).

    Returns {"times": np.ndarray of seconds per tick (after ``warmup`` ticks),
    "com_error": max m, "feet_error": max m (ankle positions vs targets; both over every
    tick), "placo_version": str}."""
    if len(references) <= warmup:
        raise ValueError(f"{len(references)} references for {warmup} warm-up ticks")
    talos = _talos()
    refs = _stack(references)
    python = python or os.environ.get("PLACO_PYTHON")
    if python is None:
        try:
            import placo  # noqa: F401
        except ImportError as exc:
            raise ImportError(
                "placo does not import here (PlaCo 0.10 pins pin==3.8.0, sotpy needs "
                "pin>=4.0): give a venv with placo as python= or $PLACO_PYTHON"
            ) from exc
        return _replay(talos, refs, dt, warmup)
    return _child(python, talos, refs, dt, warmup)


def _main(inp: str, out: str) -> None:
    with np.load(inp) as a:
        talos = {
            "urdf": str(a["urdf"]),
            "base": a["base"],
            "names": [str(s) for s in a["names"]],
            "values": [float(v) for v in a["values"]],
        }
        refs = {key: a[key] for key in ("com", "left", "right", "waist")}
        r = _replay(talos, refs, float(a["dt"]), int(a["warmup"]))
    np.savez(out, **r)


if __name__ == "__main__":
    _main(sys.argv[1], sys.argv[2])
