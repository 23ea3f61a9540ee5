"""Network output -> camera-frame SMPL-X parameters -> posed joints and vertices.

The paper's body convention: SMPL-X is evaluated with the 21 predicted body rotations theta,
the betas, **identity** global orientation and zero translation (neutral model, flat hands),
giving ``V0``; the root rotation phi and translation tau of a view are then applied about the
model origin,

    V = phi V0 + tau        (the same for the joints),

which differs from smplx's own ``global_orient``/``transl`` (that rotates about the pelvis joint).
"""
from __future__ import annotations

from collections.abc import Mapping

from torch import Tensor

from ..body.forward import cached_body
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


def posed_joints_and_vertices(body_model, params: Mapping[str, Tensor],
                              joints_only: bool = False) -> dict[str, Tensor]:
    """Evaluate the body model with the paper's convention ``X = phi X0 + tau``.

    An adapter of :class:`airpose_lib.body.forward.BodyForward` for the parameter dicts of
    :func:`to_smplx_params` (any leading dims, any float dtype: evaluation code passes network
    outputs straight in).

    Args:
        body_model: ``smplx.SMPLX`` from ``airpose_lib.body.load_body_model`` (its dtype is used).
        params: phi (..., 3, 3), theta (..., 21, 3, 3), beta (..., 10), tau (..., 3)
            (:func:`to_smplx_params`). phi and tau may be omitted (identity, zero), giving the
            root-relative body used by the 3D joint and vertex losses.
        joints_only: skip the mesh (much faster).

    Returns:
        dict with joints (..., 76, 3) (55 skeleton joints, then the 21 keypoint vertices; no face
        landmarks) and, unless joints_only, vertices (..., V, 3). Metres, camera frame.
    """
    body = cached_body(body_model, mesh=not joints_only)
    dtype = body.J_template.dtype
    theta = params["theta"]
    batch = theta.shape[:-3]
    N = batch.numel()
    cast = lambda key, *shape: (params[key].reshape(N, *shape).to(dtype)  # noqa: E731
                                if params.get(key) is not None else None)
    joints, verts = body(cast("theta", 21, 3, 3), cast("beta", -1), cast("phi", 3, 3), cast("tau", 3),
                         vertices=not joints_only)
    result = {"joints": joints.reshape(*batch, *joints.shape[-2:])}
    if verts is not None:
        result["vertices"] = verts.reshape(*batch, *verts.shape[-2:])
    return result
