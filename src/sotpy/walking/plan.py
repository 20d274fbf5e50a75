r"""A walk's plan: footprints, their timing, the swing trajectories and the ZMP reference.

A :class:`Footprint` is where a sole rests on the ground: the pose ``(x, y, yaw)`` (m,
m, rad; world) of the foot's **sole frame** (the frame of the robot description's
``[feet.<side>]``, on the ground plane ``z = 0``) and the side. A :class:`StepPlan` is a
sequence of swings, each moving one foot from its footprint to the next one, on the
timeline::

    | start DS | SS swing 1 | DS | SS swing 2 | DS | ... | SS swing n | end DS |
      tStart      ss          ds    ss          ds         ss          tEnd

(``DS`` double support, ``SS`` single support; times in s). A swing's foot goes from
its footprint ``F0`` to ``F1`` in the single support:

- height ``z(s) = h 64 s^3 (1 - s)^3`` (``s`` the normalised time in ``[0, 1]``,
  ``h`` the step height, reached at ``s = 1/2``);
- ``x, y, yaw`` along ``F0 + (F1 - F0) m(r)``, ``m(r) = 10 r^3 - 15 r^4 + 6 r^5`` the
  quintic of zero velocity and acceleration at both ends, over the middle of the swing
  (``r = (s - a) / (1 - 2 a)`` clipped to ``[0, 1]``, ``a`` = :data:`LIFT_RATIO`): the
  foot rises before it moves and lands vertically;

so every component is C2 with zero velocity and acceleration at lift-off and touch-down
(a jump of the swing foot's acceleration is a jump of the whole body's momentum rate:
a one-tick spike of the multibody ZMP, 10 cm on Talos with a ``sin^2`` height profile).

The ZMP reference ``p_ref(t)`` (m, world xy) is the centre of the supporting sole in
single support, and moves from the previous support's centre to the next one during
each double support along the same quintic ``m``: from the mid-point of both soles to the
first support during the start (from the CoM's projection, where the ZMP of a robot at
rest is, when given), and back to the mid-point during the end.
:meth:`StepPlan.zmpReference` samples it for the preview controller.

The checks of :func:`checkStep` are the ones a robot cannot survive: a step longer than
the leg, soles overlapping (feet crossing), a time below the generator's period.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from ..errors import CommandError

__all__ = [
    "LIFT_RATIO",
    "Footprint",
    "Phase",
    "Sole",
    "StepPlan",
    "checkStep",
    "quintic",
    "solesOverlap",
]

#: The fraction of a swing at each end where the foot only moves vertically.
LIFT_RATIO = 0.05


def quintic(s: float) -> tuple[float, float, float]:
    """``m(s) = 10 s^3 - 15 s^4 + 6 s^5`` on ``[0, 1]`` (0 before, 1 after) and its first
    two derivatives with respect to ``s``."""
    if s <= 0.0:
        return 0.0, 0.0, 0.0
    if s >= 1.0:
        return 1.0, 0.0, 0.0
    s2 = s * s
    return (
        s2 * s * (10.0 - 15.0 * s + 6.0 * s2),
        30.0 * s2 * (1.0 - s) ** 2,
        60.0 * s * (1.0 - s) * (1.0 - 2.0 * s),
    )


def _height(s: float) -> tuple[float, float, float]:
    """``b(s) = 64 s^3 (1 - s)^3`` and its first two derivatives (``b(1/2) = 1``)."""
    if s <= 0.0 or s >= 1.0:
        return 0.0, 0.0, 0.0
    u = 1.0 - s
    return (
        64.0 * s**3 * u**3,
        192.0 * s * s * u * u * (u - s),
        384.0 * s * u * (u * u - 3.0 * s * u + s * s),
    )


@dataclass(frozen=True)
class Sole:
    """A rectangular sole: ``length`` along the sole frame's x, ``width`` along its y
    (m), centred at ``offset`` (x, y in the sole frame, m)."""

    length: float
    width: float
    offset: tuple[float, float] = (0.0, 0.0)

    def corners(self) -> np.ndarray:
        """The 4 corners (4 x 2, m, sole frame), counter-clockwise from front-left."""
        a, b = self.length / 2, self.width / 2
        return np.array([[a, b], [-a, b], [-a, -b], [a, -b]]) + np.asarray(self.offset)


@dataclass(frozen=True)
class Footprint:
    """A sole frame's pose on the ground: ``x``, ``y`` (m), ``yaw`` (rad), world; and
    its ``side``, ``"left"`` or ``"right"``."""

    x: float
    y: float
    yaw: float
    side: str

    def rotation(self) -> np.ndarray:
        """The 2 x 2 rotation of ``yaw``."""
        c, s = math.cos(self.yaw), math.sin(self.yaw)
        return np.array([[c, -s], [s, c]])

    def point(self, local: np.ndarray) -> np.ndarray:
        """World xy of points given in the sole frame (``... x 2``)."""
        return np.asarray(local) @ self.rotation().T + (self.x, self.y)

    def relative(self, other: Footprint) -> tuple[float, float, float]:
        """``other`` in this footprint's frame: ``(dx, dy, dyaw)``."""
        d = self.rotation().T @ (other.x - self.x, other.y - self.y)
        return float(d[0]), float(d[1]), _wrap(other.yaw - self.yaw)


