"""The inverted-pendulum tutorial of the Stack of Tasks, as sotpy's first demo.

SoT's ``dynamic-graph-tutorial`` builds a two-entity graph: a cart-pole
(:class:`InvertedPendulum`) whose ``state`` feeds a state-feedback controller
(:class:`FeedbackController`) whose ``force`` drives the cart back::

    from sotpy.graph import plug
    from sotpy.tutorial import FeedbackController, InvertedPendulum

    a = InvertedPendulum("IP")
    b = FeedbackController("K")
    plug(a.state, b.state)
    plug(b.force, a.force)
    a.state.value = (0.0, 0.1, 0.0, 0.0)
    for _ in range(10_000):
        a.incr(0.001)

The loop is closed through the state signal: ``incr`` reads ``force`` at the tick of the
state, integrates, and writes the new state one tick later, as SoT's
``Device.increment`` does.

The physics (state derivative, RK4 step, linearisation, LQR gain) are plain functions
over numpy arrays, usable without a graph. :func:`run_pendulum` runs the whole story
with a tracer; ``sotpy demo pendulum`` and ``examples/inverted_pendulum.py`` call it.

Units: metres, radians, seconds, kilograms, newtons. ``theta`` is measured from the
upright vertical, positive when the pendulum leans towards +x.
"""

import math
import time as _time
from pathlib import Path
from typing import Any

import numpy as np

from .errors import CommandError, SignalTypeError, SotpyError
from .graph import DOUBLE, VECTOR, Entity, Input, Output, Tracer, command, plug

__all__ = [
    "DEFAULT_Q",
    "DEFAULT_R",
    "GRAVITY",
    "FeedbackController",
    "InvertedPendulum",
    "isConverged",
    "linearisedModel",
    "lqrGain",
    "rk4Step",
    "run_pendulum",
    "stateDerivative",
]

GRAVITY = 9.81
"""Default gravity acceleration, in m/s^2."""

DEFAULT_Q = (10.0, 10.0, 1.0, 1.0)
"""Diagonal of the default LQR state weight, for (x [m], theta [rad], x_dot [m/s],
theta_dot [rad/s]). Weighting the cart position as much as the angle brings the cart
back to the origin in a few seconds (slowest closed-loop pole about -1.7 rad/s)."""

DEFAULT_R = 0.1
"""Default LQR weight on the force, in 1/N^2 relative to the state weights."""

MAX_STEP = 1e-3
"""Longest RK4 step, in s: ``incr(dt)`` splits a longer ``dt`` into equal substeps."""


# -- physics ---------------------------------------------------------------------------
def stateDerivative(
    state: Any,
    force: float,
    cartMass: float = 1.0,
    pendulumMass: float = 1.0,
    length: float = 1.0,
    g: float = GRAVITY,
) -> np.ndarray:
    """Time derivative of the cart-pole state (see :class:`InvertedPendulum`).

    Args:
        state: (x [m], theta [rad], x_dot [m/s], theta_dot [rad/s]).
        force: horizontal force on the cart, in N.
        cartMass: M, in kg.
        pendulumMass: m, in kg.
        length: l, in m.
        g: gravity acceleration, in m/s^2.

    Returns:
        (x_dot [m/s], theta_dot [rad/s], x_ddot [m/s^2], theta_ddot [rad/s^2]).
    """
    _, th, xd, thd = (float(v) for v in state)
    xdd, thdd = _accelerations(th, thd, float(force), cartMass, pendulumMass, length, g)
    return np.array([xd, thd, xdd, thdd])


def _accelerations(
    th: float, thd: float, f: float, M: float, m: float, ell: float, g: float
) -> tuple[float, float]:
    """Solve the 2x2 mass-matrix system for (x_ddot [m/s^2], theta_ddot [rad/s^2])."""
    c = math.cos(th)
    s = math.sin(th)
    # [[a11, a12], [a12, a22]] (x_ddot, theta_ddot) = (b1, b2)
    a11 = M + m
    a12 = m * ell * c
    a22 = m * ell * ell
    b1 = f + m * ell * thd * thd * s
    b2 = m * g * ell * s
    det = a11 * a22 - a12 * a12  # = M m l^2 + m^2 l^2 sin^2(theta) > 0
    return (a22 * b1 - a12 * b2) / det, (a11 * b2 - a12 * b1) / det


