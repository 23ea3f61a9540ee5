"""Shard files of the still-frame dataset: one ``.npz`` per shard, reproducible to the byte.

A shard holds a few hundred samples: the encoded crops of every view, concatenated in one
``images`` byte array with ``image_offsets`` (sample ``i``, view ``c`` is
``images[image_offsets[i * V + c]:image_offsets[i * V + c + 1]]``), and the ground-truth arrays
(one row per sample). It is an ordinary ``.npz`` (``numpy.load`` reads it) written without
compression and with fixed zip timestamps, so the same arrays always give the same bytes and the
same SHA-256. Because nothing is compressed, a reader can memory-map the image bytes instead of
loading a whole shard (:class:`ShardImages`).

Files are written through :func:`airpose_lib.atomic.atomic_path`: a shard on disk is either
complete or absent, which is what makes interrupted generation resumable shard by shard.
"""
from __future__ import annotations

import io
import json
import struct
import zipfile
from pathlib import Path

import numpy as np

from airpose_lib.atomic import atomic_path
from airpose_lib.hashing import sha256_file

__all__ = [
    "write_shard",
    "read_shard",
    "read_shard_meta",
    "sha256_file",
    "ShardImages",
    "shard_name",
]

_ZIP_EPOCH = (1980, 1, 1, 0, 0, 0)  # fixed timestamp: identical bytes for identical content


def shard_name(index: int) -> str:
    """File name of shard ``index`` (``shard_00007.npz``)."""
    return f"shard_{index:05d}.npz"


def _npy_bytes(array: np.ndarray) -> bytes:
    buf = io.BytesIO()
    np.lib.format.write_array(buf, np.ascontiguousarray(array), version=(1, 0), allow_pickle=False)
    return buf.getvalue()


def write_shard(path: Path, arrays: dict[str, np.ndarray], meta: dict | None = None) -> tuple[str, int]:
    """Write ``arrays`` (and ``meta`` as JSON) to ``path`` atomically and reproducibly.

    Members are stored uncompressed, in sorted name order, with a fixed timestamp.

    Returns:
        ``(sha256 hex digest, size in bytes)`` of the written file.
    """
    members = dict(arrays)
    if meta is not None:
        members["meta_json"] = np.frombuffer(json.dumps(meta, sort_keys=True).encode(), dtype=np.uint8)
    with atomic_path(Path(path)) as tmp:
        with zipfile.ZipFile(tmp, "w", compression=zipfile.ZIP_STORED, allowZip64=True) as zf:
            for name in sorted(members):
                info = zipfile.ZipInfo(f"{name}.npy", date_time=_ZIP_EPOCH)
                info.compress_type = zipfile.ZIP_STORED
                info.external_attr = 0o644 << 16
                zf.writestr(info, _npy_bytes(members[name]))
        digest = sha256_file(tmp)
        size = tmp.stat().st_size
    return digest, size


def read_shard(path: Path, names: list[str] | None = None) -> dict[str, np.ndarray]:
    """Load a shard's arrays (all, or ``names``) into memory; ``meta_json`` is decoded to ``meta``."""
    with np.load(Path(path), allow_pickle=False) as data:
        keys = names if names is not None else list(data.files)
        out = {k: data[k] for k in keys if k != "meta_json"}
        if names is None and "meta_json" in data.files:
            out["meta"] = json.loads(bytes(data["meta_json"]).decode())
    return out


def read_shard_meta(path: Path) -> dict:
    """The JSON metadata written with the shard."""
    with np.load(Path(path), allow_pickle=False) as data:
        return json.loads(bytes(data["meta_json"]).decode())


def _member_data_offset(path: Path, member: str) -> tuple[int, np.dtype, tuple[int, ...]]:
    """File offset, dtype and shape of the array data of an uncompressed ``.npy`` zip member."""
    with zipfile.ZipFile(path) as zf:
        info = zf.getinfo(member)
    if info.compress_type != zipfile.ZIP_STORED:
        raise ValueError(f"{path}: member {member} is compressed; cannot memory-map it")
    with open(path, "rb") as f:
        f.seek(info.header_offset)
        local = f.read(30)
        if local[:4] != b"PK\x03\x04":
            raise ValueError(f"{path}: bad local header for {member}")
        name_len, extra_len = struct.unpack("<HH", local[26:30])
        f.seek(info.header_offset + 30 + name_len + extra_len)
        version = np.lib.format.read_magic(f)
        read_header = (np.lib.format.read_array_header_1_0 if version == (1, 0)
                       else np.lib.format.read_array_header_2_0)
        shape, fortran, dtype = read_header(f)
        if fortran:
            raise ValueError(f"{path}: {member} is Fortran-ordered")
        return f.tell(), dtype, shape


class ShardImages:
    """Lazy, memory-mapped access to the encoded crops of one shard.

    Args:
        path: the shard file.
        offsets: its ``image_offsets`` array ``(n * V + 1,)``.
        member: the image array (``images``; test shards also have ``images_tight``).

    ``get(j)`` returns the encoded bytes (JPEG/PNG) of image ``j = sample * V + view``. The map
    is opened on first use, so the object pickles cheaply into DataLoader workers.
    """

    def __init__(self, path: Path, offsets: np.ndarray, member: str = "images") -> None:
        self.path = Path(path)
        self.offsets = np.asarray(offsets, dtype=np.int64)
        self.member = member
        self._map: np.memmap | None = None

    def _open(self) -> np.memmap:
        if self._map is None:
            start, dtype, shape = _member_data_offset(self.path, f"{self.member}.npy")
            if dtype != np.uint8 or len(shape) != 1:
                raise ValueError(f"{self.path}: images must be a flat uint8 array, got {dtype} {shape}")
            self._map = np.memmap(self.path, dtype=np.uint8, mode="r", offset=start, shape=shape)
        return self._map

    def get(self, j: int) -> bytes:
        m = self._open()
        return m[self.offsets[j]:self.offsets[j + 1]].tobytes()

    def __getstate__(self) -> dict:
        return {"path": self.path, "offsets": self.offsets, "member": self.member, "_map": None}
