r"""The hierarchical solver's algorithm (internal to ``sotpy.solvers``): a cascade of
primal active-set solves, one per level, over one null-space decomposition. This module
is the NumPy version; :mod:`._activeset_jit` is its compiled twin.

The problem (see :mod:`.hierarchy`): levels ``k = 0..p-1`` of rows
``lower_i <= a_i x <= upper_i``; level ``k``'s violation ``v_k(x)`` (the distance of each
row to its interval) is minimised lexicographically (damped: ``+ lambda_k^2 ||x -
x_{k-1}||^2``, ``x_{k-1}`` the point the levels above left), then ``||x||``.

Active rows and the equality hierarchy
--------------------------------------
An *equality* row (``lower == upper``) is always active. An *inequality* row
(``lower < upper``) is inactive, or active at its lower or upper bound, its *target*. An
active row of level ``k`` sits in one of two places:

* its own level's least squares (``own_k``): the level could not keep the row inside its
  interval, so it minimises the row's distance to the bound, with the level's damping;
* *held* for a lower level ``j`` (``held_j``, just above ``own_j``; ``held_p`` for the
  final minimum-norm criterion): the row is met exactly at its bound because level ``j``
  pushes against it. Held rows are undamped.

The *equality hierarchy* (eHQP) of the active rows runs over the sub-levels
``held_0, own_0, held_1, own_1, ..., own_{p-1}, held_p`` by the null-space recursion

.. math::

    x_0 = 0,\ Z_0 = I;\qquad M_s = A_s Z_s,\ e_s = t_s - A_s x_s;\qquad
    M_s^T P_s = Q_s R_s\ \text{(Householder, column pivoting)};

    r_s = \#\{i : |R_{s,ii}| > \mathrm{rank\_tol}\,\phi_s\};\qquad
    u_s = \arg\min_u \|B_s^T u - P_s^T e_s\|^2 + \lambda_s^2 \|u\|^2,\
    B_s = R_s[:r_s, :];

    x_{s+1} = x_s + Y_s u_s,\qquad [Y_s\ Z_{s+1}] = Z_s Q_s

(``Y_s``: the ``r_s`` directions the sub-level fixes, ``Z_{s+1}`` those left below;
``phi_s``: the level's Frobenius norm for ``own_k``, the held rows' own for ``held_j``).
Held rows first, then a damped least squares in the directions they leave, is exactly
the damped least squares constrained by the held rows (the correction that meets them is
orthogonal to those directions). Each step lies in the span of the fixed directions, so
the last point is the minimum-norm point of the last optimal set.

Multipliers
-----------
For objective ``j`` (``own_j``'s least squares, gradient ``g_j = A_j^T w_j +
\lambda_j^2 (x_{s+1} - x_s)`` with ``w_j = A_j x - t_j`` on its active rows; ``j = p``:
``||x||^2/2``, ``g_p = x``), the multipliers of the active rows of the sub-levels above
solve ``g_j + \sum A_s^T \mu_s = 0``; by blocks from the sub-level just above up to the
first, ``B_s (P_s^T \mu_s) = -Y_s^T (g_j + \sum_{s' > s} A_{s'}^T \mu_{s'})`` (the
*basic* solution: the rows past the rank get 0). Releasing an active row ``i`` (its value
moved into its interval, the other active rows kept) changes objective ``j`` by
``sigma_i \mu_i`` to first order (``sigma_i = +1`` at the upper bound, ``-1`` at the
lower one): ``sigma_i \mu_i > 0`` *decides* the row (it stays, pinned: the levels below
cannot move it), ``< 0`` releases it. A multiplier counts when ``|\mu_i| ||a_i||`` exceeds
``dual_tol`` times the gradient's scale (``||A_j||_F ||w_j||``, or ``||x||``); a level met
to ``eps`` has no gradient.

The cascade
-----------
Phase ``j = 0..p-1`` minimises level ``j`` over the set the levels above left; phase ``p``
the norm. Phase 0 starts at the eHQP point of the previous call's active rows (the answer,
when they are still right; with none, the equality rows' solution: not the origin, where
homogeneous rows such as friction cones all meet at their apex), each later phase where
the one above stopped, with the previous call's active rows as its first guess; the rows
of level ``j`` violated where the phase starts join its least squares (any point is a
start for phase 0: level 0 has no level above to keep). When the eHQP point violates level
0 and the previous call's answer is given, phase 0 starts instead at that answer corrected
onto level 0's active rows (``held_0`` then ``own_0``: the smallest correction that meets
them), if level 0's violation (``||v_0||^2``) is smaller there. The eHQP point of rows
that are no longer right can lie far outside level 0 (when the load leaves a contact, past
the apex of its friction cones: dozens of rows violated at once), and minimising that
violation walks along the rows one at a time; the corrected answer met level 0 one call
ago, so the rows it violates are the few whose bounds moved since, and the steps towards
the eHQP point meet the rows that became active on the way (on the Talos torque
hierarchy, ticks of 75 to 104 iterations take 3 to 9). Then it repeats:

1. ``x^+`` = the phase's target, ``d = x^+ - x``. The target moves ``x`` only in the
   directions of the phase's sub-levels (``Y_{2j}``, ``Y_{2j+1}``: ``held_j`` then
   ``own_j``), to their least-squares values from ``x`` (damped: the damped least
   squares of those coordinates, the others as ``x`` has them); the coordinates fixed
   above stay as they are, those left below (``Z_{2j+2}``) are set to 0 when damped (the
   damping's optimum is the recursion's point) and kept when not (the phase's optimal
   set is flat there: the phases below choose within it). Phase ``p``'s target zeroes
   the coordinates left after ``held_p``. Taking the recursion's whole point
   ``x_{2j+2}`` instead would also move the coordinates above to their values *for the
   current active rows*, and a row that depends on the rows above (met at ``x`` only
   because they are) could then block the step at ``tau = 0`` again and again: a cycle.
   With the coordinates above kept, such a row is met all along the step and never
   blocks. The step ``x + tau d`` stops at the first inactive row of the levels ``<= j``
   (every level in phase ``p``) that reaches a bound (``tau < 1``); the row becomes
   active: in ``own_j`` if it is level ``j``'s, else held for ``j``. Rows of lower
   levels play no part. The held rows of the phase that are not met at the new point
   (the previous call's guesses, on their way to their bound) are released, so that the
   held rows are always met constraints and a blocking row independent of them; held
   rows that depend on the rows above them (the eHQP's rank says so) leave too.
2. At ``x^+``: ``own_j``'s rows strictly inside their interval are released (their
   residual has the wrong sign). Then the multipliers of objective ``j`` judge the rows
   that are met (own rows of the levels above, held rows) and not yet decided: a wrong
   one is released (the largest score) and the phase goes on; else the phase is done and
   the rows it decided stay pinned for the phases below.

Phase ``j``'s steps change nothing in the sub-levels above ``held_j``: the levels above
stay optimal and their decided rows keep their multipliers. Within a phase each step is a
descent of the phase's convex objective (strictly convex when damped). A row released and
blocked again at once (``tau = 0``: degenerate multipliers) is not released again until
another row changes. Nothing else limits the releases: a phase ends only when no
significant multiplier has the wrong sign (a cap on how often a row may be released
would end phases at a wrong row and call them optimal), and a cycle, should one occur,
ends at the budget and is reported as a budget stop.

The budget
----------
One iteration is one eHQP (the compiled twin restarts it at the first sub-level whose
rows changed, and computes only the sub-levels down to ``own_j`` during phase ``j``: a
phase reads nothing below; the next phase's first step completes them, which is not
counted as an iteration since no row changed). The call stops after ``max_iter`` eHQP
solves, or when the thread's CPU time would pass the ``deadline`` (set by the caller:
its entry time plus its budget, less a share kept for the return; the work before the
kernel, such as copying the levels, counts)
with one more iteration of the largest cost seen so far (the first counted from the
kernel's start: the input checks, the first eHQP and the start check) and then the last
step below, which costs about one more: the call ends within its budget unless an
iteration costs more than every one before it, and then by at most that excess.
Stopped in phase ``j``: levels ``< j`` are optimal; a last step (one eHQP with the
current active rows of every level; its target corrects the coordinates of the
sub-levels from ``held_j`` down and keeps those above, and the step goes from the
current point up to the first inactive row of the levels ``<= j`` it would leave) adds
the levels below, so level ``j`` is no worse than when the phase began and no row of
the levels ``<= j`` is left. ``info[2]`` is ``j`` (``p + 1``: optimal).

Input: ``x`` holds the previous call's answer (NaN: none; a refused input leaves it as
it was). Output: ``x``, ``res``
(``||v_k(x)||`` per level), ``ranks`` (the directions each level's rows fixed, its held
rows included), ``fro`` (``||A_k||_F``), ``info = [iterations, reason, solved levels,
error, error row, error column, active inequality rows, inequality rows]``; ``reason``:
:data:`OPTIMAL`, :data:`ITERATIONS`, :data:`TIME`; ``error``: :data:`OK` or the first
problem found in the input or the result. ``status`` (-1, 0, +1) and ``attach`` (the
level a row is held for; its own level when in ``own``) carry the warm start from one
call to the next.
"""

