r"""The box path of the SOT's usual stack as one compiled call (internal to
``sotpy.solvers``).

The stack an SOT solves at most ticks is a box (the joint limits) above equality levels
whose upper levels are met exactly and whose last level (the posture) is a least-squares
fit, or whose levels are all met exactly. :func:`box_kkt` runs the whole active-set
iteration of :mod:`._boxset` for that shape in one call: fix the variables guessed at a
bound, solve, check the bounds and the multipliers, correct the guess, repeat; the
residual of every level last. It answers only when it can prove the answer, else it
returns a status and the caller runs the general NumPy path from the corrected guess.

The solve, with ``F`` the free variables (``W`` the fixed ones, at their bound values),
``U`` the upper levels' rows and ``L`` the last level's, restricted to ``F`` (the fixed
variables moved to the right-hand sides ``d`` and ``c``):

.. math::

    \min_{x_F} \tfrac12 \|L x_F - c\|^2 \quad \text{s.t.} \quad U x_F = d

by the null-space method: ``U^T = Q [R; 0]`` (``dgeqrf``), ``x_F = Q [y_1; y_2]`` with
``R^T y_1 = d`` and ``y_2`` the least-squares solution of ``(L Q_2) y_2 = c - L Q_1 y_1``
(``dgeqrf`` of ``L Q_2``; ``L Q`` by ``dormqr``). When every level fits in the free
directions (``m_U + m_L <= |F|``) all of them go into ``U`` and the point is the
minimum-norm solution ``x_F = Q_1 R^{-T} d``. Either way the answer is the unique
lexicographic optimum with ``W`` fixed when ``R`` (``U`` of full row rank) and ``L Q_2``
(``L`` of full column rank on the null space of ``U``) are well conditioned; the call is
refused otherwise (the null-space recursion's rank threshold decides then). The
conditions, with LAPACK's 1-norm estimate ``dtrcon``: ``rcond(R) >= RCOND_MIN`` and
``rcond(L Q_2)^2 >= RCOND_MIN`` (the reduced Hessian ``(L Q_2)^T (L Q_2)`` is what the
one-system KKT solve of :mod:`._kkt` conditions on), with :data:`._kkt.RCOND_MIN`. The
same solve, on rows given apart, is the compiled KKT solve of :mod:`._kkt`
(:func:`kkt`).

The SOT's last level is usually a posture: rows of the identity on joint variables
(:func:`_posture_columns` recognises them). Then, with ``P`` the free variables with a
posture row and ``N`` the others (the free flyer), the same optimum costs a fraction of
the flops, by :func:`_posture_solve`:

.. math::

    U_N = Q_N \begin{bmatrix} R_N \\ 0 \end{bmatrix},\quad
    Q_N^T [U_P \mid d] = \begin{bmatrix} S & d_1 \\ M & e \end{bmatrix},\quad
    x_P = c + M^T \nu,\ M M^T \nu = e - M c,\quad
    R_N x_N = d_1 - S x_P,\quad \mu_U = -Q_N \begin{bmatrix} 0 \\ \nu \end{bmatrix}

(``M M^T`` through the QR ``M^T = Q_M R_M``: ``x_P = c + Q_M R_M^{-T} (e - M c)``).
``N`` may be empty (a fixed base: ``Q_N = I``) and so may ``M`` (the upper rows only
fix ``x_N``, one foot: ``x_P = c``). The split also gives the point when every level
is met with as many rows as free variables and nothing fixed (then that point is the
only one and no multiplier is needed). ``U_N`` of full column rank is ``L Q_2`` of full
column rank, and ``M`` of full row rank is ``U`` of full row rank; the split answers
when ``rcond(R_N)^2 >= RCOND_MIN`` and ``rcond(R_M) >= RCOND_MIN``, the same pair of
conditions, and else leaves the iteration to the general solve (so the call refuses no
shape it answered before). For Talos (17 upper rows, 6 free-flyer and 31 free joint
variables) that is two QR of 17 x 6 and 31 x 11 and one ``Q_N^T`` applied to 17 x 32,
against the general solve's QR of 37 x 17 and ``L Q`` of 32 x 37. At these sizes the
split does its QRs, products, triangular solves and condition numbers with
:mod:`._smallqr` rather than LAPACK (whose fixed cost per call dominates there); its
``rcond`` is the exact 1-norm one, from the small triangle's inverse, never above
``dtrcon``'s estimate, so the split refuses a little sooner, never later. The general
solve, whose QR reaches 38 x 32 (a posture alone, minimum norm), stays on LAPACK's
blocked kernels, faster there.

The multipliers: with ``g`` the gradient of the last objective at ``x`` (``L^T (L x -
c)``, or ``x`` for the minimum norm), ``U_F^T \mu_U = -g_F`` gives ``\mu_U = -R^{-1}
(Q^T g_F)_{1..m_U}`` and the fixed variables' rows ``\mu_W = -(g_W + U_W^T \mu_U)``;
releasing bound ``j`` changes the last objective at the rate ``-s_j \mu_j`` (``s_j`` the
direction into the box), exactly as in :func:`._kkt.kkt_solve`.
"""

