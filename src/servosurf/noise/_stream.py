"""Streaming vibration realisations for whole-part runs (bounded memory).

:func:`~servosurf.noise.realise` draws a whole series in one FFT, which needs the
whole series in memory. A whole face (hundreds of millions of controller samples)
needs another way: :class:`VibrationStream` filters white noise with an FIR whose
magnitude response is ``sqrt(PSD fs / 2)`` of the synthesised real positioning error.
The white noise of block ``b`` (``BLOCK`` samples) comes from
``numpy.random.default_rng([seed, b])``, so any sample range ``[k0, k0 + n)`` is
computed independently and identically, whatever the tiling or the process.
"""

from __future__ import annotations

import numpy as np
import scipy as sp

from ..errors import ConfigError
from ..servo._loop import ServoLoop
from ._synthesis import synthesize

__all__ = ["VibrationStream", "BLOCK"]

#: White-noise block size in samples (the unit of seeding).
BLOCK = 1 << 16


class VibrationStream:
    """Seeded real-positioning-error series, computable in any sample range.

    Parameters
    ----------
    loop : ServoLoop
        The closed loop whose real-error PSD (Eq 9) is realised.
    seed : int
        Seed (non-negative).
    taps : int, default: 32768
        FIR length in samples (frequency resolution ``fs / taps``; 6.1 Hz at
        199.6 kHz, well inside the structural modes' half-power widths).
    which : {"real", "following"}, default: "real"
        Realise the real tool-position error or the following error.

    Notes
    -----
    The FIR is the zero-phase impulse response of ``|H(f)| = sqrt(P(f) fs / 2)``
    centred and Hann-windowed; white noise of unit variance through it has the
    one-sided PSD ``P`` (smoothed by the window over about two bins). The output is
    Gaussian and stationary; its samples differ from :func:`realise`'s (another
    construction) but follow the same spectrum.
    """

    def __init__(
        self, loop: ServoLoop, *, seed: int, taps: int = 32768, which: str = "real"
    ) -> None:
        if not isinstance(seed, int | np.integer) or seed < 0:
            raise ConfigError(f"seed must be a non-negative integer, got {seed!r}")
        if taps < 64 or taps % 2:
            raise ConfigError(f"taps must be an even integer >= 64, got {taps!r}")
        if which not in ("real", "following"):
            raise ConfigError(f"which must be 'real' or 'following', got {which!r}")
        self.fs = loop.fs
        self.seed = int(seed)
        self.taps = int(taps)
        f = np.fft.rfftfreq(taps, 1.0 / self.fs)
        mag = np.zeros(f.size)
        band = (f >= self.fs / 4096) & (f < self.fs / 2)
        b = synthesize(loop, freq=f[band])
        psd = b.real_total if which == "real" else b.following_total
        mag[band] = np.sqrt(psd * self.fs / 2.0)
        h = np.fft.irfft(mag, taps)
        h = np.roll(h, taps // 2) * np.hanning(taps)
        self.h = h
        #: Expected RMS of the stream in m (from the FIR's energy).
        self.rms = float(np.sqrt(np.sum(h**2)))

    def _white(self, b0: int, b1: int) -> np.ndarray:
        return np.concatenate(
            [
                np.random.default_rng([self.seed, b]).standard_normal(BLOCK)
                for b in range(b0, b1)
            ]
        )

    def segment(self, k0: int, n: int) -> np.ndarray:
        """Samples ``k0 .. k0 + n - 1`` of the series (m).

        Parameters
        ----------
        k0 : int
            First global sample index (>= 0; sample k is at t = k / fs).
        n : int
            Number of samples.

        Returns
        -------
        ndarray of shape (n,)
            Tool-height error in m.
        """
        if k0 < 0 or n < 0:
            raise ConfigError(f"segment needs k0 >= 0 and n >= 0, got {k0}, {n}")
        if n == 0:
            return np.zeros(0)
        # output y[k] = sum_j h[j] w[k - j + taps - 1]: white noise is offset by
        # taps - 1 so that every k >= 0 has a full history
        w0 = k0
        w1 = k0 + n + self.taps - 1
        b0, b1 = w0 // BLOCK, (w1 - 1) // BLOCK + 1
        w = self._white(b0, b1)[w0 - b0 * BLOCK : w1 - b0 * BLOCK]
        return sp.signal.oaconvolve(w, self.h, mode="valid")

    def to_memmap(
        self, path, n: int, *, chunk: int = 1 << 22, progress=None
    ) -> np.memmap:
        """Write samples ``0 .. n - 1`` to a float32 memory-mapped file (m).

        Parameters
        ----------
        path : str or Path
            Output file (raw float32, little endian).
        n : int
            Number of samples.
        chunk : int, default: 4194304
            Samples per computed chunk (bounds memory).
        progress : callable, optional
            Wraps the chunk iterable (progress bar).
        """
        mm = np.lib.format.open_memmap(
            str(path), mode="w+", dtype=np.float32, shape=(n,)
        )
        starts = range(0, n, chunk)
        if progress is not None:
            starts = progress(starts)
        for k in starts:
            m = min(chunk, n - k)
            mm[k : k + m] = self.segment(k, m)
        mm.flush()
        return mm
