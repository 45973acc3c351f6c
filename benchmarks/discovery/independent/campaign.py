"""Campaigns and recordings of the independent generator.

A campaign says which recordings a case has and how they were taken (logger rate,
lengths, formats, FRF grid and noise, map field, pitch and position, profiles).
:func:`recordings` produces them from the machine, the installed controller, the
effect's :class:`~effects.Spec` and a seed, either as data (``clean=False``: the
stochastic sources realised in the time domain and run through the loop) or
noise-free (``clean=True``, for the effect-to-noise ratio). :func:`write_case`
writes them in the formats ``servosurf diagnose`` reads plus the manifest.

Conventions (as the manifest documentation states them):

* command records start from rest at their first sample (the machine idles for
  :data:`WARMUP` s before, so the noise is stationary at t = 0);
* the cut record's time starts with the toolpath; maps and ring profiles show the
  whole cut (every ring, every revolution, as the loop cut them);
* the open-loop FRF is DAC volts to sensor volts with hold and delay; the
  closed-loop FRF reference to measured position; the force FRF force on the tool
  to measured position;
* a logger at half the controller rate low-pass filters (zero-phase FIR) before
  it decimates.
"""

from __future__ import annotations

import math
import os
import tomllib
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import scipy.signal

from . import noise as N
from .effects import Spec
from .loop import NSUB, Chip, LoopEffects, simulate
from .machine import Machine, load_machine, loop_frf, tune
from .surface import LensletPath, field_points, heights, load_lenslet, ring_points

REPO = Path(__file__).resolve().parents[3]
TOOLPATH = REPO / "toolpaths" / "lenslet_5um.toml"
WORKPIECE = REPO / "workpieces" / "nip.toml"
MASS = 0.175
BANDWIDTH = 468.0
#: Idle time before every record (s): the noise is stationary at the record start.
WARMUP = 0.15
#: Length of the clean steady-state cut used for the map ENR (s).
STEADY = 0.25
#: Height below the face that counts as cut (map ENR), m.
EDGE = 50e-9


class Context:
    """Machine, installed controller, toolpath and chip model of every case.

    ``chip_hold``: the chip force held over each controller sample (the
    zero-order-hold force model of servosurf's loop) instead of following the
    tool continuously (the default, the physics).
    """

    def __init__(self, chip_hold: bool = False) -> None:
        self.mach: Machine = load_machine(moving_mass=MASS, bandwidth=BANDWIDTH)
        self.ctrl = tune(self.mach)
        self.path: LensletPath = load_lenslet(TOOLPATH)
        with open(WORKPIECE, "rb") as fh:
            kt = float(tomllib.load(fh)["material"]["specific-thrust-pressure"])
        self.chip = Chip(kt=kt, radius=self.path.nose_radius, hold=chip_hold)
        R, d = self.path.nose_radius, self.path.depth
        sq = math.sqrt(2 * R * d - d * d)
        self.chip_peak = (R * R * math.acos((R - d) / R) - (R - d) * sq, 2 * sq)
        fs = self.mach.fs
        t = np.arange(int(0.05 * fs)) / fs
        o = simulate(self.mach, self.ctrl, self.path.command(t))
        #: peak current demand of a command record from rest (the start-up kick), A
        self.peak_current = float(np.max(np.abs(self.mach.gi * o["u"])))

    def effective_kt(self, kt_scale: float, ke: float) -> float:
        """Least-squares chip-area coefficient of ``kt' A + ke b`` over a lenslet."""
        t = np.linspace(0, 1 / self.path.frequency, 4001)
        d = np.clip(-self.path.command(t), 0, None)
        R = self.path.nose_radius
        sq = np.sqrt(np.clip(2 * R * d - d * d, 0, None))
        a = R * R * np.arccos((R - d) / R) - (R - d) * sq
        b = 2 * sq
        return float(self.chip.kt * kt_scale + ke * np.sum(a * b) / np.sum(a * a))


_CTX: dict = {}


def context(chip_hold: bool = False) -> Context:
    """The shared context (cached per process and chip-force model)."""
    if chip_hold not in _CTX:
        _CTX[chip_hold] = Context(chip_hold)
    return _CTX[chip_hold]


