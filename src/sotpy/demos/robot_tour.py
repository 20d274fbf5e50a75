"""The robot tour: a humanoid waves its arms and turns its head while standing.

:func:`run_robot_tour` is the story (``sotpy demo robot [--robot NAME] [--duration S]
[--viewer] [--plot PATH] [--dt S]`` calls it; ``examples/robot_tour.py`` is the same
story as a script to copy). It builds this graph, runs it, and hands the run to
:class:`sotpy.demos.checks.TourLog` (the table and the checks)::

    robot = load_robot("talos", prefix="tour_talos")      # Dynamic + Device, half-sitting
    robot.device.setControlType("velocity")
    sine = JointSineVelocity("tour_talos_sine", robot.model, robot.halfSitting, 0.001)
    sine.selectChains(["arm_left_7_joint", "arm_right_7_joint", "rgbd_rgb_frame"],
                      ["leg_left_6_joint", "leg_right_6_joint", ...])
    plug(sine.control, robot.device.control)
    for _ in range(3000):
        robot.device.increment(0.001)

:class:`JointSineVelocity` commands a velocity that swings the selected joints
sinusoidally about the reference posture; the base twist and the other joints' velocities
are zero. With a zero base twist and still legs, the feet of a floating-base humanoid do
not move at all: their placements after the run equal the initial ones to rounding
(checked to :data:`FEET_TOLERANCE`).

The maths. With the amplitude ``A_j`` of joint ``j`` (rad, or m for a prismatic joint),
the angular frequency ``w = 2 pi f`` (rad/s, ``f`` in Hz), the time step ``dt`` (s) and
the start tick ``t0``, the control at tick ``t`` is::

    v_j(t) = A_j w cos(w (t - t0) dt)

The device integrates it by explicit Euler (``q_j(t + 1) = q_j(t) + v_j(t) dt``), so
after ``N`` ticks, with ``h = w dt``::

    q_j(t0 + N) - q_ref,j = A_j h sum_{k < N} cos(k h)
                          = A_j h sin(N h / 2) cos((N - 1) h / 2) / sin(h / 2)
                          = A_j sin(w N dt) + e,   |e| <= A_j h (1 + h^2 / 100)

and the excursion never exceeds ``A_j kappa(h)`` with::

    kappa(h) = h (1 + sin(h / 2)) / (2 sin(h / 2)) = 1 + h / 2 + h^2 / 24 + O(h^3)

(:func:`sineExcursion`). Each joint's amplitude is the requested amplitude ``A`` reduced
so that the joint stays inside its position and velocity limits whatever the run's
length::

    A_j = min(A, SAFETY margin_j / kappa(h), SAFETY vmax_j / w)

where ``margin_j`` is the distance from the reference to the joint's nearest position
limit, ``vmax_j`` its velocity limit and ``SAFETY`` = 0.9 (:data:`SAFETY`). A joint
resting on a limit (Talos' grippers) or without velocity (Romeo's fingers) gets
``A_j = 0``. Frequencies are limited to ``w dt < pi`` (below the Nyquist frequency
``1 / (2 dt)``).
"""

from __future__ import annotations

import difflib
import fnmatch
import math
import time
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import pinocchio as pin

from ..errors import CommandError, EntityError, SotpyError
from ..graph import VECTOR, Entity, Output, command, plug, pool

__all__ = [
    "DEFAULT_AMPLITUDE",
    "DEFAULT_FREQUENCY",
    "FEET_TOLERANCE",
    "SAFETY",
    "STILL_OP_POINTS",
    "SWING_OP_POINTS",
    "WRIST_OP_POINTS",
    "JointSineVelocity",
    "chainJoints",
    "run_robot_tour",
    "sineExcursion",
]

