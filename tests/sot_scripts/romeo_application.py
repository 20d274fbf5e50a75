# A SoT user's script in the style of sot-dynamic-pinocchio's robot classes and
# sot-application's Solver: the robot class is written by the user over a URDF (Romeo,
# from example-robot-data), the solver's control goes through a JointLimitator, joint
# limits are an inequality task (sot-dyninv's TaskJointLimits), the feet are held, the
# left hand goes to a pose given as (x, y, z, roll, pitch, yaw), the posture is set with
# gotoq, the stack is edited (push, up, down, rm, pop, clear, dispStack) and the robot's
# own tracer records. It imports nothing from sotpy.
#
#     sotpy run romeo_application.py OUTDIR [STEPS]
import sys

import numpy as np
import pinocchio
from dynamic_graph import plug
from dynamic_graph.sot.core.joint_limitator import JointLimitator
from dynamic_graph.sot.core.matrix_util import RPYToMatrix, matrixToRPY, matrixToTuple
from dynamic_graph.sot.core.meta_task_6d import toFlags
from dynamic_graph.sot.core.meta_task_posture import MetaTaskKinePosture
from dynamic_graph.sot.core.meta_tasks_kine import MetaTaskKine6d, MetaTaskKineCom, gotoNd
from dynamic_graph.sot.core.sot import SOT
from dynamic_graph.sot.dynamic_pinocchio import DynamicPinocchio
from dynamic_graph.sot.dynamic_pinocchio.humanoid_robot import AbstractHumanoidRobot
from dynamic_graph.sot.dyninv import TaskJointLimits
from example_robot_data import load_full

outdir = sys.argv[1]
steps = int(sys.argv[2]) if len(sys.argv) > 2 else 500


class Romeo(AbstractHumanoidRobot):
    """Romeo, from its URDF."""

    def __init__(self, name, urdfFile):
        self.OperationalPointsMap = {
            "left-wrist": "LWristPitch",
            "right-wrist": "RWristPitch",
            "left-ankle": "LAnkleRoll",
            "right-ankle": "RAnkleRoll",
            "gaze": "gaze",
            "waist": "root_joint",
        }
        self.loadModelFromUrdf(urdfFile, rootJointType=pinocchio.JointModelFreeFlyer)
        AbstractHumanoidRobot.__init__(self, name)
        self.OperationalPoints.append("waist")
        self.dynamic = DynamicPinocchio(self.name + "_dynamic")
        self.dynamic.setModel(self.pinocchioModel)
        self.dynamic.setData(self.pinocchioData)
        self.dimension = self.dynamic.getDimension()
        self.initializeRobot()
        self.initializeOpPoints()

    def defineHalfSitting(self, q):
        q[2] = 0.841652499
        legs = [0.0, 0.0, -0.3490658, 0.6981317, -0.3490658, 0.0]
        for side in "LR":
            names = ["HipYaw", "HipRoll", "HipPitch", "KneePitch", "AnklePitch", "AnkleRoll"]
            self.setJointValueInConfig(q, [side + n for n in names], legs)
        self.setJointValueInConfig(q, ["LShoulderPitch", "RShoulderPitch"], [1.5, 1.5])
        self.setJointValueInConfig(q, ["LElbowRoll", "RElbowRoll"], [-0.5, 0.5])


class Solver:
    def __init__(self, robot):
        self.robot = robot
        self.jointLimitator = JointLimitator("joint_limitator")
        plug(robot.dynamic.position, self.jointLimitator.joint)
        plug(robot.dynamic.upperJl, self.jointLimitator.upperJl)
        plug(robot.dynamic.lowerJl, self.jointLimitator.lowerJl)
        self.sot = SOT("solver")
        self.sot.signal("damping").value = 1e-6
        self.sot.setSize(robot.dimension)
        plug(self.sot.control, self.jointLimitator.controlIN)
        plug(self.jointLimitator.control, robot.device.control)

    def push(self, task):
        self.sot.push(task.name)

    def toList(self):
        return [x[1:-1] for x in self.sot.dispStack().split("|")[1:]]


