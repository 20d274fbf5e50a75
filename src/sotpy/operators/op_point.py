"""Operational-point tools: a frame rigidly attached to another, and the joint limitator.

SoT's ``OpPointModifier`` (``sot-core/src/math/op-point-modifier.cpp``) and
``JointLimitator`` (``sot-core/src/tools/joint-limitator.cpp``), with their class,
signal and command names:

=====================  ==========================================  ========================
class                  signals                                     computes
=====================  ==========================================  ========================
``OpPointModifier``    positionIN (SE3), jacobianIN -> position,   the frame b = a * aMb
                       jacobian
``JointLimitator``     joint, upperJl, lowerJl, controlIN, dt ->   the control, each joint
                       control, widthJl                            stopped at its limit
=====================  ==========================================  ========================
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pinocchio as pin

from ..dynamics.types import SE3, homogeneousToSE3
from ..errors import CommandError, SignalTypeError
from ..graph import DOUBLE, MATRIX, VECTOR, Entity, Input, Output, command
from ._util import check_matrix, check_vector, received, who

__all__ = ["JointLimitator", "OpPointModifier"]


class OpPointModifier(Entity):
    """A frame ``b`` rigidly attached to an operational point ``a``: ``oMb = oMa aMb``.

    Inputs: ``positionIN`` (SE3, ``oMa``, e.g. ``dynamic.<op>``) and ``jacobianIN``
    (6 x nv, the Jacobian of ``a``, e.g. ``dynamic.J<op>``). ``setTransformation(aMb)``
    sets the constant placement of ``b`` in ``a`` (a 4 x 4 homogeneous matrix, a tuple
    of its rows, or a ``pinocchio.SE3``; default identity). Outputs:

    - ``position = oMa * aMb`` (SE3, m);
    - ``jacobian``: with ``setEndEffector(True)`` (default) ``jacobianIN`` is the LOCAL
      Jacobian of ``a`` (sotpy's and SoT's op points) and ``jacobian = Ad(aMb^-1)
      jacobianIN``, the LOCAL Jacobian of ``b``; with ``setEndEffector(False)``
      ``jacobianIN`` is expressed at ``a``'s origin in world axes
      (``LOCAL_WORLD_ALIGNED``) and ``jacobian`` is the same for ``b``'s origin:
      ``v_b = v_a + w x (oRa aAB)``, ``w_b = w_a``.

    Its Python attribute ``activ`` (SoT's meta-tasks set it) is free for scripts.
    """

    positionIN = Input(SE3, doc="oMa: placement of the operational point a (m)")
    jacobianIN = Input(MATRIX, doc="6 x nv Jacobian of a (LOCAL, linear rows first)")

    def __init__(self, name: str) -> None:
        self._aMb = pin.SE3.Identity()
        self._bXa = self._aMb.toActionMatrixInverse()  # Ad(aMb^-1)
        self._endEffector = True
        self.activ = False

    @Output(SE3, deps=("positionIN",), doc="oMb = oMa aMb (m)")
    def position(self, oMa: pin.SE3) -> pin.SE3:
        """oMb = oMa * aMb."""
        return oMa * self._aMb

    @Output(MATRIX, deps=("positionIN", "jacobianIN"), doc="6 x nv Jacobian of b")
    def jacobian(self, oMa: pin.SE3, J: np.ndarray) -> np.ndarray:
        """The Jacobian of b (LOCAL, or at b's origin in world axes)."""
        check_matrix(self.jacobianIN, J, (6, None), "6 rows: linear then angular")
        if self._endEffector:
            return self._bXa @ J
        oAB = oMa.rotation @ self._aMb.translation
        out = J.copy()
        out[:3] += np.cross(J[3:].T, oAB).T  # v_b = v_a + w x oAB
        return out

    @command
    def setTransformation(self, aMb: Any) -> None:
        """Set aMb, the placement of b in a: a 4 x 4 homogeneous matrix (or a tuple of
        its rows, SoT's form) or a pinocchio.SE3 (m)."""
        if isinstance(aMb, pin.SE3):
            M = aMb.copy()
        else:
            try:
                M = homogeneousToSE3(aMb, who(self, "setTransformation"))
            except (TypeError, ValueError) as exc:
                raise CommandError(f"{exc}; the transformation is left unchanged") from None
        self._aMb = M
        self._bXa = M.toActionMatrixInverse()
        self.position.setReady()
        self.jacobian.setReady()

    @command
    def getTransformation(self) -> np.ndarray:
        """aMb as a 4 x 4 homogeneous matrix (a copy)."""
        return self._aMb.homogeneous.copy()

    @command
    def setEndEffector(self, endEffector: bool) -> None:
        """True (default): jacobianIN and jacobian are LOCAL; False: at the frame's
        origin in world axes."""
        self._endEffector = endEffector
        self.jacobian.setReady()

    @command
    def getEndEffector(self) -> bool:
        """Whether the Jacobians are LOCAL (see setEndEffector)."""
        return self._endEffector


class JointLimitator(Entity):
    """Stop each joint at its limits: ``control_i = controlIN_i`` unless one period of
    it would take joint ``i`` out of ``[lowerJl, upperJl]``, then 0 (SoT's rule).

    ``JointLimitator(name, model=None)``. Inputs: ``joint`` (q), ``upperJl`` and
    ``lowerJl`` (the limits, size of q: plug ``dynamic.upperJl``/``lowerJl``),
    ``controlIN`` (the joint velocity, size nv), ``dt`` (the period over which the
    next position is predicted, s; SoT's hard-coded 0.005 by default). For velocity
    component ``i`` of a one-DoF joint with coordinate ``k``: ``q_k + controlIN_i dt``
    must lie strictly inside ``(lowerJl_k, upperJl_k)``; the other components (a free
    flyer's) pass. Outputs ``control`` and ``widthJl = upperJl - lowerJl``.

    The map from velocity to configuration indices comes from ``model`` (a
    ``pinocchio.Model``), or else from the model of the entity whose signal ``joint``
    is plugged to (a ``Dynamic``'s ``position``, a ``Device``'s ``state``); without a
    model, ``joint`` and ``controlIN`` must have the same size and every component is
    limited.
    """

    joint = Input(VECTOR, doc="q: the configuration")
    upperJl = Input(VECTOR, doc="upper limits (size of q)")
    lowerJl = Input(VECTOR, doc="lower limits (size of q)")
    controlIN = Input(VECTOR, doc="joint velocity to limit (size nv)")
    dt = Input(DOUBLE, default=0.005, doc="prediction period (s)")

    def __init__(self, name: str, model: pin.Model | None = None) -> None:
        if model is not None and not isinstance(model, pin.Model):
            raise CommandError(
                f"JointLimitator({name}): model must be a pinocchio.Model, got "
                f"{type(model).__name__}"
            )
        self._model = model
        self._maps: dict[tuple[int, int], tuple[np.ndarray, np.ndarray]] = {}

    @Output(VECTOR, deps=("upperJl", "lowerJl"), doc="upperJl - lowerJl")
    def widthJl(self, u: np.ndarray, l: np.ndarray) -> np.ndarray:  # noqa: E741
        """Width of each joint range."""
        check_vector(self.lowerJl, l, u.shape[0], "the size of upperJl")
        return u - l

    @Output(VECTOR, deps=("joint", "upperJl", "lowerJl", "controlIN", "dt"), doc="limited control")
    def control(
        self,
        q: np.ndarray,
        u: np.ndarray,
        l: np.ndarray,  # noqa: E741
        v: np.ndarray,
        dt: float,
    ) -> np.ndarray:
        """controlIN with the components that would cross a limit in dt set to 0."""
        check_vector(self.joint, q)
        check_vector(self.upperJl, u, q.shape[0], "the size of joint")
        check_vector(self.lowerJl, l, q.shape[0], "the size of joint")
        check_vector(self.controlIN, v)
        if not dt > 0.0:
            raise SignalTypeError(f"{self.dt.name}: expected a period > 0 s, got {dt}")
        iv, iq = self._map(q.shape[0], v.shape[0])
        out = v.copy()
        qnext = q[iq] + v[iv] * dt
        stop = ~((qnext < u[iq]) & (qnext > l[iq]))
        out[iv[stop]] = 0.0
        return out

    def _map(self, nq: int, nv: int) -> tuple[np.ndarray, np.ndarray]:
        """(velocity indices, configuration indices) of the limited components."""
        key = (nq, nv)
        cached = self._maps.get(key)
        if cached is not None:
            return cached
        model = self._model or self._modelOf(nq, nv)
        if model is not None:
            if (model.nq, model.nv) != key:
                raise SignalTypeError(
                    f"{self.joint.name} and {self.controlIN.name}: expected sizes nq = "
                    f"{model.nq} and nv = {model.nv} (model {model.name!r}), received "
                    f"{nq} and {nv}"
                )
            iv, iq = [], []
            for j in range(1, model.njoints):
                jm = model.joints[j]
                if jm.nq == 1 and jm.nv == 1:
                    iv.append(jm.idx_v)
                    iq.append(jm.idx_q)
            out = (np.array(iv, dtype=int), np.array(iq, dtype=int))
        elif nq == nv:
            out = (np.arange(nv), np.arange(nq))
        else:
            raise SignalTypeError(
                f"{who(self, 'control')}: {self.joint.name} has {nq} entries and "
                f"{self.controlIN.name} {nv} ({received(np.zeros(nq))} against "
                f"{received(np.zeros(nv))}): a configuration with quaternions; give the "
                "model: JointLimitator(name, model), or plug joint from a Dynamic or a Device"
            )
        self._maps[key] = out
        return out

    def _modelOf(self, nq: int, nv: int) -> pin.Model | None:
        """The model of the entity ``joint`` reads from, if it has one of these sizes."""
        holder = self.joint._holder()
        model = getattr(holder.entity, "model", None)
        if isinstance(model, pin.Model) and (model.nq, model.nv) == (nq, nv):
            return model
        return None
