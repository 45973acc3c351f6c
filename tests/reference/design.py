"""Plain-numpy references of the design-surface kernels (servosurf.kernels._design).

Each sag is written out from its textbook formula with numpy; the gradient comes
from the analytic derivative where it is one line and otherwise from central
differences. The nose-compensated tip is a brute-force maximum over a dense grid of
the edge arc, refined on a second, finer grid around the best points. SI units.
"""

from __future__ import annotations

import numpy as np

__all__ = ["sag", "gradient", "tip_height", "RTOL_SAG", "ATOL_SAG", "ATOL_SLOPE_FD",
           "ATOL_TIP", "ATOL_CLOSED_FORM"]

#: Kernel sag against the numpy formula: same formula, different rounding.
RTOL_SAG = 1e-12
#: ... plus the cancellation of the reference's R - sqrt(R^2 - r^2) near a vertex,
#: eps R = 2e-18 m for R = 10 mm (10 am).
ATOL_SAG = 1e-17
#: Kernel gradient against central differences of the reference sag (1e-9 m step,
#: heights up to 1 mm: rounding of 2e-16 * 1e-3 / 1e-9 = 2e-10, curvature 1e-9 / R).
ATOL_SLOPE_FD = 1e-7
#: Kernel tip against the brute-force maximum, in m (2 pm): the fine grid's step of
#: 4 pm times the slope of F at a corner of the section.
ATOL_TIP = 2e-12
#: Tip against a closed form (sphere, plane), in m (1 fm): rounding only.
ATOL_CLOSED_FORM = 1e-15


def _conic(c, k, r2):
    return c * r2 / (1.0 + np.sqrt(1.0 - (1.0 + k) * c * c * r2))


def sag(design, x, y):
    """Sag in m of a servosurf design object at (x, y) (m), plain numpy.

    Parameters
    ----------
    design : DesignSurface
        Only its public parameters are read.
    x, y : ndarray
        Positions in m.

    Returns
    -------
    ndarray
        Heights in m.
    """
    name = type(design).__name__
    x = np.asarray(x, dtype=float)
    y = np.asarray(y, dtype=float)
    r2 = x * x + y * y
    if name == "Sphere":
        R = design.radius
        return np.sign(R) * (abs(R) - np.sqrt(R * R - r2))
    if name == "EvenAsphere":
        z = _conic(design.curvature, design.conic, r2)
        for i, a in enumerate(design.coefficients):
            z = z + a * r2 ** (i + 2)
        return z
    if name == "Biconic":
        cx, cy = design.curvature_x, design.curvature_y
        kx, ky = design.conic_x, design.conic_y
        q = 1 - (1 + kx) * cx**2 * x**2 - (1 + ky) * cy**2 * y**2
        return (cx * x**2 + cy * y**2) / (1 + np.sqrt(q))
    if name == "XYPolynomial":
        c = np.array(design.coefficients)
        rn = design.norm_radius
        return np.polynomial.polynomial.polyval2d(x / rn, y / rn, c)
    if name == "SinusoidalGrid":
        return (design.amplitude * np.sin(2 * np.pi * x / design.period_x)
                * np.sin(2 * np.pi * y / design.period_y))
    if name == "LensletArray":
        R = design.lens_radius
        a = design.aperture / 2
        p = design.pitch
        if design.layout == "rectangular":
            py = design.pitch_y or p
            centres = [(design.offset_x + i * p, design.offset_y + j * py)
                       for i in range(-60, 61) for j in range(-60, 61)]
        else:
            centres = [(design.offset_x + (i + 0.5 * (j % 2)) * p,
                        design.offset_y + j * p * np.sqrt(3) / 2)
                       for i in range(-60, 61) for j in range(-70, 71)]
        lo_x, hi_x = x.min() - 2 * p, x.max() + 2 * p
        lo_y, hi_y = y.min() - 2 * p, y.max() + 2 * p
        centres = [(cx, cy) for cx, cy in centres
                   if lo_x <= cx <= hi_x and lo_y <= cy <= hi_y]
        best = np.full(np.broadcast(x, y).shape, np.inf)
        for cx, cy in centres:
            best = np.minimum(best, (x - cx) ** 2 + (y - cy) ** 2)
        cap = np.sign(R) * (abs(R) - np.sqrt(np.clip(R * R - best, 0, None)))
        rim = np.sign(R) * (abs(R) - np.sqrt(R * R - a * a))
        return np.where(best < a * a, cap - rim, 0.0)
    raise TypeError(name)


def gradient(design, x, y, step=1e-9):
    """Central-difference gradient of :func:`sag` (dimensionless)."""
    gx = (sag(design, x + step, y) - sag(design, x - step, y)) / (2 * step)
    gy = (sag(design, x, y + step) - sag(design, x, y - step)) / (2 * step)
    return gx, gy


def tip_height(design, r, theta, nose_radius, arc_half_angle, center=(0.0, 0.0),
               n=20001):
    """Brute-force nose-compensated tip height (m) at one tip radius and angle.

    ``max_u [S(r + u) - (R - sqrt(R^2 - u^2))]`` over ``|u| <= R sin(phi_max)``
    on ``n`` points, then on ``n`` points within two steps of the three best
    local maxima.
    """
    R = nose_radius
    w = R * np.sin(arc_half_angle)
    c, s = np.cos(theta), np.sin(theta)

    def F(u):
        rho = r + u
        z = sag(design, rho * c - center[0], rho * s - center[1])
        return z - (R - np.sqrt(R * R - u * u))

    u = np.linspace(-w, w, n)
    f = F(u)
    du = u[1] - u[0]
    peaks = [i for i in range(n)
             if (i == 0 or f[i] >= f[i - 1]) and (i == n - 1 or f[i] >= f[i + 1])]
    peaks = sorted(peaks, key=lambda i: -f[i])[:3]
    best = -np.inf
    for i in peaks:
        v = np.linspace(max(-w, u[i] - 2 * du), min(w, u[i] + 2 * du), n)
        best = max(best, float(np.max(F(v))))
    return best
