"""The SoT's kinematic walk: a PatternGenerator plans 15 steps, the stack follows it.

    python examples/humanoid_walk.py [--robot talos|romeo|nao] [--dynamic-filter]
                                     [--plot walk.png] [--save walk.npz]

(with the virtual environment of the README: ``.venv/bin/python examples/...``). The
same story is ``sotpy demo talos-walk`` (``romeo-walk``, ``nao-walk``; ``--online`` for the
walk driven by a velocity); docs/walking.md walks through it.
The graph is built below in plain sight; the checks of the motion (the multibody ZMP
from Pinocchio, the soles' own motion) are :class:`sotpy.demos.walk.WalkLog`.
"""

import argparse

from sotpy.demos.walk import GAITS, WalkLog, stepSequence
from sotpy.dynamics import load_robot
from sotpy.graph import plug
from sotpy.solvers import SOT
from sotpy.tasks import Task
from sotpy.walking import PatternGenerator

parser = argparse.ArgumentParser(description=__doc__.split("\n", 1)[0])
parser.add_argument("--robot", default="talos", help="talos, romeo or nao")
parser.add_argument(
    "--dynamic-filter", action="store_true", help="Kajita's second stage (a few s of planning)"
)
parser.add_argument("--plot", metavar="PATH", help="save the top view and the ZMP margin (PNG)")
parser.add_argument("--save", metavar="PATH", help="save t, q, v, phases, footprints (.npz)")
args = parser.parse_args()
dt = 0.001  # control period, s
gait = GAITS[args.robot]

robot = load_robot(args.robot)
robot.device.setControlType("velocity")

# the pattern generator, configured as the SoT's walking scripts do
pg = PatternGenerator("pg")
pg.buildModel(robot)
pg.setTimeStep(dt)
for line in (
    ":samplingperiod 0.005",
    ":previewcontroltime 1.6",
    f":stepheight {gait.height}",
    f":singlesupporttime {gait.ss}",
    f":doublesupporttime {gait.ds}",
):
    pg.parseCmd(line)
if gait.comHeight is not None:
    pg.parseCmd(f":comheight {gait.comHeight}")
if args.dynamic_filter:
    pg.parseCmd(":useDynamicFilter true")  # made when the steps are given, below
plug(robot.dynamic.position, pg.position)
plug(robot.dynamic.com, pg.com)
plug(robot.dynamic.signal("left-ankle"), pg.leftfootcurrentpos)
plug(robot.dynamic.signal("right-ankle"), pg.rightfootcurrentpos)
pg.initState()
start = pg.initialFootprints
width = abs(start["left"].y - start["right"].y)
pg.parseCmd(":stepseq " + " ".join(f"{v:.6g}" for v in stepSequence(gait, width)))

# level 1: both feet on the generator's ankles, their velocities fed forward
feet = Task("task_feet")
for side in ("left", "right"):
    ankle = robot.tasks[f"{side}-ankle"]
    plug(pg.signal(f"{side}footref"), ankle.feature.reference)
    plug(pg.signal(f"{side}footvelocity"), ankle.feature.referenceVelocity)
    feet.add(ankle.feature)
feet.controlGain.value = 300.0
feet.setWithDerivative(True)
# level 2: the CoM on comref, dcomref fed forward
com = robot.tasks["com"]
com.feature.selec.value = "111"
plug(pg.comref, com.featureDes.errorIN)
plug(pg.dcomref, com.featureDes.errordotIN)
com.task.setWithDerivative(True)
com.gain.setConstant(300.0)
# level 3: the waist's orientation; level 4: half-sitting for the rest
waist = robot.tasks["waist"]
waist.feature.selec.value = "000111"
plug(pg.waistattitudematrixabsolute, waist.feature.reference)
waist.gain.setConstant(300.0)
posture = robot.tasks["posture"]
posture.gain.setConstant(10.0)

sot = SOT("sot", robot.dynamic)  # level 0: the joint limits
sot.dt.value = dt
for task in (feet, com.task, waist.task, posture.task):
    sot.push(task)
plug(sot.control, robot.device.control)

# walk: the trigger starts the plan at the next tick; record every tick, then judge
pg.trigger.value = True
robot.device.increment(dt)
ticks = round((pg.plan.duration + 0.5) / dt)
log = WalkLog(robot, pg, dt, ticks)
for _ in range(ticks):
    robot.device.increment(dt)
    log.record()
result = log.report()
for name, ok in result["checks"].items():
    print(f"{name:<16} {'ok' if ok else 'FAILED'}")
print(f"walked {result['distance']:.3f} m; ZMP margin >= {result['margin'] * 1e3:.1f} mm")
if args.save:
    log.save(args.save, result)
if args.plot:
    from sotpy.plotting import plot_walk

    plot_walk(result, pg.plan, args.plot, title=f"{args.robot} walk")
raise SystemExit(0 if result["ok"] else 1)
