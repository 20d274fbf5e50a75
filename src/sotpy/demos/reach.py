r"""The SoT slides' humanoid reaching demo: feet fixed, CoM over the support polygon, the
right wrist to a target, half-sitting posture, joint limits hard.

``sotpy demo talos|romeo|nao [--duration S] [--dt S] [--plot PATH] [--viewer]
[--target-offset X Y Z]`` and ``examples/humanoid_reach.py`` call :func:`run_reach`,
which builds this graph (``p`` = ``reach_<robot>``)::

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
import re
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import pinocchio as pin

from ..errors import RobotError, SotpyError
from ..graph import plug, pool
from . import Pacer, attach_viewer, detach_viewer

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
#: Largest excursion beyond a joint limit (rounding), rad or m.
ROUNDING = 1e-9

_WRIST = "right-wrist"
_SUMMARY_TIMES = (0.0, 0.1, 0.25, 0.5, 1.0, 2.0, 5.0, 10.0, 20.0, 50.0)


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


def _limit_indices(model: pin.Model) -> tuple[np.ndarray, np.ndarray, np.ndarray, list[str]]:
    """Index in q, lower and upper limits and names of the 1-DoF joints with finite
    limits."""
    iq, names = [], []
    for j in range(1, model.njoints):
        jm = model.joints[j]
        if jm.nq == 1 and jm.nv == 1:
            lo, hi = model.lowerPositionLimit[jm.idx_q], model.upperPositionLimit[jm.idx_q]
            if abs(lo) < 1e30 and abs(hi) < 1e30:
                iq.append(jm.idx_q)
                names.append(model.names[j])
    idx = np.array(iq, dtype=np.intp)
    return idx, model.lowerPositionLimit[idx].copy(), model.upperPositionLimit[idx].copy(), names


def _free_prefix(robot: str | Path) -> str:
    """``reach_<robot>``, or ``reach_<robot>_<k>`` when entities of that prefix exist."""
    text = str(robot)
    base = Path(text).stem if (text.endswith(".toml") or "/" in text or "\\" in text) else text
    base = re.sub(r"[^A-Za-z0-9_-]", "_", base) or "robot"
    k = 1
    while True:
        prefix = f"reach_{base}" if k == 1 else f"reach_{base}_{k}"
        names = (f"{prefix}_dynamic", f"{prefix}_device", f"{prefix}_sot", f"task_{prefix}_contact")
        if not any(pool.hasEntity(n) for n in names):
            return prefix
        k += 1


def _check_number(what: str, value: Any, positive: bool = True) -> float:
    number = isinstance(value, (int, float)) and not isinstance(value, bool)
    if not (number and math.isfinite(value) and (value > 0 or not positive)):
        bound = "> 0" if positive else ""
        raise ValueError(f"run_reach: {what} must be a finite number {bound}, got {value!r}")
    return float(value)


# -- the story ---------------------------------------------------------------------------
def run_reach(
    robot: str = "talos",
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
    sleep: Callable[[float], None] = time.sleep,
) -> dict[str, Any]:
    """Run the reaching demo (the module doc describes the graph and the maths).

    Args:
        robot: a humanoid with feet and a ``right-wrist`` op point: ``"talos"``,
            ``"romeo"``, ``"nao"`` or the path of a ``.toml`` description.
        duration: simulated time (s, > 0).
        dt: control period and integration step (s, > 0).
        target_offset: the target minus the wrist's start (world axes, m); default
            :data:`REACH_OFFSETS` of the robot (or :data:`DEFAULT_OFFSET`).
        plot: save a PNG there (errors over time, the CoM in the support polygon).
        viewer: show the robot in a meshcat viewer and run at real time.
        quiet: print nothing (the text is still returned).
        margin: the CoM's projection stays this far inside the polygon's edges (m, >= 0).
        wrist_gain: ``(g0, ginf, xref, p)`` of the wrist's ``GainAdaptive.setByPoint``.
        posture_gain: the posture task's gain (1/s).
        contact_gain: ``controlGain`` k of the level-1 task, in (0, 1].
        damping: the damping of the wrist and posture levels (``SOT.setTaskDamping``;
            0: exact). The feet, the CoM and the joint limits stay exact.
        sleep: the function that waits when paced (``time.sleep``).

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
        ``com`` ((n + 1) x 2, m), ``polygon`` (k x 2 vertices, m), ``com_distance``
        ((n + 1) x k: distance of the CoM's projection to each edge's line, m,
        positive inside), ``margin``, ``joint_margin`` ((n + 1): smallest distance of
        a joint to its limits, rad or m), ``joint_margin_min`` (joint name -> smallest
        over the run), ``wrist_final`` (m), ``wrist_speed`` (m/s at the end),
        ``reached``, ``out_of_reach`` (stopped away from the target), ``checks``
        (name -> bool), ``ok`` (every check), ``table`` (the text printed),
        ``summary`` (the convergence table), ``plot`` (path or None), ``wall_time``
        (s of the loop), ``viewer_url``, ``viewer_pid``, ``late_ticks``.

    Raises:
        ValueError: a bad number.
        sotpy.errors.RobotError: unknown robot, a robot without two feet or a right
            wrist.
        sotpy.errors.SotpyError: a viewer that cannot start, a failing step, a plot that
            cannot be saved.
    """
    from ..dynamics import load_robot, robot_info
    from ..solvers.sot import SOT
    from ..tasks import TaskInequality

    duration = _check_number("duration", duration)
    dt = _check_number("dt", dt)
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
    steps = max(1, round(duration / dt))
    lines: list[str] = []

    def emit(text: str) -> None:
        lines.append(text)
        if not quiet:
            print(text, flush=True)

    info = robot_info(robot)  # checked before any entity is created
    sides, ops = sorted(info.get("feet", {})), info.get("opPoints", {})
    if sides != ["left", "right"] or _WRIST not in ops:
        raise RobotError(
            f"reach demo: robot {info['name']!r} needs two feet and a {_WRIST!r} op point "
            f"(it has feet {sides} and op points {', '.join(ops) or 'none'})"
        )
    if target_offset is None:
        target_offset = REACH_OFFSETS.get(info["name"], DEFAULT_OFFSET)
    offset = np.asarray(target_offset, dtype=float)
    if offset.shape != (3,) or not np.isfinite(offset).all():
        raise ValueError(f"run_reach: target_offset must be 3 finite numbers (m), got {offset}")
    prefix = _free_prefix(robot)
    r = load_robot(robot, prefix=prefix)
    entities = [f"{prefix}_dynamic", f"{prefix}_device"]
    model, dyn, device = r.model, r.dynamic, r.device
    device.setControlType("velocity")
    t0 = max(device.state.time, 0)

    # level 1: feet, couplings, balance
    feet = [r.tasks["left-ankle"], r.tasks["right-ankle"]]
    couplings = r.tasks.get("couplings")  # Nao's HipYawPitch pair, Romeo's fingers
    balance = r.tasks["balance"]
    balance.setMargin(margin)
    balance.task.dt.value = dt
    contact = TaskInequality(f"task_{prefix}_contact")
    equalities = [m.feature for m in feet] + ([couplings.feature] if couplings else [])
    for f in equalities:
        contact.add(f)
    contact.add(balance.feature)
    neq = sum(int(f.error(t0).shape[0]) for f in equalities)
    bounds = balance.bounds()
    contact.referenceInf.value = np.concatenate((np.zeros(neq), np.full(len(bounds), -np.inf)))
    contact.referenceSup.value = np.concatenate((np.zeros(neq), bounds))
    contact.dt.value = dt
    contact.controlGain.value = contact_gain
    # level 2: the wrist; level 3: half-sitting
    wrist = r.tasks[_WRIST]
    start = dyn.signal(_WRIST)(t0).translation.copy()
    target = start + offset
    wrist.gotoNd(target, "111000", gain=gains)
    posture = r.tasks["posture"]
    posture.gain.setConstant(posture_gain)

    sot = SOT(f"{prefix}_sot", dyn)
    sot.dt.value = dt
    for task in (contact, wrist.task, posture.task):
        sot.push(task)
    for task in (wrist.task, posture.task):  # the feet and the CoM stay exact
        sot.setTaskDamping(task, damping)
    plug(sot.control, device.control)
    for m in r.tasks.created().values():
        entities += [e.name for e in m.entities()]
        if hasattr(m, "featureDes"):
            entities.append(m.featureDes.name)
    entities += [contact.name, sot.name]
    levels = [
        "joint limits (SOT, hard)",
        "contact: both feet fixed"
        + (" + couplings" if couplings else "")
        + f" + CoM in the support polygon (margin {margin:g} m)",
        f"{_WRIST} position (selec 111000)",
        "posture (half-sitting)",
    ]

    # recording
    soles = {}
    for side, foot in r.feet.items():
        name = f"{prefix}-{side}-sole"
        dyn.createPosition(name, foot.frame)
        soles[side] = dyn.signal(name)
    wristSig = dyn.signal(_WRIST)
    polygon = balance.polygon.getVertices()
    N, b = balance.polygon.getNormals(), balance.polygon.getOffsets()
    lim_q, lim_lo, lim_hi, lim_names = _limit_indices(model)
    n1 = steps + 1
    qs = np.empty((n1, model.nq))
    com = np.empty((n1, 2))
    err = {k: np.empty(n1) for k in ("feet", "wrist", "posture")}
    err["couplings"] = np.empty(n1) if couplings else None
    drift = {side: np.empty((n1, 2)) for side in soles}
    residuals = np.full((steps, 4), np.nan)
    methods: list[str] = []
    sole0 = {side: sig(t0).copy() for side, sig in soles.items()}
    feetFeatures = [m.feature for m in feet]

    def record(k: int) -> None:
        t = t0 + k
        qs[k] = device.state(t)
        com[k] = dyn.com(t)[:2]
        err["feet"][k] = math.sqrt(
            sum(float(np.dot(e, e)) for e in (f.error(t) for f in feetFeatures))
        )
        if couplings is not None:
            err["couplings"][k] = float(np.linalg.norm(couplings.feature.error(t)))
        err["wrist"][k] = float(np.linalg.norm(wristSig(t).translation - target))
        err["posture"][k] = float(np.linalg.norm(posture.feature.error(t)))
        for side, sig in soles.items():
            M, M0 = sig(t), sole0[side]
            drift[side][k, 0] = np.linalg.norm(M.translation - M0.translation)
            drift[side][k, 1] = np.linalg.norm(pin.log3(M0.rotation.T @ M.rotation))

    view = None
    url = pid = None
    wall = 0.0
    try:
        if viewer:
            view = attach_viewer(r, prefix)
            entities.append(view.name)
            url = view.url()
            proc = view.serverProcess
            pid = None if proc is None else proc.pid
            emit(f"viewer: open {url} in a browser (the loop runs at real time)")
        emit(
            f"reach {r.name}: {_WRIST} from {_xyz(start)} to {_xyz(target)} m "
            f"({np.linalg.norm(offset):.3f} m away); velocity control, dt = {dt:g} s, "
            f"{steps} ticks"
        )
        for i, text in enumerate(levels):
            emit(f"  level {i}: {text}")
        record(0)
        pacer = Pacer(dt, sleep)
        for k in range(1, steps + 1):
            device.increment(dt)
            res = sot.lastResult
            residuals[k - 1, : len(res.residuals)] = res.residuals
            methods.append(res.method)
            record(k)
            if view is not None:
                pacer.wait(k)
        wall = pacer.elapsed()
        late = pacer.late
        if view is not None:
            view.flush(1.0)
    finally:
        if view is not None:
            detach_viewer(r, view)

    # checks
    times = np.arange(n1) * dt
    com_distance = b[None, :] - com @ N.T
    jm = np.minimum(qs[:, lim_q] - lim_lo, lim_hi - qs[:, lim_q])
    joint_margin = jm.min(axis=1) if jm.size else np.full(n1, np.inf)
    joint_margin_min = dict(zip(lim_names, (float(x) for x in jm.min(axis=0)), strict=True))
    feet_drift = (
        max(float(d[:, 0].max()) for d in drift.values()),
        max(float(d[:, 1].max()) for d in drift.values()),
    )
    wrist_final = float(err["wrist"][-1])
    v_end = device.velocity(t0 + steps)
    # the wrist's speed at the end: its LOCAL Jacobian times the last velocity
    Jw = dyn.signal("J" + _WRIST)(t0 + steps)
    Mw = wristSig(t0 + steps)
    wrist_speed = float(np.linalg.norm(Mw.rotation @ (Jw[:3] @ v_end)))
    level1 = float(np.nanmax(residuals[:, 1]))
    bounds_report = device.boundsReport()
    clamped = sum(v["count"] for v in bounds_report.values())
    reached = wrist_final <= REACH_TOLERANCE
    g0, ginf, xref, p = gains
    asked = ((g0 - ginf) * p ** (wrist_final / xref) + ginf) * wrist_final
    out_of_reach = not reached and wrist_speed <= STALL_RATIO * asked
    checks = {
        "wrist": reached or out_of_reach,
        "feet": feet_drift[0] <= FEET_TOLERANCE and feet_drift[1] <= FEET_TOLERANCE,
        "com": bool((com_distance.min(axis=1) >= margin - COM_TOLERANCE).all()),
        "limits": bool((joint_margin >= -ROUNDING).all()) and clamped == 0,
        "level1": level1 <= LEVEL1_TOLERANCE,
        "couplings": couplings is None or float(err["couplings"].max()) <= COUPLING_TOLERANCE,
    }
    ok = all(checks.values())

    summary = _summary(times, err, drift, com_distance, residuals, duration)
    for line in summary.splitlines():
        emit(line)
    if reached:
        emit(f"wrist: reached the target ({wrist_final:.1e} m; tolerance {REACH_TOLERANCE:g} m)")
    elif out_of_reach:
        emit(
            f"wrist: target OUT OF REACH: stopped {wrist_final:.4f} m from it (speed "
            f"{wrist_speed:.1e} m/s): the best the levels above allow"
        )
    else:
        emit(
            f"wrist: NOT reached: {wrist_final:.4f} m from the target and still moving "
            f"({wrist_speed:.1e} m/s): run longer"
        )
    emit(
        f"feet: largest sole drift {feet_drift[0]:.1e} m, {feet_drift[1]:.1e} rad "
        f"(tolerance {FEET_TOLERANCE:g}){'' if checks['feet'] else ' EXCEEDED'}"
    )
    emit(
        f"CoM: at least {com_distance.min():.4f} m inside the support polygon's edges "
        f"(margin {margin:g} m){'' if checks['com'] else ' VIOLATED'}"
    )
    # joints resting on a limit from the start (Talos' grippers) say nothing of the run
    resting = [n for n, x in zip(lim_names, jm[0], strict=True) if x <= ROUNDING]
    moving = {n: v for n, v in joint_margin_min.items() if n not in resting}
    closest = min(moving, key=moving.get) if moving else None
    text = f"closest {closest}, {moving[closest]:.4f} from its limit" if closest else "none moved"
    if resting:
        text += f"; resting on a limit from the start: {_few(resting)}"
    verdict = (
        "every joint within its limits at every tick"
        if checks["limits"]
        else f"a joint LEFT its limits (by {max(0.0, -float(joint_margin.min())):.1e})"
    )
    emit(f"limits: {verdict} ({text}); device clamps: {clamped}")
    emit(f"level 1: largest residual {level1:.1e} (tolerance {LEVEL1_TOLERANCE:g})")
    if couplings is not None:
        emit(
            f"couplings: largest residual {float(err['couplings'].max()):.1e} rad "
            f"({_few(couplings.couplings.list())})"
        )
    if late:
        emit(f"{late} of {steps} ticks ended more than dt after their real-time deadline")

    result: dict[str, Any] = {
        "robot": r.name,
        "prefix": prefix,
        "entities": entities,
        "levels": levels,
        "ticks": steps,
        "dt": dt,
        "duration": steps * dt,
        "start": start,
        "target": target,
        "target_offset": offset,
        "time": times,
        "q": qs,
        "errors": err,
        "residuals": residuals,
        "methods": methods,
        "sole_drift": drift,
        "feet_drift": feet_drift,
        "com": com,
        "polygon": polygon,
        "com_distance": com_distance,
        "margin": margin,
        "joint_margin": joint_margin,
        "joint_margin_min": joint_margin_min,
        "wrist_final": wrist_final,
        "wrist_speed": wrist_speed,
        "reached": reached,
        "out_of_reach": out_of_reach,
        "checks": checks,
        "ok": ok,
        "summary": summary,
        "wall_time": wall,
        "viewer_url": url,
        "viewer_pid": pid,
        "late_ticks": late,
        "plot": None,
    }
    if plot is not None:
        result["plot"] = _plot(result, Path(plot))
        emit(f"plot: {result['plot']}")
    result["table"] = "\n".join(lines)
    return result


# -- text and plot -----------------------------------------------------------------------
def _few(names: Sequence[str], n: int = 3) -> str:
    """The first ``n`` names, then how many more."""
    more = f" and {len(names) - n} more" if len(names) > n else ""
    return ", ".join(names[:n]) + more


def _xyz(v: np.ndarray) -> str:
    return "(" + ", ".join(f"{x:.3f}" for x in v) + ")"


def _summary(
    times: np.ndarray,
    err: dict[str, Any],
    drift: dict[str, np.ndarray],
    com_distance: np.ndarray,
    residuals: np.ndarray,
    duration: float,
) -> str:
    """The convergence table: each task's error at a few times and at the end."""
    n = len(times) - 1
    dt = times[1] - times[0] if n else 1.0
    ticks = sorted({min(n, round(s / dt)) for s in _SUMMARY_TIMES if s < duration} | {n})
    header = (
        f"{'t [s]':>7}  {'wrist [m]':>10}  {'feet [m]':>9}  {'feet [rad]':>10}  "
        f"{'CoM in [m]':>10}  {'posture':>9}  {'level-1 res':>11}"
    )
    rows = [header]
    for k in ticks:
        d = np.max([drift[s][k] for s in drift], axis=0)
        res = residuals[k - 1, 1] if k > 0 else 0.0
        rows.append(
            f"{times[k]:7.3f}  {err['wrist'][k]:10.2e}  {d[0]:9.1e}  {d[1]:10.1e}  "
            f"{com_distance[k].min():10.4f}  {err['posture'][k]:9.2e}  {res:11.1e}"
        )
    return "\n".join(rows)


