r"""Collision avoidance as an inequality task: ``FeatureCollision`` and ``TaskCollision``.

::

    feature = FeatureCollision("collisions", robot)        # self-collision pairs (SRDF)
    feature.addObstacle("table", "box", (0.8, 1.2, 0.05), (0.6, 0.0, 0.7))
    task = TaskCollision("task_collisions")
    task.add(feature)
    sot.push(contact); sot.push(task); sot.push(reach) ...  # usually right below the
                                                            # joint limits (or the feet)

**Geometry.** The shapes are those of the robot's Pinocchio collision model (loaded from
the URDF's ``<collision>`` elements through ``coal``). Each mesh is replaced by its
convex hull, which contains it: a distance between hulls is never larger than the
distance between the meshes, so keeping the hulls apart keeps the meshes apart, and the
convex solver (GJK/EPA) is two orders of magnitude faster than a mesh-mesh query
(Talos: 887 pairs in about 2 ms for the hulls, 320 ms for the meshes). Primitive
shapes (boxes, cylinders, spheres, capsules) are kept as they are.

**Pairs.** All pairs of geometries, minus

- those the SRDF disables (``<disable_collisions>``, ``pinocchio.removeCollisionPairs``),
- those on the same joint, or on a joint and its parent joint (adjacent links, whose
  shapes touch at the joint by construction),

and, for each obstacle, the pairs (obstacle, robot geometry) except the geometries of the
joint it is attached to. ``addPair``/``removePair`` edit the list by geometry names.

**Distance and Jacobian.** For a pair ``(A, B)``, coal's distance query gives the
signed distance ``d`` (m, negative in penetration), the witness points ``p_A`` on ``A``
and ``p_B`` on ``B`` (world, m) and the unit normal ``n`` from ``A`` to ``B``
(``p_B - p_A = d n`` when ``d > 0``). With ``p_A`` a point fixed to ``A``'s joint ``j``
(origin ``o_j``), its velocity is ``v_j + w_j x (p_A - o_j)`` (LOCAL_WORLD_ALIGNED joint
Jacobian: ``v_j``, ``w_j`` in world axes), so

.. math::

    \dot d = n^T (\dot p_B - \dot p_A) = J_d\, v, \qquad
    J_d = n^T (J_{p_B} - J_{p_A}), \quad
    n^T J_p = n^T J^{lin}_j + ((p - o_j) \times n)^T J^{ang}_j

(1 x nv, m/s per unit of v). The tick computes the same from the joints' Jacobians in
the world frame (``data.J``, restricted to each joint's support, whose velocity is that
of the point at the world origin): ``n^T J_p = n^T J^{lin,W}_j + (p \times n)^T
J^{ang,W}_j``, with no Jacobian call per joint. This is the exact derivative of the
distance between two convex shapes whose witness points are unique (the rate of the
normal and the motion of the witness points on the surfaces contribute nothing at first
order); it is checked against central finite differences along random velocities
(``tests/test_collision.py``).
A shape fixed to the world (an obstacle on no frame) has ``J_p = 0``.

**Broad phase.** Each geometry has a bounding sphere (centre ``c_g`` in its joint's
frame, radius ``r_g``, from coal's local AABB). Each tick, one pass (a compiled kernel,
or its NumPy twin without numba) puts the centres in the world (``R_j c_g + o_j``) and
bounds every pair's distance from below by ``|c_A - c_B| - r_A - r_B``. A second bound
is the pair's last exact distance minus how far any point of either shape can have moved
since (``|c' - c| + r_g |R' - R|_F`` per tick for a geometry, ``R`` its joint's
rotation). Only the pairs whose larger bound is under the influence distance ``d_i``
reach the narrow phase (coal) and, if their distance is under ``d_i``, the task: pairs
far apart cost one iteration of that pass, and no pair under ``d_i`` is ever skipped.
The joint placements and coal's results are read through read-only arrays on Pinocchio's
and coal's memory (their layout checked against the accessors first; the accessors
otherwise).

**The velocity damper** (Faverjon and Tournassoud, *A local based approach for path
planning of manipulators with a high number of degrees of freedom*, ICRA 1987; Kanoun,
Lamiraux and Wieber, *Kinematic control of redundant manipulators: generalizing the
task-priority framework to inequality task*, IEEE T-RO 2011): for every pair with
``d < d_i``,

.. math::

    \dot d \ge -\xi \frac{d - d_s}{d_i - d_s}

with ``d_s`` the safety distance (m), ``d_i`` the influence distance (m, ``d_i > d_s``)
and ``xi`` (m/s, > 0) the largest approach speed, reached at ``d = d_i``. Met exactly,
``d - d_s`` decays at most exponentially with the time constant ``(d_i - d_s) / xi``:
the distance tends to ``d_s`` and never crosses it (to the first order of the
integration, whose error is ``O(|v|^2 dt^2)``). The rows of ``TaskCollision`` are the
pairs under ``d_i``: their number changes from tick to tick (zero when nothing is
close), which the ``SOT`` accepts at any level.

The acceleration-level form for the torque-level controller is
:class:`sotpy.solvers.wbc.collision.CollisionConstraint`.
"""

from __future__ import annotations

import ctypes
import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import coal
import numpy as np
import pinocchio as pin

from .. import _jit
from ..errors import CommandError, EntityError, SignalTypeError
from ..graph import DOUBLE, INT, VECTOR, Input, Output, command, plug
from ..graph.signal import Signal
from . import _collisionkernels as _kernels
from .features import FeatureAbstract
from .task import TaskAbstract

__all__ = [
    "DEFAULT_GAIN",
    "DEFAULT_INFLUENCE",
    "DEFAULT_SAFETY",
    "CollisionPairs",
    "FeatureCollision",
    "TaskCollision",
    "checkDamper",
    "collisionPairs",
    "convexGeometryModel",
    "robotSrdf",
]

