r"""The one-level weighted QP of a tick, in the reduced variables ``y = (a, f)``.

The problem over ``chi = (a, tau, f)`` (see :mod:`.solver`)::

    min_chi  1/2 sum_k ||W_k^(1/2) (E_k chi - f_k)||^2 + 1/2 eps ||chi||^2
    s.t.     A_dyn chi = c_dyn,   lb <= C chi <= ub

has the torques given by the actuated rows ``r`` of the equations of motion,
``tau = M_r a - J_r^T f + b_r = T_tau y + t_tau``, so ``chi = T y + t0`` with ``T``
the identity on ``a`` and ``f``. Substituting is exact: the optimum over ``y`` with the
unactuated rows ``u`` as equalities is the optimum over ``chi``. Every row block
``(E, f)`` maps to ``(E_a | E_f) + E_tau T_tau`` and ``f - E_tau t_tau``; the product is
skipped when ``E_tau`` is zero (acceleration, CoM and contact rows), so the reduced data
cost one product per block that touches the torques (torque tasks and limits) instead
of ``T^T H T``. The regularisation becomes ``eps (||y||^2 + ||T_tau y + t_tau||^2)``.

Solving. The active set of the previous tick is the guess: the KKT system of the
equalities and the guessed active rows (each at its bound),

.. math::

    \begin{bmatrix} H & G^T \\ G & 0 \end{bmatrix}
    \begin{bmatrix} y \\ \lambda \end{bmatrix} =
    \begin{bmatrix} -g \\ b_G \end{bmatrix},

is solved by one LU (``dgesv``) and accepted only if it is the optimum: every row
within its bounds (tolerance :data:`PRIMAL_TOL` relative to the row's scale), every
guessed inequality's multiplier of the right sign (``lambda >= 0`` at an upper bound,
``<= 0`` at a lower one, within :data:`DUAL_TOL`), and the KKT residual at rounding
level. These are the optimality conditions of a convex QP, so an accepted point is the
optimum, not an approximation of it. Otherwise DAQP (dual active set) solves the QP,
warm-started with the guess, and its active set becomes the next guess. The
multipliers tell the side of each active row.
"""

from __future__ import annotations

import numpy as np
from scipy.linalg import lapack as _lapack

from ..._jit import c_float64, refused
from ...errors import SotpyError
from . import _kernels
from .model import Layout

__all__ = ["DUAL_TOL", "PRIMAL_TOL", "WeightedQP"]

#: Relative primal tolerance of an accepted guess: a row may exceed its bound by
#: ``PRIMAL_TOL * (1 + |bound|)``.
PRIMAL_TOL = 1e-9
#: Multiplier sign tolerance of an accepted guess (relative to ``1 + max |g|``).
DUAL_TOL = 1e-9
#: Largest multiplier of an accepted guess (relative to ``1 + max |g|``).
_LAMBDA_MAX = 1e6
_DAQP_INF = 1e30
_DAQP_FLAGS = {
    -1: "infeasible",
    -2: "cycling",
    -3: "unbounded",
    -4: "iteration limit",
    -5: "non-convex",
    -6: "overdetermined initial active set",
}
_dgesv = _lapack.dgesv
_STATUS = {
    1: "NaN in the constraint bounds",
    2: "a constraint has lower > upper (infeasible bounds)",
}


