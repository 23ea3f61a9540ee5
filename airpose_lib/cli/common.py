"""What every command group of ``airpose`` shares: the user-error type and policy, path and range
checks, ``--set KEY=VALUE`` parsing, and the choices of common flags.

Only the standard library and pathlib at import time: the parser is built from these on every
``airpose`` call, ``--help`` included (yaml is imported when ``--set`` is parsed).
"""
from __future__ import annotations

import errno
import typing
from pathlib import Path

from airpose_lib.atomic import no_room_error  # standard library only
from airpose_lib.body.genders import GENDERS  # a leaf of the lazy body package: no torch
from airpose_lib.errors import UserError  # standard library only
from airpose_lib.profiles import profile_names  # yaml only

__all__ = [
    "CLIError", "EXIT_USER_ERROR", "GENDERS", "PROFILES", "SEQUENCE_FOLDER", "VARIANTS", "add_profile_flag",
    "parse_profile", "parse_range",
    "parse_sets", "require_file", "require_folder", "require_path", "user_error_message",
]

VARIANTS = ("baseline", "multiview", "fullcam", "airpose")
# Profile names from the files, without importing the runner (papermill is slow to import).
PROFILES = tuple(profile_names()) or ("smoke", "cpu", "paper")
SEQUENCE_FOLDER = "a recording folder in the official layout (machine_1/, machine_2/ with openpose_res.pkl)"

EXIT_USER_ERROR = 2  # as argparse for a bad flag: the user can fix it


def parse_profile(value: str) -> str:
    """``--profile``'s type: a kit profile's name or the path of a profile YAML file of one's own
    (read by :mod:`airpose_lib.profiles`; its run folders are named after the file's stem)."""
    import argparse  # the error type argparse turns into its usage message (exit 2)

    if value in PROFILES:
        return value
    if Path(value).suffix in (".yaml", ".yml"):
        if Path(value).is_file():
            return str(Path(value).absolute())
        raise argparse.ArgumentTypeError(f"profile file {value} does not exist")
    raise argparse.ArgumentTypeError(f"unknown profile {value!r}; choose one of {', '.join(PROFILES)} "
                                     "or give the path of a profile YAML file")


def add_profile_flag(parser, what: str) -> None:
    """``--profile`` as every command takes it: a kit profile's name or a profile YAML of one's own.

    Args:
        parser: the subcommand's ``argparse`` parser.
        what: what the command reads from the profile (``"sizes from the `train:` section"``).
    """
    parser.add_argument("--profile", type=parse_profile, default="smoke",
                        help=f"{what}: a kit profile ({', '.join(PROFILES)}) or the path of your own profile YAML "
                             "(default: smoke)")


class CLIError(UserError):
    """A user-facing error found by the command line itself (a flag's value): printed on one line
    without a traceback, exit status 2."""


# errno -> how to fix an OSError about a path the user gave.
_OS_FIXES = {
    errno.ENOENT: "no such file or folder; check the path",
    errno.ENOTDIR: "a part of the path is a file, not a folder; check the path",
    errno.EISDIR: "is a folder where a file was expected; give a file",
    errno.EACCES: "permission denied; choose a place you can read/write (e.g. another --out) or fix its permissions",
    errno.EPERM: "operation not permitted; choose another place (e.g. another --out) or fix its permissions",
    errno.EROFS: "read-only file system; choose another place (e.g. another --out)",
    errno.EEXIST: "already exists; remove it or choose another path",
    errno.ENAMETOOLONG: "name too long; choose a shorter path",
}


def user_error_message(exc: BaseException) -> str | None:
    """The one-line message for an error the user can fix, None for anything else (a bug)."""
    no_room = _no_room(exc)
    if no_room is not None:
        return no_room
    if isinstance(exc, UserError):  # every kit error the user can fix derives from it (CLIError too)
        return " ".join(str(exc).split()) or type(exc).__name__
    if isinstance(exc, OSError) and exc.filename is not None and exc.errno in _OS_FIXES:
        return f"{exc.filename}: {_OS_FIXES[exc.errno]}"
    if isinstance(exc, FileNotFoundError):  # raised by the kit with its own message
        return " ".join(str(exc).split())
    return None


def _no_room(exc: BaseException) -> str | None:
    """A write that found no room anywhere in the chain of ``exc`` (a writer's ENOSPC often
    surfaces as another error raised while the writer cleans up): the one-line message naming the
    file, the room there is and what to free, else None."""
    full = no_room_error(exc)
    if full is None:
        return None
    where = f" while writing {full.filename}" if full.filename else ""
    rerun = "run the command again: what was finished is kept and the rerun resumes"
    if full.errno == errno.EFBIG:
        return (f"{full.filename or 'a file'} would be larger than this process may write ({_size_limit()}); "
                f"raise the limit (`ulimit -f unlimited`) or write to another file system, and {rerun}")
    return (f"no space left on the device{where}{_free_space(full.filename)}; free some space there (or point "
            f"$AIRPOSE_CACHE / $AIRPOSE_RUNS / --out at a larger disk) and {rerun}")


def _free_space(filename: str | None) -> str:
    """`` (12.3 MB free in FOLDER)`` for the folder of ``filename``, or ``""`` when unknown."""
    import shutil

    folder = Path(filename).parent if filename else None
    while folder is not None and not folder.exists() and folder != folder.parent:
        folder = folder.parent
    try:
        return f" ({shutil.disk_usage(folder).free / 1e6:.1f} MB free in {folder})" if folder else ""
    except OSError:
        return ""


