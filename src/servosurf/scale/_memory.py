"""Process memory tuning for long tile loops (glibc only)."""

from __future__ import annotations

import ctypes
import ctypes.util
import sys

__all__ = ["reuse_freed_memory"]

_DONE = [False]


def reuse_freed_memory() -> bool:
    """Keep freed large blocks in the heap so tile buffers are reused (glibc).

    Tile loops allocate and free tens of MB of path and output arrays per tile.
    glibc returns blocks above ``M_MMAP_THRESHOLD`` to the kernel at once, so every
    tile page-faults its buffers in again, which on virtual machines costs as much as
    the kernel itself. Raising the mmap and trim thresholds to 1 GiB keeps those
    blocks for reuse; the resident size then stays at its peak instead of shrinking
    between tiles. Process-wide and idempotent; a no-op off glibc.

    Returns
    -------
    bool
        True when the thresholds were set (now or before).
    """
    if _DONE[0]:
        return True
    if not sys.platform.startswith("linux"):
        return False
    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6")
        mallopt = libc.mallopt
    except (OSError, AttributeError):
        return False
    m_trim_threshold, m_mmap_threshold = -1, -3
    ok = bool(mallopt(m_mmap_threshold, 1 << 30)) and bool(
        mallopt(m_trim_threshold, 1 << 30))
    _DONE[0] = ok
    return ok
