"""Where an asset lives on this machine.

First match wins:

1. an explicit ``root`` argument (``--root DIR`` on the command line);
2. the asset's environment variable (``env_var`` in its manifest, e.g. ``AIRPOSE_SMPLX_DIR``);
3. the assets config file, ``$AIRPOSE_ASSETS_CONFIG`` or ``~/.config/airpose/assets.yaml``
   (``$XDG_CONFIG_HOME/airpose/assets.yaml`` when that is set): a YAML mapping
   ``name: folder``; relative folders are relative to the config file, ``~`` is expanded;
4. the default under the kit cache: ``<cache>/assets/<name>`` (``<cache>`` =
   :func:`airpose_lib.paths.cache_dir`); a generated dataset's default is where the
   generator writes it, ``<cache>/data/still_<profile>``.

Nothing here creates the folder.
"""
from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import yaml

from airpose_lib.paths import cache_dir

from .manifest import AssetError, AssetManifest, load_asset_manifest

__all__ = ["ASSETS_CONFIG_ENV", "AssetLocation", "config_path", "read_config", "default_root", "locate"]

ASSETS_CONFIG_ENV = "AIRPOSE_ASSETS_CONFIG"


@dataclass(frozen=True)
class AssetLocation:
    """``path``: the asset's folder; ``origin``: ``argument``, ``env``, ``config`` or ``default``;
    ``detail``: where that came from, in words (e.g. ``$AIRPOSE_SMPLX_DIR``)."""

    name: str
    path: Path
    origin: str
    detail: str


def config_path() -> Path:
    """The assets config file to read (it need not exist)."""
    value = os.environ.get(ASSETS_CONFIG_ENV)
    if value:
        return Path(value).expanduser()
    base = os.environ.get("XDG_CONFIG_HOME") or str(Path.home() / ".config")
    return Path(base).expanduser() / "airpose" / "assets.yaml"


def read_config(path: str | Path | None = None) -> dict[str, Path]:
    """The ``name -> folder`` mapping of the assets config (empty if the default file is absent).

    Raises:
        AssetError: the file named by ``$AIRPOSE_ASSETS_CONFIG`` does not exist, or the file is not a
            mapping of names to folder strings.
    """
    explicit = path is not None or bool(os.environ.get(ASSETS_CONFIG_ENV))
    path = Path(path).expanduser() if path is not None else config_path()
    if not path.is_file():
        if explicit:
            raise AssetError(f"assets config {path} (from ${ASSETS_CONFIG_ENV}) does not exist; create it "
                             f"(a YAML mapping like `official_real: /data/airpose/real`) or unset the variable")
        return {}
    try:
        data = yaml.safe_load(path.read_text())
    except (OSError, yaml.YAMLError) as e:
        raise AssetError(f"cannot read assets config {path}: {e}") from None
    if data is None:
        return {}
    if not isinstance(data, dict):
        raise AssetError(f"assets config {path} must be a YAML mapping `asset_name: folder`, "
                         f"got {type(data).__name__}")
    out: dict[str, Path] = {}
    for name, folder in data.items():
        if not isinstance(name, str) or not isinstance(folder, str) or not folder.strip():
            raise AssetError(f"assets config {path}: entry {name!r}: expected `name: folder` with a folder "
                             f"string, got {folder!r}")
        folder_path = Path(folder.strip()).expanduser()
        out[name] = folder_path if folder_path.is_absolute() else path.parent / folder_path
    return out


def default_root(manifest: AssetManifest) -> Path:
    """The asset's folder when nothing else says where it is."""
    if manifest.generated:
        return cache_dir() / "data" / f"still_{manifest.profile}"
    return cache_dir() / "assets" / manifest.name


def locate(name: str | AssetManifest, root: str | Path | None = None,
           manifests: str | Path | None = None) -> AssetLocation:
    """Where the asset ``name`` lives (see the module docstring for the order)."""
    manifest = load_asset_manifest(name, manifests)
    if root is not None:
        return AssetLocation(manifest.name, Path(root).expanduser(), "argument", "--root")
    if manifest.env_var and os.environ.get(manifest.env_var):
        return AssetLocation(manifest.name, Path(os.environ[manifest.env_var]).expanduser(), "env",
                             f"${manifest.env_var}")
    config = read_config()
    if manifest.name in config:
        return AssetLocation(manifest.name, config[manifest.name], "config", str(config_path()))
    return AssetLocation(manifest.name, default_root(manifest), "default", "the kit cache default")
