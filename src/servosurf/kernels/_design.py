"""Numba kernels: design-surface sags, gradients and the nose-compensated tool tip.

Checked public wrappers: the design classes of :mod:`servosurf.toolpath` (``sag``,
``gradient``), :func:`servosurf.toolpath.nose_compensated_tip` and
:class:`servosurf.toolpath.DesignToolpath` (``z_at`` and sampling). Plain-numpy
references: ``tests/reference/design.py``.

Frames (SI: m, rad)
-------------------
A design is a sag ``z = S(x, y)`` in m, z up (away from the material), 0 at the
design's datum. It is addressed by an integer ``code`` and a float64 parameter
vector ``p`` whose layout per code is:

=====================  ==========================================================
``SPHERE``             ``[c]``: curvature 1/R (1/m)
``ASPHERE``            ``[c, k, n, A4, A6, ...]``: curvature (1/m), conic constant,
                       number n of even terms, then A_{2i} (m^(1 - 2i)), i = 2..n+1
``BICONIC``            ``[cx, cy, kx, ky]``
``XYPOLY``             ``[rn, mx, my, C00, C01, ..., C(mx-1)(my-1)]``: normalisation
                       radius (m), matrix shape, coefficients (m) of
                       ``(x / rn)**i (y / rn)**j``, row-major in i
``SINGRID``            ``[A, Lx, Ly]``: amplitude and periods (m)
``LENS_RECT``          ``[px, py, c, a2, z_rim, ox, oy]``: pitches (m), lens
                       curvature (1/m), squared aperture radius (m^2), sag of the
                       sphere at the rim (m), lattice offset (m)
``LENS_HEX``           ``[p, c, a2, z_rim, ox, oy]``: centre distance (m), then as
                       for ``LENS_RECT``
=====================  ==========================================================

Nose compensation
-----------------
The tool's edge is a circular arc of radius R in the radial-axial plane (the sweep
model of :mod:`servosurf.kernels._sweep`). At tip radius r and spindle angle theta
the edge point at radial offset u (|u| <= w = R sin(phi_max)) sits at height
``z_tip + R - sqrt(R**2 - u**2)``. The radial section of the design through the axis
is ``S(rho) = sag(rho cos theta - x_c, rho sin theta - y_c)`` for signed rho (rho < 0
is across the axis). The edge does not cut into the design when

    z_tip = max_u F(u),   F(u) = S(r + u) - (R - sqrt(R**2 - u**2)).

At a smooth contact F'(u) = 0: S'(r + u) = u / sqrt(R**2 - u**2) = tan(phi) with
u = R sin(phi), i.e. the contact point sits at the arc angle phi = atan(dS/drho) and
the tip is offset from it by (-R sin(phi), -R (1 - cos(phi))). The tangential slope
does not enter: the edge lies in the plane theta = const and touches the design only
in that plane.

Two solvers: ``MODE_UNIQUE`` brackets the root of F' on [-w, w] with Brent's method
(valid when F is concave there, which holds when S'' < 1 / R along the section);
``MODE_SCAN`` evaluates F on a grid over [-w, w] and refines by golden-section
search every grid cell where F could exceed the best grid value: where the cell's
mean design height plus twice the largest design slope between grid points times
half a cell, minus the arc's lowest height in the cell, is above it (any section,
including concave corners).
``MODE_NONE`` puts the tip on the design (no compensation).
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from ._config import CACHE, FASTMATH

__all__ = [
    "SPHERE",
    "ASPHERE",
    "BICONIC",
    "XYPOLY",
    "SINGRID",
    "LENS_RECT",
    "LENS_HEX",
    "MODE_NONE",
    "MODE_UNIQUE",
    "MODE_SCAN",
    "_eval",
    "_eval_points",
    "_tip",
    "_tip_heights",
    "_contact_geometry",
    "_sample_design",
]

SPHERE, ASPHERE, BICONIC, XYPOLY, SINGRID, LENS_RECT, LENS_HEX = 1, 2, 3, 4, 5, 6, 7
MODE_NONE, MODE_UNIQUE, MODE_SCAN = 0, 1, 2

_TWO_PI = 2.0 * np.pi
_SQRT3 = np.sqrt(3.0)
_GOLD = 0.5 * (np.sqrt(5.0) - 1.0)
_EPS = 2.220446049250313e-16


@njit(cache=CACHE, fastmath=FASTMATH)
def _lens(c, a2, z_rim, dx, dy):  # pragma: no cover - numba
    """Lenslet of curvature ``c`` (1/m) at offset (dx, dy) from its centre (m)."""
    rho2 = dx * dx + dy * dy
    if rho2 >= a2:
        return 0.0, 0.0, 0.0
    s = np.sqrt(1.0 - c * c * rho2)
    return c * rho2 / (1.0 + s) - z_rim, c * dx / s, c * dy / s


@njit(cache=CACHE, fastmath=FASTMATH)
def _eval(code, p, x, y):  # pragma: no cover - numba
    """Sag and gradient of design ``code`` with parameters ``p`` at (x, y).

    Parameters
    ----------
    code : int
        Design type (module constants).
    p : ndarray of float64
        Parameters (layout in the module docstring).
    x, y : float
        Position in the design frame, in m.

    Returns
    -------
    z, gx, gy : float
        Sag in m and its partial derivatives dz/dx, dz/dy (dimensionless); NaN
        outside the design's domain (beyond a sphere's or conic's edge).
    """
    nan = np.nan
    if code == SPHERE or code == ASPHERE:
        c = p[0]
        k = p[1] if code == ASPHERE else 0.0
        r2 = x * x + y * y
        q = 1.0 - (1.0 + k) * c * c * r2
        if q < 0.0:
            return nan, nan, nan
        s = np.sqrt(q)
        z = c * r2 / (1.0 + s)
        if s == 0.0:
            return z, nan, nan
        dzr = c / s  # (dz/dr) / r
        if code == ASPHERE:
            n = int(p[2])
            r2k = r2  # r^(2i - 2) for i = 2 .. n + 1
            for m in range(n):
                a = p[3 + m]
                z += a * r2k * r2
                dzr += 2.0 * (m + 2) * a * r2k
                r2k *= r2
        return z, dzr * x, dzr * y
    if code == BICONIC:
        cx, cy, kx, ky = p[0], p[1], p[2], p[3]
        num = cx * x * x + cy * y * y
        q = 1.0 - (1.0 + kx) * cx * cx * x * x - (1.0 + ky) * cy * cy * y * y
        if q < 0.0:
            return nan, nan, nan
        s = np.sqrt(q)
        d = 1.0 + s
        z = num / d
        if s == 0.0:
            return z, nan, nan
        d2 = d * d
        gx = (2.0 * cx * x * d + num * (1.0 + kx) * cx * cx * x / s) / d2
        gy = (2.0 * cy * y * d + num * (1.0 + ky) * cy * cy * y / s) / d2
        return z, gx, gy
    if code == XYPOLY:
        rn = p[0]
        mx = int(p[1])
        my = int(p[2])
        u = x / rn
        v = y / rn
        z = 0.0
        gx = 0.0
        gy = 0.0
        ui = 1.0  # u^i
        uim1 = 0.0  # i u^(i-1)
        for i in range(mx):
            vj = 1.0
            vjm1 = 0.0
            for j in range(my):
                cij = p[3 + i * my + j]
                z += cij * ui * vj
                gx += cij * uim1 * vj
                gy += cij * ui * vjm1
                vjm1 = (j + 1) * vj
                vj *= v
            uim1 = (i + 1) * ui
            ui *= u
        return z, gx / rn, gy / rn
    if code == SINGRID:
        a, lx, ly = p[0], p[1], p[2]
        kx = _TWO_PI / lx
        ky = _TWO_PI / ly
        sx = np.sin(kx * x)
        sy = np.sin(ky * y)
        return a * sx * sy, a * kx * np.cos(kx * x) * sy, a * ky * sx * np.cos(ky * y)
    if code == LENS_RECT:
        px, py, c, a2, z_rim, ox, oy = p[0], p[1], p[2], p[3], p[4], p[5], p[6]
        dx = x - ox - px * np.floor((x - ox) / px + 0.5)
        dy = y - oy - py * np.floor((y - oy) / py + 0.5)
        return _lens(c, a2, z_rim, dx, dy)
    if code == LENS_HEX:
        pt, c, a2, z_rim, ox, oy = p[0], p[1], p[2], p[3], p[4], p[5]
        ry = pt * _SQRT3  # row pair height: sublattices A (rows 0, 2, ..) and B
        xa = x - ox
        ya = y - oy
        dxa = xa - pt * np.floor(xa / pt + 0.5)
        dya = ya - ry * np.floor(ya / ry + 0.5)
        xb = xa - 0.5 * pt
        yb = ya - 0.5 * ry
        dxb = xb - pt * np.floor(xb / pt + 0.5)
        dyb = yb - ry * np.floor(yb / ry + 0.5)
        if dxb * dxb + dyb * dyb < dxa * dxa + dya * dya:
            return _lens(c, a2, z_rim, dxb, dyb)
        return _lens(c, a2, z_rim, dxa, dya)
    return nan, nan, nan


@njit(parallel=True, cache=CACHE, fastmath=FASTMATH)
def _eval_points(code, p, x, y, z, gx, gy):  # pragma: no cover - numba
    """Sag and gradient at many points (flat arrays).

    Parameters
    ----------
    code : int
        Design type.
    p : ndarray of float64
        Parameters.
    x, y : ndarray of shape (n,)
        Positions in m.
    z, gx, gy : ndarray of shape (n,)
        Output: sag (m) and gradient (dimensionless).
    """
    for i in prange(x.size):
        z[i], gx[i], gy[i] = _eval(code, p, x[i], y[i])


@njit(cache=CACHE, fastmath=FASTMATH)
def _arc(R, u):  # pragma: no cover - numba
    """Height of the edge arc above its tip at radial offset u: R - sqrt(R^2 - u^2)."""
    return u * u / (R + np.sqrt(R * R - u * u))


@njit(cache=CACHE, fastmath=FASTMATH)
def _section(code, p, rho, ct, st, cx, cy):  # pragma: no cover - numba
    """Section height S(rho) (m) and slope dS/drho along direction (ct, st)."""
    z, gx, gy = _eval(code, p, rho * ct - cx, rho * st - cy)
    return z, gx * ct + gy * st


@njit(cache=CACHE, fastmath=FASTMATH)
def _objective(code, p, r, ct, st, cx, cy, R, u):  # pragma: no cover - numba
    """F(u) = S(r + u) - arc(u), in m; -inf where the design is undefined."""
    z, _ = _section(code, p, r + u, ct, st, cx, cy)
    if z != z:
        return -np.inf
    return z - _arc(R, u)


@njit(cache=CACHE, fastmath=FASTMATH)
def _dobjective(code, p, r, ct, st, cx, cy, R, u):  # pragma: no cover - numba
    """F'(u) = S'(r + u) - u / sqrt(R^2 - u^2) (dimensionless)."""
    _, s1 = _section(code, p, r + u, ct, st, cx, cy)
    return s1 - u / np.sqrt(R * R - u * u)


@njit(cache=CACHE, fastmath=FASTMATH)
def _brent(code, p, r, ct, st, cx, cy, R, a, b, fa, fb, tol):  # pragma: no cover
    """Root of F' in [a, b] with fa = F'(a) > 0 > fb = F'(b) (Brent's method)."""
    c, fc = b, fb
    d = b - a
    e = d
    for _ in range(200):
        if (fb > 0.0 and fc > 0.0) or (fb < 0.0 and fc < 0.0):
            c, fc = a, fa
            d = b - a
            e = d
        if abs(fc) < abs(fb):
            a, b, c = b, c, b
            fa, fb, fc = fb, fc, fb
        tol1 = 2.0 * _EPS * abs(b) + 0.5 * tol
        xm = 0.5 * (c - b)
        if abs(xm) <= tol1 or fb == 0.0:
            return b
        if abs(e) >= tol1 and abs(fa) > abs(fb):
            s = fb / fa
            if a == c:
                pp = 2.0 * xm * s
                q = 1.0 - s
            else:
                q = fa / fc
                rr = fb / fc
                pp = s * (2.0 * xm * q * (q - rr) - (b - a) * (rr - 1.0))
                q = (q - 1.0) * (rr - 1.0) * (s - 1.0)
            if pp > 0.0:
                q = -q
            pp = abs(pp)
            min1 = 3.0 * xm * q - abs(tol1 * q)
            min2 = abs(e * q)
            if 2.0 * pp < min(min1, min2):
                e = d
                d = pp / q
            else:
                d = xm
                e = d
        else:
            d = xm
            e = d
        a, fa = b, fb
        if abs(d) > tol1:
            b += d
        else:
            b += tol1 if xm > 0.0 else -tol1
        fb = _dobjective(code, p, r, ct, st, cx, cy, R, b)
    return b


@njit(cache=CACHE, fastmath=FASTMATH)
def _golden(code, p, r, ct, st, cx, cy, R, a, b, tol):  # pragma: no cover - numba
    """Maximise F on [a, b] by golden-section search; returns (u, F(u))."""
    c = b - _GOLD * (b - a)
    d = a + _GOLD * (b - a)
    fc = _objective(code, p, r, ct, st, cx, cy, R, c)
    fd = _objective(code, p, r, ct, st, cx, cy, R, d)
    for _ in range(200):
        if b - a <= tol:
            break
        if fc >= fd:
            b, d, fd = d, c, fc
            c = b - _GOLD * (b - a)
            fc = _objective(code, p, r, ct, st, cx, cy, R, c)
        else:
            a, c, fc = c, d, fd
            d = a + _GOLD * (b - a)
            fd = _objective(code, p, r, ct, st, cx, cy, R, d)
    if fc >= fd:
        return c, fc
    return d, fd


@njit(cache=CACHE, fastmath=FASTMATH)
def _tip(code, p, r, theta, cx, cy, R, w, mode, nscan):  # pragma: no cover - numba
    """Nose-compensated tip height at tip radius r and angle theta.

    Parameters
    ----------
    code : int
        Design type.
    p : ndarray of float64
        Design parameters.
    r : float
        Tool-tip radius, in m (>= 0).
    theta : float
        Spindle angle of the tool in the workpiece frame, in rad.
    cx, cy : float
        Position of the design's origin in the workpiece frame, in m.
    R : float
        Nose radius the path compensates, in m.
    w : float
        Radial half-width of the edge arc R sin(phi_max), in m (< R).
    mode : int
        ``MODE_NONE``, ``MODE_UNIQUE`` or ``MODE_SCAN``.
    nscan : int
        Grid intervals over [-w, w] for ``MODE_SCAN``.

    Returns
    -------
    z_tip : float
        Tip height in the design frame, in m (``max_u F(u)``, module docstring).
    u : float
        Radial offset of the contact point from the tip, in m.
    """
    ct = np.cos(theta)
    st = np.sin(theta)
    if mode == MODE_NONE or R <= 0.0:
        z, _ = _section(code, p, r, ct, st, cx, cy)
        return z, 0.0
    tol = 1e-10 * R
    if mode == MODE_UNIQUE:
        fa = _dobjective(code, p, r, ct, st, cx, cy, R, -w)
        if not fa > 0.0:
            u = -w
        else:
            fb = _dobjective(code, p, r, ct, st, cx, cy, R, w)
            if not fb < 0.0:
                u = w
            else:
                u = _brent(code, p, r, ct, st, cx, cy, R, -w, w, fa, fb, tol)
        return _objective(code, p, r, ct, st, cx, cy, R, u), u
    # MODE_SCAN: grid, then refine every cell whose bound could beat the best
    du = 2.0 * w / nscan
    sv = np.empty(nscan + 1)  # S(r + u_i) - the design on the grid, -inf undefined
    best = -np.inf
    u_best = 0.0
    lip = 0.0
    for i in range(nscan + 1):
        u = -w + i * du
        fi = _objective(code, p, r, ct, st, cx, cy, R, u)
        sv[i] = fi + _arc(R, u)
        if fi > best:
            best = fi
            u_best = u
        if i > 0 and sv[i] > -np.inf and sv[i - 1] > -np.inf:
            lip = max(lip, abs(sv[i] - sv[i - 1]) / du)
    if not best > -np.inf:
        return np.nan, 0.0
    lip *= 2.0  # the design's slope between grid points, with a safety factor
    for i in range(nscan):
        if not (sv[i] > -np.inf and sv[i + 1] > -np.inf):
            continue
        a = -w + i * du
        b = a + du
        near = 0.0 if a <= 0.0 <= b else min(abs(a), abs(b))
        bound = 0.5 * (sv[i] + sv[i + 1] + lip * du) - _arc(R, near)
        if bound <= best:
            continue
        u, fu = _golden(code, p, r, ct, st, cx, cy, R, a, b, tol)
        if fu > best:
            best = fu
            u_best = u
    return best, u_best


@njit(parallel=True, cache=CACHE, fastmath=FASTMATH)
def _tip_heights(code, p, r, theta, cx, cy, R, w, mode, nscan, offset, z,
                 u):  # pragma: no cover - numba
    """Compensated tip heights for arrays of tip radius and angle.

    Parameters
    ----------
    code, p, cx, cy, R, w, mode, nscan
        As for :func:`_tip`.
    r, theta : ndarray of shape (n,)
        Tip radius (m) and angle (rad).
    offset : float
        Added to every height (the datum of the design in the workpiece frame), m.
    z, u : ndarray of shape (n,)
        Output: tip height (m) and contact offset (m).
    """
    for i in prange(r.size):
        zi, ui = _tip(code, p, r[i], theta[i], cx, cy, R, w, mode, nscan)
        z[i] = zi + offset
        u[i] = ui


@njit(parallel=True, cache=CACHE, fastmath=FASTMATH)
def _contact_geometry(code, p, r, theta, cx, cy, R, w, mode, nscan, delta, u,
                      slope, curv):  # pragma: no cover - numba
    """Contact offset, slope and second derivative of the section at the contact.

    Parameters
    ----------
    code, p, cx, cy, R, w, mode, nscan
        As for :func:`_tip`.
    r, theta : ndarray of shape (n,)
        Tip radius (m) and angle (rad).
    delta : float
        Step of the central difference of the slope, in m.
    u, slope, curv : ndarray of shape (n,)
        Output: contact offset u (m), dS/drho at the contact (dimensionless) and
        d2S/drho2 there (1/m).
    """
    for i in prange(r.size):
        ct = np.cos(theta[i])
        st = np.sin(theta[i])
        _, ui = _tip(code, p, r[i], theta[i], cx, cy, R, w, mode, nscan)
        rho = r[i] + ui
        _, s0 = _section(code, p, rho, ct, st, cx, cy)
        _, sp = _section(code, p, rho + delta, ct, st, cx, cy)
        _, sm = _section(code, p, rho - delta, ct, st, cx, cy)
        u[i] = ui
        slope[i] = s0
        curv[i] = (sp - sm) / (2.0 * delta)


@njit(parallel=True, cache=CACHE, fastmath=FASTMATH)
def _sample_design(starts, stops, fs, theta0, omega, linear, r_start, r_rate, t_tab,
                   r_tab, code, p, cx, cy, R, w, mode, nscan, datum, t, theta, r,
                   z):  # pragma: no cover - numba
    """Design-surface spiral at the sample numbers ``starts[m] <= k < stops[m]``.

    Parameters
    ----------
    starts, stops : ndarray of int64
        Half-open sample-number ranges.
    fs : float
        Sampling rate, in Hz (sample k is at t = k / fs).
    theta0, omega : float
        Angle at t = 0 (rad) and angular speed 2 pi n (rad/s).
    linear : bool
        True: constant feed, ``r = r_start - r_rate t`` (m). False: r linear in t
        between the nodes ``(t_tab, r_tab)`` (s, m), constant beyond them.
    r_start, r_rate : float
        Start radius (m) and radial speed (m/s) of the constant-feed spiral.
    t_tab, r_tab : ndarray of shape (m,)
        Planned-feed nodes, t increasing (s) and r non-increasing (m).
    code, p, cx, cy, R, w, mode, nscan
        As for :func:`_tip`.
    datum : float
        Height of the design's datum in the workpiece frame, in m.
    t, theta, r, z : ndarray of shape (n,)
        Output: time (s), angle (rad), tip radius (m), tip height (m).
    """
    inv_fs = 1.0 / fs
    k = 0
    m_last = t_tab.size - 1
    for m in range(starts.size):
        for i in range(starts[m], stops[m]):
            ti = i * inv_fs
            t[k] = ti
            theta[k] = theta0 + omega * ti
            if linear:
                rk = r_start - r_rate * ti
            elif ti <= t_tab[0]:
                rk = r_tab[0]
            elif ti >= t_tab[m_last]:
                rk = r_tab[m_last]
            else:
                j = np.searchsorted(t_tab, ti) - 1
                f = (ti - t_tab[j]) / (t_tab[j + 1] - t_tab[j])
                rk = r_tab[j] + f * (r_tab[j + 1] - r_tab[j])
            r[k] = rk if rk > 0.0 else 0.0
            k += 1
    for i in prange(k):
        zi, _ = _tip(code, p, r[i], theta[i], cx, cy, R, w, mode, nscan)
        z[i] = zi + datum
