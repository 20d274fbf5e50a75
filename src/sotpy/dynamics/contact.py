r"""A floor for the Device's torque mode: unilateral contacts with friction, simulated by
MuJoCo.

``Device.setFloor(patches, floor)`` puts the robot on a horizontal floor: each
:class:`FootPatch` (a sole: a rectangle in a frame's xy plane, the frame's z axis its
normal) becomes a grid of small spheres (its corners by default) that touch the floor
plane, and each torque-mode step is one step of MuJoCo on a copy of the Pinocchio
model. A foot can then lift (a point leaves the floor), tilt (the centre of pressure
reaches an edge and the sole rotates about it) and slide (friction saturates), as on a
real floor. :class:`Floor` holds the floor's settings: its height, its friction
coefficient and its stiffness (MuJoCo's soft-contact time constant and damping ratio).

Why MuJoCo (measured on this project's Talos model, 1 ms steps, the same controller):
Pinocchio 4's constraint solvers (``ADMMConstraintSolver`` over the friction cones of
``PointContactConstraintModel``, with a Delassus matrix built from ``crba`` and the
points' Jacobians) gave the same motion as MuJoCo, but a step cost 7 times MuJoCo's (840
us against 120 us, ADMM needing 50 iterations on a median step and hitting its
500-iteration limit on some), and the time stepping, contact detection and penetration
correction would have been ours to write and keep. MuJoCo's step is one C call, its
contact solver converges on every step, and it is a second, independent implementation
of the dynamics: the tests check the controller (Pinocchio's model) against another
engine's contact forces, not against itself.

The model MuJoCo simulates is built from the ``pinocchio.Model`` (not from the URDF):
one body per joint, at the joint's placement in its parent, with the joint's inertia
(mass, centre of mass, rotational inertia) and rotor inertia (``armature``), a hinge or
a slide joint along the joint's axis, a free joint for a free-flyer root; so the mass
matrix and the nonlinear effects are Pinocchio's to rounding (tested). Only the patch
spheres collide, with the floor only (the feet do not collide with each other or the
body). Joint limits, damping and friction are not simulated by MuJoCo (the Device
clamps to its bounds after each step, as in the other modes).

The step, with ``R`` the base rotation (MuJoCo's free joint takes the base linear
velocity in world axes, Pinocchio in the base frame)::

    qpos = (p, quat (w, x, y, z), joints),  qvel = (R v_lin, w_base, joints)
    qfrc_applied = (R tau_lin, tau_ang, joints)       (tau: generalised forces)
    mj_step (Euler: semi-implicit, v+ = v + a dt then q+ = q (+) v+ dt)

MuJoCo's contacts are soft: the penetration follows a damped spring of time constant
``T`` and damping ratio ``zeta`` (``solref``), so that a resting body sinks by an amount
that grows as ``T^2`` (a 10 kg box on four corners: 7 um at ``T = 5 ms``, 16 times more
at 20 ms; Talos' soles 0.02 to 0.09 mm); the friction is the exact Coulomb cone
(``cone="elliptic"``) or MuJoCo's pyramid, and MuJoCo's *noslip* iterations
(``noslip_iterations``) remove the slow creep that soft friction constraints otherwise
allow under a steady tangential load.

The contact wrench of a patch (``Device.contactForces()``) is the sum of its points'
forces (``mujoco.mj_contactForce``, the forces applied during the step), as a wrench at
the patch frame's origin in world axes (force, then torque, N and N m); the points
themselves are in ``Device.contactPoints()``.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import pinocchio as pin

from ..errors import ContactError

__all__ = ["Floor", "FloorSimulator", "FootPatch", "PatchPoint"]

_AXES = {"X": (1.0, 0.0, 0.0), "Y": (0.0, 1.0, 0.0), "Z": (0.0, 0.0, 1.0)}


def _positive(who: str, what: str, x: object, allow_zero: bool = False) -> float:
    try:
        v = float(x)  # type: ignore[arg-type]
    except (TypeError, ValueError):
        raise ContactError(f"{who}: {what} must be a number, got {x!r}") from None
    if not math.isfinite(v) or v < 0 or (v == 0 and not allow_zero):
        bound = ">= 0" if allow_zero else "> 0"
        raise ContactError(f"{who}: {what} must be finite and {bound}, got {x!r}")
    return v


@dataclass(frozen=True)
class Floor:
    """The floor's settings (validated on construction).

    Attributes:
        friction: Coulomb friction coefficient ``mu`` (>= 0, finite): the tangential
            force of a point is at most ``mu`` times its normal force.
        time_constant: stiffness of the contact, as MuJoCo's ``solref`` time constant
            (s, >= 2 dt for a stable step): the penetration behaves as a damped spring
            of this period; smaller is stiffer.
        damping_ratio: damping of that spring (> 0; 1 is critical).
        height: the floor's height (m, world z).
        cone: ``"elliptic"`` (the exact Coulomb cone) or ``"pyramidal"``.
        noslip_iterations: MuJoCo's noslip post-processing iterations (>= 0); 0 lets a
            loaded foot creep slowly under a steady tangential force (soft friction).
    """

    friction: float = 0.8
    time_constant: float = 0.005
    damping_ratio: float = 1.0
    height: float = 0.0
    cone: str = "elliptic"
    noslip_iterations: int = 20

    def __post_init__(self) -> None:
        who = "Floor"
        _positive(who, "the friction coefficient", self.friction, allow_zero=True)
        _positive(who, "the time constant (s)", self.time_constant)
        _positive(who, "the damping ratio", self.damping_ratio)
        h = float(self.height)
        if not math.isfinite(h):
            raise ContactError(f"{who}: the height must be finite (m), got {self.height!r}")
        if self.cone not in ("elliptic", "pyramidal"):
            raise ContactError(f"{who}: cone must be 'elliptic' or 'pyramidal', got {self.cone!r}")
        n = self.noslip_iterations
        if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 0:
            raise ContactError(f"{who}: noslip_iterations must be an integer >= 0, got {n!r}")


@dataclass(frozen=True)
class FootPatch:
    """A rectangular sole of a frame, modelled as a grid of contact points.

    The rectangle lies in the frame's xy plane (z is the sole's outward normal, into the
    robot), ``length`` (m) along x, ``width`` (m) along y, centred at ``offset`` (m).
    ``grid = (nx, ny)`` points along x and y, the edges included (``(2, 2)``: the four
    corners; ``(3, 3)`` adds the edge midpoints and the centre). Each point is a sphere
    of ``radius`` (m) whose lowest point lies on the sole plane.
    """

    frame: str
    length: float
    width: float
    offset: tuple[float, float] = (0.0, 0.0)
    grid: tuple[int, int] = (2, 2)
    radius: float = 0.002

    def __post_init__(self) -> None:
        who = f"FootPatch({self.frame!r})"
        if not isinstance(self.frame, str) or not self.frame:
            raise ContactError(f"FootPatch: the frame must be a frame name, got {self.frame!r}")
        _positive(who, "the length (m)", self.length)
        _positive(who, "the width (m)", self.width)
        _positive(who, "the sphere radius (m)", self.radius)
        off = np.asarray(self.offset, dtype=float)
        if off.shape not in ((2,), (3,)) or not np.isfinite(off).all():
            raise ContactError(f"{who}: offset must be 2 finite numbers (m), got {self.offset!r}")
        g = tuple(self.grid)
        if len(g) != 2 or any(isinstance(k, bool) or int(k) != k or k < 2 for k in g):
            raise ContactError(f"{who}: grid must be two integers >= 2, got {self.grid!r}")

    @classmethod
    def from_foot(cls, foot: Any, grid: tuple[int, int] = (2, 2)) -> FootPatch:
        """The patch of a robot's :class:`~sotpy.dynamics.robot.Foot` (``robot.feet``)."""
        return cls(foot.frame, foot.length, foot.width, tuple(foot.offset[:2]), grid)

    def points(self) -> np.ndarray:
        """The contact points in the frame (``nx * ny`` x 3, m), on the sole plane."""
        nx, ny = (int(k) for k in self.grid)
        ox, oy = float(self.offset[0]), float(self.offset[1])
        xs = ox + self.length * (np.linspace(0.0, 1.0, nx) - 0.5)
        ys = oy + self.width * (np.linspace(0.0, 1.0, ny) - 0.5)
        return np.array([[x, y, 0.0] for x in xs for y in ys])


