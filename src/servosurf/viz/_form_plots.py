"""Figures of the form error against a design and of a design toolpath (Agg).

Inputs are SI (m); heights are shown in nm, positions in um or mm.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import ConfigError
from ._surface_plots import _draw_map, _new_figure, _save_atomic, _unit

__all__ = ["plot_form_error", "plot_design_feed"]


def plot_form_error(form: Any, path: str | os.PathLike[str], *,
                    title: str | None = None, unit: str = "nm",
                    dpi: int = 120) -> Path:
    """Write the form-error map(s) against the design to a PNG file.

    Parameters
    ----------
    form : DesignFormError
        Result of :func:`servosurf.metrology.form_error_against_design`.
    path : str or path-like
        Destination PNG file.
    title : str or None, default: None
        Figure title.
    unit : {"nm", "um"}, default: "nm"
        Height unit of the colour bars.
    dpi : int, default: 120
        Resolution of the PNG, in dots per inch.

    Returns
    -------
    pathlib.Path
        The written file.

    Raises
    ------
    ConfigError
        If ``form`` is not a form-error result or ``unit`` is unknown.

    Notes
    -----
    Left: the error after the removed terms (piston, tilt), PV and RMS in the
    panel title. Right, when the best-fit sphere was computed: the error after it.
    """
    scale = _unit(unit)
    if not hasattr(form, "error") or not hasattr(form, "pv"):
        raise ConfigError(f"form must be a DesignFormError, got {type(form).__name__}")
    panels = [(form.error, form.pv, form.rms,
               "after " + (" and ".join(form.removed) or "nothing removed"))]
    if form.error_bfs is not None:
        panels.append((form.error_bfs, form.pv_bfs, form.rms_bfs,
                       "after piston, tilt and best-fit sphere"))
    fig = _new_figure((5.6 * len(panels), 4.8))
    axes = fig.subplots(1, len(panels), squeeze=False)[0]
    for ax, (surf, pv, rms, what) in zip(axes, panels, strict=True):
        sub = (f"{what}\nPV {pv / scale:.3g} {unit}, RMS {rms / scale:.3g} {unit}")
        _draw_map(fig, ax, surf, unit, sub)
    fig.suptitle(title or "Form error against the design")
    return _save_atomic(fig, path, dpi)


def plot_design_feed(toolpath: Any, path: str | os.PathLike[str], *,
                     theta: float = 0.0, title: str | None = None,
                     dpi: int = 120) -> Path:
    """Write the design toolpath's section and feed per revolution to a PNG file.

    Parameters
    ----------
    toolpath : DesignToolpath
        The path.
    path : str or path-like
        Destination PNG file.
    theta : float, default: 0.0
        Spindle angle of the section shown, in rad.
    title : str or None, default: None
        Figure title.
    dpi : int, default: 120
        Resolution of the PNG, in dots per inch.

    Returns
    -------
    pathlib.Path
        The written file.

    Raises
    ------
    ConfigError
        If ``toolpath`` is not a design toolpath.
    """
    if not hasattr(toolpath, "tip_height") or not hasattr(toolpath, "design_height"):
        raise ConfigError(
            f"toolpath must be a DesignToolpath, got {type(toolpath).__name__}")
    r = np.linspace(toolpath.r_end, toolpath.r_start, 801)
    z_tip = toolpath.tip_height(r, theta)
    c, s = np.cos(theta), np.sin(theta)
    z_des = toolpath.design_height(r * c, r * s)
    feed = toolpath.feed_at_radius(r)
    fig = _new_figure((7.0, 5.6))
    ax1, ax2 = fig.subplots(2, 1, sharex=True)
    ax1.plot(r * 1e3, z_des * 1e6, lw=1.0, label="design")
    ax1.plot(r * 1e3, z_tip * 1e6, lw=1.0, ls="--", label="tool tip (compensated)")
    ax1.set_ylabel("height (\u00b5m)")
    ax1.legend(loc="best")
    ax2.plot(r * 1e3, feed * 1e6, lw=1.0, color="C2")
    ax2.set_xlabel("tip radius (mm)")
    ax2.set_ylabel("feed per revolution (\u00b5m)")
    ax2.set_ylim(0.0, float(np.max(feed)) * 1.15 * 1e6)
    fig.suptitle(title or f"Design toolpath at theta = {theta:.3g} rad")
    return _save_atomic(fig, path, dpi)
