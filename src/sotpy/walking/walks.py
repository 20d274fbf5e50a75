r"""The two walks a :class:`~sotpy.walking.PatternGenerator` runs, as functions of time:
plain classes over arrays, no graph.

- :class:`FootstepWalk`: the walk of a :class:`~sotpy.walking.plan.StepPlan` (steps given
  in advance: ``:stepseq``, ``addStep``). The preview controller
  (:mod:`sotpy.walking.preview`) is run over the whole plan when the plan is made, one
  sample per period ``T``, and its states and jerks are kept: a tick only evaluates the
  exact cubic of its sample (:func:`~sotpy.walking.preview.stateAt`). Steps appended
  during the walk re-run the controller from the current sample with its saved state
  (integrated error included), so the CoM's trajectory before it is unchanged. An
  optional correction (the dynamic filter, :mod:`sotpy.walking.dynamic_filter`) is added
  sample by sample; steps appended later keep it as it was and are not filtered.
- :class:`VelocityWalk`: the walk of a velocity command ``(vx, vy, omega)``
  (``velocitydes``), planned by the MPC of :mod:`sotpy.walking.mpc` once per MPC period
  (0.1 s), in closed loop on its own cart-table state (as jrl-walkgen's online modes:
  open loop on the robot). The MPC's first jerk is applied for one period and the CoM
  evaluated at the tick by the same exact cubic. The swing foot goes to the MPC's next
  footstep along a quintic in x, y and yaw that is re-planned at each MPC sample from
  the foot's current position, velocity and acceleration (so C2 through every re-plan)
  to rest at the landing time; in the last :data:`FREEZE` s of a swing the target is
  kept (and given to the MPC as fixed). The height is the plan's ``h b(s)``
  (:mod:`sotpy.walking.plan`). The foot lands one MPC period before the MPC's step ends:
  the MPC constrains the ZMP at its samples only, and between its last sample on the old
  sole and its first on the new one the ZMP moves across, which must happen while both
  feet are down (with the landing at the MPC's step end, the ZMP left the support before
  the foot was down: 90 mm outside the soles on Talos, measured). A command without a
  plan is replaced by a stop, then by standing in double support where the feet are
  (``VelocityWalk.fault`` says why).

Both give, at a time ``t`` (s since the walk began): the CoM state (3 x 2), the feet
(each sole frame's position, yaw and velocity), the footprints on the ground, the
contact phase (1 left, -1 right, 0 both) and the ZMP reference.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from ..errors import SolverError
from .mpc import MPCParameters, MPCResult, VelocityMPC
from .plan import LIFT_RATIO, Footprint, Sole, StepPlan, _height
from .preview import PreviewController, PreviewGains, stateAt

__all__ = ["FREEZE", "FootstepWalk", "VelocityWalk", "quinticTo"]

#: In the last FREEZE seconds of a swing, the velocity walk keeps the landing target.
FREEZE = 0.15


class FootstepWalk:
    """The walk of ``plan`` from the CoM at rest at ``com`` (x, y; m) with the preview
    ``gains`` (module doc). ``settle`` (s) is how long the CoM is simulated after the
    plan's end (default one preview time: the gains have died out)."""

    def __init__(
        self, plan: StepPlan, gains: PreviewGains, com: np.ndarray, settle: float | None = None
    ) -> None:
        self.plan, self.gains, self.T = plan, gains, gains.period
        self.settle = gains.F.size * self.T if settle is None else settle
        s0 = np.zeros((3, 2))
        s0[0] = com[:2]
        self._origin = s0[0].copy()
        self.correction: tuple[np.ndarray, np.ndarray] | None = None
        self._S = np.zeros((0, 3, 2))
        self._U = np.zeros((0, 2))
        self._E = np.zeros((0, 2))
        self._run(0, PreviewController(gains, s0))

    @property
    def samples(self) -> int:
        """The number of samples computed (the plan and its settling)."""
        return len(self._U)

    @property
    def duration(self) -> float:
        """The plan's duration (s), its settling excluded."""
        return self.plan.duration

    def _run(self, k0: int, ctrl: PreviewController) -> None:
        T, n = self.T, self.gains.F.size
        K = round((self.plan.duration + self.settle) / T)
        refs = self.plan.zmpReference(np.arange(k0, K + n + 1) * T)
        S, U, E = np.empty((K - k0, 3, 2)), np.empty((K - k0, 2)), np.empty((K - k0, 2))
        for i in range(K - k0):
            S[i], E[i] = ctrl.state, ctrl.errorSum
            U[i] = ctrl.step(refs[i : i + n + 1])
        self._S = np.concatenate((self._S[:k0], S))
        self._U = np.concatenate((self._U[:k0], U))
        self._E = np.concatenate((self._E[:k0], E))
        if self.correction is not None:
            # steps added during a walk are not filtered: the correction made for the
            # plan before them is kept as it was (dropping it would make the CoM's
            # reference jump), and is zero on the new samples
            dS, dU = self.correction
            n = len(self._U)
            pad = max(n - len(dU), 0)
            self.correction = (
                np.concatenate((dS[:n], np.zeros((pad, 3, 2)))),
                np.concatenate((dU[:n], np.zeros((pad, 2)))),
            )

    def extend(self, steps: list[Footprint], now: float) -> None:
        """Append ``steps`` (online): the plan is extended and the controller re-run from
        the sample after ``now`` (s), from its saved state."""
        self.plan.extend(steps, now)
        k = min(int(now / self.T) + 1, self.samples - 1)
        ctrl = PreviewController(self.gains, self._S[k], self._origin)
        ctrl.errorSum = self._E[k].copy()
        self._run(k, ctrl)

    def setCorrection(self, dS: np.ndarray, dU: np.ndarray) -> None:
        """Add the states ``dS`` (samples x 3 x 2) and jerks ``dU`` (samples x 2) of a
        second-stage correction to the trajectory (the dynamic filter)."""
        self.correction = (dS, dU)

    def state(self, t: float) -> np.ndarray:
        """The CoM's state at ``t`` (3 x 2: rows c, dc, ddc; columns x, y)."""
        k = min(max(int(t / self.T), 0), self.samples - 1)
        tau = min(t - k * self.T, self.T)
        S, U = self._S[k], self._U[k]
        if self.correction is not None:
            S, U = S + self.correction[0][k], U + self.correction[1][k]
        if t >= self.samples * self.T:  # after the settling: at rest where it ended
            x = stateAt(S, U, self.T)
            x[1:] = 0.0
            return x
        return stateAt(S, U, tau)

    def plannedZmp(self, t: float) -> np.ndarray:
        """The first stage's cart-table ZMP at ``t`` (size 2, m): the ZMP the plan was
        made for (the dynamic filter's correction excluded)."""
        k = min(max(int(t / self.T), 0), self.samples - 1)
        x = stateAt(self._S[k], self._U[k], min(t - k * self.T, self.T))
        return x[0] - (self.gains.comHeight / self.gains.gravity) * x[2]

    def sampleStates(self) -> np.ndarray:
        """The first-stage states at every sample (samples x 3 x 2)."""
        return self._S.copy()

    def feet(self, t: float) -> dict[str, tuple[np.ndarray, np.ndarray, np.ndarray]]:
        """The plan's feet at ``t`` (:meth:`StepPlan.feet`)."""
        return self.plan.feet(t)

    def footprints(self, t: float) -> dict[str, Footprint]:
        """The footprints of the feet at ``t`` (a swinging foot's: where it left)."""
        return self.plan.footprintsAt(t)

    def contactPhase(self, t: float) -> int:
        """SoT's ``contactphase`` at ``t``."""
        return self.plan.contactPhase(t)

    def zmp(self, t: float) -> np.ndarray:
        """The ZMP reference at ``t`` (size 2, m)."""
        return self.plan.zmpAt(t)

    def steps(self) -> list[Footprint]:
        """Every footprint stepped on, in order (the plan's steps)."""
        return list(self.plan.steps)

    def finished(self, t: float) -> bool:
        """Whether the CoM has settled after the plan's end."""
        return t >= self.plan.duration + self.settle

    def firstSwing(self, side: str) -> tuple[float, float] | None:
        """``(lift, land)`` (s) of the ``side`` foot's first swing, None if it has none."""
        for ph in self.plan.phases:
            if ph.swing is not None and ph.swing[1].side == side:
                return ph.start, ph.end
        return None


