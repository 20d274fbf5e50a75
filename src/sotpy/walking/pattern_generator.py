r"""The SoT's walking pattern generator, ``PatternGenerator`` (sot-pattern-generator over
jrl-walkgen), native in sotpy.

A script builds it as the SoT's walking scripts do::

    pg = PatternGenerator("pg")
    pg.buildModel(robot)                      # sotpy's robot: soles, ankles, legs
    pg.parseCmd(":samplingperiod 0.005")      # jrl-walkgen's command lines
    pg.parseCmd(":comheight 0.876681")
    pg.parseCmd(":singlesupporttime 0.78")
    pg.parseCmd(":doublesupporttime 0.02")
    plug(robot.dynamic.com, pg.com)
    plug(robot.dynamic.signal("left-ankle"), pg.leftfootcurrentpos)
    plug(robot.dynamic.signal("right-ankle"), pg.rightfootcurrentpos)
    pg.initState()                            # the walk starts from here
    pg.parseCmd(":stepseq 0.0 -0.085 0.0 0.0  0.2 0.17 0.0 0.0 ...")
    pg.trigger.value = True                   # the walk starts at this tick

and plugs its outputs into the stack's references (``comref``/``dcomref`` into the CoM
task, ``leftfootref``/``rightfootref`` and their velocities into the feet tasks,
``waistattitudematrixabsolute`` into the waist's orientation). Every reference is in the
world frame (``frameReference("World")``, the only frame sotpy's generator has).

**The algorithms** (:mod:`sotpy.walking.walks`). *Footsteps* (``:stepseq`` in walk mode
0, 4 numbers a step, and ``addStep``; jrl-walkgen's ``Kajita``, and ``Morisawa``, ``PBW``,
``Dimitrov``, which track the same footsteps): the steps make a
:class:`~sotpy.walking.plan.StepPlan` (footprints, timing, C2 swing trajectories, the ZMP
reference), and Kajita's preview control of the cart-table model
(:mod:`sotpy.walking.preview`) turns its ZMP reference into the CoM's trajectory, one
sample every ``:samplingperiod`` (5 ms), computed when the steps are given; between two
samples the CoM is the exact cubic of the sample's constant jerk, so a 1 ms controller
reads a C2 CoM, and the feet are the plan's closed forms at the tick's time.
``:useDynamicFilter true`` adds Kajita's second stage (:mod:`sotpy.walking.dynamic_filter`).
*Velocity* (``:HerdtOnline``, ``:NaveauOnline``; ``velocitydes``): the walking MPC of
:mod:`sotpy.walking.mpc`, replanned every 0.1 s. docs/walking.md has the parseCmd table.

**Time.** The generator's time is the graph's tick: ``t_walk = (t - t0) dt`` with ``t0``
the first tick at which ``trigger`` is read true and ``dt`` the control period: the time
step of the robot's device (``buildModel``), or ``setTimeStep``'s; 1 ms, as the C++
entity assumes (five ticks per 5 ms sample), when the device has not ticked yet. A
device ticking at another period than the clock assumes is refused with an error: the
walk would run slower or faster than the robot. Before the trigger every output holds
the initial state; after the plan's end and the CoM's settling (one preview time),
``inprocess`` becomes false and the outputs hold the final state. A ``trigger`` set false
during a walk freezes the references where they are.

**Bad input** is refused before anything moves, with a :class:`~sotpy.errors.CommandError`
naming the entity, the command and what was expected: a step the robot cannot take
(longer than the leg, feet crossing or overlapping, a step time below the sampling
period), a CoM height above the legs' reach, a parseCmd line of the wrong count or type;
an unknown parseCmd command warns (:class:`~sotpy.errors.SotpyWarning`) naming the
nearest known one and is then ignored, as jrl-walkgen ignores it (silently, there).
"""

from __future__ import annotations

import difflib
import math
import warnings
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np
import pinocchio as pin

from ..dynamics.types import SE3
from ..errors import CommandError, EntityError, SignalTypeError, SotpyError, SotpyWarning
from ..graph import BOOL, INT, MATRIX, VECTOR, Entity, Input, Output, command
from ..graph.command import Command
from .mpc import MPCParameters
from .plan import Footprint, Sole, StepPlan, checkStep, quintic
from .preview import GRAVITY, previewGains
from .walks import FootstepWalk, VelocityWalk

__all__ = ["PatternGenerator", "RobotGeometry", "robotGeometry"]

_SIDES = ("left", "right")
_FOOTSTEP_ALGORITHMS = ("Kajita", "Morisawa", "PBW", "Dimitrov")
_VELOCITY_ALGORITHMS = ("Herdt", "Naveau")
#: How long the CoM takes to reach ``:comheight`` from its height at initState (s).
HEIGHT_TIME = 1.0
#: The velocity walk's MPC period (s), Herdt et al.'s.
_MPC_PERIOD = 0.1


def _rotz(yaw: float) -> np.ndarray:
    c, s = math.cos(yaw), math.sin(yaw)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


class RobotGeometry:
    """What the generator needs of a robot (:func:`robotGeometry`): per side the
    :class:`~sotpy.walking.plan.Sole`, the sole frame's name and ``soleToAnkle`` (the
    ankle op point's placement in the sole frame, ``pinocchio.SE3``); ``legLength`` (m,
    hip to ankle with the knee straight) and ``maxComHeight`` (m, the CoM's height with
    the legs straight, from the configuration it was measured at); for the dynamic
    filter, the Pinocchio ``model``, the ankles' and the waist's frame ids
    (``ankleFrames``, ``waistFrame``) and the half-sitting ``posture`` (q)."""

    def __init__(
        self,
        name: str,
        sole: Sole,
        soleFrames: dict[str, str],
        soleToAnkle: dict[str, pin.SE3],
        legLength: float,
        maxComHeight: float,
        model: Any = None,
        ankleFrames: dict[str, int] | None = None,
        waistFrame: int | None = None,
        posture: np.ndarray | None = None,
    ) -> None:
        self.model, self.ankleFrames, self.waistFrame = model, ankleFrames, waistFrame
        self.posture = posture
        self.name = name
        self.sole = sole
        self.soleFrames = soleFrames
        self.soleToAnkle = soleToAnkle
        self.legLength = legLength
        self.maxComHeight = maxComHeight


