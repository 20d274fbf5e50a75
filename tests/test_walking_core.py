"""The walking core: preview gains, the cart-table tracking, the plan's swing
trajectories and ZMP reference, and the step checks."""

import math

import numpy as np
import pytest

from sotpy.errors import CommandError
from sotpy.walking.plan import Footprint, Sole, StepPlan, checkStep, quintic, solesOverlap
from sotpy.walking.preview import PreviewController, cartTable, previewGains, stateAt

SOLE = Sole(0.205, 0.122, (-0.005, 0.0))


def test_gains_match_jrl_walkgen_reference_values():
    # jrl-walkgen's tests/TestRiccatiEquationWeightsWithoutInitialPose.datref (T = 5 ms,
    # z_c = 0.814 m, g = 9.8, Q = 1, R = 1e-6): Ks = 618.556, then -F_1 = -777.45,
    # -F_2 = -952.24 (it stores -F_j)
    g = previewGains(0.005, 0.814, 1.6, 1.0, 1e-6, 9.8)
    assert g.Ks == pytest.approx(618.556, abs=1e-3)
    assert g.F[0] == pytest.approx(777.45, abs=1e-2)
    assert g.F[1] == pytest.approx(952.24, abs=1e-2)
    assert len(g.F) == 320
    assert abs(g.F[-1]) < 0.01 * g.F[0]  # 1.6 s is enough: the gains have decayed


def test_gains_satisfy_the_riccati_optimality():
    # the state-feedback part is the LQR of the augmented system: perturbing K by
    # any small amount increases the closed loop's cost from a random start
    g = previewGains(0.005, 0.8, 1.6)
    A, B, C = cartTable(0.005, 0.8)
    At = np.zeros((4, 4))
    At[0, 0] = 1
    At[0, 1:] = C @ A
    At[1:, 1:] = A
    Bt = np.concatenate(([C @ B], B))
    K = np.concatenate(([g.Ks], g.Kx))
    Ac = At - np.outer(Bt, K)
    assert np.max(np.abs(np.linalg.eigvals(Ac))) < 1.0  # stable

    def cost(Kp: np.ndarray) -> float:
        x, J = np.array([0.01, 0.02, -0.1, 0.3]), 0.0
        for _ in range(3000):
            u = -Kp @ x
            J += x[0] ** 2 + 1e-6 * u**2
            x = At @ x + Bt * u
        return J

    base = cost(K)
    rng = np.random.default_rng(0)
    for _ in range(4):
        assert cost(K * (1 + 0.05 * rng.standard_normal(4))) > base


def test_cart_table_zmp_tracks_a_footstep_reference():
    # steps of 0.2 m every 0.8 s: the cart-table ZMP C X follows the reference within a
    # few mm away from its jumps, and the CoM ends at the last reference, at rest
    T = 0.005
    g = previewGains(T, 0.8767)
    times = np.arange(0, 8.0 + 1.7, T)
    ref = np.zeros((len(times), 2))
    ref[:, 0] = np.minimum(np.floor(times / 0.8), 6) * 0.2
    ref[:, 1] = np.where((np.floor(times / 0.8) % 2 == 1) & (times < 4.8), 0.085, -0.085)
    ref[times >= 4.8, 1] = 0.0
    ctrl = PreviewController(g, np.zeros((3, 2)))
    n = g.F.size
    zmp = []
    for k in range(round(8.0 / T)):
        zmp.append(ctrl.zmp.copy())
        ctrl.step(ref[k : k + n + 1])
    zmp = np.array(zmp)
    t = times[: len(zmp)]
    phase = (t % 0.8) / 0.8
    quiet = (phase > 0.25) & (phase < 0.9) & (t > 0.8)
    assert np.max(np.abs(zmp[quiet] - ref[: len(zmp)][quiet])) < 0.01
    assert ctrl.state[0] == pytest.approx([1.2, 0.0], abs=2e-3)
    assert np.abs(ctrl.state[1]).max() < 5e-3


def test_state_between_samples_is_the_exact_cubic():
    g = previewGains(0.005, 0.8)
    ctrl = PreviewController(g, np.array([[0.1, 0.0], [0.2, -0.1], [0.5, 1.0]]))
    s0 = ctrl.state.copy()
    u = ctrl.step(np.full((g.F.size + 1, 2), 0.3))
    # the cubic at tau = T is the discrete update
    np.testing.assert_allclose(stateAt(s0, u, 0.005), ctrl.state, atol=1e-15)
    # and its derivative is the velocity row (finite differences)
    h = 1e-6
    d = (stateAt(s0, u, 0.002 + h) - stateAt(s0, u, 0.002 - h)) / (2 * h)
    np.testing.assert_allclose(d[0], stateAt(s0, u, 0.002)[1], atol=1e-8)
    np.testing.assert_allclose(d[1], stateAt(s0, u, 0.002)[2], atol=1e-8)


