"""Measured tool edges: synthetic traces with a known nose, the real trace, files.

The synthetic trace is built here from its definition (a circular nose between two
tangent straight flanks, a known radial waviness, seeded noise, spikes at known
points and stray points inside the V); the fit must return what was put in. The
smoothed waviness is checked against the closed-form transmission of the Gaussian
smoother. The real trace is checked against the independent fits of SOURCES.md.
"""

from __future__ import annotations

import io
import math

import numpy as np
import pytest

import servosurf.toolpath as tp
from servosurf.cli import main
from servosurf.errors import ConfigError, CorruptedFileError, UnitError

R0 = 200e-6  # m, nose radius of the synthetic tool
C0 = np.array([0.35e-3, -10.8e-3])  # m, its centre in the trace plane
AXIS = math.radians(-80.0)  # tool axis (centre to tip) from +u
WAVE_A = 0.2e-6  # m, waviness amplitude
WAVE_L = 60e-6  # m, waviness wavelength along the arc
NOISE = 0.03e-6  # m, probe noise (standard deviation)
SPIKES = {(-30.0): 3e-6, 5.0: -4e-6, 33.0: 2.5e-6}  # degree -> m
#: Fit accuracy demanded: radius and centre (m), axis (rad).
POS_TOL = 0.1e-6
AXIS_TOL = math.radians(0.2)
#: Smoothed waviness against the transmitted sine (m): the kernel averages about
#: six points of 0.03 um noise, so 0.03 um is four standard errors.
WAVE_TOL = 0.03e-6
#: Independent radius fits of the real tool D906 (SOURCES.md), m.
KNOWN_FITS = (186.41e-6, 189.36e-6, 191.81e-6)


def _frame(axis):
    a = np.array([math.cos(axis), math.sin(axis)])
    o = np.array([a[1], -a[0]])
    if o[0] < 0:  # outward: the perpendicular with a positive u component
        o = -o
    return a, o


def synthetic_trace(seed=0, *, flank_deg=60.0, step=1e-6, bump=None):
    """Trace points (n, 2) in m, the indices of spikes, and the true waviness.

    Nose arc |phi| <= flank_deg, flanks tangent there and 0.6 mm long, points every
    ``step`` of path length, then 40 stray points near the centre.
    """
    rng = np.random.default_rng(seed)  # noise values depend on the seed only
    a, o = _frame(AXIS)
    pf = math.radians(flank_deg)

    def wave(phi):
        w = WAVE_A * np.sin(2 * np.pi * R0 * phi / WAVE_L)
        if bump is not None:
            w = w + bump[1] * np.exp(-(((phi - math.radians(bump[0])) / 0.05) ** 2))
        return w

    phi = np.arange(-pf, pf, step / R0)
    rad = R0 + wave(phi) + rng.normal(0, NOISE, phi.size)
    nose = C0 + rad[:, None] * (np.outer(np.cos(phi), a) + np.outer(np.sin(phi), o))
    spikes = []
    for deg, h in SPIKES.items():
        k = int(np.argmin(np.abs(phi - math.radians(deg))))
        nose[k] += h * (nose[k] - C0) / np.linalg.norm(nose[k] - C0)
        spikes.append(k)
    s = np.arange(0, 0.6e-3, step)[1:]
    flanks = []
    for sign in (1, -1):  # tangent point and the direction away from the tip
        p_t = C0 + R0 * (a * math.cos(pf) + sign * o * math.sin(pf))
        t = -a * math.sin(pf) + sign * o * math.cos(pf)
        normal = np.array([t[1], -t[0]])
        flanks.append(p_t + np.outer(s, t) + np.outer(rng.normal(0, NOISE, s.size),
                                                      normal))
    stray = C0 + rng.uniform(-40e-6, 40e-6, (40, 2))
    # order: one flank towards the nose, the nose, the other flank, then strays
    pts = np.vstack([flanks[1][::-1], nose, flanks[0], stray])
    spike_idx = [flanks[1].shape[0] + k for k in spikes]
    return pts, spike_idx, wave


def _csv(pts, *, z=None, header=None, unit_scale=1e3, fmt="{:.7f}"):
    """Plain x,y,z (or x,y) rows in mm, optional laser-probe header lines."""
    lines = list(header or [])
    for p in pts:
        vals = [fmt.format(v * unit_scale) for v in p]
        if z is not None:
            vals.append(fmt.format(z))
        lines.append(",".join(vals))
    return ("\n".join(lines) + "\n").encode()


