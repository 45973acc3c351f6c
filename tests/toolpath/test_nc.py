"""NC program reader: every construct of the dialect against hand-computed blocks,
bad programs, and the two real programs of the UPM slow-tool-servo cuts."""

from __future__ import annotations

import io
import math
import re

import numpy as np
import pytest

import servosurf.toolpath as tp
from servosurf.errors import ConfigError
from tests.conftest import SHARED

UPM = SHARED / "data" / "upm_sts"
P1021 = UPM / "1021-r1000sts-res1-0.02-0.5-tool191.nc"
P1022 = UPM / "1022" / "1022-spiralPath20230418T214917.nc"

MM = 1e-3
ATOL = 1e-15  # m: 1 fm, rounding of the unit conversions


def read(text: str, **kw) -> tp.NCProgram:
    return tp.read_nc_program(io.StringIO(text), **kw)


def deg(prog: tp.NCProgram) -> np.ndarray:
    return np.degrees(prog.c)


def test_units_mm_and_inch():
    mm = read("G71 G90\nC0 X1 Z0\nC90 X0.5 Z-0.001\n")
    np.testing.assert_allclose(mm.x, [1e-3, 0.5e-3], rtol=0, atol=ATOL)
    np.testing.assert_allclose(mm.z, [0.0, -1e-6], rtol=0, atol=ATOL)
    np.testing.assert_allclose(deg(mm), [0.0, 90.0])
    inch = read("G70\nC0 X1 Z0.1\nG71\nC10 X1 Z0\n")
    # 1 in = 25.4 mm; back to mm in the same program
    np.testing.assert_allclose(inch.x, [25.4e-3, 1e-3], rtol=0, atol=ATOL)
    np.testing.assert_allclose(inch.z, [2.54e-3, 0.0], rtol=0, atol=ATOL)
    # a file without units code, read as inch; C is always in degrees
    np.testing.assert_allclose(read("C45 X2 Z0\n", units="inch").x, [50.8e-3])
    np.testing.assert_allclose(deg(read("C45 X2 Z0\n", units="inch")), [45.0])


def test_incremental_g91():
    prog = read("G90 C0 X1 Z0\nG91 C10 X-0.1 Z0.01\nC10 X-0.1\nG90 C30 X0.5\n")
    np.testing.assert_allclose(prog.x, np.array([1.0, 0.9, 0.8, 0.5]) * MM, atol=ATOL)
    np.testing.assert_allclose(prog.z, np.array([0.0, 0.01, 0.01, 0.01]) * MM,
                               atol=ATOL)
    np.testing.assert_allclose(deg(prog), [0.0, 10.0, 20.0, 30.0])
    with pytest.raises(ConfigError, match="line 1: incremental X before any"):
        read("G91 X1\n")


def test_variables_arithmetic_and_functions():
    prog = read(
        "#1 = 2\n"
        "#2 = [#1 * 3 + 1] / 2      ( 3.5 )\n"
        "#3 = #2 - -1                ( 4.5 )\n"
        "#4 = 7 MOD 4 + ROUND[2.5] + FIX[2.7] + FUP[2.1]   ( 3 + 3 + 2 + 3 )\n"
        "#[#1 + 3] = SIN[30] * 4     ( #5 = 2 )\n"
        "C0 X#1 Z[#2 * 2]\n"
        "C[#3 * 10] X[SQRT[16]] Z[ABS[-1]]\n"
        "C[#4] X-#5 Z[#5-#1]\n"
    )
    np.testing.assert_allclose(prog.x, np.array([2.0, 4.0, -2.0]) * MM, atol=ATOL)
    np.testing.assert_allclose(prog.z, np.array([7.0, 1.0, 0.0]) * MM, atol=1e-15)
    np.testing.assert_allclose(deg(prog), [0.0, 45.0, 11.0], atol=1e-12)


def test_bracket_substitution_in_words_and_feeds():
    prog = read("#8 = -0.002\n#555 = 6000\nG93 F[#555]\nC0 X1 Z[#8]\nC1 X1 Z#8\n")
    np.testing.assert_allclose(prog.z, [-2e-6, -2e-6], rtol=0, atol=ATOL)
    # G93: F is 1 / minutes per block -> 60 / 6000 = 0.01 s
    np.testing.assert_allclose(prog.block_time, [0.01, 0.01])


