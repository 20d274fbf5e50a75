"""Entities, the pool, the factory and commands: creation rules, lookups with helpful
errors, SoT's display strings, help, typed command arguments and signals added at
runtime (documented in ``sotpy.graph.entity``, ``pool`` and ``command``)."""

from __future__ import annotations

import math
from typing import Annotated, Optional

import numpy as np
import pytest

from sotpy.errors import (
    CommandError,
    EntityError,
    FactoryError,
    SignalNotFoundError,
    SotpyError,
    UnpluggedError,
)
from sotpy.graph import (
    DOUBLE,
    VECTOR,
    Entity,
    Input,
    InputSignal,
    Output,
    OutputSignal,
    command,
    factory,
    plug,
    pool,
)


class EntAdd(Entity):
    """Adds two doubles.

    A second paragraph that help() does not print."""

    a = Input(DOUBLE, doc="first term")
    b = Input(DOUBLE, default=1.0, doc="second term")

    def __init__(self, name: str) -> None:
        self.log: list[tuple] = []

    @Output(DOUBLE, deps=("a", "b"))
    def out(self, a, b):
        """a + b"""
        return a + b

    @command
    def setGain(self, k: float) -> float:
        """Set the second term; return twice it.

        Longer explanation of the gain."""
        self.log.append(("setGain", k))
        self.b.value = k
        return 2 * k

    @command
    def setSize(self, n: int) -> int:
        """Set a size."""
        self.log.append(("setSize", n))
        return n

    @command
    def setFlag(self, on: bool) -> None:
        """Set a flag."""
        self.log.append(("setFlag", on))

    @command
    def rename(self, label: str) -> str:
        """Set a label."""
        self.log.append(("rename", label))
        return label.upper()

    @command
    def setVec(self, v: np.ndarray) -> np.ndarray:
        """Set a vector."""
        self.log.append(("setVec", v))
        return v

    @command
    def maybe(self, x: Optional[float] = None) -> Optional[float]:  # noqa: UP045
        """Optional float, typing.Optional spelling."""
        self.log.append(("maybe", x))
        return x

    @command
    def maybe2(self, x: float | None = None) -> float | None:
        """Optional float, PEP 604 spelling."""
        self.log.append(("maybe2", x))
        return x

    @command
    def link(self, other: EntAdd) -> str:
        """Link to another adder."""
        self.log.append(("link", other))
        return other.name

    @command
    def anything(self, x) -> object:
        """No annotation: anything goes."""
        return x


class EntOther(Entity):
    """Another class, for name clashes."""

    x = Input(VECTOR)


class EntBroken(Entity):
    """Its constructor fails after plugging."""

    a = Input(DOUBLE)

    def __init__(self, name: str, source: OutputSignal) -> None:
        plug(source, self.a)
        raise RuntimeError("constructor failed")


# -- creation ---------------------------------------------------------------------------
def test_creation_is_idempotent_for_the_same_class():
    e = EntAdd("e")
    assert EntAdd("e") is e
    assert factory.create("EntAdd", "e") is e
    assert pool.list() == ["e"]


def test_same_name_with_another_class_is_refused():
    e = EntAdd("e")
    with pytest.raises(EntityError, match=r"EntOther\(e\).*EntAdd"):
        EntOther("e")
    with pytest.raises(EntityError):
        factory.create("EntOther", "e")
    assert pool.getEntity("e") is e
    assert pool.list() == ["e"]


@pytest.mark.parametrize("bad", ["", " e", "e ", "a.b", 3])
def test_bad_entity_names_are_refused(bad):
    with pytest.raises(EntityError, match="name"):
        EntAdd(bad)
    assert pool.list() == []


def test_factory_creates_by_class_name():
    e = factory.create("EntAdd", "n")
    assert type(e) is EntAdd
    assert e.name == "n"
    assert e.className == "EntAdd"
    assert factory.hasClass("EntAdd")
    assert factory.getClass("EntAdd") is EntAdd
    assert "EntAdd" in factory.classes()


def test_unknown_class_lists_the_known_classes():
    with pytest.raises(FactoryError, match="NoSuchClass") as info:
        factory.create("NoSuchClass", "n")
    msg = str(info.value)
    assert "EntAdd" in msg and "EntOther" in msg
    assert pool.list() == []


def test_failed_constructor_leaves_the_pool_as_before():
    src = EntAdd("src")
    src.a.value = 1
    with pytest.raises(RuntimeError, match="constructor failed"):
        EntBroken("broken", src.out)
    assert not pool.hasEntity("broken")
    assert src.out._dependants == []
    assert src.out.value == 2.0


