"""The discovery benchmark's information bound (``benchmarks/discovery/bound.py``).

Closed forms: the Neyman-Pearson detection probability of a known signal and the
non-central chi2 power of a q-parameter likelihood-ratio test, against the normal
distribution and a seeded Monte-Carlo.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.stats import chi2, norm


@pytest.fixture(scope="module")
def B(discovery):
    return discovery("bound")


def test_np_bound_is_the_shifted_normal(B):
    alpha = 0.02
    z = norm.isf(alpha)
    assert B.np_bound(0.0, alpha) == pytest.approx(alpha, rel=1e-12)
    assert B.np_bound(z, alpha) == pytest.approx(0.5, rel=1e-12)
    assert B.np_bound(z + 1.0, alpha) == pytest.approx(norm.cdf(1.0), rel=1e-12)
    # k times the data: SNR x sqrt(k)
    assert B.np_bound(1.3, alpha, 4.0) == pytest.approx(B.np_bound(2.6, alpha))


def test_composite_one_parameter_is_a_two_sided_normal_test(B):
    alpha, m = 0.02, 180
    c = math.sqrt(chi2.isf(alpha / m, 1))
    assert B.composite(0.0, 1, alpha, m) == pytest.approx(alpha / m, rel=1e-9)
    for s in (1.0, 2.5, 4.0, 6.0):
        want = norm.cdf(-c - s) + norm.sf(c - s)
        assert B.composite(s, 1, alpha, m) == pytest.approx(want, rel=1e-9)


def test_composite_matches_a_seeded_simulation(B):
    rng = np.random.default_rng(11)
    q, s, alpha, m = 3, 4.5, 0.02, 180
    x = rng.standard_normal((200_000, q))
    x[:, 0] += s
    p_mc = float(np.mean(np.sum(x * x, axis=1) > chi2.isf(alpha / m, q)))
    p = B.composite(s, q, alpha, m)
    assert abs(p_mc - p) < 4.0 * math.sqrt(p * (1.0 - p) / x.shape[0])


def test_more_data_needed_solves_for_the_target(B):
    rows = [{"snr": 2.0, "q": 1}, {"snr": 2.5, "q": 2}, {"snr": 12.0, "q": 1}]
    alpha, m, target = 0.02, 180, 0.6
    k = B.more_data_needed(rows, alpha, m, target)
    mean = sum(B.composite(r["snr"], r["q"], alpha, m, k) for r in rows) / len(rows)
    assert k > 1.0
    assert mean == pytest.approx(target, abs=2e-3)
    assert B.more_data_needed([{"snr": 20.0, "q": 1}], alpha, m, target) == 1.0
    assert B.more_data_needed([{"snr": 0.0, "q": 1}], alpha, m, target) == math.inf