@dataclass
class Campaign:
    """What a case records (see module doc). Rates as divisors of the controller's."""

    idle: dict | None = None  # records, length, div, fmt
    air: dict | None = None  # length, div, fmt
    air_b: dict | None = None  # length, div, fmt, f
    cut: dict | None = None  # length, div, force_noise
    frfs: dict = field(default_factory=dict)  # kind -> n, fmin, fmax, spacing, noise
    surface: dict | None = None  # ring, lenslet, shift, pitch, shape, noise, ...
    profiles: list = field(default_factory=list)  # ring, dx, angle, noise
    low_freq_base: bool = False

    def kinds(self) -> set[str]:
        """Channels present: fe, frf, map, cut."""
        k = set()
        if self.idle or self.air or self.air_b or self.cut:
            k.add("fe")
        if self.frfs:
            k.add("frf")
        if self.surface or self.profiles:
            k.add("map")
        if self.cut:
            k.add("cut")
        return k

    def summary(self) -> dict:
        """JSON-ready description."""
        return {
            "idle": self.idle, "air": self.air, "air_b": self.air_b, "cut": self.cut,
            "frfs": self.frfs, "surface": self.surface, "profiles": self.profiles,
            "low_freq_base": self.low_freq_base,
        }


def draw_campaign(rng, channels: tuple[str, ...], ctx: Context) -> Campaign:
    """A random campaign that contains at least one channel of ``channels``."""
    c = Campaign()
    c.low_freq_base = bool(rng.uniform() < 0.5)

    def rate_fmt():
        return {"div": int(rng.choice([1, 2])), "fmt": str(rng.choice(["npz", "csv"]))}

    if rng.uniform() < 0.9:
        c.idle = {"records": int(rng.choice([8, 16, 24])),
                  "length": int(rng.choice([2048, 4096, 8192])), **rate_fmt()}
    if rng.uniform() < 0.85:
        c.air = {"length": int(rng.choice([8192, 16384, 32768])), **rate_fmt()}
    if rng.uniform() < 0.6:
        c.air_b = {"length": int(rng.choice([8192, 16384, 32768])), **rate_fmt(),
                   "f": float(rng.uniform(115.0, 165.0))}
    if rng.uniform() < 0.7:
        c.cut = {"length": int(rng.choice([8192, 16384, 32768])),
                 "div": int(rng.choice([1, 2])),
                 "force_noise": float(rng.uniform(1e-3, 3e-3))}
    for kind in ("frf-open-loop", "frf-closed-loop", "frf-force"):
        if rng.uniform() < 0.6:
            c.frfs[kind] = {"n": int(rng.choice([300, 800, 2000])),
                            "fmin": float(rng.choice([10.0, 20.0, 50.0])),
                            "fmax": float(rng.choice([20e3, 40e3, 80e3])),
                            "spacing": "log" if rng.uniform() < 0.8 else "linear",
                            "noise": float(rng.uniform(0.005, 0.02))}
    if rng.uniform() < 0.65:
        c.surface = _draw_surface(rng, ctx)
    for ring in range(ctx.path.rings):
        if rng.uniform() < 0.3 and len(c.profiles) < 2:
            c.profiles.append(_draw_profile(rng, ring))
    need = set(channels)
    if need and not (need & c.kinds()):
        if "map" in need:
            c.surface = _draw_surface(rng, ctx)
        elif "fe" in need:
            c.air = {"length": 16384, "div": 1, "fmt": "npz"}
        elif "cut" in need:
            c.cut = {"length": 16384, "div": 1, "force_noise": 2e-3}
        elif "frf" in need:
            c.frfs["frf-closed-loop"] = {"n": 300, "fmin": 20.0, "fmax": 40e3,
                                         "spacing": "log", "noise": 0.01}
    if not c.kinds():
        c.idle = {"records": 16, "length": 4096, "div": 1, "fmt": "npz"}
    return c


