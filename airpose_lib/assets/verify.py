"""Check an asset folder against its manifest and say exactly what is missing and how to get it.

Each layout entry gets a status:

* ``present``: found (and its size and SHA-256 match where the manifest knows them);
* ``missing``: not found (a glob: fewer than ``min_count`` matches);
* ``size-mismatch``: found, but with another size (truncated or a different release);
* ``checksum-mismatch``: right size, other SHA-256 (altered or corrupted).

The size is checked before the (slow) SHA-256; ``checksums=False`` skips the SHA-256 for a quick
look. Missing optional entries do not make a report fail; damaged files always do.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import yaml

from airpose_lib.hashing import sha256_file

from .locate import AssetLocation, config_path, locate
from .manifest import AssetManifest, LayoutEntry, ManifestError, load_asset_manifest, parse_manifest

__all__ = ["PRESENT", "MISSING", "SIZE_MISMATCH", "CHECKSUM_MISMATCH", "EntryResult", "VerifyReport",
           "sha256_file", "verify"]

PRESENT = "present"
MISSING = "missing"
SIZE_MISMATCH = "size-mismatch"
CHECKSUM_MISMATCH = "checksum-mismatch"


@dataclass(frozen=True)
class EntryResult:
    """The outcome for one layout entry; ``paths`` are the files found, ``detail`` says what is wrong."""

    entry: LayoutEntry
    status: str
    paths: tuple[Path, ...] = ()
    detail: str = ""

    @property
    def ok(self) -> bool:
        return self.status == PRESENT or (self.status == MISSING and not self.entry.required)


@dataclass(frozen=True)
class VerifyReport:
    """Per-entry results for one asset folder; ``ok`` when nothing required is missing or damaged."""

    manifest: AssetManifest
    location: AssetLocation
    results: tuple[EntryResult, ...]
    checksums: bool = True
    hint: str = ""
    warning: str = ""

    @property
    def name(self) -> str:
        return self.manifest.name

    @property
    def root(self) -> Path:
        return self.location.path

    @property
    def ok(self) -> bool:
        return all(r.ok for r in self.results)

    @property
    def problems(self) -> tuple[EntryResult, ...]:
        """Results that make the report fail."""
        return tuple(r for r in self.results if not r.ok)

    def by_status(self, status: str) -> tuple[EntryResult, ...]:
        return tuple(r for r in self.results if r.status == status)

    def how_to_get(self) -> str:
        """The manifest's steps, numbered, plus where the files must go."""
        m = self.manifest
        lines = [f"  {i}. {step}" for i, step in enumerate(m.source.how_to_get, 1)]
        if not m.generated:
            where = f"Put it in {self.root}" + (f", or point {m.env_var} at the folder" if m.env_var else "")
            lines.append(f"  {where} (or add `{m.name}: /path/to/folder` to {config_path()}).")
            if m.fetchable:
                lines.append(f"  `airpose data fetch {m.name}` downloads the public files"
                             + (" (add --allow-unverified: no checksums are published)"
                                if any(f.sha256 is None for f in m.files) else "") + ".")
            if m.registration_required:
                lines.append(f"  It needs a registration at {m.source.url}, so the kit cannot download it for you.")
        return "\n".join(lines)

    def summary(self) -> str:
        """One line: name, verdict, folder."""
        verdict = "OK" if self.ok else "NOT OK"
        return (f"{self.name}: {verdict} - {self.manifest.title}\n"
                f"  folder {self.root} (from {self.location.detail})")

    def text(self) -> str:
        """What was found, what is missing or damaged, and how to fix it."""
        lines = [self.summary()]
        exists = self.root.is_dir()
        if not self.checksums:
            lines.append("  (SHA-256 not checked)")
        if not exists:
            lines.append(f"  {self.root} does not exist: none of its {len(self.results)} layout entries is there")
        for r in self.results if exists else ():
            tag = r.status if r.entry.required or r.status != MISSING else "optional, missing"
            lines.append(f"  {tag:<18} {r.entry.path}" + (f"  - {r.detail}" if r.detail else ""))
        if self.hint:
            lines.append(f"  note: {self.hint}")
        if self.warning:
            lines.append(f"  warning: {self.warning}")
        if self.ok:
            return "\n".join(lines)
        damaged = [r for r in self.problems if r.status in (SIZE_MISMATCH, CHECKSUM_MISMATCH)]
        if damaged:
            files = ", ".join(str(p) for r in damaged for p in r.paths)
            lines.append(f"Damaged: {files}. Move or delete {'it' if len(damaged) == 1 else 'them'} and get a "
                         f"fresh copy (the kit never overwrites your files):")
        else:
            missing = ", ".join(r.entry.path for r in self.problems) if exists else "all of it"
            lines.append(f"Missing: {missing}. How to get {self.name}:")
        lines.append(self.how_to_get())
        if self.manifest.licence.name:
            lines.append(f"  Licence: {self.manifest.licence.name}"
                         + (f" ({self.manifest.licence.url})" if self.manifest.licence.url else ""))
        return "\n".join(lines)

    def __str__(self) -> str:
        return self.text()


def _check_file(entry: LayoutEntry, path: Path, checksums: bool) -> EntryResult:
    size = path.stat().st_size
    if entry.size is not None and size != entry.size:
        return EntryResult(entry, SIZE_MISMATCH, (path,),
                           f"{path} has {size} bytes, the manifest says {entry.size} (truncated or another release)")
    if checksums and entry.sha256 is not None:
        digest = sha256_file(path)
        if digest != entry.sha256:
            return EntryResult(entry, CHECKSUM_MISMATCH, (path,),
                               f"{path}: SHA-256 {digest[:12]}... instead of {entry.sha256[:12]}... (altered or corrupted)")
    return EntryResult(entry, PRESENT, (path,))


