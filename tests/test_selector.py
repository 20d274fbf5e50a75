"""sot-pattern-generator's Selector (sotpy.operators.Selector).

The output follows ``selec`` for each type, with values; a change of ``selec`` at a
later tick (plugged or a constant) is seen at that tick, by the lazy pull and by a
compiled plan; the unselected entry is not computed (counted calls of an upstream
output); the meta constructor of the SoT scripts with a Talos model; every bad input
refused with an exception of sotpy.errors and the graph left as it was;
``displaySignals`` and ``writeGraph`` show the created signals.
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

from sotpy.dynamics.types import SE3
from sotpy.errors import CommandError, CycleError, SignalTypeError, UnpluggedError
from sotpy.graph import BOOL, INT, MATRIX, VECTOR, Entity, Input, Output, Plan, plug, pool
from sotpy.graph.dot import graphDot
from sotpy.operators import Add_of_vector, Selector, VectorConstant


class Counted(Entity):
    """Time-dependent sources that count their computations."""

    def __init__(self, name: str) -> None:
        self.calls = {"a": 0, "b": 0}
        self.switchAt = 10**9  # tick from which ``flag`` is True and ``index`` is 1

    @Output(VECTOR, withTime=True, timeDependent=True)
    def a(self, t: int) -> np.ndarray:
        self.calls["a"] += 1
        return np.array([1.0, float(t)])

    @Output(VECTOR, withTime=True, timeDependent=True)
    def b(self, t: int) -> np.ndarray:
        self.calls["b"] += 1
        return np.array([-1.0, -float(t)])

    @Output(BOOL, withTime=True, timeDependent=True)
    def flag(self, t: int) -> bool:
        return t >= self.switchAt

    @Output(INT, withTime=True, timeDependent=True)
    def index(self, t: int) -> int:
        return int(t >= self.switchAt)


class Reader(Entity):
    """Reads a vector (to close cycles and to use a Selector's output)."""

    sin = Input(VECTOR)

    @Output(VECTOR, deps=("sin",))
    def sout(self, x: np.ndarray) -> np.ndarray:
        return x.copy()


def random_se3(seed: int) -> pin.SE3:
    np.random.seed(seed)
    return pin.SE3.Random()


def snapshot(sel: Selector) -> tuple[str, list]:
    """What a refused operation must leave as it was: the signal list (with plugs) and
    each output's dependencies."""
    deps = [
        (s.shortName, [d.name for d in s.dependencies])
        for s in sel.signals()
        if s.direction == "output"
    ]
    return sel.signalsDisplay(), deps


# -- values -----------------------------------------------------------------------------
def test_output_follows_selec_for_each_type():
    sel = Selector("sel")
    sel.reset(3, 3)
    sel.create("vector", "v", 0)
    sel.create("matrix", "m", 1)
    sel.create("matrixHomo", "h", 2)
    assert (sel.nbEntries, sel.nbSignals) == (3, 3)
    assert sel.families() == [("v", "vector"), ("m", "matrix"), ("h", "matrixHomo")]
    assert sel.v.type is VECTOR and sel.m.type is MATRIX and sel.h.type is SE3
    assert sel.signal("h2").type is SE3
    vs = [np.array([1.0, 2.0]), np.array([3.0, 4.0, 5.0]), np.array([6.0])]
    ms = [np.eye(2), np.arange(6.0).reshape(2, 3), -np.ones((1, 1))]
    hs = [random_se3(i) for i in range(3)]
    for i in range(3):
        sel.signal(f"v{i}").value = vs[i]
        sel.signal(f"m{i}").value = ms[i]
        sel.signal(f"h{i}").value = hs[i]
    for k in (0, 2, 1, 0):
        sel.selec.value = k
        np.testing.assert_array_equal(sel.v.value, vs[k])
        np.testing.assert_array_equal(sel.m.value, ms[k])
        assert sel.h.value.isApprox(hs[k], 0.0)
        assert isinstance(sel.h.value, pin.SE3)
    # fresh values, never the input's: changing one leaves the selected input as it was
    out = sel.v.value
    assert not np.shares_memory(out, sel.v0.value)
    out[0] = 99.0
    np.testing.assert_array_equal(sel.v0.value, vs[0])
    sel.h.value.translation[0] = 99.0
    assert sel.h0.value.isApprox(hs[0], 0.0)
    assert "vector" in sel.getTypeList() and "matrixHomo" in sel.getTypeList()
    assert sel.getTypeList() == "Types available:\n  - vector\n  - matrix\n  - matrixHomo\n"


def test_selec_takes_an_int_or_a_bool_plugged_or_constant():
    src = Counted("src")
    sel = Selector("sel", ["vector", "ref", src.a, src.b])
    # sotpy's int inputs refuse bool outputs, so selec has its own type, which takes both
    assert not INT.accepts_output(BOOL)
    assert sel.selec.name == "Selector(sel)::input(index)::selec"
    plug(src.flag, sel.selec)
    np.testing.assert_array_equal(sel.ref(1), [1.0, 1.0])
    src.switchAt = 2
    np.testing.assert_array_equal(sel.ref(2), [-1.0, -2.0])
    plug(src.index, sel.selec)
    np.testing.assert_array_equal(sel.ref(3), [-1.0, -3.0])
    sel.selec.value = False
    np.testing.assert_array_equal(sel.ref.value, [1.0, 3.0])
    sel.selec.value = True
    np.testing.assert_array_equal(sel.ref.value, [-1.0, -3.0])
    sel.selec.value = np.int64(0)
    np.testing.assert_array_equal(sel.ref.value, [1.0, 3.0])


def test_switch_at_a_later_tick_is_seen_at_that_tick():
    src = Counted("src")
    src.switchAt = 5
    sel = Selector("sel", ["vector", "ref", src.a, src.b])
    plug(src.flag, sel.selec)
    reader = Reader("reader")
    plug(sel.ref, reader.sin)
    for t in range(8):  # lazy pull through a reader
        expected = [1.0, t] if t < 5 else [-1.0, -t]
        np.testing.assert_array_equal(reader.sout(t), expected)
    src.switchAt = 10
    plan = Plan([reader.sout])
    for t in range(8, 14):  # a compiled plan: back to ref0 at tick 8, to ref1 at 10
        plan.run(t)
        expected = [1.0, t] if t < 10 else [-1.0, -t]
        np.testing.assert_array_equal(reader.sout.value, expected)
    # a constant written at the current tick is seen at once (push invalidation)
    sel.selec.value = 0
    np.testing.assert_array_equal(reader.sout.value, [1.0, 13.0])
    sel.selec.value = 1
    np.testing.assert_array_equal(reader.sout.value, [-1.0, -13.0])
    sel.selec.value = 0
    np.testing.assert_array_equal(reader.sout.value, [1.0, 13.0])
    # a constant entry written at the current tick too
    sel.ref0.value = [7.0, 8.0]
    np.testing.assert_array_equal(reader.sout.value, [7.0, 8.0])
    plan.run(14)
    np.testing.assert_array_equal(reader.sout.value, [7.0, 8.0])


def test_the_unselected_entry_is_not_computed():
    src = Counted("src")
    sel = Selector("sel", ["vector", "ref", src.a, src.b])
    sel.selec.value = 0
    for t in range(1, 6):
        sel.ref(t)
    assert src.calls == {"a": 5, "b": 0}
    sel.selec.value = 1  # a constant: the output depends on ref1 from now on
    assert [d.shortName for d in sel.ref.dependencies] == ["selec", "ref1"]
    plan = Plan([sel.ref])
    for t in range(6, 11):
        plan.run(t)
    assert src.calls == {"a": 5, "b": 5}
    assert "Src" not in [s.entity.className for s in plan.steps]
    assert [s.path for s in plan.steps] == ["src.b", "sel.ref"]
    # plugged: the output moves to the new entry at the tick selec changes; at that
    # tick only, the previous entry was already brought up to date (it was the
    # output's dependency when the read began)
    src.switchAt = 13
    plug(src.index, sel.selec)  # 0 until tick 12, then 1
    counts = []
    for t in range(11, 17):
        plan.run(t)
        expected = [1.0, t] if t < 13 else [-1.0, -t]
        np.testing.assert_array_equal(sel.ref.value, expected)
        counts.append((src.calls["a"] - 5, src.calls["b"] - 5))
    # tick 11: to ref0 (b computed once more), tick 13: to ref1 (a once more)
    assert counts == [(1, 1), (2, 1), (3, 2), (3, 3), (3, 4), (3, 5)]
    assert [d.shortName for d in sel.ref.dependencies] == ["selec", "ref1"]
    assert [s.path for s in plan.steps] == ["src.index", "src.b", "sel.ref"]


# -- the meta constructor, with a robot ---------------------------------------------------
def test_meta_constructor_as_in_the_sot_scripts():
    from sotpy.dynamics import load_robot

    robot = load_robot("talos")
    pgcom = VectorConstant("pgcom")
    pgcom.sout.value = [0.01, 0.02, 0.8]
    src = Counted("src")
    comSelector = Selector("comSelector", ["vector", "ref", robot.dynamic.com, pgcom.sout])
    plug(src.flag, comSelector.selec)  # pg.inprocess: a bool
    assert comSelector.families() == [("ref", "vector")]
    np.testing.assert_allclose(comSelector.ref(1), robot.dynamic.com(1))
    src.switchAt = 2
    np.testing.assert_array_equal(comSelector.ref(2), [0.01, 0.02, 0.8])

    rf, lf = robot.dynamic.signal("right-ankle"), robot.dynamic.signal("left-ankle")
    pgRight, pgLeft = random_se3(1), random_se3(2)
    pg = Selector("pgFeet")  # placements standing for pg.rightfootref, pg.leftfootref
    pg.reset(2, 1)
    pg.create("matrixHomo", "foot", 0)
    pg.foot0.value, pg.foot1.value = pgRight, pgLeft
    pg.selec.value = 0
    selecSupportFoot = Selector(
        "selecSupportFoot",
        ["matrixHomo", "pg_H_sf", pg.foot0, pg.foot1],
        ["matrixHomo", "wa_H_sf", rf, lf],
    )
    src.switchAt = 3
    plug(src.index, selecSupportFoot.selec)  # pg.SupportFoot: an int
    assert selecSupportFoot.pg_H_sf(3).isApprox(pgLeft, 0.0)
    assert selecSupportFoot.wa_H_sf(3).isApprox(lf(3), 0.0)
    src.switchAt = 10
    assert selecSupportFoot.pg_H_sf(4).isApprox(pgRight, 0.0)
    assert selecSupportFoot.wa_H_sf(4).isApprox(rf(4), 0.0)
    text = selecSupportFoot.signalsDisplay()
    assert "Selector(selecSupportFoot)::input(SE3)::wa_H_sf1 (Type Ref) -->-- PLUGGED <- " in text
    assert "Dynamic(" in text and "::output(SE3)::left-ankle" in text


# -- bad input ---------------------------------------------------------------------------
def test_selec_out_of_range_at_read_time():
    sel = Selector("sel")
    sel.reset(2, 1)
    sel.create("vector", "ref", 0)
    sel.ref0.value, sel.ref1.value = [1.0], [2.0]
    with pytest.raises(UnpluggedError, match=r"Selector\(sel\)::input\(index\)::selec"):
        sel.ref.value  # noqa: B018
    sel.selec.value = 1
    np.testing.assert_array_equal(sel.ref.value, [2.0])
    before = snapshot(sel)
    sel.selec.value = 2
    with pytest.raises(SignalTypeError) as exc:
        sel.ref.value  # noqa: B018
    msg = str(exc.value)
    assert "Selector(sel)::input(index)::selec" in msg and "out of range" in msg
    assert "expected 0 .. 1" in msg and "Selector(sel)::output(vector)::ref" in msg
    assert snapshot(sel)[1] == before[1]  # still reads ref1
    # plugged to an int output giving 2: the same error
    src = Counted("src")
    plug(src.index, sel.selec)
    src.switchAt = 0
    np.testing.assert_array_equal(sel.ref(1), [2.0])
    # constants that are not an entry index are refused when written
    for bad in (-1, 1.0, "1", None):
        with pytest.raises(SignalTypeError, match=r"Selector\(sel\)::input\(index\)::selec"):
            sel.selec.value = bad
    assert sel.selec.source is src.index


def test_create_refuses_bad_arguments_and_changes_nothing():
    sel = Selector("sel")
    sel.reset(2, 2)
    sel.create("vector", "ref", 0)
    sel.ref0.value = [1.0]
    before = snapshot(sel)
    version = pool.version
    with pytest.raises(CommandError) as exc:
        sel.create("quaternion", "q", 1)
    assert "Selector(sel).create" in str(exc.value)
    assert "unknown type 'quaternion'" in str(exc.value)
    assert "vector, matrix, matrixHomo" in str(exc.value)
    with pytest.raises(CommandError, match=r"Selector\(sel\).create: expected a family index"):
        sel.create("vector", "other", 2)  # nbSignals is 2: slots 0 and 1
    with pytest.raises(CommandError, match="already exists with type 'vector'"):
        sel.create("matrix", "ref", 0)  # created again with another type
    with pytest.raises(CommandError, match="already exists with type 'vector'"):
        sel.create("matrix", "ref", 1)
    with pytest.raises(CommandError, match="slot 0 already holds family 'ref'"):
        sel.create("vector", "other", 0)
    with pytest.raises(CommandError, match="selec already exist"):
        sel.create("vector", "selec", 1)
    with pytest.raises(CommandError, match="ref0 already exist"):
        sel.create("vector", "ref0", 1)  # its output would be ref0
    with pytest.raises(CommandError, match="without dots"):
        sel.create("vector", "a.b", 1)
    with pytest.raises(CommandError, match="argument 'type'"):
        sel.create(3, "x", 1)
    assert snapshot(sel) == before and pool.version == version
    sel.create("vector", "ref", 0)  # the same family again: nothing to do
    assert snapshot(sel) == before
    sel.create("matrix", "m")  # -1: the first free slot
    assert sel.families() == [("ref", "vector"), ("m", "matrix")]
    with pytest.raises(CommandError, match="no free family slot"):
        sel.create("vector", "third")
    with pytest.raises(CommandError, match=r"Selector\(sel\).reset: expected nbEntries >= 0"):
        sel.reset(-1, 2)


def test_plugging_an_entry_of_the_wrong_type_is_refused():
    sel = Selector("sel")
    sel.reset(2, 2)
    sel.create("vector", "v", 0)
    sel.create("matrixHomo", "h", 1)
    const = VectorConstant("const")
    const.sout.value = [1.0, 2.0]
    plug(const.sout, sel.v0)
    before = snapshot(sel)
    with pytest.raises(SignalTypeError, match=r"the input expects SE3, the output gives vector"):
        plug(const.sout, sel.h0)
    with pytest.raises(SignalTypeError, match=r"Selector\(sel\)::input\(SE3\)::h1"):
        sel.h1.value = [1.0, 2.0]
    with pytest.raises(SignalTypeError, match="the input expects index, the output gives vector"):
        plug(const.sout, sel.selec)
    assert snapshot(sel) == before


def test_meta_constructor_refuses_bad_lists_and_creates_nothing():
    const = VectorConstant("const")
    const.sout.value = [1.0]
    homo = Selector("homo")
    homo.reset(1, 1)
    homo.create("matrixHomo", "h", 0)
    names = pool.list()
    cases = [
        (["vector", "ref"], r"argument 1 \['vector', 'ref'\] is too short"),
        ("vector", "argument 1: expected lists"),
        (["vector", "ref", const.sout, 3.0], r"argument 1 \('ref'\), input 1: expected a signal"),
        (["vector", 7, const.sout], "the type and outName must be strings"),
        (["quaternion", "ref", const.sout], "unknown type 'quaternion'"),
    ]
    for spec, match in cases:
        with pytest.raises(CommandError, match=match):
            Selector("sel", spec)
        assert pool.list() == names and not pool.hasEntity("sel")
    with pytest.raises(CommandError, match="argument 2 has 2 inputs and argument 1 has 1"):
        Selector("sel", ["vector", "a", const.sout], ["vector", "b", const.sout, const.sout])
    # a plug of the wrong type (the second family): no entity, const left as it was
    with pytest.raises(SignalTypeError, match="the input expects SE3, the output gives vector"):
        Selector("sel", ["vector", "a", const.sout], ["matrixHomo", "b", const.sout])
    assert pool.list() == names and not pool.hasEntity("sel")
    assert const.sout._dependants == []
    Selector("sel", ["vector", "a", const.sout], ["matrixHomo", "b", homo.h])
    assert pool.hasEntity("sel")


def test_reset_refused_while_used_then_removes_the_families():
    sel = Selector("sel", ["vector", "ref", VectorConstant("c").sout])
    reader = Reader("reader")
    plug(sel.ref, reader.sin)
    before = snapshot(sel)
    with pytest.raises(CommandError, match=r"Selector\(sel\).reset: the families are still used"):
        sel.reset(2, 1)
    assert snapshot(sel) == before
    reader.sin.unplug()
    sel.reset(2, 1)
    assert [s.shortName for s in sel.signals()] == ["selec"]
    assert not sel.hasSignal("ref") and not hasattr(sel, "ref0")
    sel.create("matrix", "ref", 0)
    assert sel.ref.type is MATRIX


def test_a_plug_closing_a_cycle_through_an_unselected_entry_is_refused():
    sel = Selector("sel")
    sel.reset(2, 1)
    sel.create("vector", "ref", 0)
    sel.selec.value = 0
    sel.ref0.value = [1.0, 2.0]
    reader = Reader("reader")
    plug(sel.ref, reader.sin)
    with pytest.raises(CycleError) as exc:
        plug(reader.sout, sel.ref1)  # would close a cycle once ref1 is selected
    assert "Selector(sel)::input(vector)::ref1" in str(exc.value)
    assert "Reader(reader)::output(vector)::sout" in exc.value.cycle
    assert not sel.ref1.isPlugged
    with pytest.raises(CycleError):
        plug(reader.sout, sel.ref0)  # the selected one: refused by plug itself
    np.testing.assert_array_equal(reader.sout.value, [1.0, 2.0])


# -- display -------------------------------------------------------------------------------
def test_display_signals_and_write_graph_show_the_created_signals(capsys):
    c0, c1 = VectorConstant("c0"), VectorConstant("c1")
    c0.sout.value, c1.sout.value = [1.0], [2.0]
    sel = Selector("sel", ["vector", "ref", c0.sout, c1.sout])
    add = Add_of_vector("add")
    plug(sel.ref, add.sin0)
    add.sin1.value = [10.0]
    sel.selec.value = 1
    np.testing.assert_array_equal(add.sout.value, [12.0])
    sel.displaySignals()
    out = capsys.readouterr().out
    assert out.splitlines() == [
        "--- <sel> signal list:",
        "|-- <Sig:Selector(sel)::output(vector)::ref (Type Fun)",
        "|-- <Sig:Selector(sel)::input(vector)::ref0 (Type Ref) -->-- PLUGGED <- "
        "VectorConstant(c0)::output(vector)::sout",
        "|-- <Sig:Selector(sel)::input(vector)::ref1 (Type Ref) -->-- PLUGGED <- "
        "VectorConstant(c1)::output(vector)::sout",
        "'-- <Sig:Selector(sel)::input(index)::selec (Type Cst) AUTOPLUGGED",
    ]
    assert pool.getSignal("sel.ref1") is sel.ref1
    dot = graphDot()
    for label in ("ref0", "ref1", "ref"):
        assert f'"{label}"' in dot or f"{label}" in dot
    assert "Selector" in sel.helpText() or "reset" in sel.helpText()
    assert "create" in sel.commands() and "getTypeList" in sel.commands()
