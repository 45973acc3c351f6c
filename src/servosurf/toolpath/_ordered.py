"""Machined surface with time-ordered material rules (minimum chip thickness, side
flow, elastic recovery): the checked public wrapper of the ordered kernel."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .._defaults import numba_threads
from .._validation import check_no_kwargs
from ..config import param
from ..errors import ConfigError
from ..metrology import Surface
from ._sample import SampledPath
from ._sweep import _initial_array, prepare_path
from ._tool import Field, Tool

__all__ = ["CuttingRules", "sweep_ordered"]


@dataclass(frozen=True)
class CuttingRules:
    """Material rules the time-ordered sweep applies at every pass (SI, m).

    A pass over a point whose current height is ``s`` and where the edge sits at
    ``z_e`` meets an uncut thickness ``h = s - z_e`` (along z). Zeros switch a rule
    off; all zeros give the kinematic envelope.

    Parameters
    ----------
    min_chip_thickness : float, default: 0.0
        h_min, in m: a pass removes material only where ``h > h_min``; below it the
        material is ploughed and stays (Brammertz, Industrie-Anzeiger 83 (1961):
        ``Rt = f^2/(8R) + (h_min/2)(1 + R h_min / f^2)``).
    side_flow_height : float, default: 0.0
        a, in m: height of the side-flow ridge at the boundary of a cut.
    side_flow_width : float, default: 0.0
        b, in m: lateral half-width over which the ridge falls linearly to zero,
        on the uncut side of the boundary.
    recovery_height : float, default: 0.0
        d0, in m: elastic recovery of a cut surface where the chip thickness tends
        to zero; the recovery is ``min(h, d0 exp(-h / h_d))``.
    recovery_decay : float, default: 0.0
        h_d, in m: chip thickness over which the recovery decays (> 0 when
        ``recovery_height > 0``).
    """

    min_chip_thickness: float = param(0.0, unit="m", low=0.0,
                                      doc="minimum chip thickness h_min")
    side_flow_height: float = param(0.0, unit="m", low=0.0,
                                    doc="side-flow ridge height a")
    side_flow_width: float = param(0.0, unit="m", low=0.0,
                                   doc="side-flow ridge half-width b")
    recovery_height: float = param(0.0, unit="m", low=0.0,
                                   doc="elastic recovery at zero chip thickness d0")
    recovery_decay: float = param(0.0, unit="m", low=0.0,
                                  doc="decay thickness h_d of the recovery")

    def __post_init__(self) -> None:
        for name in ("min_chip_thickness", "side_flow_height", "side_flow_width",
                     "recovery_height", "recovery_decay"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int | float) or not (
                    math.isfinite(v) and v >= 0):
                raise ConfigError(
                    f"CuttingRules.{name} must be a finite height >= 0 m, got {v!r}")
            object.__setattr__(self, name, float(v))
        if self.side_flow_height > 0 and self.side_flow_width <= 0:
            raise ConfigError(
                "CuttingRules.side_flow_width must be > 0 m with a side-flow height, "
                f"got {self.side_flow_width!r}")
        if self.recovery_height > 0 and self.recovery_decay <= 0:
            raise ConfigError(
                "CuttingRules.recovery_decay must be > 0 m with a recovery height, "
                f"got {self.recovery_decay!r}")

    @property
    def is_kinematic(self) -> bool:
        """True when every rule is off (the result is the envelope)."""
        return not (self.min_chip_thickness > 0 or self.side_flow_height > 0
                    or self.recovery_height > 0)

    def as_array(self) -> np.ndarray:
        """``[h_min, a, b, d0, h_d]`` in m (the kernel's ``rules`` argument)."""
        return np.array([self.min_chip_thickness, self.side_flow_height,
                         self.side_flow_width, self.recovery_height,
                         self.recovery_decay], dtype=np.float64)

    def to_dict(self) -> dict[str, float]:
        """JSON-ready values with unit suffixes (m)."""
        return {
            "min_chip_thickness_m": self.min_chip_thickness,
            "side_flow_height_m": self.side_flow_height,
            "side_flow_width_m": self.side_flow_width,
            "recovery_height_m": self.recovery_height,
            "recovery_decay_m": self.recovery_decay,
        }


def sweep_ordered(path: SampledPath, tool: Tool, field: Field, *,
                  rules: CuttingRules,
                  initial: float | np.ndarray | Surface | None = None,
                  n_threads: int | None = None,
                  rows: tuple[int, int] | None = None,
                  cols: tuple[int, int] | None = None,
                  check: bool = True,
                  **kwargs) -> Surface:
    """Machined height map with the passes applied in time order under ``rules``.

    Parameters
    ----------
    path : SampledPath
        Tool path (angle in rad, radius and height in m), whole or windowed.
    tool : Tool
        Round-nose tool: radius R (m), arc half-angle (rad), optional waviness.
    field : Field
        The grid (pitch in m, size, centre).
    rules : CuttingRules
        Minimum chip thickness, side flow and elastic recovery (m).
    initial : float, ndarray of shape (ny, nx), Surface or None, default: None
        Pre-cut height in m (None: a flat face at z = 0; ``np.inf``: no material
        limit; NaN pixels stay NaN). A point never cut before has slope 0 for the
        side-flow rule.
    n_threads : int, optional
        Numba threads for this call.
    rows, cols : tuple of int, optional
        Half-open row/column ranges of a tile (pixel coordinates of the whole field).
    check : bool, default: True
        Validate the path and warn on clearance violations.

    Returns
    -------
    Surface
        Heights in m (rows = y, columns = x), ``metadata["sweep"]`` with
        ``method = "ordered"`` and the rules.

    Raises
    ------
    ConfigError
        On a bad path, shapes or rules.
    TypeError
        On unknown keyword arguments.

    Notes
    -----
    Each point visits its crossings in time order (see
    :mod:`servosurf.kernels._ordered`); with ``rules`` all zero the result equals
    :func:`~servosurf.toolpath.sweep` bit for bit. The cost grows with the passes
    that reach below the current height at each point (about 70 at 2 um/rev and
    5 um depth of cut with R = 0.5 mm) instead of the few the pruned envelope
    evaluates.
    """
    from ..kernels._ordered import _sweep_ordered

    check_no_kwargs(kwargs, name="sweep_ordered")
    if not isinstance(rules, CuttingRules):
        raise ConfigError(f"rules must be CuttingRules, got {type(rules).__name__}")
    if not isinstance(tool, Tool):
        raise ConfigError(f"tool must be a Tool, got {type(tool).__name__}")
    if not isinstance(field, Field):
        raise ConfigError(f"field must be a Field, got {type(field).__name__}")
    if not isinstance(path, SampledPath):
        raise ConfigError(f"path must be a SampledPath, got {type(path).__name__}")
    rows = (0, field.ny) if rows is None else (int(rows[0]), int(rows[1]))
    cols = (0, field.nx) if cols is None else (int(cols[0]), int(cols[1]))
    if not (0 <= rows[0] < rows[1] <= field.ny and 0 <= cols[0] < cols[1] <= field.nx):
        raise ConfigError(
            f"rows {rows} and cols {cols} must be non-empty ranges inside the field of "
            f"shape {field.shape}"
        )
    shape = (rows[1] - rows[0], cols[1] - cols[0])
    out, fill = _initial_array(initial, shape, rows, cols, field)
    with numba_threads(n_threads):
        prep = prepare_path(path, tool, field, rows=rows, cols=cols, check=check,
                            stacklevel=3)
    meta = {
        "sweep": {
            "method": "ordered",
            "nose_radius": tool.nose_radius,
            "arc_half_angle": tool.arc_half_angle,
            "n_samples": int(path.n),
            "n_samples_used": 0 if prep is None else int(prep.path.n),
            "fs": path.fs,
            "rows": list(rows),
            "cols": list(cols),
            "rules": rules.to_dict(),
        }
    }
    x0 = field.x0 + cols[0] * field.pitch_x
    y0 = field.y0 + rows[0] * field.pitch_y
    if prep is None:
        if fill is not None:
            out.fill(fill)
        return Surface(out, field.pitch_x, field.pitch_y, meta, x0, y0)
    R = tool.nose_radius
    s0, ds, wav = tool.waviness_table()
    wav_bound = max(0.0, float(wav.max())) if wav.size else 0.0
    with numba_threads(n_threads):
        _sweep_ordered(prep.theta, prep.pts, prep.bidx, prep.bstat, prep.theta_ref, R,
                       tool.half_width, wav, s0, 1.0 / ds, wav_bound, 1e-12 * R,
                       tool.half_width - prep.rmin, field.x0, field.pitch_x, cols[0],
                       field.y0, field.pitch_y, rows[0], fill is not None,
                       0.0 if fill is None else float(fill), rules.as_array(), out)
    return Surface(out, field.pitch_x, field.pitch_y, meta, x0, y0)
