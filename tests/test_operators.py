"""SoT operator entities (sotpy.operators): each against a hand computation.

Vector and SE(3) operators against numpy and Pinocchio, the derivator against finite
differences, the integrator against the closed form of its Euler steps, switches,
latches; size and range errors that name the entity, the signal and what was expected;
and the tick semantics of the time-dependent ones (once per tick, skipped ticks,
recomputation within a tick, compiled plans).
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

import sotpy.graph
from sotpy.errors import (
    CommandError,
    CycleError,
    SignalTypeError,
    SotpyError,
    UnpluggedError,
)
from sotpy.graph import INT, VECTOR, Entity, Input, Output, Plan, factory, plug, pool
from sotpy.operators import (
    Add_of_double,
    Add_of_matrix,
    Add_of_vector,
    Component_of_vector,
    Compose_R_and_T,
    Delay_of_vector,
    Derivator_of_double,
    Derivator_of_Matrix,
    Derivator_of_Vector,
    HomoToMatrix,
    Integrator,
    Inverse_of_matrixHomo,
    JointLimitator,
    Latch,
    MatrixConstant,
    MatrixHomoToPose,
    MatrixHomoToPoseUTheta,
    MatrixToHomo,
    Multiply_double_vector,
    Multiply_matrix_vector,
    Multiply_matrixHomo_vector,
    Multiply_of_double,
    Multiply_of_matrixHomo,
    OpPointModifier,
    PoseUThetaToMatrixHomo,
    Selec_of_vector,
    Stack_of_vector,
    Substract_of_matrix,
    Substract_of_vector,
    SwitchBoolean,
    SwitchMatrixHomogeneous,
    SwitchVector,
    VectorConstant,
)

RNG = np.random.default_rng(20240611)


def random_se3(rng: np.random.Generator = RNG) -> pin.SE3:
    """A placement drawn with numpy's seeded generator (pin.SE3.Random is not seeded)."""
    return pin.exp6(rng.uniform(-1.5, 1.5, 6))


class OperatorsClock(Entity):
    """Test source: ``sout(t) = f(t)`` for a Python function ``f`` of the tick."""

    def __init__(self, name: str) -> None:
        self.f = lambda t: np.array([float(t)])
        self.calls = 0

    @Output(VECTOR, withTime=True)
    def sout(self, t: int) -> np.ndarray:
        self.calls += 1
        return np.asarray(self.f(t), dtype=float)


class OperatorsArgmax(Entity):
    """Test helper: ``sout = argmax(sin)`` (an int computed from a vector)."""

    sin = Input(VECTOR)

    @Output(INT, deps=("sin",))
    def sout(self, x: np.ndarray) -> int:
        return int(np.argmax(x))


# -- vector operators ---------------------------------------------------------------------
def test_selec_of_vector_half_open_segments_and_fresh_output():
    s = Selec_of_vector("s")
    x = np.arange(10.0)
    s.sin.value = x
    s.selec(2, 5)
    out = s.sout.value
    np.testing.assert_array_equal(out, [2.0, 3.0, 4.0])  # [imin, imax): 5 excluded
    assert not np.shares_memory(out, s.sin.value)
    s.addSelec(7, 9)
    np.testing.assert_array_equal(s.sout.value, [2.0, 3.0, 4.0, 7.0, 8.0])
    s.selec(0, 0)  # an empty selection is explicit and allowed
    assert s.sout.value.shape == (0,)


def test_selec_of_vector_errors_name_the_signal():
    s = Selec_of_vector("s")
    s.sin.value = np.arange(4.0)
    with pytest.raises(SotpyError, match=r"Selec_of_vector\(s\)::output.*selec\(imin, imax\)"):
        s.sout.value  # noqa: B018 - no selection yet
    s.selec(2, 6)
    with pytest.raises(SignalTypeError) as exc:
        s.sout.value  # noqa: B018
    msg = str(exc.value)
    assert "Selec_of_vector(s)::input(vector)::sin" in msg
    assert "[2, 6)" in msg and "size >= 6" in msg and "size 4" in msg
    with pytest.raises(CommandError, match=r"Selec_of_vector\(s\)\.selec.*imin = 3, imax = 1"):
        s.selec(3, 1)
    with pytest.raises(CommandError):
        s.addSelec(-1, 2)


