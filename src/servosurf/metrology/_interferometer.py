"""A simulated white-light (coherence scanning) interferometer measurement.

The seed paper measured its parts on a ZYGO CP300 / NewView white-light
interferometer with a 20X objective. :func:`measure` turns a simulated height map
into what such an instrument would report: the camera's pixel grid, the optical
blur, the slope limit of the objective, the height noise floor and random
dropouts.

Axis convention: rows are y, columns are x. All lengths are in m, angles in rad.
"""

from __future__ import annotations

import dataclasses
import difflib
import math
import typing
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import scipy.ndimage as ndi
import scipy.sparse

from .._random import stream
from ..config import _check_bounds, from_mapping, load_toml, param, to_mapping
from ..errors import ConfigError
from ._surface import Surface

__all__ = [
    "Interferometer",
    "INSTRUMENTS",
    "load_instrument",
    "measure",
    "RAYLEIGH_FACTOR",
    "PSF_SIGMA_FACTOR",
]

#: Rayleigh two-point resolution of a circular pupil: ``0.61 lambda / NA``.
RAYLEIGH_FACTOR: float = 0.61

#: Standard deviation of the Gaussian that best fits the in-focus Airy pattern of
#: a wide-field microscope, as a multiple of ``lambda / NA`` (Zhang, Zerubia and
#: Olivo-Marin, Appl. Opt. 46 (2007) 1819, doi:10.1364/AO.46.001819). Its transfer
#: function ``exp(-2 pi^2 sigma^2 f^2)`` is about 0.1 at the Rayleigh frequency,
#: close to the incoherent OTF of the pupil there.
PSF_SIGMA_FACTOR: float = 0.21

#: A resampled or blurred pixel is valid when valid source pixels carry at least
#: this fraction of its weight.
MIN_VALID_WEIGHT: float = 0.5

#: An input whose pitch is within this fraction of the camera pixel is taken as the
#: camera grid itself (no resampling): 1 % is below a microscope's lateral
#: calibration uncertainty.
SAME_GRID_RTOL: float = 0.01

#: Gaussian kernels are truncated at this many standard deviations.
_TRUNCATE: float = 4.0

#: An input finer than ``sigma / _PREBIN_SAMPLES`` is first block-averaged so the
#: blur never needs kernels much longer than ``8 * _PREBIN_SAMPLES`` taps.
_PREBIN_SAMPLES: float = 4.0

#: Relative tolerance when comparing pixel pitches.
_PITCH_RTOL: float = 1e-9


def _field_types(cls: type) -> dict[str, Any]:
    return typing.get_type_hints(cls)


