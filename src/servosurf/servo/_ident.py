"""Grey-box identification of machine parameters from a measured FRF (paper 3.1)."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np
import scipy as sp

from ..errors import ConfigError
from ._loop import loop_elements, plant_gain
from ._machine import Machine

__all__ = [
    "fit_percent",
    "open_loop_frf",
    "identify",
    "Identification",
    "DEFAULT_IDENT_PARAMS",
    "set_param",
    "get_param",
]

#: Parameters fitted by default. ``force-constant`` is held: with the masses and
#: stiffnesses it is not identifiable from a u -> sensor FRF (only ratios are).
DEFAULT_IDENT_PARAMS = (
    "mechanics.m1",
    "mechanics.m2",
    "mechanics.k1",
    "mechanics.c1",
    "mechanics.k2",
    "mechanics.c2",
)


def fit_percent(y: np.ndarray, yhat: np.ndarray) -> float:
    """MATLAB's normalised fit in percent.

    ``100 (1 - ||y - yhat|| / ||y - mean(y)||)``.
    """
    y = np.asarray(y)
    yhat = np.asarray(yhat)
    den = np.linalg.norm(y - y.mean())
    if den == 0:
        return float("nan")
    return float(100.0 * (1.0 - np.linalg.norm(y - yhat) / den))


def open_loop_frf(
    machine: Machine, freq: np.ndarray, *, digital: bool = True
) -> np.ndarray:
    """Open-loop FRF from DAC voltage to sensor voltage (V/V), as in paper Fig. 6.

    ``G = ZOH * delay * G_I w_I^2/(s+w_I)^2 * B l * P(x_meas/Fa) * S w_s^2/(s+w_s)^2``;
    ``digital=False`` leaves out the ZOH and delay (an analogue sweep).
    """
    ch = loop_elements(machine, np.asarray(freq, float), discrete=digital)
    return plant_gain(ch, machine)


def _split(key: str) -> tuple[str, str]:
    parts = key.replace("-", "_").split(".")
    if len(parts) != 2:
        raise ConfigError(
            f"parameter {key!r} must be 'section.name', e.g. mechanics.k1"
        )
    return parts[0], parts[1]


def get_param(machine: Machine, key: str) -> float:
    """Value of a dotted machine parameter (``"mechanics.k1"``), SI."""
    sec, name = _split(key)
    try:
        return float(getattr(getattr(machine, sec), name))
    except AttributeError:
        raise ConfigError(f"unknown machine parameter {key!r}") from None
    except TypeError:
        raise ConfigError(f"machine parameter {key!r} is not numeric") from None


#: Provenance label of a number replaced by :func:`set_param` (a fit's value).
SET_PARAM_LABEL = "derived: set by a fit (servosurf.servo.set_param), not calibrated"


def set_param(machine: Machine, key: str, value: float) -> Machine:
    """Copy of ``machine`` with one dotted parameter replaced.

    The parameter's provenance label (if the machine has a ``[provenance]`` table)
    becomes :data:`SET_PARAM_LABEL`: the built-in's label described its own value.
    """
    sec, name = _split(key)
    section = getattr(machine, sec)
    out = dataclasses.replace(
        machine, **{sec: dataclasses.replace(section, **{name: value})}
    )
    if machine.provenance:
        dotted = f"{sec}.{name}".replace("_", "-")
        prov = dict(machine.provenance)
        if dotted in prov:
            prov[dotted] = SET_PARAM_LABEL
            out = dataclasses.replace(out, provenance=tuple(sorted(prov.items())))
    return out


@dataclass(frozen=True, eq=False)
class Identification:
    """Result of :func:`identify`.

    Attributes
    ----------
    machine : Machine
        The machine with fitted parameters.
    parameters : dict
        Fitted values (SI) by dotted key.
    initial : dict
        Starting values (SI).
    fit_percent_before, fit_percent_after : float
        MATLAB-style fit of the model FRF to the data, in percent.
    """

    machine: Machine
    parameters: dict[str, float]
    initial: dict[str, float]
    fit_percent_before: float
    fit_percent_after: float


def identify(
    machine: Machine,
    freq: np.ndarray,
    frf: np.ndarray,
    *,
    params: tuple[str, ...] = DEFAULT_IDENT_PARAMS,
    digital: bool = True,
    model=None,
) -> Identification:
    """Fit machine parameters to a measured FRF by nonlinear least squares.

    Parameters
    ----------
    machine : Machine
        Starting point (grey box); parameters not in ``params`` are held.
    freq : ndarray of shape (n,)
        Frequencies in Hz.
    frf : ndarray of shape (n,), complex
        Measured response (default: DAC V -> sensor V open loop).
    params : tuple of str
        Dotted parameter keys to fit (positive; fitted in log space).
    digital : bool, default: True
        The sweep went through the DSP (ZOH and delay included).
    model : callable, optional
        ``model(machine, freq) -> frf`` for other FRF kinds (closed loop, force).

    Returns
    -------
    Identification
        Fitted machine and fit percentages before and after.

    Notes
    -----
    The residual is the complex log ratio ``log(yhat / y)`` (log magnitude and phase),
    which weighs every decade alike; the reported fit is MATLAB's
    ``100 (1 - ||y - yhat|| / ||y - mean(y)||)`` on the complex data.
    """
    freq = np.asarray(freq, dtype=float)
    y = np.asarray(frf, dtype=complex)
    if y.shape != freq.shape:
        raise ConfigError(f"frf shape {y.shape} differs from freq shape {freq.shape}")
    if model is None:

        def model(m, f):
            return open_loop_frf(m, f, digital=digital)

    x0 = np.log([get_param(machine, k) for k in params])
    if not np.all(np.isfinite(x0)):
        raise ConfigError("every identified parameter must start positive")

    def build(x):
        m = machine
        for k, v in zip(params, np.exp(x), strict=True):
            m = set_param(m, k, float(v))
        return m

    def res(x):
        yh = model(build(x), freq)
        r = np.log(yh / y)
        r = r.imag * 1j + r.real
        # wrap phase
        ph = (r.imag + np.pi) % (2 * np.pi) - np.pi
        return np.concatenate([r.real, ph])

    before = fit_percent(y, model(machine, freq))
    sol = sp.optimize.least_squares(res, x0, x_scale=1.0, method="trf", max_nfev=400)
    fitted = build(sol.x)
    after = fit_percent(y, model(fitted, freq))
    return Identification(
        machine=fitted,
        parameters=dict(zip(params, map(float, np.exp(sol.x)), strict=True)),
        initial=dict(zip(params, map(float, np.exp(x0)), strict=True)),
        fit_percent_before=before,
        fit_percent_after=after,
    )
