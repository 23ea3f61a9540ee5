r"""Run a network over a recording: detections -> boxes -> crops -> per-view SMPL-X parameters.

:func:`predict_sequence` builds every view's crop exactly as a drone does
(:mod:`airpose_lib.data.network_input`: ``person_box`` on the detections, the previous-box
rule ``hold_boxes``, then ``crop_input``), runs the backbone on all
views of a batch of frames and the regressor on all views jointly (so the multi-view variants
exchange their messages, as :meth:`AirPoseNet.forward`), and returns camera-frame parameters per
view (:func:`airpose_lib.model.to_smplx_params`).

Any camera: the crops and P are formed in the network's virtual camera ``K_net`` (the camera it
was trained with, ``model.camera_K`` from :func:`~airpose_lib.finetune.network.load_sized_network`,
else ``data.network_input.network_camera()``: f = 1475 px at 1920x1080), see
``geometry.virtual_crop``. The network's translation is then already in the real camera's frame;
a weak camera is converted with ``K_net`` (the camera its P refers to). The provenance records
the rule (``camera_rule``, ``K_net``).

Frames without a usable detection in a view (fewer than 4 keypoints above the box confidence)
reuse that view's previous box, as a drone does; leading frames take the first box the view
has (``hold_boxes(leading="first")``). Their outputs are computed from that stale crop and flagged ``valid[f, v] = False``; a view
without any detection in the selection is an error.

The predictions file (:func:`save_predictions`, :func:`load_predictions`) is an ``.npz``:

==============  =====================  ===========================================================
key             shape                  meaning
==============  =====================  ===========================================================
``phi``         (F, V, 3, 3) float32   root rotation, body -> camera v
``tau``         (F, V, 3) float32      translation of the model origin, camera v, metres
``theta``       (F, V, 21, 3, 3)       body joint rotations predicted by view v
``beta``        (F, V, 10) float32     shape predicted by view v
``frames``      (F,) int64             image numbers of the recording (strictly increasing)
``P``           (F, V, 3) float32      crop vectors ``[bx, by, s]`` in the virtual camera ``K_net``
``boxes``       (F, V, 4) float32      person boxes ``[x0, y0, x1, y1]``, full-image pixels
``valid``       (F, V) bool            the box came from this frame's detections
``provenance``  () str                 JSON: kit version, sequence, detector, input size, ...
==============  =====================  ===========================================================

It is what ``airpose fit --init`` and :func:`airpose_lib.fitting.init_from_views` read (the first
five keys). Parameters follow the paper's convention ``X_cam = phi X0(theta, beta) + tau``.
"""
from __future__ import annotations

import json
from collections.abc import Mapping
from collections.abc import Sequence as SequenceABC
from pathlib import Path

import numpy as np
import torch
from torch import Tensor, nn

from airpose_lib import __version__  # the package root holds only the version
from airpose_lib.atomic import atomic_path
from airpose_lib.data.network_input import box_margin, crop_input, hold_boxes, network_camera, person_box
from airpose_lib.data.sequences.layout import SequenceFormatError
from airpose_lib.data.sequences.reader import load_sequence
from airpose_lib.errors import ConfigError, UserError
from airpose_lib.model import to_smplx_params
from airpose_lib.progress import progress_bar

__all__ = [
    "PREDICTION_KEYS",
    "REQUIRED_PREDICTION_KEYS",
    "PredictionFormatError",
    "regress_features",
    "detection_boxes",
    "frames_in_range",
    "network_camera_of",
    "camera_rule",
    "image_sizes",
    "sequence_features",
    "adapt_batchnorm",
    "predict_sequence",
    "validate_predictions",
    "save_predictions",
    "load_predictions",
]

REQUIRED_PREDICTION_KEYS = ("phi", "tau", "theta", "beta", "frames")
PREDICTION_KEYS = REQUIRED_PREDICTION_KEYS + ("P", "boxes", "valid", "provenance")


class PredictionFormatError(UserError, ValueError):
    """A predictions file or dict does not follow the contract; the message names the file."""


