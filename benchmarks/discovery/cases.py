"""Case generator of the blind discrepancy-discovery benchmark.

A case is a folder with ``manifest.toml`` and recordings in the formats ``servosurf
diagnose`` reads (nothing else: no hidden metadata). The truth of each case goes to
the sealed key file (:mod:`generate`), never into the case folder.

Campaign (DISCOVERY.md section 5.1, at the seed paper's 0.175 kg / 468 Hz set-up,
cutting the 5 um lenslets of ``toolpaths/lenslet_5um.toml``):

* ``idle.npz``: 32 idle following-error records of 4096 samples (paper 4.1);
* ``aircut.npz``: following error of the lenslet command with the tool retracted;
* ``aircut_b.csv``: the same air cut at a second FTS frequency (137 Hz, "speed B"),
  CSV with ``command_m`` (full and quick campaigns);
* ``cut.csv``: force and following error while cutting;
* ``frf_ol.csv``, ``frf_cl.csv``, ``frf_force.csv``: open-loop (V/V), closed-loop
  (m/m) and force (m/N) FRFs with 1 % complex measurement noise;
* ``surface.npz``: the interferometer field around the middle-ring lenslet;
* ``ring{k}.npz``: circumferential profiles along each ring of lenslets.

Noise: the machine's stochastic disturbances (sensor, current, base) realised per
record through the true loop (generator's own synthesis), 2 mN force-sensor noise,
0.1 nm white interferometer noise. Effects are injected as terms of the diagnosis's
model (:class:`servosurf.diagnose.Model`, the catalogue's parameter classes) where
the physics is the same; the surface map is swept with the
project's kernel (:func:`servosurf.toolpath.sweep`, waviness through
:class:`~servosurf.toolpath.Tool`), and the out-of-catalogue nonlinearities run in
the simulator's one loop kernel (:class:`servosurf.servo.Nonlinearity`). Effect
strengths are set by the effect-to-noise ratio (ENR): RMS of the effect in a
recording over the noise RMS of that recording, maximised over recordings.
"""

from __future__ import annotations

import dataclasses
import math
import os
from pathlib import Path

import numpy as np

from servosurf.cutting import ChipModel
from servosurf.diagnose import CaseModel, Model
from servosurf.diagnose import effects as E
from servosurf.servo import Nonlinearity, load_machine, write_frf_csv
from servosurf.toolpath import Tool, load_toolpath, sample, sweep

HERE = Path(__file__).resolve().parent
REPO = HERE.parents[1]
TOOLPATH = REPO / "toolpaths" / "lenslet_5um.toml"

MASS = 0.175
BANDWIDTH = 468.0
FRF_NOISE = 0.01
FORCE_NOISE = 2e-3
INSTRUMENT_NOISE = 0.1e-9

CAMPAIGNS = {
    "full": dict(
        idle_records=32,
        idle_len=4096,
        air_len=32768,
        cut_len=32768,
        frf_n=2000,
        surface=(480, 640),
        speed_b=137.0,
        rings=3,
        profile_dx=2e-6,
    ),
    "quick": dict(
        idle_records=16,
        idle_len=4096,
        air_len=16384,
        cut_len=16384,
        frf_n=800,
        surface=(300, 300),
        speed_b=137.0,
        rings=2,
        profile_dx=4e-6,
    ),
    "test": dict(
        idle_records=16,
        idle_len=4096,
        air_len=8192,
        cut_len=8192,
        frf_n=800,
        surface=(200, 260),
        rings=1,
        profile_dx=8e-6,
    ),
}

#: Catalogue effects the generator injects (every module of the catalogue).
EFFECTS = (
    "structural-mode",
    "loop-delay",
    "base-vibration-lines",
    "thermal-drift",
    "flexure-stiffness-nonlinearity",
    "force-constant-position",
    "amplifier-saturation",
    "sensor-nonlinearity",
    "sensor-noise-shape",
    "tool-edge-waviness",
    "tool-radius-error",
    "cutting-force-coefficient",
    "spindle-axial-error",
    "elastic-recovery",
    "spindle-async-error",
    "tool-wear",
)
#: Effects outside the catalogue.
OOL = (
    "bouc-wen-hysteresis",
    "quadratic-damping",
    "coulomb-friction",
    "opposite-sign-mode",
    "sensor-1/f-noise",
)


# ------------------------------------------------------------------ the case model
_CASE = {}


def base_case() -> CaseModel:
    """The nominal case (cached per process)."""
    if "case" not in _CASE:
        m = load_machine().with_moving_mass(MASS).with_bandwidth(BANDWIDTH)
        _CASE["case"] = CaseModel(m, load_toolpath(TOOLPATH))
    return _CASE["case"]


# ------------------------------------------------------------------ OOL loop
def ool_nonlinearity(ool: dict) -> Nonlinearity:
    """The out-of-catalogue force on the coil carrier (m2) as a loop nonlinearity.

    ``bouc-wen-hysteresis``: ``F = -par0 z``, ``z' = v - par1 |v| z - par2 v |z|``
    (v the flexure's deflection rate); ``quadratic-damping``: ``F = -par0 |v| v``;
    ``coulomb-friction``: ``F = -par0 tanh(v / par1)``. They run in the
    simulator's one loop kernel (:meth:`servosurf.servo.ServoLoop.simulate`).
    """
    par = [float(v) for v in ool["par"]]
    kind = ool["kind"]
    if kind == "bouc-wen-hysteresis":
        return Nonlinearity(bouc_wen_stiffness=par[0], bouc_wen_beta=par[1],
                            bouc_wen_gamma=par[2])
    if kind == "quadratic-damping":
        return Nonlinearity(quadratic_damping=par[0])
    if kind == "coulomb-friction":
        return Nonlinearity(friction=par[0], friction_velocity=par[1])
    raise ValueError(f"not a loop nonlinearity: {kind!r}")


