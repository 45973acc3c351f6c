"""Cutting: workpiece material, pre-cut surface, chip section and thrust force."""

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

__all__ = [
    "DEFAULT_WORKPIECE",
    "ChipModel",
    "Material",
    "Precut",
    "Workpiece",
    "builtin_workpieces",
    "facing_chip_area",
    "load_workpiece",
    "segment_area",
]
