"""One-sided spatial power spectral density and spectral peak finding."""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import scipy.signal

from .._validation import check_array, check_in_range, check_positive
from ..errors import ConfigError

__all__ = ["psd_1d", "find_peaks_spectrum", "sampling_alias_bands"]

#: Rows (profiles) with a larger fraction of NaN samples are skipped by psd_1d.
MAX_NAN_FRACTION: float = 0.1

#: Half-width, in frequency bins, of the band integrated for a peak's amplitude.
#: A Hann-windowed sine spreads over +-2 bins; 3 also covers a sine between bins.
PEAK_HALF_WIDTH_BINS: int = 3


def _fill_nan_1d(row: np.ndarray) -> np.ndarray:
    """Linear interpolation over NaN, constant extension beyond the valid ends."""
    ok = np.isfinite(row)
    if ok.all():
        return row
    i = np.arange(row.size)
    return np.interp(i, i[ok], row[ok])


def psd_1d(
    z: np.ndarray,
    dx: float,
    *,
    window: str | None = "hann",
    detrend: str | None = "linear",
    axis: int = -1,
    max_nan_fraction: float = MAX_NAN_FRACTION,
) -> tuple[np.ndarray, np.ndarray]:
    """Return the one-sided spatial PSD along one direction, averaged over profiles.

    Parameters
    ----------
    z : ndarray of shape (..., n)
        Heights in m. A 1-D profile, or a map whose profiles run along ``axis``
        (for a :class:`Surface` whose cutting direction is x: ``surface.z`` with
        ``axis=-1``).
    dx : float
        Sampling step along ``axis``, in m.
    window : str or None, default: "hann"
        Taper applied to each profile: a name understood by
        :func:`scipy.signal.get_window`; ``None`` or ``"boxcar"`` for none.
    detrend : {"linear", "constant", None}, default: "linear"
        Trend removed from each profile before windowing.
    axis : int, default: -1
        Axis along which the profiles run (the cutting direction).
    max_nan_fraction : float, default: 0.1
        Profiles with a larger fraction of NaN samples are skipped; the others have
        their NaN samples linearly interpolated (held constant beyond the last
        valid sample) before the transform.

    Returns
    -------
    freq : ndarray of shape (n // 2 + 1,)
        Spatial frequency, in 1/m (0 to the Nyquist frequency ``1 / (2 dx)``).
    psd : ndarray of shape (n // 2 + 1,)
        One-sided PSD, in m^2 / (1/m) = m^3, averaged over the profiles used.

    Raises
    ------
    ConfigError
        If ``dx`` is not positive, a profile has fewer than 2 samples, or every
        profile has too many NaN samples.

    See Also
    --------
    find_peaks_spectrum

    Notes
    -----
    Optics convention (ISO 10110-8, ISO 25178-2 spectral analysis): the one-sided
    PSD integrates to the variance of the (detrended) profile,
    ``sum(psd) * df ~ var(z)`` with ``df = 1 / (n dx)``. The window's power loss is
    compensated (periodogram divided by ``sum(w^2)``), so the equality is exact
    on average for stationary profiles and holds to a few per cent for a single
    profile. Computed with :func:`scipy.signal.periodogram` (``scaling="density"``).

    Examples
    --------
    >>> import numpy as np
    >>> from servosurf.metrology import psd_1d
    >>> x = np.arange(1024) * 1e-6
    >>> z = 2e-9 * np.sin(2 * np.pi * 64e3 * x)
    >>> f, p = psd_1d(z, 1e-6)
    >>> round(float(f[np.argmax(p)]))  # 1/m
    64453
    """
    dx = check_positive(dx, name="dx")
    max_nan_fraction = check_in_range(
        max_nan_fraction, name="max_nan_fraction", low=0.0, high=1.0
    )
    z = check_array(z, name="z")
    if z.ndim == 0:
        raise ConfigError(f"z must be at least 1-dimensional, got shape {z.shape}")
    if not -z.ndim <= int(axis) < z.ndim:
        raise ConfigError(f"axis must be in [-{z.ndim}, {z.ndim - 1}], got {axis}")
    if detrend not in ("linear", "constant", None):
        raise ConfigError(
            f"detrend must be 'linear', 'constant' or None, got {detrend!r}"
        )
    rows = np.moveaxis(z, int(axis), -1).reshape(-1, z.shape[int(axis)])
    n = rows.shape[1]
    if n < 2:
        raise ConfigError(f"profiles must have at least 2 samples, got {n}")
    nan_frac = np.mean(~np.isfinite(rows), axis=1)
    use = nan_frac <= max_nan_fraction
    use &= nan_frac < 1.0
    if not use.any():
        raise ConfigError(
            f"every profile of the map has more than {max_nan_fraction:.0%} invalid "
            "samples (it is mostly dropouts): crop the map to its valid region or "
            "use a measurement with fewer dropouts"
        )
    data = np.array([_fill_nan_1d(r) for r in rows[use]])
    win = "boxcar" if window is None else window
    try:
        freq, p = scipy.signal.periodogram(
            data,
            fs=1.0 / dx,
            window=win,
            detrend=False if detrend is None else detrend,
            scaling="density",
            axis=-1,
        )
    except ValueError as exc:
        raise ConfigError(f"window {window!r} is not usable: {exc}") from None
    return freq, p.mean(axis=0)