#: Default safety distance d_s (m).
DEFAULT_SAFETY = 0.01
#: Default influence distance d_i (m).
DEFAULT_INFLUENCE = 0.05
#: Default damper gain xi (m/s): the largest approach speed, at d = d_i.
DEFAULT_GAIN = 0.5

#: coal's GJK and EPA tolerance (m) for the distance queries (its default is 1e-6).
GJK_TOLERANCE = 1e-9

_SHAPES = ("box", "sphere", "capsule")


# -- the robot's geometry ---------------------------------------------------------------
def robotSrdf(robot: Any) -> Path | None:
    """The SRDF of a robot from example-robot-data (its ``<disable_collisions>``
    pairs), or None when it has none; ``robot``: a :class:`~sotpy.dynamics.Robot` or a
    robot description's name (``"talos"``)."""
    if isinstance(robot, (str, Path)):
        from ..dynamics import robot_info

        desc = robot_info(robot)
    else:
        desc = getattr(robot, "description", {}) or {}
    m = desc.get("model", {})
    if m.get("source") != "example-robot-data":
        return None
    from example_robot_data import robots_loader

    loader = robots_loader.ROBOTS.get(m.get("loader"))
    if loader is None or not getattr(loader, "srdf_filename", ""):
        return None
    base = Path(robots_loader.getModelPath(loader.path))
    path = base / loader.path / loader.srdf_subpath / loader.srdf_filename
    return path if path.is_file() else None


def convexGeometryModel(geometry: pin.GeometryModel) -> pin.GeometryModel:
    """A copy of ``geometry`` whose meshes are replaced by their convex hulls (which
    contain them, so a distance between hulls bounds the meshes' from below);
    primitive shapes are kept. ``geometry`` itself is not modified."""
    out = pin.GeometryModel()
    for g in geometry.geometryObjects:
        shape = g.geometry
        if isinstance(shape, coal.BVHModelBase):
            shape = shape.clone()
            shape.buildConvexHull(True, "Qt")
            shape = shape.convex
        obj = pin.GeometryObject(g.name, g.parentJoint, g.parentFrame, g.placement, shape)
        out.addGeometryObject(obj)
    return out


def collisionPairs(
    model: pin.Model, geometry: pin.GeometryModel, srdf: str | Path | None = None
) -> list[tuple[int, int]]:
    """The self-collision pairs ``(i, j)`` (geometry indices, ``i < j``): all pairs,
    minus those the SRDF disables (when given), minus those of the same joint or of a
    joint and its parent (see the module doc)."""
    gm = geometry.copy()
    gm.removeAllCollisionPairs()
    gm.addAllCollisionPairs()
    if srdf is not None:
        pin.removeCollisionPairs(model, gm, str(srdf))
    objs = gm.geometryObjects
    pairs = []
    for p in gm.collisionPairs:
        i, j = sorted((p.first, p.second))
        ja, jb = objs[i].parentJoint, objs[j].parentJoint
        if ja == jb or model.parents[ja] == jb or model.parents[jb] == ja:
            continue
        pairs.append((i, j))
    return sorted(pairs)


def _goodDistances(safety: Any, influence: Any) -> bool:
    """The common case of :func:`checkDamper` without a gain, checked without building
    its message: two floats with ``0 <= d_s < d_i < inf``."""
    return (
        type(safety) is float and type(influence) is float and 0.0 <= safety < influence < math.inf
    )


def checkDamper(where: str, safety: float, influence: float, gain: float | None) -> None:
    """Refuse an inconsistent damper: ``d_s >= 0``, ``d_i > d_s``, ``xi > 0``, all
    finite. ``where`` names the entity and the signals in the message."""
    for what, v in (("safety distance d_s", safety), ("influence distance d_i", influence)):
        if not (isinstance(v, (int, float)) and math.isfinite(v)):
            raise SignalTypeError(f"{where}: expected a finite {what} (m), got {v!r}")
    if safety < 0.0:
        raise SignalTypeError(f"{where}: expected a safety distance d_s >= 0 (m), got {safety}")
    if influence <= safety:
        raise SignalTypeError(
            f"{where}: expected an influence distance d_i > d_s = {safety} m, got {influence}"
        )
    if gain is not None and not (math.isfinite(gain) and gain > 0.0):
        raise SignalTypeError(f"{where}: expected a damper gain xi > 0 (m/s), got {gain!r}")


def _placement(where: str, placement: Any) -> pin.SE3:
    if isinstance(placement, pin.SE3):
        return pin.SE3(placement)
    a = np.asarray(placement, dtype=float)
    if a.shape == (3,) and np.isfinite(a).all():
        return pin.SE3(np.eye(3), a)
    if a.shape == (4, 4) and np.isfinite(a).all():
        R = a[:3, :3]
        if np.allclose(R.T @ R, np.eye(3), atol=1e-9) and np.linalg.det(R) > 0:
            return pin.SE3(R, a[:3, 3])
    raise CommandError(
        f"{where}: expected a placement (a pinocchio.SE3, a 4x4 homogeneous matrix or a "
        f"position x y z in m), got {placement!r}"
    )


def _shape(where: str, shape: str, size: Sequence[float]) -> coal.ShapeBase:
    try:
        s = [float(x) for x in np.atleast_1d(np.asarray(size, dtype=float))]
    except (TypeError, ValueError):
        s = []
    ok = all(math.isfinite(x) and x > 0 for x in s)
    if shape == "box" and len(s) == 3 and ok:
        return coal.Box(*s)
    if shape == "sphere" and len(s) == 1 and ok:
        return coal.Sphere(s[0])
    if shape == "capsule" and len(s) == 2 and ok:
        return coal.Capsule(s[0], s[1])
    expected = {
        "box": "3 side lengths x y z (m, > 0)",
        "sphere": "a radius (m, > 0)",
        "capsule": "a radius and a length (m, > 0; the axis is the placement's z)",
    }
    if shape not in expected:
        raise CommandError(f"{where}: unknown shape {shape!r}; expected one of {_SHAPES}")
    raise CommandError(f"{where}: a {shape} takes {expected[shape]}, got {size!r}")