# -- the network after the backbone ---------------------------------------------------------------
def regress_features(model: nn.Module, feat: Tensor, P: Tensor | None = None,
                     input_size: int | None = None, cut: str | None = None) -> dict:
    """The regressor part of :meth:`AirPoseNet.forward` on given backbone features.

    All views of a sample iterate together; the multi-view variants fuse the other views'
    messages after each iteration exactly as the batched forward does (the same calls in the
    same order, so eval-mode outputs equal ``model(images, P)``).

    Args:
        model: an :class:`~airpose_lib.model.AirPoseNet`.
        feat: ``(B, V, C)`` backbone features (:meth:`AirPoseNet.features`), or with ``cut``
            ``(B, V, C, h, w)`` the input of backbone block ``cut`` (:func:`sequence_features`
            with that cut), run through that block and the rest of the backbone first.
        P: ``(B, V, 3)`` crop vectors (needed by Fullcam and AirPose).
        input_size: crop side S (stored as ``out["input_size"]`` for ``to_smplx_params``).
        cut: a backbone block name (``FineTuneConfig.trainable_from``) or None.

    Returns:
        the dict of :meth:`AirPoseNet.forward`: phi6d (B, V, 6), theta6d (B, V, 21, 6),
        beta (B, V, 10), tau (B, V, 3) or cam (B, V, 3), messages, and input_size if given.
    """
    if cut is not None:
        if feat.dim() != 5:
            raise ValueError(f"features of block {cut!r}'s input must be (B, V, C, h, w), got {tuple(feat.shape)}")
        feat = model.features_from(feat, cut)
    if feat.dim() != 3:
        raise ValueError(f"features must be (B, V, C), got {tuple(feat.shape)}")
    out = model.regress(feat, P)
    if input_size is not None:
        out["input_size"] = int(input_size)
    return out


# -- detections -> boxes ----------------------------------------------------------------------------
def detection_boxes(keypoints: np.ndarray, image_sizes: SequenceABC[tuple[int, int]], *,
                    min_confidence: float = 0.2, margin_px: float | SequenceABC[float] = 20.0,
                    where: str = "the sequence") -> tuple[np.ndarray, np.ndarray]:
    """Person boxes of every frame and view from one detector's keypoints.

    Args:
        keypoints: ``(F, V, J, 3)`` ``[x, y, confidence]`` full-image pixels.
        image_sizes: ``(W, H)`` of each of the V views.
        min_confidence, margin_px: as :func:`airpose_lib.data.network_input.person_box` (the
            margin may be given per view, e.g. ``data.network_input.network_box_margin``).
        where: named in the error message (e.g. the sequence folder).

    Returns:
        ``boxes (F, V, 4)`` float64 ``[x0, y0, x1, y1]`` and ``valid (F, V)`` bool (False: no
        detection, the box is the view's previous one, or for leading frames its first one).

    Raises:
        ValueError: a view has no usable detection in any frame.
    """
    kp = np.asarray(keypoints, np.float64)
    if kp.ndim != 4 or kp.shape[-1] != 3:
        raise ValueError(f"keypoints must be (F, V, J, 3), got {kp.shape}")
    F, V = kp.shape[:2]
    if len(image_sizes) != V:
        raise ValueError(f"{len(image_sizes)} image sizes for {V} views")
    margins = np.broadcast_to(np.asarray(margin_px, np.float64), (V,))
    boxes = np.zeros((F, V, 4))
    valid = np.zeros((F, V), bool)
    for v in range(V):
        detected = [person_box(kp[f, v], image_sizes[v], min_confidence, float(margins[v])) for f in range(F)]
        boxes[:, v], valid[:, v] = hold_boxes(detected, leading="first")
        if not valid[:, v].any():
            raise SequenceFormatError(f"{where}: view {v} has no frame with at least 4 keypoints of confidence >= "
                                      f"{min_confidence}; check the detector files or lower the box confidence")
    return boxes, valid


