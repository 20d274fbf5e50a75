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
    b.setGain((0.0, 27.0, 0.001, 0.001))   # the tutorial's own gain, or keep the default
    for _ in range(1000):
        a.incr(0.001)

The loop is closed through the state signal: ``incr`` reads ``force`` at the tick of the
state, integrates, and writes the new state one tick later, as SoT's
``Device.increment`` does.

The model is the C++ tutorial's, to the sign of ``theta`` and the integration step, so
that a gain written for the SoT balances sotpy's pendulum in the same way. The physics
(state derivative, integration step, linearisation, LQR gain) are plain functions over
numpy arrays, usable without a graph; :func:`pendulumTable`, :func:`plotPendulum`,
:func:`isConverged` and :func:`hasFallen` are the helpers ``examples/inverted_pendulum.py``
calls, and :func:`run_pendulum` is the whole story for ``sotpy demo pendulum``.

Units: metres, radians, seconds, kilograms, newtons. ``theta`` is the angle of the rod
from the upright vertical, positive when the mass leans towards -x (the C++ model's
sign: pushing the cart towards +x makes ``theta`` grow).
"""

import math
import time as _time
from pathlib import Path
from typing import Any

import numpy as np

from .errors import CommandError, SignalTypeError, SimulationError, SotpyError
from .graph import DOUBLE, VECTOR, Entity, Input, Output, Tracer, command, plug

__all__ = [
    "DEFAULT_Q",
    "DEFAULT_R",
    "DEFAULT_VISCOSITY",
    "GRAVITY",
    "SOT_TUTORIAL_GAIN",
    "STEP_FRACTION",
    "FeedbackController",
    "InvertedPendulum",
    "hasFallen",
    "integrationStep",
    "isConverged",
    "linearisedModel",
    "longestStep",
    "lqrGain",
    "pendulumTable",
    "plotPendulum",
    "run_pendulum",
    "stateDerivative",
]

GRAVITY = 9.81
"""Gravity acceleration, in m/s^2 (the C++ tutorial's constant)."""

DEFAULT_VISCOSITY = 0.1
"""Default viscosity lambda of the model (the C++ tutorial's): a friction force
``-lambda x_dot`` (N) on the cart and a friction torque ``-lambda theta_dot`` (N m) at the
hinge, which make the pendulum hanging down intrinsically stable."""

SOT_TUTORIAL_GAIN = (0.0, 27.0, 0.001, 0.001)
"""The gain of the SoT tutorial's ``simu.py``, for (x, theta, x_dot, theta_dot): it
feeds back the angle only, and balances the pendulum from theta = 0.1 rad within a few
seconds; it leaves the cart's drift unstable (see ``docs/tutorial-pendulum.md``)."""

DEFAULT_Q = (10.0, 10.0, 1.0, 1.0)
"""Diagonal of the default LQR state weight, for (x [m], theta [rad], x_dot [m/s],
theta_dot [rad/s]). Weighting the cart position as much as the angle brings the cart
back to the origin in a few seconds (slowest closed-loop pole about -1.7 rad/s)."""

DEFAULT_R = 0.1
"""Default LQR weight on the force, in 1/N^2 relative to the state weights."""

STEP_FRACTION = 0.1
"""``incr(dt)`` refuses a step longer than this fraction of the fastest time constant of
the model linearised upright (:func:`longestStep`): one explicit step of the C++ scheme
is then a faithful simulation (an error of about 0.5 % per step on the fastest mode)."""


# -- physics ---------------------------------------------------------------------------
def _accelerations(
    th: float, thd: float, xd: float, f: float, M: float, m: float, ell: float, lam: float, g: float
) -> tuple[float, float]:
    """Solve the 2x2 mass-matrix system for (x_ddot [m/s^2], theta_ddot [rad/s^2])."""
    c = math.cos(th)
    s = math.sin(th)
    # [[M + m, -m l c], [-m l c, m l^2]] (x_ddot, theta_ddot) = (b1, b2)
    b1 = f - m * ell * thd * thd * s - lam * xd
    b2 = m * g * ell * s - lam * thd
    det = m * ell * ell * (M + m * s * s)  # the mass matrix's determinant, > 0
    return (m * ell * ell * b1 + m * ell * c * b2) / det, ((M + m) * b2 + m * ell * c * b1) / det


def stateDerivative(
    state: Any,
    force: float,
    cartMass: float = 1.0,
    pendulumMass: float = 1.0,
    length: float = 1.0,
    viscosity: float = DEFAULT_VISCOSITY,
    g: float = GRAVITY,
) -> np.ndarray:
    """Time derivative of the cart-pole state (see :class:`InvertedPendulum`).

    Args:
        state: (x [m], theta [rad], x_dot [m/s], theta_dot [rad/s]).
        force: horizontal force on the cart, in N.
        cartMass: M, in kg.
        pendulumMass: m, in kg.
        length: l, in m.
        viscosity: lambda, in N s/m on the cart and N m s/rad at the hinge.
        g: gravity acceleration, in m/s^2.

    Returns:
        (x_dot [m/s], theta_dot [rad/s], x_ddot [m/s^2], theta_ddot [rad/s^2]).
    """
    _, th, xd, thd = (float(v) for v in state)
    xdd, thdd = _accelerations(
        th, thd, xd, float(force), cartMass, pendulumMass, length, viscosity, g
    )
    return np.array([xd, thd, xdd, thdd])


def integrationStep(
    state: Any,
    force: float,
    dt: float,
    cartMass: float = 1.0,
    pendulumMass: float = 1.0,
    length: float = 1.0,
    viscosity: float = DEFAULT_VISCOSITY,
    g: float = GRAVITY,
) -> np.ndarray:
    """One step of ``dt`` seconds of the C++ model's scheme, the force (N) held constant.

    With the accelerations ``(x'', th'')`` of the state at the start of the step::

        x+  = x  + x'  dt + x''  dt^2 / 2        x'+  = x'  + x''  dt
        th+ = th + th' dt + th'' dt^2 / 2        th'+ = th' + th'' dt

    (explicit Euler on the velocities, second-order Taylor on the positions: first-order
    accurate). Args and units as in :func:`stateDerivative`; returns the state after
    ``dt``.
    """
    x, th, xd, thd = (float(v) for v in state)
    xdd, thdd = _accelerations(
        th, thd, xd, float(force), cartMass, pendulumMass, length, viscosity, g
    )
    h = 0.5 * dt * dt
    return np.array(
        [x + xd * dt + xdd * h, th + thd * dt + thdd * h, xd + xdd * dt, thd + thdd * dt]
    )


def linearisedModel(
    cartMass: float = 1.0,
    pendulumMass: float = 1.0,
    length: float = 1.0,
    viscosity: float = DEFAULT_VISCOSITY,
    g: float = GRAVITY,
) -> tuple[np.ndarray, np.ndarray]:
    """The cart-pole linearised at the upright equilibrium: ``s_dot = A s + B F``.

    With M the cart mass (kg), m the pendulum mass (kg), l the length (m), lambda the
    viscosity::

        x_ddot     = m g / M theta - lambda / M x_dot - lambda / (M l) theta_dot + F / M
        theta_ddot = (M + m) g / (M l) theta - lambda / (M l) x_dot
                     - (M + m) lambda / (M m l^2) theta_dot + F / (M l)

    Returns:
        ``A`` (4x4, s^-1 / s^-2) and ``B`` (4x1) for the state (x, theta, x_dot,
        theta_dot) and the force F in N.
    """
    M, m, ell, lam = cartMass, pendulumMass, length, viscosity
    A = np.zeros((4, 4))
    A[0, 2] = A[1, 3] = 1.0
    A[2, 1] = m * g / M
    A[2, 2] = -lam / M
    A[2, 3] = -lam / (M * ell)
    A[3, 1] = (M + m) * g / (M * ell)
    A[3, 2] = -lam / (M * ell)
    A[3, 3] = -(M + m) * lam / (M * m * ell * ell)
    B = np.array([[0.0], [0.0], [1.0 / M], [1.0 / (M * ell)]])
    return A, B


def longestStep(
    cartMass: float = 1.0,
    pendulumMass: float = 1.0,
    length: float = 1.0,
    viscosity: float = DEFAULT_VISCOSITY,
    g: float = GRAVITY,
) -> float:
    """The longest time step ``incr`` accepts, in s: :data:`STEP_FRACTION` of the
    fastest time constant of the linearised model, ``STEP_FRACTION / max |eig(A)|``
    (0.0219 s for the default pendulum, whose fastest modes are its fall at
    +4.31 rad/s and its swing back at -4.56 rad/s)."""
    A, _ = linearisedModel(cartMass, pendulumMass, length, viscosity, g)
    return STEP_FRACTION / float(np.abs(np.linalg.eigvals(A)).max())


def lqrGain(
    cartMass: float = 1.0,
    pendulumMass: float = 1.0,
    length: float = 1.0,
    Q: Any = None,
    R: Any = None,
    viscosity: float = DEFAULT_VISCOSITY,
    g: float = GRAVITY,
) -> np.ndarray:
    """Infinite-horizon LQR gain ``K`` (force ``F = -K s``) of the linearised model.

    Minimises the integral of ``s' Q s + R F^2`` with the continuous algebraic Riccati
    equation (``scipy.linalg.solve_continuous_are``).

    Args:
        cartMass, pendulumMass, length, viscosity, g: the model (kg, kg, m, N s/m,
            m/s^2).
        Q: 4x4 state weight, or its diagonal (default :data:`DEFAULT_Q`).
        R: weight on the force (default :data:`DEFAULT_R`).

    Returns:
        ``K``, shape (4,), in (N/m, N/rad, N s/m, N s/rad).
    """
    from scipy.linalg import solve_continuous_are

    A, B = linearisedModel(cartMass, pendulumMass, length, viscosity, g)
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


def hasFallen(state: Any) -> bool:
    """Whether the pendulum has fallen: ``|theta| > pi/2`` (below the horizontal)."""
    return bool(abs(float(np.asarray(state, dtype=float)[1])) > 0.5 * math.pi)


# -- entities --------------------------------------------------------------------------
def _parameter(entity: Entity, cmd: str, what: str, unit: str, v: float, zero: bool) -> float:
    ok = math.isfinite(v) and (v >= 0.0 if zero else v > 0.0)
    if not ok:
        bound = ">= 0" if zero else "> 0"
        raise CommandError(
            f"{entity.className}({entity.name}).{cmd}: {what} must be a finite value "
            f"{bound} {unit}, got {v!r}; it is left unchanged"
        )
    return v


class InvertedPendulum(Entity):
    """Classical inverted pendulum dynamic model

    A point mass m at the end of a massless rod of length l, hinged on a cart of mass M
    that slides on a horizontal rail under a force F, with a viscous friction lambda on
    the cart and at the hinge (the C++ tutorial's model). The state is (x, theta, x_dot,
    theta_dot): cart position (m), angle of the rod from the upright vertical (rad,
    positive when the mass leans towards -x), and their rates. The equations of motion,
    from the Lagrangian of the mass at (x - l sin(th), l cos(th)), in mass-matrix form::

        (M + m) x'' - m l cos(th) th'' + m l th'^2 sin(th) = F - lambda x'
        -m l cos(th) x'' + m l^2 th''  - m g l sin(th)     =   - lambda th'

    are solved for (x'', th'') at the state of each step, and ``incr(dt)`` takes one
    step of the C++ model's scheme (:func:`integrationStep`: x += x' dt + x'' dt^2 / 2,
    x' += x'' dt), F held constant over dt.

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
        self._viscosity = DEFAULT_VISCOSITY
        self.gravity = GRAVITY
        self._maxStep: float | None = None  # longestStep() of the parameters, cached

    def _params(self) -> tuple[float, float, float, float, float]:
        return (self._cartMass, self._pendulumMass, self._length, self._viscosity, self.gravity)

    def _changed(self) -> None:
        self._maxStep = None

    # -- integration ------------------------------------------------------------------
    @command
    def incr(self, dt: float) -> None:
        """Integrate dynamics for time step provided as input

        dt: the time step in s, > 0 and at most ``getMaxTimeStep()``. Reads ``force`` at
        the tick of ``state``, takes one step of the C++ model's scheme over dt with the
        force held constant, and writes the new ``state`` one tick later.
        """
        if not (math.isfinite(dt) and dt > 0.0):
            raise CommandError(
                f"{self.className}({self.name}).incr: time step must be a finite value > 0 "
                f"s, got {dt!r}"
            )
        longest = self.getMaxTimeStep()
        if dt > longest:
            raise CommandError(
                f"{self.className}({self.name}).incr: time step {dt!r} s is longer than "
                f"{longest:.4g} s, the longest this model integrates faithfully in one step "
                f"({STEP_FRACTION:g} of its fastest time constant, linearised upright); "
                f"call incr repeatedly with a step of at most {longest:.4g} s. The state "
                "is left unchanged"
            )
        t = max(self.state.time, 0)
        s = self.state(t)
        if np.shape(s) != (4,):
            raise SignalTypeError(
                f"{self.state.name}: expected 4 values (x, theta, x_dot, theta_dot), "
                f"got shape {np.shape(s)}"
            )
        f = self.force(t)
        try:
            s = integrationStep(s, f, dt, *self._params())
            finite = bool(np.isfinite(s).all())
        except (ValueError, OverflowError, ZeroDivisionError):
            finite = False
        if not finite:
            raise SimulationError(
                f"{self.className}({self.name}).incr: the state is no longer finite after "
                f"tick {t} (force {f!r} N): the closed loop diverged (check the controller's "
                "gain and its sign convention: theta > 0 leans towards -x). The state is "
                "left unchanged"
            )
        self.state.write(s, t + 1)

    @command
    def getMaxTimeStep(self) -> float:
        """The longest step ``incr`` accepts, in s (see :func:`longestStep`)."""
        if self._maxStep is None:
            self._maxStep = longestStep(*self._params())
        return self._maxStep

    # -- parameters -------------------------------------------------------------------
    @command
    def setCartMass(self, mass: float) -> None:
        """Set cart mass, in kg (> 0)."""
        self._cartMass = _parameter(self, "setCartMass", "cart mass", "kg", mass, False)
        self._changed()

    @command
    def getCartMass(self) -> float:
        """Get cart mass, in kg."""
        return self._cartMass

    @command
    def setPendulumMass(self, mass: float) -> None:
        """Set pendulum mass, in kg (> 0)."""
        self._pendulumMass = _parameter(self, "setPendulumMass", "pendulum mass", "kg", mass, False)
        self._changed()

    @command
    def getPendulumMass(self) -> float:
        """Get pendulum mass, in kg."""
        return self._pendulumMass

    @command
    def setPendulumLength(self, length: float) -> None:
        """Set pendulum length, in m (> 0)."""
        self._length = _parameter(self, "setPendulumLength", "pendulum length", "m", length, False)
        self._changed()

    @command
    def getPendulumLength(self) -> float:
        """Get pendulum length, in m."""
        return self._length

    @command
    def setViscosity(self, viscosity: float) -> None:
        """Set viscosity lambda (>= 0; default 0.1): N s/m on the cart, N m s/rad at the hinge."""
        self._viscosity = _parameter(self, "setViscosity", "viscosity", "N s/m", viscosity, True)
        self._changed()

    @command
    def getViscosity(self) -> float:
        """Get viscosity lambda (N s/m on the cart, N m s/rad at the hinge)."""
        return self._viscosity


class FeedbackController(Entity):
    """Linear state feedback: force = -K . state

    ``K`` holds 4 gains for (x, theta, x_dot, theta_dot), in (N/m, N/rad, N s/m,
    N s/rad). The default is :func:`lqrGain` of the default :class:`InvertedPendulum`
    (M = m = 1 kg, l = 1 m, viscosity 0.1), with Q = diag(10, 10, 1, 1) and R = 0.1;
    the SoT tutorial sets :data:`SOT_TUTORIAL_GAIN` = (0, 27, 0.001, 0.001).
    """

    state = Input(VECTOR, doc="(x [m], theta [rad], x_dot [m/s], theta_dot [rad/s])")

    def __init__(self, name: str) -> None:
        self._gain = lqrGain()

    @Output(DOUBLE, deps=("state",), doc="force on the cart, in N: -K . state")
    def force(self, state: np.ndarray) -> float:
        """Force on the cart, in N: -K . state."""
        if state.shape != (4,):
            raise SignalTypeError(
                f"{self.state.name}: expected 4 values (x, theta, x_dot, theta_dot), "
                f"got shape {state.shape}"
            )
        return -float(np.dot(self._gain, state))

    @command
    def setGain(self, K: np.ndarray) -> None:
        """Set the gain K: 4 values for (x, theta, x_dot, theta_dot)

        Units: N/m, N/rad, N s/m, N s/rad. A 1x4 or 4x1 matrix is accepted too (the C++
        controller stores a matrix).
        """
        if K.shape not in ((4,), (1, 4), (4, 1)) or not np.isfinite(K).all():
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


# -- helpers of the example ------------------------------------------------------------
def pendulumTable(data: dict[str, Any], every: float = 1.0) -> str:
    """The traced run as text: t, x, theta and force every ``every`` seconds (and the
    last row), then the final state.

    Args:
        data: a :class:`~sotpy.graph.Tracer`'s ``data()`` with columns ``state`` and
            ``force`` and ``time`` in seconds (``setTimeStep``).
        every: the period of the printed rows, in s.
    """
    t = np.asarray(data["time"], dtype=float)
    n = len(t)
    dt = float(t[1] - t[0]) if n > 1 else 1.0
    step = max(1, round(every / dt))
    rows = list(range(0, n, step))
    if rows[-1] != n - 1:
        rows.append(n - 1)
    lines = [f"{'t [s]':>7} {'x [m]':>11} {'theta [rad]':>12} {'force [N]':>11}"]
    for i in rows:
        x, th = data["state"][i, 0], data["state"][i, 1]
        f = data["force"][i, 0]
        lines.append(f"{t[i] - t[0]:7.3f} {_num(x, 11)} {_num(th, 12)} {_num(f, 11)}")
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


def plotPendulum(
    data: dict[str, Any],
    path: str | Path,
    title: str = "Inverted pendulum balanced by state feedback",
) -> str:
    """Save x, theta and force against time to ``path`` (PNG) with matplotlib's Agg
    canvas (no pyplot, so the user's backend is left alone); returns the path.

    ``data`` as for :func:`pendulumTable`. Needs matplotlib (``pip install
    'sotpy[plot]'``).
    """
    path = Path(path)
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
    t = np.asarray(data["time"], dtype=float)
    t = t - t[0]
    series = (
        (data["state"][:, 0], "x [m]"),
        (data["state"][:, 1], "theta [rad]"),
        (data["force"][:, 0], "force [N]"),
    )
    for ax, (y, label) in zip(axes, series, strict=True):
        ax.plot(t, y)
        ax.set_ylabel(label)
        ax.grid(True)
    axes[0].set_title(title)
    axes[-1].set_xlabel("time [s]")
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=100)
    return str(path)


# -- the story -------------------------------------------------------------------------
#: From rest at x = 0, the default LQR gain brings the default pendulum back upright from
#: |theta0| up to this angle (rad), measured by bisection over 10 s runs at dt = 1 ms.
DEFAULT_GAIN_RECOVERS = 0.86


def _fallCause(a: InvertedPendulum, b: FeedbackController, theta0: float, t: float) -> str:
    """Why the pendulum fell, with the numbers: what holding it at ``theta0`` takes and
    what the linear feedback asked for."""
    M, m, ell, lam, g = a._params()
    K = b.getGain()
    f0 = -float(K @ np.array([0.0, theta0, 0.0, 0.0]))
    # theta held constant (theta' = theta'' = 0, cart at rest): x'' = -g tan(theta0) and
    # F = (M + m) x''
    hold = (M + m) * g * math.tan(theta0) if abs(theta0) < 0.5 * math.pi else math.inf
    head = f"the pendulum fell: |theta| passed pi/2 rad at t = {t:.3f} s"
    if abs(f0) < abs(hold):
        cause = (
            f"from theta0 = {theta0:g} rad the rod is far from upright: a push on the cart "
            f"turns it only as cos(theta0) = {math.cos(theta0):.3f} while gravity pulls it "
            f"down as sin(theta0) = {math.sin(theta0):.3f}, so holding it there takes a "
            f"force of (M + m) g tan(theta0) = {abs(hold):.0f} N on the cart, and the linear "
            f"state feedback K = {np.round(K, 4).tolist()} (designed for the pendulum near "
            f"upright) asks for {abs(f0):.0f} N"
        )
    else:
        cause = (
            f"theta0 = {theta0:g} rad is outside the region from which the linear state "
            f"feedback K = {np.round(K, 4).tolist()}, designed for the pendulum near "
            "upright, brings it back"
        )
    hint = ""
    if (M, m, ell, lam, g) == (1.0, 1.0, 1.0, DEFAULT_VISCOSITY, GRAVITY) and np.allclose(
        K, lqrGain()
    ):
        hint = f" (the default gain recovers from |theta0| up to {DEFAULT_GAIN_RECOVERS} rad)"
    return f"{head}: {cause}. Start closer to upright{hint}"


def run_pendulum(
    duration: float = 10.0,
    dt: float = 1e-3,
    theta0: float = 0.1,
    plot: str | Path | None = None,
    quiet: bool = False,
    gain: Any = None,
    pendulum: str = "IP",
    controller: str = "K",
    tracer: str = "IP_tracer",
) -> dict[str, Any]:
    """Run SoT's inverted-pendulum tutorial: balance the pendulum from ``theta0``.

    Creates (or, by SoT's rule, reuses when they exist with the same class) the entities
    ``pendulum`` (:class:`InvertedPendulum`), ``controller`` (:class:`FeedbackController`)
    and ``tracer`` (:class:`~sotpy.graph.Tracer`), plugs them, sets the state to
    (0, theta0, 0, 0), and calls ``incr(dt)`` for ``duration`` seconds, tracing the state
    and the force at every tick. The run stops early when the pendulum falls
    (:func:`hasFallen`) or the closed loop diverges. Reused entities keep their
    parameters (masses, viscosity, gain unless ``gain`` is given); their state and the
    tracer's rows are reset. The pool is not cleared.

    Args:
        duration: simulated time, in s.
        dt: time step, in s (at most ``getMaxTimeStep()`` of the pendulum).
        theta0: initial angle from the upright vertical, in rad.
        plot: if given, save a plot of x, theta and force vs time there (needs
            matplotlib).
        quiet: do not print the table.
        gain: the controller's gain K (4 values), e.g. :data:`SOT_TUTORIAL_GAIN`; None
            keeps the controller's (the LQR gain for a new one).
        pendulum, controller, tracer: entity names.

    Returns:
        The tracer data (``time`` in s from the start of the run, ``tick``, ``state``
        (n, 4), ``force`` (n, 1)), plus ``final_state`` (4,), ``converged``
        (:func:`isConverged` of the final state), ``fell`` (whether it fell), ``error``
        (None, or why the run stopped early: the pendulum fell, or the loop diverged),
        ``table`` (the printed text), ``dt``, ``plot`` (the path written, or None) and
        ``wall_time`` (s).

    Raises:
        ValueError: a duration or time step that is not > 0.
        CommandError: a time step the pendulum refuses (longer than its
            ``getMaxTimeStep()``), or a bad gain.
    """
    if not (math.isfinite(duration) and duration > 0):
        raise ValueError(f"run_pendulum: duration must be > 0 s, got {duration!r}")
    if not (math.isfinite(dt) and dt > 0):
        raise ValueError(f"run_pendulum: dt must be > 0 s, got {dt!r}")
    steps = round(duration / dt)
    a = InvertedPendulum(pendulum)
    b = FeedbackController(controller)
    if dt > a.getMaxTimeStep():
        a.incr(dt)  # raises the pendulum's own error, before anything is changed
    if gain is not None:
        b.setGain(gain)
    tr = Tracer(tracer)
    plug(a.state, b.state)
    plug(b.force, a.force)
    a.state.value = (0.0, float(theta0), 0.0, 0.0)

    tr.stop()
    tr.clear()
    tr.setBufferSize(steps + 1)
    tr.add(a.state, "state")
    tr.add(b.force, "force")
    tr.setTimeStep(dt)
    tr.start()

    start = _time.perf_counter()
    tick0 = a.state.time
    tr.trigger.recompute(tick0)  # the initial row
    error = None
    fell = False
    try:
        for _ in range(steps):
            a.incr(dt)
            tr.trigger.recompute(a.state.time)
            if hasFallen(a.state.value):
                fell = True
                error = _fallCause(a, b, float(theta0), (a.state.time - tick0) * dt)
                break
    except SimulationError as exc:  # incr refused: the closed loop diverged; keep the rows
        error = str(exc)
    wall = _time.perf_counter() - start
    tr.stop()

    data = tr.data()
    data["time"] = (data["tick"] - tick0) * dt
    final = data["state"][-1].copy()
    table = pendulumTable(data)
    if error is not None:
        table += f"\nstopped at t = {data['time'][-1]:.3f} s: {error}"
    data.update(
        final_state=final,
        converged=error is None and isConverged(final),
        fell=fell,
        error=error,
        table=table,
        dt=dt,
        wall_time=wall,
        plot=None,
    )
    if plot is not None:
        data["plot"] = plotPendulum(data, plot)
    if not quiet:
        print(table)
        if data["plot"] is not None:
            print(f"plot saved to {data['plot']}")
    return data
