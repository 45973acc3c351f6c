"""Design surfaces and the nose-compensated spiral toolpath that cuts them.

Frames and signs (SI: m, s, rad)
--------------------------------
A design is a sag ``z = S(x, y)`` in m with z up, away from the material (the
servosurf convention), 0 at the design's datum: the vertex for the sphere, the
conic/asphere and the biconic; the mean plane for the sinusoidal grid; the flat
between lenslets for a micro-lens array; the constant term for the XY polynomial.
Positions (x, y) are in the design's frame; :class:`DesignToolpath` places its
origin at (``center_x``, ``center_y``) on the workpiece (default: the spindle axis).

Curvature sign: a positive radius (or curvature) means **concave** as seen by the
tool, the centre of curvature on the tool side (+z): a bowl whose sag rises away
from the vertex, ``z = c r**2 / (1 + sqrt(1 - (1 + k) c**2 r**2))`` with c > 0. A
negative radius is **convex** (a dome). This is the optical sag convention with z
pointing out of the material.

Nose-radius compensation
------------------------
The diamond's edge is a circular arc of radius R in the radial-axial plane (the
model of :func:`~servosurf.toolpath.sweep`). At tip radius r and spindle angle
theta the arc must touch the design's radial section ``S(rho)`` without cutting into
it, so the tip height is

    z_tip(r, theta) = max_{|u| <= R sin(phi_max)} [S(r + u) - (R - sqrt(R**2 - u**2))].

Where the contact is smooth the maximum is stationary: ``S'(rho) = tan(phi)`` with
``u = R sin(phi)``. The contact point sits at the arc angle ``phi = atan(dS/drho)``
(the local radial slope) and the tip is offset from it by
``(dr, dz) = (-R sin(phi), -R (1 - cos(phi)))``: a design rising outward (phi > 0)
is touched outboard of the tip. The tangential slope does not enter: the edge lies in
the plane theta = const through the spindle axis and touches the design only in that
plane (it sets the flank clearance, which :func:`~servosurf.toolpath.check_clearance`
checks). The maximum form also handles corners: the nose rolls around a convex corner
(a lenslet rim) and rests on both sides of a concave one (which it cannot enter).
Closed form: a sphere of signed radius Rs is cut by a tip path that is the sphere of
signed radius ``Rs - R`` with the same vertex (concave Rs > R: the nose centres lie on
the concentric sphere of radius Rs - R; convex: |Rs| + R).

Feed and scallop height
-----------------------
Consecutive revolutions place the tip a radial feed f apart. Along the tip path
(which is the nose-centre path shifted down by R) that is a spacing
``d = f / cos(phi)``; the nose-centre path is the design offset by R, with radius of
curvature ``1 / kappa - R`` where kappa is the design's section curvature (concave
positive). Two nose circles d apart leave a cusp ``d**2 / (8 R (1 - R kappa))`` high
along the normal, ``1 / cos(phi)`` of that along z. So the height an interferometer
sees is

    h = f**2 / (8 R_eff),   R_eff = R (1 - R kappa) cos(phi)**3,

to first order in f / R and h / R, with kappa and phi taken at the contact point and
constant over one feed (flat: ``R_eff = R``; sphere of radius Rs at its vertex:
``R (1 - R / Rs)``). A scallop-height target plans the feed per revolution from this:
``f(r) = min over theta of sqrt(8 h R_eff)``, piecewise constant on fine radial
segments (the smaller value at the two ends of each).
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, ClassVar, Literal

import numpy as np

from .._validation import check_finite
from ..config import from_mapping, param
from ..errors import ConfigError
from ._paths import _ConstantSpeedPath, _pop_alias
from ._tool import ToolpathWarning

__all__ = [
    "DesignSurface",
    "Sphere",
    "EvenAsphere",
    "Biconic",
    "XYPolynomial",
    "SinusoidalGrid",
    "LensletArray",
    "DesignToolpath",
    "DESIGN_TYPES",
    "design_from_mapping",
    "design_toolpath_from_mapping",
    "nose_compensated_tip",
]

_SQRT3 = math.sqrt(3.0)


# ------------------------------------------------------------------ validation
def _slip_hint(v: float, unit: str) -> str:
    if unit != "m":
        return ""
    return (f"; if it was meant in mm write {v * 1e-3:g}, in um write {v * 1e-6:g}"
            f", in nm write {v * 1e-9:g}")


def _check_range(value: Any, *, name: str, low: float, high: float, unit: str = "m",
                 what: str = "", signed: bool = False, zero: bool = False) -> float:
    """Return ``value`` as float if ``low <= |value| <= high`` (or 0 if ``zero``).

    The message names the key, the value, its unit, the allowed range and, for a
    value too large, the likely unit slip.
    """
    v = check_finite(value, name=name)
    if not signed and v < 0:
        raise ConfigError(f"{name} must be >= 0 {unit}, got {v!r}")
    mag = abs(v)
    u = f" {unit}" if unit else ""
    if mag == 0.0:
        if zero:
            return v
        raise ConfigError(f"{name} must be non-zero{u}, got {v!r}")
    if mag > high:
        raise ConfigError(
            f"{name} = {v:g}{u} is implausibly large for {what or 'diamond turning'} "
            f"(|value| at most {high:g}{u}){_slip_hint(v, unit)}"
        )
    if mag < low:
        raise ConfigError(
            f"{name} = {v:g}{u} is implausibly small for {what or 'diamond turning'} "
            f"(|value| at least {low:g}{u})"
        )
    return v


# ------------------------------------------------------------------- designs
class DesignSurface:
    """Base of the design surfaces: sag and gradient in the design frame (m).

    Subclasses are frozen dataclasses that declare ``type_name`` (the TOML
    ``[surface] type``) and implement ``_kernel``.
    """

    type_name: ClassVar[str] = ""

    def _kernel(self) -> tuple[int, np.ndarray]:  # pragma: no cover - abstract
        raise NotImplementedError

    @property
    def feature_length(self) -> float:
        """Smallest lateral length over which the sag changes shape, in m (inf)."""
        return math.inf

    @property
    def axisymmetric(self) -> bool:
        """True when the sag depends on ``hypot(x, y)`` only."""
        return False

    def min_concave_radius(self) -> float | None:
        """Smallest concave radius of curvature when known in closed form, m."""
        return None

    def evaluate(self, x, y) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Sag and gradient at positions (x, y).

        Parameters
        ----------
        x, y : array_like
            Positions in the design frame, in m (broadcast together).

        Returns
        -------
        z : ndarray
            Sag in m (NaN outside the design's domain).
        gx, gy : ndarray
            dz/dx and dz/dy (dimensionless).
        """
        from ..kernels._design import _eval_points

        xb, yb = np.broadcast_arrays(np.asarray(x, dtype=np.float64),
                                     np.asarray(y, dtype=np.float64))
        shape = xb.shape
        xf = np.ascontiguousarray(xb).ravel()
        yf = np.ascontiguousarray(yb).ravel()
        z, gx, gy = (np.empty(xf.size) for _ in range(3))
        code, p = self._kernel()
        _eval_points(code, p, xf, yf, z, gx, gy)
        return z.reshape(shape), gx.reshape(shape), gy.reshape(shape)

    def sag(self, x, y) -> np.ndarray:
        """Sag z(x, y) in m (z up, 0 at the datum).

        Parameters
        ----------
        x, y : array_like
            Positions in the design frame, in m (broadcast together).

        Returns
        -------
        ndarray
            Heights in m; NaN outside the design's domain.
        """
        return self.evaluate(x, y)[0]

    def gradient(self, x, y) -> tuple[np.ndarray, np.ndarray]:
        """Gradient (dz/dx, dz/dy) of the sag, dimensionless.

        Parameters
        ----------
        x, y : array_like
            Positions in the design frame, in m (broadcast together).

        Returns
        -------
        gx, gy : ndarray
            Partial derivatives; NaN outside the design's domain. At a lenslet rim
            the one-sided value of the lens interior or the flat is returned.
        """
        _, gx, gy = self.evaluate(x, y)
        return gx, gy

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready description: ``type`` and the parameters (SI, unit in keys)."""
        out: dict[str, Any] = {"type": self.type_name}
        for name, unit in self._units().items():
            v = getattr(self, name)
            key = f"{name}_{unit}" if unit else name
            out[key] = list(v) if isinstance(v, tuple) else v
        return out

    def _units(self) -> dict[str, str]:
        import dataclasses

        units = {"m": "m", "1/m": "per_m", "": ""}
        return {f.name: units.get(f.metadata.get("unit", ""), "si")
                for f in dataclasses.fields(self)}  # type: ignore[arg-type]


def _conic_sag(c: float, k: float, r2: float) -> float:
    return c * r2 / (1.0 + math.sqrt(max(1.0 - (1.0 + k) * c * c * r2, 0.0)))


@dataclass(frozen=True)
class Sphere(DesignSurface):
    """Spherical surface ``z = c r**2 / (1 + sqrt(1 - c**2 r**2))``, c = 1 / radius.

    Parameters
    ----------
    radius : float
        Signed radius of curvature, in m: > 0 concave (a bowl, centre of curvature
        on the tool side), < 0 convex (a dome). TOML may give ``curvature`` (1/m)
        instead. The vertex is the datum (z = 0 at x = y = 0); the sag is defined
        for ``r < |radius|``.

    Examples
    --------
    >>> s = Sphere(radius=10e-3)
    >>> round(float(s.sag(1e-3, 0.0)) * 1e6, 4)  # um, 10 - sqrt(99) mm
    50.1256
    """

    type_name: ClassVar[str] = "sphere"
    radius: float = param(unit="m", doc="signed radius of curvature (> 0 concave)")

    def __post_init__(self) -> None:
        _check_range(self.radius, name="surface.radius", low=1e-6, high=10.0,
                     what="a sphere radius", signed=True)

    @property
    def curvature(self) -> float:
        """Signed curvature 1 / radius, in 1/m."""
        return 1.0 / self.radius

    @property
    def axisymmetric(self) -> bool:
        """Always True."""
        return True

    def min_concave_radius(self) -> float | None:
        """``radius`` when concave, else None (m)."""
        return self.radius if self.radius > 0 else None

    def _kernel(self) -> tuple[int, np.ndarray]:
        from ..kernels._design import SPHERE

        return SPHERE, np.array([self.curvature])


@dataclass(frozen=True)
class EvenAsphere(DesignSurface):
    """Conic plus even polynomial: the rotationally symmetric asphere.

    ``z = c r**2 / (1 + sqrt(1 - (1 + k) c**2 r**2)) + A4 r**4 + A6 r**6 + ...``

    Parameters
    ----------
    curvature : float
        Vertex curvature c = 1 / R, in 1/m (> 0 concave, 0 flat). TOML may give
        ``radius`` (m) instead.
    conic : float, default: 0.0
        Conic constant k (0 sphere, -1 paraboloid, < -1 hyperboloid, > 0 oblate).
    coefficients : tuple of float, default: ()
        A4, A6, A8, ... of r**4, r**6, ..., in m**-3, m**-5, ... (at most 20).
    """

    type_name: ClassVar[str] = "asphere"
    curvature: float = param(unit="1/m", doc="vertex curvature 1/R (> 0 concave)")
    conic: float = param(0.0, doc="conic constant k")
    coefficients: tuple[float, ...] = param(
        default_factory=tuple, unit="m^(1-2i)",
        doc="A4, A6, ... of r^4, r^6, ...")

    def __post_init__(self) -> None:
        _check_range(self.curvature, name="surface.curvature", low=0.0, high=1e6,
                     unit="1/m", what="a vertex curvature (radius >= 1 um)",
                     signed=True, zero=True)
        _check_range(self.conic, name="surface.conic", low=0.0, high=1e4, unit="",
                     what="a conic constant", signed=True, zero=True)
        coef = tuple(float(a) for a in self.coefficients)
        if len(coef) > 20 or not all(math.isfinite(a) for a in coef):
            raise ConfigError(
                "surface.coefficients must be at most 20 finite numbers (A4, A6, ... "
                f"in m^-3, m^-5, ...), got {list(coef)[:5]}...")
        object.__setattr__(self, "coefficients", coef)

    @property
    def axisymmetric(self) -> bool:
        """Always True."""
        return True

    def _kernel(self) -> tuple[int, np.ndarray]:
        from ..kernels._design import ASPHERE

        return ASPHERE, np.array([self.curvature, self.conic,
                                  float(len(self.coefficients)), *self.coefficients])


@dataclass(frozen=True)
class Biconic(DesignSurface):
    """Biconic (toric-like) surface with different curvatures along x and y.

    ``z = (cx x**2 + cy y**2) / (1 + sqrt(1 - (1 + kx) cx**2 x**2
    - (1 + ky) cy**2 y**2))``

    Parameters
    ----------
    curvature_x, curvature_y : float
        Vertex curvatures along x and y, in 1/m (> 0 concave). TOML may give
        ``radius-x``/``radius-y`` (m) instead.
    conic_x, conic_y : float, default: 0.0
        Conic constants along x and y.

    Notes
    -----
    With ``kx = ky = 0`` the x and y sections through the vertex are circles of
    radii 1/cx and 1/cy, as for a toroid; off those sections the biconic and the
    toroid differ at fourth order in x y.
    """

    type_name: ClassVar[str] = "biconic"
    curvature_x: float = param(unit="1/m", doc="vertex curvature along x")
    curvature_y: float = param(unit="1/m", doc="vertex curvature along y")
    conic_x: float = param(0.0, doc="conic constant along x")
    conic_y: float = param(0.0, doc="conic constant along y")

    def __post_init__(self) -> None:
        for n in ("curvature_x", "curvature_y"):
            _check_range(getattr(self, n), name=f"surface.{n.replace('_', '-')}",
                         low=0.0, high=1e6, unit="1/m",
                         what="a vertex curvature (radius >= 1 um)", signed=True,
                         zero=True)
        for n in ("conic_x", "conic_y"):
            _check_range(getattr(self, n), name=f"surface.{n.replace('_', '-')}",
                         low=0.0, high=1e4, unit="", what="a conic constant",
                         signed=True, zero=True)

    def _kernel(self) -> tuple[int, np.ndarray]:
        from ..kernels._design import BICONIC

        return BICONIC, np.array([self.curvature_x, self.curvature_y, self.conic_x,
                                  self.conic_y])


@dataclass(frozen=True)
class XYPolynomial(DesignSurface):
    """Polynomial in x and y: ``z = sum_ij C[i][j] (x / rn)**i (y / rn)**j``.

    Parameters
    ----------
    coefficients : tuple of tuple of float
        ``C[i][j]`` in m multiplies ``(x / rn)**i (y / rn)**j`` (row i: power of x,
        column j: power of y); shorter rows are padded with zeros. Degree at most 20
        per axis.
    norm_radius : float, default: 1.0
        Normalisation radius rn, in m (1.0: coefficients of plain powers of x, y
        in m).
    """

    type_name: ClassVar[str] = "xy-polynomial"
    coefficients: tuple[tuple[float, ...], ...] = param(
        unit="m", doc="C[i][j] of (x/rn)^i (y/rn)^j")
    norm_radius: float = param(1.0, unit="m", doc="normalisation radius rn")

    def __post_init__(self) -> None:
        rows = [tuple(float(v) for v in row) for row in self.coefficients]
        if not rows or not any(rows):
            raise ConfigError("surface.coefficients must hold at least one row, e.g. "
                              "[[0.0, 0.0, 1e-6]] for 1 um (y / rn)^2")
        width = max(len(r) for r in rows)
        if len(rows) > 21 or width > 21:
            raise ConfigError(
                f"surface.coefficients: degree at most 20 per axis, got a "
                f"{len(rows)} x {width} matrix")
        mat = tuple(r + (0.0,) * (width - len(r)) for r in rows)
        flat = [v for r in mat for v in r]
        if not all(math.isfinite(v) for v in flat):
            raise ConfigError("surface.coefficients must be finite")
        big = max(abs(v) for v in flat)
        if big > 0.05:
            raise ConfigError(
                f"surface.coefficients: a term of {big:g} m at the normalisation "
                "radius is implausibly large for diamond turning (at most 0.05 m); "
                "the coefficients are heights in m (um: 1e-6)")
        object.__setattr__(self, "coefficients", mat)
        _check_range(self.norm_radius, name="surface.norm-radius", low=1e-6,
                     high=10.0, what="a normalisation radius")

    @property
    def feature_length(self) -> float:
        """Normalisation radius over the degree, in m."""
        deg = max(len(self.coefficients), len(self.coefficients[0])) - 1
        return self.norm_radius / max(deg, 1)

    def _kernel(self) -> tuple[int, np.ndarray]:
        from ..kernels._design import XYPOLY

        mx, my = len(self.coefficients), len(self.coefficients[0])
        flat = [v for r in self.coefficients for v in r]
        return XYPOLY, np.array([self.norm_radius, float(mx), float(my), *flat])


@dataclass(frozen=True)
class SinusoidalGrid(DesignSurface):
    """Sinusoidal grid ``z = A sin(2 pi x / Lx) sin(2 pi y / Ly)``.

    Parameters
    ----------
    amplitude : float
        Amplitude A, in m (zero-to-peak).
    period_x, period_y : float
        Periods Lx and Ly along x and y, in m.
    """

    type_name: ClassVar[str] = "sinusoidal-grid"
    amplitude: float = param(unit="m", doc="amplitude A (zero to peak)")
    period_x: float = param(unit="m", doc="period along x")
    period_y: float = param(unit="m", doc="period along y")

    def __post_init__(self) -> None:
        _check_range(self.amplitude, name="surface.amplitude", low=0.0, high=5e-3,
                     what="a servo-cut amplitude", signed=True, zero=True)
        for n in ("period_x", "period_y"):
            _check_range(getattr(self, n), name=f"surface.{n.replace('_', '-')}",
                         low=1e-6, high=1.0, what="a grid period")

    @property
    def feature_length(self) -> float:
        """Half the smaller period, in m."""
        return 0.5 * min(self.period_x, self.period_y)

    def _kernel(self) -> tuple[int, np.ndarray]:
        from ..kernels._design import SINGRID

        return SINGRID, np.array([self.amplitude, self.period_x, self.period_y])


@dataclass(frozen=True)
class LensletArray(DesignSurface):
    """Micro-lens array: spherical lenslets on a flat at z = 0.

    Each lenslet is a spherical cap of signed radius ``lens_radius`` (> 0 concave
    dimples cut into the flat, vertex at ``-lens_sag``; < 0 convex bumps, vertex at
    ``+lens_sag``) whose rim, a circle of diameter ``aperture``, lies on the flat. Where
    apertures overlap the nearest lenslet wins (for equal caps it is the lowest
    dimple or the highest bump), so neighbours meet in straight ridges or valleys.

    Layouts (centre positions, (ox, oy) = (``offset_x``, ``offset_y``)):

    * ``"rectangular"``: ``(ox + i pitch, oy + j pitch_y)``;
    * ``"hexagonal"``: rows along x, ``(ox + (i + (j mod 2) / 2) pitch,
      oy + j pitch sqrt(3) / 2)``; every lens has six neighbours ``pitch`` away.

    Parameters
    ----------
    layout : {"rectangular", "hexagonal"}
        Lattice of the lens centres.
    pitch : float
        Centre distance along x (and of neighbours for hexagonal), in m.
    lens_radius : float
        Signed radius of curvature of the lenslets, in m (> 0 concave).
    aperture : float, optional
        Lens diameter on the flat, in m (<= 2 |lens_radius|). Give this or
        ``lens_sag``.
    lens_sag : float, optional
        Lens depth (concave) or height (convex) from the flat to the vertex, in m
        (<= |lens_radius|).
    pitch_y : float, optional
        Row pitch of the rectangular layout, in m (default ``pitch``).
    offset_x, offset_y : float, default: 0.0
        Position of lens (0, 0), in m.
    """

    type_name: ClassVar[str] = "lenslet-array"
    layout: Literal["rectangular", "hexagonal"] = param(doc="lens centre lattice")
    pitch: float = param(unit="m", doc="lens centre distance")
    lens_radius: float = param(unit="m", doc="signed lens radius (> 0 concave)")
    aperture: float | None = param(None, unit="m", doc="lens diameter on the flat")
    lens_sag: float | None = param(None, unit="m", doc="lens depth or height")
    pitch_y: float | None = param(None, unit="m", doc="row pitch (rectangular)")
    offset_x: float = param(0.0, unit="m", doc="x of lens (0, 0)")
    offset_y: float = param(0.0, unit="m", doc="y of lens (0, 0)")

    def __post_init__(self) -> None:
        if self.layout not in ("rectangular", "hexagonal"):
            raise ConfigError(
                f"surface.layout must be 'rectangular' or 'hexagonal', got "
                f"{self.layout!r}")
        _check_range(self.pitch, name="surface.pitch", low=1e-6, high=0.1,
                     what="a lenslet pitch")
        R = _check_range(self.lens_radius, name="surface.lens-radius", low=1e-6,
                         high=10.0, what="a lenslet radius", signed=True)
        if self.pitch_y is not None:
            if self.layout == "hexagonal":
                raise ConfigError("surface.pitch-y applies to the rectangular layout "
                                  "only (a hexagonal row pitch is pitch sqrt(3)/2)")
            _check_range(self.pitch_y, name="surface.pitch-y", low=1e-6, high=0.1,
                         what="a lenslet pitch")
        for n in ("offset_x", "offset_y"):
            check_finite(getattr(self, n), name=f"surface.{n.replace('_', '-')}")
        if (self.aperture is None) == (self.lens_sag is None):
            raise ConfigError("surface: give the lenslet size as either aperture "
                              "(diameter, m) or lens-sag (m), not both or neither")
        a = abs(R)
        if self.aperture is not None:
            d = _check_range(self.aperture, name="surface.aperture", low=1e-7,
                             high=0.1, what="a lenslet aperture")
            if d > 2 * a:
                raise ConfigError(
                    f"surface.aperture = {d:g} m exceeds the lens diameter "
                    f"2 |lens-radius| = {2 * a:g} m")
            h = a - math.sqrt(max(a * a - 0.25 * d * d, 0.0))
            object.__setattr__(self, "lens_sag", h)
        else:
            h = _check_range(self.lens_sag, name="surface.lens-sag", low=1e-10,
                             high=0.01, what="a lenslet sag")
            if h > a:
                raise ConfigError(
                    f"surface.lens-sag = {h:g} m exceeds |lens-radius| = {a:g} m (a "
                    "hemisphere)")
            object.__setattr__(self, "aperture", 2.0 * math.sqrt(2 * a * h - h * h))

    @property
    def feature_length(self) -> float:
        """Smaller of the pitch and the aperture, in m."""
        return min(self.pitch, self.aperture or self.pitch)  # type: ignore[arg-type]

    def min_concave_radius(self) -> float | None:
        """``lens_radius`` when concave, else None (m)."""
        return self.lens_radius if self.lens_radius > 0 else None

    def lens_centres(self, xmin: float, xmax: float, ymin: float,
                     ymax: float) -> np.ndarray:
        """Lens centres inside a rectangle of the design frame.

        Parameters
        ----------
        xmin, xmax, ymin, ymax : float
            Bounds in m (inclusive).

        Returns
        -------
        ndarray of shape (n, 2)
            (x, y) of the centres in m, sorted by y then x.
        """
        p = self.pitch
        if self.layout == "rectangular":
            py = self.pitch_y or p
            rows = np.arange(math.floor((ymin - self.offset_y) / py),
                             math.ceil((ymax - self.offset_y) / py) + 1)
            ys = self.offset_y + rows * py
            shifts = np.zeros(rows.size)
        else:
            py = p * _SQRT3 / 2
            rows = np.arange(math.floor((ymin - self.offset_y) / py),
                             math.ceil((ymax - self.offset_y) / py) + 1)
            ys = self.offset_y + rows * py
            shifts = 0.5 * p * (rows % 2)
        out = []
        for y, s in zip(ys, shifts, strict=True):
            i0 = math.floor((xmin - self.offset_x - s) / p)
            i1 = math.ceil((xmax - self.offset_x - s) / p)
            for i in range(i0, i1 + 1):
                x = self.offset_x + s + i * p
                if xmin <= x <= xmax and ymin <= y <= ymax:
                    out.append((x, y))
        return np.array(out, dtype=float).reshape(-1, 2)

    def _kernel(self) -> tuple[int, np.ndarray]:
        from ..kernels._design import LENS_HEX, LENS_RECT

        c = 1.0 / self.lens_radius
        a2 = 0.25 * self.aperture**2  # type: ignore[operator]
        z_rim = _conic_sag(c, 0.0, a2)
        if self.layout == "rectangular":
            return LENS_RECT, np.array([self.pitch, self.pitch_y or self.pitch, c, a2,
                                        z_rim, self.offset_x, self.offset_y])
        return LENS_HEX, np.array([self.pitch, c, a2, z_rim, self.offset_x,
                                   self.offset_y])


#: ``[surface] type`` -> design class.
DESIGN_TYPES: dict[str, type[DesignSurface]] = {
    cls.type_name: cls
    for cls in (Sphere, EvenAsphere, Biconic, XYPolynomial, SinusoidalGrid,
                LensletArray)
}


def design_from_mapping(table: Mapping[str, Any], *,
                        prefix: str = "surface") -> DesignSurface:
    """Build a design surface from a TOML ``[surface]`` table.

    Parameters
    ----------
    table : Mapping
        ``type`` (one of :data:`DESIGN_TYPES`) and the class's parameters in
        kebab-case. Aliases: ``curvature`` (1/m) for a sphere's ``radius`` (m);
        ``radius`` (m) for an asphere's ``curvature``; ``radius-x``/``radius-y`` for
        a biconic's curvatures.
    prefix : str, default: "surface"
        Dotted prefix for error messages.

    Returns
    -------
    DesignSurface
        The validated design.

    Raises
    ------
    ConfigError
        On a missing or unknown type, unknown keys or bad values.
    """
    import difflib

    tab = dict(table)
    kind = tab.pop("type", None)
    if kind not in DESIGN_TYPES:
        sugg = difflib.get_close_matches(str(kind), list(DESIGN_TYPES), n=1)
        hint = f" Did you mean: {sugg[0]!r}?" if sugg else ""
        raise ConfigError(
            f"{prefix}.type must be one of {', '.join(map(repr, DESIGN_TYPES))}, got "
            f"{kind!r}.{hint}")

    def inverse(key: str, alias: str) -> None:
        if alias in tab:
            if key in tab:
                raise ConfigError(f"{prefix}: give either {key!r} or {alias!r}, "
                                  "not both")
            v = tab.pop(alias)
            if isinstance(v, bool) or not isinstance(v, int | float) or v == 0:
                raise ConfigError(f"{prefix}.{alias}: expected a non-zero number, got "
                                  f"{v!r}")
            tab[key] = 1.0 / float(v)

    if kind == "sphere":
        inverse("radius", "curvature")
    elif kind == "asphere":
        inverse("curvature", "radius")
    elif kind == "biconic":
        inverse("curvature-x", "radius-x")
        inverse("curvature-y", "radius-y")
    elif kind == "lenslet-array":
        _pop_alias(tab, "lens-sag", "sag", 1.0, prefix)
    return from_mapping(DESIGN_TYPES[kind], tab, prefix=prefix)


# ------------------------------------------------------------ compensation
def _solver_code(solver: str) -> int:
    from ..kernels._design import MODE_SCAN, MODE_UNIQUE

    codes = {"brent": MODE_UNIQUE, "scan": MODE_SCAN}
    if solver not in codes:
        raise ConfigError(f"solver must be 'brent' or 'scan', got {solver!r}")
    return codes[solver]


def _nscan(design: DesignSurface, w: float) -> int:
    feat = design.feature_length
    if not math.isfinite(feat):
        return 64
    return int(min(max(math.ceil(2.0 * w / (feat / 8.0)), 64), 1024))


def nose_compensated_tip(design: DesignSurface, r, theta, *, nose_radius: float,
                         arc_half_angle: float = math.radians(60.0),
                         center: tuple[float, float] = (0.0, 0.0),
                         solver: Literal["brent", "scan"] = "scan",
                         ) -> tuple[np.ndarray, np.ndarray]:
    """Tip height at which a round nose touches the design without cutting into it.

    Parameters
    ----------
    design : DesignSurface
        The design.
    r : array_like
        Tool-tip radius from the spindle axis, in m (>= 0).
    theta : array_like
        Spindle angle of the tool in the workpiece frame, in rad (broadcast with r).
    nose_radius : float
        Nose radius R, in m (0: the tip follows the design).
    arc_half_angle : float, default: radians(60)
        Half-angle phi_max of the edge arc, in rad; contacts lie within
        ``|u| <= R sin(phi_max)`` of the tip.
    center : tuple of float, default: (0.0, 0.0)
        Position of the design's origin in the workpiece frame, in m.
    solver : {"scan", "brent"}, default: "scan"
        ``"scan"``: grid over the arc and golden-section refinement of every grid
        cell where the maximum could lie (any design). ``"brent"``: root of the
        stationarity condition S'(r + u) = tan(phi), valid when the section's
        second derivative stays below 1 / R (a single contact).

    Returns
    -------
    z_tip : ndarray
        Tip height in the design frame, in m.
    offset : ndarray
        Radial offset u of the contact point from the tip, in m (R sin(phi)).

    Raises
    ------
    ConfigError
        On bad arguments.

    See Also
    --------
    DesignToolpath

    Notes
    -----
    ``z_tip = max_u [S(r + u) - (R - sqrt(R**2 - u**2))]`` over the section through
    the spindle axis at angle theta (module docstring). For a sphere of signed
    radius Rs the result is the sphere of radius ``Rs - R`` with the same vertex.

    Examples
    --------
    >>> z, u = nose_compensated_tip(Sphere(radius=10e-3), 1e-3, 0.0,
    ...                             nose_radius=0.5e-3)
    >>> bool(abs(z - (9.5e-3 - (9.5e-3**2 - 1e-6) ** 0.5)) < 1e-15)
    True
    """
    from ..kernels._design import MODE_NONE, _tip_heights

    if not isinstance(design, DesignSurface):
        raise ConfigError(
            f"design must be a DesignSurface, got {type(design).__name__}")
    R = _check_range(nose_radius, name="nose_radius", low=1e-7, high=0.05,
                     what="a nose radius", zero=True)
    phi = check_finite(arc_half_angle, name="arc_half_angle")
    if not 0 < phi <= math.pi / 2:
        raise ConfigError(f"arc_half_angle must be in (0, pi/2] rad, got {phi!r}")
    mode = _solver_code(solver) if R > 0 else MODE_NONE
    rb, tb = np.broadcast_arrays(np.asarray(r, dtype=np.float64),
                                 np.asarray(theta, dtype=np.float64))
    if np.any(rb < 0) or not np.all(np.isfinite(rb)) or not np.all(np.isfinite(tb)):
        raise ConfigError("r must be finite and >= 0 m and theta finite (rad)")
    shape = rb.shape
    rf = np.ascontiguousarray(rb).ravel()
    tf = np.ascontiguousarray(tb).ravel()
    z, u = np.empty(rf.size), np.empty(rf.size)
    code, p = design._kernel()
    w = R * math.sin(phi) if phi < math.pi / 2 else R * (1 - 1e-12)
    cx, cy = (check_finite(v, name="center") for v in center)
    _tip_heights(code, p, rf, tf, cx, cy, R, w, mode, _nscan(design, w), 0.0, z, u)
    return z.reshape(shape), u.reshape(shape)


# ------------------------------------------------------------------ the path
#: Radial segments of a planned feed (scallop-height target).
PLAN_SEGMENTS = 1024
#: Largest polar grid of the band analysis, in points.
_GRID_MAX = 4_000_000


@dataclass(frozen=True)
class _Band:
    """What the band analysis found (all SI)."""

    z_max_tip: float  # highest design point over the tip band, m
    z_min: float  # lowest over the band the arc reaches, m
    z_max: float  # highest over the band the arc reaches, m
    slope_max_tip: float  # largest |dS/drho| over the tip band
    slope_max: float  # over the reached band
    d2_max: float  # largest d2S/drho2 (1/m; a concave corner is a big value)
    kappa_max: float  # largest section curvature (1/m)
    kappa_at: tuple[float, float]  # (rho, theta) of kappa_max


@dataclass(frozen=True)
class DesignToolpath(_ConstantSpeedPath):
    """Spiral slow/fast-tool-servo path that cuts a design surface.

    The tip moves inward at a constant spindle speed, ``theta(t) = theta_start +
    2 pi n t``; its radius falls from ``r_start`` to ``r_end`` at a constant feed
    per revolution or at the feed planned for a scallop-height target; its height
    is the nose-compensated tip height (module docstring) plus the datum.

    Parameters
    ----------
    design : DesignSurface
        The surface to cut.
    r_start : float
        Tool-tip radius where the cut starts, in m.
    r_end : float, default: 0.0
        Tool-tip radius where it ends, in m (< r_start; 0 cuts to the centre).
    spindle_speed : float, default: 1000 / 60
        Spindle speed n, in rev/s (TOML may give ``spindle-speed-rpm``).
    feed_per_rev : float, optional
        Constant radial feed per revolution, in m. Give this or ``scallop_height``.
    scallop_height : float, optional
        Target kinematic scallop height along z, in m: the feed per revolution is
        planned from ``h = f**2 / (8 R_eff)`` (module docstring).
    depth_of_cut : float, default: 5e-6
        Depth below the pre-cut face (z = 0) of the design's highest point over the
        tip radii r_end..r_start, in m: the datum is placed at
        ``-(depth_of_cut + that height)`` (:attr:`datum_z`).
    compensation_radius : float, default: 0.5e-3
        Nose radius R the path compensates, in m (0: the tip follows the design).
        A toolpath file takes it from ``[tool] nose-radius`` unless ``[spiral]``
        sets it.
    arc_half_angle : float, default: radians(60)
        Half-angle of the edge arc the contact may use, in rad (from ``[tool]``).
    center_x, center_y : float, default: 0.0
        Position of the design's origin on the workpiece, in m.
    theta_start : float, default: 0.0
        Tool angle at t = 0, in rad.

    Raises
    ------
    ConfigError
        On implausible values (with the likely unit slip), a design undefined over
        the band, a radial slope beyond the arc, a concave lens or sphere radius not
        larger than the nose radius, or a scallop target without a nose radius.

    Warns
    -----
    ToolpathWarning
        When the design has concave curvature sharper than the nose (or concave
        corners) over the band: the nose cannot reach there and leaves material.

    Notes
    -----
    Where the spiral ends on the axis (r_end = 0) the last, partial revolution
    leaves a few pixels within about one feed of the axis above the scallop height.

    Solver: the band r_end - w .. r_start + w (w = R sin(phi_max)) is sampled on a
    polar grid; when the section's second derivative stays below ``0.98 / R`` there
    the contact is unique and found with Brent's method on ``S' = tan(phi)``,
    otherwise the maximum is searched on a grid over the arc and refined.
    """

    design: DesignSurface = param(doc="design surface")
    r_start: float = param(unit="m", doc="start tip radius", low=0.0, low_open=True)
    r_end: float = param(0.0, unit="m", doc="end tip radius", low=0.0)
    spindle_speed: float = param(1000.0 / 60.0, unit="rev/s", doc="spindle speed",
                                 low=0.0, low_open=True)
    feed_per_rev: float | None = param(None, unit="m", doc="radial feed per rev")
    scallop_height: float | None = param(None, unit="m",
                                         doc="target kinematic scallop height")
    depth_of_cut: float = param(5e-6, unit="m",
                                doc="depth of the highest design point", low=0.0)
    compensation_radius: float = param(0.5e-3, unit="m",
                                       doc="nose radius the path compensates",
                                       low=0.0)
    arc_half_angle: float = param(math.radians(60.0), unit="rad",
                                  doc="half-angle of the edge arc")
    center_x: float = param(0.0, unit="m", doc="x of the design origin")
    center_y: float = param(0.0, unit="m", doc="y of the design origin")
    theta_start: float = param(0.0, unit="rad", doc="tool angle at t = 0")

    # ------------------------------------------------------------ set-up
    def __post_init__(self) -> None:
        if not isinstance(self.design, DesignSurface):
            raise ConfigError(
                f"design must be a DesignSurface, got {type(self.design).__name__}")
        _check_range(self.r_start, name="spiral.r-start", low=1e-6, high=0.5,
                     what="a start radius")
        _check_range(self.r_end, name="spiral.r-end", low=0.0, high=0.5,
                     what="an end radius", zero=True)
        if not self.r_end < self.r_start:
            raise ConfigError(
                f"spiral.r-end must be < spiral.r-start (the tool moves inward), got "
                f"r-start {self.r_start!r} m and r-end {self.r_end!r} m")
        n = check_finite(self.spindle_speed, name="spiral.spindle-speed")
        if not 0 < n <= 200.0:
            raise ConfigError(
                f"spiral.spindle-speed must be in (0, 200] rev/s, got {n!r} rev/s; "
                "give rpm as spindle-speed-rpm")
        if (self.feed_per_rev is None) == (self.scallop_height is None):
            raise ConfigError("spiral: give either feed-per-rev (m) or scallop-height "
                              "(m), not both or neither")
        if self.feed_per_rev is not None:
            _check_range(self.feed_per_rev, name="spiral.feed-per-rev", low=1e-9,
                         high=1e-3, what="a feed per revolution")
        else:
            _check_range(self.scallop_height, name="spiral.scallop-height",
                         low=1e-12, high=1e-5, what="a scallop height")
        _check_range(self.depth_of_cut, name="spiral.depth-of-cut", low=0.0,
                     high=1e-3, what="a finishing depth of cut", zero=True)
        R = _check_range(self.compensation_radius, name="spiral.compensation-radius",
                         low=1e-6, high=0.05, what="a nose radius", zero=True)
        phi = check_finite(self.arc_half_angle, name="tool.arc-half-angle")
        if not 0 < phi < math.pi / 2:
            raise ConfigError(
                f"tool.arc-half-angle must be in (0, pi/2) rad, got {phi!r}")
        for nm in ("center_x", "center_y", "theta_start"):
            check_finite(getattr(self, nm), name=f"spiral.{nm.replace('_', '-')}")
        rc = self.design.min_concave_radius()
        if R > 0 and rc is not None and rc <= R:
            raise ConfigError(
                f"the design's concave radius of curvature {rc:g} m is not larger "
                f"than the nose radius {R:g} m: the nose cannot cut it; use a tool "
                f"with a nose radius below {rc:g} m")
        if self.scallop_height is not None and R == 0:
            raise ConfigError("spiral.scallop-height needs a nose radius > 0 (a "
                              "pointed tip leaves no defined scallop)")
        band = self._analyse_band()
        object.__setattr__(self, "_band", band)
        from ..kernels._design import MODE_NONE, MODE_SCAN, MODE_UNIQUE

        if R == 0:
            mode = MODE_NONE
        elif band.d2_max * R < 0.98:
            mode = MODE_UNIQUE
        else:
            mode = MODE_SCAN
        object.__setattr__(self, "_mode", mode)
        if R > 0 and band.kappa_max * R >= 1.0:
            rho, th = band.kappa_at
            warnings.warn(ToolpathWarning(
                f"the design has concave curvature sharper than the nose radius "
                f"{R:g} m (a radius of curvature of {1 / band.kappa_max:.3g} m on the "
                f"sampling grid, or a concave corner) at r = {rho:.4g} m, theta = "
                f"{th:.4g} rad: the nose cannot reach there and leaves material (the "
                "path is the non-gouging envelope)"), stacklevel=3)
        datum = -(self.depth_of_cut + band.z_max_tip)
        object.__setattr__(self, "_datum", datum)
        tilt = math.atan(band.slope_max)
        depth = (self.depth_of_cut + band.z_max_tip - band.z_min
                 + 0.01 * (band.z_max - band.z_min) + R * (1.0 - math.cos(tilt)))
        object.__setattr__(self, "_max_depth", depth)
        if self.feed_per_rev is not None:
            object.__setattr__(self, "_plan", None)
        else:
            object.__setattr__(self, "_plan", self._plan_feed())

    @property
    def _w(self) -> float:
        return self.compensation_radius * math.sin(self.arc_half_angle)

    def _grid_sizes(self, rho_lo: float, rho_hi: float) -> tuple[int, int]:
        feat = min(self.design.feature_length, max(rho_hi - rho_lo, 1e-9))
        n_rho = int(min(max(math.ceil((rho_hi - rho_lo) / (feat / 16.0)), 256), 8192))
        centred = self.center_x == 0.0 and self.center_y == 0.0
        if self.design.axisymmetric and centred:
            n_th = 1
        else:
            step = feat / 8.0 if math.isfinite(self.design.feature_length) else (
                2 * math.pi * rho_hi / 512)
            n_th = int(min(max(math.ceil(2 * math.pi * rho_hi / step), 256), 8192))
            n_th = max(16, min(n_th, _GRID_MAX // n_rho))
        return n_rho, n_th

    def _analyse_band(self) -> _Band:
        """Sample the design on a polar grid over the band the arc can reach."""
        from ..kernels._design import _eval_points

        w = self._w
        lo, hi = max(self.r_end - w, 0.0), self.r_start + w
        n_rho, n_th = self._grid_sizes(lo, hi)
        th = 2 * math.pi * np.arange(n_th) / n_th
        code, p = self.design._kernel()

        def polar(rho: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
            ct, st = np.cos(th)[:, None], np.sin(th)[:, None]
            x = np.ascontiguousarray((rho[None, :] * ct - self.center_x).ravel())
            y = np.ascontiguousarray((rho[None, :] * st - self.center_y).ravel())
            z, gx, gy = (np.empty(x.size) for _ in range(3))
            _eval_points(code, p, x, y, z, gx, gy)
            shape = (n_th, rho.size)
            s1 = gx.reshape(shape) * ct + gy.reshape(shape) * st
            z = z.reshape(shape)
            bad = ~(np.isfinite(z) & np.isfinite(s1))
            if bad.any():
                j = int(np.argmax(bad.any(axis=0)))
                raise ConfigError(
                    f"the design ({self.design.type_name}) is undefined at r = "
                    f"{rho[j]:.6g} m from the spindle axis, which the tool edge "
                    f"reaches (tip radii {self.r_end:g}..{self.r_start:g} m plus the "
                    f"arc half-width {w:g} m); reduce spiral.r-start or check the "
                    "design's radius")
            return z, s1

        rho = np.linspace(lo, hi, n_rho)
        z, s1 = polar(rho)
        # the tip band on its own grid, ends included
        z_tip, s_tip = polar(np.linspace(self.r_end, self.r_start, n_rho))
        slope_tip = float(np.max(np.abs(s_tip)))
        if math.atan(slope_tip) >= self.arc_half_angle * 0.999:
            deg = math.degrees(math.atan(slope_tip))
            raise ConfigError(
                f"the design's radial slope reaches {deg:.1f} degrees over the tip "
                f"radii {self.r_end:g}..{self.r_start:g} m, "
                f"beyond the edge arc's half-angle of "
                f"{math.degrees(self.arc_half_angle):.1f} degrees: the edge cannot "
                "touch it")
        drho = rho[1] - rho[0]
        d2 = np.diff(s1, axis=1) / drho
        s_mid = 0.5 * (s1[:, 1:] + s1[:, :-1])
        kappa = d2 / (1.0 + s_mid**2) ** 1.5
        k = np.unravel_index(int(np.argmax(kappa)), kappa.shape)
        return _Band(
            z_max_tip=float(np.max(z_tip)),
            z_min=float(np.min(z)),
            z_max=float(np.max(z)),
            slope_max_tip=slope_tip,
            slope_max=float(np.max(np.abs(s1))),
            d2_max=float(np.max(d2)),
            kappa_max=float(kappa[k]),
            kappa_at=(float(rho[k[1]] + 0.5 * drho), float(th[k[0]])),
        )

    def contact_geometry(self, r, theta) -> dict[str, np.ndarray]:
        """Contact point, slope and curvature under the tip.

        Parameters
        ----------
        r, theta : array_like
            Tip radius (m) and spindle angle (rad), broadcast together.

        Returns
        -------
        dict
            ``offset`` (m): radial offset u of the contact from the tip;
            ``slope``: dS/drho at the contact; ``curvature`` (1/m): the section's
            curvature there (concave positive); ``r_eff`` (m): the effective radius
            ``R (1 - R kappa) cos(phi)**3`` of the scallop formula (NaN where the
            nose cannot reach, R kappa >= 0.99, or the contact is at the arc's end).
        """
        from ..kernels._design import _contact_geometry

        rb, tb = np.broadcast_arrays(np.asarray(r, dtype=np.float64),
                                     np.asarray(theta, dtype=np.float64))
        shape = rb.shape
        rf = np.ascontiguousarray(rb).ravel()
        tf = np.ascontiguousarray(tb).ravel()
        u, s, d2 = (np.empty(rf.size) for _ in range(3))
        code, p = self.design._kernel()
        R = self.compensation_radius
        feat = min(self.design.feature_length, R if R > 0 else math.inf,
                   self.r_start)
        delta = 1e-4 * feat
        _contact_geometry(code, p, rf, tf, self.center_x, self.center_y, R, self._w,
                          self._mode, self._n_scan, delta, u, s, d2)
        cos_phi = 1.0 / np.sqrt(1.0 + s * s)
        kappa = d2 * cos_phi**3
        reff = R * (1.0 - R * kappa) * cos_phi**3
        bad = ~np.isfinite(reff) | (R * kappa >= 0.99) | (np.abs(u) >= 0.999 * self._w)
        reff = np.where(bad, np.nan, reff)
        return {"offset": u.reshape(shape), "slope": s.reshape(shape),
                "curvature": kappa.reshape(shape), "r_eff": reff.reshape(shape)}

    def _plan_feed(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(t nodes (s), r nodes (m), segment feeds (m/rev)) for the scallop target."""
        h = float(self.scallop_height)  # type: ignore[arg-type]
        n_seg = PLAN_SEGMENTS
        radii = np.linspace(self.r_start, self.r_end, n_seg + 1)
        _, n_th = self._grid_sizes(self.r_end, self.r_start)
        n_th = max(1, min(n_th, 2048))
        th = 2 * math.pi * np.arange(n_th) / n_th
        geo = self.contact_geometry(radii[:, None], th[None, :])
        with np.errstate(invalid="ignore"):
            f = np.sqrt(8.0 * h * geo["r_eff"])
        if not np.isfinite(f).any(axis=1).all():
            k = int(np.argmin(np.isfinite(f).any(axis=1)))
            raise ConfigError(
                f"cannot plan the feed for spiral.scallop-height at r = {radii[k]:.6g}"
                " m: the nose reaches no point of the design there (contact at the "
                "arc's end or concave curvature beyond the nose)")
        f_r = np.nanmin(f, axis=1)
        f_seg = np.minimum(f_r[:-1], f_r[1:])
        dt = (radii[:-1] - radii[1:]) / (self.spindle_speed * f_seg)
        t = np.concatenate(([0.0], np.cumsum(dt)))
        return t, radii, f_seg

    # -------------------------------------------------------- path protocol
    @property
    def _n_scan(self) -> int:
        return _nscan(self.design, self._w)

    @property
    def rev_per_s(self) -> float:
        """Spindle speed, in rev/s."""
        return self.spindle_speed

    @property
    def theta0(self) -> float:
        """Tool angle at t = 0, in rad."""
        return self.theta_start

    @property
    def datum_z(self) -> float:
        """Height of the design's datum (z = 0 of the sag) on the workpiece, in m."""
        return self._datum  # type: ignore[attr-defined]

    @property
    def max_depth(self) -> float:
        """Upper bound of the tip's depth below the pre-cut face z = 0, in m."""
        return self._max_depth  # type: ignore[attr-defined]

    @property
    def solver(self) -> str:
        """Contact solver in use: ``"none"``, ``"brent"`` or ``"scan"``."""
        return ("none", "brent", "scan")[self._mode]  # type: ignore[attr-defined]

    @property
    def duration(self) -> float:
        """Cutting time from r_start to r_end, in s."""
        if self._plan is None:  # type: ignore[attr-defined]
            return (self.r_start - self.r_end) / (self.feed_per_rev
                                                  * self.spindle_speed)
        return float(self._plan[0][-1])  # type: ignore[attr-defined]

    @property
    def n_revolutions(self) -> float:
        """Number of revolutions of the cut."""
        return self.duration * self.spindle_speed

    def radius_at(self, t: np.ndarray) -> np.ndarray:
        """Tool-tip radius at times ``t`` (s), in m."""
        t = np.asarray(t, dtype=float)
        if self._plan is None:  # type: ignore[attr-defined]
            r = self.r_start - (self.feed_per_rev * self.spindle_speed) * t
            return np.maximum(r, 0.0)
        tt, rr, _ = self._plan  # type: ignore[attr-defined]
        return np.maximum(np.interp(t, tt, rr), 0.0)

    def feed_at(self, t: np.ndarray) -> np.ndarray:
        """Radial feed per revolution at times ``t`` (s), in m."""
        t = np.asarray(t, dtype=float)
        if self._plan is None:  # type: ignore[attr-defined]
            return np.full(t.shape, float(self.feed_per_rev))
        tt, _, f = self._plan  # type: ignore[attr-defined]
        j = np.clip(np.searchsorted(tt, t, side="right") - 1, 0, f.size - 1)
        return f[j]

    def feed_at_radius(self, r: np.ndarray) -> np.ndarray:
        """Radial feed per revolution when the tip is at radius ``r`` (m), in m."""
        r = np.asarray(r, dtype=float)
        if self._plan is None:  # type: ignore[attr-defined]
            return np.full(r.shape, float(self.feed_per_rev))
        _, rr, f = self._plan  # type: ignore[attr-defined]
        j = np.searchsorted(-rr, -r, side="right") - 1
        return f[np.clip(j, 0, f.size - 1)]

    def tip_height(self, r, theta) -> np.ndarray:
        """Commanded tip height on the workpiece at tip radius r and angle theta.

        Parameters
        ----------
        r, theta : array_like
            Tip radius (m) and spindle angle (rad), broadcast together.

        Returns
        -------
        ndarray
            Height in m: the compensated tip height plus :attr:`datum_z`.
        """
        from ..kernels._design import _tip_heights

        rb, tb = np.broadcast_arrays(np.asarray(r, dtype=np.float64),
                                     np.asarray(theta, dtype=np.float64))
        rf = np.ascontiguousarray(rb).ravel()
        tf = np.ascontiguousarray(tb).ravel()
        z, u = np.empty(rf.size), np.empty(rf.size)
        code, p = self.design._kernel()
        _tip_heights(code, p, rf, tf, self.center_x, self.center_y,
                     self.compensation_radius, self._w, self._mode, self._n_scan,
                     self.datum_z, z, u)
        return z.reshape(rb.shape)

    def z_at(self, t: np.ndarray) -> np.ndarray:
        """Commanded tool-tip height at times ``t`` (s), in m."""
        t = np.asarray(t, dtype=float)
        return self.tip_height(self.radius_at(t), self.theta_at(t))

    def design_height(self, x, y) -> np.ndarray:
        """The design on the workpiece: sag at (x - center_x, y - center_y) + datum.

        Parameters
        ----------
        x, y : array_like
            Workpiece positions, in m.

        Returns
        -------
        ndarray
            Heights in m (the surface a perfect cut with no scallop would leave).
        """
        x = np.asarray(x, dtype=float) - self.center_x
        y = np.asarray(y, dtype=float) - self.center_y
        return self.design.sag(x, y) + self.datum_z

    def sag(self, x, y) -> np.ndarray:
        """Alias of :meth:`design_height` (the design in the workpiece frame, m)."""
        return self.design_height(x, y)

    def predicted_scallop(self, r, theta) -> np.ndarray:
        """Kinematic scallop height along z at tip radius r and angle theta, in m.

        Parameters
        ----------
        r, theta : array_like
            Tip radius (m) and spindle angle (rad).

        Returns
        -------
        ndarray
            ``f(r)**2 / (8 R_eff)`` (module docstring); NaN where undefined.
        """
        geo = self.contact_geometry(r, theta)
        f = self.feed_at_radius(np.broadcast_to(np.asarray(r, dtype=float),
                                                geo["r_eff"].shape))
        return f**2 / (8.0 * geo["r_eff"])

    def _fill(self, starts, stops, fs, t, theta, r, z) -> None:
        """Write samples k in [starts[m], stops[m]) into t, theta, r, z (numba)."""
        from ..kernels._design import _sample_design

        code, p = self.design._kernel()
        if self._plan is None:  # type: ignore[attr-defined]
            tt = rr = np.zeros(1)
            linear = True
            rate = self.feed_per_rev * self.spindle_speed
        else:
            tt, rr, _ = self._plan  # type: ignore[attr-defined]
            linear = False
            rate = 0.0
        _sample_design(starts, stops, fs, self.theta0, self.angular_speed, linear,
                       self.r_start, rate, np.ascontiguousarray(tt),
                       np.ascontiguousarray(rr), code, p, self.center_x,
                       self.center_y, self.compensation_radius, self._w, self._mode,
                       self._n_scan, self.datum_z, t, theta, r, z)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready description of the path (SI, units in the keys)."""
        return {
            "design": self.design.to_dict(),
            "r_start_m": self.r_start,
            "r_end_m": self.r_end,
            "spindle_speed_rev_per_s": self.spindle_speed,
            "feed_per_rev_m": self.feed_per_rev,
            "scallop_height_m": self.scallop_height,
            "depth_of_cut_m": self.depth_of_cut,
            "compensation_radius_m": self.compensation_radius,
            "center_x_m": self.center_x,
            "center_y_m": self.center_y,
            "datum_z_m": self.datum_z,
            "solver": self.solver,
            "duration_s": self.duration,
        }


_SPIRAL_KEYS = ("spindle-speed", "spindle-speed-rpm", "r-start", "r-end",
                "feed-per-rev", "scallop-height", "depth-of-cut",
                "compensation-radius", "center-x", "center-y", "theta-start")


def design_toolpath_from_mapping(surface: Mapping[str, Any], spiral: Mapping[str, Any],
                                 tool) -> DesignToolpath:
    """Build a :class:`DesignToolpath` from the ``[surface]`` and ``[spiral]`` tables.

    Parameters
    ----------
    surface : Mapping
        The ``[surface]`` table (see :func:`design_from_mapping`).
    spiral : Mapping
        The ``[spiral]`` table: ``spindle-speed`` (rev/s) or ``spindle-speed-rpm``,
        ``r-start``, ``r-end``, ``feed-per-rev`` or ``scallop-height``,
        ``depth-of-cut``, optional ``compensation-radius``, ``center-x``,
        ``center-y``, ``theta-start`` (SI units).
    tool : Tool
        The tool; its nose radius is the default compensation radius and its arc
        half-angle bounds the contact.

    Returns
    -------
    DesignToolpath
        The validated path.

    Raises
    ------
    ConfigError
        On unknown keys (with suggestions) or bad values.
    """
    import difflib

    design = design_from_mapping(surface)
    tab = dict(spiral)
    for key in tab:
        if key not in _SPIRAL_KEYS:
            sugg = difflib.get_close_matches(str(key), _SPIRAL_KEYS, n=1)
            hint = f" Did you mean: spiral.{sugg[0]}?" if sugg else ""
            raise ConfigError(f"unknown key 'spiral.{key}'.{hint} Allowed keys here: "
                              f"{', '.join(_SPIRAL_KEYS)}")
    _pop_alias(tab, "spindle-speed", "spindle-speed-rpm", 1.0 / 60.0, "spiral")
    if "r-start" not in tab:
        raise ConfigError("missing required key(s): spiral.r-start")
    tab.setdefault("compensation-radius", tool.nose_radius)
    tab["arc-half-angle"] = tool.arc_half_angle
    tab["design"] = design
    return from_mapping(DesignToolpath, tab, prefix="spiral")