def _oMiView(data: pin.Data) -> np.ndarray | None:
    """A read-only view (njoints x 12: the rotation column by column, then the
    translation) on the memory of ``data.oMi``, or None when it is not laid out so
    (checked: the rotations and translations Pinocchio hands out are views 96 bytes
    apart, the translation 72 bytes after the rotation, and the view reads back every
    placement)."""
    L = data.oMi.tolist()
    try:
        rot = [M.rotation for M in L]
        tra = [M.translation for M in L]
        ar = [x.__array_interface__["data"][0] for x in rot]
        at = [x.__array_interface__["data"][0] for x in tra]
    except (AttributeError, TypeError, KeyError):  # pragma: no cover - another binding
        return None
    nj = len(L)
    layout = all(not x.flags.owndata and x.flags.f_contiguous for x in rot) and all(
        ar[k] == ar[0] + 96 * k and at[k] == ar[k] + 72 for k in range(nj)
    )
    if not layout or nj == 0:  # pragma: no cover - another Pinocchio
        return None
    buf = (ctypes.c_double * (12 * nj)).from_address(ar[0])
    X = np.frombuffer(buf, dtype=np.float64).reshape(nj, 12)
    X.flags.writeable = False
    H = np.array([M.homogeneous for M in L])
    if not (
        np.array_equal(X[:, :9].reshape(-1, 3, 3).transpose(0, 2, 1), H[:, :3, :3])
        and np.array_equal(X[:, 9:], H[:, :3, 3])
    ):  # pragma: no cover - another Pinocchio
        return None
    return X


def _resultsView(results: list[Any]) -> np.ndarray | None:
    """A read-only view (pairs x 10: ``min_distance``, ``normal``, the two nearest
    points) on the memory of coal's distance results (``results``: the proxies of one
    ``GeometryData.distanceResults``), or None when the normals coal hands out are not
    views the same number of bytes apart. The order of the fields in that memory is
    checked against the accessors by :func:`_resultsMatch`."""
    if not results:
        return None
    try:
        normals = [r.normal for r in results]
        addr = [x.__array_interface__["data"][0] for x in normals]
    except (AttributeError, TypeError, KeyError):  # pragma: no cover - another binding
        return None
    stride = addr[1] - addr[0] if len(addr) > 1 else 160
    if stride < 80 or stride % 8 or any(x.flags.owndata for x in normals):
        return None  # pragma: no cover - another coal
    if any(a != addr[0] + stride * k for k, a in enumerate(addr)):
        return None  # pragma: no cover
    start = addr[0] - 8  # min_distance, just before the normal
    size = (stride * (len(addr) - 1)) // 8 + 10
    buf = (ctypes.c_double * size).from_address(start)
    flat = np.frombuffer(buf, dtype=np.float64)
    view = np.lib.stride_tricks.as_strided(
        flat, shape=(len(addr), 10), strides=(stride, 8), writeable=False
    )
    return view


def _resultsMatch(view: np.ndarray, results: list[Any], pairs: np.ndarray) -> bool:
    """Whether ``view`` reads back what coal's accessors give for ``pairs``."""
    for k in pairs.tolist():
        r = results[k]
        expected = np.concatenate(
            ([r.min_distance], r.normal, r.getNearestPoint1(), r.getNearestPoint2())
        )
        if not np.array_equal(view[k], expected):
            return False
    return True


