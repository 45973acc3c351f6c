"""Thermal drift of the structural loop (DISCOVERY.md catalogue row 10)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ._base import Config, Effect, EffectParams, Free, quantity

__all__ = ["ThermalDriftParams", "ThermalDriftEffect"]

NAME = "thermal-drift"

_EXPANSION = (
    "structural-loop expansion alpha L dT with alpha = 11.5e-6 /K (steel), "
    "L = 0.3 m: 3.5 um/K; thermal errors dominate machine-tool error budgets at "
    "the 10 um level (Bryan, CIRP Ann. 39 (1990) 645)")


#: Fastest drift of the tool-to-work distance (m/s).
MAX_RATE = 1e-6
_RATE_SOURCE = (
    _EXPANSION + "; 1 um/s would need the whole loop to warm by 0.3 K/s, while "
    "spindle and coil warm-up drift by micrometres over tens of minutes (Bryan "
    "1990)")


@dataclass(frozen=True)
class ThermalDriftParams(EffectParams):
    """Tool-to-work distance drifting with cutting time, ``a (1 - exp(-t / tau)) +
    b t``, outside the loop."""

    effect = NAME

    amplitude: float = quantity(
        unit="m", doc="saturating drift a", low=-10e-6, high=10e-6,
        source=_EXPANSION + "; 10 um is a 3 K change of the whole loop")
    time_constant: float = quantity(
        unit="s", doc="thermal time constant tau", low=0.02, high=1e3,
        source="coil heating settles in seconds, a machine structure in minutes "
        "to hours (Bryan 1990); below 20 ms a saturating drift is a step, above "
        "1000 s it is the linear rate over a cut of seconds (not identifiable)")
    rate: float = quantity(
        unit="m/s", doc="linear drift rate b", low=-MAX_RATE, high=MAX_RATE,
        source=_RATE_SOURCE)

    def implausible(self, evidence) -> str | None:
        """The bounds of each value, and of the drift's fastest rate: ``|a / tau +
        b|`` at the start of the cut (m/s), as bounded as ``b`` (a fast saturating
        rise cancelled by a fast linear fall is no slower a warming)."""
        why = super().implausible(evidence)
        if why is not None:
            return why
        v0 = self.amplitude / max(self.time_constant, 1e-12) + self.rate
        if abs(v0) > MAX_RATE:
            return (f"initial drift rate amplitude / time_constant + rate = "
                    f"{v0:.4g} m/s is beyond its physical bound {MAX_RATE:.4g} m/s "
                    f"({_RATE_SOURCE})")
        return None

    def path_z(self, t, theta, r, z):
        """The drift in m at times ``t`` (s)."""
        dz = np.zeros(np.shape(t))
        if self.amplitude:
            dz += self.amplitude * -np.expm1(-t / max(self.time_constant, 1e-9))
        if self.rate:
            dz += self.rate * t
        return dz


class ThermalDriftEffect(Effect):
    name = NAME
    title = "Thermal drift of the structural loop"
    physics = (
        "Coil i^2 R heating, spindle warm-up, ambient: the tool-to-work "
        "distance drifts, d(t) = a (1 - exp(-t / tau)) + b t, outside the loop."
    )
    signature = (
        "Maps/profiles only: a slow trend against cutting time (piston steps "
        "between lenslet rings, a trend along each ring); none in the "
        "following error."
    )
    confused_with = (
        "X-slide straightness (a function of radius, not time: cut with "
        "another feed); order-1 spindle axial error (repeats each turn)."
    )
    channels = ("surface", "profile")
    params = ThermalDriftParams
    taus = (0.3, 1.0, 3.0, 10.0)

    def configs(self, ev, model):
        out = [Config("linear", {"form": "lin", "tau": 1.0})]
        for t in self.taus:
            out.append(Config(f"saturating, tau {t:g} s", {"form": "exp", "tau": t}))
            out.append(Config(f"both, tau {t:g} s", {"form": "both", "tau": t}))
        return out

    def n_params(self, cfg=None):
        if cfg is None:
            return 3
        return {"lin": 1, "exp": 2, "both": 3}[cfg.values["form"]]

    def columns(self, model, cfg, ev):
        form, tau = cfg.values["form"], cfg.values["tau"]
        out = []
        if form != "lin":
            q = ThermalDriftParams(1e-9, tau, 0.0)
            out.append((model.with_terms(NAME, (q,)), 1e-9))
        if form != "exp":
            q = ThermalDriftParams(0.0, tau, 1e-9)
            out.append((model.with_terms(NAME, (q,)), 1e-9))
        return out

    def start(self, model, cfg, coefs, ev):
        form, tau = cfg.values["form"], cfg.values["tau"]
        c = list(coefs)
        a = 1e-9 * float(c.pop(0)) if form != "lin" else 0.0
        b = 1e-9 * float(c.pop(0)) if form != "exp" else 0.0
        return model.with_terms(NAME, (ThermalDriftParams(a, tau, b),))

    def free(self, model, slot, ev, cfg=None):
        form = "both" if cfg is None else cfg.values["form"]
        out = []
        if form != "lin":
            out += [
                Free("amplitude", NAME, slot, "amplitude", -1e-5, 1e-5),
                Free("time_constant", NAME, slot, "time_constant", 0.02, 1e3, True),
            ]
        if form != "exp":
            out.append(Free("rate", NAME, slot, "rate", -10 * MAX_RATE,
                            10 * MAX_RATE))
        return out
