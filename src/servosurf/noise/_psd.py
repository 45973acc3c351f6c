"""Disturbance PSDs: parametric models, measured CSV files, Welch estimates."""

from __future__ import annotations

import csv
import io
from pathlib import Path

import numpy as np
import scipy as sp

from .._validation import check_array, check_positive
from ..errors import ConfigError
from ..servo import PSDModel

__all__ = [
    "evaluate_psd",
    "read_psd_csv",
    "write_psd_csv",
    "welch_psd",
    "frequency_grid",
    "PAPER_RECORD_LENGTH",
    "PAPER_RECORDS",
]

#: Samples per following-error record in the paper (section 4.1).
PAPER_RECORD_LENGTH = 4096
#: Records averaged per condition in the paper.
PAPER_RECORDS = 32


def frequency_grid(
    fs: float, *, fmin: float | None = None, n: int = 4000
) -> np.ndarray:
    """Geometric frequency grid from ``fmin`` to just below Nyquist, in Hz.

    Parameters
    ----------
    fs : float
        Sampling rate in Hz.
    fmin : float, optional
        Lowest frequency in Hz; default ``fs / 4096``, the first bin of the paper's
        4096-sample records (48.7 Hz at 199.6 kHz). The paper writes its integrals
        "from 0 Hz", but its records cannot resolve anything below that bin.
    n : int, default: 4000
        Number of points.

    Returns
    -------
    ndarray of shape (n,)
        Frequencies in Hz.
    """
    fs = check_positive(fs, name="fs")
    fmin = (
        fs / PAPER_RECORD_LENGTH if fmin is None else check_positive(fmin, name="fmin")
    )
    if fmin >= fs / 2:
        raise ConfigError(f"fmin must be below Nyquist ({fs / 2:g} Hz), got {fmin:g}")
    return np.geomspace(fmin, fs / 2, n)


def read_psd_csv(source: str | Path | io.TextIOBase) -> tuple[np.ndarray, np.ndarray]:
    """Read a measured PSD from CSV with header ``frequency_hz,psd``.

    Parameters
    ----------
    source : str, Path or text buffer
        The CSV file. PSD values are one-sided, in (SI unit)^2/Hz.

    Returns
    -------
    freq : ndarray
        Frequencies in Hz, strictly increasing.
    psd : ndarray
        PSD values, >= 0.
    """
    name = str(source) if isinstance(source, str | Path) else "<buffer>"
    try:
        fh = open(source, newline="") if isinstance(source, str | Path) else source
    except OSError as exc:
        raise ConfigError(f"{name}: cannot open PSD file: {exc.strerror}") from None
    with fh:
        rows = list(csv.reader(line for line in fh if not line.startswith("#")))
    if not rows or [c.strip().lower() for c in rows[0][:2]] != ["frequency_hz", "psd"]:
        raise ConfigError(f"{name}: expected a header 'frequency_hz,psd'")
    try:
        data = np.array(
            [[float(r[0]), float(r[1])] for r in rows[1:] if r], dtype=float
        )
    except (ValueError, IndexError):
        raise ConfigError(f"{name}: every row must hold two numbers") from None
    if data.shape[0] < 2:
        raise ConfigError(f"{name}: need at least 2 rows of data, got {data.shape[0]}")
    f, p = data[:, 0], data[:, 1]
    if not (np.all(np.isfinite(data)) and np.all(np.diff(f) > 0) and f[0] > 0):
        raise ConfigError(
            f"{name}: frequencies must be positive, finite and increasing"
        )
    if np.any(p < 0):
        raise ConfigError(f"{name}: PSD values must be >= 0")
    return f, p


def write_psd_csv(path: str | Path, freq: np.ndarray, psd: np.ndarray) -> None:
    """Write ``frequency_hz,psd`` CSV (Hz, unit^2/Hz) atomically."""
    from .._atomic import atomic_write

    lines = ["frequency_hz,psd"] + [
        f"{f:.9g},{p:.9g}" for f, p in zip(freq, psd, strict=True)
    ]
    atomic_write(path, lambda p: p.write_text("\n".join(lines) + "\n"))


def evaluate_psd(model: PSDModel, freq: np.ndarray) -> np.ndarray:
    """Evaluate a disturbance PSD at ``freq``.

    Parameters
    ----------
    model : PSDModel
        Parametric model, or one naming a measured CSV.
    freq : array_like
        Frequencies in Hz (> 0).

    Returns
    -------
    ndarray
        One-sided PSD in (unit)^2/Hz. A measured PSD is interpolated linearly in
        log-log coordinates and is zero outside its frequency range; the model's
        ``white`` density (squared) is added at every frequency after the roll-off.
    """
    f = np.asarray(freq, dtype=float)
    if model.csv:
        fm, pm = read_psd_csv(model.csv)
        with np.errstate(divide="ignore"):
            lp = np.log(np.maximum(pm, 1e-300))
        out = np.exp(np.interp(np.log(f), np.log(fm), lp))
        out[(f < fm[0]) | (f > fm[-1])] = 0.0
        return out + model.white**2
    law = model.level**2 * (f / model.ref_frequency) ** model.slope + model.floor**2
    return law / (1.0 + (f / model.corner) ** model.order) + model.white**2


def welch_psd(
    x: np.ndarray,
    fs: float,
    *,
    nperseg: int = PAPER_RECORD_LENGTH,
    window: str = "hann",
) -> tuple[np.ndarray, np.ndarray]:
    """One-sided PSD of a recorded time series by Welch averaging.

    Parameters
    ----------
    x : ndarray of shape (n,) or (records, n)
        Samples (SI unit). A 2-D array is a set of records (the paper's 32 x 4096);
        their PSDs are averaged. A 1-D array is cut into non-overlapping segments of
        ``nperseg``.
    fs : float
        Sampling rate in Hz.
    nperseg : int, default: 4096
        Segment length in samples.
    window : str, default: "hann"
        Window (scipy name); the PSD is scaled so its integral equals the variance.

    Returns
    -------
    freq : ndarray
        Frequencies in Hz (DC removed).
    psd : ndarray
        PSD in unit^2/Hz.
    """
    fs = check_positive(fs, name="fs")
    a = check_array(x, name="x", finite=True)
    if a.ndim == 1:
        if a.size < nperseg:
            raise ConfigError(
                f"x has {a.size} samples, need at least nperseg={nperseg}"
            )
        f, p = sp.signal.welch(
            a,
            fs=fs,
            window=window,
            nperseg=nperseg,
            noverlap=0,
            detrend="constant",
            scaling="density",
        )
    elif a.ndim == 2:
        f, p = sp.signal.welch(
            a,
            fs=fs,
            window=window,
            nperseg=min(nperseg, a.shape[1]),
            noverlap=0,
            detrend="constant",
            scaling="density",
            axis=-1,
        )
        p = p.mean(axis=0)
    else:
        raise ConfigError(f"x must be 1-D or 2-D, got shape {a.shape}")
    return f[1:], p[1:]
