"""servosurf's own ``.npz`` container.

Members: ``z`` (heights in m), ``dx``, ``dy``, ``x0``, ``y0`` (m; ``dx``/``dy`` NaN when
uncalibrated) and ``metadata`` (a JSON string). Read without pickle; every array
header is checked against the member size before allocation.
"""

from __future__ import annotations

import zipfile
from io import BytesIO

import numpy as np

from ..metrology import Surface
from ._common import (
    Source,
    check_pixel_size,
    corrupt,
    make_surface,
    metadata_json,
    open_zip,
    parse_metadata_json,
    zip_archive,
    zip_member,
)
from ._registry import register_reader, register_writer

__all__ = ["read_npz", "encode_npz"]

_REQUIRED = ("z", "dx", "dy")


def _is_npz(data: bytes) -> bool:
    if not data.startswith(b"PK"):
        return False
    try:
        with zipfile.ZipFile(BytesIO(data)) as zf:
            names = zf.namelist()
    except Exception:  # sniffing must never raise
        return False
    return "z.npy" in names and all(n.endswith(".npy") for n in names)


def _array(
    zf: zipfile.ZipFile, key: str, name: str, *, required: bool
) -> np.ndarray | None:
    member = key + ".npy"
    if member not in zf.namelist():
        if required:
            raise corrupt(
                name, f"archive has no {member}", f"members {', '.join(_REQUIRED)}"
            )
        return None
    raw = zip_member(zf, member, name)
    fp = BytesIO(raw)
    try:
        version = np.lib.format.read_magic(fp)
        if version == (1, 0):
            shape, fortran, dtype = np.lib.format.read_array_header_1_0(fp)
        elif version in ((2, 0), (3, 0)):
            shape, fortran, dtype = np.lib.format.read_array_header_2_0(fp)
        else:
            raise ValueError(f"npy version {version}")
        if dtype.hasobject:
            raise ValueError("object arrays are not accepted")
        count = int(np.prod(shape, dtype=np.float64))
        if count * dtype.itemsize > len(raw) - fp.tell():
            raise ValueError(
                f"header claims {shape} {dtype} but {len(raw)} bytes are stored"
            )
        fp.seek(0)
        return np.lib.format.read_array(fp, allow_pickle=False)
    except (
        ValueError,
        TypeError,
        OverflowError,
        EOFError,
        KeyError,
        SyntaxError,
        MemoryError,
        UnicodeDecodeError,
    ) as exc:
        raise corrupt(
            name, f"{member} is not a valid .npy array ({exc})", "a numeric array"
        ) from None


def _scalar(a: np.ndarray | None, key: str, name: str) -> float | None:
    if a is None:
        return None
    if a.size != 1 or a.dtype.kind not in "fiu":
        raise corrupt(name, f"{key} has shape {a.shape} and type {a.dtype}", "a number")
    v = float(a.ravel()[0])
    return None if np.isnan(v) else v


@register_reader(
    "npz",
    description="servosurf NumPy archive (.npz): z, dx, dy, x0, y0 in m, metadata JSON",
    suffixes=(".npz",),
    magic=(b"PK\x03\x04",),
    sniff=_is_npz,
)
def read_npz(source: Source) -> Surface:
    """Read a servosurf ``.npz`` archive.

    Parameters
    ----------
    source : Source
        Loaded file.

    Returns
    -------
    Surface
        Heights and pixel sizes in m (None when stored as NaN).
    """
    name = source.name
    zf = open_zip(source.data, name, "a .npz zip archive")
    with zf:
        z = _array(zf, "z", name, required=True)
        assert z is not None
        if z.ndim != 2 or z.dtype.kind not in "fiu" or z.size == 0:
            raise corrupt(
                name, f"z has shape {z.shape} and type {z.dtype}", "a 2-D numeric map"
            )
        dx = check_pixel_size(
            _scalar(_array(zf, "dx", name, required=True), "dx", name),
            name,
            "dx",
            zero_means_uncalibrated=False,
        )
        dy = check_pixel_size(
            _scalar(_array(zf, "dy", name, required=True), "dy", name),
            name,
            "dy",
            zero_means_uncalibrated=False,
        )
        x0 = _scalar(_array(zf, "x0", name, required=False), "x0", name) or 0.0
        y0 = _scalar(_array(zf, "y0", name, required=False), "y0", name) or 0.0
        meta = _array(zf, "metadata", name, required=False)
    md = {}
    if meta is not None:
        if meta.dtype.kind != "U" or meta.size != 1:
            raise corrupt(name, f"metadata has type {meta.dtype}", "a JSON string")
        parsed = parse_metadata_json(str(meta.ravel()[0]))
        if parsed is None:
            raise corrupt(name, "metadata is not a JSON object", "a JSON object")
        md = parsed
    md["source_format"] = "npz"
    return make_surface(np.array(z, dtype=np.float64), dx, dy, md, name, x0=x0, y0=y0)


@register_writer(
    "npz",
    description="servosurf NumPy archive (.npz): z, dx, dy, x0, y0 in m, metadata JSON",
    suffixes=(".npz",),
)
def encode_npz(surface: Surface, *, compressed: bool = True) -> bytes:
    """Encode a surface as a servosurf ``.npz`` archive (exact float64 round trip).

    The members are ``.npy`` arrays as :func:`numpy.savez` writes them, in a zip
    archive with fixed member time stamps, so the same surface gives the same
    bytes (``numpy.load`` reads it).

    Parameters
    ----------
    surface : Surface
        Heights in m.
    compressed : bool, default: True
        Deflate the members.

    Returns
    -------
    bytes
        The archive.
    """
    nan = float("nan")
    arrays = {
        "z": np.ascontiguousarray(surface.z, dtype=np.float64),
        "dx": np.float64(surface.dx if surface.dx is not None else nan),
        "dy": np.float64(surface.dy if surface.dy is not None else nan),
        "x0": np.float64(surface.x0),
        "y0": np.float64(surface.y0),
        "metadata": np.array(
            metadata_json(surface.metadata, exclude=("source_format",))
        ),
    }
    members = {}
    for key, value in arrays.items():
        buf = BytesIO()
        np.lib.format.write_array(buf, np.asanyarray(value), allow_pickle=False)
        members[f"{key}.npy"] = buf.getvalue()
    # np.savez stamps every member with the current time; zip_archive does not.
    return zip_archive(members, compress=compressed)
