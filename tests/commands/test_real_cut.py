"""The real-cut procedure on case 1022, exactly as documented (examples/real_cut):

    servosurf simulate 1022-spiralPath20230418T214917.nc --block-time 1e-3 \\
        --tool-radius 189.36e-6 --out OUT
    servosurf compare 1022-WLI-2D.csv --simulated OUT/surface.datx \\
        --cutoff 2.5e-4 --json
    servosurf compare 1022-contour.DAT --simulated OUT/surface.datx \\
        --x-range -0.00099 0.00099 --cutoff 2.5e-4 --json

Oracles, all independent of servosurf's output (../shared/data/upm_sts/SOURCES.md
and the files read with numpy): the measured Ra 106.0 nm (WLI) and 107.1 nm
(Formtracer) at lambda_c 0.25 mm with the ends trimmed; a round nose of 189.4 um
swept along the blocks gives "about 115 nm (+9 %)", more than measured; the feed
per revolution of 1022 lies in 25.9 .. 33.2 um, so RSm (one groove per
revolution) must too; the WLI profile has a void around the part's centre (read
here with numpy), where the registration must put the spindle axis; the
Formtracer contour's rim (where it leaves the cut zone by more than 2 um) is
centred within a few um of the axis. Skipped when ../shared is absent.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from servosurf.cli import main
from tests.conftest import UPM

CASE = UPM / "1022"
PROGRAM = CASE / "1022-spiralPath20230418T214917.nc"
WLI = CASE / "1022-WLI-2D.csv"
CONTOUR = CASE / "1022-contour.DAT"
CUTOFF = "2.5e-4"  # m, the lambda_c of SOURCES.md's reference values
CUT_ZONE = ("-0.00099", "0.00099")  # m, the contour's cut zone (rim at ~ +-1 mm)
#: Relative tolerance on the independent measured values (as in
#: tests/report/test_profile_compare.py).
REFERENCE_RTOL = 5e-3
#: SOURCES.md: measured Ra (m) and the round-nose kinematic Ra "about 115 nm".
RA_WLI, RA_CONTOUR, RA_KINEMATIC = 106.0e-9, 107.1e-9, 115e-9
#: SOURCES.md: 1022's feed per revolution along the radius, m.
FEED_RANGE = (25.9e-6, 33.2e-6)
#: How far the contour's rim centre may lie from the axis: the aperture was not
#: necessarily turned concentric to the spiral; a registration one groove off
#: (29 um) would lie at least 20 um away.
RIM_TOL = 15e-6
#: Keys the issue asks of compare --json.
KEYS = ("measured_ra_m", "simulated_ra_m", "measured_rsm_m", "simulated_rsm_m",
        "correlation", "shift_m", "cutoff_m", "trim_length_m", "split_at_axis",
        "axis_position_m", "half_shifts_m", "half_correlations",
        "evaluation_length_m")


@pytest.fixture(scope="module")
def band(tmp_path_factory):
    if not PROGRAM.is_file():
        pytest.skip(f"shared UPM data not found at {CASE}")
    out = tmp_path_factory.mktemp("real1022")
    rc = main(["-q", "simulate", str(PROGRAM), "--block-time", "1e-3",
               "--tool-radius", "189.36e-6", "--out", str(out / "sim")])
    assert rc == 0
    return out


def _compare(band, capsys, measured, *extra):
    out = band / measured.stem
    rc = main(["compare", str(measured), "--simulated", str(band / "sim" /
                                                           "surface.datx"),
               "--cutoff", CUTOFF, *extra, "--out", str(out), "--json"])
    assert rc == 0
    res = json.loads(capsys.readouterr().out)
    assert res == json.loads((out / "compare.json").read_text())
    for key in KEYS:
        assert key in res, key
    for name in ("profiles.png", "roughness.png", "spectra.png"):
        assert (out / name).stat().st_size > 0
    return res


def _wli_void():
    """x (m) of the missing pixels inside the WLI profile (not at its ends)."""
    rows = [ln.split(",") for ln in WLI.read_text().splitlines()[1:]]
    x = np.array([float(r[0]) for r in rows]) * 1e-6
    void = np.array([not r[1].strip() for r in rows])
    ok = np.flatnonzero(~void)
    inner = void & (np.arange(x.size) > ok[0]) & (np.arange(x.size) < ok[-1])
    return x[inner]


def test_wli_against_the_simulated_band(band, capsys):
    res = _compare(band, capsys, WLI)
    assert res["cutoff_m"] == 2.5e-4 and res["trim_length_m"] == 2.5e-4
    np.testing.assert_allclose(res["measured_ra_m"], RA_WLI, rtol=REFERENCE_RTOL)
    np.testing.assert_allclose(res["measured_rq_m"], 123.0e-9, rtol=REFERENCE_RTOL)
    np.testing.assert_allclose(res["measured_rz_m"], 400.8e-9, rtol=REFERENCE_RTOL)
    # the kinematic sweep cuts deeper cusps than measured, about +9 %
    assert RA_WLI < res["simulated_ra_m"] < 1.1 * RA_KINEMATIC
    for key in ("measured_rsm_m", "simulated_rsm_m"):
        assert FEED_RANGE[0] < res[key] < FEED_RANGE[1], key
    # the line through the centre: split at the axis, which lies in the WLI's
    # central void, the halves shifted less than half a groove from it
    assert res["split_at_axis"] is True
    void = _wli_void()
    assert void.size > 10
    assert void.min() < res["axis_position_m"] < void.max()
    assert abs(res["half_offset_m"]) < FEED_RANGE[1] / 2
    assert res["correlation"] > 0.9
    one = _compare(band, capsys, WLI, "--split", "no")
    assert one["split_at_axis"] is False
    assert res["correlation"] > one["correlation"]
    # one evaluation span, one cut-off: the measured side does not depend on it
    assert one["measured_ra_m"] == pytest.approx(res["measured_ra_m"], rel=1e-9)


def test_contour_against_the_simulated_band(band, capsys):
    res = _compare(band, capsys, CONTOUR, "--x-range", *CUT_ZONE, "--labels",
                   "Formtracer", "simulated")
    np.testing.assert_allclose(res["measured_ra_m"], RA_CONTOUR,
                               rtol=REFERENCE_RTOL)
    assert res["simulated_ra_m"] > res["measured_ra_m"]
    for key in ("measured_rsm_m", "simulated_rsm_m"):
        assert FEED_RANGE[0] < res[key] < FEED_RANGE[1], key
    assert res["split_at_axis"] is True
    d = np.loadtxt(CONTOUR, skiprows=2, delimiter=",") * 1e-3  # mm -> m
    x, z = d[:, 0], d[:, 1]
    off = np.abs(z - np.median(z[np.abs(x) < 0.9e-3])) > 2e-6
    rim = 0.5 * (x[(x > 0.5e-3) & off].min() + x[(x < -0.5e-3) & off].max())
    assert abs(res["axis_position_m"] - rim) < RIM_TOL
    assert abs(res["half_offset_m"]) < FEED_RANGE[1] / 2
    assert res["correlation"] > 0.8
    one = _compare(band, capsys, CONTOUR, "--x-range", *CUT_ZONE, "--split", "no")
    assert res["correlation"] > one["correlation"] + 0.2


def test_example_toolpath_files_hold_the_documented_settings():
    # examples/real_cut/*.toml find the program through ../shared next to the repo
    import servosurf.toolpath as tp
    from tests.conftest import REPO, SHARED

    if not PROGRAM.is_file() or SHARED.resolve() != (REPO.parent / "shared").resolve():
        pytest.skip("the example files expect the shared data at <repo>/../shared")
    spec = tp.load_toolpath(REPO / "examples" / "real_cut" / "1022.toml")
    assert spec.kind == "nc" and spec.tool.nose_radius == 189.36e-6
    assert not spec.tool.has_waviness
    d = spec.path.describe()
    assert d["time_base"] == "0.001 s per cutting block (given)"
    assert (d["reference"], d["rotation"]) == ("tip", "ccw")
    edge = tp.load_toolpath(REPO / "examples" / "real_cut" / "1022-edge.toml")
    assert edge.tool.has_waviness
    # the trace's own fit, between the independent fits of SOURCES.md
    assert 186.41e-6 < edge.tool.nose_radius < 191.81e-6
