"""One loader for every frozen, typed config: YAML -> nested frozen dataclass.

Rules (house style, point 1):
- unknown keys are rejected by name, and so are missing required keys;
- each field's type is checked (int, float, bool, str, tuple of those, nested
  dataclass), and values are converted to the declared type;
- with ``cited=True`` every leaf value must be written as
  ``{value: ..., source: "..."}`` so that each parameter says where it came
  from; the sources are kept beside the dataclass in ``sources``.

Non-physical values are checked by each dataclass's ``__post_init__``, which
raises ``ConfigError`` naming the key.
"""

from __future__ import annotations

import dataclasses
import math
import types
import typing
from collections.abc import Mapping
from pathlib import Path
from typing import Any, TypeVar

import yaml

from monitor.errors import ConfigError

T = TypeVar("T")


def read_yaml(path: str | Path) -> dict[str, Any]:
    """Read a YAML mapping, raising ConfigError that names the file on any problem."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as exc:
        raise ConfigError(f"{path}: cannot read config: {exc.strerror or exc}") from exc
    except UnicodeDecodeError as exc:
        raise ConfigError(f"{path}: not a UTF-8 text file (byte {exc.start})") from None
    try:
        data = yaml.safe_load(text)
    except yaml.YAMLError as exc:
        first = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        raise ConfigError(f"{path}: invalid YAML: {first}") from None
    except (ValueError, TypeError, RecursionError) as exc:  # e.g. a YAML integer too large to hold
        raise ConfigError(f"{path}: invalid YAML: {type(exc).__name__}") from None
    if data is None:
        data = {}
    if not isinstance(data, dict):
        raise ConfigError(f"{path}: top level must be a mapping, got {type(data).__name__}")
    return data


def _convert(tp: Any, value: Any, where: str, cited: bool, sources: dict[str, str]) -> Any:
    if dataclasses.is_dataclass(tp):
        if not isinstance(value, Mapping):
            raise ConfigError(f"{where}: expected a mapping, got {type(value).__name__}")
        return _build(tp, value, where, cited, sources)
    if cited:
        if not isinstance(value, Mapping) or set(value) != {"value", "source"}:
            raise ConfigError(f"{where}: must be written as {{value: ..., source: '...'}} (every parameter cites its source)")
        src = value["source"]
        if not isinstance(src, str) or not src.strip():
            raise ConfigError(f"{where}.source: must be a non-empty string")
        sources[where] = src
        value = value["value"]
    return _convert_plain(tp, value, where)


def _convert_plain(tp: Any, value: Any, where: str) -> Any:
    origin = typing.get_origin(tp)
    if origin in (typing.Union, types.UnionType):
        args = typing.get_args(tp)
        if value is None and type(None) in args:
            return None
        inner = [a for a in args if a is not type(None)]
        return _convert_plain(inner[0], value, where)
    if origin is tuple:
        args = typing.get_args(tp)
        if not isinstance(value, (list, tuple)):
            raise ConfigError(f"{where}: expected a list, got {type(value).__name__}")
        if len(args) == 2 and args[1] is Ellipsis:
            return tuple(_convert_plain(args[0], v, f"{where}[{i}]") for i, v in enumerate(value))
        if len(args) != len(value):
            raise ConfigError(f"{where}: expected {len(args)} items, got {len(value)}")
        return tuple(_convert_plain(a, v, f"{where}[{i}]") for i, (a, v) in enumerate(zip(args, value)))
    if tp is float:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise ConfigError(f"{where}: expected a number, got {value!r}")
        try:
            value = float(value)
        except OverflowError:
            raise ConfigError(f"{where}: {value!r} is out of range") from None
        if not math.isfinite(value):  # .inf / .nan: every numeric setting has finite bounds
            raise ConfigError(f"{where}: must be a finite number, got {value!r}")
        return value
    if tp is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise ConfigError(f"{where}: expected an integer, got {value!r}")
        return int(value)
    if tp is bool:
        if not isinstance(value, bool):
            raise ConfigError(f"{where}: expected true or false, got {value!r}")
        return value
    if tp is str:
        if not isinstance(value, str):
            raise ConfigError(f"{where}: expected a string, got {value!r}")
        return value
    if tp is Any:
        return value
    raise ConfigError(f"{where}: unsupported field type {tp!r}")


def _build(cls: type[T], data: Mapping[str, Any], where: str, cited: bool, sources: dict[str, str]) -> T:
    hints = typing.get_type_hints(cls)
    fields = {f.name: f for f in dataclasses.fields(cls) if f.init}
    unknown = sorted(set(data) - set(fields))
    if unknown:
        raise ConfigError(f"{where}: unknown key(s) {', '.join(unknown)} (allowed: {', '.join(fields)})")
    kwargs = {}
    for name, field in fields.items():
        key = f"{where}.{name}" if where else name
        if name not in data:
            has_default = field.default is not dataclasses.MISSING or field.default_factory is not dataclasses.MISSING
            if not has_default:
                raise ConfigError(f"{key}: missing required key")
            continue
        kwargs[name] = _convert(hints[name], data[name], key, cited, sources)
    try:
        return cls(**kwargs)
    except ConfigError as exc:
        raise ConfigError(f"{where + ': ' if where else ''}{exc}") from None


def from_mapping(cls: type[T], data: Mapping[str, Any], *, origin: str = "", cited: bool = False) -> tuple[T, dict[str, str]]:
    """Build ``cls`` from a mapping; returns the instance and the {key: source} citations."""
    sources: dict[str, str] = {}
    try:
        obj = _build(cls, data, "", cited, sources)
    except ConfigError as exc:
        raise ConfigError(f"{origin}: {exc}" if origin else str(exc)) from None
    return obj, sources


def load_dataclass(cls: type[T], path: str | Path, *, cited: bool = False) -> tuple[T, dict[str, str]]:
    """Load ``cls`` from a YAML file, naming the file in any error."""
    return from_mapping(cls, read_yaml(path), origin=str(path), cited=cited)


def to_mapping(obj: Any, sources: Mapping[str, str] | None = None, where: str = "") -> Any:
    """Inverse of ``from_mapping``: a plain (YAML-ready) mapping, with citations if given."""
    if dataclasses.is_dataclass(obj):
        out = {}
        for f in dataclasses.fields(obj):
            if not f.init:
                continue
            key = f"{where}.{f.name}" if where else f.name
            out[f.name] = to_mapping(getattr(obj, f.name), sources, key)
        return out
    plain = list(obj) if isinstance(obj, tuple) else obj
    if isinstance(plain, list):
        plain = [list(v) if isinstance(v, tuple) else v for v in plain]
    if sources is not None:
        return {"value": plain, "source": sources.get(where, "unspecified")}
    return plain
