"""ISO 25178-2 areal field parameters: height, hybrid, spatial and material ratio.

One function, :func:`areal_parameters`, computes the parameters users expect beside
Sa and Sq, on one explicitly prepared surface (see its Notes for every definition
choice). :func:`areal_autocorrelation` exposes the void-aware autocorrelation
function that Sal and Str are read from.
"""

from __future__ import annotations

import math
from typing import Any, Literal

import numpy as np

from .._validation import check_positive
from ..errors import ConfigError
from ._filters import gaussian_filter_2d
from ._surface import Surface

__all__ = [
    "ACF_THRESHOLD",
    "EQUIVALENCE_LINE_WIDTH",
    "areal_autocorrelation",
    "areal_parameters",
]

#: ISO 25178-3 default threshold ``s`` of the autocorrelation for Sal and Str
#: (fraction of the zero-lag value).
ACF_THRESHOLD: float = 0.2

#: Width of the central region of the material ratio curve that defines the
#: equivalent straight line (ISO 13565-2, ISO 25178-2), as a fraction.
EQUIVALENCE_LINE_WIDTH: float = 0.4

#: Number of ray directions over 180 degrees searched for the ACF decay (the ACF
#: is point-symmetric): 0.25 degree apart.
_N_RAYS: int = 720

#: Samples per pixel along a ray (bilinear interpolation of the ACF between them).
_RAY_SAMPLES_PER_PIXEL: int = 4

#: Samples evaluated per ray and pass when marching outwards (memory bound).
_RAY_CHUNK: int = 256

#: ACF value given to lags no pair of valid pixels has (above any |ACF|).
_NO_PAIR: float = 10.0

Form = Literal["mean", "plane"]


def _prepare(surface: Surface, form: str, cutoff: float | None) -> np.ndarray:
    """The scale-limited surface (m): F-operation, then the optional L-filter."""
    if not isinstance(surface, Surface):
        raise ConfigError(f"surface must be a Surface, got {type(surface).__name__}")
    if form not in ("mean", "plane"):
        raise ConfigError(
            f"form must be 'mean' (subtract the mean height) or 'plane' (subtract "
            f"the least-squares plane), got {form!r}"
        )
    valid = surface.valid
    if not valid.any():
        raise ConfigError("surface has no valid pixels (all NaN)")
    s = surface.level() if form == "plane" else surface
    z = s.z - np.mean(s.z[valid])
    if cutoff is not None:
        cutoff = check_positive(cutoff, name="cutoff")
        if not surface.calibrated:
            raise ConfigError(
                "cutoff needs a calibrated surface (pixel sizes in m); the map is "
                "uncalibrated"
            )
        mean = gaussian_filter_2d(s.replace(z=z), cutoff).z
        z = z - mean
        if not np.isfinite(z).any():
            raise ConfigError(
                f"no valid pixels left after the L-filter with cutoff {cutoff:g} m"
            )
    return z


def _height(v: np.ndarray) -> dict[str, float]:
    """Height parameters of the valid heights ``v`` (m), measured from 0."""
    v2 = v * v  # products, not v**3 / v**4 (numpy's pow is slow)
    sq = float(np.sqrt(np.mean(v2)))
    return {
        "sa_m": float(np.mean(np.abs(v))),
        "sq_m": sq,
        "sp_m": float(v.max()),
        "sv_m": 0.0 - float(v.min()),  # never -0.0
        "sz_m": float(v.max() - v.min()),
        "ssk": float(np.mean(v2 * v) / sq**3) if sq > 0 else math.nan,
        "sku": float(np.mean(v2 * v2) / sq**4) if sq > 0 else math.nan,
    }


def _sdq(z: np.ndarray, dx: float, dy: float) -> float:
    """Root-mean-square gradient from forward differences between valid pixels."""
    gx = np.diff(z, axis=1) / dx
    gy = np.diff(z, axis=0) / dy
    gx, gy = gx[np.isfinite(gx)], gy[np.isfinite(gy)]
    if gx.size == 0 and gy.size == 0:
        return math.nan
    mx = float(np.mean(gx**2)) if gx.size else 0.0
    my = float(np.mean(gy**2)) if gy.size else 0.0
    return math.sqrt(mx + my)