def test_nested_while_loops():
    prog = read(
        "#1 = 0\n"
        "WHILE [#1 LT 3] DO 1\n"
        "  #2 = 0\n"
        "  WHILE[#2 LE 1]DO2\n"
        "    C[#1*20+#2*5] X[1-#1*0.1-#2*0.01] Z0\n"
        "    #2 = #2 + 1\n"
        "  END 2\n"
        "  #1 = #1 + 1\n"
        "END 1\n"
    )
    np.testing.assert_allclose(deg(prog), [0, 5, 20, 25, 40, 45], atol=1e-12)
    np.testing.assert_allclose(
        prog.x, np.array([1.0, 0.99, 0.9, 0.89, 0.8, 0.79]) * MM, atol=ATOL)
    np.testing.assert_array_equal(prog.line, [5, 5, 5, 5, 5, 5])
    # every comparison operator
    for op, n in (("LT", 2), ("LE", 3), ("GT", 0), ("GE", 0), ("EQ", 1), ("NE", 2)):
        text = (f"#1=0\nWHILE[#1 {op} 2] DO 1\nC[#1] X1 Z0\n#1=#1+1\n"
                "WHILE[#1 GT 5] DO 2\nEND 2\nEND 1\n")
        if op == "EQ":
            text = text.replace("#1=0\n", "#1=2\n")
        assert read(text + "C90 X1 Z0\n").n_blocks == n + 1, op


def test_comments():
    prog = read(
        "( HEADER: C5 X5 Z5 is not a block )\n"
        "C0 (inline) X1 Z0 ; trailing C9 X9\n"
        "; a whole line\n"
        "C1 X0.9 (C7) Z0 (two) (comments)\n"
        "%\n"
        "N10 C2 X0.8 Z0\n"
    )
    np.testing.assert_allclose(deg(prog), [0.0, 1.0, 2.0])
    np.testing.assert_allclose(prog.x, np.array([1.0, 0.9, 0.8]) * MM, atol=ATOL)
    np.testing.assert_array_equal(prog.line, [2, 4, 6])


def test_c_unwrapped_across_360():
    prog = read("C359 X1 Z0\nC359.5 X0.9 Z0\nC0 X0.8 Z0\nC0.5 X0.7 Z0\nC360 X0.6 Z0\n")
    np.testing.assert_allclose(deg(prog), [359.0, 359.5, 360.0, 360.5, 360.0])
    # turning the other way, and C written already unwrapped
    np.testing.assert_allclose(deg(read("C0.5 X1 Z0\nC0 X1 Z0\nC359.5 X1 Z0\n")),
                               [0.5, 0.0, -0.5])
    np.testing.assert_allclose(deg(read("C700 X1 Z0\nC720 X1 Z0\nC740 X1 Z0\n")),
                               [700.0, 720.0, 740.0])


def test_link_moves_are_not_cutting():
    prog = read(
        "G71 G90 G18\n"
        "G94 Z20 F500\n"
        "G94 X1\n"
        "G0 Z0.2\n"
        "G1 Z0.1 F100\n"
        "G93 F100\n"
        "C0 X1 Z0\n"
        "C90 X0.9 Z0\n"
        "C180 X0.8 Z0\n"
        "G94 Z5 F200\n"
    )
    np.testing.assert_array_equal(
        prog.cutting, [False, False, False, False, True, True, True, False])
    assert prog.cutting_runs() == [(4, 7)]
    # G93 F100: 0.6 s per block; G94 Z0.2 -> Z0.1 at 100 mm/min: 0.06 s; the
    # rapid has none
    np.testing.assert_allclose(prog.block_time[[3, 4, 5]], [0.06, 0.6, 0.6])
    assert math.isnan(prog.block_time[2])
    # a two-axis program: feed moves cut, rapids link
    two = read("G0 X1 Z0.1\nG1 X1 Z0\nX0.5\nG0 Z1\n")
    assert two.two_axis
    np.testing.assert_array_equal(two.cutting, [False, True, True, False])


def test_g52_local_offset_and_work_offsets():
    prog = read("G55\nG52 X0.1 Y0 Z-0.002\nC0 X1 Z0\nC90 X0.5 Z0\nG52\nC180 X0.4 Z0\n")
    np.testing.assert_allclose(prog.x, np.array([1.1, 0.6, 0.4]) * MM, atol=ATOL)
    np.testing.assert_allclose(prog.z, np.array([-0.002, -0.002, 0.0]) * MM,
                               atol=ATOL)
    assert any(n.startswith("G55: work offset") for n in prog.notes)
    # work offsets change no coordinate
    np.testing.assert_array_equal(read("G54\nC0 X1 Z0\n").x, read("C0 X1 Z0\n").x)


def test_documented_no_ops():
    base = read("C0 X1 Z0\nC10 X0.9 Z0\n")
    noisy = read("G40 G63 G103 T0202 S1000 M3 M26.1\nC0 X1 Z0 M8\nG4 X0.5\n"
                 "G4 P2\nC10 X0.9 Z0\nM30\nC20 X5 Z5\n")
    # M30 ends the program: the last block is never run
    for name in ("x", "z", "c", "cutting"):
        np.testing.assert_array_equal(getattr(noisy, name), getattr(base, name))


