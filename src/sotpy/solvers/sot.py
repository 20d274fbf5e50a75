r"""The ``SOT`` entity: a stack of tasks solved with strict priorities.

::

    sot = SOT("sot", robot.dynamic)          # nv from the dynamic's model
    # or SoT's: sot = SOT("sot"); sot.setSize(nv) (no joint-limit level then)
    plug(robot.device.state, sot.position)   # done by the constructor when it can
    sot.dt.value = 0.001                     # control period (s), for the joint limits
    sot.push(taskFeet)                       # highest priority first
    sot.push(taskRightWrist)
    plug(sot.control, robot.device.control)  # the device in velocity mode

Each tick ``control`` is the joint velocity :math:`\dot q` (size ``nv``: a free flyer's
twist in its own frame, then the joints) that solves, lexicographically (see
:mod:`sotpy.solvers.hierarchy` for the exact definition, damping and rank tolerance):

0. the joint limits, a hard level (on by default, ``setJointLimits(False)`` to remove
   it): for every one-dimensional joint with finite limits,
   :math:`\max(-\bar v, (q_{min} - q)/dt) \le \dot q_j \le \min(\bar v, (q_{max} - q)/dt)`,
   so that one period of integration cannot leave the limits, with :math:`\bar v` the
   velocity limit (``upperVl``);
1. then every pushed task in order: ``J qdot = task`` for an equality task
   (``task = -gain * error``), ``lower <= J qdot <= upper`` for an inequality task.

The ``damping`` input (default 0) is the solver's damping :math:`\lambda` inside each
task's level; ``setTaskDamping(task, lambda)`` sets a task's own (e.g. damp only a
reaching task that may go out of reach, keep the feet exact). The joint-limit level is
never damped (a hard level). Stack edits (``push``, ``remove``, ``up``, ``down``,
``clear``) change the dependencies of ``control``: they take effect at its next
evaluation (the next tick of a running loop), and a refused edit leaves the stack as it
was.

After each evaluation, ``lastResult`` holds the solver's
:class:`~sotpy.solvers.hierarchy.HierarchyResult` (residual and rank of every level,
the joint-limit level first when enabled). The *hard* level is the joint-limit level, or
without it a first task that is an inequality (a constraint); a first equality task is a
goal, which may be out of reach without any warning. A hard level that cannot be
satisfied still gives the least-violating control, and the SOT says so with a
``SotpyWarning`` (once until it is satisfied again) and ``lastResult.feasible``. (The
joint-limit level itself is always feasible: its bounds are clipped so that
``lower <= upper``.)

In a running loop (a compiled plan) the SOT reads each task from its features' inputs
and writes ``J`` and ``-lambda e`` (a ``TaskInequality``: ``J`` and both bounds) straight
into the rows it hands to the solver, with the joint-limit level, in one compiled call
of a row program (:mod:`sotpy.tasks.rows`), instead of one plan step per feature and
task signal; the dependencies of ``control``, the task signals and the control are
unchanged.
``setTaskFusion(False)`` reads every task through its signals.
"""

from __future__ import annotations

import functools
import math
import warnings
from typing import Any, NamedTuple

import numpy as np

from .. import _jit
from .._jit import refused
from ..errors import (
    BudgetWarning,
    CommandError,
    EntityError,
    SignalTypeError,
    SotpyError,
    SotpyWarning,
)
from ..graph import DOUBLE, MATRIX, VECTOR, Entity, Input, Output, command, plug
from ..graph.pool import pool
from ..tasks import _rowkernels
from ..tasks.rows import Gather, RowOp, RowProgram, computedByOwnCallback, levelOp
from ..tasks.task import TaskAbstract
from .hierarchy import HierarchySolver, checked_max_iter, checked_time_budget

__all__ = ["SOT"]

_NO_LIMIT = 1e30  # a limit at least this large is no limit


