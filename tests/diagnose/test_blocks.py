"""The map blocks' noise linear algebra against plain numpy (servosurf.diagnose._blocks).

The interval-statistics covariance, its tridiagonal reduction (the tool-noise
maximum likelihood) and the sparse whitening operator are checked against the
dense formulas they replace: an explicit four-term covariance with a lag lookup,
``numpy.linalg.eigh`` and ``numpy.linalg.solve`` for the likelihood terms, and a
dense block-diagonal assembly for the whitening.
"""

from __future__ import annotations

import numpy as np
import pytest

from servosurf.diagnose._blocks import (
    _interval_cov,
    _lower_block_diag,
    _lower_inverse,
    _tridiagonal,
    _tridiagonal_quad,
)


def _autocov(n: int) -> np.ndarray:
    """A positive-definite autocovariance table (damped cosine, m^2)."""
    k = np.arange(n)
    return 1e-18 * np.exp(-k / 40.0) * np.cos(k / 7.0)


def test_interval_cov_is_the_four_term_formula():
    rng = np.random.default_rng(3)
    rt = _autocov(300)
    k = np.sort(rng.choice(400, size=90, replace=False))  # lags beyond the table too
    g0, g1 = rng.uniform(0.2, 1.0, k.size), rng.uniform(-0.5, 0.5, k.size)

    def r(lag):
        lag = np.abs(lag)
        return np.array([rt[j] if j < rt.size else 0.0 for j in lag.ravel()]).reshape(
            lag.shape)

    d = k[:, None] - k[None, :]
    ref = (np.outer(g0, g0) * r(d) + np.outer(g0, g1) * r(d - 1)
           + np.outer(g1, g0) * r(d + 1) + np.outer(g1, g1) * r(d))
    c = _interval_cov(k, g0, g1, rt)
    assert np.max(np.abs(c - ref)) <= 1e-14 * np.max(np.abs(ref))
    assert np.max(np.abs(c - c.T)) <= 1e-15 * np.max(np.abs(c))


@pytest.mark.parametrize("n", [1, 2, 7, 150])
def test_tridiagonal_likelihood_terms_equal_the_eigendecomposition(n):
    rng = np.random.default_rng(n)
    a = rng.standard_normal((n, n))
    c = a @ a.T / n + 1e-3 * np.eye(n)
    b = rng.standard_normal(n)
    d, e, z = _tridiagonal(c, b)
    lam, v = np.linalg.eigh(c)
    from scipy.linalg import eigh_tridiagonal

    lt = eigh_tridiagonal(d, e, eigvals_only=True) if n > 1 else d
    np.testing.assert_allclose(np.sort(lt), lam, rtol=1e-10, atol=1e-12)
    assert abs(z @ z - b @ b) <= 1e-12 * (b @ b)  # Q is orthogonal
    for k, s2 in [(1.0, 1e-2), (0.5, 3.0), (2.0, 1e-6)]:
        ref = float(b @ np.linalg.solve(k * c + s2 * np.eye(n), b))
        assert _tridiagonal_quad(d, e, z, k, s2) == pytest.approx(ref, rel=1e-9)
        # the same quantity from the eigendecomposition (the former code path)
        proj = (v.T @ b) ** 2
        assert _tridiagonal_quad(d, e, z, k, s2) == pytest.approx(
            float(np.sum(proj / (k * lam + s2))), rel=1e-9)


def test_whitening_operator_is_the_dense_block_diagonal_inverse():
    rng = np.random.default_rng(7)
    blocks, chols = [], []
    for n in (1, 5, 40):
        a = rng.standard_normal((n, n))
        ch = np.linalg.cholesky(a @ a.T + n * np.eye(n))
        chols.append(ch)
        blocks.append(_lower_inverse(ch))
    for ch, inv in zip(chols, blocks, strict=True):
        np.testing.assert_allclose(inv @ ch, np.eye(ch.shape[0]), atol=1e-12)
        assert np.all(np.triu(inv, 1) == 0.0)
    w = _lower_block_diag(blocks).toarray()
    ref = np.zeros_like(w)
    o = 0
    for b in blocks:
        ref[o:o + b.shape[0], o:o + b.shape[0]] = b
        o += b.shape[0]
    assert np.array_equal(w, ref)
    assert _lower_block_diag([]).shape == (0, 0)
