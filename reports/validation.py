"""Type checks of the study configuration against its dataclass annotations.

A study TOML is read into :class:`~mdaug.reports.config.StudyConfig` and checked
field by field against the annotations, so a value of the wrong type (``cnn_epochs
= "fifty"``, ``sigma_p = [0.1, "x"]``, ``data = 5``) is refused before any work
with one message naming the file, the section and key, the value and the expected
type, e.g. ``study.toml: [protocol] cnn_epochs = 'fifty': expected an integer``.
Fields added to the config dataclasses are checked without further code.
"""
from __future__ import annotations

import dataclasses
import math
import numbers
import types
import typing
from functools import lru_cache


class ConfigTypeError(ValueError):
    """A config value of the wrong type or shape."""


@lru_cache(maxsize=None)
def field_types(cls) -> dict:
    """{field name: resolved annotation} of a config dataclass."""
    hints = typing.get_type_hints(cls)
    return {f.name: hints[f.name] for f in dataclasses.fields(cls)}


def describe(hint) -> str:
    """'an integer', 'a list of numbers', ... for messages."""
    origin, args = typing.get_origin(hint), typing.get_args(hint)
    if origin in (typing.Union, types.UnionType):
        kinds = [describe(a) for a in args if a is not type(None)]
        return " or ".join(kinds)
    if hint is bool:
        return "true or false"
    if hint is int:
        return "an integer"
    if hint is float:
        return "a number"
    if hint is str:
        return "a string"
    if origin is tuple or hint is tuple:
        inner = args[0] if args else None
        return "a list" + (f" of {_plural(inner)}" if inner is not None else "")
    if origin is dict or hint is dict:
        inner = args[1] if len(args) == 2 else None
        return "a table" + (f" of {_plural(inner)}" if inner not in (None, typing.Any) else "")
    if dataclasses.is_dataclass(hint):
        return "a table (section)"
    return getattr(hint, "__name__", str(hint))


def _plural(hint) -> str:
    return {int: "integers", float: "numbers", str: "strings", bool: "booleans"}.get(hint) or describe(hint)


def show(value) -> str:
    """A value as TOML writes it (true, 'text', [1, 2], a table)."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, dict):
        return "a table"
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(show(v) for v in value) + "]"
    return repr(value)


def _fail(where: str, value, hint):
    shown = show(value)
    raise ConfigTypeError(f"{where} = {shown}: expected {describe(hint)}")


def convert(value, hint, where: str):
    """``value`` as the annotation ``hint`` asks (lists become tuples, integers become
    floats where a number is asked); ConfigTypeError naming ``where`` otherwise.
    Numbers must be finite; booleans are not numbers."""
    origin, args = typing.get_origin(hint), typing.get_args(hint)
    if hint is typing.Any:
        return value
    if origin in (typing.Union, types.UnionType):
        if value is None and type(None) in args:
            return None
        for a in args:
            if a is type(None):
                continue
            try:
                return convert(value, a, where)
            except ConfigTypeError:
                pass
        _fail(where, value, hint)
    if hint is bool:
        if isinstance(value, bool):
            return value
        _fail(where, value, hint)
    if hint is int:
        if isinstance(value, numbers.Integral) and not isinstance(value, bool):
            return int(value)
        _fail(where, value, hint)
    if hint is float:
        if isinstance(value, numbers.Real) and not isinstance(value, bool) and math.isfinite(value):
            return float(value)
        _fail(where, value, hint)
    if hint is str:
        if isinstance(value, str):
            return value
        _fail(where, value, hint)
    if origin is tuple or hint is tuple:
        if not isinstance(value, (list, tuple)):
            _fail(where, value, hint)
        if not args:
            return tuple(value)
        if len(args) == 2 and args[1] is Ellipsis:
            return tuple(convert(v, args[0], f"{where}[{i}]") for i, v in enumerate(value))
        if len(value) != len(args):
            raise ConfigTypeError(f"{where} = {value!r}: expected a list of {len(args)} values")
        return tuple(convert(v, a, f"{where}[{i}]") for i, (v, a) in enumerate(zip(value, args)))
    if origin is dict or hint is dict:
        if not isinstance(value, dict):
            _fail(where, value, hint)
        key_t, val_t = args if len(args) == 2 else (str, typing.Any)
        out = {}
        for k, v in value.items():
            out[convert(k, key_t, f"{where} key")] = convert(v, val_t, f"{where}.{k}")
        return out
    if dataclasses.is_dataclass(hint):
        if not dataclasses.is_dataclass(value):
            _fail(where, value, hint)
        check_types(value, where)
        return value
    return value


def check_types(obj, where: str) -> None:
    """Check every field of a config dataclass instance (``where``: its name in messages)."""
    for name, hint in field_types(type(obj)).items():
        convert(getattr(obj, name), hint, f"{where}.{name}" if where else name)
