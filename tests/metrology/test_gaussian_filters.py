"""ISO 16610-21 / -61 Gaussian filters: transmission, NaN and end handling."""

from __future__ import annotations

import math

import numpy as np
import pytest

from servosurf.errors import ConfigError
from servosurf.metrology import (
    Profile,
    Surface,
    gaussian_filter_1d,
    gaussian_filter_2d,
    high_pass,
)
from servosurf.metrology._filters import GAUSSIAN_ALPHA, MIN_WEIGHT, gaussian_weights

#: Relative tolerance on a filter transmission (discrete kernel, finite profile).
TRANSMISSION_RTOL = 1e-4
#: Absolute tolerance on a transmission (dimensionless): the renormalised kernel
#: leaves an end effect of a few 1e-6 between lambda_c / 2 and lambda_c from the ends.
TRANSMISSION_ATOL = 2e-5
#: Relative tolerance between the NaN-aware filter and the naive reference.
NAIVE_RTOL = 1e-9


def naive_gaussian_mean(z: np.ndarray, dx: float, cutoff: float) -> np.ndarray:
    """Loop reference: weighted mean of the valid samples within +-cutoff."""
    n = z.size
    x = np.arange(n) * dx
    out = np.full(n, np.nan)
    h = math.ceil(cutoff / dx)
    full = np.exp(-np.pi * (np.arange(-h, h + 1) * dx / (GAUSSIAN_ALPHA * cutoff)) ** 2)
    for i in range(n):
        d = x - x[i]
        m = np.isfinite(z) & (np.abs(d) <= cutoff + 1e-9 * dx)
        s = np.exp(-np.pi * (d[m] / (GAUSSIAN_ALPHA * cutoff)) ** 2)
        if s.sum() >= MIN_WEIGHT * full.sum():
            out[i] = np.sum(s * z[m]) / s.sum()
    return out


def _sine_amplitude(x: np.ndarray, y: np.ndarray, wavelength: float) -> float:
    """Least-squares amplitude of the sinusoid of ``wavelength`` in ``y``."""
    m = np.isfinite(y)
    k = 2 * np.pi / wavelength
    a = np.column_stack([np.sin(k * x[m]), np.cos(k * x[m]), np.ones(m.sum())])
    c, *_ = np.linalg.lstsq(a, y[m], rcond=None)
    return float(np.hypot(c[0], c[1]))


def test_weights_are_normalised_and_symmetric():
    w = gaussian_weights(0.5e-6, 80e-6)
    np.testing.assert_allclose(w.sum(), 1.0, rtol=1e-12)
    np.testing.assert_allclose(w, w[::-1], rtol=0, atol=1e-18)


def test_alpha_value():
    np.testing.assert_allclose(GAUSSIAN_ALPHA, 0.4697, rtol=1e-4)


@pytest.mark.parametrize("ratio", [1 / 3, 0.5, 1.0, 2.0, 3.0])
def test_mean_line_transmission_matches_iso_formula(ratio):
    dx, lc = 0.5e-6, 80e-6
    wavelength = ratio * lc
    x = np.arange(8000) * dx
    z = 1e-6 * np.sin(2 * np.pi * x / wavelength + 0.3)
    w = gaussian_filter_1d(z, dx, lc)
    expected = math.exp(-math.pi * (GAUSSIAN_ALPHA * lc / wavelength) ** 2)
    amp = _sine_amplitude(x, w, wavelength) / 1e-6
    np.testing.assert_allclose(
        amp, expected, rtol=TRANSMISSION_RTOL, atol=TRANSMISSION_ATOL
    )


def test_transmission_is_50_percent_at_the_cutoff():
    dx, lc = 0.25e-6, 80e-6
    x = np.arange(16000) * dx
    z = 2e-6 * np.sin(2 * np.pi * x / lc)
    w = gaussian_filter_1d(z, dx, lc)
    r = z - w
    np.testing.assert_allclose(
        _sine_amplitude(x, w, lc), 1e-6, rtol=TRANSMISSION_RTOL
    )  # mean line: 50 %
    np.testing.assert_allclose(
        _sine_amplitude(x, r, lc), 1e-6, rtol=TRANSMISSION_RTOL
    )  # roughness: 50 %


