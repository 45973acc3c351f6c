"""Mitutoyo Formtracer contour reader: real file, synthetic files, damaged files.

Oracles: numpy's own text parser (``np.loadtxt``) for the real contour, hand-made
values for the synthetic ones. The MetroPro ``.dat`` files of ../shared/data/zygo
share the suffix and must still be read as MetroPro.
"""

from __future__ import annotations

import io

import numpy as np
import pytest

from servosurf.errors import CorruptedFileError
from servosurf.io import read_any, read_profile
from servosurf.metrology import Profile

CONTOUR = "1022/1022-contour.DAT"


def _contour(rows, unit="mm", count=None) -> bytes:
    """A Formtracer export: unit line, point count, '  x,  z' rows."""
    lines = [unit, str(len(rows) if count is None else count)]
    lines += [f"{x:24.15f},{z:24.15f}" for x, z in rows]
    return ("\r\n".join(lines) + "\r\n").encode()


def _write(tmp_path, name, data):
    p = tmp_path / name
    p.write_bytes(data)
    return p


# ------------------------------------------------------------------ real file
@pytest.mark.parametrize("how", ["path", "bytesio"])
def test_real_contour(upm_dir, how):
    path = upm_dir / CONTOUR
    src = path if how == "path" else io.BytesIO(path.read_bytes())
    p, fmt = read_any(src)
    assert fmt == "formtracer" and isinstance(p, Profile)
    ref = np.loadtxt(path, skiprows=2, delimiter=",")  # independent parse, mm
    assert p.z.size == ref.shape[0] == 12001  # SOURCES.md: +6 to -6 mm at 1 um
    np.testing.assert_allclose(p.dx, 1e-6, rtol=1e-9)
    np.testing.assert_allclose(p.x0, -6e-3, rtol=1e-12)
    np.testing.assert_allclose(p.x[-1], 6e-3, rtol=1e-9)
    # stored from +6 to -6 mm: the profile runs the other way, heights in m
    np.testing.assert_allclose(p.z, ref[::-1, 1] * 1e-3, rtol=1e-12, atol=0)
    np.testing.assert_allclose(p.x, ref[::-1, 0] * 1e-3, atol=1e-12)  # 1 pm
    assert p.metadata["x_reversed"] is True and p.metadata["resampled"] is False
    assert p.metadata["unit"] == "mm"


def test_metropro_dat_still_read_as_metropro(zygo_dir, upm_dir):
    _, fmt = read_any(zygo_dir / "newview_20x_mirau_mp8.1_metropro-1.dat")
    assert fmt == "metropro_dat"
    _, fmt = read_any(upm_dir / CONTOUR)
    assert fmt == "formtracer"  # same suffix (.DAT), told apart by content


# -------------------------------------------------------------- synthetic files
@pytest.mark.parametrize(
    "unit,factor", [("mm", 1e-3), ("um", 1e-6), ("\u00b5m", 1e-6), ("nm", 1e-9)]
)
def test_units_and_increasing_x(tmp_path, unit, factor):
    rows = [(2.0 * k, 0.5 * k * k) for k in range(6)]
    p = read_profile(_write(tmp_path, "c.dat", _contour(rows, unit)))
    np.testing.assert_allclose(p.dx, 2.0 * factor)
    np.testing.assert_allclose(p.x0, 0.0)
    np.testing.assert_allclose(p.z, [0.5 * k * k * factor for k in range(6)])
    assert p.metadata["x_reversed"] is False


def test_gap_of_whole_steps_is_nan(tmp_path):
    rows = [(0.0, 1.0), (1.0, 2.0), (4.0, 5.0), (5.0, 6.0)]  # x 2, 3 missing
    p = read_profile(_write(tmp_path, "g.dat", _contour(rows)))
    np.testing.assert_allclose(p.dx, 1e-3)
    np.testing.assert_array_equal(np.isnan(p.z), [0, 0, 1, 1, 0, 0])
    np.testing.assert_allclose(p.z[[0, 1, 4, 5]], [1e-3, 2e-3, 5e-3, 6e-3])


def test_nonuniform_step_is_resampled(tmp_path):
    # steps 1, 1.3, 0.7, 1, 1 um: median 1 um; linear interpolation by hand
    x = [0.0, 1.0, 2.3, 3.0, 4.0, 5.0]
    z = [0.0, 10.0, 23.0, 30.0, 20.0, 0.0]
    p = read_profile(_write(tmp_path, "n.dat", _contour(list(zip(x, z)), "um")))
    assert p.metadata["resampled"] is True
    np.testing.assert_allclose(p.dx, 1e-6)
    # at x = 2: between (1, 10) and (2.3, 23): 10 + 13 * (1 / 1.3) = 20
    np.testing.assert_allclose(
        p.z * 1e6, [0.0, 10.0, 20.0, 30.0, 20.0, 0.0], atol=1e-9  # 1 fm, in um
    )


def test_invalid_height_is_nan(tmp_path):
    data = b"mm\n3\n0.0, 1.0\n0.001, nan\n0.002, 3.0\n"
    p = read_profile(_write(tmp_path, "v.dat", data))
    np.testing.assert_array_equal(np.isnan(p.z), [False, True, False])


# ------------------------------------------------------------------ bad files
@pytest.mark.parametrize(
    "data,fragment",
    [
        (b"furlong\n2\n0, 1\n1, 2\n", "line 1 unit is 'furlong'"),
        (b"mm\n3\n0, 1\n1, 2\n", "line 2 declares 3 points but 2 rows follow"),
        (b"mm\n2x\n0, 1\n1, 2\n", "line 2 point count is '2x'"),
        (b"mm\n2\n0, 1\n1, abc\n", "line 4 z is 'abc'"),
        (b"mm\n2\n0, 1\nq, 2\n", "line 4 x is 'q'"),
        (b"mm\n2\n0, 1\n1, 2, 3\n", "line 4 has 3 field(s)"),
        (b"mm\n3\n0, 1\n2, 2\n1, 3\n", "x is not strictly monotonic at line 5"),
        (b"mm\n2\n0, 1\ninf, 2\n", "line 4 x is inf"),
        (b"mm\n2\n0, nan\n1, nan\n", "all 2 heights are invalid"),
        (b"mm\n", "file has 1 line(s)"),
    ],
)
def test_damaged_files_one_line_errors(tmp_path, data, fragment):
    path = _write(tmp_path, "bad.DAT", data)
    with pytest.raises(CorruptedFileError) as info:
        read_profile(path)
    msg = str(info.value)
    assert "\n" not in msg and str(path) in msg and "expected" in msg
    assert fragment in msg, msg


def test_cli_profile_reads_contour(upm_dir, capsys):
    from servosurf.cli import main

    assert main(["profile", str(upm_dir / CONTOUR), "--cutoff", "8e-4",
                 "--json"]) == 0
    assert '"points": 12001' in capsys.readouterr().out
