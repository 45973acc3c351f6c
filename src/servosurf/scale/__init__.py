"""Whole-workpiece runs and many-task studies: tiling, chunked Zarr output, dask.

zarr is a dependency (the face's output array); dask (``distributed``, the
``scale`` extra) is needed only to run tasks on a cluster, imported on use.
"""

from __future__ import annotations

from ._face import (
    FaceResult,
    IndexNoise,
    chunk_slices,
    compute_tile,
    face_field,
    face_preview,
    grid_attributes,
    simulate_face,
)
from ._memory import reuse_freed_memory
from ._tasks import map_tasks
from ._vibration import MemmapDeviation, write_vibration

__all__ = [
    "simulate_face",
    "compute_tile",
    "face_field",
    "face_preview",
    "grid_attributes",
    "chunk_slices",
    "FaceResult",
    "IndexNoise",
    "reuse_freed_memory",
    "map_tasks",
    "MemmapDeviation",
    "write_vibration",
]
