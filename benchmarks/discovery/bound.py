"""Information bound of a generated suite: how well could any detector do?

Usage::

    python benchmarks/discovery/bound.py OUT [--enr 0.03] [--alpha 0.02] [--json]

``OUT`` is a suite folder written with ``run.py --keep`` (case folders, sealed key
and, if present, ``results/``). This opens the key, so run it after the blind
diagnosis, never before.

For every single-effect case the truth is rebuilt from its spec (the generator is
deterministic in the case seed) and the effect's size is measured in the
diagnosis's own likelihood: every block's whitened residual at the nominal model
``r_b(p0)`` and at the true model ``r_b(p_true)``, both with the nominal noise
weighting, give the oracle signal-to-noise ratio

    SNR^2 = sum_b || r_b(p0) - r_b(p_true) ||^2,

the deviance a detector that already knows the effect and its parameters expects
to gain. For a known signal in Gaussian noise the Neyman-Pearson test is the best
there is; at a false-alarm rate ``alpha`` it detects with probability

    P_D = Phi(SNR - Phi^-1(1 - alpha)).

That is an upper bound for the diagnosis, which must also find the effect among
the catalogue's 14 and fit its parameters: the mean of ``P_D`` over the cases of
one ENR bounds the top-1 rate any method can reach on that campaign.

A second, less generous figure is what a detector that does not know which
effect is there can expect: a likelihood-ratio test of the effect's ``q``
parameters (its catalogue entry) against the chi2(q) threshold at ``alpha / M``,
``M`` the configurations screened (Bonferroni over the catalogue; the
diagnosis ranks about 180), detects with probability
``P(chi2'(q, SNR^2) > chi2_q^-1(1 - alpha / M))`` (non-central chi2; the fitted
deviance gain is ``SNR^2`` plus ``q`` on average). It still assumes the right
effect wins the attribution whenever it is detected.

SNR grows as the square root of the recorded data, so the script also prints
how many times more records of every kind that estimate needs to reach the
target.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))


def oracle(args) -> dict:
    """Oracle SNR of one case: ``{"case", "effect", "enr", "snr", "by_recording"}``."""
    entry, root = args
    os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
    import cases as C
    import numpy as np

    from servosurf.diagnose import Model, build_case, get_effect, load_manifest
    from servosurf.diagnose._blocks import Context
    from servosurf.diagnose._diagnose import _make_blocks

    spec = {k: entry[k] for k in ("effects", "ool", "enr", "seed")}
    p_true, _ool, _truth, _enr = C.build(spec, C.CAMPAIGNS[entry["campaign"]])
    man = load_manifest(Path(root) / "cases" / entry["case"] / "manifest.toml")
    ctx = Context(build_case(man))
    p0 = Model()
    by_rec: dict[str, float] = {}
    for b in _make_blocks(man, ctx, p0):
        d = b.residual(p0) - b.residual(p_true)
        by_rec[b.recording] = by_rec.get(b.recording, 0.0) + float(np.sum(d * d))
    eff = get_effect(entry["effects"][0])
    return {
        "case": entry["case"],
        "effect": entry["effects"][0],
        "enr": entry["enr"],
        "q": eff.n_params(),
        "snr": math.sqrt(sum(by_rec.values())),
        "by_recording": by_rec,
    }


def np_bound(snr: float, alpha: float, k: float = 1.0) -> float:
    """Neyman-Pearson detection probability of a known signal of ``snr`` at
    false-alarm rate ``alpha`` with ``k`` times the data (SNR x sqrt(k))."""
    from scipy.stats import norm

    return float(norm.cdf(snr * math.sqrt(k) - norm.ppf(1.0 - alpha)))


def composite(snr: float, q: int, alpha: float, m: int, k: float = 1.0) -> float:
    """Detection probability of a ``q``-parameter likelihood-ratio test at the
    Bonferroni threshold ``alpha / m`` with ``k`` times the data."""
    from scipy.stats import chi2, ncx2

    thr = chi2.isf(alpha / m, q)
    return float(ncx2.sf(thr, q, snr * snr * k))


def more_data_needed(rows: list[dict], alpha: float, m: int, target: float) -> float:
    """Smallest factor ``k`` of recorded data at which the mean composite
    estimate reaches ``target`` (inf when it does not by 1e4)."""
    from scipy.optimize import brentq

    def gap(logk):
        k = math.exp(logk)
        return sum(composite(r["snr"], r["q"], alpha, m, k) for r in rows) / len(
            rows) - target

    if gap(0.0) >= 0:
        return 1.0
    if gap(math.log(1e4)) < 0:
        return math.inf
    return math.exp(brentq(gap, 0.0, math.log(1e4), xtol=1e-3))


def summarise(rows: list[dict], alpha: float, target: float, results: Path,
              m: int) -> dict:
    """Bound per ENR and per effect, with the observed top-1 when results exist."""
    out: dict = {"alpha": alpha, "target": target, "configurations": m,
                 "by_enr": {}, "by_effect": {}}
    for enr in sorted({r["enr"] for r in rows}):
        rs = [r for r in rows if r["enr"] == enr]
        snrs = [r["snr"] for r in rs]
        d = {
            "n": len(rs),
            "median_snr": float(sorted(snrs)[len(snrs) // 2]),
            "cases_snr_below_3": sum(1 for s in snrs if s < 3.0),
            "bound_top1": sum(np_bound(s, alpha) for s in snrs) / len(snrs),
            "composite_top1": sum(composite(r["snr"], r["q"], alpha, m) for r in rs)
            / len(rs),
            "data_factor_for_target": more_data_needed(rs, alpha, m, target),
        }
        obs = [_top1(results, r) for r in rs]
        obs = [o for o in obs if o is not None]
        if obs:
            d["observed_top1"] = sum(obs) / len(obs)
        out["by_enr"][str(enr)] = d
        for eff in sorted({r["effect"] for r in rs}):
            re_ = [r for r in rs if r["effect"] == eff]
            e = out["by_effect"].setdefault(eff, {})
            ob = [o for o in (_top1(results, r) for r in re_) if o is not None]
            e[str(enr)] = {
                "snr": [round(r["snr"], 2) for r in re_],
                "bound_top1": sum(np_bound(r["snr"], alpha) for r in re_) / len(re_),
                "composite_top1": sum(composite(r["snr"], r["q"], alpha, m)
                                      for r in re_) / len(re_),
                "observed_top1": sum(ob) / len(ob) if ob else None,
            }
    return out


def _top1(results: Path, row: dict):
    f = results / f"{row['case']}.json"
    if not f.exists():
        return None
    r = json.loads(f.read_text())
    if "error" in r:
        return 0
    ex = sorted(r["explanations"], key=lambda e: -e["delta_bic"])
    ok = r["verdict"] in ("explained", "partly-explained")
    return int(ok and bool(ex) and ex[0]["effect"] == row["effect"])


def table(s: dict) -> str:
    """Markdown tables of :func:`summarise`."""
    lines = [
        f"Neyman-Pearson bound at a false-alarm rate of {s['alpha']:.0%} (known "
        "effect and parameters):",
        "",
        "| ENR | n | median oracle SNR | cases SNR < 3 | NP bound | composite "
        f"estimate | observed top-1 | data for a {s['target']:.0%} estimate |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for enr, d in s["by_enr"].items():
        ob = d.get("observed_top1")
        k = d["data_factor_for_target"]
        lines.append(
            f"| {enr} | {d['n']} | {d['median_snr']:.2f} | {d['cases_snr_below_3']} "
            f"| {d['bound_top1']:.0%} | {d['composite_top1']:.0%} | "
            f"{'' if ob is None else f'{ob:.0%}'} | "
            f"{f'x{k:.1f}' if math.isfinite(k) else '> x1e4'} |"
        )
    enrs = list(s["by_enr"])
    lines += [
        "",
        "| effect | "
        + " | ".join(f"SNR @ {e} | NP | composite | observed" for e in enrs) + " |",
        "|---|" + "---|---|---|---|" * len(enrs),
    ]
    for eff, by in s["by_effect"].items():
        cells = []
        for e in enrs:
            d = by.get(e)
            if d is None:
                cells += ["", "", "", ""]
                continue
            ob = d["observed_top1"]
            cells += [
                f"{min(d['snr']):.1f}-{max(d['snr']):.1f}",
                f"{d['bound_top1']:.0%}",
                f"{d['composite_top1']:.0%}",
                "" if ob is None else f"{ob:.0%}",
            ]
        lines.append(f"| {eff} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("out", help="suite folder written with run.py --keep")
    ap.add_argument("--enr", default="0.03,0.1,0.3",
                    help="comma-separated ENR levels (1) to bound")
    ap.add_argument("--alpha", type=float, default=0.02,
                    help="false-alarm rate (1) of the bound (the suite's target)")
    ap.add_argument("--target", type=float, default=0.60,
                    help="top-1 target (1) for the data-factor column")
    ap.add_argument("--configurations", type=int, default=180,
                    help="configurations screened (1), the Bonferroni count of the "
                    "composite estimate")
    ap.add_argument("--jobs", type=int, default=2, help="worker processes")
    ap.add_argument("--json", action="store_true", help="print JSON instead")
    a = ap.parse_args(argv)
    out = Path(a.out)
    if not (out / "cases").is_dir():
        print(f"error: {out}/cases does not exist (run run.py with --keep)",
              file=sys.stderr)
        return 1
    try:
        enrs = {float(x) for x in a.enr.split(",")}
    except ValueError:
        print(f"error: --enr {a.enr!r} is not a list of numbers", file=sys.stderr)
        return 1
    if not 0.0 < a.alpha < 1.0:
        print(f"error: --alpha {a.alpha} must be in (0, 1)", file=sys.stderr)
        return 1
    from generate import unseal

    key = unseal(out)
    todo = [
        (e, str(out))
        for e in key["cases"]
        if len(e["effects"]) == 1 and not e.get("ool") and e["enr"] in enrs
        and "generation_error" not in e
        and (out / "cases" / e["case"]).is_dir()
    ]
    # oracle SNRs of an earlier run are reused (they depend on the case only)
    rows = []
    if (out / "bound.json").exists():
        old = {r["case"]: r for r in json.loads((out / "bound.json").read_text())
               .get("cases", []) if "q" in r}
        rows = [old[e["case"]] for e, _ in todo if e["case"] in old]
        todo = [(e, r) for e, r in todo if e["case"] not in old]
    if a.jobs > 1:
        import multiprocessing as mp

        with mp.get_context("spawn").Pool(a.jobs) as pool:
            for i, r in enumerate(pool.imap_unordered(oracle, todo)):
                rows.append(r)
                print(f"[{i + 1}/{len(todo)}] {r['case']} {r['effect']} "
                      f"ENR {r['enr']}: SNR {r['snr']:.2f}", file=sys.stderr,
                      flush=True)
    else:
        for i, w in enumerate(todo):
            rows.append(oracle(w))
            print(f"[{i + 1}/{len(todo)}]", file=sys.stderr, flush=True)
    s = summarise(rows, a.alpha, a.target, out / "results", a.configurations)
    s["cases"] = sorted(rows, key=lambda r: r["case"])
    (out / "bound.json").write_text(json.dumps(s, indent=1))
    tab = table(s)
    (out / "bound.md").write_text(tab + "\n")
    print(json.dumps({k: v for k, v in s.items() if k != "cases"}, indent=1)
          if a.json else tab)
    return 0


if __name__ == "__main__":
    sys.exit(main())
