r"""The SoT slides' humanoid reaching demo: feet fixed, CoM over the support polygon, the
right wrist to a target, half-sitting posture, joint limits hard.

:func:`run_reach` is the story, read top to bottom: it builds this graph in plain
sight, runs it, and hands the run to :class:`sotpy.demos.checks.ReachLog` (the checks
and the table) and :func:`sotpy.plotting.plot_reach` (the figure). ``sotpy demo
talos|romeo|nao`` calls it; ``examples/humanoid_reach.py`` is the same story as a
script to copy. The graph (``p`` = ``reach_<robot>``)::

    robot = load_robot("talos", prefix=p)                 # Dynamic + Device, half-sitting
    robot.device.setControlType("velocity")
    sot = SOT(p + "_sot", robot.dynamic); sot.dt.value = dt
    # level 0: the joint limits, the SOT's own hard level (position and velocity)
    # level 1: one TaskInequality "task_<p>_contact", rows
    #     both ankles' FeaturePose (6 + 6 rows)  bounds [0, 0]    -> equalities
    #     the couplings' residuals (Nao: 1 row)  bounds [0, 0]    -> equalities
    #     N c_xy (the balance feature, k rows)   bounds [-inf, b - margin]
    sot.push(contact)
    # level 2: the right wrist's position, selec "111000", adaptive gain
    robot.tasks["right-wrist"].gotoNd(target, "111000", gain=(10, 2, 0.05, 0.5))
    sot.push(robot.tasks["right-wrist"].task)
    # level 3: half-sitting
    sot.push(robot.tasks["posture"].task)
    plug(sot.control, robot.device.control)
    robot.device.increment(dt)                             # repeatedly

**Why one level for the feet and the CoM, and how.** A task is an equality (``Task``)
or an inequality (``TaskInequality``) and the ``SOT`` pushes one task per level; but a
``TaskInequality`` row whose bounds are equal is an equality for the solver (a row
with ``lower == upper``). With ``referenceInf = referenceSup = 0`` on the feet rows,
``lower = upper = k (0 - e) / dt``: with ``k = 1`` (:data:`CONTACT_GAIN`) each foot's
error is cancelled in one period, the discrete form of a gain ``1 / dt``. The
balance rows bound the CoM's ground projection ``c_xy``: ``N c_xy <= b - margin``,
``N`` the outward normals of the support polygon's edges, ``b`` their offsets
(:func:`sotpy.tasks.ready.polygonHalfPlanes`), so that
``N Jcom_xy qdot <= (b - margin - N c_xy) / dt``: the linear prediction of the CoM after
one period stays inside the polygon shrunk by ``margin`` (:data:`MARGIN`). So the
feet, the couplings and the balance share level 1, as in the slides: none is traded
against another, and the levels below only use what all of them leave free. (Two
consecutive levels, feet then CoM, give the same control whenever both can be met,
which is the case from half-sitting; they differ only when the CoM cannot be kept,
where one level spreads the violation and two levels keep the feet first.)

**Feet drift.** ``e_{n+1} = e_n + J v dt + d_n`` with ``d_n`` the second-order term of
the explicit integration (``|d_n| ~ |v|^2 dt^2``); with ``k = 1``, ``e_{n+1} = d_n``:
the soles stay within about 1e-7 m and rad of their start at ``dt = 1 ms``
(measured: Talos 2e-8 m, Romeo 2e-8 m, Nao 6e-8 m, 9e-8 rad), 25 times more at 5 ms
(1-6e-6 m): the demo's default is 1 ms.

**The wrist.** Its task is ``J v = -g(|e|) e`` with SoT's adaptive gain
``g(x) = 8 * 0.5^(x / 0.05) + 2`` (1/s: 10 at the target, 2 far from it). As long as
no level above blocks it, ``e_{n+1} = (1 - g(|e_n|) dt) e_n`` (plus ``d_n``): the
distance decays along the scalar recursion :func:`wristDecay` (from 0.25 m: 1 mm at
0.91 s, 0.1 mm at 1.14 s). The demo checks the wrist is within
:data:`REACH_TOLERANCE` of the target at the end; a target out of reach is reported
as such when the wrist has stopped (it moves at less than :data:`STALL_RATIO` of the
rate its task asks for): the level-2 residual is then the best the levels above allow,
to first order.

The Nao-class robot's two HipYawPitch joints are one motor (``robot.couplings``): the
legs move here (the base follows the arm), so the coupling is an equality row of
level 1 (the ready task ``couplings``), and its residual is checked.
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import RobotError
from ..graph import plug, pool
from ..loop import frozenHeap

__all__ = [
    "COM_TOLERANCE",
    "CONTACT_GAIN",
    "COUPLING_TOLERANCE",
    "DEFAULT_OFFSET",
    "FEET_TOLERANCE",
    "LEVEL1_TOLERANCE",
    "MARGIN",
    "POSTURE_GAIN",
    "REACH_OFFSETS",
    "REACH_TOLERANCE",
    "STALL_RATIO",
    "WRIST_GAIN",
    "run_reach",
    "wristDecay",
]

#: Target of the right wrist, from its half-sitting position, per robot (world axes,
#: m): forward and up, 0.21-0.25 m away, reachable with the feet fixed.
REACH_OFFSETS: dict[str, tuple[float, float, float]] = {
    "talos": (0.20, 0.0, 0.15),
    "romeo": (0.20, 0.0, 0.15),
    "nao": (0.15, 0.0, 0.15),
}
#: Offset used for a robot not in :data:`REACH_OFFSETS` (m).
DEFAULT_OFFSET: tuple[float, float, float] = (0.15, 0.0, 0.15)
#: The wrist's adaptive gain, SoT's ``setByPoint(valueAt0, valueAtInfty, xref, p)``:
#: 10 1/s at the target, 2 1/s far from it, half-way at 5 cm.
WRIST_GAIN: tuple[float, float, float, float] = (10.0, 2.0, 0.05, 0.5)
#: The posture task's gain (1/s).
POSTURE_GAIN = 1.0
#: ``controlGain`` k of the level-1 TaskInequality: the fraction of each row's error
#: (feet, couplings) or distance to its bound (CoM) that one period may cover.
CONTACT_GAIN = 1.0
#: The CoM's ground projection stays this far inside the support polygon's edges (m).
MARGIN = 0.01
#: The wrist must end this close to the target (m).
REACH_TOLERANCE = 1e-3
#: Away from the target, a wrist moving at less than this fraction of the rate its task
#: asks for (``g(|e|) |e|``) at the end is blocked by the levels above: the target is
#: out of reach, and the wrist is at the best point they allow (to first order).
STALL_RATIO = 0.01
#: Largest drift of a sole from its start (m for the position, rad for the rotation).
FEET_TOLERANCE = 1e-6
#: Largest violation of level 1 (units of J qdot, m/s or rad/s): a residual r moves a
#: foot by r dt per period, 1e-9 m at 1 ms.
LEVEL1_TOLERANCE = 1e-6
#: Largest coupling residual (rad).
COUPLING_TOLERANCE = 1e-9
#: How far the CoM's projection may cross the shrunk polygon's edges (m): the bound is
#: met by the linear prediction, the integration adds a second-order term.
COM_TOLERANCE = 1e-6


# -- maths -------------------------------------------------------------------------------
def wristDecay(
    distance: float, steps: int, dt: float, gain: Sequence[float] = WRIST_GAIN
) -> np.ndarray:
    """The wrist's distance to the target when its task is met exactly every period.

    ``x_{n+1} = (1 - g(x_n) dt) x_n`` with SoT's adaptive gain
    ``g(x) = (g0 - ginf) p^(x / xref) + ginf`` (``gain = (g0, ginf, xref, p)``, as
    ``GainAdaptive.setByPoint``).

    Args:
        distance: ``x_0`` (m).
        steps: number of periods.
        dt: the period (s).
        gain: ``(g0, ginf, xref, p)``: 1/s, 1/s, m, in (0, 1).

    Returns:
        ``x_0 .. x_steps`` (m), size ``steps + 1``.
    """
    g0, ginf, xref, p = (float(v) for v in gain)
    b = -math.log(p) / xref
    out = np.empty(steps + 1)
    x = float(distance)
    out[0] = x
    for n in range(1, steps + 1):
        x -= ((g0 - ginf) * math.exp(-b * x) + ginf) * x * dt
        out[n] = x
    return out


def _check_number(what: str, value: Any, positive: bool = True) -> float:
    number = isinstance(value, (int, float)) and not isinstance(value, bool)
    if not (number and math.isfinite(value) and (value > 0 or not positive)):
        bound = "> 0" if positive else ""
        raise ValueError(f"run_reach: {what} must be a finite number {bound}, got {value!r}")
    return float(value)


def _checked_robot(robot: str | Path) -> dict[str, Any]:
    """The robot's description, if it has two feet and a right wrist (checked before
    any entity is created)."""
    from ..dynamics import robot_info

    info = robot_info(robot)
    sides, ops = sorted(info.get("feet", {})), info.get("opPoints", {})
    if sides != ["left", "right"] or "right-wrist" not in ops:
        raise RobotError(
            f"reach demo: robot {info['name']!r} needs two feet and a 'right-wrist' op "
            f"point (it has feet {sides} and op points {', '.join(ops) or 'none'})"
        )
    return info


# -- the story ---------------------------------------------------------------------------
def run_reach(
    robot: str | Path = "talos",
    duration: float = 2.0,
    dt: float = 1e-3,
    target_offset: Sequence[float] | None = None,
    plot: str | Path | None = None,
    viewer: bool = False,
    quiet: bool = False,
    margin: float = MARGIN,
    wrist_gain: Sequence[float] = WRIST_GAIN,
    posture_gain: float = POSTURE_GAIN,
    contact_gain: float = CONTACT_GAIN,
    damping: float = 0.0,
    hold: float | None = 0.0,
) -> dict[str, Any]:
    """Run the reaching demo (the module doc describes the graph and the maths).

    Args:
        robot: a humanoid with feet and a ``right-wrist`` op point: ``"talos"``,
            ``"romeo"``, ``"nao"`` or the path of a ``.toml`` description.
        duration: simulated time (s, > 0).
        dt: control period and integration step (s, > 0).
        target_offset: the target minus the wrist's start (world axes, m); default
            :data:`REACH_OFFSETS` of the robot (or :data:`DEFAULT_OFFSET`).
        plot: save a PNG there (:func:`sotpy.plotting.plot_reach`).
        viewer: show the robot in a meshcat viewer, and replay the motion there at real
            time once computed (:func:`sotpy.demos.replay`).
        quiet: print nothing (the text is still returned).
        margin: the CoM's projection stays this far inside the polygon's edges (m, >= 0).
        wrist_gain: ``(g0, ginf, xref, p)`` of the wrist's ``GainAdaptive.setByPoint``.
        posture_gain: the posture task's gain (1/s).
        contact_gain: ``controlGain`` k of the level-1 task, in (0, 1].
        damping: the damping of the wrist and posture levels (``SOT.setTaskDamping``;
            0: exact). The feet, the CoM and the joint limits stay exact.
        hold: with ``viewer``, keep it up at most this many seconds after the run
            (0: close it at once; None: until the page is closed or Ctrl-C).

    Returns:
        A dict: ``robot``, ``prefix``, ``entities`` (names created), ``levels`` (names,
        level 0 first), ``ticks``, ``dt``, ``duration``, ``start`` and ``target`` (m),
        ``time`` (n + 1 ticks, s), ``q`` ((n + 1) x nq configurations), ``errors``
        (``"feet"``: norm of both ankles' 6-D errors, m and rad; ``"couplings"`` (rad;
        None without couplings); ``"wrist"``: distance to the target, m;
        ``"posture"``: norm of the posture error, rad; each of size n + 1),
        ``residuals`` (n x levels: ``sot.lastResult.residuals`` of each control),
        ``methods`` (the solver's path per control), ``sole_drift`` (side ->
        ``(n + 1) x 2``: distance of the sole's position and angle of its rotation from
        the start, m and rad), ``feet_drift`` (largest of both, ``(m, rad)``),
        ``com`` ((n + 1) x 2, m), ``polygon`` (k x 2 vertices, m), ``polygon_inner``
        (the polygon shrunk by the margin, or None), ``com_distance``
        ((n + 1) x k: distance of the CoM's projection to each edge's line, m,
        positive inside), ``margin``, ``joint_margin`` ((n + 1): smallest distance of
        a joint to its limits, rad or m), ``joint_margin_min`` (joint name -> smallest
        over the run), ``wrist_final`` (m), ``wrist_speed`` (m/s at the end),
        ``reached``, ``out_of_reach`` (stopped away from the target), ``checks``
        (name -> bool), ``ok`` (every check), ``tolerances``, ``table`` (the text
        printed), ``summary`` (the convergence table), ``plot`` (path or None),
        ``wall_time`` (s of computation of the loop), ``viewer_url``, ``viewer_pid``.

    Raises:
        ValueError: a bad number.
        sotpy.errors.RobotError: unknown robot, a robot without two feet or a right
            wrist.
        sotpy.errors.SotpyError: a viewer that cannot start, a failing step, a plot that
            cannot be saved.
    """
    from ..dynamics import load_robot
    from ..plotting import plot_reach
    from ..solvers.sot import SOT
    from ..tasks import TaskInequality
    from . import open_viewer, replay
    from .checks import ReachLog, freePrefix

    duration, dt = _check_number("duration", duration), _check_number("dt", dt)
    margin = _check_number("margin", margin, positive=False)
    if margin < 0:
        raise ValueError(f"run_reach: margin must be >= 0 m, got {margin!r}")
    posture_gain = _check_number("posture_gain", posture_gain, positive=False)
    contact_gain = _check_number("contact_gain", contact_gain)
    if contact_gain > 1:
        raise ValueError(f"run_reach: contact_gain must be in (0, 1], got {contact_gain!r}")
    damping = _check_number("damping", damping, positive=False)
    gains = [float(g) for g in wrist_gain]
    if len(gains) != 4:
        raise ValueError(f"run_reach: wrist_gain is (g0, ginf, xref, p), got {wrist_gain!r}")
    info = _checked_robot(robot)
    if target_offset is None:
        target_offset = REACH_OFFSETS.get(info["name"], DEFAULT_OFFSET)
    offset = np.asarray(target_offset, dtype=float)
    if offset.shape != (3,) or not np.isfinite(offset).all():
        raise ValueError(f"run_reach: target_offset must be 3 finite numbers (m), got {offset}")
    steps = max(1, round(duration / dt))
    suffixes = ("{prefix}_dynamic", "{prefix}_device", "{prefix}_sot", "task_{prefix}_contact")
    prefix = freePrefix("reach", robot, suffixes)
    known = {e.name for e in pool.entities()}
    lines: list[str] = []

    def say(text: str) -> None:
        lines.append(text)
        if not quiet:
            print(text, flush=True)

    # -- the graph ----------------------------------------------------------------------
    r = load_robot(robot, prefix=prefix)  # Dynamic + Device at half-sitting
    r.device.setControlType("velocity")
    t0 = max(r.device.state.time, 0)
    # level 1, one TaskInequality: both feet fixed and the couplings (bounds [0, 0]),
    # the CoM's projection inside the support polygon shrunk by the margin (N c <= b)
    feet = [r.tasks["left-ankle"].feature, r.tasks["right-ankle"].feature]
    couplings = r.tasks.get("couplings")  # Nao's HipYawPitch pair
    equalities = feet + ([couplings.feature] if couplings else [])
    balance = r.tasks["balance"]
    balance.setMargin(margin)
    balance.task.dt.value = dt
    contact = TaskInequality(f"task_{prefix}_contact")
    for feature in [*equalities, balance.feature]:
        contact.add(feature)
    rows = sum(len(f.error(t0)) for f in equalities)
    bounds = balance.bounds()
    contact.referenceInf.value = np.concatenate((np.zeros(rows), np.full(len(bounds), -np.inf)))
    contact.referenceSup.value = np.concatenate((np.zeros(rows), bounds))
    contact.dt.value = dt
    contact.controlGain.value = contact_gain
    # level 2: the right wrist's position to the target, with SoT's adaptive gain
    wrist = r.tasks["right-wrist"]
    start = r.dynamic.signal("right-wrist")(t0).translation.copy()
    target = start + offset
    wrist.gotoNd(target, "111000", gain=gains)
    # level 3: half-sitting
    posture = r.tasks["posture"]
    posture.gain.setConstant(posture_gain)
    # level 0 (the joint limits) is the SOT's own
    sot = SOT(f"{prefix}_sot", r.dynamic)
    sot.dt.value = dt
    for task in (contact, wrist.task, posture.task):
        sot.push(task)
    for task in (wrist.task, posture.task):  # the feet and the CoM stay exact
        sot.setTaskDamping(task, damping)
    plug(sot.control, r.device.control)

    # -- run it -------------------------------------------------------------------------
    view = open_viewer(r, prefix, say) if viewer else None
    try:
        log = ReachLog(r, sot, target, steps, dt, margin, gains, damping)
        say(log.header())
        begin = time.perf_counter()
        with frozenHeap():
            for _ in range(steps):
                r.device.increment(dt)
                log.record()
        result = log.report(wall_time=time.perf_counter() - begin)
        for line in result["table"].splitlines():
            say(line)
        result["plot"] = None
        if plot is not None:
            plot_reach(result, plot)
            result["plot"] = str(plot)
            say(f"plot: {plot}")
        result["viewer_url"] = result["viewer_pid"] = None
        if view is not None:
            result["viewer_url"] = view.url()
            result["viewer_pid"] = view.serverProcess.pid
            replay(view, log.q, dt, hold, say)
    finally:
        if view is not None:
            view.close()
    result["table"] = "\n".join(lines)
    result["entities"] = [e.name for e in pool.entities() if e.name not in known]
    return result
