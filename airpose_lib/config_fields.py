"""The values of a config dataclass checked against the types its fields declare.

Every config of the kit (``TrainConfig``, ``FineTuneConfig`` ...) is a dataclass whose
annotations say what each field holds. :func:`check_fields`, called first in its
``__post_init__``, makes that a rule: a value of another type raises :class:`ConfigError` naming
the field, the type it wants and the value it got, before anything runs (``steps: thirty`` in a
profile used to end in a ``TypeError`` deep in the training loop). Ranges stay next to the field
they concern, in the dataclass's own ``__post_init__`` (:func:`require`).

The same check reads a profile section (:func:`check_keys` for unknown keys, with the closest
known one; :func:`config_from` under ``profiles.section_config``) and ``--set KEY=VALUE`` on the
command line. Imports nothing of the kit but ``errors``.
"""
from __future__ import annotations

import dataclasses
import difflib
import math
import types
import typing
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any

from airpose_lib.errors import ConfigError, ProfileError

__all__ = ["ConfigError", "check_type", "check_fields", "check_keys", "config_from", "field_types", "require", "finite"]


def _type_name(tp) -> str:
    return getattr(tp, "__name__", str(tp).replace("typing.", ""))


def field_types(cls) -> dict[str, Any]:
    """``{field name: annotation}`` of a dataclass (string annotations resolved)."""
    hints = typing.get_type_hints(cls)
    return {f.name: hints.get(f.name, typing.Any) for f in dataclasses.fields(cls)}


def check_type(name: str, value: Any, annotation: Any) -> Any:
    """``value`` if it fits ``annotation``, else :class:`ConfigError`.

    Ints widen to floats and lists become tuples (YAML has no tuples); ``bool`` is not an int here
    (``steps: yes`` is a mistake). ``Any`` and unknown annotations accept everything.

    Args:
        name: how the message calls the value (``"steps"``, ``"train: steps"``).
        value: the value.
        annotation: the field's type (``int``, ``float | None``, ``tuple[int, int]`` ...).
    Returns:
        the value, converted where said above.
    """
    options = typing.get_args(annotation) if typing.get_origin(annotation) in (typing.Union, types.UnionType) \
        else (annotation,)
    if value is None and type(None) in options:
        return None
    for tp in options:
        base = typing.get_origin(tp) or tp
        if base is typing.Any or base is typing.Literal and value in typing.get_args(tp):
            return value
        if base is float and isinstance(value, (int, float)) and not isinstance(value, bool):
            return float(value)
        if base is int and isinstance(value, int) and not isinstance(value, bool):
            return value
        if base in (bool, str, dict, list) and isinstance(value, base):
            return value
        if base is tuple and isinstance(value, (list, tuple)):
            return tuple(value)
        if base is Path and isinstance(value, str):  # YAML and --set give paths as text
            return value
        if isinstance(base, type) and base not in (bool, int, float, str) and isinstance(value, base):
            return value
        if not isinstance(base, type) and base is not typing.Literal:  # an annotation we cannot check
            return value
    wanted = " or ".join(_type_name(t) for t in options)
    raise ConfigError(f"{name}: expected {wanted}, got {value!r} ({type(value).__name__})")


def check_fields(config: Any) -> None:
    """Check (and convert in place, as :func:`check_type`) every field of a dataclass instance."""
    for name, annotation in field_types(type(config)).items():
        value = getattr(config, name)
        checked = check_type(name, value, annotation)
        if checked is not value:
            object.__setattr__(config, name, checked)


def check_keys(keys: Iterable[str], cls, where: str, error: type[ConfigError] = ConfigError) -> None:
    """Raise ``error`` for a key that is not a field of ``cls``, naming the closest one.

    The one unknown-key check of the kit's configs (profile sections, ``--set``, options).

    Args:
        keys: the keys given (a profile section's, ``--set``'s).
        cls: the config dataclass, or a tuple of them (a section shared by several configs:
            a key may be a field of any).
        where: where they came from (``"profile file X, section train:"``).
        error: the class raised (a :class:`ConfigError`).
    """
    classes = cls if isinstance(cls, tuple) else (cls,)
    known = set().union(*(field_types(c) for c in classes))
    for key in keys:
        if key not in known:
            close = difflib.get_close_matches(key, sorted(known), n=1)
            hint = f"did you mean {close[0]!r}?" if close else f"known: {', '.join(sorted(known))}"
            names = " or ".join(c.__name__ for c in classes)
            raise error(f"{where}: unknown key {key!r} of {names}; {hint}")


def finite(value: float | None) -> bool:
    """True for a finite number (None is not)."""
    return value is not None and math.isfinite(value)


def require(condition: bool, name: str, rule: str, value: Any) -> None:
    """Raise :class:`ConfigError` ``"<name> must be <rule>, got <value>"`` unless ``condition``."""
    if not condition:
        raise ConfigError(f"{name} must be {rule}, got {value!r}")


def config_from(cls, values: Mapping[str, Any], where: str, *, build=None, error: type[ConfigError] = ConfigError):
    """``cls(**values)`` (or ``build(values)``) with unknown keys and bad values named as coming
    from ``where``.

    Args:
        cls: the config dataclass.
        values: its settings.
        where: where they came from, the start of every message.
        build: makes the config of the checked values (default ``cls(**values)``; e.g. a
            ``from_dict`` that also builds nested configs).
        error: the class raised (a :class:`ConfigError`).
    """
    check_keys(values, cls, where, error)
    try:
        return cls(**values) if build is None else build(values)
    except (ConfigError, ProfileError) as e:  # ProfileError: a nested config's own check
        raise error(f"{where}: {e}") from None
