"""Robots: declarative descriptions loaded over Pinocchio, with a Dynamic and a Device.

Each robot is one TOML file in ``sotpy/robots/`` (shipped with the package; the format is
documented in ``docs/robots.md``)::

    name = "nao"
    description = "..."
    [model]            source = "urdf", file = "nao.urdf" | source = "example-robot-data",
                       loader = "talos"; floating_base = true
    halfSitting = "reference"            # the SRDF reference posture (robot.q0), or
    [halfSitting]      base = [x, y, z, qx, qy, qz, qw]   (floating base only)
    [halfSitting.joints]  JointName = angle (rad) or position (m)
    [opPoints]         SoT name (left-ankle, ..., end-effector) = Pinocchio frame name
    [feet.left]        frame = "l_sole", length = 0.16, width = 0.088, offset = [x, y]
    [couplings]        RHipYawPitch = "LHipYawPitch"
                       or {joint = "LHand", multiplier = -1.0, offset = 0.0}

:func:`load_robot` builds the SoT robot of ``humanoid_robot.py`` over it: the Pinocchio
model, a ``Dynamic`` with every operational point created, a ``Device`` set to
half-sitting whose ``state`` and ``velocity`` drive the ``Dynamic``'s ``position`` and
``velocity``.

Conventions are those of :mod:`sotpy.dynamics`: configurations are Pinocchio's (free
flyer: position in m, then the quaternion ``(qx, qy, qz, qw)``), lengths in m, angles in
rad. A coupling ``joint = master`` means ``q[joint] = multiplier * q[master] + offset``;
the model keeps both joints (``nv`` counts them) and the number of *actuated* degrees of
freedom is the number of joints minus the number of couplings. URDF ``<mimic>`` tags
between joints of the model count as couplings too (declared ones take precedence).
"""

from __future__ import annotations

import contextlib
import difflib
import math
import os
import sys
import tempfile
import xml.etree.ElementTree as ET
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import pinocchio as pin

from ..errors import RobotDescriptionError, RobotError, RobotNotFoundError

if TYPE_CHECKING:  # for the annotation only: no import of the tasks layer at run time
    from ..tasks.ready import ReadyTasks

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover - exercised on Python 3.10 only
    import tomli as tomllib

__all__ = [
    "ROBOTS_DIR",
    "Coupling",
    "Foot",
    "HumanoidRobotAPI",
    "Robot",
    "RobotDescriptionError",
    "RobotError",
    "RobotNotFoundError",
    "convex_hull_2d",
    "list_robots",
    "load_model",
    "load_robot",
    "robot_info",
    "robot_summary",
]

#: Folder of the shipped robot descriptions (``*.toml``) and URDF files.
ROBOTS_DIR: Path = Path(__file__).resolve().parent.parent / "robots"

_SOURCES = ("example-robot-data", "urdf")
_TOP_KEYS = {"name", "description", "model", "halfSitting", "opPoints", "feet", "couplings"}
_MODEL_KEYS = {"source", "loader", "file", "floating_base"}
_FOOT_KEYS = {"frame", "length", "width", "offset"}
_LIMIT_TOL = 1e-9  # rad or m: slack when checking a posture against joint limits


# -- data classes -----------------------------------------------------------------------
@dataclass(frozen=True)
class Coupling:
    """``q[joint] = multiplier * q[master] + offset`` (both 1-DoF joints of the model)."""

    joint: str
    master: str
    multiplier: float = 1.0
    offset: float = 0.0


@dataclass(frozen=True)
class Foot:
    """A rectangular sole attached to a frame of the model.

    The rectangle lies in the frame's xy plane (the frame's z axis is the sole normal),
    ``length`` (m) along x and ``width`` (m) along y, centred at ``offset`` (m, in the
    frame).
    """

    side: str
    frame: str
    length: float
    width: float
    offset: tuple[float, float, float] = (0.0, 0.0, 0.0)

    @property
    def corners(self) -> np.ndarray:
        """The 4 corners in the sole frame, a (4, 3) array (m), counter-clockwise seen
        from above: front-left, back-left, back-right, front-right."""
        a, b = self.length / 2, self.width / 2
        c = np.array([[a, b, 0.0], [-a, b, 0.0], [-a, -b, 0.0], [a, -b, 0.0]])
        return c + np.asarray(self.offset, dtype=float)


def convex_hull_2d(points: np.ndarray) -> np.ndarray:
    """Convex hull of planar points (Andrew's monotone chain).

    Args:
        points: (n, 2) array.

    Returns:
        The hull's vertices, a (k, 2) array, counter-clockwise, starting from the
        lowest-x (then lowest-y) point; collinear points are dropped.
    """
    pts = np.unique(np.asarray(points, dtype=float).reshape(-1, 2), axis=0)
    if len(pts) <= 2:
        return pts

    def cross(o: np.ndarray, a: np.ndarray, b: np.ndarray) -> float:
        return float((a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0]))

    lower: list[np.ndarray] = []
    for p in pts:
        while len(lower) >= 2 and cross(lower[-2], lower[-1], p) <= 0:
            lower.pop()
        lower.append(p)
    upper: list[np.ndarray] = []
    for p in pts[::-1]:
        while len(upper) >= 2 and cross(upper[-2], upper[-1], p) <= 0:
            upper.pop()
        upper.append(p)
    return np.array(lower[:-1] + upper[:-1])


