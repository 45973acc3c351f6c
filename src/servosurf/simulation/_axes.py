"""Simulation without the FTS loop: the commanded path, or a machine axis model.

Called by :func:`servosurf.simulation.simulate` for ``parts=("kinematic",)`` and for
machines whose ``[axis] model`` is not ``"fts"`` (see :mod:`servosurf.servo._axis`).

* **Kinematic** (``parts=("kinematic",)`` or ``model = "none"``): the commanded path
  is swept as it is. An NC program is sampled at its block end points (exact for the
  machine's linear block interpolation, :meth:`BlockPath.vertex_samples`); the
  analytic facing and lenslet paths at the controller rate.
* **Second-order axis** (``model = "second-order"``): the commanded height sampled at
  ``axis.sample_rate`` over the time that can cut the field (plus a settling
  pre-roll), through the axis's response; the difference is the ``tracking``
  deviation added to the path before the sweep.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from .. import _parts, _progress
from ..errors import ConfigError
from ..toolpath import check_clearance, sample
from ._common import (
    KINEMATIC,
    MAX_SPAN_SAMPLES,
    SETTLE_TIME,
    SimulationResult,
    _initial,
    _kernel_field,
    _measure,
    _physical,
    _reach,
    cutting_span,
)

__all__ = ["simulate_axes"]


def simulate_axes(spec, tool, machine, workpiece, parts, *, seed: int, instrument,
                  hooks, n_threads) -> Any:
    """Kinematic or machine-axis simulation (see the module docstring).

    Parameters
    ----------
    spec : ToolpathSpec
        The toolpath (any kind).
    tool : Tool
        The tool (after hooks).
    machine : Machine
        The machine (after mass, bandwidth and hooks).
    workpiece : Workpiece
        The workpiece.
    parts : tuple of str or None
        ``("kinematic",)``, a subset of ``("tracking",)`` or None (the machine's
        default).
    seed : int
        Seed of the instrument noise.
    instrument : Interferometer, str or None
        Interferometer model, as for :func:`~servosurf.simulation.simulate`.
    hooks : sequence
        Model hooks (``path_z``, ``cutting_rules`` and ``surface`` are applied).
    n_threads : int or None
        Numba threads of the kernel.

    Returns
    -------
    SimulationResult
        The map; ``t``, ``z_command`` and the deviations are empty for a kinematic
        run.
    """
    axis = machine.axis
    kinematic = (parts is not None and KINEMATIC in parts) or axis.model == "none"
    if parts is None:
        parts = (KINEMATIC,) if kinematic else ("tracking",)
    if kinematic:
        parts = (KINEMATIC,)
    else:
        extra = [p for p in parts if p != "tracking"]
        if extra:
            raise ConfigError(
                f"machine {machine.name!r} has a {axis.model} Z axis: parts "
                f"{', '.join(extra)} are models of the seed paper's FTS; use tracking "
                f"or {KINEMATIC}")
    kfield = _kernel_field(spec)
    empty = np.zeros(0)
    dev: dict[str, np.ndarray] = {}
    if kinematic:
        fs = float(machine.controller.sample_rate)
        with _progress.stage("commanded path samples (kinematic)"):
            if spec.kind == "nc":
                path = spec.path.vertex_samples()
                fs = path.fs
            else:
                path = sample(spec, fs=fs, field=kfield, tool=tool,
                              reach=_reach(spec, tool))
            t = z_cmd = empty
            extra_z = np.zeros(path.n)
            for h in hooks:
                if hasattr(h, "path_z"):
                    extra_z = extra_z + np.asarray(
                        h.path_z(path.t, path.theta, path.r, path.z), dtype=float)
            if np.any(extra_z):
                path = path.add_z(extra_z)
            dev = {"tracking": empty, "hooks": empty}
            rate_note = ("block end points" if spec.kind == "nc"
                         else "controller rate")
    else:
        fs = float(axis.sample_rate)
        t0, t1 = cutting_span(spec, tool)
        k0 = max(int(np.floor((t0 - SETTLE_TIME) * fs)), 0)
        k1 = int(np.ceil(t1 * fs)) + 2
        n = k1 - k0
        if n > MAX_SPAN_SAMPLES:
            raise ConfigError(
                f"the field needs {n} axis samples ({n / fs:.1f} s of cutting at "
                f"axis.sample-rate {fs:g} Hz), more than {MAX_SPAN_SAMPLES}; use a "
                "smaller field or a lower axis.sample-rate")
        t = (k0 + np.arange(n)) / fs
        z_cmd = spec.path.z_at(t)
        with _progress.stage(f"second-order Z axis over {n} samples"):
            dev["tracking"] = (axis.response(z_cmd) - z_cmd if "tracking" in parts
                               else np.zeros(n))
            extra_z = np.zeros(n)
            for h in hooks:
                if hasattr(h, "path_z"):
                    extra_z = extra_z + np.asarray(
                        h.path_z(t, spec.path.theta_at(t), spec.path.radius_at(t),
                                 z_cmd), dtype=float)
            dev["hooks"] = extra_z
        with _progress.stage("toolpath samples over the field"):
            path = sample(spec, fs=fs, field=kfield, tool=tool,
                          reach=_reach(spec, tool))
            idx = path.index - k0
            if idx.size and (idx.min() < 0 or idx.max() >= n):
                raise ConfigError("internal: the axis record does not cover the field")
            path = path.add_z((dev["tracking"] + extra_z)[idx])
        rate_note = "axis sample rate"
    check_clearance(path, tool)
    with _progress.stage(f"kernel on {spec.field.ny} x {spec.field.nx} grid"):
        # the envelope, or the ordered sweep when a hook sets material rules
        surface = _parts.machine_surface(path, tool, kfield,
                                         _initial(spec, workpiece), workpiece, (),
                                         hooks=hooks, n_threads=n_threads)
        surface = _physical(spec, surface)
    ctx = {"spec": spec, "machine": machine, "workpiece": workpiece, "t": t,
           "z_command": z_cmd,
           "deviation": dev, "force": np.zeros(t.size), "seed": seed}
    for h in hooks:
        if hasattr(h, "surface"):
            surface = h.surface(surface, ctx)
    settings = {
        "toolpath_kind": spec.kind,
        "seed": int(seed),
        "parts": list(parts),
        "machine": machine.name,
        "axis_model": axis.model,
        "workpiece": workpiece.name,
        "path_sample_rate_hz": float(path.fs),
        "path_samples": rate_note,
        "n_path_samples": int(path.n),
        "hooks": [type(h).__name__ for h in hooks],
    }
    if not kinematic:
        settings.update(axis_bandwidth_hz=axis.bandwidth, axis_damping=axis.damping)
    if spec.kind == "nc":
        settings["nc"] = spec.path.describe()
    surface = surface.replace(metadata={**surface.metadata, "simulation": settings})
    measured = None if instrument is None else _measure(surface, instrument, seed)
    return SimulationResult(
        surface=surface, measured=measured, t=t, z_command=z_cmd, deviation=dev,
        force=np.zeros(t.size), following_error=np.zeros(t.size), machine=machine,
        spec=spec, workpiece=workpiece, settings=settings)
