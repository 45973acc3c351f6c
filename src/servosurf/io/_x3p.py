"""ISO 5436-2 / ISO 25178-72 ``.x3p`` files (zip archive with ``main.xml``).

``main.xml`` describes the axes (Record1: CX/CY incremental with ``Increment`` and
``Offset`` in m; CZ absolute with a data type I = int16, L = int32, F = float32,
D = float64 and optional ``Increment``/``Offset``: z = raw * Increment + Offset),
optional metadata (Record2) and the data (Record3): ``MatrixDimension`` and either a
``DataLink`` to a little-endian binary member (x fastest, then y) with an optional
validity bit map (one bit per point, least significant bit first), or the values as
text in ``DataList/Datum`` elements (an empty Datum is an invalid point).

``FeatureType`` ``SUR`` is an areal map; ``PRF`` is a profile, an ``N x 1 x M``
matrix (``N`` points along CX, ``M`` layers; one layer is read), returned as a
:class:`~servosurf.metrology.Profile` and written from one.
"""

from __future__ import annotations

import hashlib
import xml.etree.ElementTree as ET
import zipfile
from io import BytesIO
from typing import Any

import numpy as np

from .._version import __version__
from ..metrology import Profile, Surface
from ._common import (
    Source,
    check_pixel_size,
    corrupt,
    iso_date,
    make_surface,
    metadata_json,
    open_zip,
    parse_metadata_json,
    timestamp_from_iso,
    unsupported,
    writer_error,
    zip_archive,
    zip_member,
)
from ._registry import register_reader, register_writer

__all__ = ["read_x3p", "encode_x3p"]

NS = "http://www.opengps.eu/2008/ISO5436_2"
_DTYPES = {"I": "<i2", "L": "<i4", "F": "<f4", "D": "<f8"}
_MAX_XML_BYTES = 256 * 2**20
_NA = "not available"  # the schema's placeholder for a required, unknown value


def _is_x3p(data: bytes) -> bool:
    if not data.startswith(b"PK"):
        return False
    try:
        with zipfile.ZipFile(BytesIO(data)) as zf:
            return "main.xml" in zf.namelist()
    except Exception:  # sniffing must never raise
        return False


def _local(tag: str) -> str:
    return tag.rsplit("}", 1)[-1]


def _child(elem: ET.Element | None, *path: str) -> ET.Element | None:
    for part in path:
        if elem is None:
            return None
        elem = next((c for c in elem if _local(c.tag) == part), None)
    return elem


def _text(elem: ET.Element | None, *path: str) -> str | None:
    e = _child(elem, *path)
    if e is None or e.text is None:
        return None
    return e.text.strip()


def _number(
    root: ET.Element,
    name: str,
    *path: str,
    default: float | None = None,
    integer: bool = False,
) -> float:
    t = _text(root, *path)
    if t is None or t == "":
        if default is None:
            raise corrupt(name, f"main.xml has no {'/'.join(path)}", "that element")
        return default
    try:
        v = float(t)
    except ValueError:
        raise corrupt(
            name, f"main.xml {'/'.join(path)} is {t[:30]!r}", "a number"
        ) from None
    if not np.isfinite(v) or (integer and (v != int(v) or not 0 < v < 2**31)):
        raise corrupt(
            name,
            f"main.xml {'/'.join(path)} is {t[:30]!r}",
            "a positive integer" if integer else "a finite number",
        )
    return int(v) if integer else v


@register_reader(
    "x3p",
    description="ISO 5436-2 / ISO 25178-72 XML 3D surface profile (.x3p)",
    suffixes=(".x3p",),
    magic=(b"PK\x03\x04",),
    sniff=_is_x3p,
)
def read_x3p(source: Source) -> Surface | Profile:
    """Read an ``.x3p`` file.

    Parameters
    ----------
    source : Source
        Loaded file.

    Returns
    -------
    Surface or Profile
        ``FeatureType SUR``: a Surface, heights in m (NaN where the validity map or
        a NaN marks an invalid point), ``dx``/``dy`` from the CX/CY increments in
        m, ``x0``/``y0`` from their offsets. ``FeatureType PRF`` (an ``N x 1 x 1``
        matrix): a Profile with step ``dx`` and start ``x0`` from CX, in m.

    Notes
    -----
    The MD5 checksums of the archive are not verified (as Gwyddion and
    SurfaceTopography, unlike the openGPS library and surfalize): a damaged
    member is caught by the size checks and the zip CRC instead.
    """
    name = source.name
    zf = open_zip(source.data, name, "an .x3p zip archive")
    with zf:
        if "main.xml" not in zf.namelist():
            raise corrupt(
                name, "archive has no main.xml", "an .x3p archive with main.xml"
            )
        info = zf.getinfo("main.xml")
        if info.file_size > _MAX_XML_BYTES:
            raise corrupt(
                name, f"main.xml has {info.file_size} bytes", "at most 256 MiB"
            )
        xml = zip_member(zf, "main.xml", name)
        if b"<!DOCTYPE" in xml or b"<!ENTITY" in xml:
            raise unsupported(name, "main.xml declares a DTD or entities", "plain XML")
        try:
            root = ET.fromstring(xml)
        except ET.ParseError as exc:
            raise corrupt(
                name, f"main.xml is not well-formed XML ({exc})", "valid XML"
            ) from None
        if _local(root.tag) != "ISO5436_2":
            raise corrupt(
                name, f"main.xml root element is {_local(root.tag)!r}", "ISO5436_2"
            )
        return _read_tree(zf, root, name)


