"""The positioning-error study of one machine (paper sections 3.3 and 5.2).

:func:`noise_study` computes, for each moving mass, the closed loop at one
bandwidth (margins, PIDF gains, FRFs, the error budget), the RMS errors against a
bandwidth grid (:func:`~servosurf.noise.design_study`) and the power share of each
disturbance source against bandwidth at the heaviest mass. The ``noise`` command
parses its flags, calls it and writes :meth:`NoiseStudy.to_dict` and
:meth:`NoiseStudy.plot`.
"""

from __future__ import annotations

import copy
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from .._progress import stage
from ..errors import ConfigError
from ._psd import frequency_grid
from ._study import DesignStudy, design_study
from ._synthesis import synthesize

__all__ = ["NoiseStudy", "noise_study"]

#: The three disturbance sources whose power shares are reported.
_SHARE_SOURCES = ("sensor_noise", "current_noise", "base_vibration")


@dataclass(frozen=True, eq=False)
class NoiseStudy:
    """The positioning-error study: its summary and the data of its figures.

    Attributes
    ----------
    summary : dict
        JSON-ready values (SI units): ``machine``, ``disturbances``,
        ``bandwidth_hz``, ``bandwidth_definition``, ``masses`` (per mass:
        stability, margins, PIDF gains, RMS errors in m, power shares, peaks in
        Hz), ``study`` and ``power_shares_vs_bandwidth``.
    study : DesignStudy
        RMS errors against bandwidth per mass.
    frfs : dict
        Label (``"0.175 kg"``) -> loop FRFs at the bandwidth (stable loops only).
    budgets : dict
        Label -> error budget at the bandwidth (stable loops only).
    grid : ndarray
        Bandwidth grid of the study, in Hz.
    shares : dict
        Source -> power share per grid bandwidth at the heaviest mass (NaN where
        the loop is unstable).
    """

    summary: dict[str, Any]
    study: DesignStudy
    frfs: dict[str, Any] = field(default_factory=dict)
    budgets: dict[str, Any] = field(default_factory=dict)
    grid: np.ndarray = field(default_factory=lambda: np.zeros(0))
    shares: dict[str, list] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        """The JSON-ready summary (a copy)."""
        return copy.deepcopy(self.summary)

    def plot(self, folder: str | Path) -> dict[str, str]:
        """Write the study's figures into ``folder``.

        ``loop_bode.png``, ``tool_frfs.png``, ``disturbance_frfs.png``,
        ``cas.png`` and ``error_spectra.png`` (when a loop is stable),
        ``rms_vs_bandwidth.png`` and ``power_shares.png``.

        Parameters
        ----------
        folder : str or Path
            Output folder (existing).

        Returns
        -------
        dict of str to str
            Figure name -> PNG path.
        """
        from .. import viz

        out = Path(folder)
        figs = {}
        if self.frfs:
            margins = {f"{e['mass_kg']:g} kg": e["margins"]
                       for e in self.summary["masses"]}
            figs["loop_bode"] = viz.plot_loop_bode(self.frfs, out / "loop_bode.png",
                                                   margins)
            figs["tool_frfs"] = viz.plot_tool_frfs(self.frfs, out / "tool_frfs.png")
            figs["disturbance_frfs"] = viz.plot_disturbance_frfs(
                self.frfs, out / "disturbance_frfs.png")
            figs["cas"] = viz.plot_cas(self.budgets, out / "cas.png")
            figs["error_spectra"] = viz.plot_error_spectra(
                self.budgets, out / "error_spectra.png")
        figs["rms_vs_bandwidth"] = viz.plot_rms_vs_bandwidth(
            self.study, out / "rms_vs_bandwidth.png")
        heavy = self.summary["power_shares_vs_bandwidth"]["mass_kg"]
        figs["power_shares"] = viz.plot_power_shares(
            self.grid, self.shares, out / "power_shares.png",
            title=f"Real-error power share per source, {heavy:g} kg (cf. Fig. 15)")
        return {k: str(v) for k, v in figs.items()}


