"""ZYGO Mx ``.datx`` files (HDF5).

Layout written by Mx: a ``/MetaData`` table of (Source, Link, Destination) strings
links ``Root`` -> ``Measurement`` -> ``Surface`` -> ``Path`` of the height dataset
(usually ``/Data/Surface/{GUID}``) and ``Attributes`` -> an attribute group.
The height dataset carries ``Unit`` (``Fringes``, ``NanoMeters``, ``MicroMeters``,
``MilliMeters``, ``Meters``), ``No Data`` (the invalid value), the ``X/Y/Z
Converter`` compounds (Category, BaseUnit, Parameters) -- for a lateral converter
with base unit ``Pixels``, ``Parameters[1]`` is the pixel size in m -- and, for
``Fringes``, ``Wavelength`` (m), ``Interferometric Scale Factor`` and ``Obliquity
Factor`` (height = fringes * wavelength * scale factor * obliquity).

libhdf5 can loop forever or crash on a damaged global heap (the store of
variable-length strings), so the heap collections are validated in Python before
the file is handed to h5py.
"""

from __future__ import annotations

import os
import struct
import uuid
from io import BytesIO
from typing import Any

import numpy as np

from .. import __version__
from ..errors import UnitError
from ..metrology._surface import Surface
from ..units import length_factor
from ._common import (
    Source,
    check_pixel_size,
    corrupt,
    iso_date,
    make_surface,
    metadata_json,
    parse_metadata_json,
    unsupported,
)
from ._registry import register_reader, register_writer

__all__ = ["read_datx", "read_in_process", "encode_datx", "check_hdf5"]

HDF5_MAGIC = b"\x89HDF\r\n\x1a\n"
_DBL_MAX = float(np.finfo(np.float64).max)
_META_KEY = "servosurf.metadata"
_ORIGIN_KEY = "servosurf.origin"  # exact (x0, y0) in m
_ATTR_PREFIX = "Data Context.Data Attributes."
_MAX_METADATA_ROWS = 100_000


# ------------------------------------------------------------ HDF5 guards
def _superblock(data: bytes, name: str) -> tuple[int, int, int]:
    """Return (base offset, size of offsets, size of lengths) of the superblock."""
    base = 0
    while base + 8 <= len(data):
        if data[base : base + 8] == HDF5_MAGIC:
            break
        base = 512 if base == 0 else base * 2
    else:
        raise corrupt(name, "no HDF5 signature found", "an HDF5 (.datx) file")
    if base + 16 > len(data):
        raise corrupt(name, f"file ends at byte {len(data)} inside the HDF5 superblock",
                      "a complete HDF5 file")
    version = data[base + 8]
    if version in (0, 1):
        so, sl = data[base + 13], data[base + 14]
        eof_at = base + 24 + (4 if version == 1 else 0) + 2 * so
    elif version in (2, 3):
        so, sl = data[base + 9], data[base + 10]
        eof_at = base + 12 + 2 * so
    else:
        raise corrupt(name, f"HDF5 superblock version is {version}", "0, 1, 2 or 3")
    if so not in (2, 4, 8) or sl not in (2, 4, 8):
        raise corrupt(name, f"HDF5 offset/length sizes are {so}/{sl} bytes", "2, 4 or 8")
    if eof_at + so > len(data):
        raise corrupt(name, f"file ends at byte {len(data)} inside the HDF5 superblock",
                      "a complete HDF5 file")
    eof = int.from_bytes(data[eof_at : eof_at + so], "little")
    if eof != (1 << (8 * so)) - 1 and base + eof > len(data):
        raise corrupt(
            name, f"file is truncated: {len(data)} bytes, but the HDF5 superblock says "
            f"{base + eof}", f"{base + eof} bytes",
        )
    return base, so, sl


