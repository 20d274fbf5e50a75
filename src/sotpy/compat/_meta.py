"""The meta-tasks of sot-core's Python modules (``meta_task_6d``, ``meta_tasks``,
``meta_tasks_kine``, ``meta_task_posture``), with SoT's signatures and semantics, over
sotpy's meta-tasks (:mod:`sotpy.tasks.meta_task`).

What they add to sotpy's:

- ``MetaTaskKine6d(name, dyn, opPoint, opPointRef)``: a ``FeaturePoint6d``
  ``'feature' + name`` whose reference is a second one, ``featureDes`` =
  ``'feature' + name + '_ref'`` (its ``position`` is the desired placement), computed in
  the ``"current"`` frame as SoT's meta-task sets it (``feature.frame("desired")``
  changes it); the op point is created on the joint or frame ``opPointRef`` if missing;
- ``gotoNd(task, position, selec, gain)`` (and the method): a 3-vector target has the
  identity orientation (SoT's ``generic6dReference``); sotpy's own keeps the current
  orientation;
- ``MetaTaskKinePosture(dyn, name)``: ``gotoq(gain, qdes, **joints)`` (SoT's argument
  order), ``ref`` and ``featureDes.errorIN`` (the desired posture) take SoT's
  roll-pitch-yaw configuration (size nv) or sotpy's (size nq).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
import pinocchio as pin

from ..dynamics import Dynamic
from ..dynamics.device import configurationFromRollPitchYaw
from ..dynamics.types import homogeneousToSE3
from ..errors import CommandError, EntityError
from ..graph import pool
from ..tasks import FeaturePoint6d, Flags
from ..tasks import meta_task as _native
from ..tasks.meta_task import setGain, toFlags
from ._errors import unsupported

__all__ = [
    "MetaTask6d",
    "MetaTaskCom",
    "MetaTaskKine6d",
    "MetaTaskKineCom",
    "MetaTaskKinePosture",
    "MetaTaskPosture",
    "generic6dReference",
    "goto6d",
    "gotoNd",
    "setGain",
    "toFlags",
]


def dynamicOf(dyn: Any, who: str) -> Dynamic:
    """The ``Dynamic`` entity behind ``dyn`` (itself, or the one a ``DynamicPinocchio``
    of the layer created with ``setModel``)."""
    real = getattr(dyn, "_sotpyDynamic", None)
    if real is not None:
        dyn = real()
    if not isinstance(dyn, Dynamic):
        raise EntityError(f"{who}: expected a Dynamic (a DynamicPinocchio), got {dyn!r}")
    return dyn


def generic6dReference(p: Any) -> pin.SE3:
    """SoT's target of ``gotoNd``: a 3-vector (the position, identity orientation), a
    4 x 4 homogeneous matrix (an array or a tuple of rows), a 6-vector (x, y, z, roll,
    pitch, yaw), or a ``pinocchio.SE3``; m, rad."""
    if isinstance(p, pin.SE3):
        return p.copy()
    a = np.asarray(p, dtype=float)
    if a.size == 3:
        return pin.SE3(np.eye(3), a.ravel())
    if a.shape == (4, 4):
        try:
            return homogeneousToSE3(a, "gotoNd")
        except ValueError as exc:
            raise CommandError(str(exc)) from None
    if a.shape == (6,):
        return pin.SE3(pin.rpy.rpyToMatrix(*a[3:]), a[:3])
    raise CommandError(
        "gotoNd: a target is a 3-vector (position, identity orientation), a 4 x 4 "
        f"homogeneous matrix, a 6-vector (x, y, z, roll, pitch, yaw) or a pinocchio.SE3; "
        f"got shape {a.shape}"
    )


class MetaTaskKine6d(_native.MetaTaskKine6d):
    """SoT's ``MetaTaskKine6d(name, dyn, opPoint, opPointRef='right-wrist')`` (see the
    module doc): ``feature``, ``featureDes``, ``task``, ``gain``, ``opPointModif``,
    ``opmodif``, ``keep()``, ``ref``, ``gotoNd``."""

    _entityAttributes = ("feature", "featureDes", "task", "gain", "opPointModif")

    def __init__(self, name: str, dyn: Any, opPoint: str, opPointRef: str = "right-wrist") -> None:
        dynamic = dynamicOf(dyn, f"MetaTaskKine6d({name!r})")
        refName = "feature" + name + "_ref"
        if pool.hasEntity(refName):
            raise EntityError(
                f"MetaTaskKine6d({name!r}): entity {refName} already exists: each meta-task "
                "needs its own; pick another name (or pool.remove it)"
            )
        frame = None if dynamic.hasSignal(opPoint) else opPointRef
        super().__init__(name, dynamic, opPoint, frame, featureClass=FeaturePoint6d)
        object.__setattr__(self, "_constructed", False)
        try:
            self.featureDes = FeaturePoint6d(refName)
            self.feature.setReference(self.featureDes)
            self.feature.frame("current")  # SoT's meta-task computes in the current frame
        except BaseException:
            names = [e.name for e in self.entities() if pool.hasEntity(e.name)]
            if names:
                pool.remove(*names)  # together: they use one another
            raise
        self._constructed = True

    def entities(self) -> list[Any]:
        return [getattr(self, a) for a in self._entityAttributes if hasattr(self, a)]

    @property
    def ref(self) -> pin.SE3:
        """The desired placement (``featureDes.position``)."""
        return self.featureDes.position.value

    @ref.setter
    def ref(self, M: Any) -> None:
        self.featureDes.position.value = M

    def gotoNd(
        self,
        position: Any,
        selec: str | Flags | Sequence[bool] | None = None,
        gain: float | Sequence[float] | None = None,
    ) -> None:
        """SoT's ``gotoNd``: the target of :func:`generic6dReference` in
        ``featureDes.position``, ``selec`` the rows (left to right), ``gain`` see
        ``setGain``."""
        M = generic6dReference(position)
        if selec is not None:
            self.feature.selec.value = selec if isinstance(selec, Flags) else Flags(selec)
        self.featureDes.position.value = M
        setGain(self.gain, gain)


#: sot-core's base class of the 6-D meta-tasks, and its only kinematic one here.
MetaTask6d = MetaTaskKine6d


class MetaTaskKineCom(_native.MetaTaskKineCom):
    """SoT's ``MetaTaskKineCom(dyn, name='com')``: ``feature``, ``featureDes``, ``task``,
    ``gain``, ``ref``, ``gotoNd``."""

    def __init__(self, dyn: Any, name: str = "com") -> None:
        super().__init__(dynamicOf(dyn, f"MetaTaskKineCom({name!r})"), name)

    def plugTask(self) -> None:
        """SoT's ``plugTask``: the feature is already in the task, the gain plugged."""


