"""What the installed loop does not know: a plant perturbation and nonlinearities.

The controller of a :class:`~servosurf.servo.ServoLoop` is what was installed (tuned
once for the nominal machine); the plant is what is found. Two small frozen objects
describe the difference and are arguments of the loop's frequency-response, pole and
time-domain functions, so that every caller (``simulate``, ``diagnose``, the
benchmarks) evaluates the same loop:

* :class:`LoopPerturbation` (linear): an extra loop delay, extra structural modes and
  recalibrated machine parameters (moving mass, flexure stiffness and damping, force
  constant, sensor bandwidth), applied to the plant with the controller held;
* :class:`Nonlinearity` (time domain only): current-demand saturation, a dead band
  and quantisation of the DAC command, the force constant's position dependence
  ``Kf(x2)``, a quadratic/cubic flexure, Bouc-Wen flexure hysteresis, Coulomb
  friction and quadratic damping of the carrier, a sensor nonlinearity and ADC
  quantisation of the reading.

Both default to "nothing": ``LoopPerturbation()`` and ``Nonlinearity()`` leave the
nominal loop bit for bit unchanged.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np

from ..errors import ConfigError
from ._machine import Machine

__all__ = ["StructuralMode", "LoopPerturbation", "Nonlinearity", "NL_FIELDS"]


@dataclass(frozen=True)
class StructuralMode:
    """An extra structural mode driven by the actuator force.

    ``q'' + 2 zeta w q' + w^2 q = w^2 g Fa`` with ``w = 2 pi frequency``; ``q`` (m)
    adds to the tool position and to the measured position (a collocated mode, sign
    of ``gain``). Disturbance forces on the carrier (current noise) drive it too.

    Parameters
    ----------
    frequency : float
        Natural frequency in Hz (> 0).
    damping : float
        Damping ratio zeta (dimensionless, > 0).
    gain : float
        Static compliance g from actuator force to ``q``, in m/N.
    """

    frequency: float
    damping: float = 0.02
    gain: float = 0.0

    def __post_init__(self) -> None:
        if not (math.isfinite(self.frequency) and self.frequency > 0):
            raise ConfigError(f"mode frequency must be > 0 Hz, got {self.frequency!r}")
        if not (math.isfinite(self.damping) and self.damping > 0):
            raise ConfigError(f"mode damping must be > 0, got {self.damping!r}")
        if not math.isfinite(self.gain):
            raise ConfigError(f"mode gain must be finite (m/N), got {self.gain!r}")

    def response(self, s: np.ndarray) -> np.ndarray:
        """``q / Fa`` in m/N at complex frequencies ``s`` (rad/s)."""
        w = 2 * np.pi * self.frequency
        return self.gain * w**2 / (s**2 + 2 * self.damping * w * s + w**2)


#: Recalibrated machine parameters of :class:`LoopPerturbation` and where they go.
_RECAL = {
    "flexure_stiffness": ("mechanics", "k2"),
    "flexure_damping": ("mechanics", "c2"),
    "force_constant": ("actuator", "force_constant"),
    "sensor_bandwidth": ("sensor", "bandwidth"),
}


@dataclass(frozen=True)
class LoopPerturbation:
    """A linear change of the plant under a fixed controller.

    Parameters
    ----------
    extra_delay : float, default: 0.0
        Loop delay added to the machine's computation delay, in s (may be negative
        down to minus that delay; the total is clipped at zero).
    modes : tuple of StructuralMode, default: ()
        Extra structural modes.
    moving_mass : float, optional
        Recalibrated m1 + m2 in kg (the difference goes where the machine puts
        added mass).
    flexure_stiffness : float, optional
        Recalibrated flexure stiffness k2 in N/m.
    flexure_damping : float, optional
        Recalibrated flexure damping c2 in N s/m.
    force_constant : float, optional
        Recalibrated motor force constant B l in N/A.
    sensor_bandwidth : float, optional
        Recalibrated -3 dB bandwidth of the position sensor, in Hz.
    """

    extra_delay: float = 0.0
    modes: tuple[StructuralMode, ...] = ()
    moving_mass: float | None = None
    flexure_stiffness: float | None = None
    flexure_damping: float | None = None
    force_constant: float | None = None
    sensor_bandwidth: float | None = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "modes", tuple(self.modes))
        if not math.isfinite(self.extra_delay):
            raise ConfigError(
                f"extra_delay must be finite (s), got {self.extra_delay!r}")
        for name in ("moving_mass", *_RECAL):
            v = getattr(self, name)
            if v is not None and not (math.isfinite(v) and v >= 0):
                raise ConfigError(f"{name} must be >= 0, got {v!r}")

    @property
    def is_nominal(self) -> bool:
        """True when the perturbation changes nothing."""
        return self == NOMINAL_PERTURBATION

    def apply(self, machine: Machine) -> Machine:
        """The machine with the recalibrated parameters and the extra delay.

        The controller gains are not touched (the loop holds its own PIDF); the
        modes are not part of a :class:`Machine` and stay in the perturbation.
        """
        m = machine
        if self.moving_mass is not None:
            m = m.with_moving_mass(self.moving_mass)
        for name, (sec, key) in _RECAL.items():
            v = getattr(self, name)
            if v is not None:
                section = dataclasses.replace(getattr(m, sec), **{key: float(v)})
                m = dataclasses.replace(m, **{sec: section})
        if self.extra_delay != 0.0:
            c = m.controller
            d = max(c.delay + self.extra_delay * c.sample_rate, 0.0)
            m = dataclasses.replace(m, controller=dataclasses.replace(c, delay=d))
        return m


NOMINAL_PERTURBATION = LoopPerturbation()

#: Order of the nonlinearity parameters in the kernel's vector (see
#: :meth:`Nonlinearity.vector` and ``kernels/_lti.py``).
NL_FIELDS = (
    "max_current",
    "kf_b1",
    "kf_b2",
    "flexure_k2",
    "flexure_k3",
    "sensor_a2",
    "sensor_a3",
    "friction",
    "friction_velocity",
    "quadratic_damping",
    "bouc_wen_stiffness",
    "bouc_wen_beta",
    "bouc_wen_gamma",
    "dac_step",
    "dac_dead_band",
    "adc_step",
)


@dataclass(frozen=True)
class Nonlinearity:
    """Memoryless and hysteretic departures of the loop (time domain), SI.

    Forces on the carrier m2 are evaluated from the state at the start of each
    controller sample and held over it, like the command (explicit treatment; the
    sample is 5 us against the fastest mechanical period of 70 us).

    Parameters
    ----------
    max_current : float, default: inf
        Saturation of the current demand ``G_I u`` at +-max_current, in A.
    kf_b1, kf_b2 : float, default: 0.0
        Force constant ``Kf(x2) = Kf0 (1 + b1 x2 + b2 x2^2)``, in 1/m and 1/m^2.
    flexure_k2, flexure_k3 : float, default: 0.0
        Flexure force ``-(k2q d^2 + k3 d^3)`` on m2, ``d = x2 - x3``, in N/m^2 and
        N/m^3.
    sensor_a2, sensor_a3 : float, default: 0.0
        Sensor reading ``y + a2 y^2 + a3 y^3`` of the filtered position y, in 1/m
        and 1/m^2.
    friction : float, default: 0.0
        Coulomb friction level on m2 in N, ``-F_c tanh(v2 / v_s)``.
    friction_velocity : float, default: 1e-6
        Smoothing velocity v_s of the friction law, in m/s.
    quadratic_damping : float, default: 0.0
        Force ``-c_q |v2| v2`` on m2, in N s^2/m^2.
    bouc_wen_stiffness, bouc_wen_beta, bouc_wen_gamma : float, default: 0.0
        Bouc-Wen hysteresis of the flexure: force ``-k_bw z`` on m2 with
        ``z' = v - beta |v| z - gamma v |z|`` (v = v2 - v3), in N/m, 1/m, 1/m.
    dac_step : float, default: 0.0
        DAC quantisation step of the command, in V (0: none).
    dac_dead_band : float, default: 0.0
        Dead band of the command, in V (0: none).
    adc_step : float, default: 0.0
        ADC quantisation step of the position reading, in m (0: none).
    """

    max_current: float = math.inf
    kf_b1: float = 0.0
    kf_b2: float = 0.0
    flexure_k2: float = 0.0
    flexure_k3: float = 0.0
    sensor_a2: float = 0.0
    sensor_a3: float = 0.0
    friction: float = 0.0
    friction_velocity: float = 1e-6
    quadratic_damping: float = 0.0
    bouc_wen_stiffness: float = 0.0
    bouc_wen_beta: float = 0.0
    bouc_wen_gamma: float = 0.0
    dac_step: float = 0.0
    dac_dead_band: float = 0.0
    adc_step: float = 0.0

    def __post_init__(self) -> None:
        for name in NL_FIELDS:
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int | float) or math.isnan(v):
                raise ConfigError(f"nonlinearity {name} must be a number, got {v!r}")
            object.__setattr__(self, name, float(v))
        for name in ("max_current", "friction_velocity"):
            if not getattr(self, name) > 0:
                raise ConfigError(f"{name} must be > 0, got {getattr(self, name)!r}")
        for name in ("friction", "dac_step", "dac_dead_band", "adc_step",
                     "quadratic_damping"):
            if getattr(self, name) < 0:
                raise ConfigError(f"{name} must be >= 0, got {getattr(self, name)!r}")

    @property
    def active(self) -> bool:
        """True when any term departs from the linear loop."""
        return self != NO_NONLINEARITY

    def vector(self, current_gain: float) -> np.ndarray:
        """Kernel parameter vector (order :data:`NL_FIELDS`).

        ``max_current`` is converted to a limit of the DAC command in V by the
        amplifier's DC gain ``current_gain`` (A/V); ``inf`` becomes 0 (off).
        """
        v = np.array([getattr(self, f) for f in NL_FIELDS], dtype=np.float64)
        finite = math.isfinite(self.max_current)
        v[0] = self.max_current / current_gain if finite else 0.0
        return v


NO_NONLINEARITY = Nonlinearity()
