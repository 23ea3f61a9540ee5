r"""Fine-tuning a trained network on the 2D detections of a recording (paper Sec. IV, real data).

``finetune(checkpoint, sequence_root, out_dir, config)``:

1. loads the network of a kit checkpoint and the recording (``data.load_sequence``), optionally
   restricted to a range of image numbers (the paper trains on frames 0-6999 of its real data);
2. builds the 2D targets with the two-detector agreement filter
   (:func:`~airpose_lib.finetune.keypoints.agreement_targets`); ``targets="ground_truth"`` uses a
   generated recording's true keypoints instead (a control: same frames, crops and loss);
   ``targets="mediapipe"`` puts MediaPipe's keypoints in OpenPose's place in the filter;
3. runs the **frozen** backbone once over every frame and view, crops made from the detections as
   the drones make them, and caches the features (``<out>/feature_cache.pt``, reused while the
   backbone, crop settings and recording are unchanged). The backbone is never run again and
   never in training mode, so its weights and BatchNorm statistics stay bit-identical; training
   then costs only the regressor, the joints-only body and the prior -- cheap enough for a CPU.
   With ``adapt_bn`` the BatchNorm statistics first move towards those of the training frames'
   crops (:func:`~airpose_lib.finetune.predict.adapt_batchnorm`) and then stay fixed;
4. trains the regressor (fc1, fc2 and the decoder heads; dropout active as in training) with
   Adam (AMSGrad, lr 5e-5, paper) on :class:`~airpose_lib.finetune.loss.FineTuneLoss` with the
   variant's paper weights. A training sample is one frame with all its views (the multi-view
   variants exchange messages as in the forward); frames whose targets are all dropped are
   skipped;
5. selects the model (the paper stops "once the model starts overfitting on any loss
   component"): the last ``holdout_fraction`` of the selected frames (20 %) never train. Before
   training and at every checkpoint each loss term is measured (eval mode) on them and on the
   training frames; the rule ``selection`` (:mod:`~airpose_lib.finetune.selection`; default the
   paper's: the last checkpoint before any weighted term's held-out value rises while its
   training value falls) picks the checkpoint kept as ``checkpoints/best.pt``
   (``FineTuneResult.best_*``). Training still runs all ``steps``, so the later checkpoints can
   be inspected. An optional ``diagnostic(model)`` (e.g. errors on a test person) is logged next
   to it in ``selection.csv`` and never used for the choice.

Pixel units: ``threshold_px`` and the 2D loss weight are the paper's values for 1920 px wide
frames (``reference_width``). A view of another width gets them at its own resolution
(:func:`~airpose_lib.finetune.keypoints.resolution_scales`, ``r = width / reference_width``):
the agreement threshold ``threshold_px r`` and the 2D residuals divided by ``r`` (= a weight
``w_j2d / r^2`` on the squared pixels), so a half-resolution recording is filtered and weighted
as its full-resolution original would be.

Crops and P are formed in the network's virtual camera (``geometry.virtual_crop``; the
checkpoint's training camera, ``camera_K`` of its network record, :mod:`airpose_lib.model.record`);
the 2D loss projects the predicted body with the recording's own intrinsics.

Determinism and resume follow ``airpose_lib.train``: the frame order of epoch e is drawn from
``(seed, e)`` only; dropout and the VPoser sample use torch's global RNG, seeded from the seed and
saved in every checkpoint (with the optimiser and the position), so an interrupted run resumed
from its last checkpoint ends with exactly the weights of an uninterrupted one (same machine and
thread count). The caller's RNG states and torch thread count are restored on return.

Output folder: ``checkpoints/last.pt`` (+ ``step_<n>.pt``) in the kit checkpoint format (read by
``airpose_lib.train.load_trained_model`` and :func:`~airpose_lib.finetune.network.load_sized_network`;
the base ``config`` is kept and a ``finetune`` entry records this run), ``log.csv``,
``config.json``, ``result.json``, ``selection.csv`` (loss terms, held-out and training, and
diagnostics per checkpoint, ``checkpoints/best.pt`` the selected one) and the feature cache.
"""
from __future__ import annotations

import dataclasses
import hashlib
import json
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import torch
from torch import nn

