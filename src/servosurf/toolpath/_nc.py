"""NC programs of diamond-turning CAM read as machine blocks (the dialect).

:func:`read_nc_program` reads three formats into one :class:`NCProgram`: a list of
motion blocks in execution order, each with the line it came from, its end position
in SI units and whether it cuts.

Formats
-------
``gcode`` (any suffix but ``.pgm`` and ``.csv``)
    The Moore / Precitech style subset that slow- and fast-tool-servo CAM writes
    (full programs with a header, macro variables and loops, or blocks only).
``pgm``
    DIFFSYS two-axis job files: a header of ``;Key : value`` comment lines
    (``Units``, ``Tool Radius``, ``Reference Point``, ...), then ``X.. Z..`` blocks.
    Read from the documented structure of such files (a header, then the profile);
    the test suite uses a hand-made sample of that structure.
``csv``
    A header naming the columns with their units (``c_deg,x_m,z_m``; also
    ``c_rad`` and ``x_mm``, ``x_um``, ... for X and Z), then one row per block.
    Every row cuts.

G-code dialect (``gcode`` and the body of ``pgm``)
--------------------------------------------------
Case does not matter; words may be written without spaces (``X9.0Z0.04``).

* Comments: ``( ... )`` anywhere in a line and everything after ``;``. ``%`` lines,
  ``N`` sequence numbers and ``O`` program numbers are ignored.
* Units: ``G71`` (and ``G21``) mm, ``G70`` (and ``G20``) inch, for X, Z, G52
  offsets and G94 feeds; C is always in degrees. Files without a units code use the
  ``units`` argument (default mm).
* ``G90`` absolute, ``G91`` incremental (X, Z and C).
* ``G0`` rapid, ``G1`` linear feed (the default motion). Arcs (``G2``/``G3``) are
  not supported.
* ``G93`` inverse-time feed: ``F`` is 1 / (block time in minutes); ``G94`` feed per
  minute (mm/min or in/min). The block times the program gives are kept
  (:attr:`NCProgram.block_time`); whether they are usable is decided by
  :class:`~servosurf.toolpath.BlockPath`.
* ``G18`` (X-Z plane) is required implicitly; ``G17``/``G19`` are refused.
* ``G52 X.. Z.. C..``: local offset, added to every later absolute position (a
  ``G52`` without axis words resets it). ``Y`` must be 0.
* ``G54``..``G59``: work offsets. Their values are machine settings, not in the
  file: the program's coordinates are taken as coordinates of the part (spindle
  axis at X = 0), i.e. the selected work offset is the part's zero. The code is
  recorded in :attr:`NCProgram.notes`.
* Documented no-ops (they change no geometry): ``G4`` dwell, ``G40`` (nose-radius
  compensation off), ``G63``, ``G103``, and every ``M``, ``T`` and ``S`` word.
  ``M2``/``M30`` end the program. ``G41``/``G42`` (compensation done by the
  machine from its own tool table) are refused.
* Variables ``#n = expression``; ``#n`` or ``[expression]`` as any word's value
  (``Z[#8]``, ``F#555``, ``X-[#1*2]``); ``#[expression]`` indirect addressing.
  Expressions: numbers, ``+ - * /``, ``MOD``, brackets ``[ ]`` and the functions
  ``SIN COS TAN ASIN ACOS ATAN`` (degrees), ``SQRT ABS ROUND FIX FUP LN EXP``. A
  variable read before it is set is an error.
* ``WHILE [a OP b] DO n`` ... ``END n`` with ``OP`` one of ``LT LE GT GE EQ NE``,
  nested to any depth. A loop that runs more than ``max_iterations`` times is an
  error (its condition never becomes false), as are a ``WHILE`` without its
  ``END`` and an ``END`` without its ``WHILE``. ``IF`` and ``GOTO`` are not
  supported.

Anything else (an unknown G code or word, a value that is not a number) is a
:class:`~servosurf.errors.ConfigError` of one line naming the file, the line number,
the code and what is supported.

Cutting blocks and links
------------------------
* A program with C words (slow/fast tool servo): a feed move (not ``G0``) is
  **cutting** when it runs in ``G93`` inverse-time mode, or when the program never
  set a feed mode (blocks-only files such as the 1022 spiral). ``G0`` rapids and
  ``G94`` feed moves are **links** (approach and retract outside the material);
  they are not swept.
* A two-axis program (no C word anywhere, e.g. DIFFSYS ``.pgm`` jobs): every feed
  move cuts, ``G0`` rapids are links. The spindle turns at a constant speed the
  user gives.

Signs and frames
----------------
X is the radius of the tool reference (negative X lies past the spindle axis, half
a turn away), Z the axial position, positive away from the part (a lower Z cuts
deeper; z in servosurf's frame is the program's Z), and C the spindle angle. C
values are angles modulo 360 degrees: each absolute C is unwrapped to the angle
nearest the previous C (a block turns less than 180 degrees), so ``C359.5``
followed by ``C0`` is a step of +0.5 degree.

What the reader does not decide, :class:`~servosurf.toolpath.BlockPath` does, from
the file or the user:

* **Reference point**: the program's Z is the tool tip (front point, the lowest
  point of the nose arc; the default, and what the UPM programs write) or the nose
  centre (converted to the tip: ``z_tip = z - R``). A DIFFSYS header states it
  (``Reference Point : Front point``) with the tool radius
  (:attr:`NCProgram.reference`, :attr:`NCProgram.tool_radius`); otherwise the user
  does (``tool.reference``, ``--reference``), and a contradiction is an error.
* **Rotation sense**: ``ccw`` (default): as C increases the tool moves
  counter-clockwise over the part seen from the tool side (+z), i.e. the tool's
  angle in the part frame is ``+C``; ``cw``: ``-C``.
* **Time base**: the program's G93 feeds when they give a plausible spindle speed,
  else ``--spindle-rpm`` or ``--block-time`` (required, the error says so).
"""

