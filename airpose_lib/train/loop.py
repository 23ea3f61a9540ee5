"""The still-frame trainings of every variant: deterministic, resumable, single process or DDP.

``train(variant, profile, seed, out_dir, resume=True)`` (:mod:`airpose_lib.train.run`: the
prerequisites first, then :func:`start_training` here) builds the model
(``airpose_lib.model.build_model``), the still-frame datasets (``airpose_lib.data``) and the
supervised loss of the variant (``airpose_lib.losses``), and optimises with Adam (AMSGrad) in the
kit's one training loop (:func:`airpose_lib.engine.run_engine`); :class:`StillFrameTask` is its
task, one ``train_step`` per ``cfg.task`` (:data:`TASK_FORWARD`).

Determinism and resume. Python, numpy and torch are seeded from the config's seed; the data order
and every sample's augmentation depend only on ``(seed, epoch, index)``
(:mod:`airpose_lib.train.sampling`); a checkpoint stores model, optimiser, every process's RNG
states and the data position. A run interrupted after a checkpoint and resumed therefore ends
with exactly the weights of an uninterrupted run (same machine, same thread count). An
interruption (Ctrl-C, a killed job) loses the steps since the last checkpoint
(``checkpoint_every``); nothing is written on the way out, so no checkpoint can hold a
half-applied step.

Multi-process training (DDP). Under ``torchrun`` (``torchrun --nproc_per_node=N -m airpose_lib.cli
train ...``, one process per GPU, one or several nodes) the processes exist already: each reads
its rank, local rank (its GPU, ``cuda:<LOCAL_RANK>``) and the world size from the environment
(:func:`airpose_lib.engine.launch.launch_env`); ``world_size > 1`` without torchrun spawns that
many processes on this machine (``torch.multiprocessing``). ``gloo`` on CPU, ``nccl`` on CUDA.

The prerequisites (the dataset, the pretrained backbone, the feature caches) are resolved by
:func:`airpose_lib.train.run.train` before the loop starts and before the process group exists,
each process alone (:func:`airpose_lib.engine.launch.single_process`) and one after the other (a
file lock in the run folder): the first builds what is missing, a nested pretraining included, the
others find it made. Several nodes therefore need the run folder and the cache on a shared file
system (or the prerequisites made beforehand: ``airpose pretrain``). Rank 0 is the run folder's
one writer (lock, checkpoints, log).

The global batch B is split over the W processes in contiguous slices whose sizes differ by at
most one (:func:`airpose_lib.train.sampling.share_bounds`: 30 over 4 GPUs is 8, 8, 7, 7), and
every process's loss terms are weighted by ``n_r W / B`` so that DDP's gradient average (and the
logged all-reduced mean) is the mean over the global batch: with the same global batch the
updates equal the single-process ones up to floating-point summation order, for any W <= B --
except for what is computed per process by design: BatchNorm batch statistics (per-process
batches; ``sync_batchnorm: true`` shares them) and dropout masks (per-process RNG streams). A run
may resume with another number of processes (the RNG streams are re-seeded, with a warning).

Precision (``precision: fp32 | bf16 | fp16``): the training step's network forward runs under
``torch.autocast`` (:mod:`airpose_lib.engine.launch`); the losses are computed in float32
(:func:`_supervised_terms`), and validation runs in float32.
"""

from __future__ import annotations

import contextlib
import dataclasses
import functools
import json
import os
import socket
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import torch
import torch.distributed as dist
from torch import nn
from torch.utils.data import DataLoader

from airpose_lib.data.official.synthetic import OfficialSyntheticDataset
from airpose_lib.data.still.dataset import StillFrameDataset
from airpose_lib.data.still.manifest import verify_dataset
from airpose_lib.data.still.training_input import training_input
from airpose_lib.engine import EngineRun, Schedule, StaleRunError, TrainingTask, process_rank, run_engine, run_folder
from airpose_lib.engine.launch import check_precision, launch_env, resolve_device
from airpose_lib.errors import ConfigError
from airpose_lib.eval.reference import git_commit
from airpose_lib.losses import SupervisedLoss, loss_config
from airpose_lib.losses.pretrain import PretrainLoss, PretrainLossConfig
from airpose_lib.model import build_model, to_smplx_params
from airpose_lib.model.pretrain import PretrainNet
from airpose_lib.model.record import NETWORK_KEY, network_record

