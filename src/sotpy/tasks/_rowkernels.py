r"""The compiled kernels that write task rows straight into a solver's buffers: an
SOT's stack (the row programs of :mod:`.rows`) and a whole-body controller's problem
(:mod:`sotpy.solvers.wbc.program`). Internal; one module because both use the
rotation and pose logarithms below, and numba's cache does not notice a change in
another file's kernel that a cached kernel calls.

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
* ``log6(M) = (V(w)^-1 p, w)`` for ``M = (R, p)``, ``w = log3(R)``, with ``V^-1 = I -
  [w]/2 + c(theta) [w]^2 = Jlog3(R)^T`` (the same ``c``), as Pinocchio's ``log6``
  (linear part first): the contact feedback's pose error.
"""

from __future__ import annotations

import math

import numpy as np

from .._jit import any_layout, kernel

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


def _relative(H, Hd, Rr, p):  # pragma: no cover - compiled
    """``(Rr, p[:3]) <- M*^-1 M = (R*^T R, R*^T (p - p*))`` of the homogeneous matrices
    ``H`` of ``M = (R, p)`` and ``Hd`` of ``M* = (R*, p*)``."""
    for i in range(3):
        for j in range(3):
            Rr[i, j] = Hd[0, i] * H[0, j] + Hd[1, i] * H[1, j] + Hd[2, i] * H[2, j]
    for i in range(3):
        p[i] = (
            Hd[0, i] * (H[0, 3] - Hd[0, 3])
            + Hd[1, i] * (H[1, 3] - Hd[1, 3])
            + Hd[2, i] * (H[2, 3] - Hd[2, 3])
        )


def _log6(H, Hd, out, Rr, Jl):  # pragma: no cover - compiled (the twin: Pinocchio's log6)
    """``out <- log6(M*^-1 M)`` (linear then angular) of the homogeneous matrices ``H``
    and ``Hd``: with ``(Rr, pr) = M*^-1 M`` and ``w = log3(Rr)``, the linear part is
    ``V(w)^-1 pr = Jlog3(Rr)^T pr`` (``V^-1 = I - [w]/2 + c [w]^2``, the transpose of
    ``Jlog3``, see the module doc)."""
    _relative_c(H, Hd, Rr, out)
    theta = _log3_c(Rr, out[3:])
    _jlog3_c(out[3:], theta, Jl)
    p0, p1, p2 = out[0], out[1], out[2]
    for i in range(3):
        out[i] = Jl[0, i] * p0 + Jl[1, i] * p1 + Jl[2, i] * p2


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
            _relative_c(H, Hd, Rr, e)
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


#: The operations of :func:`_write_problem`, the whole-body controller's writer
#: (``code[op, 0]``; see :mod:`sotpy.solvers.wbc.program`).
WBC_DYNAMICS, WBC_CONTACT, WBC_TASK, WBC_COST = 0, 1, 2, 3
#: Its ``code`` rows: kind, row, column, rows, then positions of arrays and scalars.
WBC_FIELDS = 10
#: The matrices and vectors one of its calls takes (a longer program: several calls).
WBC_MATS, WBC_VECS = 10, 16


