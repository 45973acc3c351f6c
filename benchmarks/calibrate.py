"""Re-derive every calibrated number of the built-in machine and workpiece.

Usage::

    python benchmarks/calibrate.py                # full run: structure, shape search,
                                                  # levels, thrust pressure; compare
    python benchmarks/calibrate.py --reduced      # shapes from the shipped machine
    python benchmarks/calibrate.py --write        # full run, then write the files
    python benchmarks/calibrate.py --json         # JSON on stdout

The full run searches the disturbance shapes (``SHAPE_GRID``) on the calibrated
structure; ``--reduced`` takes the shapes (the search's discrete choice) from the
shipped machine file and solves every continuous number from scratch. Both print
every calibrated number beside the shipped one and their relative difference, and
exit 1 when one differs by more than ``COMPARE_RTOL``. ``--write`` writes
``src/servosurf/data/machines/seed-prototype.toml`` and ``workpieces/nip.toml`` (and
says when ``servosurf.cutting.Material``'s default thrust pressure must follow).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--reduced", action="store_true",
                   help="take the disturbance shapes from the shipped machine")
    p.add_argument("--write", action="store_true",
                   help="write the machine and workpiece files")
    p.add_argument("--json", action="store_true", help="JSON on stdout")
    args = p.parse_args(argv)

    from servosurf.calibration import (
        COMPARE_RTOL,
        calibrate,
        calibrated_constants,
        compare_constants,
    )
    from servosurf.cutting import Material, load_workpiece
    from servosurf.servo import load_machine

    t0 = time.perf_counter()
    shipped = load_machine()

    def log(msg: str) -> None:
        print(f"[{time.perf_counter() - t0:7.1f} s] {msg}", file=sys.stderr, flush=True)

    cal = calibrate(reduced_from=shipped if args.reduced else None, log=log)
    wp_path = ROOT / "workpieces" / "nip.toml"
    kt_shipped = load_workpiece(wp_path).material.specific_thrust_pressure
    rows = compare_constants(
        cal.constants(), calibrated_constants(shipped, kt_shipped)
    )
    ok = all(r["within"] for r in rows)
    out = {
        "reduced": cal.reduced,
        "seconds": time.perf_counter() - t0,
        "default_disturbances": cal.default,
        "rtol": COMPARE_RTOL,
        "all_within": ok,
        "constants": rows,
        "log": cal.log,
    }
    if args.write:
        mpath = ROOT / "src" / "servosurf" / "data" / "machines" / "seed-prototype.toml"
        mpath.write_text(cal.machine_toml())
        wp_path.write_text(cal.workpiece_toml())
        out["written"] = [str(mpath), str(wp_path)]
        if Material().specific_thrust_pressure != cal.thrust_pressure:
            print(
                "servosurf.cutting.Material's default specific_thrust_pressure must "
                f"become {cal.thrust_pressure!r} (src/servosurf/cutting/_force.py)",
                file=sys.stderr,
            )
    if args.json:
        print(json.dumps(out, indent=2, default=str))
    else:
        print(f"calibration ({'reduced' if cal.reduced else 'full'}) in "
              f"{out['seconds']:.0f} s; default disturbances {cal.default!r}")
        w = max(len(r["key"]) for r in rows)
        for r in rows:
            d = "-" if r["rel_diff"] is None else f"{r['rel_diff']:.1e}"
            print(f"{'ok  ' if r['within'] else 'DIFF'} {r['key']:<{w}}  "
                  f"shipped {r['shipped']!s:<24} re-run {r['rerun']!s:<24} rel {d}")
    return 0 if (ok or args.write) else 1


if __name__ == "__main__":
    raise SystemExit(main())
