"""compare for profiles: registration, masking, same filter on both sides, real data.

Oracles: a continuous seeded texture evaluated at known shifted and mirrored
positions; the closed-form offset of the Gaussian mean line of a parabola; the
independent reference values of ../shared/data/upm_sts/SOURCES.md.
"""

from __future__ import annotations

import json
import math
import subprocess
import sys

import numpy as np
import pytest

from servosurf.cli import main
from servosurf.errors import ConfigError
from servosurf.metrology import Profile, Surface
from servosurf.report import compare_profiles

#: Registration accuracy demanded, as a fraction of the sampling step.
SHIFT_TOL_STEPS = 0.1
#: Relative tolerance on the independent reference roughness values (as for the
#: NexView reference of tests/metrology/test_roughness.py).
REFERENCE_RTOL = 5e-3
DX = 0.5e-6  # m
WLI = "1022/1022-WLI-2D.csv"
CONTOUR = "1022/1022-contour.DAT"
#: The cut zone of the contour: the rim of the 1 mm aperture starts at x = +0.9915
#: and -1.0075 mm (part centre at -8 um); 1022-contour.DAT, inspected.
CUT_ZONE = (-0.99e-3, 0.99e-3)


def texture(seed: int):
    """Continuous seeded texture f(x) (m -> m): sines of 3 .. 50 um, 5 .. 10 nm."""
    rng = np.random.default_rng(seed)
    lam = np.exp(rng.uniform(np.log(3e-6), np.log(50e-6), 60))
    amp = 10e-9 * rng.uniform(0.5, 1.0, 60)
    ph = rng.uniform(0, 2 * np.pi, 60)

    def f(x):
        x = np.asarray(x, dtype=float)[..., None]
        return np.sum(amp * np.sin(2 * np.pi * x / lam + ph), axis=-1)

    return f


def _pair(seed=7, shift=0.3137e-3, mirrored=True):
    """Measured (0.9 mm, NaN ends) and simulated (2 mm) profiles of one texture."""
    f = texture(seed)
    xm = 20e-6 + DX * np.arange(1800)
    zm = f(xm)
    zm[:40] = np.nan
    zm[-25:] = np.nan
    xs = -1e-3 + DX * np.arange(4001)
    zs = f(-xs + shift) if mirrored else f(xs + shift)
    return Profile(zm, DX, x0=xm[0]), Profile(zs, DX, x0=xs[0])


# ---------------------------------------------------------------- synthetic
@pytest.mark.parametrize("mirrored", [True, False])
def test_registration_shift_and_mirror(mirrored):
    shift = 0.3137e-3
    m, s = _pair(shift=shift, mirrored=mirrored)
    res = compare_profiles(m, s, cutoff=0.08e-3)
    assert res.mirrored is mirrored
    assert abs(res.shift - shift) < SHIFT_TOL_STEPS * DX
    assert res.correlation > 0.99
    rm, rs = res.roughness["measured"], res.roughness["simulated"]
    for key in ("ra_m", "rq_m"):
        np.testing.assert_allclose(rs[key], rm[key], rtol=0.02)
    d = res.to_dict()
    assert d["mirrored"] is mirrored and d["shift_m"] == res.shift


def test_same_mask_cutoff_and_trimming_on_both_sides():
    m, s = _pair(mirrored=False)
    hole = s.z.copy()
    hole[2000:2100] = np.nan  # a gap in the simulated profile
    res = compare_profiles(m, Profile(hole, s.dx, x0=s.x0), cutoff=0.08e-3)
    # NaN ends of the measured profile dropped, the gap masked on both sides
    assert np.isfinite(res.measured.z[[0, -1]]).all()
    np.testing.assert_array_equal(np.isnan(res.measured.z), np.isnan(res.simulated.z))
    assert np.isnan(res.measured.z).sum() > 0
    rm, rs = res.roughness["measured"], res.roughness["simulated"]
    for key in ("cutoff_m", "trim_length_m", "evaluation_length_m", "ends_trimmed"):
        assert rm[key] == rs[key], key
    assert rm["trim_length_m"] == rm["cutoff_m"] == 0.08e-3  # one cut-off trimmed
    np.testing.assert_array_equal(
        np.isnan(res.measured_roughness.z), np.isnan(res.simulated_roughness.z)
    )


