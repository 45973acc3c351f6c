"""Toolpaths, the round-nose tool, sampling and the swept-arc surface.

Flow: :func:`load_toolpath` (TOML) -> :func:`sample` (controller-rate samples, whole
or only the windows that cut a field) -> deviations added to ``path.z`` by the servo,
force and vibration stages -> :func:`sweep` (lower envelope of the tool arc) ->
:class:`~servosurf.metrology.Surface`.

Units are SI: m, s, rad, Hz; spindle speed in rev/s. TOML files may use the boundary
aliases ``spindle-speed-rpm`` and ``<angle>-deg``.
"""

from __future__ import annotations

from ._paths import (
    FacingToolpath,
    LensletToolpath,
    ToolpathSpec,
    builtin_toolpaths,
    lenslet_chord,
    lenslet_cut_fraction,
    lenslet_surface_speed,
    load_toolpath,
    toolpath_from_mapping,
)
from ._sample import FS_DEFAULT, SampledPath, count_samples, field_reach, sample
from ._sweep import check_clearance, sweep
from ._tool import Field, Tool, ToolpathWarning, read_waviness_csv

__all__ = [
    "FacingToolpath",
    "LensletToolpath",
    "ToolpathSpec",
    "Tool",
    "Field",
    "ToolpathWarning",
    "SampledPath",
    "FS_DEFAULT",
    "load_toolpath",
    "builtin_toolpaths",
    "toolpath_from_mapping",
    "read_waviness_csv",
    "sample",
    "count_samples",
    "field_reach",
    "sweep",
    "check_clearance",
    "lenslet_chord",
    "lenslet_cut_fraction",
    "lenslet_surface_speed",
]
