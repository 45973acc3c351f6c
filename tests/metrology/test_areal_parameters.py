"""ISO 25178-2 areal parameters: closed forms, surfalize, real files, voids.

Oracles: closed forms (tilted plane, sinusoids, Gaussian heights, a ramp), the
closed form of the unbiased ACF estimator of sampled cosines, a plain loop ACF,
surfalize 0.19 on the same void-free arrays, and the real measurements of
``shared/data/zygo``.
"""

from __future__ import annotations

import math
import warnings

import numpy as np
import pytest
from scipy import integrate, optimize, special, stats

from servosurf.errors import ConfigError
from servosurf.io import read_surface
from servosurf.metrology import Surface, areal_autocorrelation, areal_parameters

#: Exact closed forms evaluated in floating point (sums of ~1e5 terms).
RTOL_EXACT = 1e-12
#: Same numbers as surfalize, computed with other float64 roundings.
RTOL_SAME_FORMULA = 1e-12
#: Sal, Str against surfalize: both find where the ACF falls to 0.2 along rays, we
#: by bilinear, surfalize by cubic interpolation of the ACF sampled per pixel; on
#: maps with Sal >= 5 px the two differ by < 0.4 % (measured 0.02-0.3 %).
RTOL_SPATIAL_SURFALIZE = 1e-2
#: Sk, Smr1, Smr2, Spk, Svk against surfalize, whose material ratio curve has
#: 10 000 classes (0.01 % of material ratio) and whose peak and dale areas are
#: trapezoids between classes: accurate to a few 1e-3 when the zones hold >= 5 %
#: of the points (measured <= 1.7e-3); ours sums every point exactly.
RTOL_MATERIAL_SURFALIZE = 5e-3
#: A zone with fewer points than this is too coarse for surfalize's classes.
MIN_ZONE_PERCENT = 5.0
#: Material ratio family against the continuous Gaussian: ours sums n = 262 144
#: quantile points; counting a zone boundary is exact to one point (1/n = 4e-6,
#: 2e-5 relative to a 20 % zone) and the tail sum is a midpoint rule (< 1e-5).
RTOL_GAUSSIAN_MR = 1e-4


def _surfalize_values(s: Surface) -> dict[str, float]:
    surfalize = pytest.importorskip("surfalize")
    with warnings.catch_warnings():
        # surfalize warns about rectangular pixels (its Sal, Str handle them, as
        # the comparison shows) and when Str is undefined
        warnings.simplefilter("ignore")
        sf = surfalize.Surface(s.z * 1e6, s.dx * 1e6, s.dy * 1e6)  # um
        return {
            "sa_m": sf.Sa() * 1e-6,
            "sq_m": sf.Sq() * 1e-6,
            "sp_m": sf.Sp() * 1e-6,
            "sv_m": sf.Sv() * 1e-6,
            "sz_m": sf.Sz() * 1e-6,
            "ssk": sf.Ssk(),
            "sku": sf.Sku(),
            "sdq": sf.Sdq(),
            "sdr_percent": sf.Sdr(),
            "sal_m": sf.Sal() * 1e-6,
            "str": sf.Str(),
            "sk_m": sf.Sk() * 1e-6,
            "spk_m": sf.Spk() * 1e-6,
            "svk_m": sf.Svk() * 1e-6,
            "smr1_percent": sf.Smr1(),
            "smr2_percent": sf.Smr2(),
        }


def _check_against_surfalize(s: Surface) -> None:
    ours, ref = areal_parameters(s), _surfalize_values(s)
    for key in ("sa_m", "sq_m", "sp_m", "sv_m", "sz_m", "ssk", "sku", "sdq"):
        np.testing.assert_allclose(
            ours[key], ref[key], rtol=RTOL_SAME_FORMULA, err_msg=key
        )
    # Sdr: the same triangulation; a small difference of nearly equal areas
    np.testing.assert_allclose(ours["sdr_percent"], ref["sdr_percent"], rtol=1e-9)
    for key in ("sal_m", "str"):
        if math.isnan(ref[key]):
            assert math.isnan(ours[key]), key  # both find it undefined
        else:
            np.testing.assert_allclose(
                ours[key], ref[key], rtol=RTOL_SPATIAL_SURFALIZE, err_msg=key
            )
    keys = ["sk_m", "smr2_percent"]
    if ours["smr1_percent"] >= MIN_ZONE_PERCENT:
        keys += ["spk_m", "smr1_percent"]
    if ours["smr2_percent"] <= 100 - MIN_ZONE_PERCENT:
        keys += ["svk_m"]
    for key in keys:
        np.testing.assert_allclose(
            ours[key], ref[key], rtol=RTOL_MATERIAL_SURFALIZE, err_msg=key
        )


