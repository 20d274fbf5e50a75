"""The kinematic walk's costs: the preview-control tick, the walking MPC's replan, and the
whole walking tick on Talos (generator, stack, device) against the same graph standing
(the generator not triggered), measured in the same run.

* **preview tick**: :meth:`sotpy.walking.preview.PreviewController.step` (both axes,
  N = 320 samples of 5 ms ahead), the work of one generator sample;
* **generator read**: ``PatternGenerator.onestepofcontrol`` and its outputs at one tick
  (the plan's feet, its sample's cubic CoM, the ZMP reference; the preview controller
  ran when the steps were given);
* **walking tick**: ``device.increment(1 ms)`` of the walking graph (docs/walking.md):
  the generator, the four-level SOT and the device, over the 15-step walk;
* **online walking tick**: the velocity walk (``:HerdtOnline``, 0.2 then 0.3 m/s
  turning), with the **MPC replan** (one solve every 100 ms) timed inside it;
* **PlaCo's walking IK tick** (``--placo``): the same references replayed through PlaCo's
  ``KinematicsSolver`` on the same Talos (``benchmarks/_placo_walk.py``): its
  ``solve(True)`` and ``update_kinematics()``, against sotpy's walking tick less its
  generator (the kinematics, tasks, SOT and device);
* **standing tick**: the same graph with the generator not triggered (the reference:
  what the walk adds is the generator and the moving references);
* the dynamic filter's time on the 15-step plan (once, when the steps are given).

Reported: median, p99 and worst (us), and the ratio of the walking tick's median to the
standing tick's; and each benchmarked walk judged by its motion (its saved ``q`` and
``v``: the multibody ZMP's margin in the soles on the ground, the stance feet's slip,
the distance covered; :func:`sotpy.demos.walk.contactChecks`), so that a faster tick
that walks worse shows. Usage::

    python benchmarks/bench_walk.py           # the whole walk
    python benchmarks/bench_walk.py --quick   # 3 s of it, a smoke check
"""

from __future__ import annotations

import os

os.environ.setdefault("SOTPY_JIT", "wait")

import argparse
import time
import warnings

import numpy as np

from sotpy._bench import machine_line
from sotpy.demos.walk import GAITS, build_walk, contactChecks, motionOf
from sotpy.dynamics import load_robot
from sotpy.graph import pool
from sotpy.walking.preview import PreviewController, previewGains


def _stats(samples: list[float]) -> tuple[float, float, float]:
    a = np.asarray(samples) * 1e6
    return float(np.median(a)), float(np.percentile(a, 99)), float(a.max())


def judge(name: str, robot, qs: list, vs: list) -> None:
    """The benchmarked walk judged by its motion, not by the generator: the multibody ZMP
    (Pinocchio's centroidal momentum rate) in the soles on the ground, the stance feet's
    slip, the distance the feet's mid-point covered (sotpy.demos.walk's checks)."""
    m = motionOf(robot, np.array(qs), np.array(vs), 1e-3)
    c = contactChecks(m, 1e-3)
    mid = [(m["sole"]["left"][k] + m["sole"]["right"][k]) / 2 for k in (0, -1)]
    print(
        f"{name}: the motion covered {mid[1][0] - mid[0][0]:.3f} m; ZMP margin >= "
        f"{c['margin'] * 1e3:.1f} mm ({c['ticks_outside']} ticks outside); stance slip "
        f"{c['slip'] * 1e3:.4f} mm"
    )


def preview_tick(n: int = 20000) -> tuple[float, float, float]:
    g = previewGains(0.005, 0.876681)
    ctrl = PreviewController(g, np.zeros((3, 2)))
    ref = np.zeros((n + g.F.size + 1, 2))
    ref[:, 0] = np.floor(np.arange(len(ref)) * 0.005 / 0.8) * 0.2
    out = []
    for k in range(n):
        t0 = time.perf_counter()
        ctrl.step(ref[k : k + g.F.size + 1])
        out.append(time.perf_counter() - t0)
    return _stats(out)


def walking_ticks(
    seconds: float | None, references: list | None = None
) -> dict[str, tuple[float, float, float]]:
    """The footstep walk's tick and its generator's share; ``references`` (a list)
    receives each tick's references, for PlaCo's replay."""
    pool.clear()
    robot = load_robot("talos", prefix="bw")
    graph = build_walk(robot, GAITS["talos"], 1e-3, "bw")
    pg = graph["pg"]
    pg.trigger.value = True
    robot.device.increment(1e-3)
    ticks = round((seconds or pg.plan.duration) / 1e-3)
    walk, gen = [], []
    qs, vs = [], []
    for _ in range(ticks):
        t0 = time.perf_counter()
        robot.device.increment(1e-3)
        walk.append(time.perf_counter() - t0)
        qs.append(robot.device.state.value.copy())
        vs.append(robot.device.velocity.value.copy())
        if references is not None:
            references.append(
                {
                    "com": pg.comref.value,
                    "left": pg.leftfootref.value.homogeneous,
                    "right": pg.rightfootref.value.homogeneous,
                    "waist": pg.waistattitudematrixabsolute.value.rotation,
                }
            )
    judge("footstep walk", robot, qs, vs)
    # the generator alone, on a fresh one stepped by hand at the same ticks
    pool.clear()
    robot = load_robot("talos", prefix="bg")
    graph = build_walk(robot, GAITS["talos"], 1e-3, "bg")
    pg = graph["pg"]
    pg.trigger.value = True
    signals = [pg.comref, pg.dcomref, pg.leftfootref, pg.rightfootref, pg.leftfootvelocity]
    signals += [pg.rightfootvelocity, pg.waistattitudematrixabsolute]
    for _ in range(ticks):
        pool.time += 1
        t0 = time.perf_counter()
        for s in signals:
            s(pool.time)
        gen.append(time.perf_counter() - t0)
    return {"walking tick": _stats(walk), "generator read": _stats(gen)}