def quinticTo(
    p0: np.ndarray, v0: np.ndarray, a0: np.ndarray, p1: np.ndarray, T: float
) -> np.ndarray:
    """The coefficients ``c`` (6 x d, lowest degree first) of the quintic from position,
    velocity and acceleration ``(p0, v0, a0)`` at 0 to ``p1`` at rest (zero velocity and
    acceleration) at ``T`` (s): ``p(s) = sum_i c_i s^i``."""
    c0, c1, c2 = p0, v0, a0 / 2
    M = np.array(
        [[T**3, T**4, T**5], [3 * T**2, 4 * T**3, 5 * T**4], [6 * T, 12 * T**2, 20 * T**3]]
    )
    rhs = np.stack((p1 - c0 - c1 * T - c2 * T * T, -v0 - 2 * c2 * T, -a0))
    c345 = np.linalg.solve(M, rhs)
    return np.vstack((c0, c1, c2, c345))


def _poly(c: np.ndarray, s: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    p = c[0] + s * (c[1] + s * (c[2] + s * (c[3] + s * (c[4] + s * c[5]))))
    v = c[1] + s * (2 * c[2] + s * (3 * c[3] + s * (4 * c[4] + s * 5 * c[5])))
    a = 2 * c[2] + s * (6 * c[3] + s * (12 * c[4] + s * 20 * c[5]))
    return p, v, a


class VelocityWalk:
    """The velocity-driven walk (module doc) from the footprints ``initial`` (side ->
    :class:`Footprint`, standing), the CoM at rest at ``com`` (x, y; m), on soles
    ``sole``, with the MPC's ``params`` and the swing height ``stepHeight`` (m).

    :meth:`advance` runs the MPC up to a time with the command read then; a failed plan
    (:class:`~sotpy.errors.SolverError`) is retried with a zero command (stop), then, with
    both feet down, as a stand in double support where they are; with a foot in the air
    the last plan's next jerks are kept (it was feasible: its ZMP stays in its soles).
    :attr:`fault` says which and why.
    """

    def __init__(
        self,
        initial: dict[str, Footprint],
        com: np.ndarray,
        sole: Sole,
        params: MPCParameters,
        stepHeight: float,
    ) -> None:
        self.params, self.sole, self.stepHeight = params, sole, stepHeight
        self.mpc = VelocityMPC(params)
        self.T = params.period
        self.feetDown: dict[str, Footprint] = dict(initial)
        self.support = "right"
        self.otherDown = True
        self.stepStart = 0.0  # when the support landed (s)
        self.k = 0  # the next MPC sample
        self.state0 = np.zeros((3, 2))
        self.state0[0] = com[:2]
        self.jerk = np.zeros(2)
        self.mode = "standing"
        self.result: MPCResult | None = None
        self.spare: list[np.ndarray] = []  # the last plan's next jerks, for a fault
        self.fault: str | None = None
        self.stepped: list[Footprint] = []
        self.swing: dict[str, Any] | None = None
        self._first: dict[str, tuple[float, float]] = {}
        self.velocity = np.zeros(3)

    # -- sole frames <-> the MPC's sole centres
    def _centre(self, f: Footprint) -> tuple[float, float, float]:
        c = f.point(np.asarray(self.sole.offset))
        return (float(c[0]), float(c[1]), f.yaw)

    def _footprint(self, x: float, y: float, yaw: float, side: str) -> Footprint:
        c, s = math.cos(yaw), math.sin(yaw)
        ox, oy = self.sole.offset
        return Footprint(x - (c * ox - s * oy), y - (s * ox + c * oy), yaw, side)

    @property
    def other(self) -> str:
        return "left" if self.support == "right" else "right"

    def advance(self, t: float, velocity: np.ndarray) -> None:
        """Run the MPC's samples up to ``t`` (s) with the command ``velocity``."""
        self.velocity = np.asarray(velocity, dtype=float)
        while t >= self.k * self.T - 1e-12:
            self._sample(self.k * self.T)

    def _sample(self, tk: float) -> None:
        """At sample time ``tk``: finish the previous period (a landing, the step's end),
        solve, and set the jerk and the swing for ``[tk, tk + T)``."""
        if self.k > 0:
            self.state0 = self.mpc.A @ self.state0 + np.outer(self.mpc.B, self.jerk)
            self._events(tk)
        tau = tk - self.stepStart
        p = self.params
        if tau >= p.stepDuration - 1e-9:
            tau = 0.0
        sup = self._centre(self.feetDown[self.support])
        oth = self._centre(self.feetDown[self.other]) if self.otherDown else None
        nxt = self._fixedNext(tk)
        res = self._solve(sup, tau, oth, nxt)
        if res is None:
            self.jerk = self.spare.pop(0) if self.spare else np.zeros(2)
        else:
            self.result, self.mode = res, res.reason
            self.jerk = res.jerk[0]
            self.spare = list(res.jerk[1:])
            self._planSwing(tk)  # (without a new plan a swing keeps its target)
        self.k += 1

    def _solve(self, sup, tau, oth, nxt) -> MPCResult | None:
        """The command's plan; else a stop's; else, both soles down, standing on them
        where they are (in double support, safely stopped); else None (a foot in the
        air: the last plan goes on). :attr:`fault` says which and why."""
        solve = self.mpc.solve
        try:
            return solve(self.state0, sup, self.support, tau, self.velocity, oth, nxt)
        except SolverError as exc:
            why = f"the command {self.velocity.tolist()} has no plan ({exc})"
        try:
            res = solve(self.state0, sup, self.support, tau, np.zeros(3), oth, nxt)
            self.fault = f"{why}; stopping"
            return res
        except SolverError:
            pass
        if oth is not None:
            try:
                res = solve(self.state0, sup, self.support, tau, np.zeros(3), oth, stand=True)
                self.fault = f"{why}; no stop either: standing in double support where the feet are"
                self.swing = None
                return res
            except SolverError:
                pass
        self.fault = f"{why}; no stop either, a foot in the air: the last plan goes on"
        return None

    def _events(self, tk: float) -> None:
        """What happened at ``tk``: the swing foot lands one MPC period before the step's
        end (module doc: so the ZMP's move between the MPC's last sample on the old sole
        and its first on the new one happens while both are down); at the step's end the
        landed foot becomes the support."""
        p = self.params
        if self.mode == "standing":
            self.stepStart = tk
            return
        sw = self.swing
        if sw is not None and "landed" not in sw and tk >= sw["land"] - 1e-9:
            f = self._landing()
            self.feetDown[f.side] = f
            self.stepped.append(f)
            sw["landed"] = f
        if tk - self.stepStart >= p.stepDuration - 1e-9:
            if self.mode == "starting" and sw is None:
                # the first step was a double support: the other foot becomes the support
                # where it stands
                self.support, self.otherDown = self.other, True
            elif sw is not None and "landed" in sw:
                self.support, self.otherDown = sw["side"], True
                self.swing = None
            self.stepStart = tk

    def _fixedNext(self, tk: float) -> tuple[float, float, float] | None:
        """The next footstep when it is no longer the MPC's to choose: landed, or its
        target frozen (the last :data:`FREEZE` s of the swing)."""
        sw = self.swing
        if sw is None:
            return None
        if "landed" in sw:
            return self._centre(sw["landed"])
        if sw["coef"] is not None and sw["arrive"] - tk < FREEZE:
            return tuple(float(v) for v in sw["target"])
        return None

    def _landing(self) -> Footprint:
        x, y, yaw = self.swing["target"]
        return self._footprint(float(x), float(y), float(yaw), self.swing["side"])

    def _planSwing(self, tk: float) -> None:
        """The swing of the other foot over ``[tk, tk + T)``, re-planned to the MPC's
        first footstep (module doc)."""
        p, res = self.params, self.result
        if res is None or self.mode in ("standing", "starting") or not res.footsteps:
            return
        if self.swing is not None and "landed" in self.swing:
            return
        lift = self.stepStart + p.doubleSupport
        land = self.stepStart + p.stepDuration - self.T
        if tk + self.T <= lift - 1e-12 and self.swing is None:
            return  # the other foot is still down during this period
        target = np.array(res.footsteps[0][:3])
        side = self.other
        if self.swing is None:
            start = np.array(self._centre(self.feetDown[side]))
            self.otherDown = False
            # x, y and yaw move in the middle of the swing: the foot rises before it moves
            # and is still when it reaches the ground (plan.LIFT_RATIO)
            a = LIFT_RATIO * (land - lift)
            self.swing = {
                "side": side,
                "from": start,
                "lift": lift,
                "land": land,
                "depart": lift + a,
                "arrive": land - a,
                "coef": None,
            }
            self._first.setdefault(side, (lift, land))
            t0, state = lift + a, (start, np.zeros(3), np.zeros(3))
        else:
            sw = self.swing
            if sw["arrive"] - tk < FREEZE and sw["coef"] is not None:
                return
            t0 = max(tk, sw["depart"])
            if sw["coef"] is None or tk < sw["depart"]:
                state = (sw["from"], np.zeros(3), np.zeros(3))
            else:
                state = _poly(sw["coef"], t0 - sw["t0"])
        target[2] = state[0][2] + math.remainder(target[2] - state[0][2], 2 * math.pi)
        self.swing.update(
            coef=quinticTo(*state, target, self.swing["arrive"] - t0), t0=t0, target=target
        )

    # -- evaluation at a tick ---------------------------------------------------------
    def state(self, t: float) -> np.ndarray:
        """The CoM's state at ``t`` (3 x 2), ``t`` in the current MPC period."""
        return stateAt(self.state0, self.jerk, t - (self.k - 1) * self.T)

    def footprints(self, t: float) -> dict[str, Footprint]:
        """The feet on the ground (a swinging foot's: where it left)."""
        return dict(self.feetDown)

    def feet(self, t: float) -> dict[str, tuple[np.ndarray, np.ndarray, np.ndarray]]:
        """Each sole frame's ``(position, yaw (1,), velocity (4,))`` at ``t``."""
        out = {}
        for side, f in self.feetDown.items():
            out[side] = (np.array([f.x, f.y, 0.0]), np.array([f.yaw]), np.zeros(4))
        sw = self.swing
        if sw is not None and "landed" not in sw and sw["coef"] is not None and sw["lift"] <= t:
            if t < sw["depart"]:
                (x, y, yaw), (dx, dy, dyaw) = sw["from"], np.zeros(3)
            elif t >= sw["arrive"]:
                (x, y, yaw), (dx, dy, dyaw) = sw["target"], np.zeros(3)
            else:  # the sample that re-planned it may be a rounding later than the tick
                (x, y, yaw), (dx, dy, dyaw), _ = _poly(sw["coef"], max(t - sw["t0"], 0.0))
            ss = sw["land"] - sw["lift"]
            b, db, _ = _height((t - sw["lift"]) / ss)
            c, s = math.cos(yaw), math.sin(yaw)
            ox, oy = self.sole.offset
            off = np.array([c * ox - s * oy, s * ox + c * oy])
            dOff = dyaw * np.array([-off[1], off[0]])
            pos = np.array([x - off[0], y - off[1], self.stepHeight * b])
            nu = np.array([dx - dOff[0], dy - dOff[1], self.stepHeight * db / ss, dyaw])
            out[sw["side"]] = (pos, np.array([yaw]), nu)
        return out

    def contactPhase(self, t: float) -> int:
        """1 on the left foot alone, -1 on the right, 0 both."""
        sw = self.swing
        if sw is not None and "landed" not in sw and sw["lift"] <= t:
            return 1 if sw["side"] == "right" else -1
        return 0

    def zmp(self, t: float) -> np.ndarray:
        """The cart-table ZMP of the CoM's state at ``t`` (size 2, m)."""
        x = self.state(t)
        return x[0] - (self.params.comHeight / self.params.gravity) * x[2]

    def plannedZmp(self, t: float) -> np.ndarray:
        """The cart-table ZMP of the MPC's CoM at ``t`` (size 2, m)."""
        return self.zmp(t)

    def steps(self) -> list[Footprint]:
        """Every footprint stepped on so far, in order."""
        return list(self.stepped)

    def finished(self, t: float) -> bool:
        """A velocity walk runs until it is stopped: never finished."""
        return False

    def firstSwing(self, side: str) -> tuple[float, float] | None:
        """``(lift, land)`` (s) of the ``side`` foot's first swing, once it is planned."""
        return self._first.get(side)

    def plan(self, initial: dict[str, Footprint], t: float) -> StepPlan:
        """A :class:`StepPlan` of the footprints stepped on, for reports and plots (its
        timing is the footstep walk's, not this walk's)."""
        return StepPlan(initial, self.steps(), 0.7, 0.1, 1.0, 1.0, self.stepHeight, self.sole)