def test_component_of_vector():
    c = Component_of_vector("c")
    c.sin.value = [1.0, -2.5, 4.0]
    with pytest.raises(SotpyError, match="setIndex"):
        c.sout.value  # noqa: B018
    c.setIndex(1)
    assert c.sout.value == -2.5 and isinstance(c.sout.value, float)
    c.setIndex(3)
    with pytest.raises(SignalTypeError, match=r"Component_of_vector\(c\)::input.*index 3"):
        c.sout.value  # noqa: B018
    with pytest.raises(CommandError, match="index >= 0"):
        c.setIndex(-1)


def test_stack_of_vector_whole_inputs_then_segments():
    st = Stack_of_vector("st")
    a, b = RNG.normal(size=4), RNG.normal(size=3)
    st.sin1.value, st.sin2.value = a, b
    np.testing.assert_array_equal(st.sout.value, np.r_[a, b])
    st.selec1(1, 3)
    st.selec2(0, 2)
    np.testing.assert_array_equal(st.sout.value, np.r_[a[1:3], b[0:2]])
    st.selec2(1, 5)
    with pytest.raises(SignalTypeError, match=r"::input\(vector\)::sin2: selec2\(1, 5\).*size 3"):
        st.sout.value  # noqa: B018


def test_add_of_vector_weighted_sum_and_signal_number():
    add = Add_of_vector("add")
    assert add.getSignalNumber() == 2 and add.n_sin == 2
    xs = [RNG.normal(size=5) for _ in range(3)]
    add.sin0.value, add.sin1.value = xs[0], xs[1]
    np.testing.assert_allclose(add.sout.value, xs[0] + xs[1])
    add.coeffs = [2.0, -0.5]  # sot-core's property
    np.testing.assert_allclose(add.sout.value, 2.0 * xs[0] - 0.5 * xs[1])
    add.setSignalNumber(3)
    np.testing.assert_array_equal(add.coeffs, [2.0, -0.5, 1.0])  # kept, new one is 1
    with pytest.raises(UnpluggedError, match=r"Add_of_vector\(add\)::input\(vector\)::sin2"):
        add.sout.value  # noqa: B018
    add.sin(2).value = xs[2]
    assert add.sin(2) is add.sin2 is add.signal("sin2")
    np.testing.assert_allclose(add.sout.value, 2.0 * xs[0] - 0.5 * xs[1] + xs[2])
    add.setCoeffs(np.array([1.0, 1.0, -3.0]))
    np.testing.assert_allclose(add.sout.value, xs[0] + xs[1] - 3.0 * xs[2])
    with pytest.raises(CommandError, match=r"setCoeffs: expected 3 coefficients"):
        add.coeffs = [1.0, 2.0]
    with pytest.raises(CommandError, match=r"sin: expected an input index in 0\.\.2"):
        add.sin(3)
    with pytest.raises(CommandError, match="setSignalNumber"):
        add.setSignalNumber(-1)


def test_add_of_vector_refuses_mismatched_sizes_instead_of_broadcasting():
    add = Add_of_vector("add")
    add.sin0.value = [1.0, 2.0, 3.0]
    add.sin1.value = [1.0]  # numpy would broadcast this
    with pytest.raises(SignalTypeError) as exc:
        add.sout.value  # noqa: B018
    msg = str(exc.value)
    assert "Add_of_vector(add)::input(vector)::sin1" in msg
    assert "size 3 (the size of sin0)" in msg and "received size 1" in msg


def test_add_removing_inputs_unplugs_them():
    src = VectorConstant("src")
    src.set([1.0, 1.0])
    add = Add_of_vector("add")
    add.setSignalNumber(3)
    for i in range(3):
        plug(src.sout, add.sin(i))
    np.testing.assert_allclose(add.sout.value, [3.0, 3.0])
    add.n_sin = 1
    assert not add.hasSignal("sin1") and not add.hasSignal("sin2")
    assert src.sout._dependants == [add.sin0]  # the removed inputs were unplugged
    np.testing.assert_allclose(add.sout.value, [1.0, 1.0])
    add.setSignalNumber(0)
    with pytest.raises(SotpyError, match="no input"):
        add.sout.value  # noqa: B018


