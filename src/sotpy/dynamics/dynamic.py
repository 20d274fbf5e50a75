"""``Dynamic``: the kinematics and dynamics of a Pinocchio model as signals (SoT's
``DynamicPinocchio``).

::

    robot = example_robot_data.load("talos")
    dyn = Dynamic("dyn", robot.model)
    plug(device.state, dyn.position)            # q: Pinocchio configuration (size nq)
    dyn.createOpPoint("left-wrist", "arm_left_7_joint")
    dyn.signal("left-wrist").value              # pinocchio.SE3, oMf
    dyn.signal("Jleft-wrist").value             # 6 x nv, LOCAL, linear rows first
    dyn.com.value, dyn.Jcom.value               # world CoM (m) and its Jacobian

Conventions (those of :mod:`sotpy.dynamics`; SI units: m, rad, s, kg, N, N m):

- ``q`` (input ``position``, size ``nq``) is a Pinocchio configuration: for a free-flyer
  base, the base position in the world (m), then its orientation as a unit quaternion
  ``(x, y, z, w)``, then the joint positions. ``v`` (input ``velocity``) and ``a``
  (input ``acceleration``) are tangent vectors of size ``nv``: for a free-flyer base, the
  base linear velocity (m/s) then angular velocity (rad/s) **expressed in the base
  frame**, then the joint velocities; ``q ⊕ v dt = pin.integrate(model, q, v dt)``.
- An **operational point** ``createOpPoint(name, frame)`` gives two signals:

  * ``name`` (``SE3``): the placement ``oMf`` of the frame in the world: a point with
    coordinates ``p_f`` in the frame has world coordinates ``oMf * p_f`` (m);
  * ``J<name>`` (``matrix`` 6 x nv): the **LOCAL** Jacobian (the SoT's), mapping the
    joint velocity to the spatial velocity of the frame expressed in the frame itself,
    linear rows first: ``(v_f, w_f) = J v`` with ``v_f`` the velocity of the frame's
    origin (m/s) and ``w_f`` its angular velocity (rad/s), both in the frame's axes.
    Equivalently, for a small step, ``log6(oMf(q)^-1 oMf(q ⊕ dv)) = J dv + O(|dv|^2)``.

  ``createJacobian(name, frame, reference)`` gives only the Jacobian, in the chosen
  reference: ``"local"`` (as above), ``"world"`` (the spatial velocity at the world
  origin, world axes: ``(v_O, w) = J v``) or ``"local_world_aligned"`` (the velocity of
  the frame's origin and the angular velocity, in world axes); ``createPosition(name,
  frame)`` only the placement.
- ``com`` (3, m): the centre of mass ``c(q)`` in the world; ``Jcom`` (3 x nv):
  ``dc/dt = Jcom v`` (m/s), world axes. As in Pinocchio, these are of the moving bodies:
  bodies fixed to the world (a manipulator's base link) do not count, and the mass ``m``
  below is ``pinocchio.computeTotalMass(model)``.
- ``inertia`` (nv x nv): the joint-space mass matrix ``M(q)`` (CRBA), symmetric;
  ``dynamicDrift`` (nv): the nonlinear effects ``b(q, v) = C(q, v) v + g(q)``;
  ``gravity`` (nv): the generalised gravity ``g(q)``; so that the inverse dynamics is
  ``tau = M(q) a + b(q, v)`` (N, N m; for a free flyer the first six entries are the
  base wrench in the base frame, force first).
- ``momenta`` (6): the centroidal momentum ``h_G = (m dc/dt, L_G)`` (kg m/s, kg m^2/s),
  linear then angular, about the CoM and in world axes; ``angularmomentum`` (3):
  ``L_G``.
- ``zmp`` (3, m): the zero-moment point on the ground plane ``z = 0`` of the world,
  ``(x, y, 0)``, from the rate of change of the centroidal momentum at ``(q, v, a)``:
  with ``f = d(m dc/dt)/dt - m g0`` the total contact force (``g0`` the model's gravity)
  and ``n = dL_G/dt`` its moment about the CoM, ``x = c_x - (n_y + c_z f_x) / f_z`` and
  ``y = c_y + (n_x - c_z f_y) / f_z``. Undefined (an error) when ``f_z <= 0``.
- ``lowerJl``/``upperJl`` (nq): the model's position limits; ``upperVl`` (nv): the
  velocity limits, ``lowerVl = -upperVl``; ``upperTl`` (nv): the effort limits,
  ``lowerTl = -upperTl``. Pinocchio writes the largest double (``1.8e308``) where a
  URDF gives no limit. These do not depend on the tick: computed once, read-only
  arrays.

Shared computations. ``Dynamic`` holds one ``pinocchio.Data``. Each Pinocchio pass is an
internal output signal (its value is the tick at which it ran) that the public outputs
depend on, as the SoT's internal signals; a pass runs at most once per tick, and only if
an output that needs it is read:

===================================  ==========================  =======================
pass signal                          Pinocchio                   read by
===================================  ==========================  =======================
``kinematics`` (position)            computeJointJacobians,      every op point, and the
                                     updateFramePlacements       ``centerOfMass`` pass
``centerOfMass`` (kinematics)        jacobianCenterOfMass        ``com``, ``Jcom``
``crba`` (position)                  crba                        ``inertia``
``nonLinearEffects`` (pos., vel.)    nonLinearEffects            ``dynamicDrift``
``generalizedGravity`` (position)    computeGeneralizedGravity   ``gravity``
``centroidalMomentum`` (pos., vel.)  computeCentroidalMomentum   ``momenta``,
                                                                 ``angularmomentum``
``centroidalMomentumTimeVariation``  computeCentroidalMomentum-  ``zmp``
(position, velocity, acceleration)   TimeVariation
===================================  ==========================  =======================

Reading the six op points, ``com`` and ``Jcom`` of a humanoid at a tick runs one forward
kinematics (in ``computeJointJacobians``) and one CoM pass; reading only ``com`` does
not run CRBA. Every public value is a fresh copy (a ``numpy`` array, a
``pinocchio.SE3``), never a view into ``Data``, so a value cached at tick ``t`` stays
what it was when the next tick is computed.

Each pass checks its inputs before calling Pinocchio: a configuration of the wrong size
or whose quaternions are not normalised, or a velocity or acceleration of the wrong size,
raises :class:`~sotpy.errors.SignalTypeError` naming the entity, the signal, the
expected and the received size; it never reaches Pinocchio.
"""

