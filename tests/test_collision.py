"""FeatureCollision and TaskCollision: the pairs, the distance and its Jacobian, the
damper's rows appearing and disappearing, the SOT with a level of changing size, and
bad input."""

from __future__ import annotations

import xml.etree.ElementTree as ET

import numpy as np
import pinocchio as pin
import pytest

from sotpy.dynamics import Dynamic, load_robot
from sotpy.errors import CommandError, EntityError, SignalTypeError
from sotpy.graph import plug
from sotpy.solvers import SOT
from sotpy.tasks import FeatureGeneric, Task
from sotpy.tasks.collision import (
    FeatureCollision,
    TaskCollision,
    collisionPairs,
    convexGeometryModel,
    robotSrdf,
)

RNG = np.random.default_rng(24)


@pytest.fixture(scope="module")
def talos():
    from sotpy.graph.pool import pool

    r = load_robot("talos", prefix="coll_mod")
    yield r
    pool.clear()


def _robot():
    return load_robot("talos", prefix="c")


def test_pairs_are_the_srdf_minus_adjacent_links():
    r = _robot()
    srdf = robotSrdf(r)
    assert srdf is not None and srdf.name == "talos.srdf"
    pairs = collisionPairs(r.model, r.collision_model, srdf)
    # Pinocchio's own removal, then the adjacent links removed here independently
    gm = r.collision_model.copy()
    gm.addAllCollisionPairs()
    total = len(gm.collisionPairs)
    pin.removeCollisionPairs(r.model, gm, str(srdf))
    objs = gm.geometryObjects
    adjacent = 0
    for p in gm.collisionPairs:
        a, b = objs[p.first].parentJoint, objs[p.second].parentJoint
        adjacent += a == b or r.model.parents[a] == b or r.model.parents[b] == a
    assert len(pairs) == len(gm.collisionPairs) - adjacent
    # (Pinocchio's "all pairs" already leaves out the geometries of one joint)
    joints = [g.parentJoint for g in objs]
    distinct = sum(a != b for i, a in enumerate(joints) for b in joints[i + 1 :])
    assert total == distinct and len(pairs) < len(gm.collisionPairs) < total
    # every pair the SRDF disables is absent (by link name: geometry <link>_0)
    names = [g.name for g in r.collision_model.geometryObjects]
    kept = {frozenset((names[i], names[j])) for i, j in pairs}
    disabled = [
        frozenset((e.get("link1") + "_0", e.get("link2") + "_0"))
        for e in ET.parse(srdf).getroot().iter("disable_collisions")
    ]
    present = [d for d in disabled if all(n in names for n in d)]
    assert len(present) > 100
    assert not kept & set(present)
    # a pair of the same joint is absent, a far one is there
    assert frozenset(("arm_right_7_link_0", "gripper_right_base_link_0")) not in kept
    assert frozenset(("arm_right_7_link_0", "torso_2_link_0")) in kept
    f = FeatureCollision("f", r)
    assert f.getPairCount() == len(pairs)


def test_convex_hulls_bound_the_meshes_distance_from_below():
    r = _robot()
    hulls = convexGeometryModel(r.collision_model)
    assert r.collision_model.geometryObjects[0].geometry.getNodeType() != (
        hulls.geometryObjects[0].geometry.getNodeType()
    )
    data = r.model.createData()
    q = r.halfSitting
    pin.framesForwardKinematics(r.model, data, q)
    gm, gh = r.collision_model.copy(), hulls
    ids = [gm.getGeometryId(n) for n in ("arm_right_5_link_0", "torso_2_link_0")]
    for g in (gm, gh):
        g.removeAllCollisionPairs()
        g.addCollisionPair(pin.CollisionPair(*ids))
    dm, dh = pin.GeometryData(gm), pin.GeometryData(gh)
    pin.updateGeometryPlacements(r.model, data, gm, dm)
    pin.updateGeometryPlacements(r.model, data, gh, dh)
    pin.computeDistances(gm, dm)
    pin.computeDistances(gh, dh)
    mesh, hull = dm.distanceResults[0].min_distance, dh.distanceResults[0].min_distance
    assert 0.0 < hull <= mesh + 1e-9


def _dyn(r, q):
    dyn = Dynamic("fd_dyn", r.model)
    dyn.position.value = q
    return dyn


