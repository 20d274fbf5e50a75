r"""Householder QR, products with ``Q`` and ``Q^T``, triangular solves and condition
numbers, compiled, for small matrices (internal to ``sotpy.solvers``; see
:mod:`sotpy._jit`).

Below a few dozen rows a LAPACK call costs more in fixed overhead than in flops: the
argument checks, the workspace and block-size queries, and one level-2 BLAS call
(``dgemv``, ``dger``) per reflector and column block; inside a control tick, whose other
work has evicted LAPACK's code and data from the caches, more still. The box path's
posture split (:mod:`._boxkkt`) made ten such calls a tick on Talos (QRs of 17 x 6 and
32 x 11, ``Q^T`` of 17 x 33, two ``dtrcon``, triangular solves); it now makes none, and
the equality recursion (:mod:`._eqkernel`) keeps only ``dgeqp3``. Larger
factorisations (the general box solve's, up to 38 x 32) stay with LAPACK's blocked
kernels, which win there (the measurements are in ``docs/solvers.md``).

The storage is LAPACK's (``dgeqrf``): for a Fortran ``a`` (``m x k``, ``m >= k``),
``R`` on and above the diagonal, reflector ``i`` below it, with ``v_i = [0, ..., 0, 1,
a[i+1:, i]]`` and

.. math::

    Q = H_0 H_1 \cdots H_{k-1}, \qquad H_i = I - \tau_i v_i v_i^T,

so a factorisation made here can be used by LAPACK and the other way round. Each
reflector is chosen as ``dlarfg`` does: ``H_i`` maps ``a[i:, i]`` to ``\beta e_1`` with
``\beta = -\operatorname{sign}(a_{ii}) \|a[i:, i]\|``, and ``\tau_i = 0`` (``H_i = I``)
when the column below the diagonal is zero. Norms are scaled by the largest entry, so
no square overflows or underflows. The kernels divide as NumPy does (``error_model=
"numpy"``): a zero divisor gives inf or NaN, never an exception inside a compiled call.
"""

from __future__ import annotations

from .._jit import ENABLED

