"""Task rows written straight into a solver's buffer (``sotpy.tasks.rows`` and the
kernel of ``sotpy.tasks._rowkernels``): the compiled ``log3``/``Jlog3`` against
Pinocchio, an independent series and finite differences; every feature's row
operation against the feature's own ``jacobian`` and ``error`` signals on random
inputs; the task's operations against ``task.jacobian`` and ``task.task`` (or
``lower``/``upper``); when a program refuses a tick (``REFUSED``) or an operation is
not made (``None``); ``NO_ROOM``; a program cut into several kernel calls.

A program is run as the SOT runs it: ``RowProgram(ops).run(values, A, lo, up, ends,
fixed, offset)`` with ``values[offset:]`` the values of the operations' sources; rows
go to ``A``, ``lo`` and ``up`` from row 0. A feature's operation alone leaves its
error ``e`` in ``lo``; a task's operation turns it into ``-gain e``. The buffers are
filled with NaN first, so a write outside those rows shows.
"""

from __future__ import annotations

import math

import numpy as np
import pinocchio as pin
import pytest

from sotpy.errors import SignalTypeError, SotpyError
from sotpy.graph import MATRIX, Entity, Output, plug
from sotpy.tasks import (
    FeatureGeneric,
    FeaturePose,
    FeaturePoseSE3,
    FeaturePosture,
    FeatureVisualPoint,
    Flags,
    Task,
    TaskInequality,
)
from sotpy.tasks import _rowkernels as rk
from sotpy.tasks.rows import _KINDS, RowOp, RowProgram

pytestmark = pytest.mark.skipif(rk.write_rows is None, reason="the row kernel needs numba")

NV = 7
JUNK = ("junk", None)  # values before the writer's own: the offset must skip them


@pytest.fixture(scope="module", autouse=True)
def _warm_kernels():
    """Compile the kernels for the types a tick passes and freeze them, as an SOT does:
    a type the writers were not meant for then raises instead of compiling quietly."""
    rk.warm_up()


# -- independent references -----------------------------------------------------------
def skew(w: np.ndarray) -> np.ndarray:
    return np.array([[0.0, -w[2], w[1]], [w[2], 0.0, -w[0]], [-w[1], w[0], 0.0]])


def jlog3_reference(w: np.ndarray) -> np.ndarray:
    """Jlog3 at the rotation ``exp3(w)`` as the inverse of the right Jacobian of SO(3),
    ``Jr(w) = I - a [w] + b [w]^2`` with ``a = (1 - cos t) / t^2``, ``b = (t - sin t) /
    t^3`` (their Taylor series below ``t = 1e-2``, where the closed forms cancel)."""
    t = float(np.linalg.norm(w))
    if t < 1e-2:
        t2 = t * t
        a = 0.5 - t2 / 24.0 + t2 * t2 / 720.0
        b = 1.0 / 6.0 - t2 / 120.0 + t2 * t2 / 5040.0
    else:
        a = (1.0 - math.cos(t)) / t**2
        b = (t - math.sin(t)) / t**3
    W = skew(w)
    return np.linalg.inv(np.eye(3) - a * W + b * W @ W)


def unit(rng: np.random.Generator) -> np.ndarray:
    u = rng.standard_normal(3)
    return u / np.linalg.norm(u)


def random_rotation(rng: np.random.Generator) -> np.ndarray:
    q = rng.standard_normal(4)
    q /= np.linalg.norm(q)
    return pin.Quaternion(q[3], q[0], q[1], q[2]).matrix()


# -- log3 and Jlog3 -------------------------------------------------------------------
def test_log3_and_jlog3_match_pinocchio_on_random_rotations():
    rng = np.random.default_rng(20240611)
    for _ in range(300):
        R = random_rotation(rng)
        np.testing.assert_allclose(rk.log3(R), pin.log3(R), rtol=0, atol=1e-10)
        np.testing.assert_allclose(rk.jlog3(R), pin.Jlog3(R), rtol=0, atol=1e-10)
        # and exp3 undoes it
        np.testing.assert_allclose(pin.exp3(rk.log3(R)), R, rtol=0, atol=1e-12)


def test_log3_accepts_pinocchio_column_major_rotations():
    # pin.SE3's rotation is a Fortran-ordered array: log3 must read it, not its transpose
    M = pin.SE3(pin.exp3(np.array([0.3, -0.2, 0.9])), np.zeros(3))
    assert M.rotation.flags.f_contiguous
    np.testing.assert_allclose(rk.log3(M.rotation), [0.3, -0.2, 0.9], rtol=0, atol=1e-14)


