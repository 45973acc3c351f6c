"""``servosurf machines``: list built-in machines and document machine-file keys."""

from __future__ import annotations

import argparse


def add_parser(sub) -> argparse.ArgumentParser:
    p = sub.add_parser(
        "machines",
        help="list built-in machines; --describe documents keys",
        description="List built-in machine definitions (TOML). "
        "Pass one to other commands with --machine NAME or FILE.toml.",
    )
    p.add_argument(
        "--describe",
        action="store_true",
        help="print every machine-file key with its SI unit, the value in the "
        "machine (default: seed-prototype) and its provenance label (paper, "
        "assumed, derived, target:<figures>), as the file's [provenance] table "
        "states it",
    )
    p.add_argument(
        "--machine",
        metavar="FILE",
        help="machine TOML or built-in name for --describe (default: seed-prototype)",
    )
    p.add_argument("--show", metavar="NAME", help="print a built-in machine file")
    p.add_argument("--json", action="store_true", help="JSON output on stdout")
    return p


def run(args) -> int:
    from ..servo import builtin_machines, describe_machine, load_machine
    from ._common import print_json

    builtins = builtin_machines()
    if args.show:
        if args.show not in builtins:
            from ..errors import ConfigError

            raise ConfigError(
                f"no built-in machine {args.show!r}; have: {', '.join(builtins)}"
            )
        print(builtins[args.show].read_text(), end="")
        return 0
    if args.describe:
        machine = load_machine(args.machine) if args.machine else load_machine()
        rows = describe_machine(machine)
        if args.json:
            print_json({"machine": machine.name, "keys": rows})
        else:
            for r in rows:
                v = r["value"]
                vs = "" if v is None or v == "" else f" = {v!r}"
                print(
                    f"{r['key']:<52} [{r['unit'] or '-'}]{vs}  {r['doc']}"
                    + (f"  ({r['provenance']})" if r["provenance"] else "")
                )
        return 0
    out = []
    for name, path in builtins.items():
        m = load_machine(name)
        out.append(
            {
                "name": name,
                "path": str(path),
                "description": m.description,
                "moving_mass_kg": m.mechanics.moving_mass,
                "disturbance_calibrations": [m.disturbances.name]
                + [d.name for d in m.alternative_disturbances],
            }
        )
    if args.json:
        print_json({"machines": out})
    else:
        for m in out:
            print(
                f"{m['name']}: {m['description']} "
                f"(moving mass {m['moving_mass_kg']:g} kg; "
                f"disturbances: {', '.join(m['disturbance_calibrations'])})"
            )
    return 0
