"""Diagnosis manifest: the case and its recordings.

A manifest is a TOML file::

    [case]
    machine = "seed-prototype"      # built-in name or TOML path
    toolpath = "lenslet_5um.toml"   # toolpath TOML (needed by cut, surface, profile)
    bandwidth = 468.0               # Hz, open-loop crossover
    moving-mass = 0.175             # kg, m1 + m2
    disturbances = "section-5.2"    # optional disturbance calibration
    workpiece = "nip.toml"          # optional workpiece TOML (its k_t); default NiP
    specific-cutting-force = 1.0e9  # optional, N/m^2 (thrust per chip area), overrides

    [[recording]]
    path = "idle.npz"
    kind = "following-error"

The ``[case]`` keys (:class:`CaseTable`; ``preset = "<name>"`` starts from a run
preset of :mod:`servosurf.run`) may also sit at the top level and
``[[recordings]]`` is accepted for ``[[recording]]`` (:class:`RecordingTable`).
Both tables are read with :func:`servosurf.config.from_mapping`: unknown keys are
refused with a suggestion, numbers are range-checked in their units.

Relative paths (machine, toolpath, workpiece, recordings) are relative to the
manifest's folder only. (Before, a toolpath or workpiece not found there was also
looked up in ``toolpaths/`` and ``workpieces/`` of the current directory; that
fallback is gone: a manifest means the same wherever it is run from.) A name that
is no file is looked up among the built-in machines, toolpaths and workpieces.
Kinds and formats (:func:`servosurf.io.read_recording` reads them):

``following-error``
    CSV ``time_s,following_error_m`` with optional ``command_m``, ``force_n`` and
    ``record`` columns, or NPZ with ``fs_hz`` (or ``time_s``) and
    ``following_error_m`` of shape (n,) or (records, n), optional ``command_m`` and
    ``force_n`` of the same shape. In CSV a new record starts where ``time_s``
    decreases or ``record`` changes. Records of one recording are one condition;
    their spectra are averaged (seed paper: 32 records of 4096 samples). With a
    command or force the loop starts at rest at each record's first sample.
``frf-open-loop``, ``frf-closed-loop``, ``frf-force``
    CSV ``frequency_hz,real,imag``: DAC volts to sensor volts (V/V); reference to
    measured position (m/m); force on the tool to measured position (m/N; a
    constant gain such as V/N is absorbed).
``cut``
    CSV ``time_s,force_n,following_error_m`` recorded while cutting the case's
    toolpath, ``time_s`` from the start of the toolpath (loop at rest at t = 0).

Time records may be sampled at another rate than the controller's (an
acquisition at its own rate, another simulator's loop rate). The loop is then
simulated at the controller rate, its command and force splined from the record,
and its prediction splined back to the record's sample times; the residual is
compared from ``fs_controller / 4096`` up to 0.8 of the lower Nyquist frequency
(above that an acquisition's anti-alias filter rolls off, which the model does
not know). The record is assumed anti-aliased.
``surface``, ``profile``
    Any file :func:`servosurf.io.read_surface` / ``read_profile`` accept, or NPZ with
    ``z``, ``dx``, ``dy`` (surface; optional ``x0``, ``y0``, the centre of pixel
    (0, 0) in the workpiece frame, m) or ``z``, ``dx`` (profile; optional ``x0``).
    A surface without ``x0``/``y0`` is centred on the toolpath's field. A profile
    follows a straight line (keys ``start = [x, y]`` in m and ``direction`` in rad,
    default: through the field centre along the cutting direction) or a circle
    (key ``radius`` in m, optional ``angle-start`` in rad). ``form-order = K``
    (default 1: piston and tilt) says the instrument removed a polynomial form of
    that order from the recording (a profile exported "form removed"): the
    diagnosis profiles out the same polynomial from data and model.
"""

from __future__ import annotations

import dataclasses
import difflib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from ..config import from_mapping, param
from ..errors import ConfigError
from ..io import RECORDING_KINDS, read_recording

