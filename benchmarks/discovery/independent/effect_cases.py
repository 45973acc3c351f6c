"""A few independent cases of named effects, diagnosed, in one table (not blind).

Usage::

    python benchmarks/discovery/independent/effect_cases.py DIR \\
        --effects dahl-hysteresis,lugre-friction --enr 0.3 --n 3 [--seed 0]

Generates ``n`` cases of every named effect of :mod:`effects` at the target ENR
(``DIR/cases/<effect>_<k>/``, key in ``DIR/key.json``, unsealed: a development
check of single effects, not the blind suite), diagnoses each with the
``servosurf`` that ``PYTHONPATH`` selects (``DIR/results``; an existing result is
kept, so a second run with ``--results other`` compares two versions) and prints
one row per case: effect, form, ENR, verdict, the physics named first and its
parameters.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
if str(HERE.parent) not in sys.path:
    sys.path.insert(0, str(HERE.parent))

from independent import generate as G  # noqa: E402
from independent import score as S  # noqa: E402
from independent.run import diagnose_case  # noqa: E402


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("out", type=Path, help="output directory")
    ap.add_argument("--effects", required=True,
                    help="comma-separated effect names of effects.ALL")
    ap.add_argument("--enr", type=float, default=0.3, help="target ENR")
    ap.add_argument("--n", type=int, default=3, help="cases per effect")
    ap.add_argument("--seed", type=int, default=0, help="draw seed")
    ap.add_argument("--results", default="results", help="results sub-directory")
    ap.add_argument("--timeout", type=float, default=1800.0, help="s per diagnosis")
    a = ap.parse_args(argv)
    names = [n for n in a.effects.split(",") if n]
    unknown = [n for n in names if n not in G.E.ALL]
    if unknown:
        print(f"effect_cases: unknown effect {unknown[0]!r}; allowed: "
              f"{', '.join(G.E.ALL)}", file=sys.stderr)
        return 1
    out = a.out
    (out / "cases").mkdir(parents=True, exist_ok=True)
    key_path = out / "key.json"
    key = json.loads(key_path.read_text()) if key_path.exists() else {}
    for name in names:
        for k in range(a.n):
            case = f"{name}_{k}"
            if case in key:
                continue
            folder = out / "cases" / case
            key[case] = G.make_case(1000 * k + 7, {"effect": name, "enr": a.enr},
                                    a.seed, folder)
            key_path.write_text(json.dumps(key, indent=1))
    results = out / a.results
    results.mkdir(parents=True, exist_ok=True)
    print("| case | form | ENR | verdict | first physics named | parameters |")
    print("|---|---|---|---|---|---|")
    for case, entry in key.items():
        if case.rsplit("_", 1)[0] not in names:
            continue
        if "generation_error" in entry:
            print(f"| {case} | | | {entry['generation_error']} | | |")
            continue
        res = diagnose_case(out / "cases" / case, results, a.timeout)
        c = S.classify(res)
        top = c["top"]
        named = top["effect"] if top else "-"
        pars = ", ".join(f"{k}={v:.3g}" for k, v in (top or {}).get(
            "parameters", {}).items() if isinstance(v, int | float))
        print(f"| {case} | {entry.get('form', '')} | {entry.get('enr', 0):.2f} | "
              f"{c['label']} | {named} | {pars} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
