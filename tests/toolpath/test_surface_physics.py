"""Physics oracles of the swept surface: kinematic roughness, lenslet size."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

import servosurf.toolpath as tp

try:  # tests/ on sys.path (rootdir-relative packages)
    from reference import RTOL_KINEMATIC
except ImportError:  # tests/ itself is a package
    from tests.reference import RTOL_KINEMATIC

TOOLPATHS = Path(__file__).resolve().parents[2] / "toolpaths"


def test_facing_kinematic_roughness():
    """Rt = f^2 / (8 R), Ra = f^2 / (18 sqrt(3) R): 1.000 and 0.257 nm (Table 2)."""
    spec = tp.load_toolpath(TOOLPATHS / "flat_facing.toml")
    f = spec.path.feed_per_rev
    R = spec.tool.nose_radius
    # radial profile across 10 feed marks at 20 nm pitch along +x (radial), centred
    # on the pass at r = 5 mm so that samples fall on the cusps (1001 points; the
    # statistics use 1000 = 10 whole periods)
    field = tp.Field(pitch_x=20e-9, pitch_y=20e-9, nx=1001, ny=3, center_x=5e-3)
    path = tp.sample(spec, field=field)
    z = tp.sweep(path, spec.tool, field).z[1, :1000]
    rt = z.max() - z.min()
    ra = np.mean(np.abs(z - z.mean()))
    assert rt == pytest.approx(f**2 / (8 * R), rel=RTOL_KINEMATIC)
    assert ra == pytest.approx(f**2 / (18 * math.sqrt(3) * R), rel=RTOL_KINEMATIC)
    assert f**2 / (8 * R) == pytest.approx(1.000e-9, rel=1e-3)
    assert f**2 / (18 * math.sqrt(3) * R) == pytest.approx(0.257e-9, rel=2e-3, abs=0.0)
    # the deepest point of each pass is at the commanded depth
    assert z.min() == pytest.approx(-spec.path.depth_of_cut, abs=1e-12)  # 1 pm


@pytest.mark.parametrize(("name", "depth"), [("lenslet_5um", 5e-6),
                                             ("lenslet_10um", 10e-6)])
def test_lenslet_size(name, depth):
    """A lenslet is as long as it is wide (chord at depth d) and d deep."""
    spec = tp.load_toolpath(TOOLPATHS / f"{name}.toml")
    p = spec.path
    chord = tp.lenslet_chord(spec.tool.nose_radius, depth)
    pitch = 1e-6
    n = int(1.3 * chord / pitch) | 1
    field = tp.Field(pitch_x=pitch, pitch_y=pitch, nx=n, ny=n,
                     center_x=spec.field.center_x, center_y=0.0)
    path = tp.sample(spec, field=field, fs=50e3)
    z = tp.sweep(path, spec.tool, field).z
    c = n // 2
    assert z.min() == pytest.approx(-depth, abs=2e-9)  # 2 nm
    width = np.count_nonzero(z[c] < -1e-12) * pitch
    length = np.count_nonzero(z[:, c] < -1e-12) * pitch
    assert width == pytest.approx(chord, abs=2 * pitch)
    # along the cut the length is v / (3 f) at this ring's radius
    v_ring = 2 * math.pi * spec.field.center_x * p.rev_per_s
    assert length == pytest.approx(v_ring / (3 * p.frequency), abs=2 * pitch)
    assert length == pytest.approx(chord, rel=0.03)
    # outside the lenslet the pre-cut face is untouched
    assert z[0, 0] == 0.0
