"""Trajectory sources: cubic interpolation to a goal, and a motion player (sot-tools).

``CubicInterpolationSE3`` and ``CubicInterpolation`` move from the value of ``init`` at
``start(T)`` to the value of ``goal`` in ``T`` seconds with zero velocity at both ends;
``Seqplay`` plays a whole-body motion read from files, one row per tick.

All outputs are functions of the tick: ``start`` records the current tick ``t0`` and
the value at tick ``t`` is the trajectory at time ``(t - t0) * samplingPeriod``. A
tick at which nothing reads them is simply skipped: the value at the next read is the
one of its own tick. ``docs/operators.md`` has the formulas and the file format.
"""

from __future__ import annotations

import math
import os
from typing import Any

import numpy as np
import pinocchio as pin

from ..dynamics.types import SE3
from ..errors import CommandError, SotpyError
from ..graph import VECTOR, Entity, Input, Output, command, pool
from ._util import check_vector, homogeneous_to_se3, who

__all__ = ["CubicInterpolation", "CubicInterpolationSE3", "Seqplay", "cubic_profile"]


def cubic_profile(tau: float, duration: float) -> tuple[float, float]:
    """The cubic time scaling with zero end velocities and its time derivative.

    ``s(tau) = 3 tau^2 - 2 tau^3`` for ``tau`` in ``[0, 1]`` (clamped outside), and
    ``ds/dt = 6 tau (1 - tau) / duration`` (1/s). ``s(0) = 0``, ``s(1) = 1``, ``s(1/2) =
    1/2``; ``ds/dt`` is zero at both ends and ``1.5 / duration`` in the middle.
    """
    if tau <= 0.0:
        return 0.0, 0.0
    if tau >= 1.0:
        return 1.0, 0.0
    return tau * tau * (3.0 - 2.0 * tau), 6.0 * tau * (1.0 - tau) / duration


class _Interpolation:
    """Mixin: the state machine shared by the cubic interpolations (sot-tools'):

    - before ``start`` (and after ``reset``): ``sout`` is ``init`` (read live), the
      velocity zero;
    - ``start(T)`` reads ``init`` and ``goal`` now, at tick ``t0 = pool.time``;
    - at tick ``t``, with ``tau = (t - t0) * samplingPeriod / T``: the cubic for
      ``tau < 1``; for ``tau >= 1`` ``sout`` is ``goal`` (read live, so a goal that
      moves on is followed) and the velocity zero.

    ``sout`` depends on ``init`` before ``start`` and on ``goal`` after it, so only
    ``init`` needs to be set to read ``sout`` before a motion.
    """

    def __init__(self, name: str) -> None:
        self._period: float | None = None
        self._t0: int | None = None
        self._duration = 0.0

    def _tau(self, t: int) -> float | None:
        """Normalised time of tick ``t`` in the motion (None: not started)."""
        if self._t0 is None:
            return None
        return (t - self._t0) * self._period / self._duration  # type: ignore[operator]

    @command
    def setSamplingPeriod(self, period: float) -> None:
        """Duration of a tick (s, > 0)."""
        if not (math.isfinite(period) and period > 0.0):
            raise CommandError(
                f"{who(self, 'setSamplingPeriod')}: expected a period > 0 (s), got {period}"
            )
        self._period = period
        self._refresh()

    @command
    def getSamplingPeriod(self) -> float:
        """Duration of a tick (s); raises if it was not set."""
        if self._period is None:
            raise CommandError(f"{who(self, 'getSamplingPeriod')}: the period is not set")
        return self._period

    @command
    def start(self, duration: float) -> None:
        """Read ``init`` and ``goal`` now and move from one to the other in
        ``duration`` seconds (> 0), starting at the current tick."""
        if self._period is None:
            raise CommandError(
                f"{who(self, 'start')}: call setSamplingPeriod(dt) first (the duration of "
                "a tick, s)"
            )
        if not (math.isfinite(duration) and duration > 0.0):
            raise CommandError(f"{who(self, 'start')}: expected a duration > 0 (s), got {duration}")
        if self._t0 is not None:
            raise CommandError(
                f"{who(self, 'start')}: a motion was already started (at tick {self._t0}); "
                "call reset() first (sot-tools ignored this call silently)"
            )
        self._begin(self.init.value, self.goal.value)  # type: ignore[attr-defined]
        self._duration = duration
        self._t0 = pool.time
        self.sout.setDependencies([self.goal])  # type: ignore[attr-defined]
        self._refresh()

    @command
    def reset(self) -> None:
        """Forget the motion: ``sout`` follows ``init`` again until the next ``start``."""
        self._t0 = None
        self.sout.setDependencies([self.init])  # type: ignore[attr-defined]
        self._refresh()

    def _begin(self, init: Any, goal: Any) -> None:  # pragma: no cover - overridden
        raise NotImplementedError

    def _refresh(self) -> None:
        for sig in self.signals():
            if sig.direction == "output":
                sig.setReady()  # type: ignore[attr-defined]


