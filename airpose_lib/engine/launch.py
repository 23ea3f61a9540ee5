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
error rather than silently mapped to bf16); ``auto`` (:func:`resolve_precision`): bf16 where the
device computes it natively, fp32 elsewhere. A CPU without native bf16 emulates it: one ResNet-18
training step in bf16 took 20x the fp32 step with the CPU limited to AVX2
(``benchmarks/training_precision.py``), while a CPU with AVX-512 BF16 runs it 1.8x faster.
"""
from __future__ import annotations

import contextlib
import contextvars
import os

import torch
import torch.distributed as dist

from airpose_lib.devices import PRECISION_CHOICES, resolve_device
from airpose_lib.errors import ConfigError

__all__ = ["PRECISIONS", "PRECISION_CHOICES", "launch_env", "single_process", "process_rank", "is_distributed",
           "resolve_device", "check_precision", "native_bf16", "cpu_bf16", "resolve_precision", "autocast",
           "grad_scaler"]

#: ``precision`` -> autocast dtype (None: plain float32).
PRECISIONS = {"fp32": None, "bf16": torch.bfloat16, "fp16": torch.float16}
#: oneDNN ISA limits (``ONEDNN_MAX_CPU_ISA``) that still include its native bf16 kernels.
_ONEDNN_BF16_ISAS = ("AVX512_CORE_BF16", "AVX512_CORE_FP16", "AVX512_CORE_AMX", "AVX512_CORE_AMX_FP16",
                     "AVX10_1_512", "AVX10_1_512_AMX", "AVX10_1_512_AMX_FP16", "AVX10_2_512",
                     "AVX10_2_512_AMX_2", "ALL", "DEFAULT")

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
    if precision not in PRECISION_CHOICES:
        raise ConfigError(f"precision must be one of {list(PRECISION_CHOICES)}, got {precision!r}")
    if precision == "fp16" and torch.device(device).type != "cuda":
        raise ConfigError(f"precision fp16 needs a CUDA device (it trains with loss scaling there), not "
                         f"{device}; use precision=bf16 on CPU")


def native_bf16(machine: str, cpu_flags: set[str], onednn_isa: str | None, aten_capability: str
                ) -> tuple[bool, str]:
    """Whether a CPU computes bfloat16 natively, and why (pure: the caller reads the machine).

    Args:
        machine: ``platform.machine()`` (``x86_64``, ``aarch64``, ...).
        cpu_flags: the CPU's feature flags (``/proc/cpuinfo``'s ``flags`` on x86, ``Features`` on Arm).
        onednn_isa: ``$ONEDNN_MAX_CPU_ISA`` (None when unset): a limit below AVX-512 BF16 takes
            oneDNN's bf16 kernels away.
        aten_capability: ``torch.backends.cpu.get_cpu_capability()`` (``AVX512``, ``AVX2``, ...;
            ``$ATEN_CPU_CAPABILITY`` lowers it).

    Returns:
        ``(native, reason)``, the reason one short phrase.
    """
    if machine in ("aarch64", "arm64"):
        return ("bf16" in cpu_flags, "Arm CPU " + ("with" if "bf16" in cpu_flags else "without") + " BF16")
    found = sorted(cpu_flags & {"avx512_bf16", "amx_bf16"})
    if not found:
        return False, "CPU without AVX-512 BF16 or AMX"
    if onednn_isa is not None and onednn_isa.strip().upper() not in _ONEDNN_BF16_ISAS:
        return False, f"{'/'.join(found)} present but ONEDNN_MAX_CPU_ISA={onednn_isa} limits oneDNN below it"
    if not aten_capability.upper().startswith("AVX512"):
        return False, f"{'/'.join(found)} present but ATen runs its {aten_capability} kernels"
    return True, f"CPU with {'/'.join(found)}"


def cpu_bf16() -> tuple[bool, str]:
    """:func:`native_bf16` of this machine's CPU and environment."""
    import platform

    flags: set[str] = set()
    try:
        for line in open("/proc/cpuinfo", encoding="utf-8", errors="replace"):
            key, _, value = line.partition(":")
            if key.strip().lower() in ("flags", "features"):
                flags = set(value.split())
                break
    except OSError:  # not Linux: no flags, so fp32
        pass
    return native_bf16(platform.machine().lower(), flags, os.environ.get("ONEDNN_MAX_CPU_ISA"),
                       torch.backends.cpu.get_cpu_capability())


def resolve_precision(precision: str, device: torch.device | str) -> tuple[str, str]:
    """The precision a run computes in, and why: ``auto`` becomes ``bf16`` where ``device``
    computes it natively (a CPU by :func:`cpu_bf16`; a CUDA GPU that supports bf16) and ``fp32``
    elsewhere; any other value is kept ("set in the config").

    Returns:
        ``(precision, reason)``, e.g. ``("fp32", "auto: CPU without AVX-512 BF16 or AMX")``.
    """
    check_precision(precision, device)
    if precision != "auto":
        return precision, "set in the config"
    dev = torch.device(device)
    if dev.type == "cuda":
        native = torch.cuda.is_bf16_supported()
        return ("bf16" if native else "fp32"), f"auto: GPU {'with' if native else 'without'} bf16"
    if dev.type != "cpu":
        return "fp32", f"auto: {dev.type} device"
    native, why = cpu_bf16()
    return ("bf16" if native else "fp32"), f"auto: {why}"


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
