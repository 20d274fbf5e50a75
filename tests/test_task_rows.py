"""Task rows written straight into a solver's buffer (``sotpy.tasks.rows`` and the
kernels of ``sotpy.tasks._rowkernels``): the compiled ``log3``/``Jlog3`` against
Pinocchio, an independent series and finite differences; every feature's row writer
against the feature's own ``jacobian`` and ``error`` signals on random inputs; the
task's writer against ``task.jacobian`` and ``task.task``; when writers decline
(``-1``) or are not made (``None``); ``BufferFull``.

A writer is called as the SOT calls it: ``write(values, offset, A, b, r, gain)`` with
``values[offset:]`` the values of ``writer.sources``; rows go to ``A[r:r+k]`` and
``b[r:r+k]``. The buffers are filled with NaN first, so a write outside those rows
shows.
"""

from __future__ import annotations

import math

import numpy as np
import pinocchio as pin
import pytest

from sotpy.errors import SignalTypeError
from sotpy.graph import MATRIX, Entity, Output, plug
from sotpy.tasks import (
    FeatureGeneric,
    FeaturePose,
    FeaturePoseSE3,
    FeaturePosture,
    FeatureVisualPoint,
    Flags,
    Task,
)
from sotpy.tasks import _rowkernels as rk
from sotpy.tasks.rows import BufferFull, RowWriter

pytestmark = pytest.mark.skipif(rk.pose_rows is None, reason="the row kernels need numba")

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


# -- feature writers ------------------------------------------------------------------
def values_of(w: RowWriter) -> tuple:
    return tuple(s.value for s in w.sources)


def made_by(w: RowWriter) -> str:
    """Which writer: ``"FeaturePose"``, ``"FeatureGeneric"``, ``"FeaturePosture"`` (a
    kernel's), ``"callbackWriter"`` (the feature's own callbacks) or ``"Task"``."""
    return w.write.__qualname__.split(".")[0]


def check_writer(feature, gain: float, r: int = 3, extra: int = 2, nv: int = NV) -> int:
    """Write the feature's rows at row ``r`` of NaN buffers; they must equal its
    signals, and nothing else may be written."""
    w = feature._rowWriter()
    assert w is not None
    J = feature.jacobian.value
    e = feature.error.value
    m = feature.dim.value
    assert J.shape == (m, nv) and e.shape == (m,)
    A = np.full((r + m + extra, nv), np.nan)
    b = np.full(r + m + extra, np.nan)
    k = w.write((*JUNK, *values_of(w)), len(JUNK), A, b, r, gain)
    assert k == m
    np.testing.assert_allclose(A[r : r + k], J, rtol=0, atol=1e-12)
    np.testing.assert_allclose(b[r : r + k], -gain * e, rtol=0, atol=1e-12)
    assert np.isnan(A[:r]).all() and np.isnan(A[r + k :]).all()
    assert np.isnan(b[:r]).all() and np.isnan(b[r + k :]).all()
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
def test_feature_pose_writer_gives_its_jacobian_and_error(selec, seed):
    rng = np.random.default_rng(seed)
    f = pose_feature(FeaturePose, "fpose", rng, selec)
    assert made_by(f._rowWriter()) == "FeaturePose"
    gain = float(rng.uniform(0.1, 50.0))
    k = check_writer(f, gain)
    assert k == selec.count("1")
    # the error, independently: (R*^T (p - p*), log3(R*^T R)) on the selected rows
    M, Md = f.position.value, f.reference.value
    full = np.concatenate(
        (Md.rotation.T @ (M.translation - Md.translation), pin.log3(Md.rotation.T @ M.rotation))
    )
    rows = [i for i, c in enumerate(selec) if c == "1"]
    np.testing.assert_allclose(f.error.value, full[rows], rtol=0, atol=1e-12)


@pytest.mark.parametrize("theta", [0.0, 1e-8, 1e-3, math.pi - 1e-6, math.pi - 1e-3])
def test_feature_pose_writer_at_small_and_near_pi_relative_rotations(theta):
    rng = np.random.default_rng(42)
    Mdes = pin.SE3(random_rotation(rng), rng.standard_normal(3))
    f = pose_feature(FeaturePose, "fpose", rng, "111111", Mdes=Mdes)
    rel = pin.SE3(pin.exp3(theta * unit(rng)), 0.1 * rng.standard_normal(3))
    f.position.value = Mdes * rel
    # Pinocchio's Jlog3 near zero carries its own ~1e-10 (see the tiny-angle test)
    w = f._rowWriter()
    A, b = np.full((6, NV), np.nan), np.full(6, np.nan)
    assert w.write(values_of(w), 0, A, b, 0, 2.0) == 6
    np.testing.assert_allclose(A, f.jacobian.value, rtol=0, atol=1e-8)
    np.testing.assert_allclose(b, -2.0 * f.error.value, rtol=0, atol=1e-9)


