r"""What the demos record, check and print, so that a demo (and an example) is only its
story: build the graph, run it, then hand the run to one of these.

- :class:`ReachLog`: the humanoid reaching demo (:mod:`sotpy.demos.reach`). Its
  :meth:`~ReachLog.record` reads, after each tick, the configuration, the CoM, each
  task's error, both soles' drift and the SOT's residuals; :meth:`~ReachLog.report`
  checks them against the tolerances of :mod:`sotpy.demos.reach` and returns the
  demo's result (the convergence table and the verdicts included).
- :class:`TourLog`: the robot tour (:mod:`sotpy.demos.robot_tour`): the wrist and the
  CoM every 10 ms, then the feet, the joint limits and the couplings.
- :class:`CollisionLog`: the collision demo (:mod:`sotpy.demos.collision`): the
  smallest distance over every pair, the closest pair's rate (its sign changes,
  :func:`signFlips`, :func:`maxFlipsInWindow`), the feet, the limits.
- :func:`freePrefix`: a prefix no entity of the pool uses yet, so that a demo never
  clashes with what a user already built.

The checks compare the run with what the demo promises, from the recorded signals;
``tests/test_reach.py`` and ``tests/test_robot_tour.py`` check the same runs again
against independent computations (Pinocchio's kinematics, scipy's convex hull).
"""

from __future__ import annotations

import math
import re
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
import pinocchio as pin

from ..graph import pool

__all__ = [
    "CollisionLog",
    "ReachLog",
    "TourLog",
    "freePrefix",
    "jointLimits",
    "maxFlipsInWindow",
    "signFlips",
]

#: Times of the rows of the reaching demo's convergence table (s), and its end.
SUMMARY_TIMES = (0.0, 0.1, 0.25, 0.5, 1.0, 2.0, 5.0, 10.0, 20.0, 50.0)
#: Largest excursion beyond a joint limit that counts as rounding (rad or m).
ROUNDING = 1e-9


def freePrefix(kind: str, robot: str | Path, suffixes: Sequence[str]) -> str:
    """``<kind>_<robot>``, or ``<kind>_<robot>_<k>`` (k = 2, 3, ...) when an entity
    named by one of ``suffixes`` (format strings of ``prefix``, e.g.
    ``"{prefix}_dynamic"``) exists; ``robot`` may be a path (its stem is used)."""
    text = str(robot)
    base = Path(text).stem if (text.endswith(".toml") or "/" in text or "\\" in text) else text
    base = re.sub(r"[^A-Za-z0-9_-]", "_", base) or "robot"
    k = 1
    while True:
        prefix = f"{kind}_{base}" if k == 1 else f"{kind}_{base}_{k}"
        if not any(pool.hasEntity(s.format(prefix=prefix)) for s in suffixes):
            return prefix
        k += 1


def jointLimits(model: pin.Model) -> tuple[np.ndarray, np.ndarray, np.ndarray, list[str]]:
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


def _prefix(robot: Any) -> str:
    """The prefix a robot was loaded with (its Dynamic is ``<prefix>_dynamic``)."""
    return robot.dynamic.name.removesuffix("_dynamic")


def _few(names: Sequence[str], n: int = 3) -> str:
    """The first ``n`` names, then how many more."""
    more = f" and {len(names) - n} more" if len(names) > n else ""
    return ", ".join(names[:n]) + more


def _xyz(v: np.ndarray) -> str:
    return "(" + ", ".join(f"{x:.3f}" for x in v) + ")"


def shrunkPolygon(vertices: np.ndarray, margin: float) -> np.ndarray | None:
    """The polygon with every edge moved inwards by ``margin`` (its vertices), or None
    if it vanishes. Vertex i is the intersection of the shrunk edges i - 1 and i."""
    from ..tasks.ready import polygonHalfPlanes

    N, b = polygonHalfPlanes(vertices)
    b = b - margin
    out = []
    for i in range(len(b)):
        A = np.array([N[i - 1], N[i]])
        if abs(np.linalg.det(A)) < 1e-12:
            continue
        p = np.linalg.solve(A, [b[i - 1], b[i]])
        if (N @ p <= b + 1e-9).all():
            out.append(p)
    return np.array(out) if len(out) >= 3 else None


