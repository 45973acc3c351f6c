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

from ..servo import (
    PIDF,
    LoopPerturbation,
    Machine,
    Nonlinearity,
    ServoLoop,
    StructuralMode,
)

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

#: Output names of :meth:`ServoLoop.frf` as the diagnosis calls them.
_OUT = {"following_error": "fe"}


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
    def perturbation(self, p: ModelParams) -> LoopPerturbation:
        """The linear plant change of ``p`` (delay, mode, recalibration)."""
        modes = ()
        if p.has_mode:
            modes = (StructuralMode(p.mode_frequency, p.mode_damping, p.mode_gain),)
        return LoopPerturbation(
            extra_delay=p.extra_delay,
            modes=modes,
            moving_mass=p.moving_mass,
            flexure_stiffness=p.flexure_stiffness,
            flexure_damping=p.flexure_damping,
            force_constant=p.force_constant,
            sensor_bandwidth=p.sensor_bandwidth,
        )

    def nonlinearity(self, p: ModelParams) -> Nonlinearity:
        """The loop nonlinearities of ``p`` (saturation, Kf(x), flexure)."""
        return Nonlinearity(
            max_current=p.max_current,
            kf_b1=p.kf_b1,
            kf_b2=p.kf_b2,
            flexure_k2=p.flexure_k2,
            flexure_k3=p.flexure_k3,
        )

    def loop_for(self, p: ModelParams) -> ServoLoop:
        """The simulator's loop under ``p`` with the installed (nominal) controller."""
        return self.loop.perturbed(self.perturbation(p))

    def machine_for(self, p: ModelParams) -> Machine:
        """Machine with the recalibration and delay knobs of ``p`` applied."""
        return self.loop_for(p).machine

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

        The simulator's own FRFs (:meth:`ServoLoop.frf` and
        :meth:`ServoLoop.open_loop` under :meth:`perturbation`), renamed for the
        diagnosis.

        Returns
        -------
        dict
            ``"open_loop"``: DAC V -> sensor V (ZOH and delay included);
            ``"loop"``: the open-loop gain L;
            ``(input, output)`` for inputs ``reference``, ``sensor_noise``,
            ``current_noise`` (per A), ``base`` (per m), ``force`` (per N) and
            outputs ``fe`` (following error, m), ``tool`` (m), ``sensor`` (m).
        """
        freq = np.asarray(freq, dtype=float)
        pert = self.perturbation(p)
        frf = self.loop.frf(freq, perturbation=pert)
        out: dict = {
            "open_loop": self.loop.open_loop(freq, perturbation=pert),
            "loop": frf.loop,
        }
        for (inp, outp), h in frf.paths.items():
            out[(inp, _OUT.get(outp, outp))] = h
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
        """Discrete model ``(ad, bd, cx, nd, frac)`` of the loop under ``p``."""
        lp = self.loop_for(p)
        ad, bd, cx = lp.discrete_models()[:3]
        nd, frac = lp.delay_split()
        return ad, bd, cx, nd, frac

    def controller(self):
        """Tustin controller ``(ac, bc, cc, dc)`` of the installed PIDF."""
        ac, bc, cc, dc = self.loop.discrete_models()[3:]
        return ac, bc, np.ascontiguousarray(cc.ravel()), float(dc.ravel()[0])

    def kt(self, p: ModelParams) -> float:
        """Specific thrust pressure under ``p`` in N/m^2."""
        return (
            self.specific_force if p.specific_force is None else float(p.specific_force)
        )

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
        from ..cutting import ChipModel

        chip_model = ChipModel(self.kt(p), self.tool_radius(), 0.0) if chip else None
        out = self.loop.simulate(
            reference=reference,
            force=force,
            current_noise=current_noise,
            sensor_noise=sensor_noise,
            chip=chip_model,
            perturbation=self.perturbation(p),
            nonlinearity=self.nonlinearity(p),
        )
        return {
            "tool": out["tool"],
            "sensor": out["sensor"],
            "fe": out["following_error"],
            "u": out["u"],
            "force": out["force"],
            "current": out["current"],
        }

    # ------------------------------------------------------------ stability
    def is_stable(self, p: ModelParams) -> bool:
        """True when the discrete closed loop under ``p`` is stable (linear part)."""
        return self.loop.is_stable(perturbation=self.perturbation(p))