def find_peaks_spectrum(
    freq: np.ndarray,
    psd: np.ndarray,
    *,
    n: int = 5,
    min_prominence: float = 0.5,
    fmin: float | None = None,
    fmax: float | None = None,
    speed: float | None = None,
) -> list[dict[str, Any]]:
    """Find the strongest peaks of a PSD with sub-bin frequency interpolation.

    Parameters
    ----------
    freq : ndarray of shape (m,)
        Equally spaced spatial frequencies, in 1/m (as returned by :func:`psd_1d`).
    psd : ndarray of shape (m,)
        One-sided PSD, in m^3.
    n : int, default: 5
        Maximum number of peaks returned.
    min_prominence : float, default: 0.5
        Minimum prominence of a peak on the log10 PSD, in decades (0.5: the peak
        stands about three times above the surrounding floor, enough for spectra
        averaged over many profiles; raise it for a single noisy profile).
    fmin, fmax : float or None, default: None
        Only peaks with ``fmin <= freq <= fmax`` (1/m) are considered; the DC bin
        is always ignored.
    speed : float or None, default: None
        Surface speed in m/s. When given, each peak also reports the equivalent
        temporal frequency ``freq * speed`` in Hz.

    Returns
    -------
    list of dict
        Strongest (largest PSD) first. Each dict holds ``freq_per_m`` (1/m,
        interpolated), ``wavelength_m`` (m), ``amplitude_m`` (m, zero-to-peak
        amplitude of the equivalent sinusoid), ``psd_m3`` (m^3, interpolated peak
        value), ``prominence_decades``, ``index`` (the bin of the maximum) and,
        with ``speed``, ``temporal_freq_hz`` (Hz).

    Raises
    ------
    ConfigError
        If the arrays differ in shape, are too short, or the frequencies are not
        equally spaced and increasing.

    See Also
    --------
    psd_1d

    Notes
    -----
    Peaks are local maxima of ``log10(psd)`` found by
    :func:`scipy.signal.find_peaks` with the given prominence. The frequency is
    refined by a parabola through the log PSD at the maximum bin and its two
    neighbours (exact for a Gaussian-shaped main lobe, within about 0.1 bin for
    a Hann window). The amplitude is ``sqrt(2 * sum(psd - background) * df)``
    over +-:data:`PEAK_HALF_WIDTH_BINS` bins around the maximum, i.e. the
    amplitude of the sinusoid carrying the peak's variance (Parseval); the
    background is the median PSD of the three bins on each side just outside that
    band.
    """
    f = check_array(freq, name="freq", ndim=1, min_size=3, finite=True)
    p = check_array(psd, name="psd", ndim=1, min_size=3)
    if f.shape != p.shape:
        raise ConfigError(
            f"freq and psd must have the same shape, got {f.shape} and {p.shape}"
        )
    df = f[1] - f[0]
    if df <= 0 or not np.allclose(np.diff(f), df, rtol=1e-6, atol=0):
        raise ConfigError("freq must be equally spaced and increasing")
    if int(n) < 1:
        raise ConfigError(f"n must be >= 1, got {n!r}")
    min_prominence = check_positive(min_prominence, name="min_prominence")
    if speed is not None:
        speed = check_positive(speed, name="speed")
    floor = np.nanmax(p) * 1e-30 if np.any(p > 0) else 1e-300
    logp = np.log10(np.where(np.isfinite(p) & (p > floor), p, floor))
    idx, props = scipy.signal.find_peaks(logp, prominence=min_prominence)
    keep = idx > 0
    if fmin is not None:
        keep &= f[idx] >= float(fmin)
    if fmax is not None:
        keep &= f[idx] <= float(fmax)
    idx, prom = idx[keep], props["prominences"][keep]
    order = np.argsort(p[idx])[::-1][: int(n)]
    peaks: list[dict[str, Any]] = []
    for k, pr in zip(idx[order], prom[order], strict=True):
        k = int(k)
        delta, peak_log = 0.0, logp[k]
        if 0 < k < f.size - 1:
            a, b, c = logp[k - 1], logp[k], logp[k + 1]
            denom = a - 2.0 * b + c
            if denom < 0:
                delta = float(np.clip(0.5 * (a - c) / denom, -0.5, 0.5))
                peak_log = b - 0.25 * (a - c) * delta
        lo = max(1, k - PEAK_HALF_WIDTH_BINS)
        hi = min(f.size, k + PEAK_HALF_WIDTH_BINS + 1)
        side = np.concatenate([p[max(1, lo - 3) : lo], p[hi : hi + 3]])
        side = side[np.isfinite(side)]
        base = float(np.median(side)) if side.size else 0.0
        power = float(np.nansum(np.clip(p[lo:hi] - base, 0.0, None)) * df)
        fk = float(f[k] + delta * df)
        item: dict[str, Any] = {
            "freq_per_m": fk,
            "wavelength_m": 1.0 / fk if fk > 0 else math.inf,
            "amplitude_m": math.sqrt(2.0 * max(power, 0.0)),
            "psd_m3": float(10.0**peak_log),
            "prominence_decades": float(pr),
            "index": k,
        }
        if speed is not None:
            item["temporal_freq_hz"] = fk * speed
        peaks.append(item)
    return peaks