def _read_tree(zf: zipfile.ZipFile, root: ET.Element, name: str) -> Surface | Profile:
    r1 = _child(root, "Record1")
    r3 = _child(root, "Record3")
    if r1 is None or r3 is None:
        raise corrupt(name, "main.xml lacks Record1 or Record3", "both records")
    feature = _text(r1, "FeatureType") or "SUR"
    if feature not in ("SUR", "PRF"):
        raise unsupported(
            name, f"FeatureType is {feature!r}", "SUR (surface) or PRF (profile)"
        )
    axes = _child(r1, "Axes")
    for ax in ("CX", "CY"):
        if _text(axes, ax, "AxisType") not in (None, "I"):
            raise unsupported(
                name,
                f"axis {ax} is of type {_text(axes, ax, 'AxisType')!r} (point list)",
                "incremental (I) x and y axes",
            )
    dx = check_pixel_size(
        _number(root, name, "Record1", "Axes", "CX", "Increment"),
        name,
        "CX/Increment",
        zero_means_uncalibrated=False,
    )
    dy_raw = _number(root, name, "Record1", "Axes", "CY", "Increment", default=0.0)
    nx = _number(root, name, "Record3", "MatrixDimension", "SizeX", integer=True)
    ny = _number(root, name, "Record3", "MatrixDimension", "SizeY", integer=True)
    nz = _number(
        root, name, "Record3", "MatrixDimension", "SizeZ", default=1, integer=True
    )
    if nz != 1:
        raise unsupported(name, f"SizeZ is {nz} (several layers)", "SizeZ = 1")
    if feature == "PRF" and ny != 1:
        raise corrupt(
            name,
            f"FeatureType is PRF but SizeY is {ny}",
            "SizeY = 1 (ISO 5436-2 profiles are N x 1 x M matrices)",
        )
    if ny == 1 and (dy_raw == 0.0 or feature == "PRF"):
        dy = dx  # profiles may leave CY/Increment unset; it carries no data
    else:
        dy = check_pixel_size(
            dy_raw, name, "CY/Increment", zero_means_uncalibrated=False
        )
    x0 = _number(root, name, "Record1", "Axes", "CX", "Offset", default=0.0)
    y0 = _number(root, name, "Record1", "Axes", "CY", "Offset", default=0.0)
    ztype = _text(axes, "CZ", "DataType") or "D"
    if ztype not in _DTYPES:
        raise corrupt(name, f"CZ/DataType is {ztype!r}", "I, L, F or D")
    zinc = _number(root, name, "Record1", "Axes", "CZ", "Increment", default=1.0)
    zoff = _number(root, name, "Record1", "Axes", "CZ", "Offset", default=0.0)
    n = nx * ny
    link = _child(r3, "DataLink")
    if link is not None:
        member = _text(link, "PointDataLink")
        if not member:
            raise corrupt(
                name, "DataLink has no PointDataLink", "the binary member name"
            )
        dtype = np.dtype(_DTYPES[ztype])
        raw = zip_member(zf, member, name, expected_size=n * dtype.itemsize)
        values = np.frombuffer(raw, dtype=dtype).astype(np.float64)
        invalid = ~np.isfinite(values)
        vmember = _text(link, "ValidPointsLink")
        if vmember:
            bits = zip_member(zf, vmember, name)
            if len(bits) < (n + 7) // 8:
                raise corrupt(
                    name,
                    f"{vmember} has {len(bits)} bytes",
                    f"{(n + 7) // 8} bytes (one bit per point)",
                )
            valid = np.unpackbits(
                np.frombuffer(bits, dtype=np.uint8), count=n, bitorder="little"
            ).astype(bool)
            invalid |= ~valid
    else:
        values, invalid = _data_list(r3, n, name)
    z = values * zinc + zoff
    z[invalid] = np.nan
    z = z.reshape(ny, nx)
    md = _metadata(root)
    md["source_format"] = "x3p"
    md["x3p"] = {"feature_type": feature, "z_data_type": ztype}
    surface = make_surface(z, dx, dy, md, name, x0=x0, y0=y0)
    if feature != "PRF":
        return surface
    if nx < 2:
        raise corrupt(name, f"profile has {nx} point", "at least 2 points")
    md = dict(surface.metadata)
    md["kind"] = "profile"
    return Profile(surface.z[0], dx, metadata=md, x0=x0)


