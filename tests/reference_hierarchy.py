"""Plain reference implementations of the hierarchical least-squares problem (tests only).

Written for clarity, independently of ``sotpy.solvers``: no reduced bases, no LAPACK
calls, no shortcut, no warm start.

* :func:`projector_hierarchy`: equality-only stacks, n x n projectors and an SVD
  pseudo-inverse per level (Siciliano-Slotine), undamped or damped with the same
  definition as sotpy (damped least squares of each level inside the exact null space of
  the levels above, that null space given by the rank threshold).
* :func:`cascade_hierarchy`: any stack, a level-by-level cascade of QPs in the full
  variable ``x`` solved with proxsuite at eps 1e-10: level ``k`` minimises
  ``||w||^2`` subject to ``lower <= A_k x - w <= upper`` and to every level above frozen
  at its optimal slack (a row violated at the optimum pinned at its value, the others
  kept in their interval); a last QP returns the minimum-norm point of the final
  optimal set.
* :func:`violation`: the per-row violation of ``lower <= A x <= upper``.
"""

from __future__ import annotations

import numpy as np
import proxsuite


def violation(A: np.ndarray, lower: np.ndarray, upper: np.ndarray, x: np.ndarray) -> np.ndarray:
    """Per-row distance of ``A x`` to ``[lower, upper]`` (zero when satisfied)."""
    ax = A @ x
    return np.maximum(lower - ax, 0.0) + np.maximum(ax - upper, 0.0)


def level_residuals(levels, x: np.ndarray) -> np.ndarray:
    """``||violation_k(x)||_2`` for every level ``(A, lower, upper)``."""
    return np.array([np.linalg.norm(violation(A, lo, up, x)) for A, lo, up in levels])


def projector_hierarchy(
    levels, damping=0.0, rank_tol: float = 1e-9
) -> tuple[np.ndarray, list[float]]:
    """Equality-only hierarchy by n x n projectors and SVD.

    ``levels`` is a list of ``(A, b)``. Level k: ``M = A_k P``; singular values below
    ``rank_tol * ||A_k||_F`` are dropped;
    ``x += M^# (b_k - A_k x)`` with ``M^# = V diag(s / (s^2 + damping^2)) U^T`` over the
    kept singular values; ``P -= V V^T`` (kept right singular vectors). ``damping`` is
    one number or one per level. Returns ``x`` and the optimal residual norm of each
    level, ``||A_k x_k - b_k||`` right after level ``k`` (the lexicographic optimum of
    level ``k``).
    """
    n = levels[0][0].shape[1]
    x = np.zeros(n)
    P = np.eye(n)
    optimal = []
    dampings = np.broadcast_to(np.asarray(damping, dtype=float), (len(levels),))
    for (A, b), damping in zip(levels, dampings, strict=True):
        M = A @ P
        if M.size == 0:
            optimal.append(0.0)
            continue
        U, s, Vt = np.linalg.svd(M, full_matrices=False)
        keep = s > rank_tol * np.linalg.norm(A)
        U, s, Vt = U[:, keep], s[keep], Vt[keep]
        e = b - A @ x
        x = x + Vt.T @ ((s / (s**2 + damping**2)) * (U.T @ e))
        P = P - Vt.T @ Vt
        P = 0.5 * (P + P.T)
        optimal.append(float(np.linalg.norm(A @ x - b)))
    return x, optimal


def _qp(n, H, g, E, f, C, lo, up, eps):
    """min 1/2 v^T H v + g^T v  s.t.  E v = f, lo <= C v <= up (proxsuite, cold start)."""
    me, mi = E.shape[0], C.shape[0]
    qp = proxsuite.proxqp.dense.QP(n, me, mi)
    qp.settings.eps_abs = eps
    qp.settings.eps_rel = 0.0
    qp.settings.max_iter = 100000
    qp.settings.verbose = False
    # every QP here is feasible by construction (the previous level's solution satisfies
    # all its rows): keep proxsuite's infeasibility test from misfiring on thin sets
    qp.settings.eps_primal_inf = 1e-30
    qp.settings.eps_dual_inf = 1e-30
    qp.settings.check_duality_gap = True
    qp.settings.eps_duality_gap_abs = eps
    qp.settings.eps_duality_gap_rel = eps
    qp.init(
        H,
        g,
        E if me else None,
        f if me else None,
        C if mi else None,
        lo if mi else None,
        up if mi else None,
    )
    qp.solve()
    status = qp.results.info.status
    if status != proxsuite.proxqp.QPSolverOutput.PROXQP_SOLVED:
        if eps < 1e-8:
            # proxsuite sometimes stalls just above a very small eps on the degenerate
            # sets left by frozen levels: retry looser (the tests' tolerances are 1e-6)
            return _qp(n, H, g, E, f, C, lo, up, eps * 10)
        raise RuntimeError(f"reference QP not solved: {status}")
    return np.array(qp.results.x), np.array(qp.results.z)


