"""The device of the stages outside the training loop (issue 29): the one device rule
(:mod:`airpose_lib.devices`), AirPose+ and the prior's training on the asked device with their
results on the CPU, the parallel ablation workers spread over the GPUs, and the device and
precision of each training in the results provenance. Runs on a CPU-only machine; the CUDA
comparisons run where a GPU is visible."""
from __future__ import annotations

import pytest
import torch

from airpose_lib.devices import resolve_device
from airpose_lib.errors import ConfigError


@pytest.fixture(autouse=True)
def _one_thread():
    n = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(n)


def _gpus(monkeypatch, count: int) -> None:
    """Pretend this torch sees ``count`` GPUs (0: none)."""
    monkeypatch.setattr(torch.cuda, "is_available", lambda: count > 0)
    monkeypatch.setattr(torch.cuda, "device_count", lambda: count)


# -- the rule -------------------------------------------------------------------------------------
def test_auto_is_the_process_gpu_when_cuda_is_available_else_the_cpu(monkeypatch):
    _gpus(monkeypatch, 2)
    assert resolve_device("auto") == torch.device("cuda:0")
    assert resolve_device("auto", local_rank=1) == torch.device("cuda:1")
    assert resolve_device("cuda", local_rank=1) == torch.device("cuda:1")
    assert resolve_device("cuda:1") == torch.device("cuda:1")
    assert resolve_device("cpu", local_rank=1) == torch.device("cpu")
    with pytest.raises(ConfigError, match="only 2 GPU"):
        resolve_device("cuda:2")
    _gpus(monkeypatch, 0)
    assert resolve_device("auto", local_rank=1) == torch.device("cpu")
    with pytest.raises(ConfigError, match="--device cpu"):
        resolve_device("cuda")
    with pytest.raises(ConfigError, match="not a device"):
        resolve_device("gpu0")


def test_engine_launch_uses_the_same_rule():
    from airpose_lib.engine import launch

    assert launch.resolve_device is resolve_device
