"""Download an asset's public files (checksummed, with pooch) without ever touching the user's files.

Rules:

* Only files listed under ``files:`` in the manifest are downloaded, and only for assets without
  registration. Registration-only assets (SMPL-X, VPoser) raise :class:`RegistrationRequired`
  with the steps to get them by hand; generated datasets say which command makes them.
* A file whose manifest has no SHA-256 is downloaded only with ``allow_unverified=True``; its
  SHA-256 is then reported so that it can be recorded in the manifest.
* A file already in place is never replaced or deleted: right checksum -> skipped; wrong size or
  checksum -> reported as a conflict and left alone.
* Downloads go to a private staging folder beside the target and are moved in place only after
  the checksum matched (a hard link that fails if the name exists, so a file that appeared
  meanwhile is not overwritten either). A failed or tampered download leaves nothing behind.
* Archives (``extract: tar|zip``) are unpacked into ``<root>/<extract_to>`` through a staging
  folder; when every member sits in one top folder that folder is dropped; files that already
  exist are kept. A ``.<archive>.extracted`` marker records a finished extraction.
"""
from __future__ import annotations

import contextlib
import json
import logging
import os
import shutil
import tarfile
import tempfile
import urllib.parse
import zipfile
from dataclasses import dataclass
from pathlib import Path, PurePosixPath
from typing import Iterator

from airpose_lib.atomic import atomic_path

from .locate import AssetLocation, config_path, locate
from .manifest import AssetError, AssetManifest, RemoteFile, load_asset_manifest
from .verify import VerifyReport, sha256_file, verify

__all__ = ["FetchError", "RegistrationRequired", "ChecksumError", "FileOutcome", "FetchReport", "fetch",
           "DOWNLOADED", "SKIPPED", "UNVERIFIED_PRESENT", "CONFLICT"]

DOWNLOADED = "downloaded"
SKIPPED = "already-present"
UNVERIFIED_PRESENT = "present-unverified"
CONFLICT = "conflict"


class FetchError(AssetError):
    """The asset cannot be downloaded; the message says why and what to do instead."""


class RegistrationRequired(FetchError):
    """The asset's licence requires a personal registration: the user has to download it."""


class ChecksumError(FetchError):
    """A downloaded file did not match its SHA-256 (nothing was kept)."""


@dataclass(frozen=True)
class FileOutcome:
    """What happened to one manifest file. ``extraction`` describes the unpacking of an archive."""

    name: str
    path: Path
    status: str
    sha256: str | None = None
    detail: str = ""
    extraction: str = ""


@dataclass(frozen=True)
class FetchReport:
    manifest: AssetManifest
    location: AssetLocation
    outcomes: tuple[FileOutcome, ...]
    verification: VerifyReport | None = None

    @property
    def ok(self) -> bool:
        """No conflict with the user's files and the folder now verifies (sizes, no checksums)."""
        return (all(o.status != CONFLICT for o in self.outcomes)
                and (self.verification is None or self.verification.ok))

    def text(self) -> str:
        lines = [f"{self.manifest.name}: fetch into {self.location.path} (from {self.location.detail})"]
        for o in self.outcomes:
            lines.append(f"  {o.status:<18} {o.name}" + (f"  - {o.detail}" if o.detail else ""))
            if o.extraction:
                lines.append(f"  {'':<18} {o.extraction}")
        unpinned = [o for o in self.outcomes if o.status == DOWNLOADED and o.detail.startswith("unverified")]
        if unpinned:
            lines.append("  Record these SHA-256 values in the manifest's files: entries to pin the downloads:")
            lines += [f"    {o.name}: {o.sha256}" for o in unpinned]
        if self.verification is not None:
            lines.append(self.verification.text() if not self.verification.ok else
                         f"  layout check: OK (run `airpose data verify {self.manifest.name}` for checksums)")
        return "\n".join(lines)

    def __str__(self) -> str:
        return self.text()


# -- refusals -------------------------------------------------------------------------------------
def _steps(m: AssetManifest) -> str:
    return "\n".join(f"  {i}. {s}" for i, s in enumerate(m.source.how_to_get, 1))


def _refuse(m: AssetManifest, location: AssetLocation) -> None:
    where = (f"Then point {m.env_var} at the folder (or add `{m.name}: /path/to/folder` to {config_path()}), "
             f"or put it in {location.path}, and check it with `airpose data verify {m.name}`.")
    if m.generated:
        raise FetchError(f"{m.name} is made by the kit, not downloaded:\n{_steps(m)}")
    if m.registration_required:
        raise RegistrationRequired(
            f"{m.name} ({m.title}) cannot be downloaded by the kit: its licence "
            f"({m.licence.name}) requires every user to register personally at {m.source.url} and "
            f"accept the terms, and it does not allow redistribution. How to get it:\n{_steps(m)}\n{where}")
    if not m.files:
        raise FetchError(f"no public direct download is known for {m.name} ({m.title}). "
                         f"How to get it:\n{_steps(m)}\n{where}")