@dataclass(frozen=True)
class Interferometer:
    """An areal white-light interferometer with one objective.

    Every field is in SI units. ``field_of_view``, ``lateral_resolution``,
    ``psf_sigma`` and ``max_slope_angle`` are derived from the fields.
    Construction checks types and ranges and raises
    :class:`~servosurf.errors.ConfigError` naming the field.

    Notes
    -----
    The numbers of the presets in :data:`INSTRUMENTS` are approximate. The pixel
    size at the object comes from real NewView files (see ``pixel_size``); the
    numerical apertures are the usual ones of Mirau interference objectives; the
    noise floor is an assumption documented on ``noise_rms``.
    """

    name: str = param("newview-20x", doc="instrument + objective identifier")
    objective: str = param("20X Mirau", doc="objective description")
    magnification: float = param(
        20.0, unit="", low=0.0, low_open=True, doc="objective magnification"
    )
    numerical_aperture: float = param(
        0.40,
        unit="",
        low=0.0,
        high=1.0,
        low_open=True,
        doc="numerical aperture NA of the objective",
        source="usual NA of a 20X Mirau interference objective",
    )
    wavelength: float = param(
        570e-9,
        unit="m",
        low=200e-9,
        high=2e-6,
        doc="mean (centroid) wavelength of the white-light source",
        source="MetroPro header of a NewView 20X Mirau file (570 nm), "
        "shared/data/zygo/newview_20x_mirau_mp8.1_metropro-1.dat",
    )
    camera_nx: int = param(
        640,
        unit="pixels",
        low=2,
        high=100_000,
        doc="camera columns (x)",
        source="NewView 640 x 480 camera (MetroPro headers)",
    )
    camera_ny: int = param(
        480,
        unit="pixels",
        low=2,
        high=100_000,
        doc="camera rows (y)",
        source="NewView 640 x 480 camera (MetroPro headers)",
    )
    pixel_size: float = param(
        0.549e-6,
        unit="m",
        low=0.0,
        high=1e-3,
        low_open=True,
        doc="camera pixel size projected onto the object",
        source="real NewView 20X Mirau file at 0.5X image zoom: 1.0983 um, i.e. "
        "0.549 um at 1X zoom (camera-referred pitch about 10.97 um / "
        "magnification); a 100X file gives 0.1096 um",
    )
    noise_rms: float = param(
        0.15e-9,
        unit="m",
        low=0.0,
        high=1e-6,
        doc="RMS height noise per pixel of one (averaged) measurement",
        source="assumption: de Groot, Appl. Sci. 7 (2017) 54 "
        "(doi:10.3390/app7010054) reports 0.072 nm for a 1 s interference "
        "microscope acquisition; a white-light scan is noisier, 0.1-0.2 nm",
    )
    slope_acceptance: float = param(
        1.0,
        unit="",
        low=0.0,
        high=1.0,
        low_open=True,
        doc="fraction of asin(NA) up to which a local slope returns valid data",
        source="specular reflection with full-aperture illumination: slopes up to "
        "asin(NA) send some light back into the pupil",
    )
    dropout_fraction: float = param(
        0.0,
        unit="",
        low=0.0,
        high=0.99,
        doc="fraction of pixels randomly invalid (dust, low modulation)",
    )

    def __post_init__(self) -> None:
        hints = _field_types(type(self))
        for f in dataclasses.fields(self):
            value = getattr(self, f.name)
            tp = hints[f.name]
            dotted = f"Interferometer.{f.name}"
            if tp is float:
                if isinstance(value, bool | np.bool_) or not isinstance(
                    value, int | float | np.integer | np.floating
                ):
                    raise ConfigError(
                        f"{dotted}: expected float, got {type(value).__name__}"
                    )
                value = float(value)
                object.__setattr__(self, f.name, value)
            elif tp is int:
                if isinstance(value, bool | np.bool_) or not isinstance(
                    value, int | np.integer
                ):
                    raise ConfigError(
                        f"{dotted}: expected int, got {type(value).__name__}"
                    )
                value = int(value)
                object.__setattr__(self, f.name, value)
            elif tp is str and not isinstance(value, str):
                raise ConfigError(f"{dotted}: expected str, got {type(value).__name__}")
            _check_bounds(value, f.metadata, dotted)

    # ------------------------------------------------------------- derived
    @property
    def field_of_view(self) -> tuple[float, float]:
        """Field of view ``(x, y)`` in m: camera pixels times pixel size."""
        return (self.camera_nx * self.pixel_size, self.camera_ny * self.pixel_size)

    @property
    def lateral_resolution(self) -> float:
        """Optical lateral resolution in m: the Rayleigh limit ``0.61 lambda / NA``."""
        return RAYLEIGH_FACTOR * self.wavelength / self.numerical_aperture

    @property
    def psf_sigma(self) -> float:
        """Standard deviation of the Gaussian PSF model, ``0.21 lambda / NA``, in m."""
        return PSF_SIGMA_FACTOR * self.wavelength / self.numerical_aperture

    @property
    def max_slope_angle(self) -> float:
        """Largest measurable surface slope angle in rad: ``acceptance * asin(NA)``."""
        return self.slope_acceptance * math.asin(self.numerical_aperture)


def _preset(**kw: Any) -> Interferometer:
    return Interferometer(**kw)