@pytest.fixture(scope="module")
def synthetic():
    pts, spike_idx, wave = synthetic_trace()
    edge = tp.read_tool_edge(_csv(pts, z=-0.8435))
    return edge, pts, spike_idx, wave


# -------------------------------------------------------------- synthetic fit
def test_fit_recovers_the_nose(synthetic):
    edge, pts, _, _ = synthetic
    assert abs(edge.radius - R0) < POS_TOL
    np.testing.assert_allclose(edge.centre, C0, atol=POS_TOL)
    assert abs(edge.axis_angle - AXIS) < AXIS_TOL
    np.testing.assert_allclose(edge.arc, [-math.radians(45), math.radians(45)])
    assert edge.metadata["plane_columns"] == [0, 1]  # z (constant) left out
    assert edge.metadata["flanks_found"] == 2


def test_spikes_are_exactly_the_injected_points(synthetic):
    edge, _, spike_idx, _ = synthetic
    in_arc_spikes = [k for k in spike_idx if edge.in_arc[k]]
    assert len(in_arc_spikes) == 3  # all three lie within +-45 degrees
    # the 40 stray points near the centre (the last rows) are gross outliers:
    # those whose direction falls in the arc are rejected too
    n = edge.u.size
    strays = [k for k in range(n - 40, n) if edge.in_arc[k]]
    assert strays  # some strays do lie in the arc's directions
    np.testing.assert_array_equal(np.flatnonzero(edge.spike),
                                  sorted(in_arc_spikes + strays))


def test_smoothed_waviness_is_the_transmitted_wave(synthetic):
    edge, _, _, wave = synthetic
    lc = edge.settings.smoothing
    alpha = math.sqrt(math.log(2) / math.pi)
    gain = math.exp(-math.pi * (alpha * lc / WAVE_L) ** 2)  # ISO 16610-21 Gaussian
    phi = edge.waviness_angle
    inner = np.abs(phi) < edge.arc[1] - lc / R0  # one cut-off from the ends
    expect = gain * WAVE_A * np.sin(2 * np.pi * R0 * phi / WAVE_L)
    np.testing.assert_allclose(edge.waviness_deviation[inner], expect[inner],
                               atol=WAVE_TOL)
    np.testing.assert_allclose(np.diff(phi), edge.settings.angle_step, rtol=1e-6)


def test_outward_is_larger_u_and_mirror_flips():
    # a 1 um bump at phi = +20 degrees (the side of larger u)
    pts, _, _ = synthetic_trace(seed=1, bump=(20.0, 1e-6))
    data = _csv(pts)
    edge = tp.read_tool_edge(data)
    k = int(np.argmax(edge.waviness_deviation))
    assert abs(math.degrees(edge.waviness_angle[k]) - 20.0) < 2.0
    mirrored = tp.read_tool_edge(data, mirror=True)
    k = int(np.argmax(mirrored.waviness_deviation))
    assert abs(math.degrees(mirrored.waviness_angle[k]) + 20.0) < 2.0
    np.testing.assert_allclose(mirrored.radius, edge.radius, rtol=1e-9)


def test_tool_from_the_edge(synthetic):
    edge = synthetic[0]
    base = tp.Tool(rake_angle=0.1, clearance_angle=0.2)
    tool = edge.tool(base)
    assert tool.nose_radius == edge.radius
    assert tool.rake_angle == 0.1 and tool.clearance_angle == 0.2
    assert tool.arc_half_angle == pytest.approx(math.radians(45))
    np.testing.assert_allclose(tool.waviness_angle, edge.waviness_angle)
    np.testing.assert_allclose(tool.waviness_deviation, edge.waviness_deviation)
    flat = edge.tool(base, compensated=True)
    assert flat.nose_radius == edge.radius and not flat.has_waviness
    hook = tp.MeasuredEdge(edge, compensated=True)
    assert hook.tool(base).has_waviness is False
    assert tp.MeasuredEdge(edge).tool(base).has_waviness


def test_deviation_beyond_the_first_order_model_is_refused():
    pts, _, _ = synthetic_trace(seed=2, bump=(10.0, 4e-6))  # 4 um > 1 % of R
    edge = tp.read_tool_edge(_csv(pts))
    with pytest.raises(ConfigError, match="above 1 % of the fitted radius"):
        edge.tool()
    assert not edge.tool(compensated=True).has_waviness  # the radius alone is fine