def test_add_of_double_and_matrix():
    ad = Add_of_double("ad")
    ad.sin0.value, ad.sin1.value = 1.5, -4.0
    ad.coeffs = [2.0, 0.5]
    assert ad.sout.value == pytest.approx(1.0)
    am = Add_of_matrix("am")
    A, B = RNG.normal(size=(2, 3)), RNG.normal(size=(2, 3))
    am.sin0.value, am.sin1.value = A, B
    np.testing.assert_allclose(am.sout.value, A + B)
    am.sin1.value = RNG.normal(size=(3, 2))
    with pytest.raises(SignalTypeError, match=r"sin1: expected a 2 x 3 matrix \(the shape of sin0"):
        am.sout.value  # noqa: B018


def test_substract_and_products():
    sub = Substract_of_vector("sub")
    a, b = RNG.normal(size=4), RNG.normal(size=4)
    sub.sin1.value, sub.sin2.value = a, b
    np.testing.assert_allclose(sub.sout.value, a - b)
    sub.sin2.value = [1.0]
    with pytest.raises(SignalTypeError, match=r"sin2: expected a vector of size 4"):
        sub.sout.value  # noqa: B018
    subm = Substract_of_matrix("subm")
    subm.sin1.value, subm.sin2.value = np.eye(2), np.ones((2, 2))
    np.testing.assert_allclose(subm.sout.value, np.eye(2) - 1.0)

    mv = Multiply_matrix_vector("mv")
    A, x = RNG.normal(size=(3, 4)), RNG.normal(size=4)
    mv.sin1.value, mv.sin2.value = A, x
    expected = [sum(A[i, j] * x[j] for j in range(4)) for i in range(3)]
    np.testing.assert_allclose(mv.sout.value, expected)
    mv.sin2.value = RNG.normal(size=3)
    with pytest.raises(SignalTypeError, match=r"sin2: .*size 4 \(the number of columns of sin1"):
        mv.sout.value  # noqa: B018

    dv = Multiply_double_vector("dv")
    dv.sin1.value, dv.sin2.value = -2.0, [1.0, 0.5]
    np.testing.assert_allclose(dv.sout.value, [-2.0, -1.0])


def test_vector_constant_set_resize_and_push_invalidation():
    vc = VectorConstant("vc")
    with pytest.raises(SotpyError, match=r"VectorConstant\(vc\)::output.*set\(vector\)"):
        vc.sout.value  # noqa: B018
    vc.resize(3)
    np.testing.assert_array_equal(vc.sout.value, np.zeros(3))
    sub = Substract_of_vector("sub")
    plug(vc.sout, sub.sin1)
    sub.sin2.value = [1.0, 1.0, 1.0]
    np.testing.assert_array_equal(sub.sout.value, [-1.0, -1.0, -1.0])
    vc.set([4.0, 5.0, 6.0])  # same tick: the dependant sees it at once
    np.testing.assert_array_equal(sub.sout.value, [3.0, 4.0, 5.0])
    with pytest.raises(CommandError):
        vc.set([1.0, float("nan")])


# -- SE(3) operators ------------------------------------------------------------------
def test_multiply_of_matrix_homo_is_the_homogeneous_product():
    mul = Multiply_of_matrixHomo("mul")
    mul.setSignalNumber(3)
    Ms = [random_se3() for _ in range(3)]
    for i, M in enumerate(Ms):
        mul.sin(i).value = M
    expected = Ms[0].homogeneous @ Ms[1].homogeneous @ Ms[2].homogeneous
    np.testing.assert_allclose(mul.sout.value.homogeneous, expected, atol=1e-12)
    mul.setSignalNumber(0)
    assert mul.sout.value.isIdentity()


