"""ONNX export of a drone's stages and an ONNX Runtime drone node.

Two graphs per variant, static batch 1 (what runs on a drone):

* ``stage1.onnx``: ``image (1, 3, S, S), P (1, 3) -> feat (1, C), state (1, 145), message (1, 136)``
  (backbone + first iteration, the mean parameters baked in as constants);
* ``stage_next.onnx``: ``feat (1, C), P (1, 3), state (1, 145), other (1, 136) -> state, message``
  (one iteration; used for stages 2 and 3, which share all weights).

``other`` is the mean of the other drones' messages (:func:`staged.fuse_message_list`). Inputs a
variant does not use (P for the weak-camera variants, other for Baseline and Fullcam) stay in
the signature and are ignored. ``meta.json`` next to the graphs records the variant, input size,
number of stages, the mean message (the "other view" when no message arrives) and, under
``stage1``, the stage-1 graph of each precision (``fp32``; ``int8`` once
:func:`~.quantize.quantize_stage1` has run on the folder).

Exported with PyTorch's TorchScript-based exporter (``dynamo=False``): the newer exporter needs
the ``onnxscript`` package, which the kit does not install.
"""
from __future__ import annotations

import json
import warnings
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import torch
from torch import Tensor, nn

from .message import MESSAGE_DIM
from .staged import _to_numpy, _wire_dtype
from .variants import STATE_DIM, AirPoseNet, decode_state, unpack_state

__all__ = ["Stage1Graph", "IterationGraph", "export_onnx", "OnnxDroneNode", "OPSET"]

OPSET = 17


class Stage1Graph(nn.Module):
    """Backbone + first iteration of one view, as one traceable module."""

    def __init__(self, model: AirPoseNet):
        super().__init__()
        self.model = model

    def forward(self, image: Tensor, P: Tensor) -> tuple[Tensor, Tensor, Tensor]:
        m = self.model
        feat = m.features(image)
        other = m.mean_message((1,)) if m.spec.multiview else None
        state = m.iterate(feat, P, m.initial_state((1,)), other)
        return feat, m.pack_state(state), m.message(state)


class IterationGraph(nn.Module):
    """One later iteration (stages 2, 3, ...) of one view."""

    def __init__(self, model: AirPoseNet):
        super().__init__()
        self.model = model

    def forward(self, feat: Tensor, P: Tensor, state: Tensor, other: Tensor) -> tuple[Tensor, Tensor]:
        m = self.model
        new = m.iterate(feat, P, m.unpack_state(state), other)
        return m.pack_state(new), m.message(new)


def export_onnx(model: AirPoseNet, out_dir: str | Path, input_size: int = 224) -> dict[str, Path]:
    """Export both stage graphs of ``model`` (put in eval mode) for ``input_size`` crops.

    Returns:
        dict with the paths ``stage1``, ``stage_next`` and ``meta``.
    """
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    model.eval()
    dtype = model.init_beta.dtype
    image = torch.zeros(1, 3, input_size, input_size, dtype=dtype)
    P = torch.tensor([[0.0, 0.0, 1.0]], dtype=dtype)
    paths = {"stage1": out_dir / "stage1.onnx", "stage_next": out_dir / "stage_next.onnx",
             "meta": out_dir / "meta.json"}
    with torch.no_grad(), warnings.catch_warnings():
        warnings.simplefilter("ignore", DeprecationWarning)  # the TorchScript exporter's notice
        feat, state, _ = Stage1Graph(model)(image, P)
        torch.onnx.export(Stage1Graph(model), (image, P), str(paths["stage1"]), dynamo=False,
                          input_names=["image", "P"], output_names=["feat", "state", "message"],
                          opset_version=OPSET)
        other = torch.zeros(1, MESSAGE_DIM, dtype=dtype)
        torch.onnx.export(IterationGraph(model), (feat, P, state, other), str(paths["stage_next"]),
                          dynamo=False, input_names=["feat", "P", "state", "other"],
                          output_names=["state_out", "message"], opset_version=OPSET)
    meta = {
        "variant": model.variant,
        "input_size": int(input_size),
        "num_stages": model.num_iterations,
        "feature_dim": model.backbone.feature_dim,
        "state_dim": STATE_DIM,
        "mean_message": model.mean_message((1,))[0].tolist(),
        "stage1": {"fp32": {"file": "stage1.onnx"}},
    }
    paths["meta"].write_text(json.dumps(meta, indent=1))
    return paths


