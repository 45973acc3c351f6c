"""Error synthesis (Eqs 8-12), realisations, Welch estimates, PSD files.

Also the design study.
"""

from __future__ import annotations

import io

import numpy as np
import pytest

from servosurf.errors import ConfigError
from servosurf.noise import (
    cas,
    design_study,
    evaluate_psd,
    frequency_grid,
    read_psd_csv,
    realise,
    synthesize,
    welch_psd,
    write_psd_csv,
)
from servosurf.servo import PSDModel, ServoLoop, load_machine


@pytest.fixture(scope="module")
def loop() -> ServoLoop:
    return ServoLoop(load_machine().with_moving_mass(0.175).with_bandwidth(1448.0))


def test_cas_of_white_noise_closed_form():
    f = np.linspace(0, 1000, 1001)
    psd = np.full_like(f, 4e-18)  # m^2/Hz
    np.testing.assert_allclose(cas(f, psd)[-1], np.sqrt(4e-18 * 1000), rtol=1e-12)


def test_budget_is_sum_of_sources(loop):
    b = synthesize(loop)
    np.testing.assert_allclose(b.real_total, sum(b.real.values()))
    shares = b.power_shares()
    np.testing.assert_allclose(sum(shares.values()), 1.0, rtol=1e-12)
    # Eq 12: RMS is the CAS at Nyquist
    np.testing.assert_allclose(b.rms_real(), b.cas_real()["total"][-1])


def test_following_sensor_term_is_sensitivity(loop):
    """Eq 10's sensor term Ws |1 - FRF1|^2 with FRF1 the measured-position response."""
    b = synthesize(loop)
    frf = loop.frf(b.freq)
    one_minus = 1 - frf.complementary
    np.testing.assert_allclose(
        b.following["sensor_noise"],
        b.disturbance["sensor_noise"] * np.abs(one_minus) ** 2,
        rtol=1e-9,
    )


def test_realisation_rms_matches_cas(loop):
    n = 2**19
    r = realise(loop, n, seed=12345)
    f = np.fft.rfftfreq(n, 1 / loop.fs)
    band = f >= loop.fs / 4096
    b = synthesize(loop, freq=f[band])
    # the RMS of a Gaussian series with this spectrum has a sampling error of
    # roughly sqrt(f_eff / (n/fs)) relative; 3 % is > 5 sigma here (seed fixed)
    np.testing.assert_allclose(r.tool.std(), b.rms_real(), rtol=0.03)
    np.testing.assert_allclose(r.following.std(), b.rms_following(), rtol=0.03)


def test_realisation_spectrum_matches_psd(loop):
    n = 32 * 4096
    r = realise(loop, n, seed=7)
    f, p = welch_psd(r.tool, loop.fs)
    b = synthesize(loop, freq=f)
    sel = (f > 200) & (f < 40e3)
    ratio = p[sel] / b.real_total[sel]
    # 32 averaged Hann periodograms: each bin ~ chi2(64)/64, sd ~ 0.18; the median over
    # many bins is within a few percent of 1 and 95 % of bins within a factor 1.6
    assert abs(np.median(ratio) - 1) < 0.06
    assert np.mean((ratio > 1 / 1.6) & (ratio < 1.6)) > 0.95


def test_realisation_reproducible_and_seed_dependent(loop):
    a = realise(loop, 4096, seed=1).tool
    b = realise(loop, 4096, seed=1).tool
    c = realise(loop, 4096, seed=2).tool
    np.testing.assert_array_equal(a, b)
    assert not np.allclose(a, c, rtol=1e-3, atol=0)


def test_welch_recovers_white_noise_level():
    rng = np.random.default_rng(3)
    fs = 199.6e3
    sigma = 2e-9
    x = rng.normal(0, sigma, (32, 4096))
    f, p = welch_psd(x, fs)
    np.testing.assert_allclose(np.mean(p), 2 * sigma**2 / fs, rtol=0.03)
    np.testing.assert_allclose(f[0], fs / 4096)


