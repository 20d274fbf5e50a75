"""``benchmarks/bench_sot.py`` stays runnable and its controllers do what the tables say.

Tiny tick counts: the timings are only sanity-checked; the assertions are on what the
controllers achieve, against predictions computed here (the wrist's first-order decay,
the task rows of each stack, the models' nv).
"""

import math

import numpy as np
import pinocchio as pin
import pytest

TICKS = 30


@pytest.fixture(scope="module")
def scene(bench_sot):
    return bench_sot.reach_scene("talos")


def _wrist_prediction(bench_sot, scene, ticks):
    """Wrist distance after ``ticks`` if its task is met exactly each tick: the error
    is multiplied by (1 - lambda dt) per tick (explicit Euler on de/dt = -lambda e)."""
    return scene.wrist_start_distance * (1.0 - bench_sot.GAINS["wrist"] * bench_sot.DT) ** ticks


def test_scene_is_the_stated_reach(bench_sot, scene):
    # the wrist target is REACH away from the wrist's half-sitting position (0.25 m)
    assert scene.wrist_start_distance == pytest.approx(np.linalg.norm(bench_sot.REACH["talos"]))
    assert scene.wrist_start_distance == pytest.approx(0.25)
    errors = scene.errors(scene.q0)
    assert errors["feet"] == errors["com"] == errors["posture"] == 0.0
    # an independent check of errors(): move one joint by 0.1 rad
    q = scene.q0.copy()
    q[scene.model.idx_qs[scene.model.getJointId("arm_right_4_joint")]] += 0.1
    assert scene.errors(q)["posture"] == pytest.approx(0.1)
    assert scene.errors(q)["feet"] < 1e-12


def test_sotpy_holds_the_feet_and_reaches_with_strict_priority(bench_sot, scene):
    controller = bench_sot.build_sotpy_reach(scene)
    assert controller.sot.list() == ["taskContactCom", "taskrh", "taskposture"]
    ep = bench_sot.run_sotpy(controller, scene, TICKS, breakdown=True)
    assert ep.failure is None
    assert len(ep.tick) == TICKS
    # strict priorities: the feet + CoM level and the wrist level are met exactly, so the
    # wrist distance follows the first-order decay (the posture cannot slow it)
    assert ep.errors["wrist"] == pytest.approx(_wrist_prediction(bench_sot, scene, TICKS), abs=1e-4)
    residuals = controller.sot.lastResult.residuals
    assert residuals[1] < 1e-9  # feet + CoM (level 0 is the joint limits)
    assert residuals[2] < 1e-9  # wrist
    # the feet drift only by the integration's second-order error, held by the 100/s gain
    assert ep.errors["feet"] < 5e-6
    assert ep.errors["feet_rot"] < 5e-6
    assert ep.errors["com"] < 5e-6
    # the breakdown: the solve and the integration are parts of the tick
    assert (ep.solve > 0).all() and (ep.integration > 0).all()
    assert (ep.solve + ep.integration < ep.tick).all()
    # the timers were removed: the instances use their classes' methods again
    assert "solve" not in vars(controller.sot._solver)
    assert "_step" not in vars(controller.device)


def test_three_levels_give_the_same_motion(bench_sot, scene):
    one = bench_sot.run_sotpy(bench_sot.build_sotpy_reach(scene), scene, 10)
    three_controller = bench_sot.build_sotpy_reach(scene, levels=True, prefix="l3_")
    names = ["tasklf", "taskrf", "taskcom", "taskrh", "taskposture"]
    assert three_controller.sot.list() == [n.replace("task", "taskl3_") for n in names]
    three = bench_sot.run_sotpy(three_controller, scene, 10)
    for key in ("feet", "com", "wrist", "posture"):
        assert three.errors[key] == pytest.approx(one.errors[key], rel=1e-6, abs=1e-9), key


