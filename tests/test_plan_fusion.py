"""Fused plan steps (``OutputSignal.setPlanFusion``) and the SOT's fused evaluation of
its tasks (``SOT.setTaskFusion``), equality and inequality.

Graph level: a fused output is computed by one step over the sources its hook gives,
the signals in between are left out of the plan and still computed when read, the hook
is asked again after each topology change, and a fused output that is not live is
pulled through its callbacks.

SOT level: the stand-and-reach graph of ``benchmarks/bench_sot.py`` built twice in one
pool, fusion on and off, must give the same control tick after tick, the same errors
(type and message) for bad input, and the same values to every other reader of the
task signals (a tracer, an adaptive gain); the fused plan must not contain the feature
and task signals.
"""

from __future__ import annotations

import math
import warnings
from collections import Counter
from types import SimpleNamespace

import numpy as np
import pinocchio as pin
import pytest

from sotpy.dynamics import load_robot
from sotpy.errors import CommandError, SotpyError, SotpyWarning, UnpluggedError
from sotpy.graph import DOUBLE, MATRIX, VECTOR, Entity, Input, Output, Plan, compilePlan, plug, pool
from sotpy.graph.tracer import Tracer
from sotpy.solvers import SOT
from sotpy.tasks import (
    FeatureGeneric,
    FeaturePose,
    FeaturePosture,
    FeatureVisualPoint,
    Flags,
    Task,
    TaskInequality,
)
from sotpy.tasks import _rowkernels as rk
from sotpy.tasks.rows import RowProgram

DT = 0.001
TICKS = 50
ON, OFF = "fusedX_", "plainX_"  # entity name prefixes of the two graphs

needs_kernels = pytest.mark.skipif(rk.write_rows is None, reason="task fusion needs numba")


# -- graph level ----------------------------------------------------------------------
class FusionClock(Entity):
    """out(t) = offset + t (time-dependent)."""

    def __init__(self, name: str, offset: float = 0.0) -> None:
        self.offset = offset

    @Output(DOUBLE, withTime=True, timeDependent=True)
    def out(self, t):
        return self.offset + float(t)


class FusionNode(Entity):
    """m = 2 u, y = m + 1 (the fused output), z = 10 y and w = -m (other readers);
    counts the callback calls."""

    u = Input(DOUBLE)

    def __init__(self, name: str) -> None:
        self.calls: Counter[str] = Counter()

    @Output(DOUBLE, deps=("u",))
    def m(self, u):
        self.calls["m"] += 1
        return 2.0 * u

    @Output(DOUBLE, deps=("m",))
    def y(self, m):
        self.calls["y"] += 1
        return m + 1.0

    @Output(DOUBLE, deps=("y",))
    def z(self, y):
        return 10.0 * y

    @Output(DOUBLE, deps=("m",))
    def w(self, m):
        return -m


class FusionSum(Entity):
    """m = 2 u, y = m + v."""

    u = Input(DOUBLE)
    v = Input(DOUBLE)

    @Output(DOUBLE, deps=("u",))
    def m(self, u):
        return 2.0 * u

    @Output(DOUBLE, deps=("m", "v"))
    def y(self, m, v):
        return m + v


def fuse_y(node: FusionNode, log: Counter, enabled: bool = True) -> None:
    """Fuse ``y`` over ``u``'s holder: ``y = 2 u + 1`` in one step. ``log`` counts the
    hook's and the fused function's calls."""

    def fn(u):
        log["fn"] += 1
        return 2.0 * u + 1.0

    def hook():
        log["hook"] += 1
        return ((node.u._holder(),), fn) if enabled else None

    node.y.setPlanFusion(hook)


def test_fused_live_output_skips_the_intermediate_step():
    clock, n, log = FusionClock("clk"), FusionNode("n"), Counter()
    plug(clock.out, n.u)
    fuse_y(n, log)
    plan = Plan([n.y])
    for t in range(6):
        plan.run(t)
        assert n.y.value == 2.0 * t + 1.0
        assert n.y.time == t
    assert plan.steps == [clock.out, n.y]  # m is not a step
    assert log == Counter(hook=1, fn=6)  # compiled once, one fused call per tick
    assert n.calls == Counter()  # neither m's nor y's callback ran
    # m is still computed, by its callback, when something reads it
    assert n.m.value == 10.0
    assert n.calls == Counter(m=1)
    assert n.y.value == 11.0  # already up to date: not recomputed
    assert n.calls == Counter(m=1)
    assert n.w.value == -10.0


def test_hook_returning_none_gives_the_usual_plan():
    clock, n, log = FusionClock("clk"), FusionNode("n"), Counter()
    plug(clock.out, n.u)
    fuse_y(n, log, enabled=False)
    plan = Plan([n.y])
    for t in range(4):
        plan.run(t)
        assert n.y.value == 2.0 * t + 1.0
    assert plan.steps == [clock.out, n.m, n.y]
    assert log == Counter(hook=1)
    assert n.calls == Counter(m=4, y=4)


def test_removing_the_hook_recompiles_the_usual_plan():
    clock, n, log = FusionClock("clk"), FusionNode("n"), Counter()
    plug(clock.out, n.u)
    fuse_y(n, log)
    plan = Plan([n.y])
    plan.run(0)
    assert n.m not in plan.steps
    n.y.setPlanFusion(None)
    plan.run(1)
    assert plan.steps == [clock.out, n.m, n.y]
    assert n.y.value == 3.0
    assert log["hook"] == 1 and log["fn"] == 1


