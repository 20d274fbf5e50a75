r"""Torque-level whole-body control in the graph: ``Controller`` and its servos.

::

    robot = load_robot("panda")
    ctrl = Controller("ctrl", robot.dynamic)   # plugs position/velocity like the Dynamic
    ctrl.addCartesianTask("ee", "panda_hand_tcp", 1.0, 0)   # input ctrl.ee (6: a_des)
    ctrl.addJointTask("posture", 1e-3, 0)                   # input ctrl.posture (na)
    ctrl.addTorqueLimits("torque")
    servo = PoseServo("servo")                              # PD: desired acceleration
    plug(ctrl.eePose, servo.position); plug(ctrl.eeVelocity, servo.velocity)
    plug(servo.desiredAcceleration, ctrl.ee)
    ctrl.activateTasksAndConstraints()
    robot.device.setControlType("torque")
    plug(ctrl.torque, robot.device.control)

The numerics are :mod:`sotpy.solvers.wbc` (``WholeBodyController``); this entity reads
the state and the tasks' desired values, and writes the solution. Tasks and constraints
are objects owned by the controller (created by commands, addressed by name), as in
ORCA's ``controller.addTask``; each task has an input signal of its name carrying its
desired value (default zeros). Each tick (``dt``: the control period, s; the time is
``t * dt``):

* pass ``model``: Pinocchio at ``(q, v)``;
* ``solution`` (size ``n``): ``chi = (a, tau, f)``; ``acceleration`` (nv), ``torque``
  (na), ``wrenches`` (all contacts, LOCAL, force then torque), ``solutionFound``;
* ``torque`` is ``tau`` minus ``S g(q)`` if ``setRemoveGravityTorques(True)`` and minus
  ``S (b - g)`` (Coriolis and centrifugal) if ``setRemoveCoriolisTorques(True)`` (for
  robots that compensate them below); ``solution`` keeps the full ``tau``;
* no solution: ``solutionFound`` is False, a ``SotpyWarning`` is emitted once (until a
  solution is found again), and the outputs are the fallback of
  :mod:`sotpy.solvers.wbc.solver`: from the last torques sent, a step of at most the
  torque-rate bound towards gravity compensation ``S g(q)`` (``S g`` itself on the
  first tick or with no rate bound), clipped to the torque limits; ``a = 0``, ``f = 0``.

For the servos: ``<task>Pose`` (SE3) and ``<task>Velocity`` (6, LOCAL_WORLD_ALIGNED:
origin velocity and angular velocity, world axes) of each Cartesian task, ``com`` and
``comVelocity`` (3, world), ``jointPosition`` and ``jointVelocity`` (na, the actuated
joints; models whose actuated joints are all one-dimensional).
"""

from __future__ import annotations

import math
import warnings
from typing import Any

import numpy as np
import pinocchio as pin

from ..dynamics.types import SE3
from ..errors import BudgetWarning, EntityError, SotpyError, SotpyWarning
from ..graph import (
    BOOL,
    DOUBLE,
    INT,
    VECTOR,
    Entity,
    Input,
    Output,
    OutputSignal,
    command,
    plug,
    pool,
)
from ..graph.signal import InputSignal
from .hierarchy import checked_max_iter, checked_time_budget
from .wbc import (
    BilateralContactSpec,
    CartesianAccelerationTask,
    CoMAccelerationTask,
    ContactSpec,
    JointAccelerationLimit,
    JointAccelerationTask,
    JointPositionLimit,
    JointTorqueLimit,
    JointVelocityLimit,
    RegularisationTask,
    Solution,
    Task,
    TorqueTask,
    WholeBodyController,
    WrenchTask,
    check_gains,
    joint_pd,
    min_jerk,
    pid_step,
    pose_error,
    pose_pd,
    wrench_pi,
)

__all__ = [
    "ComPidServo",
    "ComServo",
    "Controller",
    "JointPidServo",
    "JointServo",
    "MinJerk",
    "PosePidServo",
    "PoseServo",
    "WrenchServo",
]

_LWA = pin.LOCAL_WORLD_ALIGNED


