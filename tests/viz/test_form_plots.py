"""Form-error and design-toolpath figures: each writes a non-empty PNG."""

from __future__ import annotations

import numpy as np
import pytest

import servosurf.toolpath as tp
from servosurf.errors import ConfigError
from servosurf.metrology import Surface, form_error_against_design
from servosurf.viz import plot_design_feed, plot_form_error

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


def _is_png(path) -> bool:
    data = path.read_bytes()
    return len(data) > 1000 and data[:8] == PNG_MAGIC


@pytest.mark.parametrize("bfs", [False, True])
def test_plot_form_error(tmp_path, bfs):
    design = tp.Sphere(radius=0.02)
    x = (np.arange(64) - 32) * 1e-6
    rng = np.random.default_rng(5)  # noise only
    z = design.sag(x[None, :], x[:, None]) + rng.normal(0, 2e-9, (64, 64))
    fe = form_error_against_design(Surface(z, 1e-6, 1e-6, x0=x[0], y0=x[0]), design,
                                   best_fit_sphere=bfs)
    out = plot_form_error(fe, tmp_path / "fe.png", title="sphere")
    assert out == tmp_path / "fe.png" and _is_png(out)
    with pytest.raises(ConfigError, match="DesignFormError"):
        plot_form_error(fe.error, tmp_path / "x.png")


def test_plot_design_feed(tmp_path):
    path = tp.DesignToolpath(design=tp.Sphere(radius=-0.02), r_start=1e-3,
                             r_end=0.0, scallop_height=20e-9)
    out = plot_design_feed(path, tmp_path / "feed.png")
    assert _is_png(out)
    with pytest.raises(ConfigError, match="DesignToolpath"):
        plot_design_feed(tp.FacingToolpath(), tmp_path / "x.png")
