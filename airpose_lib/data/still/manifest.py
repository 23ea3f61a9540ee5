"""The manifest of a generated still-frame dataset: what made it and a SHA-256 per shard.

``<root>/manifest.yaml`` is written by the generator after every finished shard (atomically), so
it always lists exactly the shards that are complete; generation resumes from it and readers
verify shards against it. When the last shard is done its ``status`` becomes ``complete``; on
request (``airpose data generate --record-manifest``, ``record=True``) a copy goes to the
checkout's tracked ``data_manifests/generated_<profile>.yaml`` (the record that says which data a
profile's figures were made from). No command writes that file unless asked to.
"""
from __future__ import annotations

from pathlib import Path

import yaml

from airpose_lib.atomic import atomic_path
from airpose_lib.errors import UserError

from .shards import sha256_file

__all__ = [
    "MANIFEST_NAME",
    "DATASET_KIND",
    "DatasetError",
    "ShardIntegrityError",
    "load_manifest",
    "write_manifest",
    "repo_manifest_dir",
    "record_manifest",
    "machine_independent",
    "regenerate_command",
    "shard_problem",
    "verify_shard",
    "verify_dataset",
    "check_complete",
]

MANIFEST_NAME = "manifest.yaml"
DATASET_KIND = "airpose-still-frames"


class DatasetError(UserError, RuntimeError):
    """A dataset folder is missing, incomplete or was made with other settings."""


class ShardIntegrityError(DatasetError):
    """A shard file is missing, truncated or altered (its SHA-256 does not match the manifest)."""


def load_manifest(root: Path) -> dict | None:
    """The manifest of the dataset in ``root``, or None if there is none."""
    path = Path(root) / MANIFEST_NAME
    if not path.is_file():
        return None
    try:
        data = yaml.safe_load(path.read_text())
    except (yaml.YAMLError, UnicodeDecodeError) as e:  # cut short or overwritten
        raise DatasetError(
            f"{path} is damaged ({type(e).__name__}); delete it and run `{regenerate_command(None, Path(root))}` "
            "again: every shard is then checked and rebuilt identically where needed") from e
    if not isinstance(data, dict) or data.get("kind") != DATASET_KIND:
        raise DatasetError(f"{path} is not a still-frame dataset manifest (kind != {DATASET_KIND!r})")
    return data


def write_manifest(root: Path, manifest: dict) -> Path:
    """Write ``<root>/manifest.yaml`` atomically; returns its path."""
    path = Path(root) / MANIFEST_NAME
    with atomic_path(path) as tmp:
        tmp.write_text(_dump(manifest))
    return path


def _dump(manifest: dict, tracked: bool = False) -> str:
    # The header names the generator's module as it was (``airpose_lib.data.generate``, now
    # ``data.still.generate``) so that a manifest stays byte for byte what the committed ones are.
    header = ("# Written by `airpose data generate` (airpose_lib.data.generate); do not edit.\n"
              + ("# The settings and splits of a profile's dataset, the same on every machine; each shard's size\n"
                 "# and SHA-256 are in the dataset's own manifest.yaml (`airpose data verify` checks them).\n"
                 if tracked else
                 "# One entry per finished shard with its SHA-256; readers refuse shards that differ.\n"))
    return header + yaml.safe_dump(manifest, sort_keys=False, default_flow_style=None, width=100)


def repo_manifest_dir() -> Path | None:
    """The checkout's ``data_manifests/`` folder, or None when the kit is installed elsewhere."""
    folder = Path(__file__).resolve().parents[3] / "data_manifests"  # <repo>/airpose_lib/data/still/
    return folder if folder.is_dir() else None


def machine_independent(manifest: dict) -> dict:
    """A dataset manifest without what differs between machines for the same settings: each shard's
    size and SHA-256, the total bytes (off-screen rendering and JPEG encoding give other bytes on
    another CPU or Mesa build) and the body-model files' SHA-256 (built on each machine). What stays (settings, fingerprint, splits, sample counts) says
    which data a profile's results were made from; the bytes are checked against the dataset's
    own ``manifest.yaml``, written by the generator on the machine that holds it."""
    out = dict(manifest)
    out["shards"] = [{k: v for k, v in rec.items() if k not in ("bytes", "sha256")}
                     for rec in manifest.get("shards") or []]
    if isinstance(out.get("totals"), dict):
        out["totals"] = {k: v for k, v in out["totals"].items() if k != "bytes"}
    if isinstance(out.get("body_models"), dict):  # the open body model is built on each machine
        out["body_models"] = {k: v for k, v in out["body_models"].items() if k != "sha256"}
    return out


