"""What a drone runs: anything with the staged API of :class:`airpose_lib.model.DroneNode`.

:class:`StageModel` is that API as a protocol. Four backends provide it:

* ``torch``: :class:`airpose_lib.model.DroneNode` around an :class:`~airpose_lib.model.AirPoseNet`
  (random weights from a seed, or a checkpoint);
* ``onnx``: :class:`airpose_lib.model.onnx_export.OnnxDroneNode` on graphs written by
  ``export_onnx`` (ONNX Runtime, no torch at inference);
* ``onnx-int8``: the same with stage 1 statically quantised to int8
  (:mod:`airpose_lib.model.quantize`, calibrated on the kit's crops);
  without ``onnx_dir`` both ONNX kinds export (and calibrate) the network into the kit cache
  on first use (:func:`airpose_lib.runtime.edge.ensure_export`);
* ``fake``: :class:`FakeStageModel`, a few small matrix products with the same inputs, outputs and
  message dependence, so that the runtime's tests run in milliseconds per frame.

:func:`airpose_lib.runtime.networks.make_stage_model` builds a backend from its :class:`BackendSpec`.
A node keeps one *prototype* per process and a shallow copy per frame in flight
(:func:`fresh_copy`): the copies share weights / sessions, each holds one frame's state.
"""
from __future__ import annotations

import copy
from collections.abc import Sequence
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Protocol, runtime_checkable

import numpy as np

from airpose_lib.errors import reading
from airpose_lib.model.message import MESSAGE_DIM

__all__ = [
    "ONNX_PRECISIONS",
    "StageModel",
    "BackendSpec",
    "FakeStageModel",
    "build_torch_model",
    "checkpoint_settings",
    "fresh_copy",
    "to_numpy",
    "warm_up",
]

#: stage-1 precision of each ONNX Runtime backend kind.
ONNX_PRECISIONS = {"onnx": "fp32", "onnx-int8": "int8"}


@runtime_checkable
class StageModel(Protocol):
    """One view's network run stage by stage (see ``airpose_lib.model.staged``)."""

    num_stages: int

    def stage1(self, image, P=None) -> np.ndarray:
        """image ``(1, 3, S, S)``, P ``(1, 3)`` -> this view's message ``(136,)``."""

    def stage(self, k: int, other_messages: Sequence = ()) -> np.ndarray:
        """Iteration k >= 2 from the other views' stage k-1 messages (each ``(136,)``); an empty
        list means "no other view" (mean parameters, the Fullcam behaviour)."""

    def result(self) -> dict:
        """phi6d (1, 6), theta6d (1, 21, 6), beta (1, 10), tau (1, 3) or cam (1, 3), ..."""


def to_numpy(x) -> np.ndarray:
    """A torch tensor or array-like as a numpy array (no copy when possible)."""
    if hasattr(x, "detach"):
        return x.detach().cpu().numpy()
    return np.asarray(x)


def fresh_copy(proto: StageModel) -> StageModel:
    """A copy sharing weights and sessions with ``proto`` but with its own per-frame state.

    DroneNode, OnnxDroneNode and FakeStageModel rebind (never mutate) their per-frame attributes
    in ``stage1``, so a shallow copy suffices.
    """
    return copy.copy(proto)


