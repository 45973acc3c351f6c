"""Measured against simulated maps: common grid, registration, residual, spectra."""

from __future__ import annotations

from typing import Any

import numpy as np

from ..errors import ConfigError
from ..metrology._surface import Surface

__all__ = ["compare_surfaces", "PEAK_MATCH_RTOL"]

#: Two spectral peaks match when their spatial frequencies differ by less than this.
PEAK_MATCH_RTOL = 0.03


def _common_grid(a: Surface, b: Surface) -> tuple[Surface, Surface]:
    from ..metrology import resample

    for s, name in ((a, "measured"), (b, "simulated")):
        if not s.calibrated:
            raise ConfigError(
                f"the {name} map is uncalibrated (no pixel size); "
                "compare needs lateral calibration"
            )
    dx, dy = max(a.dx, b.dx), max(a.dy, b.dy)

    def to(s: Surface) -> Surface:
        if np.isclose(s.dx, dx, rtol=1e-9, atol=0.0) and np.isclose(
            s.dy, dy, rtol=1e-9, atol=0.0
        ):  # no absolute tolerance: pixel sizes are ~1e-7 m
            return s
        return resample(s, dx, dy)

    return to(a), to(b)


def _crop_to(a: Surface, b: Surface) -> tuple[Surface, Surface]:
    """Crop both maps to their common shape (top-left aligned, same pitch)."""
    ny = min(a.shape[0], b.shape[0])
    nx = min(a.shape[1], b.shape[1])
    return a.replace(z=a.z[:ny, :nx]), b.replace(z=b.z[:ny, :nx])