def _crops(sequence, rows: np.ndarray, boxes: np.ndarray, input_size: int,
           K_net: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Network inputs of ``rows (B,)`` of a loaded sequence with ``boxes (B, V, 4)``
    (``data.network_input.crop_input`` per view): ``crops (B, V, 3, S, S)``, ``P (B, V, 3)`` float32."""
    B, V = len(rows), sequence.num_views
    crops = np.zeros((B, V, 3, input_size, input_size), np.float32)
    P = np.zeros((B, V, 3), np.float32)
    for v in range(V):
        K = np.asarray(sequence.K[v], np.float64)
        for b, row in enumerate(rows):
            c, p = crop_input(sequence.image(int(row), v), boxes[b, v], K, input_size, K_net)
            crops[b, v], P[b, v] = c[0], p[0]
    return crops, P


def frames_in_range(root: str | Path, start: int | None, stop: int | None) -> np.ndarray:
    """Image numbers ``start <= n < stop`` present in every view of the recording at ``root``
    (None: open end), for ``load_sequence(root, frames=...)``. Raises ``ConfigError`` if none."""
    numbers = np.asarray(load_sequence(root, detectors=(), ground_truth=False).frames)  # image numbers only
    lo = numbers[0] if start is None else start
    hi = numbers[-1] + 1 if stop is None else stop
    sel = numbers[(numbers >= lo) & (numbers < hi)]
    if sel.size == 0:
        raise ConfigError(f"{root}: no image numbered in [{lo}, {hi}) (the recording has {numbers[0]}..{numbers[-1]})")
    return sel


def _positions(sequence, frames) -> np.ndarray:
    """Positions in ``sequence.frames`` of the requested image numbers (None: all)."""
    numbers = np.asarray(sequence.frames)
    if frames is None:
        return np.arange(len(numbers))
    want = np.asarray(list(frames), np.int64).reshape(-1)
    pos = {int(n): i for i, n in enumerate(numbers)}
    missing = [int(n) for n in want if int(n) not in pos]
    if missing:
        raise ValueError(f"{sequence.root}: frames {missing[:5]} are not in the loaded sequence "
                         f"(it has {len(numbers)} frames, {numbers[0]}..{numbers[-1]})")
    out = np.array([pos[int(n)] for n in want], np.int64)
    if len(out) == 0:
        raise ValueError(f"{sequence.root}: empty frame selection")
    if np.any(np.diff(numbers[out]) <= 0):
        raise ValueError("frames must be strictly increasing image numbers")
    return out


def network_camera_of(model: nn.Module, K_net=None) -> np.ndarray:
    """``(3, 3)`` virtual camera of a network: ``K_net`` if given, else ``model.camera_K`` (set by
    ``load_sized_network``), else ``data.network_input.network_camera()``."""
    if K_net is None:
        K_net = getattr(model, "camera_K", None)
    return np.asarray(network_camera() if K_net is None else K_net, np.float64).reshape(3, 3)


def camera_rule(K_net: np.ndarray, K: np.ndarray) -> dict:
    """What predictions record about the camera rule (JSON-able)."""
    K = np.asarray(K, np.float64)
    return {"camera_rule": "virtual camera K_net (geometry.virtual_crop): crop and P formed in the network's "
                           "training camera; tau in the real camera frame",
            "K_net": np.asarray(K_net, np.float64).tolist(),
            "focal_ratio": [float(K_net[0, 0] / K[v, 0, 0]) for v in range(K.shape[0])]}


def image_sizes(sequence) -> list[tuple[int, int]]:
    """``(W, H)`` of each view of a loaded sequence (from its first frame)."""
    out = []
    for v in range(sequence.num_views):
        h, w = sequence.image(0, v).shape[:2]
        out.append((w, h))
    return out


def _model_device(model: nn.Module) -> torch.device:
    return next(model.parameters()).device


def _resolve_input_size(model: nn.Module, input_size: int | None) -> int:
    size = input_size if input_size is not None else getattr(model, "input_size", None)
    if size is None:
        raise ValueError("input_size unknown: pass the crop size the network was trained with "
                         "(airpose_lib.finetune.load_sized_network returns it from a checkpoint)")
    return int(size)


def _drone_boxes(sequence, rows: np.ndarray, detector: str, box_min_confidence: float, margin_px: float | None,
                 K_net: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The drones' person boxes of ``rows (F,)`` of a loaded sequence (:func:`detection_boxes`,
    each view's margin in its own pixels): ``boxes (F, V, 4)``, ``valid (F, V)``, ``margins (V,)``."""
    margins = np.array([box_margin(margin_px, K, K_net) for K in np.asarray(sequence.K)])
    boxes, valid = detection_boxes(np.asarray(sequence.keypoints[detector])[rows], image_sizes(sequence),
                                   min_confidence=box_min_confidence, margin_px=margins,
                                   where=f"{sequence.root} ({detector})")
    return boxes, valid, margins


# -- the sequence pass ----------------------------------------------------------------------------
@torch.no_grad()
def sequence_features(model: nn.Module, sequence, *, input_size: int, detector: str = "openpose",
                      frames=None, batch_size: int = 16, box_min_confidence: float = 0.2,
                      margin_px: float | None = None, K_net=None, progress: bool = False,
                      cut: str | None = None) -> dict[str, np.ndarray]:
    """Backbone features of every frame and view (eval mode, no gradients).

    Args: as :func:`predict_sequence`; the crops and P are formed in the virtual camera
    ``K_net`` (:func:`network_camera_of`). ``cut``: a backbone block name; the features are
    then that block's input (``ResNet.forward_until``), for training that block and the rest.

    Returns:
        ``features (F, V, C)`` float32 (with ``cut``: ``(F, V, C, h, w)``), ``P (F, V, 3)`` float32, ``boxes (F, V, 4)`` float32,
        ``valid (F, V)`` bool, ``frames (F,)`` int64 image numbers, ``positions (F,)`` int64 rows
        of ``sequence``, ``margin_px (V,)`` float64 the box margin of each view.
    """
    if detector not in sequence.keypoints:
        raise ValueError(f"{sequence.root}: no {detector!r} detections loaded (have {sorted(sequence.keypoints)})")
    if batch_size < 1:
        raise ConfigError("batch_size must be >= 1")
    pos = _positions(sequence, frames)
    V = sequence.num_views
    K_net = network_camera_of(model, K_net)
    boxes, valid, margins = _drone_boxes(sequence, pos, detector, box_min_confidence, margin_px, K_net)
    was_training = model.training
    model.eval()
    device = _model_device(model)
    dtype = model.init_beta.dtype
    feats, Ps = [], []
    chunks = range(0, len(pos), batch_size)
    if progress:
        chunks = progress_bar(chunks, desc="features", unit="batch")
    try:
        for a in chunks:
            rows = pos[a:a + batch_size]
            crops, P = _crops(sequence, rows, boxes[a:a + batch_size], input_size, K_net)
            x = torch.from_numpy(crops).to(device=device, dtype=dtype)
            x = x.flatten(0, 1)
            f = (model.features(x) if cut is None else model.backbone.forward_until(x, cut)).unflatten(0, (len(rows), V))
            feats.append(f.float().cpu())
            Ps.append(torch.from_numpy(P))
    finally:
        model.train(was_training)
    return {"features": torch.cat(feats).numpy(), "P": torch.cat(Ps).numpy().astype(np.float32),
            "boxes": boxes.astype(np.float32), "valid": valid,
            "frames": np.asarray(sequence.frames, np.int64)[pos], "positions": pos, "margin_px": margins}


@torch.no_grad()
def adapt_batchnorm(model: nn.Module, sequence, *, input_size: int, detector: str = "openpose",
                    frames=None, batch_size: int = 32, box_min_confidence: float = 0.2,
                    margin_px: float | None = None, K_net=None, seed: int = 0, weight: float = 1.0,
                    progress: bool = False) -> int:
    """Move the backbone's BatchNorm statistics towards a recording's (AdaBN: Li et al., "Adaptive
    Batch Normalization for practical domain adaptation", Pattern Recognition 80, 2018; the blend:
    Schneider et al., "Improving robustness against common corruptions by covariate shift
    adaptation", NeurIPS 2020).

    A network trained on clean renders normalises a field recording's activations with the renders'
    means and variances; exposure, noise, blur and compression shift them, and a frozen backbone
    (the paper's fine-tuning) cannot follow. Every BatchNorm layer's running mean and variance
    become ``(1 - weight) * stored + weight * recording``, the recording's being the averages over
    its crops, without labels; the learned weights, BatchNorm's affine ones included, are
    unchanged. ``weight`` 1 is AdaBN; below 1 the training statistics keep a share, as one
    recording (one person, one scene) has far less variety than the training renders.

    Args: as :func:`sequence_features` (the crops are the drones' crops of ``frames``, every view);
    ``batch_size`` crops per batch, drawn in an order shuffled with ``seed`` so that a batch mixes
    frames and views (the recording's statistics are the equal-weight average of the batches');
    ``weight`` in ``(0, 1]``.

    Returns:
        the number of crops the statistics come from. Only BatchNorm buffers change (and, if the
        pass fails, not those either); the model's training flags are restored.

    Raises:
        ConfigError: ``batch_size`` < 2 (a batch's variance needs two crops).
        ValueError: the backbone has no BatchNorm layer.
    """
    if batch_size < 2:
        raise ConfigError("batch_size must be >= 2 (a batch's variance needs two crops)")
    if not 0 < weight <= 1:
        raise ConfigError(f"weight must be in (0, 1], got {weight}")
    norms = [m for m in model.backbone.modules() if isinstance(m, nn.modules.batchnorm._BatchNorm)]
    if not norms:
        raise ValueError("the backbone has no BatchNorm layer to adapt")
    pos = _positions(sequence, frames)
    V = sequence.num_views
    K_net = network_camera_of(model, K_net)
    # boxes of the whole recording: hold_boxes as the drones do
    boxes, _, _ = _drone_boxes(sequence, np.arange(len(sequence.frames)), detector, box_min_confidence, margin_px,
                               K_net)
    pairs = np.stack(np.meshgrid(pos, np.arange(V), indexing="ij"), -1).reshape(-1, 2)  # (F V, 2) rows, views
    pairs = pairs[np.random.default_rng(seed).permutation(len(pairs))]
    was_training = model.training
    saved = [(m.momentum, m.training) for m in norms]
    stored = [(m.running_mean.clone(), m.running_var.clone(), m.num_batches_tracked.clone()) for m in norms]
    device = _model_device(model)
    dtype = model.init_beta.dtype
    chunks = range(0, len(pairs), batch_size)
    if progress:
        chunks = progress_bar(chunks, desc="BatchNorm statistics", unit="batch")
    used = 0
    model.eval()
    try:
        for m in norms:
            m.reset_running_stats()
            m.momentum = None  # a cumulative average over the batches
            m.train()
        for a in chunks:
            batch = pairs[a:a + batch_size]
            if len(batch) < 2:
                break  # one crop's spatial variance alone would weigh as much as a full batch's
            x = np.stack([crop_input(sequence.image(int(r), int(v)), boxes[int(r), int(v)],
                                     np.asarray(sequence.K[int(v)], np.float64), input_size, K_net)[0][0]
                          for r, v in batch])
            model.features(torch.from_numpy(x).to(device=device, dtype=dtype))
            used += len(batch)
        for m, (mean, var, _) in zip(norms, stored):
            m.running_mean.mul_(weight).add_(mean, alpha=1 - weight)
            m.running_var.mul_(weight).add_(var, alpha=1 - weight)
    except BaseException:  # an unreadable image, an interrupt: the network keeps its statistics
        for m, (mean, var, count) in zip(norms, stored):
            m.running_mean.copy_(mean)
            m.running_var.copy_(var)
            m.num_batches_tracked.copy_(count)
        raise
    finally:
        for m, (momentum, training) in zip(norms, saved):
            m.momentum = momentum
            m.train(training)
        model.train(was_training)
    return used


@torch.no_grad()
def predict_sequence(model: nn.Module, sequence, *, input_size: int | None = None, detector: str = "openpose",
                     frames=None, batch_size: int = 16, features_only: bool = False,
                     box_min_confidence: float = 0.2, margin_px: float | None = None, K_net=None,
                     provenance: Mapping | None = None, progress: bool = False) -> dict:
    """Run a network over a recording.

    Args:
        model: an :class:`~airpose_lib.model.AirPoseNet` (any variant; run in eval mode, its
            training flag is restored afterwards).
        sequence: a :class:`~airpose_lib.data.sequences.reader.Sequence` (``load_sequence``).
        input_size: crop side S the network was trained with (default: ``model.input_size``).
        detector: keypoints the boxes come from (``openpose`` or ``alphapose``).
        frames: image numbers to run (a subset of ``sequence.frames``, increasing); None: all.
        batch_size: frames per backbone batch (each holds V crops).
        features_only: return the backbone features instead of parameters (see
            :func:`sequence_features`; what fine-tuning caches).
        box_min_confidence, margin_px: :func:`airpose_lib.data.network_input.person_box`
            settings (the drones' defaults: 0.2, and a margin of None is
            ``data.network_input.network_box_margin``, in each view's pixels).
        K_net: ``(3, 3)`` the network's training camera (default :func:`network_camera_of`).
        provenance: extra JSON-able facts stored in the ``provenance`` string (e.g. the checkpoint).
        progress: tqdm bar over the batches.

    Returns:
        the predictions contract (module docstring): numpy arrays ``phi``, ``tau``, ``theta``,
        ``beta``, ``frames``, ``P``, ``boxes``, ``valid`` and the ``provenance`` JSON string.
    """
    size = _resolve_input_size(model, input_size)
    K_net = network_camera_of(model, K_net)
    cache = sequence_features(model, sequence, input_size=size, detector=detector, frames=frames,
                              batch_size=batch_size, box_min_confidence=box_min_confidence,
                              margin_px=margin_px, K_net=K_net, progress=progress)
    if features_only:
        return cache
    was_training = model.training
    model.eval()
    device = _model_device(model)
    dtype = model.init_beta.dtype
    # P refers to the virtual camera: a weak camera becomes a translation with K_net.
    K = torch.as_tensor(K_net, dtype=dtype, device=device).expand(sequence.num_views, 3, 3)
    parts: dict[str, list[Tensor]] = {k: [] for k in ("phi", "tau", "theta", "beta")}
    F = len(cache["frames"])
    try:
        for a in range(0, F, max(batch_size, 1) * 8):  # the regressor is cheap: larger batches
            sl = slice(a, a + max(batch_size, 1) * 8)
            feat = torch.from_numpy(cache["features"][sl]).to(device=device, dtype=dtype)
            P = torch.from_numpy(cache["P"][sl]).to(device=device, dtype=dtype)
            out = regress_features(model, feat, P, size)
            params = to_smplx_params(out, P, K.expand(feat.shape[0], -1, -1, -1), size)
            for k in parts:
                parts[k].append(params[k].float().cpu())
    finally:
        model.train(was_training)
    pred = {k: torch.cat(v).numpy() for k, v in parts.items()}
    info = {"kit_version": __version__, "sequence": str(sequence.root), "detector": detector, "input_size": size,
            "variant": getattr(model, "variant", None), "num_frames": F,
            "frames": [int(cache["frames"][0]), int(cache["frames"][-1])],
            "views_without_detection": int((~cache["valid"]).sum()),
            "box": {"min_confidence": box_min_confidence, "margin_px": cache["margin_px"].round(2).tolist(),
                    "missing": "previous box (leading frames: the first box), valid=False"},
            **camera_rule(K_net, np.asarray(sequence.K)),
            **dict(provenance or {})}
    pred.update(frames=cache["frames"], P=cache["P"], boxes=cache["boxes"], valid=cache["valid"],
                provenance=json.dumps(info, default=str))
    return validate_predictions(pred, "predict_sequence output")


# -- the file -------------------------------------------------------------------------------------
_SHAPES = {"phi": (3, 3), "tau": (3,), "theta": (21, 3, 3), "beta": (10,), "P": (3,), "boxes": (4,)}


def validate_predictions(pred: Mapping, where: str = "predictions") -> dict:
    """Check the contract; returns a dict of numpy arrays (float32 parameters, int64 frames, bool
    valid, provenance as a JSON string). Raises :class:`PredictionFormatError` naming ``where``."""
    missing = [k for k in REQUIRED_PREDICTION_KEYS if k not in pred]
    if missing:
        raise PredictionFormatError(f"{where}: missing arrays {missing} (a predictions file needs "
                                    f"{list(REQUIRED_PREDICTION_KEYS)}; see airpose_lib.finetune.predict)")
    out: dict = {}
    phi = np.asarray(pred["phi"])
    if phi.ndim != 4 or phi.shape[2:] != (3, 3):
        raise PredictionFormatError(f"{where}: phi must be (F, V, 3, 3), got {phi.shape}")
    F, V = phi.shape[:2]
    if F == 0:
        raise PredictionFormatError(f"{where}: no frames")
    for key, tail in _SHAPES.items():
        if key not in pred:
            continue
        arr = np.asarray(pred[key])
        if arr.shape != (F, V, *tail):
            raise PredictionFormatError(f"{where}: {key} must be {(F, V, *tail)} (F={F} frames, V={V} views), "
                                        f"got {arr.shape}")
        if not np.issubdtype(arr.dtype, np.floating):
            raise PredictionFormatError(f"{where}: {key} must be floating point, got {arr.dtype}")
        if not np.isfinite(arr).all():
            bad = np.argwhere(~np.isfinite(arr.reshape(F, -1)).all(-1)).ravel()
            raise PredictionFormatError(f"{where}: {key} contains NaN or inf (first bad frame position "
                                        f"{int(bad[0])} of {F})")
        out[key] = arr.astype(np.float32)
    frames = np.asarray(pred["frames"])
    if frames.shape != (F,) or not np.issubdtype(frames.dtype, np.integer):
        raise PredictionFormatError(f"{where}: frames must be ({F},) integers (one image number per frame), "
                                    f"got {frames.shape} {frames.dtype}")
    if np.any(np.diff(frames) <= 0):
        raise PredictionFormatError(f"{where}: frames must be strictly increasing image numbers")
    out["frames"] = frames.astype(np.int64)
    if "valid" in pred:
        valid = np.asarray(pred["valid"])
        if valid.shape != (F, V) or valid.dtype != np.bool_:
            raise PredictionFormatError(f"{where}: valid must be ({F}, {V}) bool, got {valid.shape} {valid.dtype}")
        out["valid"] = valid
    if "provenance" in pred:
        prov = pred["provenance"]
        prov = prov.item() if isinstance(prov, np.ndarray) else prov
        if isinstance(prov, Mapping):
            prov = json.dumps(prov, default=str)
        if not isinstance(prov, str):
            raise PredictionFormatError(f"{where}: provenance must be a JSON string or a dict")
        try:
            json.loads(prov)
        except json.JSONDecodeError as e:
            raise PredictionFormatError(f"{where}: provenance is not valid JSON: {e}") from None
        out["provenance"] = prov
    return out


def save_predictions(path: str | Path, pred: Mapping) -> Path:
    """Write predictions (the contract of the module docstring) to an ``.npz``, atomically.

    The dict is validated first, so a bad prediction never reaches the disk. Returns ``path``.
    """
    path = Path(path)
    arrays = validate_predictions(pred, f"predictions for {path}")
    if "provenance" in arrays:
        arrays["provenance"] = np.array(arrays["provenance"])
    with atomic_path(path) as tmp:
        with open(tmp, "wb") as fh:  # a file object: np.savez would append ".npz" to a name
            np.savez(fh, **arrays)
    return path


def load_predictions(path: str | Path) -> dict:
    """Read and validate a predictions ``.npz``.

    Returns:
        numpy arrays (see the module docstring) and ``provenance`` as a dict (empty if absent).

    Raises:
        PredictionFormatError: missing file, unreadable file, missing keys, wrong shapes, NaN.
    """
    path = Path(path)
    if not path.is_file():
        raise PredictionFormatError(f"no predictions file {path}; make one with `airpose predict` "
                                    "(airpose_lib.finetune.predict_sequence + save_predictions)")
    try:
        with np.load(path, allow_pickle=False) as data:
            raw = {k: data[k] for k in data.files}
    except Exception as e:  # noqa: BLE001 - zip/npy errors of many kinds
        raise PredictionFormatError(f"cannot read predictions file {path}: {e}") from None
    out = validate_predictions(raw, str(path))
    out["provenance"] = json.loads(out["provenance"]) if "provenance" in out else {}
    return out
