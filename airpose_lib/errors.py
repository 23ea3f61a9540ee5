"""Errors a user can fix, and how a damaged input file is reported.

:func:`reading` wraps the load of one input file: whatever a truncated, corrupted or foreign file
makes the underlying reader raise (``zipfile.BadZipFile``, ``EOFError``, pickle and torch errors,
a ``KeyError`` for a missing entry) becomes one :class:`DamagedFileError` that names the file,
says what it should have been and how to get a good one. A missing file stays a
``FileNotFoundError`` (the ``airpose`` command reports both in one line, exit status 2).
:class:`ProfileError` is an unknown profile or a profile file without a section it needs,
:class:`ConfigError` a configuration value of the wrong type or range; all derive from
:class:`UserError`, the class the ``airpose`` command reports on one line.

Every error class of the kit that a user can fix derives from :class:`UserError` (and keeps its
built-in base, e.g. ``class SourceError(UserError, ValueError)``, for ``except ValueError``
callers); raise one of them, never a plain ``ValueError``, for a mistake in a file, a profile or a
flag. A plain exception is a bug and keeps its traceback. ``tests/test_cli_errors.py`` lists the
two exception classes that are not user errors (``runtime.wire.WireError``,
``safe_pickle.ForbiddenGlobalError``). Imports nothing of the kit.
"""
from __future__ import annotations

import contextlib
import os
import pickle
import zipfile
from collections.abc import Iterator
from pathlib import Path

__all__ = ["ConfigError", "DamagedFileError", "ProfileError", "UserError", "reading"]

# What readers raise on a truncated, corrupted or foreign file (ImportError / AttributeError: a
# pickle naming classes that do not exist here; UnicodeDecodeError is a ValueError).
_CONTENT_ERRORS = (EOFError, KeyError, IndexError, ValueError, RuntimeError, OSError, TypeError,
                   AttributeError, ImportError, pickle.UnpicklingError, zipfile.BadZipFile)


class UserError(Exception):
    """An error the user can fix: its message names the file or value, what is wrong and the fix.
    The ``airpose`` command prints it on one line (exit status 2); anything else is a bug and
    keeps its traceback."""


class ConfigError(UserError, ValueError):
    """A configuration value of the wrong type or range, or an unknown key; the message names the
    field (and the profile file or flag it came from). A ``ValueError``, as the checks it replaced."""


class DamagedFileError(UserError, ValueError):
    """An input file exists but cannot be read as what it should be; the message names it and the fix."""

    def __init__(self, path: str | os.PathLike, what: str, fix: str, cause: BaseException | None = None):
        self.path, self.what, self.fix = Path(path), what, fix
        detail = f" ({type(cause).__name__}: {_short(cause)})" if cause is not None else ""
        super().__init__(f"{path} is damaged or not {what}{detail}; {fix}")


class ProfileError(UserError, ValueError):
    """An unknown profile, or a profile file that lacks (or garbles) a section; the message names
    the file and the fix. A ``ValueError``, as the readers it replaced raised."""


class ProfileSettingError(ProfileError, ConfigError):
    """A profile section's key that its config does not have (the message names the closest one),
    or a value it refuses; the message names the file and the section. Both a
    :class:`ProfileError` (the file is wrong) and a :class:`ConfigError` (a setting is), so the
    ``except`` clauses of either keep working (``profiles.section_config``)."""


def _short(exc: BaseException, limit: int = 120) -> str:
    text = " ".join(str(exc).split()) or type(exc).__name__
    return text if len(text) <= limit else text[: limit - 3] + "..."


@contextlib.contextmanager
def reading(path: str | os.PathLike, what: str, fix: str) -> Iterator[Path]:
    """Load ``path`` inside the block; a damaged file raises :class:`DamagedFileError`.

    Args:
        path: the input file.
        what: what it should be, with an article (``"a checkpoint of `airpose train`"``).
        fix: how to get a good one (``"train again or pick another --checkpoint"``).
    Raises:
        FileNotFoundError: ``path`` does not exist (before the block runs).
        DamagedFileError: the block failed on the file's content.
    """
    path = Path(path)
    if not path.exists():
        raise FileNotFoundError(2, "No such file or directory", str(path))
    try:
        yield path
    except (FileNotFoundError, PermissionError, IsADirectoryError, DamagedFileError):
        raise
    except _CONTENT_ERRORS as exc:
        if str(path) in str(exc):  # the reader's own message already names the file
            raise
        raise DamagedFileError(path, what, fix, exc) from exc
