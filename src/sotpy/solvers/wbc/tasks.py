r"""Tasks: weighted least-squares rows over ``chi = (a, tau, f)``.

A task gives ``E`` (m x n) and ``f`` (m) and contributes, in its level,

.. math:: \| W^{1/2} (E \chi - f) \|^2, \qquad
          W = \mathrm{diag}(r \; w \; w_i \; s_i)

with ``w`` the task weight (>= 0), ``w_i`` the per-row weights (>= 0, default 1),
``s_i`` the selection (0 or 1 per row: a 0 drops the row) and ``r`` the activation ramp
(see :mod:`.activation`). ``desired`` is the target (size m, set by the user or a servo).

=========================  ====  =========================================================
task                       m     rows
=========================  ====  =========================================================
CartesianAccelerationTask  6     ``J a + Jdot v = a_des``: ``J`` the LOCAL_WORLD_ALIGNED
                                 frame Jacobian, ``a_des`` = (linear acceleration of the
                                 frame origin (m/s^2), angular acceleration (rad/s^2)),
                                 world axes; ``Jdot v`` the classical drift
JointAccelerationTask      na    ``S a = a_des`` (actuated joints, rad/s^2)
CoMAccelerationTask        3     ``Jcom a + dJcom v = a_des`` (m/s^2, world)
WrenchTask                 6/3   ``f_c = w_des`` (contact wrench, LOCAL, N and N m)
TorqueTask                 na    ``tau = tau_des`` (N m)
RegularisationTask         n     ``chi = 0`` (global regularisation, default weight 1e-5)
=========================  ====  =========================================================
"""

from __future__ import annotations

import math

import numpy as np

from ...errors import SotpyError
from .activation import Activatable
from .model import Layout, RobotModel

__all__ = [
    "CartesianAccelerationTask",
    "CoMAccelerationTask",
    "JointAccelerationTask",
    "RegularisationTask",
    "Task",
    "TorqueTask",
    "WrenchTask",
]


def _nonneg(name: str, what: str, value: object, size: int | None = None) -> np.ndarray:
    arr = np.asarray(value, dtype=float)
    if size is not None and arr.shape != (size,):
        raise SotpyError(f"{name}: {what} must have size {size}, got shape {arr.shape}")
    if not np.all(np.isfinite(arr)) or np.any(arr < 0):
        raise SotpyError(f"{name}: {what} must be finite and >= 0, got {arr}")
    return arr


class Task(Activatable):
    """Base class: weight, row weights, selection, level, desired value, ramp."""

    size: int = 0

    def __init__(self, name: str, size: int, weight: float = 1.0, level: int = 0) -> None:
        super().__init__(name)
        self.size = size
        self.setWeight(weight)
        self.row_weights = np.ones(size)
        self.selection = np.ones(size)
        self.setLevel(level)
        self.desired = np.zeros(size)

    def setWeight(self, weight: float) -> None:
        """Task weight ``w`` (finite, >= 0)."""
        self.weight = float(_nonneg(self.name, "the weight", weight))

    def setRowWeights(self, weights: object) -> None:
        """Per-row weights ``w_i`` (size m, finite, >= 0)."""
        self.row_weights = _nonneg(self.name, "the row weights", weights, self.size).copy()

    def setSelection(self, selection: object) -> None:
        """Selection ``s_i`` (size m, each 0 or 1)."""
        s = np.asarray(selection, dtype=float)
        if s.shape != (self.size,) or not np.all((s == 0) | (s == 1)):
            raise SotpyError(
                f"{self.name}: the selection must be {self.size} values 0 or 1, got {s}"
            )
        self.selection = s.copy()

    def setLevel(self, level: int) -> None:
        """Priority level (0 first) used by the multi-level strategy."""
        if int(level) != level or level < 0:
            raise SotpyError(f"{self.name}: the level must be an integer >= 0, got {level}")
        self.level = int(level)

    def setDesired(self, desired: object) -> None:
        """The target of the task (size m, finite)."""
        d = np.asarray(desired, dtype=float)
        if d.shape != (self.size,):
            raise SotpyError(
                f"{self.name}: the desired value must have size {self.size}, got {d.shape}"
            )
        if not np.all(np.isfinite(d)):
            raise SotpyError(f"{self.name}: the desired value is not finite: {d}")
        self.desired = d.copy()

    def row_weight_vector(self) -> np.ndarray:
        """``diag(W)``: ramp * weight * row weights * selection."""
        return self.ramp * self.weight * self.row_weights * self.selection

    def rows(self, robot: RobotModel, layout: Layout) -> tuple[np.ndarray, np.ndarray]:
        """``(E, f)`` at the robot's current state."""
        raise NotImplementedError

    def bind(self, robot: RobotModel, layout: Layout) -> None:
        """Check the task against a model and layout (frames, contacts)."""


