"""Per-tick cost of the ``Dynamic`` entity against bare Pinocchio (issue 3's benchmark).

For Talos and Romeo, a ``Dynamic`` with six op points (both feet, both wrists, the
head/gaze and the chest), each giving a placement and a LOCAL Jacobian, plus ``com`` and
``Jcom``: 14 outputs. Each tick writes a new random configuration to a state source
plugged to ``dyn.position`` and evaluates the 14 outputs:

* **floor**: the bare Pinocchio calls that compute the same quantities with the same
  copies (``computeJointJacobians``, ``updateFramePlacements``, six ``oMf[i].copy()`` and
  six ``getFrameJacobian(..., LOCAL)``, ``jacobianCenterOfMass``, copies of the CoM and
  its Jacobian), in a plain function with everything in locals: the work itself;
* **plan**: ``Plan(outputs).run(t)``, the tick loop's path;
* **lazy**: reading each output with ``sig(t)``, the scripts' and shell's path.

The **+dyn** rows add ``inertia``, ``dynamicDrift``, ``gravity`` and ``momenta`` (18
outputs; the floor adds ``crba``, ``nonLinearEffects``, ``computeGeneralizedGravity``,
``computeCentroidalMomentum`` and the copies).

The three paths run interleaved within each repeat, on the same configurations; the
ratios are taken within a repeat and the table gives medians. Usage::

    python benchmarks/bench_dynamic.py            # full run, prints a Markdown table
    python benchmarks/bench_dynamic.py --quick    # fewer ticks and repeats (smoke check)
"""

from __future__ import annotations

import os

# the compiled kernels are what is measured: compiled first on a fresh machine, not the
# NumPy twins that a first run uses while they compile in the background
os.environ.setdefault("SOTPY_JIT", "wait")

import argparse
import statistics
import time
from collections.abc import Callable
from typing import Any

import example_robot_data
import numpy as np
import pinocchio as pin

from sotpy._bench import machine_line
from sotpy.dynamics.dynamic import Dynamic
from sotpy.graph import VECTOR, Entity, Output, Plan, plug, pool

#: op-point name -> frame, per robot (SoT's OperationalPointsMap, six of them)
OP_POINTS = {
    "talos": {
        "left-ankle": "leg_left_6_joint",
        "right-ankle": "leg_right_6_joint",
        "left-wrist": "arm_left_7_joint",
        "right-wrist": "arm_right_7_joint",
        "gaze": "rgbd_joint",
        "chest": "torso_2_joint",
    },
    "romeo": {
        "left-ankle": "LAnkleRoll",
        "right-ankle": "RAnkleRoll",
        "left-wrist": "LWristPitch",
        "right-wrist": "RWristPitch",
        "gaze": "gaze_joint",
        "chest": "torso",
    },
}
DYNAMICS = ("inertia", "dynamicDrift", "gravity", "momenta")
N_CONFIGURATIONS = 64


class BenchDynamicSource(Entity):
    """A state signal written every tick (as a device's ``state``)."""

    state = Output(VECTOR)


def configurations(model: pin.Model, n: int, seed: int = 0) -> list[np.ndarray]:
    """``n`` random configurations within the position limits (joints clipped to
    [-pi, pi]; the free-flyer's base within its [-1, 1] m limits)."""
    rng = np.random.default_rng(seed)
    lo = np.clip(model.lowerPositionLimit, -np.pi, np.pi)
    hi = np.clip(model.upperPositionLimit, -np.pi, np.pi)
    return [pin.normalize(model, rng.uniform(lo, hi)) for _ in range(n)]


def build(robot: str, dynamics: bool) -> tuple[Any, ...]:
    """The graph: a source plugged to a Dynamic with the op points; the sinks."""
    pool.clear()
    model = example_robot_data.load(robot).model
    src = BenchDynamicSource("src")
    dyn = Dynamic("dyn", model)
    plug(src.state, dyn.position)
    sinks = []
    for name, frame in OP_POINTS[robot].items():
        dyn.createOpPoint(name, frame)
        sinks += [dyn.signal(name), dyn.signal("J" + name)]
    sinks += [dyn.com, dyn.Jcom]
    if dynamics:
        dyn.velocity.value = 0.1 * np.random.default_rng(1).standard_normal(model.nv)
        sinks += [dyn.signal(n) for n in DYNAMICS]
    return model, src, dyn, sinks