def _roughness_transmission(wavelength: float, cutoff: float) -> float:
    return 1.0 - math.exp(-math.pi * (GAUSSIAN_ALPHA * cutoff / wavelength) ** 2)


def test_short_wavelength_passes_and_long_is_removed_zero_phase():
    dx, lc = 0.5e-6, 80e-6
    x = np.arange(8000) * dx
    short = 10e-9 * np.sin(2 * np.pi * x / 8e-6)
    long = 1e-6 * np.sin(2 * np.pi * x / 2e-3)
    r = (short + long) - gaussian_filter_1d(short + long, dx, lc)
    # zero-phase filter: each sine comes out scaled, not shifted
    expected = (
        _roughness_transmission(8e-6, lc) * short
        + _roughness_transmission(2e-3, lc) * long
    )
    interior = slice(160, -160)  # beyond lambda_c from the ends
    np.testing.assert_allclose(r[interior], expected[interior], rtol=0, atol=1e-13)
    assert _roughness_transmission(8e-6, lc) > 0.9999  # short: passes
    assert _roughness_transmission(2e-3, lc) < 2e-3  # long: removed


def test_matches_naive_reference_with_nan_everywhere():
    rng = np.random.default_rng(1234)
    dx, lc = 1e-6, 20e-6
    z = rng.normal(0, 1e-8, 300)
    z[[0, 1, 150, 151, 152, 299]] = np.nan
    z[200:230] = np.nan
    w = gaussian_filter_1d(z, dx, lc, trim_ends=False)
    ref = naive_gaussian_mean(z, dx, lc)
    np.testing.assert_allclose(w, ref, rtol=NAIVE_RTOL, atol=1e-18)  # 1e-18 m


def test_constant_is_preserved_at_ends_and_gaps():
    z = np.full(500, 3e-7)
    z[100:140] = np.nan
    w = gaussian_filter_1d(z, 1e-6, 50e-6, trim_ends=False)
    np.testing.assert_allclose(w, 3e-7, rtol=1e-12)


def test_linear_trend_is_reproduced_away_from_ends():
    dx, lc = 1e-6, 40e-6
    x = np.arange(400) * dx
    z = 1e-3 * x
    w = gaussian_filter_1d(z, dx, lc, trim_ends=False)
    interior = slice(41, -41)  # beyond lambda_c from the ends: exact
    np.testing.assert_allclose(w[interior], z[interior], rtol=0, atol=1e-18)
    # the renormalised kernel biases a slope near the ends (documented)
    assert abs(w[0] - z[0]) > 1e-9


def test_trim_removes_half_a_cutoff_from_the_valid_ends():
    dx, lc = 0.871e-6, 80e-6
    z = np.zeros(500)
    z[:3] = np.nan
    w = gaussian_filter_1d(z, dx, lc)
    k = math.ceil(lc / 2 / dx)
    assert np.isnan(w[: 3 + k]).all()
    assert np.isfinite(w[3 + k])
    assert np.isnan(w[-k:]).all() and np.isfinite(w[-k - 1])
    w2 = gaussian_filter_1d(z, dx, lc, trim_length=lc)
    k2 = math.ceil(lc / dx)
    assert np.isnan(w2[: 3 + k2]).all() and np.isfinite(w2[3 + k2])


def test_filters_rows_of_a_2d_array_along_axis():
    rng = np.random.default_rng(1234)
    z = rng.normal(0, 1e-8, (3, 200))
    w = gaussian_filter_1d(z, 1e-6, 30e-6, axis=1)
    w_t = gaussian_filter_1d(z.T, 1e-6, 30e-6, axis=0)
    np.testing.assert_allclose(w, w_t.T, rtol=1e-12, atol=1e-22)
    np.testing.assert_allclose(
        w[1], gaussian_filter_1d(z[1], 1e-6, 30e-6), rtol=1e-12, atol=1e-22
    )


