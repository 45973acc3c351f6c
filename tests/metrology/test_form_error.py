"""Nominal lenslet shape, form error against it, and centre-profile extraction."""

from __future__ import annotations

import functools
import math

import numpy as np
import pytest

from servosurf.errors import ConfigError
from servosurf.metrology import (
    Surface,
    form_error_profile,
    lenslet_centre_profile,
    nominal_lenslet_profile,
    nominal_lenslet_surface,
)

# The seed paper's 5 um lenslet (Table 2, section 5.3): 10 um zero-to-peak servo
# amplitude, 100 Hz, 5 um depth (cuts one third of a period), 0.5 mm tool radius.
LENS = dict(
    amplitude=10e-6, frequency=100.0, speed=42.3e-3, depth=5e-6, tool_radius=0.5e-3
)
#: Tolerance on a lateral position, in m (a tenth of the 0.2 um sample step).
POSITION_ATOL = 0.02e-6
#: Tolerance on a sub-pixel centre, in pixels (brief: < 0.1 pixel).
CENTRE_ATOL_PX = 0.1


def test_profile_depth_chord_and_top():
    x = np.linspace(-150e-6, 150e-6, 3001)
    z = nominal_lenslet_profile(x, **LENS)
    top = LENS["depth"] - LENS["amplitude"]
    np.testing.assert_allclose(z.max(), top, rtol=0, atol=1e-15)  # 1 fm
    np.testing.assert_allclose(z.max() - z.min(), 5e-6, rtol=1e-9)
    # depth = A/2: the tool cuts while |phase| < pi/3, a chord of v / (3 f)
    cut = x[z < top]
    chord = cut[-1] - cut[0]
    np.testing.assert_allclose(chord, LENS["speed"] / (3 * 100.0), atol=0.2e-6)
    np.testing.assert_allclose(chord, 141e-6, rtol=1e-2)


def test_profile_curvature_along_cut_is_v2_over_a_omega2():
    x = np.linspace(-1e-6, 1e-6, 101)
    z = nominal_lenslet_profile(x, **LENS)
    c2 = np.polyfit(x, z, 2)[0]
    radius = 1 / (2 * c2)
    expected = LENS["speed"] ** 2 / (LENS["amplitude"] * (2 * np.pi * 100.0) ** 2)
    np.testing.assert_allclose(radius, expected, rtol=1e-4)
    np.testing.assert_allclose(radius, 0.45e-3, rtol=0.02)


def test_tool_radius_only_shapes_the_cross_direction():
    x = np.linspace(-100e-6, 100e-6, 401)
    a = nominal_lenslet_profile(x, **LENS)
    b = nominal_lenslet_profile(x, **{**LENS, "tool_radius": 2e-3})
    np.testing.assert_array_equal(a, b)
    dr = 30e-6
    c = nominal_lenslet_profile(x, **LENS, cross_offset=dr)
    r = LENS["tool_radius"]
    lift = r - math.sqrt(r * r - dr * dr)
    top = LENS["depth"] - LENS["amplitude"]
    np.testing.assert_allclose(np.minimum(a + lift, top), c, rtol=0, atol=1e-18)
    beyond = nominal_lenslet_profile(x, **LENS, cross_offset=0.6e-3)
    np.testing.assert_allclose(beyond, top, rtol=0, atol=0)


def test_surface_rows_and_columns():
    x = np.linspace(-90e-6, 90e-6, 181)
    y = np.linspace(-90e-6, 90e-6, 181)
    zmap = nominal_lenslet_surface(x, y, **LENS)
    np.testing.assert_allclose(zmap[90], nominal_lenslet_profile(x, **LENS), atol=1e-18)
    r = LENS["tool_radius"]
    col = np.minimum(
        -LENS["amplitude"] + r - np.sqrt(r * r - y**2),
        LENS["depth"] - LENS["amplitude"],
    )
    np.testing.assert_allclose(zmap[:, 90], col, rtol=0, atol=1e-18)


def _nominal(path_amplitude=None, x=None):
    return nominal_lenslet_profile(x, **LENS, path_amplitude=path_amplitude)


def _reference(x, amplitude):
    return nominal_lenslet_profile(x, **LENS, path_amplitude=amplitude)


def test_form_error_recovers_a_lagging_error_with_the_air_cut_reference():
    x = np.arange(-100e-6, 100e-6, 0.2e-6)
    bump = 200e-9 * np.exp(-0.5 * ((x - 20e-6) / 8e-6) ** 2)  # lags 20 um
    measured = _reference(x, 5.2e-6 * 2) + bump + 3e-7  # air-cut overshoot, piston
    res = form_error_profile(x, measured, _reference, reference_amplitude=10.4e-6)
    mask = np.isfinite(res["error"])
    expected = bump[mask] - bump[mask].mean()
    np.testing.assert_allclose(res["error"][mask], expected, rtol=0, atol=1e-15)
    np.testing.assert_allclose(res["max_error_position_m"], 20e-6, atol=0.2e-6)
    np.testing.assert_allclose(res["x_deepest_m"], 0.0, atol=POSITION_ATOL)
    assert res["max_error_m"] > 0
    assert res["reference_amplitude_m"] == pytest.approx(10.4e-6)
    np.testing.assert_allclose(res["piston_m"], 3e-7 + bump[mask].mean(), atol=1e-15)


