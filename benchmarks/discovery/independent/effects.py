"""Effects of the independent generator: forms unlike the catalogue's.

Each effect is drawn with random sub-forms and off-grid parameters and is scaled
by one strength ``s`` (the effect-to-noise ratio grows with ``s``). ``make(s)``
returns a :class:`Spec`: what the loop, the logger and the surface see, the truth
(in the effect's own physical parameters) and, where a catalogue parameter has a
physical counterpart, the ``comparable`` values the scorer checks a fitted
parameter against.

Catalogue-like effects (``expected`` names the catalogue module a correct
diagnosis names first) are generated in forms that are NOT the catalogue's fitting
forms: a mode as a real mass on a spring at the tool holder, a true transport delay
of the held DAC output, waviness as sines, drift with another time law, a
Lorentzian force-constant profile, a sinh-stiffening flexure, a soft-knee current
limit, a capacitive-gap sensor law, a von Mises spindle bump, an edge (ploughing)
force beside the chip-area force, tool wear (nose radius growing with cutting
length, catalogue's tool-wear), asynchronous spindle axial error (non-integer
orders plus a narrow band, catalogue's spindle-async-error); for the loop effects
Bouc-Wen (beta != gamma) or Dahl hysteresis, LuGre friction, rounding or
truncating converters and a soft
dead zone, pickup lines in the logged following error only (one line, or mains
harmonics with a drifting phase). Nulls:
nominal noise, base vibration continuing below fs / 4096, noise PSDs off by a
factor 1.5-2.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from .loop import LoopEffects
from .machine import LinearExtras, appended_mode


@dataclass
class Spec:
    """What one effect at one strength does (SI units).

    Attributes
    ----------
    loop : LoopEffects
        Effects inside the loop.
    lines : tuple of (f Hz, amplitude m)
        Base-vibration lines (phase random per record).
    pickup : tuple of (f Hz, amplitude m) or (f, amplitude, beta rad, f_d Hz)
        Lines added to the logged following error only (with a phase drifting
        as ``beta sin(2 pi f_d t)``).
    offset : callable or None
        ``offset(t, theta)``: tool-to-work height outside the loop, m.
    radius : callable or None
        ``radius(t)``: nose radius, m.
    waviness : callable or None
        ``waviness(phi)``: outward edge deviation, m.
    kt_scale, ke : float
        Chip-area force factor (-) and edge force per chord length (N/m).
    flex_dyn : callable or None
        ``flex_dyn(f)``: describing-function stiffness (N/m, complex) of a
        nonlinear flexure term at the FRF excitation amplitude.
    noise_scale : dict
        PSD factors of the stochastic sources.
    truth, comparable : dict
        Parameters (own form) and catalogue-comparable values.
    """

    loop: LoopEffects = field(default_factory=LoopEffects)
    lines: tuple = ()
    pickup: tuple = ()
    offset: Callable | None = None
    radius: Callable | None = None
    waviness: Callable | None = None
    kt_scale: float = 1.0
    ke: float = 0.0
    flex_dyn: Callable | None = None
    noise_scale: dict = field(default_factory=dict)
    truth: dict = field(default_factory=dict)
    comparable: dict = field(default_factory=dict)


@dataclass
class Effect:
    """A drawn effect: ``make(s) -> Spec`` and how to scale it."""

    name: str
    klass: str  # "catalogue", "out-of-catalogue", "null"
    expected: tuple[str, ...]
    make: Callable[[float], Spec]
    s0: float
    channels: tuple[str, ...]  # "fe", "frf", "map", "cut"
    needs_noise: bool = False
    form: str = ""
    #: Largest physically plausible strength (same unit as ``s``): a case whose
    #: target ENR needs more is redrawn, never generated (a 2.5 km nose radius
    #: "wear" reached ENR 0.3 on a ring profile before this cap existed).
    s_max: float = math.inf


#: FRF excitation amplitude of the (stepped-sine) FRF measurements, m.
FRF_AMPLITUDE = 1e-6
#: Stroke of the lenslet command: the range the comparable curves cover, m.
STROKE = (-5e-6, 15e-6)
#: Cut part of the stroke (the surface is formed below z = 0), m.
CUT_STROKE = (-5e-6, 0.0)


def _curve(fn, lo, hi, n=41) -> dict:
    x = np.linspace(lo, hi, n)
    return {"x": [float(v) for v in x], "y": [float(v) for v in fn(x)]}


def _describing_hysteresis(ode_force, amp: float, n: int = 4000, cycles: int = 4):
    """Complex stiffness (N/m) of a rate-independent element at amplitude ``amp``.

    ``ode_force(d, v, z) -> (F, dz/dt)`` integrated with RK4 over a sinusoidal
    displacement; first harmonic of the last cycle.
    """
    th = np.linspace(0.0, 2 * math.pi * cycles, n * cycles + 1)
    h = th[1] - th[0]
    z = 0.0
    F = np.zeros(th.size)

    def step(t, z):
        d, v = amp * math.sin(t), amp * math.cos(t)
        return ode_force(d, v, z)

    for i in range(th.size):
        F[i] = step(th[i], z)[0]
        if i + 1 < th.size:
            a = step(th[i], z)[1]
            b = step(th[i] + h / 2, z + h / 2 * a)[1]
            c = step(th[i] + h / 2, z + h / 2 * b)[1]
            e = step(th[i] + h, z + h * c)[1]
            z += h / 6 * (a + 2 * b + 2 * c + e)
    last = slice(n * (cycles - 1), n * cycles)
    t = th[last]
    a1 = 2 * np.mean(F[last] * np.sin(t))
    b1 = 2 * np.mean(F[last] * np.cos(t))
    # F = a1 sin + b1 cos = (a1 + j b1) X / amp for X = amp exp(j t)
    return complex(a1, b1) / amp


# ------------------------------------------------------------------ catalogue-like
def appended_mass(rng, ctx) -> Effect:
    """A mass on a spring with damping attached to the tool holder (m1)."""
    f = float(np.exp(rng.uniform(np.log(2500.0), np.log(30000.0))))
    zeta = float(np.exp(rng.uniform(np.log(0.01), np.log(0.05))))

    def make(s):
        w = 2 * math.pi * f
        ex = LinearExtras(mode_mass=s, mode_k=s * w * w, mode_c=2 * zeta * s * w)
        fr, zr = appended_mode(ctx.mach, ex)
        return Spec(
            loop=LoopEffects(linear=ex),
            truth={"mass": s, "stiffness": s * w * w, "damping": 2 * zeta * s * w,
                   "uncoupled_frequency": f, "uncoupled_damping_ratio": zeta},
            comparable={"frequency": fr, "damping_ratio": zr},
        )

    return Effect("appended-mass-mode", "catalogue", ("structural-mode",), make,
                  2e-4, ("fe", "frf", "map", "cut"))


def transport_delay(rng, ctx) -> Effect:
    """A true extra transport delay of the held DAC output."""
    sign = 1.0 if rng.uniform() < 0.75 else -1.0
    lim = 0.45 / ctx.mach.fs

    def make(s):
        tau = s if sign > 0 else -min(s, lim)
        return Spec(loop=LoopEffects(linear=LinearExtras(extra_delay=tau)),
                    truth={"extra_delay": tau}, comparable={"extra_delay": tau})

    return Effect("transport-delay", "catalogue", ("loop-delay",), make,
                  0.2 / ctx.mach.fs, ("fe", "frf", "map", "cut"),
                  form="positive" if sign > 0 else "negative")


def base_lines(rng, ctx) -> Effect:
    """One to three sinusoidal base displacements (mains harmonics or machinery)."""
    k = int(rng.integers(1, 4))
    if rng.uniform() < 0.5:
        fr = list(rng.choice([50.0, 100.0, 150.0, 250.0, 300.0, 350.0], k,
                             replace=False))
    else:
        fr = list(rng.uniform(60.0, 4000.0, k))
    rel = np.sort(rng.uniform(0.3, 1.0, k))[::-1]
    rel[0] = 1.0

    def make(s):
        lines = tuple((float(f), float(s * r)) for f, r in zip(fr, rel, strict=True))
        return Spec(lines=lines,
                    truth={"frequencies": [x[0] for x in lines],
                           "amplitudes": [x[1] for x in lines]},
                    comparable={"frequency_1": lines[0][0], "amplitude_1": lines[0][1]})

    return Effect("base-lines", "catalogue", ("base-vibration-lines",), make, 1e-9,
                  ("fe", "map", "cut"))


def sine_waviness(rng, ctx) -> Effect:
    """Tool-edge waviness as a sum of sines of the contact angle."""
    R, d = ctx.path.nose_radius, ctx.path.depth
    phi_cut = math.asin(math.sqrt(2 * R * d - d * d) / R)
    nt = int(rng.integers(1, 4))
    cyc = rng.uniform(1.0, 4.0, nt)
    ph = rng.uniform(-math.pi, math.pi, nt)
    c = rng.normal(size=nt)
    c /= np.linalg.norm(c)

    def shape(phi):
        phi = np.asarray(phi, dtype=float)
        out = np.zeros(phi.shape)
        for a, k, p in zip(c, cyc, ph, strict=True):
            out += a * np.sin(math.pi * k * phi / phi_cut + p)
        return out

    def make(s):
        return Spec(waviness=lambda phi: s * shape(phi),
                    truth={"amplitude": s, "coefficients": [float(v) for v in c],
                           "cycles_over_cut_width": [float(v) / 2 for v in cyc],
                           "phases": [float(v) for v in ph],
                           "phi_cut": phi_cut})

    return Effect("sine-waviness", "catalogue",
                  ("tool-edge-waviness", "tool-radius-error"), make, 1e-9, ("map",))


def drift_law(rng, ctx) -> Effect:
    """Thermal drift with a time law unlike a (1 - exp(-t/tau)) + b t."""
    form = str(rng.choice(["hyperbolic", "sqrt", "logistic"]))
    T = ctx.path.duration
    tau = float(rng.uniform(0.3, 3.0))
    sg = 1.0 if rng.uniform() < 0.5 else -1.0

    def law(t):
        t = np.asarray(t, dtype=float)
        if form == "hyperbolic":
            g = (t / tau) / (1 + t / tau)
            g1 = (T / tau) / (1 + T / tau)
        elif form == "sqrt":
            g, g1 = np.sqrt(np.maximum(t, 0) / tau), math.sqrt(T / tau)
        else:
            t0, wl = 0.5 * T, 0.15 * T
            g0 = 1 / (1 + math.exp(t0 / wl))
            g = 1 / (1 + np.exp(-(t - t0) / wl)) - g0
            g1 = 1 / (1 + math.exp(-t0 / wl)) - g0
        return g / g1

    def make(s):
        return Spec(offset=lambda t, th: sg * s * law(t),
                    truth={"form": form, "drift_at_end": sg * s, "tau": tau},
                    comparable={"drift_curve": _curve(lambda t: sg * s * law(t), 0.0,
                                                      T, 200)})

    return Effect("drift-law", "catalogue", ("thermal-drift",), make, 1e-9, ("map",),
                  form=form)


def kf_lorentzian(rng, ctx) -> Effect:
    """Force constant of a coil leaving a Lorentzian field profile."""
    xc = float(rng.choice([-1, 1]) * rng.uniform(5e-6, 30e-6))
    w = float(rng.uniform(20e-6, 80e-6))
    sg = 1.0 if rng.uniform() < 0.5 else -1.0

    def g(x):
        return (1 + (xc / w) ** 2) / (1 + ((np.asarray(x) - xc) / w) ** 2) - 1

    norm = float(np.max(np.abs(g(np.linspace(*STROKE, 201)))))

    def make(s):
        amp = sg * s / norm
        return Spec(loop=LoopEffects(kf_amp=amp, kf_xc=xc, kf_w=w),
                    truth={"kf_amp": amp, "centre": xc, "width": w,
                           "max_change_over_stroke": sg * s},
                    comparable={"kf_relative_curve": _curve(lambda x: amp * g(x),
                                                            *STROKE)})

    return Effect("kf-lorentzian", "catalogue", ("force-constant-position",), make,
                  1e-3, ("fe", "map", "cut"))


def flexure_sinh(rng, ctx) -> Effect:
    """Flexure stiffening of sinh form (large-deflection leaf springs)."""
    w = float(rng.uniform(8e-6, 25e-6))
    d0 = float(rng.uniform(-10e-6, 10e-6))
    sg = 1.0 if rng.uniform() < 0.75 else -1.0

    def F(d, amp):
        d = np.asarray(d, dtype=float)
        return amp * (np.sinh((d - d0) / w) + math.sinh(d0 / w)
                      - math.cosh(d0 / w) * d / w)

    k2 = ctx.mach.k[1]
    unit = float(np.max(np.abs(F(np.linspace(*STROKE, 201), 1.0))))

    def make(s):
        # s: extra force at the stroke's worst point relative to k2 * 15 um
        amp = sg * s * k2 * 15e-6 / unit
        return Spec(loop=LoopEffects(fl_amp=amp, fl_w=w, fl_d0=d0),
                    truth={"amplitude": amp, "width": w, "offset": d0,
                           "relative_to_linear": sg * s},
                    comparable={"flexure_force_curve": _curve(lambda d: F(d, amp),
                                                              *STROKE)})

    return Effect("flexure-sinh", "catalogue", ("flexure-stiffness-nonlinearity",),
                  make, 1e-3, ("fe", "map", "cut"))


def soft_saturation(rng, ctx) -> Effect:
    """Amplifier current limit with a soft knee ``x / (1 + |x|^p)^(1/p)``.

    ``s`` is the peak demand of a command record from rest over the limit.
    """
    p = float(rng.uniform(3.0, 8.0))
    ipk = ctx.peak_current

    def make(s):
        imax = ipk / s
        return Spec(loop=LoopEffects(sat_imax=imax, sat_p=p),
                    truth={"max_current": imax, "knee_order": p,
                           "peak_demand": ipk},
                    comparable={"max_current": imax})

    return Effect("soft-saturation", "catalogue", ("amplifier-saturation",), make,
                  1.5, ("fe", "map", "cut"))


def capacitive_sensor(rng, ctx) -> Effect:
    """Capacitive-gap reading ``x + eps g0 (1/(1 - x/g0) - 1 - x/g0)``."""
    g0 = float(rng.uniform(30e-6, 100e-6))
    sg = 1.0 if rng.uniform() < 0.5 else -1.0

    def make(s):
        eps = sg * s

        def err(x):
            x = np.asarray(x, dtype=float)
            return eps * g0 * (1 / (1 - x / g0) - 1 - x / g0)

        return Spec(loop=LoopEffects(sn_eps=eps, sn_g0=g0),
                    truth={"eps": eps, "gap": g0},
                    comparable={"sensor_error_curve": _curve(err, *CUT_STROKE)})

    return Effect("capacitive-sensor", "catalogue", ("sensor-nonlinearity",), make,
                  1e-2, ("map",))


def spindle_bump(rng, ctx) -> Effect:
    """Synchronous axial error: a von Mises bump repeating h times per turn."""
    h = int(rng.integers(1, 13))
    kappa = float(rng.uniform(0.5, 3.0))
    thc = float(rng.uniform(-math.pi, math.pi))
    th = np.linspace(0, 2 * math.pi, 4096, endpoint=False)
    raw = np.exp(kappa * (np.cos(h * (th - thc)) - 1.0))
    mean = float(raw.mean())
    first = float(2 * abs(np.mean(raw * np.exp(-1j * h * th))))

    def make(s):
        def off(t, theta):
            return s * (np.exp(kappa * (np.cos(h * (theta - thc)) - 1.0)) - mean)

        return Spec(offset=off,
                    truth={"order": h, "peak_to_valley_scale": s, "kappa": kappa},
                    comparable={"order_1": float(h), "amplitude_1": s * first})

    return Effect("spindle-bump", "catalogue", ("spindle-axial-error",), make, 1e-9,
                  ("map",))


def nose_radius(rng, ctx) -> Effect:
    """The nose radius differs (tip held): the arc itself, pointwise."""
    sg = 1.0 if rng.uniform() < 0.5 else -1.0
    R0 = ctx.path.nose_radius

    def make(s):
        dr = sg * s
        return Spec(radius=lambda t: np.full(np.shape(t), R0 + dr),
                    truth={"radius_error": dr}, comparable={"radius_error": dr})

    return Effect("nose-radius", "catalogue", ("tool-radius-error",), make, 1e-6,
                  ("map",))


def edge_force(rng, ctx) -> Effect:
    """Cutting force ``kt' A + ke b``: chip-area term plus an edge (ploughing) term."""
    alpha = float(rng.uniform(0.2, 1.0))
    sg = 1.0 if rng.uniform() < 0.6 else -1.0
    kt0 = ctx.chip.kt
    area_pk, chord_pk = ctx.chip_peak

    def make(s):
        s = min(s, 0.8)
        kt_scale = 1.0 + sg * s * (1 - alpha)
        ke = sg * s * alpha * kt0 * area_pk / chord_pk
        return Spec(kt_scale=kt_scale, ke=ke,
                    truth={"specific_force": kt0 * kt_scale, "edge_force": ke},
                    comparable={"specific_force": ctx.effective_kt(kt_scale, ke)})

    return Effect("edge-force", "catalogue", ("cutting-force-coefficient",), make,
                  0.01, ("cut", "map"))