@pytest.mark.parametrize("theta", np.geomspace(1e-9, 1e-3, 13))
def test_log3_and_jlog3_at_tiny_angles(theta):
    rng = np.random.default_rng(int(-math.log10(theta) * 100))
    u = unit(rng)
    R = pin.exp3(theta * u)
    w = rk.log3(R)
    # relative to theta: the skew part carries the angle without cancellation
    assert np.abs(w - theta * u).max() <= 1e-12 * theta
    assert np.abs(w - pin.log3(R)).max() <= 1e-12 * theta
    J = rk.jlog3(R)
    np.testing.assert_allclose(J, jlog3_reference(theta * u), rtol=0, atol=1e-14)
    # Pinocchio's Jlog3 above its Taylor threshold loses ~1e-10 to 1 - cos(theta)
    # (measured 5e-10 at theta = 3e-4): compared more loosely
    np.testing.assert_allclose(J, pin.Jlog3(R), rtol=0, atol=1e-8)


@pytest.mark.parametrize("gap", np.geomspace(1e-7, 1e-2, 11))
def test_log3_and_jlog3_near_pi(gap):
    rng = np.random.default_rng(int(-math.log10(gap) * 100) + 7)
    for _ in range(5):
        u = unit(rng)
        theta = math.pi - gap
        R = pin.exp3(theta * u)
        w = rk.log3(R)
        np.testing.assert_allclose(w, theta * u, rtol=0, atol=1e-9)  # the sign too
        np.testing.assert_allclose(w, pin.log3(R), rtol=0, atol=1e-7)
        J = rk.jlog3(R)
        np.testing.assert_allclose(J, pin.Jlog3(R), rtol=0, atol=1e-7)
        np.testing.assert_allclose(J, jlog3_reference(theta * u), rtol=0, atol=1e-9)


def test_log3_at_exactly_pi_is_an_axis_of_angle_pi():
    rng = np.random.default_rng(5)
    for _ in range(10):
        u = unit(rng)
        R = pin.exp3(math.pi * u)
        w = rk.log3(R)
        assert np.isfinite(w).all()
        assert np.linalg.norm(w) == pytest.approx(math.pi, abs=1e-9)
        # +u and -u are the same rotation at pi
        assert min(np.abs(w - math.pi * u).max(), np.abs(w + math.pi * u).max()) < 1e-7
        np.testing.assert_allclose(pin.exp3(w), R, rtol=0, atol=1e-12)
        assert np.isfinite(rk.jlog3(R)).all()


# the branch switches of the kernels: the Taylor series of log3 (1e-4) and of Jlog3
# (1e-2), and the axis from the symmetric part (cos theta < -0.9)
SWITCHES = [1e-4, 1e-2, math.acos(-0.9)]


@pytest.mark.parametrize("theta", [s * f for s in SWITCHES for f in (1 - 1e-9, 1 + 1e-9)])
def test_log3_and_jlog3_on_both_sides_of_each_branch_switch(theta):
    rng = np.random.default_rng(11)
    for _ in range(5):
        u = unit(rng)
        R = pin.exp3(theta * u)
        np.testing.assert_allclose(rk.log3(R), theta * u, rtol=0, atol=1e-15 + 1e-13 * theta)
        np.testing.assert_allclose(rk.jlog3(R), jlog3_reference(theta * u), rtol=0, atol=1e-13)


def test_jlog3_is_the_derivative_of_log3_along_a_right_perturbation():
    # d log3(R exp3(d)) / dd at d = 0, by central differences
    rng = np.random.default_rng(3)
    eps = 1e-6
    for theta in (1e-3, 0.1, 1.0, 2.0, 2.8, 3.1):
        u = unit(rng)
        R = pin.exp3(theta * u)
        fd = np.empty((3, 3))
        for i in range(3):
            d = np.zeros(3)
            d[i] = eps
            fd[:, i] = (rk.log3(R @ pin.exp3(d)) - rk.log3(R @ pin.exp3(-d))) / (2 * eps)
        np.testing.assert_allclose(rk.jlog3(R), fd, rtol=0, atol=1e-7)


# -- feature operations ---------------------------------------------------------------


def values_of(ops: RowOp | list[RowOp]) -> tuple:
    ops = ops if isinstance(ops, list) else [ops]
    return tuple(s.value for op in ops for s in op.sources)


def made_by(op: RowOp) -> str:
    """The kernel's operation: ``"POSE"``, ``"GENERIC"``, ``"POSTURE"`` (a formula of
    the kernel) or ``"ROWS"`` (the feature's own callbacks)."""
    return _KINDS[op.kind]


