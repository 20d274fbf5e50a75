r"""The compiled kernel that writes an SOT's task rows straight into a solver's stacked
buffer (internal to ``sotpy.tasks``: the row programs of :mod:`.rows`).

:func:`write_rows` runs a whole program in one call: for each feature the Jacobian
rows and the error, for each task its targets or bounds, the SOT's joint-limit level
and the tasks read through their signals: the values the features' ``jacobian`` and
``error`` and the tasks' ``task`` (or ``lower``/``upper``) signals hold, without the
intermediate arrays. The formulas are those of the features (``features.py``) and
tasks (``task.py``); the tests compare the two paths on random inputs.

:func:`log3` and :func:`jlog3` are the rotation logarithm and its Jacobian, written
here so that they compile with the rest (Pinocchio's are Python calls):

* ``log3(R) = theta u`` with ``theta = atan2(|w|, (tr R - 1) / 2)``, ``w`` the vector
  of the skew part ``(R - R^T) / 2`` (``w = sin(theta) u``): ``log3 = w theta / |w|``,
  its Taylor series ``w (1 + theta^2 / 6)`` below ``theta = 1e-4``. Near ``pi``
  (``cos theta < -0.9``) the axis comes from the symmetric part, ``u u^T = (R + R^T -
  2 cos(theta) I) / (2 (1 - cos theta))`` (the largest diagonal entry first), its sign
  that of ``w``.
* ``Jlog3(R) = I + [w]/2 + c(theta) [w]^2`` with ``w = log3(R)``,
  ``c = 1/theta^2 - 1/(2 theta tan(theta/2))``, and ``c = 1/12 + theta^2/720 +
  theta^4/30240`` below ``theta = 1e-2``: ``d log3(R exp([d])) / dd`` at ``d = 0``
  (the inverse of the right Jacobian of SO(3)).
"""

from __future__ import annotations

import math

import numpy as np

from .._jit import kernel

_PI_SIDE = -0.9  # cos(theta) below this: the axis from the symmetric part


def _log3(R, out):  # pragma: no cover - compiled (the NumPy twin is Pinocchio's log3)
    """``out <- log3(R)``; returns ``theta``."""
    wx = 0.5 * (R[2, 1] - R[1, 2])
    wy = 0.5 * (R[0, 2] - R[2, 0])
    wz = 0.5 * (R[1, 0] - R[0, 1])
    c = 0.5 * (R[0, 0] + R[1, 1] + R[2, 2] - 1.0)
    s = math.sqrt(wx * wx + wy * wy + wz * wz)
    theta = math.atan2(s, c)
    if c < _PI_SIDE:
        # u u^T = (R + R^T - 2 c I) / (2 (1 - c)): the largest diagonal entry first
        d = 1.0 / (1.0 - c)
        u0 = (R[0, 0] - c) * d
        u1 = (R[1, 1] - c) * d
        u2 = (R[2, 2] - c) * d
        if u0 >= u1 and u0 >= u2:
            a = math.sqrt(max(u0, 0.0))
            x, y, z = a, 0.5 * (R[0, 1] + R[1, 0]) * d / a, 0.5 * (R[0, 2] + R[2, 0]) * d / a
        elif u1 >= u2:
            a = math.sqrt(max(u1, 0.0))
            x, y, z = 0.5 * (R[0, 1] + R[1, 0]) * d / a, a, 0.5 * (R[1, 2] + R[2, 1]) * d / a
        else:
            a = math.sqrt(max(u2, 0.0))
            x, y, z = 0.5 * (R[0, 2] + R[2, 0]) * d / a, 0.5 * (R[1, 2] + R[2, 1]) * d / a, a
        if x * wx + y * wy + z * wz < 0.0:
            x, y, z = -x, -y, -z
        out[0], out[1], out[2] = theta * x, theta * y, theta * z
    else:
        f = 1.0 + theta * theta / 6.0 if theta < 1e-4 else theta / s
        out[0], out[1], out[2] = f * wx, f * wy, f * wz
    return theta


