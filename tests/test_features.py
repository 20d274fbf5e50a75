"""Features: errors against independent formulas, Jacobians against finite differences.

Every Jacobian is checked on Talos (example-robot-data, 38 DoF, free flyer) at random
configurations: for a random tangent direction ``dq``,
``(e(q (+) eps dq) - e(q (-) eps dq)) / (2 eps) = J dq`` (central differences,
``eps = 1e-6``). Every ``errordot`` is checked the same way by moving the reference
instead of the robot.
"""

from __future__ import annotations

import warnings
import zlib

import numpy as np
import pinocchio as pin
import pytest

from sotpy.dynamics import Dynamic, load_model
from sotpy.errors import CommandError, EntityError, SignalTypeError, UnpluggedError
from sotpy.graph import plug
from sotpy.tasks import (
    OPTICAL_FROM_XFORWARD,
    FeatureAbstract,
    FeatureGeneric,
    FeatureJointLimits,
    FeaturePose,
    FeaturePoseSE3,
    FeaturePosture,
    FeatureVisualPoint,
    Flags,
    interactionMatrix,
)

EPS = 1e-6
OP_POINTS = {
    "right-wrist": "arm_right_7_joint",
    "left-ankle": "leg_left_6_joint",
    "gaze": "rgbd_rgb_frame",
}


@pytest.fixture
def talos():
    """(model, dynamic) with three op points."""
    model = load_model("talos")[0]
    dyn = Dynamic("dyn", model)
    for name, frame in OP_POINTS.items():
        dyn.createOpPoint(name, frame)
    return model, dyn


def random_q(model: pin.Model, rng: np.random.Generator) -> np.ndarray:
    """A configuration with joints uniform within their limits, a random base."""
    q = pin.neutral(model)
    lo, up = model.lowerPositionLimit, model.upperPositionLimit
    for j in range(1, model.njoints):
        i, n = model.idx_qs[j], model.nqs[j]
        if model.joints[j].shortname() == "JointModelFreeFlyer":
            q[i : i + 3] = rng.uniform(-1, 1, 3)
            quat = rng.standard_normal(4)
            q[i + 3 : i + 7] = quat / np.linalg.norm(quat)
        else:
            q[i : i + n] = rng.uniform(lo[i : i + n], up[i : i + n])
    return q


def central_difference(error, model, q, dq):
    """(e(q (+) eps dq) - e(q (-) eps dq)) / (2 eps)."""
    ep = np.array(error(pin.integrate(model, q, EPS * dq)), dtype=float)
    em = np.array(error(pin.integrate(model, q, -EPS * dq)), dtype=float)
    error(q)  # restore
    return (ep - em) / (2 * EPS)


def assert_jacobian(J, error, model, q, rng, directions=4):
    """J dq equals the central difference of ``error`` along random directions."""
    for _ in range(directions):
        dq = rng.standard_normal(model.nv)
        fd = central_difference(error, model, q, dq)
        np.testing.assert_allclose(J @ dq, fd, atol=1e-6 * max(1.0, np.abs(fd).max()))


# -- flags ----------------------------------------------------------------------------
def test_flags_are_read_left_to_right():
    assert Flags("111000").rows(6).tolist() == [0, 1, 2]
    assert Flags("000111").rows(6).tolist() == [3, 4, 5]
    assert Flags("11").rows(3).tolist() == [0, 1]  # rows past the string: off
    assert Flags("1 0 1").rows(3).tolist() == [0, 2]  # spaces ignored
    assert Flags([True, False, True]).rows(4).tolist() == [0, 2]
    assert Flags(np.array([0, 1, 1], dtype=bool)).rows(3).tolist() == [1, 2]
    assert Flags(True).rows(5) is None  # every row
    assert Flags("111111").rows(6) is None
    assert Flags(False).rows(2).tolist() == []
    f = Flags("101")
    assert [f(i) for i in range(5)] == [True, False, True, False, False]