from __future__ import annotations

import io
import math
import re
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

import numpy as np

from ..errors import ConfigError

__all__ = ["NCProgram", "read_nc_program", "NC_FORMATS", "MAX_ITERATIONS"]

#: Formats :func:`read_nc_program` reads.
NC_FORMATS = ("gcode", "pgm", "csv")
#: Default cap on the iterations of one WHILE loop (per entry into the loop).
MAX_ITERATIONS = 1_000_000
#: Cap on the number of motion blocks a program may execute (memory guard).
MAX_BLOCKS = 50_000_000

_INCH = 25.4e-3
_MM = 1e-3

#: G codes and what they do (the supported set; the message of an unknown code).
_G_SUPPORTED = {
    "0": "rapid",
    "1": "linear feed",
    "4": "dwell (no-op)",
    "18": "X-Z plane",
    "20": "inch",
    "21": "mm",
    "40": "nose-radius compensation off (no-op)",
    "52": "local offset",
    "54": "work offset",
    "55": "work offset",
    "56": "work offset",
    "57": "work offset",
    "58": "work offset",
    "59": "work offset",
    "63": "no-op",
    "70": "inch",
    "71": "mm",
    "90": "absolute",
    "91": "incremental",
    "93": "inverse-time feed",
    "94": "feed per minute",
    "103": "no-op",
}
_G_LIST = "G0 G1 G4 G18 G20 G21 G40 G52 G54-G59 G63 G70 G71 G90 G91 G93 G94 G103"
_G_REFUSED = {
    "2": "circular interpolation is not supported",
    "3": "circular interpolation is not supported",
    "17": "only the X-Z plane (G18) is supported",
    "19": "only the X-Z plane (G18) is supported",
    "41": "nose-radius compensation by the machine is not supported; give the "
    "tip or nose-centre path",
    "42": "nose-radius compensation by the machine is not supported; give the "
    "tip or nose-centre path",
}
_WORDS = "G M T S F N O X Z C Y P"
_FUNCS: dict[str, Callable[[float], float]] = {
    "SIN": lambda v: math.sin(math.radians(v)),
    "COS": lambda v: math.cos(math.radians(v)),
    "TAN": lambda v: math.tan(math.radians(v)),
    "ASIN": lambda v: math.degrees(math.asin(v)),
    "ACOS": lambda v: math.degrees(math.acos(v)),
    "ATAN": lambda v: math.degrees(math.atan(v)),
    "SQRT": math.sqrt,
    "ABS": abs,
    "ROUND": lambda v: math.copysign(math.floor(abs(v) + 0.5), v),
    "FIX": lambda v: float(math.floor(v)),
    "FUP": lambda v: float(math.ceil(v)),
    "LN": math.log,
    "EXP": math.exp,
}
_CMP = {
    "LT": lambda a, b: a < b,
    "LE": lambda a, b: a <= b,
    "GT": lambda a, b: a > b,
    "GE": lambda a, b: a >= b,
    "EQ": lambda a, b: a == b,
    "NE": lambda a, b: a != b,
}
_NUM = re.compile(r"[+-]?(?:\d+\.?\d*|\.\d+)")
_NAME = re.compile(r"[A-Z]+")
_COMMENT = re.compile(r"\([^)]*\)")
# the common cutting line "C0.5 X1.03 Z0.049" in any order of words, plain numbers
_FAST = re.compile(r"(?:[CXZ][+-]?(?:\d+\.?\d*|\.\d+))+")
_FAST_WORD = re.compile(r"([CXZ])([+-]?(?:\d+\.?\d*|\.\d+))")