#: Built-in instruments. Numbers are approximate (see :class:`Interferometer`):
#: pixel sizes from a camera-referred pitch of about 10.97 um divided by the
#: magnification (checked against real 20X and 100X NewView files); NA of ZYGO
#: Mirau objectives (20X 0.40, 50X 0.55, 100X 0.80).
INSTRUMENTS: dict[str, Interferometer] = {
    "newview-20x": _preset(),
    "newview-50x": _preset(
        name="newview-50x",
        objective="50X Mirau",
        magnification=50.0,
        numerical_aperture=0.55,
        pixel_size=0.2195e-6,
    ),
    "newview-100x": _preset(
        name="newview-100x",
        objective="100X Mirau",
        magnification=100.0,
        numerical_aperture=0.80,
        pixel_size=0.1096e-6,
    ),
    # The seed paper names a "ZYGO CP300" with a 20X objective and states nothing
    # more: assumed to carry the NewView 20X Mirau optics and 640 x 480 camera.
    "cp300-20x": _preset(name="cp300-20x", objective="20X Mirau (assumed)"),
}


def load_instrument(
    name_or_mapping: str | Path | Mapping[str, Any] | Interferometer,
) -> Interferometer:
    """Return an :class:`Interferometer` from a preset name, a TOML file or a mapping.

    Parameters
    ----------
    name_or_mapping : str, Path, Mapping or Interferometer
        A key of :data:`INSTRUMENTS` (case-insensitive), a path to a ``.toml``
        file, or a mapping with kebab-case keys (``numerical-aperture``,
        ``pixel-size`` in m, ...). A mapping may name a ``preset`` whose values it
        overrides; otherwise it starts from the default (``newview-20x``) values.
        An :class:`Interferometer` is returned unchanged.

    Returns
    -------
    Interferometer
        The instrument.

    Raises
    ------
    ConfigError
        On an unknown preset, unknown keys (with suggestions), wrong types or
        out-of-range values, naming the key.

    Examples
    --------
    >>> inst = load_instrument({"preset": "newview-50x", "noise-rms": 0.1e-9})
    >>> inst.numerical_aperture, inst.noise_rms
    (0.55, 1e-10)
    """
    if isinstance(name_or_mapping, Interferometer):
        return name_or_mapping
    if isinstance(name_or_mapping, Path) or (
        isinstance(name_or_mapping, str) and name_or_mapping.endswith(".toml")
    ):
        return load_instrument(load_toml(name_or_mapping))
    if isinstance(name_or_mapping, str):
        return _lookup(name_or_mapping)
    if not isinstance(name_or_mapping, Mapping):
        raise ConfigError(
            "instrument must be a preset name, a TOML path or a mapping, got "
            f"{type(name_or_mapping).__name__}"
        )
    data = dict(name_or_mapping)
    preset = data.pop("preset", None)
    base = Interferometer() if preset is None else _lookup(preset)
    merged = to_mapping(base) | data
    return from_mapping(Interferometer, merged, prefix="instrument")


def _lookup(name: object) -> Interferometer:
    if not isinstance(name, str):
        raise ConfigError(f"instrument.preset: expected str, got {type(name).__name__}")
    key = name.strip().lower()
    if key in INSTRUMENTS:
        return INSTRUMENTS[key]
    sugg = difflib.get_close_matches(key, list(INSTRUMENTS), n=1)
    hint = f" Did you mean: {sugg[0]}?" if sugg else ""
    raise ConfigError(
        f"unknown instrument {name!r}.{hint} Known: {', '.join(INSTRUMENTS)}"
    )