from .config import TrainConfig, check_options
from .features import FeatureDataset, ensure_features, load_backbone_file
from .sampling import ResumableBatchSampler, SeededDataset, _mix, seed_everything, worker_init_fn

__all__ = [
    "TrainResult",
    "start_training",
    "run_training",
    "default_model_factory",
    "default_dataset_factory",
    "default_loss_factory",
    "forward_loss",
    "regressor_forward_loss",
    "pretrain_forward_loss",
    "TASK_FORWARD",
    "task_forward",
    "StillFrameTask",
    "run_network_entry",
    "validation_loss",
]


# -- factories (top-level functions: picklable for spawned processes) -----------------------------
def default_model_factory(cfg: TrainConfig) -> nn.Module:
    """The network of ``cfg.task``: ``build_model(cfg.variant, backbone=cfg.backbone, **cfg.model)``
    (its backbone loaded from ``cfg.pretrained`` when given; frozen for the ``regressor`` task, whose
    checkpoints therefore hold the whole network), or a
    :class:`~airpose_lib.model.pretrain.PretrainNet` for ``pretrain``."""
    if cfg.task == "pretrain":
        model = PretrainNet(cfg.backbone, **cfg.model)
    else:
        model = build_model(cfg.variant, backbone=cfg.backbone, **cfg.model)
    if cfg.pretrained is not None:  # for pretrain: a later stage (new heads on the earlier backbone)
        backbone, meta = load_backbone_file(cfg.pretrained)
        if meta["backbone"] != cfg.backbone:
            raise ConfigError(f"{cfg.pretrained} is a {meta['backbone']}, the config asks for {cfg.backbone}")
        model.backbone.load_state_dict(backbone.state_dict())
    if cfg.task == "regressor":
        for p in model.backbone.parameters():
            p.requires_grad_(False)
        if cfg.trainable_from is not None:  # the last blocks adapt to the variant's loss
            for block in model.backbone.blocks_from(cfg.trainable_from):
                for p in block.parameters():
                    p.requires_grad_(True)
    return model


def check_data_root(cfg: TrainConfig) -> None:
    """A dataset folder the user named (``data.root``) must hold a finished, intact dataset: the kit
    makes and repairs data only in its own folders. Callers run it before they create anything; the
    shards' hashes are then known to this process and not computed again when the data are read.
    Raises :class:`~airpose_lib.data.still.manifest.DatasetError` (a damaged shard: ``ShardIntegrityError``),
    or :class:`~airpose_lib.errors.ConfigError` for a ``data:`` key the kit's datasets do not take."""
    check_options(cfg, ("data",))
    if cfg.data.get("root") is not None and cfg.data.get("source", "generated") == "generated":
        verify_dataset(Path(cfg.data["root"]))


def default_dataset_factory(cfg: TrainConfig, split: str):
    """``StillFrameDataset(cfg.data["root"], split, **other data keys)`` (after :func:`prepare_data`),
    or ``OfficialSyntheticDataset`` when ``cfg.data["source"] == "official_synthetic"``."""
    kwargs = {k: v for k, v in cfg.data.items() if k not in ("root", "profile", "source")}
    if cfg.data.get("root") is None:
        raise ValueError("cfg.data has no root; call prepare_data(cfg) first")
    if cfg.task == "regressor":
        crops = kwargs.pop("crops", "jittered")
        feats = ensure_features(cfg.pretrained, cfg.data["root"], split, crops, cut=cfg.trainable_from)
        return FeatureDataset(cfg.data["root"], split, feats, crops=crops, **kwargs)
    if cfg.data.get("source", "generated") == "official_synthetic":
        return OfficialSyntheticDataset(cfg.data["root"], split=split, **kwargs)
    return StillFrameDataset(cfg.data["root"], split=split, **kwargs)


def default_loss_factory(cfg: TrainConfig) -> nn.Module:
    """The variant's :class:`~airpose_lib.losses.SupervisedLoss` (``cfg.loss`` overrides), or the
    pretraining objective :class:`~airpose_lib.losses.pretrain.PretrainLoss` (task ``pretrain``)."""
    if cfg.task == "pretrain":
        return PretrainLoss(PretrainLossConfig(**cfg.loss), source=cfg.body_source)
    return SupervisedLoss(loss_config(cfg.variant, cfg.official_loss, **cfg.loss), source=cfg.body_source)


