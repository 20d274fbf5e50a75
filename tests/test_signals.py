"""Signals: names, lazy evaluation at the pool's tick, the outdated rule, constants,
type conversion, unplugged inputs, plugs (refusals leave the graph unchanged) and
deep chains. Each test asserts behaviour documented in ``sotpy.graph.signal``, in
docs/graph.md or in docs/architecture.md ("One tick")."""

from __future__ import annotations

import itertools
import sys
from collections import Counter

import numpy as np
import pytest

from sotpy.errors import (
    CycleError,
    PlugError,
    SignalTypeError,
    SotpyError,
    UnpluggedError,
)
from sotpy.graph import (
    ANY,
    DOUBLE,
    MATRIX,
    STRING,
    VECTOR,
    Entity,
    Input,
    Output,
    OutputSignal,
    checkPlugged,
    compilePlan,
    plug,
    pool,
)


# -- test entities ------------------------------------------------------------------------
class SigAdd(Entity):
    """out = a + b, counting callback calls."""

    a = Input(DOUBLE, doc="first term")
    b = Input(DOUBLE, doc="second term")

    def __init__(self, name: str) -> None:
        self.calls = 0

    @Output(DOUBLE, deps=("a", "b"))
    def out(self, a, b):
        self.calls += 1
        return a + b


class SigInc(Entity):
    """out = a + 1 (for chains)."""

    a = Input(DOUBLE, default=0.0)

    def __init__(self, name: str) -> None:
        self.calls = 0

    @Output(DOUBLE, deps=("a",))
    def out(self, a):
        self.calls += 1
        return a + 1.0


class SigScale(Entity):
    """out = k * v."""

    v = Input(VECTOR)
    k = Input(DOUBLE, default=2.0)
    m = Input(MATRIX)

    def __init__(self, name: str) -> None:
        self.calls = 0

    @Output(VECTOR, deps=("v", "k"))
    def out(self, v, k):
        self.calls += 1
        return k * v


class SigClock(Entity):
    """A time-dependent counter: ``count(t) = t``; ``slow`` has period 3."""

    def __init__(self, name: str) -> None:
        self.calls = Counter()

    @Output(DOUBLE, withTime=True, timeDependent=True)
    def count(self, t):
        self.calls["count"] += 1
        return float(t)

    @Output(DOUBLE, withTime=True, timeDependent=True, period=3)
    def slow(self, t):
        self.calls["slow"] += 1
        return float(t)


class SigState(Entity):
    """A state signal its entity writes with ``write(v, t)``."""

    state = Output(DOUBLE, initial=0.0, doc="state written by the entity")


class SigAny(Entity):
    """An input of type any."""

    x = Input(ANY)

    @Output(ANY, deps=("x",))
    def y(self, x):
        return x


class SigText(Entity):
    s = Input(STRING, default="hello")


class SigFlaky(Entity):
    """A callback that raises while ``fail`` is set."""

    a = Input(DOUBLE, default=1.0)

    def __init__(self, name: str) -> None:
        self.fail = False
        self.calls = 0

    @Output(DOUBLE, deps=("a",))
    def out(self, a):
        self.calls += 1
        if self.fail:
            raise RuntimeError("callback failed")
        return 10 * a


def _adder(name: str, a: float | None = None, b: float | None = None) -> SigAdd:
    e = SigAdd(name)
    if a is not None:
        e.a.value = a
    if b is not None:
        e.b.value = b
    return e


# -- names ---------------------------------------------------------------------------------
def test_full_names_follow_sot_spelling():
    s = SigScale("sc")
    assert s.v.name == "SigScale(sc)::input(vector)::v"
    assert s.k.name == "SigScale(sc)::input(double)::k"
    assert s.m.name == "SigScale(sc)::input(matrix)::m"
    assert s.out.name == "SigScale(sc)::output(vector)::out"
    assert s.out.shortName == "out"
    assert s.out.path == "sc.out"
    assert s.v.entity is s