@dataclass(frozen=True, eq=False)
class NCProgram:
    """Motion blocks of an NC program in execution order (SI units).

    Each entry describes one motion block: the position at its end and how it
    moved there. The position before the first block is unknown.

    Attributes
    ----------
    source : str
        File the program was read from.
    format : {"gcode", "pgm", "csv"}
        Format it was read as.
    line : ndarray of int64, shape (n,)
        Source line (1-based) of each motion block.
    c : ndarray of shape (n,)
        Spindle angle at the end of the block, in rad, unwrapped (continuous); NaN
        while no C was programmed (always NaN for a two-axis program).
    x : ndarray of shape (n,)
        X (radius of the tool reference; negative past the axis) at the end of the
        block, in m; NaN while not yet programmed.
    z : ndarray of shape (n,)
        Z (axial, positive away from the part) at the end of the block, in m; NaN
        while not yet programmed.
    cutting : ndarray of bool, shape (n,)
        True for cutting blocks, False for links (see the module docstring).
    block_time : ndarray of shape (n,)
        Duration the program gives the block, in s (G93: 60 / F; G94: path length
        / F); NaN where it gives none (rapids, blocks-only files).
    two_axis : bool
        True when no block has a C word (the spindle turns at constant speed).
    reference : {"tip", "centre"} or None
        Path reference point the file states (DIFFSYS header), None if unstated.
    tool_radius : float or None
        Tool nose radius the file states, in m, None if unstated.
    header : dict of str to str
        Header fields (DIFFSYS ``;Key : value`` lines).
    notes : tuple of str
        Codes read as documented no-ops or machine settings, one note per code.
    """

    source: str
    format: Literal["gcode", "pgm", "csv"]
    line: np.ndarray
    c: np.ndarray
    x: np.ndarray
    z: np.ndarray
    cutting: np.ndarray
    block_time: np.ndarray
    two_axis: bool
    reference: Literal["tip", "centre"] | None = None
    tool_radius: float | None = None
    header: dict[str, str] = field(default_factory=dict)
    notes: tuple[str, ...] = ()

    @property
    def n_blocks(self) -> int:
        """Number of motion blocks."""
        return int(self.line.size)

    @property
    def n_cutting(self) -> int:
        """Number of cutting blocks."""
        return int(np.count_nonzero(self.cutting))

    def cutting_runs(self) -> list[tuple[int, int]]:
        """Runs of consecutive cutting blocks.

        Returns
        -------
        list of tuple of int
            Half-open index ranges ``(i0, i1)`` into the block arrays.
        """
        cut = np.concatenate(([False], self.cutting, [False]))
        d = np.diff(cut.astype(np.int8))
        return list(zip(np.flatnonzero(d == 1).tolist(),
                        np.flatnonzero(d == -1).tolist(), strict=True))


class _Error(Exception):
    """A fault at a known line (turned into a ConfigError with the file name)."""

    def __init__(self, line: int, msg: str) -> None:
        super().__init__(msg)
        self.line = line
        self.msg = msg


# --------------------------------------------------------------------------------
# expressions
# --------------------------------------------------------------------------------


class _Scanner:
    """Recursive-descent parser of one (comment-free, upper-case) line."""

    def __init__(self, text: str, line: int) -> None:
        self.s = text
        self.i = 0
        self.line = line

    def fail(self, msg: str) -> _Error:
        return _Error(self.line, msg)

    def skip(self) -> None:
        s, i = self.s, self.i
        while i < len(s) and s[i] in " \t":
            i += 1
        self.i = i

    def peek(self) -> str:
        self.skip()
        return self.s[self.i] if self.i < len(self.s) else ""

    def eat(self, ch: str) -> bool:
        if self.peek() == ch:
            self.i += 1
            return True
        return False

    def expect(self, ch: str, what: str) -> None:
        if not self.eat(ch):
            got = self.s[self.i:self.i + 12] or "end of line"
            raise self.fail(f"expected {ch!r} {what}, got {got!r}")

    def name(self) -> str | None:
        self.skip()
        m = _NAME.match(self.s, self.i)
        if m is None:
            return None
        return m.group(0)

    def number(self) -> float | None:
        self.skip()
        m = _NUM.match(self.s, self.i)
        if m is None:
            return None
        self.i = m.end()
        return float(m.group(0))

    # grammar ------------------------------------------------------------------
    def expr(self) -> Any:
        node = self.term()
        while True:
            ch = self.peek()
            if ch and ch in "+-":
                self.i += 1
                node = ("bin", ch, node, self.term())
            else:
                return node

    def term(self) -> Any:
        node = self.unary()
        while True:
            ch = self.peek()
            if ch and ch in "*/":
                self.i += 1
                node = ("bin", ch, node, self.unary())
            elif self.name() == "MOD":
                self.i += 3
                node = ("bin", "MOD", node, self.unary())
            else:
                return node

    def unary(self) -> Any:
        ch = self.peek()
        if ch == "-":
            self.i += 1
            return ("neg", self.unary())
        if ch == "+":
            self.i += 1
            return self.unary()
        return self.primary()

    def primary(self) -> Any:
        ch = self.peek()
        if ch == "[":
            self.i += 1
            node = self.expr()
            self.expect("]", "to close '['")
            return node
        if ch == "#":
            self.i += 1
            return ("var", self.var_index())
        if ch.isdigit() or ch == ".":
            v = self.number()
            if v is None:
                raise self.fail(f"bad number {self.s[self.i:self.i + 12]!r}")
            return v
        nm = self.name()
        if nm is not None and nm in _FUNCS:
            self.i += len(nm)
            if self.peek() != "[":
                raise self.fail(f"{nm} needs its argument in brackets: {nm}[...]")
            return ("call", nm, self.primary())
        got = self.s[self.i:self.i + 12] or "end of line"
        funcs = " ".join(_FUNCS)
        raise self.fail(
            f"expected a number, #n, [expression] or a function ({funcs}), got "
            f"{got!r}"
        )

    def var_index(self) -> Any:
        if self.peek() == "[":
            return self.primary()
        v = self.number()
        if v is None or v != int(v) or v < 0:
            raise self.fail(
                f"expected a variable number after '#', got "
                f"{self.s[self.i:self.i + 8]!r}")
        return float(v)

    def condition(self) -> Any:
        a = self.expr()
        op = self.name()
        if op not in _CMP:
            raise self.fail(
                f"WHILE condition needs a comparison (LT LE GT GE EQ NE), got "
                f"{(op or self.s[self.i:self.i + 8])!r}"
            )
        self.i += len(op)
        return ("cmp", op, a, self.expr())