# -- the pairs --------------------------------------------------------------------------
class CollisionPairs:
    """The geometry, the pairs and the per-tick computation of a collision model, with
    no graph (see the module doc): what :class:`FeatureCollision` and the torque-level
    :class:`~sotpy.solvers.wbc.collision.CollisionConstraint` share.

    ``CollisionPairs(model, geometry, srdf=None, who="CollisionPairs")``: the
    ``pinocchio.Model``, its collision ``GeometryModel`` (copied, meshes replaced by
    their hulls), the SRDF whose disabled pairs are removed; ``who`` starts the messages
    of the errors. After :meth:`compute`, ``rowPairs`` (the rows' pair indices),
    ``rowD`` (their distances, m), ``rowJ`` (their ``J_d``, rows x nv), ``rowNormal``,
    ``rowPointA``, ``rowPointB`` (world), ``rowJointA``, ``rowJointB``, ``minDistance``
    (m) and ``narrow`` (pairs that reached coal).
    """

    def __init__(
        self,
        model: pin.Model,
        geometry: pin.GeometryModel,
        srdf: str | Path | None = None,
        who: str = "CollisionPairs",
    ) -> None:
        self.who = who
        self._model = model
        self._geom = convexGeometryModel(geometry)
        self._robotGeoms = self._geom.ngeoms
        self._obstacles: dict[str, int] = {}
        self._pairs = collisionPairs(model, self._geom, srdf)
        self._empty()
        self._rebuild()
        _jit.prepare("the collision pass", ["sotpy.tasks._collisionkernels"])

    def _empty(self, lowest: float = math.inf) -> None:
        model = self._model
        self.rowPairs, self.rowD = np.zeros(0, dtype=int), np.zeros(0)
        self.rowJ = np.zeros((0, model.nv))
        self.rowNormal = self.rowPointA = self.rowPointB = np.zeros((0, 3))
        self.rowJointA = self.rowJointB = np.zeros(0, dtype=int)
        self.minDistance, self.narrow = lowest, 0

    def _rebuild(self) -> None:
        """The geometry data, the pair arrays and the bounding spheres, after an edit."""
        gm = self._geom
        gm.removeAllCollisionPairs()
        for i, j in self._pairs:
            gm.addCollisionPair(pin.CollisionPair(i, j))
        self._gdata = gd = pin.GeometryData(gm)
        for req in gd.distanceRequests:  # witness points and normals to 1e-9 m
            req.gjk_tolerance = GJK_TOLERANCE
            req.epa_tolerance = GJK_TOLERANCE
        n = gm.ngeoms
        self._gjoint = np.array([g.parentJoint for g in gm.geometryObjects], dtype=int)
        centers = np.zeros((n, 3))
        radii = np.zeros(n)
        for k, g in enumerate(gm.geometryObjects):
            shape = g.geometry
            shape.computeLocalAABB()
            centers[k] = g.placement.act(np.asarray(shape.aabb_center, dtype=float))
            radii[k] = shape.aabb_radius
        self._gcenter, self._gradius = centers, radii
        self._pa = np.array([p[0] for p in self._pairs], dtype=int)
        self._pb = np.array([p[1] for p in self._pairs], dtype=int)
        self._rsum = radii[self._pa] + radii[self._pb] if self._pairs else np.zeros(0)
        self._joints = np.unique(self._gjoint)
        # the narrow phase: coal's results read through proxies made once (indexing the
        # vector costs as much as reading), and the pairs coal computes (all active at
        # first; compute toggles only those whose status changes)
        self._results = [gd.distanceResults[k] for k in range(len(self._pairs))]
        # ... or through one read-only array on their memory when it has the layout
        # :func:`_resultsView` checks (the values are checked at the first computation)
        self._resView = _resultsView(self._results)
        self._resChecked = False
        # temporal coherence (compute): lower bounds on the distances, and the joint
        # rotations and sphere centres of the previous tick
        self._lower = np.full(len(self._pairs), -math.inf)
        self._coherent = False
        self._prevX = np.zeros((self._model.njoints, 12))
        self._prevC = np.zeros((n, 3))
        self._c = np.zeros((n, 3))
        self._sel = np.ones(len(self._pairs), dtype=bool)  # all active in a new gd
        self._near = np.zeros(len(self._pairs), dtype=np.int64)
        self._toggle = np.zeros(len(self._pairs), dtype=np.int64)
        # the joints' supports: support[j, i] when velocity i moves joint j
        model = self._model
        support = np.zeros((model.njoints, model.nv), dtype=bool)
        for j in range(1, model.njoints):
            support[j] = support[model.parents[j]]
            support[j, model.idx_vs[j] : model.idx_vs[j] + model.nvs[j]] = True
        self._support = support
        self._view: tuple[pin.Data, np.ndarray] | None = None

    # -- the tick -----------------------------------------------------------------------
    def _placements(self, data: pin.Data) -> np.ndarray:
        """The joint placements of ``data`` (world; njoints x 12: the rotation column by
        column, then the translation): a read-only view on ``data.oMi`` when its memory
        has the layout checked by :func:`_oMiView` (one array, no accessor per joint),
        else a copy."""
        view = self._view
        if view is None or view[0] is not data:
            self._view = view = (data, _oMiView(data))
        if view[1] is not None:
            return view[1]
        H = np.array([M.homogeneous for M in data.oMi])
        return np.concatenate((H[:, :3, :3].transpose(0, 2, 1).reshape(-1, 9), H[:, :3, 3]), 1)

    def _broadPhase(self, X: np.ndarray, di: float) -> tuple[np.ndarray, np.ndarray, float]:
        """The broad phase (NumPy; :func:`._collisionkernels.broad_phase` is its compiled
        twin): the pairs' lower bounds into ``_lower``, the selection into ``_sel``;
        the selected pairs, those whose selection changed and the smallest bound of the
        others (inf when none)."""
        R, o = X[:, :9].reshape(-1, 3, 3).transpose(0, 2, 1), X[:, 9:]
        gj = self._gjoint
        c = np.einsum("gij,gj->gi", R[gj], self._gcenter) + o[gj]
        pa, pb = self._pa, self._pb
        dc = c[pa] - c[pb]
        bound = np.sqrt(np.einsum("ij,ij->i", dc, dc)) - self._rsum
        # temporal coherence: a lower bound on each pair's distance, its last exact value
        # minus how far any point of either shape can have moved since (see the doc)
        lb = self._lower
        if self._coherent:
            dR = X[:, :9] - self._prevX[:, :9]
            rot = np.sqrt(np.einsum("ja,ja->j", dR, dR))[gj]  # |R' - R|_F >= |R' - R|_2
            move = np.sqrt(np.einsum("gi,gi->g", c - self._prevC, c - self._prevC))
            move += self._gradius * rot
            lb -= move[pa] + move[pb]
        self._prevX[:] = X
        self._prevC[:] = c
        np.maximum(lb, bound, out=lb)
        sel = lb < di
        toggle = np.flatnonzero(sel != self._sel)
        self._sel[:] = sel
        rest = lb[~sel]
        return np.flatnonzero(sel), toggle, float(rest.min()) if rest.shape[0] else math.inf

    def compute(self, data: pin.Data, di: float) -> None:
        """The tick: broad phase, narrow phase and rows at ``data``'s kinematics (joint
        placements and Jacobians computed), for the influence distance ``di`` (m)."""
        model, gm, gd = self._model, self._geom, self._gdata
        if not self._pairs:
            self._empty()
            return
        # broad phase: sphere centres in the world, one pass over the pairs
        X = self._placements(data)
        lb = self._lower
        sel = self._sel
        kernel = _kernels.broad_phase
        if kernel is not None:
            try:
                count, changed, lowest = kernel(
                    X, self._gjoint, self._gcenter, self._gradius, self._pa, self._pb,
                    self._rsum, lb, self._prevX, self._prevC, self._c, self._coherent,
                    float(di), sel, self._near, self._toggle,
                )  # fmt: skip
                near, toggle = self._near[:count], self._toggle[:changed]
            except TypeError as exc:  # pragma: no cover - types not compiled for
                _jit.refused(self.who, exc)
                _kernels.broad_phase = kernel = None
        if kernel is None:
            near, toggle, lowest = self._broadPhase(X, di)
        self._coherent = True
        # narrow phase on the selected pairs only: one call, the others deactivated (only
        # the pairs whose selection changed since the last tick are toggled)
        for k in toggle.tolist():
            if sel[k]:
                gd.activateCollisionPair(k)
            else:
                gd.deactivateCollisionPair(k)
        if not near.shape[0]:
            self._empty(lowest)
            return
        pin.updateGeometryPlacements(model, data, gm, gd)
        pin.computeDistances(gm, gd)
        results, view = self._results, self._resView
        if view is not None and not self._resChecked:
            self._resChecked = True
            if not _resultsMatch(view, results, near):  # pragma: no cover - another coal
                self._resView = view = None
        kernel = _kernels.narrow_rows
        if kernel is not None and view is not None:
            k = near.shape[0]
            rows, res, Jd = np.empty(k, dtype=np.int64), np.empty((k, 10)), np.empty((k, model.nv))
            joints = np.empty((2, k), dtype=np.int64)
            try:
                m, low = kernel(
                    view, near, float(di), lb, self._gjoint, self._pa, self._pb, data.J,
                    self._support, rows, res, joints, Jd,
                )  # fmt: skip
            except TypeError as exc:  # pragma: no cover - types not compiled for
                _jit.refused(self.who, exc)
                _kernels.narrow_rows = kernel = None
            else:
                self.minDistance, self.narrow = min(lowest, low), int(k)
                if not m:
                    self._empty(self.minDistance)
                    self.narrow = int(k)
                    return
                res = res[:m]
                self.rowPairs, self.rowD, self.rowJ = rows[:m], res[:, 0], Jd[:m]
                self.rowNormal, self.rowPointA, self.rowPointB = (
                    res[:, 1:4], res[:, 4:7], res[:, 7:10]
                )  # fmt: skip
                self.rowJointA, self.rowJointB = joints[0, :m], joints[1, :m]
                return
        # the same without the compiled kernel (NumPy, or coal's accessors)
        if view is not None:
            res = view[near]
            dist = res[:, 0]
        else:
            dist = np.array([results[k].min_distance for k in near.tolist()])
        lb[near] = dist
        lowest = min(lowest, float(dist.min()))
        inside = dist < di
        rows = near[inside]
        m = rows.shape[0]
        if not m:
            self._empty(lowest)
            self.narrow = int(near.shape[0])
            return
        self.minDistance, self.narrow = lowest, int(near.shape[0])
        self.rowPairs, self.rowD = rows, dist[inside]
        # J_d = n^T (J_pB - J_pA), n^T J_p = n^T J_lin + (p x n)^T J_ang with J the
        # joint's Jacobian in the world frame (data.J restricted to the joint's support)
        if view is not None:
            res = res[inside]
            n, pA, pB = res[:, 1:4], res[:, 4:7], res[:, 7:10]
        else:
            n = np.empty((m, 3))
            pA = np.empty((m, 3))
            pB = np.empty((m, 3))
            for r, k in enumerate(rows.tolist()):
                res = results[k]
                n[r] = res.normal
                pA[r] = res.getNearestPoint1()
                pB[r] = res.getNearestPoint2()
        gj = self._gjoint
        jA, jB = gj[self._pa[rows]], gj[self._pb[rows]]
        self.rowJ = self._jacobianRows(n, pA, pB, jA, jB, data.J)
        self.rowNormal, self.rowPointA, self.rowPointB = n, pA, pB
        self.rowJointA, self.rowJointB = jA, jB

    def _jacobianRows(
        self,
        n: np.ndarray,
        pA: np.ndarray,
        pB: np.ndarray,
        jA: np.ndarray,
        jB: np.ndarray,
        J: np.ndarray,
    ) -> np.ndarray:
        """``J_d`` of the rows (NumPy; :func:`._collisionkernels.narrow_rows` computes it
        compiled)."""
        coef = np.empty((2, n.shape[0], 6))
        for side, p in enumerate((pA, pB)):
            coef[side, :, :3] = n
            # p x n, written out (np.cross costs more here)
            coef[side, :, 3] = p[:, 1] * n[:, 2] - p[:, 2] * n[:, 1]
            coef[side, :, 4] = p[:, 2] * n[:, 0] - p[:, 0] * n[:, 2]
            coef[side, :, 5] = p[:, 0] * n[:, 1] - p[:, 1] * n[:, 0]
        sup = self._support
        return np.where(sup[jB], coef[1] @ J, 0.0) - np.where(sup[jA], coef[0] @ J, 0.0)

    # -- queries ------------------------------------------------------------------------
    def distances(self, data: pin.Data) -> np.ndarray:
        """The distance of every pair (m), in the order of :meth:`listPairs`, computed by
        coal at ``data``'s joint placements (for checks and tests; not the tick's path,
        which skips far pairs)."""
        model, gm, gd = self._model, self._geom, self._gdata
        pin.updateGeometryPlacements(model, data, gm, gd)
        out = np.empty(len(self._pairs))
        for k in range(len(self._pairs)):
            pin.computeDistance(gm, gd, k)
            out[k] = gd.distanceResults[k].min_distance
        return out

    def _geometryIndex(self, cmd: str, name: str) -> int:
        gm = self._geom
        if not isinstance(name, str) or not gm.existGeometryName(name):
            raise CommandError(
                f"{self.who}.{cmd}: no geometry named {name!r} (see listGeometries())"
            )
        return int(gm.getGeometryId(name))

    def listGeometries(self) -> list[str]:
        """The geometries' names: the robot's, then the obstacles'."""
        return [g.name for g in self._geom.geometryObjects]

    def listPairs(self) -> list[str]:
        """The pairs, ``"a : b"`` by geometry name; a row's index in ``activePairs`` is
        its index here."""
        return [self.pairName(k) for k in range(len(self._pairs))]

    def getPairCount(self) -> int:
        """The number of pairs."""
        return len(self._pairs)

    def pairName(self, k: int) -> str:
        """The pair of index ``k``, ``"a : b"``."""
        objs = self._geom.geometryObjects
        i, j = self._pairs[int(k)]
        return f"{objs[i].name} : {objs[j].name}"

    def addPair(self, a: str, b: str) -> None:
        """Check the pair of geometries ``a`` and ``b`` (names) too."""
        i, j = sorted((self._geometryIndex("addPair", a), self._geometryIndex("addPair", b)))
        if i == j:
            raise CommandError(f"{self.who}.addPair: a geometry cannot collide with itself ({a!r})")
        if (i, j) in self._pairs:
            raise CommandError(f"{self.who}.addPair: the pair {a!r}, {b!r} is already checked")
        self._pairs = sorted([*self._pairs, (i, j)])
        self._rebuild()

    def removePair(self, a: str, b: str) -> None:
        """Stop checking the pair of geometries ``a`` and ``b`` (names)."""
        ij = tuple(
            sorted((self._geometryIndex("removePair", a), self._geometryIndex("removePair", b)))
        )
        if ij not in self._pairs:
            raise CommandError(
                f"{self.who}.removePair: the pair {a!r}, {b!r} is not "
                f"checked (see listPairs(); {len(self._pairs)} pairs)"
            )
        self._pairs = [p for p in self._pairs if p != ij]
        self._rebuild()

    def addObstacle(
        self,
        name: str,
        shape: str,
        size: Sequence[float] | float,
        placement: Any,
        frame: str | None = None,
    ) -> None:
        """Add an obstacle and its pairs with every robot geometry (except those of the
        joint it is attached to).

        Args:
            name: a new geometry name.
            shape: ``"box"`` (size: side lengths x y z), ``"sphere"`` (radius) or
                ``"capsule"`` (radius, length along the placement's z); m.
            placement: its placement in the world, or in ``frame`` when given: a
                ``pinocchio.SE3``, a 4x4 matrix or a position (m).
            frame: a frame of the robot's model it moves with (None: the world).
        """
        where = f"{self.who}.addObstacle"
        if not isinstance(name, str) or not name:
            raise CommandError(f"{where}: expected a name (a non-empty string), got {name!r}")
        if self._geom.existGeometryName(name):
            raise CommandError(f"{where}: a geometry named {name!r} already exists")
        geometry = _shape(where, shape, size)
        M = _placement(where, placement)
        joint, fid = 0, 0
        if frame is not None:
            model = self._model
            if not isinstance(frame, str) or not model.existFrame(frame):
                raise CommandError(
                    f"{where}: the model {model.name!r} has no frame named {frame!r}"
                )
            fid = int(model.getFrameId(frame))
            f = model.frames[fid]
            joint = int(f.parentJoint)
            M = f.placement * M
        obj = pin.GeometryObject(name, joint, fid, M, geometry)
        gid = int(self._geom.addGeometryObject(obj))
        robot = range(self._robotGeoms)
        objs = self._geom.geometryObjects
        new = [(g, gid) for g in robot if objs[g].parentJoint != joint or joint == 0]
        self._obstacles[name] = gid
        self._pairs = sorted([*self._pairs, *new])
        self._rebuild()

    def removeObstacle(self, name: str) -> None:
        """Remove the obstacle ``name`` and its pairs."""
        if name not in self._obstacles:
            raise CommandError(
                f"{self.who}.removeObstacle: no obstacle named {name!r} "
                f"(obstacles: {', '.join(self._obstacles) or 'none'})"
            )
        gid = self._obstacles.pop(name)
        old = self._geom
        gm = pin.GeometryModel()
        for k, g in enumerate(old.geometryObjects):
            if k != gid:
                gm.addGeometryObject(g)
        shift = {k: k - (k > gid) for k in range(old.ngeoms) if k != gid}
        self._pairs = sorted((shift[i], shift[j]) for i, j in self._pairs if gid not in (i, j))
        self._obstacles = {n: shift[g] for n, g in self._obstacles.items()}
        self._geom = gm
        self._rebuild()

    def setObstaclePlacement(self, name: str, placement: Any) -> None:
        """Move the obstacle ``name``: its new placement in the world, or in the frame it
        is attached to (a ``pinocchio.SE3``, a 4x4 matrix or a position, m)."""
        where = f"{self.who}.setObstaclePlacement"
        if name not in self._obstacles:
            raise CommandError(
                f"{where}: no obstacle named {name!r} (obstacles: "
                f"{', '.join(self._obstacles) or 'none'})"
            )
        M = _placement(where, placement)
        gid = self._obstacles[name]
        obj = self._geom.geometryObjects[gid]
        if obj.parentFrame:
            M = self._model.frames[obj.parentFrame].placement * M
        obj.placement = M
        # its bounding sphere's centre moves with it; the pairs' bounds start afresh
        self._gcenter[gid] = M.act(np.asarray(obj.geometry.aabb_center, dtype=float))
        self._lower[:] = -math.inf

    def clearPairs(self) -> None:
        """Check no pair (``addPair`` or ``addObstacle`` add some back)."""
        self._pairs = []
        self._rebuild()

    def listObstacles(self) -> list[str]:
        """The obstacles' names."""
        return list(self._obstacles)


