"""Form error of a simulated or measured map against its design surface.

The error map is the map minus the design evaluated at the map's pixel centres
(same frame, heights in m, z up). Piston and tilt are removed by least squares over
the valid pixels; optionally a best-fit sphere as well: piston, tilt and the sag of a
sphere of free curvature centred on the valid region (the "power" term), fitted by
nonlinear least squares. PV is max minus min and RMS the root mean square of the
residual over the valid pixels, both in m.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..errors import ConfigError
from ._surface import Surface

__all__ = ["form_error_against_design", "DesignFormError"]

_REMOVABLE = ("piston", "tilt")


@dataclass(frozen=True, eq=False)
class DesignFormError:
    """Form error of a map against its design (SI units).

    Attributes
    ----------
    error : Surface
        Map minus design after removing ``removed`` (m; NaN where not evaluated).
    pv : float
        Peak-to-valley of ``error``, in m.
    rms : float
        Root mean square of ``error``, in m.
    removed : tuple of str
        Terms removed: a subset of ("piston", "tilt").
    piston : float
        Removed mean offset, in m (0 when not removed).
    tilt_x, tilt_y : float
        Removed slopes dz/dx and dz/dy (dimensionless; 0 when not removed).
    error_bfs : Surface or None
        Map minus design after piston, tilt and the best-fit sphere (m).
    pv_bfs, rms_bfs : float or None
        PV and RMS of ``error_bfs``, in m.
    bfs_curvature : float or None
        Curvature of the removed best-fit sphere term, in 1/m (> 0: the map is
        more concave than the design).
    n_valid : int
        Number of pixels evaluated.
    """

    error: Surface
    pv: float
    rms: float
    removed: tuple[str, ...]
    piston: float
    tilt_x: float
    tilt_y: float
    error_bfs: Surface | None
    pv_bfs: float | None
    rms_bfs: float | None
    bfs_curvature: float | None
    n_valid: int

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready numbers (SI, units in the keys)."""
        return {
            "form_error_pv_m": self.pv,
            "form_error_rms_m": self.rms,
            "form_error_removed": list(self.removed),
            "form_error_piston_m": self.piston,
            "form_error_tilt_x": self.tilt_x,
            "form_error_tilt_y": self.tilt_y,
            "form_error_pv_bfs_m": self.pv_bfs,
            "form_error_rms_bfs_m": self.rms_bfs,
            "best_fit_sphere_curvature_per_m": self.bfs_curvature,
            "form_error_pixels": self.n_valid,
        }


def _design_on_grid(surface: Surface, design) -> np.ndarray:
    if isinstance(design, Surface):
        design = design.z
    if isinstance(design, np.ndarray):
        d = np.asarray(design, dtype=np.float64)
        if d.shape != surface.shape:
            raise ConfigError(
                f"design array must have the map's shape {surface.shape}, got "
                f"{d.shape}")
        return d
    fn: Callable | None = getattr(design, "sag", None)
    if fn is None and callable(design):
        fn = design
    if fn is None:
        raise ConfigError(
            "design must be a design surface (with .sag(x, y) in m), a callable "
            f"z(x, y), an array or a Surface, got {type(design).__name__}")
    if not surface.calibrated:
        raise ConfigError("the map must be calibrated (dx, dy in m) to evaluate a "
                          "design on it")
    x, y = surface.coords()
    d = np.asarray(fn(x[None, :], y[:, None]), dtype=np.float64)
    if d.shape != surface.shape:
        d = np.broadcast_to(d, surface.shape).copy()
    return d


def _sphere_sag(k: float, rho2: np.ndarray) -> np.ndarray:
    return k * rho2 / (1.0 + np.sqrt(np.clip(1.0 - k * k * rho2, 0.0, None)))