from __future__ import annotations

import math
import time

import numpy as np
from scipy.linalg import lapack

__all__ = ["solve"]

#: why the iteration stopped (``info[1]``)
OPTIMAL, ITERATIONS, TIME = 0, 1, 2
#: ``info[3]``: what is wrong with the input or the result
OK, NONFINITE_MATRIX, NAN_BOUND, CROSSED_BOUNDS, INFINITE_EQUALITY, NONFINITE_RESULT = range(6)
#: row kinds
EQ, INEQ, FREE = 0, 1, 2
#: a list to record the iteration's events in (tests and debugging), or None
TRACE: list | None = None


class _Ehqp:
    """The eHQP of the current active rows (NumPy): per sub-level its rows, rank,
    pivots, factor ``B`` and first basis column; the basis ``Y`` and the points."""

    __slots__ = ("B", "Y", "c", "piv", "r", "rows", "xs")


def _ehqp(A, t, subrows, lams, phis, rank_tol, upto) -> _Ehqp:
    """Sub-levels ``0..upto-1`` of the recursion (see the module docstring)."""
    n = A.shape[1]
    out = _Ehqp()
    Y = np.eye(n)  # columns c..n-1: Z, the directions left
    x = np.zeros(n)
    ns = len(subrows)
    out.r = np.zeros(ns, dtype=np.int64)
    out.c = np.zeros(ns + 1, dtype=np.int64)
    out.piv, out.B = [None] * ns, [None] * ns
    out.xs = [x] * (ns + 1)
    c = 0
    for s in range(upto):
        out.c[s] = c
        rows = subrows[s]
        mk, nf = len(rows), n - c
        out.xs[s + 1] = x
        if mk == 0 or nf == 0:
            continue
        As = A[rows]
        qr, jpvt, tau, _, _ = lapack.dgeqp3(np.array((As @ Y[:, c:]).T, order="F"))
        kmin = min(nf, mk)
        r = int(np.count_nonzero(np.abs(np.diagonal(qr)[:kmin]) > rank_tol * phis[s]))
        piv = jpvt - 1
        out.piv[s] = piv
        if r == 0:
            continue
        B = np.triu(qr[:r, :])  # r x mk, columns in pivot order
        rhs = (t[rows] - As @ x)[piv]
        if lams[s] == 0.0 and mk == r:
            u, _ = lapack.dtrtrs(B[:, :r], rhs, lower=0, trans=1)
        else:
            S = np.vstack([B.T, lams[s] * np.eye(r)])
            u = np.linalg.lstsq(S, np.concatenate([rhs, np.zeros(r)]), rcond=None)[0]
        Y[:, c:], _, _ = lapack.dormqr("R", "N", qr[:, :r], tau[:r], Y[:, c:], lwork=max(1, 4 * n))
        x = x + Y[:, c : c + r] @ u
        out.xs[s + 1] = x
        out.r[s], out.piv[s], out.B[s] = r, piv, B
        c += r
    for s in range(upto, ns):
        out.c[s] = c
        out.xs[s + 1] = x
    out.c[ns] = c
    out.Y, out.rows = Y, subrows
    return out


