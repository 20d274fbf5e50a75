r"""Compiled kernels of the collision pass (internal to :mod:`sotpy.tasks.collision`).

:func:`broad_phase` is the broad phase of :meth:`CollisionPairs.compute
<sotpy.tasks.collision.CollisionPairs.compute>` in one loop: the bounding spheres'
centres in the world, each pair's sphere bound ``|c_A - c_B| - r_A - r_B``, its lower
bound from the last tick (minus how far either shape can have moved since: ``|c' - c| +
r_g |R' - R|_F``), the larger of the two, and the selection ``bound < d_i``.
:func:`jacobian_rows` writes ``J_d = n^T (J_pB - J_pA)`` with ``n^T J_p = n^T J_lin +
(p x n)^T J_ang`` (``J``: ``data.J``, the joints' Jacobians in the world frame, restricted
to each joint's support). The NumPy twins are the passes written in ``collision.py``;
the tests compare both paths along a random walk.
"""

from __future__ import annotations

import math

import numpy as np

from .._jit import kernel


def _broad_phase(
    X,
    gj,
    gcenter,
    gradius,
    pa,
    pb,
    rsum,
    lower,
    prevX,
    prevC,
    c,
    coherent,
    di,
    sel,
    near,
    toggle,
):  # pragma: no cover - compiled (the NumPy twin is in collision.py)
    """``X``: the joint placements (njoints x 12, rotation column by column then the
    translation); ``c`` <- the sphere centres; ``lower`` <- the pairs' lower bounds;
    ``prevX``, ``prevC`` <- ``X``, ``c`` (with ``coherent``, the last tick's values are
    used first). ``sel`` holds the last selection: ``sel[k]`` <- ``lower[k] < di``, the
    pairs selected into ``near[:count]``, those whose selection changed into
    ``toggle[:changed]``. Returns ``(count, changed, lowest)``, ``lowest`` the smallest
    bound of the pairs not selected (inf when none)."""
    nj = X.shape[0]
    ng = gj.shape[0]
    rot = np.zeros(nj)
    if coherent:
        for j in range(nj):
            s = 0.0
            for a in range(9):
                d = X[j, a] - prevX[j, a]
                s += d * d
            rot[j] = math.sqrt(s)
    move = np.zeros(ng)
    for g in range(ng):
        j = gj[g]
        x, y, z = gcenter[g, 0], gcenter[g, 1], gcenter[g, 2]
        for i in range(3):
            c[g, i] = X[j, i] * x + X[j, 3 + i] * y + X[j, 6 + i] * z + X[j, 9 + i]
        if coherent:
            d0 = c[g, 0] - prevC[g, 0]
            d1 = c[g, 1] - prevC[g, 1]
            d2 = c[g, 2] - prevC[g, 2]
            move[g] = math.sqrt(d0 * d0 + d1 * d1 + d2 * d2) + gradius[g] * rot[j]
    count = 0
    changed = 0
    lowest = np.inf
    for k in range(pa.shape[0]):
        a, b = pa[k], pb[k]
        d0 = c[a, 0] - c[b, 0]
        d1 = c[a, 1] - c[b, 1]
        d2 = c[a, 2] - c[b, 2]
        bound = math.sqrt(d0 * d0 + d1 * d1 + d2 * d2) - rsum[k]
        lb = lower[k]
        if coherent:
            lb -= move[a] + move[b]
        if bound > lb or bound != bound:
            lb = bound
        lower[k] = lb
        s = lb < di
        if s != sel[k]:
            toggle[changed] = k
            changed += 1
        sel[k] = s
        if s:
            near[count] = k
            count += 1
        elif lb < lowest:
            lowest = lb
    prevX[:, :] = X
    prevC[:, :] = c
    return count, changed, lowest


def _jacobian_rows(n, pA, pB, jA, jB, J, support, out):  # pragma: no cover - compiled
    """``out[r] <- J_d`` of row ``r`` (see the module doc)."""
    nv = J.shape[1]
    coef = np.empty(6)
    for r in range(n.shape[0]):
        for v in range(nv):
            out[r, v] = 0.0
        for side in range(2):
            p = pA[r] if side == 0 else pB[r]
            j = jA[r] if side == 0 else jB[r]
            sign = -1.0 if side == 0 else 1.0
            coef[0], coef[1], coef[2] = n[r, 0], n[r, 1], n[r, 2]
            coef[3] = p[1] * n[r, 2] - p[2] * n[r, 1]
            coef[4] = p[2] * n[r, 0] - p[0] * n[r, 2]
            coef[5] = p[0] * n[r, 1] - p[1] * n[r, 0]
            for v in range(nv):
                if support[j, v]:
                    s = 0.0
                    for i in range(6):
                        s += coef[i] * J[i, v]
                    out[r, v] += sign * s


broad_phase = kernel(_broad_phase)
jacobian_rows = kernel(_jacobian_rows)
_warm: list[bool] = []


def warm_up() -> None:
    """Compile (or load from the cache) the kernels for the types a tick passes (the
    read-only view on ``data.oMi``, ``data.J``, int64 indices), then forbid further
    compilation (an unforeseen type raises ``TypeError`` and the caller falls back to
    NumPy). The arrays a kernel only reads are given read-only: numba then accepts a
    writable array there as well."""
    if broad_phase is None or _warm:
        return

    def ro(a: np.ndarray) -> np.ndarray:
        v = a.view()
        v.setflags(write=False)
        return v

    nj, ng, npairs, nv = 2, 2, 1, 3
    ints = ro(np.zeros(ng, dtype=np.int64))
    X = ro(np.zeros((nj, 12)))
    g3 = ro(np.zeros((ng, 3)))
    r1 = ro(np.zeros(ng))
    pairs = ro(np.array([0], dtype=np.int64))
    rsum = ro(np.zeros(npairs))
    idx = np.zeros(npairs, dtype=np.int64)
    for coherent in (False, True):
        broad_phase(
            X, ints, g3, r1, pairs, pairs, rsum, np.zeros(npairs), np.zeros((nj, 12)),
            np.zeros((ng, 3)), np.zeros((ng, 3)), coherent, 0.05, np.zeros(npairs, dtype=np.bool_),
            idx, idx,
        )  # fmt: skip
    jac = np.zeros((6, nv), order="F")  # data.J: column-major
    support = ro(np.zeros((nj, nv), dtype=np.bool_))
    # the witness data: columns of the results' rows (strided), or C-order arrays
    w = np.zeros((2, 10))[:, 1:4]  # two rows: a strided (not contiguous) view
    two = ro(np.zeros(2, dtype=np.int64))
    for m in (ro(w), w, ro(np.zeros((2, 3)))):
        for J in (ro(jac), jac, ro(np.zeros((6, nv)))):
            jacobian_rows(m, m, m, two, two, J, support, np.zeros((2, nv)))
    for k in (broad_phase, jacobian_rows):
        k.disable_compile()
    _warm.append(True)
