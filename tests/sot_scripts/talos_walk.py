# A SoT user's walking script for Talos, in the style of talos_integration_tests'
# online-walking application and sot-pattern-generator's walking.py: the pattern
# generator configured with jrl-walkgen's commands, the feet as 6D meta-tasks on the
# generator's ankles, the CoM with the generator's velocity fed forward, the waist's
# orientation, the upper body's posture; then a footstep sequence (or the velocity walk)
# and the loop. It imports nothing from sotpy.
#
#     sotpy run talos_walk.py OUTDIR [steps|online] [SECONDS]
import sys

import numpy as np
from dynamic_graph import plug
from dynamic_graph.sot.core.meta_task_posture import MetaTaskKinePosture
from dynamic_graph.sot.core.meta_tasks_kine import MetaTaskKine6d, MetaTaskKineCom
from dynamic_graph.sot.core.sot import SOT
from dynamic_graph.sot.pattern_generator import PatternGenerator
from dynamic_graph.sot.pyrene.robot import Robot

outdir = sys.argv[1]
mode = sys.argv[2] if len(sys.argv) > 2 else "steps"
seconds = float(sys.argv[3]) if len(sys.argv) > 3 else 7.0

robot = Robot(name="talos")
robot.timeStep = 0.001
dt = robot.timeStep

# --- the pattern generator
pg = PatternGenerator("pg")
pg.buildModel()
pg.parseCmd(":samplingperiod 0.005")
pg.parseCmd(":previewcontroltime 1.6")
pg.parseCmd(":walkmode 0")
pg.parseCmd(":omega 0.0")
pg.parseCmd(":stepheight 0.05")
pg.parseCmd(":armparameters 0.5")
pg.parseCmd(":LimitsFeasibility 0.0")
pg.parseCmd(":ZMPShiftParameters 0.015 0.015 0.015 0.015")
pg.parseCmd(":UpperBodyMotionParameters 0.0 -0.5 0.0")
pg.parseCmd(":comheight 0.876681")
if mode == "online":
    pg.parseCmd(":SetAlgoForZmpTrajectory Naveau")
    pg.parseCmd(":singlesupporttime 0.8")
    pg.parseCmd(":doublesupporttime 0.1")
    pg.parseCmd(":numberstepsbeforestop 2")
    pg.parseCmd(":setfeetconstraint XY 0.091 0.0489")
else:
    pg.parseCmd(":SetAlgoForZmpTrajectory Kajita")
    pg.parseCmd(":singlesupporttime 0.78")
    pg.parseCmd(":doublesupporttime 0.02")
plug(robot.dynamic.position, pg.position)
plug(robot.dynamic.com, pg.com)
plug(robot.dynamic.signal("left-ankle"), pg.leftfootcurrentpos)
plug(robot.dynamic.signal("right-ankle"), pg.rightfootcurrentpos)
pg.motorcontrol.value = robot.dynamic.velocity.value.size * (0,)
pg.zmppreviouscontroller.value = (0, 0, 0)
pg.initState()

# --- the stack
sot = SOT("sot")
sot.setSize(robot.dynamic.getDimension())
plug(sot.control, robot.device.control)

contactLF = MetaTaskKine6d("contactLF", robot.dynamic, "LF", robot.OperationalPointsMap["left-ankle"])
contactLF.feature.frame("desired")
contactLF.gain.setConstant(300)
plug(pg.leftfootref, contactLF.featureDes.position)
contactRF = MetaTaskKine6d("contactRF", robot.dynamic, "RF", robot.OperationalPointsMap["right-ankle"])
contactRF.feature.frame("desired")
contactRF.gain.setConstant(300)
plug(pg.rightfootref, contactRF.featureDes.position)

taskCom = MetaTaskKineCom(robot.dynamic)
plug(pg.comref, taskCom.featureDes.errorIN)
plug(pg.dcomref, taskCom.featureDes.errordotIN)
taskCom.task.setWithDerivative(True)
taskCom.feature.selec.value = "111"
taskCom.gain.setConstant(300)

keepWaist = MetaTaskKine6d("keepWaist", robot.dynamic, "WT", robot.OperationalPointsMap["waist"])
keepWaist.feature.frame("desired")
keepWaist.feature.selec.value = "000111"
keepWaist.gain.setConstant(300)
plug(pg.waistattitudematrixabsolute, keepWaist.featureDes.position)

taskPosture = MetaTaskKinePosture(robot.dynamic)
taskPosture.ref = robot.halfSitting
taskPosture.gain.setConstant(10)

sot.push(contactRF.task.name)
sot.push(contactLF.task.name)
sot.push(taskCom.task.name)
sot.push(keepWaist.task.name)
sot.push(taskPosture.task.name)

# --- walk
if mode == "online":
    pg.parseCmd(":setVelReference 0.1 0.0 0.0")
    pg.parseCmd(":NaveauOnline")
else:
    pg.parseCmd(":stepseq 0.0 -0.085 0.0 0.0 0.2 0.17 0.0 0.0 0.2 -0.17 0.0 0.0 0.0 0.17 0.0 0.0")
pg.trigger.value = True
states = []
for i in range(int(round(seconds / dt))):
    robot.device.increment(dt)
    states.append(np.array(robot.device.state.value))
np.savez(outdir + "/walk.npz", q=np.array(states), dt=dt)
print("walked: pg inprocess", pg.inprocess.value)