def _correct(A, t, e: _Ehqp, s: int, x: np.ndarray, lam: float = 0.0) -> np.ndarray:
    """``x`` moved in sub-level ``s``'s directions ``Y_s`` only (its coordinates in the
    other directions kept) to the sub-level's optimum, with its own factorisation:
    undamped, the smallest correction that gives the rows their least-squares values;
    damped, the coordinates ``u`` that minimise ``||B_s^T u - P_s^T e||^2 + lam^2
    ||u||^2`` (the recursion's damping, with the other coordinates as ``x`` has them)."""
    r = e.r[s]
    if r == 0:
        return x
    rows, piv, B = e.rows[s], e.piv[s], e.B[s]
    Ys = e.Y[:, e.c[s] : e.c[s] + r]
    rhs = (t[rows] - A[rows] @ x)[piv]
    if lam:
        ux = Ys.T @ x
        S = np.vstack([B.T, lam * np.eye(r)])
        u = np.linalg.lstsq(S, np.concatenate([rhs + B.T @ ux, np.zeros(r)]), rcond=None)[0]
        return x + Ys @ (u - ux)
    if len(rows) == r:
        u, _ = lapack.dtrtrs(B[:, :r], rhs, lower=0, trans=1)
    else:
        u = np.linalg.lstsq(B.T, rhs, rcond=None)[0]
    return x + Ys @ u


