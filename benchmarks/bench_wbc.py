"""One tick of the torque-level controller on Talos: two 6-D foot contacts, CoM, one
hand and posture tasks, torque limits. Prints the median per tick and a breakdown:
dynamics (Pinocchio passes), QP (rows + solve), graph (the rest of the entity tick).

    /tmp/venv/bin/python benchmarks/bench_wbc.py [--ticks 300] [--strategy ...]
"""

from __future__ import annotations

import argparse
import time
import warnings

import numpy as np


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--ticks", type=int, default=300)
    ap.add_argument("--strategy", default="OneLevelWeighted")
    args = ap.parse_args()
    warnings.simplefilter("ignore")  # the device's clamp reports while it sags
    from sotpy._blas import limit_blas_threads
    from sotpy.dynamics import load_robot
    from sotpy.graph import plug
    from sotpy.solvers.controller import Controller

    robot = load_robot("talos")
    ctrl = Controller("ctrl", robot.dynamic)
    for side, foot in robot.feet.items():
        ctrl.addContact(
            foot.frame, 0.5, foot.length, foot.width, foot.offset[0], foot.offset[1], 6, 0.0
        )
        del side
    ctrl.addComTask("comTask", 10.0, 0)
    ctrl.addCartesianTask("hand", robot.opPoints["right-wrist"], 1.0, 1)
    ctrl.addJointTask("posture", 1e-2, 2)
    ctrl.addTorqueLimits("tau")
    ctrl.setResolutionStrategy(args.strategy)
    ctrl.activateTasksAndConstraints()
    ctrl.signal("hand").value = np.array([0.2, 0, 0.1, 0, 0, 0])
    limit_blas_threads()  # as in a control loop (a HierarchySolver does it as well)
    core = ctrl.core
    q = robot.device.state.value
    v = np.zeros(robot.model.nv)

    def med(fn, n):
        ts = []
        for _ in range(n):
            t0 = time.perf_counter()
            fn()
            ts.append(time.perf_counter() - t0)
        return 1e3 * float(np.median(ts))

    dyn = med(lambda: core.robot.update(q, v), args.ticks)
    qp = med(lambda: core.tick(0.0, 0.001), args.ticks)
    rows = med(core.problem, args.ticks)
    # whole entity tick: the device in torque mode with the controller plugged, minus
    # the same device step with a constant torque (the simulation's own cost)
    dev = robot.device
    dev.setControlType("torque")
    dev.setContacts([f.frame for f in robot.feet.values()])
    dev.control.value = np.zeros(robot.model.nv - 6)
    sim = med(lambda: dev.increment(0.001), args.ticks)  # the robot sags meanwhile
    dev.set(q)  # back to half-sitting, at rest, for the controlled run
    dev.setVelocity(np.zeros(robot.model.nv))
    dev.setContacts([f.frame for f in robot.feet.values()])
    plug(ctrl.torque, dev.control)
    full = med(lambda: dev.increment(0.001), args.ticks)
    tick = full - sim
    print(f"strategy {args.strategy}, {args.ticks} ticks, medians (ms):")
    print(
        f"  controller tick   {tick:.3f}   (device step {full:.3f} - without controller {sim:.3f})"
    )
    print(f"  dynamics          {dyn:.3f}")
    print(f"  QP (rows + solve) {qp:.3f}   (rows {rows:.3f}, solve {qp - rows:.3f})")
    print(f"  graph + rest      {tick - dyn - qp:.3f}")
    print(f"  solution found    {ctrl.solutionFound.value}")


if __name__ == "__main__":
    main()
