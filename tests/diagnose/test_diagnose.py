"""servosurf diagnose: catalogue, manifest errors, and a blind benchmark subset.

The effect tests run the benchmark machinery (``benchmarks/discovery``) on a small
sealed suite with the short ``test`` campaign: the cases are generated with the key
sealed, diagnosed from their manifests only (two worker processes), then scored.
Seeds are fixed; the verdicts at ENR 0.5 are far from the decision thresholds.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
import pytest

from servosurf.cli import main

REPO = Path(__file__).resolve().parents[2]
BENCH = REPO / "benchmarks" / "discovery"
PNG = b"\x89PNG\r\n\x1a\n"

REQUIRED = (
    "structural-mode",
    "loop-delay",
    "base-vibration-lines",
    "thermal-drift",
    "flexure-stiffness-nonlinearity",
    "force-constant-position",
    "amplifier-saturation",
    "sensor-nonlinearity",
    "sensor-noise-shape",
    "tool-edge-waviness",
    "tool-radius-error",
    "cutting-force-coefficient",
    "spindle-axial-error",
    "elastic-recovery",
)

#: Effects of the blind subset: (effect, primary parameter tolerance).
EFFECTS = {
    "structural-mode": 0.10,
    "loop-delay": 0.10,
    "base-vibration-lines": 0.10,
    "amplifier-saturation": 0.10,
    "tool-radius-error": 0.10,
}
#: Tolerance of parameter errors (relative, see benchmarks/discovery/score.py).
PARAM_TOL = 0.10


def _bench():
    if str(BENCH) not in sys.path:
        sys.path.insert(0, str(BENCH))
    import generate
    import run
    import score

    return generate, run, score


# ------------------------------------------------------------------ catalogue
def test_list_prints_every_effect_with_parameters_and_units(capsys):
    assert main(["diagnose", "--list"]) == 0
    out = capsys.readouterr().out
    for name in REQUIRED:
        assert f"\n{name}:" in "\n" + out, name
    # every parameter line names its unit in brackets
    params = [
        ln
        for ln in out.splitlines()
        if ln.startswith("    ")
        and "[" in ln
        and "]" in ln
        and ":" not in ln.split("]")[0]
    ]
    assert len(params) >= 2 * len(REQUIRED)
    assert "max_current [A]" in out and "extra_delay [s]" in out
    assert "compliance [m/N]" in out and "floor [m/sqrt(Hz)]" in out


def test_list_json_has_units():
    from servosurf.diagnose import catalogue_table

    table = {e["effect"]: e for e in catalogue_table()}
    assert set(REQUIRED) <= set(table)
    for name in REQUIRED:
        assert table[name]["parameters"], name
        for q in table[name]["parameters"]:
            assert q["unit"], (name, q)
        assert table[name]["signature"] and table[name]["confused_with"]


# ------------------------------------------------------------------ manifest errors
def _manifest(tmp_path: Path, body: str) -> Path:
    m = tmp_path / "manifest.toml"
    m.write_text(
        '[case]\nmachine = "seed-prototype"\nbandwidth = 468.0\n'
        "moving-mass = 0.175\n\n" + body
    )
    return m


def _fe_csv(path: Path, header: str = "time_s,following_error_m") -> Path:
    t = np.arange(64) / 199.6e3
    rng = np.random.default_rng(3)  # any numbers: the header is what is tested
    path.write_text(
        header
        + "\n"
        + "\n".join(
            f"{a:.9g},{b:.3g}"
            for a, b in zip(t, 1e-9 * rng.standard_normal(64), strict=True)
        )
        + "\n"
    )
    return path


@pytest.mark.parametrize(
    "case, match",
    [
        ("missing-manifest", "no such file"),
        ("missing-recording", "no such file"),
        ("unknown-kind", "unknown kind"),
        ("bad-header", "bad CSV header"),
        ("no-recordings", "no [[recording]]"),
        ("unknown-key", "unknown key"),
    ],
)
def test_manifest_errors_one_line_exit_1(tmp_path, capsys, case, match):
    if case == "missing-manifest":
        m = tmp_path / "nope.toml"
    elif case == "missing-recording":
        m = _manifest(
            tmp_path, '[[recording]]\npath = "gone.csv"\nkind = "following-error"\n'
        )
    elif case == "unknown-kind":
        _fe_csv(tmp_path / "fe.csv")
        m = _manifest(tmp_path, '[[recording]]\npath = "fe.csv"\nkind = "accel"\n')
    elif case == "bad-header":
        _fe_csv(tmp_path / "fe.csv", header="t,err")
        m = _manifest(
            tmp_path, '[[recording]]\npath = "fe.csv"\nkind = "following-error"\n'
        )
    elif case == "no-recordings":
        m = _manifest(tmp_path, "")
    else:
        _fe_csv(tmp_path / "fe.csv")
        m = _manifest(
            tmp_path,
            '[[recording]]\npath = "fe.csv"\nkind = "following-error"\ngain = 2\n',
        )
    assert main(["diagnose", str(m), "--out", str(tmp_path / "o")]) == 1
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1, err
    assert match in err


def test_diagnose_without_manifest_is_a_user_error(capsys):
    assert main(["diagnose"]) == 1
    assert "MANIFEST" in capsys.readouterr().err


def test_a_record_too_slow_to_compare_is_a_user_error(tmp_path, capsys):
    t = np.arange(256) / 100.0  # 100 Hz: Nyquist 50 Hz, the model starts at 48.7 Hz
    np.savez(tmp_path / "fe.npz", time_s=t, following_error_m=np.zeros(256))
    m = _manifest(
        tmp_path, '[[recording]]\npath = "fe.npz"\nkind = "following-error"\n'
    )
    assert main(["diagnose", str(m), "--out", str(tmp_path / "o")]) == 1
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "no frequencies to compare" in err, err


# ------------------------------------------------------------------ blind subset
@pytest.fixture(scope="module")
def blind(tmp_path_factory):
    """A sealed mini-suite on the test campaign, diagnosed blind, then scored."""
    generate, run, score = _bench()
    out = tmp_path_factory.mktemp("blind")
    specs = [{"effects": [], "enr": 0.0}]
    specs += [{"effects": [e], "enr": 0.5} for e in EFFECTS]
    specs += [{"effects": [], "ool": "opposite-sign-mode", "enr": 1.0}]
    generate.generate_specs(out, specs, campaign="test", seed=5, jobs=2)
    run.diagnose_all(out, jobs=2, progress=False)
    results = {
        f.stem: json.loads(f.read_text()) for f in (out / "results").glob("case_*.json")
    }
    key = generate.unseal(out)  # opened only after every diagnosis is written
    return out, results, key, score


def _case(blind, effects, ool=None):
    out, results, key, score = blind
    for k in key["cases"]:
        if k["effects"] == effects and k["ool"] == ool:
            return k, results[k["case"]]
    raise KeyError(effects)


def _case_manifest(blind, effects, ool=None):
    """The loaded manifest of the mini-suite case with ``effects``."""
    from servosurf.diagnose._manifest import load_manifest

    k, _r = _case(blind, effects, ool)
    return load_manifest(blind[0] / "cases" / k["case"] / "manifest.toml")


def _context(man):
    """The diagnosis context of a loaded manifest."""
    from servosurf.diagnose._blocks import Context
    from servosurf.diagnose._diagnose import build_case

    return Context(build_case(man))


def test_null_case_is_consistent(blind):
    _k, r = _case(blind, [])
    assert "error" not in r, r.get("error")
    assert r["verdict"] == "consistent", (
        r["verdict"],
        r["explanations"],
        r["remainder"][:3],
    )
    assert r["explanations"] == [] and r["unexplained_power_fraction"] == 0.0


@pytest.mark.parametrize("effect", list(EFFECTS))
def test_effect_top1_and_parameter(blind, effect):
    _out, _results, _key, score = blind
    k, r = _case(blind, [effect])
    assert "error" not in r, r.get("error")
    ex = sorted(r["explanations"], key=lambda e: -e["delta_bic"])
    assert r["verdict"] in ("explained", "partly-explained"), (r["verdict"], ex)
    assert ex and ex[0]["effect"] == effect, [e["effect"] for e in ex]
    err = score.param_error(
        effect, k["truth"][effect], ex[0]["parameters"], score._nominal()
    )
    assert err <= EFFECTS[effect], (
        effect,
        err,
        k["truth"][effect],
        ex[0]["parameters"],
    )
    assert r["fit_after_percent"] >= r["fit_before_percent"] - 1e-6


def test_out_of_catalogue_is_not_a_confident_wrong_name(blind):
    _k, r = _case(blind, [], "opposite-sign-mode")
    assert "error" not in r, r.get("error")
    assert r["verdict"] in ("unexplained", "partly-explained"), (
        r["verdict"],
        r["explanations"],
    )


def test_subset_scores(blind):
    out, _results, _key, score = blind
    s = score.score(out)
    assert s["errors"] == 0
    assert s["false_alarm_rate"] == 0.0
    assert s["top1_enr_ge_0.1"] == 1.0
    assert s["median_param_error_enr_ge_0.1"] <= PARAM_TOL
    assert s["ool_flagged"] == 1.0
    assert "| top-1 attribution, ENR >= 0.1 |" in score.table(s)


def test_cli_writes_fitted_machine_pictures_and_json(blind, tmp_path, capsys):
    from servosurf.servo import load_machine

    out, _results, key, _score = blind
    k = next(c for c in key["cases"] if c["effects"] == ["loop-delay"])
    # the case's FRFs, idle records and map (its cut record, air cut and ring
    # profile left out: the CLI's outputs are under test, a third of the time)
    head, *recs = (out / "cases" / k["case"] / "manifest.toml").read_text().split(
        "[[recording]]")
    keep = [r for r in recs if not any(
        name in r for name in ("aircut.", "cut.csv", "ring0."))]
    assert len(keep) == len(recs) - 3
    manifest = out / "cases" / k["case"] / "manifest_cli.toml"
    manifest.write_text("[[recording]]".join([head, *keep]))
    dest = tmp_path / "diag"
    assert main(["diagnose", str(manifest), "--out", str(dest), "--json"]) == 0
    data = json.loads(capsys.readouterr().out)
    assert set(data) >= {
        "verdict",
        "mismatches",
        "explanations",
        "fit_before_percent",
        "fit_after_percent",
        "unexplained_power_fraction",
        "refused",
        "acceptance",
    }
    assert data["acceptance"]["rule"].startswith("held-out")
    assert data["verdict"] == "explained"
    for m in data["mismatches"]:
        assert set(m) >= {"recording", "domain", "where", "significance"}
    for r in data["refused"]:  # candidates refused as physically implausible
        assert set(r) >= {"effect", "parameters", "reason"} and r["reason"]
    e = data["explanations"][0]
    assert set(e) >= {
        "effect",
        "parameters",
        "delta_bic",
        "fit_before_percent",
        "fit_after_percent",
        "held_out_improvement",
        "signature",
        "indistinguishable_from",
    }
    # the named term's size: above the model-fidelity floor in its recording
    from servosurf.diagnose._select import FIDELITY_ENR

    sig = e["signature"]
    assert sig["signature_enr"] >= FIDELITY_ENR
    assert sig["recording"] in sig["by_recording"]
    assert sig["signature_enr"] == max(v["signature_enr"]
                                       for v in sig["by_recording"].values())
    fitted = load_machine(dest / "fitted-machine.toml")
    d_true = k["truth"]["loop-delay"]["extra_delay_s"] * 199.6e3
    nominal = load_machine().controller.delay
    assert abs(fitted.controller.delay - nominal - d_true) <= 0.1 * abs(d_true)
    assert fitted.controller.kp is not None  # the installed controller is kept
    pngs = sorted(dest.glob("*.png"))
    assert any("frf" in p.name for p in pngs) and any("map" in p.name for p in pngs)
    for p in pngs:
        assert p.read_bytes()[:8] == PNG


def test_spline_onto_record_times_meets_the_cubic_spline_bound():
    """A controller-rate signal seen at another rate's sample times: the cubic
    spline's error stays under 5/384 h^4 max|d4f/dt4| (plus rounding), the loop
    starts at the record's first time, and a diverged array stays non-finite."""
    from servosurf.diagnose._blocks import on_record_grid

    class _Case:
        fs = 199.6e3

    f0 = 3.0e3
    t_rec = 1.3e-3 + np.arange(500) / 77.0e3
    seen = {}

    def sim(tc):
        seen["t0"] = tc[0]
        seen["step"] = float(np.diff(tc).mean())
        bad = np.sin(tc)
        bad[7] = np.nan
        return {"fe": np.sin(2 * np.pi * f0 * tc), "u": bad, "k": 3.0}

    out = on_record_grid(_Case(), t_rec, sim)
    bound = 5.0 / 384.0 * (1.0 / _Case.fs) ** 4 * (2 * np.pi * f0) ** 4 + 1e-14
    err = np.abs(out["fe"] - np.sin(2 * np.pi * f0 * t_rec))
    # the end intervals of a not-a-knot spline are looser: interior points only
    assert err[5:-5].max() <= bound, (err.max(), bound)
    assert seen["t0"] == t_rec[0]
    assert seen["step"] == pytest.approx(1.0 / _Case.fs, rel=1e-9)
    assert np.all(np.isnan(out["u"])) and out["k"] == 3.0


