"""Elastic recovery / spring-back (DISCOVERY.md catalogue row 13)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ...errors import ConfigError
from ._base import Effect, EffectParams, Free, quantity

__all__ = ["ElasticRecoveryParams", "ElasticRecoveryEffect"]

NAME = "elastic-recovery"


@dataclass(frozen=True)
class ElasticRecoveryParams(EffectParams):
    """The work springs back behind the flank by ``recovery`` times the local depth
    of cut: ``z -> z + recovery (top - z)``."""

    effect = NAME

    recovery: float = quantity(
        unit="1", doc="fraction of the depth that springs back", low=0.0, high=0.2,
        source="spring-back after plastic indentation is of order H/E (Johnson, "
        "Contact Mechanics, Cambridge 1985, ch. 6); electroless NiP has H 5-7 GPa "
        "and E 100-200 GPa (Weil and Parker in Mallory and Hajdu, Electroless "
        "Plating, 1990): 0.03-0.07, so 0.2 is three times the largest; the work "
        "never sinks below the edge (>= 0)")

    def surface_heights(self, z, top: float):
        """Pointwise surface hook: heights ``z`` (m) below the pre-cut ``top`` (m)
        after the spring-back."""
        if self.recovery:
            return z + self.recovery * (top - z)
        return z

    def surface(self, surface, context):
        """The machined surface after the spring-back (flat pre-cut faces)."""
        wp = context.get("workpiece")
        if wp is None or wp.precut.kind != "flat":
            raise ConfigError("elastic-recovery needs a flat pre-cut face "
                              "(workpiece precut.kind = 'flat')")
        z = np.asarray(surface.z, dtype=float)
        return surface.replace(z=self.surface_heights(z, float(wp.precut.height)))


class ElasticRecoveryEffect(Effect):
    name = NAME
    title = "Elastic recovery (spring-back)"
    physics = (
        "The work springs back behind the flank by a fraction eps of the "
        "local depth of cut: dz = eps (top - z)."
    )
    signature = (
        "Maps only: a sag error proportional to the local depth, both along "
        "and across the cut (shallower lenslets); no servo signature."
    )
    confused_with = (
        "tool-radius-error (across the cut only); sensor gain error "
        "(identical on single-pass lenslets; compare with a facing cut); "
        "cutting-force-coefficient (has a force signature)."
    )
    channels = ("surface", "profile")
    params = ElasticRecoveryParams

    def _current(self, model):
        ps = model.get(NAME)
        return ps[0].recovery if ps else 0.0

    def columns(self, model, cfg, ev):
        q = ElasticRecoveryParams(self._current(model) + 1e-3)
        return [(model.with_terms(NAME, (q,)), 1e-3)]

    def start(self, model, cfg, coefs, ev):
        return model.with_terms(NAME, (ElasticRecoveryParams(1e-3 * float(coefs[0])),))

    def free(self, model, slot, ev, cfg=None):
        # eps >= 0: the work springs back behind the flank, it never sinks below
        # the edge (a negative value only fitted noise: a seed-59 null case named
        # elastic recovery at eps = -1.1e-6, score 1.0)
        return [Free("recovery", NAME, slot, "recovery", 0.0, 0.2)]
