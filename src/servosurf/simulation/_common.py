"""What both simulation paths share: the result, the constants, the field's span."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .. import _parts, _progress
from ..cutting import Workpiece
from ..errors import ConfigError
from ..metrology import Surface
from ..servo import Machine

__all__ = [
    "SimulationResult",
    "PARTS",
    "DEFAULT_PARTS",
    "KINEMATIC",
    "NC_MACHINE",
    "SETTLE_TIME",
    "MAX_SPAN_SAMPLES",
    "cutting_span",
    "deviation_samples",
]

#: Model parts that can be switched on and off: the servo loop's deviations, then
#: (issue 18) the terms outside the loop and the material rules of the sweep.
PARTS = _parts.ALL_PARTS
#: Parts of a default simulation on the FTS (the servo loop's deviations).
DEFAULT_PARTS = _parts.LOOP_PARTS
#: The commanded path alone (no loop, no axis dynamics); not combined with PARTS.
KINEMATIC = "kinematic"
#: Default machine of NC programs: ideal machine axes (a kinematic run).
NC_MACHINE = "sts-ideal-axes"
#: Pre-roll before the first sample that can cut the field, in s (loop settling).
SETTLE_TIME = 0.05
#: Refuse a continuous time span longer than this many samples (memory guard).
MAX_SPAN_SAMPLES = 40_000_000


@dataclass(frozen=True, eq=False)
class SimulationResult:
    """Everything a simulation produced (SI units).

    Attributes
    ----------
    surface : Surface
        The machined height map on the field grid (m), before any instrument model.
    measured : Surface or None
        The map as the interferometer model reports it (m, NaN invalid).
    t : ndarray of shape (n,)
        Times of the continuous deviation record, s.
    z_command : ndarray of shape (n,)
        Commanded tool height, m.
    deviation : dict of str to ndarray of shape (n,)
        Tool-height deviation per part (``tracking``, ``force``, ``vibration``,
        ``hooks``, and ``out-of-loop``/``spindle`` when switched on), m; their sum
        is added to the commanded path.
    force : ndarray of shape (n,)
        Thrust force on the tool, N.
    following_error : ndarray of shape (n,)
        Following error the controller reports (deterministic parts plus the
        vibration realisation's following error), m.
    machine : Machine
        The machine used (after mass, bandwidth and hooks).
    spec : object
        The toolpath specification.
    workpiece : Workpiece
        The workpiece.
    settings : dict
        JSON-ready settings (seed, parts, bandwidth, mass, files).
    """

    surface: Surface
    measured: Surface | None
    t: np.ndarray
    z_command: np.ndarray
    deviation: dict[str, np.ndarray]
    force: np.ndarray
    following_error: np.ndarray
    machine: Machine
    spec: Any
    workpiece: Workpiece
    settings: dict[str, Any] = field(default_factory=dict)

    @property
    def total_deviation(self) -> np.ndarray:
        """Sum of all deviation parts, m."""
        return sum(self.deviation.values())  # type: ignore[return-value]


def _reach(spec, tool) -> float:
    """Radial reach (m) of the tool arc below the pre-cut face (the whole arc for
    paths without a depth of cut, such as NC programs)."""
    from ..toolpath import field_reach

    # + 1 um margin for deviations (a design path's deepest point may be far
    # below its datum)
    return field_reach(tool, getattr(spec.path, "max_depth", None))


def cutting_span(spec, tool) -> tuple[float, float]:
    """Time interval ``(t0, t1)`` in s during which the ``tool`` can cut the field.

    Parameters
    ----------
    spec : ToolpathSpec
        The toolpath and its field.
    tool : Tool
        The tool (its reach below the pre-cut face widens the span).

    Returns
    -------
    tuple of float
        Start and end time, in s.

    Raises
    ------
    ConfigError
        When the path never reaches the field.
    """
    reach = _reach(spec, tool)
    rlo, rhi = spec.field.radial_range()
    span = spec.path.time_span_for_radius(max(rlo - reach, 0.0), rhi + reach)
    if span is None:
        raise ConfigError(
            f"the toolpath never reaches the field (field radii {rlo:g}..{rhi:g} m); "
            "move [field] center-x/center-y onto the path"
        )
    return span


def deviation_samples(spec, tool, fs: float, *, radii: tuple[float, float] | None = None
                      ) -> tuple[int, int]:
    """Controller samples of the deviation record :func:`simulate` runs the loop on.

    The loop starts at rest at sample ``k0`` (:data:`SETTLE_TIME` before the first
    moment the tool can cut the field, not before t = 0 except for an NC program,
    which holds its first point) and runs ``n`` samples, to two past the last.

    Parameters
    ----------
    spec : ToolpathSpec
        The toolpath and its field.
    tool : Tool
        The tool.
    fs : float
        Controller sample rate in Hz.
    radii : tuple of float, optional
        ``(rlo, rhi)`` in m: the radial range of the points to cover instead of
        the field's (a measured map or profile; for the field's own pixel
        centres the record is the same).

    Returns
    -------
    tuple of int
        ``(k0, n)``: first sample index (times ``k / fs`` in s) and sample count.
    """
    span = None
    if radii is not None:
        reach = _reach(spec, tool)
        span = spec.path.time_span_for_radius(max(radii[0] - reach, 0.0),
                                              radii[1] + reach)
    t0, t1 = cutting_span(spec, tool) if span is None else span
    k0 = int(np.floor((t0 - SETTLE_TIME) * fs))
    if spec.kind != "nc":  # an NC path holds its first point before t = 0
        k0 = max(k0, 0)
    k1 = int(np.ceil(t1 * fs)) + 2
    return k0, k1 - k0


def _kernel_field(spec):
    """The field in the sweep kernel's frame (mirrored for some NC paths)."""
    kf = getattr(spec.path, "kernel_field", None)
    return spec.field if kf is None else kf(spec.field)


def _initial(spec, workpiece):
    """Pre-cut height for the sweep: the workpiece's, or no material limit (+inf)
    for an NC program on a flat workpiece (a curved part's blank lies above the
    path; the surface is the lower envelope of every cutting block)."""
    if workpiece.precut.kind == "flat":
        if spec.kind == "nc":
            return np.inf
        return float(workpiece.precut.height)
    from ..io import read_surface

    return read_surface(workpiece.precut.file)


def _physical(spec, surface):
    """Undo the kernel frame (mirror) and mark never-cut pixels (+inf) as NaN."""
    unmirror = getattr(spec.path, "unmirror", None)
    if unmirror is None:
        return surface
    surface = unmirror(surface)
    z = surface.z
    if np.isinf(z).any():
        surface = surface.replace(z=np.where(np.isinf(z), np.nan, z))
    return surface




def _measure(surface: Surface, instrument, seed: int) -> Surface:
    """The map as the interferometer model ``instrument`` reports it (m)."""
    from ..metrology import load_instrument, measure

    with _progress.stage("interferometer model"):
        inst = (load_instrument(instrument) if isinstance(instrument, str | dict)
                else instrument)
        return measure(surface, inst, seed=int(seed))
