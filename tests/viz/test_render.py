"""3-D renders: a non-blank PNG from pyvista off-screen, or from the fallback."""

from __future__ import annotations

import gc
import sys

import numpy as np
import pytest

from servosurf.errors import ConfigError
from servosurf.metrology import Surface, nominal_lenslet_surface
from servosurf.viz import _render
from servosurf.viz._render import RenderFallbackWarning, render_surface

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"
LENS = dict(
    amplitude=10e-6, frequency=100.0, speed=42.3e-3, depth=5e-6, tool_radius=0.5e-3
)
#: A rendered surface covers much of the image in many colours; a blank or
#: single-colour image has a pixel standard deviation near 0 (8-bit levels).
MIN_PIXEL_STD = 10.0
SMALL = (320, 240)  # window size in pixels: keeps the tests fast


def _pixel_std(path) -> float:
    from matplotlib.image import imread

    img = imread(path)  # floats in 0..1 for PNG
    return float(np.std(img[..., :3]) * 255)


def _assert_png(path) -> None:
    assert path.read_bytes()[:8] == PNG_MAGIC
    assert _pixel_std(path) > MIN_PIXEL_STD
    assert [p.name for p in path.parent.iterdir()] == [path.name]  # no temp file


def _pyvista_plotters() -> list:
    pv = pytest.importorskip("pyvista")
    gc.collect()
    return [o for o in gc.get_objects() if isinstance(o, pv.Plotter)]


@pytest.fixture()
def no_plotter_leak():
    """Every Plotter a test opens is closed and collectable afterwards."""
    from pyvista.plotting.plotter import _ALL_PLOTTERS

    before = len(_pyvista_plotters())
    open_before = set(_ALL_PLOTTERS)
    yield
    assert set(_ALL_PLOTTERS) <= open_before, "a Plotter was left open"
    assert len(_pyvista_plotters()) <= before, "a Plotter is still referenced"


@pytest.fixture()
def lens():
    rng = np.random.default_rng(1234)  # 3 nm noise on a 5 um deep lenslet
    x = (np.arange(120) - 60) * 1e-6
    z = nominal_lenslet_surface(x, x, **LENS) + rng.normal(0, 3e-9, (120, 120))
    z[10:25, 30:60] = np.nan
    return Surface(z, 1e-6, 1e-6, x0=x[0], y0=x[0])


@pytest.fixture()
def needs_offscreen():
    reason = _render._offscreen_problem()
    if reason is not None:
        pytest.skip(f"pyvista cannot render off-screen here: {reason}")


def test_pyvista_render_is_a_non_blank_png(
    tmp_path, lens, needs_offscreen, no_plotter_leak
):
    out = render_surface(
        lens,
        tmp_path / "lens.png",
        title="lenslet",
        window_size=SMALL,
        backend="pyvista",
    )
    assert out == tmp_path / "lens.png"
    _assert_png(out)
    from matplotlib.image import imread

    assert imread(out).shape[:2] == (SMALL[1], SMALL[0])


def test_auto_backend_uses_pyvista_without_warnings(
    tmp_path, lens, needs_offscreen, no_plotter_leak
):
    # filterwarnings=error: a RenderFallbackWarning would fail this test
    out = render_surface(
        lens,
        tmp_path / "a" / "lens.png",
        z_exaggeration=2.0,
        cmap="magma",
        window_size=SMALL,
    )
    _assert_png(out)


def test_large_maps_are_decimated(tmp_path, needs_offscreen, no_plotter_leak):
    assert _render._stride((1000, 1200), _render.MAX_RENDER_POINTS) == 2
    assert _render._stride((1000, 1000), _render.MAX_RENDER_POINTS) == 1
    assert _render._stride((3, 2_000_001), _render.MAX_RENDER_POINTS) == 3
    rng = np.random.default_rng(5)  # 1.2 M pixels of 1 nm noise on a tilt
    z = rng.normal(0, 1e-9, (1000, 1200)) + np.linspace(0, 1e-7, 1200)
    out = render_surface(
        Surface(z, 0.2e-6, 0.2e-6), tmp_path / "big.png", window_size=SMALL
    )
    _assert_png(out)