__all__ = [
    "DIAGNOSABLE_TOOLPATHS",
    "KINDS",
    "CaseTable",
    "RecordingTable",
    "Manifest",
    "Recording",
    "load_manifest",
    "read_recording",
    "simulation_manifest",
]

#: Toolpath kinds whose maps and profiles the diagnosis models: every kind
#: ``servosurf simulate`` cuts (design surfaces and NC programs through their
#: spiral passes, on an FTS machine).
DIAGNOSABLE_TOOLPATHS = ("lenslet", "facing", "surface", "nc")

#: Recording kinds accepted in a manifest (:data:`servosurf.io.RECORDING_KINDS`).
KINDS = RECORDING_KINDS


@dataclass(frozen=True)
class CaseTable:
    """The ``[case]`` table of a manifest, as written (SI units; paths unresolved).

    Keys are the fields in kebab-case (``moving-mass``); ``mass``,
    ``bandwidth-hz``, ``moving-mass-kg`` and the snake_case spellings are accepted
    as aliases.
    """

    machine: str = param("seed-prototype",
                         doc="built-in machine name or machine TOML path")
    toolpath: str | None = param(
        None, doc="toolpath TOML path or built-in name (cut, surface, profile)")
    bandwidth: float | None = param(
        None, unit="Hz", doc="open-loop crossover bandwidth", low=0.0, low_open=True,
        plausible=(1.0, 5e4))
    moving_mass: float | None = param(
        None, unit="kg", doc="moving mass m1+m2", low=0.0, low_open=True,
        plausible=(1e-3, 50.0))
    disturbances: str | None = param(None, doc="disturbance calibration name")
    specific_cutting_force: float | None = param(
        None, unit="N/m^2", doc="specific thrust pressure (overrides the workpiece's)",
        low=0.0, low_open=True)
    workpiece: str | None = param(
        None, doc="workpiece TOML path or built-in name (its k_t); default NiP")
    preset: str | None = param(
        None, doc="run preset the case starts from (servosurf.run.PRESETS)")
    name: str | None = param(None, doc="label of the case")
    description: str | None = param(None, doc="free text")


@dataclass(frozen=True)
class RecordingTable:
    """One ``[[recording]]`` table of a manifest, as written (SI units).

    Keys are the fields in kebab-case (``angle-start``).
    """

    path: str = param(doc="the recording's file, relative to the manifest")
    kind: str = param(doc="recording kind (servosurf.io.RECORDING_KINDS)")
    name: str | None = param(None, doc="label (default: the file name)")
    condition: Any = param(None, doc="free label of the recording's condition")
    radius: float | None = param(
        None, unit="m", doc="radius of a circular profile", low=0.0, low_open=True)
    angle_start: float | None = param(
        None, unit="rad", doc="start angle of a circular profile")
    start: tuple[float, float] | None = param(
        None, unit="m", doc="start point [x, y] of a straight profile")
    direction: float | None = param(
        None, unit="rad", doc="direction of a straight profile")
    x0: float | None = param(
        None, unit="m", doc="x of the map's pixel (0, 0) in the workpiece frame")
    y0: float | None = param(
        None, unit="m", doc="y of the map's pixel (0, 0) in the workpiece frame")
    description: str | None = param(None, doc="free text")
    # checked where it is used (integer 1..6, diagnose's build of the map block)
    form_order: Any = param(None, doc="order of the polynomial form the instrument "
                            "removed from a map or profile (1..6; default 1)")


def _keys(cls) -> set[str]:
    return {f.name.replace("_", "-") for f in dataclasses.fields(cls)}


_CASE_KEYS = _keys(CaseTable)
_ALIASES = {
    "mass": "moving-mass",
    "moving_mass": "moving-mass",
    "bandwidth-hz": "bandwidth",
    "bandwidth_hz": "bandwidth",
    "moving-mass-kg": "moving-mass",
    "specific_cutting_force": "specific-cutting-force",
}
_REC_KEYS = _keys(RecordingTable)