def _wrap(a: float) -> float:
    return (a + math.pi) % (2 * math.pi) - math.pi


def solesOverlap(a: Footprint, b: Footprint, sole: Sole, clearance: float = 0.0) -> bool:
    """Whether the soles at ``a`` and ``b`` (the same :class:`Sole`), each grown by
    ``clearance`` (m), intersect: the separating-axis test on two rectangles."""
    grown = Sole(sole.length + 2 * clearance, sole.width + 2 * clearance, sole.offset)
    pa, pb = a.point(grown.corners()), b.point(grown.corners())
    for poly in (pa, pb):
        for i in range(4):
            edge = poly[(i + 1) % 4] - poly[i]
            n = np.array([edge[1], -edge[0]])
            ra, rb = pa @ n, pb @ n
            if ra.max() < rb.min() or rb.max() < ra.min():
                return False
    return True


def checkStep(
    who: str,
    support: Footprint,
    target: Footprint,
    sole: Sole,
    legLength: float,
) -> None:
    """Refuse (``CommandError`` naming ``who``) a swing to ``target`` while standing on
    ``support``: the same side, soles overlapping (feet crossing), or the feet further
    apart than ``legLength`` (m, a leg's length: hip to ankle, straight)."""
    if target.side == support.side:
        raise CommandError(f"{who}: two steps in a row with the {target.side} foot")
    dx, dy, _ = support.relative(target)
    outward = dy if target.side == "left" else -dy
    if outward <= 0 or solesOverlap(support, target, sole):
        raise CommandError(
            f"{who}: the {target.side} foot's step to ({target.x:.3f}, {target.y:.3f}) "
            f"crosses or overlaps the {support.side} sole at ({support.x:.3f}, "
            f"{support.y:.3f}) (it is {dy:+.3f} m sideways of it in its frame; the soles "
            f"are {sole.width:.3f} m wide)"
        )
    reach = math.hypot(dx, dy)
    if reach > legLength:
        raise CommandError(
            f"{who}: the {target.side} foot's step puts the feet {reach:.3f} m apart, "
            f"longer than the leg ({legLength:.3f} m, hip to ankle)"
        )


class Phase:
    """One interval of the plan: ``start``, ``end`` (s); ``support`` the side in single
    support, None in double support; in single support ``swing`` = (from, to) footprints
    of the other foot; in double support ``zmp`` = the (from, to) ZMP points (m);
    ``feet`` the footprints on the ground at its start (side -> Footprint)."""

    __slots__ = ("end", "feet", "start", "support", "swing", "zmp")

    def __init__(
        self,
        start: float,
        end: float,
        support: str | None,
        swing: tuple[Footprint, Footprint] | None = None,
        zmp: tuple[np.ndarray, np.ndarray] | None = None,
        feet: dict[str, Footprint] | None = None,
    ) -> None:
        self.start, self.end, self.support = start, end, support
        self.swing, self.zmp, self.feet = swing, zmp, feet or {}