def _eval(node: Any, env: dict[int, float], line: int) -> float:
    if isinstance(node, float):
        return node
    kind = node[0]
    if kind == "var":
        k = _eval(node[1], env, line)
        if k != int(k):
            raise _Error(line, f"variable number #{k:g} is not an integer")
        k = int(k)
        if k not in env:
            raise _Error(line, f"#{k} is used before it is set")
        return env[k]
    if kind == "neg":
        return -_eval(node[1], env, line)
    if kind == "bin":
        a = _eval(node[2], env, line)
        b = _eval(node[3], env, line)
        op = node[1]
        if op == "+":
            return a + b
        if op == "-":
            return a - b
        if op == "*":
            return a * b
        if b == 0:
            raise _Error(line, f"division by zero ({a:g} {op} 0)")
        return a / b if op == "/" else math.fmod(a, b)
    if kind == "call":
        v = _eval(node[2], env, line)
        try:
            return float(_FUNCS[node[1]](v))
        except (ValueError, OverflowError):
            raise _Error(line, f"{node[1]}[{v:g}] is undefined") from None
    if kind == "cmp":
        return float(_CMP[node[1]](_eval(node[2], env, line),
                                   _eval(node[3], env, line)))
    raise AssertionError(kind)  # pragma: no cover


# --------------------------------------------------------------------------------
# statements
# --------------------------------------------------------------------------------


def _strip(raw: str) -> str:
    """Remove comments, upper-case, drop N/O numbers; '' for empty lines."""
    s = raw
    if ";" in s:
        s = s[: s.index(";")]
    if "(" in s:
        s = _COMMENT.sub(" ", s)
        if "(" in s:  # an unclosed comment runs to the end of the line
            s = s[: s.index("(")]
    s = s.strip().upper()
    if not s or s.startswith("%"):
        return ""
    if s[0] in "NO" and len(s) > 1 and (s[1].isdigit()):
        m = re.match(r"[NO]\d+", s)
        s = s[m.end():].strip()
    return s


def _parse_line(text: str, line: int) -> tuple | None:
    """Statement of one cleaned line: ('assign'|'while'|'end'|'block', ...)."""
    if not text:
        return None
    compact = text.replace(" ", "")
    if _FAST.fullmatch(compact):
        return ("block", line, [(w, float(v)) for w, v in _FAST_WORD.findall(compact)])
    sc = _Scanner(text, line)
    if text.startswith("#"):
        sc.i = 1
        target = sc.var_index()
        sc.expect("=", "after the variable of an assignment")
        value = sc.expr()
        if sc.peek():
            raise sc.fail(f"unexpected {sc.s[sc.i:sc.i + 12]!r} after the assignment")
        return ("assign", line, target, value)
    head = sc.name()
    if head == "WHILE":
        sc.i += 5
        sc.expect("[", "after WHILE")
        cond = sc.condition()
        sc.expect("]", "to close the WHILE condition")
        if sc.name() != "DO":
            raise sc.fail("WHILE [..] must be followed by DO n")
        sc.i += 2
        label = sc.number()
        if label is None or sc.peek():
            raise sc.fail("WHILE [..] DO needs a loop number, e.g. DO 1")
        return ("while", line, cond, int(label))
    if head == "END":
        sc.i += 3
        label = sc.number()
        if label is None or sc.peek():
            raise sc.fail("END needs the loop number of its DO, e.g. END 1")
        return ("end", line, int(label))
    if head in ("IF", "GOTO", "THEN", "DO"):
        raise sc.fail(f"{head} is not supported (loops: WHILE [..] DO n ... END n)")
    words: list[tuple[str, Any]] = []
    while sc.peek():
        ch = sc.peek()
        if not ch.isalpha():
            raise sc.fail(
                f"expected an address letter ({_WORDS}), got "
                f"{sc.s[sc.i:sc.i + 12]!r}")
        sc.i += 1
        if ch not in _WORDS.split():
            m = re.match(r"[^A-Z]*", sc.s[sc.i:])
            raise sc.fail(f"word {ch}{m.group(0).strip()} is not supported "
                          f"(supported words: {_WORDS})")
        nxt = sc.peek()
        start = sc.i
        bad = not (nxt in ("#", "[", "-", "+") or nxt.isdigit() or nxt == ".")
        if not bad:
            try:
                value = sc.unary()
            except _Error:
                bad = True
            else:
                bad = bool(sc.peek()) and not sc.peek().isalpha()
        if bad:
            tail = re.match(r"[^ ]*", sc.s[start:].lstrip()).group(0)
            raise sc.fail(f"{ch} value {tail!r} is not a number (expected a number, "
                          "#n or [expression])")
        words.append((ch, value))
    return ("block", line, words)