# ------------------------------------------------------------------ out of catalogue
def hysteresis(rng, ctx) -> Effect:
    """Flexure hysteresis with memory: Bouc-Wen with an asymmetric loop shape
    (beta != gamma; the catalogue fits beta = gamma) or Dahl."""
    form = str(rng.choice(["bouc-wen", "dahl"]))
    zy = float(rng.uniform(1e-6, 5e-6))
    shape = float(rng.uniform(0.2, 0.8))  # beta / (beta + gamma)
    k2 = ctx.mach.k[1]

    def make(s):
        if form == "bouc-wen":
            hk, ha, hb = s * k2, shape / zy, (1 - shape) / zy

            def ode(d, v, z):
                return hk * z, v - ha * abs(v) * z - hb * v * abs(z)

            eff = LoopEffects(hyst=1, h_k=hk, h_a=ha, h_b=hb)
            truth = {"stiffness": hk, "yield_displacement": zy, "beta_share": shape}
        else:
            fc = s * k2 * zy
            sigma = fc / zy

            def ode(d, v, z):
                sg = 1.0 if v > 0 else (-1.0 if v < 0 else 0.0)
                return z, sigma * v * (1 - z * sg / fc)

            eff = LoopEffects(hyst=2, h_k=sigma, h_a=fc)
            truth = {"stiffness": sigma, "saturation_force": fc}
        kd = _describing_hysteresis(ode, FRF_AMPLITUDE)
        return Spec(loop=eff, flex_dyn=lambda f: np.full(np.shape(f), kd),
                    truth=truth, comparable={"stiffness": eff.h_k})

    return Effect("flexure-hysteresis", "catalogue", ("flexure-hysteresis",), make,
                  0.01, ("fe", "frf", "map", "cut"), form=form)


