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
    "builtin_workpieces",
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
        1265756479.329656,
        unit="Pa",
        low=0.0,
        plausible=(1e7, 1e11),
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
    # -- material parts of the forward model (switched on by simulate's parts
    # "ploughing", "side-flow" and "recovery"); heights scale with the tool's
    # cutting-edge radius r_n (tool.edge-radius)
    min_chip_thickness_ratio: float = param(
        0.25,
        unit="",
        low=0.0,
        high=1.0,
        doc="h_min / r_n: minimum chip thickness over the cutting-edge radius",
        source="ductile metals cut with diamond: 0.2-0.4 (Yuan, Zhou, Dong, J. Mater. "
        "Process. Technol. 62 (1996) 327; Son, Lim, Ahn, Int. J. Mach. Tools Manuf. "
        "45 (2005) 529); not measured for NiP",
    )
    side_flow_height_ratio: float = param(
        0.05,
        unit="",
        low=0.0,
        high=1.0,
        doc="a / r_n: side-flow ridge height at the cut boundary over r_n",
        source="assumed; side flow at the feed-mark ridges: Liu & Melkote, Int. J. "
        "Mach. Tools Manuf. 46 (2006) 1778; Zong et al., ibid. 84 (2014) 58",
    )
    side_flow_width_ratio: float = param(
        10.0,
        unit="",
        low=0.0,
        high=1000.0,
        doc="b / r_n: lateral half-width of the side-flow ridge over r_n",
        source="assumed (ridge about ten edge radii wide)",
    )
    recovery_ratio: float = param(
        0.1,
        unit="",
        low=0.0,
        high=1.0,
        doc="d0 / r_n: elastic recovery of a cut surface at vanishing chip thickness",
        source="assumed, of the order of a few H/E of the edge radius: electroless "
        "NiP H 5-7 GPa, E 100-200 GPa (Weil & Parker, in Mallory & Hajdu, "
        "Electroless Plating, AESF 1990, ch. 4); swelling and recovery in diamond "
        "turning: Kong, Lee, Cheung, To, J. Mater. Process. Technol. 180 (2006) 210",
    )
    recovery_decay_ratio: float = param(
        1.0,
        unit="",
        low=0.0,
        low_open=True,
        high=100.0,
        doc="h_d / r_n: chip thickness over which the recovery decays, over r_n",
        source="assumed (the edge radius sets where ploughing gives way to cutting)",
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


def builtin_workpieces() -> dict[str, Path]:
    """Return ``{name: path}`` of the workpiece files shipped with servosurf."""
    from .._builtins import builtin_files

    return builtin_files("workpiece")


def load_workpiece(source: str | Path | None = None) -> Workpiece:
    """Load a workpiece TOML file or built-in (``None``: the electroless NiP defaults).

    ``source`` is a path or the name of a built-in workpiece (see
    :func:`builtin_workpieces`, e.g. ``"nip"``). Relative ``precut.file`` paths
    resolve against the TOML file's folder.
    """
    from .._builtins import resolve_file

    if source is None:
        return Workpiece()
    path = resolve_file(source, kind="workpiece")
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