@dataclass(frozen=True, eq=False)
class Recording:
    """One recording of a manifest, read and checked.

    Attributes
    ----------
    name : str
        Label (the file name unless the manifest gives ``name``).
    kind : str
        One of :data:`KINDS`.
    path : Path
        The file.
    data : dict
        Arrays in SI units; the keys depend on the kind (see
        :func:`servosurf.io.read_recording`).
    options : dict
        Extra manifest keys (geometry of a profile, origin of a map).
    """

    name: str
    kind: str
    path: Path
    data: dict
    options: dict = field(default_factory=dict)


@dataclass(frozen=True, eq=False)
class Manifest:
    """A parsed manifest.

    Attributes
    ----------
    path : Path
        The manifest file.
    machine : str
        Built-in machine name or resolved path.
    toolpath : Path or None
        Resolved toolpath file.
    bandwidth : float or None
        Crossover bandwidth in Hz (None: the machine's).
    moving_mass : float or None
        m1 + m2 in kg (None: the machine's).
    disturbances : str or None
        Disturbance calibration name.
    specific_force : float or None
        Specific thrust pressure in N/m^2 (None: the built-in NiP workpiece's).
    recordings : tuple of Recording
        The recordings in manifest order.
    run : RunConfig or None
        The case as a run configuration (machine, workpiece, bandwidth, mass,
        disturbances, preset); :func:`build_case` builds the machine from it.
    """

    path: Path
    machine: str
    toolpath: Path | None
    bandwidth: float | None
    moving_mass: float | None
    disturbances: str | None
    specific_force: float | None
    recordings: tuple[Recording, ...]
    run: Any = None


def _toolpath_kind(path: Path) -> str:
    """The ``kind`` of a toolpath file ("nc" for an NC program)."""
    if path.suffix.lower() != ".toml":
        return "nc"
    import tomllib

    try:
        with open(path, "rb") as fh:
            return str(tomllib.load(fh).get("kind"))
    except (OSError, tomllib.TOMLDecodeError) as exc:
        raise ConfigError(f"toolpath {path}: {exc}") from None


def _suggest(key: str, known) -> str:
    close = difflib.get_close_matches(key, sorted(known), n=2)
    return f" (did you mean: {', '.join(close)}?)" if close else ""


def _resolve(base: Path, value: str) -> Path:
    """``value`` as a path: absolute, or relative to the manifest's folder."""
    p = Path(value)
    return p if p.is_absolute() else base / p


def _builtin_or_file(base: Path, value: str, what: str, builtins: dict,
                     where: str) -> Path:
    """A file relative to the manifest, else a built-in of that name."""
    p = _resolve(base, value)
    if p.is_file():
        return p
    tp = Path(value)
    found = builtins.get(tp.stem if tp.suffix == ".toml" else tp.name)
    if found is None:
        raise ConfigError(
            f"{where}: {what} {value!r}: no such file and no built-in of that "
            f"name ({', '.join(builtins)})"
        )
    return found


def _table(cls, data: dict, where: str, prefix: str = ""):
    """``from_mapping(cls, data)`` with the manifest named in its errors."""
    try:
        return from_mapping(cls, data, prefix=prefix)
    except ConfigError as exc:
        raise ConfigError(f"{where}: {exc}") from None


def _case_table(data: dict, path: Path) -> CaseTable:
    """The ``[case]`` table, with top-level case keys and aliases folded in.

    ``data`` is the manifest without its recordings; any other key is refused.
    """
    case = data.pop("case", {}) or {}
    if not isinstance(case, dict):
        raise ConfigError(f"{path}: [case] must be a table")
    case = dict(case)
    for k in list(data):
        if k in _CASE_KEYS or k in _ALIASES:
            case.setdefault(k, data.pop(k))
    if data:
        k = next(iter(data))
        raise ConfigError(
            f"{path}: unknown key {k!r}"
            f"{_suggest(k, _CASE_KEYS | {'case', 'recording'})}"
        )
    norm = {}
    for k, v in case.items():
        k2 = _ALIASES.get(k, k)
        if k2 not in _CASE_KEYS:
            raise ConfigError(
                f"{path}: unknown case key {k!r}{_suggest(k, _CASE_KEYS)}"
            )
        norm[k2] = v
    return _table(CaseTable, norm, str(path), "case")


