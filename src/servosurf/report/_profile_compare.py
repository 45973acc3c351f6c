"""A measured profile against a simulated surface or profile (or another measurement).

What :func:`compare_profiles` does, in order (SI units, m):

1. **Profiles.** A map gives the profile along one grid line
   (:func:`~servosurf.metrology.profile_through`: default along x through the map's
   centre row); a one-row or one-column map is a profile.
2. **Crop and mask.** The measured profile is cropped to ``x_range`` (in its own
   coordinates) when given; NaN samples at either end of both profiles are dropped.
3. **Cut-off.** ``lambda_c`` is given, or chosen by the ISO 4288 procedure
   (:func:`~servosurf.metrology.iso4288_cutoff`, Ra table) on the measured
   profile over the span both profiles cover (the registration is repeated once
   if that span admits another cut-off than the first guess); the same value is
   used for both sides.
4. **Registration.** Both profiles' roughness profiles (the profile minus its
   ISO 16610-21 Gaussian mean line at ``lambda_c``, end-corrected, nothing trimmed)
   are clipped to their median +- :data:`REGISTRATION_CLIP` robust standard
   deviations and registered with
   :func:`~servosurf.metrology.register_profiles`: a shift
   along the profile and, with ``mirror="auto"``, a mirror ``x -> -x`` when it
   correlates better. The simulated profile is then interpolated (cubic B-spline)
   onto the measured samples: ``x_measured = sign * x_simulated + shift``.
5. **Same mask, same form, same filter, same trimming.** Samples invalid on
   either side are invalid on both and the common valid span is kept; the same
   least-squares polynomial form (default quadratic: a part's sag) is removed from
   each; Ra, Rq, Rz, RSm
   (:func:`~servosurf.metrology.profile_roughness`) are then computed on both with
   the same cut-off and the same end trimming (one cut-off at each end by default),
   so the evaluation lengths are identical.
6. **Correlation** is the Pearson coefficient of the two roughness profiles over
   the evaluation samples; **spectra** are one-sided PSDs of the two roughness
   profiles over the evaluation length (:func:`~servosurf.metrology.psd_1d`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

import numpy as np

from .._validation import check_positive
from ..errors import ConfigError
from ..metrology._surface import Profile, Surface

__all__ = [
    "ProfileComparison",
    "compare_profiles",
    "as_profile_or_none",
    "remove_profile_form",
    "FORMS",
]

#: Roughness parameters reported side by side (keys of profile_roughness, in m).
PARAMETERS: tuple[str, ...] = ("ra_m", "rq_m", "rz_m", "rsm_m")

#: Form polynomials removed before filtering: name -> degree (-1: none).
FORMS: dict[str, int] = {"none": -1, "line": 1, "quadratic": 2}

#: Before registration each roughness profile is clipped to its median +- this
#: many robust standard deviations (1.4826 x the median absolute deviation), so
#: that steps, flanks or spikes outside the compared texture do not drive the
#: correlation.
REGISTRATION_CLIP: float = 5.0

#: Largest fraction of invalid samples (gaps, linearly filled) in the evaluation
#: length for which the spectra are computed; beyond it the spectra are left out.
SPECTRUM_MAX_NAN: float = 0.5


def as_profile_or_none(obj: Surface | Profile) -> Profile | None:
    """Return ``obj`` as a Profile if it is one or a one-row/one-column map, else None.

    Parameters
    ----------
    obj : Surface or Profile
        What a reader returned.

    Returns
    -------
    Profile or None
        The profile (positions and heights in m), None for a 2-D map.
    """
    if isinstance(obj, Profile):
        return obj
    if isinstance(obj, Surface) and 1 in obj.shape and obj.z.size >= 2:
        from ..metrology._profile import profile_through

        return profile_through(obj)
    return None


@dataclass(frozen=True, eq=False)
class ProfileComparison:
    """Result of :func:`compare_profiles` (SI units).

    Attributes
    ----------
    measured : Profile
        The measured primary profile as evaluated (cropped, common mask), heights
        in m at positions in m of the measured file.
    simulated : Profile
        The simulated primary profile registered onto the same samples, m.
    measured_roughness, simulated_roughness : Profile
        The two roughness profiles (primary minus the Gaussian mean line), NaN
        outside the evaluation length, m.
    shift : float
        Registration shift in m: ``x_measured = sign * x_simulated + shift``.
    mirrored : bool
        Whether the simulated profile was mirrored (``sign = -1``).
    correlation : float
        Pearson coefficient of the two roughness profiles over the evaluation
        samples, after registration.
    registration_correlation : float or None
        Peak normalised cross-correlation found by the registration (None when
        not registered).
    cutoff : float
        ``lambda_c`` used on both sides, in m.
    cutoff_rule : str
        ``"given"`` or ``"ISO 4288"`` (chosen on the measured profile).
    trim_length : float
        Length trimmed at each end on both sides, in m (0 when not trimmed).
    roughness : dict
        ``{"measured": {...}, "simulated": {...}}``: the full
        :func:`~servosurf.metrology.profile_roughness` results.
    spectra : tuple of ndarray
        ``(freq_measured, psd_measured, freq_simulated, psd_simulated)``, 1/m and
        m^3.
    info : dict
        How the profiles were obtained: ``line`` (for maps), ``x_range_m``,
        ``labels``, ``registered``.
    """

    measured: Profile
    simulated: Profile
    measured_roughness: Profile
    simulated_roughness: Profile
    shift: float
    mirrored: bool
    correlation: float
    registration_correlation: float | None
    cutoff: float
    cutoff_rule: str
    trim_length: float
    roughness: dict[str, dict[str, Any]]
    spectra: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]
    info: dict[str, Any] = field(default_factory=dict)

    @property
    def labels(self) -> tuple[str, str]:
        """Display names of the two sides (default ``("measured", "simulated")``)."""
        lab = self.info.get("labels") or ("measured", "simulated")
        return str(lab[0]), str(lab[1])

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready summary in SI units (keys carry their unit)."""
        m, s = self.roughness["measured"], self.roughness["simulated"]
        out: dict[str, Any] = {"kind": "profile"}
        for key in PARAMETERS:
            out[f"measured_{key}"] = m[key]
            out[f"simulated_{key}"] = s[key]
        out.update(
            correlation=self.correlation,
            shift_m=self.shift,
            mirrored=self.mirrored,
            registered=bool(self.info.get("registered", True)),
            registration_correlation=self.registration_correlation,
            registration_correlation_other_orientation=self.info.get(
                "registration_correlation_other"
            ),
            registration_overlap_m=self.info.get("registration_overlap_m"),
            form_removed=self.info.get("form_removed", "none"),
            cutoff_m=self.cutoff,
            cutoff_rule=self.cutoff_rule,
            ends_trimmed=self.trim_length > 0,
            trim_length_m=self.trim_length,
            evaluation_length_m=m["evaluation_length_m"],
            step_m=self.measured.dx,
            measured_x_m=[float(self.measured.x[0]), float(self.measured.x[-1])],
            x_range_m=self.info.get("x_range_m"),
            line=self.info.get("line"),
            labels=list(self.labels),
            measured_roughness=m,
            simulated_roughness=s,
        )
        return out

    def plot(self, out_dir: str | Path) -> dict[str, Path]:
        """Write ``profiles.png`` (overlay) and ``spectra.png`` into ``out_dir``.

        Parameters
        ----------
        out_dir : str or Path
            Destination folder (created).

        Returns
        -------
        dict of str to Path
            ``{"profiles": ..., "spectra": ...}``.
        """
        from ..viz._profile_plots import plot_profile_overlay, plot_profile_spectra

        d = Path(out_dir)
        return {
            "profiles": plot_profile_overlay(self, d / "profiles.png"),
            "spectra": plot_profile_spectra(self, d / "spectra.png"),
        }


