"""The flat face's Ra by model part (issue 18, item 6): the roughness budget.

:func:`flat_face_budget` simulates the seed paper's flat cut (2 um/rev, 250 rpm,
5 um depth, R 0.5 mm, electroless NiP) with the model parts switched on one after
the other and reports the flat-face Ra (:func:`~servosurf.report.flat_face_ra`, one
definition) after each step, beside the paper's measured 1.2 nm. Every row is a
:func:`~servosurf.simulation.simulate` run: the deviations of the parts outside the
sweep are computed once (one run with all of them) and replayed into the runs of
the single steps through simulate's ``path_z`` hook, which adds them to the tool
height exactly as simulate adds its own parts (the loop is linear and the parts
add), so each row equals ``simulate(parts=...)`` of that step.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from .._parts import LOOP_PARTS, MATERIAL_PARTS, OUTSIDE_PARTS
from ..errors import ConfigError
from ..run import preset
from ._simulation import FLAT_RA_DEFINITION, flat_face_ra

__all__ = ["flat_face_budget", "FlatFaceBudget", "FlatFaceModel", "BUDGET_STEPS",
           "PAPER_FLAT_RA"]

#: The seed paper's measured flat-face Ra (section 5.3, "no filter applied"), in m.
PAPER_FLAT_RA = 1.2e-9

#: Default steps of the budget: (label, parts switched on), each adding one part.
BUDGET_STEPS: tuple[tuple[str, tuple[str, ...]], ...] = (
    ("kinematic", ()),
    ("+ servo loop (tracking, force, vibration)", LOOP_PARTS),
    ("+ out-of-loop frame motion", LOOP_PARTS + ("out-of-loop",)),
    ("+ spindle axial error", LOOP_PARTS + OUTSIDE_PARTS),
    ("+ ploughing (h_min)", LOOP_PARTS + OUTSIDE_PARTS + ("ploughing",)),
    ("+ side flow", LOOP_PARTS + OUTSIDE_PARTS + ("ploughing", "side-flow")),
    ("+ elastic recovery", LOOP_PARTS + OUTSIDE_PARTS + MATERIAL_PARTS),
)


class _Replay:
    """simulate hook: adds recorded deviations (m) to the tool height."""

    def __init__(self, t: np.ndarray, dz: np.ndarray) -> None:
        self._t = t
        self._dz = dz

    def path_z(self, t, theta, r, z_cmd):  # noqa: ARG002 - hook signature
        if t.shape != self._t.shape or not np.array_equal(t, self._t):
            raise ConfigError(
                "internal: the replayed deviations do not cover this run's record")
        return self._dz


class FlatFaceModel:
    """The flat cut with its deviation parts computed once, for many sweeps.

    Parameters
    ----------
    toolpath : ToolpathSpec, str or Path
        The facing toolpath (the seed paper's: ``toolpaths/flat_facing.toml``).
    machine : Machine, str or Path, optional
        Machine (default: the seed prototype).
    workpiece : Workpiece, str or Path, optional
        Workpiece (default: electroless NiP).
    bandwidth : float, optional
        Crossover bandwidth in Hz (default: the ``paper-cutting`` preset's, 1448 Hz,
        the paper's cutting set-up, section 5.3).
    mass : float, optional
        Moving mass in kg (default: the ``paper-cutting`` preset's, 0.175 kg).
    seed : int, default: 0
        Seed of the vibration realisation and the spindle error.
    sensor_target : {"metrology-frame", "fts-base"} or None, default: None
        Overrides the machine's ``sensor.target`` (where the sensor's reference
        surface sits; "fts-base" lets frame motion bypass the loop).
    deviation_parts : sequence of str, optional
        Parts outside the sweep to compute (default: all of them).
    n_threads : int, optional
        Numba threads of the sweeps.
    """

    def __init__(self, toolpath, *, machine=None, workpiece=None,
                 bandwidth: float | None = None, mass: float | None = None,
                 seed: int = 0, sensor_target: str | None = None,
                 deviation_parts: Sequence[str] = LOOP_PARTS + OUTSIDE_PARTS,
                 n_threads: int | None = None) -> None:
        from ..cutting import Workpiece, load_workpiece
        from ..servo import Machine, load_machine
        from ..simulation import simulate
        from ..toolpath import ToolpathSpec, load_toolpath

        spec = toolpath if isinstance(toolpath, ToolpathSpec) else load_toolpath(
            toolpath)
        if spec.kind != "facing":
            raise ConfigError(
                f"the flat-face budget needs a facing toolpath, got kind {spec.kind!r}")
        bad = [p for p in deviation_parts if p not in LOOP_PARTS + OUTSIDE_PARTS]
        if bad:
            raise ConfigError(
                f"deviation_parts: {bad[0]!r} is not a deviation part; allowed: "
                f"{', '.join(LOOP_PARTS + OUTSIDE_PARTS)}")
        if not isinstance(machine, Machine):
            machine = load_machine(machine)
        if sensor_target is not None:
            if sensor_target not in ("metrology-frame", "fts-base"):
                raise ConfigError(
                    "sensor_target must be 'metrology-frame' or 'fts-base', got "
                    f"{sensor_target!r}")
            machine = dataclasses.replace(
                machine, sensor=dataclasses.replace(machine.sensor,
                                                    target=sensor_target))
        if not isinstance(workpiece, Workpiece):
            workpiece = load_workpiece(workpiece)
        self.spec = spec
        self.machine = machine
        self.workpiece = workpiece
        cut = preset("paper-cutting")
        bandwidth = cut.bandwidth if bandwidth is None else bandwidth
        mass = cut.mass if mass is None else mass
        self.kw = {"bandwidth": float(bandwidth), "mass": float(mass),
                   "seed": int(seed), "n_threads": n_threads}
        full = simulate(spec, machine=machine, workpiece=workpiece,
                        parts=tuple(deviation_parts), instrument=None, **self.kw)
        self.t = full.t
        self.deviation = {k: v for k, v in full.deviation.items()
                          if k in deviation_parts}
        self.parts = tuple(deviation_parts)

    def simulate(self, parts: Sequence[str], *, tool=None, workpiece=None):
        """simulate() of the flat cut with ``parts``, replaying the deviations.

        Parameters
        ----------
        parts : sequence of str
            Parts switched on (deviation parts must be among ``deviation_parts``).
        tool : Tool, optional
            Replaces the toolpath's tool (e.g. another ``edge_radius``).
        workpiece : Workpiece, optional
            Replaces the workpiece (e.g. other material ratios).

        Returns
        -------
        SimulationResult
            As from :func:`~servosurf.simulation.simulate` with ``parts``.
        """
        from ..simulation import PARTS, simulate

        bad = [p for p in parts if p not in PARTS]
        if bad:
            raise ConfigError(
                f"unknown deviation part {bad[0]!r}; allowed: {', '.join(PARTS)}")
        dev = [p for p in parts if p not in MATERIAL_PARTS]
        missing = [p for p in dev if p not in self.parts]
        if missing:
            raise ConfigError(
                f"part {missing[0]!r} was not computed (deviation_parts)")
        dz = np.zeros(self.t.size)
        for p in self.parts:  # the order simulate adds them in
            if p in dev:
                dz = dz + self.deviation[p]
        mat = tuple(p for p in parts if p in MATERIAL_PARTS)
        spec = self.spec if tool is None else dataclasses.replace(self.spec,
                                                                   tool=tool)
        return simulate(spec, machine=self.machine,
                        workpiece=self.workpiece if workpiece is None else workpiece,
                        parts=mat, instrument=None,
                        hooks=[_Replay(self.t, dz)] if dev else (), **self.kw)

    def ra(self, parts: Sequence[str], **kwargs) -> float:
        """Flat-face Ra (m, :func:`~servosurf.report.flat_face_ra`) with ``parts``;
        keywords as for :meth:`simulate`."""
        return flat_face_ra(self.simulate(parts, **kwargs).surface)


@dataclass(frozen=True, eq=False)
class FlatFaceBudget:
    """The flat face's Ra step by step (SI units).

    Attributes
    ----------
    rows : list of dict
        Per step: ``label``, ``parts``, ``ra_m`` (the flat-face Ra of the machined
        map), ``ra_instrument_m`` (the same on the interferometer model's map, or
        None), ``added_ra_m`` (the change from the previous row).
    paper_ra_m : float
        The paper's measured Ra, 1.2e-9 m.
    definition : str
        The Ra definition.
    settings : dict
        Set-up: bandwidth (Hz), mass (kg), seed, sensor target, tool edge radius
        (m), the material rules in m, the spindle PSD.
    """

    rows: list[dict[str, Any]]
    paper_ra_m: float = PAPER_FLAT_RA
    definition: str = FLAT_RA_DEFINITION
    settings: dict[str, Any] = field(default_factory=dict)

    def ra_by_part(self) -> dict[str, float]:
        """``{label: ra_m}`` in m."""
        return {r["label"]: r["ra_m"] for r in self.rows}

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dictionary."""
        return {"rows": self.rows, "paper_ra_m": self.paper_ra_m,
                "definition": self.definition, "settings": self.settings}

    def table(self) -> str:
        """Plain-text table in nm."""
        lines = [f"{'step':46s} {'Ra model':>9s} {'Ra instr.':>9s}  (nm; paper "
                 f"{self.paper_ra_m * 1e9:.2f} nm measured)"]
        for r in self.rows:
            inst = r["ra_instrument_m"]
            lines.append(f"{r['label']:46s} {r['ra_m'] * 1e9:9.3f} "
                         f"{'' if inst is None else f'{inst * 1e9:9.3f}'}")
        return "\n".join(lines)


def flat_face_budget(toolpath: str | Path, *, machine=None, workpiece=None,
                     bandwidth: float | None = None, mass: float | None = None,
                     seed: int = 0, sensor_target: str | None = "fts-base",
                     instrument: str | None = "cp300-20x",
                     steps: Sequence[tuple[str, Sequence[str]]] = BUDGET_STEPS,
                     n_threads: int | None = None) -> FlatFaceBudget:
    """The flat face's Ra by model part, one part added per step.

    Parameters
    ----------
    toolpath : ToolpathSpec, str or Path
        The facing toolpath (``toolpaths/flat_facing.toml``: the seed paper's flat
        cut).
    machine, workpiece : optional
        As for :func:`~servosurf.simulation.simulate`.
    bandwidth : float, optional
        Crossover bandwidth in Hz (default: the ``paper-cutting`` preset's: the
        paper cut at 1448 Hz with 0.175 kg).
    mass : float, optional
        Moving mass in kg (default: the ``paper-cutting`` preset's).
    seed : int, default: 0
        Seed of the vibration realisation, the spindle error and the instrument.
    sensor_target : str or None, default: "fts-base"
        Where the sensor's reference surface sits for the ``out-of-loop`` step
        (the paper does not say; None keeps the machine's). With
        "metrology-frame" the out-of-loop step adds nothing.
    instrument : str or None, default: "cp300-20x"
        Interferometer model for ``ra_instrument_m`` (None: not computed).
    steps : sequence of (str, sequence of str), default: BUDGET_STEPS
        (label, parts) per row.
    n_threads : int, optional
        Numba threads of the sweeps.

    Returns
    -------
    FlatFaceBudget
        Ra per step (m) with the settings.

    Raises
    ------
    ConfigError
        On a toolpath that is not a facing cut, or unknown parts.
    """
    from ..metrology import load_instrument, measure

    cut = preset("paper-cutting")
    bandwidth = cut.bandwidth if bandwidth is None else bandwidth
    mass = cut.mass if mass is None else mass
    dev_parts = tuple(p for p in LOOP_PARTS + OUTSIDE_PARTS
                      if any(p in parts for _, parts in steps))
    model = FlatFaceModel(toolpath, machine=machine, workpiece=workpiece,
                          bandwidth=bandwidth, mass=mass, seed=seed,
                          sensor_target=sensor_target, deviation_parts=dev_parts,
                          n_threads=n_threads)
    inst = load_instrument(instrument) if instrument is not None else None
    rows: list[dict[str, Any]] = []
    prev = None
    settings: dict[str, Any] = {}
    for label, parts in steps:
        res = model.simulate(tuple(parts))
        ra = flat_face_ra(res.surface)
        ra_i = (flat_face_ra(measure(res.surface, inst, seed=int(seed)))
                if inst is not None else None)
        rows.append({"label": label, "parts": list(parts), "ra_m": ra,
                     "ra_instrument_m": ra_i,
                     "added_ra_m": None if prev is None else ra - prev})
        prev = ra
        settings.update({k: v for k, v in res.settings.items()
                         if k in ("edge_radius_m", "material_rules")})
    from .._parts import part_settings

    settings.update(
        bandwidth_hz=float(bandwidth), moving_mass_kg=float(mass), seed=int(seed),
        toolpath=str(toolpath) if isinstance(toolpath, str | Path) else "spec",
        machine=model.machine.name, workpiece=model.workpiece.name,
        instrument=instrument,
        **part_settings(model.machine, model.spec.tool, model.workpiece,
                        dev_parts))
    return FlatFaceBudget(rows=rows, settings=settings)