from airpose_lib.atomic import atomic_path, atomic_torch_save
from airpose_lib.body import load_body_model
from airpose_lib.config_fields import ConfigError
from airpose_lib.data.sequences.reader import load_sequence, recording_fingerprint
from airpose_lib.engine import (
    AFRESH_HINT,
    EngineRun,
    Schedule,
    StaleRunError,
    TrainingTask,
    capture_rng_state,
    checkpoint_dir,
    last_checkpoint,
    load_checkpoint,
    read_log,
    restore_rng_state,
    run_engine,
    write_checkpoint,
)
from airpose_lib.engine.launch import resolve_device
from airpose_lib.errors import DamagedFileError
from airpose_lib.folder_lock import folder_lock
from airpose_lib.model import to_smplx_params
from airpose_lib.model.record import network_record
from airpose_lib.prior import load_prior
from airpose_lib.train.sampling import epoch_permutation, seed_everything

from .config import FineTuneConfig
from .keypoints import agreement_masks, agreement_summary, kept_targets, pixel_settings, resolution_scales, true_targets
from .loss import FineTuneLoss, finetune_loss_config
from .network import load_sized_network
from .predict import adapt_batchnorm, frames_in_range, image_sizes, regress_features, sequence_features
from .selection import select_step

__all__ = ["FineTuneResult", "finetune", "finetune_done", "evaluate_finetune_loss", "heldout_split"]

@dataclass
class FineTuneResult:
    """What a run ended with (also ``<out>/result.json``).

    Attributes:
        out_dir: the run folder; checkpoint: its ``checkpoints/last.pt``.
        step: optimiser steps done; stopped_early: ``stop_at`` ended it before ``steps``.
        num_frames: training frames (frames with at least one kept target).
        initial, final: mean loss terms over the training frames before and after (eval mode:
            no dropout, VPoser posterior mean), e.g. ``final["j2d"]``.
        history: ``log.csv`` as lists (``step``, ``total``, ``j2d``, ...).
        keypoints: the agreement filter's counts (``kept``, ``disagree``, ...).
        config: the :class:`FineTuneConfig`; loss: the loss config used; seconds: wall time.
        best_checkpoint, best_step, best_heldout_j2d: the model selection's choice
            (``checkpoints/best.pt``; None without held-out frames).
        overfit_step, overfit_terms: rule ``first_overfit``: where the first loss term started
            overfitting and which (None / empty: none did; the last checkpoint is kept).
        selection: ``selection.csv`` as lists (``step``, ``heldout_<term>``, ``train_<term>``,
            ``selected``, ``diag_*``).
        pixels: the per-view resolution scale and the derived threshold / 2D weight.
        heldout_frames: frames held out for selection (with kept targets).
    """

    out_dir: Path
    checkpoint: Path | None
    step: int
    num_frames: int
    initial: dict[str, float]
    final: dict[str, float] | None
    history: dict[str, list] = field(default_factory=dict)
    keypoints: dict[str, int] = field(default_factory=dict)
    config: dict = field(default_factory=dict)
    loss: dict = field(default_factory=dict)
    stopped_early: bool = False
    seconds: float = 0.0
    best_checkpoint: Path | None = None
    best_step: int | None = None
    best_heldout_j2d: float | None = None
    overfit_step: int | None = None
    overfit_terms: list[str] = field(default_factory=list)
    selection: dict[str, list] = field(default_factory=dict)
    pixels: dict = field(default_factory=dict)
    heldout_frames: int = 0

    def to_json(self) -> dict:
        d = dataclasses.asdict(self)
        d["out_dir"] = str(self.out_dir)
        d["checkpoint"] = str(self.checkpoint) if self.checkpoint else None
        d["best_checkpoint"] = str(self.best_checkpoint) if self.best_checkpoint else None
        return d


# -- pieces ---------------------------------------------------------------------------------------
def _primary(cfg: FineTuneConfig) -> str:
    """The BODY_25 detector whose keypoints the agreement filter confirms with AlphaPose."""
    return "mediapipe" if cfg.targets == "mediapipe" else "openpose"


def _load_frames(root: Path, cfg: FineTuneConfig):
    detectors = tuple(dict.fromkeys(("openpose", "alphapose", cfg.detector, _primary(cfg))))
    frames = None if cfg.frames is None else frames_in_range(root, cfg.frames[0], cfg.frames[1])
    seq = load_sequence(root, frames=frames, detectors=detectors, missing_detections=cfg.missing_detections,
                        ground_truth=cfg.targets == "ground_truth")
    if cfg.targets == "ground_truth" and (seq.ground_truth is None or "kp2d_body25" not in seq.ground_truth):
        raise ConfigError(f"{root}: targets='ground_truth' needs a generated recording's ground_truth.npz "
                          "(kp2d_body25); real recordings have none: use targets='detections'")
    return seq