def ool_simulate(case: CaseModel, ool: dict, ref: np.ndarray, chip: bool) -> dict:
    """Deterministic loop run with an out-of-catalogue nonlinearity."""
    p = Model()
    out = case.loop.simulate(
        reference=np.ascontiguousarray(ref, dtype=float),
        chip=ChipModel(case.kt(p), case.tool_radius(), 0.0) if chip else None,
        nonlinearity=ool_nonlinearity(ool),
    )
    return {"tool": out["tool"], "fe": out["following_error"], "force": out["force"]}


# ------------------------------------------------------------------ noise
def _one(p: Model, name: str):
    """The (first) term of effect ``name`` in ``p``, or None."""
    ps = p.get(name)
    return ps[0] if ps else None


def _lines(p: Model) -> tuple[list[float], list[float]]:
    """Frequencies (Hz) and amplitudes (m) of the base lines of ``p``."""
    ps = p.get("base-vibration-lines")
    return [q.frequency for q in ps], [q.amplitude for q in ps]


def _source_psds(case: CaseModel, p: Model, f: np.ndarray, ool: dict | None):
    w = case.disturbance_psds(p, f)
    if ool and ool["kind"] == "sensor-1/f-noise":
        w["sensor_noise"] = w["sensor_noise"] + ool["par"][0] ** 2 * 1000.0 / f
    if ool and ool["kind"] == "noise-scale":  # misspecified noise model (no physics)
        for k, c in zip(("base", "sensor_noise", "current_noise"), ool["par"],
                        strict=True):
            w[k] = w[k] * c
    return w


def noise_records(
    case: CaseModel,
    p: Model,
    n: int,
    rng,
    *,
    count: int = 1,
    ool=None,
    outputs=("fe",),
) -> dict:
    """Periodic Gaussian realisations of the stochastic errors, plus the lines.

    Each source gets random Fourier coefficients of variance ``W n fs / 2`` above
    ``fs / 4096`` and goes through the true closed loop; lines get a random phase
    per record.
    """
    fs = case.fs
    f = np.fft.rfftfreq(n, 1.0 / fs)
    band = (f >= fs / 4096 * (1 - 1e-9)) & (f < fs / 2)
    fb = f[band]
    ps = case.paths(p, fb)
    w = _source_psds(case, p, fb, ool)
    inp = {
        "sensor_noise": "sensor_noise",
        "current_noise": "current_noise",
        "base": "base",
    }
    out = {o: np.zeros((count, n)) for o in outputs}
    t = np.arange(n) / fs
    for c in range(count):
        spec = {o: np.zeros(f.size, dtype=complex) for o in outputs}
        for name, wk in w.items():
            g = (
                rng.standard_normal(fb.size) + 1j * rng.standard_normal(fb.size)
            ) / math.sqrt(2.0)
            x = np.sqrt(wk * n * fs / 2.0) * g
            for o in outputs:
                spec[o][band] += ps[(inp[name], o)] * x
        for o in outputs:
            out[o][c] = np.fft.irfft(spec[o], n)
        if ool and ool["kind"] == "low-band":
            low = low_band_records(case, p, n, rng, ool["par"][0], outputs)
            for o in outputs:
                out[o][c] += low[o]
        lf, la = _lines(p)
        if len(lf):
            f0 = np.asarray(lf)
            h = case.paths(p, f0)
            for j in range(f0.size):
                ph = rng.uniform(0, 2 * np.pi)
                for o in outputs:
                    hh = h[("base", o)][j]
                    out[o][c] += (
                        la[j]
                        * abs(hh)
                        * np.cos(2 * np.pi * f0[j] * t + ph + np.angle(hh))
                    )
    return out


#: A low-band record is cut from a series this many times longer (its content
#: down to 1 / (8 T): offsets and drifts as well as slow oscillation).
LOW_BAND_SPAN = 8


def low_band_records(case: CaseModel, p: Model, n: int, rng, slope: float,
                     outputs=("fe",)) -> dict:
    """Base vibration below the compared band (realistic null, issue 19 item 5).

    The base PSD continues below ``fs / 4096`` as ``W(f_lo) (f / f_lo)^-slope``
    down to ``fs / (LOW_BAND_SPAN n)``; a Gaussian series of
    ``LOW_BAND_SPAN n`` samples with that spectrum goes through the true loop's
    base path and its first ``n`` samples are returned (not periodic in the
    record: it leaks into every bin of a rectangular window).
    """
    fs = case.fs
    m = LOW_BAND_SPAN * n
    f = np.fft.rfftfreq(m, 1.0 / fs)
    f_lo = fs / 4096
    band = (f > 0) & (f < f_lo * (1 - 1e-9))
    fb = f[band]
    w_lo = case.disturbance_psds(p, np.array([f_lo]))["base"][0]
    wk = w_lo * (fb / f_lo) ** (-float(slope))
    ps = case.paths(p, fb)
    g = rng.standard_normal(fb.size) + 1j * rng.standard_normal(fb.size)
    g = g / math.sqrt(2.0)
    x = np.sqrt(wk * m * fs / 2.0) * g
    out = {}
    for o in outputs:
        spec = np.zeros(f.size, dtype=complex)
        spec[band] = ps[("base", o)] * x
        out[o] = np.fft.irfft(spec, m)[:n]
    return out


