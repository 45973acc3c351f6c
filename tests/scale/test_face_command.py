"""servosurf face: whole face with PSD-shaped vibration, in process and on dask."""

from __future__ import annotations

import json

import numpy as np
import pytest

from servosurf.cli import main


def _run(tmp_path, name, extra, capsys):
    out = tmp_path / name
    rc = main(["face", "toolpaths/flat_facing.toml", "--radius", "0.15e-3", "--pitch",
               "2e-6", "--chunk", "64", "--seed", "4", "--out", str(out), "--json",
               *extra])
    assert rc == 0
    summary = json.loads(capsys.readouterr().out)
    import zarr

    return summary, np.asarray(zarr.open_array(str(out / "face.zarr"), mode="r")[:])


def test_face_in_process_and_on_local_cluster_identical(tmp_path, capsys):
    pytest.importorskip("distributed")
    s1, a = _run(tmp_path, "local", [], capsys)
    s2, b = _run(tmp_path, "dask", ["--scheduler", "local", "--workers", "2"], capsys)
    assert s1["tasks"] == s2["tasks"] > 1
    np.testing.assert_array_equal(a, b)
    v = a[np.isfinite(a)]
    # kinematic feed marks (Rt 1 nm) plus sub-nm vibration: a few tenths of a nm RMS
    assert 0.1e-9 < v.std() < 2e-9
    assert (tmp_path / "local" / "face.png").stat().st_size > 0


def test_face_rejects_lenslet_and_bad_radius(tmp_path, capsys):
    assert main(["face", "toolpaths/lenslet_5um.toml", "--radius", "1e-3",
                 "--out", str(tmp_path / "x")]) == 1
    assert main(["face", "toolpaths/flat_facing.toml", "--radius", "-1",
                 "--out", str(tmp_path / "y")]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 2 and "facing toolpath" in err[0] and "--radius" in err[1]
