r"""Tasks: weighted least-squares rows over ``chi = (a, tau, f)``.

A task gives ``E`` (m x n) and ``f`` (m) and contributes, in its level,

.. math:: \| W^{1/2} (E \chi - f) \|^2, \qquad
          W = \mathrm{diag}(r \; w \; w_i \; s_i)

with ``w`` the task weight (>= 0), ``w_i`` the per-row weights (>= 0, default 1),
``s_i`` the selection (0 or 1 per row: a 0 drops the row) and ``r`` the activation
ramp's weight factor (``ramp_weight`` of the ramp, see :mod:`.activation`). ``desired``
is the target (size m, set by the user or a servo).

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

The controller adds the **contact wrench distribution cost** (:class:`ContactWrenchCost`)
of its contacts by default: it keeps each contact's wrench away from the edges of its
friction and CoP polyhedron, where a real contact starts to slide or tilt.
"""

from __future__ import annotations

import math

import numpy as np
import pinocchio as pin

from ...errors import SotpyError
from .activation import Activatable, ramp_weight
from .model import ContactSpec, Layout, RobotModel

_LWA = pin.LOCAL_WORLD_ALIGNED
_NO_LOADS = np.zeros(0)  # no solution observed yet: the cost's default loads

__all__ = [
    "CartesianAccelerationTask",
    "CoMAccelerationTask",
    "ContactWrenchCost",
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
        self._w_cache: tuple | None = None

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
        """``diag(W)``: ramp_weight(ramp) * weight * row weights * selection (the ramp's
        shape: :func:`.activation.ramp_weight`); do not modify the array returned (it
        is kept until the ramp or a weight changes through the setters)."""
        return self._weights()[0]

    def _weights(self) -> tuple[np.ndarray, bool]:
        """``(diag(W), whether a row has a weight > 0)``, kept until a setter or the
        ramp changes them."""
        cached = self._w_cache
        if (
            cached is None
            or cached[0] != self.ramp
            or cached[1] != self.weight
            or cached[2] is not self.row_weights
            or cached[3] is not self.selection
        ):
            w = ramp_weight(self.ramp) * self.weight * self.row_weights * self.selection
            cached = self._w_cache = (
                self.ramp, self.weight, self.row_weights, self.selection, w, bool(w.any())
            )  # fmt: skip
        return cached[4], cached[5]

    def rows(self, robot: RobotModel, layout: Layout) -> tuple[np.ndarray, np.ndarray]:
        """``(E, f)`` at the robot's current state (fresh arrays; by :meth:`write`)."""
        E = np.zeros((self.size, layout.n))
        f = np.zeros(self.size)
        self.write(robot, layout, E, f, True)
        return E, f

    def write(
        self, robot: RobotModel, layout: Layout, E: np.ndarray, f: np.ndarray, first: bool
    ) -> None:
        """Write the rows at the robot's current state into ``E`` (m x n, a view of the
        problem's buffer) and ``f`` (m). ``first``: the buffer is new (zero); otherwise
        it holds what this task wrote at the previous tick, so constant entries need not
        be written again. A subclass overrides :meth:`write` or :meth:`rows`."""
        raise NotImplementedError

    def bind(self, robot: RobotModel, layout: Layout) -> None:
        """Check the task against a model and layout (frames, contacts)."""

    #: Whether every row :meth:`write` writes is constant and has one nonzero entry, a 1
    #: (a posture, a torque, a wrench): the QP then takes it as such (see
    #: :func:`.program.owns`: a subclass overriding ``write`` must say it again).
    unit_rows = False

    def terms(self, robot: RobotModel) -> tuple[np.ndarray | None, np.ndarray | None] | None:
        """What :meth:`write` writes at each tick but the first, for the controller's
        compiled problem writer (:mod:`.program`): ``(J, drift)`` with the rows
        ``E[:, a] = J`` (nv columns; None: the rows are constant, written by
        :meth:`write` when the buffer is new) and ``f = desired - drift`` (None: ``f =
        desired``). None (the default): not expressible so; :meth:`write` is then called
        at every tick. A subclass that overrides :meth:`write` without overriding this
        is always written by :meth:`write`."""
        return None


class CartesianAccelerationTask(Task):
    """``J a + Jdot v = a_des`` for a frame, LOCAL_WORLD_ALIGNED (see module doc)."""

    def __init__(self, name: str, frame: str, weight: float = 1.0, level: int = 0) -> None:
        super().__init__(name, 6, weight, level)
        self.frame = frame
        self.fid = -1

    def bind(self, robot: RobotModel, layout: Layout) -> None:
        self.fid = robot.frame_id(self.frame, self.name)

    def write(self, robot, layout, E, f, first) -> None:
        E[:, layout.a] = robot.frame_jacobian(self.fid)
        np.subtract(self.desired, robot.frame_drift(self.fid), out=f)

    def terms(self, robot):
        m, d, fid = robot.model, robot.data, self.fid  # write()'s, without the copies
        return (
            pin.getFrameJacobian(m, d, fid, _LWA),
            pin.getFrameClassicalAcceleration(m, d, fid, _LWA).vector,
        )


class JointAccelerationTask(Task):
    """``S a = a_des`` on the actuated joints (posture)."""

    def __init__(self, name: str, na: int, weight: float = 1.0, level: int = 0) -> None:
        super().__init__(name, na, weight, level)

    def write(self, robot, layout, E, f, first) -> None:
        if first:
            E[:, layout.a] = robot.S
        f[:] = self.desired

    def terms(self, robot):
        return None, None

    unit_rows = True


class CoMAccelerationTask(Task):
    """``Jcom a + dJcom v = a_des`` (world axes, m/s^2)."""

    def __init__(self, name: str, weight: float = 1.0, level: int = 0) -> None:
        super().__init__(name, 3, weight, level)

    def write(self, robot, layout, E, f, first) -> None:
        E[:, layout.a] = robot.Jcom
        np.subtract(self.desired, robot.com_drift, out=f)

    def terms(self, robot):
        d = robot.data
        return d.Jcom, d.acom[0]  # robot.Jcom and robot.com_drift


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

    def write(self, robot, layout, E, f, first) -> None:
        if first:
            sl = layout.f[self.frame]
            E[np.arange(self.size), np.arange(sl.start, sl.stop)] = 1.0
        f[:] = self.desired

    def terms(self, robot):
        return None, None

    unit_rows = True


class TorqueTask(Task):
    """``tau = tau_des`` (actuated joints, N m)."""

    def __init__(self, name: str, na: int, weight: float = 1.0, level: int = 0) -> None:
        super().__init__(name, na, weight, level)

    def write(self, robot, layout, E, f, first) -> None:
        if first:
            E[np.arange(layout.na), np.arange(layout.tau.start, layout.tau.stop)] = 1.0
        f[:] = self.desired

    def terms(self, robot):
        return None, None

    unit_rows = True


class RegularisationTask(Task):
    """``chi = 0``: the global regularisation (size n, weight 1e-5 by default)."""

    def __init__(self, name: str, n: int, weight: float = 1e-5, level: int = 0) -> None:
        super().__init__(name, n, weight, level)

    def write(self, robot, layout, E, f, first) -> None:
        if first:
            E[:] = np.eye(layout.n)
        f[:] = self.desired

    def terms(self, robot):
        return None, None

    unit_rows = True


def _finite(x: float) -> bool:
    return math.isfinite(x)


class ContactWrenchCost:
    r"""The default distribution of the contact wrenches: each unilateral contact's CoP
    pulled to its sole's centre, its tangential force and twisting torque to zero,
    relative to its own normal force, so that the optimum stays inside the friction and
    CoP polyhedron instead of on its edge (where a least-norm split puts a lightly
    loaded contact).

    The rows approximate the squared ratios that measure how close a contact is to
    sliding or tilting: for a 6-D contact (LOCAL wrench ``(f, tau)``, sole centre
    ``(o_x, o_y)``, half-sizes ``(X, Y)`` of its CoP rectangle, friction ``mu``), with
    ``F`` its normal force at the previous solution (at least ``fmin`` and 2 % of the
    robot's weight; the weight over the number of contacts before a first solution),
    the rows (dimensionless, target 0) are::

        (tau_y + o_x f_z) / (X F),  (tau_x - o_y f_z) / (Y F)   ~ (CoP - centre) / half-size
        f_x / (mu F),  f_y / (mu F)                              ~ f_t / (mu f_z)
        tau_z / (mu min(X, Y) F)                                 ~ torsion / its bound

    (at ``f_z = F`` each is the ratio itself); a point contact has the two tangential
    rows. Scaling by the contact's own load is what keeps a light contact centred: with
    one scale for every contact, the least-squares split of a tangential force is equal
    between the feet, which saturates the friction of the light one. ``weight`` (>= 0;
    0: no cost) is the weight of every row; the rows of a contact that is not inactive
    are included (their wrench ramps down while it deactivates: the rows are linear in
    it). In the multi-level strategy the cost is part of the last level.
    """

    def __init__(self, weight: float = 0.1) -> None:
        self.setWeight(weight)
        self._observed: tuple[Layout, np.ndarray] | None = None  # (layout, wrenches)
        self._loads: dict[str, float] | None = None

    @property
    def loads(self) -> dict[str, float]:
        """Contact key -> ``F`` (N): the normal forces of the last solution observed
        (:meth:`observe`; empty before one)."""
        if self._loads is None:
            loads = {}
            if self._observed is not None:
                layout, f = self._observed
                i = 0
                for c in layout.contacts:
                    if not c.bilateral:
                        loads[c.key] = float(f[i + 2])
                    i += c.dim
            self._loads = loads
        return self._loads

    @loads.setter
    def loads(self, loads: dict[str, float]) -> None:
        """Set the loads by contact key (until the next :meth:`observe`)."""
        self._observed = None
        self._loads = {str(k): float(v) for k, v in loads.items()}

    def observed(self, layout: Layout) -> np.ndarray | None:
        """Where the controller's compiled writer reads the loads: the wrenches of the
        last solution observed over ``layout`` (layout order); an empty array before
        any (the default loads); None when the loads are known by contact key only
        (set, or observed over another layout: :meth:`write` reads them)."""
        obs = self._observed
        if obs is not None:
            return obs[1] if obs[0] is layout else None
        return None if self._loads else _NO_LOADS

    def setWeight(self, weight: float) -> None:
        w = float(weight)
        if not (math.isfinite(w) and w >= 0):
            raise SotpyError(f"contact wrench cost: the weight must be finite and >= 0, got {w}")
        self.weight = w

    @staticmethod
    def contact_rows(c: ContactSpec, F: float) -> np.ndarray:
        """The cost's rows on the contact's wrench (k x dim), for the load ``F`` (N)."""
        if c.dim == 3:
            return np.array([[1.0, 0, 0], [0, 1.0, 0]]) / (c.mu * F)
        ox, oy = c.offset
        X, Y = c.half_sizes
        G = np.zeros((5, 6))
        G[0, 4], G[0, 2] = 1.0 / (X * F), ox / (X * F)
        G[1, 3], G[1, 2] = 1.0 / (Y * F), -oy / (Y * F)
        G[2, 0] = G[3, 1] = 1.0 / (c.mu * F)
        G[4, 5] = 1.0 / (c.mu * min(X, Y) * F)
        return G

    def load(self, c: ContactSpec, weight: float, count: int) -> float:
        """``F`` of contact ``c`` (N): see the class doc."""
        F = self.loads.get(c.key)
        if F is None:
            F = weight / max(count, 1)
        return max(F, c.fmin, 0.02 * weight)

    def observe(self, layout: Layout, f: np.ndarray) -> None:
        """Record the normal forces of a solution's wrenches ``f`` (every contact's,
        layout order) as the next tick's loads (a copy: the solution is the caller's)."""
        self._observed = (layout, np.array(f, dtype=float))
        self._loads = None

    def contacts(self, layout: Layout, states: dict) -> list[ContactSpec]:
        """The contacts the cost has rows for (unilateral, not inactive; none if the
        weight is 0)."""
        if self.weight <= 0:
            return []
        out = []
        for c in layout.contacts:
            st = states.get(c.key)
            if not c.bilateral and (st is None or st.state != "inactive"):
                out.append(c)
        return out

    def write(
        self,
        robot: RobotModel,
        layout: Layout,
        contacts: list,
        E: np.ndarray,
        w: np.ndarray,
        first: bool = True,
    ) -> None:
        """The rows of ``contacts`` into ``E`` (a view of the problem's buffer, zero
        outside the contacts' wrench columns; written if ``first``) and their weights
        into ``w``; the target is 0. The rows for ``F = 1`` N are kept, and the load
        goes into the weights: ``weight / F^2`` (the same squares as the rows over
        ``F``)."""
        W = robot.weight
        count = sum(1 for c in layout.contacts if not c.bilateral)
        r = 0
        for c in contacts:
            k = 2 if c.dim == 3 else 5
            if first:
                E[r : r + k, layout.f[c.key]] = self.contact_rows(c, 1.0)
            F = self.load(c, W, count)
            w[r : r + k] = self.weight / (F * F)
            r += k

    def rows(
        self, robot: RobotModel, layout: Layout, states: dict
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(E, f, w)`` over ``chi`` (fresh arrays; no rows: an empty E)."""
        contacts = self.contacts(layout, states)
        m = sum(2 if c.dim == 3 else 5 for c in contacts)
        E, f, w = np.zeros((m, layout.n)), np.zeros(m), np.zeros(m)
        self.write(robot, layout, contacts, E, w)
        return E, f, w