def _draw_surface(rng, ctx: Context) -> dict:
    pitch = float(rng.choice([0.55e-6, 0.88e-6, 1.1e-6]))
    return {
        "ring": int(rng.integers(0, ctx.path.rings)),
        "lenslet": int(rng.integers(0, ctx.path.n_lenslets)),
        "shift": [float(v) for v in rng.uniform(-30e-6, 30e-6, 2)],
        "pitch": pitch,
        "shape": [int(rng.integers(110, 181)), int(rng.integers(130, 211))],
        "noise": float(rng.uniform(0.05e-9, 0.2e-9)),
        "piston": float(rng.uniform(-30e-9, 30e-9)),
        "tilt": [float(v) for v in rng.uniform(-2e-5, 2e-5, 2)],
        "registration": [float(v) for v in rng.uniform(-0.2, 0.2, 2) * pitch],
    }


def _draw_profile(rng, ring: int) -> dict:
    return {"ring": ring, "dx": float(rng.choice([4e-6, 6e-6, 8e-6])),
            "angle": float(rng.uniform(-math.pi, math.pi)),
            "noise": float(rng.uniform(0.05e-9, 0.2e-9)),
            "piston": float(rng.uniform(-30e-9, 30e-9)),
            "registration": float(rng.uniform(-0.3e-6, 0.3e-6))}


# ------------------------------------------------------------------ recordings
#: Samples the logger's filter sees on each side of a record (half its length).
PAD = 128
_FIR: dict = {}


def _anti_alias(fs: float) -> np.ndarray:
    """Linear-phase anti-alias FIR of the half-rate logger (255 taps, Kaiser 10).

    Cut-off 45 kHz at 199.6 kHz: flat to 3e-6 up to 39.9 kHz (0.8 of the logged
    Nyquist frequency, the band the diagnosis compares), below -110 dB from
    49.9 kHz.
    """
    if fs not in _FIR:
        _FIR[fs] = scipy.signal.firwin(2 * PAD - 1, 45e3, window=("kaiser", 10.0),
                                       fs=fs)
    return _FIR[fs]


def _logger(x: np.ndarray, div: int, fs: float, n: int) -> np.ndarray:
    """Logged record of ``n`` samples from ``x`` (which has PAD samples each side).

    ``div = 1``: the samples; ``div = 2``: the anti-alias FIR applied to the
    continuous signal (with its time-delay compensated, as a logger stamps it),
    then every second sample.
    """
    x = np.asarray(x, dtype=float)
    if div == 1:
        return x[PAD : PAD + n].copy()
    y = np.convolve(x, _anti_alias(fs), mode="same")
    return y[PAD : PAD + n : div].copy()


def _noise_run(ctx, spec: Spec, n: int, rng, low_freq: bool) -> dict:
    fs = ctx.mach.fs
    f_lo = fs / n if low_freq else fs / 4096
    src = N.sources(ctx.mach, n, rng, f_lo=f_lo, scale=spec.noise_scale)
    # fade the base displacement in over the first third of the warm-up
    nf = int(WARMUP * fs / 3)
    w = np.ones(n)
    w[:nf] = 0.5 - 0.5 * np.cos(np.pi * np.arange(nf) / nf)
    src["base"] = src["base"] * w
    return src


def _run(ctx, spec: Spec, command: np.ndarray, rng, *, clean: bool, low_freq: bool,
         chip: bool, t_abs: float, offset_fn=None, lines: bool = True,
         pre: int = 0) -> dict:
    """Loop run of ``command`` after an idle warm-up; outputs from ``-pre`` samples."""
    fs = ctx.mach.fs
    nw = int(WARMUP * fs)
    n = nw + command.size
    ref = np.concatenate([np.zeros(nw), command])
    kw = {}
    if not clean:
        src = _noise_run(ctx, spec, n, rng, low_freq)
        kw = {"sensor_noise": src["sensor"], "current_noise": src["current"],
              "base": src["base"]}
    # lines are locked to absolute time (mains, machinery): records taken at
    # different times see different phases
    lines = tuple((f, a, 0.0) for f, a in spec.lines) if lines else ()
    zoff = None
    if offset_fn is not None:
        t = (np.arange(n) - nw) / fs
        th = ctx.path.theta0 + ctx.path.omega * t
        zoff = np.where(t >= 0, offset_fn(np.maximum(t, 0.0), th), 0.0)
    ch = None
    if chip:
        ch = Chip(kt=ctx.chip.kt * spec.kt_scale, radius=ctx.chip.radius, ke=spec.ke,
                  hold=ctx.chip.hold)
    o = simulate(ctx.mach, ctx.ctrl, ref, eff=spec.loop, chip=ch, lines=lines,
                 zoff=zoff, t0=t_abs - WARMUP, nsub=NSUB, **kw)
    return {k: v[nw - pre :] for k, v in o.items()}


