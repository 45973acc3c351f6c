"""Realistic nulls are not false alarms (issue 19 item 5): the low-band nuisance
basis, the expectation of projected periodograms, the noise-level recalibration."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.signal import lfilter

from servosurf.diagnose._blocks import (
    low_band_basis,
    project_low_band,
    projected_periodogram_expectation,
)

FS = 200e3
W = FS / 4096


@pytest.mark.parametrize("n", [300, 4096, 16384])
def test_basis_is_orthonormal(n):
    q = low_band_basis(n, FS, W)
    assert q.shape[0] == n and q.shape[1] >= 2
    np.testing.assert_allclose(q.T @ q, np.eye(q.shape[1]), atol=1e-12)


def test_slepian_count_follows_time_bandwidth():
    # offset + trend, plus the well-concentrated Slepian sequences (< 2 N W / fs)
    assert low_band_basis(1000, FS, W).shape[1] == 2  # N W / fs = 0.24: none
    q = low_band_basis(8192, FS, W)  # N W / fs = 2: at most 3 (2 N W - 1)
    assert 2 + 2 <= q.shape[1] <= 2 + 3


def test_basis_spans_the_slepian_sequences():
    # scipy's tridiagonal Slepian sequences (a second implementation) lie in the
    # span: the three best concentrated of N W = 2 to 1e-3 of their energy or better
    from scipy.signal.windows import dpss

    n = 8192
    q = low_band_basis(n, FS, W)
    tapers = dpss(n, n * W / FS, Kmax=3)
    kept = np.linalg.norm(tapers @ q, axis=1) ** 2
    assert np.all(kept > 0.9), kept


def test_offset_and_trend_removed_to_machine_precision():
    n = 3000
    t = np.arange(n) / FS
    x = 3e-6 - 0.7e-3 * t
    y = project_low_band(x, low_band_basis(n, FS, W))
    assert np.max(np.abs(y)) < 1e-12 * np.max(np.abs(x))


def test_low_band_sinusoid_removed_and_band_kept():
    n = 16384  # 82 ms, N W / fs = 4
    t = np.arange(n) / FS
    q = low_band_basis(n, FS, W)
    # a sinusoid inside [-W, W] loses 99.9 % of its power or more
    for f in (5.0, 20.0, 35.0):
        low = 1e-6 * np.cos(2 * np.pi * f * t + 0.4)
        res = project_low_band(low, q)
        assert np.sum(res**2) < 1e-3 * np.sum(low**2), f
    # a sinusoid at 10 W keeps its power to 3e-3 (plain-numpy oracle; the
    # Slepians kept at lambda >= 0.9 leak a little energy above W)
    hi = np.cos(2 * np.pi * 10 * W * t + 1.3)
    kept = project_low_band(hi, q)
    assert abs(np.sum(kept**2) / np.sum(hi**2) - 1) < 3e-3


def test_projection_is_idempotent_and_batches_rows():
    q = low_band_basis(5000, FS, W)
    x = np.random.default_rng(1).standard_normal((3, 5000))
    y = project_low_band(x, q)
    np.testing.assert_allclose(project_low_band(y, q), y, atol=1e-12)
    np.testing.assert_allclose(y[1], project_low_band(x[1], q), atol=1e-12)


def test_projected_periodogram_expectation_matches_monte_carlo():
    # AR(1) with a slow pole (strong low-frequency content): r(tau) closed form
    n, phi, reps = 2048, 0.995, 3000
    fs = FS
    tau = np.arange(n)
    r = phi**tau / (1 - phi**2)
    q = low_band_basis(n, fs, 2.5 * fs / n)  # offset, trend and Slepians
    assert q.shape[1] >= 5
    e = projected_periodogram_expectation(r, q, fs)
    rng = np.random.default_rng(7)
    burn = 4000
    acc = np.zeros(n // 2 + 1)
    for _ in range(reps // 500):
        z = rng.standard_normal((500, n + burn))
        x = lfilter([1.0], [1.0, -phi], z, axis=1)[:, burn:]
        y = project_low_band(x, q)
        acc += np.sum(np.abs(np.fft.rfft(y, axis=1)) ** 2, axis=0)
    mc = acc / reps * 2.0 / (fs * n)
    # each bin's mean of 3000 ~exponential values: relative sd 1.8 %
    rel = mc[1:-1] / e[1:-1] - 1
    assert np.max(np.abs(rel)) < 6 / np.sqrt(reps)
    assert abs(np.mean(rel)) < 3 / np.sqrt(reps * rel.size) * 3
    # without the projection the expectation is far off at the low bins
    e_raw = projected_periodogram_expectation(r, q[:, :0], fs)
    assert np.max(np.abs(mc[1:20] / e_raw[1:20] - 1)) > 0.5


# ---------------------------------------------------------------- diagnoses
def _idle_case(discovery, tmp_path, ool, seed, records=16, n=4096):
    """An idle-only case (the benchmark generator's noise synthesis, not the
    diagnosis's) with ``ool``'s nuisance; returns its manifest."""
    cases = discovery("cases")
    from servosurf.diagnose import Model

    case = cases.base_case()
    rng = np.random.default_rng(seed)
    fe = cases.noise_records(case, Model(), n, rng, count=records, ool=ool)["fe"]
    np.savez(tmp_path / "idle.npz", fs_hz=case.fs, following_error_m=fe)
    tp = cases.TOOLPATH
    (tmp_path / "m.toml").write_text(
        f'[case]\nmachine = "seed-prototype"\ntoolpath = "{tp}"\n'
        f"bandwidth = {cases.BANDWIDTH}\nmoving-mass = {cases.MASS}\n\n"
        '[[recording]]\npath = "idle.npz"\nkind = "following-error"\n')
    return tmp_path / "m.toml", fe


@pytest.mark.slow  # a diagnosis of 16 idle records: ~20 s alone, more when loaded
def test_low_band_base_null_is_consistent(discovery, tmp_path):
    from servosurf.diagnose import diagnose

    ool = {"kind": "low-band", "par": [4.0]}
    man, fe = _idle_case(discovery, tmp_path, ool, seed=11)
    # the low-band content is there: drifts of a fifth of the records' RMS
    t = np.arange(fe.shape[1])
    slope = np.polyfit(t, fe.T, 1)[0] * t.size
    assert np.median(np.abs(slope)) > 0.1 * np.median(np.std(fe, axis=1))
    d = diagnose(man)
    assert d.verdict == "consistent", (d.verdict, d.explanations, d.recalibration)


@pytest.mark.slow  # a diagnosis of 16 idle records with a noise term fitted
def test_twice_the_base_noise_is_a_recalibration_not_unexplained(discovery,
                                                                 tmp_path):
    from servosurf.diagnose import diagnose

    ool = {"kind": "noise-scale", "par": [2.0, 2.25, 1.0]}  # base x2, sensor x1.5
    man, _ = _idle_case(discovery, tmp_path, ool, seed=12)
    d = diagnose(man)
    assert d.verdict != "unexplained", (d.verdict, d.recalibration)
    # no mechanism named: at most the catalogue's noise-model term or the
    # noise-level recalibration
    named = {e["effect"] for e in d.explanations}
    assert named <= {"sensor-noise-shape"}, named
    for rec in d.recalibration:
        par = rec["parameters"]
        assert all(k.endswith("noise_scale") for k in par), par


# ------------------------------------------------------ noise-level recalibration
def test_noise_level_recalibration_scales_the_psds():
    from servosurf.diagnose import effects as E
    from servosurf.noise import evaluate_psd
    from servosurf.servo import load_machine

    m = load_machine()
    f = np.geomspace(50.0, 90e3, 40)
    q = E.RecalibrationParams(base_noise_scale=2.0, sensor_noise_scale=2.25)
    d0, d1 = m.disturbances, q.machine(m).disturbances
    np.testing.assert_allclose(evaluate_psd(d1.base_vibration, f),
                               2.0 * evaluate_psd(d0.base_vibration, f), rtol=1e-12)
    np.testing.assert_allclose(evaluate_psd(d1.sensor_noise, f),
                               2.25 * evaluate_psd(d0.sensor_noise, f), rtol=1e-12)
    np.testing.assert_allclose(evaluate_psd(d1.current_noise, f),
                               evaluate_psd(d0.current_noise, f), rtol=0)
    assert q.noise_only()
    d2 = E.RecalibrationParams(current_noise_scale=1.7).machine(m).disturbances
    np.testing.assert_allclose(evaluate_psd(d2.current_noise, f),
                               1.7 * evaluate_psd(d0.current_noise, f), rtol=1e-12)
    assert not E.RecalibrationParams(moving_mass=0.18).noise_only()


def test_noise_level_config_fits_only_the_factors():
    from servosurf.diagnose import Model
    from servosurf.diagnose.effects import get_effect
    from servosurf.diagnose.effects._base import Config

    eff = get_effect("recalibration")
    assert {c.label for c in eff.configs(None, Model())} == {"plant", "noise-level"}
    cfg = Config("noise-level")
    assert eff.n_params(cfg) == 3
    p = eff.start(Model(), cfg, [10.0, 5.0, -5.0], None)  # 1 + 0.1 c
    (q,) = p.get("recalibration")
    assert q.noise_only()
    assert q.base_noise_scale == pytest.approx(2.0)
    assert q.sensor_noise_scale == pytest.approx(1.5)
    assert q.current_noise_scale == pytest.approx(0.5)
    free = eff.free(p, 0, None)
    assert {x.field for x in free} == {"base_noise_scale", "sensor_noise_scale",
                                       "current_noise_scale"}
    assert all((x.lo, x.hi) == (0.25, 4.0) for x in free)


def test_verdict_of_a_noise_level_recalibration():
    from servosurf.diagnose._diagnose import _verdict

    assert _verdict(False, True, [], 1e3, 0.0, noise_only=True) == "consistent"
    assert _verdict(False, True, [], 1e3, 0.0, noise_only=False) == "unexplained"
    assert _verdict(False, False, [], 0.0, 0.0) == "consistent"