def quantisation(rng, ctx) -> Effect:
    """DAC or ADC quantisation of the loop's converters."""
    form = str(rng.choice(["dac", "adc"]))

    def make(s):
        if form == "dac":
            return Spec(loop=LoopEffects(dac_q=s), truth={"dac_lsb_v": s},
                        comparable={"dac_step": s})
        return Spec(loop=LoopEffects(adc_q=s), truth={"adc_lsb_m": s},
                    comparable={"adc_step": s})

    s0 = 3e-4 if form == "dac" else 1e-9
    return Effect("quantisation", "catalogue", ("converter-quantisation",), make, s0,
                  ("fe", "map"), needs_noise=True, form=form)


def pickup_line(rng, ctx) -> Effect:
    """Electrical pickup in the logged following error (not in the loop)."""
    if rng.uniform() < 0.5:
        f = float(rng.choice([150.0, 250.0, 350.0, 450.0]))
    else:
        f = float(rng.uniform(2e3, 35e3))

    def make(s):
        return Spec(pickup=((f, s),), truth={"frequency": f, "amplitude": s})

    return Effect("sensor-pickup", "catalogue", ("sensor-pickup-lines",), make,
                  1e-10, ("fe",))


def tool_wear(rng, ctx) -> Effect:
    """Nose radius growing with cutting length (tip held)."""
    R0 = ctx.path.nose_radius
    v = ctx.path.omega * ctx.path.r0 * ctx.path.cut_fraction

    def make(s):
        # s: radius growth per metre of cutting length (m/m)
        return Spec(radius=lambda t: R0 + s * v * np.asarray(t, dtype=float),
                    truth={"growth_per_cut_length": s,
                           "radius_growth_over_cut": s * v * ctx.path.duration},
                    comparable={"radius_growth_rate": s * v})

    # plausible: the radius grows by at most 10 % over the whole cut (the cut is
    # metres of cutting length; diamond edges wear over kilometres)
    s_max = 0.1 * R0 / (v * ctx.path.duration)
    return Effect("tool-wear", "catalogue", ("tool-wear",), make, min(1e-4, s_max),
                  ("map",), s_max=s_max)