# ----------------------------------------------------------------- internals
def _axis_weights(
    n_src: int, d_src: float, x0_src: float, n_dst: int, d_dst: float, x0_dst: float
) -> scipy.sparse.csr_array:
    """Sparse (n_dst, n_src) resampling weights along one axis.

    Area overlap fractions when the destination pitch is at least the source
    pitch, linear-interpolation (hat) weights when it is finer. Rows sum to 1 for
    destination pixels inside the source extent.
    """
    xd = x0_dst + d_dst * np.arange(n_dst)
    if d_dst >= d_src * (1 - _PITCH_RTOL):
        # source tile i covers [x0 + (i - 1/2) d, x0 + (i + 1/2) d]
        lo = (xd - d_dst / 2 - x0_src) / d_src + 0.5
        hi = (xd + d_dst / 2 - x0_src) / d_src + 0.5
        i0 = np.clip(np.floor(lo).astype(np.int64), 0, n_src - 1)
        i1 = np.clip(np.ceil(hi).astype(np.int64), 1, n_src)
        span = int(np.max(i1 - i0))
        k = np.arange(span)
        cols = i0[:, None] + k[None, :]
        ov = np.minimum(hi[:, None], cols + 1.0) - np.maximum(lo[:, None], cols)
        ov = np.clip(ov, 0.0, None) * (d_src / d_dst)
        keep = (cols < n_src) & (ov > 0)
        rows = np.broadcast_to(np.arange(n_dst)[:, None], cols.shape)
        data, r, c = ov[keep], rows[keep], cols[keep]
    else:
        # linear, extrapolated up to half a source pixel beyond the outer
        # samples (the source tiles' extent), so planes are reproduced exactly
        u = np.clip((xd - x0_src) / d_src, -0.5, n_src - 0.5)
        i0 = np.clip(np.floor(u).astype(np.int64), 0, max(n_src - 2, 0))
        t = u - i0
        if n_src == 1:
            i0, t = np.zeros_like(i0), np.zeros_like(t)
        r = np.concatenate([np.arange(n_dst), np.arange(n_dst)])
        c = np.concatenate([i0, np.minimum(i0 + 1, n_src - 1)])
        data = np.concatenate([1.0 - t, t])
    return scipy.sparse.csr_array((data, (r, c)), shape=(n_dst, n_src))


def _apply_weights(
    z: np.ndarray, wy: scipy.sparse.csr_array, wx: scipy.sparse.csr_array
) -> np.ndarray:
    """NaN-aware separable resampling ``Wy z Wx^T`` normalised by valid weight."""
    valid = np.isfinite(z)
    z0 = np.where(valid, z, 0.0)
    num = (wx @ (wy @ z0).T).T
    den = (wx @ (wy @ valid.astype(np.float64)).T).T
    full = (wx @ (wy @ np.ones_like(z0)).T).T
    out = np.full(num.shape, np.nan)
    ok = den >= MIN_VALID_WEIGHT * full
    out[ok] = num[ok] / den[ok]
    return out


def _block_mean(z: np.ndarray, ky: int, kx: int) -> tuple[np.ndarray, int, int]:
    """NaN-aware (ky, kx) block mean; returns the map and the trimmed start offsets."""
    ny, nx = z.shape
    sy, sx = (ny % ky) // 2, (nx % kx) // 2
    my, mx = ny // ky, nx // kx
    zz = z[sy : sy + my * ky, sx : sx + mx * kx].reshape(my, ky, mx, kx)
    valid = np.isfinite(zz)
    s = np.where(valid, zz, 0.0).sum(axis=(1, 3))
    c = valid.sum(axis=(1, 3))
    out = np.full((my, mx), np.nan)
    ok = c >= MIN_VALID_WEIGHT * ky * kx
    out[ok] = s[ok] / c[ok]
    return out, sy, sx


def _plane(z: np.ndarray, valid: np.ndarray) -> np.ndarray:
    """Least-squares plane through the valid pixels, in pixel-index coordinates."""
    ny, nx = z.shape
    ii, jj = np.nonzero(valid)
    ci, cj = (ny - 1) / 2, (nx - 1) / 2
    a = np.column_stack([np.ones(ii.size), jj - cj, ii - ci])
    coef, *_ = np.linalg.lstsq(a, z[valid], rcond=None)
    return (
        coef[0]
        + coef[1] * (np.arange(nx) - cj)[None, :]
        + coef[2] * (np.arange(ny) - ci)[:, None]
    )


