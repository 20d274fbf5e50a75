"""Entities: named nodes of the graph, with signals and commands.

An entity class declares its signals and commands in its body::

    class Gain(Entity):
        '''y = k x.'''

        sin = Input(VECTOR, doc="x")
        k = Input(DOUBLE, default=1.0, doc="gain k")

        @Output(VECTOR, deps=("sin", "k"), doc="y = k x")
        def sout(self, x, k):
            return k * x

        @command
        def double(self) -> None:
            '''Double the gain.'''
            self.k.value = 2 * self.k.value

and is used as in the SoT: ``g = Gain("g")`` (creating an existing name of the same
class returns that entity, another class raises), ``g.sin.value = [1, 2]``,
``g.sout.value``, ``g.double()``, ``g.displaySignals()``, ``g.help()``.

A class registers itself in the factory under ``className`` (its Python name unless
the class sets ``className``).
"""

from __future__ import annotations

import inspect
import keyword
import warnings
from collections.abc import Callable, Iterable
from typing import Any, ClassVar

from ..errors import EntityError, SignalNotFoundError, SotpyWarning
from .command import BoundCommand, Command
from .pool import factory, pool
from .signal import InputSignal, OutputSignal, Signal, _remove_dependant
from .types import SignalType, type_named

__all__ = ["Entity", "Input", "Output"]


class Input:
    """Declares an input signal in an entity class body.

    Args:
        type: a :class:`SignalType` or its name (``"vector"``).
        default: constant the input holds until plugged (None: unset).
        doc: what the value is, with its unit.
        name: signal name if it differs from the attribute name.
    """

    def __init__(
        self, type: SignalType | str, default: Any = None, *, doc: str = "", name: str | None = None
    ) -> None:
        self.type = type_named(type)
        self.default = default
        self.doc = doc
        self.name = name

    def __set_name__(self, owner: type, attr: str) -> None:
        if self.name is None:
            self.name = attr

    def make(self, entity: Entity) -> InputSignal:
        return InputSignal(entity, self.name, self.type, self.default, self.doc)  # type: ignore[arg-type]


class Output:
    """Declares an output signal; used as a decorator on its callback.

    ``@Output(type, deps=(...))`` on a method makes the method the callback; it receives
    the values of ``deps`` (names of signals of the entity), preceded by the tick ``t``
    when ``withTime`` is true. Without a callback (``state = Output(VECTOR)``) the signal
    is a state signal the entity writes with :meth:`OutputSignal.write`.

    Args:
        type: a :class:`SignalType` or its name.
        deps: names of the entity's signals the callback reads, in argument order.
        withTime: pass the tick as first argument.
        timeDependent: recompute every tick even if no dependency changed (default:
            true when there are no dependencies).
        period: recompute at most every ``period`` ticks.
        initial: initial value of a state signal.
        doc: what the value is, with its unit.
    """

    def __init__(
        self,
        type: SignalType | str,
        deps: Iterable[str] = (),
        *,
        withTime: bool = False,
        timeDependent: bool | None = None,
        period: int = 1,
        initial: Any = None,
        doc: str = "",
        name: str | None = None,
    ) -> None:
        self.type = type_named(type)
        self.deps = tuple(deps)
        self.withTime = withTime
        self.timeDependent = timeDependent
        self.period = period
        self.initial = initial
        self.doc = doc
        self.name = name
        self.fn: Callable[..., Any] | None = None

    def __call__(self, fn: Callable[..., Any]) -> Output:
        self.fn = fn
        if not self.doc and fn.__doc__:
            self.doc = inspect.cleandoc(fn.__doc__).split("\n", 1)[0]
        return self

    def __set_name__(self, owner: type, attr: str) -> None:
        if self.name is None:
            self.name = attr

    def make(self, entity: Entity) -> OutputSignal:
        callback = None if self.fn is None else self.fn.__get__(entity)
        sig = OutputSignal(
            entity,
            self.name,  # type: ignore[arg-type]
            self.type,
            callback,
            withTime=self.withTime,
            timeDependent=(not self.deps) if self.timeDependent is None else self.timeDependent,
            period=self.period,
            doc=self.doc,
        )
        if self.fn is None and self.initial is not None:
            sig._value = sig._convert(self.initial)
            sig._time = sig._checked = pool.time
        return sig


