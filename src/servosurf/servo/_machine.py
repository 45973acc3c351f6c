"""Machine definition: every parameter of the seed paper's Eqs 1 to 7 and the loop.

A machine is a TOML file mapped onto the frozen dataclasses below. Each field carries
its SI unit, a description and its source (paper value, or calibrated and against
what); ``servosurf machines --describe`` prints them.

Decisions recorded here (see also the module docstrings of ``_plant`` and ``_loop``):

* The 300/400 kHz and 15 kHz figures are **-3 dB bandwidths** (the paper measured the
  current loop "400 kHz (-3dB)", and the CPL190 datasheet quotes -3 dB). The double
  pole ``(s + w)^2`` of Eqs 5 and 7 therefore sits at ``w = 2 pi f_3dB / 0.6436``.
* The sensor is fixed to the coil carrier (m2) as the paper's text says; Eq 7's ``x1``
  is available as ``sensor.location = "tool"``.
* "Moving mass" means m1 + m2 (paper section 3.3). Extra mass (the glued steel blocks)
  is added to ``mechanics.added-mass-on``. A file that omits the key puts it on m2
  (a tool holder that is part of the rigid coil-carrier body); the built-in
  ``seed-prototype`` puts it on m1, the tool body, as the paper's "steel blocks glued
  onto the tool holder" (4.1) reads, and only that placement gives the paper's
  measured instability above 1.6 kHz at 0.175 kg: with the blocks on m2 the loop
  stays stable (16.8 dB of gain margin at 1448 Hz) until the tuning rule runs out of
  positive gains. ``servosurf paper`` reports both placements and the pole that
  leaves the unit circle (the 11.7 kHz appendage mode, not the tool mode).
* Every number of a machine file may carry a provenance label in its
  ``[provenance]`` table (``paper: ...``, ``assumed: ...``, ``derived: ...``,
  ``target:<figure keys>``); the built-in file is written by
  :func:`servosurf.calibration.calibrate`, and ``servosurf machines --describe``
  prints the same labels.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from importlib import resources
from pathlib import Path
from typing import Literal

from ..config import describe, from_mapping, load_toml, param, to_mapping
from ..errors import ConfigError
from ._axis import AxisModel

__all__ = [
    "Mechanics",
    "Actuator",
    "Sensor",
    "Controller",
    "PSDModel",
    "Disturbances",
    "Spindle",
    "Machine",
    "load_machine",
    "builtin_machines",
    "describe_machine",
    "MINUS_3DB_DOUBLE_POLE",
    "PROVENANCE_KINDS",
]

#: -3 dB frequency of 1/(1 + s/w)^2 relative to w: sqrt(sqrt(2) - 1).
MINUS_3DB_DOUBLE_POLE = (2**0.5 - 1) ** 0.5

_PAPER = "seed paper"


@dataclass(frozen=True)
class Mechanics:
    """Lumped-parameter mechanics of Fig. 5 (Eqs 1 to 4). All SI."""

    m1: float = param(
        0.020,
        unit="kg",
        low=0.0,
        low_open=True,
        doc="tool and tool holder tip (x1)",
        source="calibrated",
    )
    m2: float = param(
        0.055,
        unit="kg",
        low=0.0,
        low_open=True,
        doc="coil carrier with sensor (x2)",
        source="calibrated",
    )
    m3: float = param(
        1.2,
        unit="kg",
        low=0.0,
        low_open=True,
        doc="X carriage (x3)",
        source="design estimate",
    )
    m4: float = param(
        0.004,
        unit="kg",
        low=0.0,
        low_open=True,
        doc="flexible appendage of the carrier (x4)",
        source="calibrated",
    )
    k1: float = param(
        9.0e7,
        unit="N/m",
        low=0.0,
        low_open=True,
        doc="tool-to-carrier stiffness",
        source="calibrated",
    )
    c1: float = param(
        8.0, unit="N s/m", low=0.0, doc="tool-to-carrier damping", source="calibrated"
    )
    k2: float = param(
        2.0e4, unit="N/m", low=0.0, doc="flexure bearing stiffness", source="calibrated"
    )
    c2: float = param(
        2.0, unit="N s/m", low=0.0, doc="flexure bearing damping", source="calibrated"
    )
    k3: float = param(
        5.0e7,
        unit="N/m",
        low=0.0,
        low_open=True,
        doc="carriage-to-ground stiffness",
        source="design estimate",
    )
    c3: float = param(
        300.0,
        unit="N s/m",
        low=0.0,
        doc="carriage-to-ground damping",
        source="design estimate",
    )
    k4: float = param(
        1.0e7,
        unit="N/m",
        low=0.0,
        low_open=True,
        doc="appendage-to-carrier stiffness",
        source="calibrated",
    )
    c4: float = param(
        1.0,
        unit="N s/m",
        low=0.0,
        doc="appendage-to-carrier damping",
        source="calibrated",
    )
    k5: float = param(
        0.0,
        unit="N/m",
        low=0.0,
        doc="coil-to-magnet stiffness",
        source="paper: ironless flat voice coil, none expected",
    )
    c5: float = param(
        0.0,
        unit="N s/m",
        low=0.0,
        doc="coil-to-magnet damping (eddy)",
        source="paper: none expected",
    )
    added_mass_on: Literal["m1", "m2"] = param(
        "m2", doc="which mass receives extra moving mass", source="decision"
    )

    @property
    def moving_mass(self) -> float:
        """m1 + m2 in kg (the paper's 'moving mass')."""
        return self.m1 + self.m2


@dataclass(frozen=True)
class Actuator:
    """Current amplifier (Eq 5) and voice-coil motor (Eq 6)."""

    force_constant: float = param(
        8.0,
        unit="N/A",
        low=0.0,
        low_open=True,
        doc="motor constant B*l",
        source="calibrated",
    )
    current_gain: float = param(
        1.0,
        unit="A/V",
        low=0.0,
        low_open=True,
        doc="current amplifier DC gain G_I",
        source="assumed",
    )
    current_bandwidth: float = param(
        400e3,
        unit="Hz",
        low=0.0,
        low_open=True,
        doc="current loop -3 dB bandwidth",
        source=_PAPER + " section 2.2",
    )
    max_current: float = param(
        3.0,
        unit="A",
        low=0.0,
        low_open=True,
        doc="amplifier current limit (saturation)",
        source="assumed",
    )

    @property
    def corner(self) -> float:
        """Double-pole corner angular frequency w_I in rad/s (Eq 5)."""
        return 2.0 * 3.141592653589793 * self.current_bandwidth / MINUS_3DB_DOUBLE_POLE


@dataclass(frozen=True)
class Sensor:
    """Capacitive displacement sensor (Eq 7)."""

    sensitivity: float = param(
        4.0e5,
        unit="V/m",
        low=0.0,
        low_open=True,
        doc="sensor sensitivity S",
        source="assumed (CPL190 range)",
    )
    bandwidth: float = param(
        15e3,
        unit="Hz",
        low=0.0,
        low_open=True,
        doc="sensor -3 dB bandwidth",
        source=_PAPER + " section 2.2",
    )
    location: Literal["carrier", "tool"] = param(
        "carrier",
        doc="mass the sensor measures: carrier (x2) or tool (x1)",
        source="paper text: fixed to the coil carrier",
    )
    target: Literal["metrology-frame", "fts-base"] = param(
        "metrology-frame",
        doc="where the sensor's reference surface sits: on the metrology frame that "
        "carries the spindle and workpiece (base motion inside the loop) or on the "
        "FTS base (frame-to-spindle motion bypasses the loop; simulate part "
        "'out-of-loop')",
        source="paper 2.2: the sensor targets 'a ground flat surface', where is not "
        "stated; a separate metrology frame forms the loop to the spindle (Fig. 3)",
    )

    @property
    def corner(self) -> float:
        """Double-pole corner angular frequency w_s in rad/s (Eq 7)."""
        return 2.0 * 3.141592653589793 * self.bandwidth / MINUS_3DB_DOUBLE_POLE


@dataclass(frozen=True)
class Controller:
    """Digital PID with derivative filter and its tuning rule.

    With ``kp``/``ki``/``kd``/``tf`` unset, the gains are tuned for ``bandwidth``
    (open-loop crossover) and ``phase-margin``; see :func:`servosurf.servo.tune_pidf`.
    """

    sample_rate: float = param(
        199.6e3,
        unit="Hz",
        low=0.0,
        low_open=True,
        doc="controller update rate",
        source=_PAPER + " 4.1",
    )
    delay: float = param(
        1.0,
        unit="samples",
        low=0.0,
        high=20.0,
        doc="computation and transport delay beyond the ZOH",
        source="calibrated to the 1.6 kHz stability limit",
    )
    bandwidth: float = param(
        468.0,
        unit="Hz",
        low=1.0,
        doc="target open-loop crossover frequency",
        source=_PAPER + " optimum at 0.175 kg",
    )
    phase_margin: float = param(
        60.0,
        unit="deg",
        low=5.0,
        high=89.0,
        doc="target phase margin at the crossover",
        source="MATLAB pidtune default",
    )
    integral_ratio: float = param(
        0.035,
        unit="",
        low=0.0,
        high=1.0,
        doc="rho: Ki = rho * Kp * w_c",
        source="calibrated: 100 Hz overshoot, 12 deg force lag",
    )
    derivative_filter_ratio: float = param(
        8.0,
        unit="",
        low=1.0,
        high=1e3,
        doc="N: Tf = 1 / (N * w_c)",
        source="calibrated: 12 deg force lag",
    )
    kp: float | None = param(None, unit="V/V", doc="explicit proportional gain")
    ki: float | None = param(None, unit="V/(V s)", doc="explicit integral gain")
    kd: float | None = param(None, unit="V s/V", doc="explicit derivative gain")
    tf: float | None = param(None, unit="s", doc="explicit derivative filter time")

    def __post_init__(self) -> None:
        given = [g is not None for g in (self.kp, self.ki, self.kd, self.tf)]
        if any(given) and not all(given):
            raise ConfigError(
                "controller: give all of kp, ki, kd, tf or none (then gains are tuned)"
            )


@dataclass(frozen=True)
class PSDModel:
    """A parametric one-sided PSD or a measured one from CSV.

    ``W(f) = (level^2 (f / ref_frequency)^slope + floor^2) / (1 + (f / corner)^order)
    + white^2``, in (unit of the disturbance)^2 / Hz. ``csv`` (``frequency_hz,psd``)
    replaces the rolled-off parametric part when given; relative paths resolve
    against the machine file. ``white`` is a density added after the roll-off: noise
    the electronics do not shape, such as a converter's quantisation (an ADC that
    digitises the sensor's output is white up to the Nyquist frequency).
    """

    level: float = param(
        0.0,
        unit="unit/sqrt(Hz)",
        low=0.0,
        doc="amplitude spectral density at ref-frequency",
    )
    ref_frequency: float = param(
        1000.0, unit="Hz", low=0.0, low_open=True, doc="frequency where level applies"
    )
    slope: float = param(
        0.0, unit="", low=-6.0, high=6.0, doc="power-law exponent of the PSD"
    )
    corner: float = param(
        1e9, unit="Hz", low=0.0, low_open=True, doc="roll-off corner frequency"
    )
    order: float = param(2.0, unit="", low=0.0, high=12.0, doc="roll-off order")
    floor: float = param(
        0.0, unit="unit/sqrt(Hz)", low=0.0, doc="white floor added to the power law"
    )
    white: float = param(
        0.0, unit="unit/sqrt(Hz)", low=0.0,
        doc="white density added after the roll-off (converter quantisation)"
    )
    csv: str = param("", doc="measured PSD file: frequency_hz,psd")


@dataclass(frozen=True)
class Disturbances:
    """Stationary stochastic disturbances of Table 1 (Ws, Wi, Wg)."""

    name: str = param("default", doc="name of this calibration")
    source: str = param("", doc="what this calibration reproduces")
    sensor_noise: PSDModel = param(
        default_factory=PSDModel,
        unit="m^2/Hz",
        doc="Ws: sensor noise, position equivalent",
    )
    current_noise: PSDModel = param(
        default_factory=PSDModel, unit="A^2/Hz", doc="Wi: motor current noise"
    )
    base_vibration: PSDModel = param(
        default_factory=PSDModel, unit="m^2/Hz", doc="Wg: base displacement"
    )


def _default_axial_error() -> PSDModel:
    return PSDModel(floor=3.5e-11, corner=500.0, order=2.0)


@dataclass(frozen=True)
class Spindle:
    """The workpiece spindle's asynchronous axial error motion (outside the FTS loop).

    The default PSD is white at 3.5e-11 m/sqrt(Hz) rolled off above 500 Hz
    (second order): 0.98 nm RMS, a few nm of asynchronous error value (the width of
    the band, ISO 230-7), the level of a good air-bearing spindle.
    """

    axial_error: PSDModel = param(
        default_factory=_default_axial_error,
        unit="m^2/Hz",
        doc="PSD of the asynchronous axial error motion of the spindle face",
        source="assumed 1 nm RMS: air-bearing spindles show nanometre asynchronous "
        "axial error (Grejda, PhD thesis, Penn State 2002; Lion Precision: most air "
        "bearings below 1 uin = 25 nm); measure it per ISO 230-7",
    )
    fmin: float = param(
        0.05,
        unit="Hz",
        low=0.0,
        low_open=True,
        doc="lowest frequency of the realised axial error",
        source="assumed (a flat-face field takes about a minute to cut)",
    )


@dataclass(frozen=True)
class Machine:
    """Root of a machine file."""

    name: str = param("unnamed", doc="machine name")
    description: str = param("", doc="free text")
    mechanics: Mechanics = param(default_factory=Mechanics)
    actuator: Actuator = param(default_factory=Actuator)
    sensor: Sensor = param(default_factory=Sensor)
    controller: Controller = param(default_factory=Controller)
    disturbances: Disturbances = param(default_factory=Disturbances)
    alternative_disturbances: tuple[Disturbances, ...] = param(
        default_factory=tuple, doc="other named calibrations of the disturbances"
    )
    # tool Z axis: the FTS loop above (default), a second-order axis or none
    axis: AxisModel = param(default_factory=AxisModel)
    spindle: Spindle = param(default_factory=Spindle)
    provenance: tuple[tuple[str, str], ...] = param(
        default_factory=tuple,
        doc="[provenance] table: dotted key -> 'paper: ...', 'assumed: ...', "
        "'derived: ...' or 'target:<figures>'",
    )
    path: str = param("", doc="file this machine was read from (set by the loader)")

    def with_moving_mass(self, mass: float) -> Machine:
        """Return a copy whose m1 + m2 equals ``mass`` (kg).

        The difference to the base moving mass goes to ``mechanics.added-mass-on``.
        """
        mech = self.mechanics
        extra = float(mass) - mech.moving_mass
        target = mech.added_mass_on
        new = getattr(mech, target) + extra
        if not new > 0:
            raise ConfigError(
                f"--mass {mass:g} kg leaves {target} = {new:g} kg; "
                "the moving mass must exceed "
                f"{mech.moving_mass - getattr(mech, target):g} kg"
            )
        return dataclasses.replace(
            self, mechanics=dataclasses.replace(mech, **{target: new})
        )

    def with_bandwidth(self, bandwidth: float) -> Machine:
        """Return a copy tuned for a new crossover ``bandwidth`` in Hz.

        The controller gains are cleared.
        """
        if not bandwidth > 0:
            raise ConfigError(f"bandwidth must be > 0 Hz, got {bandwidth!r}")
        c = dataclasses.replace(
            self.controller,
            bandwidth=float(bandwidth),
            kp=None,
            ki=None,
            kd=None,
            tf=None,
        )
        return dataclasses.replace(self, controller=c)

    def with_disturbances(self, name: str) -> Machine:
        """Return a copy whose active disturbances are the calibration ``name``."""
        sets = {d.name: d for d in (self.disturbances, *self.alternative_disturbances)}
        if name not in sets:
            raise ConfigError(
                f"unknown disturbance calibration {name!r}; this machine has: "
                f"{', '.join(sets)}"
            )
        return dataclasses.replace(self, disturbances=sets[name])

    def to_toml(self, *, header: str = "") -> str:
        """TOML text that :func:`load_machine` reads back to an equal machine."""
        from ..config import dump_toml

        return dump_toml(self.to_mapping(), header=header)

    def to_mapping(self) -> dict:
        """Kebab-case mapping suitable for TOML.

        See :func:`servosurf.config.dump_toml`.
        """
        m = to_mapping(self)
        m.pop("path", None)
        prov = m.pop("provenance", None)
        if prov:
            m["provenance"] = {k: v for k, v in prov}
        return m


def _resolve_csv(machine: Machine, base: Path) -> Machine:
    def fix(d: Disturbances) -> Disturbances:
        kw = {}
        for name in ("sensor_noise", "current_noise", "base_vibration"):
            psd = getattr(d, name)
            if psd.csv and not Path(psd.csv).is_absolute():
                kw[name] = dataclasses.replace(psd, csv=str((base / psd.csv).resolve()))
        return dataclasses.replace(d, **kw) if kw else d

    spindle = machine.spindle
    ax = spindle.axial_error
    if ax.csv and not Path(ax.csv).is_absolute():
        spindle = dataclasses.replace(
            spindle, axial_error=dataclasses.replace(
                ax, csv=str((base / ax.csv).resolve())))
    return dataclasses.replace(
        machine,
        disturbances=fix(machine.disturbances),
        alternative_disturbances=tuple(
            fix(d) for d in machine.alternative_disturbances
        ),
        spindle=spindle,
    )


def _dotted_keys(data: dict, prefix: str = "") -> list[str]:
    """Dotted keys of a TOML mapping's leaves (tables of tables flattened)."""
    out = []
    for k, v in data.items():
        key = f"{prefix}.{k}" if prefix else str(k)
        if key == "provenance":
            continue
        if isinstance(v, dict):
            out.extend(_dotted_keys(v, key))
        else:
            out.append(key)
    return out


def _merge(base: dict, over: dict) -> dict:
    out = dict(base)
    for k, v in over.items():
        if isinstance(v, dict) and isinstance(out.get(k), dict):
            out[k] = _merge(out[k], v)
        else:
            out[k] = v
    return out


def builtin_machines() -> dict[str, Path]:
    """Return ``{name: path}`` of the machine files shipped with servosurf."""
    root = resources.files("servosurf") / "data" / "machines"
    out = {}
    for entry in sorted(root.iterdir(), key=lambda e: e.name):
        if entry.name.endswith(".toml"):
            out[entry.name[:-5]] = Path(str(entry))
    return out


def load_machine(source: str | Path | None = None) -> Machine:
    """Load a machine from a TOML file or a built-in name.

    Parameters
    ----------
    source : str or Path, optional
        A path to a TOML file, or the name of a built-in machine (see
        :func:`builtin_machines`). ``None`` loads the seed paper's prototype. A file
        may start with ``inherit = "seed-prototype"`` and give only what differs
        (tables are merged key by key). Keys a file omits otherwise take the generic
        dataclass defaults.

    Returns
    -------
    Machine
        The validated machine definition.

    Raises
    ------
    ConfigError
        When the file is missing, invalid, has unknown keys or out-of-range values.
    """
    builtins = builtin_machines()
    if source is None:
        source = "seed-prototype"
    key = str(source)
    if key in builtins:
        path = builtins[key]
    else:
        path = Path(source)
        if not path.exists():
            raise ConfigError(
                f"machine {key!r}: no such file and no built-in of that name "
                f"(built-ins: {', '.join(builtins)})"
            )
    data = load_toml(path)
    parent = data.pop("inherit", None)
    seen: set[str] = set()
    while parent is not None:  # a built-in may inherit another one
        if not isinstance(parent, str) or parent not in builtins or parent in seen:
            raise ConfigError(
                f"{path}: inherit must name a built-in machine "
                f"({', '.join(builtins)}), got {parent!r}"
            )
        seen.add(parent)
        base = load_toml(builtins[parent])
        parent = base.pop("inherit", None)
        # a number the file changes loses the built-in's provenance label (the label
        # described the built-in's value), unless the file labels it itself
        own = set(_dotted_keys(data)) - set(data.get("provenance") or {})
        if isinstance(base.get("provenance"), dict):
            base["provenance"] = {
                k: v for k, v in base["provenance"].items() if k not in own
            }
        data = _merge(base, data)
    prov = data.get("provenance")
    if prov is not None:
        if not isinstance(prov, dict) or not all(
            isinstance(v, str) for v in prov.values()
        ):
            raise ConfigError(
                f"{path}: [provenance] must map dotted keys to label strings"
            )
        data["provenance"] = sorted([str(k), v] for k, v in prov.items())
    try:
        machine = from_mapping(Machine, data)
    except ConfigError as exc:
        raise ConfigError(f"{path}: {exc}") from None
    machine = dataclasses.replace(machine, path=str(path))
    return _resolve_csv(machine, Path(path).parent)


#: Provenance labels start with one of these kinds.
PROVENANCE_KINDS = ("paper", "assumed", "derived", "target")


def describe_machine(machine: Machine | None = None) -> list[dict]:
    """Return the documented parameter list of a machine file.

    Parameters
    ----------
    machine : Machine, optional
        Machine whose values and provenance to list (default: the built-in
        ``seed-prototype``).

    Returns
    -------
    list of dict
        One entry per key: ``key``, ``unit``, ``doc``, ``value`` (the machine's),
        ``provenance`` (the label of the machine file's ``[provenance]`` table: the
        same text as there), ``default`` (the generic default of a file that omits
        the key) and ``source`` (where that generic default comes from). The
        alternative disturbance sets follow, under
        ``alternative-disturbances.<name>.``.
    """
    from ..config import to_mapping

    if machine is None:
        machine = load_machine()
    prov = dict(machine.provenance)
    flat: dict = {}

    def walk(obj: dict, prefix: str) -> None:
        for k, v in obj.items():
            key = f"{prefix}.{k}" if prefix else k
            if isinstance(v, dict):
                walk(v, key)
            else:
                flat[key] = v

    mapping = to_mapping(machine)
    alts = mapping.pop("alternative-disturbances", [])
    mapping.pop("provenance", None)
    walk(mapping, "")
    rows = []
    for r in describe(Machine):
        if r["key"] in ("provenance", "alternative-disturbances", "path"):
            continue
        rows.append(
            {**r, "value": flat.get(r["key"]), "provenance": prov.get(r["key"], "")}
        )
    sub = {
        r["key"][len("disturbances."):]: r
        for r in describe(Disturbances, prefix="disturbances")
    }
    for alt in alts:
        name = alt.get("name", "?")
        aflat: dict = {}
        for k, v in alt.items():
            if isinstance(v, dict):
                for kk, vv in v.items():
                    aflat[f"{k}.{kk}"] = vv
            else:
                aflat[k] = v
        for k, r in sub.items():
            key = f"alternative-disturbances.{name}.{k}"
            rows.append(
                {
                    **r,
                    "key": key,
                    "value": aflat.get(k),
                    "provenance": prov.get(key, ""),
                }
            )
    return rows
