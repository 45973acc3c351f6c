"""Registration, sub-pixel shifting, resampling and form removal of height maps."""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
import scipy.ndimage as ndi
import scipy.sparse

from .._validation import check_finite, check_positive
from ..errors import ConfigError
from ._surface import Surface

__all__ = ["register_translation", "shift_surface", "resample", "remove_form"]

#: Form terms understood by remove_form and their basis functions of the centred,
#: scaled coordinates (u, v) in [-1, 1].
FORM_TERMS: tuple[str, ...] = ("piston", "tilt", "sphere", "astigmatism")

#: A shifted or resampled pixel is valid only when the valid source pixels carry at
#: least this fraction of its weight.
MIN_VALID_WEIGHT: float = 0.999

#: Gauss-Newton passes of the registration refinement.
_REFINE_PASSES: int = 5

#: A resampled (area-averaged) pixel is valid when at least this fraction of its
#: area is covered by valid source pixels.
MIN_VALID_AREA: float = 0.5


def _check_surface(surface: object, name: str) -> Surface:
    if not isinstance(surface, Surface):
        raise ConfigError(f"{name} must be a Surface, got {type(surface).__name__}")
    if not surface.valid.any():
        raise ConfigError(f"{name} has no valid pixels (all NaN)")
    return surface


def _fill_nearest(z: np.ndarray) -> np.ndarray:
    """Replace NaN by the nearest valid pixel's value (Euclidean distance)."""
    invalid = ~np.isfinite(z)
    if not invalid.any():
        return z
    idx = ndi.distance_transform_edt(
        invalid, return_distances=False, return_indices=True
    )
    return z[tuple(idx)]


def _steps(surface: Surface) -> tuple[float, float]:
    return (
        surface.dy if surface.dy is not None else 1.0,
        surface.dx if surface.dx is not None else 1.0,
    )


def remove_form(
    surface: Surface,
    terms: Sequence[str] = ("piston", "tilt", "sphere"),
    *,
    return_form: bool = False,
) -> Surface | tuple[Surface, Surface]:
    """Subtract a least-squares form (piston, tilt, sphere, astigmatism) fit.

    Parameters
    ----------
    surface : Surface
        Height map in m; NaN pixels are excluded from the fit and stay NaN.
    terms : sequence of str, default: ("piston", "tilt", "sphere")
        Any of ``"piston"`` (1), ``"tilt"`` (x, y), ``"sphere"`` (x^2 + y^2, the
        paraboloid "power" term) and ``"astigmatism"`` (x^2 - y^2, x y).
    return_form : bool, default: False
        Also return the fitted form as a Surface.

    Returns
    -------
    Surface or tuple of Surface
        The residual ``z - form`` in m (and the form, in m, when ``return_form``).

    Raises
    ------
    ConfigError
        On an unknown term, no terms, no valid pixels, or fewer valid pixels than
        basis functions.

    Notes
    -----
    Linear least squares over valid pixels in metric coordinates (pixel indices
    when uncalibrated, i.e. square pixels assumed), centred and scaled to
    ``[-1, 1]`` for conditioning. "sphere" is the second-order (paraboloid)
    approximation of a sphere, exact to ``O(r^4 / R^3)``, the usual "power" term of
    interferometry (ISO 10110-5 sagitta form); it is not a nonlinear sphere fit.
    ISO 25178-2 calls this the F-operation (form removal).

    Examples
    --------
    >>> import numpy as np
    >>> from servosurf.metrology import Surface, remove_form
    >>> yy, xx = np.mgrid[0:16, 0:16] * 1e-6
    >>> s = Surface(1e-3 * xx + 2e-3 * yy + 5e-9, 1e-6, 1e-6)
    >>> float(np.abs(remove_form(s, ("piston", "tilt")).z).max()) < 1e-18
    True
    """
    surface = _check_surface(surface, "surface")
    if isinstance(terms, str):
        terms = (terms,)
    terms = tuple(terms)
    if not terms:
        raise ConfigError("terms must name at least one form term")
    for t in terms:
        if t not in FORM_TERMS:
            raise ConfigError(
                f"unknown form term {t!r}; allowed: {', '.join(FORM_TERMS)}"
            )
    ny, nx = surface.shape
    sy, sx = _steps(surface)
    xs = (np.arange(nx) - (nx - 1) / 2.0) * sx
    ys = (np.arange(ny) - (ny - 1) / 2.0) * sy
    scale = max(abs(xs).max(), abs(ys).max(), 1e-300)
    u, v = np.meshgrid(xs / scale, ys / scale)
    basis: list[np.ndarray] = []
    if "piston" in terms:
        basis.append(np.ones_like(u))
    if "tilt" in terms:
        basis += [u, v]
    if "sphere" in terms:
        basis.append(u * u + v * v)
    if "astigmatism" in terms:
        basis += [u * u - v * v, u * v]
    m = surface.valid
    if m.sum() < len(basis):
        raise ConfigError(
            f"need at least {len(basis)} valid pixels to fit {terms}, got {m.sum()}"
        )
    a = np.column_stack([b[m] for b in basis])
    coef, *_ = np.linalg.lstsq(a, surface.z[m], rcond=None)
    form = sum(c * b for c, b in zip(coef, basis, strict=True))
    meta = dict(surface.metadata)
    meta["form_removed"] = list(terms)
    residual = surface.replace(z=surface.z - form, metadata=meta)
    if return_form:
        return residual, surface.replace(z=np.where(m, form, np.nan))
    return residual


