r"""Compiled kernels that write task rows straight into a solver's stacked buffer
(internal to ``sotpy.tasks``: the row writers of the features, :mod:`.rows`).

Each kernel writes, for the selected rows ``k`` of one feature, the Jacobian row into
``A[r + i, :]`` and the equality target ``-gain * e_k`` into ``b[r + i]``: the values
the feature's ``jacobian`` and the task's ``task`` signals hold, without the
intermediate arrays. The formulas are those of the features (``features.py``); the
tests compare the two paths on random inputs.

:func:`log3` and :func:`jlog3` are the rotation logarithm and its Jacobian, written
here so that they compile with the rest (Pinocchio's are Python calls):

* ``log3(R) = theta u`` with ``theta = atan2(|w|, (tr R - 1) / 2)``, ``w`` the vector
  of the skew part ``(R - R^T) / 2`` (``w = sin(theta) u``): ``log3 = w theta / |w|``,
  its Taylor series ``w (1 + theta^2 / 6)`` below ``theta = 1e-4``. Near ``pi``
  (``cos theta < -0.9``) the axis comes from the symmetric part, ``u u^T = (R + R^T -
  2 cos(theta) I) / (2 (1 - cos theta))`` (the largest diagonal entry first), its sign
  that of ``w``.
* ``Jlog3(R) = I + [w]/2 + c(theta) [w]^2`` with ``w = log3(R)``,
  ``c = 1/theta^2 - 1/(2 theta tan(theta/2))``, and ``c = 1/12 + theta^2/720 +
  theta^4/30240`` below ``theta = 1e-2``: ``d log3(R exp([d])) / dd`` at ``d = 0``
  (the inverse of the right Jacobian of SO(3)).
"""

from __future__ import annotations

import math

import numpy as np

from .._jit import kernel

_PI_SIDE = -0.9  # cos(theta) below this: the axis from the symmetric part


def _log3(R, out):  # pragma: no cover - compiled (the NumPy twin is Pinocchio's log3)
    """``out <- log3(R)``; returns ``theta``."""
    wx = 0.5 * (R[2, 1] - R[1, 2])
    wy = 0.5 * (R[0, 2] - R[2, 0])
    wz = 0.5 * (R[1, 0] - R[0, 1])
    c = 0.5 * (R[0, 0] + R[1, 1] + R[2, 2] - 1.0)
    s = math.sqrt(wx * wx + wy * wy + wz * wz)
    theta = math.atan2(s, c)
    if c < _PI_SIDE:
        # u u^T = (R + R^T - 2 c I) / (2 (1 - c)): the largest diagonal entry first
        d = 1.0 / (1.0 - c)
        u0 = (R[0, 0] - c) * d
        u1 = (R[1, 1] - c) * d
        u2 = (R[2, 2] - c) * d
        if u0 >= u1 and u0 >= u2:
            a = math.sqrt(max(u0, 0.0))
            x, y, z = a, 0.5 * (R[0, 1] + R[1, 0]) * d / a, 0.5 * (R[0, 2] + R[2, 0]) * d / a
        elif u1 >= u2:
            a = math.sqrt(max(u1, 0.0))
            x, y, z = 0.5 * (R[0, 1] + R[1, 0]) * d / a, a, 0.5 * (R[1, 2] + R[2, 1]) * d / a
        else:
            a = math.sqrt(max(u2, 0.0))
            x, y, z = 0.5 * (R[0, 2] + R[2, 0]) * d / a, 0.5 * (R[1, 2] + R[2, 1]) * d / a, a
        if x * wx + y * wy + z * wz < 0.0:
            x, y, z = -x, -y, -z
        out[0], out[1], out[2] = theta * x, theta * y, theta * z
    else:
        f = 1.0 + theta * theta / 6.0 if theta < 1e-4 else theta / s
        out[0], out[1], out[2] = f * wx, f * wy, f * wz
    return theta


def _jlog3(w, theta, J):  # pragma: no cover - compiled
    """``J <- Jlog3`` at the rotation whose logarithm is ``w`` (``theta = |w|``)."""
    t2 = theta * theta
    if theta < 1e-2:
        c = 1.0 / 12.0 + t2 / 720.0 + t2 * t2 / 30240.0
    else:
        c = 1.0 / t2 - 1.0 / (2.0 * theta * math.tan(0.5 * theta))
    x, y, z = w[0], w[1], w[2]
    # I + [w]/2 + c [w]^2, with [w]^2 = w w^T - theta^2 I
    J[0, 0] = 1.0 + c * (x * x - t2)
    J[1, 1] = 1.0 + c * (y * y - t2)
    J[2, 2] = 1.0 + c * (z * z - t2)
    J[0, 1] = -0.5 * z + c * x * y
    J[1, 0] = 0.5 * z + c * x * y
    J[0, 2] = 0.5 * y + c * x * z
    J[2, 0] = -0.5 * y + c * x * z
    J[1, 2] = -0.5 * x + c * y * z
    J[2, 1] = 0.5 * x + c * y * z


