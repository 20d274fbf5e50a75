"""The inverted-pendulum tutorial: physics against independent derivations, the SoT
display and help strings, bad input, the closed loop, and the ``sotpy`` CLI."""

import subprocess
import sys

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from sotpy.cli import main
from sotpy.errors import SotpyError
from sotpy.graph import Entity, plug, pool
from sotpy.tutorial import (
    FeedbackController,
    InvertedPendulum,
    linearisedModel,
    lqrGain,
    run_pendulum,
    stateDerivative,
)

G = 9.81
PARAMS = [(1.0, 1.0, 1.0), (2.0, 0.5, 0.7), (0.3, 1.7, 2.5)]  # cart kg, pendulum kg, m


# -- independent references ------------------------------------------------------------
def energy(s, M, m, ell, g=G):
    """Cart KE + pendulum KE + PE, from the Cartesian velocity of the point mass at
    (x + ell sin th, ell cos th)."""
    _, th, xd, thd = s
    vx = xd + ell * np.cos(th) * thd
    vy = -ell * np.sin(th) * thd
    return 0.5 * M * xd**2 + 0.5 * m * (vx**2 + vy**2) + m * g * ell * np.cos(th)


def lagrangian(q, qd, M, m, ell, g=G):
    """L = T - V written from positions, without the equations of motion."""
    _, th = q
    xd, thd = qd
    px_dot = xd + ell * np.cos(th) * thd  # d/dt (x + ell sin th)
    pz_dot = -ell * np.sin(th) * thd  # d/dt (ell cos th)
    T = 0.5 * M * xd**2 + 0.5 * m * (px_dot**2 + pz_dot**2)
    V = m * g * ell * np.cos(th)
    return T - V


