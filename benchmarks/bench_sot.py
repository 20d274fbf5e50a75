r"""The SOT control tick: sotpy against Pink on a stand-and-reach task set, and scaling
(issue 4's speed benchmark).

**Stand-and-reach** (the same task set on both sides, the same start, ``dt``, number
of ticks and gains; errors measured afterwards with Pinocchio alone):

* both feet held where they are (6-D each: ``left-ankle``/``right-ankle`` op points);
* the CoM held in x and y;
* the right wrist's position to a target (:data:`REACH` from its half-sitting
  position: 0.25 m on Talos), orientation free;
* the half-sitting posture (every joint, not the free flyer);
* the joint position and velocity limits.

sotpy: strict priorities with the ``SOT`` entity: joint limits (hard level, the SOT's
own: ``max(-v_max, (q_min - q)/dt) <= v <= min(v_max, (q_max - q)/dt)``), then feet + CoM
as one level (one ``Task`` with the three features; the row "feet/feet/CoM on 3 levels"
pushes their three tasks instead), then the wrist, then the posture. The ``Device`` is in
velocity mode; **one tick is** ``device.increment(dt)``, which pulls the graph (op-point
kinematics, features, tasks, the solve) and integrates ``q (+) v dt``.

Pink (``pin-pink``): weighted tasks in one QP, as Pink does: ``FrameTask`` for the feet
(cost :data:`PINK_COSTS`), ``ComTask`` with a zero z cost, ``FrameTask`` for the wrist
with a zero orientation cost, ``PostureTask``; its default limits (configuration:
``0.5 (q_min - q) <= dq <= 0.5 (q_max - q)``, velocity: ``|dq| <= v_max dt``). **One tick
is** ``solve_ik(configuration, tasks, dt, solver=...)`` then
``configuration.integrate_inplace(v, dt)`` (``pin.integrate`` and the next forward
kinematics and Jacobians). The variant "feet hard" passes the feet as Pink's
``constraints`` (equalities of the QP) instead of costs.

Gains. A sotpy task makes ``J v = -lambda e`` (``lambda`` in 1/s): the error decays as
``exp(-lambda t)``. Pink minimises ``sum_i ||W_i (J_i dq + alpha_i e_i)||^2`` over the
displacement ``dq = v dt``: with ``alpha_i = lambda_i dt`` a task met exactly decays at
the same rate. So both use :data:`GAINS` (``alpha = lambda dt`` on Pink's side); the
wrist is the only task that starts with an error.

Timers. sotpy's breakdown wraps the SOT solver's ``solve`` and ``solve_stacked`` (the
call once the SOT writes its rows into the solver's buffers; the copy into the buffers
is then in the graph's share) and the device's integration step (``Device._step``) with
timers, on these instances only: ``solve`` and ``integration`` are their times,
``graph + kinematics`` the rest of the tick (plan, op points, features, tasks, the
joint-limit level, checks, state writes). On Pink's side
``qpsolvers.solve_problem`` is timed the same way (the "solver call": the QP back-end
with qpsolvers' conversions). Each timer costs about 0.3 us per call; both sides carry
theirs in the comparison.

**Scaling**: sotpy's tick, with its breakdown, against the number of tasks on Talos
(:func:`scaling_tasks`: feet, CoM, then position tasks on op points created on joint
frames, always with the posture last), and against the number of degrees of freedom
(:func:`scaling_dof`: the stand-and-reach on Nao, Talos and Romeo, Pink alongside when
installed).

Each repeat builds every contender afresh (same start) and runs them interleaved: they
take turns every :data:`CHUNK` ticks (:func:`interleave`; the sotpy graphs share the
pool under different entity names), so that a change of the machine's load hits them
alike; the order of the turns rotates from one repeat to the next. Per-tick times are
pooled over the repeats for the median, the p99 and the worst; a ratio is the median of the
per-repeat ratios of medians. The garbage collector is left on for both sides. Usage::

    python benchmarks/bench_sot.py              # full run, prints Markdown
    python benchmarks/bench_sot.py --quick      # fewer ticks and repeats
    python benchmarks/bench_sot.py --profile    # also a cProfile summary of sotpy's tick
"""

from __future__ import annotations

import os

# the compiled kernels are what is measured: compiled first on a fresh machine, not the
# NumPy twins that a first run uses while they compile in the background
os.environ.setdefault("SOTPY_JIT", "wait")

import argparse
import contextlib
import cProfile
import gc
import importlib
import io
import pstats
import statistics
import sys
import time
import warnings
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import pinocchio as pin

from sotpy._bench import machine_line
from sotpy.dynamics import load_robot
from sotpy.errors import BudgetWarning, SotpyWarning
from sotpy.graph import plug, pool
from sotpy.loop import frozenHeap
from sotpy.solvers import SOT
from sotpy.tasks import (
    MetaTaskKine6d,
    MetaTaskKineCom,
    MetaTaskKinePosture,
    Task,
    setGain,
)

#: control period (s), the same on both sides
DT = 0.001
#: convergence rates lambda (1/s) of the tasks; Pink's gain is alpha = lambda * DT. The
#: feet and the CoM start with no error: their high rate removes the drift that explicit
#: Euler integration causes while the wrist moves (at 1/s the feet drifted by 1.8e-5 m
#: with sotpy and 7.8e-6 m with Pink in 300 ticks)
GAINS = {"feet": 100.0, "com": 100.0, "wrist": 3.0, "posture": 1.0}
#: Pink's costs: feet (position and orientation, [cost]/[m] and [cost]/[rad]), CoM x and
#: y, the wrist's position, the posture ([cost]/[rad]; 1e-3 is the value common in code
#: built on Pink)
PINK_COSTS = {"feet": 100.0, "com": 10.0, "wrist": 1.0, "posture": 1e-3}
#: wrist target = its half-sitting position + this offset (m, world axes), per robot
#: (0.25 m on Talos; scaled down with the robot's size on Romeo and Nao)
REACH = {
    "talos": np.array([0.15, 0.0, 0.20]),
    "romeo": np.array([0.12, 0.0, 0.16]),
    "nao": np.array([0.06, 0.0, 0.08]),
}
#: the contender that runs the tutorial's graph (docs/tutorial-reach.md)
TUTORIAL = "sotpy, tutorial graph (feet + balance TaskInequality)"
#: QP back-ends of qpsolvers tried for Pink, in this order
PINK_SOLVERS = ("daqp", "proxqp", "quadprog", "piqp", "osqp", "clarabel", "highs")
#: extra Talos op points for the scaling in the number of tasks (name -> frame)
TALOS_EXTRA_OP_POINTS = {
    "left-elbow": "arm_left_4_joint",
    "right-elbow": "arm_right_4_joint",
    "left-knee": "leg_left_4_joint",
    "right-knee": "leg_right_4_joint",
    "left-shoulder": "arm_left_2_joint",
    "right-shoulder": "arm_right_2_joint",
    "left-hip": "leg_left_2_joint",
    "right-hip": "leg_right_2_joint",
    "left-forearm": "arm_left_6_joint",
    "right-forearm": "arm_right_6_joint",
    "head": "head_2_joint",
    "torso": "torso_1_joint",
}
#: op points of the position tasks of :func:`scaling_tasks`, in stacking order
SCALING_OP_POINTS = (
    "right-wrist",
    "left-wrist",
    "gaze",
    "chest",
    *TALOS_EXTRA_OP_POINTS,
)


