"""servosurf: fast-tool-servo diamond turning simulator and surface analysis.

Data flows one way: config -> toolpath -> servo/force/noise deviation -> kernel ->
surface -> analysis -> report. Subpackages are imported lazily, so
``import servosurf`` stays light (no numba, matplotlib or pyvista at import time).

Architecture
------------
Imports only go down these layers (:data:`LAYERS`, lowest first); a module may
import its own layer (without a package cycle) or a lower one, and another
package only through its public ``__init__`` names, never its private modules
(``tests/test_architecture.py`` enforces all three):

0. ground floor: ``errors``, ``units``, ``_version``, ``_validation``, ``config``,
   ``_atomic``, ``_defaults`` (process knobs), ``_progress``, ``_random`` (the
   random streams), ``_builtins``, ``_resources``, ``_tasks``;
1. ``kernels`` (numba only; the one place of ``@njit``);
2. ``metrology`` (the Surface and Profile types every stage passes on, and their
   analysis);
3. ``io`` (file formats of surfaces, profiles and traces);
4. ``servo``, ``toolpath`` (the loop; the path, the tool and the sweep);
5. ``noise``, ``cutting`` (disturbance realisations through the loop; the chip
   force and the material rules);
6. ``_parts``, ``_hooks`` (the hook protocol of simulate and the diagnosis's
   fitted terms), ``run``, ``simulation``, ``scale`` (one run's configuration and
   assembly, the whole face);
7. ``calibration``, ``report``, ``viz``, ``diagnose`` (paper calibration,
   analyses with result objects, figures, the diagnosis);
8. ``commands`` (parse, call one library function, write; no matplotlib);
9. ``cli``, ``__main__``.

One exception is by design: a result object's ``plot`` method in a lower layer
(e.g. :meth:`servosurf.toolpath.ToolEdge.plot`) imports :mod:`servosurf.viz`
inside that method (figures stay lazy; ``viz`` itself imports nothing above
``metrology``).
"""

from __future__ import annotations

import importlib

from ._defaults import defaults, defaults_override, reset_defaults, set_defaults
from ._version import __version__

#: Architecture layers, lowest first: a module imports only from its own layer or
#: below (never a package cycle, never another package's private module).
LAYERS: tuple[frozenset[str], ...] = (
    frozenset({"errors", "units", "_version", "_validation", "config", "_atomic",
               "_defaults", "_progress", "_random", "_builtins", "_resources",
               "_tasks"}),
    frozenset({"kernels"}),
    frozenset({"metrology"}),
    frozenset({"io"}),
    frozenset({"servo", "toolpath"}),
    frozenset({"noise", "cutting"}),
    frozenset({"_parts", "_hooks", "run", "simulation", "scale"}),
    frozenset({"calibration", "report", "viz", "diagnose"}),
    frozenset({"commands"}),
    frozenset({"cli", "__main__"}),
)


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
    "calibration",
    "report",
    "scale",
    "simulation",
    "run",
    "config",
    "errors",
    "units",
)

__all__ = [
    "__version__",
    "LAYERS",
    "defaults",
    "defaults_override",
    "reset_defaults",
    "set_defaults",
    *_SUBPACKAGES,
]


def __getattr__(name: str):
    if name in _SUBPACKAGES:
        return importlib.import_module(f".{name}", __name__)
    raise AttributeError(f"module 'servosurf' has no attribute {name!r}")