def _tensor_digest(tensors: Mapping[str, torch.Tensor]) -> str:
    h = hashlib.sha256()
    for k in sorted(tensors):
        t = tensors[k].detach().cpu().contiguous()
        h.update(k.encode())
        h.update(str(t.dtype).encode())
        h.update(t.reshape(-1).view(torch.uint8).numpy().tobytes() if t.numel() else b"")
    return h.hexdigest()


def _feature_fingerprint(model, data_fp: str, cfg: FineTuneConfig, input_size: int, K_net: np.ndarray) -> str:
    """What the cached features depend on: the backbone (weights and BatchNorm statistics), the
    recording's content (``data_fp``, :func:`recording_fingerprint`: frames, images, keypoints)
    and the crop settings."""
    backbone = {k: v for k, v in model.state_dict().items() if k.startswith("backbone.")}
    h = hashlib.sha256(_tensor_digest(backbone).encode())
    h.update(json.dumps({"input_size": input_size, "detector": cfg.detector, "box": [cfg.box_min_confidence,
                         cfg.margin_px], "recording": data_fp,
                         "dtype": str(model.init_beta.dtype), **({"cut": cfg.trainable_from} if cfg.trainable_from else {}),
                         "K_net": np.asarray(K_net, np.float64).tolist()}).encode())
    return h.hexdigest()


def _feature_cache(model, seq, data_fp: str, cfg: FineTuneConfig, input_size: int, K_net: np.ndarray, out_dir: Path,
                   progress: bool) -> dict:
    path = out_dir / "feature_cache.pt"
    fp = _feature_fingerprint(model, data_fp, cfg, input_size, K_net)
    if path.is_file():
        try:
            cached = torch.load(path, map_location="cpu", weights_only=True)
            if cached.get("fingerprint") == fp:
                return {k: v.numpy() if isinstance(v, torch.Tensor) else v for k, v in cached["arrays"].items()}
        except Exception:  # noqa: BLE001 - a damaged cache is rebuilt
            pass
    arrays = sequence_features(model, seq, input_size=input_size, detector=cfg.detector,
                               batch_size=cfg.feature_batch_size, box_min_confidence=cfg.box_min_confidence,
                               margin_px=cfg.margin_px, K_net=K_net, progress=progress, cut=cfg.trainable_from)
    atomic_torch_save({"fingerprint": fp, "arrays": {k: torch.from_numpy(np.asarray(v)) for k, v in arrays.items()}},
                      path)
    return arrays


def _step_terms(model, loss_fn, feat, P, targets, K, input_size: int, K_net=None,
                pixel_scale=None, cut: str | None = None) -> dict[str, torch.Tensor]:
    out = regress_features(model, feat, P, input_size, cut=cut)
    # P lives in the virtual camera K_net (a weak camera converts there); the body projects with K.
    K_p = K if K_net is None else K_net
    pred = to_smplx_params(out, P, K_p.expand(feat.shape[0], *K.shape[-3:]), input_size)
    return loss_fn(pred, targets, K, pixel_scale=pixel_scale)


