"""The one training loop of the kit; every training (supervised, fine-tuning, prior) is a task of it.

After SPIN's ``utils/base_trainer.py``: :func:`run_engine` owns what all trainings share -- the
exclusive run folder, resume from ``<out>/checkpoints/last.pt``, the step counter and data
position, the optimiser update, atomic checkpoints (with every process's RNG states), the CSV
log, validation every N steps, the progress bar and the stop at N steps -- and a
:class:`TrainingTask` supplies what differs: its batches, its ``train_step`` (forward and loss
terms), its validation, and its own checkpoint entries.

Order within one optimiser step ``s`` (1-based, counted after the update):

1. ``terms = task.train_step(batch, s - 1)`` (under ``torch.autocast`` for ``bf16``/``fp16``
   precision, :mod:`.launch`); ``zero_grad``, ``terms["total"].backward()`` (scaled by a
   ``GradScaler`` for fp16, whose state the checkpoints carry), optional gradient clipping,
   ``optimizer.step()``;
2. the terms as floats (averaged over processes under DDP); a non-finite total raises;
3. a ``train`` row in ``log.csv`` every ``log_every`` steps and at the last one; the progress bar;
4. validation at its steps (``val_every``; also at the last step), before the checkpoint so that a
   task may keep the result in it (fine-tuning's model selection does); validation must leave
   the RNG states and the weights as it found them;
5. a checkpoint every ``checkpoint_every`` steps, at the last step and at ``stop_at``.

The engine draws no random numbers itself: a task seeds its streams in :meth:`TrainingTask.start`
and the engine saves and restores the global RNG states with the checkpoints, so a run resumed from
its last checkpoint ends with exactly the weights of an uninterrupted one. An interruption loses
the steps since the last checkpoint; nothing is written on the way out.

Without a run folder (``out_dir=None``) the same loop runs in memory: no lock, checkpoints or
CSV, only the task's own log hook (the prior's training, whose result is one saved model).

This package sits at the bottom of the kit (it imports only ``folder_lock``, ``progress``,
``errors`` and the atomic writer), so every training package may use it: ``prior`` lies below
``train`` (``fitting`` and ``finetune`` import it, and ``finetune`` is ``train`` with the 2D
losses), so the engine cannot live in ``train``.
"""
from __future__ import annotations

import contextlib
import json
import math
import time
import warnings
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import torch
import torch.distributed as dist
from torch import nn

from airpose_lib.folder_lock import folder_lock
from airpose_lib.progress import progress_bar

from .checkpoint import (
    capture_rng_state,
    checkpoint_dir,
    last_checkpoint,
    load_checkpoint,
    restore_rng_state,
    save_checkpoint,
)
from .launch import autocast, grad_scaler, is_distributed, process_rank, resolve_precision
from .logger import RunLogger

__all__ = ["Schedule", "TrainingTask", "EngineRun", "EngineResult", "run_engine", "run_folder", "process_rank"]


@dataclass(frozen=True)
class Schedule:
    """When the engine does what (steps are 1-based optimiser steps).

    Attributes:
        steps: optimiser steps in total.
        log_every: a ``train`` row (and the task's :meth:`~TrainingTask.on_log`) every this many
            steps and at the last one.
        log_offset: rows at steps ``log_offset + k * log_every`` (1: steps 1, 1 + N, ...).
        checkpoint_every: a checkpoint every this many steps (with a run folder).
        keep_checkpoints: numbered ``step_<n>.pt`` copies kept besides ``last.pt``.
        val_every: validation every this many steps and at the last one; 0: only at the last
            step; None: never.
        grad_clip: clip the gradients' global norm to this (None: no clipping).
        stop_at: stop (with a checkpoint) once this step is reached, as if interrupted there.
        checkpoint_at_end: leave a checkpoint even when no step ran (``steps == 0``).
        check_finite: raise ``FloatingPointError`` on a non-finite total loss.
        loss_name: how that error names the loss.
        what: how messages and the progress bar name the run (``train baseline``).
        progress: show a progress bar (rank 0 only).
        progress_kwargs: extra ``progress_bar`` arguments (``unit``).
        tensorboard: also write TensorBoard events next to the CSV when available.
        precision: ``auto``, ``fp32``, ``bf16`` or ``fp16`` (:func:`.launch.resolve_precision`): the
            autocast of ``train_step`` on the task's ``device`` (validation is the task's own business).
    """

    steps: int
    log_every: int = 10
    log_offset: int = 0
    checkpoint_every: int = 100
    keep_checkpoints: int = 2
    val_every: int | None = None
    grad_clip: float | None = None
    stop_at: int | None = None
    checkpoint_at_end: bool = False
    check_finite: bool = True
    loss_name: str = "loss"
    what: str = "train"
    progress: bool = False
    progress_kwargs: Mapping[str, Any] | None = None
    tensorboard: bool = True
    precision: str = "fp32"

    def logs_at(self, step: int) -> bool:
        return (step - self.log_offset) % self.log_every == 0 or step == self.steps

    def validates_at(self, step: int) -> bool:
        return self.val_every is not None and ((self.val_every and step % self.val_every == 0)
                                               or step >= self.steps)

    def checkpoints_at(self, step: int, stopped: bool) -> bool:
        return step % self.checkpoint_every == 0 or step >= self.steps or stopped


