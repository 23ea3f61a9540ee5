"""A drone's ONNX graphs as a cached artefact: exported, optionally int8-quantised, keyed by what
made them.

:func:`ensure_export` is what ``airpose export`` and the ``onnx`` / ``onnx-int8`` backends call:
the network (a checkpoint's bytes, or the seed of random weights), the crop size, the calibration
crops (the kit's own still frames, :func:`calibration_crops`) and the quantisation settings are
hashed into a key, and the folder ``<cache>/onnx/<name>-<key>/`` is built once (under a file
lock, so N drones started together build it once) and reused after::

    folder = ensure_export(BackendSpec(kind="onnx-int8", checkpoint="last.pt"))
    node = OnnxDroneNode(folder, precision="int8")

The calibration crops are read from a still-frame dataset's train split (evenly spaced samples,
every view): by default the dataset the checkpoint was trained on, else the smoke profile's.
"""
from __future__ import annotations

import hashlib
import json
import shutil
from pathlib import Path

import numpy as np
import torch

from airpose_lib.data.still.dataset import StillFrameDataset
from airpose_lib.folder_lock import file_lock
from airpose_lib.hashing import sha256_file
from airpose_lib.model.onnx_export import OPSET, export_onnx
from airpose_lib.model.quantize import QuantSettings, calibration_digest, quantize_stage1
from airpose_lib.paths import RunFolders, cache_dir

from .backends import ONNX_PRECISIONS, BackendSpec, build_torch_model, checkpoint_settings

__all__ = ["calibration_crops", "default_calibration_root", "export_key", "ensure_export"]


def default_calibration_root(checkpoint: str | Path | None = None) -> Path:
    """The still-frame dataset a checkpoint was trained on (its ``config.data.root``), else the
    smoke profile's default dataset folder (which may not exist yet)."""
    if checkpoint:
        state = torch.load(checkpoint, map_location="cpu", weights_only=True)
        root = ((state.get("config") or {}).get("data") or {}).get("root") if isinstance(state, dict) else None
        if root:
            return Path(root)
    return RunFolders("smoke").still


def calibration_crops(root: str | Path, input_size: int, samples: int = 32, split: str = "train"
                      ) -> tuple[np.ndarray, np.ndarray]:
    """Crops of a still-frame dataset for calibration.

    Args:
        root: dataset folder (``airpose data generate``).
        input_size: S of the graph; crops of another size are resized (bilinear, antialiased)
            and their ``s = S / side`` rescaled.
        samples: evenly spaced samples of the split (every view of each).

    Returns:
        ``images (samples * V, 3, S, S)`` float32 (normalised as the network's input), ``P (samples * V, 3)``.
    """
    ds = StillFrameDataset(root, split, augment=False)
    idx = np.unique(np.linspace(0, len(ds) - 1, min(samples, len(ds))).round().astype(int))
    items = [ds[int(i)] for i in idx]
    images = torch.cat([it["images"] for it in items])
    P = torch.cat([it["P"] for it in items]).clone()
    if images.shape[-1] != input_size:
        P[:, 2] *= input_size / images.shape[-1]
        images = torch.nn.functional.interpolate(images, size=(input_size, input_size), mode="bilinear",
                                                 antialias=True, align_corners=False)
    return images.numpy().astype(np.float32), P.numpy().astype(np.float32)


def _network_identity(spec: BackendSpec) -> dict:
    """What fixes the weights: the checkpoint's bytes, or the random initialisation."""
    if spec.checkpoint:
        return {"checkpoint_sha256": sha256_file(spec.checkpoint), **checkpoint_settings(spec.checkpoint)}
    return {"random": {"variant": spec.variant, "backbone": spec.backbone, "seed": spec.seed},
            "torch": torch.__version__}


def export_key(identity: dict, input_size: int, precision: str, calibration: str | None = None,
               settings: QuantSettings | None = None) -> str:
    """Hex key of an export folder: SHA-256 of everything that went into it (16 hex digits)."""
    import onnxruntime

    made_of = {"network": identity, "input_size": int(input_size), "opset": OPSET, "precision": precision,
               "exporter_torch": torch.__version__}
    if precision != "fp32":
        made_of.update(calibration_sha256=calibration, settings=settings.to_dict() if settings else None,
                       onnxruntime=onnxruntime.__version__)
    return hashlib.sha256(json.dumps(made_of, sort_keys=True, default=str).encode()).hexdigest()[:16]


