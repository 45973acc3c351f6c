"""Profile (ISO 4287 / ISO 4288) and areal (ISO 25178-2) roughness parameters."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from .._validation import check_positive
from ..errors import ConfigError
from ._filters import gaussian_filter_1d, gaussian_filter_2d
from ._surface import Profile, Surface

__all__ = [
    "ISO4288_CUTOFFS",
    "iso4288_cutoff",
    "profile_roughness",
    "areal_roughness",
]

#: The standard cut-off wavelengths (sampling lengths) of ISO 4288, in m.
ISO4288_CUTOFFS: tuple[float, ...] = (0.08e-3, 0.25e-3, 0.8e-3, 2.5e-3, 8e-3)

#: ISO 4288:1996 Table 1: upper Ra limit (m) of the range served by each cut-off
#: (non-periodic profiles). Ra <= 0.02 um -> 0.08 mm, <= 0.1 um -> 0.25 mm, ...
_RA_UPPER: tuple[float, ...] = (0.02e-6, 0.1e-6, 2e-6, 10e-6)

#: ISO 4288:1996 Table 3: upper RSm limit (m) per cut-off (periodic profiles).
_RSM_UPPER: tuple[float, ...] = (0.04e-3, 0.13e-3, 0.4e-3, 1.3e-3)

#: Number of sampling lengths of the default evaluation length (ISO 4288).
N_SAMPLING_LENGTHS: int = 5

#: Height discrimination of a profile element for RSm, as a fraction of Rz
#: (ISO 4287:1997, 3.1.9 and 4.3.1 via ISO 4288 defaults).
RSM_HEIGHT_DISCRIMINATION: float = 0.1

#: Maximum number of passes of the ISO 4288 cut-off procedure.
_MAX_PASSES: int = 10


def _table_cutoff(value: float, uppers: tuple[float, ...]) -> float:
    for upper, lc in zip(uppers, ISO4288_CUTOFFS, strict=False):
        if value <= upper:
            return lc
    return ISO4288_CUTOFFS[-1]


def _roughness_profile(
    profile: Profile, cutoff: float, trim_ends: bool, trim_length: float | None
) -> tuple[np.ndarray, np.ndarray]:
    """Roughness profile (z - mean line) and the evaluation mask."""
    mean = gaussian_filter_1d(
        profile.z, profile.dx, cutoff, trim_ends=trim_ends, trim_length=trim_length
    )
    r = profile.z - mean
    ok = np.isfinite(r)
    if not ok.any():
        raise ConfigError(
            f"profile of length {profile.z.size * profile.dx:g} m leaves no valid "
            f"samples after filtering with cutoff {cutoff:g} m and trimming the ends; "
            "use a shorter cut-off (--cutoff), a longer profile, or keep the ends "
            "(--keep-ends)"
        )
    return r, ok


def _rsm(r: np.ndarray, dx: float, rz: float) -> float:
    """Mean width of profile elements (ISO 4287 RSm), height discrimination only."""
    h = RSM_HEIGHT_DISCRIMINATION * rz
    state = 0  # -1 seen a valley below -h, +1 seen a peak above +h
    ups: list[int] = []
    for i, v in enumerate(r):
        if not math.isfinite(v):
            continue
        if v <= -h:
            state = -1
        elif v >= h and state == -1:
            ups.append(i)
            state = 1
    if len(ups) < 2:
        return float("nan")
    return float(np.mean(np.diff(ups)) * dx)


def _evaluate(r: np.ndarray, ok: np.ndarray, dx: float, cutoff: float) -> dict:
    lo, hi = np.flatnonzero(ok)[[0, -1]]
    seg = r[lo : hi + 1]
    v = seg[np.isfinite(seg)]
    ra = float(np.mean(np.abs(v)))
    rq = float(np.sqrt(np.mean(v**2)))
    rp, rv = float(v.max()), float(-v.min())
    m = max(1, round(cutoff / dx))
    n_eval = seg.size
    if n_eval >= N_SAMPLING_LENGTHS * m:
        start = (n_eval - N_SAMPLING_LENGTHS * m) // 2
        pv = []
        for k in range(N_SAMPLING_LENGTHS):
            part = seg[start + k * m : start + (k + 1) * m]
            part = part[np.isfinite(part)]
            if part.size:
                pv.append(part.max() - part.min())
        rz, n_rz = float(np.mean(pv)), len(pv)
    else:
        rz, n_rz = rp + rv, 1
    rsk = float(np.mean(v**3) / rq**3) if rq > 0 else float("nan")
    rku = float(np.mean(v**4) / rq**4) if rq > 0 else float("nan")
    return {
        "ra_m": ra,
        "rq_m": rq,
        "rz_m": rz,
        "rt_m": rp + rv,
        "rp_m": rp,
        "rv_m": rv,
        "rsk": rsk,
        "rku": rku,
        "rsm_m": _rsm(seg, dx, rz),
        "rz_sampling_lengths": n_rz,
        "evaluation_length_m": float(n_eval * dx),
    }


def iso4288_cutoff(
    profile: Profile,
    *,
    periodic: bool = False,
    trim_ends: bool = True,
    trim_length: float | None = None,
) -> float:
    """Choose the roughness cut-off wavelength by the ISO 4288 procedure.

    Parameters
    ----------
    profile : Profile
        Primary profile, heights in m.
    periodic : bool, default: False
        Use the RSm table (periodic profiles, ISO 4288 Table 3) instead of the Ra
        table (non-periodic profiles, Table 1).
    trim_ends, trim_length : bool, float or None
        End handling used for the trial measurements, as in
        :func:`profile_roughness`.

    Returns
    -------
    float
        The cut-off wavelength ``lambda_c`` (= sampling length), in m: one of
        :data:`ISO4288_CUTOFFS`.

    Raises
    ------
    ConfigError
        If the profile is shorter than twice the smallest standard cut-off
        (0.16 mm), so that no standard cut-off leaves an evaluation length.

    Notes
    -----
    ISO 4288:1996 clause 7. Only cut-offs ``lambda_c <= L / 2`` (``L`` the
    profile length) are admissible, so that at least one sampling length remains
    after the ``lambda_c / 2`` run-up and run-out. The procedure:

    1. Trial cut-off: 0.8 mm (the usual default), or the largest admissible one.
    2. Measure Ra (non-periodic) or RSm (periodic) with the trial cut-off.
    3. Look up the cut-off for that value: Ra in (0.006, 0.02], (0.02, 0.1],
       (0.1, 2], (2, 10], (10, 80] um gives 0.08, 0.25, 0.8, 2.5, 8 mm; RSm in
       (0.013, 0.04], (0.04, 0.13], (0.13, 0.4], (0.4, 1.3], (1.3, 4] mm gives the
       same cut-offs. Values below (above) the table give the smallest (largest)
       cut-off; a cut-off longer than admissible is reduced to the largest
       admissible one.
    4. If the looked-up cut-off differs from the one used, repeat from 2 with it;
       stop when they agree. If the procedure revisits a cut-off (the measured
       value jumps between two ranges), the shorter of the two is taken, as ISO
       4288 favours the shorter sampling length when in doubt.

    RSm is computed with a height discrimination of 10 % of Rz (ISO 4287); the
    1 % width discrimination is not applied.
    """
    if not isinstance(profile, Profile):
        raise ConfigError(f"profile must be a Profile, got {type(profile).__name__}")
    valid = np.isfinite(profile.z)
    if not valid.any():
        raise ConfigError("profile has no valid samples (all NaN)")
    idx = np.flatnonzero(valid)
    length = (idx[-1] - idx[0] + 1) * profile.dx
    allowed = [lc for lc in ISO4288_CUTOFFS if lc <= length / 2.0]
    if not allowed:
        raise ConfigError(
            f"profile length {length:g} m is shorter than twice the smallest ISO 4288 "
            f"cut-off ({2 * ISO4288_CUTOFFS[0]:g} m); give the cut-off (--cutoff)"
        )
    lc = 0.8e-3 if 0.8e-3 in allowed else allowed[-1]
    seen: list[float] = []
    for _ in range(_MAX_PASSES):
        seen.append(lc)
        r, ok = _roughness_profile(profile, lc, trim_ends, trim_length)
        res = _evaluate(r, ok, profile.dx, lc)
        if periodic:
            value = res["rsm_m"]
            if not math.isfinite(value):
                raise ConfigError(
                    "cannot choose the ISO 4288 cut-off from RSm (fewer than two "
                    "profile elements); give the cut-off (--cutoff)"
                )
            new = _table_cutoff(value, _RSM_UPPER)
        else:
            new = _table_cutoff(res["ra_m"], _RA_UPPER)
        new = min(new, allowed[-1])
        if new == lc:
            return lc
        if new in seen:
            return min(new, lc)
        lc = new
    return lc  # pragma: no cover - the table has five entries, passes cannot loop


def profile_roughness(
    profile: Profile,
    *,
    cutoff: float | None = None,
    trim_ends: bool = True,
    trim_length: float | None = None,
    periodic: bool = False,
) -> dict[str, Any]:
    """Return ISO 4287 roughness parameters of a profile after a Gaussian filter.

    Parameters
    ----------
    profile : Profile
        Primary profile: heights in m at step ``dx`` (m); NaN marks invalid samples.
    cutoff : float or None, default: None
        Cut-off wavelength ``lambda_c`` of the ISO 16610-21 Gaussian filter, in m.
        ``None`` chooses it by the ISO 4288 procedure (:func:`iso4288_cutoff`).
    trim_ends : bool, default: True
        Exclude ``trim_length`` at each end (run-up and run-out) from the
        evaluation length. When False, the whole profile is evaluated with the
        renormalised-kernel end correction.
    trim_length : float or None, default: None
        Length excluded at each end, in m; ``None`` means one whole ``lambda_c``:
        the region where the Gaussian kernel, truncated at +-lambda_c, does not fit
        inside the profile. This is the convention of the independent reference
        readers (the NexView profile in ``shared/data/zygo`` gives Ra 13.19 nm at
        lambda_c = 80 um with it, 14.02 nm with ``lambda_c / 2`` and 14.58 nm with
        the ends kept); pass ``cutoff / 2`` for the ISO 4288 run-up only.
    periodic : bool, default: False
        Only with ``cutoff=None``: choose the cut-off from RSm (periodic profile)
        rather than from Ra.

    Returns
    -------
    dict
        ``ra_m``, ``rq_m`` (m): arithmetic and root-mean-square deviation;
        ``rz_m`` (m): maximum height (see Notes); ``rt_m``, ``rp_m``, ``rv_m`` (m):
        total height, maximum peak height and maximum valley depth over the
        evaluation length; ``rsk``, ``rku``: skewness and kurtosis; ``rsm_m`` (m):
        mean width of profile elements (NaN if fewer than two);
        ``rz_sampling_lengths``: number of sampling lengths averaged for Rz;
        ``evaluation_length_m`` (m); ``cutoff_m`` (m); ``cutoff_rule``: ``"given"``
        or ``"ISO 4288"``; ``ends_trimmed`` (bool); ``trim_length_m`` (m, 0 when
        not trimmed).

    Raises
    ------
    ConfigError
        If ``profile`` is not a :class:`Profile`, ``cutoff`` is not positive, or
        nothing is left to evaluate.

    See Also
    --------
    iso4288_cutoff, gaussian_filter_1d, areal_roughness

    Notes
    -----
    Roughness profile: ``r = z - w`` with ``w`` the ISO 16610-21 Gaussian mean line
    (:func:`gaussian_filter_1d`); no short-wavelength (``lambda_s``) filter is
    applied. Parameters follow ISO 4287:1997 over the valid samples of the
    evaluation length (the mean line is the reference, no further mean removal):
    ``Ra = mean |r|``, ``Rq = sqrt(mean r^2)``, ``Rsk = mean r^3 / Rq^3``,
    ``Rku = mean r^4 / Rq^4``.

    Rz: ISO 4287 defines ``Rz = Rp + Rv`` over one sampling length ``lr =
    lambda_c``, and ISO 4288 reports the mean over five sampling lengths. When the
    evaluation length holds at least five sampling lengths, Rz is the mean of the
    peak-to-valley heights of five consecutive sampling lengths centred in the
    evaluation length; otherwise Rz is the peak-to-valley height over the whole
    evaluation length (then equal to Rt), and ``rz_sampling_lengths`` is 1.

    Examples
    --------
    >>> import numpy as np
    >>> from servosurf.metrology import Profile, profile_roughness
    >>> x = np.arange(4000) * 0.25e-6
    >>> p = Profile(10e-9 * np.sin(2 * np.pi * x / 5e-6), 0.25e-6)
    >>> res = profile_roughness(p, cutoff=80e-6)
    >>> round(res["rq_m"] / 10e-9 * 2**0.5, 4)  # Rq of a sine: a / sqrt(2)
    1.0
    """
    if not isinstance(profile, Profile):
        raise ConfigError(f"profile must be a Profile, got {type(profile).__name__}")
    if cutoff is None:
        cutoff = iso4288_cutoff(
            profile, periodic=periodic, trim_ends=trim_ends, trim_length=trim_length
        )
        rule = "ISO 4288"
    else:
        cutoff = check_positive(cutoff, name="cutoff")
        rule = "given"
    if trim_length is None:
        trim_length = cutoff
    r, ok = _roughness_profile(profile, cutoff, trim_ends, trim_length)
    out = _evaluate(r, ok, profile.dx, cutoff)
    out.update(
        cutoff_m=float(cutoff),
        cutoff_rule=rule,
        ends_trimmed=bool(trim_ends),
        trim_length_m=float(trim_length) if trim_ends else 0.0,
    )
    return out


def areal_roughness(
    surface: Surface,
    *,
    cutoff: float | None = None,
    trim_ends: bool = False,
) -> dict[str, Any]:
    """Return ISO 25178-2 areal height parameters (NaN-aware).

    Parameters
    ----------
    surface : Surface
        Height map in m; NaN marks invalid pixels.
    cutoff : float or None, default: None
        Nesting index of the ISO 16610-61 Gaussian L-filter, in m: the parameters
        are computed on ``z - gaussian_mean(z)`` (S-L surface). ``None``: no filter,
        only the mean height over valid pixels is removed.
    trim_ends : bool, default: False
        With a cut-off, exclude the border of width ``cutoff / 2``.

    Returns
    -------
    dict
        ``sa_m``, ``sq_m`` (m): arithmetic and root-mean-square height;
        ``sp_m``, ``sv_m`` (m): maximum peak height and maximum pit depth;
        ``sz_m`` (m): ``Sp + Sv``; ``ssk``, ``sku``: skewness and kurtosis;
        ``cutoff_m`` (m or None); ``n_valid``: number of pixels evaluated.

    Raises
    ------
    ConfigError
        If no valid pixel is left, or a cut-off is given for an uncalibrated map.

    See Also
    --------
    gaussian_filter_2d, profile_roughness, areal_parameters

    Notes
    -----
    ISO 25178-2:2012 field parameters over the valid pixels of the evaluation
    area: ``Sa = mean |z|``, ``Sq = sqrt(mean z^2)``, ``Ssk = mean z^3 / Sq^3``,
    ``Sku = mean z^4 / Sq^4``, ``Sz = Sp + Sv`` (maximum height: highest peak plus
    deepest pit, not the ten-point height of the withdrawn ISO 4287 areal variant).
    With a cut-off the reference is the Gaussian mean surface (ISO 25178-3).
    """
    if not isinstance(surface, Surface):
        raise ConfigError(f"surface must be a Surface, got {type(surface).__name__}")
    if cutoff is None:
        v = surface._valid_values()
        r = v - v.mean()
    else:
        cutoff = check_positive(cutoff, name="cutoff")
        mean = gaussian_filter_2d(surface, cutoff, trim_ends=trim_ends)
        rr = surface.z - mean.z
        r = rr[np.isfinite(rr)]
        if r.size == 0:
            raise ConfigError(
                f"no valid pixels left after filtering with cutoff {cutoff:g} m"
            )
    from ._areal import _height  # the one implementation of the height family

    return {
        **_height(r),
        "cutoff_m": None if cutoff is None else float(cutoff),
        "n_valid": int(r.size),
    }