def _data_list(r3: ET.Element, n: int, name: str) -> tuple[np.ndarray, np.ndarray]:
    dl = _child(r3, "DataList")
    if dl is None:
        raise corrupt(name, "Record3 has neither DataLink nor DataList", "one of them")
    datums = [c for c in dl if _local(c.tag) == "Datum"]
    if len(datums) != n:
        raise corrupt(
            name, f"DataList has {len(datums)} Datum elements", f"{n} (SizeX*SizeY)"
        )
    values = np.full(n, np.nan)
    for i, d in enumerate(datums):
        t = (d.text or "").strip()
        if not t:
            continue
        if ";" in t:  # x;y;z triplets: only z matters for matrix data
            t = t.rsplit(";", 1)[-1].strip()
            if not t:
                continue
        try:
            values[i] = float(t)
        except ValueError:
            raise corrupt(
                name, f"Datum {i} is {t[:30]!r}", "a number or empty"
            ) from None
    return values, ~np.isfinite(values)


def _metadata(root: ET.Element) -> dict[str, Any]:
    md: dict[str, Any] = {}
    r2 = _child(root, "Record2")
    if r2 is None:
        return md
    date = _text(r2, "Date")
    stamp = timestamp_from_iso(date)
    if date and (stamp is None or iso_date(stamp) is not None):
        md["date"] = date  # dates before 1980 are placeholders (MountainsMap: 1970)
    maker = _text(r2, "Instrument", "Manufacturer")
    model = _text(r2, "Instrument", "Model")
    inst = " ".join(
        v for v in (maker, model) if v and v.lower() not in ("unknown", "not available")
    )
    if inst:
        md["instrument"] = inst
    for key, path in (
        ("serial", ("Instrument", "Serial")),
        ("software", ("Instrument", "Version")),
        ("creator", ("Creator",)),
        ("probing_system", ("ProbingSystem", "Type")),
        ("objective", ("ProbingSystem", "Identification")),
    ):
        v = _text(r2, *path)
        if v and v.lower() not in ("unknown", "not available"):
            md[key] = v
    comment = _text(r2, "Comment")
    extra = parse_metadata_json(comment) if comment else None
    if extra is not None:
        md.update(extra)
    elif comment:
        md["comment"] = comment
    return md


def _sub(parent: ET.Element, tag: str, text: str | None = None) -> ET.Element:
    e = ET.SubElement(parent, tag)
    if text is not None:
        e.text = text
    return e


