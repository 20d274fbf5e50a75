r"""Hierarchical (lexicographic) least squares with equalities and inequalities.

The problem
-----------
A stack of ``p`` levels, level ``k`` being ``lower_k <= A_k x <= upper_k`` (``A_k`` of
shape ``m_k x n``; a row with ``lower == upper`` is an equality, ``-inf``/``+inf`` a
missing bound). The violation of level ``k`` at ``x`` is the vector

.. math:: v_k(x) = \max(lower_k - A_k x, 0) + \max(A_k x - upper_k, 0)

(the distance of each row to its interval). The lexicographic optimum is

.. math::

    S_0 = \mathbb{R}^n, \qquad
    S_k = \arg\min_{x \in S_{k-1}} \|v_k(x)\|^2, \qquad
    x^* = \arg\min_{x \in S_p} \|x\|^2 :

each level's violation is minimised without degrading any level above it, and among
the optimal points the minimum-norm one is returned. The optimal slack of a level is
unique, so ``S_k`` is ``S_{k-1}`` with level ``k``'s rows pinned to their optimal
violation.

Damping
-------
With ``damping = lambda > 0``, level ``k`` is solved as damped least squares inside
the set left by the levels above, starting from the previous level's point
``x_{k-1}`` (``x_0 = 0``):

.. math::

    x_k = \arg\min_{x \in S_{k-1}} \|v_k(x)\|^2 + \lambda^2 \|x - x_{k-1}\|^2, \qquad
    S_k = \{x \in S_{k-1} : A_k x \text{ has the violation of } A_k x_k\}

and ``x^*`` is the minimum-norm point of ``S_p``. As in soth, damping is inside the
level only: the levels below keep the exact null space of the levels above (for
equality levels ``S_k = x_k + \mathrm{range}(Z_k)`` with ``Z_k`` the null space of
``A_k`` in ``range(Z_{k-1})`` given by the rank threshold). For equality-only stacks
the step of level ``k`` is ``M^T (M M^T + \lambda^2 I)^{-1} (b_k - A_k x_{k-1})``,
``M = A_k Z_{k-1}``, and ``x^* = x_p``.

Rank tolerance
--------------
Each equality block is factored by a column-pivoted QR of ``(A_k Z)^T``; its rank is
the number of diagonal entries ``|R_ii| > rank_tol * ||A_k||_F`` (``rank_tol`` 1e-9 by
default). The threshold is relative to the level's own matrix, not to ``A_k Z``, so
that rows that depend on the levels above (``A_k Z`` pure round-off) get rank 0 and
rows that conflict within a level are solved in the least-squares sense, exactly.

Solution paths
--------------
* equality-only stacks: a reduced null-space recursion with LAPACK called directly
  (``dgeqp3``, ``dormqr``, ``dtrtrs``/``dgels``; compiled, :mod:`._eqkernel`, all
  but ``dgeqp3`` are loops of :mod:`._smallqr`) and preallocated buffers; undamped
  runs of levels found of full row rank at the previous call are factored as one block
  (split again if one of them lost rank);
* a first level that is a box (each row bounds one variable: the SOT's joint limits),
  undamped: the *active-set path* (:mod:`._boxset`): the variables guessed at a bound
  (the previous call's) are fixed, the equality rows below solved by the null-space
  recursion, and the guess verified (primal feasibility, lexicographic multipliers),
  corrected a few times if needed; no QP. Inequality rows of the levels below guessed
  at a bound are held there too (one KKT solve, their multipliers verified, when the
  levels above the last can be met exactly; else level by level, a held row judged by
  its own level's residual or, when met, by the levels below). With only equality rows
  below the box (the SOT's usual tick) the whole iteration is one compiled call
  (:mod:`._boxkkt`) when it can prove its answer, and the next call with the same row
  classes adds the bookkeeping and the box to that call (the *lane*; the *free lane*
  likewise when the levels below are of deficient rank and no bound is held); when
  that call cannot answer (levels of deficient rank with bounds held), each pass level
  by level with its multiplier check is one compiled call too;
* with inequalities: first the equality rows of the whole stack (the *shortcut*); if
  the point satisfies every inequality row it is the answer (it is optimal for a
  relaxation and feasible). Otherwise level by level: the equality step ignoring the
  level's inequality rows and the inequality rows frozen above, accepted if it
  satisfies them, else a QP in the reduced coordinates ``x = x_{k-1} + Z y`` (one
  persistent problem per level, DAQP by default, proxsuite as the alternative).
  After a QP the level's equality rows, its violated inequality rows and (undamped)
  the frozen rows with a nonzero multiplier are pinned as equalities (``Z`` shrinks);
  its other inequality rows are frozen as ``lower + w* <= A x <= upper + w*``, widened
  just enough to contain the current point (the QP met them to its tolerance). A last
  QP (if needed) gives the minimum-norm point.

See ``docs/solvers.md`` for the details and the measured costs.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from sotpy._blas import limit_blas_threads
from sotpy._jit import refused
from sotpy.errors import SolverError

from . import _boxkkt, _eqkernel
from ._boxset import DUAL_TOL, BoxActiveSet, DualCheck
from ._cascade import DaqpQP, ProxQP, daqp_available
from ._equality import NullspaceStepper
from ._kkt import RCOND_MIN, kkt_solve

__all__ = [
    "HierarchyResult",
    "HierarchySolver",
    "SolverError",
    "solve_hierarchy",
]

_F64 = np.dtype(np.float64)
_BACKENDS = ("auto", "proxsuite", "daqp")
_INVALID_KEY = b"\x00invalid"  # row classes never computed (no real key has 'i')
#: primal-dual corrections of the box path's active set before falling back to QPs
_BOX_ITERATIONS = 4
#: calls to skip the KKT solve after it was refused
_KKT_RETRY = 50
_NO_INDEX = np.zeros(0, dtype=np.intp)
#: a verdict of the active-set path's KKT solve: held rows released, solve again
_UNDECIDED = -2
#: relative distance to a bound within which a cascade's row counts as held at it
_HELD_TOL = 1e-7
_NO_VALUE = np.zeros(0)


class HierarchyResult:
    """What :meth:`HierarchySolver.solve` returns.

    Attributes:
        x: the solution (length ``n``, a fresh array).
        residuals: ``||v_k(x)||_2`` for every level ``k``: the violation of
            ``lower_k <= A_k x <= upper_k`` at ``x``, in the units of ``A_k x``.
        ranks: per level, the number of directions the level fixed (the rank of its
            pinned rows in the null space of the levels above; 0 for a level whose
            inequalities are inactive, and for every level with ``method="daqp"``).
        method: ``"equality"`` (no inequality row), ``"shortcut"`` (inequalities, no
            QP needed), ``"active-set"`` (a box first, bounds or rows held at a bound,
            no QP), ``"cascade"`` (some levels solved as QPs) or ``"daqp"``.
        qp_levels: the levels solved by a QP (``"daqp"``: all of them).
        iterations: total QP iterations.
        converged: every QP reached its tolerance (``False``: the QP back-end stopped
            at its iteration limit; ``x`` is its last iterate, still checked here).
        tolerances: threshold of :attr:`satisfied`,
            ``10 * eps * (1 + ||A_k||_F ||x||)`` per level.
        satisfied: per level, ``residuals[k] <= tolerances[k]``.
    """

    __slots__ = (
        "_eps",
        "_fro",
        "converged",
        "iterations",
        "method",
        "qp_levels",
        "ranks",
        "residuals",
        "x",
        "xnorm",
    )

    def __init__(
        self, x, residuals, ranks, method, qp_levels, iterations, converged, fro, eps, xnorm=None
    ):
        self.x = x
        self.residuals = residuals
        self.ranks = ranks
        self.method = method
        self.qp_levels = qp_levels
        self.iterations = iterations
        self.converged = converged
        self.xnorm = math.sqrt(float(x @ x)) if xnorm is None else xnorm
        self._fro = fro
        self._eps = eps

    @property
    def tolerances(self) -> np.ndarray:
        return 10.0 * self._eps * (1.0 + self._fro * self.xnorm)

    @property
    def satisfied(self) -> np.ndarray:
        return self.residuals <= self.tolerances

    @property
    def feasible(self) -> bool:
        """Whether the first (hard) level is satisfied."""
        if not len(self.residuals):
            return True
        # satisfied[0] in scalars (the SOT asks at every tick)
        return bool(self.residuals[0] <= 10.0 * self._eps * (1.0 + self._fro[0] * self.xnorm))

    @property
    def all_satisfied(self) -> bool:
        """Whether every level is satisfied."""
        return bool(self.satisfied.all())

    def __repr__(self) -> str:
        return (
            f"HierarchyResult(method={self.method!r}, residuals={self.residuals},"
            f" satisfied={self.satisfied}, ranks={self.ranks}, qp_levels={self.qp_levels},"
            f" iterations={self.iterations}, converged={self.converged})"
        )


class _Structure:
    """What depends only on the row counts and row classes: stacked buffers, index
    arrays, the plan of merged equality blocks, QP problems and their warm starts."""

    __slots__ = (
        "A",
        "Aeq",
        "Ain",
        "An",
        "active",
        "all_eq",
        "blocks",
        "box",
        "box_blocks",
        "box_full",
        "bufs",
        "d",
        "daqp_failed",
        "din",
        "eq_blocks",
        "eq_bounds",
        "eq_full",
        "eq_idx",
        "eq_starts",
        "eqmask",
        "free_lane",
        "hi_adj",
        "in_idx",
        "in_level",
        "key",
        "kkt_wait",
        "lane",
        "last",
        "lo",
        "lo_adj",
        "loin",
        "m_max",
        "nonempty",
        "nonempty_starts",
        "qps",
        "ref",
        "rlo",
        "rup",
        "shortcut_ok",
        "side",
        "sizes",
        "slices",
        "starts",
        "starts64",
        "up",
        "upin",
        "warm",
        "zero_lams",
    )


class HierarchySolver:
    """Persistent hierarchical solver: buffers, QP problems and warm starts kept between
    calls (an SOT entity keeps one and calls :meth:`solve` every tick).

    Args:
        n: number of variables (``None``: taken from the first solve).
        damping: default damping ``lambda`` (see the module docstring).
        rank_tol: relative rank threshold of the QR factorisations.
        eps: absolute accuracy asked of the QP back-end (DAQP's primal tolerance,
            proxsuite's ``eps_abs`` and duality gap, at least 1e-8) and the feasibility
            tolerance of the shortcut: an inequality row may be exceeded by about
            ``eps``.
        backend: ``"auto"`` (proxsuite cascade), ``"proxsuite"``, or ``"daqp"`` (DAQP's
            hierarchical mode; undamped stacks only, damped ones and DAQP failures fall
            back to the proxsuite cascade).
        shortcut: try the equality step first at every level with inequalities
            (``False``: a QP at every such level; for testing).
        active_set: use the active-set path when the first level is a box (undamped;
            ``False``: the QP cascade instead; for comparisons).
        check: validate the input up front (sizes are always checked; this adds
            non-finite matrices and ``lower <= upper``). Non-finite values that reach
            the solution are reported either way.
        max_iter: iteration limit of each QP.
        jit: run the equality recursion as one compiled call (:mod:`._eqkernel`, the
            same LAPACK arithmetic; ``None``: when numba is available and
            ``SOTPY_JIT`` is not ``0``).
    """

    def __init__(
        self,
        n: int | None = None,
        *,
        damping: float = 0.0,
        rank_tol: float = 1e-9,
        eps: float = 1e-9,
        backend: str = "auto",
        shortcut: bool = True,
        check: bool = True,
        max_iter: int = 1000,
        active_set: bool = True,
        jit: bool | None = None,
    ):
        if backend not in _BACKENDS:
            raise SolverError(f"HierarchySolver: backend {backend!r} is not one of {_BACKENDS}")
        if backend == "daqp" and not daqp_available():
            raise SolverError("HierarchySolver: backend 'daqp' needs the 'daqp' package")
        if backend == "auto":
            backend = "daqp" if daqp_available() else "proxsuite"
        _check_damping(damping)
        if not (rank_tol > 0.0 and eps > 0.0):
            raise SolverError(f"HierarchySolver: rank_tol ({rank_tol}) and eps ({eps}) must be > 0")
        if n is not None and int(n) < 1:
            raise SolverError(f"HierarchySolver: n must be >= 1, got {n}")
        self.n = None if n is None else int(n)
        self.damping = float(damping)
        self.rank_tol = float(rank_tol)
        self.eps = float(eps)
        self.backend = backend
        self.shortcut = bool(shortcut)
        self.active_set = bool(active_set)
        self.check = bool(check)
        self.max_iter = int(max_iter)
        if jit and _eqkernel.equality_stack is None:
            raise SolverError(
                "HierarchySolver: jit=True but compiled kernels are unavailable"
                " (numba missing or SOTPY_JIT=0)"
            )
        self.jit = _eqkernel.equality_stack is not None if jit is None else bool(jit)
        if self.jit:
            _eqkernel.warm_up()
            _boxkkt.warm_up()
        self._stepper: NullspaceStepper | None = None
        self._structure: _Structure | None = None
        self._qp_class = DaqpQP if backend == "daqp" else ProxQP
        limit_blas_threads()  # small matrices: BLAS threads only wait for a core
        # proxsuite stalls below about 1e-8 on the degenerate sets of frozen levels
        self._qp_eps = self.eps if backend == "daqp" else max(self.eps, 1e-8)
        self._fro = np.zeros(0)

    # ----------------------------------------------------------------- public API
    def reset(self) -> None:
        """Forget buffers, QP problems and warm starts."""
        self._stepper = None
        self._structure = None

    def solve(self, levels, damping=None) -> HierarchyResult:
        """Solve the stack ``levels`` (highest priority first).

        Each level is ``(A, lower, upper)`` or ``(A, b)`` (shorthand for
        ``lower = upper = b``), with ``A`` of shape ``(m_k, n)``. ``damping`` overrides
        the solver's default for this call: one number for every level, or one per
        level (e.g. 0 for hard levels, a small value for tasks that may be out of
        reach). Raises :class:`SolverError` on malformed input, naming the level and
        row.
        """
        st, parsed, general = self._prepare(levels)
        return self._solve_copied(st, parsed, general, damping)

    def stacked(self, sizes: Sequence[int]) -> tuple[np.ndarray, np.ndarray, np.ndarray, list[int]]:
        """The solver's own stacked buffers, to write a stack into in place instead of
        passing it to :meth:`solve` (which copies every level into them).

        Returns ``(A, lower, upper, starts)``: ``A`` an ``m x n`` view (``m =
        sum(sizes)``), ``lower`` and ``upper`` of length ``m``; level ``k`` is rows
        ``starts[k]:starts[k + 1]``. Write every row, then call :meth:`solve_stacked`.
        The buffers are the solver's: they stay valid until a call with other sizes
        (by :meth:`solve` or :meth:`stacked`), and their content until the next call.
        Needs ``n`` (given to the constructor or taken from a first solve).
        """
        st = self._structure
        if st is not None and st.sizes == sizes:  # the usual call: the same sizes
            return st.An, st.lo, st.up, st.starts
        n = self.n
        if n is None:
            raise SolverError(
                "HierarchySolver.stacked: the number of variables is unknown"
                " (give n to the constructor, or solve once)"
            )
        sizes = tuple(int(m) for m in sizes)
        if any(m < 0 for m in sizes):
            raise SolverError(f"HierarchySolver.stacked: negative level size in {sizes}")
        if st is None or st.sizes != sizes or st.A.shape[1] != n + 1:
            st = self._new_structure(sizes, n)
        return st.An, st.lo, st.up, st.starts

    def solve_stacked(self, damping=None, *, equality: bool = False) -> HierarchyResult:
        """Solve the stack written into the buffers of :meth:`stacked`: the same
        answer, checks and errors as :meth:`solve` on those levels, without the copy.

        ``equality=True`` says that every row is an equality ``A_k x = lower_k``
        (``upper`` is not read); else ``lower <= A x <= upper`` row by row, as in
        :meth:`solve`.
        """
        st = self._structure
        if st is None:
            raise SolverError("HierarchySolver.solve_stacked: call stacked(sizes) first")
        return self._solve_copied(st, _StackedLevels(st, equality), not equality, damping)

    def _solve_copied(self, st: _Structure, parsed, general: bool, damping) -> HierarchyResult:
        """Once the levels are in the stacked buffers: a lane when one applies
        (:meth:`_lane_solve`, :meth:`_free_lane_solve`), else the bookkeeping and the
        solve."""
        if general and st.lane:
            out = self._lane_solve(st, damping)
            if out is not None:
                return out
        elif general and st.free_lane:
            out = self._free_lane_solve(st, damping)
            if out is not None:
                return out
        self._bookkeep(st, parsed, general)
        return self._solve_prepared(st, parsed, damping)

    def _lane_solve(self, st: _Structure, damping) -> HierarchyResult | None:
        """The call after one that the compiled box path answered, with the same row
        classes: bookkeeping, box and solve in one compiled call
        (:func:`._boxkkt.lane`), the same arithmetic as the usual path. None (nothing
        changed) when the call is not of that kind or the kernel leaves it to the
        usual path, which then also says what is wrong."""
        if st.kkt_wait > 0 or not self._lane_switches(damping):
            return None
        out = self._run_lane(
            _boxkkt.lane, st, st.starts[st.last], self.eps, RCOND_MIN, DUAL_TOL, _BOX_ITERATIONS
        )
        if out is None:
            st.lane = False  # until the compiled box call answers again
            return None
        _, x_aug, res, minnorm, nf, m_upper, _its, fro, xnorm = out
        self._fro = fro
        return self._box_result(st, x_aug, res, minnorm, nf, m_upper, xnorm)

    def _free_lane_solve(self, st: _Structure, damping) -> HierarchyResult | None:
        """The call after one that the box path answered with no bound in its guess
        (:meth:`_box_free_compiled`), while the compiled box call waits after a refusal
        (rank-deficient levels below the box): bookkeeping, box, the equality recursion
        below it and the point's check against the box in one compiled call
        (:func:`._boxkkt.free_lane`), the same arithmetic as the usual path. None
        (nothing changed) as :meth:`_lane_solve`."""
        if st.kkt_wait == 0 or not self._lane_switches(damping):
            return None
        blocks = np.array(st.eq_blocks, dtype=np.int64).reshape(-1, 2)
        out = self._run_lane(
            _boxkkt.free_lane, st, st.eq_starts, blocks, self.rank_tol, self.eps, st.last
        )
        if out is None:
            st.free_lane = False  # until the box path answers so again
            return None
        _, x_aug, res, ranks, fro, xnorm = out
        self._fro = fro
        ranks = ranks.astype(np.intp)
        _remember_box_plan(st, ranks, [k for k, _ in st.eq_blocks])
        n = self.n
        return HierarchyResult(x_aug[:n], res, ranks, "shortcut", (), 0, True, fro, self.eps, xnorm)

    def _run_lane(self, kernel, st: _Structure, *extra):
        """A lane kernel's call on the stacked buffers and the box (the arguments both
        lanes start with), then ``extra``: its outputs, or None when it leaves the call
        or refuses its argument types (compiled kernels are then off for this
        solver)."""
        box = st.box
        try:
            out = kernel(
                st.A, st.lo, st.up, st.ref, st.rlo, st.rup, st.d, st.eqmask, st.starts64,
                box.cols, box.coef, box.lo, box.hi, box.at_lo, box.at_hi, st.starts[1], *extra,
            )  # fmt: skip
        except TypeError as exc:  # types the kernel was not compiled for: NumPy
            self._stop_jit(exc)
            return None
        return out if out[0] == _boxkkt.OK else None

    def _lane_switches(self, damping) -> bool:
        """Whether a call may take a lane: undamped, with the default switches."""
        lam = self.damping if damping is None else damping
        return (
            type(lam) is float
            and lam == 0.0
            and self.jit
            and self.check
            and self.shortcut
            and self.active_set
        )

    def _solve_prepared(self, st: _Structure, parsed, damping) -> HierarchyResult:
        """:meth:`solve` once the levels are in the stacked buffers."""
        if damping is None:
            damping = self.damping
        lams = _dampings(damping, len(st.sizes))
        if st.all_eq and self.jit:
            result = self._equality_compiled(st, parsed, lams)
            if result is not None:
                return result
            self._fro = _frobenius(st, self.n)  # a non-finite entry: the NumPy path
        stepper = self._stepper
        if stepper is None or stepper.m_max < st.m_max:
            stepper = self._stepper = NullspaceStepper(self.n, st.m_max)
        else:
            stepper.reset()
        if st.all_eq:
            ranks = None
            if st.eq_full is not None and not any(lams):
                ranks = self._kkt_equality(st, stepper)
            if ranks is None:
                ranks = self._solve_equality(st, stepper, lams)
            return self._result(st, parsed, stepper.x_aug, ranks, "equality", (), 0, True)
        return self._solve_general(st, parsed, stepper, lams)

    # ------------------------------------------------------------ input handling
    def _prepare(self, levels):
        """Copy the levels into the stacked buffers ``[A | -lower]``, ``upper``;
        validate. Returns ``(structure, parsed levels, general)``: ``general`` when
        some level has an ``upper`` of its own."""
        n = self.n
        parsed = []
        sizes_l = []
        mats: list[np.ndarray] = []  # A, lower, upper of every level, for one copy each
        los: list[np.ndarray] = []
        ups: list[np.ndarray] = []
        general = False
        try:
            for k, level in enumerate(levels):
                nl = len(level)
                if nl == 2:
                    A, lo = level
                    up = None
                elif nl == 3:
                    A, lo, up = level
                    if up is lo:
                        up = None
                    else:
                        general = True
                else:
                    raise SolverError(
                        f"level {k}: expected (A, lower, upper) or (A, b), got {nl} items"
                    )
                if type(A) is not np.ndarray or A.dtype != _F64 or A.ndim != 2:
                    A = _as_matrix(A, k)
                if n is None:
                    n = self.n = A.shape[1]
                    if n < 1:
                        raise SolverError(f"level {k}: A has no column")
                m = A.shape[0]
                if A.shape[1] != n:
                    raise SolverError(
                        f"level {k}: A has {A.shape[1]} columns, expected {n}"
                        " (the number of variables)"
                    )
                if type(lo) is not np.ndarray or lo.shape != (m,) or lo.dtype != _F64:
                    lo = _as_vector(lo, k, "b" if nl == 2 else "lower", m)
                if up is not None and (
                    type(up) is not np.ndarray or up.shape != (m,) or up.dtype != _F64
                ):
                    up = _as_vector(up, k, "upper", m)
                parsed.append((A, lo, up))
                sizes_l.append(m)
                mats.append(A)
                los.append(lo)
                ups.append(lo if up is None else up)
        except TypeError as exc:
            raise SolverError(f"solve_hierarchy: levels must be a list of tuples ({exc})") from None
        if n is None:
            raise SolverError("solve_hierarchy: no level and no number of variables")
        sizes = tuple(sizes_l)
        st = self._structure
        if st is None or st.sizes != sizes or st.A.shape[1] != n + 1:
            st = self._new_structure(sizes, n)
        if mats:  # one copy per buffer (the levels in order are its rows)
            np.concatenate(mats, out=st.An)
            np.concatenate(los, out=st.lo)
            if general:
                np.concatenate(ups, out=st.up)
        return st, parsed, general

    def _bookkeep(self, st: _Structure, parsed, general: bool) -> None:
        """Once ``A`` and the bounds are in the stacked buffers: the augmented column,
        the relative bounds, the checks (naming what ``parsed`` holds) and the row
        classes. ``general``: ``upper`` is written (else every row is ``A x =
        lower``)."""
        n = self.n
        A_st = st.A
        if general:
            lo_st, up_st = st.lo, st.up
            if self.jit:
                done = self._bounds_compiled(st, parsed)
                if done:
                    return
            # augmented column -ref, ref a finite bound of each row (the lower one, else
            # the upper one, else 0): rlo = lower - ref and rup = upper - ref bound A x - ref
            ref = st.ref
            np.copyto(ref, lo_st)
            nonfinite = ~np.isfinite(lo_st)
            if nonfinite.any():
                ref[nonfinite] = np.where(np.isfinite(up_st), up_st, 0.0)[nonfinite]
            np.negative(ref, out=A_st[:, n])
            np.subtract(lo_st, ref, out=st.rlo)
            np.subtract(up_st, ref, out=st.rup)
        else:
            np.negative(st.lo, out=A_st[:, n])
        # Frobenius norm of every level (the scale of its rank threshold); the compiled
        # equality path computes it (and checks it) itself
        if general or not self.jit:
            fro = self._fro = _frobenius(st, n)
            if self.check and not math.isfinite(float(fro.sum())):
                _raise_nonfinite_matrix(parsed)
        if general:
            d = st.d
            with np.errstate(invalid="ignore"):  # inf - inf: reported below
                np.subtract(st.up, st.lo, out=d)
            if self.check and not (d.min() >= 0.0):
                _raise_bad_bounds(parsed)
            key = (d == 0.0).tobytes()
        else:
            key = None
        if key != st.key:
            self._classify(st, key)

    def _bounds_compiled(self, st: _Structure, parsed) -> bool:
        """The general path's bookkeeping after the copy (references, relative bounds,
        norms, checks, row classes) in one compiled call; False (the NumPy code runs)
        if the kernel refuses its arguments."""
        try:
            fro, finite, ok, changed = _eqkernel.bounds_prepare(
                st.A, st.lo, st.up, st.ref, st.rlo, st.rup, st.d, st.eqmask, st.starts64
            )
        except TypeError as exc:
            self._stop_jit(exc)
            return False
        self._fro = fro
        if self.check and not finite:
            _raise_nonfinite_matrix(parsed)
        if self.check and not ok:
            _raise_bad_bounds(parsed)
        if changed or st.key is None or st.key == _INVALID_KEY:
            key = st.eqmask.tobytes()
            if key != st.key:
                self._classify(st, key)
        return True

    def _new_structure(self, sizes: tuple[int, ...], n: int) -> _Structure:
        st = _Structure()
        st.sizes = sizes
        starts = [0]
        for m in sizes:
            starts.append(starts[-1] + m)
        st.starts = starts
        st.starts64 = np.array(starts, dtype=np.int64)
        st.slices = [slice(starts[k], starts[k + 1]) for k in range(len(sizes))]
        mtot = starts[-1]
        st.A = np.zeros((mtot, n + 1))
        st.An = st.A[:, :n]
        st.lo = np.zeros(mtot)
        st.up = np.zeros(mtot)
        st.d = np.zeros(mtot)
        st.ref = np.zeros(mtot)
        st.rlo = np.zeros(mtot)
        st.rup = np.zeros(mtot)
        st.nonempty = np.array([k for k, m in enumerate(sizes) if m > 0], dtype=np.intp)
        st.nonempty_starts = np.array([starts[k] for k in st.nonempty], dtype=np.intp)
        st.last = int(st.nonempty[-1]) if len(st.nonempty) else -1
        st.m_max = max(mtot, 1)  # scratch rows: merged blocks, all inequality rows
        st.key = _INVALID_KEY
        st.eqmask = np.zeros(mtot, dtype=bool)
        st.qps = {}
        st.warm = {}
        st.blocks = [(k, k + 1) for k in range(len(sizes)) if sizes[k] > 0]
        st.zero_lams = np.zeros(len(sizes))  # the compiled path's dampings, undamped
        st.eq_full = None
        st.kkt_wait = 0
        st.lane = st.free_lane = False
        self._structure = st
        return st

    def _classify(self, st: _Structure, key: bytes | None) -> None:
        """Row classes (equality / inequality) and the index arrays that go with them."""
        st.key = key
        st.qps = {}
        st.warm = {}
        st.bufs = {}
        st.daqp_failed = set()
        st.active = set()
        st.shortcut_ok = True
        st.box = None
        st.lane = st.free_lane = False
        st.box_blocks = None
        st.box_full = None
        mtot = st.A.shape[0]
        eqm = np.ones(mtot, dtype=bool) if key is None else np.frombuffer(key, dtype=bool)
        st.all_eq = bool(eqm.all())
        st.eq_idx = eq_idx = np.flatnonzero(eqm)
        st.in_idx = in_idx = np.flatnonzero(~eqm)
        # per level (e0, e1, i0, i1): slices of the equality / inequality stacks
        bounds = []
        e = i = 0
        for k in range(len(st.sizes)):
            ne = int(eqm[st.slices[k]].sum())
            ni = st.sizes[k] - ne
            bounds.append((e, e + ne, i, i + ni))
            e += ne
            i += ni
        st.eq_bounds = bounds
        # the equality stack's levels for the compiled recursion: starts, one block each
        st.eq_starts = np.array([b[0] for b in bounds] + [e], dtype=np.int64)
        st.eq_blocks = [(k, k + 1) for k, b in enumerate(bounds) if b[1] > b[0]]
        st.in_level = np.repeat(
            np.arange(len(bounds), dtype=np.intp), [i1 - i0 for _, _, i0, i1 in bounds]
        )
        w = st.A.shape[1]
        st.Aeq = np.empty((len(eq_idx), w))
        st.Ain = np.empty((len(in_idx), w))
        st.loin = np.empty(len(in_idx))
        st.upin = np.empty(len(in_idx))
        st.din = np.empty(len(in_idx))
        st.lo_adj = np.empty(len(in_idx))
        st.hi_adj = np.empty(len(in_idx))
        st.side = np.zeros(len(in_idx), dtype=np.int8)

    # -------------------------------------------------------------- equality path
    def _solve_equality(
        self, st: _Structure, stepper: NullspaceStepper, lams: list[float]
    ) -> np.ndarray:
        """All rows are equalities: the null-space recursion, undamped levels known to be
        of full row rank (from the previous call) factored together (the NumPy path; the
        compiled one is :meth:`_equality_compiled`)."""
        sizes, slices, A_st = st.sizes, st.slices, st.A
        fro = self._fro
        tol = self.rank_tol
        last = st.last
        ranks = np.zeros(len(sizes), dtype=np.intp)
        step = stepper.step
        for k0, k1 in st.blocks:
            if stepper.nf == 0:
                break
            need = k1 - 1 != last
            if k1 - k0 == 1:
                ranks[k0] = step(A_st[slices[k0]], fro[k0], tol, lams[k0], need)
                continue
            if not any(lams[k0:k1]):
                rows = A_st[st.starts[k0] : st.starts[k1]]
                if step(rows, fro[k0:k1].min(), tol, 0.0, need, True) >= 0:
                    ranks[k0:k1] = sizes[k0:k1]
                    continue
            for k in range(k0, k1):
                if stepper.nf == 0:
                    break
                ranks[k] = step(A_st[slices[k]], fro[k], tol, lams[k], k != last)
        # damped levels are never merged (the merge is exact only undamped)
        undamped = [r if lam == 0.0 else -1 for r, lam in zip(ranks, lams, strict=True)]
        st.blocks = _plan_blocks(sizes, undamped)
        st.eq_full = [bool(ranks[k] == sizes[k]) for k in st.nonempty] or None
        return ranks

    def _equality_compiled(self, st: _Structure, parsed, lams: list[float]):
        """The equality path as one compiled call (:func:`._eqkernel.equality_all`):
        norms, recursion, residuals and the next plan of merged blocks. ``None`` when a
        matrix entry is not finite and ``check`` is off (the caller then takes the
        NumPy path, which reports it), or when the kernel refuses its arguments
        (compiled kernels are then off for this solver)."""
        blocks = st.blocks  # the kernel's plan of the previous call, once there is one
        if type(blocks) is not np.ndarray:
            blocks = np.asarray(blocks, dtype=np.int64).reshape(-1, 2)
        try:
            status, x, ranks, fro, res, plan, xnorm = _eqkernel.equality_all(
                st.A,
                st.starts64,
                blocks,
                np.array(lams, dtype=np.float64) if any(lams) else st.zero_lams,
                self.rank_tol,
                st.last,
            )
        except TypeError as exc:  # types the kernel was not compiled for: NumPy
            self._stop_jit(exc)
            return None
        if status == _eqkernel.NONFINITE_MATRIX:
            if self.check:
                _raise_nonfinite_matrix(parsed)
            return None
        if status != _eqkernel.SOLVED:
            _raise_nonfinite_matrix(parsed)
            raise SolverError(
                "solve_hierarchy: the solution is not finite (overflow: is the stack scaled?)"
            )
        self._fro = fro
        st.blocks = plan
        return HierarchyResult(x, res, ranks, "equality", (), 0, True, fro, self.eps, xnorm)

    def _stop_jit(self, exc: Exception) -> None:
        self.jit = False
        refused("HierarchySolver", exc)

    def _compiled_steps(self, A, starts64, blocks, lams, last, stepper) -> np.ndarray | None:
        """The equality recursion over the levels of ``A`` (rows ``starts64[k]:
        starts64[k + 1]``, blocks of full-rank levels stepped together) as one compiled
        call; the point lands in ``stepper`` (whose basis is then stale). None (nothing
        done, compiled kernels off from now on) on argument types it was not compiled
        for."""
        try:
            x, ranks = _eqkernel.equality_stack(
                A,
                starts64,
                np.array(blocks, dtype=np.int64).reshape(-1, 2),
                self._fro,
                np.array(lams, dtype=np.float64),
                self.rank_tol,
                last,
            )
        except TypeError as exc:  # types the kernel was not compiled for: NumPy
            self._stop_jit(exc)
            return None
        stepper.set_point(x)
        return ranks.astype(np.intp)

    def _kkt_equality(self, st: _Structure, stepper: NullspaceStepper) -> np.ndarray | None:
        """The equality stack as one KKT solve when its shape allows (see :mod:`._kkt`):
        every level but the last of full row rank at the previous call; None if not."""
        levels = [int(k) for k in st.nonempty]
        full = st.eq_full
        if full is None or len(full) != len(levels) or self._kkt_waiting(st):
            return None
        A = st.A
        starts = st.starts
        if all(full):
            out = kkt_solve(A[starts[levels[0]] :], None, self.n, _NO_INDEX, _NO_VALUE)
        elif all(full[:-1]):
            k = levels[-1]
            out = kkt_solve(
                A[starts[levels[0]] : starts[k]], A[starts[k] :], self.n, _NO_INDEX, _NO_VALUE
            )
        else:
            return None
        if out is None:
            st.kkt_wait = _KKT_RETRY
            return None
        stepper.reset()
        stepper.set_point(out[0])
        return self._kkt_ranks(st.sizes, levels, full)

    @staticmethod
    def _kkt_waiting(st: _Structure) -> bool:
        """After a refused KKT solve (singular or ill-conditioned: e.g. a last level
        that leaves some direction free), the next calls go straight to the null-space
        recursion; the KKT solve is tried again after :data:`_KKT_RETRY` calls."""
        if st.kkt_wait > 0:
            st.kkt_wait -= 1
            return True
        return False

    def _kkt_ranks(self, sizes, levels: list[int], full: list[bool]) -> np.ndarray:
        """Ranks after a KKT solve: the rows of each full level; the last (least-squares)
        level fixed every direction left."""
        ranks = np.zeros(len(sizes), dtype=np.intp)
        used = 0
        for k, f in zip(levels, full, strict=True):
            if f:
                ranks[k] = sizes[k]
                used += sizes[k]
            else:
                ranks[k] = self.n - used
        return ranks

    # --------------------------------------------------------------- general path
    def _solve_general(
        self,
        st: _Structure,
        parsed,
        stepper: NullspaceStepper,
        lams: list[float],
    ) -> HierarchyResult:
        """Level by level: equality step + check (shortcut), else a QP; then the
        minimum-norm point."""
        eps = self.eps
        tol = self.rank_tol
        fro = self._fro
        box = None
        if self.shortcut and self.active_set and not any(lams):
            # undamped only: damped, each level's point depends on the path (x_{k-1}),
            # and a bound may be active at one level and not at another
            box = self._box(st)
            if box is not None:
                result = self._box_compiled(st, parsed, box)
                if result is not None:
                    return result
        Aeq, Ain = st.Aeq, st.Ain
        if len(st.eq_idx):
            np.take(st.A, st.eq_idx, axis=0, out=Aeq)
        np.take(st.A, st.in_idx, axis=0, out=Ain)
        np.take(st.rlo, st.in_idx, out=st.loin)
        np.take(st.rup, st.in_idx, out=st.upin)
        lo_adj, hi_adj = st.lo_adj, st.hi_adj
        np.copyto(lo_adj, st.loin)
        np.copyto(hi_adj, st.upin)
        if box is not None:
            result = self._solve_box(st, parsed, stepper, box)
            if result is not None:
                return result
            stepper.reset()
        ranks = np.zeros(len(st.sizes), dtype=np.intp)
        x_aug = stepper.x_aug
        if self.shortcut and st.shortcut_ok and box is None:
            # the whole stack's equality rows; if the point satisfies every inequality
            # row it is the answer (tried first when it was so at the previous call)
            last = max((k for k, b in enumerate(st.eq_bounds) if b[1] > b[0]), default=-1)
            done = None
            if self.jit and len(Aeq):
                done = self._compiled_steps(Aeq, st.eq_starts, st.eq_blocks, lams, last, stepper)
            if done is not None:
                ranks[:] = done
            else:
                for k, (e0, e1, _, _) in enumerate(st.eq_bounds):
                    if e1 > e0 and stepper.nf > 0:
                        ranks[k] = stepper.step(Aeq[e0:e1], fro[k], tol, lams[k], k != last)
            v = Ain @ x_aug
            if (v >= lo_adj - eps).all() and (v <= hi_adj + eps).all():
                return self._result(st, parsed, x_aug, ranks, "shortcut", (), 0, True)
            stepper.reset()
            ranks[:] = 0
        qp_levels: list[int] = []
        iterations = 0
        converged = True
        for k, (e0, e1, _i0, i1) in enumerate(st.eq_bounds):
            if stepper.nf == 0:
                break
            if i1 == 0:
                # no inequality row so far: plain equality step
                if e1 > e0:
                    ranks[k] = stepper.step(Aeq[e0:e1], fro[k], tol, lams[k])
                continue
            if self.shortcut and k not in st.active:
                saved = _save(stepper)
                r = stepper.step(Aeq[e0:e1], fro[k], tol, lams[k]) if e1 > e0 else 0
                v = Ain[:i1] @ x_aug
                if (v >= lo_adj[:i1] - eps).all() and (v <= hi_adj[:i1] + eps).all():
                    ranks[k] = r
                    _widen(st, i1, v)  # the rows' intervals contain the current point
                    continue
                _restore(stepper, saved)
            ranks[k], its, ok = self._qp_level(st, stepper, k, lams[k])
            qp_levels.append(k)
            iterations += its
            converged = converged and ok
        if stepper.nf > 0 and qp_levels:
            its, ok = self._min_norm(st, stepper)
            iterations += its
            converged = converged and ok
        method = "cascade" if qp_levels else "shortcut"
        st.shortcut_ok = not qp_levels
        if box is not None:
            box.remember(stepper.x, self.eps)
            self._remember_rows(st, x_aug)
        return self._result(
            st, parsed, x_aug, ranks, method, tuple(qp_levels), iterations, converged
        )

    # ------------------------------------------------------------------ box path
    def _box(self, st: _Structure) -> BoxActiveSet | None:
        """The box of level 0 if level 0 is one (see :mod:`._boxset`), else None."""
        if st.sizes[0] == 0:
            return None
        box = st.box
        if box is None:
            box = st.box = BoxActiveSet(self.n)
        s1 = st.starts[1]
        if not box.set_box(st.A[:s1, : self.n], st.lo[:s1], st.up[:s1], self.jit):
            return None
        return box

    def _box_compiled(self, st: _Structure, parsed, box: BoxActiveSet) -> HierarchyResult | None:
        """The box path as one compiled call (:func:`._boxkkt.box_kkt`) when every row
        below level 0 is an equality row; None when it does not apply or cannot prove
        its answer (then :meth:`_solve_box` goes on from the guess it corrected)."""
        if _boxkkt.box_kkt is None or not self.jit or st.kkt_wait > 0:
            return None
        s1 = st.starts[1]
        if st.eq_bounds[0][3] != len(st.in_idx) or st.last < 1:
            return None  # inequality rows below level 0, or nothing below it
        try:
            status, x_aug, res, minnorm, nf, m_upper, its = _boxkkt.box_kkt(
                st.A, s1, st.starts[st.last], st.starts64, st.rlo, st.rup, box.lo, box.hi,
                box.at_lo, box.at_hi, self.eps, RCOND_MIN, DUAL_TOL, _BOX_ITERATIONS,
            )  # fmt: skip
        except TypeError as exc:
            self._stop_jit(exc)
            return None
        if status != _boxkkt.OK:
            if status == _boxkkt.REFUSED and its == 0:
                # refused on the previous call's guess: the shape itself (a corrected
                # guess that fixes too many variables says little about the next calls)
                st.kkt_wait = _KKT_RETRY
            return None
        x = x_aug[: self.n]
        xnorm = math.sqrt(x @ x)
        if not math.isfinite(xnorm + res.sum()):
            return None  # the NumPy path reports what is not finite
        st.lane = box.cols is not None  # the next call with these row classes: one call
        return self._box_result(st, x_aug, res, minnorm, nf, m_upper, xnorm)

    def _box_result(self, st, x_aug, res, minnorm, nf, m_upper, xnorm) -> HierarchyResult:
        """The result of the compiled box path: every level below the box met (its
        rows' rank), but a least-squares last level (the free directions it fixed)."""
        ranks = np.array(st.sizes, dtype=np.intp)
        ranks[0] = 0
        if not minnorm:
            ranks[st.last] = nf - m_upper
        n = self.n
        method = "active-set" if nf < n else "shortcut"
        return HierarchyResult(
            x_aug[:n], res, ranks, method, (), 0, True, self._fro, self.eps, xnorm
        )

    def _solve_box(
        self, st: _Structure, parsed, stepper: NullspaceStepper, box: BoxActiveSet
    ) -> HierarchyResult | None:
        """Fix the guessed active bounds, hold the inequality rows below level 0 guessed
        at a bound (``st.side``) at it, solve the equality rows below, verify (primal
        and lexicographic dual); a few corrections; None if still not verified."""
        eps = self.eps
        n = self.n
        i_lower = st.eq_bounds[0][3]  # inequality rows of the levels below level 0
        lower = i_lower < len(st.in_idx)
        side = st.side
        for it in range(_BOX_ITERATIONS):
            W, values, s = box.fixed()
            G = np.flatnonzero(side) if lower else _NO_INDEX
            dual = None
            free_path = False  # answered by _box_free_compiled
            if len(G):
                verdict = self._rows_kkt(st, stepper, W, values, s, G)
                if verdict is None:  # level by level, the held rows with each level
                    stepper.reset()
                    stepper.fix(W, values)
                    verdict = self._rows_steps(st, stepper, DualCheck(n, W, s), G)
                    if verdict is None:
                        return None
                ranks, release = verdict
            elif not len(W) and (ranks := self._box_free_compiled(st, stepper)) is not None:
                release = -1  # no bound fixed: nothing to release
                free_path = True
            else:
                # a refusal on a corrected guess says little about the next calls
                verdict = self._box_kkt(st, stepper, W, values, s, it == 0)
                if verdict is None:  # the shape does not allow one KKT solve: level by level
                    stepper.fix(W, values)
                    compiled = self._box_steps_compiled(st, stepper, W, values, s)
                    if compiled is not None:
                        ranks, dual = compiled
                    else:
                        dual = DualCheck(n, W, s) if len(W) else None
                        ranks = self._box_steps(st, stepper, dual)
                    release = -1
                else:
                    ranks, release = verdict
            x = stepper.x
            low = x < box.lo - eps
            high = x > box.hi + eps
            if low.any() or high.any():
                box.at_lo |= low
                box.at_hi |= high
                continue
            if dual is not None:
                dual.finish(x)
                release = dual.worst if dual.failed else -1
            if release >= 0:  # a bound the optimum would leave: release it, try again
                if release < len(W):
                    j = W[release]
                    box.at_lo[j] = box.at_hi[j] = False
                else:
                    side[G[release - len(W)]] = 0
                continue
            if release == _UNDECIDED:  # held rows not pushed against: try without them
                continue
            if lower:
                # the rows not held: within their bounds, else held at the one they cross
                # (held rows were judged with their level: met, or beyond their bound
                # because their level cannot meet them)
                v = st.Ain[i_lower:] @ stepper.x_aug
                free = side[i_lower:] == 0
                below = free & (v < st.loin[i_lower:] - eps)
                above = free & (v > st.upin[i_lower:] + eps)
                if below.any() or above.any():
                    side[i_lower:][below] = -1
                    side[i_lower:][above] = 1
                    continue
            method = "active-set" if len(W) or len(G) else "shortcut"
            out = self._result(st, parsed, stepper.x_aug, ranks, method, (), 0, True)
            # answered with no bound and no held row: the next such call in one
            # compiled call (see _free_lane_solve)
            st.free_lane = free_path and not lower and box.cols is not None
            return out
        return None

    def _rows_kkt(
        self,
        st: _Structure,
        stepper: NullspaceStepper,
        W: np.ndarray,
        values: np.ndarray,
        s: np.ndarray,
        G: np.ndarray,
    ) -> tuple[np.ndarray, int] | None:
        r"""The active-set path's solve when inequality rows below level 0 are held at a
        bound: ``G`` (indices into ``st.Ain``) at the side ``st.side[G]`` (-1 lower, +1
        upper). One KKT system (see :mod:`._kkt`): the fixed variables, the equality
        rows of levels 1.. and the held rows at their bounds are met exactly; the last
        level with rows is the least-squares one when the rows outnumber the variables,
        else it is met too and the norm is minimised.

        If the system is nonsingular, the free variables within the box and the other
        inequality rows within their bounds (checked by the caller), every level above
        the last has zero violation and the point minimises the last level (or the
        norm) over the set they leave exactly when every held constraint's multiplier
        has the sign that pushes against its bound: the rate ``-s_j mu_j`` of
        :mod:`._kkt` is positive (``s_j = -side_j`` for a held row).

        Returns ``(ranks, release)``: ``release`` the position in ``W`` then ``G`` of
        the constraint with the most negative rate (-1: none); :data:`_UNDECIDED` when
        held rows have a rate about zero (they are released: their bound may be left
        at no cost, and the minimum norm decides). None: a held row on the
        least-squares level, a singular or ill-conditioned system, or a fixed variable
        not pushed against its bound.
        """
        if self._kkt_waiting(st):
            return None
        eb = st.eq_bounds
        n = self.n
        side = st.side[G]
        level_of = st.in_level[G]
        eq_levels = [k for k in range(1, len(eb)) if eb[k][1] > eb[k][0]]
        last = max(eq_levels[-1] if eq_levels else 0, int(level_of.max()))
        Aeq = st.Aeq
        e_first = eb[1][0]
        e_last0, e_last1 = eb[last][0], eb[last][1]
        rows = st.Ain[G]
        # the held rows' targets: [a | -bound]; Ain's last column is -ref and the
        # relative bounds are bound - ref
        rows[:, n] -= np.where(side < 0, st.loin[G], st.upin[G])
        count = len(W) + (e_last1 - e_first) + len(G)
        if count <= n:
            upper = np.concatenate([Aeq[e_first:e_last1], rows])
            out = kkt_solve(upper, None, n, W, values)
        elif (level_of == last).any():
            return None
        else:
            upper = np.concatenate([Aeq[e_first:e_last0], rows])
            out = kkt_solve(upper, Aeq[e_last0:e_last1], n, W, values)
        if out is None:
            st.kkt_wait = _KKT_RETRY
            return None
        x, mu = out
        w = len(W)
        rate = np.concatenate([-s * mu[:w], side * mu[w + (len(upper) - len(G)) :]])
        judged = np.concatenate([s != 0.0, np.ones(len(G), dtype=bool)])
        tol = DUAL_TOL * (1.0 + float(np.abs(rate).max()))
        flat = judged & (np.abs(rate) <= tol)
        release = -1
        if (judged & (rate < -tol)).any():
            release = int(np.argmin(np.where(judged, rate, np.inf)))
        elif flat[:w].any():
            return None  # a bound not pushed against: the level-by-level path decides
        elif flat.any():
            st.side[G[flat[w:]]] = 0
            release = _UNDECIDED
        stepper.reset()
        stepper.set_point(x)
        ranks = np.zeros(len(st.sizes), dtype=np.intp)
        held = np.bincount(level_of, minlength=len(st.sizes))
        used = w
        for k in range(1, last + 1):
            m = (eb[k][1] - eb[k][0]) + int(held[k])
            if k == last and count > n:
                ranks[k] = n - used
            else:
                ranks[k] = m
                used += m
        return ranks, release

    def _rows_steps(
        self, st: _Structure, stepper: NullspaceStepper, dual: DualCheck, G: np.ndarray
    ) -> tuple[np.ndarray, int] | None:
        """The active-set path level by level with held rows (the fixed variables
        already fixed in ``stepper``): each level's equality rows and its held rows at
        their bounds are solved together (least squares inside the level). Then for a
        held row, with ``r_i = a_i x - bound_i`` and ``side_i`` its bound (-1, +1):

        - ``side_i r_i > 0``: the level cannot meet it; its own multiplier (the slack)
          has the right sign, and it is pinned at that value below, as the row is;
        - ``side_i r_i < 0``: the level pulls it inside: released (the returned
          ``release``, a position in ``W`` then ``G``);
        - ``r_i = 0``: the levels below judge it, as the fixed variables: its release
          direction ``d`` (``a_i d = s_i = -side_i``, the level's other rows kept, in
          the directions the level was solved in) joins ``dual``. On the last level it
          needs a unique optimum there.

        Returns ``(ranks, release)`` (release -1: none), or None: a held row met
        exactly that cannot move without the level's other rows, or met on a last
        level without a unique optimum.
        """
        eb = st.eq_bounds
        n, eps = self.n, self.eps
        side = st.side
        level_of = st.in_level[G]
        levels = [k for k in range(1, len(eb)) if eb[k][1] > eb[k][0] or (level_of == k).any()]
        ranks = np.zeros(len(st.sizes), dtype=np.intp)
        last = levels[-1]
        Aeq, fro, tol = st.Aeq, self._fro, self.rank_tol
        w = len(dual.W)
        for k in levels:
            e0, e1 = eb[k][0], eb[k][1]
            pos = np.flatnonzero(level_of == k)
            held = G[pos]
            rows = st.Ain[held]
            bound = np.where(side[held] < 0, st.loin[held], st.upin[held])
            rows[:, n] -= bound
            if e1 > e0:
                rows = np.concatenate([Aeq[e0:e1], rows])
            c0, nf = stepper.c0, stepper.nf
            judge = dual.pending
            r = stepper.step(rows, fro[k], tol, 0.0, k != last)
            ranks[k] = r
            m_eq = e1 - e0
            if len(held):
                res = rows[m_eq:] @ stepper.x_aug  # a_i x - bound_i
                thr = 10.0 * eps * (1.0 + np.abs(bound))
                sgn = side[held] * res
                inward = sgn < -thr
                if inward.any():
                    if nf > 0:  # the level's solution leans on a bound it should not
                        return ranks, w + int(pos[int(np.argmin(sgn))])
                    # nothing moved (no direction left): the rows are simply not held,
                    # and they do not count in the level's violation
                    side[held[inward]] = 0
                    keep = np.ones(len(rows), dtype=bool)
                    keep[m_eq:] = ~inward
                    rows = rows[keep]
            if judge:  # (also when no direction is left: the level may still decide)
                rank = r if k != last else -1
                dual.level(rows, stepper.x_aug, stepper.w[:n, c0:n], rank, stepper.last_qr)
            if not len(held) or nf == 0:
                continue  # (nothing left to move: the point is the only one)
            tight = np.abs(res) <= thr
            if not tight.any():
                continue
            if k == last:
                if r < nf:
                    return None  # several optima: the minimum norm would decide
                continue
            if not dual.failed and not dual.add(
                rows[:, :n],
                stepper.w[:n, c0:n],
                (e1 - e0) + np.flatnonzero(tight),
                -side[held[tight]].astype(float),
                w + pos[tight],
            ):
                return None
        dual.finish(stepper.x)
        return ranks, (dual.worst if dual.failed else -1)

    def _remember_rows(self, st: _Structure, x_aug: np.ndarray) -> None:
        """Take the inequality rows below level 0 at or beyond a bound in a cascade's
        solution as the next guess of the rows held (at that bound)."""
        i_lower = st.eq_bounds[0][3]
        if i_lower == len(st.in_idx):
            return
        v = st.Ain[i_lower:] @ x_aug
        tol = _HELD_TOL * (1.0 + np.abs(v))
        side = st.side[i_lower:]
        side.fill(0)
        side[v <= st.loin[i_lower:] + tol] = -1
        side[v >= st.upin[i_lower:] - tol] = 1

    def _box_free_compiled(self, st: _Structure, stepper: NullspaceStepper) -> np.ndarray | None:
        """No bound guessed active and only equality rows below the box: the levels below
        by the compiled equality recursion (any rank), the box left to the caller's
        primal check. If the point is within the box it is the answer: the box level
        is then met exactly, and the point is the lexicographic minimum-norm optimum of
        the levels below over every x, a fortiori over the box. None when it does not
        apply (jit off, level 0 has equality rows, nothing below it)."""
        eb = st.eq_bounds
        if not self.jit or eb[0][1] > eb[0][0] or st.last < 1:
            return None
        stepper.reset()  # (an earlier correction may have fixed variables)
        ranks = self._compiled_steps(
            st.Aeq, st.eq_starts, st.eq_blocks, [0.0] * len(eb), st.last, stepper
        )
        if ranks is not None:  # the level-by-level path's plans, as it sets them
            _remember_box_plan(st, ranks, [k for k, _ in st.eq_blocks])
        return ranks

    def _box_kkt(
        self,
        st: _Structure,
        stepper: NullspaceStepper,
        W: np.ndarray,
        values: np.ndarray,
        s: np.ndarray,
        remember: bool = True,
    ) -> tuple[np.ndarray, int] | None:
        """The box path's solve as one KKT system (see :mod:`._kkt`) when the levels
        below had the shape it needs at the previous call. Returns the ranks and the
        position in ``W`` of a bound to release (its multiplier has the wrong sign; -1:
        none), or None: not applicable, ill-conditioned, or a bound whose multiplier at
        the last level is zero (then the minimum-norm criterion decides, level by
        level)."""
        full = st.box_full
        if full is None or self._kkt_waiting(st):
            return None
        eb = st.eq_bounds
        levels = [k for k in range(1, len(eb)) if eb[k][1] > eb[k][0]]
        if len(full) != len(levels) or not levels:
            return None
        Aeq, n = st.Aeq, self.n
        e0 = eb[levels[0]][0]
        if all(full):
            out = kkt_solve(Aeq[e0 : eb[levels[-1]][1]], None, n, W, values)
        elif all(full[:-1]):
            k = levels[-1]
            out = kkt_solve(Aeq[e0 : eb[k][0]], Aeq[eb[k][0] : eb[k][1]], n, W, values)
        else:
            return None
        if out is None:
            if remember:
                st.kkt_wait = _KKT_RETRY
            return None
        x, mu = out
        mu = mu[: len(W)]
        release = -1
        if len(W):
            # releasing bound j changes the last objective at the rate -s_j mu_j
            rate = -s * mu
            tol = DUAL_TOL * (1.0 + float(np.abs(mu).max()))
            judged = s != 0.0
            if (judged & (np.abs(rate) <= tol)).any():
                return None  # a bound not pushed against: the minimum-norm rule decides
            if (judged & (rate < -tol)).any():
                release = int(np.argmin(np.where(judged, rate, np.inf)))
        stepper.reset()
        stepper.set_point(x)
        sizes = [eb[k][1] - eb[k][0] for k in levels]
        ranks = np.zeros(len(st.sizes), dtype=np.intp)
        used = len(W)
        for k, m, f in zip(levels, sizes, full, strict=True):
            ranks[k] = m if f else n - used
            used += m
        return ranks, release

    def _box_steps(
        self, st: _Structure, stepper: NullspaceStepper, dual: DualCheck | None
    ) -> np.ndarray:
        """The equality rows of levels 1.. (the fixed variables held; undamped), levels
        found of full row rank at the previous call factored together; the dual check
        run on each block."""
        eb = st.eq_bounds
        ranks = np.zeros(len(st.sizes), dtype=np.intp)
        levels = [k for k in range(1, len(eb)) if eb[k][1] > eb[k][0]]
        if not levels:
            if dual is not None:
                dual.finish(stepper.x)
            return ranks
        blocks = st.box_blocks
        if blocks is None:
            blocks = [(k, k + 1) for k in levels]
        last = levels[-1]
        Aeq, fro, tol, n = st.Aeq, self._fro, self.rank_tol, self.n
        step = stepper.step

        def one(ks: list[int], merged: bool) -> int:
            rows = Aeq[eb[ks[0]][0] : eb[ks[-1]][1]]
            c0 = stepper.c0
            judge = dual is not None and dual.pending
            if merged:
                r = step(rows, min(fro[k] for k in ks), tol, 0.0, ks[-1] != last, True)
                if r < 0:
                    return r
            else:
                r = step(rows, fro[ks[0]], tol, 0.0, ks[-1] != last)
            if judge:
                # Y = the first r columns of the basis when the step formed it
                rank = r if ks[-1] != last else -1
                dual.level(rows, stepper.x_aug, stepper.w[:n, c0:n], rank, stepper.last_qr)
            return r

        eq_sizes = _box_eq_sizes(eb)
        for k0, k1 in blocks:
            ks = list(range(k0, k1))
            if len(ks) > 1 and one(ks, True) >= 0:
                ranks[k0:k1] = eq_sizes[k0:k1]
                continue
            for k in ks:
                ranks[k] = one([k], False)
        _remember_box_plan(st, ranks, levels)
        return ranks

    def _box_steps_compiled(
        self,
        st: _Structure,
        stepper: NullspaceStepper,
        W: np.ndarray,
        values: np.ndarray,
        s: np.ndarray,
    ) -> tuple[np.ndarray, _Verdict] | None:
        """:meth:`_box_steps` with its :class:`DualCheck` as one compiled call
        (:func:`._eqkernel.box_steps`): the ranks, and the dual verdict with the
        minimum-norm criterion already applied at the point (which lands in
        ``stepper``; its basis is then stale). None when the kernels are off or there
        is no level below the box (the NumPy path then)."""
        if not self.jit:
            return None
        eb = st.eq_bounds
        levels = [k for k in range(1, len(eb)) if eb[k][1] > eb[k][0]]
        if not levels:
            return None
        blocks = st.box_blocks
        if blocks is None:
            blocks = [(k, k + 1) for k in levels]
        try:
            x, ranks, failed, worst = _eqkernel.box_steps(
                st.Aeq, st.eq_starts, np.array(blocks, dtype=np.int64).reshape(-1, 2),
                self._fro, self.rank_tol, levels[-1], W.astype(np.int64, copy=False), values,
                s, DUAL_TOL,
            )  # fmt: skip
        except TypeError as exc:  # types the kernel was not compiled for: NumPy
            self._stop_jit(exc)
            return None
        stepper.set_point(x)
        ranks = ranks.astype(np.intp)
        _remember_box_plan(st, ranks, levels)
        return ranks, _Verdict(bool(failed), int(worst))

    def _qp_level(
        self, st: _Structure, stepper: NullspaceStepper, k: int, lam: float
    ) -> tuple[int, int, bool]:
        """Level ``k`` as a QP in ``x = x_{k-1} + Z y``; freeze it; return (rank, its, ok).

        Variables ``(y, w)``: ``min 1/2 ||A_E (x + Z y) - b_E||^2 + 1/2 ||w||^2
        + 1/2 lambda^2 ||y||^2`` s.t. the frozen rows ``lo_adj <= A_F (x + Z y) - ref <=
        hi_adj`` and ``lower <= A_I (x + Z y) - w <= upper`` for the level's inequality
        rows (``ref``: a finite bound of each row, see ``_prepare``).
        """
        e0, e1, i0, i1 = st.eq_bounds[k]
        eps = self.eps
        x = stepper.x.copy()
        Z = stepper.basis()
        nf = stepper.nf
        mi = i1 - i0
        nv = nf + mi
        buf = st.bufs.get(k)
        if buf is None or buf[0].shape[0] != nv:
            # constant parts: the slacks' identity in H, -I in C
            H = np.zeros((nv, nv))
            H[nf:, nf:].flat[:: mi + 1] = 1.0
            C = np.zeros((i1, nv))
            C[i0:i1, nf:].flat[:: mi + 1] = -1.0
            buf = st.bufs[k] = (H, C, np.zeros(nv), np.empty(i1), np.empty(i1))
        H, C, g, lo, up = buf
        Hy = H[:nf, :nf]
        if e1 > e0:
            red = stepper.reduced(st.Aeq[e0:e1])  # [A_E Z | A_E x - b_E]
            Me = red[:, :nf]
            np.matmul(Me.T, Me, out=Hy)
            np.matmul(Me.T, red[:, nf], out=g[:nf])
        else:
            Hy.fill(0.0)
        if lam > 0.0:
            Hy.flat[:: nf + 1] += lam * lam
        red = stepper.reduced(st.Ain[:i1])  # [A_F Z | A_F x - ref]
        C[:, :nf] = red[:, :nf]
        v = red[:, nf]
        np.subtract(st.lo_adj[:i0], v[:i0], out=lo[:i0])
        np.subtract(st.hi_adj[:i0], v[:i0], out=up[:i0])
        np.subtract(st.loin[i0:i1], v[i0:], out=lo[i0:])
        np.subtract(st.upin[i0:i1], v[i0:], out=up[i0:])
        # proxsuite: warm start from this level's previous solution mapped to these
        # coordinates (DAQP reuses its previous working set instead)
        v0 = z0 = None
        warm = st.warm.get(k)
        if warm is not None and self._warm_proxsuite(st, k):
            xprev, wprev, zprev = warm
            v0 = np.empty(nv)
            v0[:nf] = Z.T @ (xprev - x)
            v0[nf:] = wprev
            z0 = zprev
        sol, z, its, ok = self._run_qp(st, k, H, g, C, lo, up, v0, z0)
        if not ok:
            # the QP back-end failed: keep the previous point (it satisfies every level
            # above), pin nothing, freeze the level's rows where they are; flagged in
            # the result (converged=False)
            st.warm.pop(k, None)
            _widen(st, i1, st.Ain[:i1] @ stepper.x_aug)
            return 0, its, False
        w = np.array(sol[nf:])
        z = np.array(z)
        x += Z @ sol[:nf]
        st.warm[k] = (x, w, z)
        stepper.set_point(x)
        # freeze: the level's equality rows, its violated inequality rows (w != 0) and
        # the frozen rows above that the optimum leans on (multiplier != 0) are pinned
        # where they are. The level's residual is unique over its optimal set, and along
        # any direction that keeps it, a row with a nonzero multiplier cannot leave its
        # bound (complementarity), so pinning those rows is exact (undamped only: with
        # damping the multipliers also balance the damping term); it also lets the next
        # levels' equality steps respect them (fewer QPs).
        #
        # Multipliers are used with DAQP only: its working set is exact (rows out of it
        # have a zero multiplier), while proxsuite's are noisy at the 1e-8 level and a
        # row pinned by mistake would cost the levels below.
        tol_pin = 10.0 * eps
        if lam == 0.0 and self._exact_multipliers(st, k):
            za = np.abs(z)
            if mi:
                np.maximum(za[i0:], np.abs(w), out=za[i0:])
        else:
            za = np.zeros(i1)
            za[i0:] = np.abs(w)
        pinned = np.flatnonzero(za > tol_pin)
        # rows are active at the optimum: next call, go straight to the QP (the
        # equality step would violate them); the shortcut is tried again once not
        if za.max(initial=0.0) > 0.0:
            st.active.add(k)
        else:
            st.active.discard(k)
        r = 0
        if len(pinned):
            rows = np.concatenate([st.Aeq[e0:e1], st.Ain[pinned]])
            scale = math.sqrt(float(np.einsum("ij,ij->", rows[:, :-1], rows[:, :-1])))
            r = stepper.step(rows, scale, self.rank_tol, freeze=True)
        elif e1 > e0:
            r = stepper.step(st.Aeq[e0:e1], self._fro[k], self.rank_tol, freeze=True)
        if mi:
            np.add(st.loin[i0:i1], w, out=st.lo_adj[i0:i1])
            np.add(st.upin[i0:i1], w, out=st.hi_adj[i0:i1])
        _widen(st, i1, st.Ain[:i1] @ stepper.x_aug)
        return r, its, ok

    def _run_qp(self, st, key, H, g, C, lo, up, v0, z0, fallback: bool = True):
        """Solve with the level's persistent QP; if DAQP fails, a fresh proxsuite problem
        solves it, and keeps solving this level (until the stack's shape changes): a
        DAQP that hit its iteration limit once on a level tends to again, at a high cost
        per tick. (A fresh, cold proxsuite problem measured faster on those levels than
        a persistent warm-started one.)"""
        if key in st.daqp_failed:
            return self._fresh_proxsuite(H, g, C, lo, up)
        qp = st.qps.get(key)
        if qp is None:
            qp = st.qps[key] = self._qp_class(self._qp_eps, self.max_iter)
        sol, z = qp.solve(H, g, C, lo, up, v0, z0)
        its, ok = qp.iterations, qp.status_ok
        if not ok and type(qp) is DaqpQP and fallback:
            st.daqp_failed.add(key)
            sol, z, its2, ok = self._fresh_proxsuite(H, g, C, lo, up)
            its += its2
        return sol, z, its, ok

    def _fresh_proxsuite(self, H, g, C, lo, up):
        fallback = ProxQP(max(self.eps, 1e-8), 10 * self.max_iter)
        sol, z = fallback.solve(H, g, C, lo, up)
        return sol, z, fallback.iterations, fallback.status_ok

    def _exact_multipliers(self, st: _Structure, key) -> bool:
        """Whether the level's last QP came from DAQP (exact working-set multipliers)."""
        return key not in st.daqp_failed and type(st.qps.get(key)) is DaqpQP

    def _warm_proxsuite(self, st: _Structure, key) -> bool:
        """Whether the level's QP is a persistent proxsuite one (warm-started from a
        mapped guess)."""
        if key in st.daqp_failed:
            return False
        qp = st.qps.get(key)
        return type(qp) is ProxQP or (qp is None and self._qp_class is ProxQP)

    def _min_norm(self, st: _Structure, stepper: NullspaceStepper) -> tuple[int, bool]:
        """Move to the minimum-norm point of ``x + range(Z)`` within the frozen rows."""
        x = stepper.x.copy()
        Z = stepper.basis()
        c = Z.T @ x
        stepper.set_point(x - Z @ c)
        v = st.Ain @ stepper.x_aug
        eps = self.eps
        if (v >= st.lo_adj - eps).all() and (v <= st.hi_adj + eps).all():
            return 0, True
        stepper.set_point(x)
        red = stepper.reduced(st.Ain)
        v = red[:, -1]
        warm = st.warm.get("min_norm")
        v0 = z0 = None
        if warm is not None and self._warm_proxsuite(st, "min_norm"):
            v0 = Z.T @ (warm[0] - x)
            z0 = warm[1]
        nf = stepper.nf
        # no proxsuite fallback here: on the thin, degenerate sets this QP sees it took
        # up to 10^5 iterations (seconds); the optimal point is kept instead
        y, z, its, ok = self._run_qp(
            st,
            "min_norm",
            np.eye(nf),
            c,
            red[:, :nf].copy(),
            st.lo_adj - v,
            st.hi_adj - v,
            v0,
            z0,
            fallback=False,
        )
        if not ok:  # keep the optimal (not minimum-norm) point
            st.warm.pop("min_norm", None)
            return its, False
        xk = x + Z @ y
        st.warm["min_norm"] = (xk, np.array(z))
        stepper.set_point(xk)
        return its, ok

    # -------------------------------------------------------------------- result
    def _result(
        self, st, parsed, x_aug, ranks, method, qp_levels, iterations, converged
    ) -> HierarchyResult:
        res = None
        if self.jit and len(st.nonempty):
            try:
                res = _eqkernel.residuals(
                    st.A, np.ascontiguousarray(x_aug), st.starts64, st.rlo, st.rup, not st.all_eq
                )
            except TypeError as exc:
                self._stop_jit(exc)
        if res is not None:
            pass
        elif len(st.nonempty):
            with np.errstate(invalid="ignore", over="ignore"):  # non-finite: raised below
                v = st.A @ x_aug  # A x - ref, row by row
            if not st.all_eq:
                viol = np.maximum(st.rlo - v, 0.0)
                viol += np.maximum(v - st.rup, 0.0)
                v = viol
            v *= v
            if len(st.nonempty) == len(st.sizes):
                res = np.sqrt(np.add.reduceat(v, st.nonempty_starts))
            else:
                res = np.zeros(len(st.sizes))
                res[st.nonempty] = np.sqrt(np.add.reduceat(v, st.nonempty_starts))
        else:
            res = np.zeros(len(st.sizes))
        x = x_aug[: self.n].copy()
        out = HierarchyResult(
            x, res, ranks, method, qp_levels, iterations, converged, self._fro, self.eps
        )
        if not math.isfinite(out.xnorm + float(res.sum())):
            _raise_nonfinite_matrix(parsed)
            _raise_bad_bounds(parsed)
            raise SolverError(
                "solve_hierarchy: the solution is not finite (overflow: is the stack scaled?)"
            )
        return out


def solve_hierarchy(
    levels,
    damping=0.0,
    *,
    rank_tol: float = 1e-9,
    eps: float = 1e-9,
    backend: str = "auto",
    shortcut: bool = True,
) -> HierarchyResult:
    """Solve a stack of levels once (a thin wrapper over a fresh :class:`HierarchySolver`).

    ``levels``: list of ``(A, lower, upper)`` or ``(A, b)``, highest priority first;
    ``damping``: one number for every level or one per level. Returns a
    :class:`HierarchyResult`; the solution is ``result.x``.
    """
    solver = HierarchySolver(rank_tol=rank_tol, eps=eps, backend=backend, shortcut=shortcut)
    return solver.solve(levels, damping)


# ------------------------------------------------------------------- helpers
def _frobenius(st: _Structure, n: int) -> np.ndarray:
    """The Frobenius norm of every level's matrix (the scale of its rank threshold)."""
    fro = np.zeros(len(st.sizes))
    if len(st.nonempty):
        An = st.A[:, :n]
        fro2 = np.add.reduceat(np.einsum("ij,ij->i", An, An), st.nonempty_starts)
        fro[st.nonempty] = np.sqrt(fro2)
    return fro


def _plan_blocks(sizes, ranks) -> list[tuple[int, int]]:
    """Runs of consecutive non-empty levels of full row rank become one block."""
    blocks: list[tuple[int, int]] = []
    run = -1
    for k, m in enumerate(sizes):
        if m == 0:
            if run >= 0:
                blocks.append((run, k))
                run = -1
            continue
        if ranks[k] == m:
            if run < 0:
                run = k
            continue
        if run >= 0:
            blocks.append((run, k))
            run = -1
        blocks.append((k, k + 1))
    if run >= 0:
        blocks.append((run, len(sizes)))
    return blocks


def _box_eq_sizes(eq_bounds) -> list[int]:
    """Equality rows per level on the box path (level 0: none, the box is held by
    fixing variables)."""
    return [0] + [e1 - e0 for e0, e1, _, _ in eq_bounds[1:]]


def _remember_box_plan(st: _Structure, ranks: np.ndarray, levels: list[int]) -> None:
    """The box path's plans for the next call from this call's ranks: the levels of full
    row rank merged into blocks, and which of ``levels`` (the non-empty ones below the
    box) had full row rank."""
    eq_sizes = _box_eq_sizes(st.eq_bounds)
    st.box_blocks = _plan_blocks(eq_sizes, ranks)
    st.box_full = [bool(ranks[k] == eq_sizes[k]) for k in levels]


def _widen(st: _Structure, i1: int, v: np.ndarray) -> None:
    """Widen the frozen intervals of the first ``i1`` inequality rows so that they
    contain ``v`` (their values at the current point, which the QP satisfied only to its
    tolerance): the next QP is then feasible at the current point."""
    np.minimum(st.lo_adj[:i1], v, out=st.lo_adj[:i1])
    np.maximum(st.hi_adj[:i1], v, out=st.hi_adj[:i1])


def _save(stepper: NullspaceStepper):
    """What :func:`_restore` needs to undo a step (``x``, ``Z``, counters)."""
    z = None if stepper.identity else stepper.w[:, stepper.c0 : stepper.n].copy(order="F")
    return (stepper.x.copy(), z, stepper.c0, stepper.nf, stepper.identity, stepper.moved)


def _restore(stepper: NullspaceStepper, saved) -> None:
    x, z, c0, nf, identity, moved = saved
    stepper.c0, stepper.nf = c0, nf
    if identity:
        stepper.reset()
    else:
        stepper.w[:, c0 : stepper.n] = z
        stepper.identity = False
    stepper.x[:] = x
    stepper.moved = moved


def _dampings(damping, p: int) -> list[float]:
    """The damping of each of the ``p`` levels, from one number or one per level."""
    if type(damping) is float and 0.0 <= damping < math.inf:  # the usual call
        return [damping] * p
    if isinstance(damping, (int, float, np.integer, np.floating)):
        lam = float(damping)
        _check_damping(lam)
        return [lam] * p
    try:
        lams = [float(v) for v in damping]
    except (TypeError, ValueError):
        raise SolverError(
            f"solve_hierarchy: damping must be a number or one number per level, got {damping!r}"
        ) from None
    if len(lams) != p:
        raise SolverError(
            f"solve_hierarchy: {len(lams)} dampings for {p} levels; expected one per level"
        )
    for lam in lams:
        _check_damping(lam)
    return lams


def _check_damping(damping: float) -> None:
    if not (math.isfinite(damping) and damping >= 0.0):
        raise SolverError(f"solve_hierarchy: damping must be finite and >= 0, got {damping}")


def _as_matrix(A, k: int) -> np.ndarray:
    try:
        A = np.asarray(A, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise SolverError(f"level {k}: A is not a numeric matrix ({exc})") from None
    if A.ndim != 2:
        raise SolverError(f"level {k}: A must be 2-D, got shape {A.shape}")
    return A


def _as_vector(v, k: int, name: str, m: int) -> np.ndarray:
    try:
        v = np.asarray(v, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise SolverError(f"level {k}: {name} is not a numeric vector ({exc})") from None
    if v.shape != (m,):
        if v.ndim == 2 and v.shape in ((m, 1), (1, m)):
            return v.reshape(m)
        raise SolverError(
            f"level {k}: {name} has shape {v.shape}, expected ({m},) (A has {m} rows)"
        )
    return v


class _Verdict:
    """A :class:`DualCheck`'s outcome computed elsewhere (by the compiled
    :meth:`HierarchySolver._box_steps_compiled`, the minimum-norm criterion included):
    what :meth:`HierarchySolver._solve_box` reads of it."""

    __slots__ = ("failed", "worst")

    def __init__(self, failed: bool, worst: int) -> None:
        self.failed = failed
        self.worst = worst

    def finish(self, x: np.ndarray) -> None:
        """Already applied."""


class _StackedLevels:
    """The levels written into a solver's stacked buffers, as the ``(A, lower,
    upper)`` views the error reports iterate over (``upper`` None for equalities)."""

    __slots__ = ("equality", "st")

    def __init__(self, st: _Structure, equality: bool) -> None:
        self.st = st
        self.equality = equality

    def __iter__(self):
        st = self.st
        for k in range(len(st.sizes)):
            sl = st.slices[k]
            yield st.An[sl], st.lo[sl], None if self.equality else st.up[sl]


def _raise_nonfinite_matrix(parsed) -> None:
    """Raise naming the first non-finite entry of a level's matrix or equality target."""
    for k, (A, lo, up) in enumerate(parsed):
        bad = np.argwhere(~np.isfinite(A))
        if len(bad):
            i, j = bad[0]
            raise SolverError(
                f"level {k}, row {i}: A[{i}, {j}] = {A[i, j]} is not finite"
                f" ({len(bad)} non-finite entries in this level)"
            )
        if up is None:
            bad = np.flatnonzero(~np.isfinite(lo))
            if len(bad):
                i = bad[0]
                raise SolverError(f"level {k}, row {i}: target b = {lo[i]} is not finite")


def _raise_bad_bounds(parsed) -> None:
    """Raise naming the first NaN bound, ``lower > upper`` or infinite equality."""
    for k, (_, lo, up) in enumerate(parsed):
        if up is None:
            up = lo
        for name, v in (("lower", lo), ("upper", up)):
            bad = np.flatnonzero(np.isnan(v))
            if len(bad):
                raise SolverError(f"level {k}, row {bad[0]}: {name} is NaN")
        bad = np.flatnonzero(lo > up)
        if len(bad):
            i = bad[0]
            raise SolverError(
                f"level {k}, row {i}: lower ({lo[i]}) > upper ({up[i]}); expected lower <= upper"
            )
        bad = np.flatnonzero((lo == up) & ~np.isfinite(lo))
        if len(bad):
            i = bad[0]
            raise SolverError(
                f"level {k}, row {i}: equality target {lo[i]} is not finite"
                " (lower == upper == +-inf)"
            )
