"""The whole simulation: toolpath -> servo/force/vibration deviation -> kernel -> map.

:func:`simulate` runs the stages in order:

1. **Toolpath** (:mod:`servosurf.toolpath`): the commanded tool height ``z_cmd(t)``
   at the controller rate over the time span that can cut the field (plus a settling
   pre-roll).
2. **Deviation**, each part switchable (``parts``):

   * ``tracking``: ``z_cmd`` through the exact discrete closed loop (the 100 Hz
     overshoot);
   * ``force``: the thrust force ``k_t A(z)`` from the uncut chip section, computed
     each sample from the actual, deviated tool position, through the loop (the
     difference of two loop runs with and without cutting);
   * ``vibration``: a seeded realisation of the real positioning error spectrum
     (sensor noise, current noise and base vibration through the closed loop,
     including the structural modes).

   The parts add (the loop is linear; the chip force is computed inside the loop).
   Hooks may add further terms outside the loop (``path_z``).
3. **Kernel** (:func:`servosurf.toolpath.sweep`): the exact lower envelope of the
   tool's nose arc in the radial-axial plane, on the field's grid.
4. **Instrument** (optional): an interferometer model (resampling, optical blur,
   slope dropout, height noise).

A *hook* is any object with any of the optional methods ``machine(machine) ->
Machine``, ``tool(tool) -> Tool``, ``path_z(t, theta, r, z_cmd) -> dz`` (m) and
``surface(surface, context) -> Surface``; the discrepancy catalogue plugs its
effects in this way.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from . import _progress
from .cutting._force import ChipModel, Workpiece, facing_chip_area, load_workpiece
from .errors import ConfigError
from .metrology._surface import Surface
from .servo._loop import ServoLoop
from .servo._machine import Machine, load_machine

__all__ = [
    "simulate",
    "SimulationResult",
    "realisation_study",
    "RealisationStudy",
    "PARTS",
    "SETTLE_TIME",
]

#: Deviation parts that can be switched on and off.
PARTS = ("tracking", "force", "vibration")
#: Pre-roll before the first sample that can cut the field, in s (loop settling).
SETTLE_TIME = 0.05
#: Refuse a continuous time span longer than this many samples (memory guard).
MAX_SPAN_SAMPLES = 40_000_000


@dataclass(frozen=True, eq=False)
class SimulationResult:
    """Everything a simulation produced (SI units).

    Attributes
    ----------
    surface : Surface
        The machined height map on the field grid (m), before any instrument model.
    measured : Surface or None
        The map as the interferometer model reports it (m, NaN invalid).
    t : ndarray of shape (n,)
        Times of the continuous deviation record, s.
    z_command : ndarray of shape (n,)
        Commanded tool height, m.
    deviation : dict of str to ndarray of shape (n,)
        Tool-height deviation per part (``tracking``, ``force``, ``vibration``,
        ``hooks``), m; their sum is added to the commanded path.
    force : ndarray of shape (n,)
        Thrust force on the tool, N.
    following_error : ndarray of shape (n,)
        Following error the controller reports (deterministic parts plus the
        vibration realisation's following error), m.
    machine : Machine
        The machine used (after mass, bandwidth and hooks).
    spec : object
        The toolpath specification.
    workpiece : Workpiece
        The workpiece.
    settings : dict
        JSON-ready settings (seed, parts, bandwidth, mass, files).
    """

    surface: Surface
    measured: Surface | None
    t: np.ndarray
    z_command: np.ndarray
    deviation: dict[str, np.ndarray]
    force: np.ndarray
    following_error: np.ndarray
    machine: Machine
    spec: Any
    workpiece: Workpiece
    settings: dict[str, Any] = field(default_factory=dict)

    @property
    def total_deviation(self) -> np.ndarray:
        """Sum of all deviation parts, m."""
        return sum(self.deviation.values())  # type: ignore[return-value]


def _reach(spec, tool) -> float:
    """Radial reach (m) of the tool arc below the pre-cut face."""
    from .toolpath import field_reach

    return field_reach(tool, spec.path.depth_of_cut)  # + 1 um margin for deviations


def _span(spec, tool) -> tuple[float, float]:
    """Time interval (s) during which the tool can cut the field."""
    reach = _reach(spec, tool)
    rlo, rhi = spec.field.radial_range()
    span = spec.path.time_span_for_radius(max(rlo - reach, 0.0), rhi + reach)
    if span is None:
        raise ConfigError(
            f"the toolpath never reaches the field (field radii {rlo:g}..{rhi:g} m); "
            "move [field] center-x/center-y onto the path"
        )
    return span


def simulate(
    toolpath,
    *,
    machine: Machine | str | Path | None = None,
    workpiece: Workpiece | str | Path | None = None,
    bandwidth: float | None = None,
    mass: float | None = None,
    seed: int = 0,
    parts: Sequence[str] = PARTS,
    instrument=None,
    hooks: Sequence[Any] = (),
    n_threads: int | None = None,
) -> SimulationResult:
    """Simulate the surface an FTS cuts, as the toolpath file describes it.

    Parameters
    ----------
    toolpath : ToolpathSpec, str or Path
        Toolpath specification or TOML file.
    machine : Machine, str or Path, optional
        Machine or machine file / built-in name (default: the seed prototype).
    workpiece : Workpiece, str or Path, optional
        Workpiece or file (default: electroless NiP, flat pre-cut face).
    bandwidth : float, optional
        Crossover bandwidth in Hz (default: the machine's).
    mass : float, optional
        Moving mass m1 + m2 in kg (default: the machine's).
    seed : int, default: 0
        Seed of the vibration realisation and the instrument noise.
    parts : sequence of str, default: ("tracking", "force", "vibration")
        Deviation parts to include (any subset of :data:`PARTS`).
    instrument : Interferometer, str or None, optional
        Interferometer model applied to the machined map (None: no measurement model).
    hooks : sequence, optional
        Extra model terms (see the module docstring).
    n_threads : int, optional
        Numba threads for the kernel.

    Returns
    -------
    SimulationResult
        The map, the deviations and the settings.
    """
    from .noise._synthesis import realise
    from .toolpath import ToolpathSpec, check_clearance, load_toolpath, sample, sweep

    bad = [p for p in parts if p not in PARTS]
    if bad:
        raise ConfigError(
            f"unknown deviation part {bad[0]!r}; allowed: {', '.join(PARTS)}"
        )
    if not isinstance(seed, int | np.integer) or seed < 0:
        raise ConfigError(f"seed must be a non-negative integer, got {seed!r}")
    spec = toolpath if isinstance(toolpath, ToolpathSpec) else load_toolpath(toolpath)
    if not isinstance(machine, Machine):
        machine = load_machine(machine)
    if mass is not None:
        machine = machine.with_moving_mass(mass)
    if bandwidth is not None:
        machine = machine.with_bandwidth(bandwidth)
    if not isinstance(workpiece, Workpiece):
        workpiece = load_workpiece(workpiece)
    tool = spec.tool
    for h in hooks:
        if hasattr(h, "machine"):
            machine = h.machine(machine)
        if hasattr(h, "tool"):
            tool = h.tool(tool)
    if tool is not spec.tool:
        spec = dataclasses.replace(spec, tool=tool)
    fs = machine.controller.sample_rate

    with _progress.stage("servo loop"):
        loop = ServoLoop(machine)
        if not loop.is_stable():
            raise ConfigError(
                f"the loop is unstable at {machine.controller.bandwidth:g} Hz with "
                f"{machine.mechanics.moving_mass:g} kg; lower --bandwidth"
            )

    t0, t1 = _span(spec, tool)
    k0 = max(int(np.floor((t0 - SETTLE_TIME) * fs)), 0)
    k1 = int(np.ceil(t1 * fs)) + 2
    n = k1 - k0
    if n > MAX_SPAN_SAMPLES:
        raise ConfigError(
            f"the field needs {n} controller samples ({n / fs:.1f} s of cutting), more "
            f"than {MAX_SPAN_SAMPLES}; use a smaller field or the tiled whole-part run"
        )
    t = (k0 + np.arange(n)) / fs
    z_cmd = spec.path.z_at(t)

    with _progress.stage(f"deviation ({', '.join(parts) or 'none'}) over {n} samples"):
        dev: dict[str, np.ndarray] = {}
        tracking = "tracking" in parts
        ref = z_cmd if tracking else np.zeros(n)
        offset = None if tracking else z_cmd
        base = loop.simulate(reference=ref)
        dev["tracking"] = (base["tool"] - z_cmd) if tracking else np.zeros(n)
        force = np.zeros(n)
        # copies: the loop outputs are views of one (5, n) buffer, freed below
        fol = base["following_error"].copy()
        if "force" in parts:
            kt = workpiece.material.specific_thrust_pressure
            top = workpiece.precut.height
            if spec.kind == "lenslet":
                cut = loop.simulate(
                    reference=ref,
                    chip=ChipModel(kt, tool.nose_radius, top),
                    chip_offset=offset,
                )
            else:  # facing: steady feed-limited chip, ramped in over one revolution
                p = spec.path
                area = facing_chip_area(
                    tool.nose_radius, p.feed_per_rev, p.depth_of_cut
                )
                ramp = np.clip((t - t[0]) * p.rev_per_s, 0.0, 1.0)
                cut = loop.simulate(reference=ref, force=kt * area * ramp)
            dev["force"] = cut["tool"] - base["tool"]
            force = cut["force"].copy()
            fol = cut["following_error"].copy()
            del cut
        else:
            dev["force"] = np.zeros(n)
        del base
        if "vibration" in parts:
            real = realise(loop, int(n), seed=int(seed))
            dev["vibration"] = real.tool
            fol += real.following
        else:
            dev["vibration"] = np.zeros(n)
        extra = np.zeros(n)
        for h in hooks:
            if hasattr(h, "path_z"):
                theta, radius = spec.path.theta_at(t), spec.path.radius_at(t)
                extra = extra + np.asarray(
                    h.path_z(t, theta, radius, z_cmd), dtype=float
                )
        dev["hooks"] = extra

    with _progress.stage("toolpath samples over the field"):
        path = sample(
            spec, fs=fs, field=spec.field, tool=tool, reach=_reach(spec, tool)
        )
        idx = path.index - k0
        if idx.size and (idx.min() < 0 or idx.max() >= n):
            raise ConfigError("internal: the deviation record does not cover the field")
        total = sum(dev.values())
        path = dataclasses.replace(path, z=path.z + total[idx])
        check_clearance(path, tool)

    with _progress.stage(f"kernel on {spec.field.ny} x {spec.field.nx} grid"):
        initial = None
        if workpiece.precut.kind == "flat":
            initial = float(workpiece.precut.height)
        else:
            from .io import read_surface

            initial = read_surface(workpiece.precut.file)
        surface = sweep(path, tool, spec.field, initial=initial, n_threads=n_threads)

    ctx = {
        "spec": spec,
        "machine": machine,
        "t": t,
        "z_command": z_cmd,
        "deviation": dev,
        "force": force,
        "seed": seed,
    }
    for h in hooks:
        if hasattr(h, "surface"):
            surface = h.surface(surface, ctx)

    settings = {
        "toolpath_kind": spec.kind,
        "seed": int(seed),
        "parts": list(parts),
        "bandwidth_hz": machine.controller.bandwidth,
        "bandwidth_definition": "open-loop crossover",
        "moving_mass_kg": machine.mechanics.moving_mass,
        "machine": machine.name,
        "disturbances": machine.disturbances.name,
        "workpiece": workpiece.name,
        "specific_thrust_pressure_pa": workpiece.material.specific_thrust_pressure,
        "controller_rate_hz": fs,
        "hooks": [type(h).__name__ for h in hooks],
    }
    surface = surface.replace(metadata={**surface.metadata, "simulation": settings})
    measured = None
    if instrument is not None:
        with _progress.stage("interferometer model"):
            from .metrology._interferometer import load_instrument, measure

            inst = (
                load_instrument(instrument)
                if isinstance(instrument, str | dict)
                else instrument
            )
            measured = measure(surface, inst, seed=int(seed))
    return SimulationResult(
        surface=surface,
        measured=measured,
        t=t,
        z_command=z_cmd,
        deviation=dev,
        force=force,
        following_error=fol,
        machine=machine,
        spec=spec,
        workpiece=workpiece,
        settings=settings,
    )


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
        ``peak1_per_m`` / ``peak2_per_m``, the two strongest spectral peaks (1/m).
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


def _realisation_metrics(toolpath, kwargs: dict, seed: int) -> dict:
    """One task of :func:`realisation_study`: simulate with ``seed``, analyse.

    Keeps freed large blocks for reuse (:func:`~servosurf.scale.reuse_freed_memory`):
    dask's nanny starts workers with ``MALLOC_TRIM_THRESHOLD_=65536``, so every
    realisation would otherwise page-fault its buffers in again.
    """
    from .report._simulation import analyse
    from .scale._memory import reuse_freed_memory

    reuse_freed_memory()
    quiet = _progress.is_quiet()
    _progress.set_quiet(True)
    try:
        res = simulate(toolpath, seed=int(seed), **kwargs)
        summary = analyse(res)
    finally:
        _progress.set_quiet(quiet)
    out = {}
    for k in REALISATION_METRICS:
        v = summary.get(k)
        out[k] = float("nan") if v is None else float(v)
    peaks = list(summary.get("spectrum_peaks_per_m") or [])
    for i in (0, 1):
        out[f"peak{i + 1}_per_m"] = float(peaks[i]) if len(peaks) > i else float("nan")
    return out


def realisation_study(toolpath, *, seeds: Sequence[int], client=None, progress=None,
                      **kwargs) -> RealisationStudy:
    """Simulate once per seed of the vibration realisation and collect the metrics.

    Parameters
    ----------
    toolpath : ToolpathSpec, str or Path
        As for :func:`simulate` (a path is read once, here).
    seeds : sequence of int
        Seeds (>= 0) of the vibration realisation and the instrument noise.
    client : distributed.Client, optional
        One dask task per seed on this cluster (the same values as in-process);
        default: in this process.
    progress : callable, optional
        Wraps the finished realisations, called as ``progress(it, total=k)``.
    **kwargs
        Passed to :func:`simulate` (machine, workpiece, bandwidth, mass, parts,
        instrument, ...), except ``seed``.

    Returns
    -------
    RealisationStudy
        Per-seed metrics and their statistics: how much the form error, Ra/Sa
        and the spectral peaks vary from one vibration realisation to the next.

    Raises
    ------
    ConfigError
        On an empty or invalid seed list, or what :func:`simulate` raises.
    """
    import functools

    from .scale._tasks import map_tasks
    from .toolpath import ToolpathSpec, load_toolpath

    if "seed" in kwargs:
        raise ConfigError("realisation_study takes seeds=, not seed=")
    seeds = [int(s) for s in seeds]
    if not seeds or min(seeds) < 0:
        raise ConfigError(
            f"seeds must be a non-empty list of integers >= 0, got {seeds}")
    spec = toolpath if isinstance(toolpath, ToolpathSpec) else load_toolpath(toolpath)
    task = functools.partial(_realisation_metrics, spec, kwargs)
    rows = map_tasks(task, seeds, client=client, progress=progress)
    metrics = {k: np.array([r[k] for r in rows], dtype=float) for k in rows[0]}
    return RealisationStudy(np.array(seeds, dtype=np.int64), metrics)
