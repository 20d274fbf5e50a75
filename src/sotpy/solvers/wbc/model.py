r"""The robot quantities of one control tick, and the layout of the decision vector.

Decision vector (``Layout``)::

    chi = (a, tau, f_1, ..., f_p)

* ``a`` (``nv``): the tangent acceleration (m/s^2, rad/s^2; for a free flyer, the base
  linear then angular acceleration in the base frame, as Pinocchio's ``v``);
* ``tau`` (``na``): the torques of the actuated joints (N m, N); ``S`` (``na x nv``)
  selects the actuated velocities (``nv - 6`` last ones with a free flyer, all of them
  for a fixed base);
* ``f_c``: the wrench (6: force then torque, N and N m) or force (3, N) of contact
  ``c``, applied by the environment on the contact frame, expressed in the contact
  frame itself at its origin (**LOCAL**), so that its generalised force is
  ``J_c^T f_c`` with ``J_c`` the LOCAL frame Jacobian (linear rows first; the first 3
  rows for a point contact).

``RobotModel.update(q, v)`` runs the Pinocchio passes of a tick once (kinematics with
``v`` and zero acceleration for the drift terms, joint Jacobians, CRBA, nonlinear
effects, gravity, CoM) and then answers:

* ``M`` (nv x nv), ``b = C(q, v) v + g(q)`` (nv), ``g`` (nv): ``M a + b = S^T tau +
  sum_c J_c^T f_c``;
* ``frame_jacobian(fid, ref)`` and ``frame_drift(fid, ref)``: ``J`` and ``Jdot v`` of a
  frame. For ``LOCAL_WORLD_ALIGNED`` (the Cartesian tasks) the drift is the *classical*
  acceleration of the frame's origin and its angular acceleration, world axes, at zero
  joint acceleration, so that ``d/dt (J v) = J a + drift`` where ``J v`` is the origin's
  velocity and the angular velocity in world axes. For ``LOCAL`` (contacts) it is the
  *spatial* acceleration in the frame (``pin.getFrameAcceleration``), the time
  derivative of the LOCAL twist ``J v``: a contact held fixed (twist 0) needs
  ``J a + drift = 0``;
* ``com``, ``com_velocity``, ``Jcom`` (3 x nv, world), ``com_drift`` (``dJcom v``);
* ``frame_placement(fid)``: a frame's placement. The frames' placements are computed
  when read (``pin.updateFramePlacement``, for the frames a tick uses: on Talos 121
  frames would cost a microsecond a tick), so ``data.oMf[fid]`` is that frame's only
  after a read of it (``frame_placement``, a frame Jacobian or drift).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from ...errors import SotpyError

__all__ = ["BilateralContactSpec", "ContactSpec", "Layout", "RobotModel"]

LWA = pin.LOCAL_WORLD_ALIGNED
_sum = np.add.reduce
_placement = pin.updateFramePlacement  # one frame's oMf, computed and returned
_ACCELERATION = pin.KinematicLevel.ACCELERATION


@dataclass(frozen=True)
class ContactSpec:
    """A contact of the robot with the environment (unilateral, with friction).

    Attributes:
        frame: the Pinocchio frame of the contact; its z axis is the contact normal
            (pointing out of the environment, into the robot's body).
        dim: 6 (a surface contact: the wrench at the frame origin) or 3 (a point: force).
        mu: friction coefficient (> 0); the cone is approximated by the pyramid of
            ``facets`` faces inscribed in it, ``cos(2 pi k / n) f_x + sin(2 pi k / n) f_y
            <= mu cos(pi / n) f_z`` (``n = facets``, k = 0..n-1: 4 facets lose up to 29 %
            of the cone along the diagonals of the frame's axes, 8 facets 7.6 %).
        length, width: the real sole of a 6-D contact (m), a rectangle in the frame's xy
            plane, along x and y, centred at ``offset`` (m).
        fmin: minimum normal force (N, >= 0).
        margin: the CoP is kept ``margin`` (m, >= 0) inside the sole on every side (the
            constraint's rectangle is ``(length - 2 margin) x (width - 2 margin)``).
        facets: the number of faces of the friction pyramid (>= 3).
        kp, kd: feedback of the contact frame's pose and velocity in the contact
            constraint (1/s^2, 1/s, >= 0; ``kd`` None: ``2 sqrt(kp)``): the frame's LOCAL
            spatial acceleration is asked to be ``-kp e - kd nu``, ``e`` the pose error
            ``log6(M_ref^-1 M)`` from the placement the contact had when it was created
            or activated, ``nu`` its LOCAL twist (linear part only for a point contact).
    """

    frame: str
    dim: int = 6
    mu: float = 0.5
    length: float = 0.1
    width: float = 0.1
    offset: tuple[float, float] = (0.0, 0.0)
    fmin: float = 0.0
    margin: float = 0.0
    facets: int = 8
    kp: float = 0.0
    kd: float | None = None

    @property
    def half_sizes(self) -> tuple[float, float]:
        """``(X, Y)``: the half-lengths (m) of the CoP's rectangle (the sole minus the
        margin)."""
        return self.length / 2 - self.margin, self.width / 2 - self.margin

    @property
    def gains(self) -> tuple[float, float]:
        """``(kp, kd)`` of the contact feedback (``kd`` defaulted)."""
        return self.kp, (2.0 * math.sqrt(self.kp) if self.kd is None else self.kd)

    @property
    def key(self) -> str:
        """The contact's name in the layout and the commands: its frame."""
        return self.frame

    bilateral = False


@dataclass(frozen=True)
class BilateralContactSpec:
    r"""A rigid (bilateral) contact between two frames of the robot: their relative
    placement stays constant (a closed kinematic loop: hands holding each other, a
    gripper bolted to a fixture carried by the robot).

    With ``M = B^{-1} A`` (the placement of ``frame_a`` in ``frame_b``) and the LOCAL
    twists ``nu_A = J_A v``, ``nu_B = J_B v``, the relative twist of B with respect to A,
    in B's frame, is ``nu_rel = nu_B - Ad_M nu_A``; its derivative is::

        d/dt nu_rel = J_rel a + drift_rel,   J_rel = J_B - Ad_M J_A,
        drift_rel = Jdot_B v - Ad_M Jdot_A v + ad(nu_B) Ad_M nu_A

    (``Jdot v`` the LOCAL spatial drifts; ``d/dt Ad_M = Ad_M ad(nu_A) - ad(nu_B) Ad_M``).
    The constraint is ``J_rel a + drift_rel = 0``, and the contact's decision variable
    is the **interaction wrench** ``f`` (6: force then torque) exerted by A's body on
    B's, in B's frame at its origin; the reaction on A is ``-Ad_M^T f``, so the
    generalised force is ``J_rel^T f`` (the power ``f . nu_rel``). No friction or
    unilateral condition: any wrench (a wrench task can ask for a squeeze).

    Attributes:
        frame_a, frame_b: the two Pinocchio frames (different).
        name: the contact's key (default ``"frame_a|frame_b"``).
    """

    frame_a: str
    frame_b: str
    name: str = ""
    dim = 6
    bilateral = True

    @property
    def key(self) -> str:
        return self.name or f"{self.frame_a}|{self.frame_b}"

    @property
    def frame(self) -> str:  # the layout's key, as ContactSpec.frame
        return self.key


class Layout:
    """Where each block of ``chi = (a, tau, f_1..f_p)`` lives."""

    def __init__(self, nv: int, na: int, contacts: list) -> None:
        self.nv = nv
        self.na = na
        self.contacts = list(contacts)
        self.a = slice(0, nv)
        self.tau = slice(nv, nv + na)
        self.f: dict[str, slice] = {}
        i = nv + na
        for c in self.contacts:
            self.f[c.key] = slice(i, i + c.dim)
            i += c.dim
        self.nf = i - nv - na
        self.n = i

    def __repr__(self) -> str:
        return f"Layout(nv={self.nv}, na={self.na}, contacts={[c.key for c in self.contacts]})"


class RobotModel:
    """A Pinocchio model and its data, updated once per tick at ``(q, v)``.

    Actuated joints: every joint but a free-flyer root (``S = [0 | I]``); a model whose
    root is a free flyer has ``na = nv - 6``, a fixed-base model ``na = nv``.
    """

    def __init__(self, model: pin.Model) -> None:
        self.model = model
        self.data = pin.Data(model)
        self.nq, self.nv = model.nq, model.nv
        root = model.joints[1] if model.njoints > 1 else None
        self.free_flyer = bool(root is not None and root.shortname() == "JointModelFreeFlyer")
        self.actuated = np.arange(6 if self.free_flyer else 0, self.nv)
        self.na = len(self.actuated)
        self.S = np.zeros((self.na, self.nv))
        self.S[np.arange(self.na), self.actuated] = 1.0
        self.minus_St = -self.S.T  # the torque columns of the equations of motion
        self._strict_lower = np.tril(np.ones((self.nv, self.nv), dtype=bool), -1)
        self._M = np.zeros((self.nv, self.nv))
        self._M_stale = True
        self.b = np.zeros(self.nv)
        # per-tick caches of the contact Jacobians and drifts (cleared by update)
        self._jac: dict[str, np.ndarray] = {}
        self._drift: dict[str, np.ndarray] = {}
        self._g: np.ndarray | None = None
        self._gdata: pin.Data | None = None
        self.dt = 0.001  # the control period of the tick (s), set by the controller
        self.mass = float(pin.computeTotalMass(model))
        self._weight = self.mass * float(np.linalg.norm(model.gravity.linear))
        self._fids: dict[str, int] = {}  # frame name -> id (the model is fixed)
        self.q: np.ndarray | None = None
        self.v: np.ndarray | None = None
        # joint position coordinates of the actuated one-dimensional joints
        iq, iv = [], []
        for j in range(1, model.njoints):
            jm = model.joints[j]
            if jm.nq == 1 and jm.nv == 1:
                iq.append(jm.idx_q)
                iv.append(jm.idx_v)
        self.iq1 = np.array(iq, dtype=int)
        self.iv1 = np.array(iv, dtype=int)

    def frame_id(self, frame: str, who: str = "RobotModel") -> int:
        """The id of ``frame``; raises SotpyError naming ``who`` if it does not exist."""
        fid = self._fids.get(frame)
        if fid is None:
            if not self.model.existFrame(frame):
                raise SotpyError(f"{who}: the model has no frame named {frame!r}")
            fid = self._fids[frame] = int(self.model.getFrameId(frame))
        return fid

    def update(self, q: np.ndarray, v: np.ndarray) -> None:
        """Run the Pinocchio passes at ``(q, v)`` (sizes nq, nv, finite)."""
        q = np.asarray(q, dtype=float)
        v = np.asarray(v, dtype=float)
        if q.shape != (self.nq,) or v.shape != (self.nv,):
            raise SotpyError(
                f"RobotModel.update: expected q of size {self.nq} and v of size {self.nv},"
                f" got {q.shape} and {v.shape}"
            )
        if not math.isfinite(_sum(q) + _sum(v)) and not (
            np.isfinite(q).all() and np.isfinite(v).all()  # the sum overflowed, or not
        ):
            raise SotpyError("RobotModel.update: q or v is not finite")
        m, d = self.model, self.data
        # M (upper), nle, joint Jacobians, com, Jcom; and data.v, data.a at a = 0 (the
        # bias of its forward pass: the drifts), as forwardKinematics(q, v, 0) would leave
        # them (tests/test_wbc_core.py checks it)
        pin.computeAllTerms(m, d, q, v)
        pin.centerOfMass(m, d, _ACCELERATION, False)  # vcom, acom of data.a (dJcom v)
        self._M_stale = True
        np.copyto(self.b, d.nle)
        self._g = None
        self._jac.clear()
        self._drift.clear()
        self.q = q.copy()
        self.v = v.copy()

    @property
    def M(self) -> np.ndarray:
        """The joint-space inertia ``M(q)`` (nv x nv, symmetric) at the last
        :meth:`update` (built when first read after it; do not modify it)."""
        if self._M_stale:
            self.write_mass_matrix(self._M)
            self._M_stale = False
        return self._M

    def write_mass_matrix(self, out: np.ndarray) -> None:
        """Write ``M(q)`` into ``out`` (nv x nv, a view may be strided): Pinocchio's upper
        triangle, mirrored."""
        np.copyto(out, self.data.M)
        np.copyto(out, out.T, where=self._strict_lower)

    @property
    def g(self) -> np.ndarray:
        """Generalised gravity ``g(q)`` (nv, N m or N) at the last :meth:`update`,
        computed on first use (a fallback or a removed-gravity command needs it)."""
        if self._g is None:
            if self.q is None:
                raise SotpyError("RobotModel.g: the robot state was never set (update(q, v))")
            if self._gdata is None:  # its own data: the tick's kinematics stay untouched
                self._gdata = pin.Data(self.model)
            self._g = pin.computeGeneralizedGravity(self.model, self._gdata, self.q).copy()
        return self._g

    # -- frames -------------------------------------------------------------------------
    def frame_placement(self, fid: int) -> pin.SE3:
        """The placement of frame ``fid`` at the last :meth:`update` (a copy; computed
        now, with ``data.oMf[fid]``)."""
        return pin.SE3(_placement(self.model, self.data, fid))

    def frame_jacobian(self, fid: int, ref: pin.ReferenceFrame = LWA) -> np.ndarray:
        return pin.getFrameJacobian(self.model, self.data, fid, ref)

    def frame_velocity(self, fid: int, ref: pin.ReferenceFrame = LWA) -> np.ndarray:
        return pin.getFrameVelocity(self.model, self.data, fid, ref).vector.copy()

    def frame_drift(self, fid: int, ref: pin.ReferenceFrame = LWA) -> np.ndarray:
        if ref == LWA:
            return pin.getFrameClassicalAcceleration(self.model, self.data, fid, LWA).vector.copy()
        return pin.getFrameAcceleration(self.model, self.data, fid, ref).vector.copy()

    def contact_jacobian(self, c: ContactSpec | BilateralContactSpec) -> np.ndarray:
        """``J_c`` (dim x nv): LOCAL frame Jacobian (first ``dim`` rows) of a contact, or
        ``J_rel`` of a bilateral one (:class:`BilateralContactSpec`); computed once per
        :meth:`update` (do not modify it)."""
        J = self._jac.get(c.key)
        if J is None:
            J = self._jac[c.key] = self._contact_jacobian(c)
        return J

    def _contact_jacobian(self, c: ContactSpec | BilateralContactSpec) -> np.ndarray:
        if not c.bilateral:
            return self.frame_jacobian(self.frame_id(c.frame), pin.LOCAL)[: c.dim]
        fa, fb = self.frame_id(c.frame_a), self.frame_id(c.frame_b)
        m, d = self.model, self.data
        M = _placement(m, d, fb).actInv(_placement(m, d, fa))
        return self.frame_jacobian(fb, pin.LOCAL) - M.action @ self.frame_jacobian(fa, pin.LOCAL)

    def contact_drift(self, c: ContactSpec | BilateralContactSpec) -> np.ndarray:
        """``Jdot_c v`` (LOCAL spatial drift; ``drift_rel`` of a bilateral contact); once
        per :meth:`update` (do not modify it)."""
        dr = self._drift.get(c.key)
        if dr is None:
            dr = self._drift[c.key] = self._contact_drift(c)
        return dr

    def _contact_drift(self, c: ContactSpec | BilateralContactSpec) -> np.ndarray:
        if not c.bilateral:
            return self.frame_drift(self.frame_id(c.frame), pin.LOCAL)[: c.dim]
        m, d = self.model, self.data
        fa, fb = self.frame_id(c.frame_a), self.frame_id(c.frame_b)
        M = _placement(m, d, fb).actInv(_placement(m, d, fa))
        nu_a = pin.getFrameVelocity(m, d, fa, pin.LOCAL)
        nu_b = pin.getFrameVelocity(m, d, fb, pin.LOCAL)
        da = pin.getFrameAcceleration(m, d, fa, pin.LOCAL)
        db = pin.getFrameAcceleration(m, d, fb, pin.LOCAL)
        return (db - M.act(da) + nu_b.cross(M.act(nu_a))).vector.copy()

    @property
    def weight(self) -> float:
        """The robot's weight ``m |g|`` (N; the model's gravity when it was built)."""
        return self._weight

    # -- centre of mass -----------------------------------------------------------------
    @property
    def com(self) -> np.ndarray:
        return self.data.com[0].copy()

    @property
    def com_velocity(self) -> np.ndarray:
        return self.data.vcom[0].copy()

    @property
    def Jcom(self) -> np.ndarray:
        """The CoM Jacobian (3 x nv, world; Pinocchio's array: do not modify it)."""
        return self.data.Jcom

    @property
    def com_drift(self) -> np.ndarray:
        """``dJcom v`` (3, m/s^2, world; Pinocchio's array: do not modify it)."""
        return self.data.acom[0]
