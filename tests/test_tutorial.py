"""The inverted-pendulum tutorial: physics against independent derivations, the SoT
display and help strings, bad input, the closed loop, and the ``sotpy`` CLI."""

import contextlib
import io
import re
import shlex
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from sotpy.cli import main
from sotpy.errors import CommandError, SimulationError, SotpyError
from sotpy.graph import Entity, plug, pool
from sotpy.tutorial import (
    SOT_TUTORIAL_GAIN,
    FeedbackController,
    InvertedPendulum,
    integrationStep,
    linearisedModel,
    longestStep,
    lqrGain,
    run_pendulum,
    stateDerivative,
)

G = 9.81
LAM = 0.1  # the C++ model's viscosity
PARAMS = [(1.0, 1.0, 1.0), (2.0, 0.5, 0.7), (0.3, 1.7, 2.5)]  # cart kg, pendulum kg, m


# -- independent references ------------------------------------------------------------
# The C++ model (dynamic-graph-tutorial's InvertedPendulum): the mass m sits at
# (x - l sin th, l cos th), so theta > 0 leans towards -x; a viscous force -lam x_dot on
# the cart and a viscous torque -lam th_dot at the hinge.
def energy(s, M, m, ell, g=G):
    """Cart KE + pendulum KE + PE, from the Cartesian velocity of the point mass."""
    _, th, xd, thd = s
    vx = xd - ell * np.cos(th) * thd
    vy = -ell * np.sin(th) * thd
    return 0.5 * M * xd**2 + 0.5 * m * (vx**2 + vy**2) + m * g * ell * np.cos(th)


def lagrangian(q, qd, M, m, ell, g=G):
    """L = T - V written from positions, without the equations of motion."""
    _, th = q
    xd, thd = qd
    px_dot = xd - ell * np.cos(th) * thd  # d/dt (x - ell sin th)
    pz_dot = -ell * np.sin(th) * thd  # d/dt (ell cos th)
    T = 0.5 * M * xd**2 + 0.5 * m * (px_dot**2 + pz_dot**2)
    V = m * g * ell * np.cos(th)
    return T - V


def lagrange_accelerations(s, F, M, m, ell, lam=LAM, hq=1e-5, hv=1.0):
    """Euler-Lagrange by finite differences: H qdd + C qd - dL/dq = (F - lam x_dot,
    -lam th_dot), with H = d2L/dqd2 and C = d2L/(dqd dq).

    The kinetic energy is quadratic in the velocities, so central differences in qd are
    exact for any step: ``hv = 1`` removes their round-off; ``hq`` is the step in q.
    """
    q, qd = np.array(s[:2], float), np.array(s[2:], float)
    E = np.eye(2)

    def L(a, b):
        return lagrangian(a, b, M, m, ell)

    def dL_dqd(a, b, i):
        return (L(a, b + hv * E[i]) - L(a, b - hv * E[i])) / (2 * hv)

    H = np.empty((2, 2))
    C = np.empty((2, 2))
    dLdq = np.empty(2)
    for i in range(2):
        dLdq[i] = (L(q + hq * E[i], qd) - L(q - hq * E[i], qd)) / (2 * hq)
        for j in range(2):
            H[i, j] = (dL_dqd(q, qd + hv * E[j], i) - dL_dqd(q, qd - hv * E[j], i)) / (2 * hv)
            C[i, j] = (dL_dqd(q + hq * E[j], qd, i) - dL_dqd(q - hq * E[j], qd, i)) / (2 * hq)
    Q = np.array([F - lam * qd[0], -lam * qd[1]])
    return np.linalg.solve(H, Q + dLdq - C @ qd)


def cpp_step(s, F, dt, M=1.0, m=1.0, ell=1.0, lam=LAM, g=G):
    """The C++ InvertedPendulum::computeDynamics, written out from its equations."""
    x, th, dx, dth = s
    b1 = F - m * ell * dth**2 * np.sin(th) - lam * dx
    b2 = m * ell * g * np.sin(th) - lam * dth
    det = m * ell**2 * (M + m * np.sin(th) ** 2)
    ddx = (b1 * m * ell**2 + b2 * m * ell * np.cos(th)) / det
    ddth = ((M + m) * b2 + m * ell * np.cos(th) * b1) / det
    return np.array(
        [
            x + dx * dt + 0.5 * ddx * dt**2,
            th + dth * dt + 0.5 * ddth * dt**2,
            dx + ddx * dt,
            dth + ddth * dt,
        ]
    )