@register_writer(
    "x3p",
    description="ISO 5436-2 / ISO 25178-72 (.x3p), float64 heights",
    suffixes=(".x3p",),
    profiles=True,
)
def encode_x3p(surface: Surface | Profile) -> bytes:
    """Encode a surface (``FeatureType SUR``) or a profile (``PRF``) as ``.x3p``.

    Heights are stored as float64 in m (exact), invalid pixels as NaN plus a
    validity bit map; metadata goes to Record2 (date, instrument) and, as JSON, to
    ``Record2/Comment``. A :class:`Profile` is written as a profile, as ISO
    5436-2 defines it: ``FeatureType PRF``, a matrix of ``N x 1 x 1`` points along
    the incremental CX axis (the schema still requires a CY axis: it is written
    incremental with the profile step, offset 0, and carries no data).

    The archive is reproducible: the MD5 checksums (``md5checksum.hex`` and the
    ``MD5Checksum*`` elements of ``main.xml``) are lower-case hexadecimal as the
    openGPS reference files and instrument software write them (surfalize compares
    them case-sensitively), and every zip member carries the fixed time stamp
    :data:`~servosurf.io._common.ZIP_DATE_TIME`, so the same data give the same
    bytes.

    Parameters
    ----------
    surface : Surface or Profile
        Heights in m with pixel sizes (profile step) in m.

    Returns
    -------
    bytes
        The zip archive.

    Raises
    ------
    FileFormatError
        When the surface is uncalibrated (x3p needs increments in m).
    """
    if isinstance(surface, Profile):
        feature = "PRF"
        z = np.ascontiguousarray(surface.z[None, :], dtype="<f8")
        steps = ((surface.dx, surface.x0), (surface.dx, 0.0))
    else:
        if not surface.calibrated:
            raise writer_error(
                "x3p",
                "the surface is laterally uncalibrated (no pixel size)",
                "x3p needs pixel sizes in m; write it as .datx, .dat or .npz",
            )
        feature = "SUR"
        z = np.ascontiguousarray(surface.z, dtype="<f8")
        steps = ((surface.dx, surface.x0), (surface.dy, surface.y0))
    ny, nx = z.shape
    md = surface.metadata
    valid = np.isfinite(z)
    data = z.tobytes()
    xsi = "http://www.w3.org/2001/XMLSchema-instance"
    root = ET.Element(
        "p:ISO5436_2",
        {
            "xmlns:p": NS,
            "xmlns:xsi": xsi,
            "xsi:schemaLocation": f"{NS} {NS}/ISO5436_2.xsd",
        },
    )
    r1 = _sub(root, "Record1")
    _sub(r1, "Revision", "ISO5436 - 2000")
    _sub(r1, "FeatureType", feature)
    axes = _sub(r1, "Axes")
    for ax, (inc, off) in zip(("CX", "CY"), steps, strict=True):
        e = _sub(axes, ax)
        _sub(e, "AxisType", "I")
        _sub(e, "DataType", "D")
        _sub(e, "Increment", repr(float(inc)))  # type: ignore[arg-type]
        _sub(e, "Offset", repr(float(off)))
    cz = _sub(axes, "CZ")
    _sub(cz, "AxisType", "A")
    _sub(cz, "DataType", "D")
    r2 = _sub(root, "Record2")
    date = md.get("date") if isinstance(md.get("date"), str) else "1970-01-01T00:00:00"
    _sub(r2, "Date", date)
    inst = _sub(r2, "Instrument")
    # The file is made by servosurf: Manufacturer and Version say so; the model
    # and objective of a measured map (if any) are kept, "not available" else.
    _sub(inst, "Manufacturer", "servosurf")
    _sub(inst, "Model", str(md.get("instrument", _NA)))
    _sub(inst, "Serial", str(md.get("serial", _NA)))
    _sub(inst, "Version", f"servosurf {__version__}")
    _sub(r2, "CalibrationDate", date)
    probe = _sub(r2, "ProbingSystem")
    _sub(probe, "Type", "Software")
    _sub(probe, "Identification", str(md.get("objective", _NA)))
    skip = ("source_format", "x3p") + (("kind",) if feature == "PRF" else ())
    _sub(r2, "Comment", metadata_json(md, exclude=skip))
    r3 = _sub(root, "Record3")
    dims = _sub(r3, "MatrixDimension")
    _sub(dims, "SizeX", str(nx))
    _sub(dims, "SizeY", str(ny))
    _sub(dims, "SizeZ", "1")
    link = _sub(r3, "DataLink")
    _sub(link, "PointDataLink", "bindata/data.bin")
    _sub(link, "MD5ChecksumPointData", hashlib.md5(data).hexdigest())
    members = {"bindata/data.bin": data}
    if not valid.all():
        bits = np.packbits(valid.ravel(), bitorder="little").tobytes()
        _sub(link, "ValidPointsLink", "bindata/valid.bin")
        _sub(link, "MD5ChecksumValidPoints", hashlib.md5(bits).hexdigest())
        members["bindata/valid.bin"] = bits
    r4 = _sub(root, "Record4")
    _sub(r4, "ChecksumFile", "md5checksum.hex")
    ET.indent(root)
    xml = (
        b'<?xml version="1.0" encoding="UTF-8" standalone="no" ?>\n'
        + ET.tostring(root, encoding="utf-8", xml_declaration=False)
        + b"\n"
    )
    checksum = f"{hashlib.md5(xml).hexdigest()} *main.xml\n".encode("ascii")
    return zip_archive(
        {"main.xml": xml, "md5checksum.hex": checksum, **members}, compress=True
    )
