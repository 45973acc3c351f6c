"""Design surfaces: hand-computed sags, finite-difference gradients, the hexagonal
lattice against a hand-built list, and the refusal of implausible values."""

from __future__ import annotations

import math

import numpy as np
import pytest

import servosurf.toolpath as tp
from servosurf.errors import ConfigError

S3 = math.sqrt(3.0)


def fd_gradient(design, x, y, step=1e-9):
    """Central differences of ``design.sag`` (the kernel's own sag)."""
    gx = (design.sag(x + step, y) - design.sag(x - step, y)) / (2 * step)
    gy = (design.sag(x, y + step) - design.sag(x, y - step)) / (2 * step)
    return gx, gy


# ------------------------------------------------------------ hand values
def test_sphere_hand_values_and_sign_convention():
    bowl = tp.Sphere(radius=10e-3)
    dome = tp.Sphere(radius=-10e-3)
    # 10 mm - sqrt(99 mm^2) = 50.12563 um at r = 1 mm, up for a bowl
    want = 10e-3 - math.sqrt(99e-6)
    assert float(bowl.sag(1e-3, 0.0)) == pytest.approx(want, rel=1e-12)
    assert float(bowl.sag(0.6e-3, 0.8e-3)) == pytest.approx(want, rel=1e-12)
    assert float(dome.sag(0.0, 1e-3)) == pytest.approx(-want, rel=1e-12)
    assert float(bowl.sag(0.0, 0.0)) == 0.0
    # slope r / sqrt(R^2 - r^2) = 1 / sqrt(99), rising outward for the bowl
    gx, gy = bowl.gradient(1e-3, 0.0)
    assert float(gx) == pytest.approx(1 / math.sqrt(99), rel=1e-12)
    assert float(gy) == 0.0
    assert float(dome.gradient(0.0, 1e-3)[1]) == pytest.approx(-1 / math.sqrt(99),
                                                               rel=1e-12)
    assert math.isnan(float(bowl.sag(11e-3, 0.0)))  # beyond the sphere


def test_asphere_hand_values():
    # paraboloid (k = -1): z = c r^2 / 2 exactly; plus A4 r^4 and A6 r^6
    a = tp.EvenAsphere(curvature=1 / 20e-3, conic=-1.0, coefficients=(1e3, 2e8))
    r = 1e-3
    want = r**2 / (2 * 20e-3) + 1e3 * r**4 + 2e8 * r**6  # 25 um + 1 nm + 0.2 nm
    assert float(a.sag(0.6e-3, -0.8e-3)) == pytest.approx(want, rel=1e-13)
    slope = r / 20e-3 + 4e3 * r**3 + 12e8 * r**5
    gx, gy = a.gradient(r, 0.0)
    assert float(gx) == pytest.approx(slope, rel=1e-12)
    # k = 0 is the sphere
    s = tp.EvenAsphere(curvature=1 / 10e-3)
    assert float(s.sag(1e-3, 0.0)) == pytest.approx(10e-3 - math.sqrt(99e-6),
                                                     rel=1e-12)
    flat = tp.EvenAsphere(curvature=0.0)
    assert float(flat.sag(1e-3, 2e-3)) == 0.0


def test_biconic_hand_values():
    # cylinder: no curvature along y
    cyl = tp.Biconic(curvature_x=1 / 10e-3, curvature_y=0.0)
    assert float(cyl.sag(1e-3, 5e-3)) == pytest.approx(10e-3 - math.sqrt(99e-6),
                                                       rel=1e-12)
    # two paraboloid sections (kx = ky = -1): z = (cx x^2 + cy y^2) / 2
    par = tp.Biconic(curvature_x=50.0, curvature_y=-20.0, conic_x=-1.0, conic_y=-1.0)
    assert float(par.sag(2e-3, 1e-3)) == pytest.approx(
        (50 * 4e-6 - 20 * 1e-6) / 2, rel=1e-13)
    gx, gy = par.gradient(2e-3, 1e-3)
    assert (float(gx), float(gy)) == pytest.approx((50 * 2e-3, -20 * 1e-3),
                                                   rel=1e-12)


def test_xy_polynomial_hand_values():
    # z = 1 um (x/rn) + 3 um (x/rn)^2 + 2 um (y/rn)^2 + 5 um (x/rn)(y/rn)
    p = tp.XYPolynomial(coefficients=((0.0, 0.0, 2e-6), (1e-6, 5e-6), (3e-6,)),
                        norm_radius=1e-3)
    x, y = 0.5e-3, 2e-3
    assert float(p.sag(x, y)) == pytest.approx(
        1e-6 * 0.5 + 3e-6 * 0.25 + 2e-6 * 4 + 5e-6 * 1.0, rel=1e-13)
    gx, gy = p.gradient(x, y)
    assert float(gx) == pytest.approx((1e-6 + 6e-6 * 0.5 + 5e-6 * 2) / 1e-3,
                                      rel=1e-13)
    assert float(gy) == pytest.approx((4e-6 * 2 + 5e-6 * 0.5) / 1e-3, rel=1e-13)
    assert p.coefficients == ((0.0, 0.0, 2e-6), (1e-6, 5e-6, 0.0), (3e-6, 0.0, 0.0))


