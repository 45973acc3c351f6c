"""Helpers shared by the subcommands: whole-run output folders, JSON, summaries.

Whole runs or nothing
---------------------
A command that writes a folder calls :func:`output_folder` once, where it used to
create ``--out``: it gets a fresh temporary folder beside ``--out`` and writes
everything there. :func:`servosurf.cli.main` calls :func:`commit_outputs` when the
command succeeded, which swaps the temporary folder in place of ``--out`` (the
previous results are removed only then), and :func:`discard_outputs` otherwise, so an
error or an interrupted run leaves the previous results untouched. Paths of the
temporary folder written through :func:`write_json`, :func:`print_json` and
:func:`print_summary` are given as their final paths under ``--out``.

A folder that already holds files servosurf did not write is never replaced (the
command refuses, naming it); a run marks its folder with a ``.servosurf`` file.
"""

from __future__ import annotations

import json
import math
import os
import shutil
import sys
import tempfile
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import numpy as np

from .._atomic import atomic_write

__all__ = [
    "atomic_write",
    "to_jsonable",
    "write_json",
    "out_dir",
    "output_folder",
    "commit_outputs",
    "discard_outputs",
    "print_json",
    "print_summary",
    "fmt_length",
    "check_flags",
]

#: Marker file of a folder written by servosurf (holds the command's name).
MARKER = ".servosurf"
#: Summary files of folders written before the marker existed (still replaceable).
_LEGACY = ("summary.json", "compare.json", "paper.json", "realisations.json")
#: Pending output folders of this run: [(temporary, final)].
_PENDING: list[tuple[Path, Path]] = []


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


