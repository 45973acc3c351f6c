"""Helpers shared by the subcommands: atomic output, JSON, machine loading."""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import numpy as np

from .._atomic import atomic_write

__all__ = ["atomic_write", "to_jsonable", "write_json", "out_dir", "print_json"]


def to_jsonable(obj: Any) -> Any:
    """Convert numpy scalars/arrays and non-finite floats to JSON-safe values."""
    if isinstance(obj, dict):
        return {str(k): to_jsonable(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [to_jsonable(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return to_jsonable(obj.tolist())
    if isinstance(obj, np.generic):
        return to_jsonable(obj.item())
    if isinstance(obj, float) and not math.isfinite(obj):
        return None
    if isinstance(obj, Path):
        return str(obj)
    return obj


def write_json(path: str | Path, data: Any) -> Path:
    """Write ``data`` as indented JSON atomically."""
    text = json.dumps(to_jsonable(data), indent=2)
    return atomic_write(path, lambda p: p.write_text(text + "\n"))


def print_json(data: Any) -> None:
    """Print ``data`` as JSON on stdout."""
    print(json.dumps(to_jsonable(data), indent=2))


def out_dir(path: str | Path) -> Path:
    """Create and return the output directory."""
    p = Path(path)
    if p.exists() and not p.is_dir():
        from ..errors import ConfigError

        raise ConfigError(f"--out {p}: exists and is not a directory")
    p.mkdir(parents=True, exist_ok=True)
    return p