def _gaussian_field(shape, sigma_px, seed, dx=0.5e-6, dy=0.5e-6) -> Surface:
    from scipy.ndimage import gaussian_filter

    rng = np.random.default_rng(seed)  # fixed seed: one random rough surface
    z = gaussian_filter(rng.normal(size=shape), sigma_px, mode="wrap")
    return Surface(20e-9 * z / z.std(), dx, dy)


# ---------------------------------------------------------------- naive ACF
def naive_acf(z: np.ndarray) -> np.ndarray:
    """Loop over lags: mean of z(p) z(p + t) over valid pairs, over mean z^2."""
    ny, nx = z.shape
    ly, lx = ny // 2, nx // 2
    out = np.full((2 * ly + 1, 2 * lx + 1), np.nan)
    for ty in range(-ly, ly + 1):
        for tx in range(-lx, lx + 1):
            a = z[max(0, -ty) : ny - max(0, ty), max(0, -tx) : nx - max(0, tx)]
            b = z[max(0, ty) : ny + min(0, ty), max(0, tx) : nx + min(0, tx)]
            prod = (a * b)[np.isfinite(a * b)]
            if prod.size:
                out[ty + ly, tx + lx] = prod.mean()
    return out / out[ly, lx]


def test_acf_matches_plain_loop_with_voids():
    rng = np.random.default_rng(7)  # fixed seed: random heights and voids
    z = rng.normal(size=(9, 12))
    z[rng.random(z.shape) < 0.2] = np.nan
    s = Surface(z, 1e-6, 2e-6)
    acf, tx, ty = areal_autocorrelation(s)
    zc = z - np.nanmean(z)
    np.testing.assert_allclose(acf, naive_acf(zc), rtol=1e-12, atol=1e-14)
    np.testing.assert_allclose(tx, 1e-6 * np.arange(-6, 7))
    np.testing.assert_allclose(ty, 2e-6 * np.arange(-4, 5))


# ------------------------------------------------------------- closed forms
def test_tilted_plane_sdq_sdr_are_the_slope():
    a, b = 0.02, -0.035  # slopes dz/dx, dz/dy
    dx, dy = 0.4e-6, 0.7e-6
    yy, xx = np.mgrid[0:60, 0:80]
    s = Surface(a * xx * dx + b * yy * dy, dx, dy)
    p = areal_parameters(s)
    np.testing.assert_allclose(p["sdq"], math.hypot(a, b), rtol=RTOL_EXACT)
    np.testing.assert_allclose(
        p["sdr_percent"], 100 * (math.sqrt(1 + a * a + b * b) - 1), rtol=1e-9
    )
    assert areal_parameters(s, form="plane")["sdq"] < 1e-12  # levelled: flat


def test_tilted_plane_with_voids():
    a = 0.01
    yy, xx = np.mgrid[0:40, 0:50]
    z = a * xx * 1e-6
    rng = np.random.default_rng(2)  # fixed seed: where the voids fall
    z[rng.random(z.shape) < 0.3] = np.nan
    p = areal_parameters(Surface(z, 1e-6, 1e-6))
    np.testing.assert_allclose(p["sdq"], a, rtol=RTOL_EXACT)
    np.testing.assert_allclose(p["sdr_percent"], 100 * (math.hypot(1, a) - 1), 1e-9)