# -- lazy reads, clock ------------------------------------------------------------------------
def test_value_reads_at_pool_time_and_recomputes_when_outdated():
    e = _adder("e", 1, 2)
    assert e.out.value == 3.0
    assert e.out.time == 0
    pool.advance(4)
    e.a.value = 10
    assert e.out.value == 12.0
    assert e.out.time == 4
    assert e.calls == 2


def test_call_and_recompute_advance_the_clock():
    c = SigClock("c")
    assert pool.time == 0
    assert c.count(5) == 5.0
    assert pool.time == 5
    assert c.count.recompute(7) == 7.0
    assert pool.time == 7
    # .value reads at the clock's tick
    assert c.count.value == 7.0
    # reading at an earlier tick does not move the clock backwards
    c.count(3)
    assert pool.time == 7
    pool.advance(2)
    assert pool.time == 7


def test_value_is_computed_at_most_once_per_tick_in_a_diamond():
    # src feeds left and right, which both feed top: src must be computed once
    src = _adder("src", 1, 2)
    left, right, top = SigAdd("left"), SigAdd("right"), SigAdd("top")
    plug(src.out, left.a)
    left.b.value = 10
    plug(src.out, right.a)
    right.b.value = 100
    plug(left.out, top.a)
    plug(right.out, top.b)
    assert top.out.value == 116.0
    for e in (left.out, right.out, top.out, src.out):
        e.value  # noqa: B018 - re-reading at the same tick
        e(0)
    assert (src.calls, left.calls, right.calls, top.calls) == (1, 1, 1, 1)
    pool.advance(1)
    src.a.value = 2
    assert top.out.value == 118.0
    assert (src.calls, left.calls, right.calls, top.calls) == (2, 2, 2, 2)


def test_output_of_constants_is_not_recomputed_at_later_ticks():
    e = _adder("e", 1, 2)
    f = SigAdd("f")
    plug(e.out, f.a)
    f.b.value = 4
    for t in range(10):
        assert f.out(t) == 7.0
        assert e.out(t) == 3.0
    assert (e.calls, f.calls) == (1, 1)


def test_only_signals_downstream_of_a_change_are_recomputed():
    x = _adder("x", 1, 1)
    y = _adder("y", 2, 2)
    z = SigAdd("z")
    plug(x.out, z.a)
    plug(y.out, z.b)
    assert z.out(0) == 6.0
    pool.advance(1)
    x.b.value = 5
    assert z.out(1) == 10.0
    assert (x.calls, y.calls, z.calls) == (2, 1, 2)


def test_time_dependent_output_is_recomputed_every_tick_and_dependants_follow():
    c = SigClock("c")
    f = SigAdd("f")
    plug(c.count, f.a)
    f.b.value = 0.5
    values = [f.out(t) for t in range(5)]
    assert values == [0.5, 1.5, 2.5, 3.5, 4.5]
    assert c.calls["count"] == 5
    assert f.calls == 5


def test_period_recomputes_every_k_ticks():
    c = SigClock("c")
    seen = [c.slow(t) for t in range(10)]
    assert seen == [0.0, 0.0, 0.0, 3.0, 3.0, 3.0, 6.0, 6.0, 6.0, 9.0]
    assert c.calls["slow"] == 4
    assert c.slow.period == 3


def test_setPeriod_takes_effect_at_the_next_tick():
    c = SigClock("c")
    assert c.slow(9) == 9.0
    c.slow.setPeriod(1)
    assert c.slow(10) == 10.0
    assert c.slow(11) == 11.0


@pytest.mark.parametrize("bad", [0, -1, 1.5, True, "2"])
def test_period_must_be_a_positive_integer(bad):
    c = SigClock("c")
    with pytest.raises(SignalTypeError, match=r"SigClock\(c\)::output\(double\)::slow"):
        c.slow.setPeriod(bad)
    assert c.slow.period == 3


