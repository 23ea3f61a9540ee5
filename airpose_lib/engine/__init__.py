"""The training engine: one resumable loop (:func:`run_engine`) with a task per training, atomic
checkpoints that carry every process's RNG states, and the CSV (+ TensorBoard) run log.

The lowest training layer: it imports nothing of the kit but ``folder_lock``, ``progress``,
``errors`` and the atomic writer, so ``train``, ``finetune`` and ``prior`` all build on it."""

from .checkpoint import (
    AFRESH_HINT,
    FORMAT_VERSION,
    StaleRunError,
    capture_rng_state,
    checkpoint_dir,
    kit_version,
    last_checkpoint,
    load_checkpoint,
    restore_rng_state,
    save_checkpoint,
    write_checkpoint,
)
from .logger import RunLogger, read_log
from .loop import EngineResult, EngineRun, Schedule, TrainingTask, process_rank, run_engine, run_folder

__all__ = [
    "run_engine", "run_folder", "process_rank", "Schedule", "TrainingTask", "EngineRun", "EngineResult",
    "AFRESH_HINT", "FORMAT_VERSION", "StaleRunError", "kit_version", "capture_rng_state", "restore_rng_state",
    "save_checkpoint", "write_checkpoint", "load_checkpoint", "checkpoint_dir", "last_checkpoint", "RunLogger", "read_log",
]