def register_translation(
    reference: Surface,
    moving: Surface,
    *,
    upsample: int = 100,
    window: bool = True,
    refine: bool = True,
) -> tuple[float, float, float]:
    """Find the translation registering ``moving`` onto ``reference``.

    Parameters
    ----------
    reference, moving : Surface
        Height maps in m on grids of the same shape and pixel size. NaN pixels are
        filled with the nearest valid height before correlating.
    upsample : int, default: 100
        Upsampling factor of the cross-correlation peak: the shift resolution is
        ``1 / upsample`` pixel.
    window : bool, default: True
        Taper both maps with a 2-D Hann window (after removing their mean plane)
        to suppress the edge discontinuity of the periodic FFT.
    refine : bool, default: True
        Polish the phase-correlation shift by Gauss-Newton (Lucas-Kanade)
        iterations that fit the shift together with a relative piston and tilt.

    Returns
    -------
    dy, dx : float
        Shift, in m (pixels when uncalibrated), to apply to ``moving`` with
        :func:`shift_surface` to register it onto ``reference``; i.e. ``moving`` is
        ``reference`` displaced by ``(-dy, -dx)``. ``dy`` is along rows, ``dx``
        along columns.
    error : float
        Normalised RMS residual of the registration: RMS of ``reference`` minus
        the registered ``moving`` over the pixels valid in both, after removing
        the least-squares plane of that difference (piston and relative tilt),
        divided by the RMS of ``reference`` about its mean over the same pixels.
        0 is a perfect match; NaN when nothing overlaps.

    Raises
    ------
    ConfigError
        If the maps differ in shape or pixel size, or ``upsample < 1``.

    See Also
    --------
    shift_surface, resample

    Notes
    -----
    Phase correlation with matrix-multiply DFT upsampling (Guizar-Sicairos,
    Thurman and Fienup, Opt. Lett. 33 (2008) 156,
    doi:10.1364/OL.33.000156) as implemented by scikit-image. The masked
    variant of scikit-image (``reference_mask``) has no sub-pixel refinement,
    hence the NaN filling. A least-squares plane is removed from both maps first,
    so tilt between measurements does not bias the peak. Phase correlation of
    smooth, windowed lenslet maps is biased by a few hundredths of a pixel; the
    refinement (Lucas and Kanade, IJCAI 1981) linearises the registered
    difference in the shift and reduces that to the interpolation error.
    """
    from skimage.registration import phase_cross_correlation

    reference = _check_surface(reference, "reference")
    moving = _check_surface(moving, "moving")
    if reference.shape != moving.shape:
        raise ConfigError(
            f"reference and moving must have the same shape, got {reference.shape} "
            f"and {moving.shape}; resample or crop first"
        )
    for name in ("dx", "dy"):
        a, b = getattr(reference, name), getattr(moving, name)
        if (a is None) != (b is None) or (
            a is not None and not math.isclose(a, b, rel_tol=1e-6)
        ):
            raise ConfigError(
                f"reference and moving must have the same {name}, got {a!r} and {b!r}"
            )
    if int(upsample) < 1:
        raise ConfigError(f"upsample must be >= 1, got {upsample!r}")

    def prep(s: Surface) -> np.ndarray:
        z = _fill_nearest(remove_form(s, ("piston", "tilt")).z)
        if window:
            ny, nx = z.shape
            z = z * np.outer(np.hanning(ny), np.hanning(nx))
        return z

    shift, _, _ = phase_cross_correlation(
        prep(reference), prep(moving), upsample_factor=int(upsample)
    )
    sy, sx = _steps(reference)
    dy, dx = float(shift[0]) * sy, float(shift[1]) * sx
    if refine:
        dy, dx = _refine_shift(reference, moving, dy, dx)
    # residual after registration (skimage's own error is not meaningful with the
    # default phase normalisation)
    diff = reference.z - shift_surface(moving, dy, dx).z
    both = np.isfinite(diff)
    if both.sum() < 3:
        return dy, dx, float("nan")
    d = remove_form(reference.replace(z=diff), ("piston", "tilt")).z[both]
    r = reference.z[both] - reference.z[both].mean()
    rms_ref = float(np.sqrt(np.mean(r**2)))
    error = float(np.sqrt(np.mean(d**2))) / rms_ref if rms_ref > 0 else float("nan")
    return dy, dx, error


