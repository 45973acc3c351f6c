"""Oracle bound of an independent suite: what the data of each case carries.

Usage::

    python benchmarks/discovery/independent/oracle.py DIR [--alpha 0.02] [--json]

``DIR`` is a suite folder of ``generate.py`` (diagnosed by ``run.py`` or not).
This opens the key: run it after the blind diagnosis.

The generator's ENR is a time-domain figure: RMS(change) / RMS(noise) in the
recording where it is largest. A detector does not see that; the best one (a
matched filter that knows the effect exactly) sees the change *whitened* by the
noise it sits in. For every catalogue case the script rebuilds the case's
draws from its key entry (the generator is deterministic in the suite seed and
the case index; the rebuilt recordings are checked against the written ones),
writes the same campaign with the same noise realisation and no effect (the
"twin"), and evaluates the diagnosis's own whitened residual of every block at
the nominal model on both:

    SNR^2 = sum_b || r_b(case; p0) - r_b(twin; p0) ||^2 ,

the deviance an oracle detector gains (the noise cancels in linear blocks; the
idle Whittle blocks are linearised at the realisation). As in ``../bound.py``,
the Neyman-Pearson probability ``Phi(SNR - Phi^-1(1 - alpha))`` bounds the
detection rate any method reaches at false-alarm rate ``alpha``, and the
composite estimate ``P(chi2'(q, SNR^2) > chi2_q^-1(1 - alpha / M))`` is the rate
of a ``q``-parameter test that must also find which of ``M`` configurations it
is. Both assume the detected effect is then named correctly, so they are upper
bounds of top-1.

Both also assume the twin's residual is noise. It is not quite: the twin is the
independent simulator's nominal machine seen through servosurf's nominal model,
and where the two differ along the change ``d = r(case) - r(twin)`` the
difference adds to or cancels the effect. The script reports the matched filter
on the recordings themselves, ``r(case) . d / |d|`` and ``r(twin) . d / |d|``
(the "twin projection": an N(0, 1) draw for a faithful twin), and the
"realised" composite: ``P(max(case projection, 0)^2 + chi2(q - 1) >
chi2_q^-1(1 - alpha / M))``. ``snr_deterministic`` is the SNR of the change in
the mean alone (the twin's noisy recordings plus the clean case minus the clean
twin), without the part of the noise that runs through a changed loop.

Writes ``DIR/oracle.json`` and ``DIR/oracle.md`` and prints the table with the
observed top-1 of ``DIR/results`` where it exists.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
import tempfile
from pathlib import Path

HERE = Path(__file__).resolve().parent
if str(HERE.parent) not in sys.path:
    sys.path.insert(0, str(HERE.parent))


def replay(key: dict, index: int):
    """The drawn effect, campaign and noise seed of case ``index`` of ``key``.

    Repeats :func:`independent.generate.make_case`'s draws until the noise seed
    matches the key's (a redrawn case consumed earlier draws).
    """
    import numpy as np

    from independent import campaign as CP
    from independent.generate import MAX_DRAWS, draw

    entry = key["cases"][index]
    ctx = CP.context(key.get("chip_force", "continuous") == "held")
    rng = np.random.default_rng([key["seed"], index])
    for _ in range(MAX_DRAWS):
        eff, camp, nseed = draw(rng, entry["effect"], ctx)
        if nseed == entry["noise_seed"]:
            return ctx, eff, camp, nseed
    raise RuntimeError(f"{entry['case']}: the key's noise seed is not reproduced")


#: Measured arrays of a recording (shifted by the deterministic change); FRFs,
#: whose noise is relative, are scaled instead.
MEASURED = ("fe", "force", "z")


def deterministic_shift(noisy: dict, clean_case: dict, clean_twin: dict) -> dict:
    """The twin's noisy recordings plus the effect's deterministic change alone.

    ``noisy + (clean_case - clean_twin)`` for time records and maps, ``noisy
    clean_case / clean_twin`` for FRFs (relative noise). The noise realisation
    that runs through a changed loop (a mode rings on the base and current noise,
    a delay reshapes the sensor noise) differs between a case and its twin; that
    difference is random, not a mean shift a matched filter can use, and is left
    out here.
    """
    import numpy as np

    out: dict = {}
    for name, v in noisy.items():
        c, t = clean_case.get(name), clean_twin.get(name)
        if isinstance(v, np.ndarray):
            out[name] = v + (c - t)
        elif isinstance(v, tuple):  # (frequencies, FRF)
            out[name] = (v[0], v[1] * (c[1] / t[1]))
        elif isinstance(v, dict):
            out[name] = {k: (x + (c[k] - t[k]) if k in MEASURED else x)
                         for k, x in v.items()}
        else:
            out[name] = v
    return out


def _blocks(manifest: Path) -> dict:
    """The diagnosis's blocks of a case at the nominal model: ``{(recording,
    block index): block}``."""
    from servosurf.diagnose import Model, build_case, load_manifest
    from servosurf.diagnose._blocks import Context
    from servosurf.diagnose._diagnose import _make_blocks

    man = load_manifest(manifest)
    ctx = Context(build_case(man))
    return {(b.recording, i): b
            for i, b in enumerate(_make_blocks(man, ctx, Model()))}


#: The measured data each block kind holds (what :func:`_with_data` swaps).
DATA_FIELDS = ("records", "force", "frf", "pbar", "spec_records")


def _with_data(block, other):
    """``block`` (its weights, points and nuisance) holding ``other``'s data.

    Each block estimates its noise weighting from its own recording (instrument
    sigma, tool-noise scale, record noise levels, FRF noise). Differencing two
    blocks built from two recordings mixes in the difference of their weights:
    on case_0033 (a 24593-value map) the case's sigma was 4 % above its twin's,
    which put -0.04 r0 into ``d`` and a projection of -22 on the twin. The oracle
    compares a case and its twin under the twin's weighting (the noise alone
    sets it), so the statistic is linear in the data.
    """
    import copy

    b = copy.copy(block)
    if hasattr(block, "z_all"):  # a map or profile: the twin's kept points
        b.z = other.z_all[block.keep]
        # the model heights are memoised by the block's id and point set: key
        # the copy to the block it copies (a dead copy's id can be reused)
        b._points_gen = ("with-data", id(block), block._points_gen)
    for name in DATA_FIELDS:
        if hasattr(block, name) and hasattr(other, name):
            setattr(b, name, getattr(other, name))
    return b


def _residuals(manifest: Path, weights: Path | None = None) -> dict:
    """Whitened residual at the nominal model of every block: ``{(recording,
    block index): ndarray}``; with ``weights``, the blocks of that case (its
    noise weighting and points) applied to this one's data."""
    from servosurf.diagnose import Model

    p0 = Model()
    own = _blocks(manifest)
    if weights is None:
        return {k: b.residual(p0) for k, b in own.items()}
    ref = _blocks(weights)
    return {k: _with_data(ref[k], b).residual(p0) for k, b in own.items()}