def _pickup(spec: Spec, t: np.ndarray) -> np.ndarray:
    """Pickup lines ``(f, a)`` or, with a drifting phase, ``(f, a, beta, f_d)``:
    ``a cos(2 pi f t + beta sin(2 pi f_d t))`` (a mains frequency wandering slowly
    about its nominal value, beta in rad, f_d in Hz)."""
    out = np.zeros(t.size)
    for line in spec.pickup:
        f, a = line[0], line[1]
        ph = 0.0
        if len(line) == 4:
            ph = line[2] * np.sin(2 * math.pi * line[3] * t)
        out += a * np.cos(2 * math.pi * f * t + ph)
    return out


def _frf_grid(d: dict) -> np.ndarray:
    if d["spacing"] == "log":
        return np.geomspace(d["fmin"], d["fmax"], d["n"])
    return np.linspace(d["fmin"], d["fmax"], d["n"])


def _line_response(ctx, spec: Spec, t: np.ndarray, t_abs: float, out: str):
    """Steady response of the linear loop to the base lines at times ``t``."""
    if not spec.lines:
        return np.zeros(t.size)
    f = np.array([x[0] for x in spec.lines])
    h = loop_frf(ctx.mach, ctx.ctrl, f, spec.loop.linear)[("base", out)]
    y = np.zeros(t.size)
    for j, (fj, a) in enumerate(spec.lines):
        y += a * abs(h[j]) * np.cos(2 * math.pi * fj * (t + t_abs) + np.angle(h[j]))
    return y


