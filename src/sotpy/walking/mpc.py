r"""A velocity-referenced walking MPC with automatic footstep placement, after Herdt et
al. 2010 ("Online walking motion generation with automatic footstep placement",
Advanced Robotics 24(5-6)): plain functions and classes over numpy arrays, no graph.

**Model** (the cart-table / linear inverted pendulum, per horizontal axis, x and y
independent)::

    X = (c, dc, ddc)           CoM position (m), velocity (m/s), acceleration (m/s^2)
    X(k+1) = A X(k) + B u(k)   u the CoM jerk (m/s^3), constant over one period T (s)
    z(k) = c(k) - (h/g) ddc(k) the ZMP (m); h the CoM height (m), g gravity (m/s^2)

    A = [[1, T, T^2/2], [0, 1, T], [0, 0, 1]],   B = (T^3/6, T^2/2, T)

**Condensed prediction** over the horizon of N samples (k = 1..N, the states *after*
the jerks u_0..u_(k-1); the current state X_0 is given)::

    X_k = A^k X_0 + sum_(i<k) A^(k-1-i) B u_i
    C = Pps X_0 + Ppu U,  V = Pvs X_0 + Pvu U,  Acc = Pas X_0 + Pau U,  Z = Pzs X_0 + Pzu U

with ``U = (u_0..u_(N-1))``, ``Pps`` (N x 3) the first rows of ``A^k``, ``Ppu`` (N x N,
lower triangular) the first components of ``A^(k-1-i) B``, and so on;
``Pzs = Pps - (h/g) Pas``, ``Pzu = Ppu - (h/g) Pau`` (:func:`predictionMatrices`).

**Step timing.** A step lasts ``Ts = ss + ds`` (0.8 s by default) and begins when the
current support sole lands: ``[0, ds)`` double support (the previous support is still on
the ground and lifts at ``ds``), ``[ds, Ts)`` single support on ``support`` while the
other foot swings, and at ``Ts`` the swing foot lands on the first planned footstep,
which becomes the support of the next step. Sample k of the horizon is at phase
``s_k = timeInStep + k T``; it belongs to step ``j_k = floor(s_k / Ts)`` (0: the current
support, fixed; j >= 1: footstep j, a decision variable). The horizon holds ``m = j_N``
future footsteps (2 or 3 with the defaults), alternating sides. The yaw of footstep j is
fixed in advance from the integrated turn rate, ``theta_j = theta_0 + omega j Ts``
(theta_0 the support sole's yaw): the heading grows by ``omega Ts`` per step, so the
constraints stay linear.

**Decision variables**: ``x = (U_x, U_y, F_x, F_y)``, the N jerks of each axis
(m/s^3) and the m footstep positions (m); ``2N + 2m`` of them.

**Cost**::

    alpha/2 sum_k |V_k - vref_k|^2 + beta/2 sum_k |u_k|^2 + gamma/2 sum_k |Z_k - f_(j_k)|^2

``vref_k = R(psi_k) (vx, vy)``, ``psi_k = theta_0 + omega (timeInStep + k T)``: the
command ``(vx, vy, omega)`` is given in the robot's frame, the support sole's yaw turned
by the turn made since that sole landed (so the velocity and the feet turn together; it
is the support yaw itself at the start of each step and whenever omega = 0). ``f_j`` is
the centre of the sole that carries the ZMP at sample k (the support, a footstep, or the
midpoint of two soles in double support). Weights, on the squared SI quantities
((m/s)^2, (m/s^3)^2, m^2): ``alpha = 1`` (velocity), ``beta = 1e-6`` (jerk),
``gamma = 1e-3`` (ZMP to sole centre), Herdt's values; with them the mean CoM velocity
of a steady straight walk is within 2.5 % of the command at 0.1, 0.2 and 0.3 m/s (the
closed-loop tests ask 10 %). A lateral command is followed poorly (0.05 m/s gives about
0.007 m/s): the velocity term weighs the lateral sway of every step against it; forward
walking and turning are what this core is for.

**Constraints** (hard, linear):

- the ZMP at every sample k = 1..N inside the rectangle of half sizes
  ``(footHalfLength, footHalfWidth)`` around the centre of the sole that carries it,
  in that sole's yaw: ``|R(theta_j)^T (Z_k - f_j)| <= (hl, hw)`` (two rows per sample);
- footstep j relative to the sole before it (j - 1; the support for j = 1), in the
  frame of the landing sole (yaw theta_j, known in advance): forward
  ``-maxStepBackward <= dx <= maxStepForward``, lateral ``dmin <= dy <= dmax`` for a
  left foot (``-dmax <= dy <= -dmin`` for a right foot), ``(dmin, dmax) =
  lateralRange``; the sides alternate from the support's. (In the previous sole's
  frame, as in Herdt et al., the lateral row, active at ``dmin`` in a steady walk, is
  measured in a frame that lags the heading by ``omega Ts``: turning at 0.2 rad/s the
  CoM's path then lags the feet's heading by 0.135 rad; in the landing sole's frame by
  0.016 rad.)

**Double support.** During ``[0, ds)`` of a *future* step the ZMP is kept in the
rectangle of the landing sole (the new support; simplest and still correct: it is a
subset of the convex hull of both soles, and it keeps the constraints linear in the
footstep variables). During ``[0, ds)`` of the *current* step, if the caller gives the
other sole (``otherFoot``, both soles then fixed and known), the ZMP is kept in the
convex hull of both soles (half-planes ``n_e . Z_k <= b_e``). The constraints hold at
the samples; between two samples the ZMP (a cubic in time) is not checked, as in Herdt
et al.

**Capturability** (one more hard constraint, not in Herdt et al.): the divergent
component of motion at the end of the horizon, ``xi_N = c_N + dc_N / w0``
(``w0 = sqrt(g/h)``, m), lies in the region of the last sample (its sole's rectangle,
or the hull when standing or stopping): from there the robot can still come to rest on
that support, so a plan that falls beyond the horizon is refused rather than returned
(without it "stopping" is always feasible: jerks are unbounded and the ZMP can be put
anywhere while the CoM diverges).

**Modes.** ``MPCResult.reason`` says which problem was solved:

- ``"walking"``: the problem above.
- ``"standing"``: the command is zero (all of ``|vx|, |vy|, |omega|`` below 1e-9) and the
  other sole is given and lies side by side with the support, or ``solve(stand=True)``
  (the soles where they are) (at ``feetDistance``
  laterally, same yaw, within 1e-6 m and 1e-6 rad): no step, the ZMP in the convex hull
  of both soles at every sample, its reference their midpoint; ``footsteps`` is empty.
- ``"stopping"``: a zero command otherwise: the next footstep is fixed side by side
  with the support (not a decision variable) and from its landing on the ZMP is kept in
  the hull of the two soles. If that is infeasible (too fast to stop in one step: the
  capturability row) the MPC falls back to ``"walking"`` with a zero velocity reference
  (the robot decelerates stepping) and tries to stop again at the next solve.
- ``"starting"``: a non-zero command while standing (both soles down, side by side or
  where a stand left them, and the previous solve of this object was ``"standing"`` or
  ``"starting"`` on the same support, or there was none): the current step is a double
  support to its end (the ZMP in the hull, the other sole stays down), then the other
  sole becomes the support (it is ``footsteps[0]``, fixed where it is) and the walk
  proceeds: the ZMP first moves over
  the foot that will carry the robot, instead of jumping there in one period. This is
  the only state the object keeps (:meth:`VelocityMPC.reset` forgets it).

**Solver**: DAQP (a dual active-set method for small dense QPs), primal tolerance
1e-10 m. An exit flag other than 1 (optimal) raises :class:`~sotpy.errors.SolverError`
naming the MPC, the mode and the flag; no answer is returned unconverged.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field

import numpy as np

from ..dynamics.robot import convex_hull_2d
from ..errors import CommandError, SolverError
from .preview import cartTable

__all__ = [
    "MPCParameters",
    "MPCResult",
    "Prediction",
    "SimulationResult",
    "VelocityMPC",
    "cartTableMatrices",
    "predictionMatrices",
    "simulate",
]

_ZERO_COMMAND = 1e-9  # |vx|, |vy| (m/s), |omega| (rad/s) below which a command is zero
_SIDE_BY_SIDE = 1e-6  # m and rad: tolerance of the standing test
_PHASE_EPS = 1e-9  # s: phases within this of a boundary count as past it
_PRIMAL_TOL = 1e-10  # DAQP primal feasibility tolerance (m for the ZMP rows)
_INF = 1e30  # DAQP's infinity
_DAQP_FLAGS = {
    -1: "infeasible",
    -2: "cycling",
    -3: "unbounded",
    -4: "at its iteration limit",
    -5: "non-convex",
    -6: "overdetermined initial active set",
}


@dataclass
class MPCParameters:
    """Parameters of :class:`VelocityMPC`, all SI units.

    ``comHeight`` h (m); ``period`` T (s); ``horizon`` N (samples); ``singleSupport``
    and ``doubleSupport`` (s); ``footHalfLength`` and ``footHalfWidth`` the ZMP box half
    sizes around the sole centre (m); ``feetDistance`` the nominal lateral distance
    between the sole centres (m, used to stop and stand side by side);
    ``maxStepForward``, ``maxStepBackward`` (m, along the previous sole's x axis);
    ``lateralRange`` (dmin, dmax) the lateral distance between a footstep and the
    previous sole (m, along its y axis); ``alpha`` (velocity), ``beta`` (jerk),
    ``gamma`` (ZMP to sole centre) the cost weights; ``gravity`` (m/s^2).
    """

    comHeight: float
    # the horizon and the step timing (s)
    period: float = 0.1
    horizon: int = 16
    singleSupport: float = 0.7
    doubleSupport: float = 0.1
    # the ZMP box and the feet (m)
    footHalfLength: float = 0.03
    footHalfWidth: float = 0.03
    feetDistance: float = 0.17
    # the footsteps' bounds (m)
    maxStepForward: float = 0.3
    maxStepBackward: float = 0.1
    lateralRange: tuple[float, float] = (0.15, 0.3)
    # the cost's weights; gravity (m/s^2)
    alpha: float = 1.0
    beta: float = 1e-6
    gamma: float = 1e-3
    gravity: float = 9.81

    @property
    def stepDuration(self) -> float:
        """``singleSupport + doubleSupport`` (s)."""
        return self.singleSupport + self.doubleSupport


@dataclass
class MPCResult:
    """The answer of :meth:`VelocityMPC.solve`.

    ``jerk`` (N, 2) the CoM jerks (m/s^3, x and y; the caller applies ``jerk[0]`` for
    one period); ``com`` (N, 3, 2) the predicted states after each jerk (rows c, dc,
    ddc); ``zmp`` (N, 2) the predicted ZMP at those samples (m); ``footsteps`` the
    planned next soles ``(x, y, yaw, side)`` in order (empty when standing); ``ok`` True
    (a failed solve raises); ``reason`` the mode solved (``"walking"``, ``"stopping"``,
    ``"standing"``, ``"starting"``: module doc); ``iterations`` DAQP's iterations.
    """

    jerk: np.ndarray
    com: np.ndarray
    zmp: np.ndarray
    footsteps: list[tuple[float, float, float, str]]
    ok: bool
    reason: str
    iterations: int | None


@dataclass(frozen=True)
class Prediction:
    """The condensed prediction matrices (module doc): ``Pps, Pvs, Pas, Pzs`` (N x 3) on
    the current state, ``Ppu, Pvu, Pau, Pzu`` (N x N) on the jerks."""

    Pps: np.ndarray
    Ppu: np.ndarray
    Pvs: np.ndarray
    Pvu: np.ndarray
    Pas: np.ndarray
    Pau: np.ndarray
    Pzs: np.ndarray
    Pzu: np.ndarray


def cartTableMatrices(period: float) -> tuple[np.ndarray, np.ndarray]:
    """``(A, B)`` of the jerk-driven cart-table of period ``period`` (s): A 3 x 3, B (3,)
    (:func:`sotpy.walking.preview.cartTable`'s)."""
    A, B, _ = cartTable(period, 1.0)
    return A, B


def predictionMatrices(period: float, horizon: int, comHeight: float, gravity: float = 9.81):
    """The :class:`Prediction` of ``horizon`` samples of period ``period`` (s) for a CoM
    height ``comHeight`` (m) (module doc), from the powers of A."""
    A, B = cartTableMatrices(period)
    N = int(horizon)
    S = np.empty((N, 3, 3))  # S[k-1] = A^k
    G = np.empty((N, 3))  # G[i] = A^i B
    Ak = np.eye(3)
    for k in range(N):
        G[k] = Ak @ B
        Ak = A @ Ak
        S[k] = Ak
    U = np.zeros((N, N, 3))  # U[k-1, i] = A^(k-1-i) B for i < k
    for k in range(1, N + 1):
        for i in range(k):
            U[k - 1, i] = G[k - 1 - i]
    r = comHeight / gravity
    Pps, Pvs, Pas = S[:, 0, :].copy(), S[:, 1, :].copy(), S[:, 2, :].copy()
    Ppu, Pvu, Pau = U[:, :, 0].copy(), U[:, :, 1].copy(), U[:, :, 2].copy()
    return Prediction(Pps, Ppu, Pvs, Pvu, Pas, Pau, Pps - r * Pas, Ppu - r * Pau)


def _rot(theta: float) -> np.ndarray:
    c, s = math.cos(theta), math.sin(theta)
    return np.array([[c, -s], [s, c]])


def _corners(sole: tuple[float, float, float], hl: float, hw: float) -> np.ndarray:
    local = np.array([[hl, hw], [-hl, hw], [-hl, -hw], [hl, -hw]])
    return np.asarray(sole[:2]) + local @ _rot(sole[2]).T


def _hull(points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Half-planes ``(n, b)`` (outward unit normals, e x 2, and offsets) of the convex
    hull of 2-D ``points``: ``n @ z <= b`` inside."""
    ring = convex_hull_2d(np.asarray(points, dtype=float))  # counter-clockwise
    d = np.roll(ring, -1, axis=0) - ring
    n = np.column_stack([d[:, 1], -d[:, 0]])
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    return n, np.einsum("ij,ij->i", n, ring)


def _other(side: str) -> str:
    return "left" if side == "right" else "right"


def _sideBySide(params: MPCParameters, support, side: str) -> tuple[float, float, float]:
    """The sole side by side with ``support`` (on the other side, same yaw)."""
    dy = params.feetDistance if side == "right" else -params.feetDistance
    p = np.asarray(support[:2]) + _rot(support[2]) @ np.array([0.0, dy])
    return (float(p[0]), float(p[1]), float(support[2]))


def _phase(params: MPCParameters, s: float) -> tuple[int, bool]:
    """``(j, inDoubleSupport)`` of phase ``s`` (s since the support landed)."""
    Ts = params.stepDuration
    j = math.floor((s + _PHASE_EPS) / Ts)
    return j, (s - j * Ts) < params.doubleSupport - _PHASE_EPS


class VelocityMPC:
    """The walking MPC of the module doc. ``solve`` builds and solves one QP; the
    constant matrices (prediction, the jerk block of the Hessian) are built once here.

    Raises:
        CommandError: a parameter out of range (the message names it).
    """

    def __init__(self, params: MPCParameters) -> None:
        self.params = p = params
        who = "VelocityMPC"
        for name in (
            "comHeight",
            "period",
            "singleSupport",
            "footHalfLength",
            "footHalfWidth",
            "feetDistance",
            "beta",
            "gravity",
        ):
            _check_number(who, name, getattr(p, name), positive=True)
        for name in ("doubleSupport", "maxStepForward", "maxStepBackward", "alpha", "gamma"):
            _check_number(who, name, getattr(p, name), positive=False)
        if p.gamma <= 0:
            raise CommandError(f"{who}: gamma must be > 0 (it places the footsteps), got 0")
        if not isinstance(p.horizon, (int, np.integer)) or p.horizon < 1:
            raise CommandError(f"{who}: horizon must be an int >= 1, got {p.horizon!r}")
        lo, hi = (float(v) for v in p.lateralRange)
        if not (math.isfinite(lo) and math.isfinite(hi) and 0 <= lo <= hi):
            raise CommandError(
                f"{who}: lateralRange must be 0 <= dmin <= dmax, got {p.lateralRange}"
            )
        if not lo <= p.feetDistance <= hi:
            raise CommandError(
                f"{who}: feetDistance {p.feetDistance} must lie in lateralRange {p.lateralRange} "
                "(the feet stop side by side)"
            )
        N = self.N = int(p.horizon)
        self.A, self.B = cartTableMatrices(p.period)
        self.pred = pr = predictionMatrices(p.period, N, p.comHeight, p.gravity)
        # constant Hessian block of each axis' jerks
        self._Quu = p.alpha * pr.Pvu.T @ pr.Pvu + p.beta * np.eye(N) + p.gamma * pr.Pzu.T @ pr.Pzu
        self._k = np.arange(1, N + 1)
        self._last: tuple | None = None  # (mode, support, side) of the last solve
        self._next: tuple | None = None  # the fixed next footstep of the current solve
        w0 = math.sqrt(p.gravity / p.comHeight)
        self._Xs = pr.Pps[-1] + pr.Pvs[-1] / w0  # the DCM at the horizon's end: on X0
        self._Xu = pr.Ppu[-1] + pr.Pvu[-1] / w0  # and on the jerks

    def reset(self) -> None:
        """Forget the last solve (see "Starting" in the module doc)."""
        self._last = None

    # ------------------------------------------------------------------ checks
    def _inputs(self, com, support, supportSide, timeInStep, velocity, otherFoot):
        who = "VelocityMPC.solve"
        X0 = _array(who, "com", com, (3, 2), "rows c, dc, ddc; columns x, y (m, m/s, m/s^2)")
        sup = tuple(_array(who, "support", support, (3,), "(x, y, yaw) in m, m, rad"))
        if supportSide not in ("left", "right"):
            raise CommandError(f"{who}: supportSide must be 'left' or 'right', got {supportSide!r}")
        try:
            tau = float(timeInStep)
        except (TypeError, ValueError):
            raise CommandError(
                f"{who}: timeInStep must be a number (s), got {timeInStep!r}"
            ) from None
        Ts = self.params.stepDuration
        if not (math.isfinite(tau) and 0.0 <= tau < Ts):
            raise CommandError(f"{who}: timeInStep must be in [0, {Ts:g}) s, got {timeInStep!r}")
        v = _array(who, "velocity", velocity, (3,), "(vx, vy, omega) in m/s, m/s, rad/s")
        other = None
        if otherFoot is not None:
            other = tuple(_array(who, "otherFoot", otherFoot, (3,), "(x, y, yaw) or None"))
        return X0, sup, tau, v, other

    # ------------------------------------------------------------------ solve
    def solve(
        self,
        com: np.ndarray,
        support: tuple[float, float, float],
        supportSide: str,
        timeInStep: float,
        velocity: np.ndarray,
        otherFoot: tuple[float, float, float] | None = None,
        nextStep: tuple[float, float, float] | None = None,
        stand: bool = False,
    ) -> MPCResult:
        """Plan the next N jerks and footsteps (module doc).

        Args:
            com: (3, 2), rows c, dc, ddc, columns x, y (world; m, m/s, m/s^2).
            support: the current support sole centre ``(x, y, yaw)`` (world; m, rad).
            supportSide: ``"left"`` or ``"right"``.
            timeInStep: time since the support sole landed (s), in ``[0, ss + ds)``.
            velocity: ``(vx, vy, omega)`` in the robot's frame (m/s, m/s, rad/s).
            otherFoot: the other sole ``(x, y, yaw)`` when it is on the ground (during
                the double support, or standing), else None (in the air): with it the
                ZMP may use the convex hull of both soles, and a zero command stands.
            nextStep: the next footstep ``(x, y, yaw)`` when it is no longer a choice
                (the swing foot has landed early, or its target is frozen): it is then
                fixed, and the walk's modes reduce to ``"walking"`` for this step (a zero
                command stops at the step after).
            stand: stand where the soles are (the ``"standing"`` mode with the ZMP in the
                hull of both, side by side or not; needs ``otherFoot``): the fallback of
                a walk whose commands have no plan.

        Raises:
            CommandError: an argument of the wrong size, non-finite, or out of range.
            SolverError: the QP has no solution (DAQP's flag in the message).
        """
        X0, sup, tau, v, other = self._inputs(
            com, support, supportSide, timeInStep, velocity, otherFoot
        )
        self._next = None
        if nextStep is not None:
            self._next = tuple(
                _array("VelocityMPC.solve", "nextStep", nextStep, (3,), "(x, y, yaw) or None")
            )
        together = other is not None and self._sideBySide(sup, supportSide, other)
        if stand:
            if other is None:
                raise CommandError(
                    "VelocityMPC.solve: stand=True needs otherFoot (both soles down)"
                )
            modes = ["standing"]
        elif self._next is not None:
            modes = ["walking"]
        elif np.all(np.abs(v) < _ZERO_COMMAND):
            modes = ["standing", "stopping", "walking"] if together else ["stopping", "walking"]
        else:
            resting = self._last is None or self._last == ("standing", sup, supportSide)
            resting = resting or self._last == ("starting", sup, supportSide)
            # from rest (side by side, or where a fallback left the feet) a walk starts
            # with a whole step in double support
            modes = ["starting", "walking"] if other is not None and resting else ["walking"]
        failures = []
        for mode in modes:
            out = self._solveMode(mode, X0, sup, supportSide, tau, v, other)
            if isinstance(out, MPCResult):
                self._last = (mode, sup, supportSide)
                return out
            failures.append(f"{mode}: {out}")
        raise SolverError(
            "VelocityMPC.solve: no plan found ("
            + "; ".join(failures)
            + f"); timeInStep {tau:g} s, CoM velocity {X0[1].tolist()} m/s"
        )

    def _sideBySide(self, sup, side, other) -> bool:
        q = _sideBySide(self.params, sup, side)
        yaw = math.remainder(other[2] - sup[2], 2 * math.pi)
        return (
            math.hypot(other[0] - q[0], other[1] - q[1]) <= _SIDE_BY_SIDE
            and abs(yaw) <= _SIDE_BY_SIDE
        )

    def _solveMode(self, mode, X0, sup, side, tau, v, other) -> MPCResult | str:
        """Build and solve the QP of ``mode``; the result, or why it failed (a string,
        for an infeasible problem only; other failures raise)."""
        import daqp

        p, N, pr = self.params, self.N, self.pred
        T, Ts = p.period, p.stepDuration
        hl, hw = p.footHalfLength, p.footHalfWidth
        omega = float(v[2])
        phases = [_phase(p, tau + k * T) for k in range(1, N + 1)]
        jk = np.array([ph[0] for ph in phases])
        dsk = np.array([ph[1] for ph in phases])
        J = int(jk[-1])  # the last step the horizon reaches

        # ---- the soles of steps 0..J: fixed (x, y, yaw) or free (a footstep variable)
        sides = [side]
        for _ in range(J):
            sides.append(_other(sides[-1]))
        fixed: dict[int, tuple[float, float, float]] = {0: sup}
        if mode == "starting" and J >= 1:
            fixed[1] = other
        if mode == "stopping" and J >= 1:
            fixed[1] = _sideBySide(p, sup, side)
        nxt = self._next if mode == "walking" and J >= 1 else None
        if nxt is not None:
            fixed[1] = nxt
        first = len(fixed) if mode in ("walking", "starting") else J + 1
        free = list(range(first, J + 1))
        m = len(free)
        yaws = [sup[2]] * (J + 1)
        if mode in ("walking", "starting"):
            if nxt is not None:
                base, j0 = nxt[2], 1
            else:
                base, j0 = (sup[2], 0) if mode == "walking" else (other[2], 1)
            for j in range(j0, J + 1):
                yaws[j] = base + omega * (j - j0) * Ts
        nv = 2 * N + 2 * m

        # ---- the region and the ZMP reference of each sample
        both = (sup, other) if other is not None else None
        pair = {"standing": both, "starting": both, "stopping": (sup, fixed.get(1))}.get(mode)
        hullOf: dict = {}

        def hull(a, b):
            key = (a, b)
            if key not in hullOf:
                hullOf[key] = _hull(np.vstack([_corners(a, hl, hw), _corners(b, hl, hw)]))
            return key

        region: list = []  # per sample: ("box", j) or ("hull", key)
        zcf = np.zeros((N, 2))  # fixed ZMP reference
        Uf = np.zeros((N, m))  # ZMP reference from the footstep variables
        for k in range(N):
            j = int(jk[k])
            if mode == "standing" or (mode == "starting" and j == 0):
                region.append(("hull", hull(*both)))
                zcf[k] = 0.5 * (np.asarray(both[0][:2]) + np.asarray(both[1][:2]))
            elif mode == "stopping" and j >= 1:
                region.append(("hull", hull(*pair)))
                zcf[k] = 0.5 * (np.asarray(pair[0][:2]) + np.asarray(pair[1][:2]))
            elif j == 0 and dsk[k] and other is not None:
                region.append(("hull", hull(sup, other)))
                zcf[k] = sup[:2]
            else:
                region.append(("box", j))
                if j in fixed:
                    zcf[k] = fixed[j][:2]
                else:
                    Uf[k, j - first] = 1.0

        # ---- cost
        zs = pr.Pzs @ X0  # (N, 2) the ZMP without jerks
        vs = pr.Pvs @ X0
        psi = sup[2] + omega * (tau + self._k * T)
        vref = np.column_stack(
            [np.cos(psi) * v[0] - np.sin(psi) * v[1], np.sin(psi) * v[0] + np.cos(psi) * v[1]]
        )
        H = np.zeros((nv, nv))
        g = np.empty(nv)
        ez = zs - zcf
        for a in range(2):
            u = slice(a * N, (a + 1) * N)
            H[u, u] = self._Quu
            g[u] = p.alpha * pr.Pvu.T @ (vs[:, a] - vref[:, a]) + p.gamma * pr.Pzu.T @ ez[:, a]
            if m:
                f = slice(2 * N + a * m, 2 * N + (a + 1) * m)
                H[u, f] = -p.gamma * pr.Pzu.T @ Uf
                H[f, u] = H[u, f].T
                H[f, f] = p.gamma * Uf.T @ Uf
                g[f] = -p.gamma * Uf.T @ ez[:, a]

        # ---- constraints  lo <= C x <= hi
        rows, lo, hi = [], [], []
        ux, uy = slice(0, N), slice(N, 2 * N)
        fx, fy = slice(2 * N, 2 * N + m), slice(2 * N + m, nv)
        ks = np.array([k for k in range(N) if region[k][0] == "box"], dtype=int)
        if len(ks):
            js = jk[ks]
            th = np.array([yaws[j] for j in js])
            c, s = np.cos(th)[:, None], np.sin(th)[:, None]
            P = pr.Pzu[ks]
            E = np.zeros((len(ks), m))
            centre = np.zeros((len(ks), 2))
            for r, j in enumerate(js):
                if j in fixed:
                    centre[r] = fixed[j][:2]
                else:
                    E[r, j - first] = 1.0
            off = zs[ks] - centre  # ZMP offset not carried by the variables
            for (r1, r2), half in (((c, s), hl), ((-s, c), hw)):
                R = np.zeros((len(ks), nv))
                R[:, ux] = r1 * P
                R[:, uy] = r2 * P
                R[:, fx] = -r1 * E
                R[:, fy] = -r2 * E
                d = r1[:, 0] * off[:, 0] + r2[:, 0] * off[:, 1]
                rows.append(R)
                lo.append(-half - d)
                hi.append(half - d)
        for key, (n, b) in hullOf.items():
            kk = np.array([k for k in range(N) if region[k] == ("hull", key)], dtype=int)
            P = pr.Pzu[kk]
            R = np.zeros((len(kk) * len(n), nv))
            R[:, ux] = np.kron(n[:, :1], P)
            R[:, uy] = np.kron(n[:, 1:], P)
            rhs = (b[:, None] - n @ zs[kk].T).ravel()
            rows.append(R)
            hi.append(rhs)
            lo.append(np.full(len(rhs), -_INF))
        # capturability: the DCM xi = c + dc / w0 at the end of the horizon inside the
        # region of the last sample (from there the robot can stop on that support)
        xs = self._Xs @ X0  # (2,)
        kind, what = region[N - 1]
        if kind == "hull":
            n, b = hullOf[what]
            R = np.zeros((len(n), nv))
            R[:, ux] = n[:, :1] * self._Xu
            R[:, uy] = n[:, 1:] * self._Xu
            rows.append(R)
            hi.append(b - n @ xs)
            lo.append(np.full(len(n), -_INF))
        else:
            j = int(jk[N - 1])
            c, s = math.cos(yaws[j]), math.sin(yaws[j])
            centre = np.asarray(fixed[j][:2]) if j in fixed else np.zeros(2)
            for (r1, r2), half in (((c, s), hl), ((-s, c), hw)):
                R = np.zeros(nv)
                R[ux] = r1 * self._Xu
                R[uy] = r2 * self._Xu
                if j not in fixed:
                    R[2 * N + j - first] = -r1
                    R[2 * N + m + j - first] = -r2
                d = r1 * (xs[0] - centre[0]) + r2 * (xs[1] - centre[1])
                rows.append(R[None, :])
                lo.append(np.array([-half - d]))
                hi.append(np.array([half - d]))
        dmin, dmax = (float(x) for x in p.lateralRange)
        for i, j in enumerate(free):
            th = yaws[j]  # the box in the landing sole's frame (module doc)
            c, s = math.cos(th), math.sin(th)
            left = sides[j] == "left"
            bounds = (
                (-p.maxStepBackward, p.maxStepForward),
                (dmin, dmax) if left else (-dmax, -dmin),
            )
            for (r1, r2), (a, bnd) in zip(((c, s), (-s, c)), bounds, strict=True):
                R = np.zeros(nv)
                R[2 * N + i] = r1
                R[2 * N + m + i] = r2
                if j - 1 in fixed:
                    shift = r1 * fixed[j - 1][0] + r2 * fixed[j - 1][1]
                else:
                    shift = 0.0
                    R[2 * N + i - 1] = -r1
                    R[2 * N + m + i - 1] = -r2
                rows.append(R[None, :])
                lo.append(np.array([a + shift]))
                hi.append(np.array([bnd + shift]))
        C = np.vstack(rows)
        bl, bu = np.concatenate(lo), np.concatenate(hi)
        x, _fval, flag, info = daqp.solve(
            H, g, C, bu, bl, np.zeros(len(bl), dtype=np.intc), primal_tol=_PRIMAL_TOL
        )
        if flag == -1:
            return "infeasible (DAQP exit flag -1)"
        if flag != 1:
            raise SolverError(
                f"VelocityMPC.solve: the {mode} QP failed: DAQP "
                f"{_DAQP_FLAGS.get(flag, 'failed')} (exit flag {flag})"
            )
        x = np.asarray(x, dtype=float)
        if not np.isfinite(x).all():
            raise SolverError(f"VelocityMPC.solve: the {mode} QP's solution is not finite")
        jerk = np.column_stack([x[ux], x[uy]])
        comPred = np.stack(
            [pr.Pps @ X0 + pr.Ppu @ jerk, pr.Pvs @ X0 + pr.Pvu @ jerk, pr.Pas @ X0 + pr.Pau @ jerk],
            axis=1,
        )
        zmp = zs + pr.Pzu @ jerk
        steps = []
        for j in range(1, J + 1):
            if j in fixed:
                steps.append((*(float(q) for q in fixed[j]), sides[j]))
            elif mode != "standing":
                i = j - first
                steps.append(
                    (float(x[2 * N + i]), float(x[2 * N + m + i]), float(yaws[j]), sides[j])
                )
        if mode == "standing":
            steps = []
        return MPCResult(jerk, comPred, zmp, steps, True, mode, int(info["iterations"]))


# ---------------------------------------------------------------------- helpers
def _check_number(who: str, name: str, value, positive: bool) -> None:
    try:
        x = float(value)
    except (TypeError, ValueError):
        raise CommandError(f"{who}: {name} must be a number, got {value!r}") from None
    if not math.isfinite(x) or x < 0 or (positive and x == 0):
        expected = "> 0" if positive else ">= 0"
        raise CommandError(f"{who}: {name} must be a finite number {expected}, got {value!r}")


def _array(who: str, name: str, value, shape: tuple, what: str) -> np.ndarray:
    try:
        a = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise CommandError(f"{who}: {name} must be numbers of shape {shape}: {what}") from None
    if a.shape != shape:
        raise CommandError(f"{who}: {name} must have shape {shape} ({what}), got shape {a.shape}")
    if not np.isfinite(a).all():
        raise CommandError(f"{who}: {name} must be finite ({what}), got {a.tolist()}")
    return a


# ---------------------------------------------------------------------- closed loop
@dataclass
class SimulationResult:
    """The closed loop of :func:`simulate`, sampled every period at ``t`` (K + 1,):

    ``com`` (K + 1, 3, 2) the simulated states; ``zmp`` (K + 1, 2) ``c - (h/g) ddc`` of
    those states; ``footsteps`` every sole that touched the ground, in order
    ``(x, y, yaw, side)``, the first two the initial soles; ``region`` (K + 1, 2) the
    indices (into ``footsteps``) of the soles whose region constrained the ZMP at each
    sample: ``(a, -1)`` sole a's rectangle, ``(a, b)`` the convex hull of soles a and b
    (row 0, the initial state, is ``(-1, -1)``); ``modes`` (K,) the mode of each solve;
    ``solveTime`` (K,) wall time of each solve (s); ``iterations`` (K,).

    Unpacks as ``t, com, zmp, footsteps = simulate(...)``.
    """

    t: np.ndarray
    com: np.ndarray
    zmp: np.ndarray
    footsteps: list[tuple[float, float, float, str]]
    region: np.ndarray
    modes: list[str] = field(default_factory=list)
    solveTime: np.ndarray = field(default_factory=lambda: np.zeros(0))
    iterations: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=int))

    def __iter__(self) -> Iterator:
        return iter((self.t, self.com, self.zmp, self.footsteps))


def simulate(
    params: MPCParameters,
    velocities: Callable[[float], tuple[float, float, float]],
    duration: float,
    start_support: str = "right",
    start_com: np.ndarray | None = None,
) -> SimulationResult:
    """Run :class:`VelocityMPC` in closed loop on the cart-table model alone for
    ``duration`` (s), with the command ``velocities(t) -> (vx, vy, omega)`` (robot frame).

    The robot starts standing, the soles side by side at ``feetDistance`` around the
    origin (yaw 0), the CoM at ``start_com`` (3 x 2; default at rest over the origin), the
    ``start_support`` sole the support at the start of a step. Every period the MPC is
    solved, its first jerk applied (``X+ = A X + B u``), and the step clock advanced; at
    the end of a step the swing foot lands on the first footstep of the last plan. While
    standing the clock stays at 0.
    """
    who = "simulate"
    if start_support not in ("left", "right"):
        raise CommandError(f"{who}: start_support must be 'left' or 'right', got {start_support!r}")
    mpc = VelocityMPC(params)
    p = params
    T, Ts, hr = p.period, p.stepDuration, p.comHeight / p.gravity
    K = round(float(duration) / T)
    d = p.feetDistance / 2
    feet: list[tuple[float, float, float, str]] = [(0.0, -d, 0.0, "right"), (0.0, d, 0.0, "left")]
    sup, oth = (0, 1) if start_support == "right" else (1, 0)
    otherDown = True
    X = np.zeros((3, 2)) if start_com is None else np.array(start_com, dtype=float)
    tau = 0.0
    t = np.arange(K + 1) * T
    com = np.empty((K + 1, 3, 2))
    com[0] = X
    region = np.full((K + 1, 2), -1, dtype=int)
    modes, times, iters = [], np.empty(K), np.empty(K, dtype=int)
    for i in range(K):
        v = np.asarray(velocities(i * T), dtype=float)
        s = feet[sup]
        t0 = time.perf_counter()
        res = mpc.solve(X, s[:3], s[3], tau, v, feet[oth][:3] if otherDown else None)
        times[i] = time.perf_counter() - t0
        modes.append(res.reason)
        iters[i] = res.iterations if res.iterations is not None else -1
        X = mpc.A @ X + np.outer(mpc.B, res.jerk[0])
        com[i + 1] = X
        if res.reason == "standing":
            region[i + 1] = (sup, oth)
            tau = 0.0
            continue
        j1, ds1 = _phase(p, tau + T)
        if res.reason == "starting" and j1 == 0:  # the other sole stays down
            region[i + 1] = (sup, oth)
            tau += T
        elif j1 >= 1:  # the swing foot lands on the planned footstep
            feet.append(res.footsteps[0])
            sup, oth, otherDown = len(feet) - 1, sup, True
            region[i + 1] = (sup, oth) if res.reason == "stopping" else (sup, -1)
            tau = tau + T - Ts
            if tau < _PHASE_EPS:
                tau = 0.0
        else:
            region[i + 1] = (sup, oth) if (ds1 and otherDown) else (sup, -1)
            tau += T
            if not ds1:
                otherDown = False
    zmp = com[:, 0, :] - hr * com[:, 2, :]
    return SimulationResult(t, com, zmp, feet, region, modes, times, iters)
