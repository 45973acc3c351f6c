"""Compilation settings shared by every numba kernel of servosurf.

``FASTMATH``
    The one fast-math flag set used by every ``@njit`` in :mod:`servosurf.kernels`.
    It leaves out ``nnan`` and ``ninf`` so that NaN-masked pixels (invalid initial
    surface, points outside the workpiece) and ``+inf`` (no material) stay correct.
    ``afn`` allows approximate library calls; the sweep tests compare the kernels with
    a plain-numpy reference to 1 pm, which bounds its effect.

``CACHE``
    Whether compiled kernels are cached on disk (numba ``cache=True``): the
    ``numba_cache`` knob of :data:`servosurf.defaults` when this module is first
    imported. **Default: on** (``SERVOSURF_NUMBA_CACHE=0`` turns it off); the reason
    and the multiprocessing caveat are stated in :mod:`servosurf._defaults`.
"""

from __future__ import annotations

from .._defaults import defaults

__all__ = ["FASTMATH", "CACHE"]

#: LLVM fast-math flags for every kernel (no ``nnan``/``ninf``: NaN and inf stay exact).
FASTMATH = {"nsz", "arcp", "contract", "afn", "reassoc"}

#: Disk caching of compiled kernels (read once from ``defaults["numba_cache"]``).
CACHE = bool(defaults["numba_cache"])