class TrainingTask:
    """What one kind of training adds to the engine (SPIN's ``train_step`` and friends).

    A task holds ``model`` (the unwrapped network whose ``state_dict`` is checkpointed),
    ``optimizer`` and, when it trains off the CPU or in reduced precision, ``device`` (where the
    autocast of :attr:`Schedule.precision` applies; CPU when absent). Hooks that receive ``run`` get the :class:`EngineRun` (step counter, data
    position, :meth:`EngineRun.checkpoint_state`).
    """

    model: nn.Module
    optimizer: torch.optim.Optimizer

    def batches(self, epoch: int, start: int) -> Iterable[Any]:
        """The batches of ``epoch`` from its ``start``-th on (the resume position)."""
        raise NotImplementedError

    def train_step(self, batch: Any, step: int) -> Mapping[str, torch.Tensor]:
        """Forward and loss terms of one batch (``"total"`` is optimised); ``step``: steps done."""
        raise NotImplementedError

    def train_mode(self) -> None:
        """Put the modules in training mode (the loop starts with it)."""
        self.model.train()

    def start(self, run: "EngineRun") -> None:
        """A fresh run (nothing resumed): seed the task's random streams, initial measurements."""

    def resume(self, state: Mapping[str, Any]) -> None:
        """Check that checkpoint ``state`` belongs to this run (raise ``ValueError`` if not) and
        take the task's own entries from it; the engine restores the rest."""

    def reseed(self, rank: int, step: int) -> None:
        """The checkpoint was written by another number of processes: new RNG streams."""

    def begin(self, run: "EngineRun") -> None:
        """Last preparation before the first step (e.g. the DDP wrapper, a data check)."""

    def validate(self, run: "EngineRun") -> dict[str, float] | None:
        """Validation at its steps; returned values become a ``val`` row of the log."""
        return None

    def checkpoint_state(self) -> dict[str, Any]:
        """The task's entries of a checkpoint (after ``model`` ... ``batch_in_epoch``)."""
        return {}

    def config(self) -> dict | None:
        """Written to ``<out>/config.json`` (None: no file)."""
        return None

    def on_log(self, step: int, values: Mapping[str, float]) -> None:
        """A ``train`` row's values (besides the CSV)."""


@dataclass
class EngineResult:
    """How the loop ended."""

    step: int
    epoch: int
    checkpoint: Path | None
    values: dict[str, float] | None  # the last step's loss terms
    val: dict[str, float] | None  # the last validation's values
    stopped_early: bool
    resumed: bool
    tensorboard: bool
    precision: dict | None = None  # ``used`` (fp32, bf16, fp16) and the ``reason`` it was chosen


def run_folder(out_dir: str | Path | None):
    """The run folder's exclusive lock (rank 0 is its one writer, also under ``torchrun`` before
    the process group exists: :func:`.launch.process_rank`; nothing without a folder). Re-entrant: hold it around a task's set-up too, which may write there (feature caches)."""
    if out_dir is None or process_rank()[0] != 0:
        return contextlib.nullcontext()
    return folder_lock(out_dir)