def rk4Step(
    state: Any,
    force: float,
    dt: float,
    cartMass: float = 1.0,
    pendulumMass: float = 1.0,
    length: float = 1.0,
    g: float = GRAVITY,
) -> np.ndarray:
    """One classical Runge-Kutta 4 step of ``dt`` seconds, the force (N) held constant.

    Args and units as in :func:`stateDerivative`; returns the state after ``dt``.
    """
    x, th, xd, thd = (float(v) for v in state)
    f = float(force)
    p = (f, cartMass, pendulumMass, length, g)
    h = 0.5 * dt
    a1, b1 = _accelerations(th, thd, *p)
    a2, b2 = _accelerations(th + h * thd, thd + h * b1, *p)
    xd2, thd2 = xd + h * a1, thd + h * b1
    a3, b3 = _accelerations(th + h * thd2, thd + h * b2, *p)
    xd3, thd3 = xd + h * a2, thd + h * b2
    a4, b4 = _accelerations(th + dt * thd3, thd + dt * b3, *p)
    xd4, thd4 = xd + dt * a3, thd + dt * b3
    k = dt / 6.0
    return np.array(
        [
            x + k * (xd + 2.0 * xd2 + 2.0 * xd3 + xd4),
            th + k * (thd + 2.0 * thd2 + 2.0 * thd3 + thd4),
            xd + k * (a1 + 2.0 * a2 + 2.0 * a3 + a4),
            thd + k * (b1 + 2.0 * b2 + 2.0 * b3 + b4),
        ]
    )


def linearisedModel(
    cartMass: float = 1.0, pendulumMass: float = 1.0, length: float = 1.0, g: float = GRAVITY
) -> tuple[np.ndarray, np.ndarray]:
    """The cart-pole linearised at the upright equilibrium: ``s_dot = A s + B F``.

    With M the cart mass (kg), m the pendulum mass (kg), l the length (m)::

        x_ddot     = -m g / M         theta + 1 / M       F
        theta_ddot = (M + m) g / (M l) theta - 1 / (M l)   F

    Returns:
        ``A`` (4x4, s^-1 / s^-2) and ``B`` (4x1) for the state (x, theta, x_dot,
        theta_dot) and the force F in N.
    """
    M, m, ell = cartMass, pendulumMass, length
    A = np.zeros((4, 4))
    A[0, 2] = A[1, 3] = 1.0
    A[2, 1] = -m * g / M
    A[3, 1] = (M + m) * g / (M * ell)
    B = np.array([[0.0], [0.0], [1.0 / M], [-1.0 / (M * ell)]])
    return A, B


def lqrGain(
    cartMass: float = 1.0,
    pendulumMass: float = 1.0,
    length: float = 1.0,
    Q: Any = None,
    R: Any = None,
    g: float = GRAVITY,
) -> np.ndarray:
    """Infinite-horizon LQR gain ``K`` (force ``F = -K s``) of the linearised model.

    Minimises the integral of ``s' Q s + R F^2`` with the continuous algebraic Riccati
    equation (``scipy.linalg.solve_continuous_are``).

    Args:
        cartMass, pendulumMass, length, g: the model (kg, kg, m, m/s^2).
        Q: 4x4 state weight, or its diagonal (default :data:`DEFAULT_Q`).
        R: weight on the force (default :data:`DEFAULT_R`).

    Returns:
        ``K``, shape (4,), in (N/m, N/rad, N s/m, N s/rad).
    """
    from scipy.linalg import solve_continuous_are

    A, B = linearisedModel(cartMass, pendulumMass, length, g)
    Qm = np.asarray(DEFAULT_Q if Q is None else Q, dtype=float)
    if Qm.ndim == 1:
        Qm = np.diag(Qm)
    Rm = np.atleast_2d(np.asarray(DEFAULT_R if R is None else R, dtype=float))
    P = solve_continuous_are(A, B, Qm, Rm)
    return np.linalg.solve(Rm, B.T @ P).ravel()