@dataclass(frozen=True)
class PatchPoint:
    """A contact point's force in the last step: ``frame`` (its patch), ``index`` (in
    :meth:`FootPatch.points`), ``position`` (world, m), ``force`` (world axes, N, on
    the robot), ``depth`` (penetration, m, >= 0 when touching)."""

    frame: str
    index: int
    position: np.ndarray
    force: np.ndarray
    depth: float


def _num(x: float) -> str:
    return repr(float(x))


def _vec(v: Sequence[float]) -> str:
    return " ".join(_num(x) for x in v)


def _quat_wxyz(R: np.ndarray) -> list[float]:
    qq = pin.Quaternion(R)
    qq.normalize()
    return [qq.w, qq.x, qq.y, qq.z]


class FloorSimulator:
    """One MuJoCo model of a Pinocchio model standing on a floor (see the module doc).

    ``step(q, v, tau, dt)`` returns ``(q+, v+)`` (Pinocchio's conventions) and records
    the contact forces of the step (``wrenches``, ``points``).
    """

    def __init__(self, model: pin.Model, patches: Sequence[FootPatch], floor: Floor) -> None:
        import mujoco  # a core dependency; imported here: only torque mode on a floor needs it

        self._mj = mujoco
        self.model = model
        self.floor = floor
        self.patches = list(patches)
        names = [p.frame for p in self.patches]
        if len(set(names)) != len(names):
            raise ContactError(f"FloorSimulator: a frame has two patches in {names}")
        for p in self.patches:
            if not model.existFrame(p.frame):
                raise ContactError(f"FloorSimulator: {p.frame!r} is not a frame of the model")
        self._free = model.njoints > 1 and model.joints[1].shortname() == "JointModelFreeFlyer"
        if self._free and not model.jointPlacements[1].isIdentity():
            raise ContactError(
                "FloorSimulator: a free-flyer root with a non-identity joint placement is "
                "not supported"
            )
        self.xml = self._xml()
        self.mjmodel = mujoco.MjModel.from_xml_string(self.xml)
        self.mjdata = mujoco.MjData(self.mjmodel)
        nq, nv = self.mjmodel.nq, self.mjmodel.nv
        if (nq, nv) != (model.nq, model.nv):  # pragma: no cover - the builder's invariant
            raise ContactError(f"FloorSimulator: MuJoCo model has nq, nv = {nq}, {nv}")
        # the patch of each sphere geom: geom id -> (patch index, point index)
        self._geom: dict[int, tuple[int, int]] = {}
        for i, p in enumerate(self.patches):
            for k in range(len(p.points())):
                gid = mujoco.mj_name2id(self.mjmodel, mujoco.mjtObj.mjOBJ_GEOM, f"p{i}_{k}")
                self._geom[int(gid)] = (i, k)
        # each patch frame: its MuJoCo body and its origin in that body
        self._frame_bodies = []
        for p in self.patches:
            frame = model.frames[model.getFrameId(p.frame)]
            name = model.names[frame.parentJoint]
            body = mujoco.mj_name2id(self.mjmodel, mujoco.mjtObj.mjOBJ_BODY, name)
            self._frame_bodies.append((int(body), np.array(frame.placement.translation)))
        self._force6 = np.zeros(6)
        self.wrenches: dict[str, np.ndarray] = {}
        self.points: list[PatchPoint] = []

    # -- the model ---------------------------------------------------------------------
    def _xml(self) -> str:
        m, fl = self.model, self.floor
        g = m.gravity.linear
        cone = fl.cone
        solref = f"{_num(fl.time_constant)} {_num(fl.damping_ratio)}"
        fr = f"{_num(fl.friction)} 0 0"
        body_geoms: dict[int, list[str]] = {}
        for i, p in enumerate(self.patches):
            frame = m.frames[m.getFrameId(p.frame)]
            r = p.radius
            for k, c in enumerate(p.points()):
                pos = frame.placement.act(c + np.array([0.0, 0.0, r]))
                body_geoms.setdefault(int(frame.parentJoint), []).append(
                    f'<geom name="p{i}_{k}" type="sphere" size="{_num(r)}" pos="{_vec(pos)}" '
                    f'contype="2" conaffinity="1" condim="3" friction="{fr}" '
                    f'solref="{solref}" mass="0"/>'
                )
        children: dict[int, list[int]] = {}
        for j in range(1, m.njoints):
            children.setdefault(int(m.parents[j]), []).append(j)

        def body(j: int, indent: str) -> list[str]:
            jm = m.joints[j]
            P = m.jointPlacements[j]
            inertia = m.inertias[j]
            mass = max(float(inertia.mass), 1e-9)
            In = inertia.inertia
            full = [In[0, 0], In[1, 1], In[2, 2], In[0, 1], In[0, 2], In[1, 2]]
            if max(full[:3]) < 1e-12:
                full = [1e-12, 1e-12, 1e-12, 0.0, 0.0, 0.0]
            lines = [
                f'{indent}<body name="{m.names[j]}" pos="{_vec(P.translation)}" '
                f'quat="{_vec(_quat_wxyz(P.rotation))}">',
                f'{indent}  <inertial pos="{_vec(inertia.lever)}" mass="{_num(mass)}" '
                f'fullinertia="{_vec(full)}"/>',
            ]
            kind = jm.shortname()
            if kind == "JointModelFreeFlyer":
                lines.append(f'{indent}  <freejoint name="{m.names[j]}"/>')
            else:
                lines.append(f"{indent}  {self._joint(j)}")
            lines += [f"{indent}  {geom}" for geom in body_geoms.get(j, [])]
            for c in children.get(j, []):
                lines += body(c, indent + "  ")
            lines.append(f"{indent}</body>")
            return lines

        world = []
        for c in children.get(0, []):
            world += body(c, "    ")
        # patches on the universe's frames (a fixed robot's base) do not collide: skipped
        return "\n".join(
            [
                '<mujoco model="sotpy-floor">',
                '  <compiler angle="radian" autolimits="false" inertiafromgeom="false"/>',
                f'  <option timestep="0.001" gravity="{_vec(g)}" integrator="Euler" '
                f'cone="{cone}" noslip_iterations="{int(fl.noslip_iterations)}"/>',
                "  <worldbody>",
                f'    <geom name="floor" type="plane" size="0 0 1" pos="0 0 {_num(fl.height)}" '
                f'contype="1" conaffinity="1" condim="3" friction="{fr}" solref="{solref}"/>',
                *world,
                "  </worldbody>",
                "</mujoco>",
            ]
        )

    def _joint(self, j: int) -> str:
        m = self.model
        jm = m.joints[j]
        kind = jm.shortname().removeprefix("JointModel")
        armature = float(m.armature[jm.idx_v]) if jm.nv == 1 else 0.0
        if kind in ("RX", "RY", "RZ", "PX", "PY", "PZ"):
            axis = _AXES[kind[1]]
            typ = "hinge" if kind[0] == "R" else "slide"
        elif kind in ("RevoluteUnaligned", "PrismaticUnaligned"):
            axis = tuple(np.asarray(jm.axis, dtype=float))
            typ = "hinge" if kind.startswith("Revolute") else "slide"
        else:
            raise ContactError(
                f"FloorSimulator: joint {m.names[j]!r} of type {jm.shortname()} is not "
                "supported (free-flyer root, revolute and prismatic joints are)"
            )
        return (
            f'<joint name="{m.names[j]}" type="{typ}" axis="{_vec(axis)}" '
            f'armature="{_num(armature)}" limited="false"/>'
        )

    # -- conversions -------------------------------------------------------------------
    def to_mujoco(self, q: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(qpos, qvel)`` of a Pinocchio ``(q, v)``."""
        if not self._free:
            return q.copy(), v.copy()
        qpos = np.concatenate([q[:3], [q[6]], q[3:6], q[7:]])
        R = pin.Quaternion(q[6], q[3], q[4], q[5]).normalized().toRotationMatrix()
        qvel = v.copy()
        qvel[:3] = R @ v[:3]
        return qpos, qvel

    def from_mujoco(self, qpos: np.ndarray, qvel: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(q, v)`` of a MuJoCo ``(qpos, qvel)``."""
        if not self._free:
            return np.array(qpos), np.array(qvel)
        q = np.concatenate([qpos[:3], qpos[4:7], [qpos[3]], qpos[7:]])
        R = pin.Quaternion(qpos[3], qpos[4], qpos[5], qpos[6]).normalized().toRotationMatrix()
        v = np.array(qvel)
        v[:3] = R.T @ qvel[:3]
        return q, v

    # -- the step ----------------------------------------------------------------------
    def step(
        self, q: np.ndarray, v: np.ndarray, tau: np.ndarray, dt: float
    ) -> tuple[np.ndarray, np.ndarray]:
        """One step of ``dt`` s from ``(q, v)`` under the generalised forces ``tau`` (nv,
        Pinocchio's convention, the free flyer's included); returns ``(q+, v+)`` and
        records the contact forces of the step."""
        mj, mm, md = self._mj, self.mjmodel, self.mjdata
        mm.opt.timestep = dt
        qpos, qvel = self.to_mujoco(q, v)
        md.qpos[:] = qpos
        md.qvel[:] = qvel
        f = np.array(tau, dtype=float)
        if self._free:
            R = pin.Quaternion(q[6], q[3], q[4], q[5]).normalized().toRotationMatrix()
            f[:3] = R @ f[:3]
        md.qfrc_applied[:] = f
        mj.mj_step(mm, md)
        self._record()
        return self.from_mujoco(md.qpos, md.qvel)

    def _record(self) -> None:
        """The contact forces of the step just taken (computed by MuJoCo at ``q``: its
        body placements ``xpos``, ``xmat`` are still those of ``q``)."""
        mj, mm, md = self._mj, self.mjmodel, self.mjdata
        n = md.ncon
        wrenches = {p.frame: np.zeros(6) for p in self.patches}
        self.wrenches = wrenches
        self.points = []
        if n == 0:
            return
        con = md.contact
        geoms = np.asarray(con.geom).reshape(n, 2)
        frames = np.asarray(con.frame).reshape(n, 3, 3)  # rows: normal, tangent 1, tangent 2
        pos = np.asarray(con.pos).reshape(n, 3).copy()
        dist = np.asarray(con.dist).reshape(n)
        local = np.empty((n, 3))
        buf = self._force6
        for i in range(n):
            mj.mj_contactForce(mm, md, i, buf)
            local[i] = buf[:3]
        forces = np.einsum("nij,ni->nj", frames, local)  # world axes, on geom 2
        which = []
        for i in range(n):
            g1, g2 = int(geoms[i, 0]), int(geoms[i, 1])
            if g2 in self._geom:
                which.append(self._geom[g2])
            else:  # the patch is geom 1: the force on it is the opposite
                which.append(self._geom[g1])
                forces[i] = -forces[i]
        origins = self._origins()
        points = []
        for i, (ip, k) in enumerate(which):
            frame = self.patches[ip].frame
            f, r = forces[i], pos[i] - origins[ip]
            w = wrenches[frame]
            w[:3] += f
            w[3] += r[1] * f[2] - r[2] * f[1]
            w[4] += r[2] * f[0] - r[0] * f[2]
            w[5] += r[0] * f[1] - r[1] * f[0]
            points.append(PatchPoint(frame, k, pos[i], f, float(-dist[i])))
        self.points = points

    def _origins(self) -> list[np.ndarray]:
        """The patch frames' origins (world, m) from MuJoCo's body placements."""
        md = self.mjdata
        out = []
        for body, offset in self._frame_bodies:
            R = md.xmat[body].reshape(3, 3)
            out.append(md.xpos[body] + R @ offset)
        return out

    def mass_matrix(self, q: np.ndarray) -> np.ndarray:
        """MuJoCo's joint-space inertia at ``q``, in Pinocchio's velocity convention
        (``R^T``-rotated free-flyer linear rows and columns): compare with ``crba``."""
        mj, mm, md = self._mj, self.mjmodel, self.mjdata
        qpos, _ = self.to_mujoco(q, np.zeros(self.model.nv))
        md.qpos[:] = qpos
        md.qvel[:] = 0.0
        mj.mj_forward(mm, md)
        M = np.zeros((mm.nv, mm.nv))
        mj.mj_fullM(mm, M, md.qM) if hasattr(md, "qM") else mj.mj_fullM(mm, md, M)
        if self._free:  # v_mj = T v_pin with T = blockdiag(R, I): M_pin = T^T M_mj T
            R = pin.Quaternion(q[6], q[3], q[4], q[5]).normalized().toRotationMatrix()
            T = np.eye(mm.nv)
            T[:3, :3] = R
            M = T.T @ M @ T
        return M