@torch.no_grad()
def evaluate_finetune_loss(model: nn.Module, loss_fn: nn.Module, features: torch.Tensor, P: torch.Tensor,
                           targets: torch.Tensor, K: torch.Tensor, input_size: int,
                           batch_size: int = 256, K_net: torch.Tensor | None = None,
                           pixel_scale: torch.Tensor | None = None, cut: str | None = None) -> dict[str, float]:
    """Mean loss terms over frames in eval mode (no dropout), VPoser at the posterior mean.

    Args:
        features: ``(F, V, C)`` (with ``cut``: ``(F, V, C, h, w)``, block ``cut``'s input);
            P: ``(F, V, 3)``; targets: ``(F, V, 25, 3)``; K: ``(V, 3, 3)``.
        K_net: ``(V, 3, 3)`` the virtual camera of P (default K).
        pixel_scale: ``(V,)`` resolution scale of the 2D residuals (``FineTuneLoss.forward``).

    Returns:
        term -> frame-weighted mean (the ``FineTuneLoss`` keys).
    """
    cfg = dataclasses.replace(loss_fn.config, vposer_latent="mean")
    det = FineTuneLoss(cfg, body_model=loss_fn.body_model, prior=loss_fn.prior)
    was_training = model.training
    model.eval()
    sums: dict[str, float] = {}
    n = features.shape[0]
    try:
        for a in range(0, n, batch_size):
            sl = slice(a, a + batch_size)
            terms = _step_terms(model, det, features[sl], P[sl], targets[sl], K, input_size, K_net, pixel_scale, cut)
            k = features[sl].shape[0]
            for key, v in terms.items():
                sums[key] = sums.get(key, 0.0) + float(v) * k
    finally:
        model.train(was_training)
    return {k: v / max(n, 1) for k, v in sums.items()}


def _stream_seed(seed: int) -> int:
    """Seed of the random stream of training (dropout, VPoser samples), derived from the run's seed
    so that it differs from the stream that seeded everything else."""
    return int(np.random.SeedSequence([int(seed), 2]).generate_state(1, np.uint64)[0] >> np.uint64(1))


def _set_train_mode(model: nn.Module) -> None:
    model.train()
    # frozen, or only its last blocks training: its BatchNorm statistics stay fixed (pretraining's or adapt_bn's)
    model.backbone.eval()


def heldout_split(num_frames: int, fraction: float) -> tuple[np.ndarray, np.ndarray]:
    """Positions ``0..F-1`` split in time: the first ``F - n`` train, the last ``n`` are held out,
    ``n = round(fraction F)`` (at least 1 when ``fraction > 0`` and ``F >= 2``).

    Returns:
        ``train (F - n,)`` and ``heldout (n,)`` int64 positions.
    """
    n = int(round(fraction * num_frames))
    if fraction > 0 and num_frames >= 2:
        n = min(max(n, 1), num_frames - 1)
    cut = num_frames - n
    return np.arange(cut, dtype=np.int64), np.arange(cut, num_frames, dtype=np.int64)


def _isolated(diagnostic: Callable, model: nn.Module) -> dict[str, float]:
    """Run a diagnostic so that it cannot change the run: eval mode, no gradients, the RNG
    state and the model's mode restored afterwards; its values are only logged."""
    rng = capture_rng_state()
    was_training = model.training
    model.eval()
    try:
        with torch.no_grad():
            values = dict(diagnostic(model) or {})
    finally:
        model.train(was_training)
        restore_rng_state(rng)
    return {f"diag_{k}": float(v) for k, v in values.items()}


def _write_selection(out_dir: Path, rows: list[dict]) -> None:
    import pandas as pd

    with atomic_path(out_dir / "selection.csv") as tmp:
        pd.DataFrame(rows).to_csv(tmp, index=False)


def _check_resume(saved: Mapping, cfg: FineTuneConfig, base_fp: str, data_fp: str,
                  diagnostic_key: str | None = None) -> None:
    now, default = cfg.to_dict(), FineTuneConfig().to_dict()
    # a key the saved run predates ran with its default (options are added with the old behaviour)
    diff = [k for k in FineTuneConfig.RESUME_KEYS if saved["config"].get(k, default[k]) != now.get(k)]
    if saved.get("base_fingerprint") != base_fp:
        diff.append("base checkpoint")
    # the recording's content: a run that predates the record is made again, as it cannot be checked
    if saved.get("data_fingerprint") != data_fp:
        diff.append("recording")
    if saved.get("diagnostic_key") != diagnostic_key:  # the diagnostic's columns in selection.csv
        diff.append("diagnostic's recordings")
    if diff:
        raise StaleRunError(diff, made="fine-tuned")


