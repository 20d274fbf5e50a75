"""Trajectory sources (sotpy.operators.trajectory): cubic interpolations and Seqplay.

The cubic against sot-tools' polynomial and its closed form at the start, the middle
and the end (zero boundary velocities), the velocities against finite differences;
Seqplay against the rows of small files written here, with forward differences and
the file-format errors.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest

from sotpy.errors import CommandError, SignalTypeError, SotpyError
from sotpy.graph import Plan, plug, pool
from sotpy.operators import CubicInterpolation, CubicInterpolationSE3, Seqplay, cubic_profile
from sotpy.tasks import FeaturePose

RNG = np.random.default_rng(7)


def sot_tools_cubic(x0, x1, T, t):
    """sot-tools' polynomial: p0 + (p1 + (p2 + p3 t) t) t, zero end velocities."""
    d = np.asarray(x1) - np.asarray(x0)
    p2, p3 = 3.0 * d / T**2, -2.0 * d / T**3
    return x0 + (p2 + p3 * t) * t * t, (2.0 * p2 + 3.0 * p3 * t) * t


def test_cubic_profile_closed_form():
    T = 2.0
    assert cubic_profile(0.0, T) == (0.0, 0.0)
    assert cubic_profile(1.0, T) == (1.0, 0.0)
    s, sdot = cubic_profile(0.5, T)
    assert s == pytest.approx(0.5) and sdot == pytest.approx(1.5 / T)
    assert cubic_profile(-0.1, T) == (0.0, 0.0) and cubic_profile(1.3, T) == (1.0, 0.0)
    h = 1e-6
    for tau in (0.1, 0.37, 0.8):  # ds/dt by central differences in time t = tau T
        fd = (cubic_profile(tau + h / T, T)[0] - cubic_profile(tau - h / T, T)[0]) / (2 * h)
        assert cubic_profile(tau, T)[1] == pytest.approx(fd, rel=1e-7)


def test_cubic_interpolation_vector_start_middle_end():
    ci = CubicInterpolation("ci")
    x0, x1 = np.array([0.0, 1.0, -1.0]), np.array([2.0, 1.0, 3.0])
    ci.init.value = x0
    np.testing.assert_array_equal(ci.sout.value, x0)  # before start: init, live
    ci.init.value = x0 + 1.0
    np.testing.assert_array_equal(ci.sout.value, x0 + 1.0)
    ci.init.value = x0
    with pytest.raises(CommandError, match=r"CubicInterpolation\(ci\)\.start.*setSamplingPeriod"):
        ci.start(1.0)
    ci.setSamplingPeriod(0.01)
    ci.goal.value = x1
    pool.time = 5
    ci.start(0.2)  # 20 ticks, from tick 5
    T, t0 = 0.2, 5
    for k in range(20):  # ticks in order: a signal is not read back in time
        x, v = sot_tools_cubic(x0, x1, T, k * 0.01)
        np.testing.assert_allclose(ci.sout(t0 + k), x, atol=1e-12)
        np.testing.assert_allclose(ci.soutdot(t0 + k), v, atol=1e-12)
        if k == 0:  # start: init, at rest
            np.testing.assert_array_equal(ci.sout(t0), x0)
            np.testing.assert_array_equal(ci.soutdot(t0), np.zeros(3))
        if k == 10:  # middle: half way, at the peak velocity 1.5 (x1 - x0) / T
            np.testing.assert_allclose(ci.sout(t0 + 10), (x0 + x1) / 2, atol=1e-12)
            np.testing.assert_allclose(ci.soutdot(t0 + 10), 1.5 * (x1 - x0) / T, atol=1e-12)
    np.testing.assert_array_equal(ci.sout(t0 + 20), x1)  # end: the goal, at rest
    np.testing.assert_array_equal(ci.soutdot(t0 + 20), np.zeros(3))
    ci.goal.value = x1 + 0.5  # after the motion the goal is followed (sot-tools)
    np.testing.assert_array_equal(ci.sout(t0 + 25), x1 + 0.5)
    with pytest.raises(CommandError, match=r"already started.*reset"):
        ci.start(1.0)
    ci.reset()
    np.testing.assert_array_equal(ci.sout(t0 + 26), x0)


