"""The typed run configuration: what a simulation runs on, with the paper's set-ups.

A :class:`RunConfig` holds the settings of one run that are not the toolpath: the
machine, the workpiece, the open-loop crossover bandwidth (Hz), the moving mass
(kg), the seed, the model parts, the interferometer model, the machine's
disturbance calibration and the kernel's thread count. It is frozen and checked on
construction (a physically absurd value is refused, naming the likely unit slip).

Named presets hold the seed paper's set-ups (:data:`PRESETS`, described by
:data:`PRESET_NOTES`); a run starts from one and changes what it needs::

    >>> from servosurf.run import preset
    >>> cut = preset("paper-cutting")
    >>> cut.bandwidth, cut.mass, cut.instrument
    (1448.0, 0.175, 'cp300-20x')
    >>> cut.replace(seed=3).seed
    3

From TOML (kebab-case keys, through :func:`servosurf.config.from_mapping`; unknown
keys are refused with suggestions)::

    preset = "paper-optimum-light"   # optional: the values below change it
    seed = 4
    parts = ["tracking", "vibration"]

:func:`servosurf.simulation.simulate`, :func:`servosurf.report.realisation_study`,
:func:`servosurf.scale.simulate_face_run`, the ``simulate``, ``face``, ``compare``
and ``paper`` commands and the benchmarks take their set-up from a RunConfig.
"""

from __future__ import annotations

import dataclasses
import difflib
import os
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from . import _parts
from .config import check_bounds, from_mapping, load_toml, param
from .errors import ConfigError

__all__ = [
    "RunConfig",
    "PRESETS",
    "PRESET_NOTES",
    "DEFAULT_PRESET",
    "preset",
    "load_run",
]

#: The part of the commanded path alone (not combined with the model parts).
_KINEMATIC = "kinematic"


