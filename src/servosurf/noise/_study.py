"""Design study: RMS errors against bandwidth for several moving masses."""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np
import scipy as sp

from ..errors import ModelError
from ..servo._loop import ServoLoop
from ..servo._machine import Disturbances, Machine
from ._psd import frequency_grid
from ._synthesis import synthesize

__all__ = [
    "DesignStudy",
    "design_study",
    "stability_limit",
    "optimal_bandwidth",
    "rms_at",
]


def rms_at(
    machine: Machine,
    bandwidth: float,
    *,
    disturbances: Disturbances | None = None,
    freq: np.ndarray | None = None,
) -> tuple[float, float, bool]:
    """RMS real and following error (m) at a crossover ``bandwidth`` (Hz).

    Returns ``(nan, nan, False)`` when the loop cannot be tuned or is unstable.
    """
    try:
        loop = ServoLoop(machine.with_bandwidth(bandwidth))
    except ModelError:
        return float("nan"), float("nan"), False
    if not loop.is_stable():
        return float("nan"), float("nan"), False
    b = synthesize(loop, disturbances, freq)
    return b.rms_real(), b.rms_following(), True


def _stable(machine: Machine, bandwidth: float) -> bool:
    try:
        return ServoLoop(machine.with_bandwidth(bandwidth)).is_stable()
    except ModelError:
        return False


def stability_limit(
    machine: Machine, *, fmin: float = 100.0, fmax: float = 20e3, rtol: float = 1e-3
) -> float:
    """Lowest crossover bandwidth (Hz) above ``fmin`` where the tuned loop is unstable.

    Scans upward in 5 % steps, then bisects to ``rtol``. Returns ``inf`` when the
    loop stays stable (and tunable) up to ``fmax``.
    """
    if not _stable(machine, fmin):
        return fmin
    lo, hi = fmin, None
    f = fmin
    while f < fmax:
        f *= 1.05
        if _stable(machine, f):
            lo = f
        else:
            hi = f
            break
    if hi is None:
        return float("inf")
    while hi / lo - 1 > rtol:
        mid = np.sqrt(lo * hi)
        if _stable(machine, mid):
            lo = mid
        else:
            hi = mid
    return float(hi)


def optimal_bandwidth(
    machine: Machine,
    *,
    which: str = "real",
    lo: float = 100.0,
    hi: float | None = None,
    disturbances: Disturbances | None = None,
    freq: np.ndarray | None = None,
) -> tuple[float, float]:
    """Crossover bandwidth (Hz) minimising the RMS ``"real"`` or ``"following"`` error.

    Returns
    -------
    bandwidth : float
        Optimal crossover in Hz (searched on a log grid then refined by bounded
        scalar minimisation over stable bandwidths).
    rms : float
        The minimum RMS error in m.
    """
    col = 0 if which == "real" else 1
    if hi is None:
        hi = min(stability_limit(machine, fmin=lo), 20e3) * 0.999
    grid = np.geomspace(lo, hi, 24)
    vals = np.array(
        [rms_at(machine, b, disturbances=disturbances, freq=freq)[col] for b in grid]
    )
    if not np.any(np.isfinite(vals)):
        raise ModelError("no stable bandwidth in the search range")
    i = int(np.nanargmin(vals))
    a, b = grid[max(i - 1, 0)], grid[min(i + 1, grid.size - 1)]

    def fun(lb: float) -> float:
        v = rms_at(machine, float(np.exp(lb)), disturbances=disturbances, freq=freq)[
            col
        ]
        return v if np.isfinite(v) else 1.0

    res = sp.optimize.minimize_scalar(
        fun, bounds=(np.log(a), np.log(b)), method="bounded", options={"xatol": 1e-3}
    )
    return float(np.exp(res.x)), float(res.fun)