def recordings(ctx: Context, camp: Campaign, spec: Spec, seed: int, *,
               clean: bool = False, only: set | None = None) -> dict:
    """The recordings of one case.

    Parameters
    ----------
    ctx : Context
    camp : Campaign
    spec : Spec
        The effect at its strength.
    seed : int
        Seed of every random draw of the realisation (same seed, same noise).
    clean : bool
        Noise-free (for the effect-to-noise ratio): time records without noise,
        maps from the periodic steady state plus the line responses.
    only : set of str, optional
        Recording groups to produce (``idle``, ``air``, ``air_b``, ``cut``, ``frf``,
        ``map``); default all the campaign has.

    Returns
    -------
    dict
        Arrays in SI units per recording (see :func:`write_case`).
    """
    rng = np.random.default_rng(seed)
    mach, path = ctx.mach, ctx.path
    fs = mach.fs
    out: dict = {}
    t_abs = {k: float(rng.uniform(0, 1000)) for k in ("idle", "air", "air_b", "cut")}

    def want(k):
        return only is None or k in only

    if camp.idle and want("idle"):
        # consecutive records of one idle run
        d = camp.idle
        n = d["records"] * d["length"]
        o = _run(ctx, spec, np.zeros(n + PAD), rng, clean=clean,
                 low_freq=camp.low_freq_base, chip=False, t_abs=t_abs["idle"],
                 pre=PAD)
        t = (np.arange(n + 2 * PAD) - PAD) / fs + t_abs["idle"]
        fe = o["fe"] + _pickup(spec, t)
        L = d["length"]
        fe = np.stack([_logger(fe[j * L : (j + 1) * L + 2 * PAD], d["div"], fs, L)
                       for j in range(d["records"])])
        out["idle"] = fe
    for key in ("air", "air_b"):
        d = getattr(camp, key)
        if not d or not want(key):
            continue
        n = d["length"]
        t = (np.arange(n + 2 * PAD) - PAD) / fs
        if key == "air":
            cmd = path.command(t)
        else:
            a = path.amplitude
            cmd = (a - path.depth) - a * np.sin(2 * math.pi * d["f"] * t)
        cmd[:PAD] = 0.0  # at rest before the record starts
        o = _run(ctx, spec, cmd[PAD:], rng, clean=clean, low_freq=camp.low_freq_base,
                 chip=False, t_abs=t_abs[key], pre=PAD)
        fe = o["fe"] + _pickup(spec, t + t_abs[key])
        # the command is a controller variable: logged by plain decimation
        out[key] = {"fe": _logger(fe, d["div"], fs, n),
                    "command": cmd[PAD : PAD + n : d["div"]].copy()}
    need_map = (camp.surface or camp.profiles) and want("map")
    if (camp.cut and want("cut")) or need_map:
        ncut = camp.cut["length"] if camp.cut else 0
        if clean:
            n = max(ncut, int(STEADY * fs))
        elif need_map:
            n = int(math.ceil(path.duration * fs)) + 2
        else:
            n = ncut
        n = max(n, ncut + PAD)
        t = np.arange(n) / fs
        o = _run(ctx, spec, path.command(t), rng, clean=clean,
                 low_freq=camp.low_freq_base, chip=True, t_abs=t_abs["cut"],
                 offset_fn=spec.offset, pre=PAD)
        if camp.cut and want("cut"):
            d = camp.cut
            te = (np.arange(ncut + 2 * PAD) - PAD) / fs
            fe = o["fe"][: ncut + 2 * PAD] + _pickup(spec, te + t_abs["cut"] + 0.5)
            fo = o["force"][: ncut + 2 * PAD].copy()
            if not clean:
                fo = fo + d["force_noise"] * rng.standard_normal(fo.size)
            fe_l = _logger(fe, d["div"], fs, ncut)
            out["cut"] = {"t": np.arange(fe_l.size) * d["div"] / fs, "fe": fe_l,
                          "force": _logger(fo, d["div"], fs, ncut)}
        o = {k: v[PAD:] for k, v in o.items()}
        if need_map:
            x1 = o["tool"]
            if clean and spec.lines:
                x1 = _run(ctx, spec, path.command(t), rng, clean=True, low_freq=False,
                          chip=True, t_abs=t_abs["cut"], offset_fn=spec.offset,
                          lines=False)["tool"]
            if clean:
                # periodic steady state of the last lenslet period, plus lines
                per = fs / path.frequency
                m = int(round(per))
                ss = x1[-m:] if abs(per - m) < 1e-9 else None
                k0 = t.size - m

                ta = t_abs["cut"]

                def tool_z(tt, ss=ss, k0=k0, ta=ta):
                    if ss is None:
                        raise ValueError("lenslet period is not a whole sample count")
                    ph = np.mod(tt * fs - k0, m)
                    i = np.floor(ph).astype(int)
                    a = ph - i
                    y = ss[i] * (1 - a) + ss[(i + 1) % m] * a
                    return y + _line_response(ctx, spec, tt, ta, "tool")
            else:
                def tool_z(tt, x1=x1):
                    return np.interp(tt * fs, np.arange(x1.size), x1)
            out.update(_maps(ctx, camp, spec, tool_z, rng, clean))
    if camp.frfs and want("frf"):
        for kind, d in camp.frfs.items():
            f = _frf_grid(d)
            fd = spec.flex_dyn(f) if spec.flex_dyn is not None else None
            paths = loop_frf(mach, ctx.ctrl, f, spec.loop.linear, flex_dyn=fd)
            h = paths[{"frf-open-loop": "open_loop",
                       "frf-closed-loop": ("reference", "sensor"),
                       "frf-force": ("force", "sensor")}[kind]]
            if not clean:
                g = (rng.standard_normal(f.size) + 1j * rng.standard_normal(f.size))
                h = h * (1.0 + d["noise"] * g / math.sqrt(2.0))
            out[kind] = (f, h)
    return out


