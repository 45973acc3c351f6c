"""Shared plotting helpers: Agg backend, atomic PNG output."""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

__all__ = ["figure", "save"]


def figure(*args, **kwargs):
    """Return ``(fig, axes)`` from matplotlib's object API with the Agg backend."""
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    return plt.subplots(*args, **kwargs)


def save(fig, path: str | Path, *, dpi: int = 120) -> Path:
    """Save ``fig`` as PNG atomically (temp file + rename) and close it."""
    import matplotlib.pyplot as plt

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.stem}.", suffix=".png", dir=path.parent)
    os.close(fd)
    try:
        fig.savefig(tmp, dpi=dpi, bbox_inches="tight")
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    finally:
        plt.close(fig)
    return path
