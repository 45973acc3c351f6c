"""Profile tools: crop, the line through a map, resampling, 1-D registration.

Oracles: a continuous seeded random texture evaluated at exactly known shifted or
mirrored positions, ``np.interp`` for resampling, hand-picked rows of small maps.
"""

from __future__ import annotations

import numpy as np
import pytest

from servosurf.errors import ConfigError
from servosurf.metrology import (
    Profile,
    Surface,
    crop_profile,
    profile_through,
    register_profiles,
    resample_profile,
    trim_invalid_ends,
)

#: Registration accuracy demanded, as a fraction of the sampling step.
SHIFT_TOL_STEPS = 0.1
#: Smallest peak correlation of a perfect match at a fractional shift: the peak is
#: interpolated from integer lags of a texture with 3 um waves sampled at 0.5 um.
PEAK_CORR_MIN = 0.995
DX = 0.5e-6  # m


def texture(seed: int, n_waves: int = 60):
    """A continuous random texture f(x) (m -> m): a sum of seeded sines.

    Wavelengths 3 .. 50 um, amplitudes 5 .. 10 nm (a rough, non-periodic
    profile); f can be evaluated at any position, so shifts are exact.
    """
    rng = np.random.default_rng(seed)
    lam = np.exp(rng.uniform(np.log(3e-6), np.log(50e-6), n_waves))
    amp = 10e-9 * rng.uniform(0.5, 1.0, n_waves)
    ph = rng.uniform(0, 2 * np.pi, n_waves)

    def f(x):
        x = np.asarray(x, dtype=float)[..., None]
        return np.sum(amp * np.sin(2 * np.pi * x / lam + ph), axis=-1)

    return f


# --------------------------------------------------------------- registration
@pytest.mark.parametrize("shift", [37.0 * DX, 123.3e-6, -41.77e-6])
def test_registration_recovers_known_shift(shift):
    f = texture(1)
    x_ref = 1e-3 + DX * np.arange(1200)  # 1.0 .. 1.6 mm
    x_mov = 0.7e-3 + DX * np.arange(2500)  # f over 0.7 .. 1.95 mm, shifted
    ref = Profile(f(x_ref), DX, x0=x_ref[0])
    mov = Profile(f(x_mov + shift), DX, x0=x_mov[0])  # x_ref = x_mov + shift
    reg = register_profiles(ref, mov, mirror=False)
    assert not reg.mirrored
    assert abs(reg.shift - shift) < SHIFT_TOL_STEPS * DX
    assert reg.correlation > PEAK_CORR_MIN
    np.testing.assert_allclose(reg.overlap, ref.z.size * DX, rtol=1e-9)


def test_registration_finds_the_mirror():
    f = texture(2)
    shift = 0.61e-3 + 0.3 * DX
    x_ref = DX * np.arange(1000)
    x_mov = -0.8e-3 + DX * np.arange(3000)
    ref = Profile(f(x_ref), DX)
    mov = Profile(f(-x_mov + shift), DX, x0=x_mov[0])  # x_ref = -x_mov + shift
    reg = register_profiles(ref, mov)  # mirror="auto"
    assert reg.mirrored and reg.sign == -1
    assert abs(reg.shift - shift) < SHIFT_TOL_STEPS * DX
    assert reg.correlation > PEAK_CORR_MIN
    assert reg.correlation_other is not None and reg.correlation_other < 0.5
    np.testing.assert_allclose(reg.to_moving([x_ref[10]]), [reg.shift - x_ref[10]])
    # forced without mirror: no good match
    assert register_profiles(ref, mov, mirror=False).correlation < 0.5