def online_ticks(seconds: float) -> dict[str, tuple[float, float, float]]:
    """The velocity walk: its whole tick, and the MPC's solves within it."""
    from sotpy.demos.walk import ONLINE_GAITS
    from sotpy.walking import mpc as mpc_module

    pool.clear()
    robot = load_robot("talos", prefix="bo")
    graph = build_walk(robot, ONLINE_GAITS["talos"], 1e-3, "bo", online=True)
    pg = graph["pg"]
    pg.velocitydes.value = np.array([0.2, 0.0, 0.0])
    pg.trigger.value = True
    solves: list[float] = []
    original = mpc_module.VelocityMPC.solve

    def timed(self, *args, **kwargs):
        t0 = time.perf_counter()
        try:
            return original(self, *args, **kwargs)
        finally:
            solves.append(time.perf_counter() - t0)

    mpc_module.VelocityMPC.solve = timed
    try:
        ticks, out, qs, vs = round(seconds / 1e-3), [], [], []
        for k in range(ticks):
            if k == ticks // 2:
                pg.velocitydes.value = np.array([0.3, 0.0, 0.1])
            t0 = time.perf_counter()
            robot.device.increment(1e-3)
            out.append(time.perf_counter() - t0)
            qs.append(robot.device.state.value.copy())
            vs.append(robot.device.velocity.value.copy())
    finally:
        mpc_module.VelocityMPC.solve = original
    judge("online walk", robot, qs, vs)
    return {"online walking tick": _stats(out), "MPC replan (N = 16)": _stats(solves)}


def filter_time() -> float:
    """The dynamic filter on the 15-step Talos plan (s, once)."""
    pool.clear()
    robot = load_robot("talos", prefix="bf")
    t0 = time.perf_counter()
    build_walk(robot, GAITS["talos"], 1e-3, "bf", dynamicFilter=True)
    return time.perf_counter() - t0


def standing_tick(ticks: int) -> tuple[float, float, float]:
    pool.clear()
    robot = load_robot("talos", prefix="bs")
    build_walk(robot, GAITS["talos"], 1e-3, "bs")  # trigger left false: the robot stands
    out = []
    for _ in range(ticks):
        t0 = time.perf_counter()
        robot.device.increment(1e-3)
        out.append(time.perf_counter() - t0)
    return _stats(out)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n", 1)[0])
    parser.add_argument("--quick", action="store_true", help="3 s of the walk")
    parser.add_argument(
        "--placo",
        action="store_true",
        help="replay the walk's references through PlaCo's KinematicsSolver "
        "(benchmarks/_placo_walk.py; PlaCo in its own venv: PLACO_PYTHON=...)",
    )
    args = parser.parse_args()
    warnings.simplefilter("ignore")
    print(machine_line())
    rows = {"preview tick (N = 320, 2 axes)": preview_tick(2000 if args.quick else 20000)}
    references: list | None = [] if args.placo else None
    rows.update(walking_ticks(3.0 if args.quick else None, references))
    if args.placo:
        from _placo_walk import placo_walk_ik

        placo = placo_walk_ik(references)
        rows[f"PlaCo {placo['placo_version']} walking IK tick"] = _stats(list(placo["times"]))
        print(
            f"PlaCo tracking: CoM {placo['com_error'] * 1e3:.4f} mm, "
            f"ankles {placo['feet_error'] * 1e3:.4f} mm"
        )
    rows.update(online_ticks(4.0 if args.quick else 12.0))
    n = 3000 if args.quick else 14000
    rows["standing tick (reference)"] = standing_tick(n)
    # a second round, the other way round: the machine's speed drifts over minutes
    again = standing_tick(n)
    rows.update(
        {f"{k} (2nd round)": v for k, v in walking_ticks(3.0 if args.quick else None).items()}
    )
    rows["standing tick (reference, 2nd round)"] = again
    print(f"{'':46} {'median':>8} {'p99':>8} {'worst':>8}  (us)")
    for name, (med, p99, worst) in rows.items():
        print(f"{name:46} {med:8.1f} {p99:8.1f} {worst:8.1f}")
    for tag in ("", " (2nd round)"):
        ratio = (
            rows[f"walking tick{tag}"][0]
            / rows[f"standing tick (reference{', 2nd round' if tag else ''})"][0]
        )
        print(f"walking tick / standing tick (median){tag}: {ratio:.2f}")
    if not args.quick:
        seconds = filter_time()
        print(
            f"dynamic filter, 15 steps on Talos (once, when the steps are given): {seconds:.2f} s"
        )


if __name__ == "__main__":
    main()
