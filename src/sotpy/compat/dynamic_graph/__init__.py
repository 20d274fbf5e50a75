"""dynamic-graph-python's ``dynamic_graph`` module, served by sotpy (``sotpy run``).

``plug``, ``writeGraph``, ``Entity``, ``SignalBase`` (sotpy's :class:`~sotpy.graph.Signal`),
``get_entity_list`` and ``factory_get_entity_class_list`` are sotpy's graph core. The
debug and logger functions of dynamic-graph (``enableTrace``, ``addLogger...``,
``real_time_logger_...``) raise :class:`~sotpy.compat.UnsupportedFeature`.
"""

from __future__ import annotations

from typing import Any

from ...graph import Signal as SignalBase
from ...graph import factory, plug, pool, writeGraph
from .._errors import unsupported
from . import entity, signal_base
from .entity import Entity

__all__ = [
    "Entity",
    "SignalBase",
    "entity",
    "factory_get_entity_class_list",
    "get_entity_list",
    "plug",
    "signal_base",
    "writeGraph",
]


def get_entity_list() -> list[str]:
    """The names of the entities in the pool."""
    return pool.list()


def factory_get_entity_class_list() -> list[str]:
    """The names of the entity classes the factory knows."""
    return factory.classes()


_LOGGERS = {
    "enableTrace": "Python's logging; the graph's state: entity.displaySignals(), "
    "sig.displayDependencies()",
    "addLoggerFileOutputStream": "Python's logging (sotpy reports through exceptions "
    "and SotpyWarning)",
    "addLoggerCoutOutputStream": "Python's logging",
    "closeLoggerFileOutputStream": "Python's logging",
    "real_time_logger_destroy": "Python's logging",
    "real_time_logger_spin_once": "Python's logging",
    "real_time_logger_instance": "Python's logging",
}


def __getattr__(name: str) -> Any:
    if name in _LOGGERS:

        def refuse(*args: Any, **kwargs: Any) -> None:
            raise unsupported(f"dynamic_graph.{name}", _LOGGERS[name])

        refuse.__name__ = name
        return refuse
    raise AttributeError(f"module 'dynamic_graph' (served by sotpy) has no attribute {name!r}")