def _toward(A, t, e: _Ehqp, s0: int, s1: int, x: np.ndarray, lam_sub) -> np.ndarray:
    """``x`` corrected by sub-levels ``s0..s1-1`` in turn, then its coordinates in the
    directions they leave (``Z_{s1}``) set to 0: the recursion's point, the coordinates
    above ``s0`` as ``x`` has them (the recursion's own when ``x`` keeps their values)."""
    for s in range(s0, s1):
        x = _correct(A, t, e, s, x, lam_sub[s])
    Z = e.Y[:, e.c[s1] :]
    return x - Z @ (Z.T @ x)


def _multipliers(A, g, below, e: _Ehqp, m: int) -> np.ndarray:
    """The basic multipliers of the active rows of sub-levels ``< below`` for ``g``."""
    h = g.copy()
    mu = np.zeros(m)
    for s in range(below - 1, -1, -1):
        r = e.r[s]
        if r == 0:
            continue
        c = e.c[s]
        v, _ = lapack.dtrtrs(e.B[s][:, :r], -(e.Y[:, c : c + r].T @ h), lower=0, trans=0)
        rows = e.rows[s][e.piv[s][:r]]
        mu[rows] = v
        h += A[rows].T @ v
    return mu


def _ratio(A, x, d, cand, lo, up, anorm, tol):
    """The step ``x + tau d`` (``tau <= 1``) up to the first row of ``cand`` that would
    leave its interval: ``(tau, row, side)``, ``row = -1`` when none does. A row moves
    when ``|a_i d| > tol ||a_i|| ||d||`` (``tol``: twice the rank tolerance, so that a row
    the rank test finds dependent on the active rows never blocks)."""
    dn = math.sqrt(float(d @ d))
    if dn == 0.0 or len(cand) == 0:
        return 1.0, -1, 0
    ad = A[cand] @ d
    v = A[cand] @ x
    small = tol * anorm[cand] * dn
    with np.errstate(divide="ignore", invalid="ignore"):
        tu = np.where((ad > small) & (up[cand] < np.inf), (up[cand] - v) / ad, np.inf)
        tl = np.where((ad < -small) & (lo[cand] > -np.inf), (lo[cand] - v) / ad, np.inf)
    tt = np.maximum(np.minimum(tu, tl), 0.0)
    q = int(np.argmin(tt))
    if tt[q] >= 1.0:
        return 1.0, -1, 0
    return float(tt[q]), int(cand[q]), (1 if ad[q] > 0 else -1)