class EngineRun:
    """The loop's state: step counter, data position, the checkpoint writer."""

    def __init__(self, task: TrainingTask, schedule: Schedule, out_dir: Path | None) -> None:
        self.task, self.schedule, self.out_dir = task, schedule, out_dir
        self.rank, self.world = process_rank()
        self.distributed = is_distributed()
        self.step = self.epoch = self.batch_in_epoch = 0
        self.device = torch.device(getattr(task, "device", "cpu"))
        self.precision, self.precision_reason = resolve_precision(schedule.precision, self.device)
        self.scaler = grad_scaler(self.precision, self.device)

    def checkpoint_state(self) -> dict[str, Any]:
        """The checkpoint of now: ``model, optimizer, rng`` (one entry per process), ``step,
        epoch, batch_in_epoch``, ``scaler`` (fp16 only), then the task's entries. Collective under DDP."""
        rng = capture_rng_state()
        if self.distributed:
            all_rng: list = [None] * self.world
            dist.all_gather_object(all_rng, rng)
        else:
            all_rng = [rng]
        scaler = {"scaler": self.scaler.state_dict()} if self.scaler is not None else {}
        return {"model": self.task.model.state_dict(), "optimizer": self.task.optimizer.state_dict(),
                "rng": all_rng, "step": self.step, "epoch": self.epoch, "batch_in_epoch": self.batch_in_epoch,
                **scaler, **self.task.checkpoint_state()}

    def save(self) -> Path | None:
        state = self.checkpoint_state()
        path = None
        if self.rank == 0:
            path = save_checkpoint(self.out_dir, state, keep=self.schedule.keep_checkpoints)
        self.barrier()
        return path

    def barrier(self) -> None:
        if self.distributed:
            dist.barrier()

    def resume_or_start(self, resume: bool) -> Path | None:
        """Continue from ``last.pt`` (returned) or start afresh, deleting older checkpoints."""
        ckpt = last_checkpoint(self.out_dir) if resume and self.out_dir is not None else None
        if ckpt is not None:
            state = load_checkpoint(ckpt, map_location="cpu")
            self.task.resume(state)
            self.task.model.load_state_dict(state["model"])
            self.task.optimizer.load_state_dict(state["optimizer"])
            self.step, self.epoch, self.batch_in_epoch = state["step"], state["epoch"], state["batch_in_epoch"]
            if self.scaler is not None and "scaler" in state:
                self.scaler.load_state_dict(state["scaler"])
            if len(state["rng"]) == self.world:
                restore_rng_state(state["rng"][self.rank])
            else:
                warnings.warn(f"checkpoint written by {len(state['rng'])} process(es), resuming with {self.world}: "
                              "RNG streams are re-seeded, the run will not match an uninterrupted one", stacklevel=2)
                self.task.reseed(self.rank, self.step)
        else:
            if self.out_dir is not None and self.rank == 0:
                for old in checkpoint_dir(self.out_dir).glob("*.pt"):
                    old.unlink()
            self.task.start(self)
        self.barrier()
        return ckpt

    def values(self, terms: Mapping[str, torch.Tensor]) -> dict[str, float]:
        """The terms as floats, averaged over processes under DDP."""
        if not self.distributed:
            return {k: float(v.detach()) for k, v in terms.items()}
        stacked = torch.stack([v.detach().float() for v in terms.values()])
        dist.all_reduce(stacked)
        stacked /= self.world
        return dict(zip(terms.keys(), stacked.tolist()))


def _update(optimizer: torch.optim.Optimizer, model: nn.Module, total: torch.Tensor, grad_clip: float | None,
            scaler: "torch.amp.GradScaler | None") -> None:
    """Backward and optimiser step; with a loss scaler the gradients are unscaled before clipping
    (the clip is a norm of the true gradients) and a step with inf/nan gradients is skipped."""
    if scaler is None:
        total.backward()
        if grad_clip is not None:
            nn.utils.clip_grad_norm_(model.parameters(), grad_clip)
        optimizer.step()
        return
    scaler.scale(total).backward()
    if grad_clip is not None:
        scaler.unscale_(optimizer)
        nn.utils.clip_grad_norm_(model.parameters(), grad_clip)
    scaler.step(optimizer)
    scaler.update()