#: Range of the weak camera's scale where the losses turn it into a depth ``2 f s / (S s_w)`` (with
#: the cpu crops, a person between about 1.4 m and 140 m away). Just past zero the depth flips from
#: +inf to -inf, and a scale thrown up by one large step puts the body at the camera; either sends
#: the 2D term to 1e11 and wrecks the run (measured: a multi-view run at step 340). The scale guard
#: ``exp(-10 s_w)^2``, which sees the raw value, pushes s_w back above the floor.
MIN_WEAK_SCALE = 0.05
MAX_WEAK_SCALE = 5.0


@contextlib.contextmanager
def _float32(device: torch.device):
    """No autocast inside: the losses (body model, projections, depths from the weak camera) run in
    float32 whatever the network's precision; the network's outputs are cast up first."""
    with torch.autocast(device.type, enabled=False):
        yield


def _up(out: Mapping) -> dict:
    return {k: v.float() if isinstance(v, torch.Tensor) and v.is_floating_point() else v for k, v in out.items()}


def _supervised_terms(out: Mapping, loss_fn: nn.Module, batch: Mapping[str, torch.Tensor], input_size: int) -> dict:
    with _float32(batch["P"].device):
        return _supervised_terms_fp32(_up(out), loss_fn, batch, input_size)


def _supervised_terms_fp32(out: Mapping, loss_fn: nn.Module, batch: Mapping[str, torch.Tensor], input_size: int
                           ) -> dict:
    if "cam" in out:
        cam = out["cam"]
        out = dict(out, cam=torch.cat((cam[..., :1].clamp(MIN_WEAK_SCALE, MAX_WEAK_SCALE), cam[..., 1:]), dim=-1))
    pred = dict(to_smplx_params(out, batch["P"], batch["K"], input_size=input_size))
    pred["phi6d"], pred["theta6d"] = out["phi6d"], out["theta6d"]
    if "cam" in out:
        pred["cam"] = cam  # the raw scale, for the guard
    return loss_fn(pred, batch)


def forward_loss(model: nn.Module, loss_fn: nn.Module, batch: Mapping[str, torch.Tensor]) -> dict[str, torch.Tensor]:
    """Task ``supervised``: network forward on the crops, camera-frame parameters, loss terms
    (``"total"`` included)."""
    out = model(batch["images"], batch["P"])
    return _supervised_terms(out, loss_fn, batch, int(batch["images"].shape[-1]))


def regressor_forward_loss(model: nn.Module, loss_fn: nn.Module, batch: Mapping[str, torch.Tensor],
                           cut: str | None = None) -> dict:
    """Task ``regressor``: the variant's regressor on cached ``features (B, V, C)``; same terms.
    With ``cut`` (``TrainConfig.trainable_from``) the features are the input ``(B, V, C, h, w)``
    of that backbone block, and the blocks from it on run first."""
    net = _unwrap(model)
    feat = batch["features"] if cut is None else net.features_from(batch["features"], cut)
    out = net.regress(feat, batch["P"])
    return _supervised_terms(out, loss_fn, batch, int(batch["crop_size"][0]))


def pretrain_forward_loss(model: nn.Module, loss_fn: nn.Module, batch: Mapping[str, torch.Tensor]) -> dict:
    """Task ``pretrain``: the heads on every crop of the batch (views flattened)."""
    out = model(batch["images"].flatten(0, 1))
    with _float32(batch["images"].device):
        return loss_fn(_up(out), batch, _unwrap(model).n_heading_bins)


#: The step of each task (SPIN's ``train_step`` per task, one engine around them).
TASK_FORWARD: dict[str, Callable] = {"supervised": forward_loss, "regressor": regressor_forward_loss,
                                     "pretrain": pretrain_forward_loss}


def task_forward(cfg: TrainConfig) -> Callable:
    """The step of ``cfg.task`` (:data:`TASK_FORWARD`), bound to the config's feature cut."""
    if cfg.task == "regressor" and cfg.trainable_from is not None:
        return functools.partial(regressor_forward_loss, cut=cfg.trainable_from)
    return TASK_FORWARD[cfg.task]