class StepPlan:
    """A walk from the footprints ``initial`` (``{"left": ..., "right": ...}``) through
    ``steps`` (each the next footprint of the swinging foot, alternating sides), with
    single support ``ss``, double support ``ds``, start and end double supports
    ``tStart`` and ``tEnd`` (s), step height ``stepHeight`` (m), on soles ``sole``;
    ``zmpStart`` (x, y; m) is where the ZMP is at the start (the CoM's projection of a
    robot at rest; default the mid-point of the soles' centres): a reference that
    started elsewhere would throw the CoM there in the first samples. The ZMP holds there
    for the first ``tHold`` s of the start (a preview controller's window must begin
    constant: a change already in it at the first sample is a change it "should" have
    prepared for, and its first jerks catch up: 10 cm ZMP swings in 25 ms), then moves.

    The plan is a function of time ``t`` (s, from the start of the walk): :meth:`feet`,
    :meth:`zmpAt`, :meth:`contactPhase`, :meth:`supportPolygon`; steps can be appended
    with :meth:`extend` (online) as long as they start after the current time.
    """

    def __init__(
        self,
        initial: dict[str, Footprint],
        steps: list[Footprint],
        ss: float,
        ds: float,
        tStart: float,
        tEnd: float,
        stepHeight: float,
        sole: Sole,
        zmpStart: np.ndarray | None = None,
        tHold: float = 0.0,
    ) -> None:
        self.tHold = float(tHold)
        self.initial, self.steps, self.sole = initial, list(steps), sole
        self.zmpStart = None if zmpStart is None else np.asarray(zmpStart, dtype=float)[:2]
        self.ss, self.ds, self.tStart, self.tEnd = ss, ds, tStart, tEnd
        self.stepHeight = stepHeight
        self._build()

    # -- construction --------------------------------------------------------------
    def _centre(self, f: Footprint) -> np.ndarray:
        return f.point(np.asarray(self.sole.offset))

    def _build(self) -> None:
        feet = dict(self.initial)
        phases: list[Phase] = []
        t = 0.0
        mid = (self._centre(feet["left"]) + self._centre(feet["right"])) / 2
        if self.zmpStart is not None:
            mid = self.zmpStart
        if not self.steps:
            self.phases = [Phase(0.0, self.tStart, None, zmp=(mid, mid), feet=dict(feet))]
            self.final = feet
            self.duration = self.tStart
            self._starts = np.zeros(1)
            self._last = None
            return
        first = "right" if self.steps[0].side == "left" else "left"
        phases.append(
            Phase(t, t + self.tStart, None, zmp=(mid, self._centre(feet[first])), feet=dict(feet))
        )
        t += self.tStart
        for i, step in enumerate(self.steps):
            support = "right" if step.side == "left" else "left"
            phases.append(
                Phase(t, t + self.ss, support, swing=(feet[step.side], step), feet=dict(feet))
            )
            t += self.ss
            feet[step.side] = step
            last = i == len(self.steps) - 1
            if last:
                end = (self._centre(feet["left"]) + self._centre(feet["right"])) / 2
                zmp = (self._centre(feet[support]), end)
                phases.append(Phase(t, t + self.tEnd, None, zmp=zmp, feet=dict(feet)))
                t += self.tEnd
            else:
                zmp = (self._centre(feet[support]), self._centre(step))
                phases.append(Phase(t, t + self.ds, None, zmp=zmp, feet=dict(feet)))
                t += self.ds
        self.phases = phases
        self.final = feet
        self.duration = t
        self._starts = np.array([p.start for p in phases])
        self._last: Phase | None = None

    def extend(self, steps: Sequence[Footprint], now: float) -> None:
        """Append ``steps`` to the plan (online steps); the plan before ``now`` (s) is
        unchanged: only the end double support, if it has begun later than ``now``,
        is replaced by the new swings."""
        if self.steps and self.duration - self.tEnd < now:
            raise CommandError(
                f"StepPlan.extend: the walk's last swing ended at "
                f"{self.duration - self.tEnd:.3f} s, before now ({now:.3f} s)"
            )
        self.steps.extend(steps)
        self._build()

    # -- evaluation ----------------------------------------------------------------
    def phaseAt(self, t: float) -> Phase:
        """The phase containing ``t`` (the last one after the end, the first before 0)."""
        if not self.steps:
            return self.phases[0]
        last = self._last  # a tick asks several times for the same phase: check it first
        if last is not None and last.start <= t < last.end:
            return last
        i = int(np.searchsorted(self._starts, t, side="right")) - 1
        self._last = self.phases[min(max(i, 0), len(self.phases) - 1)]
        return self._last

    def contactPhase(self, t: float) -> int:
        """SoT's ``contactphase``: 1 on the left foot alone, -1 on the right, 0 both."""
        p = self.phaseAt(t)
        return 0 if p.support is None or t >= self.duration else (1 if p.support == "left" else -1)

    def zmpAt(self, t: float) -> np.ndarray:
        """``p_ref(t)`` (size 2, m, world)."""
        p = self.phaseAt(t)
        if p.support is not None:
            return self._centre(p.feet[p.support])
        a, b = p.zmp
        start = p.start + (self.tHold if p is self.phases[0] else 0.0)
        m = quintic((t - start) / (p.end - start))[0] if p.end > start else 1.0
        return a + (b - a) * m

    def footprintsAt(self, t: float) -> dict[str, Footprint]:
        """The footprints of the feet on the ground at ``t`` (a swinging foot's is where
        it left)."""
        if t >= self.duration:
            return self.final
        return self.phaseAt(t).feet

    def zmpReference(self, times: np.ndarray) -> np.ndarray:
        """``p_ref`` at each of ``times`` (``n x 2``, m)."""
        return np.array([self.zmpAt(float(t)) for t in times])

    def feet(self, t: float) -> dict[str, tuple[np.ndarray, np.ndarray, np.ndarray]]:
        """Each sole frame's ``(position (3,), yaw rate-free rotation angle, velocity)``
        at ``t``: ``side -> (p, yaw, nu)`` with ``p`` (m, world), ``yaw`` (rad) as a
        1-array, ``nu = (dp/dt, dyaw/dt)`` (size 4: m/s and rad/s)."""
        out = {}
        for side, f in self.footprintsAt(t).items():
            out[side] = (np.array([f.x, f.y, 0.0]), np.array([f.yaw]), np.zeros(4))
        p = self.phaseAt(t)
        if p.swing is not None and p.start <= t < p.end:
            f0, f1 = p.swing
            T = p.end - p.start
            s = (t - p.start) / T
            a = LIFT_RATIO
            r = (s - a) / (1 - 2 * a)
            m, dm, _ = quintic(r)
            dm /= (1 - 2 * a) * T
            b, db, _ = _height(s)
            dyaw = _wrap(f1.yaw - f0.yaw)
            delta = np.array([f1.x - f0.x, f1.y - f0.y])
            pos = np.array([f0.x + delta[0] * m, f0.y + delta[1] * m, self.stepHeight * b])
            nu = np.array([delta[0] * dm, delta[1] * dm, self.stepHeight * db / T, dyaw * dm])
            out[f1.side] = (pos, np.array([f0.yaw + dyaw * m]), nu)
        return out

    def supportPolygon(self, t: float) -> np.ndarray:
        """The corners (k x 2, m, world) of the soles on the ground at ``t``: both in
        double support, the support foot's in single support (not their hull)."""
        p = self.phaseAt(t)
        feet = self.footprintsAt(t)
        sides = ["left", "right"] if p.support is None or t >= self.duration else [p.support]
        return np.concatenate([feet[s].point(self.sole.corners()) for s in sides])
