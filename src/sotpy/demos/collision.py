r"""Talos reaching around its own torso or an obstacle, with self-collision and obstacle
avoidance as an inequality level of the ``SOT``: ``sotpy demo talos-collision``.

:func:`run_talos_collision` is the story: the reaching demo's stack
(:mod:`sotpy.demos.reach`) with a :class:`~sotpy.tasks.collision.TaskCollision` right
below the feet and the balance (``p`` = ``collision_talos``)::

    robot = load_robot("talos", prefix=p); robot.device.setControlType("velocity")
    feature = FeatureCollision(p + "_pairs", robot)       # the SRDF's pairs, hulls
    feature.addObstacle("ball", "sphere", 0.06, centre)   # scenario "obstacle"
    collision = TaskCollision("task_" + p + "_collision"); collision.add(feature)
    # level 0: joint limits (the SOT's); level 1: feet fixed + CoM in the polygon
    # level 2: collision: d_dot >= -xi (d - d_s) / (d_i - d_s) on every pair under d_i
    # level 3: right wrist to the target; level 4: half-sitting
    # levels 3 and 4 damped (SOT.setTaskDamping): a target the level above blocks

Scenarios: ``"torso"`` sends the right hand to a point in front of the left side of the
chest (:data:`TORSO_TARGET`, from the chest): the straight line from the hand crosses
the torso's hull; ``"obstacle"`` to a point forward of the hand with a ball of radius
:data:`BALL_RADIUS` on the way (:data:`BALL_OFFSET`, :data:`OBSTACLE_TARGET`). In both
the hand slides around (the damper leaves the tangential motion free) and ends at the
target, the collision level met exactly at every tick.

**Why the wrist and posture levels are damped.** While the hand presses on a shape, the
collision rows of a few links (forearm, wrist, hand) are active and nearly parallel; the
wrist's undamped least-squares step through what is left of the null space is then
ill-conditioned (base and legs at several rad/s in a first try), and the second-order
integration error of such speeds (``|v|^2 dt^2``) eats the safety distance. A damping of
:data:`DAMPING` on levels 3 and 4 keeps the speeds of a normal reach (< 0.2 rad/s).

**Checks** (:class:`sotpy.demos.checks.CollisionLog`):

- the smallest distance over every pair at every tick is at least ``d_s`` minus
  :data:`DISTANCE_TOLERANCE` (the damper is met by the linear prediction; the
  integration adds ``O(|v|^2 dt^2)`` per tick, measured 1.4e-6 m in the obstacle
  scenario);
- no chatter: the rate of the closest pair's distance, ``(d_{k+1} - d_k) / dt`` for the
  pair closest at tick ``k``, changes sign (ignoring rates under
  :data:`CHATTER_DEADBAND`: GJK's tolerance of about 1e-8 m per 1 ms tick is 1e-5 m/s) at
  most :data:`CHATTER_FLIPS` times in any :data:`CHATTER_WINDOW` ticks;
- the collision level's residual stays under :data:`LEVEL_TOLERANCE` (it is feasible);
- the feet do not move (:data:`FEET_TOLERANCE`), no joint leaves its limits.
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from typing import Any

import numpy as np

from ..graph import plug, pool
from ..loop import frozenHeap

__all__ = [
    "BALL_OFFSET",
    "BALL_RADIUS",
    "CHATTER_DEADBAND",
    "CHATTER_FLIPS",
    "CHATTER_WINDOW",
    "COLLISION_TASK",
    "DAMPING",
    "DISTANCE_TOLERANCE",
    "FEET_TOLERANCE",
    "LEVEL_TOLERANCE",
    "OBSTACLE_TARGET",
    "REACH_TOLERANCE",
    "SCENARIOS",
    "TORSO_TARGET",
    "run_talos_collision",
]

#: The scenarios of the demo.
SCENARIOS = ("torso", "obstacle")
#: Scenario "torso": the target from the chest frame's origin (world axes, m): in front
#: of the left side of the chest.
TORSO_TARGET = (0.15, 0.25, -0.05)
#: Scenario "obstacle": the target from the wrist's start (world axes, m).
OBSTACLE_TARGET = (0.35, 0.0, 0.10)
#: Scenario "obstacle": the ball's centre from the wrist's start (m), slightly off the
#: straight line so that the hand has a side to slide to.
BALL_OFFSET = (0.18, 0.02, 0.05)
#: The ball's radius (m).
BALL_RADIUS = 0.06
#: The wrist's adaptive gain (``GainAdaptive.setByPoint``): 4 1/s at the target, 1 far.
WRIST_GAIN = (4.0, 1.0, 0.05, 0.5)
#: Damping of the wrist and posture levels (see the module doc).
DAMPING = 0.05
#: How far under d_s the smallest distance may be (m): the integration's second order.
DISTANCE_TOLERANCE = 1e-5
#: Rates of the closest distance under this (m/s) carry no sign.
CHATTER_DEADBAND = 1e-4
#: At most this many sign changes of the closest pair's rate ...
CHATTER_FLIPS = 2
#: ... in any window of this many ticks.
CHATTER_WINDOW = 50
#: Largest residual of the collision level (m/s).
LEVEL_TOLERANCE = 1e-6
#: Largest sole drift (m or rad).
FEET_TOLERANCE = 1e-6
#: The wrist is at its target within this (m).
REACH_TOLERANCE = 2e-3
#: The collision task's name.
COLLISION_TASK = "task_{prefix}_collision"


def run_talos_collision(
    scenario: str = "torso",
    duration: float = 3.0,
    dt: float = 1e-3,
    safety: float = 0.01,
    influence: float = 0.05,
    gain: float = 0.5,
    target_offset: Sequence[float] | None = None,
    quiet: bool = False,
    viewer: bool = False,
    hold: float | None = 0.0,
) -> dict[str, Any]:
    """Run the collision demo (the module doc describes the graph and the checks).

    Args:
        scenario: ``"torso"`` or ``"obstacle"``.
        duration: simulated time (s, > 0).
        dt: control period and time step (s, > 0).
        safety, influence: d_s and d_i (m, ``0 <= d_s < d_i``).
        gain: the damper's xi (m/s, > 0).
        target_offset: the target minus the wrist's start (world axes, m), instead of
            the scenario's (e.g. the ball's centre, :data:`BALL_OFFSET`: out of reach).
        quiet: print nothing (the text is still returned).
        viewer: show the run in a meshcat viewer (replayed at real time).
        hold: with ``viewer``, how long to keep it up (s; None: until closed).

    Returns:
        The dict of :meth:`sotpy.demos.checks.CollisionLog.report`: ``checks`` (name ->
        bool), ``ok``, ``min_distance`` (per tick, m), ``min_distance_overall``,
        ``closest`` (pair index per tick, -1: none under d_i), ``closest_rate`` (m/s),
        ``sign_flips``, ``max_flips_in_window``, ``rows`` (per tick), ``wrist`` (distance
        to the target per tick, m), ``residuals`` (ticks x levels), ``table``; plus
        ``scenario``, ``pairs`` (the number of pairs), ``entities`` (created).

    Raises:
        ValueError: a bad number or scenario.
        sotpy.errors.SotpyError: a failing step.
    """
    from ..dynamics import load_robot
    from ..solvers.sot import SOT
    from ..tasks import TaskInequality
    from ..tasks.collision import FeatureCollision, TaskCollision, checkDamper
    from . import open_viewer, replay
    from .checks import CollisionLog, freePrefix

    if scenario not in SCENARIOS:
        raise ValueError(
            f"run_talos_collision: scenario must be one of {SCENARIOS}, got {scenario!r}"
        )
    for what, v in (("duration", duration), ("dt", dt)):
        if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
            raise ValueError(f"run_talos_collision: {what} must be a finite number > 0, got {v!r}")
    try:
        checkDamper("run_talos_collision", safety, influence, gain)
    except Exception as exc:
        raise ValueError(str(exc)) from None
    if target_offset is not None:
        offset = np.asarray(target_offset, dtype=float)
        if offset.shape != (3,) or not np.isfinite(offset).all():
            raise ValueError(
                f"run_talos_collision: target_offset must be 3 finite numbers (m), got "
                f"{target_offset!r}"
            )
    steps = max(1, round(duration / dt))
    prefix = freePrefix("collision", "talos", ("{prefix}_dynamic", "{prefix}_device"))
    known = {e.name for e in pool.entities()}
    lines: list[str] = []

    def say(text: str) -> None:
        lines.append(text)
        if not quiet:
            print(text, flush=True)

    # -- the graph ----------------------------------------------------------------------
    r = load_robot("talos", prefix=prefix)
    r.device.setControlType("velocity")
    t0 = max(r.device.state.time, 0)
    # level 1: both feet fixed (bounds [0, 0]) and the CoM inside the support polygon
    feet = [r.tasks["left-ankle"].feature, r.tasks["right-ankle"].feature]
    balance = r.tasks["balance"]
    balance.setMargin(0.01)
    balance.task.dt.value = dt
    contact = TaskInequality(f"task_{prefix}_contact")
    for feature in [*feet, balance.feature]:
        contact.add(feature)
    bounds = balance.bounds()
    contact.referenceInf.value = np.concatenate((np.zeros(12), np.full(len(bounds), -np.inf)))
    contact.referenceSup.value = np.concatenate((np.zeros(12), bounds))
    contact.dt.value = dt
    # level 2: the collision pairs (the SRDF's, minus adjacent links; convex hulls)
    pairs = FeatureCollision(f"{prefix}_pairs", r)
    pairs.setDistances(safety, influence)
    start = r.dynamic.signal("right-wrist")(t0).translation.copy()
    if scenario == "torso":
        target = r.dynamic.signal("chest")(t0).translation + np.array(TORSO_TARGET)
    else:
        target = start + np.array(OBSTACLE_TARGET)
    if target_offset is not None:
        target = start + offset
    if scenario == "obstacle":
        pairs.addObstacle("ball", "sphere", BALL_RADIUS, start + np.array(BALL_OFFSET))
    collision = TaskCollision(COLLISION_TASK.format(prefix=prefix))
    collision.add(pairs)
    collision.setGain(gain)
    # level 3: the right wrist; level 4: half-sitting
    wrist = r.tasks["right-wrist"]
    wrist.gotoNd(target, "111000", gain=WRIST_GAIN)
    posture = r.tasks["posture"]
    posture.gain.setConstant(1.0)
    sot = SOT(f"{prefix}_sot", r.dynamic)
    sot.dt.value = dt
    for task in (contact, collision, wrist.task, posture.task):
        sot.push(task)
    for task in (wrist.task, posture.task):
        sot.setTaskDamping(task, DAMPING)
    plug(sot.control, r.device.control)

    # -- run it -------------------------------------------------------------------------
    say(
        f"talos-collision ({scenario}): right wrist from {np.round(start, 3)} to "
        f"{np.round(target, 3)} m; {pairs.getPairCount()} pairs (SRDF minus adjacent links"
        f"{', + the ball' if scenario == 'obstacle' else ''}); d_s = {safety:g} m, d_i = "
        f"{influence:g} m, xi = {gain:g} m/s; dt = {dt:g} s, {steps} ticks"
    )
    for i, name in enumerate(["joint limits (SOT, hard)", *sot.list()]):
        say(f"  level {i}: {name}")
    view = open_viewer(r, prefix, say) if viewer else None
    try:
        log = CollisionLog(r, sot, pairs, target, steps, dt)
        begin = time.perf_counter()
        with frozenHeap():
            for _ in range(steps):
                r.device.increment(dt)
                log.record()
        result = log.report(wall_time=time.perf_counter() - begin)
        for line in result["table"].splitlines():
            say(line)
        if view is not None:
            replay(view, log.q, dt, hold, say)
    finally:
        if view is not None:
            view.close()
    result["scenario"] = scenario
    result["pairs"] = pairs.getPairCount()
    result["table"] = "\n".join(lines)
    result["entities"] = [e.name for e in pool.entities() if e.name not in known]
    return result