def test_distance_and_jacobian_match_finite_differences():
    r = _robot()
    q0 = r.halfSitting.copy()
    # the right arm folded towards the torso: arm-torso pairs inside d_i
    model = r.model
    for name, val in (("arm_right_1_joint", 0.3), ("arm_right_2_joint", -0.05)):
        q0[model.joints[model.getJointId(name)].idx_q] = val
    dyn = _dyn(r, q0)
    f = FeatureCollision("fd", dyn, geometry=r.collision_model, srdf=robotSrdf(r))
    f.setDistances(0.0, 0.08)
    d0 = f.error.value
    J = f.jacobian.value
    rows = f.activePairs.value.astype(int)
    assert len(rows) >= 10 and J.shape == (len(rows), model.nv)
    # the feature's distances are coal's, for these pairs, at this configuration
    np.testing.assert_allclose(d0, f.distances()[rows], atol=1e-7)  # GJK's tolerance
    eps = 1e-4
    for _ in range(5):
        v = RNG.normal(size=model.nv)
        v[:6] *= 0.2
        ds = []
        for s in (1.0, -1.0):
            dyn.position.value = pin.integrate(model, q0, s * eps * v)
            ds.append(f.distances()[rows])
        dyn.position.value = q0
        fd = (ds[0] - ds[1]) / (2 * eps)
        # convex hulls: the witness points may jump between faces; most rows are smooth
        err = np.abs(J @ v - fd)
        # hulls are polytopes: where a witness point is about to change face or vertex
        # the distance is not smooth at the scale of eps; everywhere else it is exact
        assert np.median(err) < 1e-7
        assert (err < 1e-6).mean() >= 0.8
        assert err.max() < 2e-3 * np.linalg.norm(v)


def test_jacobian_of_a_sphere_pair_matches_finite_differences_exactly():
    # a sphere fixed to the right wrist against a sphere in the world: unique witness
    # points, d = |c1 - c2| - r1 - r2 computed here without coal
    r = _robot()
    model = r.model
    dyn = _dyn(r, r.halfSitting)
    f = FeatureCollision("sph", dyn, geometry=r.collision_model, srdf=None)
    f.clearPairs()
    fid = model.getFrameId("arm_right_7_joint")
    data = model.createData()

    def centre(q):
        pin.framesForwardKinematics(model, data, q)
        return data.oMf[fid].act(np.array([0.0, 0.0, -0.1]))

    c0 = centre(r.halfSitting)
    ball = c0 + np.array([0.05, -0.04, 0.02])
    f.addObstacle("hand_ball", "sphere", 0.02, (0.0, 0.0, -0.1), frame="arm_right_7_joint")
    f.addObstacle("ball", "sphere", 0.01, ball)
    f.clearPairs()
    f.addPair("hand_ball", "ball")
    assert f.listPairs() == ["hand_ball : ball"]
    f.setDistances(0.0, 0.2)
    d = f.error.value
    expected = np.linalg.norm(c0 - ball) - 0.03
    np.testing.assert_allclose(d, [expected], atol=1e-9)
    J = f.jacobian.value
    eps = 1e-6
    for _ in range(3):
        v = RNG.normal(size=model.nv)
        fd = (
            np.linalg.norm(centre(pin.integrate(model, r.halfSitting, eps * v)) - ball)
            - np.linalg.norm(centre(pin.integrate(model, r.halfSitting, -eps * v)) - ball)
        ) / (2 * eps)
        np.testing.assert_allclose(J @ v, [fd], rtol=1e-6, atol=1e-8)