def _pose_rows(R, p, Rd, pd, Jq, rows, A, b, r, gain):  # pragma: no cover - compiled
    """FeaturePose's selected rows: ``Mr = (Rd^T R, Rd^T (p - pd))``, error ``(p_r,
    log3(R_r))``, Jacobian ``diag(R_r, Jlog3(R_r)) Jq``; row ``i`` of the output is
    feature row ``rows[i]``. ``A[r + i] = J_k``, ``b[r + i] = -gain e_k``."""
    n = A.shape[1]
    Rr = np.empty((3, 3))
    for i in range(3):
        for j in range(3):
            Rr[i, j] = Rd[0, i] * R[0, j] + Rd[1, i] * R[1, j] + Rd[2, i] * R[2, j]
    e = np.empty(6)
    for i in range(3):
        e[i] = Rd[0, i] * (p[0] - pd[0]) + Rd[1, i] * (p[1] - pd[1]) + Rd[2, i] * (p[2] - pd[2])
    rot = False
    for k in rows:
        if k >= 3:
            rot = True
    Jl = np.empty((3, 3))
    if rot:
        theta = _log3_c(Rr, e[3:])
        _jlog3_c(e[3:], theta, Jl)
    for i in range(rows.shape[0]):
        k = rows[i]
        D = Rr if k < 3 else Jl
        kk = k if k < 3 else k - 3
        off = 0 if k < 3 else 3
        d0, d1, d2 = D[kk, 0], D[kk, 1], D[kk, 2]
        for j in range(n):
            A[r + i, j] = d0 * Jq[off, j] + d1 * Jq[off + 1, j] + d2 * Jq[off + 2, j]
        b[r + i] = -gain * e[k]


def _generic_rows(s, sdes, J, rows, A, b, r, gain):  # pragma: no cover - compiled
    """FeatureGeneric's selected rows: ``A[r + i] = J[k]``, ``b[r + i] = -gain (s_k -
    sdes_k)`` with ``k = rows[i]`` (``sdes`` empty: no reference)."""
    n = A.shape[1]
    ref = sdes.shape[0] > 0
    for i in range(rows.shape[0]):
        k = rows[i]
        for j in range(n):
            A[r + i, j] = J[k, j]
        b[r + i] = -gain * (s[k] - sdes[k]) if ref else -gain * s[k]


def _posture_rows(q, qdes, iq, iv, A, b, r, gain):  # pragma: no cover - compiled
    """FeaturePosture's rows for one-DoF joints whose configuration is their angle:
    ``A[r + i]`` the row ``iv[i]`` of the identity, ``b[r + i] = -gain (q - q*)`` at
    configuration index ``iq[i]``."""
    n = A.shape[1]
    for i in range(iv.shape[0]):
        for j in range(n):
            A[r + i, j] = 0.0
        A[r + i, iv[i]] = 1.0
        b[r + i] = -gain * (q[iq[i]] - qdes[iq[i]])


def _limit_bounds(q, iq, ql, qu, vm, dt, lo, up, r):  # pragma: no cover - compiled
    """The SOT's joint-limit level (bounds on ``qdot_j`` for the joints at ``iq``):
    ``lo[r + i] = clip((ql_i - q_j) / dt, -vm_i, vm_i)`` and ``up[r + i]`` the same with
    ``qu_i``, in the operations and order of :meth:`SOT._limitLevel` (a NaN stays NaN,
    as with ``np.maximum``/``np.minimum``). ``q`` must hold every ``iq``."""
    for i in range(iq.shape[0]):
        qi = q[iq[i]]
        v = vm[i]
        a = (ql[i] - qi) / dt
        b = (qu[i] - qi) / dt
        if a < -v:
            a = -v
        if a > v:
            a = v
        if b < -v:
            b = -v
        if b > v:
            b = v
        lo[r + i] = a
        up[r + i] = b


