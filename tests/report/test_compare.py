"""compare: registration of a shifted, tilted, noisy copy of a simulated map."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from servosurf.metrology import shift_surface
from servosurf.report._compare import compare_surfaces
from servosurf.simulation import simulate
from servosurf.toolpath import load_toolpath

SHIFT_PX_TOL = 0.1  # the acceptance: a tenth of a pixel


@pytest.fixture(scope="module")
def lens_map():
    spec = load_toolpath("toolpaths/lenslet_5um.toml")
    fld = dataclasses.replace(spec.field, pitch_x=1e-6, pitch_y=1e-6, nx=200, ny=200)
    return simulate(dataclasses.replace(spec, field=fld), seed=5).surface


def test_registration_recovers_subpixel_shift(lens_map):
    rng = np.random.default_rng(11)
    true = (2.37e-6, -1.61e-6)  # m: (dy, dx)
    moved = shift_surface(lens_map, *true)
    yy, xx = np.mgrid[0 : moved.shape[0], 0 : moved.shape[1]]
    tilt = 2e-9 * xx - 1e-9 * yy  # m per pixel
    noisy = moved.replace(z=moved.z + tilt + rng.normal(0, 2e-9, moved.shape))
    out = compare_surfaces(noisy, lens_map)
    # the simulated map must be shifted by `true` to land on the measured one
    np.testing.assert_allclose(
        out["shift_px"], [true[0] / 1e-6, true[1] / 1e-6], atol=SHIFT_PX_TOL
    )
    assert out["rms_residual_m"] < 5e-9
    assert out["fit_percent"] > 95
    assert out["correlation"] > 0.999


def test_identical_maps_are_a_perfect_fit(lens_map):
    out = compare_surfaces(lens_map, lens_map)
    np.testing.assert_allclose(out["shift_px"], [0, 0], atol=0.01)
    assert out["rms_residual_m"] < 1e-12
    assert out["fit_percent"] == pytest.approx(100.0, abs=1e-6)


def test_compare_areal_parameters_on_common_pixels(lens_map):
    # the "measured" map is the simulation plus a tilt, with a void block: after
    # the same form removal on the same pixels, both columns must agree
    yy, xx = np.mgrid[0 : lens_map.shape[0], 0 : lens_map.shape[1]]
    z = lens_map.z + 3e-9 * xx - 2e-9 * yy
    z[20:60, 30:90] = np.nan
    out = compare_surfaces(lens_map.replace(z=z), lens_map, register=False)
    m, s = out["areal"]["measured"], out["areal"]["simulated"]
    assert m["n_valid"] == s["n_valid"] == np.isfinite(z).sum()
    for key in ("sa_m", "sq_m", "sz_m", "ssk", "sdq", "sal_m", "sk_m", "spk_m"):
        # identical surfaces up to the rounding of the fitted tilt
        np.testing.assert_allclose(m[key], s[key], rtol=1e-6, err_msg=key)
    assert "piston tilt" in out["areal"]["evaluated_on"]


def test_compare_cli_files(lens_map, tmp_path, capsys):
    import json

    from servosurf.cli import main
    from servosurf.io import write_surface

    rng = np.random.default_rng(3)
    moved = shift_surface(lens_map, 1.3e-6, 0.4e-6)
    moved = moved.replace(z=moved.z + rng.normal(0, 1e-9, moved.shape))
    write_surface(moved, tmp_path / "measured.x3p")
    write_surface(lens_map, tmp_path / "sim.datx")
    rc = main(["compare", str(tmp_path / "measured.x3p"), "--simulated",
               str(tmp_path / "sim.datx"), "--out", str(tmp_path / "c"), "--json"])
    assert rc == 0
    out = json.loads(capsys.readouterr().out)
    np.testing.assert_allclose(out["shift_px"], [1.3, 0.4], atol=SHIFT_PX_TOL)
    for side in ("measured", "simulated"):
        assert out["areal"][side]["sq_m"] > 0 and "sdr_percent" in out["areal"][side]
    for name in ("residual.png", "spectra.png", "profiles.png", "compare.json"):
        assert (tmp_path / "c" / name).stat().st_size > 0
    assert main(["compare", str(tmp_path / "nope.x3p"), "--simulated",
                 str(tmp_path / "sim.datx"), "--out", str(tmp_path / "c2")]) == 1
