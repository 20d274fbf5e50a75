"""Reduced null-space steps with LAPACK called directly (internal to ``sotpy.solvers``).

A :class:`NullspaceStepper` holds, for ``n`` variables, the current point ``x`` and an
orthonormal basis ``Z`` (``n x nf``) of the directions still free, both inside one
Fortran-ordered buffer ``W = [[Z, x], [0, 1]]`` of shape ``(n + 1, nf + 1)``. Rows are
given *augmented*, ``[A | -b]``, so that one product ``[A | -b] W = [A Z | A x - b]``
yields both the reduced matrix ``M = A Z`` and the residual ``A x - b``.

:meth:`NullspaceStepper.step` treats a block of equality rows ``A x = b`` in the affine
set ``x + range(Z)``:

* a column-pivoted QR of ``M^T`` (``dgeqp3``): ``M^T P = Q R``; the rank ``r`` is the
  number of diagonal entries ``|R_ii| > rank_tol * scale`` (``scale`` is given by the
  caller: the Frobenius norm of the level's matrix);
* with ``L = R[:r, :]^T`` (``m x r``, full column rank) and ``e = P^T (b - A x)``,
  ``z = argmin ||L z - e||^2 + damping^2 ||z||^2`` (``dtrtrs`` when the block is
  square and undamped, ``dgels`` otherwise);
* ``x <- x + (Z Q)[:, :r] z`` and ``Z <- (Z Q)[:, r:]`` (``dormqr``; ``Q`` never
  formed).

The step is the minimum-norm minimiser of ``||A x' - b||^2 + damping^2 ||x' - x||^2``
over ``x' in x + range(Z)`` (``M`` truncated to rank ``r``), and the new ``Z`` spans
the null space of the truncated ``M`` inside the old one. When no later level needs
``Z`` and the block has more rows than free directions (the usual last level), the
least-squares problem ``min ||M y + (A x - b)||`` is solved from a pivoted QR of ``M``
itself (one factorisation instead of two), falling back to the general step when
``M`` is rank-deficient.
"""

from __future__ import annotations

import numpy as np
from scipy.linalg import lapack as _lapack

_dgeqp3 = _lapack.dgeqp3
_dormqr = _lapack.dormqr
_dtrtrs = _lapack.dtrtrs
_dgels = _lapack.dgels
_matmul = np.matmul
_multiply = np.multiply
_copyto = np.copyto


