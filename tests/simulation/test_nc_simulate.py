"""Simulating NC programs: kinematic runs, the second-order axis, the CLI on
programs (good and bad), and the real 1022 cut against its measured roughness."""

from __future__ import annotations

import dataclasses
import io
import json
import subprocess
import sys

import numpy as np
import pytest
import scipy.signal as sps

import servosurf.toolpath as tp
from servosurf.cli import main
from servosurf.errors import ConfigError
from servosurf.simulation import simulate
from tests.conftest import SHARED

P1022 = SHARED / "data" / "upm_sts" / "1022" / "1022-spiralPath20230418T214917.nc"
WLI = SHARED / "data" / "upm_sts" / "1022" / "1022-WLI-2D.csv"
#: Measured Ra of the 1022 white-light profile (SOURCES.md), in m.
RA_1022_MEASURED = 106.0e-9
#: Profile length of that measurement: 1047 samples at 0.871 um, in m.
WLI_LENGTH = 0.912e-3
#: Two sweeps of the same geometry sampled differently: interpolation rounding only.
SWEEP_ATOL = 1e-12  # m, 1 pm


def facing_text(r0_mm, f_mm, n_rev, z_mm, step_deg=2.0):
    c = np.arange(int(round(n_rev * 360 / step_deg)) + 1) * step_deg
    x = r0_mm - f_mm * c / 360.0
    return "G71\n" + "\n".join(f"C{a:g} X{b:.9f} Z{z_mm:g}" for a, b in
                               zip(c, x, strict=True)) + "\n"


def small_spec(text, **kw):
    fld = kw.pop("field", tp.Field(pitch_x=1e-6, pitch_y=1e-6, nx=24, ny=10,
                                   center_x=0.25e-3))
    return tp.nc_spec(tp.read_nc_program(io.StringIO(text)), field=fld,
                      tool=tp.Tool(nose_radius=0.2e-3), **kw)


def test_default_machine_of_nc_programs_is_kinematic():
    spec = small_spec(facing_text(0.3, 0.005, 12, -0.001), block_time=1e-3)
    res = simulate(spec)
    assert res.machine.name == "sts-ideal-axes"
    assert res.settings["parts"] == ["kinematic"]
    assert res.settings["path_samples"] == "block end points"
    ref = simulate(spec, parts=("kinematic",), machine="seed-prototype")
    np.testing.assert_array_equal(res.surface.z, ref.surface.z)
    with pytest.raises(ConfigError, match="cannot be combined"):
        simulate(spec, parts=("kinematic", "tracking"))


def test_second_order_axis_deviation_equals_lsim(tmp_path):
    # Z ramps down along the cut, so the slide lags behind the command
    c = np.arange(0, 12 * 360 + 1, 2.0)
    x = 0.3 - 0.005 * c / 360
    z = -0.001 - 0.002 * c / c[-1]
    text = "\n".join(f"C{a:g} X{b:.9f} Z{d:.9f}" for a, b, d in zip(c, x, z,
                                                                      strict=True))
    spec = small_spec(text, spindle_speed=2.0)
    m = tmp_path / "slide.toml"
    m.write_text('inherit = "sts-ideal-axes"\n[axis]\nmodel = "second-order"\n'
                 'bandwidth = 20.0\ndamping = 0.6\nsample-rate = 4000.0\n')
    res = simulate(spec, machine=m)
    assert res.settings["parts"] == ["tracking"]
    assert res.settings["axis_model"] == "second-order"
    wn = 2 * np.pi * 20.0
    sys_ = sps.lti([wn * wn], [1.0, 1.2 * wn, wn * wn])
    _, y, _ = sps.lsim(sys_, res.z_command - res.z_command[0], res.t - res.t[0])
    dev = y + res.z_command[0] - res.z_command
    np.testing.assert_allclose(res.deviation["tracking"], dev, rtol=0, atol=1e-15)
    # the slide lags: the ramp down is followed late, so the cut is shallower
    kin = simulate(spec, parts=("kinematic",))
    assert np.nanmean(res.surface.z - kin.surface.z) > 0
    with pytest.raises(ConfigError, match="second-order Z axis: parts force"):
        simulate(spec, machine=m, parts=("tracking", "force"))


