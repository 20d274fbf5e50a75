"""sot-talos' ``dynamic_graph.sot.pyrene.robot``: ``Robot``, LAAS' Talos (Pyrene), over
sotpy's Talos."""

from __future__ import annotations

from typing import Any

from ..talos.talos import Talos

__all__ = ["Robot"]


class Robot(Talos):
    """SoT's ``Robot(name, device=None, tracer=None, fromRosParam=None)``: sotpy's Talos
    (see :class:`~sotpy.compat.dynamic_graph.sot.talos.talos.Talos`); its half-sitting
    is sotpy's (example-robot-data's reference posture), not Pyrene's."""

    def __init__(
        self, name: str, device: Any = None, tracer: Any = None, fromRosParam: Any = None
    ) -> None:
        Talos.__init__(self, name, device=device, tracer=tracer, fromRosParam=fromRosParam)
