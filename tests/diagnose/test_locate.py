"""Calibration of the map/profile omnibus tests with an estimated noise sigma."""

import math

import numpy as np

from servosurf.diagnose._blocks import _clipped_sd
from servosurf.diagnose._locate import _chi2_logsf, variance_excess_logsf


def _trial(rng, n_sig, n_test, share):
    """One null trial: sigma estimated from ``n_sig`` instrument samples; ``n_test``
    whitened values whose variance is ``share`` instrument and the rest known (tool
    vibration), divided by the model variance at the estimated sigma."""
    sigma = 0.1e-9  # m
    e = rng.standard_normal(n_sig) * sigma
    s_hat, kept = _clipped_sd(e)
    inst = rng.standard_normal(n_test) * sigma * math.sqrt(share)
    tool = rng.standard_normal(n_test) * sigma * math.sqrt(1.0 - share)
    model_var = share * s_hat**2 + (1.0 - share) * sigma**2
    v = (inst + tool) / math.sqrt(model_var)
    return float(v @ v), n_sig * kept


def test_clipped_sd_is_the_sd_of_gaussian_data_and_ignores_spikes():
    rng = np.random.default_rng(3)
    x = rng.standard_normal(200_000) * 2e-9
    s, kept = _clipped_sd(x)
    assert abs(s - np.sqrt(np.mean(x**2))) / s < 1e-4
    assert kept > 0.9999
    y = x.copy()
    y[:20] = 1e-6  # dust: 20 spikes 500 sigma high
    s2, kept2 = _clipped_sd(y)
    assert abs(s2 / 2e-9 - 1.0) < 0.01
    assert kept2 < 1.0
    assert np.sqrt(np.mean(y**2)) > 4 * s2  # a plain SD would be ruined


def test_variance_excess_is_calibrated_with_an_estimated_sigma():
    """Along-cut-like values (2/3 instrument noise, sigma estimated from another
    10,000 points): the test's false-alarm rate matches its nominal 1 %; the chi2
    test that treats sigma as known fires about 2x too often."""
    rng = np.random.default_rng(5)
    n_sig, n_test, share = 10_000, 10_000, 2.0 / 3.0
    lp_new, lp_naive = [], []
    for _ in range(3000):
        ss, dof_sig = _trial(rng, n_sig, n_test, share)
        lp_new.append(
            variance_excess_logsf(
                ss, n_test, share=share, sigma_dof=dof_sig, overlap=0
            )
        )
        lp_naive.append(_chi2_logsf(ss, n_test))
    fa_new = np.mean(np.array(lp_new) < -2)
    fa_naive = np.mean(np.array(lp_naive) < -2)
    assert 0.004 <= fa_new <= 0.018, fa_new
    assert fa_naive > 0.02, fa_naive
    # a real excess of 8 % of the variance (4.7 of its sd) is still found
    ss, dof_sig = _trial(rng, n_sig, n_test, share)
    lp = variance_excess_logsf(
        ss * 1.08, n_test, share=share, sigma_dof=dof_sig, overlap=0
    )
    assert lp < -4


def test_variance_excess_with_overlap_and_the_degenerate_case():
    """Values that were part of the sigma estimate: an uncut top pooled with
    another 50,000 within-bin values is calibrated; an uncut top that is the whole
    estimate carries no information and is not tested."""
    rng = np.random.default_rng(7)
    n_u, n_w = 20_000, 50_000
    lps = []
    for _ in range(2000):
        u = rng.standard_normal(n_u)
        w = rng.standard_normal(n_w)
        s_hat, kept = _clipped_sd(np.concatenate([u, w]))
        ss = float(u @ u) / s_hat**2
        lps.append(
            variance_excess_logsf(
                ss, n_u, share=1.0, sigma_dof=(n_u + n_w) * kept, overlap=n_u
            )
        )
    fa = np.mean(np.array(lps) < -2)
    assert 0.004 <= fa <= 0.02, fa
    assert (
        variance_excess_logsf(float(n_u), n_u, share=1.0, sigma_dof=n_u, overlap=n_u)
        is None
    )
    # a known sigma (the floor) is plain chi2
    assert variance_excess_logsf(
        1.1e4, 10_000, share=1.0, sigma_dof=math.inf, overlap=0
    ) == _chi2_logsf(1.1e4, 10_000)


def test_expected_periodogram_is_the_fejer_sum_of_the_autocovariance():
    """Closed form: an AR(1) series x_t = phi x_{t-1} + e_t has the PSD
    ``2 s2 / fs / |1 - phi e^{-i w}|^2`` (one-sided) and the autocovariance
    ``s2 phi^|tau| / (1 - phi^2)``; its expected rectangular-window periodogram
    is the direct Fejer sum of that autocovariance. At phi = 0.9 the PSD falls
    by 25 dB to the Nyquist frequency, where leakage lifts the bins by several
    per cent over the PSD itself."""
    from types import SimpleNamespace

    from servosurf.diagnose._blocks import expected_periodogram

    fs, n, phi, s2 = 1000.0, 256, 0.9, 1.0

    def psd(p, f, output="fe"):
        w = 2 * np.pi * np.asarray(f) / fs
        return 2 * s2 / fs / np.abs(1 - phi * np.exp(-1j * w)) ** 2

    case = SimpleNamespace(fs=fs, noise_psd=psd)
    k = np.arange(1, n // 2 + 1)
    freq = k * fs / n
    got = expected_periodogram(case, None, freq, n, fs)
    tau = np.arange(-(n - 1), n)
    r = s2 * phi ** np.abs(tau) / (1 - phi**2)
    ref = np.array([np.sum((n - np.abs(tau)) * r * np.cos(2 * np.pi * kk * tau / n))
                    for kk in k]) * 2 / (fs * n)
    np.testing.assert_allclose(got, ref, rtol=1e-6)
    assert got[-1] / psd(None, freq[-1]) > 1.03  # leakage near Nyquist is real
