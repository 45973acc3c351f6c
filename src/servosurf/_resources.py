"""Memory and disk a run will need, estimated before anything is allocated.

:func:`check_resources` compares an estimate with what the machine has (available
memory from ``/proc/meminfo``, free space on the output's file system) and refuses,
with one line naming the estimate, the limit and the remedy, when the run would not
fit. The CLI passes ``--force`` through ``force=True`` to try anyway.

The estimates are deliberately simple upper-side figures (bytes per pixel and per
controller sample, measured on the built-in cases); they exist to refuse a
100000 x 100000 grid or a 1 m face at 1 um in a second instead of after an hour.
"""

from __future__ import annotations

import math
import os
import shutil
from pathlib import Path

from .errors import ConfigError

__all__ = [
    "available_memory",
    "free_disk",
    "fmt_bytes",
    "check_resources",
    "SIM_BYTES_PER_PIXEL",
    "SIM_BYTES_PER_SAMPLE",
]

#: Peak memory of ``servosurf simulate`` per grid pixel, in bytes, rounded up: the
#: map, the analysis's form-error, high-pass and filter copies and the figures.
#: Measured (peak RSS, 2026-11-25): 133 B per added pixel with ``--instrument
#: none`` (5 um lenslet, 640 x 480 -> 1280 x 960 px: 370 -> 492 MB), 34 B with the
#: default instrument model, whose camera grid does not grow with the field.
SIM_BYTES_PER_PIXEL = 240
#: Peak memory of ``servosurf simulate`` per controller sample of the deviation
#: record, in bytes, rounded up: command, time, four deviation parts, force,
#: following error, two loop runs of five outputs and the vibration synthesis.
#: Measured: 98 B per added sample (flat_facing, 11.8 M -> 28.7 M samples: 1.93 ->
#: 3.58 GB peak RSS), 163 B per sample overall including the interpreter.
SIM_BYTES_PER_SAMPLE = 240


def available_memory() -> int | None:
    """Memory available to a new allocation, in bytes (None when unknown).

    ``MemAvailable`` of ``/proc/meminfo`` (Linux), else physical memory.
    """
    try:
        with open("/proc/meminfo") as fh:
            for line in fh:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    try:
        return int(os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES"))
    except (AttributeError, ValueError, OSError):
        return None


def free_disk(path: str | Path) -> int | None:
    """Free bytes on the file system that holds ``path`` or its nearest existing
    parent (None when unknown)."""
    p = Path(path).absolute()
    for q in [p, *p.parents]:
        if q.exists():
            try:
                return int(shutil.disk_usage(q).free)
            except OSError:
                return None
    return None


def fmt_bytes(n: float) -> str:
    """``n`` bytes as a short string in kB, MB, GB or TB (powers of 1000)."""
    for unit, scale in (("TB", 1e12), ("GB", 1e9), ("MB", 1e6), ("kB", 1e3)):
        if abs(n) >= scale:
            return f"{n / scale:.3g} {unit}"
    return f"{n:.0f} B"


def check_resources(what: str, *, memory: float = 0.0, disk: float = 0.0,
                    where: str | Path = ".", remedy: str = "",
                    force: bool = False) -> dict:
    """Refuse a run whose memory or disk estimate exceeds what the machine has.

    Parameters
    ----------
    what : str
        The run, as the message names it (e.g. "the 100000 x 100000 px field").
    memory : float, default: 0
        Estimated peak memory, in bytes.
    disk : float, default: 0
        Estimated bytes written under ``where``.
    where : str or Path, default: "."
        Output path (its file system's free space is the disk limit).
    remedy : str, optional
        What to change (flags or TOML keys), appended to the message.
    force : bool, default: False
        Only return the estimate, never refuse (the CLI's ``--force``).

    Returns
    -------
    dict
        ``memory_bytes``, ``memory_available_bytes``, ``disk_bytes``,
        ``disk_free_bytes`` (None where unknown).

    Raises
    ------
    ConfigError
        When an estimate exceeds the limit and ``force`` is False.
    """
    avail = available_memory()
    free = free_disk(where) if disk else None
    out = {"memory_bytes": float(memory), "memory_available_bytes": avail,
           "disk_bytes": float(disk), "disk_free_bytes": free}
    if force:
        return out
    tail = f"; {remedy}" if remedy else ""
    tail += " (or --force to try anyway)"
    if avail is not None and math.isfinite(memory) and memory > avail:
        raise ConfigError(
            f"{what} needs about {fmt_bytes(memory)} of memory, more than the "
            f"{fmt_bytes(avail)} available{tail}"
        )
    if free is not None and disk > free:
        raise ConfigError(
            f"{what} writes about {fmt_bytes(disk)}, more than the "
            f"{fmt_bytes(free)} free on the disk of {where}{tail}"
        )
    return out
