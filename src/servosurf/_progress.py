"""Progress reporting on stderr.

Long work reports per-stage lines (``stage(...)``) or a tqdm bar (``bar(...)``) on
stderr. Both are silenced by the ``quiet`` knob of :data:`servosurf.defaults`
(``SERVOSURF_QUIET=1``, ``defaults_override(quiet=True)``, or the CLI's ``-q``).
"""

from __future__ import annotations

import sys
import time
from collections.abc import Iterable, Iterator
from contextlib import contextmanager
from typing import TypeVar

from ._defaults import defaults

__all__ = ["stage", "bar", "note", "set_quiet", "is_quiet"]

T = TypeVar("T")


def set_quiet(quiet: bool) -> None:
    """Silence (True) or enable (False) progress output for the rest of the process.

    For entry points; library code uses ``defaults_override(quiet=True)``.
    """
    defaults["quiet"] = bool(quiet)


def is_quiet() -> bool:
    """Return True when progress output is silenced."""
    return bool(defaults["quiet"])


@contextmanager
def stage(name: str) -> Iterator[None]:
    """Print ``[servosurf] name ...`` then the elapsed time in s when the block ends."""
    t0 = time.perf_counter()
    if not is_quiet():
        print(f"[servosurf] {name} ...", file=sys.stderr, flush=True)
    yield
    if not is_quiet():
        dt = time.perf_counter() - t0
        print(f"[servosurf] {name}: done in {dt:.2f} s", file=sys.stderr, flush=True)


def note(text: str) -> None:
    """Print ``[servosurf]   text`` on stderr (an aside inside a stage)."""
    if not is_quiet():
        print(f"[servosurf]   {text}", file=sys.stderr, flush=True)


def bar(it: Iterable[T], *, total: int | None = None, desc: str = "") -> Iterable[T]:
    """Wrap an iterable in a tqdm progress bar on stderr (or return it when quiet)."""
    if is_quiet():
        return it
    from tqdm import tqdm

    return tqdm(it, total=total, desc=desc, file=sys.stderr, leave=False)