class CartesianAccelerationTask(Task):
    """``J a + Jdot v = a_des`` for a frame, LOCAL_WORLD_ALIGNED (see module doc)."""

    def __init__(self, name: str, frame: str, weight: float = 1.0, level: int = 0) -> None:
        super().__init__(name, 6, weight, level)
        self.frame = frame
        self.fid = -1

    def bind(self, robot: RobotModel, layout: Layout) -> None:
        self.fid = robot.frame_id(self.frame, self.name)

    def rows(self, robot: RobotModel, layout: Layout) -> tuple[np.ndarray, np.ndarray]:
        E = np.zeros((6, layout.n))
        E[:, layout.a] = robot.frame_jacobian(self.fid)
        return E, self.desired - robot.frame_drift(self.fid)


class JointAccelerationTask(Task):
    """``S a = a_des`` on the actuated joints (posture)."""

    def __init__(self, name: str, na: int, weight: float = 1.0, level: int = 0) -> None:
        super().__init__(name, na, weight, level)

    def rows(self, robot: RobotModel, layout: Layout) -> tuple[np.ndarray, np.ndarray]:
        E = np.zeros((layout.na, layout.n))
        E[:, layout.a] = robot.S
        return E, self.desired.copy()


class CoMAccelerationTask(Task):
    """``Jcom a + dJcom v = a_des`` (world axes, m/s^2)."""

    def __init__(self, name: str, weight: float = 1.0, level: int = 0) -> None:
        super().__init__(name, 3, weight, level)

    def rows(self, robot: RobotModel, layout: Layout) -> tuple[np.ndarray, np.ndarray]:
        E = np.zeros((3, layout.n))
        E[:, layout.a] = robot.Jcom
        return E, self.desired - robot.com_drift


class WrenchTask(Task):
    """``f_c = w_des`` for the contact at ``frame`` (LOCAL wrench, N and N m)."""

    def __init__(
        self, name: str, frame: str, dim: int, weight: float = 1.0, level: int = 0
    ) -> None:
        super().__init__(name, dim, weight, level)
        self.frame = frame

    def bind(self, robot: RobotModel, layout: Layout) -> None:
        if self.frame not in layout.f:
            raise SotpyError(
                f"{self.name}: no contact at frame {self.frame!r} (contacts: {list(layout.f)})"
            )
        if layout.f[self.frame].stop - layout.f[self.frame].start != self.size:
            raise SotpyError(
                f"{self.name}: the contact at {self.frame!r} does not have dimension {self.size}"
            )

    def rows(self, robot: RobotModel, layout: Layout) -> tuple[np.ndarray, np.ndarray]:
        E = np.zeros((self.size, layout.n))
        sl = layout.f[self.frame]
        E[np.arange(self.size), np.arange(sl.start, sl.stop)] = 1.0
        return E, self.desired.copy()


class TorqueTask(Task):
    """``tau = tau_des`` (actuated joints, N m)."""

    def __init__(self, name: str, na: int, weight: float = 1.0, level: int = 0) -> None:
        super().__init__(name, na, weight, level)

    def rows(self, robot: RobotModel, layout: Layout) -> tuple[np.ndarray, np.ndarray]:
        E = np.zeros((layout.na, layout.n))
        E[np.arange(layout.na), np.arange(layout.tau.start, layout.tau.stop)] = 1.0
        return E, self.desired.copy()


class RegularisationTask(Task):
    """``chi = 0``: the global regularisation (size n, weight 1e-5 by default)."""

    def __init__(self, name: str, n: int, weight: float = 1e-5, level: int = 0) -> None:
        super().__init__(name, n, weight, level)

    def rows(self, robot: RobotModel, layout: Layout) -> tuple[np.ndarray, np.ndarray]:
        return np.eye(layout.n), self.desired.copy()


def _finite(x: float) -> bool:
    return math.isfinite(x)
