"""Material parts of the forward model: the rules of the time-ordered sweep from the
workpiece material (ratios) and the tool's cutting-edge radius r_n."""

from __future__ import annotations

from collections.abc import Iterable

from ..toolpath import CuttingRules, Tool
from ._force import Material

__all__ = ["MATERIAL_PARTS", "cutting_rules"]

#: Parts of :func:`servosurf.simulation.simulate` that act in the sweep, in order:
#: minimum chip thickness (ploughing), side-flow ridges, elastic recovery.
MATERIAL_PARTS = ("ploughing", "side-flow", "recovery")


def cutting_rules(material: Material, tool: Tool, parts: Iterable[str]) -> CuttingRules:
    """Rules of the time-ordered sweep for the material parts switched on.

    Parameters
    ----------
    material : Material
        Work material: ``min_chip_thickness_ratio`` (h_min / r_n),
        ``side_flow_height_ratio`` and ``side_flow_width_ratio`` (a / r_n, b / r_n),
        ``recovery_ratio`` and ``recovery_decay_ratio`` (d0 / r_n, h_d / r_n).
    tool : Tool
        The tool; its ``edge_radius`` r_n (m) scales every rule.
    parts : iterable of str
        Parts switched on; those of :data:`MATERIAL_PARTS` select rules (others
        are ignored).

    Returns
    -------
    CuttingRules
        Heights in m; all zero (the kinematic envelope) when no material part is on.

    Examples
    --------
    >>> from servosurf.cutting import Material, cutting_rules
    >>> from servosurf.toolpath import Tool
    >>> r = cutting_rules(Material(), Tool(edge_radius=20e-9), ["ploughing"])
    >>> round(r.min_chip_thickness * 1e9, 3)  # nm: 0.25 x 20 nm
    5.0
    """
    parts = set(parts)
    rn = tool.edge_radius
    kw: dict[str, float] = {}
    if "ploughing" in parts:
        kw["min_chip_thickness"] = material.min_chip_thickness_ratio * rn
    if "side-flow" in parts:
        kw["side_flow_height"] = material.side_flow_height_ratio * rn
        kw["side_flow_width"] = material.side_flow_width_ratio * rn
    if "recovery" in parts:
        kw["recovery_height"] = material.recovery_ratio * rn
        kw["recovery_decay"] = material.recovery_decay_ratio * rn
    return CuttingRules(**kw)