def test_records_at_another_rate_are_compared_at_their_own_samples(blind):
    """Every second sample of a case's records (fs / 2): the loop still runs at
    the controller rate and its prediction at the kept samples is the full-rate
    one; idle records are compared up to the record's Nyquist frequency."""
    from servosurf.diagnose import Model
    from servosurf.diagnose._blocks import (
        CutBlock,
        SpectralBlock,
        TimeBlock,
        line_power,
    )
    from servosurf.diagnose._diagnose import _make_blocks
    from servosurf.diagnose.effects import BaseLineParams

    man = _case_manifest(blind, ["base-vibration-lines"])
    ctx = _context(man)
    case = ctx.case
    p = Model.of(BaseLineParams(1234.5, 3e-9))
    kinds = set()
    for b in _make_blocks(man, ctx, Model()):
        if isinstance(b, CutBlock):
            kinds.add("cut")
            d = {
                "fs": b.fs / 2,
                "t": (b.k0 + np.arange(b.n_sim))[::2] / b.fs,
                "fe": b.records[0]["fe"][::2],
            }
            half = CutBlock(ctx, "half", d, p)
            full = b.predict(p)["fe"][::2]
            err = np.max(np.abs(half.predict(p)["fe"] - full))
            assert err <= 1e-12 * np.max(np.abs(full))
        elif isinstance(b, TimeBlock):
            kinds.add("time")
            recs = [
                {k: v[::2] if isinstance(v, np.ndarray) else v for k, v in r.items()}
                for r in b.records
            ]
            half = TimeBlock(ctx, "half", recs, b.fs / 2, p)
            for i in range(len(recs)):
                full = b.predict(p, i)["fe"][::2]
                got = half.predict(p, i)["fe"]
                # the command is splined from every second sample: its error is
                # at most 5/384 h^4 max|d4 command| (h = 2 / fs), passed to the
                # following error with a gain of at most the sensitivity peak (< 2)
                cmd = b.records[i].get("command", np.zeros(2))
                d4 = np.max(np.abs(np.diff(cmd, 4))) * b.fs**4 if cmd.size > 4 else 0
                bound = 2 * 2 * 5.0 / 384.0 * (2.0 / b.fs) ** 4 * d4
                assert np.max(np.abs(got - full)) <= bound + 1e-12 * np.max(
                    np.abs(full)
                )
            f = half.meta[0][2]
            assert f.max() < 0.8 * b.fs / 4 and f.min() >= case.fs / 4096 * (1 - 1e-9)
        elif isinstance(b, SpectralBlock):
            kinds.add("spectrum")
            rec = next(r for r in man.recordings if r.name == b.recording)
            fe = np.array([r["fe"][::2] for r in rec.data["records"]])
            half = SpectralBlock(ctx, "half", fe, b.fs / 2)
            assert half.freq.max() < 0.8 * b.fs / 4
            assert half.freq.min() >= case.fs / 4096 * (1 - 1e-9)
            lp = line_power(case, p, half.freq, fe.shape[1], fs=b.fs / 2)
            got = half.expected(p) - lp
            # the records are projected at their own rate too: the expectation
            # is 2 / (fs n) a_k^H P R P a_k with R the Toeplitz covariance of the
            # model's autocovariance at fs / 2 and P the projection (dense
            # matrices here; the block uses FFT identities)
            from scipy.linalg import toeplitz

            from servosurf.diagnose._blocks import sampled_autocov

            n, fs2 = fe.shape[1], b.fs / 2
            proj = np.eye(n) - half.basis @ half.basis.T
            m = proj @ toeplitz(sampled_autocov(case, p, n, fs2)) @ proj
            k = np.rint(half.freq * n / fs2).astype(int)
            ak = np.exp(2j * np.pi * np.outer(k, np.arange(n)) / n)
            akm = np.fft.fft(m, axis=0)[k]  # conj(a_k)^T m
            dense = np.real(np.sum(akm * ak, axis=1)) * 2 / (fs2 * n)
            np.testing.assert_allclose(got, dense, rtol=1e-8)
            # the projection takes most of the power of the bin at its edge
            assert got[0] < 0.5 * case.noise_psd(p, half.freq[:1], "fe")[0]
            # the line's power sits at the record's own bin of 1234.5 Hz
            assert abs(half.freq[np.argmax(lp)] - 1234.5) <= b.fs / 2 / fe.shape[1]
    assert kinds == {"cut", "time", "spectrum"}