def _sdr(z: np.ndarray, dx: float, dy: float) -> float:
    """Developed interfacial area ratio (fraction) from the cell triangulation."""
    if min(z.shape) < 2:
        return math.nan
    ex = np.diff(z, axis=1)  # x edges, shape (ny, nx - 1)
    ey = np.diff(z, axis=0)  # y edges, shape (ny - 1, nx)
    bottom, top = ex[:-1], ex[1:]
    left, right = ey[:, :-1], ey[:, 1:]
    flat = (dx * dy) ** 2

    def corner(a: np.ndarray, b: np.ndarray) -> np.ndarray:
        # area of the triangle spanned by the x edge (dx, 0, a), the y edge (0, dy, b)
        return 0.5 * np.sqrt((dy * a) ** 2 + (dx * b) ** 2 + flat)

    cells = 0.5 * (
        corner(bottom, left)
        + corner(bottom, right)
        + corner(top, left)
        + corner(top, right)
    )
    ok = np.isfinite(cells)
    if not ok.any():
        return math.nan
    return float(np.sum(cells[ok]) / (ok.sum() * dx * dy) - 1.0)


def _acf(z: np.ndarray) -> np.ndarray:
    """Void-aware unbiased ACF for lags up to half the map, normalised to 1 at 0.

    Returns an array of shape (2 ly + 1, 2 lx + 1), ``ly = ny // 2``,
    ``lx = nx // 2``, zero lag at its centre; NaN where no pixel pair overlaps.
    """
    import scipy.fft as sfft

    ny, nx = z.shape
    ly, lx = ny // 2, nx // 2
    valid = np.isfinite(z)
    r = np.where(valid, z, 0.0)
    shape = (sfft.next_fast_len(ny + ly, real=True), sfft.next_fast_len(nx + lx))

    def corr(a: np.ndarray) -> np.ndarray:
        f = sfft.rfft2(a, s=shape)
        c = sfft.irfft2(f * np.conj(f), s=shape)
        rows = np.r_[shape[0] - ly : shape[0], 0 : ly + 1]
        cols = np.r_[shape[1] - lx : shape[1], 0 : lx + 1]
        return c[np.ix_(rows, cols)]

    num = corr(r)
    if valid.all():  # pairs at lag (ty, tx): (ny - |ty|) (nx - |tx|)
        count = np.outer(
            ny - np.abs(np.arange(-ly, ly + 1)), nx - np.abs(np.arange(-lx, lx + 1))
        ).astype(np.float64)
    else:
        count = np.rint(corr(valid.astype(np.float64)))
    with np.errstate(invalid="ignore", divide="ignore"):
        acf = np.where(count >= 1, num / count, np.nan)
    return acf / acf[ly, lx]