def run_engine(task: TrainingTask, schedule: Schedule, out_dir: str | Path | None = None, resume: bool = True,
               started: float | None = None) -> EngineResult:
    """Run ``task`` to ``schedule.steps`` (or ``schedule.stop_at``).

    Args:
        task: the training's :class:`TrainingTask`, its model and optimiser built.
        schedule: steps, cadences, stop.
        out_dir: run folder (``config.json``, ``log.csv``, ``checkpoints/``); None: in memory.
        resume: continue from ``<out_dir>/checkpoints/last.pt`` if present; otherwise (or with
            False) start afresh, deleting earlier checkpoints there.
        started: ``time.time()`` the log's ``time_s`` counts from (default: the first step).

    Returns:
        :class:`EngineResult`.
    """
    out = Path(out_dir) if out_dir is not None else None
    with run_folder(out):
        return _run(task, schedule, out, resume, started)


def _run(task: TrainingTask, schedule: Schedule, out: Path | None, resume: bool, started: float | None
         ) -> EngineResult:
    run = EngineRun(task, schedule, out)
    resumed_from = run.resume_or_start(resume)
    logger = None
    if out is not None and run.rank == 0:
        out.mkdir(parents=True, exist_ok=True)
        config = task.config()
        if config is not None:
            (out / "config.json").write_text(json.dumps(config, indent=2, sort_keys=True))
        logger = RunLogger(out, resume_step=run.step if resumed_from is not None else None,
                           tensorboard=schedule.tensorboard)
    if run.rank == 0 and out is not None:  # what auto picked, in the run's output
        print(f"{schedule.what}: precision {run.precision} ({run.precision_reason})", flush=True)
    bar = progress_bar(total=schedule.steps, initial=run.step, enabled=schedule.progress and run.rank == 0,
                       desc=schedule.what, **dict(schedule.progress_kwargs or {}))
    t_start = time.time() if started is None else started
    values: dict[str, float] | None = None
    val: dict[str, float] | None = None
    checkpoint = resumed_from
    stopped = False
    try:
        task.train_mode()
        task.begin(run)
        while run.step < schedule.steps and not stopped:
            for batch in task.batches(run.epoch, run.batch_in_epoch):
                with autocast(run.precision, run.device):
                    terms = task.train_step(batch, run.step)
                task.optimizer.zero_grad(set_to_none=True)
                _update(task.optimizer, task.model, terms["total"], schedule.grad_clip, run.scaler)
                run.step += 1
                run.batch_in_epoch += 1
                step = run.step

                values = run.values(terms)
                if schedule.check_finite and not math.isfinite(values["total"]):
                    raise FloatingPointError(f"non-finite {schedule.loss_name} at step {step}: {values}")
                if run.rank == 0:
                    if schedule.logs_at(step):
                        if logger is not None:
                            logger.log(step, run.epoch, "train", time.time() - t_start,
                                       task.optimizer.param_groups[0]["lr"], values)
                        task.on_log(step, values)
                    bar.update(1)
                    bar.set_postfix(loss=f"{values['total']:.4g}")
                done = step >= schedule.steps
                stopped = schedule.stop_at is not None and step >= schedule.stop_at and not done
                if schedule.validates_at(step):
                    result = task.validate(run)
                    if result:  # None or empty: nothing measured
                        val = result
                        if logger is not None:
                            logger.log(step, run.epoch, "val", time.time() - t_start,
                                       task.optimizer.param_groups[0]["lr"], result)
                    run.barrier()
                if out is not None and schedule.checkpoints_at(step, stopped):
                    checkpoint = run.save() or checkpoint
                if done or stopped:
                    break
            else:  # the epoch ran out
                run.epoch += 1
                run.batch_in_epoch = 0
        if out is not None and checkpoint is None and schedule.checkpoint_at_end:
            checkpoint = run.save()
    finally:
        bar.close()
        if logger is not None:
            logger.close()
    return EngineResult(step=run.step, epoch=run.epoch, checkpoint=checkpoint, values=values, val=val,
                        stopped_early=stopped, resumed=resumed_from is not None,
                        tensorboard=bool(logger and logger.tensorboard),
                        precision={"used": run.precision, "reason": run.precision_reason})