def test_psd_csv_round_trip_and_model(tmp_path):
    f = np.geomspace(10, 1e5, 50)
    p = 1e-24 * (f / 1e3) ** -1.0
    path = tmp_path / "ws.csv"
    write_psd_csv(path, f, p)
    f2, p2 = read_psd_csv(path)
    np.testing.assert_allclose(f2, f, rtol=1e-8)
    np.testing.assert_allclose(p2, p, rtol=1e-8)
    model = PSDModel(csv=str(path))
    fq = np.array([100.0, 3000.0])
    np.testing.assert_allclose(
        evaluate_psd(model, fq), 1e-24 * (fq / 1e3) ** -1, rtol=1e-6
    )
    # outside the measured range the PSD is zero, not extrapolated
    assert evaluate_psd(model, np.array([1.0]))[0] == 0.0


def test_parametric_psd_formula():
    m = PSDModel(
        level=2e-12, ref_frequency=1e3, slope=0.5, corner=1e4, order=2, floor=1e-12
    )
    f = np.array([1e3, 1e4])
    expected = (4e-24 * (f / 1e3) ** 0.5 + 1e-24) / (1 + (f / 1e4) ** 2)
    np.testing.assert_allclose(evaluate_psd(m, f), expected, rtol=1e-12)


@pytest.mark.parametrize(
    "text, match",
    [
        ("freq,psd\n1,2\n2,3\n", "header"),
        ("frequency_hz,psd\n1,2\n", "at least 2"),
        ("frequency_hz,psd\n2,1\n1,1\n", "increasing"),
        ("frequency_hz,psd\n1,-1\n2,1\n", ">= 0"),
        ("frequency_hz,psd\n1,a\n2,1\n", "two numbers"),
    ],
)
def test_psd_csv_errors(text, match):
    with pytest.raises(ConfigError, match=match):
        read_psd_csv(io.StringIO(text))


def test_frequency_grid_defaults():
    f = frequency_grid(199.6e3)
    np.testing.assert_allclose(f[0], 199.6e3 / 4096)
    assert f[-1] == pytest.approx(99.8e3)


def test_design_study_larger_mass_lowers_optimum():
    m = load_machine().with_disturbances("section-3.3")
    study = design_study(m, [0.075, 0.175], [300, 468, 874, 1200])
    assert study.optimal_bandwidth[1] < study.optimal_bandwidth[0]
    # the heavier mass reduces the real error at low bandwidth (paper section 3.3)
    assert study.rms_real[1, 1] < study.rms_real[0, 1]
    assert 1400 < study.stability_limit[1] < 1800


def test_vibration_stream_segments_consistent_and_spectrum(loop):
    from servosurf.noise import VibrationStream

    vs = VibrationStream(loop, seed=9)
    whole = vs.segment(0, 300_000)
    # any sub-range equals the slice of a longer range (tiling-independent), also
    # across the white-noise block boundary at 65536
    np.testing.assert_allclose(
        vs.segment(65_000, 2_000), whole[65_000:67_000], rtol=0, atol=1e-22
    )  # exact up to FFT rounding
    np.testing.assert_allclose(
        vs.segment(123_456, 7), whole[123_456:123_463], atol=1e-22
    )
    b = synthesize(loop)
    # the FIR's energy is the synthesised RMS (window smoothing keeps the power)
    np.testing.assert_allclose(vs.rms, b.rms_real(), rtol=0.03)
    np.testing.assert_allclose(whole.std(), b.rms_real(), rtol=0.05)
    f, p = welch_psd(whole, loop.fs)
    sel = (f > 200) & (f < 40e3)
    ratio = p[sel] / synthesize(loop, freq=f[sel]).real_total
    assert abs(np.median(ratio) - 1) < 0.1
    assert not np.allclose(
        VibrationStream(loop, seed=10).segment(0, 1000), whole[:1000], rtol=1e-3, atol=0
    )