def test_topology_change_recompiles_and_asks_the_hook_again():
    c1, c2 = FusionClock("clk1"), FusionClock("clk2", offset=100.0)
    n, log = FusionNode("n"), Counter()
    plug(c1.out, n.u)
    fuse_y(n, log)
    plan = Plan([n.y])
    plan.run(0)
    plan.run(1)
    assert log["hook"] == 1
    assert n.y.value == 3.0
    plug(c2.out, n.u)  # another source: the hook must give the new holder
    plan.run(2)
    assert log["hook"] == 2
    assert plan.steps == [c2.out, n.y]
    assert n.y.value == 2.0 * 102.0 + 1.0
    n.u.value = 4.0  # a constant: the fused output is no longer live
    plan.run(3)
    assert log["hook"] == 3
    assert plan.steps == [n.y]
    assert n.y.value == 9.0
    plan.run(4)  # no topology change: no new compilation
    assert log["hook"] == 3


def test_non_live_fused_output_is_pulled_through_its_callbacks():
    n, log = FusionNode("n"), Counter()
    n.u.value = 3.0
    fuse_y(n, log)
    plan = Plan([n.y])
    plan.run(0)
    assert plan.steps == [n.y]  # m left out; y pulled over its real dependencies
    assert n.y.value == 7.0
    assert log["fn"] == 0  # the pull runs the callbacks, not the fused function
    assert n.calls == Counter(m=1, y=1)
    assert n.m.time == 0
    for t in (1, 2, 3):  # nothing changed: the lazy rule recomputes nothing
        plan.run(t)
    assert n.calls == Counter(m=1, y=1)
    pool.time = 4
    n.u.value = 5.0
    plan.run(4)
    assert n.y.value == 11.0 and n.m.value == 10.0
    assert n.calls == Counter(m=2, y=2)
    assert log["fn"] == 0


def test_fused_output_feeds_later_steps_and_other_readers_keep_the_intermediate():
    clock, n, log = FusionClock("clk"), FusionNode("n"), Counter()
    plug(clock.out, n.u)
    fuse_y(n, log)
    plan = Plan([n.z])  # z reads the fused y
    for t in range(3):
        plan.run(t)
        assert n.z.value == 10.0 * (2.0 * t + 1.0)
    assert plan.steps == [clock.out, n.y, n.z]
    both = Plan([n.z, n.w])  # w reads m: m is a step again, y still fused
    for t in range(3, 6):
        both.run(t)
        assert n.z.value == 10.0 * (2.0 * t + 1.0)
        assert n.w.value == -2.0 * t
    assert both.steps == [clock.out, n.y, n.z, n.m, n.w]
    assert n.calls["y"] == 0 and log["fn"] == 6


def test_unset_fused_source_is_reported_at_compilation():
    n, log = FusionNode("n"), Counter()
    fuse_y(n, log)
    with pytest.raises(UnpluggedError, match=r"n\)::input\(double\)::u"):
        compilePlan([n.y])


def test_same_tick_constant_write_outdates_a_fused_output():
    # signal.py: "Writing a constant at the current tick makes every dependant outdated
    # at once (push invalidation)". y = 2 u + v, v live (a clock), fused over (u, v):
    # m = 2 u, skipped by the fused step, stays invalidated, so the push reaches y
    # through the sources' fused readers, not through m.
    clock, n = FusionClock("clk"), FusionSum("n")
    n.u.value = 1.0
    plug(clock.out, n.v)
    n.y.setPlanFusion(lambda: ((n.u._holder(), n.v._holder()), lambda u, v: 2.0 * u + v))
    plan = Plan([n.y])
    plan.run(0)
    plan.run(1)
    assert n.y.value == 3.0
    n.u.value = 5.0  # same tick
    assert n.y.value == 11.0


# -- SOT level: the stand-and-reach graph, fused and not --------------------------------
@pytest.fixture(scope="module")
def scenes(bench_sot):
    cache: dict = {}

    def get(robot: str):
        if robot not in cache:
            cache[robot] = bench_sot.reach_scene(robot)
        return cache[robot]

    return get


def build_pair(bench_sot, scene):
    """The reach graph twice in the pool: ``ON`` with fusion (the default), ``OFF``
    without."""
    on = bench_sot.build_sotpy_reach(scene, prefix=ON)
    off = bench_sot.build_sotpy_reach(scene, prefix=OFF)
    for c in (on, off):  # bit-for-bit comparisons: no stop that depends on the machine's speed
        c.sot.setTimeBudget(None)
    assert on.sot.getTaskFusion() is True  # on by default with numba
    off.sot.setTaskFusion(False)
    assert off.sot.getTaskFusion() is False
    return on, off


def same_name(message: str) -> str:
    """The message with the prefix of either graph replaced by one name."""
    return message.replace(ON, "P_").replace(OFF, "P_")


def tick_both(on, off, ticks: int) -> None:
    """``ticks`` ticks of each; the states, controls and solver paths agree at each.

    The controls compared are the solver's (``lastResult.x``): reading
    ``sot.control.value`` here would pull it, through the task signals, at the next
    tick, and that tick's plan would then find it up to date and skip the fused step.
    While ``on`` fuses, its last task's ``task`` signal must not be computed at the
    tick (the fused step ran instead; a tracer may read it after, at the next tick)."""
    for _ in range(ticks):
        fused = on.sot.getTaskFusion()
        on.device.increment(DT)
        off.device.increment(DT)
        t = on.device.state.time - 1  # the tick just run
        assert on.sot.control.time == off.sot.control.time == t
        if fused and on.sot.getTaskFusion():
            assert on.tasks[-1].task.time != t
        np.testing.assert_allclose(
            on.device.state.value, off.device.state.value, rtol=0, atol=1e-12
        )
        a, b = on.sot.lastResult, off.sot.lastResult
        np.testing.assert_allclose(a.x, b.x, rtol=0, atol=1e-12)
        assert a.method == b.method
        np.testing.assert_array_equal(a.ranks, b.ranks)


