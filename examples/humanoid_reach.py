"""The SoT slides' reaching demo: a humanoid keeps its feet and its balance and brings
its right wrist to a point 20-25 cm away, forward and up.

The graph (the ready tasks come from ``robot.tasks``, see docs/robots.md)::

    robot = load_robot("talos", prefix="reach_talos")
    robot.device.setControlType("velocity")
    sot = SOT("reach_talos_sot", robot.dynamic)          # level 0: joint limits (hard)
    contact = TaskInequality("task_reach_talos_contact")  # level 1, in one task:
    contact.add(robot.tasks["left-ankle"].feature)        #   feet fixed (bounds [0, 0])
    contact.add(robot.tasks["right-ankle"].feature)
    contact.add(robot.tasks["balance"].feature)           #   CoM in the support polygon
    robot.tasks["right-wrist"].gotoNd(target, "111000", gain=(10, 2, 0.05, 0.5))
    for task in (contact, robot.tasks["right-wrist"].task, robot.tasks["posture"].task):
        sot.push(task)                                    # levels 1, 2, 3
    plug(sot.control, robot.device.control)
    robot.device.increment(0.001)                         # repeatedly

It prints a convergence table (each task's error over time) and the checks: the wrist
at the target, the soles where they were (to 1e-6 m and rad), the CoM inside the support
polygon, every joint within its limits.

Run it with ``python examples/humanoid_reach.py [--robot talos|romeo|nao] [--duration
2] [--plot reach.png] [--viewer]``; the same story is ``sotpy demo talos`` (``romeo``,
``nao``). The logic is :func:`sotpy.demos.reach.run_reach`, and docs/tutorial-reach.md
walks through it.
"""

import argparse

from sotpy.demos.reach import run_reach


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n", 1)[0])
    parser.add_argument("--robot", default="talos", help="talos, romeo or nao")
    parser.add_argument("--duration", type=float, default=2.0, help="simulated time, s")
    parser.add_argument("--dt", type=float, default=1e-3, help="time step, s")
    parser.add_argument("--plot", help="save the errors and the CoM path (PNG)")
    parser.add_argument(
        "--target-offset", type=float, nargs=3, metavar=("X", "Y", "Z"), help="m, world axes"
    )
    parser.add_argument("--viewer", action="store_true", help="show it in meshcat")
    args = parser.parse_args()
    result = run_reach(
        args.robot,
        duration=args.duration,
        dt=args.dt,
        target_offset=args.target_offset,
        plot=args.plot,
        viewer=args.viewer,
    )
    verdict = "OK" if result["ok"] else "FAILED"
    print(f"{verdict}: {result['ticks']} ticks in {result['wall_time']:.2f} s")
    return 0 if result["ok"] else 1


if __name__ == "__main__":
    raise SystemExit(main())