def test_inverse_pose_utheta_and_translation():
    M = random_se3()
    inv = Inverse_of_matrixHomo("inv")
    inv.sin.value = M
    np.testing.assert_allclose(inv.sout.value.homogeneous, np.linalg.inv(M.homogeneous), atol=1e-12)

    put = MatrixHomoToPoseUTheta("put")
    put.sin.value = M
    x = put.sout.value
    np.testing.assert_allclose(x[:3], M.homogeneous[:3, 3])
    R, u = M.rotation, x[3:]
    theta = np.linalg.norm(u)
    assert theta == pytest.approx(np.arccos((np.trace(R) - 1.0) / 2.0))  # the angle
    np.testing.assert_allclose(R @ u, u, atol=1e-12)  # the axis is fixed by R
    skew = (R - R.T) / (2.0 * np.sin(theta))  # Rodrigues: [u/theta]_x
    np.testing.assert_allclose([skew[2, 1], skew[0, 2], skew[1, 0]], u / theta, atol=1e-10)

    back = PoseUThetaToMatrixHomo("back")
    plug(put.sout, back.sin)
    np.testing.assert_allclose(back.sout.value.homogeneous, M.homogeneous, atol=1e-12)
    back.sin.value = np.zeros(5)
    with pytest.raises(SignalTypeError, match=r"PoseUThetaToMatrixHomo\(back\)::input.*size 6"):
        back.sout.value  # noqa: B018

    pose = MatrixHomoToPose("pose")
    pose.sin.value = M
    out = pose.sout.value
    np.testing.assert_array_equal(out, M.homogeneous[:3, 3])
    out[0] += 1.0  # a fresh array: the input is untouched
    assert pose.sin.value.translation[0] == M.translation[0]


def test_compose_r_and_t_checks_the_rotation():
    M = random_se3()
    comp = Compose_R_and_T("comp")
    comp.sin1.value, comp.sin2.value = M.rotation, M.translation
    assert comp.sout.value.isApprox(M, 1e-12)
    comp.sin1.value = 2.0 * np.eye(3)
    with pytest.raises(SignalTypeError, match=r"Compose_R_and_T\(comp\)::input\(matrix\)::sin1"):
        comp.sout.value  # noqa: B018
    comp.sin1.value = np.diag([1.0, 1.0, -1.0])  # orthogonal, but a reflection
    with pytest.raises(SignalTypeError, match="det R"):
        comp.sout.value  # noqa: B018
    comp.sin1.value, comp.sin2.value = M.rotation, [1.0, 2.0]
    with pytest.raises(SignalTypeError, match=r"sin2: expected a vector of size 3"):
        comp.sout.value  # noqa: B018


def test_homogeneous_matrix_round_trip_and_checks():
    M = random_se3()
    h2m, m2h = HomoToMatrix("h2m"), MatrixToHomo("m2h")
    h2m.sin.value = M
    plug(h2m.sout, m2h.sin)
    np.testing.assert_array_equal(h2m.sout.value, M.homogeneous)
    assert m2h.sout.value.isApprox(M, 1e-12)
    bad = M.homogeneous.copy()
    bad[3] = [0.0, 0.0, 1.0, 1.0]
    m2h.sin.value = bad
    with pytest.raises(SignalTypeError, match=r"MatrixToHomo\(m2h\)::input.*last row"):
        m2h.sout.value  # noqa: B018
    m2h.sin.value = np.eye(3)
    with pytest.raises(SignalTypeError, match="expected a 4 x 4 matrix"):
        m2h.sout.value  # noqa: B018
    # 6 significant digits are accepted and projected to an exact rotation
    m2h.sin.value = np.round(M.homogeneous, 6)
    R = m2h.sout.value.rotation
    np.testing.assert_allclose(R.T @ R, np.eye(3), atol=1e-14)
    np.testing.assert_allclose(R, M.rotation, atol=2e-6)


def test_multiply_matrix_homo_vector_points_and_homogeneous_coordinates():
    M = random_se3()
    op = Multiply_matrixHomo_vector("op")
    op.sin1.value = M
    p = RNG.normal(size=3)
    op.sin2.value = p
    np.testing.assert_allclose(op.sout.value, M.rotation @ p + M.translation)
    op.sin2.value = np.r_[p, 0.0]  # a direction: no translation
    np.testing.assert_allclose(op.sout.value, np.r_[M.rotation @ p, 0.0])
    op.sin2.value = np.zeros(5)
    with pytest.raises(SignalTypeError, match=r"size 3.*size 4"):
        op.sout.value  # noqa: B018