def test_reference_amplitude_matters():
    # Cut with a 4 % air-cut overshoot (the paper's 5.2 / 5 um): against the nominal
    # amplitude the form error is the 0.4 um deeper bowl; against the air-cut
    # amplitude it vanishes.
    x = np.arange(-100e-6, 100e-6, 0.2e-6)
    measured = _reference(x, 10.4e-6)
    air = form_error_profile(x, measured, _reference, reference_amplitude=10.4e-6)
    nom = form_error_profile(x, measured, _reference, reference_amplitude=10e-6)
    assert air["max_abs_error_m"] < 1e-15
    assert nom["pv_error_m"] > 150e-9


def test_lag_sign_follows_the_cutting_direction():
    x = np.arange(-100e-6, 100e-6, 0.2e-6)
    nominal = _nominal(x=x)
    bump = 100e-9 * np.exp(-0.5 * ((x - 15e-6) / 5e-6) ** 2)
    fwd = form_error_profile(x, nominal + bump, nominal)
    back = form_error_profile(x, nominal + bump, nominal, cutting_direction=-1)
    assert fwd["max_error_position_m"] == pytest.approx(15e-6, abs=0.2e-6)
    assert back["max_error_position_m"] == pytest.approx(-15e-6, abs=0.2e-6)


def test_lateral_shift_alignment():
    x = np.arange(-100e-6, 100e-6, 0.2e-6)
    measured = nominal_lenslet_profile(x, **LENS, centre=3.1e-6)
    res = form_error_profile(x, measured, _reference, max_shift=10e-6)
    np.testing.assert_allclose(res["shift_m"], 3.1e-6, atol=POSITION_ATOL)
    assert res["max_abs_error_m"] < 1e-9
    res_arr = form_error_profile(x, measured, _nominal(x=x), max_shift=10e-6)
    np.testing.assert_allclose(res_arr["shift_m"], 3.1e-6, atol=POSITION_ATOL)


def test_cut_only_false_covers_the_whole_profile_and_nan_is_ignored():
    x = np.arange(-100e-6, 100e-6, 0.5e-6)
    nominal = _nominal(x=x)
    measured = nominal.copy()
    measured[10:20] = np.nan
    res = form_error_profile(x, measured, nominal, cut_only=False)
    assert np.isnan(res["error"][10:20]).all()
    assert np.isfinite(res["error"][:10]).all()
    np.testing.assert_allclose(res["max_abs_error_m"], 0.0, atol=1e-18)


def test_form_error_argument_errors():
    x = np.arange(-100e-6, 100e-6, 0.5e-6)
    nominal = _nominal(x=x)
    with pytest.raises(ConfigError, match="callable"):
        form_error_profile(x, nominal, nominal, reference_amplitude=5.2e-6)
    with pytest.raises(ConfigError, match="shape"):
        form_error_profile(x, nominal[:-1], nominal)
    with pytest.raises(ConfigError, match="cutting_direction"):
        form_error_profile(x, nominal, nominal, cutting_direction=0)
    with pytest.raises(ConfigError, match="increasing"):
        form_error_profile(x[::-1], nominal, nominal)
    with pytest.raises(ConfigError):
        nominal_lenslet_profile(x, **{**LENS, "depth": -1.0})


@pytest.mark.parametrize("centre_px", [(0.0, 0.0), (0.37, -0.26), (-0.45, 0.41)])
def test_centre_profile_subpixel_centre(centre_px):
    rng = np.random.default_rng(1234)  # noise of 2 nm on a 5 um deep lens
    d = 1e-6
    x = (np.arange(201) - 100) * d
    y = (np.arange(181) - 90) * d
    cy, cx = centre_px[0] * d, centre_px[1] * d
    z = nominal_lenslet_surface(x, y, **LENS, centre=(cx, cy))
    z = z + rng.normal(0.0, 2e-9, z.shape)
    s = Surface(z, d, d, x0=x[0], y0=y[0])
    prof = lenslet_centre_profile(s)
    meta = prof.metadata["lenslet_centre"]
    assert abs(meta["x_m"] - cx) < CENTRE_ATOL_PX * d
    assert abs(meta["y_m"] - cy) < CENTRE_ATOL_PX * d
    assert prof.dx == d and prof.x0 == x[0]
    assert prof.z.size == x.size
    # the profile through the centre matches the nominal centre line
    expected = nominal_lenslet_profile(x, **LENS, centre=cx)
    np.testing.assert_allclose(prof.z, expected, rtol=0, atol=10e-9)  # 10 nm
    res = form_error_profile(prof.x, prof.z, expected)
    assert res["max_abs_error_m"] < 10e-9
    col = lenslet_centre_profile(s, direction="y")
    assert col.z.size == y.size and col.x0 == y[0]


def test_centre_profile_errors():
    with pytest.raises(ConfigError, match="direction"):
        lenslet_centre_profile(Surface(np.zeros((5, 5)), 1e-6, 1e-6), direction="z")
    with pytest.raises(ConfigError):
        lenslet_centre_profile(Surface(np.full((5, 5), np.nan), 1e-6, 1e-6))


def test_partial_reference_works_as_documented():
    x = np.arange(-100e-6, 100e-6, 0.5e-6)
    ref = functools.partial(
        lambda x, a, **kw: nominal_lenslet_profile(x, path_amplitude=a, **kw), **LENS
    )
    res = form_error_profile(x, ref(x, 10.4e-6), ref, reference_amplitude=10.4e-6)
    assert res["max_abs_error_m"] < 1e-15