def test_cubic_interpolation_velocity_matches_finite_differences_and_checks_sizes():
    ci = CubicInterpolation("ci")
    ci.setSamplingPeriod(0.001)
    x0, x1 = RNG.normal(size=4), RNG.normal(size=4)
    ci.init.value, ci.goal.value = x0, x1
    ci.start(0.05)
    xs = [ci.sout(k) for k in range(51)]  # read tick by tick, as a loop does
    vs = [ci.soutdot(k) for k in range(51)]
    h, T = 0.001, 0.05
    jerk = -12.0 * (x1 - x0) / T**3  # the third derivative is constant on a cubic
    for k in (3, 20, 41):
        # the central difference of a cubic is exactly x' + h^2 x''' / 6
        fd = (xs[k + 1] - xs[k - 1]) / (2 * h)
        np.testing.assert_allclose(vs[k] + h**2 * jerk / 6, fd, rtol=1e-7, atol=1e-9)
    ci.reset()
    ci.goal.value = np.zeros(2)
    with pytest.raises(SignalTypeError, match=r"CubicInterpolation\(ci\)::input\(vector\)::goal"):
        ci.start(1.0)
    ci.goal.value = x1
    with pytest.raises(CommandError, match="duration > 0"):
        ci.start(0.0)


def test_cubic_interpolation_se3_closed_form_and_velocities():
    M0 = pin.exp6(RNG.uniform(-1, 1, 6))
    M1 = pin.exp6(RNG.uniform(-1, 1, 6))
    ci = CubicInterpolationSE3("ci")
    ci.init.value, ci.goal.value = M0, M1
    assert ci.sout.value.isApprox(M0, 0.0)
    ci.setSamplingPeriod(0.01)
    T = 0.5
    ci.start(T)
    dp = M1.translation - M0.translation
    Ms, pdots, nus = [], [], []
    for k in range(51):  # ticks in order: a signal is not read back in time
        Ms.append(ci.sout(k))
        pdots.append(ci.soutdot(k))
        nus.append(ci.velocity(k))
    for k in (0, 1, 12, 25, 37, 49):
        t = k * 0.01
        p, pdot = sot_tools_cubic(M0.translation, M1.translation, T, t)
        np.testing.assert_allclose(Ms[k].translation, p, atol=1e-12)  # sot-tools' line
        np.testing.assert_allclose(pdots[k], pdot, atol=1e-12)
        s = cubic_profile(t / T, T)[0]
        # the rotation is the geodesic one: that of Pinocchio's SE3 interpolation
        np.testing.assert_allclose(
            Ms[k].rotation, pin.SE3.Interpolate(M0, M1, s).rotation, atol=1e-12
        )
    np.testing.assert_allclose(Ms[25].translation, (M0.translation + M1.translation) / 2)
    np.testing.assert_allclose(pdots[25], 1.5 * dp / T, atol=1e-12)
    # LOCAL velocity against the finite difference log6(M(t)^-1 M(t + h)) / h
    h = 0.01
    for k in (5, 25, 40):
        fd = pin.log6(Ms[k].inverse() * Ms[k + 1]).vector / h
        np.testing.assert_allclose((nus[k] + nus[k + 1]) / 2, fd, atol=2e-3)  # midpoint
        np.testing.assert_allclose(nus[k][:3], Ms[k].rotation.T @ pdots[k], atol=1e-12)
    # zero velocity at both ends, the goal exactly at the end
    assert Ms[0].isApprox(M0, 1e-12)
    np.testing.assert_array_equal(nus[0], np.zeros(6))
    np.testing.assert_array_equal(pdots[0], np.zeros(3))
    assert Ms[50].isApprox(M1, 1e-12)
    np.testing.assert_array_equal(nus[50], np.zeros(6))
    np.testing.assert_array_equal(pdots[50], np.zeros(3))


