"""Numba kernels (private).

Every kernel lives in a private ``_*.py`` module and takes contiguous float64/int64
arrays plus a preallocated ``out``; checked public wrappers live in the stage
subpackages (for example :func:`servosurf.toolpath.sweep`). Importing this package
does not compile anything: kernels compile on first call (and are cached on disk
unless ``SERVOSURF_NUMBA_CACHE=0``, see :mod:`servosurf.kernels._config`).
"""

from __future__ import annotations

from ._config import CACHE, FASTMATH

__all__ = ["FASTMATH", "CACHE"]