def test_rows_appear_and_disappear_with_the_influence_distance_in_an_sot():
    r = _robot()
    f = FeatureCollision("obs", r)
    f.clearPairs()
    w = r.dynamic.signal("right-wrist").value.translation
    far = w + np.array([0.0, -0.4, 0.0])
    f.addObstacle("ball", "sphere", 0.03, far)
    assert f.getPairCount() == r.collision_model.ngeoms
    task = TaskCollision("tcol")
    task.add(f)
    sot = SOT("sot", r.dynamic)
    sot.dt.value = 1e-3
    sot.push(task)
    # below it, a task asking the wrist for 0.3 m/s along its own y axis
    feat = FeatureGeneric("wy")
    plug(r.dynamic.signal("Jright-wrist"), feat.jacobianIN)
    feat.errorIN.value = np.array([0.0, 0.3, 0.0, 0.0, 0.0, 0.0])
    feat.selec.value = "010000"
    reach = Task("push_y")
    reach.add(feat)
    sot.push(reach)
    sizes = []
    for y in (-0.4, -0.12, -0.1, -0.4):
        f.setObstaclePlacement("ball", w + np.array([0.0, y, 0.0]))
        r.device.state.value  # noqa: B018
        m = task.jacobian.value.shape[0]
        sizes.append(m)
        lower = task.lower.value
        d = f.error.value
        np.testing.assert_allclose(lower, -0.5 * (d - 0.01) / (0.05 - 0.01))
        assert np.all(d < 0.05) and np.isinf(task.upper.value).all()
        v = sot.control.value
        # the damper holds for every row (the level is feasible)
        assert np.all(task.jacobian.value @ v >= lower - 1e-9)
        assert sot.lastResult.feasible
    assert sizes[0] == 0 and sizes[3] == 0
    assert sizes[1] == 1 and sizes[2] == 5
    # only pairs inside the broad phase reach coal
    f.setObstaclePlacement("ball", far)
    assert f.narrowPhaseCount.value == 0
    assert f.minDistance.value > 0.05


def test_bad_input_is_refused_and_changes_nothing():
    r = _robot()
    f = FeatureCollision("bad", r)
    task = TaskCollision("tbad")
    task.add(f)
    n, pairs = f.getPairCount(), f.listPairs()
    with pytest.raises(CommandError, match=r"FeatureCollision\(bad\).setDistances.*d_s >= 0"):
        f.setDistances(-0.01, 0.05)
    with pytest.raises(CommandError, match=r"d_i > d_s"):
        f.setDistances(0.05, 0.05)
    assert (f.safetyDistance.value, f.influenceDistance.value) == (0.01, 0.05)
    with pytest.raises(CommandError, match=r"TaskCollision\(tbad\).setGain.*xi > 0"):
        task.setGain(-1.0)
    assert task.controlGain.value == 0.5
    # a value written straight into the signal is refused when computed, by name
    f.safetyDistance.value = -1.0
    with pytest.raises(SignalTypeError, match=r"FeatureCollision\(bad\).*safetyDistance"):
        f.error.value  # noqa: B018
    f.safetyDistance.value = 0.01
    with pytest.raises(CommandError, match=r"no frame named 'nowhere'"):
        f.addObstacle("o", "sphere", 0.1, (1.0, 0.0, 1.0), frame="nowhere")
    with pytest.raises(CommandError, match=r"a sphere takes a radius"):
        f.addObstacle("o", "sphere", -0.1, (1.0, 0.0, 1.0))
    with pytest.raises(CommandError, match=r"unknown shape 'cone'"):
        f.addObstacle("o", "cone", 0.1, (1.0, 0.0, 1.0))
    with pytest.raises(CommandError, match=r"expected a placement"):
        f.addObstacle("o", "box", (0.1, 0.1, 0.1), (1.0, 0.0))
    with pytest.raises(CommandError, match=r"removePair: the pair .* is not checked"):
        f.removePair("arm_right_7_link_0", "gripper_right_base_link_0")
    with pytest.raises(CommandError, match=r"no geometry named 'elbow'"):
        f.removePair("elbow", "torso_2_link_0")
    with pytest.raises(CommandError, match=r"no obstacle named 'o'"):
        f.removeObstacle("o")
    assert f.getPairCount() == n and f.listPairs() == pairs and f.listObstacles() == []
    from sotpy.tasks import FeaturePosture

    with pytest.raises(CommandError, match=r"TaskCollision takes FeatureCollision"):
        task.add(FeaturePosture("post", r.model))
    assert task.list() == ["bad"]
    with pytest.raises(EntityError, match=r"FeatureCollision\(x\): expected a Robot"):
        FeatureCollision("x", 3)
    assert task.lower.value.shape == task.error.value.shape


def test_obstacles_add_and_remove_their_pairs():
    r = _robot()
    f = FeatureCollision("ob", r)
    n = f.getPairCount()
    f.addObstacle("table", "box", (0.8, 1.2, 0.05), (0.7, 0.0, 0.7))
    assert f.getPairCount() == n + r.collision_model.ngeoms
    f.addObstacle("tool", "capsule", (0.02, 0.1), np.eye(4), frame="arm_right_7_joint")
    attached = sum(
        g.parentJoint == r.model.getJointId("arm_right_7_joint")
        for g in r.collision_model.geometryObjects
    )
    assert f.getPairCount() == n + 2 * r.collision_model.ngeoms - attached
    f.removeObstacle("table")
    assert f.listObstacles() == ["tool"]
    assert f.getPairCount() == n + r.collision_model.ngeoms - attached
    assert all("table" not in p for p in f.listPairs())
    f.removeObstacle("tool")
    assert f.getPairCount() == n


