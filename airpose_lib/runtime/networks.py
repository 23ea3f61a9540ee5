"""A drone's network from its :class:`~.backends.BackendSpec`: :func:`make_stage_model`.

Apart from :mod:`.backends` (the protocol and the spec) because the ONNX kinds export into the
cache through :mod:`.edge`, which itself builds on the spec.
"""
from __future__ import annotations

from pathlib import Path

from .backends import ONNX_PRECISIONS, BackendSpec, FakeStageModel, StageModel, build_torch_model

__all__ = ["make_stage_model"]


def make_stage_model(spec: BackendSpec) -> StageModel:
    """Build the prototype :class:`StageModel` of a node (one per process)."""
    if spec.kind == "fake":
        return FakeStageModel(spec.seed, message_dtype=spec.message_dtype,
                              compute_s=spec.fake_compute_ms / 1000.0)
    # Each backend's libraries are imported when it is chosen: a drone starts (and restarts)
    # without importing what it does not run (torch, ONNX Runtime, the export's data readers).
    if spec.kind == "torch":
        import torch

        from airpose_lib.model import DroneNode

        torch.set_num_threads(spec.threads)
        return DroneNode(build_torch_model(spec), message_dtype=spec.message_dtype)
    if spec.kind in ONNX_PRECISIONS:
        from airpose_lib.model.onnx_export import OnnxDroneNode

        folder = spec.onnx_dir
        if not folder:
            from .edge import ensure_export  # torch and the calibration crops' dataset

            folder = ensure_export(spec)
        elif not (Path(folder) / "meta.json").exists():
            raise FileNotFoundError(f"{spec.kind} backend: no meta.json in {folder} (make the folder with "
                                    f"`airpose export`, or leave --onnx-dir out to export into the cache)")
        return OnnxDroneNode(folder, num_threads=spec.threads, message_dtype=spec.message_dtype,
                             precision=ONNX_PRECISIONS[spec.kind])
    raise ValueError(f"unknown backend {spec.kind!r}: choose torch, onnx, onnx-int8 or fake")