def test_blocks_only_file_without_spaces():
    prog = read("C0.000000X1.031171Z0.049025\nC0.5X1.031122Z0.049021\n")
    assert prog.cutting.all() and not prog.two_axis
    np.testing.assert_allclose(prog.x, [1.031171e-3, 1.031122e-3], rtol=0, atol=ATOL)


PGM = """;DIFFSYS Version 5.02 jobfile:
;Created           : hand-made sample in the documented structure of such files
;Units             : mm
;Z Offset          : 0.00000 mm
;Tool Radius       : 0.18641 mm
;Reference Point   : Front point
;X-axis direction  : Edge to Center
;
X0.010000Z0.001000
X0.008000Z0.000800
X0.006000Z0.000600
X0.004000Z0.000400
X0.002000Z0.000200
X0.000000Z0.000000
"""


def test_diffsys_pgm_two_axis_job():
    # hand-made: no real DIFFSYS file is among the shared data
    prog = read(PGM, format="pgm")
    assert prog.format == "pgm" and prog.two_axis and prog.cutting.all()
    assert prog.reference == "tip"
    assert prog.tool_radius == pytest.approx(186.41e-6, rel=1e-12)
    np.testing.assert_allclose(prog.x, np.arange(10, -1, -2) * 1e-6, atol=ATOL)
    np.testing.assert_allclose(prog.z, np.arange(10, -1, -2) * 1e-7, atol=ATOL)
    assert prog.header["Units"] == "mm"
    centre = read(PGM.replace("Front point", "Tool Center"), format="pgm")
    assert centre.reference == "centre"
    with pytest.raises(ConfigError, match="Reference Point"):
        read(PGM.replace("Front point", "somewhere"), format="pgm")
    # detected by content as well as by suffix
    assert read(PGM).format == "pgm"


def test_csv_blocks():
    prog = read("c_deg,x_m,z_m\n0,1e-3,0\n90,0.5e-3,-1e-6\n", format="csv")
    np.testing.assert_allclose(deg(prog), [0.0, 90.0])
    np.testing.assert_allclose(prog.x, [1e-3, 0.5e-3])
    np.testing.assert_allclose(prog.z, [0.0, -1e-6])
    assert prog.cutting.all()
    other = read("c_rad, x_mm, z_um\n0,1,0\n1.5707963267948966,0.5,-1\n",
                 format="csv")
    np.testing.assert_allclose(other.x, [1e-3, 0.5e-3])
    np.testing.assert_allclose(other.z, [0.0, -1e-6])
    np.testing.assert_allclose(deg(other), [0.0, 90.0])
    # C unwrapped as in programs
    wrap = read("c_deg,x_m,z_m\n359,1e-3,0\n359.5,1e-3,0\n0,1e-3,0\n", format="csv")
    np.testing.assert_allclose(deg(wrap), [359.0, 359.5, 360.0])
    with pytest.raises(ConfigError, match="line 3: c_deg value 'abc' is not a number"):
        read("c_deg,x_m,z_m\n0,1e-3,0\nabc,1e-3,0\n", format="csv")
    with pytest.raises(ConfigError, match="header must be c_deg,x_m,z_m"):
        read("a,b,c\n0,0,0\n", format="csv")


@pytest.mark.parametrize(
    ("text", "match"),
    [
        ("C0 X1 Z0\nG2 X1 Z0\n", r"line 2: G2 is not supported: circular"),
        ("C0 X1 Z0\nG17\n", r"line 2: G17 is not supported: only the X-Z plane"),
        ("G41 X1\n", r"line 1: G41 is not supported"),
        ("G99 X1\n", r"line 1: G99 is not supported \(supported: G0 G1 G4"),
        ("#1=0\nWHILE[#1 LT 2] DO 1\n#1=#1+1\n", r"line 2: WHILE \[..\] DO 1 has no "
         r"END 1"),
        ("END 1\n", r"line 1: END 1 without a WHILE"),
        ("WHILE[1 LT 2] DO 1\nWHILE[1 LT 2] DO 2\nEND 1\nEND 2\n",
         r"line 3: END 1 closes WHILE \[..\] DO 2 of line 2"),
        ("C0 X1 Z0\nCABC X1 Z0\n", r"line 2: C value 'ABC' is not a number"),
        ("C0 X1 Z0\nC12.5.3 X1 Z0\n", r"line 2: C value '12.5.3' is not a number"),
        ("C0 X1 Z0\nX1 Z#7\n", r"line 2: #7 is used before it is set"),
        ("IF[#1 GT 2] GOTO 10\n", r"line 1: IF is not supported"),
        ("C0 X1 Z0\nU0.5\n", r"line 2: word U0.5 is not supported"),
        ("C0 X1 Y0.5 Z0\n", r"line 1: Y0.5: the tool moves in the X-Z plane"),
        ("#1 = 1 / 0\n", r"line 1: division by zero"),
        ("G1 X1 P3\n", r"line 1: P is only supported as the dwell time of G4"),
    ],
)
def test_bad_programs_name_line_and_code(text, match):
    with pytest.raises(ConfigError, match=match) as exc:
        read(text)
    assert "\n" not in str(exc.value)


