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

    min_chi  sum_k ||W_k^(1/2) (E_k chi - f_k)||^2 + eps ||(a, f)||^2
    s.t.     A_dyn chi = c_dyn,   lb <= C chi <= ub

``eps`` (``regularisation``, default 1e-8) only makes the Hessian positive definite (the
torques, functions of ``(a, f)`` through the dynamics, are not in it);
a :class:`RegularisationTask` is the user-visible regularisation. Task levels are ignored.

``"MultiLevelWeighted"`` (hybrid: strict levels, weights inside a level), through
:class:`~sotpy.solvers.hierarchy.HierarchySolver`, whose contract is: level 0 first,
each level's violation minimised without degrading the levels above, inequalities as
rows ``lower <= A x <= upper`` of a level, and the minimum-norm point at the end, within
its time and iteration budget (``Controller.setTimeBudget``). The torques are eliminated
as in the weighted strategy (``tau = T y + t`` by the actuated rows of the dynamics; the
levels are over ``y = (a, f)``: 50 variables instead of 82 on Talos). The stack passed
is::

    level 0 (hard):  the unactuated rows of A_dyn chi = c_dyn  and  lb <= C chi <= ub
    (level 1:        the torque-rate rows of a transition, when they are on)
    level 1..L:      the tasks of level 0, 1, ... (user numbering), each task's rows
                     scaled by sqrt(diag W_k): the level's least squares is weighted;
                     the contact wrench cost's rows join the last task level (with
                     their weight, as in the weighted strategy: a level of their own
                     below would get no freedom once a posture fills the last one)
    then:            min ||(a, f)||  (the solver's final minimum-norm step)

The hard level is "hard" because it comes first: if it can be met, every solution
meets it exactly; if not (infeasible constraints), its least-violation point is found
and :attr:`HierarchyResult.feasible` is False, which the controller reports as no
solution. Scaling a level's rows does not change its optimum, so a ramping task alone
in its level is enforced fully as soon as its ramp is > 0: ramps are gradual relative
to the other tasks of the same level only (and exactly gradual in the weighted
strategy). Generalised (continuous) priorities are not implemented.

Smooth transitions (a bounded torque change per tick). From an activation or a
deactivation (of a task, a constraint or a contact) or a change of strategy until the
torques have settled (every ramp at its end and no torque at its rate bound), each
joint's torque may change by at most ``rate_j dt`` per tick:

    tau_prev - rate dt <= tau <= tau_prev + rate dt

(``tau_prev`` the torque of the previous tick; ``rate`` of
:meth:`WholeBodyController.setTorqueRateLimit`,
N m/s, by default the joint's effort limit per ``RATE_TIME`` = 0.1 s: 3 N m per 1 ms
tick on a 300 N m knee, 1 N m on a 100 N m ankle), hard rows like the torque limits.
The activation ramps themselves are smooth (:mod:`.activation`). If the rows make the
problem infeasible (a sudden loss of a contact), the weighted strategy solves it again
without them (:attr:`Solution.rate_limited` is then False); the multi-level strategy
puts them in a level of their own after the hard one (their least violation).

Warnings (:class:`~sotpy.errors.SotpyWarning`, once until the condition clears): a
floating-base robot with no active contact (its base is unconstrained: it falls), or a
robot with nothing active (no task, constraint or contact).

No solution (the QP infeasible or failed, the hard level not met, a non-finite
result): :class:`Solution` with ``found = False`` and the fallback: ``tau = tau_prev +
clip(S g(q) - tau_prev, -rate dt, rate dt)``, a step from the last torques sent towards
gravity compensation of at most the torque-rate bound (``S g(q)`` itself on the first
tick or with no rate bound), clipped to the torque limits if a torque-limit constraint
is set; ``a = 0``, ``f = 0``.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass

import numpy as np

from ... import _jit
from ...errors import SotpyError, SotpyWarning
from ...tasks import _rowkernels
from ..hierarchy import NUMPY_BUDGET_FACTOR, HierarchySolver
from ._kernels import CONSTANT, GENERAL, NO_TAU, data_layout
from .activation import Activatable
from .constraints import (
    Constraint,
    ContactConstraint,
    ContactState,
    JointTorqueLimit,
)
from .model import BilateralContactSpec, ContactSpec, Layout, RobotModel
from .program import ProblemProgram, owns, row_kinds
from .qp import WeightedQP, _as_index, _to_y_into, packed_views
from .tasks import ContactWrenchCost, Task

__all__ = ["RATE_TIME", "STRATEGIES", "Solution", "WholeBodyController"]

STRATEGIES = ("OneLevelWeighted", "MultiLevelWeighted")
#: the hierarchical strategy's default time budget per tick (s of CPU time): on Talos an
#: iteration of its solver costs 0.1 to 0.4 ms and the dynamics and rows about 0.5 ms, so
#: 1.5 ms keeps a tick within about 2.5 ms while a transition needs several iterations
#: (the kinematic SOT's solver gets 0.5 ms: its iterations cost about 40 us); the NumPy
#: twin (no compiled kernels) gets ``NUMPY_BUDGET_FACTOR`` times it, as the SOT's does
HIERARCHY_TIME_BUDGET = 1.5e-3

#: Activatable's own begin/end: the tick skips them for an active object without
#: callbacks (a subclass that overrides them is always called)
_BEGIN, _END = Activatable.begin, Activatable.end

#: The default torque rate bound of transitions: each joint's effort limit per
#: ``RATE_TIME`` seconds (N m/s).
RATE_TIME = 0.1


@dataclass
class Solution:
    """The result of a tick.

    Attributes:
        chi: the full solution ``(a, tau, f)`` (the fallback's when not found).
        a, tau, f: its blocks, views of ``chi`` (``f`` every contact's wrench, layout
            order).
        found: whether the problem was solved (constraints met).
        reason: why not, when not found ("" otherwise).
        dynamics_residual: ``||A_dyn chi - c_dyn||_inf`` of the solution.
        rate_limited: whether the torque-rate rows of a transition were enforced.
        budget_hit: the hierarchical strategy's solver stopped at its time or iteration
            budget (its answer: the levels it proved kept, see
            :attr:`WholeBodyController.last_hierarchy`).
    """

    chi: np.ndarray
    a: np.ndarray
    tau: np.ndarray
    f: np.ndarray
    found: bool
    reason: str = ""
    dynamics_residual: float = 0.0
    rate_limited: bool = False
    budget_hit: bool = False


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
        self._hierarchy: HierarchySolver | None = None
        self.setStrategy(strategy)
        self.setRegularisation(regularisation)
        #: the hierarchical strategy's last HierarchyResult (None before its first tick)
        self.last_hierarchy = None
        # the QP kernel and the problem's writer (loaded from the cache; on a machine's
        # first use compiled in the background for the next runs, said on stderr first)
        _jit.prepare(
            "the whole-body controller's kernels",
            ["sotpy.solvers.wbc._kernels", "sotpy.tasks._rowkernels"],
        )
        self.weighted_qp = WeightedQP(self.robot.actuated, self._unactuated)
        self.contact_cost = ContactWrenchCost()
        eff = np.asarray(self.robot.model.effortLimit, dtype=float)[self.robot.actuated]
        rate = np.where(np.isfinite(eff) & (eff > 0) & (eff < 1e30), eff / RATE_TIME, np.inf)
        self.torque_rate = rate
        self._rate_keep = np.flatnonzero(np.isfinite(rate))
        self._assembly: _Assembly | None = None
        self.transition = False  # a transition in progress: the torque rate is bounded
        self._rate_rows = 0  # torque-rate rows (the last constraint rows) of the last problem
        self._keep_rows = 0  # constraint rows unchanged since the previous problem's
        self._warned: set[str] = set()
        self.last: Solution | None = None
        self.last_dynamics: tuple[np.ndarray, np.ndarray] | None = None
        self.last_constraints: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None

    # -- configuration --------------------------------------------------------------------
    def setStrategy(self, strategy: str) -> None:
        """``"OneLevelWeighted"`` or ``"MultiLevelWeighted"``; a change at run time is a
        transition (the torques move to the new strategy's at the bounded rate)."""
        if strategy not in STRATEGIES:
            raise SotpyError(
                f"WholeBodyController: unknown strategy {strategy!r}; expected one of {STRATEGIES}"
            )
        if getattr(self, "strategy", strategy) != strategy:
            self.transition = True
        self.strategy = strategy
        if strategy == "MultiLevelWeighted":
            self._make_hierarchy()  # now (kernels loaded, or their compile started), not at a tick

    @property
    def hierarchy(self) -> HierarchySolver:
        """The solver of the ``MultiLevelWeighted`` strategy, made when first needed (that
        strategy chosen, or one of its settings read or set): a weighted controller
        neither loads nor, on a machine's first run, compiles its kernels."""
        return self._make_hierarchy()

    def _make_hierarchy(self) -> HierarchySolver:
        if self._hierarchy is None:
            h = HierarchySolver(time_budget=HIERARCHY_TIME_BUDGET)
            if not h.jit:
                h.time_budget = HIERARCHY_TIME_BUDGET * NUMPY_BUDGET_FACTOR
            self._hierarchy = h
        return self._hierarchy

    def setTorqueRateLimit(self, rate: object) -> None:
        """The torque rate bound of transitions (N m/s; one value or one per actuated
        joint, > 0, ``inf``: none): ``|tau - tau_prev| <= rate dt`` per tick."""
        r = np.asarray(rate, dtype=float)
        r = np.full(self.robot.na, float(r)) if r.ndim == 0 else r
        if r.shape != (self.robot.na,) or np.isnan(r).any() or (r <= 0).any():
            raise SotpyError(
                f"WholeBodyController: the torque rate limit must be one value or "
                f"{self.robot.na} values > 0 (N m/s, inf: none), got {rate!r}"
            )
        self.torque_rate = r.copy()
        self._rate_keep = np.flatnonzero(np.isfinite(r))

    def setContactCostWeight(self, weight: float) -> None:
        """Weight of the contact wrench distribution cost (:class:`ContactWrenchCost`,
        >= 0; 0 removes it)."""
        self.contact_cost.setWeight(weight)

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
            if c.dim == 6 and not (
                math.isfinite(c.margin) and 0 <= c.margin < min(c.length, c.width) / 2
            ):
                raise SotpyError(
                    f"contact {c.frame!r}: the margin must be >= 0 and less than half the "
                    f"sole's length and width (m), got {c.margin}"
                )
            if isinstance(c.facets, bool) or int(c.facets) != c.facets or c.facets < 3:
                raise SotpyError(
                    f"contact {c.frame!r}: the friction pyramid needs an integer number of "
                    f"facets >= 3, got {c.facets!r}"
                )
            kd_ok = c.kd is None or (math.isfinite(c.kd) and c.kd >= 0)
            if not (math.isfinite(c.kp) and c.kp >= 0 and kd_ok):
                raise SotpyError(
                    f"contact {c.frame!r}: the feedback gains must be finite and >= 0, got "
                    f"kp={c.kp}, kd={c.kd}"
                )
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
        x = self.item(name)
        if x.state in ("inactive", "deactivating"):
            self.transition = True
        x.activate()

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
        if x.state in ("active", "activating"):
            self.transition = True
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
            if x.state in ("inactive", "deactivating"):
                self.transition = True
            x.activate()

    def deactivateTasksAndConstraints(self) -> None:
        for x in self._all():
            if x.state in ("active", "activating"):
                self.transition = True
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
        last = self.last
        if last is not None and last.found and last.f.shape == (self.layout.nf,):
            self.contact_cost.observe(self.layout, last.f)  # the loads of the cost's rows
        live = []
        ramping = False  # a ramp under way (begin() is False only when inactive)
        for objects in (self.tasks, self.constraints, self.contact_states):
            for x in objects.values():
                if (
                    x.state == "active"
                    and x.callbacks["onComputeBegin"] is None
                    and type(x).begin is _BEGIN
                ):
                    live.append(x)  # what begin() does for it: nothing to advance
                elif x.begin(t, dt):
                    live.append(x)
                    ramping = ramping or x.state != "active"
            if objects is self.constraints:
                contacts = len(live)  # the contacts not inactive: those live after it
        contacts = len(live) > contacts
        if ramping:  # activated or deactivated directly, not through this controller
            self.transition = True
        if self._warned or not live or (self.robot.free_flyer and not contacts):
            self._check_active(live, contacts)
        try:
            sol = self.solve(rate=self.transition or ramping)
        finally:
            for x in live:
                if (
                    x.state != "active"
                    or x.callbacks["onComputeEnd"] is not None
                    or type(x).end is not _END
                ):
                    x.end(t, dt)  # (an active object without callbacks: nothing to end)
        if self.transition and not ramping and not self._at_rate_bound(sol):
            self.transition = False  # settled: the torques caught up
        self.last = sol
        return sol

    def _warn(self, key: str, message: str) -> None:
        if key not in self._warned:
            self._warned.add(key)
            warnings.warn(f"WholeBodyController: {message}", SotpyWarning, stacklevel=4)

    def _check_active(self, live: list, contacts: bool) -> None:
        """The warnings of the module doc (once until the condition clears); ``contacts``:
        whether a contact is not inactive."""
        if self.robot.free_flyer and not contacts:
            self._warn(
                "free",
                "no contact is active: the floating base is unconstrained and the robot "
                "falls (activate a contact, or expect a flight phase)",
            )
        else:
            self._warned.discard("free")
        if not live:
            self._warn(
                "nothing",
                "nothing is active (no task, constraint or contact): the solution is the "
                "regularisation's, the robot is not controlled",
            )
        else:
            self._warned.discard("nothing")

    def _rate_bounds(self, dt: float) -> tuple[np.ndarray, np.ndarray] | None:
        """The torque bounds of a transition, or None (no previous torque)."""
        last = self.last
        if last is None or last.tau.shape != (self.robot.na,):
            return None
        if not np.isfinite(last.tau).all():
            return None
        step = self.torque_rate * dt
        return last.tau - step, last.tau + step

    def _at_rate_bound(self, sol: Solution) -> bool:
        """Whether a torque of ``sol`` sits at its rate bound (the transition goes on)."""
        if not sol.rate_limited or self.last is None:
            return False
        step = self.torque_rate * self.robot.dt
        return bool(np.any(np.abs(sol.tau - self.last.tau) >= step * (1.0 - 1e-6)))

    def problem(
        self, rate: bool = False
    ) -> tuple[tuple[np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray, np.ndarray], list]:
        """The current dynamics ``(A, c)``, constraints ``(C, lb, ub)`` and tasks
        ``[(level, E, f, w)]`` (w = diag W; level -1: the contact wrench cost), from the
        last :meth:`RobotModel.update`; ``rate``: with the torque-rate rows of a
        transition (the last constraint rows, if a previous torque exists).

        The arrays are views of buffers kept from tick to tick (rebuilt when the set of
        rows changes: a task or constraint activated, a contact's state): valid until
        the next call; copy them to keep them. Each task and constraint writes its rows
        in place (:meth:`.tasks.Task.write`, :meth:`.constraints.Constraint.write`),
        the constant ones once."""
        robot, layout = self.robot, self.layout
        bounds = self._rate_bounds(robot.dt) if rate else None
        live = []
        for task in self.tasks.values():
            if task.state == "inactive":
                continue
            w, some = task._weights()
            if some:  # w >= 0: a task whose rows all have weight 0 counts for nothing
                live.append((task, w))
        cons = [c for c in self.constraints.values() if c.state != "inactive"]
        counts = tuple([c.count(robot, layout) for c in cons])
        cc = self.contact_constraint
        cost = self.contact_cost.contacts(layout, self.contact_states)
        rate_keep = self._rate_keep if bounds is not None else None
        key = (
            layout,
            tuple([(t, t.level) for t, _ in live]),
            tuple(cons),
            counts,
            cc.structure(layout),
            tuple(cost),
            None if rate_keep is None else len(rate_keep),
        )
        asm = self._assembly
        first = asm is None or asm.key != key
        # the rows before the rate rows keep their places when only those change
        self._keep_rows = 0
        if first and asm is not None and asm.key[:-1] == key[:-1]:
            self._keep_rows = asm.mc - (asm.key[-1] or 0)
        if first:
            asm = self._assembly = _Assembly(
                key, layout, robot, live, cons, counts, cc, self.contact_cost, cost, rate_keep
            )
        try:
            self._write(asm, first, live, cons, cost, rate_keep, bounds)
        except BaseException:
            if first:  # its constant entries may be missing: made again at the next tick
                self._assembly = None
            raise
        if first:
            asm.find_units(live, cons, rate_keep is not None)
        return (asm.A, asm.c), (asm.C, asm.lo, asm.hi), asm.tasks

    def _write(self, asm, first, live, cons, cost, rate_keep, bounds) -> None:
        """Write this tick's rows into ``asm``'s buffers (``first``: they are new, the
        constant entries too); see :meth:`problem`."""
        robot, layout = self.robot, self.layout
        cc = self.contact_constraint
        # the entries that change with the state: by the compiled program (not on a
        # structure's first tick, which writes the constant entries too), else in Python
        program = asm.program
        fused = not first and program is not None and program.run(asm.data, live)
        if not fused:
            A = asm.A
            robot.write_mass_matrix(asm.A_a)
            for c in layout.contacts:
                np.negative(robot.contact_jacobian(c).T, out=A[:, layout.f[c.key]])
            np.negative(robot.b, out=asm.c)
        for i in asm.unfused if fused else range(len(live)):
            task, w = live[i]
            E, f, wv = asm.task_rows[i]
            task.write(robot, layout, E, f, first)
            np.copyto(wv, w)
        for con, (C, lo, hi) in zip(cons, asm.con_rows, strict=True):
            con.write(robot, layout, C, lo, hi, first)
        if not fused or asm.contact_ramps:  # (else the program wrote all that changes)
            C, lo, hi = asm.contact_rows
            cc.write(robot, layout, C, lo, hi, first, contact_rows=not fused)
        if cost and not fused:
            E, _f, wv = asm.cost_rows
            self.contact_cost.write(robot, layout, cost, E, wv, first)
        if rate_keep is not None:
            C, lo, hi = asm.rate_rows
            if first:
                C[np.arange(len(rate_keep)), layout.tau.start + rate_keep] = 1.0
            lo[:] = bounds[0][rate_keep]
            hi[:] = bounds[1][rate_keep]
        self._rate_rows = 0 if rate_keep is None else len(rate_keep)

    def solve(self, rate: bool = False) -> Solution:
        """Solve at the last :meth:`RobotModel.update` (``rate``: with the torque-rate
        rows of a transition; if they make it fail, again without them)."""
        sol = self._solve(rate)
        if not sol.found and sol.rate_limited and self.strategy == "OneLevelWeighted":
            sol = self._solve(False)
        return sol

    def _solve(self, rate: bool) -> Solution:
        self.last_hierarchy = None
        dyn, cons, tasks = self.problem(rate)
        limited = bool(self._rate_rows)
        self.last_dynamics, self.last_constraints = dyn, cons
        try:
            if self.strategy == "OneLevelWeighted":
                chi, ok, reason = self._weighted(dyn, cons, tasks)
            else:
                chi, ok, reason = self._multilevel(dyn, cons, tasks)
        except (np.linalg.LinAlgError, ValueError) as exc:
            chi, ok, reason = None, False, f"solver error: {exc}"
        res = None
        if (
            ok
            and self.strategy == "OneLevelWeighted"
            and self.weighted_qp.last_residual is not None
        ):
            res = self.weighted_qp.last_residual  # the compiled guess: checked, finite
        elif ok and not np.all(np.isfinite(chi)):
            ok, reason = False, "non-finite solution"
        sol = self._split(chi, True, "", dyn, res) if ok else self._fallback(reason)
        sol.rate_limited = limited
        if self.strategy != "OneLevelWeighted" and self.last_hierarchy is not None:
            sol.budget_hit = self.last_hierarchy.budget_hit
        return sol

    def _split(self, chi: np.ndarray, found: bool, reason: str, dyn, res=None) -> Solution:
        """The Solution of ``chi`` (its blocks are views) and its residual in ``dyn``
        (``res`` when it is known)."""
        L = self.layout
        if res is None:
            A, c = dyn
            res = float(np.abs(A @ chi - c).max()) if len(c) else 0.0
        return Solution(
            chi, chi[: L.nv], chi[L.nv : L.nv + L.na], chi[L.nv + L.na :], found, reason, res
        )

    def _fallback(self, reason: str) -> Solution:
        """The torques of a tick without a solution: from the last torques sent, a step of
        at most the torque-rate bound towards gravity compensation ``S g(q)``,
        ``tau = tau_prev + clip(S g - tau_prev, -rate dt, rate dt)``, within the torque
        limits (``S g`` itself on the first tick, or with no rate bound). A tick whose
        solver stopped at its budget thus holds the robot about where the last solution
        held it, instead of a jump to gravity compensation, which on a standing
        humanoid ignores the contact forces the legs carry."""
        L, robot = self.layout, self.robot
        tau = robot.S @ robot.g
        last = self.last
        if last is not None and last.tau.shape == tau.shape and np.isfinite(last.tau).all():
            step = self.torque_rate * robot.dt
            tau = last.tau + np.clip(tau - last.tau, -step, step)
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
        return self._split(chi, False, reason, (A, c))

    # -- strategies -----------------------------------------------------------------------------
    def _weighted(self, dyn, cons, tasks) -> tuple[np.ndarray | None, bool, str]:
        """One QP over ``y = (a, f)``, the torques eliminated through the actuated rows of
        the equations of motion (:mod:`.qp`): the same optimum as over ``chi`` with the
        dynamics as an equality (82 -> 50 variables and 38 -> 6 equalities on Talos),
        the previous tick's active set tried first, DAQP otherwise. The answer is
        checked against the constraints over ``chi`` before it is used."""
        qp = self.weighted_qp
        asm = self._assembly
        if asm is not None and asm.tasks is tasks:  # the stacked rows of problem()
            x, reason = qp.solve_rows(
                self.layout, *dyn, asm.E, asm.f, asm.w, *cons, self.regularisation, asm.data,
                self._keep_rows, asm.unit, asm,
            )  # fmt: skip
        else:
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
        """The strict levels (see the module doc) over ``y = (a, f)``: the torques
        eliminated through the actuated rows of the equations of motion, as the
        weighted strategy does (``tau = T y + t``; on Talos 82 -> 50 variables and 38 ->
        6 equality rows in the hard level), every constraint and task row mapped to
        ``y`` and written straight into the solver's own buffers
        (:meth:`HierarchySolver.stacked`); the final minimum-norm criterion is then on
        the accelerations and wrenches. ``chi`` is rebuilt from ``y``. ``tasks`` are the
        stacked rows of :meth:`problem` (``self._assembly``)."""
        A, c = dyn
        C, lo, hi = cons
        if not (lo <= hi + 1e-12).all():  # a NaN bound fails the comparison too
            return None, False, "a constraint has lower > upper (infeasible bounds)"
        L, asm = self.layout, self._assembly
        nv, na = L.nv, L.na
        r, u = self.robot.actuated, self._unactuated
        ny = L.n - na
        Tt = np.empty((na, ny))
        Tt[:, :nv] = A[r, :nv]
        Tt[:, nv:] = A[r, nv + na :]
        tt = -c[r]
        nu, nr = len(u), self._rate_rows
        mc = C.shape[0]
        # level 0: the unactuated dynamics and the constraints but the rate rows; then
        # the rate rows of a transition (their least violation), then the task levels
        sizes = [nu + mc - nr] + ([nr] if nr else []) + asm.level_sizes
        h = self.hierarchy
        if h.n != ny:  # the contacts changed: another number of variables
            h.reset()
            h.n = ny
        H, hlo, hup, starts = h.stacked(sizes)
        H[:nu, :nv] = A[u, :nv]
        H[:nu, nv:] = A[u, nv + na :]
        hlo[:nu] = c[u]
        hup[:nu] = c[u]
        shift = _to_y_into(C, H[nu : nu + mc], nv, na, Tt, tt)
        hlo[nu : nu + mc] = lo
        hup[nu : nu + mc] = hi
        if shift is not None:
            hlo[nu : nu + mc] -= shift
            hup[nu : nu + mc] -= shift
        # each task level's rows scaled by sqrt(w): the level's least squares is weighted
        first = 2 if nr else 1
        for k, rows in enumerate(asm.levels):
            s, e = starts[first + k], starts[first + k + 1]
            Hk, fk = H[s:e], hlo[s:e]
            shift = _to_y_into(asm.E[rows], Hk, nv, na, Tt, tt)
            fk[:] = asm.f[rows]
            if shift is not None:
                fk -= shift
            sw = np.sqrt(asm.w[rows])
            Hk *= sw[:, None]
            fk *= sw
            hup[s:e] = fk
        res = self.last_hierarchy = h.solve_stacked()
        if not res.feasible:
            if res.budget_hit and res.solved == 0:
                return (
                    None,
                    False,
                    (
                        f"the solver stopped at its {res.status} budget before it met the"
                        f" constraints (violation {res.residuals[0]:.3g})"
                    ),
                )
            return None, False, f"the constraints cannot be met (violation {res.residuals[0]:.3g})"
        y = np.asarray(res.x, dtype=float)
        chi = np.empty(L.n)
        chi[:nv] = y[:nv]
        chi[nv : nv + na] = Tt @ y + tt
        chi[nv + na :] = y[nv:]
        return chi, True, ""


class _Assembly:
    """The buffers of one structure of the problem (which tasks, constraints, contact
    states, cost and rate rows): the dynamics ``A`` (``n`` columns; its torque block
    ``-S^T`` written once), the stacked task rows ``E, f, w`` and constraint rows ``C,
    lo, hi``, all views of one flat array ``data`` (the compiled QP kernel's input,
    :func:`._kernels.data_layout`), and each object's views into them."""

    def __init__(self, key, layout, robot, live, cons, counts, cc, wrench_cost, cost, rate_keep):
        self.key = key
        ncontact = cc.count(robot, layout)
        plan = cc._planned(layout)  # the contact constraint's blocks, layout order
        n, nv = layout.n, layout.nv
        sizes = [t.size for t, _ in live]
        ncost = sum(2 if c.dim == 3 else 5 for c in cost)
        m = sum(sizes) + ncost
        nrate = 0 if rate_keep is None else len(rate_keep)
        mc = sum(counts) + ncontact + nrate
        self.m, self.mc = m, mc
        self.data = np.zeros(data_layout(nv, layout.na, n, m, mc)["size"][0])
        v = packed_views(self.data, nv, layout.na, n, m, mc)
        self.A, self.c, self.E, self.f, self.w = v["A"], v["c"], v["E"], v["f"], v["w"]
        self.C, self.lo, self.hi = v["C"], v["lo"], v["hi"]
        self.A[:, layout.tau] = robot.minus_St
        self.A_a = self.A[:, layout.a]
        self.task_rows, self.tasks, self._task_starts = [], [], []
        r = 0
        for (task, _w), k in zip(live, sizes, strict=True):
            rows = (self.E[r : r + k], self.f[r : r + k], self.w[r : r + k])
            self.task_rows.append(rows)
            self._task_starts.append(r)
            self.tasks.append((task.level, *rows))
            r += k
        self.cost_rows = None
        if ncost:
            self.cost_rows = (self.E[r:], self.f[r:], self.w[r:])
            self.tasks.append((-1, *self.cost_rows))
        # the hierarchical strategy's task levels, in order: the rows of each (a slice
        # when they are contiguous); the contact wrench cost joins the last level
        spans, r = [], 0
        for (task, _w), k in zip(live, sizes, strict=True):
            spans.append((task.level, r, r + k))
            r += k
        order = sorted({lvl for lvl, _, _ in spans}) or [-1]
        if ncost:
            spans.append((order[-1], r, m))
        self.levels, self.level_sizes = [], []
        for lvl in order:
            rows = np.concatenate([np.arange(a, b) for k, a, b in spans if k == lvl] or [[]])
            if len(rows):
                self.levels.append(_as_index(rows))
                self.level_sizes.append(len(rows))
        self.con_rows = []
        r = 0
        for k in counts:
            self.con_rows.append((self.C[r : r + k], self.lo[r : r + k], self.hi[r : r + k]))
            r += k
        # the contact constraint's blocks of rows and what the QP kernel may skip in them
        self._tau = layout.tau
        self._contact_blocks = []
        c0 = r
        for c, state, nf, ramp, _sl, _st in plan:
            d = c.dim
            if state == "inactive":  # f_c = 0: rows of the identity
                self._contact_blocks.append((GENERAL, c0, c0 + d))
                c0 += d
                continue
            self._contact_blocks += [
                (NO_TAU, c0, c0 + d),  # J_c a = ...: the program writes their a columns
                (CONSTANT, c0 + d, c0 + d + nf),  # friction and CoP
                (GENERAL, c0 + d + nf, c0 + d + nf + ramp),  # the ramp's: the identity
            ]
            c0 += d + nf + ramp
        self.contact_rows = (
            self.C[r : r + ncontact],
            self.lo[r : r + ncontact],
            self.hi[r : r + ncontact],
        )
        r += ncontact
        self.rate_rows = (self.C[r:], self.lo[r:], self.hi[r:])
        self.live_tasks = [t for t, _w in live]  # the tasks with rows, in order
        self.unit: np.ndarray | None = None  # the rows of the identity (find_units)
        # whether a contact has ramp rows (their bounds change at each tick)
        self.contact_ramps = any(ramp for _c, _s, _nf, ramp, _sl, _st in plan)
        # the compiled writer of the entries that change with the state (None: the
        # kernels are not compiled) and the live tasks it does not write (by index)
        self.program = None
        self.unfused = list(range(len(live)))
        if _rowkernels.write_problem is not None:
            self.program = ProblemProgram(
                robot, layout, plan, sum(counts),
                [(t, r0) for (t, _w), r0 in zip(live, self._task_starts, strict=True)],
                (wrench_cost, cost, sum(sizes)), (nv, n, m, mc),
            )  # fmt: skip
            self.unfused = sorted(set(self.unfused) - set(self.program.fused))

    def find_units(self, live: list, cons: list, rate: bool) -> None:
        """After the first write: :attr:`unit`, what each task row then constraint row
        is, for the QP kernel (``_kernels.solve``): the column of a row of the identity
        (constant rows: their object's ``unit_rows``, the ramps' and the torque rate's),
        ``NO_TAU`` for a row without torque entries that the program or a ``terms()``
        task writes (only its ``a`` columns change), ``CONSTANT`` for the contacts'
        friction rows, ``GENERAL`` otherwise."""
        tau = self._tau
        unit = np.full(self.m + self.mc, GENERAL, dtype=np.intp)
        for (task, _w), (E, _f, _wv), r in zip(live, self.task_rows, self._task_starts,
                                                strict=True):  # fmt: skip
            if owns(task, "unit_rows") and task.unit_rows:
                unit[r : r + len(E)] = row_kinds(E, tau, GENERAL)
            elif owns(task, "terms"):
                unit[r : r + len(E)] = row_kinds(E, tau, NO_TAU, units=False)
        if self.cost_rows is not None:  # constant rows over the wrenches
            E = self.cost_rows[0]
            unit[self.m - len(E) : self.m] = row_kinds(E, tau, NO_TAU, units=False)
        r = self.m
        for con, (C, _lo, _hi) in zip(cons, self.con_rows, strict=True):
            if owns(con, "unit_rows") and con.unit_rows:
                unit[r : r + len(C)] = row_kinds(C, tau, GENERAL)
            r += len(C)
        for kind, a, b in self._contact_blocks:  # the contact constraint's rows
            rows = self.C[a:b]
            unit[self.m + a : self.m + b] = row_kinds(rows, tau, kind, units=kind != NO_TAU)
        if rate:
            C = self.rate_rows[0]
            unit[self.m + self.mc - len(C) :] = row_kinds(C, tau, GENERAL)
        self.unit = unit
