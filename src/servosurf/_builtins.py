"""Built-in definition files shipped with servosurf (toolpaths, workpieces).

The files live once in the repository, in ``toolpaths/`` and ``workpieces/`` at its
root; ``src/servosurf/data/toolpaths`` and ``data/workpieces`` are symbolic links to
them, so the wheel ships them as package data and an installed servosurf finds them
from any folder. A built-in *name* (the file name without ``.toml``) works wherever a
path does: ``servosurf simulate lenslet_5um``.

Resolution rule (:func:`resolve_file`): an existing file wins (the user's own file,
even if it shares a built-in's name); otherwise a bare name (no folder part), with or
without ``.toml``, selects the built-in; otherwise the error lists the built-ins.
"""

from __future__ import annotations

import tomllib
from importlib import resources
from pathlib import Path

from .errors import ConfigError

__all__ = ["KINDS", "builtin_files", "builtin_description", "resolve_file"]

#: Kinds of built-in files: kind -> folder under ``servosurf/data``.
KINDS = {"toolpath": "toolpaths", "workpiece": "workpieces"}


def builtin_files(kind: str) -> dict[str, Path]:
    """Return ``{name: path}`` of the built-in files of one kind, sorted by name.

    Parameters
    ----------
    kind : {"toolpath", "workpiece"}
        Which files.

    Returns
    -------
    dict of str to Path
        Name (file name without ``.toml``) and path of each built-in file.
    """
    if kind not in KINDS:
        raise ConfigError(f"unknown built-in kind {kind!r}; have {', '.join(KINDS)}")
    root = Path(str(resources.files("servosurf") / "data" / KINDS[kind]))
    if not root.is_dir():
        return {}
    return {p.stem: p for p in sorted(root.glob("*.toml"))}


def builtin_description(path: str | Path) -> str:
    """The ``description`` string of a definition file ("" when absent or unreadable).

    Parameters
    ----------
    path : str or Path
        A TOML file.

    Returns
    -------
    str
        Its top-level ``description`` value.
    """
    try:
        with open(path, "rb") as fh:
            desc = tomllib.load(fh).get("description", "")
    except (OSError, tomllib.TOMLDecodeError, UnicodeDecodeError):
        return ""
    return desc if isinstance(desc, str) else ""


def resolve_file(source: str | Path, *, kind: str) -> Path:
    """A definition file's path from a path or a built-in name.

    Parameters
    ----------
    source : str or Path
        A path to a TOML file, or the name of a built-in file of ``kind`` (with or
        without ``.toml``; see ``servosurf toolpaths``).
    kind : {"toolpath", "workpiece"}
        Which built-ins a bare name selects.

    Returns
    -------
    Path
        The file to read.

    Raises
    ------
    ConfigError
        When ``source`` is neither an existing file nor a built-in name; the message
        lists the built-ins.
    """
    p = Path(source)
    if p.is_file():
        return p
    builtins = builtin_files(kind)
    name = p.name[:-5] if p.name.endswith(".toml") else p.name
    if p.parent == Path(".") and name in builtins:
        return builtins[name]
    if p.is_dir():
        raise ConfigError(f"{kind} {str(source)!r}: is a folder, expected a TOML file")
    if name in builtins:
        raise ConfigError(
            f"{kind} {str(source)!r} not found here; to use the built-in {kind} of "
            f"that name give the name alone: {name}"
        )
    have = ", ".join(builtins) or "none"
    raise ConfigError(
        f"{kind} {str(source)!r} not found: no such file and no built-in {kind} of "
        f"that name (built-in {KINDS[kind]}: {have}; `servosurf toolpaths` lists "
        "them)"
    )