# -- derivator ------------------------------------------------------------------------
def test_derivator_is_a_finite_difference_per_tick():
    clock = OperatorsClock("clock")
    clock.f = lambda t: np.array([np.sin(0.1 * t), t * t])
    der = Derivator_of_Vector("der")
    plug(clock.sout, der.sin)
    der.dt.value = 0.01
    np.testing.assert_array_equal(der.sout(0), [0.0, 0.0])  # SoT: zero the first time
    for t in range(1, 6):
        expected = (clock.f(t) - clock.f(t - 1)) / 0.01
        np.testing.assert_allclose(der.sout(t), expected)
        np.testing.assert_allclose(der.sout(t), expected)  # a second read: same value
        assert clock.calls == t + 1  # the input was computed once per tick


def test_derivator_skipped_ticks_and_recompute_within_a_tick():
    clock = OperatorsClock("clock")
    clock.f = lambda t: np.array([3.0 * t])
    der = Derivator_of_Vector("der")
    plug(clock.sout, der.sin)
    der.sout(0)
    np.testing.assert_allclose(der.sout(1), [3.0])  # dt = 1 by default: per tick
    np.testing.assert_allclose(der.sout(4), [3.0])  # ticks 2 and 3 skipped: /3
    der.dt.value = 0.5  # at tick 4: recomputed against tick 1, not against itself
    np.testing.assert_allclose(der.sout(4), [6.0])
    np.testing.assert_allclose(der.sout(5), [6.0])
    clock.f = lambda t: np.zeros(2)
    with pytest.raises(SignalTypeError, match=r"Derivator_of_Vector\(der\)::input.*changed shape"):
        der.sout(6)
    der.dt.value = 0.0
    with pytest.raises(SignalTypeError, match=r"::dt: expected a time step > 0"):
        der.sout(7)


def test_derivator_double_and_matrix_against_analytic_derivative():
    h = 1e-4
    d = Derivator_of_double("d")
    dm = Derivator_of_Matrix("dm")
    d.dt.value = dm.dt.value = h
    for t in range(3):
        d.sin.value = float(np.exp(t * h))
        dm.sin.value = np.array([[np.cos(t * h), t * h], [1.0, 2.0]])
        pool.time = t
        vd, vm = d.sout(t), dm.sout(t)
    assert vd == pytest.approx(np.exp(2 * h), rel=1e-4)  # d/dx exp = exp
    np.testing.assert_allclose(vm, [[-np.sin(2 * h), 1.0], [0.0, 0.0]], atol=1e-4)
    d.reset()
    assert d.sout(2) == 0.0  # forgotten: zero again, as at creation


# -- integrator -----------------------------------------------------------------------
def test_integrator_euclidean_closed_form():
    clock = OperatorsClock("clock")
    clock.f = lambda t: np.array([1.0, -2.0]) * t  # v(t) = t * c
    integ = Integrator("integ")
    plug(clock.sout, integ.velocity)
    with pytest.raises(UnpluggedError, match=r"Integrator\(integ\)::input\(double\)::dt"):
        integ.configuration(0)
    integ.dt.value = 0.1
    integ.setInitialConfig([1.0, 1.0])
    np.testing.assert_allclose(integ.configuration(0), [1.0, 1.0])
    for t in range(1, 6):
        # q(t) = q0 + dt * sum_{k=1..t} k c  (rectangle rule on the current velocity)
        expected = np.array([1.0, 1.0]) + 0.1 * t * (t + 1) / 2 * np.array([1.0, -2.0])
        np.testing.assert_allclose(integ.configuration(t), expected)
        np.testing.assert_allclose(integ.configuration(t), expected)  # once per tick
    # a gap of 3 ticks: v(8) held over it
    expected = expected + 3 * 0.1 * 8 * np.array([1.0, -2.0])
    np.testing.assert_allclose(integ.configuration(8), expected)
    # recomputed within a tick (dt changed): from tick 5 again, not from tick 8
    integ.dt.value = 0.2
    np.testing.assert_allclose(
        integ.configuration(8), expected + 3 * 0.1 * 8 * np.array([1.0, -2.0])
    )
    integ.setInitialConfig([0.0, 0.0, 0.0])
    with pytest.raises(SignalTypeError, match=r"velocity: expected a vector of size 3"):
        integ.configuration(9)


