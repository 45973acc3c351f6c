"""Fuzzing: mutated and truncated files make every reader raise a ServosurfError
subclass (or succeed), never another exception, a crash or a hang.

Seeds are real instrument files (when ../shared is present) and small files written
by servosurf or by the builders in ``_helpers``. Hypothesis runs derandomised so the
suite is reproducible; the example budget keeps the module around 20 s.
"""

from __future__ import annotations

import contextlib
import io
import os
import signal
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from servosurf.errors import ServosurfError
from servosurf.io import encode_surface, formats, read_any
from servosurf.metrology import Surface

from ._helpers import metropro_dat, zygo_ascii, zygo_xyz

#: Hypothesis examples per reader (8 readers: about 1100 in all, about 6 s). Set
#: SERVOSURF_FUZZ_EXAMPLES for a longer, randomised run (e.g. nightly).
EXAMPLES = int(os.environ.get("SERVOSURF_FUZZ_EXAMPLES", "140"))
DERANDOMIZE = "SERVOSURF_FUZZ_EXAMPLES" not in os.environ
#: A single read taking longer than this (s) counts as a hang.
HANG_LIMIT = 60
#: libhdf5 gets this long (s) in its helper process before the read is abandoned.
HDF5_TIMEOUT = 10.0

_SHARED = Path(
    os.environ.get(
        "SERVOSURF_SHARED", Path(__file__).resolve().parents[2].parent / "shared"
    )
)
ZYGO = _SHARED / "data" / "zygo"
UPM = _SHARED / "data" / "upm_sts"
READERS = sorted(f.name for f in formats() if f.readable)


def _real(name: str) -> list[bytes]:
    p = ZYGO / name
    return [p.read_bytes()] if p.is_file() else []


def _upm(name: str) -> bytes:
    """The first lines of a real file of ../shared/data/upm_sts, made consistent."""
    p = UPM / name
    if not p.is_file():
        return b"mm\n2\n0.0, 0.0\n0.001, 0.0\n"
    lines = p.read_bytes().splitlines()[2:102]
    return b"\r\n".join([b"mm", str(len(lines)).encode(), *lines]) + b"\r\n"


def _seeds() -> dict[str, list[bytes]]:
    rng = np.random.default_rng(11)  # fixed seed; any heights will do
    z = rng.normal(0, 3e-8, (9, 12))
    z[2, 3] = np.nan
    s = Surface(z, 1e-6, 1e-6, metadata={"feed": 1e-6})
    raw = rng.integers(-5000, 5000, (6, 5))
    csv = "X ,Y ,Slice\n" + "".join(
        f"{0.871 * (i + 1)!r},{0.01 * float(np.sin(i))!r},Slice 1\n" for i in range(40)
    )
    contour = "mm\n40\n" + "".join(
        f"{0.001 * (20 - i):20.15f},{0.0001 * float(np.cos(i)):20.15f}\n"
        for i in range(40)
    )
    return {
        "formtracer": [contour.encode(), _upm("1022/1022-contour.DAT")],
        "metropro_dat": [
            encode_surface(s, "metropro_dat"),
            metropro_dat(
                raw,
                header_format=3,
                phase_res=2,
                sign=1,
                origin=(3, 2),
                intensity=np.ones((2, 10, 9)),
            ),
            *_real("mx_export_hdrfmt1_nolatres_20191018_flat01.dat"),
        ],
        "zygo_ascii": [zygo_ascii(raw), zygo_ascii(raw, intensity=False, sign=1)],
        "zygo_xyz": [
            encode_surface(s, "zygo_xyz"),
            zygo_xyz(z[:4, :5] * 1e6, origin=(2, 3)),
        ],
        "datx": [encode_surface(s, "datx"), *_real("gpi_mp8.3.3_zygo_test.datx")],
        "x3p": [encode_surface(s, "x3p"), *_real("ISO5436-sample4_bin.x3p")],
        "npz": [encode_surface(s, "npz"), encode_surface(s, "npz", compressed=False)],
        "mx_profile_csv": [csv.encode()],
    }