class CubicInterpolation(_Interpolation, Entity):
    """Cubic interpolation between two vectors (sot-tools' ``CubicInterpolation``).

    ``sout(t) = x0 + s(tau) (x1 - x0)`` and ``soutdot(t) = ds/dt (x1 - x0)`` with
    ``s(tau) = 3 tau^2 - 2 tau^3``, ``tau = (t - t0) dt / T`` (see ``_Interpolation``
    for before and after the motion). ``x0 = init``, ``x1 = goal`` at ``start``.
    """

    init = Input(VECTOR, doc="x0: start value (read at start; sout before start)")
    goal = Input(VECTOR, doc="x1: goal value, same size (read at start; sout after)")

    def __init__(self, name: str) -> None:
        super().__init__(name)
        self._x0 = self._dx = np.zeros(0)

    def _begin(self, init: np.ndarray, goal: np.ndarray) -> None:
        check_vector(self.init, init)
        check_vector(self.goal, goal, init.shape[0], "the size of init")
        self._x0, self._dx = init.copy(), goal - init

    @Output(VECTOR, deps=("init",), withTime=True, timeDependent=True, doc="x(t)")
    def sout(self, t: int, x: np.ndarray) -> np.ndarray:
        tau = self._tau(t)
        if tau is None or tau >= 1.0:
            return x.copy()  # init before the motion, goal after it
        s, _ = cubic_profile(tau, self._duration)
        return self._x0 + s * self._dx

    @Output(VECTOR, deps=("sout",), withTime=True, timeDependent=True, doc="dx/dt (per s)")
    def soutdot(self, t: int, x: np.ndarray) -> np.ndarray:
        tau = self._tau(t)
        if tau is None or tau >= 1.0:
            return np.zeros_like(x)
        _, sdot = cubic_profile(tau, self._duration)
        return sdot * self._dx


class CubicInterpolationSE3(_Interpolation, Entity):
    """Cubic interpolation between two placements (sot-tools' ``CubicInterpolationSE3``).

    With ``M0 = (R0, p0) = init`` and ``M1 = (R1, p1) = goal`` read at ``start(T)``,
    ``u = log3(R0^T R1)`` and ``s(tau) = 3 tau^2 - 2 tau^3``, ``tau = (t - t0) dt / T``:

    - ``sout = (R0 exp3(s u), p0 + s (p1 - p0))``: the translation moves on the
      straight line (as in sot-tools) and the rotation along the geodesic (sot-tools
      kept ``R0`` and jumped to ``R1`` at the end);
    - ``soutdot = ds/dt (p1 - p0)``: the translation velocity in the world frame (m/s),
      as in sot-tools;
    - ``velocity = (R^T soutdot, ds/dt u)``: the spatial velocity of ``sout`` in its own
      frame (LOCAL, linear first, m/s and rad/s), what ``FeaturePose.referenceVelocity``
      takes.

    Both velocities are zero at both ends, before ``start`` and after the motion.
    """

    init = Input(SE3, doc="M0: start placement (read at start; sout before start)")
    goal = Input(SE3, doc="M1: goal placement (read at start; sout after the motion)")

    def __init__(self, name: str) -> None:
        super().__init__(name)
        self._M0 = pin.SE3.Identity()
        self._dp = np.zeros(3)
        self._u = np.zeros(3)

    def _begin(self, init: pin.SE3, goal: pin.SE3) -> None:
        self._M0 = init.copy()
        self._dp = goal.translation - init.translation
        self._u = pin.log3(init.rotation.T @ goal.rotation)

    def _pose(self, s: float) -> pin.SE3:
        M0 = self._M0
        return pin.SE3(M0.rotation @ pin.exp3(s * self._u), M0.translation + s * self._dp)

    @Output(SE3, deps=("init",), withTime=True, timeDependent=True, doc="M(t)")
    def sout(self, t: int, M: pin.SE3) -> pin.SE3:
        tau = self._tau(t)
        if tau is None or tau >= 1.0:
            return M.copy()  # init before the motion, goal after it
        return self._pose(cubic_profile(tau, self._duration)[0])

    @Output(VECTOR, deps=("sout",), withTime=True, timeDependent=True, doc="dp/dt (m/s)")
    def soutdot(self, t: int, M: pin.SE3) -> np.ndarray:
        tau = self._tau(t)
        if tau is None or tau >= 1.0:
            return np.zeros(3)
        return cubic_profile(tau, self._duration)[1] * self._dp

    @Output(VECTOR, deps=("sout",), withTime=True, timeDependent=True, doc="nu (LOCAL)")
    def velocity(self, t: int, M: pin.SE3) -> np.ndarray:
        tau = self._tau(t)
        if tau is None or tau >= 1.0:
            return np.zeros(6)
        sdot = cubic_profile(tau, self._duration)[1]
        return np.concatenate([M.rotation.T @ (sdot * self._dp), sdot * self._u])