#: Default swing amplitude A, in rad.
DEFAULT_AMPLITUDE = 0.3
#: Default swing frequency f, in Hz (one swing every 2.5 s; not 0.5 Hz, whose once-a-second
#: rows would all show the reference posture).
DEFAULT_FREQUENCY = 0.4
#: Fraction of the distance to a position limit (and of a velocity limit) a swing may use.
SAFETY = 0.9
#: The feet must keep their placements to this (m for positions, rad for rotations).
FEET_TOLERANCE = 1e-9
#: A coupled joint must keep following its master to this (rad or m).
COUPLING_TOLERANCE = 1e-9
#: For a robot with feet: op points (fnmatch patterns of SoT names) whose chains from the
#: root swing ...
SWING_OP_POINTS = ("*-wrist", "gaze")
#: ... and those whose chains stay still (the legs; the soles' frames are added).
STILL_OP_POINTS = ("*-ankle",)
#: Op points printed, the first one the robot has.
WRIST_OP_POINTS = ("right-wrist", "end-effector", "wrist", "left-wrist")

_NO_BOUND = 1e300  # |bound| >= this, or not finite: no bound (Pinocchio's DBL_MAX)


# -- maths -----------------------------------------------------------------------------
def sineExcursion(h: float) -> float:
    """The largest ``|h sum_{k < N} cos(k h)|`` over every ``N >= 0``, for ``0 < h < pi``.

    ``sum_{k < N} cos(k h) = sin(N h / 2) cos((N - 1) h / 2) / sin(h / 2)`` and
    ``sin(a) cos(a - h / 2) = (sin(2 a - h / 2) + sin(h / 2)) / 2``, so the sum lies in
    ``[(-1 + sin(h / 2)), (1 + sin(h / 2))] / (2 sin(h / 2))``; hence the bound
    ``kappa(h) = h (1 + sin(h / 2)) / (2 sin(h / 2)) = 1 + h / 2 + h^2 / 24 + O(h^3)``,
    reached for some ``N``: the Euler integral of ``A w cos(w t)`` with step ``dt``
    (``h = w dt``) stays within ``A kappa(h)`` of its start.

    Raises:
        ValueError: ``h`` not in ``(0, pi)``.
    """
    if not (0.0 < h < math.pi):
        raise ValueError(f"sineExcursion: expected 0 < h < pi, got {h!r}")
    s = math.sin(0.5 * h)
    return h * (1.0 + s) / (2.0 * s)


def chainJoints(model: pin.Model, frames: Iterable[str]) -> list[str]:
    """The 1-DoF joints on the paths from the root to ``frames``, in model order.

    Args:
        model: the Pinocchio model.
        frames: Pinocchio frame names (joint names are frames too).

    Returns:
        The names of the joints with one configuration coordinate and one velocity
        (revolute, prismatic) that support at least one of the frames: those whose
        motion moves the frame. The free-flyer and the universe are never in it.

    Raises:
        KeyError: a frame is not in the model (the message gives the closest names).
    """
    joints: set[int] = set()
    for frame in frames:
        if not model.existFrame(frame):
            close = difflib.get_close_matches(frame, [f.name for f in model.frames], n=3)
            hint = f"; closest: {', '.join(close)}" if close else ""
            raise KeyError(f"no frame {frame!r} in model {model.name!r}{hint}")
        jid = model.frames[model.getFrameId(frame)].parentJoint
        joints.update(int(j) for j in model.supports[jid])
    return [
        model.names[j]
        for j in sorted(joints)
        if j > 0 and model.joints[j].nq == 1 and model.joints[j].nv == 1
    ]


def _bound(values: Any, sign: float) -> np.ndarray:
    b = np.array(values, dtype=np.float64)
    b[~np.isfinite(b) | (np.abs(b) >= _NO_BOUND)] = sign * np.inf
    return b


