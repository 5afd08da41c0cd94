"""Strict loading of TOML files into frozen config dataclasses, and the reverse for JSON records.

Every config in roft_sim is a ``@dataclass(frozen=True, slots=True, kw_only=True)`` whose
``__post_init__`` validates values. This module turns a TOML table into such a dataclass, with
errors that name the file, the dotted key and the fix:

- unknown keys are errors (with a "did you mean" suggestion);
- missing required keys are errors;
- values are checked against the field's type hint (bool, int, float, str, Path, Literal,
  tuple[...], list[...], dict[str, ...], Optional, nested dataclasses, and unions of dataclasses
  told apart by their ``kind: Literal[...]`` field);
- ``ConfigError`` raised by ``__post_init__`` is re-raised with the key path in front.

TOML has no null: an optional value (``X | None``) is set to None with the string
:data:`NONE_SPELLING` (``"none"``), unless ``"none"`` is itself a value of the field (a string,
a path, a Literal holding it).
"""

from __future__ import annotations

import dataclasses
import difflib
import enum
import functools
import json
import math
import re
import tomllib
import types
import typing
from collections.abc import Mapping
from pathlib import Path
from typing import Any, Literal, TypeVar, get_args, get_origin, get_type_hints

import numpy as np

from roft_sim.errors import ConfigError, located

T = TypeVar("T")

_INDEX_SUFFIX = re.compile(r"\[\d+\]$")

NONE_SPELLING = "none"
"""How a TOML file sets an optional value (``X | None``) to None (TOML has no null)."""

__all__ = [
    "load_toml",
    "toml_value",
    "dataclass_from_mapping",
    "load_dataclass_toml",
    "jsonable",
    "NONE_SPELLING",
]


def load_toml(path: str | Path) -> dict[str, Any]:
    """Reads a TOML file.

    Raises:
        ConfigError: the file is missing or is not valid TOML (the message gives the line).
    """
    path = Path(path)
    try:
        with path.open("rb") as f:
            return tomllib.load(f)
    except FileNotFoundError:
        raise ConfigError(f"config file {located(path)} does not exist; check the path") from None
    except tomllib.TOMLDecodeError as e:
        raise ConfigError(f"{located(path)} is not valid TOML: {e}") from None


def load_dataclass_toml(cls: type[T], path: str | Path, *, table: str | None = None) -> T:
    """Loads ``cls`` from a TOML file, or from one top-level ``table`` of it."""
    data: Any = load_toml(path)
    where = str(path)
    if table is not None:
        if table not in data:
            raise ConfigError(f"{located(path)} has no [{table}] table; add one")
        data, where = data[table], f"{path} [{table}]"
    return dataclass_from_mapping(cls, data, where=where)


def dataclass_from_mapping(cls: type[T], data: Mapping[str, Any], *, where: str = "config") -> T:
    """Builds the dataclass ``cls`` from a mapping, strictly.

    Args:
        cls: a dataclass type; nested dataclass fields are built recursively.
        data: keys are field names.
        where: prefix for error messages, e.g. the file name.

    Raises:
        ConfigError: unknown key, missing key, wrong type or a value rejected by the class.
    """
    built: T = _convert(cls, data, where)
    return built


def _field_path(where: str, key: str | int) -> str:
    """``where.key``, ``where[i]``; after a file name or ``file [table]`` a space separates."""
    if isinstance(key, int):
        return f"{where}[{key}]"
    if (
        not where
        or where.endswith(":")
        or (where.endswith("]") and not _INDEX_SUFFIX.search(where))
    ):
        return f"{where} {key}".strip()
    return f"{where}.{key}"


def _default_value(f: dataclasses.Field[Any]) -> Any:
    """A field's default value (calling its factory), or MISSING."""
    if f.default is not dataclasses.MISSING:
        return f.default
    if f.default_factory is not dataclasses.MISSING:
        return f.default_factory()
    return dataclasses.MISSING