def _code(v: float) -> str:
    """'1' for 1.0, '26.1' for 26.1 (the key of a G or M code)."""
    return f"{v:g}"


@dataclass
class _State:
    """Modal state of the interpreter (positions in m and degrees)."""

    units: float = _MM
    incremental: bool = False
    rapid: bool = False
    feed_mode: str | None = None  # "G93", "G94" or None (never set)
    f93: float | None = None
    f94: float | None = None
    off_x: float = 0.0
    off_z: float = 0.0
    off_c: float = 0.0
    x: float = math.nan
    z: float = math.nan
    c: float = math.nan  # unwrapped degrees
    ended: bool = False


class _Interpreter:
    def __init__(self, units: float, max_iterations: int) -> None:
        self.st = _State(units=units)
        self.env: dict[int, float] = {}
        self.max_iterations = int(max_iterations)
        self.notes: dict[str, str] = {}
        self.rows: list[tuple] = []  # (line, c_deg, x, z, cutting?, time, has_c, mode)

    def note(self, key: str, text: str) -> None:
        self.notes.setdefault(key, text)

    def run(self, stmts: list[tuple]) -> None:
        match = _match_loops(stmts)
        pc = 0
        count: dict[int, int] = {}
        n = len(stmts)
        while pc < n and not self.st.ended:
            s = stmts[pc]
            kind = s[0]
            if kind == "block":
                self.block(s[1], s[2])
            elif kind == "assign":
                k = _eval(s[2], self.env, s[1])
                if k != int(k) or k < 1:
                    raise _Error(s[1], f"cannot assign to #{k:g} (variables #1 and up)")
                self.env[int(k)] = _eval(s[3], self.env, s[1])
            elif kind == "while":
                if _eval(s[2], self.env, s[1]):
                    c = count.get(pc, 0) + 1
                    if c > self.max_iterations:
                        raise _Error(
                            s[1],
                            f"WHILE loop DO {s[3]} ran {self.max_iterations} times "
                            "without its condition becoming false (iteration cap "
                            "max_iterations)")
                    count[pc] = c
                else:
                    count[pc] = 0
                    pc = match[pc] + 1
                    continue
            elif kind == "end":
                pc = match[pc]
                continue
            pc += 1

    def block(self, line: int, words: list[tuple[str, Any]]) -> None:
        st = self.st
        vals: dict[str, float] = {}
        gcodes: list[str] = []
        for w, node in words:
            v = _eval(node, self.env, line)
            if w == "G":
                key = _code(v)
                if key not in _G_SUPPORTED:
                    why = _G_REFUSED.get(key)
                    extra = f": {why}" if why else ""
                    raise _Error(line, f"G{key} is not supported{extra} (supported: "
                                 f"{_G_LIST})")
                gcodes.append(key)
            elif w == "M":
                key = _code(v)
                if key in ("2", "30"):
                    st.ended = True
                self.note(f"M{key}", "machine function, no geometry")
            elif w in ("T", "S"):
                self.note(w, f"{w} words change no geometry (ignored)")
            elif w in ("N", "O"):
                pass
            else:
                if w in vals:
                    raise _Error(line, f"{w} given twice in one block")
                vals[w] = v
        g52 = False
        dwell = False
        for g in gcodes:
            if g in ("70", "20"):
                st.units = _INCH
            elif g in ("71", "21"):
                st.units = _MM
            elif g == "90":
                st.incremental = False
            elif g == "91":
                st.incremental = True
            elif g == "0":
                st.rapid = True
            elif g == "1":
                st.rapid = False
            elif g in ("93", "94"):
                st.feed_mode = "G" + g
            elif g == "52":
                g52 = True
            elif g == "4":
                dwell = True
                self.note("G4", "dwell: no geometry (its time is not modelled)")
            elif g in ("54", "55", "56", "57", "58", "59"):
                self.note(f"G{g}", "work offset: a machine setting not in the file; "
                          "program coordinates are taken as part coordinates")
            elif g == "18":
                pass
            else:
                self.note(f"G{g}", _G_SUPPORTED[g])
        if "F" in vals:
            f = vals.pop("F")
            if not f > 0:
                raise _Error(line, f"F must be > 0, got {f:g}")
            if st.feed_mode == "G93":
                st.f93 = f
            else:
                st.f94 = f
        if dwell:
            vals.pop("X", None)  # G4 X or P = dwell time
            vals.pop("P", None)
            return
        if "P" in vals:
            raise _Error(line, "P is only supported as the dwell time of G4")
        if "Y" in vals:
            y = vals.pop("Y")
            if y != 0:
                raise _Error(line, f"Y{y:g}: the tool moves in the X-Z plane (G18); "
                             "only Y0 is accepted")
        if g52:
            if not vals:
                st.off_x = st.off_z = st.off_c = 0.0
            else:
                st.off_x = vals.get("X", 0.0) * st.units
                st.off_z = vals.get("Z", 0.0) * st.units
                st.off_c = vals.get("C", 0.0)
            self.note("G52", "local offset applied to later absolute positions")
            return
        if not vals:
            return
        self.move(line, vals)

    def move(self, line: int, vals: dict[str, float]) -> None:
        st = self.st
        x0, z0 = st.x, st.z
        u = st.units
        if "X" in vals:
            st.x = (st.x + vals["X"] * u if st.incremental
                    else vals["X"] * u + st.off_x)
            if math.isnan(st.x):
                raise _Error(line, "incremental X before any absolute X position")
        if "Z" in vals:
            st.z = (st.z + vals["Z"] * u if st.incremental
                    else vals["Z"] * u + st.off_z)
            if math.isnan(st.z):
                raise _Error(line, "incremental Z before any absolute Z position")
        has_c = "C" in vals
        if has_c:
            if st.incremental:
                if math.isnan(st.c):
                    raise _Error(line, "incremental C before any absolute C position")
                st.c = st.c + vals["C"]
            else:
                target = vals["C"] + st.off_c
                if math.isnan(st.c):
                    st.c = target
                else:
                    d = (target - st.c + 180.0) % 360.0 - 180.0
                    st.c = st.c + d
        time = math.nan
        if not st.rapid:
            if st.feed_mode == "G93" and st.f93:
                time = 60.0 / st.f93
            elif st.feed_mode == "G94" and st.f94 and not has_c:
                dx = 0.0 if math.isnan(x0) else st.x - x0
                dz = 0.0 if math.isnan(z0) else st.z - z0
                length = math.hypot(dx, dz)
                time = length / (st.f94 * u / 60.0)
        self.rows.append((line, st.c, st.x, st.z, st.rapid, time, has_c, st.feed_mode))
        if len(self.rows) > MAX_BLOCKS:
            raise _Error(line, f"the program executes more than {MAX_BLOCKS} motion "
                         "blocks (memory guard)")


