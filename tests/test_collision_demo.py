"""``sotpy demo talos-collision``: its checks pass, they agree with an independent
all-pairs computation, and an unreachable target leaves the collision level met with
the wrist's residual reported."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

from sotpy.cli import main
from sotpy.demos import checks
from sotpy.demos.collision import BALL_OFFSET, BALL_RADIUS, DISTANCE_TOLERANCE, run_talos_collision
from sotpy.dynamics import load_model
from sotpy.tasks.collision import collisionPairs, convexGeometryModel


def _all_pairs(q, ball=None):
    """The smallest distance over the SRDF's pairs (and the ball's) at q, every pair
    computed by coal with no broad phase."""
    from sotpy.tasks.collision import robotSrdf

    model, _, collision = load_model("talos")
    gm = convexGeometryModel(collision)
    srdf = robotSrdf("talos")
    pairs = collisionPairs(model, gm, srdf)
    if ball is not None:
        import coal

        gid = gm.addGeometryObject(
            pin.GeometryObject("ball", 0, 0, pin.SE3(np.eye(3), ball), coal.Sphere(BALL_RADIUS))
        )
        pairs += [(g, gid) for g in range(gid)]
    gm.removeAllCollisionPairs()
    for i, j in pairs:
        gm.addCollisionPair(pin.CollisionPair(i, j))
    gd = pin.GeometryData(gm)
    for req in gd.distanceRequests:  # coal's default GJK tolerance is 1e-6 m
        req.gjk_tolerance = req.epa_tolerance = 1e-9
    data = model.createData()
    pin.framesForwardKinematics(model, data, q)
    pin.updateGeometryPlacements(model, data, gm, gd)
    pin.computeDistances(gm, gd)
    return min(r.min_distance for r in gd.distanceResults)


@pytest.mark.parametrize("scenario", ["torso", "obstacle"])
def test_demo_checks_pass_and_agree_with_all_pairs(scenario):
    r = run_talos_collision(scenario, duration=0.6, quiet=True)
    assert r["ok"], r["table"]
    assert r["min_distance_overall"] >= 0.01 - DISTANCE_TOLERANCE
    ball = r["start"] + np.array(BALL_OFFSET) if scenario == "obstacle" else None
    # the recorded smallest distance is the all-pairs one (exact under d_i = 0.05)
    for k in (0, 300, 600):
        exact = _all_pairs(r["q"][k], ball)
        assert exact >= 0.01 - DISTANCE_TOLERANCE
        if exact < 0.05:
            assert r["min_distance"][k] == pytest.approx(exact, abs=1e-7)
    # the collision level is met and has rows at every tick (the legs are close)
    assert r["collision_residual"] < 1e-6 and r["rows"].min() > 0


def test_the_hand_comes_close_to_the_ball():
    r = run_talos_collision("obstacle", duration=0.6, quiet=True)
    # the ball is reached: its pairs are the closest and within 1 mm of d_s
    assert r["min_distance_overall"] < 0.011
    assert r["max_flips_in_window"] <= 2


def test_unreachable_target_leaves_the_collision_level_met_and_reports_the_residual():
    # the target is the ball's centre
    r = run_talos_collision("obstacle", duration=0.8, target_offset=BALL_OFFSET, quiet=True)
    assert r["checks"]["distance"] and r["checks"]["collision_level"]
    ball = r["start"] + np.array(BALL_OFFSET)
    assert _all_pairs(r["q"][-1], ball) >= 0.01 - DISTANCE_TOLERANCE
    # the wrist stopped away from the target, and its level's residual says so
    wrist_level = 3
    assert r["wrist_final"] > BALL_RADIUS
    assert r["residuals"][-1, wrist_level] > 0.05
    assert r["residuals"][-1, 2] < 1e-9
    assert "residual of its level at the end" in r["table"]


def test_sign_flips_and_windows():
    rates = np.array([1.0, -1.0, 0.0, 1.0, np.nan, 1.0, -1.0, 1e-6, 1.0])
    flips = checks.signFlips(rates, deadband=1e-3)
    np.testing.assert_array_equal(flips, [1, 3, 6, 8])
    assert checks.maxFlipsInWindow(flips, 3) == 2
    assert checks.maxFlipsInWindow(flips, 10) == 4
    assert checks.maxFlipsInWindow(np.zeros(0, dtype=int), 50) == 0


def test_cli_runs_the_demo(capsys):
    assert main(["demo", "talos-collision", "--duration", "0.05"]) == 0
    assert "talos-collision OK" in capsys.readouterr().out
    assert main(["demo", "talos-collision", "--safety", "0.06", "--duration", "0.05"]) == 1
    assert "d_i > d_s" in capsys.readouterr().err