class FakeStageModel:
    """A cheap numeric stand-in with the staged API (for tests and dry runs).

    Stage 1 reduces the crop to 6 statistics, appends P and maps them, with the mean "other"
    message, to a 136-value message through fixed random matrices (seeded); stage k maps the
    same features, the previous message and the mean of the other views' messages. All maths is
    float64 numpy, so runs in different processes are bit-identical. Outputs mimic a full-camera
    variant (``tau`` in metres).

    Args:
        seed: seed of the matrices (all drones must use the same, like shared weights).
        num_stages: iterations (3 as the paper).
        message_dtype: dtype of the emitted messages (``"float32"`` or ``"float16"``).
        compute_s: optional sleep per stage 1 (emulates a backbone's run time without using CPU).
    """

    variant = "fake"

    def __init__(self, seed: int = 0, num_stages: int = 3, message_dtype="float32", compute_s: float = 0.0):
        g = np.random.default_rng(seed)
        self.num_stages = int(num_stages)
        self.message_dtype = np.dtype(message_dtype)
        self.compute_s = float(compute_s)
        self._A = g.normal(scale=0.5, size=(MESSAGE_DIM, 9))
        self._B = g.normal(scale=0.5 / np.sqrt(MESSAGE_DIM), size=(MESSAGE_DIM, MESSAGE_DIM))
        self._C = g.normal(scale=0.5 / np.sqrt(MESSAGE_DIM), size=(MESSAGE_DIM, MESSAGE_DIM))
        self._D = g.normal(scale=0.3, size=(9, 9))
        self._mean = np.tanh(g.normal(size=MESSAGE_DIM)) * 0.1
        self._k = 0

    def mean_message(self) -> np.ndarray:
        """The "other view" of iteration 1 and of a stage without messages, ``(136,)``."""
        return self._mean.astype(np.float32)

    def stage1(self, image, P=None) -> np.ndarray:
        x = to_numpy(image).astype(np.float64).reshape(3, -1)
        P = np.zeros(3) if P is None else to_numpy(P).astype(np.float64).reshape(3)
        self._f = np.concatenate((x.mean(1), x.std(1), P))
        self._input_size = int(np.sqrt(x.shape[1]))
        if self.compute_s > 0:
            import time

            time.sleep(self.compute_s)
        self._msg = np.tanh(self._A @ self._f + self._B @ self._mean)
        self._messages = [self._msg.astype(np.float32)]
        self._k = 1
        return self._messages[-1].astype(self.message_dtype)

    def stage(self, k: int, other_messages: Sequence = ()) -> np.ndarray:
        if self._k == 0:
            raise RuntimeError("run stage1 first")
        if k != self._k + 1 or k > self.num_stages:
            raise ValueError(f"expected stage {self._k + 1} (of {self.num_stages}), got {k}")
        if len(other_messages):
            # float32 first, as the real DroneNode: float16 messages are widened before fusion.
            other = np.stack([to_numpy(m).astype(np.float32).astype(np.float64).reshape(MESSAGE_DIM)
                              for m in other_messages]).mean(0)
        else:
            other = self._mean
        self._msg = np.tanh(self._A @ self._f + self._B @ other + self._C @ self._msg)
        self._messages = self._messages + [self._msg.astype(np.float32)]
        self._k = k
        return self._messages[-1].astype(self.message_dtype)

    def result(self) -> dict:
        if self._k == 0:
            raise RuntimeError("no stage has run")
        m = self._msg
        g = np.tanh(self._D @ self._f + m[:9])
        return {
            "phi6d": np.concatenate((g[:3], m[:3])).astype(np.float32)[None],
            "theta6d": m[:126].reshape(1, 21, 6).astype(np.float32),
            "beta": m[126:].astype(np.float32)[None],
            "tau": (np.array([0.0, 0.0, 10.0]) + g[3:6]).astype(np.float32)[None],
            "messages": [mm[None] for mm in self._messages],
            "input_size": self._input_size,
        }


@dataclass(frozen=True)
class BackendSpec:
    """How a node builds its :class:`StageModel` (all drones of a run use the same spec).

    Args:
        kind: ``"torch"``, ``"onnx"``, ``"onnx-int8"`` or ``"fake"``.
        variant: network variant (torch): ``"airpose"`` (default), ``"fullcam"``, ...
        backbone: ``"resnet18"``, ``"resnet34"`` or ``"resnet50"`` (torch).
        input_size: crop side S in pixels.
        seed: seed of the random weights when no checkpoint is given (torch, fake).
        checkpoint: a ``state_dict`` file (``torch.save``; a dict with ``model`` or
            ``state_dict`` inside is unwrapped, e.g. a training checkpoint, whose ``config``
            then gives variant, backbone and crop size) for the torch backend, and for the ONNX
            backends when ``onnx_dir`` is not given.
        onnx_dir: folder written by ``model.onnx_export.export_onnx`` (``onnx``), with
            ``stage1_int8.onnx`` for ``onnx-int8`` (``airpose export --quantize int8``).
        threads: intra-op threads (torch / ONNX Runtime).
        message_dtype: ``"float32"`` (paper) or ``"float16"``.
        fake_compute_ms: sleep per stage 1 of the fake backend.
    """

    kind: str = "torch"
    variant: str = "airpose"
    backbone: str = "resnet18"
    input_size: int = 128
    seed: int = 0
    checkpoint: str | None = None
    onnx_dir: str | None = None
    threads: int = 1
    message_dtype: str = "float32"
    fake_compute_ms: float = 0.0

    def to_dict(self) -> dict:
        return asdict(self)