def lagrange_accelerations(s, F, M, m, ell, hq=1e-5, hv=1.0):
    """Euler-Lagrange by finite differences: H qdd + C qd - dL/dq = (F, 0), with
    H = d2L/dqd2 and C = d2L/(dqd dq).

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
    return np.linalg.solve(H, np.array([F, 0.0]) + dLdq - C @ qd)


def lqr_by_hamiltonian(A, B, Q, R):
    """LQR gain from the stable invariant subspace of the Hamiltonian matrix (numpy only)."""
    n = A.shape[0]
    Ri = np.linalg.inv(R)
    Hm = np.block([[A, -B @ Ri @ B.T], [-Q, -A.T]])
    w, V = np.linalg.eig(Hm)
    stable = V[:, w.real < 0]
    P = np.real(stable[n:] @ np.linalg.inv(stable[:n]))
    return (Ri @ B.T @ P).ravel()


def make_pendulum(M=1.0, m=1.0, ell=1.0, name="IP"):
    a = InvertedPendulum(name)
    a.setCartMass(M)
    a.setPendulumMass(m)
    a.setPendulumLength(ell)
    return a


# -- physics ---------------------------------------------------------------------------
@pytest.mark.parametrize("M,m,ell", PARAMS)
def test_energy_and_momentum_conserved_without_force(M, m, ell):
    a = make_pendulum(M, m, ell)
    s0 = np.array([0.2, 0.5, 0.3, -0.4])
    a.state.value = s0
    E0 = energy(s0, M, m, ell)
    p0 = (M + m) * s0[2] + m * ell * np.cos(s0[1]) * s0[3]  # horizontal momentum
    thetas = []
    for _ in range(2000):
        a.incr(1e-3)
        thetas.append(a.state.value[1])
    s = a.state.value
    assert a.state.time == 2000
    assert np.ptp(thetas) > 1.0  # it did fall and swing
    assert energy(s, M, m, ell) == pytest.approx(E0, rel=1e-9, abs=1e-9)
    assert (M + m) * s[2] + m * ell * np.cos(s[1]) * s[3] == pytest.approx(p0, abs=1e-9)


def test_accelerations_match_lagrangian_finite_differences():
    rng = np.random.default_rng(1)
    for _ in range(50):
        M, m, ell = rng.uniform(0.2, 3.0, 3)
        s = np.r_[rng.uniform(-1, 1), rng.uniform(-np.pi, np.pi), rng.uniform(-3, 3, 2)]
        F = rng.uniform(-20, 20)
        d = stateDerivative(s, F, M, m, ell, G)
        np.testing.assert_allclose(d[:2], s[2:], rtol=0, atol=0)
        ref = lagrange_accelerations(s, F, M, m, ell)
        np.testing.assert_allclose(d[2:], ref, rtol=1e-7, atol=1e-7)


@pytest.mark.parametrize("M,m,ell", PARAMS)
def test_incr_matches_an_independent_integration_with_force(M, m, ell):
    """The entity (its parameters, RK4, force held over dt) against solve_ivp on the
    finite-difference Lagrangian dynamics."""
    a = make_pendulum(M, m, ell)
    s0 = np.array([0.0, 0.3, -0.2, 0.5])
    a.state.value = s0
    a.force.value = 2.5
    for _ in range(500):
        a.incr(1e-3)

    def rhs(_t, s):
        return np.r_[s[2:], lagrange_accelerations(s, 2.5, M, m, ell)]

    ref = solve_ivp(rhs, (0.0, 0.5), s0, method="DOP853", rtol=1e-10, atol=1e-10).y[:, -1]
    np.testing.assert_allclose(a.state.value, ref, rtol=0, atol=1e-8)


def test_large_dt_is_split_into_substeps():
    a, b = InvertedPendulum("a"), InvertedPendulum("b")
    for e in (a, b):
        e.state.value = (0.0, 0.2, 0.0, 0.0)
        e.force.value = 1.0
    a.incr(0.05)
    for _ in range(50):
        b.incr(0.001)
    assert a.state.time == 1
    np.testing.assert_allclose(a.state.value, b.state.value, rtol=0, atol=1e-12)


@pytest.mark.parametrize("M,m,ell", PARAMS)
def test_linearised_model_matches_finite_difference_jacobian(M, m, ell):
    A, B = linearisedModel(M, m, ell, G)
    h = 1e-6
    Afd = np.empty((4, 4))
    for j in range(4):
        e = np.zeros(4)
        e[j] = h
        Afd[:, j] = (
            stateDerivative(e, 0.0, M, m, ell, G) - stateDerivative(-e, 0.0, M, m, ell, G)
        ) / (2 * h)
    Bfd = (
        stateDerivative(np.zeros(4), h, M, m, ell, G)
        - stateDerivative(np.zeros(4), -h, M, m, ell, G)
    ) / (2 * h)
    assert A.shape == (4, 4) and B.shape == (4, 1)
    np.testing.assert_allclose(A, Afd, rtol=1e-7, atol=1e-7)
    np.testing.assert_allclose(B.ravel(), Bfd, rtol=1e-7, atol=1e-7)


def test_default_gain_is_the_lqr_gain_and_stabilises():
    K = FeedbackController("K").getGain()
    A, B = linearisedModel(1.0, 1.0, 1.0, G)
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
    A, B = linearisedModel(M, m, ell, G)
    np.testing.assert_allclose(K, lqr_by_hamiltonian(A, B, Q, np.eye(1)), rtol=1e-7)
    assert np.linalg.eigvals(A - np.outer(B, K)).real.max() < 0
    np.testing.assert_allclose(lqrGain(M, m, ell, Q=[1, 10, 1, 1], R=1.0), K)


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
    expected = solve_ivp(
        lambda _t, s: np.r_[s[2:], lagrange_accelerations(s, -K @ s0, 1.0, 1.0, 1.0)],
        (0.0, 1e-3),
        s0,
        method="DOP853",
        rtol=1e-10,
        atol=1e-12,
    ).y[:, -1]
    np.testing.assert_allclose(a.state.value, expected, atol=1e-9)
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
    np.testing.assert_array_equal(b.getGain(), [0.0, 0.0, 0.0, 1.0])
    b.getGain()[0] = 99.0  # a copy
    assert b.getGain()[0] == 0.0


def test_closed_loop_converges_from_theta0():
    out = run_pendulum(duration=10.0, dt=1e-3, theta0=0.1, quiet=True)
    s = out["final_state"]
    assert abs(s[1]) < 1e-3 and abs(s[0]) < 1e-2
    assert out["converged"] and out["error"] is None
    n = 10_001
    assert out["time"].shape == (n,) and out["time"][-1] == pytest.approx(10.0)
    assert out["state"].shape == (n, 4) and out["force"].shape == (n, 1)
    np.testing.assert_allclose(out["state"][0], [0.0, 0.1, 0.0, 0.0])
    # each row's force is the controller's output for that row's state
    K = pool.getEntity("K").getGain()
    np.testing.assert_allclose(out["force"][:, 0], -out["state"] @ K, rtol=1e-12, atol=1e-12)
    assert np.abs(out["state"][:, 1]).max() == pytest.approx(
        0.1
    )  # started leaning, fell no further


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


def test_run_pendulum_reports_divergence():
    out = run_pendulum(duration=3.0, theta0=1.5, quiet=True)
    assert not out["converged"]
    assert "diverged" in out["error"] and "InvertedPendulum(IP).incr" in out["error"]
    assert np.isfinite(out["state"]).all() and out["time"][-1] < 3.0


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


def test_cli_demo_pendulum_plot(tmp_path, capsys):
    png = tmp_path / "p.png"
    assert main(["demo", "pendulum", "--duration", "5", "--plot", str(png)]) == 0
    assert png.stat().st_size > 1000
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert str(png) in capsys.readouterr().out


def test_cli_failures_and_usage(capsys):
    assert main(["demo", "pendulum", "--duration", "2", "--theta0", "1.5"]) == 1
    assert "did NOT converge" in capsys.readouterr().out
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