def lqr_by_hamiltonian(A, B, Q, R):
    """LQR gain from the stable invariant subspace of the Hamiltonian matrix (numpy only)."""
    n = A.shape[0]
    Ri = np.linalg.inv(R)
    Hm = np.block([[A, -B @ Ri @ B.T], [-Q, -A.T]])
    w, V = np.linalg.eig(Hm)
    stable = V[:, w.real < 0]
    P = np.real(stable[n:] @ np.linalg.inv(stable[:n]))
    return (Ri @ B.T @ P).ravel()


def make_pendulum(M=1.0, m=1.0, ell=1.0, name="IP", lam=LAM):
    a = InvertedPendulum(name)
    a.setCartMass(M)
    a.setPendulumMass(m)
    a.setPendulumLength(ell)
    a.setViscosity(lam)
    return a


# -- physics ---------------------------------------------------------------------------
def test_accelerations_match_lagrangian_finite_differences():
    rng = np.random.default_rng(1)
    for _ in range(50):
        M, m, ell = rng.uniform(0.2, 3.0, 3)
        lam = rng.uniform(0.0, 1.0)
        s = np.r_[rng.uniform(-1, 1), rng.uniform(-np.pi, np.pi), rng.uniform(-3, 3, 2)]
        F = rng.uniform(-20, 20)
        d = stateDerivative(s, F, M, m, ell, lam, G)
        np.testing.assert_allclose(d[:2], s[2:], rtol=0, atol=0)
        ref = lagrange_accelerations(s, F, M, m, ell, lam)
        np.testing.assert_allclose(d[2:], ref, rtol=1e-7, atol=1e-7)


def test_theta_sign_is_the_cpp_models():
    """Pushing the cart towards +x makes theta grow (the mass lags towards -x)."""
    a = InvertedPendulum("IP")
    a.force.value = 1.0
    for _ in range(10):
        a.incr(1e-3)
    x, th, xd, thd = a.state.value
    assert x > 0 and xd > 0 and th > 0 and thd > 0
    _, B = linearisedModel()
    assert B[2, 0] > 0 and B[3, 0] > 0


@pytest.mark.parametrize("M,m,ell", PARAMS)
def test_incr_is_one_step_of_the_cpp_scheme(M, m, ell):
    a = make_pendulum(M, m, ell, lam=0.3)
    rng = np.random.default_rng(2)
    s = np.array([0.1, 0.4, -0.3, 0.7])
    a.state.value = s
    for _ in range(20):
        F = float(rng.uniform(-5, 5))
        a.force.value = F
        a.incr(2e-3)
        s = cpp_step(s, F, 2e-3, M, m, ell, 0.3)
        np.testing.assert_allclose(a.state.value, s, rtol=1e-12, atol=1e-14)
    np.testing.assert_allclose(
        integrationStep([0.1, 0.4, -0.3, 0.7], 2.0, 1e-3, M, m, ell, 0.3),
        cpp_step(np.array([0.1, 0.4, -0.3, 0.7]), 2.0, 1e-3, M, m, ell, 0.3),
        rtol=1e-13,
    )


@pytest.mark.parametrize("M,m,ell", PARAMS)
def test_incr_converges_to_the_lagrangian_dynamics_at_first_order(M, m, ell):
    """The scheme is first-order accurate: against solve_ivp on the finite-difference
    Lagrangian dynamics (with viscosity and a force), halving dt halves the error."""
    s0 = np.array([0.0, 0.3, -0.2, 0.5])

    def rhs(_t, s):
        return np.r_[s[2:], lagrange_accelerations(s, 2.5, M, m, ell)]

    ref = solve_ivp(rhs, (0.0, 0.5), s0, method="DOP853", rtol=1e-10, atol=1e-10).y[:, -1]
    errors = []
    for i, dt in enumerate((1e-3, 5e-4)):
        a = make_pendulum(M, m, ell, name=f"IP{i}")
        a.state.value = s0
        a.force.value = 2.5
        for _ in range(round(0.5 / dt)):
            a.incr(dt)
        errors.append(np.abs(a.state.value - ref).max())
    assert errors[0] < 0.05
    assert 1.7 < errors[0] / errors[1] < 2.3