def test_while_iteration_cap():
    text = "#1=0\nWHILE[#1 LT 10] DO 1\nC[#1] X1 Z0\n#1=#1+1\nEND 1\n"
    assert read(text, max_iterations=10).n_blocks == 10
    with pytest.raises(ConfigError, match=r"line 2: WHILE loop DO 1 ran 9 times "
                       r"without its condition becoming false"):
        read(text, max_iterations=9)


def test_missing_file_and_binary():
    with pytest.raises(ConfigError, match="not found"):
        tp.read_nc_program("/nonexistent/prog.nc")
    with pytest.raises(ConfigError, match="binary file"):
        tp.read_nc_program(io.BytesIO(b"C0 X1\x00\x01"))
    assert tp.read_nc_program(io.BytesIO(b"C0 X1 Z0\n")).n_blocks == 1


# ---------------------------------------------------------------------------------
# the real programs (shared data; skipped when absent)
# ---------------------------------------------------------------------------------


def _plain_blocks(path):
    """C, X, Z of the 'C.. X.. Z..' lines, read with a regex (independent)."""
    rows = [
        (i + 1, *map(float, m.groups()))
        for i, ln in enumerate(path.read_text().splitlines())
        if (m := re.fullmatch(r"C(\S+) X(\S+) Z(\S+)", ln.strip()))
    ]
    return np.array(rows)


@pytest.fixture(scope="module")
def upm():
    if not P1022.is_file() or not P1021.is_file():
        pytest.skip(f"shared UPM data not found at {UPM}")
    return UPM


def test_real_1022_blocks_only(upm):
    prog = tp.read_nc_program(P1022)
    ref = _plain_blocks(P1022)
    assert prog.n_blocks == prog.n_cutting == 27361 == ref.shape[0]
    np.testing.assert_array_equal(prog.line, ref[:, 0])
    np.testing.assert_allclose(prog.x, ref[:, 2] * MM, rtol=0, atol=ATOL)
    np.testing.assert_allclose(prog.z, ref[:, 3] * MM, rtol=0, atol=ATOL)
    # first and last block; C unwrapped: 38 turns of 720 blocks of 0.5 degree
    assert (prog.x[0], prog.z[0]) == pytest.approx((1.031171e-3, 0.049025e-3))
    assert (prog.x[-1], prog.z[-1]) == (0.0, 0.0)
    assert np.degrees(prog.c[-1]) == pytest.approx(38 * 360.0)
    np.testing.assert_allclose(np.diff(np.degrees(prog.c)), 0.5, atol=1e-9)


def test_real_1021_program(upm):
    prog = tp.read_nc_program(P1021)
    ref = _plain_blocks(P1021)
    runs = prog.cutting_runs()
    # the header's 'G93 F0.001 C0' (in the air at Z20) and the spiral
    assert [prog.line[i0] for i0, _ in runs] == [25, 34]
    i0, i1 = runs[1]
    assert i1 - i0 == ref.shape[0] == 19441
    np.testing.assert_allclose(prog.x[i0:i1], ref[:, 2] * MM, rtol=0, atol=ATOL)
    np.testing.assert_allclose(prog.z[i0:i1], ref[:, 3] * MM, rtol=0, atol=ATOL)
    assert np.degrees(prog.c[i1 - 1]) == pytest.approx(27 * 360.0)
    # links: the approach Z20 -> Z5 -> Z2 -> Z0.149025 -> Z0.049025 (G94) and the
    # retract are not cutting; G52 Z[#8] with #8 = 0 - 0 leaves Z unchanged
    assert not prog.cutting[:2].any() and not prog.cutting[i1:].any()
    np.testing.assert_allclose(prog.z[3:7], np.array([5, 2, 0.149025, 0.049025]) * MM,
                               rtol=0, atol=ATOL)
    # G93 F[#555] with #555 = 0.001: 60000 s per block (no usable time base)
    np.testing.assert_allclose(prog.block_time[i0:i1], 60000.0)
    assert {n.split(":")[0] for n in prog.notes} >= {"G55", "G52", "G63", "G103",
                                                     "M30", "T"}