def test_iso4288_cutoff_is_chosen_once_for_both():
    # Ra ~ 0.1 um (ISO 4288 Table 1: 0.8 mm) on a 0.9 mm span: 0.25 mm admissible
    f = texture(3)
    xm = DX * np.arange(1800)
    m = Profile(12 * f(xm), DX)
    s = Profile(12 * f(xm), DX)
    res = compare_profiles(m, s)
    assert res.cutoff == 0.25e-3 and res.cutoff_rule == "ISO 4288"
    assert res.roughness["simulated"]["cutoff_m"] == 0.25e-3


def test_form_removal_takes_out_the_gaussian_bias_of_a_sag():
    # texture on an 11 mm sphere's sag: the Gaussian mean line of c x^2 lies
    # c sigma^2 above it (sigma = alpha lambda_c / sqrt(2 pi)), which Rq counts
    f = texture(5)
    x = -0.45e-3 + DX * np.arange(1800)
    c = 1.0 / (2 * 11e-3)
    flat = Profile(f(x), DX, x0=x[0])
    sag = Profile(f(x) + c * x**2, DX, x0=x[0])
    lc = 0.25e-3
    quad = compare_profiles(flat, sag, cutoff=lc, register=False)
    none = compare_profiles(flat, sag, cutoff=lc, register=False, form="none")
    rq_flat = quad.roughness["measured"]["rq_m"]
    np.testing.assert_allclose(quad.roughness["simulated"]["rq_m"], rq_flat, rtol=1e-3)
    sigma = math.sqrt(math.log(2) / math.pi) * lc / math.sqrt(2 * math.pi)
    offset = c * sigma**2  # about 100 nm
    rq_none = none.roughness["simulated"]["rq_m"]
    np.testing.assert_allclose(math.sqrt(rq_none**2 - rq_flat**2), offset, rtol=0.02)


def test_map_gives_its_centre_line_and_one_row_map_is_a_profile():
    f = texture(9)
    x = DX * np.arange(1500)
    rows = np.stack([f(x + 40e-6 * k) for k in range(5)])  # row 2 is f(x + 80 um)
    sim = Surface(rows, DX, DX, y0=-2 * DX)
    meas = Surface(f(x + 80e-6)[None, :], DX, DX)  # a one-row map
    res = compare_profiles(meas, sim, cutoff=0.08e-3, mirror=False)
    assert res.info["line"]["simulated"] == {"axis": "x", "y_m": 0.0, "row": 2}
    assert abs(res.shift) < SHIFT_TOL_STEPS * DX and res.correlation > 0.999


def test_errors():
    m, s = _pair()
    with pytest.raises(ConfigError, match="form must be one of"):
        compare_profiles(m, s, form="cubic")
    with pytest.raises(ConfigError, match=r"x range .* holds 0 sample"):
        compare_profiles(m, s, x_range=(5e-3, 6e-3))
    far = Profile(s.z, s.dx, x0=1.0)
    with pytest.raises(ConfigError, match="do not overlap"):
        compare_profiles(m, far, register=False, cutoff=0.08e-3)


# ------------------------------------------------------------------ real data
def test_wli_reference_values(upm_dir):
    from servosurf.io import read_profile

    wli = read_profile(upm_dir / WLI)
    contour = read_profile(upm_dir / CONTOUR)
    res = compare_profiles(wli, contour)  # ISO 4288 choice on the measured side
    m = res.roughness["measured"]
    assert res.cutoff == 0.25e-3 and res.trim_length == 0.25e-3
    # SOURCES.md: Ra 106.0, Rq 123.0, Rz 400.8 nm (lambda_c 0.25 mm, ends trimmed
    # by one cut-off), independent of servosurf
    np.testing.assert_allclose(m["ra_m"], 106.0e-9, rtol=REFERENCE_RTOL)
    np.testing.assert_allclose(m["rq_m"], 123.0e-9, rtol=REFERENCE_RTOL)
    np.testing.assert_allclose(m["rz_m"], 400.8e-9, rtol=REFERENCE_RTOL)
    assert np.isfinite(res.correlation)


def test_formtracer_reference_value_through_the_cli(upm_dir, capsys):
    # SOURCES.md: the contour of the same part gives Ra 107.1 nm
    rc = main(["profile", str(upm_dir / CONTOUR), "--cutoff", "2.5e-4",
               "--x-range", str(CUT_ZONE[0]), str(CUT_ZONE[1]), "--json"])
    assert rc == 0
    out = json.loads(capsys.readouterr().out)
    np.testing.assert_allclose(out["ra_m"], 107.1e-9, rtol=REFERENCE_RTOL)
    assert out["x_range_m"] == list(CUT_ZONE)


