"""Blind discrepancy-discovery benchmark: generate, diagnose, then score.

Usage::

    python benchmarks/discovery/run.py            # full suite (about 250 cases)
    python benchmarks/discovery/run.py --quick    # 22 cases on the short campaign
    python benchmarks/discovery/run.py --json     # JSON summary on stdout
    python benchmarks/discovery/run.py --out DIR --jobs 2 --keep
    python benchmarks/discovery/run.py --nulls 40 --seed 7   # threshold calibration
    python benchmarks/discovery/run.py --misspecified 12 --seed 11  # noise-model nulls

Steps (each case is diagnosed from its manifest and recordings only):

1. :mod:`generate` writes the case folders and seals the key
   (``key.sealed`` + ``key.secret`` + ``key.sha256``);
2. every case is diagnosed in a pool of worker processes (``--jobs``, default 2)
   with :func:`servosurf.diagnose.diagnose`; each result goes to
   ``results/case_NNNN.json`` with its runtime;
3. only then :mod:`score` opens the key and writes ``table.md`` and
   ``score.json``.

Recordings are deleted after scoring unless ``--keep``.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))


def _diagnose_one(args) -> str:
    folder, out = args
    os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
    os.environ.setdefault("SERVOSURF_QUIET", "1")
    from servosurf.commands._common import write_json

    t0 = time.perf_counter()
    name = Path(folder).name
    try:
        from servosurf.diagnose import diagnose

        d = diagnose(Path(folder) / "manifest.toml")
        res = d.to_dict()
    except Exception as exc:  # noqa: BLE001 - a failed case is scored as an error
        res = {"error": f"{type(exc).__name__}: {exc}"}
    res["runtime_s"] = time.perf_counter() - t0
    write_json(Path(out) / "results" / f"{name}.json", res)
    return name


def diagnose_all(out: Path, jobs: int = 2, progress=True) -> None:
    """Diagnose every case folder of ``out/cases`` (blind: manifests only)."""
    import multiprocessing as mp

    folders = sorted((out / "cases").glob("case_*"))
    (out / "results").mkdir(exist_ok=True)
    work = [
        (str(f), str(out))
        for f in folders
        if not (out / "results" / f"{f.name}.json").exists()
    ]
    t0 = time.perf_counter()
    if jobs > 1:
        ctx = mp.get_context("spawn")
        with ctx.Pool(jobs, maxtasksperchild=20) as pool:
            for i, name in enumerate(pool.imap_unordered(_diagnose_one, work)):
                if progress:
                    print(
                        f"[{i + 1}/{len(work)}] {name} "
                        f"({time.perf_counter() - t0:.0f} s)",
                        file=sys.stderr,
                        flush=True,
                    )
    else:
        for i, w in enumerate(work):
            _diagnose_one(w)
            if progress:
                print(f"[{i + 1}/{len(work)}]", file=sys.stderr, flush=True)


def null_calibration(a) -> int:
    """Diagnose ``a.nulls`` fresh null cases; print their best candidate scores.

    A selection threshold read from these (for a stated false-alarm rate) is
    calibrated on data the blind suite never sees; the suite is then run with
    another seed to validate it.
    """
    import collections

    import generate

    out = Path(a.out or f"results/discovery-nulls-{a.seed}")
    out.mkdir(parents=True, exist_ok=True)
    if not (out / "key.sealed").exists():
        print(f"generating {a.nulls} null cases in {out} ...", file=sys.stderr)
        generate.generate_specs(
            out,
            [{"effects": [], "ool": None, "enr": 0.0}] * a.nulls,
            campaign="full",
            seed=a.seed,
            jobs=a.jobs,
        )
    diagnose_all(out, jobs=a.jobs)
    res = [json.loads(f.read_text()) for f in sorted((out / "results").glob("*.json"))]
    scores = sorted(r["ranking"][0]["score"] for r in res if r.get("ranking"))
    summary = {
        "cases": len(res),
        "verdicts": dict(collections.Counter(r.get("verdict", "error") for r in res)),
        "best_scores": scores,
        "max": scores[-1] if scores else None,
    }
    (out / "nulls.json").write_text(json.dumps(summary, indent=2))
    if not a.keep:
        shutil.rmtree(out / "cases", ignore_errors=True)
    print(json.dumps(summary, indent=2))
    return 0


#: Noise-model misspecification nulls (DISCOVERY.md section 6): factors on the
#: base, sensor and current noise PSDs, no effect. The right answer names no
#: physics: "consistent", or "unexplained" with the mismatch located.
MISSPECIFIED = {
    "base PSD x2": (2.0, 1.0, 1.0),
    "sensor noise x1.5": (1.0, 2.25, 1.0),
    "base PSD x1.2": (1.2, 1.0, 1.0),
    "sensor noise x1.1": (1.0, 1.21, 1.0),
}


#: Catalogue terms that model the noise itself.
NOISE_MODEL_TERMS = {"sensor-noise-shape"}


def misspecified_nulls(a) -> int:
    """Diagnose ``a.misspecified`` null cases whose noise PSDs differ from the
    machine's (cycling through :data:`MISSPECIFIED`); print the verdicts and
    every term named. A mechanism named is a wrong claim (there is none to find);
    the catalogue's noise-model term is counted apart."""
    import collections

    import generate

    out = Path(a.out or f"results/discovery-misspecified-{a.seed}")
    out.mkdir(parents=True, exist_ok=True)
    kinds = list(MISSPECIFIED)
    specs = [
        {"effects": [], "ool": None, "enr": 0.0,
         "noise_scale": MISSPECIFIED[kinds[i % len(kinds)]]}
        for i in range(a.misspecified)
    ]
    if not (out / "key.sealed").exists():
        print(f"generating {a.misspecified} misspecified-noise null cases in {out} ...",
              file=sys.stderr)
        generate.generate_specs(out, specs, campaign="full", seed=a.seed, jobs=a.jobs)
    diagnose_all(out, jobs=a.jobs)
    key = {k["case"]: k for k in generate.unseal(out)["cases"]}
    rows = []
    for f in sorted((out / "results").glob("case_*.json")):
        r = json.loads(f.read_text())
        k = key[f.stem]
        name = next(n for n, v in MISSPECIFIED.items()
                    if list(v) == list(k["noise_scale"]))
        rows.append({
            "case": f.stem,
            "noise": name,
            "enr": k["enr_achieved"].get("noise-scale"),
            "verdict": r.get("verdict", "error"),
            "physics": [e["effect"] for e in r.get("explanations", [])],
            "recalibration": [e.get("effect") for e in r.get("recalibration", [])],
        })
    # sensor-noise-shape is the catalogue's own noise-model term: naming it for a
    # misspecified sensor noise is the noise-model discrepancy, not a mechanism
    claims = [r for r in rows if set(r["physics"]) - NOISE_MODEL_TERMS]
    summary = {
        "cases": len(rows),
        "verdicts": dict(collections.Counter(r["verdict"] for r in rows)),
        "noise_model_term_named": sum(
            1 for r in rows if set(r["physics"]) & NOISE_MODEL_TERMS),
        "wrong_physics_claims": len(claims),
        "wrong_physics_claim_rate": len(claims) / len(rows) if rows else None,
        "by_kind": {
            n: dict(collections.Counter(
                ",".join(r["physics"]) or r["verdict"]
                for r in rows if r["noise"] == n))
            for n in MISSPECIFIED
        },
        "cases_detail": rows,
    }
    (out / "misspecified.json").write_text(json.dumps(summary, indent=2))
    if not a.keep:
        shutil.rmtree(out / "cases", ignore_errors=True)
    print(json.dumps(summary, indent=2))
    return 0