def _build_dataclass(cls: type, data: Any, where: str, base: Any = None) -> Any:
    """``cls`` from the table ``data``. Keys absent from ``data`` keep ``base``'s values when
    ``base`` (an instance of ``cls``: the enclosing dataclass's default for this field) is
    given, else ``cls``'s own defaults; so a partial nested table overrides single keys of
    what the enclosing class would otherwise hold (e.g. ``[gate] probability = 0.99`` keeps
    ROFT's default gate switched on)."""
    if not isinstance(data, Mapping):
        raise ConfigError(
            f"{where}: expected a table of {cls.__name__} settings, got {type(data).__name__} "
            f"{data!r}"
        )
    fields = {f.name: f for f in dataclasses.fields(cls) if f.init}
    unknown = [k for k in data if k not in fields]
    if unknown:
        key = unknown[0]
        close = difflib.get_close_matches(str(key), list(fields), n=1)
        hint = f"did you mean {close[0]!r}? " if close else ""
        raise ConfigError(
            f"{where}: unknown key {key!r} for {cls.__name__}; {hint}"
            f"valid keys: {', '.join(sorted(fields))}"
        )
    hints = _type_hints(cls)
    kwargs: dict[str, Any] = {}
    for name, f in fields.items():
        if name not in data:
            if f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING:
                raise ConfigError(f"{where}: missing required key {name!r} for {cls.__name__}")
            continue
        tp, path = hints[name], _field_path(where, name)
        if (
            dataclasses.is_dataclass(tp)
            and isinstance(tp, type)
            and isinstance(data[name], Mapping)
        ):
            inner = getattr(base, name) if base is not None else _default_value(f)
            inner = inner if isinstance(inner, tp) else None
            kwargs[name] = _build_dataclass(tp, data[name], path, inner)
        else:
            kwargs[name] = _convert(tp, data[name], path)
    if base is not None:
        kept = {n: getattr(base, n) for n in fields if n not in data}
        kwargs = {**kept, **kwargs}
    try:
        return cls(**kwargs)
    except ConfigError as e:
        raise ConfigError(f"{where}: {e}") from None
    except (TypeError, ValueError) as e:
        raise ConfigError(f"{where}: invalid {cls.__name__}: {e}") from None


def _takes_strings(tp: Any) -> bool:
    """True if ``"none"`` may itself be a value of type ``tp`` (str, Path, Any, a Literal
    holding "none"), so that it is not read as None."""
    if tp is Any or tp is str or tp is Path:
        return True
    if get_origin(tp) is Literal:
        return NONE_SPELLING in get_args(tp)
    return False


def _type_name(tp: Any) -> str:
    return getattr(tp, "__name__", None) or str(tp).replace("typing.", "")


def _convert(tp: Any, value: Any, where: str) -> Any:
    origin = get_origin(tp)
    if tp is Any:
        return value
    if dataclasses.is_dataclass(tp) and isinstance(tp, type):
        return _build_dataclass(tp, value, where)
    if origin in (typing.Union, types.UnionType):
        return _convert_union(get_args(tp), value, where)
    if origin is Literal:
        allowed = get_args(tp)
        if value not in allowed or type(value) is not type(allowed[allowed.index(value)]):
            raise ConfigError(
                f"{where}: got {value!r}, expected one of {', '.join(repr(a) for a in allowed)}"
            )
        return value
    if tp in (bool, int, float, str, Path):
        return _convert_scalar(tp, value, where)
    if isinstance(tp, type) and issubclass(tp, enum.Enum):
        try:
            return tp(value)
        except ValueError:
            members = ", ".join(repr(m.value) for m in tp)
            raise ConfigError(f"{where}: got {value!r}, expected one of {members}") from None
    if origin in (tuple, list):
        return _convert_sequence(tp, value, where)
    if origin in (dict, Mapping) or tp is dict:
        if not isinstance(value, Mapping):
            raise ConfigError(f"{where}: expected a table, got {value!r}")
        args = get_args(tp)
        val_tp = args[1] if len(args) == 2 else Any
        return {str(k): _convert(val_tp, v, _field_path(where, str(k))) for k, v in value.items()}
    raise TypeError(f"config_files cannot convert to type {tp!r} (at {where})")


def _convert_union(args: tuple[Any, ...], value: Any, where: str) -> Any:
    """``value`` as the first of the union's members ``args`` it converts to."""
    if value is None and type(None) in args:
        return None
    options = [a for a in args if a is not type(None)]
    if (
        value == NONE_SPELLING
        and type(None) in args
        and not any(_takes_strings(a) for a in options)
    ):
        return None
    dc_options: list[Any] = [a for a in options if dataclasses.is_dataclass(a)]
    if dc_options and isinstance(value, Mapping):
        return _convert_tagged_union(dc_options, value, where)
    if len(options) == 1:  # Optional[X]: keep X's own message (it says what is expected)
        return _convert(options[0], value, where)
    for option in options:
        try:
            return _convert(option, value, where)
        except ConfigError:
            continue
    raise ConfigError(
        f"{where}: {value!r} matches none of {' | '.join(_type_name(a) for a in args)}"
    )


