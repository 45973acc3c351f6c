"""One-sided spatial PSD (Parseval) and spectral peak finding."""

from __future__ import annotations

import numpy as np
import pytest

from servosurf.errors import ConfigError
from servosurf.metrology import find_peaks_spectrum, psd_1d

#: Relative tolerance on a peak frequency (brief: 1 %).
PEAK_FREQ_RTOL = 1e-2
#: Relative tolerance of Parseval: integral of the PSD against the variance.
PARSEVAL_RTOL = 2e-2
#: Relative tolerance on a peak's sinusoid amplitude.
PEAK_AMPLITUDE_RTOL = 0.02

F1, F2 = 1.7e5, 2.55e5  # 170 and 255 mm^-1, in 1/m
A1, A2 = 3e-9, 1.5e-9  # m
DX = 0.4e-6  # m


def _lenslet_error_map(rng: np.random.Generator, ny: int = 48, nx: int = 1200):
    x = np.arange(nx) * DX
    phase = rng.uniform(0, 2 * np.pi, (ny, 2))
    z = (
        A1 * np.sin(2 * np.pi * F1 * x[None, :] + phase[:, :1])
        + A2 * np.sin(2 * np.pi * F2 * x[None, :] + phase[:, 1:])
        + rng.normal(0.0, 0.5e-9, (ny, nx))
    )
    return z


def test_synthetic_peaks_and_parseval():
    rng = np.random.default_rng(1234)
    z = _lenslet_error_map(rng)
    freq, psd = psd_1d(z, DX)
    assert freq.shape == psd.shape == (z.shape[1] // 2 + 1,)
    df = freq[1] - freq[0]
    np.testing.assert_allclose(df, 1 / (z.shape[1] * DX), rtol=1e-12)
    variance = np.mean(np.var(z, axis=1))
    np.testing.assert_allclose(psd.sum() * df, variance, rtol=PARSEVAL_RTOL)
    peaks = find_peaks_spectrum(freq, psd, n=2, speed=42.3e-3)
    assert len(peaks) == 2
    np.testing.assert_allclose(peaks[0]["freq_per_m"], F1, rtol=PEAK_FREQ_RTOL)
    np.testing.assert_allclose(peaks[1]["freq_per_m"], F2, rtol=PEAK_FREQ_RTOL)
    np.testing.assert_allclose(peaks[0]["amplitude_m"], A1, rtol=PEAK_AMPLITUDE_RTOL)
    np.testing.assert_allclose(peaks[1]["amplitude_m"], A2, rtol=PEAK_AMPLITUDE_RTOL)
    # 170 mm^-1 at 42.3 mm/s is the paper's 7.2 kHz vibration
    np.testing.assert_allclose(peaks[0]["temporal_freq_hz"], 7.2e3, rtol=PEAK_FREQ_RTOL)
    assert peaks[0]["wavelength_m"] == pytest.approx(1 / peaks[0]["freq_per_m"])


def test_sub_bin_interpolation_beats_bin_spacing():
    # a single sine between two bins: the interpolated peak is within 0.15 bin
    n, dx = 1000, 0.5e-6
    df = 1 / (n * dx)
    f0 = 80.37 * df
    x = np.arange(n) * dx
    freq, psd = psd_1d(np.sin(2 * np.pi * f0 * x) * 1e-9, dx, detrend="constant")
    (pk,) = find_peaks_spectrum(freq, psd, n=1)
    assert abs(pk["freq_per_m"] - f0) < 0.15 * df


def test_parseval_single_profile_no_window():
    rng = np.random.default_rng(1234)
    z = rng.normal(0.0, 2e-9, 4096)
    freq, psd = psd_1d(z, 1e-6, window=None, detrend="constant")
    df = freq[1] - freq[0]
    np.testing.assert_allclose(psd.sum() * df, np.var(z), rtol=1e-10)


def test_nan_rows_skipped_and_samples_interpolated():
    rng = np.random.default_rng(1234)
    z = _lenslet_error_map(rng)
    z[3, :] = np.nan  # skipped (100 % invalid)
    z[5, 100:400] = np.nan  # skipped (25 % > 10 %)
    z[7, 10:20] = np.nan  # interpolated
    freq, psd = psd_1d(z, DX)
    assert np.all(np.isfinite(psd))
    peaks = find_peaks_spectrum(freq, psd, n=2)
    np.testing.assert_allclose(
        sorted(p["freq_per_m"] for p in peaks), [F1, F2], rtol=PEAK_FREQ_RTOL
    )


def test_axis_selects_the_cutting_direction():
    rng = np.random.default_rng(1234)
    z = _lenslet_error_map(rng)
    f0, p0 = psd_1d(z, DX)
    f1, p1 = psd_1d(z.T, DX, axis=0)
    np.testing.assert_allclose(p1, p0, rtol=1e-12, atol=0)


def test_fmin_and_prominence_filter_peaks():
    rng = np.random.default_rng(1234)
    z = _lenslet_error_map(rng)
    freq, psd = psd_1d(z, DX)
    peaks = find_peaks_spectrum(freq, psd, fmin=2e5)
    assert all(p["freq_per_m"] >= 2e5 for p in peaks)
    np.testing.assert_allclose(peaks[0]["freq_per_m"], F2, rtol=PEAK_FREQ_RTOL)
    assert find_peaks_spectrum(freq, psd, min_prominence=20.0) == []


@pytest.mark.parametrize(
    "kwargs",
    [dict(detrend="quadratic"), dict(window="no-such-window"), dict(axis=3)],
)
def test_psd_bad_arguments(kwargs):
    with pytest.raises(ConfigError):
        psd_1d(np.zeros((4, 64)), 1e-6, **kwargs)


def test_psd_all_nan_raises():
    with pytest.raises(ConfigError, match="invalid samples"):
        psd_1d(np.full((3, 32), np.nan), 1e-6)


def test_find_peaks_bad_arguments():
    f = np.arange(10.0)
    with pytest.raises(ConfigError, match="same shape"):
        find_peaks_spectrum(f, np.ones(9))
    with pytest.raises(ConfigError, match="equally spaced"):
        find_peaks_spectrum(f**2, np.ones(10))
