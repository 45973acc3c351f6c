"""Helpers shared by the subcommands: atomic output, JSON, machine loading."""

from __future__ import annotations

import json
import math
from contextlib import contextmanager
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


def add_scheduler_args(p, what: str) -> None:
    """``--scheduler`` and ``--workers`` options of a command that runs ``what``."""
    p.add_argument("--scheduler", metavar="ADDRESS", default=None,
                   help=f"run {what} on dask: a scheduler address, or 'local' for a "
                   "LocalCluster of --workers processes (default: in this process)")
    p.add_argument("--workers", metavar="N", type=int, default=2,
                   help="worker processes of the local cluster (default 2)")


@contextmanager
def dask_client(scheduler: str | None, workers: int = 2):
    """A dask client for ``--scheduler`` (None: yields None, run in this process).

    ``"local"`` starts a LocalCluster of ``workers`` single-threaded processes,
    anything else is a scheduler address. A missing ``distributed`` package or an
    unreachable scheduler is a :class:`ConfigError` naming the value.
    """
    from ..errors import ConfigError

    if not scheduler:
        yield None
        return
    try:
        from distributed import Client, LocalCluster
    except ImportError:
        raise ConfigError(
            "--scheduler needs dask distributed: pip install 'servosurf[scale]'"
        ) from None
    if scheduler == "local":
        if workers < 1:
            raise ConfigError(f"--workers must be >= 1, got {workers}")
        cluster = LocalCluster(n_workers=workers, threads_per_worker=1,
                               processes=True, dashboard_address=None)
        client = Client(cluster)
    else:
        cluster = None
        try:
            client = Client(scheduler, timeout="5s")
        except (OSError, TimeoutError, ValueError) as exc:
            raise ConfigError(
                f"--scheduler {scheduler!r}: no dask scheduler reachable there "
                f"({type(exc).__name__}); give host:port of a running scheduler, "
                "or 'local'"
            ) from None
    try:
        yield client
    finally:
        client.close()
        if cluster is not None:
            cluster.close()
