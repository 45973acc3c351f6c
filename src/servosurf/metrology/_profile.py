"""Profile handling: crop, take a line through a map, resample, register in 1-D.

Conventions (SI: m): a :class:`Profile` holds heights ``z`` at ``x = x0 + k dx``.
A registration maps the *moving* profile's positions onto the *reference*'s:
``x_ref = sign * x_moving + shift`` with ``sign = -1`` when the moving profile is
mirrored (``x -> -x``; a profile through the spindle axis can be measured in either
direction).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

import numpy as np
import scipy.ndimage as ndi
import scipy.signal

from .._validation import check_finite, check_positive
from ..errors import ConfigError
from ._surface import Profile, Surface

__all__ = [
    "crop_profile",
    "trim_invalid_ends",
    "profile_through",
    "resample_profile",
    "register_profiles",
    "ProfileRegistration",
    "MIN_OVERLAP",
]

#: Default smallest overlap of a registration, as a fraction of the shorter profile's
#: valid length: shifts that overlap less are not considered.
MIN_OVERLAP: float = 0.9


def _check_profile(profile: object, name: str) -> Profile:
    if not isinstance(profile, Profile):
        raise ConfigError(f"{name} must be a Profile, got {type(profile).__name__}")
    return profile


def crop_profile(profile: Profile, x_min: float, x_max: float) -> Profile:
    """Return the samples of ``profile`` with ``x_min <= x <= x_max``.

    Parameters
    ----------
    profile : Profile
        Heights in m at positions ``x`` in m.
    x_min, x_max : float
        Bounds of the kept range, in m, in the profile's own coordinates
        (``x_min < x_max``).

    Returns
    -------
    Profile
        The cropped profile (same step, ``x0`` the first kept position); metadata
        gains ``x_range_m``.

    Raises
    ------
    ConfigError
        If the bounds are not finite and increasing, or fewer than two samples of
        the profile lie in the range (the message gives the profile's extent).
    """
    _check_profile(profile, "profile")
    lo = check_finite(x_min, name="x range minimum")
    hi = check_finite(x_max, name="x range maximum")
    if not lo < hi:
        raise ConfigError(
            f"x range must have minimum < maximum, got [{lo:g}, {hi:g}] m"
        )
    x = profile.x
    tol = 1e-9 * profile.dx
    keep = np.flatnonzero((x >= lo - tol) & (x <= hi + tol))
    if keep.size < 2:
        raise ConfigError(
            f"x range [{lo:g}, {hi:g}] m holds {keep.size} sample(s) of the profile, "
            f"which spans [{x[0]:g}, {x[-1]:g}] m; expected at least 2 (the range is "
            "in m, in the file's own x coordinates)"
        )
    i0, i1 = int(keep[0]), int(keep[-1]) + 1
    md = {**profile.metadata, "x_range_m": [lo, hi]}
    return Profile(profile.z[i0:i1].copy(), profile.dx, metadata=md, x0=float(x[i0]))


def trim_invalid_ends(profile: Profile) -> Profile:
    """Return ``profile`` without its leading and trailing invalid (NaN) samples.

    Parameters
    ----------
    profile : Profile
        Heights in m, NaN where invalid.

    Returns
    -------
    Profile
        From the first to the last valid sample (inner NaN gaps are kept).

    Raises
    ------
    ConfigError
        If fewer than two samples are valid.
    """
    _check_profile(profile, "profile")
    ok = np.flatnonzero(np.isfinite(profile.z))
    if ok.size < 2:
        raise ConfigError(
            f"profile has {ok.size} valid sample(s) of {profile.z.size}; expected "
            "at least 2"
        )
    i0, i1 = int(ok[0]), int(ok[-1]) + 1
    if i0 == 0 and i1 == profile.z.size:
        return profile
    return Profile(
        profile.z[i0:i1].copy(),
        profile.dx,
        metadata=dict(profile.metadata),
        x0=profile.x0 + i0 * profile.dx,
    )


def profile_through(
    surface: Surface | Profile,
    *,
    axis: Literal["x", "y"] = "x",
    at: float | None = None,
) -> Profile:
    """Take the profile along one grid line of a map.

    Parameters
    ----------
    surface : Surface or Profile
        Height map in m (calibrated). A Profile is returned unchanged; a one-row
        map is its row and a one-column map its column, whatever ``axis``.
    axis : {"x", "y"}, default: "x"
        Direction of the profile: ``"x"`` takes a row (along the columns),
        ``"y"`` a column.
    at : float, optional
        Position of the line across it, in m: the y of the row for ``axis="x"``,
        the x of the column for ``axis="y"``. Default: the centre of the map's
        extent (with an even number of lines, the one just above the centre).
        The grid line nearest to ``at`` is taken (no interpolation between
        lines).

    Returns
    -------
    Profile
        Heights in m along the line with its positions in m (``x0`` is the map's
        ``x0`` or ``y0``). ``metadata["line"]`` states the line used:
        ``{"axis": "x", "y_m": ..., "row": ...}`` or ``{"axis": "y", "x_m": ...,
        "column": ...}``.

    Raises
    ------
    ConfigError
        If the map is uncalibrated, ``axis`` is unknown or ``at`` lies outside the
        map.
    """
    if isinstance(surface, Profile):
        return surface
    if not isinstance(surface, Surface):
        raise ConfigError(
            f"surface must be a Surface or Profile, got {type(surface).__name__}"
        )
    if axis not in ("x", "y"):
        raise ConfigError(f"line axis must be 'x' or 'y', got {axis!r}")
    ny, nx = surface.shape
    if ny == 1 and nx == 1:
        raise ConfigError("the map has a single pixel; expected a profile or a map")
    if ny == 1:
        axis = "x"
    elif nx == 1:
        axis = "y"
    step = surface.dx if axis == "x" else surface.dy
    across = surface.dy if axis == "x" else surface.dx
    if step is None or across is None:
        raise ConfigError(
            "the map is uncalibrated (no pixel size); a profile needs positions in m"
        )
    n_across = ny if axis == "x" else nx
    start = surface.y0 if axis == "x" else surface.x0
    other = "y" if axis == "x" else "x"
    if at is None:
        # the centre line; with an even count the centre lies between two lines
        # and the one at the larger coordinate is taken
        k = n_across // 2
    else:
        at = check_finite(at, name=f"line position ({other} in m)")
        u = (at - start) / across
        if not -0.5 <= u <= n_across - 0.5:
            raise ConfigError(
                f"line position {other} = {at:g} m lies outside the map, which spans "
                f"{start:g} .. {start + (n_across - 1) * across:g} m in {other}"
            )
        k = min(max(int(math.floor(u + 0.5)), 0), n_across - 1)
    z = surface.z[k, :] if axis == "x" else surface.z[:, k]
    x0 = surface.x0 if axis == "x" else surface.y0
    pos = start + k * across
    index = "row" if axis == "x" else "column"
    line = {"axis": axis, f"{other}_m": float(pos), index: k}
    md = {**surface.metadata, "line": line}
    return Profile(np.array(z, dtype=float), step, metadata=md, x0=x0)


def resample_profile(
    profile: Profile,
    dx: float,
    *,
    x0: float | None = None,
    n: int | None = None,
    order: int = 3,
) -> Profile:
    """Resample a profile onto a uniform grid (cubic B-spline or linear).

    Parameters
    ----------
    profile : Profile
        Heights in m; NaN samples stay invalid (a new sample is NaN when either
        source sample it falls between is NaN).
    dx : float
        New step, in m.
    x0 : float, optional
        First position of the new grid, in m; default the profile's ``x0``.
    n : int, optional
        Number of new samples; default as many as fit in the profile's extent.
    order : {1, 3}, default: 3
        Interpolation: 3 for a cubic B-spline interpolant
        (:func:`scipy.ndimage.map_coordinates`, which keeps short wavelengths
        that linear interpolation damps), 1 for linear interpolation.

    Returns
    -------
    Profile
        The resampled profile; positions outside the source extent are NaN.

    Notes
    -----
    Interpolation does not low-pass the profile: when the new step is coarser than
    the old one, wavelengths shorter than twice the new step alias. The measured
    profiles compare at their own step, so the simulated one is resampled and its
    pitch should not be coarser than the measured step. Before the cubic spline
    is built, NaN samples are bridged linearly; the result is NaN wherever a
    linear interpolation would touch a NaN sample.
    """
    _check_profile(profile, "profile")
    dx = check_positive(dx, name="dx")
    if order not in (1, 3):
        raise ConfigError(f"order must be 1 (linear) or 3 (cubic), got {order!r}")
    start = profile.x0 if x0 is None else check_finite(x0, name="x0")
    if n is None:
        end = profile.x0 + (profile.z.size - 1) * profile.dx
        n = int(math.floor((end - start) / dx + 1e-9)) + 1
    if n < 2:
        raise ConfigError(f"resampled profile would have {n} sample(s); expected >= 2")
    z = profile.z
    xq = start + dx * np.arange(n)
    u = (xq - profile.x0) / profile.dx
    out = np.full(n, np.nan)
    inside = (u >= -1e-9) & (u <= z.size - 1 + 1e-9)
    ui = np.clip(u[inside], 0.0, z.size - 1)
    k = np.minimum(np.floor(ui).astype(np.int64), z.size - 2)
    f = ui - k
    on0 = np.isclose(f, 0.0, atol=1e-9)  # on sample k: only it matters
    on1 = np.isclose(f, 1.0, atol=1e-9)  # on sample k + 1
    valid = np.where(on0, np.isfinite(z[k]), np.where(
        on1, np.isfinite(z[k + 1]), np.isfinite(z[k]) & np.isfinite(z[k + 1])))
    ok = np.isfinite(z)
    if ok.sum() >= 2:
        idx = np.arange(z.size)
        filled = np.where(ok, z, np.interp(idx, idx[ok], z[ok]))
    else:
        filled = np.where(ok, z, 0.0)
    if order == 1:
        vals = (1.0 - f) * filled[k] + f * filled[k + 1]
    else:
        vals = ndi.map_coordinates(filled, [ui], order=3, mode="mirror",
                                   prefilter=True)
    vals = np.where(on0, filled[k], np.where(on1, filled[k + 1], vals))
    vals[~valid] = np.nan
    out[inside] = vals
    return Profile(out, dx, metadata=dict(profile.metadata), x0=start)


@dataclass(frozen=True)
class ProfileRegistration:
    """Result of :func:`register_profiles`.

    Attributes
    ----------
    shift : float
        Translation in m: ``x_ref = sign * x_moving + shift``.
    mirrored : bool
        True when the moving profile was mirrored (``sign = -1``).
    correlation : float
        Normalised cross-correlation (Pearson coefficient over the overlap) at the
        chosen shift (-1 .. 1), interpolated at the fractional lag like the shift.
    overlap : float
        Length of the overlap at that shift, in m.
    correlation_other : float or None
        Best correlation of the other orientation (None when it was not tried).
    """

    shift: float
    mirrored: bool
    correlation: float
    overlap: float
    correlation_other: float | None

    @property
    def sign(self) -> int:
        """-1 when mirrored, else +1."""
        return -1 if self.mirrored else 1

    def to_moving(self, x_ref: np.ndarray) -> np.ndarray:
        """Positions in the moving profile's frame (m) of reference positions (m)."""
        return self.sign * (np.asarray(x_ref, dtype=float) - self.shift)


def _masked_ncc(f: np.ndarray, g: np.ndarray, min_count: int) -> tuple[np.ndarray,
                                                                        np.ndarray]:
    """Pearson correlation of ``f[i]`` with ``g[i - lag]`` for every lag.

    Returns ``(ncc, count)`` indexed like ``scipy.signal.correlate(f, g, "full")``:
    entry ``j`` is lag ``j - (g.size - 1)``. NaN samples are excluded (masked
    normalised cross-correlation); lags with fewer than ``min_count`` common valid
    samples or no variance get NaN.
    """
    mf, mg = np.isfinite(f), np.isfinite(g)
    f0, g0 = np.where(mf, f, 0.0), np.where(mg, g, 0.0)
    # centre for numerical accuracy of the sums
    f0 = np.where(mf, f0 - f0[mf].mean(), 0.0)
    g0 = np.where(mg, g0 - g0[mg].mean(), 0.0)
    wf, wg = mf.astype(float), mg.astype(float)

    def corr(a, b):
        return scipy.signal.correlate(a, b, mode="full", method="fft")

    n = np.rint(corr(wf, wg))
    sf = corr(f0, wg)
    sg = corr(wf, g0)
    sff = corr(f0 * f0, wg)
    sgg = corr(wf, g0 * g0)
    sfg = corr(f0, g0)
    ncc = np.full(n.shape, np.nan)
    ok = n >= max(min_count, 3)
    nn = n[ok]
    cov = sfg[ok] - sf[ok] * sg[ok] / nn
    vf = sff[ok] - sf[ok] ** 2 / nn
    vg = sgg[ok] - sg[ok] ** 2 / nn
    scale = max(float(np.sum(f0 * f0)), float(np.sum(g0 * g0)), 1e-300)
    good = (vf > 1e-12 * scale) & (vg > 1e-12 * scale)
    vals = np.full(nn.shape, np.nan)
    vals[good] = cov[good] / np.sqrt(vf[good] * vg[good])
    ncc[ok] = np.clip(vals, -1.0, 1.0)
    return ncc, n


def _best_lag(ncc: np.ndarray, lags: np.ndarray, allowed: np.ndarray) -> tuple[float,
                                                                              float,
                                                                              int]:
    """(fractional lag, peak value, index) of the highest allowed NCC value."""
    vals = np.where(allowed & np.isfinite(ncc), ncc, -np.inf)
    j = int(np.argmax(vals))
    if not np.isfinite(vals[j]):
        return math.nan, math.nan, -1
    frac, peak = 0.0, float(vals[j])
    if 0 < j < vals.size - 1 and np.isfinite(vals[j - 1]) and np.isfinite(vals[j + 1]):
        a, b, c = vals[j - 1], vals[j], vals[j + 1]
        den = a - 2.0 * b + c
        if den < 0:  # the parabola's vertex: fractional lag and its value
            frac = float(np.clip(0.5 * (a - c) / den, -0.5, 0.5))
            peak = float(min(b - 0.125 * (a - c) ** 2 / den, 1.0))
    return float(lags[j] + frac), peak, j


def register_profiles(
    reference: Profile,
    moving: Profile,
    *,
    mirror: bool | Literal["auto"] = "auto",
    max_shift: float | None = None,
    min_overlap: float = MIN_OVERLAP,
    shift_range: tuple[float, float] | None = None,
) -> ProfileRegistration:
    """Find the translation (and optional mirror) that best aligns two profiles.

    Parameters
    ----------
    reference : Profile
        Profile that stays in place (heights in m, NaN invalid).
    moving : Profile
        Profile to align onto ``reference``; it is resampled to the reference's
        step (cubic B-spline) before the search.
    mirror : bool or "auto", default: "auto"
        ``False``: translation only; ``True``: mirror the moving profile
        (``x -> -x``) first; ``"auto"``: try both and keep the orientation with the
        higher correlation.
    max_shift : float, optional
        Largest ``|shift - shift0|`` searched, in m, where ``shift0`` is the shift
        that puts the two profiles' centres on each other (default: every shift
        with enough overlap).
    min_overlap : float, default: 0.9
        Smallest overlap accepted, as a fraction (0 .. 1] of the shorter profile's
        length.
    shift_range : (float, float), optional
        Only shifts ``lo <= shift <= hi`` are searched, in m (for example a
        window around a shift found before); combined with ``max_shift`` when
        both are given.

    Returns
    -------
    ProfileRegistration
        Shift in m, mirror flag, peak correlation and overlap length in m.

    Raises
    ------
    ConfigError
        On bad arguments, or when no shift leaves enough overlap with variance.

    Notes
    -----
    Masked normalised cross-correlation (Padfield, IEEE TIP 21 (2012) 2706,
    reduced to 1-D): for every integer lag the Pearson coefficient of the
    overlapping valid samples, computed with FFT correlations of the heights,
    their squares and the validity masks; the peak is refined to a fraction of a
    step by a parabola through the peak and its two neighbours. Pass profiles
    without form (roughness profiles) so that the correlation is driven by the
    texture rather than by a tilt or curvature.
    """
    ref = _check_profile(reference, "reference")
    mov = _check_profile(moving, "moving")
    if mirror not in (True, False, "auto"):
        raise ConfigError(f"mirror must be True, False or 'auto', got {mirror!r}")
    if not 0.0 < float(min_overlap) <= 1.0:
        raise ConfigError(f"min_overlap must be in (0, 1], got {min_overlap!r}")
    if max_shift is not None:
        max_shift = check_positive(max_shift, name="max_shift")
    if shift_range is not None:
        if len(shift_range) != 2:
            raise ConfigError(
                f"shift_range must be (lo, hi) in m, got {shift_range!r}")
        lo_s = check_finite(shift_range[0], name="shift_range lower bound")
        hi_s = check_finite(shift_range[1], name="shift_range upper bound")
        if not lo_s <= hi_s:
            raise ConfigError(
                f"shift_range must have lo <= hi, got [{lo_s:g}, {hi_s:g}] m")
    dx = ref.dx
    f = ref.z
    orientations = [False, True] if mirror == "auto" else [bool(mirror)]
    results = []
    for mirrored in orientations:
        src = mov
        if mirrored:
            src = Profile(
                mov.z[::-1].copy(),
                mov.dx,
                x0=-(mov.x0 + (mov.z.size - 1) * mov.dx),
            )
        if not math.isclose(src.dx, dx, rel_tol=1e-9):
            src = resample_profile(src, dx)
        g = src.z
        n_short = min(int(np.isfinite(f).sum()), int(np.isfinite(g).sum()))
        min_count = max(3, int(math.ceil(min_overlap * n_short)))
        ncc, count = _masked_ncc(f, g, min_count)
        lags = np.arange(ncc.size) - (g.size - 1)
        # shift for lag k: x_f[i] = x_g[i - k]  ->  shift = x0_f - x0_g + k dx
        base = ref.x0 - src.x0
        allowed = np.ones(ncc.size, dtype=bool)
        if max_shift is not None:
            centre = (ref.x0 + 0.5 * (f.size - 1) * dx) - (
                src.x0 + 0.5 * (g.size - 1) * dx
            )
            allowed = np.abs(base + lags * dx - centre) <= max_shift + 1e-12 * dx
        if shift_range is not None:
            sh = base + lags * dx
            allowed &= (sh >= lo_s - 1e-9 * dx) & (sh <= hi_s + 1e-9 * dx)
        lag, peak, j = _best_lag(ncc, lags, allowed)
        overlap = float(count[j] * dx) if j >= 0 else 0.0
        results.append((peak, base + lag * dx, mirrored, overlap))
    found = [r for r in results if math.isfinite(r[0])]
    if not found:
        raise ConfigError(
            "the profiles cannot be registered: no shift leaves an overlap of at "
            f"least {min_overlap:.0%} of the shorter profile with height variation; "
            "check the x range, the line through the map and the pitch"
        )
    best = max(found, key=lambda r: r[0])
    other = [r for r in results if r is not best]
    other_corr = None
    if other and math.isfinite(other[0][0]):
        other_corr = float(other[0][0])
    return ProfileRegistration(
        shift=float(best[1]),
        mirrored=bool(best[2]),
        correlation=float(best[0]),
        overlap=float(best[3]),
        correlation_other=other_corr,
    )