# -- errors, measured with Pinocchio alone ------------------------------------------------
@dataclass
class ReachScene:
    """What both sides share: the model, the start, the frames and the wrist target."""

    robot: str
    model: pin.Model
    q0: np.ndarray  #: the half-sitting (start and posture target), size nq
    feet: tuple[str, str]  #: Pinocchio frames of the left and right ankle op points
    wrist: str  #: Pinocchio frame of the right-wrist op point
    target: np.ndarray  #: wrist target (m, world)

    def errors(self, q: np.ndarray) -> dict[str, float]:
        """Final errors at ``q`` against the start ``q0``.

        ``feet`` the largest foot displacement (m) and ``feet_rot`` the largest foot
        rotation (rad, ``||log3(R0^T R)||``); ``com`` the CoM's horizontal displacement
        (m); ``wrist`` the wrist's distance to its target (m); ``posture``
        ``||difference(q0, q)||`` over the joints (rad, the free flyer excluded).
        """
        model = self.model
        data = model.createData()

        def frames(qq: np.ndarray) -> list[pin.SE3]:
            pin.framesForwardKinematics(model, data, qq)
            return [data.oMf[model.getFrameId(f)].copy() for f in (*self.feet, self.wrist)]

        start = frames(self.q0)
        com0 = pin.centerOfMass(model, data, self.q0).copy()
        end = frames(q)
        com = pin.centerOfMass(model, data, q).copy()
        feet = max(
            float(np.linalg.norm(e.translation - s.translation))
            for s, e in zip(start[:2], end[:2], strict=True)
        )
        feet_rot = max(
            float(np.linalg.norm(pin.log3(s.rotation.T @ e.rotation)))
            for s, e in zip(start[:2], end[:2], strict=True)
        )
        dq = pin.difference(model, self.q0, q)
        root = 6 if model.joints[1].shortname() == "JointModelFreeFlyer" else 0
        return {
            "feet": feet,
            "feet_rot": feet_rot,
            "com": float(np.linalg.norm(com[:2] - com0[:2])),
            "wrist": float(np.linalg.norm(end[2].translation - self.target)),
            "posture": float(np.linalg.norm(dq[root:])),
        }

    @property
    def wrist_start_distance(self) -> float:
        """The wrist's distance to its target at the start (m)."""
        data = self.model.createData()
        pin.framesForwardKinematics(self.model, data, self.q0)
        return float(
            np.linalg.norm(data.oMf[self.model.getFrameId(self.wrist)].translation - self.target)
        )


def reach_scene(robot: str) -> ReachScene:
    """The stand-and-reach scene of ``robot`` (a sotpy robot description name)."""
    pool.clear()
    r = load_robot(robot)
    model = r.model
    data = model.createData()
    q0 = np.array(r.halfSitting, dtype=float)
    pin.framesForwardKinematics(model, data, q0)
    wrist = r.opPoints["right-wrist"]
    target = data.oMf[model.getFrameId(wrist)].translation + REACH[robot]
    pool.clear()
    return ReachScene(
        robot=robot,
        model=model,
        q0=q0,
        feet=(r.opPoints["left-ankle"], r.opPoints["right-ankle"]),
        wrist=wrist,
        target=target,
    )


# -- one episode ----------------------------------------------------------------------------
@dataclass
class Episode:
    """One run of ``ticks`` control ticks from the start.

    ``tick`` per-tick wall times (us); with the breakdown, ``solve`` and ``integration``
    per tick (us); ``methods`` counts sotpy's solve paths; ``errors`` the final errors
    (:meth:`ReachScene.errors`); ``failure`` a message if the controller raised (the
    episode stopped there)."""

    tick: np.ndarray
    errors: dict[str, float] = field(default_factory=dict)
    solve: np.ndarray | None = None
    integration: np.ndarray | None = None
    methods: dict[str, int] = field(default_factory=dict)
    failure: str | None = None
    rows: int = 0
    budget_hits: int = 0


class _Timed:
    """Wrap a callable, accumulating its wall time (s) into ``self.total``."""

    def __init__(self, fn: Callable[..., Any]) -> None:
        self.fn = fn
        self.total = 0.0

    def __call__(self, *args: Any, **kwargs: Any) -> Any:
        t0 = time.perf_counter()
        try:
            return self.fn(*args, **kwargs)
        finally:
            self.total += time.perf_counter() - t0


@dataclass
class SotpyController:
    """The sotpy graph of one episode: robot, SOT, the tasks pushed."""

    device: Any
    sot: SOT
    tasks: list[Task]


