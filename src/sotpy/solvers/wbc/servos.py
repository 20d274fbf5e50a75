r"""Servos (PD laws giving a task's desired acceleration) and the minimum-jerk profile.

Pose PD (``pose_pd``), everything in world axes (LOCAL_WORLD_ALIGNED, as the Cartesian
task): with the current placement ``(R, p)``, velocity ``nu = (v_p, w)`` (origin
velocity, angular velocity), the desired ``(R_d, p_d)``, ``nu_d``, ``alpha_d``:

.. math::

    e = (p - p_d, \; \log_3(R R_d^T)), \qquad
    a_{des} = \alpha_d - K_p e - K_d (\nu - \nu_d)

(translation + world rotation error; ``log3(R R_d^T)`` is the rotation vector taking
``R_d`` to ``R`` in world axes, whose time derivative is ``w - w_d`` to first order).
``K_p`` (6, 1/s^2) per axis, ``K_d`` (6, 1/s) defaults to ``2 sqrt(K_p)`` (critical
damping). The joint PD and the CoM PD are the same law on vectors.

PID with anti-windup (``pid_step``): the same law plus the integral of the error,

.. math::

    I_k = \mathrm{clamp}(I_{k-1} + e_k \, \Delta t, -I_{max}, I_{max}), \qquad
    a_{des} = \alpha_d - K_p e_k - K_d (\nu - \nu_d) - K_i I_k

``K_i`` (1/s^3) per axis, ``I`` in m s or rad s, clamped per axis to ``I_max`` (the
anti-windup: a saturated task, or one held off its goal by a constraint, cannot wind the
integral up beyond ``K_i I_max`` of acceleration). It removes the steady error a
weighted QP leaves when tasks compete (a posture task pulling against a hand task).

Minimum jerk from ``M_0`` to ``M_1`` in ``T`` seconds: ``s(x) = 10x^3 - 15x^4 + 6x^5``,
``x = clamp(t/T, 0, 1)``; ``p = p_0 + s (p_1 - p_0)``, ``R = R_0 exp(s w)`` with
``w = log3(R_0^T R_1)``; velocity ``(s' (p_1 - p_0), s' R_0 w)`` and acceleration
``(s'' (p_1 - p_0), s'' R_0 w)`` in world axes (``R_0 exp(s w) w = R_0 w``).
"""

from __future__ import annotations

import math

import numpy as np
import pinocchio as pin

from ...errors import SotpyError

__all__ = [
    "check_gains",
    "joint_pd",
    "min_jerk",
    "min_jerk_scalar",
    "pid_step",
    "pose_error",
    "pose_pd",
    "wrench_pi",
]


def check_gains(
    who: str, Kp: object, Kd: object | None, size: int
) -> tuple[np.ndarray, np.ndarray]:
    """Validate gains (finite, >= 0, scalar or of size ``size``); ``Kd`` defaults to
    ``2 sqrt(Kp)``."""
    kp = (
        np.broadcast_to(np.asarray(Kp, dtype=float), (size,)).copy()
        if np.ndim(Kp) == 0
        else np.asarray(Kp, dtype=float)
    )
    if kp.shape != (size,) or not np.all(np.isfinite(kp)) or np.any(kp < 0):
        raise SotpyError(f"{who}: Kp must be {size} finite values >= 0, got {Kp}")
    if Kd is None or (np.ndim(Kd) == 1 and np.size(Kd) == 0):
        kd = 2.0 * np.sqrt(kp)
    else:
        kd = (
            np.broadcast_to(np.asarray(Kd, dtype=float), (size,)).copy()
            if np.ndim(Kd) == 0
            else np.asarray(Kd, dtype=float)
        )
        if kd.shape != (size,) or not np.all(np.isfinite(kd)) or np.any(kd < 0):
            raise SotpyError(f"{who}: Kd must be {size} finite values >= 0, got {Kd}")
    return kp, kd


