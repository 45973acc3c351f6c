"""Process knobs in one place: a defaults mapping, its reset and a scoped override.

Runtime settings that are not physics (python-control's ``config.defaults``;
stumpy's ``config``) live in one mutable mapping, :data:`defaults`:

``numba_cache`` : bool, default: True (``SERVOSURF_NUMBA_CACHE=0`` turns it off)
    Numba ``cache=`` of every kernel: compiled kernels are written to numba's disk
    cache (``__pycache__`` beside the kernel sources, or ``NUMBA_CACHE_DIR``) and
    loaded by later processes. **On by default, on purpose**: the surface kernel
    takes about 50 s to compile on a 2-core machine, and every ``servosurf``
    command is a new process, so without the cache each ``servosurf simulate``
    would pay that minute again (and each dask worker and each pytest-xdist
    worker). The cache is not process state: it is a file store keyed on the
    kernel's source, numba's version and the CPU, written atomically by numba.
    The value is read once, when :mod:`servosurf.kernels` is first imported (the
    ``@njit`` decorators run then); changing it later has no effect in that
    process. Turn it off on read-only installs. Multiprocessing caveat: workers
    that start on a cold cache at the same time all compile (time, not
    correctness); warm it in the parent first.
``numba_threads`` : int or None, default: None
    Threads of the parallel kernels when a call gives no ``n_threads`` (None:
    numba's own setting, all cores or ``NUMBA_NUM_THREADS``). Applied around each
    kernel call by :func:`numba_threads` and restored afterwards.
``quiet`` : bool, default: False (``SERVOSURF_QUIET=1`` turns it on)
    No progress lines on stderr (:mod:`servosurf._progress`).
``blas_threads`` : int or None, default: 1
    BLAS threads inside :func:`blas_threads` blocks (many small least squares: a
    multithreaded OpenBLAS spin-waits on a busy machine; a 100 000-element dot
    product measured 0.5 s instead of 0.1 ms with four busy processes on two
    cores). None leaves BLAS alone. Restored when the block ends.
``malloc_threshold_bytes`` : int or None, default: 1 GiB
    glibc's mmap and trim thresholds inside :func:`malloc_reuse` blocks (tile loops
    and realisation tasks), so that freed tile buffers are reused instead of
    page-faulted in again. None leaves malloc alone. Set back to the process's
    values (the ``MALLOC_*_THRESHOLD_`` environment variables, else glibc's
    128 KiB; glibc's dynamic mmap threshold stays off) when the outermost block
    ends; a no-op off glibc. An entry point may keep them raised for the whole
    process with :func:`reuse_freed_memory` (benchmarks, dask worker set-up).

Library code reads the knobs and applies them only inside a ``with`` block that
restores the previous state; it never sets them for good. Entry points (the CLI,
a script, a test) change them with :func:`defaults_override` (scoped) or
:func:`set_defaults`, and :func:`reset_defaults` returns to the values above.

Examples
--------
>>> from servosurf import defaults, defaults_override
>>> with defaults_override(quiet=True):
...     defaults["quiet"]
True
"""

from __future__ import annotations

import os
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any

__all__ = [
    "defaults",
    "reset_defaults",
    "set_defaults",
    "defaults_override",
    "numba_threads",
    "blas_threads",
    "malloc_reuse",
    "reuse_freed_memory",
]

_OFF = ("0", "false", "off", "no")


def _initial() -> dict[str, Any]:
    """The documented defaults (environment variables read now)."""
    cache = os.environ.get("SERVOSURF_NUMBA_CACHE", "1").strip().lower()
    quiet = os.environ.get("SERVOSURF_QUIET", "").strip().lower()
    return {
        "numba_cache": cache not in _OFF,
        "numba_threads": None,
        "quiet": quiet not in ("", *_OFF),
        "blas_threads": 1,
        "malloc_threshold_bytes": 1 << 30,
    }


#: The process knobs (see the module docstring for each key, its unit and reason).
defaults: dict[str, Any] = _initial()