class NullspaceStepper:
    """Buffers and state of the reduced null-space recursion for ``n`` variables.

    Read by the callers: :attr:`x` (view of the current point), :attr:`nf`,
    :meth:`basis`. Not thread-safe; one per solver.
    """

    __slots__ = (
        "_init",
        "_lbuf",
        "_lwork",
        "_mbuf",
        "_rhs",
        "_triu",
        "_vec",
        "c0",
        "identity",
        "last_qr",
        "m_max",
        "moved",
        "n",
        "nf",
        "w",
        "x",
        "x_aug",
    )

    def __init__(self, n: int, m_max: int):
        self.n = n
        self.m_max = m_max = max(m_max, 1)
        init = np.zeros((n + 1, n + 1), order="F")
        init[: n + 1, : n + 1] = np.eye(n + 1)
        self._init = init
        self.w = init.copy(order="F")
        self.x_aug = self.w[:, n]
        self.x = self.w[:n, n]
        self._mbuf = np.empty(m_max * (n + 1))
        self._lbuf = np.empty(n * (m_max + n))
        self._rhs = np.empty(m_max + n)
        self._vec = np.empty(n)
        k = max(n, m_max)
        self._triu = np.triu(np.ones((k, k)))
        self._lwork = 64 * (k + 1)
        self.c0 = 0
        self.nf = n
        self.identity = True
        self.moved = False
        self.last_qr: tuple[np.ndarray, np.ndarray] | None = None

    def reset(self) -> None:
        """Back to ``x = 0``, ``Z = I``."""
        if not self.identity:
            _copyto(self.w, self._init)
        else:
            self.x.fill(0.0)
        self.c0 = 0
        self.nf = self.n
        self.identity = True
        self.moved = False

    def fix(self, idx: np.ndarray, values: np.ndarray) -> None:
        """Start from ``x_idx = values``, ``x = 0`` elsewhere, with ``Z`` the unit
        vectors of the other variables (the variables ``idx`` are held fixed)."""
        if len(idx) == 0:
            self.reset()
            return
        n, k = self.n, len(idx)
        w = self.w
        w[:, :n] = 0.0
        free = np.ones(n, dtype=bool)
        free[idx] = False
        w[np.flatnonzero(free), np.arange(k, n)] = 1.0
        w[:n, n] = 0.0
        w[idx, n] = values
        w[n, n] = 1.0
        self.c0 = k
        self.nf = n - k
        self.identity = False
        self.moved = True

    def basis(self) -> np.ndarray:
        """The current basis ``Z`` (``n x nf`` view, orthonormal columns)."""
        return self.w[: self.n, self.c0 : self.n]

    def set_point(self, x: np.ndarray) -> None:
        """Move the current point to ``x`` (which must lie in ``x + range(Z)``)."""
        _copyto(self.x, x)
        self.moved = True

    def reduced(self, rows: np.ndarray) -> np.ndarray:
        """``[A Z | A x - b]`` for augmented rows ``[A | -b]`` (``m x (nf + 1)``), in a
        scratch buffer (overwritten by the next call)."""
        m = rows.shape[0]
        mv = self._mbuf[: m * (self.nf + 1)].reshape(m, self.nf + 1)
        if self.identity:
            _copyto(mv, rows)
            mv[:, self.n] += rows[:, : self.n] @ self.x
        else:
            _matmul(rows, self.w[:, self.c0 :], out=mv)
        return mv

    def step(
        self,
        rows: np.ndarray,
        scale: float,
        rank_tol: float,
        damping: float = 0.0,
        need_basis: bool = True,
        full_rank_only: bool = False,
        freeze: bool = False,
    ) -> int:
        """Treat the augmented equality rows ``[A | -b]`` in ``x + range(Z)``.

        Returns the rank ``r`` of the block in the current null space. With
        ``full_rank_only`` nothing changes and ``-1`` is returned when ``r`` is less than
        the number of rows (the caller then splits the block). ``freeze`` pins the rows
        at their current values (only ``Z`` changes). ``need_basis=False``: no later
        level reads ``Z``, which is then left stale.
        """
        m = rows.shape[0]
        nf = self.nf
        if m == 0 or nf == 0:
            # no direction left: the rows fix none (rank 0), short of full rank if any
            return -1 if full_rank_only and m > 0 else 0
        # with Z = I and x = 0, [A Z | A x - b] is the rows themselves (read-only here)
        scratch = not self.identity or self.moved
        maug = self.reduced(rows) if scratch else rows
        thr = rank_tol * scale
        if not need_basis and not freeze and not full_rank_only and m > nf and damping == 0.0:
            r = self._last_least_squares(maug, m, nf, thr)
            if r >= 0:
                return r
        qr, jpvt, tau, _, _info = _dgeqp3(maug[:, :nf].T, self._lwork, scratch)
        self.last_qr = (qr, jpvt)
        kmax = m if m < nf else nf
        if abs(qr[kmax - 1, kmax - 1]) > thr:
            r = kmax
        else:
            # |R_ii| is non-increasing along the diagonal of a column-pivoted QR
            r = int(np.count_nonzero(np.abs(qr.diagonal()[:kmax]) > thr))
        if full_rank_only and r < m:
            return -1
        if r == 0:
            return 0
        refl = qr[:, :nf] if m > nf else qr  # dormqr wants as many columns as tau
        w = self.w
        if freeze:
            self._identity_off()
            _dormqr(b"R", b"N", refl, tau, w[:, self.c0 : self.n], self._lwork, 1)
            self.c0 += r
            self.nf = nf - r
            return r
        # z = argmin ||L z - e||^2 + damping^2 ||z||^2, e = P^T (A x - b)
        ep = maug[:, nf].take(jpvt - 1)
        if r == m and damping == 0.0:
            z, _info = _dtrtrs(qr, ep, 0, 1)
        else:
            z = self._least_squares(qr, r, m, ep, damping)
        if need_basis:
            self._identity_off()
            zq = w[:, self.c0 : self.n]
            _dormqr(b"R", b"N", refl, tau, zq, self._lwork, 1)
            self.x_aug -= zq[:, :r] @ z
            self.c0 += r
            self.nf = nf - r
        else:
            v = self._vec[:nf]
            v[:r] = z
            v[r:] = 0.0
            v, _, _info = _dormqr(b"L", b"N", refl, tau, v, self._lwork, 1)
            if self.identity:
                self.x -= v
                self.moved = True
            else:
                self.x_aug -= w[:, self.c0 : self.n] @ v
        return r

    def _identity_off(self) -> None:
        self.identity = False

    def _last_least_squares(self, maug: np.ndarray, m: int, nf: int, thr: float) -> int:
        """``x <- x + Z y``, ``y = argmin ||M y + (A x - b)||`` from a pivoted QR of ``M``
        (``m > nf``); ``-1`` (nothing done) when ``M`` has rank ``< nf``."""
        # maug[:, :nf] is never Fortran-contiguous here (m > nf >= 1): f2py copies it
        qr, jpvt, tau, _, _info = _dgeqp3(maug[:, :nf], self._lwork, 0)
        if not abs(qr[nf - 1, nf - 1]) > thr:
            return -1
        c, _, _info = _dormqr(b"L", b"T", qr, tau, maug[:, nf], self._lwork, 0)
        y, _info = _dtrtrs(qr, c[:nf], 0, 0)
        v = self._vec[:nf]
        v[jpvt - 1] = y
        if self.identity:
            self.x -= v
            self.moved = True
        else:
            self.x_aug -= self.w[:, self.c0 : self.n] @ v
        return nf

    def _least_squares(
        self, qr: np.ndarray, r: int, m: int, ep: np.ndarray, damping: float
    ) -> np.ndarray:
        """``argmin ||L z - ep||^2 + damping^2 ||z||^2`` with ``L = triu(R[:r, :m])^T``."""
        rows = m + r if damping > 0.0 else m
        lt = self._lbuf[: r * rows].reshape(r, rows)
        _multiply(qr[:r, :m], self._triu[:r, :m], out=lt[:, :m])
        rhs = self._rhs[:rows]
        rhs[:m] = ep
        if damping > 0.0:
            lt[:, m:] = 0.0
            lt[:, m:].flat[:: r + 1] = damping
            rhs[m:] = 0.0
        _, z, _info = _dgels(lt.T, rhs, b"N", 64 * (rows + 1), 1, 1)
        return z[:r].copy()