def test_viscosity_dissipates_the_energy_it_should():
    """Without a force, d E / dt = -lam (x_dot^2 + th_dot^2): the energy lost over the
    run is the integral of the viscous power (to the scheme's first order), and without
    viscosity it is kept (to the same order)."""
    dt = 1e-4
    for i, lam in enumerate((0.0, 0.5)):
        a = make_pendulum(lam=lam, name=f"IP{i}")
        s = np.array([0.2, 2.5, 0.3, -0.4])  # swinging below the horizontal
        a.state.value = s
        E0 = energy(s, 1.0, 1.0, 1.0)
        dissipated = 0.0
        for _ in range(5000):
            s = a.state.value
            dissipated += lam * (s[2] ** 2 + s[3] ** 2) * dt
            a.incr(dt)
        e_end = energy(a.state.value, 1.0, 1.0, 1.0)
        assert e_end == pytest.approx(E0 - dissipated, abs=2e-3)
        if lam:
            assert dissipated > 0.1  # the check is not vacuous


def test_sot_tutorial_gain_balances_the_pendulum():
    """The SoT tutorial's gain, on the default pendulum from theta = 0.1 rad (its
    simu.py), against the C++ formula: the pendulum never leans further than it started
    and is back within 0.01 rad after 3 s."""
    a, b = InvertedPendulum("IP"), FeedbackController("K")
    plug(a.state, b.state)
    plug(b.force, a.force)
    b.setGain(np.array(SOT_TUTORIAL_GAIN))
    s = np.array([0.0, 0.1, 0.0, 0.0])
    a.state.value = s
    K = np.array([0.0, 27.0, 0.001, 0.001])
    thetas = []
    for _ in range(3000):
        a.incr(1e-3)
        s = cpp_step(s, -K @ s, 1e-3)
        thetas.append(a.state.value[1])
    np.testing.assert_allclose(a.state.value, s, rtol=1e-9, atol=1e-12)
    assert max(np.abs(thetas)) <= 0.1
    assert abs(thetas[-1]) < 0.01
    # its linear closed loop: the swing decays at 0.218 1/s, and the cart's drift is a
    # slow unstable pole (the gain feeds back neither x nor, much, x_dot)
    A, B = linearisedModel()
    eig = np.linalg.eigvals(A - B @ K.reshape(1, 4))
    swing = eig[np.abs(eig.imag) > 1]
    np.testing.assert_allclose(swing.real, -0.2175, atol=1e-3)
    assert eig.real.max() == pytest.approx(0.1330, abs=1e-3)


@pytest.mark.parametrize("M,m,ell", PARAMS)
def test_linearised_model_matches_finite_difference_jacobian(M, m, ell):
    A, B = linearisedModel(M, m, ell, 0.3, G)
    h = 1e-6
    Afd = np.empty((4, 4))
    for j in range(4):
        e = np.zeros(4)
        e[j] = h
        Afd[:, j] = (
            stateDerivative(e, 0.0, M, m, ell, 0.3, G) - stateDerivative(-e, 0.0, M, m, ell, 0.3, G)
        ) / (2 * h)
    Bfd = (
        stateDerivative(np.zeros(4), h, M, m, ell, 0.3, G)
        - stateDerivative(np.zeros(4), -h, M, m, ell, 0.3, G)
    ) / (2 * h)
    assert A.shape == (4, 4) and B.shape == (4, 1)
    np.testing.assert_allclose(A, Afd, rtol=1e-7, atol=1e-7)
    np.testing.assert_allclose(B.ravel(), Bfd, rtol=1e-7, atol=1e-7)


def test_default_gain_is_the_lqr_gain_and_stabilises():
    K = FeedbackController("K").getGain()
    A, B = linearisedModel(1.0, 1.0, 1.0, LAM, G)
    # documented weights, solved independently of scipy
    ref = lqr_by_hamiltonian(A, B, np.diag([10.0, 10.0, 1.0, 1.0]), np.array([[0.1]]))
    np.testing.assert_allclose(K, ref, rtol=1e-8)
    np.testing.assert_allclose(lqrGain(), ref, rtol=1e-8)
    eig = np.linalg.eigvals(A - B @ K.reshape(1, 4))
    assert eig.real.max() < -0.5


