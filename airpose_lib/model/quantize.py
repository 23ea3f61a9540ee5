"""Static int8 quantisation of a drone's stage 1 with ONNX Runtime (QDQ, per-channel weights).

Stage 1 (backbone + first iteration) is ~99 % of a drone's compute, so only it is quantised;
``stage_next.onnx`` (two small regressor iterations) stays float32. Within stage 1 only the
backbone's convolutions, ReLUs, residual additions and pooling are quantised: the regressor's
fully connected layers cost ~0.1 % of the multiply-adds but their int8 rounding would go
straight into the 136-number messages and the camera translation::

    paths = export_onnx(model, out_dir, input_size=224)               # float32 graphs
    quantize_stage1(out_dir, images, P)                               # + stage1_int8.onnx
    node = OnnxDroneNode(out_dir, precision="int8")                   # same API as DroneNode

Activations are calibrated (min-max by default) on crops the caller provides: the kit's own
still-frame crops (``airpose_lib.runtime.edge`` loads them; ``model`` does not import ``data``).
Activations are unsigned 8-bit and weights signed 8-bit per output channel (ONNX Runtime's
U8S8, the format its x86 int8 kernels run). ``meta.json`` records each stage-1 file by
precision, with the quantisation settings and a digest of the calibration crops.
"""
from __future__ import annotations

import hashlib
import json
import tempfile
from collections.abc import Iterator
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
import onnx
import onnxruntime as ort
from onnxruntime.quantization import CalibrationDataReader, CalibrationMethod, QuantFormat, QuantType, quantize_static
from onnxruntime.quantization.shape_inference import quant_pre_process

from airpose_lib.atomic import atomic_path

__all__ = ["QuantSettings", "CropReader", "quantize_stage1", "calibration_digest", "STAGE1_FILES"]

#: stage-1 graph file of each precision inside an export folder.
STAGE1_FILES = {"fp32": "stage1.onnx", "int8": "stage1_int8.onnx"}

_CALIBRATION = ("minmax", "percentile", "entropy")


@dataclass(frozen=True)
class QuantSettings:
    """How stage 1 is quantised (all of it goes into the artefact's key).

    Args:
        per_channel: one weight scale per output channel (else per tensor).
        calibration: activation range estimator: ``"minmax"``, ``"percentile"`` or ``"entropy"``.
        percentile: the percentile of ``"percentile"`` calibration.
        backbone_only: leave the regressor's fully connected layers in float32 (see the module
            docstring); False quantises every supported operator.
        reduce_range: 7-bit weights (avoids the saturation of the AVX2 u8s8 kernels, at a cost
            in resolution; ONNX Runtime's advice when int8 accuracy drops on non-VNNI CPUs).
    """

    per_channel: bool = True
    calibration: str = "minmax"
    percentile: float = 99.999
    backbone_only: bool = True
    reduce_range: bool = False

    def __post_init__(self):
        if self.calibration not in _CALIBRATION:
            raise ValueError(f"calibration must be one of {_CALIBRATION}, got {self.calibration!r}")

    def to_dict(self) -> dict:
        return asdict(self)


class CropReader(CalibrationDataReader):
    """ONNX Runtime calibration reader over crops, one at a time (the graph has batch 1).

    Args:
        images: ``(N, 3, S, S)`` float32 normalised crops.
        P: ``(N, 3)`` their crop vectors.
        input_names: the graph's inputs (the exporter drops unused ones, e.g. P for Baseline).
    """

    def __init__(self, images: np.ndarray, P: np.ndarray, input_names: set[str]):
        self.images = np.ascontiguousarray(images, np.float32)
        self.P = np.ascontiguousarray(P, np.float32)
        if self.images.ndim != 4 or self.P.shape != (len(self.images), 3):
            raise ValueError(f"need images (N, 3, S, S) and P (N, 3), got {self.images.shape} and {self.P.shape}")
        self.input_names = set(input_names)
        self._it: Iterator[dict] = self._feeds()

    def _feeds(self) -> Iterator[dict]:
        for x, p in zip(self.images, self.P):
            feeds = {"image": x[None], "P": p[None]}
            yield {k: v for k, v in feeds.items() if k in self.input_names}

    def get_next(self) -> dict | None:
        return next(self._it, None)

    def rewind(self) -> None:
        self._it = self._feeds()