def test_sinusoidal_grid_hand_values():
    g = tp.SinusoidalGrid(amplitude=2e-6, period_x=100e-6, period_y=40e-6)
    assert float(g.sag(25e-6, 10e-6)) == pytest.approx(2e-6, rel=1e-14)
    assert float(g.sag(12.5e-6, 10e-6)) == pytest.approx(2e-6 / math.sqrt(2),
                                                         rel=1e-13)
    assert float(g.sag(50e-6, 10e-6)) == pytest.approx(0.0, abs=1e-20)
    gx, gy = g.gradient(0.0, 10e-6)  # d/dx at a node of x: A 2 pi / Lx
    assert float(gx) == pytest.approx(2e-6 * 2 * math.pi / 100e-6, rel=1e-13)
    assert float(gy) == pytest.approx(0.0, abs=1e-18)


def test_lenslet_array_hand_values():
    R, d = 1e-3, 150e-6
    lens = tp.LensletArray(layout="rectangular", pitch=200e-6, lens_radius=R,
                           aperture=d)
    sag = R - math.sqrt(R**2 - (d / 2) ** 2)  # 2.8165 um
    assert lens.lens_sag == pytest.approx(sag, rel=1e-12)
    assert float(lens.sag(0.0, 0.0)) == pytest.approx(-sag, rel=1e-12)
    assert float(lens.sag(400e-6, -200e-6)) == pytest.approx(-sag, rel=1e-12)
    # 30 um from a centre: the cap minus its rim height
    want = (R - math.sqrt(R**2 - 30e-6**2)) - sag
    assert float(lens.sag(200e-6 + 18e-6, 24e-6)) == pytest.approx(want, rel=1e-12)
    assert float(lens.sag(100e-6, 100e-6)) == 0.0  # the flat between lenses
    gx, _ = lens.gradient(30e-6, 0.0)
    assert float(gx) == pytest.approx(30e-6 / math.sqrt(R**2 - 30e-6**2), rel=1e-12)
    # given by sag instead of aperture; convex bumps stand up
    bump = tp.LensletArray(layout="hexagonal", pitch=200e-6, lens_radius=-R,
                           lens_sag=sag)
    assert bump.aperture == pytest.approx(d, rel=1e-9)
    assert float(bump.sag(0.0, 0.0)) == pytest.approx(sag, rel=1e-12)


def test_hexagonal_centres_against_a_hand_built_list():
    p = 100e-6
    h = p * S3 / 2
    lens = tp.LensletArray(layout="hexagonal", pitch=p, lens_radius=1e-3,
                           aperture=80e-6)
    want = np.array([
        (-50e-6, -h), (50e-6, -h),
        (-100e-6, 0.0), (0.0, 0.0), (100e-6, 0.0),
        (-50e-6, h), (50e-6, h),
    ])
    got = lens.lens_centres(-120e-6, 120e-6, -100e-6, 100e-6)
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-18)
    # with an offset, rows two apart line up, odd rows sit half a pitch over
    off = tp.LensletArray(layout="hexagonal", pitch=p, lens_radius=1e-3,
                          aperture=80e-6, offset_x=10e-6, offset_y=-20e-6)
    got = off.lens_centres(0.0, 200e-6, 0.0, 250e-6)
    want = np.array([
        (60e-6, h - 20e-6), (160e-6, h - 20e-6),
        (10e-6, 2 * h - 20e-6), (110e-6, 2 * h - 20e-6),
        (60e-6, 3 * h - 20e-6), (160e-6, 3 * h - 20e-6),  # y = 239.8 um
    ])
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-18)
    # the sag is lowest at each hand-built centre, and flat there
    c = np.array([(-50e-6, -h), (0.0, 0.0), (100e-6, 0.0), (50e-6, h)])
    np.testing.assert_allclose(lens.sag(c[:, 0], c[:, 1]), -lens.lens_sag, rtol=1e-12)
    gx, gy = lens.gradient(c[:, 0], c[:, 1])
    np.testing.assert_allclose(np.hypot(gx, gy), 0.0, atol=1e-15)
    # six neighbours at one pitch
    d = np.hypot(*(lens.lens_centres(-250e-6, 250e-6, -250e-6, 250e-6).T))
    assert np.count_nonzero(np.isclose(d, p, rtol=1e-12)) == 6


def test_rectangular_centres():
    lens = tp.LensletArray(layout="rectangular", pitch=100e-6, pitch_y=60e-6,
                           lens_radius=1e-3, aperture=50e-6, offset_x=5e-6)
    got = lens.lens_centres(0.0, 210e-6, -10e-6, 70e-6)
    want = np.array([(5e-6, 0.0), (105e-6, 0.0), (205e-6, 0.0),
                     (5e-6, 60e-6), (105e-6, 60e-6), (205e-6, 60e-6)])
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-18)


