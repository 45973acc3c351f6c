"""Chip section and workpiece files."""

from __future__ import annotations

import numpy as np
import pytest

from servosurf.cutting import (
    ChipModel,
    facing_chip_area,
    load_workpiece,
    segment_area,
)
from servosurf.errors import ConfigError
from servosurf.kernels._lti import _segment_area


def test_segment_area_closed_form_and_kernel():
    r = 0.5e-3
    d = np.array([0.0, 1e-6, 5e-6, 10e-6, 0.5e-3])
    # exact: half disc at d = R; about (2/3) chord d for d << R
    np.testing.assert_allclose(segment_area(r, d[-1]), np.pi * r**2 / 2, rtol=1e-12)
    chord = 2 * np.sqrt(2 * r * 5e-6 - 25e-12)
    np.testing.assert_allclose(segment_area(r, 5e-6), 2 / 3 * chord * 5e-6, rtol=0.01)
    for di in d:
        np.testing.assert_allclose(
            _segment_area(r, di), segment_area(r, di), rtol=1e-12
        )
    # the paper's 5 um lenslet: about 471 um^2
    np.testing.assert_allclose(segment_area(r, 5e-6), 471e-12, rtol=0.01)


def test_chip_model_force():
    chip = ChipModel(1e9, 0.5e-3, 0.0)
    assert chip.force(np.array([1e-6]))[0] == 0.0  # tool above the face
    np.testing.assert_allclose(
        chip.force(np.array([-5e-6]))[0], 1e9 * segment_area(0.5e-3, 5e-6)
    )


def test_facing_chip_area_is_feed_times_depth():
    # with a feed much smaller than the chord, the section is ~ feed * depth
    a = facing_chip_area(0.5e-3, 2e-6, 5e-6)
    np.testing.assert_allclose(a, 2e-6 * 5e-6, rtol=0.02)


def test_workpiece_file_and_errors(tmp_path):
    wp = load_workpiece("workpieces/nip.toml")
    assert wp.material.specific_thrust_pressure > 0
    p = tmp_path / "w.toml"
    p.write_text("[material]\nspecific-thrust-presure = 1e9\n")
    with pytest.raises(
        ConfigError, match="Did you mean: material.specific-thrust-pressure"
    ):
        load_workpiece(p)
    p.write_text('[precut]\nkind = "file"\n')
    with pytest.raises(ConfigError, match="precut.file"):
        load_workpiece(p)
