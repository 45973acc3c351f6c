"""Frozen-dataclass configuration loaded from TOML.

Every configuration section is a ``@dataclass(frozen=True)``. Each field declares its
unit, a one-line description and optional bounds through :func:`param`::

    mass: float = param(0.055, unit="kg", doc="coil carrier mass", low=0.0)

:func:`from_mapping` builds a dataclass tree from a (TOML) mapping. TOML keys are
kebab-case and map to snake_case fields. Unknown keys, wrong types and out-of-range
values raise :class:`~servosurf.errors.ConfigError` naming the dotted key, with
``difflib`` suggestions for misspelt keys.
"""

from __future__ import annotations

import dataclasses
import difflib
import math
import tomllib
import types
import typing
from collections.abc import Mapping
from pathlib import Path
from typing import Any, Literal, TypeVar, get_args, get_origin

from .errors import ConfigError

__all__ = [
    "param",
    "from_mapping",
    "to_mapping",
    "load_toml",
    "dump_toml",
    "describe",
]

T = TypeVar("T")


def param(
    default: Any = dataclasses.MISSING,
    *,
    unit: str = "",
    doc: str = "",
    source: str = "",
    low: float | None = None,
    high: float | None = None,
    low_open: bool = False,
    plausible: tuple[float, float] | None = None,
    default_factory: Any = dataclasses.MISSING,
) -> Any:
    """Declare a configuration field with its unit, description, source and bounds.

    Parameters
    ----------
    default : object, optional
        Default value. Omit for a required field.
    unit : str
        SI unit of the value ("" for dimensionless).
    doc : str
        One-line description.
    source : str
        Where the default comes from (paper value, calibration and against what).
    low, high : float, optional
        Inclusive bounds checked on construction.
    low_open : bool, default: False
        Make the lower bound exclusive (``value > low``).
    plausible : (float, float), optional
        Physically plausible range, in ``unit``: a file value outside it (a unit
        slip such as ``amplitude = 10`` meant in um) is refused, naming the slip.
    default_factory : callable, optional
        Factory for mutable defaults.

    Returns
    -------
    dataclasses.Field
        The field descriptor.
    """
    meta = {
        "unit": unit,
        "doc": doc,
        "source": source,
        "low": low,
        "high": high,
        "low_open": low_open,
        "plausible": plausible,
    }
    kw: dict[str, Any] = {"metadata": meta}
    if default is not dataclasses.MISSING:
        kw["default"] = default
    if default_factory is not dataclasses.MISSING:
        kw["default_factory"] = default_factory
    return dataclasses.field(**kw)


def _kebab(name: str) -> str:
    return name.replace("_", "-")


def _type_name(tp: Any) -> str:
    if isinstance(tp, type):
        return tp.__name__
    return str(tp).replace("typing.", "")


def _check_bounds(value: Any, meta: Mapping[str, Any], dotted: str,
                  default: Any = None) -> None:
    if not isinstance(value, int | float) or isinstance(value, bool):
        return
    low, high = meta.get("low"), meta.get("high")
    unit = meta.get("unit") or ""
    u = f" {unit}" if unit else ""
    if not math.isfinite(value):
        raise ConfigError(f"{dotted} must be finite, got {value!r}")
    if low is not None:
        if meta.get("low_open") and not value > low:
            raise ConfigError(f"{dotted} must be > {low:g}{u}, got {value!r}")
        if not meta.get("low_open") and value < low:
            raise ConfigError(f"{dotted} must be >= {low:g}{u}, got {value!r}")
    if high is not None and value > high:
        raise ConfigError(f"{dotted} must be <= {high:g}{u}, got {value!r}")
    plausible = meta.get("plausible")
    if plausible is not None:
        from ._validation import check_plausible

        typical = default if isinstance(default, int | float) else None
        check_plausible(value, name=dotted, unit=unit, low=plausible[0],
                        high=plausible[1], what=meta.get("doc") or "",
                        typical=typical)


