"""Removing entities: refused while anything outside the removed group uses them (naming
every user, the graph left as it was); a group removed together; a stale reference to a
removed entity cannot be wired again; a re-created entity of the same name works."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

from sotpy.dynamics import Device, Dynamic
from sotpy.errors import EntityError, PlugError
from sotpy.graph import DOUBLE, VECTOR, Entity, Input, Output, Tracer, plug, pool
from sotpy.loop import ControlLoop
from sotpy.solvers.sot import SOT
from sotpy.tasks import FeatureGeneric, Task


class RmEntAdd(Entity):
    """out = a + 1."""

    a = Input(DOUBLE)

    @Output(DOUBLE, deps=("a",))
    def out(self, a):
        return a + 1.0


class RmEntSum(Entity):
    """out = sum of the signals it is made to read (setDependencies)."""

    @Output(DOUBLE)
    def out(self, *values):
        return float(sum(values))


class RmEntVector(Entity):
    """sout = sin."""

    sin = Input(VECTOR)

    @Output(VECTOR, deps=("sin",))
    def sout(self, x):
        return x


def _arm():
    """A sample manipulator driven by an SOT with one task on joint 0 (velocity control)."""
    model = pin.buildSampleModelManipulator()
    dyn = Dynamic("dyn", model)
    dev = Device("dev", model)
    dev.set(pin.neutral(model))
    plug(dev.state, dyn.position)
    sot = SOT("sot", dyn)
    sot.dt.value = 0.01
    f = FeatureGeneric("featureee")
    J = np.zeros((1, model.nv))
    J[0, 0] = 1.0
    f.jacobianIN.value = J
    f.errorIN.value = np.array([-0.5])  # joint 0 moves at +0.5 rad/s under gain 1
    t = Task("taskee")
    t.add(f)
    sot.push(t)
    plug(sot.control, dev.control)
    return model, dyn, dev, sot, t, f


def _run(dev: Device, n: int) -> None:
    for _ in range(n):
        dev.increment(0.01)


def test_removing_a_task_the_sot_uses_is_refused_naming_the_users():
    _, _, dev, sot, task, feature = _arm()
    tracer = Tracer("tr")
    tracer.add(task.task, "target")
    _run(dev, 3)
    before = (pool.list(), pool.version, sot.list(), dev.control.source)
    with pytest.raises(EntityError) as err:
        pool.remove("taskee")
    msg = str(err.value)
    assert "Task(taskee)" in msg
    assert "SOT(sot)::output(vector)::control reads taskee.jacobian, taskee.task" in msg
    assert "Tracer(tr)::output(int)::trigger reads taskee.task" in msg
    assert "pool.remove('taskee', 'sot', 'tr')" in msg
    with pytest.raises(EntityError, match=r"Task\(taskee\)::output\(vector\)::error reads"):
        pool.remove(feature)
    assert (pool.list(), pool.version, sot.list(), dev.control.source) == before
    # the graph still works as before: joint 0 keeps moving at 0.5 rad/s
    q0 = dev.state.value[0]
    _run(dev, 10)
    assert dev.state.value[0] == pytest.approx(q0 + 10 * 0.01 * 0.5)


def test_after_taking_it_out_the_task_is_removed_and_a_new_one_of_that_name_works():
    model, _, dev, sot, task, _ = _arm()
    tracer = Tracer("tr")
    tracer.add(task.task, "target")
    sot.remove("taskee")
    tracer.remove("target")
    pool.remove("taskee", "featureee")  # together: the task reads the feature
    assert not pool.hasEntity("taskee") and not pool.hasEntity("featureee")
    assert sot.list() == []
    q0 = dev.state.value.copy()
    _run(dev, 20)  # no task left: the SOT commands zero velocity, the arm stays
    np.testing.assert_array_equal(dev.state.value, q0)
    # a stale reference to the removed task cannot come back into the graph
    with pytest.raises(PlugError, match=r"Task\(taskee\) was removed from the pool"):
        sot.push(task)
    assert sot.list() == []
    with pytest.raises(PlugError, match="was removed"):
        tracer.add(task.task, "again")
    with pytest.raises(PlugError, match="was removed"):
        plug(RmEntAdd("g").out, task.controlGain)
    # re-created under the same names: pushed, used, removed from the stack again
    f2 = FeatureGeneric("featureee")
    J = np.zeros((1, model.nv))
    J[0, 1] = 1.0
    f2.jacobianIN.value = J
    f2.errorIN.value = np.array([0.2])
    t2 = Task("taskee")
    assert t2 is not task
    t2.add(f2)
    sot.push("taskee")
    assert sot.list() == ["taskee"]
    np.testing.assert_allclose(sot.control.value[1], -0.2)
    sot.remove("taskee")
    assert sot.list() == []


def test_a_plain_output_reading_a_removed_signal_is_never_left_stale():
    c1 = RmEntAdd("c1")
    c1.a.value = 1.0
    c2 = RmEntSum("c2")
    c2.out.setDependencies([c1.out])
    assert c2.out.value == 2.0
    with pytest.raises(EntityError, match=r"RmEntSum\(c2\)::output\(double\)::out reads c1.out"):
        pool.remove("c1")
    c1.a.value = 5.0  # still connected: the value follows
    assert c2.out.value == 6.0
    c2.out.setDependencies([])
    pool.remove("c1")
    assert c2.out.value == 0.0


def test_an_input_plugged_to_a_removed_output_is_refused_then_removed_together():
    a = RmEntAdd("a")
    a.a.value = 1.0
    b = RmEntAdd("b")
    plug(a.out, b.a)
    with pytest.raises(EntityError, match=r"RmEntAdd\(b\)::input\(double\)::a plugged to a.out"):
        pool.remove("a")
    assert b.a.source is a.out and b.out.value == 3.0
    pool.remove("a", "b")
    assert pool.list() == []


def test_periodic_calls_and_loops_count_as_users():
    model = pin.buildSampleModelManipulator()
    dev = Device("dev", model)
    dev.control.value = np.zeros(model.nv)
    tracer = Tracer("tr")
    tracer.add(dev.state, "q")
    dev.after.addSignal(tracer.trigger)
    with pytest.raises(EntityError, match=r"Device\(dev\)\.after refreshes tr.trigger"):
        pool.remove("tr")
    dev.after.rmSignal(tracer.trigger)
    pool.remove("tr")
    loop = ControlLoop("loop", dev, 0.01)
    with pytest.raises(EntityError, match=r"ControlLoop\(loop\) uses Device\(dev\)"):
        pool.remove(dev)
    loop.step(2)
    assert loop.fault is None
    pool.remove("loop", "dev")
    assert pool.list() == []


def test_a_group_removal_is_all_or_nothing():
    a = RmEntAdd("a")
    RmEntAdd("b")
    with pytest.raises(EntityError, match="unknown entity 'nope'"):
        pool.remove("a", "nope")
    assert pool.list() == ["a", "b"]
    with pytest.raises(EntityError, match="at least one"):
        pool.remove()
    pool.remove(a)
    with pytest.raises(EntityError, match="unknown entity 'a'"):
        pool.remove(a)
    a2 = RmEntAdd("a")
    with pytest.raises(EntityError, match="not the entity the pool holds"):
        pool.remove(a)
    assert pool.getEntity("a") is a2


def test_an_sot_removed_with_its_device_plug_refused_until_unplugged():
    model, dyn, dev, sot, task, _ = _arm()
    with pytest.raises(EntityError, match=r"Device\(dev\)::input\(vector\)::control plugged to"):
        pool.remove("sot")
    dev.control.value = np.zeros(model.nv)
    pool.remove("sot")
    assert sot._removed and not pool.hasEntity("sot")
    # the task it read stays, usable by a new solver
    sot2 = SOT("sot", dyn)
    sot2.dt.value = 0.01
    sot2.push(task)
    np.testing.assert_allclose(sot2.control.value[0], 0.5)


def test_a_meta_task_that_fails_half_built_removes_what_it_created(monkeypatch):
    import sotpy.tasks.meta_task as meta_task
    from sotpy.tasks import MetaTaskKine6d

    model = pin.buildSampleModelManipulator()
    dyn = Dynamic("dyn", model)
    before = pool.list()
    real_plug = meta_task.plug

    def plug_failing_on_the_gain(source, target):
        if target.shortName == "controlGain":  # the last step: the others are wired
            raise RuntimeError("injected")
        real_plug(source, target)

    monkeypatch.setattr(meta_task, "plug", plug_failing_on_the_gain)
    with pytest.raises(RuntimeError, match="injected"):
        MetaTaskKine6d("ee", dyn, "ee", "effector_body")
    assert pool.list() == before  # feature, task and gain removed together
    assert not dyn.hasSignal("ee")


def test_the_compat_meta_task_that_fails_half_built_removes_what_it_created(monkeypatch):
    from sotpy.compat._meta import MetaTaskKine6d
    from sotpy.tasks import FeaturePoint6d

    model = pin.buildSampleModelManipulator()
    dyn = Dynamic("dyn", model)
    before = pool.list()

    def failing_frame(self, which):
        raise RuntimeError("injected")

    monkeypatch.setattr(FeaturePoint6d, "frame", failing_frame)  # after setReference
    with pytest.raises(RuntimeError, match="injected"):
        MetaTaskKine6d("ee", dyn, "ee", "effector_body")
    assert pool.list() == before  # the feature, its reference, the task... together


class RmFakePublish(Entity):
    """Stands for ZenohPublish (zenoh is optional): inputs added by add(), a trigger."""

    def add(self, type, name, key, size=None):
        from sotpy.graph.signal import InputSignal
        from sotpy.graph.types import type_named

        self.addSignal(InputSignal(self, name, type_named(type)))

    @Output(DOUBLE, timeDependent=True)
    def trigger(self):
        return 0.0


class RmFakeSubscribe(Entity):
    """Stands for ZenohSubscribe: outputs added by add()."""

    def add(self, type, name, key, size=None):
        from sotpy.graph.signal import OutputSignal
        from sotpy.graph.types import type_named

        out = OutputSignal(self, name, type_named(type))
        out.setConstant(np.zeros(size or 6))
        self.addSignal(out)


def test_the_zenoh_bridge_takes_its_entities_out_before_removing_them(monkeypatch):
    import sotpy.bridge.entities as entities
    from sotpy.bridge.serve import ServeBridge
    from sotpy.errors import BridgeError

    monkeypatch.setattr(entities, "ZenohPublish", lambda name, session: RmFakePublish(name))
    monkeypatch.setattr(entities, "ZenohSubscribe", lambda name, session: RmFakeSubscribe(name))
    model = pin.buildSampleModelManipulator()
    dev = Device("dev", model)
    cfg = {
        "wait": 0.0,
        "session": None,
        "path": "bridge.toml",
        "publish": [{"signal": "dev.state", "key": "k/state"}],
        "subscribe": [{"signal": "dev.control", "key": "k/control", "size": model.nv}],
    }
    before = pool.list()
    bridge = ServeBridge(cfg, dev)
    assert dev.control.source is not None and dev.after.list()
    bridge.close()  # the device's after list and control plug let go first
    assert pool.list() == before and dev.after.list() == [] and dev.control.source is None
    # a file refused half way leaves the pool as it was (the BridgeError, not a refusal)
    cfg["publish"] = [
        {"signal": "dev.state", "key": "a", "call": "after"},
        {"signal": "dev.velocity", "key": "b", "call": "before"},
    ]
    with pytest.raises(BridgeError, match="the same call and period"):
        ServeBridge(cfg, dev)
    assert pool.list() == before
