"""The SoT slides' reaching demo: a humanoid keeps its feet and its balance and brings
its right wrist to a point 20-25 cm away, forward and up.

    python examples/humanoid_reach.py [--robot talos|romeo|nao] [--duration 2]
                                      [--plot reach.png] [--viewer]

(with the virtual environment of the README: ``.venv/bin/python examples/...``). The
same story is ``sotpy demo talos`` (``romeo``, ``nao``); docs/tutorial-reach.md walks
through it. The graph is built below in plain sight; the recording, the checks and
the table are :class:`sotpy.demos.checks.ReachLog`, the figure
:func:`sotpy.plotting.plot_reach`.
"""

import argparse

import numpy as np

from sotpy.demos.checks import ReachLog
from sotpy.dynamics import load_robot
from sotpy.graph import plug
from sotpy.solvers import SOT
from sotpy.tasks import TaskInequality

parser = argparse.ArgumentParser(description=__doc__.split("\n", 1)[0])
parser.add_argument("--robot", default="talos", help="talos, romeo or nao")
parser.add_argument("--duration", type=float, default=2.0, help="simulated time, s")
parser.add_argument("--plot", metavar="PATH", help="save the errors and the CoM path (PNG)")
parser.add_argument("--viewer", action="store_true", help="replay the motion in meshcat")
args = parser.parse_args()
dt = 0.001  # control period and integration step, s
margin = 0.01  # the CoM stays this far inside the support polygon, m
offset = np.array([0.15 if args.robot == "nao" else 0.20, 0.0, 0.15])  # target - wrist, m

robot = load_robot(args.robot, prefix="reach")  # a Dynamic and a Device at half-sitting
robot.device.setControlType("velocity")

# level 1, one TaskInequality: the feet fixed (and Nao's coupled hips: bounds [0, 0]) and
# the CoM's ground projection inside the support polygon shrunk by the margin (N c <= b)
feet = [robot.tasks["left-ankle"].feature, robot.tasks["right-ankle"].feature]
if "couplings" in robot.tasks:
    feet.append(robot.tasks["couplings"].feature)
balance = robot.tasks["balance"]
balance.setMargin(margin)
balance.task.dt.value = dt
contact = TaskInequality("task_contact")
for feature in [*feet, balance.feature]:
    contact.add(feature)
rows = sum(len(feature.error.value) for feature in feet)
bound = balance.bounds()
contact.referenceInf.value = np.concatenate((np.zeros(rows), np.full(len(bound), -np.inf)))
contact.referenceSup.value = np.concatenate((np.zeros(rows), bound))
contact.dt.value = dt
contact.controlGain.value = 1.0  # each error cancelled in one period

# level 2: the right wrist to the target, with SoT's adaptive gain (10 1/s near it, 2 far)
wrist = robot.tasks["right-wrist"]
target = robot.dynamic.signal("right-wrist").value.translation + offset
wrist.gotoNd(target, "111000", gain=(10.0, 2.0, 0.05, 0.5))

# level 3: half-sitting; level 0 (the joint limits) is the SOT's own
posture = robot.tasks["posture"]
posture.gain.setConstant(1.0)

sot = SOT("sot", robot.dynamic)
sot.dt.value = dt
for task in (contact, wrist.task, posture.task):
    sot.push(task)
plug(sot.control, robot.device.control)

# run it, recording each tick; then the checks and the table
steps = round(args.duration / dt)
log = ReachLog(robot, sot, target, steps, dt, margin, (10.0, 2.0, 0.05, 0.5))
print(log.header())
for _ in range(steps):
    robot.device.increment(dt)
    log.record()
result = log.report()
print(result["table"])

if args.plot:
    from sotpy.plotting import plot_reach

    plot_reach(result, args.plot)
    print(f"plot: {args.plot}")
if args.viewer:
    from sotpy.demos import open_viewer, replay

    view = open_viewer(robot, "reach", print)
    replay(view, result["q"], dt, None, print)  # until the page is closed or Ctrl-C
    view.close()
raise SystemExit(0 if result["ok"] else 1)