# -- placing files without clobbering -------------------------------------------------------------
def _place(src: Path, target: Path) -> bool:
    """Move ``src`` to ``target`` unless ``target`` exists; True if moved. Atomic where hard links work."""
    target.parent.mkdir(parents=True, exist_ok=True)
    if src.is_symlink():
        if target.exists() or target.is_symlink():
            return False
        os.rename(src, target)
        return True
    try:
        os.link(src, target)  # fails if target exists: never overwrites
    except FileExistsError:
        return False
    except OSError:  # file system without hard links
        if target.exists() or target.is_symlink():
            return False
        os.rename(src, target)
        return True
    os.unlink(src)
    return True


@contextlib.contextmanager
def _staging(parent: Path, prefix: str) -> Iterator[Path]:
    """A private temporary folder in ``parent`` (same file system), always removed afterwards."""
    parent.mkdir(parents=True, exist_ok=True)
    folder = Path(tempfile.mkdtemp(dir=parent, prefix=prefix))
    try:
        yield folder
    finally:
        shutil.rmtree(folder, ignore_errors=True)


@contextlib.contextmanager
def _pooch_quiet(progress: bool) -> Iterator[None]:
    import pooch

    logger = pooch.get_logger()
    level = logger.level
    if not progress:
        logger.setLevel(logging.WARNING)
    try:
        yield
    finally:
        logger.setLevel(level)


def _download(url: str, sha256: str | None, target: Path, progress: bool) -> str:
    """Download ``url`` to ``target`` (must not exist) through a staging folder; returns its SHA-256."""
    import pooch
    import requests

    with _staging(target.parent, f".{target.name}.fetch-") as stage, _pooch_quiet(progress):
        try:
            got = Path(pooch.retrieve(url, known_hash=f"sha256:{sha256}" if sha256 else None, fname=target.name,
                                      path=stage, progressbar=progress,
                                      downloader=pooch.HTTPDownloader(progressbar=progress, timeout=60)))
        except requests.exceptions.RequestException as e:
            raise FetchError(f"download of {url} failed: {e}") from None
        except ValueError as e:
            if "hash" in str(e).lower():
                raise ChecksumError(
                    f"{url} does not match the manifest's SHA-256 {sha256} (the server's copy differs: a "
                    f"changed release, a proxy error page or tampering); nothing was saved to {target}. "
                    f"Details: {e}") from None
            raise FetchError(f"download of {url} failed: {e}") from None
        digest = sha256 or sha256_file(got)
        if not _place(got, target):
            raise FetchError(f"{target} appeared while downloading; it was left untouched")
    return digest


# -- archives -------------------------------------------------------------------------------------
def _unpack(archive: Path, kind: str, into: Path) -> None:
    """Unpack ``archive`` into the (empty, private) folder ``into``, refusing unsafe member names."""
    try:
        if kind == "tar":
            with tarfile.open(archive, "r:*") as tf:
                if hasattr(tarfile, "data_filter"):
                    tf.extractall(into, filter="data")  # no absolute/.. paths, links or devices outside
                else:  # pragma: no cover - Python without PEP 706
                    for member in tf.getmembers():
                        parts = PurePosixPath(member.name).parts
                        if member.name.startswith("/") or ".." in parts or member.issym() or member.islnk() \
                                or member.isdev():
                            raise FetchError(f"{archive}: refusing unsafe member {member.name!r}")
                    tf.extractall(into)
        elif kind == "zip":
            with zipfile.ZipFile(archive) as zf:
                zf.extractall(into)  # zipfile drops absolute and '..' components
        else:
            raise FetchError(f"unknown archive kind {kind!r}")
    except (tarfile.TarError, zipfile.BadZipFile, EOFError, OSError) as e:
        raise FetchError(f"cannot unpack {archive}: {e}. Move the file away and fetch again.") from None


def _merge(src: Path, dest: Path) -> tuple[int, int]:
    """Move every file of ``src`` into ``dest`` keeping existing files; returns (moved, kept)."""
    moved = kept = 0
    for dirpath, _dirnames, filenames in os.walk(src):
        rel = Path(dirpath).relative_to(src)
        for fn in filenames:
            if _place(Path(dirpath) / fn, dest / rel / fn):
                moved += 1
            else:
                kept += 1
    return moved, kept


