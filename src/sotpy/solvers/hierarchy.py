r"""Hierarchical (lexicographic) least squares with equalities and inequalities, in
bounded time.

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
the optimal points the minimum-norm one is returned.

Damping
-------
With ``damping = lambda > 0``, level ``k`` is solved as damped least squares inside
the set left by the levels above, starting from the previous level's point
``x_{k-1}`` (``x_0 = 0``):

.. math::

    x_k = \arg\min_{x \in S_{k-1}} \|v_k(x)\|^2 + \lambda^2 \|x - x_{k-1}\|^2, \qquad
    S_k = \{x \in S_{k-1} : \text{level } k\text{'s rows keep their values at } x_k\}

As in soth, damping is inside the level only: the levels below keep the exact null space
of the levels above (given by the rank threshold).

Rank tolerance
--------------
The active rows of each level are factored by a column-pivoted QR of ``(A_k Z)^T``; the
rank is the number of diagonal entries ``|R_ii| > rank_tol * ||A_k||_F``, relative to the
level's own matrix: rows that depend on the levels above get rank 0, rows that conflict
within a level are solved in the least-squares sense, exactly.

The algorithm and its budget
----------------------------
One method for every stack (:mod:`._activeset` states it): a lexicographic primal
active-set iteration whose every step is one equality hierarchy of the active rows,
warm-started with the previous call's active rows. Each call stops at the optimum, or
after ``max_iter`` equality solves, or when the thread's CPU time exceeds
``time_budget`` (checked between iterations: a call ends within it unless an
iteration costs more than every one before it; ``cold_time_budget`` for a call without
the full warm start). A
stopped call returns the current iterate, which is finite, no worse than the call's
starting point on any level in lexicographic order, optimal on the levels it has proven
(:attr:`HierarchyResult.solved`); the next call continues from its active rows.

See ``docs/solvers.md`` for the details and the measured costs.
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from itertools import pairwise

import numpy as np

from sotpy import _jit
from sotpy._blas import limit_blas_threads
from sotpy.errors import CommandError, SolverError

from . import _activeset, _activeset_jit

__all__ = [
    "HierarchyResult",
    "HierarchySolver",
    "SolverError",
    "solve_hierarchy",
]

_F64 = np.dtype(np.float64)
_STATUS = ("optimal", "iterations", "time")
#: the default time budget (s of thread CPU time): a 1 kHz tick leaves the solver half of
#: its period
DEFAULT_TIME_BUDGET = 5e-4
#: the budget of a call without the full warm start (a solver's first call; the first
#: after the level sizes changed, whose changed levels start with no active row), when
#: it is larger than the time budget: 2 ms, the worst the adversarial kinematic stacks
#: (n up to 40) need from nothing on this project's machine (bench_worst_case.py)
DEFAULT_COLD_TIME_BUDGET = 2e-3
#: the NumPy twin's budgets are this many times the compiled ones. It cannot keep a
#: 1 kHz humanoid tick (measured on the collision demo's Talos stack: a solve of 3 ms
#: median, 2 ms an iteration, 15 times the compiled kernel's): its budget bounds a
#: pathological solve (seconds) rather than a tick. With 10 times (5 ms), a tenth of that
#: demo's ticks stopped at it and its feet drifted 5 um; with 20 ms, one tick in 3000.
NUMPY_BUDGET_FACTOR = 40.0
DEFAULT_TIME_BUDGET_NUMPY = DEFAULT_TIME_BUDGET * NUMPY_BUDGET_FACTOR
DEFAULT_COLD_TIME_BUDGET_NUMPY = DEFAULT_COLD_TIME_BUDGET * NUMPY_BUDGET_FACTOR
DEFAULT_MAX_ITER = 200
#: the share of a call's time budget kept for what follows the kernel (the answer copied
#: out, the result made): the kernel's deadline is ``entry + (1 - RETURN_SHARE) budget``.
#: Measured on cold calls of 35 to 40 variables: 15 to 50 us, against 100 us kept of 2 ms
RETURN_SHARE = 0.05
_DEFAULT = object()


class HierarchyResult:
    """What :meth:`HierarchySolver.solve` returns.

    Attributes:
        x: the solution (length ``n``, a fresh array).
        residuals: ``||v_k(x)||_2`` for every level ``k``: the violation of
            ``lower_k <= A_k x <= upper_k`` at ``x``, in the units of ``A_k x``.
        ranks: per level, the number of directions the level's active rows fixed.
        status: ``"optimal"`` (the lexicographic optimum), ``"iterations"`` or
            ``"time"`` (the call stopped at its iteration or time budget; see
            :attr:`solved`).
        solved: the number of leading levels proven optimal at ``x`` (all ``p`` when
            ``status == "optimal"``; at a budget stop, levels ``0..solved-1`` are
            optimal, level ``solved`` is no worse than the levels above left it, and
            the levels below come from one last step; ``solved == p``: every level is
            optimal, the minimum-norm criterion was not finished).
        iterations: equality-hierarchy solves of the call (1 when the previous active
            set was right).
        method: ``"equality"`` (every row an equality) or ``"active-set"``.
        tolerances: threshold of :attr:`satisfied`,
            ``10 * eps * (1 + ||A_k||_F ||x||)`` per level.
        satisfied: per level, ``residuals[k] <= tolerances[k]``.
    """

    __slots__ = (
        "_active",
        "_eps",
        "_fro",
        "_starts",
        "_status",
        "_xnorm",
        "iterations",
        "method",
        "ranks",
        "residuals",
        "solved",
        "status",
        "x",
    )

    def __init__(self, x, residuals, ranks, status, solved, iterations, active, method, fro, eps):
        self.x = x
        self.residuals = residuals
        self.ranks = ranks
        self.status = status
        self.solved = solved
        self.iterations = iterations
        self._status, self._starts = active  # the statuses: `active` is made when read
        self._active = None
        self.method = method
        self._xnorm = -1.0  # computed when first read
        self._fro = fro
        self._eps = eps

    @property
    def xnorm(self) -> float:
        """``||x||`` (the units of ``x``)."""
        if self._xnorm < 0.0:
            x = self.x
            self._xnorm = math.sqrt(float(x @ x))
        return self._xnorm

    @property
    def active(self) -> tuple[np.ndarray, ...]:
        """Per level, the indices (in the level) of its inequality rows held at a bound at
        ``x`` (at the bound, or beyond it when the level cannot meet them); :attr:`n_active`
        counts them."""
        if self._active is None:
            held = np.flatnonzero(self._status)
            self._active = tuple(
                held[(held >= s) & (held < e)] - s for s, e in pairwise(self._starts)
            )
        return self._active

    @property
    def n_active(self) -> int:
        """The number of inequality rows held at a bound, over every level."""
        return int(np.count_nonzero(self._status))

    @property
    def converged(self) -> bool:
        """Whether ``x`` is the lexicographic optimum (no budget was hit)."""
        return self.status == "optimal"

    @property
    def budget_hit(self) -> bool:
        """Whether the call stopped at its iteration or time budget."""
        return self.status != "optimal"

    @property
    def stopped_level(self) -> int | None:
        """The first level not proven optimal when a budget was hit (``None`` at the
        optimum)."""
        return None if self.status == "optimal" else self.solved

    @property
    def reason(self) -> str:
        """Why the call stopped, in words."""
        if self.status == "optimal":
            return "optimal"
        what = "iteration" if self.status == "iterations" else "time"
        return (
            f"{what} budget hit after {self.iterations} iterations; levels 0..{self.solved - 1}"
            f" proven optimal, level {self.solved} and below the best point so far"
            if self.solved
            else f"{what} budget hit after {self.iterations} iterations; no level proven yet"
        )

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
        r0 = float(self.residuals[0])
        return r0 == 0.0 or r0 <= 10.0 * self._eps * (1.0 + float(self._fro[0]) * self.xnorm)

    @property
    def all_satisfied(self) -> bool:
        """Whether every level is satisfied."""
        return bool(self.satisfied.all())

    def __repr__(self) -> str:
        return (
            f"HierarchyResult(method={self.method!r}, status={self.status!r},"
            f" residuals={self.residuals}, satisfied={self.satisfied}, ranks={self.ranks},"
            f" iterations={self.iterations}, active={self.n_active}, solved={self.solved})"
        )


class _Buffers:
    """Everything that depends only on the level sizes: the stacked rows, the statuses
    (the warm start) and the kernel's outputs."""

    __slots__ = (
        "A", "attach", "fro", "info", "lo", "ranks", "res", "sizes", "starts", "starts_list",
        "status", "up", "warm", "wf", "wi", "x",
    )  # fmt: skip

    def __init__(self, sizes: tuple[int, ...], n: int) -> None:
        self.sizes = sizes
        starts = np.zeros(len(sizes) + 1, dtype=np.int64)
        np.cumsum(sizes, out=starts[1:])
        self.starts = starts
        self.starts_list = [int(s) for s in starts]  # handed out by stacked()
        m = int(starts[-1])
        self.A = np.zeros((m, n))
        self.lo = np.zeros(m)
        self.up = np.zeros(m)
        self.status = np.zeros(m, dtype=np.int8)
        self.attach = np.zeros(m, dtype=np.int64)
        self.x = np.full(n, np.nan)  # the last answer, the kernel's start (NaN: none yet)
        self.res = np.zeros(len(sizes))
        self.ranks = np.zeros(len(sizes), dtype=np.int64)
        self.fro = np.zeros(len(sizes))
        self.info = np.zeros(8, dtype=np.int64)
        self.warm = False  # whether status, attach and x hold a previous call's answer
        self.wf = self.wi = None  # the compiled kernel's scratch (made at its first call)