def test_blocks_kept_by_a_rebuild_are_those_a_fresh_build_gives(blind):
    """After a term is accepted the diagnosis rebuilds the noise weighting, but
    keeps a recording's blocks when nothing they read changed: each kept block
    scores every model as a block built afresh at the new model does, and a
    term that changes a block's weighting (a tool radius for the map, a loop
    delay for the FRFs and records) has it rebuilt."""
    from servosurf.diagnose import Model
    from servosurf.diagnose._blocks import (
        ForceBlock,
        FRFBlock,
        PointsBlock,
        SpectralBlock,
    )
    from servosurf.diagnose._diagnose import _make_blocks, _rebuild
    from servosurf.diagnose.effects import LoopDelayParams, ToolRadiusErrorParams

    man = _case_manifest(blind, ["tool-radius-error"])
    ctx = _context(man)
    blocks0 = _make_blocks(man, ctx, Model())
    radius = Model.of(ToolRadiusErrorParams(2e-6))
    delay = Model.of(LoopDelayParams(4e-6))
    assert all(a is b for a, b in zip(_rebuild(blocks0, ctx, man, Model()), blocks0,
                                      strict=True))
    kept_by = {}
    for p in (radius, delay):
        rebuilt = _rebuild(blocks0, ctx, man, p)
        fresh = _make_blocks(man, ctx, p)
        for f, b0 in zip(fresh, blocks0, strict=True):
            if isinstance(f, FRFBlock | ForceBlock):  # noise levels of the nominal
                f.sigma = b0.sigma
        kept_by[p] = {b.recording for b, b0 in zip(rebuilt, blocks0, strict=True)
                      if b is b0}
        for b, f in zip(rebuilt, fresh, strict=True):
            assert (b.recording, b.n) == (f.recording, f.n)
            for q in (Model(), p):
                np.testing.assert_allclose(b.deviance(q), f.deviance(q), rtol=1e-9)
    maps = {b.recording for b in blocks0 if isinstance(b, PointsBlock)}
    idle = {b.recording for b in blocks0 if isinstance(b, SpectralBlock)}
    assert maps and not maps & kept_by[radius]
    assert idle <= kept_by[radius] and idle <= kept_by[delay]  # built at no model
    assert len(kept_by[radius]) > len(idle) > 0
    assert kept_by[delay] == idle