def _check_entry(root: Path, entry: LayoutEntry, checksums: bool) -> EntryResult:
    if entry.is_glob:
        found = tuple(p for p in sorted(root.glob(entry.path)) if p.is_file())
        if len(found) >= entry.min_count:
            return EntryResult(entry, PRESENT, found, f"{len(found)} files")
        need = "at least one file" if entry.min_count == 1 else f"at least {entry.min_count} files"
        return EntryResult(entry, MISSING, found, f"found {len(found)}, need {need}")
    for rel in (entry.path, *entry.alternatives):
        path = root / rel
        if path.is_file():
            return _check_file(entry, path, checksums)
    return EntryResult(entry, MISSING, (), entry.description)


def _nested_hint(root: Path, manifest: AssetManifest, results: tuple[EntryResult, ...]) -> str:
    """If the layout sits one folder deeper (an archive unpacked with its top folder), say so."""
    first = next((r.entry for r in results if r.entry.required and r.status == MISSING), None)
    if first is None or not root.is_dir():
        return ""
    for sub in sorted(p for p in root.iterdir() if p.is_dir())[:50]:
        if _check_entry(sub, first, checksums=False).status == PRESENT:
            target = manifest.env_var or "the asset's folder"
            return f"the layout seems to be in {sub}: point {target} at that folder"
    return ""


def verify(name: str | AssetManifest, root: str | Path | None = None, checksums: bool = True,
           manifests: str | Path | None = None) -> VerifyReport:
    """Check the folder of asset ``name`` (``root``, else :func:`~airpose_lib.assets.locate.locate`).

    Args:
        name: an asset name (``official_real``, ``smplx_v1_1``, ``generated_smoke``, ...), a YAML
            path or a loaded manifest.
        root: the folder to check instead of the located one.
        checksums: compute SHA-256 where the manifest has one (sizes are always compared).
        manifests: manifests folder (default: the checkout's ``data_manifests/``).
    Returns:
        the :class:`VerifyReport`; ``report.ok`` and ``print(report)`` say the rest.
    """
    manifest = load_asset_manifest(name, manifests)
    location = locate(manifest, root=root)
    if manifest.generated:
        return _verify_generated(manifest, location, checksums)
    results = tuple(_check_entry(location.path, e, checksums) for e in manifest.layout)
    hint = ""
    if location.path.is_dir() and not all(r.ok for r in results):
        hint = _nested_hint(location.path, manifest, results)
    return VerifyReport(manifest, location, results, checksums, hint)


def _settings_warning(record: AssetManifest, own: AssetManifest, root: Path) -> str:
    """What ``verify`` says of a dataset made with other settings than its tracked record: both
    fingerprints and the command that rewrites the record from this dataset (after which the two
    agree, so following it ends the warning)."""
    out = "" if root == locate(record).path else f" --out {root}"
    return (f"made with other settings than the record {record.path} (fingerprint {str(own.fingerprint)[:12]}... "
            f"instead of {str(record.fingerprint)[:12]}...: the generator or the profile changed); if that is "
            f"intended, update the record with `airpose data generate --profile {record.profile}{out} "
            "--record-manifest`, else regenerate the dataset")


def _verify_generated(record: AssetManifest, location: AssetLocation, checksums: bool) -> VerifyReport:
    """A kit-generated dataset: its shards against the sizes and SHA-256 that the generator on
    *this* machine wrote into the dataset's own ``manifest.yaml``, after checking that it was made
    with the settings of the tracked record (same fingerprint, same shard files).

    The tracked ``data_manifests/generated_<profile>.yaml`` holds no shard bytes: rendering and
    JPEG encoding differ between machines, so a healthy dataset made elsewhere has other bytes,
    while a damaged one never matches its own manifest.
    """
    own_path = location.path / "manifest.yaml"
    if not own_path.is_file():
        results = tuple(_check_entry(location.path, e, checksums=False) for e in record.layout)
        return VerifyReport(record, location, results, checksums)
    try:
        own = parse_manifest(yaml.safe_load(own_path.read_text()), own_path)
    except (yaml.YAMLError, UnicodeDecodeError, ManifestError) as e:
        entry = LayoutEntry(path="manifest.yaml", required=True, description="the dataset's own manifest")
        return VerifyReport(record, location, (EntryResult(entry, CHECKSUM_MISMATCH, (own_path,),
                                                           f"unreadable ({type(e).__name__})"),), checksums)
    results = [_check_entry(location.path, e, checksums) for e in own.layout]
    hint = "shards checked against the SHA-256 this machine's generator recorded in manifest.yaml" if checksums else ""
    if record.fingerprint is not None and own.fingerprint != record.fingerprint:
        # Other settings are not damage: the shards are checked against the dataset's own manifest
        # all the same, and the record is what must follow a changed generator or profile.
        return VerifyReport(record, location, tuple(results), checksums, hint,
                            warning=_settings_warning(record, own, location.path))
    ours = {e.path for e in own.layout}
    results += [EntryResult(e, MISSING, (), "listed in the tracked record, not in the dataset's manifest")
                for e in record.layout if e.path not in ours]
    return VerifyReport(record, location, tuple(results), checksums, hint)