def task_and_feature_signals(controller) -> list:
    out = []
    for t in controller.tasks:
        out += [t.error, t.jacobian, t.task]
        for f in t.features():
            out += [f.error, f.jacobian]
    return out


def entity(name: str):
    return pool.getEntity(name)


@needs_kernels
@pytest.mark.parametrize("robot", ["talos", "nao"])
def test_fused_and_unfused_reach_give_the_same_control(bench_sot, scenes, robot):
    scene = scenes(robot)
    on, off = build_pair(bench_sot, scene)
    tick_both(on, off, TICKS)
    # the run did something: the wrist moved towards its target, the feet stayed (up to
    # the integration's drift, micrometres)
    errors = scene.errors(on.device.state.value)
    assert errors["wrist"] < scene.wrist_start_distance - 1e-3
    assert errors["feet"] < 1e-4
    assert on.sot.getTaskFusion() is True  # no fallback switched it off


@needs_kernels
def test_fused_plan_skips_task_signals_which_still_read_correctly(bench_sot, scenes):
    scene = scenes("talos")
    on, off = build_pair(bench_sot, scene)
    tick_both(on, off, TICKS)
    steps_on = set(map(id, on.device._controlPlan.steps))
    steps_off = set(map(id, off.device._controlPlan.steps))
    sigs_on, sigs_off = task_and_feature_signals(on), task_and_feature_signals(off)
    assert len(sigs_on) == 3 * 3 + 2 * 5  # 3 tasks, 5 features
    assert not any(id(s) in steps_on for s in sigs_on)
    assert all(id(s) in steps_off for s in sigs_off)
    assert on.sot.control in on.device._controlPlan.steps
    # never computed by the fused run (the last computation: the push's width check)
    assert all(s.time < TICKS - 1 for s in sigs_on)
    assert all(s.time == TICKS - 1 for s in sigs_off)
    # read now, they are computed by their callbacks: the values of the unfused graph
    for a, b in zip(sigs_on, sigs_off, strict=True):
        np.testing.assert_allclose(a.value, b.value, rtol=0, atol=1e-12, err_msg=a.name)
        assert a.time == pool.time
    # and the wrist's, independently with Pinocchio: position rows of FeaturePose
    rh = entity(f"feature{ON}rh")
    model = scene.model
    data = model.createData()
    q = on.device.state.value
    fid = model.getFrameId(scene.wrist)
    pin.computeJointJacobians(model, data, q)
    pin.updateFramePlacements(model, data)
    Md = rh.reference.value
    e = Md.rotation.T @ (data.oMf[fid].translation - Md.translation)
    J = Md.rotation.T @ pin.getFrameJacobian(model, data, fid, pin.LOCAL_WORLD_ALIGNED)[:3]
    np.testing.assert_allclose(rh.error.value, e, rtol=0, atol=1e-12)
    np.testing.assert_allclose(rh.jacobian.value, J, rtol=0, atol=1e-12)
    task = entity(f"task{ON}rh")
    np.testing.assert_allclose(task.task.value, -bench_sot.GAINS["wrist"] * e, rtol=0, atol=1e-12)


# faults: (apply, fix, what the message must name), each given (controller, prefix)
def _gain_fault(c, p):
    c.tasks[0].controlGain.value = -1.0


def _gain_fix(c, p, bench_sot):
    c.tasks[0].controlGain.value = bench_sot.GAINS["feet"]


def _inf_reference(c, p):
    entity(f"featureDes{p}com").errorIN.value = [np.inf, 0.0, 0.0]


def _reference_fix(c, p, bench_sot):
    entity(f"featureDes{p}com").errorIN.value = entity(f"{p}talos_dynamic").com.value


class FusionNaN(Entity):
    """A vector output holding ``value`` (time-dependent: read every tick)."""

    @Output(VECTOR)
    def out(self):
        return self.value


def _nan_reference(c, p):
    src = FusionNaN(p + "nan")
    src.value = np.array([0.0, np.nan, 0.0])
    plug(src.out, entity(f"featureDes{p}com").errorIN)


def _long_selection(c, p):
    entity(f"feature{p}rh").selec.value = "1110001"  # row 6 of a 6-row feature


def _selection_fix(c, p, bench_sot):
    entity(f"feature{p}rh").selec.value = "111000"


def _jq_rows(c, p):
    entity(f"feature{p}rh").Jq.value = np.ones((5, c.sot.nv))


def _jq_fix(c, p, bench_sot):
    plug(entity(f"{p}talos_dynamic").signal("Jright-wrist"), entity(f"feature{p}rh").Jq)


def _posture_size(c, p):
    entity(f"feature{p}posture").posture.value = np.zeros(3)


def _posture_fix(c, p, bench_sot):
    entity(f"feature{p}posture").posture.value = entity(f"{p}talos_device").state.value


def _com_width(c, p):
    entity(f"feature{p}com").jacobianIN.value = np.ones((3, c.sot.nv + 1))