@pytest.mark.parametrize(
    "kwargs",
    [
        dict(dx=0.0, cutoff=1e-5),
        dict(dx=1e-6, cutoff=-1.0),
        dict(dx=1e-6, cutoff=1e-5, trim_length=-1.0),
    ],
)
def test_bad_arguments_raise(kwargs):
    with pytest.raises(ConfigError):
        gaussian_filter_1d(np.zeros(10), **kwargs)


def test_areal_transmission_is_isotropic_50_percent_at_cutoff():
    d, lc = 1e-6, 40e-6
    n = 256
    yy, xx = np.mgrid[0:n, 0:n] * d
    # wave vector at 45 degrees with |k| = 2 pi / lc
    k = 2 * np.pi / lc / math.sqrt(2)
    z = 1e-6 * np.sin(k * (xx + yy))
    mean = gaussian_filter_2d(Surface(z, d, d), lc)
    m = np.zeros(z.shape, dtype=bool)
    m[40:-40, 40:-40] = True  # beyond lambda_c from the borders
    a = np.column_stack([np.sin(k * (xx + yy))[m], np.cos(k * (xx + yy))[m]])
    c, *_ = np.linalg.lstsq(a, mean.z[m], rcond=None)
    np.testing.assert_allclose(np.hypot(*c), 0.5e-6, rtol=TRANSMISSION_RTOL)


def test_areal_filter_separable_equals_row_then_column_profile_filter():
    rng = np.random.default_rng(1234)
    z = rng.normal(0, 1e-8, (60, 80))
    s = Surface(z, 1e-6, 2e-6)
    mean = gaussian_filter_2d(s, 15e-6).z
    rows = gaussian_filter_1d(z, 1e-6, 15e-6, trim_ends=False, axis=1)
    both = gaussian_filter_1d(rows, 2e-6, 15e-6, trim_ends=False, axis=0)
    # no NaN: the normalised 2-D filter equals two 1-D normalised passes only
    # away from the corners' mixed renormalisation; compare in the interior
    np.testing.assert_allclose(
        mean[10:-10, 10:-10], both[10:-10, 10:-10], rtol=0, atol=1e-21
    )  # 1e-21 m


def test_areal_constant_with_holes_is_preserved():
    z = np.full((40, 50), -2e-7)
    z[10:15, 20:30] = np.nan
    z[0, :] = np.nan
    mean = gaussian_filter_2d(Surface(z, 1e-6, 1e-6), 10e-6)
    np.testing.assert_allclose(mean.z, -2e-7, rtol=1e-12)


def test_areal_filter_needs_calibration():
    with pytest.raises(ConfigError, match="calibrated"):
        gaussian_filter_2d(Surface(np.zeros((4, 4)), None, None), 1e-5)


def test_high_pass_80_per_mm_halves_a_12_5_um_wave():
    d = 0.5e-6
    cutoff = 1 / 80e3  # 80 mm^-1 -> 12.5 um
    x = np.arange(2000) * d
    z = np.tile(1e-8 * np.sin(2 * np.pi * x / 12.5e-6), (4, 1))
    hp = high_pass(Surface(z, d, d), cutoff)
    assert isinstance(hp, Surface)
    amp = _sine_amplitude(x[100:-100], hp.z[2, 100:-100], 12.5e-6)
    np.testing.assert_allclose(amp, 0.5e-8, rtol=1e-3)
    hp1 = high_pass(Profile(z[0], d), cutoff, trim_ends=True)
    assert isinstance(hp1, Profile)
    amp1 = _sine_amplitude(x, hp1.z, 12.5e-6)
    np.testing.assert_allclose(amp1, 0.5e-8, rtol=TRANSMISSION_RTOL)
    assert hp1.metadata["filter"]["cutoff_m"] == cutoff


def test_high_pass_rejects_other_types():
    with pytest.raises(ConfigError):
        high_pass(np.zeros(5), 1e-5)
