"""The one way a config is read: a dataclass from a JSON-ready table (a training config, a
model's config in a checkpoint, the synthetic city's recipe in city.json, label settings).

Configs are written by hand or by another version of the code, so a key the dataclass does not
know is an error naming the key (and, through the caller, the file), never a silent default;
JSON lists become tuples where the field's default is a tuple; a field whose default is a
config (or that ``nested`` names, for fields that default to None) is built from its own table
the same way.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from typing import Any, ClassVar, TypeVar

from csboundary.errors import reject_unknown

T = TypeVar("T")


def config_from_dict(
    cls: type[T], data: Mapping[str, Any], what: str | None = None, nested: Mapping[str, type] | None = None
) -> T:
    """``cls(**data)`` with unknown keys refused, lists turned into tuples where the default is a
    tuple, and the fields in ``nested`` built from their own tables."""
    what = what or cls.__name__
    if not isinstance(data, Mapping):
        raise ValueError(f"{what}: expected a table of options, got {type(data).__name__}")
    fields = {f.name: f for f in dataclasses.fields(cls)}
    reject_unknown(data, fields, what)
    values = {}
    for key, value in data.items():
        field = fields[key]
        default = field.default if field.default is not dataclasses.MISSING else None
        if default is None and field.default_factory is not dataclasses.MISSING:
            default = field.default_factory()
        kind = (nested or {}).get(key) or (type(default) if dataclasses.is_dataclass(default) else None)
        if kind is not None and isinstance(value, Mapping):  # a nested config, from its own table
            value = config_from_dict(kind, value, f"{what}.{key}")
        elif isinstance(value, list) and isinstance(default, tuple):
            value = tuple(value)
        values[key] = value
    return cls(**values)


class Config:
    """Base of every config dataclass: ``from_dict`` reads a table through
    :func:`config_from_dict` (``config_name`` names it in errors, ``config_nested`` names fields
    that default to None but hold a config) and ``to_dict`` writes it back."""

    config_name: ClassVar[str | None] = None
    config_nested: ClassVar[Mapping[str, type] | None] = None

    def to_dict(self) -> dict:
        return dataclasses.asdict(self)

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]):
        return config_from_dict(cls, data, cls.config_name, cls.config_nested)
