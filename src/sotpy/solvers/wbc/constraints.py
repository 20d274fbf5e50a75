r"""Constraints: rows ``lb <= C chi <= ub`` over ``chi = (a, tau, f)`` (hard).

==========================  =================================================================
constraint                  rows
==========================  =================================================================
dynamics (always on)        ``M a - S^T tau - sum_c J_c^T f_c = -b`` (equality, nv rows)
JointTorqueLimit            ``tau_min <= tau <= tau_max`` (N m)
JointPositionLimit(h, m)    ``q_min + m <= q + h v + h^2/2 a <= q_max - m`` for the 1-D
                            joints with finite limits, horizon ``h`` (s), margin ``m``
                            (default 0), and the next tick's
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
    """``(G, h)`` with ``G f_c <= h`` the friction and CoP polyhedron of contact ``c``:
    ``f_z >= fmin``, the ``facets``-sided pyramid inscribed in the cone, and for a 6-D
    contact the CoP inside the sole shrunk by the margin and the torsion bound (see the
    module doc)."""
    n = int(c.facets)
    pad = [0.0] * (c.dim - 3)
    k = c.mu * math.cos(math.pi / n)
    rows = [[0.0, 0.0, -1.0, *pad]]
    for i in range(n):
        phi = 2.0 * math.pi * i / n
        rows.append([math.cos(phi), math.sin(phi), -k, *pad])
    h = [-c.fmin] + [0.0] * n
    if c.dim == 6:
        ox, oy = c.offset
        X, Y = c.half_sizes
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
    """Base class: ``rows(robot, layout) -> (C, lb, ub)``, or the incremental pair
    :meth:`count` and :meth:`write` (what the controller calls each tick)."""

    def bind(self, robot: RobotModel, layout: Layout) -> None:
        """Check the constraint against a model and layout."""

    def rows(self, robot: RobotModel, layout: Layout) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(C, lb, ub)`` at the robot's current state (fresh arrays; by :meth:`write`)."""
        m = self.count(robot, layout)
        C, lo, hi = np.zeros((m, layout.n)), np.zeros(m), np.zeros(m)
        self.write(robot, layout, C, lo, hi, True)
        return C, lo, hi

    #: Whether every row :meth:`write` writes is constant with one nonzero entry, a 1
    #: (the joint limits: their bounds change, not their rows); see ``.tasks.Task``.
    unit_rows = False

    def count(self, robot: RobotModel, layout: Layout) -> int:
        """The number of rows (a change rebuilds the problem's buffers)."""
        raise NotImplementedError

    def write(
        self,
        robot: RobotModel,
        layout: Layout,
        C: np.ndarray,
        lo: np.ndarray,
        hi: np.ndarray,
        first: bool,
    ) -> None:
        """Write the rows into ``C`` (a view of the problem's buffer: zero if ``first``,
        else what this constraint wrote at the previous tick) and the bounds."""
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

    unit_rows = True

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
        self._kept: tuple | None = None
        self._written: tuple | None = None  # (bounds, buffer) last written (write)

    def _bounds_kept(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(kept joints, their lower and upper bounds): recomputed when the bounds change
        (even in place)."""
        key = (self.lower.tobytes(), self.upper.tobytes())
        if self._kept is None or self._kept[0] != key:
            keep = np.flatnonzero(_keep(self.lower, self.upper))
            self._kept = (key, (keep, _clip(self.lower[keep]), _clip(self.upper[keep])))
        return self._kept[1]

    def count(self, robot: RobotModel, layout: Layout) -> int:
        return len(self._bounds_kept()[0])

    def write(self, robot, layout, C, lo, hi, first) -> None:
        # count() has just checked the bounds (the controller calls it first each tick)
        kept = self._kept[1] if self._kept is not None and not first else self._bounds_kept()
        written = self._written
        if not first and written is not None and written[0] is kept and written[1] is lo:
            return  # the same bounds as at the previous tick, still in this buffer
        keep, lower, upper = kept
        if first:
            C[np.arange(len(keep)), layout.tau.start + keep] = 1.0
        lo[:] = lower
        hi[:] = upper
        self._written = (kept, lo)  # (a constraint in two controllers: per buffer)


class JointAccelerationLimit(Constraint):
    """``a_min <= S a <= a_max`` (rad/s^2)."""

    unit_rows = True

    def __init__(self, name: str, robot: RobotModel, lower: object, upper: object) -> None:
        super().__init__(name)
        self.lower, self.upper = _bounds(name, "acceleration", lower, upper, robot.na)

    def count(self, robot: RobotModel, layout: Layout) -> int:
        return int(np.count_nonzero(_keep(self.lower, self.upper)))

    def write(self, robot, layout, C, lo, hi, first) -> None:
        keep = np.flatnonzero(_keep(self.lower, self.upper))
        if first:
            C[np.arange(len(keep)), robot.actuated[keep]] = 1.0
        lo[:] = _clip(self.lower[keep])
        hi[:] = _clip(self.upper[keep])


def _horizon(name: str, h: float) -> float:
    h = float(h)
    if not (math.isfinite(h) and h > 0):
        raise SotpyError(f"{name}: the horizon must be finite and > 0 (s), got {h}")
    return h


class JointVelocityLimit(Constraint):
    """``v_min <= v + h a <= v_max`` over the actuated joints (default: model limits)."""

    unit_rows = True

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

    def count(self, robot: RobotModel, layout: Layout) -> int:
        return int(np.count_nonzero(_keep(self.lower, self.upper)))

    def write(self, robot, layout, C, lo, hi, first) -> None:
        keep = np.flatnonzero(_keep(self.lower, self.upper))
        iv = robot.actuated[keep]
        h = self.horizon
        if first:
            C[np.arange(len(keep)), iv] = 1.0  # (v_min - v) / h <= a <= (v_max - v) / h
        v = robot.v[iv]
        lo[:] = (_clip(self.lower[keep]) - v) / h
        hi[:] = (_clip(self.upper[keep]) - v) / h


class JointPositionLimit(Constraint):
    """``q_min <= q + h v + h^2/2 a <= q_max`` and ``q_min <= q + dt v + dt^2 a <= q_max``
    (the next tick, ``dt = robot.dt``) for the one-dimensional joints; ``margin`` (rad or
    m, >= 0, less than half a joint's range) keeps ``q`` that far inside the model's
    limits (the real robot, or another simulator, does not integrate exactly as the
    prediction)."""

    unit_rows = True

    def __init__(self, name: str, robot: RobotModel, horizon: float, margin: float = 0.0) -> None:
        super().__init__(name)
        self.horizon = _horizon(name, horizon)
        lo = robot.model.lowerPositionLimit[robot.iq1]
        hi = robot.model.upperPositionLimit[robot.iq1]
        keep = (np.abs(lo) < _NO_LIMIT) & (np.abs(hi) < _NO_LIMIT)
        self.iq = robot.iq1[keep]
        self.iv = robot.iv1[keep]
        m = float(margin)
        if not (math.isfinite(m) and m >= 0 and np.all(2 * m < hi[keep] - lo[keep])):
            raise SotpyError(
                f"{name}: the margin must be >= 0 and less than half of every joint's range, "
                f"got {margin}"
            )
        self.margin = m
        self.lower, self.upper = lo[keep] + m, hi[keep] - m

    def count(self, robot: RobotModel, layout: Layout) -> int:
        return 2 * len(self.iq)

    def write(self, robot, layout, C, lo, hi, first) -> None:
        h, dt = self.horizon, robot.dt
        m = len(self.iq)
        # rows scaled to a unit coefficient on a (bounds on a, rad/s^2): a row
        # dt^2 a <= ... would be met within the QP's tolerance by far too much
        if first:
            C[np.arange(2 * m), np.tile(self.iv, 2)] = 1.0
        q, v = robot.q[self.iq], robot.v[self.iv]
        a, b = 2.0 / (h * h), 1.0 / (dt * dt)
        ph, pt = q + h * v, q + dt * v
        lo[:m] = (self.lower - ph) * a
        lo[m:] = (self.lower - pt) * b
        hi[:m] = (self.upper - ph) * a
        hi[m:] = (self.upper - pt) * b


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
        #: the placement the contact feedback holds (``ContactSpec.kp``): the frame's
        #: placement at the first tick after the contact was created or activated
        self.reference: pin.SE3 | None = None

    def activate(self) -> None:
        if self.state in ("inactive", "deactivating"):
            self.reference = None  # the contact holds where it lands
        super().activate()

    @property
    def has_feedback(self) -> bool:
        """Whether the contact has pose or velocity feedback (unilateral, a gain > 0)."""
        c = self.spec
        return not c.bilateral and not (c.kp == 0.0 and c.kd in (None, 0.0))

    def feedback_terms(self, robot: RobotModel) -> tuple[np.ndarray, np.ndarray]:
        """``(e, nu)`` of a contact with feedback (:attr:`has_feedback`): the pose error
        ``log6(M_ref^-1 M)`` and the frame's LOCAL twist (6 each); sets the reference
        at its first call."""
        fid = robot.frame_id(self.spec.frame)
        data = robot.data
        e = self.pose_error(pin.updateFramePlacement(robot.model, data, fid))
        return e, pin.getFrameVelocity(robot.model, data, fid, _LOCAL).vector

    def pose_error(self, M: pin.SE3) -> np.ndarray:
        """``log6(M_ref^-1 M)`` (6: LOCAL, linear then angular) of the frame's placement
        ``M``; ``M`` becomes the reference if there is none yet."""
        if self.reference is None:
            self.reference = pin.SE3(M)
        return pin.log6(self.reference.actInv(M)).vector

    def reference_homogeneous(self, M: pin.SE3) -> np.ndarray:
        """The reference's homogeneous matrix (read at each call: a reference changed in
        place counts); ``M`` becomes the reference if there is none yet."""
        ref = self.reference
        if ref is None:
            ref = self.reference = pin.SE3(M)
        return ref.homogeneous

    def feedback(self, robot: RobotModel) -> np.ndarray | None:
        """``-kp e - kd nu`` (LOCAL, the contact's dim; :meth:`feedback_terms`) of a
        contact with feedback, or None."""
        if not self.has_feedback:
            return None
        e, nu = self.feedback_terms(robot)
        kp, kd = self.spec.gains
        d = self.spec.dim
        return -(kp * e[:d] + kd * nu[:d])


class ContactConstraint(Constraint):
    """The contacts of the layout: no contact acceleration, friction, CoP (unilateral),
    with each contact's life cycle (:class:`ContactState`, ``states`` by key)."""

    def __init__(self, name: str) -> None:
        super().__init__(name)
        self.states: dict[str, ContactState] = {}
        self._friction: dict[ContactSpec, tuple[np.ndarray, np.ndarray]] = {}  # constant
        self._plan: tuple | None = None  # (structure, [(spec, state, nf, ramp, slice, st)])

    def _friction_rows(self, c: ContactSpec) -> tuple[np.ndarray, np.ndarray]:
        fr = self._friction.get(c)
        if fr is None:
            fr = self._friction[c] = friction_rows(c)
        return fr

    def structure(self, layout: Layout) -> tuple:
        """What the row count depends on: each contact's state (and, while a bilateral
        contact deactivates, whether it has a wrench to ramp from). Also plans the rows
        that :meth:`count` and :meth:`write` use until the next call."""
        out = []
        states = self.states
        for c in layout.contacts:
            st = states.get(c.key)
            out.append("active" if st is None else (st.state, st.scale is None))
        key = (layout, tuple(out))
        if self._plan is None or self._plan[0] != key:
            plan = []
            for c in layout.contacts:
                state, nf, ramp = self._blocks(c)
                plan.append((c, state, nf, ramp, layout.f[c.key], states.get(c.key)))
            self._plan = (key, plan)
        return key[1]

    def _blocks(self, c: ContactSpec) -> tuple[str, int, int]:
        """(state, friction rows, ramp rows) of a contact."""
        st = self.states.get(c.key)
        state = "active" if st is None else st.state
        if state == "inactive":
            return state, 0, 0
        nf = 0 if c.bilateral else len(self._friction_rows(c)[1])
        ramp = 0
        if state in ("activating", "deactivating"):
            if not c.bilateral:
                ramp = 1
            elif state == "deactivating" and st.scale is not None:
                ramp = c.dim
        return state, nf, ramp

    def _planned(self, layout: Layout) -> list:
        self.structure(layout)
        return self._plan[1]

    def count(self, robot: RobotModel, layout: Layout) -> int:
        return sum(c.dim + nf + ramp for c, _s, nf, ramp, _sl, _st in self._planned(layout))

    def write(self, robot, layout, C, lo, hi, first, contact_rows: bool = True) -> None:
        """:meth:`Constraint.write`; ``contact_rows=False``: all but the rows ``J_c a =
        -Jdot_c v + feedback`` of the contacts that are not inactive (the controller's
        compiled writer wrote them, :mod:`.program`)."""
        r = 0
        a = layout.a
        for c, state, nf, ramp, sl, st in self._planned(layout):
            d = c.dim
            if state == "inactive":  # f_c = 0
                if first:
                    C[np.arange(r, r + d), np.arange(sl.start, sl.stop)] = 1.0
                    lo[r : r + d] = 0.0
                    hi[r : r + d] = 0.0
                r += d
                continue
            if contact_rows:
                C[r : r + d, a] = robot.contact_jacobian(c)
                rhs = -robot.contact_drift(c)
                fb = None if st is None else st.feedback(robot)
                if fb is not None:
                    rhs += fb
                lo[r : r + d] = rhs
                hi[r : r + d] = rhs
            r += d
            if nf:
                if first:  # constant rows and bounds
                    G, h = self._friction_rows(c)
                    C[r : r + nf, sl] = G
                    lo[r : r + nf] = -np.inf
                    hi[r : r + nf] = h
                r += nf
            if ramp:
                if not c.bilateral:
                    F = robot.weight if state == "activating" or st.scale is None else st.scale[2]
                    if first:
                        C[r, sl.start + 2] = 1.0
                    lo[r] = -np.inf
                    hi[r] = st.ramp * max(float(F), 0.0)
                else:
                    if first:
                        C[np.arange(r, r + d), np.arange(sl.start, sl.stop)] = 1.0
                    bound = st.ramp * np.abs(st.scale)
                    lo[r : r + d] = -bound
                    hi[r : r + d] = bound
                r += ramp
