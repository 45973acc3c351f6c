"""``servosurf toolpaths``: the built-in toolpaths and workpieces, by name."""

from __future__ import annotations

import argparse


def add_parser(sub) -> argparse.ArgumentParser:
    p = sub.add_parser(
        "toolpaths",
        help="list the built-in toolpaths and workpieces (usable by name)",
        description="List the toolpath and workpiece files shipped with servosurf, "
        "one line each with its description. A built-in name works wherever a file "
        "path does (servosurf simulate lenslet_5um --workpiece nip); --show NAME "
        "prints the file, to copy and edit (servosurf toolpaths --show lenslet_5um "
        "> my_lenslet.toml). Values in the files are SI (m, s, Hz).",
    )
    p.add_argument("--show", metavar="NAME",
                   help="print the built-in toolpath or workpiece file NAME")
    p.add_argument("--json", action="store_true", help="JSON output on stdout")
    return p


def run(args) -> int:
    from .._builtins import KINDS, builtin_description, builtin_files
    from ..errors import ConfigError
    from ._common import print_json

    found = {kind: builtin_files(kind) for kind in KINDS}
    if args.show:
        name = args.show[:-5] if args.show.endswith(".toml") else args.show
        for files in found.values():
            if name in files:
                print(files[name].read_text(encoding="utf-8"), end="")
                return 0
        have = ", ".join(n for files in found.values() for n in files)
        raise ConfigError(
            f"--show {args.show!r}: no built-in toolpath or workpiece of that name; "
            f"have: {have}"
        )
    table = {
        KINDS[kind]: [
            {"name": n, "description": builtin_description(p), "path": str(p)}
            for n, p in files.items()
        ]
        for kind, files in found.items()
    }
    if args.json:
        print_json(table)
        return 0
    width = max((len(r["name"]) for rows in table.values() for r in rows), default=8)
    for folder, rows in table.items():
        print(f"{folder} (use the name wherever a file path goes):")
        for r in rows:
            print(f"  {r['name']:<{width}}  {r['description']}")
    return 0