if ENABLED:  # pragma: no branch - the environment decides
    import numba as _nb
    import numpy as np

    @_nb.njit(cache=True, nogil=True, error_model="numpy")
    def _norm(a, j, i0, m):  # pragma: no cover - compiled
        """``||a[i0:m, j]||_2``, scaled by the largest entry."""
        big = 0.0
        for i in range(i0, m):
            big = max(big, abs(a[i, j]))
        if big == 0.0 or not np.isfinite(big):
            return big
        acc = 0.0
        for i in range(i0, m):
            t = a[i, j] / big
            acc += t * t
        return big * np.sqrt(acc)

    @_nb.njit(cache=True, nogil=True, error_model="numpy")
    def householder_qr(a, tau):  # pragma: no cover - compiled
        """``a = Q R`` in place (Fortran ``a``, ``m x k``, ``m >= k``; LAPACK's storage,
        see the module doc); ``tau`` receives the ``k`` reflectors' factors."""
        m = a.shape[0]
        k = a.shape[1]
        for i in range(k):
            alpha = a[i, i]
            xnorm = _norm(a, i, i + 1, m)
            if xnorm == 0.0:
                tau[i] = 0.0
                continue
            beta = -np.copysign(np.hypot(alpha, xnorm), alpha)
            tau[i] = (beta - alpha) / beta
            scale = 1.0 / (alpha - beta)
            for r in range(i + 1, m):
                a[r, i] *= scale
            a[i, i] = beta
            ti = tau[i]
            # H_i a[i:, j], four columns at a time: four independent sums per row
            # instead of one dependency chain per column
            j = i + 1
            while j + 3 < k:
                s0 = a[i, j]
                s1 = a[i, j + 1]
                s2 = a[i, j + 2]
                s3 = a[i, j + 3]
                for r in range(i + 1, m):
                    v = a[r, i]
                    s0 += v * a[r, j]
                    s1 += v * a[r, j + 1]
                    s2 += v * a[r, j + 2]
                    s3 += v * a[r, j + 3]
                s0 *= ti
                s1 *= ti
                s2 *= ti
                s3 *= ti
                a[i, j] -= s0
                a[i, j + 1] -= s1
                a[i, j + 2] -= s2
                a[i, j + 3] -= s3
                for r in range(i + 1, m):
                    v = a[r, i]
                    a[r, j] -= s0 * v
                    a[r, j + 1] -= s1 * v
                    a[r, j + 2] -= s2 * v
                    a[r, j + 3] -= s3 * v
                j += 4
            while j < k:
                s = a[i, j]
                for r in range(i + 1, m):
                    s += a[r, i] * a[r, j]
                s *= ti
                a[i, j] -= s
                for r in range(i + 1, m):
                    a[r, j] -= s * a[r, i]
                j += 1

    @_nb.njit(cache=True, nogil=True, error_model="numpy")
    def reflect_rows(a, tau, k, c, w, trans):  # pragma: no cover - compiled
        """``c <- Q^T c`` (``trans``) or ``c <- Q c``, with ``Q`` from the first ``k``
        reflectors of ``a`` (``m`` rows) and ``c`` an ``m x p`` C-order array (the
        loops run along its rows); ``w`` is scratch of length ``p``."""
        m = a.shape[0]
        p = c.shape[1]
        for t in range(k):
            i = t if trans else k - 1 - t
            ti = tau[i]
            if ti == 0.0:
                continue
            for j in range(p):  # w = v_i^T c
                w[j] = c[i, j]
            for r in range(i + 1, m):
                v = a[r, i]
                for j in range(p):
                    w[j] += v * c[r, j]
            for j in range(p):
                w[j] *= ti
                c[i, j] -= w[j]
            for r in range(i + 1, m):
                v = a[r, i]
                for j in range(p):
                    c[r, j] -= v * w[j]

    @_nb.njit(cache=True, nogil=True, error_model="numpy")
    def reflect_vector(a, tau, k, y, trans):  # pragma: no cover - compiled
        """:func:`reflect_rows` for one vector ``y`` (length ``m``); its own loops, as
        :func:`reflect_rows` on a one-column view made the equality solve 4 µs slower."""
        m = a.shape[0]
        for t in range(k):
            i = t if trans else k - 1 - t
            ti = tau[i]
            if ti == 0.0:
                continue
            s = y[i]
            for r in range(i + 1, m):
                s += a[r, i] * y[r]
            s *= ti
            y[i] -= s
            for r in range(i + 1, m):
                y[r] -= s * a[r, i]

    @_nb.njit(cache=True, nogil=True, error_model="numpy")
    def solve_upper(a, k, y, trans):  # pragma: no cover - compiled
        """``R z = y`` (or ``R^T z = y`` with ``trans``) in place of ``y``, ``R`` the
        upper triangle of the leading ``k x k`` block of ``a``. A zero on the diagonal
        gives inf or NaN (the callers test the condition first)."""
        if trans:
            for i in range(k):
                s = y[i]
                for r in range(i):
                    s -= a[r, i] * y[r]
                y[i] = s / a[i, i]
        else:
            for i in range(k - 1, -1, -1):
                s = y[i]
                for j in range(i + 1, k):
                    s -= a[i, j] * y[j]
                y[i] = s / a[i, i]

    @_nb.njit(cache=True, nogil=True, error_model="numpy")
    def rcond_upper(a, k):  # pragma: no cover - compiled
        r"""The reciprocal 1-norm condition number ``1 / (\|R\|_1 \|R^{-1}\|_1)`` of the
        upper triangle ``R`` of the leading ``k x k`` block of ``a``, from ``R^{-1}``
        itself (``k^3 / 6`` flops). It is never above LAPACK's estimate (``dtrcon``
        bounds ``\|R^{-1}\|_1`` from below); 0 for a singular or non-finite ``R``, 1
        for ``k = 0``."""
        if k == 0:
            return 1.0
        norm_r = 0.0
        for j in range(k):
            s = 0.0
            for i in range(j + 1):
                s += abs(a[i, j])
            if not s <= norm_r:  # (NaN kept)
                norm_r = s
        col = np.empty(k)
        norm_inv = 0.0
        for j in range(k):  # column j of R^{-1}: R x = e_j, x[j + 1:] = 0, by columns
            if a[j, j] == 0.0:
                return 0.0
            for i in range(j + 1):
                col[i] = 0.0
            col[j] = 1.0
            s = 0.0
            for i in range(j, -1, -1):
                xi = col[i] / a[i, i]
                col[i] = xi
                s += abs(xi)
                for r in range(i):  # col[:i] -= x_i R[:i, i] (a column of a)
                    col[r] -= xi * a[r, i]
            if not s <= norm_inv:
                norm_inv = s
        rc = 1.0 / (norm_r * norm_inv)
        return rc if rc > 0.0 and np.isfinite(rc) else 0.0