class HumanoidRobotAPI:
    """The attributes and methods of SoT's humanoid robot class (sot-dynamic-pinocchio's
    ``AbstractRobot``) over sotpy's robot: shared by :class:`Robot` and the robot
    classes of the compatibility layer (``sotpy run``).

    Needs ``name``, ``model``, ``dynamic``, ``device``, ``opPoints`` and
    ``halfSitting``. Provides:

    - ``timeStep`` (s): the device's time step (``device.getTimeStep()``; assigning it
      calls ``device.setTimeStep``); ``dimension``: nv; ``OperationalPointsMap``: the
      op points (SoT name -> Pinocchio frame), ``OperationalPoints``: their names;
      ``pinocchioModel``, ``pinocchioData``: the model and the ``Dynamic``'s data;
    - the tracer of SoT's robot: ``initializeTracer()`` (a ``Tracer`` ``"trace"`` whose
      files are ``/tmp/dg_<entity>-<signal>.dat``, triggered by ``device.after``),
      ``addTrace(entityName, signalName)``, ``traceDefaultSignals()``,
      ``startTracer()``, ``stopTracer()`` (dump, stop, close, clear; the tracer is
      then forgotten); ``tracerSize`` is in rows (SoT's was bytes per signal);
    - ``reset(posture)``, ``getActuatedJoints()``, ``setJointValueInConfig(q, names,
      values)``, ``createFrame(name, aMb, opPoint)`` (an ``OpPointModifier``),
      ``initializeRobot()`` (the device back to half-sitting, at rest).
    """

    tracer: Any = None
    tracerSize: int = 10_000
    #: dynamic's signals, then the device's, that traceDefaultSignals traces (SoT's)
    tracedSignals: dict[str, list[str]] = {
        "dynamic": ["com", "zmp", "angularmomentum", "position", "velocity", "acceleration"],
        "device": ["zmp", "control", "state"],
    }

    name: str
    model: Any
    dynamic: Any
    device: Any
    opPoints: dict[str, str]
    halfSitting: np.ndarray

    # -- SoT's attributes ----------------------------------------------------------------
    @property
    def timeStep(self) -> float:
        """The device's time step, s (``device.getTimeStep()``)."""
        return float(self.device.getTimeStep())

    @timeStep.setter
    def timeStep(self, dt: float) -> None:
        self.device.setTimeStep(dt)

    @property
    def dimension(self) -> int:
        """nv: the size of the velocity, of the control and of the Jacobians' rows."""
        return int(self.model.nv)

    @dimension.setter
    def dimension(self, n: int) -> None:
        if n != self.model.nv:
            raise RobotError(
                f"robot {self.name!r}: its dimension is nv = {self.model.nv} (the model's), got {n}"
            )

    @property
    def OperationalPointsMap(self) -> dict[str, str]:
        """SoT name -> Pinocchio frame of each op point (the dict itself)."""
        return self.opPoints

    @OperationalPointsMap.setter
    def OperationalPointsMap(self, mapping: dict[str, str]) -> None:
        self.opPoints = dict(mapping)

    @property
    def OperationalPoints(self) -> tuple[str, ...]:
        """The op points' names (created on ``dynamic``)."""
        return tuple(self.opPoints)

    @property
    def pinocchioModel(self) -> Any:
        """The Pinocchio model (SoT's name)."""
        return self.model

    @property
    def pinocchioData(self) -> Any:
        """The ``Dynamic``'s Pinocchio data."""
        return self.dynamic.data

    # -- SoT's methods -------------------------------------------------------------------
    def initializeRobot(self) -> None:
        """Put the device back at half-sitting, at rest (SoT's ``initializeRobot`` also
        built the device and the dynamic, which :func:`load_robot` did)."""
        self.device.set(np.asarray(self.halfSitting, dtype=float).copy())
        self.device.setVelocity(np.zeros(self.model.nv))

    def createSimulator(self) -> Any:
        """The simulated device (built with the robot): ``self.device``."""
        return self.device

    def initializeTracer(
        self, dirname: str = "/tmp/", prefix: str = "dg_", suffix: str = ".dat"
    ) -> Any:
        """Create the robot's tracer if it has none: a ``Tracer("trace")`` of
        ``tracerSize`` rows, whose files are ``dirname/prefix<name>suffix``, triggered
        after each ``device.increment`` (``device.after``). Returns it."""
        from ..graph import Tracer

        if self.tracer is None:
            tr = Tracer("trace")
            tr.setBufferSize(self.tracerSize)
            tr.open(dirname, prefix, suffix)
            self.device.after.addSignal(tr.triger)
            self.tracer = tr
            self.autoRecomputedSignals = []
        return self.tracer

    def addTrace(self, entityName: str, signalName: str) -> None:
        """Trace ``entityName.signalName`` in the robot's tracer (file
        ``<entity>-<signal>``, SoT's name) if it has one (SoT's rule: nothing without
        a tracer)."""
        if self.tracer is None:
            return
        path = f"{entityName}.{signalName}"
        self.tracer.add(path, f"{entityName}-{signalName}".replace("/", "_"))
        self.autoRecomputedSignals.append(path)

    def traceDefaultSignals(self) -> None:
        """Trace the op points, the dynamic's ``tracedSignals["dynamic"]`` and the
        device's ``tracedSignals["device"]`` (SoT's list)."""
        for s in [*self.opPoints, *self.tracedSignals["dynamic"]]:
            self.addTrace(self.dynamic.name, s)
        for s in self.tracedSignals["device"]:
            self.addTrace(self.device.name, s)

    def startTracer(self) -> None:
        """Start the robot's tracer (if it has one)."""
        if self.tracer is not None:
            self.tracer.start()

    def stopTracer(self) -> None:
        """Dump, stop, close and clear the robot's tracer, detach it from the device,
        and forget it (SoT's ``stopTracer``)."""
        tr = self.tracer
        if tr is None:
            return
        tr.dump()
        tr.stop()
        tr.close()
        tr.clear()
        self.device.after.rmSignal(tr.triger, missing_ok=True)
        self.autoRecomputedSignals = []
        self.tracer = None

    def reset(self, posture: Any = None) -> None:
        """Put the device at ``posture`` (default half-sitting), at rest."""
        q = self.halfSitting if posture is None else posture
        self.device.set(np.asarray(q, dtype=float))
        self.device.setVelocity(np.zeros(self.model.nv))

    def getActuatedJoints(self) -> range:
        """The velocity indices of the joints (after a free flyer's 6)."""
        model = self.model
        ff = model.njoints > 1 and model.joints[1].shortname() == "JointModelFreeFlyer"
        return range(6 if ff else 0, model.nv)

    def setJointValueInConfig(self, q: np.ndarray, jointNames: Any, jointValues: Any) -> None:
        """Write ``jointValues`` into ``q`` (in place) for the one-coordinate joints
        ``jointNames`` of the model."""
        model = self.model
        for jn, jv in zip(jointNames, jointValues, strict=True):
            if not model.existJointName(jn):
                raise RobotError(f"robot {self.name!r}: no joint named {jn!r} in its model")
            joint = model.joints[model.getJointId(jn)]
            if joint.nq != 1:
                raise RobotError(
                    f"robot {self.name!r}: joint {jn!r} has {joint.nq} coordinates; write "
                    "them into q directly"
                )
            q[joint.idx_q] = float(jv)

    def createFrame(self, frameName: str, transformation: Any, operationalPoint: str) -> Any:
        """An ``OpPointModifier`` called ``frameName``: the frame at ``transformation``
        (aMb: 4 x 4 matrix or ``pinocchio.SE3``, m) in the op point ``operationalPoint``."""
        from ..graph.signal import plug
        from ..operators.op_point import OpPointModifier

        frame = OpPointModifier(frameName)
        frame.setTransformation(transformation)
        plug(self.dynamic.signal(operationalPoint), frame.positionIN)
        plug(self.dynamic.signal(f"J{operationalPoint}"), frame.jacobianIN)
        return frame


