r"""Ready tasks of a robot: ``robot.tasks["left-ankle"]``, ``["com"]``, ``["posture"]``...

The SoT's ``AbstractHumanoidRobot`` (before 2013) built a feature and a task for each
operational point, a CoM task and a posture task when the robot was created
(``robot.features[op]``, ``robot.tasks[op]``, ``robot.comTask``). sotpy builds them
**on first access** instead (``load_robot`` creates no task), as SoT's meta-tasks::

    robot = load_robot("talos")
    lf = robot.tasks["left-ankle"]        # MetaTaskKine6d, holding its placement
    rh = robot.tasks["right-wrist"]
    rh.gotoNd(target, "111000", gain=2.0)
    sot.push(lf.task)                     # the meta-task's Task entity
    sot.push(rh.task)
    sot.push(robot.tasks["posture"].task) # MetaTaskKinePosture, towards half-sitting

``robot.tasks`` is a :class:`ReadyTasks`, a read-only mapping from a key to a
meta-task; the keys (``list(robot.tasks)``) are:

==================  =====================================================================
key                 value (created on first access, then the same object)
==================  =====================================================================
an op point         :class:`~sotpy.tasks.meta_task.MetaTaskKine6d` on that op point
(``left-ankle``,    of ``robot.dynamic`` (every op point of the description: feet,
``right-wrist``,    wrists, gaze, chest, waist; ``end-effector`` for an arm), selection
``gaze``, ...)      ``"111111"``, ``keep()``: it holds the placement the op point has
                    when the task is created
``com``             :class:`~sotpy.tasks.meta_task.MetaTaskKineCom`, selection ``"11"``
                    (the ground projection, SoT's ``comTask``), ``keep()``
``posture``         :class:`~sotpy.tasks.meta_task.MetaTaskKinePosture` towards
                    ``robot.halfSitting`` (``feature.state`` plugged to ``device.state``)
``balance``         :class:`MetaTaskKineBalance` (robots with feet): the CoM's ground
                    projection kept inside the support polygon of the feet's current
                    placement, shrunk by :data:`BALANCE_MARGIN`
``couplings``       :class:`MetaTaskKineCouplings` (robots with couplings, e.g. Nao's
                    HipYawPitch pair): ``q_joint = multiplier q_master + offset``
==================  =====================================================================

Every gain is the meta-tasks' default, a constant 0.1 1/s (set it with ``gain=`` of
``gotoNd``/``gotoq``, or ``meta.gain.setConstant(g)``); the inequality task of
``balance`` takes its period ``dt`` from the device's last ``increment`` if there was
one, else it must be set (``robot.tasks["balance"].task.dt.value = dt``).

Entity names start with the robot's prefix (that of ``load_robot(name, prefix)``, read
from ``robot.dynamic``'s name ``<prefix>_dynamic``), so that two robots in one pool do
not collide: the meta-task of key ``k`` is named ``_<prefix>_<k>``, hence the entities
``feature_<prefix>_<k>``, ``task_<prefix>_<k>``, ``gain_<prefix>_<k>`` (an op point's
also ``opmodif_<prefix>_<k>``, its ``OpPointModifier``; and
``featureDes_<prefix>_com``, ``polygon_<prefix>_balance``,
``couplings_<prefix>_couplings``).

This module is imported lazily by :attr:`sotpy.dynamics.robot.Robot.tasks`: the
dynamics layer must not import the tasks layer at module level (``tasks`` imports
``dynamics``; the layers of :doc:`docs/architecture.md </architecture>`).

The entities of the two tasks SoT did not have
-------------------------------------------------

:class:`SupportPolygon`. For a convex polygon with vertices ``v_0 .. v_{k-1}``
counter-clockwise (m, world xy), edge ``i`` goes from ``v_i`` to ``v_{i+1}``; its outward
unit normal is ``n_i = (d_y, -d_x) / |d|`` with ``d = v_{i+1} - v_i``, and its offset
``b_i = n_i . v_i``. A point ``p`` is inside iff ``N p <= b`` row by row (``N`` the
``k x 2`` matrix of the normals), and ``b_i - n_i . p`` is its distance to the line of
edge ``i`` (positive inside); inside, the smallest of them is its distance to the
boundary. The entity outputs ``value = N c_xy`` and ``jacobian = N Jcom_xy`` (``c`` the
CoM, ``Jcom`` its 3 x nv Jacobian), the ``errorIN``/``jacobianIN`` of a
``FeatureGeneric``; a ``TaskInequality`` with ``referenceSup = b - margin`` keeps the CoM's
projection inside the polygon shrunk by ``margin`` (every edge moved inwards by
``margin``).

:class:`JointCouplings`. For couplings ``q_j = m q_master + o`` between one-DoF joints,
``value`` is the vector of residuals ``q_j - m q_master - o`` (rad or m) and ``jacobian``
the constant rows ``e_{v(j)} - m e_{v(master)}`` (``v(.)`` the joint's velocity index).
"""