def test_flags_combine_and_compare():
    f = Flags("1100")
    assert (~f).rows(4).tolist() == [2, 3]
    assert (~f)(10) is True  # the complement selects every row past the string
    assert (f & Flags("0110")).rows(4).tolist() == [1]
    assert (f | "0011").rows(4) is None
    assert f.set(3).rows(4).tolist() == [0, 1, 3]
    assert f.set(0, False).rows(4).tolist() == [1]
    assert f.set(6).rows(7).tolist() == [0, 1, 6]
    assert Flags("110") == Flags("11") and hash(Flags("110")) == hash(Flags("11"))
    assert Flags("1") != Flags(True)
    assert Flags([False] * 6, rest=True).rows(8).tolist() == [6, 7]
    assert str(Flags("1100")) == "1100" and str(Flags(True)) == "all"
    assert str(Flags("00", rest=True)) == "00[1...]"
    assert eval(repr(Flags("0110"))) == Flags("0110")


def test_flags_refuse_bad_input():
    with pytest.raises(ValueError, match="'2'"):
        Flags("1120")
    with pytest.raises(TypeError, match="number"):
        Flags(63)  # the SoT's old bit masks are not accepted
    with pytest.raises(TypeError, match="booleans"):
        Flags([1, 2])
    with pytest.raises(ValueError, match="select row 6 but there are only 6 rows"):
        Flags("1111111").rows(6)
    Flags("1111110").rows(6)  # trailing zeros are fine


def test_selec_signal_converts_strings_and_names_itself_on_error(talos):
    f = FeatureGeneric("fg")
    f.selec.value = "101"
    assert isinstance(f.selec.value, Flags) and f.selec.value.rows(3).tolist() == [0, 2]
    f.selec.value = [True, True]
    assert f.selec.value == Flags("11")
    with pytest.raises(SignalTypeError, match=r"FeatureGeneric\(fg\)::input\(flag\)::selec"):
        f.selec.value = "1x"
    f.errorIN.value = [1.0, 2.0]
    f.jacobianIN.value = np.eye(2)
    f.selec.value = "111"
    with pytest.raises(SignalTypeError, match=r"::selec: flags 111 select row 2 .* only 2"):
        f.error.value  # noqa: B018


def test_feature_abstract_is_abstract():
    with pytest.raises(EntityError, match="abstract"):
        FeatureAbstract("fa")


# -- FeaturePose ----------------------------------------------------------------------
def independent_placement(model, q, frame):
    data = model.createData()
    pin.framesForwardKinematics(model, data, q)
    return data.oMf[model.getFrameId(frame)]


@pytest.mark.parametrize("cls", [FeaturePose, FeaturePoseSE3])
@pytest.mark.parametrize("op", list(OP_POINTS))
def test_feature_pose_error_and_jacobian(talos, cls, op):
    model, dyn = talos
    rng = np.random.default_rng(zlib.crc32(op.encode()))  # str hash() varies per process
    f = cls("f")
    plug(dyn.signal(op), f.position)
    plug(dyn.signal("J" + op), f.Jq)

    def error(q):
        dyn.position.value = q
        return f.error.value.copy()

    for _ in range(3):
        q = random_q(model, rng)
        dyn.position.value = q
        M = independent_placement(model, q, OP_POINTS[op])
        # a reference at most 2 rad away in rotation: near pi, log3 and its Jacobian are
        # ill-conditioned (1/sin) and a central difference loses digits
        axis = rng.standard_normal(3)
        twist = np.concatenate(
            [rng.uniform(-0.5, 0.5, 3), axis / np.linalg.norm(axis) * rng.uniform(0.0, 2.0)]
        )
        Mdes = M * pin.exp6(twist)
        f.reference.value = Mdes
        rel = Mdes.inverse() * M
        if cls is FeaturePose:  # translation of M*^-1 M, u-theta of R*^T R
            expected = np.concatenate([rel.translation, pin.log3(Mdes.rotation.T @ M.rotation)])
        else:
            expected = pin.log6(rel).vector
        np.testing.assert_allclose(f.error.value, expected, atol=1e-10)
        assert np.abs(expected).max() > 1e-2  # a non-trivial error
        assert_jacobian(f.jacobian.value, error, model, q, rng)
        np.testing.assert_array_equal(f.errordot.value, np.zeros(6))  # fixed reference