def _jlog3(w, theta, J):  # pragma: no cover - compiled
    """``J <- Jlog3`` at the rotation whose logarithm is ``w`` (``theta = |w|``)."""
    t2 = theta * theta
    if theta < 1e-2:
        c = 1.0 / 12.0 + t2 / 720.0 + t2 * t2 / 30240.0
    else:
        c = 1.0 / t2 - 1.0 / (2.0 * theta * math.tan(0.5 * theta))
    x, y, z = w[0], w[1], w[2]
    # I + [w]/2 + c [w]^2, with [w]^2 = w w^T - theta^2 I
    J[0, 0] = 1.0 + c * (x * x - t2)
    J[1, 1] = 1.0 + c * (y * y - t2)
    J[2, 2] = 1.0 + c * (z * z - t2)
    J[0, 1] = -0.5 * z + c * x * y
    J[1, 0] = 0.5 * z + c * x * y
    J[0, 2] = 0.5 * y + c * x * z
    J[2, 0] = -0.5 * y + c * x * z
    J[1, 2] = -0.5 * x + c * y * z
    J[2, 1] = 0.5 * x + c * y * z


#: Operation kinds of a row program (``code[op, 0]``; see :mod:`.rows` and
#: :func:`_write_rows` for each one's fields).
POSE, GENERIC, POSTURE, ROWS, EQUALITY, INEQUALITY, LIMITS, LEVEL = range(8)
#: How many matrices, vectors and index vectors one call takes (a longer program is
#: cut into several calls, see :class:`.rows.RowProgram`).
MATS, VECS, INTS = 12, 8, 12
#: Width of a program's ``code`` rows: the kind, then up to six fields.
FIELDS = 7

# Return codes of _write_rows besides a row count >= 0.
REFUSED = -1  # something the signals' callbacks would refuse (they then say what)
NO_ROOM = -2  # the rows do not fit in A
RESIZED = -3  # a level's size differs from ``ends`` (with ``fixed``)