# -- same-tick changes (SoT's defect, fixed) ----------------------------------------------
def test_input_change_at_current_tick_outdates_dependants_in_the_same_tick():
    e = _adder("e", 1, 2)
    assert e.out.value == 3.0
    e.a.value = 5  # same tick
    assert e.out.value == 7.0
    assert e.out(0) == 7.0
    assert e.calls == 2


def test_same_tick_change_propagates_through_a_chain_of_entities():
    a = _adder("a", 1, 1)
    b, c = SigAdd("b"), SigAdd("c")
    plug(a.out, b.a)
    b.b.value = 0
    plug(b.out, c.a)
    c.b.value = 0
    assert c.out.value == 2.0
    pool.advance(3)
    assert c.out.value == 2.0
    a.a.value = 41
    assert c.out.value == 42.0
    assert b.out.value == 42.0
    assert (a.calls, b.calls, c.calls) == (2, 2, 2)


def test_state_written_at_current_tick_outdates_dependants():
    s = SigState("s")
    f = SigAdd("f")
    plug(s.state, f.a)
    f.b.value = 1
    assert f.out.value == 1.0
    s.state.write(5.0, 0)
    assert f.out.value == 6.0


def test_state_written_at_a_later_tick_moves_the_clock():
    s = SigState("s")
    f = SigAdd("f")
    plug(s.state, f.a)
    f.b.value = 1
    assert f.out.value == 1.0
    s.state.write(2.0, 1)
    assert pool.time == 1
    assert s.state.time == 1
    assert f.out.value == 3.0
    assert f.calls == 2


def test_state_signal_holds_its_initial_value():
    s = SigState("s")
    assert s.state.value == 0.0
    assert s.state.dependencies == []


# -- constants on outputs, setReady ---------------------------------------------------------
def test_output_set_to_constant_disables_callback_and_resetCallback_restores_it():
    e = _adder("e", 1, 2)
    f = SigAdd("f")
    plug(e.out, f.a)
    f.b.value = 0
    assert f.out.value == 3.0
    e.out.value = 100  # same tick: f must see it
    assert "(Type Cst)" in e.out.display()
    assert f.out.value == 100.0
    calls = e.calls
    pool.advance(1)
    e.a.value = 7
    assert e.out.value == 100.0
    assert f.out.value == 100.0
    assert e.calls == calls  # callback disabled
    assert e.out.dependencies == []
    e.out.resetCallback()  # same tick: computed again
    assert "(Type Fun)" in e.out.display()
    assert e.out.value == 9.0
    assert f.out.value == 9.0
    assert e.calls == calls + 1
    assert [s.shortName for s in e.out.dependencies] == ["a", "b"]


def test_resetCallback_on_a_periodic_output_computes_with_the_callback():
    e = SigAdd("e")
    e.a.value = 1
    e.b.value = 2
    e.out.setPeriod(3)
    assert e.out(0) == 3.0
    pool.advance(1)
    e.out.value = 100.0
    e.out.resetCallback()
    # the constant must not survive resetCallback while the signal says "Fun"
    assert "(Type Fun)" in e.out.display()
    assert e.out.value == 3.0
    assert e.out(2) == 3.0


def test_resetCallback_on_a_state_signal_is_refused():
    s = SigState("s")
    with pytest.raises(PlugError, match=r"SigState\(s\)::output\(double\)::state"):
        s.state.resetCallback()


def test_resetCallback_that_would_close_a_cycle_is_refused():
    a = _adder("a", 1, 0)
    b = SigAdd("b")
    b.b.value = 0
    a.out.value = 5.0  # a constant reads nothing: a loop through it is no cycle
    plug(a.out, b.a)
    plug(b.out, a.a)
    assert b.out.value == 5.0
    with pytest.raises(CycleError) as info:
        a.out.resetCallback()
    assert a.out.name in info.value.cycle and a.a.name in info.value.cycle
    assert "(Type Cst)" in a.out.display()
    assert a.out.value == 5.0
    assert b.out.value == 5.0


