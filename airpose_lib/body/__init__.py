"""Body models: the open anny-derived SMPL-X-format model, the licensed SMPL-X, joint sets and a
joints-only fast path. Everything is consumed through the ``smplx`` API."""
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
from .pose import axis_angle, body_pose_from_joints, pose_at_origin

__all__ = [name for name in dir() if not name.startswith("_")]