def fe_noise_rms(
    case: CaseModel, p: Model, n: int = 4096, ool=None, output: str = "fe"
) -> float:
    """RMS (m) of the stochastic part of ``output`` (no lines)."""
    fs = case.fs
    f = np.fft.rfftfreq(n, 1.0 / fs)[1:]
    f = f[(f >= fs / 4096 * (1 - 1e-9)) & (f < fs / 2)]
    ps = case.paths(p, f)
    w = _source_psds(case, p, f, ool)
    inp = {
        "sensor_noise": "sensor_noise",
        "current_noise": "current_noise",
        "base": "base",
    }
    s = sum(wk * np.abs(ps[(inp[k], output)]) ** 2 for k, wk in w.items())
    return float(math.sqrt(np.sum(s) * fs / n))


# ------------------------------------------------------------------ geometry
def surface_field(campaign: dict):
    """The map's field: the toolpath's 20X field (cropped in quick runs)."""
    spec = load_toolpath(TOOLPATH)
    ny, nx = campaign["surface"]
    return dataclasses.replace(spec.field, nx=nx, ny=ny)


def path_terms(p: Model, t, theta, z):
    """Outside-the-loop tool terms (generator's own formulas; the sensor
    nonlinearity acts inside the loop, through the loop kernel)."""
    dr = _one(p, "thermal-drift")
    amp, tau, rate = ((dr.amplitude, dr.time_constant, dr.rate) if dr is not None
                      else (0.0, 1.0, 0.0))
    dz = np.zeros(np.shape(z))
    if amp:
        dz = dz + amp * (1 - np.exp(-t / tau))
    dz = dz + rate * t
    for q in p.get("spindle-axial-error"):
        dz = dz + q.amplitude * np.cos(q.order * theta + q.phase)
    for q in p.get("spindle-async-error"):
        dz = dz + q.path_z(t, theta, None, z)
    return dz


def waviness_tool(spec, p: Model) -> Tool:
    """The toolpath's tool with the radius error and the waviness of ``p``."""
    from servosurf.diagnose.effects._tool_edge_waviness import phi_reference

    tool = spec.tool
    re_ = _one(p, "tool-radius-error")
    kw = {"nose_radius": tool.nose_radius
          + (re_.radius_error if re_ is not None else 0.0)}
    wv = _one(p, "tool-edge-waviness")
    waviness = wv.coefficients if wv is not None else ()
    if len(waviness) and any(waviness):
        phi = np.linspace(-tool.arc_half_angle, tool.arc_half_angle, 4001)
        ref = phi_reference(base_case())
        u = np.clip(phi / ref, -1.5, 1.5)
        c = np.zeros(3 + len(waviness))
        c[3:] = waviness
        dev = np.polynomial.legendre.legval(u, c)
        kw["waviness_angle"] = tuple(phi)
        kw["waviness_deviation"] = tuple(dev)
    return dataclasses.replace(tool, **kw)


def tool_series(case: CaseModel, p: Model, ool, t_max: float) -> tuple:
    """Deterministic tool height over [0, t_max] (steady state repeated)."""
    from servosurf.diagnose._surface import ToolTrajectory

    fs = case.fs
    n = int(round(0.12 * fs))
    t = np.arange(n) / fs
    ref = case.toolpath.path.z_at(t)
    if ool and ool["kind"] in (
        "bouc-wen-hysteresis",
        "quadratic-damping",
        "coulomb-friction",
    ):
        x1 = ool_simulate(case, ool, ref, True)["tool"]
    else:
        x1 = case.simulate_path(p, t)["tool"]
    return ToolTrajectory(t, x1, 1.0 / case.toolpath.path.frequency)


# ------------------------------------------------------------------ recordings
def deterministic(case: CaseModel, p: Model, ool, campaign: dict) -> dict:
    """Noise-free recordings of a case (used for the data and for the ENR)."""
    fs = case.fs
    spec = case.toolpath
    out = {}
    nonlin_ool = ool and ool["kind"] in (
        "bouc-wen-hysteresis",
        "quadratic-damping",
        "coulomb-friction",
    )
    ta = np.arange(campaign["air_len"]) / fs
    ref = spec.path.z_at(ta)
    if nonlin_ool:
        out["air"] = ool_simulate(case, ool, ref, False)["fe"]
    else:
        out["air"] = case.simulate(p, reference=ref)["fe"]
    if campaign.get("speed_b"):
        ref_b = speed_b_command(ta, spec, campaign["speed_b"])
        if nonlin_ool:
            out["air_b"] = ool_simulate(case, ool, ref_b, False)["fe"]
        else:
            out["air_b"] = case.simulate(p, reference=ref_b)["fe"]
    tc = np.arange(campaign["cut_len"]) / fs
    if nonlin_ool:
        c = ool_simulate(case, ool, spec.path.z_at(tc), True)
    else:
        c = case.simulate_path(p, tc)
    out["cut_fe"], out["cut_force"] = c["fe"], c["force"]
    f = np.geomspace(20.0, 40e3, campaign["frf_n"])
    ps = case.paths(p, f)
    out["frf"] = {
        "frf_ol": (f, ps["open_loop"]),
        "frf_cl": (f, ps[("reference", "sensor")]),
        "frf_force": (f, ps[("force", "sensor")]),
    }
    traj = tool_series(case, p, ool, spec.path.duration)
    out["traj"] = traj
    return out


def speed_b_command(t, spec, f_b: float):
    """Air-cut command at a second FTS frequency ``f_b`` (Hz), same stroke.

    DISCOVERY.md 5.1 "speed B": separates effects that scale with speed (inertial
    force, saturation) from those that depend on position only (flexure).
    """
    path = spec.path
    a = path.amplitude
    return (a - path.depth_of_cut) - a * np.sin(2 * np.pi * f_b * t)