def test_cubic_interpolation_se3_in_a_plan_feeds_a_feature_pose():
    M0 = pin.exp6(RNG.uniform(-1, 1, 6))
    M1 = pin.exp6(RNG.uniform(-1, 1, 6))
    ci = CubicInterpolationSE3("ci")
    ci.init.value, ci.goal.value = M0, M1
    ci.setSamplingPeriod(0.01)
    feature = FeaturePose("feature")
    feature.position.value = M0
    feature.Jq.value = np.eye(6)
    plug(ci.sout, feature.reference)
    plug(ci.velocity, feature.referenceVelocity)
    plan = Plan([feature.error, feature.errordot])
    plan.run(0)
    np.testing.assert_allclose(feature.error.value, np.zeros(6), atol=1e-12)
    ci.start(0.1)
    values = []
    for t in range(1, 12):
        plan.run(t)
        values.append(ci.sout.value)
        if t == 5:  # moving: the feature sees the reference's velocity
            assert np.abs(feature.errordot.value).max() > 0.1
    assert values[-1].isApprox(M1, 1e-12)
    assert np.abs(feature.errordot.value).max() == 0.0  # at rest at the goal


# -- Seqplay --------------------------------------------------------------------------
def write_motion(base: Path, n: int = 5, dt: float = 0.1, **extra: np.ndarray) -> dict:
    """Write a motion of ``n`` rows as Seqplay files ``base.*``; return its data."""
    time = dt * np.arange(n)
    data = {
        "posture": RNG.normal(size=(n, 4)),
        "la": [pin.exp6(RNG.uniform(-0.3, 0.3, 6)) for _ in range(n)],
        "ra": [pin.exp6(RNG.uniform(-0.3, 0.3, 6)) for _ in range(n)],
        "com": RNG.normal(size=(n, 3)),
    }
    data.update(extra)
    for ext, rows in data.items():
        if ext in ("la", "ra"):
            rows = np.array([M.homogeneous.ravel() for M in rows])
        table = np.column_stack([time, rows])
        np.savetxt(f"{base}.{ext}", table, delimiter="\t", fmt="%.17g")
    data["time"] = time
    return data


def test_seqplay_plays_one_row_per_tick(tmp_path):
    data = write_motion(tmp_path / "walk")
    posture = tmp_path / "walk.posture"
    posture.write_text("# time q0 q1 q2 q3\n\n" + posture.read_text() + "\n\n")  # skipped
    sp = Seqplay("sp")
    with pytest.raises(SotpyError, match=r"Seqplay\(sp\)::output\(vector\)::posture.*load"):
        sp.posture.value  # noqa: B018
    with pytest.raises(CommandError, match="load"):
        sp.start()
    sp.load(str(tmp_path / "walk"))
    np.testing.assert_array_equal(sp.posture.value, data["posture"][0])  # not started
    np.testing.assert_array_equal(sp.comdot.value, np.zeros(3))  # at rest
    pool.time = 10
    sp.start()
    for k in range(5):
        np.testing.assert_array_equal(sp.posture(10 + k), data["posture"][k])
        np.testing.assert_array_equal(sp.com(10 + k), data["com"][k])
        assert sp.leftAnkle(10 + k).isApprox(data["la"][k], 1e-12)
        assert sp.rightAnkle(10 + k).isApprox(data["ra"][k], 1e-12)
    np.testing.assert_array_equal(sp.posture(30), data["posture"][-1])  # over: last row
    with pytest.raises(CommandError, match="already started"):
        sp.start()
    out = sp.posture(30)
    out[:] = 0.0  # a fresh array: the player is unaffected
    sp.load(str(tmp_path / "walk"))  # reloading rewinds
    np.testing.assert_array_equal(sp.posture(31), data["posture"][0])
    with pytest.raises(SotpyError, match=r"zmp: no data: .*walk\.zmp was not found"):
        sp.zmp(31)


