"""The package's architecture: imports only go down, no package cycle, no reaching
into another package's private module, the CLI on top, kernels own numba.

Every module's imports are read with :mod:`ast` (module-level and function-local,
``TYPE_CHECKING`` blocks included) and resolved to their target module; the layer
order is the one stated in ``servosurf/__init__.py``'s docstring (``LAYERS``).
"""

from __future__ import annotations

import ast
import re
from collections import defaultdict
from pathlib import Path

import pytest

import servosurf

SRC = Path(servosurf.__file__).resolve().parent

#: Units of the architecture: a subpackage or a top-level module of servosurf.
LAYERS = servosurf.LAYERS

#: Known violations, each (kind, source unit or module, target), kind one of "up",
#: "private", "cycle", "njit", "rng", "knob". None is left: keep it empty.
ALLOWED: set[tuple[str, str, str]] = set()


def _modules() -> dict[str, Path]:
    out = {}
    for path in sorted(SRC.rglob("*.py")):
        rel = path.relative_to(SRC.parent).with_suffix("")
        parts = list(rel.parts)
        if parts[-1] == "__init__":
            parts = parts[:-1]
        out[".".join(parts)] = path
    return out


MODULES = _modules()


def _is_package(name: str) -> bool:
    return MODULES[name].name == "__init__.py"


def _resolve(module: str, node: ast.ImportFrom) -> list[str]:
    """Absolute names a ``from ... import ...`` statement in ``module`` reaches."""
    if node.level:
        base = module.split(".")
        if not _is_package(module):
            base = base[:-1]
        base = base[: len(base) - (node.level - 1)]
        prefix = ".".join(base + ([node.module] if node.module else []))
    else:
        prefix = node.module or ""
    out = []
    for alias in node.names:
        full = f"{prefix}.{alias.name}"
        # ``from .. import _parts`` names a module; ``from ..x import f`` a name
        out.append(full if full in MODULES else prefix)
    return out


def imports(module: str) -> list[tuple[str, int, str]]:
    """(target module, line, enclosing function or "") of every servosurf import."""
    tree = ast.parse(MODULES[module].read_text(encoding="utf-8"))
    found = []

    def visit(node, func: str) -> None:
        for child in ast.iter_child_nodes(node):
            if isinstance(child, ast.FunctionDef | ast.AsyncFunctionDef):
                visit(child, child.name)
                continue
            if isinstance(child, ast.Import):
                names = [a.name for a in child.names]
            elif isinstance(child, ast.ImportFrom):
                names = _resolve(module, child)
            else:
                visit(child, func)
                continue
            for name in names:
                if name == "servosurf" or name.startswith("servosurf."):
                    found.append((name, child.lineno, func))

    visit(tree, "")
    return found


def unit(module: str) -> str:
    """The architecture unit of a module: ``servo``, ``_parts``, ``cli``, ..."""
    parts = module.split(".")
    return parts[1] if len(parts) > 1 else ""


def rank(u: str) -> int:
    for i, layer in enumerate(LAYERS):
        if u in layer:
            return i
    raise AssertionError(f"servosurf.{u} is in no layer of servosurf.LAYERS")


def _private_target(src: str, dst: str) -> bool:
    """``dst`` is a private module of another unit than ``src``'s."""
    if unit(src) == unit(dst):
        return False
    return any(p.startswith("_") for p in dst.split(".")[2:])


#: The CLI units: nothing below them imports them.
CLI = ("commands", "cli", "__main__")


def _plot_delegation(dst: str, func: str) -> bool:
    """A result's ``plot`` method importing the public viz package (by design)."""
    return func == "plot" and dst == "servosurf.viz"


def _kernel_call(src: str, dst: str) -> bool:
    """A library module's checked public function calling its numba kernel.

    Kernels are private functions in ``kernels/_*.py`` by design (STYLE.md 2); the
    public wrapper that checks the inputs lives in the package that owns the
    capability. The CLI never calls a kernel.
    """
    return unit(dst) == "kernels" and unit(src) not in CLI


def violations() -> set[tuple[str, str, str]]:
    """Upward and private cross-package imports: (kind, module, target)."""
    out = set()
    for mod in MODULES:
        if mod == "servosurf":
            continue
        for dst, _line, func in imports(mod):
            if dst == "servosurf":
                continue
            a, b = unit(mod), unit(dst)
            if a != b and rank(b) > rank(a) and not _plot_delegation(dst, func):
                out.add(("up", mod, dst))
            if _private_target(mod, dst) and not _kernel_call(mod, dst):
                out.add(("private", mod, dst))
    return out


