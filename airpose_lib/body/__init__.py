"""Body models: the open anny-derived SMPL-X-format model, the licensed SMPL-X, joint sets, the
gender codes, and their evaluation in the paper's root convention (``forward``: mesh, joints,
keypoint vertices). Models are loaded through the ``smplx`` API.

Names are imported lazily from their modules, so the light ones (``genders``, ``joint_sets``)
can be used without importing torch and smplx (``data.still.scene`` and a drone's start-up need that).
"""
from __future__ import annotations

from airpose_lib._lazy import lazy_namespace

_MODULES = ("genders", "joint_sets", "loader", "open_model", "pose", "forward")
_EXPORTS = {
    **dict.fromkeys(("GENDERS", "GENDER_CODES", "GENDER_NAMES"), "genders"),
    **dict.fromkeys(("BODY22_NAMES", "BODY_25_EDGES", "BODY_25_FROM_SMPLX", "BODY_25_NAMES", "COCO17_FROM_SMPLX",
                     "COCO17_NAMES", "COCO18_FROM_SMPLX", "COCO18_NAMES", "EXTRA_JOINT_NAMES", "NUM_BODY_JOINTS",
                     "NUM_POSE_JOINTS", "OUTPUT_JOINT_NAMES", "SMPLX_JOINT_NAMES", "SMPLX_PARENTS", "joint_index"),
                    "joint_sets"),
    **dict.fromkeys(("BodyModelError", "body_model_info", "check_model_file", "load_body_model", "open_model_texture",
                     "resolve_model_file", "stature"), "loader"),
    **dict.fromkeys(("build_open_model", "open_model_path"), "open_model"),
    **dict.fromkeys(("axis_angle", "body_pose_from_joints", "pose_at_origin"), "pose"),
    **dict.fromkeys(("BodyForward", "NUM_SKELETON_JOINTS", "axis_angle_rotations", "cached_body", "rest_body"),
                    "forward"),
}

__all__ = sorted(_EXPORTS)
__getattr__, __dir__ = lazy_namespace(__name__, globals(), _MODULES, _EXPORTS)
