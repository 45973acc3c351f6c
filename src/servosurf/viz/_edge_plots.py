"""Figure of a measured tool edge: the trace, the fitted nose, spikes and deviation.

Inputs are SI (m, rad); the figure shows positions in um, deviations in um and
angles in degrees. matplotlib is imported inside the function (Agg canvas, no
pyplot) and the file is written atomically.
"""

from __future__ import annotations

import math
import os
from pathlib import Path
from typing import Any

import numpy as np

from ._surface_plots import _new_figure, _save_atomic

__all__ = ["plot_tool_edge"]


def plot_tool_edge(
    edge: Any, path: str | os.PathLike[str], *, dpi: int = 120
) -> Path:
    """Write the trace with its fit, the rejected spikes and the edge deviation.

    Parameters
    ----------
    edge : ToolEdge
        The fitted trace (coordinates in m, angles in rad).
    path : str or path-like
        Destination PNG file.
    dpi : int, default: 120
        Resolution, in dots per inch.

    Returns
    -------
    pathlib.Path
        The written file.

    Notes
    -----
    Left: every trace point (um), the fitted circle, the usable arc, the tool axis
    and the rejected points (spikes and gross outliers inside the arc). Right: the
    radial residual of each point against its contact angle (degrees, outward
    positive), the rejected points, and the smoothed deviation the Tool uses.
    """
    um = 1e6
    cu, cv = edge.centre
    r = edge.radius
    fig = _new_figure((12.0, 5.2))
    ax1, ax2 = fig.subplots(1, 2, gridspec_kw={"width_ratios": [1.0, 1.3]})
    ax1.plot(edge.u * um, edge.v * um, ".", ms=2, color="0.6", label="trace")
    used = edge.used
    ax1.plot(edge.u[used] * um, edge.v[used] * um, ".", ms=3, color="C0",
             label="usable arc")
    ax1.plot(edge.u[edge.spike] * um, edge.v[edge.spike] * um, "x", ms=5,
             color="C3", label=f"rejected ({int(edge.spike.sum())})")
    t = np.linspace(0.0, 2.0 * np.pi, 721)
    ax1.plot((cu + r * np.cos(t)) * um, (cv + r * np.sin(t)) * um, "-", lw=0.8,
             color="C1", label=f"fit R = {r * um:.2f} \u00b5m")
    ax1.plot([cu * um, (cu + 1.3 * r * math.cos(edge.axis_angle)) * um],
             [cv * um, (cv + 1.3 * r * math.sin(edge.axis_angle)) * um], "k--",
             lw=0.8, label="tool axis")
    pad = 2.5 * r * um
    ax1.set_xlim(cu * um - pad, cu * um + pad)
    ax1.set_ylim(cv * um - pad, cv * um + pad)
    ax1.set_aspect("equal")
    cols = edge.metadata.get("plane_columns") or [0, 1]
    ax1.set_xlabel(f"u = column {cols[0]} (\u00b5m)")
    ax1.set_ylabel(f"v = column {cols[1]} (\u00b5m)")
    ax1.set_title("Trace and fitted nose")
    ax1.legend(fontsize=7, loc="upper right")
    deg = 180.0 / math.pi
    lo, hi = edge.arc
    near = (edge.angle >= lo - 0.35) & (edge.angle <= hi + 0.35)
    near &= np.abs(edge.residual) < 0.05 * r
    ax2.plot(edge.angle[near & ~used & ~edge.spike] * deg,
             edge.residual[near & ~used & ~edge.spike] * um, ".", ms=3,
             color="0.6", label="outside the usable arc")
    ax2.plot(edge.angle[used] * deg, edge.residual[used] * um, ".", ms=4,
             color="C0", label="kept points")
    sp = edge.spike & (np.abs(edge.residual) < 0.05 * r)
    ax2.plot(edge.angle[sp] * deg, edge.residual[sp] * um, "x", ms=5, color="C3",
             label="spikes")
    ax2.plot(edge.waviness_angle * deg, edge.waviness_deviation * um, "-",
             color="C1", lw=1.5,
             label=f"smoothed (Gaussian, \u03bbc = "
             f"{edge.settings.smoothing * um:g} \u00b5m)")
    for a in (lo, hi):
        ax2.axvline(a * deg, color="k", ls=":", lw=0.8)
    ax2.axhline(0.0, color="k", lw=0.5)
    kept = edge.residual[used]
    span = max(float(np.max(np.abs(kept))) if kept.size else 1e-6, 0.5e-6)
    ax2.set_ylim(-2.0 * span * um, 2.0 * span * um)
    side = "smaller u" if edge.settings.mirror else "larger u"
    ax2.set_xlabel(f"contact angle \u03c6 (degree, outward +: towards {side})")
    ax2.set_ylabel("edge deviation (\u00b5m, outward +)")
    ax2.set_title(
        f"Deviation from the fitted circle (usable arc {lo * deg:.1f} .. "
        f"{hi * deg:.1f} degree)"
    )
    ax2.legend(fontsize=7, loc="lower center")
    return _save_atomic(fig, path, dpi)
