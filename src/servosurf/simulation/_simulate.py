"""The FTS simulation: toolpath -> servo/force/vibration deviation -> kernel -> map.

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
Workpiece``, ``tool(tool) -> Tool`` (and ``tool_at(tool, t) -> Tool``, a tool
changing in time, swept revolution by revolution), ``path_z(t, theta, r, z) -> dz``
(m; ``z`` the deterministic tool height the loop delivers),
``surface(surface, context) -> Surface``, and for the FTS loop itself
``perturbation() -> LoopPerturbation`` (plant change under the installed
controller), ``nonlinearity() -> dict`` (fields of
:class:`servosurf.servo.Nonlinearity`) and ``base_lines()`` (deterministic base
sinusoids ``(frequency, amplitude)``, through the loop from zero phase);
``sensor_lines()`` adds sinusoids to the logged reading only (the following error,
not the surface). The
discrepancy catalogue's fitted terms are hooks
(``simulate(spec, hooks=diagnosis.model.hooks())``).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from .. import _hooks, _parts, _progress
from ..cutting import ChipModel, Workpiece, facing_chip_area, load_workpiece
from ..errors import ConfigError
from ..run import RunConfig, load_run
from ..servo import Machine, ServoLoop
from ._common import (
    DEFAULT_PARTS,
    KINEMATIC,
    MAX_SPAN_SAMPLES,
    NC_MACHINE,
    SimulationResult,
    _initial,
    _kernel_field,
    _measure,
    _physical,
    _reach,
    deviation_samples,
)
from ._timed_tool import has_timed_tool, timed_tool_surface

__all__ = ["simulate", "design_force"]


def design_force(path, tool, kt: float, t: np.ndarray) -> np.ndarray:
    """Thrust force (N) of a design-surface finishing pass at times ``t`` (s).

    The pre-form is taken to follow the design ``path.depth_of_cut`` higher, so the
    chip is the steady facing chip at the local feed per revolution (planned feeds
    vary with radius), ramped in over the record's first revolution (from
    ``t[0]``).

    Parameters
    ----------
    path : DesignToolpath
        The design surface's spiral (its ``feed_at``, ``depth_of_cut`` and
        ``rev_per_s``).
    tool : Tool
        The tool (its nose radius in m).
    kt : float
        Specific thrust pressure in N/m^2.
    t : ndarray of shape (n,)
        Times in s, increasing.

    Returns
    -------
    ndarray of shape (n,)
        Thrust force in N.
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
    run: RunConfig | str | None = None,
    *,
    machine: Machine | str | Path | None = None,
    workpiece: Workpiece | str | Path | None = None,
    bandwidth: float | None = None,
    mass: float | None = None,
    seed: int | None = None,
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
    run : RunConfig or str, optional
        The run's settings (:class:`~servosurf.run.RunConfig`, or a preset name or
        run TOML file, :func:`~servosurf.run.load_run`); default ``RunConfig()``,
        every default below. The keywords below replace its values when given
        (not None).
    machine : Machine, str or Path, optional
        Machine or machine file / built-in name (default: the seed prototype; for
        NC programs ``sts-ideal-axes``, ideal machine axes).
    workpiece : Workpiece, str or Path, optional
        Workpiece or file (default: electroless NiP, flat pre-cut face).
    bandwidth : float, optional
        Crossover bandwidth in Hz (default: the machine's).
    mass : float, optional
        Moving mass m1 + m2 in kg (default: the machine's).
    seed : int, optional
        Seed of the vibration realisation and the instrument noise (default: the
        run's, 0).
    parts : sequence of str, optional
        Model parts to include: any subset of :data:`PARTS` (default:
        :data:`DEFAULT_PARTS` for the FTS; ``("tracking", "vibration")`` for an NC
        program on the FTS; ``("tracking",)`` on a second-order axis), or
        ``("kinematic",)``: the commanded path alone, swept at its own resolution
        (NC programs: the block end points) without the loop.
    instrument : Interferometer, str or None, optional
        Interferometer model applied to the machined map (default: the run's, no
        measurement model; ``"none"`` switches a run's model off).
    hooks : sequence, optional
        Extra model terms (see the module docstring).
    n_threads : int, optional
        Numba threads for the kernel (default: the run's, then
        ``defaults["numba_threads"]``).

    Returns
    -------
    SimulationResult
        The map, the deviations and the settings.
    """
    from ..noise import realise
    from ..toolpath import ToolpathSpec, check_clearance, load_toolpath, sample

    cfg = load_run(run).with_overrides(
        machine=machine, workpiece=workpiece, bandwidth=bandwidth, mass=mass,
        seed=seed, parts=None if parts is None else tuple(parts),
        instrument=instrument, n_threads=n_threads)
    parts, seed, instrument, n_threads = (cfg.parts, cfg.seed, cfg.instrument,
                                          cfg.n_threads)
    spec = toolpath if isinstance(toolpath, ToolpathSpec) else load_toolpath(toolpath)
    machine = cfg.machine_model(default=NC_MACHINE if spec.kind == "nc" else None)
    workpiece = cfg.workpiece
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
        from ._axes import simulate_axes

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

    k0, n = deviation_samples(spec, tool, fs)
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
                    reference=ref, force=design_force(spec.path, tool, kt, t),
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
        for f, a in _hooks.compose_sensor_lines(hooks):
            # pickup in the logged reading only: outside the loop, not on the cut
            # surface (the following error is reference minus reading)
            fol = fol - a * np.cos(2 * np.pi * f * t)
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
        if has_timed_tool(hooks):  # a tool changing in time (wear): by revolution
            surface = timed_tool_surface(
                path, tool, kfield, _initial(spec, workpiece), workpiece, parts,
                hooks, angular_speed=spec.path.angular_speed, n_threads=n_threads)
        else:
            surface = _parts.machine_surface(path, tool, kfield,
                                             _initial(spec, workpiece), workpiece,
                                             parts, hooks=hooks, n_threads=n_threads)
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
    measured = None if instrument is None else _measure(surface, instrument, seed)
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
