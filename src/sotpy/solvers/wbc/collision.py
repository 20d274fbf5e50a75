r"""Collision avoidance at the acceleration level: rows over ``a`` for the torque-level
controller, the velocity damper of :mod:`sotpy.tasks.collision` one order higher.

For every pair under the influence distance ``d_i`` (the pairs, the broad phase and
``J_d`` are those of :class:`~sotpy.tasks.collision.CollisionPairs`), the distance's
rate and acceleration are

.. math::

    \dot d = J_d v, \qquad \ddot d = J_d a + \dot J_d v,

with the drift ``Jdot_d v = n^T (a_{p_B} - a_{p_A})``: the classical accelerations of the
witness points at zero joint acceleration, ``a_p = a_j + alpha_j x r + w_j x (w_j x r)``
(``r = p - o_j``; ``a_j``, ``alpha_j``, ``w_j`` the joint's classical linear
acceleration, angular acceleration and angular velocity in world axes, from the
``RobotModel``'s kinematics at ``(q, v, 0)``). This treats the witness points as
points fixed to their bodies and the normal as constant: the rate of the normal and the
motion of the witness points on the surfaces are neglected. For two spheres (radii
``r_A``, ``r_B``, centres ``D`` apart) the exact acceleration is this drift plus
``|v_t|^2 / D - r_A |w_A,perp|^2 - r_B |w_B,perp|^2`` (``v_t`` the centres' tangential
relative velocity, ``w_perp`` a body's angular velocity across the normal):
``tests/test_collision_torque.py`` checks that identity. The error is of either sign
and second order in the velocities; the horizon's margin absorbs it at the speeds of a
reach, but it is not a guarantee at high speed.

The constraint asks the velocity damper ``d_dot >= -c (d - d_s)``, ``c = xi / (d_i -
d_s)``, to hold one horizon ``h`` ahead, with ``d_dot(t + h) = d_dot + h d_ddot`` and
``d(t + h) = d + h d_dot``:

.. math::

    \ddot d \ge \frac{-c (d - d_s) - (1 + c h) \dot d}{h},

a damped second-order approach (stiffness ``c / h``, damping ``(1 + c h) / h``, in
1/s^2 and 1/s) to ``d_s``; the rows are ``J_d a >= that - Jdot_d v`` (m/s^2). Their
number changes from tick to tick (zero when nothing is close): ``count`` says it, and
the controller rebuilds its buffers when it changes.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pinocchio as pin

from ...errors import SotpyError
from ...tasks.collision import (
    DEFAULT_GAIN,
    DEFAULT_INFLUENCE,
    DEFAULT_SAFETY,
    CollisionPairs,
    checkDamper,
)
from .constraints import Constraint
from .model import Layout, RobotModel

__all__ = ["DEFAULT_HORIZON", "CollisionConstraint"]

#: The horizon h of the acceleration-level damper (s).
DEFAULT_HORIZON = 0.05

_LWA = pin.LOCAL_WORLD_ALIGNED


class CollisionConstraint(Constraint):
    """The collision pairs' damper over ``a`` (see the module doc).

    ``CollisionConstraint(name, robot, geometry, srdf=None, horizon=0.05,
    safety=0.01, influence=0.05, gain=0.5)``: ``robot`` the controller's
    :class:`~.model.RobotModel`, ``geometry`` its collision ``pinocchio.GeometryModel``,
    ``srdf`` the SRDF whose disabled pairs are removed; ``horizon`` h (s, > 0),
    ``safety`` d_s and ``influence`` d_i (m, ``0 <= d_s < d_i``), ``gain`` xi (m/s,
    > 0). ``pairs`` is the :class:`~sotpy.tasks.collision.CollisionPairs` (its
    commands edit the pairs and the obstacles).
    """

    def __init__(
        self,
        name: str,
        robot: RobotModel,
        geometry: pin.GeometryModel,
        srdf: str | Path | None = None,
        horizon: float = DEFAULT_HORIZON,
        safety: float = DEFAULT_SAFETY,
        influence: float = DEFAULT_INFLUENCE,
        gain: float = DEFAULT_GAIN,
    ) -> None:
        super().__init__(name)
        who = f"CollisionConstraint({name})"
        try:
            checkDamper(who, safety, influence, gain)
        except SotpyError as exc:
            raise SotpyError(str(exc)) from None
        if not (isinstance(horizon, (int, float)) and math.isfinite(horizon) and horizon > 0):
            raise SotpyError(f"{who}: expected a horizon h > 0 (s), got {horizon!r}")
        if not isinstance(geometry, pin.GeometryModel):
            raise SotpyError(f"{who}: expected a pinocchio.GeometryModel, got {geometry!r}")
        if srdf is not None and not Path(srdf).is_file():
            raise SotpyError(f"{who}: no SRDF file {str(srdf)!r}")
        self.horizon = float(horizon)
        self.safety, self.influence, self.gain = float(safety), float(influence), float(gain)
        self.pairs = CollisionPairs(robot.model, geometry, srdf, who=who)

    def count(self, robot: RobotModel, layout: Layout) -> int:
        """The pairs under d_i at the robot's state (computed here, written by
        :meth:`write`)."""
        self.pairs.compute(robot.data, self.influence)
        return int(self.pairs.rowD.shape[0])

    def drift(self, robot: RobotModel) -> np.ndarray:
        """``Jdot_d v`` of the rows of the last :meth:`count` (m/s^2): the witness
        points' classical accelerations at ``a = 0`` along the normals."""
        P = self.pairs
        m = P.rowD.shape[0]
        out = np.zeros(m)
        model, data = robot.model, robot.data
        for side, (joints, points) in enumerate(
            ((P.rowJointA, P.rowPointA), (P.rowJointB, P.rowPointB))
        ):
            sign = -1.0 if side == 0 else 1.0
            for r in range(m):
                j = int(joints[r])
                if j == 0:
                    continue  # fixed to the world
                acc = pin.getClassicalAcceleration(model, data, j, _LWA)
                w = pin.getVelocity(model, data, j, _LWA).angular
                rr = points[r] - data.oMi[j].translation
                a_p = acc.linear + np.cross(acc.angular, rr) + np.cross(w, np.cross(w, rr))
                out[r] += sign * float(P.rowNormal[r] @ a_p)
        return out

    def bounds(self, robot: RobotModel) -> np.ndarray:
        """The lower bounds of the rows (m/s^2): the damper one horizon ahead, minus the
        drift."""
        P = self.pairs
        d, ddot = P.rowD, P.rowJ @ robot.v
        c = self.gain / (self.influence - self.safety)
        h = self.horizon
        return (-c * (d - self.safety) - (1.0 + c * h) * ddot) / h - self.drift(robot)

    def write(self, robot, layout, C, lo, hi, first) -> None:
        C[:, layout.a] = self.pairs.rowJ
        lo[:] = self.bounds(robot)
        hi[:] = np.inf