def oracle(args) -> dict:
    """Oracle SNR of one case: ``{"case", "effect", "enr", "snr", "by_recording",
    "q", "check"}`` (``check``: largest relative difference between the rebuilt
    and the written recordings)."""
    key, index, root = args
    os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
    import numpy as np

    from independent import campaign as CP
    from servosurf.diagnose import get_effect

    entry = key["cases"][index]
    folder = Path(root) / "cases" / entry["case"]
    ctx, eff, camp, nseed = replay(key, index)
    spec = eff.make(entry["strength"])
    with tempfile.TemporaryDirectory() as tmp:
        rebuilt = Path(tmp) / "rebuilt"
        twin = Path(tmp) / "twin"
        det = Path(tmp) / "deterministic"
        CP.write_case(rebuilt, ctx, camp, CP.recordings(ctx, camp, spec, nseed))
        rec_twin = CP.recordings(ctx, camp, CP.nominal_spec(), nseed)
        CP.write_case(twin, ctx, camp, rec_twin)
        CP.write_case(det, ctx, camp, deterministic_shift(
            rec_twin, CP.recordings(ctx, camp, spec, nseed, clean=True),
            CP.recordings(ctx, camp, CP.nominal_spec(), nseed, clean=True)))
        check = 0.0
        for f in sorted(folder.iterdir()):
            if f.suffix == ".npz":
                a, b = np.load(f), np.load(rebuilt / f.name)
                for k in a.files:
                    d = np.max(np.abs(a[k] - b[k])) if a[k].size else 0.0
                    s = np.max(np.abs(a[k])) if a[k].size else 1.0
                    check = max(check, float(d / s) if s > 0 else float(d))
            elif f.suffix == ".csv":
                a = np.loadtxt(f, delimiter=",", skiprows=1)
                b = np.loadtxt(rebuilt / f.name, delimiter=",", skiprows=1)
                check = max(check, float(np.max(np.abs(a - b))
                                         / max(np.max(np.abs(a)), 1e-300)))
        # under the twin's weighting (see _with_data)
        r1 = _residuals(folder / "manifest.toml", twin / "manifest.toml")
        r0 = _residuals(twin / "manifest.toml")
        rd = _residuals(det / "manifest.toml", twin / "manifest.toml")
    by_rec: dict[str, float] = {}
    by_det: dict[str, float] = {}
    proj_case = proj_twin = 0.0
    for k, v in r1.items():
        d = v - r0[k]
        by_rec[k[0]] = by_rec.get(k[0], 0.0) + float(d @ d)
        proj_case += float(v @ d)
        proj_twin += float(r0[k] @ d)
        d = rd[k] - r0[k]
        by_det[k[0]] = by_det.get(k[0], 0.0) + float(d @ d)
    snr = math.sqrt(sum(by_rec.values()))
    q = max(get_effect(n).n_params() for n in entry["expected"])
    return {
        "case": entry["case"],
        "effect": entry["effect"],
        "expected": entry["expected"],
        "enr": entry["enr_target"],
        "enr_achieved": entry["enr"],
        "enr_by_recording": entry.get("enr_by_recording", {}),
        "q": q,
        "snr": snr,
        "by_recording": {k: math.sqrt(v) for k, v in by_rec.items()},
        # the matched filter on the recordings themselves: the case's residual and
        # the twin's along the change d (r . d / |d|); a faithful twin gives an
        # N(0, 1) draw, the case that plus the SNR; a twin far from 0 is a
        # difference of the two simulators' nominal machines along d
        "case_projection": proj_case / snr if snr > 0 else 0.0,
        "twin_projection": proj_twin / snr if snr > 0 else 0.0,
        "snr_deterministic": math.sqrt(sum(by_det.values())),
        "by_recording_deterministic": {k: math.sqrt(v) for k, v in by_det.items()},
        "check": check,
    }