# ------------------------------------------------------------------- files
def test_laser_probe_header_and_count(synthetic, tmp_path):
    _, pts, _, _ = synthetic
    n = pts.shape[0]
    header = [
        "3D_003,24",
        "Type of measurement data,3D data in details.",
        f"Number of points in X direction,{n}",
        "Number of points in Y direction,1",
        "Pitch,Tracing axis : ,0.001000,Stepping axis : ,0.000000",
        " ",
        "X,Y,Z",
    ]
    path = tmp_path / "probe.csv"
    path.write_bytes(_csv(pts, z=-0.78, header=header))
    edge = tp.read_tool_edge(path)
    assert abs(edge.radius - R0) < POS_TOL
    assert edge.metadata["columns"] == ["X", "Y", "Z"]
    assert edge.metadata["header"]["Number of points in X direction"] == str(n)
    bad = _csv(pts[:-5], z=-0.78, header=header)
    with pytest.raises(CorruptedFileError,
                       match=f"declares {n} points but {n - 5} rows follow"):
        tp.read_tool_edge(io.BytesIO(bad))


def test_two_columns_and_units(synthetic):
    _, pts, _, _ = synthetic
    um_file = _csv(pts, unit_scale=1e6)
    edge = tp.read_tool_edge(um_file, unit="um")
    assert abs(edge.radius - R0) < POS_TOL
    with pytest.raises(ConfigError, match=r"probably in um \(pass unit='um'\)"):
        tp.read_tool_edge(um_file)  # read as mm: 1000 times too large
    with pytest.raises(UnitError, match="edge trace unit 'furlong'"):
        tp.read_tool_edge(_csv(pts), unit="furlong")


@pytest.mark.parametrize(
    "data,fragment",
    [
        (b"1,2\n" * 3 + b"1,abc\n", "line 4 is '1,abc'"),
        (b"1,2,3\n" * 3 + b"1,2\n", "line 4 has 2 values after rows of 3"),
        (b"1,2,3,4\n" * 12, "line 1 has 4 values"),
        (b"1,2\n" * 5, "trace has 5 point(s)"),
        (b"header only\nX,Y\n", "no numeric rows found"),
        (b"1,2\n" * 11 + b"nan,2\n", "point 12 is not finite"),
    ],
)
def test_damaged_trace_files(tmp_path, data, fragment):
    path = tmp_path / "bad.csv"
    path.write_bytes(data)
    with pytest.raises(CorruptedFileError) as info:
        tp.read_tool_edge(path)
    msg = str(info.value)
    assert "\n" not in msg and str(path) in msg and fragment in msg, msg


def test_no_nose_in_a_straight_trace():
    x = np.linspace(0, 1, 200)
    with pytest.raises(ConfigError, match="no usable nose arc|no circular nose"):
        tp.fit_tool_edge(np.column_stack([x, 0.5 * x]) * 1e-3)


def test_settings_refuse_unit_slips():
    with pytest.raises(ConfigError, match="degrees given as rad"):
        tp.EdgeSettings(half_angle=45.0)
    with pytest.raises(ConfigError, match="um given as m"):
        tp.EdgeSettings(smoothing=25.0)


# --------------------------------------------------------------- the real trace
def test_real_trace_against_independent_fits(upm_dir):
    path = upm_dir / "tool" / "r200.csv"
    edge = tp.read_tool_edge(io.BytesIO(path.read_bytes()))
    assert edge.u.size == 1830  # SOURCES.md: raw, 1830 points
    # inside the band of the three independent fits, within 1.5 % of the planner's
    assert KNOWN_FITS[0] <= edge.radius <= KNOWN_FITS[2]
    assert abs(edge.radius / KNOWN_FITS[1] - 1) < 0.015
    assert edge.metadata["flanks_found"] == 2
    assert edge.spike.sum() > 0  # the trace has spikes of several um
    assert edge.noise < 0.5e-6
    tool = edge.tool()
    assert tool.has_waviness and tool.nose_radius == edge.radius


def test_real_trace_figure(upm_dir, tmp_path):
    edge = tp.read_tool_edge(upm_dir / "tool" / "r200.csv")
    out = edge.plot(tmp_path / "edge.png")
    assert out.stat().st_size > 10_000


