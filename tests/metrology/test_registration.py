"""Registration, sub-pixel shift, area resampling and form removal."""

from __future__ import annotations

import numpy as np
import pytest

from servosurf.errors import ConfigError
from servosurf.metrology import (
    Surface,
    nominal_lenslet_surface,
    register_translation,
    remove_form,
    resample,
    shift_surface,
)

LENS = dict(
    amplitude=10e-6, frequency=100.0, speed=42.3e-3, depth=5e-6, tool_radius=0.5e-3
)
D = 2e-6  # pixel size, m
N = 128
#: Registration accuracy required by the brief, in pixels (phase correlation alone).
REGISTRATION_ATOL_PX = 0.1
#: Accuracy after the Gauss-Newton refinement, in pixels.
REFINED_ATOL_PX = 0.01


def _lens_map(cx: float = 0.0, cy: float = 0.0) -> np.ndarray:
    x = (np.arange(N) - N / 2) * D
    return nominal_lenslet_surface(x, x, **LENS, centre=(cx, cy))


def _moving(rng, shift_px, *, tilt=(2e-4, -1e-4), noise=5e-9):
    """Reference lens displaced by shift_px (rows, cols), tilted and noised."""
    z = _lens_map(cx=shift_px[1] * D, cy=shift_px[0] * D)
    yy, xx = np.mgrid[0:N, 0:N] * D
    z = z + tilt[0] * xx + tilt[1] * yy + 1e-7
    return z + rng.normal(0.0, noise, z.shape)


@pytest.mark.parametrize("shift_px", [(0.0, 0.0), (3.37, -5.62), (-0.41, 0.26)])
@pytest.mark.parametrize("refine", [True, False])
def test_registration_of_shifted_tilted_noisy_lenslet(shift_px, refine):
    rng = np.random.default_rng(1234)  # 5 nm noise on a 5 um deep lens
    ref = Surface(_lens_map(), D, D)
    mov = Surface(_moving(rng, shift_px), D, D)
    dy, dx, err = register_translation(ref, mov, refine=refine)
    # the shift registering moving onto reference is minus its displacement
    atol = REFINED_ATOL_PX if refine else REGISTRATION_ATOL_PX
    np.testing.assert_allclose(dy / D, -shift_px[0], atol=atol)
    np.testing.assert_allclose(dx / D, -shift_px[1], atol=atol)
    # residual: the 5 nm noise and interpolation at the lens rim, against a map RMS
    # of about 1.5 um
    assert 0.0 <= err < 0.02


def test_registration_with_nan_holes_and_uncalibrated_pixels():
    rng = np.random.default_rng(1234)
    shift_px = (2.3, 1.7)
    ref = _lens_map()
    mov = _moving(rng, shift_px)
    mov[10:30, 90:110] = np.nan
    ref = ref.copy()
    ref[100:110, 5:20] = np.nan
    dy, dx, _ = register_translation(Surface(ref, None, None), Surface(mov, None, None))
    np.testing.assert_allclose([dy, dx], [-2.3, -1.7], atol=REGISTRATION_ATOL_PX)


def test_shift_surface_subpixel_against_analytic_lens():
    x = (np.arange(N) - N / 2) * D
    ref = _lens_map()
    mov = nominal_lenslet_surface(x, x, **LENS, centre=(-2.2 * D, 1.6 * D))
    back = shift_surface(Surface(mov, D, D), -1.6 * D, 2.2 * D)
    diff = (back.z - ref)[10:-10, 10:-10]
    # cubic spline error concentrates at the lens rim (a slope kink)
    assert np.sqrt(np.nanmean(diff**2)) < 5e-9  # 5 nm rms


def test_shift_then_register_round_trip():
    rng = np.random.default_rng(1234)
    ref = Surface(_lens_map(), D, D)
    mov = Surface(_moving(rng, (1.6, -2.2), tilt=(0.0, 0.0), noise=0.0), D, D)
    dy, dx, err = register_translation(ref, mov)
    back = shift_surface(mov, dy, dx)
    inner = (slice(10, -10), slice(10, -10))
    diff = back.z[inner] - ref.z[inner] - 1e-7
    # spline error plus the residual registration error on the lens wall
    assert np.sqrt(np.nanmean(diff**2)) < 15e-9  # 15 nm rms
    assert err < 0.01


def test_shift_integer_equals_roll_and_nan_moves():
    rng = np.random.default_rng(1234)
    z = rng.normal(0.0, 1e-8, (40, 50))
    z[5, 5] = np.nan
    s = Surface(z, 1e-6, 1e-6)
    out = shift_surface(s, 2e-6, -3e-6)
    np.testing.assert_allclose(
        out.z[2:, :-3][10:, 10:], z[:-2, 3:][10:, 10:], rtol=0, atol=1e-20
    )
    assert np.isnan(out.z[7, 2])  # the invalid pixel moved with the content
    assert np.isnan(out.z[:2, :]).all() and np.isnan(out.z[:, -3:]).all()