def form_error_against_design(surface: Surface, design, *,
                              remove: Sequence[str] = ("piston", "tilt"),
                              best_fit_sphere: bool = False,
                              mask: np.ndarray | None = None) -> DesignFormError:
    """Form error of a map against its design: error map, PV and RMS in m.

    Parameters
    ----------
    surface : Surface
        Simulated or measured height map, in m (NaN = invalid).
    design : object with ``sag(x, y)``, callable, ndarray or Surface
        The design in the map's frame: a :class:`~servosurf.toolpath.DesignSurface`
        or a :class:`~servosurf.toolpath.DesignToolpath` (whose ``sag`` places the
        design on the workpiece), any callable ``z(x, y)`` in m, or the design's
        heights on the map's grid (shape (ny, nx), m).
    remove : sequence of str, default: ("piston", "tilt")
        Terms removed by least squares before PV and RMS: any of "piston", "tilt".
    best_fit_sphere : bool, default: False
        Also report PV and RMS after piston, tilt and a best-fit sphere.
    mask : ndarray of bool, shape (ny, nx), optional
        Pixels to evaluate (True); default every pixel where map and design are
        finite.

    Returns
    -------
    DesignFormError
        Error maps and numbers.

    Raises
    ------
    ConfigError
        On an unknown term, a design of the wrong shape, an uncalibrated map with a
        design function, or fewer than 4 valid pixels.

    Examples
    --------
    >>> import numpy as np
    >>> from servosurf.metrology import Surface
    >>> from servosurf.toolpath import Sphere
    >>> s = Sphere(radius=0.1)
    >>> x = (np.arange(101) - 50) * 1e-6
    >>> z = s.sag(x[None, :], x[:, None]) + 2e-9 * (x[None, :] / 50e-6) ** 3
    >>> fe = form_error_against_design(Surface(z + 1e-6, 1e-6, 1e-6, x0=-50e-6,
    ...                                        y0=-50e-6), s)
    >>> bool(fe.pv < 4e-9)  # piston removed, the cubic term remains
    True
    """
    if not isinstance(surface, Surface):
        raise ConfigError(f"surface must be a Surface, got {type(surface).__name__}")
    remove = tuple(remove)
    bad = [r for r in remove if r not in _REMOVABLE]
    if bad:
        raise ConfigError(f"remove: unknown term {bad[0]!r}; allowed: "
                          f"{', '.join(_REMOVABLE)}")
    d = _design_on_grid(surface, design)
    e = surface.z - d
    valid = np.isfinite(e)
    if mask is not None:
        m = np.asarray(mask, dtype=bool)
        if m.shape != surface.shape:
            raise ConfigError(f"mask must have the map's shape {surface.shape}, got "
                              f"{m.shape}")
        valid &= m
    n = int(valid.sum())
    if n < 4:
        raise ConfigError(f"fewer than 4 valid pixels to compare with the design "
                          f"(got {n}); does the map overlap the design?")
    x, y = surface.coords()
    X, Y = np.meshgrid(x, y)
    xc, yc = X[valid].mean(), Y[valid].mean()
    u, v, ev = X[valid] - xc, Y[valid] - yc, e[valid]
    cols, names = [], []
    if "piston" in remove:
        cols.append(np.ones(n))
        names.append("piston")
    if "tilt" in remove:
        cols += [u, v]
        names += ["tilt_x", "tilt_y"]
    coef = dict.fromkeys(("piston", "tilt_x", "tilt_y"), 0.0)
    res = ev
    if cols:
        a = np.column_stack(cols)
        sol, *_ = np.linalg.lstsq(a, ev, rcond=None)
        res = ev - a @ sol
        coef.update({k: float(c) for k, c in zip(names, sol, strict=True)})
    err = np.full(surface.shape, np.nan)
    err[valid] = res
    meta = dict(surface.metadata)
    meta["form_error"] = {"removed": list(remove), "reference": "design"}
    out_bfs = pv_bfs = rms_bfs = k_bfs = None
    if best_fit_sphere:
        res_b, k_bfs = _fit_sphere(u, v, ev)
        eb = np.full(surface.shape, np.nan)
        eb[valid] = res_b
        out_bfs = surface.replace(z=eb, metadata={
            **meta, "form_error": {"removed": ["piston", "tilt", "sphere"],
                                   "reference": "design"}})
        pv_bfs = float(res_b.max() - res_b.min())
        rms_bfs = float(np.sqrt(np.mean(res_b**2)))
    return DesignFormError(
        error=surface.replace(z=err, metadata=meta),
        pv=float(res.max() - res.min()),
        rms=float(np.sqrt(np.mean(res**2))),
        removed=remove,
        piston=coef["piston"],
        tilt_x=coef["tilt_x"],
        tilt_y=coef["tilt_y"],
        error_bfs=out_bfs,
        pv_bfs=pv_bfs,
        rms_bfs=rms_bfs,
        bfs_curvature=k_bfs,
        n_valid=n,
    )


def _fit_sphere(u: np.ndarray, v: np.ndarray,
                e: np.ndarray) -> tuple[np.ndarray, float]:
    """Residual of e after piston, tilt and a centred sphere sag; its curvature."""
    import scipy.optimize

    rho2 = u * u + v * v
    a = np.column_stack([np.ones(u.size), u, v, rho2])
    sol, *_ = np.linalg.lstsq(a, e, rcond=None)
    lin = a[:, :3]
    k_max = 0.999 / np.sqrt(rho2.max()) if rho2.max() > 0 else np.inf

    def residual(k: float) -> np.ndarray:
        s = _sphere_sag(k, rho2)
        c, *_ = np.linalg.lstsq(lin, e - s, rcond=None)
        return e - s - lin @ c

    k0 = float(np.clip(2.0 * sol[3], -k_max, k_max))
    if rho2.max() == 0:
        return residual(0.0), 0.0
    opt = scipy.optimize.least_squares(lambda p: residual(p[0]), [k0],
                                       bounds=([-k_max], [k_max]), x_scale=[k_max],
                                       xtol=1e-14, ftol=1e-14, gtol=1e-14)
    k = float(opt.x[0])
    r0, r1 = residual(k0), residual(k)
    if np.sum(r0**2) <= np.sum(r1**2):
        k, r1 = k0, r0
    return r1, k