def test_real_vs_real_cli(upm_dir, tmp_path, capsys):
    rc = main(["compare", str(upm_dir / WLI), "--simulated", str(upm_dir / CONTOUR),
               "--labels", "WLI", "Formtracer", "--out", str(tmp_path / "c")])
    assert rc == 0
    text = capsys.readouterr().out
    assert "Ra [nm]" in text and "RSm [um]" in text and "WLI" in text
    out = json.loads((tmp_path / "c" / "compare.json").read_text())
    for key in ("measured_ra_m", "simulated_ra_m", "measured_rsm_m",
                "simulated_rsm_m", "correlation", "shift_m", "cutoff_m",
                "trim_length_m", "mirrored"):
        assert key in out, key
    np.testing.assert_allclose(out["measured_ra_m"], 106.0e-9, rtol=REFERENCE_RTOL)
    for name in ("profiles.png", "spectra.png"):
        assert (tmp_path / "c" / name).stat().st_size > 0


# ------------------------------------------------------------------------ CLI
def _mx_csv(path, profile: Profile):
    """An Mx profile export: X, Y in um, missing heights empty."""
    lines = ["X ,Y ,Slice"]
    for x, z in zip(profile.x, profile.z, strict=True):
        zt = "" if np.isnan(z) else repr(float(z) * 1e6)
        lines.append(f"{float(x) * 1e6!r},{zt},Slice 1")
    path.write_text("\n".join(lines) + "\n")
    return path


def test_cli_profile_against_one_row_map(tmp_path, capsys):
    from servosurf.io import write_surface

    m, s = _pair(mirrored=True)
    meas = _mx_csv(tmp_path / "m.csv", Profile(m.z, m.dx, x0=m.x0 + 1e-3))
    write_surface(Surface(s.z[None, :], s.dx, s.dx, x0=s.x0), tmp_path / "s.x3p")
    rc = main(["compare", str(meas), "--simulated", str(tmp_path / "s.x3p"),
               "--cutoff", "8e-5", "--out", str(tmp_path / "o"), "--json"])
    assert rc == 0
    out = json.loads(capsys.readouterr().out)
    assert out["kind"] == "profile" and out["mirrored"] is True
    assert abs(out["shift_m"] - (0.3137e-3 + 1e-3)) < SHIFT_TOL_STEPS * DX
    assert out["correlation"] > 0.99
    assert out["cutoff_m"] == 8e-5 and out["trim_length_m"] == 8e-5


def test_cli_one_row_map_measured_no_traceback(tmp_path):
    from servosurf.io import write_surface

    m, s = _pair(mirrored=False)
    write_surface(Surface(m.z[None, :], m.dx, m.dx, x0=m.x0), tmp_path / "m.datx")
    write_surface(Surface(np.tile(s.z, (3, 1)), s.dx, s.dx, x0=s.x0),
                  tmp_path / "s.datx")
    proc = subprocess.run(
        [sys.executable, "-m", "servosurf", "-q", "compare", str(tmp_path / "m.datx"),
         "--simulated", str(tmp_path / "s.datx"), "--cutoff", "8e-5", "--out",
         str(tmp_path / "o")],
        capture_output=True, text=True, timeout=300,
    )
    assert proc.returncode == 0, proc.stderr
    assert "Traceback" not in proc.stderr
    assert "correlation" in proc.stdout


def test_cli_profile_flags_on_two_maps_are_an_error(tmp_path, capsys):
    from servosurf.io import write_surface

    rng = np.random.default_rng(1)  # any heights
    write_surface(Surface(rng.normal(0, 1e-8, (20, 20)), 1e-6, 1e-6),
                  tmp_path / "a.x3p")
    rc = main(["compare", str(tmp_path / "a.x3p"), "--simulated",
               str(tmp_path / "a.x3p"), "--x-range", "0", "1e-5",
               "--out", str(tmp_path / "o")])
    assert rc == 1
    err = capsys.readouterr().err
    assert "--x-range apply to profiles" in err and "\n" == err[-1]
    assert err.count("\n") == 1