from __future__ import annotations

import difflib
from typing import Any

import numpy as np
import pinocchio as pin

from ..errors import CommandError, EntityError, SignalNotFoundError, SignalTypeError, SotpyError
from ..graph import INT, MATRIX, VECTOR, Entity, Input, Output, OutputSignal, command
from .types import SE3

__all__ = ["Dynamic"]

#: Jacobian references accepted by :meth:`Dynamic.createJacobian`.
REFERENCES: dict[str, Any] = {
    "local": pin.LOCAL,
    "world": pin.WORLD,
    "local_world_aligned": pin.LOCAL_WORLD_ALIGNED,
}

#: Tolerance on the norm of quaternions (and other unit-norm joint coordinates) of ``q``.
NORM_TOLERANCE = 1e-6


class Dynamic(Entity):
    """Kinematics and dynamics of a Pinocchio model: op points, CoM, M(q), b(q, v).

    ``Dynamic(name, model)``: ``model`` is a ``pinocchio.Model`` (free-flyer or fixed
    base); the entity keeps its own copy, fixed at construction, and one
    ``pinocchio.Data``. See the module doc for the conventions and units.
    """

    className = "Dynamic"

    position = Input(VECTOR, doc="q: Pinocchio configuration (size nq; m, quaternion, rad)")
    velocity = Input(VECTOR, doc="v: tangent velocity (size nv; m/s, rad/s), default 0")
    acceleration = Input(VECTOR, doc="a: tangent acceleration (size nv), default 0")

    # -- passes: internal signals whose value is the tick at which they ran -----------
    @Output(INT, deps=("position",), withTime=True)
    def kinematics(self, t: int, q: np.ndarray) -> int:
        """Pass: forward kinematics, joint Jacobians and frame placements at q (tick)."""
        self._checkConfiguration(q, "kinematics")
        pin.computeJointJacobians(self.model, self.data, q)
        pin.updateFramePlacements(self.model, self.data)
        return t

    @Output(INT, deps=("kinematics",), withTime=True)
    def centerOfMass(self, t: int, _kinematics: int) -> int:
        """Pass: CoM and its Jacobian from the kinematics pass (tick)."""
        pin.jacobianCenterOfMass(self.model, self.data, False)
        return t

    @Output(INT, deps=("position",), withTime=True)
    def crba(self, t: int, q: np.ndarray) -> int:
        """Pass: joint-space mass matrix M(q) by CRBA (tick)."""
        self._checkConfiguration(q, "crba")
        pin.crba(self.model, self.data, q)
        return t

    @Output(INT, deps=("position", "velocity"), withTime=True)
    def nonLinearEffects(self, t: int, q: np.ndarray, v: np.ndarray) -> int:
        """Pass: nonlinear effects b(q, v) = C(q, v) v + g(q) (tick)."""
        self._checkConfiguration(q, "nonLinearEffects")
        self._checkTangent(v, self.velocity, "nonLinearEffects")
        pin.nonLinearEffects(self.model, self.data, q, v)
        return t

    @Output(INT, deps=("position",), withTime=True)
    def generalizedGravity(self, t: int, q: np.ndarray) -> int:
        """Pass: generalised gravity g(q) (tick)."""
        self._checkConfiguration(q, "generalizedGravity")
        pin.computeGeneralizedGravity(self.model, self.data, q)
        return t

    @Output(INT, deps=("position", "velocity"), withTime=True)
    def centroidalMomentum(self, t: int, q: np.ndarray, v: np.ndarray) -> int:
        """Pass: centroidal momentum h_G(q, v) (tick)."""
        self._checkConfiguration(q, "centroidalMomentum")
        self._checkTangent(v, self.velocity, "centroidalMomentum")
        pin.computeCentroidalMomentum(self.model, self.data, q, v)
        return t

    @Output(INT, deps=("position", "velocity", "acceleration"), withTime=True)
    def centroidalMomentumTimeVariation(
        self, t: int, q: np.ndarray, v: np.ndarray, a: np.ndarray
    ) -> int:
        """Pass: centroidal momentum and its rate of change at (q, v, a) (tick)."""
        self._checkConfiguration(q, "centroidalMomentumTimeVariation")
        self._checkTangent(v, self.velocity, "centroidalMomentumTimeVariation")
        self._checkTangent(a, self.acceleration, "centroidalMomentumTimeVariation")
        pin.computeCentroidalMomentumTimeVariation(self.model, self.data, q, v, a)
        return t

    # -- public outputs -------------------------------------------------------------------
    @Output(VECTOR, deps=("centerOfMass",))
    def com(self, _pass: int) -> np.ndarray:
        """Centre of mass c(q) in the world (m), size 3."""
        return self._com.copy()

    @Output(MATRIX, deps=("centerOfMass",))
    def Jcom(self, _pass: int) -> np.ndarray:
        """CoM Jacobian, 3 x nv: dc/dt = Jcom v (world axes)."""
        return self._Jcom.copy()

    @Output(MATRIX, deps=("crba",))
    def inertia(self, _pass: int) -> np.ndarray:
        """Joint-space mass matrix M(q), nv x nv, symmetric (kg, kg m, kg m^2)."""
        M = self._M.copy()
        if self._symmetrise:  # CRBA filled only the upper triangle
            np.copyto(M, M.T, where=self._strictlyLower)
        return M

    @Output(VECTOR, deps=("nonLinearEffects",))
    def dynamicDrift(self, _pass: int) -> np.ndarray:
        """Nonlinear effects b(q, v) = C(q, v) v + g(q), size nv (N, N m)."""
        return self._nle.copy()

    @Output(VECTOR, deps=("generalizedGravity",))
    def gravity(self, _pass: int) -> np.ndarray:
        """Generalised gravity g(q), size nv (N, N m)."""
        return self._g.copy()

    @Output(VECTOR, deps=("centroidalMomentum",))
    def momenta(self, _pass: int) -> np.ndarray:
        """Centroidal momentum (m dc/dt, L_G), size 6, about the CoM, world axes."""
        return self.data.hg.vector.copy()

    @Output(VECTOR, deps=("centroidalMomentum",))
    def angularmomentum(self, _pass: int) -> np.ndarray:
        """Angular momentum L_G about the CoM, world axes (kg m^2/s), size 3."""
        return self.data.hg.angular.copy()

    @Output(VECTOR, deps=("centroidalMomentumTimeVariation",))
    def zmp(self, _pass: int) -> np.ndarray:
        """Zero-moment point (x, y, 0) on the world plane z = 0 (m)."""
        data = self.data
        c = self._com
        dhg = data.dhg
        f = dhg.linear - self._mass * self._gravity0
        n = dhg.angular
        fz = f[2]
        if not fz > 0.0:
            raise SotpyError(
                f"{self.signal('zmp').name}: the vertical contact force is f_z = {fz:.6g} N "
                "<= 0 (the robot would pull on the ground, or falls freely): the ZMP is "
                "undefined"
            )
        return np.array([c[0] - (n[1] + c[2] * f[0]) / fz, c[1] + (n[0] - c[2] * f[1]) / fz, 0.0])

    # -- limits: no dependencies, computed once ---------------------------------------
    @Output(VECTOR, timeDependent=False)
    def lowerJl(self) -> np.ndarray:
        """Lower position limits of the model, size nq."""
        return _frozen(self.model.lowerPositionLimit)

    @Output(VECTOR, timeDependent=False)
    def upperJl(self) -> np.ndarray:
        """Upper position limits of the model, size nq."""
        return _frozen(self.model.upperPositionLimit)

    @Output(VECTOR, timeDependent=False)
    def upperVl(self) -> np.ndarray:
        """Velocity limits of the model, size nv (m/s, rad/s)."""
        return _frozen(self.model.velocityLimit)

    @Output(VECTOR, timeDependent=False)
    def lowerVl(self) -> np.ndarray:
        """Opposite of the velocity limits, size nv (m/s, rad/s)."""
        return _frozen(-self.model.velocityLimit)

    @Output(VECTOR, timeDependent=False)
    def upperTl(self) -> np.ndarray:
        """Effort limits of the model, size nv (N, N m)."""
        return _frozen(self.model.effortLimit)

    @Output(VECTOR, timeDependent=False)
    def lowerTl(self) -> np.ndarray:
        """Opposite of the effort limits, size nv (N, N m)."""
        return _frozen(-self.model.effortLimit)

    # -- construction -----------------------------------------------------------------
    def __init__(self, name: str, model: pin.Model) -> None:
        if not isinstance(model, pin.Model):
            raise EntityError(
                f"{self.className}({name}): the second argument must be a pinocchio.Model, "
                f"got {type(model).__name__}"
            )
        self.model: pin.Model = model.copy()
        self.data: pin.Data = pin.Data(self.model)
        nq, nv = self.model.nq, self.model.nv
        self._qshape = (nq,)
        self._vshape = (nv,)
        # joints whose coordinates must have unit norm: quaternions, (cos, sin) pairs
        self._hasUnitNorm = any(j.nq != j.nv for j in self.model.joints)
        # Views into Data, fetched once: Pinocchio's algorithms write these buffers in
        # place (allocated with Data), so each public output copies from them.
        data = self.data
        self._com = data.com[0]
        self._Jcom = data.Jcom
        self._M = data.M
        self._nle = data.nle
        self._g = data.g
        # CRBA computes the upper triangle of M; Pinocchio's Python binding copies it to
        # the lower one. Check that once, and symmetrise each tick if it does not.
        self._strictlyLower = np.tri(nv, k=-1, dtype=bool)
        self._symmetrise = not _crbaIsSymmetric(self.model)
        self._mass = float(pin.computeTotalMass(self.model))  # moving bodies only
        self._gravity0 = np.array(self.model.gravity.linear)
        # op points: public name -> names of the signals created for it
        self._opPoints: dict[str, tuple[str, ...]] = {}
        for sig in (self.velocity, self.acceleration):
            sig.setDefault(np.zeros(nv))  # unplug() restores it

    # -- commands ---------------------------------------------------------------------
    @command
    def getDimension(self) -> int:
        """Dimension nv of the tangent space (the size of the velocity, the number of
        columns of the Jacobians)."""
        return int(self.model.nv)

    @command
    def frames(self) -> list[str]:
        """Names of the model's frames (joints, bodies, fixed frames), in model order."""
        return [f.name for f in self.model.frames]

    @command
    def createOpPoint(self, name: str, frame: str) -> None:
        """Create the outputs ``name`` (SE3, the placement oMf of ``frame``) and
        ``J<name>`` (6 x nv LOCAL Jacobian, linear rows first).

        ``frame`` is a Pinocchio frame name (joint names are frames too).
        """
        fid = self._frameId("createOpPoint", frame)
        self._checkFree("createOpPoint", name, (name, "J" + name))
        sigs = (
            self._placementSignal(name, frame, fid),
            self._jacobianSignal("J" + name, frame, fid, "local"),
        )
        self._addOpPoint(name, sigs)

    @command
    def createJacobian(self, name: str, frame: str, reference: str = "local") -> None:
        """Create the output ``name``: the 6 x nv Jacobian of ``frame`` in
        ``reference`` (``"local"``, ``"world"`` or ``"local_world_aligned"``), linear
        rows first."""
        if reference not in REFERENCES:
            raise CommandError(
                f"{self.className}({self.name}).createJacobian: argument 'reference': "
                f"expected one of {', '.join(map(repr, REFERENCES))}, got {reference!r}"
            )
        fid = self._frameId("createJacobian", frame)
        self._checkFree("createJacobian", name, (name,))
        self._addOpPoint(name, (self._jacobianSignal(name, frame, fid, reference),))

    @command
    def createPosition(self, name: str, frame: str) -> None:
        """Create the output ``name`` (SE3): the placement oMf of ``frame``."""
        fid = self._frameId("createPosition", frame)
        self._checkFree("createPosition", name, (name,))
        self._addOpPoint(name, (self._placementSignal(name, frame, fid),))

    @command
    def destroyOpPoint(self, name: str) -> None:
        """Remove the outputs made by ``createOpPoint(name, ...)`` (``name`` and
        ``J<name>``), ``createJacobian(name, ...)`` or ``createPosition(name, ...)``."""
        sigs = self._opPoints.get(name)
        if sigs is None:
            known = ", ".join(sorted(self._opPoints)) or "none"
            raise SignalNotFoundError(
                f"{self.className}({self.name}).destroyOpPoint: no op point {name!r} "
                f"(op points: {known})"
            )
        for s in sigs:
            self.removeSignal(s)
        del self._opPoints[name]

    # -- helpers ----------------------------------------------------------------------
    def _frameId(self, cmd: str, frame: str) -> int:
        model = self.model
        if frame and model.existFrame(frame):
            return int(model.getFrameId(frame))
        names = list(dict.fromkeys(f.name for f in model.frames))
        close = difflib.get_close_matches(frame, names, n=5, cutoff=0.5)
        hint = (
            f"close names: {', '.join(close)}"
            if close
            else f"the model has {len(names)} frames, e.g. {', '.join(names[1:6])}"
        )
        raise CommandError(
            f"{self.className}({self.name}).{cmd}: argument 'frame': no frame named "
            f"{frame!r} in model {model.name!r} ({hint}; frames() lists them all)"
        )

    def _checkFree(self, cmd: str, name: str, signals: tuple[str, ...]) -> None:
        if not name or name.strip() != name:
            raise CommandError(
                f"{self.className}({self.name}).{cmd}: argument 'name': expected a non-empty "
                f"name without surrounding spaces, got {name!r}"
            )
        if name in self._opPoints:
            raise EntityError(
                f"{self.className}({self.name}).{cmd}: an op point named {name!r} already "
                "exists (destroyOpPoint removes it)"
            )
        for s in signals:
            if self.hasSignal(s):
                raise EntityError(
                    f"{self.className}({self.name}).{cmd}: cannot create signal {s!r}: a "
                    "signal of that name already exists"
                )

    def _addOpPoint(self, name: str, sigs: tuple[OutputSignal, ...]) -> None:
        added: list[str] = []
        try:
            for s in sigs:
                self.addSignal(s)
                added.append(s.shortName)
        except BaseException:
            for n in added:
                self.removeSignal(n)
            raise
        self._opPoints[name] = tuple(added)

    def _placementSignal(self, name: str, frame: str, fid: int) -> OutputSignal:
        model, data = self.model, self.data
        updateFramePlacement = pin.updateFramePlacement

        def placement(_pass: int) -> pin.SE3:
            # data.oMf[fid] as the kinematics pass left it, recomputed (the same product
            # oMi[parent] * placement) and returned as a new SE3: 0.17 us against 0.46
            # for oMf[fid].copy()
            return updateFramePlacement(model, data, fid)

        return OutputSignal(
            self,
            name,
            SE3,
            placement,
            (self.kinematics,),
            doc=f"placement oMf of frame {frame!r} in the world (m)",
        )

    def _jacobianSignal(self, name: str, frame: str, fid: int, reference: str) -> OutputSignal:
        model, data, ref = self.model, self.data, REFERENCES[reference]
        getFrameJacobian = pin.getFrameJacobian

        def jacobian(_pass: int) -> np.ndarray:
            return getFrameJacobian(model, data, fid, ref)  # a new array

        return OutputSignal(
            self,
            name,
            MATRIX,
            jacobian,
            (self.kinematics,),
            doc=f"{reference.upper()} Jacobian of frame {frame!r}, 6 x nv, linear rows first",
        )

    def _checkConfiguration(self, q: Any, pass_: str) -> None:
        """Raise SignalTypeError unless ``q`` is a configuration of this model."""
        shape = getattr(q, "shape", None)
        if shape != self._qshape:
            self._sizeError(self.position, q, self.model.nq, "nq", pass_)
        if self._hasUnitNorm and not pin.isNormalized(self.model, q, NORM_TOLERANCE):
            model = self.model
            neutral = pin.neutral(model)
            bad = []
            for j, jm in enumerate(model.joints):
                if jm.nq != jm.nv:  # test this joint's coordinates alone
                    part = slice(jm.idx_q, jm.idx_q + jm.nq)
                    alone = neutral.copy()
                    alone[part] = q[part]
                    if not pin.isNormalized(model, alone, NORM_TOLERANCE):
                        bad.append(f"{model.names[j]} (q[{part.start}:{part.stop}])")
            raise SignalTypeError(
                f"{self.position.name}: the configuration is not normalised (reading it for "
                f"{self.signal(pass_).name}): the unit quaternions / (cos, sin) pairs of "
                f"joints {', '.join(bad)} have a norm differing from 1 by more than "
                f"{NORM_TOLERANCE:g}; use pinocchio.neutral, pinocchio.integrate or "
                "pinocchio.normalize"
            )

    def _checkTangent(self, v: Any, sig: Any, pass_: str) -> None:
        if getattr(v, "shape", None) != self._vshape:
            self._sizeError(sig, v, self.model.nv, "nv", pass_)

    def _sizeError(self, sig: Any, value: Any, n: int, what: str, pass_: str) -> None:
        shape = getattr(value, "shape", None)
        got = (
            f"size {shape[0]}"
            if shape is not None and len(shape) == 1
            else f"shape {shape}"
            if shape is not None
            else f"a {type(value).__name__}"
        )
        raise SignalTypeError(
            f"{sig.name}: expected a vector of size {what} = {n} for model "
            f"{self.model.name!r}, received {got} (reading it for "
            f"{self.signal(pass_).name})"
        )


def _crbaIsSymmetric(model: pin.Model) -> bool:
    """Whether ``pin.crba`` returns the full symmetric matrix (checked at a generic
    configuration, on a scratch ``Data``)."""
    rng = np.random.default_rng(0)
    q = pin.integrate(model, pin.neutral(model), rng.uniform(-0.5, 0.5, model.nv))
    M = pin.crba(model, pin.Data(model), q)
    upper = np.triu(M, 1)
    return bool(np.any(upper != 0.0)) and np.array_equal(M, M.T)


def _frozen(a: Any) -> np.ndarray:
    """A read-only copy of ``a`` (a value computed once and shared by every tick)."""
    out = np.array(a, dtype=float)
    out.flags.writeable = False
    return out