# -- the reaching demo --------------------------------------------------------------------
class ReachLog:
    """The record of one run of the reaching demo, tick by tick, and its checks.

    ``ReachLog(robot, sot, target, steps, dt, margin, wrist_gain, damping)``: the
    robot of :func:`~sotpy.dynamics.load_robot` (its ready tasks ``left-ankle``,
    ``right-ankle``, ``balance``, ``right-wrist``, ``posture`` and, if it has some,
    ``couplings`` are those of the stack), the ``SOT``, the wrist's target (world, m),
    the number of ticks and the period (s) of the run, the CoM's margin (m), the
    wrist's adaptive gain ``(g0, ginf, xref, p)`` and the damping of the wrist and
    posture levels. It records the state the robot is in now (tick 0) at once; call
    :meth:`record` after each ``device.increment(dt)``, then :meth:`report`.
    """

    def __init__(
        self,
        robot: Any,
        sot: Any,
        target: np.ndarray,
        steps: int,
        dt: float,
        margin: float,
        wrist_gain: Sequence[float],
        damping: float = 0.0,
    ) -> None:
        self.robot, self.sot = robot, sot
        self.target = np.asarray(target, dtype=float)
        self.steps, self.dt, self.margin = steps, dt, margin
        self.gains = tuple(float(g) for g in wrist_gain)
        self.damping = damping
        dyn, tasks = robot.dynamic, robot.tasks
        self.t0 = t0 = max(robot.device.state.time, 0)
        self._feet = [tasks["left-ankle"].feature, tasks["right-ankle"].feature]
        self._couplings = tasks.get("couplings")
        self._posture = tasks["posture"].feature
        balance = tasks["balance"]
        self.polygon = balance.polygon.getVertices()
        self._N, self._b = balance.polygon.getNormals(), balance.polygon.getOffsets()
        self._wrist = dyn.signal("right-wrist")
        self.start = self._wrist(t0).translation.copy()
        self._soles = {}
        for side, foot in robot.feet.items():
            name = f"{_prefix(robot)}-{side}-sole"
            if not dyn.hasSignal(name):
                dyn.createPosition(name, foot.frame)
            self._soles[side] = dyn.signal(name)
        self._sole0 = {side: sig(t0).copy() for side, sig in self._soles.items()}
        n1 = steps + 1
        model = robot.model
        self.q = np.empty((n1, model.nq))
        self.com = np.empty((n1, 2))
        self.errors: dict[str, Any] = {k: np.empty(n1) for k in ("feet", "wrist", "posture")}
        self.errors["couplings"] = np.empty(n1) if self._couplings else None
        self.drift = {side: np.empty((n1, 2)) for side in self._soles}
        self.residuals = np.full((steps, 4), np.nan)
        self.methods: list[str] = []
        self.k = -1
        self._record(0)

    def levels(self) -> list[str]:
        """The stack, level 0 first, in words."""
        return [
            "joint limits (SOT, hard)",
            "contact: both feet fixed"
            + (" + couplings" if self._couplings else "")
            + f" + CoM in the support polygon (margin {self.margin:g} m)",
            "right-wrist position (selec 111000)",
            "posture (half-sitting)",
        ]

    def header(self) -> str:
        """What the run is about to do, and the stack."""
        offset = self.target - self.start
        lines = [
            f"reach {self.robot.name}: right-wrist from {_xyz(self.start)} to "
            f"{_xyz(self.target)} m ({np.linalg.norm(offset):.3f} m away); velocity "
            f"control, dt = {self.dt:g} s, {self.steps} ticks"
        ]
        lines += [f"  level {i}: {text}" for i, text in enumerate(self.levels())]
        return "\n".join(lines)

    def record(self) -> None:
        """Record the tick the device has just written, and the SOT's result."""
        k = self.k + 1
        if k > self.steps:
            raise IndexError(f"ReachLog: already {self.steps} ticks recorded")
        res = self.sot.lastResult
        self.residuals[k - 1, : len(res.residuals)] = res.residuals
        self.methods.append(res.method)
        self._record(k)

    def _record(self, k: int) -> None:
        t = self.t0 + k
        dyn = self.robot.dynamic
        self.q[k] = self.robot.device.state(t)
        self.com[k] = dyn.com(t)[:2]
        self.errors["feet"][k] = math.sqrt(
            sum(float(np.dot(e, e)) for e in (f.error(t) for f in self._feet))
        )
        if self._couplings is not None:
            self.errors["couplings"][k] = float(np.linalg.norm(self._couplings.feature.error(t)))
        self.errors["wrist"][k] = float(np.linalg.norm(self._wrist(t).translation - self.target))
        self.errors["posture"][k] = float(np.linalg.norm(self._posture.error(t)))
        for side, sig in self._soles.items():
            M, M0 = sig(t), self._sole0[side]
            self.drift[side][k, 0] = np.linalg.norm(M.translation - M0.translation)
            self.drift[side][k, 1] = np.linalg.norm(pin.log3(M0.rotation.T @ M.rotation))
        self.k = k

    def report(self, wall_time: float = 0.0) -> dict[str, Any]:
        """Check the run and describe it: the result of
        :func:`~sotpy.demos.reach.run_reach` (its docstring lists the keys), with
        ``table``, the text to print (the convergence table, then one verdict per
        check)."""
        from . import reach as demo

        if self.k != self.steps:
            raise ValueError(f"ReachLog: {self.k} of {self.steps} ticks recorded")
        r, err, drift, steps = self.robot, self.errors, self.drift, self.steps
        model, dyn, device = r.model, r.dynamic, r.device
        n1 = steps + 1
        times = np.arange(n1) * self.dt
        com_distance = self._b[None, :] - self.com @ self._N.T
        lim_q, lim_lo, lim_hi, lim_names = jointLimits(model)
        jm = np.minimum(self.q[:, lim_q] - lim_lo, lim_hi - self.q[:, lim_q])
        joint_margin = jm.min(axis=1) if jm.size else np.full(n1, np.inf)
        joint_margin_min = dict(zip(lim_names, (float(x) for x in jm.min(axis=0)), strict=True))
        feet_drift = (
            max(float(d[:, 0].max()) for d in drift.values()),
            max(float(d[:, 1].max()) for d in drift.values()),
        )
        wrist_final = float(err["wrist"][-1])
        t_end = self.t0 + steps
        v_end = device.velocity(t_end)
        # the wrist's speed at the end: its LOCAL Jacobian times the last velocity
        Jw = dyn.signal("Jright-wrist")(t_end)
        wrist_speed = float(np.linalg.norm(self._wrist(t_end).rotation @ (Jw[:3] @ v_end)))
        level1 = float(np.nanmax(self.residuals[:, 1]))
        clamped = sum(v["count"] for v in device.boundsReport().values())
        reached = wrist_final <= demo.REACH_TOLERANCE
        g0, ginf, xref, p = self.gains
        asked = ((g0 - ginf) * p ** (wrist_final / xref) + ginf) * wrist_final
        out_of_reach = not reached and wrist_speed <= demo.STALL_RATIO * asked
        couplings = self._couplings
        checks = {
            "wrist": reached or out_of_reach,
            "feet": feet_drift[0] <= demo.FEET_TOLERANCE and feet_drift[1] <= demo.FEET_TOLERANCE,
            "com": bool((com_distance.min(axis=1) >= self.margin - demo.COM_TOLERANCE).all()),
            "limits": bool((joint_margin >= -ROUNDING).all()) and clamped == 0,
            "level1": level1 <= demo.LEVEL1_TOLERANCE,
            "couplings": couplings is None
            or float(err["couplings"].max()) <= demo.COUPLING_TOLERANCE,
        }
        summary = self.summary(times, com_distance)
        lines = summary.splitlines()
        if reached:
            lines.append(
                f"wrist: reached the target ({wrist_final:.1e} m; tolerance "
                f"{demo.REACH_TOLERANCE:g} m)"
            )
        elif out_of_reach:
            lines.append(
                f"wrist: target OUT OF REACH: stopped {wrist_final:.4f} m from it (speed "
                f"{wrist_speed:.1e} m/s): the best the levels above allow"
            )
        else:
            lines.append(
                f"wrist: NOT reached: {wrist_final:.4f} m from the target and still moving "
                f"({wrist_speed:.1e} m/s): run longer"
            )
        lines.append(
            f"feet: largest sole drift {feet_drift[0]:.1e} m, {feet_drift[1]:.1e} rad "
            f"(tolerance {demo.FEET_TOLERANCE:g}){'' if checks['feet'] else ' EXCEEDED'}"
        )
        lines.append(
            f"CoM: at least {com_distance.min():.4f} m inside the support polygon's edges "
            f"(margin {self.margin:g} m){'' if checks['com'] else ' VIOLATED'}"
        )
        # joints resting on a limit from the start (Talos' grippers) say nothing of the run
        resting = [n for n, x in zip(lim_names, jm[0], strict=True) if x <= ROUNDING]
        moving = {n: v for n, v in joint_margin_min.items() if n not in resting}
        closest = min(moving, key=moving.get) if moving else None
        text = (
            f"closest {closest}, {moving[closest]:.4f} from its limit" if closest else "none moved"
        )
        if resting:
            text += f"; resting on a limit from the start: {_few(resting)}"
        verdict = (
            "every joint within its limits at every tick"
            if checks["limits"]
            else f"a joint LEFT its limits (by {max(0.0, -float(joint_margin.min())):.1e})"
        )
        lines.append(f"limits: {verdict} ({text}); device clamps: {clamped}")
        lines.append(
            f"level 1: largest residual {level1:.1e} (tolerance {demo.LEVEL1_TOLERANCE:g})"
        )
        if couplings is not None:
            lines.append(
                f"couplings: largest residual {float(err['couplings'].max()):.1e} rad "
                f"({_few(couplings.couplings.list())})"
            )
        return {
            "robot": r.name,
            "prefix": _prefix(r),
            "levels": self.levels(),
            "ticks": steps,
            "dt": self.dt,
            "duration": steps * self.dt,
            "start": self.start,
            "target": self.target,
            "target_offset": self.target - self.start,
            "time": times,
            "q": self.q,
            "errors": err,
            "residuals": self.residuals,
            "methods": self.methods,
            "sole_drift": drift,
            "feet_drift": feet_drift,
            "com": self.com,
            "polygon": self.polygon,
            "polygon_inner": shrunkPolygon(self.polygon, self.margin),
            "com_distance": com_distance,
            "margin": self.margin,
            "joint_margin": joint_margin,
            "joint_margin_min": joint_margin_min,
            "wrist_final": wrist_final,
            "wrist_speed": wrist_speed,
            "reached": reached,
            "out_of_reach": out_of_reach,
            "checks": checks,
            "ok": all(checks.values()),
            "summary": summary,
            "tolerances": {"wrist": demo.REACH_TOLERANCE, "feet": demo.FEET_TOLERANCE},
            "table": "\n".join(lines),
            "wall_time": wall_time,
        }

    def summary(self, times: np.ndarray, com_distance: np.ndarray) -> str:
        """The convergence table: each task's error at a few times and at the end."""
        err, drift, residuals = self.errors, self.drift, self.residuals
        n = len(times) - 1
        duration = n * self.dt
        ticks = sorted({min(n, round(s / self.dt)) for s in SUMMARY_TIMES if s < duration} | {n})
        rows = [
            f"{'t [s]':>7}  {'wrist [m]':>10}  {'feet [m]':>9}  {'feet [rad]':>10}  "
            f"{'CoM in [m]':>10}  {'posture':>9}  {'level-1 res':>11}"
        ]
        for k in ticks:
            d = np.max([drift[s][k] for s in drift], axis=0)
            res = residuals[k - 1, 1] if k > 0 else 0.0
            rows.append(
                f"{times[k]:7.3f}  {err['wrist'][k]:10.2e}  {d[0]:9.1e}  {d[1]:10.1e}  "
                f"{com_distance[k].min():10.4f}  {err['posture'][k]:9.2e}  {res:11.1e}"
            )
        return "\n".join(rows)


