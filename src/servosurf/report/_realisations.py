"""Many vibration realisations of one run: per-seed metrics and their spread.

:func:`realisation_study` simulates the run once per seed of the vibration
realisation (:func:`servosurf.simulation.simulate`) and analyses each map
(:func:`servosurf.report.analyse`), in this process or one dask task per seed.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .._defaults import defaults_override, malloc_reuse
from ..errors import ConfigError
from ..run import RunConfig, load_run

__all__ = [
    "realisation_study",
    "RealisationStudy",
    "REALISATION_METRICS",
    "LINE_TOLERANCE",
    "match_lines",
]


#: Scalar metrics of :func:`realisation_study`, each in SI (m, s, N).
REALISATION_METRICS = (
    "form_error_max_m",
    "form_error_rim_max_m",
    "form_error_rms_m",
    "ra_m",
    "sa_m",
    "sq_m",
    "deviation_max_m",
    "deviation_overshoot_m",
)


@dataclass(frozen=True, eq=False)
class RealisationStudy:
    """Metrics of one simulation per seed of the vibration realisation.

    Attributes
    ----------
    seeds : ndarray of int64, shape (k,)
        The seeds, one realisation each.
    metrics : dict of str to ndarray of shape (k,)
        Per seed, the scalar metrics of :data:`REALISATION_METRICS` (SI; NaN where
        the analysis has none, e.g. no form error on a flat face) and
        ``peak1_per_m`` / ``peak2_per_m``, the frequencies (1/m) of the two
        strongest spectral lines, matched by frequency across the seeds (NaN for a
        seed without that line; see :func:`match_lines`).
    """

    seeds: np.ndarray
    metrics: dict

    def statistics(self) -> dict:
        """Per metric: mean, standard deviation (ddof=1), min, 5th/50th/95th
        percentile and max over the realisations, in the metric's SI unit."""
        out = {}
        for k, v in self.metrics.items():
            v = v[np.isfinite(v)]
            if v.size == 0:
                continue
            out[k] = {
                "mean": float(v.mean()),
                "std": float(v.std(ddof=1)) if v.size > 1 else 0.0,
                "min": float(v.min()),
                "p5": float(np.percentile(v, 5)),
                "median": float(np.median(v)),
                "p95": float(np.percentile(v, 95)),
                "max": float(v.max()),
            }
        return out

    def to_dict(self) -> dict:
        """JSON-ready dictionary (SI units)."""
        return {
            "seeds": self.seeds.tolist(),
            "realisations": {k: v.tolist() for k, v in self.metrics.items()},
            "statistics": self.statistics(),
        }

    def plot(self, path: str | Path) -> Path:
        """Write the per-seed metrics as strip plots (mean, 5-95 % band) to a PNG.

        Parameters
        ----------
        path : str or Path
            Destination PNG file.

        Returns
        -------
        Path
            The written file.
        """
        from ..viz import plot_realisations

        return plot_realisations(self.seeds, self.metrics, path)


def _realisation_metrics(toolpath, run: RunConfig, seed: int, hooks=()) -> dict:
    """One task of :func:`realisation_study`: simulate with ``seed``, analyse.

    Quiet (no progress lines) and with freed large blocks kept for reuse while it
    runs (:func:`servosurf._defaults.malloc_reuse`: dask's nanny starts workers with
    ``MALLOC_TRIM_THRESHOLD_=65536``, so every realisation would otherwise
    page-fault its buffers in again); both knobs are restored afterwards.
    """
    from ..simulation import simulate
    from ._simulation import analyse

    with defaults_override(quiet=True), malloc_reuse():
        res = simulate(toolpath, run.replace(seed=int(seed)), hooks=hooks)
        analysis = analyse(res)
    summary = analysis.summary
    out = {}
    for k in REALISATION_METRICS:
        v = summary.get(k)
        out[k] = float("nan") if v is None else float(v)
    found = analysis.plot_data.get("spectrum", (None, None, []))[2]
    out["_peaks"] = [(float(q["freq_per_m"]), float(q.get("psd_m3", 1.0)))
                     for q in found or []]
    return out


#: Peaks of two realisations within this relative distance are the same line.
LINE_TOLERANCE = 0.05


