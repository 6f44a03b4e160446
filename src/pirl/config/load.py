"""The one mechanism that loads and checks every settings section.

A section is a frozen dataclass that derives from :class:`Settings` and names itself
(``class PPOSettings(Settings, section="ppo")``). Building one, from keywords, a mapping or a
YAML file, runs the same three steps:

1. keys: an unknown key is refused with the closest known key and the allowed ones;
2. types: every value is checked against its field's type hint (YAML lists become tuples,
   a nested section's mapping becomes that section);
3. values: the section's own :meth:`Settings.validate` (ranges, choices, cross-field rules).

Every refusal is one :class:`ConfigError` line that names ``section.key``.
"""

from __future__ import annotations

import dataclasses
import difflib
import functools
import types
import typing
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any, ClassVar, Self

import yaml

from pirl.config.errors import ConfigError


class Settings:
    """Base of every settings section (see the module docstring for what building one checks).

    Subclasses are frozen dataclasses; ``section`` is the name their keys sit under in a run
    config ("" for the run config itself).
    """

    section: ClassVar[str] = ""

    def __init_subclass__(cls, section: str = "", **kwargs: Any) -> None:
        super().__init_subclass__(**kwargs)
        cls.section = section

    def __post_init__(self) -> None:
        hints = _hints(type(self))
        for f in dataclasses.fields(self):  # type: ignore[arg-type]
            value = getattr(self, f.name)
            try:
                settled = _settle(hints[f.name], value)
            except _Mismatch:
                raise ConfigError(
                    f"{self.where(f.name)}={value!r}: expected {_describe(hints[f.name])}"
                ) from None
            # Frozen: the dataclass itself refuses plain assignment.
            object.__setattr__(self, f.name, settled)
        self.validate()

    def validate(self) -> None:
        """The section's own value rules; raise :meth:`refuse` for an impossible value."""

    # -- messages -------------------------------------------------------------------------
    def where(self, key: str) -> str:
        """``section.key``, the name a message gives a setting."""
        return f"{self.section}.{key}" if self.section else key

    def refuse(self, key: str, rule: str) -> ConfigError:
        """The error for an impossible value: ``section.key=value: rule``."""
        return ConfigError(f"{self.where(key)}={getattr(self, key)!r}: {rule}")

    def require_choice(self, key: str, allowed: Iterable[str]) -> None:
        """Refuse a value of ``key`` that is not one of ``allowed``."""
        allowed = tuple(allowed)
        if getattr(self, key) not in allowed:
            raise self.refuse(key, f"allowed values are {', '.join(allowed)}")

    def require_positive(self, *keys: str) -> None:
        """Refuse a value <= 0 of any of ``keys``."""
        for key in keys:
            if not getattr(self, key) > 0:
                raise self.refuse(key, "must be > 0")

    # -- construction ---------------------------------------------------------------------
    @classmethod
    def from_dict(cls, values: Mapping[str, Any] | None) -> Self:
        """Build from a mapping of settings (None or empty: the defaults)."""
        if values is None:
            values = {}
        if not isinstance(values, Mapping):
            what = f"section {cls.section!r}" if cls.section else "a config"
            raise ConfigError(f"{what} must be a mapping of settings, got {type(values).__name__}")
        check_keys(values, [f.name for f in dataclasses.fields(cls)], cls.section)  # type: ignore[arg-type]
        return cls(**values)

    @classmethod
    def from_yaml(cls, path: str | Path) -> Self:
        """Load from a YAML file whose top level is a mapping of settings."""
        return cls.from_dict(read_yaml(path))

    def replace(self, **changes: Any) -> Self:
        """A copy with some settings changed (checked like :meth:`from_dict`)."""
        check_keys(changes, [f.name for f in dataclasses.fields(self)], self.section)  # type: ignore[arg-type]
        return dataclasses.replace(self, **changes)  # type: ignore[type-var]

    def to_dict(self) -> dict[str, Any]:
        """Plain, YAML-safe dict of every setting (tuples as lists, sections as dicts)."""
        return {
            f.name: _plain(getattr(self, f.name))
            for f in dataclasses.fields(self)  # type: ignore[arg-type]
        }


