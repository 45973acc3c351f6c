"""Command-line interface: ``servosurf <command> ...``.

This module only parses and dispatches. Each subcommand lives in
``servosurf.commands.<name>`` with two functions:

``add_parser(subparsers) -> argparse.ArgumentParser``
    registers the subcommand and its flags (every flag states its unit);
``run(args) -> int``
    does the work (heavy imports happen here, not at import time).

User errors (:class:`~servosurf.errors.ServosurfError`, missing files, bad flags and
flag values) print one line to stderr and return 1, never a traceback; ``--help``
and ``--version`` return 0.

``-q`` (before or after the command name) silences the progress lines and the
compilation notice on stderr and the result summary on stdout. It keeps the
one-line errors, warnings, ``--json`` output and the output of the commands whose
result *is* text (``toolpaths``, ``machines``, ``info``, ``profile``, ``paper``,
``convert``'s one line, ``diagnose --list``).

A command that writes a folder writes into a temporary folder beside ``--out``; the
folder replaces ``--out`` only when the command succeeds (see
:func:`servosurf.commands._common.output_folder`).
"""

from __future__ import annotations

import argparse
import importlib
import sys

__all__ = ["main", "build_parser", "COMMANDS"]

#: Subcommands in the order ``--help`` lists them.
COMMANDS = (
    "toolpaths",
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
    parser = _Parser(
        prog="servosurf",
        description=(
            "Simulate and analyse ultra-precision diamond turning with a fast tool "
            "servo. SI units inside; flags state their unit."
        ),
    )
    parser.add_argument("--version", action="version", version=f"%(prog)s {_version()}")
    quiet_help = ("quiet: no progress lines on stderr and no result summary on "
                  "stdout (errors, --json and text results stay)")
    parser.add_argument("-q", "--quiet", action="store_true", help=quiet_help)
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
        # -q also after the command name; SUPPRESS keeps a -q given before it
        p.add_argument("-q", "--quiet", action="store_true",
                       default=argparse.SUPPRESS, help=quiet_help)
    return parser


class _ArgumentError(Exception):
    """A usage error: bad flag, missing argument or a value of the wrong type."""

    def __init__(self, prog: str, message: str) -> None:
        super().__init__(message)
        self.prog = prog


class _Parser(argparse.ArgumentParser):
    """argparse that raises on a usage error instead of printing a usage block."""

    def error(self, message: str):  # type: ignore[override]
        raise _ArgumentError(self.prog, message)


def main(argv: list[str] | None = None) -> int:
    """Run the servosurf command line.

    Parameters
    ----------
    argv : list of str, optional
        Arguments without the program name; ``sys.argv[1:]`` when None.

    Returns
    -------
    int
        Exit status: 0 on success (and for ``--help``), 1 on a user error (a bad
        flag or value included), 130 when interrupted.
    """
    from .commands._common import commit_outputs, discard_outputs
    from .errors import ServosurfError

    parser = build_parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit as exc:  # --help and --version
        return int(exc.code or 0)
    except _ArgumentError as exc:
        print(f"{exc.prog}: error: {exc} (see {exc.prog} --help)", file=sys.stderr)
        return 1
    if getattr(args, "_run", None) is None:
        parser.print_help(sys.stderr)
        return 1
    import warnings

    from . import _progress

    quiet_before = _progress.is_quiet()
    if args.quiet:
        _progress.set_quiet(True)
    show_before = warnings.showwarning

    def one_line(message, category, filename, lineno, file=None, line=None):
        # a warning is one line naming the command, not a source file and line
        print(f"servosurf {args.command}: warning: {message}", file=sys.stderr,
              flush=True)

    warnings.showwarning = one_line
    status = 1
    try:
        status = int(args._run(args) or 0)
        if status == 0:
            commit_outputs(args.command)
        return status
    except ServosurfError as exc:
        print(f"servosurf {args.command}: error: {exc}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print(f"servosurf {args.command}: interrupted; previous results left as they "
              "were", file=sys.stderr)
        return 130
    except BrokenPipeError:  # e.g. `servosurf info f --json | head`
        import os

        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        return 0
    except MemoryError:
        print(f"servosurf {args.command}: error: out of memory; use a smaller field "
              "or grid", file=sys.stderr)
        return 1
    except OSError as exc:  # missing file, full disk, path under a file, ...
        where = f": {exc.filename}" if exc.filename else ""
        why = exc.strerror or str(exc)
        print(f"servosurf {args.command}: error: {why}{where}", file=sys.stderr)
        return 1
    finally:
        discard_outputs()  # after a commit there is nothing left to discard
        _progress.set_quiet(quiet_before)
        warnings.showwarning = show_before


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