def _match_loops(stmts: list[tuple]) -> dict[int, int]:
    """Map WHILE index -> END index and back; raise on unbalanced loops."""
    stack: list[tuple[int, int, int]] = []  # (index, label, line)
    match: dict[int, int] = {}
    for i, s in enumerate(stmts):
        if s[0] == "while":
            stack.append((i, s[3], s[1]))
        elif s[0] == "end":
            if not stack:
                raise _Error(s[1], f"END {s[2]} without a WHILE [..] DO {s[2]}")
            j, label, ln = stack.pop()
            if label != s[2]:
                raise _Error(s[1], f"END {s[2]} closes WHILE [..] DO {label} of line "
                             f"{ln}; loops must nest (END {label} expected)")
            match[j] = i
            match[i] = j
    if stack:
        j, label, ln = stack[-1]
        raise _Error(ln, f"WHILE [..] DO {label} has no END {label}")
    return match


# --------------------------------------------------------------------------------
# formats
# --------------------------------------------------------------------------------


def _read_text(source: Any) -> tuple[str, str]:
    """(text, name) from a path or a text/binary file object."""
    if isinstance(source, str | Path):
        p = Path(source)
        try:
            data = p.read_bytes()
        except FileNotFoundError:
            raise ConfigError(f"{p}: NC program not found") from None
        except IsADirectoryError:
            raise ConfigError(f"{p}: is a directory, not an NC program") from None
        name = str(p)
    else:
        data = source.read()
        name = getattr(source, "name", "<stream>")
        if not isinstance(name, str):
            name = "<stream>"
    if isinstance(data, bytes):
        try:
            text = data.decode("utf-8")
        except UnicodeDecodeError:
            text = data.decode("latin-1")
    else:
        text = str(data)
    if "\x00" in text:
        raise ConfigError(f"{name}: binary file, not an NC program (text expected)")
    return text, name


