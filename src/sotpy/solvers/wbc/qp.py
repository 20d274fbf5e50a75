r"""The one-level weighted QP of a tick, in the reduced variables ``y = (a, f)``.

The problem over ``chi = (a, tau, f)`` (see :mod:`.solver`)::

    min_chi  1/2 sum_k ||W_k^(1/2) (E_k chi - f_k)||^2 + 1/2 eps ||(a, f)||^2
    s.t.     A_dyn chi = c_dyn,   lb <= C chi <= ub

has the torques given by the actuated rows ``r`` of the equations of motion,
``tau = M_r a - J_r^T f + b_r = T_tau y + t_tau``, so ``chi = T y + t0`` with ``T``
the identity on ``a`` and ``f``. Substituting is exact: the optimum over ``y`` with the
unactuated rows ``u`` as equalities is the optimum over ``chi``. Every row block
``(E, f)`` maps to ``(E_a | E_f) + E_tau T_tau`` and ``f - E_tau t_tau``; the product is
skipped when ``E_tau`` is zero (acceleration, CoM and contact rows), so the reduced data
cost one product per block that touches the torques (torque tasks and limits) instead
of ``T^T H T``. The regularisation ``eps ||y||^2`` is on the accelerations and the
wrenches only (the torques are their function), so that the Hessian's force block is
coupled to the accelerations' only by rows that touch both (torque rows).

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

from ... import _jit
from ..._jit import refused
from ...errors import SotpyError
from . import _kernels
from .model import Layout

__all__ = ["DUAL_TOL", "PRIMAL_TOL", "WeightedQP", "pack", "packed_views"]

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
_NO_UNIT = np.zeros(0, dtype=np.intp)
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
        if jit and (_kernels.solve is None or not tail):
            raise SotpyError(
                f"WeightedQP: compiled kernels unavailable ({_jit.UNAVAILABLE};"
                " or actuated joints that are not the last velocities)"
            )
        self.jit = bool(_kernels.solve is not None and tail) if jit is None else bool(jit)
        if self.jit or (jit is None and tail):
            # loaded from the cache; on a machine's first use compiled in the background
            # for the next runs (this one keeps the NumPy code), said on stderr first
            _jit.prepare("the whole-body QP kernel", ["sotpy.solvers.wbc._kernels"])
        self.guess_hits = 0
        self.daqp_solves = 0
        self.last_residual: float | None = None  # the compiled guess's dynamics residual
        self.last_method = ""
        self._key: tuple | None = None
        self._ws: tuple | None = None  # (sizes, workspace, views) of the compiled kernel
        self._active = np.zeros(0, dtype=np.intp)  # indices into the constraint rows
        self._upper = np.zeros(0, dtype=bool)  # at the upper bound (else the lower)
        self._unit = _NO_UNIT  # what each row is (see solve_rows)
        self._structure: object = None  # whose constant rows ``unit`` marks
        self._written: tuple | None = None  # (structure, workspace) of the last call

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
        H = regularisation * np.eye(ny)
        g = np.zeros(ny)
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

    # --------------------------------------------------------------------- solve
    def solve(
        self, layout: Layout, dyn, cons, tasks, regularisation: float
    ) -> tuple[np.ndarray | None, str]:
        """``(chi, "")`` at the optimum, or ``(None, reason)``; ``tasks`` as
        :meth:`.solver.WholeBodyController.problem` returns them."""
        if tasks:
            E = np.vstack([t[1] for t in tasks]) if len(tasks) > 1 else tasks[0][1]
            f = np.concatenate([t[2] for t in tasks])
            w = np.concatenate([t[3] for t in tasks])
        else:
            E, f, w = np.zeros((0, layout.n)), np.zeros(0), np.zeros(0)
        return self.solve_rows(layout, dyn[0], dyn[1], E, f, w, *cons, regularisation)

    def solve_rows(
        self,
        layout: Layout,
        A,
        c,
        E,
        f,
        w,
        C,
        lo,
        hi,
        regularisation: float,
        packed=None,
        keep: int = 0,
        unit: np.ndarray | None = None,
        structure: object = None,
    ) -> tuple[np.ndarray | None, str]:
        """:meth:`solve` with the task rows stacked (``E`` m x n, ``f``, ``w`` = diag W).
        ``packed``: the flat array the arrays are views of, laid out by
        ``_kernels.data_layout`` (the controller's buffers are); otherwise they
        are copied into one for the compiled kernel. ``keep``: the constraint rows of
        the previous solve kept at the same places when the number of rows changed
        (rows appended or removed at the end): its active set is still a guess there.
        ``unit``: for the compiled kernel, what each task then constraint row is (a row
        of the identity, without torque entries, constant: ``_kernels.solve``; the
        controller's :meth:`~.solver.WholeBodyController.problem` knows it), and
        ``structure``: an object that stays the same exactly while the rows marked
        constant do (the kernel then keeps what it computed for them)."""
        nv, na, n = layout.nv, layout.na, layout.n
        m, mc = E.shape[0], C.shape[0]
        known = unit is not None and len(unit) == m + mc and structure is not None
        self._unit = unit if known else _NO_UNIT
        self._structure = structure if known else None
        key = (n, mc, nv - na)
        self.last_residual: float | None = None
        if key != self._key and self._key is not None and keep and self._key[0::2] == key[0::2]:
            inside = self._active < min(keep, mc)
            self._active, self._upper = self._active[inside], self._upper[inside]
            self._key = key
        guess = key == self._key
        y = None
        data = views = None
        if self.jit:
            try:
                if packed is None:
                    packed = pack(layout, A, c, E, f, w, C, lo, hi)
                ws, views = self._workspace(nv, na, n, m, mc)
                args = (packed, ws, nv, na, n, m, mc, float(regularisation))
                status, ok = self._kernel(*args, guess)
                data = views
                if ok:  # the kernel assembled chi and its residual
                    self.guess_hits += 1
                    self.last_method = "guess"
                    self.last_residual = float(views[11][0])
                    return views[10].copy(), ""
            except TypeError as exc:  # argument types the kernel was not compiled for
                self._stop_jit(exc)
                data = None
        if data is None:
            data = self.reduce(layout, (A, c), (C, lo, hi), [(0, E, f, w)], regularisation)
            lo_y, hi_y = data[5], data[6]
            status = 1 if np.isnan(lo_y).any() or np.isnan(hi_y).any() else 0
            status = status or (2 if (lo_y > hi_y + 1e-12).any() else 0)
            if not status and guess:
                y = self._try_guess(*data[:7], lo == hi)
        if status:
            return None, _STATUS[status]
        H, g, Au, cu, Cy, lo_y, hi_y, Tt, tt = data[:9]
        if y is not None:
            self.guess_hits += 1
            self.last_method = "guess"
        else:
            y, reason = self._daqp(H, g, Au, cu, Cy, lo_y, hi_y, lo == hi, key)
            if y is None:
                return None, reason
            self.daqp_solves += 1
            self.last_method = "daqp"
            # polish: DAQP's active set solved exactly (DAQP stops at its tolerance,
            # far from the optimum along the nearly flat directions of the wrenches)
            exact = None
            if views is not None and data is views:
                if self._kernel(*args, True)[1]:
                    exact = views[9]
            else:
                exact = self._try_guess(H, g, Au, cu, Cy, lo_y, hi_y, lo == hi)
            if exact is not None:
                y = exact
        chi = np.empty(n)
        chi[:nv] = y[:nv]
        chi[nv + na :] = y[nv:]
        chi[nv : nv + na] = Tt @ y + tt
        return chi, ""

    def _kernel(self, packed, ws, nv, na, n, m, mc, reg, guess) -> tuple[int, bool]:
        fresh = self._written != (self._structure, id(ws))
        self._written = (self._structure, id(ws))
        return _kernels.solve(
            packed, ws, self._active, self._upper, self._unit, fresh, nv, na, n, m, mc, reg,
            guess, PRIMAL_TOL, DUAL_TOL, _LAMBDA_MAX,
        )  # fmt: skip

    def _workspace(self, nv: int, na: int, n: int, m: int, mc: int) -> tuple[np.ndarray, list]:
        """The kernel's workspace for these sizes (kept) and its views ``(H, g, Au, cu,
        Cy, lo_y, hi_y, Tt, tt, y, chi, res)``."""
        dims = (nv, na, n, m, mc)
        if self._ws is None or self._ws[0] != dims:
            lay = _kernels.work_layout(*dims)
            ws = np.zeros(lay["size"][0])
            names = ("H", "g", "Au", "cu", "Cy", "lo_y", "hi_y", "Tt", "tt", "y", "chi", "res")
            views = [_view(ws, *lay[k]) for k in names]
            self._ws = (dims, ws, views)
        return self._ws[1], self._ws[2]

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


def _view(buf: np.ndarray, offset: int, shape: tuple) -> np.ndarray:
    return buf[offset : offset + int(np.prod(shape))].reshape(shape)


def pack(layout: Layout, A, c, E, f, w, C, lo, hi) -> np.ndarray:
    """The problem's arrays copied into one flat array (``_kernels.data_layout``)."""
    lay = _kernels.data_layout(layout.nv, layout.na, layout.n, E.shape[0], C.shape[0])
    data = np.empty(lay["size"][0])
    for name, arr in zip(("A", "c", "E", "f", "w", "C", "lo", "hi"), (A, c, E, f, w, C, lo, hi),
                         strict=True):  # fmt: skip
        _view(data, *lay[name])[...] = arr
    return data


def packed_views(data: np.ndarray, nv: int, na: int, n: int, m: int, mc: int) -> dict:
    """The views ``A, c, E, f, w, C, lo, hi`` of a packed array."""
    lay = _kernels.data_layout(nv, na, n, m, mc)
    return {k: _view(data, *v) for k, v in lay.items() if k != "size"}


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


def _to_y_into(
    E: np.ndarray, out: np.ndarray, nv: int, na: int, Tt: np.ndarray, tt: np.ndarray
) -> np.ndarray | None:
    """Write the rows ``E`` (over ``chi``) as rows over ``y`` into ``out``: ``E chi =
    out y + E_tau t_tau``. Returns ``E_tau t_tau`` to subtract from the rows' targets,
    or None when ``E`` has no torque entry."""
    Et = E[:, nv : nv + na]
    out[:, :nv] = E[:, :nv]
    out[:, nv:] = E[:, nv + na :]
    if not Et.any():
        return None
    out += Et @ Tt
    return Et @ tt


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