def _com_width_fix(c, p, bench_sot):
    dyn = entity(f"{p}talos_dynamic")
    plug(dyn.Jcom, entity(f"feature{p}com").jacobianIN)


FAULTS = {
    "negative gain": (_gain_fault, _gain_fix, "{p}taskContactCom"),
    "infinite reference": (_inf_reference, _reference_fix, "feature{p}com"),
    "NaN from a plugged output": (_nan_reference, _reference_fix, "feature{p}com"),
    "selection too long": (_long_selection, _selection_fix, "feature{p}rh"),
    "Jq of 5 rows": (_jq_rows, _jq_fix, "feature{p}rh"),
    "posture of the wrong size": (_posture_size, _posture_fix, "feature{p}posture"),
    "Jacobian of another width": (_com_width, _com_width_fix, "feature{p}com"),
}


@needs_kernels
@pytest.mark.parametrize("fault", list(FAULTS))
def test_errors_with_fusion_are_those_of_the_signals(bench_sot, scenes, fault):
    apply, fix, names = FAULTS[fault]
    on, off = build_pair(bench_sot, scenes("talos"))
    tick_both(on, off, 5)
    caught = {}
    for c, p in ((on, ON), (off, OFF)):
        apply(c, p)
        before = c.device.state.value.copy()
        t = c.device.state.time
        with pytest.raises(SotpyError) as info:
            c.device.increment(DT)
        caught[p] = info.value
        # the tick failed before the integration: the state is unchanged
        assert c.device.state.time == t
        np.testing.assert_array_equal(c.device.state.value, before)
    assert type(caught[ON]) is type(caught[OFF])
    assert same_name(str(caught[ON])) == same_name(str(caught[OFF]))
    assert names.format(p=ON) in str(caught[ON])
    # fixed, the loop runs again, fused, with the same control as the unfused graph
    for c, p in ((on, ON), (off, OFF)):
        fix(c, p, bench_sot)
    tick_both(on, off, 5)
    assert on.sot.getTaskFusion() is True
    steps = set(map(id, on.device._controlPlan.steps))
    assert not any(id(s) in steps for s in task_and_feature_signals(on))


@needs_kernels
def test_adaptive_gain_and_tracer_read_task_error_with_fusion(bench_sot, scenes):
    scene = scenes("talos")
    on, off = build_pair(bench_sot, scene)
    tracers = {}
    for c, p in ((on, ON), (off, OFF)):
        entity(f"gain{p}rh").set(6.0, 3.0, 20.0)  # reads the wrist task's error
        tr = Tracer(p + "tracer")
        tr.add(entity(f"task{p}rh").error, "rh_error")
        tr.add(entity(f"feature{p}com").error, "com_error")
        tr.add(entity(f"task{p}posture").task, "posture_task")
        tr.start()
        c.device.after.addSignal(tr.trigger)
        tracers[p] = tr
    tick_both(on, off, 30)
    # the gain's reader made the wrist task's error a step; the posture task is fused
    steps = on.device._controlPlan.steps
    assert entity(f"task{ON}rh").error in steps
    assert entity(f"gain{ON}rh").gain in steps
    assert entity(f"task{ON}posture").task not in steps
    assert entity(f"task{ON}rh").task not in steps
    d_on, d_off = tracers[ON].data(), tracers[OFF].data()
    assert d_on["rh_error"].shape == (30, 3)
    np.testing.assert_array_equal(d_on["time"], d_off["time"])
    for label in ("rh_error", "com_error", "posture_task"):
        np.testing.assert_allclose(d_on[label], d_off[label], rtol=0, atol=1e-12)
    # the last row: the wrist's error at the final state, with Pinocchio
    model, data = scene.model, scene.model.createData()
    pin.framesForwardKinematics(model, data, on.device.state.value)
    Md = entity(f"feature{ON}rh").reference.value
    e = Md.rotation.T @ (data.oMf[model.getFrameId(scene.wrist)].translation - Md.translation)
    np.testing.assert_allclose(d_on["rh_error"][-1], e, rtol=0, atol=1e-12)
    # the adaptive gain followed the error: 3 + 3 exp(-20/3 |e|)
    gain = entity(f"gain{ON}rh").gain.value
    assert gain == pytest.approx(3.0 + 3.0 * math.exp(-20.0 / 3.0 * np.linalg.norm(e)), rel=1e-12)


@needs_kernels
def test_switching_fusion_off_and_on_while_running_keeps_the_control(bench_sot, scenes):
    on, off = build_pair(bench_sot, scenes("talos"))
    rh_task = entity(f"task{ON}rh").task
    tick_both(on, off, 15)
    assert rh_task not in on.device._controlPlan.steps
    on.sot.setTaskFusion(False)
    tick_both(on, off, 15)
    assert rh_task in on.device._controlPlan.steps
    on.sot.setTaskFusion(True)
    assert on.sot.getTaskFusion() is True
    tick_both(on, off, 20)
    assert rh_task not in on.device._controlPlan.steps