class EntityMeta(type):
    """Makes ``Class("name")`` idempotent (SoT's rule) and registers classes."""

    def __call__(cls, name: str, *args: Any, **kwargs: Any) -> Any:
        if not isinstance(name, str) or not name or name.strip() != name or "." in name:
            raise EntityError(
                f"{cls.__name__}: entity name must be a non-empty string without dots or "
                f"surrounding spaces, got {name!r}"
            )
        existing = pool._entities.get(name)
        if existing is not None:
            if type(existing) is cls:
                if args or kwargs:
                    warnings.warn(
                        f"{cls.className}({name}) already exists: the construction arguments "
                        "are ignored (SoT's rule returns the existing entity); use its "
                        "commands to change it",
                        SotpyWarning,
                        stacklevel=2,
                    )
                return existing
            raise EntityError(
                f"cannot create {cls.className}({name}): an entity named {name!r} already "
                f"exists with class {existing.className}"
            )
        obj = cls.__new__(cls)
        obj._setup(name)
        try:
            obj.__init__(name, *args, **kwargs)
        except BaseException:
            try:
                obj.onRemove()  # release what the failed __init__ may have started
            finally:
                obj._detach()
            raise
        pool.register(obj)
        return obj


class Entity(metaclass=EntityMeta):
    """Base class of every entity. See the module doc for how to declare one."""

    className: ClassVar[str] = "Entity"
    #: True once the entity left the pool (``pool.remove``, ``pool.clear``).
    _removed: bool = False
    _specs: ClassVar[dict[str, Input | Output]] = {}
    _commands: ClassVar[dict[str, Command]] = {}

    def __init_subclass__(cls, **kwargs: Any) -> None:
        super().__init_subclass__(**kwargs)
        if "className" not in cls.__dict__:
            cls.className = cls.__name__
        specs: dict[str, Input | Output] = {}
        commands: dict[str, Command] = {}
        for klass in reversed(cls.__mro__):
            for value in vars(klass).values():
                if isinstance(value, (Input, Output)):
                    specs[value.name] = value  # type: ignore[index]
                elif isinstance(value, Command):
                    commands[value.name] = value
        cls._specs = specs
        cls._commands = commands
        for spec in specs.values():
            if isinstance(spec, Output):
                for dep in spec.deps:
                    if dep not in specs:
                        raise EntityError(
                            f"{cls.__name__}: output {spec.name!r} depends on {dep!r}, "
                            "which is not a signal of the class"
                        )
        factory.register(cls)

    def __init__(self, name: str) -> None:
        """Entities are created as ``ClassName("name")``."""

    # -- construction -----------------------------------------------------------------
    def _setup(self, name: str) -> None:
        object.__setattr__(self, "_name", name)
        object.__setattr__(self, "_signals", {})
        for spec in self._specs.values():
            self.addSignal(spec.make(self))
        for spec in self._specs.values():
            if isinstance(spec, Output) and spec.deps:
                self._signals[spec.name].setDependencies([self._signals[d] for d in spec.deps])

    def onRemove(self) -> None:
        """Called when the entity leaves the pool (``pool.remove``, ``pool.clear``, or a
        construction that raised): release what it holds outside the graph (threads,
        processes, files). It may run on a partly built entity."""

    def _holds(self) -> Iterable[Entity]:
        """Entities this one uses outside the signal graph (a loop's device); while it is
        in the pool, they cannot be removed without it. Default: none."""
        return ()

    def _detach(self) -> None:
        """Unplug everything connected to this entity (it is leaving the pool) and mark it
        removed: its signals can no longer be plugged or made dependencies."""
        object.__setattr__(self, "_removed", True)
        for sig in self._signals.values():
            for d in list(sig._dependants):
                if isinstance(d, InputSignal) and d.entity is not self:
                    d.unplug()
            if isinstance(sig, InputSignal) and sig._source is not None:
                _remove_dependant(sig._source, sig)
                sig._source = None
            if isinstance(sig, OutputSignal):
                for s in sig._deps:
                    _remove_dependant(s, sig)
        pool.version += 1

    @property
    def name(self) -> str:
        """The entity's name in the pool."""
        return self._name  # type: ignore[attr-defined]

    # -- signals ----------------------------------------------------------------------
    def addSignal(self, sig: Signal) -> Signal:
        """Register ``sig`` (created by the entity, e.g. by ``createOpPoint``).

        It becomes ``entity.signal(name)`` and, when its name is a valid identifier
        free in the class, the attribute ``entity.<name>`` (tab-completed).
        """
        if sig.entity is not self:
            raise EntityError(
                f"{self.className}({self.name}): {sig.name} belongs to another entity"
            )
        if sig.shortName in self._signals:  # type: ignore[attr-defined]
            raise EntityError(
                f"{self.className}({self.name}): a signal named {sig.shortName!r} already exists"
            )
        self._signals[sig.shortName] = sig  # type: ignore[attr-defined]
        n = sig.shortName
        if n.isidentifier() and not keyword.iskeyword(n):
            clash = getattr(type(self), n, None)
            if clash is None or isinstance(clash, (Input, Output)):
                object.__setattr__(self, n, sig)
        pool.version += 1
        return sig

    def removeSignal(self, name: str) -> None:
        """Remove a signal added with :meth:`addSignal` (unplugging its readers)."""
        sig = self.signal(name)
        for d in list(sig._dependants):
            if isinstance(d, InputSignal):
                d.unplug()
            elif isinstance(d, OutputSignal):
                d.setDependencies([s for s in d._deps if s is not sig])
        if isinstance(sig, InputSignal) and sig._source is not None:
            sig.unplug()
        if isinstance(sig, OutputSignal):
            sig.setDependencies(())
        del self._signals[name]  # type: ignore[attr-defined]
        if self.__dict__.get(name) is sig:
            object.__delattr__(self, name)
        pool.version += 1

    def signal(self, name: str) -> Signal:
        """The signal called ``name`` (any name, e.g. ``'left-wrist'``)."""
        try:
            return self._signals[name]  # type: ignore[attr-defined]
        except KeyError:
            known = ", ".join(sorted(self._signals)) or "none"  # type: ignore[attr-defined]
            raise SignalNotFoundError(
                f"{self.className}({self.name}) has no signal {name!r} (signals: {known})"
            ) from None

    def hasSignal(self, name: str) -> bool:
        """Whether the entity has a signal called ``name``."""
        return name in self._signals  # type: ignore[attr-defined]

    def signals(self) -> list[Signal]:
        """The signals, sorted by name."""
        return [self._signals[k] for k in sorted(self._signals)]  # type: ignore[attr-defined]

    def __setattr__(self, attr: str, value: Any) -> None:
        current = self.__dict__.get(attr)
        if isinstance(current, Signal):
            raise EntityError(
                f"{self.className}({self.name}).{attr} is a signal: set its value with "
                f"'.{attr}.value = ...' or plug it"
            )
        object.__setattr__(self, attr, value)

    def __getattr__(self, attr: str) -> Any:
        # only called when normal lookup fails: name the signals and commands
        if attr.startswith("_"):
            raise AttributeError(attr)
        sigs = ", ".join(sorted(self.__dict__.get("_signals", {}))) or "none"
        cmds = ", ".join(sorted(self._commands)) or "none"
        raise SignalNotFoundError(
            f"{self.className}({self.__dict__.get('_name', '?')}) has no signal or command "
            f"{attr!r} (signals: {sigs}; commands: {cmds})"
        )

    # -- display ----------------------------------------------------------------------
    def displaySignals(self) -> None:
        """Print the signal list in SoT's layout."""
        print(self.signalsDisplay())

    def signalsDisplay(self) -> str:
        """The text :meth:`displaySignals` prints."""
        sigs = self.signals()
        lines = [f"--- <{self.name}> signal list:"]
        for i, s in enumerate(sigs):
            branch = "'--" if i == len(sigs) - 1 else "|--"
            lines.append(f"{branch} <{s.display()}")
        return "\n".join(lines)

    def commands(self) -> list[str]:
        """Names of the commands, sorted."""
        return sorted(self._commands)

    def help(self, name: str | None = None) -> None:
        """Print the class doc and the command list, or the doc of command ``name``."""
        print(self.helpText(name))

    def helpText(self, name: str | None = None) -> str:
        """The text :meth:`help` prints."""
        if name is None:
            doc = inspect.cleandoc(type(self).__doc__ or "").split("\n\n", 1)[0]
            lines = [doc, "List of commands:"] if doc else ["List of commands:"]
            width = max((len(c) for c in self._commands), default=0)
            for c in self.commands():
                lines.append(f" {c + ':':<{width + 1}} {self._commands[c].summary}")
            text = "\n".join(lines)
        else:
            cmd = self._commands.get(name)
            if cmd is None:
                raise SignalNotFoundError(
                    f"{self.className}({self.name}) has no command {name!r} "
                    f"(commands: {', '.join(self.commands()) or 'none'})"
                )
            body = "\n".join(("   " + line).rstrip() for line in cmd.__doc__.splitlines())
            text = f"{cmd.usage()}\n{body}" if body else cmd.usage()
        return text

    def getCommand(self, name: str) -> BoundCommand:
        """The bound command called ``name``."""
        if name not in self._commands:
            self.helpText(name)  # raises with the list
        return self._commands[name].__get__(self)

    def graphClusters(self) -> list[tuple[str, list[Entity]]]:
        """Ordered groups of entities to draw as a cluster in :func:`writeGraph` (a
        solver returns its stack of tasks, highest priority first)."""
        return []

    def __repr__(self) -> str:
        return f"{self.className}({self.name!r})"