def _blur(z: np.ndarray, sigma_rows: float, sigma_cols: float) -> np.ndarray:
    """NaN-aware Gaussian blur (normalised convolution); NaN pixels stay NaN.

    The least-squares plane is taken out before and put back after, so tilt
    causes no bias where the kernel is one-sided (borders, holes).
    """
    valid = np.isfinite(z)
    plane = _plane(z, valid)
    z0 = np.where(valid, z - plane, 0.0)
    kw = dict(
        sigma=(sigma_rows, sigma_cols), mode="constant", cval=0.0, truncate=_TRUNCATE
    )
    num = ndi.gaussian_filter(z0, **kw)
    den = ndi.gaussian_filter(valid.astype(np.float64), **kw)
    out = np.full(z.shape, np.nan)
    out[valid] = num[valid] / den[valid] + plane[valid]
    return out


def _nan_gradient(z: np.ndarray, axis: int) -> np.ndarray:
    """Central differences per pixel along ``axis`` (one-sided next to NaN).

    Returns height steps per pixel; 0 where neither neighbour is valid.
    """
    d = np.diff(z, axis=axis)
    shape = list(z.shape)
    shape[axis] = 1
    pad = np.full(shape, np.nan)
    fwd = np.concatenate([d, pad], axis=axis)
    bwd = np.concatenate([pad, d], axis=axis)
    ff, fb = np.isfinite(fwd), np.isfinite(bwd)
    s = np.where(ff, fwd, 0.0) + np.where(fb, bwd, 0.0)
    n = ff.astype(np.int64) + fb
    return np.divide(s, n, out=np.zeros_like(s), where=n > 0)


def _target_grid(
    surface: Surface, inst: Interferometer
) -> tuple[int, int, float, float]:
    """Camera grid (ny, nx, x0, y0) centred on the input field, clipped to it."""
    ny_in, nx_in = surface.shape
    p = inst.pixel_size
    nx = min(inst.camera_nx, int(math.floor(nx_in * surface.dx / p + 1e-9)))
    ny = min(inst.camera_ny, int(math.floor(ny_in * surface.dy / p + 1e-9)))
    if nx < 2 or ny < 2:
        raise ConfigError(
            f"surface extent {nx_in * surface.dx:g} m x {ny_in * surface.dy:g} m "
            f"holds fewer than 2 x 2 instrument pixels of {p:g} m; use a larger "
            "field (field.nx, field.ny) or no instrument model (--instrument none)"
        )
    cx = surface.x0 + (nx_in - 1) * surface.dx / 2
    cy = surface.y0 + (ny_in - 1) * surface.dy / 2
    return ny, nx, cx - (nx - 1) * p / 2, cy - (ny - 1) * p / 2


