"""Progress reporting on stderr.

Long work reports per-stage lines (``stage(...)``) or a tqdm bar (``bar(...)``) on
stderr. Both are silenced with ``SERVOSURF_QUIET=1`` or ``set_quiet(True)``.
"""

from __future__ import annotations

import os
import sys
import time
from collections.abc import Iterable, Iterator
from contextlib import contextmanager
from typing import TypeVar

__all__ = ["stage", "bar", "note", "set_quiet", "is_quiet"]

T = TypeVar("T")
_QUIET = [os.environ.get("SERVOSURF_QUIET", "") not in ("", "0")]


def set_quiet(quiet: bool) -> None:
    """Silence (True) or enable (False) progress output."""
    _QUIET[0] = bool(quiet)


def is_quiet() -> bool:
    """Return True when progress output is silenced."""
    return _QUIET[0]


@contextmanager
def stage(name: str) -> Iterator[None]:
    """Print ``[servosurf] name ...`` then the elapsed time in s when the block ends."""
    t0 = time.perf_counter()
    if not _QUIET[0]:
        print(f"[servosurf] {name} ...", file=sys.stderr, flush=True)
    yield
    if not _QUIET[0]:
        dt = time.perf_counter() - t0
        print(f"[servosurf] {name}: done in {dt:.2f} s", file=sys.stderr, flush=True)


def note(text: str) -> None:
    """Print ``[servosurf]   text`` on stderr (an aside inside a stage)."""
    if not _QUIET[0]:
        print(f"[servosurf]   {text}", file=sys.stderr, flush=True)


def bar(it: Iterable[T], *, total: int | None = None, desc: str = "") -> Iterable[T]:
    """Wrap an iterable in a tqdm progress bar on stderr (or return it when quiet)."""
    if _QUIET[0]:
        return it
    from tqdm import tqdm

    return tqdm(it, total=total, desc=desc, file=sys.stderr, leave=False)