def _check(kw: dict[str, Any]) -> None:
    """Refuse unknown knobs and values of the wrong kind (TypeError/ValueError)."""
    for key, value in kw.items():
        if key not in defaults:
            import difflib

            near = difflib.get_close_matches(key, list(defaults), n=1)
            hint = f" Did you mean: {near[0]}?" if near else ""
            raise TypeError(f"unknown servosurf default {key!r}.{hint} Known: "
                            f"{', '.join(defaults)}")
        if key in ("numba_cache", "quiet"):
            if not isinstance(value, bool):
                raise ValueError(f"{key} must be True or False, got {value!r}")
        elif value is not None and (isinstance(value, bool)
                                    or not isinstance(value, int) or value < 1):
            raise ValueError(f"{key} must be a positive integer or None, got "
                             f"{value!r}")


def set_defaults(**kw: Any) -> None:
    """Change knobs for the rest of the process (entry points only).

    Parameters
    ----------
    **kw
        Knob names of :data:`defaults` and their new values.

    Raises
    ------
    TypeError
        On an unknown knob.
    ValueError
        On a value of the wrong kind.
    """
    _check(kw)
    defaults.update(kw)


def reset_defaults() -> None:
    """Return every knob to its documented default (environment read again)."""
    defaults.clear()
    defaults.update(_initial())


@contextmanager
def defaults_override(**kw: Any) -> Iterator[dict[str, Any]]:
    """Change knobs inside a ``with`` block; the previous values come back after.

    Parameters
    ----------
    **kw
        Knob names of :data:`defaults` and their values inside the block.

    Yields
    ------
    dict
        The :data:`defaults` mapping.

    Raises
    ------
    TypeError
        On an unknown knob.
    ValueError
        On a value of the wrong kind.
    """
    _check(kw)
    before = {k: defaults[k] for k in kw}
    defaults.update(kw)
    try:
        yield defaults
    finally:
        defaults.update(before)


@contextmanager
def numba_threads(n_threads: int | None = None) -> Iterator[None]:
    """Run the block with ``n_threads`` numba threads, restored afterwards.

    Parameters
    ----------
    n_threads : int, optional
        Threads of the parallel kernels (default: ``defaults["numba_threads"]``;
        None there too: numba's current setting, nothing changed).

    Raises
    ------
    ConfigError
        When ``n_threads`` is not in ``[1, NUMBA_NUM_THREADS]``.
    """
    n_threads = defaults["numba_threads"] if n_threads is None else n_threads
    if n_threads is None:
        yield
        return
    import numba

    from .errors import ConfigError

    top = numba.config.NUMBA_NUM_THREADS
    if isinstance(n_threads, bool) or not isinstance(n_threads, int | float) or not (
            1 <= n_threads <= top and int(n_threads) == n_threads):
        raise ConfigError(f"n_threads must be an integer in [1, {top}], got "
                          f"{n_threads!r}")
    old = numba.get_num_threads()
    numba.set_num_threads(int(n_threads))
    try:
        yield
    finally:
        numba.set_num_threads(old)


def _openblas_handles() -> list:
    """``(set, get)`` thread-count entry points of the OpenBLAS libraries loaded."""
    import ctypes

    out: list = []
    try:
        with open("/proc/self/maps") as fh:
            paths = {ln.split()[-1] for ln in fh
                     if "openblas" in ln.lower() and ".so" in ln}
    except OSError:
        return out
    for path in sorted(paths):
        try:
            lib = ctypes.CDLL(path)
        except OSError:
            continue
        found = None
        for stem in ("scipy_openblas", "openblas"):
            for suffix in ("64_", ""):
                setter = getattr(lib, f"{stem}_set_num_threads{suffix}", None)
                getter = getattr(lib, f"{stem}_get_num_threads{suffix}", None)
                if setter is not None and getter is not None:
                    getter.restype = ctypes.c_int
                    found = (setter, getter)
                    break
            if found:
                break
        if found:
            out.append(found)
    return out


@contextmanager
def blas_threads(n_threads: int | None = None) -> Iterator[None]:
    """Limit BLAS to ``n_threads`` inside the block (restored on exit).

    Uses ``threadpoolctl`` when installed, otherwise the loaded OpenBLAS libraries'
    own ``*_set_num_threads`` entry points found in the process's memory map; a
    no-op where neither works.

    Parameters
    ----------
    n_threads : int, optional
        BLAS threads (default: ``defaults["blas_threads"]``; None there too: BLAS
        is left alone).
    """
    n_threads = defaults["blas_threads"] if n_threads is None else n_threads
    if n_threads is None:
        yield
        return
    try:
        from threadpoolctl import threadpool_limits
    except ImportError:
        threadpool_limits = None
    if threadpool_limits is not None:
        with threadpool_limits(limits=int(n_threads), user_api="blas"):
            yield
        return
    import ctypes

    handles = []
    try:
        handles = [(s, int(g())) for s, g in _openblas_handles()]
        for s, _n in handles:
            s(ctypes.c_int(int(n_threads)))
    except (OSError, AttributeError, ValueError):
        handles = []
    try:
        yield
    finally:
        for s, n in handles:
            try:
                s(ctypes.c_int(n))
            except (OSError, ValueError):
                pass