def _convert(value: Any, tp: Any, dotted: str) -> Any:
    """Convert a TOML value to the annotated type ``tp`` or raise ConfigError."""
    origin = get_origin(tp)
    if tp is Any:
        return value
    if dataclasses.is_dataclass(tp):
        if not isinstance(value, Mapping):
            raise ConfigError(f"{dotted}: expected a table, got {type(value).__name__}")
        return from_mapping(tp, value, prefix=dotted)
    if origin is Literal:
        allowed = get_args(tp)
        if value not in allowed:
            sugg = difflib.get_close_matches(str(value), [str(a) for a in allowed], 1)
            hint = f" Did you mean: {sugg[0]!r}?" if sugg else ""
            raise ConfigError(
                f"{dotted} must be one of {', '.join(map(repr, allowed))}, "
                f"got {value!r}.{hint}"
            )
        return value
    if origin in (typing.Union, types.UnionType):
        args = get_args(tp)
        if value is None and type(None) in args:
            return None
        errors = []
        for a in args:
            if a is type(None):
                continue
            try:
                return _convert(value, a, dotted)
            except ConfigError as exc:
                errors.append(str(exc))
        raise ConfigError(
            f"{dotted}: expected {_type_name(tp)}, got {type(value).__name__}"
        )
    if origin in (tuple, list):
        args = get_args(tp)
        if not isinstance(value, list | tuple):
            raise ConfigError(f"{dotted}: expected a list, got {type(value).__name__}")
        if origin is tuple and args and args[-1] is not Ellipsis:
            if len(args) != len(value):
                raise ConfigError(
                    f"{dotted}: expected {len(args)} items, got {len(value)}"
                )
            return tuple(
                _convert(v, a, f"{dotted}[{i}]")
                for i, (v, a) in enumerate(zip(value, args, strict=True))
            )
        inner = args[0] if args else Any
        out = [_convert(v, inner, f"{dotted}[{i}]") for i, v in enumerate(value)]
        return tuple(out) if origin is tuple else out
    if tp is float:
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise ConfigError(f"{dotted}: expected float, got {type(value).__name__}")
        return float(value)
    if tp is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise ConfigError(f"{dotted}: expected int, got {type(value).__name__}")
        return value
    if tp is bool:
        if not isinstance(value, bool):
            raise ConfigError(f"{dotted}: expected bool, got {type(value).__name__}")
        return value
    if tp is str:
        if not isinstance(value, str):
            raise ConfigError(f"{dotted}: expected str, got {type(value).__name__}")
        return value
    if isinstance(tp, type) and not isinstance(value, tp):
        raise ConfigError(
            f"{dotted}: expected {tp.__name__}, got {type(value).__name__}"
        )
    return value


def from_mapping(cls: type[T], data: Mapping[str, Any], *, prefix: str = "") -> T:
    """Build the frozen dataclass ``cls`` from a mapping with kebab-case keys.

    Parameters
    ----------
    cls : type
        A dataclass type whose fields were declared with :func:`param` or nested
        dataclasses.
    data : Mapping
        Keys are kebab-case (``moving-mass``) or snake_case field names.
    prefix : str, optional
        Dotted prefix used in error messages.

    Returns
    -------
    object
        An instance of ``cls``.

    Raises
    ------
    ConfigError
        On unknown keys (with suggestions), wrong types or out-of-range values.
    """
    hints = typing.get_type_hints(cls)
    fields = {f.name: f for f in dataclasses.fields(cls) if f.init}
    by_key = {_kebab(n): n for n in fields} | {n: n for n in fields}
    kwargs: dict[str, Any] = {}
    for key, value in data.items():
        dotted = f"{prefix}.{key}" if prefix else str(key)
        name = by_key.get(key)
        if name is None:
            known = sorted(_kebab(n) for n in fields)
            sugg = difflib.get_close_matches(str(key), known, n=1, cutoff=0.6)
            hint = (
                f" Did you mean: {prefix + '.' if prefix else ''}{sugg[0]}?"
                if sugg
                else ""
            )
            raise ConfigError(
                f"unknown key {dotted!r}.{hint} Allowed keys here: {', '.join(known)}"
            )
        f = fields[name]
        converted = _convert(value, hints[name], dotted)
        _check_bounds(converted, f.metadata, dotted, f.default)
        kwargs[name] = converted
    missing = [
        n
        for n, f in fields.items()
        if n not in kwargs
        and f.default is dataclasses.MISSING
        and f.default_factory is dataclasses.MISSING
    ]
    if missing:
        keys = ", ".join(
            f"{prefix + '.' if prefix else ''}{_kebab(n)}" for n in missing
        )
        raise ConfigError(f"missing required key(s): {keys}")
    try:
        return cls(**kwargs)
    except ConfigError as exc:
        if prefix and not str(exc).startswith(prefix):
            raise ConfigError(f"{prefix}.{exc}") from None
        raise


def to_mapping(obj: Any) -> dict[str, Any]:
    """Return a kebab-case mapping of a dataclass tree (the inverse of from_mapping)."""
    out: dict[str, Any] = {}
    for f in dataclasses.fields(obj):
        v = getattr(obj, f.name)
        if dataclasses.is_dataclass(v):
            v = to_mapping(v)
        elif isinstance(v, tuple):
            v = [to_mapping(x) if dataclasses.is_dataclass(x) else x for x in v]
        if v is None:
            continue
        out[_kebab(f.name)] = v
    return out