def test_refused_setFunction_keeps_the_old_callback():
    a = _adder("a", 1, 0)
    b = SigAdd("b")
    b.b.value = 0
    a.out.value = 5.0
    plug(a.out, b.a)
    plug(b.out, a.a)
    with pytest.raises(CycleError):
        a.out.setFunction(lambda x, y: 100.0)
    a.a.value = 1  # break the loop, then restore the callback
    a.out.resetCallback()
    assert a.out.value == 1.0  # the old callback: 1 + 0


def test_setReady_forces_a_recompute():
    e = _adder("e", 1, 2)
    assert e.out(0) == 3.0
    assert e.out(1) == 3.0
    assert e.calls == 1
    e.out.setReady()
    assert e.out.value == 3.0
    assert e.calls == 2
    pool.advance(2)
    e.out.setReady()
    assert e.out.value == 3.0
    assert e.calls == 3


def test_setFunction_replaces_the_callback_at_once():
    e = _adder("e", 1, 2)
    assert e.out.value == 3.0
    e.out.setFunction(lambda a, b: a * b)
    assert e.out.value == 2.0
    e.out.setFunction(lambda t, a, b: t + a + b, withTime=True)
    assert e.out(5) == 8.0


def test_callback_error_does_not_cache_a_stale_value():
    e = SigFlaky("e")
    assert e.out.value == 10.0
    pool.advance(1)
    e.a.value = 2
    e.fail = True
    with pytest.raises(RuntimeError):
        e.out.value  # noqa: B018
    e.fail = False
    assert e.out.value == 20.0  # same tick: recomputed, not the stale 10
    assert e.calls == 3


# -- type conversion ------------------------------------------------------------------------
def test_list_becomes_a_float64_array_and_is_not_aliased():
    s = SigScale("s")
    s.v.value = [1, 2, 3]
    v = s.v.value
    assert isinstance(v, np.ndarray)
    assert v.dtype == np.float64
    np.testing.assert_array_equal(s.out.value, [2.0, 4.0, 6.0])
    src = np.array([1.0, 1.0])
    s.v.value = src
    src[0] = 99.0  # the constant is a constant
    np.testing.assert_array_equal(s.v.value, [1.0, 1.0])
    s.m.value = [[1, 2], [3, 4]]
    assert s.m.value.shape == (2, 2)
    assert s.m.value.dtype == np.float64


def test_int_is_converted_to_float_for_a_double():
    e = SigAdd("e")
    e.a.value = 3
    assert type(e.a.value) is float
    e.a.value = np.int64(4)
    assert e.a.value == 4.0


@pytest.mark.parametrize(
    ("signal", "bad"),
    [
        ("a", True),
        ("a", np.bool_(False)),
        ("a", float("nan")),
        ("a", "1.0"),
        ("a", [1.0]),
        ("a", None),
        ("v", [[1.0, 2.0]]),
        ("v", 3.0),
        ("v", "12"),
        ("v", [1.0, float("nan")]),
        ("v", [1.0, "x"]),
        ("m", [1.0, 2.0]),
        ("m", [[[1.0]]]),
    ],
)
def test_bad_values_are_refused_naming_the_signal_and_keep_the_old_value(signal, bad):
    s = SigScale("s")
    s.v.value = [1.0, 2.0]
    s.m.value = [[1.0]]
    e = SigAdd("e")
    e.a.value = 1.0
    e.b.value = 2.0
    assert e.out.value == 3.0
    ent = e if signal == "a" else s
    sig = ent.signal(signal)
    old = sig.value
    calls_e, calls_s = e.calls, s.calls
    np.testing.assert_array_equal(s.out.value, [2.0, 4.0])
    calls_s = s.calls
    pattern = rf"{type(ent).__name__}\({ent.name}\)::input\(\w+\)::{signal}"
    with pytest.raises(SignalTypeError, match=pattern):
        sig.value = bad
    np.testing.assert_array_equal(sig.value, old)
    assert e.out.value == 3.0
    np.testing.assert_array_equal(s.out.value, [2.0, 4.0])
    # the refused write did not outdate anything
    assert (e.calls, s.calls) == (calls_e, calls_s)