class Controller(Entity):
    """Torque-level whole-body QP controller (ORCA-style); see the module doc."""

    position = Input(VECTOR, doc="q: Pinocchio configuration (nq)")
    velocity = Input(VECTOR, doc="v: tangent velocity (nv)")
    dt = Input(DOUBLE, default=0.001, doc="control period (s): ramps and callbacks' time")

    @Output(INT, deps=("position", "velocity"), withTime=True)
    def model(self, t: int, q: np.ndarray, v: np.ndarray) -> int:
        """Pass: Pinocchio at (q, v) (tick)."""
        try:
            self.core.robot.update(q, v)
        except SotpyError as exc:
            raise SotpyError(f"{self.model_signal_name()}: {exc}") from None
        return t

    @Output(VECTOR, timeDependent=False, withTime=True, doc="chi = (a, tau, f)")
    def solution(self, t: int, _model: int, dt: float, *desired: Any) -> np.ndarray:
        """Solve the tick's QP (see the module doc)."""
        for task, value in zip(self._inputTasks, desired, strict=True):
            try:
                task.setDesired(value)
            except SotpyError as exc:
                raise SotpyError(
                    f"{self.className}({self.name})::input(vector)::{task.name}: {exc}"
                ) from None
        sol = self.core.tick(t * dt, dt)
        self._last = sol
        if not sol.found:
            if not self._warned:
                self._warned = True
                warnings.warn(
                    f"{self.className}({self.name}): no solution at tick {t} ({sol.reason}); "
                    "output: the fallback (the last torque, moving towards gravity compensation at"
                    " the torque-rate bound)",
                    SotpyWarning,
                    stacklevel=2,
                )
        else:
            self._warned = False
        if sol.budget_hit:  # the hierarchical strategy stopped at its budget
            self.budgetHits += 1
            pool.budgetHits += 1
            if not self._budgetWarned:
                self._budgetWarned = True
                res = self.core.last_hierarchy
                warnings.warn(
                    f"{self.className}({self.name}): the hierarchical solver stopped at its"
                    f" {res.status} budget at tick {t}: {res.reason}. Said once until it"
                    " converges again; budgetHits and the loop's stats count every such tick",
                    BudgetWarning,
                    stacklevel=2,
                )
        elif self._budgetWarned:
            self._budgetWarned = False
        return sol.chi.copy()

    @command
    def setTimeBudget(self, seconds: float | None) -> None:
        """The hierarchical strategy's time budget per tick (s of the ticking thread's CPU
        time; finite, > 0; ``None`` from Python: none). A tick that reaches it keeps the
        levels it proved (see ``docs/solvers.md``); the weighted strategy has no budget."""
        h = self.core.hierarchy
        h.time_budget = checked_time_budget(
            f"{self.className}({self.name}).setTimeBudget", seconds, h.time_budget
        )
        self.solution.setReady()  # a tick already solved is solved again with it

    @command
    def getTimeBudget(self) -> float | None:
        """The hierarchical strategy's time budget per tick (s; ``None``: none)."""
        return self.core.hierarchy.time_budget

    @command
    def setColdTimeBudget(self, seconds: float | None) -> None:
        """The hierarchical strategy's budget for a tick without the full warm start
        (the first, the first after the levels change size), when larger than the time
        budget (s of CPU time; finite, > 0; ``None`` from Python: the same; default 2 ms)."""
        h = self.core.hierarchy
        h.cold_time_budget = checked_time_budget(
            f"{self.className}({self.name}).setColdTimeBudget", seconds, h.cold_time_budget
        )
        self.solution.setReady()

    @command
    def getColdTimeBudget(self) -> float | None:
        """The hierarchical strategy's budget for a cold tick (s; ``None``: the same)."""
        return self.core.hierarchy.cold_time_budget

    @command
    def setMaxIterations(self, n: int) -> None:
        """The hierarchical strategy's iteration budget per tick (>= 1)."""
        h = self.core.hierarchy
        h.max_iter = checked_max_iter(
            f"{self.className}({self.name}).setMaxIterations", n, h.max_iter
        )
        self.solution.setReady()

    @command
    def getMaxIterations(self) -> int:
        """The hierarchical strategy's iteration budget per tick."""
        return self.core.hierarchy.max_iter

    @Output(VECTOR, deps=("solution",), doc="torque command tau (na, N m), minus removed terms")
    def torque(self, _chi: np.ndarray) -> np.ndarray:
        """The torque command (module doc)."""
        tau = self._last.tau.copy()
        robot = self.core.robot
        if self._removeGravity:
            tau -= robot.S @ robot.g
        if self._removeCoriolis:
            tau -= robot.S @ (robot.b - robot.g)
        return tau

    @Output(VECTOR, deps=("solution",), doc="acceleration command a (nv)")
    def acceleration(self, _chi: np.ndarray) -> np.ndarray:
        return self._last.a.copy()

    @Output(VECTOR, deps=("solution",), doc="contact wrenches (LOCAL, force then torque)")
    def wrenches(self, _chi: np.ndarray) -> np.ndarray:
        return self._last.f.copy()

    @Output(BOOL, deps=("solution",), doc="whether the QP was solved (False: fallback)")
    def solutionFound(self, _chi: np.ndarray) -> bool:
        return bool(self._last.found)

    @Output(VECTOR, deps=("solution",), doc="activation ramps (tasks, then constraints)")
    def ramps(self, _chi: np.ndarray) -> np.ndarray:
        """The ramp (0..1) of every task then constraint, in ``rampNames()`` order, as
        the last solve used them."""
        return np.array([x.ramp for x in self.core._all()], dtype=float)

    @Output(VECTOR, deps=("model",), doc="CoM (3, m, world)")
    def com(self, _m: int) -> np.ndarray:
        return self.core.robot.com

    @Output(VECTOR, deps=("model",), doc="CoM velocity (3, m/s, world)")
    def comVelocity(self, _m: int) -> np.ndarray:
        return self.core.robot.com_velocity

    @Output(VECTOR, deps=("model",), doc="actuated joint positions (na, rad)")
    def jointPosition(self, _m: int) -> np.ndarray:
        self._needOneDof("jointPosition")
        return self.core.robot.q[self._iqa].copy()

    @Output(VECTOR, deps=("model",), doc="actuated joint velocities (na, rad/s)")
    def jointVelocity(self, _m: int) -> np.ndarray:
        return self.core.robot.v[self.core.robot.actuated].copy()

    def __init__(self, name: str, dynamic: Entity) -> None:
        model = getattr(dynamic, "model", None)
        if not isinstance(model, pin.Model):
            raise EntityError(f"Controller({name}): expected a Dynamic entity, got {dynamic!r}")
        self.core = WholeBodyController(model)
        self._last: Solution = Solution(
            np.zeros(0), np.zeros(0), np.zeros(0), np.zeros(0), False, "not solved yet"
        )
        self._warned = False
        self._budgetWarned = False
        #: ticks whose hierarchical solve stopped at its iteration or time budget
        self.budgetHits = 0
        self._removeGravity = False
        self._removeCoriolis = False
        self._inputTasks: list[Task] = []
        robot = self.core.robot
        iq = [
            model.joints[j].idx_q
            for j in range(1, model.njoints)
            if model.joints[j].nq == 1 and model.joints[j].idx_v in set(robot.actuated.tolist())
        ]
        self._iqa = np.array(iq, dtype=int)
        for sig in ("position", "velocity"):
            src = dynamic.signal(sig).source
            if src is not None:
                plug(src, self.signal(sig))
        self.velocity.setDefault(np.zeros(model.nv))
        self._rewire()

    def model_signal_name(self) -> str:
        return self.signal("model").name

    def _needOneDof(self, what: str) -> None:
        if len(self._iqa) != self.core.robot.na:
            raise SotpyError(
                f"{self.className}({self.name})::{what}: actuated joints are not all 1-D"
            )

    def _who(self, cmd: str) -> str:
        return f"{self.className}({self.name}).{cmd}"

    def _rewire(self) -> None:
        self._inputTasks = [t for t in self.core.tasks.values() if self.hasSignal(t.name)]
        self.solution.setDependencies(
            [self.signal("model"), self.dt] + [self.signal(t.name) for t in self._inputTasks]
        )

    def _addTask(self, cmd: str, task: Task) -> None:
        if self.hasSignal(task.name) or self.hasSignal(task.name + "Pose"):
            raise SotpyError(f"{self._who(cmd)}: the name {task.name!r} is taken by a signal")
        try:
            self.core.addTask(task)
        except SotpyError as exc:
            raise SotpyError(f"{self._who(cmd)}: {exc}") from None
        self.addSignal(
            InputSignal(
                self, task.name, VECTOR, np.zeros(task.size), doc=f"desired value of {task.name}"
            )
        )
        self._rewire()

    def _task(self, cmd: str, name: str) -> Task:
        if name not in self.core.tasks:
            raise SotpyError(
                f"{self._who(cmd)}: no task named {name!r} (tasks: {list(self.core.tasks)})"
            )
        return self.core.tasks[name]

    def _item(self, cmd: str, name: str) -> Any:
        return self._wrap(cmd, self.core.item, name)

    def _wrap(self, cmd: str, fn: Any, *args: Any) -> Any:
        try:
            return fn(*args)
        except SotpyError as exc:
            raise SotpyError(f"{self._who(cmd)}: {exc}") from None

    # -- tasks ------------------------------------------------------------------------------
    @command
    def addCartesianTask(self, name: str, frame: str, weight: float = 1.0, level: int = 0) -> None:
        """Cartesian acceleration task of ``frame`` (LOCAL_WORLD_ALIGNED); input ``name``
        (6: desired linear then angular acceleration, world axes), outputs
        ``namePose`` and ``nameVelocity`` for its servo."""
        task = self._wrap("addCartesianTask", CartesianAccelerationTask, name, frame, weight, level)
        self._addTask("addCartesianTask", task)
        robot = self.core.robot
        fid = task.fid
        model = self.signal("model")
        self.addSignal(
            OutputSignal(
                self,
                name + "Pose",
                SE3,
                lambda _m: robot.frame_placement(fid),
                (model,),
                doc="placement of the task frame",
            )
        )
        self.addSignal(
            OutputSignal(
                self,
                name + "Velocity",
                VECTOR,
                lambda _m: robot.frame_velocity(fid, _LWA),
                (model,),
                doc="velocity of the task frame (6, world axes)",
            )
        )

    @command
    def addJointTask(self, name: str, weight: float = 1.0, level: int = 0) -> None:
        """Joint acceleration (posture) task; input ``name`` (na, rad/s^2)."""
        self._addTask(
            "addJointTask",
            self._wrap(
                "addJointTask", JointAccelerationTask, name, self.core.robot.na, weight, level
            ),
        )

    @command
    def addComTask(self, name: str, weight: float = 1.0, level: int = 0) -> None:
        """CoM acceleration task; input ``name`` (3, m/s^2, world)."""
        self._addTask(
            "addComTask", self._wrap("addComTask", CoMAccelerationTask, name, weight, level)
        )

    @command
    def addWrenchTask(self, name: str, frame: str, weight: float = 1.0, level: int = 0) -> None:
        """Wrench task on the contact at ``frame``; input ``name`` (6 or 3, LOCAL)."""
        sl = self.core.layout.f.get(frame)
        if sl is None:
            raise SotpyError(
                f"{self._who('addWrenchTask')}: no contact at {frame!r} (addContact first)"
            )
        self._addTask(
            "addWrenchTask",
            self._wrap("addWrenchTask", WrenchTask, name, frame, sl.stop - sl.start, weight, level),
        )

    @command
    def addTorqueTask(self, name: str, weight: float = 1.0, level: int = 0) -> None:
        """Torque task; input ``name`` (na, N m)."""
        self._addTask(
            "addTorqueTask",
            self._wrap("addTorqueTask", TorqueTask, name, self.core.robot.na, weight, level),
        )

    @command
    def addRegularisationTask(self, name: str, weight: float = 1e-5, level: int = 0) -> None:
        """Global regularisation ``chi = 0`` (input ``name``: the target, default 0)."""
        self._addTask(
            "addRegularisationTask",
            self._wrap(
                "addRegularisationTask", RegularisationTask, name, self.core.layout.n, weight, level
            ),
        )

    @command
    def setTaskWeight(self, name: str, weight: float) -> None:
        """The task's weight (>= 0); a change is a transition (bounded torque rate)."""
        self._wrap("setTaskWeight", self._task("setTaskWeight", name).setWeight, weight)
        self.core.transition = True
        self.solution.setReady()

    @command
    def setTaskRowWeights(self, name: str, weights: np.ndarray) -> None:
        self._wrap(
            "setTaskRowWeights", self._task("setTaskRowWeights", name).setRowWeights, weights
        )
        self.solution.setReady()

    @command
    def setTaskSelection(self, name: str, selection: np.ndarray) -> None:
        self._wrap("setTaskSelection", self._task("setTaskSelection", name).setSelection, selection)
        self.solution.setReady()

    @command
    def setTaskLevel(self, name: str, level: int) -> None:
        self._wrap("setTaskLevel", self._task("setTaskLevel", name).setLevel, level)
        self.solution.setReady()

    @command
    def remove(self, name: str) -> None:
        """Remove a task (and its signals) or a constraint."""
        self._wrap("remove", self.core.remove, name)
        for s in (name, name + "Pose", name + "Velocity"):
            if self.hasSignal(s):
                self.removeSignal(s)
        self._rewire()

    # -- constraints ------------------------------------------------------------------------
    def _addConstraint(self, cmd: str, cls: Any, *args: Any) -> None:
        c = self._wrap(cmd, cls, *args)
        self._wrap(cmd, self.core.addConstraint, c)
        self.solution.setReady()

    @command
    def addTorqueLimits(
        self, name: str, lower: np.ndarray | None = None, upper: np.ndarray | None = None
    ) -> None:
        """``lower <= tau <= upper`` (default the model's effort limits)."""
        self._addConstraint(
            "addTorqueLimits", JointTorqueLimit, name, self.core.robot, lower, upper
        )

    @command
    def addJointPositionLimits(self, name: str, horizon: float, margin: float = 0.0) -> None:
        """``q + h v + h^2/2 a`` (and the next tick's ``q``) within the model's position
        limits, ``margin`` (rad) inside them."""
        self._addConstraint(
            "addJointPositionLimits", JointPositionLimit, name, self.core.robot, horizon, margin
        )

    @command
    def addJointVelocityLimits(self, name: str, horizon: float) -> None:
        """``v + h a`` within the model's velocity limits."""
        self._addConstraint(
            "addJointVelocityLimits", JointVelocityLimit, name, self.core.robot, horizon
        )

    @command
    def addJointAccelerationLimits(self, name: str, lower: np.ndarray, upper: np.ndarray) -> None:
        """``lower <= a <= upper`` on the actuated joints (rad/s^2)."""
        self._addConstraint(
            "addJointAccelerationLimits",
            JointAccelerationLimit,
            name,
            self.core.robot,
            lower,
            upper,
        )

    @command
    def addCollisionAvoidance(
        self,
        name: str,
        geometry: pin.GeometryModel,
        srdf: str | None = None,
        horizon: float = 0.05,
        safety: float = 0.01,
        influence: float = 0.05,
        gain: float = 0.5,
    ) -> None:
        """The collision pairs of ``geometry`` (the robot's collision model; minus the
        SRDF's disabled pairs and adjacent links) kept ``safety`` m apart: for each pair
        under ``influence`` m, ``d_ddot >= (-c (d - d_s) - (1 + c h) d_dot) / h`` with
        ``c = gain / (influence - safety)`` and ``h = horizon`` (see
        ``sotpy.solvers.wbc.collision``). ``getCollisionPairs(name)`` gives its
        :class:`~sotpy.tasks.collision.CollisionPairs` (obstacles, pair edits)."""
        from .wbc.collision import CollisionConstraint

        self._addConstraint(
            "addCollisionAvoidance",
            CollisionConstraint,
            name,
            self.core.robot,
            geometry,
            srdf,
            horizon,
            safety,
            influence,
            gain,
        )

    @command
    def getCollisionPairs(self, name: str) -> Any:
        """The pairs of the collision constraint ``name`` (a ``CollisionPairs``)."""
        c = self.core.constraints.get(name)
        pairs = getattr(c, "pairs", None)
        if pairs is None:
            raise SotpyError(
                f"{self._who('getCollisionPairs')}: no collision constraint named {name!r}"
            )
        return pairs

    @command
    def addContact(
        self,
        frame: str,
        mu: float = 0.5,
        length: float = 0.1,
        width: float = 0.1,
        offsetX: float = 0.0,
        offsetY: float = 0.0,
        dim: int = 6,
        fmin: float = 0.0,
        margin: float = 0.0,
        facets: int = 8,
        Kp: float = 0.0,
        Kd: float | None = None,
    ) -> None:
        """A unilateral contact at ``frame`` (z the normal): friction ``mu`` (pyramid of
        ``facets`` faces), the real sole ``length`` x ``width`` (m) centred at
        ``(offsetX, offsetY)``, the CoP kept ``margin`` (m) inside it, normal force >=
        ``fmin`` (N), the frame's pose and velocity fed back with ``Kp`` (1/s^2) and
        ``Kd`` (1/s, default ``2 sqrt(Kp)``); see ``ContactSpec``."""
        spec = ContactSpec(
            frame, dim, mu, length, width, (offsetX, offsetY), fmin, margin, facets, Kp, Kd
        )
        self._wrap("addContact", self.core.setContacts, [*self.core.contacts, spec])
        self.solution.setReady()

    @command
    def setContactCostWeight(self, weight: float) -> None:
        """Weight (>= 0) of the default contact wrench distribution cost (0: none): each
        CoP pulled to its sole's centre, tangential forces and torsion to zero (see
        ``sotpy.solvers.wbc.ContactWrenchCost``)."""
        self._wrap("setContactCostWeight", self.core.setContactCostWeight, weight)
        self.solution.setReady()

    @command
    def setTorqueRateLimit(self, rate: Any) -> None:
        """The bound on the torque change during a transition (an activation, a
        deactivation, a strategy switch): ``|tau - tau_prev| <= rate dt`` per tick
        (N m/s, one value or one per actuated joint; default each joint's effort limit
        per 0.25 s)."""
        self._wrap("setTorqueRateLimit", self.core.setTorqueRateLimit, rate)
        self.solution.setReady()

    @command
    def getTorqueRateLimit(self) -> np.ndarray:
        """The torque rate bound of transitions (N m/s per actuated joint)."""
        return self.core.torque_rate.copy()

    @command
    def addBilateralContact(self, name: str, frameA: str, frameB: str) -> None:
        """A rigid contact between two frames of the robot (their relative placement is
        kept; variables: the interaction wrench on ``frameB`` in its frame, 6); see
        ``BilateralContactSpec``. Addressed by ``name`` (``removeContact``,
        ``deactivate``, ``addWrenchTask``)."""
        if any(c.key == name for c in self.core.contacts):
            raise SotpyError(f"{self._who('addBilateralContact')}: contact {name!r} exists")
        spec = BilateralContactSpec(frameA, frameB, name)
        self._wrap("addBilateralContact", self.core.setContacts, [*self.core.contacts, spec])
        self.solution.setReady()

    @command
    def removeContact(self, frame: str) -> None:
        """Remove a contact at once (its variables leave the layout; a wrench task on it
        must be removed first). For a gradual release, ``deactivate(frame)``."""
        left = [c for c in self.core.contacts if c.key != frame]
        if len(left) == len(self.core.contacts):
            raise SotpyError(f"{self._who('removeContact')}: no contact at {frame!r}")
        self._wrap("removeContact", self.core.setContacts, left)
        self.solution.setReady()

    @command
    def getContacts(self) -> list[str]:
        return [c.key for c in self.core.contacts]

    # -- strategy, options, life cycle ------------------------------------------------------
    @command
    def setResolutionStrategy(self, strategy: str) -> None:
        """``"OneLevelWeighted"`` or ``"MultiLevelWeighted"``."""
        self._wrap("setResolutionStrategy", self.core.setStrategy, strategy)
        self.solution.setReady()

    @command
    def getResolutionStrategy(self) -> str:
        return self.core.strategy

    @command
    def setRemoveGravityTorques(self, flag: bool) -> None:
        self._removeGravity = flag
        self.torque.setReady()

    @command
    def setRemoveCoriolisTorques(self, flag: bool) -> None:
        self._removeCoriolis = flag
        self.torque.setReady()

    @command
    def setRampDuration(self, name: str, duration: float) -> None:
        self._wrap("setRampDuration", self._item("setRampDuration", name).setRampDuration, duration)

    @command
    def setCallback(self, name: str, event: str, fn: Any) -> None:
        """Set ``event`` (onActivation, onActivated, onComputeBegin(t, dt),
        onComputeEnd(t, dt), onDeactivation, onDeactivated) of a task or constraint."""
        self._wrap("setCallback", self._item("setCallback", name).setCallback, event, fn)

    @command
    def activate(self, name: str) -> None:
        """Start the activation ramp of a task, constraint or contact (by frame/name)."""
        self._wrap("activate", self.core.activate, name)
        self.solution.setReady()

    @command
    def deactivate(self, name: str) -> None:
        """Start the deactivation ramp of a task, constraint or contact; a contact's
        wrench is ramped down to 0 from its last value, then the contact is released
        (see ``sotpy.solvers.wbc.ContactState``)."""
        self._wrap("deactivate", self.core.deactivate, name)
        self.solution.setReady()

    @command
    def activateTasksAndConstraints(self) -> None:
        self.core.activateTasksAndConstraints()
        self.solution.setReady()

    @command
    def deactivateTasksAndConstraints(self) -> None:
        self.core.deactivateTasksAndConstraints()
        self.solution.setReady()

    @command
    def tasksAndConstraintsDeactivated(self) -> bool:
        return self.core.tasksAndConstraintsDeactivated()

    @command
    def rampNames(self) -> list[str]:
        """Names of the entries of ``ramps``: the tasks, then the constraints."""
        return [x.name for x in self.core._all()]

    @command
    def lastSolution(self) -> Any:
        """The last :class:`~sotpy.solvers.wbc.Solution` (reason, dynamics residual)."""
        return self._last