def _refine_shift(
    reference: Surface, moving: Surface, dy: float, dx: float
) -> tuple[float, float]:
    """Gauss-Newton (Lucas-Kanade) refinement of a translation, with relative tilt.

    Linearises ``reference ~ shifted_moving - delta . grad(shifted_moving) +
    plane`` over the pixels valid in both, solves for ``delta`` and the plane by
    least squares, and iterates. Falls back to the starting shift when the
    refinement moves by more than one pixel (it is meant to polish, not search).
    """
    sy, sx = _steps(reference)
    ny, nx = reference.shape
    vv, uu = np.mgrid[0:ny, 0:nx]
    uu = (uu - (nx - 1) / 2.0) / max(nx, 1)
    vv = (vv - (ny - 1) / 2.0) / max(ny, 1)
    y0, x0 = dy, dx
    for _ in range(_REFINE_PASSES):
        m = shift_surface(moving, dy, dx).z
        gy, gx = np.gradient(m, sy, sx)
        d = reference.z - m
        ok = np.isfinite(d) & np.isfinite(gy) & np.isfinite(gx)
        if ok.sum() < 10:
            return y0, x0
        a = np.column_stack([-gy[ok], -gx[ok], np.ones(ok.sum()), uu[ok], vv[ok]])
        c, *_ = np.linalg.lstsq(a, d[ok], rcond=None)
        dy, dx = dy + float(c[0]), dx + float(c[1])
        if abs(dy - y0) > sy or abs(dx - x0) > sx:
            return y0, x0
        if abs(c[0]) < 1e-4 * sy and abs(c[1]) < 1e-4 * sx:
            break
    return dy, dx


def shift_surface(surface: Surface, dy: float, dx: float, *, order: int = 3) -> Surface:
    """Translate a height map by a sub-pixel amount (NaN-safe).

    Parameters
    ----------
    surface : Surface
        Height map in m.
    dy, dx : float
        Shift along rows (y) and columns (x), in m (pixels when uncalibrated).
        Positive values move the content towards larger row / column indices.
    order : int, default: 3
        Spline order of :func:`scipy.ndimage.shift` (1 = bilinear, 3 = cubic).

    Returns
    -------
    Surface
        The shifted map on the same grid, in m. Pixels whose interpolation would
        use invalid or outside pixels are NaN.

    Raises
    ------
    ConfigError
        If a shift is not finite or ``order`` is not in 0..5.

    Notes
    -----
    NaN pixels are filled with the nearest valid height, the filled map is shifted
    by spline interpolation, and the validity mask is shifted bilinearly: an output
    pixel is kept when its valid weight is at least :data:`MIN_VALID_WEIGHT`. The
    cubic spline prefilter spreads the filled values a little beyond the masked
    border (decaying by a factor 0.27 per pixel).
    """
    surface = _check_surface(surface, "surface")
    dy = check_finite(dy, name="dy")
    dx = check_finite(dx, name="dx")
    if order not in range(6):
        raise ConfigError(f"order must be an integer in 0..5, got {order!r}")
    sy, sx = _steps(surface)
    sh = (dy / sy, dx / sx)
    z = ndi.shift(_fill_nearest(surface.z), sh, order=order, mode="nearest")
    w = ndi.shift(surface.valid.astype(float), sh, order=1, mode="constant", cval=0.0)
    z[w < MIN_VALID_WEIGHT] = np.nan
    return surface.replace(z=z)