def test_time_records_at_half_rate_are_whitened_at_their_own_rate(blind):
    """Every second sample of a null case's command records: the whitened
    residual's mean square is the model's aliased-to-unaliased power ratio
    mean(1 + S(fs/2 - f) / S(f)) (subsampling folds the band above the new
    Nyquist frequency), within 5 standard errors."""
    from servosurf.diagnose import Model
    from servosurf.diagnose._blocks import CutBlock, TimeBlock
    from servosurf.diagnose._diagnose import _make_blocks

    man = _case_manifest(blind, [])
    ctx = _context(man)
    case = ctx.case
    p = Model()
    checked = 0
    for b in _make_blocks(man, ctx, p):
        if not isinstance(b, TimeBlock) or isinstance(b, CutBlock):
            continue
        recs = [
            {k: v[::2] if isinstance(v, np.ndarray) else v for k, v in r.items()}
            for r in b.records
        ]
        fr = b.fs / 2
        half = TimeBlock(ctx, "half", recs, fr, p)
        for i in range(len(recs)):
            f = half.meta[i][2]
            s = case.noise_psd(p, f, "fe")
            want = float(np.mean(1.0 + case.noise_psd(p, fr - f, "fe") / s))
            x = half.whitened(p, i)
            v = np.concatenate([x.real, x.imag]) ** 2
            se = np.std(v) / np.sqrt(v.size)
            assert abs(v.mean() - want) <= 5 * se, (v.mean(), want, se)
            checked += 1
    assert checked >= 1