@pytest.mark.parametrize("op", list(OP_POINTS))
def test_feature_pose_current_frame_error_jacobian_errordot(talos, op):
    """SoT's frame('current'): the error of M* seen from M, its exact Jacobian and its
    errordot, against the formula and finite differences."""
    model, dyn = talos
    rng = np.random.default_rng(zlib.crc32(op.encode()) + 1)
    f = FeaturePose("f")
    assert f.getFrame() == "desired"
    f.frame("current")
    assert f.getFrame() == "current"
    plug(dyn.signal(op), f.position)
    plug(dyn.signal("J" + op), f.Jq)

    def error(q):
        dyn.position.value = q
        return f.error.value.copy()

    for _ in range(3):
        q = random_q(model, rng)
        dyn.position.value = q
        M = independent_placement(model, q, OP_POINTS[op])
        axis = rng.standard_normal(3)
        twist = np.concatenate(
            [rng.uniform(-0.5, 0.5, 3), axis / np.linalg.norm(axis) * rng.uniform(0.0, 2.0)]
        )
        Mdes = M * pin.exp6(twist)
        f.reference.value = Mdes
        expected = np.concatenate(
            [
                M.rotation.T @ (Mdes.translation - M.translation),
                pin.log3(M.rotation.T @ Mdes.rotation),
            ]
        )
        np.testing.assert_allclose(f.error.value, expected, atol=1e-10)
        assert_jacobian(f.jacobian.value, error, model, q, rng)
        # errordot: the rate of the error when the reference moves, q fixed
        nu = rng.standard_normal(6)
        f.referenceVelocity.value = nu
        ed = f.errordot.value
        f.reference.value = Mdes * pin.exp6(EPS * nu)
        ep = f.error.value.copy()
        f.reference.value = Mdes * pin.exp6(-EPS * nu)
        em = f.error.value.copy()
        np.testing.assert_allclose(ed, (ep - em) / (2 * EPS), atol=1e-6)
        f.referenceVelocity.value = np.zeros(6)
        f.reference.value = Mdes
    # the selection keeps the rows of the current-frame error
    f.selec.value = "111000"
    np.testing.assert_allclose(f.error.value, expected[:3], atol=1e-10)
    with pytest.raises(CommandError, match=r"FeaturePose\(f\)\.frame: expected 'current'"):
        f.frame("world")
    assert f.getFrame() == "current"
    with pytest.raises(CommandError, match="FeaturePose's frame"):
        FeaturePoseSE3("g").frame("current")


def test_placement_inputs_take_homogeneous_matrices_and_tuples(talos):
    """SoT writes placements as 4 x 4 homogeneous matrices (arrays or tuples of rows);
    they are checked and stored as pinocchio.SE3."""
    f = FeaturePose("f")
    M = pin.SE3(pin.exp3(np.array([0.1, -0.2, 0.3])), np.array([0.5, -0.2, 1.0]))
    f.reference.value = M.homogeneous
    assert isinstance(f.reference.value, pin.SE3) and f.reference.value.isApprox(M, 1e-12)
    f.reference.value = tuple(tuple(r) for r in M.homogeneous.tolist())
    assert f.reference.value.isApprox(M, 1e-12)
    with warnings.catch_warnings():  # numpy.matrix, as old SoT scripts use it
        warnings.simplefilter("ignore", PendingDeprecationWarning)
        f.reference.value = np.asmatrix(M.homogeneous)
    assert f.reference.value.isApprox(M, 1e-12)
    rounded = np.round(M.homogeneous, 6)  # a few digits: projected on SO(3)
    f.reference.value = rounded
    R = f.reference.value.rotation
    np.testing.assert_allclose(R.T @ R, np.eye(3), atol=1e-14)
    for bad, why in (
        (np.diag([2.0, 2.0, 2.0, 1.0]), "not a rotation"),
        (np.eye(3), "4 x 4"),
        (np.diag([1.0, 1.0, 1.0, 2.0]), "last row"),
        ("eye", "homogeneous matrix"),
    ):
        with pytest.raises(
            SignalTypeError, match=rf"FeaturePose\(f\)::input\(SE3\)::reference.*{why}"
        ):
            f.reference.value = bad
    assert f.reference.value.isApprox(pin.SE3(R, rounded[:3, 3]), 1e-12)  # left unchanged


