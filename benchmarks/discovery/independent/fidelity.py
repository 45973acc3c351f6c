"""Derive the diagnosis's model-fidelity floor from an independent suite's nulls.

Usage::

    python benchmarks/discovery/independent/fidelity.py DIR [DIR ...] [--json]

``DIR`` is a suite folder of ``generate.py`` diagnosed by ``run.py`` with the floor
switched off (``servosurf.diagnose._select.FIDELITY_ENR = 0``), so that every
term the diagnosis would name is in the results. This opens the key: run it after
the blind diagnosis, and use a suite seed you will not score the diagnosis on.

For every physics term the diagnosis names on a null case (an explanation or a
tentative term; there is no effect in the data, so each one absorbed a
difference between the two implementations or a noise misspecification), its
``signature.signature_enr``: the RMS of the term's whitened change over the
noise RMS in the recording where it is largest. The floor is the largest of
them rounded up to the next 0.005 (:func:`floor_from`). A term is then named
only when its signature is larger than every model-error term seen on nulls.

The script also prints what the floor costs: the signature of the correct top-1
term of every catalogue case (the share of them below the floor would be lost).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
if str(HERE.parent) not in sys.path:
    sys.path.insert(0, str(HERE.parent))

#: Terms of the noise model, not physics (a noise level is no mechanism).
NOISE_MODEL = {"sensor-noise-shape"}
#: Resolution the floor is rounded up to (dimensionless ENR).
STEP = 0.005


def floor_from(null_enrs: list[float]) -> float:
    """The floor: the largest null signature rounded up to the next ``STEP``
    (0 when no null named anything)."""
    if not null_enrs:
        return 0.0
    return math.ceil(max(null_enrs) / STEP - 1e-9) * STEP


def _terms(res: dict) -> list[dict]:
    return [e for e in list(res.get("explanations", [])) + list(res.get("tentative", []))
            if e.get("effect") not in NOISE_MODEL and "signature" in e]


def _diagnosed(dirs: list[Path]):
    """``(suite, key entry, result)`` of every case with a diagnosis."""
    from independent.generate import unseal

    for d in dirs:
        for k in unseal(d)["cases"]:
            f = d / "results" / f"{k.get('case')}.json"
            if "generation_error" in k or not f.exists():
                continue
            res = json.loads(f.read_text())
            if "error" not in res:
                yield d, k, res


def collect(dirs: list[Path]) -> dict:
    """Null and catalogue signatures of every suite in ``dirs``."""
    nulls, hits = [], []
    for d, k, res in _diagnosed(dirs):
        terms = _terms(res)
        if k["klass"] == "null":
            for e in terms:
                nulls.append({"suite": d.name, "case": k["case"], "null": k["effect"],
                              "effect": e["effect"],
                              "signature_enr": e["signature"]["signature_enr"],
                              "recording": e["signature"]["recording"]})
        elif k["klass"] == "catalogue" and k["enr_target"] >= 0.1 and terms:
            top = max(terms, key=lambda e: e.get("delta_bic") or -math.inf)
            if top["effect"] in k["expected"]:
                hits.append({"suite": d.name, "case": k["case"],
                             "effect": k["effect"], "enr": k["enr_target"],
                             "named": top["effect"],
                             "signature_enr": top["signature"]["signature_enr"],
                             "recording": top["signature"]["recording"]})
    fl = floor_from([r["signature_enr"] for r in nulls])
    lost = [h for h in hits if h["signature_enr"] < fl]
    return {"floor": fl, "nulls": nulls, "correct_top1": hits,
            "correct_top1_below_floor": len(lost)}


def what_if(dirs: list[Path], floors) -> list[dict]:
    """Top-1 and null false alarms had the floor been each of ``floors``,
    approximated without a refit: the terms below it are dropped from the
    results of a diagnosis run without the floor (a null whose every named
    term falls is consistent unless its verdict was ``unexplained``)."""
    rows = [(k, res) for _d, k, res in _diagnosed(dirs)]
    out = []
    for fl in floors:
        top = cat = fa = nul = 0
        for k, res in rows:
            left = [e for e in _terms(res) if e["signature"]["signature_enr"] >= fl]
            if k["klass"] == "null":
                nul += 1
                if left or res["verdict"] == "unexplained":
                    fa += 1
            elif k["klass"] == "catalogue" and k["enr_target"] >= 0.1:
                cat += 1
                if left and res["verdict"] in ("explained", "partly-explained"):
                    best = max(left, key=lambda e: e.get("delta_bic") or -math.inf)
                    top += best["effect"] in k["expected"]
        out.append({"floor": fl, "top1": top, "catalogue": cat, "false_alarms": fa,
                    "nulls": nul})
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("dirs", type=Path, nargs="+", help="diagnosed suite folders")
    ap.add_argument("--json", action="store_true", help="print the result as JSON")
    a = ap.parse_args(argv)
    for d in a.dirs:
        if not (d / "results").is_dir():
            print(f"error: {d}: no results/ folder (run run.py first)", file=sys.stderr)
            return 1
    out = collect(a.dirs)
    if a.json:
        print(json.dumps(out, indent=1))
        return 0
    print("terms named on nulls (signature ENR, recording):")
    for r in sorted(out["nulls"], key=lambda r: -r["signature_enr"]):
        print(f"  {r['case']} {r['null']:<18} {r['effect']:<32} "
              f"{r['signature_enr']:.4f}  {r['recording']}")
    print("correct top-1 terms at ENR >= 0.1 (signature ENR):")
    for r in sorted(out["correct_top1"], key=lambda r: r["signature_enr"]):
        print(f"  {r['case']} {r['effect']:<22} ENR {r['enr']:<4} {r['named']:<32} "
              f"{r['signature_enr']:.4f}  {r['recording']}")
    print("had the floor been (no refit; dropped terms only):")
    for r in what_if(a.dirs, sorted({0.0, 0.03, 0.045, 0.06, 0.08, out["floor"]})):
        print(f"  {r['floor']:<6g} top-1 {r['top1']}/{r['catalogue']}, false alarms "
              f"{r['false_alarms']}/{r['nulls']}")
    print(f"model-fidelity floor: {out['floor']:g} (largest null signature rounded up "
          f"to {STEP}); correct top-1 terms below it: "
          f"{out['correct_top1_below_floor']} of {len(out['correct_top1'])}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