def test_flat_program_on_an_axis_equals_kinematic(tmp_path):
    spec = small_spec(facing_text(0.3, 0.005, 12, -0.001), spindle_speed=2.0)
    m = tmp_path / "slide.toml"
    m.write_text('inherit = "sts-ideal-axes"\n[axis]\nmodel = "second-order"\n'
                 'bandwidth = 20.0\nsample-rate = 7200.0\n')
    res = simulate(spec, machine=m)
    kin = simulate(spec, parts=("kinematic",))
    # a constant Z is followed exactly; the axis samples (7200 Hz = one per
    # degree at 2 rev/s) and the block end points describe the same spiral
    np.testing.assert_allclose(res.surface.z, kin.surface.z, rtol=0, atol=SWEEP_ATOL)


def test_fts_kinds_kinematic_equals_commanded_sweep():
    spec = tp.load_toolpath("toolpaths/lenslet_5um.toml")
    fld = dataclasses.replace(spec.field, pitch_x=2e-6, pitch_y=2e-6, nx=60, ny=60)
    spec = dataclasses.replace(spec, field=fld)
    kin = simulate(spec, parts=("kinematic",))
    assert kin.machine.name == "seed-prototype" and kin.t.size == 0
    path = tp.sample(spec, field=fld, tool=spec.tool)
    ref = tp.sweep(path, spec.tool, fld, initial=0.0)
    np.testing.assert_array_equal(kin.surface.z, ref.z)


def test_nc_program_on_the_fts():
    spec = small_spec(facing_text(0.3, 0.005, 12, -0.001), spindle_speed=2.0)
    res = simulate(spec, machine="seed-prototype", bandwidth=1448.0, mass=0.175)
    assert res.settings["parts"] == ["tracking", "vibration"]
    assert np.isfinite(res.surface.z).all()
    with pytest.raises(ConfigError, match="cutting-force part needs the chip"):
        simulate(spec, machine="seed-prototype", parts=("force",))


# ---------------------------------------------------------------------------------
# command line
# ---------------------------------------------------------------------------------


BAD = {
    "unknown G-code": ("C0 X1 Z0\nG2 X0.5 Z0\n", r"line 2: G2 is not supported"),
    "WHILE without END": ("#1=0\nWHILE[#1 LT 2] DO 1\nC[#1] X1 Z0\n#1=#1+1\n",
                          r"line 2: WHILE \[..\] DO 1 has no END 1"),
    "missing time base": ("C0 X1 Z0\nC0.5 X0.99 Z0\n",
                          r"line 1: the program gives no time for its cutting blocks"),
    "C not a number": ("C0 X1 Z0\nC0,5 X0.99 Z0\n", r"line 2: C value '0,5' is not "
                       r"a number"),
}


@pytest.mark.parametrize("case", sorted(BAD))
def test_bad_programs_exit_1_one_line_nothing_written(case, tmp_path, capsys):
    text, match = BAD[case]
    prog = tmp_path / "bad.nc"
    prog.write_text(text)
    out = tmp_path / "out"
    argv = ["simulate", str(prog), "--tool-radius", "2e-4", "--out", str(out)]
    if case != "missing time base":
        argv += ["--block-time", "1e-3"]
    assert main(argv) == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "Traceback" not in err
    import re

    assert re.search(match, err), err
    assert not out.exists()


@pytest.mark.parametrize(
    ("extra", "match"),
    [
        (["--tool-radius", "189.36"], r"--tool-radius 189.36 m is not a diamond "
         r"tool's nose radius .* 189.36 um = 0.00018936 m"),
        (["--tool-radius", "2e-4", "--spindle-rpm", "-3"], r"--spindle-rpm must be"),
        (["--tool-radius", "2e-4", "--block-time", "500"], r"a value in ms"),
        ([], r"states no tool nose radius: give --tool-radius M"),
    ],
)
def test_cli_refuses_absurd_values(extra, match, tmp_path, capsys):
    prog = tmp_path / "p.nc"
    prog.write_text("C0 X1 Z0\nC1 X0.99 Z0\n")
    out = tmp_path / "out"
    argv = ["simulate", str(prog), "--out", str(out), *extra]
    if "--block-time" not in extra and "--spindle-rpm" not in extra:
        argv += ["--block-time", "1e-3"]
    assert main(argv) == 1
    import re

    err = capsys.readouterr().err
    assert re.search(match, err), err
    assert not out.exists()