# -- pool ---------------------------------------------------------------------------------
def test_getEntity_and_getSignal():
    e = EntAdd("e")
    assert pool.getEntity("e") is e
    assert pool.hasEntity("e")
    assert pool.getSignal("e.out") is e.out
    assert pool.getSignal("e.a") is e.a


def test_unknown_entity_lists_the_known_ones():
    EntAdd("alpha")
    EntAdd("beta")
    with pytest.raises(EntityError, match="gamma") as info:
        pool.getEntity("gamma")
    assert "alpha" in str(info.value) and "beta" in str(info.value)
    with pytest.raises(EntityError, match="alpha"):
        pool.getSignal("gamma.out")


def test_unknown_signal_lists_the_signals():
    EntAdd("e")
    with pytest.raises(SignalNotFoundError, match=r"EntAdd\(e\).*'nope'.*a, b, out"):
        pool.getSignal("e.nope")
    with pytest.raises(SignalNotFoundError, match=r"entity\.signal"):
        pool.getSignal("nodot")


def test_getSignal_reaches_a_signal_whose_name_has_a_dot():
    e = EntAdd("e")
    s = e.addSignal(InputSignal(e, "l.w", DOUBLE, 1.0))
    assert e.signal("l.w") is s
    assert pool.getSignal("e.l.w") is s


def test_clear_forgets_entities_and_resets_the_clock():
    e = EntAdd("e")
    e.a.value = 1
    e.out(12)
    assert pool.time == 12
    pool.clear()
    assert pool.list() == []
    assert pool.entities() == []
    assert pool.time == 0
    with pytest.raises(EntityError):
        pool.getEntity("e")
    other = EntOther("e")  # the name is free again, for another class
    assert pool.getEntity("e") is other


def test_remove_is_refused_while_a_reader_is_plugged_and_unplugs_it_inside_a_group():
    a = EntAdd("a")
    a.a.value = 1
    b = EntAdd("b")
    plug(a.out, b.a)
    assert b.out.value == 3.0
    with pytest.raises(EntityError, match=r"EntAdd\(b\)::input\(double\)::a plugged to a.out"):
        pool.remove("a")
    assert pool.hasEntity("a") and b.a.source is a.out and b.out.value == 3.0
    b.a.unplug()
    pool.remove("a")
    assert not pool.hasEntity("a")
    with pytest.raises(UnpluggedError, match=r"EntAdd\(b\)::input\(double\)::a"):
        b.out(1)
    c = EntAdd("c")
    plug(b.out, c.a)
    pool.remove("b", "c")  # together: the plug between them goes with them
    assert pool.list() == [] and b.out._dependants == []


# -- display ----------------------------------------------------------------------------
def test_displaySignals_layout(capsys):
    src = EntAdd("src")
    e = EntAdd("e")
    plug(src.out, e.a)
    e.displaySignals()
    text = capsys.readouterr().out.rstrip("\n")
    lines = text.splitlines()
    assert lines[0] == "--- <e> signal list:"
    assert len(lines) == 4
    assert all(line.startswith("|-- <Sig:") for line in lines[1:-1])
    assert lines[-1].startswith("'-- <Sig:")
    by_name = {line.split("::")[2].split(" ")[0]: line for line in lines[1:]}
    assert by_name["a"].startswith("|-- <Sig:EntAdd(e)::input(double)::a (Type ")
    assert "-->-- PLUGGED" in by_name["a"]
    assert by_name["b"].endswith("AUTOPLUGGED")
    assert "EntAdd(e)::output(double)::out (Type Fun)" in by_name["out"]
    assert text == e.signalsDisplay()
    src.displaySignals()
    unplugged = capsys.readouterr().out
    assert "Sig:EntAdd(src)::input(double)::a (Type Cst) UNPLUGGED" in unplugged


def _printed_help(capsys, entity, *args) -> str:
    capsys.readouterr()
    entity.help(*args)
    return capsys.readouterr().out.rstrip("\n")


def test_help_lists_the_commands(capsys):
    e = EntAdd("e")
    text = _printed_help(capsys, e)
    lines = text.splitlines()
    assert lines[0] == "Adds two doubles."
    assert "second paragraph" not in text
    assert lines[1] == "List of commands:"
    listed = [line.split(":")[0].strip() for line in lines[2:]]
    assert listed == sorted(listed) == e.commands()
    assert "setGain" in listed
    gain_line = next(line for line in lines if line.strip().startswith("setGain:"))
    assert gain_line.endswith("Set the second term; return twice it.")


def test_help_of_one_command(capsys):
    e = EntAdd("e")
    first, *rest = _printed_help(capsys, e, "setGain").splitlines()
    assert first == "setGain(k: float) -> float"
    assert "Set the second term; return twice it." in rest[0]
    assert any("Longer explanation of the gain." in line for line in rest)
    assert e.setGain.__doc__.startswith("Set the second term")
    with pytest.raises(SignalNotFoundError, match=r"EntAdd\(e\).*'nope'.*setGain"):
        e.help("nope")


