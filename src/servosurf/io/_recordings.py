"""Recordings of a machine and its parts: following error, FRFs, cuts, maps, profiles.

:func:`read_recording` reads one recording file of a kind (:data:`RECORDING_KINDS`)
into SI arrays; ``servosurf diagnose`` reads a manifest's recordings with it.
Formats by kind:

``following-error``
    CSV ``time_s,following_error_m`` with optional ``command_m``, ``force_n`` and
    ``record`` columns, or NPZ with ``fs_hz`` (or ``time_s``) and
    ``following_error_m`` of shape (n,) or (records, n), optional ``command_m`` and
    ``force_n`` of the same shape. In CSV a new record starts where ``time_s``
    decreases or ``record`` changes; every record must be uniformly sampled.
``frf-open-loop``, ``frf-closed-loop``, ``frf-force``
    CSV ``frequency_hz,real,imag`` (:func:`read_frf_csv`; values non-zero).
``cut``
    CSV or NPZ ``time_s,force_n,following_error_m``.
``surface``
    Any file :func:`read_surface` accepts, or NPZ with ``z``, ``dx``, ``dy`` (m;
    optional ``x0``, ``y0``, the centre of pixel (0, 0), m).
``profile``
    Any file :func:`read_profile` accepts, or NPZ with ``z``, ``dx`` (m; optional
    ``x0``).

Errors are one-line :class:`~servosurf.errors.ConfigError` messages naming the file
and the column or key.
"""

from __future__ import annotations

import csv
import io
from pathlib import Path

import numpy as np

from .._atomic import atomic_write
from ..errors import ConfigError
from ._registry import read_profile, read_surface

__all__ = ["RECORDING_KINDS", "read_frf_csv", "read_recording", "write_frf_csv"]

#: Recording kinds :func:`read_recording` reads.
RECORDING_KINDS = (
    "following-error",
    "frf-open-loop",
    "frf-closed-loop",
    "frf-force",
    "cut",
    "surface",
    "profile",
)


def read_frf_csv(source: str | Path | io.TextIOBase) -> tuple[np.ndarray, np.ndarray]:
    """Read an FRF from CSV with header ``frequency_hz,real,imag``.

    A UTF-8 byte-order mark is tolerated and a row at 0 Hz (DC, where a measured
    FRF carries no phase information and the models' logs are undefined) is
    dropped; other frequencies must be positive and increasing.

    Returns
    -------
    freq : ndarray
        Frequencies in Hz (positive, increasing).
    frf : ndarray of complex
        The response (SI units of output per input).
    """
    name = str(source) if isinstance(source, str | Path) else "<buffer>"
    try:
        fh = (
            open(source, newline="", encoding="utf-8-sig")
            if isinstance(source, str | Path)
            else source
        )
    except OSError as exc:
        raise ConfigError(f"{name}: cannot open FRF file: {exc.strerror}") from None
    with fh:
        rows = list(csv.reader(line for line in fh if not line.startswith("#")))
    if not rows or [c.strip().lower() for c in rows[0][:3]] != [
        "frequency_hz",
        "real",
        "imag",
    ]:
        raise ConfigError(f"{name}: expected a header 'frequency_hz,real,imag'")
    try:
        data = np.array([[float(v) for v in r[:3]] for r in rows[1:] if r], dtype=float)
    except ValueError:
        raise ConfigError(f"{name}: every row must hold three numbers") from None
    if data.ndim != 2 or data.shape[0] < 3 or data.shape[1] != 3:
        raise ConfigError(f"{name}: need at least 3 rows of three numbers")
    if data.shape[0] > 3 and data[0, 0] == 0.0:
        data = data[1:]  # DC row
    f = data[:, 0]
    if not (np.all(np.isfinite(data)) and f[0] > 0 and np.all(np.diff(f) > 0)):
        raise ConfigError(
            f"{name}: frequencies must be positive, finite and increasing"
        )
    return f, data[:, 1] + 1j * data[:, 2]


def write_frf_csv(path: str | Path, freq: np.ndarray, frf: np.ndarray) -> None:
    """Write ``frequency_hz,real,imag`` CSV atomically."""
    lines = ["frequency_hz,real,imag"] + [
        f"{f:.10g},{h.real:.10g},{h.imag:.10g}" for f, h in zip(freq, frf, strict=True)
    ]
    atomic_write(path, lambda p: p.write_text("\n".join(lines) + "\n"))


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
        One of :data:`RECORDING_KINDS`.

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
    raise ConfigError(
        f"unknown recording kind {kind!r} (kinds: {', '.join(RECORDING_KINDS)})"
    )
