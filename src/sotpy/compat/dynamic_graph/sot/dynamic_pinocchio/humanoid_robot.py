"""sot-dynamic-pinocchio's ``humanoid_robot``: the robot classes SoT's robot packages
derive from, served by sotpy.

``AbstractRobot`` / ``AbstractHumanoidRobot`` keep SoT's protocol: a subclass loads its
model (``loadModelFromUrdf``, ``loadModelFromString``), creates ``self.dynamic =
DynamicPinocchio(name + "_dynamic")`` with ``setModel``, defines ``defineHalfSitting(q)``
and calls ``initializeRobot()`` and ``initializeOpPoints()``. Over sotpy:

- ``initializeRobot`` builds a simulated :class:`~sotpy.dynamics.Device`
  ``name + "_device"`` (unless ``self.device`` is one), sets it to ``halfSitting`` and
  plugs ``device.state -> dynamic.position`` and ``device.velocity -> dynamic.velocity``
  (the state's exact derivative: a ``Derivator_of_Vector`` of the quaternion state has nq
  entries and would not fit, so ``enableVelocityDerivator`` needs none); with
  ``enableAccelerationDerivator`` a ``Derivator_of_Vector('accelerationDerivator')`` of
  ``device.velocity`` feeds ``dynamic.acceleration``;
- ``halfSitting`` is a Pinocchio configuration (size nq, the free flyer's quaternion);
  SoT's converted it to roll-pitch-yaw (size nv); ``device.set`` takes both;
- ``timeStep`` is :data:`DEFAULT_TIME_STEP` until the device increments (SoT's
  RobotSimu left it uninitialised);
- ``HumanoidRobot(name, pinocchioModel, pinocchioData, initialConfig,
  OperationalPointsMap)``, the class of older scripts, is built the same way.

Everything else is :class:`sotpy.dynamics.robot.HumanoidRobotAPI`'s (``addTrace``,
``initializeTracer``, ``startTracer``, ``stopTracer``, ``reset``,
``setJointValueInConfig``, ``createFrame``...).
"""

from __future__ import annotations

import os
import xml.etree.ElementTree as ET
from abc import ABC, abstractmethod
from pathlib import Path
from typing import Any

import numpy as np
import pinocchio as pin

from .....dynamics import Device, Dynamic
from .....dynamics.device import configurationFromRollPitchYaw
from .....dynamics.robot import HumanoidRobotAPI, load_robot
from .....errors import RobotError
from .....graph import plug
from ...._errors import unsupported
from . import DynamicPinocchio

__all__ = [
    "DEFAULT_TIME_STEP",
    "AbstractHumanoidRobot",
    "AbstractRobot",
    "HumanoidRobot",
]

#: The robots' time step until their device increments, s (200 Hz, HRP-2's and the SoT
#: examples' period).
DEFAULT_TIME_STEP = 0.005


