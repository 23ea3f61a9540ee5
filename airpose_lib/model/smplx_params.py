"""Network output -> camera-frame SMPL-X parameters -> posed joints and vertices.

The paper's body convention: SMPL-X is evaluated with the 21 predicted body rotations theta,
the betas, **identity** global orientation and zero translation (neutral model, flat hands),
giving ``V0``; the root rotation phi and translation tau of a view are then applied about the
model origin,

    V = phi V0 + tau        (the same for the joints),

which differs from smplx's own ``global_orient``/``transl`` (that rotates about the pelvis joint).
"""
from __future__ import annotations

import weakref
from collections.abc import Mapping

import torch
from smplx.lbs import batch_rodrigues, lbs
from torch import Tensor

from ..body.fast import JointsOnly
from ..geometry import rot6d_to_matrix, weak_perspective_to_translation

__all__ = ["to_smplx_params", "posed_joints_and_vertices"]


def to_smplx_params(out: Mapping, P: Tensor, K: Tensor, input_size: int | None = None) -> dict[str, Tensor]:
    """Any variant's output -> camera-frame SMPL-X parameters.

    Args:
        out: network output (``AirPoseNet.forward`` or ``DroneNode.result``): phi6d (..., 6),
            theta6d (..., 21, 6), beta (..., 10), and cam (..., 3) (weak variants) or tau (..., 3).
        P: ``(..., 3)`` crop vectors ``[bx, by, s]`` used for the crops.
        K: ``(..., 3, 3)`` full-image intrinsics.
        input_size: crop side S in pixels; default ``out["input_size"]`` (or 224).

    Returns:
        dict with phi (..., 3, 3), theta (..., 21, 3, 3), beta (..., 10), tau (..., 3) metres in
        the full camera frame. For the weak-camera variants tau comes from the weak camera by
        ``geometry.weak_perspective_to_translation`` (always recomputed from cam with this K).
    """
    phi = rot6d_to_matrix(out["phi6d"])
    theta = rot6d_to_matrix(out["theta6d"])
    if "cam" in out:
        size = input_size if input_size is not None else int(out.get("input_size", 224))
        cam = out["cam"]
        tau = weak_perspective_to_translation(cam, P.to(cam.dtype), K.to(cam.dtype), size)
    else:
        tau = out["tau"]
    return {"phi": phi, "theta": theta, "beta": out["beta"], "tau": tau}


# One JointsOnly per body model (it precomputes regressed joints and keypoint-vertex data).
_JOINTS_ONLY: "weakref.WeakKeyDictionary" = weakref.WeakKeyDictionary()


def _joints_only(body_model) -> JointsOnly:
    cached = _JOINTS_ONLY.get(body_model)
    ref = body_model.v_template
    if cached is None or cached.J_template.dtype != ref.dtype or cached.J_template.device != ref.device:
        cached = JointsOnly(body_model)
        _JOINTS_ONLY[body_model] = cached
    return cached


def _full_rotmats(body_model, theta: Tensor) -> Tensor:
    """(N, 21, 3, 3) body rotations -> (N, 55, 3, 3): identity root, theta, then jaw, eyes and
    hands at the model's mean pose (identity for the flat-hand models the kit loads)."""
    N = theta.shape[0]
    eye = torch.eye(3, dtype=theta.dtype, device=theta.device).expand(N, 1, 3, 3)
    rest_aa = body_model.pose_mean[66:].to(theta.dtype).reshape(-1, 3)  # jaw, eyes, 2 x 15 hand
    rest = batch_rodrigues(rest_aa).expand(N, -1, 3, 3)
    return torch.cat((eye, theta, rest), dim=1)


def posed_joints_and_vertices(body_model, params: Mapping[str, Tensor],
                              joints_only: bool = False) -> dict[str, Tensor]:
    """Evaluate the body model with the paper's convention ``X = phi X0 + tau``.

    Args:
        body_model: ``smplx.SMPLX`` from ``airpose_lib.body.load_body_model`` (its dtype is used).
        params: phi (..., 3, 3), theta (..., 21, 3, 3), beta (..., 10), tau (..., 3)
            (:func:`to_smplx_params`). phi and tau may be omitted (identity, zero), giving the
            root-relative body used by the 3D joint and vertex losses.
        joints_only: skip the mesh (``body.fast.JointsOnly``; much faster).

    Returns:
        dict with joints (..., 76, 3) (55 skeleton joints, then the 21 keypoint vertices; no face
        landmarks) and, unless joints_only, vertices (..., V, 3). Metres, camera frame.
    """
    theta = params["theta"]
    batch = theta.shape[:-3]
    dtype = body_model.v_template.dtype
    theta = theta.reshape(-1, 21, 3, 3).to(dtype)
    N = theta.shape[0]
    betas = params["beta"].reshape(N, -1).to(dtype)
    rotmats = _full_rotmats(body_model, theta)
    if joints_only:
        joints = _joints_only(body_model).forward_rotmat(rotmats, betas)
        result = {"joints": joints}
    else:
        n_expr = body_model.expr_dirs.shape[-1]
        shape = torch.cat((betas, betas.new_zeros(N, n_expr)), dim=-1)
        shapedirs = torch.cat((body_model.shapedirs, body_model.expr_dirs), dim=-1)
        verts, joints = lbs(shape, rotmats, body_model.v_template, shapedirs, body_model.posedirs,
                            body_model.J_regressor, body_model.parents, body_model.lbs_weights,
                            pose2rot=False)
        joints = body_model.vertex_joint_selector(verts, joints)  # + the 21 keypoint vertices
        result = {"joints": joints, "vertices": verts}
    phi, tau = params.get("phi"), params.get("tau")
    for key, X in result.items():
        if phi is not None:
            X = X @ phi.reshape(N, 3, 3).to(dtype).transpose(-1, -2)
        if tau is not None:
            X = X + tau.reshape(N, 1, 3).to(dtype)
        result[key] = X.reshape(*batch, *X.shape[-2:])
    return result
