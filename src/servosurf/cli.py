"""Command-line interface: ``servosurf <command> ...``.

This module only parses and dispatches. Each subcommand lives in
``servosurf.commands.<name>`` with two functions:

``add_parser(subparsers) -> argparse.ArgumentParser``
    registers the subcommand and its flags (every flag states its unit);
``run(args) -> int``
    does the work (heavy imports happen here, not at import time).

User errors (:class:`~servosurf.errors.ServosurfError`, missing files) print one line
to stderr and return 1, never a traceback.
"""

from __future__ import annotations

import argparse
import importlib
import sys

__all__ = ["main", "build_parser", "COMMANDS"]

#: Subcommands in the order ``--help`` lists them.
COMMANDS = (
    "machines",
    "noise",
    "psd",
    "paper",
    "identify",
    "simulate",
    "face",
    "info",
    "convert",
    "profile",
    "compare",
    "tool_edge",
    "diagnose",
)


def _version() -> str:
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("servosurf")
    except PackageNotFoundError:  # pragma: no cover - running from a source tree
        return "unknown"


def build_parser() -> argparse.ArgumentParser:
    """Return the argparse parser with every available subcommand registered."""
    parser = argparse.ArgumentParser(
        prog="servosurf",
        description=(
            "Simulate and analyse ultra-precision diamond turning with a fast tool "
            "servo. SI units inside; flags state their unit."
        ),
    )
    parser.add_argument("--version", action="version", version=f"%(prog)s {_version()}")
    parser.add_argument(
        "-q", "--quiet", action="store_true", help="no progress output on stderr"
    )
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name in COMMANDS:
        try:
            mod = importlib.import_module(f".commands.{name}", __package__)
        except ModuleNotFoundError as exc:  # command not built yet
            if exc.name == f"{__package__}.commands.{name}":
                continue
            raise
        p = mod.add_parser(sub)
        p.set_defaults(_run=mod.run)
    return parser


class _ArgumentError(Exception):
    pass


def main(argv: list[str] | None = None) -> int:
    """Run the servosurf command line.

    Parameters
    ----------
    argv : list of str, optional
        Arguments without the program name; ``sys.argv[1:]`` when None.

    Returns
    -------
    int
        Exit status: 0 on success, 1 on a user error, 2 on a usage error.
    """
    from .errors import ServosurfError

    parser = build_parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit as exc:  # argparse usage errors and --help
        return int(exc.code or 0)
    if getattr(args, "_run", None) is None:
        parser.print_help(sys.stderr)
        return 1
    if args.quiet:
        from ._progress import set_quiet

        set_quiet(True)
    try:
        return int(args._run(args) or 0)
    except ServosurfError as exc:
        print(f"servosurf {args.command}: error: {exc}", file=sys.stderr)
        return 1
    except (FileNotFoundError, IsADirectoryError, PermissionError) as exc:
        print(f"servosurf {args.command}: error: {exc}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print("servosurf: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:  # e.g. `servosurf info f --json | head`
        import os

        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        return 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