def _detect(name: str, text: str) -> str:
    suffix = Path(name).suffix.lower()
    if suffix == ".csv":
        return "csv"
    if suffix == ".pgm" or text.lstrip().upper().startswith(";DIFFSYS"):
        return "pgm"
    return "gcode"


_HEADER = re.compile(r"^;\s*([^:]+?)\s*:\s*(.*?)\s*$")


def _pgm_header(lines: list[str], name: str) -> tuple[dict[str, str], float | None,
                                                      str | None, float | None]:
    """Header fields, units factor, reference and tool radius of a DIFFSYS job."""
    header: dict[str, str] = {}
    for raw in lines:
        s = raw.strip()
        if not s:
            continue
        if not s.startswith(";"):
            break
        m = _HEADER.match(s)
        if m:
            header[m.group(1).strip()] = m.group(2).strip()
    keys = {k.lower(): v for k, v in header.items()}
    units = None
    if "units" in keys:
        u = keys["units"].lower()
        if u in ("mm", "millimeter", "millimetre", "millimeters", "millimetres"):
            units = _MM
        elif u in ("inch", "inches", "in"):
            units = _INCH
        else:
            raise ConfigError(f"{name}: header Units {keys['units']!r} is not mm or "
                              "inch")
    ref = None
    if "reference point" in keys:
        v = keys["reference point"].lower()
        if "front" in v or "tip" in v:
            ref = "tip"
        elif "cent" in v:
            ref = "centre"
        else:
            raise ConfigError(
                f"{name}: header Reference Point {keys['reference point']!r} is "
                "neither a front point (tip) nor the tool centre")
    radius = None
    if "tool radius" in keys:
        m = re.match(r"\s*([+-]?(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?)\s*([a-zA-Z]*)",
                     keys["tool radius"])
        if m is None:
            raise ConfigError(f"{name}: header Tool Radius {keys['tool radius']!r} is "
                              "not a number")
        unit = m.group(2).lower() or ("inch" if units == _INCH else "mm")
        from ..units import length_factor

        if unit in ("inch", "in"):
            f = _INCH
        else:
            try:
                f = length_factor(unit)
            except ValueError:
                raise ConfigError(
                    f"{name}: header Tool Radius unit {m.group(2)!r} is not a length "
                    "unit") from None
        radius = float(m.group(1)) * f
        if not radius > 0:
            raise ConfigError(f"{name}: header Tool Radius must be > 0, got "
                              f"{keys['tool radius']!r}")
    return header, units, ref, radius


_CSV_C = {"c_deg": 1.0, "c_rad": 180.0 / math.pi}


def _csv_unit(col: str, axis: str, name: str) -> float:
    from ..units import length_factor

    head = col.strip().lower()
    if not head.startswith(axis + "_"):
        raise ConfigError(
            f"{name}: line 1: column {col.strip()!r} must be {axis}_<unit> (e.g. "
            f"{axis}_m or {axis}_mm); the header is c_deg,x_m,z_m")
    try:
        return length_factor(head[2:])
    except ValueError:
        raise ConfigError(f"{name}: line 1: unit of column {col.strip()!r} is not a "
                          "length unit (m, mm, um, ...)") from None


def _read_csv(text: str, name: str) -> NCProgram:
    lines = text.splitlines()
    first = 0
    while first < len(lines) and not lines[first].strip():
        first += 1
    if first == len(lines):
        raise ConfigError(f"{name}: empty CSV (expected the header c_deg,x_m,z_m)")
    head = [h.strip().lower() for h in lines[first].split(",")]
    if len(head) != 3 or head[0] not in _CSV_C:
        raise ConfigError(
            f"{name}: line {first + 1}: header must be c_deg,x_m,z_m (C in deg or rad, "
            f"X and Z with a length unit), got {lines[first].strip()!r}")
    cf = _CSV_C[head[0]]
    xf = _csv_unit(head[1], "x", name)
    zf = _csv_unit(head[2], "z", name)
    rows, lns = [], []
    for i in range(first + 1, len(lines)):
        s = lines[i].strip()
        if not s or s.startswith("#"):
            continue
        parts = s.split(",")
        if len(parts) != 3:
            raise ConfigError(f"{name}: line {i + 1}: expected 3 values "
                              f"({','.join(head)}), got {len(parts)}")
        vals = []
        for h, p in zip(head, parts, strict=True):
            try:
                v = float(p)
            except ValueError:
                raise ConfigError(f"{name}: line {i + 1}: {h} value {p.strip()!r} is "
                                  "not a number") from None
            if not math.isfinite(v):
                raise ConfigError(f"{name}: line {i + 1}: {h} value {p.strip()!r} is "
                                  "not finite")
            vals.append(v)
        rows.append(vals)
        lns.append(i + 1)
    if not rows:
        raise ConfigError(f"{name}: no data rows after the header")
    a = np.asarray(rows, dtype=np.float64)
    cdeg = a[:, 0] * cf
    d = np.diff(cdeg)
    d = (d + 180.0) % 360.0 - 180.0
    c = np.radians(np.concatenate(([cdeg[0]], cdeg[0] + np.cumsum(d))))
    n = a.shape[0]
    return NCProgram(
        source=name, format="csv", line=np.asarray(lns, dtype=np.int64), c=c,
        x=a[:, 1] * xf, z=a[:, 2] * zf, cutting=np.ones(n, dtype=bool),
        block_time=np.full(n, np.nan), two_axis=False,
        notes=("csv: every row is a cutting block",))