def _area_weights(
    n: int, step: float, new_step: float
) -> tuple[scipy.sparse.csr_array, int]:
    """Sparse (n_new, n) overlap fractions of new pixels with old pixels."""
    n_new = max(1, int(math.floor(n * step / new_step + 1e-9)))
    rows, cols, vals = [], [], []
    for i in range(n_new):
        a, b = i * new_step, (i + 1) * new_step
        j0, j1 = int(math.floor(a / step)), min(n, int(math.ceil(b / step)))
        for j in range(j0, j1):
            ov = min(b, (j + 1) * step) - max(a, j * step)
            if ov > 0:
                rows.append(i)
                cols.append(j)
                vals.append(ov / new_step)
    w = scipy.sparse.csr_array((vals, (rows, cols)), shape=(n_new, n))
    return w, n_new


def resample(surface: Surface, dx: float, dy: float | None = None) -> Surface:
    """Resample a map onto a coarser pitch by area averaging (NaN-aware).

    Parameters
    ----------
    surface : Surface
        Calibrated height map in m.
    dx : float
        New pixel size along x (columns), in m; at least the current ``dx``.
    dy : float or None, default: None
        New pixel size along y (rows), in m; ``None`` means ``dx``.

    Returns
    -------
    Surface
        Map on the new grid, in m. The new grid starts at the outer edge of the
        old one (``x0_new = x0 - dx_old / 2 + dx_new / 2``) and covers as many
        whole new pixels as fit. A new pixel is NaN when less than
        :data:`MIN_VALID_AREA` of its area holds valid data.

    Raises
    ------
    ConfigError
        If the surface is uncalibrated or a new pitch is finer than the old one.

    Notes
    -----
    Each new pixel is the area-weighted mean of the old pixels it overlaps, each
    old pixel being a uniform tile (the usual camera-pixel model; separable:
    ``Wy z Wx^T`` with sparse overlap matrices). For integer ratios this is the
    block mean; for non-integer ratios a plane is reproduced only to within a
    fraction of one source pixel's height step, as partially covered tiles
    weigh their centre values. Area averaging is the natural anti-aliasing for
    comparing a fine measurement with a coarser simulation; it preserves the mean
    height and attenuates wavelengths near the new pitch (sinc response).
    """
    surface = _check_surface(surface, "surface")
    if not surface.calibrated:
        raise ConfigError("surface must be calibrated (dx, dy in m) to resample it")
    dx = check_positive(dx, name="dx")
    dy = dx if dy is None else check_positive(dy, name="dy")
    if dx < surface.dx * (1 - 1e-9) or dy < surface.dy * (1 - 1e-9):
        raise ConfigError(
            f"resample only coarsens: new pitch ({dx:g}, {dy:g}) m must be >= the "
            f"current ({surface.dx:g}, {surface.dy:g}) m; use shift_surface/spline "
            "interpolation to refine"
        )
    ny, nx = surface.shape
    wx, nx_new = _area_weights(nx, surface.dx, dx)
    wy, ny_new = _area_weights(ny, surface.dy, dy)
    m = surface.valid.astype(float)
    z0 = np.where(surface.valid, surface.z, 0.0)
    num = (wx @ (wy @ z0).T).T
    den = (wx @ (wy @ m).T).T
    out = np.full((ny_new, nx_new), np.nan)
    ok = den >= MIN_VALID_AREA
    out[ok] = num[ok] / den[ok]
    meta = dict(surface.metadata)
    meta["resampled_from_m"] = [surface.dx, surface.dy]
    return Surface(
        out,
        dx,
        dy,
        meta,
        surface.x0 - surface.dx / 2 + dx / 2,
        surface.y0 - surface.dy / 2 + dy / 2,
    )