@dataclass(frozen=True, eq=False)
class DesignStudy:
    """RMS errors on a (mass x bandwidth) grid.

    Attributes
    ----------
    masses : ndarray of shape (m,)
        Moving masses m1 + m2 in kg.
    bandwidths : ndarray of shape (b,)
        Crossover bandwidths in Hz.
    rms_real, rms_following : ndarray of shape (m, b)
        RMS errors in m; NaN where the loop is unstable or cannot be tuned.
    optimal_bandwidth : ndarray of shape (m,)
        Bandwidth of minimum RMS real error per mass, Hz.
    optimal_rms : ndarray of shape (m,)
        The minimum RMS real error per mass, m.
    stability_limit : ndarray of shape (m,)
        Lowest unstable crossover per mass, Hz.
    """

    masses: np.ndarray
    bandwidths: np.ndarray
    rms_real: np.ndarray
    rms_following: np.ndarray
    optimal_bandwidth: np.ndarray
    optimal_rms: np.ndarray
    stability_limit: np.ndarray

    def to_dict(self) -> dict:
        """JSON-ready dictionary (SI units, keys carry the unit)."""
        return {
            "masses_kg": self.masses,
            "bandwidths_hz": self.bandwidths,
            "rms_real_m": self.rms_real,
            "rms_following_m": self.rms_following,
            "optimal_bandwidth_hz": self.optimal_bandwidth,
            "optimal_rms_real_m": self.optimal_rms,
            "stability_limit_hz": self.stability_limit,
        }


def design_study(
    machine: Machine,
    masses,
    bandwidths,
    *,
    disturbances: Disturbances | None = None,
    progress=None,
    client=None,
) -> DesignStudy:
    """RMS real and following error against bandwidth for a list of moving masses.

    Parameters
    ----------
    machine : Machine
        Base machine (its controller rule is re-tuned for every bandwidth).
    masses : sequence of float
        Moving masses m1 + m2 in kg.
    bandwidths : sequence of float
        Crossover bandwidths in Hz.
    disturbances : Disturbances, optional
        Default: the machine's active calibration.
    progress : callable, optional
        Wraps the iterable of finished masses, called as ``progress(it, total=n)``
        (e.g. a progress bar).
    client : distributed.Client, optional
        Run one dask task per mass on this cluster (same results as in-process);
        default: in this process.

    Returns
    -------
    DesignStudy
        The grid, the optimum per mass and the stability limit per mass.
    """
    from ..scale._tasks import map_tasks

    masses = np.atleast_1d(np.asarray(masses, dtype=float))
    bws = np.atleast_1d(np.asarray(bandwidths, dtype=float))
    freq = frequency_grid(machine.controller.sample_rate, n=2000)
    task = functools.partial(_mass_row, machine, bws, disturbances, freq)
    rows = map_tasks(task, [float(m) for m in masses], client=client,
                     progress=progress)
    rr = np.array([r[0] for r in rows]).reshape(masses.size, bws.size)
    rf = np.array([r[1] for r in rows]).reshape(masses.size, bws.size)
    opt, optv, lim = (np.array([r[k] for r in rows], dtype=float) for k in (2, 3, 4))
    return DesignStudy(masses, bws, rr, rf, opt, optv, lim)


def _mass_row(machine: Machine, bws: np.ndarray, disturbances, freq: np.ndarray,
              mass: float):
    """One mass of :func:`design_study` (one task): RMS real and following error
    at every bandwidth (m), optimal bandwidth (Hz), its RMS (m), stability limit (Hz).
    """
    m = machine.with_moving_mass(mass)
    rr = np.full(bws.size, np.nan)
    rf = np.full(bws.size, np.nan)
    for j, b in enumerate(bws):
        rr[j], rf[j], _ = rms_at(m, b, disturbances=disturbances, freq=freq)
    lim = stability_limit(m)
    opt = optv = np.nan
    try:
        opt, optv = optimal_bandwidth(m, hi=0.999 * lim, disturbances=disturbances,
                                      freq=freq)
    except ModelError:
        pass
    return rr, rf, opt, optv, lim