def run_ops(ops, nv: int, rows: int = 40, values=None, levels: int = 1):
    """Run ``ops`` (an operation or a list) into NaN buffers of ``rows x nv``, their
    values after two junk ones (the offset must skip them); ``(r, A, lo, up, ends)``."""
    ops = ops if isinstance(ops, list) else [ops]
    A, lo, up = np.full((rows, nv), np.nan), np.full(rows, np.nan), np.full(rows, np.nan)
    ends = np.full(levels, -7, dtype=np.int64)
    v = values if values is not None else values_of(ops)
    r = RowProgram(ops).run((*JUNK, *v), A, lo, up, ends, False, len(JUNK))
    return r, A, lo, up, ends


def check_writer(feature, nv: int = NV, extra: int = 2) -> int:
    """Run the feature's operation: its rows must equal its signals (``J`` in ``A``,
    ``e`` in ``lo``), and nothing else may be written."""
    op = feature._rowOp()
    assert op is not None
    J = feature.jacobian.value
    e = feature.error.value
    m = feature.dim.value
    assert J.shape == (m, nv) and e.shape == (m,)
    k, A, lo, up, _ = run_ops(op, nv, rows=m + extra)
    assert k == m
    np.testing.assert_allclose(A[:k], J, rtol=0, atol=1e-12)
    np.testing.assert_allclose(lo[:k], e, rtol=0, atol=1e-12)
    assert np.isnan(A[k:]).all() and np.isnan(lo[k:]).all() and np.isnan(up).all()
    return k


def pose_feature(cls, name: str, rng: np.random.Generator, selec, Mdes=None):
    f = cls(name)
    M = pin.SE3(random_rotation(rng), rng.standard_normal(3))
    f.position.value = M
    f.reference.value = (
        Mdes if Mdes is not None else pin.SE3(random_rotation(rng), rng.standard_normal(3))
    )
    f.Jq.value = rng.standard_normal((6, NV))
    f.selec.value = selec
    return f


POSE_SELECTIONS = ["111111", "111000", "000111", "101010", "000011", "010000"]


@pytest.mark.parametrize("selec", POSE_SELECTIONS)
@pytest.mark.parametrize("seed", range(3))
def test_feature_pose_operation_gives_its_jacobian_and_error(selec, seed):
    rng = np.random.default_rng(seed)
    f = pose_feature(FeaturePose, "fpose", rng, selec)
    assert made_by(f._rowOp()) == "POSE"
    k = check_writer(f)
    assert k == selec.count("1")
    # the error, independently: (R*^T (p - p*), log3(R*^T R)) on the selected rows
    M, Md = f.position.value, f.reference.value
    full = np.concatenate(
        (Md.rotation.T @ (M.translation - Md.translation), pin.log3(Md.rotation.T @ M.rotation))
    )
    rows = [i for i, c in enumerate(selec) if c == "1"]
    np.testing.assert_allclose(f.error.value, full[rows], rtol=0, atol=1e-12)


@pytest.mark.parametrize("theta", [0.0, 1e-8, 1e-3, math.pi - 1e-6, math.pi - 1e-3])
def test_feature_pose_operation_at_small_and_near_pi_relative_rotations(theta):
    rng = np.random.default_rng(42)
    Mdes = pin.SE3(random_rotation(rng), rng.standard_normal(3))
    f = pose_feature(FeaturePose, "fpose", rng, "111111", Mdes=Mdes)
    rel = pin.SE3(pin.exp3(theta * unit(rng)), 0.1 * rng.standard_normal(3))
    f.position.value = Mdes * rel
    # Pinocchio's Jlog3 near zero carries its own ~1e-10 (see the tiny-angle test)
    r, A, lo, _, _ = run_ops(f._rowOp(), NV, rows=6)
    assert r == 6
    np.testing.assert_allclose(A, f.jacobian.value, rtol=0, atol=1e-8)
    np.testing.assert_allclose(lo, f.error.value, rtol=0, atol=1e-9)


def test_feature_pose_operation_reads_the_sources_of_its_jacobian():
    class ConstJacobian(Entity):
        @Output(MATRIX, timeDependent=False)
        def out(self):
            return self.J

    rng = np.random.default_rng(0)
    f = pose_feature(FeaturePose, "fpose", rng, "110011")
    src = ConstJacobian("src")
    src.J = rng.standard_normal((6, NV))
    plug(src.out, f.Jq)
    op = f._rowOp()
    # the holders: a plugged input is replaced by the output it follows
    assert op.sources == (f.selec, f.position, f.reference, src.out)
    check_writer(f)
    # the operation reads the values it is given, not the signals: another Jacobian
    values = list(values_of(op))
    values[3] = 2.0 * values[3]
    r, A, _, _, _ = run_ops(op, NV, rows=4, values=values)
    assert r == 4
    np.testing.assert_allclose(A, 2.0 * f.jacobian.value, rtol=0, atol=1e-12)