def finetune_done(out_dir: str | Path, checkpoint: str | Path, sequence_root: str | Path, cfg: FineTuneConfig,
                  *, diagnostic_key: str | None = None) -> bool:
    """Whether ``out_dir`` holds a finished run of ``cfg`` from the network ``checkpoint`` on the
    recording ``sequence_root`` (its content, :func:`~airpose_lib.data.sequences.reader.recording_fingerprint`),
    which :func:`finetune` would load rather than train (the resume check of :func:`finetune`
    itself). A run from another network (the profile's networks retrained) or on other frames
    (the recording rendered again) is not."""
    last = last_checkpoint(out_dir)
    try:
        state = load_checkpoint(last) if last is not None else None
        if state is None or int(state["step"]) < cfg.steps:
            return False
        model, _, _ = load_sized_network(checkpoint)
        _check_resume(state["finetune"], cfg, _tensor_digest(model.state_dict()),
                      recording_fingerprint(_load_frames(Path(sequence_root), cfg)), diagnostic_key)
    except (OSError, ValueError, KeyError, RuntimeError):  # StaleRunError is a ValueError
        return False
    return True


def _history(log_path: Path) -> dict[str, list]:
    hist: dict[str, list] = {}
    for row in read_log(log_path):
        if row.get("split") != "train":
            continue
        for k, v in row.items():
            if k in ("split",):
                continue
            try:
                val: Any = int(v) if k in ("step", "epoch") else float(v)
            except (TypeError, ValueError):
                val = float("nan")
            hist.setdefault(k, []).append(val)
    return hist


# -- entry point ----------------------------------------------------------------------------------
def finetune(checkpoint: str | Path, sequence_root: str | Path, out_dir: str | Path,
             config: FineTuneConfig | None = None, resume: bool = True, progress: bool = False, *,
             prior=None, body_model=None, stop_at: int | None = None,
             diagnostic: Callable[[nn.Module], Mapping[str, float]] | None = None,
             diagnostic_key: str | None = None) -> FineTuneResult:
    """Fine-tune a trained network on a recording's 2D detections.

    Args:
        checkpoint: a kit checkpoint (``airpose train``; a fine-tuned one works too).
        sequence_root: a recording in the official layout (``machine_k/`` with ``openpose_res.pkl``
            and ``alphapose_res.json``).
        out_dir: run folder (see the module docstring).
        config: :class:`FineTuneConfig` (default: its defaults; see :func:`finetune_config`).
        resume: continue from ``<out_dir>/checkpoints/last.pt`` if present; otherwise (or with
            False) start afresh, deleting earlier checkpoints there.
        progress: tqdm bars.
        prior: a :class:`~airpose_lib.prior.VPoser` to use instead of ``config.prior``.
        body_model: the neutral ``smplx.SMPLX`` of the loss instead of ``config.body_source``'s.
        stop_at: stop (with a checkpoint) once this step is reached, as if interrupted there.
        diagnostic: ``f(model) -> {name: value}`` run at every model-selection point (e.g. the
            test person's 2D and 3D errors); logged as ``diag_<name>`` in ``selection.csv``, never
            used for the choice (it runs after it, isolated: eval mode, RNG state restored).
        diagnostic_key: what the diagnostic measures on (e.g. the test recordings' fingerprints);
            part of the resume check, so that a finished run is not reused with another
            diagnostic's columns.

    Returns:
        :class:`FineTuneResult`.
    """
    cfg = config if config is not None else FineTuneConfig()
    caller_rng = capture_rng_state()
    threads = torch.get_num_threads()
    if cfg.num_threads:
        torch.set_num_threads(cfg.num_threads)
    try:
        inputs = _read_inputs(Path(checkpoint), Path(sequence_root), cfg)
        with folder_lock(out_dir):  # one writer per run folder
            return _finetune(inputs, Path(checkpoint), Path(sequence_root), Path(out_dir), cfg, resume, progress, prior,
                             body_model, stop_at, diagnostic, diagnostic_key)
    finally:
        torch.set_num_threads(threads)
        restore_rng_state(caller_rng)


