"""The compiled small Householder QR (``sotpy.solvers._smallqr``) against LAPACK and
NumPy: the same factorisation in LAPACK's storage, products with ``Q`` and ``Q^T``,
triangular solves and the exact condition number."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.linalg import lapack, solve_triangular

from sotpy.solvers import _smallqr

pytestmark = pytest.mark.skipif(
    not hasattr(_smallqr, "householder_qr"), reason="compiled kernels disabled"
)

SHAPES = [(1, 1), (5, 5), (17, 6), (32, 11), (40, 15), (9, 1)]


def factor(a: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``a`` factorised by the kernel: (Fortran storage, tau)."""
    qr = np.asfortranarray(a, dtype=float).copy(order="F")
    tau = np.empty(a.shape[1])
    _smallqr.householder_qr(qr, tau)
    return qr, tau


def q_of(qr: np.ndarray, tau: np.ndarray) -> np.ndarray:
    """The full ``Q`` of a factorisation in LAPACK's storage, by LAPACK (``dorgqr``)."""
    m, k = qr.shape
    wide = np.zeros((m, m), order="F")
    wide[:, :k] = qr
    q, _, info = lapack.dorgqr(wide, tau)
    assert info == 0
    return q


@pytest.mark.parametrize("shape", SHAPES)
@pytest.mark.parametrize("scale", [1.0, 1e-150, 1e150])
def test_qr_is_lapack_dgeqrf(shape, scale):
    """Same reflectors, ``tau`` and ``R`` as ``dgeqrf`` (the same algorithm, so to
    rounding), at any scale; ``Q`` orthogonal and ``Q R = A``."""
    rng = np.random.default_rng(sum(shape))
    a = rng.standard_normal(shape) * scale
    qr, tau = factor(a)
    ref, ref_tau, _, info = lapack.dgeqrf(a)
    assert info == 0
    np.testing.assert_allclose(tau, ref_tau, rtol=1e-12, atol=1e-14)
    np.testing.assert_allclose(qr, ref, rtol=1e-11, atol=1e-13 * scale)
    q = q_of(qr, tau)
    np.testing.assert_allclose(q.T @ q, np.eye(shape[0]), atol=1e-14)
    r = np.triu(qr[: shape[1]])
    np.testing.assert_allclose(q[:, : shape[1]] @ r, a, atol=1e-14 * scale * shape[0])


def test_qr_of_columns_already_reduced():
    """A column with zeros below the diagonal gets no reflector (``tau = 0``), as in
    LAPACK; a zero matrix stays zero."""
    a = np.triu(np.arange(1.0, 13.0).reshape(4, 3))
    qr, tau = factor(a)
    np.testing.assert_array_equal(tau, 0.0)
    np.testing.assert_array_equal(qr, a)
    qr, tau = factor(np.zeros((3, 2)))
    np.testing.assert_array_equal(qr, 0.0)
    np.testing.assert_array_equal(tau, 0.0)


@pytest.mark.parametrize("trans", [True, False])
@pytest.mark.parametrize("shape", [(17, 6), (40, 15), (5, 5)])
def test_reflections_are_lapack_dormqr(shape, trans):
    """``Q^T C``, ``Q C`` on a C-order matrix and on a vector against ``dormqr`` on the
    same factorisation, and back to ``C``."""
    rng = np.random.default_rng(7 + shape[0])
    qr, tau = factor(rng.standard_normal(shape))
    m, k = shape
    c = rng.standard_normal((m, 33))
    ref, _, info = lapack.dormqr("L", "T" if trans else "N", qr, tau, c, lwork=64 * 33)
    assert info == 0
    out = np.ascontiguousarray(c)
    _smallqr.reflect_rows(qr, tau, k, out, np.empty(33), trans)
    np.testing.assert_allclose(out, ref, atol=1e-13)
    _smallqr.reflect_rows(qr, tau, k, out, np.empty(33), not trans)
    np.testing.assert_allclose(out, c, atol=1e-13)
    y = c[:, 0].copy()
    _smallqr.reflect_vector(qr, tau, k, y, trans)
    np.testing.assert_allclose(y, ref[:, 0], atol=1e-13)


def test_reflections_with_fewer_reflectors():
    """Only the first ``k`` reflectors are applied: ``Q_k = H_0 ... H_{k-1}``."""
    rng = np.random.default_rng(3)
    qr, tau = factor(rng.standard_normal((12, 5)))
    c = rng.standard_normal((12, 4))
    ref, _, info = lapack.dormqr("L", "T", qr[:, :3], tau[:3], c, lwork=256)
    assert info == 0
    out = c.copy()
    _smallqr.reflect_rows(qr, tau, 3, out, np.empty(4), True)
    np.testing.assert_allclose(out, ref, atol=1e-13)


@pytest.mark.parametrize("trans", [True, False])
def test_triangular_solves(trans):
    """``R z = y`` and ``R^T z = y`` on the leading block, against SciPy."""
    rng = np.random.default_rng(11)
    a = np.asfortranarray(rng.standard_normal((9, 9)) + 4 * np.eye(9))
    y = rng.standard_normal(6)
    z = y.copy()
    _smallqr.solve_upper(a, 6, z, trans)
    ref = solve_triangular(np.triu(a[:6, :6]), y, trans="T" if trans else "N")
    np.testing.assert_allclose(z, ref, rtol=1e-12)
    a[3, 3] = 0.0  # singular: inf or NaN as NumPy divides, not an exception
    z = y.copy()
    _smallqr.solve_upper(a, 6, z, trans)
    assert not np.isfinite(z).all()


@pytest.mark.parametrize("k", [1, 6, 11])
def test_rcond_is_the_exact_one_norm_condition(k):
    """``1 / (||R||_1 ||R^-1||_1)`` to rounding, never above LAPACK's estimate, on well
    and badly conditioned triangles; 0 when singular, 1 when empty."""
    rng = np.random.default_rng(k)
    for spread in (1.0, 1e-6, 1e-12):
        r = np.triu(rng.standard_normal((k, k)))
        r[np.diag_indices(k)] = np.geomspace(1.0, spread, k) * rng.choice([-1, 1], k)
        a = np.asfortranarray(np.vstack([r, rng.standard_normal((2, k))]))
        rc = _smallqr.rcond_upper(a, k)
        exact = 1.0 / np.linalg.cond(r, 1)
        assert rc == pytest.approx(exact, rel=1e-8)
        estimate, info = lapack.dtrcon(r, norm="1", uplo="U")
        assert info == 0
        assert rc <= estimate * (1 + 1e-12)
    singular = np.asfortranarray(np.triu(np.ones((4, 4))))
    singular[2, 2] = 0.0
    assert _smallqr.rcond_upper(singular, 4) == 0.0
    assert _smallqr.rcond_upper(np.asfortranarray(np.full((3, 3), np.nan)), 3) == 0.0
    assert _smallqr.rcond_upper(singular, 0) == 1.0
