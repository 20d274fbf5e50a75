"""The hierarchical solver's iteration as one compiled call (internal to ``sotpy.solvers``;
the algorithm is stated in :mod:`._activeset`, whose NumPy ``solve`` this mirrors).

Why a second implementation: at these sizes (tens of rows, 20 to 80 variables) a NumPy or
LAPACK call costs more in fixed overhead than in arithmetic, and an iteration makes a few
dozen of them; compiled, one iteration on the Talos stand-and-reach stack costs about
30 us. The differences from the NumPy twin, all in the cost, none in the decisions:

* the basis is kept transposed (``Yt``: a row per direction), so that every product is a
  dot product of contiguous rows, and the pivoted QR of ``M^T`` works on the rows of
  ``M`` (LAPACK's column storage, transposed), with the rows' norms downdated from one
  pivot to the next as LAPACK's ``dgeqp3`` does;
* an iteration restarts the recursion at the first sub-level whose active rows changed
  (the sub-levels above, their basis rows and point are kept) and runs it only down to
  the phase's own level (the next phase completes it);
* a row that joins the phase's held rows, when nothing else changed, updates their
  factor in place (:func:`_append_held`) instead of refactoring them;
* the deadline is read from ``clock_gettime(CLOCK_THREAD_CPUTIME_ID)`` (libc, reached
  through its address as an external symbol), the same clock as :func:`time.thread_time`
  with which the caller set it.

``solve`` is ``None`` when compiled kernels are disabled (:mod:`sotpy._jit`) or the
platform has no thread CPU clock.
"""

from __future__ import annotations

import ctypes
import math
import time

import numpy as np

from .._jit import ENABLED, kernel
from ._activeset import (
    CROSSED_BOUNDS,
    EQ,
    FREE,
    INEQ,
    INFINITE_EQUALITY,
    ITERATIONS,
    NAN_BOUND,
    NONFINITE_MATRIX,
    NONFINITE_RESULT,
    OPTIMAL,
    TIME,
)

__all__ = ["solve", "warm_up"]

solve = None
_CLOCK = getattr(time, "CLOCK_THREAD_CPUTIME_ID", None)


def _clock_symbol():
    """The external ``clock_gettime`` for compiled code, or None."""
    try:
        import llvmlite.binding as llvm
        from numba import types as nt

        libc = ctypes.CDLL(None)
        addr = ctypes.cast(libc.clock_gettime, ctypes.c_void_p).value
    except (ImportError, OSError, AttributeError):  # pragma: no cover - not on Linux/macOS
        return None
    llvm.add_symbol("sotpy_clock_gettime", addr)
    return nt.ExternalFunction("sotpy_clock_gettime", nt.int32(nt.int32, nt.voidptr))


#: LAPACK's threshold for summing a downdated norm again (see _pivoted_qr)
_SQRT_EPS = math.sqrt(np.finfo(np.float64).eps)

_clock_gettime = _clock_symbol() if ENABLED and _CLOCK is not None else None