def _check(A, lo, up, info) -> bool:
    """The first bad entry of the input, in ``info[3:6]``; True when all is well."""
    bad = ~np.isfinite(A)
    if bad.any():
        i, j = np.argwhere(bad)[0]
        info[3:6] = (NONFINITE_MATRIX, i, j)
        return False
    for code, rows in (
        (NAN_BOUND, np.isnan(lo) | np.isnan(up)),
        (CROSSED_BOUNDS, lo > up),
        (INFINITE_EQUALITY, (lo == up) & ~np.isfinite(lo)),
    ):
        if rows.any():
            info[3:6] = (code, int(np.argmax(rows)), 0)
            return False
    return True


def solve(A, lo, up, starts, status, attach, lams, rank_tol, eps, dual_tol, max_iter,
          deadline, x_out, res, ranks, fro, info, wf=None, wi=None) -> None:  # fmt: skip
    """See the module docstring; ``deadline`` is the budget's end on the thread CPU clock
    (:func:`time.thread_time`, s; ``inf``: none). The compiled twin has the same arguments
    (``wf``, ``wi``: its scratch arrays, unused here)."""
    start = time.thread_time()
    xprev = x_out.copy()
    m = A.shape[0]
    p = len(starts) - 1
    info[:] = 0
    res[:] = 0.0
    ranks[:] = 0
    with np.errstate(invalid="ignore"):
        if not _check(A, lo, up, info):
            return
        kind = np.where(lo == up, EQ, np.where(np.isfinite(lo) | np.isfinite(up), INEQ, FREE))
    level_of = np.repeat(np.arange(p), np.diff(starts))
    fro[:] = [np.linalg.norm(A[starts[k] : starts[k + 1]]) for k in range(p)]
    anorm = np.linalg.norm(A, axis=1)
    # an equality, a free row, or a bound that is no longer finite (the rows changed since
    # the last call): no target to warm-start at
    status[(kind != INEQ) | ((status > 0) & (up == np.inf)) | ((status < 0) & (lo == -np.inf))] = 0
    bad = (status == 0) | (attach < level_of) | (attach > p)
    attach[bad] = level_of[bad]
    lam_sub = np.zeros(2 * p + 1)
    lam_sub[1::2] = lams
    ineq = np.flatnonzero(kind == INEQ)
    move_tol = max(eps, 2.0 * rank_tol)

    def sub_of(i):
        return 2 * attach[i] + (1 if attach[i] == level_of[i] else 0)

    def build():
        act = np.flatnonzero((kind == EQ) | (status != 0))
        subs = [[] for _ in range(2 * p + 1)]
        for i in act:
            subs[sub_of(i)].append(i)
        subrows = [np.array(r, dtype=np.int64) for r in subs]
        phis = np.zeros(2 * p + 1)
        phis[1::2] = fro
        for j in range(p + 1):
            phis[2 * j] = np.linalg.norm(A[subrows[2 * j]]) if len(subrows[2 * j]) else 0.0
        return subrows, phis, np.where(status > 0, up, lo)

    decided = np.zeros(m, dtype=bool)
    locked = np.zeros(m, dtype=bool)
    longest = 0.0
    checked = start  # when the budget was last checked: the start's work counts too
    reason = OPTIMAL
    solved = p + 1
    # the first phase starts where the previous call's active rows lead: their eHQP point
    # (with nothing active, the equality rows' solution)
    subrows, phis, t = build()
    e = _ehqp(A, t, subrows, lam_sub, phis, rank_tol, 2 * p + 1)
    its = 1
    x = e.xs[2 * p + 1]
    stale = False
    # x is the recursion's point of the current active rows, nothing changed since: every
    # phase's target is x itself (the usual tick: the guess was right)
    at_ehqp = True
    lev0 = slice(starts[0], starts[1]) if p > 0 else slice(0, 0)
    warm0 = p > 0 and bool(np.isfinite(xprev).all())
    v0 = _violation(A[lev0], lo[lev0], up[lev0], anorm[lev0], eps, x) if warm0 else 0.0
    met0 = warm0 and v0 == 0.0  # x meets level 0: its phase has no violated row to add
    if v0 > 0.0:
        # ... unless it violates level 0 more than the previous answer does once corrected
        # onto level 0's active rows (the smallest correction that meets them): then the
        # phase starts there, near a point that met level 0 a call ago
        xc = _correct(A, t, e, 1, _correct(A, t, e, 0, xprev))
        if _violation(A[lev0], lo[lev0], up[lev0], anorm[lev0], eps, xc) < v0:
            x = xc
            at_ehqp = False
    for j in range(p + 1):
        upto = 2 * j + 2 if j < p else 2 * p + 1  # the sub-levels phase j sees
        scope = ineq[level_of[ineq] <= min(j, p - 1)]  # the rows that may block
        released = -1
        # level j's rows violated where the phase starts join its least squares (none when
        # the start check above found level 0 met at this very point: no second scan)
        if j < p and not (j == 0 and met0):
            mine = ineq[(level_of[ineq] == j) & ((status[ineq] == 0) | (attach[ineq] > j))]
            if len(mine):
                v = A[mine] @ x
                tol = eps * (1.0 + anorm[mine] * max(1.0, float(np.abs(x).max())))
                out = (v > up[mine] + tol) | (v < lo[mine] - tol)
                status[mine[v > up[mine] + tol]] = 1
                status[mine[v < lo[mine] - tol]] = -1
                attach[mine[out]] = j
                stale = stale or bool(out.any())
        while True:
            if stale:
                # an iteration is all the work from one check to the next (the eHQP, the
                # target, the step, the verdict): the longest so far predicts the next,
                # and the last step of a stopped call (one more eHQP) must fit after it
                now = time.thread_time()
                longest = max(longest, now - checked)
                checked = now
                if its >= max_iter or now + 2.0 * longest > deadline:
                    reason = ITERATIONS if its >= max_iter else TIME
                    break
                subrows, phis, t = build()
                e = _ehqp(A, t, subrows, lam_sub, phis, rank_tol, 2 * p + 1)
                its += 1
                stale = at_ehqp = False
            # held rows that depend on the rows above them (a guess from the previous call
            # that no longer fits, a degenerate vertex) leave: held rows are constraints the
            # point must meet
            rows = e.rows[2 * j]
            if e.r[2 * j] < len(rows):
                dep = rows if e.piv[2 * j] is None else rows[e.piv[2 * j][e.r[2 * j] :]]
                status[dep] = 0
                if TRACE is not None:
                    TRACE.append(("dependent", j, [int(i) for i in dep]))
                stale = True
                continue
            # the phase's target: level j's rows (held, then its own least squares, damped
            # towards where the levels above leave the point) fitted by the smallest
            # correction of x; the last phase: the minimum-norm point
            if at_ehqp:
                xj = x
            elif j < p:
                if lam_sub[2 * j + 1]:  # damped: the recursion's point (the damping's optimum)
                    xj = _toward(A, t, e, 2 * j, 2 * j + 2, x, lam_sub)
                else:
                    xj = _correct(A, t, e, 2 * j + 1, _correct(A, t, e, 2 * j, x))
            else:
                xj = _toward(A, t, e, 2 * p, 2 * p + 1, x, lam_sub)
            # the rows that may block: those of the levels <= j not active in the sub-levels
            # this phase sees (a row held for a phase below is free here)
            sub = 2 * attach[scope] + (attach[scope] == level_of[scope])
            cand = scope[(status[scope] == 0) | (sub >= upto)]
            # the step, up to the first of them that reaches a bound: held for this phase
            blocked = False
            if not at_ehqp:
                tau, i, side = _ratio(A, x, xj - x, cand, lo, up, anorm, move_tol)
                if i < 0:
                    x = xj
                else:
                    x = x + tau * (xj - x)
                    if i == released and tau == 0.0:
                        locked[i] = True  # released and blocked at once: not again ...
                    else:
                        locked[:] = False  # ... until something else changes
                    # held rows of the phase not met yet (guesses from the previous call, on
                    # their way to their bound) leave: the held rows must be met constraints
                    # for the next blocking row to be independent of them
                    held = ineq[(status[ineq] != 0) & (attach[ineq] == j) & (level_of[ineq] < j)]
                    if len(held):
                        gap = np.abs(A[held] @ x - t[held])
                        tol = eps * (1.0 + anorm[held] * max(1.0, float(np.abs(x).max())))
                        status[held[gap > tol]] = 0
                    status[i] = side
                    attach[i] = j
                    if TRACE is not None:
                        TRACE.append(("block", j, i, tau, j))
                    released = -1
                    stale = blocked = True
            if blocked:
                continue
            if j == p:
                verdict = _verify(A, x, t, e, status, attach, decided, locked, level_of,
                                  anorm, lam_sub, fro, ineq, j, p, eps, dual_tol, xj)  # fmt: skip
                if TRACE is not None:
                    TRACE.append(("verify", j, verdict))
                if verdict is True:
                    break
                released = verdict
                stale = True
                continue
            # own_j's active rows strictly inside their interval are released
            own = ineq[(level_of[ineq] == j) & (status[ineq] != 0) & (attach[ineq] == j)]
            if len(own):
                v = A[own] @ x
                tol = eps * (1.0 + anorm[own] * max(1.0, float(np.abs(x).max())))
                # beyond the other bound: that bound is the target now
                flip = ((status[own] > 0) & (v < lo[own] - tol)) | (
                    (status[own] < 0) & (v > up[own] + tol)
                )
                status[own[flip]] = -status[own[flip]]
                inside = ~flip & (
                    ((status[own] > 0) & (v < up[own] - tol))
                    | ((status[own] < 0) & (v > lo[own] + tol))
                )
                if flip.any() and not inside.any():
                    stale = True
                    continue
                if inside.any():
                    status[own[inside]] = 0
                    if TRACE is not None:
                        TRACE.append(("inside", j, [int(i) for i in own[inside]]))
                    stale = True
                    continue
            verdict = _verify(A, x, t, e, status, attach, decided, locked, level_of,
                              anorm, lam_sub, fro, ineq, j, p, eps, dual_tol, xj)  # fmt: skip
            if TRACE is not None:
                TRACE.append(("verify", j, verdict))
            if verdict is True:
                break
            released = verdict
            stale = True
        if reason != OPTIMAL:
            solved = j
            break
    if reason != OPTIMAL:
        # the last step: every level's active rows, up to the first row of the levels
        # <= solved that it would leave
        subrows, phis, t = build()
        e = _ehqp(A, t, subrows, lam_sub, phis, rank_tol, 2 * p + 1)
        its += 1
        scope = ineq[(level_of[ineq] <= min(solved, p - 1)) & (status[ineq] == 0)]
        d = _toward(A, t, e, 2 * solved, 2 * p + 1, x, lam_sub) - x
        tau, _, _ = _ratio(A, x, d, scope, lo, up, anorm, move_tol)
        x = x + tau * d
    _finish(A, lo, up, starts, x, e, status, ineq, its, reason, solved, x_out, res, ranks, info)


