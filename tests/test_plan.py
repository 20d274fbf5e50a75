"""Compiled plans, periodic calls and one-tick delays (``sotpy.graph.plan`` and
``sotpy.graph.delay``): a plan gives the values lazy reads give, follows topology
changes, computes each signal at most once per tick, leaves constant subgraphs alone,
scales to long chains and reports every unplugged input; a delay closes a loop."""

from __future__ import annotations

import random
from collections import Counter

import numpy as np
import pytest

from sotpy.errors import CycleError, PlugError, SotpyError, UnpluggedError
from sotpy.graph import (
    DOUBLE,
    VECTOR,
    Delay_of_double,
    Delay_of_vector,
    Entity,
    Input,
    Output,
    PeriodicCall,
    Plan,
    compilePlan,
    plug,
    pool,
)


# -- test entities --------------------------------------------------------------------------
class PlanNode(Entity):
    """out = a + 2 b; records the tick of each call."""

    a = Input(DOUBLE)
    b = Input(DOUBLE)

    def __init__(self, name: str) -> None:
        self.ticks: list[int] = []

    @Output(DOUBLE, deps=("a", "b"))
    def out(self, a, b):
        self.ticks.append(pool.time)
        return a + 2.0 * b


class PlanClock(Entity):
    """out(t) = t (time-dependent)."""

    def __init__(self, name: str) -> None:
        self.ticks: list[int] = []

    @Output(DOUBLE, withTime=True, timeDependent=True)
    def out(self, t):
        self.ticks.append(t)
        return float(t)


class PlanSlow(Entity):
    """out(t) = t, recomputed every 3 ticks."""

    @Output(DOUBLE, withTime=True, timeDependent=True, period=3)
    def out(self, t):
        return float(t)


class PlanState(Entity):
    """A state signal written by ``write(v, t)``."""

    state = Output(DOUBLE, initial=0.0)


class PlanVecAdd(Entity):
    """out = a + b on vectors."""

    a = Input(VECTOR)
    b = Input(VECTOR)

    @Output(VECTOR, deps=("a", "b"))
    def out(self, a, b):
        return a + b


class PlanDoubleAdd(Entity):
    """out = a + b on doubles."""

    a = Input(DOUBLE)
    b = Input(DOUBLE)

    @Output(DOUBLE, deps=("a", "b"))
    def out(self, a, b):
        return a + b


class PlanInc(Entity):
    """out = a + 1."""

    a = Input(DOUBLE, default=0.0)

    @Output(DOUBLE, deps=("a",))
    def out(self, a):
        return a + 1.0


