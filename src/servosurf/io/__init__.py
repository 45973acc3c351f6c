"""Interferometer and exchange file formats: read and write :class:`Surface` maps.

Readers (detected by magic bytes, then suffix):

============== ========= ===============================================
format         suffix    content
============== ========= ===============================================
metropro_dat   .dat      ZYGO MetroPro binary, header formats 1, 2, 3
zygo_ascii     .asc      ZYGO MetroPro ASCII ("Zygo ASCII Data File")
zygo_xyz       .xyz      ZYGO XYZ (pixel x, y, height in um / No Data)
datx           .datx     ZYGO Mx HDF5
x3p            .x3p      ISO 5436-2 / ISO 25178-72 (SUR map or PRF profile)
npz            .npz      servosurf NumPy archive
mx_profile_csv .csv      ZYGO Mx profile export (a :class:`Profile`)
formtracer     .dat      Mitutoyo Formtracer contour text (a :class:`Profile`)
============== ========= ===============================================

Writers: ``datx``, ``metropro_dat``, ``x3p``, ``zygo_xyz``, ``npz``. A
:class:`Profile` is written to ``.x3p`` as a profile (``FeatureType PRF``), to the
other formats as a one-row map. Written files are reproducible (the same surface
gives the same bytes: no time stamps, no random IDs) and name servosurf as their
software, never a ZYGO instrument.

MetroPro ``.dat`` and Formtracer ``.dat`` share a suffix and are told apart by
content (binary magic number against a text unit line).

Recordings of a machine (following error, FRFs, cuts; maps and profiles as NPZ or
any format above): :func:`read_recording` of a kind in :data:`RECORDING_KINDS`;
FRFs as ``frequency_hz,real,imag`` CSV with :func:`read_frf_csv` /
:func:`write_frf_csv`.

All heights and pixel sizes are in metres; invalid pixels are NaN; row 0 is the top
of the map as the instrument shows it.
"""

from __future__ import annotations

# Importing the format modules registers their readers and writers.
from . import _datx, _metropro_dat, _mx_profile_csv, _npz, _x3p, _zygo_ascii, _zygo_xyz  # noqa: F401

# isort: split
# Formtracer registers after MetroPro: a .dat file that neither content check
# recognises falls back on the first reader of its suffix, the binary format.
from . import _formtracer  # noqa: F401
from ._common import decode_text, load_source
from ._recordings import RECORDING_KINDS, read_frf_csv, read_recording, write_frf_csv
from ._registry import (
    FormatInfo,
    encode_surface,
    formats,
    read_any,
    read_profile,
    read_surface,
    write_surface,
)

__all__ = [
    "decode_text",
    "load_source",
    "FormatInfo",
    "encode_surface",
    "formats",
    "read_any",
    "read_profile",
    "read_surface",
    "write_surface",
    "RECORDING_KINDS",
    "read_frf_csv",
    "read_recording",
    "write_frf_csv",
]