# -- the feature ------------------------------------------------------------------------
class FeatureCollision(FeatureAbstract):
    """The distances of the collision pairs under the influence distance, and their
    Jacobians (see the module doc for the maths).

    ``FeatureCollision(name, robot, srdf="auto", geometry=None)``: ``robot`` is a
    :class:`~sotpy.dynamics.Robot` (its ``dynamic``, ``model`` and ``collision_model``)
    or a ``Dynamic`` entity, then with ``geometry`` (a ``pinocchio.GeometryModel``).
    ``srdf``: the SRDF whose disabled pairs are removed (``"auto"``: the robot's, from
    example-robot-data; None: none). The feature reads the ``Dynamic``'s kinematics
    pass (input ``kinematics``, plugged by the constructor): it costs no second forward
    kinematics.

    Inputs: ``safetyDistance`` d_s (m, >= 0, default 0.01), ``influenceDistance`` d_i
    (m, > d_s, default 0.05); ``setDistances(d_s, d_i)`` sets both, refusing an
    inconsistent pair and leaving both as they were.

    Outputs: ``error`` (the distances d of the pairs under d_i, m, in the order of the
    pair list), ``jacobian`` (their ``J_d``, rows x nv), ``errordot`` (zeros),
    ``activePairs`` (the rows' pair indices, a vector of ints), ``minDistance`` (m: the
    smallest distance over every pair; exact when under d_i, a lower bound from the
    broad phase otherwise), ``narrowPhaseCount`` (how many pairs reached coal this
    tick).

    Commands: ``addObstacle(name, shape, size, placement, frame=None)``,
    ``removeObstacle(name)``, ``setObstaclePlacement(name, placement)``,
    ``listObstacles()``, ``addPair(a, b)``, ``removePair(a, b)``, ``clearPairs()``,
    ``listPairs()``,
    ``getPairCount()``, ``listGeometries()``, ``pairName(k)``, ``setDistances(d_s, d_i)``.
    Each edit is checked first and refused with a :class:`~sotpy.errors.CommandError`
    (naming the entity, what was given and what was expected) that leaves the feature as
    it was.
    """

    className = "FeatureCollision"

    kinematics = Input(INT, doc="the Dynamic's kinematics pass (plugged by the constructor)")
    safetyDistance = Input(DOUBLE, default=DEFAULT_SAFETY, doc="d_s (m), >= 0")
    influenceDistance = Input(DOUBLE, default=DEFAULT_INFLUENCE, doc="d_i (m), > d_s")

    @Output(INT, withTime=True, deps=("kinematics", "safetyDistance", "influenceDistance"))
    def collisions(self, t: int, _kinematics: int, ds: float, di: float) -> int:
        """The pass: broad phase, narrow phase and rows of the tick (its value is the
        tick); every other output reads it."""
        if not _goodDistances(ds, di):
            checkDamper(
                f"{self.className}({self.name}): {self.safetyDistance.name}, "
                f"{self.influenceDistance.name}",
                ds,
                di,
                None,
            )
        self.core.compute(self._data, di)
        return t

    @Output(VECTOR, deps=("collisions",))
    def activePairs(self, _pass: int) -> np.ndarray:
        """Indices (in :meth:`listPairs`) of the pairs that are rows this tick."""
        return self.core.rowPairs.astype(float)

    @Output(DOUBLE, deps=("collisions",))
    def minDistance(self, _pass: int) -> float:
        """The smallest distance over every pair (m): exact when under d_i, otherwise a
        lower bound (the broad phase's)."""
        return self.core.minDistance

    @Output(INT, deps=("collisions",))
    def narrowPhaseCount(self, _pass: int) -> int:
        """How many pairs passed the broad phase and were computed by coal this tick."""
        return self.core.narrow

    def __init__(
        self,
        name: str,
        robot: Any,
        srdf: str | Path | None = "auto",
        geometry: pin.GeometryModel | None = None,
    ) -> None:
        dynamic = getattr(robot, "dynamic", robot)
        model = getattr(dynamic, "model", None)
        if not isinstance(model, pin.Model) or not hasattr(dynamic, "kinematics"):
            raise EntityError(
                f"FeatureCollision({name}): expected a Robot or a Dynamic entity, got {robot!r}"
            )
        if geometry is None:
            geometry = getattr(robot, "collision_model", None)
        if not isinstance(geometry, pin.GeometryModel):
            raise EntityError(
                f"FeatureCollision({name}): no collision model: pass a Robot, or "
                "geometry=<pinocchio.GeometryModel> with a Dynamic"
            )
        if srdf == "auto":
            srdf = robotSrdf(robot)
        if srdf is not None and not Path(srdf).is_file():
            raise EntityError(f"FeatureCollision({name}): no SRDF file {str(srdf)!r}")
        self._dynamic = dynamic
        self._data: pin.Data = dynamic.data
        self.core = CollisionPairs(model, geometry, srdf, who=f"FeatureCollision({name})")
        super().__init__(name)
        plug(dynamic.kinematics, self.kinematics)

    # -- wiring -------------------------------------------------------------------------
    def _errorDeps(self) -> list[Signal]:
        return [self.collisions]

    def _jacobianDeps(self) -> list[Signal]:
        return [self.collisions]

    def _error(self, _pass: int) -> np.ndarray:
        return self.core.rowD.copy()

    def _jacobian(self, _pass: int) -> np.ndarray:
        return self.core.rowJ.copy()

    def _changed(self) -> None:
        self.collisions.setReady()

    def distances(self) -> np.ndarray:
        """The distance of every pair (m), in the order of :meth:`listPairs`, computed by
        coal now at the Dynamic's current configuration (for checks and tests; not the
        tick's path, which skips far pairs)."""
        self._dynamic.kinematics.value  # noqa: B018 - run the kinematics pass
        return self.core.distances(self._data)

    @command
    def listGeometries(self) -> list[str]:
        """The geometries' names: the robot's, then the obstacles'."""
        return self.core.listGeometries()

    @command
    def listPairs(self) -> list[str]:
        """The pairs, ``"a : b"`` by geometry name; a row's index in ``activePairs`` is
        its index here."""
        return self.core.listPairs()

    @command
    def getPairCount(self) -> int:
        """The number of pairs."""
        return self.core.getPairCount()

    @command
    def pairName(self, k: int) -> str:
        """The pair of index ``k``, ``"a : b"``."""
        return self.core.pairName(k)

    @command
    def addPair(self, a: str, b: str) -> None:
        """Check the pair of geometries ``a`` and ``b`` (names) too."""
        self.core.addPair(a, b)
        self._changed()

    @command
    def removePair(self, a: str, b: str) -> None:
        """Stop checking the pair of geometries ``a`` and ``b`` (names)."""
        self.core.removePair(a, b)
        self._changed()

    @command
    def clearPairs(self) -> None:
        """Check no pair (``addPair`` or ``addObstacle`` add some back)."""
        self.core.clearPairs()
        self._changed()

    @command
    def addObstacle(
        self,
        name: str,
        shape: str,
        size: Sequence[float] | float,
        placement: Any,
        frame: str | None = None,
    ) -> None:
        """Add an obstacle (see :meth:`CollisionPairs.addObstacle`): ``shape`` ``"box"``
        (side lengths), ``"sphere"`` (radius) or ``"capsule"`` (radius, length), m;
        ``placement`` in the world, or in ``frame`` (a frame of the model)."""
        self.core.addObstacle(name, shape, size, placement, frame)
        self._changed()

    @command
    def removeObstacle(self, name: str) -> None:
        """Remove the obstacle ``name`` and its pairs."""
        self.core.removeObstacle(name)
        self._changed()

    @command
    def setObstaclePlacement(self, name: str, placement: Any) -> None:
        """Move the obstacle ``name`` (its placement in the world or in its frame)."""
        self.core.setObstaclePlacement(name, placement)
        self._changed()

    @command
    def listObstacles(self) -> list[str]:
        """The obstacles' names."""
        return self.core.listObstacles()

    @command
    def setDistances(self, safety: float, influence: float) -> None:
        """Set ``safetyDistance`` d_s and ``influenceDistance`` d_i (m); refused (both
        unchanged) unless ``0 <= d_s < d_i``, finite."""
        try:
            checkDamper(f"{self.className}({self.name}).setDistances", safety, influence, None)
        except SignalTypeError as exc:
            raise CommandError(str(exc)) from None
        self.safetyDistance.value = float(safety)
        self.influenceDistance.value = float(influence)