def build_sotpy_reach(
    scene: ReachScene, levels: bool = False, prefix: str = "", fused: bool = True
) -> SotpyController:
    """The sotpy stand-and-reach graph, its entities named with ``prefix`` (several
    graphs can then share the pool; the caller clears the pool).

    Stack: joint limits (the SOT's hard level), feet + CoM (one task; three with
    ``levels``), wrist position, posture. ``fused=False``: the SOT reads its tasks
    through their signals (``setTaskFusion(False)``) instead of writing their rows from
    the features' inputs.
    """
    r = load_robot(scene.robot, prefix=prefix + scene.robot)
    dyn, dev = r.dynamic, r.device
    dev.set(scene.q0)
    sot = SOT(prefix + "sot", dyn)
    sot.dt.value = DT
    if not fused:
        sot.setTaskFusion(False)
    lf = MetaTaskKine6d(prefix + "lf", dyn, "left-ankle")
    rf = MetaTaskKine6d(prefix + "rf", dyn, "right-ankle")
    com = MetaTaskKineCom(dyn, prefix + "com")
    for m in (lf, rf, com):
        m.keep()
    setGain(lf.gain, GAINS["feet"])
    setGain(rf.gain, GAINS["feet"])
    com.feature.selec.value = "11"
    setGain(com.gain, GAINS["com"])
    rh = MetaTaskKine6d(prefix + "rh", dyn, "right-wrist")
    rh.gotoNd(scene.target, "111000", GAINS["wrist"])
    posture = MetaTaskKinePosture(dyn, dev, prefix + "posture")
    posture.gotoq(scene.q0, GAINS["posture"])
    if levels:
        stack = [lf.task, rf.task, com.task]
    else:
        if GAINS["feet"] != GAINS["com"]:
            raise ValueError("one feet + CoM task needs GAINS['feet'] == GAINS['com']")
        contact = Task(prefix + "taskContactCom")
        for f in (lf.feature, rf.feature, com.feature):
            contact.add(f)
        contact.controlGain.value = GAINS["feet"]
        stack = [contact]
    stack += [rh.task, posture.task]
    for t in stack:
        sot.push(t)
    plug(sot.control, dev.control)
    dev.setControlType("velocity")
    return SotpyController(dev, sot, stack)


def build_sotpy_tutorial(scene: ReachScene, prefix: str = "tut_") -> SotpyController:
    """The humanoid graph of ``docs/tutorial-reach.md`` as the tutorial writes it: joint
    limits, then the feet and the balance polygon in ONE ``TaskInequality`` (the CoM's
    ground projection within the support polygon shrunk by 1 cm: inequality rows), the
    wrist's position with SoT's adaptive gain, the posture. Its wrist target is the
    scene's (the same as the other contenders')."""
    from sotpy.tasks import TaskInequality

    r = load_robot(scene.robot, prefix=prefix + scene.robot)
    dev = r.device
    dev.set(scene.q0)
    dev.setControlType("velocity")
    lf, rf = r.tasks["left-ankle"], r.tasks["right-ankle"]
    balance = r.tasks["balance"]
    contact = TaskInequality(prefix + "contact")
    for f in (lf.feature, rf.feature, balance.feature):
        contact.add(f)
    bounds = balance.bounds()
    contact.referenceInf.value = np.r_[np.zeros(12), np.full(len(bounds), -np.inf)]
    contact.referenceSup.value = np.r_[np.zeros(12), bounds]
    contact.dt.value = DT
    contact.controlGain.value = 1.0
    rh = r.tasks["right-wrist"]
    rh.gotoNd(scene.target, "111000", gain=(10.0, 2.0, 0.05, 0.5))
    posture = r.tasks["posture"]
    posture.gain.setConstant(1.0)
    sot = SOT(prefix + "sot", r.dynamic)
    sot.dt.value = DT
    stack = [contact, rh.task, posture.task]
    for task in stack:
        sot.push(task)
    plug(sot.control, dev.control)
    return SotpyController(dev, sot, stack)


class SotpyRunner:
    """Runs a :class:`SotpyController` tick by tick, in chunks (see :func:`interleave`).

    One tick is ``device.increment(DT)``, timed. With ``breakdown``, the SOT solver's
    ``solve`` and ``solve_stacked`` and the device's integration step (private
    attributes, wrapped on these instances only, until :meth:`finish`) are timed too
    (about 0.3 us per call)."""

    def __init__(
        self,
        controller: SotpyController,
        scene: ReachScene | None,
        ticks: int,
        breakdown: bool = False,
    ) -> None:
        self.controller, self.scene, self.breakdown = controller, scene, breakdown
        self.times = np.empty(ticks)
        self.solve = np.empty(ticks) if breakdown else None
        self.integration = np.empty(ticks) if breakdown else None
        self.methods: dict[str, int] = {}
        self.done = 0
        self.failure: str | None = None
        dev, sot = controller.device, controller.sot
        if breakdown:
            # the solver is called with the levels (solve) or, once the SOT writes its
            # rows in place, on its own buffers (solve_stacked): one timer for both
            self._solve = _Timed(sot._solver.solve)
            self._solve_stacked = _Timed(sot._solver.solve_stacked)
            self._step = _Timed(dev._step)
            sot._solver.solve = self._solve
            sot._solver.solve_stacked = self._solve_stacked
            dev._step = self._step

    def run(self, k: int) -> None:
        """``k`` more ticks (fewer at the end; none after a failure)."""
        if self.failure is not None:
            return
        dev, sot = self.controller.device, self.controller.sot
        increment, perf, times, methods = dev.increment, time.perf_counter, self.times, self.methods
        breakdown = self.breakdown
        stop = min(self.done + k, len(times))
        try:
            for i in range(self.done, stop):
                if breakdown:
                    self._solve.total = self._solve_stacked.total = self._step.total = 0.0
                t0 = perf()
                increment(DT)
                times[i] = perf() - t0
                if breakdown:
                    self.solve[i] = self._solve.total + self._solve_stacked.total
                    self.integration[i] = self._step.total
                method = sot.lastResult.method
                methods[method] = methods.get(method, 0) + 1
                self.done = i + 1
        except Exception as exc:  # reported in the table, not hidden
            self.failure = f"{type(exc).__name__} at tick {self.done}: {exc}"

    def finish(self) -> Episode:
        """Remove the timers; the episode (errors at the final state if a scene was
        given)."""
        dev, sot = self.controller.device, self.controller.sot
        if self.breakdown:
            del sot._solver.solve
            del sot._solver.solve_stacked
            del dev._step
        n = self.done
        ep = Episode(
            tick=self.times[:n] * 1e6,
            solve=None if self.solve is None else self.solve[:n] * 1e6,
            integration=None if self.integration is None else self.integration[:n] * 1e6,
            methods=self.methods,
            failure=self.failure,
            rows=sum(len(t.error.value) for t in self.controller.tasks),
            budget_hits=sot.budgetHits,
        )
        if self.scene is not None:
            ep.errors = self.scene.errors(np.array(dev.state.value))
        return ep


