"""Figures of a profile comparison: overlay of the two profiles and their spectra.

Inputs are SI (m, 1/m, m^3); display units are um for positions, nm for heights and
1/mm for spatial frequencies. matplotlib is imported inside the functions (Agg
canvas, no pyplot) and files are written atomically.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from ._surface_plots import _new_figure, _save_atomic

if TYPE_CHECKING:
    from ..report._profile_compare import ProfileComparison

__all__ = ["plot_profile_overlay", "plot_profile_spectra"]


def _fmt_nm(v: float) -> str:
    return "n/a" if v is None or not np.isfinite(v) else f"{v * 1e9:.1f} nm"


def _fmt_um(v: float) -> str:
    return "n/a" if v is None or not np.isfinite(v) else f"{v * 1e6:.2f} \u00b5m"


def plot_profile_overlay(
    result: ProfileComparison, path: str | os.PathLike[str], *, dpi: int = 120
) -> Path:
    """Write the two registered profiles, primary and roughness, to a PNG.

    Parameters
    ----------
    result : ProfileComparison
        The comparison (profiles in m).
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
    Top: the primary profiles over the common span, each minus its mean (nm)
    against the measured file's position (um); the shaded ends are the trimmed
    run-up and run-out. Bottom: the roughness profiles (primary minus the Gaussian
    mean line) over the evaluation length, with Ra, RSm and the correlation.
    """
    lm, ls = result.labels
    m, s = result.measured, result.simulated
    x = m.x * 1e6
    fig = _new_figure((10.0, 6.6))
    ax1, ax2 = fig.subplots(2, 1, sharex=True)
    for prof, lab, col in ((m, lm, "C0"), (s, ls, "C1")):
        z = prof.z - np.nanmean(prof.z)
        ax1.plot(x, z * 1e9, color=col, lw=0.8, label=lab)
    trim = result.trim_length * 1e6
    if trim > 0:
        ok = np.flatnonzero(np.isfinite(m.z))
        lo, hi = x[ok[0]], x[ok[-1]]
        for a, b in ((lo, lo + trim), (hi - trim, hi)):
            ax1.axvspan(a, b, color="0.85", zorder=0)
            ax2.axvspan(a, b, color="0.85", zorder=0)
    ax1.set_ylabel("height - mean (nm)")
    how = "mirrored, " if result.mirrored else ""
    reg = (
        f"registered ({how}shift {result.shift * 1e6:.2f} \u00b5m)"
        if result.info.get("registered", True)
        else "not registered"
    )
    ax1.set_title(f"Primary profiles, {ls} {reg}; grey: trimmed ends")
    ax1.legend(loc="upper right", fontsize=8)
    rm, rs = result.roughness["measured"], result.roughness["simulated"]
    for prof, lab, res, col in (
        (result.measured_roughness, lm, rm, "C0"),
        (result.simulated_roughness, ls, rs, "C1"),
    ):
        ax2.plot(
            x,
            prof.z * 1e9,
            color=col,
            lw=0.8,
            label=f"{lab}: Ra {_fmt_nm(res['ra_m'])}, RSm {_fmt_um(res['rsm_m'])}",
        )
    ax2.set_xlabel(f"position along the {lm} profile (\u00b5m)")
    ax2.set_ylabel("roughness (nm)")
    ax2.set_title(
        f"Roughness profiles (Gaussian, \u03bbc = {result.cutoff * 1e3:g} mm), "
        f"correlation {result.correlation:.3f}"
    )
    ax2.legend(loc="upper right", fontsize=8)
    return _save_atomic(fig, path, dpi)


def plot_profile_spectra(
    result: ProfileComparison, path: str | os.PathLike[str], *, dpi: int = 120
) -> Path:
    """Write the one-sided PSDs of the two roughness profiles to a PNG.

    Parameters
    ----------
    result : ProfileComparison
        The comparison (spectra in 1/m and m^3).
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
    PSD in nm^2 mm (m^3 x 1e21) against spatial frequency in 1/mm, log-log; the
    dotted line marks the cut-off frequency 1 / lambda_c. An empty panel says that
    the evaluation length held too many gaps for a spectrum.
    """
    lm, ls = result.labels
    fm, pm, fs_, ps = result.spectra
    fig = _new_figure((8.0, 4.6))
    ax = fig.add_subplot()
    drawn = False
    for f, p, lab, col in ((fm, pm, lm, "C0"), (fs_, ps, ls, "C1")):
        ok = (f > 0) & (p > 0)
        if ok.any():
            ax.loglog(f[ok] * 1e-3, p[ok] * 1e21, color=col, lw=0.9, label=lab)
            drawn = True
    ax.axvline(1e-3 / result.cutoff, color="k", ls=":", lw=0.8,
               label="1 / \u03bbc")
    ax.set_xlabel("spatial frequency (1/mm)")
    ax.set_ylabel("PSD (nm\u00b2 mm)")
    if drawn:
        ax.set_title("Spectra of the roughness profiles over the evaluation length")
        ax.legend(fontsize=8)
    else:
        ax.set_title("no spectra: too many gaps in the evaluation length")
    return _save_atomic(fig, path, dpi)