def test_feature_pose_writer_reads_the_sources_of_its_jacobian():
    class ConstJacobian(Entity):
        @Output(MATRIX, timeDependent=False)
        def out(self):
            return self.J

    rng = np.random.default_rng(0)
    f = pose_feature(FeaturePose, "fpose", rng, "110011")
    src = ConstJacobian("src")
    src.J = rng.standard_normal((6, NV))
    plug(src.out, f.Jq)
    w = f._rowWriter()
    # the holders: a plugged input is replaced by the output it follows
    assert w.sources == (f.selec, f.position, f.reference, src.out)
    check_writer(f, 1.5)
    # the writer reads the values it is given, not the signals: another Jacobian
    values = list(values_of(w))
    values[3] = 2.0 * values[3]
    A, b = np.full((4, NV), np.nan), np.full(4, np.nan)
    assert w.write(values, 0, A, b, 0, 1.5) == 4
    np.testing.assert_allclose(A, 2.0 * f.jacobian.value, rtol=0, atol=1e-12)


@pytest.mark.parametrize("selec", POSE_SELECTIONS)
def test_feature_pose_se3_uses_its_callbacks_as_writer(selec):
    rng = np.random.default_rng(9)
    f = pose_feature(FeaturePoseSE3, "fse3", rng, selec)
    w = f._rowWriter()
    assert made_by(w) == "callbackWriter"
    # the generic writer: the error's then the jacobian's sources
    assert w.sources == (*f.error.dependencies, *f.jacobian.dependencies)
    check_writer(f, 0.7)


@pytest.mark.parametrize("selec", [True, "10110", "00001", "11111", "0"])
@pytest.mark.parametrize("reference", [False, True])
def test_feature_generic_writer_gives_its_jacobian_and_error(selec, reference):
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
    w = f._rowWriter()
    assert made_by(w) == "FeatureGeneric"
    assert len(w) == (3 if reference else 2) + 2
    k = check_writer(f, 3.25)
    assert k == Flags(selec).count(m)
    if reference:  # the difference, independently
        e = f.errorIN.value - ref.errorIN.value
        rows = Flags(selec).rows(m)
        np.testing.assert_allclose(f.error.value, e if rows is None else e[rows], atol=0)


def test_feature_generic_writer_declines_what_its_callbacks_refuse():
    rng = np.random.default_rng(1)
    f = FeatureGeneric("fgen")
    f.errorIN.value = rng.standard_normal(3)
    f.jacobianIN.value = rng.standard_normal((3, NV))
    ref = FeatureGeneric("fgenDes")
    ref.errorIN.value = rng.standard_normal(2)  # wrong size
    f.setReference(ref)
    w = f._rowWriter()
    A, b = np.full((6, NV), np.nan), np.full(6, np.nan)
    assert w.write(values_of(w), 0, A, b, 0, 1.0) == -1
    with pytest.raises(SignalTypeError, match="fgenDes"):
        f.error.value  # noqa: B018
    ref.errorIN.value = rng.standard_normal(3)
    # a Jacobian of another width than the buffer, or of other rows than the error
    assert w.write(values_of(w), 0, np.full((6, NV + 1), np.nan), b, 0, 1.0) == -1
    f.jacobianIN.value = rng.standard_normal((4, NV))
    assert w.write(values_of(w), 0, A, b, 0, 1.0) == -1
    assert np.isnan(A).all() and np.isnan(b).all()  # nothing written when declining


def test_callback_writer_calls_the_callback_in_force():
    rng = np.random.default_rng(2)
    f = FeatureGeneric("fgen")
    f.errorIN.value = rng.standard_normal(3)
    f.jacobianIN.value = rng.standard_normal((3, NV))
    f.error.setFunction(lambda selec, s: 2.0 * s + 1.0)
    # not the kernel's: the error is no longer FeatureGeneric's
    assert made_by(f._rowWriter()) == "callbackWriter"
    check_writer(f, 0.5)
    np.testing.assert_allclose(f.error.value, 2.0 * f.errorIN.value + 1.0)