@pytest.mark.parametrize("M,m,ell", PARAMS)
def test_lqr_gain_other_models_and_weights_is_hurwitz(M, m, ell):
    Q = np.diag([1.0, 10.0, 1.0, 1.0])
    K = lqrGain(M, m, ell, Q=Q, R=1.0)
    A, B = linearisedModel(M, m, ell, LAM, G)
    np.testing.assert_allclose(K, lqr_by_hamiltonian(A, B, Q, np.eye(1)), rtol=1e-7)
    assert np.linalg.eigvals(A - np.outer(B, K)).real.max() < 0
    np.testing.assert_allclose(lqrGain(M, m, ell, Q=[1, 10, 1, 1], R=1.0), K)


def test_unreasonable_time_steps_are_refused():
    a = InvertedPendulum("IP")
    a.state.value = (0.0, 0.1, 0.0, 0.0)
    A, _ = linearisedModel()
    longest = 0.1 / np.abs(np.linalg.eigvals(A)).max()  # a tenth of the fastest mode
    assert a.getMaxTimeStep() == pytest.approx(longest, rel=1e-12)
    assert a.getMaxTimeStep() == pytest.approx(longestStep())
    for dt in (1e6, 1.0, 2 * longest):
        with pytest.raises(CommandError, match=r"InvertedPendulum\(IP\)\.incr: time step") as e:
            a.incr(dt)
        assert f"{longest:.4g} s" in str(e.value)
    assert a.state.time == 0
    np.testing.assert_array_equal(a.state.value, [0.0, 0.1, 0.0, 0.0])
    a.incr(0.99 * longest)
    assert a.state.time == 1
    # the limit follows the parameters: a shorter pendulum falls faster
    a.setPendulumLength(0.25)
    assert a.getMaxTimeStep() < 0.6 * longest


def test_divergence_is_reported_and_leaves_the_state():
    a = InvertedPendulum("IP")
    a.state.value = (0.0, 0.1, 0.0, 1e200)  # theta_dot^2 overflows
    with pytest.raises(SimulationError, match=r"InvertedPendulum\(IP\)\.incr.*no longer finite"):
        a.incr(1e-3)
    np.testing.assert_array_equal(a.state.value, [0.0, 0.1, 0.0, 1e200])
    assert a.state.time == 0


# -- the graph -------------------------------------------------------------------------
def test_feedback_loop_reads_force_at_state_tick_and_writes_next_tick():
    a, b = InvertedPendulum("IP"), FeedbackController("K")
    plug(a.state, b.state)
    plug(b.force, a.force)
    K = np.array([1.0, 20.0, 2.0, 5.0])
    b.setGain(K)
    s0 = np.array([0.05, 0.1, -0.1, 0.2])
    a.state.value = s0
    assert b.force.value == pytest.approx(-K @ s0)
    a.incr(1e-3)
    assert a.state.time == pool.time == 1
    np.testing.assert_allclose(a.state.value, cpp_step(s0, -K @ s0, 1e-3), rtol=1e-13)
    assert b.force(1) == pytest.approx(-K @ a.state.value)


def test_set_gain_updates_force_in_the_same_tick():
    b = FeedbackController("K")
    b.state.value = (1.0, 1.0, 1.0, 1.0)
    before = b.force.value
    assert before == pytest.approx(-lqrGain().sum())
    b.setGain([1.0, 2.0, 3.0, 4.0])
    assert b.force.value == pytest.approx(-10.0)
    b.setGain(np.array([[0.0, 0.0, 0.0, 1.0]]))  # a 1x4 matrix is accepted
    assert b.force.value == pytest.approx(-1.0)
    b.setGain(np.array([[0.0], [0.0], [2.0], [0.0]]))  # and a 4x1 one (the C++ storage)
    assert b.force.value == pytest.approx(-2.0)
    np.testing.assert_array_equal(b.getGain(), [0.0, 0.0, 2.0, 0.0])
    b.getGain()[0] = 99.0  # a copy
    assert b.getGain()[0] == 0.0