def test_integrator_on_a_free_flyer_model_matches_pinocchio_integrate():
    model = pin.Model()
    ff = model.addJoint(0, pin.JointModelFreeFlyer(), pin.SE3.Identity(), "base")
    model.addJoint(ff, pin.JointModelRZ(), pin.SE3.Identity(), "yaw")
    integ = Integrator("integ")
    integ.setModel(model)
    integ.dt.value = 0.05
    v = RNG.normal(size=model.nv)
    integ.velocity.value = v
    q = pin.neutral(model)
    np.testing.assert_allclose(integ.configuration(0), q)
    for t in range(1, 4):
        q = pin.integrate(model, q, 0.05 * v)
        np.testing.assert_allclose(integ.configuration(t), q, atol=1e-12)
    assert pin.isNormalized(model, integ.configuration(3), 1e-12)
    integ.velocity.value = np.zeros(model.nq)
    with pytest.raises(SignalTypeError, match=r"velocity: expected a vector of size 7 \(the model"):
        integ.configuration(4)
    with pytest.raises(CommandError, match="size nq = 8"):
        integ.setInitialConfig(np.zeros(7))
    with pytest.raises(CommandError, match="not normalised"):
        integ.setInitialConfig(np.zeros(8))


def test_integrator_loop_through_a_delay_is_explicit_euler():
    # q' = -k q: the direct loop is refused, the loop through a Delay gives
    # q(t) = (1 - k dt)^t q0 (explicit Euler).
    integ = Integrator("integ")
    gain = Multiply_double_vector("gain")
    gain.sin1.value = -2.0
    plug(integ.configuration, gain.sin2)
    with pytest.raises(CycleError):
        plug(gain.sout, integ.velocity)
    delay = Delay_of_vector("delay")
    delay.setInitialValue(np.zeros(2))
    plug(gain.sout, delay.sin)
    plug(delay.sout, integ.velocity)
    integ.dt.value = 0.1
    q0 = np.array([1.0, -3.0])
    integ.setInitialConfig(q0)
    plan = Plan([integ.configuration])
    for t in range(0, 8):
        plan.run(t)
        expected = q0 * (1.0 - 2.0 * 0.1) ** t  # q(t) = q(t-1) + dt v(t-1)
        np.testing.assert_allclose(integ.configuration.value, expected)


# -- switches and latch ---------------------------------------------------------------
def test_switch_vector_selection_and_bool_selection():
    sw = SwitchVector("sw")
    a, b = np.array([1.0, 2.0]), np.array([3.0, 4.0])
    sw.sin0.value, sw.sin1.value = a, b
    with pytest.raises(UnpluggedError, match=r"SwitchVector\(sw\)::input\(int\)::selection"):
        sw.sout.value  # noqa: B018
    sw.boolSelection.value = True
    np.testing.assert_array_equal(sw.sout.value, b)
    sw.boolSelection.value = False
    np.testing.assert_array_equal(sw.sout.value, a)
    sw.selection.value = 1  # selection, when set, wins over boolSelection (SoT's rule)
    np.testing.assert_array_equal(sw.sout.value, b)
    out = sw.sout.value
    assert not np.shares_memory(out, sw.sin1.value)
    sw.selection.unplug()
    np.testing.assert_array_equal(sw.sout.value, a)
    sw.setSignalNumber(3)
    sw.sin2.value = [5.0, 6.0]
    sw.selection.value = 2
    np.testing.assert_array_equal(sw.sout.value, [5.0, 6.0])
    sw.selection.value = 3
    with pytest.raises(SignalTypeError) as exc:
        sw.sout.value  # noqa: B018
    msg = str(exc.value)
    assert "SwitchVector(sw)::input(int)::selection" in msg and "out of range" in msg
    assert "3 inputs" in msg