# ------------------------------------------------------------------- public
def measure(
    surface: Surface,
    instrument: Interferometer | str | Mapping[str, Any],
    *,
    seed: int,
    resample: bool = True,
) -> Surface:
    """Simulate measuring a height map with a white-light interferometer.

    Parameters
    ----------
    surface : Surface
        Calibrated height map in m (NaN = no data). Its grid may be finer or
        coarser than the instrument's.
    instrument : Interferometer, str or Mapping
        The instrument, or anything :func:`load_instrument` accepts.
    seed : int
        Seed of the generator drawing the height noise and dropouts.
    resample : bool, default: True
        Resample onto the instrument's camera grid (pixel size
        ``instrument.pixel_size`` in m, at most ``camera_ny x camera_nx`` pixels,
        centred on the input field and clipped to it). An input whose pitch is
        within :data:`SAME_GRID_RTOL` of the camera pixel is only cropped to the
        camera's pixel count, not interpolated (``resampled`` is then False).
        ``False`` keeps the input grid and applies only blur, slope limit, noise
        and dropouts.

    Returns
    -------
    Surface
        The simulated measurement: heights in m, NaN where the slope exceeds
        ``instrument.max_slope_angle``, where a random dropout hit, or where the
        input had no data. ``metadata`` extends the input's with ``instrument``,
        ``objective``, ``magnification``, ``numerical_aperture``,
        ``wavelength_m``, ``pixel_size_m``, ``lateral_resolution_m``,
        ``psf_sigma_m``, ``noise_rms_m``, ``max_slope_angle_rad``,
        ``dropout_fraction``, ``seed``, ``resampled`` and ``simulated=True``.

    Raises
    ------
    ConfigError
        If ``surface`` is not a calibrated Surface with valid pixels, if its
        field holds fewer than 2 x 2 instrument pixels, if ``seed`` is not an
        integer, or if the instrument is invalid.

    See Also
    --------
    load_instrument, INSTRUMENTS

    Notes
    -----
    The steps, in order:

    1. Optics: a Gaussian point-spread function of standard deviation
       ``0.21 lambda / NA`` (:data:`PSF_SIGMA_FACTOR`), applied as a NaN-aware
       normalised convolution of the map minus its least-squares plane (so a
       tilt is not biased where the kernel is one-sided, at borders and holes;
       curved or steep maps still are within about ``4 sigma`` of a border).
       The blur acts on the finer of the two grids: on
       the input before the camera sampling when the input is at least as fine
       as the camera (the physical order, which also suppresses aliasing), on
       the camera grid after interpolation otherwise. Inputs much finer than the
       PSF are block-averaged first (box variance subtracted from the Gaussian's).
    2. Camera: each camera pixel is the area average of the (blurred) input
       where the input is finer, a bilinear interpolation where it is coarser
       (extrapolated linearly up to half an input pixel beyond the outer input
       samples; separable sparse weights, NaN-aware: valid when valid input carries at
       least :data:`MIN_VALID_WEIGHT` of the weight). The field centre is kept.
    3. Slope limit: pixels whose slope ``atan(|grad z|)`` (central differences
       of the blurred map on the output grid) exceeds ``max_slope_angle`` become
       NaN: no specularly reflected light returns through the pupil.
    4. Noise and dropouts: white Gaussian noise of RMS ``noise_rms`` in m on
       every valid pixel, then a random ``dropout_fraction`` of pixels set to NaN.

    The Gaussian PSF is a linear, small-height model of the instrument transfer
    function (ISO 25178-600); it ignores the non-linear response of
    interference microscopes to steep or high-amplitude structures, batwing
    artefacts at steps, and focus effects.

    Examples
    --------
    >>> import numpy as np
    >>> flat = Surface(np.zeros((480, 640)), 0.549e-6, 0.549e-6)
    >>> m = measure(flat, "newview-20x", seed=1)
    >>> m.shape, round(m.sq() * 1e9, 2)
    ((480, 640), 0.15)
    """
    inst = load_instrument(instrument)
    if not isinstance(surface, Surface):
        raise ConfigError(f"surface must be a Surface, got {type(surface).__name__}")
    if not surface.calibrated:
        raise ConfigError(
            "surface must be calibrated (dx, dy in m) to simulate a measurement"
        )
    if not surface.valid.any():
        raise ConfigError("surface has no valid pixels (all NaN)")
    if isinstance(seed, bool | np.bool_) or not isinstance(seed, int | np.integer):
        raise ConfigError(f"seed must be an int, got {type(seed).__name__}")
    if not isinstance(resample, bool | np.bool_):
        raise ConfigError(f"resample must be a bool, got {type(resample).__name__}")

    sigma = inst.psf_sigma
    z, dx, dy = surface.z, float(surface.dx), float(surface.dy)
    x0, y0 = surface.x0, surface.y0
    p = inst.pixel_size
    on_camera_grid = (abs(dx / p - 1.0) <= SAME_GRID_RTOL
                      and abs(dy / p - 1.0) <= SAME_GRID_RTOL)
    if resample and on_camera_grid:
        # the input already is a camera grid (within the lateral calibration
        # tolerance): crop to the camera's pixel count, no interpolation (a
        # bilinear resampling by a fraction of a pixel would add a curvature
        # bias and mix neighbouring rows that no camera makes)
        ny_c = min(inst.camera_ny, z.shape[0])
        nx_c = min(inst.camera_nx, z.shape[1])
        r0 = (z.shape[0] - ny_c) // 2
        c0 = (z.shape[1] - nx_c) // 2
        z = z[r0 : r0 + ny_c, c0 : c0 + nx_c]
        x0, y0 = x0 + c0 * dx, y0 + r0 * dy
        z = _blur(z, sigma / dy, sigma / dx)
        resample = False
    elif resample:
        ny, nx, x0_out, y0_out = _target_grid(surface, inst)
        if dx <= p * (1 + _PITCH_RTOL) and dy <= p * (1 + _PITCH_RTOL):
            z, dx, dy, x0, y0, s_rows, s_cols = _prebin(z, dx, dy, x0, y0, sigma)
            z = _blur(z, s_rows, s_cols)
            wy = _axis_weights(z.shape[0], dy, y0, ny, p, y0_out)
            wx = _axis_weights(z.shape[1], dx, x0, nx, p, x0_out)
            z = _apply_weights(z, wy, wx)
        else:
            wy = _axis_weights(z.shape[0], dy, y0, ny, p, y0_out)
            wx = _axis_weights(z.shape[1], dx, x0, nx, p, x0_out)
            z = _blur(_apply_weights(z, wy, wx), sigma / p, sigma / p)
        dx = dy = p
        x0, y0 = x0_out, y0_out
    else:
        z = _blur(z, sigma / dy, sigma / dx)

    if not np.isfinite(z).any():
        raise ConfigError("no valid pixel left after resampling (input mostly NaN)")

    gx = _nan_gradient(z, axis=1) / dx
    gy = _nan_gradient(z, axis=0) / dy
    too_steep = np.hypot(gx, gy) > math.tan(inst.max_slope_angle)
    z[too_steep] = np.nan

    rng = stream(int(seed), "instrument")  # not the vibration's normal numbers
    noise = rng.standard_normal(z.shape) * inst.noise_rms
    dropped = rng.random(z.shape) < inst.dropout_fraction
    z = z + noise
    z[dropped] = np.nan

    meta = dict(surface.metadata)
    meta.update(
        instrument=inst.name,
        objective=inst.objective,
        magnification=inst.magnification,
        numerical_aperture=inst.numerical_aperture,
        wavelength_m=inst.wavelength,
        pixel_size_m=inst.pixel_size,
        lateral_resolution_m=inst.lateral_resolution,
        psf_sigma_m=sigma,
        noise_rms_m=inst.noise_rms,
        max_slope_angle_rad=inst.max_slope_angle,
        dropout_fraction=inst.dropout_fraction,
        seed=int(seed),
        resampled=bool(resample),
        simulated=True,
    )
    return Surface(z, dx, dy, meta, x0, y0)


