"""Cutting: workpiece material, pre-cut surface, chip section and thrust force."""

from ._cycle import cutting_cycle_stats
from ._force import (
    DEFAULT_WORKPIECE,
    ChipModel,
    Material,
    Precut,
    Workpiece,
    facing_chip_area,
    load_workpiece,
    segment_area,
)

__all__ = [
    "cutting_cycle_stats",
    "DEFAULT_WORKPIECE",
    "ChipModel",
    "Material",
    "Precut",
    "Workpiece",
    "facing_chip_area",
    "load_workpiece",
    "segment_area",
]