def _observed(results: Path, row: dict):
    """1/0: the case's top-1 is an expected name with an explained/partly verdict;
    None without a result."""
    f = results / f"{row['case']}.json"
    if not f.exists():
        return None
    r = json.loads(f.read_text())
    if "error" in r or "verdict" not in r:
        return 0
    ex = sorted(r.get("explanations", []), key=lambda e: -e["delta_bic"])
    ok = r["verdict"] in ("explained", "partly-explained")
    return int(ok and bool(ex) and ex[0]["effect"] in row["expected"])


def summarise(rows: list[dict], alpha: float, m: int, results: Path) -> dict:
    """Bound and observed top-1 per target ENR and per case."""
    from bound import composite, np_bound

    out: dict = {"alpha": alpha, "configurations": m, "by_enr": {}}
    for r in rows:
        r["np_bound"] = np_bound(r["snr"], alpha)
        r["composite"] = composite(r["snr"], r["q"], alpha, m)
        r["realised"] = (realised(r["case_projection"], r["q"], alpha, m)
                         if "case_projection" in r else None)
        r["observed_top1"] = _observed(results, r)
        r["snr_over_enr"] = r["snr"] / r["enr_achieved"] if r["enr_achieved"] else None
    for enr in sorted({r["enr"] for r in rows}):
        rs = [r for r in rows if r["enr"] == enr]
        snrs = sorted(r["snr"] for r in rs)
        obs = [r["observed_top1"] for r in rs if r["observed_top1"] is not None]
        rea = [r["realised"] for r in rs if r.get("realised") is not None]
        twin = sorted(abs(r["twin_projection"]) for r in rs if "twin_projection" in r)
        out["by_enr"][str(enr)] = {
            "n": len(rs),
            "median_snr": snrs[len(snrs) // 2],
            "cases_snr_below_3": sum(1 for s in snrs if s < 3.0),
            "bound_top1": sum(r["np_bound"] for r in rs) / len(rs),
            "composite_top1": sum(r["composite"] for r in rs) / len(rs),
            "observed_top1": sum(obs) / len(obs) if obs else None,
            "observed_n": len(obs),
            "realised_top1": sum(rea) / len(rea) if rea else None,
            "median_abs_twin_projection": twin[len(twin) // 2] if twin else None,
            "cases_twin_projection_above_3": sum(1 for t in twin if t > 3.0),
        }
    return out


def realised(projection: float, q: int, alpha: float, m: int) -> float:
    """Detection probability of the ``q``-parameter test on the recorded noise:
    the case's residual along the change gives ``max(projection, 0)^2`` of its
    deviance gain (the realised value, simulator differences included), the other
    ``q - 1`` directions a chi2(q - 1) draw, against the Bonferroni threshold
    ``chi2_q^-1(1 - alpha / m)``."""
    from scipy.stats import chi2

    thr = float(chi2.isf(alpha / m, q))
    gain = max(projection, 0.0) ** 2
    if q <= 1:
        return float(gain > thr)
    return float(chi2.sf(max(thr - gain, 0.0), q - 1))


def table(s: dict, rows: list[dict]) -> str:
    """Markdown tables of :func:`summarise`."""
    lines = [
        f"Oracle bound at a false-alarm rate of {s['alpha']:.0%} "
        f"({s['configurations']} configurations for the composite estimate):",
        "",
        "| target ENR | n | median oracle SNR | cases SNR < 3 | NP bound | composite | "
        "realised composite | median abs twin projection (cases > 3) | "
        "observed top-1 |",
        "|---|---|---|---|---|---|---|---|---|",
    ]

    def pct(v):
        return "" if v is None else f"{v:.0%}"

    for enr, d in s["by_enr"].items():
        ob = d["observed_top1"]
        tw = d.get("median_abs_twin_projection")
        lines.append(
            f"| {enr} | {d['n']} | {d['median_snr']:.2f} | {d['cases_snr_below_3']} | "
            f"{d['bound_top1']:.0%} | {d['composite_top1']:.0%} | "
            f"{pct(d.get('realised_top1'))} | "
            + (f"{tw:.2f} ({d['cases_twin_projection_above_3']})" if tw is not None
               else "") + " | "
            + (f"{ob:.0%} (n={d['observed_n']})" if ob is not None else "") + " |")
    lines += ["", "| case | effect | ENR (achieved) | oracle SNR | largest recording "
              "(SNR) | NP | composite | twin projection | realised | observed |",
              "|---|---|---|---|---|---|---|---|---|---|"]
    for r in sorted(rows, key=lambda r: (r["enr"], r["effect"])):
        best = max(r["by_recording"].items(), key=lambda kv: kv[1], default=("", 0.0))
        ob = r["observed_top1"]
        tw = r.get("twin_projection")
        lines.append(
            f"| {r['case']} | {r['effect']} | {r['enr_achieved']:.3g} | "
            f"{r['snr']:.2f} | {best[0]} ({best[1]:.2f}) | {r['np_bound']:.0%} | "
            f"{r['composite']:.0%} | {'' if tw is None else f'{tw:+.2f}'} | "
            f"{pct(r.get('realised'))} | {'' if ob is None else ob} |")
    return "\n".join(lines)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("out", type=Path, help="suite folder of generate.py")
    ap.add_argument("--alpha", type=float, default=0.02,
                    help="false-alarm rate (1) of the bound (the suite's target)")
    ap.add_argument("--configurations", type=int, default=180,
                    help="configurations screened (1), the Bonferroni count of the "
                    "composite estimate")
    ap.add_argument("--jobs", type=int, default=1, help="worker processes")
    ap.add_argument("--json", action="store_true", help="print JSON instead")
    a = ap.parse_args(argv)
    if not (a.out / "key.sealed").exists():
        print(f"error: {a.out}/key.sealed does not exist (not a generate.py suite)",
              file=sys.stderr)
        return 1
    if not 0.0 < a.alpha < 1.0:
        print(f"error: --alpha {a.alpha}: must be in (0, 1)", file=sys.stderr)
        return 1
    from independent.generate import unseal

    key = unseal(a.out)
    todo = [(key, i, str(a.out)) for i, e in enumerate(key["cases"])
            if e.get("klass") == "catalogue" and "generation_error" not in e
            and (a.out / "cases" / e["case"]).is_dir()]
    rows: list[dict] = []
    old = {}
    if (a.out / "oracle.json").exists():
        old = {r["case"]: r for r in json.loads((a.out / "oracle.json").read_text())
               .get("cases", [])}
    rows = [old[key["cases"][i]["case"]] for _, i, _ in todo
            if key["cases"][i]["case"] in old]
    todo = [t for t in todo if key["cases"][t[1]]["case"] not in old]

    def report(k, r):
        print(f"[{k}/{len(todo)}] {r['case']} {r['effect']} ENR {r['enr_achieved']:.3g}"
              f": oracle SNR {r['snr']:.2f} (rebuilt to {r['check']:.1e})",
              file=sys.stderr, flush=True)

    if a.jobs > 1:
        import multiprocessing as mp

        with mp.get_context("spawn").Pool(a.jobs) as pool:
            for k, r in enumerate(pool.imap_unordered(oracle, todo)):
                rows.append(r)
                report(k + 1, r)
    else:
        for k, t in enumerate(todo):
            rows.append(oracle(t))
            report(k + 1, rows[-1])
    s = summarise(rows, a.alpha, a.configurations, a.out / "results")
    s["cases"] = sorted(rows, key=lambda r: r["case"])
    (a.out / "oracle.json").write_text(json.dumps(s, indent=1))
    tab = table(s, rows)
    (a.out / "oracle.md").write_text(tab + "\n")
    print(json.dumps({k: v for k, v in s.items() if k != "cases"}, indent=1)
          if a.json else tab)
    return 0


if __name__ == "__main__":
    sys.exit(main())
