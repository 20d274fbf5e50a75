"""The velocity-referenced walking MPC (sotpy.walking.mpc), checked against independent
computations: the discrete model stepped by hand, the ZMP recomputed from the simulated
states, the soles' rectangles and scipy's convex hull."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest
from scipy.spatial import ConvexHull

from sotpy.errors import CommandError, SolverError
from sotpy.walking.mpc import MPCParameters, VelocityMPC, predictionMatrices, simulate

H = 0.8  # CoM height (m)
TOL = 1e-6  # m: the ZMP's tolerance outside its region


def params(**kw) -> MPCParameters:
    return MPCParameters(comHeight=H, **kw)


def inside(p: MPCParameters, sole, z) -> bool:
    """z inside the sole's rectangle, in the sole's frame (within TOL)."""
    c, s = math.cos(sole[2]), math.sin(sole[2])
    dx, dy = z[0] - sole[0], z[1] - sole[1]
    return abs(c * dx + s * dy) <= p.footHalfLength + TOL and (
        abs(-s * dx + c * dy) <= p.footHalfWidth + TOL
    )


def corners(p: MPCParameters, sole) -> np.ndarray:
    c, s = math.cos(sole[2]), math.sin(sole[2])
    out = []
    for a, b in ((1, 1), (-1, 1), (-1, -1), (1, -1)):
        lx, ly = a * p.footHalfLength, b * p.footHalfWidth
        out.append((sole[0] + c * lx - s * ly, sole[1] + s * lx + c * ly))
    return np.array(out)


def inHull(p: MPCParameters, a, b, z) -> bool:
    hull = ConvexHull(np.vstack([corners(p, a), corners(p, b)]))
    return bool(np.all(hull.equations[:, :2] @ z + hull.equations[:, 2] <= TOL))


def check_zmp(p: MPCParameters, sim) -> None:
    """The ZMP of the simulated states, c - (h/g) ddc, inside the region of the soles
    that had landed, at every sample after the start."""
    zmp = sim.com[:, 0, :] - p.comHeight / p.gravity * sim.com[:, 2, :]
    for i in range(1, len(sim.t)):
        a, b = sim.region[i]
        feet = sim.footsteps
        ok = inside(p, feet[a], zmp[i]) if b < 0 else inHull(p, feet[a], feet[b], zmp[i])
        assert ok, f"t = {sim.t[i]:.2f} s: ZMP {zmp[i]} outside {feet[a]} / {b}"


def check_steps(p: MPCParameters, feet) -> None:
    """Sides alternate; each step within its box relative to the previous sole, in the
    landing sole's frame."""
    dmin, dmax = p.lateralRange
    for prev, cur in itertools.pairwise(feet):
        if cur[:3] == prev[:3]:  # the start: the other sole stays where it is
            continue
        assert cur[3] != prev[3]
        c, s = math.cos(cur[2]), math.sin(cur[2])
        dx, dy = cur[0] - prev[0], cur[1] - prev[1]
        fwd, lat = c * dx + s * dy, -s * dx + c * dy
        assert -p.maxStepBackward - 1e-9 <= fwd <= p.maxStepForward + 1e-9
        sign = 1.0 if cur[3] == "left" else -1.0
        assert dmin - 1e-9 <= sign * lat <= dmax + 1e-9


def test_prediction_matrices_match_stepping_the_model():
    T, N, g = 0.1, 16, 9.81
    pr = predictionMatrices(T, N, H, g)
    A = np.array([[1.0, T, T * T / 2], [0.0, 1.0, T], [0.0, 0.0, 1.0]])
    B = np.array([T**3 / 6, T * T / 2, T])
    rng = np.random.default_rng(3)
    for _ in range(5):
        X0, U = rng.normal(size=3), rng.normal(size=N)
        X, states = X0.copy(), []
        for u in U:
            X = A @ X + B * u
            states.append(X)
        S = np.array(states)
        np.testing.assert_allclose(pr.Pps @ X0 + pr.Ppu @ U, S[:, 0], atol=1e-12)
        np.testing.assert_allclose(pr.Pvs @ X0 + pr.Pvu @ U, S[:, 1], atol=1e-12)
        np.testing.assert_allclose(pr.Pas @ X0 + pr.Pau @ U, S[:, 2], atol=1e-12)
        np.testing.assert_allclose(pr.Pzs @ X0 + pr.Pzu @ U, S[:, 0] - H / g * S[:, 2], atol=1e-12)