@pytest.mark.parametrize("selec", POSE_SELECTIONS)
def test_feature_pose_se3_uses_its_callbacks(selec):
    rng = np.random.default_rng(9)
    f = pose_feature(FeaturePoseSE3, "fse3", rng, selec)
    op = f._rowOp()
    assert made_by(op) == "ROWS"
    # the callbacks' operation: the error's then the jacobian's sources
    assert op.sources == (*f.error.dependencies, *f.jacobian.dependencies)
    check_writer(f)


@pytest.mark.parametrize("selec", [True, "10110", "00001", "11111", "0"])
@pytest.mark.parametrize("reference", [False, True])
def test_feature_generic_operation_gives_its_jacobian_and_error(selec, reference):
    rng = np.random.default_rng(17)
    m = 5
    f = FeatureGeneric("fgen")
    f.errorIN.value = rng.standard_normal(m)
    f.jacobianIN.value = rng.standard_normal((m, NV))
    f.selec.value = selec
    if reference:
        ref = FeatureGeneric("fgenDes")
        ref.errorIN.value = rng.standard_normal(m)
        f.setReference(ref)
    op = f._rowOp()
    assert made_by(op) == "GENERIC"
    assert len(op) == (3 if reference else 2) + 2
    k = check_writer(f)
    assert k == Flags(selec).count(m)
    if reference:  # the difference, independently
        e = f.errorIN.value - ref.errorIN.value
        rows = Flags(selec).rows(m)
        np.testing.assert_allclose(f.error.value, e if rows is None else e[rows], atol=0)


def test_feature_generic_operation_refuses_what_its_callbacks_refuse():
    rng = np.random.default_rng(1)
    f = FeatureGeneric("fgen")
    f.errorIN.value = rng.standard_normal(3)
    f.jacobianIN.value = rng.standard_normal((3, NV))
    ref = FeatureGeneric("fgenDes")
    ref.errorIN.value = rng.standard_normal(2)  # wrong size
    f.setReference(ref)
    op = f._rowOp()
    r, A, lo, _, _ = run_ops(op, NV, rows=6)
    assert r == rk.REFUSED
    assert np.isnan(A).all() and np.isnan(lo).all()  # nothing written when refusing
    with pytest.raises(SignalTypeError, match="fgenDes"):
        f.error.value  # noqa: B018
    ref.errorIN.value = rng.standard_normal(3)
    assert run_ops(op, NV, rows=6)[0] == 3
    # a Jacobian of another width than the buffer, or of other rows than the error
    assert run_ops(op, NV + 1, rows=6)[0] == rk.REFUSED
    f.jacobianIN.value = rng.standard_normal((4, NV))
    assert run_ops(op, NV, rows=6)[0] == rk.REFUSED


def test_callback_operation_calls_the_callback_in_force():
    rng = np.random.default_rng(2)
    f = FeatureGeneric("fgen")
    f.errorIN.value = rng.standard_normal(3)
    f.jacobianIN.value = rng.standard_normal((3, NV))
    f.error.setFunction(lambda selec, s: 2.0 * s + 1.0)
    # not the kernel's: the error is no longer FeatureGeneric's
    assert made_by(f._rowOp()) == "ROWS"
    check_writer(f)
    np.testing.assert_allclose(f.error.value, 2.0 * f.errorIN.value + 1.0)


def test_feature_visual_point_uses_its_callbacks():
    rng = np.random.default_rng(4)
    f = FeatureVisualPoint("fvp")
    f.xy.value = [0.1, -0.2]
    f.Z.value = 1.5
    f.Jq.value = rng.standard_normal((6, NV))
    f.xyRef.value = [0.05, 0.0]
    for selec in (True, "01"):
        f.selec.value = selec
        assert made_by(f._rowOp()) == "ROWS"
        check_writer(f)


# -- FeaturePosture -------------------------------------------------------------------
@pytest.fixture(scope="module")
def humanoid():
    """Pinocchio's sample humanoid: a free flyer and 28 revolute joints (nv = 34)."""
    return pin.buildSampleModelHumanoid()


@pytest.fixture(scope="module")
def continuous():
    """A revolute, a continuous (unbounded: (cos, sin), nq = 2, nv = 1) and a prismatic
    joint: nq = 4, nv = 3."""
    model = pin.Model()
    j = model.addJoint(0, pin.JointModelRX(), pin.SE3.Identity(), "rx")
    j = model.addJoint(j, pin.JointModelRUBZ(), pin.SE3(np.eye(3), np.array([0, 0, 0.3])), "c")
    model.addJoint(j, pin.JointModelPY(), pin.SE3(np.eye(3), np.array([0.2, 0, 0])), "py")
    assert (model.nq, model.nv) == (4, 3)
    return model