def test_closed_loop_converges_from_theta0():
    out = run_pendulum(duration=10.0, dt=1e-3, theta0=0.1, quiet=True)
    s = out["final_state"]
    assert abs(s[1]) < 1e-3 and abs(s[0]) < 1e-2
    assert out["converged"] and out["error"] is None and not out["fell"]
    n = 10_001
    assert out["time"].shape == (n,) and out["time"][-1] == pytest.approx(10.0)
    assert out["state"].shape == (n, 4) and out["force"].shape == (n, 1)
    np.testing.assert_allclose(out["state"][0], [0.0, 0.1, 0.0, 0.0])
    # each row's force is the controller's output for that row's state
    K = pool.getEntity("K").getGain()
    np.testing.assert_allclose(out["force"][:, 0], -out["state"] @ K, rtol=1e-12, atol=1e-12)
    assert np.abs(out["state"][:, 1]).max() == pytest.approx(0.1)  # fell no further


def test_run_pendulum_reuses_entities_and_keeps_the_pool():
    class Other(Entity):
        """Unrelated entity of the user."""

    Other("mine")
    first = run_pendulum(duration=0.5, quiet=True)
    a = pool.getEntity("IP")
    second = run_pendulum(duration=0.5, quiet=True)
    assert pool.getEntity("IP") is a and pool.hasEntity("mine")
    np.testing.assert_array_equal(first["state"], second["state"])
    np.testing.assert_array_equal(first["time"], second["time"])
    assert second["tick"][0] == 500  # the clock was not reset
    with pytest.raises(SotpyError):
        run_pendulum(duration=0.1, quiet=True, pendulum="mine")


def test_run_pendulum_names_why_the_pendulum_fell():
    out = run_pendulum(duration=3.0, theta0=1.5, quiet=True)
    assert not out["converged"] and out["fell"]
    err = out["error"]
    assert err.startswith("the pendulum fell")
    # the cause, with its numbers: holding the rod at 1.5 rad takes (M + m) g tan(1.5)
    hold = 2 * G * np.tan(1.5)
    asked = abs(lqrGain()[1] * 1.5)
    assert hold > asked  # what the message says
    assert f"cos(theta0) = {np.cos(1.5):.3f}" in err
    assert f"{hold:.0f} N" in err and f"{asked:.0f} N" in err
    assert "Start closer to upright" in err and "0.86 rad" in err
    assert np.isfinite(out["state"]).all() and out["time"][-1] < 1.0
    assert abs(out["state"][-1, 1]) > np.pi / 2 > abs(out["state"][-2, 1])


def test_default_gain_recovers_up_to_the_documented_angle():
    from sotpy.tutorial import DEFAULT_GAIN_RECOVERS

    assert run_pendulum(theta0=DEFAULT_GAIN_RECOVERS, quiet=True)["converged"]
    pool.clear()
    out = run_pendulum(theta0=DEFAULT_GAIN_RECOVERS + 0.01, quiet=True)
    assert out["fell"] and "outside the region" in out["error"]


def test_run_pendulum_refuses_a_step_the_pendulum_refuses():
    with pytest.raises(CommandError, match=r"InvertedPendulum\(IP\)\.incr: time step 0\.5"):
        run_pendulum(dt=0.5, quiet=True)
    assert not pool.hasEntity("IP_tracer")  # nothing built past the refusal


# -- SoT display and help --------------------------------------------------------------
def test_display_signals_layout(capsys):
    InvertedPendulum("IP").displaySignals()
    lines = capsys.readouterr().out.splitlines()
    assert lines == [
        "--- <IP> signal list:",
        "|-- <Sig:InvertedPendulum(IP)::input(double)::force (Type Cst) AUTOPLUGGED",
        "'-- <Sig:InvertedPendulum(IP)::output(vector)::state (Type Cst)",
    ]