# -- a random layered DAG, built twice, and its independent evaluation ----------------------
class Dag:
    """Structure: node i reads two sources, each ("const", value), ("node", j) with j in an
    earlier layer, ("clock",) or ("state",)."""

    def __init__(self, rng: random.Random, layers: int, width: int) -> None:
        self.sources: list[list[tuple]] = []
        previous: list[int] = []
        for layer in range(layers):
            current = []
            for _ in range(rng.randint(1, width)):
                pair = []
                for _ in range(2):
                    r = rng.random()
                    if previous and r < 0.6:
                        pair.append(("node", rng.choice(previous)))
                    elif (layer == 0 and r < 0.2) or r < 0.1:
                        pair.append((rng.choice(["clock", "state"]),))
                    else:
                        pair.append(("const", float(rng.randint(-5, 5))))
                self.sources.append(pair)
                current.append(len(self.sources) - 1)
            previous = previous + current if rng.random() < 0.3 else current
        self.sinks = previous

    def build(self, prefix: str) -> tuple[list[PlanNode], PlanClock, PlanState]:
        clock = PlanClock(prefix + "clock")
        state = PlanState(prefix + "state")
        nodes = [PlanNode(f"{prefix}n{i}") for i in range(len(self.sources))]
        for node, pair in zip(nodes, self.sources, strict=True):
            for inp, src in zip((node.a, node.b), pair, strict=True):
                if src[0] == "const":
                    inp.value = src[1]
                elif src[0] == "node":
                    plug(nodes[src[1]].out, inp)
                elif src[0] == "clock":
                    plug(clock.out, inp)
                else:
                    plug(state.state, inp)
        return nodes, clock, state

    def evaluate(self, consts: dict[tuple[int, int], float], t: int, s: float) -> list[float]:
        values: list[float] = []
        for i, pair in enumerate(self.sources):
            v = []
            for k, src in enumerate(pair):
                if src[0] == "const":
                    v.append(consts[(i, k)])
                elif src[0] == "node":
                    v.append(values[src[1]])
                elif src[0] == "clock":
                    v.append(float(t))
                else:
                    v.append(s)
            values.append(v[0] + 2.0 * v[1])
        return values

    def live(self) -> list[bool]:
        out: list[bool] = []
        for pair in self.sources:
            out.append(
                any(
                    src[0] in ("clock", "state") or (src[0] == "node" and out[src[1]])
                    for src in pair
                )
            )
        return out

    def dirty(self, changed: set[tuple[int, int]]) -> list[bool]:
        """Nodes downstream of a changed constant or of the clock/state."""
        live = self.live()
        out: list[bool] = []
        for i, pair in enumerate(self.sources):
            out.append(
                live[i]
                or any((i, k) in changed for k in range(2))
                or any(src[0] == "node" and out[src[1]] for src in pair)
            )
        return out


@pytest.mark.parametrize("seed", range(16))
def test_plan_gives_the_values_of_lazy_reads_on_a_random_dag(seed):
    rng = random.Random(seed)
    dag = Dag(rng, layers=rng.randint(2, 6), width=5)
    plan_nodes, _, plan_state = dag.build("p_")
    lazy_nodes, _, lazy_state = dag.build("l_")
    consts = {
        (i, k): src[1]
        for i, pair in enumerate(dag.sources)
        for k, src in enumerate(pair)
        if src[0] == "const"
    }
    const_keys = sorted(consts)
    extra = rng.sample(range(len(plan_nodes)), k=min(2, len(plan_nodes)))
    sinks = sorted(set(dag.sinks) | set(extra))
    plan = compilePlan([plan_nodes[i].out for i in sinks])
    assert len(plan.steps) <= len(plan_nodes) + 1  # nodes and the clock
    for t in range(12):
        if rng.random() < 0.5:
            pool.advance(t)
        changed: set[tuple[int, int]] = set()
        if t and const_keys:
            for key in rng.sample(const_keys, k=rng.randint(0, min(3, len(const_keys)))):
                consts[key] = float(rng.randint(-9, 9))
                changed.add(key)
                i, k = key
                for nodes in (plan_nodes, lazy_nodes):
                    (nodes[i].a, nodes[i].b)[k].value = consts[key]
        s = float(rng.randint(-9, 9))
        plan_state.state.write(s, t)
        lazy_state.state.write(s, t)
        expected = dag.evaluate(consts, t, s)
        # mix lazy reads into the planned graph, before and after the plan
        for i in rng.sample(range(len(plan_nodes)), k=rng.randint(0, 2)):
            assert plan_nodes[i].out(t) == expected[i]
        plan.run(t)
        assert pool.time == t
        for i in sinks:
            assert plan_nodes[i].out._value == expected[i], (t, i)
        for i in rng.sample(range(len(plan_nodes)), k=rng.randint(0, 2)):
            assert plan_nodes[i].out(t) == expected[i]
        plan.run(t)  # a second run at the same tick computes nothing
        # the lazy graph
        for i in sinks:
            assert lazy_nodes[i].out(t) == expected[i], (t, i)
        # every node, both graphs (lazy reads for the nodes no plan covers)
        for i in range(len(plan_nodes)):
            assert plan_nodes[i].out.value == expected[i]
            assert lazy_nodes[i].out.value == expected[i]
        # each callback ran once if something it reads changed, else not at all
        dirty = dag.dirty(changed)
        for i in range(len(plan_nodes)):
            want = 1 if (t == 0 or dirty[i]) else 0
            assert plan_nodes[i].ticks.count(t) == want, ("plan", t, i)
            assert lazy_nodes[i].ticks.count(t) == want, ("lazy", t, i)


