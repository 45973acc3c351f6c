"""ZYGO MetroPro binary ``.dat`` files (header formats 1, 2 and 3).

Layout (MetroPro Reference Guide, "Data Format"): a fixed header (834 bytes for
formats 1 and 2, 4096 bytes for format 3), then ``ac_n_bytes`` of intensity data
(``uint16``, ``ac_n_buckets`` frames of ``ac_height x ac_width``), then
``cn_n_bytes`` of connected phase data (``int32``, ``cn_height x cn_width`` rows from
the top). Everything is big-endian except a block of fields after byte 502 that
MetroPro stores little-endian. Heights are

    height = raw * intf_scale_factor * obliquity_factor * wavelength_in / R

with R = 4096, 32768, 131072 for ``phase_res`` = 0, 1, 2, negated when ``sign`` is
non-zero; raw values >= 2147483640 mean "no data". ``lateral_res`` (m per pixel) of
0 means the lateral scale is uncalibrated. The phase array may cover a sub-window of
the camera starting at (``cn_org_x``, ``cn_org_y``).
"""

from __future__ import annotations

import struct
from typing import Any

import numpy as np

from ..metrology import Surface
from ._common import (
    Source,
    check_pixel_size,
    corrupt,
    iso_date,
    make_surface,
    metadata_json,
    parse_metadata_json,
    pixel_origin,
    software_label,
    software_version_numbers,
    timestamp_from_iso,
    writer_error,
    written_by_servosurf,
)
from ._registry import register_reader, register_writer

__all__ = ["read_metropro_dat", "encode_metropro_dat"]

MAGIC = {1: 0x881B036F, 2: 0x881B0370, 3: 0x881B0371}
HEADER_SIZE = {1: 834, 2: 834, 3: 4096}
PHASE_RES = {0: 4096, 1: 32768, 2: 131072}
NO_DATA = 2147483640  # raw values >= this are invalid

# (name, offset, struct format) -- big-endian unless the format says "<".
_FIELDS: tuple[tuple[str, int, str], ...] = (
    ("magic", 0, ">I"),
    ("header_format", 4, ">H"),
    ("header_size", 6, ">I"),
    ("swinfo_type", 10, ">h"),
    ("swinfo_date", 12, "30s"),
    ("swinfo_vers_maj", 42, ">h"),
    ("swinfo_vers_min", 44, ">h"),
    ("swinfo_vers_bug", 46, ">h"),
    ("ac_org_x", 48, ">h"),
    ("ac_org_y", 50, ">h"),
    ("ac_width", 52, ">H"),
    ("ac_height", 54, ">H"),
    ("ac_n_buckets", 56, ">H"),
    ("ac_range", 58, ">h"),
    ("ac_n_bytes", 60, ">I"),
    ("cn_org_x", 64, ">h"),
    ("cn_org_y", 66, ">h"),
    ("cn_width", 68, ">H"),
    ("cn_height", 70, ">H"),
    ("cn_n_bytes", 72, ">I"),
    ("time_stamp", 76, ">i"),
    ("comment", 80, "82s"),
    ("source", 162, ">h"),
    ("intf_scale_factor", 164, ">f"),
    ("wavelength_in", 168, ">f"),
    ("num_aperture", 172, ">f"),
    ("obliquity_factor", 176, ">f"),
    ("magnification", 180, ">f"),
    ("lateral_res", 184, ">f"),
    ("acq_type", 188, ">h"),
    ("phase_res", 218, ">h"),
    ("sign", 232, ">h"),
    ("camera_width", 234, ">h"),
    ("camera_height", 236, ">h"),
    ("sys_type", 238, ">h"),
    ("sys_board", 240, ">h"),
    ("sys_serial", 242, ">H"),
    ("inst_id", 244, ">h"),
    ("obj_name", 246, "12s"),
    ("part_name", 258, "40s"),
    ("phase_avg_cnt", 300, ">h"),
    ("part_ser_num", 320, "40s"),
    ("refractive_index", 360, ">f"),
    ("wavelen_select", 398, "8s"),
    ("pixel_width", 486, ">f"),
    ("pixel_height", 490, ">f"),
    ("zoom_descr", 562, "8s"),
    ("sys_serial2", 798, "<i"),
)
_FIXED_PART = 834  # all fields above live in the first 834 bytes