@pytest.mark.parametrize("cls", [FeaturePose, FeaturePoseSE3])
def test_feature_pose_errordot_is_the_rate_due_to_the_moving_reference(talos, cls):
    """errordot = d e / dt at fixed q when dM*/dt = M* [nu*]; and with J it predicts the
    total rate when both move."""
    model, dyn = talos
    rng = np.random.default_rng(7)
    f = cls("f")
    plug(dyn.signal("right-wrist"), f.position)
    plug(dyn.signal("Jright-wrist"), f.Jq)
    q = random_q(model, rng)
    dyn.position.value = q
    Mdes = independent_placement(model, random_q(model, rng), "arm_right_7_joint")
    for _ in range(3):
        nu = rng.standard_normal(6)
        f.reference.value = Mdes
        f.referenceVelocity.value = nu
        ed = f.errordot.value
        J = f.jacobian.value
        f.reference.value = Mdes * pin.exp6(EPS * nu)
        ep = f.error.value.copy()
        f.reference.value = Mdes * pin.exp6(-EPS * nu)
        em = f.error.value.copy()
        np.testing.assert_allclose(ed, (ep - em) / (2 * EPS), atol=1e-6)
        # both move: e(t + h) - e(t - h) ~ 2 h (J v + errordot)
        v = rng.standard_normal(model.nv)
        f.reference.value = Mdes * pin.exp6(EPS * nu)
        dyn.position.value = pin.integrate(model, q, EPS * v)
        ep = f.error.value.copy()
        f.reference.value = Mdes * pin.exp6(-EPS * nu)
        dyn.position.value = pin.integrate(model, q, -EPS * v)
        em = f.error.value.copy()
        dyn.position.value = q
        np.testing.assert_allclose(J @ v + ed, (ep - em) / (2 * EPS), atol=1e-6)


@pytest.mark.parametrize("cls", [FeaturePose, FeaturePoseSE3])
def test_feature_pose_selection_keeps_the_selected_rows(talos, cls):
    model, dyn = talos
    rng = np.random.default_rng(3)
    f = cls("f")
    plug(dyn.signal("right-wrist"), f.position)
    plug(dyn.signal("Jright-wrist"), f.Jq)
    dyn.position.value = random_q(model, rng)
    f.reference.value = pin.SE3.Random()
    f.referenceVelocity.value = rng.standard_normal(6)
    e, J, ed = f.error.value, f.jacobian.value, f.errordot.value
    assert f.dim.value == 6 and J.shape == (6, model.nv)
    for flags, rows in (
        ("111000", [0, 1, 2]),
        ("000111", [3, 4, 5]),
        ("001", [2]),
        ("010001", [1, 5]),
        ("111001", [0, 1, 2, 5]),
        ("000011", [4, 5]),
        ("111111", [0, 1, 2, 3, 4, 5]),
    ):
        f.selec.value = flags
        np.testing.assert_array_equal(f.error.value, e[rows])
        np.testing.assert_allclose(f.jacobian.value, J[rows], rtol=0, atol=1e-14)
        np.testing.assert_allclose(f.errordot.value, ed[rows], atol=1e-15)
        assert f.dim.value == len(rows)
    # the error is a fresh array: writing into it changes nothing the feature computes
    f.selec.value = "111000"
    f.error.value[:] = np.nan
    np.testing.assert_allclose(f.errordot.value, ed[:3], atol=1e-15)
    f.reference.value = f.reference.value.copy()  # new tick's values, same placements
    np.testing.assert_array_equal(f.error.value, e[:3])
    f.selec.value = "1111111"  # 7 rows asked of a 6-row feature
    with pytest.raises(SignalTypeError, match=rf"{cls.__name__}\(f\)::input\(flag\)::selec"):
        f.error.value  # noqa: B018


def test_feature_pose_keep_gives_zero_error_and_reference_is_required(talos):
    model, dyn = talos
    f = FeaturePose("f")
    plug(dyn.signal("left-ankle"), f.position)
    plug(dyn.signal("Jleft-ankle"), f.Jq)
    dyn.position.value = random_q(model, np.random.default_rng(4))
    with pytest.raises(UnpluggedError, match=r"FeaturePose\(f\)::input\(SE3\)::reference"):
        f.error.value  # noqa: B018
    f.referenceVelocity.value = np.ones(6)
    f.keep()
    np.testing.assert_allclose(f.error.value, np.zeros(6), atol=1e-12)
    np.testing.assert_array_equal(f.errordot.value, np.zeros(6))
    with pytest.raises(CommandError, match="reference"):
        f.setReference(FeaturePose("g"))  # a pose takes its reference from a signal