def _extract(archive: Path, f: RemoteFile, root: Path, progress: bool) -> str:
    marker = root / f".{f.name}.extracted"
    dest = root / f.extract_to
    if marker.is_file():
        return f"already unpacked into {dest} ({marker.name} exists; delete it to unpack again)"
    if progress:
        print(f"unpacking {archive.name} into {dest} ...", flush=True)
    with _staging(root, f".{f.name}.unpack-") as stage:
        _unpack(archive, f.extract, stage)
        top = [p for p in stage.iterdir()]
        base = top[0] if len(top) == 1 and top[0].is_dir() and not top[0].is_symlink() else stage
        moved, kept = _merge(base, dest)

    with atomic_path(marker) as tmp:
        tmp.write_text(json.dumps({"archive": f.name, "into": str(dest), "files": moved, "kept_existing": kept}) + "\n")
    stripped = f" (dropped the archive's top folder {base.name}/)" if base is not stage else ""
    return (f"unpacked {moved} files into {dest}{stripped}"
            + (f"; kept {kept} existing files unchanged" if kept else "")
            + f"; {archive.name} can be deleted if disk space is short")


# -- entry point ----------------------------------------------------------------------------------
def _url_for(f: RemoteFile, base_url: str | None) -> str:
    if base_url is None:
        return f.url
    return f"{base_url.rstrip('/')}/{urllib.parse.quote(f.name)}"


def _existing(f: RemoteFile, path: Path) -> FileOutcome:
    size = path.stat().st_size
    if f.size is not None and size != f.size:
        return FileOutcome(f.name, path, CONFLICT, None,
                           f"{path} exists with {size} bytes, the manifest says {f.size}; left untouched - "
                           f"move it away to download a fresh copy")
    if f.sha256 is None:
        return FileOutcome(f.name, path, UNVERIFIED_PRESENT, None,
                           f"{path} exists; no published SHA-256 to check it against")
    digest = sha256_file(path)
    if digest != f.sha256:
        return FileOutcome(f.name, path, CONFLICT, digest,
                           f"{path} exists but its SHA-256 {digest[:12]}... is not the manifest's "
                           f"{f.sha256[:12]}...; left untouched - move it away to download a fresh copy")
    return FileOutcome(f.name, path, SKIPPED, digest, "checksum OK")


def fetch(name: str | AssetManifest, root: str | Path | None = None, base_url: str | None = None,
          progress: bool = False, *, allow_unverified: bool = False,
          manifests: str | Path | None = None) -> FetchReport:
    """Download the public files of asset ``name`` into its folder (see the module docstring).

    Args:
        name: asset name (``official_real``, ...), YAML path or loaded manifest.
        root: target folder instead of the located one (:func:`~airpose_lib.assets.locate.locate`).
        base_url: fetch ``<base_url>/<file name>`` instead of each file's URL (a mirror).
        progress: show download progress bars.
        allow_unverified: also download files whose SHA-256 is not in the manifest.
        manifests: manifests folder (default: the checkout's ``data_manifests/``).
    Returns:
        a :class:`FetchReport`; ``report.ok`` is False if a file of yours conflicts or the folder
        still does not verify.
    Raises:
        RegistrationRequired: the asset needs a personal registration.
        FetchError: nothing to download, unverified files without ``allow_unverified``, a network
            error or a bad archive; ChecksumError when a download does not match (nothing kept).
    """
    manifest = load_asset_manifest(name, manifests)
    location = locate(manifest, root=root)
    _refuse(manifest, location)
    root_path = location.path
    todo = [f for f in manifest.files if not (root_path / f.name).exists()]
    unpinned = [f.name for f in todo if f.sha256 is None]
    if unpinned and not allow_unverified:
        raise FetchError(
            f"the manifest of {manifest.name} has no SHA-256 for {', '.join(unpinned)} (none is published), so "
            f"the download cannot be verified. Run again with --allow-unverified (fetch(..., "
            f"allow_unverified=True)) to download anyway; the SHA-256 obtained is printed so that you can "
            f"record it in {manifest.path}. Or download by hand:\n{_steps(manifest)}")
    root_path.mkdir(parents=True, exist_ok=True)
    outcomes = []
    for f in manifest.files:
        target = root_path / f.name
        if target.exists():
            outcome = _existing(f, target)
        else:
            url = _url_for(f, base_url)
            digest = _download(url, f.sha256, target, progress)
            outcome = FileOutcome(f.name, target, DOWNLOADED, digest,
                                  "checksum OK" if f.sha256 else f"unverified (no published SHA-256), sha256 {digest}")
        if f.extract and outcome.status != CONFLICT:
            outcome = FileOutcome(outcome.name, outcome.path, outcome.status, outcome.sha256, outcome.detail,
                                  _extract(target, f, root_path, progress))
        outcomes.append(outcome)
    return FetchReport(manifest, location, tuple(outcomes), verify(manifest, root=root_path, checksums=False))
