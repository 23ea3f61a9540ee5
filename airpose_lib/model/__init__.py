"""The AirPose network: ResNet backbone, HMR-style iterative regressor, the four ablation
variants, per-drone staged execution and ONNX export.

Imports only ``geometry`` and ``body`` from the kit (and onnxruntime lazily, for ONNX runs).
Names are imported lazily from their modules, so ``model.message`` (the message size) is usable
without torch: the runtime's wire format sizes its packets from it at a drone's start-up.
"""
from __future__ import annotations

from airpose_lib._lazy import lazy_namespace

_MODULES = ("message", "backbone", "regressor", "variants", "staged", "onnx_export", "official", "record",
            "smplx_params", "pretrain", "quantize")
_EXPORTS = {
    **dict.fromkeys(("BETA_DIM", "MESSAGE_DIM", "NUM_BODY_JOINTS", "THETA_DIM"), "message"),
    **dict.fromkeys(("BACKBONES", "BasicBlock", "Bottleneck", "ResNet", "build_backbone", "resnet18", "resnet34",
                     "resnet50"), "backbone"),
    **dict.fromkeys(("DECODER_GAIN", "HIDDEN_WIDTH", "IterativeRegressor"), "regressor"),
    **dict.fromkeys(("OnnxDroneNode", "export_onnx"), "onnx_export"),
    **dict.fromkeys(("load_official_checkpoint", "to_official_state_dict", "write_official_checkpoint"), "official"),
    **dict.fromkeys(("NetworkRecord", "network_record", "read_network"), "record"),
    **dict.fromkeys(("posed_joints_and_vertices", "to_smplx_params"), "smplx_params"),
    **dict.fromkeys(("DroneNode", "decode_message", "encode_message", "fuse_message_list", "message_nbytes"),
                    "staged"),
    **dict.fromkeys(("STATE_DIM", "TAU_INIT", "TAU_SCALE", "VARIANTS", "WEAK_CAM_INIT", "AirPoseNet", "MeanParams",
                     "VariantSpec", "build_model", "convert_official_state_dict", "decode_state",
                     "default_mean_params", "fc1_input_width", "fuse_messages", "load_mean_params", "state_keys",
                     "unpack_state"), "variants"),
}

__all__ = sorted(_EXPORTS)
__getattr__, __dir__ = lazy_namespace(__name__, globals(), _MODULES, _EXPORTS)
