"""The values of a config dataclass checked against the types its fields declare.

Every config of the kit (``TrainConfig``, ``FineTuneConfig`` ...) is a dataclass whose
annotations say what each field holds. :func:`check_fields`, called first in its
``__post_init__``, makes that a rule: a value of another type raises :class:`ConfigError` naming
the field, the type it wants and the value it got, before anything runs (``steps: thirty`` in a
profile used to end in a ``TypeError`` deep in the training loop). A numeric range is declared with
the field it concerns (:func:`ranged`: ``steps: int = ranged(1000, ge=0)``) and checked by
:func:`check_fields` too; a rule that ties several fields together stays in the dataclass's own
``__post_init__`` (:func:`require`).

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

__all__ = ["ConfigError", "Range", "check_type", "check_fields", "check_keys", "check_keys_in", "closest_key", "config_from",
           "field_range", "field_types", "finite", "ranged", "require", "unknown_hint"]


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


@dataclasses.dataclass(frozen=True)
class Range:
    """The numbers a field accepts: each bound given is a limit (``ge``: >=, ``gt``: >, ``le``: <=,
    ``lt``: <); a bounded number must also be finite. None (where the field's type allows it) is
    not a number and passes."""

    ge: float | None = None
    gt: float | None = None
    le: float | None = None
    lt: float | None = None

    def holds(self, value: Any) -> bool:
        """True when ``value`` (a number, or None) is inside the range."""
        if value is None:
            return True
        return (math.isfinite(value) and (self.ge is None or value >= self.ge) and (self.gt is None or value > self.gt)
                and (self.le is None or value <= self.le) and (self.lt is None or value < self.lt))

    @property
    def rule(self) -> str:
        """``">= 0"``, ``"in [0, 1)"`` ...: how a message states the range."""
        low = (f"[{_num(self.ge)}" if self.ge is not None else f"({_num(self.gt)}" if self.gt is not None else None)
        high = (f"{_num(self.le)}]" if self.le is not None else f"{_num(self.lt)})" if self.lt is not None else None)
        if low is not None and high is not None:
            return f"in {low}, {high}"
        if low is not None:
            return f"{'>=' if low[0] == '[' else '>'} {low[1:]}"
        return f"{'<=' if high[-1] == ']' else '<'} {high[:-1]}"


def _num(x: float) -> str:
    return str(int(x)) if float(x).is_integer() else str(x)


_RANGE = "airpose_range"  # the key of a field's metadata that holds its Range


def ranged(default: Any = dataclasses.MISSING, *, ge: float | None = None, gt: float | None = None,
           le: float | None = None, lt: float | None = None) -> Any:
    """A dataclass field with a default and the :class:`Range` of numbers it accepts, checked by
    :func:`check_fields` (``lr: float = ranged(5e-5, gt=0)``)."""
    return dataclasses.field(default=default, metadata={_RANGE: Range(ge=ge, gt=gt, le=le, lt=lt)})


def field_range(cls, name: str) -> Range | None:
    """The :class:`Range` declared for field ``name`` of dataclass ``cls`` (None: any number)."""
    return next((f.metadata.get(_RANGE) for f in dataclasses.fields(cls) if f.name == name), None)


def check_fields(config: Any, prefix: str = "", convert: bool = True) -> None:
    """Check every field of a dataclass instance: its type, then its declared :class:`Range`; a
    field that holds a dataclass is checked the same way, its fields named ``<field>.<name>``.

    Args:
        config: the dataclass instance.
        prefix: put before every field name in messages.
        convert: store the converted values (:func:`check_type`: ints to floats, lists to
            tuples). Off for configs whose values make a fingerprint or a cache key, where
            ``1`` and ``1.0`` would name other data.
    """
    for f in dataclasses.fields(config):
        name, value = prefix + f.name, getattr(config, f.name)
        checked = check_type(name, value, field_types(type(config))[f.name])
        if convert and checked is not value:
            object.__setattr__(config, f.name, checked)
        rng = f.metadata.get(_RANGE)
        if rng is not None and not isinstance(checked, bool):
            require(rng.holds(checked), name, rng.rule, checked)
        if dataclasses.is_dataclass(checked) and not isinstance(checked, type):
            check_fields(checked, f"{name}.", convert)


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
    check_keys_in(keys, known, where, " or ".join(c.__name__ for c in classes), error)


def check_keys_in(keys: Iterable[str], known: Iterable[str], where: str, of: str | None = None,
                  error: type[ConfigError] = ConfigError) -> None:
    """Raise ``error`` ``"<where>: unknown key 'x' [of <of>]; did you mean 'y'?"`` for a key not in ``known``."""
    known = set(known)
    for key in keys:
        if key not in known:
            raise error(f"{where}: unknown key {key!r}{f' of {of}' if of else ''}; {unknown_hint(str(key), known)}")


def closest_key(key: str, known: Iterable[str]) -> str | None:
    """The known key a misspelt ``key`` most likely meant, or None.

    A dotted key (``model.dropout``) is also found by its last part (``dropout``), and a key
    that starts with a known one of two letters or more (``lrate``: ``lr``) counts as close.
    """
    known = sorted(set(known))
    close = difflib.get_close_matches(key, known, n=1)
    if close:
        return close[0]
    tails = {k.rpartition(".")[2]: k for k in known if "." in k}
    close = difflib.get_close_matches(key, sorted(tails), n=1)
    if close:
        return tails[close[0]]
    starts = [k for k in known if len(k) >= 2 and key.startswith(k)]
    return max(starts, key=len) if starts else None


def unknown_hint(key: str, known: Iterable[str]) -> str:
    """``"did you mean 'lr'?"``, or the known keys when none is close."""
    known = sorted(set(known))
    close = closest_key(key, known)
    return f"did you mean {close!r}?" if close else f"known: {', '.join(known)}"


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
        config = cls(**values) if build is None else build(values)
        check_fields(config, convert=False)  # the configs without a __post_init__ of their own too
        return config
    except (ConfigError, ProfileError) as e:  # ProfileError: a nested config's own check
        raise error(f"{where}: {e}") from None
