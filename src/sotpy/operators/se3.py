"""SE(3) operators: composing, inverting and converting placements.

SoT's ``MatrixHomogeneous`` is ``pinocchio.SE3`` here (the ``SE3`` signal type of
:mod:`sotpy.dynamics.types`). The classes keep SoT's names (``docs/operators.md``):

==============================  ============================  ============================
class                           signals                       sout
==============================  ============================  ============================
``Multiply_of_matrixHomo``      sin0..sin{n-1} -> sout        ``sin0 * sin1 * ...``
``Inverse_of_matrixHomo``       sin -> sout                   ``sin^-1``
``MatrixHomoToPoseUTheta``      sin -> sout (vector 6)        ``(p, log3(R))``
``PoseUThetaToMatrixHomo``      sin (vector 6) -> sout        ``(exp3(u), p)``
``MatrixHomoToPose``            sin -> sout (vector 3)        ``p``
``Compose_R_and_T``             sin1 (3x3), sin2 (3) -> sout  ``(R, p)``
``HomoToMatrix``                sin -> sout (matrix 4x4)      the homogeneous matrix
``MatrixToHomo``                sin (matrix 4x4) -> sout      the placement, checked
``Multiply_matrixHomo_vector``  sin1, sin2 (3 or 4) -> sout   ``M p`` (point) or ``[M] x``
==============================  ============================  ============================

A 4 x 4 homogeneous matrix enters an SE3 input through ``MatrixToHomo`` (plugged) or
as a constant (``sin.value = M``, an array or a tuple of rows as SoT writes it, or a
``pinocchio.SE3``), and leaves through ``HomoToMatrix``. Rotation
blocks given as matrices are checked (``R^T R = I``, ``det R = 1``, within 1e-5): a
wrong matrix raises instead of producing a placement that is not rigid.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pinocchio as pin

from ..dynamics.types import SE3
from ..errors import SignalTypeError
from ..graph import MATRIX, VECTOR, Entity, Input, Output
from ._util import check_matrix, check_rotation, check_vector, homogeneous_to_se3, received
from .vector import VariadicOp

__all__ = [
    "Compose_R_and_T",
    "HomoToMatrix",
    "Inverse_of_matrixHomo",
    "MatrixHomoToPose",
    "MatrixHomoToPoseUTheta",
    "MatrixToHomo",
    "Multiply_matrixHomo_vector",
    "Multiply_of_matrixHomo",
    "PoseUThetaToMatrixHomo",
]


def _check_se3(sig: Any, M: Any) -> pin.SE3:
    if not isinstance(M, pin.SE3):
        raise SignalTypeError(f"{sig.name}: expected a pinocchio.SE3, received {received(M)}")
    return M


class Multiply_of_matrixHomo(VariadicOp, Entity):
    """Compose placements: ``sout = sin0 * sin1 * ... * sin{n-1}`` (identity if n = 0).

    With ``sin0 = aMb`` and ``sin1 = bMc``, ``sout = aMc``. Two inputs by default;
    ``setSignalNumber(n)`` changes the number.
    """

    _inType = SE3
    _inDoc = "placement"

    def __init__(self, name: str) -> None:
        self._initVariadic()

    @Output(SE3, timeDependent=False, doc="the product of the inputs, left to right")
    def sout(self, *Ms: pin.SE3) -> pin.SE3:
        out = pin.SE3.Identity()
        for sig, M in zip(self._inputs(), Ms, strict=True):
            out = out * _check_se3(sig, M)
        return out


class Inverse_of_matrixHomo(Entity):
    """Inverse placement: ``sout = sin^-1`` (``aMb -> bMa``)."""

    sin = Input(SE3, doc="placement aMb (m)")

    @Output(SE3, deps=("sin",), doc="bMa = aMb^-1 (m)")
    def sout(self, M: pin.SE3) -> pin.SE3:
        return _check_se3(self.sin, M).inverse()


class MatrixHomoToPoseUTheta(Entity):
    """Placement to the 6-vector ``(p, u theta)``: translation (m) then the rotation
    vector ``log3(R)`` (rad, norm in ``[0, pi]``)."""

    sin = Input(SE3, doc="placement M = (R, p)")

    @Output(VECTOR, deps=("sin",), doc="(p, log3(R)): m, rad")
    def sout(self, M: pin.SE3) -> np.ndarray:
        _check_se3(self.sin, M)
        return np.concatenate([M.translation, pin.log3(M.rotation)])


class PoseUThetaToMatrixHomo(Entity):
    """The 6-vector ``(p, u theta)`` to the placement ``(exp3(u theta), p)``."""

    sin = Input(VECTOR, doc="(p, u theta): translation (m), rotation vector (rad)")

    @Output(SE3, deps=("sin",), doc="M = (exp3(u theta), p)")
    def sout(self, x: np.ndarray) -> pin.SE3:
        check_vector(self.sin, x, 6, "translation then rotation vector")
        return pin.SE3(pin.exp3(x[3:]), x[:3].copy())


class MatrixHomoToPose(Entity):
    """The translation of a placement: ``sout = p`` (m)."""

    sin = Input(SE3, doc="placement M = (R, p)")

    @Output(VECTOR, deps=("sin",), doc="p (m)")
    def sout(self, M: pin.SE3) -> np.ndarray:
        return _check_se3(self.sin, M).translation.copy()


class Compose_R_and_T(Entity):
    """Placement from a rotation matrix and a translation: ``sout = (sin1, sin2)``.

    ``sin1`` must be a rotation (``R^T R = I``, ``det R = 1`` within 1e-5; SoT did not
    check); it is used as given.
    """

    sin1 = Input(MATRIX, doc="rotation R (3 x 3)")
    sin2 = Input(VECTOR, doc="translation p (3, m)")

    @Output(SE3, deps=("sin1", "sin2"), doc="M = (R, p)")
    def sout(self, R: np.ndarray, p: np.ndarray) -> pin.SE3:
        check_matrix(self.sin1, R, (3, 3), "a rotation")
        check_rotation(self.sin1, R)
        check_vector(self.sin2, p, 3, "a translation")
        return pin.SE3(R.copy(), p.copy())


class HomoToMatrix(Entity):
    """A placement as its 4 x 4 homogeneous matrix ``[[R, p], [0, 1]]``."""

    sin = Input(SE3, doc="placement M = (R, p)")

    @Output(MATRIX, deps=("sin",), doc="the 4 x 4 homogeneous matrix")
    def sout(self, M: pin.SE3) -> np.ndarray:
        return _check_se3(self.sin, M).homogeneous.copy()


class MatrixToHomo(Entity):
    """A 4 x 4 homogeneous matrix as a placement (plug a matrix output into an SE3 input).

    The last row must be ``(0, 0, 0, 1)`` and the rotation block a rotation within
    1e-5; the block is then projected on SO(3) (nearest rotation).
    """

    sin = Input(MATRIX, doc="4 x 4 homogeneous matrix")

    @Output(SE3, deps=("sin",), doc="the placement")
    def sout(self, A: np.ndarray) -> pin.SE3:
        check_matrix(self.sin, A, (4, 4), "a homogeneous matrix")
        try:
            return homogeneous_to_se3(A, self.sin.name)
        except ValueError as exc:
            raise SignalTypeError(str(exc)) from None


class Multiply_matrixHomo_vector(Entity):
    """Placement times vector.

    ``sin2`` of size 3 is a point: ``sout = R p + t`` (``M.act(p)``); of size 4 it is
    homogeneous coordinates: ``sout = [M] x`` (SoT's only form).
    """

    sin1 = Input(SE3, doc="placement aMb")
    sin2 = Input(VECTOR, doc="point in b (3, m) or homogeneous coordinates (4)")

    @Output(VECTOR, deps=("sin1", "sin2"), doc="the point in a (3) or [M] x (4)")
    def sout(self, M: pin.SE3, x: np.ndarray) -> np.ndarray:
        _check_se3(self.sin1, M)
        check_vector(self.sin2, x)
        if x.shape[0] == 3:
            return M.act(x)
        if x.shape[0] == 4:
            return M.homogeneous @ x
        raise SignalTypeError(
            f"{self.sin2.name}: expected a point (size 3) or homogeneous coordinates "
            f"(size 4), received size {x.shape[0]}"
        )