def async_spindle(rng, ctx) -> Effect:
    """Asynchronous axial error motion: non-integer orders plus a narrow band."""
    fsp = ctx.path.omega / (2 * math.pi)
    nt = int(rng.integers(1, 4))
    orders = []
    while len(orders) < nt:
        o = float(rng.uniform(1.2, 25.0))
        if abs(o - round(o)) > 0.15:
            orders.append(o)
    ph = rng.uniform(-math.pi, math.pi, nt)
    amp = rng.uniform(0.4, 1.0, nt)
    # narrow-band part: a resonant AR(2) process at a non-integer order
    fb = float(rng.uniform(3.0, 15.0)) * fsp + 0.37 * fsp
    dt = 1e-3
    n = int(ctx.path.duration / dt) + 10
    r = math.exp(-2 * math.pi * 0.05 * fb * dt)
    a1, a2 = 2 * r * math.cos(2 * math.pi * fb * dt), -r * r
    e = rng.standard_normal(n)
    xb = np.zeros(n)
    for i in range(2, n):
        xb[i] = a1 * xb[i - 1] + a2 * xb[i - 2] + e[i]
    xb /= np.std(xb[n // 10:])
    tb = np.arange(n) * dt

    def shape(t):
        t = np.asarray(t, dtype=float)
        out = 0.5 * np.interp(t, tb, xb)
        for o, p, a in zip(orders, ph, amp, strict=True):
            out = out + a * np.cos(2 * math.pi * o * fsp * t + p)
        return out

    k1 = int(np.argmax(amp))

    def make(s):
        return Spec(offset=lambda t, th: s * shape(t),
                    truth={"amplitude": s, "orders": orders,
                           "narrow_band_hz": fb},
                    comparable={"frequency_1": orders[k1] * fsp,
                                "amplitude_1": s * float(amp[k1])})

    return Effect("async-spindle", "catalogue", ("spindle-async-error",), make, 1e-9,
                  ("map",))


# ------------------------------------------------------------------ loop effects
# forms unlike the catalogue's loop modules (flexure-hysteresis: Bouc-Wen;
# friction: tanh Coulomb; converter-quantisation: rounding steps as additive
# noise, a hard dead band; sensor-pickup-lines: fixed-phase sinusoids)
def dahl_hysteresis(rng, ctx) -> Effect:
    """Flexure hysteresis generated with the Dahl model (the catalogue fits
    Bouc-Wen): ``F' = sigma v (1 - F sgn(v) / F_c)``."""
    zy = float(rng.uniform(0.5e-6, 3e-6))
    k2 = ctx.mach.k[1]

    def make(s):
        fc = s * k2 * zy
        sigma = fc / zy

        def ode(d, v, z):
            sg = 1.0 if v > 0 else (-1.0 if v < 0 else 0.0)
            return z, sigma * v * (1 - z * sg / fc)

        kd = _describing_hysteresis(ode, FRF_AMPLITUDE)
        return Spec(loop=LoopEffects(hyst=2, h_k=sigma, h_a=fc),
                    flex_dyn=lambda f: np.full(np.shape(f), kd),
                    truth={"stiffness": sigma, "saturation_force": fc},
                    comparable={"stiffness": sigma, "yield_displacement": zy})

    return Effect("dahl-hysteresis", "catalogue", ("flexure-hysteresis",), make,
                  0.02, ("fe", "frf", "map", "cut"), form="dahl")


def lugre_friction(rng, ctx) -> Effect:
    """Friction generated with the LuGre bristle model and a Stribeck peak (the
    catalogue fits a tanh Coulomb law): ``F = sigma0 z``, ``z' = v - sigma0 |v| z /
    g(v)``, ``g = F_c + (F_s - F_c) exp(-(v / v_s)^2)``."""
    ratio = float(rng.uniform(1.1, 1.5))  # static / Coulomb force
    vs = float(np.exp(rng.uniform(np.log(1e-5), np.log(1e-4))))
    presliding = float(rng.uniform(0.3e-6, 1e-6))  # F_c / sigma0, m

    def make(s):
        fc = s
        sigma0 = fc / presliding

        def ode(d, v, z):  # describing function at the Coulomb level
            return sigma0 * z, v - sigma0 * abs(v) * z / fc

        kd = _describing_hysteresis(ode, FRF_AMPLITUDE)
        return Spec(loop=LoopEffects(hyst=3, h_k=sigma0, h_a=fc, h_b=ratio * fc,
                                     fric_vs=vs),
                    flex_dyn=lambda f: np.full(np.shape(f), kd),
                    truth={"coulomb_force": fc, "static_force": ratio * fc,
                           "stribeck_velocity": vs, "bristle_stiffness": sigma0},
                    comparable={"level": fc})

    return Effect("lugre-friction", "catalogue", ("friction",), make, 5e-3,
                  ("fe", "frf", "map", "cut"), form="lugre")


def integer_converters(rng, ctx) -> Effect:
    """Integer (truncating) converters and a soft dead zone ``u - b tanh(u / b)``
    (the catalogue fits rounding steps as additive noise and a hard dead band)."""
    form = str(rng.choice(["dac", "adc", "dead-zone"]))

    def make(s):
        if form == "dac":
            return Spec(loop=LoopEffects(dac_q=s, conv_trunc=True),
                        truth={"dac_lsb_v": s}, comparable={"dac_step": s})
        if form == "adc":
            return Spec(loop=LoopEffects(adc_q=s, conv_trunc=True),
                        truth={"adc_lsb_m": s}, comparable={"adc_step": s})
        return Spec(loop=LoopEffects(dac_dead=s), truth={"soft_dead_zone_v": s},
                    comparable={"dead_band": s})

    s0 = {"dac": 1e-3, "adc": 3e-9, "dead-zone": 1e-3}[form]
    return Effect("integer-converters", "catalogue", ("converter-quantisation",),
                  make, s0, ("fe", "map"), needs_noise=form != "dead-zone",
                  form=form)


def mains_pickup(rng, ctx) -> Effect:
    """Mains harmonics in the logged following error with a drifting phase (the
    catalogue fits fixed-phase sinusoids per record)."""
    mains = float(rng.choice([50.0, 60.0]))
    orders = sorted(rng.choice([1, 3, 5, 7, 9], size=int(rng.integers(1, 4)),
                               replace=False).tolist())
    drift = float(rng.uniform(0.05, 0.3))  # Hz, slow wander of the mains frequency
    dev = float(rng.uniform(0.005, 0.02))  # Hz, its excursion

    def make(s):
        lines = tuple((mains * h, s / h, h * dev / drift, drift) for h in orders)
        return Spec(pickup=lines, truth={"mains_hz": mains, "orders": orders,
                                         "amplitude": s},
                    comparable={"amplitude": s})

    return Effect("mains-pickup", "catalogue", ("sensor-pickup-lines",), make,
                  1e-10, ("fe",), form=f"{mains:g} Hz")


# ------------------------------------------------------------------ nulls
def null_nominal(rng, ctx) -> Effect:
    """No effect, the machine file's noise in its documented band."""
    return Effect("null-nominal", "null", (), lambda s: Spec(), 0.0, ())


def null_lowfreq(rng, ctx) -> Effect:
    """No effect; base vibration continues below fs / 4096 (set by the campaign)."""
    return Effect("null-lowfreq", "null", (), lambda s: Spec(), 0.0, ())


def null_misspecified(rng, ctx) -> Effect:
    """No effect; one noise PSD off by a factor 1.5-2."""
    src = str(rng.choice(["base", "sensor", "current"]))
    c = float(rng.uniform(1.5, 2.0))
    return Effect("null-misspecified", "null", (),
                  lambda s: Spec(noise_scale={src: c},
                                 truth={"source": src, "psd_factor": c}),
                  0.0, (), form=src)


CATALOGUE_LIKE = {
    "appended-mass-mode": appended_mass,
    "transport-delay": transport_delay,
    "base-lines": base_lines,
    "sine-waviness": sine_waviness,
    "drift-law": drift_law,
    "kf-lorentzian": kf_lorentzian,
    "flexure-sinh": flexure_sinh,
    "soft-saturation": soft_saturation,
    "capacitive-sensor": capacitive_sensor,
    "spindle-bump": spindle_bump,
    "nose-radius": nose_radius,
    "edge-force": edge_force,
    "tool-wear": tool_wear,
    "async-spindle": async_spindle,
    "dahl-hysteresis": dahl_hysteresis,
    "lugre-friction": lugre_friction,
    "integer-converters": integer_converters,
    "mains-pickup": mains_pickup,
    "flexure-hysteresis": hysteresis,
    "quantisation": quantisation,
    "sensor-pickup": pickup_line,
}
#: Every form the catalogue lacks has been given a catalogue module (loop- and
#: path-side effects); new out-of-catalogue forms go here.
OUT_OF_CATALOGUE: dict = {}
NULLS = {
    "null-nominal": null_nominal,
    "null-lowfreq": null_lowfreq,
    "null-misspecified": null_misspecified,
}
ALL = {**CATALOGUE_LIKE, **OUT_OF_CATALOGUE, **NULLS}

