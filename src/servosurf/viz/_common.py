"""Shared plotting helpers: Agg backend, atomic PNG output."""

from __future__ import annotations

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

    from .._atomic import atomic_path

    try:
        with atomic_path(path, suffix=".png") as tmp:
            fig.savefig(tmp, dpi=dpi, bbox_inches="tight")
    finally:
        plt.close(fig)
    return Path(path)