def run_sotpy(
    controller: SotpyController, scene: ReachScene | None, ticks: int, breakdown: bool = False
) -> Episode:
    """``ticks`` ticks of ``controller`` in one go (see :class:`SotpyRunner`)."""
    runner = SotpyRunner(controller, scene, ticks, breakdown)
    gc.collect()
    runner.run(ticks)
    return runner.finish()


# -- Pink -----------------------------------------------------------------------------------
def pink_available() -> bool:
    """Whether ``pin-pink`` (and qpsolvers) can be imported."""
    try:
        importlib.import_module("pink")
    except ImportError:
        return False
    return True


def pink_solvers() -> list[str]:
    """The QP back-ends of :data:`PINK_SOLVERS` that qpsolvers has installed."""
    import qpsolvers

    return [s for s in PINK_SOLVERS if s in qpsolvers.available_solvers]


@dataclass
class PinkController:
    """Pink's configuration and tasks for one episode."""

    configuration: Any
    tasks: list[Any]
    constraints: list[Any]


def build_pink_reach(scene: ReachScene, feet_hard: bool = False) -> PinkController:
    """Pink's stand-and-reach: the same frames, targets, gains (``alpha = lambda dt``)
    and limits; feet as costs, or as equality ``constraints`` with ``feet_hard``."""
    import pink
    from pink.tasks import ComTask, FrameTask, PostureTask

    model = pin.Model(scene.model)  # Pink sets attributes on its model: a copy
    configuration = pink.Configuration(model, model.createData(), scene.q0)
    c = PINK_COSTS
    feet = [
        FrameTask(f, position_cost=c["feet"], orientation_cost=c["feet"], gain=GAINS["feet"] * DT)
        for f in scene.feet
    ]
    com = ComTask(cost=np.array([c["com"], c["com"], 0.0]), gain=GAINS["com"] * DT)
    wrist = FrameTask(
        scene.wrist, position_cost=c["wrist"], orientation_cost=0.0, gain=GAINS["wrist"] * DT
    )
    posture = PostureTask(cost=c["posture"], gain=GAINS["posture"] * DT)
    for t in (*feet, com):
        t.set_target_from_configuration(configuration)
    start = configuration.get_transform_frame_to_world(scene.wrist)
    wrist.set_target(pin.SE3(start.rotation, scene.target))
    posture.set_target(scene.q0)
    if feet_hard:
        return PinkController(configuration, [com, wrist, posture], feet)
    return PinkController(configuration, [*feet, com, wrist, posture], [])


@contextlib.contextmanager
def _timed_qpsolvers(timed: _Timed) -> Iterator[None]:
    """Route ``qpsolvers.solve_problem`` (what Pink's ``solve_ik`` calls) through
    ``timed`` meanwhile."""
    import qpsolvers

    original = qpsolvers.solve_problem
    timed.fn = original
    qpsolvers.solve_problem = timed
    try:
        yield
    finally:
        qpsolvers.solve_problem = original


class PinkRunner:
    """Runs Pink tick by tick, in chunks: one tick is ``solve_ik(...)`` then
    ``configuration.integrate_inplace(v, DT)``, timed; with ``breakdown``, the time in
    ``qpsolvers.solve_problem`` too (patched during :meth:`run` only)."""

    def __init__(
        self,
        controller: PinkController,
        scene: ReachScene | None,
        ticks: int,
        solver: str,
        breakdown: bool = False,
    ) -> None:
        self.controller, self.scene, self.solver = controller, scene, solver
        self.times = np.empty(ticks)
        self.solve = np.empty(ticks) if breakdown else None
        self._timed = _Timed(lambda *a, **k: None) if breakdown else None
        self.done = 0
        self.failure: str | None = None

    def run(self, k: int) -> None:
        """``k`` more ticks (fewer at the end; none after a failure)."""
        from pink import solve_ik

        if self.failure is not None:
            return
        configuration, tasks = self.controller.configuration, self.controller.tasks
        constraints = self.controller.constraints or None
        solver, times, perf, timed = self.solver, self.times, time.perf_counter, self._timed
        stop = min(self.done + k, len(times))
        with contextlib.ExitStack() as stack:
            if timed is not None:
                stack.enter_context(_timed_qpsolvers(timed))
            try:
                for i in range(self.done, stop):
                    if timed is not None:
                        timed.total = 0.0
                    t0 = perf()
                    v = solve_ik(configuration, tasks, DT, solver=solver, constraints=constraints)
                    configuration.integrate_inplace(v, DT)
                    times[i] = perf() - t0
                    if timed is not None:
                        self.solve[i] = timed.total
                    self.done = i + 1
            except Exception as exc:  # reported in the table, not hidden
                first = str(exc).splitlines()[0][:120] if str(exc) else ""
                self.failure = f"{type(exc).__name__} at tick {self.done}: {first}"

    def finish(self) -> Episode:
        """The episode (errors at the final configuration if a scene was given)."""
        n = self.done
        ep = Episode(
            tick=self.times[:n] * 1e6,
            solve=None if self.solve is None else self.solve[:n] * 1e6,
            failure=self.failure,
        )
        if self.scene is not None:
            ep.errors = self.scene.errors(np.array(self.controller.configuration.q))
        return ep


def run_pink(
    controller: PinkController,
    scene: ReachScene | None,
    ticks: int,
    solver: str,
    breakdown: bool = False,
) -> Episode:
    """``ticks`` of Pink in one go (see :class:`PinkRunner`)."""
    runner = PinkRunner(controller, scene, ticks, solver, breakdown)
    gc.collect()
    runner.run(ticks)
    return runner.finish()


#: ticks each contender runs before the next one's turn in :func:`interleave`
CHUNK = 100


def interleave(
    runners: Sequence[SotpyRunner | PinkRunner], ticks: int, chunk: int = CHUNK
) -> list[Episode]:
    """Run ``ticks`` ticks of every runner, taking turns every ``chunk`` ticks (so that
    a change of the machine's load hits them alike), on a frozen heap as a real-time
    ``ControlLoop`` runs (``sotpy.loop.frozenHeap``; Pink's runners too); their
    episodes, in order."""
    with frozenHeap():
        for start in range(0, ticks, chunk):
            for r in runners:
                r.run(min(chunk, ticks - start))
    return [r.finish() for r in runners]