#: the servos' inputs, in the order their ``desiredAcceleration`` reads them
_SERVO_INPUTS = (
    "position",
    "velocity",
    "reference",
    "referenceVelocity",
    "referenceAcceleration",
    "Kp",
    "Kd",
)


class PoseServo(Entity):
    """PD on a pose: ``a_des = a_ff - Kp (p - p_d, log3(R R_d^T)) - Kd (nu - nu_d)``
    (world axes; see :mod:`sotpy.solvers.wbc.servos`)."""

    position = Input(SE3, doc="current placement")
    velocity = Input(VECTOR, doc="current velocity (6, world axes)")
    reference = Input(SE3, doc="desired placement")
    referenceVelocity = Input(VECTOR, default=np.zeros(6), doc="desired velocity (6)")
    referenceAcceleration = Input(VECTOR, default=np.zeros(6), doc="feed-forward (6)")
    Kp = Input(VECTOR, default=np.full(6, 100.0), doc="proportional gains (6, 1/s^2)")
    Kd = Input(VECTOR, default=np.zeros(0), doc="derivative gains (6, 1/s); empty: 2 sqrt(Kp)")

    @Output(VECTOR, deps=_SERVO_INPUTS)
    def desiredAcceleration(self, M, nu, Md, nud, ad, Kp, Kd) -> np.ndarray:
        """Desired acceleration (6, world axes)."""
        kp, kd = check_gains(f"{self.className}({self.name})", Kp, Kd, 6)
        for n, x in (("velocity", nu), ("referenceVelocity", nud), ("referenceAcceleration", ad)):
            if np.shape(x) != (6,):
                raise SotpyError(
                    f"{self.className}({self.name})::{n}: expected size 6, got {np.shape(x)}"
                )
        return pose_pd(M, nu, Md, nud, ad, kp, kd)

    @Output(VECTOR, deps=("position", "reference"))
    def error(self, M, Md) -> np.ndarray:
        """Pose error (p - p_d, log3(R R_d^T)) (m, rad)."""
        return pose_error(M, Md)