def calibration_digest(images: np.ndarray, P: np.ndarray) -> str:
    """SHA-256 of the calibration crops and crop vectors (float32 bytes, shapes included)."""
    h = hashlib.sha256()
    for a in (np.ascontiguousarray(images, np.float32), np.ascontiguousarray(P, np.float32)):
        h.update(repr(a.shape).encode())
        h.update(a.tobytes())
    return h.hexdigest()


def _excluded_nodes(model_path: Path, backbone_only: bool) -> list[str]:
    """Names of the nodes to keep in float32: everything after the backbone's pooling."""
    if not backbone_only:
        return []
    graph = onnx.load(str(model_path), load_external_data=False).graph
    return [n.name for n in graph.node if not n.name.startswith("/backbone/")]


def quantize_stage1(export_dir: str | Path, images: np.ndarray, P: np.ndarray,
                    settings: QuantSettings = QuantSettings(), provenance: dict | None = None) -> Path:
    """Write ``stage1_int8.onnx`` next to the float32 ``stage1.onnx`` of an export folder.

    Args:
        export_dir: a folder written by :func:`~.onnx_export.export_onnx`.
        images: ``(N, 3, S, S)`` float32 calibration crops (normalised as the network's input).
        P: ``(N, 3)`` their crop vectors.
        settings: see :class:`QuantSettings`.
        provenance: extra entries stored with the int8 file in ``meta.json`` (e.g. the dataset).

    Returns:
        the path of ``stage1_int8.onnx``.
    """
    export_dir = Path(export_dir)
    meta_path = export_dir / "meta.json"
    meta = json.loads(meta_path.read_text())
    size = int(meta["input_size"])
    if images.shape[1:] != (3, size, size):
        raise ValueError(f"calibration crops are {tuple(images.shape[1:])}, the graph takes (3, {size}, {size})")
    src = export_dir / STAGE1_FILES["fp32"]
    target = export_dir / STAGE1_FILES["int8"]
    method = {"minmax": CalibrationMethod.MinMax, "percentile": CalibrationMethod.Percentile,
              "entropy": CalibrationMethod.Entropy}[settings.calibration]
    inputs = {i.name for i in ort.InferenceSession(str(src), providers=["CPUExecutionProvider"]).get_inputs()}
    with tempfile.TemporaryDirectory(dir=export_dir) as tmp:
        # Shape inference and constant folding first (ONNX Runtime's recommended pre-processing);
        # BatchNorm is already folded into the convolutions by the exporter.
        pre = Path(tmp) / "stage1_pre.onnx"
        quant_pre_process(str(src), str(pre), skip_symbolic_shape=True)
        extra = {"CalibPercentile": settings.percentile} if settings.calibration == "percentile" else {}
        with atomic_path(target) as out:
            quantize_static(str(pre), str(out), CropReader(images, P, inputs), quant_format=QuantFormat.QDQ,
                            per_channel=settings.per_channel, reduce_range=settings.reduce_range,
                            activation_type=QuantType.QUInt8, weight_type=QuantType.QInt8,
                            calibrate_method=method, nodes_to_exclude=_excluded_nodes(pre, settings.backbone_only),
                            extra_options=extra)
    stage1 = dict(meta.get("stage1", {"fp32": {"file": STAGE1_FILES["fp32"]}}))
    stage1["int8"] = {"file": STAGE1_FILES["int8"], "settings": settings.to_dict(),
                      "calibration": {"crops": int(len(images)), "sha256": calibration_digest(images, P)},
                      "onnxruntime": ort.__version__, **(provenance or {})}
    meta["stage1"] = stage1
    with atomic_path(meta_path) as tmp_meta:
        tmp_meta.write_text(json.dumps(meta, indent=1))
    return target