# -- the robot tour ----------------------------------------------------------------------
def _tourXyz(p: np.ndarray) -> str:
    return " ".join(f"{0.0 if abs(x) < 5e-7 else x:8.4f}" for x in p)


class TourLog:
    """The record of one robot tour and its checks.

    ``TourLog(robot, sine, steps, dt)``: the robot of
    :func:`~sotpy.dynamics.load_robot`, the
    :class:`~sotpy.demos.robot_tour.JointSineVelocity` plugged into its device, the
    number of ticks and the period (s). It follows the first op point of
    :data:`~sotpy.demos.robot_tour.WRIST_OP_POINTS` the robot has, and both soles.
    :meth:`record` after each ``device.increment(dt)`` keeps the wrist, the CoM and the
    configuration every 10 ms (and at the end), and gives the table row to print once
    a second (else None); :meth:`report` checks the run.
    """

    def __init__(self, robot: Any, sine: Any, steps: int, dt: float) -> None:
        from .robot_tour import WRIST_OP_POINTS

        self.robot, self.sine, self.steps, self.dt = robot, sine, steps, dt
        model, amplitudes = robot.model, sine.getAmplitudes()
        #: the selected joints that swing (a joint resting on a limit does not)
        self.joints = [
            n for n in sine.getJoints() if amplitudes[model.joints[model.getJointId(n)].idx_v] > 0
        ]
        dyn = robot.dynamic
        self.t0 = t0 = max(robot.device.state.time, 0)
        wrist = next((op for op in WRIST_OP_POINTS if op in robot.opPoints), None)
        if wrist is None:
            wrist = next(iter(robot.opPoints), None)
        if wrist is None:
            from ..errors import SotpyError

            raise SotpyError(f"robot tour: robot {robot.name!r} has no op point to follow")
        self.wrist = wrist
        self._wristSig = dyn.signal(wrist)
        self._soles = {}
        for side, foot in robot.feet.items():
            name = f"tour-{side}-sole"
            if not dyn.hasSignal(name):
                dyn.createPosition(name, foot.frame)
            self._soles[side] = dyn.signal(name)
        self._sole0 = {side: sig(t0) for side, sig in self._soles.items()}
        self._coupled = [
            (c.joint, c.master, c.multiplier, c.offset) for c in robot.couplings.values()
        ]
        self._res0 = self._couplingResiduals(robot.device.state(t0))
        self._every = max(1, round(1.0 / dt))
        self._sample = max(1, round(0.01 / dt))
        self.path: list[np.ndarray] = []
        self.q: list[np.ndarray] = []
        self.k = 0
        self._keep(t0)

    def _couplingResiduals(self, q: np.ndarray) -> np.ndarray:
        model = self.robot.model
        idx = {n: model.joints[model.getJointId(n)].idx_q for c in self._coupled for n in c[:2]}
        return np.array([q[idx[j]] - (m * q[idx[mst]] + off) for j, mst, m, off in self._coupled])

    def _keep(self, t: int) -> np.ndarray:
        dyn = self.robot.dynamic
        row = np.concatenate(([(t - self.t0) * self.dt], self._wristSig(t).translation, dyn.com(t)))
        self.path.append(row)
        self.q.append(np.array(self.robot.device.state(t)))
        return row

    def header(self) -> str:
        """What swings, and the table's header with its first row (tick 0)."""
        sine, joints = self.sine, self.joints
        first = self.path[0]
        return (
            f"robot {self.robot.name}: {len(joints)} joints swing by up to "
            f"{sine.getAmplitude():g} rad at {sine.getFrequency():g} Hz (velocity control, "
            f"dt = {self.dt:g} s, {self.steps} ticks): {', '.join(joints)}\n"
            f"{'tick':>7} {'t [s]':>7}  {self.wrist + ' x y z [m]':<26}  CoM x y z [m]\n"
            + self._row(self.t0, first)
        )

    def _row(self, t: int, values: np.ndarray) -> str:
        return f"{t:7d} {values[0]:7.3f}  {_tourXyz(values[1:4])}  {_tourXyz(values[4:7])}"

    def record(self) -> str | None:
        """Record the tick just written; the table row to print (once a second and at
        the end), else None."""
        self.k += 1
        k, t = self.k, self.t0 + self.k
        if k % self._sample == 0 or k == self.steps:
            values = self._keep(t)
            if k % self._every == 0 or k == self.steps:
                return self._row(t, values)
        return None

    def report(self, wall_time: float = 0.0) -> dict[str, Any]:
        """Check the run: the result of :func:`~sotpy.demos.robot_tour.run_robot_tour`
        (its docstring lists the keys), ``table`` holding the verdicts to print."""
        from .robot_tour import COUPLING_TOLERANCE, FEET_TOLERANCE

        r, device, joints = self.robot, self.robot.device, self.joints
        t_end = self.t0 + self.k
        q_end = device.state(t_end)
        feet_drift = None
        if self._soles:
            drifts = []
            for side, sig in self._soles.items():
                m0, m1 = self._sole0[side], sig(t_end)
                drifts.append(float(np.linalg.norm(m1.translation - m0.translation)))
                drifts.append(float(np.linalg.norm(pin.log3(m0.rotation.T @ m1.rotation))))
            feet_drift = max(drifts)
        feet_fixed = None if feet_drift is None else feet_drift <= FEET_TOLERANCE
        bounds = device.boundsReport()
        clamped = sum(b["count"] for b in bounds.values())
        residuals = self._couplingResiduals(q_end) - self._res0
        coupling_error = float(np.max(np.abs(residuals), initial=0.0))
        couplings_ok = coupling_error <= COUPLING_TOLERANCE
        trajectory = np.array(self.path)
        travel = float(np.max(np.linalg.norm(trajectory[:, 1:4] - trajectory[0, 1:4], axis=1)))
        lines = []
        if feet_fixed is None:
            lines.append("feet: none (fixed base)")
        else:
            sides = " and ".join(f"{s} sole" for s in self._soles)
            lines.append(
                f"feet: {sides} {'did not move' if feet_fixed else 'MOVED'} (largest drift "
                f"{feet_drift:.1e} m or rad; tolerance {FEET_TOLERANCE:.0e})"
            )
        if clamped == 0:
            lines.append("limits: no joint left its limits (boundsReport empty)")
        else:
            detail = "; ".join(
                f"{kind}: {', '.join(f'{j} x{n}' for j, n in b['joints'].items())}"
                for kind, b in bounds.items()
                if b["count"]
            )
            lines.append(f"limits: {clamped} values CLAMPED ({detail})")
        if self._coupled:
            lines.append(
                f"couplings: {len(self._coupled)} coupled joint(s) "
                f"{'still follow' if couplings_ok else 'NO LONGER follow'} their master "
                f"(largest error {coupling_error:.1e}; tolerance {COUPLING_TOLERANCE:.0e})"
            )
        lines.append(f"{r.name}'s {self.wrist} travelled up to {travel:.3f} m from its start")
        model = r.model
        lim_q, lim_lo, lim_hi, lim_names = jointLimits(model)
        swinging = [n for n in joints if n in lim_names]
        pick = [lim_names.index(n) for n in swinging]
        return {
            "robot": r.name,
            "prefix": _prefix(r),
            "joints": list(joints),
            "amplitudes": self.sine.getAmplitudes(),
            "ticks": self.steps,
            "dt": float(self.dt),
            "duration": self.steps * float(self.dt),
            "wrist": self.wrist,
            "path": trajectory,
            "q": np.array(self.q),
            "limits": {
                "joints": swinging,
                "index": lim_q[pick],
                "lower": lim_lo[pick],
                "upper": lim_hi[pick],
            },
            "wrist_travel": travel,
            "feet_drift": feet_drift,
            "feet_fixed": feet_fixed,
            "bounds": bounds,
            "bounds_ok": clamped == 0,
            "coupling_error": coupling_error,
            "couplings_ok": couplings_ok,
            "ok": feet_fixed is not False and clamped == 0 and couplings_ok,
            "table": "\n".join(lines),
            "wall_time": wall_time,
        }


