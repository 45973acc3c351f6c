"""Asynchronous spindle axial error motion: a seeded series from its PSD.

The spindle carries the workpiece; its axial error motion moves the face along z
relative to the tool and the FTS sensor's reference, outside the servo loop.
Synchronous error (the part that repeats every revolution) is the same at every
radius and leaves no mark-to-mark scatter on a flat face; the asynchronous part
does (Grejda, PhD thesis, Penn State 2002; ISO 230-7 for its measurement).
"""

from __future__ import annotations

import numpy as np
import scipy as sp

from .._random import KEYS, keyed
from .._validation import check_positive
from ..errors import ConfigError
from ..servo import PSDModel, Spindle
from ._psd import evaluate_psd

__all__ = ["psd_series", "realise_spindle_axial", "SPINDLE_STREAM"]

#: Second entropy word of the spindle's random stream: the axial error drawn for a
#: seed is independent of the vibration realisation drawn for the same seed.
SPINDLE_STREAM = KEYS["spindle"]


def psd_series(model: PSDModel, n: int, fs: float, *, rng: np.random.Generator,
               fmin: float) -> np.ndarray:
    """A stationary Gaussian series with the one-sided PSD ``model``.

    Parameters
    ----------
    model : PSDModel
        One-sided PSD, in unit^2/Hz.
    n : int
        Number of samples (>= 16).
    fs : float
        Sampling rate, in Hz.
    rng : numpy.random.Generator
        Source of the random Fourier coefficients.
    fmin : float
        Frequencies below ``fmin`` (Hz) carry no power.

    Returns
    -------
    ndarray of shape (n,)
        The series, in unit. It is drawn periodic on the next FFT-friendly length
        ``m >= n`` (bins ``k fs / m``) and its first ``n`` samples are returned; its
        expected variance is the sum of ``W(f_k) fs / m`` over the bins in
        ``[fmin, fs / 2)``, i.e. ``int W df`` over that band.
    """
    if not isinstance(n, int | np.integer) or n < 16:
        raise ConfigError(f"n must be an integer >= 16 samples, got {n!r}")
    fs = check_positive(fs, name="fs")
    fmin = check_positive(fmin, name="fmin")
    m = sp.fft.next_fast_len(int(n), real=True)
    f = np.fft.rfftfreq(m, 1.0 / fs)
    band = slice(int(np.searchsorted(f, fmin)), int(np.searchsorted(f, fs / 2.0)))
    w = evaluate_psd(model, f[band])
    # complex normal coefficients with E|g|^2 = 2 (real and imaginary parts N(0, 1))
    g = rng.standard_normal(2 * w.size).view(np.complex128)
    x = np.zeros(f.size, dtype=complex)
    x[band] = np.sqrt(w * (m * fs / 4.0)) * g
    return sp.fft.irfft(x, m, workers=-1)[:n]


def realise_spindle_axial(spindle: Spindle, n: int, fs: float, *,
                          seed: int) -> np.ndarray:
    """Seeded asynchronous axial error motion of the spindle face, in m.

    Parameters
    ----------
    spindle : Spindle
        The machine's spindle: ``axial_error`` PSD (m^2/Hz) and ``fmin`` (Hz).
    n : int
        Number of samples.
    fs : float
        Sampling rate, in Hz (the controller's).
    seed : int
        Seed (>= 0); the stream is independent of the vibration realisation's.

    Returns
    -------
    ndarray of shape (n,)
        Axial displacement of the workpiece face toward the tool, in m.
    """
    if not isinstance(seed, int | np.integer) or seed < 0:
        raise ConfigError(f"seed must be a non-negative integer, got {seed!r}")
    rng = keyed(seed, "spindle")  # default_rng([seed, SPINDLE_STREAM])
    return psd_series(spindle.axial_error, n, fs, rng=rng, fmin=spindle.fmin)