@dataclass(eq=False)
class Robot(HumanoidRobotAPI):
    """A loaded robot: Pinocchio model, ``Dynamic``, ``Device`` and its description.

    Attributes:
        name: the robot's name (from its description).
        model, visual_model, collision_model: Pinocchio models, shared with every robot
            of the same description loaded in this process: treat them as read-only.
        dynamic: the ``Dynamic`` entity, every op point of :attr:`opPoints` created.
        device: the ``Device`` entity, set to :attr:`halfSitting`; ``device.state`` is
            plugged to ``dynamic.position`` and ``device.velocity`` to
            ``dynamic.velocity``.
        halfSitting: the half-sitting configuration (Pinocchio q, size nq).
        opPoints: SoT op-point name -> Pinocchio frame name.
        feet: ``"left"``/``"right"`` -> :class:`Foot` (empty for arms).
        couplings: coupled joint name -> :class:`Coupling`.
        description: the parsed description (see :func:`robot_info`).

    It also has the attributes and methods of SoT's humanoid robot class
    (:class:`HumanoidRobotAPI`: ``timeStep``, ``dimension``, ``OperationalPointsMap``,
    ``addTrace``, ``startTracer``...).
    """

    name: str
    model: Any
    visual_model: Any
    collision_model: Any
    dynamic: Any
    device: Any
    halfSitting: np.ndarray
    opPoints: dict[str, str]
    feet: dict[str, Foot]
    couplings: dict[str, Coupling] = field(default_factory=dict)
    description: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        self._data = self.model.createData()

    @property
    def tasks(self) -> ReadyTasks:
        """The robot's ready tasks: ``robot.tasks["left-ankle"]``, ``["right-wrist"]``,
        ``["gaze"]``, ``["com"]``, ``["posture"]``, ... (a
        :class:`sotpy.tasks.ready.ReadyTasks`: key -> meta-task, created on first access
        and cached; ``list(robot.tasks)`` gives the keys).

        The module is imported here, on first use, not at the top of this file: the
        tasks layer imports the dynamics layer, and the dynamics layer must not import
        the tasks layer at module level (the layers of :doc:`docs/architecture.md
        </architecture>`), so that loading a robot does not need (or create) any task.
        """
        ready = self.__dict__.get("_readyTasks")
        if ready is None:
            from ..tasks.ready import ReadyTasks

            ready = self.__dict__["_readyTasks"] = ReadyTasks(self)
        return ready

    @property
    def nActuated(self) -> int:
        """Actuated degrees of freedom: joints besides the root, minus couplings."""
        return _n_joints(self.model) - len(self.couplings)

    def _q(self, q: Any) -> np.ndarray:
        if q is None:
            q = self.device.state.value if self.device is not None else self.halfSitting
        q = np.asarray(q, dtype=float)
        if q.shape != (self.model.nq,):
            raise RobotError(
                f"robot {self.name!r}: expected a configuration of size nq = "
                f"{self.model.nq}, got shape {q.shape}"
            )
        return q

    def soleCorners(self, q: Any = None) -> dict[str, np.ndarray]:
        """World positions of each foot's 4 sole corners at ``q``.

        Args:
            q: configuration (Pinocchio, size nq); default: the device's current state.

        Returns:
            side -> (4, 3) array (m), ``oMf * corner`` for each corner of
            :attr:`Foot.corners`.
        """
        q = self._q(q)
        pin.framesForwardKinematics(self.model, self._data, q)
        out = {}
        for side, foot in self.feet.items():
            oMs = self._data.oMf[self.model.getFrameId(foot.frame)]
            out[side] = foot.corners @ oMs.rotation.T + oMs.translation
        return out

    def supportPolygon(self, q: Any = None) -> np.ndarray:
        """Support polygon of both feet: the convex hull of the 4 + 4 sole corners
        projected on the world's xy plane.

        Args:
            q: configuration (Pinocchio, size nq); default: the device's current state.

        Returns:
            (k, 2) array of vertices (m), counter-clockwise.

        Raises:
            RobotError: the robot has no feet (a fixed-base arm).
        """
        if not self.feet:
            raise RobotError(f"robot {self.name!r} has no feet, hence no support polygon")
        corners = self.soleCorners(q)
        return convex_hull_2d(np.vstack([c[:, :2] for c in corners.values()]))


