"""Features, tasks and gains: what the solver stacks (SoT's ``sot/core`` features and
tasks), and meta-tasks that build them.

- features (:mod:`sotpy.tasks.features`): an error ``e``, its Jacobian ``J`` (LOCAL
  Jacobians of :mod:`sotpy.dynamics` in, ``de/dt = J v + errordot``), rows selected by
  SoT flags read left to right (``"111000"``: the first three rows);
- tasks (:mod:`sotpy.tasks.task`): features stacked, with ``task = -gain e`` (equality,
  ``J qdot = task``) or bounds ``lower <= J qdot <= upper`` (inequality): the contract a
  solver reads, written in ``docs/tasks.md``;
- collisions (:mod:`sotpy.tasks.collision`): ``FeatureCollision`` (the distances of
  the robot's and the obstacles' pairs under an influence distance, and their
  Jacobians) and ``TaskCollision`` (the velocity damper on them);
- :class:`GainAdaptive`: ``gain = a exp(-b |e|) + c``;
- meta-tasks (:mod:`sotpy.tasks.meta_task`): ``MetaTaskKine6d``, ``MetaTaskKineCom``,
  ``MetaTaskKinePosture``.
"""

from .collision import FeatureCollision, TaskCollision
from .features import (
    FLAGS,
    OPTICAL_FROM_XFORWARD,
    FeatureAbstract,
    FeatureGeneric,
    FeatureJointLimits,
    FeaturePoint6d,
    FeaturePose,
    FeaturePoseSE3,
    FeaturePosture,
    FeatureVisualPoint,
    Flags,
    interactionMatrix,
)
from .gain import GainAdaptive
from .joint_limits import TaskJointLimits
from .meta_task import (
    MetaTaskKine6d,
    MetaTaskKineCom,
    MetaTaskKinePosture,
    goto6d,
    gotoNd,
    setGain,
    toFlags,
)
from .task import Task, TaskAbstract, TaskInequality

__all__ = [
    "FLAGS",
    "OPTICAL_FROM_XFORWARD",
    "FeatureAbstract",
    "FeatureCollision",
    "FeatureGeneric",
    "FeatureJointLimits",
    "FeaturePoint6d",
    "FeaturePose",
    "FeaturePoseSE3",
    "FeaturePosture",
    "FeatureVisualPoint",
    "Flags",
    "GainAdaptive",
    "MetaTaskKine6d",
    "MetaTaskKineCom",
    "MetaTaskKinePosture",
    "Task",
    "TaskAbstract",
    "TaskCollision",
    "TaskInequality",
    "TaskJointLimits",
    "goto6d",
    "gotoNd",
    "interactionMatrix",
    "setGain",
    "toFlags",
]