def isConverged(state: Any, thetaTol: float = 1e-3, thetaDotTol: float = 1e-2) -> bool:
    """Whether the pendulum is upright and still: ``|theta| < thetaTol`` (rad) and
    ``|theta_dot| < thetaDotTol`` (rad/s)."""
    s = np.asarray(state, dtype=float)
    return bool(abs(s[1]) < thetaTol and abs(s[3]) < thetaDotTol)


# -- entities --------------------------------------------------------------------------
def _positive(entity: Entity, cmd: str, what: str, unit: str, v: float) -> float:
    if not (math.isfinite(v) and v > 0.0):
        raise CommandError(
            f"{entity.className}({entity.name}).{cmd}: {what} must be a finite value > 0 "
            f"{unit}, got {v!r}; it is left unchanged"
        )
    return v


class InvertedPendulum(Entity):
    """Classical inverted pendulum dynamic model

    A point mass m at the end of a massless rod of length l, hinged on a cart of mass M
    that slides without friction on a horizontal rail under a force F. The state is
    (x, theta, x_dot, theta_dot): cart position (m), angle of the rod from the upright
    vertical (rad, positive towards +x), and their rates. The equations of motion, from
    the Lagrangian, in mass-matrix form::

        (M + m) x'' + m l cos(th) th'' - m l th'^2 sin(th) = F
        m l cos(th) x'' + m l^2 th''  - m g l sin(th)      = 0

    are solved for (x'', th'') at each evaluation and integrated by ``incr(dt)`` with
    classical RK4 (steps of at most 1 ms), F held constant over ``dt``.

    Signals: ``force`` (input, N, default 0) and ``state`` (output written by ``incr``).
    """

    force = Input(DOUBLE, default=0.0, doc="horizontal force on the cart, in N")
    state = Output(
        VECTOR,
        initial=(0.0, 0.0, 0.0, 0.0),
        doc="(x [m], theta [rad], x_dot [m/s], theta_dot [rad/s])",
    )

    def __init__(self, name: str) -> None:
        self._cartMass = 1.0
        self._pendulumMass = 1.0
        self._length = 1.0
        self.gravity = GRAVITY

    # -- integration ------------------------------------------------------------------
    @command
    def incr(self, dt: float) -> None:
        """Integrate dynamics for time step provided as input

        dt: the time step in s (> 0). Reads ``force`` at the tick of ``state``, integrates
        over dt with the force held constant (RK4, substeps of at most 1 ms), and writes
        the new ``state`` one tick later.
        """
        if not (math.isfinite(dt) and dt > 0.0):
            raise CommandError(
                f"{self.className}({self.name}).incr: time step must be a finite value > 0 "
                f"s, got {dt!r}"
            )
        t = max(self.state.time, 0)
        s = self.state(t)
        if np.shape(s) != (4,):
            raise SignalTypeError(
                f"{self.state.name}: expected 4 values (x, theta, x_dot, theta_dot), "
                f"got shape {np.shape(s)}"
            )
        f = self.force(t)
        n = max(1, math.ceil(dt / MAX_STEP - 1e-9))
        h = dt / n
        p = (self._cartMass, self._pendulumMass, self._length, self.gravity)
        try:
            for _ in range(n):
                s = rk4Step(s, f, h, *p)
            finite = bool(np.isfinite(s).all())
        except (ValueError, OverflowError, ZeroDivisionError):
            finite = False
        if not finite:
            raise SotpyError(
                f"{self.className}({self.name}).incr: the state is no longer finite after "
                f"tick {t} (force {f!r} N): the simulation diverged; reduce dt or the "
                "controller gains. The state is left unchanged"
            )
        self.state.write(s, t + 1)

    # -- parameters -------------------------------------------------------------------
    @command
    def setCartMass(self, mass: float) -> None:
        """Set cart mass, in kg (> 0)."""
        self._cartMass = _positive(self, "setCartMass", "cart mass", "kg", mass)

    @command
    def getCartMass(self) -> float:
        """Get cart mass, in kg."""
        return self._cartMass

    @command
    def setPendulumMass(self, mass: float) -> None:
        """Set pendulum mass, in kg (> 0)."""
        self._pendulumMass = _positive(self, "setPendulumMass", "pendulum mass", "kg", mass)

    @command
    def getPendulumMass(self) -> float:
        """Get pendulum mass, in kg."""
        return self._pendulumMass

    @command
    def setPendulumLength(self, length: float) -> None:
        """Set pendulum length, in m (> 0)."""
        self._length = _positive(self, "setPendulumLength", "pendulum length", "m", length)

    @command
    def getPendulumLength(self) -> float:
        """Get pendulum length, in m."""
        return self._length


