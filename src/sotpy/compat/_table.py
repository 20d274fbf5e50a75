"""The sot-core modules that only hold entity classes, built from sotpy's.

``MODULES[name] = (source, names)``: under ``sotpy run``, ``import name`` gives a module
whose attributes ``names`` are those of the sotpy module ``source``. The modules with
functions and classes of their own (``matrix_util``, the meta-tasks, the robot classes)
are files of :mod:`sotpy.compat.dynamic_graph`.
"""

from __future__ import annotations

__all__ = ["MODULES", "OPERATORS"]

_ENT = "sotpy.compat._entities"

#: sot-core's ``operator`` module: its entity classes sotpy has.
OPERATORS = [
    "Selec_of_vector",
    "Component_of_vector",
    "Stack_of_vector",
    "Add_of_vector",
    "Add_of_double",
    "Add_of_matrix",
    "Substract_of_vector",
    "Substract_of_double",
    "Substract_of_matrix",
    "Multiply_matrix_vector",
    "Multiply_double_vector",
    "Multiply_of_double",
    "Multiply_of_matrixHomo",
    "Multiply_matrixHomo_vector",
    "Inverse_of_matrixHomo",
    "MatrixHomoToPoseUTheta",
    "PoseUThetaToMatrixHomo",
    "MatrixHomoToPose",
    "Compose_R_and_T",
    "HomoToMatrix",
    "MatrixToHomo",
]

_DERIVATORS = ["Derivator_of_Vector", "Derivator_of_double", "Derivator_of_Matrix"]
_SWITCHES = ["SwitchVector", "SwitchBoolean", "SwitchMatrixHomogeneous"]

MODULES: dict[str, tuple[str, list[str]]] = {
    "dynamic_graph.tracer": (_ENT, ["Tracer"]),
    "dynamic_graph.tracer_real_time": (_ENT, ["TracerRealTime"]),
    "dynamic_graph.tutorial": ("sotpy.tutorial", ["InvertedPendulum", "FeedbackController"]),
    "dynamic_graph.sot.core.sot": (_ENT, ["SOT", "Task"]),
    "dynamic_graph.sot.core.task": (_ENT, ["Task"]),
    "dynamic_graph.sot.core.gain_adaptive": (_ENT, ["GainAdaptive"]),
    "dynamic_graph.sot.core.feature_point6d": (_ENT, ["FeaturePoint6d"]),
    "dynamic_graph.sot.core.feature_generic": (_ENT, ["FeatureGeneric"]),
    "dynamic_graph.sot.core.feature_posture": (_ENT, ["FeaturePosture"]),
    "dynamic_graph.sot.core.feature_joint_limits": (_ENT, ["FeatureJointLimits"]),
    "dynamic_graph.sot.core.feature_visual_point": (_ENT, ["FeatureVisualPoint"]),
    "dynamic_graph.sot.core.op_point_modifier": (_ENT, ["OpPointModifier"]),
    "dynamic_graph.sot.core.derivator": (_ENT, _DERIVATORS),
    "dynamic_graph.sot.core.operator": (_ENT, OPERATORS),
    "dynamic_graph.sot.core.vector_constant": (_ENT, ["VectorConstant"]),
    "dynamic_graph.sot.core.matrix_constant": (_ENT, ["MatrixConstant"]),
    "dynamic_graph.sot.core.joint_limitator": (_ENT, ["JointLimitator"]),
    "dynamic_graph.sot.core.robot_simu": (_ENT, ["RobotSimu"]),
    "dynamic_graph.sot.core.device": (_ENT, ["Device"]),
    "dynamic_graph.sot.core.latch": (_ENT, ["Latch"]),
    "dynamic_graph.sot.core.switch": (_ENT, _SWITCHES),
    "dynamic_graph.sot.core.math_small_entities": (
        _ENT,
        [*OPERATORS, *_DERIVATORS, *_SWITCHES, "VectorConstant", "MatrixConstant", "Latch"],
    ),
    "dynamic_graph.sot.tools": (_ENT, ["Seqplay", "CubicInterpolation", "CubicInterpolationSE3"]),
    "dynamic_graph.sot.dyninv": (_ENT, ["SolverKine", "TaskInequality", "TaskJointLimits"]),
}