def test_bad_constant_on_an_output_keeps_its_callback():
    e = _adder("e", 1, 2)
    with pytest.raises(SignalTypeError, match=r"SigAdd\(e\)::output\(double\)::out"):
        e.out.value = "three"
    assert "(Type Fun)" in e.out.display()
    e.a.value = 2
    assert e.out.value == 4.0


def test_string_and_any_signals():
    t = SigText("t")
    assert t.s.value == "hello"
    with pytest.raises(SignalTypeError, match=r"SigText\(t\)::input\(string\)::s"):
        t.s.value = 3
    assert t.s.value == "hello"
    a = SigAny("x")
    obj = object()
    a.x.value = obj
    assert a.y.value is obj


def test_any_input_accepts_an_output_of_every_type():
    a = SigAny("x")
    s = SigScale("s")
    s.v.value = [1.0]
    plug(s.out, a.x)
    np.testing.assert_array_equal(a.y.value, [2.0])
    e = _adder("e", 1, 1)
    plug(e.out, a.x)
    assert a.y.value == 2.0


# -- unplugged inputs -------------------------------------------------------------------------
def test_reading_an_unset_input_names_entity_and_signal():
    e = SigAdd("e")
    with pytest.raises(UnpluggedError, match=r"SigAdd\(e\)::input\(double\)::a") as info:
        e.a.value  # noqa: B018
    assert info.value.signals == ["SigAdd(e)::input(double)::a"]


def test_reading_an_output_over_an_unset_input_names_that_input():
    e = SigAdd("e")
    e.a.value = 1
    f = SigAdd("f")
    plug(e.out, f.a)
    f.b.value = 0
    with pytest.raises(UnpluggedError, match=r"SigAdd\(e\)::input\(double\)::b") as info:
        f.out.value  # noqa: B018
    assert "SigAdd(e)::input(double)::b" in info.value.signals
    assert e.calls == f.calls == 0
    e.b.value = 2  # the error left nothing behind: the same tick now works
    assert f.out.value == 3.0


def test_checkPlugged_lists_every_unplugged_input_upstream():
    a, b, c = SigAdd("a"), SigAdd("b"), SigAdd("c")
    plug(a.out, b.a)
    plug(b.out, c.a)
    c.b.value = 1
    expected = sorted(
        [
            "SigAdd(a)::input(double)::a",
            "SigAdd(a)::input(double)::b",
            "SigAdd(b)::input(double)::b",
        ]
    )
    assert checkPlugged(c.out) == expected
    assert checkPlugged(c.a) == expected
    assert checkPlugged(c.b) == []
    a.a.value = 1
    a.b.value = 1
    b.b.value = 1
    assert checkPlugged(c.out) == []
    assert c.out.value == 4.0


def test_unplug_restores_the_declared_default_at_once():
    src = _adder("src", 3, 4)
    i = SigInc("i")
    plug(src.out, i.a)
    assert i.out.value == 8.0
    i.a.unplug()
    assert i.a.source is None
    assert i.a.value == 0.0
    assert i.out.value == 1.0  # same tick
    assert "AUTOPLUGGED" in i.a.display()


def test_unplug_without_default_leaves_the_input_unset():
    src = _adder("src", 3, 4)
    e = SigAdd("e")
    plug(src.out, e.a)
    e.b.value = 0
    assert e.out.value == 7.0
    e.a.unplug()
    assert not e.a.isPlugged
    assert "UNPLUGGED" in e.a.display()
    with pytest.raises(UnpluggedError, match=r"SigAdd\(e\)::input\(double\)::a"):
        e.out.value  # noqa: B018
    # a later change of the old source does not reach e
    src.a.value = 0
    assert src.out.value == 4.0
    assert checkPlugged(e.out) == ["SigAdd(e)::input(double)::a"]


