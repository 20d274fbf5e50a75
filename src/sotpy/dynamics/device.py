"""The simulated robot: SoT's ``Device``, integrating its control over a Pinocchio model.

A :class:`Device` holds the configuration ``q`` (signal ``state``, size ``nq``) and the
velocity ``v`` (signal ``velocity``, size ``nv``) of a robot described by a
``pinocchio.Model``. Each call of ``increment(dt)`` drives one tick of the graph, in
SoT's order::

    t = state.time                      (-1, never written, counts as 0)
    before.run(t)                       periodic calls (PeriodicCall)
    u = control(t)                      pulls the graph through a compiled Plan
    check u (size, finite), clamp it    errors leave the state unchanged
    (q+, v+) = integrate(q, v, u, dt)   see below
    clamp q+ to the position bounds
    state.write(q+, t + 1); velocity.write(v+, t + 1)
    after.run(t + 1)                    tracers hang here

so a controller that reads ``state`` at ``t`` produces the control applied from ``t`` to
``t + 1``: the state breaks the feedback loop.

Units: configurations in m and rad (the free-flyer as position then unit quaternion
``(x, y, z, w)``, Pinocchio's layout), velocities in m/s and rad/s (the free-flyer's
linear then angular velocity, expressed in the base frame), accelerations in m/s^2 and
rad/s^2, joint torques in N m (N for prismatic joints), contact wrenches in N and N m,
``dt`` in s.

Control types (``setControlType``)
----------------------------------
``'velocity'`` (default; SoT's ``'oneInteg'``)
    ``u = v``, size ``nv``. Explicit Euler on the configuration manifold::

        v+ = clamp_v(u)
        q+ = q (+) v+ dt

``'acceleration'`` (SoT's ``'twoInteg'``)
    ``u = dv/dt``, size ``nv``. Semi-implicit (symplectic) Euler::

        v+ = clamp_v(v + u dt)
        q+ = q (+) v+ dt

    (SoT's C++ device advanced the position with ``v + u dt / 2``; this one uses the new
    velocity, the usual choice for simulators.)

``'torque'``
    ``u = tau``, the torques of the actuated joints: size ``nv - 6`` with a free-flyer
    (the base is not actuated), ``nv`` for a fixed base. With ``tau_full = (0_6, tau)``
    (or ``tau``), the acceleration is the one of the rigid-body dynamics::

        M(q) a + b(q, v) = tau_full + sum_c J_c(q)^T f_c

    * without contacts: ``a = ABA(q, v, tau_full)`` (``pinocchio.aba``); a free-floating
      robot falls;
    * with the contacts set by ``setContacts(frames)``: ``a`` and the contact wrenches
      ``f_c`` solve Pinocchio's constrained dynamics (``pinocchio.constraintDynamics``)
      with one 6-D rigid contact per frame, the frame held at the placement it had when
      ``setContacts`` was called (or ``set`` teleported the robot), and the contact
      acceleration required to be ``-Kp e - Kd de/dt``, where ``e`` is the placement
      error (Baumgarte stabilisation, gains of ``setContactGains``, default
      ``Kp = 100 s^-2``, ``Kd = 20 s^-1``, critically damped), so the contacts do not
      drift. The proximal solver runs with accuracy 1e-12, ``mu = 1e-8`` and at most
      10 iterations, so a redundant set of contacts still has a (least-norm) solution.

    * on a floor set by ``setFloor(patches, floor)`` (the default of the torque demos
      and tests): each sole (:class:`~sotpy.dynamics.contact.FootPatch`, a grid of
      points) touches a horizontal floor through unilateral contacts with Coulomb
      friction, so that a foot can lift, tilt and slide; the step is one step of MuJoCo
      on a copy of the model (:mod:`sotpy.dynamics.contact`: the floor's friction and
      stiffness, how the model is built, why MuJoCo), then the bounds below.

    then semi-implicit Euler: ``v+ = clamp_v(v + a dt)``, ``q+ = q (+) v+ dt``.

    ``setExternalWrench(frame, w)`` adds a wrench ``w`` (force then torque, N and N m,
    world axes, at the frame's origin: a push) to every torque-mode step, as the
    generalised force ``J^T w`` (``J`` the frame's LOCAL_WORLD_ALIGNED Jacobian).

``q (+) w`` is ``pinocchio.integrate``: for the free-flyer the base placement becomes
``M exp6(w)`` (the exact SE(3) exponential of the twist ``w`` expressed in the base
frame); every unit quaternion (or unit complex number) of ``q+`` is then renormalised
(``pinocchio.normalize``), so its norm stays 1 to rounding however long the run.

What the simulation assumes (torque mode)
-----------------------------------------
* on a floor (``setFloor``): MuJoCo's soft unilateral contacts (see
  :mod:`sotpy.dynamics.contact`); the rest of this list is about welded contacts;
* welded contacts (``setContacts``) are rigid and bilateral: a contact frame is welded
  to its reference placement, it pulls as well as it pushes and never breaks or slides
  (no unilateral condition, no friction cone, no limit on the contact wrench);
* no collision between bodies or with the ground besides those contacts;
* torques are held constant over ``dt``; semi-implicit Euler, first order in ``dt``
  (use ``dt`` of about 1 ms);
* the model's rotor inertias (``armature``) are used as Pinocchio's algorithms use
  them; joint friction and damping, motor dynamics and sensor noise are not simulated;
* the default Baumgarte gains suit ``dt`` of 1 to 10 ms (with zero torques Talos sags
  on its knees while its welded feet drift by 2e-6 m at 1 ms, 3e-5 m at 10 ms, over
  0.15 s; 2e-4 m without the correction); much larger steps need lower gains;
* clamping the velocity to its bounds (below) removes energy as a brake would, and with
  contacts breaks their consistency for a tick (the Baumgarte correction restores it):
  it is a safety net, reported, not a motor model.

Bounds
------
Position bounds (size ``nq``, from ``model.lowerPositionLimit``/``upperPositionLimit``)
apply to the joints with one coordinate (revolute, prismatic); the free-flyer's and
other multi-coordinate joints' entries are ignored. Velocity bounds (size ``nv``, from
``model.velocityLimit``, symmetric) and torque bounds (from ``model.effortLimit``,
symmetric) complete them. A bound that is infinite or of magnitude >= 1e300 (Pinocchio's
``max()`` for "no limit") is no bound. ``setPositionBounds``, ``setVelocityBounds`` and
``setTorqueBounds`` override them.

Each step clamps, never silently:

* the torques to the torque bounds (torque mode);
* the velocity ``v+`` to the velocity bounds (every mode: the commanded velocity, or the
  integrated one);
* the configuration ``q+`` to the position bounds, zeroing each velocity component that
  pushed its coordinate out.

Every clamped value is counted per kind and per joint (``boundsReport``); the first clamp
of each kind since the device was created or ``resetBoundsReport`` was called emits a
:class:`~sotpy.errors.SotpyWarning` naming the device, the kind and the joints (emitted
after the state is written: if warnings are turned into errors, the step is taken and
``after`` is not run). A value beyond its bound by no more than rounding
(``ROUNDING_TOLERANCE * (1 + |bound|)``, 1e-9) is clamped without being counted: a joint
resting on its limit (Talos' grippers in half-sitting) would otherwise report every tick.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Sequence
from typing import Any

import numpy as np
import pinocchio as pin

from .._jit import kernel, prepare
from ..errors import (
    CommandError,
    ContactError,
    EntityError,
    SignalTypeError,
    SimulationError,
    SotpyError,
    SotpyWarning,
)
from ..graph import VECTOR, Entity, Input, Output, OutputSignal, PeriodicCall, Plan, command
from ..graph.pool import pool
from .contact import Floor, FloorSimulator, FootPatch, PatchPoint

__all__ = [
    "BOUND_KINDS",
    "CONTROL_TYPES",
    "CONTROL_TYPE_ALIASES",
    "DEFAULT_CONTACT_KD",
    "DEFAULT_CONTACT_KP",
    "ROUNDING_TOLERANCE",
    "Device",
    "RobotSimu",
    "configurationFromRollPitchYaw",
]

#: Control types and what the control is.
CONTROL_TYPES: dict[str, str] = {
    "velocity": "the velocity v (size nv), in m/s and rad/s",
    "acceleration": "the acceleration dv/dt (size nv), in m/s^2 and rad/s^2",
    "torque": "the actuated joint torques (size nv - 6 with a free-flyer, nv for a fixed "
    "base), in N m",
}

#: SoT's names of the control types (sot-core ``Device::setControlInputType``).
#: ``'noInteg'`` (the control is the configuration) is not simulated.
CONTROL_TYPE_ALIASES: dict[str, str] = {"oneInteg": "velocity", "twoInteg": "acceleration"}

#: The kinds of bounds, in the order a step applies them.
BOUND_KINDS = ("torque", "velocity", "position")

_NO_BOUND = 1e300  # |bound| >= this, or not finite: no bound (Pinocchio uses DBL_MAX)

#: A value beyond its bound by at most ``ROUNDING_TOLERANCE * (1 + |bound|)`` is clamped
#: without being reported (rounding, e.g. a joint resting on its limit).
ROUNDING_TOLERANCE = 1e-9

#: Default Baumgarte gains of the contacts: Kp in s^-2, Kd in s^-1 (critically damped).
DEFAULT_CONTACT_KP = 100.0
DEFAULT_CONTACT_KD = 20.0


def configurationFromRollPitchYaw(model: pin.Model, q: Any) -> np.ndarray:
    """SoT's configuration of a free-flyer robot (size nv: the base's x, y, z (m), then
    roll, pitch, yaw (rad) of ``R = Rz(yaw) Ry(pitch) Rx(roll)``, then the joints) as a
    Pinocchio configuration (size nq: the base's position, its unit quaternion
    ``(x, y, z, w)``, the joints). A configuration of size nq is returned as it is.

    Raises:
        CommandError: ``q`` has neither size, or the model has no free flyer.
    """
    q = np.asarray(q, dtype=np.float64).ravel()
    if q.shape == (model.nq,):
        return q
    free = model.njoints > 1 and model.joints[1].shortname() == "JointModelFreeFlyer"
    if not free or q.shape != (model.nv,):
        raise CommandError(
            f"model {model.name!r}: expected a configuration of size nq = {model.nq}"
            + (f" or SoT's nv = {model.nv} (roll-pitch-yaw base)" if free else "")
            + f", got shape {q.shape}"
        )
    quat = pin.Quaternion(pin.rpy.rpyToMatrix(q[3], q[4], q[5])).coeffs()  # (x, y, z, w)
    return np.concatenate((q[:3], quat, q[6:]))


def _bound_array(values: np.ndarray, sign: float) -> np.ndarray:
    """A copy of ``values`` with the missing bounds (not finite, or of magnitude >=
    1e300) replaced by ``sign * inf`` (sign -1 for a lower bound, +1 for an upper one)."""
    b = np.array(values, dtype=np.float64)
    missing = ~np.isfinite(b) | (np.abs(b) >= _NO_BOUND)
    b[missing] = sign * np.inf
    return b


def _inside(x: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> bool:
    """Whether no entry of ``x`` is below ``lo`` or above ``hi`` (a NaN entry is not:
    as ``not ((x < lo) | (x > hi)).any()``). A loop: numba compiles it (not ``all()``)."""
    for i in range(x.shape[0]):  # noqa: SIM110
        if x[i] < lo[i] or x[i] > hi[i]:
            return False
    return True


def _finite(x: np.ndarray) -> bool:
    """Whether every entry of ``x`` is finite (as ``np.isfinite(x).all()``)."""
    for i in range(x.shape[0]):  # noqa: SIM110
        if not math.isfinite(x[i]):
            return False
    return True


def _inside_np(x: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> bool:
    return not ((x < lo) | (x > hi)).any()


def _finite_np(x: np.ndarray) -> bool:
    return bool(np.isfinite(x).all())


# the per-tick checks of the step: one compiled call each instead of two or three NumPy
# calls (the NumPy twins without numba)
_inside_k = kernel(_inside)
_finite_k = kernel(_finite)
_inside_c = _inside_k or _inside_np
_finite_c = _finite_k or _finite_np


def warm_up() -> None:
    """Compile the step's checks (or load them from numba's cache) for the arrays the
    device passes, so that the first tick does not pay for it."""
    if _inside_k is None or _finite_k is None:
        return
    z = np.zeros(1)
    _inside_k(z, z, z)
    _finite_k(z)


class Device(Entity):
    """Simulated robot over a Pinocchio model: integrates its control each tick.

    ``Device(name, model)`` with ``model`` a ``pinocchio.Model``. The state starts at
    ``pinocchio.neutral(model)`` with zero velocity; ``set(q)`` and ``setVelocity(v)``
    change it. ``increment(dt)`` pulls ``control`` at the state's tick, integrates over
    ``dt`` seconds and writes ``state`` and ``velocity`` one tick later. ``before`` and
    ``after`` are SoT's periodic calls (``device.after.addSignal(tracer.trigger)``).

    The maths, the units, the bounds and what the simulation assumes are in the module
    documentation (``help(sotpy.dynamics.device)``).
    """

    control = Input(
        VECTOR,
        doc="control: v (m/s, rad/s), dv/dt (m/s^2, rad/s^2) or actuated torques (N m), "
        "see setControlType",
    )
    zmp = Input(
        VECTOR,
        default=np.zeros(3),
        doc="ZMP reference (3, m, world) for a real robot's stabiliser; not simulated",
    )
    state = Output(VECTOR, doc="configuration q (size nq): m, rad, free-flyer quaternion")
    velocity = Output(VECTOR, doc="velocity v (size nv): m/s, rad/s, base frame for the base")

    def __init__(self, name: str, model: pin.Model | None = None) -> None:
        if model is None:
            raise EntityError(
                f"{self.className}({name}): a simulated device needs the robot's "
                f"pinocchio.Model: {self.className}(name, model) (SoT's {self.className}"
                "(name) then resize(n) has no model to integrate a free flyer with; "
                "load_robot(name) builds a robot's Dynamic and Device)"
            )
        if not isinstance(model, pin.Model):
            raise EntityError(
                f"Device({name}): expected a pinocchio.Model, got {type(model).__name__}"
            )
        self._model = model
        self._data = model.createData()
        self._nq, self._nv = model.nq, model.nv
        prepare("the device's checks", ["sotpy.dynamics.device"])  # now, not at a tick
        self._freeFlyer = model.njoints > 1 and model.joints[1].shortname() == "JointModelFreeFlyer"
        self._tauOffset = 6 if self._freeFlyer else 0
        self._ntau = self._nv - self._tauOffset
        self._controlType = "velocity"
        self._timeStep: float | None = None

        # joint names per configuration coordinate and per velocity component
        self._qNames = [""] * self._nq
        self._vNames = [""] * self._nv
        self._qToV = np.full(self._nq, -1, dtype=np.intp)  # -1: no scalar bound there
        scalar = np.zeros(self._nq, dtype=bool)
        for joint, jname in zip(model.joints[1:], model.names[1:], strict=True):
            for k in range(joint.nq):
                self._qNames[joint.idx_q + k] = jname if joint.nq == 1 else f"{jname}[{k}]"
            for k in range(joint.nv):
                self._vNames[joint.idx_v + k] = jname if joint.nv == 1 else f"{jname}[{k}]"
            if joint.nq == 1 and joint.nv == 1:
                scalar[joint.idx_q] = True
                self._qToV[joint.idx_q] = joint.idx_v
        self._tauNames = self._vNames[self._tauOffset :]
        self._scalarCoords = scalar

        # bounds from the model
        self._posLower = np.full(self._nq, -np.inf)
        self._posUpper = np.full(self._nq, np.inf)
        self._setPos(model.lowerPositionLimit, model.upperPositionLimit)
        self._velLower = _bound_array(-np.abs(model.velocityLimit), -1.0)
        self._velUpper = _bound_array(np.abs(model.velocityLimit), 1.0)
        effort = np.abs(np.asarray(model.effortLimit, dtype=np.float64))[self._tauOffset :]
        self._tauLower = _bound_array(-effort, -1.0)
        self._tauUpper = _bound_array(effort, 1.0)
        self._clampCounts: dict[str, dict[str, int]] = {k: {} for k in BOUND_KINDS}
        self._warned: set[str] = set()

        # contacts
        self._contactFrames: list[str] = []
        self._contactModels: Any = None
        self._contactDatas: Any = None
        self._contactKp = DEFAULT_CONTACT_KP
        self._contactKd = DEFAULT_CONTACT_KD
        self._contactForces: dict[str, np.ndarray] = {}
        self._prox = pin.ProximalSettings(1e-12, 1e-8, 10)
        self._floor: FloorSimulator | None = None
        self._externalWrenches: dict[str, np.ndarray] = {}

        self.before = PeriodicCall(f"{self.className}({name}).before")
        self.after = PeriodicCall(f"{self.className}({name}).after")
        self._controlPlan = Plan([self.control])
        self.state.write(pin.neutral(model), pool.time)
        self.velocity.write(np.zeros(self._nv), pool.time)

    # -- model -----------------------------------------------------------------------
    @property
    def model(self) -> pin.Model:
        """The Pinocchio model the device simulates (not copied: do not modify it)."""
        return self._model

    @property
    def hasFreeFlyer(self) -> bool:
        """Whether the first joint is a free-flyer (the base is not actuated)."""
        return self._freeFlyer

    # -- control type ------------------------------------------------------------------
    @command
    def setControlType(self, kind: str) -> None:
        """Set what the control is: 'velocity' (default), 'acceleration' or 'torque'

        'velocity': v, size nv (m/s, rad/s); 'acceleration': dv/dt, size nv; 'torque':
        the actuated joint torques, size nv - 6 with a free-flyer, nv for a fixed base
        (N m). SoT's names 'oneInteg' (velocity) and 'twoInteg' (acceleration) are
        accepted; 'noInteg' (the control is the configuration) is not simulated.
        """
        self._controlType = self._controlKind(kind, "setControlType")

    @command
    def setControlInputType(self, kind: str) -> None:
        """SoT's name of setControlType: 'oneInteg', 'twoInteg', or the sotpy names."""
        self._controlType = self._controlKind(kind, "setControlInputType")

    @command
    def getControlType(self) -> str:
        """The control type: 'velocity', 'acceleration' or 'torque'."""
        return self._controlType

    @command
    def getControlSize(self) -> int:
        """The size the control must have for the current control type."""
        return self._ntau if self._controlType == "torque" else self._nv

    def _controlKind(self, kind: str, cmd: str) -> str:
        kind = CONTROL_TYPE_ALIASES.get(kind, kind)
        if kind not in CONTROL_TYPES:
            known = ", ".join(repr(k) for k in CONTROL_TYPES)
            aliases = ", ".join(f"{a!r} ({k})" for a, k in CONTROL_TYPE_ALIASES.items())
            extra = (
                " ('noInteg', SoT's position control, is not simulated)"
                if kind == "noInteg"
                else ""
            )
            raise CommandError(
                f"{self._who(cmd)}: unknown control type {kind!r}{extra}; expected one of "
                f"{known}, or SoT's {aliases}; the control type is left "
                f"{self._controlType!r}"
            )
        return kind

    # -- state -------------------------------------------------------------------------
    @command
    def set(self, q: np.ndarray) -> None:
        """Set the configuration q (size nq; m, rad, free-flyer quaternion (x, y, z, w))

        The quaternions are normalised. With a free flyer, SoT's configuration of size nv
        (the base as x, y, z, roll, pitch, yaw) is accepted too and converted
        (:func:`configurationFromRollPitchYaw`). The state is written at the current tick
        (``pool.time``), so everything that reads it is recomputed at its next read. The
        contacts (``setContacts``) are re-anchored at the new frame placements.
        """
        q = np.asarray(q, dtype=np.float64)
        if self._freeFlyer and q.shape == (self._nv,):
            q = configurationFromRollPitchYaw(self._model, q)
        if q.shape != (self._nq,):
            nv = f" (or SoT's nv = {self._nv}, roll-pitch-yaw)" if self._freeFlyer else ""
            raise CommandError(
                f"{self._who('set')}: expected a configuration of size nq = {self._nq}{nv}, "
                f"got shape {q.shape}; the state is left unchanged"
            )
        if not np.isfinite(q).all():
            raise CommandError(
                f"{self._who('set')}: the configuration has non-finite entries at "
                f"{self._names(np.flatnonzero(~np.isfinite(q)), self._qNames)}; "
                "the state is left unchanged"
            )
        qn = pin.normalize(self._model, q)
        if not pin.isNormalized(self._model, qn, 1e-9):
            raise CommandError(
                f"{self._who('set')}: a quaternion (or unit complex) part of the "
                "configuration is zero and cannot be normalised; the state is left unchanged"
            )
        if self._contactFrames:
            models, datas = self._makeContacts(self._contactFrames, qn)
        self.state.write(qn, pool.time)
        if self._contactFrames:
            self._contactModels, self._contactDatas = models, datas
            self._contactForces = {}

    @command
    def setVelocity(self, v: np.ndarray) -> None:
        """Set the velocity v (size nv; m/s, rad/s; the base's in the base frame)

        Written at the current tick (``pool.time``), as ``set``.
        """
        v = np.asarray(v, dtype=np.float64)
        if v.shape != (self._nv,) or not np.isfinite(v).all():
            raise CommandError(
                f"{self._who('setVelocity')}: expected {self._nv} finite values (nv), got "
                f"shape {v.shape}; the velocity is left unchanged"
            )
        self.velocity.write(v.copy(), pool.time)

    @command
    def getTimeStep(self) -> float:
        """The time step of the last ``increment`` (or the one ``setTimeStep`` set), in s."""
        if self._timeStep is None:
            raise SotpyError(
                f"{self._who('getTimeStep')}: increment has not been called yet (and "
                "setTimeStep was not)"
            )
        return self._timeStep

    @command
    def setTimeStep(self, dt: float) -> None:
        """Set the time step getTimeStep gives until the next ``increment`` (s, > 0;
        SoT's ``RobotSimu.setTimeStep``). ``increment(dt)`` still takes its step."""
        if not (math.isfinite(dt) and dt > 0.0):
            raise CommandError(
                f"{self._who('setTimeStep')}: dt must be a finite value > 0 s, got {dt!r}"
            )
        self._timeStep = dt

    @command
    def resize(self, n: int) -> None:
        """SoT's ``resize``: the size of the state is the model's; accepted (and without
        effect) when ``n`` is nq or nv, refused otherwise."""
        if n not in (self._nq, self._nv):
            raise CommandError(
                f"{self._who('resize')}: the state of a Device has the size of its model "
                f"(nq = {self._nq}, nv = {self._nv}), got {n}; build the Device over the "
                "model you simulate (Device(name, model), or load_robot)"
            )

    # -- contacts ----------------------------------------------------------------------
    @command
    def setContacts(self, frames: list[str]) -> None:
        """Weld the frames ``frames`` (names of model frames) to their current placement

        Torque mode then simulates the constrained dynamics with one 6-D rigid bilateral
        contact per frame (see the module documentation); ``setContacts([])`` removes
        them. The reference placement of each contact is the frame's placement in the
        current state.
        """
        if isinstance(frames, str) or not isinstance(frames, (list, tuple)):
            raise CommandError(
                f"{self._who('setContacts')}: expected a list of frame names, got {frames!r}"
            )
        frames = list(frames)
        for f in frames:
            if not isinstance(f, str) or not self._model.existFrame(f):
                raise CommandError(
                    f"{self._who('setContacts')}: {f!r} is not a frame of the model; "
                    "the contacts are left unchanged"
                )
        if len(set(frames)) != len(frames):
            raise CommandError(
                f"{self._who('setContacts')}: a frame is listed twice in {frames}; "
                "the contacts are left unchanged"
            )
        if frames:
            models, datas = self._makeContacts(frames, self.state.value)
        else:
            models = datas = None
        self._contactFrames = frames
        self._contactModels, self._contactDatas = models, datas
        self._contactForces = {}
        if frames:
            self._floor = None  # welded feet or a floor, not both

    @command
    def getContacts(self) -> list[str]:
        """The contact frames (``setContacts``)."""
        return list(self._contactFrames)

    @command
    def setFloor(self, patches: Sequence[Any], floor: Floor | None = None) -> None:
        """Stand the robot on a floor (torque mode): unilateral contacts with friction

        ``patches``: the soles, each a :class:`~sotpy.dynamics.contact.FootPatch` or a
        robot's ``Foot`` (``robot.feet.values()``: its corners); ``floor``: a
        :class:`~sotpy.dynamics.contact.Floor` (friction, stiffness, height; default
        ``Floor()``). Replaces welded contacts (``setContacts``); ``setFloor([])``
        removes the floor. See :mod:`sotpy.dynamics.contact`.
        """
        if isinstance(patches, (str, FootPatch)) or not isinstance(patches, (list, tuple)):
            raise CommandError(
                f"{self._who('setFloor')}: expected a list of FootPatch (or robot feet), "
                f"got {patches!r}"
            )
        if floor is not None and not isinstance(floor, Floor):
            raise CommandError(f"{self._who('setFloor')}: expected a Floor, got {floor!r}")
        ps = [p if isinstance(p, FootPatch) else FootPatch.from_foot(p) for p in patches]
        sim = FloorSimulator(self._model, ps, floor or Floor()) if ps else None
        self._floor = sim
        if sim is not None:
            self._contactFrames = []
            self._contactModels = self._contactDatas = None
        self._contactForces = {}

    @command
    def getFloor(self) -> Floor | None:
        """The floor's settings (``setFloor``), or None."""
        return None if self._floor is None else self._floor.floor

    @command
    def getFloorPatches(self) -> list[FootPatch]:
        """The soles on the floor (``setFloor``)."""
        return [] if self._floor is None else list(self._floor.patches)

    @command
    def contactPoints(self) -> list[PatchPoint]:
        """The floor's contact points of the last torque-mode step: patch frame, point
        index, position (world, m), force on the robot (world axes, N), penetration
        (m). A point of a patch that does not touch the floor is not listed."""
        return [] if self._floor is None else list(self._floor.points)

    @command
    def setExternalWrench(self, frame: str, wrench: Any) -> None:
        """Apply ``wrench`` (6: force in N then torque in N m, world axes, at the
        frame's origin) to ``frame`` in every torque-mode step, until cleared
        (``clearExternalWrenches``, or a zero wrench)."""
        if not isinstance(frame, str) or not self._model.existFrame(frame):
            raise ContactError(
                f"{self._who('setExternalWrench')}: {frame!r} is not a frame of the model; "
                "nothing is applied"
            )
        try:
            w = np.asarray(wrench, dtype=np.float64)
        except (TypeError, ValueError):
            w = np.zeros(0)
        if w.shape != (6,) or not np.isfinite(w).all():
            raise ContactError(
                f"{self._who('setExternalWrench')}: the wrench must be 6 finite values "
                f"(force N, torque N m), got {wrench!r}; nothing is applied"
            )
        if np.any(w):
            self._externalWrenches[frame] = w.copy()
        else:
            self._externalWrenches.pop(frame, None)

    @command
    def getExternalWrenches(self) -> dict[str, np.ndarray]:
        """The wrenches applied by ``setExternalWrench``, per frame."""
        return {k: w.copy() for k, w in self._externalWrenches.items()}

    @command
    def clearExternalWrenches(self) -> None:
        """Remove every external wrench."""
        self._externalWrenches.clear()

    def _externalForces(self, q: np.ndarray) -> np.ndarray | None:
        """``sum_k J_k^T w_k`` (nv) of the external wrenches at ``q``, or None."""
        if not self._externalWrenches:
            return None
        model, data = self._model, self._data
        out = np.zeros(self._nv)
        for frame, w in self._externalWrenches.items():
            J = pin.computeFrameJacobian(
                model, data, q, model.getFrameId(frame), pin.LOCAL_WORLD_ALIGNED
            )
            out += J.T @ w
        return out

    @command
    def setContactGains(self, Kp: float, Kd: float) -> None:
        """Baumgarte gains of the contacts: Kp in s^-2, Kd in s^-1 (both >= 0)

        The contact acceleration is required to be ``-Kp e - Kd de/dt``, ``e`` the
        placement error of the contact frame. Default 100 and 20 (critically damped).
        """
        if not (0 <= Kp < math.inf and 0 <= Kd < math.inf):
            raise CommandError(
                f"{self._who('setContactGains')}: gains must be finite and >= 0, got Kp={Kp}, "
                f"Kd={Kd}"
            )
        self._contactKp, self._contactKd = Kp, Kd
        if self._contactModels is not None:
            for cm in self._contactModels:
                self._setBaumgarte(cm)

    @command
    def contactForces(self) -> dict[str, np.ndarray]:
        """The contact wrenches of the last torque-mode step, per contact frame

        Each a 6-vector (force in N, then torque in N m) exerted by the environment on
        the robot at the frame's origin, in world-aligned axes (Pinocchio's
        LOCAL_WORLD_ALIGNED): the vertical force is entry 2. The welded contacts
        (``setContacts``) or the floor's patches (``setFloor``: the sum of the patch's
        point forces, zero when it does not touch). Empty until a torque-mode step with
        contacts ran since the contacts were set.
        """
        return {k: f.copy() for k, f in self._contactForces.items()}

    def _makeContacts(self, frames: Sequence[str], q: np.ndarray) -> tuple[Any, Any]:
        model, data = self._model, self._data
        pin.framesForwardKinematics(model, data, q)
        models = pin.StdVec_RigidConstraintModel()
        for name in frames:
            fid = model.getFrameId(name)
            frame = model.frames[fid]
            cm = pin.RigidConstraintModel(
                pin.ContactType.CONTACT_6D,
                model,
                frame.parentJoint,
                frame.placement,
                0,
                data.oMf[fid].copy(),
                pin.LOCAL_WORLD_ALIGNED,
            )
            cm.name = name
            self._setBaumgarte(cm)
            models.append(cm)
        datas = pin.StdVec_RigidConstraintData()
        for cm in models:
            datas.append(cm.createData())
        pin.initConstraintDynamics(model, data, models, datas)
        return models, datas

    def _setBaumgarte(self, cm: Any) -> None:
        if hasattr(cm, "setBaumgarteCorrectorParameters"):  # Pinocchio 4
            cm.setBaumgarteCorrectorParameters(
                pin.BaumgarteCorrectorParameters(self._contactKp, self._contactKd)
            )
        else:  # pragma: no cover - Pinocchio 3
            cm.corrector.Kp[:] = self._contactKp
            cm.corrector.Kd[:] = self._contactKd

    # -- bounds ------------------------------------------------------------------------
    @command
    def setPositionBounds(self, lower: np.ndarray, upper: np.ndarray) -> None:
        """Set the position bounds, size nq (m, rad)

        Entries of the free-flyer and of other multi-coordinate joints are ignored;
        +-inf means no bound.
        """
        lower, upper = self._checkBounds("setPositionBounds", lower, upper, (self._nq,), "nq")
        self._setPos(lower, upper)

    @command
    def getPositionBounds(self) -> tuple[np.ndarray, np.ndarray]:
        """(lower, upper) position bounds used, size nq (+-inf: none)."""
        return self._posLower.copy(), self._posUpper.copy()

    @command
    def setVelocityBounds(self, lower: np.ndarray, upper: np.ndarray) -> None:
        """Set the velocity bounds, size nv (m/s, rad/s); +-inf means no bound."""
        lower, upper = self._checkBounds("setVelocityBounds", lower, upper, (self._nv,), "nv")
        self._velLower = _bound_array(lower, -1.0)
        self._velUpper = _bound_array(upper, 1.0)

    @command
    def getVelocityBounds(self) -> tuple[np.ndarray, np.ndarray]:
        """(lower, upper) velocity bounds used, size nv (+-inf: none)."""
        return self._velLower.copy(), self._velUpper.copy()

    @command
    def setTorqueBounds(self, lower: np.ndarray, upper: np.ndarray) -> None:
        """Set the torque bounds of the actuated joints (N m)

        Size nv - 6 with a free-flyer, nv for a fixed base; size nv is accepted too with
        a free-flyer (its 6 first entries, the base's, are ignored). +-inf means no
        bound.
        """
        sizes = (self._ntau, self._nv)
        lower, upper = self._checkBounds("setTorqueBounds", lower, upper, sizes, "the torques")
        if lower.shape[0] != self._ntau:
            lower, upper = lower[self._tauOffset :], upper[self._tauOffset :]
        self._tauLower = _bound_array(lower, -1.0)
        self._tauUpper = _bound_array(upper, 1.0)

    @command
    def getTorqueBounds(self) -> tuple[np.ndarray, np.ndarray]:
        """(lower, upper) torque bounds used, size of the torque control (+-inf: none)."""
        return self._tauLower.copy(), self._tauUpper.copy()

    @command
    def boundsReport(self) -> dict[str, dict[str, Any]]:
        """Clamped values since the start or ``resetBoundsReport``

        ``{kind: {"count": n, "joints": {joint: n}}}`` for kind in 'torque', 'velocity',
        'position': how many values were clamped, in total and per joint (multi-dof
        joints as ``name[k]``).
        """
        return {
            kind: {"count": sum(c.values()), "joints": dict(c)}
            for kind, c in self._clampCounts.items()
        }

    @command
    def resetBoundsReport(self) -> None:
        """Zero the clamp counts; the next clamp of each kind warns again."""
        self._clampCounts = {k: {} for k in BOUND_KINDS}
        self._warned.clear()

    def _setPos(self, lower: np.ndarray, upper: np.ndarray) -> None:
        lo = _bound_array(lower, -1.0)
        hi = _bound_array(upper, 1.0)
        lo[~self._scalarCoords] = -np.inf
        hi[~self._scalarCoords] = np.inf
        self._posLower, self._posUpper = lo, hi

    def _checkBounds(
        self, cmd: str, lower: np.ndarray, upper: np.ndarray, sizes: tuple[int, ...], what: str
    ) -> tuple[np.ndarray, np.ndarray]:
        lower = np.asarray(lower, dtype=np.float64)
        upper = np.asarray(upper, dtype=np.float64)
        expected = " or ".join(str(s) for s in sizes)
        if lower.ndim != 1 or lower.shape != upper.shape or lower.shape[0] not in sizes:
            raise CommandError(
                f"{self._who(cmd)}: expected lower and upper of size {expected} ({what}), got "
                f"shapes {lower.shape} and {upper.shape}; the bounds are left unchanged"
            )
        bad = np.flatnonzero(lower > upper)
        if bad.size:
            raise CommandError(
                f"{self._who(cmd)}: lower > upper at indices {bad.tolist()}; the bounds are "
                "left unchanged"
            )
        return lower, upper

    # -- the step ----------------------------------------------------------------------
    @command
    def increment(self, dt: float) -> None:
        """Integrate the control over dt seconds (> 0); one tick of the graph

        t = state.time; before.run(t); pull control at t; check and clamp it; integrate;
        write state and velocity at t + 1; after.run(t + 1). A control of the wrong
        size or with non-finite values raises, leaving the state unchanged.
        """
        if not (math.isfinite(dt) and dt > 0.0):
            raise CommandError(
                f"{self._who('increment')}: dt must be a finite value > 0 s, got {dt!r}"
            )
        t = self.state.time
        if t < 0:
            t = 0
        self.before.run(t)
        self._controlPlan.run(t)
        u = self._checkedControl(self.control(t), t)
        q = self.state(t)
        v = self.velocity(t)
        events: list[tuple[str, np.ndarray, np.ndarray, np.ndarray]] = []
        kind = self._controlType
        if kind == "velocity" and dt <= 1.0:
            # |v dt| <= |v|: nothing can overflow (and NumPy's error state costs 1 us)
            q_next, v_next, forces = self._step(q, v, u, dt, events)
        else:
            with np.errstate(over="ignore", invalid="ignore"):  # divergence is raised below
                q_next, v_next, forces = self._step(q, v, u, dt, events)
        if not (_finite_c(q_next) and _finite_c(v_next)):
            raise SimulationError(
                f"{self._who('increment')}: the state is no longer finite after tick {t} "
                f"({kind} control, dt = {dt} s): the simulation diverged; reduce dt or the "
                "controller gains. The state is left unchanged"
            )
        if dt != self._timeStep:  # (an entity's attribute set costs a Python call)
            self._timeStep = dt
        if forces is not None:
            self._contactForces = forces
        OutputSignal.writeMany(((self.state, q_next), (self.velocity, v_next)), t + 1)
        if events:
            self._report(events, t)
        self.after.run(t + 1)

    def _step(
        self,
        q: np.ndarray,
        v: np.ndarray,
        u: np.ndarray,
        dt: float,
        events: list[tuple[str, np.ndarray, np.ndarray, np.ndarray]],
    ) -> tuple[np.ndarray, np.ndarray, dict[str, np.ndarray] | None]:
        """(q+, v+, contact wrenches or None) after ``dt`` under the control ``u``
        (checked), clamped to the bounds; clamps are appended to ``events``."""
        kind = self._controlType
        forces: dict[str, np.ndarray] | None = None
        model = self._model
        if kind == "velocity":
            v_next = self._clamp(u.copy(), self._velLower, self._velUpper, "velocity", events)
        elif kind == "acceleration":
            v_next = self._clamp(v + u * dt, self._velLower, self._velUpper, "velocity", events)
        else:
            tau = self._clamp(u, self._tauLower, self._tauUpper, "torque", events)
            if self._tauOffset:
                tau_full = np.zeros(self._nv)
                tau_full[self._tauOffset :] = tau
            else:
                tau_full = tau
            ext = self._externalForces(q)
            if ext is not None:
                tau_full = tau_full + ext
            if self._floor is not None:
                return self._floorStep(q, v, tau_full, dt, events)
            if self._contactModels is not None:
                a = pin.constraintDynamics(
                    model,
                    self._data,
                    q,
                    v,
                    tau_full,
                    self._contactModels,
                    self._contactDatas,
                    self._prox,
                )
                forces = {
                    name: np.concatenate((cd.contact_force.linear, cd.contact_force.angular))
                    for name, cd in zip(self._contactFrames, self._contactDatas, strict=True)
                }
            else:
                a = pin.aba(model, self._data, q, v, tau_full)
            v_next = self._clamp(v + a * dt, self._velLower, self._velUpper, "velocity", events)
        q_next = pin.normalize(model, pin.integrate(model, q, v_next * dt))
        q_next = self._clampPosition(q_next, v_next, events)
        return q_next, v_next, forces

    def _floorStep(
        self,
        q: np.ndarray,
        v: np.ndarray,
        tau_full: np.ndarray,
        dt: float,
        events: list[tuple[str, np.ndarray, np.ndarray, np.ndarray]],
    ) -> tuple[np.ndarray, np.ndarray, dict[str, np.ndarray]]:
        """A torque-mode step on the floor (MuJoCo), then the velocity and position
        bounds; a clamped velocity is integrated again by ``pinocchio.integrate``."""
        sim = self._floor
        assert sim is not None
        q_sim, v_sim = sim.step(q, v, tau_full, dt)
        v_next = self._clamp(v_sim, self._velLower, self._velUpper, "velocity", events)
        if v_next is v_sim:
            q_next = pin.normalize(self._model, q_sim)
        else:
            q_next = pin.normalize(self._model, pin.integrate(self._model, q, v_next * dt))
        q_next = self._clampPosition(q_next, v_next, events)
        return q_next, v_next, {k: w.copy() for k, w in sim.wrenches.items()}

    def _checkedControl(self, u: Any, t: int) -> np.ndarray:
        n = self._ntau if self._controlType == "torque" else self._nv
        u = np.asarray(u, dtype=np.float64)
        if u.shape != (n,):
            if self._controlType == "torque":
                size = f"{n} (nv - 6, the actuated joints)" if self._tauOffset else f"{n} (nv)"
            else:
                size = f"{n} (nv)"
            raise SignalTypeError(
                f"{self.control.name}: {self._controlType} control of size {size} expected "
                f"at tick {t}, got shape {u.shape}; the state is left unchanged"
            )
        if not _finite_c(u):
            bad = ~np.isfinite(u)
            names = self._tauNames if self._controlType == "torque" else self._vNames
            raise SignalTypeError(
                f"{self.control.name}: non-finite {self._controlType} control at tick {t} for "
                f"{self._names(np.flatnonzero(bad), names)}; nothing is integrated, the "
                "state is left unchanged"
            )
        return u

    def _clamp(
        self,
        x: np.ndarray,
        lo: np.ndarray,
        hi: np.ndarray,
        kind: str,
        events: list[tuple[str, np.ndarray, np.ndarray, np.ndarray]],
    ) -> np.ndarray:
        """``x`` clamped to ``[lo, hi]`` (a new array if anything was clamped); the
        clamps larger than rounding are appended to ``events``."""
        if _inside_c(x, lo, hi):
            return x
        out = (x < lo) | (x > hi)
        clamped = np.minimum(np.maximum(x, lo), hi)
        self._record(kind, x, clamped, out, events)
        return clamped

    def _clampPosition(
        self,
        q: np.ndarray,
        v: np.ndarray,
        events: list[tuple[str, np.ndarray, np.ndarray, np.ndarray]],
    ) -> np.ndarray:
        """``q`` clamped to the position bounds; the components of ``v`` (modified in
        place) that pushed a coordinate out are zeroed."""
        lo, hi = self._posLower, self._posUpper
        if _inside_c(q, lo, hi):
            return q
        below = q < lo
        above = q > hi
        out = below | above
        clamped = np.minimum(np.maximum(q, lo), hi)
        self._record("position", q, clamped, out, events)
        for i in np.flatnonzero(out):
            j = self._qToV[i]
            if (below[i] and v[j] < 0.0) or (above[i] and v[j] > 0.0):
                v[j] = 0.0
        return clamped

    @staticmethod
    def _record(
        kind: str,
        x: np.ndarray,
        clamped: np.ndarray,
        out: np.ndarray,
        events: list[tuple[str, np.ndarray, np.ndarray, np.ndarray]],
    ) -> None:
        """Append the clamps of ``x`` larger than rounding to ``events``."""
        idx = np.flatnonzero(out)
        big = np.abs(x[idx] - clamped[idx]) > ROUNDING_TOLERANCE * (1.0 + np.abs(clamped[idx]))
        idx = idx[big]
        if idx.size:
            events.append((kind, idx, x[idx].copy(), clamped[idx]))

    def _report(self, events: list[tuple[str, np.ndarray, np.ndarray, np.ndarray]], t: int) -> None:
        for kind, idx, before, after in events:
            names = {"position": self._qNames, "velocity": self._vNames, "torque": self._tauNames}[
                kind
            ]
            counts = self._clampCounts[kind]
            for i in idx:
                counts[names[i]] = counts.get(names[i], 0) + 1
            if kind not in self._warned:
                self._warned.add(kind)
                detail = ", ".join(
                    f"{names[i]}: {b:.6g} -> {a:.6g}"
                    for i, b, a in zip(idx[:8], before[:8], after[:8], strict=True)
                )
                more = f" and {idx.size - 8} more" if idx.size > 8 else ""
                warnings.warn(
                    f"{self.className}({self.name}): {kind} bounds clamped at tick {t} for "
                    f"joints {detail}{more}; further {kind} clamps are counted in "
                    "boundsReport() without warning",
                    SotpyWarning,
                    stacklevel=5,
                )

    # -- helpers -----------------------------------------------------------------------
    def _who(self, cmd: str) -> str:
        return f"{self.className}({self.name}).{cmd}"

    @staticmethod
    def _names(idx: np.ndarray, names: list[str]) -> str:
        return ", ".join(names[i] for i in idx)


class RobotSimu(Device):
    """SoT's former name of the simulated device (``RobotSimu`` of sot-core): a
    :class:`Device` (``RobotSimu(name, model)``), the same commands and signals."""

    className = "RobotSimu"
