"""Numba kernels: toolpath samples over index ranges, and index-keyed noise.

Sampling a whole-part path window by window with numpy costs several temporaries per
sample; these kernels write t, theta, r and z in one pass. Checked wrappers:
:func:`servosurf.toolpath.sample` and :class:`servosurf.scale.IndexNoise`.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from ._config import CACHE, FASTMATH

__all__ = ["_sample_facing", "_sample_lenslet", "_index_noise"]


@njit(nogil=True, cache=CACHE, fastmath=FASTMATH)
def _sample_facing(starts, stops, fs, theta0, omega, r_start, r_rate, z0, t, theta, r,
                   z):  # pragma: no cover - numba
    """Spiral facing path at the sample numbers ``starts[m] <= k < stops[m]``.

    Parameters
    ----------
    starts, stops : ndarray of int64
        Half-open sample-number ranges, increasing and disjoint.
    fs : float
        Sampling rate, in Hz (sample k is at t = k / fs).
    theta0 : float
        Tool angle at t = 0, in rad.
    omega : float
        Angular speed 2 pi n, in rad/s.
    r_start : float
        Radius at t = 0, in m.
    r_rate : float
        Radial speed f n (feed per revolution times rev/s), in m/s.
    z0 : float
        Tool height (-depth of cut), in m.
    t, theta, r, z : ndarray of shape (n,)
        Output: time (s), angle (rad), radius (m), height (m).

    Notes
    -----
    theta = theta0 + omega t, r = r_start - r_rate t, z = z0 (seed paper Table 2
    facing: 2 um/rev, 250 rpm, 5 um depth).
    """
    inv_fs = 1.0 / fs
    k = 0
    for m in range(starts.size):
        for i in range(starts[m], stops[m]):
            ti = i * inv_fs
            t[k] = ti
            theta[k] = theta0 + omega * ti
            rk = r_start - r_rate * ti
            r[k] = rk if rk > 0.0 else 0.0  # rounding at r_end = 0
            z[k] = z0
            k += 1


@njit(nogil=True, cache=CACHE, fastmath=FASTMATH)
def _sample_lenslet(starts, stops, fs, theta0, omega, frequency, amplitude, depth,
                    ring_radius, ring_pitch, ring_count, n_per_ring, t, theta, r,
                    z):  # pragma: no cover - numba
    """Lenslet-ring path at the sample numbers ``starts[m] <= k < stops[m]``.

    Parameters
    ----------
    starts, stops : ndarray of int64
        Half-open sample-number ranges.
    fs : float
        Sampling rate, in Hz.
    theta0, omega : float
        Angle at t = 0 (rad) and angular speed (rad/s).
    frequency : float
        Sinusoid frequency f, in Hz.
    amplitude : float
        Zero-to-peak amplitude A, in m.
    depth : float
        Lenslet depth d, in m.
    ring_radius, ring_pitch : float
        First ring radius and inward ring pitch, in m.
    ring_count, n_per_ring : int
        Number of rings and of lenslets (periods) per ring.
    t, theta, r, z : ndarray of shape (n,)
        Output: time (s), angle (rad), radius (m), height (m).

    Notes
    -----
    z = (A - d) - A sin(2 pi f t) (seed paper section 4.2: the tool cuts while
    sin > (A - d) / A); the ring step is a half-cosine ramp over the second half of
    each ring's last period (see :class:`servosurf.toolpath.LensletToolpath`).
    """
    inv_fs = 1.0 / fs
    t_ring = n_per_ring / frequency
    ramp_start = (n_per_ring - 0.5) / frequency
    two_f = 2.0 * frequency
    w = 2.0 * np.pi * frequency
    k = 0
    for m in range(starts.size):
        for i in range(starts[m], stops[m]):
            ti = i * inv_fs
            ring = np.floor(ti / t_ring)
            if ring < 0.0:
                ring = 0.0
            elif ring > ring_count - 1:
                ring = ring_count - 1.0
            step = 0.0
            if ring < ring_count - 1:
                u = (ti - ring * t_ring - ramp_start) * two_f
                if u > 0.0:
                    if u > 1.0:
                        u = 1.0
                    step = 0.5 * (1.0 - np.cos(np.pi * u))
            t[k] = ti
            theta[k] = theta0 + omega * ti
            r[k] = ring_radius - ring_pitch * (ring + step)
            z[k] = (amplitude - depth) - amplitude * np.sin(w * ti)
            k += 1


@njit(cache=CACHE, fastmath=FASTMATH)
def _index_noise(t, fs, key, scale, out):  # pragma: no cover - numba
    """Uniform white noise keyed on the sample number round(t fs) (splitmix64).

    Parameters
    ----------
    t : ndarray of shape (n,)
        Sample times, in s.
    fs : float
        Sampling rate, in Hz.
    key : uint64
        Seed-derived offset.
    scale : float
        Output range: values in [-scale / 2, scale / 2), in m.
    out : ndarray of shape (n,)
        Output deviation, in m.
    """
    g = np.uint64(0x9E3779B97F4A7C15)
    m1 = np.uint64(0xBF58476D1CE4E5B9)
    m2 = np.uint64(0x94D049BB133111EB)
    inv = 1.0 / 9007199254740992.0  # 2**-53
    for j in range(t.size):
        k = np.uint64(np.int64(np.rint(t[j] * fs))) + key + g
        k = (k ^ (k >> np.uint64(30))) * m1
        k = (k ^ (k >> np.uint64(27))) * m2
        k = k ^ (k >> np.uint64(31))
        u = np.float64(k >> np.uint64(11)) * inv
        out[j] = (u - 0.5) * scale
