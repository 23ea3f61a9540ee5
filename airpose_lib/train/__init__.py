"""Training: one deterministic, resumable loop (single process or DDP) for every variant, the
profile's ``train:`` section as configuration, atomic checkpoints, CSV (+ TensorBoard) logs, and
evaluation of trained networks."""

from .checkpoint import kit_version, last_checkpoint, load_checkpoint, save_checkpoint
from .config import TrainConfig, load_train_config
from .evaluate import evaluate, evaluate_checkpoint, load_trained_model, predict
from .logger import RunLogger, read_log
from .loop import (
    TrainResult,
    default_dataset_factory,
    default_loss_factory,
    default_model_factory,
    default_out_dir,
    prepare_data,
    forward_loss,
    run_training,
    train,
    validation_loss,
)
from .sampling import ResumableBatchSampler, SeededDataset, epoch_permutation, sample_seed, seed_everything

__all__ = [
    "train", "run_training", "TrainResult", "TrainConfig", "load_train_config", "default_out_dir", "prepare_data",
    "default_model_factory", "default_dataset_factory", "default_loss_factory", "forward_loss",
    "validation_loss", "save_checkpoint", "load_checkpoint", "last_checkpoint", "kit_version",
    "RunLogger", "read_log", "ResumableBatchSampler", "SeededDataset", "epoch_permutation", "sample_seed",
    "seed_everything", "predict", "evaluate", "load_trained_model", "evaluate_checkpoint",
]
