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
    "LoopLimit",
    "LOOP_STATES",
    "loop_limit",
    "loop_state",
    "stability_limit",
    "tuning_limit",
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


#: Outcomes of tuning the loop for one crossover (see :func:`loop_limit`).
LOOP_STATES = ("stable", "unstable", "untunable")


def loop_state(machine: Machine, bandwidth: float) -> str:
    """Classify the loop tuned for a crossover ``bandwidth`` (Hz).

    Returns
    -------
    str
        ``"stable"``; ``"unstable"`` (tuned, but a discrete closed-loop pole lies on
        or outside the unit circle); ``"untunable"`` (the tuning rule has no positive
        PIDF gains for this crossover and phase margin: no loop exists, which is not
        an instability).
    """
    try:
        loop = ServoLoop(machine.with_bandwidth(bandwidth))
    except ModelError:
        return "untunable"
    return "stable" if loop.is_stable() else "unstable"


@dataclass(frozen=True)
class LoopLimit:
    """Where the tuned loop stops working as its crossover rises.

    Attributes
    ----------
    bandwidth_hz : float
        Lowest crossover (Hz) above the scan start at which the loop fails, to the
        requested relative tolerance; ``inf`` when it works up to the scan end.
    kind : str
        ``"unstable"``, ``"untunable"`` (no positive PIDF gains: not an
        instability) or ``"none"``.
    last_working_hz : float
        Highest crossover (Hz) known to give a stable, tuned loop.
    """

    bandwidth_hz: float
    kind: str
    last_working_hz: float


def loop_limit(
    machine: Machine,
    *,
    fmin: float = 100.0,
    fmax: float = 20e3,
    rtol: float = 1e-3,
) -> LoopLimit:
    """Lowest crossover bandwidth (Hz) above ``fmin`` where the tuned loop fails.

    Scans upward in 5 % steps, then bisects to ``rtol`` between the last working and
    the first failing crossover. A failure is either an instability or a tuning
    failure (no positive PIDF gains), reported apart.

    Parameters
    ----------
    machine : Machine
        The machine (moving mass and tuning rule as given).
    fmin, fmax : float
        Scan range of crossover frequencies, Hz.
    rtol : float, default: 1e-3
        Relative tolerance of the limit.

    Returns
    -------
    LoopLimit
        The limit, its kind and the last working crossover.
    """
    state = loop_state(machine, fmin)
    if state != "stable":
        return LoopLimit(float(fmin), state, float("nan"))
    lo, hi, kind = fmin, None, "none"
    f = fmin
    while f < fmax:
        f *= 1.05
        state = loop_state(machine, f)
        if state == "stable":
            lo = f
        else:
            hi, kind = f, state
            break
    if hi is None:
        return LoopLimit(float("inf"), "none", float(lo))
    while hi / lo - 1 > rtol:
        mid = float(np.sqrt(lo * hi))
        state = loop_state(machine, mid)
        if state == "stable":
            lo = mid
        else:
            hi, kind = mid, state
    return LoopLimit(float(hi), kind, float(lo))


def stability_limit(
    machine: Machine, *, fmin: float = 100.0, fmax: float = 20e3, rtol: float = 1e-3
) -> float:
    """Lowest crossover bandwidth (Hz) above ``fmin`` where the tuned loop is unstable.

    Scans upward in 5 % steps, then bisects to ``rtol``. Returns ``inf`` when the
    loop stays stable up to ``fmax`` or when the tuning rule fails first (no positive
    PIDF gains, see :func:`tuning_limit`): a crossover that cannot be tuned is not
    an unstable loop.
    """
    lim = loop_limit(machine, fmin=fmin, fmax=fmax, rtol=rtol)
    return lim.bandwidth_hz if lim.kind == "unstable" else float("inf")


