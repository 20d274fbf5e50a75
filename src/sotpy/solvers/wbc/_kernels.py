"""Compiled twins of :class:`.qp.WeightedQP`'s reduction and guessed KKT solve (see
:mod:`sotpy._jit`). Same arithmetic as the NumPy code of :mod:`.qp`, one call each.
``None`` when compiled kernels are disabled."""

from __future__ import annotations

import time

import numpy as np

from ..._jit import kernel, report_compile


def _reduce(A, c, E, f, w, C, lo, hi, reg, nv, na):  # pragma: no cover - compiled
    """``(status, (H, g, Au, cu, Cy, lo_y, hi_y, Tt, tt))`` as
    :meth:`.qp.WeightedQP.reduce`; the actuated rows of ``A`` are its last ``na`` rows.
    ``status``: 0, or 1 (a NaN bound), 2 (a row with lower > upper + 1e-12)."""
    n = A.shape[1]
    ny = n - na
    nu = nv - na
    Ay = np.empty((nv, ny))
    Ay[:, :nv] = A[:, :nv]
    Ay[:, nv:] = A[:, nv + na :]
    Tt = np.ascontiguousarray(Ay[nu:])
    tt = -c[nu:]
    Au = np.ascontiguousarray(Ay[:nu])
    cu = c[:nu].copy()
    H = reg * (Tt.T @ Tt)
    for i in range(ny):
        H[i, i] += reg
    g = reg * (Tt.T @ tt)
    m = E.shape[0]
    if m > 0:
        Ey = np.empty((m, ny))
        Ey[:, :nv] = E[:, :nv]
        Ey[:, nv:] = E[:, nv + na :]
        fy = f.copy()
        _add_torque_columns(E, nv, na, Tt, tt, Ey, fy)
        for i in range(m):
            s = np.sqrt(w[i])
            Ey[i] *= s
            fy[i] *= s
        H += Ey.T @ Ey
        g -= Ey.T @ fy
    mc = C.shape[0]
    Cy = np.empty((mc, ny))
    Cy[:, :nv] = C[:, :nv]
    Cy[:, nv:] = C[:, nv + na :]
    shift = np.zeros(mc)
    _add_torque_columns(C, nv, na, Tt, tt, Cy, shift)
    lo = lo + shift
    hi = hi + shift
    status = 0
    for i in range(mc):
        if np.isnan(lo[i]) or np.isnan(hi[i]):
            status = 1
            break
        if lo[i] > hi[i] + 1e-12:
            status = 2
    return status, (H, g, Au, cu, Cy, lo, hi, Tt, tt)


def _add_torque_columns(E, nv, na, Tt, tt, Ey, fy):  # pragma: no cover - compiled
    """``Ey += E_tau T_tau`` and ``fy -= E_tau t_tau`` (``E_tau`` the torque columns of
    ``E``), by rows and skipping zeros when ``E_tau`` is sparse (torque limits: one
    entry a row; acceleration rows: none), by one product otherwise."""
    m = E.shape[0]
    nnz = 0
    for i in range(m):
        for j in range(na):
            if E[i, nv + j] != 0.0:
                nnz += 1
    if nnz == 0:
        return
    if 4 * nnz > m * na:
        Et = np.ascontiguousarray(E[:, nv : nv + na])
        Ey += Et @ Tt
        fy -= Et @ tt
        return
    ny = Tt.shape[1]
    for i in range(m):
        for j in range(na):
            e = E[i, nv + j]
            if e != 0.0:
                for c in range(ny):
                    Ey[i, c] += e * Tt[j, c]
                fy[i] -= e * tt[j]


def _guess(H, g, Au, cu, Cy, lo, hi, act, up, ptol, dtol_rel, lam_max):  # pragma: no cover
    """``(ok, y)`` as :meth:`.qp.WeightedQP._try_guess` (``ok`` False: not the optimum;
    raises on a singular KKT matrix)."""
    ny = H.shape[0]
    nu = Au.shape[0]
    mc = Cy.shape[0]
    neq = 0
    for i in range(mc):
        if lo[i] == hi[i]:
            neq += 1
    na_ = act.shape[0]
    k = ny + nu + neq + na_
    K = np.zeros((k, k))
    rhs = np.empty(k)
    K[:ny, :ny] = H
    rhs[:ny] = -g
    K[ny : ny + nu, :ny] = Au
    rhs[ny : ny + nu] = cu
    j = ny + nu
    for i in range(mc):
        if lo[i] == hi[i]:
            K[j, :ny] = Cy[i]
            rhs[j] = lo[i]
            j += 1
    for t in range(na_):
        i = act[t]
        K[j, :ny] = Cy[i]
        rhs[j] = hi[i] if up[t] else lo[i]
        j += 1
    K[:ny, ny:] = K[ny:, :ny].T
    z = np.linalg.solve(K, rhs)
    y = z[:ny].copy()
    if not np.all(np.isfinite(z)):
        return False, y
    gmax = 1.0 + np.max(np.abs(g))
    if k > ny and np.max(np.abs(z[ny:])) > lam_max * gmax:
        return False, y
    dtol = dtol_rel * gmax
    base = ny + nu + neq
    for t in range(na_):
        lam = z[base + t]
        if (up[t] and lam < -dtol) or ((not up[t]) and lam > dtol):
            return False, y
    v = Cy @ y
    for i in range(mc):
        if v[i] > hi[i] + ptol * (1.0 + abs(hi[i])) or v[i] < lo[i] - ptol * (1.0 + abs(lo[i])):
            return False, y
    return True, y


_add_torque_columns = kernel(_add_torque_columns)
reduce = kernel(_reduce)
guess = kernel(_guess)
_warm: list[bool] = []


def warm_up() -> None:
    """Compile (or load from numba's cache) both kernels for the argument types of
    :class:`.qp.WeightedQP`, so that the first control tick does not pay for it; then
    forbid further compilation: a call with other types raises ``TypeError`` (the
    caller falls back to NumPy) instead of stalling a control tick for seconds."""
    if reduce is None or guess is None or _warm:
        return
    start = time.perf_counter()
    nv, na = 2, 1
    n = nv + na
    A = np.eye(nv, n)
    c = np.zeros(nv)
    E = np.eye(1, n)
    C = np.zeros((1, n))
    C[0, nv] = 1.0
    b = np.ones(1)
    _status, data = reduce(A, c, E, b, b, C, -b, b, 1e-8, nv, na)
    H, g, Au, cu, Cy, lo, hi, _Tt, _tt = data
    guess(H, g, Au, cu, Cy, lo, hi, np.zeros(1, dtype=np.intp), np.ones(1, dtype=np.bool_),
          1e-9, 1e-9, 1e6)  # fmt: skip
    reduce.disable_compile()
    guess.disable_compile()
    _warm.append(True)
    report_compile("the whole-body QP kernels", time.perf_counter() - start)
