"""The equality recursion of :class:`._equality.NullspaceStepper` as one compiled call
(internal to ``sotpy.solvers``; see :mod:`sotpy._jit`).

:func:`equality_stack` runs the null-space recursion over a whole stack of equality
levels with the arithmetic of :meth:`NullspaceStepper.step`: ``dgeqp3`` of ``M^T``, the
rank from ``|R_ii|``, the step by a triangular solve or (a rank-deficient or damped
block) a least-squares solve, ``Z`` updated by the reflectors; the least-squares last
level from a pivoted QR of ``M``. ``dgeqp3`` is reached from numba through the address
that ``scipy.linalg.cython_lapack`` exports, so the call costs no Python; the
reflections, triangular solves and least squares are those of :mod:`._smallqr`
(LAPACK's ``dormqr``, ``dtrtrs`` and ``dgels`` cost more in fixed overhead than in
flops at these sizes). Blocks of
consecutive levels known to be of full row rank are stepped together, as by
:meth:`HierarchySolver._solve_equality`. ``None`` when compiled kernels are disabled.
"""

from __future__ import annotations

import time

import numpy as np

from .._jit import ENABLED, report_compile

#: :func:`equality_all`'s status
SOLVED, NONFINITE_MATRIX, NONFINITE_RESULT = 0, 1, 2

equality_stack = None
equality_all = None
box_steps = None
residuals = None
box_update = None
bounds_prepare = None
_warm: list[bool] = []


def warm_up() -> None:
    """Compile (or load from numba's cache) the kernels for the argument types the
    solver passes, once per process, so that a control loop's first tick does not pay
    for it; then forbid further compilation: a call with other types raises
    ``TypeError`` (the solver falls back to NumPy) instead of stalling a tick."""
    if equality_all is None or _warm:
        return
    start = time.perf_counter()
    n = 3
    A = np.hstack([np.eye(n), -np.ones((n, 1))])
    starts = np.array([0, 1, n], dtype=np.int64)
    blocks = np.array([[0, 1], [1, 2]], dtype=np.int64)
    lams = np.zeros(2)
    # the kernels themselves, not the module's names (a test may have wrapped those)
    _equality_all(A, starts, blocks, lams, 1e-9, 1)
    _equality_stack(A, starts, blocks, np.ones(2), lams, 1e-9, 1)
    _residuals(A, np.ones(n + 1), starts, np.zeros(n), np.ones(n), True)
    _box_update(  # a column slice of the stacked buffer, as the solver passes it
        A[:, :n], n, n, np.arange(n), np.ones(n), -np.ones(n), np.ones(n), np.zeros(n), np.zeros(n),
        np.zeros(n, dtype=np.bool_), np.zeros(n, dtype=np.bool_),
    )  # fmt: skip
    z = np.zeros(n)
    _bounds_prepare(A, -np.ones(n), np.ones(n), z, z.copy(), z.copy(), z.copy(),
                    np.zeros(n, dtype=np.bool_), starts)  # fmt: skip
    _box_steps(A, starts, blocks, np.ones(2), 1e-9, 1, np.zeros(1, dtype=np.int64), np.zeros(1),
               np.ones(1), 1e-10)  # fmt: skip
    kernels = (_equality_all, _equality_stack, _residuals, _box_update, _bounds_prepare, _box_steps)
    for fn in kernels:
        fn.disable_compile()
    _warm.append(True)
    report_compile("the hierarchical solver kernels", time.perf_counter() - start)