# -- SOT level: other stacks -------------------------------------------------------------
def mixed_stack(prefix: str):
    """Nao with: an inequality task, a fused pose task, a pose task with the derivative
    feed-forward (read through its signals), a 150-row generic task (more rows than the
    SOT's initial buffer), a fused posture task."""
    rng = np.random.default_rng(99)
    r = load_robot("nao", prefix=prefix + "nao")
    dyn, dev = r.dynamic, r.device
    nv = r.model.nv
    sot = SOT(prefix + "sot", dyn)
    sot.dt.value = DT

    fi = FeatureGeneric(prefix + "fineq")
    fi.errorIN.value = 0.01 * rng.standard_normal(2)
    fi.jacobianIN.value = rng.standard_normal((2, nv))
    ineq = TaskInequality(prefix + "ineq")
    ineq.add(fi)
    ineq.referenceInf.value = [-0.02, -0.02]
    ineq.referenceSup.value = [0.02, 0.02]
    ineq.dt.value = DT

    def pose_task(name, op, offset, derivative):
        f = FeaturePose(prefix + "f" + name)
        plug(dyn.signal(op), f.position)
        plug(dyn.signal("J" + op), f.Jq)
        M = dyn.signal(op).value
        f.reference.value = pin.SE3(M.rotation, M.translation + offset)
        f.selec.value = "111000"
        t = Task(prefix + name)
        t.add(f)
        t.controlGain.value = 2.0
        if derivative:
            f.referenceVelocity.value = [0.01, 0.0, 0.02, 0.0, 0.0, 0.0]
            t.setWithDerivative(True)
        return t

    left = pose_task("left", "left-wrist", np.array([0.02, 0.0, 0.01]), False)
    right = pose_task("right", "right-wrist", np.array([0.0, -0.01, 0.02]), True)

    fb = FeatureGeneric(prefix + "fbig")
    fb.errorIN.value = 0.01 * rng.standard_normal(150)
    fb.jacobianIN.value = rng.standard_normal((150, nv))
    big = Task(prefix + "big")
    big.add(fb)
    big.controlGain.value = 0.1

    fp = FeaturePosture(prefix + "fposture", dyn.model)
    plug(dev.state, fp.state)
    fp.posture.value = dev.state.value
    posture = Task(prefix + "posture")
    posture.add(fp)
    posture.controlGain.value = 1.0

    stack = [ineq, left, right, big, posture]
    for t in stack:
        sot.push(t)
    plug(sot.control, dev.control)
    dev.setControlType("velocity")

    return SimpleNamespace(device=dev, sot=sot, tasks=stack)


@needs_kernels
def test_mixed_stack_with_inequalities_and_unfused_tasks():
    on, off = mixed_stack(ON), mixed_stack(OFF)
    off.sot.setTaskFusion(False)
    tick_both(on, off, 20)
    steps = on.device._controlPlan.steps
    ineq, left, right, big, posture = on.tasks
    # read through its signals: the task with the feed-forward
    for s in (right.jacobian, right.task):
        assert s in steps, s.name
    # fused: the others, the inequality task too
    for s in (ineq.jacobian, ineq.lower, ineq.upper):
        assert s not in steps, s.name
    for t in (left, big, posture):
        assert t.task not in steps and t.jacobian not in steps, t.name
    # the buffer grew to hold the fused rows (3 + 150 + 26)
    rows = 3 + 150 + on.sot.nv - 6
    assert on.sot._rowsA.shape[0] >= rows > 64
    assert on.sot.getTaskFusion() is True


class Float32Jacobian(Entity):
    """A matrix output handing out ``value`` as float32 (no input coerces it)."""

    @Output(MATRIX)
    def out(self):
        return self.value.astype(np.float32)


@needs_kernels
def test_fortran_jacobians_stay_on_the_fused_path(bench_sot, scenes):
    """A Jacobian in Fortran order (a user's entity, Eigen's own layout): the kernel
    takes it as it is (no warning, no fallback) and gives the control of the signals."""
    on, off = build_pair(bench_sot, scenes("talos"))
    tick_both(on, off, 3)
    for p in (ON, OFF):
        f = entity(f"feature{p}com")
        f.jacobianIN.value = np.asfortranarray(f.jacobianIN.value)
        assert f.jacobianIN.value.flags.f_contiguous
    with warnings.catch_warnings():
        warnings.simplefilter("error", SotpyWarning)
        tick_both(on, off, 5)
    assert on.sot.getTaskFusion() is True
    assert entity(f"{ON}taskContactCom").task not in on.device._controlPlan.steps


@needs_kernels
def test_kernel_refusing_a_float32_jacobian_falls_back_with_a_warning(bench_sot, scenes):
    on, off = build_pair(bench_sot, scenes("talos"))
    tick_both(on, off, 3)
    for p in (ON, OFF):
        src = Float32Jacobian(p + "f32")
        src.value = np.asarray(entity(f"{p}talos_dynamic").Jcom.value)
        plug(src.out, entity(f"feature{p}com").jacobianIN)
    assert entity(f"feature{ON}com").jacobianIN.value.dtype == np.float32
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        tick_both(on, off, 5)
    messages = [str(w.message) for w in caught if issubclass(w.category, SotpyWarning)]
    assert len(messages) == 1
    assert f"SOT({ON}sot)'s task rows: compiled kernels refused the data" in messages[0]
    # the signals from then on
    assert on.sot.getTaskFusion() is False
    assert entity(f"{ON}taskContactCom").task in on.device._controlPlan.steps


@needs_kernels
def test_read_only_inputs_stay_on_the_fused_path(bench_sot, scenes):
    """A Dynamic's Jacobians are read-only arrays: the kernels take them (no warning,
    no fallback) and give the control of the signals."""
    on, off = build_pair(bench_sot, scenes("talos"))
    tick_both(on, off, 3)
    for p in (ON, OFF):
        f = entity(f"feature{p}com")
        f.jacobianIN.value.flags.writeable = False  # as a Dynamic's output is
        assert not f.jacobianIN.value.flags.writeable
    with warnings.catch_warnings():
        warnings.simplefilter("error", SotpyWarning)
        tick_both(on, off, 5)
    assert on.sot.getTaskFusion() is True
    assert entity(f"{ON}taskContactCom").task not in on.device._controlPlan.steps