def floor_function(
    model: pin.Model, frames: list[str], v: np.ndarray | None
) -> Callable[[np.ndarray], list[Any]]:
    """The bare Pinocchio calls for the same outputs, with their copies."""
    data = pin.Data(model)
    fids = [model.getFrameId(f) for f in frames]
    oMf, com0, Jcom = data.oMf, data.com[0], data.Jcom
    M, nle, g = data.M, data.nle, data.g
    LOCAL = pin.LOCAL
    computeJointJacobians = pin.computeJointJacobians
    updateFramePlacements = pin.updateFramePlacements
    getFrameJacobian = pin.getFrameJacobian
    jacobianCenterOfMass = pin.jacobianCenterOfMass
    crba = pin.crba
    nonLinearEffects = pin.nonLinearEffects
    computeGeneralizedGravity = pin.computeGeneralizedGravity
    computeCentroidalMomentum = pin.computeCentroidalMomentum

    def floor(q: np.ndarray) -> list[Any]:
        computeJointJacobians(model, data, q)
        updateFramePlacements(model, data)
        out = []
        for fid in fids:
            out.append(oMf[fid].copy())
            out.append(getFrameJacobian(model, data, fid, LOCAL))
        jacobianCenterOfMass(model, data, False)
        out.append(com0.copy())
        out.append(Jcom.copy())
        return out

    def floor_dynamics(q: np.ndarray) -> list[Any]:
        out = floor(q)
        crba(model, data, q)
        out.append(M.copy())
        nonLinearEffects(model, data, q, v)
        out.append(nle.copy())
        computeGeneralizedGravity(model, data, q)
        out.append(g.copy())
        out.append(computeCentroidalMomentum(model, data, q, v).vector.copy())
        return out

    return floor if v is None else floor_dynamics


def _us(fn: Callable[[int], None], ticks: int) -> float:
    t0 = time.perf_counter()
    fn(ticks)
    return (time.perf_counter() - t0) / ticks * 1e6


def measure(robot: str, dynamics: bool = False, ticks: int = 2000, repeats: int = 9) -> dict:
    model, src, dyn, sinks = build(robot, dynamics)
    qs = configurations(model, N_CONFIGURATIONS)
    plan = Plan(sinks)
    state = src.state
    clock = [0]

    def run_plan(k: int) -> None:
        t = clock[0]
        for _ in range(k):
            t += 1
            state.write(qs[t % N_CONFIGURATIONS], t)
            plan.run(t)
        clock[0] = t

    def run_lazy(k: int) -> None:
        t = clock[0]
        for _ in range(k):
            t += 1
            state.write(qs[t % N_CONFIGURATIONS], t)
            for s in sinks:
                s(t)
        clock[0] = t

    v = dyn.velocity.value if dynamics else None
    floor = floor_function(model, list(OP_POINTS[robot].values()), v)

    def run_floor(k: int) -> None:
        for i in range(k):
            floor(qs[i % N_CONFIGURATIONS])

    # correctness: the plan, the lazy pull and the floor give the same values
    for run in (run_plan, run_lazy):
        run(3)
        t = clock[0]
        expected = floor(qs[t % N_CONFIGURATIONS])
        for s, e in zip(sinks, expected, strict=True):
            got = s.value
            assert s.time == t, f"{s.name} not computed at tick {t}"
            if isinstance(e, pin.SE3):
                assert got.isApprox(e, 1e-12), s.name
            else:
                np.testing.assert_allclose(got, e, atol=1e-10, err_msg=s.name)
    samples: dict[str, list[float]] = {"floor": [], "plan": [], "lazy": []}
    ratios: dict[str, list[float]] = {"plan": [], "lazy": []}
    for _ in range(repeats):
        f = _us(run_floor, ticks)
        p = _us(run_plan, ticks)
        lz = _us(run_lazy, ticks)
        samples["floor"].append(f)
        samples["plan"].append(p)
        samples["lazy"].append(lz)
        ratios["plan"].append(p / f)
        ratios["lazy"].append(lz / f)
    row: dict[str, Any] = {key: statistics.median(x) for key, x in samples.items()}
    row.update(
        robot=robot + (" +dyn" if dynamics else ""),
        nv=model.nv,
        outputs=len(sinks),
        steps=len(plan.steps),
    )
    row["plan/floor"] = statistics.median(ratios["plan"])
    row["lazy/floor"] = statistics.median(ratios["lazy"])
    return row


def main(argv: list[str] | None = None) -> list[dict]:
    parser = argparse.ArgumentParser(description=__doc__.split("\n", 1)[0])
    parser.add_argument("--quick", action="store_true", help="fewer ticks and repeats")
    args = parser.parse_args(argv)
    ticks, repeats = (200, 3) if args.quick else (2000, 9)
    rows = [
        measure(robot, dynamics, ticks, repeats)
        for robot in OP_POINTS
        for dynamics in (False, True)
    ]
    print(machine_line(f"Pinocchio {pin.__version__}"))
    print(
        "| robot | nv | outputs | plan steps | floor us/tick | plan us/tick | plan/floor "
        "| lazy us/tick | lazy/floor |"
    )
    print("|---|---:|---:|---:|---:|---:|---:|---:|---:|")
    for r in rows:
        print(
            f"| {r['robot']} | {r['nv']} | {r['outputs']} | {r['steps']} | {r['floor']:.1f} "
            f"| {r['plan']:.1f} | {r['plan/floor']:.2f} | {r['lazy']:.1f} "
            f"| {r['lazy/floor']:.2f} |"
        )
    return rows


if __name__ == "__main__":
    main()
