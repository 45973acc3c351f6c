"""``servosurf paper``: every seed-paper number: a target, a prediction or a check."""

from __future__ import annotations

import argparse


def add_parser(sub) -> argparse.ArgumentParser:
    p = sub.add_parser(
        "paper",
        help="table of seed-paper numbers: targets, predictions, checks",
        description="Compute every number of the seed paper that servosurf "
        "compares with: quantity, paper value, servosurf value, unit, tolerance, "
        "within, and its role (target: used by the calibration; prediction: not "
        "used; check: closed form or consistency). Also the cross-predictions of "
        "every disturbance calibration, the calibration's re-run against the "
        "shipped constants, and multi-seed surface figures. Bandwidths are "
        "open-loop crossovers (Hz).",
    )
    p.add_argument("--json", action="store_true", help="print the table as JSON")
    p.add_argument("--out", metavar="DIR", help="also write paper.json to DIR")
    p.add_argument("--machine", metavar="FILE", help="machine TOML or built-in name")
    p.add_argument(
        "--only",
        metavar="GROUP",
        action="append",
        help="row group(s) to compute (default all)",
    )
    p.add_argument(
        "--seeds",
        metavar="N",
        type=int,
        default=24,
        help="vibration realisations per lenslet study (default 24; the peak rows "
        "need at least 20 to be stable)",
    )
    return p


def run(args) -> int:
    from .._progress import stage
    from ..errors import ConfigError
    from ..report import GROUPS, paper_table
    from ..servo import load_machine
    from ._common import output_folder, print_json, write_json

    if args.only:
        bad = [g for g in args.only if g not in GROUPS]
        if bad:
            raise ConfigError(
                f"--only {bad[0]!r}: unknown group; have {', '.join(GROUPS)}"
            )
    if args.seeds < 1:
        raise ConfigError(f"--seeds must be a positive integer, got {args.seeds}")
    machine = load_machine(args.machine)
    table = paper_table(
        tuple(args.only) if args.only else None,
        machine=machine,
        progress=lambda n: stage(f"paper rows: {n}"),
        seeds=args.seeds,
    )
    if args.out:
        write_json(output_folder(args.out) / "paper.json", table)
    if args.json:
        print_json(table)
    else:
        _print_text(table)
    return 0


def _fmt(v) -> str:
    if isinstance(v, bool) or v is None:
        return str(v)
    if isinstance(v, float | int):
        return f"{v:.4g}"
    if isinstance(v, list):
        return "..".join(_fmt(x) for x in v)
    return str(v)


def _print_text(table: dict) -> None:
    rows = table["rows"]
    if rows:
        w = max(len(r["quantity"]) for r in rows)
        for r in rows:
            mark = "ok  " if r["within"] else "MISS"
            print(
                f"{mark} {r['role']:<10} {r['quantity']:<{w}}  paper "
                f"{_fmt(r['paper']):<12} servosurf {_fmt(r['servosurf']):<11} "
                f"{r['unit']:<4} tol {r['tolerance']}"
            )
            if r.get("note"):
                print(f"     why: {r['note']}")
    for r in table.get("reported", []):
        print(
            f"rep  {r['role']:<10} {r['quantity']}: paper {_fmt(r['paper'])} "
            f"servosurf {_fmt(r['servosurf'])} {r['unit']} ({r['comment']})"
        )
    cp = table.get("cross_predictions")
    if cp:
        print("cross-predictions (violated figures per disturbance calibration):")
        for s in cp["sets"]:
            print(
                f"  {s['disturbances']}{' (default)' if s['default'] else ''}: "
                f"{len(s['violated'])} violated, {len(s['violated_measured'])} of "
                f"them measured: {', '.join(s['violated']) or 'none'}"
            )
    cal = table.get("calibration")
    if cal:
        print(
            f"calibration re-run: {len(cal['constants'])} constants, largest "
            f"relative difference {cal['largest_rel_diff']:.1e} "
            f"({'within' if cal['all_within'] else 'OUTSIDE'} {cal['rtol']:g})"
        )
    for n in table["notes"]:
        print(f"note: {n}")