def test_solve_prediction_is_the_model_and_respects_its_constraints():
    p = params()
    mpc = VelocityMPC(p)
    com = np.array([[0.02, -0.03], [0.15, 0.1], [0.0, -0.2]])
    res = mpc.solve(com, (0.0, -0.085, 0.0), "right", 0.3, np.array([0.2, 0.0, 0.0]))
    assert res.ok and res.reason == "walking" and res.iterations is not None
    A, B = mpc.A, mpc.B
    X = com.copy()
    for k in range(p.horizon):
        X = A @ X + np.outer(B, res.jerk[k])
        np.testing.assert_allclose(res.com[k], X, atol=1e-12)
    np.testing.assert_allclose(res.zmp, res.com[:, 0] - H / p.gravity * res.com[:, 2], atol=1e-12)
    # timeInStep 0.3 s, N T = 1.6 s: the horizon reaches 2.2 s, i.e. two more steps
    assert [f[3] for f in res.footsteps] == ["left", "right"]
    soles = [(0.0, -0.085, 0.0), *[f[:3] for f in res.footsteps]]
    for k in range(p.horizon):
        j = int((0.3 + (k + 1) * p.period + 1e-9) // p.stepDuration)
        assert inside(p, soles[j], res.zmp[k])


@pytest.mark.parametrize("v", [0.1, 0.2, 0.3])
def test_closed_loop_straight_walk(v):
    p = params()
    sim = simulate(p, lambda t: (v, 0.0, 0.0), 8.0)
    check_zmp(p, sim)
    check_steps(p, sim.footsteps)
    # mean velocity over three full sway periods (two steps each), after the start
    i0, i1 = 32, 80  # 3.2 s .. 8.0 s
    mean = (sim.com[i1, 0] - sim.com[i0, 0]) / (sim.t[i1] - sim.t[i0])
    assert abs(mean[0] - v) <= 0.1 * v
    assert abs(mean[1]) <= 0.01
    assert len(sim.footsteps) >= 10


def test_closed_loop_turn():
    p = params()
    omega, v = 0.2, 0.2
    sim = simulate(p, lambda t: (v, 0.0, omega), 8.0)
    check_zmp(p, sim)
    check_steps(p, sim.footsteps)
    Ts = p.stepDuration
    # the start step (index 2: the left sole stays down) ends at Ts; then one landing per
    # step. The yaw of each sole is fixed in advance, theta_0 + omega j Ts, so it follows
    # omega t exactly (rounding only: 1e-12 rad)
    walk = sim.footsteps[3:]
    for c, f in enumerate(walk, start=1):
        assert abs(f[2] - omega * c * Ts) <= 1e-12
    # the CoM goes where the feet point: over each full sway period (two steps) the
    # displacement of a velocity that follows the rotating reference exactly points at
    # the heading of mid-period, theta(t) = omega (t - Ts). Measured: 0.016 rad in the
    # steady turn; 0.05 rad is under a third of one step's turn (omega Ts = 0.16 rad),
    # so a path lagging the feet by a third of a step fails (the previous sole's frame
    # for the step box gives 0.135 rad)
    n = round(2 * Ts / p.period)
    for i0 in range(24, len(sim.t) - n, n):
        d = sim.com[i0 + n, 0] - sim.com[i0, 0]
        heading = omega * (0.5 * (sim.t[i0] + sim.t[i0 + n]) - Ts)
        assert abs(math.remainder(math.atan2(d[1], d[0]) - heading, 2 * math.pi)) <= 0.05
        # and at the commanded speed (the chord of an arc of 0.32 rad: 0.4 % shorter)
        assert abs(np.linalg.norm(d) / (sim.t[i0 + n] - sim.t[i0]) - v) <= 0.1 * v


def test_stop_after_walking():
    p = params()
    sim = simulate(p, lambda t: (0.3, 0.0, 0.0) if t < 4.0 else (0.0, 0.0, 0.0), 9.0)
    check_zmp(p, sim)
    check_steps(p, sim.footsteps)
    assert sim.modes[-1] == "standing"
    assert np.linalg.norm(sim.com[-1, 1]) < 0.01
    a, b = sim.footsteps[-2], sim.footsteps[-1]
    c, s = math.cos(a[2]), math.sin(a[2])
    dx, dy = b[0] - a[0], b[1] - a[1]
    sign = 1.0 if b[3] == "left" else -1.0
    assert abs(c * dx + s * dy) <= 1e-9
    assert abs(-s * dx + c * dy - sign * p.feetDistance) <= 1e-9
    assert b[2] == a[2]
    # the CoM at rest over the middle of the two soles
    mid = 0.5 * (np.array(a[:2]) + np.array(b[:2]))
    assert np.linalg.norm(sim.com[-1, 0] - mid) < 0.02


def test_bad_input_is_refused_and_the_mpc_still_works():
    mpc = VelocityMPC(params())
    com = np.zeros((3, 2))
    com[0, 1] = -0.085
    good = dict(com=com, support=(0.0, -0.085, 0.0), supportSide="right", timeInStep=0.2)
    good["velocity"] = np.array([0.1, 0.0, 0.0])
    bad = [
        ("velocity", np.array([0.1, 0.0])),
        ("velocity", np.array([0.1, np.nan, 0.0])),
        ("com", np.full((3, 2), np.inf)),
        ("com", np.zeros((2, 3))),
        ("timeInStep", 0.8),
        ("timeInStep", -0.01),
        ("supportSide", "middle"),
        ("support", (0.0, 0.0)),
    ]
    for name, value in bad:
        with pytest.raises(CommandError, match=rf"VelocityMPC\.solve: {name}"):
            mpc.solve(**{**good, name: value})
    res = mpc.solve(**good)
    assert res.ok and res.jerk.shape == (16, 2) and res.com.shape == (16, 3, 2)


def test_unrecoverable_state_raises_solver_error():
    mpc = VelocityMPC(params())
    com = np.zeros((3, 2))
    com[1, 1] = 3.0  # 3 m/s sideways: no step within the box can catch it
    with pytest.raises(SolverError, match=r"VelocityMPC\.solve.*infeasible"):
        mpc.solve(com, (0.0, -0.085, 0.0), "right", 0.2, np.array([0.1, 0.0, 0.0]))
    com[1, 1] = 0.0
    com[0, 1] = -0.085  # at rest over the support
    assert mpc.solve(com, (0.0, -0.085, 0.0), "right", 0.2, np.array([0.1, 0.0, 0.0])).ok


def test_bad_parameters_are_refused():
    with pytest.raises(CommandError, match="comHeight"):
        VelocityMPC(MPCParameters(comHeight=-1.0))
    with pytest.raises(CommandError, match="feetDistance"):
        VelocityMPC(params(feetDistance=0.5))


def test_solve_time_sanity():
    sim = simulate(params(), lambda t: (0.2, 0.0, 0.1), 4.0)
    assert np.median(sim.solveTime) < 0.1


def test_a_walk_whose_command_has_no_plan_stops_and_says_why():
    """VelocityWalk (the generator's online walk): a command the MPC cannot plan (3 m/s
    sideways) is replaced by a stop, or by standing in double support where the feet
    are, said in ``fault``; the ZMP stays over the soles; a command that can be planned
    walks again."""
    from sotpy.walking.plan import Footprint, Sole
    from sotpy.walking.walks import VelocityWalk

    p = params()
    feet = {
        "left": Footprint(0.0, 0.085, 0.0, "left"),
        "right": Footprint(0.0, -0.085, 0.0, "right"),
    }
    walk = VelocityWalk(feet, np.zeros(2), Sole(0.2, 0.12), p, 0.05)

    def command(t: float) -> np.ndarray:
        if t < 3.0:
            return np.array([0.2, 0.0, 0.0])
        return np.array([0.0, 3.0, 0.0]) if t < 5.0 else np.array([0.1, 0.0, 0.0])

    modes = []
    for k in range(90):  # 9 s
        t = k * p.period
        walk.advance(t, command(t))
        modes.append(walk.mode)
        z = walk.zmp(t)
        soles = list(walk.footprints(t).values())
        assert min(np.hypot(z[0] - f.x, z[1] - f.y) for f in soles) < 0.15, (t, z)
        if 3.5 <= t < 5.0:
            assert walk.fault is not None and "has no plan" in walk.fault
    assert "standing" in modes[35:50]
    assert modes[-1] == "walking"  # walking again at 0.1 m/s
    assert np.all(np.isfinite(walk.state(t)))
