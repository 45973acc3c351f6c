"""``servosurf convert``: rewrite a surface file in another format."""

from __future__ import annotations

import argparse


def add_parser(sub) -> argparse.ArgumentParser:
    """Register ``servosurf convert`` and its flags on ``sub``."""
    p = sub.add_parser(
        "convert",
        help="convert a surface file to .datx, .dat, .x3p, .xyz or .npz",
        description="Read any readable surface or profile file and write it in a "
        "writable format (datx, metropro_dat, x3p, zygo_xyz, npz), chosen from OUT's "
        "suffix unless --format is given. Heights stay in m; metadata is carried over "
        "where the output format has room for it. The output is written atomically.",
    )
    p.add_argument("input", metavar="IN", help="input file")
    p.add_argument("output", metavar="OUT", help="output file")
    p.add_argument(
        "--format",
        metavar="FMT",
        help="output format name or suffix (default: from OUT's suffix)",
    )
    p.add_argument(
        "--from",
        dest="in_format",
        metavar="FMT",
        help="input format name or suffix (default: detect)",
    )
    return p


def run(args) -> int:
    """Convert IN to OUT; return the exit status."""
    from pathlib import Path

    from ..errors import ConfigError
    from ..io import read_any, write_surface

    if Path(args.input).resolve() == Path(args.output).resolve():
        raise ConfigError(f"OUT {args.output} is the input file; choose another path")
    obj, fmt = read_any(args.input, format=args.in_format)
    write_surface(obj, args.output, format=args.format)
    shape = "x".join(str(n) for n in obj.z.shape)
    print(f"wrote {args.output} ({shape}, from {fmt})")
    return 0