def test_feature_pose_refuses_a_jacobian_that_is_not_6_rows(talos):
    f = FeaturePose("f")
    f.position.value = pin.SE3.Identity()
    f.reference.value = pin.SE3.Identity()
    f.Jq.value = np.zeros((3, 10))
    with pytest.raises(SignalTypeError, match=r"::Jq: expected a 6 x nv Jacobian"):
        f.jacobian.value  # noqa: B018


# -- FeatureGeneric -------------------------------------------------------------------
def test_feature_generic_com_with_reference_feature(talos):
    model, dyn = talos
    rng = np.random.default_rng(5)
    f = FeatureGeneric("fcom")
    fdes = FeatureGeneric("fcomdes")
    plug(dyn.com, f.errorIN)
    plug(dyn.Jcom, f.jacobianIN)
    f.setReference("fcomdes")
    assert f.getReference() == "fcomdes"
    cdes = np.array([0.1, -0.05, 0.8])
    fdes.errorIN.value = cdes
    q = random_q(model, rng)
    dyn.position.value = q
    data = model.createData()
    com = pin.centerOfMass(model, data, q)
    np.testing.assert_allclose(f.error.value, com - cdes, atol=1e-12)

    def error(qq):
        dyn.position.value = qq
        return f.error.value.copy()

    assert_jacobian(f.jacobian.value, error, model, q, rng)
    # errordot: own rate minus the reference's (a reference moving at cdot gives -cdot)
    np.testing.assert_array_equal(f.errordot.value, np.zeros(3))
    fdes.errordotIN.value = [0.1, 0.2, 0.3]
    np.testing.assert_allclose(f.errordot.value, [-0.1, -0.2, -0.3])
    f.errordotIN.value = [1.0, 1.0, 1.0]
    np.testing.assert_allclose(f.errordot.value, [0.9, 0.8, 0.7])
    f.selec.value = "11"
    np.testing.assert_allclose(f.error.value, (com - cdes)[:2], atol=1e-12)
    assert f.jacobian.value.shape == (2, model.nv)
    np.testing.assert_allclose(f.errordot.value, [0.9, 0.8])
    f.unsetReference()
    assert f.getReference() == "none"
    np.testing.assert_allclose(f.error.value, com[:2], atol=1e-12)


def test_feature_generic_reference_errors():
    f = FeatureGeneric("f")
    with pytest.raises(CommandError, match="must be a FeatureGeneric"):
        f.setReference(FeaturePose("p"))
    with pytest.raises(CommandError, match="its own reference"):
        f.setReference(f)
    with pytest.raises(CommandError, match="unknown entity 'nope'"):
        f.setReference("nope")
    assert f.getReference() == "none"
    g = FeatureGeneric("g")
    f.setReference(g)
    f.errorIN.value = [1.0, 2.0]
    g.errorIN.value = [1.0, 2.0, 3.0]
    with pytest.raises(SignalTypeError, match=r"FeatureGeneric\(g\)::input\(vector\)::errorIN"):
        f.error.value  # noqa: B018
    g.errorIN.unplug()
    with pytest.raises(UnpluggedError, match=r"FeatureGeneric\(g\)"):
        f.error.value  # noqa: B018


# -- FeaturePosture -------------------------------------------------------------------
def test_feature_posture_default_excludes_the_free_flyer(talos):
    model, _ = talos
    rng = np.random.default_rng(6)
    f = FeaturePosture("fp", model)
    q, qdes = random_q(model, rng), random_q(model, rng)
    f.state.value = q
    f.posture.value = qdes
    assert f.dim.value == model.nv - 6
    # revolute joints: e = q - q* (q has 7 base coordinates, v 6)
    np.testing.assert_allclose(f.error.value, q[7:] - qdes[7:], atol=1e-12)
    J = f.jacobian.value
    np.testing.assert_array_equal(J, np.eye(model.nv)[6:])
    assert_jacobian(J, lambda qq: _set(f.state, qq, f.error), model, q, rng)
    f.selectDof(10, False)
    assert f.dim.value == model.nv - 7
    assert f.dofNames()[10] == model.names[6] and f.dofNames()[3] == "root_joint[3]"
    with pytest.raises(CommandError, match=r"selectDof: argument 'dofId'.*0\.\.37"):
        f.selectDof(38, True)