# -- descriptions -----------------------------------------------------------------------
def list_robots() -> list[str]:
    """Names of the shipped robots (the ``*.toml`` files of :data:`ROBOTS_DIR`), sorted."""
    return sorted(p.stem for p in ROBOTS_DIR.glob("*.toml"))


def _resolve(name_or_path: str | Path) -> Path:
    """The description file of a shipped robot name, or a path to a ``.toml`` file."""
    text = str(name_or_path)
    if isinstance(name_or_path, Path) or text.endswith(".toml") or "/" in text or "\\" in text:
        path = Path(name_or_path).expanduser()
        if not path.is_file():
            raise RobotDescriptionError(f"robot description {path}: no such file")
        return path.resolve()
    path = ROBOTS_DIR / f"{text}.toml"
    if not path.is_file():
        known = list_robots()
        close = difflib.get_close_matches(text, known, n=1)
        hint = f" (did you mean {close[0]!r}?)" if close else ""
        raise RobotNotFoundError(
            f"unknown robot {text!r}{hint}; known robots: {', '.join(known)} "
            f"(or pass the path of a .toml description)"
        )
    return path


def _fail(path: Path, problem: str) -> RobotDescriptionError:
    return RobotDescriptionError(f"robot description {path}: {problem}")


def _number(path: Path, where: str, v: Any) -> float:
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
        raise _fail(path, f"{where} must be a finite number, got {v!r}")
    return float(v)


def _numbers(path: Path, where: str, v: Any, n: tuple[int, ...]) -> list[float]:
    if not isinstance(v, list) or len(v) not in n:
        sizes = " or ".join(str(k) for k in n)
        raise _fail(path, f"{where} must be a list of {sizes} numbers, got {v!r}")
    return [_number(path, f"{where}[{i}]", x) for i, x in enumerate(v)]


def _table(path: Path, where: str, v: Any) -> dict[str, Any]:
    if not isinstance(v, dict):
        raise _fail(path, f"{where} must be a table, got {v!r}")
    return v


def _string(path: Path, where: str, v: Any) -> str:
    if not isinstance(v, str) or not v:
        raise _fail(path, f"{where} must be a non-empty string, got {v!r}")
    return v


