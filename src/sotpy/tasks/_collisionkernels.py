r"""Compiled kernels of the collision pass (internal to :mod:`sotpy.tasks.collision`).

:func:`broad_phase` is the broad phase of :meth:`CollisionPairs.compute
<sotpy.tasks.collision.CollisionPairs.compute>` in one loop: the bounding spheres'
centres in the world, each pair's sphere bound ``|c_A - c_B| - r_A - r_B``, its lower
bound from the last tick (minus how far either shape can have moved since: ``|c' - c| +
r_g |R' - R|_F``), the larger of the two, and the selection ``bound < d_i``.
:func:`narrow_rows`, after coal, keeps the pairs under ``d_i`` (their distances, normals
and witness points, read from coal's results) and writes their ``J_d = n^T (J_pB -
J_pA)`` with ``n^T J_p = n^T J_lin + (p x n)^T J_ang`` (``J``: ``data.J``, the joints'
Jacobians in the world frame, restricted to each joint's support). The NumPy twins are
the passes written in ``collision.py``; the tests compare both paths along a random
walk.
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


def _narrow_rows(
    res, near, di, lower, gj, pa, pb, J, support, rows, out, joints, Jd
):  # pragma: no cover - compiled (the NumPy twin is in collision.py)
    """After coal: ``res`` its results (pairs x 10: distance, normal, the nearest points
    on A and B), ``near`` the pairs it computed. ``lower[k]`` <- their distances; the
    pairs under ``di`` in order into ``rows[:m]``, their results into ``out[:m]``, their
    joints (A, B) into ``joints[:, :m]``, their ``J_d`` into ``Jd[:m]`` (see the module
    doc). Returns ``(m, lowest)``, ``lowest`` the smallest distance of ``near``."""
    m = 0
    lowest = np.inf
    for i in range(near.shape[0]):
        k = near[i]
        d = res[k, 0]
        lower[k] = d
        if d < lowest:
            lowest = d
        if d < di:
            rows[m] = k
            for c in range(10):
                out[m, c] = res[k, c]
            m += 1
    nv = J.shape[1]
    coef = np.empty(6)
    for r in range(m):
        k = rows[r]
        joints[0, r] = gj[pa[k]]
        joints[1, r] = gj[pb[k]]
        for v in range(nv):
            Jd[r, v] = 0.0
        n0, n1, n2 = out[r, 1], out[r, 2], out[r, 3]
        for side in range(2):
            o = 4 + 3 * side
            p0, p1, p2 = out[r, o], out[r, o + 1], out[r, o + 2]
            j = joints[side, r]
            sign = -1.0 if side == 0 else 1.0
            coef[0], coef[1], coef[2] = n0, n1, n2
            coef[3] = p1 * n2 - p2 * n1
            coef[4] = p2 * n0 - p0 * n2
            coef[5] = p0 * n1 - p1 * n0
            for v in range(nv):
                if support[j, v]:
                    s = 0.0
                    for i in range(6):
                        s += coef[i] * J[i, v]
                    Jd[r, v] += sign * s
    return m, lowest


broad_phase = kernel(_broad_phase)
narrow_rows = kernel(_narrow_rows)
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
    # coal's results: the strided view on their memory (two rows: not contiguous)
    res = np.lib.stride_tricks.as_strided(
        np.zeros(40), shape=(2, 10), strides=(160, 8), writeable=False
    )
    two = ro(np.zeros(2, dtype=np.int64))
    for J in (ro(jac), jac, ro(np.zeros((6, nv)))):
        narrow_rows(
            res, two, 0.05, np.zeros(2), ints, two, two, J, support,
            np.zeros(2, dtype=np.int64), np.zeros((2, 10)), np.zeros((2, 2), dtype=np.int64),
            np.zeros((2, nv)),
        )  # fmt: skip
    for k in (broad_phase, narrow_rows):
        k.disable_compile()
    _warm.append(True)