def test_help_usage_shows_unquoted_types(capsys):
    # sotpy's own modules use postponed annotations: the usage must not show them quoted
    from sotpy.graph import Tracer

    t = Tracer("tr")
    first = _printed_help(capsys, t, "add").splitlines()[0]
    assert "'" not in first
    assert first.startswith("add(signal: ")
    assert "Signal | str, name: str | None = None) -> None" in first


# -- commands -----------------------------------------------------------------------------
def test_command_runs_and_returns_its_value():
    e = EntAdd("e")
    e.a.value = 1
    assert e.setGain(3) == 6.0
    assert e.log == [("setGain", 3.0)]
    assert type(e.log[0][1]) is float
    assert e.out.value == 4.0
    assert e.setSize(4) == 4
    assert e.rename("x") == "X"
    assert e.link(EntAdd("f")) == "f"
    assert e.anything("whatever") == "whatever"
    assert e.getCommand("setSize")(5) == 5
    assert e.setGain(k=2.5) == 5.0


def test_ndarray_argument_converts_lists():
    e = EntAdd("e")
    v = e.setVec([1, 2, 3])
    assert isinstance(v, np.ndarray) and v.dtype == np.float64
    np.testing.assert_array_equal(v, [1.0, 2.0, 3.0])


def test_optional_arguments():
    e = EntAdd("e")
    assert e.maybe() is None
    assert e.maybe(None) is None
    assert e.maybe(2) == 2.0
    assert e.maybe2(None) is None
    assert e.maybe2(3) == 3.0
    with pytest.raises(CommandError, match=r"EntAdd\(e\)\.maybe.*'x'"):
        e.maybe("a")
    with pytest.raises(CommandError, match=r"EntAdd\(e\)\.maybe2.*'x'"):
        e.maybe2(True)


@pytest.mark.parametrize(
    ("cmd", "bad"),
    [
        ("setGain", "1.0"),
        ("setGain", True),
        ("setGain", math.nan),
        ("setGain", np.nan),
        ("setGain", None),
        ("setGain", [1.0]),
        ("setSize", 2.0),
        ("setSize", True),
        ("setSize", "2"),
        ("setFlag", 1),
        ("setFlag", "yes"),
        ("rename", 3),
        ("setVec", "abc"),
        ("setVec", [1.0, math.nan]),
        ("setVec", [1.0, "x"]),
        ("link", "f"),
    ],
)
def test_ill_typed_arguments_raise_and_the_body_does_not_run(cmd, bad):
    e = EntAdd("e")
    EntOther("other")
    old_b = e.b.value
    with pytest.raises(CommandError, match=rf"EntAdd\(e\)\.{cmd}.*argument '\w+'"):
        getattr(e, cmd)(bad)
    assert e.log == []
    assert e.b.value == old_b


def test_entity_typed_argument_refuses_another_entity_class():
    e = EntAdd("e")
    other = EntOther("other")
    with pytest.raises(CommandError, match=r"EntAdd\(e\)\.link.*'other'.*EntAdd"):
        e.link(other)
    assert e.log == []


def test_missing_or_extra_arguments_raise_command_error():
    e = EntAdd("e")
    with pytest.raises(CommandError, match=r"EntAdd\(e\)\.setGain.*'k'.*usage: setGain\(k"):
        e.setGain()
    with pytest.raises(CommandError, match=r"EntAdd\(e\)\.setGain"):
        e.setGain(1.0, 2.0)
    with pytest.raises(CommandError, match=r"EntAdd\(e\)\.setGain"):
        e.setGain(gain=1.0)
    assert e.log == []
    assert isinstance(CommandError("x"), TypeError)


def test_command_errors_are_sotpy_errors():
    e = EntAdd("e")
    with pytest.raises(SotpyError):
        e.setSize(1.5)


def test_command_decorator_name_argument_names_the_command():
    class EntNamed(Entity):
        @command(name="print")
        def print_(self) -> int:
            """Print something."""
            return 1

    e = EntNamed("named")
    assert "print" in e.commands()
    assert e.getCommand("print")() == 1


def test_an_unresolvable_annotation_does_not_disable_the_other_checks():
    class LocalThing:
        pass

    class EntLocalAnn(Entity):
        @command
        def f(self, x: float, thing: LocalThing) -> float:
            """Uses a local class in an annotation."""
            return x

    e = EntLocalAnn("loc")
    with pytest.raises(CommandError, match=r"EntLocalAnn\(loc\)\.f.*'x'"):
        e.f("not a number", LocalThing())


