"""External assets: manifests, where they live, verification, download, and the data-source choice.

One YAML per asset in ``data_manifests/`` (schema in its README) describes the official AirPose
data and checkpoints, SMPL-X v1.1, VPoser V02_05 and the kit's generated datasets.

* :func:`list_manifests`, :func:`load_asset_manifest`: read and validate them;
* :func:`locate`: the asset's folder (``--root``, its environment variable, the assets config
  file, or ``<cache>/assets/<name>``);
* :func:`verify`: per-file present / missing / size-mismatch / checksum-mismatch and what to do;
* :func:`fetch`: checksummed downloads of public files (never replaces the user's files);
* :func:`resolve_data_source`: ``"official"`` when the assets are there, else the generated data
  with a message saying what is missing.

Command line: ``airpose data list | verify NAME | fetch NAME``. Nothing here imports torch; pooch
is imported only when downloading.
"""
from __future__ import annotations

from .data_source import DATA_SOURCES, DataSource, resolve_data_source
from .fetch import ChecksumError, FetchError, FetchReport, FileOutcome, RegistrationRequired, fetch
from .locate import ASSETS_CONFIG_ENV, AssetLocation, config_path, default_root, locate, read_config
from .manifest import (
    GENERATED_KIND,
    KINDS,
    AssetError,
    AssetManifest,
    LayoutEntry,
    Licence,
    ManifestError,
    RemoteFile,
    Source,
    list_manifests,
    load_asset_manifest,
    manifest_dir,
    read_manifest,
)
from .verify import CHECKSUM_MISMATCH, MISSING, PRESENT, SIZE_MISMATCH, EntryResult, VerifyReport, sha256_file, verify

__all__ = [
    "AssetError", "ManifestError", "FetchError", "RegistrationRequired", "ChecksumError",
    "AssetManifest", "LayoutEntry", "RemoteFile", "Source", "Licence", "KINDS", "GENERATED_KIND",
    "manifest_dir", "read_manifest", "list_manifests", "load_asset_manifest",
    "ASSETS_CONFIG_ENV", "AssetLocation", "config_path", "read_config", "default_root", "locate",
    "PRESENT", "MISSING", "SIZE_MISMATCH", "CHECKSUM_MISMATCH", "EntryResult", "VerifyReport", "sha256_file",
    "verify", "FileOutcome", "FetchReport", "fetch", "DATA_SOURCES", "DataSource", "resolve_data_source",
]