def _size_limit() -> str:
    """The process's file size limit as the message gives it (``ulimit -f`` is in 1024-byte blocks)."""
    import resource

    soft = resource.getrlimit(resource.RLIMIT_FSIZE)[0]
    if soft == resource.RLIM_INFINITY:
        return "no process limit: the file system's largest file"
    return f"the process limit `ulimit -f` is {soft} bytes"


def parse_range(text: str | None, what: str = "image numbers",
                example: str = "0:7000") -> tuple[int | None, int | None] | None:
    """``--frames START:STOP`` (either side may be empty) -> ``(START, STOP)``; None if not given."""
    if not text:
        return None
    start, sep, stop = text.partition(":")
    try:
        if not sep:
            raise ValueError
        return (int(start) if start else None, int(stop) if stop else None)
    except ValueError:
        raise CLIError(f"--frames expects START:STOP {what} (e.g. {example}), got {text!r}") from None


def require_file(path: Path | str | None, flag: str, what: str) -> Path | None:
    """``path`` (None passes) if it is an existing file, else a :class:`CLIError` naming the flag."""
    if path is None:
        return None
    p = Path(path)
    if p.is_dir():
        raise CLIError(f"{flag} {p} is a folder; give {what}")
    if not p.is_file():
        raise CLIError(f"{flag} {p}: no such file; give {what}")
    return p


def require_folder(path: Path | str | None, flag: str, what: str) -> Path | None:
    """``path`` (None passes) if it is an existing folder, else a :class:`CLIError` naming the flag."""
    if path is None:
        return None
    p = Path(path)
    if not p.is_dir():
        raise CLIError(f"{flag} {p}: {'not a folder' if p.exists() else 'no such folder'}; give {what}")
    return p


def require_path(path: Path | str | None, flag: str, what: str) -> Path | None:
    """``path`` (None passes) if it exists (file or folder), else a :class:`CLIError` naming the flag."""
    if path is not None and not Path(path).exists():
        raise CLIError(f"{flag} {path}: no such file or folder; give {what}")
    return None if path is None else Path(path)


def _check_value(item: str, value, annotation) -> object:
    """``value`` if it fits the field type ``annotation`` (ints widen to floats), else CLIError."""
    from airpose_lib.config_fields import ConfigError, check_type  # standard library only

    try:
        return check_type(f"--set {item}", value, annotation)
    except ConfigError as e:
        raise CLIError(str(e)) from None


def parse_sets(items, config_cls=None, nested: dict | None = None) -> dict:
    """``KEY=VALUE`` pairs -> ``{key: value}`` (VALUE parsed as YAML; ``loss.w_V=10`` sets a key of a
    dict field, returned as ``{"loss": {"w_V": 10.0}}``).

    With ``config_cls`` (a dataclass) every key must be one of its fields and every value must fit
    the field's type; ``nested`` maps a dict field to ``{key: type}`` of what it holds (``{"loss":
    field_types(LossConfig)}``), which checks the dotted keys. A bad key or value is a one-line
    :class:`CLIError` naming it, the expected type and, for a typo, the closest key (a dotted one
    too: ``dropout`` -> ``model.dropout``).
    """
    import yaml  # only when --set is given: the parser is built on every call, --help included

    from airpose_lib.config_fields import field_types as fields_of
    from airpose_lib.config_fields import unknown_hint

    nested = nested or {}
    top = fields_of(config_cls) if config_cls is not None else None
    dotted = [f"{name}.{key}" for name, keys in nested.items() for key in keys]
    out: dict = {}
    for item in items or ():
        key, sep, value = item.partition("=")
        if not sep or not key:
            raise CLIError(f"--set expects KEY=VALUE, got {item!r}")
        parsed = _parse_value(yaml, value)
        field_name, dot, sub = key.partition(".")
        if top is not None:
            if field_name not in top:
                raise CLIError(f"--set {item}: unknown key {field_name!r} of {config_cls.__name__}; "
                               f"{unknown_hint(field_name, [*top, *dotted])}")
            if not dot:
                parsed = _check_value(item, parsed, top[field_name])
            elif typing.get_origin(top[field_name]) not in (dict,) and top[field_name] is not dict:
                raise CLIError(f"--set {item}: {field_name!r} is not a dict option; write {field_name}=VALUE")
            elif field_name in nested:
                if sub not in nested[field_name]:
                    raise CLIError(f"--set {item}: unknown key {sub!r} of {field_name}; "
                                   f"{unknown_hint(sub, nested[field_name])}")
                parsed = _check_value(item, parsed, nested[field_name][sub])
        if dot:
            out.setdefault(field_name, {})[sub] = parsed
        else:
            out[key] = parsed
    return out


def _parse_value(yaml, text: str):
    """A ``--set`` value as YAML reads it (text that is not YAML stays text; ``1e-4``, which YAML
    1.1 reads as text, is a number)."""
    try:
        parsed = yaml.safe_load(text) if text else None
    except yaml.YAMLError:
        return text  # not YAML: keep the text, the type check decides
    if isinstance(parsed, str):
        try:
            return float(parsed)
        except ValueError:
            pass
    return parsed
