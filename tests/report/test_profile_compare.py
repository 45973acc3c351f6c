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
        [sys.executable, "-m", "servosurf", "compare", str(tmp_path / "m.datx"),
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


# ------------------------------------------------------ split at the spindle axis
#: The simulated line through the spindle axis (x = 0): the side x < 0 lies half a
#: turn away, its texture displaced by HALF_REV along the radius.
HALF_REV = 60e-6
SIM_META = {"simulation": {"toolpath_kind": "nc"}}


def _band(f, *, meta=True, x_min=-1e-3, n=4001):
    """A one-row band map through the axis: f(r) at azimuth 0, f(r + HALF_REV) at pi."""
    xs = x_min + DX * np.arange(n)
    zs = np.where(xs >= 0, f(xs), f(-xs + HALF_REV))
    return Surface(zs[None, :], DX, DX, x0=float(xs[0]),
                   metadata=dict(SIM_META) if meta else {})


def _through_centre(f, axis, delta, x0, n, *, reverse=False):
    """A measured line through the axis (at ``axis`` on it) at another azimuth.

    Both sides are displaced inward by ``delta`` from the simulated line, so in
    the measured frame x_m = x_s + axis + delta below the axis and x_m = x_s + axis
    - delta above it. ``reverse``: measured from the other end (positions -u).
    """
    u = x0 + DX * np.arange(n)
    r = u - axis
    z = np.where(r >= 0, f(r + delta), f(-r + HALF_REV + delta))
    if reverse:
        return Profile(z[::-1].copy(), DX, x0=-float(u[-1]))
    return Profile(z, DX, x0=float(u[0]))


@pytest.mark.parametrize("reverse", [False, True])
def test_split_registration_recovers_the_axis_and_opposite_half_shifts(reverse):
    f = texture(11)
    axis, delta = 0.4137e-3, 5.3e-6
    meas = _through_centre(f, axis, delta, 20e-6, 1800, reverse=reverse)
    band = _band(f)
    res = compare_profiles(meas, band, cutoff=0.08e-3)
    d = res.to_dict()
    assert d["split_at_axis"] is True and d["split_skipped"] is None
    a = -axis if reverse else axis  # the axis in the measured file's frame
    # below the axis x_m = +-x_s + a + delta, above it a - delta (either
    # orientation: a line through the centre read backwards is the line half a
    # turn away, and fits just as well)
    assert abs(d["half_shifts_m"]["below"] - (a + delta)) < SHIFT_TOL_STEPS * DX
    assert abs(d["half_shifts_m"]["above"] - (a - delta)) < SHIFT_TOL_STEPS * DX
    assert abs(d["axis_position_m"] - a) < SHIFT_TOL_STEPS * DX
    assert d["shift_m"] == d["axis_position_m"]
    assert abs(abs(d["half_offset_m"]) - delta) < SHIFT_TOL_STEPS * DX
    assert res.correlation > 0.99
    assert min(d["half_correlations"].values()) > 0.99
    for key in ("ra_m", "rq_m", "rsm_m"):
        np.testing.assert_allclose(d[f"simulated_{key}"], d[f"measured_{key}"],
                                   rtol=0.01)
    # one shift for the whole profile aligns at best one half
    single = compare_profiles(meas, band, cutoff=0.08e-3, split=False)
    assert single.to_dict()["split_at_axis"] is False
    assert single.correlation < 0.8


def spiral_grooves(theta, r0=0.65e-3, p0=29e-6):
    """Radii (m) of the grooves a spiral leaves at azimuth ``theta`` (rad).

    The tool radius against its total angle phi is ``r(phi) = r0 - p0 phi / (2 pi)
    - b sin(phi / 10)``: a feed per revolution varying by +-30 % over about ten
    revolutions, as on case 1022 (25.9 .. 33.2 um).
    """
    b = 0.3 * p0 * 10 / (2 * np.pi)
    phi = theta + 2 * np.pi * np.arange(60)
    r = r0 - p0 * phi / (2 * np.pi) - b * np.sin(phi / 10)
    return r[r > -p0]


def groove_profile(r, grooves, nose=0.19e-3):
    """Height (m) at radii ``r`` left by round-nose grooves: the lowest circle arc."""
    d = np.abs(r[:, None] - grooves[None, :])
    h = nose - np.sqrt(np.maximum(nose**2 - d**2, 0.0))
    return h.min(axis=1)


def test_split_registration_of_spiral_grooves_with_varying_feed():
    # closed-form cusps of a round nose along a spiral: the simulated line at
    # azimuths 0 / pi, the measured one at psi / psi + pi, axis at 0.41 mm on it
    psi, axis = 0.9, 0.41e-3
    xs = -0.6e-3 + DX * np.arange(2401)
    zs = np.where(xs >= 0, groove_profile(np.abs(xs), spiral_grooves(0.0)),
                  groove_profile(np.abs(xs), spiral_grooves(np.pi)))
    band = Surface(zs[None, :], DX, DX, x0=float(xs[0]), metadata=dict(SIM_META))
    u = 0.02e-3 + DX * np.arange(1760)
    r = u - axis
    zm = np.where(r >= 0, groove_profile(np.abs(r), spiral_grooves(psi)),
                  groove_profile(np.abs(r), spiral_grooves(psi + np.pi)))
    meas = Profile(zm, DX, x0=float(u[0]))
    res = compare_profiles(meas, band, cutoff=0.25e-3)
    d = res.to_dict()
    assert d["split_at_axis"]
    # the grooves at psi lie p psi / (2 pi) (about 4 um) inward: opposite shifts
    # of the halves; the feed varies along the radius, so each half's shift is a
    # compromise, but the two sides vary alike and their mean is the axis
    assert abs(d["axis_position_m"] - axis) < 2 * DX
    # half offset -p psi' / (2 pi) modulo p, psi' = psi (or psi + pi when the line
    # is read backwards, which fits as well); p varies by +-30 % (+-1.2 um of it)
    p0 = 29e-6
    want = -p0 * (psi + (np.pi if d["mirrored"] else 0.0)) / (2 * np.pi)
    err = (d["half_offset_m"] - want + p0 / 2) % p0 - p0 / 2
    assert abs(err) < 1.5e-6
    # what one shift per half leaves: up to 1.2 um = x = 4 % of p of misalignment;
    # the autocorrelation of periodic parabolic arcs is -30 B4(x) = 1 - 30 x^2 +
    # ..., at least 0.95 there
    assert res.correlation > 0.95
    np.testing.assert_allclose(d["simulated_ra_m"], d["measured_ra_m"], rtol=0.03)
    np.testing.assert_allclose(d["simulated_rsm_m"], d["measured_rsm_m"], rtol=0.03)
    # one shift: one half off by 2 p psi / (2 pi) = 8 um (x = 0.29, -30 B4 < 0)
    single = compare_profiles(meas, band, cutoff=0.25e-3, split=False)
    assert single.correlation < 0.8


def test_split_needs_a_simulated_axis_and_both_sides():
    f = texture(12)
    axis, delta = 0.4137e-3, 5.3e-6
    meas = _through_centre(f, axis, delta, 20e-6, 1800)
    # not a servosurf simulation: x = 0 means nothing, one shift
    plain = compare_profiles(meas, _band(f, meta=False), cutoff=0.08e-3)
    assert plain.to_dict()["split_at_axis"] is False
    assert "split" not in plain.info and "split_skipped" not in plain.info
    forced = compare_profiles(meas, _band(f, meta=False), cutoff=0.08e-3, split=True)
    assert forced.to_dict()["split_at_axis"] is True
    assert abs(forced.shift - axis) < SHIFT_TOL_STEPS * DX
    # a measured profile on one side of the axis (20 um beyond it): one shift,
    # the one of its long half
    side = _through_centre(f, axis, delta, axis - 20e-6, 1000)
    one = compare_profiles(side, _band(f), cutoff=0.08e-3)
    d = one.to_dict()
    assert d["split_at_axis"] is False and "one side of the spindle axis" in (
        d["split_skipped"])
    assert abs(one.shift - (axis - delta)) < SHIFT_TOL_STEPS * DX
    far = _through_centre(f, axis, delta, axis + 50e-6, 1000)
    assert abs(compare_profiles(far, _band(f), cutoff=0.08e-3).shift
               - (axis - delta)) < SHIFT_TOL_STEPS * DX
    # split=True on a simulated profile that does not reach the axis
    with pytest.raises(ConfigError, match="crosses x = 0"):
        compare_profiles(meas, _band(f, x_min=0.1e-3, n=2000), split=True)
    with pytest.raises(ConfigError, match="split must be"):
        compare_profiles(meas, _band(f), split="yes")


def test_through_spindle_axis_detection():
    from servosurf.metrology import profile_through
    from servosurf.report._profile_compare import through_spindle_axis

    f = texture(13)
    band = _band(f)
    assert through_spindle_axis(band, profile_through(band))
    assert not through_spindle_axis(_band(f, meta=False), profile_through(band))
    three = Surface(np.tile(band.z, (3, 1)), DX, DX, x0=band.x0, y0=0.0,
                    metadata=dict(SIM_META))  # centre row at y = DX
    assert not through_spindle_axis(three, profile_through(three))
    assert through_spindle_axis(three, profile_through(three, at=0.0))
    prof = Profile(band.z[0], DX, x0=band.x0, metadata=dict(SIM_META))
    assert through_spindle_axis(prof, prof)
    right = Profile(band.z[0, 2100:], DX, x0=band.x0 + 2100 * DX,
                    metadata=dict(SIM_META))
    assert not through_spindle_axis(right, right)


def test_cli_split_keys_and_flag(tmp_path, capsys):
    from servosurf.io import read_any, write_surface

    f = texture(14)
    axis, delta = 0.4137e-3, 5.3e-6
    meas = _mx_csv(tmp_path / "m.csv", _through_centre(f, axis, delta, 20e-6, 1800))
    write_surface(_band(f), tmp_path / "band.datx")
    assert "simulation" in read_any(tmp_path / "band.datx")[0].metadata
    argv = ["compare", str(meas), "--simulated", str(tmp_path / "band.datx"),
            "--cutoff", "8e-5", "--json"]
    assert main([*argv, "--out", str(tmp_path / "a")]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["split_at_axis"] is True
    assert abs(out["axis_position_m"] - axis) < SHIFT_TOL_STEPS * DX
    assert set(out["half_shifts_m"]) == set(out["half_correlations"]) == {
        "below", "above"}
    assert set(out["files"]) >= {"profiles", "roughness", "spectra", "json"}
    assert (tmp_path / "a" / "roughness.png").stat().st_size > 0
    assert main([*argv, "--split", "no", "--out", str(tmp_path / "b")]) == 0
    assert json.loads(capsys.readouterr().out)["split_at_axis"] is False
    assert main(argv[:-1] + ["--out", str(tmp_path / "c")]) == 0
    text = capsys.readouterr().out
    assert "split at axis  axis at 413.70 um" in text


def test_axis_search_does_not_rely_on_the_whole_profile_registration():
    # on case 1022 with the measured edge swept, one shift for the whole WLI
    # profile lands 0.6 mm away from the axis; the search over axis positions on
    # the measured profile must still find it. Here the whole-profile guesses
    # handed to it are wrong on purpose.
    from servosurf.metrology import profile_through
    from servosurf.report._profile_compare import _split_search

    f = texture(15)
    axis, delta = 0.4137e-3, 5.3e-6
    meas = _through_centre(f, axis, delta, 20e-6, 1800)
    sim = profile_through(_band(f))
    found = _split_search(meas, meas, sim, 0.08e-3, "auto", None,
                          {False: axis + 0.3e-3, True: -0.2e-3})
    assert found is not None and found["below"] and found["above"]
    assert abs(found["axis_m"] - axis) < SHIFT_TOL_STEPS * DX
    assert abs(found["below"]["shift_m"] - (axis + delta)) < SHIFT_TOL_STEPS * DX
    assert found["score"] > 0.99