from __future__ import annotations

import contextlib
import math
from collections.abc import Iterator, Mapping, Sequence
from typing import Any

import numpy as np

from ..dynamics import Dynamic
from ..errors import CommandError, EntityError, RobotError, SignalTypeError, SotpyError
from ..graph import MATRIX, VECTOR, Entity, Input, Output, command, plug, pool
from .features import FeatureGeneric
from .meta_task import MetaTaskKine6d, MetaTaskKineCom, MetaTaskKinePosture, _MetaTask
from .task import Task, TaskInequality

__all__ = [
    "BALANCE_MARGIN",
    "JointCouplings",
    "MetaTaskKineBalance",
    "MetaTaskKineCouplings",
    "ReadyTasks",
    "SupportPolygon",
    "polygonHalfPlanes",
]

#: Default margin of the ``balance`` ready task: the support polygon's edges are moved
#: inwards by this (m).
BALANCE_MARGIN = 0.01


# -- polygons --------------------------------------------------------------------------
def polygonHalfPlanes(vertices: Any) -> tuple[np.ndarray, np.ndarray]:
    """Half-planes of a convex polygon: ``p`` inside iff ``N p <= b``.

    Args:
        vertices: (k, 2) array, k >= 3, the vertices in counter-clockwise order (m),
            as :meth:`sotpy.dynamics.robot.Robot.supportPolygon` returns them.

    Returns:
        ``(N, b)``: ``N`` (k, 2), row ``i`` the outward unit normal of the edge from
        vertex ``i`` to vertex ``i + 1``; ``b`` (k,), ``b_i = N_i . v_i`` (m).

    Raises:
        ValueError: fewer than 3 vertices, non-finite values, a zero-length edge, or
            vertices that are not a convex polygon in counter-clockwise order.
    """
    v = np.asarray(vertices, dtype=float)
    if v.ndim != 2 or v.shape[1] != 2 or v.shape[0] < 3:
        raise ValueError(
            f"a polygon is a (k, 2) array of vertices with k >= 3, got shape {v.shape}"
        )
    if not np.isfinite(v).all():
        raise ValueError("the polygon's vertices must be finite")
    d = np.roll(v, -1, axis=0) - v
    length = np.linalg.norm(d, axis=1)
    if (length <= 1e-12).any():
        i = int(np.argmin(length))
        raise ValueError(f"the polygon's edge {i} (vertex {i} to the next) has zero length")
    N = np.column_stack((d[:, 1], -d[:, 0])) / length[:, None]
    b = np.einsum("ij,ij->i", N, v)
    # convex and counter-clockwise: every vertex on the inner side of every edge
    slack = b[:, None] - N @ v.T  # slack[i, j] = b_i - n_i . v_j >= 0
    if (slack < -1e-9 * (1.0 + np.abs(v).max())).any():
        raise ValueError(
            "the vertices are not a convex polygon in counter-clockwise order (use "
            "sotpy.dynamics.robot.convex_hull_2d)"
        )
    return N, b