def run_network_entry(config: Mapping[str, Any], dataset: Any) -> dict[str, Any]:
    """``{"network": record}`` for the checkpoints of a run (``{}`` for task ``pretrain``).

    Args:
        config: the run's ``TrainConfig.to_dict()``, its data resolved (``prepare_data``).
        dataset: the training split; its ``crop_size`` is the input size (the config's data,
            manifest or profile when it has none). The camera is the data's
            (:func:`airpose_lib.data.still.training_input.training_input`).
    """
    if config.get("task") == "pretrain":
        return {}
    size, K = training_input(config)
    size = getattr(dataset, "crop_size", None) or size
    if size is None:
        return {}  # a custom dataset nobody can size: readers ask for input_size, as before
    return {NETWORK_KEY: network_record(config["variant"], config["backbone"], config.get("model") or {},
                                        int(size), K)}


# -- results --------------------------------------------------------------------------------------
@dataclass
class TrainResult:
    """What a run ended with (also written to ``<out>/result.json``)."""

    out_dir: Path
    step: int
    checkpoint: Path | None
    train_loss: float | None = None
    val_losses: dict[str, float] | None = None
    tensorboard: bool = False
    stopped_early: bool = False
    config: dict = field(default_factory=dict)
    wall_s: float | None = None  # seconds of this call (a resumed run counts from its resume)
    # the kit's commit that ran this call (``eval.reference.git_commit``: ``commit``, ``dirty``);
    # a resumed run names the commit that finished it. None: not a git checkout, or an older run.
    git: dict | None = None
    # the precision this call computed in and why (``config["precision"]`` may say ``auto``)
    precision: dict | None = None

    def to_json(self) -> dict:
        return {"out_dir": str(self.out_dir), "step": self.step,
                "checkpoint": str(self.checkpoint) if self.checkpoint else None,
                "train_loss": self.train_loss, "val_losses": self.val_losses, "tensorboard": self.tensorboard,
                "stopped_early": self.stopped_early, "config": self.config, "wall_s": self.wall_s, "git": self.git,
                "precision": self.precision}

    @classmethod
    def from_json(cls, d: dict) -> "TrainResult":
        return cls(out_dir=Path(d["out_dir"]), step=d["step"],
                   checkpoint=Path(d["checkpoint"]) if d["checkpoint"] else None, train_loss=d["train_loss"],
                   val_losses=d["val_losses"], tensorboard=d["tensorboard"], stopped_early=d["stopped_early"],
                   config=d["config"], wall_s=d.get("wall_s"), git=d.get("git"), precision=d.get("precision"))


# -- entry point ----------------------------------------------------------------------------------
def start_training(cfg: TrainConfig, out: Path, resume: bool = True, *, model_factory: Callable | None = None,
                   dataset_factory: Callable | None = None, loss_factory: Callable | None = None,
                   stop_at: int | None = None) -> TrainResult:
    """Train ``cfg``, whose prerequisites are resolved (:func:`airpose_lib.train.run.prepare_data`),
    into ``out``: in this process, in torchrun's process group, or in ``cfg.world_size`` spawned
    processes. The arguments are :func:`airpose_lib.train.run.train`'s.

    Returns:
        :class:`TrainResult`.
    """
    factories = (model_factory or default_model_factory, dataset_factory or default_dataset_factory,
                 loss_factory or default_loss_factory)
    launch = launch_env()
    check_precision(cfg.precision, resolve_device(cfg.device, launch[1] if launch else 0))
    if launch is not None:  # torchrun: join the process group
        rank, local_rank, world = launch
        cfg = cfg.replace(world_size=world)
        if dist.is_initialized():
            return run_training(cfg, out, resume, *factories, stop_at=stop_at)
        device = resolve_device(cfg.device, local_rank)
        if device.type == "cuda":
            torch.cuda.set_device(device)  # before NCCL's first collective: one GPU per process
        dist.init_process_group(_backend(cfg, local_rank))
        try:
            return run_training(cfg, out, resume, *factories, stop_at=stop_at)
        finally:
            dist.destroy_process_group()
    if cfg.world_size > 1:
        for rank in range(cfg.world_size):  # every process's device exists, or one line before any starts
            resolve_device(cfg.device, rank)
        return _spawn(cfg, out, resume, factories, stop_at)
    return run_training(cfg, out, resume, *factories, stop_at=stop_at)