_SOFTWARE = {1: "MetroPro", 2: "MetroBASIC", 3: "d2bug"}

#: Metadata keys the header stores in its own fields (not repeated in the comment).
_NATIVE_KEYS = (
    "wavelength",
    "objective",
    "date",
    "magnification",
    "numerical_aperture",
    "source_format",
    "metropro",
    "software",
    "comment",
    "zoom",
    "serial",
)


def _text(raw: bytes) -> str:
    return raw.split(b"\0", 1)[0].decode("latin-1").strip()


def parse_header(data: bytes, name: str) -> dict[str, Any]:
    """Parse and validate a MetroPro header against the buffer length.

    Parameters
    ----------
    data : bytes
        Whole file.
    name : str
        File name for messages.

    Returns
    -------
    dict
        Field values (strings decoded, floats as Python floats).

    Raises
    ------
    CorruptedFileError
        Wrong magic, inconsistent header format/size, inconsistent data sizes or a
        file shorter than the header announces.
    """
    magics = ", ".join(f"0x{m:08X}" for m in MAGIC.values())
    if len(data) < 4:
        raise corrupt(
            name,
            f"file has only {len(data)} bytes",
            f"a MetroPro magic number ({magics})",
        )
    (magic,) = struct.unpack_from(">I", data, 0)
    fmt_by_magic = {v: k for k, v in MAGIC.items()}
    if magic not in fmt_by_magic:
        raise corrupt(
            name, f"magic number is 0x{magic:08X}", f"a MetroPro .dat magic ({magics})"
        )
    if len(data) < _FIXED_PART:
        raise corrupt(
            name,
            f"file ends at byte {len(data)} inside the MetroPro header",
            f"at least {_FIXED_PART} header bytes",
        )
    h: dict[str, Any] = {}
    for field, off, fmt in _FIELDS:
        (v,) = struct.unpack_from(fmt, data, off)
        h[field] = _text(v) if isinstance(v, bytes) else v
    hf = fmt_by_magic[magic]
    if h["header_format"] != hf:
        raise corrupt(
            name,
            f"header_format is {h['header_format']} but the magic number is that "
            f"of format {hf}",
            f"header_format {hf}",
        )
    if h["header_size"] != HEADER_SIZE[hf]:
        raise corrupt(
            name,
            f"header_size is {h['header_size']} bytes for header format {hf}",
            f"{HEADER_SIZE[hf]} bytes",
        )
    n_int = 2 * h["ac_width"] * h["ac_height"] * h["ac_n_buckets"]
    if h["ac_n_bytes"] != n_int:
        raise corrupt(
            name,
            f"ac_n_bytes is {h['ac_n_bytes']} for {h['ac_n_buckets']} intensity "
            f"frame(s) of {h['ac_width']}x{h['ac_height']}",
            f"2*width*height*buckets = {n_int}",
        )
    if h["cn_width"] == 0 or h["cn_height"] == 0:
        raise corrupt(
            name,
            f"phase window is {h['cn_width']}x{h['cn_height']} pixels",
            "a non-empty connected phase array",
        )
    n_phase = 4 * h["cn_width"] * h["cn_height"]
    if h["cn_n_bytes"] != n_phase:
        raise corrupt(
            name,
            f"cn_n_bytes is {h['cn_n_bytes']} for a "
            f"{h['cn_width']}x{h['cn_height']} phase window",
            f"4*width*height = {n_phase}",
        )
    need = h["header_size"] + h["ac_n_bytes"] + h["cn_n_bytes"]
    if len(data) < need:
        raise corrupt(
            name,
            f"file is truncated: {len(data)} bytes, but header ({h['header_size']}) + "
            f"intensity ({h['ac_n_bytes']}) + phase ({h['cn_n_bytes']}) need {need}",
            f"at least {need} bytes",
        )
    if h["phase_res"] not in PHASE_RES:
        raise corrupt(name, f"phase_res is {h['phase_res']}", "0, 1 or 2")
    for field in ("wavelength_in", "intf_scale_factor", "obliquity_factor"):
        v = h[field]
        if not np.isfinite(v) or v <= 0:
            raise corrupt(name, f"{field} is {v!r}", "a positive finite number")
    return h