def sampling_alias_bands(
    spacing, pitch: float, *, harmonics=(1, 2, 3)
) -> list[dict[str, Any]]:
    """Spatial frequencies at which a sampled tool path shows on a pixel grid.

    A tool path sampled every ``spacing`` metres along the scan direction leaves a
    periodic pattern at ``k / spacing`` (the samples and their harmonics); a pixel
    grid of ``pitch`` folds it to ``|k / spacing - m / pitch|`` below the Nyquist
    frequency ``1 / (2 pitch)``. In servosurf's surfaces this is the controller
    rate: ``spacing = v / fs`` (0.21 um at 42.3 mm/s and 199.6 kHz on 0.55 um
    pixels folds to about 720 mm^-1).

    Parameters
    ----------
    spacing : float or array_like
        Path sample spacing along the scan direction, m; an array spans the range
        over the analysed region (the surface speed changes with the radius).
    pitch : float
        Pixel pitch along the scan direction, m.
    harmonics : sequence of int, default: (1, 2, 3)
        Harmonics ``k`` of the sampling frequency.

    Returns
    -------
    list of dict
        Per harmonic: ``harmonic``, ``low_per_m`` and ``high_per_m`` (1/m), the
        band the fold of ``k / spacing`` covers over the ``spacing`` range.
    """
    s = np.atleast_1d(np.asarray(spacing, dtype=float))
    if s.size == 0 or np.any(~np.isfinite(s)) or np.any(s <= 0):
        raise ConfigError("spacing must be positive, finite sample spacings in m")
    pitch = check_positive(pitch, name="pitch")
    s = np.linspace(s.min(), s.max(), 65) if s.size > 1 else s
    fp = 1.0 / pitch
    out = []
    for k in harmonics:
        f = int(k) / s
        a = np.abs(f - np.round(f / fp) * fp)
        out.append(
            {
                "harmonic": int(k),
                "low_per_m": float(a.min()),
                "high_per_m": float(a.max()),
            }
        )
    return out
