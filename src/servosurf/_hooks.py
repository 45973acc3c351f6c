"""The model-hook protocol of :func:`servosurf.simulation.simulate`, composed once.

A *hook* is any object with any of these optional methods (SI units throughout):

* ``perturbation() -> LoopPerturbation``: a linear change of the FTS plant under the
  installed controller (extra delay, extra structural modes, recalibrated machine
  parameters), :class:`servosurf.servo.LoopPerturbation`;
* ``nonlinearity() -> dict``: fields of :class:`servosurf.servo.Nonlinearity`
  (saturation, ``Kf(x)``, flexure stiffness, ...) the loop runs with;
* ``base_lines() -> tuple of (frequency, amplitude)``: deterministic sinusoids of
  the base displacement (Hz, m zero-to-peak), through the closed loop;
* ``sensor_lines() -> tuple of (frequency, amplitude)``: deterministic sinusoids
  in the logged measured position only (Hz, m zero-to-peak): electrical pickup
  outside the loop, in the following-error records but not on the cut surface;
* ``machine(machine) -> Machine``: a changed machine file (the diagnosis reads its
  disturbance PSDs from it);
* ``workpiece(workpiece) -> Workpiece``: a changed work material (cutting force);
* ``tool(tool) -> Tool``: a changed tool (edge waviness, nose radius);
* ``cutting_rules(rules) -> CuttingRules``: changed material rules of the
  time-ordered sweep (:class:`servosurf.toolpath.CuttingRules`, heights in m: a
  minimum chip thickness below which a pass ploughs instead of cutting); any
  rule that is not zero switches the simulator to the ordered sweep;
* ``path_z(t, theta, r, z) -> dz``: tool-height terms outside the loop in m at times
  ``t`` (s), spindle angles ``theta`` (rad), radii ``r`` (m) and deterministic tool
  heights ``z`` (m: the command plus the loop's tracking and force deviations);
* ``surface(surface, context) -> Surface``: a change of the machined surface.

:func:`servosurf.simulation.simulate` and the diagnosis's case model
(:class:`servosurf.diagnose.CaseModel`) compose hooks with the functions here, so a
fitted catalogue effect is simulated by the same rules the diagnosis fitted it with.
With no hook (or hooks that change nothing) every function returns the nominal
object, and results are bit for bit those without hooks.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from typing import Any

import numpy as np

from .errors import ConfigError

__all__ = [
    "HOOKS",
    "compose_perturbation",
    "compose_nonlinearity",
    "compose_base_lines",
    "compose_sensor_lines",
    "apply_hooks",
    "compose_path_z",
]

#: Every hook method of the protocol, in the order a simulation applies them.
HOOKS = (
    "perturbation",
    "nonlinearity",
    "base_lines",
    "sensor_lines",
    "machine",
    "workpiece",
    "tool",
    "cutting_rules",
    "path_z",
    "surface",
)


def compose_perturbation(hooks: Sequence[Any]):
    """The loop perturbation of all ``hooks`` together (None when none has one).

    Extra delays add, structural modes are collected in hook order, and a
    recalibrated machine parameter may be set by one hook only (two different
    values are a :class:`~servosurf.errors.ConfigError`).
    """
    from .servo import LoopPerturbation

    pieces = [h.perturbation() for h in hooks if hasattr(h, "perturbation")]
    if not pieces:
        return None
    recal_fields = [
        f.name for f in dataclasses.fields(LoopPerturbation)
        if f.name not in ("extra_delay", "modes")
    ]
    delay = 0.0
    modes: list = []
    recal: dict[str, float] = {}
    for p in pieces:
        delay += p.extra_delay
        modes += list(p.modes)
        for name in recal_fields:
            v = getattr(p, name)
            if v is None:
                continue
            if name in recal and recal[name] != v:
                raise ConfigError(
                    f"two hooks recalibrate {name} ({recal[name]!r} and {v!r}); "
                    "allowed: one value per machine parameter")
            recal[name] = v
    return LoopPerturbation(extra_delay=delay, modes=tuple(modes), **recal)


def compose_nonlinearity(hooks: Sequence[Any]):
    """The loop nonlinearity of all ``hooks`` together (None when none has one).

    Each hook names fields of :class:`servosurf.servo.Nonlinearity`; a field set
    by two hooks to different values is a :class:`~servosurf.errors.ConfigError`.
    """
    from .servo import Nonlinearity

    found = False
    fields: dict[str, float] = {}
    for h in hooks:
        if not hasattr(h, "nonlinearity"):
            continue
        found = True
        for k, v in h.nonlinearity().items():
            if k in fields and fields[k] != v:
                raise ConfigError(
                    f"two hooks set the loop nonlinearity {k} ({fields[k]!r} and "
                    f"{v!r}); allowed: one value per field")
            fields[k] = v
    return Nonlinearity(**fields) if found else None


def compose_base_lines(hooks: Sequence[Any]) -> tuple[tuple[float, float], ...]:
    """Every base-vibration line ``(frequency in Hz, amplitude in m)`` of ``hooks``."""
    out: list[tuple[float, float]] = []
    for h in hooks:
        if hasattr(h, "base_lines"):
            out += [(float(f), float(a)) for f, a in h.base_lines()]
    return tuple(out)


def compose_sensor_lines(hooks: Sequence[Any]) -> tuple[tuple[float, float], ...]:
    """Every sensor pickup line ``(frequency in Hz, amplitude in m)`` of ``hooks``
    (in the logged following error only, outside the loop)."""
    out: list[tuple[float, float]] = []
    for h in hooks:
        if hasattr(h, "sensor_lines"):
            out += [(float(f), float(a)) for f, a in h.sensor_lines()]
    return tuple(out)


def apply_hooks(hooks: Sequence[Any], method: str, obj):
    """``obj`` passed through the ``method`` hooks (``machine``, ``workpiece``,
    ``tool``, ``cutting_rules``) in order."""
    for h in hooks:
        if hasattr(h, method):
            obj = getattr(h, method)(obj)
    return obj


def compose_path_z(hooks: Sequence[Any], t: np.ndarray, theta: np.ndarray,
                   r: np.ndarray, z: np.ndarray) -> np.ndarray | None:
    """Sum of the ``path_z`` terms of ``hooks`` in m (None when none has one)."""
    out = None
    for h in hooks:
        if hasattr(h, "path_z"):
            dz = np.asarray(h.path_z(t, theta, r, z), dtype=float)
            out = dz if out is None else out + dz
    return out