class AbstractRobot(HumanoidRobotAPI, ABC):
    """SoT's ``AbstractRobot`` over sotpy's entities (see the module doc)."""

    #: the op points to create on ``dynamic`` (a list subclasses extend)
    OperationalPoints: list[str] = []  # type: ignore[assignment]

    def __init__(self, name: str, tracer: Any = None) -> None:
        self._initialize()
        self.name = name
        if tracer:
            self.tracer = tracer

    def _initialize(self) -> None:
        self.OperationalPoints = []
        self.AdditionalFrames: list[Any] = []
        self.frames: dict[str, Any] = {}
        self.enableVelocityDerivator = False
        self.enableAccelerationDerivator = False
        self.enableZmpComputation = False
        self.tracer = None
        self.autoRecomputedSignals: list[str] = []
        if "opPoints" not in self.__dict__:
            self.opPoints = {}

    def help(self) -> None:
        """Print the class documentation."""
        print(type(self).__doc__)

    # -- the model -----------------------------------------------------------------------
    @property  # type: ignore[override]
    def pinocchioModel(self) -> Any:
        """The Pinocchio model (set by ``loadModelFromUrdf`` / ``loadModelFromString``)."""
        model = self.__dict__.get("model")
        if model is None:
            raise RobotError(
                f"{type(self).__name__}: no model yet: call loadModelFromUrdf(path) or "
                "loadModelFromString(urdf) first"
            )
        return model

    @pinocchioModel.setter
    def pinocchioModel(self, model: Any) -> None:
        self.model = model

    @property  # type: ignore[override]
    def pinocchioData(self) -> Any:
        """The model's data (the ``Dynamic``'s once it exists)."""
        dyn = self.__dict__.get("dynamic")
        if dyn is not None and getattr(dyn, "_entity", True) is not None:
            return dyn.data
        return self.__dict__.get("_data")

    @pinocchioData.setter
    def pinocchioData(self, data: Any) -> None:
        self._data = data

    def _storeRootJointType(self, rootJointType: Any) -> None:
        if rootJointType is pin.JointModelFreeFlyer:
            self.rootJointType = "freeflyer"
        elif rootJointType is pin.JointModelPlanar:
            self.rootJointType = "planar"
        elif rootJointType is None:
            self.rootJointType = "fixed"
        else:
            raise TypeError(
                "rootJointType should be pinocchio.JointModelFreeFlyer, "
                "pinocchio.JointModelPlanar or None"
            )

    def loadModelFromString(
        self,
        urdfString: str,
        rootJointType: Any = pin.JointModelFreeFlyer,
        removeMimicJoints: bool = True,
    ) -> None:
        """Load the model from a URDF string (root joint ``rootJointType()``, or none)."""
        if rootJointType is None:
            self.pinocchioModel = pin.buildModelFromXML(urdfString)
        else:
            self.pinocchioModel = pin.buildModelFromXML(urdfString, rootJointType())
        self.pinocchioData = self.model.createData()
        if removeMimicJoints:
            self.removeJoints(_mimicJoints(ET.fromstring(urdfString)))
        self._storeRootJointType(rootJointType)

    def loadModelFromUrdf(
        self,
        urdfPath: str,
        urdfDir: Any = None,
        rootJointType: Any = pin.JointModelFreeFlyer,
        removeMimicJoints: bool = True,
    ) -> None:
        """Load the model from a URDF file; a ``package://<pkg>/<path>`` path is looked
        up in example-robot-data's robots (ROS's package path is not searched)."""
        path = _resolvePackage(urdfPath)
        if rootJointType is None:
            self.pinocchioModel = pin.buildModelFromUrdf(path)
        else:
            self.pinocchioModel = pin.buildModelFromUrdf(path, rootJointType())
        self.pinocchioData = self.model.createData()
        if removeMimicJoints:
            self.removeJoints(_mimicJoints(ET.parse(path).getroot()))
        self._storeRootJointType(rootJointType)

    def removeJoints(self, joints: list[str]) -> None:
        """Lock the joints ``joints`` (names) of the model at their neutral value."""
        model = self.pinocchioModel
        ids = [model.getJointId(j) for j in joints if model.existJointName(j)]
        if ids:
            self.pinocchioModel = pin.buildReducedModel(model, ids, pin.neutral(model))
            self.pinocchioData = self.model.createData()

    @abstractmethod
    def defineHalfSitting(self, q: np.ndarray) -> None:
        """Write the half-sitting posture into ``q`` (a Pinocchio configuration, in
        place); ``setJointValueInConfig`` helps."""

    # -- the entities --------------------------------------------------------------------
    def initializeRobot(self) -> None:
        """Build and wire the device over ``self.dynamic`` (see the module doc)."""
        if "dynamic" not in self.__dict__:
            raise RuntimeError("Dynamic robot model must be initialized first")
        dyn = self.dynamic
        if isinstance(dyn, DynamicPinocchio):
            dyn = dyn._sotpyDynamic()
        if not isinstance(dyn, Dynamic):
            raise RobotError(f"{type(self).__name__}: self.dynamic is not a Dynamic: {dyn!r}")
        self.dynamic = dyn
        self.model = dyn.model
        device = self.__dict__.get("device")
        if device is None:
            device = Device(self.name + "_device", dyn.model)
        elif not isinstance(device, Device):
            raise unsupported(
                f"the device {device!r} (a real robot's)",
                "sotpy's simulated Device, built by initializeRobot",
            )
        self.device = device
        try:
            device.getTimeStep()
        except Exception:
            device.setTimeStep(DEFAULT_TIME_STEP)
        q = pin.neutral(dyn.model)
        self.defineHalfSitting(q)
        self.halfSitting = q
        device.set(q.copy())
        plug(device.state, dyn.position)
        plug(device.velocity, dyn.velocity)
        if self.enableAccelerationDerivator:
            from .....operators import Derivator_of_Vector

            self.accelerationDerivator = Derivator_of_Vector("accelerationDerivator")
            self.accelerationDerivator.dt.value = self.timeStep
            plug(device.velocity, self.accelerationDerivator.sin)
            plug(self.accelerationDerivator.sout, dyn.acceleration)

    def initializeOpPoints(self) -> None:
        """Create the op points of ``OperationalPoints`` on ``dynamic``, on the frames
        of ``OperationalPointsMap``."""
        for op in self.OperationalPoints:
            if not self.dynamic.hasSignal(op):
                self.dynamic.createOpPoint(op, self.OperationalPointsMap[op])