def _metadata(h: dict[str, Any]) -> dict[str, Any]:
    own = written_by_servosurf(h["swinfo_date"])
    # A file servosurf wrote names servosurf in its software field (swinfo_date)
    # and comes from no ZYGO instrument; any other .dat is ZYGO's.
    md: dict[str, Any] = (
        {"software": h["swinfo_date"]} if own else {"instrument": "ZYGO"}
    )
    serial = h["sys_serial2"] if h["sys_serial2"] > 0 else h["sys_serial"]
    if serial:
        md["serial"] = str(serial)
    if h["obj_name"]:
        md["objective"] = h["obj_name"]
    if h["zoom_descr"]:
        md["zoom"] = h["zoom_descr"]
    md["wavelength"] = float(h["wavelength_in"])
    if h["num_aperture"] > 0:
        md["numerical_aperture"] = float(h["num_aperture"])
    if h["magnification"] > 0:
        md["magnification"] = float(h["magnification"])
    date = iso_date(h["time_stamp"])
    if date:
        md["date"] = date
    sw = _SOFTWARE.get(h["swinfo_type"])
    version = f"{h['swinfo_vers_maj']}.{h['swinfo_vers_min']}.{h['swinfo_vers_bug']}"
    if sw and not own:
        md["software"] = f"{sw} {version}"
    extra = parse_metadata_json(h["comment"])
    if extra is not None:
        for k, v in extra.items():
            md.setdefault(k, v)
    elif h["comment"]:
        md["comment"] = h["comment"]
    md["metropro"] = {
        "header_format": h["header_format"],
        "software_version": version,
        "software_date": h["swinfo_date"],
        "phase_res": h["phase_res"],
        "sign": h["sign"],
        "intf_scale_factor": float(h["intf_scale_factor"]),
        "obliquity_factor": float(h["obliquity_factor"]),
        "lateral_res": float(h["lateral_res"]),
        "camera_size": [h["camera_width"], h["camera_height"]],
        "phase_origin": [h["cn_org_x"], h["cn_org_y"]],
        "intensity": (
            {
                "buckets": h["ac_n_buckets"],
                "size": [h["ac_width"], h["ac_height"]],
                "origin": [h["ac_org_x"], h["ac_org_y"]],
                "range": h["ac_range"],
            }
            if h["ac_n_bytes"]
            else None
        ),
        "sys_type": h["sys_type"],
        "part_name": h["part_name"],
        "part_serial": h["part_ser_num"],
        "acq_type": h["acq_type"],
        "time_stamp": h["time_stamp"],
    }
    return md


@register_reader(
    "metropro_dat",
    description="ZYGO MetroPro binary data (.dat), header formats 1-3",
    suffixes=(".dat",),
    magic=tuple(struct.pack(">I", m) for m in MAGIC.values()),
)
def read_metropro_dat(source: Source) -> Surface:
    """Read a MetroPro ``.dat`` file.

    Parameters
    ----------
    source : Source
        Loaded file.

    Returns
    -------
    Surface
        Heights in m (NaN for no-data), ``dx = dy = lateral_res`` in m or None when
        ``lateral_res`` is 0. ``x0, y0`` locate the phase window on the camera, in m
        (0 when uncalibrated). ``metadata["instrument"]`` is ``"ZYGO"`` unless the
        software field names servosurf (a file servosurf wrote).
    """
    h = parse_header(source.data, source.name)
    start = h["header_size"] + h["ac_n_bytes"]
    ny, nx = h["cn_height"], h["cn_width"]
    raw = np.frombuffer(source.data, dtype=">i4", count=nx * ny, offset=start).reshape(
        ny, nx
    )
    scale = (
        float(h["intf_scale_factor"])
        * float(h["obliquity_factor"])
        * float(h["wavelength_in"])
        / PHASE_RES[h["phase_res"]]
    )
    if h["sign"]:
        scale = -scale
    z = raw.astype(np.float64) * scale
    z[raw >= NO_DATA] = np.nan
    dx = check_pixel_size(
        h["lateral_res"], source.name, "lateral_res", zero_means_uncalibrated=True
    )
    md = _metadata(h)
    md["source_format"] = "metropro_dat"
    org = (h["cn_org_x"] * dx, h["cn_org_y"] * dx) if dx else (0.0, 0.0)
    return make_surface(z, dx, dx, md, source.name, x0=org[0], y0=org[1])


