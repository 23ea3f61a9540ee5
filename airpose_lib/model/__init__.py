"""The AirPose network: ResNet backbone, HMR-style iterative regressor, the four ablation
variants, per-drone staged execution and ONNX export.

Imports only ``geometry`` and ``body`` from the kit (and onnxruntime lazily, for ONNX runs).
"""
from .backbone import BACKBONES, BasicBlock, Bottleneck, ResNet, build_backbone, resnet18, resnet34, resnet50
from .regressor import DECODER_GAIN, HIDDEN_WIDTH, IterativeRegressor
from .onnx_export import OnnxDroneNode, export_onnx
from .record import NetworkRecord, network_record, read_network
from .official import load_official_checkpoint, to_official_state_dict, write_official_checkpoint
from .smplx_params import posed_joints_and_vertices, to_smplx_params
from .staged import DroneNode, decode_message, encode_message, fuse_message_list, message_nbytes
from .variants import (
    BETA_DIM,
    MESSAGE_DIM,
    NUM_BODY_JOINTS,
    STATE_DIM,
    TAU_INIT,
    TAU_SCALE,
    THETA_DIM,
    VARIANTS,
    WEAK_CAM_INIT,
    AirPoseNet,
    MeanParams,
    VariantSpec,
    build_model,
    convert_official_state_dict,
    decode_state,
    default_mean_params,
    fc1_input_width,
    fuse_messages,
    load_mean_params,
    state_keys,
    unpack_state,
)

__all__ = [name for name in dir() if not name.startswith("_")]
