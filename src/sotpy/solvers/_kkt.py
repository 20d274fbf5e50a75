r"""One KKT solve for the common shape of a stack (internal to ``sotpy.solvers``).

Most ticks of an SOT have the same shape: every level but the last is of full row rank
(they are met exactly: feet, CoM, a hand), and the last one (the posture) has more
rows than directions left, or there is no such last level. The lexicographic optimum is
then the solution of one equality-constrained least-squares problem,

.. math::

    \min_x \tfrac12 \|L x - c\|^2 \quad \text{s.t.} \quad U x = d

(``U``: the upper levels' rows and, on the box path, the fixed variables' unit rows;
``L``: the last level), or the minimum-norm solution of ``U x = d`` when every level is
in ``U``. Both are one linear system, the KKT system

.. math::

    \begin{bmatrix} H & U^T \\ U & 0 \end{bmatrix}
    \begin{bmatrix} x \\ \mu \end{bmatrix} =
    \begin{bmatrix} L^T c \\ d \end{bmatrix}, \qquad H = L^T L \text{ or } I,

nonsingular exactly when ``U`` has full row rank and ``H`` is positive definite on the
null space of ``U``; its solution is then the unique optimum, which is the
lexicographic one (each upper level is met exactly, the last one is optimal over what
they leave, and the solution is unique, hence of minimum norm). One solve replaces the
level-by-level factorisations.

Two ways to the same solution. Compiled (numba), by the null-space method of
:mod:`._boxkkt` (:func:`._boxkkt.kkt`): the fixed variables moved to the right-hand
sides, a QR of ``U_F^T``, a QR of ``L_F Q_2``, the multipliers from ``R``; about a
third of the flops of the assembled system (on the active benchmark stack, ``n = 40``,
8 fixed variables, 25 upper and 34 last rows, the active-set solve went from 384 to
304-310 µs median). Without numba, the system assembled and solved by ``dgesv``. The
solve is used only when it is well conditioned, so that the answer is accurate to about
``1e-16 / RCOND_MIN`` relative: compiled, ``rcond(R) >= RCOND_MIN`` and ``rcond(L_F
Q_2)^2 >= RCOND_MIN`` (``dtrcon``'s 1-norm estimates for the triangular factors: ``U``
far from rank deficiency, and the reduced Hessian ``(L_F Q_2)^T (L_F Q_2)`` too); with
NumPy, the assembled matrix's reciprocal condition number (``dgecon``, 1-norm) at least
:data:`RCOND_MIN`. Otherwise (a level close to rank deficiency, a singular
configuration) the caller runs the null-space recursion, whose rank threshold
decides.

The multipliers ``mu`` (of the fixed variables' rows, then of the rows of ``U``) are
the constraints' multipliers at the last level: releasing a constraint ``j`` along the
direction ``d`` that moves its row by ``s_j`` (into the box for a fixed variable, into
the interval for an inequality row held at a bound) and keeps the other constraints
changes the last level's objective at the rate ``-s_j mu_j`` (the gradient is
``-U^T mu``). The upper levels are met exactly, so they do not decide a bound: its
verdict is this rate (see :mod:`._boxset` and the general rows of
:mod:`.hierarchy`'s active-set path).
"""

from __future__ import annotations

import numpy as np
from scipy.linalg.lapack import dgecon as _dgecon
from scipy.linalg.lapack import dgesv as _dgesv

from .._jit import c_float64
from . import _boxkkt

_refused: list[bool] = []  # the compiled kernel refused its arguments once


#: smallest reciprocal condition number of the KKT matrix accepted (else: null space)
RCOND_MIN = 1e-9


def kkt_solve(
    upper: np.ndarray,
    last: np.ndarray | None,
    n: int,
    fixed: np.ndarray,
    values: np.ndarray,
    compiled: bool = True,
) -> tuple[np.ndarray, np.ndarray] | None:
    """Solve the KKT system above.

    Args:
        upper: the augmented rows ``[U | -d]`` of the upper levels (``m_u x (n + 1)``).
        last: the augmented rows ``[L | -c]`` of the last level, or None (minimum norm).
        n: number of variables.
        fixed: indices of the fixed variables (their unit rows are added to ``U``).
        values: their values.

    Returns:
        ``(x, mu)``, ``mu`` the multipliers of the fixed variables' rows then of the
        rows of ``upper``; or None when the system is singular or its reciprocal
        condition number is below :data:`RCOND_MIN`.
    """
    w = len(fixed)
    if _boxkkt.kkt is not None and compiled and not _refused:
        rows = c_float64(upper if last is None else np.concatenate([upper, last]))
        try:
            ok, sol = _boxkkt.kkt(
                rows,
                upper.shape[0],
                last is not None,
                n,
                np.asarray(fixed, dtype=np.int64),
                np.asarray(values, dtype=np.float64),
                RCOND_MIN,
            )
        except TypeError:  # types the kernel was not compiled for: NumPy from now on
            _refused.append(True)
        else:
            return (sol[:n], sol[n:]) if ok else None
    mu = upper.shape[0]
    size = n + w + mu
    K = np.zeros((size, size), order="F")
    rhs = np.zeros(size)
    if last is None:
        K[:n, :n].flat[:: n + 1] = 1.0
    else:
        L = last[:, :n]
        np.matmul(L.T, L, out=K[:n, :n])
        np.matmul(L.T, last[:, n], out=rhs[:n])
        np.negative(rhs[:n], out=rhs[:n])  # L^T c, c = -last[:, n]
    if w:
        cols = np.arange(n, n + w)
        K[fixed, cols] = 1.0
        K[cols, fixed] = 1.0
        rhs[n : n + w] = values
    U = upper[:, :n]
    K[:n, n + w :] = U.T
    K[n + w :, :n] = U
    np.negative(upper[:, n], out=rhs[n + w :])
    anorm = float(np.abs(K).sum(axis=0).max())
    lu, _piv, sol, info = _dgesv(K, rhs, 1, 1)
    if info != 0:
        return None
    rcond, info = _dgecon(lu, anorm, "1")
    if info != 0 or not rcond >= RCOND_MIN:
        return None
    return sol[:n], sol[n:]
