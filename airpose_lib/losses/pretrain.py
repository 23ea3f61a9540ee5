"""The variant-neutral objective of the shared pretrained backbone (:mod:`airpose_lib.model.pretrain`).

Every term compares one head with the sample's ground truth, per crop (the views of a sample are
independent crops here; nothing couples them):

``heading``  cross-entropy of the heading class (:func:`heading_bin`)
``phi``      ``||R(phi6d) - phi||^2`` on rotation matrices (mean over entries), or with
             ``phi_loss="geodesic"`` the geodesic angle between them in radians
``theta``    ``||R(theta6d) - theta||^2`` on the 21 body rotations
``beta``     ``||beta - beta_gt||^2``
``j3d``      ``||J - J_gt||^2`` joints of the gendered ground-truth body, metres: in the model frame
             (identity root), or with ``j3d_frame="camera"`` turned by the view's root rotation
             ``phi`` and centred on the pelvis (what the crop shows)
``j2d``      ``||u - u_gt||^2`` joints in the crop normalised to [-1, 1]
``stature``  (only with ``w_stature > 0``; the network's ``body_scalars`` heads) ``(s - (h -
             stature_mean) / stature_scale)^2``, ``h`` the height of the subject's T-posed
             gendered body (its beta), metres
``gender``   (only with ``w_gender > 0``) binary cross-entropy of the ``female`` logit

Why the two options: with the defaults the root orientation is learnt from a weak signal. At a
14 deg root error the matrix MSE is about 0.013 (against about 0.8 nats of the heading classes),
and model-frame joints carry no root information at all. The geodesic angle is 0.24 rad there,
and camera-frame joints move by about 0.1 m, so both terms keep pulling where the MSE has gone
flat.

No term uses the crop vector P, the translation or the other view, so no variant of the ablation
is favoured by the starting point they share.
"""
from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import asdict, dataclass

import torch
from torch import Tensor, nn
from torch.nn import functional as F

from airpose_lib.body.genders import GENDER_CODES
from airpose_lib.body.loader import stature
from airpose_lib.errors import ConfigError
from airpose_lib.geometry import (
    axis_angle_to_matrix,
    full_to_crop_pixels,
    geodesic_angle,
    heading_of,
    rot6d_to_matrix,
)

from .supervised import SupervisedLoss

__all__ = ["PretrainLossConfig", "PretrainLoss", "camera_frame_joints", "heading_of", "heading_bin"]


# The classes of the heading head: defined here, with the objective that trains it (the network
# only knows how many classes it has); the heading itself is geometry's (the evaluation's yaw
# error reads it too).
def heading_bin(phi: Tensor, n_bins: int) -> Tensor:
    """Class index ``(...)`` int64 of :func:`heading_of` in ``n_bins`` equal bins of ``(-pi, pi]``."""
    h = heading_of(phi)
    return torch.floor((h + math.pi) / (2 * math.pi) * n_bins).long().clamp_(0, n_bins - 1)


def camera_frame_joints(J: Tensor, phi: Tensor) -> Tensor:
    """Model-frame joints as the camera sees them, up to translation: ``phi (J - J_pelvis)``.

    Args:
        J: ``(..., K, 3)`` joints of the body with identity root (joint 0 the pelvis).
        phi: ``(..., 3, 3)`` root rotation, model -> camera.

    Returns:
        ``(..., K, 3)`` pelvis-centred joints in the camera's axes.
    """
    return (J - J[..., :1, :]) @ phi.transpose(-1, -2)


@dataclass(frozen=True)
class PretrainLossConfig:
    """Term weights (chosen so that every term starts at a comparable size: errors of about 90
    degrees, 0.1 m and a tenth of the crop) and the form of the root terms.

    Attributes:
        phi_loss: ``"mse"`` (matrix entries) or ``"geodesic"`` (angle, radians).
        j3d_frame: ``"model"`` (identity root) or ``"camera"`` (turned by the view's ``phi``,
            pelvis-centred).
        w_stature, w_gender: weights of the stature and gender terms (0: not computed; the
            network then needs no ``stature``/``female`` heads).
        stature_mean, stature_scale: the stature head reads ``(h - mean) / scale`` (metres), so
            that an untrained head starts at a term of about 1.
    """

    w_heading: float = 1.0
    w_phi: float = 1.0
    w_theta: float = 10.0
    w_beta: float = 0.1
    w_j3d: float = 100.0
    w_j2d: float = 10.0
    phi_loss: str = "mse"
    j3d_frame: str = "model"
    w_stature: float = 0.0
    w_gender: float = 0.0
    stature_mean: float = 1.72
    stature_scale: float = 0.1

    def __post_init__(self) -> None:
        if self.stature_scale <= 0:
            raise ConfigError(f"loss.stature_scale must be positive, got {self.stature_scale}")
        if self.phi_loss not in ("mse", "geodesic"):
            raise ConfigError(f"loss.phi_loss must be 'mse' or 'geodesic', got {self.phi_loss!r}")
        if self.j3d_frame not in ("model", "camera"):
            raise ConfigError(f"loss.j3d_frame must be 'model' or 'camera', got {self.j3d_frame!r}")

    def to_dict(self) -> dict:
        return asdict(self)


