r"""Constraints: rows ``lb <= C chi <= ub`` over ``chi = (a, tau, f)`` (hard).

==========================  =================================================================
constraint                  rows
==========================  =================================================================
dynamics (always on)        ``M a - S^T tau - sum_c J_c^T f_c = -b`` (equality, nv rows)
JointTorqueLimit            ``tau_min <= tau <= tau_max`` (N m)
JointPositionLimit(h)       ``q_min <= q + h v + h^2/2 a <= q_max`` for the 1-D joints
                            with finite limits, horizon ``h`` (s), and the next tick's
                            ``q + dt v + dt^2 a`` (the semi-implicit Euler step of the
                            Device, ``dt`` the control period): a continuous-time
                            horizon alone lets the discrete step overshoot
JointVelocityLimit(h)       ``v_min <= v + h a <= v_max`` (horizon ``h``, s)
JointAccelerationLimit      ``a_min <= a <= a_max`` (actuated joints)
ContactConstraint           per contact (with its life cycle, :class:`ContactState`;
                            bilateral contacts: ``J_rel a + drift_rel = 0``, see
                            :class:`~.model.BilateralContactSpec`, no friction rows):
                            ``J_c a + Jdot_c v = 0`` (LOCAL, the contact point
                            does not accelerate; 6 rows, 3 for a point), and its
                            friction/CoP polyhedron on ``f_c`` (LOCAL, z the normal):
                            ``f_z >= fmin``, ``|f_x|, |f_y| <= mu/sqrt(2) f_z`` (inner
                            pyramid of the cone); for 6-D contacts the CoP
                            ``(-tau_y/f_z, tau_x/f_z)`` inside the rectangle
                            ``[ox - L/2, ox + L/2] x [oy - W/2, oy + W/2]`` and
                            ``|tau_z| <= mu min(L, W)/2 f_z`` (a conservative bound on the
                            torsion)
==========================  =================================================================

The limits' infinite entries (or of magnitude >= 1e30, Pinocchio's "no limit") are
dropped. A position limit already violated gives an infeasible row: the controller
reports it (no solution) rather than hiding it.
"""

from __future__ import annotations

import math

import numpy as np
import pinocchio as pin

from ...errors import SotpyError
from .activation import Activatable
from .model import ContactSpec, Layout, RobotModel

__all__ = [
    "Constraint",
    "ContactConstraint",
    "ContactState",
    "JointAccelerationLimit",
    "JointPositionLimit",
    "JointTorqueLimit",
    "JointVelocityLimit",
    "dynamics_rows",
    "friction_rows",
]

_NO_LIMIT = 1e30
_LOCAL = pin.LOCAL


def dynamics_rows(robot: RobotModel, layout: Layout) -> tuple[np.ndarray, np.ndarray]:
    """``(A, c)`` with ``A chi = c`` the equations of motion ``M a + b = S^T tau + J^T f``."""
    A = np.empty((layout.nv, layout.n))
    A[:, layout.a] = robot.M
    A[:, layout.tau] = robot.minus_St
    for c in layout.contacts:
        A[:, layout.f[c.key]] = -robot.contact_jacobian(c).T
    return A, -robot.b


def friction_rows(c: ContactSpec) -> tuple[np.ndarray, np.ndarray]:
    """``(G, h)`` with ``G f_c <= h`` the friction and CoP polyhedron of contact ``c``."""
    k = c.mu / math.sqrt(2.0)
    rows = [
        [0, 0, -1] + [0] * (c.dim - 3),
        [1, 0, -k] + [0] * (c.dim - 3),
        [-1, 0, -k] + [0] * (c.dim - 3),
        [0, 1, -k] + [0] * (c.dim - 3),
        [0, -1, -k] + [0] * (c.dim - 3),
    ]
    h = [-c.fmin, 0, 0, 0, 0]
    if c.dim == 6:
        ox, oy = c.offset
        X, Y = c.length / 2, c.width / 2
        # (ox - X) fz <= -ty <= (ox + X) fz ; (oy - Y) fz <= tx <= (oy + Y) fz
        rows += [
            [0, 0, -(ox + X), 0, -1, 0],
            [0, 0, ox - X, 0, 1, 0],
            [0, 0, -(oy + Y), 1, 0, 0],
            [0, 0, oy - Y, -1, 0, 0],
            [0, 0, -c.mu * min(X, Y), 0, 0, 1],
            [0, 0, -c.mu * min(X, Y), 0, 0, -1],
        ]
        h += [0] * 6
    return np.array(rows, dtype=float), np.array(h, dtype=float)


