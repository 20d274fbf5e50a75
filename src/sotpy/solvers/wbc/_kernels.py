r"""Compiled twin of :class:`.qp.WeightedQP`'s reduction and guessed active-set solve
(see :mod:`sotpy._jit`): one call per tick, ``None`` when compiled kernels are disabled.

It computes what the NumPy code of :mod:`.qp` computes, exploiting what the rows of a
whole-body problem look like rather than treating them as dense:

* the reduced Hessian ``H = eps I + sum_i w_i e_i e_i^T`` is accumulated row by row
  over each row's nonzero entries (``e_i`` the row over ``y``; a posture row has one, a
  Cartesian row the joints of its chain), ``sum_i nnz_i^2`` operations instead of
  ``m ny^2``;
* the guessed KKT system is solved in the range space of the Hessian instead of by an
  LU of the whole KKT matrix. For the equalities and guessed rows ``G y = b``, the
  Hessian is first augmented, ``H_a = H + G^T R G`` and ``g_a = g - G^T R b`` (``R``
  diagonal, ``rho_p = max diag H / |G_p|^2``): the same optimum on ``G y = b`` and the
  same multipliers, but the directions that only the regularisation penalises and the
  equalities pin (the floating base's) are no longer ``eps``-flat, without which the
  range-space solve loses eight digits. With ``H_a = L L^T`` (Cholesky), ``W = L^{-1}
  G^T R^{1/2}`` and ``u = L^{-1} g_a``, the scaled multipliers solve ``(W^T W) mu =
  -(R^{1/2} b + W^T u)`` (a Cholesky of ``k x k``, ``k`` the number of those rows),
  ``lambda = R^{1/2} mu`` and ``y = -L^{-T} (u + W mu)``. ``y`` is then stationary by
  construction; the guess is accepted only if every row holds (``PRIMAL_TOL``: the
  equalities and guessed rows as well, which catches nearly dependent rows) and every
  guessed multiplier has the sign of its bound (``DUAL_TOL``): the optimality
  conditions of the convex QP.

The dense steps run along contiguous rows, which the compiler vectorises once sums may
be reassociated (``kernel(fast=True)``): the augmentation as one rank-one update of
``L``'s rows per nonzero entry of a scaled row of ``G`` (stored as the rows of ``W^T``,
then solved in place), the Cholesky factor row by row, one forward substitution per
right-hand side and ``W^T W`` as dot products. The same solves as updates of a column
block (all right-hand sides at once, short rows) measured 3 times slower, and the
previous version of this kernel, which skipped the Hessian's envelope, 1.45 times slower
as a whole on Talos's 50 variables (the floating base's rows make the augmented Hessian
dense anyway).

The data come packed in one array and the results go to one workspace array (their
layouts: :func:`data_layout`, :func:`work_layout`): at these sizes (50 variables on
Talos) converting a dozen arrays to and from Python would cost as much as the
arithmetic. The small factorisations are loops for the same reason.
"""

from __future__ import annotations

import time

import numpy as np

from ..._jit import kernel, report_compile

__all__ = ["data_layout", "solve", "warm_up", "work_layout"]


def data_layout(nv: int, na: int, n: int, m: int, mc: int) -> dict[str, tuple[int, tuple]]:
    """Offsets and shapes of the packed input: the dynamics ``A`` (nv x n), ``c``, the
    task rows ``E`` (m x n), ``f``, ``w``, the constraint rows ``C`` (mc x n), ``lo``,
    ``hi``; ``"size"``: the total."""
    out: dict[str, tuple[int, tuple]] = {}
    o = 0
    for name, shape in (
        ("A", (nv, n)), ("c", (nv,)), ("E", (m, n)), ("f", (m,)), ("w", (m,)),
        ("C", (mc, n)), ("lo", (mc,)), ("hi", (mc,)),
    ):  # fmt: skip
        out[name] = (o, shape)
        o += int(np.prod(shape))
    out["size"] = (o, ())
    return out