def _convert_scalar(tp: type, value: Any, where: str) -> Any:
    """``value`` as a bool, int, float, str or Path (TOML's booleans are not numbers)."""
    if tp is bool:
        if not isinstance(value, bool):
            raise ConfigError(f"{where}: expected true or false, got {value!r}")
        return value
    if tp is int:
        if isinstance(value, bool) or not isinstance(value, int | np.integer):
            raise ConfigError(f"{where}: expected an integer, got {value!r}")
        return int(value)
    if tp is float:
        if isinstance(value, bool) or not isinstance(value, int | float | np.number):
            raise ConfigError(f"{where}: expected a number, got {value!r}")
        return float(value)
    if tp is str:
        if not isinstance(value, str):
            raise ConfigError(f"{where}: expected a string, got {value!r}")
        return value
    if not isinstance(value, str | Path):
        raise ConfigError(f"{where}: expected a path string, got {value!r}")
    return Path(value)


def _convert_sequence(tp: Any, value: Any, where: str) -> Any:
    """``value`` as ``tuple[...]`` (fixed length or ``...``) or ``list[...]``."""
    if not isinstance(value, list | tuple):
        raise ConfigError(f"{where}: expected a list, got {value!r}")
    origin = get_origin(tp)
    args = get_args(tp)
    if origin is tuple and args and args[-1] is not Ellipsis:
        if len(value) != len(args):
            raise ConfigError(f"{where}: expected {len(args)} values, got {len(value)}")
        items = [
            _convert(a, v, _field_path(where, i))
            for i, (a, v) in enumerate(zip(args, value, strict=True))
        ]
    else:
        item_tp = args[0] if args else Any
        items = [_convert(item_tp, v, _field_path(where, i)) for i, v in enumerate(value)]
    return tuple(items) if origin is tuple else items


@functools.cache
def _type_hints(cls: type) -> dict[str, Any]:
    """``typing.get_type_hints(cls)``, resolved once per class: resolving the string annotations
    was 90 % of reading a fault file (one call per field per tagged-union option)."""
    return get_type_hints(cls)


def _convert_tagged_union(options: list[type], value: Mapping[str, Any], where: str) -> Any:
    """Picks the dataclass whose ``kind`` Literal matches ``value['kind']``."""
    by_kind: dict[str, type] = {}
    for cls in options:
        hint = _type_hints(cls).get("kind")
        if get_origin(hint) is Literal:
            for k in get_args(hint):
                by_kind[k] = cls
    if not by_kind:
        if len(options) == 1:
            return _build_dataclass(options[0], value, where)
        raise TypeError(f"union of dataclasses without a 'kind' Literal field at {where}")
    kind = value.get("kind")
    if "kind" not in value:
        raise ConfigError(
            f"{where}: missing key 'kind'; add kind = one of "
            f"{', '.join(repr(k) for k in sorted(by_kind))}"
        )
    if kind not in by_kind:
        close = difflib.get_close_matches(str(kind), list(by_kind), n=1)
        hint = f" (did you mean {close[0]!r}?)" if close else ""
        raise ConfigError(
            f"{where}: kind = {kind!r} is not known{hint}; expected one of "
            f"{', '.join(repr(k) for k in sorted(by_kind))}"
        )
    return _build_dataclass(by_kind[kind], value, where)


def jsonable(obj: Any) -> Any:
    """Converts configs and records to JSON-compatible values (for metadata files).

    Dataclasses become dicts, tuples lists, Paths strings, numpy scalars and arrays Python
    numbers and lists, enums their values.
    """
    if dataclasses.is_dataclass(obj) and not isinstance(obj, type):
        return {f.name: jsonable(getattr(obj, f.name)) for f in dataclasses.fields(obj)}
    if isinstance(obj, Mapping):
        return {str(k): jsonable(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [jsonable(v) for v in obj]
    if isinstance(obj, Path):
        return str(obj)
    if isinstance(obj, enum.Enum):
        return obj.value
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, np.generic):
        return obj.item()
    return obj


def toml_value(value: Any) -> str:
    """A TOML value's text: booleans, integers, floats (``nan``, ``inf``), strings and paths
    (JSON-escaped, which TOML basic strings accept) and lists of these.

    Raises:
        TypeError: anything else (TOML has no null; tables are the caller's).
    """
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        if math.isnan(value):
            return "nan"
        if math.isinf(value):
            return "inf" if value > 0 else "-inf"
        return repr(value)
    if isinstance(value, str | Path):
        return json.dumps(str(value))
    if isinstance(value, list | tuple):
        return "[" + ", ".join(toml_value(v) for v in value) + "]"
    raise TypeError(f"cannot write {type(value).__name__} {value!r} as a TOML value")
