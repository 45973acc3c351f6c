"""Figures of a simulation's analysis, a realisation study and a map comparison.

Inputs are SI (m, s, N, 1/m); display units appear only here (um, nm, mm^-1, ms).
Every figure is written atomically (:func:`servosurf.viz._common.save`). The
``simulate`` and ``compare`` commands reach these through the result objects of
:mod:`servosurf.report` (``.plot(folder)``).
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np

from .._random import figure_jitter
from ._common import figure, save

__all__ = [
    "simulation_figures",
    "plot_highpass",
    "plot_analysis_spectrum",
    "plot_lenslet_profile",
    "plot_deviation",
    "plot_realisations",
    "plot_map_comparison",
]


def plot_highpass(plot_data: dict[str, Any], path: str | Path, *,
                  cutoff: float) -> Path:
    """The high-pass map, its filter-end rim masked, colours by percentile.

    The Gaussian filter has no data beyond the map's edge (the lenslet's rim or the
    field's border): within half a cut-off of it the high-pass holds the filter's
    end effect, tens of times the texture, so that band is masked and the colour
    scale spans the 0.5-99.5 percentiles of the rest.

    Parameters
    ----------
    plot_data : dict
        The analysis's figure data: ``highpass`` (Surface, m) and, for lenslets,
        ``profile``.
    path : str or Path
        PNG file.
    cutoff : float
        Cut-off wavelength of the high-pass, in m.

    Returns
    -------
    Path
        The PNG file.
    """
    from scipy import ndimage

    from ._surface_plots import plot_map

    hp = plot_data["highpass"]
    valid = np.pad(np.isfinite(hp.z), 1, constant_values=False)
    dist = ndimage.distance_transform_edt(valid, sampling=(hp.dy, hp.dx))[1:-1, 1:-1]
    rim = 0.5 * cutoff
    shown = hp.replace(z=np.where(dist > rim, hp.z, np.nan))
    what = " of the form error" if "profile" in plot_data else ""
    return plot_map(
        shown, path, robust=0.5,
        title=f"{1e-3 / cutoff:g} mm^-1 high-pass{what}\n"
        f"(a {rim * 1e6:.3g} um rim masked: filter end effect)")


def plot_analysis_spectrum(plot_data: dict[str, Any], path: str | Path, *,
                           peak_fmin: float, speed: float | None = None) -> Path:
    """The PSD along the cut with every detected peak labelled (in mm^-1 and kHz).

    ``summary.json`` lists the peaks above ``peak_fmin``; peaks below it
    (attenuated by the filter, e.g. a tool mode on a slow facing cut) are found
    the same way and drawn in grey in the shaded band.

    Parameters
    ----------
    plot_data : dict
        The analysis's figure data: ``spectrum`` ``(freq, psd, peaks)`` (1/m, m^3).
    path : str or Path
        PNG file.
    peak_fmin : float
        Lowest spatial frequency of the listed peaks, in 1/m.
    speed : float, optional
        Surface speed in m/s (labels peaks in kHz too).

    Returns
    -------
    Path
        The PNG file.
    """
    from ..metrology import find_peaks_spectrum
    from ._surface_plots import plot_spectrum

    freq, psd, peaks = plot_data["spectrum"]
    low = [q for q in find_peaks_spectrum(freq, psd, n=5, fmax=peak_fmin)
           if q["freq_per_m"] < peak_fmin]
    return plot_spectrum(
        freq, psd, [*peaks, *low], path, speed=speed, fmin=peak_fmin,
        title="PSD along the cutting direction (y), peaks labelled")


def plot_lenslet_profile(plot_data: dict[str, Any], path: str | Path, *,
                         measured: bool) -> Path:
    """The lenslet's centre profile along the cut (y) with the form error.

    Parameters
    ----------
    plot_data : dict
        The analysis's figure data: ``profile`` ``(y, z, form_error)`` (m).
    path : str or Path
        PNG file.
    measured : bool
        The map is the instrument model's (label "as measured").

    Returns
    -------
    Path
        The PNG file.
    """
    from ._surface_plots import plot_profile_with_form_error

    y, z, fe = plot_data["profile"]
    which = "simulated, as measured" if measured else "simulated"
    return plot_profile_with_form_error(
        y, z, fe["reference"], fe["error"], path,
        xlabel="y, along the cut through the lenslet centre (\u00b5m)",
        label=which, nominal_label="nominal at the air-cut amplitude",
        title="Lenslet profile along the cutting direction and its form error")


def plot_deviation(result, path: str | Path) -> Path:
    """Force, tool deviation and following error over the last cutting cycles.

    Parameters
    ----------
    result : SimulationResult
        The run (times in s, deviations in m, force in N).
    path : str or Path
        PNG file.

    Returns
    -------
    Path
        The PNG file.
    """
    res = result
    fs = res.machine.controller.sample_rate
    n = min(res.t.size, int(0.035 * fs))
    sl = slice(res.t.size - n, res.t.size)
    t = (res.t[sl] - res.t[sl][0]) * 1e3
    fig, ax = figure(2, 1, figsize=(8, 5.5), sharex=True)
    ax[0].plot(t, res.force[sl], color="C3")
    ax[0].set_ylabel("thrust force [N]")
    for name, dev in res.deviation.items():
        if np.any(dev[sl]):
            ax[1].plot(t, dev[sl] * 1e9, label=name, lw=0.8)
    ax[1].plot(t, res.following_error[sl] * 1e9, "k", lw=0.5, alpha=0.6,
               label="following error")
    ax[1].set_ylabel("tool deviation [nm]")
    ax[1].set_xlabel("time [ms]")
    ax[1].legend(fontsize=7)
    ax[0].set_title("Cutting force and tool deviation (cf. Fig. 17b)")
    return save(fig, path)


def simulation_figures(result, plot_data: dict[str, Any], folder: str | Path, *,
                       name: str = "", render: bool = True,
                       speed: float | None = None, cutoff: float,
                       peak_fmin: float, surface=None) -> dict[str, str]:
    """Write the figures of a lenslet, facing or design-surface simulation.

    Parameters
    ----------
    result : SimulationResult
        The run.
    plot_data : dict
        The analysis's figure data (:attr:`servosurf.report.SimulationAnalysis.
        plot_data`).
    folder : str or Path
        Output folder (existing).
    name : str, optional
        Name of the run in the titles.
    render : bool, default: True
        Also write the 3-D render ``render.png``.
    speed : float, optional
        Surface speed in m/s (spectrum peaks labelled in kHz too).
    cutoff : float
        Cut-off of the high-pass map, in m.
    peak_fmin : float
        Lowest spatial frequency of the listed spectrum peaks, in 1/m.
    surface : Surface, optional
        The map drawn (default: the measured map if any, else the machined one).

    Returns
    -------
    dict of str to str
        ``map_png``, ``highpass_png``, (``form_error_png``, ``toolpath_png``),
        ``spectrum_png``, (``profile_png``), (``deviation_png``),
        (``render_png``) -> PNG paths, in the order written.
    """
    from ._surface_plots import plot_map

    out = Path(folder)
    res = result
    if surface is None:
        surface = res.measured if res.measured is not None else res.surface
    files: dict[str, str] = {}
    files["map_png"] = str(
        plot_map(surface, out / "map.png", title=f"{name}: simulated height map"))
    files["highpass_png"] = str(plot_highpass(plot_data, out / "highpass.png",
                                              cutoff=cutoff))
    if "form_error" in plot_data:  # design surface: error map against the design
        from ._form_plots import plot_design_feed, plot_form_error

        files["form_error_png"] = str(plot_form_error(
            plot_data["form_error"], out / "form_error.png",
            title=f"{name}: form error against the design"))
        fld = res.spec.field
        files["toolpath_png"] = str(plot_design_feed(
            res.spec.path, out / "toolpath.png",
            theta=float(math.atan2(fld.center_y, fld.center_x))))
    files["spectrum_png"] = str(plot_analysis_spectrum(
        plot_data, out / "spectrum.png", peak_fmin=peak_fmin, speed=speed))
    if "profile" in plot_data:
        files["profile_png"] = str(plot_lenslet_profile(
            plot_data, out / "profile.png", measured=res.measured is not None))
    if res.t.size:
        files["deviation_png"] = str(plot_deviation(res, out / "deviation.png"))
    if render:
        from ._render import render_surface

        files["render_png"] = str(
            render_surface(surface, out / "render.png", title=f"{name} (simulated)"))
    return files


def plot_realisations(seeds: np.ndarray, metrics: dict[str, np.ndarray],
                      path: str | Path) -> Path:
    """Per-seed metrics as strip plots with their mean and 5-95 % band.

    Parameters
    ----------
    seeds : ndarray of int
        The seeds (one realisation each).
    metrics : dict of str to ndarray
        Per-seed metrics in SI (``form_error_max_m``, ``ra_m``, ``sa_m`` in m,
        ``peak1_per_m`` in 1/m); NaN where a seed has none.
    path : str or Path
        PNG file.

    Returns
    -------
    Path
        The PNG file.
    """
    shown = [
        ("form_error_max_m", "max form error [nm]", 1e9),
        ("ra_m", "Ra [nm]", 1e9),
        ("sa_m", "Sa [nm]", 1e9),
        ("peak1_per_m", "strongest spectral line (matched\nby frequency) [1/mm]", 1e-3),
    ]
    shown = [s for s in shown if np.isfinite(metrics[s[0]]).any()]
    fig, axes = figure(1, len(shown), figsize=(3.2 * len(shown), 3.6), squeeze=False)
    for ax, (key, label, scale) in zip(axes[0], shown, strict=True):
        v = metrics[key] * scale
        v = v[np.isfinite(v)]
        # horizontal jitter of the markers only (a fixed seed: the same figure)
        x = figure_jitter().uniform(-0.15, 0.15, v.size)
        ax.plot(x, v, "o", ms=4, alpha=0.7)
        ax.axhline(v.mean(), color="C3", lw=1)
        ax.axhspan(np.percentile(v, 5), np.percentile(v, 95), color="C3", alpha=0.12)
        ax.set_xlim(-0.5, 0.5)
        ax.set_xticks([])
        ax.set_ylabel(label)
    fig.suptitle(f"{np.size(seeds)} vibration realisations: mean (line), 5-95 % "
                 "(band)")
    fig.tight_layout()
    return save(fig, path)


def plot_map_comparison(measured, simulated, residual, spectra, folder: str | Path,
                        *, rms_residual: float, matched_peaks, axis: str = "y"
                        ) -> dict[str, str]:
    """Write ``residual.png``, ``spectra.png`` and ``profiles.png`` of a comparison.

    Parameters
    ----------
    measured, simulated, residual : Surface
        The registered maps and their difference, in m.
    spectra : tuple of ndarray
        ``(f_measured, psd_measured, f_simulated, psd_simulated)`` (1/m, m^3).
    folder : str or Path
        Output folder (existing).
    rms_residual : float
        RMS of the residual, in m (in the title).
    matched_peaks : sequence of (float, float)
        Matched spectral peaks (measured, simulated), in 1/m (dotted lines).
    axis : {"y", "x"}, default: "y"
        Cutting direction of the profile figure.

    Returns
    -------
    dict of str to str
        ``residual``, ``spectra``, ``profiles`` -> PNG paths.
    """
    from ._surface_plots import plot_map

    d = Path(folder)
    plot_map(residual, d / "residual.png",
             title=f"residual (measured - simulated), RMS {rms_residual * 1e9:.2f} nm")
    fm, pm, fs_, ps = spectra
    fig, ax = figure(figsize=(8, 4.5))
    ax.semilogy(fm / 1e3, pm * 1e21, label="measured")
    ax.semilogy(fs_ / 1e3, ps * 1e21, label="simulated", alpha=0.8)
    for a, _b in matched_peaks:
        ax.axvline(a / 1e3, color="k", ls=":", lw=0.8)
    ax.set_xlabel("spatial frequency [1/mm]")
    ax.set_ylabel("PSD [nm^2 mm]")
    ax.set_title("Spectra along the cutting direction (dotted: matched peaks)")
    ax.legend()
    save(fig, d / "spectra.png")
    m, s = measured, simulated
    fig, ax = figure(figsize=(8, 4))
    if axis == "y":
        j = m.shape[1] // 2
        x = m.y0 + m.dy * np.arange(m.shape[0])
        ax.plot(x * 1e6, m.z[:, j] * 1e9, label="measured")
        ax.plot(x * 1e6, s.z[:, j] * 1e9, label="simulated")
    else:
        i = m.shape[0] // 2
        x = m.x0 + m.dx * np.arange(m.shape[1])
        ax.plot(x * 1e6, m.z[i] * 1e9, label="measured")
        ax.plot(x * 1e6, s.z[i] * 1e9, label="simulated")
    ax.set_xlabel(f"{axis} [um]")
    ax.set_ylabel("height [nm]")
    ax.set_title("Profile through the map centre along the cutting direction")
    ax.legend()
    save(fig, d / "profiles.png")
    return {k: str(d / f"{k}.png") for k in ("residual", "spectra", "profiles")}
