"""Diagnosis pictures: every kind writes a PNG of the data it is given, in display
units, with the located mismatches marked."""

from __future__ import annotations

import numpy as np
import pytest

import servosurf.viz._diagnosis_plots as dp
from servosurf.viz import diagnosis_figures

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


def _data() -> dict[str, dict]:
    rng = np.random.default_rng(11)
    f = np.geomspace(10.0, 5000.0, 200)
    t = np.arange(256) / 10e3
    h = 1.0 / (1.0 + 1j * f / 400.0)
    img = rng.normal(0, 3e-9, (24, 32))
    img[0, :5] = np.nan
    pos = np.linspace(-1e-3, 1e-3, 300)
    return {
        "idle_spectrum": {
            "kind": "spectrum",
            "recording": "idle",
            "records": 4,
            "frequency_hz": f,
            "measured_m2_per_hz": 1e-20 * (1 + rng.random(200)),
            "before_m2_per_hz": np.full(200, 1e-20),
            "after_m2_per_hz": np.full(200, 1.5e-20),
            "marks": [{"band_hz": (100.0, 200.0)}, {"frequency_hz": 1000.0}],
        },
        "cut_residual": {
            "kind": "residual",
            "recording": "cut",
            "time_s": t,
            "residual_before_m": 5e-9 * np.sin(2e3 * t),
            "residual_after_m": 1e-9 * np.sin(2e3 * t),
            "band_centre_before_hz": f[::20],
            "whitened_power_before": np.full(10, 3.0),
            "band_centre_after_hz": f[::20],
            "whitened_power_after": np.full(10, 2.0),
            "force_residual_before_n": 2e-3 * np.cos(2e3 * t),
            "force_residual_after_n": 1e-4 * np.cos(2e3 * t),
            "marks": [{"t_s": (0.005, 0.01), "band_hz": (300.0, 400.0)}],
        },
        "ol_frf": {
            "kind": "frf",
            "recording": "ol",
            "frf_kind": "frf-open-loop",
            "frequency_hz": f,
            "measured": h * (1 + 0.01 * rng.normal(size=200)),
            "before": h,
            "after": h * 1.01,
            "marks": [],
        },
        "part_map": {
            "kind": "map",
            "recording": "part",
            "residual_before_m": img,
            "residual_after_m": 0.5 * img,
        },
        "line_profile": {
            "kind": "profile",
            "recording": "line",
            "position_before_m": pos,
            "residual_before_m": 2e-9 * np.sin(pos * 1e4),
            "position_after_m": pos,
            "residual_after_m": 1e-9 * np.sin(pos * 1e4),
        },
    }


def test_every_kind_writes_a_png(tmp_path):
    out = diagnosis_figures(_data(), tmp_path)
    assert sorted(out) == sorted(_data())
    for name, path in out.items():
        assert path == tmp_path / f"{name}.png"
        data = path.read_bytes()
        assert len(data) > 1000 and data[:8] == PNG_MAGIC


@pytest.fixture
def drawn(monkeypatch, tmp_path):
    """Figure objects by picture name (``save`` captured, nothing written)."""
    figs = {}

    def keep(fig, path):
        figs[path.stem] = fig
        return path

    monkeypatch.setattr(dp, "save", keep)
    diagnosis_figures(_data(), tmp_path)
    yield figs
    import matplotlib.pyplot as plt

    for fig in figs.values():
        plt.close(fig)


def test_curves_are_the_data_in_display_units(drawn):
    g = _data()
    ax = drawn["cut_residual"].axes
    lines = ax[0].get_lines()
    np.testing.assert_allclose(lines[0].get_xdata(), g["cut_residual"]["time_s"] * 1e3)
    np.testing.assert_allclose(
        lines[0].get_ydata(), g["cut_residual"]["residual_before_m"] / 1e-9
    )
    np.testing.assert_allclose(
        lines[1].get_ydata(), g["cut_residual"]["residual_after_m"] / 1e-9
    )
    np.testing.assert_allclose(
        ax[2].get_lines()[0].get_ydata(),
        g["cut_residual"]["force_residual_before_n"] / 1e-3,
    )
    frf = drawn["ol_frf"].axes
    h = g["ol_frf"]["after"]
    np.testing.assert_allclose(
        frf[1].get_lines()[2].get_ydata(), np.arctan2(h.imag, h.real) * 180 / np.pi
    )
    prof = drawn["line_profile"].axes[0].get_lines()[1]
    np.testing.assert_allclose(
        prof.get_xdata(), g["line_profile"]["position_after_m"] / 1e-3
    )
    im = drawn["part_map"].axes[1].get_images()[0]
    np.testing.assert_allclose(
        np.asarray(im.get_array().filled(np.nan)),
        g["part_map"]["residual_after_m"] / 1e-9,
    )


def test_mismatches_are_marked_on_the_right_axes(drawn):
    # spectrum: one shaded band (100..200 Hz) and one line (1 kHz)
    ax = drawn["idle_spectrum"].axes[0]
    assert len(ax.patches) == 1
    assert [ln.get_xdata()[0] for ln in ax.get_lines()[3:]] == [1000.0]
    # residual: the time window on the time axis (ms), the band on the spectrum
    ax = drawn["cut_residual"].axes
    (span_t,), (span_f,) = ax[0].patches, ax[1].patches
    assert span_t.get_x() == pytest.approx(5.0) and span_t.get_width() == (
        pytest.approx(5.0)
    )
    assert span_f.get_x() == pytest.approx(300.0)
    assert len(ax[2].patches) == 0


def test_unknown_kind_is_refused(tmp_path):
    with pytest.raises(ValueError, match="unknown kind 'bode'"):
        diagnosis_figures({"x": {"kind": "bode", "recording": "x"}}, tmp_path)