class SupportPolygon(Entity):
    r"""The CoM's ground projection against the edges of a convex polygon.

    ``SupportPolygon(name)``; ``setPolygon(vertices)`` (a (k, 2) array, counter-clockwise,
    m) sets the half-planes ``N p <= b`` (see :func:`polygonHalfPlanes`). Inputs ``com``
    (3, m, world; plug ``dynamic.com``) and ``Jcom`` (3 x nv; plug ``dynamic.Jcom``).
    Outputs ``value = N c_xy`` (k, m) and ``jacobian = N Jcom[:2]`` (k x nv), for a
    ``FeatureGeneric``; ``offsets`` = ``b`` (k, m) and ``distances = b - N c_xy`` (k, m,
    positive inside: the distance to each edge's line).
    """

    com = Input(VECTOR, doc="CoM c (3, m, world axes): plug dynamic.com")
    Jcom = Input(MATRIX, doc="CoM Jacobian (3 x nv): plug dynamic.Jcom")

    @Output(VECTOR, deps=("com",), doc="N c_xy (k, m): the projections on the edge normals")
    def value(self, com: np.ndarray) -> np.ndarray:
        """``N c_xy`` (k, m)."""
        N = self._normals()
        if com.shape != (3,):
            raise SignalTypeError(f"{self.com.name}: expected a 3-vector (m), received {com.shape}")
        return N @ com[:2]

    @Output(MATRIX, deps=("Jcom",), doc="N Jcom_xy (k x nv)")
    def jacobian(self, Jcom: np.ndarray) -> np.ndarray:
        """``N Jcom[:2]`` (k x nv)."""
        N = self._normals()
        if Jcom.ndim != 2 or Jcom.shape[0] != 3:
            raise SignalTypeError(
                f"{self.Jcom.name}: expected a 3 x nv matrix, received shape {Jcom.shape}"
            )
        return N @ Jcom[:2]

    @Output(VECTOR, deps=("value",), doc="b - N c_xy (k, m): distance to each edge's line")
    def distances(self, value: np.ndarray) -> np.ndarray:
        """``b - N c_xy`` (k, m), positive inside."""
        return self._b - value

    def __init__(self, name: str) -> None:
        self._N: np.ndarray | None = None
        self._b = np.zeros(0)
        self._vertices = np.zeros((0, 2))

    def _normals(self) -> np.ndarray:
        if self._N is None:
            raise SotpyError(
                f"SupportPolygon({self.name}): no polygon set (call setPolygon(vertices))"
            )
        return self._N

    @command
    def setPolygon(self, vertices: np.ndarray) -> None:
        """Set the polygon: (k, 2) vertices (m), convex, counter-clockwise."""
        try:
            N, b = polygonHalfPlanes(vertices)
        except ValueError as exc:
            raise CommandError(f"SupportPolygon({self.name}).setPolygon: {exc}") from None
        self._N, self._b = N, b
        self._vertices = np.array(vertices, dtype=float)
        self.value.setReady()
        self.jacobian.setReady()
        self.distances.setReady()

    @command
    def getVertices(self) -> np.ndarray:
        """The polygon's vertices, (k, 2), m."""
        return self._vertices.copy()

    @command
    def getNormals(self) -> np.ndarray:
        """``N`` (k, 2): the edges' outward unit normals."""
        return self._normals().copy()

    @command
    def getOffsets(self) -> np.ndarray:
        """``b`` (k,): ``N p <= b`` inside (m)."""
        self._normals()
        return self._b.copy()