def load_toml(path: str | Path) -> dict[str, Any]:
    """Read a TOML file or raise :class:`ConfigError` naming the file.

    Parameters
    ----------
    path : str or Path
        The TOML file.

    Returns
    -------
    dict
        The parsed document.
    """
    p = Path(path)
    try:
        with p.open("rb") as fh:
            return tomllib.load(fh)
    except FileNotFoundError:
        raise ConfigError(f"{p}: file not found") from None
    except IsADirectoryError:
        raise ConfigError(f"{p}: is a directory, expected a TOML file") from None
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"{p}: invalid TOML: {exc}") from None
    except UnicodeDecodeError as exc:  # e.g. a Latin-1 "µm" in a comment
        raise ConfigError(_encoding_message(p, exc)) from None


def _encoding_message(path: Path, exc: UnicodeDecodeError) -> str:
    """One line naming the line and byte of a non-UTF-8 TOML file."""
    data = exc.object if isinstance(exc.object, bytes) else b""
    line = data.count(b"\n", 0, exc.start) + 1
    bad = data[exc.start:exc.end]
    return (
        f"{path}: not UTF-8 text (byte 0x{bad.hex() or '??'} on line {line}, likely "
        "a Latin-1 or Windows-1252 character such as µ or °); TOML files must be "
        "UTF-8: save the file as UTF-8 or write um instead of µm"
    )


def _toml_value(v: Any) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        return repr(v) if math.isfinite(v) else ("inf" if v > 0 else "-inf")
    if isinstance(v, str):
        return '"' + v.replace("\\", "\\\\").replace('"', '\\"') + '"'
    if isinstance(v, list | tuple):
        return "[" + ", ".join(_toml_value(x) for x in v) + "]"
    raise TypeError(f"cannot write {type(v).__name__} to TOML")


def _toml_key(k: str) -> str:
    """A bare TOML key, or a quoted one when it holds other characters (dots)."""
    import re

    return k if re.fullmatch(r"[A-Za-z0-9_-]+", k) else _toml_value(k)


def dump_toml(data: Mapping[str, Any], *, header: str = "") -> str:
    """Serialise a nested mapping of plain values to TOML text.

    Parameters
    ----------
    data : Mapping
        Nested mapping of bool, int, float, str, lists and sub-mappings.
    header : str, optional
        Comment lines written first (without the leading ``#``).

    Returns
    -------
    str
        TOML text that :func:`tomllib.loads` reads back to ``data``.
    """
    lines = [f"# {h}" for h in header.splitlines()] if header else []

    def is_table_array(v: Any) -> bool:
        return (
            isinstance(v, list | tuple)
            and bool(v)
            and all(isinstance(x, Mapping) for x in v)
        )

    def emit(table: Mapping[str, Any], path: str, array: bool = False) -> None:
        scalars = {
            k: v
            for k, v in table.items()
            if not isinstance(v, Mapping) and not is_table_array(v)
        }
        subs = {k: v for k, v in table.items() if isinstance(v, Mapping)}
        arrays = {k: v for k, v in table.items() if is_table_array(v)}
        if array:
            lines.append(f"\n[[{path}]]")
        elif path and scalars:
            lines.append(f"\n[{path}]")
        for k, v in scalars.items():
            lines.append(f"{_toml_key(k)} = {_toml_value(v)}")
        for k, v in subs.items():
            emit(v, f"{path}.{k}" if path else k)
        for k, v in arrays.items():
            for item in v:
                emit(item, f"{path}.{k}" if path else k, array=True)

    emit(data, "")
    return "\n".join(lines).lstrip("\n") + "\n"


def describe(cls: type, *, prefix: str = "") -> list[dict[str, Any]]:
    """List every field of a dataclass tree with its unit, doc, source and default.

    Parameters
    ----------
    cls : type
        A dataclass type.
    prefix : str, optional
        Dotted prefix.

    Returns
    -------
    list of dict
        One entry per leaf field: ``key``, ``unit``, ``doc``, ``source``, ``default``.
    """
    rows: list[dict[str, Any]] = []
    hints = typing.get_type_hints(cls)
    for f in dataclasses.fields(cls):
        key = f"{prefix}.{_kebab(f.name)}" if prefix else _kebab(f.name)
        tp = hints[f.name]
        if dataclasses.is_dataclass(tp):
            rows.extend(describe(tp, prefix=key))
            continue
        default = f.default if f.default is not dataclasses.MISSING else None
        rows.append(
            {
                "key": key,
                "unit": f.metadata.get("unit", ""),
                "doc": f.metadata.get("doc", ""),
                "source": f.metadata.get("source", ""),
                "default": default,
            }
        )
    return rows
