"""Form error against a design: known residuals after piston, tilt and sphere."""

from __future__ import annotations

import numpy as np
import pytest

import servosurf.toolpath as tp
from servosurf.errors import ConfigError
from servosurf.metrology import Surface, form_error_against_design

#: Rounding of heights of up to 25 um (sag) in the subtraction, in m (1 fm).
ATOL_FORM = 1e-15

DESIGN = tp.Sphere(radius=20e-3)
N, PITCH = 129, 1e-6  # 128 um square, pixel centres from -64 to 64 um
X0 = 1e-3 - 64e-6  # centred on x = 1 mm


def grid():
    x = X0 + PITCH * np.arange(N)
    y = -64e-6 + PITCH * np.arange(N)
    return x[None, :], y[:, None]


def ripple(amp=3e-9, period=32e-6):
    """A residual orthogonal to piston and tilt: whole periods of an even cosine
    about the grid centre (128 um = 4 periods)."""
    x, y = grid()
    return amp * np.cos(2 * np.pi * (x - 1e-3) / period) + 0.0 * y


def surface_of(z):
    return Surface(z, PITCH, PITCH, x0=X0, y0=-64e-6)


def test_piston_and_tilt_are_removed_and_reported():
    x, y = grid()
    g = ripple()
    z = DESIGN.sag(x, y) + 5e-6 + 2e-5 * (x - 1e-3) - 3e-5 * y + g
    fe = form_error_against_design(surface_of(z), DESIGN)
    # the cosine sampled 32 px per period on 129 px: peaks at both ends and the
    # centre, valleys in between, so PV = 2 A; RMS of 4 whole periods plus one end
    # sample: sqrt((sum cos^2) / N)
    c = np.cos(2 * np.pi * np.arange(-64, 65) / 32)
    # the fit removes the (tiny) mean and x-slope of the 129 samples as well
    a = np.column_stack([np.ones(N), np.arange(-64, 65)])
    resid = c - a @ np.linalg.lstsq(a, c, rcond=None)[0]
    assert fe.pv == pytest.approx(3e-9 * (resid.max() - resid.min()), rel=1e-9)
    assert fe.rms == pytest.approx(3e-9 * np.sqrt(np.mean(resid**2)), rel=1e-9)
    assert fe.tilt_y == pytest.approx(-3e-5, rel=1e-9)
    assert fe.tilt_x == pytest.approx(2e-5, abs=1e-9 * 2e-5 + 1e-12)
    assert fe.removed == ("piston", "tilt")
    assert fe.n_valid == N * N
    np.testing.assert_allclose(fe.error.z, 3e-9 * np.broadcast_to(resid, (N, N)),
                               rtol=0, atol=ATOL_FORM)


def test_nothing_removed_keeps_the_offset():
    x, y = grid()
    z = DESIGN.sag(x, y) + 7e-9
    fe = form_error_against_design(surface_of(z), DESIGN, remove=())
    assert fe.pv == pytest.approx(0.0, abs=ATOL_FORM)
    assert fe.rms == pytest.approx(7e-9, abs=ATOL_FORM)
    fe = form_error_against_design(surface_of(z), DESIGN, remove=("piston",))
    assert fe.rms == pytest.approx(0.0, abs=ATOL_FORM)
    assert fe.piston == pytest.approx(7e-9, abs=ATOL_FORM)


