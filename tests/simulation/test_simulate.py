"""The whole pipeline: parts switch, seeds, closed forms, CLI."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest

from servosurf.cli import main
from servosurf.errors import ConfigError
from servosurf.servo import ServoLoop
from servosurf.simulation import simulate
from servosurf.toolpath import load_toolpath

LENS = "toolpaths/lenslet_5um.toml"


@pytest.fixture(scope="module")
def small_lens():
    """The 5 um lenslet toolpath on a coarser 2 um grid (fast)."""
    spec = load_toolpath(LENS)
    fld = dataclasses.replace(spec.field, pitch_x=2e-6, pitch_y=2e-6, nx=120, ny=120)
    return dataclasses.replace(spec, field=fld)


def test_no_deviation_reproduces_kernel_alone(small_lens):
    from servosurf.toolpath import sample, sweep

    res = simulate(small_lens, parts=())
    path = sample(small_lens, field=small_lens.field, tool=small_lens.tool)
    ref = sweep(path, small_lens.tool, small_lens.field, initial=0.0)
    np.testing.assert_allclose(res.surface.z, ref.z, atol=1e-15)  # 1 fm
    assert not any(np.any(v) for v in res.deviation.values())


def test_tracking_matches_closed_loop_gain(small_lens):
    res = simulate(small_lens, parts=("tracking",), bandwidth=1448, mass=0.175)
    p = small_lens.path
    loop = ServoLoop(res.machine)
    h = loop.frf(np.array([p.frequency])).paths[("reference", "tool")][0]
    # amplitude of the actual tool motion over the last periods, against |T| A
    tail = res.z_command.size // 2
    x = res.z_command[tail:] + res.deviation["tracking"][tail:]
    amp = (x.max() - x.min()) / 2
    np.testing.assert_allclose(amp, abs(h) * p.amplitude, rtol=2e-3)


def test_force_deviation_scales_with_thrust_pressure(small_lens):
    from servosurf.cutting import Material, Workpiece

    def run(kt):
        wp = Workpiece(material=Material(specific_thrust_pressure=kt))
        return simulate(
            small_lens,
            parts=("tracking", "force"),
            workpiece=wp,
            bandwidth=1448,
            mass=0.175,
        ).deviation["force"]

    a, b = run(0.5e9), run(1.0e9)
    # the chip depends on the deviated position, so the response is only nearly
    # linear in k_t (a few per cent at these deviations)
    np.testing.assert_allclose(b.max() / a.max(), 2.0, rtol=0.05)
    assert a.max() > 0


def test_force_deviation_is_the_loop_response_to_the_force(small_lens):
    """The force part equals the force -> tool FRF applied to the force record.

    Oracle: the frequency-domain loop model (sampled-data FRF; the force ramps
    linearly between its samples, a first-order hold: factor sinc^2, no phase)
    filtering ``result.force`` by FFT, independent of how
    :func:`simulate` subtracts two time-domain runs. The record starts at rest, so
    only its steady second half is compared against the periodic filter.
    """
    res = simulate(small_lens, parts=("tracking", "force"), bandwidth=1448,
                   mass=0.175)
    loop = ServoLoop(res.machine)
    force = res.force
    n = force.size
    f = np.fft.rfftfreq(n, 1.0 / loop.fs)
    h = np.zeros(f.size, dtype=complex)
    h[1:] = loop.frf(f[1:]).paths[("force", "tool")] * np.sinc(f[1:] / loop.fs) ** 2
    h[0] = loop.frf(np.array([1e-3])).paths[("force", "tool")][0].real
    pred = np.fft.irfft(np.fft.rfft(force) * h, n)
    dev = res.deviation["force"]
    tail = slice(n // 2, n)
    assert np.max(np.abs(dev[tail])) > 100e-9  # the paper's few hundred nm
    np.testing.assert_allclose(dev[tail], pred[tail], rtol=0,
                               atol=2e-3 * np.max(np.abs(dev[tail])))


def test_seed_stability_and_dependence(small_lens):
    a = simulate(small_lens, parts=("vibration",), seed=3)
    b = simulate(small_lens, parts=("vibration",), seed=3)
    c = simulate(small_lens, parts=("vibration",), seed=4)
    np.testing.assert_array_equal(a.surface.z, b.surface.z)
    assert not np.array_equal(a.surface.z, c.surface.z)


def test_bad_inputs(small_lens):
    with pytest.raises(ConfigError, match="unknown deviation part"):
        simulate(small_lens, parts=("wobble",))
    with pytest.raises(ConfigError, match="unstable"):
        simulate(small_lens, bandwidth=1700, mass=0.175)


def test_simulate_cli_json_keys(tmp_path, capsys):
    rc = main(
        [
            "simulate",
            LENS,
            "--out",
            str(tmp_path / "s"),
            "--json",
            "--no-render",
            "--format",
            "npz",
        ]
    )
    assert rc == 0
    data = json.loads(capsys.readouterr().out)
    for key in (
        "form_error_max_m",
        "form_error_lag_m",
        "spectrum_peaks_per_m",
        "ra_m",
        "sa_m",
        "sq_m",
    ):
        assert key in data
    assert data["analysed_map"] == "measured"  # default: the CP300 20X model
    # the central-chord maximum (fitted registration) lies below the rim maximum
    assert 0 < data["form_error_max_m"] < data["form_error_rim_max_m"] < 350e-9
    assert data["form_error_lag_m"] > 0
    assert set(data["form_error_registrations"]) >= {
        "fitted/servosurf", "deepest_point/servosurf", "commanded_centre/servosurf"
    }
    assert any(abs(p - 173e3) < 10e3 for p in data["spectrum_peaks_per_m"][:3])
    for name in (
        "map.png",
        "profile.png",
        "spectrum.png",
        "highpass.png",
        "summary.json",
        "surface.npz",
    ):
        assert (tmp_path / "s" / name).stat().st_size > 0


@pytest.mark.parametrize(
    "argv, match",
    [
        (["simulate", "nope.toml"], "not found"),
        (["simulate", LENS, "--bandwidth", "-5"], "--bandwidth"),
        (["simulate", LENS, "--mass", "0"], "--mass"),
        (["simulate", LENS, "--bandwidth", "5000"], "bandwidth"),
        (["simulate", LENS, "--realisations", "0"], "--realisations"),
    ],
)
def test_simulate_cli_errors(argv, match, capsys, tmp_path):
    assert main(argv + ["--out", str(tmp_path / "o")]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and match in err[0]
    assert not list((tmp_path / "o").glob("surface.*"))


def test_realisations_match_single_runs(small_lens):
    from servosurf.report import realisation_study
    from servosurf.report._simulation import analyse

    seeds = [0, 3, 5]
    study = realisation_study(small_lens, seeds=seeds, instrument=None)
    assert study.seeds.tolist() == seeds
    for i, seed in enumerate(seeds):  # each task is simulate(seed) + analyse
        one = analyse(simulate(small_lens, seed=seed))
        for k in ("form_error_max_m", "ra_m", "sa_m", "sq_m", "deviation_max_m"):
            assert study.metrics[k][i] == one[k]
        peaks = one["spectrum_peaks_per_m"]  # may be empty on this small field
        p1 = study.metrics["peak1_per_m"][i]  # one of this seed's peaks, or none
        assert np.isnan(p1) or p1 in peaks
    # the vibration realisation changes the roughness, not the force deviation
    assert np.unique(study.metrics["sa_m"]).size == len(seeds)
    assert np.unique(study.metrics["deviation_max_m"]).size == 1
    st = study.statistics()["sa_m"]
    assert st["mean"] == pytest.approx(np.mean(study.metrics["sa_m"]), rel=1e-12,
                                       abs=0.0)
    assert st["std"] == pytest.approx(np.std(study.metrics["sa_m"], ddof=1),
                                      rel=1e-12, abs=0.0)
    assert st["min"] <= st["p5"] <= st["median"] <= st["p95"] <= st["max"]


def test_realisation_lines_matched_by_frequency():
    """peak1/peak2 follow one spectral line each, whichever is strongest per seed.

    Hand-made peaks: the 171 mm^-1 line is the stronger one in seeds 0 and 2, the
    277 mm^-1 line in seed 1, and seed 2 has no 277 line. Ranking per seed would
    put 277 into "peak1" for seed 1 and average two different lines.
    """
    from servosurf.report import match_lines

    peaks = [
        [(170e3, 10.0), (277e3, 5.0), (400e3, 1.0)],
        [(277.5e3, 12.0), (171e3, 8.0)],
        [(172e3, 9.0)],
    ]
    lines = match_lines(peaks)
    np.testing.assert_array_equal(lines["peak1_per_m"], [170e3, 171e3, 172e3])
    np.testing.assert_array_equal(lines["peak2_per_m"], [277e3, 277.5e3, np.nan])
    # a line seen in fewer than half of the seeds (400) is not reported
    assert not any(400e3 in v for v in lines.values())


def test_realisations_bad_seeds(small_lens):
    from servosurf.report import realisation_study

    with pytest.raises(ConfigError, match="seeds"):
        realisation_study(small_lens, seeds=[])
    with pytest.raises(ConfigError, match="seeds"):
        realisation_study(small_lens, seeds=[2, -1])
    with pytest.raises(ConfigError, match="seeds="):
        realisation_study(small_lens, seeds=[1], seed=3)


def test_simulate_cli_realisations(tmp_path, capsys):
    rc = main(["simulate", LENS, "--realisations", "3", "--seed", "2", "--out",
               str(tmp_path / "r"), "--json", "--instrument", "none"])
    assert rc == 0
    data = json.loads(capsys.readouterr().out)
    assert data["seeds"] == [2, 3, 4]
    assert len(data["realisations"]["form_error_max_m"]) == 3
    st = data["statistics"]
    assert 150e-9 < st["form_error_rim_max_m"]["mean"] < 350e-9
    assert 0 < st["form_error_max_m"]["mean"] < st["form_error_rim_max_m"]["mean"]
    png = (tmp_path / "r" / "realisations.png").read_bytes()
    assert png[:8] == b"\x89PNG\r\n\x1a\n"
    saved = json.loads((tmp_path / "r" / "realisations.json").read_text())
    assert saved["realisations"] == data["realisations"]
    assert not list((tmp_path / "r").glob("surface.*"))  # the study, not a map
