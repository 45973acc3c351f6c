"""Surface, form-error and spectrum figures: each writes a non-empty PNG."""

from __future__ import annotations

import sys

import numpy as np
import pytest

from servosurf.errors import ConfigError
from servosurf.metrology import (
    Surface,
    find_peaks_spectrum,
    form_error_profile,
    high_pass,
    nominal_lenslet_profile,
    nominal_lenslet_surface,
    psd_1d,
)
from servosurf.viz._surface_plots import (
    plot_filtered_map,
    plot_map,
    plot_profile_with_form_error,
    plot_spectrum,
)

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"
LENS = dict(
    amplitude=10e-6, frequency=100.0, speed=42.3e-3, depth=5e-6, tool_radius=0.5e-3
)


def _is_png(path) -> bool:
    data = path.read_bytes()
    return len(data) > 1000 and data[:8] == PNG_MAGIC


@pytest.fixture()
def lens_surface():
    rng = np.random.default_rng(1234)
    x = (np.arange(96) - 48) * 2e-6
    z = nominal_lenslet_surface(x, x, **LENS) + rng.normal(0, 3e-9, (96, 96))
    z[:4, :4] = np.nan
    return Surface(z, 2e-6, 2e-6, x0=x[0], y0=x[0])


@pytest.mark.parametrize("unit", ["nm", "um"])
def test_plot_map(tmp_path, lens_surface, unit):
    out = plot_map(lens_surface, tmp_path / "map.png", title="lenslet", unit=unit)
    assert out == tmp_path / "map.png" and _is_png(out)
    assert [p.name for p in tmp_path.iterdir()] == ["map.png"]  # no temp file left


def test_plot_map_uncalibrated_and_new_folder(tmp_path):
    s = Surface(np.arange(12.0).reshape(3, 4) * 1e-9, None, None)
    out = plot_map(s, tmp_path / "sub" / "m.png")
    assert _is_png(out)


def test_plot_map_rejects_unknown_unit(tmp_path, lens_surface):
    with pytest.raises(ConfigError, match="unit"):
        plot_map(lens_surface, tmp_path / "m.png", unit="mm")
    assert not any(tmp_path.iterdir())


def test_plot_filtered_map(tmp_path, lens_surface):
    hp = high_pass(lens_surface, 1 / 80e3)
    out = plot_filtered_map(
        lens_surface,
        hp,
        tmp_path / "f.png",
        cutoff=1 / 80e3,
        title="80 mm^-1 high-pass",
    )
    assert _is_png(out)


def test_plot_profile_with_form_error(tmp_path):
    x = np.arange(-100e-6, 100e-6, 0.5e-6)
    nominal = nominal_lenslet_profile(x, **LENS)
    measured = nominal + 100e-9 * np.exp(-0.5 * ((x - 15e-6) / 8e-6) ** 2)
    res = form_error_profile(x, measured, nominal)
    out = plot_profile_with_form_error(
        x, measured, res["reference"], res["error"], tmp_path / "form.png", title="form"
    )
    assert _is_png(out)
    with pytest.raises(ConfigError, match="same length"):
        plot_profile_with_form_error(
            x, measured[:-1], nominal, res["error"], tmp_path / "bad.png"
        )


def test_plot_spectrum_with_speed(tmp_path):
    rng = np.random.default_rng(1234)
    x = np.arange(1024) * 0.4e-6
    z = 2e-9 * np.sin(2 * np.pi * 1.7e5 * x) + rng.normal(0, 0.3e-9, (16, 1024))
    f, p = psd_1d(z, 0.4e-6)
    peaks = find_peaks_spectrum(f, p, n=3)
    assert _is_png(plot_spectrum(f, p, peaks, tmp_path / "s.png", speed=42.3e-3))
    assert _is_png(plot_spectrum(f, p, [], tmp_path / "s2.png"))
    with pytest.raises(ConfigError):
        plot_spectrum(f, p, peaks, tmp_path / "s3.png", speed=-1.0)


def test_matplotlib_not_loaded_by_import_servosurf():
    # matplotlib is imported inside the plotting functions only
    import subprocess

    code = (
        "import sys, servosurf, servosurf.metrology, servosurf.viz._surface_plots;"
        "print('matplotlib' in sys.modules)"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True
    )
    assert out.stdout.strip() == "False"
