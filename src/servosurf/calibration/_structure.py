"""Structure and controller calibration: modes, damping, tuning rule.

Five numbers are solved from five figures of the paper, all at 0.175 kg:

=================  ========================================================
parameter          target (:data:`~servosurf.calibration.FIGURES` key)
=================  ========================================================
``k1``             real-error spectrum peak near 7.4 kHz (``peak_7400``)
``k4``             real-error spectrum peak near 11.7 kHz (``peak_11700``)
``zeta4`` (``c4``) stability limit 1.6 kHz (``stability_limit``)
``rho``            force-to-sensor phase lag 12 deg at 100 Hz (``force_lag``)
``N``              closed-loop gain at 100 Hz, 5.2/5 um (``overshoot_air_cut``)
=================  ========================================================

The damping of the tool mode ``zeta1`` (so ``c1``) and the loop delay are assumed
(the paper gives one stability figure for three candidates); ``c1`` and ``c4`` derive
from the modal damping ratios ``c = 2 zeta sqrt(k mu)`` with ``mu`` the reduced mass
of the two bodies the spring joins, at the paper's 0.075 kg moving mass.

The solve is block Gauss-Seidel: the tuning rule (``rho``, ``N``) by a 2-D Newton
step on the 100 Hz response, the modes (``k1``, ``k4``) by a 2-D Newton step on the
refined spectrum peaks, ``zeta4`` by a secant on the stability limit, repeated until
no parameter moves by more than the tolerance. Deterministic for a given start.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np
import scipy as sp

from ..errors import ModelError
from ..noise._study import loop_state
from ..noise._synthesis import synthesize
from ..servo._loop import ServoLoop
from ..servo._machine import Disturbances, Machine

__all__ = [
    "StructureParams",
    "apply_structure",
    "structure_of",
    "error_peaks",
    "response_at_100hz",
    "limit_near",
    "structure_figures",
    "solve_structure",
    "HEAVY_MASS",
    "FIG13C_BANDWIDTH",
]

#: The paper's heavier moving mass, kg (sections 3.3, 4.1).
HEAVY_MASS = 0.175
#: Crossover of Fig. 13c, the lenslet cuts and Fig. 17, Hz.
FIG13C_BANDWIDTH = 1448.0


@dataclass(frozen=True)
class StructureParams:
    """The solved structure and tuning numbers.

    Attributes
    ----------
    k1, k4 : float
        Tool-carrier and appendage-carrier stiffness, N/m.
    zeta1, zeta4 : float
        Modal damping ratios of the tool and appendage springs (zeta1 assumed).
    rho : float
        Integral ratio of the tuning rule (``Ki = rho Kp w_c``).
    n_filter : float
        Derivative filter ratio of the tuning rule (``Tf = 1 / (N w_c)``).
    """

    k1: float
    k4: float
    zeta1: float
    zeta4: float
    rho: float
    n_filter: float


def _mu(a: float, b: float) -> float:
    return a * b / (a + b)


def apply_structure(machine: Machine, p: StructureParams) -> Machine:
    """The machine with these structure and tuning numbers (c1, c4 from zeta)."""
    m = machine.mechanics
    c1 = 2.0 * p.zeta1 * math.sqrt(p.k1 * _mu(m.m1, m.m2))
    c4 = 2.0 * p.zeta4 * math.sqrt(p.k4 * _mu(m.m4, m.m2))
    mech = dataclasses.replace(m, k1=float(p.k1), k4=float(p.k4), c1=c1, c4=c4)
    ctl = dataclasses.replace(
        machine.controller,
        integral_ratio=float(p.rho),
        derivative_filter_ratio=float(p.n_filter),
    )
    return dataclasses.replace(machine, mechanics=mech, controller=ctl)


def structure_of(machine: Machine) -> StructureParams:
    """The structure and tuning numbers of a machine (zeta from c, k, masses)."""
    m = machine.mechanics
    z1 = m.c1 / (2.0 * math.sqrt(m.k1 * _mu(m.m1, m.m2)))
    z4 = m.c4 / (2.0 * math.sqrt(m.k4 * _mu(m.m4, m.m2)))
    c = machine.controller
    return StructureParams(
        m.k1, m.k4, z1, z4, c.integral_ratio, c.derivative_filter_ratio
    )


def error_peaks(
    loop: ServoLoop,
    disturbances: Disturbances | None = None,
    *,
    fmin: float = 2000.0,
    n: int = 2,
) -> list[float]:
    """Frequencies (Hz) of the ``n`` most prominent real-error PSD peaks, refined.

    The peaks of :meth:`~servosurf.noise.ErrorBudget.peaks` on the standard grid,
    each refined by a parabola through the log PSD on a local grid of 0.01 %
    spacing (the standard grid is 0.3 % apart, too coarse to calibrate on).
    """
    coarse = synthesize(loop, disturbances).peaks(fmin=fmin, n=n)
    out = []
    for f0 in coarse:
        f = f0 * np.linspace(0.99, 1.01, 201)
        p = np.log(synthesize(loop, disturbances, freq=f).real_total)
        k = int(np.argmax(p))
        fk = float(f[k])
        if 0 < k < f.size - 1:
            a, b, c = p[k - 1], p[k], p[k + 1]
            den = a - 2.0 * b + c
            if den < 0:
                fk += 0.5 * (a - c) / den * (f[k + 1] - f[k - 1]) / 2.0
        out.append(fk)
    return sorted(out)


def response_at_100hz(loop: ServoLoop) -> tuple[float, float]:
    """Force-to-sensor phase lag (deg) and reference-to-sensor gain (dB) at 100 Hz.

    The lag is ``-arg`` of the force -> measured-position FRF (Fig. 17a); the gain
    is ``20 log10 |T|`` of reference -> measured position (the air-cut amplitude).
    """
    fr = loop.frf(np.array([100.0])).paths
    lag = -float(np.degrees(np.angle(fr[("force", "sensor")][0])))
    gain = 20.0 * float(np.log10(abs(fr[("reference", "sensor")][0])))
    return lag, gain


def limit_near(
    machine: Machine, guess: float, *, rtol: float = 1e-6
) -> tuple[float, str]:
    """The crossover (Hz) near ``guess`` where the loop stops working, and how.

    Brackets the boundary between a working (tuned, stable) crossover below and a
    failing one above, starting at ``guess`` and widening by 5 %, then bisects.
    Assumes the loop works everywhere below the bracket; :func:`loop_limit` checks
    that from 100 Hz up (the calibration does so once, at the end).
    """
    lo = hi = float(guess)
    while loop_state(machine, lo) != "stable":
        hi = lo
        lo /= 1.05
        if lo < 50.0:
            return lo, "unstable"
    if hi == lo:
        hi = lo * 1.05
        while loop_state(machine, hi) == "stable":
            lo, hi = hi, hi * 1.05
            if hi > 1e5:
                return float("inf"), "none"
    kind = loop_state(machine, hi)
    while hi / lo - 1.0 > rtol:
        mid = math.sqrt(lo * hi)
        s = loop_state(machine, mid)
        if s == "stable":
            lo = mid
        else:
            hi, kind = mid, s
    return hi, kind


def structure_figures(
    machine: Machine, disturbances: Disturbances | None = None, *, limit_guess=1600.0
) -> dict[str, float]:
    """The five structure targets' values for a machine (see the module table)."""
    heavy = machine.with_moving_mass(HEAVY_MASS)
    loop = ServoLoop(heavy.with_bandwidth(FIG13C_BANDWIDTH))
    lag, gain = response_at_100hz(loop)
    pk = error_peaks(loop, disturbances) + [float("nan")] * 2
    lim, kind = limit_near(heavy, limit_guess)
    return {
        "peak_7400": pk[0],
        "peak_11700": pk[1],
        "stability_limit": lim if kind == "unstable" else float("nan"),
        "force_lag": lag,
        "overshoot_air_cut": gain,
    }


