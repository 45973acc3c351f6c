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

import hashlib
import math
import os
import struct
import uuid
from io import BytesIO
from typing import Any

import numpy as np

from .._version import __version__
from ..errors import UnitError
from ..metrology import Surface
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

__all__ = ["read_datx", "encode_datx", "check_hdf5"]

HDF5_MAGIC = b"\x89HDF\r\n\x1a\n"
_DBL_MAX = float(np.finfo(np.float64).max)
_META_KEY = "servosurf.metadata"
_ORIGIN_KEY = "servosurf.origin"  # exact (x0, y0) in m
#: Set on the dataset when its wavelength is the nominal placeholder.
_NOMINAL_WL_KEY = "servosurf.nominal_wavelength"
_ATTR_PREFIX = "Data Context.Data Attributes."  # Mx attribute-name prefix


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
        raise corrupt(
            name,
            f"file ends at byte {len(data)} inside the HDF5 superblock",
            "a complete HDF5 file",
        )
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
        raise corrupt(
            name, f"HDF5 offset/length sizes are {so}/{sl} bytes", "2, 4 or 8"
        )
    if eof_at + so > len(data):
        raise corrupt(
            name,
            f"file ends at byte {len(data)} inside the HDF5 superblock",
            "a complete HDF5 file",
        )
    eof = int.from_bytes(data[eof_at : eof_at + so], "little")
    if eof != (1 << (8 * so)) - 1 and base + eof > len(data):
        raise corrupt(
            name,
            f"file is truncated: {len(data)} bytes, but the HDF5 superblock says "
            f"{base + eof}",
            f"{base + eof} bytes",
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
        if (
            a + 8 + sl > len(data)
            or data[a + 4] != 1
            or data[a + 5 : a + 8] != b"\0\0\0"
        ):
            continue  # not a collection header (or one libhdf5 itself rejects)
        (size,) = struct.unpack_from(length_fmt, data, a + 8)
        end = a + size
        if size < 8 + sl or end > len(data):
            raise corrupt(
                name,
                f"HDF5 global heap at byte {a} claims {size} bytes (file has "
                f"{len(data)})",
                "a heap collection inside the file",
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
                    name,
                    f"HDF5 global heap at byte {a}: object {idx} at byte {p} has "
                    f"size {osize}",
                    "objects inside their heap collection",
                )
            p += need


_H5_ERRORS: tuple[type[BaseException], ...] = (
    OSError,
    RuntimeError,
    ValueError,
    KeyError,
    TypeError,
    IndexError,
    UnicodeDecodeError,
    AttributeError,
    OverflowError,
    struct.error,
)


def _first(v: Any) -> Any:
    while isinstance(v, list):
        if not v:
            return None
        v = v[0]
    return v


def _s(v: Any) -> str | None:
    """First element of a plain attribute value as ``str`` (None otherwise)."""
    v = _first(v)
    return v if isinstance(v, str) else None


def _f(v: Any) -> float | None:
    """First element of a plain attribute value as ``float`` (None otherwise)."""
    v = _first(v)
    if isinstance(v, int | float) and not isinstance(v, bool):
        return float(v)
    return None


def _rec(v: Any) -> dict[str, Any]:
    """First record of a plain compound attribute (empty dict otherwise)."""
    v = _first(v)
    return v if isinstance(v, dict) else {}


def _converter(attrs: dict[str, Any], key: str) -> tuple[str | None, list[float]]:
    """(BaseUnit, Parameters) of a converter attribute."""
    rec = _rec(attrs.get(key))
    params = rec.get("Parameters")
    if not isinstance(params, list):
        params = []
    params = [p for p in params if isinstance(p, float)]
    return _s(rec.get("BaseUnit")), params


def _group_metadata(g: dict[str, Any]) -> dict[str, Any]:
    md: dict[str, Any] = {}
    if not g:
        return md
    stype = _s(g.get("System Type"))
    sw = _s(g.get("Software Info Name"))
    if stype:
        md["instrument"] = f"ZYGO {stype}"
    elif sw and sw.startswith(("MetroPro", "Mx")):
        md["instrument"] = "ZYGO"
    serial = _s(g.get("System Serial Number"))
    if serial:
        md["serial"] = serial
    obj = _s(g.get("Objective"))
    if obj:
        md["objective"] = obj
    ver = _s(g.get("Software Info Version"))
    if sw:
        md["software"] = f"{sw} {ver}".strip() if ver else sw
    comment = _s(g.get("Comment"))
    if comment:
        md["comment"] = comment
    wl = _f(g.get("Wavelength:Value"))
    if wl is not None and np.isfinite(wl) and wl > 0:
        md["wavelength"] = wl
    t = _f(_rec(g.get("Time Stamp")).get("time"))
    date = iso_date(t) if t is not None else None
    if date:
        md["date"] = date
    extra = parse_metadata_json(_s(g.get(_META_KEY)) or "")
    if extra:
        md.update(extra)
    return md


def _height_factor(attrs: dict[str, Any], name: str) -> tuple[float, str]:
    """(metres per stored value, unit name)."""
    zunit, zparams = _converter(attrs, "Z Converter")
    unit = _s(attrs.get("Unit")) or zunit
    if unit is None:
        raise corrupt(name, "surface dataset has no 'Unit' attribute", "a height unit")
    if unit.strip().lower() in ("fringes", "fringe", "waves"):
        wl = _f(attrs.get("Wavelength"))
        isf = _f(attrs.get("Interferometric Scale Factor"))
        obl = _f(attrs.get("Obliquity Factor"))
        if len(zparams) >= 4:
            wl = wl if wl is not None else zparams[1]
            isf = isf if isf is not None else zparams[2]
            obl = obl if obl is not None else zparams[3]
        for label, v in (
            ("Wavelength", wl),
            ("Interferometric Scale Factor", isf),
            ("Obliquity Factor", obl),
        ):
            if v is None or not np.isfinite(v) or v <= 0:
                raise corrupt(
                    name,
                    f"surface unit is Fringes but {label} is {v!r}",
                    "a positive wavelength (m), scale factor and obliquity",
                )
        assert wl is not None and isf is not None and obl is not None
        return wl * isf * obl, unit
    try:
        return length_factor(unit), unit
    except UnitError:
        raise unsupported(
            name,
            f"surface unit is {unit!r}",
            "Fringes, NanoMeters, MicroMeters, MilliMeters or Meters",
        ) from None


def _is_length(unit: str) -> bool:
    try:
        length_factor(unit)
    except UnitError:
        return False
    return True


def _interpret(ex: dict[str, Any], name: str) -> Surface:
    """Build the Surface from :func:`_hdf5.extract` output."""
    attrs = ex["attrs"]
    factor, unit = _height_factor(attrs, name)
    z = ex["z"]
    invalid = ~np.isfinite(z)
    nd = _f(attrs.get("No Data"))
    if nd is not None:
        invalid |= z == nd
        if nd >= 0.5 * _DBL_MAX:
            invalid |= z >= nd
    z = z * factor
    z[invalid] = np.nan
    pixel = []
    for axis in ("X", "Y"):
        base, params = _converter(attrs, f"{axis} Converter")
        value = None
        if len(params) >= 2:
            value = params[1]
            if (
                base is not None
                and base.lower() not in ("pixels", "pixel")
                and _is_length(base)
            ):
                value *= length_factor(base)
        pixel.append(
            check_pixel_size(
                value, name, f"{axis} Converter", zero_means_uncalibrated=True
            )
        )
    dx, dy = pixel
    x0 = y0 = 0.0
    coords = _rec(attrs.get("Coordinates"))
    col, row = _f(coords.get("ColumnStart")), _f(coords.get("RowStart"))
    if col is not None and dx:
        x0 = col * dx
    if row is not None and dy:
        y0 = row * dy
    origin = attrs.get(_ORIGIN_KEY)
    if (
        isinstance(origin, list)
        and len(origin) == 2
        and all(isinstance(v, float) for v in origin)
    ):
        x0, y0 = origin
    md = _group_metadata(ex["group"])
    if _f(attrs.get(_NOMINAL_WL_KEY)):
        md.pop("wavelength", None)  # servosurf's placeholder, not a measurement
    elif "wavelength" not in md:
        wl = _f(attrs.get("Wavelength"))
        if wl is not None and np.isfinite(wl) and wl > 0:
            md["wavelength"] = wl
    md["source_format"] = "datx"
    md["datx"] = {"unit": unit, "dataset": ex["dataset"]}
    return make_surface(z, dx, dy, md, name, x0=x0, y0=y0)


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
    libhdf5 can hang or crash on damaged files, so the file is parsed in a helper
    process (see ``servosurf.io._hdf5``) and such failures become
    :class:`~servosurf.errors.CorruptedFileError`. Set the environment variable
    ``SERVOSURF_HDF5_ISOLATION=0`` to parse in-process (trusted files only).
    """
    from ._hdf5 import ExtractError, extract, extract_isolated

    name = source.name
    check_hdf5(source.data, name)
    try:
        if os.environ.get("SERVOSURF_HDF5_ISOLATION", "1") != "0":
            ex = extract_isolated(source.data, name)
        else:
            ex = extract(source.data)
    except ExtractError as exc:
        raise corrupt(name, *exc.args) from None
    except _H5_ERRORS as exc:
        msg = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise corrupt(
            name, f"HDF5 structure is damaged ({msg})", "a readable .datx file"
        ) from None
    return _interpret(ex, name)


# ------------------------------------------------------------------ writer
#: Wavelength written when the surface carries none, in m (the HeNe line of the
#: MetroPro and XYZ writers). The heights are in NanoMeters, so it does not enter
#: them; readers such as prysm require the attribute to exist.
NOMINAL_WAVELENGTH = 632.8e-9

#: Namespace of the content-derived GUIDs of written files (uuid5 of this name).
_GUID_NAMESPACE = uuid.uuid5(uuid.NAMESPACE_URL, "https://servosurf/datx")


def _guids(surface: Surface, meta: str) -> dict[str, str]:
    """Mx-style ``{GUID}`` names derived from the content (same data, same GUIDs)."""
    h = hashlib.sha256()
    z = np.ascontiguousarray(surface.z, dtype="<f8")
    h.update(repr((z.shape, surface.dx, surface.dy, surface.x0, surface.y0)).encode())
    h.update(z.tobytes())
    h.update(meta.encode())
    digest = h.hexdigest()
    return {
        k: "{" + str(uuid.uuid5(_GUID_NAMESPACE, f"{digest}:{k}")).upper() + "}"
        for k in ("m", "s", "a")
    }


@register_writer(
    "datx",
    description="ZYGO Mx-style data (.datx, HDF5), heights in NanoMeters",
    suffixes=(".datx",),
)
def encode_datx(surface: Surface) -> bytes:
    """Encode a surface as an Mx-style ``.datx`` (HDF5) file.

    Heights are stored as float64 in ``NanoMeters`` with ``No Data`` = the largest
    float64 for invalid pixels; pixel sizes go to the X/Y converters (0 when
    uncalibrated) and, as real Mx files carry it, to the lateral resolution
    attributes of the attribute group (``Data Context.Lateral Resolution`` and
    ``Data Context.Data Attributes.Resolution``, the x pixel size in m, where
    prysm looks for the pixel size); all metadata is stored as JSON in the
    attribute ``servosurf.metadata`` of the attribute group, and the exact origin
    in ``servosurf.origin`` of the dataset. The software attributes name
    servosurf, not a ZYGO instrument.

    The bytes are reproducible: the ``{GUID}`` names are derived from the content
    (uuid5 of a SHA-256 of heights, pixel sizes, origin and metadata) instead of
    being random, and no object carries creation or modification times (datasets
    are created with ``track_times=False``; groups in the default, earliest
    HDF5 file format store none).

    Parameters
    ----------
    surface : Surface
        Heights in m.

    Returns
    -------
    bytes
        The HDF5 file content.

    Notes
    -----
    The ``Wavelength`` attributes hold ``metadata["wavelength"]`` (m) when it is a
    positive number, else :data:`NOMINAL_WAVELENGTH` (never NaN); the reader
    reports a wavelength only when the metadata held one.
    """
    import h5py

    md = surface.metadata
    meta = metadata_json(md, exclude=("source_format",))
    guid = _guids(surface, meta)
    wl = md.get("wavelength")
    wl_known = isinstance(wl, int | float) and math.isfinite(wl) and wl > 0
    wl = float(wl) if wl_known else NOMINAL_WAVELENGTH
    vstr = h5py.string_dtype("utf-8")
    astr = h5py.string_dtype("ascii")
    conv_dt = np.dtype(
        [
            ("Category", astr),
            ("BaseUnit", astr),
            ("Parameters", h5py.vlen_dtype(np.float64)),
        ]
    )
    conv_value_dt = np.dtype([("Converter", conv_dt), ("Value", np.float64)])

    def conv(cat: str, unit: str, params: list[float]) -> np.ndarray:
        a = np.empty(1, dtype=conv_dt)
        a[0] = (cat.encode(), unit.encode(), np.asarray(params, dtype=np.float64))
        return a

    def conv_value(cat: str, unit: str, params: list[float], v: float) -> np.ndarray:
        a = np.empty(1, dtype=conv_value_dt)
        a[0] = (conv(cat, unit, params)[0], v)
        return a

    def s(text: str) -> np.ndarray:
        return np.array([text], dtype=vstr)

    def num(v: float) -> np.ndarray:
        return np.array([v], dtype=np.float64)

    ny, nx = surface.shape
    z = surface.z * 1e9
    z[~np.isfinite(z)] = _DBL_MAX
    dxv = surface.dx or 0.0
    dyv = surface.dy or 0.0
    bio = BytesIO()
    with h5py.File(bio, "w") as f:
        top = f.create_group("Attributes")
        top.attrs["File Layout Version"] = np.array([1], dtype=np.int32)
        attrs = top.create_group(guid["a"]).attrs
        for key, text in (
            ("Objective", md.get("objective")),
            ("Comment", md.get("comment")),
        ):
            if isinstance(text, str):
                attrs[_ATTR_PREFIX + key] = s(text)
        attrs[_ATTR_PREFIX + "Software Info Name"] = s("servosurf")
        attrs[_ATTR_PREFIX + "Software Info Version"] = s(__version__)
        attrs[_ATTR_PREFIX + "Wavelength"] = conv_value(
            "LinearCat", "Meters", [0.0], wl
        )
        attrs[_ATTR_PREFIX + "Wavelength:Value"] = num(wl)
        attrs[_ATTR_PREFIX + "Wavelength:Unit"] = s("Meters")
        # Lateral resolution as Mx writes it: in the data attributes
        # ("Resolution") and in the data context ("Lateral Resolution").
        for key in (_ATTR_PREFIX + "Resolution", "Data Context.Lateral Resolution"):
            attrs[key] = conv_value("LinearCat", "Meters", [0.0], dxv)
            attrs[key + ":Value"] = num(dxv)
            attrs[key + ":Unit"] = s("Meters")
        attrs[_META_KEY] = s(meta)
        ds = f.create_group("Data/Surface").create_dataset(
            guid["s"], data=z, dtype=np.float64, track_times=False
        )
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
            dtype=[
                ("RowStart", "<i4"),
                ("ColumnStart", "<i4"),
                ("Width", "<i4"),
                ("Height", "<i4"),
            ],
        )
        ds.attrs["Coordinates"] = coords
        ds.attrs["Group Number"] = np.array([1], dtype=np.int32)
        ds.attrs[_ORIGIN_KEY] = np.array([surface.x0, surface.y0], dtype=np.float64)
        if not wl_known:
            ds.attrs[_NOMINAL_WL_KEY] = np.array([1], dtype=np.uint8)
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
        f.create_dataset("MetaData", data=table, track_times=False)
    return bio.getvalue()