if _clock_gettime is not None:  # pragma: no branch - the environment decides
    _CLOCK_ID = int(_CLOCK)

    @kernel(fast=True)
    def _cpu_time(buf):  # pragma: no cover - compiled
        _clock_gettime(_CLOCK_ID, buf.ctypes)
        return buf[0] + 1e-9 * buf[1]

    @kernel(fast=True)
    def _dot(a, b, n):  # pragma: no cover - compiled
        s = 0.0
        for i in range(n):
            s += a[i] * b[i]
        return s

    @kernel(fast=True)
    def _reflect(V, s, t, y, w):  # pragma: no cover - compiled
        """``y[s:w]`` times the Householder reflector ``I - t v v^T``, ``v = (1, V[s, s+1:w])``
        (stored after the diagonal of row ``s``)."""
        d = y[s]
        for j in range(s + 1, w):
            d += V[s, j] * y[j]
        d *= t
        y[s] -= d
        for j in range(s + 1, w):
            y[j] -= d * V[s, j]

    @kernel(fast=True)
    def _house(v, s, w):  # pragma: no cover - compiled
        """The Householder reflector ``I - t u u^T`` that maps ``v[s:w]`` to ``(beta, 0,
        ...)``: ``v[s]`` becomes ``beta`` (``|beta| = ||v[s:w]||``), ``v[s+1:w]`` the
        vector ``u`` after its unit entry; returns ``t`` (0 when ``v[s+1:w]`` is already
        0: ``v[s]`` is then kept)."""
        alpha = v[s]
        xn2 = 0.0
        for i in range(s + 1, w):
            xn2 += v[i] * v[i]
        if xn2 == 0.0:
            return 0.0
        beta = -math.copysign(math.sqrt(alpha * alpha + xn2), alpha)
        scale = 1.0 / (alpha - beta)
        for i in range(s + 1, w):
            v[i] *= scale
        v[s] = beta
        return (beta - alpha) / beta

    @kernel(fast=True)
    def _pivoted_qr(M, mk, f, tau, piv, nrm, ref):  # pragma: no cover - compiled
        """Householder QR with column pivoting of ``M^T`` (``f x mk``) on the rows of
        ``M``: row ``s`` ends holding ``R[:s+1, s]`` then reflector ``s`` (unit entry
        ``s`` implicit), row ``j >= f`` all of ``R[:, j]``; ``piv[s]`` the original
        index of row ``s``. Returns ``min(mk, f)``.

        The pivot is the row with the largest norm over the entries not reduced yet.
        Those norms (squared, in ``nrm``; scratch of ``mk`` entries each with ``ref``)
        are downdated as LAPACK's ``dgeqp3`` does: a reflector keeps a row's norm, so the
        part left loses the square of the entry it moved into ``R``; a row whose norm
        dropped below ``sqrt(eps)`` of its last exact value is summed again (the
        difference would have lost its digits). Recomputing every norm at every step
        was a third of the flops of a 32 x 23 factor."""
        kmin = min(mk, f)
        for j in range(mk):
            piv[j] = j
            v = 0.0
            for i in range(f):
                v += M[j, i] * M[j, i]
            nrm[j] = v
            ref[j] = v
        for s in range(kmin):
            best = s
            bn = -1.0
            for j in range(s, mk):
                if nrm[j] > bn:
                    bn = nrm[j]
                    best = j
            if best != s:
                for i in range(f):
                    tmp = M[s, i]
                    M[s, i] = M[best, i]
                    M[best, i] = tmp
                tp = piv[s]
                piv[s] = piv[best]
                piv[best] = tp
                nrm[best] = nrm[s]
                ref[best] = ref[s]
            t = _house(M[s], s, f)
            tau[s] = t
            for j in range(s + 1, mk):
                if t != 0.0:
                    w = M[j, s]
                    for i in range(s + 1, f):
                        w += M[s, i] * M[j, i]
                    w *= t
                    M[j, s] -= w
                    for i in range(s + 1, f):
                        M[j, i] -= w * M[s, i]
                left = nrm[j] - M[j, s] * M[j, s]
                if left <= _SQRT_EPS * ref[j]:
                    left = 0.0
                    for i in range(s + 1, f):
                        left += M[j, i] * M[j, i]
                    ref[j] = left
                nrm[j] = left
        return kmin

    @kernel(fast=True)
    def _reflect_rows(v, s, t, f, Yt, c, n, w):  # pragma: no cover - compiled
        """Rows ``c+s..c+f-1`` of ``Yt`` (basis directions) <- ``H`` times them, ``H = I -
        t u u^T``, ``u = (1, v[s+1:f])``."""
        if t == 0.0:
            return
        for col in range(n):
            w[col] = Yt[c + s, col]
        for i in range(s + 1, f):
            vi = v[i]
            for col in range(n):
                w[col] += vi * Yt[c + i, col]
        for col in range(n):
            Yt[c + s, col] -= t * w[col]
        for i in range(s + 1, f):
            vi = t * v[i]
            for col in range(n):
                Yt[c + i, col] -= vi * w[col]

    @kernel(fast=True)
    def _reflect_basis(M, tau, r, f, Yt, c, ncol, w):  # pragma: no cover - compiled
        """Rows ``c..c+f-1`` of ``Yt`` (``Z^T``) <- ``Q^T Z^T``, ``Q = H_0 ... H_{r-1}``.
        Each reflector moves only the rows up to its vector's last nonzero entry, and
        only the columns below ``ncol``, raised to that row: ``ncol = n`` for any basis;
        ``0`` when these rows are still the identity's (``c = 0``: row ``i`` is 0 beyond
        column ``i`` until a reflector mixes it with the rows below)."""
        for s in range(r):
            v = M[s]
            hi = s + 1
            for i in range(f - 1, s, -1):
                if v[i] != 0.0:
                    hi = i + 1
                    break
            ncol = max(ncol, c + hi)
            _reflect_rows(v, s, tau[s], hi, Yt, c, ncol, w)

    @kernel(fast=True)
    def _forward(M, r, rhs, u):  # pragma: no cover - compiled
        """``u`` solves ``B^T u = rhs`` for a square factor (``B^T[j, i] = M[j, i]``,
        lower triangular, ``r x r``)."""
        for j in range(r):
            s = rhs[j]
            for i in range(j):
                s -= M[j, i] * u[i]
            u[j] = s / M[j, j]

    @kernel(fast=True)
    def _ls_factor(M, mk, r, lam, G, gt):  # pragma: no cover - compiled
        """Householder QR of ``[B^T; lam I]`` (``(mk + r) x r``, ``B^T[j, i] = M[j, i]``,
        ``i <= j``, full column rank) on the rows of ``G`` (row ``i``: column ``i``; the
        reflector after the diagonal, its factor in ``gt[i]``). Undamped, the rows of
        ``lam I`` are zero and left out: the factor has ``mk`` rows, which ``gt[-1]``
        keeps for :func:`_ls_apply` (``r <= n``: that entry is never a factor)."""
        w = mk + r if lam != 0.0 else mk
        gt[gt.shape[0] - 1] = w
        for i in range(r):
            for j in range(w):
                G[i, j] = 0.0
            for j in range(i, mk):
                G[i, j] = M[j, i]
            if w > mk:
                G[i, mk + i] = lam
        for s in range(r):
            t = _house(G[s], s, w)
            gt[s] = t
            if t == 0.0:
                continue
            for q in range(s + 1, r):
                _reflect(G, s, t, G[q], w)

    @kernel(fast=True)
    def _ls_apply(G, gt, mk, r, rhs, u, y):  # pragma: no cover - compiled
        """``u = argmin ||[B^T; lam I] u - [rhs; 0]||`` with the factor of
        :func:`_ls_factor`: ``Q^T`` applied to the right-hand side, then ``R u = y``."""
        w = int(gt[gt.shape[0] - 1])  # the factor's rows: mk + r damped, mk undamped
        for j in range(mk):
            y[j] = rhs[j]
        for j in range(mk, w):
            y[j] = 0.0
        for s in range(r):
            if gt[s] != 0.0:
                _reflect(G, s, gt[s], y, w)
        for s in range(r - 1, -1, -1):
            v = y[s]
            for q in range(s + 1, r):
                v -= G[q, s] * u[q]
            u[s] = v / G[s, s]

    @kernel(fast=True)
    def _ehqp(A, t, act, lstart, lam_sub, phis, rank_tol, k0, kend, ws, nzp,
              nzi):  # pragma: no cover - compiled  # fmt: skip
        """The eHQP of the active rows ``act`` (sub-level ``s``: ``act[lstart[s]:lstart[s+1]]``)
        for sub-levels ``k0..kend-1`` (the sub-levels above, their basis rows and points kept
        from the last call; those from ``kend`` on left for a later call that starts there:
        a phase needs only its own and those above). ``xs[s]``: the point before sub-level
        ``s``; ``xs[kend]`` the last.
        Rows with few nonzero entries (``nzp``/``nzi``: their columns) multiply the basis
        by those columns only. The last sub-level with rows applies its reflectors to the
        step only; the basis waits (``pend[0]``) until :func:`_complete` needs it, and the
        bases saved after it are not valid (``pend[1]``: a restart below starts there)."""
        Yt, Ysave, xs, cs, Mw, piv, tau, ranks, x, e, u, Gs, gts, w, y, pend, sv = ws
        n = A.shape[1]
        ns = lstart.shape[0] - 1
        if 0 <= pend[1] < k0:  # the bases saved after that sub-level were never formed
            k0 = pend[1]
        pend[0] = pend[1] = -1
        last = -1
        for k in range(ns):
            if lstart[k + 1] > lstart[k]:
                last = k
        ident = k0 == 0
        if k0 > 0:
            c = cs[k0]
            src = sv[k0]  # the saved basis valid at k0 (-1: the identity)
            for i in range(c, n):
                for col in range(n):
                    Yt[i, col] = Ysave[src, i, col] if src >= 0 else (1.0 if i == col else 0.0)
            for col in range(n):
                x[col] = xs[k0, col]
            ident = src < 0
        else:
            for i in range(n):
                for col in range(n):
                    Yt[i, col] = 0.0
                Yt[i, i] = 1.0
                x[i] = 0.0
            cs[0] = 0
        changed = True  # the basis changed since the last save
        for k in range(k0, kend + 1):
            c = cs[k]
            # the basis at the start of k, saved for a restart there: only when it changed
            if k < ns:
                if ident:
                    sv[k] = -1
                elif changed or k == k0:
                    for i in range(c, n):
                        for col in range(n):
                            Ysave[k, i, col] = Yt[i, col]
                    sv[k] = k
                    changed = False
                else:
                    sv[k] = sv[k - 1]
            for col in range(n):
                xs[k, col] = x[col]
            if k == kend:
                break
            r0 = lstart[k]
            mk = lstart[k + 1] - r0
            f = n - c
            ranks[k] = 0
            if mk == 0 or f == 0:
                cs[k + 1] = c
                continue
            M = Mw[r0 : r0 + mk]
            fq = f  # the columns the factor works on: M is 0 beyond them
            if ident:  # M = the rows themselves: up to their last nonzero column
                fq = 0
                for j in range(mk):
                    row = act[r0 + j]
                    if nzp[row + 1] > nzp[row]:
                        fq = max(fq, nzi[nzp[row + 1] - 1] + 1)
            for j in range(mk):
                row = act[r0 + j]
                a = A[row]
                q0 = nzp[row]
                q1 = nzp[row + 1]
                if ident:
                    for i in range(n):
                        M[j, i] = a[i]
                elif 3 * (q1 - q0) <= n:  # a sparse row (a posture, a bound, a coupling)
                    for i in range(f):
                        v = 0.0
                        for q in range(q0, q1):
                            v += a[nzi[q]] * Yt[c + i, nzi[q]]
                        M[j, i] = v
                else:
                    for i in range(f):
                        M[j, i] = _dot(a, Yt[c + i], n)
                e[r0 + j] = t[row] - _dot(a, x, n)
            pv = piv[r0 : r0 + mk]
            kmin = _pivoted_qr(M, mk, fq, tau[k], pv, w, y)
            thr = rank_tol * phis[k]
            r = 0
            while r < kmin and abs(M[r, r]) > thr:
                r += 1
            ranks[k] = r
            if r > 0:
                for j in range(mk):
                    w[j] = e[r0 + pv[j]]
                if lam_sub[k] == 0.0 and mk == r:
                    _forward(M, r, w, u)
                else:  # kept for the corrections of this sub-level (see _correct)
                    _ls_factor(M, mk, r, lam_sub[k], Gs[k], gts[k])
                    _ls_apply(Gs[k], gts[k], mk, r, w, u, y)
                if k == last:
                    # the step Z Q [u; 0]: the reflectors on the vector, the basis later
                    for i in range(f):
                        y[i] = u[i] if i < r else 0.0
                    for s in range(r - 1, -1, -1):
                        if tau[k, s] != 0.0:
                            _reflect(M, s, tau[k, s], y, f)
                    for i in range(f):
                        yi = y[i]
                        for col in range(n):
                            x[col] += yi * Yt[c + i, col]
                    pend[0] = pend[1] = k
                else:
                    _reflect_basis(M, tau[k], r, f, Yt, c, 0 if ident else n, w)
                    ident = False
                    changed = True
                    for j in range(r):
                        uj = u[j]
                        for col in range(n):
                            x[col] += uj * Yt[c + j, col]
            cs[k + 1] = c + r

    @kernel(fast=True)
    def _complete(ws, lstart, n):  # pragma: no cover - compiled
        """Apply the waiting sub-level's reflectors to the basis (see :func:`_ehqp`)."""
        Yt, _, _, cs, Mw, _, tau, ranks, _, _, _, _, _, w, _, pend, _ = ws
        k = pend[0]
        if k < 0:
            return
        c = cs[k]
        r0 = lstart[k]
        _reflect_basis(Mw[r0 : lstart[k + 1]], tau[k], ranks[k], n - c, Yt, c, n, w)
        pend[0] = -1

    @kernel(fast=True)
    def _correct(A, t, act, lstart, s, lam, x, ws, out, rhs):  # pragma: no cover - compiled
        """``out`` = ``x`` moved in sub-level ``s``'s directions only, to its optimum
        (undamped: the least-squares correction; damped by ``lam``: the coordinates of
        the recursion's damped least squares, the other coordinates as ``x`` has them),
        with its factorisation from the last eHQP (see :mod:`._activeset`)."""
        Yt, _, _, cs, Mw, piv, _, ranks, _, _, u, Gs, gts, _, y, pend, _ = ws
        n = A.shape[1]
        if pend[0] == s:
            _complete(ws, lstart, n)
        for col in range(n):
            out[col] = x[col]
        r = ranks[s]
        if r == 0:
            return
        r0 = lstart[s]
        mk = lstart[s + 1] - r0
        c = cs[s]
        M = Mw[r0 : r0 + mk]
        for j in range(mk):
            row = act[r0 + piv[r0 + j]]
            rhs[j] = t[row] - _dot(A[row], x, n)
        if lam != 0.0:  # the right-hand side of the coordinates: B^T (Y_s^T x) added
            for i in range(r):
                ux = _dot(Yt[c + i], x, n)
                for j in range(i, mk):
                    rhs[j] += M[j, i] * ux
            _ls_apply(Gs[s], gts[s], mk, r, rhs, u, y)
            for i in range(r):
                u[i] -= _dot(Yt[c + i], x, n)
        elif mk == r:
            _forward(M, r, rhs, u)
        else:
            _ls_apply(Gs[s], gts[s], mk, r, rhs, u, y)
        for i in range(r):
            ui = u[i]
            for col in range(n):
                out[col] += ui * Yt[c + i, col]

    @kernel(fast=True)
    def _toward(A, t, act, lstart, s0, s1, lam_sub, x, ws, out, rhs, tmp):  # pragma: no cover
        """``out`` = ``x`` corrected by sub-levels ``s0..s1-1`` in turn, then its
        coordinates in the directions they leave set to 0 (see :mod:`._activeset`)."""
        Yt, _, _, cs, _, _, _, _, _, _, _, _, _, _, _, pend, _ = ws
        n = A.shape[1]
        for col in range(n):
            out[col] = x[col]
        for s in range(s0, s1):
            _correct(A, t, act, lstart, s, lam_sub[s], out, ws, tmp, rhs)
            for col in range(n):
                out[col] = tmp[col]
        if pend[0] >= 0:
            _complete(ws, lstart, n)
        for i in range(cs[s1], n):
            v = _dot(Yt[i], out, n)
            for col in range(n):
                out[col] -= v * Yt[i, col]

    @kernel(fast=True)
    def _multipliers(A, act, lstart, below, g, ws, mu, h, rhs):  # pragma: no cover - compiled
        """``mu[slot]``: the basic multipliers of the active rows of the sub-levels
        ``< below`` for the gradient ``g``."""
        Yt, _, _, cs, Mw, piv, _, ranks, _, _, _, _, _, _, _, pend, _ = ws
        n = A.shape[1]
        if 0 <= pend[0] < below:
            _complete(ws, lstart, n)
        for col in range(n):
            h[col] = g[col]
        for k in range(below - 1, -1, -1):
            r0 = lstart[k]
            for q in range(r0, lstart[k + 1]):
                mu[q] = 0.0
            r = ranks[k]
            if r == 0:
                continue
            c = cs[k]
            for i in range(r):
                rhs[i] = -_dot(Yt[c + i], h, n)
            for q in range(r - 1, -1, -1):  # R11 v = rhs, R[i, q] = Mw[r0 + q, i]
                v = rhs[q] / Mw[r0 + q, q]
                rhs[q] = v
                for i in range(q):
                    rhs[i] -= Mw[r0 + q, i] * v
            for q in range(r):
                slot = r0 + piv[r0 + q]
                mu[slot] = rhs[q]
                a = A[act[slot]]
                v = rhs[q]
                for col in range(n):
                    h[col] += v * a[col]

    @kernel(fast=True)
    def _append_held(A, t, act, slot, lstart, phis, rank_tol, s, row, ws):  # pragma: no cover
        """Sub-level ``s`` (a ``held_j``, full rank) with row ``row`` appended, its factor
        and the basis after it updated in place instead of refactored: the row's
        coordinates in the old held directions are its new column of ``R``, one
        Householder reflector folds its coordinates in the directions left into one new
        direction, and that reflector alone moves the basis below. A blocking row is
        independent of the held rows (the step does not move a row that depends on them),
        so a pivoted refactorisation would keep every row too; the point after ``s`` moves
        along the new direction only, to meet the row. Then sub-level ``s + 1`` restarts
        from the saved basis and point. False (nothing that a restart at ``s`` reads is
        touched) when the update does not apply: the held rows not of full rank, no
        direction left, the basis after ``s`` not formed, or a rank decision that the
        row's weight in the threshold could change."""
        Yt, Ysave, xs, cs, Mw, piv, tau, ranks, _, _, _, _, _, _, y, pend, sv = ws
        n = A.shape[1]
        ns = lstart.shape[0] - 1
        if s + 1 >= ns or 0 <= pend[1] <= s:
            return False
        r0 = lstart[s]
        mk = lstart[s + 1] - r0
        r = ranks[s]
        c = cs[s]
        if r != mk or n - c - r < 1 or cs[s + 1] != c + r:
            return False
        a = A[row]
        a2 = 0.0
        for col in range(n):
            a2 += a[col] * a[col]
        phi = math.sqrt(phis[s] * phis[s] + a2)
        thr = rank_tol * phi
        for q in range(r):
            if not abs(Mw[r0 + q, q]) > thr:
                return False
        # the basis after the old held rows (rows c+r..n-1), into Yt, and the row in it
        src = sv[s + 1]
        f = n - c - r
        for i in range(c + r, n):
            for col in range(n):
                Yt[i, col] = Ysave[src, i, col] if src >= 0 else (1.0 if i == col else 0.0)
        m_new = r0 + mk  # the new row's slot: the held block's end (own_j's move down)
        M = Mw[m_new]
        for q in range(f):  # its coordinates in the directions left, folded into one
            M[r + q] = _dot(a, Yt[c + r + q], n)
        tq = _house(M, r, r + f)
        if not abs(M[r]) > thr:
            return False
        for q in range(r):
            M[q] = _dot(a, Yt[c + q], n)  # its coordinates in the held directions
        _reflect_rows(M, r, tq, r + f, Yt, c, n, y)
        tau[s, r] = tq
        piv[m_new] = r
        ranks[s] = r + 1
        phis[s] = phi
        act[m_new] = row
        slot[row] = m_new
        lstart[s + 1] = m_new + 1
        cs[s + 1] = c + r + 1
        # the point after s: along the new direction, to the row's target (a . y = M[r])
        xa = 0.0
        for col in range(n):
            xa += a[col] * xs[s + 1, col]
        step = (t[row] - xa) / M[r]
        for col in range(n):
            xs[s + 1, col] += step * Yt[c + r, col]
        # the basis at the start of s + 1, saved for the restart there
        for i in range(c + r + 1, n):
            for col in range(n):
                Ysave[s + 1, i, col] = Yt[i, col]
        sv[s + 1] = s + 1
        return True

    @kernel
    def _gather(A, starts, kind, status, attach, level_of, lo, up, fro, k0, act, slot, lstart,
                t, phis):  # pragma: no cover - compiled  # fmt: skip
        """The active rows, sub-level by sub-level (``held_0, own_0, ..., own_{p-1},
        held_p``), from sub-level ``k0`` on; targets and the sub-levels' norms."""
        m, n = A.shape
        p = starts.shape[0] - 1
        ns = 2 * p + 1
        nact = lstart[k0]
        for s in range(k0, ns):
            lstart[s] = nact
            j = s // 2
            if s % 2 == 1:  # own_j: the level's equality rows and own active rows
                phis[s] = fro[j]
                for i in range(starts[j], starts[j + 1]):
                    if kind[i] == EQ or (status[i] != 0 and attach[i] == j):
                        act[nact] = i
                        slot[i] = nact
                        nact += 1
            else:  # held_j: rows of the levels above held for level j
                s2 = 0.0
                for i in range(0, starts[min(j, p)]):
                    if kind[i] == INEQ and status[i] != 0 and attach[i] == j and level_of[i] < j:
                        act[nact] = i
                        slot[i] = nact
                        nact += 1
                        for col in range(n):
                            s2 += A[i, col] * A[i, col]
                phis[s] = math.sqrt(s2)
        lstart[ns] = nact
        for i in range(m):
            t[i] = up[i] if status[i] > 0 else lo[i]
        return nact

    @kernel(fast=True)
    def _violation(A, lo, up, anorm, eps, r0, r1, x, n):  # pragma: no cover - compiled
        """``||v(x)||^2`` over rows ``r0..r1-1``: their squared distance to their intervals
        beyond the feasibility tolerance (see :func:`._activeset._violation`)."""
        xi = 1.0
        for col in range(n):
            xi = max(xi, abs(x[col]))
        v2 = 0.0
        for i in range(r0, r1):
            v = _dot(A[i], x, n)
            tol = eps * (1.0 + anorm[i] * xi)
            if v < lo[i] - tol:
                v2 += (lo[i] - tol - v) ** 2
            elif v > up[i] + tol:
                v2 += (v - up[i] - tol) ** 2
        return v2

    @kernel(fast=True)
    def _ratio(
        A, x, d, kind, status, attach, level_of, lo, up, anorm, jmax, upto, tol
    ):  # pragma: no cover
        """As ``_ratio`` of :mod:`._activeset`, over the inequality rows of the levels
        ``<= jmax`` that are not active in the sub-levels ``< upto``: ``(tau, row, side)``."""
        m, n = A.shape
        dn = math.sqrt(_dot(d, d, n))
        tau = 1.0
        blk = -1
        side = 0
        if dn == 0.0:
            return tau, blk, side
        for i in range(m):
            if kind[i] != INEQ or level_of[i] > jmax:
                continue
            if status[i] != 0:
                sub = 2 * attach[i] + (1 if attach[i] == level_of[i] else 0)
                if sub < upto:
                    continue
            ad = _dot(A[i], d, n)
            small = tol * anorm[i] * dn
            if ad > small and up[i] < math.inf:
                ti = (up[i] - _dot(A[i], x, n)) / ad
                sd = 1
            elif ad < -small and lo[i] > -math.inf:
                ti = (lo[i] - _dot(A[i], x, n)) / ad
                sd = -1
            else:
                continue
            ti = max(ti, 0.0)
            if ti < tau:
                tau = ti
                blk = i
                side = sd
        return tau, blk, side

    @kernel(fast=True)
    def _verify(A, x, xj, t, act, lstart, status, attach, kind, level_of, decided, locked,
                anorm, lam_sub, fro, j, p, eps, dual_tol, ws, mu, h, g, rhs, score,
                cand):  # pragma: no cover - compiled  # fmt: skip
        """As ``_verify`` of :mod:`._activeset`: -1 when no judged row is wrong (the kept
        ones are then decided), else the row released."""
        n = A.shape[1]
        below = 2 * j + 1 if j < p else 2 * p + 1
        xi = 1.0
        xn = 0.0
        for col in range(n):
            xi = max(xi, abs(x[col]))
            xn += x[col] * x[col]
        xn = math.sqrt(xn)
        nc = 0
        for q in range(lstart[below]):
            i = act[q]
            if kind[i] != INEQ or decided[i]:
                continue
            if abs(_dot(A[i], x, n) - t[i]) <= eps * (1.0 + anorm[i] * xi):
                cand[nc] = q
                nc += 1
        if nc == 0:
            return -1
        if j < p:
            r0 = lstart[2 * j + 1]
            r1 = lstart[2 * j + 2]
            wn = 0.0
            tn = 0.0
            for col in range(n):
                g[col] = 0.0
            for q in range(r0, r1):
                i = act[q]
                wq = _dot(A[i], x, n) - t[i]
                wn += wq * wq
                tn += t[i] * t[i]
                a = A[i]
                for col in range(n):
                    g[col] += wq * a[col]
            wn = math.sqrt(wn)
            if wn <= eps * (1.0 + fro[j] * xn + math.sqrt(tn)):
                return -1  # the level is met: no gradient
            gscale = fro[j] * wn
            lam = lam_sub[2 * j + 1]
            if lam != 0.0:  # the damping's gradient, lambda^2 x
                sn = 0.0
                for col in range(n):
                    g[col] += lam * lam * xj[col]
                    sn += xj[col] * xj[col]
                gscale += lam * lam * math.sqrt(sn)
        else:
            if xn == 0.0:
                return -1
            for col in range(n):
                g[col] = x[col]
            gscale = xn
        _multipliers(A, act, lstart, below, g, ws, mu, h, rhs)
        best = -1
        bs = -1.0
        for k in range(nc):
            q = cand[k]
            i = act[q]
            li = mu[q] * anorm[i] / gscale
            score[k] = li
            free = not locked[i]
            if abs(li) > dual_tol and status[i] * li < 0.0 and free and abs(li) > bs:
                bs = abs(li)
                best = i
        if best >= 0:
            status[best] = 0
            return best
        for k in range(nc):
            i = act[cand[k]]
            if abs(score[k]) > dual_tol and status[i] * score[k] > 0.0:
                decided[i] = True
        return -1

    @kernel(fast=True)
    def _solve(A, lo, up, starts, status, attach, lams, rank_tol, eps, dual_tol, max_iter,
               deadline, x_out, res, ranks_out, fro, info, wf, wi):  # pragma: no cover  # fmt: skip
        clock = np.zeros(2, dtype=np.int64)
        start = _cpu_time(clock)
        # 0 and 1 as int64 values, not literals: numba compiles a helper once per literal
        # argument it is called with (and once per literal a variable holds while its
        # type is inferred), which cost about a fifth of this module's compile time
        I0 = clock[0] * 0
        I1 = I0 + 1
        m, n = A.shape
        p = starts.shape[0] - 1
        ns = 2 * p + 1
        for q in range(info.shape[0]):
            info[q] = 0
        x = np.zeros(n)
        xprev = np.empty(n)  # the previous call's answer (NaN: none)
        warm = True
        for col in range(n):  # x_out is written at the end only: a refused input keeps it
            xprev[col] = x_out[col]
            warm = warm and math.isfinite(xprev[col])
        for k in range(p):
            res[k] = 0.0
            ranks_out[k] = 0
        # the input: checks, norms, row kinds
        level_of = np.empty(m, dtype=np.int64)
        kind = np.empty(m, dtype=np.int8)
        anorm = np.empty(m)
        for k in range(p):
            s2 = 0.0
            for i in range(starts[k], starts[k + 1]):
                level_of[i] = k
                a2 = 0.0
                for col in range(n):
                    a2 += A[i, col] * A[i, col]
                anorm[i] = math.sqrt(a2)
                s2 += a2
            fro[k] = math.sqrt(s2)
        for i in range(m):
            if not math.isfinite(anorm[i]):
                info[3] = NONFINITE_MATRIX
                info[4] = i
                for col in range(n):
                    if not math.isfinite(A[i, col]):
                        info[5] = col
                        break
                return
        for i in range(m):
            if math.isnan(lo[i]) or math.isnan(up[i]):
                info[3] = NAN_BOUND
                info[4] = i
                return
        for i in range(m):
            if lo[i] > up[i]:
                info[3] = CROSSED_BOUNDS
                info[4] = i
                return
        for i in range(m):
            if lo[i] == up[i] and not math.isfinite(lo[i]):
                info[3] = INFINITE_EQUALITY
                info[4] = i
                return
        for i in range(m):
            if lo[i] == up[i]:
                kind[i] = EQ
            elif lo[i] > -math.inf or up[i] < math.inf:
                kind[i] = INEQ
            else:
                kind[i] = FREE
            # an equality, a free row, or a bound that is no longer finite (the rows
            # changed since the last call): no target to warm-start at
            if (
                kind[i] != INEQ
                or (status[i] > 0 and up[i] == math.inf)
                or (status[i] < 0 and lo[i] == -math.inf)
            ):
                status[i] = 0
            if status[i] == 0 or attach[i] < level_of[i] or attach[i] > p:
                attach[i] = level_of[i]
        # each row's nonzero columns (the sparse rows' products skip the zeros)
        nzp = np.zeros(m + 1, dtype=np.int64)
        nzi = wi[: max(m * n, 1)]
        q = 0
        for i in range(m):
            nzp[i] = q
            for col in range(n):
                if A[i, col] != 0.0:
                    nzi[q] = col
                    q += 1
        nzp[m] = q
        lam_sub = np.zeros(ns)
        for k in range(p):
            lam_sub[2 * k + 1] = lams[k]
        move_tol = max(eps, 2.0 * rank_tol)
        # workspace
        act = np.empty(max(m, 1), dtype=np.int64)
        slot = np.full(max(m, 1), -1, dtype=np.int64)
        lstart = np.zeros(ns + 1, dtype=np.int64)
        t = np.empty(max(m, 1))
        phis = np.zeros(ns)
        ws = (
            np.empty((n, n)),  # Yt: a row per direction, the last ones Z^T
            wf[: ns * n * n].reshape((ns, n, n)),  # Ysave: Yt's rows before each sub-level
            np.empty((ns + 1, n)),  # xs: the point before each sub-level
            np.zeros(ns + 1, dtype=np.int64),  # cs: first basis row of each sub-level
            np.empty((max(m, 1), n)),  # Mw: each sub-level's factored rows
            np.empty(max(m, 1), dtype=np.int64),  # piv
            np.empty((ns, n)),  # tau
            np.zeros(ns, dtype=np.int64),  # ranks
            np.zeros(n),  # x of the recursion
            np.empty(max(m, 1)),  # e
            np.empty(n),  # u
            wf[ns * n * n : ns * n * n + ns * (n + 1) * (m + n)].reshape((ns, n + 1, m + n)),
            np.empty((ns, n + 1)),  # gts
            np.empty(max(m, n)),  # w
            np.empty(m + n),  # y
            np.full(2, -1, dtype=np.int64),  # pend: the sub-level whose basis waits, twice
            np.full(ns + 1, -1, dtype=np.int64),  # sv: where the basis at each start is saved
        )
        xs = ws[2]
        sub_ranks = ws[7]
        xj = np.zeros(n)
        tmp = np.zeros(n)
        d = np.zeros(n)
        rhs = np.empty(max(m, n))
        mu = np.zeros(max(m, 1))
        h = np.empty(n)
        g = np.empty(n)
        score = np.zeros(max(m, 1))
        cand = np.zeros(max(m, 1), dtype=np.int64)
        decided = np.zeros(max(m, 1), dtype=np.bool_)
        locked = np.zeros(max(m, 1), dtype=np.bool_)
        longest = 0.0
        checked = start  # when the budget was last checked: the start's work counts too
        reason = OPTIMAL
        solved = p + 1
        # the first phase starts at the eHQP point of the previous call's active rows
        _gather(A, starts, kind, status, attach, level_of, lo, up, fro, I0, act, slot, lstart,
                t, phis)  # fmt: skip
        _ehqp(A, t, act, lstart, lam_sub, phis, rank_tol, I0, ns, ws, nzp, nzi)
        its = 1
        valid = ns  # the eHQP is computed for the sub-levels < valid
        for col in range(n):
            x[col] = xs[ns, col]
        stale = False
        # x is the recursion's point of the current active rows, nothing changed since:
        # every phase's target is x itself (the usual tick: the guess was right)
        at_ehqp = True
        warm = warm and p > 0
        v0 = _violation(A, lo, up, anorm, eps, starts[0], starts[1], x, n) if warm else 0.0
        met0 = warm and v0 == 0.0  # x meets level 0: its phase has no violated row to add
        if v0 > 0.0:
            # ... unless it violates level 0 more than the previous answer corrected onto
            # level 0's active rows: then the first phase starts there
            _correct(A, t, act, lstart, I0, 0.0, xprev, ws, tmp, rhs)
            _correct(A, t, act, lstart, I1, 0.0, tmp, ws, xj, rhs)
            if _violation(A, lo, up, anorm, eps, starts[0], starts[1], xj, n) < v0:
                for col in range(n):
                    x[col] = xj[col]
                at_ehqp = False
        dirty = ns  # the first sub-level whose rows changed since the last eHQP
        append = I0 - 1  # a row to append to the held rows of the phase (see _append_held)
        for j in range(p + 1):
            upto = 2 * j + 2 if j < p else ns
            jmax = min(j, p - 1)
            released = -1
            # the sub-levels of this phase that the last eHQP left: computed before its
            # first step (not counted as an iteration: no row changed)
            extend = valid < upto
            if extend:
                dirty = min(dirty, valid)
            # level j's rows violated where the phase starts join its least squares (none
            # when the start check above found level 0 met at this very point)
            if j < p and not (j == 0 and met0):
                xi = 1.0
                for col in range(n):
                    xi = max(xi, abs(x[col]))
                for i in range(starts[j], starts[j + 1]):
                    if kind[i] != INEQ or (status[i] != 0 and attach[i] <= j):
                        continue
                    v = _dot(A[i], x, n)
                    tol = eps * (1.0 + anorm[i] * xi)
                    if v > up[i] + tol or v < lo[i] - tol:
                        status[i] = 1 if v > up[i] + tol else -1
                        attach[i] = j
                        dirty = min(dirty, 2 * j + 1)
                        stale = True
            while True:
                if stale or extend:
                    # an iteration is all the work from one check to the next (the eHQP,
                    # the target, the step, the verdict): the longest predicts the next,
                    # and the last step of a stopped call (one more eHQP) must fit after it
                    now = _cpu_time(clock)
                    longest = max(longest, now - checked)
                    checked = now
                    if (stale and its >= max_iter) or now + 2.0 * longest > deadline:
                        reason = ITERATIONS if stale and its >= max_iter else TIME
                        break
                    if append >= 0:
                        # its target (the gather below sets every row's), then the update
                        t[append] = up[append] if status[append] > 0 else lo[append]
                        if _append_held(A, t, act, slot, lstart, phis, rank_tol, 2 * j,
                                        append, ws):  # fmt: skip
                            dirty = 2 * j + 1
                    _gather(A, starts, kind, status, attach, level_of, lo, up, fro,
                                   dirty, act, slot, lstart, t, phis)  # fmt: skip
                    _ehqp(A, t, act, lstart, lam_sub, phis, rank_tol, dirty, upto, ws, nzp, nzi)
                    append = I0 - 1
                    if stale:
                        its += 1
                        at_ehqp = False
                    stale = extend = False
                    valid = upto
                    dirty = ns
                # held rows that depend on the rows above them leave
                s = 2 * j
                mk = lstart[s + 1] - lstart[s]
                if sub_ranks[s] < mk:
                    piv = ws[5]
                    r0 = lstart[s]
                    for q in range(sub_ranks[s] if n - ws[3][s] > 0 else 0, mk):
                        status[act[r0 + piv[r0 + q]] if n - ws[3][s] > 0 else act[r0 + q]] = 0
                    dirty = min(dirty, s)
                    stale = True
                    continue
                # the phase's target (see _activeset)
                if at_ehqp:
                    for col in range(n):
                        xj[col] = x[col]
                elif j < p and lam_sub[2 * j + 1] != 0.0:  # damped: the recursion's point
                    _toward(A, t, act, lstart, 2 * j, 2 * j + 2, lam_sub, x, ws, xj, rhs, tmp)
                elif j < p:
                    _correct(A, t, act, lstart, 2 * j, 0.0, x, ws, tmp, rhs)
                    _correct(A, t, act, lstart, 2 * j + 1, 0.0, tmp, ws, xj, rhs)
                else:
                    _toward(A, t, act, lstart, ns - 1, ns, lam_sub, x, ws, xj, rhs, tmp)
                # the step, up to the first row of the levels <= j that reaches a bound: held
                # for this phase (in held_j, or own_j when it is level j's)
                if not at_ehqp:
                    for col in range(n):
                        d[col] = xj[col] - x[col]
                    tau, i, side = _ratio(A, x, d, kind, status, attach, level_of, lo, up,
                                          anorm, jmax, upto, move_tol)  # fmt: skip
                    for col in range(n):
                        x[col] += tau * d[col]
                    if i >= 0:
                        if i == released and tau == 0.0:
                            locked[i] = True  # released and blocked at once: not again ...
                        else:
                            for q in range(m):
                                locked[q] = False  # ... until something else changes
                        xi = 1.0
                        for col in range(n):
                            xi = max(xi, abs(x[col]))
                        kept = True
                        for q in range(m):  # unmet held rows of the phase leave
                            if status[q] != 0 and attach[q] == j and level_of[q] < j:
                                tq = up[q] if status[q] > 0 else lo[q]
                                if abs(_dot(A[q], x, n) - tq) > eps * (1.0 + anorm[q] * xi):
                                    status[q] = 0
                                    kept = False
                        # the only change since the last eHQP: a row of a level above joins
                        # held_j, whose factor can then be updated (see _append_held)
                        if kept and dirty == ns and level_of[i] < j:
                            append = i
                        status[i] = side
                        attach[i] = j
                        # the sub-levels above held_j keep their rows, whatever level the
                        # row is of
                        dirty = min(dirty, 2 * j)
                        released = -1
                        stale = True
                        continue
                if j < p:  # own_j's rows beyond the other bound flip, strictly inside leave
                    xi = 1.0
                    for col in range(n):
                        xi = max(xi, abs(x[col]))
                    flipped = False
                    inside = False
                    for i in range(starts[j], starts[j + 1]):
                        if kind[i] != INEQ or status[i] == 0 or attach[i] != j:
                            continue
                        v = _dot(A[i], x, n)
                        tol = eps * (1.0 + anorm[i] * xi)
                        if (status[i] > 0 and v < lo[i] - tol) or (
                            status[i] < 0 and v > up[i] + tol
                        ):
                            status[i] = -status[i]
                            flipped = True
                        elif (status[i] > 0 and v < up[i] - tol) or (
                            status[i] < 0 and v > lo[i] + tol
                        ):
                            inside = True
                    if inside:
                        for i in range(starts[j], starts[j + 1]):
                            if kind[i] != INEQ or status[i] == 0 or attach[i] != j:
                                continue
                            v = _dot(A[i], x, n)
                            tol = eps * (1.0 + anorm[i] * xi)
                            if (status[i] > 0 and v < up[i] - tol) or (
                                status[i] < 0 and v > lo[i] + tol
                            ):
                                status[i] = 0
                    if flipped or inside:
                        dirty = min(dirty, 2 * j + 1)
                        stale = True
                        continue
                verdict = _verify(A, x, xj, t, act, lstart, status, attach, kind, level_of,
                                  decided, locked, anorm, lam_sub, fro, j, p, eps,
                                  dual_tol, ws, mu, h, g, rhs, score, cand)  # fmt: skip
                if verdict < 0:
                    break
                released = verdict
                ss = 2 * attach[verdict] + (1 if attach[verdict] == level_of[verdict] else 0)
                dirty = min(dirty, ss)
                stale = True
            if reason != OPTIMAL:
                solved = j
                break
        if reason != OPTIMAL:
            # the last step: every level's active rows, up to the first row of the levels
            # <= solved that it would leave
            _gather(A, starts, kind, status, attach, level_of, lo, up, fro, I0, act, slot, lstart,
                    t, phis)  # fmt: skip
            _ehqp(A, t, act, lstart, lam_sub, phis, rank_tol, I0, ns, ws, nzp, nzi)
            its += 1
            _toward(A, t, act, lstart, 2 * solved, ns, lam_sub, x, ws, xj, rhs, tmp)
            for col in range(n):
                d[col] = xj[col] - x[col]
            tau, _i, _s = _ratio(A, x, d, kind, status, attach, level_of, lo, up, anorm,
                                 min(solved, p - 1), ns + 1, move_tol)  # fmt: skip
            for col in range(n):
                x[col] += tau * d[col]
        # the result
        finite = True
        for col in range(n):
            x_out[col] = x[col]
            if not math.isfinite(x[col]):
                finite = False
        if not finite:
            info[3] = NONFINITE_RESULT
        for k in range(p):
            s2 = 0.0
            for i in range(starts[k], starts[k + 1]):
                v = _dot(A[i], x, n)
                if v < lo[i]:
                    s2 += (lo[i] - v) * (lo[i] - v)
                elif v > up[i]:
                    s2 += (v - up[i]) * (v - up[i])
            res[k] = math.sqrt(s2)
            ranks_out[k] = sub_ranks[2 * k] + sub_ranks[2 * k + 1]
        nin = 0
        for i in range(m):
            if kind[i] == INEQ and status[i] != 0:
                nin += 1
        info[0] = its
        info[1] = reason
        info[2] = solved
        info[6] = nin
        ninq = 0
        for i in range(m):
            if kind[i] == INEQ:
                ninq += 1
        info[7] = ninq

    solve = _solve