# -- the collision demo ------------------------------------------------------------------
def signFlips(rates: np.ndarray, deadband: float) -> np.ndarray:
    """The ticks at which a rate changes sign: ``rates[k]`` and the last rate before it
    whose magnitude exceeded ``deadband`` have opposite signs (rates within the deadband,
    or NaN, carry no sign). Returns the indices ``k``."""
    flips = []
    last = 0.0
    for k, r in enumerate(rates):
        if not (abs(r) > deadband):  # NaN or inside the deadband: no sign
            continue
        s = 1.0 if r > 0 else -1.0
        if last and s != last:
            flips.append(k)
        last = s
    return np.array(flips, dtype=int)


def maxFlipsInWindow(flips: np.ndarray, window: int) -> int:
    """The largest number of sign changes (:func:`signFlips`) in any ``window``
    consecutive ticks."""
    if flips.shape[0] == 0:
        return 0
    ends = np.searchsorted(flips, flips + window, side="left")
    return int((ends - np.arange(flips.shape[0])).max())


class CollisionLog:
    """The record of the collision demo (:mod:`sotpy.demos.collision`), tick by tick:
    the smallest distance over every pair (the feature's ``minDistance``, exact under
    d_i), the closest pair and its rate, the wrist's distance to its target, the soles'
    drift and the SOT's residuals; then its checks (:meth:`report`).

    ``CollisionLog(robot, sot, feature, target, steps, dt)``; call :meth:`record` after
    each ``device.increment(dt)``.
    """

    def __init__(
        self, robot: Any, sot: Any, feature: Any, target: np.ndarray, steps: int, dt: float
    ) -> None:
        self.robot, self.sot, self.feature = robot, sot, feature
        self.target = np.asarray(target, dtype=float)
        self.steps, self.dt = steps, dt
        dyn = robot.dynamic
        self.t0 = t0 = max(robot.device.state.time, 0)
        self._wrist = dyn.signal("right-wrist")
        self.start = self._wrist(t0).translation.copy()
        self._soles = {}
        for side, foot in robot.feet.items():
            name = f"{_prefix(robot)}-{side}-sole"
            if not dyn.hasSignal(name):
                dyn.createPosition(name, foot.frame)
            self._soles[side] = dyn.signal(name)
        self._sole0 = {side: sig(t0).copy() for side, sig in self._soles.items()}
        n1 = steps + 1
        self.q = np.empty((n1, robot.model.nq))
        self.min_distance = np.empty(n1)
        self.closest = np.full(n1, -1, dtype=int)  # pair index, -1: none under d_i
        self.closest_rate = np.full(n1, np.nan)  # m/s, from tick k to k + 1
        self.rows = np.zeros(n1, dtype=int)
        self.wrist = np.empty(n1)
        self.drift = np.zeros(n1)
        self.residuals: list[np.ndarray] = []
        self._last: dict[int, float] = {}
        self.k = -1
        self._record(0)

    def record(self) -> None:
        """Record the tick the device has just written, and the SOT's result."""
        if self.k + 1 > self.steps:
            raise IndexError(f"CollisionLog: already {self.steps} ticks recorded")
        self.residuals.append(np.array(self.sot.lastResult.residuals))
        self._record(self.k + 1)

    def _record(self, k: int) -> None:
        t = self.t0 + k
        f = self.feature
        self.q[k] = self.robot.device.state(t)
        d = f.error(t)
        pairs = f.activePairs(t).astype(int)
        self.min_distance[k] = f.minDistance(t)
        self.rows[k] = d.shape[0]
        now = dict(zip(pairs.tolist(), d.tolist(), strict=True))
        if k > 0 and self.closest[k - 1] >= 0:
            p = int(self.closest[k - 1])
            if p in now:  # the closest pair of the previous tick, one tick later
                self.closest_rate[k - 1] = (now[p] - self._last[p]) / self.dt
        if d.shape[0]:
            self.closest[k] = int(pairs[int(np.argmin(d))])
        self._last = now
        self.wrist[k] = float(np.linalg.norm(self._wrist(t).translation - self.target))
        drift = 0.0
        for side, sig in self._soles.items():
            M, M0 = sig(t), self._sole0[side]
            drift = max(drift, float(np.linalg.norm(M.translation - M0.translation)))
            drift = max(drift, float(np.linalg.norm(pin.log3(M0.rotation.T @ M.rotation))))
        self.drift[k] = drift
        self.k = k

    def report(self, wall_time: float = 0.0) -> dict[str, Any]:
        """Check the run: the result of
        :func:`~sotpy.demos.collision.run_talos_collision` (its docstring lists the
        keys), with ``table``, the verdicts to print."""
        from . import collision as demo

        if self.k != self.steps:
            raise ValueError(f"CollisionLog: {self.k} of {self.steps} ticks recorded")
        f, r = self.feature, self.robot
        ds = float(f.safetyDistance.value)
        lowest = float(self.min_distance.min())
        worst = int(self.min_distance.argmin())
        flips = signFlips(self.closest_rate, demo.CHATTER_DEADBAND)
        chatter = maxFlipsInWindow(flips, demo.CHATTER_WINDOW)
        active = int((self.closest >= 0).sum())
        lim_q, lim_lo, lim_hi, _ = jointLimits(r.model)
        jm = np.minimum(self.q[:, lim_q] - lim_lo, lim_hi - self.q[:, lim_q])
        clamped = sum(v["count"] for v in r.device.boundsReport().values())
        res = np.array(self.residuals)
        levels = self.sot.list()
        ic = 1 + levels.index(demo.COLLISION_TASK.format(prefix=_prefix(r)))
        collision_residual = float(res[:, ic].max()) if res.size else 0.0
        wrist_final = float(self.wrist[-1])
        reached = wrist_final <= demo.REACH_TOLERANCE
        checks = {
            "distance": lowest >= ds - demo.DISTANCE_TOLERANCE,
            "chatter": chatter <= demo.CHATTER_FLIPS,
            "feet": float(self.drift.max()) <= demo.FEET_TOLERANCE,
            "limits": bool((jm >= -ROUNDING).all()) and clamped == 0,
            "collision_level": collision_residual <= demo.LEVEL_TOLERANCE,
        }
        closest = f.pairName(int(self.closest[worst])) if self.closest[worst] >= 0 else "none"
        lines = [
            f"distance: smallest over every pair and tick {lowest:.5f} m at tick {worst} "
            f"({closest}); safety distance {ds:g} m (tolerance {demo.DISTANCE_TOLERANCE:g} m)"
            + ("" if checks["distance"] else " VIOLATED"),
            f"chatter: the closest pair's rate changed sign {len(flips)} times, at most "
            f"{chatter} in any {demo.CHATTER_WINDOW} ticks (allowed {demo.CHATTER_FLIPS}; "
            f"deadband {demo.CHATTER_DEADBAND:g} m/s; a pair under d_i at {active} of "
            f"{self.steps + 1} ticks)" + ("" if checks["chatter"] else " CHATTER"),
            f"collision level: largest residual {collision_residual:.1e} m/s (tolerance "
            f"{demo.LEVEL_TOLERANCE:g}); rows per tick {int(self.rows.min())}.."
            f"{int(self.rows.max())}",
            f"wrist: {wrist_final:.4f} m from the target"
            + (
                " (reached)"
                if reached
                else f" (residual of its level at the end: {float(res[-1, ic + 1]):.3g} m/s)"
                if res.size
                else ""
            ),
            f"feet: largest sole drift {float(self.drift.max()):.1e} (m or rad; tolerance "
            f"{demo.FEET_TOLERANCE:g})" + ("" if checks["feet"] else " EXCEEDED"),
            f"limits: {'every joint within its limits' if checks['limits'] else 'LEFT'}; "
            f"device clamps: {clamped}",
        ]
        return {
            "robot": r.name,
            "prefix": _prefix(r),
            "levels": ["joint limits (SOT, hard)", *levels],
            "ticks": self.steps,
            "dt": self.dt,
            "duration": self.steps * self.dt,
            "start": self.start,
            "target": self.target,
            "q": self.q,
            "min_distance": self.min_distance,
            "min_distance_overall": lowest,
            "closest": self.closest,
            "closest_rate": self.closest_rate,
            "sign_flips": flips,
            "max_flips_in_window": chatter,
            "rows": self.rows,
            "wrist": self.wrist,
            "wrist_final": wrist_final,
            "reached": reached,
            "residuals": res,
            "collision_residual": collision_residual,
            "feet_drift": float(self.drift.max()),
            "checks": checks,
            "ok": all(checks.values()),
            "table": "\n".join(lines),
            "wall_time": wall_time,
        }
