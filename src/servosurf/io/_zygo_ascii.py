"""ZYGO MetroPro ASCII data files (``.asc``, "Zygo ASCII Data File - Format 2").

The text header mirrors the binary ``.dat`` header, one group of fields per line
(MetroPro Reference Guide, "ASCII Data File Format")::

    Zygo ASCII Data File - Format 2
    SoftwareType MajorVers MinorVers BugVers "SoftwareDate"
    IntensOriginX IntensOriginY IntensWidth IntensHeight NBuckets IntensRange
    PhaseOriginX PhaseOriginY PhaseWidth PhaseHeight
    "Comment"
    "PartSerNum"
    "PartNum"
    Source IntfScaleFactor WavelengthIn NumericAperture ObliquityFactor
        Magnification CameraRes TimeStamp
    CameraWidth CameraHeight SystemType SystemBoard SystemSerial InstrumentId
        "ObjectiveName"
    AcquireMode IntensAvgs PZTCal PZTGain PZTGainTolerance AGC TargetRange
        LightLevel MinMod MinModPts
    PhaseRes PhaseAvgs MinimumAreaSize DisconAction DisconFilter ConnectionOrder
        RemoveTiltBias DataSign CodeVType
    SubtractSysErr "SysErrFile"
    RefractiveIndex PartThickness
    "ZoomDesc"
    #
    <intensity counts> #
    <phase integers> #

Heights use the same rule as ``.dat`` (raw * IntfScaleFactor * ObliquityFactor *
WavelengthIn / R, R from PhaseRes, negated when DataSign is set; raw >= 2147483640
is no data). The ZYGO XYZ format shares this header (see ``_zygo_xyz``).
"""

from __future__ import annotations

import re
from typing import Any

import numpy as np

from ..metrology import Surface
from ._common import (
    Source,
    check_pixel_size,
    corrupt,
    decode_text,
    iso_date,
    make_surface,
    parse_metadata_json,
    written_by_servosurf,
)
from ._metropro_dat import NO_DATA, PHASE_RES
from ._registry import register_reader

__all__ = ["read_zygo_ascii", "parse_ascii_header", "split_ascii"]

ASCII_MAGIC = b"Zygo ASCII Data File"

_TOKEN = re.compile(r'"[^"\n]*"|\S+')

# (line index after the title line, field names); a name starting with "$" is a
# quoted string, others are numbers.
_LINES: tuple[tuple[str, ...], ...] = (
    (
        "swinfo_type",
        "swinfo_vers_maj",
        "swinfo_vers_min",
        "swinfo_vers_bug",
        "$swinfo_date",
    ),
    ("ac_org_x", "ac_org_y", "ac_width", "ac_height", "ac_n_buckets", "ac_range"),
    ("cn_org_x", "cn_org_y", "cn_width", "cn_height"),
    ("$comment",),
    ("$part_ser_num",),
    ("$part_name",),
    (
        "source",
        "intf_scale_factor",
        "wavelength_in",
        "num_aperture",
        "obliquity_factor",
        "magnification",
        "lateral_res",
        "time_stamp",
    ),
    (
        "camera_width",
        "camera_height",
        "sys_type",
        "sys_board",
        "sys_serial",
        "inst_id",
        "$obj_name",
    ),
    (
        "acq_type",
        "intens_avg_cnt",
        "pzt_cal",
        "pzt_gain",
        "pzt_gain_tol",
        "agc",
        "target_range",
        "light_level",
        "min_mod",
        "min_mod_count",
    ),
    (
        "phase_res",
        "phase_avg_cnt",
        "min_area",
        "discon_action",
        "discon_filter",
        "connect_order",
        "rem_tilt_bias",
        "sign",
        "codev_type",
    ),
    ("sub_sys_err", "$sys_err_file_name"),
    ("refractive_index", "part_thickness"),
    ("$zoom_descr",),
)
_INT_FIELDS = {
    "ac_org_x",
    "ac_org_y",
    "ac_width",
    "ac_height",
    "ac_n_buckets",
    "cn_org_x",
    "cn_org_y",
    "cn_width",
    "cn_height",
    "phase_res",
    "sign",
    "time_stamp",
    "swinfo_type",
    "swinfo_vers_maj",
    "swinfo_vers_min",
    "swinfo_vers_bug",
    "camera_width",
    "camera_height",
}
_MAX_DIM = 1 << 16