class _LimitRows(NamedTuple):
    """The joint-limit level's rows for one set of limit arrays (see
    :meth:`SOT._limitRows`): the arrays they came from, the bounded joints' indices in
    ``q`` and ``v``, their limits (inf where none), ``-vm``, the level's matrix and
    ``lim = (ql, qu, vm)`` stacked for the row program's ``LIMITS`` operation."""

    lower: Any
    upper: Any
    vmax: Any
    iq: np.ndarray
    iv: np.ndarray
    ql: np.ndarray
    qu: np.ndarray
    vm: np.ndarray
    nvm: np.ndarray
    A: np.ndarray
    lim: np.ndarray


class SOT(Entity):
    """Stack of tasks with strict priorities; ``control`` is the joint velocity."""

    damping = Input(DOUBLE, default=0.0, doc="damping inside each level (0: exact)")
    position = Input(VECTOR, doc="q, for the joint-limit level (plug the device state)")
    lowerJl = Input(VECTOR, doc="lower position limits (nq), from Dynamic")
    upperJl = Input(VECTOR, doc="upper position limits (nq), from Dynamic")
    upperVl = Input(VECTOR, doc="velocity limits (nv), from Dynamic")
    dt = Input(DOUBLE, doc="control period (s), for the joint-limit level")

    @Output(VECTOR, timeDependent=False, doc="joint velocity qdot (nv)")
    def control(self, *values: Any) -> np.ndarray:
        """Solve the stack (see the module doc)."""
        return self._solve(values)

    def __init__(self, name: str, dynamic: Entity | None = None) -> None:
        model = None
        if dynamic is not None:
            model = getattr(dynamic, "model", None)
            if model is None or not hasattr(model, "nv"):
                raise EntityError(
                    f"SOT({name}): expected a Dynamic entity (with a Pinocchio model), got "
                    f"{dynamic!r}"
                )
        self._model = model
        self._nv: int | None = None
        self._stack: list[TaskAbstract] = []
        # SoT's SOT has no joint-limit level: without a Dynamic there are no limits to
        # read, so there is none either
        self._jointLimits = model is not None
        # the solver's and the task rows' kernels, compiled together on a first run
        _jit.prepare(
            "the hierarchical solver and the task rows",
            ["sotpy.solvers._activeset_jit", "sotpy.tasks._rowkernels"],
        )
        self._solver = HierarchySolver()
        self._last: list[Any] = [None]  # lastResult (set in place at every tick)
        self._warned = False
        self._budgetWarned = False
        #: ticks whose solve stopped at its iteration or time budget
        self.budgetHits = 0
        self._limits: _LimitRows | None = None
        self._taskDamping: dict[str, float] = {}
        # (row program, level sizes, level ends) of the last tick written into the SOT's
        # own buffers: the next ticks of that program write in place into the solver's
        self._inPlace: tuple[Any, tuple[int, ...], np.ndarray] | None = None
        # one-dimensional joints: their index in q and in v
        iq, iv = [], []
        if model is not None:
            for j in range(1, model.njoints):
                joint = model.joints[j]
                if joint.nq == 1 and joint.nv == 1:
                    iq.append(joint.idx_q)
                    iv.append(joint.idx_v)
            self._qShape = (int(model.nq),)
            self._setSize(int(model.nv))
        self._iq = np.array(iq, dtype=np.int64)
        self._iv = np.array(iv, dtype=np.int64)
        if dynamic is not None:
            for sig in ("lowerJl", "upperJl", "upperVl"):
                plug(dynamic.signal(sig), self.signal(sig))
            source = dynamic.signal("position").source
            if source is not None:
                plug(source, self.position)
        self._rewire()
        self._fuse = False
        self.setTaskFusion(_rowkernels.write_rows is not None)

    @property
    def lastResult(self) -> Any:
        """The solver's result of the last evaluation of ``control`` (a
        :class:`~sotpy.solvers.hierarchy.HierarchyResult`; None before the first)."""
        return self._last[0]

    @lastResult.setter
    def lastResult(self, result: Any) -> None:
        self._last[0] = result

    @property
    def nv(self) -> int:
        """The size of ``control`` (the robot's nv): from the Dynamic, from ``setSize``,
        or from the Jacobian of the first task pushed."""
        n = self._nv
        if n is None:
            raise SotpyError(
                f"SOT({self.name}): the size of the control is not known yet: call "
                f"{self.name}.setSize(nv) (SoT's), push a task whose Jacobian can be "
                "computed, or create SOT(name, dynamic)"
            )
        return n

    def _setSize(self, nv: int) -> None:
        self._nv = nv
        self._rowsA = np.empty((64, nv))  # the fused tasks' rows (see _fusion)
        self._rowsB = np.empty(64)
        self._rowsU = np.empty(64)  # the fused inequality tasks' upper bounds
        self._inPlace = None

    @command
    def setSize(self, nv: int) -> None:
        """Set the size of the control (SoT's ``setSize``, the number of DoFs nv > 0).

        With a Dynamic the size is its model's nv and only that value is accepted; without
        one, it may be set before any task is pushed, or to the width of the tasks in the
        stack."""
        if nv <= 0:
            raise CommandError(f"SOT({self.name}).setSize: expected a size > 0, got {nv}")
        if self._model is not None and nv != self._model.nv:
            raise CommandError(
                f"SOT({self.name}).setSize: the size is nv = {self._model.nv}, the model's "
                f"(SOT built on a Dynamic), got {nv}"
            )
        if self._nv is not None and nv != self._nv and self._stack:
            raise CommandError(
                f"SOT({self.name}).setSize: the tasks in the stack have {self._nv} columns, "
                f"got {nv}; clear() the stack first"
            )
        if nv != self._nv:
            self._setSize(nv)
            self.control.setReady()

    def _inferSize(self, task: TaskAbstract) -> None:
        """Take the size from ``task``'s Jacobian (or its features' Jacobian inputs) when
        it is not known yet."""
        if self._nv is not None:
            return
        candidates = [task.jacobian]
        for f in getattr(task, "_features", ()):
            candidates += [s for s in f.signals() if s.type is MATRIX and s.direction == "input"]
        for sig in candidates:
            try:
                J = sig.value
            except SotpyError:
                continue
            if np.ndim(J) == 2 and np.shape(J)[1] > 0:
                self._setSize(int(np.shape(J)[1]))
                return

    # -- the stack --------------------------------------------------------------------
    def _task(self, task: TaskAbstract | str, cmd: str) -> TaskAbstract:
        if isinstance(task, str):
            if not pool.hasEntity(task):
                raise SotpyError(
                    f"SOT({self.name}).{cmd}: no entity named {task!r} in the pool; "
                    f"the stack is unchanged"
                )
            task = pool.getEntity(task)  # type: ignore[assignment]
        if not isinstance(task, TaskAbstract):
            raise SotpyError(
                f"SOT({self.name}).{cmd}: {task!r} is not a task (Task or TaskInequality); "
                "the stack is unchanged"
            )
        return task

    def _index(self, task: TaskAbstract, cmd: str) -> int:
        for i, t in enumerate(self._stack):
            if t is task:
                return i
        raise SotpyError(
            f"SOT({self.name}).{cmd}: {task.name} is not in the stack "
            f"({', '.join(self.list()) or 'empty'})"
        )

    @command
    def push(self, task: Any) -> None:
        """Add ``task`` (an entity or its name) at the lowest priority."""
        task = self._task(task, "push")
        if any(t is task for t in self._stack):
            raise SotpyError(f"SOT({self.name}).push: {task.name} is already in the stack")
        self._inferSize(task)
        self._checkWidth(task, "push")
        self._edit([*self._stack, task])

    @command
    def remove(self, task: Any) -> None:
        """Remove ``task`` from the stack."""
        task = self._task(task, "remove")
        i = self._index(task, "remove")
        self._edit(self._stack[:i] + self._stack[i + 1 :])

    @command
    def rm(self, task: Any) -> None:
        """Remove ``task`` from the stack (sot-dyninv's name of ``remove``)."""
        self.remove(task)

    @command
    def pop(self) -> str:
        """Remove the last (lowest priority) task; returns its name."""
        if not self._stack:
            raise SotpyError(f"SOT({self.name}).pop: the stack is empty")
        last = self._stack[-1]
        self._edit(self._stack[:-1])
        return last.name

    @command
    def dispStack(self) -> str:
        """The stack as text, one ``| name`` line per task, highest priority first
        (sot-dyninv's ``dispStack``, which scripts split on ``|``)."""
        lines = ["+-----------------", f"+   SOT {self.name}", "+-----------------"]
        lines += [f"| {t.name}" for t in self._stack]
        return "\n".join(lines) + "\n"

    @command
    def up(self, task: Any) -> None:
        """Move ``task`` one level up (higher priority)."""
        task = self._task(task, "up")
        i = self._index(task, "up")
        if i > 0:
            s = list(self._stack)
            s[i - 1], s[i] = s[i], s[i - 1]
            self._edit(s)

    @command
    def down(self, task: Any) -> None:
        """Move ``task`` one level down (lower priority)."""
        task = self._task(task, "down")
        i = self._index(task, "down")
        if i < len(self._stack) - 1:
            s = list(self._stack)
            s[i + 1], s[i] = s[i], s[i + 1]
            self._edit(s)

    @command
    def clear(self) -> None:
        """Remove every task."""
        self._edit([])

    @command
    def list(self) -> list[str]:
        """Names of the tasks, highest priority first."""
        return [t.name for t in self._stack]

    @command
    def display(self) -> None:
        """Print the stack, highest priority first."""
        print(f"+-----------------\n+   SOT {self.name}\n+-----------------")
        if self._jointLimits:
            print("| 0. joint limits (hard)")
        for i, t in enumerate(self._stack, start=1):
            kind = "inequality" if t.isInequality else "equality"
            print(f"| {i}. {t.name} ({t.className}, {kind})")
        print("+-----------------")

    @command
    def setTaskDamping(self, task: Any, damping: float) -> None:
        """Damping of ``task``'s level (finite, >= 0), instead of the ``damping`` input."""
        task = self._task(task, "setTaskDamping")
        if not (math.isfinite(damping) and damping >= 0.0):
            raise CommandError(
                f"SOT({self.name}).setTaskDamping: the damping of {task.name} must be "
                f"finite and >= 0, got {damping}"
            )
        self._taskDamping[task.name] = float(damping)
        self.control.setReady()

    @command
    def unsetTaskDamping(self, task: Any) -> None:
        """``task``'s level follows the ``damping`` input again."""
        task = self._task(task, "unsetTaskDamping")
        self._taskDamping.pop(task.name, None)
        self.control.setReady()

    @command
    def getTaskDamping(self, task: Any) -> float:
        """The damping used for ``task``'s level now."""
        task = self._task(task, "getTaskDamping")
        return self._taskDamping.get(task.name, float(self.damping.value))

    @command
    def setJointLimits(self, enabled: bool) -> None:
        """Keep (default) or drop the joint-limit level."""
        self._jointLimits = enabled
        self._rewire()

    @command
    def setTimeBudget(self, seconds: float | None) -> None:
        """The solver's time budget per tick, in seconds of the ticking thread's CPU time
        (finite, > 0; ``None`` from Python: no time budget, for offline runs). A tick that
        reaches it returns the best control proven so far (see ``docs/solvers.md``)."""
        now = self._solver.time_budget
        self._solver.time_budget = checked_time_budget(
            f"SOT({self.name}).setTimeBudget", seconds, now
        )
        self.control.setReady()

    @command
    def getTimeBudget(self) -> float | None:
        """The solver's time budget per tick (s of CPU time; ``None``: none)."""
        return self._solver.time_budget

    @command
    def setColdTimeBudget(self, seconds: float | None) -> None:
        """The budget of a tick without the full warm start (the first tick, the first
        after a task is pushed or a level changes size), when larger than the time budget
        (s of CPU time; finite, > 0; ``None`` from Python: the same budget; default 2 ms)."""
        now = self._solver.cold_time_budget
        self._solver.cold_time_budget = checked_time_budget(
            f"SOT({self.name}).setColdTimeBudget", seconds, now
        )
        self.control.setReady()

    @command
    def getColdTimeBudget(self) -> float | None:
        """The budget of a tick without the full warm start (s; ``None``: the same)."""
        return self._solver.cold_time_budget

    @command
    def setMaxIterations(self, n: int) -> None:
        """The solver's iteration budget per tick (equality-hierarchy solves, >= 1)."""
        now = self._solver.max_iter
        self._solver.max_iter = checked_max_iter(f"SOT({self.name}).setMaxIterations", n, now)
        self.control.setReady()

    @command
    def getMaxIterations(self) -> int:
        """The solver's iteration budget per tick."""
        return self._solver.max_iter

    @command
    def getSize(self) -> int:
        """nv, the size of ``control`` (raises while it is not known)."""
        return self.nv

    def _edit(self, stack: list[TaskAbstract]) -> None:
        old = self._stack
        self._stack = stack
        try:
            self._rewire()
        except BaseException:
            self._stack = old
            self._rewire()
            raise

    def _headDeps(self) -> list[Any]:
        """What ``control`` reads before the tasks (see :meth:`_head`)."""
        deps: list[Any] = [self.damping]
        if self._jointLimits:
            deps += [self.position, self.lowerJl, self.upperJl, self.upperVl, self.dt]
        return deps

    def _rewire(self) -> None:
        deps = self._headDeps()
        for t in self._stack:
            deps.append(t.jacobian)
            deps += [t.lower, t.upper] if t.isInequality else [t.task]
        self.control.setDependencies(deps)

    def _checkWidth(self, task: TaskAbstract, cmd: str) -> None:
        """Refuse a task whose Jacobian is readable now and has the wrong width."""
        try:
            J = task.jacobian.value
        except SotpyError:
            return  # not computable yet (unplugged inputs): checked at each solve
        if np.ndim(J) != 2 or np.shape(J)[1] != self.nv:
            raise SignalTypeError(
                f"SOT({self.name}).{cmd}: {task.jacobian.name} has shape {np.shape(J)}, "
                f"expected (m, {self.nv}) (nv of the robot); the stack is unchanged"
            )

    def graphClusters(self) -> list[tuple[str, list[Entity]]]:
        """The stack, drawn by :func:`~sotpy.graph.writeGraph` as a magenta cluster of the
        tasks in priority order, chained by red edges."""
        return [(f"SOT {self.name}", list(self._stack))]

    # -- solve ------------------------------------------------------------------------
    def _solve(self, values: tuple[Any, ...]) -> np.ndarray:
        nv = self.nv
        it = iter(values)
        levels, lams, damping = self._head(it)
        overrides = self._taskDamping
        ndarray = np.ndarray
        for task in self._stack:
            J = next(it)
            if type(J) is not ndarray or J.ndim != 2 or J.shape[1] != nv:
                raise SignalTypeError(
                    f"SOT({self.name}): {task.jacobian.name} has shape {np.shape(J)}, "
                    f"expected (m, {nv})"
                )
            if task.isInequality:
                levels.append((J, next(it), next(it)))
            else:
                b = next(it)
                levels.append((J, b, b))
            lams.append(overrides.get(task.name, damping) if overrides else damping)
        return self._finish(levels, lams)

    def _head(self, it: Any) -> tuple[list[Any], list[float], float]:
        """The damping and the joint-limit level, from the first values of ``control``'s
        dependencies."""
        damping = float(next(it))
        if not (math.isfinite(damping) and damping >= 0.0):
            raise SignalTypeError(
                f"{self.damping.name}: expected a finite damping >= 0, got {damping}"
            )
        levels: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = []
        lams: list[float] = []
        if self._jointLimits:
            levels.append(self._limitLevel(next(it), next(it), next(it), next(it), next(it)))
            lams.append(0.0)  # the joint limits: hard, never damped
        return levels, lams, damping

    def _finish(self, levels: list[Any], lams: list[float]) -> np.ndarray:
        """Solve ``levels``, keep the result, warn about an infeasible hard level."""
        if not levels:
            return np.zeros(self.nv)
        # one number when every level has the same damping (the usual undamped stack):
        # the solver then skips its per-level parsing
        return self._accept(self._solver.solve(levels, damping=lams if any(lams) else 0.0))

    def _accept(self, result: Any) -> np.ndarray:
        """Keep ``result`` as ``lastResult``, warn about an infeasible hard level."""
        self._last[0] = result
        hard = self._jointLimits or self._stack[0].isInequality
        if hard and not result.feasible:
            if not self._warned:
                self._warned = True
                first = "the joint limits" if self._jointLimits else self._stack[0].name
                warnings.warn(
                    f"SOT({self.name}): the hard level ({first}) cannot be satisfied "
                    f"(violation {result.residuals[0]:.3g}); the control is the least "
                    "violating one (see sot.lastResult)",
                    SotpyWarning,
                    stacklevel=3,
                )
        elif self._warned:
            self._warned = False
        if result.status != "optimal":
            self.budgetHits += 1
            pool.budgetHits += 1
            if not self._budgetWarned:
                self._budgetWarned = True
                warnings.warn(
                    f"SOT({self.name}): the solver stopped at its {result.status} budget"
                    f" (time budget {self._solver.time_budget}, max iterations"
                    f" {self._solver.max_iter}): {result.reason}. Said once until it converges"
                    " again; sot.budgetHits and the loop's stats count every such tick",
                    BudgetWarning,
                    stacklevel=3,
                )
        elif self._budgetWarned:
            self._budgetWarned = False
        return result.x

    # -- fused evaluation of the tasks ------------------------------------------------
    def _fusion(self) -> tuple[tuple[Any, ...], Any] | None:
        """The plan's evaluation of ``control`` (see
        :meth:`~sotpy.graph.signal.OutputSignal.setPlanFusion`): one row program
        (:mod:`sotpy.tasks.rows`) writes the joint limits and every task's rows into
        the solver's buffers, the tasks with row operations from their features'
        inputs, the others from their signals. None (the usual step) when no task has
        row operations."""
        if not computedByOwnCallback(self.control, SOT.control.fn):
            return None
        # the stack as it is now (an edit recompiles the plan, which calls this again)
        ops: list[RowOp] = [self._limitsOp()] if self._jointLimits else []
        fused = False
        for t in self._stack:
            task_ops = t._rowOps()  # type: ignore[attr-defined]
            if task_ops is None:
                bounds = (t.lower, t.upper) if t.isInequality else (t.task, t.task)  # type: ignore[attr-defined]
                ops.append(levelOp(t.jacobian, *bounds))
            else:
                ops += task_ops
                fused = True
        if not fused:
            return None
        program = RowProgram(ops)
        equalities = (False,) * self._jointLimits + tuple(not t.isInequality for t in self._stack)
        solve = functools.partial(self._solveFused, program, equalities, all(equalities))
        return (self.damping, *program.sources), solve

    def _limitsOp(self) -> RowOp:
        """The joint-limit level as a ``LIMITS`` operation (the rows of
        :meth:`_limitLevel`, from :meth:`_limitRowsFor`)."""
        ndarray, shape = np.ndarray, self._qShape

        def bind(at: tuple[int, ...]) -> Gather:
            aiq, aiv, aq, alim, sdt = at

            def gather(v: Any, o: int, args: list[Any], scal: np.ndarray, n: int) -> bool:
                q, lower, upper, vmax, dt = v[o : o + 5]
                rows = self._limitRowsFor(lower, upper, vmax)
                if type(q) is not ndarray or q.shape != shape or type(dt) is not float:
                    return False
                if not dt > 0.0:
                    return False
                args[aiq], args[aiv], args[aq], args[alim] = rows.iq, rows.iv, q, rows.lim
                scal[sdt] = dt
                return True

            return gather

        sources = (self.position, self.lowerJl, self.upperJl, self.upperVl, self.dt)
        return RowOp(_rowkernels.LIMITS, "iivms", sources, bind)

    def _fromSignals(self) -> np.ndarray:
        """The control from the task signals (their callbacks raise what is wrong)."""
        return self._solve(tuple(s.value for s in self.control._deps))

    def _solveFused(
        self,
        program: RowProgram,
        equalities: tuple[bool, ...],
        equalityOnly: bool,
        damping: Any,
        *values: Any,
    ) -> np.ndarray:
        """The control, the rows written by ``program``: in place into the solver's
        buffers when the level sizes are those of the previous tick, else into the
        SOT's own buffers and solved as levels. ``equalities`` says which levels are
        equalities (``equalityOnly``: all of them). Anything the program refuses goes
        through the signals."""
        if type(damping) is not float or not 0.0 <= damping < math.inf:
            return self._fromSignals()  # the damping's own error
        lams: Any = 0.0
        overrides = self._taskDamping
        if overrides or damping:
            per = [overrides.get(t.name, damping) for t in self._stack] if overrides else None
            lams = [0.0] * self._jointLimits + (per or [damping] * len(self._stack))
            if not any(lams):
                lams = 0.0
        solver = self._solver
        try:
            known = self._inPlace
            if known is not None and known[0] is program:
                A, lo, up, _ = solver.stacked(known[1])
                r = program.run(values, A, lo, up, known[2], True)
                if r >= 0:
                    try:
                        result = solver.solve_stacked(lams, equality=equalityOnly)
                    except SotpyError:
                        return self._fromSignals()  # the checks of solve() name it
                    return self._accept(result)
                if r == _rowkernels.REFUSED:
                    return self._fromSignals()
            # a first tick, or the level sizes changed: the SOT's buffers, then levels
            ends = np.empty(program.levels, dtype=np.int64)
            while True:
                A, lo, up = self._rowsA, self._rowsB, self._rowsU
                r = program.run(values, A, lo, up, ends, False)
                if r != _rowkernels.NO_ROOM:
                    break
                m = 2 * A.shape[0]
                self._rowsA, self._rowsB, self._rowsU = (
                    np.empty((m, self.nv)),
                    np.empty(m),
                    np.empty(m),
                )
        except TypeError as exc:
            # the kernel refused its arguments (types it was not compiled for) or a
            # callback failed: the signals decide, and raise if they fail too
            x = self._fromSignals()
            refused(f"SOT({self.name})'s task rows", exc)
            self.setTaskFusion(False)
            return x
        if r < 0:
            self._inPlace = None
            return self._fromSignals()
        levels = []
        start = 0
        for end, equality in zip(ends.tolist(), equalities, strict=True):
            level = (A[start:end], lo[start:end], lo[start:end] if equality else up[start:end])
            levels.append(level)
            start = end
        x = self._finish(levels, lams if isinstance(lams, list) else [0.0] * len(levels))
        sizes = tuple(len(level[0]) for level in levels)
        self._inPlace = (program, sizes, ends)
        return x

    @command
    def setTaskFusion(self, enabled: bool) -> None:
        """Write the stack's rows in one compiled call from the features' inputs
        (default, with numba), or read each feature's and task's signals (see
        ``docs/tasks.md``, "Fused rows"). The control is the same either way."""
        if enabled and _rowkernels.write_rows is None:
            raise CommandError(
                f"SOT({self.name}).setTaskFusion: the fused evaluation needs the compiled "
                f"kernels ({_jit.UNAVAILABLE})"
            )
        if enabled:
            _jit.prepare("the task rows", ["sotpy.tasks._rowkernels"])
        self._fuse = bool(enabled)
        self.control.setPlanFusion(self._fusion if self._fuse else None)

    @command
    def getTaskFusion(self) -> bool:
        """Whether the tasks' rows are evaluated in one pass (see ``setTaskFusion``)."""
        return self._fuse

    def _limitLevel(
        self, q: Any, lower: Any, upper: Any, vmax: Any, dt: float
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        if not dt > 0:
            raise SignalTypeError(f"{self.dt.name}: the control period must be > 0 s, got {dt}")
        rows = self._limitRowsFor(lower, upper, vmax)
        ql, qu, vm, nvm = rows.ql, rows.qu, rows.vm, rows.nvm
        qj = np.asarray(q)[rows.iq]
        lo = np.subtract(ql, qj)
        lo /= dt
        hi = np.subtract(qu, qj)
        hi /= dt
        # clipped to [-vm, vm] (np.clip costs several times two ufunc calls here)
        np.minimum(np.maximum(lo, nvm, out=lo), vm, out=lo)
        np.minimum(np.maximum(hi, nvm, out=hi), vm, out=hi)
        return rows.A, lo, hi

    def _limitRowsFor(self, lower: Any, upper: Any, vmax: Any) -> _LimitRows:
        """The limits' rows for these limit arrays: kept while the same arrays come
        (they change rarely), made again from new ones (which raises the error naming a
        bad limit)."""
        rows = self._limits
        if rows is None or not (
            rows.lower is lower and rows.upper is upper and rows.vmax is vmax
        ):  # by identity: a new array, new rows
            rows = self._limits = self._limitRows(lower, upper, vmax)
        return rows

    def _limitRows(self, lower: Any, upper: Any, vmax: Any) -> _LimitRows:
        """What the joint-limit level needs from the limits: the bounded joints, their
        limits (inf where none) and the level's matrix."""
        ql, qu = np.asarray(lower)[self._iq], np.asarray(upper)[self._iq]
        vm = np.asarray(vmax)[self._iv]
        # refused where they enter: swapped or NaN limits, a negative velocity limit
        bad = ~(ql <= qu) | ~(vm >= 0)
        if bad.any():
            j = int(np.flatnonzero(bad)[0])
            raise SignalTypeError(
                f"SOT({self.name}): joint at q[{self._iq[j]}]: {self.lowerJl.name} = {ql[j]:g}, "
                f"{self.upperJl.name} = {qu[j]:g}, {self.upperVl.name} = {vm[j]:g}: expected "
                "lower <= upper and a velocity limit >= 0 (swapped limits?)"
            )
        # Pinocchio writes ~1.8e308 where a model gives no limit: no bound there
        vm = np.where(vm < _NO_LIMIT, vm, np.inf)
        ql = np.where(ql > -_NO_LIMIT, ql, -np.inf)
        qu = np.where(qu < _NO_LIMIT, qu, np.inf)
        rows = np.flatnonzero(np.isfinite(ql) | np.isfinite(qu) | np.isfinite(vm))
        A = np.zeros((len(rows), self.nv))
        A[np.arange(len(rows)), self._iv[rows]] = 1.0
        A.flags.writeable = False
        vm = vm[rows]
        ql, qu = ql[rows], qu[rows]
        lim = np.array([ql, qu, vm])
        return _LimitRows(
            lower, upper, vmax, self._iq[rows], self._iv[rows], ql, qu, vm, -vm, A, lim
        )