def test_separable_sinusoids_sdq_exact_discrete_closed_form():
    # z = A sin(kx x) + B sin(ky y), whole periods along the differences: forward
    # differences of a sine have amplitude 2 sin(k h / 2) / h exactly.
    dx, dy = 0.5e-6, 0.8e-6
    nper_x, nper_y = 40, 25  # samples per period
    kx, ky = 2 * np.pi / (nper_x * dx), 2 * np.pi / (nper_y * dy)
    aa, bb = 30e-9, 50e-9
    x = dx * np.arange(3 * nper_x + 1)
    y = dy * np.arange(4 * nper_y + 1)
    z = aa * np.sin(kx * x)[None, :] + bb * np.sin(ky * y)[:, None]
    p = areal_parameters(Surface(z, dx, dy))
    gx = aa * 2 * np.sin(kx * dx / 2) / dx
    gy = bb * 2 * np.sin(ky * dy / 2) / dy
    np.testing.assert_allclose(p["sdq"], np.sqrt(gx**2 / 2 + gy**2 / 2), RTOL_EXACT)
    # and the continuum value A k / sqrt(2), within the O((k h)^2) of differencing
    cont = np.sqrt((aa * kx) ** 2 / 2 + (bb * ky) ** 2 / 2)
    kh = max(kx * dx, ky * dy)
    np.testing.assert_allclose(p["sdq"], cont, rtol=kh**2 / 24 * 1.01)


def test_corrugation_sdr_is_the_elliptic_closed_form():
    # z = A sin(k x): Sdr = (2/pi) sqrt(1 + a^2) E(a^2 / (1 + a^2)) - 1, a = A k
    h = 0.5e-6
    lam = 128 * h
    k = 2 * np.pi / lam
    amp = 0.05 * lam
    x = h * np.arange(4 * 128 + 1)
    p = areal_parameters(Surface(np.tile(amp * np.sin(k * x), (8, 1)), h, h))
    a2 = (amp * k) ** 2
    sdr = (2 / np.pi) * np.sqrt(1 + a2) * special.ellipe(a2 / (1 + a2)) - 1
    # the triangulated (polyline) length differs from the arc by O((k h)^2)
    np.testing.assert_allclose(p["sdr_percent"], 100 * sdr, rtol=(k * h) ** 2 / 8)


def test_sinusoidal_grid_sdq_sdr():
    # the design surface A sin(2 pi x / Lx) sin(2 pi y / Ly)
    h = 0.5e-6
    lx, ly = 128 * h, 192 * h
    kx, ky = 2 * np.pi / lx, 2 * np.pi / ly
    amp = 0.03 * lx
    yy, xx = np.mgrid[0 : 4 * 192 + 1, 0 : 4 * 128 + 1] * h
    p = areal_parameters(Surface(amp * np.sin(kx * xx) * np.sin(ky * yy), h, h))

    def dev(y, x):
        gx = amp * kx * np.cos(kx * x) * np.sin(ky * y)
        gy = amp * ky * np.sin(kx * x) * np.cos(ky * y)
        return np.sqrt(1 + gx**2 + gy**2)

    area, _ = integrate.dblquad(dev, 0, lx, 0, ly, epsabs=0, epsrel=1e-12)
    kh = max(kx, ky) * h
    # O((k h)^2) of the triangulation; the map ends on whole periods but counts
    # both end rows, which biases the mean square slope by O(1 / n) (n = 769)
    np.testing.assert_allclose(
        p["sdr_percent"], 100 * (area / (lx * ly) - 1), rtol=kh**2 / 8
    )
    np.testing.assert_allclose(
        p["sdq"], amp * np.hypot(kx, ky) / 2, rtol=kh**2 / 24 + 1 / 769
    )


def test_gaussian_quantile_heights_material_ratio_closed_form():
    # heights: the 262 144 Gaussian quantiles, shuffled (seeded) over the map
    sigma, n = 20e-9, 512 * 512
    q = sigma * stats.norm.ppf((np.arange(n) + 0.5) / n)
    rng = np.random.default_rng(3)  # fixed seed: the arrangement only
    p = areal_parameters(Surface(rng.permutation(q).reshape(512, 512), 1e-6, 1e-6))
    # continuous material ratio curve h(mr) = sigma Phi^-1(1 - mr); by symmetry
    # the least steep 40 % secant is [30 %, 70 %]; least-squares line over it
    num, _ = integrate.quad(
        lambda m: (m - 0.5) * sigma * stats.norm.ppf(1 - m), 0.3, 0.7
    )
    slope = num / (0.4**3 / 12)
    c1, c2 = -slope / 2, slope / 2
    smr1 = stats.norm.sf(c1 / sigma)
    a1 = sigma * stats.norm.pdf(c1 / sigma) - c1 * smr1  # integral of (h - c1)+
    spk = 2 * a1 / smr1
    expected = {
        "sk_m": c1 - c2,
        "smr1_percent": 100 * smr1,
        "smr2_percent": 100 * (1 - smr1),
        "spk_m": spk,
        "svk_m": spk,
    }
    for key, value in expected.items():
        np.testing.assert_allclose(p[key], value, rtol=RTOL_GAUSSIAN_MR, err_msg=key)
    assert abs(p["ssk"]) < 1e-12  # symmetric quantiles
    # kurtosis of n quantiles: 3 less the truncated tails beyond |z| = 4.6 sigma
    np.testing.assert_allclose(p["sku"], 3.0, atol=1e-3)
    np.testing.assert_allclose(p["sq_m"], sigma, rtol=1e-4)