def test_reading_an_input_unplugged_at_the_current_tick_raises():
    src = _adder("src", 3, 4)
    e = SigAdd("e")
    plug(src.out, e.a)
    assert e.a.value == 7.0
    e.a.unplug()
    with pytest.raises(UnpluggedError, match=r"SigAdd\(e\)::input\(double\)::a"):
        e.a.value  # noqa: B018


# -- plugs ----------------------------------------------------------------------------------
def test_plug_makes_the_input_follow_the_output():
    src = _adder("src", 1, 2)
    e = SigAdd("e")
    plug(src.out, e.a)
    e.b.value = 10
    assert e.a.source is src.out
    assert e.a.isPlugged
    assert e.a.value == 3.0
    assert e.out.value == 13.0
    assert "-->-- PLUGGED" in e.a.display()
    pool.advance(1)
    src.a.value = 5
    assert e.a.value == 7.0
    assert e.a.time == 1
    assert e.out.value == 17.0


def test_setting_a_constant_unplugs():
    src = _adder("src", 1, 2)
    e = SigAdd("e")
    plug(src.out, e.a)
    e.b.value = 0
    assert e.out.value == 3.0
    e.a.value = 50  # same tick
    assert e.a.source is None
    assert e.out.value == 50.0
    calls = e.calls
    pool.advance(1)
    src.a.value = 100  # the old source no longer reaches e
    assert e.out.value == 50.0
    assert e.calls == calls


def test_plugging_an_input_that_held_a_constant_follows_the_source_at_once():
    src = _adder("src", 2, 3)
    e = SigAdd("e")
    e.a.value = 1
    e.b.value = 0
    assert e.out.value == 1.0
    plug(src.out, e.a)  # same tick
    assert e.a.value == 5.0
    assert e.out.value == 5.0


def test_replug_to_another_source():
    s1 = _adder("s1", 1, 0)
    s2 = _adder("s2", 2, 0)
    e = SigAdd("e")
    e.b.value = 0
    plug(s1.out, e.a)
    assert e.out.value == 1.0
    e.a.plug(s2.out)  # same tick, method form
    assert e.a.source is s2.out
    assert e.out.value == 2.0
    calls = e.calls
    pool.advance(1)
    s1.a.value = 100  # old source: no effect
    assert e.out.value == 2.0
    assert e.calls == calls
    s2.a.value = 200  # new source: followed
    assert e.out.value == 200.0


def _snapshot(*entities):
    out = {}
    for ent in entities:
        for s in ent.signals():
            src = getattr(s, "source", None)
            out[s.name] = (src.name if src is not None else None, s.display())
    return out


def test_plug_into_an_output_is_refused_and_changes_nothing():
    a, b = _adder("a", 1, 2), _adder("b", 3, 4)
    before = _snapshot(a, b)
    with pytest.raises(PlugError, match=r"SigAdd\(b\)::output\(double\)::out"):
        plug(a.out, b.out)
    assert _snapshot(a, b) == before
    assert b.out.value == 7.0