def record_manifest(manifest: dict, folder: Path | None = None) -> Path | None:
    """Copy a complete manifest, :func:`machine_independent`, to ``<folder>/generated_<profile>.yaml``
    (default: the checkout's ``data_manifests/``). Returns the path, or None if there is no such
    folder or no profile."""
    folder = Path(folder) if folder is not None else repo_manifest_dir()
    profile = manifest.get("profile")
    if folder is None or not profile:
        return None
    path = folder / f"generated_{profile}.yaml"
    with atomic_path(path) as tmp:
        tmp.write_text(_dump(machine_independent(manifest), tracked=True))
    return path


def regenerate_command(manifest: dict | None, root: Path) -> str:
    """The command that (re)generates or resumes this dataset."""
    profile = (manifest or {}).get("profile")
    prof = f" --profile {profile}" if profile else " --profile PROFILE"
    return f"airpose data generate{prof} --out {root}"


# Shards this process has hashed: absolute path -> (size, mtime_ns, SHA-256). A shard is hashed
# once per process (a training opens its splits several times) and again whenever its size or
# modification time changes.
_VERIFIED: dict[str, tuple[int, int, str]] = {}


def shard_problem(root: Path, record: dict) -> str | None:
    """What is wrong with one shard against its manifest record (missing, size, SHA-256), or None.

    The SHA-256 is computed once per process and file version (size and modification time).
    """
    path = Path(root) / record["file"]
    try:
        st = path.stat()
    except FileNotFoundError:
        return "is missing"
    if st.st_size != record["bytes"]:
        return f"is damaged: {st.st_size} bytes instead of {record['bytes']} (truncated or altered)"
    key = str(path.absolute())
    seen = _VERIFIED.get(key)
    if seen is not None and seen[:2] == (st.st_size, st.st_mtime_ns):
        digest = seen[2]
    else:
        digest = sha256_file(path)
        _VERIFIED[key] = (st.st_size, st.st_mtime_ns, digest)
    if digest != record["sha256"]:
        return (f"is damaged: SHA-256 {digest[:16]}... does not match the manifest's "
                f"{record['sha256'][:16]}... (altered or corrupted)")
    return None


def verify_shard(root: Path, record: dict, manifest: dict | None = None) -> Path:
    """Check one shard against its manifest record (size, then SHA-256); returns its path.

    Raises:
        ShardIntegrityError: naming the file, what is wrong and the command that repairs it.
    """
    path = Path(root) / record["file"]
    problem = shard_problem(root, record)
    if problem is not None:
        raise ShardIntegrityError(
            f"shard {path} {problem}; regenerate it with `{regenerate_command(manifest, root)}` (finished "
            f"shards are kept, missing or damaged ones are rebuilt identically)")
    return path


def verify_dataset(root: Path) -> dict:
    """:func:`check_complete`, then every shard checked (:func:`verify_shard`; hashed once per
    process, so the datasets that open it later do not hash again). Returns the manifest."""
    manifest = check_complete(root)
    for rec in manifest.get("shards") or []:
        verify_shard(root, rec, manifest)
    return manifest


def check_complete(root: Path) -> dict:
    """The manifest of ``root``, raising :class:`DatasetError` if absent or unfinished."""
    root = Path(root)
    manifest = load_manifest(root)
    if manifest is None:
        raise DatasetError(
            f"no dataset in {root} (no {MANIFEST_NAME}); generate it with "
            f"`{regenerate_command(None, root)}`")
    if manifest.get("status") != "complete":
        done = len(manifest.get("shards") or [])
        raise DatasetError(
            f"dataset in {root} is incomplete ({done} of {manifest.get('num_shards')} shards); "
            f"resume with `{regenerate_command(manifest, root)}`")
    return manifest