def test_help_lists_commands_and_incr_doc(capsys):
    a = InvertedPendulum("IP")
    a.help()
    text = a.helpText()
    assert capsys.readouterr().out.strip() == text.strip()
    assert text.splitlines()[0] == "Classical inverted pendulum dynamic model"
    commands = {
        "incr": "Integrate dynamics for time step provided as input",
        "setCartMass": "Set cart mass, in kg (> 0).",
        "getCartMass": "Get cart mass, in kg.",
        "setPendulumMass": "Set pendulum mass, in kg (> 0).",
        "getPendulumMass": "Get pendulum mass, in kg.",
        "setPendulumLength": "Set pendulum length, in m (> 0).",
        "getPendulumLength": "Get pendulum length, in m.",
        "setViscosity": "Set viscosity lambda (>= 0; default 0.1): N s/m on the cart, "
        "N m s/rad at the hinge.",
        "getViscosity": "Get viscosity lambda (N s/m on the cart, N m s/rad at the hinge).",
        "getMaxTimeStep": "The longest step ``incr`` accepts, in s (see :func:`longestStep`).",
    }
    assert sorted(a.commands()) == sorted(commands)
    for name, summary in commands.items():
        assert any(line.split() == [f"{name}:", *summary.split()] for line in text.splitlines()), (
            name
        )
    a.help("incr")
    text = a.helpText("incr")
    assert text.splitlines()[0] == "incr(dt: float) -> None"
    assert "Integrate dynamics for time step provided as input" in text
    assert capsys.readouterr().out.strip() == text.strip()
    b = FeedbackController("K")
    assert sorted(b.commands()) == ["getGain", "setGain"]
    assert "setGain(K: ndarray) -> None" in b.helpText("setGain")


# -- bad input -------------------------------------------------------------------------
@pytest.mark.parametrize("setter", ["setCartMass", "setPendulumMass", "setPendulumLength"])
@pytest.mark.parametrize("bad", [-1, 0, 0.0, "x", float("nan"), float("inf"), None, True])
def test_bad_parameters_are_refused_and_leave_value(setter, bad):
    a = InvertedPendulum("IP")
    getter = "get" + setter[3:]
    getattr(a, setter)(2.0)
    with pytest.raises(SotpyError) as info:
        getattr(a, setter)(bad)
    assert f"InvertedPendulum(IP).{setter}" in str(info.value)
    assert getattr(a, getter)() == 2.0


def test_viscosity_setting():
    a = InvertedPendulum("IP")
    assert a.getViscosity() == 0.1  # the C++ model's
    a.setViscosity(0.0)  # allowed: a frictionless pendulum
    assert a.getViscosity() == 0.0
    for bad in (-0.1, float("nan"), float("inf"), "x"):
        with pytest.raises(SotpyError, match=r"InvertedPendulum\(IP\)\.setViscosity"):
            a.setViscosity(bad)
        assert a.getViscosity() == 0.0


def test_bad_gain_and_dt_are_refused():
    b = FeedbackController("K")
    K = b.getGain()
    for bad in ([1.0, 2.0, 3.0], [[1.0, 2.0], [3.0, 4.0]], [1, 2, 3, float("inf")], "abcd", None):
        with pytest.raises(SotpyError, match=r"FeedbackController\(K\)\.setGain"):
            b.setGain(bad)
        np.testing.assert_array_equal(b.getGain(), K)
    a = InvertedPendulum("IP")
    for bad in (0.0, -1e-3, float("inf"), "x"):
        with pytest.raises(SotpyError, match=r"InvertedPendulum\(IP\)\.incr"):
            a.incr(bad)
    assert a.state.time == 0
    a.state.value = (1.0, 2.0, 3.0)
    with pytest.raises(SotpyError, match="4 values"):
        a.incr(1e-3)


# -- command line ----------------------------------------------------------------------
def test_cli_demo_pendulum(capsys):
    assert main(["demo", "pendulum", "--duration", "5"]) == 0
    out = capsys.readouterr().out
    lines = out.splitlines()
    assert lines[0].split() == ["t", "[s]", "x", "[m]", "theta", "[rad]", "force", "[N]"]
    assert [line.split()[0] for line in lines[1:7]] == [f"{t}.000" for t in range(6)]
    assert float(lines[1].split()[2]) == pytest.approx(0.1)
    assert "final state:" in out and "pendulum converged" in out


def test_cli_demo_pendulum_with_the_sot_gain(capsys):
    assert main(["demo", "pendulum", "--duration", "3", "--gain", "0", "27", "0.001", "0.001"]) == 1
    out = capsys.readouterr().out
    final_theta = float(out.splitlines()[4].split()[2])  # the row of t = 3 s
    assert abs(final_theta) < 0.01  # balanced, not yet converged to 1e-3 rad
    assert "did NOT converge" in out and "it fell" not in out


