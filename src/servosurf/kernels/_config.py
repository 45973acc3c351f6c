"""Compilation settings shared by every numba kernel of servosurf.

``FASTMATH``
    The one fast-math flag set used by every ``@njit`` in :mod:`servosurf.kernels`.
    It leaves out ``nnan`` and ``ninf`` so that NaN-masked pixels (invalid initial
    surface, points outside the workpiece) and ``+inf`` (no material) stay correct.
    ``afn`` allows approximate library calls; the sweep tests compare the kernels with
    a plain-numpy reference to 1 pm, which bounds its effect.

``CACHE``
    Whether compiled kernels are cached on disk (numba ``cache=True``), so that a second
    ``servosurf simulate`` does not pay the JIT compilation again. **Default: on.**
    Set the environment variable ``SERVOSURF_NUMBA_CACHE=0`` (or ``false``/``off``/
    ``no``) before importing servosurf to disable it.

Notes
-----
Multiprocessing caveat: the cache lives in ``__pycache__`` beside the kernel sources
(or in ``NUMBA_CACHE_DIR``). Worker processes that start at the same time on a cold
cache (dask workers, ``multiprocessing`` pools) may all compile and write the same
cache entry; numba writes the files atomically, so this costs time but not
correctness. Warm the cache in the parent first (call the kernel once on a tiny case)
or set ``SERVOSURF_NUMBA_CACHE=0`` on read-only installs. The cache is keyed on the
source file and the CPU; a changed machine recompiles.
"""

from __future__ import annotations

import os

__all__ = ["FASTMATH", "CACHE"]

#: LLVM fast-math flags for every kernel (no ``nnan``/``ninf``: NaN and inf stay exact).
FASTMATH = {"nsz", "arcp", "contract", "afn", "reassoc"}

_OFF = ("0", "false", "off", "no")

#: Disk caching of compiled kernels (``SERVOSURF_NUMBA_CACHE=0`` disables it).
CACHE = os.environ.get("SERVOSURF_NUMBA_CACHE", "1").strip().lower() not in _OFF
