"""Lenslet segmentation and sub-pixel location of lenslet centres (deepest points)."""

from __future__ import annotations

from typing import Any

import numpy as np
import scipy.ndimage as ndi

from .._validation import check_positive
from ..errors import ConfigError
from ._surface import Surface

__all__ = ["find_deepest_point", "segment_lenslets"]

#: Half-size, in pixels, of the window of the paraboloid fit around a minimum.
FIT_HALF_WINDOW: int = 8

#: Passes of the paraboloid fit, each re-centring the window on the last estimate.
_FIT_PASSES: int = 3

#: Percentile of the valid heights taken as the uncut top surface.
TOP_PERCENTILE: float = 99.0

#: Default depth threshold as a fraction of the (top - deepest) height range.
DEPTH_FRACTION: float = 0.1

#: Regions with fewer pixels are ignored by segment_lenslets (noise specks).
MIN_AREA_PIXELS: int = 9


def _nan_smooth(z: np.ndarray, sigma: float) -> np.ndarray:
    """Gaussian smoothing (in pixels) that ignores NaN pixels."""
    valid = np.isfinite(z)
    num = ndi.gaussian_filter(np.where(valid, z, 0.0), sigma, mode="constant")
    den = ndi.gaussian_filter(valid.astype(float), sigma, mode="constant")
    out = np.full(z.shape, np.nan)
    ok = valid & (den > 1e-6)
    out[ok] = num[ok] / den[ok]
    return out


def _paraboloid_step(
    z: np.ndarray, i0: int, j0: int, half: int
) -> tuple[float, float] | None:
    """One least-squares paraboloid fit in the window centred on (i0, j0)."""
    ny, nx = z.shape
    i_lo, i_hi = max(0, i0 - half), min(ny, i0 + half + 1)
    j_lo, j_hi = max(0, j0 - half), min(nx, j0 + half + 1)
    win = z[i_lo:i_hi, j_lo:j_hi]
    ii, jj = np.mgrid[i_lo:i_hi, j_lo:j_hi]
    m = np.isfinite(win)
    if m.sum() < 6:
        return None
    u = (jj[m] - j0).astype(float)
    v = (ii[m] - i0).astype(float)
    a = np.column_stack([np.ones_like(u), u, v, u * u, u * v, v * v])
    c, *_ = np.linalg.lstsq(a, win[m], rcond=None)
    # gradient zero: [2 c3, c4; c4, 2 c5] [u, v] = -[c1, c2]
    h = np.array([[2 * c[3], c[4]], [c[4], 2 * c[5]]])
    if np.linalg.det(h) <= 0 or h[0, 0] <= 0:
        return None
    du, dv = np.linalg.solve(h, -c[1:3])
    if abs(du) > half or abs(dv) > half:
        return None
    return float(i0 + dv), float(j0 + du)


def _subpixel_minimum(
    z: np.ndarray, i0: int, j0: int, half: int = FIT_HALF_WINDOW
) -> tuple[float, float]:
    """Refine a minimum at (i0, j0) by least-squares paraboloid fits.

    The window is re-centred on the rounded estimate and the fit repeated, so a
    first pixel off by a few pixels (flat, noisy bottom) does not bias the result.
    Returns fractional (row, column) indices; falls back to the integer position
    when no fit gives a proper minimum inside its window.
    """
    best = (float(i0), float(j0))
    ci, cj = i0, j0
    for _ in range(_FIT_PASSES):
        step = _paraboloid_step(z, ci, cj, half)
        if step is None:
            break
        best = step
        ni, nj = round(step[0]), round(step[1])
        if (ni, nj) == (ci, cj):
            break
        ci = min(max(ni, 0), z.shape[0] - 1)
        cj = min(max(nj, 0), z.shape[1] - 1)
    return best


def find_deepest_point(
    surface: Surface, *, smooth: float = 1.0, window: int = FIT_HALF_WINDOW
) -> tuple[float, float]:
    """Return the sub-pixel (row, column) index of the deepest point of a map.

    Parameters
    ----------
    surface : Surface
        Height map in m; NaN pixels are ignored.
    smooth : float, default: 1.0
        Standard deviation, in pixels, of the NaN-aware Gaussian smoothing used to
        pick the deepest pixel robustly against noise (0 for none).
    window : int, default: 8
        Half-size, in pixels, of the square window of the paraboloid fit. It should
        stay inside the bowl (below the uncut top) and span a height change well
        above the noise.

    Returns
    -------
    row, col : float
        Fractional pixel indices of the minimum (multiply by ``dy``, ``dx`` and
        add ``y0``, ``x0`` for metres).

    Raises
    ------
    ConfigError
        If the map has no valid pixels.

    Notes
    -----
    The deepest pixel of the smoothed map is refined by a least-squares
    paraboloid fit of the raw heights over a ``(2 window + 1)^2`` window around
    it, re-centred on the estimate and refitted (up to three passes). A lenslet
    bottom is smooth
    (curvature radius about the tool radius), so the paraboloid is a good local
    model; remove any tilt first (:func:`remove_form`) since tilt shifts the
    minimum of a curved bowl.
    """
    if not isinstance(surface, Surface):
        raise ConfigError(f"surface must be a Surface, got {type(surface).__name__}")
    if not surface.valid.any():
        raise ConfigError("surface has no valid pixels (all NaN)")
    if int(window) < 1:
        raise ConfigError(f"window must be >= 1 pixel, got {window!r}")
    zs = _nan_smooth(surface.z, smooth) if smooth > 0 else surface.z
    i0, j0 = np.unravel_index(np.nanargmin(zs), zs.shape)
    return _subpixel_minimum(surface.z, int(i0), int(j0), int(window))