def test_cli_demo_pendulum_plot(tmp_path, capsys):
    png = tmp_path / "p.png"
    assert main(["demo", "pendulum", "--duration", "5", "--plot", str(png)]) == 0
    assert png.stat().st_size > 1000
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert str(png) in capsys.readouterr().out


def test_cli_failures_and_usage(capsys):
    assert main(["demo", "pendulum", "--duration", "2", "--theta0", "1.5"]) == 1
    out = capsys.readouterr().out
    assert "did NOT converge" in out and "it fell" in out and "tan(theta0)" in out
    assert main(["demo", "pendulum", "--dt", "1"]) == 1
    assert "InvertedPendulum(IP).incr: time step 1.0 s is longer" in capsys.readouterr().err
    assert main([]) == 2
    assert main(["demo", "nope"]) == 2
    assert main(["demo", "pendulum", "--duration", "-1"]) == 2
    assert main(["--help"]) == 0
    assert "demo" in capsys.readouterr().out


def test_python_dash_m_sotpy():
    r = subprocess.run(
        [sys.executable, "-m", "sotpy", "demo", "--help"],
        capture_output=True,
        text=True,
        timeout=60,
        check=False,
    )
    assert r.returncode == 0, r.stderr
    assert "pendulum" in r.stdout


# -- the tutorial page's recorded output is true ---------------------------------------
_DOC = Path(__file__).resolve().parents[1] / "docs" / "tutorial-pendulum.md"
_FENCE = re.compile(r"^```([a-z]*)[ \t]*\n(.*?)^```[ \t]*$", re.S | re.M)
_NUMBER = re.compile(r"^[-+]?(\d+\.?\d*|\.\d+)([eE][-+]?\d+)?[,\]\)]*$")


def _same_text(got: str, recorded: str, where: str) -> None:
    """Line by line; numbers equal to 6 significant digits (printing may round the last
    one differently across platforms), the wall time of a run ignored."""
    g, r = got.strip("\n").splitlines(), recorded.strip("\n").splitlines()
    assert len(g) == len(r), f"{where}: printed\n{got}\nrecorded\n{recorded}"
    for a, b in zip(g, r, strict=True):
        if "ticks in" in b:  # '... 205 ticks in 0.01 s': the time varies
            a, b = a.rsplit(" in ", 1)[0], b.rsplit(" in ", 1)[0]
        ta, tb = a.replace("[", " [ ").split(), b.replace("[", " [ ").split()
        assert len(ta) == len(tb), f"{where}: printed {a!r}, recorded {b!r}"
        for x, y in zip(ta, tb, strict=True):
            if _NUMBER.match(x) and _NUMBER.match(y):
                fx, fy = float(x.rstrip(",])")), float(y.rstrip(",])"))
                assert fx == pytest.approx(fy, rel=1e-5, abs=1e-12), f"{where}: {a!r} vs {b!r}"
            else:
                assert x == y, f"{where}: printed {a!r}, recorded {b!r}"


def test_tutorial_page_output_is_what_the_code_prints(tmp_path, monkeypatch):
    """Every Python block of docs/tutorial-pendulum.md runs, in order, and prints what
    the block after it records; the console run of the failing pendulum too."""
    monkeypatch.chdir(tmp_path)  # the plot lands here
    blocks = _FENCE.findall(_DOC.read_text())
    namespace: dict = {"__name__": "__main__"}
    checked = 0
    for i, (lang, body) in enumerate(blocks):
        where = f"docs/tutorial-pendulum.md, block {i + 1}"
        if lang == "python":
            out = io.StringIO()
            with contextlib.redirect_stdout(out):
                exec(compile(body, where, "exec"), namespace)
            assert blocks[i + 1][0] == "", f"{where}: no recorded output after it"
            _same_text(out.getvalue(), blocks[i + 1][1], where)
            checked += 1
        elif (
            lang == "console"
            and "\n" in body.strip()
            and not body.startswith("$ sotpy demo pendulum --plot")
        ):
            lines = body.strip("\n").splitlines()
            args = shlex.split(lines[0][2:])[1:]
            end = lines.index("$ echo $?")
            out = io.StringIO()
            with contextlib.redirect_stdout(out):
                code = main(args)
            _same_text(out.getvalue(), "\n".join(lines[1:end]), where)
            assert str(code) == lines[end + 1]
            checked += 1
    assert checked >= 9
