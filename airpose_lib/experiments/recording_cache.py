"""The real-data experiment's cache: each step's arrays in one ``.npz`` under the experiment's
folder, keyed by what they depend on (settings, files' size and time, recordings), so notebooks
03, 04 and 05 share one run and a changed input recomputes only its steps.
"""
from __future__ import annotations

import hashlib
import json
from pathlib import Path

import numpy as np

from airpose_lib.atomic import atomic_path

__all__ = ["file_stamp", "cache_key", "method_slug", "cached_arrays", "save_arrays", "sequence_stamp"]


def file_stamp(path: Path) -> str:
    """A file's identity for a cache key: its resolved path, size and modification time."""
    st = Path(path).stat()
    return f"{Path(path).resolve()}:{st.st_size}:{st.st_mtime_ns}"


def cache_key(*parts) -> str:
    """16 hex digits of the SHA-256 of ``parts`` as JSON (keys sorted, anything else as text)."""
    return hashlib.sha256(json.dumps(parts, sort_keys=True, default=str).encode()).hexdigest()[:16]


def method_slug(method: str) -> str:
    """A method's name as a file name: ``"AirPose (pre-trained)"`` -> ``"airpose_pre_trained"``."""
    return "".join(c if c.isalnum() else "_" for c in method.lower()).strip("_").replace("__", "_")


def cached_arrays(path: Path, key: str) -> dict | None:
    """The arrays of ``path`` saved under ``key`` (:func:`save_arrays`); None when the file is
    missing, unreadable or saved under another key."""
    if not path.is_file():
        return None
    try:
        with np.load(path, allow_pickle=False) as d:
            if str(d["cache_key"]) != key:
                return None
            return {k: d[k] for k in d.files if k != "cache_key"}
    except (OSError, ValueError, KeyError):
        return None


def save_arrays(path: Path, key: str, arrays: dict) -> None:
    """Write ``arrays`` and ``key`` to ``path`` atomically (a reader never sees half a file)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    with atomic_path(path) as tmp:
        with open(tmp, "wb") as fh:
            np.savez(fh, cache_key=np.array(key), **{k: np.asarray(v) for k, v in arrays.items()})


def sequence_stamp(sequence) -> list[str]:
    """What a recording's estimates depend on besides the images: its detector files and metadata
    (re-simulated detections change the boxes)."""
    root = Path(sequence.root)
    files = sorted(root.glob("machine_*/*_res.*")) + sorted(root.glob("sequence.json"))
    return [file_stamp(f) for f in files]