def test_interleaved_runs_match_runs_alone(bench_sot, scene):
    # two sotpy graphs in one pool, taking turns every 7 ticks, move exactly as each
    # does alone (and so does Pink when installed)
    alone = bench_sot.run_sotpy(bench_sot.build_sotpy_reach(scene, prefix="a_"), scene, 20)
    runners = [
        bench_sot.SotpyRunner(bench_sot.build_sotpy_reach(scene, prefix="b_"), scene, 20),
        bench_sot.SotpyRunner(
            bench_sot.build_sotpy_reach(scene, levels=True, prefix="c_"), scene, 20
        ),
    ]
    pink = bench_sot.pink_available() and bench_sot.pink_solvers()
    if pink:
        pink_alone = bench_sot.run_pink(bench_sot.build_pink_reach(scene), scene, 20, pink[0])
        runners.append(bench_sot.PinkRunner(bench_sot.build_pink_reach(scene), scene, 20, pink[0]))
    episodes = bench_sot.interleave(runners, 20, chunk=7)
    assert all(len(e.tick) == 20 and e.failure is None for e in episodes)
    for ep in episodes[:2]:
        for key in ("feet", "com", "wrist", "posture"):
            assert ep.errors[key] == pytest.approx(alone.errors[key], rel=1e-9, abs=1e-12)
    if pink:
        assert episodes[2].errors == pink_alone.errors


def test_pink_reaches_with_the_same_task_set(bench_sot, scene):
    pytest.importorskip("pink")
    solvers = bench_sot.pink_solvers()
    assert solvers, "pin-pink installed but no QP back-end known to qpsolvers"
    for feet_hard in (False, True):
        ep = bench_sot.run_pink(
            bench_sot.build_pink_reach(scene, feet_hard), scene, TICKS, solvers[0], breakdown=True
        )
        assert ep.failure is None, ep.failure
        assert len(ep.tick) == TICKS and (ep.solve < ep.tick).all()
        # weighted: the posture pulls a little, but the decay is nearly the same
        assert ep.errors["wrist"] == pytest.approx(
            _wrist_prediction(bench_sot, scene, TICKS), abs=1e-3
        )
        assert ep.errors["wrist"] < scene.wrist_start_distance - 0.02
        assert ep.errors["feet"] < 1e-5
        assert ep.errors["com"] < 1e-5


def test_compare_reports_every_contender(bench_sot, monkeypatch):
    result = bench_sot.compare(ticks=3, repeats=2, screen_ticks=3, keep=2)
    contenders = result["contenders"]
    assert all(len(c.episodes) == 2 for c in contenders.values())
    assert all(len(e.tick) == 3 for c in contenders.values() for e in c.episodes)
    table = bench_sot.compare_table(result)
    assert table.count("\n| sotpy") == 4
    assert not contenders[bench_sot.TUTORIAL].failure  # the tutorial's graph ran
    # the same stack read through the task signals gives the same episode
    fused, plain = (
        contenders[k].episodes[0] for k in ("sotpy", "sotpy, tasks through their signals")
    )
    assert fused.errors == pytest.approx(plain.errors, abs=1e-12)
    if result["pink"]:
        assert result["fastest"] in contenders and len(result["ratios"]) == 2
        assert f"sotpy / {result['fastest']}" in table
        assert len(result["tutorial_ratios"]) == 2 and f"{bench_sot.TUTORIAL} / " in table
        # every installed back-end was screened, the fastest two compared
        screening = result["screening"]
        assert {r["solver"] for r in screening} == set(bench_sot.pink_solvers())
        ok = [r for r in screening if r["failure"] is None]
        assert [r["tick"] for r in ok] == sorted(r["tick"] for r in ok)
        kept = [name.removeprefix("Pink ") for name in contenders if name.startswith("Pink")]
        assert [k for k in kept if "hard" not in k] == [r["solver"] for r in ok[:2]]
        assert len(bench_sot.screen_table(screening, 3).splitlines()) == 4 + len(screening)
    # without Pink, the sotpy part still runs and the table says Pink was skipped
    monkeypatch.setattr(bench_sot, "pink_available", lambda: False)
    result = bench_sot.compare(ticks=2, repeats=1)
    assert list(result["contenders"]) == [
        "sotpy",
        "sotpy, feet/feet/CoM on 3 levels",
        "sotpy, tasks through their signals",
        bench_sot.TUTORIAL,
    ]
    assert result["fastest"] is None and result["ratios"] == []
    assert "Pink skipped" in bench_sot.compare_table(result)