def test_switch_selection_plugged_and_cycle_refused():
    sw = SwitchVector("sw")
    sw.sin0.value, sw.sin1.value = [0.0, 9.0], [7.0, 1.0]
    arg = OperatorsArgmax("arg")
    arg.sin.value = [0.0, 5.0]
    plug(arg.sout, sw.selection)
    np.testing.assert_array_equal(sw.sout.value, [7.0, 1.0])
    arg.sin.value = [5.0, 0.0]
    np.testing.assert_array_equal(sw.sout.value, [0.0, 9.0])
    # selection computed from sout itself: a same-tick cycle, refused; selection unset
    sw.selection.unplug()
    sw.boolSelection.value = False
    arg2 = OperatorsArgmax("arg2")
    plug(sw.sout, arg2.sin)
    with pytest.raises(CycleError):
        plug(arg2.sout, sw.selection)
    assert not sw.selection.isPlugged
    np.testing.assert_array_equal(sw.sout.value, [0.0, 9.0])  # boolSelection still used


def test_switch_boolean_and_matrix_homogeneous():
    sb = SwitchBoolean("sb")
    sb.sin0.value, sb.sin1.value = False, True
    sb.boolSelection.value = True
    assert sb.sout.value is True
    sm = SwitchMatrixHomogeneous("sm")
    M0, M1 = random_se3(), random_se3()
    sm.sin0.value, sm.sin1.value = M0, M1
    sm.selection.value = 0
    assert sm.sout.value.isApprox(M0, 0.0)
    sm.selection.value = -1
    with pytest.raises(SignalTypeError, match="out of range"):
        sm.sout.value  # noqa: B018


def test_latch():
    latch = Latch("latch")
    assert latch.out.value is False
    latch.turnOn()
    assert latch.out.value is True  # at once, in the same tick
    pool.time = 3
    assert latch.out(3) is True  # held
    latch.turnOff()
    assert latch.out.value is False
    assert latch.turnOnSout(4) is True
    assert latch.out(4) is True
    assert latch.turnOffSout(5) is False
    assert latch.out(5) is False


# -- names, factory, plans ------------------------------------------------------------
def test_sot_names_in_the_factory_and_delays_reexported():
    import sotpy.operators as ops

    for name in ops.__all__:
        obj = getattr(ops, name)
        if isinstance(obj, type) and issubclass(obj, Entity):
            assert factory.getClass(name) is obj
    assert ops.Delay_of_vector is sotpy.graph.Delay_of_vector
    e = factory.create("Selec_of_vector", "viaFactory")
    assert e.sin.name == "Selec_of_vector(viaFactory)::input(vector)::sin"
    assert factory.create("Add_of_vector", "a2").sin1.name.endswith("::input(vector)::sin1")


def test_a_plan_over_operators_gives_the_lazy_values():
    clock = OperatorsClock("clock")
    clock.f = lambda t: np.array([t, 2.0 * t, t * t])
    sel = Selec_of_vector("sel")
    sel.selec(1, 3)
    plug(clock.sout, sel.sin)
    der = Derivator_of_Vector("der")
    plug(sel.sout, der.sin)
    add = Add_of_vector("add")
    plug(der.sout, add.sin0)
    add.sin1.value = [10.0, 10.0]
    plan = Plan([add.sout])
    plan.run(0)
    for t in range(1, 5):
        plan.run(t)
        np.testing.assert_allclose(add.sout.value, [2.0 + 10.0, 2.0 * t - 1.0 + 10.0])
    assert clock.calls == 5


# -- OpPointModifier, JointLimitator, Multiply_of_double, MatrixConstant -----------------
def _talos_dynamic():
    from sotpy.dynamics import Dynamic, load_model

    model = load_model("talos")[0]
    dyn = Dynamic("dyn", model)
    dyn.createOpPoint("rh", "arm_right_7_joint")
    dyn.createJacobian("Jrh_world", "arm_right_7_joint", "local_world_aligned")
    rng = np.random.default_rng(11)
    q = pin.integrate(model, pin.neutral(model), rng.uniform(-0.4, 0.4, model.nv))
    dyn.position.value = q
    return model, dyn, q