# ------------------------------------------------------------------- TOML, CLI
def _toml(tmp_path, tool_lines):
    (tmp_path / "t.toml").write_text(
        'kind = "facing"\n[tool]\n' + "\n".join(tool_lines) + "\n")
    return tmp_path / "t.toml"


def test_toml_edge_trace(synthetic, tmp_path):
    _, pts, _, _ = synthetic
    (tmp_path / "edge.csv").write_bytes(_csv(pts))
    spec = tp.load_toolpath(_toml(tmp_path, ['edge-trace = "edge.csv"',
                                             "clearance-angle-deg = 10"]))
    assert abs(spec.tool.nose_radius - R0) < POS_TOL
    assert spec.tool.has_waviness
    assert spec.tool.arc_half_angle == pytest.approx(math.radians(45))
    assert spec.tool.clearance_angle == pytest.approx(math.radians(10))
    spec = tp.load_toolpath(_toml(tmp_path, [
        'edge-trace = "edge.csv"', "edge-compensated = true",
        "edge-half-angle-deg = 30", "arc-half-angle-deg = 20"]))
    assert not spec.tool.has_waviness
    assert spec.tool.arc_half_angle == pytest.approx(math.radians(20))
    mirrored = tp.load_toolpath(_toml(tmp_path, ['edge-trace = "edge.csv"',
                                                 "edge-mirror = true"]))
    np.testing.assert_allclose(mirrored.tool.waviness_deviation,
                               spec_tool_dev_reversed(tmp_path), atol=1e-15)


def spec_tool_dev_reversed(tmp_path):
    spec = tp.load_toolpath(_toml(tmp_path, ['edge-trace = "edge.csv"']))
    return spec.tool.waviness_deviation[::-1]


@pytest.mark.parametrize(
    "lines,fragment",
    [
        (['edge-trace = "edge.csv"', "nose-radius = 1e-3"],
         "give either edge-trace"),
        (["edge-mirror = true"], "tool.edge-mirror needs tool.edge-trace"),
        (['edge-trace = "edge.csv"', 'edge-compensated = "yes"'],
         "tool.edge-compensated: expected bool, got str"),
        (['edge-trace = "missing.csv"'], "not found"),
    ],
)
def test_toml_edge_errors(synthetic, tmp_path, lines, fragment):
    (tmp_path / "edge.csv").write_bytes(_csv(synthetic[1]))
    with pytest.raises(ConfigError, match=fragment):
        tp.load_toolpath(_toml(tmp_path, lines))


def test_cli_edge_compensated_needs_tool(tmp_path, capsys):
    path = _toml(tmp_path, ["nose-radius = 0.5e-3"])
    assert main(["simulate", str(path), "--edge-compensated", "--out",
                 str(tmp_path / "o")]) == 1
    assert "--edge-compensated needs --tool" in capsys.readouterr().err


def test_cli_simulate_with_measured_edge(synthetic, tmp_path, capsys):
    import json

    _, pts, _, _ = synthetic
    (tmp_path / "edge.csv").write_bytes(_csv(pts, z=0.0))
    (tmp_path / "f.toml").write_text(
        'kind = "facing"\n[facing]\nfeed-per-rev = 25e-6\nspindle-speed-rpm = 250\n'
        "r-start = 5.2e-3\nr-end = 4.8e-3\ndepth-of-cut = 2e-6\n[tool]\n"
        "nose-radius = 0.5e-3\n[field]\npitch-x = 1e-6\npitch-y = 1e-6\nnx = 160\n"
        "ny = 24\ncenter-x = 5e-3\n")
    runs = {}
    for name, extra in (("edge", []), ("compensated", ["--edge-compensated"])):
        rc = main(["simulate", str(tmp_path / "f.toml"), "--tool",
                   str(tmp_path / "edge.csv"), *extra, "--parts", "tracking",
                   "--instrument", "none", "--no-render", "--out",
                   str(tmp_path / name), "--json"])
        assert rc == 0
        runs[name] = json.loads(capsys.readouterr().out)
    out = runs["edge"]
    assert abs(out["tool_edge"]["nose_radius_m"] - R0) < POS_TOL
    assert out["tool_edge"]["compensated"] is False
    assert runs["compensated"]["tool_edge"]["compensated"] is True
    assert out["settings"]["hooks"] == ["MeasuredEdge"]
    assert (tmp_path / "edge" / "tool_edge.png").stat().st_size > 0
    # only the fitted radius: scallops of a 200 um nose at 25 um/rev, h = f^2 /
    # (8 R), whose Ra (parabolic arcs) is 4 h / (9 sqrt 3)
    h = 25e-6**2 / (8 * R0)
    ra_round = runs["compensated"]["ra_m"]
    assert ra_round == pytest.approx(4 * h / (9 * math.sqrt(3)), rel=0.01)
    # with the deviation the 0.2 um waviness (60 um long waves) reshapes them
    assert abs(out["ra_m"] / ra_round - 1) > 0.03