def test_best_fit_sphere_removes_a_radius_error():
    """A map cut with radius 19 mm against the 20 mm design: the difference is
    piston, tilt and power of curvature dc = 1/19 mm - 1/20 mm = 2.63 1/m about the
    field centre (plus c^3 x0^2 = 0.8 % from the fourth-order term 1 mm off axis),
    dc rho^2 / 2 = 10.8 nm at the field's corners. It vanishes after the best-fit
    sphere; the ripple (PV 2 A) remains."""
    x, y = grid()
    other = tp.Sphere(radius=19e-3)
    g = ripple(amp=1e-9)
    z = other.sag(x, y) + g
    fe = form_error_against_design(surface_of(z), DESIGN, best_fit_sphere=True)
    dc = 1 / 19e-3 - 1 / 20e-3
    assert fe.pv > 0.9 * dc * 2 * 64e-6**2 / 2
    # expected: the ripple minus its least-squares part in 1, x, y, x^2 + y^2 (the
    # sphere fit removes a little of the cosine too)
    xi, yi = np.meshgrid(np.arange(-64, 65) * PITCH, np.arange(-64, 65) * PITCH)
    a = np.column_stack([np.ones(N * N), xi.ravel(), yi.ravel(),
                         (xi**2 + yi**2).ravel()])
    gr = g.ravel() + 0 * xi.ravel()
    want = gr - a @ np.linalg.lstsq(a, gr, rcond=None)[0]
    assert fe.pv_bfs == pytest.approx(want.max() - want.min(), rel=0.02)
    assert fe.rms_bfs == pytest.approx(np.sqrt(np.mean(want**2)), rel=0.02)
    # curvature: twice the x^2 + y^2 coefficient of the whole error (paraboloid
    # and sphere differ by c^3 rho^4 / 8 < 1e-15 m here), near dc
    e = (z - DESIGN.sag(x, y)).ravel()
    k_want = 2 * np.linalg.lstsq(a, e, rcond=None)[0][3]
    assert fe.bfs_curvature == pytest.approx(k_want, rel=1e-4)
    assert fe.bfs_curvature == pytest.approx(dc, rel=0.05)
    assert fe.error_bfs.metadata["form_error"]["removed"] == ["piston", "tilt",
                                                              "sphere"]


def test_design_given_as_array_callable_surface_or_path():
    x, y = grid()
    z = DESIGN.sag(x, y) + ripple()
    s = surface_of(z)
    ref = form_error_against_design(s, DESIGN)
    for design in (DESIGN.sag(x, y) + 0 * x, lambda a, b: DESIGN.sag(a, b),
                   surface_of(DESIGN.sag(x, y) + 1e-6)):
        fe = form_error_against_design(s, design)
        assert fe.pv == pytest.approx(ref.pv, abs=ATOL_FORM)
    path = tp.DesignToolpath(design=DESIGN, r_start=1.2e-3, r_end=0.8e-3,
                             feed_per_rev=5e-6)
    fe = form_error_against_design(s.replace(z=z + path.datum_z), path)
    assert fe.pv == pytest.approx(ref.pv, abs=ATOL_FORM)


def test_invalid_pixels_and_mask_are_skipped():
    x, y = grid()
    z = DESIGN.sag(x, y) + ripple()
    z[:10] = np.nan
    z[50, 50] += 1e-6  # a spike, masked out below
    mask = np.ones_like(z, dtype=bool)
    mask[50, 50] = False
    fe = form_error_against_design(surface_of(z), DESIGN, mask=mask)
    assert fe.n_valid == N * N - 10 * N - 1
    assert fe.pv < 7e-9
    assert np.isnan(fe.error.z[:10]).all() and np.isnan(fe.error.z[50, 50])


def test_bad_arguments():
    s = surface_of(np.zeros((N, N)))
    with pytest.raises(ConfigError, match="unknown term 'power'"):
        form_error_against_design(s, DESIGN, remove=("piston", "power"))
    with pytest.raises(ConfigError, match="shape"):
        form_error_against_design(s, np.zeros((3, 3)))
    with pytest.raises(ConfigError, match="fewer than 4 valid pixels"):
        form_error_against_design(s.replace(z=np.full((N, N), np.nan)), DESIGN)
    with pytest.raises(ConfigError, match="calibrated"):
        form_error_against_design(Surface(np.zeros((4, 4)), None, None), DESIGN)
    with pytest.raises(ConfigError, match="design must be"):
        form_error_against_design(s, "sphere")
    fe = form_error_against_design(s, np.zeros((N, N)))
    assert fe.to_dict()["form_error_pv_m"] == 0.0
