"""Signals: typed, tick-stamped values that entities read and compute.

Semantics (dynamic-graph's, with its known defects fixed; see ``docs/graph.md``):

* An **output** signal is computed by a callback from the values of its dependencies
  (signals of its entity or of others), or holds a constant. Setting an output to a
  constant disables its callback; :meth:`OutputSignal.resetCallback` restores it. An
  output declared without a callback is a *state* signal that its entity writes (for
  example ``Device.state``).
* An **input** signal is plugged to an output, set to a constant (SoT's
  ``AUTOPLUGGED``), or unset. Setting a constant unplugs it. An input may also be
  plugged to another input (dynamic-graph allows it): it then follows whatever that
  input holds or is plugged to, now and after it changes.
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
# ``_invalid`` of an output whose next read must recompute it even before its period
# elapsed (its callback, dependencies or period changed); cleared by the computation.
FORCE = 1 << 62


class Signal:
    """Common part of input and output signals.

    Attributes:
        entity: the entity that owns the signal.
        shortName: the name within the entity (``state``, ``left-wrist``).
        type: the declared :class:`~sotpy.graph.types.SignalType`.
        doc: one line saying what the value is, with its unit.
    """

    __slots__ = (
        "__weakref__",
        "_checked",
        "_dependants",
        "_fusedReaders",
        "_invalid",
        "_mode",
        "_time",
        "_value",
        "doc",
        "entity",
        "shortName",
        "type",
    )
    direction = "signal"

    def __init__(self, entity: Entity, shortName: str, type: SignalType, doc: str = "") -> None:
        self.entity = entity
        self.shortName = shortName
        self.type = type
        self.doc = doc
        self._value: Any = None
        self._time = NEVER
        # The value is known valid for every tick <= _checked (the reads' fast path).
        self._checked = NEVER
        # Tick of the last invalidation; the signal is invalidated ("dirty") while
        # _invalid > _checked, which a computation clears by moving _checked forward.
        self._invalid = NEVER
        self._mode = UNSET
        self._dependants: list[Signal] = []
        # outputs a compiled plan computes from this signal by a fused step (see
        # OutputSignal.setPlanFusion): invalidation reaches them directly
        self._fusedReaders: tuple[OutputSignal, ...] = ()

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

    def getName(self) -> str:
        """The full name (dynamic-graph-python's ``getName()``, as :attr:`name`)."""
        return self.name

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
        """Hold the constant ``v`` (converted to the signal's type); what else happens
        depends on the kind of signal: see the input's and the output's."""
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


#: see :meth:`OutputSignal.setPlanFusion`
_FusionHook = Callable[[], "tuple[tuple[Signal, ...], Callable[..., Any]] | None"]


class OutputSignal(Signal):
    """A signal computed by a callback of its entity, or holding a constant.

    Attributes:
        period: recompute every ``period`` ticks at most (SoT's ``period``).
        timeDependent: recompute at every due tick even if no dependency changed (a
            clock, a trajectory, an integrator). Outputs without dependencies are
            time-dependent unless declared otherwise.
    """

    __slots__ = (
        "_callback",
        "_deps",
        "_fn",
        "_fusion",
        "_srcs",
        "_volatile",
        "_withTime",
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
        self._fusion: Callable[[], tuple[tuple[Signal, ...], Callable[..., Any]] | None] | None = (
            None
        )
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
        if new:
            _refuse_removed((self, *new), f"{self.name}: cannot set its dependencies")
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
        _invalidate(self, force=True)

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
            pool.version += 1
            _invalidate(self, force=True)

    def setFunction(self, callback: Callable[..., Any], *, withTime: bool = False) -> None:
        """Replace the callback (it receives the dependencies' values, ``t`` first if
        ``withTime``) and compute with it from the next read on.

        On an output holding a constant this also restores computing; refused, leaving
        the old callback and the constant, if that would close a cycle.
        """
        if self._mode != FUNCTION:
            for s in self._deps:
                _refuse_cycle(s, self, f"restoring the callback of {self.name}")
        self._callback = self._fn = callback
        self._withTime = withTime
        self._volatile = False
        self._mode = FUNCTION
        pool.version += 1
        _invalidate(self, force=True)

    def setPlanFusion(self, hook: _FusionHook | None) -> None:
        """Let compiled plans evaluate this output in one step over other signals.

        ``hook()`` is called each time a :class:`~sotpy.graph.Plan` that needs this
        output compiles (after any change of topology). It returns ``None`` (the plan
        runs the callback over the dependencies, as usual) or ``(sources, fn)``: the
        plan brings ``sources`` up to date instead of the dependencies and stores
        ``fn(*values of sources)`` as this output's value (a plugged input stands for
        its source). ``fn`` must give the value the callback would give at the same
        tick, reading nothing but ``sources``: the entity vouches for it (e.g. the SOT
        evaluating its tasks' features straight into its solver's rows, instead of one
        plan step per feature and task signal). The dependencies, the lazy pull from
        scripts and the shell, ``displayDependencies`` and ``writeGraph`` are
        unchanged; a signal the fused step skips is still computed, by its callback,
        when something reads it.
        """
        self._fusion = hook
        pool.version += 1

    def setReady(self) -> None:
        """Recompute at the next read, even before the period elapsed (its entity
        changed a parameter the callback reads)."""
        _invalidate(self, force=True)

    def setPeriod(self, period: int) -> None:
        """Recompute at most every ``period`` ticks, from now on."""
        self.period = _check_period(self, period)
        if self._mode == FUNCTION and self._time != NEVER:
            self._checked = min(self._checked, self._time + self.period - 1)
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

    @staticmethod
    def writeMany(values: Iterable[tuple[OutputSignal, Any]], t: int) -> None:
        """:meth:`write` of several ``(signal, value)`` pairs at the same tick ``t`` (a
        device's state and velocity): as many writes in a row, with one look at the
        clock. When ``t`` is after the clock, nothing was evaluated at ``t`` yet and
        the dependants see the new stamps; otherwise each signal's dependants are
        invalidated at once."""
        pairs = tuple(values)
        for sig, v in pairs:
            sig._value = v
            sig._time = sig._checked = t
        if t > pool.time:
            pool.time = t
        else:
            for sig, _ in pairs:
                _invalidate_dependants(sig)

    def _update(self, t: int) -> None:
        """Recompute at ``t`` if outdated (dependencies already brought to ``t``)."""
        tm = self._time
        period = self.period
        srcs = self._srcs
        if self._invalid <= self._checked:  # not invalidated: the outdated rule
            due = tm + period
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
        elif period > 1 and tm != NEVER and t < tm + period and self._invalid != FORCE:
            # invalidated before its period elapsed: recompute at the due tick, staying
            # invalidated until then (_invalid > _checked)
            self._invalid = tm + period
            self._checked = tm + period - 1
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
        self._checked = t + period - 1
        if self._invalid == FORCE:
            self._invalid = t

    def _modeLabel(self) -> str:
        return "Fun" if self._mode == FUNCTION else "Cst"


class InputSignal(Signal):
    """A signal an entity reads: plugged to an output, a constant, or unset."""

    __slots__ = ("_default", "_source")
    direction = "input"

    def __init__(
        self, entity: Entity, shortName: str, type: SignalType, default: Any = None, doc: str = ""
    ) -> None:
        super().__init__(entity, shortName, type, doc)
        self._source: Signal | None = None  # an output, or an input it follows
        self._default = default
        if default is not None:
            self._value = self._convert(default)
            self._mode = CONSTANT
            self._time = self._checked = pool.time

    @property
    def source(self) -> Signal | None:
        """The signal this input is plugged to (an output, or an input it follows), if
        any."""
        return self._source

    @property
    def isPlugged(self) -> bool:
        """Whether the input has a value (plugged, or set to a constant)."""
        return self._mode != UNSET

    @property
    def dependencies(self) -> list[Signal]:
        return [self._source] if self._source is not None else []

    def _holder(self) -> Signal:
        src = self._source
        return self if src is None else src._holder()

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

    def setDefault(self, value: Any) -> None:
        """Hold ``value`` when not plugged (now, if unset, and after :meth:`unplug`).

        For defaults that depend on the entity (a zero vector of the robot's size).
        """
        v = self._convert(value)
        self._default = v
        if self._mode == UNSET:
            self.setConstant(v)

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
        if self._mode == UNSET:
            self._checked = NEVER  # never up to date: reading it must raise
        self._retarget()
        _invalidate_dependants(self)

    def _retarget(self) -> None:
        """Re-resolve the outputs reading this input after a plug change (and those
        reading the inputs that follow it)."""
        for d in self._dependants:
            if isinstance(d, OutputSignal):
                d._resolve()
            elif isinstance(d, InputSignal):
                d._retarget()
        pool.version += 1
        self.modeChanged()

    def modeChanged(self) -> None:
        """Called after the input is plugged, unplugged or gets its first constant (its
        source changed). Does nothing; a subclass overrides it to react, e.g. an entity
        whose output reads one input or another depending on which is set."""

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

    ``source`` may also be an input: ``target`` then follows it, holding what it holds
    (its constant, or the output it is plugged to, as it changes); reading ``target``
    while ``source`` is unset raises naming ``source``.

    Refused with an exception, leaving both signals as they were, when ``source`` is not
    a signal, ``target`` is not an input, the types differ (an ``any`` input takes
    every type), or the plug would close a same-tick cycle.
    """
    if not isinstance(target, InputSignal):
        kind = "an output" if isinstance(target, OutputSignal) else type(target).__name__
        raise PlugError(
            f"cannot plug into {getattr(target, 'name', target)!r}: it is {kind}; "
            "the second argument of plug must be an input signal"
        )
    if not isinstance(source, (OutputSignal, InputSignal)):
        raise PlugError(
            f"cannot plug {getattr(source, 'name', source)!r} into {target.name}: the source is "
            f"{type(source).__name__}; the first argument of plug must be a signal"
        )
    if not target.type.accepts_output(source.type):
        raise SignalTypeError(
            f"cannot plug {source.name} into {target.name}: type mismatch, "
            f"the input expects {target.type.name}, the output gives {source.type.name}"
        )
    if target._source is source:
        return
    _refuse_removed((source, target), f"cannot plug {source.name} into {target.name}")
    _refuse_cycle(source, target, f"plugging {source.name} into {target.name}")
    if target._source is not None:
        _remove_dependant(target._source, target)
    target._source = source
    target._mode = PLUGGED
    target._value = None
    target._checked = NEVER  # a plugged input forwards: never take its own fast path
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


def _invalidate(sig: OutputSignal, force: bool = False) -> None:
    """Make ``sig`` and everything downstream outdated at the current tick; with
    ``force``, ``sig`` is recomputed at its next read even before its period elapsed."""
    if sig._mode == FUNCTION:
        now = pool.time
        sig._invalid = FORCE if force and sig.period > 1 else now
        if sig._checked >= now:
            sig._checked = now - 1
    _invalidate_dependants(sig)


def _invalidate_dependants(sig: Signal) -> None:
    """Push invalidation: every output reading ``sig`` (transitively) becomes outdated
    at the current tick. Stops at outputs already outdated (their dependants are)."""
    now = pool.time
    stack = [*sig._dependants, *sig._fusedReaders]
    while stack:
        s = stack.pop()
        if isinstance(s, OutputSignal):
            if s._mode != FUNCTION or s._invalid > s._checked:
                continue  # a constant, or already invalidated (and so its dependants)
            s._invalid = now
            if s._checked >= now:
                s._checked = now - 1
        stack.extend(s._dependants)
        # a fused step may have recomputed an output downstream of an output that
        # stays invalidated (skipped by the step): reach it through its sources
        stack.extend(s._fusedReaders)


def _remove_dependant(sig: Signal, dependant: Signal) -> None:
    deps = sig._dependants
    for i, d in enumerate(deps):
        if d is dependant:
            del deps[i]
            return


def _reads(s: Signal) -> tuple[Signal, ...] | list[Signal]:
    """The signals ``s`` reads in the same tick."""
    if isinstance(s, InputSignal):
        return (s._source,) if s._source is not None else ()
    return s._deps if s._mode == FUNCTION else ()  # type: ignore[attr-defined]


def _readers(s: Signal) -> list[Signal]:
    """The signals that read ``s`` in the same tick."""
    return [d for d in s._dependants if not isinstance(d, OutputSignal) or d._mode == FUNCTION]


def _search_step(
    stack: list[Signal],
    seen: dict[int, Signal | None],
    other: dict[int, Signal | None],
    neighbours: Callable[[Signal], Iterable[Signal]],
    nodes: dict[int, Signal],
) -> int | None:
    """Expand one signal of one side of :func:`_refuse_cycle`'s search; return the id of
    a signal the other side has reached, if any."""
    s = stack.pop()
    for d in neighbours(s):
        if id(d) not in seen:
            seen[id(d)] = s
            nodes[id(d)] = d
            if id(d) in other:
                return id(d)
            stack.append(d)
    return None


def _refuse_cycle(source: Signal, reader: Signal, action: str) -> None:
    """Raise CycleError if ``reader`` reading ``source`` would close a same-tick cycle,
    that is if ``source`` already depends on ``reader``.

    Searches from both ends at once, one signal at a time each way (upstream of
    ``source``, downstream of ``reader``), and stops when either side is exhausted, so
    the cost is that of the smaller side: building a long chain in either order stays
    linear.
    """
    if source is reader:
        raise CycleError(f"{action} would make {reader.name} read itself", [reader.name] * 2)
    # up[x] = the signal that reads x (towards source); down[x] = the signal x reads
    # (towards reader)
    up: dict[int, Signal | None] = {id(source): None}
    down: dict[int, Signal | None] = {id(reader): None}
    nodes: dict[int, Signal] = {id(source): source, id(reader): reader}
    up_stack, down_stack = [source], [reader]
    meet: int | None = None
    while up_stack and down_stack and meet is None:
        meet = _search_step(up_stack, up, down, _reads, nodes) or _search_step(
            down_stack, down, up, _readers, nodes
        )
    if meet is None:
        return
    # source reads ... reads meet (walk up[] from meet to source), and meet reads ...
    # reads reader (walk down[] from meet to reader).
    head: list[Signal] = []
    x: Signal | None = nodes[meet]
    while x is not None:
        head.append(x)
        x = up[id(x)]
    head.reverse()  # source, ..., meet
    x = down[meet]
    while x is not None:
        head.append(x)
        x = down[id(x)]
    names = [n.name for n in head]  # each reads the next; reader would read source
    cycle = [*names, names[0]]
    shown = (
        cycle if len(cycle) <= 13 else [*cycle[:6], f"... {len(cycle) - 12} more ...", *cycle[-6:]]
    )
    raise CycleError(
        f"{action} would close a same-tick cycle of {len(names)} signals: "
        + " -> ".join(shown)
        + " (each reads the next; break it with a Delay entity or a state signal)",
        cycle,
    )


def _refuse_removed(signals: Iterable[Signal], action: str) -> None:
    """Raise PlugError if one of ``signals`` belongs to an entity removed from the pool
    (a stale reference kept by a script): wiring it would use a dead entity."""
    for s in signals:
        e = s.entity
        if getattr(e, "_removed", False):
            raise PlugError(
                f"{action}: {e.className}({e.name}) was removed from the pool "
                f"({s.name}); create it again, or use the entity the pool holds now"
            )


def _check_period(sig: Signal, period: Any) -> int:
    if isinstance(period, bool) or not isinstance(period, int) or period < 1:
        raise SignalTypeError(f"{sig.name}: period must be a positive integer, got {period!r}")
    return period
