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

The ``[case]`` keys may also sit at the top level and ``[[recordings]]`` is
accepted for ``[[recording]]``. Paths are relative to the manifest. Kinds and
formats:

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

import csv
import difflib
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import ConfigError

__all__ = [
    "DIAGNOSABLE_TOOLPATHS",
    "KINDS",
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

#: Recording kinds accepted in a manifest.
KINDS = (
    "following-error",
    "frf-open-loop",
    "frf-closed-loop",
    "frf-force",
    "cut",
    "surface",
    "profile",
)

_CASE_KEYS = {
    "machine",
    "toolpath",
    "bandwidth",
    "moving-mass",
    "disturbances",
    "specific-cutting-force",
    "workpiece",
    "name",
    "description",
}
_ALIASES = {
    "mass": "moving-mass",
    "moving_mass": "moving-mass",
    "bandwidth-hz": "bandwidth",
    "bandwidth_hz": "bandwidth",
    "moving-mass-kg": "moving-mass",
    "specific_cutting_force": "specific-cutting-force",
}
_REC_KEYS = {
    "path",
    "form-order",
    "kind",
    "name",
    "condition",
    "radius",
    "angle-start",
    "start",
    "direction",
    "x0",
    "y0",
    "description",
}


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
        :func:`read_recording`).
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
    """

    path: Path
    machine: str
    toolpath: Path | None
    bandwidth: float | None
    moving_mass: float | None
    disturbances: str | None
    specific_force: float | None
    recordings: tuple[Recording, ...]


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


def _number(value: Any, name: str, where: str, *, positive: bool = True) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise ConfigError(f"{where}: {name} must be a number, got {value!r}")
    v = float(value)
    if not math.isfinite(v) or (positive and v <= 0):
        raise ConfigError(
            f"{where}: {name} must be a positive finite number, got {v!r}"
        )
    return v


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

    path = Path(path)
    if not path.is_file():
        raise ConfigError(f"manifest {path}: no such file")
    try:
        data = load_toml(path)
    except ConfigError as exc:
        raise ConfigError(f"manifest {exc}") from None
    base = path.parent
    case = dict(data.pop("case", {}) or {})
    recs = data.pop("recording", None)
    if recs is None:
        recs = data.pop("recordings", None)
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
    where = str(path)
    machine = str(norm.get("machine", "seed-prototype"))
    from ..servo import builtin_machines

    if machine not in builtin_machines():
        mp = (base / machine) if not Path(machine).is_absolute() else Path(machine)
        if not mp.is_file():
            raise ConfigError(
                f"{where}: machine {machine!r}: no such file and no "
                f"built-in of that name ({', '.join(builtin_machines())})"
            )
        machine = str(mp)
    toolpath = None
    if "toolpath" in norm:
        tp = Path(str(norm["toolpath"]))
        cands = [
            tp if tp.is_absolute() else base / tp,
            Path("toolpaths") / tp,
            Path("toolpaths") / (tp.name if tp.suffix else tp.name + ".toml"),
        ]
        found = next((c for c in cands if c.is_file()), None)
        if found is None:  # a built-in toolpath by name (servosurf toolpaths)
            from ..toolpath import builtin_toolpaths

            name = tp.stem if tp.suffix == ".toml" else tp.name
            found = builtin_toolpaths().get(name)
        if found is None:
            raise ConfigError(
                f"{where}: toolpath {str(tp)!r}: no such file and no built-in of that "
                f"name ({', '.join(builtin_toolpaths())})"
            )
        toolpath = found
    bandwidth = (
        _number(norm["bandwidth"], "bandwidth (Hz)", where)
        if "bandwidth" in norm
        else None
    )
    mass = (
        _number(norm["moving-mass"], "moving-mass (kg)", where)
        if "moving-mass" in norm
        else None
    )
    kt = None
    if "workpiece" in norm:
        wp = Path(str(norm["workpiece"]))
        cands = [
            wp if wp.is_absolute() else base / wp,
            Path("workpieces") / wp,
            Path("workpieces") / (wp.name + ".toml"),
        ]
        found = next((c for c in cands if c.is_file()), None)
        if found is None:  # a built-in workpiece by name
            from ..cutting import builtin_workpieces

            name = wp.stem if wp.suffix == ".toml" else wp.name
            found = builtin_workpieces().get(name)
        if found is None:
            raise ConfigError(
                f"{where}: workpiece {str(wp)!r}: no such file and no built-in of that "
                f"name ({', '.join(builtin_workpieces())})"
            )
        from ..cutting import load_workpiece

        kt = float(load_workpiece(found).material.specific_thrust_pressure)
    if "specific-cutting-force" in norm:
        kt = _number(
            norm["specific-cutting-force"], "specific-cutting-force (N/m^2)", where
        )
    dist = norm.get("disturbances")
    if recs is None or not isinstance(recs, list) or not recs:
        raise ConfigError(
            f"{where}: no [[recording]] entries (each needs path and kind)"
        )
    out = []
    for i, rec in enumerate(recs):
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
        rp = Path(str(rec["path"]))
        rp = rp if rp.is_absolute() else base / rp
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
        name = str(rec.get("name", rp.name))
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
        machine=machine,
        toolpath=toolpath,
        bandwidth=bandwidth,
        moving_mass=mass,
        disturbances=None if dist is None else str(dist),
        specific_force=kt,
        recordings=tuple(out),
    )


# ---------------------------------------------------------------- readers
def _read_csv(path: Path, required: tuple[str, ...], optional: tuple[str, ...]):
    try:
        with open(path, newline="", encoding="utf-8-sig") as fh:  # BOM-tolerant
            rows = [
                r for r in csv.reader(ln for ln in fh if not ln.startswith("#")) if r
            ]
    except (OSError, UnicodeDecodeError) as exc:
        raise ConfigError(f"{path}: cannot read CSV: {exc}") from None
    if not rows:
        raise ConfigError(f"{path}: empty file")
    header = [c.strip().lower() for c in rows[0]]
    missing = [c for c in required if c not in header]
    if missing:
        raise ConfigError(
            f"{path}: bad CSV header {','.join(header)!r}: expected "
            f"columns {','.join(required)}"
            + (f" (optional {','.join(optional)})" if optional else "")
        )
    cols = {c: header.index(c) for c in (*required, *optional) if c in header}
    try:
        arr = np.array(
            [[float(r[i]) for i in cols.values()] for r in rows[1:]], dtype=float
        )
    except (ValueError, IndexError):
        raise ConfigError(
            f"{path}: every row must hold numbers in the columns {','.join(cols)}"
        ) from None
    if arr.ndim != 2 or arr.shape[0] < 8:
        raise ConfigError(f"{path}: need at least 8 rows of data")
    if not np.all(np.isfinite(arr)):
        raise ConfigError(f"{path}: non-finite values")
    return {c: arr[:, j] for j, c in enumerate(cols)}


def _fs_from_time(t: np.ndarray, path: Path) -> float:
    """Sampling rate (Hz) of a record's time column (s).

    The step is the least-squares slope of time against sample number, and every
    time must lie within a quarter step of that uniform grid: times printed with a few
    significant digits (``%.6g`` puts 1e-5 s of rounding on a 1e-4 s step) are
    accepted, a missing or repeated sample is not.
    """
    dt = np.diff(t)
    if dt.size == 0 or not np.all(dt > 0):
        raise ConfigError(f"{path}: time_s must increase within a record")
    k = np.arange(t.size) - 0.5 * (t.size - 1)
    step = float(k @ (t - t.mean())) / float(k @ k)  # least-squares step
    off = t - (t.mean() + step * k)
    if np.max(np.abs(off)) > 0.25 * step:
        i = int(np.argmax(np.abs(off)))
        raise ConfigError(
            f"{path}: time_s must be uniformly sampled (sample {i} at "
            f"{t[i]!r} s is {off[i] / step:+.2f} steps off the grid of "
            f"{step:.6g} s)"
        )
    return 1.0 / step


def _load_npz(path: Path) -> dict:
    try:
        with np.load(path, allow_pickle=False) as z:
            return {k: z[k] for k in z.files}
    except (OSError, ValueError) as exc:
        raise ConfigError(f"{path}: cannot read NPZ: {exc}") from None


def _read_following(path: Path) -> dict:
    if path.suffix.lower() == ".npz":
        z = _load_npz(path)
        if "following_error_m" not in z:
            raise ConfigError(f"{path}: NPZ needs 'following_error_m' (and fs_hz)")
        fe = np.atleast_2d(np.asarray(z["following_error_m"], dtype=float))
        if "fs_hz" in z:
            fs = float(np.asarray(z["fs_hz"]).ravel()[0])
        elif "time_s" in z:
            fs = _fs_from_time(np.atleast_2d(z["time_s"])[0], path)
        else:
            raise ConfigError(f"{path}: NPZ needs 'fs_hz' or 'time_s'")
        t0 = np.zeros(fe.shape[0])
        if "time_s" in z:
            t0 = np.atleast_2d(np.asarray(z["time_s"], dtype=float))[:, 0]
            if t0.size != fe.shape[0]:
                t0 = np.zeros(fe.shape[0])
        recs = []
        for i in range(fe.shape[0]):
            rec = {"fe": fe[i], "t0": float(t0[i])}
            for key, name in (("command_m", "command"), ("force_n", "force")):
                if key in z:
                    a = np.atleast_2d(np.asarray(z[key], dtype=float))
                    if a.shape != fe.shape:
                        raise ConfigError(
                            f"{path}: {key} shape {a.shape} differs from "
                            f"following_error_m {fe.shape}"
                        )
                    rec[name] = a[i]
            recs.append(rec)
    else:
        cols = _read_csv(
            path, ("time_s", "following_error_m"), ("command_m", "force_n", "record")
        )
        t = cols["time_s"]
        brk = np.nonzero(np.diff(t) <= 0)[0] + 1
        if "record" in cols:
            brk = np.union1d(brk, np.nonzero(np.diff(cols["record"]) != 0)[0] + 1)
        bounds = np.concatenate([[0], brk, [t.size]]).astype(int)
        recs, fss = [], []
        for a, b in zip(bounds[:-1], bounds[1:], strict=True):
            if b - a < 8:
                raise ConfigError(f"{path}: a record has fewer than 8 samples")
            fss.append(_fs_from_time(t[a:b], path))
            rec = {"fe": cols["following_error_m"][a:b], "t0": float(t[a])}
            if "command_m" in cols:
                rec["command"] = cols["command_m"][a:b]
            if "force_n" in cols:
                rec["force"] = cols["force_n"][a:b]
            recs.append(rec)
        fs = float(np.median(fss))
    if not (np.isfinite(fs) and fs > 0):
        raise ConfigError(f"{path}: sampling rate must be positive, got {fs!r}")
    for rec in recs:
        if not np.all(np.isfinite(rec["fe"])):
            raise ConfigError(f"{path}: following_error_m has non-finite values")
    return {"fs": fs, "records": recs}


def _read_cut(path: Path) -> dict:
    if path.suffix.lower() == ".npz":
        z = _load_npz(path)
        need = ("time_s", "force_n", "following_error_m")
        if not all(k in z for k in need):
            raise ConfigError(f"{path}: NPZ needs {', '.join(need)}")
        cols = {k: np.asarray(z[k], dtype=float).ravel() for k in need}
    else:
        cols = _read_csv(path, ("time_s", "force_n", "following_error_m"), ())
    fs = _fs_from_time(cols["time_s"], path)
    return {
        "fs": fs,
        "t": cols["time_s"],
        "force": cols["force_n"],
        "fe": cols["following_error_m"],
    }


def _read_frf(path: Path) -> dict:
    from ..servo import read_frf_csv

    f, h = read_frf_csv(path)
    if np.any(h == 0):
        raise ConfigError(f"{path}: FRF values must be non-zero")
    return {"freq": f, "frf": h}


def _read_surface(path: Path) -> dict:
    if path.suffix.lower() == ".npz":
        z = _load_npz(path)
        if not all(k in z for k in ("z", "dx", "dy")):
            raise ConfigError(f"{path}: surface NPZ needs z, dx, dy (m)")
        zz = np.asarray(z["z"], dtype=float)
        out = {
            "z": zz,
            "dx": float(np.ravel(z["dx"])[0]),
            "dy": float(np.ravel(z["dy"])[0]),
        }
        for k in ("x0", "y0"):
            if k in z:
                out[k] = float(np.ravel(z[k])[0])
    else:
        from ..io import read_surface

        s = read_surface(path)
        if s.dx is None or s.dy is None:
            raise ConfigError(f"{path}: the surface has no lateral calibration")
        out = {"z": np.asarray(s.z, dtype=float), "dx": s.dx, "dy": s.dy}
    if out["z"].ndim != 2 or min(out["z"].shape) < 4:
        raise ConfigError(f"{path}: z must be a 2-D map, got shape {out['z'].shape}")
    if not (out["dx"] > 0 and out["dy"] > 0):
        raise ConfigError(f"{path}: dx and dy must be positive pixel sizes in m")
    if np.isfinite(out["z"]).sum() < 16:
        raise ConfigError(f"{path}: fewer than 16 valid pixels")
    return out


def _read_profile(path: Path) -> dict:
    if path.suffix.lower() == ".npz":
        z = _load_npz(path)
        if not all(k in z for k in ("z", "dx")):
            raise ConfigError(f"{path}: profile NPZ needs z and dx (m)")
        out = {
            "z": np.asarray(z["z"], dtype=float).ravel(),
            "dx": float(np.ravel(z["dx"])[0]),
        }
        if "x0" in z:
            out["x0"] = float(np.ravel(z["x0"])[0])
    else:
        try:
            from ..io import read_profile  # written by another engineer
        except ImportError:
            raise ConfigError(
                f"{path}: only .npz profiles (z, dx) can be read here "
                "(servosurf.io.read_profile is unavailable)"
            ) from None
        p = read_profile(path)
        out = {"z": np.asarray(p.z, dtype=float), "dx": float(p.dx), "x0": float(p.x0)}
    if out["z"].size < 8 or not out["dx"] > 0:
        raise ConfigError(f"{path}: a profile needs >= 8 samples and dx > 0 m")
    return out


def read_recording(path: str | Path, kind: str) -> dict:
    """Read one recording file of a given kind.

    Parameters
    ----------
    path : str or Path
        The file.
    kind : str
        One of :data:`KINDS`.

    Returns
    -------
    dict
        ``following-error``: ``fs`` (Hz), ``records`` (list of dicts with ``fe``,
        optional ``command``, ``force``; m, m, N); ``frf-*``: ``freq`` (Hz),
        ``frf`` (complex); ``cut``: ``fs``, ``t`` (s), ``force`` (N), ``fe`` (m);
        ``surface``: ``z`` (m, NaN invalid), ``dx``, ``dy`` (m), optional ``x0``,
        ``y0``; ``profile``: ``z``, ``dx``, optional ``x0`` (m).

    Raises
    ------
    ConfigError
        When the file cannot be read or has the wrong layout.
    """
    path = Path(path)
    if kind == "following-error":
        return _read_following(path)
    if kind.startswith("frf-"):
        return _read_frf(path)
    if kind == "cut":
        return _read_cut(path)
    if kind == "surface":
        return _read_surface(path)
    if kind == "profile":
        return _read_profile(path)
    raise ConfigError(f"unknown recording kind {kind!r} (kinds: {', '.join(KINDS)})")


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