# -- 1. sotpy against Pink on Talos ----------------------------------------------------------
@dataclass
class Contender:
    """One line of the comparison: its episodes over the repeats."""

    name: str
    episodes: list[Episode] = field(default_factory=list)

    def pooled(self, key: str = "tick") -> np.ndarray:
        """The per-tick times ``key`` ("tick" or "solve", us) of every episode, joined."""
        arrays = [getattr(e, key) for e in self.episodes if getattr(e, key) is not None]
        return np.concatenate(arrays) if arrays else np.zeros(0)

    @property
    def failure(self) -> str | None:
        """The first episode's failure message, if any."""
        return next((e.failure for e in self.episodes if e.failure), None)

    @property
    def budget_hits(self) -> int:
        """The ticks that stopped at the solver's budget, over every episode."""
        return sum(e.budget_hits for e in self.episodes)

    @property
    def medians(self) -> list[float]:
        """The median tick (us) of each episode."""
        return [float(np.median(e.tick)) if len(e.tick) else float("nan") for e in self.episodes]


def screen_pink_solvers(scene: ReachScene, ticks: int) -> list[dict[str, Any]]:
    """One episode of ``ticks`` of Pink's stand-and-reach with each installed QP
    back-end (:func:`pink_solvers`), fastest first (failed ones last)."""
    rows = []
    for solver in pink_solvers():
        with warnings.catch_warnings():
            # the sparse back-ends warn that Pink's dense matrices are converted
            warnings.simplefilter("ignore")
            ep = run_pink(build_pink_reach(scene), scene, ticks, solver, breakdown=True)
        rows.append(
            {
                "solver": solver,
                "tick": float(np.median(ep.tick)) if len(ep.tick) else float("inf"),
                "solve": float(np.median(ep.solve)) if len(ep.solve) else float("nan"),
                "errors": ep.errors,
                "failure": ep.failure,
            }
        )
    return sorted(rows, key=lambda r: (r["failure"] is not None, r["tick"]))


def screen_table(rows: list[dict[str, Any]], ticks: int) -> str:
    """Markdown: the screening of Pink's QP back-ends."""
    lines = [
        f"Pink's QP back-ends screened on one episode of {ticks} ticks (the fastest go on "
        "to the interleaved comparison):",
        "",
        "| back-end | median us/tick | solver call us | wrist dist m | posture err rad "
        "| feet drift m | failure |",
        "|---|---:|---:|---:|---:|---:|---|",
    ]
    for r in rows:
        e = r["errors"]
        lines.append(
            f"| {r['solver']} | {_fmt(r['tick'])} | {_fmt(r['solve'])} "
            f"| {e.get('wrist', np.nan):.1e} | {e.get('posture', np.nan):.3f} "
            f"| {e.get('feet', np.nan):.1e} | {r['failure'] or ''} |"
        )
    return "\n".join(lines)


def compare(
    ticks: int,
    repeats: int,
    robot: str = "talos",
    solvers: Sequence[str] | None = None,
    screen_ticks: int = 300,
    keep: int = 3,
) -> dict[str, Any]:
    """The stand-and-reach on ``robot`` by sotpy (one feet + CoM level, and three
    levels) and by Pink, interleaved in ``repeats``, with the QP back-ends ``solvers``
    (default: the ``keep`` fastest of :func:`screen_pink_solvers` over ``screen_ticks``)
    and, when DAQP is among them, the feet as hard constraints with DAQP. Returns the
    contenders, the fastest Pink back-end, the ratios sotpy/Pink per repeat and the
    screening."""
    scene = reach_scene(robot)
    has_pink = pink_available()
    screening: list[dict[str, Any]] = []
    if has_pink and solvers is None:
        screening = screen_pink_solvers(scene, screen_ticks)
        solvers = [r["solver"] for r in screening if r["failure"] is None][:keep]
    solvers = list(solvers or []) if has_pink else []
    # name -> builder of a fresh runner (each repeat starts from the start)
    makers: dict[str, Callable[[], SotpyRunner | PinkRunner]] = {
        "sotpy": lambda: SotpyRunner(build_sotpy_reach(scene), scene, ticks, True),
        "sotpy, feet/feet/CoM on 3 levels": lambda: SotpyRunner(
            build_sotpy_reach(scene, levels=True, prefix="l3_"), scene, ticks, True
        ),
        "sotpy, tasks through their signals": lambda: SotpyRunner(
            build_sotpy_reach(scene, prefix="sig_", fused=False), scene, ticks, True
        ),
        TUTORIAL: lambda: SotpyRunner(build_sotpy_tutorial(scene), scene, ticks, True),
    }
    for s in solvers:
        makers[f"Pink {s}"] = lambda s=s: PinkRunner(build_pink_reach(scene), scene, ticks, s, True)
    if "daqp" in solvers:
        makers["Pink daqp, feet hard"] = lambda: PinkRunner(
            build_pink_reach(scene, feet_hard=True), scene, ticks, "daqp", True
        )
    contenders = {name: Contender(name) for name in makers}
    names = list(makers)
    for rep in range(repeats):
        pool.clear()
        order = names[rep % len(names) :] + names[: rep % len(names)]  # rotate the turns
        runners = [makers[name]() for name in order]
        for name, ep in zip(order, interleave(runners, ticks), strict=True):
            contenders[name].episodes.append(ep)
    pink_ok = [
        c
        for name, c in contenders.items()
        if name.startswith("Pink") and "hard" not in name and not c.failure
    ]
    fastest = min(pink_ok, key=lambda c: statistics.median(c.medians)) if pink_ok else None
    ratios = (
        [s / p for s, p in zip(contenders["sotpy"].medians, fastest.medians, strict=True)]
        if fastest
        else []
    )
    tutorial_ratios = (
        [s / p for s, p in zip(contenders[TUTORIAL].medians, fastest.medians, strict=True)]
        if fastest and not contenders[TUTORIAL].failure
        else []
    )
    return {
        "scene": scene,
        "ticks": ticks,
        "repeats": repeats,
        "contenders": contenders,
        "fastest": fastest.name if fastest else None,
        "ratios": ratios,
        "tutorial_ratios": tutorial_ratios,
        "screening": screening,
        "screen_ticks": screen_ticks,
        "pink": has_pink,
    }