def test_shift_rejects_bad_order():
    with pytest.raises(ConfigError, match="order"):
        shift_surface(Surface(np.zeros((4, 4)), 1e-6, 1e-6), 0.0, 0.0, order=7)


def test_resample_integer_factor_is_block_mean():
    rng = np.random.default_rng(1234)
    z = rng.normal(0.0, 1e-8, (40, 60))
    s = Surface(z, 1e-6, 1e-6, x0=5e-6, y0=-2e-6)
    r = resample(s, 2e-6)
    expected = z.reshape(20, 2, 30, 2).mean(axis=(1, 3))
    np.testing.assert_allclose(r.z, expected, rtol=1e-12, atol=1e-24)
    assert r.dx == r.dy == 2e-6
    np.testing.assert_allclose([r.x0, r.y0], [5.5e-6, -1.5e-6], rtol=1e-12)


def test_resample_non_integer_plane_and_mean():
    ny, nx = 30, 45
    yy, xx = np.mgrid[0:ny, 0:nx] * 1e-6
    z = 2e-3 * xx - 1e-3 * yy + 1e-7
    r = resample(Surface(z, 1e-6, 1e-6), 1.5e-6, 2.5e-6)
    assert r.shape == (12, 30)
    # the grids cover the same area exactly: the mean height is preserved
    np.testing.assert_allclose(r.z.mean(), z.mean(), rtol=1e-12)
    xn, yn = r.coords()
    expected = 2e-3 * xn[None, :] - 1e-3 * yn[:, None] + 1e-7
    # uniform-tile model: within half a source pixel's height step (2e-3 * 1 um / 2)
    np.testing.assert_allclose(r.z, expected, rtol=0, atol=1e-9)


def test_resample_nan_coverage_rule():
    z = np.zeros((4, 4))
    z[0, 0] = np.nan  # 25 % of the first 2x2 block: kept
    z[2:4, 2] = np.nan
    z[3, 3] = np.nan  # 75 % of the last block: dropped
    r = resample(Surface(z, 1e-6, 1e-6), 2e-6)
    assert np.isfinite(r.z[0, 0]) and np.isnan(r.z[1, 1])


def test_resample_rejects_finer_pitch_and_uncalibrated():
    with pytest.raises(ConfigError, match="coarsens"):
        resample(Surface(np.zeros((4, 4)), 1e-6, 1e-6), 0.5e-6)
    with pytest.raises(ConfigError, match="calibrated"):
        resample(Surface(np.zeros((4, 4)), None, None), 2.0)


def test_remove_form_exact_and_nan_aware():
    rng = np.random.default_rng(1234)
    yy, xx = np.mgrid[0:50, 0:70] * 1e-6
    form = 3e-7 + 1e-3 * xx - 2e-3 * yy + 40.0 * ((xx - 30e-6) ** 2 + (yy - 20e-6) ** 2)
    rough = rng.normal(0.0, 1e-9, form.shape)
    rough -= rough.mean()
    z = form + rough
    z[5:9, 5:9] = np.nan
    res, fitted = remove_form(Surface(z, 1e-6, 1e-6), return_form=True)
    m = np.isfinite(z)
    np.testing.assert_allclose(res.z[m] + fitted.z[m], z[m], rtol=0, atol=1e-18)
    # residual equals the roughness to within its projection on the form basis
    assert np.sqrt(np.mean((res.z[m] - rough[m]) ** 2)) < 0.1e-9
    assert np.isnan(res.z[6, 6])
    assert res.metadata["form_removed"] == ["piston", "tilt", "sphere"]


def test_remove_form_errors():
    s = Surface(np.zeros((4, 4)), 1e-6, 1e-6)
    with pytest.raises(ConfigError, match="unknown form term"):
        remove_form(s, ("coma",))
    with pytest.raises(ConfigError):
        remove_form(s, ())
    res = remove_form(s, "piston")
    np.testing.assert_allclose(res.z, 0.0, atol=0)


def test_register_errors():
    a = Surface(np.zeros((8, 8)), 1e-6, 1e-6)
    with pytest.raises(ConfigError, match="same shape"):
        register_translation(a, Surface(np.zeros((8, 9)), 1e-6, 1e-6))
    with pytest.raises(ConfigError, match="same dx"):
        register_translation(a, Surface(np.zeros((8, 8)), 2e-6, 1e-6))