def test_plug_from_an_input_follows_it():
    """dynamic-graph's plug(input, input): the second input follows the first, whatever
    it holds now and later."""
    a = _adder("a", 1, 2)
    b = SigAdd("b")
    b.b.value = 10
    plug(a.a, b.a)  # b.a follows a.a (a constant, 1)
    assert b.out.value == 11.0
    assert b.a.source is a.a
    assert "-->-- PLUGGED <- SigAdd(a)::input(double)::a" in b.a.display()
    a.a.value = 5  # a new constant of the source, seen at once
    assert b.out.value == 15.0
    src = _adder("src", 20, 0)
    plug(src.out, a.a)  # the source gets plugged to an output: the follower follows it
    assert b.out.value == 30.0 and a.out.value == 22.0
    src.a.value = 40
    pool.advance(1)
    assert b.out.value == 50.0
    # a compiled plan reads through both plugs
    plan = compilePlan([b.out])
    src.a.value = 41
    plan.run(2)
    assert b.out(2) == 51.0
    # the source unplugged and unset: reading the follower names the source
    a.a.unplug()
    with pytest.raises(UnpluggedError, match=r"SigAdd\(a\)::input\(double\)::a") as info:
        b.out.recompute(3)
    assert info.value.signals == ["SigAdd(a)::input(double)::a"]
    assert checkPlugged(b.out) == ["SigAdd(a)::input(double)::a"]
    # a cycle of inputs is refused, and leaves the plugs as they were
    with pytest.raises(CycleError):
        plug(b.a, a.a)
    assert a.a.source is None and b.a.source is a.a
    with pytest.raises(PlugError, match="must be a signal"):
        plug(3.0, b.a)


def test_plug_type_mismatch_is_refused_and_keeps_the_previous_plug():
    s = SigScale("s")
    s.v.value = [1.0, 2.0]
    e = SigAdd("e")
    src = _adder("src", 1, 1)
    plug(src.out, e.a)
    e.b.value = 0
    assert e.out.value == 2.0
    with pytest.raises(SignalTypeError, match=r"SigScale\(s\)::output\(vector\)::out") as info:
        plug(s.out, e.a)
    assert "SigAdd(e)::input(double)::a" in str(info.value)
    assert isinstance(info.value, SotpyError)
    assert e.a.source is src.out
    assert e.out.value == 2.0
    assert e.calls == 1
    with pytest.raises(SignalTypeError):
        plug(src.out, s.v)
    np.testing.assert_array_equal(s.v.value, [1.0, 2.0])


def test_self_cycle_is_refused_with_the_cycle_named():
    e = _adder("e", 1, 2)
    assert e.out.value == 3.0
    with pytest.raises(CycleError) as info:
        plug(e.out, e.a)
    assert isinstance(info.value, PlugError)
    cyc = info.value.cycle
    assert cyc[0] == cyc[-1]
    assert set(cyc) == {e.out.name, e.a.name}
    assert e.out.name in str(info.value) and e.a.name in str(info.value)
    assert e.a.source is None
    assert e.a.value == 1.0
    assert e.out.value == 3.0
    assert e.calls == 1


def test_cycle_through_several_entities_is_refused_and_the_graph_is_unchanged():
    a, b, c = _adder("a", 1, 1), SigAdd("b"), SigAdd("c")
    plug(a.out, b.a)
    b.b.value = 1
    plug(b.out, c.a)
    c.b.value = 1
    assert c.out.value == 4.0
    old = _adder("old", 10, 0)
    plug(old.out, a.a)  # a.a follows old.out; the cycle attempt must keep this plug
    assert c.out.value == 13.0
    before = _snapshot(a, b, c, old)
    calls = (a.calls, b.calls, c.calls)
    with pytest.raises(CycleError) as info:
        plug(c.out, a.a)
    cyc = info.value.cycle
    assert cyc[0] == cyc[-1]
    expected = {c.out.name, c.a.name, b.out.name, b.a.name, a.out.name, a.a.name}
    assert set(cyc) == expected
    assert len(cyc) == len(expected) + 1
    msg = str(info.value)
    for name in expected:
        assert name in msg
    # each name reads the next one (the new edge: a.a reads c.out)
    reads = {
        c.out.name: c.a.name,
        c.a.name: b.out.name,
        b.out.name: b.a.name,
        b.a.name: a.out.name,
        a.out.name: a.a.name,
        a.a.name: c.out.name,
    }
    for x, y in itertools.pairwise(cyc):
        assert reads[x] == y, (x, y)
    assert _snapshot(a, b, c, old) == before
    assert a.a.source is old.out
    assert c.out.value == 13.0
    assert (a.calls, b.calls, c.calls) == calls