def _maps(ctx, camp: Campaign, spec: Spec, tool_z, rng, clean: bool) -> dict:
    path = ctx.path
    out = {}
    kw = {"radius": spec.radius, "waviness": spec.waviness, "offset": spec.offset}
    if camp.surface:
        s = camp.surface
        r = path.ring_radii()[s["ring"]]
        ang = 2 * math.pi * s["lenslet"] / path.n_lenslets
        cx = r * math.cos(ang) + s["shift"][0]
        cy = r * math.sin(ang) + s["shift"][1]
        shape = tuple(s["shape"])
        x, y, x0, y0 = field_points((cx, cy), (s["pitch"], s["pitch"]), shape)
        dx, dy = (0.0, 0.0) if clean else s["registration"]
        z = heights(path, x + dx, y + dy, tool_z, **kw).reshape(shape)
        if not clean:
            xx = (x - cx).reshape(shape)
            yy = (y - cy).reshape(shape)
            z = (z + s["piston"] + s["tilt"][0] * xx + s["tilt"][1] * yy
                 + s["noise"] * rng.standard_normal(shape))
        out["surface"] = {"z": z, "dx": s["pitch"], "dy": s["pitch"], "x0": x0,
                          "y0": y0}
    for k, p in enumerate(camp.profiles):
        r = float(path.ring_radii()[p["ring"]])
        x, y = ring_points(r, p["dx"], p["angle"])
        if not clean:
            a = p["registration"] / r
            c, s_ = math.cos(a), math.sin(a)
            x, y = c * x - s_ * y, s_ * x + c * y
        z = heights(path, x, y, tool_z, **kw)
        if not clean:
            z = z + p["piston"] + p["noise"] * rng.standard_normal(z.size)
        out[f"ring{k}"] = {"z": z, "dx": p["dx"], "radius": r, "angle": p["angle"]}
    return out


# ------------------------------------------------------------------ noise levels
def noise_rms(ctx: Context, camp: Campaign, spec: Spec | None = None) -> dict:
    """RMS of the noise each recording carries (the ENR denominators), SI.

    Time records: the documented sources through the loop, integrated over
    ``[fs / 4096, logger Nyquist]``; maps: the tool's noise and the instrument's;
    FRFs: the relative complex noise; the cut force: the force sensor's noise.
    """
    mach = ctx.mach
    fs = mach.fs
    scale = spec.noise_scale if spec is not None else {}
    out = {}

    def band(div, outp):
        f = np.geomspace(fs / 4096, fs / 2 / div, 4000)
        h = loop_frf(mach, ctx.ctrl, f)
        p = np.zeros(f.size)
        for src, key in (("sensor", "sensor_noise"), ("current", "current_noise"),
                         ("base", "base")):
            p += scale.get(src, 1.0) * mach.psd[src](f) * np.abs(h[(key, outp)]) ** 2
        return float(math.sqrt(np.trapezoid(p, f)))

    for key in ("idle", "air", "air_b"):
        d = getattr(camp, key)
        if d:
            out[key] = band(d["div"], "fe")
    if camp.cut:
        out["cut_fe"] = band(camp.cut["div"], "fe")
        out["cut_force"] = camp.cut["force_noise"]
    for kind, d in camp.frfs.items():
        out[kind] = d["noise"]
    tool = band(1, "tool")
    if camp.surface:
        out["surface"] = math.hypot(tool, camp.surface["noise"])
    for k, p in enumerate(camp.profiles):
        out[f"ring{k}"] = math.hypot(tool, p["noise"])
    return out


def enr_by_recording(rec1: dict, rec0: dict, sigma: dict) -> dict:
    """Effect-to-noise ratio per recording: RMS of the change over the noise RMS.

    FRFs: RMS of ``|log(h1 / h0)|``; maps and profiles: over the points cut
    (below -EDGE) in both; the idle records: over all samples.
    """
    out = {}
    for key, s in sigma.items():
        src = "cut" if key.startswith("cut_") else key
        if src not in rec1 or src not in rec0:
            continue
        if key == "idle":
            d = rec1["idle"] - rec0["idle"]
        elif key in ("air", "air_b"):
            d = rec1[key]["fe"] - rec0[key]["fe"]
        elif key == "cut_fe":
            d = rec1["cut"]["fe"] - rec0["cut"]["fe"]
        elif key == "cut_force":
            d = rec1["cut"]["force"] - rec0["cut"]["force"]
        elif key.startswith("frf-"):
            d = np.abs(np.log(rec1[key][1] / rec0[key][1]))
        else:
            z1, z0 = rec1[key]["z"], rec0[key]["z"]
            cut = (z0 < -EDGE) & (z1 < -EDGE)
            if not cut.any():
                continue
            d = (z1 - z0)[cut]
        out[key] = float(np.sqrt(np.mean(np.square(d)))) / s
    return out


