"""Training: the still-frame trainings of every variant as tasks of the kit's engine
(:mod:`airpose_lib.engine`: deterministic, resumable, single process or DDP; atomic checkpoints,
CSV (+ TensorBoard) logs), the profile's ``train:`` section as configuration, and evaluation of
trained networks. The checkpoint and log functions are re-exported here from the engine."""

from airpose_lib.engine import RunLogger, kit_version, last_checkpoint, load_checkpoint, read_log, save_checkpoint

from .config import TrainConfig, TrainSection, load_train_config, train_section
from .evaluate import evaluate, evaluate_checkpoint, load_trained_model, predict
from .loop import (
    TrainResult,
    default_dataset_factory,
    default_loss_factory,
    default_model_factory,
    forward_loss,
    run_training,
    validation_loss,
)
from .run import TrainInputs, prepare_data, train
from .sampling import ResumableBatchSampler, SeededDataset, epoch_permutation, sample_seed, seed_everything

__all__ = [
    "train", "run_training", "TrainResult", "TrainConfig", "TrainSection", "TrainInputs", "load_train_config",
    "train_section", "prepare_data",
    "default_model_factory", "default_dataset_factory", "default_loss_factory", "forward_loss",
    "validation_loss", "save_checkpoint", "load_checkpoint", "last_checkpoint", "kit_version",
    "RunLogger", "read_log", "ResumableBatchSampler", "SeededDataset", "epoch_permutation", "sample_seed",
    "seed_everything", "predict", "evaluate", "load_trained_model", "evaluate_checkpoint",
]
