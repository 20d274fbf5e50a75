"""Meta-tasks: a feature, a task and a gain built and plugged together (SoT's
``meta_tasks_kine.py``).

::

    rh = MetaTaskKine6d("rh", robot.dynamic, "right-wrist")
    rh.keep()                                      # hold the current placement
    rh.opmodif = pin.SE3(np.eye(3), [0.1, 0, 0])   # control a point 10 cm along x
    rh.gotoNd([0.3, -0.3, 1.0], "111000", 1.0)     # position only, gain 1/s
    gotoNd(rh, [0.3, -0.3, 1.0], "111000", 1.0)    # the same, SoT's function
    sot.push(rh.task.name)

    com = MetaTaskKineCom(robot.dynamic)           # featurecom, featureDescom, taskcom
    com.keep()
    posture = MetaTaskKinePosture(robot.dynamic, robot.device)
    posture.gotoq(robot.halfSitting, gain=0.5)

Each meta-task creates entities named from its name (``'feature' + name``,
``'task' + name``, ``'gain' + name``, ...) and refuses a name whose entities already
exist, so two meta-tasks never share an entity. Until ``keep()``, ``gotoNd``/``gotoq``
or ``ref = ...`` sets a reference, reading the task raises an error naming the unset
reference input.

Selection flags are read left to right (``"111000"``: the translation; see
:mod:`sotpy.tasks.features`).

A meta-task refuses an attribute it does not have (``AttributeError`` naming it and
the meta-task's attributes): a typo, or a SoT attribute this meta-task lacks, is never
silently stored and ignored.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
import pinocchio as pin

from ..dynamics import Device, Dynamic
from ..dynamics.types import homogeneousToSE3
from ..errors import CommandError, EntityError
from ..graph import Entity, plug, pool
from ..operators.op_point import OpPointModifier
from .features import FeatureGeneric, FeaturePose, FeaturePosture, Flags
from .gain import GainAdaptive
from .task import Task

__all__ = [
    "MetaTaskKine6d",
    "MetaTaskKineCom",
    "MetaTaskKinePosture",
    "goto6d",
    "gotoNd",
    "setGain",
    "toFlags",
]


def toFlags(spec: Any) -> Flags:
    """SoT's ``toFlags``: a flag string (``"111000"``) or a sequence of booleans as
    :class:`Flags` takes them, or a sequence of row indices (``range(6, 12)``; the
    meaning old SoT scripts give it): those rows selected, the others not."""
    if isinstance(spec, (str, Flags, bool, np.bool_)):
        return Flags(spec)
    items = list(spec)
    if items and all(isinstance(i, (int, np.integer)) and not isinstance(i, bool) for i in items):
        if any(i < 0 for i in items):
            raise CommandError(f"toFlags: row indices must be >= 0, got {items}")
        if not all(i in (0, 1) for i in items) or len(items) == 1:
            bits = [False] * (max(items) + 1)
            for i in items:
                bits[i] = True
            return Flags(bits)
    return Flags(items)


def gotoNd(
    task: Any,
    position: Any,
    selec: str | Flags | Sequence[bool] | None = None,
    gain: float | Sequence[float] | None = None,
    resetJacobian: bool = True,
) -> None:
    """SoT's ``gotoNd(task, position, selec, gain)``: ``task.gotoNd(position, selec,
    gain)`` for a :class:`MetaTaskKine6d` or :class:`MetaTaskKineCom` (see their
    method). ``resetJacobian`` (SoT's, for ``TaskPD``) has no effect here."""
    method = getattr(task, "gotoNd", None)
    if method is None:
        raise CommandError(
            f"gotoNd: {task!r} is not a meta-task with a target (MetaTaskKine6d, MetaTaskKineCom)"
        )
    method(position, selec, gain)


def goto6d(task: Any, position: Any, gain: float | Sequence[float] | None = None) -> None:
    """SoT's ``goto6d``: :func:`gotoNd` with every row selected (``"111111"``)."""
    gotoNd(task, position, "111111", gain)


def setGain(gain: GainAdaptive, value: float | Sequence[float] | None) -> None:
    """SoT's ``setGain``: a number (or a 1-sequence) sets a constant gain, a 3-sequence
    ``gain.set(g0, ginf, slope)``, a 4-sequence ``gain.setByPoint(g0, ginf, xref, p)``;
    ``None`` leaves the gain unchanged."""
    if value is None:
        return
    if isinstance(value, (int, float, np.integer, np.floating)) and not isinstance(value, bool):
        gain.setConstant(float(value))
        return
    values = [float(v) for v in value]  # type: ignore[union-attr]
    if len(values) == 1:
        gain.setConstant(values[0])
    elif len(values) == 3:
        gain.set(*values)
    elif len(values) == 4:
        gain.setByPoint(*values)
    else:
        raise CommandError(
            f"{gain!r}: a gain is a number, (g0, ginf, slope) or (g0, ginf, xref, p); got {value!r}"
        )


class _MetaTask:
    """Entity bookkeeping shared by the meta-tasks."""

    _constructed = False

    def __setattr__(self, attr: str, value: Any) -> None:
        if (
            self._constructed
            and not attr.startswith("_")
            and attr not in self.__dict__
            and not hasattr(type(self), attr)
        ):
            known = sorted(a for a in (*self.__dict__, *dir(type(self))) if not a.startswith("_"))
            raise AttributeError(
                f"{type(self).__name__}({self.name!r}) has no attribute {attr!r}: it is "
                f"not stored (it would be ignored); its attributes: {', '.join(known)}"
            )
        object.__setattr__(self, attr, value)

    def _reserve(self, kind: str, names: list[str]) -> None:
        taken = [n for n in names if pool.hasEntity(n)]
        if taken:
            raise EntityError(
                f"{kind}({self.name!r}): entities {', '.join(taken)} already exist: each "
                "meta-task needs its own; pick another name (or pool.remove them)"
            )

    def _build(self, steps: Any) -> None:
        """Run ``steps()``; on failure remove the entities it created."""
        before = set(pool.list())
        try:
            steps()
        except BaseException:
            created = [n for n in pool.list() if n not in before]
            if created:
                pool.remove(*created)  # together: they use one another
            raise

    def entities(self) -> list[Entity]:
        """The entities this meta-task created."""
        return [getattr(self, a) for a in self._entityAttributes]

    _entityAttributes: tuple[str, ...] = ()
    name: str


class MetaTaskKine6d(_MetaTask):
    """A 6-D task on an operational point of a ``Dynamic``.

    ``MetaTaskKine6d(name, dynamic, opPoint, frame=None)``: uses the op point
    ``opPoint`` of ``dynamic`` (signals ``opPoint`` and ``J<opPoint>``), creating it on
    the Pinocchio frame ``frame`` if it does not exist. Creates and plugs:

    - ``feature`` = ``FeaturePose('feature' + name)`` (``featureClass`` to use
      ``FeaturePoseSE3``): ``dynamic.<opPoint>`` -> ``position``,
      ``dynamic.J<opPoint>`` -> ``Jq``, selection ``"111111"``;
    - ``task`` = ``Task('task' + name)`` with the feature;
    - ``gain`` = ``GainAdaptive('gain' + name)``, constant 0.1 1/s (SoT's default):
      ``task.error`` -> ``gain.error``, ``gain.gain`` -> ``task.controlGain``;
    - ``opPointModif`` = ``OpPointModifier('opmodif' + name)`` on the op point,
      inactive until ``opmodif`` is set.

    ``keep()`` holds the current placement; ``gotoNd(position, selec, gain)`` sets a
    target; ``ref`` is the desired placement. ``opmodif = aMb`` (a 4 x 4 homogeneous
    matrix, a tuple of its rows or a ``pinocchio.SE3``; m) makes the task control the
    frame ``b`` rigidly attached to the op point ``a`` (a grip point, a tool tip)
    instead of ``a`` itself: the feature then reads the modifier's ``position`` and
    ``jacobian``; ``opmodif = False`` goes back to the op point. Reading ``opmodif``
    gives ``aMb`` as a 4 x 4 matrix, or ``False`` when inactive (SoT's).
    """

    _entityAttributes = ("feature", "task", "gain", "opPointModif")

    def __init__(
        self,
        name: str,
        dynamic: Dynamic,
        opPoint: str,
        frame: str | None = None,
        featureClass: type[FeaturePose] = FeaturePose,
    ) -> None:
        self.name = name
        if not isinstance(dynamic, Dynamic):
            raise EntityError(
                f"MetaTaskKine6d({name!r}): expected a Dynamic entity, got {dynamic!r}"
            )
        self.dynamic = self.dyn = dynamic
        self.opPoint = opPoint
        self._reserve(
            "MetaTaskKine6d",
            ["feature" + name, "task" + name, "gain" + name, "opmodif" + name],
        )
        created = False
        if not dynamic.hasSignal(opPoint):
            if frame is None:
                raise EntityError(
                    f"MetaTaskKine6d({name!r}): {dynamic!r} has no op point {opPoint!r}; "
                    "give the Pinocchio frame to create it on (argument 'frame')"
                )
            dynamic.createOpPoint(opPoint, frame)
            created = True
        if not dynamic.hasSignal("J" + opPoint):
            raise EntityError(
                f"MetaTaskKine6d({name!r}): {dynamic!r} has a signal {opPoint!r} but no "
                f"Jacobian 'J{opPoint}' (create it with createOpPoint)"
            )

        def steps() -> None:
            self.feature = featureClass("feature" + name)
            self.task = Task("task" + name)
            self.gain = GainAdaptive("gain" + name)
            self.opPointModif = OpPointModifier("opmodif" + name)
            self.feature.selec.value = "111111"
            plug(dynamic.signal(opPoint), self.opPointModif.positionIN)
            plug(dynamic.signal("J" + opPoint), self.opPointModif.jacobianIN)
            plug(dynamic.signal(opPoint), self.feature.position)
            plug(dynamic.signal("J" + opPoint), self.feature.Jq)
            self.task.add(self.feature)
            plug(self.task.error, self.gain.error)
            plug(self.gain.gain, self.task.controlGain)

        try:
            self._build(steps)
        except BaseException:
            if created:
                dynamic.destroyOpPoint(opPoint)
            raise
        self._constructed = True

    @property
    def opmodif(self) -> np.ndarray | bool:
        """``aMb`` (4 x 4) of the controlled frame in the op point, or ``False`` when
        the task controls the op point itself (see the class doc)."""
        if not self.opPointModif.activ:
            return False
        return self.opPointModif.getTransformation()

    @opmodif.setter
    def opmodif(self, aMb: Any) -> None:
        modifier, dyn = self.opPointModif, self.dynamic
        if isinstance(aMb, (bool, np.bool_)):
            if aMb:
                raise CommandError(
                    f"MetaTaskKine6d({self.name!r}).opmodif: True is not a placement; give "
                    "aMb (a 4 x 4 homogeneous matrix or a pinocchio.SE3), or False"
                )
            plug(dyn.signal(self.opPoint), self.feature.position)
            plug(dyn.signal("J" + self.opPoint), self.feature.Jq)
            modifier.activ = False
            return
        if isinstance(aMb, pin.SE3):
            M = aMb
        else:
            try:
                M = homogeneousToSE3(aMb, f"MetaTaskKine6d({self.name!r}).opmodif")
            except (TypeError, ValueError) as exc:
                raise CommandError(f"{exc}; the task is left unchanged") from None
        modifier.setTransformation(M)
        if not modifier.activ:
            plug(modifier.position, self.feature.position)
            plug(modifier.jacobian, self.feature.Jq)
            modifier.activ = True

    @property
    def ref(self) -> pin.SE3:
        """The desired placement ``oMf*`` (``feature.reference``)."""
        return self.feature.reference.value

    @ref.setter
    def ref(self, M: Any) -> None:
        self.feature.reference.value = self._toSE3(M)

    def keep(self) -> None:
        """Hold the current placement: reference = the controlled frame's placement now
        (the op point, or the frame of ``opmodif``), with a zero reference velocity (the
        error becomes zero)."""
        self.feature.keep()

    def gotoNd(
        self,
        position: Any,
        selec: str | Flags | Sequence[bool] | None = None,
        gain: float | Sequence[float] | None = None,
    ) -> None:
        """Set the target (SoT's ``gotoNd``).

        Args:
            position: a ``pinocchio.SE3``; a 4 x 4 homogeneous matrix; a 3-vector (the
                target position; the orientation stays that of the current reference,
                or of the current placement if none is set); a 6-vector ``(x, y, z,
                roll, pitch, yaw)`` (``R = Rz(yaw) Ry(pitch) Rx(roll)``); a 7-vector
                ``(x, y, z, qx, qy, qz, qw)``. m, rad.
            selec: rows to control (``"111000"`` position only, left to right); None
                keeps the current selection.
            gain: see :func:`setGain`; None keeps the current gain.
        """
        M = self._toSE3(position)
        if selec is not None:
            self.feature.selec.value = selec
        self.feature.reference.value = M
        setGain(self.gain, gain)

    def _toSE3(self, p: Any) -> pin.SE3:
        if isinstance(p, pin.SE3):
            return p.copy()
        a = np.asarray(p, dtype=float)
        if a.shape == (4, 4):
            R = a[:3, :3]
            if not (
                np.allclose(a[3], [0, 0, 0, 1])
                and np.allclose(R.T @ R, np.eye(3), atol=1e-6)
                and np.linalg.det(R) > 0
            ):
                raise CommandError(
                    f"MetaTaskKine6d({self.name!r}): the 4 x 4 matrix is not a homogeneous "
                    "transform (rotation block not orthonormal, or last row not 0 0 0 1)"
                )
            return pin.SE3(R, a[:3, 3])
        if a.shape == (3,):
            ref = self.feature.reference
            base = ref.value if ref.isPlugged else self.feature.position.value
            return pin.SE3(base.rotation, a)
        if a.shape == (6,):
            return pin.SE3(pin.rpy.rpyToMatrix(*a[3:]), a[:3])
        if a.shape == (7,):
            quat = a[3:]
            if not abs(np.linalg.norm(quat) - 1.0) < 1e-6:
                raise CommandError(
                    f"MetaTaskKine6d({self.name!r}): the quaternion {quat} is not normalised"
                )
            return pin.XYZQUATToSE3(a)
        raise CommandError(
            f"MetaTaskKine6d({self.name!r}): a target is a pinocchio.SE3, a 4 x 4 matrix, or a "
            f"vector of size 3 (xyz), 6 (xyz rpy) or 7 (xyz quaternion); got shape {a.shape}"
        )


class MetaTaskKineCom(_MetaTask):
    """A CoM task (SoT's ``MetaTaskKineCom``).

    ``MetaTaskKineCom(dynamic, name="com")`` creates ``feature`` =
    ``FeatureGeneric('feature' + name)`` on ``dynamic.com``/``dynamic.Jcom``, its
    reference ``featureDes`` = ``FeatureGeneric('featureDes' + name)`` (the desired CoM in
    ``featureDes.errorIN``, m, world axes), ``task`` = ``Task('task' + name)`` and
    ``gain`` = ``GainAdaptive('gain' + name)`` (constant 0.1 1/s). ``gotoNd(com, "11")``
    controls only ``x, y`` (the projection on the ground).
    """

    _entityAttributes = ("feature", "featureDes", "task", "gain")

    def __init__(self, dynamic: Dynamic, name: str = "com") -> None:
        self.name = name
        if not isinstance(dynamic, Dynamic):
            raise EntityError(
                f"MetaTaskKineCom({name!r}): expected a Dynamic entity, got {dynamic!r}"
            )
        self.dynamic = self.dyn = dynamic
        self._reserve(
            "MetaTaskKineCom",
            ["feature" + name, "featureDes" + name, "task" + name, "gain" + name],
        )

        def steps() -> None:
            self.feature = FeatureGeneric("feature" + name)
            self.featureDes = FeatureGeneric("featureDes" + name)
            self.task = Task("task" + name)
            self.gain = GainAdaptive("gain" + name)
            plug(dynamic.com, self.feature.errorIN)
            plug(dynamic.Jcom, self.feature.jacobianIN)
            self.feature.setReference(self.featureDes)
            self.task.add(self.feature)
            plug(self.task.error, self.gain.error)
            plug(self.gain.gain, self.task.controlGain)

        self._build(steps)
        self._constructed = True

    @property
    def ref(self) -> np.ndarray:
        """The desired CoM (m, world), ``featureDes.errorIN``."""
        return self.featureDes.errorIN.value

    @ref.setter
    def ref(self, c: Any) -> None:
        self.featureDes.errorIN.value = self._com(c)

    def _com(self, c: Any) -> np.ndarray:
        a = np.asarray(c, dtype=float)
        if a.shape != (3,):
            raise CommandError(
                f"MetaTaskKineCom({self.name!r}): a CoM target is a 3-vector (m), got shape "
                f"{a.shape}"
            )
        return a

    def keep(self) -> None:
        """Hold the current CoM (the error becomes zero)."""
        self.featureDes.errorIN.value = self.dynamic.com.value

    def gotoNd(
        self,
        position: Any,
        selec: str | Flags | Sequence[bool] | None = None,
        gain: float | Sequence[float] | None = None,
    ) -> None:
        """Target CoM ``position`` (3-vector, m, world axes); ``selec`` the rows
        (``"11"``: x and y), ``gain`` see :func:`setGain`."""
        c = self._com(position)
        if selec is not None:
            self.feature.selec.value = selec
        self.featureDes.errorIN.value = c
        setGain(self.gain, gain)


class MetaTaskKinePosture(_MetaTask):
    """A posture task (SoT's ``MetaTaskKinePosture``) on a :class:`FeaturePosture`.

    ``MetaTaskKinePosture(dynamic, device=None, name="posture")``: ``dynamic`` is a
    ``Dynamic`` (its model is used) or a ``pinocchio.Model``. ``feature.state`` is
    plugged to ``device.state`` if a device is given, else to the output that feeds
    ``dynamic.position`` (if any); otherwise plug it yourself. Creates ``feature`` =
    ``FeaturePosture('feature' + name, model)`` (every joint, not the free flyer),
    ``task`` = ``Task('task' + name)``, ``gain`` = ``GainAdaptive('gain' + name)``
    (constant 0.1 1/s). ``gotoq`` sets the desired posture, ``keep()`` holds the current
    one.
    """

    _entityAttributes = ("feature", "task", "gain")

    def __init__(
        self,
        dynamic: Dynamic | pin.Model,
        device: Device | None = None,
        name: str = "posture",
    ) -> None:
        self.name = name
        if isinstance(dynamic, Dynamic):
            model = dynamic.model
            self.dynamic: Dynamic | None = dynamic
        elif isinstance(dynamic, pin.Model):
            model = dynamic
            self.dynamic = None
        else:
            raise EntityError(
                f"MetaTaskKinePosture({name!r}): expected a Dynamic or a pinocchio.Model, "
                f"got {dynamic!r}"
            )
        if device is not None and not isinstance(device, Device):
            raise EntityError(
                f"MetaTaskKinePosture({name!r}): expected a Device (or None), got {device!r}"
            )
        self.device = device
        self._reserve("MetaTaskKinePosture", ["feature" + name, "task" + name, "gain" + name])

        def steps() -> None:
            self.feature = FeaturePosture("feature" + name, model)
            self.task = Task("task" + name)
            self.gain = GainAdaptive("gain" + name)
            if device is not None:
                plug(device.state, self.feature.state)
            elif self.dynamic is not None and self.dynamic.position.source is not None:
                plug(self.dynamic.position.source, self.feature.state)
            self.task.add(self.feature)
            plug(self.task.error, self.gain.error)
            plug(self.gain.gain, self.task.controlGain)

        self._build(steps)
        self._constructed = True

    @property
    def model(self) -> pin.Model:
        """The feature's model."""
        return self.feature.model

    @property
    def ref(self) -> np.ndarray:
        """The desired posture ``q*`` (``feature.posture``)."""
        return self.feature.posture.value

    @ref.setter
    def ref(self, q: Any) -> None:
        self.feature.posture.value = self._configuration(q)

    def keep(self) -> None:
        """Hold the current configuration (the error becomes zero)."""
        self.feature.posture.value = self.feature.state.value

    def gotoq(
        self,
        qdes: Any = None,
        gain: float | Sequence[float] | None = None,
        joints: dict[str, float] | None = None,
    ) -> None:
        """Set the desired posture.

        Args:
            qdes: a configuration (size nq, Pinocchio's); None starts from the current
                desired posture, or from the current state if none is set.
            gain: see :func:`setGain`; None keeps the current gain.
            joints: ``{joint name: value}`` (rad or m) for one-coordinate joints,
                applied on top of ``qdes``.
        """
        if qdes is None:
            src = self.feature.posture if self.feature.posture.isPlugged else self.feature.state
            q = np.array(src.value, dtype=float)
        else:
            q = self._configuration(qdes)
        model = self.model
        for jname, value in (joints or {}).items():
            if not model.existJointName(jname):
                raise CommandError(
                    f"MetaTaskKinePosture({self.name!r}).gotoq: no joint named {jname!r} in "
                    f"model {model.name!r}"
                )
            j = model.getJointId(jname)
            if model.nqs[j] != 1:
                raise CommandError(
                    f"MetaTaskKinePosture({self.name!r}).gotoq: joint {jname!r} has "
                    f"{model.nqs[j]} coordinates; set it through qdes"
                )
            q[model.idx_qs[j]] = float(value)
        self.feature.posture.value = q
        setGain(self.gain, gain)

    def _configuration(self, q: Any) -> np.ndarray:
        a = np.array(q, dtype=float)
        nq = self.model.nq
        if a.shape != (nq,):
            raise CommandError(
                f"MetaTaskKinePosture({self.name!r}): expected a configuration of size nq = "
                f"{nq}, got shape {a.shape}"
            )
        return a