def _parse(path: Path) -> dict[str, Any]:
    """Read and validate a description (structure only, no model): see module doc."""
    try:
        with path.open("rb") as f:
            d = tomllib.load(f)
    except tomllib.TOMLDecodeError as exc:
        raise _fail(path, f"invalid TOML: {exc}") from None
    except OSError as exc:
        raise _fail(path, f"cannot read: {exc}") from None
    unknown = set(d) - _TOP_KEYS
    if unknown:
        raise _fail(path, f"unknown key(s) {sorted(unknown)}; expected some of {sorted(_TOP_KEYS)}")
    for key in ("name", "description", "model"):
        if key not in d:
            raise _fail(path, f"missing key {key!r}")
    _string(path, "name", d["name"])
    _string(path, "description", d["description"])
    model = _table(path, "[model]", d["model"])
    unknown = set(model) - _MODEL_KEYS
    if unknown:
        raise _fail(path, f"[model] has unknown key(s) {sorted(unknown)}")
    source = model.get("source")
    if source not in _SOURCES:
        raise _fail(path, f"[model] source must be one of {list(_SOURCES)}, got {source!r}")
    needed = "loader" if source == "example-robot-data" else "file"
    _string(path, f"[model] {needed} (for source {source!r})", model.get(needed))
    if not isinstance(model.get("floating_base"), bool):
        raise _fail(
            path, f"[model] floating_base must be true or false, got {model.get('floating_base')!r}"
        )
    floating = model["floating_base"]

    hs = d.get("halfSitting")
    if hs is None:
        raise _fail(path, 'missing halfSitting ("reference" or a [halfSitting] table)')
    if isinstance(hs, str):
        if hs != "reference":
            raise _fail(path, f'halfSitting must be "reference" or a table, got {hs!r}')
    else:
        hs = _table(path, "[halfSitting]", hs)
        unknown = set(hs) - {"base", "joints"}
        if unknown:
            raise _fail(path, f"[halfSitting] has unknown key(s) {sorted(unknown)}")
        if floating:
            if "base" not in hs:
                raise _fail(path, "[halfSitting] needs base = [x, y, z, qx, qy, qz, qw]")
            base = _numbers(path, "[halfSitting] base", hs["base"], (7,))
            norm = math.sqrt(sum(x * x for x in base[3:]))
            if abs(norm - 1.0) > 1e-6:
                raise _fail(
                    path,
                    f"[halfSitting] base quaternion (qx, qy, qz, qw) has norm {norm:.9g}, "
                    "expected 1",
                )
        elif "base" in hs:
            raise _fail(path, "[halfSitting] base is only for a floating base")
        joints = _table(path, "[halfSitting.joints]", hs.get("joints", {}))
        for j, v in joints.items():
            _number(path, f"[halfSitting.joints] {j}", v)

    ops = _table(path, "[opPoints]", d.get("opPoints", {}))
    for op, frame in ops.items():
        _string(path, f"[opPoints] {op}", frame)

    feet = _table(path, "[feet]", d.get("feet", {}))
    for side, foot in feet.items():
        if side not in ("left", "right"):
            raise _fail(path, f"[feet] sides are 'left' and 'right', got {side!r}")
        foot = _table(path, f"[feet.{side}]", foot)
        unknown = set(foot) - _FOOT_KEYS
        if unknown:
            raise _fail(path, f"[feet.{side}] has unknown key(s) {sorted(unknown)}")
        _string(path, f"[feet.{side}] frame", foot.get("frame"))
        for k in ("length", "width"):
            if _number(path, f"[feet.{side}] {k}", foot.get(k)) <= 0:
                raise _fail(path, f"[feet.{side}] {k} must be > 0 (m), got {foot[k]!r}")
        _numbers(path, f"[feet.{side}] offset", foot.get("offset", [0.0, 0.0]), (2, 3))

    couplings = _table(path, "[couplings]", d.get("couplings", {}))
    for j, c in couplings.items():
        if isinstance(c, str):
            continue
        c = _table(path, f"[couplings] {j}", c)
        if set(c) - {"joint", "multiplier", "offset"}:
            raise _fail(path, f"[couplings] {j}: keys are joint, multiplier, offset")
        _string(path, f"[couplings] {j} joint", c.get("joint"))
        _number(path, f"[couplings] {j} multiplier", c.get("multiplier", 1.0))
        _number(path, f"[couplings] {j} offset", c.get("offset", 0.0))
    d["path"] = str(path)
    return d


def robot_info(name: str | Path) -> dict[str, Any]:
    """The parsed description of a robot (no model loaded).

    Args:
        name: a shipped robot's name (see :func:`list_robots`) or the path of a ``.toml``
            description.

    Returns:
        The TOML content as a dict (keys ``name``, ``description``, ``model``,
        ``halfSitting``, ``opPoints``, ``feet``, ``couplings``), plus ``path``, the
        description file.

    Raises:
        RobotNotFoundError: unknown name (the message lists the known robots).
        RobotDescriptionError: malformed description (the message names file and problem).
    """
    return _parse(_resolve(name))


# -- models -----------------------------------------------------------------------------
@dataclass
class _Loaded:
    model: Any
    visual_model: Any
    collision_model: Any
    urdf: Path | None  # the URDF file, for <mimic> tags
    reference: np.ndarray | None  # the SRDF reference configuration, if any


#: Loaded models by (source, loader or URDF path and modification time, floating base).
_CACHE: dict[tuple[str, str, int, bool], _Loaded] = {}