def noise_study(machine, masses: Sequence[float], bandwidth: float | None = None,
                bandwidths: Sequence[float] | None = None, *, client=None,
                progress: Callable[..., Iterable] | None = None) -> NoiseStudy:
    """The positioning-error study of ``machine`` at each of ``masses``.

    Parameters
    ----------
    machine : Machine
        The machine (with its disturbance calibration).
    masses : sequence of float
        Moving masses m1 + m2, in kg; the last is the heavy one of the power-share
        curve.
    bandwidth : float, optional
        Crossover bandwidth in Hz of the FRFs, CAS and spectra (default: the
        machine's).
    bandwidths : sequence of float, optional
        Bandwidth grid in Hz of the RMS-against-bandwidth study (default 17
        log-spaced values 200..1800 Hz).
    client : distributed.Client, optional
        Run the design study's masses as dask tasks.
    progress : callable, optional
        Wraps the design study's finished masses (``progress(it, total=k)``).

    Returns
    -------
    NoiseStudy
        The summary, the design study and the figures' data.

    Raises
    ------
    ConfigError
        On a non-positive bandwidth.
    """
    from ..servo import ServoLoop

    masses = [float(m) for m in masses]
    bw = machine.controller.bandwidth if bandwidth is None else bandwidth
    if not (bw > 0 and np.isfinite(bw)):
        raise ConfigError(f"--bandwidth must be a positive frequency in Hz, got {bw!r}")
    grid = np.array(bandwidths if bandwidths else np.geomspace(200, 1800, 17))
    if np.any(~np.isfinite(grid)) or np.any(grid <= 0):
        raise ConfigError("--bandwidths must be positive frequencies in Hz")
    freq = frequency_grid(machine.controller.sample_rate)
    summary: dict[str, Any] = {
        "machine": machine.name,
        "disturbances": machine.disturbances.name,
        "bandwidth_hz": bw,
        "bandwidth_definition": "open-loop crossover",
        "masses": [],
    }
    frfs, budgets = {}, {}
    with stage(f"closed loops at {bw:g} Hz"):
        for m in masses:
            loop = ServoLoop(machine.with_moving_mass(m).with_bandwidth(bw))
            stable = loop.is_stable()
            label = f"{m:g} kg"
            entry = {
                "mass_kg": m,
                "stable": stable,
                "margins": loop.margins(),
                "pidf": {
                    "kp": loop.pidf.kp,
                    "ki_per_s": loop.pidf.ki,
                    "kd_s": loop.pidf.kd,
                    "tf_s": loop.pidf.tf,
                },
            }
            if stable:
                frfs[label] = loop.frf(freq)
                b = synthesize(loop, freq=freq)
                budgets[label] = b
                entry.update(
                    rms_real_m=b.rms_real(),
                    rms_following_m=b.rms_following(),
                    power_shares=b.power_shares(),
                    real_peaks_hz=b.peaks(),
                )
            summary["masses"].append(entry)
    with stage("RMS against bandwidth (design study)"):
        study = design_study(machine, masses, grid, progress=progress, client=client)
    summary["study"] = study.to_dict()
    shares: dict[str, list] = {k: [] for k in _SHARE_SOURCES}
    with stage("power shares against bandwidth"):
        heavy = machine.with_moving_mass(masses[-1])
        for b in grid:
            try:
                loop = ServoLoop(heavy.with_bandwidth(float(b)))
                ok = loop.is_stable()
            except Exception:
                ok = False
            sh = synthesize(loop, freq=freq).power_shares() if ok else None
            for k in shares:
                shares[k].append(sh[k] if sh else float("nan"))
    summary["power_shares_vs_bandwidth"] = {
        "mass_kg": masses[-1],
        "bandwidths_hz": grid,
        **shares,
    }
    return NoiseStudy(summary=summary, study=study, frfs=frfs, budgets=budgets,
                      grid=grid, shares=shares)