class JointCouplings(Entity):
    r"""Residuals of joint couplings ``q_j = m q_master + o`` (one-DoF joints).

    ``JointCouplings(name, model, couplings)``: ``model`` a ``pinocchio.Model``,
    ``couplings`` a sequence of :class:`~sotpy.dynamics.robot.Coupling` (or of tuples
    ``(joint, master, multiplier, offset)``). Input ``state`` (q, size nq). Outputs
    ``value`` (one residual ``q_j - m q_master - o`` per coupling, rad or m) and
    ``jacobian`` (constant rows ``e_{v(j)} - m e_{v(master)}``, size c x nv).
    """

    state = Input(VECTOR, doc="configuration q (size nq): plug device.state")

    @Output(VECTOR, deps=("state",), doc="q_j - m q_master - o per coupling (rad or m)")
    def value(self, q: np.ndarray) -> np.ndarray:
        """The coupling residuals."""
        if q.shape != (self._nq,):
            raise SignalTypeError(
                f"{self.state.name}: expected a configuration of size nq = {self._nq}, "
                f"received shape {q.shape}"
            )
        return q[self._iq] - self._m * q[self._iqm] - self._o

    @Output(MATRIX, timeDependent=False, doc="d value / dq (c x nv), constant")
    def jacobian(self) -> np.ndarray:
        """The constant Jacobian (a read-only array)."""
        return self._J

    def __init__(self, name: str, model: Any, couplings: Sequence[Any]) -> None:
        rows = []
        for c in couplings:
            if hasattr(c, "joint"):
                rows.append((c.joint, c.master, float(c.multiplier), float(c.offset)))
            else:
                j, master, m, o = c
                rows.append((str(j), str(master), float(m), float(o)))
        if not rows:
            raise EntityError(f"JointCouplings({name}): no coupling given")
        iq, iqm, iv, ivm = [], [], [], []
        for j, master, _, _ in rows:
            for n in (j, master):
                if not model.existJointName(n):
                    raise EntityError(f"JointCouplings({name}): no joint {n!r} in the model")
                jm = model.joints[model.getJointId(n)]
                if jm.nq != 1 or jm.nv != 1:
                    raise EntityError(f"JointCouplings({name}): joint {n!r} is not one-DoF")
            jj, jmst = model.joints[model.getJointId(j)], model.joints[model.getJointId(master)]
            iq.append(jj.idx_q)
            iqm.append(jmst.idx_q)
            iv.append(jj.idx_v)
            ivm.append(jmst.idx_v)
        self._nq = int(model.nq)
        self.couplings = rows
        self._iq, self._iqm = np.array(iq), np.array(iqm)
        self._m = np.array([r[2] for r in rows])
        self._o = np.array([r[3] for r in rows])
        J = np.zeros((len(rows), model.nv))
        for r, (a, b, m) in enumerate(zip(iv, ivm, self._m, strict=True)):
            J[r, a] += 1.0
            J[r, b] -= m
        J.flags.writeable = False
        self._J = J

    @command
    def list(self) -> list[str]:
        """The couplings, ``"joint = m * master + o"``."""
        return [f"{j} = {m:g} * {mst} + {o:g}" for j, mst, m, o in self.couplings]