def _write_rows(  # pragma: no cover - compiled
    code, scal, state, A, lo, up, ends, fixed,
    m0, m1, m2, m3, m4, m5, m6, m7, m8, m9, m10, m11,
    v0, v1, v2, v3, v4, v5, v6, v7,
    i0, i1, i2, i3, i4, i5, i6, i7, i8, i9, i10, i11,
):  # fmt: skip
    """Run the operations ``code`` (one per row: ``code[op, 0]`` its kind, then its
    fields: positions in ``mats = (m0, ...)``, ``vecs = (v0, ...)``, ``ints = (i0, ...)``
    or ``scal``; -1 for an absent optional one), writing rows of ``A``, ``lo`` and ``up``
    from row ``state[0]`` on. The arrays are positional arguments rather than tuples:
    numba's dispatcher then types them in C, whatever their layout (measured: 2.5 us
    for 40 arrays, 10 us as tuples of mixed layouts).

    A feature's operation writes its selected rows ``k``: the Jacobian row into ``A``
    and its error ``e_k`` into ``lo``.

    * ``POSE (sel, H, H*, Jq)``: FeaturePose, ``H`` and ``H*`` the homogeneous
      matrices of ``M = (R, p)`` and ``M* = (R*, p*)``. ``Mr = (R*^T R, R*^T (p -
      p*))``, ``e = (p_r, log3(R_r))``, ``J = diag(R_r, Jlog3(R_r)) Jq``.
    * ``GENERIC (sel, J, s, s*)``: FeatureGeneric. ``J_k``, ``e_k = s_k - s*_k``
      (``s_k`` without ``s*``).
    * ``POSTURE (iq, iv, q, q*, J, e)``: FeaturePosture's one-DoF joints. Row ``iv_i``
      of the identity, ``e_i = q[iq_i] - q*[iq_i]``; with ``iv = [-1]``, ``J`` and
      ``e`` as ``ROWS`` (a selection with richer joints: the callbacks computed them).
    * ``ROWS (J, e)``: every row as given (a feature's own callbacks computed them).

    A task's operation then closes a level over the rows written since the previous
    level:

    * ``EQUALITY (gain, cols)``: ``lo = up = -gain e``.
    * ``INEQUALITY (c, inf, sup, cols)``: ``lo = -c e + c inf`` and ``up = -c e + c
      sup`` (``-inf``/``+inf`` where a reference is empty), as ``TaskInequality``.
    * ``cols``: the columns the task keeps (``[-1]``: all); the others become 0.

    A level operation writes a whole level:

    * ``LIMITS (iq, iv, q, lim, dt)``: the SOT's joint limits. Row ``iv_i`` of the
      identity, ``lo = clip((lim[0] - q[iq]) / dt, -lim[2], lim[2])``, ``up`` the same
      with ``lim[1]``.
    * ``LEVEL (J, lower, upper)``: a task read through its signals, copied.

    Level ``k`` ends at row ``ends[k]``: written there, or, with ``fixed``, checked
    against it. ``state = (row, first row of the open level, level)`` carries on to the
    next call of a program cut into several. Returns the row after the last one
    written, or :data:`REFUSED` (a shape, a gain, a period or a reference out of range,
    an index out of bounds, a value that is not finite), :data:`NO_ROOM` or
    :data:`RESIZED`; the rows written so far are then not to be used.
    """
    mats = (m0, m1, m2, m3, m4, m5, m6, m7, m8, m9, m10, m11)
    vecs = (v0, v1, v2, v3, v4, v5, v6, v7)
    ints = (i0, i1, i2, i3, i4, i5, i6, i7, i8, i9, i10, i11)
    n = A.shape[1]
    cap = A.shape[0]
    r, t0, lev = state[0], state[1], state[2]
    Rr = np.empty((3, 3))
    Jl = np.empty((3, 3))
    e = np.empty(6)
    keep = np.empty(n, dtype=np.bool_)
    for op in range(code.shape[0]):
        kind = code[op, 0]
        f1, f2, f3, f4, f5, f6 = (
            code[op, 1],
            code[op, 2],
            code[op, 3],
            code[op, 4],
            code[op, 5],
            code[op, 6],
        )
        r0 = r
        closes = False
        if kind == POSTURE and ints[f2].shape[0] == 1 and ints[f2][0] < 0:
            kind, f1, f2 = ROWS, f5, f6  # the rows its callbacks computed
        if kind == POSE:
            sel, H, Hd, Jq = ints[f1], mats[f2], mats[f3], mats[f4]
            if Jq.shape[0] != 6 or Jq.shape[1] != n:
                return REFUSED
            if H.shape[0] != 4 or H.shape[1] != 4 or Hd.shape[0] != 4 or Hd.shape[1] != 4:
                return REFUSED
            k = sel.shape[0]
            if r + k > cap:
                return NO_ROOM
            rot = False
            for i in range(k):
                if sel[i] < 0 or sel[i] >= 6:
                    return REFUSED
                if sel[i] >= 3:
                    rot = True
            # R = H[:3, :3], p = H[:3, 3] (and R*, p* from H*)
            for i in range(3):
                for j in range(3):
                    Rr[i, j] = Hd[0, i] * H[0, j] + Hd[1, i] * H[1, j] + Hd[2, i] * H[2, j]
            for i in range(3):
                e[i] = (
                    Hd[0, i] * (H[0, 3] - Hd[0, 3])
                    + Hd[1, i] * (H[1, 3] - Hd[1, 3])
                    + Hd[2, i] * (H[2, 3] - Hd[2, 3])
                )
            if rot:
                theta = _log3_c(Rr, e[3:])
                _jlog3_c(e[3:], theta, Jl)
            for i in range(k):
                kk = sel[i]
                D = Rr if kk < 3 else Jl
                off = 0 if kk < 3 else 3
                d0, d1, d2 = D[kk - off, 0], D[kk - off, 1], D[kk - off, 2]
                for j in range(n):
                    A[r + i, j] = d0 * Jq[off, j] + d1 * Jq[off + 1, j] + d2 * Jq[off + 2, j]
                lo[r + i] = e[kk]
            r += k
        elif kind == GENERIC:
            sel, J, s = ints[f1], mats[f2], vecs[f3]
            m = s.shape[0]
            ref = f4 >= 0
            sd = vecs[f4] if ref else s
            if J.shape[0] != m or J.shape[1] != n or sd.shape[0] != m:
                return REFUSED
            k = sel.shape[0]
            if r + k > cap:
                return NO_ROOM
            for i in range(k):
                kk = sel[i]
                if kk < 0 or kk >= m:
                    return REFUSED
                for j in range(n):
                    A[r + i, j] = J[kk, j]
                lo[r + i] = s[kk] - sd[kk] if ref else s[kk]
            r += k
        elif kind in (POSTURE, LIMITS):
            iq, iv, q = ints[f1], ints[f2], vecs[f3]
            k = iv.shape[0]
            if iq.shape[0] != k:
                return REFUSED
            if r + k > cap:
                return NO_ROOM
            qd = vecs[f4] if kind == POSTURE else q
            lim = mats[f4] if kind == LIMITS else mats[0]
            if kind == LIMITS and (lim.shape[0] != 3 or lim.shape[1] != k):
                return REFUSED
            dt = scal[f5] if kind == LIMITS else 1.0
            if not dt > 0.0:
                return REFUSED
            for i in range(k):
                a, c = iq[i], iv[i]
                if a < 0 or a >= q.shape[0] or a >= qd.shape[0] or c < 0 or c >= n:
                    return REFUSED
                for j in range(n):
                    A[r + i, j] = 0.0
                A[r + i, c] = 1.0
                if kind == POSTURE:
                    lo[r + i] = q[a] - qd[a]
                else:  # the operations and order of SOT._limitLevel (NaN stays NaN)
                    v = lim[2, i]
                    x = (lim[0, i] - q[a]) / dt
                    y = (lim[1, i] - q[a]) / dt
                    x = -v if x < -v else x
                    x = v if x > v else x
                    y = -v if y < -v else y
                    y = v if y > v else y
                    lo[r + i] = x
                    up[r + i] = y
            r += k
            closes = kind == LIMITS
        elif kind in (ROWS, LEVEL):
            J, b = mats[f1], vecs[f2]
            m = b.shape[0]
            bu = vecs[f3] if kind == LEVEL else b
            if J.shape[0] != m or J.shape[1] != n or bu.shape[0] != m:
                return REFUSED
            if r + m > cap:
                return NO_ROOM
            for i in range(m):
                for j in range(n):
                    A[r + i, j] = J[i, j]
                lo[r + i] = b[i]
                if kind == LEVEL:
                    up[r + i] = bu[i]
            r += m
            closes = kind == LEVEL
        elif kind in (EQUALITY, INEQUALITY):
            cols = ints[f2] if kind == EQUALITY else ints[f4]
            ss = 0.0
            for i in range(t0, r):
                ss += lo[i] * lo[i]
            if not math.isfinite(ss):  # an error that overflowed: the callbacks say so
                return REFUSED
            if kind == EQUALITY:
                g = scal[f1]
                if not (g >= 0.0 and g < math.inf):
                    return REFUSED
                ss = 0.0
                for i in range(t0, r):
                    lo[i] = -g * lo[i]
                    up[i] = lo[i]
                    ss += lo[i] * lo[i]
                if not math.isfinite(ss):  # a target that overflowed
                    return REFUSED
            else:
                c, rinf, rsup = scal[f1], vecs[f2], vecs[f3]
                m = r - t0
                ni, ns = rinf.shape[0], rsup.shape[0]
                if (ni != 0 and ni != m) or (ns != 0 and ns != m) or not 0.0 < c < math.inf:
                    return REFUSED
                for i in range(m):
                    b = -c * lo[t0 + i]
                    lower, upper = -math.inf, math.inf
                    if ni:
                        ri = rinf[i]
                        if not ri < math.inf:
                            return REFUSED
                        lower = ri * c + b
                        if math.isfinite(ri) != math.isfinite(lower):
                            return REFUSED
                    if ns:
                        si = rsup[i]
                        if not si > -math.inf:
                            return REFUSED
                        if ni and rinf[i] > si:
                            return REFUSED
                        upper = si * c + b
                        if math.isfinite(si) != math.isfinite(upper):
                            return REFUSED
                    lo[t0 + i] = lower
                    up[t0 + i] = upper
            if not (cols.shape[0] == 1 and cols[0] < 0):  # a column selection
                keep[:] = False
                for j in range(cols.shape[0]):
                    if cols[j] < 0 or cols[j] >= n:
                        return REFUSED
                    keep[cols[j]] = True
                for i in range(t0, r):
                    for j in range(n):
                        if not keep[j]:
                            A[i, j] = 0.0
            closes = True
        else:
            return REFUSED
        if kind in (POSE, GENERIC, ROWS, LEVEL):  # not the identity's rows
            # the Jacobian rows written by this operation: finite (a sum of squares that is)
            ss = 0.0
            for i in range(r0, r):
                for j in range(n):
                    ss += A[i, j] * A[i, j]
            if not math.isfinite(ss):
                return REFUSED
        if closes:
            if fixed:
                if lev >= ends.shape[0] or ends[lev] != r:
                    return RESIZED
            elif lev < ends.shape[0]:
                ends[lev] = r
            else:  # more levels than ``ends`` holds: not this program's
                return REFUSED
            lev += 1
            t0 = r
    state[0], state[1], state[2] = r, t0, lev
    return r


