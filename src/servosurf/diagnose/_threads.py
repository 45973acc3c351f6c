"""Run the diagnosis with one BLAS thread.

The diagnosis makes many small and medium BLAS calls (dot products of residual
vectors, small least squares). A multithreaded OpenBLAS on a shared or
oversubscribed machine turns each into a spin-wait: a 100 000-element dot product
measured 0.5 s instead of 0.1 ms with four busy processes on two cores. The
context manager :func:`single_blas_thread` limits the loaded OpenBLAS libraries to
one thread and restores their setting afterwards (``threadpoolctl`` when installed,
otherwise the libraries' own ``*_set_num_threads`` entry points found in the
process's memory map; a no-op where neither works).
"""

from __future__ import annotations

import ctypes
from contextlib import contextmanager

__all__ = ["single_blas_thread"]


def _openblas_handles():
    out = []
    try:
        with open("/proc/self/maps") as fh:
            paths = {
                ln.split()[-1] for ln in fh if "openblas" in ln.lower() and ".so" in ln
            }
    except OSError:
        return out
    for path in sorted(paths):
        try:
            lib = ctypes.CDLL(path)
        except OSError:
            continue
        for stem in ("scipy_openblas", "openblas"):
            for suffix in ("64_", ""):
                setter = getattr(lib, f"{stem}_set_num_threads{suffix}", None)
                getter = getattr(lib, f"{stem}_get_num_threads{suffix}", None)
                if setter is not None and getter is not None:
                    getter.restype = ctypes.c_int
                    out.append((setter, getter))
                    break
            else:
                continue
            break
    return out


@contextmanager
def single_blas_thread():
    """Limit BLAS to one thread inside the block (restored on exit)."""
    try:
        from threadpoolctl import threadpool_limits
    except ImportError:
        threadpool_limits = None
    if threadpool_limits is not None:
        with threadpool_limits(limits=1, user_api="blas"):
            yield
        return
    handles = []
    try:
        handles = [(s, g, int(g())) for s, g in _openblas_handles()]
        for s, _g, _n in handles:
            s(ctypes.c_int(1))
    except (OSError, AttributeError, ValueError):
        handles = []
    try:
        yield
    finally:
        for s, _g, n in handles:
            try:
                s(ctypes.c_int(n))
            except (OSError, ValueError):
                pass
