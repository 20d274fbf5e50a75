"""QP back-ends of the hierarchical cascade (internal to ``sotpy.solvers``).

Each level of the cascade that needs a QP keeps one persistent problem
``min 1/2 v^T H v + g^T v  s.t.  lo <= C v <= up`` (dense, small), re-created only when
its sizes change:

* :class:`DaqpQP` (default): DAQP's dual active-set solver (``daqp.Model``); the
  working set of the previous solve is the warm start (constraint rows keep their
  meaning from one tick to the next even when the reduced coordinates rotate); a
  semi-definite ``H`` is handled by DAQP's proximal regularisation. Exact up to its
  primal tolerance, typically 10-30 us per level here.
* :class:`ProxQP`: proxsuite's dense proximal ALM solver, warm-started from the
  previous solution mapped into the current coordinates. It needs a duality-gap test
  (small KKT residuals alone accepted points whose objective was off by 1e-4), no
  preconditioner (zero rows spoil it), and on the degenerate sets left by frozen
  levels it may stall near its tolerance (hence an eps of at least 1e-8).

DAQP's own hierarchical mode (``break_points``) was evaluated and is not used: it
measures each level's violation on rows normalised to unit norm (a weighted least
squares, not ``||A x - b||``) and with the small slack weights needed for accuracy it
often stops early (exit flag 3); see ``docs/solvers.md``.
"""

from __future__ import annotations

import numpy as np

try:
    import daqp as _daqp
except ImportError:  # pragma: no cover - daqp is a dependency; keep the message clear
    _daqp = None

import proxsuite

_Dense = proxsuite.proxqp.dense.QP
_WARM_START = proxsuite.proxqp.InitialGuess.WARM_START
_WARM_PREVIOUS = proxsuite.proxqp.InitialGuess.WARM_START_WITH_PREVIOUS_RESULT
_EQ_GUESS = proxsuite.proxqp.InitialGuess.EQUALITY_CONSTRAINED_INITIAL_GUESS
_SOLVED = proxsuite.proxqp.QPSolverOutput.PROXQP_SOLVED

#: DAQP's stand-in for an infinite bound.
_DAQP_INF = 1e30


def daqp_available() -> bool:
    """Whether the ``daqp`` package can be imported."""
    return _daqp is not None


class DaqpQP:
    """A persistent DAQP problem (see the module docstring)."""

    __slots__ = ("_model", "_sense", "_settings", "iterations", "m", "nv", "status_ok")

    def __init__(self, eps: float, max_iter: int):
        self._model = None
        self._sense = None
        # Forced proximal regularisation (eps_prox > 0) with a tight stopping test
        # (eta_prox): the level QPs have semi-definite Hessians (no cost on directions
        # that only the constraints see), and DAQP's automatic setting stopped with
        # slacks of 1e-7 where the optimum is 0. A small eps_prox (1e-5) needed
        # thousands of outer iterations on some levels; 1e-2 needs about 5-20.
        self._settings = {
            "primal_tol": eps,
            "iter_limit": max_iter,
            "eps_prox": 1e-2,
            "eta_prox": 1e-13,
        }
        self.nv = -1
        self.m = -1
        self.iterations = 0
        self.status_ok = True

    def solve(self, H, g, C, lo, up, v0=None, z0=None) -> tuple[np.ndarray, np.ndarray]:
        """Solve; return ``(v, multipliers)``. ``v0``/``z0`` are ignored (the previous
        working set is the warm start)."""
        nv = H.shape[0]
        m = C.shape[0]
        bu = np.minimum(up, _DAQP_INF)
        bl = np.maximum(lo, -_DAQP_INF)
        model = self._model
        if model is None or nv != self.nv or m != self.m:
            model = _daqp.Model()
            model.settings = self._settings
            self._sense = np.zeros(m, dtype=np.intc)
            flag, _ = model.setup(H, g, C, bu, bl, self._sense)
            self._model = model
            self.nv = nv
            self.m = m
            if flag < 0:
                self._model = None
                self.status_ok = False
                self.iterations = 0
                return np.zeros(nv), np.zeros(m)
        else:
            model.update(H=H, f=g, A=C, bupper=bu, blower=bl)
        x, _fval, exitflag, info = model.solve()
        self.iterations = int(info["iterations"])
        self.status_ok = exitflag > 0
        if not self.status_ok:
            self._model = None  # start afresh next time
        return x, info["lam"]

    def reset(self) -> None:
        """Forget the problem (the next solve sets it up again)."""
        self._model = None


class ProxQP:
    """A persistent proxsuite dense problem (see the module docstring)."""

    __slots__ = ("_qp", "_solved", "eps", "iterations", "max_iter", "nin", "nv", "status_ok")

    def __init__(self, eps: float, max_iter: int):
        self._qp = None
        self._solved = False
        self.nv = -1
        self.nin = -1
        self.eps = eps
        self.max_iter = max_iter
        self.iterations = 0
        self.status_ok = True

    def solve(self, H, g, C, lo, up, v0=None, z0=None) -> tuple[np.ndarray, np.ndarray]:
        """Solve; return ``(v, z)`` (primal solution, inequality multipliers).

        ``v0``/``z0`` warm-start the primal and dual iterates; without them the previous
        result is the warm start (or proxsuite's own initial guess for a new problem).
        """
        nv = H.shape[0]
        nin = C.shape[0]
        qp = self._qp
        if qp is None or nv != self.nv or nin != self.nin:
            self._solved = False
            qp = _Dense(nv, 0, nin)
            s = qp.settings
            s.eps_abs = self.eps
            s.eps_rel = 0.0
            s.max_iter = self.max_iter
            s.max_iter_in = 100
            s.verbose = False
            s.compute_timings = False
            # small KKT residuals alone can stop at a point whose objective is off by
            # orders of magnitude more than eps (complementarity not yet reached): also
            # require a small duality gap
            s.check_duality_gap = True
            s.eps_duality_gap_abs = self.eps
            s.eps_duality_gap_rel = self.eps
            # every QP of the cascade is feasible by construction (the previous level's
            # point satisfies all its rows): keep the infeasibility test from misfiring
            # on the thin sets left by frozen levels
            s.eps_primal_inf = 1e-30
            s.eps_dual_inf = 1e-30
            # no Ruiz preconditioner: rows of frozen levels that are pinned have zero
            # coefficients in the reduced coordinates, and with such rows proxsuite's
            # equilibration returned "solved" points whose objective was off by 25 %
            qp.init(H, g, None, None, C, lo, up, False)
            self._qp = qp
            self.nv = nv
            self.nin = nin
        else:
            qp.update(H, g, None, None, C, lo, up, False)
        s = qp.settings
        if v0 is not None:
            s.initial_guess = _WARM_START
            qp.solve(v0, None, z0)
        elif self._solved:
            s.initial_guess = _WARM_PREVIOUS
            qp.solve()
        else:
            s.initial_guess = _EQ_GUESS
            qp.solve()
        self._solved = True
        res = qp.results
        info = res.info
        self.iterations = info.iter
        self.status_ok = info.status == _SOLVED
        return res.x, res.z

    def reset(self) -> None:
        """Forget the problem (the next solve re-initialises it)."""
        self._qp = None
        self._solved = False