def sweep_surface(case: CaseModel, p: Model, traj, field, noise_fn=None):
    """Map by the project's sweep kernel (generator path), heights in m."""
    spec = case.toolpath
    tool = waviness_tool(spec, p)
    path = sample(spec, fs=case.fs, field=field, tool=tool)
    z = traj(path.t) + path_terms(p, path.t, path.theta, traj(path.t))
    if noise_fn is not None:
        z = z + noise_fn(path.t)
    path = path.with_z(z)
    wear = _one(p, "tool-wear")
    if wear is None:
        surf = sweep(path, tool, field, check=False)
        zz = surf.z.copy()
    else:  # each ring (revolution) with its own worn radius: envelope of the rings
        ring = np.floor(path.t * spec.path.angular_speed / (2 * math.pi))
        zz = None
        for k in np.unique(ring):
            sel = ring == k
            piece = type(path)(path.t[sel], path.theta[sel], path.r[sel],
                               path.z[sel], path.fs)
            tk = wear.tool_at(tool, 0.5 * (piece.t[0] + piece.t[-1]))
            zk = sweep(piece, tk, field, check=False).z
            zz = zk.copy() if zz is None else np.fmin(zz, zk)
    rc = _one(p, "elastic-recovery")
    if rc is not None and rc.recovery:
        zz = zz + rc.recovery * (0.0 - zz)
    return zz


def ring_points(case: CaseModel, k: int, dx: float):
    """Points of the circumferential profile along ring k (x, y, s) and its radius."""
    spec = case.toolpath
    r = float(spec.path.ring_radii()[k])
    n = int(2 * math.pi * r / dx)
    s = dx * np.arange(n)
    th = s / r
    return r * np.cos(th), r * np.sin(th), r


def profile_heights(case: CaseModel, p: Model, traj, x, y, noise_fn=None):
    """Heights along a profile with the pointwise model (generator path)."""
    from servosurf.diagnose._surface import PointSet, surface_heights

    pts = PointSet(case, x, y)
    return surface_heights(case, pts, p, traj, noise=noise_fn)


class ToolNoise:
    """Stochastic tool error as a function of time: one realisation per window."""

    def __init__(self, case, p, rng, windows, ool=None):
        self.parts = []
        fs = case.fs
        for t0, t1 in windows:
            n = 1 << int(math.ceil(math.log2(max((t1 - t0) * fs + 64, 1024))))
            x = noise_records(case, p, n, rng, ool=ool, outputs=("tool",))["tool"][0]
            self.parts.append((t0 - 16 / fs, fs, x))

    def __call__(self, t):
        t = np.asarray(t, dtype=float)
        out = np.zeros(t.shape)
        for t0, fs, x in self.parts:
            k = (t - t0) * fs
            sel = (k >= 0) & (k < x.size - 1)
            out[sel] = np.interp(k[sel], np.arange(x.size), x)
        return out


def _field_windows(case, field):
    """Time windows in which each ring passes the field."""
    spec = case.toolpath
    path = spec.path
    x, y = field.coords()
    th = np.arctan2(
        np.array([y[0], y[-1], y[0], y[-1]]), np.array([x[0], x[0], x[-1], x[-1]])
    )
    w = path.angular_speed
    t_rev = 2 * math.pi / w
    ph = np.mod(th - path.theta0, 2 * math.pi) / w
    lo, hi = ph.min(), ph.max()
    if hi - lo > math.pi / w:  # wraps
        lo, hi = 0.0, t_rev
    return [
        (k * t_rev + lo - 1e-3, k * t_rev + hi + 1e-3) for k in range(path.ring_count)
    ]


def enr(case: CaseModel, p: Model, ool, campaign: dict, nominal: dict) -> float:
    """Effect-to-noise ratio: max over recordings of effect RMS / noise RMS."""
    d = deterministic(case, p, ool, campaign)
    sig_fe = fe_noise_rms(case, Model())
    vals = [
        float(np.sqrt(np.mean((d["air"] - nominal["air"]) ** 2))) / sig_fe,
        float(np.sqrt(np.mean((d["air_b"] - nominal["air_b"]) ** 2))) / sig_fe
        if "air_b" in d
        else 0.0,
        float(np.sqrt(np.mean((d["cut_fe"] - nominal["cut_fe"]) ** 2))) / sig_fe,
        float(np.sqrt(np.mean((d["cut_force"] - nominal["cut_force"]) ** 2)))
        / FORCE_NOISE,
    ]
    for k, (_f, h) in d["frf"].items():
        h0 = nominal["frf"][k][1]
        vals.append(float(np.sqrt(np.mean(np.abs(np.log(h / h0)) ** 2))) / FRF_NOISE)
    # idle spectrum: lines and changes of the noise power
    s1 = fe_noise_rms(case, p, ool=ool) ** 2
    s0 = sig_fe**2
    lf, la = _lines(p)
    if len(lf):
        h = case.paths(p, np.asarray(lf))[("base", "fe")]
        s1 += float(np.sum((np.asarray(la) * np.abs(h)) ** 2) / 2)
    vals.append(math.sqrt(abs(s1 - s0) / s0))
    # maps and profiles: deterministic height change over the cut points
    tool_sig = fe_noise_rms(case, Model(), output="tool")
    map_sig = math.sqrt(tool_sig**2 + INSTRUMENT_NOISE**2)
    for key in ("surface", "rings"):
        if key in nominal:
            z0 = nominal[key]
            z1 = _maps(case, p, ool, campaign, d["traj"])[key]
            cut = (z0 < -EDGE) & (z1 < -EDGE)
            if cut.any():
                vals.append(float(np.sqrt(np.mean((z1[cut] - z0[cut]) ** 2))) / map_sig)
    return max(vals)


EDGE = 50e-9


