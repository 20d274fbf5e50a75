"""dynamic-graph-python's ``dynamic_graph.tools``: ``addTrace``."""

from __future__ import annotations

from typing import Any

__all__ = ["addTrace"]


def addTrace(
    robot: Any, trace: Any, entityName: str, signalName: str, autoRecompute: bool = True
) -> None:
    """Trace ``entityName.signalName`` in ``trace`` (file ``<entity>-<signal>``) and, with
    ``autoRecompute``, recompute it after each ``robot.device.increment`` (SoT's)."""
    path = f"{entityName}.{signalName}"
    trace.add(path, f"{entityName}-{signalName}".replace("/", "_"))
    if autoRecompute:
        robot.device.after.addSignal(path)
