"""Signals: typed, tick-stamped values that entities read and compute.

Semantics (dynamic-graph's, with its known defects fixed; see ``docs/graph.md``):

* An **output** signal is computed by a callback from the values of its dependencies
  (signals of its entity or of others), or holds a constant. Setting an output to a
  constant disables its callback; :meth:`OutputSignal.resetCallback` restores it. An
  output declared without a callback is a *state* signal that its entity writes (for
  example ``Device.state``).
* An **input** signal is plugged to an output, set to a constant (SoT's
  ``AUTOPLUGGED``), or unset. Setting a constant unplugs it.
* Every signal carries the tick ``time`` at which its value was last computed or
  written. An output is *outdated* at tick ``t`` when ``t >= time + period`` and either
  it is time-dependent, or a dependency is outdated, or a dependency was computed
  later than it. Reading an outdated signal recomputes it, so a value is computed at
  most once per tick.
* The dependencies are exactly the values the callback receives: there is no separate
  list that could disagree with the callback.
* Writing a constant at the current tick makes every dependant outdated at once (push
  invalidation), so a script that changes a gain and reads the control in the same tick
  sees the new gain.
* A plug that would close a same-tick cycle is refused with the cycle in the message;
  feedback goes through a state signal (a device) or a ``Delay`` entity.
* Reading an unset input raises :class:`~sotpy.errors.UnpluggedError` naming it.

Evaluation never recurses: the lazy pull walks the outdated part of the graph with an
explicit stack, and the tick loop runs a plan compiled once per topology change
(:mod:`sotpy.graph.plan`).
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Sequence
from typing import TYPE_CHECKING, Any

from ..errors import CycleError, PlugError, SignalTypeError, UnpluggedError
from .pool import pool
from .types import SignalType

if TYPE_CHECKING:
    from .entity import Entity

__all__ = ["InputSignal", "OutputSignal", "Signal", "checkPlugged", "plug"]

# Signal modes. A signal whose mode is not FUNCTION is a leaf of the evaluation: it
# holds its value in ``_value`` (CONSTANT), forwards to its source (PLUGGED), or has none
# (UNSET).
FUNCTION = 0
CONSTANT = 1
UNSET = 2
PLUGGED = 3

NEVER = -1  # ``time`` of a signal never computed nor written


class Signal:
    """Common part of input and output signals.

    Attributes:
        entity: the entity that owns the signal.
        shortName: the name within the entity (``state``, ``left-wrist``).
        type: the declared :class:`~sotpy.graph.types.SignalType`.
        doc: one line saying what the value is, with its unit.
    """

    __slots__ = (
        "_value",
        "_time",
        "_checked",
        "_invalid",
        "_mode",
        "_dependants",
        "entity",
        "shortName",
        "type",
        "doc",
        "__weakref__",
    )
    direction = "signal"

    def __init__(self, entity: Entity, shortName: str, type: SignalType, doc: str = "") -> None:
        self.entity = entity
        self.shortName = shortName
        self.type = type
        self.doc = doc
        self._value: Any = None
        self._time = NEVER
        self._checked = NEVER  # the value is known valid for every tick <= _checked
        self._invalid = NEVER  # tick of the last push invalidation
        self._mode = UNSET
        self._dependants: list[Signal] = []

    # -- identity ---------------------------------------------------------------------
    @property
    def name(self) -> str:
        """SoT's full name, ``Class(entity)::direction(type)::shortName``."""
        e = self.entity
        return f"{e.className}({e.name})::{self.direction}({self.type.name})::{self.shortName}"

    @property
    def path(self) -> str:
        """``entity.shortName``, the form :meth:`Pool.getSignal` takes."""
        return f"{self.entity.name}.{self.shortName}"

    def __repr__(self) -> str:
        return f"<{self.display()}>"

    # -- time -------------------------------------------------------------------------
    @property
    def time(self) -> int:
        """Tick at which the value was last computed or written (-1: never)."""
        return self._holder()._time

    # -- values -----------------------------------------------------------------------
    def __call__(self, t: int) -> Any:
        """The value at tick ``t``, recomputed first if outdated (``sig(t)``)."""
        return self.recompute(t)

    def recompute(self, t: int) -> Any:
        """The value at tick ``t``, recomputed first if outdated.

        Reading at a tick later than the clock moves the clock there.
        """
        if t > pool.time:
            pool.time = t
        return _read(self._holder(), t, self)

    @property
    def value(self) -> Any:
        """The value at the current tick (``pool.time``), recomputed first if outdated.

        Assigning sets the signal to a constant (see :meth:`setConstant`).
        """
        t = pool.time
        if t <= self._checked:  # up to date (a plugged input never is: it forwards)
            return self._value
        return _read(self._holder(), t, self)

    @value.setter
    def value(self, v: Any) -> None:
        self.setConstant(v)

    def setConstant(self, v: Any) -> None:  # pragma: no cover - overridden
        raise NotImplementedError

    def _convert(self, v: Any) -> Any:
        try:
            return self.type.convert(v)
        except (TypeError, ValueError) as exc:
            raise SignalTypeError(
                f"{self.name}: cannot set value: {exc} (signal type {self.type.name})"
            ) from None

    def _holder(self) -> Signal:
        """The signal that holds this signal's value (the source of a plugged input)."""
        return self

    # -- display ----------------------------------------------------------------------
    def _modeLabel(self) -> str:
        return "Cst"

    def display(self) -> str:
        """``Sig:<name> (Type Cst|Fun|Ref)`` plus the plug state of an input."""
        return f"Sig:{self.name} (Type {self._modeLabel()})"

    @property
    def dependencies(self) -> list[Signal]:
        """The signals this one reads in the same tick."""
        return []

    def displayDependencies(self, depth: int = -1) -> str:
        """An ASCII tree of what this signal reads, ``t=<time>`` on each line."""
        lines: list[str] = []
        # (signal, depth, prefix of its line, prefix for its children)
        stack: list[tuple[Signal, int, str, str]] = [(self, 0, "", "")]
        while stack:
            sig, level, head, indent = stack.pop()
            period = getattr(sig, "period", 1)
            tail = f" (/{period})" if period != 1 else ""
            lines.append(f"{head}<{sig.display()}> t={sig.time}{tail}")
            if depth >= 0 and level >= depth:
                continue
            children = sig.dependencies
            for i in reversed(range(len(children))):
                last = i == len(children) - 1
                stack.append(
                    (
                        children[i],
                        level + 1,
                        indent + ("`-- " if last else "|-- "),
                        indent + ("    " if last else "|   "),
                    )
                )
        return "\n".join(lines)