def test_vibration_stream_memmap(tmp_path, loop):
    from servosurf.noise import VibrationStream

    vs = VibrationStream(loop, seed=1, taps=4096)
    mm = vs.to_memmap(tmp_path / "v.npy", 50_000, chunk=12_345)
    np.testing.assert_allclose(mm[:], vs.segment(0, 50_000).astype(np.float32))
    # threads compute chunks in any order; the file is the same for any count
    seen = []
    m1 = vs.to_memmap(tmp_path / "v1.npy", 50_000, chunk=4_000, workers=1)
    m3 = vs.to_memmap(tmp_path / "v3.npy", 50_000, chunk=4_000, workers=3,
                      progress=lambda it: (seen.append(len(it)), it)[1])
    np.testing.assert_array_equal(m1[:], m3[:])
    np.testing.assert_allclose(m3[:], mm[:], rtol=0, atol=1e-15)
    assert seen == [13]  # the progress wrapper sees a sized iterable


def test_psd_command_round_trip(tmp_path, capsys):
    import json

    from servosurf.cli import main

    rng = np.random.default_rng(5)
    fs = 199.6e3
    rec = rng.normal(0, 1e-9, (32, 4096))
    np.savez(tmp_path / "r.npz", records=rec, fs_hz=fs)
    assert main(["psd", str(tmp_path / "r.npz"), "--out", str(tmp_path / "ws.csv"),
                 "--json"]) == 0
    data = json.loads(capsys.readouterr().out)
    f, p = read_psd_csv(tmp_path / "ws.csv")
    np.testing.assert_allclose(np.mean(p), 2 * 1e-18 / fs, rtol=0.03)
    np.testing.assert_allclose(data["rms_from_psd"], 1e-9, rtol=0.03)
    # a machine file can use it
    model = PSDModel(csv=str(tmp_path / "ws.csv"))
    assert evaluate_psd(model, np.array([1e3]))[0] > 0
    bad = tmp_path / "bad.csv"
    bad.write_text("t,v\n0,1\n")
    assert main(["psd", str(bad), "--out", str(tmp_path / "x.csv")]) == 1


def test_a_tuning_failure_is_not_an_instability():
    """At 0.075 kg the tuning rule runs out of positive gains before the loop goes
    unstable: the limit is 'untunable' and stability_limit reports none."""
    from servosurf.errors import ModelError
    from servosurf.noise import loop_limit, stability_limit, tuning_limit
    from servosurf.servo import tune_pidf

    light = load_machine().with_moving_mass(0.075)
    lim = loop_limit(light)
    assert lim.kind == "untunable"
    assert stability_limit(light) == np.inf
    assert tuning_limit(light) == pytest.approx(lim.bandwidth_hz)
    # the independent check: the tuning rule itself refuses just above the limit
    with pytest.raises(ModelError, match="cannot tune"):
        tune_pidf(light.with_bandwidth(lim.bandwidth_hz * 1.002))
    assert ServoLoop(light.with_bandwidth(lim.last_working_hz)).is_stable()
    heavy = load_machine().with_moving_mass(0.175)
    hl = loop_limit(heavy)
    assert hl.kind == "unstable"
    assert not ServoLoop(heavy.with_bandwidth(hl.bandwidth_hz * 1.002)).is_stable()


def test_design_study_optimum_is_the_refined_one_number():
    """The study's optima are noise.optimal_bandwidth's (refined), not grid points."""
    from servosurf.noise import optimal_bandwidth

    m = load_machine()
    study = design_study(m, [0.175], [300, 468, 874])
    bw_f, rms_f = optimal_bandwidth(m.with_moving_mass(0.175), which="following")
    bw_r, _ = optimal_bandwidth(m.with_moving_mass(0.175), which="real")
    assert study.optimal_following_bandwidth[0] == bw_f
    assert study.optimal_bandwidth[0] == bw_r
    assert study.optimal_following_rms[0] == rms_f
    assert bw_f not in (300, 468, 874)