def tuning_limit(
    machine: Machine, *, fmin: float = 100.0, fmax: float = 20e3, rtol: float = 1e-3
) -> float:
    """Lowest crossover bandwidth (Hz) where the tuning rule has no positive gains.

    ``inf`` when the loop goes unstable first or works up to ``fmax``.
    """
    lim = loop_limit(machine, fmin=fmin, fmax=fmax, rtol=rtol)
    return lim.bandwidth_hz if lim.kind == "untunable" else float("inf")


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

    This is the one definition of "optimal bandwidth" in servosurf: ``servosurf
    noise`` and ``servosurf paper`` both call it with its defaults (frequency grid
    :func:`~servosurf.noise.frequency_grid`, search up to just below the loop limit),
    so they report the same number.

    Returns
    -------
    bandwidth : float
        Optimal crossover in Hz (searched on a log grid then refined by bounded
        scalar minimisation over stable bandwidths).
    rms : float
        The minimum RMS error in m.
    """
    if which not in ("real", "following"):
        raise ModelError(f"which must be 'real' or 'following', got {which!r}")
    col = 0 if which == "real" else 1
    if hi is None:
        hi = min(loop_limit(machine, fmin=lo).bandwidth_hz, 20e3) * 0.999
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
        Crossover of minimum RMS real error per mass, Hz, found by refinement
        (:func:`optimal_bandwidth`), not a grid point.
    optimal_rms : ndarray of shape (m,)
        The minimum RMS real error per mass, m.
    stability_limit : ndarray of shape (m,)
        Lowest unstable crossover per mass, Hz (inf when the tuning fails first).
    optimal_following_bandwidth : ndarray of shape (m,)
        Crossover of minimum RMS following error per mass, Hz (refined).
    optimal_following_rms : ndarray of shape (m,)
        The minimum RMS following error per mass, m.
    tuning_limit : ndarray of shape (m,)
        Lowest crossover per mass where the tuning rule has no positive PIDF gains,
        Hz (inf when the loop goes unstable first).
    """

    masses: np.ndarray
    bandwidths: np.ndarray
    rms_real: np.ndarray
    rms_following: np.ndarray
    optimal_bandwidth: np.ndarray
    optimal_rms: np.ndarray
    stability_limit: np.ndarray
    optimal_following_bandwidth: np.ndarray
    optimal_following_rms: np.ndarray
    tuning_limit: np.ndarray

    def to_dict(self) -> dict:
        """JSON-ready dictionary (SI units, keys carry the unit)."""
        return {
            "masses_kg": self.masses,
            "bandwidths_hz": self.bandwidths,
            "rms_real_m": self.rms_real,
            "rms_following_m": self.rms_following,
            "optimal_bandwidth_hz": self.optimal_bandwidth,
            "optimal_rms_real_m": self.optimal_rms,
            "optimal_following_bandwidth_hz": self.optimal_following_bandwidth,
            "optimal_rms_following_m": self.optimal_following_rms,
            "optimal_bandwidth_definition": "crossover minimising the RMS error, "
            "refined by bounded scalar minimisation (noise.optimal_bandwidth)",
            "stability_limit_hz": self.stability_limit,
            "tuning_limit_hz": self.tuning_limit,
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
        The grid, the refined optima (real and following) per mass, and the
        stability and tuning limits per mass.
    """
    from ..scale._tasks import map_tasks

    masses = np.atleast_1d(np.asarray(masses, dtype=float))
    bws = np.atleast_1d(np.asarray(bandwidths, dtype=float))
    freq = frequency_grid(machine.controller.sample_rate)
    task = functools.partial(_mass_row, machine, bws, disturbances, freq)
    rows = map_tasks(task, [float(m) for m in masses], client=client,
                     progress=progress)
    rr = np.array([r[0] for r in rows]).reshape(masses.size, bws.size)
    rf = np.array([r[1] for r in rows]).reshape(masses.size, bws.size)
    opt, optv, lim, fopt, foptv, tun = (
        np.array([r[k] for r in rows], dtype=float) for k in range(2, 8)
    )
    return DesignStudy(masses, bws, rr, rf, opt, optv, lim, fopt, foptv, tun)


def _mass_row(machine: Machine, bws: np.ndarray, disturbances, freq: np.ndarray,
              mass: float):
    """One mass of :func:`design_study` (one task).

    Returns the RMS real and following error at every bandwidth (m), the refined
    real-error optimum (Hz) and its RMS (m), the stability limit (Hz), the refined
    following-error optimum (Hz) and its RMS (m) and the tuning limit (Hz).
    """
    m = machine.with_moving_mass(mass)
    rr = np.full(bws.size, np.nan)
    rf = np.full(bws.size, np.nan)
    for j, b in enumerate(bws):
        rr[j], rf[j], _ = rms_at(m, b, disturbances=disturbances, freq=freq)
    lim = loop_limit(m)
    stab = lim.bandwidth_hz if lim.kind == "unstable" else float("inf")
    tun = lim.bandwidth_hz if lim.kind == "untunable" else float("inf")
    out = []
    for which in ("real", "following"):
        try:
            out.append(optimal_bandwidth(m, which=which, disturbances=disturbances))
        except ModelError:
            out.append((np.nan, np.nan))
    (opt, optv), (fopt, foptv) = out
    return rr, rf, opt, optv, stab, fopt, foptv, tun
