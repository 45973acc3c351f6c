"""Tool nose radius error (DISCOVERY.md catalogue row 9)."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

from ._base import Bound, Effect, EffectParams, Free, quantity

__all__ = ["ToolRadiusErrorParams", "ToolRadiusErrorEffect"]

NAME = "tool-radius-error"

#: Largest nose-radius error as a share of the nominal radius.
MAX_SHARE = 0.1


@dataclass(frozen=True)
class ToolRadiusErrorParams(EffectParams):
    """The nose radius is ``R + radius_error`` instead of R (tip held)."""

    effect = NAME

    radius_error: float = quantity(
        unit="m", doc="nose radius error dR",
        low=Bound("-0.1 R", lambda ev, p: -MAX_SHARE * ev.nominal.tool_radius),
        high=Bound("0.1 R", lambda ev, p: MAX_SHARE * ev.nominal.tool_radius),
        source="single-crystal diamond tools are sold with the nose radius "
        "specified to about +-10 % (and profiled to a few um); a larger error "
        "is another tool")

    def edge(self, phi):
        """Pointwise tool hook: the radius change, no edge deviation."""
        return self.radius_error, None

    def tool(self, tool):
        """The tool with the radius error."""
        return dataclasses.replace(tool, nose_radius=tool.nose_radius
                                   + self.radius_error)


class ToolRadiusErrorEffect(Effect):
    name = NAME
    title = "Tool nose radius error"
    physics = (
        "The nose radius is R + dR instead of R (tip held): the surface "
        "across the cut changes by dR (1 - R / sqrt(R^2 - dr^2)) ~ -dR dr^2 / "
        "(2 R^2)."
    )
    signature = (
        "Maps only: error quadratic in the radial offset across the cut "
        "(contact angle), identical along the cut, in every lenslet."
    )
    confused_with = (
        "tool-edge-waviness (orders >= 3); elastic-recovery (also "
        "follows the depth along the cut)."
    )
    channels = ("surface", "profile")
    params = ToolRadiusErrorParams

    def _current(self, model):
        ps = model.get(NAME)
        return ps[0].radius_error if ps else 0.0

    def columns(self, model, cfg, ev):
        q = ToolRadiusErrorParams(self._current(model) + 1e-6)
        return [(model.with_terms(NAME, (q,)), 1e-6)]

    def start(self, model, cfg, coefs, ev):
        return model.with_terms(NAME, (ToolRadiusErrorParams(1e-6 * float(coefs[0])),))

    def free(self, model, slot, ev, cfg=None):
        return [Free("radius_error", NAME, slot, "radius_error", -2e-4, 2e-4)]