def test_skipped_pairs_are_never_inside_the_influence_distance():
    # along a random walk of the configuration (steps of up to 0.05 rad per joint, some
    # big jumps), the rows are exactly the pairs an all-pairs computation finds under
    # d_i, although most pairs are not queried at most ticks
    r = _robot()
    model = r.model
    dyn = _dyn(r, r.halfSitting)
    f = FeatureCollision("walk", dyn, geometry=r.collision_model, srdf=robotSrdf(r))
    f.setDistances(0.0, 0.06)
    q = r.halfSitting.copy()
    queried = []
    for k in range(60):
        step = RNG.normal(size=model.nv) * (0.5 if k % 20 == 19 else 0.02)
        step[:6] *= 0.1
        q = pin.integrate(model, q, step)
        dyn.position.value = q
        rows = set(f.activePairs.value.astype(int).tolist())
        queried.append(f.narrowPhaseCount.value)
        exact = f.distances()
        assert rows == set(np.flatnonzero(exact < 0.06).tolist()), k
        np.testing.assert_allclose(np.sort(f.error.value), np.sort(exact[exact < 0.06]), atol=1e-7)
        assert f.minDistance.value <= exact.min() + 1e-7
        if exact.min() < 0.06:
            assert f.minDistance.value == pytest.approx(exact.min(), abs=1e-7)
    assert np.median(queried) < f.getPairCount() / 10


def test_compiled_pass_and_placement_view_match_the_numpy_path(monkeypatch):
    # the tick's fast path (the read-only views on data.oMi and on coal's results, the
    # compiled broad phase and Jacobian rows) against the NumPy twins on copies of
    # data.oMi and coal's accessors, along a random walk
    # with big jumps: the same rows, distances, witness points and normals bit for bit,
    # the same Jacobian to rounding, the same pairs through the narrow phase
    from sotpy import _jit
    from sotpy.tasks import _collisionkernels as kernels
    from sotpy.tasks import collision

    r = _robot()
    model, srdf = r.model, robotSrdf(r)
    fast = collision.CollisionPairs(model, r.collision_model, srdf)
    with monkeypatch.context() as m:  # coal's results through their accessors
        m.setattr(collision, "_resultsView", lambda results: None)
        ref = collision.CollisionPairs(model, r.collision_model, srdf)
    assert ref._resView is None
    fast_data, ref_data = model.createData(), model.createData()
    q = r.halfSitting.copy()
    for k in range(80):
        step = RNG.normal(size=model.nv) * (0.5 if k % 20 == 19 else 0.02)
        step[:6] *= 0.1
        q = pin.integrate(model, q, step)
        for d in (fast_data, ref_data):
            pin.computeJointJacobians(model, d, q)
        fast.compute(fast_data, 0.06)
        with monkeypatch.context() as m:
            m.setattr(kernels, "broad_phase", None)
            m.setattr(kernels, "narrow_rows", None)
            m.setattr(collision, "_oMiView", lambda data: None)
            ref.compute(ref_data, 0.06)
        assert np.array_equal(fast.rowPairs, ref.rowPairs), k
        assert np.array_equal(fast.rowD, ref.rowD)
        for a in ("rowNormal", "rowPointA", "rowPointB", "rowJointA", "rowJointB"):
            assert np.array_equal(getattr(fast, a), getattr(ref, a)), a
        np.testing.assert_allclose(fast.rowJ, ref.rowJ, rtol=0, atol=1e-14)
        np.testing.assert_allclose(fast._lower, ref._lower, rtol=0, atol=1e-12)
        assert fast.minDistance == pytest.approx(ref.minDistance, abs=1e-12)
    assert fast._resView is not None and fast._resChecked
    assert fast._view is not None and fast._view[1] is not None
    if _jit.ENABLED:  # the kernels took every call (none refused its types)
        assert kernels.broad_phase is not None and kernels.narrow_rows is not None
