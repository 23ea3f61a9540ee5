"""Where the kit keeps what it builds, and an inter-process lock for building it once.

``AIRPOSE_CACHE`` (default ``~/.cache/airpose``) holds the open body model and anny's own build
cache (``<cache>/anny`` unless ``ANNY_CACHE_DIR`` is set).
"""
from __future__ import annotations

import contextlib
import fcntl
import os
from pathlib import Path
from typing import Iterator


def cache_dir() -> Path:
    """The kit's cache folder (``$AIRPOSE_CACHE`` or ``~/.cache/airpose``), created on demand."""
    root = Path(os.environ.get("AIRPOSE_CACHE", Path.home() / ".cache" / "airpose")).expanduser()
    root.mkdir(parents=True, exist_ok=True)
    return root


@contextlib.contextmanager
def file_lock(path: Path) -> Iterator[None]:
    """Exclusive inter-process lock, so parallel test workers build the model only once."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "a+") as handle:
        fcntl.flock(handle, fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(handle, fcntl.LOCK_UN)