def test_registration_ignores_nan_ends_and_resamples_the_moving_step():
    f = texture(3)
    shift = -0.25e-3
    x_ref = DX * np.arange(1500)
    z_ref = f(x_ref)
    z_ref[:70] = np.nan
    z_ref[-40:] = np.nan
    dx_mov = 0.25e-6  # finer: resampled onto the reference step
    x_mov = 0.1e-3 + dx_mov * np.arange(5000)
    z_mov = f(x_mov + shift)
    z_mov[:300] = np.nan
    reg = register_profiles(Profile(z_ref, DX), Profile(z_mov, dx_mov, x0=x_mov[0]),
                            mirror=False)
    assert abs(reg.shift - shift) < SHIFT_TOL_STEPS * DX


def test_registration_max_shift_limits_the_search():
    f = texture(4)
    x = DX * np.arange(2000)
    ref = Profile(f(x), DX)
    mov = Profile(f(x + 100e-6), DX)  # true shift 100 um
    assert abs(register_profiles(ref, mov, mirror=False).shift - 100e-6) < 1e-7
    near = register_profiles(ref, mov, mirror=False, max_shift=20e-6,
                             min_overlap=0.5)
    assert abs(near.shift) <= 20e-6 + 1e-12  # the true one is out of reach
    assert near.correlation < 0.5


def test_registration_shift_range_restricts_the_search():
    # the moving profile holds the reference texture twice: at shift 0.1 mm, and
    # at shift -0.5 mm with another texture added (a weaker match); the whole
    # search finds the first, a window around the second finds the second
    f, g = texture(6), texture(7)
    x = DX * np.arange(1000)  # 0 .. 0.5 mm
    ref = Profile(f(x), DX)
    xm = -0.2e-3 + DX * np.arange(2400)  # -0.2 .. 1.0 mm
    second = xm >= 0.5e-3
    zm = np.where(second, f(xm - 0.5e-3) + 0.8 * g(xm), f(xm + 0.1e-3))
    mov = Profile(zm, DX, x0=xm[0])
    whole = register_profiles(ref, mov, mirror=False)
    assert abs(whole.shift - 0.1e-3) < SHIFT_TOL_STEPS * DX
    win = register_profiles(ref, mov, mirror=False, shift_range=(-0.55e-3, -0.45e-3))
    assert abs(win.shift + 0.5e-3) < SHIFT_TOL_STEPS * DX
    assert 0.5 < win.correlation < whole.correlation
    edge = register_profiles(ref, mov, mirror=False, shift_range=(0.02e-3, 0.05e-3))
    assert 0.02e-3 - 1e-12 <= edge.shift <= 0.05e-3 + 1e-12
    with pytest.raises(ConfigError, match="lo <= hi"):
        register_profiles(ref, mov, shift_range=(1e-4, -1e-4))
    with pytest.raises(ConfigError, match=r"shift_range must be \(lo, hi\)"):
        register_profiles(ref, mov, shift_range=(1e-4,))


def test_registration_errors():
    p = Profile(np.arange(10.0), 1e-6)
    with pytest.raises(ConfigError, match="mirror must be"):
        register_profiles(p, p, mirror="both")
    with pytest.raises(ConfigError, match="min_overlap must be in"):
        register_profiles(p, p, min_overlap=0.0)
    flat = Profile(np.zeros(50), 1e-6)
    with pytest.raises(ConfigError, match="cannot be registered"):
        register_profiles(flat, flat)
    with pytest.raises(ConfigError, match="reference must be a Profile"):
        register_profiles(np.zeros(5), p)


# ------------------------------------------------------------- crop and lines
def test_crop_profile():
    p = Profile(np.arange(11.0), 1e-6, x0=-5e-6, metadata={"a": 1})
    c = crop_profile(p, -2e-6, 3e-6)
    np.testing.assert_array_equal(c.z, [3.0, 4, 5, 6, 7, 8])
    np.testing.assert_allclose(c.x0, -2e-6)
    assert c.metadata == {"a": 1, "x_range_m": [-2e-6, 3e-6]}
    with pytest.raises(ConfigError, match=r"holds 0 sample\(s\).*spans"):
        crop_profile(p, 1e-3, 2e-3)
    with pytest.raises(ConfigError, match="minimum < maximum"):
        crop_profile(p, 3e-6, -2e-6)