def _put_text(buf: bytearray, offset: int, size: int, text: str) -> None:
    raw = text.encode("utf-8")[: size - 1]
    while raw:  # do not cut a multi-byte character in half
        try:
            raw.decode("utf-8")
            break
        except UnicodeDecodeError:
            raw = raw[:-1]
    buf[offset : offset + len(raw)] = raw


@register_writer(
    "metropro_dat",
    description="ZYGO MetroPro binary data (.dat), header format 1 by default",
    suffixes=(".dat",),
)
def encode_metropro_dat(
    surface: Surface,
    *,
    header_format: int = 1,
    phase_res: int = 1,
    sign: bool = False,
    wavelength: float | None = None,
    intf_scale_factor: float = 0.5,
    obliquity_factor: float = 1.0,
    camera_size: tuple[int, int] | None = None,
    phase_origin: tuple[int, int] | None = None,
    intensity: np.ndarray | None = None,
) -> bytes:
    """Encode a surface as a MetroPro ``.dat`` file.

    Heights are quantised to ``intf_scale_factor * obliquity_factor * wavelength /
    R`` (about 9.7 pm with the defaults), the resolution of the format. The file
    is labelled as servosurf's, not as a ZYGO instrument's: ``swinfo_type`` 0,
    ``swinfo_date`` = ``"servosurf <version>"``, the version in ``swinfo_vers``,
    no system type or serial number. The same surface gives the same bytes (the
    time stamp comes from ``metadata["date"]``, 0 without one).

    Parameters
    ----------
    surface : Surface
        Heights in m; ``dx`` must equal ``dy`` (one ``lateral_res`` field).
    header_format : {1, 2, 3}, default: 1
        Header format (834-byte header for 1 and 2, 4096 bytes for 3).
    phase_res : {0, 1, 2}, default: 1
        Phase resolution code (R = 4096, 32768, 131072).
    sign : bool, default: False
        Store negated phase and set the ``sign`` field (readers negate back).
    wavelength : float, optional
        Wavelength in m; default ``metadata["wavelength"]`` or 632.8e-9.
    intf_scale_factor : float, default: 0.5
        Interferometric scale factor (0.5 for a reflection measurement).
    obliquity_factor : float, default: 1.0
        Obliquity factor.
    camera_size : (int, int), optional
        Camera (width, height) in pixels; default just holds the phase window.
    phase_origin : (int, int), optional
        Camera pixel (x, y) of the top-left corner of the phase window; default
        ``(x0 / dx, y0 / dy)`` when those are whole pixels, else (0, 0).
    intensity : ndarray of shape (h, w) or (buckets, h, w), optional
        Intensity frames (uint16 counts) stored before the phase data.

    Returns
    -------
    bytes
        The file content.

    Raises
    ------
    FileFormatError
        Non-square pixels, heights outside the int32 phase range, or bad options.
    """
    if header_format not in MAGIC:
        raise writer_error(
            "metropro_dat", f"header_format is {header_format!r}", "use 1, 2 or 3"
        )
    if phase_res not in PHASE_RES:
        raise writer_error(
            "metropro_dat", f"phase_res is {phase_res!r}", "use 0, 1 or 2"
        )
    md = surface.metadata
    if wavelength is None:
        w = md.get("wavelength")
        wavelength = (
            float(w) if isinstance(w, int | float) and 0 < w < 1e-3 else 632.8e-9
        )
    f32 = np.float32
    wl, isf, obl = (
        float(f32(v)) for v in (wavelength, intf_scale_factor, obliquity_factor)
    )
    for label, v in (
        ("wavelength", wl),
        ("intf_scale_factor", isf),
        ("obliquity_factor", obl),
    ):
        if not np.isfinite(v) or v <= 0:
            raise writer_error(
                "metropro_dat", f"{label} is {v!r}", "use a positive number"
            )
    ny, nx = surface.shape
    if nx > 65535 or ny > 65535:
        raise writer_error(
            "metropro_dat", f"map is {ny}x{nx}", "at most 65535x65535 pixels"
        )
    if surface.calibrated:
        assert surface.dx is not None and surface.dy is not None
        if abs(surface.dx - surface.dy) > 1e-6 * max(surface.dx, surface.dy):
            raise writer_error(
                "metropro_dat",
                f"pixels are not square (dx={surface.dx!r} m, dy={surface.dy!r} m)",
                "MetroPro stores one lateral_res; use .x3p or .datx",
            )
        lateral_res = surface.dx
    else:
        lateral_res = 0.0
    q = isf * obl * wl / PHASE_RES[phase_res]  # metres per count
    z = surface.z
    valid = np.isfinite(z)
    raw = np.full(z.shape, NO_DATA, dtype=np.int64)
    counts = np.rint(z[valid] / q)
    if counts.size and np.abs(counts).max() >= NO_DATA:
        span = float(np.abs(z[valid]).max())
        raise writer_error(
            "metropro_dat",
            f"heights up to {span:.3g} m exceed the int32 phase range of "
            f"{NO_DATA * q:.3g} m at phase_res={phase_res}",
            "use a lower phase_res",
        )
    raw[valid] = -counts if sign else counts

    ox, oy = (
        pixel_origin(surface)
        if phase_origin is None
        else (int(v) for v in phase_origin)
    )
    cam_w, cam_h = camera_size if camera_size is not None else (ox + nx, oy + ny)
    if intensity is not None:
        inten = np.asarray(intensity)
        if inten.ndim == 2:
            inten = inten[None]
        if inten.ndim != 3:
            raise writer_error(
                "metropro_dat",
                f"intensity has shape {inten.shape}",
                "use (h, w) or (buckets, h, w)",
            )
        inten_bytes = np.clip(inten, 0, 65535).astype(">u2").tobytes()
        nb, ah, aw = inten.shape
    else:
        inten_bytes, nb, ah, aw = b"", 0, 0, 0

    hsize = HEADER_SIZE[header_format]
    hdr = bytearray(hsize)
    ts = timestamp_from_iso(md.get("date")) or 0

    def put(fmt: str, off: int, value: Any) -> None:
        try:
            struct.pack_into(fmt, hdr, off, value)
        except struct.error:
            field = next((f for f, o, _ in _FIELDS if o == off), f"byte {off}")
            raise writer_error(
                "metropro_dat",
                f"header field {field} cannot hold {value!r}",
                "check the phase window, camera size and origin",
            ) from None

    put(">I", 0, MAGIC[header_format])
    put(">H", 4, header_format)
    put(">I", 6, hsize)
    # Software: swinfo_type 0 (not MetroPro, MetroBASIC or d2bug) and the software
    # string "servosurf <version>" where MetroPro writes its build date; no
    # instrument type or serial number (sys_type, sys_serial stay 0).
    put(">h", 10, 0)
    _put_text(hdr, 12, 30, software_label())
    for off, v in zip((42, 44, 46), software_version_numbers(), strict=True):
        put(">h", off, v)
    put(">H", 52, aw)
    put(">H", 54, ah)
    put(">H", 56, nb)
    put(">h", 58, 255 if nb else 0)
    put(">I", 60, len(inten_bytes))
    put(">h", 64, ox)
    put(">h", 66, oy)
    put(">H", 68, nx)
    put(">H", 70, ny)
    put(">I", 72, 4 * nx * ny)
    put(">i", 76, ts if -(2**31) <= ts < 2**31 else 0)
    comment = md.get("comment") if isinstance(md.get("comment"), str) else None
    if comment is None:
        rest = metadata_json(md, exclude=_NATIVE_KEYS)
        comment = rest if rest != "{}" else ""
    _put_text(hdr, 80, 82, comment)
    put(">f", 164, isf)
    put(">f", 168, wl)
    na = md.get("numerical_aperture")
    put(">f", 172, float(na) if isinstance(na, int | float) else 0.0)
    put(">f", 176, obl)
    mag = md.get("magnification")
    put(">f", 180, float(mag) if isinstance(mag, int | float) else 0.0)
    put(">f", 184, lateral_res)
    put(">h", 218, phase_res)
    put(">h", 232, 1 if sign else 0)
    put(">h", 234, int(cam_w))
    put(">h", 236, int(cam_h))
    obj = md.get("objective")
    if isinstance(obj, str):
        _put_text(hdr, 246, 12, obj)
    put(">f", 360, 1.0)  # refractive index
    put(">f", 386, wl)  # wavelength_in_1
    zoom = md.get("zoom")
    if isinstance(zoom, str):
        _put_text(hdr, 562, 8, zoom)
    return bytes(hdr) + inten_bytes + raw.astype(">i4").tobytes()