def _prebin(
    z: np.ndarray, dx: float, dy: float, x0: float, y0: float, sigma: float
) -> tuple[np.ndarray, float, float, float, float, float, float]:
    """Block-average inputs much finer than the PSF; return blur sigmas in pixels.

    The box of width ``w`` adds variance ``w^2 / 12``, which is taken off the
    Gaussian's so the total blur variance stays ``sigma^2``.
    """
    kx = max(1, int(sigma / (_PREBIN_SAMPLES * dx)))
    ky = max(1, int(sigma / (_PREBIN_SAMPLES * dy)))
    kx, ky = min(kx, z.shape[1] // 2 or 1), min(ky, z.shape[0] // 2 or 1)
    if kx > 1 or ky > 1:
        z, sy, sx = _block_mean(z, ky, kx)
        x0 = x0 + sx * dx + (kx - 1) * dx / 2
        y0 = y0 + sy * dy + (ky - 1) * dy / 2
        dx, dy = kx * dx, ky * dy
    var_x = sigma**2 - (dx**2 / 12 if kx > 1 else 0.0)
    var_y = sigma**2 - (dy**2 / 12 if ky > 1 else 0.0)
    return z, dx, dy, x0, y0, math.sqrt(var_y) / dy, math.sqrt(var_x) / dx