# -- meta-tasks --------------------------------------------------------------------------
class MetaTaskKineBalance(_MetaTask):
    """The CoM's ground projection kept inside a convex polygon (static balance).

    ``MetaTaskKineBalance(dynamic, vertices, margin=BALANCE_MARGIN, dt=None,
    name="balance")`` creates ``polygon`` = :class:`SupportPolygon` ``('polygon' +
    name)`` on ``dynamic.com``/``dynamic.Jcom``, ``feature`` = ``FeatureGeneric('feature'
    + name)`` on its ``value``/``jacobian`` (the projections ``N c_xy``) and ``task`` =
    ``TaskInequality('task' + name)`` with ``referenceSup = b - margin``: the CoM's
    projection stays inside the polygon with every edge moved inwards by ``margin`` (m).
    With the task's ``controlGain`` ``k`` (default 1) and period ``dt`` (s; required),
    ``N Jcom_xy qdot <= k (b - margin - N c_xy) / dt`` (``docs/tasks.md``).
    """

    _entityAttributes = ("polygon", "feature", "task")

    def __init__(
        self,
        dynamic: Dynamic,
        vertices: Any,
        margin: float = BALANCE_MARGIN,
        dt: float | None = None,
        name: str = "balance",
    ) -> None:
        self.name = name
        if not isinstance(dynamic, Dynamic):
            raise EntityError(
                f"MetaTaskKineBalance({name!r}): expected a Dynamic entity, got {dynamic!r}"
            )
        self.dynamic = self.dyn = dynamic
        self._reserve("MetaTaskKineBalance", ["polygon" + name, "feature" + name, "task" + name])
        self._margin = self._checkMargin(margin)

        def steps() -> None:
            self.polygon = SupportPolygon("polygon" + name)
            self.polygon.setPolygon(np.asarray(vertices, dtype=float))
            self.feature = FeatureGeneric("feature" + name)
            self.task = TaskInequality("task" + name)
            plug(dynamic.com, self.polygon.com)
            plug(dynamic.Jcom, self.polygon.Jcom)
            plug(self.polygon.value, self.feature.errorIN)
            plug(self.polygon.jacobian, self.feature.jacobianIN)
            self.task.add(self.feature)
            self._setBounds()
            if dt is not None:
                self.task.dt.value = float(dt)

        self._build(steps)

    def _checkMargin(self, margin: Any) -> float:
        if isinstance(margin, bool) or not isinstance(margin, (int, float)):
            raise CommandError(f"MetaTaskKineBalance({self.name!r}): margin must be a number (m)")
        if not (math.isfinite(margin) and margin >= 0):
            raise CommandError(
                f"MetaTaskKineBalance({self.name!r}): margin must be finite and >= 0 m, got "
                f"{margin!r}"
            )
        return float(margin)

    def _setBounds(self) -> None:
        self.task.referenceSup.value = self.bounds()

    def bounds(self) -> np.ndarray:
        """``b - margin`` (k, m): the task's ``referenceSup``."""
        return self.polygon.getOffsets() - self._margin

    @property
    def margin(self) -> float:
        """How far inside the polygon's edges the CoM's projection must stay (m)."""
        return self._margin

    def setMargin(self, margin: float) -> None:
        """Move the bounds: every edge ``margin`` (m, >= 0) inwards."""
        self._margin = self._checkMargin(margin)
        self._setBounds()

    def setPolygon(self, vertices: Any) -> None:
        """A new polygon ((k, 2) vertices, counter-clockwise, m); the margin is kept.
        The task's size is the number of edges."""
        self.polygon.setPolygon(np.asarray(vertices, dtype=float))
        self._setBounds()

    def distances(self) -> np.ndarray:
        """``b - N c_xy`` now (k, m): the CoM projection's distance to each edge's line."""
        return self.polygon.distances.value


class MetaTaskKineCouplings(_MetaTask):
    """Joint couplings as an equality task: ``q_j - m q_master - o -> 0``.

    ``MetaTaskKineCouplings(model, couplings, state, name="couplings")`` creates
    ``couplings`` = :class:`JointCouplings` ``('couplings' + name)`` (``state`` plugged
    to the given output signal, e.g. ``device.state``), ``feature`` =
    ``FeatureGeneric('feature' + name)`` on its residuals, ``task`` = ``Task('task' +
    name)`` with ``controlGain`` 1 1/s. The residuals are zero at half-sitting; with the
    task at a priority the stack meets, the coupled joints move together.
    """

    _entityAttributes = ("couplings", "feature", "task")

    def __init__(
        self, model: Any, couplings: Sequence[Any], state: Any, name: str = "couplings"
    ) -> None:
        self.name = name
        self._reserve(
            "MetaTaskKineCouplings", ["couplings" + name, "feature" + name, "task" + name]
        )

        def steps() -> None:
            self.couplings = JointCouplings("couplings" + name, model, couplings)
            self.feature = FeatureGeneric("feature" + name)
            self.task = Task("task" + name)
            plug(state, self.couplings.state)
            plug(self.couplings.value, self.feature.errorIN)
            plug(self.couplings.jacobian, self.feature.jacobianIN)
            self.task.add(self.feature)

        self._build(steps)