def _backend(cfg: TrainConfig, local_rank: int = 0) -> str:
    return "nccl" if resolve_device(cfg.device, local_rank).type == "cuda" else "gloo"


def _free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _spawn(cfg: TrainConfig, out: Path, resume: bool, factories: tuple, stop_at: int | None) -> TrainResult:
    import torch.multiprocessing as mp

    port = _free_port()
    mp.spawn(_ddp_entry, args=(cfg.world_size, port, cfg, str(out), resume, factories, stop_at),
             nprocs=cfg.world_size, join=True)
    return TrainResult.from_json(json.loads((out / "result.json").read_text()))


def _ddp_entry(rank: int, world: int, port: int, cfg: TrainConfig, out: str, resume: bool, factories: tuple,
               stop_at: int | None) -> None:
    os.environ.update(MASTER_ADDR="127.0.0.1", MASTER_PORT=str(port), RANK=str(rank), WORLD_SIZE=str(world),
                      LOCAL_RANK=str(rank))
    dist.init_process_group(_backend(cfg), rank=rank, world_size=world)
    try:
        run_training(cfg, Path(out), resume, *factories, stop_at=stop_at)
    finally:
        dist.destroy_process_group()


# -- the loop -------------------------------------------------------------------------------------
def _to_device(batch: Mapping, device: torch.device) -> dict:
    return {k: (v.to(device, non_blocking=True) if isinstance(v, torch.Tensor) else v) for k, v in batch.items()}


def _unwrap(model: nn.Module) -> nn.Module:
    return model.module if isinstance(model, nn.parallel.DistributedDataParallel) else model


def _set_train_mode(model: nn.Module, cfg: TrainConfig) -> None:
    model.train()
    if (cfg.freeze_backbone or cfg.task == "regressor") and hasattr(model, "backbone"):
        model.backbone.eval()  # frozen BatchNorm statistics (the regressor task's features were made so)


def _param_groups(model: nn.Module, cfg: TrainConfig) -> list[dict]:
    """The trainable parameters; the backbone's at ``cfg.backbone_lr_scale`` of the rate."""
    backbone = {id(p) for p in model.backbone.parameters()} if hasattr(model, "backbone") else set()
    params = [p for p in model.parameters() if p.requires_grad]
    rest = [p for p in params if id(p) not in backbone]
    trunk = [p for p in params if id(p) in backbone]
    if not trunk or cfg.backbone_lr_scale == 1.0:
        return [{"params": params}]  # one group: the optimiser state of earlier checkpoints still loads
    return [{"params": rest}, {"params": trunk, "lr_scale": cfg.backbone_lr_scale}]


def _check_resume(saved: dict, cfg: TrainConfig) -> None:
    now = cfg.to_dict()
    # a key added after the checkpoint was written compares with its default
    saved = {**{f.name: f.default for f in dataclasses.fields(TrainConfig) if f.name not in saved
                and f.default is not dataclasses.MISSING}, **saved}
    strip = lambda d: {k: v for k, v in (d or {}).items() if k != "root"}  # noqa: E731 - may move
    diff = [k for k in cfg.resume_keys()
            if (strip(saved.get(k)) != strip(now.get(k)) if k == "data" else saved.get(k) != now.get(k))]
    if diff:
        raise StaleRunError(diff)


def run_training(cfg: TrainConfig, out_dir: Path, resume: bool, model_factory: Callable,
                 dataset_factory: Callable, loss_factory: Callable, stop_at: int | None = None) -> TrainResult:
    """The loop itself, in this process (``torch.distributed`` initialised for DDP).

    Torch's process-wide settings it changes (thread count, deterministic algorithms) are
    restored on return.
    """
    saved = (torch.get_num_threads(), torch.are_deterministic_algorithms_enabled(),
             torch.is_deterministic_algorithms_warn_only_enabled())
    try:  # rank 0 is the run folder's one writer
        with run_folder(out_dir):
            return _run_training(cfg, out_dir, resume, model_factory, dataset_factory, loss_factory, stop_at)
    finally:
        torch.set_num_threads(saved[0])
        torch.use_deterministic_algorithms(saved[1], warn_only=saved[2])