def posture_feature(model, rng, name="fposture"):
    f = FeaturePosture(name, model)
    q0 = pin.neutral(model)
    f.state.value = pin.integrate(model, q0, rng.standard_normal(model.nv))
    f.posture.value = pin.integrate(model, q0, rng.standard_normal(model.nv))
    return f


def test_feature_posture_operation_default_selection_uses_the_kernel(humanoid):
    rng = np.random.default_rng(8)
    f = posture_feature(humanoid, rng)
    assert made_by(f._rowOp()) == "POSTURE"
    assert f._postureIndex(f.selec.value) is not None  # one-DoF joints only: the kernel
    k = check_writer(f, nv=humanoid.nv)
    assert k == humanoid.nv - 6  # the free flyer excluded
    # the rows of the identity at the joints' DoFs
    J = f.jacobian.value
    np.testing.assert_array_equal(J, np.eye(humanoid.nv)[6:])


@pytest.mark.parametrize(
    "dofs, kernel",
    [([7, 10, 33], True), ([6], True), ([0, 4, 12], False), ([3, 4, 5], False)],
)
def test_feature_posture_operation_with_a_few_dofs(humanoid, dofs, kernel):
    rng = np.random.default_rng(len(dofs) + dofs[0])
    f = posture_feature(humanoid, rng)
    f.selec.value = Flags([i in dofs for i in range(humanoid.nv)])
    # a free flyer's DoF: Pinocchio's dDifference block through the callbacks
    assert (f._postureIndex(f.selec.value) is not None) == kernel
    assert check_writer(f, nv=humanoid.nv) == len(dofs)


@pytest.mark.parametrize("selec, kernel", [(True, False), ("101", True), ("010", False)])
def test_feature_posture_operation_with_a_continuous_joint(continuous, selec, kernel):
    rng = np.random.default_rng(21)
    f = posture_feature(continuous, rng)
    f.selec.value = selec
    assert (f._postureIndex(f.selec.value) is not None) == kernel
    k = check_writer(f, nv=continuous.nv)
    assert k == Flags(selec).count(3)
    # the continuous joint's error: the angle between the two, in (-pi, pi]
    if selec is True:
        q, qd = f.state.value, f.posture.value
        angle = math.atan2(q[2], q[1]) - math.atan2(qd[2], qd[1])
        angle = math.remainder(angle, 2 * math.pi)
        assert f.error.value[1] == pytest.approx(angle, abs=1e-12)


def test_feature_posture_operation_raises_the_callbacks_errors(humanoid):
    rng = np.random.default_rng(0)
    f = posture_feature(humanoid, rng)
    op = f._rowOp()

    def same_error(nv: int) -> str:
        """The program's error and the error signal's, word for word."""
        with pytest.raises(SignalTypeError) as fused:
            run_ops(op, nv)
        with pytest.raises(SignalTypeError) as plain:
            f.error.value  # noqa: B018
        assert str(fused.value) == str(plain.value)
        return str(fused.value)

    f.posture.value = np.zeros(5)
    assert "fposture" in same_error(humanoid.nv)
    f.posture.value = pin.neutral(humanoid)
    assert run_ops(op, humanoid.nv)[0] == humanoid.nv - 6
    # a state whose quaternion is not normalised: the callbacks' error, word for word
    q = f.state.value.copy()
    good = q.copy()
    q[3:7] *= 1.01
    f.state.value = q
    assert "not normalised" in same_error(humanoid.nv)
    f.state.value = good
    assert run_ops(op, humanoid.nv)[0] == humanoid.nv - 6
    # a buffer of another width: the callbacks' rows, which do not fit it
    assert run_ops(op, 3)[0] == rk.REFUSED


# -- operations not made --------------------------------------------------------------
def test_no_operation_for_outputs_not_computed_by_a_callback_every_tick():
    rng = np.random.default_rng(6)
    f = pose_feature(FeaturePose, "fpose", rng, "111111")
    assert f._rowOp() is not None
    f.jacobian.setPeriod(2)
    assert f._rowOp() is None
    f.jacobian.setPeriod(1)
    assert f._rowOp() is not None
    f.error.value = np.zeros(6)  # a constant
    assert f._rowOp() is None
    f.error.resetCallback()
    assert f._rowOp() is not None