def test_white_gaussian_surface_skewness_kurtosis():
    n = 512 * 512
    rng = np.random.default_rng(4)  # fixed seed: one realisation
    p = areal_parameters(Surface(rng.normal(0, 5e-9, (512, 512)), 1e-6, 1e-6))
    # sample skewness and kurtosis of n iid normals: std sqrt(6/n), sqrt(24/n)
    assert abs(p["ssk"]) < 5 * math.sqrt(6 / n)
    assert abs(p["sku"] - 3) < 5 * math.sqrt(24 / n)


def test_uniform_heights_have_no_peak_or_dale_zone():
    # heights spread evenly: the material ratio curve is its own straight line
    n = 100 * 80
    h = 1e-7 * (1 - 2 * (np.arange(n) + 0.5) / n)  # -100 .. 100 nm
    rng = np.random.default_rng(5)  # fixed seed: the arrangement only
    p = areal_parameters(Surface(rng.permutation(h).reshape(100, 80), 1e-6, 1e-6))
    np.testing.assert_allclose(p["sk_m"], 2e-7, rtol=1e-9)
    assert p["spk_m"] == 0 and p["svk_m"] == 0
    assert p["smr1_percent"] == 0 and p["smr2_percent"] == 100


# --------------------------------------------------------------- Sal and Str
def acf_cos_estimator(tx, ty, k, n, two_d):
    """Unbiased ACF estimator of cos(k i) (+ cos(k j)) on n x n pixels, closed form.

    ``n`` is a whole number of periods ``2 pi / k`` (pixels). With ``M = n - t``
    pairs, ``(1/M) sum cos(k i) cos(k (i + t)) = cos(k t) / 2 - sin(k t) cot(k) /
    (2 M)`` (geometric sums); the cross terms of the 2-D sum are products of
    ``sum_{i<M} cos(k i)`` and ``sum_{i<M} cos(k (i + t))``.
    """

    def c(t):
        return 0.5 * np.cos(k * t) - np.sin(k * t) / np.tan(k) / (2 * (n - t))

    def s0(t):
        return np.real((np.exp(-1j * k * t) - 1) / (np.exp(1j * k) - 1))

    def st(t):
        return np.real((1 - np.exp(1j * k * t)) / (np.exp(1j * k) - 1))

    tx, ty = np.abs(tx), np.abs(ty)
    if not two_d:
        return 2 * c(tx)
    return c(tx) + c(ty) + (s0(tx) * st(ty) + s0(ty) * st(tx)) / ((n - tx) * (n - ty))


def _first_crossing(f, phi, rmax, s=0.2):
    r = np.linspace(0, rmax, 4001)
    v = f(r * np.cos(phi), r * np.sin(phi))
    j = int(np.argmax(v <= s))
    return optimize.brentq(
        lambda q: f(q * np.cos(phi), q * np.sin(phi)) - s, r[j - 1], r[j], xtol=1e-12
    )


@pytest.fixture(scope="module")
def cos_sum():
    n, per = 512, 64  # pixels, pixels per period
    k = 2 * np.pi / per
    i = np.arange(n)
    z = 10e-9 * (np.cos(k * i)[None, :] + np.cos(k * i)[:, None])
    f = lambda a, b: acf_cos_estimator(a, b, k, n, True)  # noqa: E731
    r = [_first_crossing(f, phi, 0.6 * per) for phi in np.linspace(0, np.pi / 2, 721)]
    return z, k, min(r), min(r) / max(r)