def work_layout(nv: int, na: int, n: int, m: int, mc: int) -> dict[str, tuple[int, tuple]]:
    """Offsets and shapes of the workspace: the reduced QP ``H, g, Au, cu, Cy, lo_y,
    hi_y, Tt, tt`` (as :meth:`.qp.WeightedQP.reduce`), the solution ``y``, scratch, and
    an accepted guess's ``chi = (a, tau, f)`` and dynamics residual ``res``
    (``||A chi - c||_inf``)."""
    ny, nu = n - na, nv - na
    kmax = nu + mc
    out: dict[str, tuple[int, tuple]] = {}
    o = 0
    for name, shape in (
        ("H", (ny, ny)), ("g", (ny,)), ("Au", (nu, ny)), ("cu", (nu,)), ("Cy", (mc, ny)),
        ("lo_y", (mc,)), ("hi_y", (mc,)), ("Tt", (na, ny)), ("tt", (na,)), ("y", (ny,)),
        ("L", (ny, ny)), ("ey", (ny,)), ("Wt", (kmax + 1, ny)), ("sr", (kmax,)),
        ("bs", (kmax,)), ("S", (kmax, kmax)), ("lam", (kmax,)),
        ("chi", (n,)), ("res", (1,)),
    ):  # fmt: skip
        out[name] = (o, shape)
        o += int(np.prod(shape))
    out["size"] = (o, ())
    return out


def _cholesky(A, n):  # pragma: no cover - compiled
    """``A[:n, :n]``'s lower triangle overwritten by ``L``, ``L L^T = A`` (row by row:
    ``L_ij = (A_ij - L_i,<j . L_j,<j) / L_jj``, dot products along rows); False if
    ``A`` is not positive definite. The upper triangle is neither read nor written."""
    for i in range(n):
        Ai = A[i]
        for j in range(i + 1):
            Aj = A[j]
            s = Ai[j]
            for q in range(j):
                s -= Ai[q] * Aj[q]
            if j < i:
                Ai[j] = s / Aj[j]
            elif s > 1e-300:
                Ai[i] = np.sqrt(s)
            else:
                return False
    return True


def _forward(L, x, n):  # pragma: no cover - compiled
    """``x[:n] = L^{-1} x[:n]`` (``L`` lower, n x n), in place:
    ``x_i = (x_i - L_i,<i . x_<i) / L_ii``."""
    for i in range(n):
        Li = L[i]
        s = x[i]
        for j in range(i):
            s -= Li[j] * x[j]
        x[i] = s / Li[i]


def _put_row(out, row, b, hmax, sr, bs, p, n):  # pragma: no cover - compiled
    """``out = sqrt(rho) row`` and ``bs[p] = sqrt(rho) b``, ``rho = hmax / |row|^2`` (1
    for a zero row, which the multipliers' solve then refuses); ``sr[p] = sqrt(rho)``."""
    nrm = 0.0
    for j in range(n):
        nrm += row[j] * row[j]
    scale = np.sqrt(hmax / nrm) if nrm > 0.0 else 1.0
    for j in range(n):
        out[j] = scale * row[j]
    sr[p] = scale
    bs[p] = scale * b


#: The kinds of rows in ``unit`` besides a column (see :func:`_solve_lower`).
GENERAL, NO_TAU, CONSTANT = -1, -2, -3


def _data_views(data, nv, n, m, mc):  # pragma: no cover - compiled
    """The views ``(A, c, E, f, w, C, lo, hi)`` of the packed input (:func:`data_layout`)."""
    o = 0
    A = data[o : o + nv * n].reshape((nv, n))
    o += nv * n
    c = data[o : o + nv]
    o += nv
    E = data[o : o + m * n].reshape((m, n))
    o += m * n
    f = data[o : o + m]
    o += m
    w = data[o : o + m]
    o += m
    C = data[o : o + mc * n].reshape((mc, n))
    o += mc * n
    lo = data[o : o + mc]
    o += mc
    hi = data[o : o + mc]
    return A, c, E, f, w, C, lo, hi


def _solve(
    data, ws, act, up, unit, fresh, nv, na, n, m, mc, reg, guess, ptol, dtol_rel, lam_max
):  # pragma: no cover - compiled
    """:func:`_solve_lower`, then, unless the guess was accepted, ``H``'s upper triangle
    mirrored from its lower one (the caller's other solvers read all of it; the guess
    reads only the lower one)."""
    status, ok = _solve_lower_c(
        data, ws, act, up, unit, fresh, nv, na, n, m, mc, reg, guess, ptol, dtol_rel, lam_max
    )
    if not ok:
        ny = n - na
        H = ws[: ny * ny].reshape((ny, ny))
        for a in range(ny):
            for b in range(a):
                H[b, a] = H[a, b]
    return status, ok