class OutputSignal(Signal):
    """A signal computed by a callback of its entity, or holding a constant.

    Attributes:
        period: recompute every ``period`` ticks at most (SoT's ``period``).
        timeDependent: recompute at every due tick even if no dependency changed (a
            clock, a trajectory, an integrator). Outputs without dependencies are
            time-dependent unless declared otherwise.
    """

    __slots__ = (
        "_fn",
        "_withTime",
        "_deps",
        "_srcs",
        "_volatile",
        "_callback",
        "period",
        "timeDependent",
    )
    direction = "output"

    def __init__(
        self,
        entity: Entity,
        shortName: str,
        type: SignalType,
        callback: Callable[..., Any] | None = None,
        dependencies: Sequence[Signal] = (),
        *,
        withTime: bool = False,
        timeDependent: bool | None = None,
        period: int = 1,
        doc: str = "",
    ) -> None:
        super().__init__(entity, shortName, type, doc)
        self._callback = callback
        self._fn = callback
        self._withTime = withTime
        self._deps: tuple[Signal, ...] = ()
        self._srcs: tuple[Signal, ...] = ()
        self._volatile = callback is None
        self.period = _check_period(self, period)
        self.timeDependent = (not dependencies) if timeDependent is None else timeDependent
        if callback is None:
            self._mode = CONSTANT
        else:
            self._mode = FUNCTION
            self._invalid = 0
        if dependencies:
            self.setDependencies(dependencies)

    # -- dependencies -----------------------------------------------------------------
    @property
    def dependencies(self) -> list[Signal]:
        """The signals whose values the callback receives, in order."""
        return list(self._deps) if self._mode == FUNCTION else []

    def setDependencies(self, signals: Iterable[Signal]) -> None:
        """Make the callback receive the values of ``signals`` (in this order).

        Entities whose inputs vary (a task's features, a solver's tasks) call this when
        they change. Refused, leaving the old dependencies, if it would close a cycle.
        """
        new = tuple(signals)
        for s in new:
            if not isinstance(s, Signal):
                raise PlugError(f"{self.name}: dependency {s!r} is not a signal")
        if self._mode == FUNCTION:
            for s in new:
                _refuse_cycle(s, self, f"making {self.name} depend on {s.name}")
        for s in self._deps:
            _remove_dependant(s, self)
        self._deps = new
        for s in new:
            s._dependants.append(self)
        self._resolve()
        pool.version += 1
        _invalidate(self)

    def _resolve(self) -> None:
        self._srcs = tuple(s._holder() for s in self._deps)

    # -- values -----------------------------------------------------------------------
    def setConstant(self, v: Any) -> None:
        """Hold the constant ``v`` from now on; the callback is disabled."""
        v = self._convert(v)
        if self._mode == FUNCTION:
            self._mode = CONSTANT
            pool.version += 1
        self._value = v
        self._time = self._checked = pool.time
        _invalidate_dependants(self)

    def resetCallback(self) -> None:
        """Compute the value with the entity's callback again (undo :meth:`setConstant`)."""
        if self._callback is None:
            raise PlugError(f"{self.name}: this output has no callback; its entity writes it")
        if self._mode != FUNCTION:
            for s in self._deps:
                _refuse_cycle(s, self, f"restoring the callback of {self.name}")
            self._mode = FUNCTION
            self._time = self._checked = min(self._time, pool.time - 1)
            self._invalid = pool.time
            pool.version += 1
            _invalidate_dependants(self)

    def setFunction(self, callback: Callable[..., Any], *, withTime: bool = False) -> None:
        """Replace the callback (it receives the dependencies' values, ``t`` first if
        ``withTime``)."""
        self._callback = callback
        self._withTime = withTime
        self._volatile = False
        if self._mode == FUNCTION:
            self._fn = callback
            pool.version += 1
            _invalidate(self)
        else:
            self._fn = callback
            self.resetCallback()

    def setReady(self) -> None:
        """Mark the value outdated now (its entity changed a parameter it reads)."""
        _invalidate(self)

    def setPeriod(self, period: int) -> None:
        """Recompute at most every ``period`` ticks."""
        self.period = _check_period(self, period)
        pool.version += 1

    def write(self, v: Any, t: int) -> None:
        """Store ``v`` as the value at tick ``t`` (an entity writing its state signal).

        No conversion: entities write values of the declared type. Dependants see the
        new stamp; if ``t`` is not after the clock, they are also invalidated at once.
        """
        self._value = v
        self._time = self._checked = t
        if t > pool.time:
            pool.time = t
        else:
            _invalidate_dependants(self)

    def _update(self, t: int) -> None:
        """Recompute at ``t`` if outdated (dependencies already brought to ``t``)."""
        tm = self._time
        srcs = self._srcs
        if self._invalid <= tm:  # not invalidated: apply the outdated rule
            due = tm + self.period
            if t < due:
                self._checked = due - 1
                return
            if not self.timeDependent:
                for s in srcs:
                    if s._time > tm:
                        break
                else:  # no dependency changed since the last computation
                    self._checked = t
                    return
        fn = self._fn
        n = len(srcs)
        if self._withTime:
            self._value = fn(t, *[s._value for s in srcs])
        elif n == 1:
            self._value = fn(srcs[0]._value)
        elif n == 2:
            self._value = fn(srcs[0]._value, srcs[1]._value)
        else:
            self._value = fn(*[s._value for s in srcs])
        self._time = t
        self._checked = t + self.period - 1

    def _modeLabel(self) -> str:
        return "Fun" if self._mode == FUNCTION else "Cst"