def _pad(M: np.ndarray, m: int) -> np.ndarray:
    """``[M, 0]`` with ``m`` zero columns (no cost on the slack variables)."""
    return np.hstack([M, np.zeros((M.shape[0], m))])


def cascade_hierarchy(levels, eps: float = 1e-10, margin: float = 1e-9, damping: float = 0.0):
    """Lexicographic optimum by a plain cascade of QPs in the full variable ``x``.

    Returns ``(x, optimal)``: the minimum-norm point of the final optimal set and the
    optimal violation norm of each level over the optimal set of the levels above.
    With ``damping`` (lambda, one number or one per level), level ``k`` minimises
    ``||w||^2 + lambda^2 ||x||^2`` (Tikhonov within the level) and its optimal set is the
    set of the levels above with the level's rows pinned as at its solution, and (a
    damped level) the frozen rows above it pushes against (a multiplier above 1e-7 times
    the level's gradient scale) pinned at their bounds, as the solver defines it.
    A frozen row violated at its level's optimum (equality rows included) becomes the
    equality constraint ``A_j x = A_j x_j*``; the others keep their interval widened by
    ``margin`` (so that the next QP stays feasible despite the solver's tolerance).
    """
    n = levels[0][0].shape[1]
    dampings = np.broadcast_to(np.asarray(damping, dtype=float), (len(levels),))
    E = np.zeros((0, n))
    f = np.zeros(0)
    C = np.zeros((0, n))
    clo = np.zeros(0)
    cup = np.zeros(0)
    optimal = []
    big = np.inf
    for (A, lo, up), damping in zip(levels, dampings, strict=True):
        m = A.shape[0]
        # variables v = (x, w): min 1/2 ||w||^2 + 1/2 lambda^2 ||x||^2
        # (lambda = 0: a negligible 1e-12 ||x||^2 instead)
        H = np.zeros((n + m, n + m))
        H[n:, n:] = np.eye(m)
        H[:n, :n] = max(damping**2, 1e-12) * np.eye(n)
        g = np.zeros(n + m)
        Cv = np.vstack([_pad(C, m), np.hstack([A, -np.eye(m)])])
        lov = np.concatenate([clo, np.maximum(lo, -big)])
        upv = np.concatenate([cup, np.minimum(up, big)])
        v, z = _qp(n + m, H, g, _pad(E, m), f, Cv, lov, upv, eps)
        x, w = v[:n], v[n:]
        if damping > 0.0 and len(C):
            scale = np.abs(A).max(initial=1.0) * (1.0 + np.abs(w).max(initial=0.0))
            scale += damping**2 * (1.0 + np.abs(x).max())
            pushed = np.abs(z[: len(C)]) * np.abs(C).max(axis=1) > 1e-7 * scale
            E = np.vstack([E, C[pushed]])
            f = np.concatenate([f, C[pushed] @ x])
            C, clo, cup = C[~pushed], clo[~pushed], cup[~pushed]
        optimal.append(float(np.linalg.norm(violation(A, lo, up, x))))
        pinned = (lo == up) | (np.abs(w) > 10 * margin)
        E = np.vstack([E, A[pinned]])
        f = np.concatenate([f, A[pinned] @ x])
        C = np.vstack([C, A[~pinned]])
        clo = np.concatenate([clo, np.maximum(lo[~pinned], -big) - margin])
        cup = np.concatenate([cup, np.minimum(up[~pinned], big) + margin])
    x, _ = _qp(n, np.eye(n), np.zeros(n), E, f, C, clo, cup, eps)
    return x, optimal