def _write_problem(  # pragma: no cover - compiled
    data, offs, nv, n, m, mc, code, scal, M, b,
    m0, m1, m2, m3, m4, m5, m6, m7, m8, m9,
    v0, v1, v2, v3, v4, v5, v6, v7, v8, v9, v10, v11, v12, v13, v14, v15,
):  # fmt: skip
    """Write the entries of a whole-body problem that change with the state, into the
    packed array ``data``: ``A`` (nv x n), ``c``, ``E`` (m x n), ``f``, ``w``, ``C`` (mc
    x n), ``lo``, ``hi`` at the offsets ``offs`` (in that order). Each row of ``code``
    is an operation, its fields ``kind, row, col, k, J, H, Hd, u, x, s``: ``J, H, Hd``
    positions in ``mats = (m0, ...)``, ``u, x`` in ``vecs = (v0, ...)``, ``s`` in
    ``scal``; -1 for an absent one. Every row of ``J`` has ``nv`` entries (the columns
    of ``a``); the other entries of the rows written are constant (the Python writers
    wrote them when the buffers were made).

    * ``WBC_DYNAMICS``: ``A[:, :nv] = M`` (``M``'s upper triangle, mirrored: Pinocchio's
      CRBA fills only that one) and ``c = -b``.
    * ``WBC_CONTACT (row, col, k, J, H, Hd, u = drift, x = qdot, s)``: ``A[:, col:col+k]
      = -J^T`` (the contact's wrench columns of the equations of motion; the first
      ``k`` rows of ``J``); with ``row >= 0`` also the contact rows ``C[row:row+k, :nv]
      = J`` and ``lo = hi = -drift - kp e - kd J qdot`` (the first ``k`` entries). The
      feedback, with ``H >= 0``: ``e = log6(M*^-1 M)`` of the frame's placement ``M``
      (homogeneous ``H``) and its reference ``M*`` (``Hd``), ``J qdot`` the frame's
      twist, ``kp = scal[s]``, ``kd = scal[s + 1]``.
    * ``WBC_TASK (row, k, J, u = drift, x = desired, s = w)``: ``E[row:row+k, :nv] = J``
      (with ``J``), ``f = desired - drift`` (``drift`` optional) and the row weights
      ``w = vecs[s]``.
    * ``WBC_COST (row, k, col, x = f, s)``: the contact wrench cost's weights of one
      contact, ``w[row:row+k] = scal[s] / F^2`` with ``F = max(f[col], scal[s + 1])``
      (``f`` the wrenches of the last solution, ``col`` the contact's normal force), or
      ``max(scal[s + 2], scal[s + 1])`` when ``f`` is empty.

    Returns 0, or :data:`REFUSED` (an array of an unexpected shape, a row outside the
    buffers: nothing is to be used; the caller writes the tick in Python).
    """
    mats = (m0, m1, m2, m3, m4, m5, m6, m7, m8, m9)
    vecs = (v0, v1, v2, v3, v4, v5, v6, v7, v8, v9, v10, v11, v12, v13, v14, v15)
    A = data[offs[0] : offs[0] + nv * n].reshape((nv, n))
    c = data[offs[1] : offs[1] + nv]
    E = data[offs[2] : offs[2] + m * n].reshape((m, n))
    f = data[offs[3] : offs[3] + m]
    w = data[offs[4] : offs[4] + m]
    C = data[offs[5] : offs[5] + mc * n].reshape((mc, n))
    lo = data[offs[6] : offs[6] + mc]
    hi = data[offs[7] : offs[7] + mc]
    e = np.empty(6)
    Rr = np.empty((3, 3))
    Jl = np.empty((3, 3))
    for op in range(code.shape[0]):
        kind, row, col, k = code[op, 0], code[op, 1], code[op, 2], code[op, 3]
        jm, ih, ihd, u, x, s = (
            code[op, 4], code[op, 5], code[op, 6], code[op, 7], code[op, 8], code[op, 9]
        )  # fmt: skip
        if kind == WBC_DYNAMICS:
            if M.shape[0] != nv or M.shape[1] != nv or b.shape[0] != nv:
                return REFUSED
            for i in range(nv):
                for j in range(nv):
                    A[i, j] = M[i, j] if i <= j else M[j, i]
                c[i] = -b[i]
            continue
        J = mats[jm]
        if kind == WBC_CONTACT:
            if jm < 0 or J.shape[0] < k or J.shape[1] != nv or col < nv or col + k > n:
                return REFUSED
            for i in range(nv):
                for j in range(k):
                    A[i, col + j] = -J[j, i]
            if row < 0:
                continue
            if u < 0 or vecs[u].shape[0] < k or row + k > mc or k > 6:
                return REFUSED
            feedback = ih >= 0
            if feedback:
                H, Hd, qdot = mats[ih], mats[ihd], vecs[x]
                if H.shape[0] != 4 or H.shape[1] != 4 or Hd.shape[0] != 4 or Hd.shape[1] != 4:
                    return REFUSED
                if qdot.shape[0] != nv:
                    return REFUSED
                _log6_c(H, Hd, e, Rr, Jl)
            drift = vecs[u]
            for i in range(k):
                Ci = C[row + i]
                Ji = J[i]
                nu = 0.0
                for j in range(nv):
                    Ci[j] = Ji[j]
                rhs = -drift[i]
                if feedback:
                    for j in range(nv):
                        nu += Ji[j] * vecs[x][j]
                    rhs -= scal[s] * e[i] + scal[s + 1] * nu
                lo[row + i] = rhs
                hi[row + i] = rhs
        elif kind == WBC_TASK:
            d, wk = vecs[x], vecs[s]
            if jm >= 0 and (J.shape[0] != k or J.shape[1] != nv):
                return REFUSED
            if row < 0 or row + k > m or d.shape[0] != k or wk.shape[0] != k:
                return REFUSED
            if u >= 0 and vecs[u].shape[0] != k:
                return REFUSED
            for i in range(k):
                if jm >= 0:
                    Ei = E[row + i]
                    Ji = J[i]
                    for j in range(nv):
                        Ei[j] = Ji[j]
                f[row + i] = d[i] - vecs[u][i] if u >= 0 else d[i]
                w[row + i] = wk[i]
        elif kind == WBC_COST:
            if row < 0 or row + k > m or col < 0:
                return REFUSED
            loads = vecs[x]
            F = loads[col] if loads.shape[0] > col else scal[s + 2]
            F = max(F, scal[s + 1])
            for i in range(k):
                w[row + i] = scal[s] / (F * F)
        else:
            return REFUSED
    return 0


