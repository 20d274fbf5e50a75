"""sot-pattern-generator's ``Selector``: outputs that copy one of several inputs, the
same index choosing in every family.

A ``Selector`` holds ``M`` *families* of signals, all chosen by one input ``selec``.
A family called ``ref`` with ``N`` entries has the inputs ``ref0 .. ref{N-1}`` and the
output ``ref``::

    ref(t) = ref{k}(t),   k = selec(t)

Building one by commands (upstream's ``reset`` / ``create``)::

    sel = Selector("sel")
    sel.reset(2, 1)                    # N = 2 entries per family, M = 1 family
    sel.create("vector", "ref", 0)     # family 0: inputs ref0, ref1; output ref
    plug(robot.dynamic.com, sel.ref0)
    plug(pg.comref, sel.ref1)
    plug(pg.inprocess, sel.selec)      # a bool: False selects ref0, True ref1

or by the meta constructor of sot-pattern-generator's Python package, one list
``[type, name, input0, input1, ...]`` per family, which does the same::

    sel = Selector("sel", ["vector", "ref", robot.dynamic.com, pg.comref])

**Types.** ``create``'s type is one of upstream's names: ``vector`` (signals of type
``vector``), ``matrix`` (``matrix``) or ``matrixHomo`` (``SE3``: ``pinocchio.SE3``
values). ``selec`` has the type :data:`SELECTION` (named ``index``): an int, or a bool
(False is 0, True is 1), so that it can be plugged to an ``int`` output (a support-foot
index) or to a ``bool`` one (a pattern generator's ``inprocess``). sotpy's ``int``
inputs refuse ``bool`` outputs; ``SwitchVector`` has two inputs for this
(``selection``, ``boolSelection``), where upstream's ``Selector`` has one.

**Only the selected input is computed.** The output reads ``selec`` and the selected
entry only: its dependencies are ``[selec, ref{k}]`` for the current ``k``, so a
lazy read, a compiled plan, the outdated rule, push invalidation, cycle checks and
``displayDependencies`` all see exactly those two. When ``selec`` is set to a constant
the dependencies follow at once. When ``selec`` is plugged, the new ``k`` is known only
once ``selec`` has been computed: at a tick where it changes, the output's computation
moves its dependencies to the new entry and reads it at that tick (the plans recompile
at the next tick). At that one tick the previously selected entry has already been
brought up to date, because it was the dependency when the read began; at every other
tick an unselected entry is not computed. (The graph computes every dependency of an
output before its callback; an output whose dependencies depend on a value it reads
is beyond that model, and this is the nearest it allows.)

**Errors** (exceptions of :mod:`sotpy.errors`, naming the entity and the signal or the
command; nothing changes when one is raised): ``selec`` outside ``0 .. N-1`` when an
output is read (``SignalTypeError``); an unknown type, a family index outside
``0 .. M-1``, a name already used, a family created again with another type
(``CommandError``); a meta-constructor list too short, of unequal length, or holding
something other than a signal (``CommandError``); a plug of the wrong type
(``SignalTypeError``, from ``plug``); a plug into an entry that would close a same-tick
cycle through the output if that entry were selected (``CycleError``; the entry is
left unplugged, as ``SwitchVector`` leaves its selector).
"""

from __future__ import annotations

import contextlib
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np
import pinocchio as pin

from ..dynamics.types import SE3
from ..errors import CommandError, CycleError, SignalTypeError
from ..graph import BOOL, INT, MATRIX, VECTOR, Entity, command, plug
from ..graph.signal import CONSTANT, InputSignal, OutputSignal, Signal
from ..graph.types import SignalType
from ._util import who

__all__ = ["SELECTION", "Selector"]


class _SelectionType(SignalType):
    """The type of ``selec``: an int >= 0, or a bool (False 0, True 1); it accepts
    plugs from ``int`` and ``bool`` outputs."""

    __slots__ = ()

    def accepts_output(self, other: SignalType) -> bool:
        return other is self or other is INT or other is BOOL


def _as_selection(v: Any) -> int:
    if isinstance(v, (bool, np.bool_)):
        return int(bool(v))
    if not isinstance(v, (int, np.integer)):
        raise TypeError(f"expected an int >= 0 or a bool, got {type(v).__name__} {v!r}")
    if v < 0:
        raise ValueError(f"expected an int >= 0 (an entry index) or a bool, got {int(v)}")
    return int(v)