# ------------------------------------------------------------- gradients
GRADIENT_CASES = [
    tp.Sphere(radius=-4e-3),
    tp.EvenAsphere(curvature=1 / 6e-3, conic=-2.0, coefficients=(-400.0, 1e8)),
    tp.Biconic(curvature_x=1 / 5e-3, curvature_y=1 / 9e-3, conic_x=0.4),
    tp.XYPolynomial(coefficients=((1e-6, -2e-6), (0.0, 3e-6, 1e-6), (2e-6,)),
                    norm_radius=1e-3),
    tp.SinusoidalGrid(amplitude=-0.5e-6, period_x=80e-6, period_y=60e-6),
    tp.LensletArray(layout="hexagonal", pitch=150e-6, lens_radius=0.6e-3,
                    aperture=140e-6),
]


@pytest.mark.parametrize("design", GRADIENT_CASES,
                         ids=lambda d: type(d).__name__)
def test_gradient_against_finite_differences(design):
    rng = np.random.default_rng(7)  # positions only
    x, y = rng.uniform(-1.5e-3, 1.5e-3, (2, 300))
    gx, gy = design.gradient(x, y)
    fx, fy = fd_gradient(design, x, y)
    np.testing.assert_allclose(gx, fx, rtol=0, atol=1e-7)
    np.testing.assert_allclose(gy, fy, rtol=0, atol=1e-7)


# ----------------------------------------------------- mapping and refusals
def test_design_from_mapping_and_aliases():
    s = tp.design_from_mapping({"type": "sphere", "curvature": -50.0})
    assert s == tp.Sphere(radius=-0.02)
    a = tp.design_from_mapping({"type": "asphere", "radius": 0.01, "conic": -1,
                                "coefficients": [1e3]})
    assert a.curvature == pytest.approx(100.0) and a.coefficients == (1e3,)
    b = tp.design_from_mapping({"type": "biconic", "radius-x": 0.01,
                                "curvature-y": 0.0})
    assert b.curvature_x == pytest.approx(100.0)
    m = tp.design_from_mapping({"type": "lenslet-array", "layout": "hexagonal",
                                "pitch": 1e-4, "lens-radius": 1e-3, "sag": 1e-6})
    assert m.lens_sag == 1e-6
    x = tp.design_from_mapping({"type": "xy-polynomial",
                                "coefficients": [[0, 0, 1e-6], [0, 2e-6]]})
    assert x.coefficients[1] == (0.0, 2e-6, 0.0)
    assert tp.Sphere(radius=-0.02).to_dict() == {"type": "sphere", "radius_m": -0.02}


@pytest.mark.parametrize(("table", "match"), [
    ({"type": "spere", "radius": 1e-2}, "Did you mean: 'sphere'"),
    ({"radius": 1e-2}, "surface.type must be one of"),
    ({"type": "sphere", "radius": 1e-2, "curvature": 100}, "not both"),
    ({"type": "sphere", "raduis": 1e-2}, "Did you mean: surface.radius"),
    ({"type": "sphere", "radius": 20.0}, "meant in mm write 0.02"),
    ({"type": "sphere", "radius": 0.0}, "non-zero"),
    ({"type": "asphere", "curvature": 1e7}, "radius >= 1 um"),
    ({"type": "sinusoidal-grid", "amplitude": 2.0, "period-x": 1e-4,
      "period-y": 1e-4}, "in um write 2e-06"),
    ({"type": "sinusoidal-grid", "amplitude": 1e-6, "period-x": 100,
      "period-y": 1e-4}, "surface.period-x"),
    ({"type": "xy-polynomial", "coefficients": [[0, 5]]}, "0.05 m"),
    ({"type": "lenslet-array", "layout": "square", "pitch": 1e-4,
      "lens-radius": 1e-3, "aperture": 1e-4}, "surface.layout must be one of"),
    ({"type": "lenslet-array", "layout": "hexagonal", "pitch": 150,
      "lens-radius": 1e-3, "aperture": 1e-4}, "surface.pitch = 150 m"),
    ({"type": "lenslet-array", "layout": "hexagonal", "pitch": 1e-4,
      "lens-radius": 1e-3, "aperture": 3e-3}, "exceeds the lens diameter"),
    ({"type": "lenslet-array", "layout": "hexagonal", "pitch": 1e-4,
      "lens-radius": 1e-3}, "either aperture"),
    ({"type": "lenslet-array", "layout": "hexagonal", "pitch": 1e-4,
      "lens-radius": 1e-3, "lens-sag": 2e-3}, "exceeds |lens-radius|"),
    ({"type": "lenslet-array", "layout": "hexagonal", "pitch": 1e-4,
      "pitch-y": 1e-4, "lens-radius": 1e-3, "lens-sag": 1e-6}, "rectangular"),
])
def test_bad_designs_are_refused(table, match):
    with pytest.raises(ConfigError, match=match):
        tp.design_from_mapping(table)