def _verify(A, x, t, e, status, attach, decided, locked, level_of, anorm, lam_sub,
            fro, ineq, j, p, eps, dual_tol, xj):  # fmt: skip
    """Phase ``j``'s multipliers judge the met active rows above ``own_j`` that no phase
    above decided: True when none is wrong (those with a significant multiplier are then
    decided, pinned for the phases below), else the row released."""
    below = 2 * j + 1 if j < p else 2 * p + 1
    xi = max(1.0, float(np.abs(x).max(initial=0.0)))
    act = ineq[status[ineq] != 0]
    w = A @ x - t
    sub = 2 * attach[act] + (attach[act] == level_of[act])
    met = np.abs(w[act]) <= eps * (1.0 + anorm[act] * xi)
    cand = act[(sub < below) & met & ~decided[act]]
    if len(cand) == 0:
        return True
    if j < p:
        rows = e.rows[2 * j + 1]
        wn = float(np.linalg.norm(w[rows])) if len(rows) else 0.0
        xn = math.sqrt(float(x @ x))
        if wn <= eps * (1.0 + fro[j] * xn + float(np.linalg.norm(t[rows]))):
            return True  # the level is met: no gradient
        g = A[rows].T @ w[rows]
        gscale = fro[j] * wn
        lam = lam_sub[2 * j + 1]
        if lam:
            step = xj  # the damping's gradient: lambda^2 x
            g = g + lam**2 * step
            gscale += lam**2 * float(np.linalg.norm(step))
    else:
        g = x
        gscale = math.sqrt(float(x @ x))
        if gscale == 0.0:
            return True
    mu = _multipliers(A, g, below, e, len(w))
    li = mu[cand] * anorm[cand] / gscale
    sig = np.abs(li) > dual_tol
    wrong = cand[sig & (status[cand] * li < 0) & ~locked[cand]]
    if len(wrong) == 0:
        # the phase is done: the rows it kept are pinned for the phases below
        decided[cand[sig & (status[cand] * li > 0)]] = True
        return True
    i = int(wrong[np.argmax(np.abs(li[np.isin(cand, wrong)]))])
    status[i] = 0
    return i


