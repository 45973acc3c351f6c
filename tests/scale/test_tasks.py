"""Many-task studies on dask: the same values, in item order, as in one process."""

from __future__ import annotations

import time

import numpy as np
import pytest

from servosurf.noise import design_study
from servosurf.scale import map_tasks
from servosurf.servo import load_machine

distributed = pytest.importorskip("distributed")


@pytest.fixture(scope="module")
def client():
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                  dashboard_address=":0") as cluster, \
            distributed.Client(cluster) as c:
        yield c


def _slow_square(x):
    # later items finish first, so completion order is the reverse of item order
    time.sleep(0.05 * (5 - x))
    return x * x


def _fails_on_three(x):
    if x == 3:
        raise ValueError("item 3 is bad")
    return x


def test_map_tasks_keeps_item_order(client):
    items = [0, 1, 2, 3, 4]
    assert map_tasks(_slow_square, items) == [0, 1, 4, 9, 16]
    assert map_tasks(_slow_square, items, client=client) == [0, 1, 4, 9, 16]
    seen = []

    def progress(it, total=None):
        assert total == len(items)
        for x in it:
            seen.append(x)
            yield x

    map_tasks(_slow_square, items, client=client, progress=progress)
    assert len(seen) == len(items)


def test_map_tasks_raises_a_task_error(client):
    with pytest.raises(ValueError, match="item 3"):
        map_tasks(_fails_on_three, range(5))
    with pytest.raises(ValueError, match="item 3"):
        map_tasks(_fails_on_three, range(5), client=client)


def test_design_study_on_workers_equals_one_process(client):
    machine = load_machine(None)
    masses, bws = [0.075, 0.175, 0.125], [300.0, 468.0, 900.0]
    local = design_study(machine, masses, bws)
    dask = design_study(machine, masses, bws, client=client)
    for name in ("rms_real", "rms_following", "optimal_bandwidth", "optimal_rms",
                 "stability_limit"):
        np.testing.assert_array_equal(getattr(dask, name), getattr(local, name))
    # the study itself: the heavier set-up has the lower optimum (seed paper 3.3)
    assert local.optimal_bandwidth[1] < local.optimal_bandwidth[0]
    assert np.all(np.isfinite(local.rms_real))


def test_realisations_on_workers_equal_one_process(client):
    import dataclasses

    import servosurf.toolpath as tp
    from servosurf.simulation import realisation_study

    spec = tp.load_toolpath("toolpaths/lenslet_5um.toml")
    fld = dataclasses.replace(spec.field, pitch_x=2e-6, pitch_y=2e-6, nx=80, ny=80)
    spec = dataclasses.replace(spec, field=fld)
    local = realisation_study(spec, seeds=[1, 2, 3], instrument=None)
    dask = realisation_study(spec, seeds=[1, 2, 3], instrument=None, client=client)
    assert dask.metrics.keys() == local.metrics.keys()
    for k in local.metrics:
        np.testing.assert_array_equal(dask.metrics[k], local.metrics[k])