def test_cli_nc_program_with_a_measured_edge_needs_no_radius(synthetic, tmp_path,
                                                            capsys):
    import json

    _, pts, _, _ = synthetic
    (tmp_path / "edge.csv").write_bytes(_csv(pts, z=0.0))
    # a flat facing program: 25 um per revolution from r = 0.4 mm to the axis,
    # 2 degree blocks; it states no nose radius
    c = np.arange(16 * 180 + 1) * 2.0
    x = 0.4 - 0.025 * c / 360.0
    (tmp_path / "p.nc").write_text(
        "G71\n" + "\n".join(f"C{a:g} X{b:.9f} Z0" for a, b in
                             zip(c, x, strict=True)) + "\n")
    runs = {}
    for name, extra in (("edge", []), ("round", ["--edge-compensated"])):
        rc = main(["simulate", str(tmp_path / "p.nc"), "--block-time", "1e-3",
                   "--tool", str(tmp_path / "edge.csv"), *extra, "--out",
                   str(tmp_path / name), "--json"])
        assert rc == 0
        runs[name] = json.loads(capsys.readouterr().out)
        assert (tmp_path / name / "tool_edge.png").stat().st_size > 0
    out = runs["edge"]
    assert abs(out["tool_edge"]["nose_radius_m"] - R0) < POS_TOL
    assert out["settings"]["hooks"] == ["MeasuredEdge"]
    assert out["settings"]["nc"]["reference"] == "tip"
    # the swept shape (0.2 um waves, 60 um long) reshapes the cusps of the round
    # nose, whose Ra for parabolic arcs of h = f^2 / (8 R) is 4 h / (9 sqrt 3)
    h = 25e-6**2 / (8 * R0)
    ra_round = runs["round"]["ra_m"]
    assert ra_round == pytest.approx(4 * h / (9 * math.sqrt(3)), rel=0.02)
    assert abs(out["ra_m"] / ra_round - 1) > 0.03
    # the same as a toolpath file of kind nc: the trace gives the radius
    (tmp_path / "p.toml").write_text(
        'kind = "nc"\n[nc]\nprogram = "p.nc"\nblock-time = 1e-3\n'
        '[tool]\nedge-trace = "edge.csv"\n')
    spec = tp.load_toolpath(tmp_path / "p.toml")
    assert abs(spec.tool.nose_radius - R0) < POS_TOL and spec.tool.has_waviness


def test_cli_tool_edge_writes_a_reusable_waviness_csv(synthetic, tmp_path, capsys):
    import json

    edge, pts, _, _ = synthetic
    (tmp_path / "edge.csv").write_bytes(_csv(pts, z=-0.8435))
    rc = main(["tool-edge", str(tmp_path / "edge.csv"), "--half-angle-deg", "30",
               "--out", str(tmp_path / "o"), "--json"])
    assert rc == 0
    out = json.loads(capsys.readouterr().out)
    np.testing.assert_allclose(out["arc_rad"], [-math.radians(30), math.radians(30)])
    assert abs(out["nose_radius_m"] - R0) < POS_TOL
    # the CSV is the existing edge-waviness format: read back by the toolpath reader
    ang, dev = tp.read_waviness_csv(tmp_path / "o" / "edge_waviness.csv")
    narrow = tp.read_tool_edge(tmp_path / "edge.csv",
                               settings=tp.EdgeSettings(half_angle=math.radians(30)))
    np.testing.assert_allclose(ang, narrow.waviness_angle, atol=1e-7)  # 6 digits
    np.testing.assert_allclose(dev, narrow.waviness_deviation, rtol=1e-5,
                               atol=1e-15)
    assert (tmp_path / "o" / "tool_edge.png").stat().st_size > 0
    assert main(["tool-edge", str(tmp_path / "edge.csv"), "--out",
                 str(tmp_path / "p")]) == 0
    assert "nose radius" in capsys.readouterr().out