def _fmt(x: float, digits: int = 0) -> str:
    return "—" if x is None or not np.isfinite(x) else f"{x:.{digits}f}"


def compare_table(result: dict[str, Any]) -> str:
    """Markdown: time per tick and final errors of every contender."""
    scene: ReachScene = result["scene"]
    lines = [
        f"Stand-and-reach on {scene.robot} (nv = {scene.model.nv}): dt = {DT * 1e3:g} ms, "
        f"{result['ticks']} ticks per episode (wrist at "
        f"{scene.wrist_start_distance:.3f} m from its target at the start), "
        f"{result['repeats']} interleaved repeats.",
        "",
        "| controller | median us/tick | p99 us/tick | worst us/tick | solver call us "
        "| feet drift m | feet rot rad | CoM xy err m | wrist dist m | posture err rad | notes |",
        "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---|",
    ]
    for name, c in result["contenders"].items():
        tick = c.pooled()
        solve = c.pooled("solve")
        err = c.episodes[-1].errors
        notes = []
        methods: dict[str, int] = {}
        for e in c.episodes:
            for k, v in e.methods.items():
                methods[k] = methods.get(k, 0) + v
        if methods:
            total = sum(methods.values())
            notes.append(
                "solve paths "
                + ", ".join(f"{k} {v / total:.0%}" for k, v in sorted(methods.items()))
            )
        if c.budget_hits:
            notes.append(f"{c.budget_hits} budget hits")
        if c.failure:
            notes.append(f"**failed**: {c.failure}")
        if name == result["fastest"]:
            notes.append("fastest Pink back-end")
        lines.append(
            f"| {name} | {_fmt(np.median(tick) if len(tick) else np.nan)} "
            f"| {_fmt(np.percentile(tick, 99) if len(tick) else np.nan)} "
            f"| {_fmt(np.max(tick) if len(tick) else np.nan)} "
            f"| {_fmt(np.median(solve) if len(solve) else np.nan)} "
            f"| {err.get('feet', np.nan):.1e} | {err.get('feet_rot', np.nan):.1e} "
            f"| {err.get('com', np.nan):.1e} | {err.get('wrist', np.nan):.1e} "
            f"| {err.get('posture', np.nan):.3f} | {'; '.join(notes)} |"
        )
    lines.append("")
    if not result["pink"]:
        lines.append("Pink skipped: `pin-pink` is not installed (`pip install -e .[bench]`).")
    elif result["ratios"]:
        r = result["ratios"]
        lines.append(
            f"sotpy / {result['fastest']}: median of per-repeat ratios "
            f"**{statistics.median(r):.2f}** (range {min(r):.2f} to {max(r):.2f})."
        )
        t = result.get("tutorial_ratios") or []
        if t:
            tut = result["contenders"][TUTORIAL].pooled()
            lines.append(
                f"{TUTORIAL} / {result['fastest']}: **{statistics.median(t):.2f}** (range"
                f" {min(t):.2f} to {max(t):.2f}); its p99 / median"
                f" **{np.percentile(tut, 99) / np.median(tut):.2f}**."
            )
    else:
        lines.append("No Pink back-end completed the episode: no ratio.")
    return "\n".join(lines)


# -- 2. scaling --------------------------------------------------------------------------------
def build_sotpy_tasks(n_tasks: int, prefix: str = "") -> SotpyController:
    """Talos with ``n_tasks`` equality tasks (and the joint-limit level): the first
    ``n_tasks - 1`` of feet (6-D, held), CoM (x, y, held), then position tasks ("111000")
    on :data:`SCALING_OP_POINTS`, each to 1 cm above its half-sitting position; the
    posture last. One task per level. Entities named with ``prefix`` (the caller clears
    the pool)."""
    if not 1 <= n_tasks <= 3 + len(SCALING_OP_POINTS) + 1:
        raise ValueError(f"n_tasks must be within 1..{4 + len(SCALING_OP_POINTS)}, got {n_tasks}")
    r = load_robot("talos", prefix=prefix + "talos")
    dyn, dev = r.dynamic, r.device
    for name, frame in TALOS_EXTRA_OP_POINTS.items():
        dyn.createOpPoint(name, frame)
    sot = SOT(prefix + "sot", dyn)
    sot.dt.value = DT
    stack: list[Task] = []
    k = n_tasks - 1
    for i, side in enumerate(("left-ankle", "right-ankle")):
        if len(stack) < k:
            m = MetaTaskKine6d(f"{prefix}foot{i}", dyn, side)
            m.keep()
            setGain(m.gain, GAINS["feet"])
            stack.append(m.task)
    if len(stack) < k:
        com = MetaTaskKineCom(dyn, prefix + "com")
        com.keep()
        com.feature.selec.value = "11"
        setGain(com.gain, GAINS["com"])
        stack.append(com.task)
    for op in SCALING_OP_POINTS:
        if len(stack) >= k:
            break
        m = MetaTaskKine6d(f"{prefix}op_{op}", dyn, op)
        p = m.feature.position.value.translation + np.array([0.0, 0.0, 0.01])
        m.gotoNd(p, "111000", GAINS["wrist"])
        stack.append(m.task)
    posture = MetaTaskKinePosture(dyn, dev, prefix + "posture")
    posture.gotoq(r.halfSitting, GAINS["posture"])
    stack.append(posture.task)
    for t in stack:
        sot.push(t)
    plug(sot.control, dev.control)
    dev.setControlType("velocity")
    return SotpyController(dev, sot, stack)


def _breakdown_row(label: str, episodes: list[Episode], extra: dict[str, Any]) -> dict[str, Any]:
    tick = np.concatenate([e.tick for e in episodes])
    solve = np.concatenate([e.solve for e in episodes])
    integ = np.concatenate([e.integration for e in episodes])
    graph = tick - solve - integ
    methods: dict[str, int] = {}
    for e in episodes:
        for k, v in e.methods.items():
            methods[k] = methods.get(k, 0) + v
    total = sum(methods.values())
    return {
        "label": label,
        "tick": float(np.median(tick)),
        "p99": float(np.percentile(tick, 99)),
        "worst": float(np.max(tick)),
        "graph": float(np.median(graph)),
        "solve": float(np.median(solve)),
        "integration": float(np.median(integ)),
        "methods": {k: v / total for k, v in sorted(methods.items())},
        "failure": next((e.failure for e in episodes if e.failure), None),
        "budget_hits": sum(e.budget_hits for e in episodes),
        **extra,
    }