def _read_gcode(text: str, name: str, fmt: str, units: float,
                max_iterations: int) -> NCProgram:
    lines = text.splitlines()
    header: dict[str, str] = {}
    reference = None
    radius = None
    if fmt == "pgm":
        header, hunits, reference, radius = _pgm_header(lines, name)
        if hunits is not None:
            units = hunits
    try:
        stmts = []
        for i, raw in enumerate(lines):
            st = _parse_line(_strip(raw), i + 1)
            if st is not None:
                stmts.append(st)
        interp = _Interpreter(units, max_iterations)
        interp.run(stmts)
    except _Error as exc:
        raise ConfigError(f"{name}: line {exc.line}: {exc.msg}") from None
    rows = interp.rows
    if not rows:
        raise ConfigError(f"{name}: no motion blocks (X, Z or C words) in the program")
    line = np.array([r[0] for r in rows], dtype=np.int64)
    c = np.radians(np.array([r[1] for r in rows], dtype=np.float64))
    x = np.array([r[2] for r in rows], dtype=np.float64)
    z = np.array([r[3] for r in rows], dtype=np.float64)
    rapid = np.array([r[4] for r in rows], dtype=bool)
    time = np.array([r[5] for r in rows], dtype=np.float64)
    has_c = np.array([r[6] for r in rows], dtype=bool)
    mode = [r[7] for r in rows]
    two_axis = not has_c.any()
    if two_axis:
        cutting = ~rapid
        c[:] = np.nan
    else:
        cutting = ~rapid & np.array([m in ("G93", None) for m in mode], dtype=bool)
        # a G94 block with C and no explicit mode is still a link; blocks-only
        # files (no mode ever set) cut
    notes = tuple(f"{k}: {v}" for k, v in sorted(interp.notes.items()))
    return NCProgram(
        source=name, format=fmt, line=line, c=c, x=x, z=z, cutting=cutting,
        block_time=time, two_axis=bool(two_axis), reference=reference,
        tool_radius=radius, header=header, notes=notes)


def read_nc_program(source: str | Path | io.IOBase, *,
                    format: Literal["gcode", "pgm", "csv"] | None = None,
                    units: Literal["mm", "inch"] = "mm",
                    max_iterations: int = MAX_ITERATIONS) -> NCProgram:
    """Read an NC program (G-code, DIFFSYS ``.pgm`` job or ``c_deg,x_m,z_m`` CSV).

    Parameters
    ----------
    source : str, Path or file object
        The program file, or an open text or binary stream.
    format : {"gcode", "pgm", "csv"}, optional
        Format; default by suffix (``.csv``, ``.pgm``) and content (a first line
        ``;DIFFSYS``), G-code otherwise.
    units : {"mm", "inch"}, default: "mm"
        Units of X, Z and feeds until the program sets them (G70/G71, a DIFFSYS
        ``Units`` header). Not used for CSV, whose header states them.
    max_iterations : int, default: 1_000_000
        Cap on the iterations of one WHILE loop.

    Returns
    -------
    NCProgram
        Motion blocks in execution order, SI units.

    Raises
    ------
    ConfigError
        One line naming the file, the line number, the code and what is supported:
        unknown G codes or words, values that are not numbers, a WHILE without END,
        a loop over the iteration cap, a variable used before it is set, a missing
        file.

    Notes
    -----
    The dialect, the link-move rule, signs and frames are described in the module
    docstring (:mod:`servosurf.toolpath._nc`).

    Examples
    --------
    >>> import io
    >>> prog = read_nc_program(io.StringIO("G71 G90\\nC0 X1 Z0\\nC90 X0.5 Z0\\n"))
    >>> prog.x.tolist(), prog.cutting.tolist()
    ([0.001, 0.0005], [True, True])
    """
    if format is not None and format not in NC_FORMATS:
        raise ConfigError(f"format must be one of {', '.join(NC_FORMATS)}, got "
                          f"{format!r}")
    if units not in ("mm", "inch"):
        raise ConfigError(f"units must be 'mm' or 'inch', got {units!r}")
    if isinstance(max_iterations, bool) or not isinstance(max_iterations, int) or \
            max_iterations < 1:
        raise ConfigError(f"max_iterations must be a positive integer, got "
                          f"{max_iterations!r}")
    text, name = _read_text(source)
    fmt = format or _detect(name, text)
    if fmt == "csv":
        return _read_csv(text, name)
    return _read_gcode(text, name, fmt, _INCH if units == "inch" else _MM,
                       max_iterations)