class Constraint(Activatable):
    """Base class: ``rows(robot, layout, dt) -> (C, lb, ub)``."""

    def bind(self, robot: RobotModel, layout: Layout) -> None:
        """Check the constraint against a model and layout."""

    def rows(self, robot: RobotModel, layout: Layout) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        raise NotImplementedError


def _bounds(
    name: str, what: str, lower: object, upper: object, size: int
) -> tuple[np.ndarray, np.ndarray]:
    lo = np.asarray(lower, dtype=float)
    hi = np.asarray(upper, dtype=float)
    if lo.shape != (size,) or hi.shape != (size,):
        raise SotpyError(
            f"{name}: {what} bounds must have size {size}, got {lo.shape} and {hi.shape}"
        )
    if np.any(np.isnan(lo)) or np.any(np.isnan(hi)) or np.any(lo > hi):
        raise SotpyError(f"{name}: {what} bounds must be ordered numbers (lower <= upper)")
    return lo.copy(), hi.copy()


def _keep(lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    return (np.abs(lo) < _NO_LIMIT) | (np.abs(hi) < _NO_LIMIT)


def _clip(x: np.ndarray) -> np.ndarray:
    """Entries of magnitude >= 1e30 (no limit) become infinite."""
    return np.where(np.abs(x) >= _NO_LIMIT, np.sign(x) * np.inf, x)


class JointTorqueLimit(Constraint):
    """``tau_min <= tau <= tau_max`` (default: the model's effort limits)."""

    def __init__(
        self, name: str, robot: RobotModel, lower: object = None, upper: object = None
    ) -> None:
        super().__init__(name)
        eff = robot.model.effortLimit[robot.actuated]
        self.lower, self.upper = _bounds(
            name,
            "torque",
            -eff if lower is None else lower,
            eff if upper is None else upper,
            robot.na,
        )
        self._rows: tuple | None = None

    def rows(self, robot: RobotModel, layout: Layout) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        # constant rows: rebuilt only when the layout or the bounds change
        key = (layout, self.lower.tobytes(), self.upper.tobytes())
        if self._rows is None or self._rows[0] != key:
            keep = np.flatnonzero(_keep(self.lower, self.upper))
            C = np.zeros((len(keep), layout.n))
            C[np.arange(len(keep)), layout.tau.start + keep] = 1.0
            self._rows = (key, C, _clip(self.lower[keep]), _clip(self.upper[keep]))
        _, C, lo, hi = self._rows
        return C.copy(), lo.copy(), hi.copy()


class JointAccelerationLimit(Constraint):
    """``a_min <= S a <= a_max`` (rad/s^2)."""

    def __init__(self, name: str, robot: RobotModel, lower: object, upper: object) -> None:
        super().__init__(name)
        self.lower, self.upper = _bounds(name, "acceleration", lower, upper, robot.na)

    def rows(self, robot: RobotModel, layout: Layout) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        keep = np.flatnonzero(_keep(self.lower, self.upper))
        C = np.zeros((len(keep), layout.n))
        C[np.arange(len(keep)), robot.actuated[keep]] = 1.0
        return C, _clip(self.lower[keep]), _clip(self.upper[keep])


def _horizon(name: str, h: float) -> float:
    h = float(h)
    if not (math.isfinite(h) and h > 0):
        raise SotpyError(f"{name}: the horizon must be finite and > 0 (s), got {h}")
    return h


class JointVelocityLimit(Constraint):
    """``v_min <= v + h a <= v_max`` over the actuated joints (default: model limits)."""

    def __init__(
        self,
        name: str,
        robot: RobotModel,
        horizon: float,
        lower: object = None,
        upper: object = None,
    ) -> None:
        super().__init__(name)
        self.horizon = _horizon(name, horizon)
        vl = robot.model.velocityLimit[robot.actuated]
        self.lower, self.upper = _bounds(
            name,
            "velocity",
            -vl if lower is None else lower,
            vl if upper is None else upper,
            robot.na,
        )

    def rows(self, robot: RobotModel, layout: Layout) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        keep = np.flatnonzero(_keep(self.lower, self.upper))
        iv = robot.actuated[keep]
        h = self.horizon
        C = np.zeros((len(keep), layout.n))
        C[np.arange(len(keep)), iv] = 1.0  # (v_min - v) / h <= a <= (v_max - v) / h
        v = robot.v[iv]
        return C, (_clip(self.lower[keep]) - v) / h, (_clip(self.upper[keep]) - v) / h


class JointPositionLimit(Constraint):
    """``q_min <= q + h v + h^2/2 a <= q_max`` and ``q_min <= q + dt v + dt^2 a <= q_max``
    (the next tick, ``dt = robot.dt``) for the one-dimensional joints."""

    def __init__(self, name: str, robot: RobotModel, horizon: float) -> None:
        super().__init__(name)
        self.horizon = _horizon(name, horizon)
        lo = robot.model.lowerPositionLimit[robot.iq1]
        hi = robot.model.upperPositionLimit[robot.iq1]
        keep = (np.abs(lo) < _NO_LIMIT) & (np.abs(hi) < _NO_LIMIT)
        self.iq = robot.iq1[keep]
        self.iv = robot.iv1[keep]
        self.lower, self.upper = lo[keep], hi[keep]

    def rows(self, robot: RobotModel, layout: Layout) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        h, dt = self.horizon, robot.dt
        m = len(self.iq)
        # rows scaled to a unit coefficient on a (bounds on a, rad/s^2): a row
        # dt^2 a <= ... would be met within the QP's tolerance by far too much
        C = np.zeros((2 * m, layout.n))
        C[np.arange(2 * m), np.tile(self.iv, 2)] = 1.0
        q, v = robot.q[self.iq], robot.v[self.iv]
        pred = np.concatenate([q + h * v, q + dt * v])
        scale = np.concatenate([np.full(m, 2.0 / (h * h)), np.full(m, 1.0 / (dt * dt))])
        lo, hi = np.tile(self.lower, 2), np.tile(self.upper, 2)
        return C, (lo - pred) * scale, (hi - pred) * scale


class ContactState(Activatable):
    """The life cycle of one contact (created **active**: a declared contact holds).

    ``deactivate()`` ramps the contact's wrench down to zero before releasing it, and
    ``activate()`` ramps it up (the :mod:`.activation` ramp ``r``, duration
    ``setRampDuration``), so that a foot is unloaded before it lifts and loaded
    gradually after it lands:

    * active: the contact rows (no acceleration, friction/CoP of a unilateral contact);
    * deactivating / activating: the same, plus ``f_z <= r F`` (unilateral) or
      ``|f_i| <= r |F_i|`` per component (bilateral; not while activating: a rigid
      loop closes at once), where ``F`` is the contact's wrench of the last solution
      when ``deactivate()`` was called (``scale``; a unilateral contact without a
      solution yet: the robot's weight), and the robot's weight ``m |g|`` (N) for the
      activation of a unilateral contact;
    * inactive: no acceleration row, and ``f_c = 0`` (the variables stay in the layout).
    """

    def __init__(self, spec: object) -> None:
        super().__init__(getattr(spec, "key", str(spec)))
        self.spec = spec
        self.state = "active"
        self.ramp = 1.0
        self.scale: np.ndarray | None = None


class ContactConstraint(Constraint):
    """The contacts of the layout: no contact acceleration, friction, CoP (unilateral),
    with each contact's life cycle (:class:`ContactState`, ``states`` by key)."""

    def __init__(self, name: str) -> None:
        super().__init__(name)
        self.states: dict[str, ContactState] = {}
        self._friction: dict[ContactSpec, tuple[np.ndarray, np.ndarray]] = {}  # constant
        self._template: tuple | None = None  # (layout, C, lb, ub, slots): all active

    def rows(self, robot: RobotModel, layout: Layout) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        if all(self._state(c) == "active" for c in layout.contacts):
            return self._active_rows(robot, layout)
        return self._general_rows(robot, layout)

    def _state(self, c: ContactSpec) -> str:
        st = self.states.get(c.key)
        return "active" if st is None else st.state

    def _active_rows(
        self, robot: RobotModel, layout: Layout
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Every contact active: the rows of :meth:`_general_rows`, from a template built
        once per layout (friction rows are constant) with the Jacobians and drifts
        written in place."""
        cache = self._template
        if cache is None or cache[0] is not layout:
            C, lb, ub = self._general_rows(robot, layout)
            slots, r = [], 0
            for c in layout.contacts:
                slots.append((c, r, r + c.dim))
                r += c.dim if c.bilateral else c.dim + len(self._friction[c][1])
            cache = self._template = (layout, C, lb, ub, slots)
            return C.copy(), lb.copy(), ub.copy()
        _, C, lb, ub, slots = cache
        a = layout.a
        for c, r0, r1 in slots:
            C[r0:r1, a] = robot.contact_jacobian(c)
            drift = robot.contact_drift(c)
            np.negative(drift, out=lb[r0:r1])
            np.negative(drift, out=ub[r0:r1])
        return C.copy(), lb.copy(), ub.copy()

    def _general_rows(
        self, robot: RobotModel, layout: Layout
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        blocks, lbs, ubs = [], [], []
        for c in layout.contacts:
            st = self.states.get(c.key)
            state = "active" if st is None else st.state
            sl = layout.f[c.key]
            d = c.dim
            if state == "inactive":
                C = np.zeros((d, layout.n))
                C[np.arange(d), np.arange(sl.start, sl.stop)] = 1.0
                blocks.append(C)
                lbs.append(np.zeros(d))
                ubs.append(np.zeros(d))
                continue
            C = np.zeros((d, layout.n))
            C[:, layout.a] = robot.contact_jacobian(c)
            drift = robot.contact_drift(c)
            blocks.append(C)
            lbs.append(-drift)
            ubs.append(-drift)
            if not c.bilateral:
                G, hh = self._friction.get(c) or self._friction.setdefault(c, friction_rows(c))
                C2 = np.zeros((len(hh), layout.n))
                C2[:, sl] = G
                blocks.append(C2)
                lbs.append(np.full(len(hh), -np.inf))
                ubs.append(hh)
            if state == "active" or st is None:
                continue
            r = st.ramp
            if not c.bilateral:
                F = robot.weight if state == "activating" or st.scale is None else st.scale[2]
                C3 = np.zeros((1, layout.n))
                C3[0, sl.start + 2] = 1.0
                blocks.append(C3)
                lbs.append(np.array([-np.inf]))
                ubs.append(np.array([r * max(float(F), 0.0)]))
            elif state == "deactivating" and st.scale is not None:
                C3 = np.zeros((d, layout.n))
                C3[np.arange(d), np.arange(sl.start, sl.stop)] = 1.0
                bound = r * np.abs(st.scale)
                blocks.append(C3)
                lbs.append(-bound)
                ubs.append(bound)
        if not blocks:
            return np.zeros((0, layout.n)), np.zeros(0), np.zeros(0)
        return np.vstack(blocks), np.concatenate(lbs), np.concatenate(ubs)
