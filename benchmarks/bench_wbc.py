"""One tick of the torque-level controller on Talos, as a ratio to its own Pinocchio
floor, measured in the same run.

The problem: Talos on the floor (the Device's MuJoCo contact simulation), two 6-D foot
contacts as the demo has them (friction ``mu`` 0.5, 8-facet pyramids, CoP 1 cm inside
the soles, ``fmin`` 40 N, pose and velocity feedback), the contact wrench cost, a CoM
task (weight 10, a PD to a point moving 2 cm sideways and back), a right-hand task
(weight 10, a PD to a point 5 cm away), a posture task (1e-2), torque limits; the robot
driven in closed loop by the core controller (``WholeBodyController``, no graph).

Each simulated tick, at the same ``(q, v)`` and one right after the other, the script
times:

* **floor**: what any torque-level controller of this robot must compute, by Pinocchio
  (``crba``, ``nonLinearEffects``, ``computeJointJacobians`` and the two contact
  frames' ``getFrameJacobian``);
* **tick**: ``WholeBodyController.update(q, v, t, dt)``, the whole weighted tick
  (Pinocchio's passes, the rows, the QP).

and reports their medians, the tick's 90th percentile and worst, and the ratio of the
medians; then the tick's parts (``RobotModel.update``; ``problem()``, the rows; the
compiled QP kernel; the rest), measured the same way on the states of the run. BLAS is
limited to one thread, as in a control loop. ``--strategy MultiLevelWeighted`` measures
the hierarchical strategy instead (its worst case is the bounded-time solver's issue); a
tick whose solver stopped at its time budget before the hard level sends the fallback and
is counted, and any other tick without a solution stops the benchmark.

    python benchmarks/bench_wbc.py [--ticks 2000] [--strategy OneLevelWeighted]
"""

from __future__ import annotations

import os

# the compiled kernels are what is measured: compiled first on a fresh machine, not the
# NumPy twins that a first run uses while they compile in the background
os.environ.setdefault("SOTPY_JIT", "wait")

import argparse
import time
import warnings

import numpy as np


def build(strategy: str):
    """The robot on the floor and its controller (see the module doc)."""
    import pinocchio as pin

    from sotpy.dynamics import load_robot
    from sotpy.dynamics.contact import Floor
    from sotpy.solvers.wbc import (
        CartesianAccelerationTask,
        CoMAccelerationTask,
        ContactSpec,
        JointAccelerationTask,
        JointTorqueLimit,
        WholeBodyController,
    )

    robot = load_robot("talos", prefix="bench")
    model, dev = robot.model, robot.device
    q = dev.state.value.copy()
    for joint in ("leg_left_6_joint", "leg_right_6_joint"):  # flat soles
        q[model.joints[model.getJointId(joint)].idx_q] = 0.0
    iq = model.nq - (model.nv - 6)
    lo, hi = model.lowerPositionLimit[iq:], model.upperPositionLimit[iq:]
    q[iq:] = np.clip(q[iq:], lo + 1e-3, hi - 1e-3)
    dev.set(q)
    dev.setControlType("torque")
    dev.setFloor(list(robot.feet.values()), Floor())
    w = WholeBodyController(model, strategy)
    feet = list(robot.feet.values())
    w.setContacts(
        [
            ContactSpec(f.frame, 6, 0.5, f.length, f.width, f.offset[:2], 40.0, 0.01, 8, 100.0)
            for f in feet
        ]
    )
    tasks = {
        "com": w.addTask(CoMAccelerationTask("com", 10.0)),
        "hand": w.addTask(CartesianAccelerationTask("hand", "arm_right_7_joint", 10.0)),
        "post": w.addTask(JointAccelerationTask("post", w.robot.na, 1e-2)),
    }
    w.addConstraint(JointTorqueLimit("tau", w.robot))
    w.activateTasksAndConstraints()
    fids = [model.getFrameId(f.frame) for f in feet]
    data = model.createData()

    def floor(q, v):
        pin.crba(model, data, q)
        pin.nonLinearEffects(model, data, q, v)
        pin.computeJointJacobians(model, data, q)
        for fid in fids:
            pin.getFrameJacobian(model, data, fid, pin.LOCAL)

    return robot, w, tasks, floor


def servo(w, tasks, q, v, k, refs):
    """The tasks' desired accelerations (PDs) at the state last given to ``w.robot``."""
    robot = w.robot
    if not refs:
        refs["com"] = robot.com.copy()
        refs["hand"] = robot.frame_placement(robot.frame_id("arm_right_7_joint")).translation
        refs["hand"] = refs["hand"] + np.array([0.05, 0.0, 0.05])
        refs["q"] = q[7:].copy()
    com_ref = refs["com"] + np.array([0.0, 0.02 * np.sin(2 * np.pi * k / 2000.0), 0.0])
    tasks["com"].setDesired(-100 * (robot.com - com_ref) - 20 * robot.com_velocity)
    fid = robot.frame_id("arm_right_7_joint")
    e = np.concatenate([robot.frame_placement(fid).translation - refs["hand"], np.zeros(3)])
    tasks["hand"].setDesired(-100 * e - 20 * robot.frame_velocity(fid))
    tasks["post"].setDesired(-25 * (q[7:] - refs["q"]) - 10 * v[6:])


