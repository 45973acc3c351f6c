"""Analysis of a simulated (or measured) map as a metrologist would do it.

Conventions stated once:

* Lenslet maps: the cutting direction is the local tangential direction. For a field
  centred on the +x axis it is +y (the spindle angle increases), i.e. along the map's
  columns, rows increasing in the direction the tool travels.
* Form error: the simulated (or measured) profile along the cutting direction through
  the lenslet's deepest point, minus the nominal lenslet cut with the **air-cut
  amplitude** ``|T(f)| A`` as the reference (the paper used the 5.2 um air-cut
  amplitude for its nominal 5 um), aligned in piston. The position of the maximum
  error is given relative to the deepest point, positive when it lags (comes later in
  the cut).
* High-pass: ISO 16610-61 Gaussian areal filter with cut-off wavelength 12.5 um
  (the paper's "80 mm^-1 high-pass"), no ends trimmed.
* Spectrum: one-sided PSD along the cutting direction of the high-passed map over
  the lenslet's columns (optics convention: integral = variance), peaks above
  80 mm^-1, strongest first, in 1/m.
* Roughness: ``sa_m``/``sq_m`` over the analysed region, unfiltered about the
  least-squares plane for flat faces (the paper's "no filter applied") and of the
  high-passed map inside the lenslet for lenslets; ``ra_m`` for lenslets along the
  cutting direction of the high-passed centre profile.
* Flat-face Ra (``ra_m`` of a face; one definition for ``simulate``, ``paper``
  and the README, :func:`flat_face_ra`): the arithmetic mean deviation of the
  heights from their least-squares plane (piston and tilt), no filter (neither a
  lambda-s nor a lambda-c cut-off, the paper's "no filter applied"), over the whole
  simulated field (the toolpath's ``[field]``: the 20X interferometer field,
  640 x 480 pixels at 0.55 um), nothing trimmed, on the machined map before any
  interferometer model. ``ra_instrument_m`` is the same on the interferometer
  model's map.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ..metrology._surface import Profile, Surface

__all__ = ["analyse", "flat_face_ra", "FLAT_RA_DEFINITION", "HIGH_PASS_CUTOFF",
           "PEAK_FMIN"]

#: Cut-off wavelength of the paper's 80 mm^-1 high-pass, in m.
HIGH_PASS_CUTOFF = 1.0 / 80e3
#: Lowest spatial frequency searched for spectral peaks, in 1/m.
PEAK_FMIN = 80e3

#: The flat-face Ra definition (see :func:`flat_face_ra`), as reported.
FLAT_RA_DEFINITION = (
    "flat-face Ra: mean |z - least-squares plane| over the whole simulated field "
    "(the toolpath's [field]), no filter (no lambda-s, no lambda-c cut-off), nothing "
    "trimmed, on the machined map before the interferometer model"
)


def flat_face_ra(surface: Surface) -> float:
    """The flat-face Ra: one definition for ``simulate``, ``paper`` and the README.

    Parameters
    ----------
    surface : Surface
        A face's height map in m (NaN pixels are left out).

    Returns
    -------
    float
        Arithmetic mean deviation of the heights from their least-squares plane
        (piston and tilt removed, no filter, no cut-off, nothing trimmed), in m. For
        a kinematic facing cut it is ``f^2 / (18 sqrt(3) R)``, 0.257 nm at
        2 um/rev with R = 0.5 mm.

    Notes
    -----
    The seed paper reports "1.2 nm (Ra) with no filter applied" for its flat cut,
    measured over a white-light interferometer field; servosurf evaluates the same
    quantity over the toolpath's field (the 20X field, 0.352 x 0.264 mm). It is the
    areal Sa of ISO 25178-2 about the plane, which for feed marks equals the profile
    Ra across them.
    """
    lev = surface.level()
    v = lev.z[np.isfinite(lev.z)]
    return float(np.mean(np.abs(v)))


def _deviation_stats(result) -> dict[str, Any]:
    """Peak force deviation, its lag behind the force peak, and the overshoot."""
    from ..toolpath import FacingToolpath

    dev, force = result.deviation["force"], result.force
    fs = result.machine.controller.sample_rate
    out: dict[str, Any] = {}
    if (isinstance(result.spec.path, FacingToolpath) or result.spec.kind == "surface"
            or not np.any(force > 0)):
        out["force_max_n"] = float(force.max()) if force.size else 0.0
        return out
    settle = int(0.05 * fs)
    f = force[settle:]
    d = dev[settle:]
    period = int(round(fs / result.spec.path.frequency))
    # last complete cutting cycle in the record
    cutting = np.nonzero(f > 0)[0]
    if cutting.size == 0:
        return out
    start = cutting[-1]
    while start > 0 and f[start - 1] > 0:
        start -= 1
    seg = slice(max(start - period // 6, 0), min(start + period, f.size))
    fc, dc = f[seg], d[seg]
    i_f, i_d = int(np.argmax(fc)), int(np.argmax(dc))
    out.update(
        force_max_n=float(fc.max()),
        deviation_max_m=float(dc.max()),
        deviation_overshoot_m=float(-dc.min()),
        deviation_lag_s=float((i_d - i_f) / fs),
    )
    return out


def _lenslet(surface: Surface, result, out: dict[str, Any]) -> dict[str, Any]:
    from ..metrology import (
        find_peaks_spectrum,
        form_error_profile,
        high_pass,
        lenslet_centre_profile,
        nominal_lenslet_profile,
        nominal_lenslet_surface,
        profile_roughness,
        psd_1d,
    )
    from ..servo._loop import ServoLoop

    p = result.spec.path
    fld = result.spec.field
    radius = float(np.hypot(fld.center_x, fld.center_y))
    speed = p.angular_speed * radius
    loop = ServoLoop(result.machine)
    gain = abs(loop.frf(np.array([p.frequency])).paths[("reference", "tool")][0])
    air_cut = (
        gain * p.amplitude
        if "tracking" in result.settings.get("parts", [])
        else p.amplitude
    )
    prof = lenslet_centre_profile(surface, direction="y")
    y = prof.x
    centre = prof.metadata["lenslet_centre"]["y_m"]

    def nominal(x, a):
        return nominal_lenslet_profile(
            x,
            amplitude=p.amplitude,
            frequency=p.frequency,
            speed=speed,
            depth=p.depth_of_cut,
            tool_radius=result.spec.tool.nose_radius,
            centre=centre,
            path_amplitude=a,
        )

    fe = form_error_profile(
        y, prof.z, nominal, reference_amplitude=air_cut, cutting_direction=1
    )
    # form-error map: model minus the nominal lenslet at the air-cut amplitude
    # (nominal_lenslet_surface takes the cut along its x; ours runs along rows)
    xs, ys = surface.coords()
    xc = prof.metadata["lenslet_centre"]["x_m"]
    nom = nominal_lenslet_surface(
        ys,
        xs,
        amplitude=p.amplitude,
        frequency=p.frequency,
        speed=speed,
        depth=p.depth_of_cut,
        tool_radius=result.spec.tool.nose_radius,
        centre=(centre, xc),
        path_amplitude=air_cut,
    ).T
    top = p.depth_of_cut - p.amplitude
    inside_lens = nom < top - 0.05 * p.depth_of_cut
    err = surface.z - nom
    err = np.where(inside_lens, err - np.nanmedian(err[inside_lens]), np.nan)
    err_map = surface.replace(z=err)
    hp = high_pass(err_map, HIGH_PASS_CUTOFF)
    rows = np.nonzero(inside_lens.any(axis=1))[0]
    cols = np.nonzero(inside_lens.any(axis=0))[0]
    if cols.size == 0:
        raise ValueError("no lenslet in the field")
    # central half of the lenslet's columns; rows one cut-off inside the lenslet's
    # ends, where the filter has no data on one side
    c0, c1 = cols[0] + cols.size // 4, cols[-1] - cols.size // 4 + 1
    edge = int(np.ceil(HIGH_PASS_CUTOFF / surface.dy))
    r0, r1 = rows[0] + edge, rows[-1] - edge + 1
    if r1 - r0 < 16:
        r0, r1 = rows[0], rows[-1] + 1
    block = hp.z[r0:r1, c0:c1]
    freq, psd = psd_1d(block, surface.dy, axis=0)
    peaks = find_peaks_spectrum(freq, psd, n=5, fmin=PEAK_FMIN, speed=speed)
    jc = int(round(prof.metadata["lenslet_centre"]["col"]))
    hp_prof = hp.z[r0:r1, jc]
    ok = np.isfinite(hp_prof)
    ra = (
        float(np.mean(np.abs(hp_prof[ok] - hp_prof[ok].mean())))
        if ok.sum() > 2
        else np.nan
    )
    inside = block
    v = inside[np.isfinite(inside)]
    out.update(
        form_error_max_m=fe["max_abs_error_m"],
        form_error_lag_m=fe["max_error_position_m"],
        form_error_rms_m=fe["rms_error_m"],
        form_reference="air-cut amplitude |T(f)| A",
        air_cut_amplitude_m=float(air_cut),
        surface_speed_m_per_s=float(speed),
        spectrum_peaks_per_m=[pk["freq_per_m"] for pk in peaks],
        spectrum_peaks_hz=[pk["freq_per_m"] * speed for pk in peaks],
        ra_m=ra,
        sa_m=float(np.mean(np.abs(v - v.mean()))),
        sq_m=float(np.sqrt(np.mean((v - v.mean()) ** 2))),
        roughness_definition="80 mm^-1 high-passed map inside the lenslet (Ra: centre "
        "profile along the cut)",
    )
    if not ok.any():
        out["ra_m"] = None
    _ = profile_roughness  # profile Ra with ISO filtering is used for flat faces
    out["_plots"] = {
        "profile": (y, prof.z, fe),
        "highpass": hp,
        "form_error_map": err_map,
        "spectrum": (freq, psd, peaks),
    }
    return out


def _flat(surface: Surface, result, out: dict[str, Any]) -> dict[str, Any]:
    from ..metrology import find_peaks_spectrum, high_pass, psd_1d

    lev = surface.level()
    v = lev.z[np.isfinite(lev.z)]
    hp = high_pass(surface, HIGH_PASS_CUTOFF)
    freq, psd = psd_1d(hp.z, surface.dy, axis=0)
    peaks = find_peaks_spectrum(freq, psd, n=5, fmin=PEAK_FMIN)
    out.update(
        ra_m=flat_face_ra(result.surface),
        ra_instrument_m=(flat_face_ra(result.measured)
                         if result.measured is not None else None),
        sa_m=float(np.mean(np.abs(v - v.mean()))),
        sq_m=float(np.sqrt(np.mean((v - v.mean()) ** 2))),
        sz_m=float(v.max() - v.min()),
        form_error_max_m=None,
        form_error_lag_m=None,
        spectrum_peaks_per_m=[pk["freq_per_m"] for pk in peaks],
        roughness_definition=FLAT_RA_DEFINITION + "; sa_m, sq_m, sz_m: of the "
        "analysed map, unfiltered about the least-squares plane",
    )
    out["_plots"] = {"highpass": hp, "spectrum": (freq, psd, peaks)}
    return out


def _design(surface: Surface, result, out: dict[str, Any]) -> dict[str, Any]:
    """Form error against the design; roughness and spectrum of the error map."""
    from ..metrology import form_error_against_design

    path = result.spec.path
    fe = form_error_against_design(surface, path, best_fit_sphere=True)
    out = _flat(fe.error, result, out)
    err = fe.error.z[np.isfinite(fe.error.z)]
    fld = result.spec.field
    xs = np.linspace(fld.bounds[0], fld.bounds[1], 3)
    ys = np.linspace(fld.bounds[2], fld.bounds[3], 3)
    gx, gy = np.meshgrid(xs, ys)
    with np.errstate(invalid="ignore"):
        scallop = path.predicted_scallop(np.hypot(gx, gy), np.arctan2(gy, gx))
    out.update(fe.to_dict())
    out.update(
        form_error_max_m=float(np.max(np.abs(err))),
        form_reference="design surface (toolpath [surface]) on the workpiece, after "
        "piston and tilt; bfs: also after the best-fit sphere",
        kinematic_scallop_m=(float(np.nanmax(scallop)) if np.isfinite(scallop).any()
                             else None),
        design_toolpath=path.to_dict(),
        roughness_definition="of the form-error map (map minus design, after piston "
        "and tilt), unfiltered about its least-squares plane; Ra mean over radial rows "
        "after a line fit",
    )
    out["_plots"]["form_error"] = fe
    return out


def analyse(result, *, use_measured: bool = True) -> dict[str, Any]:
    """Metrology summary of a :class:`~servosurf.simulation.SimulationResult`.

    Parameters
    ----------
    result : SimulationResult
        A simulation.
    use_measured : bool, default: True
        Analyse the interferometer model's map when there is one.

    Returns
    -------
    dict
        SI values: ``form_error_max_m``, ``form_error_lag_m`` (lenslets),
        ``form_error_pv_m``, ``form_error_rms_m`` and their ``_bfs`` variants
        (design surfaces, against the design after piston and tilt),
        ``spectrum_peaks_per_m`` (strongest first), ``ra_m``, ``sa_m``, ``sq_m``,
        deviation statistics (``deviation_max_m``, ``deviation_overshoot_m``,
        ``deviation_lag_s``, ``force_max_n``) and ``_plots`` data (not JSON).
    """
    surface = (
        result.measured
        if (use_measured and result.measured is not None)
        else result.surface
    )
    out: dict[str, Any] = {
        "analysed_map": "measured" if surface is result.measured else "model"
    }
    if result.spec.kind == "nc":
        from ._nc import analyse_nc

        return analyse_nc(result, use_measured=use_measured)
    out.update(_deviation_stats(result))
    if result.spec.kind == "lenslet":
        return _lenslet(surface, result, out)
    if result.spec.kind == "surface":
        return _design(surface, result, out)
    return _flat(surface, result, out)


def profile_of(surface: Surface, axis: int) -> Profile:
    """Centre row (axis=1) or column (axis=0) of a map as a Profile."""
    if axis == 1:
        return Profile(surface.z[surface.shape[0] // 2], surface.dx)
    return Profile(surface.z[:, surface.shape[1] // 2], surface.dy)
