"""The shipped networks of a profile: the model zoo in ``results/<profile>/networks/``.

A profile's trained networks (the four variants' regressors of one seed, the recordings'
fine-tuned Baseline and AirPose, the kit's pose prior) are committed beside its backbone so that
the notebooks show every paper artefact without training (profile section ``networks: shipped``).
Each file is listed in ``manifest.yaml`` with its SHA-256, size, metric and the commit and
command that made it; :func:`verified` refuses a damaged or foreign file in one line.

A regressor file holds only what the variant adds to the shared backbone (``fc1``, ``fc2``, the
decoders, the initial estimates), in float16, with its network record
(:mod:`airpose_lib.model.record`); :func:`kit_checkpoint` joins it with the backbone file into an
ordinary kit checkpoint in the cache, which every loader of the kit reads
(``train.evaluate.load_network``, fine-tuning's predictions, the drones).
"""
from __future__ import annotations

import hashlib
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import torch
import yaml

from airpose_lib.atomic import atomic_path, atomic_torch_save
from airpose_lib.engine.checkpoint import load_checkpoint, write_checkpoint
from airpose_lib.errors import DamagedFileError, reading
from airpose_lib.hashing import sha256_file
from airpose_lib.paths import RunFolders, cache_dir, portable, repo_root

__all__ = ["MANIFEST", "FORMAT", "zoo_dir", "sha256_file", "read_manifest", "write_manifest", "verified",
           "regressor_blob", "export_regressor", "kit_checkpoint", "half_state", "zoo_table"]

MANIFEST = "manifest.yaml"
FORMAT = "airpose-kit-shipped-regressor"
FORMAT_VERSION = 1
#: Prefix of the shared backbone's entries in a variant's ``state_dict``.
BACKBONE_PREFIX = "backbone."
#: Checkpoint entries a shipped file keeps besides the weights (plain values only).
_KEPT = ("network", "config", "step", "input_size", "camera_K", "finetune", "kit_version")


def zoo_dir(folders: RunFolders) -> Path:
    """``<checkout>/results/<profile>/networks`` (the shipped networks of the profile ``folders``
    name)."""
    root = repo_root()
    if root is None:
        raise DamagedFileError("results/", "the kit's checkout", "the shipped networks live in a checkout of the "
                               "kit; clone it instead of installing a copy")
    return folders.results / "networks"


def read_manifest(folder: str | Path) -> dict[str, dict]:
    """``name -> entry`` of ``<folder>/manifest.yaml`` (entries: ``file`` relative to the folder,
    ``sha256``, ``bytes``, ``kind``, ...)."""
    path = Path(folder) / MANIFEST
    with reading(path, "the shipped networks' manifest", "restore it with `git checkout -- " + str(path) + "`"):
        data = yaml.safe_load(path.read_text())
        entries = {e["name"]: dict(e) for e in data["networks"]}
    return entries


def write_manifest(folder: str | Path, entries: list[Mapping], about: Mapping[str, Any]) -> Path:
    """Write ``manifest.yaml`` (``about``: what the set is and the command that rebuilds it), any
    path in it :func:`~airpose_lib.paths.portable` (it is committed; its files are named relative
    to the folder)."""
    path = Path(folder) / MANIFEST
    manifest = portable({**dict(about), "networks": [dict(e) for e in entries]})
    with atomic_path(path) as tmp:
        Path(tmp).write_text(yaml.safe_dump(manifest, sort_keys=False, width=110))
    return path


def verified(folder: str | Path, name: str) -> Path:
    """The file of entry ``name``, after checking its size and SHA-256 against the manifest.

    Raises:
        DamagedFileError: missing from the manifest, or a file whose bytes differ (damaged, a Git
            LFS pointer, another build's file): one line naming the file and the fix.
    """
    folder = Path(folder)
    entries = read_manifest(folder)
    if name not in entries:
        raise DamagedFileError(folder / MANIFEST, f"a manifest listing {name!r}",
                               f"it lists {sorted(entries)}; restore it with git checkout")
    entry = entries[name]
    path = folder / entry["file"]
    if not path.is_file():
        raise DamagedFileError(path, f"the shipped network {name!r}", "restore it with `git checkout -- "
                               f"{path}` or rebuild the set with `{entry.get('rebuild', 'airpose zoo build')}`")
    size, digest = path.stat().st_size, sha256_file(path)
    if size != int(entry["bytes"]) or digest != entry["sha256"]:
        raise DamagedFileError(path, f"the shipped network {name!r} ({entry['bytes']} bytes, SHA-256 "
                               f"{entry['sha256'][:12]}...)", f"it has {size} bytes, SHA-256 {digest[:12]}...: "
                               f"restore it with `git checkout -- {path}` or rebuild the set with "
                               f"`{entry.get('rebuild', 'airpose zoo build')}`")
    return path


def half_state(state: Mapping[str, torch.Tensor]) -> dict[str, torch.Tensor]:
    """Floating tensors as float16 (others as they are), the shipped precision."""
    return {k: (v.detach().cpu().half() if v.is_floating_point() else v.detach().cpu()) for k, v in state.items()}