# -- Seqplay ------------------------------------------------------------------------------
# (extension, columns after the time, what) of the files Seqplay reads.
_REQUIRED = (
    ("posture", None, "posture"),
    ("la", 16, "left ankle placement (4 x 4 homogeneous matrix, row-major)"),
    ("ra", 16, "right ankle placement (4 x 4 homogeneous matrix, row-major)"),
    ("com", 3, "centre of mass (m)"),
)
_OPTIONAL = (
    ("fl", 6, "left foot force and moment (N, N m)"),
    ("fr", 6, "right foot force and moment (N, N m)"),
    ("comdot", 3, "centre of mass velocity (m/s)"),
    ("comddot", 3, "centre of mass acceleration (m/s^2)"),
    ("zmp", 3, "zero-moment point (m)"),
    ("ladot", 6, "left ankle velocity (LOCAL, m/s and rad/s)"),
    ("radot", 6, "right ankle velocity (LOCAL, m/s and rad/s)"),
)
_TIME_TOLERANCE = 1e-9


def _read_table(path: str, columns: int | None) -> np.ndarray:
    """Rows of ``time value...`` (tab- or space-separated); ``columns`` values per row,
    or any number, the same on every row, if None. Blank lines and lines starting with
    ``#`` are skipped (sot-tools stopped at the first blank line, ignoring the rest)."""
    rows: list[list[float]] = []
    width = None if columns is None else columns + 1
    with open(path, encoding="utf-8") as f:
        for lineno, line in enumerate(f, 1):
            text = line.strip()
            if not text or text.startswith("#"):
                continue
            try:
                row = [float(x) for x in text.split()]
            except ValueError:
                raise SotpyError(f"{path}, line {lineno}: expected numbers, got {text!r}") from None
            if not all(math.isfinite(x) for x in row):
                raise SotpyError(f"{path}, line {lineno}: non-finite number in {text!r}")
            if width is None:
                width = len(row)
                if width < 2:
                    raise SotpyError(
                        f"{path}, line {lineno}: expected the time then at least one value"
                    )
            if len(row) != width:
                raise SotpyError(
                    f"{path}, line {lineno}: expected {width} numbers (the time, then "
                    f"{width - 1} values), got {len(row)}"
                )
            rows.append(row)
    if not rows:
        raise SotpyError(f"{path}: no data (expected rows of: time, then values)")
    return np.array(rows)


