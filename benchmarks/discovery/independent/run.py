"""Diagnose every case of an independent suite blind, then score it.

Usage::

    python benchmarks/discovery/independent/run.py DIR [--jobs 1] [--timeout 3600]
    python benchmarks/discovery/independent/run.py DIR --generate --seed N \\
        --n-cases K            # generate first (generate.py), then diagnose

Each ``DIR/cases/case_NNNN/manifest.toml`` goes through ``servosurf diagnose
--json`` in a subprocess (``python -m servosurf``); the JSON summary plus the
runtime is written to ``DIR/results/case_NNNN.json`` (a case whose result exists
is skipped, so an interrupted run resumes). A runner claims a case with
``DIR/results/case_NNNN.claim`` before diagnosing it, so several runners (one
``--reverse``) can share a suite; ``--reclaim`` ignores the claims a killed
runner left. The key is opened by the scorer only after every result is written.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

HERE = Path(__file__).resolve().parent
if str(HERE.parent) not in sys.path:
    sys.path.insert(0, str(HERE.parent))


def _claim(results: Path, name: str, reclaim: bool) -> bool:
    path = results / f"{name}.claim"
    if reclaim and path.exists():
        path.unlink()
    try:
        fd = os.open(path, os.O_CREAT | os.O_EXCL | os.O_WRONLY)
    except FileExistsError:
        return False
    os.write(fd, str(os.getpid()).encode())
    os.close(fd)
    return True


def diagnose_case(folder: Path, results: Path, timeout: float, *,
                  reclaim: bool = False) -> dict | None:
    """Run ``servosurf diagnose --json`` on one case folder; write its result.

    Returns None when another runner has claimed the case.
    """
    out = results / f"{folder.name}.json"
    if out.exists():
        return json.loads(out.read_text())
    if not _claim(results, folder.name, reclaim):
        return None
    t0 = time.perf_counter()
    cmd = [sys.executable, "-m", "servosurf", "diagnose", "--json", "--out",
           str(results / "out" / folder.name), str(folder / "manifest.toml")]
    try:
        p = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout)
        if p.returncode != 0:
            res = {"error": (p.stderr.strip().splitlines() or ["?"])[-1],
                   "returncode": p.returncode}
        else:
            res = json.loads(p.stdout)
    except subprocess.TimeoutExpired:
        res = {"error": f"timeout after {timeout:g} s"}
    except json.JSONDecodeError as exc:
        res = {"error": f"unreadable JSON: {exc}"}
    res["runtime_s"] = time.perf_counter() - t0
    out.write_text(json.dumps(res))
    return res


def run(out: Path, *, jobs: int = 1, timeout: float = 3600.0, reverse: bool = False,
        reclaim: bool = False, progress=print) -> None:
    """Diagnose every case of ``out/cases`` (``jobs`` at a time)."""
    out = Path(out)
    results = out / "results"
    results.mkdir(parents=True, exist_ok=True)
    folders = sorted((p for p in (out / "cases").iterdir()
                      if (p / "manifest.toml").is_file()), reverse=reverse)

    def one(f):
        r = diagnose_case(f, results, timeout, reclaim=reclaim)
        if r is None:
            progress(f"{f.name}: claimed by another runner")
            return r
        progress(f"{f.name}: {r.get('verdict', r.get('error'))} "
                 f"({r.get('runtime_s', 0):.0f} s)")
        return r

    with ThreadPoolExecutor(max(1, jobs)) as pool:
        list(pool.map(one, folders))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("out", type=Path, help="suite directory")
    ap.add_argument("--jobs", type=int, default=1, help="diagnoses at a time")
    ap.add_argument("--timeout", type=float, default=3600.0,
                    help="seconds per diagnosis")
    ap.add_argument("--generate", action="store_true", help="generate first")
    ap.add_argument("--seed", type=int, default=0, help="suite seed (--generate)")
    ap.add_argument("--n-cases", type=int, default=36, help="cases (--generate)")
    ap.add_argument("--chip-force", choices=("continuous", "held"),
                    default="continuous", help="chip-force model (--generate)")
    ap.add_argument("--json", action="store_true", help="print the score as JSON")
    ap.add_argument("--reverse", action="store_true",
                    help="take the cases in reverse order (a second runner)")
    ap.add_argument("--reclaim", action="store_true",
                    help="ignore claims left by a killed runner")
    ap.add_argument("--no-score", action="store_true", help="do not score at the end")
    a = ap.parse_args(argv)
    if a.generate:
        from independent.generate import generate

        generate(a.out, seed=a.seed, n_cases=a.n_cases, jobs=1,
                 chip_force=a.chip_force)
    run(a.out, jobs=a.jobs, timeout=a.timeout, reverse=a.reverse, reclaim=a.reclaim)
    if a.no_score:
        return 0
    from independent.score import main as score_main

    return score_main([str(a.out)] + (["--json"] if a.json else []))


if __name__ == "__main__":
    sys.exit(main())
