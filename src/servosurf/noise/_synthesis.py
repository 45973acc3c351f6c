"""Frequency-domain error synthesis (seed paper Eqs 8 to 12) and realisations."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy as sp

from .._random import root
from .._validation import check_positive
from ..errors import ConfigError
from ..servo import Disturbances, ServoLoop
from ._psd import evaluate_psd, frequency_grid

__all__ = [
    "SOURCES",
    "ErrorBudget",
    "synthesize",
    "cas",
    "realise",
    "Realisation",
]

#: Above this many frequency bins, realisations interpolate the FRFs from a dense grid.
_DENSE_LIMIT = 120_000

#: Stochastic sources (Table 1) with the loop input each enters at and its unit.
SOURCES = {
    "sensor_noise": ("sensor_noise", "m^2/Hz"),
    "current_noise": ("current_noise", "A^2/Hz"),
    "base_vibration": ("base", "m^2/Hz"),
}


def cas(freq: np.ndarray, psd: np.ndarray) -> np.ndarray:
    """Cumulative amplitude spectrum (Eq 11): ``sqrt(int_0^f PSD df)``.

    Parameters
    ----------
    freq : ndarray of shape (n,)
        Frequencies in Hz, increasing.
    psd : ndarray of shape (n,)
        One-sided PSD in m^2/Hz.

    Returns
    -------
    ndarray of shape (n,)
        CAS in m; its last value is the RMS (Eq 12). Integration is trapezoidal from
        the first grid frequency.
    """
    return np.sqrt(sp.integrate.cumulative_trapezoid(psd, freq, initial=0.0))


@dataclass(frozen=True, eq=False)
class ErrorBudget:
    """Synthesised real positioning error and following error (Eqs 8 to 12).

    Attributes
    ----------
    freq : ndarray of shape (n,)
        Frequencies in Hz.
    disturbance : dict of str to ndarray
        Disturbance PSDs Ws (m^2/Hz), Wi (A^2/Hz), Wg (m^2/Hz) by source name.
    real : dict of str to ndarray
        ``PSD_i = W_i |FRF_i|^2`` of the tool position x1 per source, m^2/Hz (Eq 8).
    following : dict of str to ndarray
        Following-error PSD per source, m^2/Hz. The sensor term is
        ``Ws |1 / (1 + L)|^2``, which is Eq 10's ``|1 - FRF1|^2`` written with the
        sensitivity so it holds whichever position FRF1 refers to.
    """

    freq: np.ndarray
    disturbance: dict[str, np.ndarray]
    real: dict[str, np.ndarray]
    following: dict[str, np.ndarray]

    @property
    def real_total(self) -> np.ndarray:
        """``PSD_Real`` (Eq 9) in m^2/Hz."""
        return sum(self.real.values())  # type: ignore[return-value]

    @property
    def following_total(self) -> np.ndarray:
        """``PSD_Fol`` (Eq 10) in m^2/Hz."""
        return sum(self.following.values())  # type: ignore[return-value]

    def rms_real(self) -> float:
        """RMS real positioning error in m (Eq 12)."""
        return float(cas(self.freq, self.real_total)[-1])

    def rms_following(self) -> float:
        """RMS following error in m (Eq 12)."""
        return float(cas(self.freq, self.following_total)[-1])

    def cas_real(self) -> dict[str, np.ndarray]:
        """CAS per source and ``"total"`` of the real error, in m (Eq 11)."""
        out = {k: cas(self.freq, v) for k, v in self.real.items()}
        out["total"] = cas(self.freq, self.real_total)
        return out

    def power_shares(self) -> dict[str, float]:
        """Share of real-error power per source (Fig. 15), fractions summing to 1."""
        p = {k: float(np.trapezoid(v, self.freq)) for k, v in self.real.items()}
        tot = sum(p.values())
        return {k: (v / tot if tot > 0 else 0.0) for k, v in p.items()}

    def peaks(
        self, *, fmin: float = 2000.0, n: int = 2, which: str = "real"
    ) -> list[float]:
        """Frequencies (Hz) of the ``n`` most prominent peaks of the error PSD."""
        psd = self.real_total if which == "real" else self.following_total
        sel = self.freq >= fmin
        f, p = self.freq[sel], np.log(psd[sel] + 1e-300)
        idx, props = sp.signal.find_peaks(p, prominence=0.5)
        order = np.argsort(props["prominences"])[::-1][:n]
        return sorted(float(f[i]) for i in idx[order])


def synthesize(
    loop: ServoLoop,
    disturbances: Disturbances | None = None,
    freq: np.ndarray | None = None,
) -> ErrorBudget:
    """Synthesise the error PSDs of a closed loop from its disturbance PSDs.

    Parameters
    ----------
    loop : ServoLoop
        The closed loop.
    disturbances : Disturbances, optional
        Disturbance models; default the machine's active calibration.
    freq : ndarray, optional
        Frequencies in Hz; default :func:`frequency_grid` of the controller rate.

    Returns
    -------
    ErrorBudget
        Per-source PSDs of the real error and the following error.
    """
    d = disturbances if disturbances is not None else loop.machine.disturbances
    f = frequency_grid(loop.fs) if freq is None else np.asarray(freq, dtype=float)
    frf = loop.frf(f)
    dist, real, fol = {}, {}, {}
    for name, (inp, _unit) in SOURCES.items():
        w = evaluate_psd(getattr(d, name), f)
        dist[name] = w
        real[name] = w * np.abs(frf.paths[(inp, "tool")]) ** 2
        fol[name] = w * np.abs(frf.paths[(inp, "following_error")]) ** 2
    return ErrorBudget(freq=f, disturbance=dist, real=real, following=fol)


@dataclass(frozen=True, eq=False)
class Realisation:
    """Seeded time series of the stochastic errors.

    Attributes
    ----------
    fs : float
        Sampling rate in Hz.
    tool : ndarray of shape (n,)
        Real tool-position error x1 in m.
    following : ndarray of shape (n,)
        Following error the controller would report, in m.
    sources : dict of str to ndarray
        Disturbance time series (sensor noise m, current noise A, base m).
    out_of_loop : ndarray of shape (n,) or None
        With ``realise(..., out_of_loop=True)``: the tool error (m) that the same
        base displacement adds when the sensor's reference surface sits on the FTS
        base instead of the metrology frame, so that the sensor no longer sees it
        (``tool + out_of_loop`` is the tool error of that set-up).
    """

    fs: float
    tool: np.ndarray
    following: np.ndarray
    sources: dict[str, np.ndarray]
    out_of_loop: np.ndarray | None = None

    @property
    def t(self) -> np.ndarray:
        """Sample times in s."""
        return np.arange(self.tool.size) / self.fs


def realise(
    loop: ServoLoop,
    n: int,
    *,
    seed: int,
    disturbances: Disturbances | None = None,
    fmin: float | None = None,
    sources: bool = False,
    out_of_loop: bool = False,
) -> Realisation:
    """Draw a seeded realisation of the real and following errors.

    Each disturbance is drawn as a Gaussian series with its PSD (random complex
    Fourier coefficients of variance ``W N fs / 2``), then passed through the
    closed-loop FRFs, so the tool error and the following error share the same
    disturbances. The series is drawn on the next FFT-friendly length ``m >= n``
    (periodic with period ``m / fs``) and its first ``n`` samples are returned.

    Parameters
    ----------
    loop : ServoLoop
        The closed loop.
    n : int
        Number of samples at the controller rate.
    seed : int
        Seed of the numpy generator (results are reproducible).
    disturbances : Disturbances, optional
        Default: the machine's active calibration.
    fmin : float, optional
        Frequencies below ``fmin`` (Hz) carry no power; default ``fs / 4096`` like
        :func:`frequency_grid`, so the RMS matches the synthesised CAS.
    sources : bool, default: False
        Also return the disturbance time series (three more inverse FFTs).
    out_of_loop : bool, default: False
        Also return the out-of-loop path of the same base displacement
        (:attr:`Realisation.out_of_loop`): with the sensor target on the FTS base
        the sensor reads ``hs (x_m - x_g)`` instead of ``hs x_m``, i.e. the loop
        sees an extra sensor noise ``-hs x_g`` (``hs`` the sensor's double pole of
        Eq 7), which reaches the tool through the sensor-noise path.

    Returns
    -------
    Realisation
        Time series in SI units.
    """
    if not isinstance(n, int | np.integer) or n < 16:
        raise ConfigError(f"n must be an integer >= 16 samples, got {n!r}")
    fs = loop.fs
    fmin = fs / 4096 if fmin is None else check_positive(fmin, name="fmin")
    d = disturbances if disturbances is not None else loop.machine.disturbances
    rng = root(seed)  # the root stream (servosurf._random)
    m = sp.fft.next_fast_len(int(n), real=True)
    f = np.fft.rfftfreq(m, 1.0 / fs)
    # the band fmin <= f < fs/2 is a contiguous slice of the rfft bins
    i0 = int(np.searchsorted(f, fmin))
    i1 = int(np.searchsorted(f, fs / 2.0))
    band = slice(i0, i1)
    fb = f[band]
    if fb.size > _DENSE_LIMIT:
        # long series: FRFs from a dense log grid (spacing < 0.02 %), interpolated
        fd = np.geomspace(fb[0], fb[-1], _DENSE_LIMIT // 2)
        dense = loop.frf(fd).paths
        lf, lfd = np.log(fb), np.log(fd)

        def path(key):
            h = dense[key]
            return np.interp(lf, lfd, h.real) + 1j * np.interp(lf, lfd, h.imag)
    else:
        paths = loop.frf(fb).paths

        def path(key):
            return paths[key]

    tool = np.zeros(f.size, dtype=complex)
    fol = np.zeros(f.size, dtype=complex)
    bypass = np.zeros(f.size, dtype=complex) if out_of_loop else None
    series = {}
    for name, (inp, _unit) in SOURCES.items():
        w = evaluate_psd(getattr(d, name), fb)
        # complex normal with E|g|^2 = 1: interleaved real/imag standard normals
        g = rng.standard_normal(2 * fb.size).view(np.complex128)
        xb = np.sqrt(w * (m * fs / 4.0)) * g
        if sources:
            x = np.zeros(f.size, dtype=complex)
            x[band] = xb
            series[name] = sp.fft.irfft(x, m, workers=-1)[:n]
        tool[band] += path((inp, "tool")) * xb
        fol[band] += path((inp, "following_error")) * xb
        if bypass is not None and inp == "base":
            from ..servo import double_pole

            hs = double_pole(2j * np.pi * fb, loop.machine.sensor.corner)
            bypass[band] = path(("sensor_noise", "tool")) * (-hs * xb)
    return Realisation(
        fs=fs,
        tool=sp.fft.irfft(tool, m, workers=-1)[:n],
        following=sp.fft.irfft(fol, m, workers=-1)[:n],
        sources=series,
        out_of_loop=(None if bypass is None
                     else sp.fft.irfft(bypass, m, workers=-1)[:n]),
    )