class HierarchySolver:
    """Persistent hierarchical solver: buffers and the warm start (the previous call's
    active rows) kept between calls; an SOT entity keeps one and calls it every tick.

    Args:
        n: number of variables (``None``: taken from the first solve).
        damping: default damping ``lambda`` (see the module docstring): one number, or
            one per level.
        rank_tol: relative rank threshold of the QR factorisations.
        eps: feasibility tolerance: an inequality row counts as met within
            ``eps (1 + ||a_i|| max(1, ||x||_inf))``.
        max_iter: iteration budget of a call (equality-hierarchy solves, >= 1).
        time_budget: time budget of a call, in seconds of the calling thread's CPU time
            from the call's entry (its input checks, copies and new buffers count; > 0,
            finite, or ``None`` for none). A call stops before an iteration after
            which the last step would not fit (judged by the longest iteration so far):
            it ends within the budget unless an iteration costs more than every one
            before it, and then by at most that excess. Default:
            ``DEFAULT_TIME_BUDGET`` (0.5 ms) compiled, ``DEFAULT_TIME_BUDGET_NUMPY``
            (20 ms) for the NumPy twin.
        cold_time_budget: the budget of a call without the full warm start, when larger
            than ``time_budget`` (> 0, finite, or ``None``: the same budget as every
            call): the first call (or the first after :meth:`reset`), which has to find
            the active rows from nothing, and the first after the level sizes changed
            (the levels of unchanged size keep their active rows and the last answer is
            the start, but the levels that changed start with none). Default:
            ``DEFAULT_COLD_TIME_BUDGET`` (2 ms) compiled, 80 ms for the NumPy twin.
        jit: run the iteration as one compiled call (:mod:`._activeset_jit`; ``None``:
            when numba is available, ``SOTPY_JIT`` is not ``0`` and the kernels are
            compiled on this machine, see :mod:`sotpy._jit`).
    """

    def __init__(
        self,
        n: int | None = None,
        *,
        damping: float | Sequence[float] = 0.0,
        rank_tol: float = 1e-9,
        eps: float = 1e-9,
        max_iter: int = DEFAULT_MAX_ITER,
        time_budget: float | object | None = _DEFAULT,
        cold_time_budget: float | object | None = _DEFAULT,
        jit: bool | None = None,
    ):
        _check_damping_value(damping)
        if not (rank_tol > 0.0 and eps > 0.0 and math.isfinite(rank_tol) and math.isfinite(eps)):
            raise SolverError(
                f"HierarchySolver: rank_tol ({rank_tol}) and eps ({eps}) must be finite and > 0"
            )
        if n is not None and int(n) < 1:
            raise SolverError(f"HierarchySolver: n must be >= 1, got {n}")
        self.n = None if n is None else int(n)
        self.damping = damping
        self.rank_tol = float(rank_tol)
        self.eps = float(eps)
        self.dual_tol = 1e-9
        if jit and _activeset_jit.solve is None:
            raise SolverError(
                "HierarchySolver: jit=True but compiled kernels are unavailable"
                f" ({_jit.UNAVAILABLE})"
            )
        self.jit = _activeset_jit.solve is not None if jit is None else bool(jit)
        self._max_iter = self._time_budget = self._cold_time_budget = None
        self.max_iter = max_iter
        if time_budget is _DEFAULT:
            time_budget = DEFAULT_TIME_BUDGET if self.jit else DEFAULT_TIME_BUDGET_NUMPY
        self.time_budget = time_budget
        if cold_time_budget is _DEFAULT:
            cold_time_budget = (
                DEFAULT_COLD_TIME_BUDGET if self.jit else DEFAULT_COLD_TIME_BUDGET_NUMPY
            )
        self.cold_time_budget = cold_time_budget
        if self.jit or jit is None:
            # loaded from the cache; on a machine's first use compiled in the background
            # for the next runs (this solver keeps the NumPy code), said on stderr first
            _jit.prepare("the hierarchical solver", ["sotpy.solvers._activeset_jit"])
        self._buf: _Buffers | None = None
        limit_blas_threads()  # small matrices: BLAS threads only wait for a core

    # ------------------------------------------------------------------ settings
    @property
    def max_iter(self) -> int:
        """The iteration budget of a call (equality-hierarchy solves)."""
        return self._max_iter

    @max_iter.setter
    def max_iter(self, value: int) -> None:
        ok = isinstance(value, (int, np.integer)) and not isinstance(value, bool) and value >= 1
        if not ok:
            raise SolverError(
                f"HierarchySolver: max_iter must be an integer >= 1, got {value!r}"
                " (the setting is unchanged)"
            )
        self._max_iter = int(value)

    @property
    def time_budget(self) -> float | None:
        """The time budget of a call, in seconds of thread CPU time (``None``: none)."""
        return self._time_budget

    @time_budget.setter
    def time_budget(self, value: float | None) -> None:
        self._time_budget = _seconds("time_budget", value)

    @property
    def cold_time_budget(self) -> float | None:
        """The budget of a call without the full warm start when larger than
        :attr:`time_budget`, in seconds of thread CPU time (``None``: the same budget)."""
        return self._cold_time_budget

    @cold_time_budget.setter
    def cold_time_budget(self, value: float | None) -> None:
        self._cold_time_budget = _seconds("cold_time_budget", value)

    def reset(self) -> None:
        """Forget the buffers and the warm start."""
        self._buf = None

    def _resized(self, sizes: tuple[int, ...], n: int) -> _Buffers:
        """New buffers for level sizes that changed (a task pushed, collision pairs that
        came within reach): with the same ``n`` and number of levels, the levels whose
        size did not change keep their rows' warm start (a guess, which the solver
        checks) and the last answer is kept (the first level's start, see
        :mod:`._activeset`); the rows of the levels that changed start inactive."""
        buf = _Buffers(sizes, n)
        old = self._buf
        if old is None or old.x.shape != buf.x.shape:
            return buf
        buf.x[:] = old.x
        if len(old.sizes) == len(sizes):
            for k, (a, b) in enumerate(zip(old.starts[:-1], buf.starts[:-1], strict=True)):
                if old.sizes[k] == sizes[k]:
                    buf.status[b : b + sizes[k]] = old.status[a : a + sizes[k]]
                    buf.attach[b : b + sizes[k]] = old.attach[a : a + sizes[k]]
        return buf

    # ------------------------------------------------------------------ solving
    def solve(self, levels, damping=None) -> HierarchyResult:
        """Solve the stack ``levels`` (highest priority first).

        Each level is ``(A, lower, upper)`` or ``(A, b)`` (shorthand for
        ``lower = upper = b``), with ``A`` of shape ``(m_k, n)``. ``damping`` overrides
        the solver's default for this call: one number for every level, or one per
        level (e.g. 0 for hard levels, a small value for tasks that may be out of
        reach). Raises :class:`SolverError` on malformed input, naming the level and
        row; a refused call leaves the solver as it was.
        """
        entry = time.thread_time()  # the budget counts the input checks and the copy too
        buf, parsed = self._copy(levels)
        return self._run(buf, parsed, damping, entry)

    def stacked(self, sizes: Sequence[int]) -> tuple[np.ndarray, np.ndarray, np.ndarray, list[int]]:
        """The solver's own stacked buffers, to write a stack into in place instead of
        passing it to :meth:`solve` (which copies every level into them).

        Returns ``(A, lower, upper, starts)``: ``A`` an ``m x n`` array (``m =
        sum(sizes)``), ``lower`` and ``upper`` of length ``m``; level ``k`` is rows
        ``starts[k]:starts[k + 1]`` (``starts`` is the solver's own list: read it, do not
        change it). Write every row, then call :meth:`solve_stacked`.
        The buffers stay valid until a call with other sizes (by :meth:`solve` or
        :meth:`stacked`). Needs ``n`` (given to the constructor or taken from a solve).
        """
        buf = self._buf
        if buf is None or buf.sizes != tuple(sizes):
            if self.n is None:
                raise SolverError(
                    "HierarchySolver.stacked: the number of variables is unknown"
                    " (give n to the constructor, or solve once)"
                )
            sizes = tuple(int(m) for m in sizes)
            if any(m < 0 for m in sizes):
                raise SolverError(f"HierarchySolver.stacked: negative level size in {sizes}")
            buf = self._buf = self._resized(sizes, self.n)
        return buf.A, buf.lo, buf.up, buf.starts_list

    def solve_stacked(self, damping=None, *, equality: bool = False) -> HierarchyResult:
        """Solve the stack written into the buffers of :meth:`stacked`: the same
        answer, checks and errors as :meth:`solve` on those levels, without the copy.

        ``equality=True`` says that every row is an equality ``A_k x = lower_k``
        (``upper`` is not read); else ``lower <= A x <= upper`` row by row.
        """
        entry = time.thread_time()
        buf = self._buf
        if buf is None:
            raise SolverError("HierarchySolver.solve_stacked: call stacked(sizes) first")
        if equality:
            np.copyto(buf.up, buf.lo)
        return self._run(buf, None, damping, entry, pair=equality)

    def _run(self, buf: _Buffers, parsed, damping, entry: float, pair=False) -> HierarchyResult:
        """Run the kernel on the buffers, to a deadline on the thread CPU clock: ``entry``
        (the time at which the call began) plus the budget less its :data:`RETURN_SHARE`.
        What comes before the kernel (a cold call's new buffers, the copy of the levels,
        the kernel's dispatch) and after it is in the budget, not added to it."""
        p = len(buf.sizes)
        lams = _dampings(self.damping if damping is None else damping, p)
        budget = math.inf if self._time_budget is None else self._time_budget
        if not buf.warm and self._cold_time_budget is not None:
            # the first call, or the first after the level sizes changed
            budget = max(budget, self._cold_time_budget)
        deadline = entry + (1.0 - RETURN_SHARE) * budget
        args = (buf.A, buf.lo, buf.up, buf.starts, buf.status, buf.attach, lams, self.rank_tol,
                self.eps, self.dual_tol, self._max_iter, deadline, buf.x, buf.res, buf.ranks,
                buf.fro, buf.info)  # fmt: skip
        if self.jit:
            if buf.wf is None:
                buf.wf, buf.wi = _activeset_jit.workspace(buf.A.shape[0], buf.A.shape[1], p)
            try:
                _activeset_jit.solve(*args, buf.wf, buf.wi)
            except TypeError as exc:  # types the kernel was not compiled for: NumPy
                self.jit = False
                _jit.refused("HierarchySolver", exc)
                _activeset.solve(*args)
        else:
            _activeset.solve(*args)
        info = buf.info
        if info[3] != _activeset.OK:
            if info[3] == _activeset.NONFINITE_RESULT:
                buf.status[:] = 0  # nothing to warm-start from
                buf.x[:] = np.nan
            self._raise(buf, parsed, pair)
        buf.warm = True
        its, reason = int(info[0]), int(info[1])
        active = (buf.status.copy(), buf.starts)
        solved = min(int(info[2]), p)
        eq = int(info[7]) == 0
        return HierarchyResult(
            buf.x.copy(), buf.res.copy(), buf.ranks.copy(), _STATUS[reason], solved, its,
            active, "equality" if eq else "active-set", buf.fro.copy(), self.eps,
        )  # fmt: skip

    # ------------------------------------------------------------ input handling
    def _copy(self, levels):
        """Check the levels' shapes and copy them into the stacked buffers (one
        ``concatenate`` per buffer). Returns ``(buffers, parsed levels)``."""
        n = self.n
        parsed = []
        mats: list[np.ndarray] = []
        los: list[np.ndarray] = []
        ups: list[np.ndarray] = []
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
                    raise SolverError(
                        f"level {k}: expected (A, lower, upper) or (A, b), got {nl} items"
                    )
                if type(A) is not np.ndarray or A.dtype != _F64 or A.ndim != 2:
                    A = _as_matrix(A, k)
                if n is None:
                    n = A.shape[1]
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
                mats.append(A)
                los.append(lo)
                ups.append(lo if up is None else up)
        except TypeError as exc:
            raise SolverError(f"solve_hierarchy: levels must be a list of tuples ({exc})") from None
        if n is None:
            raise SolverError("solve_hierarchy: no level and no number of variables")
        self.n = n
        sizes = tuple(A.shape[0] for A in mats)
        buf = self._buf
        if buf is None or buf.sizes != sizes or buf.A.shape[1] != n:
            buf = self._buf = self._resized(sizes, n)
        if mats:
            np.concatenate(mats, out=buf.A)
            np.concatenate(los, out=buf.lo)
            np.concatenate(ups, out=buf.up)
        return buf, parsed

    def _raise(self, buf: _Buffers, parsed, pair: bool) -> None:
        """Raise the error the kernel found, naming the level and row."""
        if parsed is None:  # solve_stacked: the buffers' levels
            parsed = [
                (buf.A[s:e], buf.lo[s:e], None if pair else buf.up[s:e])
                for s, e in pairwise(buf.starts)
            ]
        code = buf.info[3]
        if code == _activeset.NONFINITE_RESULT:
            raise SolverError(
                "solve_hierarchy: the solution is not finite (overflow: is the stack scaled?)"
            )
        _raise_nonfinite_matrix(parsed)
        _raise_bad_bounds(parsed)
        raise SolverError(f"solve_hierarchy: input refused (code {code})")  # pragma: no cover


