"""Values that cannot be meant are refused where they enter, naming the entity and the
signal, not later by the solver as "level k, row i": a task target that overflows, an
inequality bound that cannot be met or overflows, swapped joint limits, infinite contact
gains, a reference whose rotation is not a rotation."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

from sotpy.dynamics import Device, Dynamic
from sotpy.errors import CommandError, SignalTypeError, SotpyError
from sotpy.graph import plug
from sotpy.loop import ControlLoop
from sotpy.solvers.sot import SOT
from sotpy.tasks import FeatureGeneric, FeaturePose, Task, TaskInequality


@pytest.fixture
def arm():
    model = pin.buildSampleModelManipulator()
    dyn = Dynamic("dyn", model)
    dev = Device("dev", model)
    dev.set(pin.neutral(model))
    plug(dev.state, dyn.position)
    sot = SOT("sot", dyn)
    sot.dt.value = 0.01
    plug(sot.control, dev.control)
    return model, dyn, dev, sot


def _generic(name: str, nv: int, e: list[float], col: int = 0) -> FeatureGeneric:
    f = FeatureGeneric(name)
    J = np.zeros((len(e), nv))
    for i in range(len(e)):
        J[i, col + i] = 1.0
    f.jacobianIN.value = J
    f.errorIN.value = np.array(e)
    return f


@pytest.mark.filterwarnings("ignore:overflow encountered:RuntimeWarning")
def test_a_task_target_that_overflows_is_refused_by_the_task(arm):
    model, _, dev, sot = arm
    t = Task("t")
    t.add(_generic("f", model.nv, [10.0]))  # a 10 m error
    t.controlGain.value = 1e308
    sot.push(t)
    with pytest.raises(SotpyError, match=r"Task\(t\)::output\(vector\)::task\[0\]") as info:
        _ = t.task.value
    msg = str(info.value)
    assert "controlGain = 1e+308" in msg and "error[0] = 10" in msg and "not finite" in msg
    with pytest.raises(SotpyError, match=r"Task\(t\).*controlGain = 1e\+308"):
        _ = sot.control.value
    # in a running loop too (a compiled plan, with the SOT's fused rows when compiled)
    loop = ControlLoop("loop", dev, 0.01)
    with pytest.raises(SotpyError, match=r"Task\(t\)::output\(vector\)::task\[0\]"):
        loop.step(1)
    assert loop.fault is not None
    # a large but finite target is fine
    loop.clearFault()
    plug(sot.control, dev.control)
    t.controlGain.value = 1e10
    np.testing.assert_allclose(t.task.value, [-1e11])
    assert np.isfinite(sot.control.value).all()  # clipped by the joint-limit level


def test_inequality_bounds_no_error_can_meet_are_refused(arm):
    model, _, _, sot = arm
    ti = TaskInequality("ti")
    ti.add(_generic("g", model.nv, [0.0, 0.0]))
    ti.dt.value = 0.01
    sot.push(ti)
    ti.referenceInf.value = [np.inf, -1.0]
    ti.referenceSup.value = [np.inf, 1.0]
    with pytest.raises(
        SignalTypeError, match=r"TaskInequality\(ti\)::input\(vector\)::referenceInf\[0\] = inf"
    ):
        _ = sot.control.value
    ti.referenceInf.value = [-1.0, -1.0]
    ti.referenceSup.value = [1.0, -np.inf]
    with pytest.raises(SignalTypeError, match=r"referenceSup\[1\] = -inf: a bound no error"):
        _ = ti.upper.value


@pytest.mark.filterwarnings("ignore:overflow encountered:RuntimeWarning")
def test_an_inequality_bound_that_overflows_is_refused_not_dropped(arm):
    model, _, _, sot = arm
    ti = TaskInequality("ti")
    ti.add(_generic("g", model.nv, [0.0]))
    ti.dt.value = 1e-3  # controlGain / dt = 1000
    ti.referenceInf.value = [-1.0]
    ti.referenceSup.value = [1e307]  # 1000 * 1e307 overflows to +inf: no bound any more
    sot.push(ti)
    with pytest.raises(
        SignalTypeError, match=r"TaskInequality\(ti\)::output\(vector\)::upper\[0\]"
    ) as info:
        _ = sot.control.value
    assert "referenceSup[0] = 1e+307" in str(info.value)
    ti.controlGain.value = 1e308
    ti.dt.value = 1e-10
    with pytest.raises(
        SignalTypeError, match=r"controlGain / dt = 1e\+308 / 1e-10 s is not finite"
    ):
        _ = ti.lower.value


def test_a_row_with_both_bounds_infinite_is_a_free_row(arm):
    # the decision: such a row bounds nothing, so it changes nothing (not an error)
    model, _, _, sot = arm
    goal = Task("goal")
    goal.add(_generic("fg", model.nv, [0.3, -0.2, 0.1], col=0))
    sot.push(goal)
    alone = sot.control.value.copy()
    ti = TaskInequality("ti")
    ti.add(_generic("g", model.nv, [0.0, 0.0], col=0))
    ti.dt.value = 0.01
    ti.referenceInf.value = [-np.inf, -np.inf]
    ti.referenceSup.value = [np.inf, np.inf]
    sot.push(ti)
    sot.up(ti)  # above the goal: a real bound here would change the goal's solution
    np.testing.assert_array_equal(ti.lower.value, [-np.inf, -np.inf])
    np.testing.assert_allclose(sot.control.value, alone, atol=1e-12)
    assert alone[0] == pytest.approx(-0.3)
    ti.referenceInf.value = [0.0, -np.inf]  # a real bound on row 0, qdot_0 >= 0, does
    assert sot.control.value[0] == pytest.approx(0.0, abs=1e-9)


def test_swapped_joint_limits_are_refused_naming_the_signals(arm):
    _, dyn, _, sot = arm
    sot.lowerJl.value = dyn.upperJl.value.copy()
    sot.upperJl.value = dyn.lowerJl.value.copy()
    with pytest.raises(SignalTypeError, match=r"SOT\(sot\): joint at q\[0\]") as info:
        _ = sot.control.value
    msg = str(info.value)
    assert "SOT(sot)::input(vector)::lowerJl" in msg and "swapped" in msg
    plug(dyn.lowerJl, sot.lowerJl)
    plug(dyn.upperJl, sot.upperJl)
    np.testing.assert_array_equal(sot.control.value, np.zeros(dyn.model.nv))


def test_infinite_contact_gains_are_refused(arm):
    _, _, dev, _ = arm
    with pytest.raises(CommandError, match=r"Device\(dev\)\.setContactGains: gains must be finite"):
        dev.setContactGains(np.inf, 20.0)
    with pytest.raises(CommandError, match="must be finite"):
        dev.setContactGains(100.0, float("inf"))
    dev.setContactGains(100.0, 20.0)


def test_a_reference_whose_rotation_is_not_a_rotation_is_refused():
    f = FeaturePose("fp")
    with pytest.raises(
        SignalTypeError, match=r"FeaturePose\(fp\)::input\(SE3\)::reference.*not a rotation"
    ):
        f.reference.value = pin.SE3(5 * np.eye(3), np.zeros(3))
    with pytest.raises(SignalTypeError, match="det R = -1"):
        f.reference.value = pin.SE3(np.diag([1.0, 1.0, -1.0]), np.zeros(3))  # a reflection
    with pytest.raises(SignalTypeError, match="non-finite"):
        f.reference.value = pin.SE3(np.eye(3), np.array([0.0, np.inf, 0.0]))
    R = pin.rpy.rpyToMatrix(0.1, -0.4, 2.0)
    M = pin.SE3(R + 1e-9, np.array([0.1, 0.2, 0.3]))  # rounding-level noise: accepted
    f.reference.value = M
    np.testing.assert_array_equal(f.reference.value.rotation, M.rotation)
