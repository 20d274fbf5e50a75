"""dynamic-graph-python's ``dynamic_graph.signal_base``: ``SignalBase`` is sotpy's
:class:`~sotpy.graph.Signal`. The string conversions of dynamic-graph-python 3
(``stringToTuple`` and friends) are kept for old scripts."""

from __future__ import annotations

import re
from typing import Any

from ...graph import Signal as SignalBase

__all__ = ["SignalBase", "matrixToString", "stringToMatrix", "stringToTuple", "tupleToString"]


def stringToTuple(text: str) -> tuple[float, ...]:
    """``'[n](x1,...,xn)'`` -> a tuple of n floats."""
    m = re.fullmatch(r"\s*\[(\d+)\]\((.*)\)\s*", text, re.S)
    if m is None:
        raise ValueError(f"stringToTuple: expected '[n](x1,...,xn)', got {text!r}")
    items = [float(x) for x in m.group(2).split(",")] if m.group(2).strip() else []
    if len(items) != int(m.group(1)):
        raise ValueError(f"stringToTuple: {text!r} announces {m.group(1)} values, has {len(items)}")
    return tuple(items)


def tupleToString(vector: Any) -> str:
    """A sequence of numbers -> ``'[n](x1,...,xn)'``."""
    return f"[{len(vector)}](" + ",".join(f"{float(x):f}" for x in vector) + ")"


def stringToMatrix(text: str) -> tuple[tuple[float, ...], ...]:
    """``'[n,m]((x11,...),...)'`` -> a tuple of n rows of m floats."""
    m = re.fullmatch(r"\s*\[(\d+),(\d+)\]\((.*)\)\s*", text, re.S)
    if m is None:
        raise ValueError(f"stringToMatrix: expected '[n,m]((...),...)', got {text!r}")
    rows = re.findall(r"\(([^()]*)\)", m.group(3))
    out = tuple(tuple(float(x) for x in r.split(",")) for r in rows)
    if len(out) != int(m.group(1)) or any(len(r) != int(m.group(2)) for r in out):
        raise ValueError(f"stringToMatrix: {text!r} does not have the announced shape")
    return out


def matrixToString(matrix: Any) -> str:
    """Rows of numbers -> ``'[n,m]((x11,...),...)'``."""
    rows = [list(r) for r in matrix]
    if not rows:
        return "[0,0](())"
    body = ",".join("(" + ",".join(str(float(x)) for x in r) + ")" for r in rows)
    return f"[{len(rows)},{len(rows[0])}]({body})"
