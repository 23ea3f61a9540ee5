"""Geometry core: rotations, pinhole camera, person crop (paper eq. 1-2) and rigid transforms.

Depends only on torch, roma, numpy and OpenCV (the image crop); imports nothing else from the kit.
"""

from .camera import intrinsics_matrix, project_points, split_intrinsics, transform_points
from .crop import (
    box_in_crop,
    crop_affine_matrix,
    crop_from_image,
    crop_intrinsics,
    crop_to_full_pixels,
    crop_to_full_translation,
    crop_vector,
    full_to_crop_pixels,
    full_to_crop_translation,
    pad_outside_box,
    translation_to_weak_perspective,
    virtual_box,
    virtual_camera_map,
    virtual_crop,
    weak_perspective_to_translation,
)
from .rotations import (
    axis_angle_to_matrix,
    axis_angle_to_rot6d,
    geodesic_angle,
    heading_of,
    matrix_to_axis_angle,
    matrix_to_rot6d,
    rot6d_to_axis_angle,
    rot6d_to_matrix,
)
from .transforms import (
    apply_transform,
    body_in_camera,
    camera_center,
    compose,
    invert_transform,
    make_transform,
    relative_camera_pose,
    split_transform,
)

__all__ = [
    # rotations
    "rot6d_to_matrix",
    "matrix_to_rot6d",
    "axis_angle_to_matrix",
    "matrix_to_axis_angle",
    "axis_angle_to_rot6d",
    "rot6d_to_axis_angle",
    "geodesic_angle",
    "heading_of",
    # camera
    "intrinsics_matrix",
    "split_intrinsics",
    "project_points",
    "transform_points",
    # crop
    "crop_vector",
    "crop_affine_matrix",
    "crop_intrinsics",
    "full_to_crop_pixels",
    "crop_to_full_pixels",
    "crop_to_full_translation",
    "full_to_crop_translation",
    "weak_perspective_to_translation",
    "translation_to_weak_perspective",
    "virtual_camera_map",
    "virtual_box",
    "virtual_crop",
    "box_in_crop",
    "pad_outside_box",
    "crop_from_image",
    # transforms
    "make_transform",
    "split_transform",
    "invert_transform",
    "compose",
    "apply_transform",
    "body_in_camera",
    "relative_camera_pose",
    "camera_center",
]
