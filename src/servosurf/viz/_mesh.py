"""Triangle meshes of height maps (trimesh), and STL/PLY export.

trimesh is imported inside the functions that need it, never at package import.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from ..errors import ConfigError, UnsupportedFileFormatError
from ..metrology import Surface

if TYPE_CHECKING:
    import trimesh

__all__ = ["surface_to_mesh", "write_mesh", "MESH_FORMATS"]

#: Mesh file formats :func:`write_mesh` writes (binary encodings).
MESH_FORMATS: tuple[str, ...] = ("stl", "ply")


def _check_surface(surface: object) -> Surface:
    if not isinstance(surface, Surface):
        raise ConfigError(f"surface must be a Surface, got {type(surface).__name__}")
    return surface


def _check_stride(decimate: object) -> int:
    if decimate is None:
        return 1
    if isinstance(decimate, bool | np.bool_) or not isinstance(
        decimate, int | np.integer
    ):
        raise ConfigError(
            f"decimate must be None or an int >= 1, got {type(decimate).__name__}"
        )
    if decimate < 1:
        raise ConfigError(f"decimate must be None or an int >= 1, got {decimate!r}")
    return int(decimate)


def _check_exaggeration(z_exaggeration: object) -> float:
    try:
        v = float(z_exaggeration)  # type: ignore[arg-type]
    except (TypeError, ValueError):
        raise ConfigError(
            f"z_exaggeration must be a positive number, got {z_exaggeration!r}"
        ) from None
    if not math.isfinite(v) or v <= 0:
        raise ConfigError(
            f"z_exaggeration must be a positive number, got {z_exaggeration!r}"
        )
    return v


def _triangulate(
    surface: Surface, stride: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Grid triangles of the valid pixel quads of a (strided) height map.

    Parameters
    ----------
    surface : Surface
        Height map in m (NaN = no data).
    stride : int
        Keep every ``stride``-th row and column.

    Returns
    -------
    xyz : ndarray of shape (n_vertices, 3)
        Vertex coordinates ``(x, y, z)`` in m (pixel index units when the
        surface is uncalibrated), only vertices used by a face.
    faces : ndarray of shape (n_faces, 3)
        Vertex indices, counter-clockwise seen from +z (normals point to +z).
    pixel : ndarray of shape (n_vertices, 2)
        ``(row, column)`` of each vertex in the full-resolution map.

    Raises
    ------
    ConfigError
        If no 2 x 2 block of valid pixels exists at this stride.
    """
    x, y = surface.coords()
    rows = np.arange(0, surface.shape[0], stride)
    cols = np.arange(0, surface.shape[1], stride)
    z = surface.z[np.ix_(rows, cols)]
    ny, nx = z.shape
    v = np.isfinite(z)
    quad = v[:-1, :-1] & v[:-1, 1:] & v[1:, :-1] & v[1:, 1:]
    if not quad.any():
        raise ConfigError(
            f"surface has no 2 x 2 block of valid pixels (stride {stride}); "
            "nothing to triangulate"
        )
    i, j = np.nonzero(quad)
    a = i * nx + j  # (i, j)
    b = a + 1  # (i, j + 1)
    c = a + nx + 1  # (i + 1, j + 1)
    d = a + nx  # (i + 1, j)
    faces = np.stack([np.stack([a, b, c], 1), np.stack([a, c, d], 1)], 1).reshape(-1, 3)
    used, faces = np.unique(faces, return_inverse=True)
    faces = faces.reshape(-1, 3)
    ui, uj = np.divmod(used, nx)
    xyz = np.column_stack([x[cols][uj], y[rows][ui], z[ui, uj]])
    pixel = np.column_stack([rows[ui], cols[uj]])
    return xyz, faces.astype(np.int64), pixel


