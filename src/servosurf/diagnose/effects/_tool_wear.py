"""Tool wear: the nose radius grows with cutting length (DISCOVERY.md row 18)."""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np

from ._base import Bound, Effect, EffectParams, Free, quantity

__all__ = ["ToolWearParams", "ToolWearEffect", "cutting_speed"]

NAME = "tool-wear"

#: Largest radius growth over the recorded cut as a share of the nominal radius.
MAX_SHARE = 0.1


def cutting_speed(spec) -> float:
    """Mean rate (m/s) at which the edge cuts length along a toolpath: the surface
    speed times the share of the time the tool is in the material (lenslet paths:
    the share of the FTS period below the pre-cut face; facing and design spirals:
    always; NC block paths: the arc length of the cutting blocks over their
    duration)."""
    path = spec.path
    if spec.kind == "lenslet":
        a, d = path.amplitude, path.depth_of_cut
        # z = (a - d) - a sin(2 pi f t) < 0 while sin > (a - d) / a
        share = 0.5 - math.asin(min(max((a - d) / a, -1.0), 1.0)) / math.pi
        r = float(np.mean(path.ring_radii()))
    elif hasattr(path, "r_start"):
        share = 1.0
        r = 0.5 * (path.r_start + path.r_end)
    else:
        # NC block path: vertex arrays in time; the cut length is the arc swept
        # (r dtheta per segment, radial feed neglected) over the path's duration.
        r_mid = 0.5 * (path.r[1:] + path.r[:-1])
        length = float(np.sum(r_mid * np.abs(np.diff(path.theta))))
        return length / max(float(path.duration), 1e-12)
    return float(path.angular_speed * r * share)


def _max_growth(ev, p) -> float:
    case = ev.case
    span = float(case.toolpath.path.duration) if case is not None else 1.0
    return MAX_SHARE * ev.nominal.tool_radius / max(p.cutting_speed * span, 1e-12)


@dataclass(frozen=True)
class ToolWearParams(EffectParams):
    """The nose radius is ``R + g v t`` at time t (tip held): it grows by ``g`` per
    metre of cutting length, the edge cutting ``v`` metres per second."""

    effect = NAME

    growth: float = quantity(
        unit="1", doc="nose radius growth per cutting length g (m per m)",
        low=0.0, high=Bound("0.1 R / (v T)", _max_growth),
        source="wear only removes diamond: the radius of a worn round nose grows "
        "(low 0); single-crystal tools are profiled to a few um and sold to "
        "+-10 % of R, so a growth of 0.1 R over the recorded cut (length v T, T "
        "the toolpath's duration) is another, chipped tool. Real wear is far "
        "slower: diamond wear on electroless nickel is measured over kilometres "
        "of cutting (Paul, Evans, Mangamelli, McGlauflin, Polvani, Prec. Eng. 18 "
        "(1996) 4)")
    cutting_speed: float = quantity(
        0.0, unit="m/s", doc="cutting length per second v (from the toolpath)",
        low=0.0, high=100.0, fitted=False,
        source="set from the toolpath (surface speed times the engaged share); "
        "diamond turning runs below 100 m/s (40 mm/s to 20 m/s in practice)")

    def growth_at(self, t) -> np.ndarray:
        """The radius growth in m at times ``t`` (s)."""
        return self.growth * self.cutting_speed * np.maximum(np.asarray(t, float), 0.0)

    def tool(self, tool):
        """The tool at t = 0 (unworn: the nominal tool)."""
        return tool

    def edge(self, phi):
        """Pointwise tool hook at t = 0: no change."""
        return 0.0, None

    def tool_at(self, tool, t: float):
        """The tool at time ``t`` (s): nose radius grown by ``g v t``."""
        return dataclasses.replace(
            tool, nose_radius=tool.nose_radius + float(self.growth_at(t)))

    def edge_at(self, t, phi):
        """Pointwise tool hook at times ``t`` (s): the radius growth, no edge
        deviation."""
        return self.growth_at(t), None


class ToolWearEffect(Effect):
    name = NAME
    title = "Tool wear (nose radius growing with cutting length)"
    physics = (
        "Abrasive and chemical wear flattens the engaged nose: the radius grows "
        "with the cutting length L, R(L) = R + g L (tip held), so the surface "
        "across the cut changes by about -g L dr^2 / (2 R^2)."
    )
    signature = (
        "Maps only: an error quadratic across the cut (contact angle) that grows "
        "with cutting time from ring to ring (cusps between passes drop as "
        "f^2 / 8R(L)); none in the following error."
    )
    confused_with = (
        "tool-radius-error (static: the same in every ring); thermal-drift "
        "(a height change in time, not a change of shape across the cut)."
    )
    channels = ("surface", "profile")
    params = ToolWearParams

    def _speed(self, ev) -> float:
        case = ev.case
        return cutting_speed(case.toolpath) if case is not None else 0.0

    def _probe(self, ev) -> float:
        """Growth giving 1 um of radius change over the toolpath's duration."""
        case = ev.case
        span = float(case.toolpath.path.duration) if case is not None else 1.0
        return 1e-6 / max(self._speed(ev) * span, 1e-12)

    def _current(self, model):
        ps = model.get(NAME)
        return ps[0].growth if ps else 0.0

    def columns(self, model, cfg, ev):
        pr = self._probe(ev)
        q = ToolWearParams(self._current(model) + pr, self._speed(ev))
        return [(model.with_terms(NAME, (q,)), pr)]

    def start(self, model, cfg, coefs, ev):
        g = self._probe(ev) * float(coefs[0])
        return model.with_terms(NAME, (ToolWearParams(g, self._speed(ev)),))

    def free(self, model, slot, ev, cfg=None):
        pr = self._probe(ev)
        return [Free("growth", NAME, slot, "growth", -100 * pr, 100 * pr)]