# -- Task -----------------------------------------------------------------------------
def three_feature_task(humanoid, rng, name="task"):
    """A Task with a pose ("101100"), a generic (with reference, "101") and a posture
    (three joints) feature on the humanoid's nv."""
    nv = humanoid.nv
    fp = FeaturePose(name + "_pose")
    fp.position.value = pin.SE3(random_rotation(rng), rng.standard_normal(3))
    fp.reference.value = pin.SE3(random_rotation(rng), rng.standard_normal(3))
    fp.Jq.value = rng.standard_normal((6, nv))
    fp.selec.value = "101100"
    fg = FeatureGeneric(name + "_gen")
    fg.errorIN.value = rng.standard_normal(3)
    fg.jacobianIN.value = rng.standard_normal((3, nv))
    fd = FeatureGeneric(name + "_genDes")
    fd.errorIN.value = rng.standard_normal(3)
    fg.setReference(fd)
    fg.selec.value = "101"
    fq = posture_feature(humanoid, rng, name + "_posture")
    fq.selec.value = Flags([i in (8, 9, 20) for i in range(nv)])
    t = Task(name)
    for f in (fp, fg, fq):
        t.add(f)
    t.controlGain.value = 4.0
    return t, (fp, fg, fq)


def write_task(t, nv, rows=14, values=None):
    """Run the task's operations (its features', then its own) into NaN buffers."""
    ops = t._rowOps()
    assert ops is not None
    r, A, lo, up, ends = run_ops(ops, nv, rows=rows, values=values)
    if r >= 0:
        assert ends[0] == r  # the task closes its level
    return r, A, lo, up


def test_task_operations_give_the_task_jacobian_and_target(humanoid):
    rng = np.random.default_rng(30)
    t, features = three_feature_task(humanoid, rng)
    m = sum(f.dim.value for f in features)
    assert m == 3 + 2 + 3
    k, A, lo, up = write_task(t, humanoid.nv)
    assert k == m
    np.testing.assert_allclose(A[:k], t.jacobian.value, rtol=0, atol=1e-12)
    np.testing.assert_allclose(lo[:k], t.task.value, rtol=0, atol=1e-12)
    np.testing.assert_allclose(lo[:k], -4.0 * t.error.value, rtol=0, atol=1e-12)
    np.testing.assert_array_equal(up[:k], lo[:k])  # an equality: both bounds
    assert np.isnan(A[k:]).all() and np.isnan(lo[k:]).all() and np.isnan(up[k:]).all()
    # the operations: each feature's, then the task's own on controlSelec, controlGain
    ops = t._rowOps()
    assert [made_by(op) for op in ops] == ["POSE", "GENERIC", "POSTURE", "EQUALITY"]
    assert ops[-1].sources == (t.controlSelec, t.controlGain)
    # a level end array too short for the program: refused (not "no room": no buffer
    # would do)
    assert run_ops(ops, humanoid.nv, levels=0)[0] == rk.REFUSED


def test_task_operations_zero_the_unselected_columns(humanoid):
    rng = np.random.default_rng(31)
    t, _ = three_feature_task(humanoid, rng)
    nv = humanoid.nv
    cols = [i % 3 != 0 for i in range(nv)]
    t.controlSelec.value = cols
    k, A, lo, _ = write_task(t, nv)
    J = t.jacobian.value
    assert not J[:, ~np.array(cols)].any()
    np.testing.assert_allclose(A[:k], J, rtol=0, atol=1e-12)
    np.testing.assert_allclose(lo[:k], t.task.value, rtol=0, atol=1e-12)
    assert not A[:k, ~np.array(cols)].any()


def test_task_operations_are_not_made_when_the_task_signals_must_be_read(humanoid):
    rng = np.random.default_rng(32)
    t, (_, fg, _) = three_feature_task(humanoid, rng)
    assert t._rowOps() is not None
    t.setWithDerivative(True)  # the feed-forward reads errordot
    assert t._rowOps() is None
    t.setWithDerivative(False)
    assert t._rowOps() is not None
    t.task.value = np.zeros(8)  # the target set to a constant
    assert t._rowOps() is None
    t.task.resetCallback()
    assert t._rowOps() is not None
    fg.jacobian.setPeriod(2)  # a feature computed every other tick
    assert t._rowOps() is None
    fg.jacobian.setPeriod(1)
    assert t._rowOps() is not None
    t.jacobian.setPeriod(3)
    assert t._rowOps() is None
    t.jacobian.setPeriod(1)
    t.error.setFunction(lambda *errors: np.concatenate(errors))  # another callback
    assert t._rowOps() is None
    assert Task("empty")._rowOps() is None


@pytest.mark.parametrize("gain", [-1.0, math.nan, math.inf])
def test_task_operations_refuse_a_gain_out_of_range(humanoid, gain):
    rng = np.random.default_rng(33)
    t, _ = three_feature_task(humanoid, rng)
    values = list(values_of(t._rowOps()))
    values[-1] = gain  # controlGain's value (a NaN constant is refused by the signal)
    assert write_task(t, humanoid.nv, values=values)[0] == rk.REFUSED
    if gain == -1.0:  # the task signal says what is wrong
        t.controlGain.value = gain
        with pytest.raises(SignalTypeError, match="controlGain: expected a finite gain >= 0"):
            t.task.value  # noqa: B018
        t.controlGain.value = 4.0
        assert write_task(t, humanoid.nv)[0] == 8