class FeedbackController(Entity):
    """Linear state feedback: force = -K . state

    ``K`` holds 4 gains for (x, theta, x_dot, theta_dot), in (N/m, N/rad, N s/m,
    N s/rad). The default is :func:`lqrGain` of the default :class:`InvertedPendulum`
    (M = m = 1 kg, l = 1 m), with Q = diag(10, 10, 1, 1) and R = 0.1.
    """

    state = Input(VECTOR, doc="(x [m], theta [rad], x_dot [m/s], theta_dot [rad/s])")

    def __init__(self, name: str) -> None:
        self._gain = lqrGain()

    @Output(DOUBLE, deps=("state",), doc="force on the cart, in N: -K . state")
    def force(self, state: np.ndarray) -> float:
        """Force on the cart, in N: -K . state."""
        return -float(np.dot(self._gain, state))

    @command
    def setGain(self, K: np.ndarray) -> None:
        """Set the gain K: 4 values for (x, theta, x_dot, theta_dot)

        Units: N/m, N/rad, N s/m, N s/rad. A 1x4 matrix is accepted too.
        """
        if K.shape not in ((4,), (1, 4)) or not np.isfinite(K).all():
            raise CommandError(
                f"{self.className}({self.name}).setGain: expected 4 finite values for "
                f"(x, theta, x_dot, theta_dot), got {K.tolist()!r}; the gain is left unchanged"
            )
        self._gain = K.reshape(4).copy()
        self.force.setReady()

    @command
    def getGain(self) -> np.ndarray:
        """Get the gain K (a copy), in (N/m, N/rad, N s/m, N s/rad)."""
        return self._gain.copy()


# -- the story -------------------------------------------------------------------------
def run_pendulum(
    duration: float = 10.0,
    dt: float = 1e-3,
    theta0: float = 0.1,
    plot: str | Path | None = None,
    quiet: bool = False,
    pendulum: str = "IP",
    controller: str = "K",
    tracer: str = "IP_tracer",
) -> dict[str, Any]:
    """Run SoT's inverted-pendulum tutorial: balance the pendulum from ``theta0``.

    Creates (or, by SoT's rule, reuses when they exist with the same class) the entities
    ``pendulum`` (:class:`InvertedPendulum`), ``controller`` (:class:`FeedbackController`)
    and ``tracer`` (:class:`~sotpy.graph.Tracer`), plugs them, sets the state to
    (0, theta0, 0, 0), and calls ``incr(dt)`` for ``duration`` seconds, tracing the state
    and the force at every tick. Reused entities keep their parameters (masses, gain);
    their state and the tracer's rows are reset. The pool is not cleared.

    Args:
        duration: simulated time, in s.
        dt: time step, in s.
        theta0: initial angle from the upright vertical, in rad.
        plot: if given, save a plot of x, theta and force vs time there (needs
            matplotlib).
        quiet: do not print the table and the final state.
        pendulum, controller, tracer: entity names.

    Returns:
        The tracer data (``time`` in s from the start of the run, ``tick``, ``state``
        (n, 4), ``force`` (n, 1)), plus ``final_state`` (4,), ``converged``
        (:func:`isConverged` of the final state), ``error`` (None, or why the run
        stopped early: the closed loop diverged), ``table`` (the printed text), ``dt``,
        ``plot`` (the path written, or None) and ``wall_time`` (s).
    """
    if not (math.isfinite(duration) and duration > 0):
        raise ValueError(f"run_pendulum: duration must be > 0 s, got {duration!r}")
    if not (math.isfinite(dt) and dt > 0):
        raise ValueError(f"run_pendulum: dt must be > 0 s, got {dt!r}")
    steps = round(duration / dt)
    a = InvertedPendulum(pendulum)
    b = FeedbackController(controller)
    tr = Tracer(tracer)
    plug(a.state, b.state)
    plug(b.force, a.force)
    a.state.value = (0.0, float(theta0), 0.0, 0.0)

    tr.stop()
    tr.clear()
    for label in tr.columns():
        tr.remove(label)
    tr.setBufferSize(steps + 1)
    tr.add(a.state, "state")
    tr.add(b.force, "force")
    tr.setTimeStep(dt)
    tr.start()

    start = _time.perf_counter()
    tick0 = a.state.time
    tr.trigger.recompute(tick0)  # the initial row
    error = None
    try:
        for _ in range(steps):
            a.incr(dt)
            tr.trigger.recompute(a.state.time)
    except SotpyError as exc:  # incr refused: the closed loop diverged; keep the rows
        error = str(exc)
    wall = _time.perf_counter() - start
    tr.stop()

    data = tr.data()
    data["time"] = (data["tick"] - tick0) * dt
    final = data["state"][-1].copy()
    table = _table(data, dt)
    if error is not None:
        table += f"\nstopped at t = {data['time'][-1]:.3f} s: {error}"
    data.update(
        final_state=final,
        converged=error is None and isConverged(final),
        error=error,
        table=table,
        dt=dt,
        wall_time=wall,
        plot=None,
    )
    if plot is not None:
        data["plot"] = _plot(data, Path(plot))
    if not quiet:
        print(table)
        if data["plot"] is not None:
            print(f"plot saved to {data['plot']}")
    return data


