"""Segmentation of a lenslet array map into lenslets."""

from __future__ import annotations

import numpy as np
import pytest

from servosurf.errors import ConfigError
from servosurf.metrology import Surface, find_deepest_point, segment_lenslets
from servosurf.metrology import nominal_lenslet_surface as lens

LENS = dict(
    amplitude=10e-6, frequency=100.0, speed=42.3e-3, depth=5e-6, tool_radius=0.5e-3
)
D = 2e-6  # m
#: Sub-pixel centre accuracy, in pixels.
CENTRE_ATOL_PX = 0.1
#: Depth accuracy, in m (noise of 3 nm; the 99th percentile top sits ~7 nm high).
DEPTH_ATOL = 20e-9


def _array_map(rng):
    """2 x 3 lenslets (pitch 180 um in x, 240 um in y), sub-pixel offsets, noise."""
    x = np.arange(300) * D
    y = np.arange(200) * D
    centres = [
        (cx + ox * D, cy + oy * D)
        for (cy, oy) in ((100e-6, 0.3), (340e-6, -0.2))
        for (cx, ox) in ((110e-6, 0.25), (290e-6, -0.4), (470e-6, 0.1))
    ]
    z = np.min([lens(x, y, **LENS, centre=c) for c in centres], axis=0)
    return z + rng.normal(0.0, 3e-9, z.shape), centres


def test_segments_all_lenslets_with_subpixel_centres():
    rng = np.random.default_rng(1234)
    z, centres = _array_map(rng)
    found = segment_lenslets(Surface(z, D, D))
    assert len(found) == 6
    # reading order: the first row of three, then the second (centres listed so)
    for got, (cx, cy) in zip(found, centres, strict=True):
        assert abs(got["centre_x_m"] - cx) < CENTRE_ATOL_PX * D
        assert abs(got["centre_y_m"] - cy) < CENTRE_ATOL_PX * D
        np.testing.assert_allclose(got["depth_m"], 5e-6, atol=DEPTH_ATOL)
        r0, c0, r1, c1 = got["bbox"]
        assert r0 <= cy / D <= r1 and c0 <= cx / D <= c1
        assert got["area_m2"] > 0
    # the second row of lenslets reaches the bottom edge of the map
    assert [d["touches_border"] for d in found] == [False] * 3 + [True] * 3


def test_depth_threshold_and_offsets():
    rng = np.random.default_rng(1234)
    z, _ = _array_map(rng)
    s = Surface(z, D, D, x0=1e-3, y0=-5e-4)
    found = segment_lenslets(s, depth_threshold=4.9e-6)
    assert len(found) == 6  # only the bowls' bottoms, still one region each
    assert all(d["centre_x_m"] > 1e-3 for d in found)
    shallow = segment_lenslets(s, depth_threshold=4.99e-6, min_area=10_000)
    assert shallow == []


def test_flat_map_has_no_lenslets_and_errors():
    assert segment_lenslets(Surface(np.zeros((20, 20)), D, D)) == []
    with pytest.raises(ConfigError):
        segment_lenslets(Surface(np.full((4, 4), np.nan), D, D))
    with pytest.raises(ConfigError):
        segment_lenslets(Surface(np.zeros((4, 4)), D, D), depth_threshold=-1.0)


def test_find_deepest_point_uncalibrated_pixels():
    x = (np.arange(81) - 40.0) * D
    z = lens(x, x, **LENS, centre=(0.3 * D, -0.2 * D))
    fi, fj = find_deepest_point(Surface(z, None, None))
    np.testing.assert_allclose([fi, fj], [39.8, 40.3], atol=CENTRE_ATOL_PX)
    with pytest.raises(ConfigError, match="window"):
        find_deepest_point(Surface(z, None, None), window=0)