def robotGeometry(robot: Any) -> RobotGeometry:
    """The :class:`RobotGeometry` of a sotpy robot (``load_robot``'s
    :class:`~sotpy.dynamics.robot.Robot`), measured at its device's current state.

    ``legLength`` sums the joint offsets from the hip (the first joint of the leg's
    chain) down to the ankle op point's joint: the longest the leg can be.
    ``maxComHeight`` is the CoM's height plus what straightening the legs adds to the
    hips' height.

    Raises:
        EntityError: the robot has no feet or no ``left-ankle``/``right-ankle`` op point.
    """
    missing = [s for s in _SIDES if s not in robot.feet] + [
        f"{s}-ankle" for s in _SIDES if f"{s}-ankle" not in robot.opPoints
    ]
    if missing:
        raise EntityError(
            f"robot {robot.name!r}: a walking robot needs two feet and the op points "
            f"left-ankle and right-ankle; missing: {', '.join(missing)}"
        )
    model = robot.model
    data = model.createData()
    q = np.asarray(robot.device.state.value, dtype=float)
    pin.forwardKinematics(model, data, q)
    pin.updateFramePlacements(model, data)
    com = pin.centerOfMass(model, data, q)
    left, right = robot.feet["left"], robot.feet["right"]
    if (left.length, left.width) != (right.length, right.width):
        raise EntityError(f"robot {robot.name!r}: the generator needs two soles of one size")
    sole = Sole(left.length, left.width, (left.offset[0], left.offset[1]))
    toAnkle, legs, rise = {}, [], []
    for side in _SIDES:
        oMs = data.oMf[model.getFrameId(robot.feet[side].frame)]
        ankleFrame = model.frames[model.getFrameId(robot.opPoints[f"{side}-ankle"])]
        toAnkle[side] = oMs.actInv(data.oMf[model.getFrameId(ankleFrame.name)])
        chain, j = [], ankleFrame.parentJoint
        while j > 0 and model.parents[j] > 0 and model.nqs[model.parents[j]] < 7:
            chain.append(j)
            j = model.parents[j]
        hip = j  # the first joint of the leg (its parent is the root or the base)
        length = sum(float(np.linalg.norm(model.jointPlacements[k].translation)) for k in chain)
        now = float(
            np.linalg.norm(data.oMi[hip].translation - data.oMi[ankleFrame.parentJoint].translation)
        )
        legs.append(length)
        rise.append(length - now)
    return RobotGeometry(
        robot.name,
        sole,
        {s: robot.feet[s].frame for s in _SIDES},
        toAnkle,
        min(legs),
        float(com[2]) + min(rise),
        model,
        {s: model.getFrameId(robot.opPoints[f"{s}-ankle"]) for s in _SIDES},
        model.getFrameId(robot.opPoints["waist"]) if "waist" in robot.opPoints else None,
        np.asarray(robot.halfSitting, dtype=float).copy(),
    )


# -- parseCmd -----------------------------------------------------------------------
#: jrl-walkgen's commands sotpy's generator accepts with no effect on its walk, and why
#: (docs/walking.md has the table): they tune parts of jrl-walkgen sotpy does not have
#: (its arm swing, its own inverse kinematics, its ZMP shifts and time distribution).
INERT_COMMANDS: dict[str, str] = {
    ":armparameters": "jrl-walkgen's arm swing (sotpy's stack holds the arms)",
    ":LimitsFeasibility": "jrl-walkgen's own IK feasibility margin",
    ":ZMPShiftParameters": "ZMP shifts inside the sole (sotpy's ZMP is the sole's centre)",
    ":TimeDistributionParameters": "jrl-walkgen's time distribution of the steps",
    ":UpperBodyMotionParameters": "jrl-walkgen's upper-body motion",
    ":SetZMPFrame": "the ZMP's frame (sotpy's zmpref is in the world)",
    ":SetAutoFirstStep": "jrl-walkgen's automatic first step (the plan starts as given)",
    ":setDSFeetDistance": "the online MPC's feet distance",
    ":numberstepsbeforestop": "the online MPC's steps before stopping",
    ":deleteallobstacles": "Naveau's obstacles",
}


_MODEL_FILES = (
    "sotpy's generator takes its model from a sotpy robot, not from files: "
    "pg.buildModel(robot) with robot = load_robot('talos') (or a robot description's URDF, "
    "docs/robots.md)"
)


def _refused(name: str, way: str) -> Command:
    """A command of the C++ entity sotpy refuses, saying ``way`` (what to do instead)."""

    def refuse(self: PatternGenerator, *args: Any) -> None:
        raise CommandError(f"PatternGenerator({self.name}).{name}: {way}")

    refuse.__doc__ = f"Refused: {way}."
    return Command(refuse, name)