# Bilinear interpolation of the ACF between integer lags errs by at most k^2 / 8
# (|f_xx| + |f_yy| <= k^2); divided by the ACF slope at the crossing times the
# distance this is 0.093 k^2 of Sal (diagonal) and 0.141 k^2 of the slowest
# decay (axis), so 0.1 k^2 bounds Sal and 0.25 k^2 bounds Str.
def test_cos_sum_sal_str_closed_form(cos_sum):
    z, k, sal_px, str_ = cos_sum
    h = 0.3e-6
    p = areal_parameters(Surface(z, h, h))
    np.testing.assert_allclose(p["sal_m"], sal_px * h, rtol=0.1 * k**2)
    np.testing.assert_allclose(p["str"], str_, rtol=0.25 * k**2)
    # the ideal (infinite-field) values, which the estimator approaches with a
    # bias of order (period / field) = 1/8 here (-1.4 % on Sal)
    bias = 0.2 * 64 / 512
    np.testing.assert_allclose(sal_px, np.sqrt(2) * np.arccos(0.2) / k, rtol=bias)
    ideal_str = np.sqrt(2) * np.arccos(0.2) / np.arccos(-0.6)
    np.testing.assert_allclose(str_, ideal_str, rtol=bias)


def test_cos_sum_sal_str_with_voids(cos_sum):
    z, k, sal_px, str_ = cos_sum
    z = z.copy()
    rng = np.random.default_rng(6)  # fixed seed: where the 10 % voids fall
    z[rng.random(z.shape) < 0.1] = np.nan
    p = areal_parameters(Surface(z, 1e-6, 1e-6))
    # voids drop ~19 % of the pixel pairs at random: the ACF average over
    # ~2e5 pairs moves by ~0.5 / sqrt(2e5) = 1e-3; 5 of those, divided by the
    # slope times distance at the crossing (0.69 x 1.94) adds 4e-3
    np.testing.assert_allclose(p["sal_m"], sal_px * 1e-6, rtol=0.1 * k**2 + 4e-3)
    np.testing.assert_allclose(p["str"], str_, rtol=0.25 * k**2 + 8e-3)