def _share_weight(n_local: int, batch_size: int, world: int) -> float:
    """``n_r W / B``: the weight of a process's mean loss that makes DDP's average over the W
    processes the mean over the B samples of the global batch (1 for an even split)."""
    return n_local * world / batch_size


class StillFrameTask(TrainingTask):
    """The engine's task for the still-frame trainings (``supervised``, ``regressor``,
    ``pretrain``: the step of :data:`TASK_FORWARD`), one process of a DDP group or alone.

    Batches follow :class:`~airpose_lib.train.sampling.ResumableBatchSampler` (this process's
    share of each global batch); after the shared weight initialisation every process draws
    from its own stream (dropout).
    """

    def __init__(self, cfg: TrainConfig, model: nn.Module, loss_fn: nn.Module, train_ds, val_ds,
                 device: torch.device, rank: int, world: int, network: Mapping | None = None) -> None:
        # ``device`` also tells the engine where the autocast of ``cfg.precision`` applies
        self.cfg, self.model, self.loss_fn, self.device = cfg, model, loss_fn, device
        self.train_ds, self.val_ds, self.rank, self.world = train_ds, val_ds, rank, world
        self.network = dict(network or {})  # the checkpoints' network record (run_network_entry)
        self.optimizer = torch.optim.Adam(_param_groups(model, cfg), lr=cfg.lr, amsgrad=cfg.amsgrad,
                                          weight_decay=cfg.weight_decay)
        self.net: nn.Module = model  # the DDP wrapper once begun
        self.step_fn = task_forward(cfg)

    def batches(self, epoch: int, start: int):
        cfg = self.cfg
        sampler = ResumableBatchSampler(len(self.train_ds), cfg.batch_size, cfg.seed, epoch, start, self.rank,
                                        self.world)
        loader = DataLoader(SeededDataset(self.train_ds), batch_sampler=sampler, num_workers=cfg.num_workers,
                            worker_init_fn=worker_init_fn, pin_memory=self.device.type == "cuda",
                            generator=torch.Generator().manual_seed(_mix(cfg.seed, 3, epoch, self.rank)))
        for batch in loader:
            yield _to_device(batch, self.device)

    def train_step(self, batch: Mapping[str, torch.Tensor], step: int) -> dict[str, torch.Tensor]:
        lr = self.cfg.lr_at(step)  # a function of the step alone, so a resumed run follows it too
        for group in self.optimizer.param_groups:
            group["lr"] = lr * group.get("lr_scale", 1.0)
        terms = self.step_fn(self.net, self.loss_fn, batch)
        weight = _share_weight(int(batch["phi"].shape[0]), self.cfg.batch_size, self.world)
        return terms if weight == 1.0 else {k: v * weight for k, v in terms.items()}

    def train_mode(self) -> None:
        _set_train_mode(self.model, self.cfg)

    def start(self, run: EngineRun) -> None:
        seed_everything(_mix(self.cfg.seed, 2, self.rank))  # per-process stream (dropout) after the shared init

    def resume(self, state: Mapping) -> None:
        _check_resume(state["config"], self.cfg)

    def reseed(self, rank: int, step: int) -> None:
        seed_everything(_mix(self.cfg.seed, 2, rank, step))

    def begin(self, run: EngineRun) -> None:
        if run.distributed:
            self.net = nn.parallel.DistributedDataParallel(
                self.model, device_ids=[self.device] if self.device.type == "cuda" else None)
        n_train, cfg = len(self.train_ds), self.cfg
        if ResumableBatchSampler(n_train, cfg.batch_size, cfg.seed, 0).num_batches() == 0 and run.step < cfg.steps:
            raise ConfigError(f"training split has {n_train} samples, fewer than one batch of {cfg.batch_size}")

    def validate(self, run: EngineRun) -> dict[str, float] | None:
        if self.rank != 0 or self.val_ds is None or len(self.val_ds) == 0:
            return None
        result = validation_loss(self.model, self.loss_fn, self.val_ds, self.cfg, self.device)
        _set_train_mode(self.model, self.cfg)
        return result

    def checkpoint_state(self) -> dict:
        return {"config": self.cfg.to_dict(), "world_size": self.world, **self.network}

    def config(self) -> dict:
        return self.cfg.to_dict()