class PatternGenerator(Entity):
    """The walking pattern generator (module doc): SoT's ``PatternGenerator``.

    Commands: ``buildModel(robot)``, ``initState()``, ``parseCmd(line)``,
    ``addStep(x, y, theta)`` (= ``addOnLineStep``), ``setSingleSupportTime(s)``,
    ``setDoubleSupportTime(s)``, ``frameReference(name)``, ``getTimeStep()``,
    ``setTimeStep(dt)``, ``getInitByRealState()``, ``setInitByRealState(b)``,
    ``feedBackControl(b)``, ``dynamicFilter(b)``, ``debug()``; the model-file commands
    of the C++ entity (``setURDFpath``, ``setSRDFpath``, ``setXmlRank``,
    ``setSoleParameters``, ``addJointMapping``, ``setParamPreview``) and the VRML-era
    ones (``setVrmlDir``, ``setVrml``, ``setXmlSpec``) are refused with the way to do it.
    """

    className = "PatternGenerator"

    position = Input(
        VECTOR, default=np.zeros(0), doc="q of the robot (unused: initState reads com and feet)"
    )
    motorcontrol = Input(VECTOR, default=np.zeros(0), doc="last commanded q (unused)")
    zmppreviouscontroller = Input(VECTOR, default=np.zeros(3), doc="previous ZMP (unused)")
    com = Input(VECTOR, doc="the robot's CoM (m, world), read by initState")
    comStateSIN = Input(VECTOR, default=np.zeros(3), doc="CoM state for feedBackControl (unused)")
    zmpSIN = Input(VECTOR, default=np.zeros(3), doc="ZMP for feedBackControl (unused)")
    forceSIN = Input(VECTOR, default=np.zeros(6), doc="external force (unused)")
    velocitydes = Input(VECTOR, default=np.zeros(3), doc="(vx, vy, omega) (m/s, rad/s)")
    trigger = Input(BOOL, default=False, doc="true: walk; false: hold the references")
    leftfootcurrentpos = Input(SE3, doc="the left ankle's placement, read by initState")
    rightfootcurrentpos = Input(SE3, doc="the right ankle's placement, read by initState")

    def __init__(self, name: str) -> None:
        super().__init__(name)
        self._geometry: RobotGeometry | None = None
        self._device: Any = None  # the robot's Device: its time step is the control period
        self._dtSet = False
        self._T = 0.005
        self._dt = 0.001
        self._previewTime = 1.6
        self._comHeight: float | None = None
        self._stepHeight = 0.05
        self._ss = 0.78
        self._ds = 0.02
        self._tStart = 1.0
        self._tEnd = 1.0
        self._walkMode = 0
        self._algorithm = "Kajita"
        self._initByRealState = True
        self._pending: list[tuple[float, float, float]] = []
        self._initial: dict[str, Any] | None = None
        self._walk: FootstepWalk | VelocityWalk | None = None
        self._online = False
        self._zmpBox: tuple[float, float] | None = None
        self._filter = False
        #: what the dynamic filter predicted of its plan (None: not run), see
        #: :func:`sotpy.walking.dynamic_filter.dynamicFilter`
        self.filterStats: dict[str, float] | None = None
        self._t0: int | None = None
        self._out: dict[str, Any] = {}
        self._restCache: dict[str, tuple[Any, Any]] = {}  # a foot at rest's outputs
        self._inert: dict[str, list[str]] = {}

    # -- model and state -----------------------------------------------------------
    @command
    def buildModel(self, robot: Any = None) -> None:
        """Read the robot's soles, ankles and legs (:func:`robotGeometry`) from a sotpy
        robot (``load_robot``'s, or its name in this process); without an argument, the
        one robot loaded in this process."""
        from ..dynamics.robot import loadedRobots

        who = f"PatternGenerator({self.name}).buildModel"
        if robot is None or isinstance(robot, str):
            robots = loadedRobots()
            if isinstance(robot, str):
                robots = [r for r in robots if r.name == robot or r.dynamic.name == robot]
            if len(robots) != 1:
                names = ", ".join(f"{r.name} ({r.dynamic.name})" for r in robots) or "none"
                raise CommandError(
                    f"{who}: expected one robot loaded in this process to build the model "
                    f"from (load_robot), found {len(robots)}: {names}; pass the robot: "
                    f"buildModel(robot)"
                )
            robot = robots[0]
        self._geometry = robotGeometry(robot)
        self._device = robot.device

    def _requireModel(self, what: str) -> RobotGeometry:
        if self._geometry is None:
            raise CommandError(f"{self._who(what)}: no model yet; call buildModel(robot) first")
        return self._geometry

    @command
    def initState(self) -> None:
        """Read the current CoM (``com``) and ankles (``leftfootcurrentpos``,
        ``rightfootcurrentpos``): the walk starts from them. Steps given before are kept."""
        geo = self._requireModel("initState")
        com = np.asarray(self.com.value, dtype=float)
        if com.shape != (3,) or not np.all(np.isfinite(com)):
            raise CommandError(
                f"PatternGenerator({self.name}).initState: input 'com' must be a finite "
                f"3-vector (m), got {com!r}"
            )
        ankles = {"left": self.leftfootcurrentpos.value, "right": self.rightfootcurrentpos.value}
        footprints = {}
        for side, oMa in ankles.items():
            oMs = oMa * geo.soleToAnkle[side].inverse()
            yaw = math.atan2(oMs.rotation[1, 0], oMs.rotation[0, 0])
            footprints[side] = Footprint(
                float(oMs.translation[0]), float(oMs.translation[1]), yaw, side
            )
        q = np.asarray(self.position.value, dtype=float)
        if q.size >= 7 and np.all(np.isfinite(q[3:7])) and np.linalg.norm(q[3:7]) > 0.5:
            # a free-flyer's q: the waist's orientation, less its yaw (the feet's)
            R = pin.Quaternion(q[6], q[3], q[4], q[5]).normalized().toRotationMatrix()
        else:
            R = np.eye(3)
        yaw0 = math.atan2(
            math.sin(footprints["left"].yaw) + math.sin(footprints["right"].yaw),
            math.cos(footprints["left"].yaw) + math.cos(footprints["right"].yaw),
        )
        waist = pin.utils.rpyToMatrix(0.0, 0.0, -yaw0) @ R
        offsets = {}
        for side, oMa in ankles.items():
            f = footprints[side]
            flat = pin.SE3(pin.utils.rpyToMatrix(0.0, 0.0, f.yaw), np.array([f.x, f.y, 0.0]))
            offsets[side] = pin.log6((flat * geo.soleToAnkle[side]).actInv(oMa)).vector
        self._initial = {
            "q": q.copy() if q.size == self._geometry.model.nq else self._geometry.posture.copy(),
            "com": com,
            "ankles": ankles,
            "footprints": footprints,
            "waist": waist,
            "offsets": offsets,
        }
        if self._comHeight is None:
            self._comHeight = float(com[2])
        self._checkComHeight(self._comHeight, "initState")
        self._walk = None
        self._t0 = None
        if self._pending:
            self._walk = self._footstepWalk(self._footprints(self._pending, "initState"))
        self._holdInitial()

    def _checkComHeight(self, h: float, what: str) -> None:
        geo = self._geometry
        if geo is not None and h > geo.maxComHeight:
            raise CommandError(
                f"PatternGenerator({self.name}).{what}: a CoM height of {h:.4f} m is above "
                f"the legs' reach ({geo.maxComHeight:.4f} m with the legs straight)"
            )

    def _who(self, what: str) -> str:
        """``PatternGenerator(name).what`` for an error message (``what`` as it is when it
        already names the entity: parseCmd's)."""
        return (
            what
            if what.startswith("PatternGenerator(")
            else f"PatternGenerator({self.name}).{what}"
        )

    # -- steps -----------------------------------------------------------------------
    def _footprints(self, steps: Sequence[tuple[float, float, float]], who: str) -> list[Footprint]:
        """jrl-walkgen's relative steps (x, y, theta in degrees) as footprints: the first
        one chooses the first support foot (the sign of y) and must be where that foot
        is, relative to the mid-point of the feet; each next one is the next support
        foot relative to the previous one."""
        geo = self._requireModel(who)
        if self._initial is None:
            raise CommandError(f"{self._who(who)}: call initState() first")
        feet = self._initial["footprints"]
        started = isinstance(self._walk, FootstepWalk) and self._t0 is not None
        if started and self._walk.plan.steps:
            support = self._walk.plan.steps[-1]
            out: list[Footprint] = []
            rest = list(steps)
        else:
            x, y, th = steps[0]
            side = "right" if y < 0 else "left"
            mid = Footprint(
                (feet["left"].x + feet["right"].x) / 2,
                (feet["left"].y + feet["right"].y) / 2,
                (feet["left"].yaw + feet["right"].yaw) / 2,
                side,
            )
            dx, dy, _ = mid.relative(feet[side])
            if math.hypot(dx - x, dy - y) > 0.01:
                raise CommandError(
                    f"{self._who(who)}: the first step places the first "
                    f"support foot ({side}) at ({x:.3f}, {y:.3f}) from the feet's mid-point; "
                    f"that foot is at ({dx:.3f}, {dy:.3f}) (a first step must be where the "
                    f"support foot is, within 1 cm)"
                )
            support = feet[side]
            out = []
            rest = list(steps[1:])
        for x, y, th in rest:
            side = "left" if support.side == "right" else "right"
            c, s = math.cos(support.yaw), math.sin(support.yaw)
            f = Footprint(
                support.x + c * x - s * y,
                support.y + s * x + c * y,
                support.yaw + math.radians(th),
                side,
            )
            checkStep(f"{self._who(who)}", support, f, geo.sole, geo.legLength)
            out.append(f)
            support = f
        return out

    def _addSteps(self, steps: list[tuple[float, float, float]], who: str) -> None:
        if isinstance(self._walk, VelocityWalk) or self._online:
            raise CommandError(
                f"{self._who(who)}: the walk is driven by velocitydes "
                f"(:HerdtOnline); steps cannot be added to it"
            )
        if self._t0 is None:
            all_steps = self._pending + steps
            footprints = self._footprints(all_steps, who)  # refused now, before anything moves
            self._pending = all_steps
            self._walk = self._footstepWalk(footprints)
            return
        new = self._footprints(steps, who)
        self._walk.extend(new, self._now())

    @command
    def addStep(self, x: float, y: float, theta: float) -> None:
        """Add a step: the next support foot at ``(x, y)`` (m) and ``theta`` (degrees)
        relative to the previous one (the first step of a walk: relative to the feet's
        mid-point). During a walk the step is appended to the plan (it must begin after
        now). Upstream binds ``addStep`` to ``addOnLineStep``; so does sotpy."""
        self._addSteps([(float(x), float(y), float(theta))], "addStep")

    @command
    def addOnLineStep(self, x: float, y: float, theta: float) -> None:
        """The same as :meth:`addStep`."""
        self._addSteps([(float(x), float(y), float(theta))], "addOnLineStep")

    @command
    def setSingleSupportTime(self, time: float) -> None:
        """The single support's duration (s), at least the sampling period."""
        self._ss = self._stepTime("setSingleSupportTime", time)
        self._replan()

    @command
    def setDoubleSupportTime(self, time: float) -> None:
        """The double support's duration (s), at least the sampling period."""
        self._ds = self._stepTime("setDoubleSupportTime", time)
        self._replan()

    def _stepTime(self, who: str, time: float) -> float:
        t = float(time)
        if not math.isfinite(t) or t < self._T - 1e-12:
            raise CommandError(
                f"{self._who(who)}: a step time must be at least the "
                f"sampling period {self._T} s, got {time!r}"
            )
        self._requireIdle(who)
        return t

    def _requireIdle(self, who: str) -> None:
        if self._t0 is not None and self._walk is not None and not self._walk.finished(self._now()):
            raise CommandError(
                f"{self._who(who)}: cannot change the walk's parameters during a walk"
            )

    def _replan(self) -> None:
        """A parameter changed before the trigger: the planned walk is made again."""
        if self._t0 is None and isinstance(self._walk, FootstepWalk):
            self._walk = self._footstepWalk(self._footprints(self._pending, "replan"))

    @command
    def frameReference(self, frame: str) -> None:
        """The frame of the references: ``World`` only (sotpy's outputs are in the world)."""
        if frame != "World":
            raise CommandError(
                f"PatternGenerator({self.name}).frameReference: sotpy's generator writes its "
                f"references in the world frame only ('World'), got {frame!r}"
            )

    @command
    def getTimeStep(self) -> float:
        """The control period ``dt`` (s): the time between two ticks. Default: the time
        step of the robot's device (``buildModel``), read at the walk's first tick; 1 ms
        (the C++ entity's five ticks per 5 ms sample) when it has none yet."""
        return self._dt

    @command
    def setTimeStep(self, dt: float) -> None:
        """Set the control period ``dt`` (s), at most the sampling period."""
        v = float(dt)
        if not math.isfinite(v) or v <= 0 or v > self._T + 1e-12:
            raise CommandError(
                f"PatternGenerator({self.name}).setTimeStep: the control period must be > 0 "
                f"and at most the sampling period {self._T} s, got {dt!r}"
            )
        self._requireIdle("setTimeStep")
        self._dt = v
        self._dtSet = True

    @command
    def getInitByRealState(self) -> bool:
        """Whether initState reads the robot's state (always true here)."""
        return self._initByRealState

    @command
    def setInitByRealState(self, value: bool) -> None:
        """Accepted for SoT scripts; sotpy always starts from the robot's state."""
        self._initByRealState = bool(value)

    @command
    def feedBackControl(self, on: bool) -> None:
        """jrl-walkgen's state feedback: refused when true (sotpy's feedback is the
        balance chain's, sotpy.walking's docs)."""
        self.parseCmd(f":feedBackControl {'true' if on else 'false'}")

    @command
    def dynamicFilter(self, on: bool) -> None:
        """Kajita's second stage (:mod:`sotpy.walking.dynamic_filter`), as
        ``:useDynamicFilter``."""
        self.parseCmd(f":useDynamicFilter {'true' if on else 'false'}")

    @command
    def debug(self) -> str:
        """A summary of the generator's parameters and plan."""
        lines = [
            f"PatternGenerator({self.name}): robot "
            f"{self._geometry.name if self._geometry else None}",
            f"  sampling period {self._T} s, control period {self._dt} s, "
            f"preview {self._previewTime} s",
            f"  CoM height {self._comHeight} m, step height {self._stepHeight} m",
            f"  single support {self._ss} s, double support {self._ds} s",
            f"  steps pending {len(self._pending)}, walk: " + self._walkSummary(),
        ]
        for cmd, args in sorted(self._inert.items()):
            lines.append(f"  {cmd} {' '.join(args)}: recorded, no effect ({INERT_COMMANDS[cmd]})")
        return "\n".join(lines)

    def _walkSummary(self) -> str:
        w = self._walk
        if isinstance(w, FootstepWalk):
            return f"{len(w.plan.steps)} swings, {w.plan.duration:.3f} s"
        if isinstance(w, VelocityWalk) or self._online:
            return "driven by velocitydes (online)"
        return "none"

    # the C++ entity's model-file and VRML-era commands, each refused with the way to do it
    setURDFpath = _refused("setURDFpath", _MODEL_FILES)
    setSRDFpath = _refused("setSRDFpath", _MODEL_FILES)
    setXmlRank = _refused("setXmlRank", _MODEL_FILES)
    setVrmlDir = _refused("setVrmlDir", _MODEL_FILES)
    setVrml = _refused("setVrml", _MODEL_FILES)
    setXmlSpec = _refused("setXmlSpec", _MODEL_FILES)
    setParamPreview = _refused(
        "setParamPreview",
        "the preview gains come from the Riccati equation (:previewcontroltime sets the preview)",
    )
    setSoleParameters = _refused(
        "setSoleParameters", "the soles are the robot description's [feet] (buildModel(robot))"
    )
    addJointMapping = _refused(
        "addJointMapping",
        "the ankles are the robot's left-ankle and right-ankle op points (buildModel(robot))",
    )

    # -- parseCmd --------------------------------------------------------------------
    @command
    def parseCmd(self, line: str) -> None:
        """One of jrl-walkgen's command lines (``:comheight 0.876681``); the table of
        docs/walking.md lists them. An unknown command warns, naming the nearest known
        one, and is ignored."""
        words = str(line).split()
        if not words:
            raise CommandError(f"PatternGenerator({self.name}).parseCmd: an empty command line")
        cmd, args = words[0], words[1:]
        who = f"PatternGenerator({self.name}).parseCmd({cmd})"
        handler = _PARSERS.get(cmd)
        if handler is not None:
            handler(self, who, args)
            return
        if cmd in INERT_COMMANDS:
            self._inert[cmd] = args
            return
        known = sorted([*_PARSERS, *INERT_COMMANDS])
        near = difflib.get_close_matches(cmd, known, n=1, cutoff=0.6)
        hint = f"; did you mean {near[0]}?" if near else ""
        warnings.warn(
            f"{who}: unknown command, ignored (as jrl-walkgen ignores it){hint}",
            SotpyWarning,
            stacklevel=3,
        )

    def _numbers(self, who: str, args: list[str], count: int | None = None) -> list[float]:
        if count is not None and len(args) != count:
            raise CommandError(f"{who}: expected {count} number(s), got {len(args)}: {args}")
        try:
            values = [float(a) for a in args]
        except ValueError:
            raise CommandError(f"{who}: expected numbers, got {args}") from None
        if not all(math.isfinite(v) for v in values):
            raise CommandError(f"{who}: expected finite numbers, got {args}")
        return values

    def _positive(self, who: str, args: list[str]) -> float:
        (v,) = self._numbers(who, args, 1)
        if v <= 0:
            raise CommandError(f"{who}: expected a number > 0, got {v}")
        return v

    def _cmdSampling(self, who: str, args: list[str]) -> None:
        v = self._positive(who, args)
        if v < self._dt - 1e-12:
            raise CommandError(
                f"{who}: the sampling period {v} s is below the control period {self._dt} s"
            )
        self._requireIdle(who)
        self._T = v
        self._replan()

    def _cmdPreview(self, who: str, args: list[str]) -> None:
        v = self._positive(who, args)
        self._requireIdle(who)
        self._previewTime = v
        self._replan()

    def _cmdComHeight(self, who: str, args: list[str]) -> None:
        v = self._positive(who, args)
        self._checkComHeight(v, "parseCmd(:comheight)")
        self._requireIdle(who)
        self._comHeight = v
        self._replan()

    def _cmdStepHeight(self, who: str, args: list[str]) -> None:
        (v,) = self._numbers(who, args, 1)
        if v < 0:
            raise CommandError(f"{who}: expected a step height >= 0 (m), got {v}")
        self._stepHeight = v
        self._replan()

    def _cmdSS(self, who: str, args: list[str]) -> None:
        self._ss = self._stepTime(who, self._positive(who, args))
        self._replan()

    def _cmdDS(self, who: str, args: list[str]) -> None:
        self._ds = self._stepTime(who, self._positive(who, args))
        self._replan()

    def _cmdOmega(self, who: str, args: list[str]) -> None:
        (v,) = self._numbers(who, args, 1)
        if v != 0.0:
            raise CommandError(f"{who}: sotpy's feet land flat (omega 0); got {v} degrees")

    def _cmdWalkMode(self, who: str, args: list[str]) -> None:
        (v,) = self._numbers(who, args, 1)
        if v not in (0.0, 4.0):
            raise CommandError(
                f"{who}: sotpy reads :stepseq in walk mode 0 (x y theta z a step; 4 the "
                f"same), got walk mode {v:g}"
            )
        self._walkMode = int(v)

    def _cmdAlgo(self, who: str, args: list[str]) -> None:
        if len(args) != 1:
            raise CommandError(f"{who}: expected one algorithm name, got {args}")
        name = args[0]
        if name not in (*_FOOTSTEP_ALGORITHMS, *_VELOCITY_ALGORITHMS):
            raise CommandError(
                f"{who}: expected one of {', '.join(_FOOTSTEP_ALGORITHMS)} (footsteps: "
                f"Kajita's preview control) or {', '.join(_VELOCITY_ALGORITHMS)} (velocitydes: "
                f"the walking MPC), got {name!r}"
            )
        self._requireIdle(who)
        self._algorithm = name

    def _cmdOnline(self, who: str, args: list[str]) -> None:
        """``:HerdtOnline`` / ``:NaveauOnline``: the walk at the trigger is driven by
        ``velocitydes`` (its numbers, if any, are ignored as jrl-walkgen ignores them)."""
        self._numbers(who, args)
        self._requireModel(who)
        if self._initial is None:
            raise CommandError(f"{who}: call initState() first")
        self._requireIdle(who)
        step = self._ss + self._ds
        if abs(step / _MPC_PERIOD - round(step / _MPC_PERIOD)) > 1e-9:
            raise CommandError(
                f"{who}: the velocity walk's step ({self._ss} + {self._ds} s) must be a "
                f"multiple of its MPC period {_MPC_PERIOD} s"
            )
        if self._ds < _MPC_PERIOD - 1e-9:
            raise CommandError(
                f"{who}: the velocity walk's double support ({self._ds} s) must last at least "
                f"its MPC period {_MPC_PERIOD} s: the MPC constrains the ZMP at its samples, "
                f"and between two of them the ZMP moves from one sole to the other"
            )
        if self._ss < _MPC_PERIOD + 0.3 - 1e-9:
            raise CommandError(
                f"{who}: the velocity walk's single support ({self._ss} s) must last at least "
                f"{_MPC_PERIOD + 0.3:g} s (its swing ends one MPC period early)"
            )
        if self._pending:
            raise CommandError(
                f"{who}: steps were given (:stepseq, addStep): one walk or the other"
            )
        from .mpc import VelocityMPC

        VelocityMPC(self.mpcParameters())  # refuse now the parameters the MPC refuses
        self._online = True
        if self._algorithm in _FOOTSTEP_ALGORITHMS:
            self._algorithm = "Herdt" if "Herdt" in who else "Naveau"

    def _cmdDynamicFilter(self, who: str, args: list[str]) -> None:
        if len(args) != 1 or args[0] not in ("true", "false"):
            raise CommandError(f"{who}: expected 'true' or 'false', got {args}")
        self._requireIdle(who)
        self._filter = args[0] == "true"
        self._replan()

    def _cmdVelReference(self, who: str, args: list[str]) -> None:
        v = self._numbers(who, args, 3)
        self.velocitydes.value = np.array(v)

    def _cmdFeetConstraint(self, who: str, args: list[str]) -> None:
        if len(args) != 3 or args[0] != "XY":
            raise CommandError(f"{who}: expected 'XY mx my' (m), got {args}")
        mx, my = self._numbers(who, args[1:], 2)
        geo = self._requireModel(who)
        hl, hw = geo.sole.length / 2 - mx, geo.sole.width / 2 - my
        if hl <= 0 or hw <= 0:
            raise CommandError(
                f"{who}: the ZMP box (the sole's half sizes {geo.sole.length / 2:.4f} x "
                f"{geo.sole.width / 2:.4f} m minus ({mx}, {my})) would be empty"
            )
        self._zmpBox = (hl, hw)

    def _cmdStepSeq(self, who: str, args: list[str]) -> None:
        values = self._numbers(who, args)
        if len(values) % 4:
            legacy = (
                " (it fits the legacy 3-number form x y theta: jrl-walkgen reads 4 since 2014)"
                if len(values) % 3 == 0
                else ""
            )
            raise CommandError(
                f"{who}: walk mode 0 reads 4 numbers a step (x y theta z); got "
                f"{len(values)} numbers{legacy}"
            )
        steps = []
        for i in range(0, len(values), 4):
            x, y, th, z = values[i : i + 4]
            if z != 0.0:
                raise CommandError(
                    f"{who}: step {i // 4 + 1} has z = {z} m: sotpy walks on flat ground"
                )
            steps.append((x, y, th))
        if not steps:
            raise CommandError(f"{who}: no step given")
        self._addSteps(steps, who)

    # -- the walk --------------------------------------------------------------------
    def _now(self) -> float:
        return 0.0 if self._t0 is None else (self._tick - self._t0) * self._dt

    def _footstepWalk(self, footprints: list[Footprint]) -> FootstepWalk:
        """The walk of these footprints from the state of initState (module doc)."""
        plan = StepPlan(
            dict(self._initial["footprints"]),
            footprints,
            self._ss,
            self._ds,
            self._previewTime + self._tStart,
            self._tEnd,
            self._stepHeight,
            self._geometry.sole,
            zmpStart=self._initial["com"][:2],
            tHold=self._previewTime,
        )
        gains = previewGains(self._T, self._comHeight, self._previewTime)
        walk = FootstepWalk(plan, gains, self._initial["com"])
        self.filterStats = None
        if self._filter and footprints:
            from .dynamic_filter import dynamicFilter

            self.filterStats = dynamicFilter(self, walk)
        return walk

    def mpcParameters(self) -> MPCParameters:
        """The velocity walk's MPC parameters from the robot and the commands: the step
        timing, the CoM height, the ZMP box (``:setfeetconstraint``; default a quarter of
        the sole's half sizes around its centre), the feet's distance at initState and
        step bounds from the leg's length."""
        geo = self._geometry
        fp = self._initial["footprints"]
        d = math.hypot(fp["left"].x - fp["right"].x, fp["left"].y - fp["right"].y)
        hl, hw = self._zmpBox or (geo.sole.length / 16, geo.sole.width / 8)
        return MPCParameters(
            comHeight=self._comHeight,
            period=_MPC_PERIOD,
            horizon=round(self._previewTime / _MPC_PERIOD),
            singleSupport=self._ss,
            doubleSupport=self._ds,
            footHalfLength=hl,
            footHalfWidth=hw,
            feetDistance=d,
            maxStepForward=0.45 * geo.legLength,
            maxStepBackward=0.15 * geo.legLength,
            lateralRange=(max(geo.sole.width + 0.01, 0.9 * d), max(1.5 * d, geo.sole.width + 0.02)),
            gravity=GRAVITY,
        )

    def _start(self, t: int) -> None:
        if self._initial is None:
            raise EntityError(
                f"PatternGenerator({self.name}): trigger is true but initState() was never called"
            )
        if self._online:
            self._walk = VelocityWalk(
                dict(self._initial["footprints"]),
                self._initial["com"],
                self._geometry.sole,
                self.mpcParameters(),
                self._stepHeight,
            )
        elif self._walk is None:
            self._walk = self._footstepWalk([])
        self._t0 = t
        self._tick = t

    def _checkPeriod(self, first: bool) -> None:
        """The device's time step is the generator's control period: adopted at the
        walk's first tick unless ``setTimeStep`` set one; a device that ticks at another
        period than the generator's clock assumes is refused (the walk would run slower
        or faster than the robot)."""
        dev = self._device
        if dev is None:
            return
        try:
            dt = float(dev.getTimeStep())
        except SotpyError:  # the device has not ticked yet
            return
        if abs(dt - self._dt) <= 1e-12:
            return
        if first and not self._dtSet:
            if dt > self._T + 1e-12:
                raise EntityError(
                    f"PatternGenerator({self.name}): the device ticks every {dt} s, longer "
                    f"than the sampling period {self._T} s"
                )
            self._dt = float(dt)
            return
        raise EntityError(
            f"PatternGenerator({self.name}): the device {dev.name} ticks every {dt} s but "
            f"the generator's clock assumes {self._dt} s (setTimeStep); the walk would run "
            f"{dt / self._dt:.3g} times too slow"
        )

    def _velocity(self, v: np.ndarray) -> np.ndarray:
        a = np.asarray(v, dtype=float)
        if a.shape != (3,) or not np.all(np.isfinite(a)):
            raise SignalTypeError(
                f"{self.velocitydes.name}: expected (vx, vy, omega), 3 finite numbers (m/s, "
                f"m/s, rad/s), got {a.tolist()}; the walk keeps its last command"
            )
        return a

    def _height(self, tau: float) -> tuple[float, float, float]:
        """The CoM's height reference and its two derivatives at ``tau``: from its height
        at initState to ``:comheight`` along a quintic over the first
        :data:`HEIGHT_TIME` s (the cart-table model holds a constant height: it is
        reached before the first step), then constant."""
        z0, z1 = float(self._initial["com"][2]), self._comHeight
        m, dm, ddm = quintic(tau / HEIGHT_TIME)
        d = z1 - z0
        return z0 + d * m, d * dm / HEIGHT_TIME, d * ddm / HEIGHT_TIME**2

    def _holdInitial(self) -> None:
        init = self._initial
        com = init["com"].copy()  # the CoM height moves to :comheight after the trigger
        feet = {
            s: (np.array([f.x, f.y, 0.0]), np.array([f.yaw]), np.zeros(4))
            for s, f in init["footprints"].items()
        }
        self._setOutputs(com, np.zeros(3), np.zeros(3), feet, 0.0, 0, False)
        for side in _SIDES:  # exactly the feet read
            self._out[f"{side}foot"] = init["ankles"][side]

    def _setOutputs(self, com, dcom, ddcom, feet, tau, phase, inprocess) -> None:
        """The outputs of a tick from the CoM's state and ``feet`` (side -> the sole frame's
        position, yaw and velocity: the walk's ``feet``)."""
        out = self._out
        yaws = []
        for side in _SIDES:
            p, yaw, nu = feet[side]
            weight, rate = self._startWeight(side, tau)
            yaws.append(float(yaw[0]))
            if not nu.any() and not rate:
                # a foot at rest: the same outputs as the last tick's if it has not moved
                key = (p[0], p[1], p[2], yaws[-1], weight)
                cached = self._restCache.get(side)
                if cached is not None and cached[0] == key:
                    out[f"{side}foot"], out[f"{side}vel"], out[f"{side}w"], out[f"{side}va"] = (
                        cached[1]
                    )
                    continue
            else:
                key = None
            oMa, local, w, va = self._ankle(side, p, yaw[0], nu, weight, rate)
            out[f"{side}foot"] = oMa
            out[f"{side}vel"] = local
            out[f"{side}w"] = w
            out[f"{side}va"] = va
            if key is not None:
                self._restCache[side] = (key, (oMa, local, w, va))
        yaw = math.atan2(
            math.sin(yaws[0]) + math.sin(yaws[1]), math.cos(yaws[0]) + math.cos(yaws[1])
        )
        out["com"], out["dcom"], out["ddcom"] = com, dcom, ddcom
        out["yaw"] = yaw
        out["phase"] = phase
        out["inprocess"] = inprocess
        if self._walk is not None and self._t0 is not None:
            out["zmp"] = np.append(self._walk.zmp(tau), 0.0)
        else:
            out["zmp"] = np.array([com[0], com[1], 0.0])
        if phase == 1:
            out["support"] = 1
        elif phase == -1:
            out["support"] = 0
        else:
            out.setdefault("support", 1)

    def _ankle(
        self, side: str, p: np.ndarray, yaw: float, nu: np.ndarray, weight: float, rate: float
    ) -> tuple[pin.SE3, np.ndarray, np.ndarray, np.ndarray]:
        """The ankle's reference placement, its velocity in itself (6), its angular and
        linear world velocities, from the sole frame's position ``p``, ``yaw`` and
        velocity ``nu = (dp/dt, dyaw/dt)``, and the start blend ``weight`` and its
        ``rate`` (:meth:`_startWeight`)."""
        # the ankle at oMs * sMa, oMs = (Rz(yaw), p); its velocity from the sole's
        # (dp/dt, yaw rate wz): v_a = dp/dt + wz e_z x (p_a - p), w = wz e_z
        Rz = _rotz(float(yaw))
        sMa = self._geometry.soleToAnkle[side]
        r = Rz @ sMa.translation
        R = Rz @ sMa.rotation
        oMa = pin.SE3(R, p + r)
        wz = nu[3]
        w = np.array([0.0, 0.0, wz])
        va = np.array([nu[0] - wz * r[1], nu[1] + wz * r[0], nu[2]])
        local = np.concatenate((R.T @ va, R[2] * wz))
        if weight:
            # the foot as it stood at initState (a sole tilted by the ankle, a few
            # tenths of a mm off the ground), blended into the flat plan over its
            # first swing (module doc)
            xi = self._initial["offsets"][side]
            oMa = oMa * pin.exp6(weight * xi)
            local = local + rate * xi
        return oMa, local, w, va

    def referencesAt(
        self, walk: Any, tau: float
    ) -> tuple[np.ndarray, dict[str, pin.SE3], np.ndarray]:
        """The references of ``walk`` at ``tau`` without the outputs: the CoM (3), the
        ankles (side -> SE3) and the waist's rotation (3 x 3); what the dynamic filter's
        inverse kinematics follows."""
        x = walk.state(tau)
        feet = walk.feet(tau)
        ankles, yaws = {}, []
        for side in _SIDES:
            p, yaw, nu = feet[side]
            weight, rate = self._startWeight(side, tau, walk)
            ankles[side] = self._ankle(side, p, yaw[0], nu, weight, rate)[0]
            yaws.append(float(yaw[0]))
        yaw = math.atan2(
            math.sin(yaws[0]) + math.sin(yaws[1]), math.cos(yaws[0]) + math.cos(yaws[1])
        )
        com = np.array([x[0, 0], x[0, 1], self._height(tau)[0]])
        return com, ankles, _rotz(yaw) @ self._initial["waist"]

    def _startWeight(self, side: str, tau: float, walk: Any = None) -> tuple[float, float]:
        """How much of the initial pose's offset from the flat footprint the ``side``
        foot still carries at ``tau``: 1 until its first swing, then ``1 - m(s)`` (the
        swing's own quintic, so C2) and 0 after; with its rate (1/s)."""
        if not self._initial["offsets"][side].any():
            return 0.0, 0.0
        if walk is None:
            walk = None if self._t0 is None else self._walk
        first = None if walk is None else walk.firstSwing(side)
        if first is None or tau < first[0]:
            return 1.0, 0.0
        if tau >= first[1]:
            return 0.0, 0.0
        T = first[1] - first[0]
        m, dm, _ = quintic((tau - first[0]) / T)
        return 1.0 - m, -dm / T

    @Output(INT, deps=("trigger", "velocitydes"), withTime=True, timeDependent=True)
    def onestepofcontrol(self, t: int, trigger: bool, velocity: np.ndarray) -> int:
        """The generator's step at tick t (internal: every output depends on it)."""
        if self._initial is None:
            raise EntityError(f"PatternGenerator({self.name}): read before initState()")
        if not trigger:
            if self._t0 is not None:
                self._t0 += t - self._tick  # frozen: the walk's clock stops
                self._tick = t
            return t
        self._checkPeriod(first=self._t0 is None)
        if self._t0 is None:
            self._start(t)
        self._tick = t
        tau = (t - self._t0) * self._dt
        walk = self._walk
        if isinstance(walk, VelocityWalk):
            walk.advance(tau, self._velocity(velocity))
        x = walk.state(tau)
        z, dz, ddz = self._height(tau)
        com = np.array([x[0, 0], x[0, 1], z])
        dcom = np.array([x[1, 0], x[1, 1], dz])
        ddcom = np.array([x[2, 0], x[2, 1], ddz])
        self._setOutputs(
            com,
            dcom,
            ddcom,
            walk.feet(tau),
            tau,
            walk.contactPhase(tau),
            not walk.finished(tau),
        )
        return t

    # the outputs, each a read of the step's results
    def _o(key: str, kind: Any, doc: str) -> Output:  # noqa: N805 - a class-body helper
        def read(self: PatternGenerator, _step: int) -> Any:
            return self._out[key]

        read.__doc__ = doc
        return Output(kind, deps=("onestepofcontrol",), doc=doc)(read)

    comref = _o("com", VECTOR, "CoM reference (m, world; z the CoM height)")
    dcomref = _o("dcom", VECTOR, "CoM velocity reference (m/s)")
    ddcomref = _o("ddcom", VECTOR, "CoM acceleration reference (m/s^2)")
    zmpref = _o("zmp", VECTOR, "ZMP reference (x, y, 0) (m, world)")
    leftfootref = _o("leftfoot", SE3, "left ankle's reference placement (world)")
    rightfootref = _o("rightfoot", SE3, "right ankle's reference placement (world)")
    leftfootvelocity = _o(
        "leftvel",
        VECTOR,
        "left ankle's reference velocity in itself (m/s, rad/s), for FeaturePose.referenceVelocity",
    )
    rightfootvelocity = _o(
        "rightvel",
        VECTOR,
        "right ankle's reference velocity in itself (m/s, rad/s), for "
        "FeaturePose.referenceVelocity",
    )
    contactphase = _o("phase", INT, "1: left foot alone, -1: right alone, 0: both")
    SupportFoot = _o(
        "support", INT, "1: left, 0: right (in double support: the last single support's)"
    )
    inprocess = _o("inprocess", BOOL, "true while the walk's references move")

    def _dot(self, side: str) -> np.ndarray:
        out = self._out
        dH = np.zeros((4, 4))
        dH[:3, :3] = pin.skew(out[f"{side}w"]) @ out[f"{side}foot"].rotation
        dH[:3, 3] = out[f"{side}va"]
        return dH

    @Output(MATRIX, deps=("onestepofcontrol",))
    def dotleftfootref(self, _step: int) -> np.ndarray:
        """Time derivative of leftfootref's 4 x 4 matrix (1/s, m/s)."""
        return self._dot("left")

    @Output(MATRIX, deps=("onestepofcontrol",))
    def dotrightfootref(self, _step: int) -> np.ndarray:
        """Time derivative of rightfootref's 4 x 4 matrix (1/s, m/s)."""
        return self._dot("right")

    @Output(BOOL, deps=("onestepofcontrol",))
    def leftfootcontact(self, _step: int) -> bool:
        """Whether the left foot is on the ground."""
        return self._out["phase"] != -1

    @Output(BOOL, deps=("onestepofcontrol",))
    def rightfootcontact(self, _step: int) -> bool:
        """Whether the right foot is on the ground."""
        return self._out["phase"] != 1

    def _rpy(self) -> np.ndarray:
        return np.array([0.0, 0.0, self._out["yaw"]])

    @Output(VECTOR, deps=("onestepofcontrol",))
    def waistattitude(self, _step: int) -> np.ndarray:
        """Waist roll, pitch, yaw (rad): level, the feet's mean yaw."""
        return self._rpy()

    @Output(VECTOR, deps=("onestepofcontrol",))
    def waistattitudeabsolute(self, _step: int) -> np.ndarray:
        """Waist roll, pitch, yaw (rad, world): level, the feet's mean yaw."""
        return self._rpy()

    @Output(VECTOR, deps=("onestepofcontrol",))
    def comattitude(self, _step: int) -> np.ndarray:
        """CoM attitude roll, pitch, yaw (rad): the waist's."""
        return self._rpy()

    @Output(SE3, deps=("onestepofcontrol",))
    def waistattitudematrixabsolute(self, _step: int) -> pin.SE3:
        """Waist reference placement: the waist's orientation at initState (read from
        ``position``'s free flyer, if plugged; else level) turned by the feet's mean yaw;
        translation the CoM reference's (the rotation is what a waist orientation task
        reads)."""
        R = _rotz(self._out["yaw"]) @ self._initial["waist"]
        return pin.SE3(R, self._out["com"].copy())

    @Output(VECTOR, deps=("onestepofcontrol",))
    def initzmpref(self, _step: int) -> np.ndarray:
        """The ZMP at initState: the mid-point of the soles' centres (m)."""
        fp = self._initial["footprints"]
        off = np.asarray(self._geometry.sole.offset)
        mid = (fp["left"].point(off) + fp["right"].point(off)) / 2
        return np.array([mid[0], mid[1], 0.0])

    @Output(VECTOR, deps=("onestepofcontrol",))
    def initcomref(self, _step: int) -> np.ndarray:
        """The CoM at initState (m)."""
        return self._initial["com"].copy()

    @Output(SE3, deps=("onestepofcontrol",))
    def initleftfootref(self, _step: int) -> pin.SE3:
        """The left ankle at initState."""
        return self._initial["ankles"]["left"]

    @Output(SE3, deps=("onestepofcontrol",))
    def initrightfootref(self, _step: int) -> pin.SE3:
        """The right ankle at initState."""
        return self._initial["ankles"]["right"]

    del _o

    # -- what the checks and demos read ----------------------------------------------
    @property
    def plan(self) -> StepPlan | None:
        """The footstep walk's :class:`~sotpy.walking.plan.StepPlan` (None before steps
        are given); for a velocity walk, a plan of the footprints stepped on so far."""
        w = self._walk
        if isinstance(w, VelocityWalk):
            return w.plan(dict(self._initial["footprints"]), self._now())
        return None if w is None else w.plan

    @property
    def initialConfiguration(self) -> np.ndarray:
        """The robot's q at initState (``position``; half-sitting when not plugged)."""
        if self._initial is None:
            raise EntityError(f"PatternGenerator({self.name}): initState() was not called")
        return self._initial["q"].copy()

    @property
    def walk(self) -> FootstepWalk | VelocityWalk | None:
        """The walk being run (:mod:`sotpy.walking.walks`), None before it is planned."""
        return self._walk

    @property
    def steppedFootprints(self) -> list[Footprint]:
        """The two initial footprints, then every one stepped on (or planned), in order."""
        fp = self.initialFootprints
        steps = [] if self._walk is None else self._walk.steps()
        return [fp["left"], fp["right"], *steps]

    @property
    def initialFootprints(self) -> dict[str, Footprint]:
        """The feet's footprints read by initState (side -> Footprint)."""
        if self._initial is None:
            raise EntityError(f"PatternGenerator({self.name}): initState() was not called")
        return dict(self._initial["footprints"])

    @property
    def geometry(self) -> RobotGeometry | None:
        """The :class:`RobotGeometry` of ``buildModel``."""
        return self._geometry

    @property
    def walkTime(self) -> float:
        """The walk's clock (s): 0 before the trigger."""
        return self._now()

    @property
    def comHeight(self) -> float | None:
        """The cart-table's CoM height (m)."""
        return self._comHeight

    @property
    def gravity(self) -> float:
        """Gravity of the cart-table model (m/s^2)."""
        return GRAVITY


