"""Toolpaths, the round-nose tool, sampling and the swept-arc surface.

Toolpath kinds: spiral facing, sinusoidal lenslet rings, design surfaces (sphere,
conic/asphere, biconic, XY polynomial, sinusoidal grid, micro-lens arrays) cut by a
nose-compensated spiral (:class:`DesignToolpath`), and NC programs
(:func:`read_nc_program` into a :class:`BlockPath`, :func:`nc_spec`).

Flow: :func:`load_toolpath` -> :func:`sample` (controller-rate samples, whole or only
the windows that cut a field) -> deviations added to ``path.z`` by the servo, force
and vibration stages -> :func:`sweep` (lower envelope of the tool arc) or
:func:`sweep_ordered` (the passes in time order under material rules) ->
:class:`~servosurf.metrology.Surface`. A measured tool edge (:func:`read_tool_edge`)
gives the :class:`Tool` its nose radius and edge deviation.

Units are SI: m, s, rad, Hz; spindle speed in rev/s. TOML files may use the boundary
aliases ``spindle-speed-rpm`` and ``<angle>-deg``.
"""

from __future__ import annotations

from ._design import (
    DESIGN_TYPES,
    Biconic,
    DesignSurface,
    DesignToolpath,
    EvenAsphere,
    LensletArray,
    SinusoidalGrid,
    Sphere,
    XYPolynomial,
    design_from_mapping,
    design_toolpath_from_mapping,
    nose_compensated_tip,
)
from ._edge import (
    EdgeSettings,
    MeasuredEdge,
    ToolEdge,
    fit_tool_edge,
    read_edge_trace,
    read_tool_edge,
    tool_table_from_trace,
)
from ._nc import NC_FORMATS, NCProgram, read_nc_program
from ._ordered import CuttingRules, sweep_ordered
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
from ._trajectory import (
    BAND_PITCH,
    BlockPath,
    NCSettings,
    apply_overrides,
    band_field,
    nc_spec,
    nc_spec_from_mapping,
)

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
    "ToolEdge",
    "EdgeSettings",
    "MeasuredEdge",
    "read_edge_trace",
    "read_tool_edge",
    "fit_tool_edge",
    "tool_table_from_trace",
    "sample",
    "count_samples",
    "field_reach",
    "sweep",
    "sweep_ordered",
    "CuttingRules",
    "check_clearance",
    "lenslet_chord",
    "lenslet_cut_fraction",
    "lenslet_surface_speed",
    "NCProgram",
    "NC_FORMATS",
    "read_nc_program",
    "BlockPath",
    "NCSettings",
    "BAND_PITCH",
    "band_field",
    "nc_spec",
    "nc_spec_from_mapping",
    "apply_overrides",
    "DesignSurface",
    "Sphere",
    "EvenAsphere",
    "Biconic",
    "XYPolynomial",
    "SinusoidalGrid",
    "LensletArray",
    "DESIGN_TYPES",
    "DesignToolpath",
    "design_from_mapping",
    "design_toolpath_from_mapping",
    "nose_compensated_tip",
]