def _maps(case, p, ool, campaign, traj) -> dict:
    out = {}
    fld = surface_field(campaign)
    out["surface"] = sweep_surface(case, p, traj, fld).ravel()
    zs = []
    for k in range(campaign["rings"]):
        x, y, _ = ring_points(case, k, campaign["profile_dx"])
        zs.append(profile_heights(case, p, traj, x, y))
    out["rings"] = np.concatenate(zs)
    return out


def nominal_recordings(campaign: dict) -> dict:
    """Noise-free nominal recordings (cached per process and campaign)."""
    key = ("nominal", tuple(sorted(campaign.items())))
    if key not in _CASE:
        case = base_case()
        d = deterministic(case, Model(), None, campaign)
        d.update(_maps(case, Model(), None, campaign, d["traj"]))
        _CASE[key] = d
    return _CASE[key]


# ------------------------------------------------------------------ effect draws
def draw(effect: str, rng) -> tuple:
    """Random sub-form and off-grid parameters; returns ``(terms(s), truth(s), s0)``.

    ``terms(s)`` gives the effect's terms (catalogue parameter instances) at
    strength ``s`` (> 0, ENR increases with s); ``truth(s)`` the parameters the
    diagnosis should report (its unit-suffixed report keys); ``s0`` a first
    strength.
    """
    case = base_case()
    m = case.machine
    if effect == "structural-mode":
        f = float(np.exp(rng.uniform(np.log(2500.0), np.log(30000.0))))
        z = float(np.exp(rng.uniform(np.log(0.01), np.log(0.05))))

        def kn(s):
            return (E.StructuralModeParams(f, z, s),)

        return kn, lambda s: kn(s)[0].report(), 1e-10
    if effect == "loop-delay":
        sign = 1.0 if rng.uniform() < 0.75 else -1.0

        def kn(s):
            return (E.LoopDelayParams(sign * min(s, 0.45 / case.fs) if sign < 0
                                      else s),)

        return kn, lambda s: kn(s)[0].report(), 0.2 / case.fs
    if effect == "base-vibration-lines":
        k = int(rng.integers(1, 4))
        if rng.uniform() < 0.5:
            fr = sorted(
                rng.choice([50.0, 100.0, 150.0, 250.0, 350.0], k, replace=False)
            )
        else:
            fr = sorted(rng.uniform(60.0, 4000.0, k))
        rel = np.sort(rng.uniform(0.3, 1.0, k))[::-1]
        rel[0] = 1.0
        fr = [float(x) for x in fr]
        order = np.argsort(-rel)
        fr = [fr[i] for i in order]
        rel = rel[order]
        return (
            lambda s: tuple(E.BaseLineParams(f, float(s * r))
                            for f, r in zip(fr, rel, strict=True)),
            lambda s: {"frequency_1_hz": fr[0], "amplitude_1_m": s},
            1e-9,
        )
    if effect == "thermal-drift":
        form = rng.choice(["exp", "lin", "both"])
        tau = float(rng.uniform(0.6, 3.0))
        sg = 1.0 if rng.uniform() < 0.5 else -1.0

        def kn(s):
            return (E.ThermalDriftParams(
                amplitude=sg * s if form != "lin" else 0.0,
                time_constant=tau,
                rate=-sg * s / 4.0 if form != "exp" else 0.0,
            ),)

        return kn, lambda s: kn(s)[0].report(), 1e-9
    if effect == "flexure-stiffness-nonlinearity":
        form = rng.choice(["k2", "k3", "both"])
        sg = 1.0 if rng.uniform() < 0.7 else -1.0
        k2 = m.mechanics.k2
        st = 15e-6

        def kn(s):
            return (E.FlexureNonlinearityParams(
                k_quadratic=sg * s * k2 / st if form != "k3" else 0.0,
                k_cubic=sg * s * k2 / st**2 if form != "k2" else 0.0,
            ),)

        return kn, lambda s: kn(s)[0].report(), 1e-3
    if effect == "force-constant-position":
        form = rng.choice(["b1", "b2", "both"])
        sg = 1.0 if rng.uniform() < 0.5 else -1.0
        st = 15e-6

        def kn(s):
            return (E.ForceConstantPositionParams(
                b1=sg * s / st if form != "b2" else 0.0,
                b2=-s / st**2 if form != "b1" else 0.0,
            ),)

        return kn, lambda s: kn(s)[0].report(), 1e-3
    if effect == "amplifier-saturation":
        peak = steady_peak_current(case)

        def kn(s):
            return (E.AmplifierSaturationParams(peak * (1.0 - min(s, 0.95))),)

        return kn, lambda s: kn(s)[0].report(), 0.02
    if effect == "sensor-nonlinearity":
        form = rng.choice(["a2", "a3", "both"])
        sg = 1.0 if rng.uniform() < 0.5 else -1.0
        st = 10e-6

        def kn(s):
            return (E.SensorNonlinearityParams(
                a2=sg * s / st if form != "a3" else 0.0,
                a3=s / st**2 if form != "a2" else 0.0,
            ),)

        return kn, lambda s: kn(s)[0].report(), 1e-3
    if effect == "sensor-noise-shape":
        sn = m.disturbances.sensor_noise
        form = rng.choice(["floor", "corner"])

        def kn(s):
            if form == "floor":
                return (E.SensorNoiseShapeParams(sn.floor * (1.0 + s), sn.corner),)
            return (E.SensorNoiseShapeParams(sn.floor, sn.corner * (1.0 + s)),)

        key = E.SensorNoiseShapeParams.report_key(form)
        return (
            kn,
            lambda s: {key: getattr(kn(s)[0], form)},
            0.1,
        )
    if effect == "tool-edge-waviness":
        from servosurf.diagnose.effects._tool_edge_waviness import phi_reference

        v = rng.normal(size=4)
        v /= np.linalg.norm(v)
        ref = phi_reference(case)

        def kn(s):
            return (E.ToolEdgeWavinessParams(ref, *(float(s * c) for c in v)),)

        return kn, lambda s: kn(s)[0].report(), 1e-9
    if effect == "tool-radius-error":
        sg = 1.0 if rng.uniform() < 0.5 else -1.0

        def kn(s):
            return (E.ToolRadiusErrorParams(sg * s),)

        return kn, lambda s: kn(s)[0].report(), 1e-6
    if effect == "cutting-force-coefficient":
        sg = 1.0 if rng.uniform() < 0.5 else -1.0
        k0 = case.specific_force

        def kn(s):
            return (E.CuttingForceCoefficientParams(k0 * (1 + sg * min(s, 0.8))),)

        return kn, lambda s: kn(s)[0].report(), 0.01
    if effect == "spindle-axial-error":
        h = int(rng.integers(1, 13))
        ph = float(rng.uniform(-np.pi, np.pi))
        return (
            lambda s: (E.SpindleAxialErrorParams(h, s, ph),),
            lambda s: {"order_1": float(h), "amplitude_1_m": s},
            1e-9,
        )
    if effect == "elastic-recovery":
        def kn(s):
            return (E.ElasticRecoveryParams(s),)

        return kn, lambda s: kn(s)[0].report(), 1e-3
    if effect == "spindle-async-error":
        return _draw_async(case, rng)
    if effect == "tool-wear":
        return _draw_wear(case, rng)
    raise KeyError(effect)


