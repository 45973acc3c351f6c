"""The one surface type that readers, the simulator and the analysis share."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..errors import ConfigError

__all__ = ["Surface", "Profile"]


@dataclass(frozen=True, eq=False)
class Surface:
    """A height map in metres on a regular grid.

    Axis convention: rows are y, columns are x; pixel (i, j) is centred at
    ``(x0 + j dx, y0 + i dy)`` (:meth:`coords`). Readers keep the file's row order
    (row 0 is the first row the instrument stores, the top of its image); simulated
    maps have y increasing with the row index.

    Parameters
    ----------
    z : ndarray of shape (ny, nx)
        Heights in m. Invalid pixels are ``np.nan``.
    dx, dy : float or None
        Pixel size along x (columns) and y (rows), in m. ``None`` means the lateral
        scale is uncalibrated (a MetroPro lateral resolution of 0).
    metadata : dict
        Free-form metadata (instrument, objective, wavelength in m, date, source
        file, simulation settings...). Values must be JSON-serialisable.
    x0, y0 : float, default: 0.0
        Position of the centre of pixel (0, 0), in m.
    """

    z: np.ndarray
    dx: float | None
    dy: float | None
    metadata: dict[str, Any] = field(default_factory=dict)
    x0: float = 0.0
    y0: float = 0.0

    def __post_init__(self) -> None:
        z = np.asarray(self.z, dtype=np.float64)
        if z.ndim != 2:
            raise ConfigError(f"Surface.z must be 2-dimensional, got shape {z.shape}")
        if z.size == 0:
            raise ConfigError("Surface.z must not be empty")
        object.__setattr__(self, "z", z)
        for name in ("dx", "dy"):
            v = getattr(self, name)
            if v is not None:
                v = float(v)
                if not np.isfinite(v) or v <= 0:
                    raise ConfigError(
                        f"Surface.{name} must be a positive pixel size in m or None "
                        f"(uncalibrated), got {v!r}"
                    )
                object.__setattr__(self, name, v)

    # ------------------------------------------------------------------ basics
    @property
    def shape(self) -> tuple[int, int]:
        """(rows, cols) of the map."""
        return self.z.shape  # type: ignore[return-value]

    @property
    def calibrated(self) -> bool:
        """True when both pixel sizes are known."""
        return self.dx is not None and self.dy is not None

    @property
    def valid(self) -> np.ndarray:
        """Boolean mask of valid (finite) pixels, shape (ny, nx)."""
        return np.isfinite(self.z)

    @property
    def invalid_fraction(self) -> float:
        """Fraction of pixels that are NaN (0..1)."""
        return float(1.0 - self.valid.mean())

    def coords(self) -> tuple[np.ndarray, np.ndarray]:
        """Return pixel-centre coordinates ``x`` (nx,) and ``y`` (ny,) in m.

        Uses pixel index units (1 per pixel) when uncalibrated.
        """
        dx = self.dx if self.dx is not None else 1.0
        dy = self.dy if self.dy is not None else 1.0
        ny, nx = self.shape
        return self.x0 + dx * np.arange(nx), self.y0 + dy * np.arange(ny)

    def replace(self, **changes: Any) -> Surface:
        """Return a copy with some fields replaced (like dataclasses.replace)."""
        return dataclasses.replace(self, **changes)

    # ------------------------------------------------------------- statistics
    def _valid_values(self) -> np.ndarray:
        v = self.z[self.valid]
        if v.size == 0:
            raise ConfigError("surface has no valid pixels (all NaN)")
        return v

    def sa(self) -> float:
        """Arithmetic mean height about the mean over valid pixels, in m (no filter)."""
        v = self._valid_values()
        return float(np.mean(np.abs(v - v.mean())))

    def sq(self) -> float:
        """Root-mean-square height about the mean of valid pixels, in m (no filter)."""
        v = self._valid_values()
        return float(np.sqrt(np.mean((v - v.mean()) ** 2)))

    def level(self) -> Surface:
        """Return the surface minus its least-squares plane over valid pixels.

        The plane is fitted in pixel-index coordinates, which gives the same residual
        as metric coordinates and also works when uncalibrated.
        """
        ny, nx = self.shape
        jj, ii = np.meshgrid(np.arange(nx, dtype=float), np.arange(ny, dtype=float))
        m = self.valid
        if not m.any():
            raise ConfigError("surface has no valid pixels (all NaN)")
        a = np.column_stack([np.ones(m.sum()), jj[m], ii[m]])
        coef, *_ = np.linalg.lstsq(a, self.z[m], rcond=None)
        plane = coef[0] + coef[1] * jj + coef[2] * ii
        return self.replace(z=self.z - plane)


@dataclass(frozen=True, eq=False)
class Profile:
    """A height profile in metres sampled at a constant step.

    Parameters
    ----------
    z : ndarray of shape (n,)
        Heights in m; invalid samples are ``np.nan``.
    dx : float
        Sampling step along the profile, in m.
    metadata : dict
        Free-form, JSON-serialisable metadata.
    x0 : float, default: 0.0
        Position of the first sample, in m.
    """

    z: np.ndarray
    dx: float
    metadata: dict[str, Any] = field(default_factory=dict)
    x0: float = 0.0

    def __post_init__(self) -> None:
        z = np.asarray(self.z, dtype=np.float64)
        if z.ndim != 1 or z.size < 2:
            raise ConfigError(f"Profile.z must be 1-D with >= 2 samples, got {z.shape}")
        object.__setattr__(self, "z", z)
        dx = float(self.dx)
        if not np.isfinite(dx) or dx <= 0:
            raise ConfigError(
                f"Profile.dx must be a positive step in m, got {self.dx!r}"
            )
        object.__setattr__(self, "dx", dx)

    @property
    def x(self) -> np.ndarray:
        """Sample positions in m, shape (n,)."""
        return self.x0 + self.dx * np.arange(self.z.size)
