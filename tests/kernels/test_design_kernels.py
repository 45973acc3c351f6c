"""Design-surface kernels (sag, gradient, compensated tip) against plain numpy."""

from __future__ import annotations

import math

import numpy as np
import pytest

import servosurf.toolpath as tp

try:  # tests/ on sys.path (rootdir-relative packages)
    from reference import design as ref
except ImportError:  # tests/ itself is a package
    from tests.reference import design as ref

DESIGNS = {
    "sphere-concave": tp.Sphere(radius=10e-3),
    "sphere-convex": tp.Sphere(radius=-3e-3),
    "asphere": tp.EvenAsphere(curvature=1 / 8e-3, conic=-0.6,
                              coefficients=(600.0, -1.5e8)),
    "biconic": tp.Biconic(curvature_x=1 / 5e-3, curvature_y=-1 / 8e-3, conic_x=-0.5,
                          conic_y=0.3),
    "xy-polynomial": tp.XYPolynomial(
        coefficients=((0.0, 1e-6, 2e-6), (-1e-6, 3e-6), (4e-6,)), norm_radius=2e-3),
    "sinusoid": tp.SinusoidalGrid(amplitude=1e-6, period_x=100e-6, period_y=140e-6),
    "lenses-rect": tp.LensletArray(layout="rectangular", pitch=120e-6,
                                   pitch_y=100e-6, lens_radius=0.4e-3,
                                   aperture=90e-6, offset_x=7e-6, offset_y=-3e-6),
    "lenses-hex": tp.LensletArray(layout="hexagonal", pitch=150e-6, lens_radius=1e-3,
                                  aperture=170e-6, offset_x=-11e-6, offset_y=5e-6),
    "lenses-hex-convex": tp.LensletArray(layout="hexagonal", pitch=100e-6,
                                         lens_radius=-0.8e-3, lens_sag=1e-6),
}
#: Designs whose sections keep d2S/drho2 < 1 / R for R = 0.2 mm (single contact).
SINGLE_CONTACT = [k for k in DESIGNS if k != "lenses-hex-convex"]
NOSE = 0.2e-3


def random_points(n, seed, half=2e-3):
    rng = np.random.default_rng(seed)  # the points only; results do not depend on it
    return rng.uniform(-half, half, n), rng.uniform(-half, half, n)


@pytest.mark.parametrize("name", list(DESIGNS))
def test_sag_matches_numpy_formula(name):
    d = DESIGNS[name]
    x, y = random_points(400, 1)
    np.testing.assert_allclose(d.sag(x, y), ref.sag(d, x, y), rtol=ref.RTOL_SAG,
                               atol=ref.ATOL_SAG)


@pytest.mark.parametrize("name", list(DESIGNS))
def test_gradient_matches_finite_differences(name):
    d = DESIGNS[name]
    x, y = random_points(400, 2)
    gx, gy = d.gradient(x, y)
    fx, fy = ref.gradient(d, x, y)
    np.testing.assert_allclose(gx, fx, rtol=0, atol=ref.ATOL_SLOPE_FD)
    np.testing.assert_allclose(gy, fy, rtol=0, atol=ref.ATOL_SLOPE_FD)


def test_sag_broadcasts_and_keeps_shape():
    d = DESIGNS["biconic"]
    x = np.linspace(-1e-3, 1e-3, 5)
    y = np.linspace(-1e-3, 1e-3, 3)
    z = d.sag(x[None, :], y[:, None])
    assert z.shape == (3, 5)
    np.testing.assert_allclose(z, ref.sag(d, x[None, :], y[:, None]),
                               rtol=ref.RTOL_SAG, atol=ref.ATOL_SAG)


@pytest.mark.parametrize("solver", ["brent", "scan"])
@pytest.mark.parametrize("name", SINGLE_CONTACT)
def test_compensated_tip_matches_brute_force(name, solver):
    d = DESIGNS[name]
    rng = np.random.default_rng(3)  # the positions only
    r = rng.uniform(0.0, 1.5e-3, 6)
    r[0] = 0.05e-3  # the arc reaches across the spindle axis
    th = rng.uniform(0, 2 * math.pi, 6)
    z, u = tp.nose_compensated_tip(d, r, th, nose_radius=NOSE, solver=solver)
    want = [ref.tip_height(d, ri, ti, NOSE, math.radians(60)) for ri, ti in
            zip(r, th, strict=True)]
    np.testing.assert_allclose(z, want, rtol=0, atol=ref.ATOL_TIP)
    assert np.all(np.abs(u) <= NOSE * math.sin(math.radians(60)))


def test_scan_finds_both_contacts_of_concave_corners():
    """Convex bumps on a flat: the nose rests on a bump and on the flat at once;
    along a run of radii the better of two near-equal contacts changes sides, and
    the grid's best point is sometimes on the wrong one (near r = 1.152 mm here, the
    flat at u = 0 against the bump 7.8 um inward, 6 nm higher)."""
    d = DESIGNS["lenses-hex-convex"]
    r = np.concatenate([np.linspace(0.3e-3, 0.6e-3, 7),
                        np.linspace(1.145e-3, 1.16e-3, 31)])
    th = np.where(r < 1e-3, 0.3, 3.002671620610689)
    z, _ = tp.nose_compensated_tip(d, r, th, nose_radius=NOSE, solver="scan")
    want = [ref.tip_height(d, ri, ti, NOSE, math.radians(60)) for ri, ti in
            zip(r, th, strict=True)]
    np.testing.assert_allclose(z, want, rtol=0, atol=ref.ATOL_TIP)


def test_decentred_design_and_zero_nose():
    d = DESIGNS["asphere"]
    r = np.array([0.2e-3, 1.1e-3])
    th = np.array([0.4, 2.5])
    z, _ = tp.nose_compensated_tip(d, r, th, nose_radius=NOSE, center=(3e-4, -2e-4),
                                   solver="brent")
    want = [ref.tip_height(d, ri, ti, NOSE, math.radians(60), center=(3e-4, -2e-4))
            for ri, ti in zip(r, th, strict=True)]
    np.testing.assert_allclose(z, want, rtol=0, atol=ref.ATOL_TIP)
    z0, u0 = tp.nose_compensated_tip(d, r, th, nose_radius=0.0)
    np.testing.assert_allclose(z0, ref.sag(d, r * np.cos(th), r * np.sin(th)),
                               rtol=ref.RTOL_SAG, atol=ref.ATOL_SAG)
    assert not np.any(u0)


def test_scan_picks_the_best_of_many_contacts():
    """A grid sharper than the nose: along the diagonal the section is the pure
    sinusoid A (1 - cos(sqrt(2) k rho)) / 2, so F has a local maximum under every
    crest within the arc, of heights falling off only with the arc's parabola; the
    best two are often within the grid's sampling error of each other and the
    refined runner-up must be compared too."""
    d = tp.SinusoidalGrid(amplitude=1e-6, period_x=40e-6, period_y=40e-6)
    rng = np.random.default_rng(13)  # positions only
    r = rng.uniform(0.2e-3, 1.5e-3, 60)
    th = math.pi / 4 + rng.integers(0, 4, 60) * math.pi / 2
    z, _ = tp.nose_compensated_tip(d, r, th, nose_radius=NOSE, solver="scan")
    want = [ref.tip_height(d, ri, ti, NOSE, math.radians(60)) for ri, ti in
            zip(r, th, strict=True)]
    np.testing.assert_allclose(z, want, rtol=0, atol=ref.ATOL_TIP)