@dataclasses.dataclass(frozen=True)
class SaturatingWear(E.EffectParams):
    """Generator form of tool wear (not the catalogue's linear growth): the nose
    radius grows by ``A (1 - exp(-L / L0))`` with the cutting length ``L = v t``
    (break-in wear that levels off), tip held."""

    effect = "tool-wear"

    growth_limit: float = 0.0  # m, A
    length_scale: float = 1.0  # m, L0
    speed: float = 0.0  # m/s, v

    def grown(self, t):
        t = np.maximum(np.asarray(t, dtype=float), 0.0)
        return self.growth_limit * -np.expm1(-self.speed * t / self.length_scale)

    def tool(self, tool):
        return tool

    def edge(self, phi):
        return 0.0, None

    def tool_at(self, tool, t):
        return dataclasses.replace(tool, nose_radius=tool.nose_radius
                                   + float(self.grown(t)))

    def edge_at(self, t, phi):
        return self.grown(t), None


def _draw_wear(case, rng):
    """Saturating radius growth, its length scale 0.3-2 times the cut's length."""
    from servosurf.diagnose.effects._tool_wear import cutting_speed

    v = cutting_speed(case.toolpath)
    length = v * case.toolpath.path.duration
    u = float(rng.uniform(0.3, 2.0))

    def kn(s):
        # s: radius growth (m) at the end of the toolpath
        return (SaturatingWear(s / -math.expm1(-1.0 / u), u * length, v),)

    return kn, lambda s: {"growth": s / length}, 1e-6


@dataclasses.dataclass(frozen=True)
class DriftingSines(E.EffectParams):
    """Generator form of the asynchronous spindle error (not the catalogue's fixed
    sine): sines whose frequency wanders slowly and whose amplitude breathes.

    Line k: ``a_k (1 + m sin(2 pi t / T_m + psi_m)) cos(Phi_k(t))`` with the
    instantaneous frequency ``f_k + df sin(2 pi t / T_d + psi_d)`` (Hz), i.e.
    ``Phi_k = 2 pi f_k t - df T_d cos(2 pi t / T_d + psi_d) + phi_k``.
    """

    effect = "spindle-async-error"

    frequencies: tuple = ()  # Hz
    amplitudes: tuple = ()  # m
    phases: tuple = ()  # rad
    wander: float = 0.0  # Hz, frequency excursion df
    wander_period: float = 3.0  # s, T_d
    wander_phase: float = 0.0  # rad
    breathing: float = 0.0  # amplitude modulation depth m (1)
    breathing_period: float = 2.0  # s, T_m
    breathing_phase: float = 0.0  # rad

    def path_z(self, t, theta, r, z):
        t = np.asarray(t, dtype=float)
        env = 1.0 + self.breathing * np.sin(2 * np.pi * t / self.breathing_period
                                            + self.breathing_phase)
        wob = -self.wander * self.wander_period * np.cos(
            2 * np.pi * t / self.wander_period + self.wander_phase)
        out = np.zeros(t.shape)
        for f, a, ph in zip(self.frequencies, self.amplitudes, self.phases,
                            strict=True):
            out = out + a * env * np.cos(2 * np.pi * f * t + wob + ph)
        return out


def _draw_async(case, rng):
    """Drifting sines at non-integer spindle orders (DISCOVERY.md row 7)."""
    fsp = case.toolpath.path.rev_per_s
    k = int(rng.integers(1, 3))
    fr = []
    while len(fr) < k:
        f = float(rng.uniform(60.0, 2000.0))
        h = f / fsp
        if abs(h - round(h)) > 0.15:  # a non-integer order
            fr.append(f)
    rel = [1.0] + [float(rng.uniform(0.2, 0.5)) for _ in fr[1:]]
    ph = [float(v) for v in rng.uniform(-np.pi, np.pi, k)]
    wander = float(rng.uniform(0.02, 0.15))
    t_d = float(rng.uniform(2.0, 6.0))
    psi_d = float(rng.uniform(-np.pi, np.pi))
    m = float(rng.uniform(0.05, 0.2))
    t_m = float(rng.uniform(1.5, 5.0))
    psi_m = float(rng.uniform(-np.pi, np.pi))

    def kn(s):
        return (DriftingSines(tuple(fr), tuple(s * r for r in rel), tuple(ph),
                              wander, t_d, psi_d, m, t_m, psi_m),)

    return kn, lambda s: {"frequency_1_hz": fr[0], "amplitude_1_m": s}, 1e-9