_, _, urdf, _ = load_full("romeo")
robot = Romeo("romeo", urdf)
solver = Solver(robot)
dt = robot.timeStep

# --- joint limits, an inequality at the top (the free flyer excluded)
taskJL = TaskJointLimits("taskJL")
plug(robot.dynamic.position, taskJL.position)
taskJL.controlGain.value = 10
taskJL.referenceInf.value = robot.dynamic.lowerJl.value
taskJL.referenceSup.value = robot.dynamic.upperJl.value
taskJL.dt.value = dt
taskJL.selec.value = toFlags(range(6, robot.dimension))

# --- contacts
contacts = []
for name, op in (("LF", "left-ankle"), ("RF", "right-ankle")):
    contact = MetaTaskKine6d("contact" + name, robot.dynamic, name, robot.OperationalPointsMap[op])
    contact.feature.frame("desired")
    contact.gain.setConstant(10)
    contact.keep()
    contacts.append(contact)

# --- CoM over the feet
taskCom = MetaTaskKineCom(robot.dynamic)
robot.dynamic.com.recompute(0)
taskCom.featureDes.errorIN.value = robot.dynamic.com.value
taskCom.task.controlGain.value = 10
taskCom.feature.selec.value = "11"

# --- the left hand to a pose: 5 cm forward, 5 cm up, its orientation kept
taskLH = MetaTaskKine6d("lh", robot.dynamic, "lh", robot.OperationalPointsMap["left-wrist"])
taskLH.feature.frame("desired")
start = matrixToRPY(matrixToTuple(robot.dynamic.signal("lh").value))
goal = [start[0] + 0.05, start[1], start[2] + 0.05] + start[3:]
gotoNd(taskLH, goal, "111111", 4.0)

# --- posture: half-sitting (SoT's argument order: the gain, then the posture)
taskPosture = MetaTaskKinePosture(robot.dynamic)
taskPosture.gotoq(1.0, robot.halfSitting)

solver.push(taskLH.task)
solver.push(taskJL)
solver.push(contacts[0].task)
solver.push(contacts[1].task)
solver.push(taskCom.task)
solver.push(taskPosture.task)
for i in range(3):  # the joint limits, then the contacts and the CoM, above the hand
    solver.sot.up(taskJL.name)
for c in (contacts[0], contacts[1], taskCom):
    solver.sot.up(c.task.name)
solver.sot.down(taskLH.task.name)
solver.sot.down(taskLH.task.name)  # below the posture
solver.sot.up(taskLH.task.name)  # back above it
popped = solver.sot.pop()  # the posture
solver.sot.rm(taskCom.task.name)
solver.push(taskCom.task)  # back in, last
solver.sot.up(taskCom.task.name)  # above the hand
solver.push(taskPosture.task)
print("stack:", solver.toList())

# --- the robot's tracer, in OUTDIR
robot.initializeTracer()
robot.tracer.open(outdir, "dg_", ".dat")
robot.addTrace(robot.device.name, "state")
robot.addTrace(robot.dynamic.name, "lh")
robot.addTrace(solver.jointLimitator.name, "control")
robot.startTracer()

feetBefore = [np.array(robot.dynamic.signal(n).value.homogeneous) for n in ("LF", "RF")]
for i in range(steps):
    robot.device.increment(dt)
robot.stopTracer()

hand = matrixToRPY(matrixToTuple(robot.dynamic.signal("lh").value))
np.savez(
    outdir + "/result.npz",
    hand=np.array(hand),
    goal=np.array(goal),
    handM=np.array(robot.dynamic.signal("lh").value.homogeneous),
    goalM=RPYToMatrix(goal),
    feetBefore=np.array(feetBefore),
    feetAfter=np.array([robot.dynamic.signal(n).value.homogeneous for n in ("LF", "RF")]),
    state=np.array(robot.device.state.value),
    lower=np.array(robot.dynamic.lowerJl.value),
    upper=np.array(robot.dynamic.upperJl.value),
    stack=np.array(solver.toList()),
    popped=np.array(popped),
)
solver.sot.clear()
print("left hand error: %.2e" % np.abs(np.array(hand) - np.array(goal)).max())
