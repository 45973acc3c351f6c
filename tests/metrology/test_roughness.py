"""ISO 4287 / 4288 profile roughness and ISO 25178-2 areal parameters."""

from __future__ import annotations

import math
import os
from pathlib import Path

import numpy as np
import pytest

from servosurf.errors import ConfigError
from servosurf.metrology import (
    Profile,
    Surface,
    areal_roughness,
    iso4288_cutoff,
    profile_roughness,
)

# like tests/conftest.py: SERVOSURF_SHARED, else the checkout's ../shared
SHARED = Path(
    os.environ.get(
        "SERVOSURF_SHARED", Path(__file__).resolve().parents[2].parent / "shared"
    )
)
NEXVIEW_CSV = SHARED / "data" / "zygo" / "nexview_nx2_diamond_turned_1016-WLI-2D.csv"

#: Relative tolerance on the NexView reference values (brief: 0.5 %).
NEXVIEW_RTOL = 5e-3
#: Relative tolerance of a sampled sine's Ra/Rq against 2a/pi and a/sqrt(2).
SINE_RTOL = 2e-3
#: Relative tolerance of moment statistics of seeded Gaussian noise.
NOISE_RTOL = 0.05


def read_mx_profile_csv(path: Path) -> Profile:
    """Minimal reader of a ZYGO Mx profile CSV (X, Y columns in um; a text header).

    Local to the test: ``servosurf.io`` owns the real reader.
    """
    xs, zs = [], []
    for line in path.read_text(encoding="utf-8", errors="replace").splitlines():
        parts = [p.strip() for p in line.split(",")]
        try:
            x, z = float(parts[0]), float(parts[1])
        except (ValueError, IndexError):
            continue  # header lines
        xs.append(x)
        zs.append(z)
    x = np.asarray(xs) * 1e-6
    z = np.asarray(zs) * 1e-6
    return Profile(z, float(np.mean(np.diff(x))), {"source": path.name}, float(x[0]))


@pytest.fixture(scope="module")
def nexview() -> Profile:
    if not NEXVIEW_CSV.is_file():
        pytest.skip(f"shared measurement data not found at {NEXVIEW_CSV}")
    return read_mx_profile_csv(NEXVIEW_CSV)


def test_nexview_file_is_parsed(nexview):
    assert nexview.z.size == 962
    np.testing.assert_allclose(nexview.dx, 0.871e-6, rtol=1e-3)


def test_nexview_ra_ends_kept(nexview):
    res = profile_roughness(nexview, cutoff=80e-6, trim_ends=False)
    assert res["ends_trimmed"] is False and res["trim_length_m"] == 0.0
    np.testing.assert_allclose(res["ra_m"], 14.6e-9, rtol=NEXVIEW_RTOL)


def test_nexview_ra_reference_value_default_trim(nexview):
    # The shared reference quotes Ra 13.19 nm "with the ends trimmed". It is
    # reproduced when lambda_c (80 um) is discarded at each end, servosurf's default.
    res = profile_roughness(nexview, cutoff=80e-6)
    assert res["ends_trimmed"] is True
    np.testing.assert_allclose(res["trim_length_m"], 80e-6, rtol=1e-12)
    np.testing.assert_allclose(res["ra_m"], 13.19e-9, rtol=NEXVIEW_RTOL)


def test_nexview_ra_iso_trim_golden(nexview):
    # ISO 4288 run-up and run-out of lambda_c / 2 only. Golden value from this
    # implementation, cross-checked with scipy.ndimage.gaussian_filter1d
    # (sigma = alpha lambda_c / sqrt(2 pi), any boundary mode): 14.019 nm.
    res = profile_roughness(nexview, cutoff=80e-6, trim_length=40e-6)
    assert res["ends_trimmed"] is True
    np.testing.assert_allclose(res["trim_length_m"], 40e-6, rtol=1e-12)
    np.testing.assert_allclose(res["ra_m"], 14.019e-9, rtol=1e-3)
    assert res["cutoff_rule"] == "given"
    assert res["rz_sampling_lengths"] == 5


def test_nexview_iso4288_picks_80_um(nexview):
    # Ra about 14 nm is in the (0.006, 0.02] um range of ISO 4288 Table 1.
    assert iso4288_cutoff(nexview) == pytest.approx(80e-6)
    res = profile_roughness(nexview)
    assert res["cutoff_rule"] == "ISO 4288"
    assert res["cutoff_m"] == pytest.approx(80e-6)


def _sine_profile(a: float, wavelength: float, n: int, dx: float) -> Profile:
    x = np.arange(n) * dx
    return Profile(a * np.sin(2 * np.pi * x / wavelength + 0.1), dx)


def test_sine_below_cutoff_gives_ra_2a_over_pi_and_rq_a_over_sqrt2():
    a = 20e-9
    # 7.3 um period at 0.29 um step: incommensurate, so the sampled |sin| averages
    p = _sine_profile(a, 7.3e-6, 20000, 0.29e-6)
    res = profile_roughness(p, cutoff=250e-6)
    np.testing.assert_allclose(res["ra_m"], 2 * a / math.pi, rtol=SINE_RTOL)
    np.testing.assert_allclose(res["rq_m"], a / math.sqrt(2), rtol=SINE_RTOL)
    np.testing.assert_allclose(res["rz_m"], 2 * a, rtol=SINE_RTOL)
    np.testing.assert_allclose(res["rsm_m"], 7.3e-6, rtol=SINE_RTOL)
    np.testing.assert_allclose(res["rsk"], 0.0, atol=1e-2)
    np.testing.assert_allclose(res["rku"], 1.5, rtol=SINE_RTOL)