#: Signal type of ``Selector.selec``: an entry index, from an int or a bool.
SELECTION = _SelectionType("index", _as_selection, lambda v: np.array([float(v)]))


def _copy_array(v: np.ndarray) -> np.ndarray:
    return np.array(v, dtype=float)


def _copy_se3(v: pin.SE3) -> pin.SE3:
    return v.copy()


#: upstream's type names, in upstream's order: (signal type, copy of a value)
_TYPES: dict[str, tuple[SignalType, Callable[[Any], Any]]] = {
    "vector": (VECTOR, _copy_array),
    "matrix": (MATRIX, _copy_array),
    "matrixHomo": (SE3, _copy_se3),
}


class _SelecInput(InputSignal):
    """``selec``: when it gets a constant, the outputs move their dependencies to the
    entry it selects at once (when plugged, they do at their next computation)."""

    __slots__ = ()

    def setConstant(self, v: Any) -> None:
        super().setConstant(v)
        self.entity._followSelec(self._value)  # type: ignore[attr-defined]


class _EntryInput(InputSignal):
    """An entry ``<name><i>`` of a family: a plug into it is refused (left unplugged,
    ``CycleError``) if it would close a same-tick cycle when the entry is selected."""

    __slots__ = ("_family",)

    def __init__(self, entity: Selector, family: _Family, index: int, type: SignalType) -> None:
        super().__init__(
            entity, f"{family.name}{index}", type, None, f"entry {index} of {family.name}"
        )
        self._family = family

    def modeChanged(self) -> None:
        src = self._source
        if src is None:
            return
        path = _path_to(src, self._family.output)
        if path is not None:
            self.unplug()
            names = [self.name, *(s.name for s in path), self.name]
            raise CycleError(
                f"plugging {src.name} into {self.name} would close a same-tick cycle when "
                f"{self.name} is selected: {' -> '.join(names)}; the input is left unplugged",
                names,
            )


def _path_to(start: Signal, target: Signal) -> list[Signal] | None:
    """The signals from ``start`` to ``target`` following what each reads in the same
    tick, a Selector's output reading every entry of its family; None if there is no
    such path."""
    parent: dict[int, Signal | None] = {id(start): None}
    stack = [start]
    while stack:
        s = stack.pop()
        if s is target:
            path = [s]
            p = parent[id(s)]
            while p is not None:
                path.append(p)
                p = parent[id(p)]
            path.reverse()
            return path
        reads = list(s.dependencies)
        family = getattr(s, "_selectorFamily", None)
        if family is not None:
            reads.extend(family.inputs)
        for d in reads:
            if id(d) not in parent:
                parent[id(d)] = s
                stack.append(d)
    return None


class _FamilyOutput(OutputSignal):
    """The output of a family; ``_selectorFamily`` lets the cycle check of the entries
    see every entry as a possible dependency."""

    __slots__ = ("_selectorFamily",)


class _Family:
    """One family: its name, type, slot, entries and output, and the entry the output
    currently depends on (``route``; None without entries)."""

    __slots__ = ("copy", "inputs", "name", "output", "route", "slot", "type", "typeName")

    def __init__(self, name: str, typeName: str, slot: int) -> None:
        self.name = name
        self.typeName = typeName
        self.type, self.copy = _TYPES[typeName]
        self.slot = slot
        self.inputs: list[_EntryInput] = []
        self.output: _FamilyOutput = None  # type: ignore[assignment]
        self.route: int | None = None


