"""sot-talos' ``dynamic_graph.sot.talos``, served by sotpy: ``Talos``."""

from .talos import Talos

__all__ = ["Talos"]