class _VectorServo(Entity):
    size_doc = ""
    position = Input(VECTOR, doc="current value")
    velocity = Input(VECTOR, doc="current rate")
    reference = Input(VECTOR, doc="desired value")
    referenceVelocity = Input(VECTOR, default=np.zeros(0), doc="desired rate (empty: 0)")
    referenceAcceleration = Input(VECTOR, default=np.zeros(0), doc="feed-forward (empty: 0)")
    Kp = Input(VECTOR, default=np.full(1, 100.0), doc="proportional gains (one or per axis)")
    Kd = Input(VECTOR, default=np.zeros(0), doc="derivative gains; empty: 2 sqrt(Kp)")

    @Output(VECTOR, deps=_SERVO_INPUTS)
    def desiredAcceleration(self, x, v, xd, vd, ad, Kp, Kd) -> np.ndarray:
        """``a_d - Kp (x - x_d) - Kd (v - v_d)``."""
        n = len(x)
        who = f"{self.className}({self.name})"
        for name, y in (("velocity", v), ("reference", xd)):
            if len(y) != n:
                raise SotpyError(f"{who}::{name}: expected size {n}, got {len(y)}")
        vd = np.zeros(n) if len(vd) == 0 else vd
        ad = np.zeros(n) if len(ad) == 0 else ad
        if len(vd) != n or len(ad) != n:
            raise SotpyError(f"{who}: referenceVelocity/referenceAcceleration must have size {n}")
        kp, kd = check_gains(
            who,
            Kp[0] if len(Kp) == 1 else Kp,
            None if len(Kd) == 0 else (Kd[0] if len(Kd) == 1 else Kd),
            n,
        )
        return joint_pd(x, v, xd, vd, ad, kp, kd)

    @Output(VECTOR, deps=("position", "reference"))
    def error(self, x: np.ndarray, xd: np.ndarray) -> np.ndarray:
        """``x - x_d`` (the unit of ``position``)."""
        if len(x) != len(xd):
            raise SotpyError(
                f"{self.className}({self.name})::reference: expected size {len(x)}, got {len(xd)}"
            )
        return np.asarray(x, dtype=float) - xd