def _recording_table(rec: Any, i: int, where: str) -> RecordingTable:
    if not isinstance(rec, dict):
        raise ConfigError(f"{where}: recording {i + 1} must be a table")
    for k in rec:
        if k not in _REC_KEYS:
            raise ConfigError(
                f"{where}: recording {i + 1}: unknown key {k!r}"
                f"{_suggest(k, _REC_KEYS)}"
            )
    if "path" not in rec or "kind" not in rec:
        raise ConfigError(f"{where}: recording {i + 1} needs 'path' and 'kind'")
    kind = str(rec["kind"])
    if kind not in KINDS:
        raise ConfigError(
            f"{where}: recording {i + 1}: unknown kind {kind!r} "
            f"(kinds: {', '.join(KINDS)})"
        )
    return _table(RecordingTable, rec, f"{where}: recording {i + 1}")


def load_manifest(path: str | Path) -> Manifest:
    """Read a manifest and every recording it lists.

    Parameters
    ----------
    path : str or Path
        The manifest TOML file.

    Returns
    -------
    Manifest
        The case and the recordings (arrays in SI units).

    Raises
    ------
    ConfigError
        On a missing or malformed manifest or recording (one-line message).
    """
    from ..config import load_toml
    from ..run import RunConfig

    path = Path(path)
    if not path.is_file():
        raise ConfigError(f"manifest {path}: no such file")
    try:
        data = load_toml(path)
    except ConfigError as exc:
        raise ConfigError(f"manifest {exc}") from None
    base = path.parent
    where = str(path)
    recs = data.pop("recording", None)
    if recs is None:
        recs = data.pop("recordings", None)
    case = _case_table(data, path)
    from ..servo import builtin_machines

    machine = case.machine
    if machine not in builtin_machines():
        mp = _resolve(base, machine)
        if not mp.is_file():
            raise ConfigError(
                f"{where}: machine {machine!r}: no such file and no "
                f"built-in of that name ({', '.join(builtin_machines())})"
            )
        machine = str(mp)
    toolpath = None
    if case.toolpath is not None:
        from ..toolpath import builtin_toolpaths

        toolpath = _builtin_or_file(base, case.toolpath, "toolpath",
                                    builtin_toolpaths(), where)
    kt = workpiece = None
    if case.workpiece is not None:
        from ..cutting import builtin_workpieces, load_workpiece

        workpiece = _builtin_or_file(base, case.workpiece, "workpiece",
                                     builtin_workpieces(), where)
        kt = float(load_workpiece(workpiece).material.specific_thrust_pressure)
    if case.specific_cutting_force is not None:
        kt = case.specific_cutting_force
    run_keys = {"machine": machine, "workpiece": workpiece and str(workpiece),
                "bandwidth": case.bandwidth, "mass": case.moving_mass,
                "disturbances": case.disturbances, "preset": case.preset}
    try:
        run = RunConfig.from_mapping(
            {k: v for k, v in run_keys.items() if v is not None}, prefix="case")
    except ConfigError as exc:
        raise ConfigError(f"{where}: {exc}") from None
    if recs is None or not isinstance(recs, list) or not recs:
        raise ConfigError(
            f"{where}: no [[recording]] entries (each needs path and kind)"
        )
    out = []
    for i, rec in enumerate(recs):
        table = _recording_table(rec, i, where)
        kind = table.kind
        rp = _resolve(base, table.path)
        if not rp.is_file():
            raise ConfigError(f"{where}: recording {i + 1}: {rp}: no such file")
        if kind in ("cut", "surface", "profile") and toolpath is None:
            raise ConfigError(f"{where}: a {kind!r} recording needs case.toolpath")
        if kind in ("cut", "surface", "profile"):
            tk = _toolpath_kind(toolpath)
            if tk not in DIAGNOSABLE_TOOLPATHS:
                raise ConfigError(
                    f"{where}: recording {i + 1}: a {kind!r} recording of a toolpath "
                    f"of kind {tk!r} ({toolpath.name}) cannot be diagnosed yet: the "
                    f"diagnosis models the toolpath kinds "
                    f"{', '.join(DIAGNOSABLE_TOOLPATHS)} (servosurf simulate and "
                    "compare handle every kind)")
        opts = {k: v for k, v in rec.items() if k not in ("path", "kind", "name")}
        name = table.name if table.name is not None else rp.name
        out.append(
            Recording(
                name=name,
                kind=kind,
                path=rp,
                data=read_recording(rp, kind),
                options=opts,
            )
        )
    names = [r.name for r in out]
    if len(set(names)) != len(names):
        raise ConfigError(f"{where}: recording names must be unique, got {names}")
    return Manifest(
        path=path,
        machine=str(run.machine),
        toolpath=toolpath,
        bandwidth=run.bandwidth,
        moving_mass=run.mass,
        disturbances=run.disturbances,
        specific_force=kt,
        recordings=tuple(out),
        run=run,
    )