def test_feature_visual_point_uses_its_callbacks_as_writer():
    rng = np.random.default_rng(4)
    f = FeatureVisualPoint("fvp")
    f.xy.value = [0.1, -0.2]
    f.Z.value = 1.5
    f.Jq.value = rng.standard_normal((6, NV))
    f.xyRef.value = [0.05, 0.0]
    for selec in (True, "01"):
        f.selec.value = selec
        check_writer(f, 1.2)


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


def test_feature_posture_writer_default_selection_uses_the_kernel(humanoid):
    rng = np.random.default_rng(8)
    f = posture_feature(humanoid, rng)
    assert made_by(f._rowWriter()) == "FeaturePosture"
    assert f._postureIndex(f.selec.value) is not None  # one-DoF joints only: the kernel
    k = check_writer(f, 0.9, nv=humanoid.nv)
    assert k == humanoid.nv - 6  # the free flyer excluded
    # the rows of the identity at the joints' DoFs
    J = f.jacobian.value
    np.testing.assert_array_equal(J, np.eye(humanoid.nv)[6:])


@pytest.mark.parametrize(
    "dofs, kernel",
    [([7, 10, 33], True), ([6], True), ([0, 4, 12], False), ([3, 4, 5], False)],
)
def test_feature_posture_writer_with_a_few_dofs(humanoid, dofs, kernel):
    rng = np.random.default_rng(len(dofs) + dofs[0])
    f = posture_feature(humanoid, rng)
    f.selec.value = Flags([i in dofs for i in range(humanoid.nv)])
    # a free flyer's DoF: Pinocchio's dDifference block through the callbacks
    assert (f._postureIndex(f.selec.value) is not None) == kernel
    assert check_writer(f, 2.5, nv=humanoid.nv) == len(dofs)


@pytest.mark.parametrize("selec, kernel", [(True, False), ("101", True), ("010", False)])
def test_feature_posture_writer_with_a_continuous_joint(continuous, selec, kernel):
    rng = np.random.default_rng(21)
    f = posture_feature(continuous, rng)
    f.selec.value = selec
    assert (f._postureIndex(f.selec.value) is not None) == kernel
    k = check_writer(f, 1.75, nv=continuous.nv)
    assert k == Flags(selec).count(3)
    # the continuous joint's error: the angle between the two, in (-pi, pi]
    if selec is True:
        q, qd = f.state.value, f.posture.value
        angle = math.atan2(q[2], q[1]) - math.atan2(qd[2], qd[1])
        angle = math.remainder(angle, 2 * math.pi)
        assert f.error.value[1] == pytest.approx(angle, abs=1e-12)


def test_feature_posture_writer_raises_the_callbacks_errors(humanoid):
    rng = np.random.default_rng(0)
    f = posture_feature(humanoid, rng)
    w = f._rowWriter()
    A, b = np.full((40, humanoid.nv), np.nan), np.full(40, np.nan)
    f.posture.value = np.zeros(5)
    with pytest.raises(SignalTypeError) as fused:
        w.write(values_of(w), 0, A, b, 0, 1.0)
    with pytest.raises(SignalTypeError) as plain:
        f.error.value  # noqa: B018
    assert str(fused.value) == str(plain.value)
    assert "fposture" in str(fused.value)
    f.posture.value = pin.neutral(humanoid)
    assert w.write(values_of(w), 0, A, b, 0, 1.0) == humanoid.nv - 6
    # the buffer of another width: declined
    assert w.write(values_of(w), 0, np.full((40, 3), np.nan), b, 0, 1.0) == -1


# -- writers not made -----------------------------------------------------------------
def test_no_writer_for_outputs_not_computed_by_a_callback_every_tick():
    rng = np.random.default_rng(6)
    f = pose_feature(FeaturePose, "fpose", rng, "111111")
    assert f._rowWriter() is not None
    f.jacobian.setPeriod(2)
    assert f._rowWriter() is None
    f.jacobian.setPeriod(1)
    assert f._rowWriter() is not None
    f.error.value = np.zeros(6)  # a constant
    assert f._rowWriter() is None
    f.error.resetCallback()
    assert f._rowWriter() is not None


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