def _seconds(setting: str, value: float | None) -> float | None:
    """``value`` as a budget in seconds (finite, > 0, or ``None``), else a
    :class:`~sotpy.errors.SolverError` naming the setting."""
    if value is None:
        return None
    try:
        v = float(value)
    except (TypeError, ValueError):
        v = math.nan
    if not (v > 0.0 and math.isfinite(v)) or isinstance(value, bool):
        raise SolverError(
            f"HierarchySolver: {setting} must be a finite number of seconds > 0 (or None),"
            f" got {value!r} (the setting is unchanged)"
        )
    return v


def checked_time_budget(who: str, seconds: float | None, now: float | None) -> float | None:
    """``seconds`` as an entity's time budget (finite, > 0, or ``None``: none), else a
    :class:`~sotpy.errors.CommandError` naming ``who`` (``"SOT(sot).setTimeBudget"``)
    and the budget it keeps (``now``)."""
    if seconds is None:
        return None
    ok = isinstance(seconds, (int, float, np.floating, np.integer)) and not isinstance(
        seconds, bool
    )
    if not (ok and math.isfinite(seconds) and seconds > 0.0):
        what = "cold time budget" if who.endswith("setColdTimeBudget") else "time budget"
        raise CommandError(
            f"{who}: the {what} must be a finite number of seconds > 0, got"
            f" {seconds!r}; the budget is unchanged ({now})"
        )
    return float(seconds)