class JointServo(_VectorServo):
    """PD on the actuated joints (plug ``Controller.jointPosition``/``jointVelocity``)."""


class ComServo(_VectorServo):
    """PD on the CoM (plug ``Controller.com``/``comVelocity``)."""


_PID_INPUTS = (*_SERVO_INPUTS, "Ki", "integralLimit", "dt")


class _Pid:
    """The integral state of the PID servos (see :func:`sotpy.solvers.wbc.pid_step`):
    ``I`` integrates the error once per tick (``dt`` times the ticks since the last
    computation, one tick at the first), clamped per axis to ``integralLimit``."""

    def _pidInit(self) -> None:
        self._integral: np.ndarray | None = None
        self._tLast: int | None = None

    def _gain(self, what: str, x: np.ndarray, n: int, allow_inf: bool = False) -> np.ndarray:
        x = np.asarray(x, dtype=float)
        x = np.full(n, x[0]) if x.shape == (1,) else x
        ok = np.all(~np.isnan(x)) and (allow_inf or np.all(np.isfinite(x)))
        if x.shape != (n,) or not ok or np.any(x < 0):
            raise SotpyError(
                f"{self.className}({self.name})::{what}: expected 1 or {n} values >= 0"
                f"{'' if allow_inf else ', finite'}, got {x}"
            )
        return x

    def _pid(self, t, e, de, ad, kp, kd, Ki, limit, dt) -> np.ndarray:
        n = len(e)
        ki = self._gain("Ki", Ki, n)
        lim = self._gain("integralLimit", limit, n, allow_inf=True)
        if not (math.isfinite(dt) and dt > 0):
            raise SotpyError(f"{self.className}({self.name})::dt: expected > 0 s, got {dt}")
        if self._integral is None or self._integral.shape != (n,):
            self._integral = np.zeros(n)
        steps = 1 if self._tLast is None else max(t - self._tLast, 0)
        self._tLast = t
        out, self._integral = pid_step(e, de, ad, self._integral, steps * dt, kp, kd, ki, lim)
        return out

    @command
    def resetIntegral(self) -> None:
        """Set the integral to zero (at the next computation): call it when the task
        the servo drives is activated, or its reference jumps."""
        self._integral = None
        self._tLast = None
        self.signal("desiredAcceleration").setReady()

    @command
    def getIntegral(self) -> np.ndarray:
        """The integral ``I`` of the error after the last computation (m s, rad s)."""
        return np.zeros(0) if self._integral is None else self._integral.copy()


