"""One module per CLI subcommand.

Each defines ``add_parser(subparsers)`` and ``run(args) -> int``: it parses, calls
one library function and writes. Model assembly, analyses and figures live in the
library (result objects with ``.to_dict()`` and ``.plot(folder)``); no command
imports matplotlib or draws a figure itself (``tests/test_architecture.py``).
"""

from ._common import commit_outputs, discard_outputs

__all__ = ["commit_outputs", "discard_outputs"]