def test_cli_nc_flags_refused_for_other_kinds(capsys, tmp_path):
    assert main(["simulate", "toolpaths/flat_facing.toml", "--spindle-rpm", "30",
                 "--out", str(tmp_path / "o")]) == 1
    assert "--spindle-rpm applies to NC programs" in capsys.readouterr().err
    # one time base at most (argparse usage error: one line, exit 1)
    assert main(["simulate", "x.nc", "--spindle-rpm", "30", "--block-time", "1"]) == 1
    assert "not allowed with argument" in capsys.readouterr().err


def test_cli_small_program_through_python_m(tmp_path):
    prog = tmp_path / "face.nc"
    prog.write_text(facing_text(0.2, 0.008, 25, 0.0))
    out = tmp_path / "run"
    r = subprocess.run(
        [sys.executable, "-m", "servosurf", "simulate", str(prog),
         "--spindle-rpm", "60", "--tool-radius", "0.2e-3", "--out", str(out)],
        capture_output=True, text=True, check=False)
    assert r.returncode == 0, r.stderr
    assert r.stdout.startswith("simulate face.nc: centre profile\n  Ra / Rq / Rz ")
    summary = json.loads((out / "summary.json").read_text())
    assert summary["toolpath"]["time_base"] == "spindle 60 rpm (given)"
    for name in ("map_png", "toolpath_png", "profile_png", "roughness_png", "map"):
        assert (out / summary["files"][name].split("/")[-1]).is_file()


# ---------------------------------------------------------------------------------
# the real 1022 cut (shared data; skipped when absent)
# ---------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def run_1022(tmp_path_factory):
    if not P1022.is_file():
        pytest.skip(f"shared UPM data not found at {P1022}")
    out = tmp_path_factory.mktemp("c1022")
    argv = ["simulate", str(P1022), "--block-time", "1e-3", "--tool-radius",
            "189.36e-6", "--profile-length", str(WLI_LENGTH), "--out", str(out),
            "--json"]
    return out, argv


def test_1022_kinematic_cli(run_1022, capsys):
    out, argv = run_1022
    assert main(argv) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary == json.loads((out / "summary.json").read_text())
    rough = summary["roughness"]
    # measured 106.0 nm (white-light profile, same cut-off and trimming)
    assert abs(rough["ra_m"] / RA_1022_MEASURED - 1) < 0.10
    assert rough["cutoff_m"] == 0.25e-3 and rough["trim_length_m"] == 0.25e-3
    assert rough["profile_length_m"] == pytest.approx(WLI_LENGTH, abs=1e-6)
    # the band: through the axis across the whole radius, pitch stated, <= 1 um
    fld = summary["field"]
    assert fld["kind"] == "band through the spindle axis"
    assert fld["pitch_x_m"] <= 1e-6 and fld["x_max_m"] == pytest.approx(1.031e-3,
                                                                        abs=1e-6)
    path = summary["toolpath"]
    assert path["time_base"] == "0.001 s per cutting block (given)"
    assert (path["reference"], path["rotation"]) == ("tip", "ccw")
    assert path["n_revolutions"] == pytest.approx(38.0)
    # over r > 5 % of r_max: 22.7 um near r = 0.88 mm to 33.2 um near 0.3 mm
    assert 22e-6 < path["feed_per_rev_min_m"] < path["feed_per_rev_max_m"] < 33.3e-6
    assert summary["settings"]["parts"] == ["kinematic"]
    for key in ("map", "map_png", "toolpath_png", "profile_png", "roughness_png"):
        assert (out / summary["files"][key].split("/")[-1]).is_file()
    from servosurf.io import read_surface

    band = read_surface(out / "surface.datx")
    assert band.shape == (5, 4125)