def test_trim_invalid_ends():
    z = np.array([np.nan, np.nan, 1.0, np.nan, 2.0, 3.0, np.nan])
    t = trim_invalid_ends(Profile(z, 2e-6, x0=1e-6))
    np.testing.assert_array_equal(np.isnan(t.z), [False, True, False, False])
    np.testing.assert_allclose(t.x0, 5e-6)
    with pytest.raises(ConfigError, match="1 valid sample"):
        trim_invalid_ends(Profile(np.array([np.nan, 1.0, np.nan]), 1e-6))


def test_profile_through_maps():
    z = np.arange(20.0).reshape(5, 4)  # rows y, columns x
    s = Surface(z, 1e-6, 2e-6, x0=10e-6, y0=-4e-6)
    row = profile_through(s)  # centre row (index 2, y = 0)
    np.testing.assert_array_equal(row.z, z[2])
    assert row.dx == 1e-6 and row.x0 == 10e-6
    assert row.metadata["line"] == {"axis": "x", "y_m": 0.0, "row": 2}
    col = profile_through(s, axis="y", at=12.2e-6)  # nearest column: x = 12 um
    np.testing.assert_array_equal(col.z, z[:, 2])
    assert col.dx == 2e-6 and col.x0 == -4e-6
    even = Surface(np.arange(8.0).reshape(4, 2), 1e-6, 1e-6)
    np.testing.assert_array_equal(profile_through(even).z, [4.0, 5.0])  # row 2
    one = Surface(np.arange(5.0)[None, :], 1e-6, 1e-6)
    np.testing.assert_array_equal(profile_through(one, axis="y").z, np.arange(5.0))
    with pytest.raises(ConfigError, match="lies outside the map"):
        profile_through(s, at=1.0)
    with pytest.raises(ConfigError, match="uncalibrated"):
        profile_through(Surface(z, None, None))


def test_resample_profile_is_linear_interpolation():
    rng = np.random.default_rng(5)  # any heights
    z = rng.normal(size=40)
    p = Profile(z, 1e-6, x0=2e-6)
    r = resample_profile(p, 0.37e-6, x0=3.1e-6, n=90, order=1)
    xq = 3.1e-6 + 0.37e-6 * np.arange(90)
    expect = np.interp(xq, p.x, z, left=np.nan, right=np.nan)
    np.testing.assert_allclose(r.z, expect, rtol=1e-12, atol=1e-12)
    z2 = z.copy()
    z2[10] = np.nan  # a NaN spoils the interpolated samples next to it only
    for order in (1, 3):
        r2 = resample_profile(Profile(z2, 1e-6, x0=2e-6), 0.5e-6, order=order)
        bad = np.flatnonzero(np.isnan(r2.z))
        np.testing.assert_array_equal(bad, [19, 20, 21])  # x = 11.5, 12, 12.5 um


def test_cubic_resampling_keeps_short_waves():
    # a sine of 6 samples per period, shifted by half a sample: linear
    # interpolation damps it by cos(pi / 6) = 0.87, the cubic spline hardly
    lam = 6e-6
    x = 1e-6 * np.arange(300)
    p = Profile(np.sin(2 * np.pi * x / lam), 1e-6)
    xq = 0.5e-6 + 1e-6 * np.arange(299)
    truth = np.sin(2 * np.pi * xq / lam)
    mid = slice(20, -20)  # away from the ends (boundary condition)
    lin = resample_profile(p, 1e-6, x0=0.5e-6, n=299, order=1).z
    cub = resample_profile(p, 1e-6, x0=0.5e-6, n=299).z
    np.testing.assert_allclose(np.max(np.abs(lin[mid])), np.cos(np.pi / 6),
                               rtol=1e-3)
    assert np.max(np.abs(cub[mid] - truth[mid])) < 0.02
    with pytest.raises(ConfigError, match="order must be 1"):
        resample_profile(p, 1e-6, order=2)
