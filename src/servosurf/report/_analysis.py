"""Result objects of the analyses: the JSON summary, the figures' data, ``.plot()``.

:func:`servosurf.report.analyse` and :func:`servosurf.report.analyse_nc` return a
:class:`SimulationAnalysis`; :func:`servosurf.report.compare_surfaces` returns a
:class:`MapComparison`. Each holds its JSON-ready summary (``.to_dict()``, SI
units, the keys ``summary.json`` and ``compare.json`` carry) apart from the arrays
its figures draw (``plot_data``, not JSON), and ``.plot(folder)`` writes the
figures through :mod:`servosurf.viz`. Both read like their summary
(``analysis["ra_m"]``, a read-only mapping); the figures' arrays are not in it.
"""

from __future__ import annotations

import copy
import math
from collections.abc import Iterator, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

__all__ = ["SimulationAnalysis", "MapComparison"]


class _SummaryView(Mapping):
    """Read-only mapping access to ``summary`` (``analysis["ra_m"]``)."""

    summary: dict[str, Any]

    def __getitem__(self, key: str) -> Any:
        return self.summary[key]

    def __iter__(self) -> Iterator[str]:
        return iter(self.summary)

    def __len__(self) -> int:
        return len(self.summary)


@dataclass(frozen=True, eq=False)
class SimulationAnalysis(_SummaryView):
    """Metrology summary of a simulated map and the data its figures draw.

    Attributes
    ----------
    summary : dict
        JSON-ready values in SI units (see :func:`~servosurf.report.analyse`,
        :func:`~servosurf.report.analyse_nc`).
    result : SimulationResult
        The simulation analysed.
    plot_data : dict
        Arrays of the figures (high-passed map, spectrum and its peaks, profile and
        form error, ...), not JSON.
    constants : dict
        The analysis constants the figures name (``highpass_cutoff_m``,
        ``peak_fmin_per_m``).
    """

    summary: dict[str, Any]
    result: Any
    plot_data: dict[str, Any] = field(default_factory=dict)
    constants: dict[str, float] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        """The JSON-ready summary (a copy; SI units, keys carry their unit)."""
        return copy.deepcopy(self.summary)

    def plot(self, folder: str | Path, *, name: str = "",
             render: bool = True) -> dict[str, str]:
        """Write the figures of the analysis into ``folder``.

        Lenslet, facing and design maps: ``map.png``, ``highpass.png``
        (``form_error.png`` and ``toolpath.png`` for a design surface),
        ``spectrum.png``, ``profile.png`` (lenslets), ``deviation.png`` (when the
        run has a deviation record) and ``render.png`` (``render``). NC runs:
        ``toolpath.png``, ``map.png``, ``profile.png`` and ``roughness.png``.

        Parameters
        ----------
        folder : str or Path
            Destination folder (existing).
        name : str, optional
            Name of the run in the titles (e.g. the toolpath file's stem).
        render : bool, default: True
            Also write the 3-D render (slow: pyvista off-screen).

        Returns
        -------
        dict of str to str
            ``summary.json``'s ``files`` keys (``map_png``, ...) -> PNG paths, in
            the order written.
        """
        from .. import viz

        out = Path(folder)
        res = self.result
        if res.spec.kind == "nc":
            return viz.nc_figures(res, self.plot_data, out, name=name)
        surf = res.measured if res.measured is not None else res.surface
        speed = self.summary.get("surface_speed_m_per_s")
        if speed is None and hasattr(res.spec.path, "angular_speed"):
            f = res.spec.field
            speed = res.spec.path.angular_speed * math.hypot(f.center_x, f.center_y)
        return viz.simulation_figures(
            res, self.plot_data, out, name=name, render=render, speed=speed or None,
            cutoff=self.constants["highpass_cutoff_m"],
            peak_fmin=self.constants["peak_fmin_per_m"], surface=surf)


@dataclass(frozen=True, eq=False)
class MapComparison(_SummaryView):
    """A measured map against a simulated one: the summary and the figures' maps.

    Attributes
    ----------
    summary : dict
        JSON-ready values in SI units (see
        :func:`~servosurf.report.compare_surfaces`).
    plot_data : dict
        ``measured``, ``simulated`` (registered) and ``residual`` maps (m) and
        ``spectra`` ``(f_measured, psd_measured, f_simulated, psd_simulated)``
        (1/m, m^3), not JSON.
    """

    summary: dict[str, Any]
    plot_data: dict[str, Any] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        """The JSON-ready summary (a copy; SI units, keys carry their unit)."""
        return copy.deepcopy(self.summary)

    def plot(self, folder: str | Path, *, axis: str = "y") -> dict[str, str]:
        """Write ``residual.png``, ``spectra.png`` and ``profiles.png`` into ``folder``.

        Parameters
        ----------
        folder : str or Path
            Destination folder (existing).
        axis : {"y", "x"}, default: "y"
            Cutting direction of the profile figure (y: along columns).

        Returns
        -------
        dict of str to str
            ``residual``, ``spectra``, ``profiles`` -> PNG paths.
        """
        from .. import viz

        d = self.plot_data
        return viz.plot_map_comparison(
            d["measured"], d["simulated"], d["residual"], d["spectra"], Path(folder),
            rms_residual=self.summary["rms_residual_m"],
            matched_peaks=self.summary["peaks_matched_per_m"], axis=axis)