def test_sine_far_above_cutoff_is_removed():
    a = 1e-6
    p = _sine_profile(a, 8e-3, 20000, 1e-6)  # 100 x the cut-off
    res = profile_roughness(p, cutoff=80e-6)
    # roughness transmission 1 - exp(-pi (alpha / 100)^2) ~ 7e-5
    assert res["ra_m"] < 1e-4 * 2 * a / math.pi


def test_rz_over_evaluation_length_when_short():
    p = _sine_profile(10e-9, 5.3e-6, 600, 0.5e-6)  # 300 um < 5 x 80 um + 80 um
    res = profile_roughness(p, cutoff=80e-6)
    assert res["rz_sampling_lengths"] == 1
    assert res["rz_m"] == pytest.approx(res["rt_m"], abs=0.0)
    assert res["rt_m"] == pytest.approx(res["rp_m"] + res["rv_m"], abs=0.0)


def test_nan_samples_are_ignored():
    p = _sine_profile(20e-9, 7.3e-6, 20000, 0.29e-6)
    z = p.z.copy()
    z[5000:5040] = np.nan
    z[:7] = np.nan
    res_nan = profile_roughness(Profile(z, p.dx), cutoff=250e-6)
    np.testing.assert_allclose(res_nan["ra_m"], 2 * 20e-9 / math.pi, rtol=SINE_RTOL)


@pytest.mark.parametrize(
    ("ra", "expected"),
    [(10e-9, 0.08e-3), (50e-9, 0.25e-3), (0.5e-6, 0.8e-3), (4e-6, 2.5e-3)],
)
def test_iso4288_non_periodic_table(ra, expected):
    # Seeded white noise: Ra = sigma sqrt(2/pi), nearly independent of the cut-off.
    rng = np.random.default_rng(1234)
    dx = 2e-6
    z = rng.normal(0.0, ra / math.sqrt(2 / math.pi), 4000)  # 8 mm
    assert iso4288_cutoff(Profile(z, dx)) == pytest.approx(expected)


@pytest.mark.parametrize(
    ("wavelength", "expected"),
    [(25e-6, 0.08e-3), (100e-6, 0.25e-3), (300e-6, 0.8e-3)],
)
def test_iso4288_periodic_table(wavelength, expected):
    p = _sine_profile(50e-9, wavelength, 6000, 1e-6)  # 6 mm
    assert iso4288_cutoff(p, periodic=True) == pytest.approx(expected)


def test_iso4288_limits_cutoff_to_profile_length():
    rng = np.random.default_rng(1234)
    z = rng.normal(0.0, 1e-6, 1000)  # Ra 0.8 um asks for 0.8 mm; 1 mm long profile
    assert iso4288_cutoff(Profile(z, 1e-6)) == pytest.approx(0.25e-3)
    with pytest.raises(ConfigError, match="shorter than twice"):
        iso4288_cutoff(Profile(z[:100], 1e-6))


def test_profile_roughness_rejects_bad_input():
    with pytest.raises(ConfigError):
        profile_roughness(np.zeros(10))
    with pytest.raises(ConfigError):
        profile_roughness(Profile(np.zeros(10), 1e-6), cutoff=-1.0)
    with pytest.raises(ConfigError, match="no valid samples"):
        profile_roughness(Profile(np.zeros(50), 1e-6), cutoff=80e-6)
    with pytest.raises(TypeError):
        profile_roughness(Profile(np.zeros(10), 1e-6), cut_off=1e-5)


def test_areal_sine_surface():
    a = 30e-9
    yy, xx = np.mgrid[0:64, 0:1000]
    z = a * np.sin(2 * np.pi * xx * 0.37e-6 / 6.1e-6) + 0 * yy
    res = areal_roughness(Surface(z, 0.37e-6, 0.37e-6))
    np.testing.assert_allclose(res["sa_m"], 2 * a / math.pi, rtol=SINE_RTOL)
    np.testing.assert_allclose(res["sq_m"], a / math.sqrt(2), rtol=SINE_RTOL)
    np.testing.assert_allclose(res["sku"], 1.5, rtol=SINE_RTOL)
    np.testing.assert_allclose(res["sz_m"], 2 * a, rtol=SINE_RTOL)
    assert res["cutoff_m"] is None


def test_areal_noise_moments_nan_aware_and_filtered():
    rng = np.random.default_rng(1234)  # moments within NOISE_RTOL for this seed
    sigma = 5e-9
    z = rng.normal(0.0, sigma, (200, 200))
    yy, xx = np.mgrid[0:200, 0:200] * 1e-6
    tilted = z + 1e-3 * xx + 2e-7  # tilt and offset
    tilted[50:60, 50:60] = np.nan
    res = areal_roughness(Surface(tilted, 1e-6, 1e-6), cutoff=25e-6)
    np.testing.assert_allclose(res["sq_m"], sigma, rtol=NOISE_RTOL)
    np.testing.assert_allclose(
        res["sa_m"], sigma * math.sqrt(2 / math.pi), rtol=NOISE_RTOL
    )
    np.testing.assert_allclose(res["ssk"], 0.0, atol=0.1)
    np.testing.assert_allclose(res["sku"], 3.0, rtol=NOISE_RTOL)
    assert res["sz_m"] == pytest.approx(res["sp_m"] + res["sv_m"], abs=0.0)
    assert res["n_valid"] == 200 * 200 - 100
    # without a filter only the mean goes: the tilt dominates
    raw = areal_roughness(Surface(tilted, 1e-6, 1e-6))
    assert raw["sq_m"] > 10 * res["sq_m"]


def test_areal_errors():
    with pytest.raises(ConfigError):
        areal_roughness(Surface(np.full((3, 3), np.nan), 1e-6, 1e-6))
    with pytest.raises(ConfigError, match="calibrated"):
        areal_roughness(Surface(np.zeros((3, 3)), None, None), cutoff=1e-5)
