r"""The whole-body QP of one tick and its two resolution strategies.

Over ``chi = (a, tau, f)`` (:class:`.model.Layout`), with the tasks ``(E_k, f_k, W_k)``
of :mod:`.tasks` and the constraints ``lb <= C chi <= ub`` of :mod:`.constraints`
(every constraint that is not inactive), and the equations of motion
``A_dyn chi = c_dyn`` (``M a - S^T tau - J^T f = -b``):

``"OneLevelWeighted"`` (ORCA's weighted prioritisation): one dense QP over
``y = (a, f)`` with the torques eliminated by the actuated rows of the dynamics (the
same optimum, fewer variables), solved by one KKT solve on the previous tick's active
set when that is verified optimal, else by DAQP (dual active set); either way
equalities and active constraints hold to rounding (:mod:`.qp`)::

    min_chi  sum_k ||W_k^(1/2) (E_k chi - f_k)||^2 + eps ||chi||^2
    s.t.     A_dyn chi = c_dyn,   lb <= C chi <= ub

``eps`` (``regularisation``, default 1e-8) only makes the Hessian positive definite;
a :class:`RegularisationTask` is the user-visible regularisation. Task levels are ignored.

``"MultiLevelWeighted"`` (hybrid: strict levels, weights inside a level), through
:class:`~sotpy.solvers.hierarchy.HierarchySolver`, whose contract is: level 0 first,
each level's violation minimised without degrading the levels above, inequalities as
rows ``lower <= A x <= upper`` of a level, and the minimum-norm point at the end. The
stack passed is::

    level 0 (hard):  A_dyn chi = c_dyn  and  lb <= C chi <= ub     (one level)
    level 1..L:      the tasks of level 0, 1, ... (user numbering), each task's rows
                     scaled by sqrt(diag W_k): the level's least squares is weighted
    then:            min ||chi||  (the solver's final minimum-norm step)

The hard level is "hard" because it comes first: if it can be met, every solution
meets it exactly; if not (infeasible constraints), its least-violation point is found
and :attr:`HierarchyResult.feasible` is False, which the controller reports as no
solution. Scaling a level's rows does not change its optimum, so a ramping task alone
in its level is enforced fully as soon as its ramp is > 0: ramps are gradual relative
to the other tasks of the same level only (and exactly gradual in the weighted
strategy). Generalised (continuous) priorities are not implemented.

No solution (the QP infeasible or failed, the hard level not met, a non-finite
result): :class:`Solution` with ``found = False`` and the fallback: ``tau = S g(q)``
(gravity compensation at the current configuration, clipped to the torque limits if a
torque-limit constraint is set), ``a = 0``, ``f = 0``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ...errors import SotpyError
from ..hierarchy import HierarchySolver
from .constraints import (
    Constraint,
    ContactConstraint,
    ContactState,
    JointTorqueLimit,
    dynamics_rows,
)
from .model import BilateralContactSpec, ContactSpec, Layout, RobotModel
from .qp import WeightedQP
from .tasks import Task

__all__ = ["STRATEGIES", "Solution", "WholeBodyController"]

STRATEGIES = ("OneLevelWeighted", "MultiLevelWeighted")


@dataclass
class Solution:
    """The result of a tick.

    Attributes:
        chi: the full solution ``(a, tau, f)`` (the fallback's when not found).
        a, tau, f: its blocks (``f`` every contact's wrench, layout order).
        found: whether the problem was solved (constraints met).
        reason: why not, when not found ("" otherwise).
        dynamics_residual: ``||A_dyn chi - c_dyn||_inf`` of the solution.
    """

    chi: np.ndarray
    a: np.ndarray
    tau: np.ndarray
    f: np.ndarray
    found: bool
    reason: str = ""
    dynamics_residual: float = 0.0


class WholeBodyController:
    """Tasks and constraints over ``chi``, solved each tick (no graph).

    ::

        wbc = WholeBodyController(model)            # pinocchio.Model
        hand = wbc.addTask(CartesianAccelerationTask("hand", "panda_hand_tcp"))
        wbc.addConstraint(JointTorqueLimit("tau", wbc.robot))
        wbc.activateTasksAndConstraints()
        hand.setDesired(a_des)
        sol = wbc.update(q, v, t, dt)               # sol.tau, sol.found
    """

    def __init__(
        self, model: object, strategy: str = "OneLevelWeighted", regularisation: float = 1e-8
    ) -> None:
        self.robot = RobotModel(model)  # type: ignore[arg-type]
        self._unactuated = np.setdiff1d(np.arange(self.robot.nv), self.robot.actuated)
        self.contacts: list[ContactSpec] = []
        self.layout = Layout(self.robot.nv, self.robot.na, [])
        self.tasks: dict[str, Task] = {}
        self.constraints: dict[str, Constraint] = {}
        self.contact_constraint = ContactConstraint("contacts")
        self.setStrategy(strategy)
        self.setRegularisation(regularisation)
        self.hierarchy = HierarchySolver()
        self.weighted_qp = WeightedQP(self.robot.actuated, self._unactuated)
        self.last: Solution | None = None
        self.last_dynamics: tuple[np.ndarray, np.ndarray] | None = None
        self.last_constraints: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None

    # -- configuration --------------------------------------------------------------------
    def setStrategy(self, strategy: str) -> None:
        if strategy not in STRATEGIES:
            raise SotpyError(
                f"WholeBodyController: unknown strategy {strategy!r}; expected one of {STRATEGIES}"
            )
        self.strategy = strategy

    def setRegularisation(self, eps: float) -> None:
        eps = float(eps)
        if not (math.isfinite(eps) and eps > 0):
            raise SotpyError(
                f"WholeBodyController: the regularisation must be finite and > 0, got {eps}"
            )
        self.regularisation = eps

    def setContacts(self, contacts: list[ContactSpec | BilateralContactSpec]) -> None:
        """Replace the contact set (each frame must exist, dim 3 or 6, mu > 0; a bilateral
        contact between two different frames). A contact that stays keeps its life-cycle
        state; a new one is active."""
        seen = set()
        for c in contacts:
            if isinstance(c, BilateralContactSpec):
                for fr in (c.frame_a, c.frame_b):
                    self.robot.frame_id(fr, "WholeBodyController.setContacts")
                if c.frame_a == c.frame_b:
                    raise SotpyError(
                        f"bilateral contact {c.key!r}: the two frames must differ, got "
                        f"{c.frame_a!r} twice"
                    )
                if c.key in seen:
                    raise SotpyError(f"contact {c.key!r} given twice")
                seen.add(c.key)
                continue
            if not isinstance(c, ContactSpec):
                raise SotpyError(
                    f"WholeBodyController.setContacts: expected ContactSpec or "
                    f"BilateralContactSpec, got {c!r}"
                )
            self.robot.frame_id(c.frame, "WholeBodyController.setContacts")
            if c.dim not in (3, 6):
                raise SotpyError(f"contact {c.frame!r}: dim must be 3 or 6, got {c.dim}")
            if not (math.isfinite(c.mu) and c.mu > 0):
                raise SotpyError(f"contact {c.frame!r}: mu must be finite and > 0, got {c.mu}")
            if c.dim == 6 and not (c.length > 0 and c.width > 0):
                raise SotpyError(f"contact {c.frame!r}: length and width must be > 0")
            if not (math.isfinite(c.fmin) and c.fmin >= 0):
                raise SotpyError(f"contact {c.frame!r}: fmin must be finite and >= 0")
            if c.frame in seen:
                raise SotpyError(f"contact {c.frame!r} given twice")
            seen.add(c.frame)
        layout = Layout(self.robot.nv, self.robot.na, list(contacts))
        for t in self.tasks.values():
            t.bind(self.robot, layout)  # a wrench task on a removed contact is refused
        self.contacts = list(contacts)
        self.layout = layout
        states = self.contact_constraint.states
        self.contact_constraint.states = {
            c.key: states[c.key] if c.key in states else ContactState(c) for c in contacts
        }

    @property
    def contact_states(self) -> dict[str, ContactState]:
        """The life cycle of each contact, by key (frame, or a bilateral contact's name)."""
        return self.contact_constraint.states

    def item(self, name: str) -> Task | Constraint | ContactState:
        """The task, constraint or contact (its :class:`ContactState`) called ``name``."""
        x = self.tasks.get(name) or self.constraints.get(name) or self.contact_states.get(name)
        if x is None:
            raise SotpyError(
                f"WholeBodyController: no task, constraint or contact named {name!r} (tasks: "
                f"{list(self.tasks)}, constraints: {list(self.constraints)}, contacts: "
                f"{list(self.contact_states)})"
            )
        return x

    def activate(self, name: str) -> None:
        """Start the activation ramp of a task, constraint or contact."""
        self.item(name).activate()

    def deactivate(self, name: str) -> None:
        """Start the deactivation ramp of a task, constraint or contact; a contact's wrench
        bound starts from its wrench in the last solution (see ContactState)."""
        x = self.item(name)
        if isinstance(x, ContactState) and x.state in ("active", "activating"):
            last = self.last
            if last is not None and last.found and last.chi.shape == (self.layout.n,):
                x.scale = last.chi[self.layout.f[name]].copy()
            else:
                x.scale = None
        x.deactivate()

    def addTask(self, task: Task) -> Task:
        if task.name in self.tasks or task.name in self.constraints:
            raise SotpyError(
                f"WholeBodyController: a task or constraint named {task.name!r} exists"
            )
        task.bind(self.robot, self.layout)
        self.tasks[task.name] = task
        return task

    def addConstraint(self, constraint: Constraint) -> Constraint:
        if constraint.name in self.tasks or constraint.name in self.constraints:
            raise SotpyError(
                f"WholeBodyController: a task or constraint named {constraint.name!r} exists"
            )
        constraint.bind(self.robot, self.layout)
        self.constraints[constraint.name] = constraint
        return constraint

    def remove(self, name: str) -> None:
        if self.tasks.pop(name, None) is None and self.constraints.pop(name, None) is None:
            raise SotpyError(f"WholeBodyController: no task or constraint named {name!r}")

    def _all(self) -> list:
        return [*self.tasks.values(), *self.constraints.values()]

    def activateTasksAndConstraints(self) -> None:
        for x in self._all():
            x.activate()

    def deactivateTasksAndConstraints(self) -> None:
        for x in self._all():
            x.deactivate()

    def tasksAndConstraintsDeactivated(self) -> bool:
        return all(x.isDeactivated for x in self._all())

    # -- one tick ---------------------------------------------------------------------------
    def update(self, q: np.ndarray, v: np.ndarray, t: float = 0.0, dt: float = 0.001) -> Solution:
        """Update the model at ``(q, v)``, advance the ramps by ``dt``, solve."""
        self.robot.update(q, v)
        return self.tick(t, dt)

    def tick(self, t: float = 0.0, dt: float = 0.001) -> Solution:
        """Advance the ramps by ``dt`` (s), call the callbacks, solve at the state of the
        last :meth:`RobotModel.update`."""
        if self.robot.q is None:
            raise SotpyError(
                "WholeBodyController.tick: the robot state was never set (update(q, v))"
            )
        if not (math.isfinite(dt) and dt > 0):
            raise SotpyError(f"WholeBodyController: dt must be finite and > 0 (s), got {dt}")
        self.robot.dt = dt
        live = [x for x in [*self._all(), *self.contact_states.values()] if x.begin(t, dt)]
        try:
            sol = self.solve()
        finally:
            for x in live:
                x.end(t, dt)
        self.last = sol
        return sol

    def problem(
        self,
    ) -> tuple[tuple[np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray, np.ndarray], list]:
        """The current dynamics ``(A, c)``, constraints ``(C, lb, ub)`` and tasks
        ``[(level, E, f, w)]`` (w = diag W), from the last :meth:`RobotModel.update`."""
        robot, layout = self.robot, self.layout
        dyn = dynamics_rows(robot, layout)
        Cs, lbs, ubs = [np.zeros((0, layout.n))], [np.zeros(0)], [np.zeros(0)]
        cons = [c for c in self.constraints.values() if c.state != "inactive"]
        cons.append(self.contact_constraint)  # contacts are physical: always enforced
        for c in cons:
            C, lb, ub = c.rows(robot, layout)
            Cs.append(C)
            lbs.append(lb)
            ubs.append(ub)
        tasks = []
        for task in self.tasks.values():
            if task.state == "inactive":
                continue
            w = task.row_weight_vector()
            if not w.any():  # w >= 0: no row counts
                continue
            E, f = task.rows(robot, layout)
            tasks.append((task.level, E, f, w))
        return dyn, (np.vstack(Cs), np.concatenate(lbs), np.concatenate(ubs)), tasks

    def solve(self) -> Solution:
        dyn, cons, tasks = self.problem()
        self.last_dynamics, self.last_constraints = dyn, cons
        try:
            if self.strategy == "OneLevelWeighted":
                chi, ok, reason = self._weighted(dyn, cons, tasks)
            else:
                chi, ok, reason = self._multilevel(dyn, cons, tasks)
        except (np.linalg.LinAlgError, ValueError) as exc:
            chi, ok, reason = None, False, f"solver error: {exc}"
        if ok and not np.all(np.isfinite(chi)):
            ok, reason = False, "non-finite solution"
        if ok:
            res = float(np.max(np.abs(dyn[0] @ chi - dyn[1]), initial=0.0))
            return self._split(chi, True, "", res)
        return self._fallback(reason)

    def _split(self, chi: np.ndarray, found: bool, reason: str, res: float) -> Solution:
        L = self.layout
        return Solution(
            chi, chi[L.a].copy(), chi[L.tau].copy(), chi[L.nv + L.na :].copy(), found, reason, res
        )

    def _fallback(self, reason: str) -> Solution:
        L, robot = self.layout, self.robot
        tau = robot.S @ robot.g
        for c in self.constraints.values():
            if isinstance(c, JointTorqueLimit) and c.state != "inactive":
                tau = np.clip(tau, c.lower, c.upper)
        chi = np.zeros(L.n)
        chi[L.tau] = tau
        A, c = (
            self.last_dynamics
            if self.last_dynamics is not None
            else (np.zeros((0, L.n)), np.zeros(0))
        )
        res = float(np.max(np.abs(A @ chi - c), initial=0.0))
        return self._split(chi, False, reason, res)

    # -- strategies -----------------------------------------------------------------------------
    def _weighted(self, dyn, cons, tasks) -> tuple[np.ndarray | None, bool, str]:
        """One QP over ``y = (a, f)``, the torques eliminated through the actuated rows of
        the equations of motion (:mod:`.qp`): the same optimum as over ``chi`` with the
        dynamics as an equality (82 -> 50 variables and 38 -> 6 equalities on Talos),
        the previous tick's active set tried first, DAQP otherwise. The answer is
        checked against the constraints over ``chi`` before it is used."""
        qp = self.weighted_qp
        x, reason = qp.solve(self.layout, dyn, cons, tasks, self.regularisation)
        if x is None:
            return None, False, reason
        if qp.last_method == "guess":
            return x, True, ""  # optimality and feasibility verified (see .qp)
        A = dyn[0]
        viol = max(
            float(np.max(np.abs(A @ x - dyn[1]), initial=0.0)),
            float(np.max(cons[1] - cons[0] @ x, initial=0.0)),
            float(np.max(cons[0] @ x - cons[2], initial=0.0)),
        )
        scale = max(
            float(np.max(np.abs(A), initial=0.0)), float(np.max(np.abs(cons[0]), initial=0.0))
        )
        tol = 1e-6 * (1.0 + scale * (1.0 + float(np.max(np.abs(x)))))
        if viol > tol:
            return None, False, f"QP solution violates the constraints by {viol:.3g}"
        return x, True, ""

    def _multilevel(self, dyn, cons, tasks) -> tuple[np.ndarray | None, bool, str]:
        hard = (
            np.vstack([dyn[0], cons[0]]),
            np.concatenate([dyn[1], cons[1]]),
            np.concatenate([dyn[1], cons[2]]),
        )
        if (
            np.any(hard[1] > hard[2] + 1e-12)
            or np.any(np.isnan(hard[1]))
            or np.any(np.isnan(hard[2]))
        ):
            return None, False, "a constraint has lower > upper (infeasible bounds)"
        levels: list[tuple] = [hard]
        for lvl in sorted({t[0] for t in tasks}):
            rows = [(E * np.sqrt(w)[:, None], f * np.sqrt(w)) for (k, E, f, w) in tasks if k == lvl]
            levels.append((np.vstack([r[0] for r in rows]), np.concatenate([r[1] for r in rows])))
        res = self.hierarchy.solve(levels)
        if not res.feasible:
            return None, False, f"the constraints cannot be met (violation {res.residuals[0]:.3g})"
        return np.asarray(res.x, dtype=float), True, ""