class PosePidServo(_Pid, PoseServo):
    r"""PID on a pose with anti-windup, beside the PD :class:`PoseServo`:

    .. math:: a_{des} = a_{ff} - K_p e - K_d (\nu - \nu_d) - K_i I, \qquad
              I_k = \mathrm{clamp}(I_{k-1} + e_k \Delta t, -I_{max}, I_{max})

    with ``e = (p - p_d, log3(R R_d^T))`` (m, rad, world axes); ``Ki`` (1/s^3, one or 6
    values), ``integralLimit`` (``I_max``, m s and rad s, one or 6 values, inf: none).
    ``resetIntegral()`` when the task is activated."""

    Ki = Input(VECTOR, default=np.zeros(1), doc="integral gains (one or 6, 1/s^3)")
    integralLimit = Input(
        VECTOR, default=np.full(1, np.inf), doc="anti-windup clamp of I (one or 6, m s, rad s)"
    )
    dt = Input(DOUBLE, default=0.001, doc="tick period (s)")

    def __init__(self, name: str) -> None:
        self._pidInit()

    @Output(VECTOR, deps=_PID_INPUTS, withTime=True, timeDependent=True)
    def desiredAcceleration(self, t, M, nu, Md, nud, ad, Kp, Kd, Ki, limit, dt) -> np.ndarray:
        """Desired acceleration (6, world axes)."""
        kp, kd = check_gains(f"{self.className}({self.name})", Kp, Kd, 6)
        for n, x in (("velocity", nu), ("referenceVelocity", nud), ("referenceAcceleration", ad)):
            if np.shape(x) != (6,):
                raise SotpyError(
                    f"{self.className}({self.name})::{n}: expected size 6, got {np.shape(x)}"
                )
        e = pose_error(M, Md)
        return self._pid(t, e, np.asarray(nu) - nud, ad, kp, kd, Ki, limit, dt)