def test_task_operations_refuse_a_jacobian_of_the_wrong_width(humanoid):
    rng = np.random.default_rng(34)
    t, (_, fg, _) = three_feature_task(humanoid, rng)
    # a buffer of another width than the features' Jacobians
    assert write_task(t, humanoid.nv + 1)[0] == rk.REFUSED
    # one feature's Jacobian of another width (the others fit the buffer)
    fg.jacobianIN.value = rng.standard_normal((3, humanoid.nv - 1))
    assert write_task(t, humanoid.nv)[0] == rk.REFUSED
    # a column selection longer than the Jacobian
    fg.jacobianIN.value = rng.standard_normal((3, humanoid.nv))
    assert write_task(t, humanoid.nv)[0] == 8
    t.controlSelec.value = Flags([False] * (humanoid.nv + 2) + [True])
    assert write_task(t, humanoid.nv)[0] == rk.REFUSED


def test_task_operations_refuse_rows_that_are_not_finite(humanoid):
    """A non-finite Jacobian entry or error (a feature's input): refused, and the task
    signals name it."""
    rng = np.random.default_rng(35)
    t, (_, fg, _) = three_feature_task(humanoid, rng)
    J = rng.standard_normal((3, humanoid.nv))
    J[0, 4] = np.inf  # a selected row
    fg.jacobianIN.value = J
    assert write_task(t, humanoid.nv)[0] == rk.REFUSED
    with pytest.raises(SotpyError):
        t.jacobian.value  # noqa: B018
    fg.jacobianIN.value = rng.standard_normal((3, humanoid.nv))
    assert write_task(t, humanoid.nv)[0] == 8
    t.controlGain.value = 1e300  # a finite gain whose target overflows
    fg.errorIN.value = np.full(3, 1e10)
    assert write_task(t, humanoid.nv)[0] == rk.REFUSED
    with np.errstate(over="ignore"), pytest.raises(SotpyError, match="not finite"):
        t.task.value  # noqa: B018


# -- NO_ROOM --------------------------------------------------------------------------
def _writers(humanoid, continuous, rng):
    pose = pose_feature(FeaturePose, "bf_pose", rng, "111011")
    se3 = pose_feature(FeaturePoseSE3, "bf_se3", rng, "111111")
    gen = FeatureGeneric("bf_gen")
    gen.errorIN.value = rng.standard_normal(4)
    gen.jacobianIN.value = rng.standard_normal((4, NV))
    post = posture_feature(humanoid, rng, "bf_posture")  # the kernel
    cont = posture_feature(continuous, rng, "bf_cont")  # the callbacks
    task, _ = three_feature_task(humanoid, rng, "bf_task")
    return [
        (pose._rowOp(), NV, 5),
        (se3._rowOp(), NV, 6),
        (gen._rowOp(), NV, 4),
        (post._rowOp(), humanoid.nv, humanoid.nv - 6),
        (cont._rowOp(), continuous.nv, 3),
        (task._rowOps(), humanoid.nv, 8),
    ]


def test_programs_answer_no_room_when_the_rows_do_not_fit(humanoid, continuous):
    rng = np.random.default_rng(40)
    for ops, nv, k in _writers(humanoid, continuous, rng):
        for rows in (k - 1, 0):  # one row short; none at all
            assert run_ops(ops, nv, rows=rows)[0] == rk.NO_ROOM
        r, A, _, _, _ = run_ops(ops, nv, rows=k)  # exactly enough
        assert r == k
        assert np.isfinite(A).all()


def test_a_long_program_is_cut_into_calls_with_the_same_rows(humanoid):
    """Eight tasks of three features: more arrays than one kernel call takes, so the
    program makes several calls; the rows are those of each task's signals."""
    rng = np.random.default_rng(41)
    tasks = [three_feature_task(humanoid, rng, f"long{i}")[0] for i in range(8)]
    ops = [op for t in tasks for op in t._rowOps()]
    program = RowProgram(ops)
    assert len(program._calls) > 2
    assert program.levels == 8
    r, A, lo, up, ends = run_ops(ops, humanoid.nv, rows=70, levels=8)
    assert r == 64
    np.testing.assert_array_equal(ends, np.arange(8, 65, 8))
    for i, t in enumerate(tasks):
        rows = slice(8 * i, 8 * i + 8)
        np.testing.assert_allclose(A[rows], t.jacobian.value, rtol=0, atol=1e-12)
        np.testing.assert_allclose(lo[rows], t.task.value, rtol=0, atol=1e-12)
        np.testing.assert_array_equal(up[rows], lo[rows])