def match_lines(peaks: list[list[tuple[float, float]]], n_lines: int = 2) -> dict:
    """Per-seed frequencies of the same spectral lines, matched by frequency.

    The peaks of all seeds are grouped into lines (a peak joins a line whose median
    frequency lies within :data:`LINE_TOLERANCE`); lines found in at least half of
    the seeds are ranked by their median PSD, strongest first. ``peak{k}_per_m`` of
    a seed is its peak on line k (NaN when that seed has none), so the statistics
    average one line, not whichever peak came second in each seed.
    """
    lines: list[dict] = []  # {"f": [...], "p": [...], "seeds": [...]}
    flat = sorted((f, p, i) for i, pk in enumerate(peaks) for f, p in pk)
    for f, p, i in flat:
        near = [ln for ln in lines
                if abs(f - np.median(ln["f"])) <= LINE_TOLERANCE * f and i not in
                ln["seeds"]]
        if near:
            near[0]["f"].append(f)
            near[0]["p"].append(p)
            near[0]["seeds"].append(i)
        else:
            lines.append({"f": [f], "p": [p], "seeds": [i]})
    k = len(peaks)
    common = [ln for ln in lines if 2 * len(ln["seeds"]) >= k]
    common.sort(key=lambda ln: -float(np.median(ln["p"])))
    out = {}
    for j in range(n_lines):
        col = np.full(k, np.nan)
        if j < len(common):
            for f, i in zip(common[j]["f"], common[j]["seeds"], strict=True):
                col[i] = f
        out[f"peak{j + 1}_per_m"] = col
    return out


def realisation_study(toolpath, run: RunConfig | str | None = None, *,
                      seeds: Sequence[int], client=None, progress=None,
                      **kwargs) -> RealisationStudy:
    """Simulate once per seed of the vibration realisation and collect the metrics.

    Parameters
    ----------
    toolpath : ToolpathSpec, str or Path
        As for :func:`~servosurf.simulation.simulate` (a path is read once, here).
    run : RunConfig or str, optional
        The run's settings (a :class:`~servosurf.run.RunConfig`, a preset name or a
        run TOML file); its seed is replaced by each of ``seeds``.
    seeds : sequence of int
        Seeds (>= 0) of the vibration realisation and the instrument noise.
    client : distributed.Client, optional
        One dask task per seed on this cluster (the same values as in-process);
        default: in this process.
    progress : callable, optional
        Wraps the finished realisations, called as ``progress(it, total=k)``.
    **kwargs
        Settings that replace the run's, as keywords of
        :func:`~servosurf.simulation.simulate` (machine, workpiece, bandwidth,
        mass, parts, instrument, n_threads, hooks), except ``seed``.

    Returns
    -------
    RealisationStudy
        Per-seed metrics and their statistics: how much the form error, Ra/Sa
        and the spectral peaks vary from one vibration realisation to the next.

    Raises
    ------
    ConfigError
        On an empty or invalid seed list, or what :func:`simulate` raises.
    TypeError
        On a keyword :func:`simulate` does not take.
    """
    import functools

    from .._tasks import map_tasks
    from ..toolpath import ToolpathSpec, load_toolpath

    if "seed" in kwargs:
        raise ConfigError("realisation_study takes seeds=, not seed=")
    allowed = ("machine", "workpiece", "bandwidth", "mass", "parts", "instrument",
               "n_threads", "hooks")
    bad = [k for k in kwargs if k not in allowed]
    if bad:
        raise TypeError(f"realisation_study() got an unexpected keyword argument "
                        f"{bad[0]!r}")
    if "parts" in kwargs and kwargs["parts"] is not None:
        kwargs["parts"] = tuple(kwargs["parts"])
    hooks = tuple(kwargs.pop("hooks", None) or ())
    cfg = load_run(run).with_overrides(**kwargs)
    seeds = [int(s) for s in seeds]
    if not seeds or min(seeds) < 0:
        raise ConfigError(
            f"seeds must be a non-empty list of integers >= 0, got {seeds}")
    spec = toolpath if isinstance(toolpath, ToolpathSpec) else load_toolpath(toolpath)
    task = functools.partial(_realisation_metrics, spec, cfg, hooks=hooks)
    rows = map_tasks(task, seeds, client=client, progress=progress)
    peaks = [r.pop("_peaks") for r in rows]
    metrics = {k: np.array([r[k] for r in rows], dtype=float) for k in rows[0]}
    metrics.update(match_lines(peaks))
    return RealisationStudy(np.array(seeds, dtype=np.int64), metrics)