class InputSignal(Signal):
    """A signal an entity reads: plugged to an output, a constant, or unset."""

    __slots__ = ("_source", "_default")
    direction = "input"

    def __init__(
        self, entity: Entity, shortName: str, type: SignalType, default: Any = None, doc: str = ""
    ) -> None:
        super().__init__(entity, shortName, type, doc)
        self._source: OutputSignal | None = None
        self._default = default
        if default is not None:
            self._value = self._convert(default)
            self._mode = CONSTANT
            self._time = self._checked = pool.time

    @property
    def source(self) -> OutputSignal | None:
        """The output this input is plugged to, if any."""
        return self._source

    @property
    def isPlugged(self) -> bool:
        """Whether the input has a value (plugged, or set to a constant)."""
        return self._mode != UNSET

    @property
    def dependencies(self) -> list[Signal]:
        return [self._source] if self._source is not None else []

    def _holder(self) -> Signal:
        return self._source if self._source is not None else self

    def setConstant(self, v: Any) -> None:
        """Unplug, and hold the constant ``v`` (SoT's AUTOPLUGGED)."""
        v = self._convert(v)
        was = self._mode
        if self._source is not None:
            _remove_dependant(self._source, self)
            self._source = None
        self._value = v
        self._mode = CONSTANT
        self._time = self._checked = pool.time
        if was != CONSTANT:
            self._retarget()
        _invalidate_dependants(self)

    def plug(self, source: OutputSignal) -> None:
        """Follow ``source`` from now on (same as ``plug(source, self)``)."""
        plug(source, self)

    def unplug(self) -> None:
        """Leave the input unset (its default constant, if declared, is restored)."""
        if self._source is not None:
            _remove_dependant(self._source, self)
            self._source = None
        if self._default is not None:
            self._value = self._convert(self._default)
            self._mode = CONSTANT
        else:
            self._value = None
            self._mode = UNSET
        self._time = self._checked = pool.time
        self._retarget()
        _invalidate_dependants(self)

    def _retarget(self) -> None:
        """Re-resolve the outputs reading this input after a plug change."""
        for d in self._dependants:
            if isinstance(d, OutputSignal):
                d._resolve()
        pool.version += 1

    def _modeLabel(self) -> str:
        return "Ref" if self._mode == PLUGGED else "Cst"

    def display(self) -> str:
        base = super().display()
        if self._mode == PLUGGED:
            return f"{base} -->-- PLUGGED <- {self._source.name}"  # type: ignore[union-attr]
        if self._mode == CONSTANT:
            return f"{base} AUTOPLUGGED"
        return f"{base} UNPLUGGED"