def steady_peak_current(case) -> float:
    """Peak current demand (A) of the lenslet cut from rest, nominal machine.

    The records start from rest with the command's 5 um step, so the peak is the
    start-up spike; a limit below the steady 0.06 A peak would wreck every record.
    """
    if "ipeak" not in _CASE:
        t = np.arange(int(0.1 * case.fs)) / case.fs
        u = case.simulate_path(Model(), t)["u"]
        # the limit acts on the DAC command itself (ServoLoop's amplifier stage)
        _CASE["ipeak"] = float(np.max(np.abs(u)) * case.machine.actuator.current_gain)
    return _CASE["ipeak"]


def draw_ool(kind: str, rng) -> tuple:
    """Out-of-catalogue effect at strength s: ``(ool(s), terms(s), s0)``."""
    case = base_case()
    k2 = case.machine.mechanics.k2
    if kind == "bouc-wen-hysteresis":
        az = float(rng.uniform(2e-6, 6e-6))
        return (
            lambda s: {"kind": kind, "par": [s * k2, 0.5 / az, 0.5 / az]},
            lambda s: (),
            0.01,
        )
    if kind == "quadratic-damping":
        return (lambda s: {"kind": kind, "par": [s * 100.0]}, lambda s: (), 0.1)
    if kind == "coulomb-friction":
        return (lambda s: {"kind": kind, "par": [s, 1e-4]}, lambda s: (), 1e-3)
    if kind == "opposite-sign-mode":
        f = float(np.exp(rng.uniform(np.log(3000.0), np.log(20000.0))))
        z = float(rng.uniform(0.01, 0.04))
        return (
            lambda s: None,
            # a mode of negative compliance (non-collocated): outside the
            # catalogue's physical bounds, carried by its parameter class
            lambda s: (E.StructuralModeParams(f, z, -s),),
            1e-10,
        )
    if kind == "sensor-1/f-noise":
        sn = case.machine.disturbances.sensor_noise
        return (lambda s: {"kind": kind, "par": [s * sn.level]}, lambda s: (), 1.0)
    raise KeyError(kind)


def scale_to_enr(target: float, make, campaign: dict, s0: float) -> float:
    """Strength s with ENR(s) = target (secant iterations in log-log).

    Returns ``(s, enr(s))``: the caller checks that the target was reached (an
    effect that vanishes below a threshold can leave ENR at zero).
    """
    case = base_case()
    nom = nominal_recordings(campaign)

    def f(s):
        p, ool = make(s)
        if "structural-mode" in p and not case.is_stable(p):
            return float("inf")
        return enr(case, p, ool, campaign, nom)

    s, e = s0, f(s0)
    for _ in range(8):
        if not np.isfinite(e) or e <= 0:
            s *= 0.3
            e = f(s)
            continue
        if abs(math.log(e / target)) < 0.03:
            break
        s2 = s * (target / e)
        e2 = f(s2)
        if np.isfinite(e2) and e2 > 0 and abs(math.log(e2 / e)) > 1e-6:
            slope = math.log(e2 / e) / math.log(s2 / s)
            slope = min(max(slope, 0.3), 3.0)
            s, e = s2, e2
            s = s * (target / e) ** (1.0 / slope)
            e = f(s)
        else:
            s, e = s2, e2
    return s, e


