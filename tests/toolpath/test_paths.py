"""Toolpath definitions, the tool, the field and the TOML files."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

import servosurf.toolpath as tp
from servosurf.errors import ConfigError

TOOLPATHS = Path(__file__).resolve().parents[2] / "toolpaths"


@pytest.mark.parametrize(("depth", "speed"), [(5e-6, 42.3e-3), (10e-6, 59.7e-3)])
def test_cutting_length_equals_width_gives_the_paper_speeds(depth, speed):
    # seed paper 5.3: 42.3 mm/s (5 um lenslets) and 59.7 mm/s (10 um lenslets)
    v = tp.lenslet_surface_speed(0.5e-3, depth, 100.0)
    assert v == pytest.approx(speed, rel=0.005)
    assert tp.lenslet_cut_fraction(2 * depth, depth) == pytest.approx(1 / 3)
    # the chord at depth d is the cut length v / (3 f)
    assert tp.lenslet_chord(0.5e-3, depth) == pytest.approx(v / 300.0)


@pytest.mark.parametrize("name", ["flat_facing", "lenslet_5um", "lenslet_10um"])
def test_shipped_toolpaths_load(name):
    spec = tp.load_toolpath(TOOLPATHS / f"{name}.toml")
    assert spec.tool.nose_radius == 0.5e-3
    assert spec.tool.clearance_angle == pytest.approx(math.radians(15))
    assert spec.tool.rake_angle == 0.0
    if spec.kind == "facing":
        assert spec.path.spindle_speed == pytest.approx(250 / 60)
        assert spec.path.feed_per_rev == 2e-6
        assert spec.path.depth_of_cut == 5e-6
        rmin, rmax = spec.field.radial_range()
        reach = spec.tool.chord_half_width(spec.path.depth_of_cut)
        assert spec.path.r_end < rmin - reach and rmax + reach < spec.path.r_start
    else:
        p = spec.path
        assert p.depth_of_cut == p.amplitude / 2
        v = tp.lenslet_surface_speed(spec.tool.nose_radius, p.depth_of_cut,
                                     p.frequency)
        assert p.surface_speed == pytest.approx(v, rel=0.005)
        assert p.actual_surface_speed == pytest.approx(v, rel=0.01)
        assert spec.field.center_x in p.ring_radii()


def test_lenslet_path_geometry():
    p = tp.LensletToolpath()
    n = p.lenslets_per_ring
    assert n == round(2 * math.pi * 10e-3 * 100 / 42.3e-3)
    t = np.linspace(0, p.duration, 200001)
    theta, r, z = p.evaluate(t)
    assert np.all(np.diff(theta) > 0) and np.all(np.diff(r) <= 0)
    assert z.min() == pytest.approx(-5e-6) and z.max() == pytest.approx(15e-6)
    # the ring changes only while the tool is above the face
    moving = np.diff(r) != 0
    assert moving.any()
    assert np.all(z[1:][moving] > 4e-6) and np.all(z[:-1][moving] > 4e-6)
    # lenslet centres (deepest points) sit at multiples of 2 pi / N
    tc = (0.25 + np.arange(3 * n)) / p.frequency
    ang = p.theta_at(tc) * n / (2 * math.pi)
    np.testing.assert_allclose(ang, np.round(ang), atol=1e-9)
    assert p.radius_at(np.array([0.0, p.duration]))[1] == pytest.approx(9.6e-3)


def test_facing_path():
    p = tp.FacingToolpath()
    assert p.duration == pytest.approx(120.0)
    assert p.n_revolutions == pytest.approx(500.0)
    t0, t1 = p.time_span_for_radius(4.9e-3, 5.1e-3)
    assert p.radius_at(np.array([t0, t1])) == pytest.approx([5.1e-3, 4.9e-3])
    assert p.time_span_for_radius(6e-3, 7e-3) is None


def test_unknown_key_suggests(tmp_path):
    f = tmp_path / "bad.toml"
    f.write_text('kind = "facing"\n[facing]\nfeed-per-revv = 2e-6\n')
    with pytest.raises(ConfigError, match="Did you mean: facing.feed-per-rev"):
        tp.load_toolpath(f)
    f.write_text('kind = "facing"\n[feld]\n')
    with pytest.raises(ConfigError, match="Did you mean: field"):
        tp.load_toolpath(f)
    f.write_text('kind = "turning"\n')
    with pytest.raises(ConfigError, match="kind"):
        tp.load_toolpath(f)


def test_aliases_and_conflicts(tmp_path):
    f = tmp_path / "a.toml"
    f.write_text('kind = "facing"\n[facing]\nspindle-speed = 2.0\n'
                 'spindle-speed-rpm = 120\n')
    with pytest.raises(ConfigError, match="not both"):
        tp.load_toolpath(f)
    f.write_text('kind = "facing"\n[facing]\nspindle-speed-rpm = 120\n'
                 '[tool]\nclearance-angle-deg = 10\narc-half-angle = 0.5\n')
    spec = tp.load_toolpath(f)
    assert spec.path.spindle_speed == pytest.approx(2.0)
    assert spec.tool.clearance_angle == pytest.approx(math.radians(10))
    assert spec.tool.arc_half_angle == 0.5
    f.write_text('kind = "facing"\n[facing]\nr-start = 1e-3\nr-end = 2e-3\n')
    with pytest.raises(ConfigError, match="inward"):
        tp.load_toolpath(f)


def test_waviness_csv(tmp_path):
    (tmp_path / "edge.csv").write_text(
        "# measured edge\nangle_deg,deviation_m\n-60,1e-8\n0,0\n60,-1e-8\n")
    f = tmp_path / "w.toml"
    f.write_text('kind = "lenslet"\n[tool]\nedge-waviness = "edge.csv"\n')
    tool = tp.load_toolpath(f).tool
    assert tool.waviness_angle == pytest.approx((-math.pi / 3, 0.0, math.pi / 3))
    s0, ds, table = tool.waviness_table()
    s = s0 + ds * np.arange(table.size)
    phi = np.arcsin(s)
    expect = np.interp(phi, tool.waviness_angle, tool.waviness_deviation) / np.cos(phi)
    np.testing.assert_allclose(table, expect, rtol=0, atol=1e-15)  # 1 fm
    (tmp_path / "bad.csv").write_text("angle_furlong,deviation_m\n1,2\n")
    f.write_text('kind = "lenslet"\n[tool]\nedge-waviness = "bad.csv"\n')
    with pytest.raises(ConfigError, match="angle_deg or angle_rad"):
        tp.load_toolpath(f)


def test_tool_and_field_checks():
    with pytest.raises(ConfigError, match="same length"):
        tp.Tool(waviness_angle=(0.0, 1.0), waviness_deviation=(0.0,))
    assert tp.Tool().half_width == pytest.approx(0.5e-3 * math.sin(math.radians(60)))
    assert tp.Tool().chord_half_width(5e-6) == pytest.approx(70.53e-6, rel=1e-3)
    f = tp.Field(pitch_x=1e-6, pitch_y=2e-6, nx=11, ny=5, center_x=1e-3, center_y=0.0)
    x, y = f.coords()
    assert x[5] == pytest.approx(1e-3) and y[2] == pytest.approx(0.0)
    assert f.angular_window() is not None
    assert tp.Field(center_x=0.0).angular_window() is None
    sub = f.subfield(1, 3, 2, 6)
    np.testing.assert_allclose(sub.coords()[0], x[2:6], rtol=0, atol=1e-18)
    with pytest.raises(ConfigError):
        tp.Field(nx=0)
