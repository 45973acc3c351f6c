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
     difference of two loop runs with and without cutting); for facing and design
     surfaces the steady facing chip at the (local) feed per revolution;
   * ``vibration``: a seeded realisation of the real positioning error spectrum
     (sensor noise, current noise and base vibration through the closed loop,
     including the structural modes).

   The parts add (the loop is linear; the chip force is computed inside the loop).
   Hooks may add further terms outside the loop (``path_z``). Parts beyond the
   loop (off by default, :mod:`servosurf._parts`): ``out-of-loop`` (frame motion
   that bypasses the loop when the sensor targets the FTS base) and ``spindle``
   (asynchronous spindle axial error) add to the tool height; ``ploughing``,
   ``side-flow`` and ``recovery`` switch the kernel to the time-ordered sweep
   with material rules.
3. **Kernel** (:func:`servosurf.toolpath.sweep`): the exact lower envelope of the
   tool's nose arc in the radial-axial plane, on the field's grid.
4. **Instrument** (optional): an interferometer model (resampling, optical blur,
   slope dropout, height noise).

A *hook* is any object with any of the optional methods of the protocol in
:mod:`servosurf._hooks`: ``machine(machine) -> Machine``, ``workpiece(workpiece) ->
Workpiece``, ``tool(tool) -> Tool``, ``path_z(t, theta, r, z) -> dz`` (m; ``z`` the
deterministic tool height the loop delivers),
``surface(surface, context) -> Surface``, and for the FTS loop itself
``perturbation() -> LoopPerturbation`` (plant change under the installed
controller), ``nonlinearity() -> dict`` (fields of
:class:`servosurf.servo.Nonlinearity`) and ``base_lines()`` (deterministic base
sinusoids ``(frequency, amplitude)``, through the loop from zero phase). The
discrepancy catalogue's fitted terms are hooks
(``simulate(spec, hooks=diagnosis.model.hooks())``).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from . import _hooks, _parts, _progress
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
    "KINEMATIC",
    "DEFAULT_PARTS",
    "SETTLE_TIME",
]

#: Model parts that can be switched on and off: the servo loop's deviations, then
#: (issue 18) the terms outside the loop and the material rules of the sweep.
PARTS = _parts.ALL_PARTS
#: Parts of a default simulation on the FTS (the servo loop's deviations).
DEFAULT_PARTS = _parts.LOOP_PARTS
#: The commanded path alone (no loop, no axis dynamics); not combined with PARTS.
KINEMATIC = "kinematic"
#: Default machine of NC programs: ideal machine axes (a kinematic run).
NC_MACHINE = "sts-ideal-axes"
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
        ``hooks``, and ``out-of-loop``/``spindle`` when switched on), m; their sum
        is added to the commanded path.
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
    """Radial reach (m) of the tool arc below the pre-cut face (the whole arc for
    paths without a depth of cut, such as NC programs)."""
    from .toolpath import field_reach

    # + 1 um margin for deviations (a design path's deepest point may be far
    # below its datum)
    return field_reach(tool, getattr(spec.path, "max_depth", None))


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


def _kernel_field(spec):
    """The field in the sweep kernel's frame (mirrored for some NC paths)."""
    kf = getattr(spec.path, "kernel_field", None)
    return spec.field if kf is None else kf(spec.field)


def _initial(spec, workpiece):
    """Pre-cut height for the sweep: the workpiece's, or no material limit (+inf)
    for an NC program on a flat workpiece (a curved part's blank lies above the
    path; the surface is the lower envelope of every cutting block)."""
    if workpiece.precut.kind == "flat":
        if spec.kind == "nc":
            return np.inf
        return float(workpiece.precut.height)
    from .io import read_surface

    return read_surface(workpiece.precut.file)


def _physical(spec, surface):
    """Undo the kernel frame (mirror) and mark never-cut pixels (+inf) as NaN."""
    unmirror = getattr(spec.path, "unmirror", None)
    if unmirror is None:
        return surface
    surface = unmirror(surface)
    z = surface.z
    if np.isinf(z).any():
        surface = surface.replace(z=np.where(np.isinf(z), np.nan, z))
    return surface


def _design_force(path, tool, kt: float, t: np.ndarray) -> np.ndarray:
    """Thrust force (N) of a design-surface finishing pass at times ``t`` (s).

    The pre-form is taken to follow the design ``path.depth_of_cut`` higher, so the
    chip is the steady facing chip at the local feed per revolution (planned feeds
    vary with radius), ramped in over the record's first revolution.
    """
    feed = path.feed_at(t)
    levels = np.unique(feed)
    if levels.size > 64:
        levels = np.linspace(levels[0], levels[-1], 64)
    area = [facing_chip_area(tool.nose_radius, f, path.depth_of_cut) for f in levels]
    ramp = np.clip((t - t[0]) * path.rev_per_s, 0.0, 1.0)
    return kt * np.interp(feed, levels, area) * ramp