def _table(data: dict[str, Any], dt: float) -> str:
    """Every second: t, x, theta, force; then the final state."""
    n = len(data["time"])
    every = max(1, round(1.0 / dt))
    rows = list(range(0, n, every))
    if rows[-1] != n - 1:
        rows.append(n - 1)
    lines = [f"{'t [s]':>7} {'x [m]':>11} {'theta [rad]':>12} {'force [N]':>11}"]
    for i in rows:
        x, th = data["state"][i, 0], data["state"][i, 1]
        f = data["force"][i, 0]
        lines.append(f"{data['time'][i]:7.3f} {_num(x, 11)} {_num(th, 12)} {_num(f, 11)}")
    s = data["state"][-1]
    lines.append(
        f"final state: x = {s[0]:.3e} m, theta = {s[1]:.3e} rad, "
        f"x_dot = {s[2]:.3e} m/s, theta_dot = {s[3]:.3e} rad/s"
    )
    return "\n".join(lines)


def _num(v: float, width: int) -> str:
    """``v`` with 6 decimals (no ``-0.000000``), or in scientific notation when that
    would not fit."""
    if abs(v) < 5e-7:
        v = 0.0
    return f"{v:{width}.6f}" if abs(v) < 1e4 else f"{v:{width}.4e}"


def _plot(data: dict[str, Any], path: Path) -> str:
    """Save x, theta and force vs time to ``path`` with matplotlib's Agg canvas (no
    pyplot, so the user's backend is left alone)."""
    try:
        from matplotlib.backends.backend_agg import FigureCanvasAgg
        from matplotlib.figure import Figure
    except ImportError:
        raise SotpyError(
            f"cannot save the plot {str(path)!r}: matplotlib is not installed "
            "(pip install 'sotpy[plot]')"
        ) from None

    fig = Figure(figsize=(7.0, 6.0), layout="constrained")
    FigureCanvasAgg(fig)
    axes = fig.subplots(3, 1, sharex=True)
    t = data["time"]
    series = (
        (data["state"][:, 0], "x [m]"),
        (data["state"][:, 1], "theta [rad]"),
        (data["force"][:, 0], "force [N]"),
    )
    for ax, (y, label) in zip(axes, series, strict=True):
        ax.plot(t, y)
        ax.set_ylabel(label)
        ax.grid(True)
    axes[0].set_title("Inverted pendulum balanced by LQR state feedback")
    axes[-1].set_xlabel("time [s]")
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=100)
    return str(path)
