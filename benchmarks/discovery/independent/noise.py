"""Noise synthesis of the independent generator: coloured Gaussian time series.

A white Gaussian sequence of twice the needed length (rounded up to a power of
two) is filtered in the frequency domain by the amplitude response
``sqrt(W(f) fs / 2)`` (the one-sided PSD of unit-variance white noise is
``2 / fs``), and the middle part is kept, so a realisation is not periodic over the
record. Content below ``f_lo`` is removed: the machine's documented band starts at
``fs / 4096`` (48.7 Hz), a real machine's base vibration continues down to the
record length (``f_lo = 1 / duration``).

The sources are realised in the time domain and run through the generator's own
loop (:mod:`loop`), so the loop's nonlinear effects act on the noise too.
"""

from __future__ import annotations

import math

import numpy as np


def colored(psd, n: int, fs: float, rng, *, f_lo: float, f_hi: float | None = None):
    """Gaussian time series whose one-sided PSD is ``psd(f)`` on ``[f_lo, f_hi)``.

    Parameters
    ----------
    psd : callable
        ``psd(f)`` in unit^2/Hz for ``f`` in Hz (> 0).
    n : int
        Number of samples.
    fs : float
        Sampling rate in Hz.
    rng : numpy.random.Generator
        Source of randomness.
    f_lo : float
        Lowest frequency kept, Hz.
    f_hi : float, optional
        Highest frequency kept, Hz (default Nyquist).

    Returns
    -------
    ndarray of shape (n,)
        The realisation in the PSD's unit.
    """
    big = 1 << int(math.ceil(math.log2(max(2 * n, 64))))
    w = rng.standard_normal(big)
    spec = np.fft.rfft(w)
    f = np.fft.rfftfreq(big, 1.0 / fs)
    keep = f >= f_lo
    if f_hi is not None:
        keep &= f < f_hi
    keep[0] = False
    gain = np.zeros(f.size)
    gain[keep] = np.sqrt(psd(f[keep]) * fs / 2.0)
    x = np.fft.irfft(spec * gain, big)
    start = (big - n) // 2
    return x[start : start + n].copy()


def band_power(psd, fs: float, *, f_lo: float, f_hi: float | None = None,
               n: int = 200000) -> float:
    """Integral of ``psd`` over ``[f_lo, f_hi]`` (unit^2), log-spaced trapezoid."""
    f_hi = fs / 2 if f_hi is None else f_hi
    f = np.geomspace(f_lo, f_hi, n)
    return float(np.trapezoid(psd(f), f))


def sources(mach, n: int, rng, *, f_lo: float, scale: dict | None = None) -> dict:
    """Realisations of the three stochastic sources of the machine file.

    Parameters
    ----------
    mach : Machine
        The machine (its ``psd`` dict: sensor m^2/Hz, current A^2/Hz, base
        m^2/Hz).
    n : int
        Samples at the controller rate.
    rng : numpy.random.Generator
        Source of randomness.
    f_lo : float
        Lowest frequency, Hz (see module doc).
    scale : dict, optional
        PSD factors per source (a misspecified noise model).

    Returns
    -------
    dict
        ``sensor`` (m), ``current`` (A), ``base`` (m), each of shape (n,).
    """
    scale = scale or {}
    out = {}
    for name in ("sensor", "current", "base"):
        p = mach.psd[name]
        c = float(scale.get(name, 1.0))
        out[name] = math.sqrt(c) * colored(p, n, mach.fs, rng, f_lo=f_lo)
    return out