def _inequality_bounds(rinf, rsup, c, lo, up, r, m):  # pragma: no cover - compiled
    """TaskInequality's bounds from its references, in place: on entry ``lo[r:r + m]``
    holds ``-c e`` (the features' rows), on exit ``lo = -c e + c referenceInf`` and
    ``up = -c e + c referenceSup`` (``-inf``/``+inf`` where a reference is empty), the
    operations of :meth:`TaskInequality._bounds`. Returns ``m``, or -1 (the task's
    callbacks then say what is wrong) when a reference's size is neither 0 nor ``m``,
    a lower reference is ``+inf`` or an upper one ``-inf``, ``referenceInf >
    referenceSup``, or a finite reference gives a bound that is not finite (an
    overflow). On -1 the bounds written so far are not to be used."""
    ni, ns = rinf.shape[0], rsup.shape[0]
    if (ni != 0 and ni != m) or (ns != 0 and ns != m):
        return -1
    for i in range(m):
        b = lo[r + i]
        lower, upper = -math.inf, math.inf
        if ni:
            ri = rinf[i]
            if not ri < math.inf:
                return -1
            lower = ri * c + b
            if math.isfinite(ri) != math.isfinite(lower):
                return -1
        if ns:
            si = rsup[i]
            if not si > -math.inf:
                return -1
            if ni and rinf[i] > si:
                return -1
            upper = si * c + b
            if math.isfinite(si) != math.isfinite(upper):
                return -1
        lo[r + i] = lower
        up[r + i] = upper
    return m


_log3_c = kernel(_log3)
_jlog3_c = kernel(_jlog3)
pose_rows = kernel(_pose_rows)
generic_rows = kernel(_generic_rows)
posture_rows = kernel(_posture_rows)
limit_bounds = kernel(_limit_bounds)
inequality_bounds = kernel(_inequality_bounds)
_warm: list[bool] = []


def log3(R: np.ndarray) -> np.ndarray:
    """The compiled ``log3`` (tests compare it with Pinocchio's; needs numba)."""
    out = np.empty(3)
    _log3_c(np.ascontiguousarray(R, dtype=float), out)  # type: ignore[misc]
    return out


def jlog3(R: np.ndarray) -> np.ndarray:
    """The compiled ``Jlog3`` (tests compare it with Pinocchio's)."""
    w = log3(R)
    J = np.empty((3, 3))
    _jlog3_c(w, float(np.linalg.norm(w)), J)  # type: ignore[misc]
    return J


def warm_up() -> None:
    """Compile (or load from the cache) the kernels for the argument types a tick
    passes (Pinocchio's column-major rotations, C-order Jacobians, int64 rows), then
    forbid further compilation: an unforeseen type raises ``TypeError`` at the call
    and the caller goes back to the feature signals, instead of compiling mid-loop.

    The arrays a kernel only reads are given read-only here: numba then accepts both a
    read-only and a writable array there (a signal's value may be either), without a
    version compiled for each combination."""
    if pose_rows is None or _warm:
        return
    import pinocchio as pin

    def ro(a: np.ndarray) -> np.ndarray:
        v = a.view()
        v.setflags(write=False)
        return v

    M = pin.SE3.Identity()
    n = 2
    b = np.zeros(6)
    Jq = ro(np.zeros((6, n)))
    rows = ro(np.arange(6, dtype=np.int64))
    s, J = ro(np.zeros(3)), ro(np.zeros((3, n)))
    # rows into a C-order buffer (the SOT's own) or into the m x n view of the solver's
    # stacked [A | -ref] (HierarchySolver.stacked)
    for A in (np.zeros((6, n)), np.zeros((6, n + 1))[:, :n]):
        for R, p in ((M.rotation, M.translation), (np.eye(3), np.zeros(3))):
            R, p = ro(R), ro(p)
            pose_rows(R, p, R, p, Jq, rows, A, b, 0, 1.0)
        generic_rows(s, s, J, rows[:3], A, b, 0, 1.0)
        generic_rows(s, s[:0], J, rows[:3], A, b, 0, 1.0)
        posture_rows(s, s, rows[:1], rows[:1], A, b, 0, 1.0)
    log3(np.eye(3))
    jlog3(np.eye(3))
    limit_bounds(s, rows[:1], s, s, s, 1.0, b, b, 0)
    inequality_bounds(s, s[:0], 1.0, b, b, 0, 3)
    for k in (
        pose_rows,
        generic_rows,
        posture_rows,
        limit_bounds,
        inequality_bounds,
        _log3_c,
        _jlog3_c,
    ):
        k.disable_compile()
    _warm.append(True)