class AbstractHumanoidRobot(AbstractRobot):
    """SoT's ``AbstractHumanoidRobot``: an ``AbstractRobot`` whose op points are the
    wrists, the ankles and the gaze."""

    def _initialize(self) -> None:
        super()._initialize()
        self.OperationalPoints.extend(
            ["left-wrist", "right-wrist", "left-ankle", "right-ankle", "gaze"]
        )


class HumanoidRobot(AbstractHumanoidRobot):
    """The ``HumanoidRobot(name, pinocchioModel, pinocchioData, initialConfig,
    OperationalPointsMap)`` of older SoT scripts: the robot over that model, set to
    ``initialConfig`` (SoT's roll-pitch-yaw configuration of size nv, or size nq)."""

    def __init__(
        self,
        name: str,
        pinocchioModel: Any,
        pinocchioData: Any = None,
        initialConfig: Any = None,
        OperationalPointsMap: dict[str, str] | None = None,
        tracer: Any = None,
    ) -> None:
        super().__init__(name, tracer)
        self.pinocchioModel = pinocchioModel
        self._initial = (
            pin.neutral(pinocchioModel)
            if initialConfig is None
            else configurationFromRollPitchYaw(pinocchioModel, initialConfig)
        )
        if OperationalPointsMap is not None:
            self.OperationalPointsMap = OperationalPointsMap
        self.OperationalPoints = [op for op in self.OperationalPoints if op in self.opPoints]
        self.OperationalPoints += [op for op in self.opPoints if op not in self.OperationalPoints]
        self.dynamic = Dynamic(name + "_dynamic", pinocchioModel)
        self.initializeRobot()
        self.initializeOpPoints()

    def defineHalfSitting(self, q: np.ndarray) -> None:
        q[:] = self._initial


def fromDescription(robot: Any, description: str, name: str, device: Any) -> None:
    """Fill ``robot`` (an ``AbstractRobot``) from sotpy's robot ``description``
    (:func:`~sotpy.dynamics.load_robot` with the prefix ``name``): its model,
    ``Dynamic`` ``name_dynamic`` with every op point, ``Device`` ``name_device`` at
    half-sitting. ``robot.sotpyRobot`` is the :class:`~sotpy.dynamics.Robot`."""
    if device is not None:
        raise unsupported(
            f"a robot built on the device {device!r} (a real robot's)",
            "the simulated Device load_robot builds (robot.device)",
        )
    r = load_robot(description, prefix=name)
    robot.sotpyRobot = r
    robot.model = r.model
    robot.pinocchioData = r.dynamic.data
    robot.dynamic = r.dynamic
    robot.device = r.device
    robot.OperationalPointsMap = dict(r.opPoints)
    robot.OperationalPoints = list(r.opPoints)
    robot.halfSitting = r.halfSitting.copy()
    robot.dimension = r.model.nv
    robot.rootJointType = "freeflyer" if r.device.hasFreeFlyer else "fixed"
    r.device.setTimeStep(DEFAULT_TIME_STEP)


def _mimicJoints(root: ET.Element) -> list[str]:
    """The names of the joints of a URDF tree that have a ``<mimic>`` element."""
    return [j.get("name", "") for j in root.iter("joint") if j.find("mimic") is not None]


def _resolvePackage(path: str) -> str:
    """``package://pkg/rel`` -> example-robot-data's ``robots/pkg/rel``; other paths as
    they are."""
    if not path.startswith("package://"):
        return os.fspath(path)
    rel = path[len("package://") :]
    try:
        import example_robot_data

        root = Path(example_robot_data.getModelPath(rel)) / rel
    except Exception:
        root = None
    if root is None or not root.is_file():
        raise unsupported(
            f"the URDF {path!r} (a ROS package path)",
            "a file path, example-robot-data's robots (package://talos_data/robots/...), "
            "or load_robot(name) for the robots sotpy ships",
        )
    return str(root)
