"""Dataclass configs read from YAML strictly: every field once, nothing else, types checked.

A config file on disk is then the complete record of a run: a missing or unknown key, or a
value of the wrong type, is an error naming the key and the file. Shared by the PPO-RNN expert
(``zoo expert train``) and the RL agents (``zoo rl train``).
"""

from __future__ import annotations

import dataclasses
from dataclasses import fields
from pathlib import Path
from typing import Any, Self, TypeVar

import yaml

T = TypeVar("T")


def dataclass_from_dict(cls: type[T], values: Any, source: str = "<dict>") -> T:
    """Build ``cls`` from a complete mapping; ``source`` names the file in error messages."""
    name = cls.__name__
    if not isinstance(values, dict):
        got = type(values).__name__
        raise ValueError(f"{source}: expected a mapping of {name} fields, got {got}")  # noqa: TRY004
    known = {f.name: f for f in fields(cls)}
    unknown = sorted(set(values) - set(known))
    if unknown:
        raise ValueError(f"{source}: unknown key(s) {unknown}; {name} fields are {sorted(known)}")
    missing = sorted(set(known) - set(values))
    if missing:
        raise ValueError(f"{source}: missing key(s) {missing}; every {name} field must be set")
    return cls(**{k: coerce(values[k], str(known[k].type), k, source) for k in known})


def dataclass_from_yaml(cls: type[T], path: str | Path) -> T:
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{cls.__name__} config file not found: {path}")
    with path.open() as f:
        values = yaml.safe_load(f)
    return dataclass_from_dict(cls, values if values is not None else {}, source=str(path))


def coerce(value: Any, kind: str, name: str, source: str) -> Any:
    """Check a YAML value against a field type (``int``, ``float``, ``bool``, ``str``, or one of
    them ``| None``); accept '1e9'-style numbers (YAML 1.1 reads exponent notation without a dot
    as a string) where they are exact."""
    if kind.endswith(" | None"):
        return None if value is None else coerce(value, kind[: -len(" | None")], name, source)
    if kind == "str" and isinstance(value, str):
        return value
    if kind == "bool" and isinstance(value, bool):
        return value
    if kind in ("int", "float") and not isinstance(value, bool):
        try:
            number = float(value) if isinstance(value, str) else value
            if isinstance(number, (int, float)):
                if kind == "float":
                    return float(number)
                if float(number).is_integer():
                    return int(number)
        except ValueError:
            pass
    raise ValueError(f"{source}: {name} must be {kind}, got {value!r} ({type(value).__name__})")


class StrictConfig:
    """Mixin of a config dataclass: ``from_yaml``/``from_dict`` (strict), ``to_dict``, ``replace``."""

    def to_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)

    def replace(self, **changes: Any) -> Self:
        return dataclasses.replace(self, **changes)

    @classmethod
    def from_dict(cls, values: dict[str, Any], source: str = "<dict>") -> Self:
        """Build from a complete mapping; ``source`` names the file in error messages."""
        return dataclass_from_dict(cls, values, source)

    @classmethod
    def from_yaml(cls, path: str | Path) -> Self:
        return dataclass_from_yaml(cls, path)
