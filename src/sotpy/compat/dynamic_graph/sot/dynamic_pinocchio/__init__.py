"""sot-dynamic-pinocchio's ``dynamic_graph.sot.dynamic_pinocchio``, served by sotpy:
``DynamicPinocchio`` and ``fromSotToPinocchio``.

``DynamicPinocchio(name)`` then ``setModel(model)`` builds sotpy's
:class:`~sotpy.dynamics.Dynamic` ``name`` over the model (sotpy's ``Dynamic`` needs its
model at construction): the object ``DynamicPinocchio`` returns stands for it, and
every attribute (signals, commands) is the ``Dynamic``'s. ``setData`` is accepted and
unused (the ``Dynamic`` keeps its own ``pinocchio.Data``).
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pinocchio as pin

from .....dynamics import Dynamic
from .....graph import pool
from ...._errors import unsupported

__all__ = ["DynamicPinocchio", "fromSotToPinocchio"]


class DynamicPinocchio:
    """SoT's ``DynamicPinocchio(name)``: sotpy's ``Dynamic(name, model)`` once
    ``setModel(model)`` is called (see the module doc)."""

    def __init__(self, name: str) -> None:
        object.__setattr__(self, "_name", name)
        existing = pool._entities.get(name)
        object.__setattr__(self, "_entity", existing if isinstance(existing, Dynamic) else None)

    def _sotpyDynamic(self) -> Dynamic:
        if self._entity is None:
            raise unsupported(
                f"DynamicPinocchio({self._name!r}) used before setModel(model)",
                f"call {self._name}.setModel(pinocchio_model) first (it creates sotpy's "
                f"Dynamic({self._name!r}, model)), or use load_robot",
            )
        return self._entity

    @property
    def name(self) -> str:
        """The entity's name."""
        return self._name

    def setModel(self, model: Any) -> None:
        """Create the ``Dynamic`` over ``model`` (a ``pinocchio.Model``)."""
        if self._entity is not None:
            if self._entity.model.nq != model.nq or self._entity.model.nv != model.nv:
                raise unsupported(
                    f"DynamicPinocchio({self._name!r}).setModel a second time with another model",
                    "a new Dynamic entity of another name",
                )
            return
        object.__setattr__(self, "_entity", Dynamic(self._name, model))

    def setData(self, data: Any) -> None:
        """Accepted, unused: the ``Dynamic`` computes with its own ``pinocchio.Data``."""

    def add_signals(self) -> None:
        """Nothing to do: sotpy's signals are attributes at once."""

    def displayModel(self) -> None:
        """Print the model."""
        print(self._sotpyDynamic().model)

    def __getattr__(self, attr: str) -> Any:
        return getattr(self._sotpyDynamic(), attr)

    def __setattr__(self, attr: str, value: Any) -> None:
        setattr(self._sotpyDynamic(), attr, value)

    def __repr__(self) -> str:
        return f"DynamicPinocchio({self._name!r})"


def fromSotToPinocchio(q_sot: Any, freeflyer: bool = True) -> np.ndarray:
    """SoT's configuration (the free flyer as x, y, z, roll, pitch, yaw) as a Pinocchio
    configuration (x, y, z, qx, qy, qz, qw): a 1-D array (SoT's returned a 1 x nq
    numpy matrix)."""
    q = np.asarray(q_sot, dtype=float).ravel()
    if not freeflyer:
        return q.copy()
    if q.shape[0] < 6:
        raise ValueError(
            f"fromSotToPinocchio: a free-flyer configuration has >= 6 entries, got {q}"
        )
    quat = pin.Quaternion(pin.rpy.rpyToMatrix(q[3], q[4], q[5])).coeffs()  # (x, y, z, w)
    return np.concatenate((q[:3], quat, q[6:]))