class _FineTuneTask(TrainingTask):
    """The engine's task for fine-tuning: regressor steps on the cached features of the training
    frames; model selection (:mod:`~airpose_lib.finetune.selection`, ``checkpoints/best.pt``) as
    its validation."""

    def __init__(self, *, model, loss_fn, optimizer, cfg: FineTuneConfig, train_cfg, frames: dict, heldout: dict,
                 evaluate: Callable, input_size: int, network: dict, info: dict, out_dir: Path,
                 diagnostic: Callable | None, terms: list[str]) -> None:
        self.model, self.loss_fn, self.optimizer = model, loss_fn, optimizer
        self.cfg, self.train_cfg, self.frames, self.heldout = cfg, train_cfg, frames, heldout
        self.evaluate, self.input_size, self.network = evaluate, input_size, network
        self.info, self.out_dir, self.diagnostic = info, out_dir, diagnostic
        self.terms = terms  # the weighted loss terms: those the selection rule watches
        self.selection: dict = info["selection"]
        self.best_path = checkpoint_dir(out_dir) / "best.pt"
        self.n = int(frames["features"].shape[0])
        self._train_eval: tuple[int, dict] | None = None  # (step, loss terms on the training frames)

    def batches(self, epoch: int, start: int):
        B = self.cfg.batch_size
        order = epoch_permutation(self.n, self.cfg.seed, epoch)
        for b in range(start, self.n // B):
            yield order[b * B:(b + 1) * B].to(self.frames["features"].device)

    def train_step(self, idx: torch.Tensor, step: int) -> dict[str, torch.Tensor]:
        f = self.frames
        return _step_terms(self.model, self.loss_fn, f["features"][idx], f["P"][idx], f["targets"][idx], f["K"],
                           self.input_size, f["K_net"], f["r_px"], self.cfg.trainable_from)

    def train_mode(self) -> None:
        _set_train_mode(self.model)
        self.loss_fn.train()

    def train_terms(self, step: int) -> dict[str, float]:
        """The loss terms on the training frames at ``step`` (evaluation is deterministic: eval
        mode, VPoser mean), computed once per step: the selection, ``initial`` and ``final`` share it."""
        if self._train_eval is None or self._train_eval[0] != step:
            f = self.frames
            self._train_eval = (step, self.evaluate(f["features"], f["P"], f["targets"]))
        return self._train_eval[1]

    def start(self, run: EngineRun) -> None:
        self.info["initial"] = self.train_terms(run.step)  # before validate: best.pt may be saved there
        self.validate(run)  # the network before fine-tuning is a candidate too
        seed_everything(_stream_seed(self.cfg.seed))  # the dropout / VPoser-sample stream

    def resume(self, state: Mapping) -> None:
        if "finetune" not in state:
            raise DamagedFileError(checkpoint_dir(self.out_dir) / "last.pt", "a fine-tuning checkpoint", AFRESH_HINT)
        _check_resume(state["finetune"], self.cfg, self.info["base_fingerprint"], self.info["data_fingerprint"],
                      self.info["diagnostic_key"])
        self.info["initial"] = state["finetune"]["initial"]
        self.selection = dict(state["finetune"].get("selection") or self.selection)
        self.info["selection"] = self.selection

    def validate(self, run: EngineRun) -> None:
        """Every loss term of the current weights on the held-out and the training frames (the
        only inputs of the choice), the selection rule over all points so far, then the diagnostic
        (logged only); the chosen weights go to best.pt when they are the current ones (a rule
        only ever keeps the current point or one it chose before). Not at an interruption: a
        resumed run selects where a straight one does."""
        h = self.heldout
        if not len(h["features"]):
            return None
        held = self.evaluate(h["features"], h["P"], h["targets"])
        trained = self.train_terms(run.step)
        row = {"step": run.step, **{f"heldout_{k}": v for k, v in held.items()},
               **{f"train_{k}": v for k, v in trained.items()}}
        rows = [r for r in self.selection["rows"] if r["step"] != run.step] + [row]
        choice = select_step(rows, self.cfg.selection, self.terms)
        if choice.step == run.step:
            write_checkpoint(self.best_path, run.checkpoint_state())
        chosen = next(r for r in rows if r["step"] == choice.step)
        self.selection.update(best_step=choice.step, best_heldout_j2d=chosen["heldout_j2d"],
                              overfit_step=choice.overfit_step, overfit_terms=choice.overfit_terms)
        if self.diagnostic is not None:
            row.update(_isolated(self.diagnostic, self.model))
        row["selected"] = choice.step
        self.selection["rows"] = rows
        _write_selection(self.out_dir, rows)
        return None

    def checkpoint_state(self) -> dict:
        return {"config": self.train_cfg.to_dict(), "world_size": 1, "network": self.network, "finetune": self.info}

    def config(self) -> dict:
        return self.cfg.to_dict()


def _read_inputs(checkpoint: Path, root: Path, cfg: FineTuneConfig) -> tuple:
    """The network, the recording and its 2D targets, read (and so checked) before the run folder
    is created or locked: a refused command leaves no trace.

    Returns:
        ``(device, model, train_cfg, input_size, seq, scales, targets_np (F, V, 25, 3), keypoints)``.
    """
    device = resolve_device(cfg.device)
    seed_everything(cfg.seed)  # first, as before the split: the network's build draws from it
    model, train_cfg, input_size = load_sized_network(checkpoint, device, cfg.input_size)
    if cfg.trainable_from is not None and cfg.trainable_from not in model.backbone.block_names():
        raise ConfigError(f"trainable_from={cfg.trainable_from!r} is not a block of {checkpoint}'s backbone; "
                          f"choose one of {', '.join(model.backbone.block_names())}")
    seq = _load_frames(root, cfg)
    scales = resolution_scales(image_sizes(seq), cfg.reference_width)  # (V,)
    threshold = cfg.threshold_px * scales
    if cfg.targets == "ground_truth":
        gt = seq.ground_truth
        targets_np = true_targets(gt["kp2d_body25"], gt["kp_depth_body25"], np.asarray(image_sizes(seq)))
        keypoints = {"targets": "ground_truth", "kept": int((targets_np[..., 2] > 0).sum())}
    else:
        primary = seq.keypoints[_primary(cfg)]
        masks = agreement_masks(primary, seq.keypoints["alphapose"], threshold_px=threshold,
                                min_confidence=cfg.min_confidence, unmatched=cfg.unmatched)
        targets_np = kept_targets(primary, masks)
        keypoints = agreement_summary(masks)
    return device, model, train_cfg, input_size, seq, scales, targets_np, keypoints


def _finetune(inputs: tuple, checkpoint: Path, root: Path, out_dir: Path, cfg: FineTuneConfig, resume: bool,
              progress: bool, prior, body_model, stop_at, diagnostic, diagnostic_key) -> FineTuneResult:
    t0 = time.time()
    device, model, train_cfg, input_size, seq, scales, targets_np, keypoints = inputs
    K_net_np = np.asarray(model.camera_K, np.float64)
    base_fp = _tensor_digest(model.state_dict())
    out_dir.mkdir(parents=True, exist_ok=True)
    train_pos, held_pos = heldout_split(len(seq.frames), cfg.holdout_fraction)
    adapted = None
    if cfg.adapt_bn > 0:  # before the cache: its fingerprint hashes the backbone, statistics included
        adapted = adapt_batchnorm(model, seq, input_size=input_size, detector=cfg.detector,
                                  frames=np.asarray(seq.frames)[train_pos], box_min_confidence=cfg.box_min_confidence,
                                  margin_px=cfg.margin_px, K_net=K_net_np, seed=cfg.seed, weight=cfg.adapt_bn,
                                  progress=progress)
    data_fp = recording_fingerprint(seq)
    cache = _feature_cache(model, seq, data_fp, cfg, input_size, K_net_np, out_dir, progress)
    has_targets = targets_np[..., 2].sum(axis=(1, 2)) > 0
    usable = train_pos[has_targets[train_pos]]
    held = held_pos[has_targets[held_pos]]
    n = len(usable)
    if n < cfg.batch_size and cfg.steps > 0:
        raise ConfigError(f"{root}: {n} training frames have kept 2D targets (after holding out "
                          f"{len(held_pos)} for model selection), fewer than one batch of {cfg.batch_size}; "
                          "lower batch_size or holdout_fraction, select more frames or relax the agreement filter")

    dtype = model.init_beta.dtype
    as_t = lambda a: torch.as_tensor(np.asarray(a)).to(device=device, dtype=dtype)  # noqa: E731
    K = as_t(seq.K)
    K_net = as_t(np.broadcast_to(K_net_np, K.shape).copy())
    r_px = as_t(scales)
    frames = {"features": as_t(cache["features"][usable]), "P": as_t(cache["P"][usable]),
              "targets": as_t(targets_np[usable]), "K": K, "K_net": K_net, "r_px": r_px}
    heldout = {"features": as_t(cache["features"][held]), "P": as_t(cache["P"][held]),
               "targets": as_t(targets_np[held])}
    pixels = {**pixel_settings(scales, cfg.threshold_px, finetune_loss_config(train_cfg.variant, cfg.official_loss,
                                                                              **cfg.loss).w_j2d),
              "reference_width": cfg.reference_width}

    for p in model.backbone.parameters():
        p.requires_grad_(False)
    params = [p for p in model.regressor.parameters()]
    for p in params:
        p.requires_grad_(True)
    groups = [{"params": params}]
    if cfg.trainable_from is not None:  # the last blocks adapt to the recording (checked in _read_inputs)
        tail = [p for block in model.backbone.blocks_from(cfg.trainable_from) for p in block.parameters()]
        for p in tail:
            p.requires_grad_(True)
        groups.append({"params": tail, "lr": cfg.lr * cfg.backbone_lr_scale})
    loss_cfg = finetune_loss_config(train_cfg.variant, cfg.official_loss, **cfg.loss)
    if body_model is None:
        body_model = load_body_model(cfg.body_source, "neutral")
    if prior is None and loss_cfg.w_vposer != 0:
        prior = load_prior(cfg.prior, cfg.prior_path, tag=cfg.prior_tag)
    loss_fn = FineTuneLoss(loss_cfg, body_model=body_model, prior=prior).to(device)
    optimizer = torch.optim.Adam(groups, lr=cfg.lr, amsgrad=cfg.amsgrad, weight_decay=cfg.weight_decay)

    def evaluate(f, p_, t):
        return evaluate_finetune_loss(model, loss_fn, f, p_, t, K, input_size, cfg.eval_batch_size, K_net, r_px,
                                      cfg.trainable_from)

    info = {"config": cfg.to_dict(), "loss": loss_cfg.to_dict(), "base_checkpoint": str(checkpoint),
            "base_fingerprint": base_fp, "sequence": str(root), "data_fingerprint": data_fp,
            "diagnostic_key": diagnostic_key,
            "frames": [int(seq.frames[0]), int(seq.frames[-1])], "num_frames": n,
            "heldout_frames": [int(seq.frames[held_pos[0]]), int(seq.frames[held_pos[-1]])] if len(held_pos) else [],
            "num_heldout": len(held), "keypoints": keypoints, "pixels": pixels, "adapted_bn_crops": adapted,
            "camera_K": K_net_np.tolist(), "initial": None,
            "selection": {"rule": cfg.selection, "rows": [], "best_step": None, "best_heldout_j2d": None,
                          "overfit_step": None, "overfit_terms": []}}
    network = network_record(train_cfg.variant, train_cfg.backbone, train_cfg.model, input_size, K_net_np)
    task = _FineTuneTask(model=model, loss_fn=loss_fn, optimizer=optimizer, cfg=cfg, train_cfg=train_cfg,
                         frames=frames, heldout=heldout, evaluate=evaluate, input_size=input_size,
                         network=network, info=info, out_dir=out_dir, diagnostic=diagnostic,
                         terms=[k for k, w in loss_cfg.weights.items() if w != 0])
    schedule = Schedule(steps=cfg.steps, log_every=cfg.log_every, checkpoint_every=cfg.checkpoint_every,
                        keep_checkpoints=cfg.keep_checkpoints, val_every=cfg.checkpoint_every, stop_at=stop_at,
                        checkpoint_at_end=True, loss_name="fine-tuning loss", what=f"finetune {train_cfg.variant}",
                        progress=progress, tensorboard=False)
    run = run_engine(task, schedule, out_dir, resume, started=t0)

    final = None if run.stopped_early else task.train_terms(run.step)
    selection = task.selection
    rows = selection["rows"]
    result = FineTuneResult(out_dir=out_dir, checkpoint=run.checkpoint, step=run.step, num_frames=n,
                            initial=info["initial"], final=final, history=_history(out_dir / "log.csv"),
                            keypoints=info["keypoints"], config=cfg.to_dict(), loss=loss_cfg.to_dict(),
                            stopped_early=run.stopped_early, seconds=time.time() - t0,
                            best_checkpoint=task.best_path if selection["best_step"] is not None else None,
                            best_step=selection["best_step"], best_heldout_j2d=selection["best_heldout_j2d"],
                            overfit_step=selection.get("overfit_step"),
                            overfit_terms=list(selection.get("overfit_terms") or []),
                            selection={k: [r.get(k) for r in rows] for k in dict.fromkeys(k for r in rows for k in r)},
                            pixels=pixels, heldout_frames=len(held))
    with atomic_path(out_dir / "result.json") as tmp:
        tmp.write_text(json.dumps(result.to_json(), indent=2, default=str))
    return result