class Selector(Entity):
    """Outputs copying one of several inputs: ``<name> = <name>{selec}`` for every
    family (sot-pattern-generator's ``Selector``).

    ``Selector(name)`` has only ``selec``; ``reset(nbEntries, nbSignals)`` then
    ``create(type, name, sigId)`` add the families. ``Selector(name, [type, outName,
    in0, in1, ...], ...)`` (the meta constructor of sot-pattern-generator's Python
    package) does it for each list and plugs ``in_k`` into ``outName<k>``. See the
    module doc for the semantics and the errors.
    """

    def __init__(self, name: str, *families: Sequence[Any]) -> None:
        self._families: list[_Family | None] = []
        self._nbEntries = 0
        self.addSignal(
            _SelecInput(
                self,
                "selec",
                SELECTION,
                None,
                "k: index of the selected entry, an int >= 0 or a bool (False 0, True 1)",
            )
        )
        if families:
            self._build(families)

    # -- the meta constructor -----------------------------------------------------------
    def _build(self, families: Sequence[Sequence[Any]]) -> None:
        where = f"{self.className}({self.name})"
        usage = "expected lists [type, outName, input0, input1, ...] with at least one input"
        n: int | None = None
        for i, spec in enumerate(families):
            if not isinstance(spec, (list, tuple)):
                raise CommandError(f"{where}: argument {i + 1}: {usage}, got {spec!r}")
            if len(spec) < 3:
                raise CommandError(
                    f"{where}: argument {i + 1} {list(spec)!r} is too short: {usage}"
                )
            if not isinstance(spec[0], str) or not isinstance(spec[1], str):
                raise CommandError(
                    f"{where}: argument {i + 1}: {usage}; the type and outName must be "
                    f"strings, got {spec[0]!r} and {spec[1]!r}"
                )
            if n is not None and len(spec) - 2 != n:
                raise CommandError(
                    f"{where}: argument {i + 1} has {len(spec) - 2} inputs and argument 1 "
                    f"has {n}: every family has the same number of entries"
                )
            n = len(spec) - 2
            for j, sig in enumerate(spec[2:]):
                if not isinstance(sig, (OutputSignal, InputSignal)):
                    raise CommandError(
                        f"{where}: argument {i + 1} ({spec[1]!r}), input {j}: expected a "
                        f"signal to plug into {spec[1]}{j}, got {sig!r}"
                    )
        self.reset(n or 0, len(families))
        # (a failure below leaves no entity: the pool does not register it)
        for i, spec in enumerate(families):
            self.create(spec[0], spec[1], i)
            for j, sig in enumerate(spec[2:]):
                plug(sig, self.signal(f"{spec[1]}{j}"))

    # -- commands -------------------------------------------------------------------------
    @command
    def reset(self, nbEntries: int, nbSignals: int) -> None:
        """Remove every family; then ``create`` may make ``nbSignals`` families of
        ``nbEntries`` inputs each (upstream's ``reset(N, M)``).

        Refused (``CommandError``, nothing removed) while a family's output is read by
        another entity: unplug its readers first."""
        if nbEntries < 0 or nbSignals < 0:
            raise CommandError(
                f"{who(self, 'reset')}: expected nbEntries >= 0 and nbSignals >= 0, got "
                f"{nbEntries} and {nbSignals}"
            )
        users = [
            f"{d.name} reads {sig.path}"
            for fam in self._families
            if fam is not None
            for sig in (fam.output, *fam.inputs)
            for d in sig._dependants
            if d.entity is not self
        ]
        if users:
            raise CommandError(
                f"{who(self, 'reset')}: the families are still used: {'; '.join(users)}; "
                "nothing was reset: unplug them first"
            )
        for fam in self._families:
            if fam is not None:
                self.removeSignal(fam.name)
                for inp in fam.inputs:
                    self.removeSignal(inp.shortName)
        self._nbEntries = nbEntries
        self._families = [None] * nbSignals

    @command
    def create(self, type: str, signalName: str, sigId: int = -1) -> None:
        """Create family ``sigId`` (0 .. nbSignals-1; -1: the first free one): the inputs
        ``<signalName>0 .. <signalName>{nbEntries-1}`` of ``type`` (``vector``,
        ``matrix``, ``matrixHomo``) and the output ``<signalName>`` copying the one
        ``selec`` selects.

        Creating a family again with the same type and slot does nothing; with another
        type or slot, or in a slot another family holds, it is refused (``reset`` starts
        over)."""
        if type not in _TYPES:
            raise CommandError(
                f"{who(self, 'create')}: unknown type {type!r}; known types: {', '.join(_TYPES)}"
            )
        if not signalName or "." in signalName or signalName.strip() != signalName:
            raise CommandError(
                f"{who(self, 'create')}: expected a signal name without dots or surrounding "
                f"spaces, got {signalName!r}"
            )
        m = len(self._families)
        for fam in self._families:
            if fam is not None and fam.name == signalName:
                if fam.typeName == type and sigId in (-1, fam.slot):
                    return
                raise CommandError(
                    f"{who(self, 'create')}: family {signalName!r} already exists with type "
                    f"{fam.typeName!r} in slot {fam.slot}; asked type {type!r} in slot "
                    f"{sigId} (reset(nbEntries, nbSignals) starts over)"
                )
        if sigId == -1:
            free = [i for i, fam in enumerate(self._families) if fam is None]
            if not free:
                raise CommandError(
                    f"{who(self, 'create')}: no free family slot (nbSignals = {m}; "
                    "reset(nbEntries, nbSignals) sets it)"
                )
            sigId = free[0]
        elif not 0 <= sigId < m:
            raise CommandError(
                f"{who(self, 'create')}: expected a family index sigId in 0 .. {m - 1} or -1 "
                f"(nbSignals = {m}, set by reset(nbEntries, nbSignals)), got {sigId}"
            )
        held = self._families[sigId]
        if held is not None:
            raise CommandError(
                f"{who(self, 'create')}: slot {sigId} already holds family {held.name!r}; "
                "reset(nbEntries, nbSignals) starts over"
            )
        names = [signalName, *(f"{signalName}{i}" for i in range(self._nbEntries))]
        taken = [n for n in names if self.hasSignal(n)]
        if taken:
            raise CommandError(
                f"{who(self, 'create')}: family {signalName!r} needs the signals "
                f"{', '.join(names)}, and {', '.join(taken)} already exist"
            )
        fam = _Family(signalName, type, sigId)
        fam.inputs = [_EntryInput(self, fam, i, fam.type) for i in range(self._nbEntries)]
        out = _FamilyOutput(
            self,
            signalName,
            fam.type,
            lambda t, k, *value: self._compute(fam, t, k, value),
            withTime=True,
            timeDependent=False,
            doc=f"{signalName}{{selec}}: a copy of the selected entry",
        )
        out._selectorFamily = fam
        fam.output = out
        for inp in fam.inputs:
            self.addSignal(inp)
        self.addSignal(out)
        self._families[sigId] = fam
        k = self.selec._value if self.selec._mode == CONSTANT else 0
        self._route(fam, k if k < self._nbEntries else 0)

    @command
    def getTypeList(self) -> str:
        """The types ``create`` accepts, in upstream's layout."""
        return "Types available:\n" + "".join(f"  - {t}\n" for t in _TYPES)

    # -- introspection ----------------------------------------------------------------------
    @property
    def nbEntries(self) -> int:
        """Inputs per family (``reset``'s first argument)."""
        return self._nbEntries

    @property
    def nbSignals(self) -> int:
        """Number of family slots (``reset``'s second argument)."""
        return len(self._families)

    def families(self) -> list[tuple[str, str]]:
        """``(name, type)`` of each created family, by slot."""
        return [(f.name, f.typeName) for f in self._families if f is not None]

    # -- evaluation -------------------------------------------------------------------------
    def _route(self, fam: _Family, k: int) -> None:
        """Make ``fam``'s output depend on ``selec`` and entry ``k`` (if it exists)."""
        if not fam.inputs:  # no entry: reading raises (out of range)
            fam.output.setDependencies([self.selec])
            return
        fam.output.setDependencies([self.selec, fam.inputs[k]])
        fam.route = k

    def _followSelec(self, k: int) -> None:
        """``selec`` got the constant ``k``: route every family to entry ``k`` now (an
        index out of range is reported when an output is read)."""
        if k >= self._nbEntries:
            return
        for fam in self._families:
            if fam is not None and fam.route != k:
                # an entry closing a cycle: the read that needs it reports it
                with contextlib.suppress(CycleError):
                    self._route(fam, k)

    def _compute(self, fam: _Family, t: int, k: int, value: tuple[Any, ...]) -> Any:
        n = self._nbEntries
        idx = int(k)
        if not 0 <= idx < n:
            expected = (
                f"expected 0 .. {n - 1} (entries {fam.name}0 .. {fam.name}{n - 1})"
                if n
                else "the family has no entries"
            )
            raise SignalTypeError(
                f"{self.selec.name}: selection {k!r} is out of range for {fam.output.name}: "
                f"{expected}; reset(nbEntries, nbSignals) sets the number of entries"
            )
        if idx != fam.route:  # selec, plugged, changed at t: read the new entry at t
            self._route(fam, idx)
            return fam.copy(fam.inputs[idx](t))
        return fam.copy(value[0])