def _solve_lower(
    data, ws, act, up, unit, fresh, nv, na, n, m, mc, reg, guess, ptol, dtol_rel, lam_max
):  # pragma: no cover - compiled
    """``(status, ok)``: the reduced QP of :meth:`.qp.WeightedQP.reduce` written to the
    workspace (``H``: its lower triangle) and, if ``guess``, the guessed active set's
    solution ``y`` (``ok``: accepted). ``status``: 0, or 1 (a NaN bound), 2 (a row
    with lower > upper + 1e-12). The actuated rows of ``A`` are its last ``na`` rows.

    ``unit`` (size ``m + mc``, the task rows then the constraint rows; or empty: every
    row ``GENERAL``) says what the kernel may skip in each row:

    * ``>= 0``: the column of the row's only nonzero entry, a 1 (a posture, a torque or
      joint limit): one update of ``H``, or a copy of ``T_tau``'s row, instead of a pass
      over ``n`` columns;
    * ``NO_TAU``: no entry in the torque columns (a Jacobian row, a friction row): no
      pass over them;
    * ``CONSTANT`` (constraint rows): no torque entry and the same row at every call of
      this structure: its row over ``y`` is written only when ``fresh`` (the first call
      of the structure with this workspace; the caller knows) and kept in the
      workspace after;
    * ``GENERAL``: none of these."""
    ny = n - na
    nu = nv - na
    kmax = nu + mc
    A, c, E, f, w, C, lo, hi = _data_views(data, nv, n, m, mc)
    o = 0
    H = ws[o : o + ny * ny].reshape((ny, ny))
    o += ny * ny
    g = ws[o : o + ny]
    o += ny
    Au = ws[o : o + nu * ny].reshape((nu, ny))
    o += nu * ny
    cu = ws[o : o + nu]
    o += nu
    Cy = ws[o : o + mc * ny].reshape((mc, ny))
    o += mc * ny
    loy = ws[o : o + mc]
    o += mc
    hiy = ws[o : o + mc]
    o += mc
    Tt = ws[o : o + na * ny].reshape((na, ny))
    o += na * ny
    tt = ws[o : o + na]
    o += na
    y = ws[o : o + ny]
    o += ny
    L = ws[o : o + ny * ny].reshape((ny, ny))
    o += ny * ny
    ey = ws[o : o + ny]
    o += ny
    Wt = ws[o : o + (kmax + 1) * ny].reshape((kmax + 1, ny))
    o += (kmax + 1) * ny
    sr = ws[o : o + kmax]
    o += kmax
    bs = ws[o : o + kmax]
    o += kmax
    S = ws[o : o + kmax * kmax].reshape((kmax, kmax))
    o += kmax * kmax
    lam = ws[o : o + kmax]
    o += kmax
    chi = ws[o : o + n]
    o += n
    res = ws[o : o + 1]

    for i in range(nv):
        for j in range(nv):
            v = A[i, j]
            if i < nu:
                Au[i, j] = v
            else:
                Tt[i - nu, j] = v
        for j in range(nv, ny):
            v = A[i, j + na]
            if i < nu:
                Au[i, j] = v
            else:
                Tt[i - nu, j] = v
    for j in range(na):
        tt[j] = -c[nu + j]
    for i in range(nu):
        cu[i] = c[i]
    H[:, :] = 0.0
    g[:] = 0.0
    idx = np.empty(ny, dtype=np.intp)
    for i in range(ny):  # eps I: the regularisation of y = (a, f)
        H[i, i] = reg
    # the task rows
    general = unit.shape[0] != m + mc  # no unit rows known
    for i in range(m):
        wi = w[i]
        if wi == 0.0:
            continue
        fyi = f[i]
        col = GENERAL if general else unit[i]
        if col >= 0 and (col < nv or col >= nv + na):  # one entry 1 on a or f
            yc = col if col < nv else col - na
            H[yc, yc] += wi
            g[yc] -= wi * fyi
            continue
        k = 0  # the nonzero entries of the row over y, as it is copied
        for j in range(nv):
            e = E[i, j]
            ey[j] = e
            if e != 0.0:
                idx[k] = j
                k += 1
        for j in range(nv, ny):
            e = E[i, j + na]
            ey[j] = e
            if e != 0.0:
                idx[k] = j
                k += 1
        if col == GENERAL or col >= 0:  # the torque entries (none in NO_TAU rows)
            mapped = False
            for j in range(na):
                e = E[i, nv + j]
                if e != 0.0:
                    mapped = True
                    for q in range(ny):
                        ey[q] += e * Tt[j, q]
                    fyi -= e * tt[j]
            if mapped:
                k = 0
                for q in range(ny):
                    if ey[q] != 0.0:
                        idx[k] = q
                        k += 1
        for p in range(k):
            a = idx[p]
            va = wi * ey[a]
            g[a] -= va * fyi
            for q in range(p + 1):
                b = idx[q]
                H[a, b] += va * ey[b]
    # the constraint rows over y: lo - C_tau tt <= (C_y + C_tau Tt) y <= hi - C_tau tt
    status = 0
    neq = 0
    for i in range(mc):
        col = GENERAL if general else unit[m + i]
        s = 0.0
        if col == CONSTANT and not fresh:
            pass  # its row over y is the one written at the structure's first call
        elif col >= 0:  # one entry 1: a row of the identity over y, or of T_tau
            if nv <= col < nv + na:
                j = col - nv
                for q in range(ny):
                    Cy[i, q] = Tt[j, q]
                s = tt[j]
            else:
                for q in range(ny):
                    Cy[i, q] = 0.0
                Cy[i, col if col < nv else col - na] = 1.0
        else:
            for j in range(nv):
                Cy[i, j] = C[i, j]
            for j in range(nv, ny):
                Cy[i, j] = C[i, j + na]
            if col == GENERAL:  # the torque entries (none in the other kinds of rows)
                for j in range(na):
                    e = C[i, nv + j]
                    if e != 0.0:
                        for q in range(ny):
                            Cy[i, q] += e * Tt[j, q]
                        s += e * tt[j]
        loy[i] = lo[i] - s
        hiy[i] = hi[i] - s
        if np.isnan(loy[i]) or np.isnan(hiy[i]):
            status = 1
        elif status == 0 and loy[i] > hiy[i] + 1e-12:
            status = 2
        if lo[i] == hi[i]:
            neq += 1
    y[:] = 0.0
    if status != 0 or not guess:
        return status, False
    # the guessed KKT system G y = b: the equalities, then the guessed rows, each row
    # scaled by sqrt(rho_p), rho_p = max diag H / |G_p|^2, as a row of Wt
    nact = act.shape[0]
    k = nu + neq + nact
    if k > kmax:
        return status, False
    hmax = 0.0
    for i in range(ny):
        if H[i, i] > hmax:
            hmax = H[i, i]
    r = 0
    for i in range(nu):
        _put_row(Wt[r], Au[i], cu[i], hmax, sr, bs, r, ny)
        r += 1
    for i in range(mc):
        if lo[i] == hi[i]:
            _put_row(Wt[r], Cy[i], loy[i], hmax, sr, bs, r, ny)
            r += 1
    for t in range(nact):
        i = act[t]
        _put_row(Wt[r], Cy[i], hiy[i] if up[t] else loy[i], hmax, sr, bs, r, ny)
        r += 1
    # augmented Lagrangian: H_a = H + G^T R G and g_a = g - G^T R b have the same
    # optimum on G y = b and the same multipliers, but no direction that the equalities
    # pin and only eps penalises: the range-space solve is then as accurate as an LU of
    # the KKT matrix. H_a's lower triangle goes to L, g_a to Wt's last row; one
    # rank-one update along L's rows per nonzero entry of a scaled row.
    u = Wt[k]
    for i in range(ny):
        Li = L[i]
        Hi = H[i]
        for j in range(i + 1):
            Li[j] = Hi[j]
        u[i] = g[i]
    for p in range(k):
        Wp = Wt[p]
        bp = bs[p]
        for i in range(ny):
            wi = Wp[i]
            if wi != 0.0:
                Li = L[i]
                for j in range(i + 1):
                    Li[j] += wi * Wp[j]
                u[i] -= wi * bp
    if not _cholesky(L, ny):  # H_a = L L^T, in place
        return status, False
    # the rows of (W, u)^T = (L^{-1} (G^T R^1/2, g_a))^T, in place: forward
    # substitutions, each a sequence of dot products along contiguous rows
    for p in range(k + 1):
        _forward(L, Wt[p], ny)
    # the scaled multipliers: (W^T W) lambda = -(b_s + W^T u)
    for p in range(k):
        Wp = Wt[p]
        s = 0.0
        for i in range(ny):
            s += Wp[i] * u[i]
        lam[p] = -bs[p] - s
        for q in range(p + 1):
            Wq = Wt[q]
            s = 0.0
            for i in range(ny):
                s += Wp[i] * Wq[i]
            S[p, q] = s
    if k > 0 and not _cholesky(S, k):
        return status, False
    for i in range(k):  # S = Ls Ls^T (in S's lower triangle); Ls Ls^T lam = rhs
        s = lam[i]
        for j in range(i):
            s -= S[i, j] * lam[j]
        lam[i] = s / S[i, i]
    for i in range(k - 1, -1, -1):
        s = lam[i]
        for j in range(i + 1, k):
            s -= S[j, i] * lam[j]
        lam[i] = s / S[i, i]
    # y = -L^{-T} (u + W lambda), a back substitution along L's rows
    for i in range(ny):
        ey[i] = u[i]
    for p in range(k):
        Wp = Wt[p]
        lp = lam[p]
        for i in range(ny):
            ey[i] += Wp[i] * lp
    for i in range(ny - 1, -1, -1):
        yi = ey[i] / L[i, i]
        y[i] = -yi
        Li = L[i]
        for j in range(i):
            ey[j] -= Li[j] * yi
    lmax = 0.0
    for p in range(k):  # the multipliers of the unscaled rows
        lam[p] *= sr[p]
        a = abs(lam[p])
        if not a < 1e300:  # NaN or infinite
            return status, False
        if a > lmax:
            lmax = a
    gmax = 1.0
    for i in range(ny):
        if abs(g[i]) + 1.0 > gmax:
            gmax = abs(g[i]) + 1.0
    if lmax > lam_max * gmax:
        return status, False
    dtol = dtol_rel * gmax
    base = nu + neq
    for t in range(nact):
        lt = lam[base + t]
        if (up[t] and lt < -dtol) or ((not up[t]) and lt > dtol):
            return status, False
    for i in range(nu):
        s = 0.0
        for j in range(ny):
            s += Au[i, j] * y[j]
        if abs(s - cu[i]) > ptol * (1.0 + abs(cu[i])):
            return status, False
    for i in range(mc):
        s = 0.0
        for j in range(ny):
            s += Cy[i, j] * y[j]
        if s > hiy[i] + ptol * (1.0 + abs(hiy[i])) or s < loy[i] - ptol * (1.0 + abs(loy[i])):
            return status, False
    for i in range(ny):
        if not abs(y[i]) < 1e300:  # NaN passes the comparisons above
            return status, False
    # chi = (a, tau = Tt y + tt, f) and its dynamics residual
    for i in range(nv):
        chi[i] = y[i]
    for i in range(nv, ny):
        chi[i + na] = y[i]
    for j in range(na):
        s = tt[j]
        for i in range(ny):
            s += Tt[j, i] * y[i]
        chi[nv + j] = s
    rmax = 0.0
    for i in range(nv):
        s = -c[i]
        for j in range(n):
            s += A[i, j] * chi[j]
        if abs(s) > rmax:
            rmax = abs(s)
    res[0] = rmax
    return status, True