def _violation(A, lo, up, anorm, eps, x) -> float:
    """``||v(x)||^2``: the squared distance of the rows ``A x`` to their intervals beyond
    the feasibility tolerance (``eps (1 + ||a_i|| max(1, ||x||_inf))``: 0 when every row
    counts as met)."""
    ax = A @ x
    tol = eps * (1.0 + anorm * max(1.0, float(np.abs(x).max(initial=0.0))))
    v = np.maximum(lo - tol - ax, 0.0) + np.maximum(ax - up - tol, 0.0)
    return float(v @ v)


def _finish(A, lo, up, starts, x, e, status, ineq, its, reason, solved, x_out, res, ranks, info):
    if not np.isfinite(x).all():
        info[3] = NONFINITE_RESULT
    ax = A @ x
    with np.errstate(invalid="ignore"):
        v = np.maximum(lo - ax, 0.0) + np.maximum(ax - up, 0.0)
    for k in range(len(starts) - 1):
        res[k] = math.sqrt(float(v[starts[k] : starts[k + 1]] @ v[starts[k] : starts[k + 1]]))
        ranks[k] = e.r[2 * k] + e.r[2 * k + 1]
    x_out[:] = x
    info[0], info[1], info[2] = its, reason, solved
    info[6] = int(np.count_nonzero(status[ineq]))
    info[7] = len(ineq)