def ensure_export(spec: BackendSpec, precision: str | None = None, calibration_root: str | Path | None = None,
                  calibration_samples: int = 32, settings: QuantSettings = QuantSettings(),
                  root: str | Path | None = None, force: bool = False, progress: bool = False) -> Path:
    """The export folder of ``spec``'s network (built if missing), with an int8 stage 1 if asked.

    Args:
        spec: network and crop size (``checkpoint``, or ``variant`` / ``backbone`` / ``seed``;
            a checkpoint's own settings and crop size win).
        precision: ``"fp32"`` or ``"int8"``; default from ``spec.kind`` (:data:`~.backends.ONNX_PRECISIONS`).
        calibration_root: still-frame dataset of the calibration crops (int8); default
            :func:`default_calibration_root`.
        calibration_samples: samples of its train split (all views of each).
        settings: quantisation settings (int8).
        root: parent folder (default ``<cache>/onnx``).
        force: rebuild even if the folder is complete.

    Returns:
        the folder (``stage1.onnx``, ``stage_next.onnx``, ``meta.json``, and ``stage1_int8.onnx``).

    Raises:
        FileNotFoundError: no checkpoint, or no calibration dataset (with the command that makes one).
    """
    precision = precision or ONNX_PRECISIONS.get(spec.kind, "fp32")
    if precision not in ("fp32", "int8"):
        raise ValueError(f"precision must be fp32 or int8, got {precision!r}")
    if spec.checkpoint and not Path(spec.checkpoint).is_file():
        raise FileNotFoundError(f"no checkpoint at {spec.checkpoint}")
    settings_ckpt = checkpoint_settings(spec.checkpoint) if spec.checkpoint else {}
    size = int(settings_ckpt.get("input_size", spec.input_size))
    identity = _network_identity(spec)
    images = P = None
    digest = None
    calib_info: dict = {}
    if precision == "int8":
        calib = Path(calibration_root) if calibration_root else default_calibration_root(spec.checkpoint)
        if not (calib / "manifest.yaml").exists():
            raise FileNotFoundError(
                f"no still-frame dataset at {calib} for the int8 calibration: run `airpose data generate "
                f"--profile smoke` or pass a dataset folder (--calibration DIR)")
        images, P = calibration_crops(calib, size, calibration_samples)
        digest = calibration_digest(images, P)
        calib_info = {"dataset": str(calib), "split": "train", "samples": int(calibration_samples)}
    key = export_key(identity, size, precision, digest, settings)
    name = "{}_{}_{}_{}".format(settings_ckpt.get("variant", spec.variant), settings_ckpt.get("backbone", spec.backbone),
                                size, precision)
    folder = Path(root) if root is not None else cache_dir() / "onnx"
    folder = folder / f"{name}-{key}"
    done = folder / "complete.json"
    with file_lock(folder.with_name(folder.name + ".lock")):
        if done.exists() and not force:
            return folder
        if folder.exists():
            shutil.rmtree(folder)
        tmp = folder.with_name(folder.name + ".partial")
        if tmp.exists():
            shutil.rmtree(tmp)
        if progress:
            print(f"exporting {name} to {folder}", flush=True)
        export_onnx(build_torch_model(spec), tmp, input_size=size)
        if precision == "int8":
            if progress:
                print(f"calibrating int8 stage 1 on {len(images)} crops of {calib_info['dataset']}", flush=True)
            quantize_stage1(tmp, images, P, settings, provenance={"dataset": calib_info})
        (tmp / "complete.json").write_text(json.dumps(
            {"key": key, "network": identity, "input_size": size, "precision": precision,
             "calibration": {**calib_info, "sha256": digest} if digest else None,
             "settings": settings.to_dict() if precision == "int8" else None}, indent=1, default=str))
        tmp.rename(folder)
    return folder