def checked_max_iter(who: str, n: int, now: int) -> int:
    """``n`` as an entity's iteration budget (an integer >= 1), else a
    :class:`~sotpy.errors.CommandError` naming ``who`` and the budget it keeps."""
    if not (isinstance(n, (int, np.integer)) and not isinstance(n, bool) and n >= 1):
        raise CommandError(
            f"{who}: the iteration budget must be an integer >= 1, got {n!r}; the budget is"
            f" unchanged ({now})"
        )
    return int(n)


def solve_hierarchy(
    levels,
    damping=0.0,
    *,
    rank_tol: float = 1e-9,
    eps: float = 1e-9,
    max_iter: int = DEFAULT_MAX_ITER,
    time_budget: float | None = None,
    jit: bool | None = None,
) -> HierarchyResult:
    """One-shot :class:`HierarchySolver` (``solve(levels, damping)``); no time budget by
    default (a one-shot call has no tick to keep)."""
    solver = HierarchySolver(
        rank_tol=rank_tol, eps=eps, max_iter=max_iter, time_budget=time_budget, jit=jit
    )
    return solver.solve(levels, damping)


_ZEROS: dict[int, np.ndarray] = {}


def _dampings(damping, p: int) -> np.ndarray:
    """One damping per level, each finite and >= 0."""
    if type(damping) is float and damping == 0.0:  # the usual call: undamped
        z = _ZEROS.get(p)
        if z is None:
            z = _ZEROS[p] = np.zeros(p)
        return z
    if isinstance(damping, (int, float, np.floating, np.integer)) and not isinstance(damping, bool):
        v = float(damping)
        _check_damping(v)
        return np.full(p, v)
    try:
        lams = np.array(damping, dtype=float).reshape(-1)
    except (TypeError, ValueError):
        raise SolverError(
            f"damping must be a number, or one number per level, got {damping!r}"
        ) from None
    if lams.shape != (p,):
        raise SolverError(
            f"damping: {len(lams)} dampings for {p} levels; expected one number or one per level"
        )
    for v in lams:
        _check_damping(float(v))
    return lams