def pose_error(M: pin.SE3, Md: pin.SE3) -> np.ndarray:
    """``(p - p_d, log3(R R_d^T))`` (m, rad), world axes."""
    return np.concatenate([M.translation - Md.translation, pin.log3(M.rotation @ Md.rotation.T)])


def pose_pd(
    M: pin.SE3,
    nu: np.ndarray,
    Md: pin.SE3,
    nud: np.ndarray,
    alphad: np.ndarray,
    Kp: np.ndarray,
    Kd: np.ndarray,
) -> np.ndarray:
    """Desired acceleration (6, world axes) of the pose PD (module doc)."""
    return np.asarray(alphad) - Kp * pose_error(M, Md) - Kd * (np.asarray(nu) - np.asarray(nud))


def joint_pd(
    x: np.ndarray,
    v: np.ndarray,
    xd: np.ndarray,
    vd: np.ndarray,
    ad: np.ndarray,
    Kp: np.ndarray,
    Kd: np.ndarray,
) -> np.ndarray:
    """``a_d - Kp (x - x_d) - Kd (v - v_d)`` (joints, CoM)."""
    return np.asarray(ad) - Kp * (np.asarray(x) - xd) - Kd * (np.asarray(v) - vd)


def min_jerk_scalar(t: float, T: float) -> tuple[float, float, float]:
    """``(s, ds/dt, d2s/dt2)`` of the minimum-jerk profile at time ``t`` of ``[0, T]``."""
    if not (math.isfinite(T) and T > 0):
        raise SotpyError(f"min_jerk: the duration must be finite and > 0 (s), got {T}")
    if t <= 0.0:
        return 0.0, 0.0, 0.0
    if t >= T:
        return 1.0, 0.0, 0.0
    x = t / T
    s = x**3 * (10 - 15 * x + 6 * x * x)
    ds = 30 * x * x * (1 - x) ** 2 / T
    dds = 60 * x * (1 - 3 * x + 2 * x * x) / (T * T)
    return s, ds, dds


def min_jerk(
    start: pin.SE3, goal: pin.SE3, duration: float, t: float
) -> tuple[pin.SE3, np.ndarray, np.ndarray]:
    """Pose, velocity (6) and acceleration (6) at ``t`` (world axes, module doc)."""
    s, ds, dds = min_jerk_scalar(t, duration)
    dp = goal.translation - start.translation
    w = pin.log3(start.rotation.T @ goal.rotation)
    R = start.rotation @ pin.exp3(s * w)
    M = pin.SE3(R, start.translation + s * dp)
    ww = start.rotation @ w
    return M, np.concatenate([ds * dp, ds * ww]), np.concatenate([dds * dp, dds * ww])


def wrench_pi(
    w: np.ndarray,
    wd: np.ndarray,
    integral: np.ndarray,
    dt: float,
    Kp: np.ndarray,
    Ki: np.ndarray,
    limit: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """One step of the wrench PI: ``e = wd - w``, ``I+ = clamp(I + e dt, -limit, limit)``,
    returns ``(wd + Kp e + Ki I+, I+)`` (N / N m, N s)."""
    e = wd - w
    integral = np.clip(integral + e * dt, -limit, limit)
    return wd + Kp * e + Ki * integral, integral


def pid_step(
    e: np.ndarray,
    de: np.ndarray,
    ad: np.ndarray,
    integral: np.ndarray,
    dt: float,
    Kp: np.ndarray,
    Kd: np.ndarray,
    Ki: np.ndarray,
    limit: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """One step of the PID (module doc): the error ``e``, its rate ``de`` (``nu - nu_d``),
    the feed-forward ``ad``; returns ``(a_des, I+)`` with ``I+ = clamp(I + e dt, -limit,
    limit)``."""
    integral = np.clip(integral + e * dt, -limit, limit)
    return np.asarray(ad) - Kp * e - Kd * de - Ki * integral, integral