def run(strategy: str, ticks: int, warmup: int = 200) -> dict:
    from sotpy._blas import limit_blas_threads
    from sotpy.solvers.wbc import _kernels

    limit_blas_threads()
    robot, w, tasks, floor = build(strategy)
    dev = robot.device
    qp = w.weighted_qp
    dt = 1e-3
    refs: dict = {}
    pc = time.perf_counter
    t_floor, t_tick, states = [], [], []
    fallbacks = 0  # ticks whose solver stopped at its budget before the hard level
    for k in range(warmup + ticks):
        q, v = dev.state.value.copy(), dev.velocity.value.copy()
        w.robot.update(q, v)
        servo(w, tasks, q, v, k, refs)
        t0 = pc()
        floor(q, v)
        t1 = pc()
        sol = w.update(q, v, k * dt, dt)
        t2 = pc()
        if not sol.found:
            if not sol.budget_hit:  # a failure, not the bounded-time contract
                raise SystemExit(f"tick {k}: no solution ({sol.reason})")
            fallbacks += 1  # the contract's fallback (gravity compensation) was sent
        if k >= warmup:
            t_floor.append(t1 - t0)
            t_tick.append(t2 - t1)
            if len(states) < 400:
                states.append((q, v, [t.desired.copy() for t in tasks.values()]))
        dev.control.value = sol.tau
        dev.increment(dt)
    out = {"floor": np.array(t_floor), "tick": np.array(t_tick), "fallbacks": fallbacks}
    out["guess"] = qp.guess_hits / max(1, qp.guess_hits + qp.daqp_solves)
    # the tick's parts, on the states of the run (each part right after the floor)
    parts: dict[str, list[float]] = {"update": [], "problem": [], "kernel": [], "floor": []}
    lay = w.layout
    for q, v, desired in states * 3:
        for t, d in zip(tasks.values(), desired, strict=True):
            t.setDesired(d)
        t0 = pc()
        floor(q, v)
        t1 = pc()
        w.robot.update(q, v)
        t2 = pc()
        w.problem(w.transition)
        t3 = pc()
        asm = w._assembly
        if strategy == "OneLevelWeighted" and _kernels.solve is not None:
            ws, _views = qp._workspace(lay.nv, lay.na, lay.n, asm.m, asm.mc)
            qp._kernel(asm.data, ws, lay.nv, lay.na, lay.n, asm.m, asm.mc, w.regularisation, True)
        t4 = pc()
        for key, dt_ in (("floor", t1 - t0), ("update", t2 - t1), ("problem", t3 - t2),
                         ("kernel", t4 - t3)):  # fmt: skip
            parts[key].append(dt_)
    out["parts"] = {k: np.array(v) for k, v in parts.items()}
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--ticks", type=int, default=2000)
    ap.add_argument("--strategy", default="OneLevelWeighted")
    args = ap.parse_args()
    warnings.simplefilter("ignore")  # the device's clamp reports, if any
    import numba

    from sotpy._bench import machine_line

    r = run(args.strategy, args.ticks)
    us = lambda x: 1e6 * float(x)  # noqa: E731
    fl, tk = np.median(r["floor"]), np.median(r["tick"])
    print(machine_line(f"numba {numba.__version__}", "one BLAS thread"))
    print(f"strategy {args.strategy}, {args.ticks} ticks of Talos on the floor, closed loop")
    print(f"  floor (crba, nle, joint Jacobians, 2 contact Jacobians): median {us(fl):.1f} us")
    weighted = args.strategy == "OneLevelWeighted"
    guess = f"; guessed active set {r['guess']:.0%} of ticks" if weighted else ""
    print(
        f"  tick: median {us(tk):.1f} us, p90 {us(np.percentile(r['tick'], 90)):.1f}"
        f" us, worst {us(r['tick'].max()):.1f} us{guess}"
    )
    print(f"  ratio tick / floor (medians): {tk / fl:.2f}")
    if r["fallbacks"]:
        print(
            f"  ticks that sent the fallback (the budget hit before the hard level):"
            f" {r['fallbacks']}"
        )
    p = {k: np.median(v) for k, v in r["parts"].items()}
    rest = tk - p["update"] - p["problem"] - p["kernel"]
    solver = (
        f", QP kernel {us(p['kernel']):.1f} ({p['kernel'] / p['floor']:.2f})" if weighted else ""
    )
    what = "the rest of the tick" if weighted else "the hierarchy and the rest"
    print(
        f"  parts (medians, us; the floor in that pass {us(p['floor']):.1f}): update"
        f" {us(p['update']):.1f} ({p['update'] / p['floor']:.2f} x floor), rows"
        f" {us(p['problem']):.1f} ({p['problem'] / p['floor']:.2f}){solver}, {what}"
        f" {us(rest):.1f} ({rest / fl:.2f})"
    )


if __name__ == "__main__":
    main()