_log3_c = kernel(_log3)
_jlog3_c = kernel(_jlog3)
write_rows = kernel(_write_rows)
_warm: list[bool] = []


def log3(R: np.ndarray) -> np.ndarray:
    """The compiled ``log3`` (tests compare it with Pinocchio's; needs numba)."""
    out = np.empty(3)
    _log3_c(np.ascontiguousarray(R, dtype=float), out)  # type: ignore[misc]
    return out


def jlog3(R: np.ndarray) -> np.ndarray:
    """The compiled ``Jlog3`` (tests compare it with Pinocchio's)."""
    w = log3(R)
    J = np.empty((3, 3))
    _jlog3_c(w, float(np.linalg.norm(w)), J)  # type: ignore[misc]
    return J


def _padding(ndim: int, dtype: type) -> np.ndarray:
    """A read-only array of layout ``A`` (a strided view): the type every matrix,
    vector or index argument of :func:`write_rows` is compiled for. numba converts any
    float64 (int64) array of that dimension to it, C or Fortran, writable or not, so
    that one compiled version serves them all."""
    a = np.zeros((3, 4) if ndim == 2 else 4, dtype=dtype)[..., ::2]
    a.setflags(write=False)
    return a


#: The arguments a call of ``write_rows`` pads its unused positions with.
PAD = (
    (_padding(2, np.float64),) * MATS + (_padding(1, np.float64),) * VECS
    + (_padding(1, np.int64),) * INTS
)  # fmt: skip


def warm_up() -> None:
    """Compile (or load from the cache) ``write_rows`` for the argument types it is
    given (see :func:`_padding`; the rows go to C-ordered arrays, the solver's stacked
    buffers and the SOT's own), then forbid further compilation: an unforeseen type (an
    integer Jacobian) raises ``TypeError`` at the call and the caller goes back to the
    signals, instead of compiling mid-loop."""
    if write_rows is None or _warm:
        return
    A = np.zeros((6, 2))
    b = np.zeros(6)
    code = np.full((1, FIELDS), -1, dtype=np.int64)
    code[0, 0] = LIMITS
    write_rows(code[:0], b, np.zeros(3, np.int64), A, b, b, np.zeros(1, np.int64), False, *PAD)
    log3(np.eye(3))
    jlog3(np.eye(3))
    for k in (write_rows, _log3_c, _jlog3_c):
        k.disable_compile()
    _warm.append(True)
