"""A robot tour: a humanoid waves its arms and turns its head while standing.

    python examples/robot_tour.py [--robot talos|romeo|nao|panda] [--duration 3]
                                  [--plot tour.png] [--viewer]

(with the virtual environment of the README: ``.venv/bin/python examples/...``). The
same story is ``sotpy demo robot``. The graph is built below in plain sight: a
:class:`~sotpy.demos.robot_tour.JointSineVelocity` swings the joints of the arms and the
head about half-sitting (``v_j = A_j w cos(w t)``, each amplitude limited so that no
joint reaches its limits) with a zero base twist and still legs, so the feet stay
exactly where they were. The table and the checks are
:class:`sotpy.demos.checks.TourLog`, the figure :func:`sotpy.plotting.plot_robot_tour`.
"""

import argparse

from sotpy.demos.checks import TourLog
from sotpy.demos.robot_tour import JointSineVelocity
from sotpy.dynamics import load_robot
from sotpy.graph import plug

parser = argparse.ArgumentParser(description=__doc__.split("\n", 1)[0])
parser.add_argument("--robot", default="talos", help="a name listed by 'sotpy robots'")
parser.add_argument("--duration", type=float, default=3.0, help="simulated time, s")
parser.add_argument("--plot", metavar="PATH", help="save the wrist, CoM and joints (PNG)")
parser.add_argument("--viewer", action="store_true", help="replay the motion in meshcat")
args = parser.parse_args()
dt = 0.001  # s

robot = load_robot(args.robot, prefix="tour")  # a Dynamic and a Device at half-sitting
robot.device.setControlType("velocity")

sine = JointSineVelocity("tour_sine", robot.model, robot.halfSitting, dt)
sine.setAmplitude(0.3)  # rad, reduced per joint to stay inside its limits
sine.setFrequency(0.4)  # Hz
if robot.feet:  # a humanoid: the chains to the wrists and the head, not the legs
    ops = robot.opPoints
    swing = [ops[op] for op in ("left-wrist", "right-wrist", "gaze") if op in ops]
    still = [ops[op] for op in ("left-ankle", "right-ankle")] + [
        foot.frame for foot in robot.feet.values()
    ]
    sine.selectChains(swing, still)
else:  # an arm: every joint
    sine.selectJoints(["*"])
plug(sine.control, robot.device.control)

# run it: a table row each second, then the checks (feet, limits, couplings)
steps = round(args.duration / dt)
log = TourLog(robot, sine, steps, dt)
print(log.header())
for _ in range(steps):
    robot.device.increment(dt)
    row = log.record()
    if row:
        print(row)
result = log.report()
print(result["table"])

if args.plot:
    from sotpy.plotting import plot_robot_tour

    plot_robot_tour(result, args.plot)
    print(f"plot: {args.plot}")
if args.viewer:
    from sotpy.demos import open_viewer, replay

    view = open_viewer(robot, "tour", print)
    replay(view, result["q"], 0.01, None, print)  # frames every 10 ms; until closed
    view.close()
raise SystemExit(0 if result["ok"] else 1)