# ------------------------------------------------------------------ writing
def _write_csv(path: Path, header: list[str], cols: list[np.ndarray]) -> None:
    with open(path, "w", newline="") as fh:
        fh.write(",".join(header) + "\n")
        np.savetxt(fh, np.column_stack(cols), delimiter=",", fmt="%.12g")


def write_case(folder: Path, ctx: Context, camp: Campaign, rec: dict) -> None:
    """Write the recordings and ``manifest.toml`` of one case into ``folder``."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    fs = ctx.mach.fs
    items = []
    if "idle" in rec:
        d = camp.idle
        fl = fs / d["div"]
        x = rec["idle"]
        if d["fmt"] == "npz":
            np.savez(folder / "idle.npz", fs_hz=fl, following_error_m=x)
            items.append(("idle.npz", "following-error", {}))
        else:
            t = np.tile(np.arange(x.shape[1]) / fl, x.shape[0])
            r = np.repeat(np.arange(x.shape[0]), x.shape[1])
            _write_csv(folder / "idle.csv", ["time_s", "following_error_m", "record"],
                       [t, x.ravel(), r])
            items.append(("idle.csv", "following-error", {}))
    for key, name in (("air", "aircut"), ("air_b", "aircut_b")):
        if key not in rec:
            continue
        d = getattr(camp, key)
        fl = fs / d["div"]
        fe, cmd = rec[key]["fe"], rec[key]["command"]
        if d["fmt"] == "npz":
            np.savez(folder / f"{name}.npz", fs_hz=fl, following_error_m=fe[None],
                     command_m=cmd[None])
            items.append((f"{name}.npz", "following-error", {}))
        else:
            _write_csv(folder / f"{name}.csv", ["time_s", "following_error_m",
                                                "command_m"],
                       [np.arange(fe.size) / fl, fe, cmd])
            items.append((f"{name}.csv", "following-error", {}))
    if "cut" in rec:
        c = rec["cut"]
        _write_csv(folder / "cut.csv", ["time_s", "force_n", "following_error_m"],
                   [c["t"], c["force"], c["fe"]])
        items.append(("cut.csv", "cut", {}))
    for kind in ("frf-open-loop", "frf-closed-loop", "frf-force"):
        if kind in rec:
            f, h = rec[kind]
            name = kind.replace("frf-", "frf_").replace("-", "_") + ".csv"
            _write_csv(folder / name, ["frequency_hz", "real", "imag"],
                       [f, h.real, h.imag])
            items.append((name, kind, {}))
    if "surface" in rec:
        s = rec["surface"]
        np.savez(folder / "surface.npz", z=s["z"], dx=s["dx"], dy=s["dy"], x0=s["x0"],
                 y0=s["y0"])
        items.append(("surface.npz", "surface", {}))
    k = 0
    while f"ring{k}" in rec:
        p = rec[f"ring{k}"]
        np.savez(folder / f"ring{k}.npz", z=p["z"], dx=p["dx"])
        items.append((f"ring{k}.npz", "profile",
                      {"radius": p["radius"], "angle-start": p["angle"]}))
        k += 1
    tp = os.path.relpath(TOOLPATH, folder)
    lines = ["[case]", 'machine = "seed-prototype"', f'toolpath = "{tp}"',
             f"bandwidth = {BANDWIDTH}", f"moving-mass = {MASS}", ""]
    for name, kind, opts in items:
        lines += ["[[recording]]", f'path = "{name}"', f'kind = "{kind}"']
        lines += [f"{k2} = {v!r}" for k2, v in opts.items()]
        lines.append("")
    (folder / "manifest.toml").write_text("\n".join(lines))


def nominal_spec() -> Spec:
    """The nominal machine (no effect)."""
    return Spec(loop=LoopEffects())