def _check_nyquist(spec, fs: float) -> None:
    """Refuse a toolpath motion frequency the controller cannot represent."""
    f = getattr(spec.path, "frequency", None)
    if f is not None and f >= fs / 2:
        raise ConfigError(
            f"{spec.kind}.frequency = {f:g} Hz is at or above the controller's "
            f"Nyquist frequency {fs / 2:g} Hz (controller.sample-rate {fs:g} Hz): the "
            "servo cannot follow it; FTS frequencies are Hz to a few kHz"
        )


def simulate(
    toolpath,
    *,
    machine: Machine | str | Path | None = None,
    workpiece: Workpiece | str | Path | None = None,
    bandwidth: float | None = None,
    mass: float | None = None,
    seed: int = 0,
    parts: Sequence[str] | None = None,
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
        Machine or machine file / built-in name (default: the seed prototype; for
        NC programs ``sts-ideal-axes``, ideal machine axes).
    workpiece : Workpiece, str or Path, optional
        Workpiece or file (default: electroless NiP, flat pre-cut face).
    bandwidth : float, optional
        Crossover bandwidth in Hz (default: the machine's).
    mass : float, optional
        Moving mass m1 + m2 in kg (default: the machine's).
    seed : int, default: 0
        Seed of the vibration realisation and the instrument noise.
    parts : sequence of str, optional
        Model parts to include: any subset of :data:`PARTS` (default:
        :data:`DEFAULT_PARTS` for the FTS; ``("tracking", "vibration")`` for an NC
        program on the FTS; ``("tracking",)`` on a second-order axis), or
        ``("kinematic",)``: the commanded path alone, swept at its own resolution
        (NC programs: the block end points) without the loop.
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
    from .toolpath import ToolpathSpec, check_clearance, load_toolpath, sample

    if parts is not None:
        parts = tuple(parts)
        bad = [p for p in parts if p not in (*PARTS, KINEMATIC)]
        if bad:
            raise ConfigError(
                f"unknown deviation part {bad[0]!r}; allowed: {', '.join(PARTS)} "
                f"or {KINEMATIC} alone"
            )
        if KINEMATIC in parts and len(parts) > 1:
            raise ConfigError(
                f"part {KINEMATIC!r} is the commanded path alone; it cannot be "
                f"combined with {', '.join(p for p in parts if p != KINEMATIC)}")
    if not isinstance(seed, int | np.integer) or seed < 0:
        raise ConfigError(f"seed must be a non-negative integer, got {seed!r}")
    spec = toolpath if isinstance(toolpath, ToolpathSpec) else load_toolpath(toolpath)
    if machine is None and spec.kind == "nc":
        machine = NC_MACHINE
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
        if hasattr(h, "workpiece"):
            workpiece = h.workpiece(workpiece)
    if tool is not spec.tool:
        spec = dataclasses.replace(spec, tool=tool)
    # hooks on the FTS loop itself (the diagnosis's fitted loop effects)
    pert = _hooks.compose_perturbation(hooks)
    nonlin = _hooks.compose_nonlinearity(hooks)
    lines = _hooks.compose_base_lines(hooks)
    if (parts is not None and KINEMATIC in parts) or machine.axis.model != "fts":
        if pert is not None or nonlin is not None or lines:
            raise ConfigError(
                "hooks with perturbation(), nonlinearity() or base_lines() act on "
                "the FTS servo loop; allowed only on an FTS machine without the "
                f"{KINEMATIC!r} part")
        from ._simulate_axes import simulate_axes

        return simulate_axes(spec, tool, machine, workpiece, parts, seed=int(seed),
                             instrument=instrument, hooks=hooks, n_threads=n_threads)
    if parts is None:
        parts = ("tracking", "vibration") if spec.kind == "nc" else DEFAULT_PARTS
    if spec.kind == "nc" and "force" in parts:
        raise ConfigError(
            "the cutting-force part needs the chip of a facing or lenslet path; for "
            "an NC program use parts tracking and vibration, or kinematic")
    fs = machine.controller.sample_rate
    _check_nyquist(spec, fs)

    with _progress.stage("servo loop"):
        # the installed controller on the (hook-perturbed) plant
        loop = ServoLoop(machine).perturbed(pert)
        if not loop.is_stable():
            raise ConfigError(
                f"the loop is unstable at {machine.controller.bandwidth:g} Hz with "
                f"{machine.mechanics.moving_mass:g} kg; lower --bandwidth"
            )

    t0, t1 = _span(spec, tool)
    k0 = int(np.floor((t0 - SETTLE_TIME) * fs))
    if spec.kind != "nc":  # an NC path holds its first point before t = 0
        k0 = max(k0, 0)
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
        base = loop.simulate(reference=ref, nonlinearity=nonlin)
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
                    nonlinearity=nonlin,
                )
            elif spec.kind == "surface":  # finishing pass: facing chip, local feed
                cut = loop.simulate(
                    reference=ref, force=_design_force(spec.path, tool, kt, t),
                    nonlinearity=nonlin,
                )
            else:  # facing: steady feed-limited chip, ramped in over one revolution
                p = spec.path
                area = facing_chip_area(
                    tool.nose_radius, p.feed_per_rev, p.depth_of_cut
                )
                ramp = np.clip((t - t[0]) * p.rev_per_s, 0.0, 1.0)
                cut = loop.simulate(reference=ref, force=kt * area * ramp,
                                    nonlinearity=nonlin)
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
        # parts outside the loop (issue 18): out-of-loop frame motion, spindle error
        dev.update(_parts.outside_loop(loop, parts, n, seed))
        extra = np.zeros(n)
        if any(hasattr(h, "path_z") for h in hooks):
            # the deterministic tool height the loop delivers (command plus its
            # tracking and force deviations): what a term outside the loop, e.g.
            # a sensor's nonlinear reading of the actual position, depends on
            z_loop = z_cmd + dev["tracking"] + dev["force"]
            theta, radius = spec.path.theta_at(t), spec.path.radius_at(t)
            for h in hooks:
                if hasattr(h, "path_z"):
                    extra = extra + np.asarray(
                        h.path_z(t, theta, radius, z_loop), dtype=float
                    )
        if lines:
            # deterministic base lines through the loop (steady state)
            f0 = np.array([f for f, _ in lines])
            paths = loop.frf(f0).paths
            for j, (f, a) in enumerate(lines):
                for out, key in ((None, "tool"), ("fol", "following_error")):
                    h_ = paths[("base", key)][j]
                    wave = a * abs(h_) * np.cos(2 * np.pi * f * t + np.angle(h_))
                    if out is None:
                        extra = extra + wave
                    else:
                        fol = fol + wave
        dev["hooks"] = extra

    kfield = _kernel_field(spec)
    with _progress.stage("toolpath samples over the field"):
        path = sample(
            spec, fs=fs, field=kfield, tool=tool, reach=_reach(spec, tool)
        )
        idx = path.index - k0
        if idx.size and (idx.min() < 0 or idx.max() >= n):
            raise ConfigError("internal: the deviation record does not cover the field")
        total = sum(dev.values())
        path = dataclasses.replace(path, z=path.z + total[idx])
        check_clearance(path, tool)

    with _progress.stage(f"kernel on {spec.field.ny} x {spec.field.nx} grid"):
        # material parts (issue 18) switch to the time-ordered sweep
        surface = _parts.machine_surface(path, tool, kfield, _initial(spec, workpiece),
                                         workpiece, parts, n_threads=n_threads)
        surface = _physical(spec, surface)

    ctx = {
        "spec": spec,
        "machine": machine,
        "workpiece": workpiece,
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
        **_parts.part_settings(machine, tool, workpiece, parts),
    }
    if spec.kind == "nc":
        settings["nc"] = spec.path.describe()
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
        ``peak1_per_m`` / ``peak2_per_m``, the frequencies (1/m) of the two
        strongest spectral lines, matched by frequency across the seeds (NaN for a
        seed without that line; see ``_match_lines``).
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
    found = (summary.get("_plots") or {}).get("spectrum", (None, None, []))[2]
    out["_peaks"] = [(float(q["freq_per_m"]), float(q.get("psd_m3", 1.0)))
                     for q in found or []]
    return out


#: Peaks of two realisations within this relative distance are the same line.
LINE_TOLERANCE = 0.05


def _match_lines(peaks: list[list[tuple[float, float]]], n_lines: int = 2) -> dict:
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
    peaks = [r.pop("_peaks") for r in rows]
    metrics = {k: np.array([r[k] for r in rows], dtype=float) for k in rows[0]}
    metrics.update(_match_lines(peaks))
    return RealisationStudy(np.array(seeds, dtype=np.int64), metrics)
