"""sot-core's ``dynamic_graph.sot.core``, served by sotpy (``sotpy run``).

``Device`` and ``Flags`` (sot-core 4's names here), and, for scripts written for
sot-core 3 (``from dynamic_graph.sot.core import *``), every entity class the layer
serves. The submodules (``sot``, ``task``, ``feature_point6d``, ``meta_tasks_kine``,
``matrix_util``, ...) are listed in ``docs/porting.md``.
"""

from __future__ import annotations

from .....tasks import Flags
from ...._entities import *  # noqa: F403  (sot-core 3 exported every class here)
from ...._entities import Device
from ...._entities import __all__ as _classes

__all__ = ["Device", "Flags", *[c for c in _classes if c != "Device"]]