def _newton2(fun, x0, target, *, steps, tol, max_iter=30):
    """Damped 2-D Newton with forward differences on log-parameters."""
    x = np.asarray(x0, dtype=float)
    t = np.asarray(target, dtype=float)
    for _ in range(max_iter):
        y = fun(x) - t
        jac = np.empty((2, 2))
        for i in range(2):
            dx = np.zeros(2)
            dx[i] = steps[i]
            jac[:, i] = (fun(x + dx) - t - y) / steps[i]
        step = np.linalg.solve(jac, -y)
        lam = 1.0
        while lam > 1e-3:
            xn = x + lam * step
            try:
                yn = fun(xn) - t
            except ModelError:
                yn = np.full(2, np.inf)
            if np.all(np.isfinite(yn)) and np.linalg.norm(yn) < np.linalg.norm(y):
                break
            lam /= 2.0
        x = xn
        if np.max(np.abs(lam * step)) < tol:
            break
    return x


def solve_structure(
    machine: Machine,
    start: StructureParams,
    disturbances: Disturbances | None = None,
    *,
    targets: dict | None = None,
    tol: float = 1e-7,
    max_sweeps: int = 12,
    log=None,
) -> StructureParams:
    """Solve the five structure and tuning numbers from their targets.

    Parameters
    ----------
    machine : Machine
        Machine with every other number set (masses, delay, zeta1 via ``start``).
    start : StructureParams
        Starting values (the ``zeta1`` given here is kept: it is assumed).
    disturbances : Disturbances, optional
        Disturbances that shape the real-error spectrum (peak targets).
    targets : dict, optional
        Target values by figure key (default: the paper's).
    tol : float, default: 1e-7
        Convergence: largest change of a log-parameter in a sweep.
    max_sweeps : int, default: 12
    log : callable, optional
        ``log(str)`` progress messages.

    Returns
    -------
    StructureParams
        The solution.
    """
    from ._figures import FIGURES

    tg = {k: FIGURES[k].value for k in (
        "peak_7400", "peak_11700", "stability_limit", "force_lag", "overshoot_air_cut"
    )}
    tg.update(targets or {})
    p = start
    heavy_of = lambda m: m.with_moving_mass(HEAVY_MASS)  # noqa: E731
    guess = tg["stability_limit"]
    for sweep in range(max_sweeps):
        old = np.log([p.k1, p.k4, p.zeta4, p.rho, p.n_filter])

        def ctl(x, p=p):
            q = dataclasses.replace(p, rho=math.exp(x[0]), n_filter=math.exp(x[1]))
            loop = ServoLoop(
                heavy_of(apply_structure(machine, q)).with_bandwidth(FIG13C_BANDWIDTH)
            )
            lag, gain = response_at_100hz(loop)
            return np.array([lag, 10.0 * gain])

        x = _newton2(
            ctl,
            [math.log(p.rho), math.log(p.n_filter)],
            [tg["force_lag"], 10.0 * tg["overshoot_air_cut"]],
            steps=(1e-4, 1e-4),
            tol=tol,
        )
        p = dataclasses.replace(p, rho=math.exp(x[0]), n_filter=math.exp(x[1]))

        def modes(x, p=p):
            q = dataclasses.replace(p, k1=math.exp(x[0]), k4=math.exp(x[1]))
            loop = ServoLoop(
                heavy_of(apply_structure(machine, q)).with_bandwidth(FIG13C_BANDWIDTH)
            )
            pk = error_peaks(loop, disturbances)
            if len(pk) < 2:
                raise ModelError("fewer than two real-error peaks above 2 kHz")
            return 1e3 * np.log(np.array(pk[:2]))

        x = _newton2(
            modes,
            [math.log(p.k1), math.log(p.k4)],
            1e3 * np.log([tg["peak_7400"], tg["peak_11700"]]),
            steps=(1e-4, 1e-4),
            tol=tol,
        )
        p = dataclasses.replace(p, k1=math.exp(x[0]), k4=math.exp(x[1]))

        def lim(lz: float, p=p) -> float:
            nonlocal guess
            q = dataclasses.replace(p, zeta4=math.exp(lz))
            f, kind = limit_near(heavy_of(apply_structure(machine, q)), guess)
            if kind != "unstable":
                raise ModelError(
                    f"the loop at 0.175 kg becomes {kind} near {f:.0f} Hz, not "
                    "unstable: the stability target cannot set zeta4"
                )
            guess = f
            return math.log(f / tg["stability_limit"])

        # bracket the root in log zeta4 (the limit rises with the damping), then
        # Brent's method
        a = math.log(p.zeta4)
        fa = lim(a)
        step = 0.3 if fa < 0 else -0.3
        b, fb = a, fa
        for _ in range(30):
            if fa * fb <= 0 and b != a:
                break
            a, fa = b, fb
            b = a + step
            if not math.log(1e-5) < b < math.log(0.5):
                raise ModelError(
                    "the stability limit at 0.175 kg cannot reach "
                    f"{tg['stability_limit']:g} Hz with zeta4 in 1e-5..0.5"
                )
            fb = lim(b)
        lo, hi = sorted((a, b))
        b = sp.optimize.brentq(lim, lo, hi, xtol=tol, rtol=1e-12)
        p = dataclasses.replace(p, zeta4=math.exp(b))
        new = np.log([p.k1, p.k4, p.zeta4, p.rho, p.n_filter])
        change = float(np.max(np.abs(new - old)))
        if log is not None:
            log(f"structure sweep {sweep + 1}: largest log change {change:.2e}")
        if change < tol:
            break
    return p
