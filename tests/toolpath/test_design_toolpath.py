"""The nose-compensated design toolpath: closed forms of the compensation and of the
scallop planner, and the kinematic sweep reproducing the design to within the
scallop height (sphere, hexagonal lenslet array, flat).

The kinematic tests sweep the sampled path directly with ``servosurf.toolpath.sweep``
(no servo, force or vibration): the surface is then the lower envelope of the nose
arc along the commanded path, which must lie on or above the design by at most the
kinematic scallop height.
"""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np
import pytest

import servosurf.toolpath as tp
from servosurf.errors import ConfigError

try:  # tests/ on sys.path (rootdir-relative packages)
    from reference import RTOL_KINEMATIC
    from reference.design import ATOL_CLOSED_FORM
except ImportError:  # tests/ itself is a package
    from tests.reference import RTOL_KINEMATIC
    from tests.reference.design import ATOL_CLOSED_FORM

TOOLPATHS = Path(__file__).resolve().parents[2] / "toolpaths"
NOSE = 0.5e-3
TOOL = tp.Tool(nose_radius=NOSE)
#: No gouging: the swept surface is never below the design by more than rounding
#: of the envelope and design evaluation (1 pm).
ATOL_GOUGE = 1e-12


def sphere_sag(radius, r):
    """Sag of a sphere of signed radius (m) at r (m), written out by hand."""
    return math.copysign(1.0, radius) * (abs(radius) - np.sqrt(radius**2 - r**2))


def sphere_tip_path(rs, nose, r):
    """Closed-form tip path of a sphere of signed radius ``rs`` cut by a nose.

    The nose centre stays ``nose`` away from the sphere along its normal, i.e. on
    the concentric sphere of radius ``|rs| - nose`` (concave, nose inside the bowl)
    or ``|rs| + nose`` (convex); the tip is ``nose`` below the centre. The tip
    height at radius r is therefore the sag of the sphere of signed radius
    ``rs - nose`` with the same vertex: at r = 0 the centre is at ``nose`` and the
    tip at 0.
    """
    return sphere_sag(rs - nose, r)


def flat_design():
    return tp.EvenAsphere(curvature=0.0)


def path_of(design, **kw):
    args = dict(design=design, r_start=1.6e-3, r_end=1.4e-3, spindle_speed=10.0,
                compensation_radius=NOSE)
    args.update(kw)
    if "scallop_height" not in kw and "feed_per_rev" not in kw:
        args["feed_per_rev"] = 20e-6
    return tp.DesignToolpath(**args)


# --------------------------------------------------------------- compensation
@pytest.mark.parametrize("solver", ["brent", "scan"])
@pytest.mark.parametrize("rs", [10e-3, -10e-3, 2e-3, -1.5e-3])
def test_sphere_compensation_closed_form(rs, solver):
    rng = np.random.default_rng(11)  # angles only (the sphere is axisymmetric)
    r = np.linspace(0.0, 0.5e-3, 11)
    th = rng.uniform(0, 2 * math.pi, r.size)
    z, u = tp.nose_compensated_tip(tp.Sphere(radius=rs), r, th, nose_radius=NOSE,
                                   solver=solver)
    np.testing.assert_allclose(z, sphere_tip_path(rs, NOSE, r), rtol=0,
                               atol=ATOL_CLOSED_FORM)
    # the contact lies on the ray from the centre of curvature: u = R sin(phi),
    # sin(phi) = r / (rs - R)
    np.testing.assert_allclose(u, NOSE * r / (rs - NOSE), rtol=0, atol=1e-10)