@pytest.mark.parametrize("seed", range(10))
def test_plan_matches_lazy_reads_with_periods(seed):
    """Outputs recomputed every 1, 2 or 3 ticks: the plan and the lazy pull agree at
    every tick, whatever the constants do."""
    rng = random.Random(500 + seed)
    dag = Dag(rng, layers=rng.randint(2, 5), width=4)
    plan_nodes, _, plan_state = dag.build("p_")
    lazy_nodes, _, lazy_state = dag.build("l_")
    for i in range(len(plan_nodes)):
        k = rng.choice([1, 1, 2, 3])
        plan_nodes[i].out.setPeriod(k)
        lazy_nodes[i].out.setPeriod(k)
    const_keys = [
        (i, k)
        for i, pair in enumerate(dag.sources)
        for k, src in enumerate(pair)
        if src[0] == "const"
    ]
    plan = compilePlan([plan_nodes[i].out for i in dag.sinks])
    for t in range(14):
        # both graphs must see the same clock: a state written at the current tick
        # invalidates its readers at once, one written at a later tick does not, and
        # with periods the stamps (not only the values) decide later recomputations
        pool.advance(t)
        for i, k in rng.sample(const_keys, k=min(len(const_keys), rng.randint(0, 2))):
            v = float(rng.randint(-9, 9))
            for nodes in (plan_nodes, lazy_nodes):
                (nodes[i].a, nodes[i].b)[k].value = v
        s = float(rng.randint(-9, 9))
        plan_state.state.write(s, t)
        lazy_state.state.write(s, t)
        plan.run(t)
        for i in dag.sinks:
            assert plan_nodes[i].out._value == lazy_nodes[i].out(t), (t, i)
        for i in range(len(plan_nodes)):
            assert plan_nodes[i].out.value == lazy_nodes[i].out.value, (t, i)
            assert plan_nodes[i].ticks.count(t) <= 1
            assert lazy_nodes[i].ticks.count(t) <= 1


class PlanCopy(Entity):
    """y = x."""

    x = Input(DOUBLE)

    @Output(DOUBLE, deps=("x",))
    def y(self, x):
        return x


def test_plan_live_step_between_periodic_signals():
    # clock -> a (every 3 ticks) -> b (every tick) -> c (every 2 ticks), twice
    def build(prefix):
        clock = PlanClock(prefix + "clock")
        a, b, c = (PlanCopy(prefix + n) for n in "abc")
        plug(clock.out, a.x)
        plug(a.y, b.x)
        plug(b.y, c.x)
        a.y.setPeriod(3)
        c.y.setPeriod(2)
        return c

    planned, lazy = build("p"), build("l")
    plan = compilePlan([planned.y])
    got = []
    for t in range(7):
        plan.run(t)
        got.append((planned.y._value, lazy.y(t)))
    # lazy: b changes at 0, 3, 6 only, so c takes 3 at tick 3 and 6 at tick 6
    assert [g[1] for g in got] == [0.0, 0.0, 0.0, 3.0, 3.0, 3.0, 6.0]
    assert [g[0] for g in got] == [g[1] for g in got]


class PlanNodeD(Entity):
    """out = a + 2 b, inputs defaulting to 0."""

    a = Input(DOUBLE, default=0.0)
    b = Input(DOUBLE, default=0.0)

    @Output(DOUBLE, deps=("a", "b"))
    def out(self, a, b):
        return a + 2.0 * b