def _flag(name: str) -> Callable[[PatternGenerator, str, list[str]], None]:
    """A parseCmd flag sotpy has only as false: true is refused, naming ``name``."""

    def handler(pg: PatternGenerator, who: str, args: list[str]) -> None:
        if len(args) != 1 or args[0] not in ("true", "false"):
            raise CommandError(f"{who}: expected 'true' or 'false', got {args}")
        if args[0] == "true":
            raise CommandError(f"{who}: {name} is not in sotpy's generator yet")

    return handler


_PARSERS: dict[str, Callable[[PatternGenerator, str, list[str]], None]] = {
    ":samplingperiod": PatternGenerator._cmdSampling,
    ":previewcontroltime": PatternGenerator._cmdPreview,
    ":comheight": PatternGenerator._cmdComHeight,
    ":stepheight": PatternGenerator._cmdStepHeight,
    ":singlesupporttime": PatternGenerator._cmdSS,
    ":doublesupporttime": PatternGenerator._cmdDS,
    ":omega": PatternGenerator._cmdOmega,
    ":walkmode": PatternGenerator._cmdWalkMode,
    ":SetAlgoForZmpTrajectory": PatternGenerator._cmdAlgo,
    ":stepseq": PatternGenerator._cmdStepSeq,
    ":HerdtOnline": PatternGenerator._cmdOnline,
    ":NaveauOnline": PatternGenerator._cmdOnline,
    ":setVelReference": PatternGenerator._cmdVelReference,
    ":setfeetconstraint": PatternGenerator._cmdFeetConstraint,
    ":useDynamicFilter": PatternGenerator._cmdDynamicFilter,
    ":feedBackControl": _flag("jrl-walkgen's state feedback (:feedBackControl)"),
}