@pytest.mark.parametrize("solver", ["brent", "scan"])
def test_inclined_plane_compensation_closed_form(solver):
    """z = s0 x: the section slope is s = s0 cos(theta); the tip sits
    ``s r + R (sqrt(1 + s^2) - 1)`` high, the contact ``R s / sqrt(1 + s^2)`` out."""
    s0 = 0.2
    plane = tp.XYPolynomial(coefficients=((0.0,), (s0 * 1e-3,)), norm_radius=1e-3)
    r = np.array([0.0, 0.3e-3, 1e-3, 2e-3])
    th = np.array([0.0, 1.0, 2.5, 4.0])
    s = s0 * np.cos(th)
    z, u = tp.nose_compensated_tip(plane, r, th, nose_radius=NOSE, solver=solver)
    np.testing.assert_allclose(z, s * r + NOSE * (np.sqrt(1 + s * s) - 1), rtol=0,
                               atol=ATOL_CLOSED_FORM)
    np.testing.assert_allclose(u, NOSE * s / np.sqrt(1 + s * s), rtol=0, atol=1e-10)


def test_path_places_the_design_at_its_datum():
    rs = -10e-3
    p = path_of(tp.Sphere(radius=rs), r_start=1.5e-3, r_end=0.5e-3,
                depth_of_cut=4e-6)
    # the highest design point over the tip radii is at r_end (a dome)
    assert p.datum_z == pytest.approx(-(4e-6 + sphere_sag(rs, 0.5e-3)), rel=1e-3)
    r = np.linspace(0.5e-3, 1.5e-3, 7)
    th = np.linspace(0, 6, 7)
    np.testing.assert_allclose(p.tip_height(r, th),
                               sphere_tip_path(rs, NOSE, r) + p.datum_z, rtol=0,
                               atol=ATOL_CLOSED_FORM)
    x, y = r * np.cos(th), r * np.sin(th)
    np.testing.assert_allclose(p.design_height(x, y), sphere_sag(rs, r) + p.datum_z,
                               rtol=0, atol=ATOL_CLOSED_FORM)
    assert p.solver == "brent"
    assert p.max_depth >= -(p.tip_height(r, th).min())


# -------------------------------------------------------------------- planner
def test_scallop_planner_on_a_flat():
    """h = f^2 / (8 R): a 10 nm target gives sqrt(8 h R) = 6.3246 um per rev."""
    h = 10e-9
    p = path_of(flat_design(), scallop_height=h, r_start=2e-3, r_end=0.0)
    f = math.sqrt(8 * h * NOSE)
    assert f == pytest.approx(6.3246e-6, rel=1e-4)
    r = np.linspace(0.0, 2e-3, 50)
    np.testing.assert_allclose(p.feed_at_radius(r), f, rtol=1e-9)
    assert p.duration == pytest.approx(2e-3 / (f * 10.0), rel=1e-9)
    t = np.linspace(0, p.duration, 9)
    np.testing.assert_allclose(p.radius_at(t), 2e-3 - f * 10.0 * t, rtol=0,
                               atol=1e-15)


@pytest.mark.parametrize("rs", [20e-3, -20e-3])
def test_scallop_planner_on_a_sphere(rs):
    """R_eff = R (1 - R / Rs) cos(phi)^3, sin(phi) = r / (Rs - R) at tip radius r."""
    h = 20e-9
    p = path_of(tp.Sphere(radius=rs), scallop_height=h, r_start=3e-3, r_end=0.0)
    r = np.linspace(0.0, 3e-3, 31)
    sin_phi = r / (rs - NOSE)
    cos3 = (1 - sin_phi**2) ** 1.5
    f = np.sqrt(8 * h * NOSE * (1 - NOSE / rs) * cos3)
    # segments of 3 um take the smaller feed of their ends
    np.testing.assert_allclose(p.feed_at_radius(r), f, rtol=1e-3)
    assert np.all(p.feed_at_radius(r) <= f * (1 + 1e-6))


# --------------------------------------------------------- kinematic sweeps
def radial_strip(center_x, pitch=20e-9, n=2001):
    return tp.Field(pitch_x=pitch, pitch_y=pitch, nx=n, ny=3, center_x=center_x)


