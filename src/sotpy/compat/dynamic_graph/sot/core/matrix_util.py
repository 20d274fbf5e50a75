"""sot-core's ``matrix_util``: small conversions between tuples, numpy arrays,
homogeneous matrices and roll-pitch-yaw angles, with sot-core's names and results.

Conventions (sot-core's): a homogeneous matrix is 4 x 4 (a tuple of rows, a numpy array
or a ``pinocchio.SE3``, accepted everywhere a matrix is read); roll-pitch-yaw ``(r, p,
y)`` are the angles of ``R = Rz(y) Ry(p) Rx(r)`` (rad); a quaternion is ``[qx, qy, qz,
qw]``. ``matrixToRPY`` and ``RPYToMatrix`` are inverse of each other, with the pose
``(x, y, z, roll, pitch, yaw)`` (m, rad). Note sot-core's ``tr2rpy`` returns the angles
in the order ``[yaw, pitch, roll]`` (its variables are named r, p, y but hold the
rotations about z, y and x); so does this one, for the scripts that use it.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pinocchio as pin

__all__ = [
    "RPYToMatrix",
    "distVector",
    "generateOrthonormalM",
    "matrixToRPY",
    "matrixToTuple",
    "quaternionToMatrix",
    "rotate",
    "rpy2tr",
    "tr2rpy",
    "vectorToTuple",
]


def _array(M: Any) -> np.ndarray:
    """``M`` as a float array (a ``pinocchio.SE3`` as its 4 x 4 homogeneous matrix)."""
    if isinstance(M, pin.SE3):
        return M.homogeneous
    return np.asarray(M, dtype=float)


def matrixToTuple(M: Any) -> tuple[tuple[float, ...], ...]:
    """A matrix (numpy array or matrix, ``pinocchio.SE3``, nested sequence) as a tuple
    of its rows, each a tuple of floats."""
    A = np.atleast_2d(_array(M))
    return tuple(tuple(float(x) for x in row) for row in A)


def vectorToTuple(M: Any) -> tuple[float, ...]:
    """A vector as a tuple of floats: a 1-D array, a row (1 x n) or a column (n x 1)."""
    A = np.asarray(M, dtype=float)
    if A.ndim == 1:
        return tuple(float(x) for x in A)
    if A.shape[0] == 1:
        return tuple(float(x) for x in A[0])
    return tuple(float(x) for x in A[:, 0])


def rotate(axis: str, ang: float) -> tuple[tuple[float, ...], ...]:
    """The 4 x 4 homogeneous matrix of a rotation of ``ang`` (rad) about ``axis``
    ('x', 'y' or 'z'), as a tuple of rows."""
    c, s = math.cos(ang), math.sin(ang)
    R = {
        "x": ((1.0, 0.0, 0.0), (0.0, c, -s), (0.0, s, c)),
        "y": ((c, 0.0, s), (0.0, 1.0, 0.0), (-s, 0.0, c)),
        "z": ((c, -s, 0.0), (s, c, 0.0), (0.0, 0.0, 1.0)),
    }.get(axis)
    if R is None:
        raise ValueError(f"rotate: the axis must be 'x', 'y' or 'z', got {axis!r}")
    return (*((*row, 0.0) for row in R), (0.0, 0.0, 0.0, 1.0))


def rpy2tr(r: float, p: float, y: float) -> tuple[tuple[float, ...], ...]:
    """The homogeneous matrix of ``Rz(y) Ry(p) Rx(r)`` (rad), as a tuple of rows."""
    M = np.asarray(rotate("z", y)) @ np.asarray(rotate("y", p)) @ np.asarray(rotate("x", r))
    return matrixToTuple(M)


def tr2rpy(M: Any) -> list[float]:
    """The angles of the rotation of ``M`` (3 x 3 or 4 x 4) in sot-core's order
    ``[yaw, pitch, roll]`` (rad), pitch in [-pi/2, pi/2]. At pitch = +-pi/2 (within
    0.001 rad) the first angle is 0 and the last one takes the whole rotation about z."""
    A = _array(M)
    pitch = math.atan2(-A[2, 0], math.hypot(A[2, 1], A[2, 2]))
    if abs(pitch - math.pi / 2) < 0.001:
        return [0.0, float(pitch), float(math.atan2(A[0, 1], A[1, 1]))]
    if abs(pitch + math.pi / 2) < 0.001:
        return [0.0, float(pitch), float(-math.atan2(A[0, 1], A[1, 1]))]
    return [
        float(math.atan2(A[1, 0], A[0, 0])),
        float(pitch),
        float(math.atan2(A[2, 1], A[2, 2])),
    ]


def matrixToRPY(M: Any) -> list[float]:
    """A 4 x 4 homogeneous matrix as the pose ``[x, y, z, roll, pitch, yaw]`` (m, rad)."""
    A = _array(M)
    yaw, pitch, roll = tr2rpy(A)
    return [float(A[0, 3]), float(A[1, 3]), float(A[2, 3]), roll, pitch, yaw]


def RPYToMatrix(pr: Any) -> np.ndarray:
    """The pose ``(x, y, z, roll, pitch, yaw)`` (m, rad) as a 4 x 4 homogeneous array."""
    pr = [float(v) for v in pr]
    M = np.array(rpy2tr(pr[3], pr[4], pr[5]))
    M[:3, 3] = pr[:3]
    return M


def distVector(M2: Any, M1: Any) -> list[float]:
    """The translation of ``M1`` minus that of ``M2`` (two homogeneous matrices)."""
    a, b = _array(M1), _array(M2)
    return [float(a[i, 3] - b[i, 3]) for i in range(3)]


def generateOrthonormalM(v1: Any) -> tuple[tuple[float, ...], ...]:
    """A rotation matrix (tuple of rows) whose first column is ``e1 = v1 / |v1|``: the
    second column is ``e1 x a / |e1 x a|``, ``a`` the coordinate axis least aligned with
    ``e1`` (``|e1 x a| >= sqrt(2/3)``), the third ``e1 x e2``: orthonormal to rounding,
    determinant +1. sot-core completes the basis from random vectors instead; any
    completion is a valid answer, this one is the same at every call. ``v1``: a finite,
    nonzero 3-vector (``ValueError`` otherwise)."""
    e1 = np.asarray(v1, dtype=float).ravel()
    n = float(np.linalg.norm(e1)) if e1.shape == (3,) else 0.0
    if not (math.isfinite(n) and n > 0.0):
        raise ValueError(f"generateOrthonormalM: v1 must be a finite nonzero 3-vector, got {v1!r}")
    e1 = e1 / n
    a = np.zeros(3)
    a[int(np.argmin(np.abs(e1)))] = 1.0
    e2 = np.cross(e1, a)
    e2 /= np.linalg.norm(e2)
    return matrixToTuple(np.column_stack((e1, e2, np.cross(e1, e2))))


def quaternionToMatrix(q: Any) -> list[list[float]]:
    """The rotation matrix (a list of rows) of the unit quaternion ``[qx, qy, qz, qw]``."""
    qx, qy, qz, qw = (float(v) for v in q)
    R = pin.Quaternion(qw, qx, qy, qz).toRotationMatrix()
    return [[float(x) for x in row] for row in R]