def write_task(t, nv, r=2, rows=None, gain=123.0, values=None):
    w = t._rowWriter()
    assert w is not None
    n = rows if rows is not None else r + 12
    A, b = np.full((n, nv), np.nan), np.full(n, np.nan)
    v = values if values is not None else values_of(w)
    k = w.write((*JUNK, *v), len(JUNK), A, b, r, gain)
    return k, A, b


def test_task_writer_gives_the_task_jacobian_and_target(humanoid):
    rng = np.random.default_rng(30)
    t, features = three_feature_task(humanoid, rng)
    m = sum(f.dim.value for f in features)
    assert m == 3 + 2 + 3
    r = 2
    # the gain argument is the SOT's placeholder: the task writes -controlGain e
    k, A, b = write_task(t, humanoid.nv, r=r, gain=123.0)
    assert k == m
    np.testing.assert_allclose(A[r : r + k], t.jacobian.value, rtol=0, atol=1e-12)
    np.testing.assert_allclose(b[r : r + k], t.task.value, rtol=0, atol=1e-12)
    np.testing.assert_allclose(b[r : r + k], -4.0 * t.error.value, rtol=0, atol=1e-12)
    assert np.isnan(A[:r]).all() and np.isnan(A[r + k :]).all()
    assert np.isnan(b[:r]).all() and np.isnan(b[r + k :]).all()
    # the sources: controlSelec, controlGain, then each feature's
    w = t._rowWriter()
    assert w.sources[:2] == (t.controlSelec, t.controlGain)
    assert len(w) == 2 + sum(len(f._rowWriter()) for f in features)


def test_task_writer_zeroes_the_unselected_columns(humanoid):
    rng = np.random.default_rng(31)
    t, _ = three_feature_task(humanoid, rng)
    nv = humanoid.nv
    cols = [i % 3 != 0 for i in range(nv)]
    t.controlSelec.value = cols
    k, A, b = write_task(t, nv, r=0)
    J = t.jacobian.value
    assert not J[:, ~np.array(cols)].any()
    np.testing.assert_allclose(A[:k], J, rtol=0, atol=1e-12)
    np.testing.assert_allclose(b[:k], t.task.value, rtol=0, atol=1e-12)
    assert not A[:k, ~np.array(cols)].any()


def test_task_writer_is_not_made_when_the_task_signals_must_be_read(humanoid):
    rng = np.random.default_rng(32)
    t, (_, fg, _) = three_feature_task(humanoid, rng)
    assert t._rowWriter() is not None
    t.setWithDerivative(True)  # the feed-forward reads errordot
    assert t._rowWriter() is None
    t.setWithDerivative(False)
    assert t._rowWriter() is not None
    t.task.value = np.zeros(8)  # the target set to a constant
    assert t._rowWriter() is None
    t.task.resetCallback()
    assert t._rowWriter() is not None
    fg.jacobian.setPeriod(2)  # a feature computed every other tick
    assert t._rowWriter() is None
    fg.jacobian.setPeriod(1)
    assert t._rowWriter() is not None
    t.jacobian.setPeriod(3)
    assert t._rowWriter() is None
    t.jacobian.setPeriod(1)
    t.error.setFunction(lambda *errors: np.concatenate(errors))  # another callback
    assert t._rowWriter() is None
    assert Task("empty")._rowWriter() is None


@pytest.mark.parametrize("gain", [-1.0, math.nan, math.inf])
def test_task_writer_declines_a_gain_out_of_range(humanoid, gain):
    rng = np.random.default_rng(33)
    t, _ = three_feature_task(humanoid, rng)
    values = list(values_of(t._rowWriter()))
    values[1] = gain  # controlGain's value (a NaN constant is refused by the signal)
    k, A, b = write_task(t, humanoid.nv, values=values)
    assert k == -1
    assert np.isnan(A[:2]).all() and np.isnan(b[:2]).all()  # before its rows: untouched
    if gain == -1.0:  # the task signal says what is wrong
        t.controlGain.value = gain
        with pytest.raises(SignalTypeError, match="controlGain: expected a finite gain >= 0"):
            t.task.value  # noqa: B018
        t.controlGain.value = 4.0
        assert write_task(t, humanoid.nv)[0] == 8


