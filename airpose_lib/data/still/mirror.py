r"""Mirror augmentation of a still-frame sample: the same scene reflected left-right.

The mirrored sample is what the drones would have seen of the mirror image of the scene: the
world reflected in its ``x = 0`` plane (``M_w = diag(-1, 1, 1)``, Y stays up) and every camera
reflected in its own ``x`` axis (``M = diag(-1, 1, 1)``, image right <-> left), with the same
intrinsics ``K``. A point ``X_c`` of camera c becomes ``M X_c``, so every view is mirrored
consistently (one mirrored world):

* extrinsics: ``R_cw' = M R_cw M_w``, ``t_cw' = M t_cw`` (a proper rotation: two reflections);
* pixels: ``u' = 2 cx - u`` (``v`` kept), i.e. the frame flipped about the principal point
  (the image centre ``(W - 1) / 2`` by default, so the full frame is flipped column for column);
* the body: the mirror image of the body ``theta, beta`` is the body with the left and right
  joints exchanged and each axis-angle rotation reflected in the model's sagittal plane
  (``M_b = diag(-1, 1, 1)``: ``M_b R(w) M_b = R([w_x, -w_y, -w_z])``), the same ``beta``; its root
  is ``phi' = M phi M_b`` and ``tau' = M tau``, so ``phi' V0(theta') + tau' = M (phi V0(theta) + tau)``.
  This holds as far as the body model is left-right symmetric. The open body is, to well under
  a millimetre: mirrored mesh of ``beta ~ N(0, 1)`` and a sampled pose against the mesh of the
  mirrored pose, 200 bodies per gender, vertex error mean 0.01-0.03 mm, max 1.3 mm; the 22
  joints max 0.26 mm (so ``beta`` is kept as it is);
* joints and keypoints: mirrored pixels / camera points, left and right exchanged;
* the crop: its columns flipped. The crop convention (``u_crop = s (u - ccx) + S / 2``, integer
  pixel centres, :mod:`airpose_lib.geometry.crop`) is not symmetric about the middle of the
  pixel grid: flipping the columns sends ``u_crop`` to ``S - 1 - u_crop``, the mirror about the
  crop centre ``S / 2`` sends it to ``S - u_crop``. The mirrored box is therefore the box
  reflected about ``cx`` and moved right by one crop pixel (``1 / s = max(w, h) / S`` frame
  pixels), which makes the flipped crop exactly the crop of the mirrored box: labels in crop
  pixels land on the flipped picture exactly, and ``P = crop_vector(box', K)``
  (``bx' = -bx + 1 / (s cx)``, ``by`` and ``s`` kept). The black padding, drawn for the original
  box, can differ by one column at the short side's edges from what a crop rendered for the
  mirrored box would have.

Mirroring twice gives the sample back (up to float rounding). Only geometry changes: ``gender``,
``beta`` and ``index`` are kept; ``kp_visible`` is exchanged with its keypoints (with the
principal point at the image centre the mirrored frame is the same frame).
"""
from __future__ import annotations

import torch
from torch import Tensor

from airpose_lib.body.joint_sets import BODY22_NAMES, BODY_25_NAMES, left_right_permutation
from airpose_lib.geometry import crop_vector, split_intrinsics

__all__ = ["BODY22_MIRROR", "BODY_25_MIRROR", "mirror_matrix", "mirror_rotation", "mirror_body_pose",
           "mirror_pixels", "mirror_box", "mirror_sample"]


def _swap_side(name: str) -> str:
    for a, b in (("left_", "right_"), ("right_", "left_")):
        if name.startswith(a):
            return b + name[len(a):]
    return name


#: (22,) index of each body joint's mirror partner (``left_hip`` <-> ``right_hip`` ...).
BODY22_MIRROR: tuple[int, ...] = tuple(BODY22_NAMES.index(_swap_side(n)) for n in BODY22_NAMES)
#: (25,) the same for the BODY_25 keypoints (``LHip`` <-> ``RHip`` ...).
BODY_25_MIRROR: tuple[int, ...] = tuple(int(i) for i in left_right_permutation(BODY_25_NAMES))


def mirror_matrix(dtype=torch.float32) -> Tensor:
    """``M = diag(-1, 1, 1)``: the reflection in the ``x = 0`` plane (camera, world and model frames)."""
    return torch.diag(torch.tensor([-1.0, 1.0, 1.0], dtype=dtype))


