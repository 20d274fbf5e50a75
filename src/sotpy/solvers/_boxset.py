r"""Active-set path for stacks whose first level is a box (internal to ``sotpy.solvers``).

The SOT's joint-limit level is a box, ``lo_j <= x_j <= hi_j``, on some variables, above
equality tasks. For such a stack the lexicographic optimum is found without a QP once
the set ``W`` of variables held at a bound is known: fix them (``x_W = bound``), solve
the equality rows of the levels below by the null-space recursion over the other
variables, and *verify* the guess. The guess is the previous call's set (a joint at its
limit stays there for many ticks), corrected by a few primal-dual iterations; when the
verification fails after them, the caller falls back to the QP cascade and this path
takes the cascade's active set as its next guess.

Verification (the lexicographic KKT conditions, computed level by level)
-------------------------------------------------------------------------
*Primal*: every free variable within its bounds; every inequality row of the levels
below (ignored by the solve) satisfied — then the point is optimal for a relaxation
and feasible, hence optimal.

*Dual*: for ``j`` in ``W`` let ``s_j`` be the direction into the box (``+1`` at the
lower bound, ``-1`` at the upper). Releasing ``j`` means moving along a direction
``d`` with ``d_j = s_j``, ``d_i = 0`` for the other fixed variables and
``A_i d = 0`` for every level ``i`` above the current one (it keeps their optimal
fitted values, which define the optimal sets). At level ``k`` the first-order change
of the level's objective ``1/2 ||A_k x - b_k||^2`` along ``d`` is

.. math:: \delta_j = r_k^T A_k d, \qquad r_k = A_k x - b_k,

the multiplier of the bound at level ``k`` (``d`` is defined up to directions the level
is already optimal along, which do not change ``\delta``). The first level with
``\delta_j \neq 0`` decides: ``\delta_j > 0`` (leaving the bound would degrade it) the
bound is justified, and is an equality for the levels below; ``\delta_j < 0`` the guess
is wrong. When no such ``d`` keeps a level (``A_k d = 0`` has no solution), the bound
cannot move without degrading that level: justified. Bounds still undecided after the
last level are judged by the minimum-norm criterion, ``x^T d >= 0``. ``d`` is carried
from level to level by the minimum-norm correction in the free directions ``Z``:
``d <- d - Z (A_k Z)^+ A_k d``.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.linalg.lapack import dtrtrs as _dtrtrs

from . import _eqkernel

_lstsq = np.linalg.lstsq

#: relative threshold below which a multiplier counts as zero (undecided)
DUAL_TOL = 1e-10


class BoxActiveSet:
    """The box of the first level and the active set carried between calls."""

    __slots__ = ("at_hi", "at_lo", "coef", "cols", "hi", "lo", "n", "rows")

    def __init__(self, n: int) -> None:
        self.n = n
        self.at_lo = np.zeros(n, dtype=bool)
        self.at_hi = np.zeros(n, dtype=bool)
        self.lo = np.full(n, -np.inf)
        self.hi = np.full(n, np.inf)
        self.cols = self.coef = self.rows = None

    def set_box(self, A0: np.ndarray, lo: np.ndarray, hi: np.ndarray, jit: bool = False) -> bool:
        """Read the box from level 0's rows ``lo <= A0 x <= hi``; ``False`` when a row
        has not exactly one nonzero entry or two rows bound the same variable. With
        ``jit``, a box of the remembered structure is read by one compiled call."""
        cols, coef = self.cols, self.coef
        m = A0.shape[0]
        if jit and cols is not None and len(cols) == m and _eqkernel.box_update is not None:
            try:
                if _eqkernel.box_update(
                    A0, m, self.n, cols, coef, lo, hi, self.lo, self.hi, self.at_lo, self.at_hi
                ):
                    return True
            except TypeError:  # types the kernel was not compiled for: NumPy below
                pass
        same = (
            cols is not None
            and len(cols) == m
            and np.count_nonzero(A0) == m
            and (A0[self.rows, cols] == coef).all()
        )
        if not same:
            nz = A0 != 0.0
            if not (nz.sum(axis=1) == 1).all():
                return False
            cols = nz.argmax(axis=1)
            if len(np.unique(cols)) != len(cols):
                return False
            self.rows = np.arange(m)
            coef = A0[self.rows, cols]
            self.cols, self.coef = cols, coef
        with np.errstate(invalid="ignore"):
            a, b = lo / coef, hi / coef
        neg = coef < 0.0
        self.lo.fill(-np.inf)
        self.hi.fill(np.inf)
        self.lo[cols] = np.where(neg, b, a)
        self.hi[cols] = np.where(neg, a, b)
        # a remembered bound that no longer exists is dropped; equal bounds fix x_j
        self.at_lo &= np.isfinite(self.lo)
        self.at_hi &= np.isfinite(self.hi)
        fixed = self.lo == self.hi
        self.at_lo |= fixed
        self.at_hi &= ~fixed
        return True

    def remember(self, x: np.ndarray, eps: float) -> None:
        """Take the variables at a bound in ``x`` (a cascade's solution) as the next
        guess."""
        scale = eps * (1.0 + np.abs(x))
        np.less_equal(x, self.lo + scale, out=self.at_lo)
        np.greater_equal(x, self.hi - scale, out=self.at_hi)
        both = self.at_lo & self.at_hi  # lo == hi (or nearly): one side is enough
        self.at_hi &= ~both

    def fixed(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(W, values, s)``: the fixed variables, their bound values and the direction
        into the box (0 for a variable whose bounds coincide: never released)."""
        W = np.flatnonzero(self.at_lo | self.at_hi)
        at_lo = self.at_lo[W]
        values = np.where(at_lo, self.lo[W], self.hi[W])
        s = np.where(at_lo, 1.0, -1.0)
        s[self.lo[W] == self.hi[W]] = 0.0
        return W, values, s


class DualCheck:
    """The release directions of the undecided bounds and the verdict, level by level.

    ``D`` (``n x u``) holds one direction per undecided bound, ``idx`` their positions
    in ``W`` (then, for inequality rows held at a bound below level 0, added by
    :meth:`add`, positions in the caller's list of held rows offset by ``len(W)``); a
    bound leaves both when it is decided.
    """

    __slots__ = ("D", "W", "failed", "idx", "worst")

    def __init__(self, n: int, W: np.ndarray, s: np.ndarray) -> None:
        idx = np.flatnonzero(s)  # bounds that coincide are never released
        self.W = W
        self.idx = idx
        self.D = np.zeros((n, len(idx)))
        self.D[W[idx], np.arange(len(idx))] = s[idx]
        self.failed = False
        self.worst = -1  # position in W of the bound to release, when failed

    @property
    def pending(self) -> bool:
        return not self.failed and len(self.idx) > 0

    def _fail(self, delta: np.ndarray, tol: float) -> None:
        self.failed = True
        self.worst = int(self.idx[int(np.argmin(delta))])

    def _drop(self, gone: np.ndarray) -> None:
        keep = ~gone
        self.idx = self.idx[keep]
        self.D = self.D[:, keep]

    def level(
        self,
        rows: np.ndarray,
        x_aug: np.ndarray,
        basis: np.ndarray,
        rank: int,
        qr: tuple[np.ndarray, np.ndarray] | None,
    ) -> None:
        """Judge the undecided bounds at a level (augmented rows ``[A | -b]``, solved),
        then carry their directions into the level's null space.

        ``basis`` spans the free directions the level was solved in. When ``rank``
        equals the number of rows and ``qr`` is the step's pivoted QR of ``(A Z)^T``
        (``M^T P = Q R``), the first ``rank`` columns of ``basis`` are ``Y = Z Q_r``
        and ``A Y = P R^T``: the carry is two triangular solves; otherwise (``rank``
        -1) a least-squares solve in ``basis``, which also finds the bounds the level
        blocks.
        """
        n = x_aug.shape[0] - 1
        A = rows[:, :n]
        D = self.D
        T = A @ D
        tf = T.ravel()
        tt = float(tf @ tf)
        if tt == 0.0:
            return  # the level does not see these variables: nothing to judge or carry
        r = rows @ x_aug  # A x - b
        delta = r @ T
        tol = DUAL_TOL * (1.0 + math.sqrt(float(r @ r) * tt))
        if delta.min() < -tol:
            self._fail(delta, tol)
            return
        decided = delta > tol
        if decided.any():
            self._drop(decided)
            if not len(self.idx):
                return
            T = T[:, ~decided]
            D = self.D
        if rank == A.shape[0] and rank > 0 and qr is not None:
            qrf, jpvt = qr
            C, _info = _dtrtrs(qrf, T[jpvt - 1], 0, 1)
            D -= basis[:, :rank] @ C
            return
        if basis.shape[1] == 0:
            self._drop(np.ones(len(self.idx), dtype=bool))  # nothing compensates: blocked
            return
        AB = A @ basis
        C = _lstsq(AB, T, rcond=None)[0]
        miss = T - AB @ C
        tn = np.sqrt(np.einsum("ij,ij->j", T, T))
        blocked = np.sqrt(np.einsum("ij,ij->j", miss, miss)) > 1e-9 * (1.0 + tn)
        D -= basis @ (C * ~blocked)
        if blocked.any():
            self._drop(blocked)

    def add(self, A: np.ndarray, basis: np.ndarray, rows: np.ndarray, s: np.ndarray, ids) -> bool:
        """New constraints to judge from the next level on: rows ``rows`` of a level just
        solved (``A``, its rows; ``basis`` spans the directions it was solved in), held
        at a bound, each to be moved by ``s`` (into its interval) while the level's
        other rows keep their values: ``d = basis c``, ``A basis c = s_i e_i`` (any
        solution: the levels below judge ``d`` up to the level's null space, along
        which their objective is stationary). ``ids`` are the positions reported by
        :attr:`worst`. False when a row cannot move alone (it depends on the others
        there): its verdict is not defined by one direction."""
        if not len(rows):
            return True
        M = A @ basis
        T = np.zeros((A.shape[0], len(rows)))
        T[rows, np.arange(len(rows))] = s
        C = _lstsq(M, T, rcond=None)[0]
        miss = M @ C - T
        if float(np.abs(miss).max()) > 1e-9 * (1.0 + float(np.abs(M).max())):
            return False
        self.D = np.concatenate([self.D, basis @ C], axis=1)
        self.idx = np.concatenate([self.idx, ids])
        return True

    def finish(self, x: np.ndarray) -> None:
        """The minimum-norm criterion for the bounds still undecided: ``x^T d >= 0``."""
        if not self.pending:
            return
        D = self.D
        delta = x @ D
        tol = DUAL_TOL * (1.0 + math.sqrt(float(x @ x) * float(D.ravel() @ D.ravel())))
        if delta.min() < -tol:
            self._fail(delta, tol)
