"""SoT's operator entities, to build graphs by hand, and trajectory sources.

Everything a script needs to wire signals together::

    from sotpy.operators import Selec_of_vector, Add_of_vector, Multiply_of_matrixHomo

Class, signal and command names are sot-core's (``src/matrix/operator.cpp``,
``derivator.hh``, ``switch.hh``, ``latch.hh``, ``integrator.hh``, ``op-point-modifier``,
``joint-limitator``) and sot-tools'
(``CubicInterpolationSE3``, ``Seqplay``): ``sin``/``sin1``/``sin2``/``sin0..sin{n-1}``
in, ``sout`` out, ``selec(imin, imax)``, ``setSignalNumber(n)``... ``docs/operators.md``
is the reference: each entity's signals, commands, formula and units, and where sotpy
differs from the C++ original.

Placements (SoT's ``MatrixHomogeneous``) are ``pinocchio.SE3`` values on signals of
type ``SE3``. The one-tick delays are the graph core's, re-exported here.
"""

from .op_point import JointLimitator, OpPointModifier
from .se3 import (
    Compose_R_and_T,
    HomoToMatrix,
    Inverse_of_matrixHomo,
    MatrixHomoToPose,
    MatrixHomoToPoseUTheta,
    MatrixToHomo,
    Multiply_matrixHomo_vector,
    Multiply_of_matrixHomo,
    PoseUThetaToMatrixHomo,
)
from .selector import Selector
from .signal_tools import (
    Delay_of_double,
    Delay_of_matrix,
    Delay_of_vector,
    Derivator_of_double,
    Derivator_of_Matrix,
    Derivator_of_Vector,
    Integrator,
    Latch,
    SwitchBoolean,
    SwitchMatrixHomogeneous,
    SwitchVector,
)
from .trajectory import CubicInterpolation, CubicInterpolationSE3, Seqplay, cubic_profile
from .vector import (
    Add_of_double,
    Add_of_matrix,
    Add_of_vector,
    Component_of_vector,
    MatrixConstant,
    Multiply_double_vector,
    Multiply_matrix_vector,
    Multiply_of_double,
    Selec_of_vector,
    Stack_of_vector,
    Substract_of_double,
    Substract_of_matrix,
    Substract_of_vector,
    VariadicOp,
    VectorConstant,
)

__all__ = [
    "Add_of_double",
    "Add_of_matrix",
    "Add_of_vector",
    "Component_of_vector",
    "Compose_R_and_T",
    "CubicInterpolation",
    "CubicInterpolationSE3",
    "Delay_of_double",
    "Delay_of_matrix",
    "Delay_of_vector",
    "Derivator_of_Matrix",
    "Derivator_of_Vector",
    "Derivator_of_double",
    "HomoToMatrix",
    "Integrator",
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
    "Selec_of_vector",
    "Selector",
    "Seqplay",
    "Stack_of_vector",
    "Substract_of_double",
    "Substract_of_matrix",
    "Substract_of_vector",
    "SwitchBoolean",
    "SwitchMatrixHomogeneous",
    "SwitchVector",
    "VariadicOp",
    "VectorConstant",
    "cubic_profile",
]
