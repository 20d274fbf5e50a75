"""The pool of entities, the graph's clock and the factory of entity classes.

There is one :data:`pool` per process: it is the only global state of sotpy. It holds

- the entities by name (:meth:`Pool.getEntity`, :meth:`Pool.getSignal`),
- the current tick :attr:`Pool.time` (the latest tick any signal was computed or written
  at; ``sig.value`` reads at this tick),
- a topology counter :attr:`Pool.version`, bumped on every plug, unplug, dependency or
  mode change, which tells compiled plans to recompile,
- :attr:`Pool.lock`, a re-entrant lock held by a running loop
  (:class:`sotpy.loop.ControlLoop`) during each tick; hold it to edit the graph
  atomically from another thread (the shell holds it while it executes each input, the
  remote interpreter during each call into sotpy). Signals never take it: a tick pays
  one acquire/release.

An entity leaves the pool with :meth:`Pool.remove`, which refuses while something
outside the removed group still uses it (see its doc and ``docs/graph.md``).

:data:`factory` maps class names to entity classes; a subclass of ``Entity`` registers
itself when it is defined.
"""

from __future__ import annotations

import threading
from typing import TYPE_CHECKING, Any

from ..errors import EntityError, FactoryError, SignalNotFoundError

if TYPE_CHECKING:
    from .entity import Entity
    from .signal import Signal

__all__ = ["Factory", "Pool", "factory", "pool"]


class Pool:
    """Registry of the entities of the process, with the graph clock."""

    def __init__(self) -> None:
        self._entities: dict[str, Entity] = {}
        #: The current tick: the latest tick any signal was computed or written at
        #: (``sig.value`` reads at this tick).
        self.time: int = 0
        #: Topology counter, bumped on every plug, unplug, dependency or mode change;
        #: compiled plans recompile when it moved.
        self.version: int = 0
        #: Held by a running loop during each tick; hold it to edit the graph atomically
        #: from another thread (``with pool.lock: ...``). Re-entrant.
        self.lock: threading.RLock = threading.RLock()
        #: Solves that stopped at their budget (entities with a time-budgeted solver add
        #: one each time); a control loop counts the ticks during which it moved.
        self.budgetHits: int = 0

    # -- entities ---------------------------------------------------------------------
    def register(self, entity: Entity) -> None:
        """Add ``entity`` under its name (called by entity construction)."""
        if entity.name in self._entities:
            raise EntityError(f"an entity named {entity.name!r} already exists in the pool")
        self._entities[entity.name] = entity

    def getEntity(self, name: str) -> Entity:
        """Return the entity called ``name``."""
        try:
            return self._entities[name]
        except KeyError:
            known = ", ".join(sorted(self._entities)) or "none"
            raise EntityError(f"unknown entity {name!r} (entities in the pool: {known})") from None

    def hasEntity(self, name: str) -> bool:
        """Whether an entity called ``name`` exists."""
        return name in self._entities

    def getSignal(self, path: str) -> Signal:
        """Return the signal at ``"entity.signal"`` (the signal's short name)."""
        entity_name, sep, signal_name = path.partition(".")  # entity names have no dot
        if not sep:
            raise SignalNotFoundError(f"signal path {path!r} must have the form 'entity.signal'")
        return self.getEntity(entity_name).signal(signal_name)

    def entities(self) -> list[Entity]:
        """The entities, in creation order."""
        return list(self._entities.values())

    def list(self) -> list[str]:
        """Names of the entities, in creation order."""
        return list(self._entities)

    def remove(self, *entities: Entity | str) -> None:
        """Remove ``entities`` (entities or names) from the pool, all together.

        Refused with :class:`~sotpy.errors.EntityError`, leaving the graph as it was,
        while anything outside the group still uses one of them: an input plugged to
        one of their outputs, an output computed from one of their signals (a solver
        reading a task, a task its features, a tracer the traced signals), a periodic
        call refreshing one of their signals, an entity holding one of them (a loop its
        device). The message names every user; take the entity out of them first
        (``sot.remove(task)``, ``task.remove(feature)``, ``tracer.remove(label)``,
        ``unplug()``) or remove the users in the same call
        (``pool.remove("task", "feature")``). Then each entity's ``onRemove()`` runs (it
        releases threads, servers, files), its signals are unplugged from one another,
        it leaves the pool and it is marked removed: a stale Python reference to it can
        no longer be plugged, pushed or traced. The name is free for a new entity.
        """
        from .entity import _forgetFused, _users

        if not entities:
            raise EntityError("pool.remove: name at least one entity to remove")
        group: list[Entity] = []
        for entity in entities:
            name = entity if isinstance(entity, str) else getattr(entity, "name", None)
            if not isinstance(name, str):
                raise EntityError(f"pool.remove: expected an entity or its name, got {entity!r}")
            e = self.getEntity(name)
            if not isinstance(entity, str) and e is not entity:
                raise EntityError(
                    f"pool.remove: {entity!r} is not the entity the pool holds under the name "
                    f"{name!r} (it was removed already)"
                )
            if not any(g is e for g in group):
                group.append(e)
        users = _users(group)
        if users:
            names = ", ".join(f"{g.className}({g.name})" for g in group)
            uses = "; ".join(f"{who} {what}" for who, what in users.items())
            owners = [who.split("(", 1)[1].split(")", 1)[0] for who in users]
            together = ", ".join(map(repr, dict.fromkeys([*(g.name for g in group), *owners])))
            raise EntityError(
                f"cannot remove {names}: still used by {uses}. Nothing was removed: take it "
                "out of them first (a solver's or a task's remove(...), a tracer's "
                f"remove(label), unplug()), or remove them together: pool.remove({together})"
            )
        for e in group:
            e.onRemove()
        for e in group:
            e._detach()
            del self._entities[e.name]
        _forgetFused(group)
        self.version += 1

    def clear(self) -> None:
        """Forget every entity and reset the clock (tests start from here)."""
        for e in list(self._entities.values()):
            e.onRemove()
            e._detach()
        self._entities.clear()
        self.time = 0
        self.version += 1
        self.budgetHits = 0

    def advance(self, t: int) -> None:
        """Move the clock forward to tick ``t`` (never backwards)."""
        if t > self.time:
            self.time = t

    def writeGraph(self, path: str, **kwargs: Any) -> str:
        """Write the graph to ``path``; see :func:`sotpy.graph.writeGraph`."""
        from .dot import writeGraph

        return writeGraph(path, **kwargs)


class Factory:
    """Entity classes by class name; ``factory.create("Task", "t1")`` builds one."""

    def __init__(self) -> None:
        self._classes: dict[str, type[Entity]] = {}

    def register(self, cls: type[Entity]) -> None:
        """Record ``cls`` under ``cls.className`` (a redefinition replaces the old one)."""
        self._classes[cls.className] = cls

    def create(self, className: str, name: str, *args: Any, **kwargs: Any) -> Entity:
        """Create (or return, SoT's idempotent rule) entity ``name`` of class ``className``."""
        return self.getClass(className)(name, *args, **kwargs)

    def getClass(self, className: str) -> type[Entity]:
        """Return the class registered as ``className``."""
        try:
            return self._classes[className]
        except KeyError:
            raise FactoryError(
                f"unknown entity class {className!r}; known classes: "
                f"{', '.join(sorted(self._classes))}"
            ) from None

    def hasClass(self, className: str) -> bool:
        """Whether ``className`` is registered."""
        return className in self._classes

    def classes(self) -> list[str]:
        """Names of the registered classes, sorted."""
        return sorted(self._classes)


pool = Pool()
factory = Factory()