def test_bad_gain_arguments_are_refused():
    with pytest.raises(CommandError, match="period"):
        previewGains(0.0, 0.8)
    with pytest.raises(CommandError, match="comHeight"):
        previewGains(0.005, float("nan"))


def _plan(steps: int = 3, length: float = 0.2) -> StepPlan:
    feet = {
        "left": Footprint(0.0, 0.085, 0.0, "left"),
        "right": Footprint(0.0, -0.085, 0.0, "right"),
    }
    seq, support = [], feet["right"]
    for i in range(steps):
        side = "left" if support.side == "right" else "right"
        y = 0.17 if side == "left" else -0.17
        f = Footprint(support.x + (length if i < steps - 1 else 0.0), support.y + y, 0.1 * i, side)
        seq.append(f)
        support = f
    return StepPlan(feet, seq, 0.78, 0.02, 1.0, 1.0, 0.05, SOLE)


def test_swing_is_c2_with_zero_velocity_and_acceleration_at_its_ends():
    plan = _plan()
    p = next(ph for ph in plan.phases if ph.swing is not None)
    side = p.swing[1].side
    h = 1e-5

    def pos(t):
        q, yaw, _ = plan.feet(t)[side]
        return np.append(q, yaw)

    # the reported velocity is the time derivative (finite differences), inside the swing
    for s in (0.1, 0.33, 0.5, 0.8):
        t = p.start + s * (p.end - p.start)
        fd = (pos(t + h) - pos(t - h)) / (2 * h)
        np.testing.assert_allclose(plan.feet(t)[side][2], fd, atol=1e-6)
    # at both ends: position continuous, velocity and acceleration zero
    for t in (p.start, p.end):
        acc = (pos(t + h) - 2 * pos(t) + pos(t - h)) / h**2
        vel = (pos(t + h) - pos(t - h)) / (2 * h)
        assert np.abs(vel).max() < 1e-6
        assert np.abs(acc).max() < 1e-2
    assert pos(p.start + 0.5 * (p.end - p.start))[2] == pytest.approx(0.05)
    assert quintic(0.5)[0] == pytest.approx(0.5)


def test_zmp_reference_is_in_the_support_foot_and_plan_distance():
    plan = _plan(steps=4)
    for ph in plan.phases:
        if ph.support is not None:
            t = (ph.start + ph.end) / 2
            centre = ph.feet[ph.support].point(np.asarray(SOLE.offset))
            np.testing.assert_allclose(plan.zmpAt(t), centre, atol=1e-12)
            assert plan.contactPhase(t) == (1 if ph.support == "left" else -1)
            assert plan.supportPolygon(t).shape == (4, 2)
    assert plan.contactPhase(0.5) == 0
    assert plan.supportPolygon(0.5).shape == (8, 2)
    assert plan.final["left"].x == pytest.approx(0.6)
    assert plan.duration == pytest.approx(1.0 + 4 * 0.78 + 3 * 0.02 + 1.0)


def test_step_checks_refuse_what_the_robot_cannot_take():
    right = Footprint(0.0, -0.085, 0.0, "right")
    checkStep("pg", right, Footprint(0.2, 0.085, 0.0, "left"), SOLE, 0.705)
    with pytest.raises(CommandError, match="crosses or overlaps"):
        checkStep("pg", right, Footprint(0.2, -0.2, 0.0, "left"), SOLE, 0.705)
    with pytest.raises(CommandError, match="crosses or overlaps"):
        checkStep("pg", right, Footprint(0.05, 0.0, 0.0, "left"), SOLE, 0.705)
    with pytest.raises(CommandError, match="longer than the leg"):
        checkStep("pg", right, Footprint(0.8, 0.085, 0.0, "left"), SOLE, 0.705)
    with pytest.raises(CommandError, match="two steps in a row"):
        checkStep("pg", right, Footprint(0.2, -0.3, 0.0, "right"), SOLE, 0.705)
    # the overlap test against a direct sampling of the two rectangles
    a = Footprint(0.0, 0.0, 0.0, "left")
    for b, expected in (
        (Footprint(0.0, 0.121, 0.0, "right"), True),
        (Footprint(0.0, 0.123, 0.0, "right"), False),
        (Footprint(0.15, 0.1, math.pi / 4, "right"), None),
    ):
        got = solesOverlap(a, b, SOLE)
        if expected is None:
            g = np.stack(
                np.meshgrid(np.linspace(-0.1075, 0.0975, 60), np.linspace(-0.061, 0.061, 40)), -1
            ).reshape(-1, 2)
            inside = b.rotation().T @ (a.point(g) - (b.x, b.y)).T
            off = np.asarray(SOLE.offset)[:, None]
            hit = np.any((np.abs(inside - off)[0] <= 0.1025) & (np.abs(inside - off)[1] <= 0.061))
            assert got == hit
        else:
            assert got is expected