def realistic_nulls(a) -> int:
    """Diagnose ``a.realistic_nulls`` null cases of each realistic kind
    (:data:`generate.REALISTIC_NULLS`, test campaign); print the verdicts per kind.
    A false alarm is any verdict other than "consistent"."""
    import collections

    import generate

    out = Path(a.out or f"results/discovery-realistic-nulls-{a.seed}")
    out.mkdir(parents=True, exist_ok=True)
    if not (out / "key.sealed").exists():
        print(f"generating {a.realistic_nulls} x {len(generate.REALISTIC_NULLS)} "
              f"realistic null cases in {out} ...", file=sys.stderr)
        generate.generate_specs(out, generate.realistic_null_specs(a.realistic_nulls),
                                campaign="test", seed=a.seed, jobs=a.jobs)
    diagnose_all(out, jobs=a.jobs)
    key = {k["case"]: k for k in generate.unseal(out)["cases"]}
    rows = []
    for f in sorted((out / "results").glob("case_*.json")):
        r = json.loads(f.read_text())
        rows.append({"case": f.stem, "kind": key[f.stem].get("null"),
                     "verdict": r.get("verdict", "error"),
                     "physics": [e["effect"] for e in r.get("explanations", [])],
                     "recalibration": [e.get("parameters") for e in
                                       r.get("recalibration", [])]})
    table = {}
    for kind in generate.REALISTIC_NULLS:
        rs = [r for r in rows if r["kind"] == kind]
        fa = sum(1 for r in rs if r["verdict"] != "consistent")
        table[kind] = {"cases": len(rs), "false_alarms": fa,
                       "verdicts": dict(collections.Counter(r["verdict"] for r in rs))}
    summary = {"by_kind": table, "cases_detail": rows}
    (out / "realistic_nulls.json").write_text(json.dumps(summary, indent=2))
    if not a.keep:
        shutil.rmtree(out / "cases", ignore_errors=True)
    print(json.dumps(summary, indent=2))
    return 0


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="22 cases, short campaign")
    ap.add_argument("--json", action="store_true", help="print the JSON summary")
    ap.add_argument(
        "--out", default=None, help="work folder (default results/discovery[-quick])"
    )
    ap.add_argument("--jobs", type=int, default=2, help="worker processes")
    ap.add_argument("--seed", type=int, default=1, help="suite seed")
    ap.add_argument("--keep", action="store_true", help="keep the recordings")
    ap.add_argument("--limit", type=int, help="only the first N cases")
    ap.add_argument(
        "--nulls",
        type=int,
        metavar="N",
        help="calibration only: N null cases of the full campaign (use a --seed "
        "other than the suite's); prints the best candidate score of each",
    )
    ap.add_argument(
        "--misspecified",
        type=int,
        metavar="N",
        help="robustness only: N null cases whose noise PSDs differ from the "
        "machine's (base x2 or x1.2, sensor x1.5 or x1.1); prints the verdicts and "
        "every physics named",
    )
    ap.add_argument(
        "--realistic-nulls",
        type=int,
        metavar="K",
        help="false alarms only: K null cases of each realistic kind (nominal, "
        "low-band base content, noise factor) on the test campaign; prints the "
        "verdicts per kind",
    )
    a = ap.parse_args(argv)
    os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
    if a.realistic_nulls:
        return realistic_nulls(a)
    if a.nulls:
        return null_calibration(a)
    if a.misspecified:
        return misspecified_nulls(a)
    out = Path(a.out or ("results/discovery-quick" if a.quick else "results/discovery"))
    out.mkdir(parents=True, exist_ok=True)
    import generate
    import score

    t0 = time.perf_counter()
    if not (out / "key.sealed").exists():
        print(f"generating cases in {out} ...", file=sys.stderr, flush=True)
        generate.generate(out, quick=a.quick, seed=a.seed, jobs=a.jobs, limit=a.limit)
    t1 = time.perf_counter()
    print("diagnosing (blind) ...", file=sys.stderr, flush=True)
    diagnose_all(out, jobs=a.jobs)
    t2 = time.perf_counter()
    s = score.score(out)
    s["wall_time_s"] = {"generate": t1 - t0, "diagnose": t2 - t1}
    (out / "score.json").write_text(json.dumps(s, indent=2))
    tab = score.table(s)
    (out / "table.md").write_text(tab + "\n")
    if not a.keep:
        shutil.rmtree(out / "cases", ignore_errors=True)
    print(json.dumps(s, indent=2) if a.json else tab)
    return 0


if __name__ == "__main__":
    sys.exit(main())