def test_matplotlib_backend(tmp_path, lens):
    out = render_surface(
        lens,
        tmp_path / "m.png",
        title="lenslet",
        window_size=SMALL,
        backend="matplotlib",
    )
    _assert_png(out)


def test_fallback_when_offscreen_rendering_is_unavailable(
    tmp_path, lens, monkeypatch, no_plotter_leak
):
    monkeypatch.setattr(_render, "_offscreen_problem", lambda: "no display (test)")
    with pytest.warns(RenderFallbackWarning, match="no display"):
        out = render_surface(lens, tmp_path / "f.png", window_size=SMALL)
    _assert_png(out)


def test_fallback_when_the_pyvista_render_raises(
    tmp_path, lens, monkeypatch, no_plotter_leak
):
    def broken(*args, **kwargs):
        raise RuntimeError("OpenGL context lost")

    monkeypatch.setattr(_render, "_offscreen_problem", lambda: None)
    monkeypatch.setattr(_render, "_render_pyvista", broken)
    with pytest.warns(RenderFallbackWarning, match="OpenGL context lost"):
        out = render_surface(lens, tmp_path / "g.png", window_size=SMALL)
    _assert_png(out)
    with pytest.raises(RuntimeError, match="context lost"):  # forced back-end
        render_surface(lens, tmp_path / "h.png", window_size=SMALL, backend="pyvista")
    assert not (tmp_path / "h.png").exists()


def test_missing_pyvista_raises_import_error(tmp_path, lens, monkeypatch):
    monkeypatch.setitem(sys.modules, "pyvista", None)
    with pytest.raises(ImportError, match="pip install pyvista"):
        render_surface(lens, tmp_path / "x.png")
    out = render_surface(
        lens, tmp_path / "y.png", window_size=SMALL, backend="matplotlib"
    )  # matplotlib alone still works
    _assert_png(out)


def test_scene_units_and_auto_exaggeration(lens):
    scene = _render._scene(lens, 1, None)
    h = scene["height_nm"]
    assert abs(h.mean()) < 1e-6  # nm: heights about their mean
    np.testing.assert_allclose(
        np.ptp(h) * 1e-9, np.nanmax(lens.z) - np.nanmin(lens.z), rtol=0, atol=1e-12
    )  # 1 pm
    # drawn relief: between AUTO_RELIEF / 5 and AUTO_RELIEF of the 119 um extent
    exag = scene["exaggeration"]
    relief = np.ptp(scene["points"][:, 2]) / 119.0
    assert _render.AUTO_RELIEF / 5 < relief <= _render.AUTO_RELIEF
    mantissa = exag / 10 ** np.floor(np.log10(exag))
    assert min(abs(mantissa - m) for m in (1, 2, 5)) < 1e-9
    assert scene["xtitle"] == "x (um)" and "nm" in scene["bar_title"]
    assert scene["ztitle"] == f"z (um, drawn x{exag:g})"
    flat = _render._scene(Surface(np.zeros((3, 3)), None, None), 1, None)
    assert flat["exaggeration"] == 1.0 and flat["xtitle"] == "x (px)"


@pytest.mark.parametrize(
    "kwargs",
    [
        {"cmap": "no-such-map"},
        {"backend": "vtk"},
        {"z_exaggeration": -1.0},
        {"window_size": (4, 4)},
        {"title": 3},
    ],
)
def test_bad_options_raise_config_error(tmp_path, lens, kwargs):
    with pytest.raises(ConfigError):
        render_surface(lens, tmp_path / "bad.png", **kwargs)
    assert not any(tmp_path.iterdir())


def test_all_nan_map_raises(tmp_path):
    with pytest.raises(ConfigError, match="2 x 2"):
        render_surface(
            Surface(np.full((4, 4), np.nan), 1e-6, 1e-6),
            tmp_path / "n.png",
            backend="matplotlib",
        )
