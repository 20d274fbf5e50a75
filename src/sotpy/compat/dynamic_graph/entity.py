"""dynamic-graph-python's ``dynamic_graph.entity``: ``Entity`` is sotpy's
:class:`~sotpy.graph.Entity`, and ``Entity.entities`` (SoT's map of the entities by
name) is the pool's, read-only."""

from __future__ import annotations

from types import MappingProxyType
from typing import Any

from ...graph import Entity, pool

__all__ = ["Entity", "VerbosityLevel"]


class _Entities:
    """``Entity.entities``: a read-only view of the pool's entities by name."""

    def __get__(self, obj: Any, owner: Any = None) -> Any:
        return MappingProxyType(pool._entities)


if not isinstance(Entity.__dict__.get("entities"), _Entities):
    type.__setattr__(Entity, "entities", _Entities())


class VerbosityLevel:
    """dynamic-graph's logger levels (sotpy has no logger: accepted names only)."""

    VERBOSITY_ALL = 0
    VERBOSITY_INFO_WARNING_ERROR = 1
    VERBOSITY_WARNING_ERROR = 2
    VERBOSITY_ERROR = 3
    VERBOSITY_NONE = 4