def plug(source: Signal, target: Signal) -> None:
    """Plug the output ``source`` into the input ``target`` (SoT's ``plug(out, in)``).

    Refused with an exception, leaving both signals as they were, when ``source`` is not
    an output, ``target`` is not an input, the types differ (an ``any`` input takes
    every type), or the plug would close a same-tick cycle.
    """
    if not isinstance(target, InputSignal):
        kind = "an output" if isinstance(target, OutputSignal) else type(target).__name__
        raise PlugError(
            f"cannot plug into {getattr(target, 'name', target)!r}: it is {kind}; "
            "the second argument of plug must be an input signal"
        )
    if not isinstance(source, OutputSignal):
        kind = "an input" if isinstance(source, InputSignal) else type(source).__name__
        raise PlugError(
            f"cannot plug {getattr(source, 'name', source)!r} into {target.name}: the source is "
            f"{kind}; the first argument of plug must be an output signal"
        )
    if not target.type.accepts_output(source.type):
        raise SignalTypeError(
            f"cannot plug {source.name} into {target.name}: type mismatch, "
            f"the input expects {target.type.name}, the output gives {source.type.name}"
        )
    if target._source is source:
        return
    _refuse_cycle(source, target, f"plugging {source.name} into {target.name}")
    if target._source is not None:
        _remove_dependant(target._source, target)
    target._source = source
    target._mode = PLUGGED
    target._value = None
    source._dependants.append(target)
    target._retarget()
    _invalidate_dependants(target)


def checkPlugged(signal: Signal) -> list[str]:
    """Full names of every unset input that ``signal`` depends on (empty: all plugged).

    Follows plugs and callback dependencies transitively, without recursion.
    """
    missing: list[str] = []
    seen = {id(signal)}
    stack = [signal]
    while stack:
        s = stack.pop()
        if isinstance(s, InputSignal) and s._mode == UNSET:
            missing.append(s.name)
        for d in s.dependencies:
            if id(d) not in seen:
                seen.add(id(d))
                stack.append(d)
    return sorted(missing)


# -- evaluation -------------------------------------------------------------------------
def _read(h: Signal, t: int, asked: Signal) -> Any:
    """Value of holder ``h`` at ``t``, pulling outdated dependencies first."""
    if t <= h._checked:
        return h._value
    mode = h._mode
    if mode == FUNCTION:
        _pull(h, t)  # type: ignore[arg-type]
        return h._value
    if mode == UNSET:
        raise _unplugged([h], asked)
    return h._value


_RECURSION_DEPTH = 100  # recursive pull up to this depth, then an explicit stack