# ------------------------------------------------------------------ writing a case
def write_case(folder: Path, p: Model, ool, campaign: dict, seed: int) -> None:
    """Write the recordings and the manifest of one case."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    case = base_case()
    fs = case.fs
    rng = np.random.default_rng(seed)
    d = deterministic(case, p, ool, campaign)
    # idle records
    nr, nl = campaign["idle_records"], campaign["idle_len"]
    idle = noise_records(case, p, nl, rng, count=nr, ool=ool)["fe"]
    np.savez(folder / "idle.npz", fs_hz=fs, following_error_m=idle)
    # air cut
    na = campaign["air_len"]
    air = d["air"] + noise_records(case, p, na, rng, ool=ool)["fe"][0]
    cmd = case.toolpath.path.z_at(np.arange(na) / fs)
    np.savez(
        folder / "aircut.npz",
        fs_hz=fs,
        following_error_m=air[None],
        command_m=cmd[None],
    )
    extra = ""
    if "air_b" in d:
        air_b = d["air_b"] + noise_records(case, p, na, rng, ool=ool)["fe"][0]
        cmd_b = speed_b_command(np.arange(na) / fs, case.toolpath, campaign["speed_b"])
        with open(folder / "aircut_b.csv", "w") as fh:
            fh.write("time_s,following_error_m,command_m\n")
            np.savetxt(
                fh,
                np.column_stack([np.arange(na) / fs, air_b, cmd_b]),
                delimiter=",",
                fmt="%.12g",
            )
        extra = '[[recording]]\npath = "aircut_b.csv"\nkind = "following-error"\n\n'
    # cut
    nc = campaign["cut_len"]
    fe = d["cut_fe"] + noise_records(case, p, nc, rng, ool=ool)["fe"][0]
    fo = d["cut_force"] + FORCE_NOISE * rng.standard_normal(nc)
    t = np.arange(nc) / fs
    with open(folder / "cut.csv", "w") as fh:
        fh.write("time_s,force_n,following_error_m\n")
        np.savetxt(fh, np.column_stack([t, fo, fe]), delimiter=",", fmt="%.12g")
    # FRFs
    for name, (f, h) in d["frf"].items():
        g = (
            rng.standard_normal(f.size) + 1j * rng.standard_normal(f.size)
        ) / math.sqrt(2.0)
        write_frf_csv(folder / f"{name}.csv", f, h * (1.0 + FRF_NOISE * g))
    # surface and ring profiles
    fld = surface_field(campaign)
    noise = ToolNoise(case, p, rng, _field_windows(case, fld), ool=ool)
    z = sweep_surface(case, p, d["traj"], fld, noise)
    z = z + INSTRUMENT_NOISE * rng.standard_normal(z.shape)
    np.savez(
        folder / "surface.npz",
        z=z,
        dx=fld.pitch_x,
        dy=fld.pitch_y,
        x0=fld.x0,
        y0=fld.y0,
    )
    rec_lines = []
    t_rev = 2 * math.pi / case.toolpath.path.angular_speed
    for k in range(campaign["rings"]):
        x, y, r = ring_points(case, k, campaign["profile_dx"])
        tn = ToolNoise(
            case, p, rng, [(k * t_rev - 0.01, (k + 1) * t_rev + 0.01)], ool=ool
        )
        zp = profile_heights(case, p, d["traj"], x, y, tn)
        zp = zp + INSTRUMENT_NOISE * rng.standard_normal(zp.shape)
        np.savez(folder / f"ring{k}.npz", z=zp, dx=campaign["profile_dx"])
        rec_lines.append(
            f'[[recording]]\npath = "ring{k}.npz"\nkind = "profile"\nradius = {r!r}\n'
        )
    tp = os.path.relpath(TOOLPATH, folder)
    text = (
        f'[case]\nmachine = "seed-prototype"\ntoolpath = "{tp}"\n'
        f"bandwidth = {BANDWIDTH}\nmoving-mass = {MASS}\n\n"
        '[[recording]]\npath = "idle.npz"\nkind = "following-error"\n\n'
        '[[recording]]\npath = "aircut.npz"\nkind = "following-error"\n\n'
        + extra
        + '[[recording]]\npath = "cut.csv"\nkind = "cut"\n\n'
        '[[recording]]\npath = "frf_ol.csv"\nkind = "frf-open-loop"\n\n'
        '[[recording]]\npath = "frf_cl.csv"\nkind = "frf-closed-loop"\n\n'
        '[[recording]]\npath = "frf_force.csv"\nkind = "frf-force"\n\n'
        '[[recording]]\npath = "surface.npz"\nkind = "surface"\n\n'
        + "\n".join(rec_lines)
    )
    (folder / "manifest.toml").write_text(text)


#: Largest accepted ratio between the achieved and the target ENR.
ENR_TOLERANCE = 1.15
#: Effect draws tried before the generator gives up on a case.
MAX_DRAWS = 6


def _scaled(target, draw_fn, make_fn, campaign, what):
    """Draw an effect and scale it to ``target``; redraw when the target is missed."""
    for _ in range(MAX_DRAWS):
        d = draw_fn()
        s, e = scale_to_enr(target, make_fn(d), campaign, d[-1])
        if np.isfinite(e) and e > 0 and abs(math.log(e / target)) <= math.log(
                ENR_TOLERANCE):
            return d, s, e
    raise RuntimeError(
        f"{what}: ENR {target} not reached in {MAX_DRAWS} draws (last {e:.3g}); "
        "the case would be mislabelled"
    )


def build(spec: dict, campaign: dict):
    """Model of a case spec: ``(Model, ool, truth, enr_achieved)``.

    ``spec``: ``{"effects": [name, ...], "ool": name or None, "enr": float,
    "seed": int}``. Every effect is scaled to the target ENR and checked: the
    achieved ENR (per effect, recorded in the key) is within ``ENR_TOLERANCE``.
    """
    rng = np.random.default_rng(spec["seed"] + 7919)
    knobs, truths, achieved = [], {}, {}
    ool_make = None
    for name in spec["effects"]:
        (kn, tr, _s0), s, e = _scaled(
            spec["enr"],
            lambda name=name: draw(name, rng),
            lambda d: (lambda s, kn=d[0]: (Model.of(*kn(s)), None)),
            campaign,
            name,
        )
        knobs.append(kn(s))
        truths[name] = {k: float(v) for k, v in tr(s).items()}
        achieved[name] = float(e)
    if spec.get("noise_scale"):
        # noise-model misspecification null: PSD factors (base, sensor, current),
        # no effect; its ENR (relative change of the idle noise power) is recorded
        par = [float(c) for c in spec["noise_scale"]]
        ool_make = {"kind": "noise-scale", "par": par}
        achieved["noise-scale"] = enr(base_case(), Model(), ool_make, campaign,
                                      nominal_recordings(campaign))
    if spec.get("low_band"):
        # realistic null: the base PSD continuing below the compared band
        ool_make = {"kind": "low-band", "par": [float(spec["low_band"])]}
        achieved["low-band"] = enr(base_case(), Model(), ool_make, campaign,
                                   nominal_recordings(campaign))
    if spec.get("ool"):
        (om, okn, _s0), s, e = _scaled(
            spec["enr"],
            lambda: draw_ool(spec["ool"], rng),
            lambda d: (lambda s, om=d[0], okn=d[1]: (Model.of(*okn(s)), om(s))),
            campaign,
            spec["ool"],
        )
        knobs.append(okn(s))
        ool_make = om(s)
        achieved[spec["ool"]] = float(e)
    return Model.of(*(q for k in knobs for q in k)), ool_make, truths, achieved
