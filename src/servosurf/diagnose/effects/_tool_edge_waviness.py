"""Tool nose (edge) waviness (DISCOVERY.md catalogue row 9)."""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np

from ._base import Effect, EffectParams, Free, quantity

__all__ = ["ToolEdgeWavinessParams", "ToolEdgeWavinessEffect", "phi_reference",
           "legendre_waviness"]

NAME = "tool-edge-waviness"
#: Legendre orders of the waviness terms.
ORDERS = (3, 4, 5, 6)
#: Points of the waviness table the ``tool`` hook writes (over the edge arc).
TABLE_POINTS = 4001

_SOURCE = (
    "diamond tool makers grade the nose waviness over the used arc at 0.05-0.5 um "
    "(controlled-waviness tools) to about 1 um (standard tools); each Legendre "
    "coefficient within +-1 um")


def phi_reference(case) -> float:
    """Contact angle (rad) spanned by the cut: the waviness basis runs over it."""
    spec = case.toolpath
    r = spec.tool.nose_radius
    from .._surface import feed_per_rev

    depth = spec.path.depth_of_cut if spec.kind == "lenslet" else feed_per_rev(spec) * 4
    half = min(math.sqrt(max(2 * r * depth - depth * depth, 0.0)), spec.tool.half_width)
    return max(math.asin(min(half / r, 1.0)), 1e-6)


def legendre_waviness(phi: np.ndarray, coefs, phi_ref: float) -> np.ndarray:
    """Edge deviation ``sum c_k P_{k+3}(phi / phi_ref)`` in m (orders 3, 4, ...)."""
    if not len(coefs):
        return np.zeros_like(phi)
    u = np.clip(phi / phi_ref, -1.5, 1.5)
    c = np.zeros(3 + len(coefs))
    c[3:] = coefs
    return np.polynomial.legendre.legval(u, c)


@dataclass(frozen=True)
class ToolEdgeWavinessParams(EffectParams):
    """Outward edge deviation ``W(phi) = sum_k p_k P_k(phi / phi_ref)``, k = 3..6,
    lowering the surface by ``W / cos(phi)``."""

    effect = NAME

    reference_angle: float = quantity(
        unit="rad", doc="contact angle phi_ref the Legendre basis spans",
        low=0.0, high=math.pi / 2, fitted=False,
        source="geometry: the half-angle of the arc the cut uses (set from the "
        "toolpath's depth of cut and nose radius)")
    p3: float = quantity(0.0, unit="m", doc="Legendre coefficient of order 3",
                         low=-1e-6, high=1e-6, source=_SOURCE)
    p4: float = quantity(0.0, unit="m", doc="Legendre coefficient of order 4",
                         low=-1e-6, high=1e-6, source=_SOURCE)
    p5: float = quantity(0.0, unit="m", doc="Legendre coefficient of order 5",
                         low=-1e-6, high=1e-6, source=_SOURCE)
    p6: float = quantity(0.0, unit="m", doc="Legendre coefficient of order 6",
                         low=-1e-6, high=1e-6, source=_SOURCE)

    @property
    def coefficients(self) -> tuple[float, float, float, float]:
        """``(p3, p4, p5, p6)`` in m."""
        return (self.p3, self.p4, self.p5, self.p6)

    def edge_deviation(self, phi: np.ndarray) -> np.ndarray:
        """Outward deviation of the edge in m at contact angles ``phi`` (rad)."""
        return legendre_waviness(phi, self.coefficients, self.reference_angle)

    def edge(self, phi: np.ndarray):
        """Pointwise tool hook: no radius change, the deviation at ``phi``."""
        return 0.0, self.edge_deviation(phi)

    def tool(self, tool):
        """The tool with this waviness added to its edge profile."""
        a = tool.arc_half_angle
        phi = np.linspace(-a, a, TABLE_POINTS)
        dev = self.edge_deviation(phi)
        if tool.has_waviness:
            dev = dev + np.interp(phi, np.asarray(tool.waviness_angle),
                                  np.asarray(tool.waviness_deviation))
        return dataclasses.replace(tool, waviness_angle=tuple(phi),
                                   waviness_deviation=tuple(dev))


class ToolEdgeWavinessEffect(Effect):
    name = NAME
    title = "Tool nose (edge) waviness"
    physics = (
        "The diamond edge is not a circle: an outward deviation "
        "W(phi) = sum c_k P_k(phi / phi_ref), k = 3..6 (Legendre in the "
        "contact angle over the cut's range) lowers the surface by W / cos phi."
    )
    signature = (
        "Maps only: an error depending on the contact angle (the radial "
        "offset across the cut), identical in every lenslet, ring and "
        "speed; orders >= 3 in phi."
    )
    confused_with = (
        "tool-radius-error (the order-2 part); elastic-recovery (also "
        "across the cut, but follows the depth along the cut too)."
    )
    channels = ("surface", "profile")
    params = ToolEdgeWavinessParams

    def _params(self, ev, coefs) -> ToolEdgeWavinessParams:
        ref = ev.memo((NAME, "phi_ref"), lambda: phi_reference(ev.case))
        return ToolEdgeWavinessParams(ref, *(float(c) for c in coefs))

    def columns(self, model, cfg, ev):
        ps = model.get(NAME)
        base = np.array(ps[0].coefficients if ps else (0.0,) * 4)
        out = []
        for k in range(4):
            w = base.copy()
            w[k] += 1e-9
            out.append((model.with_terms(NAME, (self._params(ev, w),)), 1e-9))
        return out

    def start(self, model, cfg, coefs, ev):
        return model.with_terms(
            NAME, (self._params(ev, 1e-9 * np.asarray(coefs, dtype=float)),))

    def free(self, model, slot, ev, cfg=None):
        return [Free(f"p{k}", NAME, slot, f"p{k}", -1e-6, 1e-6) for k in ORDERS]