# -- the control entity ----------------------------------------------------------------
class JointSineVelocity(Entity):
    """Velocity control swinging joints sinusoidally about a reference posture

    ``JointSineVelocity(name, model, reference, dt=0.001)``: ``model`` a
    ``pinocchio.Model``, ``reference`` the configuration the device starts from (size
    nq, e.g. half-sitting), ``dt`` the device's time step in s. Output ``control``
    (size nv, time-dependent): zero base twist and zero velocity for the joints not
    selected; for a selected joint ``j``, ``v_j(t) = A_j w cos(w (t - t0) dt)`` in rad/s
    (m/s for a prismatic joint), ``w = 2 pi f``. Plugged into a velocity-controlled
    ``Device`` started at ``reference`` at tick ``t0``, joint ``j`` follows
    ``q_ref,j + A_j sin(w (t - t0) dt)`` to within ``A_j w dt (1 + (w dt)^2 / 100)``
    (explicit Euler's error).

    ``A_j`` is the amplitude ``A`` (``setAmplitude``, rad or m) reduced so that the joint
    stays within ``SAFETY`` (0.9) of its distance to its position limits and of its
    velocity limit: ``A_j = min(A, 0.9 margin_j / kappa(w dt), 0.9 vmax_j / w)``
    (``getAmplitudes``; the module documentation derives it). Selectable joints are
    those with one coordinate and one velocity (revolute, prismatic); by default every
    one of them is selected.
    """

    def __init__(
        self, name: str, model: pin.Model, reference: np.ndarray, dt: float = 1e-3
    ) -> None:
        who = f"{self.className}({name})"
        if not isinstance(model, pin.Model):
            raise EntityError(f"{who}: expected a pinocchio.Model, got {type(model).__name__}")
        self._model = model
        self._nv = model.nv
        names, iq, iv = [], [], []
        for jid in range(1, model.njoints):
            joint = model.joints[jid]
            if joint.nq == 1 and joint.nv == 1:
                names.append(model.names[jid])
                iq.append(joint.idx_q)
                iv.append(joint.idx_v)
        self._names = names
        self._iq = np.array(iq, dtype=np.intp)
        self._iv = np.array(iv, dtype=np.intp)
        self._lower = _bound(model.lowerPositionLimit[self._iq], -1.0)
        self._upper = _bound(model.upperPositionLimit[self._iq], 1.0)
        self._vmax = _bound(np.abs(model.velocityLimit[self._iv]), 1.0)
        self._selected = np.ones(len(names), dtype=bool)
        self._amplitude = DEFAULT_AMPLITUDE
        self._frequency = DEFAULT_FREQUENCY
        self._t0 = 0
        try:
            self._dt = self._checkedDt("", dt)
            self._checkNyquist("", self._frequency, self._dt)
            self._reference = self._checkedReference("", reference)
        except CommandError as exc:
            raise EntityError(str(exc)) from None
        self._amplitudes = np.zeros(self._nv)
        self._omega = 0.0
        self._update()

    @Output(
        VECTOR,
        withTime=True,
        doc="velocity v (size nv): A_j w cos(w (t - t0) dt) for the selected joints, rad/s "
        "(m/s if prismatic); zero elsewhere, zero base twist",
    )
    def control(self, t: int) -> np.ndarray:
        """Velocity v (size nv): A_j w cos(w (t - t0) dt) for the selected joints."""
        w = self._omega
        return self._amplitudes * (w * math.cos(w * (t - self._t0) * self._dt))

    # -- parameters ------------------------------------------------------------------
    @command
    def setAmplitude(self, amplitude: float) -> None:
        """Set the swing amplitude A in rad (m for prismatic joints), finite, >= 0

        Each joint swings by A_j = min(A, what its limits allow): see getAmplitudes.
        """
        if not (math.isfinite(amplitude) and amplitude >= 0.0):
            raise CommandError(
                f"{self._who('setAmplitude')}: amplitude must be a finite value >= 0 rad, got "
                f"{amplitude!r}; it is left {self._amplitude!r}"
            )
        self._amplitude = float(amplitude)
        self._update()

    @command
    def getAmplitude(self) -> float:
        """The requested swing amplitude A, in rad (m for prismatic joints)."""
        return self._amplitude

    @command
    def setFrequency(self, frequency: float) -> None:
        """Set the swing frequency f in Hz: 0 < f < 1 / (2 dt) (w = 2 pi f, w dt < pi)"""
        if not (math.isfinite(frequency) and frequency > 0.0):
            raise CommandError(
                f"{self._who('setFrequency')}: frequency must be a finite value > 0 Hz, got "
                f"{frequency!r}; it is left {self._frequency!r}"
            )
        self._checkNyquist("setFrequency", frequency, self._dt)
        self._frequency = float(frequency)
        self._update()

    @command
    def getFrequency(self) -> float:
        """The swing frequency f, in Hz."""
        return self._frequency

    @command
    def setTimeStep(self, dt: float) -> None:
        """Set the time step dt of the device, in s (> 0, and w dt < pi)"""
        dt = self._checkedDt("setTimeStep", dt)
        self._checkNyquist("setTimeStep", self._frequency, dt)
        self._dt = dt
        self._update()

    @command
    def getTimeStep(self) -> float:
        """The time step dt, in s."""
        return self._dt

    @command
    def setStartTick(self, tick: int) -> None:
        """Set the tick t0 at which the swing starts (phase 0; the device at reference)"""
        self._t0 = int(tick)
        self.control.setReady()

    @command
    def getStartTick(self) -> int:
        """The tick t0 at which the swing starts."""
        return self._t0

    @command
    def setReference(self, q: np.ndarray) -> None:
        """Set the reference posture (size nq; within the position limits)

        The joints swing about it: it must be the configuration of the device at the
        start tick. The amplitudes are recomputed from its distance to the limits.
        """
        self._reference = self._checkedReference("setReference", q)
        self._update()

    @command
    def getReference(self) -> np.ndarray:
        """The reference posture (a copy, size nq)."""
        return self._reference.copy()

    # -- joint selection ---------------------------------------------------------------
    @command
    def selectJoints(self, patterns: Any, exclude: Any = None) -> list[str]:
        """Swing the joints whose names match a pattern and no pattern of exclude

        patterns, exclude: lists of fnmatch patterns of joint names ('arm_*', '*Wrist*',
        '*'); each pattern of patterns must match a selectable (1-DoF) joint. Replaces
        the selection; returns the selected joints, in model order.
        """
        include = self._patterns("selectJoints", "patterns", patterns)
        excl = self._patterns("selectJoints", "exclude", exclude)
        for p in include:
            if not fnmatch.filter(self._names, p):
                close = difflib.get_close_matches(p, self._names, n=3)
                hint = f" (closest: {', '.join(close)})" if close else ""
                raise CommandError(
                    f"{self._who('selectJoints')}: pattern {p!r} matches no 1-DoF joint of "
                    f"model {self._model.name!r}{hint}; the selection is left unchanged"
                )
        selected = np.array(
            [
                any(fnmatch.fnmatchcase(n, p) for p in include)
                and not any(fnmatch.fnmatchcase(n, p) for p in excl)
                for n in self._names
            ],
            dtype=bool,
        )
        return self._select(selected)

    @command
    def selectChains(self, frames: Any, exclude: Any = None) -> list[str]:
        """Swing the joints on the paths from the root to frames, minus those to exclude

        frames, exclude: lists of Pinocchio frame names (joints are frames too), e.g. the
        frames of the op points 'left-wrist', 'right-wrist', 'gaze' and, to exclude, of
        'left-ankle', 'right-ankle'. Replaces the selection; returns the selected joints,
        in model order.
        """
        include = self._patterns("selectChains", "frames", frames)
        excl = self._patterns("selectChains", "exclude", exclude)
        try:
            chosen = set(chainJoints(self._model, include))
            chosen -= set(chainJoints(self._model, excl))
        except KeyError as exc:
            raise CommandError(
                f"{self._who('selectChains')}: {exc.args[0]}; the selection is left unchanged"
            ) from None
        return self._select(np.array([n in chosen for n in self._names], dtype=bool))

    @command
    def getJoints(self) -> list[str]:
        """The selected joints, in model order."""
        return [n for n, s in zip(self._names, self._selected, strict=True) if s]

    @command
    def getAmplitudes(self) -> np.ndarray:
        """A_j per velocity component (size nv, rad or m): 0 where nothing swings

        A_j = min(A, 0.9 margin_j / kappa(w dt), 0.9 vmax_j / w), margin_j the distance
        from the reference to the nearest position limit, vmax_j the velocity limit.
        """
        return self._amplitudes.copy()

    # -- helpers -----------------------------------------------------------------------
    def _who(self, cmd: str) -> str:
        """``Class(name).cmd``, or ``Class(name)`` for the constructor (``cmd`` empty)."""
        return f"{self.className}({self.name})" + (f".{cmd}" if cmd else "")

    def _select(self, selected: np.ndarray) -> list[str]:
        self._selected = selected
        self._update()
        return self.getJoints()

    def _patterns(self, cmd: str, what: str, value: Any) -> list[str]:
        if value is None:
            return []
        if isinstance(value, str):
            return [value]
        if isinstance(value, (list, tuple)) and all(isinstance(v, str) for v in value):
            return list(value)
        raise CommandError(
            f"{self._who(cmd)}: argument {what!r}: expected a list of strings, got "
            f"{type(value).__name__} {value!r}; the selection is left unchanged"
        )

    def _checkedDt(self, cmd: str, dt: Any) -> float:
        if isinstance(dt, bool) or not isinstance(dt, (int, float)) or not math.isfinite(dt):
            dt = float("nan")
        if not dt > 0.0:
            raise CommandError(f"{self._who(cmd)}: dt must be a finite value > 0 s, got {dt!r}")
        return float(dt)

    def _checkNyquist(self, cmd: str, frequency: float, dt: float) -> None:
        if 2.0 * math.pi * frequency * dt >= math.pi:
            raise CommandError(
                f"{self._who(cmd)}: frequency {frequency!r} Hz with dt = {dt!r} s is at or "
                f"above the Nyquist frequency 1 / (2 dt) = {0.5 / dt:g} Hz; nothing is changed"
            )

    def _checkedReference(self, cmd: str, q: Any) -> np.ndarray:
        q = np.array(q, dtype=np.float64)
        if q.shape != (self._model.nq,) or not np.isfinite(q).all():
            raise CommandError(
                f"{self._who(cmd)}: reference must be a finite configuration of size nq = "
                f"{self._model.nq}, got shape {q.shape}"
            )
        qj = q[self._iq]
        out = (qj < self._lower - 1e-9) | (qj > self._upper + 1e-9)
        if out.any():
            bad = ", ".join(
                f"{self._names[i]} = {qj[i]:.6g} not in [{self._lower[i]:.6g}, "
                f"{self._upper[i]:.6g}]"
                for i in np.flatnonzero(out)[:5]
            )
            raise CommandError(f"{self._who(cmd)}: reference outside the position limits: {bad}")
        return q

    def _update(self) -> None:
        """Recompute w and every A_j (see getAmplitudes)."""
        w = 2.0 * math.pi * self._frequency
        kappa = sineExcursion(w * self._dt)
        qj = self._reference[self._iq]
        margin = np.maximum(np.minimum(qj - self._lower, self._upper - qj), 0.0)
        amp = np.minimum(self._amplitude, SAFETY * margin / kappa)
        amp = np.minimum(amp, SAFETY * self._vmax / w)
        amplitudes = np.zeros(self._nv)
        amplitudes[self._iv[self._selected]] = amp[self._selected]
        self._omega = w
        self._amplitudes = amplitudes
        self.control.setReady()


