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

from .._random import block
from ..errors import ConfigError
from ..servo import ServoLoop
from ._synthesis import synthesize

__all__ = ["VibrationStream", "BLOCK"]

#: White-noise block size in samples (the unit of seeding).
BLOCK = 1 << 16
#: Largest FFT of the overlap-save filter (samples): 4 x the default FIR length.
NFFT_MAX = 1 << 17


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
        self._H: dict[int, np.ndarray] = {}
        #: Expected RMS of the stream in m (from the FIR's energy).
        self.rms = float(np.sqrt(np.sum(h**2)))

    def _white(self, b0: int, b1: int) -> np.ndarray:
        w = np.empty((b1 - b0) * BLOCK)
        for b in range(b0, b1):
            k = (b - b0) * BLOCK
            block(self.seed, b).standard_normal(out=w[k : k + BLOCK])
        return w

    def _spectrum(self, nfft: int) -> np.ndarray:
        H = self._H.get(nfft)
        if H is None:
            H = self._H[nfft] = sp.fft.rfft(self.h, nfft)
        return H

    def _filter(self, w: np.ndarray) -> np.ndarray:
        """Valid-mode convolution of ``w`` with the FIR by overlap-save (m)."""
        M = self.taps
        n = w.size - M + 1
        nfft = min(NFFT_MAX, sp.fft.next_fast_len(n + M - 1, real=True))
        nfft = max(nfft, sp.fft.next_fast_len(2 * M, real=True))
        H = self._spectrum(nfft)
        step = nfft - M + 1
        out = np.empty(n)
        for k in range(0, n, step):
            m = min(step, n - k)
            seg = sp.fft.irfft(sp.fft.rfft(w[k : k + m + M - 1], nfft) * H, nfft)
            out[k : k + m] = seg[M - 1 : M - 1 + m]
        return out

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
        return self._filter(w)

    def to_memmap(
        self, path, n: int, *, chunk: int = 1 << 22, progress=None,
        workers: int | None = None,
    ) -> np.memmap:
        """Write samples ``0 .. n - 1`` to a float32 memory-mapped file (m).

        Parameters
        ----------
        path : str or Path
            Output file (``.npy`` format, float32 little endian).
        n : int
            Number of samples.
        chunk : int, default: 4194304
            Samples per computed chunk (bounds memory: about 5 x 8 bytes x chunk
            per worker).
        progress : callable, optional
            Wraps the chunk iterable (progress bar).
        workers : int, optional
            Threads computing chunks at once (default: the CPUs available to this
            process). NumPy's generators and SciPy's FFT release the GIL, so the
            chunks run in parallel; every chunk is the same whatever the count
            (block seeding), so the file is identical for any ``workers``.
        """
        import os
        from concurrent.futures import ThreadPoolExecutor

        if workers is None:
            workers = len(os.sched_getaffinity(0)) if hasattr(
                os, "sched_getaffinity") else (os.cpu_count() or 1)
        workers = max(1, int(workers))
        mm = np.lib.format.open_memmap(
            str(path), mode="w+", dtype=np.float32, shape=(n,)
        )

        def one(k: int) -> int:
            m = min(chunk, n - k)
            mm[k : k + m] = self.segment(k, m)
            return k

        starts = range(0, n, chunk)
        with ThreadPoolExecutor(max_workers=workers) as pool:
            # bounded look-ahead: at most 2 x workers chunks in flight
            done = _BoundedMap(pool, one, starts, 2 * workers)
            if progress is not None:
                done = progress(done)
            for _ in done:
                pass
        mm.flush()
        return mm


class _BoundedMap:
    """``pool.map`` in order with at most ``ahead`` submitted tasks (bounded memory);
    sized, so that progress bars know the total."""

    def __init__(self, pool, fn, items, ahead: int) -> None:
        self.pool, self.fn, self.items, self.ahead = pool, fn, items, max(1, ahead)

    def __len__(self) -> int:
        return len(self.items)

    def __iter__(self):
        from collections import deque

        it = iter(self.items)
        q: deque = deque()
        for x in it:
            q.append(self.pool.submit(self.fn, x))
            if len(q) >= self.ahead:
                break
        while q:
            yield q.popleft().result()
            for x in it:
                q.append(self.pool.submit(self.fn, x))
                break