def _check_urdf(desc: Path, urdf: Path) -> ET.Element:
    if not urdf.is_file():
        raise _fail(desc, f"model file {urdf}: no such file")
    try:
        root = ET.parse(urdf).getroot()
    except ET.ParseError as exc:
        raise _fail(desc, f"model file {urdf}: malformed XML: {exc}") from None
    if root.tag != "robot":
        raise _fail(desc, f"model file {urdf}: root element is <{root.tag}>, expected <robot>")
    return root


@contextlib.contextmanager
def _stderr_captured() -> Iterator[list[str]]:
    """Capture what C++ code writes on file descriptor 2 (urdfdom explains its errors
    there, Pinocchio's exception only says the file is not valid). Yields a list that
    receives the text; on success the text is written back to stderr."""
    out: list[str] = []
    try:
        sys.stderr.flush()
        saved = os.dup(2)
    except (OSError, ValueError):  # no usable fd 2: run without capture
        yield out
        return
    with tempfile.TemporaryFile(mode="w+b") as tmp:
        os.dup2(tmp.fileno(), 2)
        ok = False
        try:
            yield out
            ok = True
        finally:
            os.dup2(saved, 2)
            os.close(saved)
            tmp.seek(0)
            text = tmp.read().decode(errors="replace")
            out.append(text)
            if ok and text:
                sys.stderr.write(text)


def _load_urdf(desc: Path, urdf: Path, floating: bool) -> _Loaded:
    _check_urdf(desc, urdf)
    try:
        with _stderr_captured() as parser_output:
            if floating:
                model = pin.buildModelFromUrdf(str(urdf), pin.JointModelFreeFlyer())
            else:
                model = pin.buildModelFromUrdf(str(urdf))
            dirs = [str(urdf.parent)]
            visual = pin.buildGeomFromUrdf(model, str(urdf), pin.GeometryType.VISUAL, None, dirs)
            collision = pin.buildGeomFromUrdf(
                model, str(urdf), pin.GeometryType.COLLISION, None, dirs
            )
    except (ValueError, RuntimeError) as exc:
        detail = " ".join(
            line.strip()
            for line in "".join(parser_output).splitlines()
            if line.strip() and not line.strip().startswith("at line")
        )
        reason = f"{exc}" + (f" ({detail})" if detail else "")
        raise _fail(desc, f"model file {urdf}: Pinocchio cannot load it: {reason}") from None
    return _Loaded(model, visual, collision, urdf, None)


def _load_erd(desc: Path, loader: str, floating: bool) -> _Loaded:
    import example_robot_data

    try:
        r = example_robot_data.load(loader)
    except ValueError as exc:
        raise _fail(desc, f"example-robot-data has no loader {loader!r}: {exc}") from None
    has_ff = r.model.njoints > 1 and r.model.joints[1].shortname() == "JointModelFreeFlyer"
    if has_ff != floating:
        raise _fail(
            desc,
            f"floating_base = {str(floating).lower()} but example-robot-data's {loader!r} "
            f"model has {'a free flyer' if has_ff else 'a fixed base'}",
        )
    reference = np.array(r.q0, dtype=float) if len(r.model.referenceConfigurations) else None
    urdf = Path(r.urdf) if getattr(r, "urdf", None) else None
    return _Loaded(r.model, r.visual_model, r.collision_model, urdf, reference)


def _load(path: Path, d: dict[str, Any]) -> _Loaded:
    m = d["model"]
    if m["source"] == "urdf":
        urdf = (path.parent / m["file"]).resolve()
        mtime = urdf.stat().st_mtime_ns if urdf.is_file() else -1
        key = ("urdf", str(urdf), mtime, m["floating_base"])  # an edited file is reloaded
    else:
        key = ("example-robot-data", m["loader"], 0, m["floating_base"])
    if key not in _CACHE:
        if m["source"] == "urdf":
            _CACHE[key] = _load_urdf(path, urdf, m["floating_base"])
        else:
            _CACHE[key] = _load_erd(path, m["loader"], m["floating_base"])
    return _CACHE[key]


def load_model(name: str | Path) -> tuple[Any, Any, Any]:
    """Load (once per process) a robot's Pinocchio models.

    A ``source = "urdf"`` model is built with ``pin.buildModelFromUrdf`` (with a
    ``JointModelFreeFlyer`` root when ``floating_base``) and ``pin.buildGeomFromUrdf``;
    an ``example-robot-data`` model with ``example_robot_data.load(loader)``. Later calls
    return the same objects: treat them as read-only.

    Args:
        name: a shipped robot's name or the path of a ``.toml`` description.

    Returns:
        ``(model, visual_model, collision_model)``.

    Raises:
        RobotNotFoundError, RobotDescriptionError: see :func:`robot_info`; also a
            missing or malformed model file.
    """
    path = _resolve(name)
    loaded = _load(path, _parse(path))
    return loaded.model, loaded.visual_model, loaded.collision_model


def _n_joints(model: Any) -> int:
    """Joints besides the universe and the free-flyer root."""
    n = model.njoints - 1
    if n > 0 and model.joints[1].shortname() == "JointModelFreeFlyer":
        n -= 1
    return n


