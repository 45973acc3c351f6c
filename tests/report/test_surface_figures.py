"""Robust surface figures: alias bands, cutting-cycle lags, form registrations,
multi-seed peaks.

Oracles: hand-computed folds of the path sampling frequency, synthetic records with
known peak positions, synthetic profiles with a known lateral offset, and two
disjoint sets of seeds.
"""

from __future__ import annotations

import numpy as np
import pytest

from servosurf.cutting import cutting_cycle_stats
from servosurf.metrology import (
    form_error_profile,
    nominal_lenslet_profile,
    sampling_alias_bands,
)


def test_path_sampling_alias_closed_form():
    # 5 um lenslets: 149 lenslets on the 10 mm ring -> v = 2 pi 0.01 m 100 Hz / 149
    v = 2 * np.pi * 0.01 * 100.0 / 149
    s = v / 199.6e3  # path sample spacing, 0.211 um
    fp = 1 / 0.55e-6  # pixel sampling frequency, 1818 mm^-1
    b = sampling_alias_bands(s, 0.55e-6)
    # k = 1: 4733 mm^-1 folded by 2 x 1818 mm^-1 and mirrored about the Nyquist
    expected1 = abs(1 / s - 3 * fp)
    assert b[0]["harmonic"] == 1
    assert b[0]["low_per_m"] == pytest.approx(expected1, rel=1e-12)
    assert b[0]["low_per_m"] == pytest.approx(721e3, rel=0.01)  # issue 18's 721
    assert b[1]["low_per_m"] == pytest.approx(abs(2 / s - 5 * fp), rel=1e-12)
    # 10 um lenslets at 9.75 mm: v = 2 pi 0.00975 m 100 Hz / 105 -> 215 mm^-1
    v10 = 2 * np.pi * 0.00975 * 100.0 / 105
    b10 = sampling_alias_bands(v10 / 199.6e3, 0.55e-6)
    assert b10[0]["low_per_m"] == pytest.approx(215e3, rel=0.02)
    # a range of spacings gives a band containing both ends' folds
    band = sampling_alias_bands([s * 0.99, s * 1.01], 0.55e-6)[0]
    assert band["low_per_m"] < expected1 < band["high_per_m"]


def test_cutting_cycle_lags_are_sample_exact():
    fs, f = 10000.0, 100.0
    n = 500  # five periods
    t = np.arange(n) / fs
    period = 100
    force = np.zeros(n)
    dev = np.zeros(n)
    cmd = np.cos(2 * np.pi * f * t)  # deepest (minimum) at t = 5 ms + k 10 ms
    for k in range(5):
        c = k * period + 50  # deepest commanded sample
        force[c - 15 : c + 16] = 1.0 - np.abs(np.arange(-15, 16)) / 16.0
        dev[c - 10 : c + 20] = np.hanning(30)  # peak at c + 4 or c + 5
        dev[c + 25 : c + 35] = -0.3
    out = cutting_cycle_stats(force, dev, fs=fs, frequency=f, command=cmd)
    i_dev = int(np.argmax(np.hanning(30))) - 10
    assert out["deviation_lag_s"] == pytest.approx(i_dev / fs)
    assert out["deviation_lag_deepest_s"] == pytest.approx(i_dev / fs)
    assert out["deviation_overshoot_m"] == pytest.approx(0.3)
    assert out["force_max_n"] == pytest.approx(1.0)
    assert cutting_cycle_stats(np.zeros(n), dev, fs=fs, frequency=f) == {
        "force_max_n": 0.0
    }


def _lens(y, centre, amp):
    return nominal_lenslet_profile(
        y, amplitude=10e-6, frequency=100.0, speed=42.3e-3, depth=5e-6,
        tool_radius=0.5e-3, centre=centre, path_amplitude=amp,
    )


def test_fitted_registration_recovers_a_lateral_offset():
    y = np.arange(-120e-6, 120e-6, 0.55e-6)
    true_c = 1.7e-6
    z = _lens(y, true_c, 10.4e-6)
    # an error that lags: a bump 30 um after the deepest point
    z = z + 40e-9 * np.exp(-(((y - true_c - 30e-6) / 8e-6) ** 2)) * (z < -5e-6 + 4.9e-6)
    fe = form_error_profile(
        y, z, lambda x, a: _lens(x, 0.0, a), reference_amplitude=10.4e-6,
        max_shift=20e-6,
    )
    assert fe["shift_m"] == pytest.approx(true_c, abs=0.05e-6)
    k = int(np.nanargmax(np.abs(fe["error"])))
    assert y[k] - fe["x_deepest_m"] == pytest.approx(30e-6, abs=1.1e-6)
    # registered on a point 1.7 um off instead, the error picks up the lens slope
    fe0 = form_error_profile(
        y, z, lambda x, a: _lens(x, 0.0, a), reference_amplitude=10.4e-6
    )
    assert fe0["max_abs_error_m"] > 2 * fe["max_abs_error_m"]


@pytest.mark.slow
def test_mean_spectrum_peaks_are_stable_across_seeds():
    """Two disjoint sets of 20 seeds give the same physical peaks (5 um lenslet on a
    field cropped to its central lenslet), the sampling alias is removed, and the
    peaks show in most single seeds."""
    import dataclasses
    from pathlib import Path

    from servosurf.report import lenslet_peak_study
    from servosurf.toolpath import load_toolpath

    root = Path(__file__).resolve().parents[2]
    spec = load_toolpath(root / "toolpaths" / "lenslet_5um.toml")
    fld = dataclasses.replace(spec.field, nx=320, center_x=10e-3)
    spec = dataclasses.replace(spec, field=fld)
    kw = {"bandwidth": 1448.0, "mass": 0.175}
    a = lenslet_peak_study(spec, seeds=range(0, 20), alias_seeds=3, **kw)
    b = lenslet_peak_study(spec, seeds=range(20, 40), alias_seeds=3, **kw)
    df = a["frequency_resolution_per_m"]
    pa, pb = a["physical_peaks_per_m"][:2], b["physical_peaks_per_m"][:2]
    assert len(pa) == 2 and len(pb) == 2
    for fa, fb in zip(sorted(pa), sorted(pb), strict=True):
        assert abs(fa - fb) <= df
    # the model's 7.4 and 11.7 kHz modes at 42.2 mm/s
    assert sorted(pa)[0] == pytest.approx(7.4e3 / a["speed_m_per_s"], rel=0.03)
    assert sorted(pa)[1] == pytest.approx(11.7e3 / a["speed_m_per_s"], rel=0.03)
    for p in a["peaks"][:2]:
        assert p["seed_fraction"] >= 0.5
    aliases = [p for p in a["peaks"] if p["alias"]]
    assert any(abs(p["freq_per_m"] - 721e3) < 10e3 for p in aliases)