def test_set_task_fusion_needs_the_kernels(monkeypatch):
    monkeypatch.setattr(rk, "write_rows", None)
    r = load_robot("nao", prefix="nokernels")
    sot = SOT("sot", r.dynamic)
    assert sot.getTaskFusion() is False
    with pytest.raises(CommandError, match=r"SOT\(sot\)\.setTaskFusion: .*numba"):
        sot.setTaskFusion(True)
    sot.setTaskFusion(False)  # always allowed


@needs_kernels
def test_gain_change_after_a_plan_run_is_seen_in_the_same_tick():
    controls = {}
    for p, fused in ((ON, True), (OFF, False)):
        r = load_robot("nao", prefix=p + "nao")
        sot = SOT(p + "sot", r.dynamic)
        sot.dt.value = DT
        sot.setTaskFusion(fused)
        rng = np.random.default_rng(0)
        f = FeatureGeneric(p + "f")
        f.errorIN.value = rng.standard_normal(3)
        f.jacobianIN.value = rng.standard_normal((3, r.model.nv))
        t = Task(p + "t")
        t.add(f)
        sot.push(t)
        compilePlan([sot.control]).run(pool.time)
        before = sot.control.value.copy()
        t.controlGain.value = 2.0  # same tick: the control must follow
        controls[p] = (before, sot.control.value.copy())
    np.testing.assert_allclose(controls[ON][0], controls[OFF][0], atol=1e-12)
    assert not np.allclose(controls[OFF][0], controls[OFF][1])  # the gain matters
    np.testing.assert_allclose(controls[ON][1], controls[OFF][1], atol=1e-12)


# -- SOT level: rows written in place into the solver's buffers ---------------------------
def count_solves(sot) -> Counter:
    """Count the SOT solver's calls with the levels (``solve``) and on the rows the SOT
    wrote in place (``solve_stacked``)."""
    calls: Counter = Counter()
    solver = sot._solver
    for name in ("solve", "solve_stacked"):
        real = getattr(solver, name)

        def spy(*args, _real=real, _name=name, **kwargs):
            calls[_name] += 1
            return _real(*args, **kwargs)

        setattr(solver, name, spy)
    return calls


@needs_kernels
def test_rows_are_written_in_place_from_the_second_tick(bench_sot, scenes):
    """The first tick of a plan goes through the levels (it learns their sizes), the
    next ones write every row straight into the solver's buffers, with the control of
    the unfused graph at every tick. A stack edit recompiles the plan: once through the
    levels again."""
    on, off = build_pair(bench_sot, scenes("talos"))
    calls = count_solves(on.sot)
    tick_both(on, off, 10)
    assert calls == {"solve": 1, "solve_stacked": 9}
    # limits, feet and CoM, wrist position, posture
    assert on.sot._inPlace[1] == on.sot._solver._buf.sizes == (32, 14, 3, 32)
    for c in (on, off):
        c.sot.remove(c.tasks[-1])  # the posture
    tick_both(on, off, 5)
    assert calls == {"solve": 2, "solve_stacked": 13}
    assert on.sot._solver._buf.sizes == (32, 14, 3)


@needs_kernels
def test_a_task_changing_size_goes_through_the_levels_once(bench_sot, scenes):
    on, off = build_pair(bench_sot, scenes("talos"))
    calls = count_solves(on.sot)
    tick_both(on, off, 5)
    for p in (ON, OFF):
        entity(f"feature{p}rh").selec.value = "111111"  # the wrist: 3 rows to 6
    tick_both(on, off, 5)
    assert calls == {"solve": 2, "solve_stacked": 8}
    assert on.sot._solver._buf.sizes == (32, 14, 6, 32)


@needs_kernels
def test_new_limits_are_seen_in_the_same_tick(bench_sot, scenes):
    """Velocity limits replaced by a new array while running: the row program makes
    the limit rows again from the new array in the same tick (still in place: the
    same joints are limited), and the control respects the new limits from that tick
    on."""
    on, off = build_pair(bench_sot, scenes("talos"))
    vmax = np.asarray(on.sot.upperVl.value)
    for c in (on, off):
        c.sot.upperVl.value = vmax  # a constant from now on (the plan recompiles)
    calls = count_solves(on.sot)
    tick_both(on, off, 5)
    assert calls == {"solve": 1, "solve_stacked": 4}
    iv = on.sot._iv
    slow = 0.02 * vmax
    for c in (on, off):
        c.sot.upperVl.value = slow  # a new array, the same plan
    tick_both(on, off, 5)
    assert calls == {"solve": 1, "solve_stacked": 9}
    assert on.sot._limits.vmax is on.sot.upperVl.value
    x = on.sot.lastResult.x
    assert np.all(np.abs(x[iv]) <= slow[iv] + 1e-9)
    assert np.abs(x[iv]).max() > 0.9 * slow[iv].min()  # the new limits are active
    # one joint without a velocity limit nor position limits: one row fewer, through
    # the levels once
    unlimited = slow.copy()
    unlimited[iv[0]] = np.inf
    for c in (on, off):
        lower = np.asarray(c.sot.lowerJl.value).copy()
        upper = np.asarray(c.sot.upperJl.value).copy()
        lower[on.sot._iq[0]], upper[on.sot._iq[0]] = -np.inf, np.inf
        c.sot.lowerJl.value, c.sot.upperJl.value = lower, upper
        c.sot.upperVl.value = unlimited
    tick_both(on, off, 5)
    assert calls == {"solve": 2, "solve_stacked": 13}
    assert on.sot._inPlace[1][0] == on.sot.nv - 6 - 1


