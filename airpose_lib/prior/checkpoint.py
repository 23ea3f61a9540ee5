"""Saving and loading pose priors: the kit's own checkpoints and the official VPoser V02_05.

Kit priors (trained by :func:`airpose_lib.prior.train_prior`, ``airpose prior train``) live in
``<cache>/prior/<tag>/vposer.pt`` (``<cache>`` = :func:`airpose_lib.paths.cache_dir`; the tag
is the profile that trained it: ``smoke``, ``cpu`` or ``paper``). The file is a plain
``torch.save`` dict::

    {"format": "airpose-kit-vposer", "format_version": 1, "architecture": {...},
     "state_dict": {...}, "provenance": {...}}

written atomically, so a crash never leaves half a checkpoint.

The official prior is the licensed VPoser V02_05 release (https://smpl-x.is.tue.mpg.de, "VPoser
v2.0"). Unzip it into the folder named by ``$AIRPOSE_VPOSER_DIR`` so that
``$AIRPOSE_VPOSER_DIR/V02_05/snapshots/*.ckpt`` exists. That file is a PyTorch-Lightning
checkpoint whose ``state_dict`` holds the VAE's tensors under the prefix ``vp_model.``; the kit
reads only those.
"""
from __future__ import annotations

import os
import pickle
import re
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import torch

from airpose_lib import __version__  # the package root holds only the version
from airpose_lib.atomic import atomic_torch_save
from airpose_lib.body.loader import _located
from airpose_lib.errors import ConfigError, UserError, reading
from airpose_lib.paths import cache_dir
from airpose_lib.safe_pickle import torch_pickle_module

from .vposer import LATENT_DIM, NUM_NEURONS, VPoser

__all__ = [
    "PriorError",
    "VPOSER_ENV",
    "VPOSER_URL",
    "KIT_FORMAT",
    "KIT_TAGS",
    "kit_prior_path",
    "save_prior",
    "load_prior",
    "find_vposer_checkpoint",
    "vposer_state_dict",
]

VPOSER_ENV = "AIRPOSE_VPOSER_DIR"
VPOSER_URL = "https://smpl-x.is.tue.mpg.de"
KIT_FORMAT = "airpose-kit-vposer"
KIT_FORMAT_VERSION = 1
KIT_TAGS = ("paper", "cpu", "smoke")
"""Kit prior tags, best first: ``load_prior("kit")`` takes the first one that exists."""
_OFFICIAL_PREFIX = "vp_model."


class PriorError(UserError, FileNotFoundError):
    """A prior checkpoint is missing or unusable; the message says what to do."""


# -- kit checkpoints ------------------------------------------------------------------------------
def kit_prior_path(tag: str = "cpu") -> Path:
    """``<cache>/prior/<tag>/vposer.pt`` (not created)."""
    if not tag or "/" in tag or tag.startswith("."):
        raise ConfigError(f"invalid prior tag {tag!r}")
    return cache_dir() / "prior" / tag / "vposer.pt"


def save_prior(model: VPoser, path: str | Path, provenance: Mapping[str, Any] | None = None) -> Path:
    """Write ``model`` as a kit checkpoint at ``path``, atomically.

    Args:
        model: the prior.
        path: target file.
        provenance: JSON-like facts about how it was made (kit version, seed, corpus, metrics).
    Returns:
        ``path``.
    """
    path = Path(path)
    blob = {
        "format": KIT_FORMAT,
        "format_version": KIT_FORMAT_VERSION,
        "architecture": {"num_neurons": model.num_neurons, "latent_dim": model.latent_dim},
        "state_dict": {k: v.detach().cpu().clone() for k, v in model.state_dict().items()},
        "provenance": {"kit_version": __version__, "torch": str(torch.__version__), **dict(provenance or {})},
    }
    return atomic_torch_save(blob, path)


def _load_kit(path: Path) -> tuple[VPoser, dict]:
    with reading(path, "a prior checkpoint of `airpose prior train`", "train it again with `airpose prior train`"):
        blob = torch.load(path, map_location="cpu", weights_only=True)
    if not isinstance(blob, dict) or blob.get("format") != KIT_FORMAT:
        raise PriorError(f"{path} is not a kit prior checkpoint (format {blob.get('format')!r}); "
                         "for the official VPoser use load_prior(source='vposer')")
    arch = blob.get("architecture", {})
    model = VPoser(arch.get("num_neurons", NUM_NEURONS), arch.get("latent_dim", LATENT_DIM))
    model.load_state_dict(blob["state_dict"])
    return model, dict(blob.get("provenance", {}))


# -- official VPoser V02_05 -----------------------------------------------------------------------
def _vposer_missing(where: str) -> PriorError:
    return PriorError(
        f"no VPoser V02_05 checkpoint found ({where}). Download 'VPoser v2.0' (V02_05) from "
        f"{VPOSER_URL} (registration required), unzip it and set {VPOSER_ENV} to the folder that "
        f"contains V02_05/, so that ${VPOSER_ENV}/V02_05/snapshots/*.ckpt exists. Without it use "
        "the kit's own prior: load_prior('kit') after `airpose prior train`.")


def _epoch(p: Path) -> int:
    m = re.search(r"epoch=(\d+)", p.name)
    return int(m.group(1)) if m else -1