def areal_autocorrelation(
    surface: Surface,
    *,
    form: Form = "mean",
    cutoff: float | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Return the normalised areal autocorrelation function (ISO 25178-2), void-aware.

    Parameters
    ----------
    surface : Surface
        Height map in m (NaN invalid) with pixel sizes in m.
    form : {"mean", "plane"}, default: "mean"
        F-operation before the ACF, as in :func:`areal_parameters`.
    cutoff : float or None, default: None
        Nesting index of the Gaussian L-filter in m, as in :func:`areal_parameters`.

    Returns
    -------
    acf : ndarray of shape (2 ny // 2 + 1, 2 nx // 2 + 1)
        ``f_ACF(tx, ty)``, 1 at zero lag (the centre); lags up to half the map in
        each direction. NaN where no pair of valid pixels has that lag.
    tx : ndarray of shape (2 nx // 2 + 1,)
        Lags along x (columns), in m.
    ty : ndarray of shape (2 ny // 2 + 1,)
        Lags along y (rows), in m.

    Raises
    ------
    ConfigError
        Uncalibrated, flat or all-invalid surface, bad ``form`` or ``cutoff``.

    Notes
    -----
    ``f_ACF(t) = sum z(p) z(p + t) / N(t)`` over the pairs of valid pixels ``p``,
    ``p + t`` (``N(t)`` of them: the unbiased, non-circular estimator; voids simply
    drop out of the sums), divided by its zero-lag value ``mean z^2``. Computed with
    zero-padded FFTs.
    """
    if not isinstance(surface, Surface) or not surface.calibrated:
        raise ConfigError(
            "areal_autocorrelation needs a calibrated Surface (pixel sizes in m)"
        )
    z = _prepare(surface, form, cutoff)
    if not np.any(z[np.isfinite(z)]):
        raise ConfigError("the surface is flat (Sq = 0): its autocorrelation is 0/0")
    acf = _acf(z)
    ly, lx = (acf.shape[0] - 1) // 2, (acf.shape[1] - 1) // 2
    assert surface.dx is not None and surface.dy is not None
    return acf, surface.dx * np.arange(-lx, lx + 1), surface.dy * np.arange(-ly, ly + 1)


def _decay_lengths(
    acf: np.ndarray, dx: float, dy: float, s: float
) -> tuple[np.ndarray, np.ndarray]:
    """Ray angles (rad) and distance (m) of the first ACF crossing of ``s`` on each.

    NaN where a ray reaches the edge of the lag range without falling to ``s``.
    """
    from scipy.ndimage import map_coordinates

    ly, lx = (acf.shape[0] - 1) // 2, (acf.shape[1] - 1) // 2
    theta = np.arange(_N_RAYS) * (np.pi / _N_RAYS)
    c, sn = np.cos(theta), np.sin(theta)
    # ray length to the edge of the lag rectangle |tx| <= lx dx, |ty| <= ly dy
    with np.errstate(divide="ignore"):
        reach = np.minimum(
            np.where(np.abs(c) > 1e-12, lx * dx / np.abs(c), np.inf),
            np.where(np.abs(sn) > 1e-12, ly * dy / np.abs(sn), np.inf),
        )
    # Lags without any valid pixel pair get a value above any ACF: never a crossing.
    filled = np.where(np.isfinite(acf), acf, _NO_PAIR)
    step = min(dx, dy) / _RAY_SAMPLES_PER_PIXEL
    lengths = np.full(_N_RAYS, np.nan)
    prev = np.ones(_N_RAYS)  # ACF at the previous sample (1 at zero lag)
    todo = np.arange(_N_RAYS)
    k0 = 1
    while todo.size:  # march outwards in chunks, only along rays not yet crossed
        d = step * np.arange(k0, k0 + _RAY_CHUNK)
        rows = ly + d[None, :] * sn[todo, None] / dy
        cols = lx + d[None, :] * c[todo, None] / dx
        vals = map_coordinates(
            filled, [rows.ravel(), cols.ravel()], order=1, cval=_NO_PAIR
        ).reshape(rows.shape)
        inside = d[None, :] <= reach[todo, None] * (1 + 1e-12)
        vals = np.where(inside, vals, _NO_PAIR)
        below = vals <= s
        hit = below.any(axis=1)
        j = np.argmax(below, axis=1)
        for i in np.flatnonzero(hit):
            a = vals[i, j[i] - 1] if j[i] > 0 else prev[todo[i]]
            b = vals[i, j[i]]
            frac = (a - s) / (a - b) if a != b else 1.0
            lengths[todo[i]] = d[j[i]] - step + frac * step
        prev[todo] = vals[:, -1]
        done = hit | ~inside[:, -1]
        todo = todo[~done]
        k0 += _RAY_CHUNK
    return theta, lengths


def _material_ratio(v: np.ndarray) -> dict[str, float]:
    """Sk, Spk, Svk (m) and Smr1, Smr2 (%) from the areal material ratio curve."""
    h = np.sort(v)[::-1]  # heights by decreasing height: the material ratio curve
    n = h.size
    w = int(round(EQUIVALENCE_LINE_WIDTH * n))
    if n < 3 or w < 2:
        nan = math.nan
        return {
            "sk_m": nan,
            "spk_m": nan,
            "svk_m": nan,
            "smr1_percent": nan,
            "smr2_percent": nan,
        }
    mr = (np.arange(n) + 0.5) / n  # material ratio of each sorted point, 0..1
    # Central region: the 40 % window whose secant has the smallest gradient
    # (the first one of equal gradients), then the least-squares line over it.
    drop = h[w:] - h[:-w]  # <= 0; the least steep secant is the largest
    i0 = int(np.argmax(drop))
    sl = slice(i0, i0 + w + 1)
    slope, c1 = np.polyfit(mr[sl], h[sl], 1)
    c2 = c1 + slope  # the line at material ratio 1 (100 %)
    smr1 = float(np.count_nonzero(h >= c1) / n)
    smr2 = float(np.count_nonzero(h >= c2) / n)
    a1 = float(np.sum(h[h > c1] - c1) / n)  # peak area above c1 (m x ratio)
    a2 = float(np.sum(c2 - h[h < c2]) / n)  # dale area below c2
    return {
        "sk_m": float(c1 - c2),
        "spk_m": 2.0 * a1 / smr1 if a1 > 0 and smr1 > 0 else 0.0,
        "svk_m": 2.0 * a2 / (1.0 - smr2) if a2 > 0 and smr2 < 1 else 0.0,
        "smr1_percent": 100.0 * smr1,
        "smr2_percent": 100.0 * smr2,
    }


def areal_parameters(
    surface: Surface,
    *,
    form: Form = "mean",
    cutoff: float | None = None,
    acf_threshold: float = ACF_THRESHOLD,
) -> dict[str, Any]:
    """Return the ISO 25178-2 areal field parameters of a height map.

    Parameters
    ----------
    surface : Surface
        Height map in m; NaN marks invalid pixels (voids), which every parameter
        leaves out (see Notes).
    form : {"mean", "plane"}, default: "mean"
        F-operation: subtract the mean height only (no levelling, as ``info``
        reports Sa and Sq), or the least-squares plane (levelling).
    cutoff : float or None, default: None
        Nesting index ``lambda_c`` of the ISO 16610-61 Gaussian L-filter, in m:
        the parameters are then those of the S-L surface ``z - gaussian_mean(z)``.
        ``None``: no L-filter.
    acf_threshold : float, default: 0.2
        Threshold ``s`` of the autocorrelation for Sal and Str (ISO 25178-3
        default 0.2), in (0, 1).

    Returns
    -------
    dict
        Height: ``sa_m``, ``sq_m``, ``sp_m``, ``sv_m``, ``sz_m`` (m), ``ssk``,
        ``sku``. Hybrid: ``sdq`` (root-mean-square gradient, m/m), ``sdr_percent``
        (developed interfacial area ratio, %). Spatial: ``sal_m`` (autocorrelation
        length, m), ``str`` (texture aspect ratio). Material ratio: ``sk_m``,
        ``spk_m``, ``svk_m`` (core height, reduced peak height, reduced dale height,
        m), ``smr1_percent``, ``smr2_percent`` (material ratios bounding the core,
        %). Conventions: ``form``, ``cutoff_m`` (m or None), ``acf_threshold``,
        ``n_valid``. Undefined values are NaN: hybrid and spatial parameters of an
        uncalibrated map; Sal when the ACF does not fall to ``s`` within half the
        map in any direction; Str when it does not in every direction.

    Raises
    ------
    ConfigError
        If ``surface`` is not a Surface or has no valid pixel, ``form`` is unknown,
        ``cutoff`` is not positive (or given for an uncalibrated map), or
        ``acf_threshold`` is outside (0, 1).

    See Also
    --------
    areal_roughness, areal_autocorrelation, gaussian_filter_2d

    Notes
    -----
    Definitions (ISO 25178-2:2012; ISO 25178-3 defaults; ISO 13565-2 for the
    material ratio construction), with the discretisation chosen here:

    * Surface evaluated: the map as given, no S-filter; F-operation ``form``;
      optional L-filter ``cutoff``. Heights ``z`` are measured from the reference
      surface: the mean plane (``form``) or the Gaussian mean surface (``cutoff``).
    * Height: over the ``n_valid`` valid pixels, ``Sa = mean |z|``, ``Sq =
      sqrt(mean z^2)``, ``Sp = max z``, ``Sv = -min z``, ``Sz = Sp + Sv``,
      ``Ssk = mean z^3 / Sq^3``, ``Sku = mean z^4 / Sq^4``.
    * Sdq: ``sqrt(<(dz/dx)^2> + <(dz/dy)^2>)`` with forward differences between
      neighbouring valid pixels, each direction averaged over its own differences.
    * Sdr: ``A_developed / A_projected - 1`` in %, over grid cells whose four
      corners are valid; a cell's area is the mean of its two triangulations (along
      either diagonal), the projected area ``dx dy`` per cell.
    * Sal, Str: from :func:`areal_autocorrelation` (unbiased, void-aware, lags up to
      half the map). Along 720 rays from the origin (0.25 degree apart over 180
      degrees; the ACF is point-symmetric), the first lag where the ACF falls to
      ``s`` is found by bilinear interpolation sampled 4 times per pixel and linear
      interpolation between samples. ``Sal`` is the shortest of these distances
      (the nearest lag with ``f_ACF <= s``); ``Str`` is ``Sal`` divided by the
      longest (the farthest edge of the central lobe above ``s``), and is NaN
      when some ray leaves the lag range without falling to ``s``.
    * Material ratio: the curve is the valid heights sorted by decreasing height,
      point ``i`` at material ratio ``(i + 1/2) / n``. The central region is the
      window of 40 % of the points whose secant has the smallest gradient (first
      of equal ones); the equivalent straight line is the least-squares line
      through the curve points of that window. Its heights at 0 % and 100 % are
      ``c1``, ``c2``; ``Sk = c1 - c2``; ``Smr1``, ``Smr2`` are the fractions of
      valid pixels at or above ``c1``, ``c2``; ``Spk = 2 A1 / Smr1`` and ``Svk =
      2 A2 / (1 - Smr2)`` with ``A1 = sum(z - c1 for z > c1) / n`` and ``A2 =
      sum(c2 - z for z < c2) / n`` (the areas of the peak and dale zones of the
      curve); Spk (Svk) is 0 when no point lies above ``c1`` (below ``c2``).

    Examples
    --------
    >>> import numpy as np
    >>> from servosurf.metrology import Surface, areal_parameters
    >>> x = np.arange(256) * 1e-6
    >>> z = 1e-8 * np.ones((64, 1)) * x / 1e-6  # a plane tilted 10 nm per um
    >>> p = areal_parameters(Surface(z, 1e-6, 1e-6))
    >>> round(p["sdq"], 6)  # the slope of the plane
    0.01
    """
    s = float(acf_threshold)
    if not 0.0 < s < 1.0:
        raise ConfigError(
            f"acf_threshold must lie in (0, 1) (ISO 25178-3 default 0.2), got {s!r}"
        )
    z = _prepare(surface, form, cutoff)
    v = z[np.isfinite(z)]
    out: dict[str, Any] = _height(v)
    if surface.calibrated:
        assert surface.dx is not None and surface.dy is not None
        dx, dy = surface.dx, surface.dy
        out["sdq"] = _sdq(z, dx, dy)
        sdr = _sdr(z, dx, dy)
        out["sdr_percent"] = 100.0 * sdr if math.isfinite(sdr) else math.nan
        if min(z.shape) >= 2 and out["sq_m"] > 0:
            _, lengths = _decay_lengths(_acf(z), dx, dy, s)
            crossed = np.isfinite(lengths)
            sal = float(lengths[crossed].min()) if crossed.any() else math.nan
            out["sal_m"] = sal
            out["str"] = sal / float(lengths.max()) if crossed.all() else math.nan
        else:
            out["sal_m"] = out["str"] = math.nan
    else:
        out.update(sdq=math.nan, sdr_percent=math.nan, sal_m=math.nan, str=math.nan)
    out.update(_material_ratio(v))
    out.update(
        form=form,
        cutoff_m=None if cutoff is None else float(cutoff),
        acf_threshold=s,
        n_valid=int(v.size),
    )
    return out