def _line_of(obj: Surface | Profile, axis: str, at: float | None,
             name: str) -> Profile:
    from ..metrology._profile import profile_through

    if not isinstance(obj, Surface | Profile):
        raise ConfigError(
            f"{name} must be a Surface or Profile, got {type(obj).__name__}"
        )
    return profile_through(obj, axis=axis, at=at)  # type: ignore[arg-type]


def _common_span(a: np.ndarray, b: np.ndarray) -> slice:
    ok = np.flatnonzero(np.isfinite(a) & np.isfinite(b))
    if ok.size < 2:
        return slice(0, 0)
    return slice(int(ok[0]), int(ok[-1]) + 1)


def remove_profile_form(profile: Profile, form: str) -> Profile:
    """Subtract a least-squares polynomial form from a profile.

    Parameters
    ----------
    profile : Profile
        Heights in m (NaN samples are left out of the fit and stay NaN).
    form : {"none", "line", "quadratic"}
        Polynomial removed: nothing, degree 1 or degree 2 in x.

    Returns
    -------
    Profile
        The profile minus the fitted polynomial, in m.

    Raises
    ------
    ConfigError
        For an unknown ``form``.
    """
    if form not in FORMS:
        raise ConfigError(f"form must be one of {', '.join(FORMS)}, got {form!r}")
    deg = FORMS[form]
    if deg < 0:
        return profile
    ok = np.isfinite(profile.z)
    if ok.sum() <= deg:
        return profile
    u = np.linspace(-1.0, 1.0, profile.z.size)  # scaled x: well conditioned
    coef = np.polynomial.polynomial.polyfit(u[ok], profile.z[ok], deg)
    z = profile.z - np.polynomial.polynomial.polyval(u, coef)
    return Profile(z, profile.dx, metadata=dict(profile.metadata), x0=profile.x0)


