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
from collections.abc import Callable, Iterable, Mapping
from enum import StrEnum
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
        for name, hint, settle in _plan(type(self)):
            value = getattr(self, name)
            try:
                settled = settle(value)
            except _Mismatch:
                raise ConfigError(
                    f"{self.where(name)}={value!r}: expected {_describe(hint)}"
                ) from None
            if settled is not value:
                # Frozen: the dataclass itself refuses plain assignment.
                object.__setattr__(self, name, settled)
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


SEED_LIMIT = 2**32
"""Seeds are 0 <= seed < 2**32: what numpy's and PyTorch's generators accept alike."""


def check_seed(seed: int, option: str = "--seed") -> int:
    """Refuse a seed outside 0 <= seed < 2**32 in one line naming ``option``."""
    if isinstance(seed, bool) or not isinstance(seed, int) or not 0 <= seed < SEED_LIMIT:
        raise ConfigError(f"{option} {seed!r}: a seed must be an integer in 0 .. {SEED_LIMIT - 1}")
    return seed


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


class _DuplicateKey(yaml.YAMLError):
    """A mapping that gives one key twice."""


# libyaml's parser when PyYAML was built with it (its wheels are): about 10x faster than the
# pure-Python one, and every run folder's config.yaml is read at each resume and evaluation.
_SafeLoader = getattr(yaml, "CSafeLoader", yaml.SafeLoader)


class _UniqueKeyLoader(_SafeLoader):  # type: ignore[misc,valid-type]
    """PyYAML's safe loader, refusing a key given twice in one mapping (plain PyYAML keeps
    the last value without a word)."""

    def construct_mapping(self, node: yaml.MappingNode, deep: bool = False) -> dict[Any, Any]:
        seen: dict[Any, int] = {}
        for key_node, _ in node.value:
            key = self.construct_object(key_node, deep=deep)
            line = key_node.start_mark.line + 1
            try:
                first = seen.get(key)
            except TypeError:  # an unhashable key: the base loader reports it
                break
            if first is not None:
                raise _DuplicateKey(
                    f"key {key!r} is given twice (lines {first} and {line}); keep one"
                )
            seen[key] = line
        return super().construct_mapping(node, deep=deep)


def _one_line(exc: BaseException) -> str:
    return " ".join(str(exc).split())


def read_yaml(path: str | Path) -> Any:
    """The data of a YAML settings file; a missing, broken or empty file is a ConfigError."""
    path = Path(path)
    if not path.is_file():
        raise ConfigError(f"config file not found: {path}")
    try:
        text = path.read_bytes().decode("utf-8")
    except UnicodeDecodeError as exc:
        raise ConfigError(
            f"{path}: not UTF-8 text (byte {exc.start} is {exc.object[exc.start]:#04x}); save "
            "it as UTF-8"
        ) from None
    try:
        data = yaml.load(text, Loader=_UniqueKeyLoader)  # noqa: S506 - a SafeLoader subclass
    except _DuplicateKey as exc:
        raise ConfigError(f"{path}: {exc}") from None
    except yaml.YAMLError as exc:
        raise ConfigError(f"{path}: not valid YAML: {_one_line(exc)}") from None
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
def _plan(cls: type) -> tuple[tuple[str, Any, Callable[[Any], Any]], ...]:
    """(name, type hint, settler) of every field of a section, in field order."""
    hints = typing.get_type_hints(cls)
    return tuple(
        (f.name, hints[f.name], _settler(hints[f.name]))
        for f in dataclasses.fields(cls)  # type: ignore[arg-type]
    )


def _is_section(hint: Any) -> bool:
    return isinstance(hint, type) and issubclass(hint, Settings)


@functools.cache
def _settler(hint: Any) -> Callable[[Any], Any]:
    """The function that returns a value as ``hint`` holds it (lists as tuples, a mapping as
    its section) or raises _Mismatch; built once per hint, as configs are built often (every
    env, every evaluation job)."""
    if hint in _PLAIN:
        kinds = _PLAIN[hint]

        def plain(value: Any) -> Any:
            # bool is an int to Python, never to a config: true is no step count.
            if not isinstance(value, kinds) or (isinstance(value, bool) and hint is not bool):
                raise _Mismatch
            return value

        return plain
    if hint is Any:
        return lambda value: value
    if hint is type(None):

        def none(value: Any) -> Any:
            if value is not None:
                raise _Mismatch
            return value

        return none
    if _is_section(hint):
        return lambda value: value if isinstance(value, hint) else hint.from_dict(value)
    origin, args = typing.get_origin(hint), typing.get_args(hint)
    if origin in (types.UnionType, typing.Union):
        arms = [_settler(a) for a in args]

        def union(value: Any) -> Any:
            for arm in arms:
                try:
                    return arm(value)
                except _Mismatch:
                    continue
            raise _Mismatch

        return union
    if origin is tuple and len(args) == 2 and args[1] is Ellipsis:
        each = _settler(args[0])

        def many(value: Any) -> Any:
            if not isinstance(value, list | tuple):
                raise _Mismatch
            return tuple(each(v) for v in value)

        return many
    if origin is dict:
        key, item = _settler(args[0]), _settler(args[1])

        def mapping(value: Any) -> Any:
            if not isinstance(value, Mapping):
                raise _Mismatch
            return {key(k): item(v) for k, v in value.items()}

        return mapping
    if origin is tuple:
        parts = [_settler(a) for a in args]

        def fixed(value: Any) -> Any:
            if not isinstance(value, list | tuple) or len(value) != len(parts):
                raise _Mismatch
            return tuple(part(v) for part, v in zip(parts, value, strict=True))

        return fixed
    raise TypeError(f"no config rule for the type hint {hint!r}")


_PLAIN: dict[Any, type | tuple[type, ...]] = {
    bool: bool,
    int: int,
    float: (int, float),  # an integer is a fine number: YAML writes 50, not 50.0
    str: str,
}


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
    if origin is dict:
        head = "mappings" if plural else "a mapping"
        return f"{head} of {_describe(args[0], True)} to {_describe(args[1], True)}"
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
        return {_plain(k): _plain(v) for k, v in value.items()}
    if isinstance(value, StrEnum):  # a value set's member (config.choices) is its plain text
        return str(value)
    return value


__all__ = ["Settings", "check_keys", "read_yaml"]
