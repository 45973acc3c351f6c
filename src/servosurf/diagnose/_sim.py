"""The diagnosis simulator: the seed-paper loop with pluggable effect modules.

:class:`ModelParams` holds every knob a catalogue effect can turn, all in SI units
and all "off" by default, so ``ModelParams()`` is the nominal machine.
:class:`CaseModel` evaluates one case (machine, bandwidth, moving mass, toolpath)
under a :class:`ModelParams`:

* frequency domain (sampled-data approximation, as :meth:`ServoLoop.frf`): open-
  and closed-loop FRFs and the stochastic following-error and tool-error PSDs,
  with an extra structural mode and an extra loop delay;
* time domain (exact ZOH discretisation, as :meth:`ServoLoop.simulate`): the loop
  with the memoryless nonlinear modules (current saturation, force constant
  ``Kf(x)``, flexure ``k2q d^2 + k3 d^3``), the extra mode and the chip force.

Decisions (documented here once):

* The controller gains are those tuned for the **nominal** machine at the case's
  bandwidth and are held fixed whatever the effects do to the plant: the
  controller is what was installed, the plant is what is found.
* The structural mode ``q'' + 2 zeta w q' + w^2 q = w^2 g Fa`` is driven by the
  actuator force and adds ``q`` to both the tool and the measured position
  (collocated, ``g > 0``).
* Saturation clips the current demand ``G_I u`` at ``+-I_max`` before the
  amplifier's double pole.
* The flexure nonlinearity acts on m2 only (its reaction on the 1.2 kg, 5e7 N/m
  carriage moves it by picometres).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np
import scipy as sp

from ..servo import PIDF, Machine, ServoLoop, plant_from_machine, set_param

__all__ = ["ModelParams", "CaseModel", "NOMINAL"]


@dataclass(frozen=True)
class ModelParams:
    """Every knob of the diagnosis simulator, SI units, default = nominal machine.

    Parameters
    ----------
    extra_delay : float
        Loop delay added to the machine's, in s (may be negative down to minus
        the nominal delay).
    mode_frequency, mode_damping, mode_gain : float
        Extra structural mode: natural frequency (Hz), damping ratio (-), static
        compliance from actuator force to tool and sensor (m/N; 0 = no mode).
    max_current : float
        Current-demand saturation in A (``inf`` = none).
    kf_b1, kf_b2 : float
        Position dependence of the force constant, 1/m and 1/m^2.
    flexure_k2, flexure_k3 : float
        Quadratic (N/m^2) and cubic (N/m^3) flexure stiffness.
    line_frequencies, line_amplitudes : tuple of float
        Deterministic base-vibration lines: Hz and zero-to-peak base displacement
        in m.
    sensor_floor : float or None
        White floor of the sensor noise, m/sqrt(Hz) (None = machine's).
    sensor_corner : float or None
        Roll-off corner of the sensor noise, Hz (None = machine's).
    specific_force : float or None
        Specific cutting force k_t in N/m^2 (None = case's).
    sensor_a2, sensor_a3 : float
        Sensor nonlinearity ``y = x + a2 x^2 + a3 x^3`` (1/m, 1/m^2).
    drift_amplitude, drift_time_constant, drift_rate : float
        Thermal drift ``a (1 - exp(-t / tau)) + b t`` of the tool height (m, s,
        m/s).
    spindle_orders, spindle_amplitudes, spindle_phases : tuple
        Synchronous axial error ``sum a_h cos(h theta + phi_h)`` (integer orders,
        m, rad).
    waviness : tuple of float
        Tool-edge waviness: Legendre coefficients (m) of orders 3, 4, ... in
        ``phi / phi_ref`` (outward deviation of the edge).
    radius_error : float
        Tool nose radius error in m (tip held).
    recovery : float
        Elastic recovery: fraction of the local depth of cut that springs back (-).
    moving_mass, flexure_stiffness, flexure_damping, force_constant : float or None
        Recalibrated machine parameters (kg, N/m, N s/m, N/A; None = machine's).
    sensor_bandwidth : float or None
        Recalibrated -3 dB bandwidth of the position sensor, Hz (None = machine's).
        Its lag is in every tracking record: 15 against 20 kHz changes the
        following error of the 10 um, 100 Hz lenslet command by about 17 nm.
    """

    extra_delay: float = 0.0
    mode_frequency: float = 0.0
    mode_damping: float = 0.02
    mode_gain: float = 0.0
    max_current: float = math.inf
    kf_b1: float = 0.0
    kf_b2: float = 0.0
    flexure_k2: float = 0.0
    flexure_k3: float = 0.0
    line_frequencies: tuple[float, ...] = ()
    line_amplitudes: tuple[float, ...] = ()
    sensor_floor: float | None = None
    sensor_corner: float | None = None
    specific_force: float | None = None
    sensor_a2: float = 0.0
    sensor_a3: float = 0.0
    drift_amplitude: float = 0.0
    drift_time_constant: float = 1.0
    drift_rate: float = 0.0
    spindle_orders: tuple[int, ...] = ()
    spindle_amplitudes: tuple[float, ...] = ()
    spindle_phases: tuple[float, ...] = ()
    waviness: tuple[float, ...] = ()
    radius_error: float = 0.0
    recovery: float = 0.0
    moving_mass: float | None = None
    flexure_stiffness: float | None = None
    flexure_damping: float | None = None
    force_constant: float | None = None
    sensor_bandwidth: float | None = None

    def replace(self, **kw) -> ModelParams:
        """Return a copy with some knobs changed."""
        return dataclasses.replace(self, **kw)

    # keys selecting cached discrete models
    def linear_key(self) -> tuple:
        """Knobs that change the linear loop (delay, mode, recalibration)."""
        mode = (
            (self.mode_frequency, self.mode_damping, self.mode_gain)
            if self.mode_gain != 0.0 and self.mode_frequency > 0
            else ()
        )
        return (
            self.extra_delay,
            mode,
            self.moving_mass,
            self.flexure_stiffness,
            self.flexure_damping,
            self.force_constant,
            self.sensor_bandwidth,
        )

    def key(self, tags: tuple[str, ...]) -> tuple:
        """Values of the knob groups ``tags`` (for caching what depends on them).

        Groups: ``linear`` (delay, mode, recalibration), ``lines``,
        ``sensor_noise``, ``nonlin`` (saturation, Kf(x), flexure), ``force``
        (specific cutting force), ``path`` (sensor nonlinearity, drift, spindle),
        ``tool`` (waviness, radius error, elastic recovery).
        """
        out = []
        for t in tags:
            if t == "linear":
                out.append(self.linear_key())
            elif t == "lines":
                out.append((self.line_frequencies, self.line_amplitudes))
            elif t == "sensor_noise":
                out.append((self.sensor_floor, self.sensor_corner))
            elif t == "nonlin":
                out.append(
                    (
                        self.max_current,
                        self.kf_b1,
                        self.kf_b2,
                        self.flexure_k2,
                        self.flexure_k3,
                    )
                )
            elif t == "force":
                out.append(self.specific_force)
            elif t == "path":
                out.append(
                    (
                        self.sensor_a2,
                        self.sensor_a3,
                        self.drift_amplitude,
                        self.drift_time_constant,
                        self.drift_rate,
                        self.spindle_orders,
                        self.spindle_amplitudes,
                        self.spindle_phases,
                    )
                )
            elif t == "tool":
                out.append((self.waviness, self.radius_error, self.recovery))
            else:
                raise ValueError(f"unknown knob group {t!r}")
        return tuple(out)

    @property
    def has_mode(self) -> bool:
        """True when an extra structural mode is active."""
        return self.mode_gain != 0.0 and self.mode_frequency > 0.0


NOMINAL = ModelParams()


def _double_pole(s: np.ndarray, w: float) -> np.ndarray:
    return w**2 / (s + w) ** 2


class CaseModel:
    """One diagnosis case: nominal machine, fixed controller and toolpath.

    Parameters
    ----------
    machine : Machine
        Nominal machine (moving mass and bandwidth already applied).
    toolpath : ToolpathSpec, optional
        The toolpath of cut recordings and surface maps.
    specific_force : float, optional
        Nominal specific thrust pressure k_t in N/m^2 (thrust per chip area);
        default the built-in NiP workpiece's
        (:class:`servosurf.cutting.Material`).
    """

    def __init__(
        self, machine: Machine, toolpath=None, *, specific_force: float | None = None
    ) -> None:
        if specific_force is None:
            from ..cutting import load_workpiece

            specific_force = load_workpiece(None).material.specific_thrust_pressure
        self.machine = machine
        self.toolpath = toolpath
        self.specific_force = float(specific_force)
        self.loop = ServoLoop(machine)
        self.pidf: PIDF = self.loop.pidf
        self.fs = float(machine.controller.sample_rate)
        self._cache: dict = {}

    # ------------------------------------------------------------ machine
    def machine_for(self, p: ModelParams) -> Machine:
        """Machine with the recalibration and delay knobs of ``p`` applied."""
        m = self.machine
        if p.moving_mass is not None:
            m = m.with_moving_mass(p.moving_mass)
            # keep the controller as installed (with_moving_mass keeps gains unset)
        if p.flexure_stiffness is not None:
            m = set_param(m, "mechanics.k2", float(p.flexure_stiffness))
        if p.flexure_damping is not None:
            m = set_param(m, "mechanics.c2", float(p.flexure_damping))
        if p.force_constant is not None:
            m = set_param(m, "actuator.force_constant", float(p.force_constant))
        if p.sensor_bandwidth is not None:
            m = set_param(m, "sensor.bandwidth", float(p.sensor_bandwidth))
        if p.extra_delay != 0.0:
            d = m.controller.delay + p.extra_delay * self.fs
            m = set_param(m, "controller.delay", float(max(d, 0.0)))
        return m

    def loop_for(self, p: ModelParams) -> ServoLoop:
        """ServoLoop of the plant under ``p`` with the nominal controller."""
        key = ("loop",) + p.linear_key()
        if key not in self._cache:
            self._trim()
            self._cache[key] = ServoLoop(self.machine_for(p), pidf=self.pidf)
        return self._cache[key]

    def _trim(self) -> None:
        if len(self._cache) > 256:
            for k in list(self._cache)[:128]:
                del self._cache[k]

    def tool_radius(self) -> float:
        """Nose radius of the case's tool in m (0.5 mm without a toolpath)."""
        return (
            float(self.toolpath.tool.nose_radius)
            if self.toolpath is not None
            else 0.5e-3
        )

    # ------------------------------------------------------------ frequency
    def paths(self, p: ModelParams, freq: np.ndarray) -> dict:
        """Closed-loop and open-loop responses at ``freq`` (Hz) under ``p``.

        Returns
        -------
        dict
            ``"open_loop"``: DAC V -> sensor V (ZOH and delay included);
            ``(input, output)`` for inputs ``reference``, ``sensor_noise``,
            ``current_noise`` (per A), ``base`` (per m), ``force`` (per N) and
            outputs ``fe`` (following error, m), ``tool`` (m), ``sensor`` (m).
        """
        freq = np.asarray(freq, dtype=float)
        m = self.machine_for(p)
        s = 2j * np.pi * freq
        t = 1.0 / self.fs
        amp = m.actuator.current_gain * _double_pole(s, m.actuator.corner)
        sens = _double_pole(s, m.sensor.corner)
        with np.errstate(invalid="ignore", divide="ignore"):
            zoh = np.where(np.abs(s) > 0, (1 - np.exp(-s * t)) / (s * t), 1.0)
        delay = zoh * np.exp(-s * m.controller.delay * t)
        pl = plant_from_machine(m).frf(freq)
        sd = 1 if m.sensor.location == "carrier" else 0
        bl = m.actuator.force_constant
        hr = np.zeros_like(s)
        if p.has_mode:
            wr = 2 * np.pi * p.mode_frequency
            hr = p.mode_gain * wr**2 / (s**2 + 2 * p.mode_damping * wr * s + wr**2)
        pa1 = pl["actuator_force"][:, 0] + hr
        pam = pl["actuator_force"][:, sd] + hr
        gyu = amp * bl * pam * sens
        gxu = amp * bl * pa1
        k = self.pidf.frf(freq) * delay * m.sensor.sensitivity
        loop = k * gyu
        one = 1.0 + loop
        out: dict = {"open_loop": delay * gyu * m.sensor.sensitivity, "loop": loop}
        out[("reference", "fe")] = 1.0 / one
        out[("reference", "sensor")] = gyu * k / one
        out[("reference", "tool")] = gxu * k / one
        out[("sensor_noise", "fe")] = -1.0 / one
        out[("sensor_noise", "tool")] = -gxu * k / one
        dist = {
            "current_noise": (bl * pa1, bl * pam * sens),
            "base": (pl["base"][:, 0], pl["base"][:, sd] * sens),
            "force": (pl["tool_force"][:, 0], pl["tool_force"][:, sd] * sens),
        }
        for name, (gx, gy) in dist.items():
            out[(name, "fe")] = -gy / one
            out[(name, "sensor")] = gy / one
            out[(name, "tool")] = gx - gxu * k * gy / one
        return out

    def disturbance_psds(self, p: ModelParams, freq: np.ndarray) -> dict:
        """Disturbance PSDs Ws (m^2/Hz), Wi (A^2/Hz), Wg (m^2/Hz) under ``p``."""
        from ..noise import evaluate_psd

        d = self.machine.disturbances
        sn = d.sensor_noise
        kw = {}
        if p.sensor_floor is not None:
            kw["floor"] = float(p.sensor_floor)
        if p.sensor_corner is not None:
            kw["corner"] = float(p.sensor_corner)
        if kw:
            sn = dataclasses.replace(sn, **kw)
        return {
            "sensor_noise": evaluate_psd(sn, freq),
            "current_noise": evaluate_psd(d.current_noise, freq),
            "base": evaluate_psd(d.base_vibration, freq),
        }

    def noise_psd(
        self,
        p: ModelParams,
        freq: np.ndarray,
        output: str = "fe",
        paths: dict | None = None,
    ) -> np.ndarray:
        """One-sided PSD (m^2/Hz) of the stochastic part of ``output`` at ``freq``.

        ``output`` is ``"fe"`` (following error) or ``"tool"`` (real tool error).
        Frequencies below ``fs / 4096`` carry no power (the project's convention,
        :func:`servosurf.noise.frequency_grid`). Lines are not included.
        """
        freq = np.asarray(freq, dtype=float)
        ps = self.paths(p, freq) if paths is None else paths
        w = self.disturbance_psds(p, freq)
        tot = np.zeros(freq.shape)
        for name, wk in w.items():
            tot += wk * np.abs(ps[(name, output)]) ** 2
        tot[freq < self.fs / 4096 * (1 - 1e-9)] = 0.0
        return tot

    # ------------------------------------------------------------ time domain
    def discrete(self, p: ModelParams):
        """Discrete augmented model ``(ad, bd, cx, nd, frac)`` under ``p`` (cached)."""
        key = ("disc",) + p.linear_key()
        hit = self._cache.get(key)
        if hit is not None:
            return hit
        loop = self.loop_for(p)
        a, b, c = loop.analogue_ss()
        m = loop.machine
        n0 = a.shape[0]
        nm = 2 if p.has_mode else 0
        n = n0 + nm
        A = np.zeros((n, n))
        B = np.zeros((n, 3))
        A[:n0, :n0] = a
        B[:n0] = b
        cx = np.zeros((5, n))
        cx[0, :n0] = c[0]
        cx[1, :n0] = c[1]
        cx[2, 0] = 1.0  # coil current I (amplifier state)
        cx[3, 3] = 1.0  # x2
        cx[4, 4] = 1.0  # x3
        if nm:
            wr = 2 * np.pi * p.mode_frequency
            bl = m.actuator.force_constant
            ws = m.sensor.corner
            A[n0, n0 + 1] = 1.0
            A[n0 + 1, n0] = -(wr**2)
            A[n0 + 1, n0 + 1] = -2 * p.mode_damping * wr
            A[n0 + 1, 0] = wr**2 * p.mode_gain * bl
            B[n0 + 1, 1] = wr**2 * p.mode_gain * bl
            A[11, n0] += ws**2  # sensor filter sees q
            cx[0, n0] = 1.0  # tool sees q
        t = 1.0 / self.fs
        big = np.zeros((n + 3, n + 3))
        big[:n, :n] = A * t
        big[:n, n:] = B * t
        e = sp.linalg.expm(big)
        ad, bd = e[:n, :n].copy(), e[:n, n:].copy()
        d = m.controller.delay
        nd = int(math.floor(d))
        out = (
            np.ascontiguousarray(ad),
            np.ascontiguousarray(bd),
            np.ascontiguousarray(cx),
            nd,
            float(d - nd),
        )
        self._trim()
        self._cache[key] = out
        return out

    def controller(self):
        """Tustin controller ``(ac, bc, cc, dc)`` of the fixed PIDF."""
        key = ("ctrl",)
        if key not in self._cache:
            ac, bc, cc, dc = self.pidf.discrete_ss()
            self._cache[key] = (
                np.ascontiguousarray(ac),
                np.ascontiguousarray(bc),
                np.ascontiguousarray(cc.ravel()),
                float(dc.ravel()[0]),
            )
        return self._cache[key]

    def kt(self, p: ModelParams) -> float:
        """Specific thrust pressure under ``p`` in N/m^2."""
        return (
            self.specific_force if p.specific_force is None else float(p.specific_force)
        )

    def chip_args(self, p: ModelParams) -> tuple[float, float, float, float]:
        """``(k_t, radius, top, area)`` of the lenslet chip force (plunge model)."""
        return self.kt(p), self.tool_radius(), 0.0, -1.0

    def facing_force(self, p: ModelParams, t: np.ndarray) -> np.ndarray:
        """Steady facing thrust ``k_t A`` (N), ramped in over the first revolution.

        As :func:`servosurf.simulation.simulate`: the feed-limited chip section of
        :func:`servosurf.cutting.facing_chip_area`, ramped from the record's start.
        """
        from ..cutting import facing_chip_area

        path = self.toolpath.path
        key = ("facing_area",)
        if key not in self._cache:
            self._cache[key] = facing_chip_area(
                self.tool_radius(), path.feed_per_rev, path.depth_of_cut
            )
        ramp = np.clip((t - t[0]) * path.rev_per_s, 0.0, 1.0)
        return self.kt(p) * self._cache[key] * ramp

    def simulate_path(self, p: ModelParams, t: np.ndarray) -> dict[str, np.ndarray]:
        """Cut the case's toolpath at times ``t`` (s), loop at rest at ``t[0]``.

        Lenslets: the chip force of a round tool plunging into the flat face at
        z = 0, from the actual tool height; facing: the steady feed-limited chip
        force (see :meth:`facing_force`).
        """
        ref = self.toolpath.path.z_at(t)
        if self.toolpath.kind == "facing":
            return self.simulate(p, reference=ref, force=self.facing_force(p, t))
        return self.simulate(p, reference=ref, chip=True)

    def simulate(
        self,
        p: ModelParams,
        *,
        reference: np.ndarray,
        force: np.ndarray | None = None,
        chip: bool = False,
        current_noise: np.ndarray | None = None,
        sensor_noise: np.ndarray | None = None,
    ) -> dict[str, np.ndarray]:
        """Simulate the loop sample by sample under ``p``.

        Parameters
        ----------
        p : ModelParams
            Effects.
        reference : ndarray of shape (n,)
            Commanded tool height in m (loop at rest before the first sample).
        force : ndarray of shape (n,), optional
            External force on the tool in N.
        chip : bool, default: False
            Add the chip force of the case's toolpath, computed from the actual
            tool height.
        current_noise, sensor_noise : ndarray of shape (n,), optional
            Noise inputs in A and m.

        Returns
        -------
        dict of str to ndarray of shape (n,)
            ``tool`` (m), ``sensor`` (m), ``fe`` (m), ``u`` (V), ``force`` (N),
            ``current`` (A). Non-finite values mean the loop diverged.
        """
        from ._kernels import _nl_loop

        r = np.ascontiguousarray(reference, dtype=np.float64)
        n = r.size
        z = np.zeros(n)

        def prep(a):
            return z if a is None else np.ascontiguousarray(a, dtype=np.float64)

        ad, bd, cx, nd, frac = self.discrete(p)
        ac, bc, cc, dc = self.controller()
        m = self.machine_for(p)
        kt, radius, top, area = self.chip_args(p) if chip else (0.0, 1.0, 0.0, -1.0)
        sat = math.isfinite(p.max_current)
        umax = p.max_current / m.actuator.current_gain if sat else 0.0
        out = np.zeros((6, n))
        with np.errstate(all="ignore"):
            _nl_loop(
                ad,
                bd,
                cx,
                ac,
                bc,
                cc,
                dc,
                m.sensor.sensitivity,
                nd,
                frac,
                r,
                prep(force),
                prep(current_noise),
                prep(sensor_noise),
                kt,
                radius,
                top,
                area,
                umax,
                p.kf_b1,
                p.kf_b2,
                p.flexure_k2,
                p.flexure_k3,
                m.actuator.force_constant,
                1 if sat else 0,
                out,
            )
        return {
            "tool": out[0],
            "sensor": out[1],
            "fe": out[2],
            "u": out[3],
            "force": out[4],
            "current": out[5],
        }

    # ------------------------------------------------------------ stability
    def is_stable(self, p: ModelParams) -> bool:
        """True when the discrete closed loop under ``p`` is stable (linear part)."""
        ad, bd, cx, nd, frac = self.discrete(p)
        ac, bc, cc, dc = self.controller()
        s = self.machine_for(p).sensor.sensitivity
        nb = nd + 2
        na, nc = ad.shape[0], ac.shape[0]
        n = na + nc + nb
        a = np.zeros((n, n))
        e_row = -s * cx[1]
        a[na : na + nc, :na] = np.outer(bc[:, 0], e_row)
        a[na : na + nc, na : na + nc] = ac
        u_row_a = dc * e_row
        o = na + nc
        a[o, :na] = u_row_a
        a[o, na : na + nc] = cc
        for j in range(1, nb):
            a[o + j, o + j - 1] = 1.0

        def add_applied(col: int, weight: float) -> None:
            if col == 0:
                a[:na, :na] += weight * np.outer(bd[:, 0], u_row_a)
                a[:na, na : na + nc] += weight * np.outer(bd[:, 0], cc)
            else:
                a[:na, o + col - 1] += weight * bd[:, 0]

        a[:na, :na] += ad
        add_applied(nd, 1.0 - frac)
        if frac > 0:
            add_applied(nd + 1, frac)
        return bool(np.max(np.abs(np.linalg.eigvals(a))) < 1.0 - 1e-9)
