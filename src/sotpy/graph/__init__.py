"""sotpy's data-flow core: entities, signals, commands, the pool and the factory.

Everything a graph-building script needs::

    from sotpy.graph import Entity, Input, Output, command, plug, pool, writeGraph

The semantics are dynamic-graph's, with its documented defects fixed; they are
described in ``docs/graph.md``. This package needs neither robotics nor numpy, except
for the ``vector``/``matrix`` signal types and the tracer.
"""

from .command import Command, command
from .delay import Delay_of_double, Delay_of_matrix, Delay_of_vector
from .dot import graphDot, writeGraph
from .entity import Entity, Input, Output
from .plan import PeriodicCall, Plan, compilePlan
from .pool import factory, pool
from .signal import InputSignal, OutputSignal, Signal, checkPlugged, plug
from .tracer import Tracer
from .types import ANY, BOOL, DOUBLE, INT, MATRIX, STRING, VECTOR, SignalType, object_type

__all__ = [
    "ANY",
    "BOOL",
    "DOUBLE",
    "INT",
    "MATRIX",
    "STRING",
    "VECTOR",
    "Command",
    "Delay_of_double",
    "Delay_of_matrix",
    "Delay_of_vector",
    "Entity",
    "Input",
    "InputSignal",
    "Output",
    "OutputSignal",
    "PeriodicCall",
    "Plan",
    "Signal",
    "SignalType",
    "Tracer",
    "checkPlugged",
    "command",
    "compilePlan",
    "factory",
    "graphDot",
    "object_type",
    "plug",
    "pool",
    "writeGraph",
]
