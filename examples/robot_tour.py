"""A robot tour: Talos waves its arms and turns its head while standing.

The graph::

    robot = load_robot("talos", prefix="tour_talos")     # Dynamic + Device at half-sitting
    robot.device.setControlType("velocity")
    sine = JointSineVelocity("tour_talos_sine", robot.model, robot.halfSitting, dt)
    sine.selectChains(wrist and gaze frames, exclude=ankle and sole frames)
    plug(sine.control, robot.device.control)             # v_j = A_j w cos(w t dt)
    robot.device.increment(dt)                           # repeatedly

The base twist is zero and the legs do not move, so the feet stay exactly where they
were; each joint's amplitude is limited so that no joint reaches its limits.

Run it with ``python examples/robot_tour.py [--robot nao] [--duration 10] [--viewer]``
(``--viewer`` prints the address of a meshcat page showing the robot, and paces the loop
at real time); the same story is ``sotpy demo robot``. The logic is
:func:`sotpy.demos.robot_tour.run_robot_tour`.
"""

import argparse

from sotpy.demos.robot_tour import DEFAULT_AMPLITUDE, DEFAULT_FREQUENCY, run_robot_tour


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n", 1)[0])
    parser.add_argument("--robot", default="talos", help="robot name or .toml description")
    parser.add_argument("--duration", type=float, default=3.0, help="simulated time, s")
    parser.add_argument("--dt", type=float, default=1e-3, help="time step, s")
    parser.add_argument("--amplitude", type=float, default=DEFAULT_AMPLITUDE, help="rad")
    parser.add_argument("--frequency", type=float, default=DEFAULT_FREQUENCY, help="Hz")
    parser.add_argument("--viewer", action="store_true", help="show it in meshcat")
    args = parser.parse_args()
    result = run_robot_tour(
        args.robot,
        duration=args.duration,
        dt=args.dt,
        viewer=args.viewer,
        amplitude=args.amplitude,
        frequency=args.frequency,
    )
    verdict = "OK" if result["ok"] else "FAILED"
    print(f"{verdict}: {result['ticks']} ticks in {result['wall_time']:.2f} s")
    return 0 if result["ok"] else 1


if __name__ == "__main__":
    raise SystemExit(main())