def unit_graph() -> dict[str, set[str]]:
    g: dict[str, set[str]] = defaultdict(set)
    for mod in MODULES:
        if mod == "servosurf":
            continue
        for dst, _line, _func in imports(mod):
            if dst != "servosurf" and unit(dst) != unit(mod):
                g[unit(mod)].add(unit(dst))
    return g


def cycles(g: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components with more than one unit (Tarjan)."""
    index, low, stack, on, out = {}, {}, [], set(), []
    counter = [0]

    def visit(v):
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on.add(v)
        for w in sorted(g.get(v, ())):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(sorted(comp))

    for v in sorted(g):
        if v not in index:
            visit(v)
    return out


def _allowed(kind: str) -> set[tuple[str, str]]:
    return {(m, t) for k, m, t in ALLOWED if k == kind}


# ------------------------------------------------------------------ the layers
def test_every_unit_is_in_one_layer():
    units = {unit(m) for m in MODULES if m != "servosurf"}
    named = [u for layer in LAYERS for u in layer]
    assert len(named) == len(set(named)), "a unit is named in two layers"
    assert units == set(named), (sorted(units - set(named)),
                                 sorted(set(named) - units))


def test_layers_are_stated_in_the_package_docstring():
    doc = servosurf.__doc__
    for layer in LAYERS:
        for u in layer:
            assert f"``{u}``" in doc, u


def test_imports_only_go_down():
    up = {(m, t) for k, m, t in violations() if k == "up"}
    assert up <= _allowed("up"), sorted(up - _allowed("up"))


def test_no_private_module_of_another_package():
    private = {(m, t) for k, m, t in violations() if k == "private"}
    assert private <= _allowed("private"), sorted(private - _allowed("private"))


def test_no_package_cycle():
    assert cycles(unit_graph()) == []


def test_library_never_imports_the_cli():
    bad = sorted((m, t) for m in MODULES if unit(m) not in CLI and m != "servosurf"
                 for t, _line, _f in imports(m) if unit(t) in CLI)
    assert bad == []


def test_allow_list_is_not_stale():
    """Every allowed violation still exists (remove entries as they are fixed)."""
    found = violations()
    found |= {("knob", m, "") for m, path in MODULES.items() if _knob_changes(path)}
    stale = [v for v in ALLOWED if v not in found]
    assert stale == []


# ------------------------------------------------------------------ thin commands
def _third_party_imports(path: Path) -> set[str]:
    tree = ast.parse(path.read_text(encoding="utf-8"))
    out = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            out.update(a.name.split(".")[0] for a in node.names)
        elif isinstance(node, ast.ImportFrom) and not node.level and node.module:
            out.add(node.module.split(".")[0])
    return out


@pytest.mark.parametrize("name", sorted(m for m in MODULES if unit(m) in CLI))
def test_commands_draw_no_figures(name):
    """Commands parse, call the library and write: figures live in viz."""
    used = _third_party_imports(MODULES[name])
    assert not used & {"matplotlib", "pyvista", "trimesh"}, used


# ------------------------------------------------------------------ kernels
_NUMBA_DECORATORS = {"njit", "jit", "vectorize", "guvectorize", "stencil", "cfunc",
                     "generated_jit"}


def _numba_names(tree: ast.AST) -> set[str]:
    """Local names bound to numba's compiling decorators (``from numba import ...``)."""
    out = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom) and node.module == "numba":
            out.update(a.asname or a.name for a in node.names
                       if a.name in _NUMBA_DECORATORS)
    return out


def _compiled_in(path: Path) -> list[int]:
    """Lines that compile with numba (``@njit``, ``numba.njit(...)``, ...)."""
    tree = ast.parse(path.read_text(encoding="utf-8"))
    local = _numba_names(tree)
    lines = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Name) and node.id in local:
            lines.append(node.lineno)
        elif (isinstance(node, ast.Attribute) and node.attr in _NUMBA_DECORATORS
              and isinstance(node.value, ast.Name) and node.value.id == "numba"):
            lines.append(node.lineno)
    return lines


def test_numba_compiles_only_in_kernels():
    bad = sorted((m, line) for m, path in MODULES.items() if unit(m) != "kernels"
                 for line in _compiled_in(path)
                 if ("njit", m, "") not in ALLOWED)
    assert bad == []


