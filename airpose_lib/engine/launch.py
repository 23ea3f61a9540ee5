"""Where a training process stands: its rank among the processes, its device, its precision.

Three launches are recognised: a single process; ``torchrun`` (or ``python -m
torch.distributed.run``), which starts one process per GPU and tells each its place through the
environment (``RANK``, ``WORLD_SIZE``, ``LOCAL_RANK``: rank on this node, which picks the GPU);
and the kit's own ``torch.multiprocessing`` spawn, which sets the same variables. Before the
process group exists the environment is the only source; once it exists the group is.

:func:`single_process` marks work that every process does alone (building a prerequisite: the
dataset, the pretrained backbone, the feature cache): inside it a process counts as rank 0 of 1
whatever the environment says, so a nested training there neither joins the group nor waits for
the other ranks (otherwise rank 0 pretrains inside the group while rank 1 waits on the
backbone's file lock: a deadlock).

Precision (:data:`PRECISIONS`): ``fp32``; ``bf16`` (``torch.autocast`` with bfloat16, on CPU and
CUDA); ``fp16`` (autocast with float16 and a ``GradScaler``, CUDA only: CPU float16 kernels are
slow or missing and there is no CPU loss scaling in the kit, so it is refused with a one-line
error rather than silently mapped to bf16).
"""
from __future__ import annotations

import contextlib
import contextvars
import os

import torch
import torch.distributed as dist

from airpose_lib.devices import resolve_device
from airpose_lib.errors import ConfigError

__all__ = ["PRECISIONS", "launch_env", "single_process", "process_rank", "is_distributed", "resolve_device",
           "check_precision", "autocast", "grad_scaler"]

#: ``precision`` -> autocast dtype (None: plain float32).
PRECISIONS = {"fp32": None, "bf16": torch.bfloat16, "fp16": torch.float16}

_ALONE = contextvars.ContextVar("airpose_single_process", default=False)


@contextlib.contextmanager
def single_process():
    """Inside: this process is rank 0 of 1 (a prerequisite built alone, see the module docstring)."""
    token = _ALONE.set(True)
    try:
        yield
    finally:
        _ALONE.reset(token)


def launch_env() -> tuple[int, int, int] | None:
    """``(rank, local_rank, world_size)`` from ``torchrun``'s environment, None when not launched
    so (or inside :func:`single_process`). ``LOCAL_RANK`` defaults to ``RANK`` (one node)."""
    if _ALONE.get() or "RANK" not in os.environ or "WORLD_SIZE" not in os.environ:
        return None
    rank, world = int(os.environ["RANK"]), int(os.environ["WORLD_SIZE"])
    return rank, int(os.environ.get("LOCAL_RANK", rank)), world


def is_distributed() -> bool:
    """A process group exists and this process takes part in it (not inside :func:`single_process`)."""
    return not _ALONE.get() and dist.is_available() and dist.is_initialized()


def process_rank() -> tuple[int, int]:
    """``(rank, world_size)`` of this process: the process group's, else the launch environment's
    (so that only rank 0 takes a run folder's lock before the group exists), else ``(0, 1)``."""
    if is_distributed():
        return dist.get_rank(), dist.get_world_size()
    env = launch_env()
    return (env[0], env[2]) if env is not None else (0, 1)


def check_precision(precision: str, device: torch.device | str) -> None:
    """Raise ``ConfigError`` for an unknown precision or fp16 off CUDA (see the module docstring)."""
    if precision not in PRECISIONS:
        raise ConfigError(f"precision must be one of {sorted(PRECISIONS)}, got {precision!r}")
    if precision == "fp16" and torch.device(device).type != "cuda":
        raise ConfigError(f"precision fp16 needs a CUDA device (it trains with loss scaling there), not "
                         f"{device}; use precision=bf16 on CPU")


def autocast(precision: str, device: torch.device | str):
    """``torch.autocast`` of ``precision`` on ``device``'s type (a no-op context for fp32)."""
    dtype = PRECISIONS[precision]
    if dtype is None:
        return contextlib.nullcontext()
    return torch.autocast(torch.device(device).type, dtype=dtype)


def grad_scaler(precision: str, device: torch.device | str) -> "torch.amp.GradScaler | None":
    """The loss scaler of fp16 training (None otherwise: bf16 has float32's exponent range)."""
    if precision != "fp16":
        return None
    return torch.amp.GradScaler(torch.device(device).type)
