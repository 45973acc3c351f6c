"""Closed-loop FRFs of the stochastic sources on a (mass x bandwidth) grid, stored once.

The RMS errors of Eqs 8 to 12 are linear in each disturbance PSD:
``RMS^2(mass, bandwidth) = sum_i int W_i(f) |FRF_i(f)|^2 df``. The FRFs depend on
the machine and the tuned loop only, so :class:`ErrorBank` computes them once
(through :class:`~servosurf.servo.ServoLoop`, the same loop every command uses) and
evaluates any number of disturbance PSD sets by one weighted sum: the disturbance
search evaluates thousands of PSD sets this way.
"""

from __future__ import annotations

import numpy as np

from ..errors import ModelError
from ..noise._psd import frequency_grid
from ..noise._study import loop_limit
from ..noise._synthesis import SOURCES
from ..servo._loop import ServoLoop
from ..servo._machine import Machine

__all__ = ["ErrorBank", "curve_minimum", "bandwidth_for_3db"]

#: Outputs stored by the bank: the real tool position and the following error.
OUTPUTS = ("tool", "following_error")


def curve_minimum(bandwidths: np.ndarray, rms: np.ndarray) -> float:
    """Bandwidth (Hz) of the minimum of a sampled RMS curve.

    A cubic spline in log-bandwidth through the seven samples around the smallest
    one; its minimum between the smallest sample's neighbours. The result moves
    continuously with the curve (a parabola through three samples jumps when the
    smallest sample changes), which the level fits need. NaN samples (unstable
    loops) are skipped; the grid point at an end of the valid range; NaN when all
    samples are NaN.
    """
    from scipy.interpolate import CubicSpline

    b = np.asarray(bandwidths, dtype=float)
    a = np.asarray(rms, dtype=float)
    fin = np.where(np.isfinite(a), a, np.inf)
    j = int(np.argmin(fin))
    if not np.isfinite(fin[j]):
        return float("nan")
    lo, hi = max(j - 3, 0), min(j + 4, a.size)
    win = np.arange(lo, hi)
    win = win[np.isfinite(a[win])]
    if j == win[0] or j == win[-1] or win.size < 4:
        return float(b[j])
    x = np.log(b[win])
    spl = CubicSpline(x, a[win])
    k = int(np.searchsorted(win, j))
    left, right = x[k - 1], x[k + 1]
    roots = spl.derivative().roots(extrapolate=False)
    roots = roots[(roots >= left) & (roots <= right)]
    cand = np.concatenate([roots, [x[k]]])
    best = cand[int(np.argmin(spl(cand)))]
    return float(np.exp(best))


def bandwidth_for_3db(machine: Machine, f3db: float, *, xtol: float = 0.01) -> float:
    """Crossover (Hz) whose closed-loop -3 dB bandwidth (r -> sensor) is ``f3db`` Hz.

    The paper's section 3.3 states its 468 Hz as a closed-loop -3 dB bandwidth;
    servosurf's bandwidths are crossovers, so this converts one reading into the
    other.
    """
    import scipy as sp

    def g(b: float) -> float:
        loop = ServoLoop(machine.with_bandwidth(b))
        return loop.margins(n=4000)["bandwidth_3db_hz"] - f3db

    return float(sp.optimize.brentq(g, 0.3 * f3db, 1.2 * f3db, xtol=xtol))


class ErrorBank:
    """Weighted ``|FRF|^2`` of every source to the tool and the following error.

    Parameters
    ----------
    machine : Machine
        The machine (its tuning rule is re-tuned for every bandwidth).
    masses : sequence of float
        Moving masses m1 + m2 in kg.
    bandwidths : sequence of float
        Crossover bandwidths in Hz (the same for every mass).
    freq : ndarray, optional
        Frequencies in Hz; default :func:`~servosurf.noise.frequency_grid`.

    Attributes
    ----------
    freq : ndarray of shape (nf,)
        Frequencies in Hz.
    weights : ndarray of shape (nf,)
        Trapezoid weights in Hz (``sum(weights * psd)`` is Eq 11 at Nyquist squared).
    h : ndarray of shape (nm, nb, 3, 2, nf)
        ``weights |FRF|^2`` per mass, bandwidth, source (:data:`SOURCES` order) and
        output (tool, following error); source units as in :data:`SOURCES`.
    ok : ndarray of bool, shape (nm, nb)
        True where the loop is tuned and stable (below the mass's loop limit).
    limits : list of LoopLimit
        The loop limit per mass.
    """

    def __init__(self, machine: Machine, masses, bandwidths, *, freq=None) -> None:
        self.machine = machine
        self.masses = np.atleast_1d(np.asarray(masses, dtype=float))
        self.bandwidths = np.atleast_1d(np.asarray(bandwidths, dtype=float))
        fs = machine.controller.sample_rate
        self.freq = frequency_grid(fs) if freq is None else np.asarray(freq, float)
        f = self.freq
        w = np.zeros_like(f)
        d = np.diff(f)
        w[:-1] += d / 2
        w[1:] += d / 2
        self.weights = w
        nm, nb = self.masses.size, self.bandwidths.size
        self.h = np.zeros((nm, nb, len(SOURCES), len(OUTPUTS), f.size))
        self.ok = np.zeros((nm, nb), dtype=bool)
        self.limits = []
        for i, mass in enumerate(self.masses):
            mm = machine.with_moving_mass(float(mass))
            lim = loop_limit(mm, fmin=min(100.0, float(self.bandwidths.min())))
            self.limits.append(lim)
            for j, b in enumerate(self.bandwidths):
                if not b < lim.bandwidth_hz:
                    continue
                try:
                    loop = ServoLoop(mm.with_bandwidth(float(b)))
                except ModelError:
                    continue
                paths = loop.frf(f).paths
                self.ok[i, j] = True
                for k, (inp, _unit) in enumerate(SOURCES.values()):
                    for m, out in enumerate(OUTPUTS):
                        self.h[i, j, k, m] = w * np.abs(paths[(inp, out)]) ** 2

    def index(self, bandwidth: float) -> int:
        """Index of the bank bandwidth nearest ``bandwidth`` (Hz)."""
        return int(np.argmin(np.abs(np.log(self.bandwidths / bandwidth))))

    def powers(self, psd: np.ndarray) -> np.ndarray:
        """Error power per (mass, bandwidth, source, output) in m^2.

        Parameters
        ----------
        psd : ndarray of shape (3, nf)
            Disturbance PSDs in :data:`SOURCES` order (m^2/Hz, A^2/Hz, m^2/Hz).

        Returns
        -------
        ndarray of shape (nm, nb, 3, 2)
            NaN where the loop is unstable or cannot be tuned.
        """
        p = np.einsum("mbsof,sf->mbso", self.h, psd)
        p[~self.ok] = np.nan
        return p
