"""Forward-model parts beyond the servo loop (issue 18, item 6), plugged into
:func:`servosurf.simulation.simulate` through two calls.

Outside the loop, added to the tool height like the loop's deviations:

* ``out-of-loop``: frame-to-spindle motion that bypasses the loop when the sensor's
  reference surface sits on the FTS base (``[sensor] target = "fts-base"``): the
  base displacement of the vibration realisation (same seed, same draw) through the
  sensor-noise path (:func:`servosurf.noise.realise`, ``out_of_loop=True``). Zero
  when the target is on the metrology frame (the default), where the loop sees it.
* ``spindle``: the spindle's asynchronous axial error motion from its PSD
  (``[spindle] axial-error``, :func:`servosurf.noise.realise_spindle_axial`).

In the sweep (:func:`servosurf.toolpath.sweep_ordered`, passes in time order), with
heights scaled by the tool's cutting-edge radius ``[tool] edge-radius``:

* ``ploughing``: minimum chip thickness ``h_min = min-chip-thickness-ratio * r_n``;
* ``side-flow``: a ridge at the boundary of every cut;
* ``recovery``: elastic recovery that grows as the local chip thickness vanishes.

With none of them on, the surface is the envelope of :func:`servosurf.toolpath.sweep`
(the default parts' results are unchanged).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

# Light on purpose (no numpy at import): the CLI reads the part names at start-up.
__all__ = ["LOOP_PARTS", "OUTSIDE_PARTS", "MATERIAL_PARTS", "ALL_PARTS",
           "outside_loop", "machine_surface", "part_settings"]

#: Parts computed through the servo loop (the model before issue 18).
LOOP_PARTS = ("tracking", "force", "vibration")
#: Parts added to the tool height outside the loop.
OUTSIDE_PARTS = ("out-of-loop", "spindle")
#: Parts that act in the sweep (:data:`servosurf.cutting.MATERIAL_PARTS`).
MATERIAL_PARTS = ("ploughing", "side-flow", "recovery")
#: Every part, in the order of :data:`servosurf.simulation.PARTS`.
ALL_PARTS = LOOP_PARTS + OUTSIDE_PARTS + MATERIAL_PARTS


def outside_loop(loop, parts: Sequence[str], n: int,
                 seed: int) -> dict:
    """Tool-height terms of the parts outside the loop that are switched on.

    Parameters
    ----------
    loop : ServoLoop
        The closed loop (its machine gives the sensor target and the spindle).
    parts : sequence of str
        Parts switched on.
    n : int
        Samples of the deviation record (from the record's first sample).
    seed : int
        Seed of the vibration realisation (and of the spindle's own stream).

    Returns
    -------
    dict of str to ndarray of shape (n,)
        ``"out-of-loop"`` and ``"spindle"`` when switched on, in m (tool height
        relative to the workpiece, up = away from the material).
    """
    import numpy as np

    out: dict = {}
    machine = loop.machine
    if "out-of-loop" in parts:
        if machine.sensor.target == "fts-base":
            from .noise import realise

            real = realise(loop, int(n), seed=int(seed), out_of_loop=True)
            out["out-of-loop"] = real.out_of_loop
        else:  # the sensor sees frame motion: nothing bypasses the loop
            out["out-of-loop"] = np.zeros(n)
    if "spindle" in parts:
        from .noise import realise_spindle_axial

        # the face moving toward the tool lowers the tool relative to the face
        out["spindle"] = -realise_spindle_axial(
            machine.spindle, int(n), loop.fs, seed=int(seed))
    return out


def machine_surface(path, tool, field, initial, workpiece, parts: Sequence[str], *,
                    hooks: Sequence = (), n_threads: int | None = None):
    """The machined map: the envelope, or the ordered sweep with material parts.

    Parameters
    ----------
    path : SampledPath
        Tool path with every deviation added (m).
    tool : Tool
        The tool (its ``edge_radius`` scales the material rules).
    field : Field
        The grid.
    initial : float or ndarray
        Pre-cut height(s), in m.
    workpiece : Workpiece
        Its material holds the rule ratios.
    parts : sequence of str
        Parts switched on.
    hooks : sequence, optional
        Model hooks; their ``cutting_rules`` methods change the rules of the parts
        (a catalogue effect's minimum chip thickness, for example).
    n_threads : int, optional
        Numba threads.

    Returns
    -------
    Surface
        Heights in m.
    """
    from ._hooks import apply_hooks
    from .cutting import cutting_rules
    from .toolpath import sweep, sweep_ordered

    rules = apply_hooks(hooks, "cutting_rules",
                        cutting_rules(workpiece.material, tool, parts))
    if rules.is_kinematic:
        return sweep(path, tool, field, initial=initial, n_threads=n_threads)
    return sweep_ordered(path, tool, field, rules=rules, initial=initial,
                         n_threads=n_threads)


def part_settings(machine, tool, workpiece, parts: Sequence[str]) -> dict[str, Any]:
    """JSON-ready settings of the parts beyond the loop that are switched on (SI)."""
    out: dict[str, Any] = {}
    if "out-of-loop" in parts:
        out["sensor_target"] = machine.sensor.target
    if "spindle" in parts:
        ax = machine.spindle.axial_error
        out["spindle_axial_error"] = {
            "floor_m_per_sqrt_hz": ax.floor, "level_m_per_sqrt_hz": ax.level,
            "ref_frequency_hz": ax.ref_frequency, "slope": ax.slope,
            "corner_hz": ax.corner, "order": ax.order, "csv": ax.csv,
            "fmin_hz": machine.spindle.fmin,
        }
    if any(p in parts for p in MATERIAL_PARTS):
        from .cutting import cutting_rules

        out["edge_radius_m"] = tool.edge_radius
        out["material_rules"] = cutting_rules(workpiece.material, tool,
                                              parts).to_dict()
    return out