def _pull(node: OutputSignal, t: int, depth: int = 0) -> None:
    """Bring ``node`` up to date at ``t``: dependencies first, then ``node``.

    Recursive while shallow (the cheapest walk in CPython), it switches to an explicit
    stack below :data:`_RECURSION_DEPTH`, so a graph of any depth is evaluated without
    approaching the interpreter's recursion limit. A dependency that is up to date at
    ``t`` (``t <= _checked``) is not visited, so each signal is walked once.
    """
    for d in node._srcs:
        if t > d._checked:
            m = d._mode
            if m == FUNCTION:
                if depth < _RECURSION_DEPTH:
                    _pull(d, t, depth + 1)  # type: ignore[arg-type]
                else:
                    _pull_iterative(d, t)  # type: ignore[arg-type]
            elif m == UNSET:
                raise _unplugged([d], node)
    node._update(t)


def _pull_iterative(root: OutputSignal, t: int) -> None:
    """:func:`_pull` with an explicit stack: post-order walk of the outdated upstream."""
    stack = [(root, iter(root._srcs))]
    push = stack.append
    while stack:
        node, it = stack[-1]
        for d in it:
            if t > d._checked:
                m = d._mode
                if m == FUNCTION:
                    push((d, iter(d._srcs)))  # type: ignore[attr-defined]
                    break
                if m == UNSET:
                    raise _unplugged([d], node)
        else:
            stack.pop()
            node._update(t)


def _unplugged(inputs: list[Signal], asked: Signal) -> UnpluggedError:
    names = [s.name for s in inputs]
    what = ", ".join(names)
    via = "" if asked in inputs else f" (needed to compute {asked.name})"
    return UnpluggedError(
        f"input {what} is read but neither plugged nor set to a constant{via}; "
        "plug it to an output or set its value",
        names,
    )


def _invalidate(sig: OutputSignal) -> None:
    """Make ``sig`` and everything downstream outdated at the current tick."""
    if sig._mode == FUNCTION:
        now = pool.time
        sig._invalid = now
        if sig._time >= now:
            sig._time = now - 1
        if sig._checked >= now:
            sig._checked = now - 1
    _invalidate_dependants(sig)


def _invalidate_dependants(sig: Signal) -> None:
    """Push invalidation: every output reading ``sig`` (transitively) becomes outdated
    at the current tick. Stops at outputs already outdated (their dependants are)."""
    now = pool.time
    stack = list(sig._dependants)
    while stack:
        s = stack.pop()
        if isinstance(s, OutputSignal):
            if s._mode != FUNCTION or (s._invalid > s._time and s._checked < now):
                continue
            s._invalid = now
            if s._time >= now:
                s._time = now - 1
            if s._checked >= now:
                s._checked = now - 1
        stack.extend(s._dependants)


def _remove_dependant(sig: Signal, dependant: Signal) -> None:
    deps = sig._dependants
    for i, d in enumerate(deps):
        if d is dependant:
            del deps[i]
            return


def _refuse_cycle(source: Signal, reader: Signal, action: str) -> None:
    """Raise CycleError if ``reader`` reading ``source`` would close a same-tick cycle,
    that is if ``source`` already depends on ``reader``."""
    if source is reader:
        raise CycleError(f"{action} would make {reader.name} read itself", [reader.name] * 2)
    parent: dict[int, Signal | None] = {id(source): None}
    stack = [source]
    while stack:
        s = stack.pop()
        for d in s.dependencies if not isinstance(s, OutputSignal) or s._mode == FUNCTION else ():
            if id(d) in parent:
                continue
            parent[id(d)] = s
            if d is reader:
                chain = [d]
                p: Signal | None = s
                while p is not None:
                    chain.append(p)
                    p = parent[id(p)]
                # chain lists reader, the signal reading it, ..., source: reversed, each
                # element reads the next, and the new edge makes reader read source.
                names = [x.name for x in reversed(chain)]
                cycle = [*names, names[0]]
                raise CycleError(
                    f"{action} would close a same-tick cycle: "
                    + " -> ".join(cycle)
                    + " (each reads the next; break it with a Delay entity or a state signal)",
                    cycle,
                )
            stack.append(d)


def _check_period(sig: Signal, period: Any) -> int:
    if isinstance(period, bool) or not isinstance(period, int) or period < 1:
        raise SignalTypeError(f"{sig.name}: period must be a positive integer, got {period!r}")
    return period