class _Model:
    """The expected values of a graph of PlanNodeD under edits, in plain Python."""

    def __init__(self, n: int) -> None:
        self.inputs = {(i, k): ("const", 0.0) for i in range(n) for k in range(2)}
        self.override: dict[int, float] = {}
        self.n = n

    def source_value(self, src: tuple, out: list[float], t: int, s: float) -> float:
        if src[0] == "const":
            return src[1]
        if src[0] == "node":
            return out[src[1]]
        return float(t) if src[0] == "clock" else s

    def values(self, t: int, s: float) -> list[float]:
        out: list[float] = []
        for i in range(self.n):
            if i in self.override:
                out.append(self.override[i])
                continue
            a, b = (self.source_value(self.inputs[(i, k)], out, t, s) for k in range(2))
            out.append(a + 2.0 * b)
        return out


@pytest.mark.parametrize("seed", range(12))
def test_plan_and_lazy_reads_follow_random_edits(seed):
    """Random plugs, replugs, unplugs, constants on inputs and outputs and callback
    resets, at random points of each tick (before or after reads at the same tick)."""
    rng = random.Random(1000 + seed)
    n = rng.randint(3, 9)
    model = _Model(n)
    graphs = []
    for prefix in ("p", "l"):
        nodes = [PlanNodeD(f"{prefix}{i}") for i in range(n)]
        graphs.append((nodes, PlanClock(prefix + "clock"), PlanState(prefix + "state")))
    sinks = sorted(rng.sample(range(n), k=rng.randint(1, n)))
    plan = Plan([graphs[0][0][i].out for i in sinks])

    def edit():
        op = rng.choice(["const", "plug", "plug", "unplug", "out_const", "reset"])
        i, k = rng.randrange(n), rng.randrange(2)
        v = float(rng.randint(-5, 5))
        choice = rng.randrange(i + 2)  # an earlier node, the clock or the state
        for nodes, clock, state in graphs:
            inp = (nodes[i].a, nodes[i].b)[k]
            if op == "const":
                inp.value = v
            elif op == "plug" and choice < i:
                plug(nodes[choice].out, inp)
            elif op == "plug" and choice == i:
                plug(clock.out, inp)
            elif op == "plug":
                plug(state.state, inp)
            elif op == "unplug":
                inp.unplug()
            elif op == "out_const":
                nodes[i].out.value = v
            else:
                nodes[i].out.resetCallback()
        if op == "const":
            model.inputs[(i, k)] = ("const", v)
        elif op == "plug":
            model.inputs[(i, k)] = (
                ("node", choice) if choice < i else ("clock",) if choice == i else ("state",)
            )
        elif op == "unplug":
            model.inputs[(i, k)] = ("const", 0.0)
        elif op == "out_const":
            model.override[i] = v
        else:
            model.override.pop(i, None)

    for t in range(15):
        if rng.random() < 0.5:
            pool.advance(t)
        s = float(t * t)
        for _, _, state in graphs:
            state.state.write(s, t)
        for _ in range(rng.randint(0, 2)):
            edit()
        for phase in range(2):
            expected = model.values(t, s)
            plan.run(t)
            for i in sinks:
                assert graphs[0][0][i].out._value == expected[i], (t, phase, i)
            for i in rng.sample(range(n), k=rng.randint(1, n)):
                assert graphs[1][0][i].out(t) == expected[i], (t, phase, i)
                assert graphs[0][0][i].out.value == expected[i], (t, phase, i)
                k = rng.randrange(2)
                want = model.source_value(model.inputs[(i, k)], expected, t, s)
                for nodes, _, _ in graphs:
                    assert (nodes[i].a, nodes[i].b)[k].value == want, (t, phase, i, k)
            if phase == 0:
                for _ in range(rng.randint(0, 2)):
                    edit()  # same-tick edits after the reads


def _chain3():
    """x -> y -> z with constants; z.out = ((xa + 2 xb) + 2 yb) + 2 zb."""
    x, y, z = PlanNode("x"), PlanNode("y"), PlanNode("z")
    x.a.value = 1
    x.b.value = 1
    plug(x.out, y.a)
    y.b.value = 1
    plug(y.out, z.a)
    z.b.value = 1
    return x, y, z


