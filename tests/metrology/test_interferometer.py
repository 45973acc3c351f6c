"""Simulated white-light interferometer: grid, blur, slope limit, noise, config."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from servosurf.errors import ConfigError
from servosurf.metrology import Surface
from servosurf.metrology._interferometer import (
    INSTRUMENTS,
    Interferometer,
    load_instrument,
    measure,
)

NV20 = INSTRUMENTS["newview-20x"]
#: The same instrument without height noise, to look at the deterministic steps.
QUIET = dataclasses.replace(NV20, noise_rms=0.0)
P = NV20.pixel_size  # 0.549 um
#: Relative accuracy of the measured Sq of a flat against the noise floor (brief:
#: 5 %; with 307 200 pixels the sampling scatter is about 0.13 %).
NOISE_RTOL = 0.05
#: A sinusoid of period well above the resolution keeps its amplitude to 2 %.
PASSBAND_RTOL = 0.02
#: ... and one below the Rayleigh limit keeps less than this fraction of it.
STOPBAND_MAX_GAIN = 0.05
#: Mid-band gain against the model's Gaussian x pixel-sinc transfer function (the
#: fit window's ends and the truncated kernel account for under 1 %).
MTF_RTOL = 0.015
#: Pixels this close (in output pixels) to the analytic slope limit may go
#: either way: central differences and the blur move the boundary by far less.
SLOPE_BOUNDARY_PX = 1.0


def _flat(shape=(480, 640), d=P, value=0.0) -> Surface:
    return Surface(np.full(shape, value), d, d)


def _fit_amplitude(s: Surface, period: float) -> float:
    """Least-squares amplitude of sin/cos at ``period`` along x, in m."""
    x, _ = s.coords()
    xx = np.broadcast_to(x, s.shape)[s.valid]
    a = np.column_stack(
        [
            np.ones(xx.size),
            np.sin(2 * np.pi * xx / period),
            np.cos(2 * np.pi * xx / period),
        ]
    )
    coef, *_ = np.linalg.lstsq(a, s.z[s.valid], rcond=None)
    return float(np.hypot(coef[1], coef[2]))


# ------------------------------------------------------------------- config
def test_presets_and_derived_quantities():
    assert set(INSTRUMENTS) == {
        "newview-20x",
        "newview-50x",
        "newview-100x",
        "cp300-20x",
    }
    fov = NV20.field_of_view
    np.testing.assert_allclose(
        fov, (640 * 0.549e-6, 480 * 0.549e-6), rtol=0, atol=1e-12
    )  # 1 pm
    # Rayleigh limit 0.61 lambda / NA = 0.869 um for 570 nm and NA 0.40
    np.testing.assert_allclose(
        NV20.lateral_resolution, 0.61 * 570e-9 / 0.40, rtol=1e-12, atol=0
    )
    np.testing.assert_allclose(NV20.max_slope_angle, math.asin(0.40), rtol=1e-12)
    for name, inst in INSTRUMENTS.items():
        assert inst.name == name
        assert load_instrument(name.upper()) is inst
        # the camera samples at least at the optical resolution / 2
        assert inst.pixel_size < inst.lateral_resolution


def test_load_instrument_from_mapping_and_toml(tmp_path):
    inst = load_instrument({"preset": "newview-50x", "noise-rms": 0.1e-9})
    assert inst.numerical_aperture == 0.55 and inst.noise_rms == 0.1e-9
    assert load_instrument({"numerical-aperture": 0.3}).pixel_size == NV20.pixel_size
    f = tmp_path / "inst.toml"
    f.write_text('preset = "newview-100x"\nslope-acceptance = 0.5\n')
    inst = load_instrument(f)
    assert inst.magnification == 100.0 and inst.slope_acceptance == 0.5
    assert load_instrument(NV20) is NV20


@pytest.mark.parametrize(
    ("kwargs", "field"),
    [
        ({"numerical_aperture": 1.5}, "numerical_aperture"),
        ({"numerical_aperture": 0.0}, "numerical_aperture"),
        ({"pixel_size": -1e-6}, "pixel_size"),
        ({"noise_rms": float("nan")}, "noise_rms"),
        ({"camera_nx": 1}, "camera_nx"),
        ({"camera_ny": 480.0}, "camera_ny"),
        ({"wavelength": "570 nm"}, "wavelength"),
        ({"slope_acceptance": 1.2}, "slope_acceptance"),
        ({"dropout_fraction": 1.0}, "dropout_fraction"),
        ({"magnification": True}, "magnification"),
    ],
)
def test_bad_values_raise_config_error_naming_the_field(kwargs, field):
    with pytest.raises(ConfigError, match=field):
        Interferometer(**kwargs)
    key = field.replace("_", "-")
    with pytest.raises(ConfigError, match=f"instrument.{key}"):
        load_instrument({key: next(iter(kwargs.values()))})


def test_unknown_keys_and_presets_suggest():
    hint = "Did you mean: instrument.numerical-aperture"
    with pytest.raises(ConfigError, match=hint):
        load_instrument({"numerical-apperture": 0.4})
    with pytest.raises(ConfigError, match="Did you mean: newview-20x"):
        load_instrument("newview-20")
    with pytest.raises(ConfigError, match="field-of-view"):
        load_instrument({"field-of-view": 1e-3})  # derived, not settable
    with pytest.raises(ConfigError, match="preset name"):
        load_instrument(3)


def test_measure_rejects_bad_arguments():
    with pytest.raises(ConfigError, match="calibrated"):
        measure(Surface(np.zeros((8, 8)), None, None), NV20, seed=1)
    with pytest.raises(ConfigError, match="Surface"):
        measure(np.zeros((8, 8)), NV20, seed=1)
    with pytest.raises(ConfigError, match="seed"):
        measure(_flat(), NV20, seed=1.5)
    with pytest.raises(ConfigError, match="2 x 2 instrument pixels"):
        measure(_flat((4, 4), d=0.1e-6), NV20, seed=1)
    with pytest.raises(TypeError):
        measure(_flat(), NV20, 1)  # seed is keyword-only


# ------------------------------------------------------------------ physics
def test_flat_map_measures_the_noise_floor():
    m = measure(_flat(), NV20, seed=1234)  # Sq scatter ~0.13 % for this seed
    assert m.shape == (480, 640) and m.valid.all()
    np.testing.assert_allclose(m.sq(), NV20.noise_rms, rtol=NOISE_RTOL)
    assert m.dx == m.dy == P


def test_seeded_output_is_reproducible_and_input_untouched():
    s = Surface(np.random.default_rng(7).normal(0, 1e-9, (200, 300)), 0.3e-6, 0.3e-6)
    before = s.z.copy()
    a = measure(s, NV20, seed=42)
    b = measure(s, NV20, seed=42)
    c = measure(s, NV20, seed=43)
    np.testing.assert_array_equal(a.z, b.z)
    assert not np.array_equal(a.z, c.z)
    np.testing.assert_array_equal(s.z, before)


@pytest.mark.parametrize("acceptance", [1.0, 0.5])
def test_slope_limit_invalidates_exactly_the_steep_pixels(acceptance):
    """A sphere cap of radius R: slope angle asin(r / R) exceeds the limit at
    r > R sin(limit); exactly those pixels become NaN (away from the edges)."""
    inst = dataclasses.replace(QUIET, slope_acceptance=acceptance)
    radius = 300e-6
    ny, nx = 480, 640
    x = (np.arange(nx) - (nx - 1) / 2) * P
    y = (np.arange(ny) - (ny - 1) / 2) * P
    r = np.hypot(x[None, :], y[:, None])
    assert r.max() < radius  # the cap covers the whole field
    z = np.sqrt(radius**2 - r**2) - radius
    m = measure(Surface(z, P, P, x0=x[0], y0=y[0]), inst, seed=1)
    assert m.shape == (ny, nx)
    expected_nan = np.arcsin(r / radius) > inst.max_slope_angle
    r_limit = radius * math.sin(inst.max_slope_angle)
    # at the borders the normalised blur is one-sided and biased on steep slopes
    edge = int(math.ceil(4 * inst.psf_sigma / P)) + 1
    inner = np.zeros_like(expected_nan)
    inner[edge:-edge, edge:-edge] = True
    ok = inner & m.valid
    # blur of a sphere: sigma^2 / 2 * laplacian, under 1 nm here
    np.testing.assert_allclose(m.z[ok], z[ok], atol=1e-9)  # 1 nm
    decided = inner & (np.abs(r - r_limit) > SLOPE_BOUNDARY_PX * P)
    np.testing.assert_array_equal(~m.valid[decided], expected_nan[decided])
    assert expected_nan[decided].sum() > 1000 and (~expected_nan[decided]).sum() > 1000


def test_long_period_sinusoid_passes_short_period_is_attenuated():
    d = 0.05e-6  # input 11x finer than the camera, 6 samples per PSF sigma
    n = 1600
    x = np.arange(n) * d
    amp = 10e-9
    for period, check in [(40e-6, "pass"), (0.6e-6, "stop")]:
        z = np.broadcast_to(amp * np.sin(2 * np.pi * x / period), (n, n))
        m = measure(Surface(z, d, d), QUIET, seed=1)
        assert m.valid.all()
        if check == "pass":
            np.testing.assert_allclose(
                _fit_amplitude(m, period), amp, rtol=PASSBAND_RTOL
            )
        else:
            # 0.6 um < Rayleigh 0.87 um: Gaussian gain exp(-2 pi^2 (0.3 / 0.6)^2)
            # ~ 0.007, then camera-pixel averaging; whatever aliases stays tiny
            assert m.sq() < STOPBAND_MAX_GAIN * amp / np.sqrt(2)


@pytest.mark.parametrize("d", [0.1e-6, 0.02e-6])  # 0.02 um: block-averaged first
@pytest.mark.parametrize("period", [2e-6, 3e-6])
def test_mid_band_gain_matches_gaussian_psf_times_pixel_sinc(d, period):
    n = int(round(60e-6 / d))
    x = np.arange(n) * d
    amp = 10e-9
    rows = int(round(2.5e-6 / d))  # four camera rows
    z = np.broadcast_to(amp * np.sin(2 * np.pi * x / period), (rows, n))
    m = measure(Surface(z, d, d), QUIET, seed=1)
    gain = _fit_amplitude(m, period) / amp
    expected = np.exp(-2 * np.pi**2 * (QUIET.psf_sigma / period) ** 2) * np.sinc(
        P / period
    )
    np.testing.assert_allclose(gain, expected, rtol=MTF_RTOL)


def test_finer_input_resampling_keeps_mean_and_centre():
    rng = np.random.default_rng(2024)  # smooth random field, 50 nm RMS
    ncam = (120, 160)
    n = (300, 400)  # extent exactly 120 x 160 camera pixels: ratio 2.5
    d = ncam[1] * P / n[1]
    z = rng.normal(0, 1.0, n)
    from scipy.ndimage import gaussian_filter

    z = gaussian_filter(z, 20, mode="wrap")
    z = 50e-9 * z / z.std() + 3e-6
    s = Surface(z, d, d, x0=-17e-6, y0=5e-6)
    m = measure(s, QUIET, seed=3)
    assert m.shape == ncam
    cx_in = s.x0 + (n[1] - 1) * d / 2
    cy_in = s.y0 + (n[0] - 1) * d / 2
    np.testing.assert_allclose(m.x0 + (ncam[1] - 1) * P / 2, cx_in, atol=1e-15)
    np.testing.assert_allclose(m.y0 + (ncam[0] - 1) * P / 2, cy_in, atol=1e-15)
    # area averaging preserves the mean exactly; the normalised blur only moves
    # it through the one-sided kernels at the borders
    np.testing.assert_allclose(np.nanmean(m.z), z.mean(), atol=0.2e-9)  # 0.2 nm


def test_coarser_input_is_interpolated_and_clipped_to_the_field():
    d = 2e-6  # coarser than the camera: bilinear interpolation, then blur
    n = (60, 90)  # 120 x 180 um: fewer pixels than the camera's 480 x 640
    yy, xx = np.mgrid[0 : n[0], 0 : n[1]] * d
    # a plane: bilinear interpolation (extrapolated to the tiles' outer edge) and
    # the plane-detrended blur reproduce it exactly, borders included
    z = 1e-3 * xx - 2e-3 * yy + 1e-6
    s = Surface(z, d, d)
    m = measure(s, QUIET, seed=3)
    assert m.shape == (int(n[0] * d / P), int(n[1] * d / P))
    x, y = m.coords()
    np.testing.assert_allclose(
        m.z, 1e-3 * x[None, :] - 2e-3 * y[:, None] + 1e-6, atol=1e-12
    )  # 1 pm
    np.testing.assert_allclose(m.z.mean(), z.mean(), atol=1e-12)  # 1 pm


def test_camera_size_clips_large_fields_and_resample_false_keeps_grid():
    s = _flat((1000, 1500), d=0.4e-6)
    m = measure(s, QUIET, seed=1)
    assert m.shape == (480, 640)  # the camera is smaller than the 600 x 400 um map
    k = measure(s, QUIET, seed=1, resample=False)
    assert k.shape == s.shape and (k.dx, k.dy, k.x0, k.y0) == (s.dx, s.dy, 0.0, 0.0)
    assert k.metadata["resampled"] is False


def test_nan_holes_stay_nan_and_dropout_fraction():
    z = np.zeros((480, 640))
    z[100:140, 200:260] = np.nan
    inst = dataclasses.replace(NV20, dropout_fraction=0.1)
    m = measure(Surface(z, P, P), inst, seed=99)  # 307 200 Bernoulli draws
    assert np.isnan(m.z[100:140, 200:260]).all()
    outside = np.ones(z.shape, bool)
    outside[100:140, 200:260] = False
    np.testing.assert_allclose(np.isnan(m.z[outside]).mean(), 0.1, atol=0.005)


def test_metadata():
    s = Surface(np.zeros((480, 640)), P, P, metadata={"source": "sim"})
    m = measure(s, "cp300-20x", seed=5)
    md = m.metadata
    assert md["source"] == "sim" and md["simulated"] is True
    assert md["instrument"] == "cp300-20x" and md["objective"].startswith("20X")
    assert md["numerical_aperture"] == 0.40 and md["wavelength_m"] == 570e-9
    assert md["pixel_size_m"] == P and md["noise_rms_m"] == NV20.noise_rms
    assert md["seed"] == 5 and md["magnification"] == 20.0
    assert s.metadata == {"source": "sim"}


def test_instrument_noise_is_not_the_vibration_stream():
    """The height noise draws its own stream of the seed, not default_rng(seed)."""
    import numpy as np

    from servosurf.metrology import Surface
    from servosurf.metrology._interferometer import Interferometer, measure

    flat = Surface(np.zeros((64, 64)), 0.549e-6, 0.549e-6)
    inst = Interferometer(noise_rms=1e-9, dropout_fraction=0.0, camera_nx=64,
                          camera_ny=64)
    m = measure(flat, inst, seed=3)
    shared = np.random.default_rng(3).standard_normal(m.z.shape) * 1e-9
    assert abs(np.corrcoef(m.z.ravel(), shared.ravel())[0, 1]) < 0.1
    again = measure(flat, inst, seed=3)
    np.testing.assert_array_equal(m.z, again.z)