def regressor_blob(state: Mapping[str, Any], backbone_sha256: str) -> dict[str, Any]:
    """What a shipped regressor file holds, from a kit checkpoint's loaded ``state``: the weights
    that are not the backbone's in float16, the entries of :data:`_KEPT`, and the SHA-256 of the
    backbone file it reads the features of. ``config``'s machine paths are dropped, and every
    other path (a fine-tuned network's prior, recording and base network in ``finetune``) is
    named :func:`~airpose_lib.paths.portable`: the file is committed, and no loader opens them."""
    model = state["model"]
    head = {k: v for k, v in model.items() if not k.startswith(BACKBONE_PREFIX)}
    kept = {k: state[k] for k in _KEPT if k in state}
    if "config" in kept:
        cfg = dict(kept["config"])
        cfg["data"] = {k: v for k, v in (cfg.get("data") or {}).items() if k != "root"}
        cfg["pretrained"] = "shipped"
        kept["config"] = cfg
    kept = portable(kept)
    return {"format": FORMAT, "format_version": FORMAT_VERSION, "backbone_sha256": backbone_sha256,
            "regressor": half_state(head), **kept}


def export_regressor(checkpoint: str | Path, backbone_file: str | Path, dst: str | Path) -> Path:
    """Write the shipped file of a kit checkpoint whose backbone is ``backbone_file``'s.

    Raises:
        ValueError: the checkpoint's backbone differs from the file's (beyond float16 rounding):
            it trained its backbone, which a regressor file cannot carry.
    """
    state = load_checkpoint(checkpoint)
    backbone = _backbone_state(backbone_file)
    for k, v in backbone.items():
        mine = state["model"][BACKBONE_PREFIX + k].float()
        if not torch.allclose(mine, v.float(), rtol=2e-3, atol=1e-4):
            raise ValueError(f"{checkpoint}: its backbone entry {k} differs from {backbone_file}'s; only a "
                             "network on the frozen shared backbone can be shipped as a regressor file")
    return atomic_torch_save(regressor_blob(state, sha256_file(backbone_file)), Path(dst))


def _backbone_state(backbone_file: str | Path) -> dict[str, torch.Tensor]:
    with reading(backbone_file, "a pretrained backbone file", "restore it with git checkout"):
        blob = torch.load(Path(backbone_file), map_location="cpu", weights_only=True)
        return dict(blob["state_dict"])


def kit_checkpoint(regressor_file: str | Path, backbone_file: str | Path) -> Path:
    """An ordinary kit checkpoint of a shipped regressor on its backbone, made once in
    ``<cache>/zoo/`` (named by both files' SHA-256) and read by every loader of the kit.

    Raises:
        DamagedFileError: not a shipped regressor file, or one made on another backbone.
    """
    regressor_file, backbone_file = Path(regressor_file), Path(backbone_file)
    what = "a shipped regressor file of `airpose zoo build`"
    with reading(regressor_file, what, "restore it with git checkout"):
        blob = torch.load(regressor_file, map_location="cpu", weights_only=True)
        if blob.get("format") != FORMAT or blob.get("format_version") != FORMAT_VERSION:
            raise KeyError("format")
    backbone_sha = sha256_file(backbone_file)
    if blob["backbone_sha256"] != backbone_sha:
        raise DamagedFileError(regressor_file, f"a regressor on the backbone {backbone_file}",
                               f"it was made on the backbone of SHA-256 {blob['backbone_sha256'][:12]}...; "
                               "ship both from one `airpose zoo build`")
    key = hashlib.sha256((sha256_file(regressor_file) + backbone_sha).encode()).hexdigest()[:16]
    out = cache_dir() / "zoo" / f"{regressor_file.stem}-{key}.pt"
    if out.is_file():
        return out
    model = {BACKBONE_PREFIX + k: v.float() if v.is_floating_point() else v
             for k, v in _backbone_state(backbone_file).items()}
    model.update({k: v.float() if v.is_floating_point() else v for k, v in blob["regressor"].items()})
    state = {k: blob[k] for k in _KEPT if k in blob and k != "kit_version"}
    out.parent.mkdir(parents=True, exist_ok=True)
    write_checkpoint(out, {"model": model, **state, "shipped": {"file": regressor_file.name,
                                                                "backbone_sha256": backbone_sha}})
    return out


def zoo_table(folder: str | Path) -> str:
    """The manifest as a Markdown table (the model-zoo page's rows)."""
    entries = read_manifest(folder)
    lines = ["| file | kind | variant | metric | MB | SHA-256 | made by |", "|---|---|---|---|---|---|---|"]
    for e in entries.values():
        metric = ", ".join(f"{k} {v}" for k, v in (e.get("metric") or {}).items())
        lines.append(f"| `{e['file']}` | {e['kind']} | {e.get('variant', '-')} | {metric} | "
                     f"{int(e['bytes']) / 1e6:.2f} | `{e['sha256'][:16]}` | {e.get('made_by', '-')} |")
    return "\n".join(lines)
