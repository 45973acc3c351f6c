"""The null test on the whole grid: simulate -> map file -> diagnose.

    python benchmarks/null_roundtrip.py [--seeds 3] [--out results/null]

For every shipped toolpath the diagnosis models (lenslet_5um, lenslet_10um,
flat_facing), with the interferometer model (cp300-20x) and without it, and for
``--seeds`` seeds: ``servosurf simulate`` writes the map and its manifest,
``servosurf diagnose`` reads them back. Prints one row per run (verdict, located
mismatches, explanations, the seconds each step took) and the count of runs
that were not "consistent"; exit status 1 if any was not. The test suite runs
four of these cases (tests/diagnose/test_null_contract.py).
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import sys
import time
from pathlib import Path

from servosurf.cli import main as servosurf

TOOLPATHS = ("lenslet_5um", "lenslet_10um", "flat_facing")
INSTRUMENTS = ("cp300-20x", "none")


def run_one(toolpath: str, instrument: str, seed: int, out: Path) -> dict:
    """One round trip; returns the verdict and timings."""
    sim, diag = out / f"{toolpath}-{instrument}-{seed}", out / (
        f"{toolpath}-{instrument}-{seed}-diagnosis")
    t0 = time.perf_counter()
    rc = servosurf(["-q", "simulate", toolpath, "--instrument", instrument,
                    "--seed", str(seed), "--no-render", "--out", str(sim), "--force"])
    t1 = time.perf_counter()
    if rc != 0:
        return {"verdict": f"simulate failed ({rc})", "t_sim_s": t1 - t0}
    buf = io.StringIO()
    with contextlib.redirect_stdout(buf):
        rc = servosurf(["-q", "diagnose", str(sim / "manifest.toml"), "--out",
                        str(diag), "--json"])
    t2 = time.perf_counter()
    if rc != 0:
        return {"verdict": f"diagnose failed ({rc})", "t_sim_s": t1 - t0}
    d = json.loads(buf.getvalue())
    return {"verdict": d["verdict"], "mismatches": len(d["mismatches"]),
            "explanations": [e.get("effect", "?") for e in d["explanations"]],
            "t_sim_s": t1 - t0, "t_diagnose_s": t2 - t1}


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--seeds", type=int, default=3, help="seeds per case (default 3)")
    p.add_argument("--out", type=Path, default=Path("results") / "null_roundtrip",
                   help="folder for the runs (default results/null_roundtrip)")
    args = p.parse_args(argv)
    if args.seeds < 1:
        print("null_roundtrip: error: --seeds must be >= 1", file=sys.stderr)
        return 1
    args.out.mkdir(parents=True, exist_ok=True)
    bad = 0
    print(f"{'toolpath':14s} {'instrument':10s} seed  verdict          mismatches "
          "sim [s]  diagnose [s]  explanations")
    for tp in TOOLPATHS:
        for inst in INSTRUMENTS:
            for seed in range(args.seeds):
                r = run_one(tp, inst, seed, args.out)
                bad += r["verdict"] != "consistent"
                print(f"{tp:14s} {inst:10s} {seed:4d}  {r['verdict']:16s} "
                      f"{r.get('mismatches', '-')!s:10s} {r['t_sim_s']:7.1f}  "
                      f"{r.get('t_diagnose_s', float('nan')):12.1f}  "
                      f"{', '.join(r.get('explanations', [])) or '-'}", flush=True)
    n = len(TOOLPATHS) * len(INSTRUMENTS) * args.seeds
    print(f"not consistent: {bad} of {n}")
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