def test_plan_recompiles_after_a_plug_change():
    x, y, z = _chain3()
    other = PlanNode("other")
    other.a.value = 100
    other.b.value = 0
    plan = Plan([z.out])
    plan.run(0)
    assert z.out._value == 7.0
    assert [s.path for s in plan.steps] == ["x.out", "y.out", "z.out"]
    plug(other.out, y.a)  # same tick
    plan.run(0)
    assert z.out._value == 104.0
    assert [s.path for s in plan.steps] == ["other.out", "y.out", "z.out"]
    plan.run(1)
    assert z.out._value == 104.0
    y.a.value = -2  # a constant unplugs: other drops out of the plan
    plan.run(1)
    assert z.out._value == 2.0
    assert [s.path for s in plan.steps] == ["y.out", "z.out"]
    x.out.value = 5  # an output set to a constant is not a step any more
    plug(x.out, y.a)
    plan.run(2)
    assert z.out._value == 9.0
    assert [s.path for s in plan.steps] == ["y.out", "z.out"]
    x.out.resetCallback()
    plan.run(3)
    assert z.out._value == 7.0
    assert [s.path for s in plan.steps] == ["x.out", "y.out", "z.out"]


def test_plan_follows_a_same_tick_constant_change():
    x, y, z = _chain3()
    plan = compilePlan([z.out])
    plan.run(0)
    assert z.out._value == 7.0
    x.a.value = 11  # same tick
    plan.run(0)
    assert z.out._value == 17.0
    assert z.out.value == 17.0
    assert (x.ticks, y.ticks, z.ticks) == ([0, 0], [0, 0], [0, 0])


def test_callbacks_run_once_per_tick_when_plan_and_lazy_reads_mix():
    clock = PlanClock("clock")
    n1, n2 = PlanNode("n1"), PlanNode("n2")
    plug(clock.out, n1.a)
    n1.b.value = 0
    plug(n1.out, n2.a)
    n2.b.value = 1
    plan = compilePlan([n2.out])
    for t in range(6):
        if t % 2:
            assert n1.out(t) == t  # lazy first
            plan.run(t)
        else:
            plan.run(t)
            assert n1.out(t) == t
        assert n2.out.value == t + 2.0
        plan.run(t)
        assert n2.out(t) == t + 2.0
    assert Counter(clock.ticks) == Counter(range(6))
    assert Counter(n1.ticks) == Counter(range(6))
    assert Counter(n2.ticks) == Counter(range(6))


def test_static_steps_are_not_recomputed_unless_a_constant_changes():
    x, y, z = _chain3()
    clock = PlanClock("clock")
    live = PlanNode("live")
    plug(z.out, live.a)
    plug(clock.out, live.b)
    plan = compilePlan([live.out])
    for t in range(10):
        if t == 5:
            pool.advance(5)
            y.b.value = 2  # changes y and z, not x
        plan.run(t)
        assert live.out._value == (9.0 if t >= 5 else 7.0) + 2.0 * t
    assert x.ticks == [0]
    assert y.ticks == [0, 5]
    assert z.ticks == [0, 5]
    assert live.ticks == list(range(10))


def test_plan_over_a_10000_signal_chain():
    n = 5_000  # 5,000 inputs and 5,000 outputs
    es = [PlanInc(f"c{k}") for k in range(n)]
    for k in range(n - 1, 0, -1):
        plug(es[k - 1].out, es[k].a)
    clock = PlanClock("clock")
    plug(clock.out, es[0].a)
    plan = compilePlan([es[-1].out])
    assert len(plan.steps) == n + 1
    for t in range(3):
        plan.run(t)
        assert es[-1].out._value == t + n
    # a static chain too
    es[0].a.value = 0.5
    plan.run(3)
    assert es[-1].out._value == 0.5 + n
    assert es[-1].out.value == 0.5 + n