#: sot-core's ``MetaTaskCom`` (the CoM feature and gain; here with its task too).
MetaTaskCom = MetaTaskKineCom


class _PostureReference:
    """``featureDes`` of SoT's posture meta-task: its ``errorIN`` is the desired
    posture (sotpy's ``feature.posture``), ``errordotIN`` its velocity."""

    def __init__(self, meta: MetaTaskKinePosture) -> None:
        self.errorIN = meta.feature.posture
        self.errordotIN = meta.feature.postureDot
        self.name = meta.feature.name

    def __repr__(self) -> str:
        return f"<the desired posture of {self.name}: {self.errorIN.name}>"


class MetaTaskKinePosture(_native.MetaTaskKinePosture):
    """SoT's ``MetaTaskKinePosture(dyn, name='posture')`` over sotpy's
    ``FeaturePosture`` (see the module doc)."""

    def __init__(self, dyn: Any, name: str = "posture") -> None:
        super().__init__(dynamicOf(dyn, f"MetaTaskKinePosture({name!r})"), None, name)
        object.__setattr__(self, "_constructed", False)
        self.featureDes = _PostureReference(self)
        self._constructed = True

    def plugTask(self) -> None:
        """SoT's ``plugTask``: the feature is already in the task, the gain plugged."""

    def _configuration(self, q: Any) -> np.ndarray:
        try:
            return configurationFromRollPitchYaw(self.model, q)
        except CommandError as exc:
            raise CommandError(f"MetaTaskKinePosture({self.name!r}): {exc}") from None

    def gotoq(  # type: ignore[override]
        self,
        gain: float | Sequence[float] | None = None,
        qdes: Any = None,
        **joints: Any,
    ) -> None:
        """SoT's ``gotoq(gain, qdes, **kwargs)``: the desired posture ``qdes`` (size nq,
        or nv roll-pitch-yaw; None: the current one), ``gain`` see ``setGain``.

        Keyword arguments name joints of the model (``arm_right_4_joint=-1.2``, or
        ``[]`` to keep the value): only those joints are then controlled (SoT's rule for
        its limbs). SoT's HRP-2 limb names (``rarm=...``) are refused."""
        model = self.model
        limbs = [k for k in joints if not model.existJointName(k)]
        if limbs:
            raise unsupported(
                f"MetaTaskKinePosture.gotoq({', '.join(limbs)}=...): SoT's limb names are "
                "HRP-2's velocity ranges",
                "the joints by name, gotoq(gain, qdes, arm_right_4_joint=-1.2, ...)",
            )
        values = {k: v for k, v in joints.items() if not (isinstance(v, list) and v == [])}
        super().gotoq(qdes, gain, values)
        if joints:
            dofs: list[int] = []
            for k in joints:
                j = model.getJointId(k)
                dofs += range(model.idx_vs[j], model.idx_vs[j] + model.nvs[j])
            bits = [False] * model.nv
            for i in dofs:
                bits[i] = True
            self.feature.selec.value = Flags(bits)


#: sot-core's base class of the posture meta-task.
MetaTaskPosture = MetaTaskKinePosture


def gotoNd(
    task: Any,
    position: Any,
    selec: str | Flags | Sequence[bool] | None = None,
    gain: float | Sequence[float] | None = None,
    resetJacobian: bool = True,
) -> None:
    """SoT's ``gotoNd(task, position, selec, gain)``: ``task.gotoNd(position, selec,
    gain)`` (``resetJacobian``, for SoT's ``TaskPD``, has no effect)."""
    _native.gotoNd(task, position, selec, gain, resetJacobian)


def goto6d(
    task: Any,
    position: Any,
    gain: float | Sequence[float] | None = None,
    resetJacobian: bool = True,
) -> None:
    """SoT's ``goto6d``: ``gotoNd`` with the six rows selected."""
    gotoNd(task, position, "111111", gain, resetJacobian)
