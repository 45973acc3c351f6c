"""Analysis of an NC-program run: the centre profile's roughness and the toolpath.

Conventions stated once (all values SI):

* **Centre profile**: the row of the map through the spindle axis (y = 0 on the
  default band), x from -R_max to +R_max (the band's columns; negative x lies half
  a turn from positive x).
* **Form removal**: the commanded tool-tip height at radius ``|x|``
  (:meth:`BlockPath.radial_form`) is subtracted, then a least-squares quadratic over
  the evaluated profile (piston, tilt and the smooth difference between the tip
  path and the nose envelope on a curved part), as a metrologist removes the form
  of a measured profile.
* **Roughness**: :func:`servosurf.metrology.profile_roughness` with the ISO 4288
  cut-off (chosen from Ra by the standard's procedure: the largest admissible
  cut-off is half the profile length) and the ends trimmed by one cut-off: Ra, Rq,
  Rz (mean of five sampling lengths when they fit), RSm (10 % Rz height
  discrimination).
* **Profile length**: the whole band by default; ``profile_length`` evaluates only
  the part centred on the axis, as long as the measuring instrument's profile, so
  that the same cut-off and the same stretch of radii are compared.
* **Feed per revolution**: ``r(theta) - r(theta + 2 pi)`` along the path.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ..errors import ConfigError
from ..metrology import Profile, Surface
from ._analysis import SimulationAnalysis

__all__ = ["analyse_nc", "centre_profile"]

_ROUGH_KEYS = ("ra_m", "rq_m", "rz_m", "rsm_m", "rt_m", "cutoff_m", "cutoff_rule",
               "evaluation_length_m", "trim_length_m", "rz_sampling_lengths")


def centre_profile(surface: Surface, path, *,
                   profile_length: float | None = None) -> dict[str, Any]:
    """Form-removed profile through the spindle axis of a simulated NC map.

    Parameters
    ----------
    surface : Surface
        Heights in m on a field whose rows run along x.
    path : BlockPath
        The program's path (its radial form is removed).
    profile_length : float, optional
        Length of the evaluated profile, in m, centred on x = 0; default the
        whole row.

    Returns
    -------
    dict
        ``row`` (index), ``y_m``, ``x`` (m, shape (n,)), ``z`` (heights, m),
        ``form`` (the removed form, m) and ``residual`` (m): the profile after
        form removal, NaN outside the evaluated part.

    Raises
    ------
    ConfigError
        When the field does not contain y = 0, or too little of the row is valid.
    """
    x, y = surface.coords()
    row = int(np.argmin(np.abs(y)))
    if abs(y[row]) > 0.5 * surface.dy + 1e-12:
        raise ConfigError(
            f"the field does not cross the spindle axis (rows at y = {y[0]:g}.."
            f"{y[-1]:g} m): the centre profile needs a row through y = 0")
    z = np.asarray(surface.z[row], dtype=np.float64)
    form = path.radial_form(np.abs(x))
    resid = z - form
    keep = np.isfinite(resid)
    if profile_length is not None:
        L = float(profile_length)
        if not L > 0:
            raise ConfigError(f"profile_length must be > 0 m, got {profile_length!r}")
        keep &= np.abs(x) <= 0.5 * L + 1e-12
    idx = np.flatnonzero(keep)
    if idx.size < 16:
        raise ConfigError("fewer than 16 valid samples in the centre profile; widen "
                          "the field or the profile length")
    lo, hi = idx[0], idx[-1] + 1
    seg = np.full(z.size, np.nan)
    xs = x[lo:hi]
    rs = resid[lo:hi]
    ok = np.isfinite(rs)
    coef = np.polyfit(xs[ok], rs[ok], 2)
    seg[lo:hi] = rs - np.polyval(coef, xs)
    return {"row": row, "y_m": float(y[row]), "x": x, "z": z, "form": form,
            "residual": seg, "span": (int(lo), int(hi))}


def analyse_nc(result, *, profile_length: float | None = None,
               use_measured: bool = True) -> SimulationAnalysis:
    """Roughness of the centre profile and toolpath figures of an NC run.

    Parameters
    ----------
    result : SimulationResult
        A simulation of a toolpath of kind ``"nc"``.
    profile_length : float, optional
        Evaluated length of the centre profile, in m (default: the whole row).
    use_measured : bool, default: True
        Analyse the interferometer model's map when there is one.

    Returns
    -------
    SimulationAnalysis
        ``.summary`` / ``.to_dict()``: JSON-ready SI values: ``roughness``
        (``ra_m``, ``rq_m``, ``rz_m``, ``rsm_m``, ``cutoff_m``, ...),
        ``centre_profile`` (row, length), ``toolpath`` (revolutions, feed per
        revolution, time base, reference, rotation), ``ra_m``/``sa_m``/``sq_m``
        (for study tables); ``.plot_data``: the centre profile, the feed and the
        roughness the figures draw; ``.plot(folder)`` writes them.
    """
    from ..metrology import profile_roughness

    surface = (result.measured if (use_measured and result.measured is not None)
               else result.surface)
    path = result.spec.path
    prof = centre_profile(surface, path, profile_length=profile_length)
    lo, hi = prof["span"]
    p = Profile(prof["residual"][lo:hi], surface.dx, x0=float(prof["x"][lo]))
    try:
        rough = profile_roughness(p)
    except ConfigError as exc:  # a profile too short for any ISO 4288 cut-off
        rough = dict.fromkeys(_ROUGH_KEYS)
        rough.update(cutoff_rule="ISO 4288", trim_length_m=0.0,
                     not_evaluated=str(exc))
    r_f, feed = path.feed_per_revolution()
    inside = r_f > 0.05 * path.r_max
    f_in = np.abs(feed[inside]) if inside.any() else np.abs(feed)
    v = surface.z[np.isfinite(surface.z)]
    fld = result.spec.field
    out: dict[str, Any] = {
        "analysed_map": "measured" if surface is result.measured else "model",
        "roughness": {
            **{k: rough[k] for k in _ROUGH_KEYS},
            **({"not_evaluated": rough["not_evaluated"]}
               if "not_evaluated" in rough else {}),
            "profile": "centre row (through the spindle axis)",
            "profile_length_m": float((hi - lo) * surface.dx),
            "form_removal": "commanded tip height at |x|, then a least-squares "
            "quadratic",
            "standard": "ISO 4287/4288, Gaussian ISO 16610-21, ends trimmed by one "
            "cut-off",
        },
        "centre_profile": {
            "row": prof["row"],
            "y_m": prof["y_m"],
            "x_start_m": float(prof["x"][lo]),
            "x_end_m": float(prof["x"][hi - 1]),
        },
        "field": {
            "kind": "band through the spindle axis" if (
                fld.center_x == 0 and fld.center_y == 0) else "given [field]",
            "nx": fld.nx, "ny": fld.ny,
            "pitch_x_m": fld.pitch_x, "pitch_y_m": fld.pitch_y,
            "x_min_m": fld.bounds[0], "x_max_m": fld.bounds[1],
            "y_min_m": fld.bounds[2], "y_max_m": fld.bounds[3],
        },
        "toolpath": {
            **path.describe(),
            "feed_per_rev_min_m": float(f_in.min()) if f_in.size else None,
            "feed_per_rev_max_m": float(f_in.max()) if f_in.size else None,
            "feed_per_rev_mean_m": float(f_in.mean()) if f_in.size else None,
            "feed_per_rev_range": "r > 5 % of r_max",
        },
        "ra_m": rough["ra_m"],
        "rsm_m": rough["rsm_m"],
        "sa_m": float(np.mean(np.abs(v - v.mean()))) if v.size else None,
        "sq_m": float(np.sqrt(np.mean((v - v.mean()) ** 2))) if v.size else None,
        "form_error_max_m": None,
        "spectrum_peaks_per_m": [],
    }
    plots = {
        "profile": prof,
        "feed": (r_f, feed),
        "roughness": rough,
    }
    return SimulationAnalysis(summary=out, result=result, plot_data=plots)
