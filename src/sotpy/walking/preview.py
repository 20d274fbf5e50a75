r"""Kajita's preview control of the cart-table model (Kajita et al., ICRA 2003,
"Biped walking pattern generation by using preview control of zero-moment point").

The model, per horizontal axis (x and y are independent and share the gains)::

    X = (c, dc/dt, d2c/dt2)      the CoM's position (m), velocity (m/s), acceleration (m/s^2)
    X(k+1) = A X(k) + B u(k)     u the CoM's jerk (m/s^3), constant over one period T (s)
    p(k) = C X(k)                the cart-table ZMP (m)

    A = [[1, T, T^2/2], [0, 1, T], [0, 0, 1]],  B = (T^3/6, T^2/2, T),  C = (1, 0, -z_c/g)

with ``z_c`` the CoM height (m) and ``g`` gravity (m/s^2).

**Design** (the integral form of Katayama et al. 1985, as jrl-walkgen's
``PreviewControl`` without initial position). The augmented system
``Xt = (e, dX)`` (``e = p - p_ref`` the ZMP error, ``dX`` the state's increment) has::

    At = [[1, C A], [0, A]],   Bt = (C B, B),   Qt = diag(Q, 0, 0, 0)

``P`` solves the discrete algebraic Riccati equation of ``(At, Bt, Qt, R)``
(:func:`scipy.linalg.solve_discrete_are`); with ``W = (R + Bt^T P Bt)^-1``::

    K = W Bt^T P At = (Ks, Kx)           Ks scalar (the integral gain), Kx a 1 x 3 row
    Ac = At - Bt K
    F_j = W Bt^T (Ac^T)^(j-1) (-Ac^T P I1) ... written as X_1 = -Ac^T P I1,
          X_(j+1) = Ac^T X_j,  F_j = -W Bt^T X_j       (I1 = (1, 0, 0, 0))

and the control law is::

    u(k) = -Ks sum_(i <= k) (p(i) - p_ref(i)) - Kx X(k) + sum_(j = 1..N) F_j p_ref(k + j)

``N = round(preview time / T)`` (1.6 s: the gains have decayed below 1 % of ``F_1`` by
then). Q = 1 and R = 1e-6 are jrl-walkgen's weights. The sign convention is
that ``F_j > 0`` for small ``j``: a ZMP reference ahead pulls the jerk towards it
(jrl-walkgen stores ``-F_j``). Checked against jrl-walkgen's own reference values
(``tests/test_walking_preview.py``: T = 5 ms, z_c = 0.814 m, g = 9.8: Ks = 618.556,
F_1 = 777.45).

**Between two samples** the jerk is constant, so the state at ``tau`` in ``[0, T)`` after
sample ``k`` is the exact cubic :func:`stateAt`: a controller ticking faster than the
generator (1 ms under a 5 ms generator) reads a C2 CoM, not a linear interpolation whose
acceleration would be a train of impulses.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import scipy.linalg

from ..errors import CommandError

__all__ = ["GRAVITY", "PreviewController", "PreviewGains", "cartTable", "previewGains", "stateAt"]

#: Gravity (m/s^2) used by the walking modules unless told otherwise.
GRAVITY = 9.81


def cartTable(period: float, comHeight: float, gravity: float = GRAVITY):
    """The cart-table matrices ``(A, B, C)`` of period ``period`` (s) and CoM height
    ``comHeight`` (m): ``A`` 3 x 3, ``B`` and ``C`` of size 3 (see the module doc)."""
    T = float(period)
    A = np.array([[1.0, T, T * T / 2], [0.0, 1.0, T], [0.0, 0.0, 1.0]])
    B = np.array([T**3 / 6, T * T / 2, T])
    C = np.array([1.0, 0.0, -comHeight / gravity])
    return A, B, C


@dataclass(frozen=True)
class PreviewGains:
    """The gains of :func:`previewGains`: ``Ks`` (1/s^3 per m of integrated ZMP error,
    per sample), ``Kx`` (size 3, on ``(c, dc, ddc)``), ``F`` (size N, on the ZMP reference
    ``1..N`` samples ahead), for the period ``period`` (s) and CoM height ``comHeight``
    (m)."""

    Ks: float
    Kx: np.ndarray
    F: np.ndarray
    period: float
    comHeight: float
    gravity: float


def _positive(name: str, value: float) -> float:
    x = float(value)
    if not math.isfinite(x) or x <= 0:
        raise CommandError(f"previewGains: {name} must be a finite number > 0, got {value!r}")
    return x


def previewGains(
    period: float,
    comHeight: float,
    previewTime: float = 1.6,
    Q: float = 1.0,
    R: float = 1e-6,
    gravity: float = GRAVITY,
) -> PreviewGains:
    """The preview-control gains (module doc) for a sampling ``period`` (s), a CoM height
    ``comHeight`` (m) and a preview of ``previewTime`` (s), with the weights ``Q`` on the
    ZMP error and ``R`` on the jerk increment.

    Raises:
        CommandError: a non-positive or non-finite argument, or a preview shorter than
            one period.
    """
    T = _positive("period", period)
    zc = _positive("comHeight", comHeight)
    g = _positive("gravity", gravity)
    _positive("Q", Q)
    _positive("R", R)
    n = round(_positive("previewTime", previewTime) / T)
    if n < 1:
        raise CommandError(
            f"previewGains: the preview {previewTime} s is shorter than one period {T} s"
        )
    A, B, C = cartTable(T, zc, g)
    At = np.zeros((4, 4))
    At[0, 0] = 1.0
    At[0, 1:] = C @ A
    At[1:, 1:] = A
    Bt = np.concatenate(([C @ B], B)).reshape(4, 1)
    Qt = np.zeros((4, 4))
    Qt[0, 0] = Q
    P = scipy.linalg.solve_discrete_are(At, Bt, Qt, np.array([[R]]))
    W = 1.0 / (R + float((Bt.T @ P @ Bt)[0, 0]))
    K = W * (Bt.T @ P @ At).ravel()
    Ac = At - Bt @ K.reshape(1, 4)
    X = -Ac.T @ P[:, 0]
    F = np.empty(n)
    for j in range(n):
        F[j] = -W * float(Bt[:, 0] @ X)
        X = Ac.T @ X
    return PreviewGains(float(K[0]), K[1:].copy(), F, T, zc, g)


def stateAt(state: np.ndarray, jerk: np.ndarray, tau: float) -> np.ndarray:
    """The cart-table state ``tau`` seconds (``0 <= tau <= T``) after ``state`` (3 x 2:
    rows ``c, dc, ddc``, columns x, y) under the constant ``jerk`` (size 2, m/s^3)::

        c(tau) = c + dc tau + ddc tau^2 / 2 + u tau^3 / 6,   dc(tau) = ..., ddc(tau) = ddc + u tau
    """
    t2 = tau * tau
    out = np.empty_like(state)
    out[0] = state[0] + state[1] * tau + state[2] * (t2 / 2) + jerk * (t2 * tau / 6)
    out[1] = state[1] + state[2] * tau + jerk * (t2 / 2)
    out[2] = state[2] + jerk * tau
    return out


class PreviewController:
    """Kajita's preview controller on both horizontal axes at once.

    ``PreviewController(gains, state)`` starts from ``state`` (3 x 2: rows ``c, dc, ddc``,
    columns x, y; m, m/s, m/s^2) with a zero integrated error. The law of the module doc
    is the sum of the design's increments from a robot at rest at the origin (all zero),
    so it is applied to the deviations from the rest at ``origin`` (x, y; default the
    start's position): ``X - (origin, 0, 0)`` and ``p_ref - origin``. (Applied to the
    absolute values, a robot at rest 1 m from the world's origin would be thrown by a
    jerk of ``(Kx_0 - sum F) * 1 m``: the two differ by 1 %.) The reference should start
    at the origin: a robot at rest has its ZMP under its CoM. Each :meth:`step` takes
    the ZMP reference at the current sample and the ``N`` next ones, applies the law of
    the module doc for one period and returns the jerk it applied (size 2, m/s^3).
    ``state``, ``jerk`` (the last one) and ``zmp`` (the cart-table ZMP ``C X``, size 2)
    are attributes.
    """

    def __init__(
        self, gains: PreviewGains, state: np.ndarray, origin: np.ndarray | None = None
    ) -> None:
        self.gains = gains
        self.A, self.B, self.C = cartTable(gains.period, gains.comHeight, gains.gravity)
        self.state = np.array(state, dtype=float).reshape(3, 2)
        self.origin = self.state[0].copy() if origin is None else np.asarray(origin, float)
        self._X0 = np.zeros((3, 2))
        self._X0[0] = self.origin
        self.errorSum = np.zeros(2)
        self.jerk = np.zeros(2)

    @property
    def zmp(self) -> np.ndarray:
        """The cart-table ZMP of the current state, ``C X`` (size 2, m)."""
        return self.C @ self.state

    def step(self, zmpRef: np.ndarray) -> np.ndarray:
        """One period: ``zmpRef`` is ``(N + 1) x 2``, the reference at the current sample
        and the ``N`` next ones (m). Returns the jerk applied (size 2, m/s^3)."""
        g = self.gains
        self.errorSum += self.C @ self.state - zmpRef[0]
        u = (
            -g.Ks * self.errorSum
            - g.Kx @ (self.state - self._X0)
            + g.F @ (zmpRef[1:] - self.origin)
        )
        self.state = self.A @ self.state + np.outer(self.B, u)
        self.jerk = u
        return u