def _users(group: list[Entity]) -> dict[str, str]:
    """What uses the entities of ``group`` from outside it: ``{"user": "reads a.x, a.y"}``
    (the user a signal's full name, a periodic call or an entity), empty when nothing
    does.

    A use is an input plugged to one of their outputs, an output whose callback reads
    one of their signals (a task reading a feature, a solver its tasks, a tracer the
    traced signals), a periodic call (a device's ``before``/``after``) refreshing one of
    their signals, or an entity holding one of them outside the graph (``_holds``: a
    loop's device).
    """
    from .plan import PeriodicCall

    inside = {id(e) for e in group}
    uses: dict[str, dict[str, list[str]]] = {}

    def use(who: str, verb: str, what: str) -> None:
        lst = uses.setdefault(who, {}).setdefault(verb, [])
        if what not in lst:
            lst.append(what)

    for e in group:
        for sig in e._signals.values():  # type: ignore[attr-defined]
            for d in sig._dependants:
                if id(d.entity) not in inside:
                    use(d.name, "plugged to" if isinstance(d, InputSignal) else "reads", sig.path)
    for other in pool.entities():
        if id(other) in inside:
            continue
        who = f"{other.className}({other.name})"
        for attr, value in vars(other).items():
            if isinstance(value, PeriodicCall):
                for sigs in value._signals.values():
                    for s in sigs:
                        if id(s.entity) in inside:
                            use(f"{who}.{attr}", "refreshes", s.path)
        for held in other._holds():
            if id(held) in inside:
                use(who, "uses", f"{held.className}({held.name})")
    return {
        who: "; ".join(f"{verb} {', '.join(what)}" for verb, what in verbs.items())
        for who, verbs in uses.items()
    }


def _forgetFused(group: list[Entity]) -> None:
    """Drop the outputs of ``group`` (removed) from the fused readers of the signals
    left in the pool (see :meth:`OutputSignal.setPlanFusion`)."""
    gone = {id(e) for e in group}
    for other in pool.entities():
        for sig in other._signals.values():  # type: ignore[attr-defined]
            readers = sig._fusedReaders
            if readers and any(id(r.entity) in gone for r in readers):
                sig._fusedReaders = tuple(r for r in readers if id(r.entity) not in gone)