def split_ascii(text: str) -> tuple[list[str], list[str]]:
    """Split a ZYGO text file into header lines and data blocks.

    Parameters
    ----------
    text : str
        Whole file.

    Returns
    -------
    (list of str, list of str)
        Header lines (title first, without the ``#`` line) and the text of each
        block between ``#`` separator lines.
    """
    lines = text.splitlines()
    seps = [i for i, ln in enumerate(lines) if ln.strip() == "#"]
    if not seps:
        return lines, []
    header = lines[: seps[0]]
    blocks = []
    bounds = [*seps, len(lines)]
    for a, b in zip(bounds[:-1], bounds[1:], strict=True):
        blocks.append("\n".join(lines[a + 1 : b]))
    return header, blocks


def parse_ascii_header(
    header: list[str], name: str, *, required_lines: int
) -> dict[str, Any]:
    """Parse the MetroPro text header shared by the ASCII and XYZ formats.

    Parameters
    ----------
    header : list of str
        Lines before the first ``#``, the title line first.
    name : str
        File name for messages.
    required_lines : int
        Number of lines after the title that must be present.

    Returns
    -------
    dict
        Field values; missing optional fields are absent.

    Raises
    ------
    CorruptedFileError
        A required line is missing or a number cannot be parsed.
    """
    body = header[1:]
    if len(body) < required_lines:
        raise corrupt(
            name,
            f"header has {len(body)} lines after the title",
            f"at least {required_lines} (MetroPro text header)",
        )
    h: dict[str, Any] = {}
    for i, fields in enumerate(_LINES):
        if i >= len(body):
            break
        tokens = _TOKEN.findall(body[i])
        if (
            i < required_lines
            and len(tokens) < len(fields)
            and not fields[0].startswith("$")
        ):
            raise corrupt(
                name,
                f"header line {i + 2} has {len(tokens)} fields ({body[i][:60]!r})",
                f"{len(fields)} fields ({' '.join(f.lstrip('$') for f in fields)})",
            )
        for field, tok in zip(fields, tokens, strict=False):
            if field.startswith("$"):
                h[field[1:]] = tok.strip('"').strip()
                continue
            try:
                v = float(tok)
            except ValueError:
                raise corrupt(
                    name,
                    f"header line {i + 2} field {field} is {tok[:30]!r}",
                    "a number",
                ) from None
            if field in _INT_FIELDS:
                if not np.isfinite(v) or v != int(v) or abs(v) > 2**31:
                    raise corrupt(
                        name, f"header field {field} is {tok[:30]!r}", "an integer"
                    )
                v = int(v)
            h[field] = v
    for field in ("ac_width", "ac_height", "ac_n_buckets", "cn_width", "cn_height"):
        v = h.get(field, 0)
        if not 0 <= v < _MAX_DIM:
            raise corrupt(name, f"header field {field} is {v}", f"0..{_MAX_DIM - 1}")
    return h