class OnnxDroneNode:
    """:class:`staged.DroneNode` with ONNX Runtime instead of torch (same methods and outputs).

    Args:
        out_dir: folder written by :func:`export_onnx`.
        num_threads: intra-op threads of the ONNX Runtime sessions.
        message_dtype: ``"float32"`` or ``"float16"`` for the emitted messages.
        precision: stage-1 graph to run, ``"fp32"`` or ``"int8"`` (:func:`~.quantize.quantize_stage1`);
            stages 2+ are float32 either way.
    """

    def __init__(self, out_dir: str | Path, num_threads: int = 2, message_dtype="float32", precision: str = "fp32"):
        import onnxruntime as ort

        out_dir = Path(out_dir)
        self.meta = json.loads((out_dir / "meta.json").read_text())
        files = self.meta.get("stage1", {"fp32": {"file": "stage1.onnx"}})  # older exports: fp32 only
        if precision not in files:
            raise FileNotFoundError(f"{out_dir}: no {precision} stage 1 (has {sorted(files)}); make it with "
                                    f"`airpose export --quantize {precision}`")
        self.precision = precision
        opts = ort.SessionOptions()
        opts.intra_op_num_threads = num_threads
        opts.inter_op_num_threads = 1
        providers = ["CPUExecutionProvider"]
        self._s1 = ort.InferenceSession(str(out_dir / files[precision]["file"]), opts, providers=providers)
        self._sk = ort.InferenceSession(str(out_dir / "stage_next.onnx"), opts, providers=providers)
        self._s1_inputs = {i.name for i in self._s1.get_inputs()}
        self._sk_inputs = {i.name for i in self._sk.get_inputs()}
        self.variant = self.meta["variant"]
        self.num_stages = int(self.meta["num_stages"])
        self.message_dtype = _wire_dtype(message_dtype)
        self._mean = np.asarray(self.meta["mean_message"], np.float32)[None]
        self._k = 0

    def _run(self, session, names: set, feeds: dict) -> list:
        # The exporter drops graph inputs the computation does not use (e.g. P for Baseline).
        return session.run(None, {k: v for k, v in feeds.items() if k in names})

    def stage1(self, image, P=None) -> np.ndarray:
        """As :meth:`DroneNode.stage1`; image ``(1, 3, S, S)``, P ``(1, 3)``."""
        image = np.asarray(_to_numpy(image), np.float32)
        image = image[None] if image.ndim == 3 else image
        self._P = np.zeros((1, 3), np.float32) if P is None else np.asarray(_to_numpy(P), np.float32).reshape(1, 3)
        self._input_size = int(image.shape[-1])
        self._feat, self._state, msg = self._run(self._s1, self._s1_inputs, {"image": image, "P": self._P})
        self._messages = [msg]
        self._k = 1
        return msg[0].astype(self.message_dtype)

    def stage(self, k: int, other_messages: Sequence = ()) -> np.ndarray:
        """As :meth:`DroneNode.stage`."""
        if self._k == 0:
            raise RuntimeError("run stage1 first")
        if k != self._k + 1 or k > self.num_stages:
            raise ValueError(f"expected stage {self._k + 1} (of {self.num_stages}), got {k}")
        if len(other_messages):
            other = np.stack([np.asarray(_to_numpy(m)).astype(np.float32).reshape(MESSAGE_DIM)
                              for m in other_messages]).mean(0, keepdims=True)
        else:
            other = self._mean
        self._state, msg = self._run(self._sk, self._sk_inputs, {
            "feat": self._feat, "P": self._P, "state": self._state, "other": other.astype(np.float32)})
        self._messages.append(msg)
        self._k = k
        return msg[0].astype(self.message_dtype)

    def result(self) -> dict:
        """As :meth:`DroneNode.result` (torch tensors, batch 1)."""
        state = unpack_state(torch.from_numpy(np.ascontiguousarray(self._state)), self.variant)
        out = decode_state(state, self.variant)
        out["messages"] = [torch.from_numpy(m) for m in self._messages]
        out["input_size"] = self._input_size
        return out