def scaling_tasks(
    counts: Sequence[int] = (1, 2, 5, 10, 20), ticks: int = 500, repeats: int = 5
) -> list[dict[str, Any]]:
    """sotpy's tick on Talos against the number of tasks (see :func:`build_sotpy_tasks`),
    with its breakdown; one row per count, the counts interleaved (:func:`interleave`)
    in each repeat."""
    episodes: dict[int, list[Episode]] = {n: [] for n in counts}
    for _ in range(repeats):
        pool.clear()
        runners = [
            SotpyRunner(build_sotpy_tasks(n, prefix=f"n{n}_"), None, ticks, True) for n in counts
        ]
        for n, ep in zip(counts, interleave(runners, ticks), strict=True):
            episodes[n].append(ep)
    return [
        _breakdown_row(str(n), episodes[n], {"tasks": n, "rows": episodes[n][0].rows, "nv": 38})
        for n in counts
    ]


def scaling_dof(
    robots: Sequence[str] = ("nao", "talos", "romeo"),
    ticks: int = 1000,
    repeats: int = 5,
    pink_solver: str | None = None,
) -> list[dict[str, Any]]:
    """The stand-and-reach on each robot: sotpy's tick with its breakdown, and Pink's
    (``pink_solver``, if given), all interleaved (:func:`interleave`) in each repeat."""
    scenes = {r: reach_scene(r) for r in robots}
    sot_eps: dict[str, list[Episode]] = {r: [] for r in robots}
    pink_eps: dict[str, list[Episode]] = {r: [] for r in robots}
    for _ in range(repeats):
        pool.clear()
        runners: list[SotpyRunner | PinkRunner] = []
        for r in robots:
            scene = scenes[r]
            controller = build_sotpy_reach(scene, prefix=f"{r}_")
            runners.append(SotpyRunner(controller, scene, ticks, True))
            if pink_solver:
                runners.append(PinkRunner(build_pink_reach(scene), scene, ticks, pink_solver, True))
        episodes = iter(interleave(runners, ticks))
        for r in robots:
            sot_eps[r].append(next(episodes))
            if pink_solver:
                pink_eps[r].append(next(episodes))
    rows = []
    for r in robots:
        extra: dict[str, Any] = {
            "nv": scenes[r].model.nv,
            "rows": sot_eps[r][0].rows,
            "errors": sot_eps[r][-1].errors,
        }
        if pink_solver:
            ptick = np.concatenate([e.tick for e in pink_eps[r]])
            extra["pink"] = float(np.median(ptick)) if len(ptick) else float("nan")
            extra["pink_errors"] = pink_eps[r][-1].errors
            extra["pink_failure"] = next((e.failure for e in pink_eps[r] if e.failure), None)
            extra["ratio"] = (
                statistics.median(
                    float(np.median(s.tick) / np.median(p.tick))
                    for s, p in zip(sot_eps[r], pink_eps[r], strict=True)
                    if len(p.tick)
                )
                if all(len(p.tick) for p in pink_eps[r])
                else float("nan")
            )
        rows.append(_breakdown_row(r, sot_eps[r], extra))
    return rows


def _methods(m: dict[str, float]) -> str:
    return ", ".join(f"{k} {v:.0%}" for k, v in m.items())


def scaling_tasks_table(rows: list[dict[str, Any]], ticks: int, repeats: int) -> str:
    lines = [
        f"sotpy on Talos (nv = 38) against the number of tasks: {ticks} ticks x {repeats} "
        "repeats; us per tick (medians; the parts are medians of their own, so they need not "
        "add up exactly).",
        "",
        "| tasks | task rows | median tick | p99 tick | worst tick | graph + kinematics | solve "
        "| integration | solve paths |",
        "|---:|---:|---:|---:|---:|---:|---:|---:|---|",
    ]
    for r in rows:
        fail = f"; {r['budget_hits']} budget hits" if r["budget_hits"] else ""
        fail += f"; **failed**: {r['failure']}" if r["failure"] else ""
        lines.append(
            f"| {r['tasks']} | {r['rows']} | {r['tick']:.0f} | {r['p99']:.0f} | {r['worst']:.0f} "
            f"| {r['graph']:.0f} "
            f"| {r['solve']:.0f} | {r['integration']:.0f} | {_methods(r['methods'])}{fail} |"
        )
    return "\n".join(lines)


def scaling_dof_table(
    rows: list[dict[str, Any]], ticks: int, repeats: int, solver: str | None
) -> str:
    lines = [
        f"The stand-and-reach against the degrees of freedom: {ticks} ticks x {repeats} "
        "repeats; us per tick (medians); wrist distance at the end (m).",
        "",
        "| robot | nv | task rows | median tick | p99 tick | worst tick | graph + kinematics "
        "| solve | integration | solve paths | wrist dist | "
        + (f"Pink {solver} tick | sotpy/Pink | Pink wrist dist |" if solver else ""),
        "|---|---:|---:|---:|---:|---:|---:|---:|---:|---|---:|"
        + ("---:|---:|---:|" if solver else ""),
    ]
    for r in rows:
        fail = f"; {r['budget_hits']} budget hits" if r["budget_hits"] else ""
        fail += f"; **failed**: {r['failure']}" if r["failure"] else ""
        line = (
            f"| {r['label']} | {r['nv']} | {r['rows']} | {r['tick']:.0f} | {r['p99']:.0f} "
            f"| {r['worst']:.0f} | {r['graph']:.0f} | {r['solve']:.0f} | {r['integration']:.0f} "
            f"| {_methods(r['methods'])}{fail} | {r['errors']['wrist']:.1e} |"
        )
        if solver:
            pf = " (failed)" if r.get("pink_failure") else ""
            line += (
                f" {_fmt(r['pink'])}{pf} | {_fmt(r['ratio'], 2)} "
                f"| {r['pink_errors'].get('wrist', np.nan):.1e} |"
            )
        lines.append(line)
    return "\n".join(lines)


