"""``servosurf paper``: every seed-paper number the model reproduces, one row each."""

from __future__ import annotations

import argparse


def add_parser(sub) -> argparse.ArgumentParser:
    p = sub.add_parser(
        "paper",
        help="table of seed-paper numbers reproduced by the model",
        description="Compute every number of the seed paper that servosurf "
        "reproduces: quantity, paper value, servosurf value, unit, tolerance, "
        "within. Bandwidths are open-loop crossovers (Hz).",
    )
    p.add_argument("--json", action="store_true", help='print {"rows": [...]} as JSON')
    p.add_argument("--out", metavar="DIR", help="also write paper.json to DIR")
    p.add_argument("--machine", metavar="FILE", help="machine TOML or built-in name")
    p.add_argument(
        "--only",
        metavar="GROUP",
        action="append",
        help="row group(s) to compute (default all)",
    )
    return p


def run(args) -> int:
    from .._progress import stage
    from ..report import GROUPS, paper_table
    from ..servo import load_machine
    from ._common import output_folder, print_json, write_json

    if args.only:
        bad = [g for g in args.only if g not in GROUPS]
        if bad:
            from ..errors import ConfigError

            raise ConfigError(
                f"--only {bad[0]!r}: unknown group; have {', '.join(GROUPS)}"
            )
    machine = load_machine(args.machine)
    table = paper_table(
        tuple(args.only) if args.only else None,
        machine=machine,
        progress=lambda n: stage(f"paper rows: {n}"),
    )
    if args.out:
        write_json(output_folder(args.out) / "paper.json", table)
    if args.json:
        print_json(table)
    else:
        w = max(len(r["quantity"]) for r in table["rows"])
        for r in table["rows"]:
            mark = "ok  " if r["within"] else "MISS"
            sv, pv = (
                f"{v:.4g}" if isinstance(v, float | int) else str(v)
                for v in (r["servosurf"], r["paper"])
            )
            print(
                f"{mark} {r['quantity']:<{w}}  paper {pv:<10} servosurf {sv:<10} "
                f"{r['unit']:<4} tol {r['tolerance']}"
            )
        for r in table.get("reported", []):
            print(
                f"rep  {r['quantity']:<{w}}  paper {r['paper']:<10.4g} servosurf "
                f"{r['servosurf']:<10.4g} {r['unit']:<4} ({r['comment']})"
            )
        for n in table["notes"]:
            print(f"note: {n}")
    return 0
