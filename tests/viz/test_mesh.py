"""Height map -> triangle mesh, and STL/PLY round trips through trimesh."""

from __future__ import annotations

import numpy as np
import pytest

from servosurf.errors import ConfigError, UnsupportedFileFormatError
from servosurf.metrology import Surface
from servosurf.viz._mesh import surface_to_mesh, write_mesh

trimesh = pytest.importorskip("trimesh")

DX, DY = 0.5e-6, 0.8e-6  # pixel sizes, m
X0, Y0 = 10e-6, -3e-6  # centre of pixel (0, 0), m


def _small(nan: tuple[int, int] | None = None) -> Surface:
    rng = np.random.default_rng(11)  # heights only; counts do not depend on them
    z = rng.normal(0.0, 5e-9, (4, 5))
    if nan is not None:
        z[nan] = np.nan
    return Surface(z, DX, DY, x0=X0, y0=Y0)


def test_vertex_count_faces_and_bounds_of_a_small_map():
    s = _small()
    m = surface_to_mesh(s)
    assert m.vertices.shape == (20, 3)
    assert m.faces.shape == (2 * 3 * 4, 3)  # two triangles per quad
    z = s.z
    np.testing.assert_allclose(
        m.bounds,
        [[X0, Y0, z.min()], [X0 + 4 * DX, Y0 + 3 * DY, z.max()]],
        rtol=0,
        atol=1e-15,  # 1 fm
    )
    # every face points up, and the mesh covers the 4 x 3 pixel-pitch area
    assert np.all(m.face_normals[:, 2] > 0.99)
    # projected area (areas weighted by the normals' z cosine) is exact
    projected = np.sum(m.area_faces * m.face_normals[:, 2])
    np.testing.assert_allclose(projected, 4 * DX * 3 * DY, rtol=1e-12)


def test_nan_quads_are_skipped():
    m = surface_to_mesh(_small(nan=(1, 2)))  # an inner pixel: 4 quads lose a corner
    assert m.faces.shape == (2 * (12 - 4), 3)
    # the NaN pixel is not a vertex, nor is (0, 2): both its quads touch (1, 2)
    assert m.vertices.shape == (18, 3)
    assert np.isfinite(m.vertices).all()
    corner = surface_to_mesh(_small(nan=(0, 0)))  # one quad lost, vertex dropped
    assert corner.faces.shape == (22, 3) and corner.vertices.shape == (19, 3)


def test_exaggeration_and_decimation():
    s = _small()
    m = surface_to_mesh(s, z_exaggeration=100.0)
    base = surface_to_mesh(s)
    np.testing.assert_allclose(m.vertices[:, 2], 100 * base.vertices[:, 2], rtol=1e-15)
    d = surface_to_mesh(s, decimate=2)  # rows 0, 2 and columns 0, 2, 4
    assert d.vertices.shape == (6, 3) and d.faces.shape == (4, 3)
    assert d.bounds[1, 0] == pytest.approx(X0 + 4 * DX, abs=1e-15)


@pytest.mark.parametrize(
    "kwargs", [{"decimate": 0}, {"decimate": 1.5}, {"z_exaggeration": 0.0}]
)
def test_bad_options(kwargs):
    with pytest.raises(ConfigError):
        surface_to_mesh(_small(), **kwargs)


def test_no_valid_quad():
    z = np.full((3, 3), np.nan)
    z[0, 0] = 0.0
    with pytest.raises(ConfigError, match="no 2 x 2 block"):
        surface_to_mesh(Surface(z, DX, DY))


@pytest.mark.parametrize("fmt", ["stl", "ply"])
def test_round_trip_through_trimesh(tmp_path, fmt):
    s = _small(nan=(2, 3))
    mesh = surface_to_mesh(s)
    out = write_mesh(s, tmp_path / "sub" / f"part.{fmt.upper()}")
    assert out.exists() and [p.name for p in out.parent.iterdir()] == [out.name]
    back = trimesh.load_mesh(out, process=False)
    # both formats store float32 coordinates as trimesh writes them
    expected = mesh.triangles.astype(np.float32).astype(np.float64)
    np.testing.assert_array_equal(back.triangles, expected)
    if fmt == "ply":  # PLY keeps the indexed vertices and faces
        np.testing.assert_array_equal(back.faces, mesh.faces)
        np.testing.assert_array_equal(
            back.vertices, mesh.vertices.astype(np.float32).astype(np.float64)
        )


def test_format_argument_and_unsupported_suffix(tmp_path):
    out = write_mesh(_small(), tmp_path / "part.bin", format="stl")
    assert trimesh.load_mesh(out, file_type="stl").faces.shape == (24, 3)
    with pytest.raises(UnsupportedFileFormatError, match="obj"):
        write_mesh(_small(), tmp_path / "part.obj")
    assert not (tmp_path / "part.obj").exists()