def _run_training(cfg: TrainConfig, out_dir: Path, resume: bool, model_factory: Callable,
                  dataset_factory: Callable, loss_factory: Callable, stop_at: int | None) -> TrainResult:
    rank, world = process_rank()
    if world != cfg.world_size:
        cfg = cfg.replace(world_size=world)
    local_rank = int(os.environ.get("LOCAL_RANK", rank)) if world > 1 else 0
    device = resolve_device(cfg.device, local_rank)
    if device.type == "cuda":
        torch.cuda.set_device(device)
    cfg = cfg.replace(device=str(device))  # what the run used, in config.json and the checkpoints
    threads = cfg.num_threads or (max(1, torch.get_num_threads() // world) if world > 1 else None)
    if threads:
        torch.set_num_threads(threads)
    if cfg.deterministic:
        if device.type == "cuda":  # cuBLAS is deterministic only with a fixed workspace (CUDA docs);
            os.environ.setdefault("CUBLAS_WORKSPACE_CONFIG", ":4096:8")  # read when cuBLAS starts
        torch.use_deterministic_algorithms(True, warn_only=True)
    out_dir = Path(out_dir)

    seed_everything(cfg.seed)
    model = model_factory(cfg).to(device)  # identical initial weights in every process
    if cfg.sync_batchnorm and world > 1:  # batch statistics over the global batch (same parameters)
        model = nn.SyncBatchNorm.convert_sync_batchnorm(model)
    if cfg.freeze_backbone and hasattr(model, "backbone"):
        for p in model.backbone.parameters():
            p.requires_grad_(False)
    loss_fn = loss_factory(cfg).to(device)
    train_ds = dataset_factory(cfg, cfg.train_split)
    val_ds = dataset_factory(cfg, cfg.val_split) if cfg.val_every is not None and rank == 0 else None
    network = run_network_entry(cfg.to_dict(), train_ds) if rank == 0 else {}
    task = StillFrameTask(cfg, model, loss_fn, train_ds, val_ds, device, rank, world, network)
    schedule = Schedule(steps=cfg.steps, log_every=cfg.log_every, checkpoint_every=cfg.checkpoint_every,
                        keep_checkpoints=cfg.keep_checkpoints, val_every=cfg.val_every, grad_clip=cfg.grad_clip,
                        stop_at=stop_at, what=f"train {cfg.variant}", progress=cfg.progress,
                        precision=cfg.precision)
    t_start = time.time()
    run = run_engine(task, schedule, out_dir, resume)
    result = TrainResult(out_dir=out_dir, step=run.step, checkpoint=run.checkpoint,
                         train_loss=run.values["total"] if run.values else None, val_losses=run.val,
                         tensorboard=run.tensorboard, stopped_early=run.stopped_early,
                         config=cfg.to_dict(), wall_s=round(time.time() - t_start, 1),
                         git=git_commit() if rank == 0 else None, precision=run.precision)
    if rank == 0:
        (out_dir / "result.json").write_text(json.dumps(result.to_json(), indent=2))
    return result


@torch.no_grad()
def validation_loss(model: nn.Module, loss_fn: nn.Module, dataset, cfg: TrainConfig,
                    device: torch.device | str = "cpu") -> dict[str, float]:
    """Mean loss terms over the validation split (first ``cfg.val_batches`` batches, in order).

    Eval mode, no augmentation randomness leaks out (samples seeded, RNG states restored).
    """
    model.eval()
    bs = cfg.val_batch_size or cfg.batch_size
    sampler = ResumableBatchSampler(len(dataset), bs, cfg.seed, epoch=0, drop_last=False, shuffle=False)
    loader = DataLoader(SeededDataset(dataset), batch_sampler=sampler, num_workers=cfg.num_workers,
                        worker_init_fn=worker_init_fn, generator=torch.Generator().manual_seed(cfg.seed))
    step = task_forward(cfg)
    sums: dict[str, float] = {}
    n = 0
    for b, batch in enumerate(loader):
        if cfg.val_batches is not None and b >= cfg.val_batches:
            break
        batch = _to_device(batch, device)
        terms = step(model, loss_fn, batch)
        k = batch["phi"].shape[0]
        for key, v in terms.items():
            sums[key] = sums.get(key, 0.0) + float(v) * k
        n += k
    return {key: v / max(n, 1) for key, v in sums.items()}
