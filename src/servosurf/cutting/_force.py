"""Workpiece material, pre-cut surface and the cutting-force (chip) model.

The thrust force on the tool is ``F = k_t A`` (N): the specific thrust pressure
``k_t`` (Pa) of the material times the uncut chip cross-section ``A`` (m^2) in the
radial-axial plane, i.e. the part of the tool's nose arc that lies below the current
surface. It pushes the tool away from the work (+z) and enters the servo loop at the
tool (m1) in the time domain, computed from the actual, deviated tool position (seed
paper section 3.2.2; force model after Zhu et al., ref. 22 of the paper).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

import numpy as np

from ..config import from_mapping, load_toml, param
from ..errors import ConfigError

__all__ = [
    "Material",
    "Precut",
    "Workpiece",
    "load_workpiece",
    "ChipModel",
    "segment_area",
    "facing_chip_area",
    "DEFAULT_WORKPIECE",
]

#: Built-in default workpiece file name (in the repository's workpieces/ folder and
#: mirrored in the defaults below).
DEFAULT_WORKPIECE = "nip"


@dataclass(frozen=True)
class Material:
    """Work material and its cutting-force coefficients."""

    name: str = param("Electroless plated NiP alloy", doc="material name")
    specific_thrust_pressure: float = param(
        1265621909.1639545,
        unit="Pa",
        low=0.0,
        doc="thrust force per uncut chip area, k_t",
        source="target:deviation_max (seed paper Fig. 17b, 295 nm peak deviation; "
        "servosurf.calibration.solve_thrust_pressure)",
    )
    specific_cutting_pressure: float = param(
        3.5e9,
        unit="Pa",
        low=0.0,
        doc="tangential force per uncut chip area",
        source="assumed; reported only",
    )
    source: str = param(
        "target:deviation_max (seed paper Fig. 17b, 295 nm peak deviation)",
        doc="where the coefficients come from",
    )


@dataclass(frozen=True)
class Precut:
    """The surface before this cut."""

    kind: Literal["flat", "file"] = param("flat", doc="flat face or a height map file")
    height: float = param(0.0, unit="m", doc="height of the flat pre-cut face")
    file: str = param("", doc="height map (any readable format) for kind = 'file'")


@dataclass(frozen=True)
class Workpiece:
    """Root of a workpiece file."""

    name: str = param("electroless-nip", doc="workpiece name")
    description: str = param("", doc="free text")
    material: Material = param(default_factory=Material)
    precut: Precut = param(default_factory=Precut)

    def __post_init__(self) -> None:
        if self.precut.kind == "file" and not self.precut.file:
            raise ConfigError(
                "precut.file must name a height map when precut.kind = 'file'"
            )


def load_workpiece(source: str | Path | None = None) -> Workpiece:
    """Load a workpiece TOML file (``None``: the electroless NiP defaults).

    Relative ``precut.file`` paths resolve against the TOML file's folder.
    """
    if source is None:
        return Workpiece()
    path = Path(source)
    data = load_toml(path)
    try:
        wp = from_mapping(Workpiece, data)
    except ConfigError as exc:
        raise ConfigError(f"{path}: {exc}") from None
    if wp.precut.file and not Path(wp.precut.file).is_absolute():
        pre = dataclasses.replace(
            wp.precut, file=str((path.parent / wp.precut.file).resolve())
        )
        wp = dataclasses.replace(wp, precut=pre)
    return wp


def segment_area(radius: float, depth: np.ndarray | float) -> np.ndarray:
    """Area in m^2 of a circle of ``radius`` (m) below a chord at ``depth`` (m).

    The uncut chip section of a round tool plunged ``depth`` into a flat face.
    """
    d = np.clip(np.asarray(depth, dtype=float), 0.0, radius)
    h = radius - d
    return radius**2 * np.arccos(h / radius) - h * np.sqrt(
        np.maximum(2 * radius * d - d * d, 0)
    )


def facing_chip_area(
    radius: float, feed: float, depth: float, *, n: int = 20001
) -> float:
    """Steady-state uncut chip section (m^2) in face turning.

    The region between the current tool arc (tip at ``-depth``) and the surface left
    by the previous revolution (the same arc one ``feed`` outward), below the pre-cut
    face at 0. Integrated numerically over the radial offset.
    """
    half = np.sqrt(max(2 * radius * depth - depth**2, 0.0))
    u = np.linspace(-half - feed, half + feed, n)

    def arc(v):
        return -depth + radius - np.sqrt(np.maximum(radius**2 - v**2, 0.0))

    prev = np.minimum(0.0, arc(u - feed))
    thick = np.maximum(prev - arc(u), 0.0)
    return float(np.trapezoid(thick, u))


@dataclass(frozen=True)
class ChipModel:
    """Thrust force from a round tool plunging into a flat face (lenslet cutting).

    Parameters
    ----------
    thrust_pressure : float
        Specific thrust pressure k_t in Pa.
    tool_radius : float
        Nose radius in m.
    top : float
        Height of the flat face in m.
    """

    thrust_pressure: float
    tool_radius: float
    top: float = 0.0

    def force(self, z_tool: np.ndarray) -> np.ndarray:
        """Thrust force in N for tool-tip heights ``z_tool`` (m)."""
        return self.thrust_pressure * segment_area(
            self.tool_radius, self.top - np.asarray(z_tool)
        )

    def kernel_args(self) -> tuple[int, np.ndarray]:
        """Arguments of the numba loop kernel (kind 1: plunge into a flat top)."""
        return 1, np.array([self.thrust_pressure, self.tool_radius, self.top, 0.0])