def test_task_writer_declines_a_jacobian_of_the_wrong_width(humanoid):
    rng = np.random.default_rng(34)
    t, (_, fg, _) = three_feature_task(humanoid, rng)
    # a buffer of another width than the features' Jacobians
    assert write_task(t, humanoid.nv + 1)[0] == -1
    # one feature's Jacobian of another width (the others fit the buffer)
    fg.jacobianIN.value = rng.standard_normal((3, humanoid.nv - 1))
    assert write_task(t, humanoid.nv)[0] == -1
    # a column selection longer than the Jacobian
    fg.jacobianIN.value = rng.standard_normal((3, humanoid.nv))
    assert write_task(t, humanoid.nv)[0] == 8
    t.controlSelec.value = Flags([False] * (humanoid.nv + 2) + [True])
    assert write_task(t, humanoid.nv)[0] == -1


# -- BufferFull -----------------------------------------------------------------------
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
        (pose, NV, 5),
        (se3, NV, 6),
        (gen, NV, 4),
        (post, humanoid.nv, humanoid.nv - 6),
        (cont, continuous.nv, 3),
        (task, humanoid.nv, 8),
    ]


def test_writers_raise_buffer_full_when_the_rows_do_not_fit(humanoid, continuous):
    rng = np.random.default_rng(40)
    for entity, nv, k in _writers(humanoid, continuous, rng):
        w = entity._rowWriter()
        r = 3
        for rows in (r + k - 1, r):  # one row short; none left at all
            A, b = np.full((rows, nv), np.nan), np.full(rows, np.nan)
            with pytest.raises(BufferFull):
                w.write(values_of(w), 0, A, b, r, 1.0)
        A, b = np.full((r + k, nv), np.nan), np.full(r + k, np.nan)  # exactly enough
        assert w.write(values_of(w), 0, A, b, r, 1.0) == k, entity.name
        assert np.isfinite(A[r:]).all() and np.isnan(A[:r]).all()


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
def test_inequality_bounds_kernel_matches_the_task_callback(case):
    """``inequality_bounds`` (the bounds of TaskInequality's writer) against the task's
    own ``_bounds`` callback: the same bounds where the callback accepts the references
    (to rounding: the writer adds ``c ref`` to the features' ``-c e``, the callback
    computes ``c (ref - e)``), -1 where it raises."""
    from sotpy.errors import SotpyError
    from sotpy.tasks import TaskInequality

    rng = np.random.default_rng(sum(map(ord, case)))  # a seed per case, the same every run
    task = TaskInequality("ineq_" + case.replace(" ", "_"))
    m, r, k, dt = 7, 3, 0.7, 1e-3
    c = k / dt
    e = rng.standard_normal(m)
    rinf, rsup = _references(rng, m, case)
    lo = np.full(m + 5, np.nan)
    up = np.full(m + 5, np.nan)
    lo[r : r + m] = -c * e  # what the features' rows leave there
    got = rk.inequality_bounds(rinf, rsup, c, lo, up, r, m)
    try:
        with np.errstate(over="ignore"):  # the overflow case: the callback refuses it
            want = task._bounds(rinf, rsup, k, dt, e)
    except SotpyError:
        want = None
    if want is None:  # "overflow": a finite reference whose bound is not finite
        assert got == -1
        return
    assert got == m
    assert np.isnan(lo[:r]).all() and np.isnan(up[r + m :]).all()  # only its rows
    for got_bound, want_bound in ((lo[r : r + m], want[0]), (up[r : r + m], want[1])):
        np.testing.assert_array_equal(np.isfinite(got_bound), np.isfinite(want_bound))
        np.testing.assert_allclose(got_bound, want_bound, rtol=1e-13, atol=0.0)


def test_inequality_bounds_accept_strided_references():
    """A reference handed out as a strided view (a user's entity slicing a vector): the
    fused write gives the bounds the task's callback gives, with no fallback."""
    from sotpy.graph import VECTOR, Entity, Output
    from sotpy.tasks import TaskInequality

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
    writer = task._rowWriter()
    assert writer is not None
    values = tuple(s._holder().value for s in writer.sources)
    assert not values[1].flags.c_contiguous  # referenceInf, strided
    A = np.full((6, NV), np.nan)
    lo, up = np.full(6, np.nan), np.full(6, np.nan)
    assert writer.write(values, 0, A, lo, up, 1) == 4
    np.testing.assert_allclose(lo[1:5], task.lower.value, rtol=1e-13)
    np.testing.assert_array_equal(up[1:5], task.upper.value)  # +inf: no referenceSup
    np.testing.assert_array_equal(A[1:5], task.jacobian.value)