@dataclass(frozen=True)
class RunConfig:
    """Settings of one simulation run besides the toolpath (SI units).

    Every field may be left at None, which means "the default of the machine, the
    workpiece or the toolpath" as :func:`servosurf.simulation.simulate` states it.

    Parameters
    ----------
    machine : str, Path or Machine, optional
        Machine TOML file or built-in name (``servosurf machines``); in Python also
        a :class:`~servosurf.servo.Machine`. Default: the seed prototype (NC
        programs: ``sts-ideal-axes``, ideal machine axes).
    workpiece : str, Path or Workpiece, optional
        Workpiece TOML file or built-in name; in Python also a
        :class:`~servosurf.cutting.Workpiece`. Default: electroless NiP, flat.
    bandwidth : float, optional
        Open-loop crossover bandwidth, in Hz (default: the machine's).
    mass : float, optional
        Moving mass m1 + m2, in kg (default: the machine's).
    seed : int, default: 0
        Seed of the vibration realisation (and of the instrument's own stream).
    parts : tuple of str, optional
        Model parts (:data:`servosurf.simulation.PARTS`, or ``("kinematic",)``);
        default: the toolpath's and machine's default.
    instrument : str, optional
        Interferometer model applied to the machined map (``cp300-20x``,
        ``newview-20x``, ... or a TOML file); None or ``"none"``: no model.
    disturbances : str, optional
        Name of the machine's disturbance calibration (default: its active one).
    n_threads : int, optional
        Numba threads of the kernels (default: ``defaults["numba_threads"]``).
    preset : str, optional
        The named preset these values started from (a record; it changes
        nothing by itself once the config is built).
    """

    machine: str | None = param(
        None, doc="machine TOML file or built-in name (default: the seed prototype)")
    workpiece: str | None = param(
        None, doc="workpiece TOML file or built-in name (default: NiP, flat)")
    bandwidth: float | None = param(
        None, unit="Hz", doc="open-loop crossover bandwidth", low=0.0, low_open=True,
        plausible=(1.0, 5e4))
    mass: float | None = param(
        None, unit="kg", doc="moving mass m1+m2", low=0.0, low_open=True,
        plausible=(1e-3, 50.0))
    seed: int = param(0, doc="seed of the vibration realisation", low=0)
    parts: tuple[str, ...] | None = param(
        None, doc="model parts (default: the toolpath's and machine's)")
    instrument: str | None = param(
        None, doc="interferometer model of the machined map (none: no model)")
    disturbances: str | None = param(
        None, doc="disturbance calibration of the machine (default: its active one)")
    n_threads: int | None = param(
        None, doc="numba threads of the kernels (default: defaults['numba_threads'])",
        low=1)
    preset: str | None = param(None, doc="the named preset these values started from")

    def __post_init__(self) -> None:
        seed = self.seed
        if (isinstance(seed, bool) or not isinstance(seed, int | np_integer())
                or seed < 0):
            raise ConfigError(f"seed must be a non-negative integer, got {seed!r}")
        object.__setattr__(self, "seed", int(seed))
        typical = {"bandwidth": 1448.0, "mass": 0.175}
        for f in dataclasses.fields(self):
            value = getattr(self, f.name)
            if isinstance(value, int | float) and not isinstance(value, bool):
                check_bounds(value, f.metadata, f.name, typical.get(f.name))
        if self.n_threads is not None and (isinstance(self.n_threads, bool)
                                           or not isinstance(self.n_threads, int)):
            raise ConfigError(f"n_threads must be a positive integer, got "
                              f"{self.n_threads!r}")
        for name in ("machine", "workpiece"):
            value = getattr(self, name)
            if isinstance(value, int | float | bool):
                raise ConfigError(f"{name} must be a file or built-in name, got "
                                  f"{value!r}")
        if isinstance(self.instrument, str) and self.instrument.lower() == "none":
            object.__setattr__(self, "instrument", None)
        if self.parts is not None:
            if isinstance(self.parts, str):
                raise ConfigError(f"parts must be a list of part names, got "
                                  f"{self.parts!r}")
            parts = tuple(self.parts)
            allowed = (*_parts.ALL_PARTS, _KINEMATIC)
            bad = [p for p in parts if p not in allowed]
            if bad:
                near = difflib.get_close_matches(str(bad[0]), allowed, n=1)
                hint = f" Did you mean: {near[0]}?" if near else ""
                raise ConfigError(
                    f"parts: unknown deviation part {bad[0]!r}.{hint} Allowed: "
                    f"{', '.join(_parts.ALL_PARTS)}, or {_KINEMATIC} alone")
            if _KINEMATIC in parts and len(parts) > 1:
                raise ConfigError(
                    f"parts: {_KINEMATIC!r} is the commanded path alone; it cannot be "
                    f"combined with {', '.join(p for p in parts if p != _KINEMATIC)}")
            object.__setattr__(self, "parts", parts)
        if self.preset is not None and self.preset not in PRESET_NOTES:
            raise ConfigError(_unknown_preset(self.preset))

    # ------------------------------------------------------------------ building
    @classmethod
    def from_mapping(cls, data: Mapping[str, Any], *, prefix: str = "") -> RunConfig:
        """Build a run configuration from a (TOML) mapping with kebab-case keys.

        A ``preset`` key starts from that preset; the other keys change it.

        Parameters
        ----------
        data : Mapping
            Keys of :class:`RunConfig` (kebab-case or snake_case).
        prefix : str, optional
            Dotted prefix of the keys in error messages (e.g. ``"run"`` for the
            ``[run]`` table of a manifest).

        Returns
        -------
        RunConfig
            The configuration.

        Raises
        ------
        ConfigError
            On an unknown key or preset (with suggestions), a wrong type or an
            implausible value, naming the dotted key.
        """
        if not isinstance(data, Mapping):
            where = prefix or "run configuration"
            raise ConfigError(f"{where}: expected a table, got {type(data).__name__}")
        data = dict(data)
        name = data.get("preset")
        if name is not None:
            if not isinstance(name, str) or name not in PRESETS:
                key = f"{prefix}.preset" if prefix else "preset"
                raise ConfigError(f"{key}: {_unknown_preset(name)}")
            base = PRESETS[name].to_mapping()
            data = {**base, **{k.replace("_", "-"): v for k, v in data.items()}}
        return from_mapping(cls, data, prefix=prefix)

    @classmethod
    def load(cls, path: str | os.PathLike[str]) -> RunConfig:
        """Read a run configuration from a TOML file (the keys at its top level).

        Parameters
        ----------
        path : str or path-like
            The TOML file.

        Returns
        -------
        RunConfig
            The configuration (errors name the file).
        """
        data = load_toml(path)
        try:
            return cls.from_mapping(data)
        except ConfigError as exc:
            raise ConfigError(f"{Path(path)}: {exc}") from None

    def replace(self, **changes: Any) -> RunConfig:
        """A copy with ``changes`` (checked like a new configuration)."""
        return dataclasses.replace(self, **changes)

    def with_overrides(self, **given: Any) -> RunConfig:
        """A copy with the values that were given (None: keep this config's).

        For command-line flags, whose None means "not given"; an instrument of
        ``"none"`` switches the model off.
        """
        return self.replace(**{k: v for k, v in given.items() if v is not None})

    def to_mapping(self) -> dict[str, Any]:
        """Kebab-case mapping of the values set (the inverse of :meth:`from_mapping`).

        A machine or workpiece given as an object is written by its name.
        """
        out: dict[str, Any] = {}
        for f in dataclasses.fields(self):
            v = getattr(self, f.name)
            if v is None:
                continue
            if f.name in ("machine", "workpiece") and not isinstance(v, str):
                v = str(v) if isinstance(v, os.PathLike) else getattr(v, "name", str(v))
            out[f.name.replace("_", "-")] = list(v) if isinstance(v, tuple) else v
        return out

    # ------------------------------------------------------------------ models
    def machine_model(self, default: str | None = None):
        """The machine of this run: loaded, with its disturbances, mass and bandwidth.

        Parameters
        ----------
        default : str, optional
            Machine used when :attr:`machine` is None (default: the seed
            prototype).

        Returns
        -------
        Machine
            The machine after :attr:`disturbances`, then :attr:`mass` (kg), then
            :attr:`bandwidth` (Hz) were applied (the order of
            :func:`servosurf.simulation.simulate`).
        """
        from .servo import Machine, load_machine

        machine = self.machine if self.machine is not None else default
        if not isinstance(machine, Machine):
            machine = load_machine(machine)
        if self.disturbances is not None:
            machine = machine.with_disturbances(self.disturbances)
        if self.mass is not None:
            machine = machine.with_moving_mass(self.mass)
        if self.bandwidth is not None:
            machine = machine.with_bandwidth(self.bandwidth)
        return machine


