"""simulate() and the CLI on design-surface toolpaths (kind = "surface")."""

from __future__ import annotations

import dataclasses
import json
import math
from pathlib import Path

import numpy as np
import pytest

from servosurf.cli import main
from servosurf.report._simulation import analyse
from servosurf.simulation import simulate
from servosurf.toolpath import load_toolpath, sample, sweep

TOOLPATHS = Path(__file__).resolve().parents[2] / "toolpaths"


@pytest.fixture(scope="module")
def small_sphere():
    """The shipped sphere toolpath on a 96 x 64 field at 1 um (fast)."""
    spec = load_toolpath(TOOLPATHS / "sphere.toml")
    fld = dataclasses.replace(spec.field, pitch_x=1e-6, pitch_y=1e-6, nx=96, ny=64)
    return dataclasses.replace(spec, field=fld)


def test_kinematic_simulation_is_the_sweep_and_meets_the_scallop(small_sphere):
    res = simulate(small_sphere, parts=())
    path = sample(small_sphere, field=small_sphere.field, tool=small_sphere.tool)
    ref = sweep(path, small_sphere.tool, small_sphere.field, initial=0.0)
    np.testing.assert_allclose(res.surface.z, ref.z, atol=1e-15)  # 1 fm
    summary = analyse(res)
    h = small_sphere.path.scallop_height  # 20 nm target of the planned feed
    assert summary["kinematic_scallop_m"] == pytest.approx(h, rel=2e-3)
    # after piston and tilt the scallops stay within [0, h]: PV <= h; the 1 um
    # pixels sample cusps of slope f / (2 R) = 0.009 to within 5 nm
    assert h - 5e-9 <= summary["form_error_pv_m"] <= h * 1.01
    assert summary["form_error_rms_m"] < summary["form_error_pv_m"] / 2
    # one more fitted term cannot raise the RMS (it may raise the PV)
    assert summary["form_error_rms_bfs_m"] <= summary["form_error_rms_m"] * (1 + 1e-9)
    assert summary["design_toolpath"]["design"] == {"type": "sphere",
                                                     "radius_m": -0.05}


def test_kinematic_simulation_on_a_steep_sphere(small_sphere):
    """At a slope of 19 degrees the nose touches the sphere R sin(phi) = 0.16 mm
    inboard of the tip, far beyond the arc's reach at the finishing depth: the
    simulated span must follow the tip's whole depth below the pre-cut face."""
    from servosurf.toolpath import DesignToolpath, Field, Sphere

    p = DesignToolpath(design=Sphere(radius=-5e-3), r_start=2.2e-3, r_end=1.0e-3,
                       spindle_speed=20.0, feed_per_rev=20e-6, depth_of_cut=3e-6)
    fld = Field(pitch_x=1e-6, pitch_y=1e-6, nx=48, ny=32, center_x=1.6e-3)
    spec = dataclasses.replace(small_sphere, path=p, field=fld)
    res = simulate(spec, parts=())
    ref = sweep(sample(spec, field=fld, tool=spec.tool), spec.tool, fld)
    np.testing.assert_allclose(res.surface.z, ref.z, atol=1e-15)  # 1 fm
    x, y = fld.coords()
    err = res.surface.z - p.design_height(x[None, :], y[:, None])
    # scallop f^2 / (8 R (1 + R / 5 mm) cos(phi)^3), sin(phi) = r / 5.5 mm
    rmax = np.hypot(x[-1], y[-1])
    h = 20e-6**2 / (8 * 0.5e-3 * 1.1 * (1 - (rmax / 5.5e-3) ** 2) ** 1.5)
    assert err.min() >= -1e-12 and err.max() <= h * 1.01


def test_force_is_the_steady_facing_chip(small_sphere):
    """Constant feed f, finishing depth d: the chip section is f (d - f^2 / (24 R))
    (the volume cut per revolution: f times the depth below the mean of the
    parabolic scallop, whose mean is f^2 / (24 R))."""
    p = dataclasses.replace(small_sphere.path, scallop_height=None,
                            feed_per_rev=8e-6)
    spec = dataclasses.replace(small_sphere, path=p)
    res = simulate(spec, parts=("force",))
    kt = res.workpiece.material.specific_thrust_pressure
    R, f, d = spec.tool.nose_radius, 8e-6, p.depth_of_cut
    steady = res.force[res.t - res.t[0] > 1.5 / p.rev_per_s]
    np.testing.assert_allclose(steady, kt * f * (d - f**2 / (24 * R)), rtol=2e-3)
    assert res.settings["toolpath_kind"] == "surface"


def _small_toml(tmp_path, name):
    text = (TOOLPATHS / f"{name}.toml").read_text()
    text = text.replace("nx = 640", "nx = 96").replace("nx = 480", "nx = 96")
    text = text.replace("ny = 480", "ny = 64")
    text = text.replace("pitch-x = 0.55e-6", "pitch-x = 1e-6")
    text = text.replace("pitch-y = 0.55e-6", "pitch-y = 1e-6")
    p = tmp_path / f"{name}.toml"
    p.write_text(text)
    return p


def test_simulate_cli_reports_the_form_error(tmp_path, capsys):
    toml = _small_toml(tmp_path, "lenslet_array_hex")
    out = tmp_path / "o"
    rc = main(["simulate", str(toml), "--out", str(out), "--json", "--no-render",
               "--format", "npz", "--instrument", "none"])
    assert rc == 0
    data = json.loads(capsys.readouterr().out)
    for key in ("form_error_pv_m", "form_error_rms_m", "form_error_pv_bfs_m",
                "form_error_rms_bfs_m", "kinematic_scallop_m", "form_error_max_m"):
        assert isinstance(data[key], float) and math.isfinite(data[key])
    assert data["settings"]["toolpath_kind"] == "surface"
    assert data["form_error_pv_m"] >= data["kinematic_scallop_m"] * 0.9
    assert data["files"]["form_error_png"].endswith("form_error.png")
    for name in ("form_error.png", "toolpath.png", "map.png", "summary.json",
                 "surface.npz"):
        assert (out / name).stat().st_size > 0
    # without --json: the summary states PV and RMS against the design in nm
    rc = main(["simulate", str(toml), "--out", str(out), "--no-render", "--format",
               "npz", "--instrument", "none"])
    assert rc == 0
    text = capsys.readouterr().out
    pv = data["form_error_pv_m"] * 1e9
    line = next(v for v in text.splitlines() if "form error vs design" in v)
    assert f"PV {pv:.3g} nm" in line and "RMS" in line, line


def test_simulate_cli_bad_design_is_one_line(tmp_path, capsys):
    toml = _small_toml(tmp_path, "sphere")
    toml.write_text(toml.read_text().replace("radius = -50e-3", "radius = -50"))
    assert main(["simulate", str(toml), "--out", str(tmp_path / "o")]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "surface.radius = -50 m" in err[0]
    assert not (tmp_path / "o").exists() or not list((tmp_path / "o").iterdir())
