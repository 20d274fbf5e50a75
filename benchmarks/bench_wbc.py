"""One tick of the torque-level controller on Talos: two 6-D foot contacts, CoM, one
hand and posture tasks, torque limits. Prints the median per tick and a breakdown:
dynamics (Pinocchio passes), QP (rows + solve), graph (the rest of the entity tick).

With the one-level weighted strategy it then compares, in the same run and on the same
ticks (the variants take turns every 25 ticks of one simulation), the QP solve of
:class:`sotpy.solvers.wbc.qp.WeightedQP` as used (compiled kernels, last tick's active
set tried first), its NumPy twin (``jit=False``), and DAQP on every tick (the guess
dropped before each solve: the previous implementation's path), with each variant's
median controller tick and its ratio to the DAQP-every-tick reference.

    python benchmarks/bench_wbc.py [--ticks 300] [--strategy ...]
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
    if args.strategy == "OneLevelWeighted":
        compare_variants(ctrl, dev, args.ticks)


def compare_variants(ctrl, dev, ticks: int, chunk: int = 25) -> None:
    """Interleaved turns of the QP variants on one simulation (see the module doc)."""
    from sotpy.solvers.wbc import _kernels
    from sotpy.solvers.wbc.qp import WeightedQP

    core = ctrl.core
    make = lambda jit: WeightedQP(core.robot.actuated, core._unactuated, jit=jit)  # noqa: E731
    variants = {"compiled + guess": make(None), "NumPy + guess": make(False)}
    if _kernels.reduce is None:
        del variants["compiled + guess"]
    variants["DAQP every tick (reference)"] = make(False)
    times: dict[str, list[float]] = {k: [] for k in variants}
    for _ in range(max(1, ticks // chunk)):
        for name, qp in variants.items():
            core.weighted_qp = qp
            reference = name.startswith("DAQP")
            for _ in range(chunk):
                if reference:
                    qp.forget()
                t0 = time.perf_counter()
                dev.increment(0.001)
                times[name].append(time.perf_counter() - t0)
            if not ctrl.solutionFound.value:
                raise SystemExit(f"{name}: no solution ({core.last.reason})")
    ref = float(np.median(times["DAQP every tick (reference)"]))
    print("\nQP variants, interleaved (device step incl. the simulation, median ms):")
    for name, qp in variants.items():
        m = float(np.median(times[name]))
        hits = qp.guess_hits / max(1, qp.guess_hits + qp.daqp_solves)
        print(f"  {name:30s} {1e3 * m:.3f}   ratio {m / ref:.2f}   guess answered {hits:.0%}")


if __name__ == "__main__":
    main()
