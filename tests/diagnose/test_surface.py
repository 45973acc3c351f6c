"""The diagnosis's surface model is simulate's: on the same inputs (toolpath,
machine, no vibration, no instrument) the diagnosis's nominal heights at the
pixel centres equal the map :func:`servosurf.simulation.simulate` sweeps, for the
design surfaces and an NC program (spiral passes, non-periodic deviation record).

The oracle is simulate itself (its controller-rate samples through the numba
swept-arc kernel); the diagnosis evaluates the lowest pass at each point from the
path's own functions, a second implementation of the same envelope.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from servosurf.diagnose._blocks import Context
from servosurf.diagnose._sim import CaseModel
from servosurf.diagnose._surface import PointSet, surface_heights
from servosurf.diagnose.effects import Model
from servosurf.simulation import simulate
from servosurf.toolpath import builtin_toolpaths, load_toolpath

from .test_null_contract import write_nc_spiral

#: Agreement of the two envelopes, m (the NC program's piecewise-linear radius
#: against its controller-rate samples differs by ~1e-13 m).
ATOL = 1e-12  # 1 pm


def _spec(name, tmp_path):
    if name == "nc":
        return load_toolpath(write_nc_spiral(tmp_path))
    spec = load_toolpath(builtin_toolpaths()[name])
    return dataclasses.replace(
        spec, field=dataclasses.replace(spec.field, nx=40, ny=24)
    )


@pytest.mark.parametrize("name", ["sphere", "lenslet_array_hex", "nc"])
def test_nominal_map_is_simulates_map(name, tmp_path):
    spec = _spec(name, tmp_path)
    parts = ("tracking",) if spec.kind == "nc" else ("tracking", "force")
    res = simulate(
        spec, parts=parts, instrument="none", seed=0, machine="seed-prototype"
    )
    s = res.surface
    case = CaseModel(res.machine, spec)
    ctx = Context(case)
    ny, nx = s.z.shape
    xx, yy = np.meshgrid(s.x0 + s.dx * np.arange(nx), s.y0 + s.dy * np.arange(ny))
    x, y = xx.ravel(), yy.ravel()
    ctx.cover(np.hypot(x, y))
    h = surface_heights(case, PointSet(case, x, y), Model(), ctx.trajectory(Model()))
    z = s.z.ravel()
    assert np.isfinite(z).all() and np.isfinite(h).all()
    assert np.ptp(z) > 50e-9  # a real surface (scallops, lenslets), not a plane
    np.testing.assert_allclose(h, z, rtol=0, atol=ATOL)