def residual(path, field, fs=200e3):
    sp = tp.sample(path, field=field, tool=TOOL, fs=fs)
    z = tp.sweep(sp, TOOL, field).z
    x, y = field.coords()
    return z - path.design_height(x[None, :], y[:, None])


def test_flat_planned_path_reaches_the_target_scallop():
    h = 100e-9
    p = path_of(flat_design(), scallop_height=h)
    f = math.sqrt(8 * h * NOSE)  # 20 um: the strip holds two cusps
    field = radial_strip(1.5e-3, pitch=f / 1000, n=2001)
    res = residual(p, field)
    assert res.min() >= -ATOL_GOUGE
    assert res.max() == pytest.approx(h, rel=RTOL_KINEMATIC)


@pytest.mark.parametrize("rs", [10e-3, -10e-3])
def test_sphere_reproduced_within_the_scallop(rs):
    """Across the feed: the cusp height is f^2 / (8 R_eff), R_eff = R (1 - R / Rs)
    cos(phi)^3; the sphere is never undercut."""
    f = 20e-6
    # the contact sits R r / (rs - R) from the tip: start and end 0.2 mm away
    p = path_of(tp.Sphere(radius=rs), feed_per_rev=f, r_start=1.7e-3, r_end=1.3e-3)
    field = radial_strip(1.5e-3)
    res = residual(p, field)
    x = field.coords()[0]
    sin_phi = x / (rs - NOSE)  # tip radius ~ contact radius here (to 5 %)
    h = f**2 / (8 * NOSE * (1 - NOSE / rs) * (1 - sin_phi**2) ** 1.5)
    assert res.min() >= -ATOL_GOUGE
    assert res.max() <= h.max() * (1 + RTOL_KINEMATIC)
    assert res.max() >= h.min() * (1 - RTOL_KINEMATIC)
    # a 2-D patch against the design evaluated on the grid
    patch = tp.Field(pitch_x=0.1e-6, pitch_y=0.1e-6, nx=201, ny=101, center_x=1.45e-3,
                     center_y=0.05e-3)
    res2 = residual(p, patch)
    assert res2.min() >= -ATOL_GOUGE
    assert res2.max() <= h.max() * (1 + RTOL_KINEMATIC)
    assert res2.max() >= 0.9 * h.min()  # 0.1 um pixels sample the cusps to 5 %


def test_hexagonal_lenslet_array_reproduced_within_the_scallop():
    """Concave lenslets (R_l = 1 mm) on a flat: scallop f^2 / (8 R) on the flat and
    f^2 / (8 R (1 - R kappa) cos(phi)^3) in the lenses, kappa ~ 1 / R_l."""
    rl, ap, pitch = 1e-3, 150e-6, 150e-6
    lenses = tp.LensletArray(layout="hexagonal", pitch=pitch, lens_radius=rl,
                             aperture=ap)
    f, fs = 20e-6, 1e6
    p = tp.DesignToolpath(design=lenses, r_start=1.3e-3, r_end=0.8e-3,
                          spindle_speed=5.0, feed_per_rev=f, compensation_radius=NOSE)
    assert p.solver == "brent"  # lens radius > nose radius: one contact
    cx = 7 * pitch  # a lens centre on the +x axis
    field = tp.Field(pitch_x=0.5e-6, pitch_y=0.5e-6, nx=321, ny=321, center_x=cx)
    res = residual(p, field, fs=fs)
    x, y = field.coords()
    X, Y = np.meshgrid(x, y)
    # lens centres of the hexagonal lattice near the field, by hand
    h = pitch * math.sqrt(3) / 2
    centres = [((i + 0.5 * (j % 2)) * pitch, j * h) for i in range(4, 11)
               for j in range(-2, 3)]
    d = np.min([np.hypot(X - a, Y - b) for a, b in centres], axis=0)
    a = ap / 2
    h_flat = f**2 / (8 * NOSE)
    # worst lens section: offset e = a from the lens centre (radius sqrt(Rl^2 -
    # a^2)) at the slope of 0.9 a
    kappa = 1 / math.sqrt(rl**2 - a**2)
    s = 0.9 * a / math.sqrt(rl**2 - (0.9 * a) ** 2)
    h_lens_max = f**2 / (8 * NOSE * (1 - NOSE * kappa)) * (1 + s * s) ** 1.5
    h_lens = f**2 / (8 * NOSE * (1 - NOSE / rl))
    inner = d < 0.9 * a
    flat = d > a + 2e-6
    rim = ~inner & ~flat
    # pixel pitch 0.5 um samples a cusp of slope f / (2 R) to within 5 nm
    sampling = f / (2 * NOSE) * 0.25e-6
    assert res[inner].min() >= -ATOL_GOUGE
    assert res[inner].max() <= h_lens_max * (1 + RTOL_KINEMATIC)
    assert res[inner].max() >= h_lens - sampling
    assert res[flat].min() >= -ATOL_GOUGE
    assert res[flat].max() <= h_flat * (1 + RTOL_KINEMATIC)
    assert res[flat].max() >= h_flat - sampling
    # at the rims the path has a kink along the cut; linear interpolation between
    # samples dv = v / fs apart cuts at most dv * (rim slope) / 2 below it
    dv = 2 * math.pi * (cx + 0.2e-3) * 5.0 / fs
    rim_slope = a / math.sqrt(rl**2 - a**2)
    assert res[rim].min() >= -dv * rim_slope / 2
    assert res[rim].max() <= h_lens_max * (1 + RTOL_KINEMATIC)