# -- the story -------------------------------------------------------------------------
def _select_tour_joints(sine: JointSineVelocity, robot: Any) -> list[str]:
    """Humanoid: the chains to the wrists and the gaze, not the legs. Arm: every joint."""
    if not robot.feet:
        return sine.selectJoints(["*"])
    ops = robot.opPoints

    def frames(patterns: Sequence[str]) -> list[str]:
        return [f for op, f in ops.items() if any(fnmatch.fnmatchcase(op, p) for p in patterns)]

    swing = frames(SWING_OP_POINTS)
    still = frames(STILL_OP_POINTS) + [foot.frame for foot in robot.feet.values()]
    joints = sine.selectChains(swing, still) if swing else []
    if not joints:
        raise SotpyError(
            f"robot tour: robot {robot.name!r} has no joint on the paths to its op points "
            f"matching {list(SWING_OP_POINTS)} (op points: {', '.join(ops) or 'none'}); "
            "nothing would move"
        )
    return joints


def _check_arguments(duration: Any, dt: Any, amplitude: Any, frequency: Any) -> None:
    for what, value in (("duration", duration), ("dt", dt)):
        number = isinstance(value, (int, float)) and not isinstance(value, bool)
        if not (number and math.isfinite(value) and value > 0):
            raise ValueError(f"run_robot_tour: {what} must be a finite value > 0 s, got {value!r}")
    number = isinstance(amplitude, (int, float)) and not isinstance(amplitude, bool)
    if not (number and math.isfinite(amplitude) and amplitude >= 0):
        raise ValueError(
            f"run_robot_tour: amplitude must be a finite value >= 0 rad, got {amplitude!r}"
        )
    if not (isinstance(frequency, (int, float)) and 0 < frequency < 0.5 / dt):
        raise ValueError(
            f"run_robot_tour: frequency must be > 0 Hz and below the Nyquist frequency "
            f"1 / (2 dt) = {0.5 / dt:g} Hz, got {frequency!r}"
        )