def _plot(result: dict[str, Any], path: Path) -> str:
    """Errors over time (log scale) and the CoM's path in the support polygon; a PNG
    saved with matplotlib's Agg canvas (no pyplot: the user's backend is left alone)."""
    try:
        from matplotlib.backends.backend_agg import FigureCanvasAgg
        from matplotlib.figure import Figure
    except ImportError:
        raise SotpyError(
            f"cannot save the plot {str(path)!r}: matplotlib is not installed "
            "(pip install 'sotpy[plot]')"
        ) from None
    fig = Figure(figsize=(11.0, 4.5), layout="constrained")
    FigureCanvasAgg(fig)
    ax, ax2 = fig.subplots(1, 2, width_ratios=(1.6, 1.0))
    t = result["time"]
    tiny = 1e-16
    series = [
        (result["errors"]["wrist"], "wrist to target [m]"),
        (result["errors"]["posture"], "posture |e| [rad]"),
        (np.max([d[:, 0] for d in result["sole_drift"].values()], axis=0), "sole drift [m]"),
        (np.max([d[:, 1] for d in result["sole_drift"].values()], axis=0), "sole drift [rad]"),
    ]
    if result["errors"]["couplings"] is not None:
        series.append((result["errors"]["couplings"], "coupling residual [rad]"))
    for y, label in series:
        ax.semilogy(t, np.maximum(y, tiny), label=label)
    ax.axhline(REACH_TOLERANCE, color="grey", lw=0.8, ls="--")
    ax.set_xlabel("time [s]")
    ax.set_ylabel("error")
    ax.set_ylim(1e-12, None)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(loc="lower left", fontsize=8)
    ax.set_title(f"{result['robot']}: task errors")
    poly = np.vstack((result["polygon"], result["polygon"][:1]))
    ax2.plot(poly[:, 0], poly[:, 1], "k-", label="support polygon")
    inner = _shrunk(result["polygon"], result["margin"])
    if inner is not None:
        inner = np.vstack((inner, inner[:1]))
        ax2.plot(inner[:, 0], inner[:, 1], "k--", lw=0.8, label=f"margin {result['margin']:g} m")
    c = result["com"]
    ax2.plot(c[:, 0], c[:, 1], "C0-", label="CoM projection")
    ax2.plot(c[0, 0], c[0, 1], "C0o", ms=4)
    ax2.plot(c[-1, 0], c[-1, 1], "C0s", ms=4)
    ax2.set_aspect("equal")
    ax2.set_xlabel("x [m]")
    ax2.set_ylabel("y [m]")
    ax2.grid(True, alpha=0.3)
    ax2.legend(loc="upper right", fontsize=8)
    ax2.set_title("CoM over the support polygon")
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        fig.savefig(path, dpi=100)
    except OSError as exc:
        raise SotpyError(f"cannot save the plot {str(path)!r}: {exc}") from None
    return str(path)


def _shrunk(vertices: np.ndarray, margin: float) -> np.ndarray | None:
    """The polygon with every edge moved inwards by ``margin`` (its vertices), or None
    if it vanishes. Vertex i is the intersection of the shrunk edges i - 1 and i."""
    from ..tasks.ready import polygonHalfPlanes

    N, b = polygonHalfPlanes(vertices)
    b = b - margin
    k = len(b)
    out = []
    for i in range(k):
        A = np.array([N[i - 1], N[i]])
        if abs(np.linalg.det(A)) < 1e-12:
            continue
        p = np.linalg.solve(A, [b[i - 1], b[i]])
        if (N @ p <= b + 1e-9).all():
            out.append(p)
    return np.array(out) if len(out) >= 3 else None