def _set(sig, value, out):
    sig.value = value
    return out.value.copy()


def test_feature_posture_free_flyer_rows_and_errordot(talos):
    model, _ = talos
    rng = np.random.default_rng(8)
    f = FeaturePosture("fp", model)
    for i in range(6):
        f.selectDof(i, True)
    q, qdes = random_q(model, rng), random_q(model, rng)
    f.state.value = q
    f.posture.value = qdes
    np.testing.assert_allclose(f.error.value, pin.difference(model, qdes, q), atol=1e-12)
    J = f.jacobian.value
    assert not np.allclose(J[:6, :6], np.eye(6))  # the free flyer's block is not identity
    assert_jacobian(J, lambda qq: _set(f.state, qq, f.error), model, q, rng)
    vdes = rng.standard_normal(model.nv)
    f.postureDot.value = vdes
    ed = f.errordot.value
    fd = central_difference(lambda qq: _set(f.posture, qq, f.error), model, qdes, vdes)
    np.testing.assert_allclose(ed, fd, atol=1e-6)
    np.testing.assert_allclose(ed[6:], -vdes[6:], atol=1e-12)  # revolute: -v*


def test_feature_posture_checks_sizes(talos):
    model, _ = talos
    f = FeaturePosture("fp", model)
    f.state.value = np.zeros(5)
    f.posture.value = pin.neutral(model)
    with pytest.raises(SignalTypeError, match=r"::state: expected a configuration of size nq = 39"):
        f.error.value  # noqa: B018
    q = pin.neutral(model)
    q[3:7] = [0.0, 0.0, 0.0, 2.0]
    f.state.value = q
    with pytest.raises(SignalTypeError, match="not normalised"):
        f.error.value  # noqa: B018
    with pytest.raises(EntityError, match=r"pinocchio\.Model"):
        FeaturePosture("fp2", "talos")


# -- FeatureJointLimits ---------------------------------------------------------------
def test_feature_joint_limits(talos):
    model, _ = talos
    rng = np.random.default_rng(9)
    f = FeatureJointLimits("jl", model)
    q = random_q(model, rng)
    f.joint.value = q
    lo, up = model.lowerPositionLimit[7:], model.upperPositionLimit[7:]
    assert f.dim.value == model.nv - 6  # every Talos joint is limited; not the base
    np.testing.assert_allclose(f.error.value, 2 * (q[7:] - lo) / (up - lo) - 1, atol=1e-12)
    np.testing.assert_allclose(f.widthJl.value, model.upperPositionLimit - model.lowerPositionLimit)
    assert_jacobian(f.jacobian.value, lambda qq: _set(f.joint, qq, f.error), model, q, rng)
    # -1 at the lower limit, 0 at mid-range, 1 at the upper limit
    q2 = q.copy()
    q2[7], q2[8], q2[9] = lo[0], (lo[1] + up[1]) / 2, up[2]
    f.joint.value = q2
    np.testing.assert_allclose(f.error.value[:3], [-1.0, 0.0, 1.0], atol=1e-12)
    np.testing.assert_allclose(f.activation.value[:3], [1.0, 0.0, 1.0])
    f.setThreshold(0.5)
    q2[7] = lo[0] + 0.125 * (up[0] - lo[0])  # error -0.75: halfway from 0.5 to 1
    f.joint.value = q2
    assert f.activation.value[0] == pytest.approx(0.5)
    assert f.getThreshold() == 0.5
    with pytest.raises(CommandError, match=r"setThreshold.*\[0, 1\)"):
        f.setThreshold(1.0)
    f.selec.value = "1"  # DoF 0 is the free flyer's x
    with pytest.raises(SignalTypeError, match=r"DoF 0 \(joint root_joint\) is not a one-DoF"):
        f.error.value  # noqa: B018
    f.selec.value = [False] * 6 + [True]
    f.upperJl.value = model.lowerPositionLimit  # empty ranges
    with pytest.raises(SignalTypeError, match="finite limits with lowerJl < upperJl"):
        f.error.value  # noqa: B018


