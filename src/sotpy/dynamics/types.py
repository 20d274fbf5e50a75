"""Signal types of the robotics layers."""

from __future__ import annotations

from typing import Any

import numpy as np
import pinocchio as pin

from ..graph.types import object_type

__all__ = ["ROTATION_TOLERANCE", "SE3", "homogeneousToSE3"]

#: Largest ``max |R^T R - I|`` and ``|det R - 1|`` accepted for a rotation matrix
#: written by a user or a file (6 significant digits give errors near 1e-6).
ROTATION_TOLERANCE = 1e-5


def homogeneousToSE3(M: Any, where: str = "", tolerance: float = ROTATION_TOLERANCE) -> pin.SE3:
    """The ``pinocchio.SE3`` of a 4 x 4 homogeneous matrix (an array, a numpy matrix or
    a tuple of 4 rows, as SoT scripts write them), checked.

    The last row must be ``(0, 0, 0, 1)`` and the top-left block a rotation, within
    ``tolerance``; the rotation is then projected on SO(3) (the nearest rotation, by
    SVD), so that a matrix written with a few digits gives an exact rotation.

    Raises:
        ValueError: the matrix is not homogeneous; the message starts with ``where``.
    """
    head = f"{where}: " if where else ""
    M = np.asarray(M, dtype=float)
    if M.shape != (4, 4):
        raise ValueError(f"{head}expected a 4 x 4 homogeneous matrix, got shape {M.shape}")
    if not np.isfinite(M).all():
        raise ValueError(f"{head}the homogeneous matrix has non-finite entries")
    if np.abs(M[3] - (0.0, 0.0, 0.0, 1.0)).max() > tolerance:
        raise ValueError(
            f"{head}the last row of a homogeneous matrix must be (0, 0, 0, 1), got {M[3].tolist()}"
        )
    R = M[:3, :3]
    err = float(np.abs(R.T @ R - np.eye(3)).max())
    det = float(np.linalg.det(R))
    if not (err <= tolerance and abs(det - 1.0) <= tolerance):
        raise ValueError(
            f"{head}the top-left 3 x 3 block is not a rotation (max|R^T R - I| = "
            f"{err:.3g}, det R = {det:.6g}; tolerance {tolerance:g})"
        )
    U, _, Vt = np.linalg.svd(R)
    return pin.SE3(U @ Vt, M[:3, 3].copy())


def _checkPlacement(M: pin.SE3, tolerance: float = ROTATION_TOLERANCE) -> None:
    """Refuse (ValueError) a ``pinocchio.SE3`` whose rotation is not one, within
    ``tolerance``, or with non-finite entries: ``pin.SE3(5 * I, p)`` constructs."""
    R, p = M.rotation, M.translation
    if not (np.isfinite(R).all() and np.isfinite(p).all()):
        raise ValueError("the placement has non-finite entries")
    err = float(np.abs(R.T @ R - np.eye(3)).max())
    det = float(np.linalg.det(R))
    if not (err <= tolerance and abs(det - 1.0) <= tolerance):
        raise ValueError(
            f"the rotation of the placement is not a rotation (max|R^T R - I| = {err:.3g}, "
            f"det R = {det:.6g}; tolerance {tolerance:g})"
        )


def _toSE3(v: Any) -> pin.SE3:
    """A placement written to an SE3 signal: a ``pinocchio.SE3`` (copied), or a 4 x 4
    homogeneous matrix as SoT writes it (an array, a numpy matrix, a tuple of rows);
    either checked to hold a rotation."""
    if isinstance(v, pin.SE3):
        _checkPlacement(v)
        return v.copy()
    if isinstance(v, (str, bytes)) or not hasattr(v, "__len__"):
        raise TypeError(
            f"expected a pinocchio.SE3 or a 4 x 4 homogeneous matrix, got {type(v).__name__}"
        )
    try:
        return homogeneousToSE3(v)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"expected a pinocchio.SE3 or a 4 x 4 homogeneous matrix: {exc}") from None


#: ``pinocchio.SE3`` placements; traced as the 16 entries of the homogeneous matrix
#: (row-major). A constant may be written as a ``pinocchio.SE3`` (its rotation checked to
#: be one) or, as SoT scripts do, as a 4 x 4 homogeneous matrix (array, numpy matrix or
#: tuple of 4 rows): it is checked (:func:`homogeneousToSE3`) and stored as a
#: ``pinocchio.SE3``.
SE3 = object_type("SE3", pin.SE3, to_array=lambda M: M.homogeneous.ravel())
SE3.convert = _toSE3