@needs_kernels
def test_limit_rows_kernel_is_the_limit_level_bit_for_bit():
    """The joint-limit level written by the row program (a ``LIMITS`` operation)
    against ``SOT._limitLevel``: random configurations inside and beyond the limits,
    joints without a velocity limit or a position limit, a NaN configuration entry."""
    r = load_robot("talos", prefix="limitsX_")
    sot = SOT("limitsX_sot", r.dynamic)
    program = RowProgram([sot._limitsOp()])
    rng = np.random.default_rng(7)
    lower = np.asarray(r.dynamic.lowerJl.value).copy()
    upper = np.asarray(r.dynamic.upperJl.value).copy()
    vmax = np.asarray(r.dynamic.upperVl.value).copy()
    lower[8], upper[9], vmax[10] = -np.inf, np.inf, np.inf
    for trial in range(20):
        q = pin.randomConfiguration(
            r.model, r.model.lowerPositionLimit - 0.3, r.model.upperPositionLimit + 0.3
        )
        if trial == 0:
            q[12] = np.nan
        dt = float(rng.uniform(1e-4, 1e-2))
        A, lo, hi = sot._limitLevel(q, lower, upper, vmax, dt)
        m = A.shape[0]
        A2 = np.full((m + 3, sot.nv), 7.0)
        lo2, hi2 = np.full(m + 3, 7.0), np.full(m + 3, 7.0)
        ends = np.zeros(1, dtype=np.int64)
        assert program.run((q, lower, upper, vmax, dt), A2, lo2, hi2, ends, False) == m
        assert ends[0] == m
        np.testing.assert_array_equal(A2[:m], A)
        np.testing.assert_array_equal(lo2[:m], lo)
        np.testing.assert_array_equal(hi2[:m], hi)
        assert lo2[m] == hi2[m] == 7.0 and (A2[m:] == 7.0).all()  # nothing else written
        if trial == 0:
            assert np.isnan(lo).any()
        # the same rows checked against the level's known end, or refused when it moved
        assert program.run((q, lower, upper, vmax, dt), A2, lo2, hi2, ends, True) == m
        ends[0] = m + 1
        assert program.run((q, lower, upper, vmax, dt), A2, lo2, hi2, ends, True) == rk.RESIZED


# -- the tutorial's graph: an inequality task (feet + balance polygon) fused ----------------
def tutorial_pair(bench_sot, scenes, margin: float = 0.01):
    """The graph of docs/tutorial-reach.md twice, fusion on and off, with the balance
    polygon shrunk by ``margin`` (m); no time budget (bit-for-bit comparisons)."""
    scene = scenes("talos")
    pair = []
    for p in (ON, OFF):
        c = bench_sot.build_sotpy_tutorial(scene, prefix=p)
        contact = c.tasks[0]
        if margin != 0.01:
            sup = np.asarray(contact.referenceSup.value).copy()
            sup[12:] -= margin - 0.01
            contact.referenceSup.value = sup
        c.sot.setTimeBudget(None)
        pair.append(c)
    pair[1].sot.setTaskFusion(False)
    return pair


def _max_diff(on, off, ticks):
    worst = 0.0
    active = 0
    for _ in range(ticks):
        on.device.increment(DT)
        off.device.increment(DT)
        worst = max(worst, float(np.abs(on.sot.lastResult.x - off.sot.lastResult.x).max()))
        active = max(active, len(on.sot.lastResult.active[1]))
    return worst, active


@needs_kernels
@pytest.mark.parametrize("margin", [0.01, 0.09])
def test_fused_inequality_task_gives_the_control_of_its_signals(bench_sot, scenes, margin):
    """The tutorial's contact task (feet equalities and balance inequalities in one
    TaskInequality) written straight into the solver's rows gives the control of the
    same graph read through its signals, with the balance rows inactive (1 cm margin)
    and active (9 cm: the CoM starts at the shrunk polygon); the fused plan skips the
    task's lower/upper/jacobian signals."""
    on, off = tutorial_pair(bench_sot, scenes, margin)
    worst, active = _max_diff(on, off, 300)
    assert worst < 1e-10  # the same arithmetic but for the rounding of the rows' writers
    assert (active > 0) == (margin > 0.05)  # the balance rows were held in the 9 cm case
    contact = on.tasks[0]
    steps = on.device._controlPlan.steps
    for s in (contact.jacobian, contact.lower, contact.upper):
        assert s not in steps, s.name
    assert on.sot._inPlace is not None  # written into the solver's buffers


@needs_kernels
def test_fused_inequality_task_declines_bad_bounds_and_the_signals_name_them(bench_sot, scenes):
    """A referenceSup of the wrong size: the writer declines, the task's signal raises
    the same named error as the unfused graph's; fixed, both run on, fused."""
    on, off = tutorial_pair(bench_sot, scenes)
    _max_diff(on, off, 3)
    errors = {}
    for c, p in ((on, ON), (off, OFF)):
        good = np.asarray(c.tasks[0].referenceSup.value).copy()
        c.tasks[0].referenceSup.value = good[:5]
        with pytest.raises(SotpyError) as info:
            c.device.increment(DT)
        errors[p] = same_name(str(info.value))
        c.tasks[0].referenceSup.value = good
    assert errors[ON] == errors[OFF] and "referenceSup" in errors[ON]
    worst, _ = _max_diff(on, off, 5)
    assert worst < 1e-10 and on.sot.getTaskFusion()