# -- the task ---------------------------------------------------------------------------
class TaskCollision(TaskAbstract):
    r"""The velocity damper on every pair of its features under the influence distance:
    ``lower = -xi (d - d_s) / (d_i - d_s) <= J_d qdot`` (``upper = +inf``), with ``d_s``
    and ``d_i`` each feature's ``safetyDistance`` and ``influenceDistance`` (see the
    module doc). Input ``controlGain``: xi (m/s, > 0, default 0.5); ``setGain(xi)``
    refuses a bad one and keeps the old. Features: :class:`FeatureCollision` only. Its
    number of rows changes from tick to tick (zero when no pair is close)."""

    className = "TaskCollision"
    isInequality = True

    controlGain = Input(DOUBLE, default=DEFAULT_GAIN, doc="xi (m/s), > 0: approach speed at d_i")

    @Output(VECTOR, timeDependent=False)
    def lower(self, xi: float, *values: Any) -> np.ndarray:
        """-xi (d - d_s) / (d_i - d_s) for every row (m/s)."""
        if not (math.isfinite(xi) and xi > 0.0):
            raise SignalTypeError(
                f"{self.controlGain.name}: expected a damper gain xi > 0 (m/s), got {xi!r}"
            )
        parts = []
        for k, f in enumerate(self._wired):
            d, ds, di = values[3 * k : 3 * k + 3]
            if not _goodDistances(ds, di):
                checkDamper(
                    f"{self.className}({self.name}): {f.safetyDistance.name}, "
                    f"{f.influenceDistance.name}",
                    ds,
                    di,
                    None,
                )
            parts.append(-xi * (d - ds) / (di - ds))
        if len(parts) == 1:
            return parts[0]
        return np.concatenate(parts) if parts else np.zeros(0)

    @Output(VECTOR, timeDependent=False)
    def upper(self, e: np.ndarray) -> np.ndarray:
        """+inf: a distance may grow as fast as it likes."""
        out = np.empty(e.shape[0])
        out.fill(math.inf)
        return out

    def _wireOutputs(self) -> None:
        deps: list[Signal] = [self.controlGain]
        for f in self._wired:
            deps += [f.error, f.safetyDistance, f.influenceDistance]
        self.lower.setDependencies(deps)
        self.upper.setDependencies([self.error])

    def _resolve(self, cmd: str, feature: Any) -> Any:
        f = super()._resolve(cmd, feature)
        if not isinstance(f, FeatureCollision):
            raise CommandError(
                f"{self.className}({self.name}).{cmd}: {f.name} is a {f.className}; a "
                "TaskCollision takes FeatureCollision features"
            )
        return f

    @command
    def setGain(self, xi: float) -> None:
        """Set ``controlGain`` xi (m/s, finite, > 0); refused (unchanged) otherwise."""
        if not (isinstance(xi, (int, float)) and math.isfinite(xi) and xi > 0.0):
            raise CommandError(
                f"{self.className}({self.name}).setGain: {self.controlGain.name}: expected a "
                f"damper gain xi > 0 (m/s), got {xi!r}"
            )
        self.controlGain.value = float(xi)
