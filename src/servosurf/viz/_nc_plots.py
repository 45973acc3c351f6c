"""Figures of an NC-program run (matplotlib, Agg): toolpath, band map, centre
profile and roughness table.

Inputs are SI (m, s, rad); display units appear only here: radii and lateral
positions in mm, heights in nm or um, feed per revolution in um, angles in
revolutions. Every figure is written atomically (:func:`servosurf.viz._common.save`).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from ._common import figure, save

__all__ = [
    "plot_nc_toolpath",
    "plot_band_map",
    "plot_centre_profile",
    "plot_roughness_table",
    "nc_figures",
]

#: Most points drawn per curve (the path is decimated evenly beyond this).
MAX_POINTS = 20000


def _every(n: int) -> int:
    return max(1, n // MAX_POINTS)


def plot_nc_toolpath(path, out: str | Path, *, title: str = "") -> Path:
    """Radius against angle, and feed per revolution against radius.

    Parameters
    ----------
    path : BlockPath
        The program's cutting path (radius in m, angle in rad).
    out : str or Path
        PNG file.
    title : str, optional
        Figure title.

    Returns
    -------
    Path
        The PNG file.
    """
    fig, ax = figure(1, 2, figsize=(10, 3.8))
    k = _every(path.t.size)
    rev = (path.theta - path.theta[0]) / (2 * np.pi)
    ax[0].plot(rev[::k], path.r[::k] * 1e3, lw=0.8)
    ax[0].set_xlabel("tool angle from the start [revolutions]")
    ax[0].set_ylabel("radius [mm]")
    ax[0].set_title("radius against angle")
    r, f = path.feed_per_revolution()
    if r.size:
        k = _every(r.size)
        ax[1].plot(r[::k] * 1e3, np.abs(f[::k]) * 1e6, ".", ms=1.5)
    ax[1].set_xlabel("radius [mm]")
    ax[1].set_ylabel("feed per revolution [\u00b5m]")
    ax[1].set_title("feed per revolution against radius")
    fig.suptitle(title or "NC toolpath")
    return save(fig, out)


def plot_band_map(surface, path, out: str | Path, *, title: str = "") -> Path:
    """The predicted surface on the band, its form (the tip path) removed.

    Parameters
    ----------
    surface : Surface
        Heights in m (rows y, columns x).
    path : BlockPath
        The path whose radial form is removed for display.
    out : str or Path
        PNG file.
    title : str, optional
        Figure title.

    Returns
    -------
    Path
        The PNG file.
    """
    x, y = surface.coords()
    rr = np.hypot(x[None, :], y[:, None])
    res = surface.z - path.radial_form(rr)
    row = int(np.argmin(np.abs(y)))
    ok = np.isfinite(res[row])
    if ok.sum() > 3:  # the tip path differs from the nose envelope: a smooth form
        res = res - np.polyval(np.polyfit(x[ok], res[row][ok], 2), x)[None, :]
    fig, ax = figure(2, 1, figsize=(10, 4.6), sharex=True)
    finite = res[np.isfinite(res)]
    lo, hi = (np.percentile(finite, [1, 99]) * 1e9) if finite.size else (0, 1)
    # pixel edges: a one-row band keeps a height of one pitch
    hy = 0.5 * (surface.dy or 0.0)
    im = ax[0].imshow(res * 1e9, aspect="auto", cmap="viridis", vmin=lo, vmax=hi,
                      extent=[x[0] * 1e3, x[-1] * 1e3, (y[-1] + hy) * 1e6,
                              (y[0] - hy) * 1e6],
                      interpolation="nearest")
    ax[0].set_ylabel("y [\u00b5m]")
    ax[0].set_title("height minus the commanded tip path and a quadratic in x [nm]")
    # one colour bar for both panels, so that they keep the same width and x axis
    fig.colorbar(im, ax=list(ax), pad=0.01, shrink=0.5, anchor=(0.0, 1.0))
    ax[1].plot(x * 1e3, surface.z[row] * 1e6, lw=0.6)
    ax[1].set_xlabel("x [mm]")
    ax[1].set_ylabel("height [\u00b5m]")
    ax[1].set_title(f"row through the axis (y = {y[row] * 1e6:g} \u00b5m)")
    fig.suptitle(title or "predicted surface (band through the spindle axis)")
    return save(fig, out)


def plot_centre_profile(profile: dict[str, Any], roughness: dict[str, Any],
                        out: str | Path, *, title: str = "") -> Path:
    """The form-removed profile through the centre, whole and zoomed.

    Parameters
    ----------
    profile : dict
        From :func:`servosurf.report.centre_profile` (``x``, ``residual`` in m).
    roughness : dict
        From :func:`servosurf.metrology.profile_roughness` (cut-off, trim, in m).
    out : str or Path
        PNG file.
    title : str, optional
        Figure title.

    Returns
    -------
    Path
        The PNG file.
    """
    x, res = profile["x"], profile["residual"]
    lo, hi = profile["span"]
    fig, ax = figure(2, 1, figsize=(10, 5.2))
    ax[0].plot(x[lo:hi] * 1e3, res[lo:hi] * 1e9, lw=0.5)
    trim = roughness.get("trim_length_m", 0.0)
    if trim:
        for v in (x[lo] + trim, x[hi - 1] - trim):
            ax[0].axvline(v * 1e3, color="C3", lw=0.8, ls="--")
    ax[0].set_xlabel("x [mm]")
    ax[0].set_ylabel("height [nm]")
    if roughness.get("cutoff_m"):
        ax[0].set_title(f"centre profile, form removed (evaluation between the "
                        f"dashed lines, \u03bbc = {roughness['cutoff_m'] * 1e3:g} mm)")
    else:
        ax[0].set_title("centre profile, form removed (too short for an ISO 4288 "
                        "cut-off)")
    mid = 0.5 * (x[lo] + x[hi - 1])
    w = min(0.1e-3, 0.5 * (x[hi - 1] - x[lo]))
    m = (x >= mid - w / 2) & (x <= mid + w / 2)
    ax[1].plot(x[m] * 1e3, res[m] * 1e9, lw=0.8)
    ax[1].set_xlabel("x [mm]")
    ax[1].set_ylabel("height [nm]")
    ax[1].set_title("zoom on the middle 0.1 mm")
    fig.suptitle(title or "profile through the centre")
    fig.tight_layout()
    return save(fig, out)


def plot_roughness_table(roughness: dict[str, Any], out: str | Path, *,
                         title: str = "") -> Path:
    """The roughness parameters of the centre profile as a table figure.

    Parameters
    ----------
    roughness : dict
        SI values: ``ra_m``, ``rq_m``, ``rz_m``, ``rsm_m``, ``cutoff_m``,
        ``evaluation_length_m``.
    out : str or Path
        PNG file.
    title : str, optional
        Figure title.

    Returns
    -------
    Path
        The PNG file.
    """
    def nm(v):
        return "-" if v is None or not np.isfinite(v) else f"{v * 1e9:.1f} nm"

    def um(v):
        return "-" if v is None or not np.isfinite(v) else f"{v * 1e6:.2f} \u00b5m"

    def mm(v):
        return "-" if v is None or not np.isfinite(v) else f"{v * 1e3:.3g} mm"

    rows = [
        ("Ra", nm(roughness.get("ra_m"))),
        ("Rq", nm(roughness.get("rq_m"))),
        ("Rz", nm(roughness.get("rz_m"))),
        ("RSm", um(roughness.get("rsm_m"))),
        ("cut-off \u03bbc", mm(roughness.get("cutoff_m"))),
        ("evaluation length", mm(roughness.get("evaluation_length_m"))),
    ]
    fig, ax = figure(figsize=(4.2, 2.6))
    ax.axis("off")
    tab = ax.table(cellText=rows, colLabels=("parameter", "centre profile"),
                   loc="center", cellLoc="left")
    tab.scale(1.0, 1.4)
    ax.set_title(title or "roughness (ISO 4287/4288, ends trimmed by \u03bbc)")
    return save(fig, out)


def nc_figures(result, summary_plots: dict[str, Any], out_dir: str | Path, *,
               name: str = "") -> dict[str, str]:
    """Write the four figures of an NC run next to its JSON.

    Parameters
    ----------
    result : SimulationResult
        The run (its ``spec.path`` is a BlockPath).
    summary_plots : dict
        The ``_plots`` entry of :func:`servosurf.report.analyse_nc`.
    out_dir : str or Path
        Output folder.
    name : str, optional
        Name used in the titles.

    Returns
    -------
    dict of str to str
        Figure name -> PNG path.
    """
    out = Path(out_dir)
    surf = result.measured if result.measured is not None else result.surface
    prefix = f"{name}: " if name else ""
    return {
        "toolpath_png": str(plot_nc_toolpath(result.spec.path, out / "toolpath.png",
                                             title=f"{prefix}NC toolpath")),
        "map_png": str(plot_band_map(surf, result.spec.path, out / "map.png",
                                     title=f"{prefix}predicted surface")),
        "profile_png": str(plot_centre_profile(
            summary_plots["profile"], summary_plots["roughness"], out / "profile.png",
            title=f"{prefix}profile through the centre")),
        "roughness_png": str(plot_roughness_table(
            summary_plots["roughness"], out / "roughness.png",
            title=f"{prefix}roughness of the centre profile")),
    }