def _fastmath_values(path: Path) -> list[tuple[int, str]]:
    """(line, source) of every ``fastmath=`` keyword argument."""
    text = path.read_text(encoding="utf-8")
    tree = ast.parse(text)
    return [(kw.value.lineno, ast.unparse(kw.value)) for node in ast.walk(tree)
            if isinstance(node, ast.Call) for kw in node.keywords
            if kw.arg == "fastmath"]


def _fastmath_aliases(path: Path) -> set[str]:
    """Names bound to ``kernels._config.FASTMATH`` in a module."""
    tree = ast.parse(path.read_text(encoding="utf-8"))
    out = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom) and (node.module or "").endswith("_config"):
            out.update(a.asname or a.name for a in node.names if a.name == "FASTMATH")
    return out


def test_every_fastmath_is_the_shared_constant():
    """No module sets a fastmath other than ``kernels._config.FASTMATH``."""
    bad = []
    for m, path in MODULES.items():
        ok = _fastmath_aliases(path)
        bad += [(m, line, v) for line, v in _fastmath_values(path) if v not in ok]
    assert bad == []


def test_compiled_kernels_use_the_shared_fastmath():
    """Every compiled dispatcher of the package carries exactly FASTMATH."""
    import importlib

    from numba.core.registry import CPUDispatcher

    from servosurf.kernels._config import FASTMATH

    assert {"nnan", "ninf", "fast"}.isdisjoint(FASTMATH)
    seen = 0
    for m, path in MODULES.items():
        if "numba" not in path.read_text(encoding="utf-8"):
            continue
        mod = importlib.import_module(m)
        for name, obj in vars(mod).items():
            if isinstance(obj, CPUDispatcher) and obj.__module__ == m:
                seen += 1
                assert unit(m) == "kernels", (m, name)
                assert set(obj.targetoptions.get("fastmath", ())) == FASTMATH, (
                    m, name)
    assert seen > 10  # the kernels were found


# ------------------------------------------------------------------ process knobs
#: Calls that change a process knob for the rest of the process.
_PERMANENT = {"set_quiet", "set_defaults", "reset_defaults", "reuse_freed_memory",
              "set_num_threads", "mallopt", "threadpool_limits", "putenv"}
#: Where knobs are defined or set by an entry point (the CLI's -q).
_KNOB_OWNERS = {"servosurf._defaults", "servosurf._progress", "servosurf.cli",
                "servosurf"}


def _knob_changes(path: Path) -> list[int]:
    """Lines that change a process knob outside a scoped ``with`` block's helper."""
    tree = ast.parse(path.read_text(encoding="utf-8"))
    lines = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Call):
            f = node.func
            name = f.id if isinstance(f, ast.Name) else getattr(f, "attr", "")
            if name in _PERMANENT:
                lines.append(node.lineno)
        elif isinstance(node, ast.Assign | ast.AugAssign):
            targets = node.targets if isinstance(node, ast.Assign) else [node.target]
            for t in targets:
                if isinstance(t, ast.Subscript) and ast.unparse(t.value) in (
                        "defaults", "os.environ", "_QUIET"):
                    lines.append(node.lineno)
    return lines


def test_library_never_changes_a_process_knob_for_good():
    """Library code uses ``defaults_override``/``numba_threads``/``malloc_reuse``
    (restored on exit); only entry points set knobs for the process."""
    bad = sorted((m, line) for m, path in MODULES.items()
                 if m not in _KNOB_OWNERS and unit(m) != "commands"
                 for line in _knob_changes(path)
                 if ("knob", m, "") not in ALLOWED)
    assert bad == []


# ------------------------------------------------------------------ random streams
def test_random_streams_start_in_one_module():
    """Every generator is started in servosurf/_random.py (one seed, named streams)."""
    pattern = re.compile(r"\b(default_rng|SeedSequence|RandomState)\s*\(|"
                         r"np\.random\.(seed|normal|uniform|rand|randn|standard_normal)"
                         r"\s*\(")
    bad = []
    for m, path in MODULES.items():
        if m == "servosurf._random":
            continue
        tree = ast.parse(path.read_text(encoding="utf-8"))
        for node in ast.walk(tree):
            if isinstance(node, ast.Call) and pattern.search(ast.unparse(node.func)
                                                             + "("):
                if ("rng", m, "") not in ALLOWED:
                    bad.append((m, node.lineno))
    assert bad == []


if __name__ == "__main__":
    for v in sorted(violations()):
        print(v)
    print(cycles(unit_graph()))