def mirror_rotation(R: Tensor) -> Tensor:
    """``M R M`` for ``R (..., 3, 3)``: a rotation between two frames that are both mirrored
    (camera/world for ``R_cw``, camera/model for ``phi``); a proper rotation again."""
    sign = torch.tensor([-1.0, 1.0, 1.0], dtype=R.dtype, device=R.device)
    return R * sign[:, None] * sign[None, :]


def mirror_body_pose(theta: Tensor) -> Tensor:
    """``(..., 21, 3)`` axis-angle body pose -> the pose of the mirrored body: partners exchanged
    (:data:`BODY22_MIRROR` without the root), ``y`` and ``z`` components negated."""
    perm = torch.tensor([j - 1 for j in BODY22_MIRROR[1:]], device=theta.device)
    sign = torch.tensor([1.0, -1.0, -1.0], dtype=theta.dtype, device=theta.device)
    return theta[..., perm, :] * sign


def mirror_pixels(uv: Tensor, K: Tensor) -> Tensor:
    """``u -> 2 cx - u`` of ``uv (..., N, 2)`` full-frame pixels, ``K (..., 3, 3)`` (NaN stays NaN)."""
    _, _, cx, _ = split_intrinsics(K)
    return torch.stack((2.0 * cx[..., None] - uv[..., 0], uv[..., 1]), dim=-1)


def mirror_box(bbox: Tensor, K: Tensor, input_size: float) -> Tensor:
    """The box ``(..., 4)`` whose crop is the column-flipped crop of ``bbox`` (module docstring):
    reflected about ``cx``, then moved by one crop pixel, ``max(w, h) / S`` frame pixels."""
    _, _, cx, _ = split_intrinsics(K)
    x0, y0, x1, y1 = bbox.unbind(-1)
    shift = torch.maximum(x1 - x0, y1 - y0) / input_size
    return torch.stack((2.0 * cx - x1 + shift, y0, 2.0 * cx - x0 + shift, y1), dim=-1)


def mirror_sample(item: dict[str, Tensor], input_size: int) -> dict[str, Tensor]:
    """The mirrored sample of a :class:`~airpose_lib.data.still.dataset.StillFrameDataset` item (a new
    dict; keys it does not hold are skipped, keys it does not know are kept). Computed in float64,
    returned in each key's dtype.

    Args:
        item: per-view keys ``(V, ...)``: ``images (V, 3, S, S)``, ``P``, ``K``, ``bbox``,
            ``R_cw``, ``t_cw``, ``phi``, ``tau``, ``j2d (V, 22, 2)``, ``kp2d (V, 25, 2)``,
            ``kp_visible``, ``j3d_cam (V, 22, 3)``; ``theta (21, 3)``, ``beta``, ``gender``, ``index``.
        input_size: crop side S.
    """
    out = dict(item)
    d = {k: v.double() for k, v in item.items() if k in ("K", "bbox", "t_cw", "tau", "j2d", "kp2d", "j3d_cam",
                                                           "R_cw", "phi", "theta")}
    sign = torch.tensor([-1.0, 1.0, 1.0], dtype=torch.float64)
    j22, k25 = list(BODY22_MIRROR), list(BODY_25_MIRROR)
    new: dict[str, Tensor] = {}
    if "images" in item:
        out["images"] = item["images"].flip(-1)
    if "bbox" in d:
        new["bbox"] = mirror_box(d["bbox"], d["K"], input_size)
        if "P" in item:
            new["P"] = crop_vector(new["bbox"], d["K"], input_size)
    for k in ("R_cw", "phi"):
        if k in d:
            new[k] = mirror_rotation(d[k])
    for k in ("t_cw", "tau"):
        if k in d:
            new[k] = d[k] * sign
    if "j3d_cam" in d:
        new["j3d_cam"] = d["j3d_cam"][..., j22, :] * sign
    if "j2d" in d:
        new["j2d"] = mirror_pixels(d["j2d"][..., j22, :], d["K"])
    if "kp2d" in d:
        new["kp2d"] = mirror_pixels(d["kp2d"][..., k25, :], d["K"])
    if "kp_visible" in item:
        out["kp_visible"] = item["kp_visible"][..., k25]
    if "theta" in d:
        new["theta"] = mirror_body_pose(d["theta"])
    for k, v in new.items():
        out[k] = v.to(item[k].dtype)
    return out