def test_cycle_refused_in_setDependencies_keeps_the_old_dependencies():
    a = _adder("a", 1, 2)
    b = SigAdd("b")
    plug(a.out, b.a)
    b.b.value = 0
    assert b.out.value == 3.0
    with pytest.raises(CycleError):
        a.out.setDependencies([b.out])
    assert a.out.dependencies == [a.a, a.b]
    assert b.out.value == 3.0


# -- deep chains, display -------------------------------------------------------------------
def _chain(n: int) -> list[SigInc]:
    """n SigInc entities, each reading the previous one (2 n signals). Plugged from
    the end so that building is linear."""
    es = [SigInc(f"i{k}") for k in range(n)]
    for k in range(n - 1, 0, -1):
        plug(es[k - 1].out, es[k].a)
    return es


def test_a_10000_signal_chain_evaluates_with_the_default_recursion_limit():
    assert sys.getrecursionlimit() <= 10_000
    es = _chain(5_000)  # 5,000 inputs + 5,000 outputs
    es[0].a.value = 0.5
    assert es[-1].out.value == 5_000.5
    es[0].a.value = 1.5  # same tick, pushed down the whole chain
    assert es[-1].out.value == 5_001.5
    assert es[2_500].out.value == 2_502.5
    pool.advance(1)
    assert es[-1].out.value == 5_001.5
    assert sum(e.calls for e in es) == 2 * 5_000
    assert len(checkPlugged(es[-1].out)) == 0
    text = es[-1].out.displayDependencies()
    assert text.count("\n") + 1 == 2 * 5_000


def test_displayDependencies_shows_the_tree():
    a = _adder("a", 1, 2)
    b = SigAdd("b")
    plug(a.out, b.a)
    b.b.value = 5
    b.out.value  # noqa: B018
    text = b.out.displayDependencies()
    lines = text.splitlines()
    assert lines[0].startswith("<Sig:SigAdd(b)::output(double)::out (Type Fun)>")
    assert lines[0].endswith("t=0")
    assert lines[1].startswith("|-- <Sig:SigAdd(b)::input(double)::a")
    assert "PLUGGED" in lines[1]
    # a's output hangs under b.a, one level deeper, then a's inputs under it
    assert lines[2].startswith("|   `-- <Sig:SigAdd(a)::output(double)::out")
    assert lines[3].startswith("|       |-- <Sig:SigAdd(a)::input(double)::a")
    assert lines[4].startswith("|       `-- <Sig:SigAdd(a)::input(double)::b")
    assert lines[5].startswith("`-- <Sig:SigAdd(b)::input(double)::b")
    assert len(lines) == 6
    assert all("t=" in line for line in lines)
    # depth limits the tree
    assert len(b.out.displayDependencies(1).splitlines()) == 3


def test_displayDependencies_shows_the_period():
    c = SigClock("c")
    c.slow(0)
    assert "(/3)" in c.slow.displayDependencies()


def test_time_is_the_tick_of_the_last_computation_after_an_invalidation():
    e = _adder("e", 1, 2)
    assert e.out.value == 3.0
    assert e.out.time == 0
    e.a.value = 2  # outdates e.out at tick 0; its value is still the one of tick 0
    assert e.out.time == 0


def test_runtime_output_signal_with_dependencies():
    e = _adder("e", 1, 2)
    sq = OutputSignal(e, "sq", DOUBLE, lambda a: a * a, [e.a])
    e.addSignal(sq)
    assert e.sq.value == 1.0
    e.a.value = 3
    assert e.sq.value == 9.0
    assert e.sq.timeDependent is False
    assert sq.name == "SigAdd(e)::output(double)::sq"