def np_integer() -> type:
    """numpy's integer type (numpy imported on use: this module stays light)."""
    import numpy as np

    return np.integer


def _unknown_preset(name: Any) -> str:
    near = difflib.get_close_matches(str(name), list(PRESET_NOTES), n=1)
    hint = f" Did you mean: {near[0]}?" if near else ""
    return f"unknown run preset {name!r}.{hint} Presets: {', '.join(PRESET_NOTES)}"


#: What each preset is, and where the paper states it.
PRESET_NOTES: dict[str, str] = {
    "paper-cutting": "the seed paper's cutting set-up (section 5.3, Figs 17-19): "
    "1448 Hz open-loop crossover with 0.175 kg moving mass (the added mass on the "
    "coil carrier), maps seen through the CP300 20X interferometer",
    "paper-optimum-heavy": "the paper's optimal bandwidth at 0.175 kg (section 5.1, "
    "Fig. 12a): 468 Hz crossover",
    "paper-optimum-light": "the paper's optimal bandwidth at 0.075 kg, the bare "
    "moving mass (section 5.1, Fig. 12a): 874 Hz crossover",
}

#: The preset of the commands' defaults.
DEFAULT_PRESET = "paper-cutting"

#: The seed paper's set-ups by name (see :data:`PRESET_NOTES`).
PRESETS: dict[str, RunConfig] = {
    "paper-cutting": RunConfig(bandwidth=1448.0, mass=0.175, instrument="cp300-20x",
                               preset="paper-cutting"),
    "paper-optimum-heavy": RunConfig(bandwidth=468.0, mass=0.175,
                                     instrument="cp300-20x",
                                     preset="paper-optimum-heavy"),
    "paper-optimum-light": RunConfig(bandwidth=874.0, mass=0.075,
                                     instrument="cp300-20x",
                                     preset="paper-optimum-light"),
}


def preset(name: str) -> RunConfig:
    """The named preset (:data:`PRESETS`).

    Parameters
    ----------
    name : str
        ``paper-cutting``, ``paper-optimum-heavy`` or ``paper-optimum-light``.

    Returns
    -------
    RunConfig
        The preset.

    Raises
    ------
    ConfigError
        On an unknown name (with a suggestion).
    """
    if name not in PRESETS:
        raise ConfigError(_unknown_preset(name))
    return PRESETS[name]


def load_run(source: str | os.PathLike[str] | Mapping[str, Any] | RunConfig | None
             ) -> RunConfig:
    """A run configuration from a preset name, a TOML file, a mapping or itself.

    Parameters
    ----------
    source : str, path-like, Mapping, RunConfig or None
        A preset name, a ``.toml`` file, a mapping (see
        :meth:`RunConfig.from_mapping`) or a RunConfig (returned as it is); None:
        ``RunConfig()``, every default.

    Returns
    -------
    RunConfig
        The configuration.
    """
    if source is None:
        return RunConfig()
    if isinstance(source, RunConfig):
        return source
    if isinstance(source, Mapping):
        return RunConfig.from_mapping(source)
    if isinstance(source, str) and source in PRESETS:
        return PRESETS[source]
    p = Path(source)
    if p.suffix.lower() == ".toml" or p.is_file():
        return RunConfig.load(p)
    raise ConfigError(_unknown_preset(source) + ", or a run TOML file")