_log3_c = kernel(_log3)
_jlog3_c = kernel(_jlog3)
_relative_c = kernel(_relative)
_log6_c = kernel(_log6)
write_rows = kernel(_write_rows)
write_problem = kernel(_write_problem)
_warm: list[bool] = []


def log3(R: np.ndarray) -> np.ndarray:
    """The compiled ``log3`` (tests compare it with Pinocchio's; needs numba)."""
    out = np.empty(3)
    _log3_c(np.ascontiguousarray(R, dtype=float), out)  # type: ignore[misc]
    return out


def log6(H: np.ndarray, Hd: np.ndarray) -> np.ndarray:
    """The compiled ``log6(M*^-1 M)`` of two homogeneous matrices (tests compare it with
    Pinocchio's)."""
    out = np.empty(6)
    _log6_c(np.ascontiguousarray(H, dtype=float), np.ascontiguousarray(Hd, dtype=float),
            out, np.empty((3, 3)), np.empty((3, 3)))  # type: ignore[misc]  # fmt: skip
    return out


def jlog3(R: np.ndarray) -> np.ndarray:
    """The compiled ``Jlog3`` (tests compare it with Pinocchio's)."""
    w = log3(R)
    J = np.empty((3, 3))
    _jlog3_c(w, float(np.linalg.norm(w)), J)  # type: ignore[misc]
    return J


#: The arguments a call of ``write_rows`` pads its unused positions with.
PAD = (
    (any_layout(2),) * MATS + (any_layout(1),) * VECS + (any_layout(1, np.int64),) * INTS
)  # fmt: skip
#: The same for ``write_problem``.
WBC_PAD = (any_layout(2),) * WBC_MATS + (any_layout(1),) * WBC_VECS


def warm_up() -> None:
    """Compile (or load from the cache) ``write_rows`` for the argument types it is
    given (see :func:`sotpy._jit.any_layout`; the rows go to C-ordered arrays, the solver's stacked
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
    wcode = np.full((1, WBC_FIELDS), -1, dtype=np.int64)
    wcode[0, 0] = WBC_DYNAMICS
    write_problem(np.zeros(12), np.zeros(8, np.int64), 2, 3, 0, 0, wcode[:0], np.zeros(1),
                  any_layout(2), any_layout(1), *WBC_PAD)  # fmt: skip
    log3(np.eye(3))
    jlog3(np.eye(3))
    log6(np.eye(4), np.eye(4))
    for k in (write_rows, write_problem, _log3_c, _jlog3_c, _log6_c):
        k.disable_compile()
    _warm.append(True)