def simulation_manifest(
    *,
    toolpath: str | Path,
    recording: str,
    kind: str = "surface",
    machine: str | Path | None = None,
    bandwidth: float | None = None,
    moving_mass: float | None = None,
    disturbances: str | None = None,
    workpiece: str | Path | None = None,
    x0: float | None = None,
    y0: float | None = None,
    note: str = "",
) -> str:
    """The manifest text of one simulated recording (``servosurf simulate`` writes it).

    Diagnosing a simulation with the settings it was made with is the null test:
    the verdict should be "consistent". Replacing the recording's ``path`` with a
    measured map of the same cut diagnoses the real part.

    Parameters
    ----------
    toolpath : str or Path
        Toolpath TOML (absolute path or built-in name).
    recording : str
        The recording's file, relative to the manifest.
    kind : str
        Recording kind (see :data:`KINDS`).
    machine : str or Path, optional
        Built-in machine name or machine TOML (default: the built-in machine).
    bandwidth : float, optional
        Open-loop crossover in Hz.
    moving_mass : float, optional
        m1 + m2 in kg.
    disturbances : str, optional
        Disturbance calibration name.
    workpiece : str or Path, optional
        Built-in workpiece name or workpiece TOML.
    x0, y0 : float, optional
        Centre of the map's pixel (0, 0) in the workpiece frame, m.
    note : str
        A comment line written at the top.
    """
    if kind not in KINDS:
        raise ConfigError(
            f"recording kind {kind!r} unknown (kinds: {', '.join(KINDS)})")

    def q(v) -> str:
        return '"' + str(v).replace("\\", "\\\\").replace('"', '\\"') + '"'

    lines = [
        "# Diagnosis manifest of a simulated recording. `servosurf diagnose` on it is",
        "# the null test (verdict: consistent); put a measured map of the same cut in",
        "# the recording's path to diagnose a real part.",
    ]
    if note:
        lines.append(f"# {note}")
    lines += ["[case]", f"machine = {q(machine or 'seed-prototype')}",
              f"toolpath = {q(toolpath)}"]
    if bandwidth is not None:
        lines.append(f"bandwidth = {float(bandwidth)!r}  # Hz, open-loop crossover")
    if moving_mass is not None:
        lines.append(f"moving-mass = {float(moving_mass)!r}  # kg, m1 + m2")
    if disturbances is not None:
        lines.append(f"disturbances = {q(disturbances)}")
    if workpiece is not None:
        lines.append(f"workpiece = {q(workpiece)}")
    lines += ["", "[[recording]]", f"path = {q(recording)}", f"kind = {q(kind)}"]
    if x0 is not None:
        lines.append(f"x0 = {float(x0)!r}  # m, pixel (0, 0) in the workpiece frame")
    if y0 is not None:
        lines.append(f"y0 = {float(y0)!r}  # m")
    return "\n".join(lines) + "\n"