# ----------------------------------------------------------------- sampling
@pytest.mark.parametrize("planned", [False, True])
def test_numba_sampling_matches_the_path_formulas(planned):
    lenses = tp.LensletArray(layout="rectangular", pitch=120e-6, lens_radius=0.8e-3,
                             lens_sag=2e-6)
    kw = {"scallop_height": 30e-9} if planned else {"feed_per_rev": 8e-6}
    p = tp.DesignToolpath(design=lenses, r_start=0.5e-3, r_end=0.3e-3,
                          spindle_speed=50.0, compensation_radius=NOSE, **kw)
    sp = tp.sample(p, fs=20e3)
    np.testing.assert_array_equal(sp.index, np.arange(sp.n))
    assert sp.n == math.floor(p.duration * 20e3 * (1 + 1e-15)) + 1
    np.testing.assert_allclose(sp.theta, p.theta_at(sp.t), rtol=1e-14, atol=0)
    np.testing.assert_allclose(sp.r, p.radius_at(sp.t), rtol=0, atol=1e-17)
    np.testing.assert_allclose(sp.z, p.z_at(sp.t), rtol=0, atol=1e-17)
    if planned:
        assert np.ptp(p.feed_at(sp.t)) > 0  # lenses and flat want other feeds
    sub = tp.sample(p, fs=20e3, t_window=(0.2 * p.duration, 0.3 * p.duration))
    idx = sub.index
    np.testing.assert_array_equal(sub.z, sp.z[idx])


# ---------------------------------------------------------- files, refusals
@pytest.mark.parametrize("name", ["sphere", "lenslet_array_hex"])
def test_shipped_design_toolpaths_load(name):
    spec = tp.load_toolpath(TOOLPATHS / f"{name}.toml")
    assert spec.kind == "surface"
    assert isinstance(spec.path, tp.DesignToolpath)
    assert spec.path.compensation_radius == spec.tool.nose_radius
    assert spec.path.solver == "brent"
    rmin, rmax = spec.field.radial_range()
    assert spec.path.r_end < rmin and rmax < spec.path.r_start


def _toml(tmp_path, text):
    p = tmp_path / "t.toml"
    p.write_text(text)
    return p


BASE = """
kind = "surface"
[surface]
type = "sphere"
radius = 0.02
[spiral]
r-start = 2e-3
feed-per-rev = 5e-6
"""