def _winsorize(r: np.ndarray) -> np.ndarray:
    """Clip ``r`` to its median +- REGISTRATION_CLIP robust standard deviations."""
    ok = np.isfinite(r)
    if ok.sum() < 3:
        return r
    med = float(np.median(r[ok]))
    sigma = 1.4826 * float(np.median(np.abs(r[ok] - med)))
    if not sigma > 0:
        return r
    lim = REGISTRATION_CLIP * sigma
    return np.where(ok, np.clip(r, med - lim, med + lim), np.nan)


def _register_common(
    m: Profile,
    s: Profile,
    lc: float,
    register: bool,
    mirror: bool | str,
    max_shift: float | None,
    form: str,
    info: dict[str, Any],
) -> tuple[Profile, Profile, float, bool, float | None]:
    """Register ``s`` onto ``m`` at cut-off ``lc``; both on the common valid span,
    with the same mask and the ``form`` polynomial removed from each."""
    from ..metrology._profile import register_profiles, resample_profile
    from ..metrology._roughness import _roughness_profile

    def rough(p: Profile) -> Profile:
        r, _ = _roughness_profile(remove_profile_form(p, form), lc, False, None)
        return Profile(_winsorize(r), p.dx, x0=p.x0)

    if register:
        reg = register_profiles(rough(m), rough(s), mirror=mirror,  # type: ignore[arg-type]
                                max_shift=max_shift)
        shift, mirrored, reg_corr = reg.shift, reg.mirrored, reg.correlation
        info["registration_correlation_other"] = reg.correlation_other
        info["registration_overlap_m"] = reg.overlap
    else:
        shift, mirrored, reg_corr = 0.0, False, None
    src = s
    if mirrored:
        src = Profile(s.z[::-1].copy(), s.dx, x0=-(s.x0 + (s.z.size - 1) * s.dx))
    # in the (possibly mirrored) frame x' = sign * x_sim, and x' = x_m - shift
    on_m = resample_profile(src, m.dx, x0=m.x0 - shift, n=m.z.size).z
    span = _common_span(m.z, on_m)
    if span.stop - span.start < 2:
        raise ConfigError(
            "the measured and simulated profiles do not overlap"
            + (" after registration" if register else "")
            + f" (measured x {m.x[0]:g}..{m.x[-1]:g} m, simulated x "
            f"{s.x[0]:g}..{s.x[-1]:g} m, shift {shift:g} m); check the x range and "
            "the line through the map"
            + ("" if register else ", or let compare register the profiles")
        )
    mz = m.z[span].copy()
    sz = on_m[span].copy()
    bad = ~(np.isfinite(mz) & np.isfinite(sz))
    mz[bad] = np.nan
    sz[bad] = np.nan
    x0 = m.x0 + span.start * m.dx
    md_m = {k: v for k, v in m.metadata.items() if k != "line"}
    md_s = {k: v for k, v in s.metadata.items() if k != "line"}
    pm = remove_profile_form(Profile(mz, m.dx, metadata=md_m, x0=x0), form)
    ps = remove_profile_form(Profile(sz, m.dx, metadata=md_s, x0=x0), form)
    return pm, ps, float(shift), bool(mirrored), reg_corr


