"""Say so before numba compiles a slow kernel (once per process).

The first call of a kernel compiles it, which for the surface kernel takes about a
minute; later runs load it from numba's disk cache in well under a second. Without
a word the user reads the first run's "kernel on 480 x 640 grid: done in 53 s" as a
slow kernel. :func:`compile_notice` prints one line on stderr (through
:mod:`servosurf._progress`, so ``-q`` silences it) when the kernel has neither been
compiled in this process nor has a usable disk-cache entry.
"""

from __future__ import annotations

from .. import _progress
from ._config import CACHE

__all__ = ["needs_compilation", "compile_notice", "COMPILE_SECONDS"]

#: Measured first-call compilation time per kernel, in s, on the 2-core AMD EPYC
#: VM of the benchmarks (``NUMBA_CACHE_DIR`` pointing at an empty folder,
#: ``servosurf simulate lenslet_5um``): the sweep kernel and its inlined helpers.
COMPILE_SECONDS = {"surface kernel": 50.0}

_ANNOUNCED: set[str] = set()


def needs_compilation(dispatcher) -> bool:
    """True when calling the numba ``dispatcher`` will compile it first.

    It will not when it was compiled in this process, or when numba's disk cache
    holds a fresh entry (same source stamp and numba version) for this CPU. The
    check reads numba's cache index (private numba API); if that fails it answers
    True (a notice too many rather than a silent minute).
    """
    if getattr(dispatcher, "overloads", None):
        return False
    if not CACHE:
        return True
    try:
        index = dispatcher._cache._cache_file._load_index()
        magic = dispatcher.targetctx.codegen().magic_tuple()
    except Exception:  # numba internals changed: say it rather than stay silent
        return True
    return not any(isinstance(k, tuple) and len(k) > 1 and k[1] == magic
                   for k in index)


def compile_notice(dispatcher, what: str) -> bool:
    """Print one line before a slow first compilation of ``dispatcher``.

    Parameters
    ----------
    dispatcher : numba Dispatcher
        The kernel about to be called.
    what : str
        Its name in the message, a key of :data:`COMPILE_SECONDS`.

    Returns
    -------
    bool
        True when the notice was printed (at most once per ``what`` and process).
    """
    if what in _ANNOUNCED or not needs_compilation(dispatcher):
        return False
    _ANNOUNCED.add(what)
    seconds = COMPILE_SECONDS.get(what)
    took = f"about {seconds:.0f} s on a 2-core machine, " if seconds else ""
    later = ("once: later runs load it from the disk cache" if CACHE else
             "in every process: SERVOSURF_NUMBA_CACHE=0 turns the disk cache off")
    _progress.note(f"first run: compiling the {what} with numba ({took}{later})")
    return True
