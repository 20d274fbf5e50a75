"""sotpy: the Stack of Tasks in Python.

A data-flow graph of entities and typed, tick-stamped signals (:mod:`sotpy.graph`)
that computes a robot's control each tick; robots, tasks and solvers build on it.
"""

from .graph import (
    Entity,
    Input,
    Output,
    Tracer,
    checkPlugged,
    command,
    factory,
    plug,
    pool,
    writeGraph,
)

__version__ = "0.1.0"

__all__ = [
    "Entity",
    "Input",
    "Output",
    "Tracer",
    "__version__",
    "checkPlugged",
    "command",
    "factory",
    "plug",
    "pool",
    "writeGraph",
]