def test_op_point_modifier_position_and_jacobians_against_finite_differences():
    model, dyn, q = _talos_dynamic()
    aMb = random_se3()
    m = OpPointModifier("m")
    plug(dyn.signal("rh"), m.positionIN)
    plug(dyn.signal("Jrh"), m.jacobianIN)
    m.setTransformation(tuple(map(tuple, aMb.homogeneous)))  # SoT's tuple of rows
    np.testing.assert_allclose(m.getTransformation(), aMb.homogeneous, atol=1e-15)
    oMb = dyn.signal("rh").value * aMb
    assert m.position.value.isApprox(oMb, 1e-12)
    # LOCAL Jacobian of b: log6(oMb(q)^-1 oMb(q + eps v)) / eps = J v
    v = np.random.default_rng(12).standard_normal(model.nv)
    J = m.jacobian.value
    eps = 1e-6
    dyn.position.value = pin.integrate(model, q, eps * v)
    fd = pin.log6(oMb.actInv(m.position.value)).vector / eps
    np.testing.assert_allclose(J @ v, fd, atol=1e-4)
    # world-aligned mode: the velocity of b's origin in world axes, and the angular one
    dyn.position.value = q
    m.setEndEffector(False)
    assert not m.getEndEffector()
    plug(dyn.signal("Jrh_world"), m.jacobianIN)
    Jw = m.jacobian.value
    dyn.position.value = pin.integrate(model, q, eps * v)
    p1 = m.position.value.translation
    dyn.position.value = pin.integrate(model, q, -eps * v)
    p0 = m.position.value.translation
    np.testing.assert_allclose(Jw[:3] @ v, (p1 - p0) / (2 * eps), atol=1e-5)
    with pytest.raises(CommandError, match=r"OpPointModifier\(m\)\.setTransformation"):
        m.setTransformation(np.diag([1.0, 2.0, 1.0, 1.0]))
    np.testing.assert_allclose(m.getTransformation(), aMb.homogeneous, atol=1e-15)


def test_joint_limitator_stops_a_joint_at_its_limit_one_period_ahead():
    model, dyn, q = _talos_dynamic()
    jl = JointLimitator("jl")
    plug(dyn.position, jl.joint)  # an input following an input: its model is found
    plug(dyn.upperJl, jl.upperJl)
    plug(dyn.lowerJl, jl.lowerJl)
    elbow = model.joints[model.getJointId("arm_right_4_joint")]
    u = np.zeros(model.nv)
    room = model.upperPositionLimit[elbow.idx_q] - q[elbow.idx_q]
    u[elbow.idx_v] = 0.9 * room / 0.005  # stays inside in 5 ms: kept
    u[:6] = 1.0  # the free flyer's components pass
    jl.controlIN.value = u
    np.testing.assert_array_equal(jl.control.value, u)
    u[elbow.idx_v] = 1.1 * room / 0.005  # would cross: stopped
    jl.controlIN.value = u
    out = jl.control.value
    assert out[elbow.idx_v] == 0.0 and out[:6].tolist() == [1.0] * 6
    jl.dt.value = 0.001  # a shorter prediction keeps it
    assert jl.control.value[elbow.idx_v] == u[elbow.idx_v]
    np.testing.assert_allclose(
        jl.widthJl.value, model.upperPositionLimit - model.lowerPositionLimit
    )
    bare = JointLimitator("bare")  # no model to find: q and the control must match
    bare.joint.value = q
    bare.upperJl.value = model.upperPositionLimit
    bare.lowerJl.value = model.lowerPositionLimit
    bare.controlIN.value = u
    with pytest.raises(SignalTypeError, match=r"JointLimitator\(bare\)\.control.*model"):
        _ = bare.control.value


def test_multiply_of_double_and_matrix_constant():
    p = Multiply_of_double("p")
    p.setSignalNumber(3)
    for i, x in enumerate((2.0, -1.5, 4.0)):
        p.sin(i).value = x
    assert p.sout.value == pytest.approx(-12.0)
    c = MatrixConstant("c")
    with pytest.raises(SotpyError, match=r"MatrixConstant\(c\)::output\(matrix\)::sout"):
        _ = c.sout.value
    c.resize(2, 3)
    np.testing.assert_array_equal(c.sout.value, np.zeros((2, 3)))
    c.set(((1.0, 2.0), (3.0, 4.0)))
    np.testing.assert_array_equal(c.sout.value, [[1.0, 2.0], [3.0, 4.0]])