# -- FeatureVisualPoint ---------------------------------------------------------------
def test_interaction_matrix_against_a_moving_camera():
    """d(x, y)/dt = L (v, w) for a fixed point seen by a camera moving with the LOCAL
    twist (v, w) (x right, y down, z forward)."""
    rng = np.random.default_rng(10)
    for _ in range(5):
        P = np.array([*rng.uniform(-0.5, 0.5, 2), rng.uniform(0.5, 3.0)])  # in the camera
        nu = rng.standard_normal(6)

        def project(h, P=P, nu=nu):
            Pc = pin.exp6(h * nu).actInv(P)  # the camera moved by exp6(h nu)
            return Pc[:2] / Pc[2]

        fd = (project(EPS) - project(-EPS)) / (2 * EPS)
        L = interactionMatrix(P[0] / P[2], P[1] / P[2], P[2])
        np.testing.assert_allclose(L @ nu, fd, atol=1e-6)


@pytest.mark.parametrize("extra", [False, True])
def test_feature_visual_point_against_a_projected_world_point(talos, extra):
    model, dyn = talos
    rng = np.random.default_rng(11 + extra)
    f = FeatureVisualPoint("vp")
    plug(dyn.signal("Jgaze"), f.Jq)
    fMc = OPTICAL_FROM_XFORWARD
    if extra:  # an arbitrary camera mounting
        fMc = fMc * pin.SE3(pin.exp3(0.2 * rng.standard_normal(3)), 0.05 * rng.standard_normal(3))
    f.opticalFrame.value = fMc
    q = random_q(model, rng)
    dyn.position.value = q
    Pw = (dyn.signal("gaze").value * fMc) * np.array([0.2, -0.1, 1.5])  # in front

    def project(qq):
        dyn.position.value = qq
        Pc = (dyn.signal("gaze").value * fMc).actInv(Pw)
        return Pc[:2] / Pc[2], Pc[2]

    xy, Z = project(q)
    f.xy.value = xy
    f.Z.value = Z
    f.xyRef.value = [0.05, -0.02]
    np.testing.assert_allclose(f.error.value, xy - [0.05, -0.02])
    assert_jacobian(f.jacobian.value, lambda qq: project(qq)[0], model, q, rng)
    np.testing.assert_array_equal(f.errordot.value, np.zeros(2))
    f.selec.value = "01"
    np.testing.assert_allclose(f.error.value, [xy[1] + 0.02])
    assert f.jacobian.value.shape == (1, model.nv)


def test_feature_visual_point_reference_feature_and_depth_check():
    f = FeatureVisualPoint("vp")
    fdes = FeatureVisualPoint("vpdes")
    f.xy.value = [0.1, 0.2]
    fdes.xy.value = [0.3, -0.1]
    f.setReference(fdes)
    np.testing.assert_allclose(f.error.value, [-0.2, 0.3])
    f.Z.value = -1.0
    f.Jq.value = np.eye(6)
    with pytest.raises(SignalTypeError, match=r"::Z: expected a positive depth"):
        f.jacobian.value  # noqa: B018
    f.Z.value = 2.0
    np.testing.assert_allclose(f.jacobian.value, interactionMatrix(0.1, 0.2, 2.0))


def test_optical_from_xforward_is_talos_optical_frame(talos):
    """OPTICAL_FROM_XFORWARD is the placement of Talos' rgbd_rgb_optical_frame in its
    rgbd_rgb_frame (the URDF's own optical frame): checked at a random configuration."""
    model, _ = talos
    data = model.createData()
    pin.framesForwardKinematics(model, data, random_q(model, np.random.default_rng(12)))
    f = data.oMf[model.getFrameId("rgbd_rgb_frame")]
    c = data.oMf[model.getFrameId("rgbd_rgb_optical_frame")]
    assert f.actInv(c).isApprox(OPTICAL_FROM_XFORWARD, 1e-9)
