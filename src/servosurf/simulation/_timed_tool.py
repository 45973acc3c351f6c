"""A tool that changes during the cut (``tool_at`` hooks, e.g. wear): the sweep in
time chunks.

The kinematic surface is the lower envelope of the tool arc over every sample of
the path, so it is the pointwise minimum of the envelopes of consecutive pieces of
the path. Each piece (one spindle revolution, or one of the path's time windows over
the field when shorter; at most :data:`MAX_CHUNKS` pieces) is swept with the tool
of its mid-time; pieces that meet without a gap share their boundary sample, so
every interpolated crossing belongs to one piece.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np

from ..errors import ConfigError

__all__ = ["has_timed_tool", "timed_tool_surface", "MAX_CHUNKS"]

#: Largest number of pieces (the tool is constant within a piece).
MAX_CHUNKS = 256


def has_timed_tool(hooks: Sequence[Any]) -> bool:
    """Whether any hook changes the tool in time (has ``tool_at(tool, t)``)."""
    return any(hasattr(h, "tool_at") for h in hooks)


def _tool_at(hooks, tool, t: float):
    for h in hooks:
        if hasattr(h, "tool_at"):
            tool = h.tool_at(tool, t)
    return tool


def timed_tool_surface(path, tool, field, initial, workpiece, parts, hooks, *,
                       angular_speed: float, n_threads=None):
    """The machined surface with the tool of each revolution.

    Parameters
    ----------
    path : SampledPath
        Tool path with every deviation added (m).
    tool : Tool
        The tool at t = 0 (after the ``tool`` hooks).
    field, initial, workpiece, parts
        As :func:`servosurf._parts.machine_surface`.
    hooks : sequence
        Model hooks; those with ``tool_at(tool, t)`` give the tool at time t (s).
    angular_speed : float
        Spindle angular speed in rad/s (one piece per revolution).
    n_threads : int, optional
        Numba threads.

    Returns
    -------
    Surface
        Heights in m.
    """
    from .._hooks import apply_hooks
    from .._parts import machine_surface
    from ..cutting import cutting_rules

    if not apply_hooks(hooks, "cutting_rules",
                       cutting_rules(workpiece.material, tool, parts)).is_kinematic:
        raise ConfigError(
            "a tool that changes in time (tool_at hook) is swept as an envelope; "
            "allowed only without the material parts (ploughing, side-flow, "
            "recovery) and without a minimum-chip-thickness term")
    if path.n < 2:
        return machine_surface(path, _tool_at(hooks, tool, 0.0), field, initial,
                               workpiece, parts, n_threads=n_threads)
    rev = np.floor(path.t * angular_speed / (2 * math.pi)).astype(np.int64)
    gap = path.gaps()[:-1]
    # a piece ends at a revolution boundary (sharing the sample) or at a gap
    cut = np.flatnonzero((np.diff(rev) != 0) | gap) + 1
    if cut.size + 1 > MAX_CHUNKS:
        cut = cut[np.linspace(0, cut.size - 1, MAX_CHUNKS - 1).astype(int)]
    starts = np.concatenate([[0], cut])
    stops = np.concatenate([cut + 1, [path.n]])
    # no shared sample across a gap (no crossing is interpolated there)
    stops[:-1] = np.where(gap[cut - 1], cut, cut + 1)
    out = None
    for a, b in zip(starts, stops, strict=True):
        if b - a < 2:
            continue
        piece = type(path)(path.t[a:b], path.theta[a:b], path.r[a:b], path.z[a:b],
                           path.fs)
        t_mid = 0.5 * (float(piece.t[0]) + float(piece.t[-1]))
        s = machine_surface(piece, _tool_at(hooks, tool, t_mid), field, initial,
                            workpiece, parts, n_threads=n_threads)
        out = s if out is None else out.replace(z=np.fmin(out.z, s.z))
    return out