class _VectorPid(_Pid, _VectorServo):
    Ki = Input(VECTOR, default=np.zeros(1), doc="integral gains (one or per axis, 1/s^3)")
    integralLimit = Input(
        VECTOR, default=np.full(1, np.inf), doc="anti-windup clamp of I (one or per axis)"
    )
    dt = Input(DOUBLE, default=0.001, doc="tick period (s)")

    def __init__(self, name: str) -> None:
        self._pidInit()

    @Output(VECTOR, deps=_PID_INPUTS, withTime=True, timeDependent=True)
    def desiredAcceleration(self, t, x, v, xd, vd, ad, Kp, Kd, Ki, limit, dt) -> np.ndarray:
        """``a_d - Kp (x - x_d) - Kd (v - v_d) - Ki I``."""
        n = len(x)
        who = f"{self.className}({self.name})"
        for name, y in (("velocity", v), ("reference", xd)):
            if len(y) != n:
                raise SotpyError(f"{who}::{name}: expected size {n}, got {len(y)}")
        vd = np.zeros(n) if len(vd) == 0 else vd
        ad = np.zeros(n) if len(ad) == 0 else ad
        if len(vd) != n or len(ad) != n:
            raise SotpyError(f"{who}: referenceVelocity/referenceAcceleration must have size {n}")
        kp, kd = check_gains(
            who,
            Kp[0] if len(Kp) == 1 else Kp,
            None if len(Kd) == 0 else (Kd[0] if len(Kd) == 1 else Kd),
            n,
        )
        e = np.asarray(x, dtype=float) - xd
        return self._pid(t, e, np.asarray(v, dtype=float) - vd, ad, kp, kd, Ki, limit, dt)


class JointPidServo(_VectorPid):
    """PID with anti-windup on the actuated joints (see :class:`PosePidServo`)."""


class ComPidServo(_VectorPid):
    """PID with anti-windup on the CoM (see :class:`PosePidServo`; m, m s)."""