if ENABLED:  # pragma: no branch - the environment decides
    import llvmlite.binding as _llvm
    import numba as _nb
    from numba import types as _t
    from numba.extending import get_cython_function_address as _address

    from ._smallqr import householder_qr, reflect_rows, reflect_vector, solve_upper

    def _external(name: str, nargs: int):
        symbol = f"sotpy_lapack_{name}"
        _llvm.add_symbol(symbol, _address("scipy.linalg.cython_lapack", name))
        return _t.ExternalFunction(symbol, _t.void(*([_t.voidptr] * nargs)))

    _dgeqp3 = _external("dgeqp3", 9)

    @_nb.njit(cache=True, nogil=True)
    def _geqp3(a, jpvt, tau, work, iw):  # pragma: no cover - compiled
        """Pivoted QR in place of the Fortran array ``a``; ``jpvt`` 1-based."""
        iw[0] = a.shape[0]
        iw[1] = a.shape[1]
        iw[2] = max(a.shape[0], 1)
        iw[3] = work.shape[0]
        jpvt[:] = 0
        _dgeqp3(
            iw[0:].ctypes, iw[1:].ctypes, a.ctypes, iw[2:].ctypes, jpvt.ctypes,
            tau.ctypes, work.ctypes, iw[3:].ctypes, iw[4:].ctypes,
        )  # fmt: skip
        return iw[4]

    @_nb.njit(cache=True, nogil=True)
    def _equality_stack(A, starts, blocks, fro, lams, rank_tol, last):  # pragma: no cover
        n = A.shape[1] - 1
        p = starts.shape[0] - 1
        ranks = np.zeros(p, dtype=np.int64)
        # W = [[Z, x], [0, 1]] (Fortran): Z = W[:n, c0:n], x = W[:n, n]
        W = np.asfortranarray(np.eye(n + 1))
        c0 = 0
        nwork = 64 * (max(n, A.shape[0]) + 2)
        work = np.empty(nwork)
        iw = np.zeros(8, dtype=np.int32)
        jpvt = np.zeros(max(n, A.shape[0]), dtype=np.int32)
        tau = np.empty(max(n, 1))
        nokeep = np.empty((0, 0)).T  # (R not wanted)
        for b in range(blocks.shape[0]):
            k0 = blocks[b, 0]
            k1 = blocks[b, 1]
            nf = n - c0
            if nf == 0:
                break
            merged = k1 - k0 > 1
            for k in range(k0, k1):
                if lams[k] != 0.0:
                    merged = False  # the merge is exact only undamped
            if merged:
                s0, s1 = starts[k0], starts[k1]
                scale = fro[k0]
                for k in range(k0 + 1, k1):
                    scale = min(scale, fro[k])
                r = _step(A[s0:s1], W, c0, scale, rank_tol, 0.0, k1 - 1 != last, True,
                          work, iw, jpvt, tau, nokeep)  # fmt: skip
                if r >= 0:
                    for k in range(k0, k1):
                        ranks[k] = starts[k + 1] - starts[k]
                    c0 += r
                    continue
            for k in range(k0, k1):
                if n - c0 == 0:
                    break
                s0, s1 = starts[k], starts[k + 1]
                if s1 == s0:
                    continue
                r = _step(A[s0:s1], W, c0, fro[k], rank_tol, lams[k], k != last, False,
                          work, iw, jpvt, tau, nokeep)  # fmt: skip
                ranks[k] = r
                if k != last:
                    c0 += r
        return W[:n, n].copy(), ranks

    @_nb.njit(cache=True, nogil=True)
    def _step(
        rows, W, c0, scale, rank_tol, lam, need, full_only, work, iw, jpvt, tau, keep
    ):  # pragma: no cover
        """One step of :meth:`NullspaceStepper.step` on ``W`` (see there). Returns the
        rank, or -1 (nothing changed) when ``full_only`` and the rank is short. The
        caller advances ``c0`` by the rank when ``need``. When the rank is the number
        of rows ``m`` and ``keep`` has room, its leading ``m x m`` block receives the
        pivoted QR's ``R`` (``jpvt[:m]`` its permutation), as ``last_qr`` does."""
        m = rows.shape[0]
        n = W.shape[0] - 1
        nf = n - c0
        # [A Z | A x - b]; before any step (Z = I, x = 0) the rows themselves, copied:
        # LAPACK overwrites views of maug below. The product takes the columns c0: of W
        # only, through a view numba knows to be Fortran-contiguous (one BLAS call)
        maug = rows.copy() if c0 == 0 else rows @ W.T[c0:].T
        thr = rank_tol * scale
        if not need and not full_only and m > nf and lam == 0.0:
            # least squares from a pivoted QR of M itself
            qr = np.asfortranarray(maug[:, :nf])
            if _geqp3(qr, jpvt[:nf], tau[:nf], work, iw) == 0 and abs(qr[nf - 1, nf - 1]) > thr:
                y = maug[:, nf].copy()
                reflect_vector(qr, tau, nf, y, True)  # Q^T (b - A x)
                solve_upper(qr, nf, y, False)
                v = np.zeros(nf)
                for i in range(nf):
                    v[jpvt[i] - 1] = y[i]
                W[:, n] -= v @ W.T[c0:n]  # W[:, c0:n] @ v, C-contiguous operands
                return nf
        qr = np.asfortranarray(maug[:, :nf].T)  # nf x m
        kmax = min(m, nf)
        _geqp3(qr, jpvt[:m], tau[:kmax], work, iw)
        r = 0
        for i in range(kmax):
            if abs(qr[i, i]) > thr:  # as the NumPy code: every |R_ii| above thr
                r += 1
        if full_only and r < m:
            return -1
        if r == 0:
            return 0
        if r == m and keep.shape[0] >= m:
            for j in range(m):
                for i in range(j + 1):
                    keep[i, j] = qr[i, j]
        ep = np.empty(m)
        for i in range(m):
            ep[i] = maug[jpvt[i] - 1, nf]
        if r == m and lam == 0.0:
            z = ep
            solve_upper(qr, m, z, True)  # R^T z = ep
        else:
            rows_ls = m + r if lam > 0.0 else m
            L = np.zeros((rows_ls, r), dtype=np.float64).T.copy().T  # Fortran
            for j in range(r):
                for i in range(j, m):
                    L[i, j] = qr[j, i]  # L = R[:r, :m]^T (lower trapezoidal)
            rhs = np.zeros(max(rows_ls, r))
            rhs[:m] = ep
            if lam > 0.0:
                for j in range(r):
                    L[m + j, j] = lam
            tl = np.empty(r)  # least squares by a QR of L (full column rank)
            householder_qr(L, tl)
            reflect_vector(L, tl, r, rhs, True)
            solve_upper(L, r, rhs, False)
            z = rhs[:r].copy()
        if need and c0 == 0:
            # W = I (no step yet): Z Q = Q, of which only the null-space columns
            # Q[:, r:] = Q [0; I] are used from now on: the columns r: of W, which
            # hold [0; I] (a left product on n - r columns instead of a right one on n),
            # formed in C order (the reflections run along its rows) and copied in
            q0 = np.zeros((n, n - r))
            for j in range(n - r):
                q0[r + j, j] = 1.0
            reflect_rows(qr, tau, kmax, q0, work, False)
            W.T[r:n, :n] = q0.T
            v = np.zeros(nf)
            v[:r] = z[:r]
            reflect_vector(qr, tau, kmax, v, False)
            for i in range(n):  # x = 0 - Q [z; 0]
                W[i, n] = -v[i]
        elif need:
            # Z Q: (Z Q)^T = Q^T Z^T, and Z^T is the C-order view W.T[c0:n]
            reflect_rows(qr, tau, kmax, W.T[c0:n], work, True)
            W[:, n] -= z[:r] @ W.T[c0 : c0 + r]
        else:
            v = np.zeros(nf)
            v[:r] = z[:r]
            reflect_vector(qr, tau, kmax, v, False)
            W[:, n] -= v @ W.T[c0:n]
        return r

    @_nb.njit(cache=True, nogil=True)
    def _equality_all(A, starts, blocks, lams, rank_tol, last):  # pragma: no cover
        """The whole equality path: the Frobenius norm of each level (its rank scale),
        the recursion, the residual ``||A_k x - b_k||`` of each level and the next plan
        of blocks (runs of undamped full-rank levels, as ``hierarchy._plan_blocks``).
        Returns ``(status, x, ranks, fro, res, plan, xnorm)``: ``status``
        :data:`SOLVED`, :data:`NONFINITE_MATRIX` (nothing solved) or
        :data:`NONFINITE_RESULT` (``x`` or a residual overflowed); ``xnorm`` is
        ``||x||_2``."""
        n = A.shape[1] - 1
        p = starts.shape[0] - 1
        fro, finite = _level_norms(A, starts)
        if not finite:
            return NONFINITE_MATRIX, np.zeros(n), np.zeros(p, dtype=np.int64), fro, fro, blocks, 0.0
        x, ranks = _equality_stack(A, starts, blocks, fro, lams, rank_tol, last)
        x_aug = np.ones(n + 1)
        x_aug[:n] = x
        res = _residuals(A, x_aug, starts, fro, fro, False)  # (bounds unused: equalities)
        acc = 0.0
        for i in range(n):
            acc += x[i] * x[i]
        xnorm = np.sqrt(acc)
        status = SOLVED if np.isfinite(xnorm + res.sum()) else NONFINITE_RESULT
        plan = np.zeros((p, 2), dtype=np.int64)
        nb = 0
        run = -1
        for k in range(p):
            m = starts[k + 1] - starts[k]
            if m == 0:
                if run >= 0:
                    plan[nb, 0] = run
                    plan[nb, 1] = k
                    nb += 1
                    run = -1
                continue
            if ranks[k] == m and lams[k] == 0.0:
                if run < 0:
                    run = k
                continue
            if run >= 0:
                plan[nb, 0] = run
                plan[nb, 1] = k
                nb += 1
                run = -1
            plan[nb, 0] = k
            plan[nb, 1] = k + 1
            nb += 1
        if run >= 0:
            plan[nb, 0] = run
            plan[nb, 1] = p
            nb += 1
        return status, x, ranks, fro, res, plan[:nb].copy(), xnorm

    @_nb.njit(cache=True, nogil=True)
    def _box_steps(
        A, starts, blocks, fro, rank_tol, last, fixed, values, s, dual_tol
    ):  # pragma: no cover - compiled
        """:meth:`HierarchySolver._box_steps` with its :class:`._boxset.DualCheck`, in
        one call: from ``x_fixed = values`` (``Z`` the free unit vectors, as
        :meth:`NullspaceStepper.fix`), the undamped recursion over the equality rows
        ``A`` (levels ``starts``, ``blocks`` of levels stepped together when of full
        row rank), each level judging the bounds still undecided (``s_i != 0``: the
        direction into the box) and carrying their release directions into its null
        space; then the minimum-norm criterion at the point (``DualCheck.finish``).

        Returns ``(x, ranks, failed, worst)``: ``worst`` the position in ``fixed`` of
        the bound to release when ``failed``."""
        n = A.shape[1] - 1
        p = starts.shape[0] - 1
        ranks = np.zeros(p, dtype=np.int64)
        k = fixed.shape[0]
        W = np.zeros((n + 1, n + 1)).T  # Fortran; W = [[Z, x], [0, 1]]
        held = np.zeros(n, dtype=np.bool_)
        for i in range(k):
            held[fixed[i]] = True
            W[fixed[i], n] = values[i]
        col = k
        for j in range(n):
            if not held[j]:
                W[j, col] = 1.0
                col += 1
        W[n, n] = 1.0
        c0 = k
        # the undecided bounds: their positions in `fixed`, their release directions
        u = 0
        for i in range(k):
            if s[i] != 0.0:
                u += 1
        idx = np.empty(u, dtype=np.int64)
        D = np.zeros((n, u))
        a = 0
        for i in range(k):
            if s[i] != 0.0:
                idx[a] = i
                D[fixed[i], a] = s[i]
                a += 1
        alive = np.ones(u, dtype=np.bool_)
        state = np.array([0, -1], dtype=np.int64)  # failed, worst
        m_all = A.shape[0]
        work = np.empty(64 * (max(n, m_all) + 2))
        iw = np.zeros(8, dtype=np.int32)
        jpvt = np.zeros(max(n, m_all, 1), dtype=np.int32)
        tau = np.empty(max(n, 1))
        keep = np.zeros((max(m_all, 1), max(m_all, 1))).T
        for b in range(blocks.shape[0]):
            k0 = blocks[b, 0]
            k1 = blocks[b, 1]
            if k1 - k0 > 1:
                judge = state[0] == 0 and alive.any()
                s0, s1 = starts[k0], starts[k1]
                scale = fro[k0]
                for kk in range(k0 + 1, k1):
                    scale = min(scale, fro[kk])
                need = k1 - 1 != last
                r = -1
                if n - c0 > 0 and s1 > s0:
                    r = _step(A[s0:s1], W, c0, scale, rank_tol, 0.0, need, True,
                              work, iw, jpvt, tau, keep)  # fmt: skip
                if r >= 0:
                    if judge:
                        _dual_level(A[s0:s1], W, c0, r if need else -1, keep, jpvt, D,
                                    alive, idx, state, dual_tol)  # fmt: skip
                    for kk in range(k0, k1):
                        ranks[kk] = starts[kk + 1] - starts[kk]
                    if need:
                        c0 += r
                    continue
            for kk in range(k0, k1):
                s0, s1 = starts[kk], starts[kk + 1]
                judge = state[0] == 0 and alive.any()
                need = kk != last
                r = 0
                if n - c0 > 0 and s1 > s0:
                    r = _step(A[s0:s1], W, c0, fro[kk], rank_tol, 0.0, need, False,
                              work, iw, jpvt, tau, keep)  # fmt: skip
                ranks[kk] = r
                if judge:
                    _dual_level(A[s0:s1], W, c0, r if need else -1, keep, jpvt, D, alive,
                                idx, state, dual_tol)  # fmt: skip
                if need:
                    c0 += r
        x = W[:n, n].copy()
        if state[0] == 0 and alive.any():  # DualCheck.finish: x^T d >= 0
            xx = 0.0
            for j in range(n):
                xx += x[j] * x[j]
            dd = 0.0
            best = np.inf
            at = -1
            for a in range(u):
                if not alive[a]:
                    continue
                acc = 0.0
                for j in range(n):
                    acc += x[j] * D[j, a]
                    dd += D[j, a] * D[j, a]
                if acc < best:
                    best = acc
                    at = a
            if best < -dual_tol * (1.0 + np.sqrt(xx * dd)):
                state[0] = 1
                state[1] = idx[at]
        return x, ranks, state[0] == 1, state[1]

    @_nb.njit(cache=True, nogil=True)
    def _dual_level(
        rows, W, c0, rank, keep, jpvt, D, alive, idx, state, dual_tol
    ):  # pragma: no cover - compiled
        """:meth:`._boxset.DualCheck.level` on the columns of ``D`` still ``alive``;
        ``W[:n, c0:n]`` is the basis the level was solved in (its first ``rank``
        columns ``Y = Z Q_r`` when ``rank`` is the number of rows, ``R`` then in
        ``keep``); ``state`` = (failed, worst)."""
        n = W.shape[0] - 1
        m = rows.shape[0]
        cols = np.flatnonzero(alive)
        ua = cols.shape[0]
        T = np.zeros((m, ua))
        tt = 0.0
        for i in range(m):
            for a in range(ua):
                acc = 0.0
                for j in range(n):
                    acc += rows[i, j] * D[j, cols[a]]
                T[i, a] = acc
                tt += acc * acc
        if tt == 0.0:
            return  # the level does not see these variables
        res = np.empty(m)  # A x - b
        rr = 0.0
        for i in range(m):
            acc = rows[i, n]
            for j in range(n):
                acc += rows[i, j] * W[j, n]
            res[i] = acc
            rr += acc * acc
        tol = dual_tol * (1.0 + np.sqrt(rr * tt))
        delta = np.zeros(ua)
        for a in range(ua):
            for i in range(m):
                delta[a] += res[i] * T[i, a]
        at = np.argmin(delta)
        if delta[at] < -tol:
            state[0] = 1
            state[1] = idx[cols[at]]
            return
        keepc = np.zeros(ua, dtype=np.bool_)
        for a in range(ua):
            if delta[a] > tol:  # decided
                alive[cols[a]] = False
            else:
                keepc[a] = True
        left = np.flatnonzero(keepc)
        if left.shape[0] == 0:
            return
        cols = cols[left]
        T = np.ascontiguousarray(T[:, left])
        ul = cols.shape[0]
        if rank == m and rank > 0:
            # R^T C = P^T T (forward substitution), then D -= Y C
            C = np.empty((m, ul))
            for i in range(m):
                for a in range(ul):
                    acc = T[jpvt[i] - 1, a]
                    for h in range(i):
                        acc -= keep[h, i] * C[h, a]
                    C[i, a] = acc / keep[i, i]
            for j in range(n):
                for a in range(ul):
                    acc = 0.0
                    for i in range(rank):
                        acc += W[j, c0 + i] * C[i, a]
                    D[j, cols[a]] -= acc
            return
        nb = n - c0
        if nb == 0:
            for a in range(ul):
                alive[cols[a]] = False  # nothing compensates: blocked
            return
        B = np.ascontiguousarray(W[:n, c0:n])
        AB = np.ascontiguousarray(rows[:, :n]) @ B
        C = np.linalg.lstsq(AB, T, rcond=2.220446049250313e-16 * max(m, nb))[0]
        miss = T - AB @ C
        for a in range(ul):
            mn = 0.0
            tn = 0.0
            for i in range(m):
                mn += miss[i, a] * miss[i, a]
                tn += T[i, a] * T[i, a]
            if np.sqrt(mn) > 1e-9 * (1.0 + np.sqrt(tn)):
                alive[cols[a]] = False  # blocked: no carry
            else:
                for j in range(n):
                    acc = 0.0
                    for i in range(nb):
                        acc += B[j, i] * C[i, a]
                    D[j, cols[a]] -= acc

    # The two reductions below may sum in any order (``reassoc``: the loops over a row
    # vectorize, twice as fast). Only the rounding of a norm changes; NaN and inf
    # propagate as in any order (no ``nnan``/``ninf``), and every caller gets the same
    # kernel, so lanes and usual paths still agree bit for bit.
    @_nb.njit(cache=True, nogil=True, fastmath={"reassoc"})
    def _level_norms(A, starts):  # pragma: no cover - compiled
        """The Frobenius norm of each level's matrix (rows ``starts[k]:starts[k + 1]``
        of ``A[:, :n]``, the last column being the targets) and whether all are
        finite."""
        n = A.shape[1] - 1
        p = starts.shape[0] - 1
        fro = np.zeros(p)
        total = 0.0
        for k in range(p):
            acc = 0.0
            for i in range(starts[k], starts[k + 1]):
                row = A[i]
                s = 0.0
                for j in range(n):
                    s += row[j] * row[j]
                acc += s
            fro[k] = np.sqrt(acc)
            total += acc
        return fro, np.isfinite(total)

    @_nb.njit(cache=True, nogil=True, fastmath={"reassoc"})
    def _residuals(A, x_aug, starts, rlo, rup, general):  # pragma: no cover - compiled
        """Each level's ``||A_k x - b_k||`` (rows ``[A | -b]``), or with ``general`` its
        violation ``||max(rlo - v, 0) + max(v - rup, 0)||`` with ``v = [A | -ref] x_aug``
        (the solver's bounds relative to ``ref``)."""
        p = starts.shape[0] - 1
        w = A.shape[1]
        res = np.zeros(p)
        for k in range(p):
            acc = 0.0
            for i in range(starts[k], starts[k + 1]):
                row = A[i]
                v = 0.0
                for j in range(w):
                    v += row[j] * x_aug[j]
                if general:
                    below = rlo[i] - v
                    above = v - rup[i]
                    e = 0.0
                    if below > 0.0:
                        e += below
                    if above > 0.0:
                        e += above
                    if below != below or above != above:  # NaN (as np.maximum): the
                        e = np.nan  # caller's finiteness test reports it
                    v = e
                acc += v * v
            res[k] = np.sqrt(acc)
        return res

    @_nb.njit(cache=True, nogil=True)
    def _box_update(A, m, n, cols, coef, lo, hi, blo, bhi, at_lo, at_hi):  # pragma: no cover
        """:meth:`._boxset.BoxActiveSet.set_box` when the box's structure is the
        remembered one (row ``i`` of ``A[:m, :n]`` has its only nonzero, ``coef[i]``, in
        column ``cols[i]``): the bounds ``blo <= x <= bhi`` and the remembered active
        set updated in place. ``False`` (nothing changed) when the structure differs."""
        for i in range(m):
            for j in range(n):
                a = A[i, j]
                if j == cols[i]:
                    if a != coef[i]:
                        return False
                elif a != 0.0:
                    return False
        blo[:] = -np.inf
        bhi[:] = np.inf
        for i in range(m):
            c = coef[i]
            j = cols[i]
            if c < 0.0:
                blo[j] = hi[i] / c
                bhi[j] = lo[i] / c
            else:
                blo[j] = lo[i] / c
                bhi[j] = hi[i] / c
        for j in range(n):
            if not np.isfinite(blo[j]):
                at_lo[j] = False
            if not np.isfinite(bhi[j]):
                at_hi[j] = False
            if blo[j] == bhi[j]:  # equal bounds fix x_j
                at_lo[j] = True
                at_hi[j] = False
        return True

    @_nb.njit(cache=True, nogil=True)
    def _bounds_prepare(A, lo, up, ref, rlo, rup, d, eqmask, starts):  # pragma: no cover
        """The general path's bookkeeping of :meth:`HierarchySolver._prepare` in one
        pass: ``ref`` (each row's lower bound if finite, else its upper one, else 0),
        ``A[:, n] = -ref``, ``rlo = lo - ref``, ``rup = up - ref``, ``d = up - lo``,
        the equality mask (``d == 0``) updated in place, and each level's Frobenius
        norm. Returns ``(fro, finite, bounds_ok, changed)``: the matrices finite, every
        ``d >= 0`` (no NaN), the mask changed."""
        return _bounds(A, lo, up, ref, rlo, rup, d, eqmask, starts, True)

    @_nb.njit(cache=True, nogil=True)
    def _bounds(A, lo, up, ref, rlo, rup, d, eqmask, starts, commit):  # pragma: no cover
        """:func:`_bounds_prepare`; the mask is written only with ``commit`` (else
        ``changed`` says whether it would change)."""
        m = A.shape[0]
        n = A.shape[1] - 1
        ok = True
        changed = False
        for i in range(m):
            lo_i = lo[i]
            up_i = up[i]
            if np.isfinite(lo_i):
                r = lo_i
            elif np.isfinite(up_i):
                r = up_i
            else:
                r = 0.0
            ref[i] = r
            A[i, n] = -r
            rlo[i] = lo_i - r
            rup[i] = up_i - r
            di = up_i - lo_i
            d[i] = di
            if not di >= 0.0:
                ok = False
            e = di == 0.0
            if e != eqmask[i]:
                if commit:
                    eqmask[i] = e
                changed = True
        fro, finite = _level_norms(A, starts)
        return fro, finite, ok, changed

    equality_stack = _equality_stack
    equality_all = _equality_all
    box_steps = _box_steps
    bounds_prepare = _bounds_prepare
    residuals = _residuals
    box_update = _box_update