class PretrainLoss(nn.Module):
    """Loss of :class:`~airpose_lib.model.pretrain.PretrainNet` on a still-frame batch.

    Args:
        config: weights (default :class:`PretrainLossConfig`).
        body_models: gender name -> ``smplx.SMPLX`` (ground-truth joints); default loaded from
            ``source``.
        source: body-model source (``open`` or ``smplx``).
    """

    def __init__(self, config: PretrainLossConfig | None = None, body_models: Mapping | None = None,
                 source: str = "open") -> None:
        super().__init__()
        self.config = config or PretrainLossConfig()
        # The supervised loss's gendered ground-truth body, without its vertices.
        self.gt = SupervisedLoss(body_models=body_models, source=source)

    @torch.no_grad()
    def rest_stature(self, beta: Tensor, gender: Tensor | None) -> Tensor:
        """Height ``(B,)`` in metres of each subject's T-posed gendered body (float32, autocast off)."""
        with torch.autocast(beta.device.type, enabled=False):
            beta = beta.float()
            identity = torch.eye(3, dtype=beta.dtype, device=beta.device).expand(len(beta), 21, 3, 3)
            _, vertices = self.gt.ground_truth_body(identity, beta, gender, vertices=True)
        return stature(vertices)

    def forward(self, out: Mapping[str, Tensor], batch: Mapping[str, Tensor], n_bins: int) -> dict[str, Tensor]:
        """Terms and their weighted ``total``.

        Args:
            out: heads of ``B * V`` crops (``PretrainNet.forward`` on the flattened views).
            batch: ``phi (B, V, 3, 3)``, ``theta (B, 21, 3)``, ``beta (B, 10)``, ``gender (B,)``,
                ``j2d (B, V, 22, 2)``, ``bbox (B, V, 4)``, ``images (B, V, 3, S, S)``.
            n_bins: heading classes.
        """
        c = self.config
        B, V = batch["phi"].shape[:2]
        S = batch["images"].shape[-1]
        dtype = out["phi6d"].dtype
        flat = lambda x: x.reshape(B * V, *x.shape[2:]).to(dtype)  # noqa: E731
        phi = flat(batch["phi"])
        theta = axis_angle_to_matrix(batch["theta"].to(dtype))  # (B, 21, 3, 3)
        with torch.no_grad():
            J0, _ = self.gt.ground_truth_body(theta, batch["beta"].to(dtype), batch.get("gender"), vertices=False)
        rep = lambda x: x.unsqueeze(1).expand(B, V, *x.shape[1:]).reshape(B * V, *x.shape[1:])  # noqa: E731
        uv = full_to_crop_pixels(batch["j2d"].to(dtype), batch["bbox"].to(dtype), S) / (0.5 * S) - 1.0
        R_phi = rot6d_to_matrix(out["phi6d"])
        J = rep(J0)  # (B * V, 22, 3)
        if c.j3d_frame == "camera":
            J = camera_frame_joints(J, phi)
        terms = {
            "heading": F.cross_entropy(out["heading"], heading_bin(phi, n_bins)),
            "phi": geodesic_angle(R_phi, phi).mean() if c.phi_loss == "geodesic" else (R_phi - phi).square().mean(),
            "theta": (rot6d_to_matrix(out["theta6d"]) - rep(theta)).square().mean(),
            "beta": (out["beta"] - rep(batch["beta"].to(dtype))).square().mean(),
            "j3d": (out["j3d"] - J).square().mean(),
            "j2d": (out["j2d"] - flat(uv)).square().mean(),
        }
        w = {"heading": c.w_heading, "phi": c.w_phi, "theta": c.w_theta, "beta": c.w_beta, "j3d": c.w_j3d,
             "j2d": c.w_j2d}
        if c.w_stature > 0:
            h = rep(self.rest_stature(batch["beta"], batch.get("gender")))
            target = ((h - c.stature_mean) / c.stature_scale).to(dtype)
            terms["stature"] = (out["stature"].reshape(B * V) - target).square().mean()
            w["stature"] = c.w_stature
        if c.w_gender > 0:
            female = rep((batch["gender"] == GENDER_CODES["female"]).to(dtype))
            terms["gender"] = F.binary_cross_entropy_with_logits(out["female"].reshape(B * V), female)
            w["gender"] = c.w_gender
        return {"total": sum(w[k] * terms[k] for k in terms), **terms}

