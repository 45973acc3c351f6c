"""Is there one disturbance calibration for sections 3.3 and 5.2 of the seed paper?

Usage::

    python benchmarks/disturbance_search.py            # the table on stdout
    python benchmarks/disturbance_search.py --json     # JSON
    python benchmarks/disturbance_search.py --zeta1 0.1 0.15 0.2   # also the tool
        # mode's damping: structure re-solved, the default shape's levels re-fitted

On the shipped machine's structure and tuning rule, every shape of
``servosurf.calibration.SHAPE_GRID`` gets its three levels fitted to each subset of
the paper's figures (``MAIN_SUBSETS``, and leave-one-out subsets on the best shapes),
for both readings of section 3.3's 468 Hz (crossover; closed-loop -3 dB). Every
candidate is then checked against every figure. Printed: the best candidate per
subset and reading with the figures it violates; whether any candidate meets all
quantitative figures of both sections with the sensor noise inside the CPL190 band;
what dropping each figure buys; the set with the fewest violated measured figures
(the calibration's default).
"""

from __future__ import annotations

import argparse
import json
import sys
import time


def _fmt(key: str, v: float) -> str:
    from servosurf.calibration import FIGURES

    u = FIGURES[key].unit
    if u == "m":
        return f"{v * 1e9:.3f} nm"
    if u == "Hz":
        return f"{v:.0f} Hz"
    return f"{v:.3g}"


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--json", action="store_true")
    p.add_argument("--zeta1", type=float, nargs="*", default=[],
                   help="tool-mode damping ratios for the sensitivity table")
    args = p.parse_args(argv)

    from servosurf.calibration import (
        DISTURBANCE_FIGURES,
        FIGURES,
        READINGS,
        search_disturbances,
        within,
    )
    from servosurf.calibration._disturbances import _QUANT, MAIN_SUBSETS
    from servosurf.servo import load_machine

    t0 = time.perf_counter()
    machine = load_machine()
    search = search_disturbances(machine)
    out: dict = {"seconds": None, "candidates": len(search.candidates)}
    best_rows = []
    for reading in READINGS:
        for subset in MAIN_SUBSETS:
            c = search.section_set(subset, reading)
            best_rows.append(
                {
                    "reading": reading,
                    "subset": subset,
                    "shape": c.shape.as_dict(),
                    "levels": c.levels,
                    "violated": c.violated(),
                    "violated_quantitative": c.violated(_QUANT),
                    "figures": {k: c.figures[k] for k in DISTURBANCE_FIGURES},
                }
            )
    joint = search.joint()
    best = search.best()
    out.update(
        best_per_subset=best_rows,
        joint_candidates=len(joint),
        conflicts={r: search.conflicts(r) for r in READINGS},
        default={
            "subset": best.subset,
            "reading": best.reading,
            "shape": best.shape.as_dict(),
            "levels": best.levels,
            "violated": best.violated(),
            "score": list(best.score()[:4]),
        },
    )
    # how far apart the contradicting figures are, on the best candidates
    gaps = []
    for reading in READINGS:
        for a, b in (("real_rms_468_s52", "real_rms_0175_s33"),
                     ("following_rms_468", "real_rms_0075_s33")):
            both = [c for c in search.candidates if c.reading == reading]
            ok = [
                c for c in both
                if within(FIGURES[a], c.figures[a])
                and within(FIGURES[b], c.figures[b])
            ]
            gaps.append({"reading": reading, "figures": [a, b],
                         "candidates_meeting_both": len(ok)})
    out["pairs"] = gaps
    if args.zeta1:
        out["zeta1_sensitivity"] = _zeta1(machine, args.zeta1)
    out["seconds"] = time.perf_counter() - t0
    if args.json:
        print(json.dumps(out, indent=2, default=str))
        return 0
    print(f"disturbance search: {out['candidates']} candidates in "
          f"{out['seconds']:.0f} s (machine {machine.name})")
    for r in best_rows:
        s = r["shape"]
        print(
            f"\n[{r['reading']:>9}] fitted to {r['subset']}: sensor slope "
            f"{s['sensor_slope']:+g} floor {s['sensor_floor_ratio']:g}, current slope "
            f"{s['current_slope']:+g}, base slope {s['base_slope']:+g}; levels "
            + ", ".join(f"{v:.3g}" for v in r["levels"])
        )
        for k in DISTURBANCE_FIGURES:
            v = r["figures"][k]
            f = FIGURES[k]
            paper = f.value if isinstance(f.value, str) else _fmt(k, f.value) \
                if not isinstance(f.value, tuple) else "0.5..1 nm"
            mark = "  " if within(f, v) else "XX"
            print(f"   {mark} {k:<34} paper {paper:<12} model {_fmt(k, v)}")
    print(f"\ncandidates meeting every quantitative figure of 3.3 and 5.2 with the "
          f"CPL190-bounded sensor noise: {out['joint_candidates']}")
    for g in gaps:
        print(f"  [{g['reading']}] {g['figures'][0]} and {g['figures'][1]} both met by "
              f"{g['candidates_meeting_both']} candidates")
    for reading, rows in out["conflicts"].items():
        print(f"\nleave one figure out [{reading}] (fewest other quantitative figures "
              "violated):")
        for r in rows:
            print(f"   without {r['figure']:<24} -> {r['fewest_violated_without']} "
                  f"violated: {', '.join(r['violated']) or 'none'}")
    d = out["default"]
    print(f"\ndefault (fewest violated measured figures): fitted to {d['subset']} "
          f"[{d['reading']}], shape {d['shape']}, levels "
          + ", ".join(f"{v:.3g}" for v in d["levels"])
          + f"; violated: {', '.join(d['violated'])}")
    for z in out.get("zeta1_sensitivity", []):
        print(f"zeta1 {z['zeta1']:g}: zeta4 {z['zeta4']:.4g}; "
              + ", ".join(f"{k} {v:.3g}" for k, v in z["claims"].items()))
    return 0


def _zeta1(machine, values):
    """Claims of Figs 10 and 12 for other tool-mode damping ratios (the structure
    re-solved for its targets, the default set's levels re-fitted)."""
    import dataclasses

    from servosurf.calibration import (
        apply_structure,
        fit_levels,
        make_bank,
        shape_of,
        solve_structure,
        structure_of,
    )

    out = []
    shape, _ = shape_of(machine.disturbances)
    for z1 in values:
        p0 = dataclasses.replace(structure_of(machine), zeta1=z1)
        try:
            p = solve_structure(machine, p0, machine.disturbances)
        except Exception as exc:  # noqa: BLE001 - report and go on
            out.append({"zeta1": z1, "error": str(exc)})
            continue
        m = apply_structure(machine, p)
        ctx = make_bank(m)
        fit = fit_levels(ctx, shape, "section-5.2")
        out.append(
            {
                "zeta1": z1,
                "zeta4": p.zeta4,
                "claims": {
                    k: fit.figures[k]
                    for k in ("claim_mass_above_900", "claim_following_same_level",
                              "claim_following_lower_with_mass")
                },
                "violated": fit.violated(),
            }
        )
        print(f"zeta1 {z1}: done", file=sys.stderr)
    return out


if __name__ == "__main__":
    raise SystemExit(main())
