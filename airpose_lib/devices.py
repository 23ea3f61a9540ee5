"""Which torch device a process, a worker or a fit runs on: the one rule of the kit.

``auto`` means the process's own GPU when CUDA is available, else the CPU; ``cuda`` (no index)
the process's own GPU; ``cuda:N``, ``cpu``, ``mps`` as given. A process's own GPU is
``cuda:<local_rank>`` under ``torchrun`` (:mod:`airpose_lib.engine.launch`) and
``cuda:<k mod GPUs>`` for the k-th parallel worker of the ablation runner (:func:`worker_device`).

A helper every package may use (``fitting`` and ``prior`` may not import ``engine``); torch is
imported inside the functions so that importing the helpers stays free of torch (the CLI's parser).
"""
from __future__ import annotations

from airpose_lib.errors import ConfigError

__all__ = ["PRECISION_CHOICES", "is_device_name", "resolve_device", "worker_device"]

#: What a training config may say for its precision (resolved by ``engine.launch.resolve_precision``).
PRECISION_CHOICES = ("auto", "fp32", "bf16", "fp16")


def is_device_name(device: str) -> bool:
    """``auto`` or a string torch reads as a device: what a config may say. Whether this machine has
    it is :func:`resolve_device`'s question, asked when a run starts (a config read from a checkpoint
    trained on a GPU stays valid on a CPU)."""
    import torch

    try:
        return device == "auto" or torch.device(device) is not None
    except (RuntimeError, TypeError):
        return False


def resolve_device(device: str, local_rank: int = 0) -> "torch.device":  # noqa: F821
    """The device of the process with ``local_rank`` on its node (rules: the module docstring).

    Raises:
        ConfigError: not a device string, or a CUDA device that this torch or machine does not have
            (one line: what was asked, what there is, the fix).
    """
    import torch  # here, not at module level: see the module docstring

    if device == "auto":
        if not torch.cuda.is_available():
            return torch.device("cpu")
        device = "cuda"  # the process's own GPU, which must exist (below)
    try:
        dev = torch.device(device)
    except (RuntimeError, TypeError):
        raise ConfigError(f"device {device!r} is not a device; use auto, cpu, cuda or cuda:N") from None
    if dev.type == "cuda":
        if not torch.cuda.is_available():
            build = "a CPU-only torch" if torch.version.cuda is None else "no visible GPU"
            raise ConfigError(f"device {device!r} asked for, but this machine has {build} "
                              f"(torch {torch.__version__}); use --device cpu, or install a CUDA build of torch")
        if dev.index is None:
            dev = torch.device(f"cuda:{local_rank}")
            if dev.index >= torch.cuda.device_count():  # more processes on this node than GPUs
                raise ConfigError(f"the process of local rank {local_rank} would train on {dev}, but only "
                                  f"{torch.cuda.device_count()} GPU(s) are visible: start at most that many "
                                  "processes per node (--world-size, torchrun --nproc_per_node), or use --device cpu")
        if dev.index >= torch.cuda.device_count():
            raise ConfigError(f"device {dev} asked for, but only {torch.cuda.device_count()} GPU(s) are visible; "
                              "use another index or set CUDA_VISIBLE_DEVICES")
    return dev


def worker_device(k: int, gpus: int, device: str) -> str:
    """The device string of the ``k``-th of several parallel workers (k = 0, 1, ...).

    With ``device`` ``auto`` or ``cuda`` (no index) and ``gpus`` > 1 visible GPUs the workers are
    spread round-robin, ``cuda:(k mod gpus)``; anything else (CPU, one GPU, an explicit
    ``cuda:N``, which the user chose) is returned unchanged, so a CPU run does not change.
    Pure: ``gpus`` is ``torch.cuda.device_count()`` (0 without CUDA), read by the caller.
    """
    if device in ("auto", "cuda") and gpus > 1:
        return f"cuda:{k % gpus}"
    return device