# -- profile -----------------------------------------------------------------------------------
#: areas of the profile summary: (label, test on the profiled function's file or name)
_AREAS: tuple[tuple[str, Callable[[str, str], bool]], ...] = (
    ("sotpy.solvers", lambda f, n: "/sotpy/solvers/" in f),
    ("sotpy.tasks", lambda f, n: "/sotpy/tasks/" in f),
    ("sotpy.dynamics", lambda f, n: "/sotpy/dynamics/" in f),
    ("sotpy.graph", lambda f, n: "/sotpy/graph/" in f),
    ("numpy (C functions)", lambda f, n: f == "~" and "numpy" in n),
    ("numpy, scipy (Python functions)", lambda f, n: "/numpy/" in f or "/scipy/" in f),
    ("other", lambda f, n: True),
)


def profile_sotpy(ticks: int = 1000, top: int = 15, robot: str = "talos") -> str:
    """cProfile of ``ticks`` sotpy stand-and-reach ticks, as Markdown: own time by area
    and the ``top`` functions by own time (us per tick).

    cProfile sees Python functions and numpy's C functions, not Pinocchio's (Boost.Python)
    nor scipy's LAPACK wrappers: their time counts as the own time of the Python function
    that calls them (``Dynamic``'s callbacks, the solver's steps). The profiler's
    overhead inflates the total."""
    scene = reach_scene(robot)
    pool.clear()
    controller = build_sotpy_reach(scene)
    controller.sot.setTimeBudget(None)  # the profiler's overhead would spend the budget
    dev = controller.device
    for _ in range(20):
        dev.increment(DT)
    profiler = cProfile.Profile()
    profiler.enable()
    for _ in range(ticks):
        dev.increment(DT)
    profiler.disable()
    stats = pstats.Stats(profiler, stream=io.StringIO())
    total = stats.total_tt
    areas = {label: 0.0 for label, _ in _AREAS}
    for (filename, _line, name), (_cc, _nc, tt, _ct, _callers) in stats.stats.items():
        label = next(lb for lb, test in _AREAS if test(filename, name))
        areas[label] += tt
    lines = [
        f"cProfile of {ticks} sotpy ticks on {robot}: {total / ticks * 1e6:.0f} us per tick "
        "under the profiler. Own time by area (Pinocchio's and LAPACK's calls count in the "
        "Python function that makes them):",
        "",
        "| area | own us/tick | own % |",
        "|---|---:|---:|",
    ]
    for label, tt in sorted(areas.items(), key=lambda kv: -kv[1]):
        lines.append(f"| {label} | {tt / ticks * 1e6:.0f} | {tt / total:.0%} |")
    lines += [
        "",
        "| function | calls/tick | own us/tick | own % | cumulative us/tick |",
        "|---|---:|---:|---:|---:|",
    ]
    entries = sorted(stats.stats.items(), key=lambda kv: kv[1][2], reverse=True)[:top]
    for (filename, line, name), (_cc, nc, tt, ct, _callers) in entries:
        if "/src/" in filename:
            where = filename.rsplit("/src/", 1)[-1]
        else:
            where = filename.rsplit("/", 1)[-1]
        label = f"`{name}` ({where}:{line})" if line else f"`{name}`"
        lines.append(
            f"| {label} | {nc / ticks:.1f} | {tt / ticks * 1e6:.1f} | {tt / total:.0%} "
            f"| {ct / ticks * 1e6:.1f} |"
        )
    return "\n".join(lines)


# -- main ------------------------------------------------------------------------------------------
def versions() -> str:
    """The versions of the libraries in the comparison."""
    parts = [f"Pinocchio {pin.__version__}", f"numpy {np.__version__}"]
    for mod in ("pink", "qpsolvers", "daqp", "proxsuite", "quadprog"):
        try:
            m = importlib.import_module(mod)
        except ImportError:
            continue
        v = getattr(m, "__version__", None)
        if v is None:
            from importlib.metadata import PackageNotFoundError, version

            dist = {"pink": "pin-pink"}.get(mod, mod)
            with contextlib.suppress(PackageNotFoundError):
                v = version(dist)
        parts.append(f"{mod} {v}")
    return ", ".join(parts)


def episode_warnings() -> None:
    """The benchmark's warning filters: a reused entity name or an unsatisfiable hard
    level fails the episode (reported in the tables); a tick that stops at the solver's
    time budget is the real-time contract at work, not a failure: the episode goes on
    and the tables count such ticks (``Episode.budget_hits``)."""
    warnings.simplefilter("error", SotpyWarning)
    warnings.simplefilter("ignore", BudgetWarning)


def main(argv: list[str] | None = None) -> dict[str, Any]:
    parser = argparse.ArgumentParser(description=__doc__.split("\n", 1)[0])
    parser.add_argument("--quick", action="store_true", help="fewer ticks and repeats")
    parser.add_argument("--profile", action="store_true", help="add a cProfile summary")
    args = parser.parse_args(argv)
    episode_warnings()
    if args.quick:
        cmp_ticks, cmp_rep, sc_ticks, sc_rep, prof = 300, 2, 100, 2, 300
    else:
        cmp_ticks, cmp_rep, sc_ticks, sc_rep, prof = 2000, 7, 500, 5, 2000
    out: dict[str, Any] = {}
    print(machine_line(versions()))
    print()
    print("### Stand-and-reach: sotpy against Pink")
    print()
    out["compare"] = compare(cmp_ticks, cmp_rep, screen_ticks=cmp_ticks // 4)
    if out["compare"]["screening"]:
        print(screen_table(out["compare"]["screening"], out["compare"]["screen_ticks"]))
        print()
    print(compare_table(out["compare"]))
    print()
    sys.stdout.flush()
    print("### Scaling with the number of tasks")
    print()
    out["tasks"] = scaling_tasks(ticks=sc_ticks, repeats=sc_rep)
    print(scaling_tasks_table(out["tasks"], sc_ticks, sc_rep))
    print()
    sys.stdout.flush()
    print("### Scaling with the degrees of freedom")
    print()
    solver = out["compare"]["fastest"]
    solver = solver.split(" ", 1)[1] if solver else None
    out["dof"] = scaling_dof(ticks=2 * sc_ticks, repeats=sc_rep, pink_solver=solver)
    print(scaling_dof_table(out["dof"], 2 * sc_ticks, sc_rep, solver))
    if args.profile:
        print()
        print("### Where sotpy's tick goes")
        print()
        print(profile_sotpy(prof))
    return out


if __name__ == "__main__":
    main()