_CKPT_FIX = "give another --checkpoint (e.g. the newest checkpoints/step_*.pt of the run)"


def _read_checkpoint(path: str | Path):
    """The loaded file of a ``--checkpoint`` (a checkpoint dict or a bare ``state_dict``)."""
    import torch  # lazy: a fake drone starts without torch

    with reading(path, "a model checkpoint (a state_dict or a checkpoint of `airpose train`)", _CKPT_FIX):
        return torch.load(path, map_location="cpu", weights_only=True)


def _state_settings(state) -> dict:
    """:func:`checkpoint_settings` of a loaded file."""
    if not isinstance(state, dict) or not isinstance(state.get("config"), dict):
        return {}
    # lazy: only a drone with a checkpoint needs the data readers (a drone's start-up stays short)
    from airpose_lib.data.still.training_input import training_input
    from airpose_lib.model.record import read_network

    record = read_network(state, legacy=training_input)  # old checkpoints: from their data
    out = {"variant": record.variant, "backbone": record.backbone, "model": record.model}
    if record.input_size:
        out["input_size"] = int(record.input_size)
    return out


def checkpoint_settings(path: str | Path) -> dict:
    """Network settings of a training or fine-tuning checkpoint (its network record,
    :func:`airpose_lib.model.record.read_network`): ``variant``, ``backbone``, ``model`` (extra
    ``build_model`` kwargs) and ``input_size`` (the crop size) when known; empty for a bare
    ``state_dict``."""
    return _state_settings(_read_checkpoint(path))


def build_torch_model(spec: BackendSpec):
    """The torch :class:`~airpose_lib.model.AirPoseNet` of ``spec`` (eval mode): random weights
    from ``spec.seed``, or the checkpoint's, read once (a training checkpoint's own variant and
    backbone win over the spec's: :func:`airpose_lib.model.record.network_from_checkpoint`)."""
    import torch  # lazy, with the model: a fake drone starts without torch

    from airpose_lib.model import build_model

    torch.manual_seed(spec.seed)  # identical random weights in every drone process
    if not spec.checkpoint:
        return build_model(spec.variant, spec.backbone).eval()
    state = _read_checkpoint(spec.checkpoint)
    settings = _state_settings(state)
    if settings and isinstance(state.get("model"), dict):  # a kit checkpoint: the one loader
        from airpose_lib.data.still.training_input import training_input
        from airpose_lib.model.record import network_from_checkpoint

        return network_from_checkpoint(state, legacy=training_input)[0]
    model = build_model(settings.get("variant", spec.variant), settings.get("backbone", spec.backbone),
                        **settings.get("model", {}))
    for key in ("model", "state_dict"):  # a state_dict wrapped in a dict
        if isinstance(state, dict) and key in state and isinstance(state[key], dict):
            state = state[key]
    model.load_state_dict(state)
    return model.eval()


def warm_up(model: StageModel, input_size: int) -> None:
    """Run one frame of zeros through all stages (first-call allocations, lazy init)."""
    m = fresh_copy(model)
    image = np.zeros((1, 3, input_size, input_size), np.float32)
    P = np.array([[0.0, 0.0, 1.0]], np.float32)
    msg = m.stage1(image, P)  # numpy works for every backend (torch.as_tensor takes it)
    for k in range(2, model.num_stages + 1):
        msg = m.stage(k, [msg])
    m.result()

