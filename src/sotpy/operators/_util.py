"""Checks shared by the operator entities: shapes, rotations, homogeneous matrices.

Every check raises an exception from :mod:`sotpy.errors` whose message names the signal
(SoT's ``Class(entity)::input(type)::name``) and what was expected, so that a wrong
size in a running graph is reported where it enters, never broadcast by numpy into a
silently wrong value.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np
import pinocchio as pin

from ..dynamics.types import ROTATION_TOLERANCE, homogeneousToSE3
from ..errors import CommandError, SignalTypeError
from ..graph.signal import InputSignal, Signal

__all__ = [
    "ROTATION_TOLERANCE",
    "SelectorInput",
    "check_index_range",
    "check_matrix",
    "check_rotation",
    "check_vector",
    "homogeneous_to_se3",
    "received",
    "who",
]


def who(entity: Any, command: str) -> str:
    """``Class(name).command``, the prefix of a command's error message."""
    return f"{entity.className}({entity.name}).{command}"


def received(value: Any) -> str:
    """A short description of ``value`` for an error message."""
    shape = getattr(value, "shape", None)
    if shape is not None:
        return f"shape {shape}" if len(shape) != 1 else f"size {shape[0]}"
    return f"a {type(value).__name__}"


def check_vector(sig: Signal, value: Any, size: int | None = None, what: str = "") -> np.ndarray:
    """``value`` as a 1-D array (of ``size`` entries if given), or SignalTypeError.

    ``what`` says where the expected size comes from (``"the size of sin0"``).
    """
    if not isinstance(value, np.ndarray) or value.ndim != 1:
        raise SignalTypeError(f"{sig.name}: expected a vector, received {received(value)}")
    if size is not None and value.shape[0] != size:
        because = f" ({what})" if what else ""
        raise SignalTypeError(
            f"{sig.name}: expected a vector of size {size}{because}, received size {value.shape[0]}"
        )
    return value


def check_matrix(
    sig: Signal, value: Any, shape: tuple[int | None, int | None] | None = None, what: str = ""
) -> np.ndarray:
    """``value`` as a 2-D array (of ``shape``, ``None`` meaning any, if given)."""
    if not isinstance(value, np.ndarray) or value.ndim != 2:
        raise SignalTypeError(f"{sig.name}: expected a matrix, received {received(value)}")
    if shape is not None and any(
        n is not None and n != m for n, m in zip(shape, value.shape, strict=True)
    ):
        text = " x ".join("n" if n is None else str(n) for n in shape)
        because = f" ({what})" if what else ""
        raise SignalTypeError(
            f"{sig.name}: expected a {text} matrix{because}, received shape {value.shape}"
        )
    return value


def check_rotation(sig: Signal, R: np.ndarray, tolerance: float = ROTATION_TOLERANCE) -> None:
    """Raise SignalTypeError unless ``R`` (3 x 3) is a rotation: ``R^T R = I``,
    ``det R = 1``, within ``tolerance``."""
    err = float(np.abs(R.T @ R - np.eye(3)).max())
    det = float(np.linalg.det(R))
    if not (err <= tolerance and abs(det - 1.0) <= tolerance):
        raise SignalTypeError(
            f"{sig.name}: expected a rotation matrix (R^T R = I and det R = 1 within "
            f"{tolerance:g}), got max|R^T R - I| = {err:.3g} and det R = {det:.6g}"
        )


def homogeneous_to_se3(M: np.ndarray, where: str, tolerance: float = ROTATION_TOLERANCE) -> pin.SE3:
    """The ``pinocchio.SE3`` of a 4 x 4 homogeneous matrix, checked (see
    :func:`sotpy.dynamics.types.homogeneousToSE3`); ``where`` starts the error message
    (a signal name, or ``file, line n``).

    Raises:
        ValueError: the matrix is not homogeneous (callers wrap it in their error).
    """
    return homogeneousToSE3(M, where, tolerance)


def check_index_range(entity: Any, command: str, imin: int, imax: int) -> None:
    """CommandError unless ``0 <= imin <= imax`` (a half-open range ``[imin, imax)``)."""
    if imin < 0 or imax < imin:
        raise CommandError(
            f"{who(entity, command)}: expected a half-open range [imin, imax) with "
            f"0 <= imin <= imax, got imin = {imin}, imax = {imax}"
        )


class SelectorInput(InputSignal):
    """An input that tells its entity when it becomes set or unset.

    ``Switch`` reads ``selection`` if it is set and ``boolSelection`` otherwise (SoT's
    rule), so its output depends on one or the other: ``onChange`` (the entity's method)
    is called whenever the input is plugged, unplugged or gets its first constant, and
    updates the output's dependencies (through the core's
    :meth:`InputSignal.modeChanged` hook).
    """

    __slots__ = ("_onChange",)

    def __init__(
        self,
        entity: Any,
        shortName: str,
        type: Any,
        onChange: Callable[[SelectorInput], None],
        doc: str = "",
    ) -> None:
        super().__init__(entity, shortName, type, None, doc)
        self._onChange = onChange

    def modeChanged(self) -> None:
        self._onChange(self)
