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
5. **Split at the spindle axis** (simulated lines through the axis of a turned
   part, see below): the two halves of the measured profile on either side of the
   axis are registered separately, each within one RSm of a searched axis
   position, and the simulated profile is stitched from the two at the axis.
6. **Same mask, same form, same filter, same trimming.** Samples invalid on
   either side are invalid on both and the common valid span is kept; the same
   least-squares polynomial form (default quadratic: a part's sag) is removed from
   each; Ra, Rq, Rz, RSm
   (:func:`~servosurf.metrology.profile_roughness`) are then computed on both with
   the same cut-off and the same end trimming (one cut-off at each end by default),
   so the evaluation lengths are identical.
7. **Correlation** is the Pearson coefficient of the two roughness profiles over
   the evaluation samples; **spectra** are one-sided PSDs of the two roughness
   profiles over the evaluation length (:func:`~servosurf.metrology.psd_1d`).

Why split at the axis
---------------------
A turned part's profile through its centre at azimuth psi crosses the spiral's
grooves at radii displaced from those of the simulated line (azimuths 0 and pi)
by ``f psi / (2 pi)`` (f the feed per revolution): *inward* on both sides of the
axis, that is in opposite directions along the profile. One shift can align one
half only (on case 1022 the best registration puts the halves of the
white-light profile 23 um apart, those of the Formtracer contour 9 um, against
a feed of about 29 um; correlation 0.975 and 0.874, against 0.868 and about 0
with one shift). The halves are therefore registered separately; their mean
shift is the position of the spindle axis on the measured profile (reported as
``shift``), half their difference the azimuthal offset. The split is made when
the simulated side is a line through the spindle axis of a servosurf simulation
(a map whose metadata holds ``simulation``, its line through y = 0 or x = 0
and crossing the axis; ``split="auto"``). The axis position is searched:
candidates are the whole-profile registration and a grid over the measured
profile (half an RSm apart); at each, every half holding at least
:data:`SPLIT_MIN_WINDOWS` RSm of valid samples is registered against its side of
the simulated line within one RSm of the candidate, and the candidate whose
halves correlate best (length-weighted) wins, in either orientation with
``mirror="auto"``. A measured profile with less than that on one side of the
axis gets the shift of its longer half.
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
    "through_spindle_axis",
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
        When the registration was split at the spindle axis, the mean of the two
        half shifts: the position of the simulated x = 0 (the axis) on the
        measured profile (the halves' shifts are in ``info["split"]``).
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
        ``labels``, ``registered``, ``split`` (the two half registrations: for
        ``"below"`` and ``"above"`` the axis, ``shift_m``, ``correlation`` over
        the evaluation samples of that half, ``length_m``; ``axis_m``,
        ``offset_m``, ``window_m``) or ``split_skipped`` (why one shift was
        used).
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
            **self._split_dict(),
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

    def _split_dict(self) -> dict[str, Any]:
        """JSON keys of the registration split at the spindle axis."""
        h = self.info.get("split")
        out: dict[str, Any] = {
            "split_at_axis": h is not None,
            "split_skipped": self.info.get("split_skipped"),
            "axis_position_m": None,
            "half_offset_m": None,
            "half_shifts_m": None,
            "half_correlations": None,
            "half_evaluated_lengths_m": None,
        }
        if h is not None:
            sides = ("below", "above")
            out.update(
                axis_position_m=h["axis_m"],
                half_offset_m=h["offset_m"],
                half_shifts_m={k: h[k]["shift_m"] for k in sides},
                half_correlations={
                    k: (None if not math.isfinite(h[k].get("correlation", math.nan))
                        else h[k]["correlation"]) for k in sides},
                half_evaluated_lengths_m={k: h[k].get("evaluated_length_m")
                                          for k in sides},
            )
        return out

    def plot(self, out_dir: str | Path) -> dict[str, Path]:
        """Write ``profiles.png`` (overlay), ``roughness.png`` (table) and
        ``spectra.png`` into ``out_dir``.

        Parameters
        ----------
        out_dir : str or Path
            Destination folder (created).

        Returns
        -------
        dict of str to Path
            ``{"profiles": ..., "roughness": ..., "spectra": ...}``.
        """
        from ..viz._profile_plots import (
            plot_profile_overlay,
            plot_profile_spectra,
            plot_profile_table,
        )

        d = Path(out_dir)
        return {
            "profiles": plot_profile_overlay(self, d / "profiles.png"),
            "roughness": plot_profile_table(self, d / "roughness.png"),
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


def through_spindle_axis(obj: Surface | Profile, line: Profile) -> bool:
    """Whether ``line`` (taken from ``obj``) runs through a simulated spindle axis.

    Parameters
    ----------
    obj : Surface or Profile
        What the simulated file held.
    line : Profile
        The line taken from it (:func:`~servosurf.metrology.profile_through`).

    Returns
    -------
    bool
        True when ``obj`` comes from a servosurf simulation (``metadata`` holds
        ``simulation``: its coordinates are the workpiece's, the spindle axis at
        the origin), the line lies on y = 0 (rows) or x = 0 (columns) within half
        a pitch, and its positions cross 0.
    """
    md = getattr(obj, "metadata", None) or {}
    if "simulation" not in md:
        return False
    where = line.metadata.get("line")
    if isinstance(obj, Surface) and where is not None:
        if where.get("axis") == "x":
            pitch, pos = obj.dy, where.get("y_m")
        else:
            pitch, pos = obj.dx, where.get("x_m")
        if pos is None or (pitch is not None and abs(pos) > 0.5 * pitch + 1e-15) or (
                pitch is None and pos != 0):
            return False
    ok = np.flatnonzero(np.isfinite(line.z))
    if ok.size < 2:
        return False
    return bool(line.x[ok[0]] < 0.0 < line.x[ok[-1]])


def _mirrored(p: Profile) -> Profile:
    """``p`` seen in the mirror ``x -> -x`` (positions stay increasing)."""
    return Profile(p.z[::-1].copy(), p.dx, x0=-(p.x0 + (p.z.size - 1) * p.dx))


def _valid_length(p: Profile, sel: np.ndarray) -> float:
    ok = np.flatnonzero(np.isfinite(p.z) & sel)
    return 0.0 if ok.size < 2 else float((ok[-1] - ok[0]) * p.dx)


def _register_halves(rm: Profile, rs: Profile, mirrored: bool, axis: float,
                     window: float, min_length: float) -> dict[str, Any] | None:
    """Register the halves of ``rm`` either side of ``axis`` separately.

    ``rm`` and ``rs`` are the clipped roughness profiles (measured, simulated at
    the measured step); ``axis`` is a candidate position of the simulated x = 0
    on the measured profile. Each half holding at least ``min_length`` of valid
    samples is registered against its side of the simulated profile (with
    ``window`` to spare across the axis), its shift searched within ``axis +-
    window``. ``score`` is the length-weighted correlation of the registered
    halves; None when no half could be registered.
    """
    from ..metrology._profile import register_profiles

    sign = -1.0 if mirrored else 1.0
    out: dict[str, Any] = {}
    for side, sel, band in (
        ("below", rm.x < axis, sign * rs.x < window),
        ("above", rm.x >= axis, sign * rs.x > -window),
    ):
        length = _valid_length(rm, sel)
        if length < min_length:
            out[side] = None
            continue
        half = Profile(np.where(sel, rm.z, np.nan), rm.dx, x0=rm.x0)
        part = Profile(np.where(band, rs.z, np.nan), rs.dx, x0=rs.x0)
        try:
            reg = register_profiles(half, part, mirror=mirrored,
                                    shift_range=(axis - window, axis + window))
        except ConfigError:
            out[side] = None
            continue
        out[side] = (None if not math.isfinite(reg.correlation) else
                     {"shift_m": float(reg.shift),
                      "registration_correlation": float(reg.correlation),
                      "length_m": length})
    done = [h for h in (out["below"], out["above"]) if h is not None]
    if not done:
        return None
    total = sum(h["length_m"] for h in done)
    out["score"] = float(sum(h["length_m"] * h["registration_correlation"]
                             for h in done) / total)
    out.update(window_m=float(window), first_axis_m=float(axis),
               mirrored=bool(mirrored))
    if len(done) == 2:
        sb, sa = out["below"]["shift_m"], out["above"]["shift_m"]
        out.update(axis_m=0.5 * (sb + sa), offset_m=0.5 * (sa - sb))
    return out


#: Most candidate axis positions tried per orientation by the split search; a
#: longer measured profile is searched on a coarser grid (and a wider window).
SPLIT_MAX_CANDIDATES: int = 150

#: A half of the measured profile is registered on its own when it holds at least
#: this many search windows (one RSm each) of valid samples.
SPLIT_MIN_WINDOWS: float = 4.0


def _split_search(m: Profile, rm: Profile, rs: Profile, lc: float,
                  mirror: bool | str, max_shift: float | None,
                  first: dict[bool, float]) -> dict[str, Any] | None:
    """Best registration by halves over the candidate axis positions.

    Candidates per orientation allowed by ``mirror``: the whole-profile shift
    ``first[orientation]`` (the axis where one shift puts it) and a grid over
    the measured profile, half a search window apart (the window is one RSm of
    the measured profile). Every candidate is scored by
    :func:`_register_halves` (halves of at least :data:`SPLIT_MIN_WINDOWS`
    windows); the best score wins, ``score_other`` is the best of the other
    orientation. None when no candidate registers.
    """
    from ..metrology._roughness import profile_roughness

    try:
        rsm = profile_roughness(m, cutoff=lc, trim_ends=False)["rsm_m"]
    except ConfigError:
        rsm = math.nan
    window = rsm if math.isfinite(rsm) and 0 < rsm < lc else 0.1 * lc
    window = max(window, 4.0 * m.dx)
    min_half = SPLIT_MIN_WINDOWS * window
    ok = np.flatnonzero(np.isfinite(rm.z))
    if ok.size < 2:
        return None
    lo, hi = rm.x[ok[0]] + min_half, rm.x[ok[-1]] - min_half
    step = 0.5 * window
    if hi > lo and (hi - lo) / step > SPLIT_MAX_CANDIDATES:
        step = (hi - lo) / SPLIT_MAX_CANDIDATES
        window = 2.0 * step
    grid = list(np.arange(lo, hi + 1e-12, step)) if hi > lo else []
    orients = [False, True] if mirror == "auto" else [bool(mirror)]
    best: dict[bool, dict[str, Any]] = {}
    for o in orients:
        axes = ([first[o]] if o in first else []) + grid
        for a in axes:
            if max_shift is not None:
                sign = -1.0 if o else 1.0
                centre = 0.5 * (rm.x[0] + rm.x[-1]) - sign * 0.5 * (rs.x[0] + rs.x[-1])
                if abs(a - centre) > max_shift:
                    continue
            h = _register_halves(rm, rs, o, float(a), window, min_half)
            if h is not None and (o not in best or h["score"] > best[o]["score"]):
                best[o] = h
    if not best:
        return None
    win = max(best.values(), key=lambda h: h["score"])
    others = [h["score"] for h in best.values() if h is not win]
    win["score_other"] = others[0] if others else None
    return win


def _register_common(
    m: Profile,
    s: Profile,
    lc: float,
    register: bool,
    mirror: bool | str,
    max_shift: float | None,
    form: str,
    info: dict[str, Any],
    split: bool,
) -> tuple[Profile, Profile, float, bool, float | None]:
    """Register ``s`` onto ``m`` at cut-off ``lc``; both on the common valid span,
    with the same mask and the ``form`` polynomial removed from each.

    ``split``: register the halves either side of the simulated x = 0 separately
    when the measured profile covers both (see the module docstring).
    """
    from ..metrology._profile import register_profiles, resample_profile
    from ..metrology._roughness import _roughness_profile

    def rough(p: Profile) -> Profile:
        r, _ = _roughness_profile(remove_profile_form(p, form), lc, False, None)
        return Profile(_winsorize(r), p.dx, x0=p.x0)

    halves = None
    info.pop("split", None)
    info.pop("split_skipped", None)
    if register:
        rm, rs = rough(m), rough(s)
        reg = register_profiles(rm, rs, mirror=mirror,  # type: ignore[arg-type]
                                max_shift=max_shift)
        shift, mirrored, reg_corr = reg.shift, reg.mirrored, reg.correlation
        info["registration_correlation_other"] = reg.correlation_other
        info["registration_overlap_m"] = reg.overlap
        if split:
            first = {bool(mirrored): float(shift)}
            if mirror == "auto":
                try:
                    o = not mirrored
                    first[o] = register_profiles(rm, rs, mirror=o,
                                                 max_shift=max_shift).shift
                except ConfigError:
                    pass
            found = _split_search(m, rm, rs, lc, mirror, max_shift, first)
            if found is not None and found["below"] and found["above"]:
                halves = found
                shift, mirrored = halves["axis_m"], halves["mirrored"]
                reg_corr = halves["score"]
                info["registration_correlation_other"] = halves.pop("score_other")
                info["split"] = halves
            else:
                if found is not None:  # one half only: its shift, the other short
                    h = found["below"] or found["above"]
                    shift, mirrored = h["shift_m"], found["mirrored"]
                    reg_corr = h["registration_correlation"]
                    info["registration_correlation_other"] = found["score_other"]
                info["split_skipped"] = (
                    "the measured profile holds less than "
                    f"{SPLIT_MIN_WINDOWS:g} RSm of valid samples on one side of the "
                    "spindle axis")
    else:
        shift, mirrored, reg_corr = 0.0, False, None
    src = _mirrored(s) if mirrored else s
    # in the (possibly mirrored) frame x' = sign * x_sim, and x' = x_m - shift
    if halves is None:
        on_m = resample_profile(src, m.dx, x0=m.x0 - shift, n=m.z.size).z
    else:
        below = resample_profile(src, m.dx, x0=m.x0 - halves["below"]["shift_m"],
                                 n=m.z.size).z
        above = resample_profile(src, m.dx, x0=m.x0 - halves["above"]["shift_m"],
                                 n=m.z.size).z
        on_m = np.where(m.x < halves["axis_m"], below, above)
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
    split: bool | Literal["auto"] = "auto",
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
    split : bool or "auto", default: "auto"
        Register the two halves of the measured profile on either side of the
        spindle axis (the simulated x = 0) separately and stitch the simulated
        profile from them (see the module docstring). ``"auto"``: when the
        simulated side is a line through the axis of a servosurf simulation
        (:func:`through_spindle_axis`); True: whenever the simulated profile
        crosses x = 0. Either way only when the measured profile holds at least
        :data:`SPLIT_MIN_WINDOWS` RSm on each side of the axis; otherwise one
        shift is used and ``info["split_skipped"]`` says why.

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
    if split not in (True, False, "auto"):
        raise ConfigError(f"split must be True, False or 'auto', got {split!r}")
    m = _line_of(measured, line_axis, line_at, "measured")
    s = _line_of(simulated, line_axis, line_at, "simulated")
    if split == "auto":
        do_split = through_spindle_axis(simulated, s)
    elif split:
        ok = np.flatnonzero(np.isfinite(s.z))
        if ok.size < 2 or not s.x[ok[0]] < 0.0 < s.x[ok[-1]]:
            raise ConfigError(
                "split at the axis needs a simulated profile that crosses x = 0 (the "
                f"spindle axis); it spans {s.x[0]:g} .. {s.x[-1]:g} m")
        do_split = True
    else:
        do_split = False
    do_split = do_split and bool(register)
    info["split_mode"] = split
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
            m, s, lc, register, mirror, max_shift, form, info, do_split
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
    halves = info.get("split")
    if halves is not None:
        for side, sel in (("below", pm.x < halves["axis_m"]),
                          ("above", pm.x >= halves["axis_m"])):
            b = both & sel
            c = math.nan
            if b.sum() >= 3 and rm[b].std() > 0 and rs[b].std() > 0:
                c = float(np.corrcoef(rm[b], rs[b])[0, 1])
            halves[side]["correlation"] = c
            halves[side]["evaluated_length_m"] = float(b.sum() * m.dx)
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