# -- the accessor ----------------------------------------------------------------------
_DIRECT = ("com", "posture", "balance", "couplings")


class ReadyTasks(Mapping[str, Any]):
    """A robot's ready tasks: key -> meta-task, created on first access (see the module
    doc for the keys, the entities and their names).

    ``tasks[key]`` creates the meta-task the first time and returns the same object
    afterwards; ``key in tasks``, ``list(tasks)``, ``len(tasks)`` and :meth:`created`
    create nothing (``values()`` and ``items()`` create them all). An unknown key raises
    :class:`~sotpy.errors.RobotError` listing the available ones.
    """

    def __init__(self, robot: Any) -> None:
        self._robot = robot
        name = robot.dynamic.name
        self.prefix: str = name[: -len("_dynamic")] if name.endswith("_dynamic") else name
        keys = list(robot.opPoints)
        keys += ["com", "posture"]
        if robot.feet:
            keys.append("balance")
        if robot.couplings:
            keys.append("couplings")
        self._keys = keys
        self._made: dict[str, Any] = {}

    # -- mapping -----------------------------------------------------------------------
    def __getitem__(self, key: str) -> Any:
        made = self._made.get(key)
        if made is not None:
            return made
        if key not in self._keys:
            raise RobotError(
                f"robot {self._robot.name!r} (prefix {self.prefix!r}) has no ready task "
                f"{key!r}; available: {', '.join(self._keys)}"
            )
        made = self._make(key)
        self._made[key] = made
        return made

    def __contains__(self, key: object) -> bool:
        return key in self._keys

    def __iter__(self) -> Iterator[str]:
        return iter(self._keys)

    def __len__(self) -> int:
        return len(self._keys)

    def get(self, key: str, default: Any = None) -> Any:
        """``tasks[key]`` (created if needed) if ``key`` is available, else ``default``."""
        return self[key] if key in self._keys else default

    def created(self) -> dict[str, Any]:
        """The meta-tasks created so far, key -> meta-task."""
        return dict(self._made)

    def name(self, key: str) -> str:
        """The meta-task name of ``key`` (``_<prefix>_<key>``): its entities are
        ``feature_<prefix>_<key>``, ``task_<prefix>_<key>``..."""
        return f"_{self.prefix}_{key}"

    def __repr__(self) -> str:
        made = ", ".join(self._made) or "none"
        return f"ReadyTasks({self._robot.name!r}, keys: {', '.join(self._keys)}; created: {made})"

    # -- construction ------------------------------------------------------------------
    def _make(self, key: str) -> Any:
        robot = self._robot
        name = self.name(key)
        dyn = robot.dynamic
        if key not in _DIRECT:
            meta = MetaTaskKine6d(name, dyn, key)
            try:
                meta.keep()
            except BaseException:
                _remove(meta)
                raise
            return meta
        if key == "com":
            meta = MetaTaskKineCom(dyn, name)
            try:
                meta.feature.selec.value = "11"
                meta.keep()
            except BaseException:
                _remove(meta)
                raise
            return meta
        if key == "posture":
            meta = MetaTaskKinePosture(dyn, robot.device, name)
            meta.gotoq(robot.halfSitting)
            return meta
        if key == "balance":
            dt = None
            with contextlib.suppress(SotpyError):  # no increment yet: dt left unset
                dt = robot.device.getTimeStep()
            return MetaTaskKineBalance(dyn, robot.supportPolygon(), BALANCE_MARGIN, dt, name)
        # couplings
        return MetaTaskKineCouplings(
            robot.model, list(robot.couplings.values()), robot.device.state, name
        )


def _remove(meta: Any) -> None:
    names = [e.name for e in meta.entities() if pool.hasEntity(e.name)]
    if names:
        pool.remove(*names)  # together: they use one another