class WeightedQP:
    """The weighted QP over ``y = (a, f)``, with the previous tick's active set as the
    first guess (see the module docstring).

    Attributes:
        guess_hits: solves answered by the guessed active set.
        daqp_solves: solves that needed DAQP.
        last_method: ``"guess"`` or ``"daqp"`` (the last solve).
    """

    def __init__(
        self, actuated: np.ndarray, unactuated: np.ndarray, jit: bool | None = None
    ) -> None:
        self.actuated = _as_index(actuated)
        self.unactuated = _as_index(unactuated)
        # the compiled kernels take the actuated rows as the last ones (a free-flyer
        # root first, or none): true of every RobotModel
        tail = isinstance(self.actuated, slice) and (self.actuated.start == _stop(self.unactuated))
        if jit and (_kernels.reduce is None or not tail):
            raise SotpyError(
                "WeightedQP: compiled kernels unavailable (numba missing, SOTPY_JIT=0,"
                " or actuated joints that are not the last velocities)"
            )
        self.jit = bool(_kernels.reduce is not None and tail) if jit is None else bool(jit)
        if self.jit:
            _kernels.warm_up()
        self.guess_hits = 0
        self.daqp_solves = 0
        self.last_method = ""
        self._key: tuple | None = None
        self._active = np.zeros(0, dtype=np.intp)  # indices into the constraint rows
        self._upper = np.zeros(0, dtype=bool)  # at the upper bound (else the lower)

    def forget(self) -> None:
        """Drop the active-set guess (the next solve calls DAQP)."""
        self._key = None

    # ------------------------------------------------------------------ reduction
    def reduce(self, layout: Layout, dyn, cons, tasks, regularisation: float):
        """The reduced QP ``(H, g, Au, cu, Cy, lo, hi, T_tau, t_tau)`` over ``y``."""
        nv, na = layout.nv, layout.na
        A, c = dyn
        r = self.actuated
        ny = layout.n - na
        Tt = np.empty((na, ny))
        Tt[:, :nv] = A[r, :nv]
        Tt[:, nv:] = A[r, nv + na :]
        tt = -c[r]
        u = self.unactuated
        Au = np.empty((c[u].shape[0], ny))
        Au[:, :nv] = A[u, :nv]
        Au[:, nv:] = A[u, nv + na :]
        cu = c[u]
        H = Tt.T @ Tt
        H.flat[:: ny + 1] += 1.0
        H *= regularisation
        g = regularisation * (Tt.T @ tt)
        if tasks:
            E = np.vstack([t[1] for t in tasks]) if len(tasks) > 1 else tasks[0][1]
            f = np.concatenate([t[2] for t in tasks])
            sw = np.sqrt(np.concatenate([t[3] for t in tasks]))
            Ey, fy = _to_y(E, f, nv, na, Tt, tt)
            Ey *= sw[:, None]
            fy *= sw
            H += Ey.T @ Ey
            g -= Ey.T @ fy
        C, lo, hi = cons
        Cy, shift = _to_y(C, np.zeros(C.shape[0]), nv, na, Tt, tt)
        # shift = -C_tau t_tau: C chi = Cy y - shift
        return H, g, Au, cu, Cy, lo + shift, hi + shift, Tt, tt

    def _stop_jit(self, exc: Exception) -> None:
        self.jit = False
        refused("WeightedQP", exc)

    def _reduce_compiled(self, layout: Layout, dyn, cons, tasks, regularisation: float):
        A, c = dyn
        if tasks:
            E = np.vstack([t[1] for t in tasks]) if len(tasks) > 1 else tasks[0][1]
            f = np.concatenate([t[2] for t in tasks])
            w = np.concatenate([t[3] for t in tasks])
        else:
            E, f, w = np.zeros((0, layout.n)), np.zeros(0), np.zeros(0)
        C, lo, hi = cons
        args = [c_float64(a) for a in (A, c, E, f, w, C, lo, hi)]
        return _kernels.reduce(*args, float(regularisation), layout.nv, layout.na)

    # --------------------------------------------------------------------- solve
    def solve(
        self, layout: Layout, dyn, cons, tasks, regularisation: float
    ) -> tuple[np.ndarray | None, str]:
        """``(chi, "")`` at the optimum, or ``(None, reason)``."""
        data = None
        if self.jit:
            try:
                status, data = self._reduce_compiled(layout, dyn, cons, tasks, regularisation)
            except TypeError as exc:  # argument types the kernel was not compiled for
                self._stop_jit(exc)
        if data is None:
            data = self.reduce(layout, dyn, cons, tasks, regularisation)
            lo, hi = data[5], data[6]
            status = 1 if np.isnan(lo).any() or np.isnan(hi).any() else 0
            status = status or (2 if (lo > hi + 1e-12).any() else 0)
        if status:
            return None, _STATUS[status]
        H, g, Au, cu, Cy, lo, hi, Tt, tt = data
        key = (layout.n, Cy.shape[0], Au.shape[0])
        eq = None
        y = None
        if key == self._key:
            if self.jit:
                try:
                    ok, y = _kernels.guess(
                        H, g, Au, cu, Cy, lo, hi, self._active, self._upper,
                        PRIMAL_TOL, DUAL_TOL, _LAMBDA_MAX,
                    )  # fmt: skip
                except (np.linalg.LinAlgError, ZeroDivisionError):  # singular KKT matrix
                    ok = False
                except TypeError as exc:
                    self._stop_jit(exc)
                    ok = False
                y = y if ok else None
            else:
                eq = lo == hi
                y = self._try_guess(H, g, Au, cu, Cy, lo, hi, eq)
        if y is not None:
            self.guess_hits += 1
            self.last_method = "guess"
        else:
            y, reason = self._daqp(H, g, Au, cu, Cy, lo, hi, lo == hi if eq is None else eq, key)
            if y is None:
                return None, reason
            self.daqp_solves += 1
            self.last_method = "daqp"
        nv, na = layout.nv, layout.na
        chi = np.empty(layout.n)
        chi[:nv] = y[:nv]
        chi[nv + na :] = y[nv:]
        chi[nv : nv + na] = Tt @ y + tt
        return chi, ""

    def _try_guess(self, H, g, Au, cu, Cy, lo, hi, eq) -> np.ndarray | None:
        ny = H.shape[0]
        act, up = self._active, self._upper
        ie = np.flatnonzero(eq)
        rows = np.concatenate([ie, act])
        ne, nc = Au.shape[0], len(rows)
        k = ny + ne + nc
        K = np.zeros((k, k))
        K[:ny, :ny] = H
        K[ny : ny + ne, :ny] = Au
        K[ny + ne :, :ny] = Cy[rows]
        K[:ny, ny:] = K[ny:, :ny].T
        rhs = np.empty(k)
        np.negative(g, out=rhs[:ny])
        rhs[ny : ny + ne] = cu
        rhs[ny + ne : ny + ne + len(ie)] = lo[ie]
        rhs[ny + ne + len(ie) :] = np.where(up, hi[act], lo[act])
        _lu, _piv, z, info = _dgesv(K, rhs)
        if info != 0 or not np.isfinite(z).all():
            return None
        y = z[:ny]
        lam = z[ny + ne + len(ie) :]
        gmax = 1.0 + np.abs(g).max()
        # LU is backward stable: the KKT equations hold to rounding relative to
        # |K| |z|; huge multipliers (nearly dependent active rows) would make that loose
        if len(z) > ny and np.abs(z[ny:]).max() > _LAMBDA_MAX * gmax:
            return None
        dtol = DUAL_TOL * gmax
        if len(act) and ((lam[up] < -dtol).any() or (lam[~up] > dtol).any()):
            return None
        v = Cy @ y
        if (v > hi + PRIMAL_TOL * (1.0 + np.abs(hi))).any():
            return None
        if (v < lo - PRIMAL_TOL * (1.0 + np.abs(lo))).any():
            return None
        return y

    def _daqp(self, H, g, Au, cu, Cy, lo, hi, eq, key) -> tuple[np.ndarray | None, str]:
        import daqp

        ne = Au.shape[0]
        G = np.vstack([Au, Cy])
        bl = np.concatenate([cu, np.maximum(lo, -_DAQP_INF)])
        bu = np.concatenate([cu, np.minimum(hi, _DAQP_INF)])
        sense = np.zeros(len(bl), dtype=np.intc)
        sense[:ne] = 5  # equality (active, immutable)
        sense[ne:][eq] = 5
        if key == self._key and len(self._active):
            warm = ne + self._active
            sense[warm[sense[warm] == 0]] = 1  # active inequality: DAQP's warm start
        y, _fval, flag, info = daqp.solve(np.ascontiguousarray(H), g, G, bu, bl, sense)
        if flag not in (1, 2):
            self._key = None
            return None, f"QP {_DAQP_FLAGS.get(flag, 'failed')} (DAQP exit flag {flag})"
        y = np.asarray(y, dtype=float)
        lam = np.asarray(info["lam"])[ne:]
        act = np.flatnonzero((lam != 0.0) & ~eq)
        v = Cy[act] @ y
        self._active = act
        self._upper = np.abs(v - hi[act]) <= np.abs(v - lo[act])
        self._key = key
        return y, ""


def _to_y(E: np.ndarray, f: np.ndarray, nv: int, na: int, Tt: np.ndarray, tt: np.ndarray):
    """Rows ``E chi - f`` as rows over ``y``: ``(Ey, fy)`` with ``E chi - f = Ey y - fy``
    (fresh arrays)."""
    Et = E[:, nv : nv + na]
    Ey = np.empty((E.shape[0], E.shape[1] - na))
    Ey[:, :nv] = E[:, :nv]
    Ey[:, nv:] = E[:, nv + na :]
    if Et.any():
        Ey += Et @ Tt
        fy = f - Et @ tt
    else:
        fy = f.copy()
    return Ey, fy


def _as_index(idx) -> slice | np.ndarray:
    """A slice when the indices are a contiguous increasing run (cheaper to apply),
    else an index array."""
    idx = np.asarray(idx, dtype=np.intp)
    if len(idx) == 0:
        return slice(0, 0)
    if np.array_equal(idx, np.arange(idx[0], idx[0] + len(idx))):
        return slice(int(idx[0]), int(idx[0]) + len(idx))
    return idx


def _stop(idx: slice | np.ndarray) -> int:
    if isinstance(idx, slice):
        return idx.stop
    return int(idx[-1]) + 1 if len(idx) else 0