def test_compiling_with_unplugged_inputs_lists_all_of_them():
    x, y, z = PlanNode("x"), PlanNode("y"), PlanNode("z")
    plug(x.out, y.a)
    plug(y.out, z.a)
    z.b.value = 0
    w = PlanNode("w")  # a second sink with its own unplugged input
    w.a.value = 0
    expected = {
        "PlanNode(x)::input(double)::a",
        "PlanNode(x)::input(double)::b",
        "PlanNode(y)::input(double)::b",
        "PlanNode(w)::input(double)::b",
    }
    with pytest.raises(UnpluggedError) as info:
        compilePlan([z.out, w.out])
    assert set(info.value.signals) == expected
    assert len(info.value.signals) == len(expected)
    for name in expected:
        assert name in str(info.value)
    plan = Plan([z.out])
    with pytest.raises(UnpluggedError) as info:
        plan.run(0)
    assert set(info.value.signals) == expected - {"PlanNode(w)::input(double)::b"}
    assert x.ticks == y.ticks == z.ticks == []
    x.a.value = x.b.value = y.b.value = 1
    plan.run(0)
    assert z.out._value == 5.0


def test_plan_refuses_non_signals():
    with pytest.raises(PlugError):
        Plan(["x.out"])


def test_plan_with_a_period_gives_the_lazy_values():
    slow_p, slow_l = PlanSlow("sp"), PlanSlow("sl")
    np_, nl = PlanNode("np"), PlanNode("nl")
    for slow, node in ((slow_p, np_), (slow_l, nl)):
        plug(slow.out, node.a)
        node.b.value = 0.5
    plan = compilePlan([np_.out])
    for t in range(10):
        plan.run(t)
        assert np_.out._value == nl.out(t) == 3 * (t // 3) + 1.0


def test_plan_with_a_state_signal():
    st = PlanState("st")
    n = PlanNode("n")
    plug(st.state, n.a)
    n.b.value = 1
    plan = compilePlan([n.out])
    for t in range(1, 6):
        st.state.write(10.0 * t, t)
        plan.run(t)
        assert n.out._value == 10.0 * t + 2.0
    assert n.ticks == [1, 2, 3, 4, 5]


# -- periodic calls -------------------------------------------------------------------------
def test_periodic_call_refreshes_every_k_ticks():
    c1, c3 = PlanClock("c1"), PlanClock("c3")
    pc = PeriodicCall("dev.after")
    assert not pc
    pc.addSignal(c1.out)
    pc.addSignal("c3.out", 3)
    assert pc
    assert sorted(pc.list()) == ["c1.out (every 1)", "c3.out (every 3)"]
    for t in range(10):
        pool.advance(t)
        pc.run(t)
    assert c1.ticks == list(range(10))
    assert c3.ticks == [0, 3, 6, 9]
    pc.rmSignal("c3.out")
    pc.run(12)
    assert c3.ticks == [0, 3, 6, 9]
    assert c1.ticks[-1] == 12
    with pytest.raises(PlugError, match=r"PlanClock\(c3\)::output\(double\)::out"):
        pc.rmSignal(c3.out)
    pc.addDownsampledSignal(c3.out, 2)
    pc.run(14)
    assert c3.ticks[-1] == 14
    pc.clear()
    assert not pc


@pytest.mark.parametrize("bad", [0, -2, 1.5, True])
def test_periodic_call_refuses_bad_periods(bad):
    c = PlanClock("c")
    pc = PeriodicCall("p")
    with pytest.raises(PlugError, match="period"):
        pc.addSignal(c.out, bad)
    assert not pc


# -- delays -----------------------------------------------------------------------------------
def _vector_accumulator(u=(1.0, 2.0), x0=(0.5, -1.0)):
    d = Delay_of_vector("d")
    acc = PlanVecAdd("acc")
    d.setInitialValue(list(x0))
    plug(d.sout, acc.a)
    acc.b.value = list(u)
    plug(acc.out, d.sin)  # closes the loop through the delay
    return d, acc


def test_delay_of_vector_closes_a_feedback_loop():
    d, acc = _vector_accumulator()
    u, x0 = np.array([1.0, 2.0]), np.array([0.5, -1.0])
    for t in range(6):
        np.testing.assert_array_equal(acc.out(t), x0 + (t + 1) * u)
        np.testing.assert_array_equal(d.sout.value, x0 + t * u)
    acc.b.value = [0.0, 0.0]  # same tick 5: x(5) = x(4)
    np.testing.assert_array_equal(acc.out.value, x0 + 5 * u)
    np.testing.assert_array_equal(acc.out(6), x0 + 5 * u)


def test_delay_loop_in_a_plan():
    _, acc = _vector_accumulator(u=(1.0,), x0=(0.0,))
    plan = compilePlan([acc.out])
    seq = []
    for t in range(5):
        plan.run(t)
        seq.append(float(acc.out._value[0]))
    assert seq == [1.0, 2.0, 3.0, 4.0, 5.0]


def test_delay_of_double_accumulator_and_cycle_without_delay():
    d = Delay_of_double("dd")
    acc = PlanDoubleAdd("dacc")
    plug(d.sout, acc.a)
    acc.b.value = 2.0
    plug(acc.out, d.sin)
    assert [acc.out(t) for t in range(4)] == [2.0, 4.0, 6.0, 8.0]  # initial value 0.0
    other = PlanDoubleAdd("other")
    other.b.value = 1.0
    plug(acc.out, other.a)
    with pytest.raises(CycleError) as info:
        plug(other.out, acc.a)  # the same loop without the delay
    assert info.value.cycle[0] == info.value.cycle[-1]
    assert "PlanDoubleAdd(dacc)::input(double)::a" in info.value.cycle
    assert acc.a.source is d.sout
    assert acc.out(4) == 10.0


def test_plugging_the_loop_without_a_delay_is_refused():
    acc = PlanVecAdd("acc")
    acc.b.value = [1.0]
    with pytest.raises(CycleError, match=r"PlanVecAdd\(acc\)::output\(vector\)::out"):
        plug(acc.out, acc.a)
    assert acc.a.source is None


def test_delay_refuses_a_value_from_the_wrong_tick():
    clock = PlanClock("clock")
    d = Delay_of_double("dd")
    plug(clock.out, d.sin)
    assert d.sout(1) == 0.0  # sin(0)
    assert clock.out(5) == 5.0  # sin computed at 5 first: its value at 4 is gone
    with pytest.raises(SotpyError, match=r"Delay_of_double\(dd\)::output\(double\)::sout"):
        d.sout(5)


def test_delay_loop_read_after_a_long_gap():
    _, acc = _vector_accumulator(u=(1.0,), x0=(0.0,))
    np.testing.assert_array_equal(acc.out(0), [1.0])
    np.testing.assert_array_equal(acc.out(2_000), [2_001.0])


def test_a_plan_whose_sinks_are_up_to_date_computes_nothing_as_a_read_would():
    # clock (live) -> s (every 3 ticks): at ticks 1 and 2 reading s computes nothing, not
    # even the live clock; a plan over s does the same, and a second plan over a sink the
    # first one brought up to date does not walk its steps again
    def build(prefix):
        clock = PlanClock(prefix + "clock")
        s = PlanCopy(prefix + "s")
        plug(clock.out, s.x)
        s.y.setPeriod(3)
        return clock, s

    (pc, ps), (lc, ls) = build("p"), build("l")
    plan = compilePlan([ps.y])
    for t in range(7):
        plan.run(t)
        assert ps.y._value == ls.y(t)
    assert pc.ticks == lc.ticks == [0, 3, 6]
    first, second = compilePlan([ps.y]), compilePlan([ps.y])
    calls = Counter()
    seg = second._segments[0][0]
    second._segments = [
        (lambda items, t: calls.update([t]) or seg(items, t), second._segments[0][1])
    ]
    for t in (9, 10, 11, 12):
        first.run(t)
        second.run(t)
    assert calls == Counter()  # the first plan brought the sink up to date at every tick
    second.run(15)
    assert calls == Counter({15: 1})