from __future__ import annotations

import numpy as np

from .._jit import ENABLED

box_kkt = None
lane = None
free_lane = None
kkt = None
_compiled = None  # the kernel itself (box_kkt may be wrapped, e.g. by a test's spy)
_warm: list[bool] = []

#: :func:`box_kkt`'s statuses; :func:`lane` and :func:`free_lane` also answer ``LEFT``
#: (nothing decided)
OK, REFUSED, UNDECIDED, NOT_CONVERGED, LEFT = 0, 1, 2, 3, 4


if ENABLED:  # pragma: no branch - the environment decides
    import numba as _nb

    from ._eqkernel import _bounds, _box_update, _equality_stack, _external, _residuals
    from ._smallqr import householder_qr, rcond_upper, reflect_rows, reflect_vector, solve_upper

    _dgeqrf = _external("dgeqrf", 8)
    _dormqr = _external("dormqr", 13)
    _dtrtrs = _external("dtrtrs", 10)
    _dtrcon = _external("dtrcon", 10)
    _R, _L, _N, _T, _U, _O = ord("R"), ord("L"), ord("N"), ord("T"), ord("U"), ord("1")

    @_nb.njit(cache=True, nogil=True)
    def _geqrf(a, tau, work, iw):  # pragma: no cover - compiled
        """QR in place of the Fortran array ``a`` (no pivoting)."""
        iw[0] = a.shape[0]
        iw[1] = a.shape[1]
        iw[2] = max(a.shape[0], 1)
        iw[3] = work.shape[0]
        _dgeqrf(
            iw[0:].ctypes, iw[1:].ctypes, a.ctypes, iw[2:].ctypes, tau.ctypes,
            work.ctypes, iw[3:].ctypes, iw[4:].ctypes,
        )  # fmt: skip
        return iw[4]

    @_nb.njit(cache=True, nogil=True)
    def _rcond_upper(a, k, work, iwork, iw, ch):  # pragma: no cover - compiled
        """Reciprocal condition number (1-norm estimate) of the upper triangle of the
        leading ``k x k`` block of the Fortran array ``a``."""
        ch[0] = _O
        ch[1] = ord("U")
        ch[2] = _N
        iw[0] = k
        iw[1] = max(a.shape[0], 1)
        rc = np.zeros(1)
        _dtrcon(
            ch[0:].ctypes, ch[1:].ctypes, ch[2:].ctypes, iw[0:].ctypes, a.ctypes,
            iw[1:].ctypes, rc.ctypes, work.ctypes, iwork.ctypes, iw[2:].ctypes,
        )  # fmt: skip
        if iw[2] != 0:
            return 0.0
        return rc[0]

    @_nb.njit(cache=True, nogil=True)
    def _ormqr(side, trans, refl, k, tau, c, work, iw, ch):  # pragma: no cover
        """``c <- op(Q) c`` or ``c op(Q)`` (Fortran ``c``), ``Q`` from ``k`` reflectors
        in the columns of the Fortran array ``refl``."""
        ch[0] = side
        ch[1] = trans
        iw[0] = c.shape[0]
        iw[1] = c.shape[1]
        iw[2] = k
        iw[3] = max(refl.shape[0], 1)
        iw[5] = max(c.shape[0], 1)
        iw[6] = work.shape[0]
        _dormqr(
            ch[0:].ctypes, ch[1:].ctypes, iw[0:].ctypes, iw[1:].ctypes, iw[2:].ctypes,
            refl.ctypes, iw[3:].ctypes, tau.ctypes, c.ctypes, iw[5:].ctypes,
            work.ctypes, iw[6:].ctypes, iw[7:].ctypes,
        )  # fmt: skip
        return iw[7]

    @_nb.njit(cache=True, nogil=True)
    def _trtrs_upper(a, n, trans, b, iw, ch):  # pragma: no cover
        """``op(U) z = b`` in place of ``b`` (length ``n``), ``U`` the upper triangle of
        the leading ``n x n`` block of the Fortran array ``a``."""
        ch[0] = _U
        ch[1] = trans
        ch[2] = _N
        iw[0] = n
        iw[1] = 1
        iw[2] = max(a.shape[0], 1)
        iw[3] = max(n, 1)
        _dtrtrs(
            ch[0:].ctypes, ch[1:].ctypes, ch[2:].ctypes, iw[0:].ctypes, iw[1:].ctypes,
            a.ctypes, iw[2:].ctypes, b.ctypes, iw[3:].ctypes, iw[4:].ctypes,
        )  # fmt: skip
        return iw[4]

    @_nb.njit(cache=True, nogil=True)
    def _posture_columns(A, split):  # pragma: no cover - compiled
        """The column of each last-level row when the last level is posture-shaped
        (each row of ``A[split:, :n]`` a single 1 in its own column), indexed by
        column (``-1`` for a column without a row); an empty array otherwise."""
        m = A.shape[0]
        n = A.shape[1] - 1
        row_of = np.full(n, -1, dtype=np.int64)
        none = np.empty(0, dtype=np.int64)
        for row in range(split, m):
            col = -1
            for j in range(n):
                a = A[row, j]
                if a == 0.0:
                    continue
                if a != 1.0 or col >= 0:
                    return none
                col = j
            if col < 0 or row_of[col] >= 0:
                return none
            row_of[col] = row
        return row_of

    @_nb.njit(cache=True, nogil=True)
    def _posture_solve(A, s1, mu_, row_of, W, vals, F, x_aug, muU, rcond_min):  # pragma: no cover
        """The last level a posture (see :func:`_posture_columns`): the solve and the
        upper rows' multipliers of the module doc by the split of the free variables
        into ``P`` (a posture row each) and ``N`` (none; may be empty, then ``Q_N =
        I``). ``M`` may be empty (the upper rows only fix ``x_N``: ``x_P = c``, no
        multiplier). ``False`` (nothing written) when the split does not apply (more
        ``N`` variables than upper rows, more ``M`` rows than ``P`` variables) or is
        ill-conditioned."""
        n = A.shape[1] - 1
        w = W.shape[0]
        nf = F.shape[0]
        nN = 0
        for i in range(nf):
            if row_of[F[i]] < 0:
                nN += 1
        nP = nf - nN
        mM = mu_ - nN
        if mM < 0 or mM > nP:
            return False
        N = np.empty(nN, dtype=np.int64)
        P = np.empty(nP, dtype=np.int64)
        a = 0
        b = 0
        for i in range(nf):
            if row_of[F[i]] < 0:
                N[a] = F[i]
                a += 1
            else:
                P[b] = F[i]
                b += 1
        # U_N (Fortran), [U_P | d] (C order: Q_N^T runs along its rows), d = b_U - U_W x_W
        UN = np.empty((nN, mu_)).T
        UP = np.empty((mu_, nP + 1))
        for r in range(mu_):
            row = s1 + r
            acc = -A[row, n]
            for i in range(w):
                acc -= A[row, W[i]] * vals[i]
            UP[r, nP] = acc
            for i in range(nN):
                UN[r, i] = A[row, N[i]]
            for i in range(nP):
                UP[r, i] = A[row, P[i]]
        # the small QRs and their uses by :mod:`._smallqr` (no LAPACK call: see there)
        tauN = np.empty(max(nN, 1))
        if nN > 0:
            householder_qr(UN, tauN)
            rc = rcond_upper(UN, nN)
            if not rc * rc >= rcond_min:
                return False
            reflect_rows(UN, tauN, nN, UP, np.empty(nP + 1), True)  # Q_N^T [U_P | d]
        c = np.empty(nP)
        for i in range(nP):
            c[i] = -A[row_of[P[i]], n]
        t = np.zeros(max(mM, 1))
        z = np.zeros(nP)  # x_P - c = M^T nu
        if mM > 0:
            # M^T (Fortran) from the rows of Q_N^T U_P below R_N; t = e - M c
            Mt = np.empty((mM, nP)).T
            for r in range(mM):
                acc = UP[nN + r, nP]
                for i in range(nP):
                    v = UP[nN + r, i]
                    Mt[i, r] = v
                    acc -= v * c[i]
                t[r] = acc
            tauM = np.empty(mM)
            householder_qr(Mt, tauM)
            if not rcond_upper(Mt, mM) >= rcond_min:
                return False
            solve_upper(Mt, mM, t, True)  # R_M^T t' = t
            z[:mM] = t[:mM]
            reflect_vector(Mt, tauM, mM, z, False)  # Q_M [t'; 0]
            solve_upper(Mt, mM, t, False)  # R_M nu = t'
        for i in range(nP):
            x_aug[P[i]] = c[i] + z[i]
        # x_N from R_N x_N = (Q_N^T d)_N - (Q_N^T U_P)_N x_P
        if nN > 0:
            xN = np.empty(nN)
            for r in range(nN):
                acc = UP[r, nP]
                for i in range(nP):
                    acc -= UP[r, i] * x_aug[P[i]]
                xN[r] = acc
            solve_upper(UN, nN, xN, False)
            for i in range(nN):
                x_aug[N[i]] = xN[i]
        for i in range(w):
            x_aug[W[i]] = vals[i]
        # mu_U = -Q_N [0; nu]
        h = np.zeros(mu_)
        for r in range(mM):
            h[nN + r] = t[r]
        if nN > 0 and mM > 0:
            reflect_vector(UN, tauN, nN, h, False)
        for r in range(mu_):
            muU[r] = -h[r]
        return True

    @_nb.njit(cache=True, nogil=True)
    def _gradient(A, split, minnorm, x_aug, g):  # pragma: no cover - compiled
        """``g`` <- the gradient of the last objective at ``x``: ``x`` for the minimum
        norm, else ``L^T (L x - c)`` over the rows ``[split, m)`` of ``[L | -c]``."""
        m = A.shape[0]
        n = A.shape[1] - 1
        if minnorm:
            g[:] = x_aug[:n]
            return
        g[:] = 0.0
        for row in range(split, m):
            e = 0.0
            for j in range(n + 1):
                e += A[row, j] * x_aug[j]
            for j in range(n):
                g[j] += e * A[row, j]

    @_nb.njit(cache=True, nogil=True)
    def _lapack_scratch(n, m):  # pragma: no cover - compiled
        """The workspaces of :func:`_general_solve`'s LAPACK calls (``n`` variables,
        ``m`` rows)."""
        return (
            np.empty(64 * (n + m + 2)),
            np.empty(max(n, 1), dtype=np.int32),
            np.zeros(8, dtype=np.int32),
            np.zeros(3, dtype=np.uint8),
        )

    @_nb.njit(cache=True, nogil=True)
    def _general_solve(
        A, s1, split, mu_, ml, minnorm, W, vals, F, x_aug, g, muU,
        rcond_min, work, iwork, iw, ch,
    ):  # fmt: skip  # pragma: no cover - compiled
        """The solve of the module doc for any last level (or the minimum norm when
        ``minnorm``): ``x_aug``, the gradient ``g`` and the upper rows' multipliers
        ``muU`` written in place. ``False`` (refused) when ``R`` or ``L Q_2`` is
        ill-conditioned."""
        n = A.shape[1] - 1
        w = W.shape[0]
        nf = F.shape[0]
        # U_F^T (nf x m_U, Fortran) and d = b_U - U_W x_W
        Ut = np.empty((mu_, nf)).T
        y = np.zeros(nf)
        for r in range(mu_):
            row = s1 + r
            acc = -A[row, n]
            for i in range(w):
                acc -= A[row, W[i]] * vals[i]
            y[r] = acc
            for i in range(nf):
                Ut[i, r] = A[row, F[i]]
        kq = min(nf, mu_)
        tau = np.empty(max(kq, 1))
        if mu_ > 0:
            if _geqrf(Ut, tau[:kq], work, iw) != 0:
                return False
            if not _rcond_upper(Ut, mu_, work, iwork, iw, ch) >= rcond_min:
                return False
            y1 = y[:mu_]
            _trtrs_upper(Ut, mu_, _T, y1, iw, ch)  # R^T y_1 = d
        if not minnorm:
            k2 = nf - mu_
            # B = L_F (m_L x nf, Fortran) and c = b_L - L_W x_W
            B = np.empty((nf, ml)).T
            c = np.empty((1, ml)).T
            for r in range(ml):
                row = split + r
                acc = -A[row, n]
                for i in range(w):
                    acc -= A[row, W[i]] * vals[i]
                c[r, 0] = acc
                for i in range(nf):
                    B[r, i] = A[row, F[i]]
            if mu_ > 0:
                _ormqr(_R, _N, Ut, kq, tau[:kq], B, work, iw, ch)  # B <- L_F Q
            for r in range(ml):
                acc = c[r, 0]
                for i in range(mu_):
                    acc -= B[r, i] * y[i]
                c[r, 0] = acc
            if k2 > 0:
                B2 = np.asfortranarray(B[:, mu_:])
                tau2 = np.empty(k2)
                if _geqrf(B2, tau2, work, iw) != 0:
                    return False
                rc = _rcond_upper(B2, k2, work, iwork, iw, ch)
                if not rc * rc >= rcond_min:
                    return False
                _ormqr(_L, _T, B2, k2, tau2, c, work, iw, ch)  # c <- Q_2'^T c
                y2 = np.ascontiguousarray(c[:k2, 0])
                _trtrs_upper(B2, k2, _N, y2, iw, ch)
                y[mu_:] = y2
        # x_F = Q y
        z = np.empty((1, nf)).T
        z[:, 0] = y
        if mu_ > 0:
            _ormqr(_L, _N, Ut, kq, tau[:kq], z, work, iw, ch)
        for i in range(w):
            x_aug[W[i]] = vals[i]
        for i in range(nf):
            x_aug[F[i]] = z[i, 0]
        _gradient(A, split, minnorm, x_aug, g)
        if mu_ > 0:
            h = np.empty((1, nf)).T
            for i in range(nf):
                h[i, 0] = g[F[i]]
            _ormqr(_L, _T, Ut, kq, tau[:kq], h, work, iw, ch)
            mu = np.ascontiguousarray(h[:mu_, 0])
            _trtrs_upper(Ut, mu_, _N, mu, iw, ch)
            for r in range(mu_):
                muU[r] = -mu[r]
        return True

    @_nb.njit(cache=True, nogil=True)
    def _box_kkt(
        A,
        s1,
        split,
        starts,
        rlo,
        rup,
        blo,
        bhi,
        at_lo,
        at_hi,
        eps,
        rcond_min,
        dual_tol,
        max_iter,
    ):  # pragma: no cover - compiled
        """The box path's iteration (see the module doc), ``box_kkt`` when compiled.

        Args:
            A: the stacked augmented rows ``[A | -ref]`` (``m x (n + 1)``, C order):
                the box rows ``[0, s1)``, then equality rows (``-ref = -b``).
            s1: first row below the box; ``split``: first row of the last level.
            starts: level starts (int64), for the residuals; ``rlo``, ``rup``: the
                bounds relative to ``ref`` (the box rows' violation).
            blo, bhi: the box on the variables; ``at_lo``, ``at_hi``: the guess,
                corrected in place.
            eps: primal tolerance; ``rcond_min``: see the module doc; ``dual_tol``:
                relative zero of a multiplier; ``max_iter``: corrections allowed.

        Returns:
            ``(status, x_aug, residuals, minnorm, nf, m_upper, iterations)``: the
            status (:data:`OK`, :data:`REFUSED`, :data:`UNDECIDED`,
            :data:`NOT_CONVERGED`), the point ``[x; 1]``, each level's residual (with
            ``OK``), whether every level was met (minimum norm), the free variables and
            upper rows of the last solve, and the correction at which it stopped.
        """
        m = A.shape[0]
        n = A.shape[1] - 1
        x_aug = np.ones(n + 1)
        res = np.zeros(starts.shape[0] - 1)
        row_of = _posture_columns(A, split)
        for it in range(max_iter):
            w = 0
            for j in range(n):
                if at_lo[j] or at_hi[j]:
                    w += 1
            nf = n - w
            W = np.empty(w, dtype=np.int64)
            F = np.empty(nf, dtype=np.int64)
            vals = np.empty(w)
            s = np.empty(w)
            a = 0
            b = 0
            for j in range(n):
                if at_lo[j] or at_hi[j]:
                    W[a] = j
                    vals[a] = blo[j] if at_lo[j] else bhi[j]
                    s[a] = 0.0 if blo[j] == bhi[j] else (1.0 if at_lo[j] else -1.0)
                    a += 1
                else:
                    F[b] = j
                    b += 1
            minnorm = m - s1 <= nf
            u_end = m if minnorm else split
            mu_ = u_end - s1
            ml = m - u_end
            if mu_ > nf or (not minnorm and ml < nf - mu_):
                return REFUSED, x_aug, res, minnorm, nf, mu_, it
            muU = np.zeros(max(mu_, 1))
            g = np.empty(n)
            posture = False
            # the posture split: for the least-squares last level, or when every level
            # is met and nothing is fixed with as many rows as variables (the point is
            # then the only one; no multiplier is needed)
            mp = split - s1
            if row_of.shape[0] > 0 and mp > 0 and (not minnorm or (w == 0 and m - s1 == nf)):
                posture = _posture_solve(A, s1, mp, row_of, W, vals, F, x_aug, muU, rcond_min)
            if posture:
                _gradient(A, split, minnorm, x_aug, g)
            elif not _general_solve(  # (LAPACK's workspaces only on this branch)
                A, s1, split, mu_, ml, minnorm, W, vals, F, x_aug, g, muU,
                rcond_min, *_lapack_scratch(n, m),
            ):  # fmt: skip
                return REFUSED, x_aug, res, minnorm, nf, mu_, it
            release = -1
            if w > 0:
                muW = np.empty(w)
                big = 0.0
                for i in range(w):
                    acc = g[W[i]]
                    for r in range(mu_):
                        acc += A[s1 + r, W[i]] * muU[r]
                    muW[i] = -acc
                    big = max(big, abs(acc))
                tol = dual_tol * (1.0 + big)
                worst = np.inf
                for i in range(w):
                    if s[i] == 0.0:
                        continue
                    rate = -s[i] * muW[i]
                    if not abs(rate) > tol:  # a bound not pushed against (or NaN)
                        return UNDECIDED, x_aug, res, minnorm, nf, mu_, it
                    if rate < -tol and rate < worst:
                        worst = rate
                        release = i
            # the primal check first: a free variable out of its box joins the bounds
            crossed = False
            for j in range(n):
                if x_aug[j] < blo[j] - eps:
                    at_lo[j] = True
                    crossed = True
                elif x_aug[j] > bhi[j] + eps:
                    at_hi[j] = True
                    crossed = True
            if crossed:
                continue
            if release >= 0:
                at_lo[W[release]] = False
                at_hi[W[release]] = False
                continue
            res = _residuals(A, x_aug, starts, rlo, rup, True)
            return OK, x_aug, res, minnorm, nf, mu_, it
        return NOT_CONVERGED, x_aug, res, False, 0, 0, max_iter

    @_nb.njit(cache=True, nogil=True)
    def _lane(
        A, lo, up, ref, rlo, rup, d, eqmask, starts, cols, coef, blo, bhi, at_lo, at_hi,
        s1, split, eps, rcond_min, dual_tol, max_iter,
    ):  # pragma: no cover - compiled  # fmt: skip
        """The box path of a solve whose row classes and box structure are those of the
        previous call, which this kernel answered: the bookkeeping
        (:func:`._eqkernel._bounds`, the mask left as it is), the box
        (:func:`._eqkernel._box_update`) and :func:`_box_kkt`, in one call.

        Returns ``(status, x_aug, residuals, minnorm, nf, m_upper, iterations, fro,
        xnorm)`` as :func:`_box_kkt` with the level norms and ``||x||``. Anything else
        than a proven, finite answer is ``LEFT``, the guess ``at_lo``, ``at_hi`` not
        corrected (as the box reading leaves it, where the usual path starts): a
        non-finite entry, a bound pair out of order, a row that changes class, a box of
        another structure, a refusal, an undecided or unfinished correction. The caller
        then runs the usual path, which does the same work again and reports what is
        wrong.
        """
        n = A.shape[1] - 1
        x_aug = np.ones(n + 1)
        res = np.zeros(starts.shape[0] - 1)
        fro, finite, ok, changed = _bounds(A, lo, up, ref, rlo, rup, d, eqmask, starts, False)
        if not finite or not ok or changed or cols.shape[0] != s1:
            return LEFT, x_aug, res, False, 0, 0, 0, fro, 0.0
        if not _box_update(A, s1, n, cols, coef, lo, up, blo, bhi, at_lo, at_hi):
            return LEFT, x_aug, res, False, 0, 0, 0, fro, 0.0
        lo0 = at_lo.copy()
        hi0 = at_hi.copy()
        status, x_aug, res, minnorm, nf, m_upper, its = _box_kkt(
            A, s1, split, starts, rlo, rup, blo, bhi, at_lo, at_hi, eps, rcond_min, dual_tol,
            max_iter,
        )  # fmt: skip
        acc = 0.0
        for j in range(n):
            acc += x_aug[j] * x_aug[j]
        xnorm = np.sqrt(acc)
        if status != OK or not np.isfinite(xnorm + res.sum()):
            at_lo[:] = lo0
            at_hi[:] = hi0
            return LEFT, x_aug, res, False, 0, 0, 0, fro, 0.0
        return OK, x_aug, res, minnorm, nf, m_upper, its, fro, xnorm

    @_nb.njit(cache=True, nogil=True)
    def _free_lane(
        A, lo, up, ref, rlo, rup, d, eqmask, starts, cols, coef, blo, bhi, at_lo, at_hi,
        s1, eq_starts, blocks, rank_tol, eps, last,
    ):  # pragma: no cover - compiled  # fmt: skip
        """The box path of a solve with the row classes and box structure of the
        previous call, which the guess without a bound answered: the levels below the
        box by the equality recursion (any rank, :func:`._eqkernel._equality_stack` on
        the rows below the box, ``eq_starts`` their level starts, ``blocks`` the plan)
        and the point inside the box. One call with the bookkeeping and the box
        reading, as :func:`_lane`.

        Returns ``(status, x_aug, residuals, ranks, fro, xnorm)``: ``OK``, or ``LEFT``
        (nothing decided; the guess as the box reading leaves it): a non-finite entry, a
        bound pair out of order, a row that changes class, a box of another structure,
        a bound in the guess, a point out of the box, a non-finite point.
        """
        n = A.shape[1] - 1
        p = starts.shape[0] - 1
        x_aug = np.ones(n + 1)
        res = np.zeros(p)
        ranks = np.zeros(p, dtype=np.int64)
        fro, finite, ok, changed = _bounds(A, lo, up, ref, rlo, rup, d, eqmask, starts, False)
        if not finite or not ok or changed or cols.shape[0] != s1:
            return LEFT, x_aug, res, ranks, fro, 0.0
        if not _box_update(A, s1, n, cols, coef, lo, up, blo, bhi, at_lo, at_hi):
            return LEFT, x_aug, res, ranks, fro, 0.0
        for j in range(n):
            if at_lo[j] or at_hi[j]:
                return LEFT, x_aug, res, ranks, fro, 0.0
        x, ranks = _equality_stack(A[s1:], eq_starts, blocks, fro, np.zeros(p), rank_tol, last)
        acc = 0.0
        for j in range(n):
            if x[j] < blo[j] - eps or x[j] > bhi[j] + eps:
                return LEFT, x_aug, res, ranks, fro, 0.0
            x_aug[j] = x[j]
            acc += x[j] * x[j]
        res = _residuals(A, x_aug, starts, rlo, rup, True)
        xnorm = np.sqrt(acc)
        if not np.isfinite(xnorm + res.sum()):
            return LEFT, x_aug, res, ranks, fro, 0.0
        return OK, x_aug, res, ranks, fro, xnorm

    @_nb.njit(cache=True, nogil=True)
    def _kkt(rows, m_upper, has_last, n, fixed, values, rcond_min):  # pragma: no cover
        """:func:`._kkt.kkt_solve` by the null-space method of the module doc: ``rows``
        the upper rows ``[U | -d]`` (the first ``m_upper``) then, with ``has_last``,
        the last level's ``[L | -c]``; ``fixed`` the fixed variables, at ``values``.
        Returns ``(ok, solution)``, the solution ``[x; mu_W; mu_U]`` (the KKT
        system's unknowns, :mod:`._kkt`); not ``ok`` (refused, nothing solved) when
        the KKT system is singular or ill-conditioned by the module doc's conditions:
        more upper rows than free variables, fewer last-level rows than the
        directions they leave, ``rcond(R)`` or ``rcond(L Q_2)^2`` below
        ``rcond_min``."""
        w = fixed.shape[0]
        ml = rows.shape[0] - m_upper if has_last else 0
        held = np.zeros(n, dtype=np.bool_)
        for i in range(w):
            held[fixed[i]] = True
        nf = n - w
        F = np.empty(nf, dtype=np.int64)
        b = 0
        for j in range(n):
            if not held[j]:
                F[b] = j
                b += 1
        sol = np.zeros(n + w + m_upper)
        if m_upper > nf or (has_last and ml < nf - m_upper):
            return False, sol
        x_aug = np.ones(n + 1)
        g = np.empty(n)
        muU = np.zeros(max(m_upper, 1))
        work, iwork, iw, ch = _lapack_scratch(n, rows.shape[0])
        if not _general_solve(
            rows, 0, m_upper, m_upper, ml, not has_last, fixed, values, F, x_aug, g, muU,
            rcond_min, work, iwork, iw, ch,
        ):  # fmt: skip
            return False, sol
        sol[:n] = x_aug[:n]
        for i in range(w):  # mu_W = -(g_W + U_W^T mu_U)
            acc = g[fixed[i]]
            for r in range(m_upper):
                acc += rows[r, fixed[i]] * muU[r]
            sol[n + i] = -acc
        for r in range(m_upper):
            sol[n + w + r] = muU[r]
        return np.isfinite(sol).all(), sol

    box_kkt = _compiled = _box_kkt
    kkt = _kkt
    lane = _lane
    free_lane = _free_lane