# -- random stacks: the row program against the signals ------------------------------------
def _random_rotation(rng: np.random.Generator) -> np.ndarray:
    q = rng.standard_normal(4)
    q /= np.linalg.norm(q)
    return pin.Quaternion(q[3], q[0], q[1], q[2]).matrix()


def _random_flags(rng: np.random.Generator, n: int, p: float = 0.6) -> Flags:
    keep = rng.random(n) < p
    keep[rng.integers(n)] = True  # at least one row
    return Flags(keep)


def _random_feature(rng, p: str, name: str, robot, kind: str):
    """A feature of ``kind`` with random inputs (constants; the posture reads the device)."""
    nv = robot.model.nv
    if kind == "pose":
        f = FeaturePose(p + name)
        f.position.value = pin.SE3(_random_rotation(rng), rng.standard_normal(3))
        f.reference.value = pin.SE3(_random_rotation(rng), rng.standard_normal(3))
        f.Jq.value = rng.standard_normal((6, nv))
        f.selec.value = _random_flags(rng, 6)
    elif kind in ("generic", "generic+ref"):
        m = int(rng.integers(1, 7))
        f = FeatureGeneric(p + name)
        f.errorIN.value = rng.standard_normal(m)
        f.jacobianIN.value = rng.standard_normal((m, nv))
        f.selec.value = _random_flags(rng, m)
        if kind == "generic+ref":
            ref = FeatureGeneric(p + name + "_des")
            ref.errorIN.value = rng.standard_normal(m)
            f.setReference(ref)
    elif kind == "visual":
        f = FeatureVisualPoint(p + name)
        f.xy.value = rng.uniform(-0.3, 0.3, 2)
        f.Z.value = float(rng.uniform(0.5, 2.0))
        f.Jq.value = rng.standard_normal((6, nv))
        f.xyRef.value = rng.uniform(-0.3, 0.3, 2)
    else:  # a posture, over a few DoFs; the free flyer's among them: its callbacks
        f = FeaturePosture(p + name, robot.model)
        plug(robot.device.state, f.state)
        f.posture.value = pin.integrate(
            robot.model, robot.device.state.value, 0.1 * rng.standard_normal(nv)
        )
        first = 0 if kind == "posture+base" else 6
        f.selec.value = Flags([i >= first and rng.random() < 0.5 for i in range(nv)]).set(7)
    return f


KINDS = ["pose", "generic", "generic+ref", "visual", "posture", "posture+base"]


def _random_stack(rng, p: str, robot, sot, n_tasks: int) -> list:
    tasks = []
    for i in range(n_tasks):
        kinds = rng.choice(KINDS, size=int(rng.integers(1, 4)))
        inequality = rng.random() < 0.35
        t = (TaskInequality if inequality else Task)(f"{p}t{i}")
        for j, kind in enumerate(kinds):
            t.add(_random_feature(rng, p, f"f{i}_{j}", robot, str(kind)))
        if rng.random() < 0.3:
            t.controlSelec.value = _random_flags(rng, robot.model.nv, 0.8)
        if inequality:
            m = t.error.value.shape[0]
            e = t.error.value
            lo = e - rng.uniform(-0.1, 1.0, m)
            up = lo + rng.uniform(0.0, 2.0, m)
            lo[rng.random(m) < 0.2] = -np.inf
            t.referenceInf.value = lo
            t.referenceSup.value = up if rng.random() < 0.8 else np.zeros(0)
            t.dt.value = DT
            t.controlGain.value = float(rng.uniform(0.1, 1.0))
        else:
            t.controlGain.value = float(rng.uniform(0.1, 20.0))
        if rng.random() < 0.15:  # a feed-forward: this task is read through its signals
            t.setWithDerivative(True)
        sot.push(t)
        tasks.append(t)
    return tasks


@needs_kernels
@pytest.mark.parametrize("seed", range(16))
def test_random_stacks_give_the_control_of_their_signals(seed):
    """Random stacks (1 to 9 tasks of 1 to 3 features of every kind the row program
    knows, or copies from their callbacks; equality and inequality tasks, column
    selections, feed-forward tasks read through their signals; the largest cut into
    several kernel calls) on Nao: at every tick the fused SOT's control is the control
    of the same stack through its signals."""
    controls = {}
    programs = {}
    for p, fused in ((ON, True), (OFF, False)):
        rng = np.random.default_rng(seed)
        r = load_robot("nao", prefix=p + "nao")
        r.device.setControlType("velocity")
        sot = SOT(p + "sot", r.dynamic)
        sot.dt.value = DT
        sot.setTimeBudget(None)
        sot.setTaskFusion(fused)
        _random_stack(rng, p, r, sot, int(rng.integers(1, 10)))
        plug(sot.control, r.device.control)
        xs = []
        for _ in range(4):
            r.device.increment(DT)
            xs.append(sot.lastResult.x.copy())
        controls[p] = np.array(xs)
        programs[p] = sot._inPlace
    assert programs[OFF] is None
    if programs[ON] is not None:  # fused (a stack of feed-forward tasks alone is not)
        assert programs[ON][0].levels == len(programs[ON][1])
    np.testing.assert_allclose(controls[ON], controls[OFF], rtol=0, atol=1e-9)