def test_corrugation_str_undefined_sal_closed_form():
    n, per = 512, 64
    k = 2 * np.pi / per
    z = np.tile(10e-9 * np.cos(k * np.arange(n)), (n // 2, 1))
    p = areal_parameters(Surface(z, 1e-6, 1e-6))
    f = lambda a, b: acf_cos_estimator(a, 0, k, n, False)  # noqa: E731
    np.testing.assert_allclose(
        p["sal_m"], _first_crossing(f, 0.0, 0.6 * per) * 1e-6, rtol=0.1 * k**2
    )
    assert math.isnan(p["str"])  # along the grooves the ACF never falls to 0.2


def test_sal_in_metres_with_rectangular_pixels():
    # a lay along x sampled with dx = 6 dy: Sal is a length in m, not in pixels
    n, per = 256, 32
    k = 2 * np.pi / per
    z = 10e-9 * np.cos(k * np.arange(n))[:, None] * np.ones((1, 64))  # lay along x
    p = areal_parameters(Surface(z, 3e-6, 0.5e-6))
    f = lambda a, b: acf_cos_estimator(a, 0, k, n, False)  # noqa: E731
    np.testing.assert_allclose(
        p["sal_m"], _first_crossing(f, 0.0, 0.6 * per) * 0.5e-6, rtol=0.1 * k**2
    )


# ------------------------------------------------------------------ surfalize
@pytest.mark.parametrize(
    "shape,sigma,dx,dy",
    [((300, 400), (3, 6), 0.5e-6, 0.7e-6), ((256, 256), (5, 5), 1e-6, 1e-6)],
)
def test_random_surfaces_against_surfalize(shape, sigma, dx, dy):
    _check_against_surfalize(_gaussian_field(shape, sigma, seed=1, dx=dx, dy=dy))


VOID_FREE_REAL = [
    "newview_20x_mirau_mp8.1_metropro-1.dat",
    "newview_100x_mirau_mp8.1_05_C1S01.dat",
    "newview_100x_05_C1S01_EDITEDHEADER.asc",
    "st_x3p-2_mountainsmap.x3p",
]


@pytest.mark.parametrize("name", VOID_FREE_REAL)
def test_real_files_against_surfalize(zygo_dir, name):
    s = read_surface(zygo_dir / name)
    assert s.invalid_fraction == 0  # surfalize fills voids: void-free maps only
    _check_against_surfalize(s)


def test_real_file_sa_sq_reference_values(zygo_dir):
    # SOURCES.md: Sa / Sq from Gwyddion, SurfaceTopography and prysm
    p = areal_parameters(read_surface(zygo_dir / "st_x3p-2_mountainsmap.x3p"))
    np.testing.assert_allclose([p["sa_m"], p["sq_m"]], [61.9547e-9, 77.2803e-9], 1e-5)


def test_real_files_with_voids_give_finite_values(zygo_dir):
    s = read_surface(zygo_dir / "gpi_mp8.3.3_zygo_test.datx")  # 9 % voids
    p = areal_parameters(s)
    assert p["n_valid"] == np.isfinite(s.z).sum()
    for key in ("sa_m", "sdq", "sdr_percent", "sal_m", "sk_m", "spk_m", "svk_m"):
        assert np.isfinite(p[key]) and p[key] > 0, key
    un = areal_parameters(
        read_surface(zygo_dir / "mx_export_hdrfmt1_nolatres_20191018_flat01.dat")
    )
    assert all(math.isnan(un[k]) for k in ("sdq", "sdr_percent", "sal_m", "str"))
    assert np.isfinite(un["sk_m"])  # heights and material ratio need no pixel size


# ---------------------------------------------------------------- conventions
def test_height_parameters_leave_voids_out():
    s = _gaussian_field((64, 80), 2, seed=8)
    z = np.pad(s.z, 5, constant_values=np.nan)  # a void frame
    a, b = areal_parameters(s), areal_parameters(Surface(z, s.dx, s.dy))
    for key in ("sa_m", "sq_m", "sp_m", "sv_m", "ssk", "sku", "sdq", "sk_m", "spk_m"):
        np.testing.assert_allclose(b[key], a[key], rtol=RTOL_EXACT, err_msg=key)
    np.testing.assert_allclose(b["sdr_percent"], a["sdr_percent"], rtol=1e-9)


def test_form_and_cutoff_are_reported_and_applied():
    s = _gaussian_field((64, 64), 2, seed=9)
    tilt = s.replace(z=s.z + 1e-8 * np.arange(64)[None, :])
    mean = areal_parameters(tilt)
    plane = areal_parameters(tilt, form="plane")
    assert mean["form"] == "mean" and plane["form"] == "plane"
    # a 630 nm ramp (Sq 182 nm) against 20 nm of roughness
    assert mean["sq_m"] > 5 * plane["sq_m"]
    np.testing.assert_allclose(plane["sq_m"], areal_parameters(s, form="plane")["sq_m"])
    filt = areal_parameters(s, cutoff=8e-6)
    assert filt["cutoff_m"] == 8e-6 and filt["sq_m"] < areal_parameters(s)["sq_m"]
    assert mean["acf_threshold"] == 0.2 and mean["cutoff_m"] is None


@pytest.mark.parametrize(
    "kwargs,match",
    [
        ({"form": "sphere"}, "form must be 'mean'"),
        ({"acf_threshold": 1.2}, r"acf_threshold must lie in \(0, 1\)"),
        ({"cutoff": -1.0}, "cutoff"),
    ],
)
def test_bad_options(kwargs, match):
    with pytest.raises(ConfigError, match=match):
        areal_parameters(_gaussian_field((16, 16), 1, seed=0), **kwargs)


def test_not_a_surface_and_all_invalid():
    with pytest.raises(ConfigError, match="must be a Surface"):
        areal_parameters(np.zeros((4, 4)))
    with pytest.raises(ConfigError, match="no valid pixels"):
        areal_parameters(Surface(np.full((4, 4), np.nan), 1e-6, 1e-6))


def test_flat_and_uncalibrated_autocorrelation_refused():
    with pytest.raises(ConfigError, match="flat"):
        areal_autocorrelation(Surface(np.zeros((8, 8)), 1e-6, 1e-6))
    with pytest.raises(ConfigError, match="calibrated"):
        areal_autocorrelation(Surface(np.ones((8, 8)), None, None))
    flat = areal_parameters(Surface(np.zeros((8, 8)), 1e-6, 1e-6))
    assert flat["sq_m"] == 0 and math.isnan(flat["sal_m"]) and math.isnan(flat["ssk"])