def compare_surfaces(
    measured: Surface,
    simulated: Surface,
    *,
    remove: tuple[str, ...] = ("piston", "tilt"),
    axis: int = 0,
    register: bool = True,
    per_lenslet: bool = True,
) -> dict[str, Any]:
    """Bring two maps onto one grid, register them and report their difference.

    Parameters
    ----------
    measured, simulated : Surface
        Height maps in m (NaN invalid), calibrated.
    remove : tuple of str, default: ("piston", "tilt")
        Form terms removed from the residual ("piston", "tilt", "sphere").
    axis : {0, 1}, default: 0
        Axis of the cutting direction for the spectra (0: along columns/y, the
        convention of simulated lenslet maps; 1: along rows/x).
    register : bool, default: True
        Register the simulated map onto the measured one (sub-pixel translation).
    per_lenslet : bool, default: True
        When the measured map holds several lenslets, also register each lenslet
        separately and report its shift.

    Returns
    -------
    dict
        ``shift_m`` ([dy, dx] applied to the simulated map, m), ``lenslet_shifts``,
        ``rms_residual_m``, ``pv_residual_m``, ``fit_percent`` (MATLAB-style
        ``100 (1 - ||residual|| / ||measured - mean||)`` with the removed form
        terms), ``correlation``, ``peaks_measured``,
        ``peaks_simulated`` and ``peaks_matched`` (1/m), ``areal`` (the ISO 25178-2
        parameters of :func:`~servosurf.metrology.areal_parameters` of each map
        side by side, see Notes), plus arrays for plotting under ``_plots``.

    Notes
    -----
    ``areal["measured"]`` and ``areal["simulated"]`` are evaluated on the same
    pixels (valid in both maps after resampling and registration) with the same
    F-operation (the ``remove`` terms fitted to each map separately; the mean
    height when ``remove`` is empty) and no S- or L-filter.
    """
    from ..metrology import (
        areal_parameters,
        find_peaks_spectrum,
        psd_1d,
        register_translation,
        remove_form,
        segment_lenslets,
        shift_surface,
    )

    if axis not in (0, 1):
        raise ConfigError(f"axis must be 0 or 1, got {axis!r}")
    m, s = _common_grid(measured, simulated)
    m, s = _crop_to(m, s)
    s = s.replace(x0=m.x0, y0=m.y0)
    shift = (0.0, 0.0)
    if register:
        dy, dx, _err = register_translation(m, s)
        shift = (float(dy), float(dx))
        s = shift_surface(s, dy, dx)
    lens_shifts = []
    if per_lenslet and register:
        try:
            lenses = segment_lenslets(m)
        except (ConfigError, ValueError):
            lenses = []
        if len(lenses) >= 2:
            for lens in lenses:
                r0, c0, r1, c1 = lens["bbox"]
                sub_m = m.replace(z=m.z[r0:r1, c0:c1])
                sub_s = s.replace(z=s.z[r0:r1, c0:c1])
                try:
                    ly, lx, _ = register_translation(sub_m, sub_s)
                except (ConfigError, ValueError):
                    continue
                lens_shifts.append(
                    {
                        "centre_x_m": lens["centre_x_m"],
                        "centre_y_m": lens["centre_y_m"],
                        "shift_m": [float(ly), float(lx)],
                    }
                )
    both = np.isfinite(m.z) & np.isfinite(s.z)
    if both.sum() < 16:
        raise ConfigError(
            "the measured and simulated maps hardly overlap after "
            "registration (fewer than 16 common valid pixels)"
        )
    res = m.replace(z=np.where(both, m.z - s.z, np.nan))
    if remove:
        res = remove_form(res, terms=tuple(remove))
    r = res.z[np.isfinite(res.z)]
    mv, sv = m.z[both], s.z[both]
    # fit percent with the removed form terms: 1 - ||residual|| / ||m - mean(m)||
    rr = res.z[both]
    rr = rr[np.isfinite(rr)]
    fit = (
        float(100.0 * (1.0 - np.linalg.norm(rr) / np.linalg.norm(mv - mv.mean())))
        if mv.std() > 0
        else float("nan")
    )
    # correlation of the form-corrected measurement (simulated + residual) with the
    # simulation, on the pixels where both are valid
    rz = res.z[both]
    ok = np.isfinite(rz)
    corr = (
        float(np.corrcoef(sv[ok] + rz[ok], sv[ok])[0, 1])
        if sv[ok].std() > 0
        else float("nan")
    )
    fm, pm = psd_1d(np.where(both, m.z, np.nan), m.dy if axis == 0 else m.dx, axis=axis)
    fs_, ps = psd_1d(
        np.where(both, s.z, np.nan), s.dy if axis == 0 else s.dx, axis=axis
    )
    pk_m = [p["freq_per_m"] for p in find_peaks_spectrum(fm, pm, n=5)]
    pk_s = [p["freq_per_m"] for p in find_peaks_spectrum(fs_, ps, n=5)]
    matched = []
    for a in pk_m:
        best = min(pk_s, key=lambda b: abs(b - a), default=None)
        if best is not None and abs(best - a) <= PEAK_MATCH_RTOL * a:
            matched.append([a, best])
    areal: dict[str, Any] = {}
    for key, surf in (("measured", m), ("simulated", s)):
        common = surf.replace(z=np.where(both, surf.z, np.nan))
        if remove:
            common = remove_form(common, terms=tuple(remove))
        areal[key] = areal_parameters(common)
    areal["evaluated_on"] = (
        "pixels valid in both maps after registration; form removed per map: "
        + (" ".join(remove) if remove else "mean height")
        + "; no S- or L-filter"
    )
    return {
        "pixel_m": [m.dy, m.dx],
        "shape": list(m.shape),
        "shift_m": list(shift),
        "shift_px": [shift[0] / m.dy, shift[1] / m.dx],
        "lenslet_shifts": lens_shifts,
        "removed": list(remove),
        "rms_residual_m": float(np.sqrt(np.mean((r - r.mean()) ** 2))),
        "pv_residual_m": float(r.max() - r.min()),
        "fit_percent": fit,
        "correlation": corr,
        "peaks_measured_per_m": pk_m,
        "peaks_simulated_per_m": pk_s,
        "peaks_matched_per_m": matched,
        "areal": areal,
        "_plots": {
            "measured": m,
            "simulated": s,
            "residual": res,
            "spectra": (fm, pm, fs_, ps),
        },
    }