def _one_dof(model: Any, name: str) -> int | None:
    """Index in q of a 1-DoF joint (None if absent or not 1-DoF)."""
    if not model.existJointName(name):
        return None
    jm = model.joints[model.getJointId(name)]
    return jm.idx_q if jm.nq == 1 and jm.nv == 1 else None


def _mimics(urdf: Path | None) -> dict[str, Coupling]:
    if urdf is None or not urdf.is_file():
        return {}
    out = {}
    for j in ET.parse(urdf).getroot().iter("joint"):
        mimic = j.find("mimic")
        if mimic is not None and j.get("name") and mimic.get("joint"):
            out[j.get("name")] = Coupling(
                j.get("name"),
                mimic.get("joint"),
                float(mimic.get("multiplier", 1.0)),
                float(mimic.get("offset", 0.0)),
            )
    return out


def _frame_check(path: Path, model: Any, where: str, frame: str) -> None:
    if not model.existFrame(frame):
        names = [f.name for f in model.frames]
        close = difflib.get_close_matches(frame, names, n=3)
        hint = f"; close names: {', '.join(close)}" if close else ""
        raise _fail(path, f"{where}: frame {frame!r} is not in the model{hint}")


def _couplings(path: Path, d: dict[str, Any], loaded: _Loaded) -> dict[str, Coupling]:
    model = loaded.model
    out = {
        j: c
        for j, c in _mimics(loaded.urdf).items()
        if _one_dof(model, j) is not None and _one_dof(model, c.master) is not None
    }
    for j, c in d.get("couplings", {}).items():
        if isinstance(c, str):
            c = {"joint": c}
        coupling = Coupling(
            j, c["joint"], float(c.get("multiplier", 1.0)), float(c.get("offset", 0.0))
        )
        for name in (j, coupling.master):
            if _one_dof(model, name) is None:
                raise _fail(path, f"[couplings] {j}: {name!r} is not a 1-DoF joint of the model")
        out[j] = coupling
    for j, c in out.items():
        if c.master in out:
            raise _fail(path, f"coupling {j} -> {c.master}: {c.master!r} is itself coupled")
    return out


def _half_sitting(
    path: Path, d: dict[str, Any], loaded: _Loaded, couplings: dict[str, Coupling]
) -> np.ndarray:
    """The half-sitting q: checked against the joint limits and the couplings."""
    model = loaded.model
    hs = d["halfSitting"]
    if isinstance(hs, str):  # "reference"
        if loaded.reference is None:
            raise _fail(
                path,
                'halfSitting = "reference" but the model has no SRDF reference '
                "configuration: give [halfSitting] explicitly",
            )
        q = loaded.reference.copy()
        for c in couplings.values():  # make the reference consistent with the couplings
            q[_one_dof(model, c.joint)] = c.multiplier * q[_one_dof(model, c.master)] + c.offset
    else:
        q = pin.neutral(model)
        if "base" in hs:
            base = np.array(hs["base"], dtype=float)
            base[3:] /= np.linalg.norm(base[3:])
            q[:7] = base
        joints = hs.get("joints", {})
        for j, v in joints.items():
            i = _one_dof(model, j)
            if i is None:
                close = difflib.get_close_matches(j, list(model.names), n=3)
                hint = f"; close names: {', '.join(close)}" if close else ""
                raise _fail(path, f"[halfSitting.joints] {j!r} is not a 1-DoF joint{hint}")
            q[i] = v
        missing = [
            model.names[k]
            for k in range(1, model.njoints)
            if _one_dof(model, model.names[k]) is not None
            and model.names[k] not in joints
            and model.names[k] not in couplings
        ]
        if missing:
            raise _fail(path, f"[halfSitting.joints] misses joint(s) {', '.join(missing)}")
        for c in couplings.values():
            i, im = _one_dof(model, c.joint), _one_dof(model, c.master)
            expected = c.multiplier * q[im] + c.offset
            if c.joint not in joints:
                q[i] = expected
            elif abs(q[i] - expected) > 1e-9:
                raise _fail(
                    path,
                    f"[halfSitting.joints] {c.joint} = {q[i]:.9g} violates the coupling "
                    f"{c.joint} = {c.multiplier:g} * {c.master} + {c.offset:g} = {expected:.9g}",
                )
    for k in range(1, model.njoints):
        jm = model.joints[k]
        if jm.shortname() == "JointModelFreeFlyer":
            continue
        for i in range(jm.idx_q, jm.idx_q + jm.nq):
            lo, hi = model.lowerPositionLimit[i], model.upperPositionLimit[i]
            if not lo - _LIMIT_TOL <= q[i] <= hi + _LIMIT_TOL:
                raise _fail(
                    path,
                    f"halfSitting: joint {model.names[k]} = {q[i]:.9g} is outside its limits "
                    f"[{lo:.9g}, {hi:.9g}]",
                )
    return q