def compare_profiles(
    measured: Surface | Profile,
    simulated: Surface | Profile,
    *,
    line_axis: Literal["x", "y"] = "x",
    line_at: float | None = None,
    x_range: tuple[float, float] | None = None,
    cutoff: float | None = None,
    trim_ends: bool = True,
    register: bool = True,
    mirror: bool | Literal["auto"] = "auto",
    max_shift: float | None = None,
    form: Literal["none", "line", "quadratic"] = "quadratic",
    labels: tuple[str, str] = ("measured", "simulated"),
) -> ProfileComparison:
    """Compare a measured profile with a simulated surface or profile.

    Parameters
    ----------
    measured : Surface or Profile
        Measured profile (a map gives its line, see ``line_axis``); heights in m,
        NaN invalid.
    simulated : Surface or Profile
        Simulated profile, or a map from which the line is taken.
    line_axis : {"x", "y"}, default: "x"
        Direction of the line taken through a map (rows along x, columns along y).
    line_at : float, optional
        Position of that line across it, in m (default: the map's centre line).
    x_range : (float, float), optional
        Crop of the measured profile, ``(x_min, x_max)`` in m in its own
        coordinates (e.g. the cut zone of a stylus contour that also holds the
        part's flanks).
    cutoff : float, optional
        ``lambda_c`` in m; default: the ISO 4288 choice
        (:func:`~servosurf.metrology.iso4288_cutoff`, Ra table) on the measured
        profile over the span that both profiles cover.
    trim_ends : bool, default: True
        Exclude one cut-off at each end of the common valid span on both sides.
    register : bool, default: True
        Register the simulated profile onto the measured one (shift, mirror).
        When False the simulated positions are taken as measured positions.
    mirror : bool or "auto", default: "auto"
        Mirror handling of the registration (see
        :func:`~servosurf.metrology.register_profiles`).
    max_shift : float, optional
        Largest registration shift from centre-on-centre, in m.
    form : {"none", "line", "quadratic"}, default: "quadratic"
        Least-squares polynomial removed from each profile (over the common span,
        the same on both sides) before the Gaussian filter. The Gaussian mean line
        of a parabola ``c x^2`` lies ``c sigma^2`` above it (``sigma = alpha
        lambda_c / sqrt(2 pi)``, the kernel's standard deviation), an offset that
        Ra would count: about 100 nm for the sag of an 11 mm sphere at
        lambda_c = 0.25 mm. The quadratic removes such a sag.
    labels : (str, str), default: ("measured", "simulated")
        Display names of the two sides in the figures (e.g. two instruments).

    Returns
    -------
    ProfileComparison
        Both profiles on the same samples, the roughness side by side, the
        registration and the spectra.

    Raises
    ------
    ConfigError
        When a profile is too short for the cut-off, the x range is empty, the
        profiles do not overlap, or an argument is invalid.

    Examples
    --------
    >>> import numpy as np
    >>> from servosurf.metrology import Profile
    >>> from servosurf.report import compare_profiles
    >>> x = np.arange(4000) * 0.5e-6
    >>> z = 50e-9 * np.sin(2 * np.pi * x / (30e-6 + 2e-3 * x))
    >>> meas = Profile(z[500:2500], 0.5e-6, x0=x[500])
    >>> sim = Profile(z, 0.5e-6, x0=-1e-3)  # the same surface, other origin
    >>> res = compare_profiles(meas, sim, cutoff=0.25e-3, mirror=False)
    >>> round(res.shift * 1e3, 6), round(res.correlation, 6)
    (1.0, 1.0)
    """
    from ..metrology._profile import crop_profile, resample_profile, trim_invalid_ends
    from ..metrology._roughness import (
        _roughness_profile,
        iso4288_cutoff,
        profile_roughness,
    )
    from ..metrology._spectrum import psd_1d

    if len(labels) != 2 or not all(isinstance(v, str) for v in labels):
        raise ConfigError(f"labels must be two strings, got {labels!r}")
    if form not in FORMS:
        raise ConfigError(f"form must be one of {', '.join(FORMS)}, got {form!r}")
    info: dict[str, Any] = {
        "labels": list(labels),
        "registered": bool(register),
        "form_removed": form,
    }
    m = _line_of(measured, line_axis, line_at, "measured")
    s = _line_of(simulated, line_axis, line_at, "simulated")
    lines = {k: p.metadata["line"] for k, p in (("measured", m), ("simulated", s))
             if "line" in p.metadata}
    if lines:
        info["line"] = lines
    if x_range is not None:
        if len(x_range) != 2:
            raise ConfigError(f"x_range must be (x_min, x_max) in m, got {x_range!r}")
        m = crop_profile(m, float(x_range[0]), float(x_range[1]))
        info["x_range_m"] = [float(x_range[0]), float(x_range[1])]
    m = trim_invalid_ends(m)
    s = trim_invalid_ends(s)
    if not math.isclose(s.dx, m.dx, rel_tol=1e-9):
        s = resample_profile(s, m.dx)
    if cutoff is None:
        # the ISO 4288 choice on the measured profile, limited to what the shorter
        # profile admits; chosen again below on the common span actually evaluated
        shorter = m if m.z.size <= s.z.size else s
        lc = iso4288_cutoff(shorter, trim_ends=trim_ends)
        rule = "ISO 4288"
    else:
        lc = check_positive(cutoff, name="cutoff")
        rule = "given"
    for _ in range(2):
        pm, ps, shift, mirrored, reg_corr = _register_common(
            m, s, lc, register, mirror, max_shift, form, info
        )
        if cutoff is not None:
            break
        final = iso4288_cutoff(pm, trim_ends=trim_ends)
        if final == lc:
            break
        lc = final  # register again with the cut-off of the evaluated span
    trim = lc if trim_ends else None
    res_m = profile_roughness(pm, cutoff=lc, trim_ends=trim_ends, trim_length=trim)
    res_s = profile_roughness(ps, cutoff=lc, trim_ends=trim_ends, trim_length=trim)
    res_m["cutoff_rule"] = res_s["cutoff_rule"] = rule
    rm, _ = _roughness_profile(pm, lc, trim_ends, trim)
    rs, _ = _roughness_profile(ps, lc, trim_ends, trim)
    both = np.isfinite(rm) & np.isfinite(rs)
    if both.sum() >= 3 and rm[both].std() > 0 and rs[both].std() > 0:
        corr = float(np.corrcoef(rm[both], rs[both])[0, 1])
    else:
        corr = float("nan")
    ev = _common_span(rm, rs)
    try:
        fm, psm = psd_1d(rm[ev], m.dx, max_nan_fraction=SPECTRUM_MAX_NAN)
        fs_, pss = psd_1d(rs[ev], m.dx, max_nan_fraction=SPECTRUM_MAX_NAN)
    except ConfigError:  # too short or too many gaps: no spectra, numbers still hold
        fm = psm = fs_ = pss = np.zeros(0)
    return ProfileComparison(
        measured=pm,
        simulated=ps,
        measured_roughness=Profile(rm, m.dx, x0=pm.x0),
        simulated_roughness=Profile(rs, m.dx, x0=pm.x0),
        shift=float(shift),
        mirrored=bool(mirrored),
        correlation=corr,
        registration_correlation=None if reg_corr is None else float(reg_corr),
        cutoff=float(lc),
        cutoff_rule=rule,
        trim_length=float(res_m["trim_length_m"]),
        roughness={"measured": res_m, "simulated": res_s},
        spectra=(fm, psm, fs_, pss),
        info=info,
    )