def warm_up() -> None:
    """Compile (or load) :func:`box_kkt` for the solver's argument types; then forbid
    further compilation (see :func:`._eqkernel.warm_up`)."""
    if _compiled is None or _warm:
        return
    n = 3
    A = np.hstack([np.vstack([np.eye(n), np.eye(n)]), -np.ones((2 * n, 1))])
    starts = np.array([0, n, 2 * n], dtype=np.int64)
    z = np.zeros(2 * n)
    _compiled(
        A, n, n, starts, z, z, -np.ones(n), np.ones(n), np.zeros(n, dtype=np.bool_),
        np.zeros(n, dtype=np.bool_), 1e-9, 1e-9, 1e-10, 4,
    )  # fmt: skip
    m = 2 * n  # the buffers as HierarchySolver passes them (a box on every variable)
    _lane(
        A, -np.ones(m), np.ones(m), np.zeros(m), np.zeros(m), np.zeros(m), np.zeros(m),
        np.zeros(m, dtype=np.bool_), starts, np.arange(n), np.ones(n), np.zeros(n),
        np.zeros(n), np.zeros(n, dtype=np.bool_), np.zeros(n, dtype=np.bool_), n, n,
        1e-9, 1e-9, 1e-10, 4,
    )  # fmt: skip
    _free_lane(
        A, -np.ones(m), np.ones(m), np.zeros(m), np.zeros(m), np.zeros(m), np.zeros(m),
        np.zeros(m, dtype=np.bool_), starts, np.arange(n), np.ones(n), np.zeros(n),
        np.zeros(n), np.zeros(n, dtype=np.bool_), np.zeros(n, dtype=np.bool_), n,
        np.array([0, 0, n], dtype=np.int64), np.array([[1, 2]], dtype=np.int64), 1e-9,
        1e-9, 1,
    )  # fmt: skip
    _kkt(A, n, True, n, np.zeros(1, dtype=np.int64), np.zeros(1), 1e-9)
    for fn in (_compiled, _lane, _free_lane, _kkt):
        fn.disable_compile()
    _warm.append(True)