# -- the inequality task's bounds ------------------------------------------------------
def _references(rng: np.random.Generator, m: int, case: str) -> tuple[np.ndarray, np.ndarray]:
    """(referenceInf, referenceSup) for ``case``: both, one side only, infinite entries,
    or one of the inputs the task's callback refuses."""
    lo = rng.uniform(-1.0, 0.5, m)
    up = lo + rng.uniform(0.0, 1.0, m)
    if case == "lower only":
        up = np.zeros(0)
    elif case == "upper only":
        lo = np.zeros(0)
    elif case == "infinite entries":
        lo[::3], up[1::3] = -np.inf, np.inf
    elif case == "lower above upper":
        lo[m // 2] = up[m // 2] + 0.1
    elif case == "lower +inf":
        lo[1] = np.inf
    elif case == "upper -inf":
        up[2] = -np.inf
    elif case == "wrong size":
        up = up[:-1]
    elif case == "overflow":  # finite, but (k / dt) * 1e306 is not
        lo[0] = 1e306
    return lo, up


@pytest.mark.parametrize(
    "case",
    ["both", "lower only", "upper only", "infinite entries", "lower above upper",
     "lower +inf", "upper -inf", "wrong size", "overflow"],
)  # fmt: skip
def test_inequality_operation_matches_the_task_callback(case):
    """TaskInequality's operations against the task's own ``lower``/``upper``
    callback: the same bounds where the callback accepts the references (to rounding:
    the kernel adds ``c ref`` to ``-c e``, the callback computes ``c (ref - e)``),
    ``REFUSED`` where it raises."""
    rng = np.random.default_rng(sum(map(ord, case)))  # a seed per case, the same every run
    name = "ineq_" + case.replace(" ", "_")
    m, k, dt = 7, 0.7, 1e-3
    e = rng.standard_normal(m)
    f = FeatureGeneric(name + "_f")
    f.errorIN.value = e
    f.jacobianIN.value = rng.standard_normal((m, NV))
    task = TaskInequality(name)
    task.add(f)
    task.controlGain.value = k
    task.dt.value = dt
    rinf, rsup = _references(rng, m, case)
    ops = task._rowOps()
    assert [made_by(op) for op in ops] == ["GENERIC", "INEQUALITY"]
    values = list(values_of(ops))
    o = len(ops[0])  # the INEQUALITY's sources: selection, references, gain, dt
    values[o + 1], values[o + 2] = rinf, rsup
    got, A, lo, up, _ = run_ops(ops, NV, rows=m + 3, values=values)
    try:
        with np.errstate(over="ignore"):  # the overflow case: the callback refuses it
            want = task._bounds(rinf, rsup, k, dt, e)
    except SotpyError:
        want = None
    if want is None:
        assert got == rk.REFUSED
        return
    assert got == m
    assert np.isnan(lo[m:]).all() and np.isnan(up[m:]).all()  # only its rows
    np.testing.assert_array_equal(A[:m], f.jacobian.value)
    for got_bound, want_bound in ((lo[:m], want[0]), (up[:m], want[1])):
        np.testing.assert_array_equal(np.isfinite(got_bound), np.isfinite(want_bound))
        np.testing.assert_allclose(got_bound, want_bound, rtol=1e-13, atol=0.0)


def test_inequality_operation_accepts_strided_references():
    """A reference handed out as a strided view (a user's entity slicing a vector): the
    program gives the bounds the task's callback gives, with no fallback."""
    from sotpy.graph import VECTOR

    class Halves(Entity):
        className = "Halves"

        @Output(VECTOR, deps=())
        def every_other(self) -> np.ndarray:
            return self._buf[::2]  # 4 entries, stride 16 bytes

        def __init__(self, name: str) -> None:
            self._buf = np.arange(8.0) - 10.0

    src = Halves("halves")
    fg = FeatureGeneric("strided_fg")
    fg.errorIN.value = np.array([0.1, -0.2, 0.3, 0.0])
    fg.jacobianIN.value = np.arange(4 * NV, dtype=float).reshape(4, NV)
    task = TaskInequality("strided_ineq")
    task.add(fg)
    plug(src.every_other, task.referenceInf)
    task.dt.value = 1e-3
    ops = task._rowOps()
    assert ops is not None
    values = tuple(s._holder().value for op in ops for s in op.sources)
    assert not values[len(ops[0]) + 1].flags.c_contiguous  # referenceInf, strided
    r, A, lo, up, _ = run_ops(ops, NV, rows=6, values=values)
    assert r == 4
    np.testing.assert_allclose(lo[:4], task.lower.value, rtol=1e-13)
    np.testing.assert_array_equal(up[:4], task.upper.value)  # +inf: no referenceSup
    np.testing.assert_array_equal(A[:4], task.jacobian.value)
