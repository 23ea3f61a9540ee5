"""Checkpoints: written atomically, complete enough to resume a run bit for bit.

A checkpoint (``torch.save`` dict, loadable with ``weights_only=True``) holds

``model``        the unwrapped model's ``state_dict``
``optimizer``    the optimiser's ``state_dict``
``rng``          per process: torch CPU (and CUDA), numpy and python RNG states
``step``         optimiser steps done; ``epoch`` and ``batch_in_epoch``: the data-order position
``format_version``, ``kit_version``

and the task's own entries (:meth:`airpose_lib.engine.TrainingTask.checkpoint_state`): the
still-frame trainings add ``config`` (the ``TrainConfig`` as a dict), ``world_size`` and
``network`` (what rebuilds the network and forms its input, :mod:`airpose_lib.model.record`:
variant, backbone, input size, normalisation, camera rule and camera; not for the backbone
pretraining, whose network is not a variant); fine-tuning also ``input_size``, ``camera_K`` and
``finetune``.

``<out>/checkpoints/last.pt`` is always the newest; ``step_<n>.pt`` copies are kept as configured.
"""

from __future__ import annotations

import random
from pathlib import Path
from typing import Any

import numpy as np
import torch

from airpose_lib import __version__  # the package root holds only the version
from airpose_lib.atomic import atomic_torch_save
from airpose_lib.errors import DamagedFileError, UserError, reading

__all__ = [
    "StaleRunError",
    "AFRESH_HINT",
    "kit_version",
    "capture_rng_state",
    "restore_rng_state",
    "write_checkpoint",
    "save_checkpoint",
    "load_checkpoint",
    "checkpoint_dir",
    "last_checkpoint",
]

FORMAT_VERSION = 1


#: The two ways out of a run folder that cannot be resumed, for a command-line and a Python user.
AFRESH_HINT = ("start afresh in it (`--no-resume`; resume=False in Python) or choose another folder "
               "(`--out`; out_dir=)")


class StaleRunError(UserError, ValueError):
    """A run folder's checkpoint was made with other settings (``fields``) than asked for now, so
    it cannot be resumed (raised by the trainings' resume checks, caught by callers that may
    start such a run afresh)."""

    def __init__(self, fields: list[str], made: str = "trained"):
        self.fields = fields
        super().__init__(f"cannot resume: the checkpoint was {made} with different {', '.join(fields)}; "
                         f"{AFRESH_HINT}")


def kit_version() -> str:
    """The kit's version recorded in checkpoints: :data:`airpose_lib.__version__`, its one home
    (the version of the code that runs, also when the kit is used from a checkout without being
    installed; pyproject.toml reads the installed version from the same attribute)."""
    return __version__


def capture_rng_state() -> dict[str, Any]:
    """This process's RNG states as plain types and tensors (``weights_only``-loadable)."""
    kind, keys, pos, has_gauss, gauss = np.random.get_state()
    version, internal, py_gauss = random.getstate()
    state: dict[str, Any] = {
        "torch": torch.get_rng_state(),
        "numpy": {"kind": kind, "keys": torch.from_numpy(keys.astype(np.int64)), "pos": int(pos),
                  "has_gauss": int(has_gauss), "gauss": float(gauss)},
        "python": {"version": version, "internal": list(internal), "gauss": py_gauss},
    }
    if torch.cuda.is_available() and torch.cuda.is_initialized():
        state["cuda"] = torch.cuda.get_rng_state_all()
    return state


def restore_rng_state(state: dict[str, Any]) -> None:
    """Inverse of :func:`capture_rng_state`."""
    torch.set_rng_state(state["torch"])
    n = state["numpy"]
    np.random.set_state((n["kind"], n["keys"].numpy().astype(np.uint32), n["pos"], n["has_gauss"], n["gauss"]))
    p = state["python"]
    random.setstate((p["version"], tuple(p["internal"]), p["gauss"]))
    if "cuda" in state and torch.cuda.is_available():
        _restore_cuda_rng(list(state["cuda"]))


def _restore_cuda_rng(states: list) -> None:
    """One saved state per GPU that was visible then, restored onto the GPUs visible now: the
    common ones in order. A process that trains on one GPU (``cuda:<local_rank>``) draws only from
    that GPU's stream, which keeps its index when a resumed job sees fewer or more GPUs only if the
    job keeps its ``CUDA_VISIBLE_DEVICES`` order; the others are re-seeded by torch as usual."""
    for index in range(min(len(states), torch.cuda.device_count())):
        torch.cuda.set_rng_state(states[index], index)


def checkpoint_dir(out_dir: str | Path) -> Path:
    return Path(out_dir) / "checkpoints"


def last_checkpoint(out_dir: str | Path) -> Path | None:
    """``<out>/checkpoints/last.pt`` if it exists."""
    p = checkpoint_dir(out_dir) / "last.pt"
    return p if p.is_file() else None


def write_checkpoint(path: str | Path, state: dict[str, Any]) -> Path:
    """Write ``state`` with the format's ``format_version`` and ``kit_version`` in front as one
    checkpoint file ``path`` (atomically): every kit checkpoint is written here (the engine's
    ``last.pt`` and ``step_<n>.pt``, fine-tuning's ``best.pt``, converted official weights).

    Returns:
        ``path``.
    """
    path = Path(path)
    return atomic_torch_save({"format_version": FORMAT_VERSION, "kit_version": kit_version(), **state}, path)


def save_checkpoint(out_dir: str | Path, state: dict[str, Any], keep: int = 2) -> Path:
    """Write ``state`` as ``last.pt`` and ``step_<step>.pt`` (:func:`write_checkpoint`), prune old
    step files.

    Returns:
        the path of ``last.pt``.
    """
    folder = checkpoint_dir(out_dir)
    last = write_checkpoint(folder / "last.pt", state)
    if keep > 0:
        write_checkpoint(folder / f"step_{state['step']:08d}.pt", state)
        numbered = sorted(folder.glob("step_*.pt"))
        for old in numbered[:-keep]:
            old.unlink(missing_ok=True)
    return last


def load_checkpoint(path: str | Path, map_location: str | torch.device = "cpu") -> dict[str, Any]:
    """Load a checkpoint written by :func:`save_checkpoint`."""
    with reading(path, "a checkpoint of `airpose train` or `airpose finetune`",
                 "use another checkpoint (e.g. the newest checkpoints/step_*.pt) or train again"):
        state = torch.load(Path(path), map_location=map_location, weights_only=True)
    if not isinstance(state, dict) or state.get("format_version") != FORMAT_VERSION:
        found = state.get("format_version") if isinstance(state, dict) else type(state).__name__
        raise DamagedFileError(path, "a checkpoint of `airpose train` or `airpose finetune`",
                               f"its format is {found!r}, this kit reads {FORMAT_VERSION}; use a checkpoint of "
                               "this kit version or train again")
    return state