def test_toml_defaults_and_aliases(tmp_path):
    spec = tp.load_toolpath(_toml(tmp_path, BASE + "spindle-speed-rpm = 600\n"
                                  "[tool]\nnose-radius = 0.2e-3\n"))
    p = spec.path
    assert p.spindle_speed == pytest.approx(10.0)
    assert p.compensation_radius == 0.2e-3 and p.r_end == 0.0
    assert p.arc_half_angle == pytest.approx(math.radians(60))
    spec = tp.load_toolpath(_toml(tmp_path, BASE + "compensation-radius = 0.0\n"))
    assert spec.path.solver == "none"


@pytest.mark.parametrize(("extra", "match"), [
    ("scallop-height = 1e-8\n", "not both"),
    ("r-ned = 0.0\n", "Did you mean: spiral.r-end"),
    ("spindle-speed = 1000\n", "give rpm as spindle-speed-rpm"),
    ("depth-of-cut = 5\n", "in um write 5e-06"),
    ("[facing]\nfeed-per-rev = 1e-6\n", r"\[facing\] table given but kind"),
])
def test_toml_errors(tmp_path, extra, match):
    with pytest.raises(ConfigError, match=match):
        tp.load_toolpath(_toml(tmp_path, BASE + extra))


def test_surface_table_with_another_kind_is_refused(tmp_path):
    text = 'kind = "facing"\n[surface]\ntype = "sphere"\nradius = 0.02\n'
    with pytest.raises(ConfigError, match=r"\[surface\] table given but kind"):
        tp.load_toolpath(_toml(tmp_path, text))
    with pytest.raises(ConfigError, match="missing required key"):
        tp.load_toolpath(_toml(tmp_path, BASE.replace("r-start = 2e-3\n", "")))


def test_physically_impossible_paths_are_refused():
    with pytest.raises(ConfigError, match="concave radius of curvature 0.0004 m"):
        path_of(tp.Sphere(radius=0.4e-3), r_start=0.2e-3, r_end=0.0)
    with pytest.raises(ConfigError, match="nose radius below 0.0003 m"):
        path_of(tp.LensletArray(layout="hexagonal", pitch=1e-4, lens_radius=0.3e-3,
                                lens_sag=1e-6))
    with pytest.raises(ConfigError, match="radial slope reaches 68"):
        path_of(tp.Sphere(radius=1e-3), compensation_radius=0.05e-3,
                r_start=0.93e-3, r_end=0.5e-3)
    with pytest.raises(ConfigError, match="undefined at r"):
        path_of(tp.Sphere(radius=-2e-3), r_start=1.9e-3, r_end=1.0e-3)
    with pytest.raises(ConfigError, match="scallop-height needs a nose radius"):
        path_of(flat_design(), scallop_height=1e-8, compensation_radius=0.0)
    with pytest.raises(ConfigError, match="r-start = 2 m"):
        path_of(flat_design(), r_start=2.0)


def test_concave_corners_warn_and_use_the_scan():
    bumps = tp.LensletArray(layout="hexagonal", pitch=100e-6, lens_radius=-0.8e-3,
                            lens_sag=1e-6)
    with pytest.warns(tp.ToolpathWarning, match="concave curvature sharper than"):
        p = path_of(bumps)
    assert p.solver == "scan"
    with pytest.warns(tp.ToolpathWarning, match="concave curvature sharper than"):
        q = path_of(tp.SinusoidalGrid(amplitude=2e-6, period_x=60e-6,
                                      period_y=60e-6))
    assert q.solver == "scan"


def test_replace_rebuilds_the_plan():
    p = path_of(flat_design(), scallop_height=10e-9)
    q = dataclasses.replace(p, scallop_height=40e-9)
    assert q.feed_at_radius(1.5e-3) == pytest.approx(2 * p.feed_at_radius(1.5e-3),
                                                     rel=1e-9)