def find_vposer_checkpoint(root: str | Path | None = None) -> Path:
    """Locate the official snapshot.

    Args:
        root: a ``.ckpt`` file, the ``V02_05`` folder, or a folder containing ``V02_05/``;
            None reads ``$AIRPOSE_VPOSER_DIR``.
    Returns:
        the ``.ckpt`` path; with several snapshots, the highest ``epoch=NN`` (then the last name).
    Raises:
        PriorError: nothing found (the message says where the file goes).
    """
    if root is None:
        env = os.environ.get(VPOSER_ENV)
        if not env:
            env = _located("vposer_v02_05")  # the asset config file or the kit cache default
        if not env:
            raise _vposer_missing(f"${VPOSER_ENV} is not set")
        root = env
    root = Path(root).expanduser()
    if root.is_file():
        return root
    candidates: list[Path] = []
    for folder in (root / "V02_05" / "snapshots", root / "snapshots"):
        if folder.is_dir():
            candidates += sorted(folder.glob("*.ckpt"))
    if not candidates:
        raise _vposer_missing(f"looked for {root}/V02_05/snapshots/*.ckpt")
    return max(candidates, key=lambda p: (_epoch(p), p.name))


def vposer_state_dict(ckpt: str | Path) -> dict[str, torch.Tensor]:
    """The VAE's tensors from an official Lightning checkpoint, prefix ``vp_model.`` removed.

    The release pickles non-tensor hyper-parameters next to the weights; if the
    ``weights_only`` unpickler refuses them, the file is read again with the kit's checkpoint
    unpickler (:func:`airpose_lib.safe_pickle.torch_pickle_module`): tensors and containers are
    built, every other object becomes an inert placeholder, and no code of the file runs.
    """
    ckpt = Path(ckpt)
    with reading(ckpt, "a VPoser V02_05 checkpoint", "download VPoser v2.0 again (data_manifests/vposer_v02_05.yaml)"):
        try:
            blob = torch.load(ckpt, map_location="cpu", weights_only=True)
        except pickle.UnpicklingError:
            blob = torch.load(ckpt, map_location="cpu", weights_only=False, pickle_module=torch_pickle_module())
    state = blob.get("state_dict", blob) if isinstance(blob, Mapping) else None
    if not isinstance(state, Mapping):
        raise PriorError(f"{ckpt}: no state_dict in this checkpoint")
    out = {k[len(_OFFICIAL_PREFIX):]: v for k, v in state.items() if k.startswith(_OFFICIAL_PREFIX)}
    if not out:
        raise PriorError(f"{ckpt}: no '{_OFFICIAL_PREFIX}*' tensors; is this a VPoser V02_05 snapshot?")
    return out


def _load_vposer(path: str | Path | None) -> tuple[VPoser, dict]:
    ckpt = find_vposer_checkpoint(path)
    state = vposer_state_dict(ckpt)
    latent = state["decoder_net.0.weight"].shape[1] if "decoder_net.0.weight" in state else LATENT_DIM
    width = state["encoder_net.2.weight"].shape[0] if "encoder_net.2.weight" in state else NUM_NEURONS
    model = VPoser(width, latent)
    missing, unexpected = model.load_state_dict(state, strict=False)
    if missing or unexpected:
        raise PriorError(f"{ckpt}: does not match the VPoser V02_05 layout "
                         f"(missing {sorted(missing)}, unexpected {sorted(unexpected)})")
    return model, {"source": "vposer", "file": str(ckpt)}


# -- entry point ----------------------------------------------------------------------------------
def load_prior(source: str = "kit", path: str | Path | None = None, *, tag: str | None = None,
               return_provenance: bool = False):
    """Load a pose prior, ready for inference (eval mode, gradients off for its weights).

    Args:
        source: ``"kit"`` (trained by the kit) or ``"vposer"`` (the official V02_05 weights).
        path: kit: a checkpoint file (default :func:`kit_prior_path` of ``tag``); vposer: a
            ``.ckpt`` or a folder (default ``$AIRPOSE_VPOSER_DIR``).
        tag: kit only: which cached prior (default: the first of :data:`KIT_TAGS` that exists).
        return_provenance: also return the provenance dict.
    Returns:
        the :class:`VPoser` (and its provenance).
    Raises:
        PriorError: no checkpoint (the message names the expected file and how to get it).
    """
    if source == "kit":
        if path is None:
            tags = (tag,) if tag else KIT_TAGS
            found = [kit_prior_path(t) for t in tags if kit_prior_path(t).is_file()]
            if not found:
                raise PriorError(
                    f"no kit pose prior in {cache_dir() / 'prior'} (looked for tag(s) {list(tags)}); "
                    "train one with `airpose prior train --profile cpu` (a few minutes on a CPU) "
                    "or use load_prior('vposer') with the official weights")
            path = found[0]
        path = Path(path)
        if not path.is_file():
            raise PriorError(f"kit prior checkpoint {path} does not exist")
        model, prov = _load_kit(path)
        prov = {"source": "kit", "file": str(path), **prov}
    elif source == "vposer":
        model, prov = _load_vposer(path)
    else:
        raise ValueError(f"unknown prior source {source!r}; choose 'kit' or 'vposer'")
    model.eval()
    model.requires_grad_(False)
    return (model, prov) if return_provenance else model
