"""``TaskJointLimits``: joint positions kept within bounds, as an inequality task
(sot-dyninv's ``TaskJointLimits``).

For each selected velocity DoF ``i`` of a one-DoF joint, whose coordinate is ``q_k``:

    (referenceInf_k - q_k) / (dt controlGain) <= qdot_i <= (referenceSup_k - q_k) / (dt controlGain)

so that with ``controlGain = 1`` one period ``dt`` of the bound velocity reaches the
limit, and with ``controlGain = c > 1`` a fraction ``1/c`` of the distance (sot-dyninv's
``K = 1 / (dt controlGain)``). The task's ``jacobian`` has one row ``e_i`` per selected
DoF, ``lower``/``upper`` are the bounds above, ``error`` is ``q_k`` and
``normalizedPosition`` is ``(q_k - inf_k) / (sup_k - inf_k)`` (0 at the lower limit, 1
at the upper one).
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pinocchio as pin

from ..errors import CommandError, SignalTypeError
from ..graph import DOUBLE, INT, VECTOR, Input, Output
from ..graph.signal import Signal
from .features import FLAGS, Flags
from .task import TaskAbstract

__all__ = ["TaskJointLimits"]


class TaskJointLimits(TaskAbstract):
    """Bounds on the joint positions, one period ahead (see the module doc).

    ``TaskJointLimits(name, model=None)``. Inputs: ``position`` (q: plug
    ``dynamic.position`` or ``device.state``), ``referenceInf``/``referenceSup`` (the
    limits, size of q, or size nv indexed by DoF: plug ``dynamic.lowerJl``/``upperJl``),
    ``dt`` (s, > 0), ``controlGain`` (> 0, default 1), ``selec`` (the velocity DoFs
    bounded, SoT flags; default all the one-DoF joints). The map from DoFs to
    coordinates comes from ``model``, or from the model of the entity ``position``
    reads from (a ``Dynamic``, a ``Device``); without one, q is indexed like the DoFs.
    It has no feature: ``add`` is refused.
    """

    className = "TaskJointLimits"
    isInequality = True

    position = Input(VECTOR, doc="q: the configuration")
    referenceInf = Input(VECTOR, doc="lower position limits (size nq, or nv)")
    referenceSup = Input(VECTOR, doc="upper position limits (size nq, or nv)")
    dt = Input(DOUBLE, doc="control period (s), > 0")
    controlGain = Input(DOUBLE, default=1.0, doc="c > 0: bounds scaled by 1 / (dt c)")
    selec = Input(FLAGS, default=Flags(True), doc="bounded velocity DoFs (SoT flags)")

    @Output(VECTOR, timeDependent=False)
    def lower(self, *values: Any) -> np.ndarray:
        """Lower bound on qdot of the selected DoFs."""
        return self._bounds(*values)[0]

    @Output(VECTOR, timeDependent=False)
    def upper(self, *values: Any) -> np.ndarray:
        """Upper bound on qdot of the selected DoFs."""
        return self._bounds(*values)[1]

    @Output(VECTOR, deps=("selec", "position", "referenceInf", "referenceSup"))
    def normalizedPosition(
        self, selec: Flags, q: np.ndarray, inf: np.ndarray, sup: np.ndarray
    ) -> np.ndarray:
        """(q - inf) / (sup - inf) of the selected DoFs."""
        _, iq = self._rows(selec, q)
        lo, up = self._limits(inf, q, iq), self._limits(sup, q, iq, True)
        return (q[iq] - lo) / (up - lo)

    @Output(INT, deps=("selec", "position"))
    def activeSize(self, selec: Flags, q: np.ndarray) -> int:
        """The number of bounded DoFs."""
        return len(self._rows(selec, q)[0])

    def __init__(self, name: str, model: pin.Model | None = None) -> None:
        if model is not None and not isinstance(model, pin.Model):
            raise CommandError(
                f"TaskJointLimits({name}): model must be a pinocchio.Model, got "
                f"{type(model).__name__}"
            )
        self._model = model
        self._maps: dict[tuple[int, Any], tuple[np.ndarray, np.ndarray, int]] = {}
        super().__init__(name)
        self.error.setFunction(self._error)
        self.jacobian.setFunction(self._jacobian)
        self.errorTimeDerivative.setFunction(self._errordot)

    # -- wiring -------------------------------------------------------------------------
    def _wire(self) -> None:
        self.error.setDependencies([self.selec, self.position])
        self.jacobian.setDependencies([self.selec, self.position, self.controlSelec])
        self.errorTimeDerivative.setDependencies([self.error])
        self._wired = []
        self._wireOutputs()

    def _wireOutputs(self) -> None:
        deps: list[Signal] = [
            self.selec,
            self.position,
            self.referenceInf,
            self.referenceSup,
            self.dt,
            self.controlGain,
        ]
        self.lower.setDependencies(deps)
        self.upper.setDependencies(deps)

    def _change(self, features: list[Any]) -> None:
        if features:
            raise CommandError(
                f"TaskJointLimits({self.name}): this task has no feature; its rows are the "
                "selected joints (selec)"
            )

    # -- computations -------------------------------------------------------------------
    def _rows(self, selec: Flags, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(velocity DoFs, their coordinates in q) of the bounded joints."""
        if not isinstance(q, np.ndarray) or q.ndim != 1:
            raise SignalTypeError(f"{self.position.name}: expected a vector, got {q!r}")
        key = (q.shape[0], selec)
        cached = self._maps.get(key)
        if cached is None:
            iv, iq, nv = self._dofs(q.shape[0])
            try:
                mask = selec.mask(nv)
                selec.rows(nv)  # refuses flags past the last DoF
            except ValueError as exc:
                raise SignalTypeError(f"{self.selec.name}: {exc}") from None
            bad = [i for i in np.flatnonzero(mask) if i not in set(iv.tolist())]
            explicit = [i for i in bad if i < len(selec)]
            if explicit:
                raise SignalTypeError(
                    f"{self.selec.name}: DoF {explicit[0]} is not a one-DoF joint (a free "
                    "flyer's, or a joint of several coordinates): it has no joint limit; "
                    "deselect it"
                )
            keep = mask[iv]
            cached = (iv[keep], iq[keep], nv)
            self._maps[key] = cached
        return cached[0], cached[1]

    def _dofs(self, nq: int) -> tuple[np.ndarray, np.ndarray, int]:
        model = self._model
        if model is None:
            holder = self.position._holder()
            m = getattr(holder.entity, "model", None)
            if isinstance(m, pin.Model) and m.nq == nq:
                model = m
        if model is None:
            return np.arange(nq), np.arange(nq), nq
        if model.nq != nq:
            raise SignalTypeError(
                f"{self.position.name}: expected a configuration of size nq = {model.nq} "
                f"(model {model.name!r}), received size {nq}"
            )
        iv, iq = [], []
        for j in range(1, model.njoints):
            jm = model.joints[j]
            if jm.nq == 1 and jm.nv == 1:
                iv.append(jm.idx_v)
                iq.append(jm.idx_q)
        return np.array(iv, dtype=int), np.array(iq, dtype=int), int(model.nv)

    def _limits(self, b: np.ndarray, q: np.ndarray, iq: np.ndarray, upper: bool = False) -> Any:
        sig = self.referenceSup if upper else self.referenceInf
        if b.shape == q.shape:
            return b[iq]
        iv, _ = self._rows(self.selec.value, q)
        nv = self._maps[(q.shape[0], self.selec.value)][2]
        if b.shape == (nv,):
            return b[iv]
        raise SignalTypeError(
            f"{sig.name}: expected a vector of the size of {self.position.name} "
            f"({q.shape[0]}) or of nv ({nv}), received size {b.shape[0]}"
        )

    def _error(self, selec: Flags, q: np.ndarray) -> np.ndarray:
        _, iq = self._rows(selec, q)
        return q[iq].copy()

    def _jacobian(self, selec: Flags, q: np.ndarray, controlSelec: Flags) -> np.ndarray:
        iv, _ = self._rows(selec, q)
        nv = self._maps[(q.shape[0], selec)][2]
        J = np.zeros((len(iv), nv))
        J[np.arange(len(iv)), iv] = 1.0
        cols = controlSelec.rows(nv)
        if cols is not None:
            J *= controlSelec.mask(nv)
        return J

    def _errordot(self, e: np.ndarray) -> np.ndarray:
        return np.zeros(e.shape[0])

    def _bounds(
        self,
        selec: Flags,
        q: np.ndarray,
        inf: np.ndarray,
        sup: np.ndarray,
        dt: float,
        gain: float,
    ) -> tuple[np.ndarray, np.ndarray]:
        if not 0.0 < dt < np.inf:
            raise SignalTypeError(f"{self.dt.name}: expected a control period > 0 (s), got {dt}")
        if not 0.0 < gain < np.inf:
            raise SignalTypeError(f"{self.controlGain.name}: expected a gain > 0, got {gain}")
        _, iq = self._rows(selec, q)
        lo = self._limits(inf, q, iq)
        up = self._limits(sup, q, iq, True)
        k = 1.0 / (dt * gain)
        return (lo - q[iq]) * k, (up - q[iq]) * k
