"""servosurf: fast-tool-servo diamond turning simulator and surface analysis.

Data flows one way: config -> toolpath -> servo/force/noise deviation -> kernel ->
surface -> analysis -> report. Subpackages are imported lazily, so
``import servosurf`` stays light (no numba, matplotlib or pyvista at import time).
"""

from __future__ import annotations

import importlib

__version__ = "0.1.0"

_SUBPACKAGES = (
    "servo",
    "noise",
    "cutting",
    "toolpath",
    "kernels",
    "metrology",
    "io",
    "viz",
    "diagnose",
    "config",
    "errors",
    "units",
)

__all__ = ["__version__", *_SUBPACKAGES]


def __getattr__(name: str):
    if name in _SUBPACKAGES:
        return importlib.import_module(f".{name}", __name__)
    raise AttributeError(f"module 'servosurf' has no attribute {name!r}")