class MinJerk(Entity):
    """Minimum-jerk pose trajectory: ``start``, ``goal``, ``duration`` (s), started by
    ``start_(t0)``; outputs ``pose``, ``velocity`` and ``acceleration`` (6, world axes)
    at ``(t - t0) * dt``."""

    dt = Input(DOUBLE, default=0.001, doc="tick period (s)")

    def __init__(self, name: str) -> None:
        self._start: pin.SE3 | None = None
        self._goal: pin.SE3 | None = None
        self._duration = 1.0
        self._t0 = 0

    @command
    def setTrajectory(self, start: pin.SE3, goal: pin.SE3, duration: float, t0: int = 0) -> None:
        """From ``start`` at tick ``t0`` to ``goal`` in ``duration`` s."""
        if not (math.isfinite(duration) and duration > 0):
            raise SotpyError(
                f"{self.className}({self.name}).setTrajectory: duration must be > 0, got {duration}"
            )
        self._start, self._goal, self._duration, self._t0 = (
            pin.SE3(start),
            pin.SE3(goal),
            duration,
            t0,
        )
        for s in ("pose", "velocity", "acceleration"):
            self.signal(s).setReady()

    def _at(self, t: int, dt: float) -> tuple[pin.SE3, np.ndarray, np.ndarray]:
        if self._start is None:
            raise SotpyError(f"{self.className}({self.name}): setTrajectory was not called")
        return min_jerk(self._start, self._goal, self._duration, (t - self._t0) * dt)

    @Output(SE3, deps=("dt",), withTime=True, timeDependent=True)
    def pose(self, t: int, dt: float) -> pin.SE3:
        """Desired placement."""
        return self._at(t, dt)[0]

    @Output(VECTOR, deps=("dt",), withTime=True, timeDependent=True)
    def velocity(self, t: int, dt: float) -> np.ndarray:
        """Desired velocity (6, world axes)."""
        return self._at(t, dt)[1]

    @Output(VECTOR, deps=("dt",), withTime=True, timeDependent=True)
    def acceleration(self, t: int, dt: float) -> np.ndarray:
        """Desired acceleration (6, world axes)."""
        return self._at(t, dt)[2]


class WrenchServo(_Pid, Entity):
    r"""PI on a wrench, for a wrench task: with the error ``e = w_d - w`` (the desired
    minus the measured wrench, N and N m),

    .. math:: I_k = \mathrm{clamp}(I_{k-1} + e_k \, \Delta t, -I_{max}, I_{max}), \qquad
              w_{task} = w_d + K_p e_k + K_i I_k

    (feed-forward plus PI; the integral, in N s, is clamped per axis to
    ``integralLimit``: the anti-windup). ``Delta t`` is ``dt`` times the ticks since the
    last computation (one tick at the first). ``desiredWrench`` is the wrench task's
    input (plug it into ``Controller.<task>``); ``measured`` is a force sensor or the
    simulated contact wrench, **not** the controller's own ``wrenches`` of the same tick
    (a same-tick cycle). ``Kp`` (no unit) and ``Ki`` (1/s): one value or one per axis,
    finite and >= 0; ``integralLimit`` (N s): one value or per axis, >= 0 (inf: none).
    ``resetIntegral()`` sets ``I = 0``.
    """

    measured = Input(VECTOR, doc="measured wrench w (3 or 6: N, then N m)")
    reference = Input(VECTOR, doc="desired wrench w_d (same size)")
    Kp = Input(VECTOR, default=np.zeros(1), doc="proportional gain (one or per axis)")
    Ki = Input(VECTOR, default=np.zeros(1), doc="integral gain, 1/s (one or per axis)")
    integralLimit = Input(
        VECTOR, default=np.full(1, np.inf), doc="anti-windup clamp of I, N s (one or per axis)"
    )
    dt = Input(DOUBLE, default=0.001, doc="tick period (s)")

    def __init__(self, name: str) -> None:
        self._pidInit()

    @Output(
        VECTOR,
        deps=("measured", "reference", "Kp", "Ki", "integralLimit", "dt"),
        withTime=True,
        timeDependent=True,
        doc="the wrench task's desired value (N, N m)",
    )
    def desiredWrench(self, t: int, w, wd, Kp, Ki, limit, dt) -> np.ndarray:
        """``w_d + Kp e + Ki I`` (class doc)."""
        n = len(wd)
        if n not in (3, 6) or np.shape(w) != (n,):
            raise SotpyError(
                f"{self.className}({self.name})::measured: expected the size of reference "
                f"(3 or 6), got {np.shape(w)} and {np.shape(wd)}"
            )
        if not (np.all(np.isfinite(w)) and np.all(np.isfinite(wd))):
            raise SotpyError(f"{self.className}({self.name}): measured/reference not finite")
        kp = self._gain("Kp", Kp, n)
        ki = self._gain("Ki", Ki, n)
        lim = self._gain("integralLimit", limit, n, allow_inf=True)
        if not (math.isfinite(dt) and dt > 0):
            raise SotpyError(f"{self.className}({self.name})::dt: expected > 0 s, got {dt}")
        if self._integral is None or self._integral.shape != (n,):
            self._integral = np.zeros(n)
        steps = 1 if self._tLast is None else max(t - self._tLast, 0)
        self._tLast = t
        out, self._integral = wrench_pi(
            np.asarray(w, float), np.asarray(wd, float), self._integral, steps * dt, kp, ki, lim
        )
        return out

    @command
    def resetIntegral(self) -> None:
        """Set the integral to zero (at the next computation)."""
        self._integral = None
        self._tLast = None
        self.desiredWrench.setReady()

    @command
    def getIntegral(self) -> np.ndarray:
        """The integral ``I`` (N s) after the last computation."""
        return np.zeros(0) if self._integral is None else self._integral.copy()