def _check_damping_value(damping) -> None:
    if isinstance(damping, (int, float, np.floating, np.integer)):
        _check_damping(float(damping))
    else:
        for v in np.asarray(damping, dtype=float).reshape(-1):
            _check_damping(float(v))


def _check_damping(damping: float) -> None:
    if not (math.isfinite(damping) and damping >= 0.0):
        raise SolverError(f"damping must be finite and >= 0, got {damping}")


def _as_matrix(A, k: int) -> np.ndarray:
    try:
        A = np.asarray(A, dtype=float)
    except (TypeError, ValueError) as exc:
        raise SolverError(f"level {k}: A is not a numeric matrix ({exc})") from None
    if A.ndim != 2:
        raise SolverError(f"level {k}: A must be 2-D, got shape {A.shape}")
    return A


def _as_vector(v, k: int, name: str, m: int) -> np.ndarray:
    try:
        v = np.asarray(v, dtype=float)
    except (TypeError, ValueError) as exc:
        raise SolverError(f"level {k}: {name} is not numeric ({exc})") from None
    if v.ndim == 0:
        v = np.full(m, float(v))
    if v.shape != (m,):
        raise SolverError(
            f"level {k}: {name} has shape {v.shape}, expected ({m},) (A has {m} rows)"
        )
    return v


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