def check_keys(values: Mapping[str, Any], known: list[str], section: str = "") -> None:
    """Refuse keys not in ``known``, naming the key, a close match and the allowed keys."""
    for key in values:
        if key not in known:
            close = difflib.get_close_matches(str(key), known, n=1)
            hint = f" (did you mean {close[0]!r}?)" if close else ""
            where = f" in section {section!r}" if section else ""
            raise ConfigError(
                f"unknown setting {key!r}{where}{hint}; allowed keys: {', '.join(sorted(known))}"
            )


def read_yaml(path: str | Path) -> Any:
    """The data of a YAML settings file; a missing, broken or empty file is a ConfigError."""
    path = Path(path)
    if not path.is_file():
        raise ConfigError(f"config file not found: {path}")
    try:
        data = yaml.safe_load(path.read_text())
    except yaml.YAMLError as exc:
        raise ConfigError(f"{path}: not valid YAML: {exc}") from exc
    if data is None:
        # An empty file would silently train on built-in defaults that match no preset.
        raise ConfigError(
            f"{path} is empty; give settings (or {{}} for the built-in defaults), or a "
            "preset such as quick or test"
        )
    return data


# -- type hints -------------------------------------------------------------------------------
class _Mismatch(Exception):
    """A value does not fit a type hint (turned into one ConfigError for the whole field)."""


@functools.cache
def _hints(cls: type) -> dict[str, Any]:
    return typing.get_type_hints(cls)


def _is_section(hint: Any) -> bool:
    return isinstance(hint, type) and issubclass(hint, Settings)


def _settle(hint: Any, value: Any) -> Any:
    """``value`` as ``hint`` holds it (lists as tuples, a mapping as its section)."""
    if hint is Any:
        return value
    if _is_section(hint):
        return value if isinstance(value, hint) else hint.from_dict(value)
    origin, args = typing.get_origin(hint), typing.get_args(hint)
    if origin in (types.UnionType, typing.Union):
        for arm in args:
            try:
                return _settle(arm, value)
            except _Mismatch:
                continue
        raise _Mismatch
    if origin is tuple:
        if not isinstance(value, list | tuple):
            raise _Mismatch
        if len(args) == 2 and args[1] is Ellipsis:
            return tuple(_settle(args[0], v) for v in value)
        if len(value) != len(args):
            raise _Mismatch
        return tuple(_settle(a, v) for a, v in zip(args, value, strict=True))
    if hint is type(None):
        if value is not None:
            raise _Mismatch
        return value
    # bool is an int to Python, never to a config: true is no step count.
    if isinstance(value, bool) and hint is not bool:
        raise _Mismatch
    ok = isinstance(value, int | float) if hint is float else isinstance(value, hint)
    if not ok:
        raise _Mismatch
    return value


_NAMES: dict[Any, tuple[str, str]] = {
    bool: ("true or false", "true/false values"),
    int: ("an integer", "integers"),
    float: ("a number", "numbers"),
    str: ("a string", "strings"),
    type(None): ("null", "nulls"),
    Any: ("any value", "values"),
}


def _describe(hint: Any, plural: bool = False) -> str:
    """What a value of ``hint`` is, in words: 'a list of 3 integers', 'a number or null'."""
    if hint in _NAMES:
        return _NAMES[hint][plural]
    if _is_section(hint):
        return "mappings" if plural else "a mapping"
    origin, args = typing.get_origin(hint), typing.get_args(hint)
    if origin in (types.UnionType, typing.Union):
        return " or ".join(_describe(a, plural) for a in args)
    if origin is tuple:
        head = "lists of" if plural else "a list of"
        if len(args) == 2 and args[1] is Ellipsis:
            return f"{head} {_describe(args[0], True)}"
        if len(set(args)) == 1:
            return f"{head} {len(args)} {_describe(args[0], True)}"
        return f"{head} ({', '.join(_describe(a) for a in args)})"
    return getattr(hint, "__name__", str(hint))


def _plain(value: Any) -> Any:
    if isinstance(value, Settings):
        return value.to_dict()
    if isinstance(value, tuple | list):
        return [_plain(v) for v in value]
    if isinstance(value, Mapping):
        return {k: _plain(v) for k, v in value.items()}
    return value


__all__ = ["Settings", "check_keys", "read_yaml"]