#: glibc mallopt parameters: M_TRIM_THRESHOLD, M_MMAP_THRESHOLD.
_M_TRIM, _M_MMAP = -1, -3
#: glibc's defaults of both thresholds, in bytes.
_GLIBC_THRESHOLD = 128 * 1024
#: Depth of nested :func:`malloc_reuse` blocks in this process.
_MALLOC_DEPTH = [0]
#: Set by :func:`reuse_freed_memory`: the thresholds stay raised for the process.
_MALLOC_KEPT = [False]


def _mallopt():
    """glibc's ``mallopt`` or None (not Linux, not glibc)."""
    import sys

    if not sys.platform.startswith("linux"):
        return None
    import ctypes
    import ctypes.util

    try:
        return ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6").mallopt
    except (OSError, AttributeError):
        return None


def _process_threshold(name: str) -> int:
    """The process's own threshold: its environment variable, else glibc's."""
    try:
        return int(os.environ[f"MALLOC_{name}_THRESHOLD_"])
    except (KeyError, ValueError):
        return _GLIBC_THRESHOLD


@contextmanager
def malloc_reuse(threshold: int | None = None) -> Iterator[bool]:
    """Keep freed large blocks in the heap inside the block (glibc only).

    Tile loops allocate and free tens of MB of path and output arrays per tile.
    glibc returns blocks above ``M_MMAP_THRESHOLD`` to the kernel at once, so every
    tile page-faults its buffers in again, which on virtual machines costs as much
    as the kernel itself (dask's nanny also starts workers with
    ``MALLOC_TRIM_THRESHOLD_=65536``). Raising the mmap and trim thresholds keeps
    those blocks for reuse; the resident size stays at its peak while the block
    runs. The outermost block sets the process's thresholds back when it ends.

    Parameters
    ----------
    threshold : int, optional
        Both thresholds in bytes (default: ``defaults["malloc_threshold_bytes"]``;
        None there too: malloc is left alone).

    Yields
    ------
    bool
        True when the thresholds are raised inside the block.
    """
    threshold = defaults["malloc_threshold_bytes"] if threshold is None else threshold
    mallopt = None if threshold is None else _mallopt()
    if mallopt is None:
        yield False
        return
    outer = _MALLOC_DEPTH[0] == 0 and not _MALLOC_KEPT[0]
    ok = True
    if outer:
        ok = bool(mallopt(_M_MMAP, int(threshold))) and bool(
            mallopt(_M_TRIM, int(threshold)))
    _MALLOC_DEPTH[0] += 1
    try:
        yield ok
    finally:
        _MALLOC_DEPTH[0] -= 1
        if outer:
            mallopt(_M_MMAP, _process_threshold("MMAP"))
            mallopt(_M_TRIM, _process_threshold("TRIM"))


def reuse_freed_memory() -> bool:
    """Raise glibc's heap thresholds for the rest of the process (entry points only).

    The permanent form of :func:`malloc_reuse` for a process that runs tile loops
    for its whole life (a benchmark script, a dask worker's set-up); library code
    uses the scoped :func:`malloc_reuse`. Idempotent; a no-op off glibc or with
    ``defaults["malloc_threshold_bytes"]`` None.

    Returns
    -------
    bool
        True when the thresholds are raised (now or before).
    """
    if _MALLOC_KEPT[0]:
        return True
    threshold = defaults["malloc_threshold_bytes"]
    mallopt = None if threshold is None else _mallopt()
    if mallopt is None:
        return False
    ok = bool(mallopt(_M_MMAP, int(threshold))) and bool(
        mallopt(_M_TRIM, int(threshold)))
    _MALLOC_KEPT[0] = ok
    return ok