def test_idle_records_at_half_the_controller_rate_run_end_to_end(
    blind, tmp_path, capsys
):
    """A null case's idle records, anti-aliased and decimated by 2, are found
    consistent with the model (the decimator's roll-off near the new Nyquist
    frequency is outside the compared band)."""
    from scipy.signal import decimate

    man = _case_manifest(blind, [])
    rec = next(
        r
        for r in man.recordings
        if r.kind == "following-error"
        and not any("command" in x or "force" in x for x in r.data["records"])
    )
    fe = np.array([r["fe"] for r in rec.data["records"]])
    half = decimate(fe, 2, ftype="fir", zero_phase=True, axis=1)
    np.savez(tmp_path / "idle.npz", fs_hz=rec.data["fs"] / 2, following_error_m=half)
    m = _manifest(
        tmp_path, '[[recording]]\npath = "idle.npz"\nkind = "following-error"\n'
    )
    assert main(["diagnose", str(m), "--out", str(tmp_path / "o"), "--json"]) == 0
    d = json.loads(capsys.readouterr().out)
    assert d["verdict"] == "consistent", (d["mismatches"], d["explanations"])


# ------------------------------------------------------------------ surface model
def test_pointwise_surface_matches_the_sweep_kernel():
    """The diagnosis's pointwise surface equals servosurf.toolpath.sweep."""
    import dataclasses

    from servosurf.diagnose import CaseModel, Model
    from servosurf.diagnose._surface import PointSet, surface_heights, tool_trajectory
    from servosurf.servo import load_machine
    from servosurf.toolpath import load_toolpath, sample, sweep

    spec = load_toolpath(REPO / "toolpaths" / "lenslet_5um.toml")
    fld = dataclasses.replace(spec.field, nx=120, ny=100)
    case = CaseModel(load_machine().with_moving_mass(0.175).with_bandwidth(468.0),
                     spec)
    traj = tool_trajectory(case, Model())
    path = sample(spec, field=fld)
    ref = sweep(path.with_z(traj(path.t)), spec.tool, fld)
    x, y = fld.coords()
    xx, yy = np.meshgrid(x, y)
    z = surface_heights(case, PointSet(case, xx.ravel(), yy.ravel()), Model(),
                        traj).reshape(xx.shape)
    assert (z < -1e-6).mean() > 0.2  # the field holds a good part of a lenslet
    np.testing.assert_allclose(z, ref.z, rtol=0, atol=1e-15)  # 1 fm