class EntTyped(Entity):
    """Commands annotated with signal types."""

    @command
    def setV(self, v: VECTOR, w: Annotated[np.ndarray, VECTOR]) -> float:
        """Vector arguments."""
        return float(v.sum() + w.sum())


def test_signal_type_annotations_check_arguments():
    e = EntTyped("typed")
    assert e.setV([1, 2], [3]) == 6.0
    with pytest.raises(CommandError, match=r"EntTyped\(typed\)\.setV.*'v'"):
        e.setV([[1.0]], [1.0])
    with pytest.raises(CommandError, match=r"EntTyped\(typed\)\.setV.*'w'"):
        e.setV([1.0], [[1.0]])


def test_output_depending_on_an_unknown_signal_is_refused_at_class_definition():
    with pytest.raises(EntityError, match="nothere"):

        class EntBadDeps(Entity):
            @Output(DOUBLE, deps=("nothere",))
            def out(self, x):
                return x

    assert not factory.hasClass("EntBadDeps")


# -- attributes, signals added at runtime ---------------------------------------------------
def test_signals_are_attributes_and_tab_complete():
    e = EntAdd("e")
    names = dir(e)
    for n in ("a", "b", "out", "setGain", "help", "displaySignals"):
        assert n in names
    assert e.a is e.signal("a")
    assert e.hasSignal("out")
    assert [s.shortName for s in e.signals()] == ["a", "b", "out"]


def test_signal_added_at_runtime_becomes_an_attribute():
    e = EntAdd("e")
    e.a.value = 2
    calls = []

    def twice(a):
        calls.append(a)
        return 2 * a

    sig = e.addSignal(OutputSignal(e, "twice", DOUBLE, twice, [e.a]))
    assert e.twice is sig
    assert "twice" in dir(e)
    assert pool.getSignal("e.twice") is sig
    assert sig.name == "EntAdd(e)::output(double)::twice"
    assert e.twice.value == 4.0
    assert "EntAdd(e)::output(double)::twice (Type Fun)" in e.signalsDisplay()
    # it takes part in plugs like any other output
    f = EntAdd("f")
    plug(e.twice, f.a)
    assert f.out.value == 5.0
    e.a.value = 3  # same tick
    assert f.out.value == 7.0
    assert calls == [2.0, 3.0]


def test_non_identifier_signal_names_are_reachable_through_signal():
    e = EntAdd("e")
    sig = e.addSignal(InputSignal(e, "left-wrist", VECTOR, [0.0, 1.0]))
    assert e.signal("left-wrist") is sig
    assert pool.getSignal("e.left-wrist") is sig
    assert "left-wrist" not in dir(e)
    np.testing.assert_array_equal(e.signal("left-wrist").value, [0.0, 1.0])
    assert sig.name == "EntAdd(e)::input(vector)::left-wrist"


def test_duplicate_signal_name_is_refused():
    e = EntAdd("e")
    with pytest.raises(EntityError, match=r"EntAdd\(e\).*'a'"):
        e.addSignal(InputSignal(e, "a", DOUBLE))
    assert e.a.type is DOUBLE


def test_removeSignal_drops_the_attribute_and_unplugs_readers():
    e = EntAdd("e")
    e.a.value = 1
    sig = e.addSignal(OutputSignal(e, "extra", DOUBLE, lambda a: a, [e.a]))
    f = EntAdd("f")
    plug(sig, f.a)
    assert f.out.value == 2.0
    e.removeSignal("extra")
    assert not e.hasSignal("extra")
    assert "extra" not in dir(e)
    assert f.a.source is None


def test_assigning_to_a_signal_attribute_raises():
    e = EntAdd("e")
    e.a.value = 1
    a = e.a
    with pytest.raises(EntityError, match=r"EntAdd\(e\)\.a is a signal"):
        e.a = 5
    assert e.a is a
    assert e.a.value == 1.0
    e.addSignal(OutputSignal(e, "late", DOUBLE, lambda a: a, [e.a]))
    with pytest.raises(EntityError, match="late"):
        e.late = 3
    # other attributes can be set as usual
    e.note = "fine"
    assert e.note == "fine"


def test_unknown_attribute_names_the_signals_and_commands():
    e = EntAdd("e")
    with pytest.raises(SignalNotFoundError, match=r"EntAdd\(e\).*'nope'.*a, b, out.*setGain"):
        e.nope  # noqa: B018
    assert not hasattr(e, "nope")
    with pytest.raises(AttributeError):
        e.nope  # noqa: B018
    with pytest.raises(SignalNotFoundError, match=r"EntAdd\(e\).*'nope'.*a, b, out"):
        e.signal("nope")


def test_class_name_appears_in_repr_and_signal_names():
    e = EntAdd("e")
    assert repr(e) == "EntAdd('e')"
    assert e.out.name.startswith("EntAdd(e)::")