SEEDS = _seeds()

_WORDS = (
    b"\xff\xff\xff\xff",
    b"\x7f\xff\xff\xff",
    b"\x00\x00\x00\x00",
    b"\x80\x00\x00\x00",
    b"\x00\x00\x00\x01",
    b"\x7f\xf0\x00\x00",
)


@st.composite
def mutated(draw, seeds: list[bytes]) -> bytes:
    """A seed with 1-4 random edits: bit flips, bytes, extreme words, digit runs,
    deletions, insertions, truncation (edits favour the first kilobyte: headers)."""
    data = bytearray(draw(st.sampled_from(seeds)))
    for _ in range(draw(st.integers(1, 4))):
        if not data:
            break
        op = draw(
            st.sampled_from(
                ["flip", "byte", "word", "digits", "delete", "insert", "truncate"]
            )
        )
        hi = min(len(data), 1024) if draw(st.booleans()) else len(data)
        pos = draw(st.integers(0, hi - 1))
        if op == "flip":
            data[pos] ^= 1 << draw(st.integers(0, 7))
        elif op == "byte":
            data[pos] = draw(st.integers(0, 255))
        elif op == "word":
            data[pos : pos + 4] = draw(st.sampled_from(_WORDS))
        elif op == "digits":  # huge numbers in text headers
            data[pos:pos] = draw(
                st.sampled_from([b"99999999", b"-1", b"nan", b"1e308"])
            )
        elif op == "delete":
            del data[pos : pos + draw(st.integers(1, 64))]
        elif op == "insert":
            data[pos:pos] = draw(st.binary(min_size=1, max_size=32))
        else:
            data = data[:pos]
    return bytes(data)


@contextlib.contextmanager
def _no_hang(seconds: int):
    """Fail (instead of hanging the suite) when the body takes over ``seconds``."""
    if not hasattr(signal, "SIGALRM"):  # pragma: no cover - Windows
        yield
        return

    def boom(signum, frame):
        raise AssertionError(f"reader did not return within {seconds} s")

    old = signal.signal(signal.SIGALRM, boom)
    signal.alarm(seconds)
    try:
        yield
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, old)


@pytest.fixture(scope="module", autouse=True)
def _short_hdf5_timeout():
    from servosurf.io import _hdf5

    old = _hdf5.TIMEOUT
    _hdf5.TIMEOUT = HDF5_TIMEOUT
    yield
    _hdf5.TIMEOUT = old


def _read(blob: bytes, fmt: str | None) -> None:
    with _no_hang(HANG_LIMIT):
        try:
            read_any(io.BytesIO(blob), format=fmt)
        except ServosurfError:
            pass


def test_every_reader_has_seeds():
    assert set(SEEDS) == set(READERS)
    for name, seeds in SEEDS.items():
        for blob in seeds:
            read_any(io.BytesIO(blob), format=name)  # the seeds themselves are valid


@pytest.mark.parametrize("reader", READERS)
@settings(
    max_examples=EXAMPLES,
    deadline=None,
    derandomize=DERANDOMIZE,
    suppress_health_check=[
        HealthCheck.too_slow,
        HealthCheck.data_too_large,
        HealthCheck.large_base_example,
    ],
)
@given(data=st.data())
def test_mutated_files_raise_only_servosurf_errors(reader, data):
    blob = data.draw(mutated(SEEDS[reader]), label="file")
    forced = data.draw(st.booleans(), label="format forced")
    _read(blob, reader if forced else None)


@pytest.mark.parametrize("reader", READERS)
def test_every_truncation_of_small_seeds(reader):
    blob = SEEDS[reader][0]
    step = max(1, len(blob) // 300)
    for cut in range(0, len(blob), step):
        _read(blob[:cut], reader)