def _final(obj: Any) -> Any:
    """``obj`` with paths inside a pending temporary folder given as final paths."""
    if not _PENDING:
        return obj
    if isinstance(obj, dict):
        return {k: _final(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [_final(v) for v in obj]
    if isinstance(obj, str | Path):
        text = str(obj)
        for tmp, final in _PENDING:
            for a, b in ((str(tmp), str(final)), (str(tmp.resolve()),
                                                  str(final.resolve()))):
                if text == a or text.startswith(a + os.sep):
                    return b + text[len(a):]
    return obj


def write_json(path: str | Path, data: Any) -> Path:
    """Write ``data`` as indented JSON atomically (pending paths given as final)."""
    text = json.dumps(to_jsonable(_final(data)), indent=2)
    return atomic_write(path, lambda p: p.write_text(text + "\n"))


def print_json(data: Any) -> None:
    """Print ``data`` as JSON on stdout (pending paths given as final)."""
    print(json.dumps(to_jsonable(_final(data)), indent=2))


def _config_error(msg: str):
    from ..errors import ConfigError

    return ConfigError(msg)


def _check_out_path(p: Path, flag: str) -> None:
    """Refuse an output path below a regular file, or the current folder itself."""
    for parent in [p, *p.parents]:
        if parent.exists() or parent.is_symlink():
            if not parent.is_dir():
                what = "is" if parent == p else f"lies under {parent}, which is"
                raise _config_error(
                    f"{flag} {p}: {what} a file, not a folder; give a folder path"
                )
            break
    here = Path.cwd().resolve()
    target = p.resolve()
    if target == here or target in here.parents:
        raise _config_error(
            f"{flag} {p}: is the current folder (or holds it); give a sub-folder, "
            "e.g. results/run1"
        )


def out_dir(path: str | Path, *, flag: str = "--out") -> Path:
    """Create and return an output folder written in place (no whole-run swap)."""
    p = Path(path)
    _check_out_path(p, flag)
    try:
        p.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise _config_error(f"{flag} {p}: cannot create the folder: "
                            f"{exc.strerror}") from None
    return p


def output_folder(path: str | Path, *, flag: str = "--out") -> Path:
    """A temporary folder beside ``path`` that replaces ``path`` when the run succeeds.

    Parameters
    ----------
    path : str or Path
        The final output folder (``--out``).
    flag : str, default: "--out"
        The flag named in error messages.

    Returns
    -------
    Path
        The temporary folder to write into; :func:`commit_outputs` (called by the
        CLI after a successful command) swaps it in place of ``path``.

    Raises
    ------
    ConfigError
        When ``path`` is a file or lies under one, is the current folder, or is a
        folder holding files that servosurf did not write (it is never replaced).
    """
    final = Path(path)
    _check_out_path(final, flag)
    if final.is_dir():
        names = os.listdir(final)
        ours = MARKER in names or any(n in names for n in _LEGACY)
        if names and not ours:
            shown = ", ".join(sorted(names)[:3]) + (", ..." if len(names) > 3 else "")
            raise _config_error(
                f"{flag} {final}: the folder holds files servosurf did not write "
                f"({shown}); give a new or empty folder (a run replaces its --out "
                "folder whole)"
            )
    parent = final.parent
    try:
        parent.mkdir(parents=True, exist_ok=True)
        tmp = Path(tempfile.mkdtemp(prefix=f".{final.name}.", suffix=".tmp",
                                    dir=parent))
    except OSError as exc:
        raise _config_error(f"{flag} {final}: cannot create a folder in {parent}: "
                            f"{exc.strerror}") from None
    os.chmod(tmp, 0o777 & ~_umask())
    _PENDING.append((tmp, final))
    return tmp


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def commit_outputs(command: str = "") -> list[Path]:
    """Swap every pending temporary folder in place of its final folder.

    The previous folder is renamed aside, the new one renamed in, and the previous
    one removed; both renames happen within one parent folder.

    Parameters
    ----------
    command : str, optional
        Command name recorded in the folder's marker file.

    Returns
    -------
    list of Path
        The final folders written.
    """
    done = []
    while _PENDING:
        tmp, final = _PENDING.pop(0)
        (tmp / MARKER).write_text(f"written by servosurf {command}\n".rstrip() + "\n")
        old = None
        if final.exists():
            old = Path(tempfile.mkdtemp(prefix=f".{final.name}.", suffix=".old",
                                        dir=final.parent))
            os.replace(final, old / final.name)
        os.replace(tmp, final)
        if old is not None:
            shutil.rmtree(old, ignore_errors=True)
        done.append(final)
    return done


def discard_outputs() -> None:
    """Remove every pending temporary folder (the previous results stay)."""
    while _PENDING:
        tmp, _ = _PENDING.pop()
        shutil.rmtree(tmp, ignore_errors=True)


#: Plausible ranges of numeric flags: attribute -> (unit, low, high, typical, what).
FLAG_RANGES = {
    "bandwidth": ("Hz", 1.0, 5e4, 1448.0, "open-loop crossover bandwidth"),
    "bandwidths": ("Hz", 1.0, 5e4, 1448.0, "open-loop crossover bandwidth"),
    "mass": ("kg", 1e-3, 50.0, 0.175, "moving mass m1+m2"),
    "radius": ("m", 1e-5, 1.0, 0.01, "face radius"),
    "pitch": ("m", 1e-9, 1e-3, 1e-6, "grid pitch"),
}


def check_flags(args) -> None:
    """Refuse absurd values of the numeric flags a command has (one line each).

    Each flag of :data:`FLAG_RANGES` present on ``args`` must be finite, > 0 and
    inside its plausible range; the message names the flag, the value, the unit and
    the likely unit slip (``--mass 175`` meant in g).
    """
    from .._validation import check_plausible

    for attr, (unit, low, high, typical, what) in FLAG_RANGES.items():
        value = getattr(args, attr, None)
        if value is None or isinstance(value, bool):
            continue
        flag = "--" + attr.replace("_", "-")
        for v in value if isinstance(value, list | tuple) else [value]:
            if not (math.isfinite(v) and v > 0):
                raise _config_error(f"{flag} must be a positive {what} in {unit}, "
                                    f"got {v!r}")
            check_plausible(v, name=flag, unit=unit, low=low, high=high, what=what,
                            typical=typical)


def fmt_length(value: float | None, unit: str = "nm", digits: int = 3) -> str:
    """A length in m shown in ``unit`` (nm, um or mm) with ``digits`` significant."""
    if value is None or not math.isfinite(value):
        return "n/a"
    scale = {"nm": 1e9, "um": 1e6, "mm": 1e3, "m": 1.0}[unit]
    return f"{value * scale:.{digits}g} {unit}"


def print_summary(args, title: str, rows: list[tuple[str, str]] = (),
                  *, wrote: str | Path | None = None) -> None:
    """Print a command's result on stdout: a title, aligned rows, where it wrote.

    Silent with ``-q`` and with ``--json`` (stdout then holds only the JSON).

    Parameters
    ----------
    args : argparse.Namespace
        The command's arguments (``quiet``, ``json``).
    title : str
        First line.
    rows : list of (label, value)
        The numbers the user came for, each with its unit.
    wrote : str or Path, optional
        The output folder or file (a pending folder is given as its final path).
    """
    if getattr(args, "quiet", False) or getattr(args, "json", False):
        return
    lines = [title]
    width = max((len(k) for k, _ in rows), default=0)
    lines += [f"  {k:<{width}}  {v}" for k, v in rows]
    if wrote is not None:
        wrote = Path(wrote)
        names = (sorted(n for n in os.listdir(wrote) if not n.startswith("."))
                 if wrote.is_dir() else [])
        shown = f" ({', '.join(names)})" if names else ""
        lines.append(f"wrote {_final(wrote)}{os.sep if names else ''}{shown}")
    print("\n".join(lines))
    sys.stdout.flush()


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
                               processes=True, dashboard_address=":0")  # any free port
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
