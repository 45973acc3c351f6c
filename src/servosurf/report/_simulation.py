"""Analysis of a simulated (or measured) map as a metrologist would do it.

Conventions stated once:

* Lenslet maps: the cutting direction is the local tangential direction. For a field
  centred on the +x axis it is +y (the spindle angle increases), i.e. along the map's
  columns, rows increasing in the direction the tool travels.
* Form error: the simulated (or measured) profile along the cutting direction through
  the lenslet's deepest point, minus the nominal lenslet cut with the **air-cut
  amplitude** ``|T(f)| A`` as the reference (the paper used the 5.2 um air-cut
  amplitude for its nominal 5 um; ``paper_reference_amplitude_m`` and the
  ``form_error_registrations`` entries ``*/paper`` use the paper's 5.2/5 ratio),
  aligned in piston and registered laterally by least squares (a shift of up to
  20 um). ``form_error_max_m`` is the largest error inside the central 80 % of the
  chord; the rim maximum (``form_error_rim_max_m``) moves by 100-150 nm per um of
  registration and is reported beside it. ``form_error_registrations`` repeats both
  for the reference centred on the map's deepest point and on the commanded lens
  centre. Positions are relative to the reference's deepest point, positive when
  the error lags (comes later in the cut).
* High-pass: ISO 16610-61 Gaussian areal filter with cut-off wavelength 12.5 um
  (the paper's "80 mm^-1 high-pass"), no ends trimmed.
* Spectrum: one-sided PSD along the cutting direction of the high-passed map over
  every lenslet of the map (:func:`lenslet_spectrum`; optics convention: integral =
  variance), peaks above 80 mm^-1, strongest first, in 1/m. Peaks inside a band
  where the controller-rate path samples fold onto the pixel grid
  (:func:`servosurf.metrology.sampling_alias_bands`, e.g. 721 mm^-1 for the 5 um
  lenslets at 0.55 um pixels) are flagged ``possible_alias`` (listed in
  ``spectrum_possible_aliases_per_m``); the multi-seed study of ``servosurf paper``
  removes the ones that move with the pixel pitch.
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

__all__ = [
    "analyse",
    "flat_face_ra",
    "FLAT_RA_DEFINITION",
    "lenslet_spectrum",
    "path_alias_bands",
    "alias_flags",
    "commanded_centre",
    "HIGH_PASS_CUTOFF",
    "PEAK_FMIN",
    "PAPER_AIR_CUT_RATIO",
    "CENTRAL_CHORD",
]

#: Cut-off wavelength of the paper's 80 mm^-1 high-pass, in m.
HIGH_PASS_CUTOFF = 1.0 / 80e3
#: Lowest spatial frequency searched for spectral peaks, in 1/m.
PEAK_FMIN = 80e3
#: The paper's form reference: the air-cut amplitude 5.2 um for a nominal 5 um
#: (section 5.3), as a ratio to the nominal amplitude.
PAPER_AIR_CUT_RATIO = 5.2 / 5.0

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
    """Peak force deviation, its lags behind the force peak and the deepest commanded
    point, and the overshoot (:func:`servosurf.cutting.cutting_cycle_stats`)."""
    from ..cutting import cutting_cycle_stats
    from ..toolpath import FacingToolpath

    dev, force = result.deviation["force"], result.force
    fs = result.machine.controller.sample_rate
    if (isinstance(result.spec.path, FacingToolpath) or result.spec.kind == "surface"
            or not np.any(force > 0)):
        return {"force_max_n": float(force.max()) if force.size else 0.0}
    settle = int(0.05 * fs)
    return cutting_cycle_stats(
        force[settle:],
        dev[settle:],
        fs=fs,
        frequency=result.spec.path.frequency,
        command=result.z_command[settle:],
    )


def lenslet_spectrum(
    surface: Surface, *, cutoff: float = HIGH_PASS_CUTOFF, blocks=None
) -> tuple[np.ndarray, np.ndarray, list[dict[str, Any]]]:
    """Mean PSD along the cutting direction (rows) over every lenslet of a map.

    Each lenslet (:func:`~servosurf.metrology.segment_lenslets`) contributes the
    profiles of the central half of its columns, from one cut-off inside its first
    row to one cut-off inside its last (where the high-pass has data on both sides),
    of the map high-passed at ``cutoff`` (m). Lenslets cut by the map's top or bottom
    edge are left out (used only when the map holds no complete one); all profiles are cut to the shortest length so that their
    PSDs share one frequency grid. ``blocks`` (the ``used`` list of an earlier call
    on a map of the same field) reuses those pixel ranges, so that the spectra of
    several realisations share their grid.

    Returns
    -------
    freq : ndarray
        Spatial frequency, 1/m.
    psd : ndarray
        Mean one-sided PSD, m^3 (:func:`~servosurf.metrology.psd_1d`).
    used : list of dict
        Per lenslet used: ``rows`` and ``cols`` (pixel ranges), ``x_m`` (the
        columns' x positions, m) and ``partial`` (the lenslet is cut by the map's
        edge).
    """
    from ..metrology import high_pass, psd_1d, segment_lenslets

    hp = high_pass(surface, cutoff)
    xs, _ = surface.coords()
    if blocks is not None:
        profiles = [hp.z[u["rows"][0]:u["rows"][1], u["cols"][0]:u["cols"][1]]
                    for u in blocks]
        freq, psd = psd_1d(np.concatenate(profiles, axis=1), surface.dy, axis=0)
        return freq, psd, list(blocks)
    edge = int(np.ceil(cutoff / surface.dy))
    ny = surface.shape[0]
    lenses = segment_lenslets(surface)
    blocks = []
    # complete lenslets first; a field smaller than one lenslet along the cut
    # (a quick test field) falls back to the lenslet parts it holds, marked
    # ``partial`` in ``used``
    for partial in (False, True):
        for lens in lenses:
            r0, c0, r1, c1 = lens["bbox"]
            cut = r0 == 0 or r1 == ny
            if cut and not partial:
                continue
            w = c1 - c0
            cc0, cc1 = c0 + w // 4, c1 - w // 4
            rr0, rr1 = r0 + (0 if r0 == 0 else edge), r1 - (0 if r1 == ny else edge)
            if rr1 - rr0 < 32 or cc1 <= cc0:
                continue
            blocks.append((rr0, rr1, cc0, cc1, cut))
        if blocks:
            break
    if not blocks:
        raise ValueError("no lenslet of 32 pixels or more along the cutting "
                         "direction in the map")
    n = min(b[1] - b[0] for b in blocks)
    profiles, used = [], []
    for rr0, rr1, cc0, cc1, cut in blocks:
        mid = (rr0 + rr1) // 2
        s0 = mid - n // 2
        profiles.append(hp.z[s0 : s0 + n, cc0:cc1])
        used.append({"rows": (s0, s0 + n), "cols": (cc0, cc1), "x_m": xs[cc0:cc1],
                     "partial": bool(cut)})
    freq, psd = psd_1d(np.concatenate(profiles, axis=1), surface.dy, axis=0)
    return freq, psd, used


def alias_flags(
    peaks: list[dict[str, Any]], bands: list[dict[str, Any]], df: float
) -> list[dict[str, Any]]:
    """Mark peaks inside a sampling-alias band (+- 2 frequency bins).

    Adds ``possible_alias`` (bool) and ``alias_harmonic`` (int or None) to each
    peak. A band only says where an alias *can* sit: a physical peak may share it
    (the 10 um lenslet's 11.7 kHz mode lies in its band), so the flag does not
    remove a peak; :func:`servosurf.report.lenslet_peak_study` tells them apart by
    changing the pixel pitch.
    """
    out = []
    for pk in peaks:
        f = pk["freq_per_m"]
        hit = next(
            (b for b in bands
             if b["low_per_m"] - 2 * df <= f <= b["high_per_m"] + 2 * df),
            None,
        )
        out.append({**pk, "possible_alias": hit is not None,
                    "alias_harmonic": hit["harmonic"] if hit else None})
    return out


def path_alias_bands(result, used: list[dict[str, Any]], dy: float) -> list[dict]:
    """Alias bands of the controller-rate path samples on the map's pixel grid.

    The path is sampled every ``v / fs`` along the cut, with ``v = omega r`` the
    surface speed at each analysed column's radius; one band per lenslet and
    harmonic (1 and 2: the kinks of the sampled path fall off as 1/k^2).
    """
    from ..metrology import sampling_alias_bands

    fs = result.machine.controller.sample_rate
    omega = result.spec.path.angular_speed
    yc = result.spec.field.center_y
    out = []
    for u in used:
        r = np.hypot(u["x_m"], yc)
        out.extend(sampling_alias_bands(omega * r / fs, dy, harmonics=(1, 2)))
    return out


#: Share of the chord (centred on the deepest point) inside which the "central"
#: form error is taken, away from the rim where a 1 um registration change moves
#: the error by 100-150 nm.
CENTRAL_CHORD = 0.8
#: Largest lateral shift tried by the fitted registration, m.
MAX_SHIFT = 20e-6


def _form_summary(y: np.ndarray, fe: dict[str, Any]) -> dict[str, Any]:
    """Rim and central-chord maxima of a form-error profile and their positions."""
    err, ref = fe["error"], fe["reference"]
    cut = np.isfinite(err)
    xd = fe["x_deepest_m"]
    chord = float(y[cut].max() - y[cut].min()) if cut.any() else np.nan
    central = cut & (np.abs(y - xd) <= 0.5 * CENTRAL_CHORD * chord)
    k = int(np.nanargmax(np.where(central, np.abs(err), np.nan)))
    _ = ref
    return {
        "max_central_m": float(abs(err[k])),
        "lag_central_m": float(y[k] - xd),
        "max_rim_m": fe["max_abs_error_m"],
        "lag_rim_m": fe["max_error_position_m"],
        "shift_m": fe["shift_m"],
        "chord_m": chord,
    }


def commanded_centre(result, x_m: float, y_m: float) -> float:
    """y (m) of the deepest commanded point nearest ``(x_m, y_m)`` on a lenslet path.

    The tool is deepest where ``sin(2 pi f t) = 1``; the workpiece position there is
    ``r (cos theta, sin theta)`` of the path.
    """
    p = result.spec.path
    k = np.arange(int(p.duration * p.frequency) + 1)
    t = (k + 0.25) / p.frequency
    th, r = p.theta_at(t), p.radius_at(t)
    x, y = r * np.cos(th), r * np.sin(th)
    i = int(np.argmin((x - x_m) ** 2 + (y - y_m) ** 2))
    return float(y[i])


def _lenslet(surface: Surface, result, out: dict[str, Any]) -> dict[str, Any]:
    from ..metrology import (
        find_peaks_spectrum,
        form_error_profile,
        high_pass,
        lenslet_centre_profile,
        nominal_lenslet_profile,
        nominal_lenslet_surface,
    )
    from ..servo._loop import ServoLoop

    p = result.spec.path
    fld = result.spec.field
    radius = float(np.hypot(fld.center_x, fld.center_y))
    speed = p.angular_speed * radius
    loop = ServoLoop(result.machine)
    gain = abs(loop.frf(np.array([p.frequency])).paths[("reference", "tool")][0])
    tracking = "tracking" in result.settings.get("parts", [])
    air_cut = gain * p.amplitude if tracking else p.amplitude
    paper_ref = PAPER_AIR_CUT_RATIO * p.amplitude
    prof = lenslet_centre_profile(surface, direction="y")
    y = prof.x
    centre = prof.metadata["lenslet_centre"]["y_m"]
    xc = prof.metadata["lenslet_centre"]["x_m"]
    y_cmd = commanded_centre(result, xc, centre)

    def nominal_at(c):
        def nominal(x, a):
            return nominal_lenslet_profile(
                x,
                amplitude=p.amplitude,
                frequency=p.frequency,
                speed=speed,
                depth=p.depth_of_cut,
                tool_radius=result.spec.tool.nose_radius,
                centre=c,
                path_amplitude=a,
            )

        return nominal

    # three registrations of the reference along the cut: the map's deepest point
    # (what a measurement offers), the commanded lens centre (what a simulation
    # knows) and a least-squares lateral shift (the registration the form fixes)
    views = {}
    fits = {}
    for name, c, shift in (
        ("deepest_point", centre, 0.0),
        ("commanded_centre", y_cmd, 0.0),
        ("fitted", centre, MAX_SHIFT),
    ):
        for ref_name, amp in (("servosurf", air_cut), ("paper", paper_ref)):
            fe = form_error_profile(
                y,
                prof.z,
                nominal_at(c),
                reference_amplitude=amp,
                cutting_direction=1,
                max_shift=shift,
            )
            views[f"{name}/{ref_name}"] = _form_summary(y, fe)
            fits[(name, ref_name)] = fe
    fe = fits[("fitted", "servosurf")]
    main = views["fitted/servosurf"]
    # form-error map: model minus the nominal lenslet at the air-cut amplitude
    # (nominal_lenslet_surface takes the cut along its x; ours runs along rows)
    xs, ys = surface.coords()
    nom = nominal_lenslet_surface(
        ys,
        xs,
        amplitude=p.amplitude,
        frequency=p.frequency,
        speed=speed,
        depth=p.depth_of_cut,
        tool_radius=result.spec.tool.nose_radius,
        centre=(centre + fe["shift_m"], xc),
        path_amplitude=air_cut,
    ).T
    top = p.depth_of_cut - p.amplitude
    inside_lens = nom < top - 0.05 * p.depth_of_cut
    err = surface.z - nom
    err = np.where(inside_lens, err - np.nanmedian(err[inside_lens]), np.nan)
    err_map = surface.replace(z=err)
    hp = high_pass(err_map, HIGH_PASS_CUTOFF)
    # spectrum: every lenslet of the map, path-sampling aliases flagged
    freq, psd, used = lenslet_spectrum(surface)
    bands = path_alias_bands(result, used, surface.dy)
    peaks = find_peaks_spectrum(freq, psd, n=8, fmin=PEAK_FMIN, speed=speed)
    peaks = alias_flags(peaks, bands, float(freq[1] - freq[0]))
    # roughness of the central lenslet's high-passed centre profile
    rows = np.nonzero(inside_lens.any(axis=1))[0]
    cols = np.nonzero(inside_lens.any(axis=0))[0]
    if cols.size == 0:
        raise ValueError("no lenslet in the field")
    c0, c1 = cols[0] + cols.size // 4, cols[-1] - cols.size // 4 + 1
    edge = int(np.ceil(HIGH_PASS_CUTOFF / surface.dy))
    r0, r1 = rows[0] + edge, rows[-1] - edge + 1
    if r1 - r0 < 16:
        r0, r1 = rows[0], rows[-1] + 1
    block = hp.z[r0:r1, c0:c1]
    jc = int(round(prof.metadata["lenslet_centre"]["col"]))
    hp_prof = hp.z[r0:r1, jc]
    ok = np.isfinite(hp_prof)
    ra = (
        float(np.mean(np.abs(hp_prof[ok] - hp_prof[ok].mean())))
        if ok.sum() > 2
        else None
    )
    v = block[np.isfinite(block)]
    out.update(
        form_error_max_m=main["max_central_m"],
        form_error_lag_m=main["lag_central_m"],
        form_error_rim_max_m=main["max_rim_m"],
        form_error_rms_m=fe["rms_error_m"],
        form_error_registrations=views,
        form_reference="air-cut amplitude |T(f)| A; fitted lateral registration; "
        f"max inside the central {CENTRAL_CHORD:.0%} of the chord (rim maximum "
        "beside it)",
        air_cut_amplitude_m=float(air_cut),
        paper_reference_amplitude_m=float(paper_ref),
        commanded_centre_y_m=y_cmd,
        deepest_point_y_m=float(centre),
        surface_speed_m_per_s=float(speed),
        spectrum_peaks_per_m=[pk["freq_per_m"] for pk in peaks],
        spectrum_peaks_hz=[pk["freq_per_m"] * speed for pk in peaks],
        spectrum_possible_aliases_per_m=[
            pk["freq_per_m"] for pk in peaks if pk["possible_alias"]
        ],
        sampling_alias_bands=bands,
        spectrum_lenslets=len(used),
        spectrum_partial_lenslets=any(u.get("partial", False) for u in used),
        ra_m=ra,
        sa_m=float(np.mean(np.abs(v - v.mean()))),
        sq_m=float(np.sqrt(np.mean((v - v.mean()) ** 2))),
        roughness_definition="80 mm^-1 high-passed map inside the lenslet (Ra: centre "
        "profile along the cut)",
    )
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