def segment_lenslets(
    surface: Surface,
    *,
    depth_threshold: float | None = None,
    min_area: int = MIN_AREA_PIXELS,
) -> list[dict[str, Any]]:
    """Segment the cut lenslets of a map (regions below the uncut top surface).

    Parameters
    ----------
    surface : Surface
        Height map in m, levelled (remove tilt first), lenslets as depressions.
    depth_threshold : float or None, default: None
        A pixel belongs to a lenslet when it lies more than this depth below the
        top surface, in m. ``None``: 10 % of the map's top-to-deepest range.
    min_area : int, default: 9
        Regions with fewer pixels are ignored.

    Returns
    -------
    list of dict
        One dict per lenslet in reading order (rows of lenslets from the first
        image row down, each from left to right), with
        ``centre_x_m``, ``centre_y_m`` (m): sub-pixel deepest point;
        ``depth_m`` (m): top level minus the deepest height; ``bbox``:
        ``(min_row, min_col, max_row, max_col)`` in pixels (max exclusive, as
        :func:`skimage.measure.regionprops`); ``centroid_x_m``, ``centroid_y_m``
        (m): area centroid of the region; ``area_m2`` (m^2, pixel count when
        uncalibrated); ``touches_border`` (bool): the region reaches the map edge,
        so the lenslet may be incomplete; ``top_m`` (m): the top level used.
        Lateral values are in pixels when the map is uncalibrated.

    Raises
    ------
    ConfigError
        If the map has no valid pixels or ``depth_threshold`` is not positive.

    Notes
    -----
    The top level is the 99th percentile of the valid heights (robust to spikes;
    it assumes some uncut top surface is present, otherwise it is the rim of
    the lenslets). Regions are 8-connected components of ``z < top -
    depth_threshold`` labelled with :func:`skimage.measure.label` and measured with
    :func:`skimage.measure.regionprops`. Each centre is the sub-pixel deepest
    point of its region (see :func:`find_deepest_point`).
    """
    from skimage.measure import label, regionprops

    if not isinstance(surface, Surface):
        raise ConfigError(f"surface must be a Surface, got {type(surface).__name__}")
    v = surface._valid_values()
    top = float(np.percentile(v, TOP_PERCENTILE))
    if depth_threshold is None:
        depth_threshold = DEPTH_FRACTION * (top - float(v.min()))
        if depth_threshold <= 0:
            return []
    else:
        depth_threshold = check_positive(depth_threshold, name="depth_threshold")
    z = surface.z
    cut = np.isfinite(z) & (z < top - depth_threshold)
    labels = label(cut, connectivity=2)
    dx = surface.dx if surface.dx is not None else 1.0
    dy = surface.dy if surface.dy is not None else 1.0
    ny, nx = z.shape
    out: list[dict[str, Any]] = []
    for region in regionprops(labels):
        if region.area < min_area:
            continue
        r0, c0, r1, c1 = region.bbox
        masked = np.where(labels == region.label, z, np.nan)
        sub = masked[r0:r1, c0:c1]
        i0, j0 = np.unravel_index(np.nanargmin(sub), sub.shape)
        fi, fj = _subpixel_minimum(masked, int(i0) + r0, int(j0) + c0)
        cy, cx = region.centroid
        out.append(
            {
                "centre_x_m": surface.x0 + fj * dx,
                "centre_y_m": surface.y0 + fi * dy,
                "depth_m": top - float(np.nanmin(sub)),
                "bbox": (int(r0), int(c0), int(r1), int(c1)),
                "centroid_x_m": surface.x0 + float(cx) * dx,
                "centroid_y_m": surface.y0 + float(cy) * dy,
                "area_m2": float(region.area) * dx * dy,
                "touches_border": bool(r0 == 0 or c0 == 0 or r1 == ny or c1 == nx),
                "top_m": top,
            }
        )
    return _reading_order(out, dy)


def _reading_order(items: list[dict[str, Any]], dy: float) -> list[dict[str, Any]]:
    """Sort lenslets into rows (top to bottom), each row left to right.

    Consecutive centres (sorted by y) belong to the same row while they lie within
    half the median region height of the row's first centre.
    """
    if not items:
        return items
    half = 0.5 * float(np.median([(d["bbox"][2] - d["bbox"][0]) * dy for d in items]))
    by_y = sorted(items, key=lambda d: d["centre_y_m"])
    rows: list[list[dict[str, Any]]] = [[by_y[0]]]
    for d in by_y[1:]:
        if d["centre_y_m"] - rows[-1][0]["centre_y_m"] <= half:
            rows[-1].append(d)
        else:
            rows.append([d])
    return [d for row in rows for d in sorted(row, key=lambda d: d["centre_x_m"])]