_data_views = kernel(_data_views)
_cholesky = kernel(_cholesky, fast=True)
_forward = kernel(_forward, fast=True)
_put_row = kernel(_put_row, fast=True)
_solve_lower_c = kernel(_solve_lower, fast=True)
solve = kernel(_solve, fast=True)
_warm: list[bool] = []


def warm_up() -> None:
    """Compile (or load from numba's cache) the kernel for the argument types of
    :class:`.qp.WeightedQP`, so that the first control tick does not pay for it; then
    forbid further compilation: a call with other types raises ``TypeError`` (the
    caller falls back to NumPy) instead of stalling a control tick for seconds."""
    if solve is None or _warm:
        return
    start = time.perf_counter()
    nv, na, m, mc = 2, 1, 1, 1
    n = nv + na
    lay = data_layout(nv, na, n, m, mc)
    data = np.zeros(lay["size"][0])
    ws = np.zeros(work_layout(nv, na, n, m, mc)["size"][0])
    A = data[: nv * n].reshape(nv, n)
    A[:, :nv] = np.eye(nv)
    solve(data, ws, np.zeros(1, dtype=np.intp), np.ones(1, dtype=np.bool_),
          np.zeros(0, dtype=np.intp), True, nv, na, n, m, mc, 1e-8, True, 1e-9, 1e-9,
          1e6)  # fmt: skip
    solve.disable_compile()
    _warm.append(True)
    report_compile("the whole-body QP kernel", time.perf_counter() - start)