def header_metadata(h: dict[str, Any]) -> dict[str, Any]:
    """Return the common metadata of a parsed text header.

    ``instrument`` is ``"ZYGO"`` unless the software date field names servosurf
    (a file servosurf wrote), whose ``software`` is that field.
    """
    sw_date = h.get("swinfo_date")
    own = written_by_servosurf(sw_date)
    md: dict[str, Any] = {"software": sw_date} if own else {"instrument": "ZYGO"}
    if h.get("obj_name"):
        md["objective"] = h["obj_name"]
    if h.get("zoom_descr"):
        md["zoom"] = h["zoom_descr"]
    wl = h.get("wavelength_in")
    if isinstance(wl, float) and np.isfinite(wl) and wl > 0:
        md["wavelength"] = wl
    date = iso_date(h.get("time_stamp", 0))
    if date:
        md["date"] = date
    if h.get("swinfo_type") == 1 and not own:
        md["software"] = (
            f"MetroPro {h.get('swinfo_vers_maj', 0)}.{h.get('swinfo_vers_min', 0)}."
            f"{h.get('swinfo_vers_bug', 0)}"
        )
    comment = h.get("comment", "")
    extra = parse_metadata_json(comment) if comment else None
    if extra is not None:
        for k, v in extra.items():
            md.setdefault(k, v)
    elif comment:
        md["comment"] = comment
    md["metropro"] = {
        k: h[k]
        for k in (
            "phase_res",
            "sign",
            "intf_scale_factor",
            "obliquity_factor",
            "lateral_res",
            "camera_width",
            "camera_height",
            "cn_org_x",
            "cn_org_y",
            "part_name",
            "part_ser_num",
            "time_stamp",
        )
        if k in h
    }
    return md


def _ints(block: str, count: int, name: str, what: str) -> np.ndarray:
    tokens = block.split()
    if len(tokens) != count:
        raise corrupt(
            name, f"{what} block has {len(tokens)} values", f"{count} (from the header)"
        )
    if count == 0:
        return np.zeros(0, dtype=np.int64)
    try:
        return np.array(tokens, dtype=np.int64)
    except (ValueError, OverflowError):
        bad = next((t for t in tokens if not t.lstrip("+-").isdigit()), tokens[0])
        raise corrupt(name, f"{what} block holds {bad[:30]!r}", "integers") from None


@register_reader(
    "zygo_ascii",
    description="ZYGO MetroPro ASCII data (.asc)",
    suffixes=(".asc",),
    magic=(ASCII_MAGIC,),
)
def read_zygo_ascii(source: Source) -> Surface:
    """Read a MetroPro ASCII (``.asc``) file.

    Parameters
    ----------
    source : Source
        Loaded file.

    Returns
    -------
    Surface
        Heights in m (NaN for no-data), pixel size from CameraRes in m (None when 0).
    """
    name = source.name
    if not source.data.startswith(ASCII_MAGIC):
        raise corrupt(
            name, f"file starts with {source.data[:24]!r}", f"{ASCII_MAGIC.decode()!r}"
        )
    header, blocks = split_ascii(decode_text(source.data))
    h = parse_ascii_header(header, name, required_lines=10)
    if len(blocks) < 2:
        raise corrupt(
            name,
            f"file has {len(blocks)} '#'-separated data block(s)",
            "an intensity block and a phase block",
        )
    nx, ny = h["cn_width"], h["cn_height"]
    if nx == 0 or ny == 0:
        raise corrupt(name, f"phase window is {nx}x{ny}", "a non-empty phase array")
    n_int = h["ac_width"] * h["ac_height"] * h["ac_n_buckets"]
    _ints(blocks[0], n_int, name, "intensity")
    raw = _ints(blocks[1], nx * ny, name, "phase").reshape(ny, nx)
    pr = h.get("phase_res")
    if pr not in PHASE_RES:
        raise corrupt(name, f"PhaseRes is {pr}", "0, 1 or 2")
    for field in ("wavelength_in", "intf_scale_factor", "obliquity_factor"):
        v = h.get(field)
        if v is None or not np.isfinite(v) or v <= 0:
            raise corrupt(name, f"{field} is {v!r}", "a positive finite number")
    scale = (
        h["intf_scale_factor"]
        * h["obliquity_factor"]
        * h["wavelength_in"]
        / PHASE_RES[pr]
    )
    if h.get("sign"):
        scale = -scale
    z = raw.astype(np.float64) * scale
    z[raw >= NO_DATA] = np.nan
    dx = check_pixel_size(
        h.get("lateral_res", 0.0), name, "CameraRes", zero_means_uncalibrated=True
    )
    md = header_metadata(h)
    md["source_format"] = "zygo_ascii"
    x0 = h["cn_org_x"] * dx if dx else 0.0
    y0 = h["cn_org_y"] * dx if dx else 0.0
    return make_surface(z, dx, dx, md, name, x0=x0, y0=y0)