def test_scaling_in_tasks_stacks_what_it_says(bench_sot):
    counts = (1, 2, 3, 5, 10, 20)
    rows = bench_sot.scaling_tasks(counts, ticks=2, repeats=1)
    assert [r["tasks"] for r in rows] == list(counts)
    joints = 38 - 6  # Talos' posture rows: every DoF but the free flyer's
    # feet 6 + 6, CoM x y, then 3 rows per position task; the posture last
    extra = [0, 6, 12, 14, 17, 20, 23, 26, 29, 32, 35, 38, 41, 44, 47, 50, 53, 56, 59, 62]
    for r in rows:
        assert r["rows"] == joints + extra[r["tasks"] - 1], r["tasks"]
        assert r["failure"] is None
        assert 0 < r["solve"] < r["tick"] and 0 < r["integration"] < r["tick"]
        assert math.isclose(sum(r["methods"].values()), 1.0)
    controller = bench_sot.build_sotpy_tasks(20)
    assert len(controller.sot.list()) == 20
    assert controller.sot.list()[-1] == "taskposture"
    with pytest.raises(ValueError, match="n_tasks"):
        bench_sot.build_sotpy_tasks(0)
    table = bench_sot.scaling_tasks_table(rows, 2, 1)
    assert len(table.splitlines()) == 4 + len(counts)


def test_scaling_in_dof_covers_the_three_humanoids(bench_sot):
    rows = bench_sot.scaling_dof(ticks=2, repeats=1, pink_solver=None)
    assert [r["label"] for r in rows] == ["nao", "talos", "romeo"]
    for r in rows:
        model = bench_sot.reach_scene(r["label"]).model
        free_flyer = model.joints[1].shortname() == "JointModelFreeFlyer"
        assert free_flyer
        assert r["nv"] == model.nv == pin.neutral(model).shape[0] - 1
        # feet 12, CoM 2, wrist 3, posture nv - 6
        assert r["rows"] == 12 + 2 + 3 + model.nv - 6
        assert r["errors"]["wrist"] < np.linalg.norm(bench_sot.REACH[r["label"]])
    assert [r["nv"] for r in rows] == sorted(r["nv"] for r in rows)
    table = bench_sot.scaling_dof_table(rows, 2, 1, None)
    assert "Pink" not in table and len(table.splitlines()) == 4 + 3


def test_profile_summary(bench_sot):
    text = bench_sot.profile_sotpy(ticks=5, top=4)
    assert "| sotpy.solvers |" in text and "| sotpy.graph |" in text
    assert text.count("\n| `") == 4


def test_a_budget_hit_is_counted_and_the_episode_goes_on(bench_sot, scene):
    import warnings

    controller = bench_sot.build_sotpy_reach(scene)
    controller.sot.setMaxIterations(1)  # every tick that needs a second iteration stops
    with warnings.catch_warnings():
        bench_sot.episode_warnings()
        ep = bench_sot.run_sotpy(controller, scene, 120, breakdown=False)
    assert ep.failure is None and len(ep.tick) == 120  # not cut at the first hit
    assert ep.budget_hits == controller.sot.budgetHits > 0
    # an unsatisfiable hard level still fails the episode under the same filters
    with warnings.catch_warnings():
        bench_sot.episode_warnings()
        with pytest.raises(bench_sot.SotpyWarning):
            warnings.warn("a hard level is infeasible", bench_sot.SotpyWarning, stacklevel=1)
