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

__all__ = ["plot_profile_overlay", "plot_profile_spectra", "plot_profile_table"]


def _fmt_nm(v: float) -> str:
    return "n/a" if v is None or not np.isfinite(v) else f"{v * 1e9:.1f} nm"


def _fmt_um(v: float) -> str:
    return "n/a" if v is None or not np.isfinite(v) else f"{v * 1e6:.2f} \u00b5m"


def _zoom_window(result: ProfileComparison, width: float) -> tuple[float, float]:
    """A window of ``width`` m inside the longest evaluated run of samples."""
    both = np.isfinite(result.measured_roughness.z) & np.isfinite(
        result.simulated_roughness.z)
    x = result.measured.x
    if not both.any():
        return float(x[0]), float(x[-1])
    # longest run of consecutive evaluated samples
    edges = np.flatnonzero(np.diff(np.concatenate([[0], both.astype(int), [0]])))
    starts, stops = edges[::2], edges[1::2]
    k = int(np.argmax(stops - starts))
    a, b = float(x[starts[k]]), float(x[stops[k] - 1])
    mid = 0.5 * (a + b)
    half = 0.5 * min(width, b - a)
    return mid - half, mid + half


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
    run-up and run-out, a dotted line marks the spindle axis when the
    registration was split there. Middle: the roughness profiles (primary minus
    the Gaussian mean line) over the evaluation length, with Ra, RSm and the
    correlation. Bottom: a 0.1 mm zoom on the roughness profiles (the cusp
    shapes).
    """
    lm, ls = result.labels
    m, s = result.measured, result.simulated
    x = m.x * 1e6
    fig = _new_figure((10.0, 8.6))
    ax1, ax2, ax3 = fig.subplots(3, 1)
    ax2.sharex(ax1)
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
    split = result.info.get("split")
    if split is not None:
        for ax in (ax1, ax2):
            ax.axvline(split["axis_m"] * 1e6, color="k", ls=":", lw=0.9)
    ax1.set_ylabel("height - mean (nm)")
    how = "mirrored, " if result.mirrored else ""
    if not result.info.get("registered", True):
        reg = "not registered"
    elif split is not None:
        reg = (f"registered per half ({how}shifts "
               f"{split['below']['shift_m'] * 1e6:.2f} / "
               f"{split['above']['shift_m'] * 1e6:.2f} \u00b5m; dotted: axis)")
    else:
        reg = f"registered ({how}shift {result.shift * 1e6:.2f} \u00b5m)"
    ax1.set_title(f"Primary profiles, {ls} {reg}; grey: trimmed ends", fontsize=10)
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
        f"correlation {result.correlation:.3f}", fontsize=10
    )
    ax2.legend(loc="upper right", fontsize=8)
    a, b = _zoom_window(result, 100e-6)
    sel = (m.x >= a) & (m.x <= b)
    for prof, lab, col in ((result.measured_roughness, lm, "C0"),
                           (result.simulated_roughness, ls, "C1")):
        ax3.plot(x[sel], prof.z[sel] * 1e9, color=col, lw=1.0, marker=".", ms=2,
                 label=lab)
    ax3.set_xlabel(f"position along the {lm} profile (\u00b5m)")
    ax3.set_ylabel("roughness (nm)")
    ax3.set_title("Zoom on 0.1 mm of the evaluation length", fontsize=10)
    ax3.legend(loc="upper right", fontsize=8)
    return _save_atomic(fig, path, dpi)


def _fmt_pct(a: float | None, b: float | None) -> str:
    if a is None or b is None or not (np.isfinite(a) and np.isfinite(b)) or a == 0:
        return "n/a"
    return f"{b / a - 1.0:+.1%}"


def plot_profile_table(
    result: ProfileComparison, path: str | os.PathLike[str], *, dpi: int = 120
) -> Path:
    """Write the roughness parameters of both sides as a table figure (PNG).

    Parameters
    ----------
    result : ProfileComparison
        The comparison (values in m).
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
    Rows Ra, Rq, Rz (nm) and RSm (um); columns the two sides and the relative
    difference of the second to the first; below, the cut-off, the evaluation
    length, the correlation after registration and the registration itself.
    """
    lm, ls = result.labels
    rm, rs = result.roughness["measured"], result.roughness["simulated"]
    rows = []
    for key, name, fmt in (("ra_m", "Ra", _fmt_nm), ("rq_m", "Rq", _fmt_nm),
                           ("rz_m", "Rz", _fmt_nm), ("rsm_m", "RSm", _fmt_um)):
        rows.append((name, fmt(rm[key]), fmt(rs[key]), _fmt_pct(rm[key], rs[key])))
    fig = _new_figure((6.4, 3.2))
    ax = fig.add_subplot()
    ax.axis("off")
    tab = ax.table(cellText=rows, colLabels=("", lm, ls, f"{ls} vs {lm}"),
                   cellLoc="center", bbox=(0.0, 0.34, 1.0, 0.66))
    tab.auto_set_font_size(False)
    tab.set_fontsize(9)
    split = result.info.get("split")
    lines = [
        f"\u03bbc {result.cutoff * 1e3:g} mm ({result.cutoff_rule}), ends trimmed "
        f"{result.trim_length * 1e6:g} \u00b5m, evaluation "
        f"{rm['evaluation_length_m'] * 1e3:.3g} mm",
        f"correlation after registration {result.correlation:.3f}",
    ]
    if split is not None:
        c = [split[k].get("correlation") for k in ("below", "above")]
        cs = " / ".join("n/a" if v is None or not np.isfinite(v) else f"{v:.3f}"
                        for v in c)
        lines.append(
            f"split at the axis ({result.shift * 1e6:.1f} \u00b5m): half shifts "
            f"{split['below']['shift_m'] * 1e6:.1f} / "
            f"{split['above']['shift_m'] * 1e6:.1f} \u00b5m, correlations {cs}")
    elif result.info.get("registered", True):
        lines.append(f"shift {result.shift * 1e6:.1f} \u00b5m"
                     + (", mirrored" if result.mirrored else ""))
    ax.text(0.5, 0.28, "\n".join(lines), ha="center", va="top", fontsize=8,
            transform=ax.transAxes)
    ax.set_title(f"Roughness, {lm} and {ls} (ISO 4287, same cut-off and span)",
                 fontsize=10)
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