def workspace(m: int, n: int, p: int) -> tuple[np.ndarray, np.ndarray]:
    """The kernel's large scratch arrays for ``m`` rows, ``n`` variables and ``p`` levels
    (kept by the solver per stack shape: no allocation, no page touched anew per call):
    the saved bases and the least-squares factors (floats), the rows' nonzero columns."""
    ns = 2 * p + 1
    return np.empty(ns * n * n + ns * (n + 1) * (m + n)), np.empty(max(m * n, 1), dtype=np.int64)


def warm_up() -> None:
    """Compile the kernel for the argument types the solver passes (or load it from
    numba's cache), then forbid further compilation: a call with other types raises
    ``TypeError`` (the solver then uses the NumPy twin) instead of stalling a tick."""
    if solve is None or _solve.signatures:  # type: ignore[union-attr]
        return
    n = 3
    A = np.eye(n)
    lo, up = -np.ones(n), np.ones(n)
    starts = np.array([0, 1, n], dtype=np.int64)
    status = np.zeros(n, dtype=np.int8)
    attach = np.zeros(n, dtype=np.int64)
    out = (np.empty(n), np.empty(2), np.empty(2, dtype=np.int64), np.empty(2))
    info = np.empty(8, dtype=np.int64)
    _solve(A, lo, up, starts, status, attach, np.zeros(2), 1e-9, 1e-9, 1e-9, 10, math.inf,
           *out, info, *workspace(n, n, 2))  # fmt: skip
    _solve.disable_compile()