def check_hdf5(data: bytes, name: str) -> None:
    """Validate the parts of an HDF5 file that make libhdf5 hang or crash.

    Checks the superblock against the file length and walks every global heap
    collection (signature ``GCOL``) the way libhdf5 does, requiring each object to
    advance inside its collection.

    Parameters
    ----------
    data : bytes
        Whole file.
    name : str
        File name for messages.

    Raises
    ------
    CorruptedFileError
        Truncated file or damaged global heap.
    """
    _, _, sl = _superblock(data, name)
    obj_hdr = 8 + sl
    length_fmt = {2: "<H", 4: "<I", 8: "<Q"}[sl]
    start = 0
    while True:
        a = data.find(b"GCOL", start)
        if a < 0:
            return
        start = a + 4
        if a + 8 + sl > len(data) or data[a + 4] != 1 or data[a + 5 : a + 8] != b"\0\0\0":
            continue  # not a collection header (or one libhdf5 itself rejects)
        (size,) = struct.unpack_from(length_fmt, data, a + 8)
        end = a + size
        if size < 8 + sl or end > len(data):
            raise corrupt(
                name, f"HDF5 global heap at byte {a} claims {size} bytes (file has "
                f"{len(data)})", "a heap collection inside the file",
            )
        p = a + 8 + sl
        while p < end:
            if p + obj_hdr > end:
                break
            idx = data[p] | (data[p + 1] << 8)
            (osize,) = struct.unpack_from(length_fmt, data, p + 8)
            need = osize if idx == 0 else obj_hdr + ((osize + 7) // 8) * 8
            if need <= 0 or p + need > end:
                raise corrupt(
                    name, f"HDF5 global heap at byte {a}: object {idx} at byte {p} has "
                    f"size {osize}", "objects inside their heap collection",
                )
            p += need


_H5_ERRORS: tuple[type[BaseException], ...] = (
    OSError, RuntimeError, ValueError, KeyError, TypeError, IndexError,
    UnicodeDecodeError, AttributeError, OverflowError, struct.error,
)


def _s(value: Any) -> str | None:
    """First element of a string attribute as ``str`` (None when not a string)."""
    v = value
    while isinstance(v, np.ndarray):
        if v.size == 0:
            return None
        v = v.flat[0]
    if isinstance(v, bytes):
        return v.decode("utf-8", errors="replace")
    if isinstance(v, str):
        return v
    return None


def _f(value: Any) -> float | None:
    """First element of a numeric attribute as ``float`` (None otherwise)."""
    v = value
    if isinstance(v, np.ndarray):
        if v.size == 0 or v.dtype.kind not in "fiu":
            return None
        v = v.flat[0]
    if isinstance(v, int | float | np.integer | np.floating) and not isinstance(v, bool):
        return float(v)
    return None


def _attr(obj: Any, key: str) -> Any:
    try:
        if key not in obj.attrs:
            return None
        return obj.attrs[key]
    except _H5_ERRORS:
        return None


def _converter(obj: Any, key: str) -> tuple[str | None, str | None, np.ndarray | None]:
    """(Category, BaseUnit, Parameters) of a converter attribute, None when absent."""
    v = _attr(obj, key)
    if not isinstance(v, np.ndarray) or v.dtype.names is None or v.size == 0:
        if isinstance(v, np.void) and v.dtype.names is not None:
            rec = v
        else:
            return None, None, None
    else:
        rec = v.flat[0]
    names = rec.dtype.names or ()
    cat = _s(rec["Category"]) if "Category" in names else None
    unit = _s(rec["BaseUnit"]) if "BaseUnit" in names else None
    params = None
    if "Parameters" in names:
        p = rec["Parameters"]
        try:
            params = np.asarray(p, dtype=np.float64).ravel()
        except (TypeError, ValueError):
            params = None
    return cat, unit, params


def _metadata_table(f: Any) -> dict[str, dict[str, str]]:
    ds = f.get("MetaData")
    if ds is None or not hasattr(ds, "dtype") or ds.dtype.names is None:
        return {}
    if not {"Source", "Link", "Destination"} <= set(ds.dtype.names) or ds.ndim != 1:
        return {}
    if ds.shape[0] > _MAX_METADATA_ROWS:
        return {}
    table: dict[str, dict[str, str]] = {}
    for row in ds[()]:
        src, link, dest = _s(row["Source"]), _s(row["Link"]), _s(row["Destination"])
        if src is None or link is None or dest is None:
            continue
        table.setdefault(src, {})[link] = dest
    return table


def _locate(f: Any, name: str) -> tuple[Any, Any]:
    """Return (surface dataset, attribute group or None)."""
    import h5py

    table = _metadata_table(f)
    surface = attrs_group = None
    meas = table.get("Root", {}).get("Measurement")
    if meas is not None:
        links = table.get(meas, {})
        s = links.get("Surface")
        if s is not None:
            path = table.get(s, {}).get("Path", s if s.startswith("/") else None)
            if path is not None and isinstance(f.get(path), h5py.Dataset):
                surface = f[path]
        a = links.get("Attributes")
        if a is not None and isinstance(f.get(a), h5py.Group):
            attrs_group = f[a]
    if surface is None:
        for path in ("/Measurement/Surface", "/Data/Surface"):
            obj = f.get(path)
            if isinstance(obj, h5py.Dataset):
                surface = obj
                break
            if isinstance(obj, h5py.Group):
                sets = [obj[k] for k in obj if isinstance(obj.get(k), h5py.Dataset)]
                if sets:
                    surface = sets[0]
                    break
    if surface is None:
        raise corrupt(
            name, "HDF5 file has no surface dataset",
            "a /MetaData link Root -> Measurement -> Surface, /Measurement/Surface or "
            "/Data/Surface/<dataset>",
        )
    if attrs_group is None:
        grp = f.get("Attributes")
        if isinstance(grp, h5py.Group):
            subs = [k for k in grp if k != "System" and isinstance(grp.get(k), h5py.Group)]
            if subs:
                attrs_group = grp[subs[-1]]
    return surface, attrs_group


def _find_attr(group: Any, suffix: str) -> Any:
    """Attribute of ``group`` whose name ends with ``suffix`` (first match)."""
    if group is None:
        return None
    try:
        keys = list(group.attrs.keys())
    except _H5_ERRORS:
        return None
    for prefix in (_ATTR_PREFIX, "Surface " + _ATTR_PREFIX, ""):
        if prefix + suffix in keys:
            return _attr(group, prefix + suffix)
    return None


def _group_metadata(group: Any) -> dict[str, Any]:
    md: dict[str, Any] = {}
    if group is None:
        return md
    stype = _s(_find_attr(group, "System Type"))
    md["instrument"] = f"ZYGO {stype}".strip() if stype is not None else "ZYGO"
    serial = _s(_find_attr(group, "System Serial Number"))
    if serial:
        md["serial"] = serial
    obj = _s(_find_attr(group, "Objective"))
    if obj:
        md["objective"] = obj
    sw = _s(_find_attr(group, "Software Info Name"))
    ver = _s(_find_attr(group, "Software Info Version"))
    if sw:
        md["software"] = f"{sw} {ver}".strip() if ver else sw
    comment = _s(_find_attr(group, "Comment"))
    if comment:
        md["comment"] = comment
    wl = _f(_find_attr(group, "Wavelength:Value"))
    if wl is not None and np.isfinite(wl) and wl > 0:
        md["wavelength"] = wl
    ts = _find_attr(group, "Time Stamp")
    if isinstance(ts, np.ndarray) and ts.dtype.names and "time" in ts.dtype.names and ts.size:
        date = iso_date(float(ts.flat[0]["time"]))
        if date:
            md["date"] = date
    extra = parse_metadata_json(_s(_attr(group, _META_KEY)) or "")
    if extra:
        md.update(extra)
    return md


def _height_factor(ds: Any, unit: str | None, name: str) -> float:
    """Metres per stored value."""
    _, zunit, zparams = _converter(ds, "Z Converter")
    unit = unit or zunit
    if unit is None:
        raise corrupt(name, "surface dataset has no 'Unit' attribute", "a height unit")
    if unit.strip().lower() in ("fringes", "fringe", "waves"):
        wl = _f(_attr(ds, "Wavelength"))
        isf = _f(_attr(ds, "Interferometric Scale Factor"))
        obl = _f(_attr(ds, "Obliquity Factor"))
        if zparams is not None and zparams.size >= 4:
            wl = wl if wl is not None else float(zparams[1])
            isf = isf if isf is not None else float(zparams[2])
            obl = obl if obl is not None else float(zparams[3])
        for label, v in (("Wavelength", wl), ("Interferometric Scale Factor", isf),
                         ("Obliquity Factor", obl)):
            if v is None or not np.isfinite(v) or v <= 0:
                raise corrupt(
                    name, f"surface unit is Fringes but {label} is {v!r}",
                    "a positive wavelength (m), scale factor and obliquity",
                )
        assert wl is not None and isf is not None and obl is not None
        return wl * isf * obl
    try:
        return length_factor(unit)
    except UnitError:
        raise unsupported(
            name, f"surface unit is {unit!r}",
            "Fringes, NanoMeters, MicroMeters, MilliMeters or Meters",
        ) from None


@register_reader(
    "datx",
    description="ZYGO Mx data (.datx, HDF5)",
    suffixes=(".datx",),
    magic=(HDF5_MAGIC,),
)
def read_datx(source: Source) -> Surface:
    """Read a ZYGO Mx ``.datx`` file.

    Parameters
    ----------
    source : Source
        Loaded file.

    Returns
    -------
    Surface
        Heights in m (NaN where the value equals ``No Data`` or is not finite),
        pixel sizes in m from the X/Y converters (None when 0), ``x0, y0`` from the
        ``Coordinates`` attribute.

    Notes
    -----
    libhdf5 can hang or crash on damaged files, so by default the file is parsed
    in a helper process (see ``servosurf.io._hdf5_worker``) and such failures
    become :class:`~servosurf.errors.CorruptedFileError`. Set the environment
    variable ``SERVOSURF_HDF5_ISOLATION=0`` to parse in-process.
    """
    name = source.name
    check_hdf5(source.data, name)
    if os.environ.get("SERVOSURF_HDF5_ISOLATION", "1") != "0":
        from ._hdf5_worker import run_isolated

        z, dx, dy, x0, y0, md = run_isolated(source.data, name)
        return make_surface(z, dx, dy, md, name, x0=x0, y0=y0)
    return read_in_process(source)


def read_in_process(source: Source) -> Surface:
    """Parse a ``.datx`` file with h5py in this process (see :func:`read_datx`).

    Only for trusted files: libhdf5 may hang or crash on damaged ones.

    Parameters
    ----------
    source : Source
        Loaded file.

    Returns
    -------
    Surface
        As :func:`read_datx`.
    """
    import h5py

    name = source.name
    check_hdf5(source.data, name)
    try:
        with h5py.File(BytesIO(source.data), "r") as f:
            return _read_open(f, source)
    except _H5_ERRORS as exc:
        msg = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise corrupt(name, f"HDF5 structure is damaged ({msg})", "a readable .datx file") from None


def _read_open(f: Any, source: Source) -> Surface:
    name = source.name
    ds, group = _locate(f, name)
    if ds.ndim != 2 or ds.dtype.kind not in "fiu" or 0 in ds.shape:
        raise corrupt(
            name, f"surface dataset {ds.name} has shape {ds.shape} and type {ds.dtype}",
            "a non-empty 2-D numeric array",
        )
    nbytes = int(np.prod(ds.shape, dtype=np.float64)) * 8
    if nbytes > max(1100 * len(source.data), 1 << 20):
        raise corrupt(
            name, f"surface dataset claims {ds.shape[0]}x{ds.shape[1]} values in a "
            f"{len(source.data)}-byte file", "a size the file can hold",
        )
    z = np.asarray(ds[()], dtype=np.float64)
    unit = _s(_attr(ds, "Unit"))
    factor = _height_factor(ds, unit, name)
    invalid = ~np.isfinite(z)
    nd = _f(_attr(ds, "No Data"))
    if nd is not None:
        invalid |= z == nd
        if nd >= 0.5 * _DBL_MAX:
            invalid |= z >= nd
    z = z * factor
    z[invalid] = np.nan
    pixel = []
    for axis in ("X", "Y"):
        cat, base, params = _converter(ds, f"{axis} Converter")
        value = None
        if params is not None and params.size >= 2:
            value = float(params[1])
            if base is not None and base.lower() not in ("pixels", "pixel"):
                value *= length_factor(base) if _is_length(base) else 1.0
        pixel.append(check_pixel_size(value, name, f"{axis} Converter", zero_means_uncalibrated=True))
    dx, dy = pixel
    x0 = y0 = 0.0
    coords = _attr(ds, "Coordinates")
    if isinstance(coords, np.ndarray) and coords.dtype.names and coords.size:
        rec = coords.flat[0]
        if "ColumnStart" in rec.dtype.names and dx:
            x0 = float(rec["ColumnStart"]) * dx
        if "RowStart" in rec.dtype.names and dy:
            y0 = float(rec["RowStart"]) * dy
    origin = _attr(ds, _ORIGIN_KEY)
    if isinstance(origin, np.ndarray) and origin.dtype.kind == "f" and origin.size == 2:
        x0, y0 = (float(v) for v in origin)
    md = _group_metadata(group)
    if "wavelength" not in md:
        wl = _f(_attr(ds, "Wavelength"))
        if wl is not None and np.isfinite(wl) and wl > 0:
            md["wavelength"] = wl
    md["source_format"] = "datx"
    md["datx"] = {"unit": unit, "dataset": ds.name}
    return make_surface(z, dx, dy, md, name, x0=x0, y0=y0)


def _is_length(unit: str) -> bool:
    try:
        length_factor(unit)
    except UnitError:
        return False
    return True


# ------------------------------------------------------------------ writer
@register_writer(
    "datx",
    description="ZYGO Mx-style data (.datx, HDF5), heights in NanoMeters",
    suffixes=(".datx",),
)
def encode_datx(surface: Surface) -> bytes:
    """Encode a surface as an Mx-style ``.datx`` (HDF5) file.

    Heights are stored as float64 in ``NanoMeters`` with ``No Data`` = the largest
    float64 for invalid pixels; pixel sizes go to the X/Y converters (0 when
    uncalibrated); all metadata is stored as JSON in the attribute
    ``servosurf.metadata`` of the attribute group, and the exact origin in
    ``servosurf.origin`` of the dataset.

    Parameters
    ----------
    surface : Surface
        Heights in m.

    Returns
    -------
    bytes
        The HDF5 file content.
    """
    import h5py

    guid = {k: "{" + str(uuid.uuid4()).upper() + "}" for k in ("m", "s", "a")}
    md = surface.metadata
    wl = md.get("wavelength")
    wl = float(wl) if isinstance(wl, int | float) and wl > 0 else float("nan")
    vstr = h5py.string_dtype("utf-8")
    astr = h5py.string_dtype("ascii")
    conv_dt = np.dtype([("Category", astr), ("BaseUnit", astr),
                        ("Parameters", h5py.vlen_dtype(np.float64))])

    def conv(cat: str, unit: str, params: list[float]) -> np.ndarray:
        a = np.empty(1, dtype=conv_dt)
        a[0] = (cat.encode(), unit.encode(), np.asarray(params, dtype=np.float64))
        return a

    def s(text: str) -> np.ndarray:
        return np.array([text], dtype=vstr)

    def num(v: float) -> np.ndarray:
        return np.array([v], dtype=np.float64)

    ny, nx = surface.shape
    z = surface.z * 1e9
    z[~np.isfinite(z)] = _DBL_MAX
    bio = BytesIO()
    with h5py.File(bio, "w") as f:
        attrs = f.create_group(f"Attributes/{guid['a']}").attrs
        for key, text in (("Objective", md.get("objective")), ("Comment", md.get("comment"))):
            if isinstance(text, str):
                attrs[_ATTR_PREFIX + key] = s(text)
        attrs[_ATTR_PREFIX + "Software Info Name"] = s("servosurf")
        attrs[_ATTR_PREFIX + "Software Info Version"] = s(__version__)
        attrs[_ATTR_PREFIX + "Wavelength:Value"] = num(wl)
        attrs[_ATTR_PREFIX + "Wavelength:Unit"] = s("Meters")
        attrs[_META_KEY] = s(metadata_json(md, exclude=("source_format",)))
        ds = f.create_dataset(f"Data/Surface/{guid['s']}", data=z, dtype=np.float64)
        dxv = surface.dx or 0.0
        dyv = surface.dy or 0.0
        ds.attrs["Unit"] = s("NanoMeters")
        ds.attrs["No Data"] = num(_DBL_MAX)
        ds.attrs["Wavelength"] = num(wl)
        ds.attrs["Interferometric Scale Factor"] = num(0.5)
        ds.attrs["Obliquity Factor"] = num(1.0)
        ds.attrs["X Converter"] = conv("LateralCat", "Pixels", [0.0, dxv, 0.0, 0.0])
        ds.attrs["Y Converter"] = conv("LateralCat", "Pixels", [0.0, dyv, 0.0, 0.0])
        ds.attrs["Z Converter"] = conv("HeightCat", "NanoMeters", [])
        col0 = int(round(surface.x0 / dxv)) if dxv else 0
        row0 = int(round(surface.y0 / dyv)) if dyv else 0
        coords = np.array(
            [(row0, col0, nx, ny)],
            dtype=[("RowStart", "<i4"), ("ColumnStart", "<i4"), ("Width", "<i4"),
                   ("Height", "<i4")],
        )
        ds.attrs["Coordinates"] = coords
        ds.attrs["Group Number"] = np.array([1], dtype=np.int32)
        ds.attrs[_ORIGIN_KEY] = np.array([surface.x0, surface.y0], dtype=np.float64)
        rows = [
            ("Root", "Measurement", guid["m"]),
            (guid["m"], "Attributes", f"/Attributes/{guid['a']}"),
            (guid["m"], "Surface", guid["s"]),
            (guid["m"], "Group Number", "1"),
            (guid["m"], "Element Type", "Measurement"),
            (guid["m"], "Name", "servosurf"),
            (guid["s"], "Path", f"/Data/Surface/{guid['s']}"),
            (guid["s"], "Name", "Surface"),
            (guid["s"], "MpxDataType", "DoubleMatrix2D"),
        ]
        meta_dt = np.dtype([("Source", astr), ("Link", astr), ("Destination", astr)])
        table = np.array([tuple(c.encode() for c in r) for r in rows], dtype=meta_dt)
        f.create_dataset("MetaData", data=table)
    return bio.getvalue()