def test_force_excess_test_is_calibrated_with_an_estimated_sigma():
    """White force noise, sigma from the periodogram median of the top of the band
    as ForceBlock does: the power-excess test's false-alarm rate matches its
    nominal level (the chi2(n) test that treats sigma as known fires several times
    too often at 1 %)."""
    import math

    from servosurf.diagnose._blocks import white_level
    from servosurf.diagnose._locate import _chi2_logsf, force_excess_logsf

    def compared(x, fs, hi):
        sig, var_log, keep = white_level(x, fs, hi)
        xf = np.fft.rfft(x)[keep] / math.sqrt(0.5 * x.size * sig**2)
        return np.concatenate([xf.real, xf.imag]), var_log

    rng = np.random.default_rng(11)
    fs = 199.6e3
    n, trials = 8192, 1500
    lp_new, lp_naive = [], []
    for _ in range(trials):
        x = rng.standard_normal(n) * 2e-3  # N
        r, var_log = compared(x, fs, fs / 2)
        lp_new.append(force_excess_logsf(r, var_log))
        lp_naive.append(_chi2_logsf(float(r @ r), r.size))
    fa_new = np.mean(np.array(lp_new) < -2)  # nominal 1 %
    fa_naive = np.mean(np.array(lp_naive) < -2)
    assert 0.003 <= fa_new <= 0.022, fa_new
    assert fa_naive > 0.03, fa_naive
    # a real excess (8 % of the variance) is still found
    x = rng.standard_normal(32768)
    slow = 0.4 * np.sin(np.linspace(0, 20 * np.pi, x.size))  # smooth misfit
    r, var_log = compared(x + slow, fs, fs / 2)
    assert force_excess_logsf(r, var_log) < -4


def test_force_level_of_an_anti_aliased_record_is_its_passband_level():
    """Force noise logged at half the controller rate through scipy's FIR
    decimator: the level from the band top (0.8 Nyquist) is the white level, while
    the MAD of first differences reads the filter's roll-off as less noise."""
    import math

    from scipy.signal import resample_poly

    from servosurf.diagnose._blocks import RESAMPLED_BAND, white_level

    rng = np.random.default_rng(5)
    x = resample_poly(rng.standard_normal(2 * 32768) * 1e-3, 1, 2,
                      window=("kaiser", 10.0))  # N, white to 0.9 of Nyquist
    fs = 99.8e3
    sig, _var, _keep = white_level(x, fs, RESAMPLED_BAND * fs / 2)
    want = 1e-3 / math.sqrt(2.0)  # the decimator halves the noise power
    assert abs(sig / want - 1) < 0.03, sig / want
    d = np.diff(x)
    mad = 1.4826 * np.median(np.abs(d - np.median(d))) / math.sqrt(2.0)
    assert mad / want < 0.97  # what the previous estimate read