def surface_to_mesh(
    surface: Surface,
    *,
    z_exaggeration: float = 1.0,
    decimate: int | None = None,
) -> trimesh.Trimesh:
    """Triangulate a height map: two triangles per quad of four valid pixels.

    Parameters
    ----------
    surface : Surface
        Height map in m; rows are y, columns are x. NaN pixels leave holes.
    z_exaggeration : float, default: 1.0
        Factor applied to the heights (dimensionless); 1 keeps true scale.
    decimate : int or None, default: None
        Keep every ``decimate``-th row and column (plain subsampling, no
        averaging); ``None`` keeps all pixels.

    Returns
    -------
    trimesh.Trimesh
        Vertices at pixel centres ``(x, y, z_exaggeration * z)`` in m (pixel
        index units if the surface is uncalibrated), only those used by a face.
        Each quad of four valid pixels ``(i, j), (i, j+1), (i+1, j+1),
        (i+1, j)`` gives the faces ``(a, b, c)`` and ``(a, c, d)``, wound so that
        normals point towards +z; quads with a NaN corner are skipped. The mesh
        is built with ``process=False`` (no vertex merging or reordering).

    Raises
    ------
    ConfigError
        If ``surface`` is not a Surface, the options are invalid, or no quad of
        four valid pixels exists.
    ImportError
        If trimesh is not installed.

    See Also
    --------
    write_mesh

    Examples
    --------
    >>> import numpy as np
    >>> from servosurf.metrology import Surface
    >>> m = surface_to_mesh(Surface(np.zeros((3, 4)), 1e-6, 1e-6))
    >>> m.vertices.shape, m.faces.shape
    ((12, 3), (12, 3))
    """
    try:
        import trimesh
    except ImportError:
        raise ImportError("mesh export needs trimesh: pip install trimesh") from None
    surface = _check_surface(surface)
    stride = _check_stride(decimate)
    exaggeration = _check_exaggeration(z_exaggeration)
    xyz, faces, _ = _triangulate(surface, stride)
    xyz[:, 2] *= exaggeration
    return trimesh.Trimesh(vertices=xyz, faces=faces, process=False)


def write_mesh(
    surface: Surface,
    path: str | Path,
    *,
    format: str | None = None,
    z_exaggeration: float = 1.0,
    decimate: int | None = None,
) -> Path:
    """Write a height map as a binary STL or PLY triangle mesh, atomically.

    Parameters
    ----------
    surface : Surface
        Height map in m (see :func:`surface_to_mesh`).
    path : str or Path
        Output file; missing parent folders are created.
    format : {"stl", "ply"} or None, default: None
        File format; ``None`` takes it from the suffix of ``path``.
    z_exaggeration : float, default: 1.0
        Factor applied to the heights (dimensionless).
    decimate : int or None, default: None
        Keep every ``decimate``-th row and column.

    Returns
    -------
    Path
        The written file. Coordinates are in m (STL stores float32; PLY as
        trimesh writes it). The file appears complete or not at all (temporary
        file in the same folder + :func:`os.replace`).

    Raises
    ------
    UnsupportedFileFormatError
        If the format (or suffix) is not one of :data:`MESH_FORMATS`.
    ConfigError
        On invalid surface or options (see :func:`surface_to_mesh`).

    Notes
    -----
    STL and PLY carry no unit; the values are metres, so most CAD tools (which
    assume millimetres) show the part 1000x too small.
    """
    path = Path(path)
    fmt = (format if format is not None else path.suffix.lstrip(".")).lower()
    if fmt not in MESH_FORMATS:
        what = f"format {format!r}" if format is not None else f"suffix {path.suffix!r}"
        raise UnsupportedFileFormatError(
            f"cannot write a mesh with {what}; supported: {', '.join(MESH_FORMATS)}"
        )
    mesh = surface_to_mesh(surface, z_exaggeration=z_exaggeration, decimate=decimate)
    data = mesh.export(file_type=fmt)
    if isinstance(data, str):  # pragma: no cover - ASCII encodings only
        data = data.encode()
    from .._atomic import atomic_path

    with atomic_path(path, suffix=f".{fmt}") as tmp:
        tmp.write_bytes(data)
    return path
