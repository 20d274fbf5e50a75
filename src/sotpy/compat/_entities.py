"""The entity classes ``sotpy run`` serves under sot-core's module names.

Most are sotpy's own classes (their SoT names are sotpy's names); a few take SoT's
constructor arguments or units:

- ``TracerRealTime``: a :class:`~sotpy.graph.Tracer` whose ``setBufferSize`` takes
  SoT's size in bytes per signal;
- ``FeaturePosture(name, model)`` and ``FeatureJointLimits(name, model)`` need the
  robot's model, which SoT's took from signals: without it they raise
  :class:`~sotpy.compat.UnsupportedFeature` naming what to pass;
- ``SolverKine`` (sot-dyninv's hierarchical solver with inequalities) is sotpy's
  :class:`~sotpy.solvers.SOT`, which solves inequality tasks at any level.
"""

from __future__ import annotations

from typing import Any

from ..dynamics import Device, RobotSimu
from ..errors import SotpyError
from ..graph import Tracer, command
from ..operators import (
    Add_of_double,
    Add_of_matrix,
    Add_of_vector,
    Component_of_vector,
    Compose_R_and_T,
    CubicInterpolation,
    CubicInterpolationSE3,
    Derivator_of_double,
    Derivator_of_Matrix,
    Derivator_of_Vector,
    HomoToMatrix,
    Inverse_of_matrixHomo,
    JointLimitator,
    Latch,
    MatrixConstant,
    MatrixHomoToPose,
    MatrixHomoToPoseUTheta,
    MatrixToHomo,
    Multiply_double_vector,
    Multiply_matrix_vector,
    Multiply_matrixHomo_vector,
    Multiply_of_double,
    Multiply_of_matrixHomo,
    OpPointModifier,
    PoseUThetaToMatrixHomo,
    Selec_of_vector,
    Seqplay,
    Stack_of_vector,
    Substract_of_double,
    Substract_of_matrix,
    Substract_of_vector,
    SwitchBoolean,
    SwitchMatrixHomogeneous,
    SwitchVector,
    VectorConstant,
)
from ..solvers import SOT
from ..tasks import (
    FeatureGeneric,
    FeaturePoint6d,
    FeatureVisualPoint,
    GainAdaptive,
    Task,
    TaskInequality,
    TaskJointLimits,
)
from ..tasks import FeatureJointLimits as _FeatureJointLimits
from ..tasks import FeaturePosture as _FeaturePosture
from ._errors import unsupported

__all__ = [
    "SOT",
    "Add_of_double",
    "Add_of_matrix",
    "Add_of_vector",
    "Component_of_vector",
    "Compose_R_and_T",
    "CubicInterpolation",
    "CubicInterpolationSE3",
    "Derivator_of_Matrix",
    "Derivator_of_Vector",
    "Derivator_of_double",
    "Device",
    "FeatureGeneric",
    "FeatureJointLimits",
    "FeaturePoint6d",
    "FeaturePosture",
    "FeatureVisualPoint",
    "GainAdaptive",
    "HomoToMatrix",
    "Inverse_of_matrixHomo",
    "JointLimitator",
    "Latch",
    "MatrixConstant",
    "MatrixHomoToPose",
    "MatrixHomoToPoseUTheta",
    "MatrixToHomo",
    "Multiply_double_vector",
    "Multiply_matrixHomo_vector",
    "Multiply_matrix_vector",
    "Multiply_of_double",
    "Multiply_of_matrixHomo",
    "OpPointModifier",
    "PoseUThetaToMatrixHomo",
    "RobotSimu",
    "Selec_of_vector",
    "Seqplay",
    "SolverKine",
    "Stack_of_vector",
    "Substract_of_double",
    "Substract_of_matrix",
    "Substract_of_vector",
    "SwitchBoolean",
    "SwitchMatrixHomogeneous",
    "SwitchVector",
    "Task",
    "TaskInequality",
    "TaskJointLimits",
    "Tracer",
    "TracerRealTime",
    "VectorConstant",
]

#: SoT's default buffer of a TracerRealTime, in bytes per traced signal.
TRACER_REAL_TIME_BUFFER = 1 << 20


class TracerRealTime(Tracer):
    """SoT's ``TracerRealTime``: a :class:`~sotpy.graph.Tracer` (rows in memory,
    written to the files of ``open`` by ``dump`` and ``close``) whose buffer size is
    SoT's, in bytes per traced signal (default 1 MiB): it keeps
    ``bytes // (8 * width)`` rows, ``width`` the number of values of the widest traced
    signal (sotpy stores float64 values; SoT stored text)."""

    className = "TracerRealTime"

    def __init__(self, name: str, bufferSize: int = TRACER_REAL_TIME_BUFFER) -> None:
        super().__init__(name, bufferSize)

    @command
    def setBufferSize(self, size: int) -> None:
        """Set the buffer size, in bytes per traced signal (SoT's unit, >= 8)."""
        if size < 8:
            raise SotpyError(
                f"{self.className}({self.name}).setBufferSize: expected a size in bytes per "
                f"signal >= 8, got {size}"
            )
        if getattr(self, "_count", 0):
            raise SotpyError(
                f"{self.className}({self.name}).setBufferSize: empty() the recorded rows first"
            )
        self._bytes = size
        self._size = size // 8  # the rows are fixed at the first record
        self._buffers = None

    @command
    def getBufferSize(self) -> int:
        """The buffer size, in bytes per traced signal."""
        return self._bytes

    def _allocate(self, values: tuple[Any, ...]) -> None:
        widths = [
            self._width(label, sig, v).size
            for (label, sig), v in zip(self._columns, values, strict=True)
        ]
        self._size = max(1, self._bytes // (8 * max(widths, default=1)))
        super()._allocate(values)


class SolverKine(SOT):
    """sot-dyninv's ``SolverKine`` (a hierarchy of equality and inequality tasks):
    sotpy's :class:`~sotpy.solvers.SOT`, which solves both at any priority level."""

    className = "SolverKine"


def FeaturePosture(name: str, model: Any = None) -> _FeaturePosture:
    """SoT's ``FeaturePosture(name)``: sotpy's needs the model,
    ``FeaturePosture(name, robot.dynamic.model)``."""
    if model is None:
        raise unsupported(
            f"FeaturePosture({name!r}) without a model (SoT's reads the posture's layout "
            "from its signals)",
            "FeaturePosture(name, robot.dynamic.model), or MetaTaskKinePosture(robot.dynamic)",
        )
    return _FeaturePosture(name, model)


def FeatureJointLimits(name: str, model: Any = None) -> _FeatureJointLimits:
    """SoT's ``FeatureJointLimits(name)``: sotpy's needs the model,
    ``FeatureJointLimits(name, robot.dynamic.model)``."""
    if model is None:
        raise unsupported(
            f"FeatureJointLimits({name!r}) without a model",
            "FeatureJointLimits(name, robot.dynamic.model), or TaskJointLimits(name)",
        )
    return _FeatureJointLimits(name, model)
