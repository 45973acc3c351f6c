"""Minimum chip thickness: ploughing at the feed-mark ridges (DISCOVERY.md rows 12
and 13, the material side of the cut)."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from ._base import Config, Effect, EffectParams, Free, quantity

__all__ = ["MinimumChipThicknessParams", "MinimumChipThicknessEffect"]

NAME = "minimum-chip-thickness"

#: Largest minimum chip thickness accepted as physics, m.
H_MIN_MAX = 50e-9
#: Smallest and number of the screened levels of h_min (m; log-spaced up to the
#: search's top).
LEVEL_MIN = 2e-9
N_LEVELS = 7
#: Share of f^2 / 2R (the thickness a pass meets at the bottom of the previous
#: one) up to which the pointwise model is searched on cuts whose passes overlap.
WINDOW_SHARE = 0.9


def overlap_limit(ev) -> float | None:
    """Largest h_min in m the pointwise model evaluates on the case's cut, or None
    (single-pass cuts: lenslets).

    On a cut whose passes overlap (facing, spirals, NC programs) with feed f per
    revolution and nose radius R, a pass meets at most ``f^2 / 2R`` of the surface
    the previous pass left. Below that every pass cuts and each point's surface
    follows from its nearest passes (Brammertz's regime, the one evaluated here).
    Above it passes are skipped, and which ones depends on the whole history of
    the cut from its start (and on the tool noise); the nearest-pass model
    cannot describe that, so the search stops at ``WINDOW_SHARE`` of it and a
    fit that wants more sits at the search bound and is refused.
    """
    case = getattr(ev, "case", None)
    spec = getattr(case, "toolpath", None)
    if spec is None or spec.kind == "lenslet":
        return None
    from .._surface import feed_per_rev

    f = feed_per_rev(spec)
    if f <= 0.0:
        return None
    return WINDOW_SHARE * f * f / (2.0 * float(spec.tool.nose_radius))


@dataclass(frozen=True)
class MinimumChipThicknessParams(EffectParams):
    """A pass removes material only where it meets more than ``h_min`` of it; a
    thinner sliver (at the ridge an earlier pass left, or at the rim of a cut) is
    ploughed and stays (Brammertz's rule, the ``ploughing`` part of
    :func:`servosurf.simulation.simulate`)."""

    effect = NAME

    h_min: float = quantity(
        unit="m", doc="minimum chip thickness (uncut thickness along z)",
        low=0.0, high=H_MIN_MAX,
        source="h_min is 0.2-0.4 of the cutting-edge radius for ductile metals "
        "cut with diamond (Yuan, Zhou, Dong, J. Mater. Process. Technol. 62 "
        "(1996) 327; Son, Lim, Ahn, Int. J. Mach. Tools Manuf. 45 (2005) 529); "
        "single-crystal diamond edges are 5-100 nm in radius (a worn one about "
        "100 nm), so 0.4 x 100 nm = 40 nm is the largest and 50 nm leaves a "
        "margin; a negative thickness is no physics (>= 0)")

    def cutting_rules(self, rules):
        """Material rules of the ordered sweep with this minimum chip thickness
        (m): the larger of the two when the rules already hold one."""
        return dataclasses.replace(
            rules, min_chip_thickness=max(rules.min_chip_thickness, self.h_min))


class MinimumChipThicknessEffect(Effect):
    name = NAME
    title = "Minimum chip thickness (ploughing)"
    physics = (
        "Below a minimum uncut thickness h_min (a fraction of the cutting-edge "
        "radius) the edge ploughs and rubs instead of cutting: a pass leaves the "
        "material where it would remove less than h_min, so the feed-mark ridges "
        "stand higher (Brammertz: Rt = f^2/8R + (h_min/2)(1 + R h_min/f^2)) and the "
        "rim of a single-pass cut moves inward."
    )
    signature = (
        "Maps and profiles of cuts whose passes overlap (facing, spirals, NC "
        "programs): the cusps between passes higher by up to h_min over a band "
        "of width R h_min / f on the side of the later pass, the same at every "
        "radius with the same feed; raises Rz and Ra. Single-pass lenslets: only "
        "the rim, where the depth is below h_min. No servo signature. Modelled "
        "for h_min < f^2/2R, where every pass cuts (beyond it passes are "
        "skipped as the cut's history decides)."
    )
    confused_with = (
        "tool-radius-error (changes the whole cusp, not its top); elastic-recovery "
        "(proportional to the depth, everywhere in the cut); tool-edge-waviness "
        "(a function of the contact angle, also in the valleys)."
    )
    channels = ("surface", "profile")
    params = MinimumChipThicknessParams

    threshold = True

    def _search_max(self, ev) -> float:
        lim = overlap_limit(ev)
        return 4 * H_MIN_MAX if lim is None else min(4 * H_MIN_MAX, lim)

    def configs(self, ev, model):
        # a threshold: the surface change is not linear in h_min (the ploughed
        # band is R h_min / f wide and up to h_min high, often below a pixel), so
        # the candidates are levels, searched between neighbours on the deviance.
        # None on a single-pass cut (lenslets): there it acts only at the rim,
        # which the map and profile likelihoods leave out with the cut edge
        if overlap_limit(ev) is None:
            return []
        top = self._search_max(ev)
        return [Config(f"{h * 1e9:.3g} nm", {"h": float(h)})
                for h in np.geomspace(min(LEVEL_MIN, 0.5 * top), top, N_LEVELS)]

    def _term(self, model, cfg):
        return model.with_terms(NAME, (MinimumChipThicknessParams(cfg.values["h"]),))

    def columns(self, model, cfg, ev):
        return [(self._term(model, cfg), 1.0)]

    def start(self, model, cfg, coefs, ev):
        return self._term(model, cfg)

    def free(self, model, slot, ev, cfg=None):
        # h_min > 0 (a pass never removes more than it meets; searched in log);
        # the search goes beyond the physical bound so that a fit that wants
        # more is seen and refused, not clipped into a plausible-looking value;
        # on overlapping passes it stops where the pointwise model stops holding
        top = self._search_max(ev)
        return [Free("h_min", NAME, slot, "h_min", min(LEVEL_MIN, 0.5 * top) / 10,
                     top, True)]
