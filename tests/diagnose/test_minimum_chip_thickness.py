"""Minimum chip thickness (ploughing) in the diagnosis's pointwise surface model.

Oracles, none of them the code under test:

* Brammertz's closed form of a facing cut's peak-to-valley with ploughing,
  ``Rt = f^2/8R + (h_min/2)(1 + R h_min / f^2)`` (valid for ``h_min < f^2/2R``),
  at points placed either side of the analytic ploughing boundary;
* the simulator's time-ordered numba sweep (``simulate(hooks=[term])``, the
  kernel of :mod:`servosurf.kernels._ordered`), which visits crossings of a grid
  point in time order, against the diagnosis's rule over each point's nearest
  passes (plain numpy).
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from servosurf.diagnose import CaseModel, Model
from servosurf.diagnose import effects as E
from servosurf.diagnose._blocks import Context
from servosurf.diagnose._surface import PointSet, ordered_heights, surface_heights
from servosurf.servo import load_machine
from servosurf.toolpath import load_toolpath

REPO = Path(__file__).resolve().parents[2]
FACING = REPO / "toolpaths" / "flat_facing.toml"


@pytest.fixture(scope="module")
def facing():
    spec = load_toolpath(FACING)
    case = CaseModel(load_machine(), spec)
    return spec, case, Context(case)


def _heights(case, ctx, x, h_min):
    m = Model() if h_min == 0.0 else Model.of(E.MinimumChipThicknessParams(h_min))
    pts = PointSet(case, x, np.zeros_like(x))
    return surface_heights(case, pts, m, ctx.trajectory(m))


@pytest.mark.parametrize("h_min", [1e-9, 2e-9, 3e-9])
def test_facing_ridge_meets_brammertz(facing, h_min):
    spec, case, ctx = facing
    f = spec.path.feed_per_rev
    R = spec.tool.nose_radius
    assert h_min < f * f / (2 * R)  # the closed form's range
    # the pass of a point x0 (tip radius x0), the next pass at x0 - f (the tool
    # moves inward); the next pass cuts where it meets more than h_min, i.e.
    # beyond u_b = f/2 + R h_min / f inward of x0
    # x0: the tip radius of the pass nearest to 5.0137 mm (a valley bottom)
    guess = np.array([5.0137e-3])
    dr = PointSet(case, guess, np.zeros(1)).dr[0]
    x0 = float(guess[0] - dr[np.argmin(np.abs(dr))])
    u_b = f / 2 + R * h_min / f
    eps = 1e-10  # m: 0.1 nm either side of the boundary
    x = np.array([x0, x0 - u_b + eps, x0 - u_b - eps, x0 - f])
    z = _heights(case, ctx, x, h_min)
    valley = 0.5 * (z[0] + z[3])
    brammertz = f * f / (8 * R) + 0.5 * h_min * (1 + R * h_min / f**2)
    assert z[1] - valley == pytest.approx(brammertz, rel=2e-3)
    # on the cut side of the boundary the next pass's arc: h_min lower
    assert z[1] - z[2] == pytest.approx(h_min, rel=2e-3)
    # without ploughing the cusp is the kinematic f^2 / 8R
    zk = _heights(case, ctx, np.array([x0, x0 - f / 2, x0 - f]), 0.0)
    assert zk[1] - 0.5 * (zk[0] + zk[2]) == pytest.approx(f * f / (8 * R), rel=2e-3)


def test_ordered_rule_is_the_envelope_at_zero_and_keeps_thin_slivers():
    rng = np.random.default_rng(3)
    h = rng.uniform(-5e-9, 5e-9, (200, 5))
    h[rng.random(h.shape) < 0.2] = np.inf  # passes that do not reach
    t = rng.permutation(np.arange(1000.0)).reshape(200, 5)
    z, k = ordered_heights(h, t, 0.0, 0.0)
    env = np.minimum(np.min(h, axis=1), 0.0)
    np.testing.assert_array_equal(z, env)
    assert np.all((k >= 0) == (np.min(h, axis=1) < 0.0))
    # with h_min every cut met more than h_min: the height only steps down by
    # more than h_min, so no point ends above the envelope by h_min or more of
    # a pass that came after its last cut
    zh, kh = ordered_heights(h, t, 0.0, 2e-9)
    assert np.all(zh >= env) and np.any(zh > env)
    for i in range(h.shape[0]):
        tl = t[i, kh[i]] if kh[i] >= 0 else -np.inf
        later = (t[i] > tl) & np.isfinite(h[i])
        assert np.all(zh[i] - h[i, later] <= 2e-9)


@pytest.mark.slow
def test_simulate_with_the_term_is_the_diagnosis_surface(facing):
    """The simulator's ordered numba sweep and the diagnosis's pointwise rule give
    the same change of a facing field (the loop parts cancel in the difference)."""
    from servosurf.simulation import simulate

    spec, case, ctx = facing
    spec = dataclasses.replace(spec, field=dataclasses.replace(
        spec.field, nx=120, ny=4, pitch_x=0.05e-6, pitch_y=0.5e-6))
    q = E.MinimumChipThicknessParams(2e-9)
    nom = simulate(spec, machine=case.machine, parts=("tracking", "force"))
    res = simulate(spec, machine=case.machine, parts=("tracking", "force"), hooks=[q])
    x, y = spec.field.coords()
    xx, yy = np.meshgrid(x, y)
    pts = PointSet(case, xx.ravel(), yy.ravel())
    m = Model.of(q)
    d_diag = (surface_heights(case, pts, m, ctx.trajectory(m))
              - surface_heights(case, pts, Model(), ctx.trajectory(Model())))
    d_sim = (res.surface.z - nom.surface.z).ravel()
    scale = float(np.sqrt(np.mean(d_diag**2)))
    assert scale > 3e-10  # the term raises the ridges (h_min 2 nm)
    np.testing.assert_allclose(d_sim, d_diag, rtol=0, atol=1e-13)
    # the simulated cusp is Brammertz's, not the kinematic one
    f, R = spec.path.feed_per_rev, spec.tool.nose_radius
    rt = float(np.ptp(res.surface.z[1]))
    kin = f * f / (8 * R)
    assert rt > kin + 0.5 * 2e-9


@pytest.mark.slow
def test_ploughing_simulated_on_an_nc_spiral_is_named(tmp_path, capsys):
    """``simulate --parts ... ploughing`` (the ordered kernel over the whole cut
    from its start, with the tool noise) -> diagnose names the minimum chip
    thickness it was simulated with, out of sample, within 10 %.

    The NC spiral of the null contract (10 um/rev, R 0.5 mm: f^2/2R = 100 nm)
    with a cutting-edge radius of 80 nm: h_min = 0.25 x 80 nm = 20 nm (the work
    material's ratio); without ploughing the same case is "consistent"
    (tests/diagnose/test_null_contract.py)."""
    import json

    from servosurf.cli import main
    from servosurf.cutting import Material

    from .test_null_contract import write_nc_spiral

    tp = write_nc_spiral(tmp_path)
    tp.write_text(tp.read_text().replace(
        "nose-radius = 0.5e-3  # m\n", "nose-radius = 0.5e-3  # m\nedge-radius = 80e-9  # m\n"))
    truth = Material().min_chip_thickness_ratio * 80e-9
    sim = tmp_path / "sim"
    assert main(["-q", "simulate", str(tp), "--machine", "seed-prototype",
                 "--instrument", "none", "--seed", "4", "--no-render", "--parts",
                 "tracking", "vibration", "ploughing", "--out", str(sim)]) == 0
    capsys.readouterr()
    assert main(["-q", "diagnose", str(sim / "manifest.toml"), "--out",
                 str(tmp_path / "d"), "--json"]) == 0
    verdict = json.loads(capsys.readouterr().out)
    ex = sorted(verdict["explanations"], key=lambda e: -e["delta_bic"])
    assert verdict["verdict"] in ("explained", "partly-explained"), verdict["verdict"]
    assert ex and ex[0]["effect"] == "minimum-chip-thickness", [e["effect"] for e in ex]
    h = ex[0]["parameters"]["h_min_m"]
    assert abs(h - truth) <= 0.10 * truth, (h, truth)
    assert ex[0]["held_out_improvement"]["passed"]
