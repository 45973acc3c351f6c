"""Roughness of the centre profile of an NC run against the closed-form scallop."""

from __future__ import annotations

import io

import numpy as np
import pytest

import servosurf.toolpath as tp
from servosurf.errors import ConfigError
from servosurf.report import analyse_nc, centre_profile
from servosurf.simulation import simulate


def scallop_ra(f: float, R: float) -> float:
    """Ra of a train of circular arcs of radius R and spacing f (numerical mean of
    |p - mean p| over one period, 200001 points), in m."""
    u = np.linspace(-f / 2, f / 2, 200001)
    p = R - np.sqrt(R * R - u * u)
    return float(np.mean(np.abs(p - p.mean())))


def facing_run(f_mm=0.010, r0_mm=0.6, R=0.5e-3, z_mm=-0.0005, pitch=0.5e-6):
    n_rev = r0_mm / f_mm
    c = np.arange(int(round(n_rev * 360 / 2.0)) + 1) * 2.0
    x = r0_mm - f_mm * c / 360.0
    text = "\n".join(f"C{a:g} X{b:.9f} Z{z_mm:g}" for a, b in zip(c, x, strict=True))
    spec = tp.nc_spec(tp.read_nc_program(io.StringIO(text)), block_time=1e-3,
                      tool=tp.Tool(nose_radius=R))
    spec = tp.ToolpathSpec(kind="nc", path=spec.path, tool=spec.tool,
                           field=tp.band_field(spec.path.r_max, pitch=pitch))
    return simulate(spec, parts=("kinematic",))


def test_centre_profile_roughness_of_a_facing_cut():
    f, R = 10e-6, 0.5e-3
    res = facing_run(f_mm=f / 1e-3, R=R)
    out = analyse_nc(res)
    rough = out["roughness"]
    expected = scallop_ra(f, R)  # 6.4 nm: Ra <= 20 nm -> lambda_c = 0.08 mm
    assert rough["cutoff_m"] == 0.08e-3 and rough["cutoff_rule"] == "ISO 4288"
    # ~100 feed marks are evaluated: a partial one and the half-period shift of the
    # spiral across the axis bias Ra by at most 1 / 100
    assert rough["ra_m"] == pytest.approx(expected, rel=0.01)
    assert rough["rsm_m"] == pytest.approx(f, rel=0.01)
    # evaluation length: the band (-0.6..0.6 mm) less one cut-off at each end
    assert rough["evaluation_length_m"] == pytest.approx(1.2e-3 - 0.16e-3, abs=2e-6)
    assert out["toolpath"]["feed_per_rev_mean_m"] == pytest.approx(f, rel=1e-6)
    # a shorter evaluated profile, centred on the axis
    short = analyse_nc(res, profile_length=0.4e-3)["roughness"]
    assert short["profile_length_m"] == pytest.approx(0.4e-3, abs=1e-6)
    assert short["ra_m"] == pytest.approx(expected, rel=0.02)


def test_form_is_removed_on_a_curved_part():
    # the same feed on a concave sphere (R_part = 5 mm): the nose centres lie on a
    # sphere of radius Rp - R, so the cusps between neighbouring passes sit
    # f^2/8 (1/R + 1/(Rp - R)) below the design: scallops of radius
    # R_eff = 1 / (1/R + 1/(Rp - R)) on the form the analysis removes
    f, R, Rp = 10e-6, 0.5e-3, 5e-3
    c = np.arange(0, 60 * 360 + 1, 2.0)
    x = 0.6 - 0.010 * c / 360
    z = (x * 1e-3) ** 2 / (2 * (Rp - R)) / 1e-3  # tip path of the offset sphere, mm
    text = "\n".join(f"C{a:g} X{b:.9f} Z{d:.12f}" for a, b, d in zip(c, x, z,
                                                                       strict=True))
    spec = tp.nc_spec(tp.read_nc_program(io.StringIO(text)), block_time=1e-3,
                      tool=tp.Tool(nose_radius=R))
    res = simulate(spec, parts=("kinematic",))
    prof = centre_profile(res.surface, spec.path)
    assert np.nanmax(np.abs(prof["residual"])) < 50e-9  # form gone: scallops only
    rough = analyse_nc(res)["roughness"]
    r_eff = 1.0 / (1.0 / R + 1.0 / (Rp - R))
    assert rough["ra_m"] == pytest.approx(scallop_ra(f, r_eff), rel=0.01)


def test_non_quadratic_form_is_removed():
    # the tip path carries a long-wave form a quadratic cannot remove (0.1 um,
    # 0.4 mm wavelength, slope <= 1.6e-3: the nose envelope follows the tip path to
    # R s^2 / 2 < 1 nm); the commanded tip height at |x| removes it
    f, R = 10e-6, 0.5e-3
    c = np.arange(0, 60 * 360 + 1, 2.0)
    x = 0.6 - 0.010 * c / 360
    z = 1e-4 * np.cos(2 * np.pi * x / 0.4)  # mm
    text = "\n".join(f"C{a:g} X{b:.9f} Z{d:.12f}" for a, b, d in zip(c, x, z,
                                                                       strict=True))
    spec = tp.nc_spec(tp.read_nc_program(io.StringIO(text)), block_time=1e-3,
                      tool=tp.Tool(nose_radius=R))
    res = simulate(spec, parts=("kinematic",))
    prof = centre_profile(res.surface, spec.path)
    assert np.nanmax(np.abs(prof["residual"])) < 50e-9
    # the form's curvature (<= 25 /m) changes the local scallop radius by <= 1.2 %
    rough = analyse_nc(res)["roughness"]
    assert rough["ra_m"] == pytest.approx(scallop_ra(f, R), rel=0.02)


def test_centre_profile_needs_the_axis_and_enough_length():
    res = facing_run(f_mm=0.010, r0_mm=0.06)
    out = analyse_nc(res)
    # a 0.12 mm band: too short for the smallest ISO 4288 cut-off (0.08 mm, x2)
    assert out["roughness"]["ra_m"] is None
    assert "shorter than twice" in out["roughness"]["not_evaluated"]
    off = res.surface.replace(y0=5e-6)
    with pytest.raises(ConfigError, match="does not cross the spindle axis"):
        centre_profile(off, res.spec.path)
