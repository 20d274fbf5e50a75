# A SoT user's reaching script for Talos, in the style of sot-talos' appli.py and
# sot-dynamic-pinocchio's kinetalos.py: the feet held as contacts, the centre of mass over
# them, the right hand's grip point (10 cm in front of the wrist, an opmodif) sent to a
# target with a position-only mask, a posture task below, some stack edits, and a Tracer
# writing its files. It imports nothing from sotpy.
#
#     sotpy run talos_reach.py OUTDIR [STEPS]
import sys

import numpy as np
from dynamic_graph import plug
from dynamic_graph.sot.core.matrix_util import matrixToTuple
from dynamic_graph.sot.core.meta_task_posture import MetaTaskKinePosture
from dynamic_graph.sot.core.meta_tasks_kine import MetaTaskKine6d, MetaTaskKineCom, gotoNd
from dynamic_graph.sot.core.sot import SOT
from dynamic_graph.sot.pyrene.robot import Robot
from dynamic_graph.tracer import Tracer
from numpy import eye

outdir = sys.argv[1]
steps = int(sys.argv[2]) if len(sys.argv) > 2 else 600

robot = Robot(name="talos")
dt = robot.timeStep

sot = SOT("sot")
sot.setSize(robot.dynamic.getDimension())
plug(sot.control, robot.device.control)

# --- the right hand: its grip point, 10 cm along the wrist's x axis
taskRH = MetaTaskKine6d("rh", robot.dynamic, "rh", robot.OperationalPointsMap["right-wrist"])
handMgrip = eye(4)
handMgrip[0:3, 3] = (0.1, 0, 0)
taskRH.opmodif = matrixToTuple(handMgrip)
taskRH.feature.frame("desired")

# --- static CoM
taskCom = MetaTaskKineCom(robot.dynamic)
robot.dynamic.com.recompute(0)
taskCom.featureDes.errorIN.value = robot.dynamic.com.value
taskCom.task.controlGain.value = 10
taskCom.feature.selec.value = "11"

# --- contacts
contactLF = MetaTaskKine6d(
    "contactLF", robot.dynamic, "LF", robot.OperationalPointsMap["left-ankle"]
)
contactLF.feature.frame("desired")
contactLF.gain.setConstant(10)
contactLF.keep()
contactRF = MetaTaskKine6d(
    "contactRF", robot.dynamic, "RF", robot.OperationalPointsMap["right-ankle"]
)
contactRF.feature.frame("desired")
contactRF.gain.setConstant(10)
contactRF.keep()

# --- posture
taskPosture = MetaTaskKinePosture(robot.dynamic)
taskPosture.ref = robot.halfSitting
taskPosture.gain.setConstant(1)

# --- the gaze, pushed and moved around before being removed
taskGaze = MetaTaskKine6d("gaze", robot.dynamic, "gaze", robot.OperationalPointsMap["gaze"])
taskGaze.keep()

target = (0.45, -0.3, 0.95)
gotoNd(taskRH, target, "111", (4.9, 0.9, 0.01, 0.9))

sot.push(taskGaze.task.name)
sot.clear()
sot.push(contactRF.task.name)
sot.push(contactLF.task.name)
sot.push(taskRH.task.name)
sot.push(taskCom.task.name)
sot.up(taskCom.task.name)  # the CoM before the hand
sot.push(taskGaze.task.name)
sot.push(taskPosture.task.name)
sot.down(taskGaze.task.name)  # below the posture
sot.rm(taskGaze.task.name)
print("stack:", " ".join(sot.list()))

# --- a tracer, as the robot classes make one
tracer = Tracer("trace")
tracer.open(outdir, "dg_", ".dat")
tracer.add(robot.device.name + ".state", "state")
tracer.add(robot.dynamic.name + ".com", "com")
tracer.add("opmodifrh.position", "grip")
robot.device.after.addSignal("trace.triger")
tracer.start()

feetBefore = [np.array(robot.dynamic.signal(op).value.homogeneous) for op in ("LF", "RF")]
for i in range(steps):
    robot.device.increment(dt)
tracer.dump()
tracer.stop()
tracer.close()

grip = np.array(taskRH.opPointModif.position.value.homogeneous)
feetAfter = [np.array(robot.dynamic.signal(op).value.homogeneous) for op in ("LF", "RF")]
np.savez(
    outdir + "/result.npz",
    grip=grip,
    target=np.array(target),
    feetBefore=np.array(feetBefore),
    feetAfter=np.array(feetAfter),
    com=np.array(robot.dynamic.com.value),
    comRef=np.array(taskCom.featureDes.errorIN.value),
    state=np.array(robot.device.state.value),
    stack=np.array(sot.list()),
)
print("grip point error: %.2e m" % np.linalg.norm(grip[0:3, 3] - target))