def run_robot_tour(
    robot: str | Path = "talos",
    duration: float = 3.0,
    dt: float = 1e-3,
    viewer: bool = False,
    quiet: bool = False,
    *,
    amplitude: float = DEFAULT_AMPLITUDE,
    frequency: float = DEFAULT_FREQUENCY,
    plot: str | Path | None = None,
    hold: float | None = 0.0,
) -> dict[str, Any]:
    """Load a robot and swing its arms and head (a whole arm) for ``duration`` seconds.

    The story, top to bottom: load ``robot`` with :func:`~sotpy.dynamics.load_robot`
    under a fresh prefix (``tour_<robot>``, ``tour_<robot>_2``, ...: the pool is neither
    cleared nor clashed with), set its device to velocity control, plug into
    ``device.control`` a :class:`JointSineVelocity` ``<prefix>_sine`` swinging, for a
    robot with feet, every joint on the paths from the root to the op points of
    :data:`SWING_OP_POINTS` (wrists, gaze) except those to :data:`STILL_OP_POINTS`
    (ankles) and the soles, and for a robot without feet (an arm) every 1-DoF joint;
    then call ``device.increment(dt)`` ``round(duration / dt)`` times. A
    :class:`~sotpy.demos.checks.TourLog` prints each second the tick, the position of
    the first op point of :data:`WRIST_OP_POINTS` and the CoM (both from the
    ``Dynamic``, m, world frame), and checks at the end that

    * the feet did not move: each sole's placement (from the ``Dynamic``) is the initial
      one to :data:`FEET_TOLERANCE` (m and rad); robots without feet skip this check;
    * no joint left its limits: ``device.boundsReport()`` counts no clamp;
    * every coupled joint still follows its master (``robot.couplings``, to
      :data:`COUPLING_TOLERANCE`).

    With ``viewer``, a :class:`~sotpy.viewer.RobotViewer` ``<prefix>_viewer`` shows the
    robot (its URL is printed) and, once the run is computed, replays it at real time
    (:func:`sotpy.demos.replay`); it is closed when the function returns or raises
    (Ctrl-C included). The entities stay in the pool for inspection.

    Args:
        robot: a shipped robot's name (``sotpy robots``) or the path of a ``.toml``.
        duration: simulated time, in s (> 0).
        dt: time step, in s (> 0).
        viewer: show the robot in a meshcat viewer and replay the motion there.
        quiet: print nothing.
        amplitude: swing amplitude A, in rad (each joint's is limited, see
            :class:`JointSineVelocity`).
        frequency: swing frequency, in Hz.
        plot: save a PNG there (:func:`sotpy.plotting.plot_robot_tour`).
        hold: with ``viewer``, keep it up at most this many seconds after the run
            (0: close it at once; None: until the page is closed or Ctrl-C).

    Returns:
        ``robot`` (name), ``prefix``, ``entities`` (names created), ``joints`` (those
        that swing: selected, with ``A_j > 0``), ``amplitudes`` (``A_j``, size nv, rad),
        ``ticks``, ``dt``, ``duration`` (s), ``wrist`` (the op point printed), ``path``
        (n x 7: t [s], wrist xyz, CoM xyz, every 10 ms and at the end), ``q`` (the
        configurations at the same times), ``limits`` (the swinging joints with finite
        limits: ``joints``, ``index`` in q, ``lower``, ``upper``), ``wrist_travel``
        (largest distance of the wrist from its start, m), ``feet_drift`` (largest sole
        displacement, m or rad; None without feet), ``feet_fixed`` (bool, None without
        feet), ``bounds`` (the ``boundsReport``), ``bounds_ok``, ``coupling_error`` (rad
        or m), ``couplings_ok``, ``ok`` (every check holds), ``table`` (the text
        printed), ``plot`` (path or None), ``wall_time`` (s of computation of the
        loop), ``viewer_url`` and ``viewer_pid`` (the meshcat server's address and
        process id, None without viewer; the process has ended on return).

    Raises:
        ValueError: ``duration`` or ``dt`` not finite and > 0, ``amplitude`` not finite
            and >= 0, ``frequency`` not in ``(0, 1 / (2 dt))``.
        sotpy.errors.SotpyError: unknown robot, broken description, a viewer that cannot
            start, or a failing step.
    """
    from ..dynamics import load_robot
    from ..plotting import plot_robot_tour
    from . import open_viewer, replay
    from .checks import TourLog, freePrefix

    _check_arguments(duration, dt, amplitude, frequency)
    steps = max(1, round(duration / dt))
    suffixes = ("{prefix}_dynamic", "{prefix}_device", "{prefix}_sine", "{prefix}_viewer")
    prefix = freePrefix("tour", robot, suffixes)
    emit = (lambda text: None) if quiet else (lambda text: print(text, flush=True))
    known = {e.name for e in pool.entities()}
    lines: list[str] = []

    def say(text: str) -> None:
        lines.append(text)
        emit(text)

    # -- the graph ----------------------------------------------------------------------
    r = load_robot(robot, prefix=prefix)  # Dynamic + Device at half-sitting
    r.device.setControlType("velocity")
    sine = JointSineVelocity(f"{prefix}_sine", r.model, r.halfSitting, float(dt))
    sine.setFrequency(float(frequency))
    sine.setAmplitude(float(amplitude))
    _select_tour_joints(sine, r)  # the arms and the head, not the legs
    sine.setStartTick(max(r.device.state.time, 0))
    plug(sine.control, r.device.control)

    # -- run it -------------------------------------------------------------------------
    view = open_viewer(r, prefix, say) if viewer else None
    try:
        log = TourLog(r, sine, steps, dt)
        say(log.header())
        begin = time.perf_counter()
        for _ in range(steps):
            r.device.increment(dt)
            row = log.record()
            if row is not None:
                say(row)
        result = log.report(wall_time=time.perf_counter() - begin)
        for line in result["table"].splitlines():
            say(line)
        result["plot"] = None
        if plot is not None:
            plot_robot_tour(result, plot)
            result["plot"] = str(plot)
            say(f"plot: {plot}")
        result["viewer_url"] = result["viewer_pid"] = None
        if view is not None:
            result["viewer_url"] = view.url()
            result["viewer_pid"] = view.serverProcess.pid
            replay(view, result["q"], result["path"][1, 0] - result["path"][0, 0], hold, say)
    finally:
        if view is not None:
            view.close()
    result["table"] = "\n".join(lines)
    result["entities"] = [e.name for e in pool.entities() if e.name not in known]
    return result
