"""Machine-axis models of the tool's Z motion (instead of the seed paper's FTS loop).

Slow-tool-servo cuts run on the machine's own axes: the spindle is a C axis and the
Z slide follows the programmed Z. A machine file selects the model with an
``[axis]`` table:

* ``model = "fts"`` (default): the seed paper's fast-tool-servo loop
  (:class:`~servosurf.servo.ServoLoop`, Eqs 1 to 7) with its tracking, cutting-force
  and vibration parts;
* ``model = "second-order"``: the Z slide as a unity-gain second-order system
  ``H(s) = w_n^2 / (s^2 + 2 zeta w_n s + w_n^2)`` with ``w_n = 2 pi bandwidth``
  and damping ratio ``zeta``; only the tracking part exists (force and vibration
  are models of the FTS);
* ``model = "none"``: ideal axes, the tool follows the command exactly (a kinematic
  run).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

import numpy as np

from ..config import param
from ..errors import ConfigError

__all__ = ["AxisModel", "AXIS_MODELS"]

#: Axis models a machine file may select.
AXIS_MODELS = ("fts", "second-order", "none")
#: The axis response is computed at least this many samples per natural period.
MIN_SAMPLES_PER_PERIOD = 20


@dataclass(frozen=True)
class AxisModel:
    """How the tool's Z position follows the command.

    Parameters
    ----------
    model : {"fts", "second-order", "none"}, default: "fts"
        The seed paper's FTS loop, a second-order machine axis, or ideal axes.
    bandwidth : float, default: 100.0
        Natural frequency f_n of the second-order axis, in Hz (for ``damping``
        1/sqrt(2) also its -3 dB bandwidth).
    damping : float, default: 0.7
        Damping ratio zeta of the second-order axis (dimensionless).
    sample_rate : float, default: 20e3
        Rate at which the second-order response is computed, in Hz (at least
        20 f_n); the commanded path is sampled at this rate.
    """

    model: Literal["fts", "second-order", "none"] = param(
        "fts", doc="tool Z axis: the seed paper's FTS loop, a second-order machine "
        "axis or ideal axes", source="decision (issue 17)")
    bandwidth: float = param(100.0, unit="Hz", low=0.0, low_open=True,
                             doc="natural frequency of the second-order Z axis",
                             source="assumed")
    damping: float = param(0.7, unit="", low=0.0, low_open=True, high=10.0,
                           doc="damping ratio of the second-order Z axis",
                           source="assumed")
    sample_rate: float = param(20e3, unit="Hz", low=0.0, low_open=True,
                               doc="rate of the axis simulation")

    def __post_init__(self) -> None:
        if self.model == "second-order" and (
                self.sample_rate < MIN_SAMPLES_PER_PERIOD * self.bandwidth):
            raise ConfigError(
                f"axis.sample-rate must be >= {MIN_SAMPLES_PER_PERIOD} x "
                f"axis.bandwidth = {MIN_SAMPLES_PER_PERIOD * self.bandwidth:g} Hz, "
                f"got {self.sample_rate:g} Hz")

    def discrete(self) -> tuple[np.ndarray, np.ndarray]:
        """Exact discretisation of the second-order axis for piecewise-linear input.

        Returns
        -------
        b, a : ndarray
            Numerator and denominator of the discrete transfer function at
            :attr:`sample_rate` (first-order hold: exact when the command is linear
            between samples, as the machine's block interpolation is).
        """
        import scipy.signal as sps

        if self.model != "second-order":
            raise ConfigError(f"axis model {self.model!r} has no transfer function")
        wn = 2.0 * math.pi * self.bandwidth
        num = [wn * wn]
        den = [1.0, 2.0 * self.damping * wn, wn * wn]
        b, a, _ = sps.cont2discrete((num, den), 1.0 / self.sample_rate, method="foh")
        return np.ravel(b), np.ravel(a)

    def response(self, z_command: np.ndarray) -> np.ndarray:
        """Z position of the axis for a command sampled at :attr:`sample_rate`.

        Parameters
        ----------
        z_command : ndarray of shape (n,)
            Commanded Z, in m, linear between samples.

        Returns
        -------
        ndarray of shape (n,)
            Axis position, in m; at rest at ``z_command[0]`` before the first
            sample.
        """
        import scipy.signal as sps

        z = np.asarray(z_command, dtype=np.float64)
        if self.model == "none":
            return z.copy()
        if z.size == 0:
            return z.copy()
        b, a = self.discrete()
        zi = sps.lfilter_zi(b, a) * z[0]
        out, _ = sps.lfilter(b, a, z, zi=zi)
        return out