def test_seqplay_forward_differences_are_consistent_with_euler_steps(tmp_path):
    data = write_motion(tmp_path / "m", n=6, dt=0.05)
    sp = Seqplay("sp")
    sp.load(str(tmp_path / "m"))
    sp.start()
    h, com = 0.05, data["com"]
    for k in range(5):
        # com[k+1] = com[k] + h comdot[k];  comdot[k+1] = comdot[k] + h comddot[k]
        np.testing.assert_allclose(com[k] + h * sp.comdot(k), com[k + 1], atol=1e-12)
        if k < 4:
            np.testing.assert_allclose(
                sp.comdot(k) + h * sp.comddot(k), (com[k + 2] - com[k + 1]) / h, atol=1e-9
            )
        # the ankle reaches the next row with its LOCAL velocity held over the row
        for out, ext in ((sp.leftAnkleVel, "la"), (sp.rightAnkleVel, "ra")):
            nu = out(k)
            M_next = data[ext][k] * pin.exp6(h * nu)
            assert M_next.isApprox(data[ext][k + 1], 1e-10)
    for out in (sp.comdot, sp.comddot, sp.leftAnkleVel):
        assert not out(5).any()  # the last row: stopped


def test_seqplay_optional_files(tmp_path):
    n = 4
    zmp = RNG.normal(size=(n, 3))
    fl, fr = RNG.normal(size=(n, 6)), RNG.normal(size=(n, 6))
    comdot = RNG.normal(size=(n, 3))
    write_motion(tmp_path / "m", n=n, zmp=zmp, fl=fl, fr=fr, comdot=comdot)
    sp = Seqplay("sp")
    sp.load(str(tmp_path / "m"))
    sp.start()
    for k in range(n):
        np.testing.assert_array_equal(sp.zmp(k), zmp[k])
        np.testing.assert_array_equal(sp.forceLeftFoot(k), fl[k])
        np.testing.assert_array_equal(sp.forceRightFoot(k), fr[k])
    np.testing.assert_array_equal(sp.comdot(1), comdot[1])  # from the file, not differences
    (tmp_path / "m.fr").unlink()
    with pytest.raises(CommandError, match=r"m\.fl was found but not .*m\.fr"):
        sp.load(str(tmp_path / "m"))


def test_seqplay_file_errors_name_file_and_line(tmp_path):
    sp = Seqplay("sp")
    with pytest.raises(CommandError, match=r"cannot open .*nothing\.posture"):
        sp.load(str(tmp_path / "nothing"))
    data = write_motion(tmp_path / "m", n=3)
    base = str(tmp_path / "m")
    com = Path(f"{base}.com")
    good = com.read_text()
    com.write_text(good.replace("\t", "\tx", 1))
    with pytest.raises(
        CommandError, match=r"Seqplay\(sp\)\.load: .*m\.com, line 1: expected numbers"
    ):
        sp.load(base)
    rows = good.splitlines()
    com.write_text("\n".join([rows[0], rows[1].rsplit("\t", 1)[0], rows[2]]) + "\n")
    with pytest.raises(
        CommandError, match=r"Seqplay\(sp\)\.load: .*m\.com, line 2: expected 4 numbers"
    ):
        sp.load(base)
    com.write_text("\n".join(rows[:2]) + "\n")
    with pytest.raises(CommandError, match="same number of rows"):
        sp.load(base)
    com.write_text(good.replace(rows[1].split("\t", 1)[0], "0.15", 1))
    with pytest.raises(CommandError, match=r"m\.(posture|la|ra), row 2: time"):
        sp.load(base)
    com.write_text(good)
    la = data["la"][1].homogeneous.copy()
    la[0, 0] += 0.01  # not a rotation any more
    table = np.column_stack([data["time"], [M.homogeneous.ravel() for M in data["la"]]])
    table[1, 1:] = la.ravel()
    np.savetxt(f"{base}.la", table, delimiter="\t")
    with pytest.raises(CommandError, match=r"m\.la, row 2: the top-left 3 x 3 block"):
        sp.load(base)