def _feet(path: Path, d: dict[str, Any], model: Any) -> dict[str, Foot]:
    feet = {}
    for side, f in d.get("feet", {}).items():
        _frame_check(path, model, f"[feet.{side}]", f["frame"])
        offset = [float(x) for x in f.get("offset", [0.0, 0.0])]
        offset += [0.0] * (3 - len(offset))
        feet[side] = Foot(side, f["frame"], float(f["length"]), float(f["width"]), tuple(offset))
    return feet


@dataclass
class _Prepared:
    description: dict[str, Any]
    loaded: _Loaded
    couplings: dict[str, Coupling]
    feet: dict[str, Foot]
    halfSitting: np.ndarray


def _prepare(name: str | Path) -> _Prepared:
    """Resolve, parse, load and check a description against its model."""
    path = _resolve(name)
    d = _parse(path)
    loaded = _load(path, d)
    for op, frame in d.get("opPoints", {}).items():
        _frame_check(path, loaded.model, f"[opPoints] {op}", frame)
    feet = _feet(path, d, loaded.model)
    couplings = _couplings(path, d, loaded)
    q = _half_sitting(path, d, loaded, couplings)
    return _Prepared(d, loaded, couplings, feet, q)


def robot_summary(name: str | Path) -> dict[str, Any]:
    """Degrees of freedom and op points of a robot (loads its model, no entity).

    Returns:
        dict with ``name``, ``nq``, ``nv``, ``joints`` (joints besides the free flyer),
        ``couplings`` (their number), ``actuated`` (``joints - couplings``),
        ``floating_base``, ``source`` (``"example-robot-data:talos"``,
        ``"urdf:nao.urdf"``), ``opPoints`` (mapping) and ``halfSitting`` (q).
    """
    p = _prepare(name)
    d, model = p.description, p.loaded.model
    m = d["model"]
    joints = _n_joints(model)
    return {
        "name": d["name"],
        "nq": model.nq,
        "nv": model.nv,
        "joints": joints,
        "couplings": len(p.couplings),
        "actuated": joints - len(p.couplings),
        "floating_base": m["floating_base"],
        "source": f"{m['source']}:{m.get('loader') or m.get('file')}",
        "opPoints": dict(d.get("opPoints", {})),
        "halfSitting": p.halfSitting,
    }


def load_robot(name: str | Path, prefix: str | None = None) -> Robot:
    """Load a robot: its model, a ``Dynamic`` and a ``Device`` wired as in the SoT.

    Creates ``Dynamic(f"{prefix or name}_dynamic", model)`` with ``createOpPoint(op,
    frame)`` for every op point, and ``Device(f"{prefix or name}_device", model)`` set to
    half-sitting; plugs ``device.state -> dynamic.position`` and ``device.velocity ->
    dynamic.velocity``.

    Args:
        name: a shipped robot's name (:func:`list_robots`) or the path of a ``.toml``
            description.
        prefix: entity name prefix (default: the robot's name), to load the same robot
            twice in one pool.

    Raises:
        RobotNotFoundError: unknown name (the message lists the known robots).
        RobotDescriptionError: broken description or model file, unknown frame, joint
            or posture outside the limits (the message names the file and the problem).
        RobotError: the entities' names are already taken in the pool.
    """
    from ..graph.pool import pool
    from ..graph.signal import plug
    from .device import Device
    from .dynamic import Dynamic

    p = _prepare(name)
    d, loaded = p.description, p.loaded
    prefix = prefix or d["name"]
    names = (f"{prefix}_dynamic", f"{prefix}_device")
    for n in names:
        if pool.hasEntity(n):
            raise RobotError(
                f"cannot load robot {d['name']!r}: entity {n!r} already exists; "
                "pass prefix=... to load another instance"
            )
    ops = dict(d.get("opPoints", {}))
    try:
        dynamic = Dynamic(names[0], loaded.model)
        for op, frame in ops.items():
            dynamic.createOpPoint(op, frame)
        device = Device(names[1], loaded.model)
        device.set(p.halfSitting.copy())
        plug(device.state, dynamic.position)
        plug(device.velocity, dynamic.velocity)
    except BaseException:
        for n in names:  # leave the pool as it was
            if pool.hasEntity(n):
                pool.remove(n)
        raise
    robot = Robot(
        name=d["name"],
        model=loaded.model,
        visual_model=loaded.visual_model,
        collision_model=loaded.collision_model,
        dynamic=dynamic,
        device=device,
        halfSitting=p.halfSitting.copy(),
        opPoints=ops,
        feet=p.feet,
        couplings=p.couplings,
        description=d,
    )
    _LOADED[dynamic.name] = robot
    return robot


#: The robots of :func:`load_robot` (by their Dynamic's name); :func:`loadedRobots`
#: forgets those whose Dynamic left the pool.
_LOADED: dict[str, Robot] = {}


def loadedRobots() -> list[Robot]:
    """The robots :func:`load_robot` made in this process that are still in use (their
    ``Dynamic`` still in the pool): what a command that needs "the robot" looks in (the
    pattern generator's ``buildModel()`` without an argument)."""
    from ..graph import pool

    for name, r in list(_LOADED.items()):
        if not (pool.hasEntity(name) and pool.getEntity(name) is r.dynamic):
            del _LOADED[name]
    return list(_LOADED.values())
