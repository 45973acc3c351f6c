"""The whole simulation: toolpath -> servo/force/vibration deviation -> kernel -> map.

:func:`simulate` runs the FTS loop model (``_simulate.py``); machines whose Z axis
is not the FTS and kinematic runs go through ``_axes.py``; both return a
:class:`SimulationResult` (``_common.py``). A run's settings come from a
:class:`servosurf.run.RunConfig` (or a preset name). The analysis of a result and
the multi-seed realisation study live in :mod:`servosurf.report`.
"""

from __future__ import annotations

from ._common import (
    DEFAULT_PARTS,
    KINEMATIC,
    MAX_SPAN_SAMPLES,
    NC_MACHINE,
    PARTS,
    SETTLE_TIME,
    SimulationResult,
    cutting_span,
    deviation_samples,
)
from ._simulate import design_force, simulate

__all__ = [
    "simulate",
    "design_force",
    "SimulationResult",
    "PARTS",
    "KINEMATIC",
    "DEFAULT_PARTS",
    "SETTLE_TIME",
    "NC_MACHINE",
    "MAX_SPAN_SAMPLES",
    "cutting_span",
    "deviation_samples",
]
