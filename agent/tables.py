"""TOML tables ↔ frozen dataclasses: the one converter of the configuration.

:func:`build_dataclass` makes a dataclass from a table: every key must be a field, of the
field's type (an integer is not a boolean, a list becomes a tuple, a nested table a nested
dataclass), and the dataclass's own checks (``__post_init__``) become
:class:`~knowledge.errors.ConfigError` s naming the key; :func:`dataclass_table` is the inverse.
Every section of the robot's configuration and of the bus goes through it.
"""

from __future__ import annotations

import dataclasses
import types
import typing
from collections.abc import Collection, Mapping
from pathlib import Path
from typing import Any, TypeVar

from knowledge.errors import ConfigError

T = TypeVar("T")


def _type_name(tp: Any) -> str:
    return {bool: "true or false", int: "an integer", float: "a number", str: "a string"}.get(
        tp, getattr(tp, "__name__", str(tp))
    )


def _coerce(value: Any, tp: Any, where: str) -> Any:
    """``value`` (from TOML) as type ``tp`` (a field's annotation), or a ConfigError."""
    origin = typing.get_origin(tp)
    if origin in (types.UnionType, typing.Union):
        args = [a for a in typing.get_args(tp) if a is not type(None)]
        if value is None:
            return None
        return _coerce(value, args[0], where)
    if tp is bool:
        if not isinstance(value, bool):
            raise ConfigError(f"{where} must be true or false, got {value!r}")
        return value
    if tp is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise ConfigError(f"{where} must be an integer, got {value!r}")
        return value
    if tp is float:
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise ConfigError(f"{where} must be a number, got {value!r}")
        return float(value)
    if tp is str:
        if not isinstance(value, str):
            raise ConfigError(f"{where} must be a string, got {value!r}")
        return value
    if origin is tuple:
        inner = typing.get_args(tp)[0]
        if not isinstance(value, list | tuple):
            raise ConfigError(f"{where} must be a list of {_type_name(inner)}s, got {value!r}")
        return tuple(_coerce(v, inner, f"{where}[{i}]") for i, v in enumerate(value))
    if dataclasses.is_dataclass(tp) and isinstance(tp, type):
        if not isinstance(value, Mapping):
            raise ConfigError(f"{where} must be a table, e.g. [{where}]")
        return build_dataclass(tp, value, where)
    raise ConfigError(f"{where}: unsupported setting type {tp!r}")  # pragma: no cover - a bug


def build_dataclass(cls: type[T], table: Mapping[str, Any], where: str, *, skip: Collection[str] = ()) -> T:
    """A frozen dataclass from a TOML table: every key must be a field (except ``skip``),
    of the field's type; the dataclass's own checks become ConfigErrors naming ``where``."""
    if not dataclasses.is_dataclass(cls):
        raise TypeError(f"{cls!r} is not a dataclass")
    hints = typing.get_type_hints(cls)
    known = [f.name for f in dataclasses.fields(cls) if f.init and f.name not in skip]
    kwargs: dict[str, Any] = {}
    for key, value in table.items():
        if key not in known:
            raise ConfigError(f"[{where}]: unknown key {key!r} (known: {', '.join(sorted(known))})")
        kwargs[key] = _coerce(value, hints[key], f"{where}.{key}")
    try:
        return cls(**kwargs)
    except ConfigError:
        raise
    except (TypeError, ValueError) as exc:
        raise ConfigError(f"[{where}]: {exc}") from exc


def dataclass_table(obj: Any) -> dict[str, Any]:
    """The fields of a (nested) dataclass as a plain dict (the inverse of :func:`build_dataclass`)."""
    out: dict[str, Any] = {}
    for f in dataclasses.fields(obj):
        v = getattr(obj, f.name)
        if dataclasses.is_dataclass(v) and not isinstance(v, type):
            v = dataclass_table(v)
        elif isinstance(v, tuple):
            v = list(v)
        elif isinstance(v, Path):
            v = str(v)
        out[f.name] = v
    return out