class Seqplay(Entity):
    """Play a whole-body motion read from files, one row per tick (sot-tools' ``Seqplay``).

    ``load(basename)`` reads ``basename.posture``, ``.la``, ``.ra``, ``.com`` and the
    optional ``.fl`` + ``.fr``, ``.comdot``, ``.comddot``, ``.zmp``, ``.ladot`` +
    ``.radot`` (format in ``docs/operators.md``); ``start()`` plays them from the
    current tick ``t0``: the outputs at tick ``t`` are row ``k = t - t0`` (the last row
    once the motion is over, row 0 before ``start``).

    Velocities and accelerations not given by a file are forward differences of the
    rows, with the time column: ``comdot[k] = (com[k+1] - com[k]) / (time[k+1] -
    time[k])``, ``comddot[k]`` likewise from ``comdot``, the ankle velocities
    ``log6(M[k]^-1 M[k+1]) / (time[k+1] - time[k])`` (LOCAL, linear first); all are
    zero before ``start`` and at the last row (the motion has stopped).
    """

    def __init__(self, name: str) -> None:
        self._data: dict[str, Any] | None = None
        self._t0: int | None = None
        self._basename = ""

    # -- commands ---------------------------------------------------------------------
    @command
    def load(self, basename: str) -> None:
        """Read the motion from ``basename.posture``, ``.la``, ``.ra``, ``.com`` (and the
        optional files); the player goes back to row 0, not started.

        Every file has one row per tick: the time (s), then the values. All files
        must have the same number of rows and the same time column.
        """
        tables: dict[str, np.ndarray] = {}
        for ext, columns, _ in _REQUIRED:
            path = f"{basename}.{ext}"
            if not os.path.isfile(path):
                raise CommandError(f"{who(self, 'load')}: cannot open {path!r} (required)")
            tables[ext] = self._readTable(path, columns)
        for ext, columns, _ in _OPTIONAL:
            path = f"{basename}.{ext}"
            if os.path.isfile(path):
                tables[ext] = self._readTable(path, columns)
        for a, b in (("fl", "fr"), ("ladot", "radot")):
            if (a in tables) != (b in tables):
                have, missing = (a, b) if a in tables else (b, a)
                raise CommandError(
                    f"{who(self, 'load')}: {basename}.{have} was found but not "
                    f"{basename}.{missing}: they go together"
                )
        n = tables["posture"].shape[0]
        time = tables["com"][:, 0]
        if any(table.shape[0] != n for table in tables.values()):
            counts = ", ".join(f"{basename}.{e}: {t.shape[0]}" for e, t in tables.items())
            raise CommandError(
                f"{who(self, 'load')}: the files must have the same number of rows; read {counts}"
            )
        for ext, table in tables.items():
            bad = np.flatnonzero(np.abs(table[:, 0] - time) > _TIME_TOLERANCE)
            if bad.size:
                k = int(bad[0])
                raise CommandError(
                    f"{who(self, 'load')}: {basename}.{ext}, row {k + 1}: time "
                    f"{table[k, 0]!r} differs from {basename}.com's {time[k]!r}"
                )
        if n > 1 and not (np.diff(time) > 0).all():
            k = int(np.flatnonzero(np.diff(time) <= 0)[0])
            raise CommandError(
                f"{who(self, 'load')}: {basename}.com, row {k + 2}: the time must increase "
                f"strictly, got {time[k]!r} then {time[k + 1]!r}"
            )
        self._data = self._prepare(basename, tables, time)
        self._basename = basename
        self._t0 = None
        self._refresh()

    @command
    def start(self) -> None:
        """Play the motion from the current tick (row 0 now, row k k ticks later)."""
        if self._data is None:
            raise CommandError(f"{who(self, 'start')}: call load(basename) first")
        if self._t0 is not None:
            raise CommandError(
                f"{who(self, 'start')}: the motion was already started (at tick {self._t0}); "
                "call load() again to replay it (sot-tools ignored this call silently)"
            )
        self._t0 = pool.time
        self._refresh()

    # -- data -------------------------------------------------------------------------
    def _readTable(self, path: str, columns: int | None) -> np.ndarray:
        try:
            return _read_table(path, columns)
        except (SotpyError, OSError, UnicodeDecodeError) as exc:
            raise CommandError(f"{who(self, 'load')}: {exc}") from None

    def _prepare(self, basename: str, tables: dict[str, np.ndarray], time: np.ndarray) -> dict:
        data: dict[str, Any] = {"n": time.shape[0]}
        dt = np.diff(time)[:, None]  # (n - 1, 1): duration of each row (s)
        data["posture"] = tables["posture"][:, 1:]
        for ext in ("la", "ra"):
            placements = []
            for k, row in enumerate(tables[ext][:, 1:]):
                try:
                    placements.append(
                        homogeneous_to_se3(row.reshape(4, 4), f"{basename}.{ext}, row {k + 1}")
                    )
                except ValueError as exc:
                    raise CommandError(f"{who(self, 'load')}: {exc}") from None
            data[ext] = placements
            if f"{ext}dot" in tables:
                data[f"{ext}dot"] = tables[f"{ext}dot"][:, 1:]
            else:
                vel = np.zeros((len(placements), 6))
                for k in range(len(placements) - 1):
                    rel = placements[k].inverse() * placements[k + 1]
                    vel[k] = pin.log6(rel).vector / dt[k, 0]
                data[f"{ext}dot"] = vel
        com = tables["com"][:, 1:]
        data["com"] = com
        data["comdot"] = tables["comdot"][:, 1:] if "comdot" in tables else _forward(com, dt)
        data["comddot"] = (
            tables["comddot"][:, 1:] if "comddot" in tables else _forward(data["comdot"], dt)
        )
        for ext in ("fl", "fr", "zmp"):
            data[ext] = tables[ext][:, 1:] if ext in tables else None
        return data

    def _row(self, sig: Any, t: int) -> int:
        if self._data is None:
            raise SotpyError(f"{sig.name}: no motion: call {self.name}.load(basename) first")
        if self._t0 is None:
            return 0
        return min(max(t - self._t0, 0), self._data["n"] - 1)

    def _moving(self, k: int) -> bool:
        return self._t0 is not None and k < self._data["n"] - 1  # type: ignore[index]

    def _get(self, sig: Any, t: int, key: str, rate: bool = False) -> Any:
        k = self._row(sig, t)
        table = self._data[key]  # type: ignore[index]
        if table is None:
            raise SotpyError(
                f"{sig.name}: no data: {self._basename}.{key} was not found when loading"
            )
        if rate and not self._moving(k):
            return np.zeros_like(table[k])
        return table[k].copy()

    def _refresh(self) -> None:
        for sig in self.signals():
            sig.setReady()  # type: ignore[attr-defined]

    # -- outputs ----------------------------------------------------------------------
    @Output(VECTOR, withTime=True, doc="the posture of the current row")
    def posture(self, t: int) -> np.ndarray:
        return self._get(self.posture, t, "posture")

    @Output(SE3, withTime=True, doc="left ankle placement (m)")
    def leftAnkle(self, t: int) -> pin.SE3:
        return self._get(self.leftAnkle, t, "la")

    @Output(SE3, withTime=True, doc="right ankle placement (m)")
    def rightAnkle(self, t: int) -> pin.SE3:
        return self._get(self.rightAnkle, t, "ra")

    @Output(VECTOR, withTime=True, doc="left ankle velocity, LOCAL (m/s, rad/s)")
    def leftAnkleVel(self, t: int) -> np.ndarray:
        return self._get(self.leftAnkleVel, t, "ladot", rate=True)

    @Output(VECTOR, withTime=True, doc="right ankle velocity, LOCAL (m/s, rad/s)")
    def rightAnkleVel(self, t: int) -> np.ndarray:
        return self._get(self.rightAnkleVel, t, "radot", rate=True)

    @Output(VECTOR, withTime=True, doc="centre of mass (m)")
    def com(self, t: int) -> np.ndarray:
        return self._get(self.com, t, "com")

    @Output(VECTOR, withTime=True, doc="centre of mass velocity (m/s)")
    def comdot(self, t: int) -> np.ndarray:
        return self._get(self.comdot, t, "comdot", rate=True)

    @Output(VECTOR, withTime=True, doc="centre of mass acceleration (m/s^2)")
    def comddot(self, t: int) -> np.ndarray:
        return self._get(self.comddot, t, "comddot", rate=True)

    @Output(VECTOR, withTime=True, doc="left foot force and moment (N, N m)")
    def forceLeftFoot(self, t: int) -> np.ndarray:
        return self._get(self.forceLeftFoot, t, "fl")

    @Output(VECTOR, withTime=True, doc="right foot force and moment (N, N m)")
    def forceRightFoot(self, t: int) -> np.ndarray:
        return self._get(self.forceRightFoot, t, "fr")

    @Output(VECTOR, withTime=True, doc="zero-moment point (m)")
    def zmp(self, t: int) -> np.ndarray:
        return self._get(self.zmp, t, "zmp")


def _forward(x: np.ndarray, dt: np.ndarray) -> np.ndarray:
    """Forward differences ``(x[k+1] - x[k]) / dt[k]``, zero at the last row."""
    out = np.zeros_like(x)
    out[:-1] = np.diff(x, axis=0) / dt
    return out
