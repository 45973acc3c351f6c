"""Cutting: workpiece material, pre-cut surface, chip section, thrust force and the
material rules of the time-ordered sweep (ploughing, side flow, elastic recovery)."""

from ._cycle import cutting_cycle_stats
from ._force import (
    DEFAULT_WORKPIECE,
    ChipModel,
    Material,
    Precut,
    Workpiece,
    builtin_workpieces,
    facing_chip_area,
    load_workpiece,
    segment_area,
)
from ._rules import MATERIAL_PARTS, cutting_rules

__all__ = [
    "cutting_cycle_stats",
    "DEFAULT_WORKPIECE",
    "ChipModel",
    "Material",
    "Precut",
    "Workpiece",
    "builtin_workpieces",
    "facing_chip_area",
    "load_workpiece",
    "segment_area",
    "MATERIAL_PARTS",
    "cutting_rules",
]
