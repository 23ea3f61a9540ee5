r"""The fine-tuning loss on 2D detections (paper Sec. IV, real data; no 3D ground truth).

Terms (pred = the network's camera-frame parameters per view, neutral body, the paper's
convention ``X = phi X0(theta, beta) + tau``; each term is a mean over the batch and the elements
of one view, reduced over the views like the supervised loss: summed for the multi-view variants
(paper eq. 4, ``sum_c``), averaged for the monocular ones):

``j2d``     ``w (u - u_hat)^2``: the BODY_25 keypoints of the predicted body (55 SMPL-X joints +
            keypoint vertices via :class:`~airpose_lib.body.forward.BodyForward`, selected by
            ``BODY_25_FROM_SMPLX``) projected with each view's full-image ``K``, against the
            targets of :func:`~airpose_lib.finetune.keypoints.agreement_targets`; ``w`` =
            OpenPose confidence, 0 for dropped joints (they still count in the mean, as the
            official code's ``(MSE * conf).mean()``). Pixels squared, at the reference resolution
            when ``pixel_scale`` is given (residuals divided by each view's ``r = width / 1920``,
            i.e. ``w_j2d / r^2``: the paper's weight means the same on a half-resolution frame).
``beta``    ``||beta||^2`` (L2 shape prior); with ``cross_view_beta`` plus
            ``||1beta - 2beta||^2`` (the official code's beta term).
``vposer``  ``||z||^2`` of the VPoser encoding of the predicted body pose ``theta`` (axis-angle
            into the encoder). ``vposer_latent="sample"`` (default) draws ``z ~ q(z | theta)``
            with the reparameterisation trick, as the paper ("a sample of the encoded pose") and
            the official code; this also penalises poses the encoder is unsure about (a large
            posterior spread adds ``E||z||^2 = ||mu||^2 + sum sigma^2``). ``"mean"`` uses the
            posterior mean: deterministic, for evaluation.
``theta``   cross-view consistency ``||1theta - 2theta||^2`` of the 21 body rotation matrices
            (mean over view pairs; 0 with one view). Root rotation and translation differ between
            views by construction and are not compared.
``depth``   ``exp(-tz)^2`` per view: the official code's extra term that keeps the person in front
            of the cameras (weight 0 by default; 1 in :func:`finetune_loss_config` ``official=True``).

``total = total_scale * sum_k w_k term_k``. Paper weights: Baseline ``w_j2d 0.01, w_beta 5,
w_vposer 1``; AirPose ``w_j2d 0.01, w_beta 5, w_vposer 0.1, w_theta 100`` (+ the cross-view beta
term). The paper gives no fine-tuning weights for the two middle ablation rows; the kit gives
Multi-view AirPose's and Fullcam AirPose's without the cross-view terms (as its supervised
configs do). ``official=True``: the official code's total x 60 and depth term.
"""
from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Literal

import torch
from torch import Tensor, nn

from airpose_lib.body import load_body_model
from airpose_lib.body.joint_sets import BODY_25_FROM_SMPLX
from airpose_lib.errors import ConfigError
from airpose_lib.geometry import matrix_to_axis_angle, project_points
from airpose_lib.losses import cross_view_mse, view_mse
from airpose_lib.model import posed_joints_and_vertices
from airpose_lib.prior import load_prior

__all__ = ["FineTuneLossConfig", "FINETUNE_LOSS_DEFAULTS", "finetune_loss_config", "FineTuneLoss"]

_DEPTH_CLAMP = 10.0  # metres behind the camera at which exp(-tz) stops growing (e^20 is finite in float32)


@dataclass(frozen=True)
class FineTuneLossConfig:
    """Weights and options of :class:`FineTuneLoss` (defaults: the paper's Baseline).

    Attributes:
        w_j2d, w_beta, w_vposer, w_theta, w_depth: term weights (see the module docstring).
        cross_view_beta: add ``||1beta - 2beta||^2`` to the beta term.
        vposer_latent: ``"sample"`` (paper, official code) or ``"mean"``.
        view_reduction: ``"sum"`` (multi-view variants) or ``"mean"`` over the views.
        total_scale: multiplies the total (official code: 60).
        min_depth: depth floor (m) before dividing when projecting (a prediction behind a camera
            gives large but finite pixels).
    """

    w_j2d: float = 0.01
    w_beta: float = 5.0
    w_vposer: float = 1.0
    w_theta: float = 0.0
    w_depth: float = 0.0
    cross_view_beta: bool = False
    vposer_latent: Literal["sample", "mean"] = "sample"
    view_reduction: Literal["sum", "mean"] = "mean"
    total_scale: float = 1.0
    min_depth: float = 0.1

    def __post_init__(self) -> None:
        if self.vposer_latent not in ("sample", "mean"):
            raise ConfigError(f"vposer_latent must be 'sample' or 'mean', got {self.vposer_latent!r}")
        if self.view_reduction not in ("sum", "mean"):
            raise ConfigError(f"view_reduction must be 'sum' or 'mean', got {self.view_reduction!r}")

    @property
    def weights(self) -> dict[str, float]:
        return {"j2d": self.w_j2d, "beta": self.w_beta, "vposer": self.w_vposer, "theta": self.w_theta,
                "depth": self.w_depth}

    def to_dict(self) -> dict:
        return dataclasses.asdict(self)


_AIRPOSE = dict(w_vposer=0.1, w_theta=100.0, cross_view_beta=True, view_reduction="sum")
FINETUNE_LOSS_DEFAULTS: dict[str, dict] = {
    "baseline": {},
    "multiview": dict(_AIRPOSE),
    "fullcam": dict(w_vposer=0.1),
    "airpose": dict(_AIRPOSE),
}
"""Per network variant: the fields that differ from :class:`FineTuneLossConfig`'s defaults."""


def finetune_loss_config(variant: str, official: bool = False, **overrides) -> FineTuneLossConfig:
    """The fine-tuning loss of a variant (``baseline``, ``multiview``, ``fullcam``, ``airpose``),
    optionally with the official code's total x 60 and depth term, then ``overrides``."""
    if variant not in FINETUNE_LOSS_DEFAULTS:
        raise ValueError(f"unknown variant {variant!r}; one of {tuple(FINETUNE_LOSS_DEFAULTS)}")
    values = dict(FINETUNE_LOSS_DEFAULTS[variant])
    if official:
        values.update(total_scale=60.0, w_depth=1.0)
    values.update(overrides)
    names = {f.name for f in dataclasses.fields(FineTuneLossConfig)}
    unknown = sorted(set(values) - names)
    if unknown:
        raise ConfigError(f"unknown fine-tuning loss option(s) {unknown}; known: {sorted(names)}")
    return FineTuneLossConfig(**values)


class FineTuneLoss(nn.Module):
    """Fine-tuning loss terms on 2D targets.

    Args:
        config: a :class:`FineTuneLossConfig` (e.g. :func:`finetune_loss_config`).
        body_model: the neutral ``smplx.SMPLX`` of the predictions (default: the open model).
        prior: the pose prior (:class:`~airpose_lib.prior.VPoser`; put in eval mode, its weights
            frozen); default ``load_prior("kit")`` when ``w_vposer > 0``, unused otherwise.
    """

    def __init__(self, config: FineTuneLossConfig | None = None, body_model=None, prior=None) -> None:
        super().__init__()
        self.config = config if config is not None else FineTuneLossConfig()
        if body_model is None:
            body_model = load_body_model("open", "neutral")
        self.body_model = body_model
        if prior is None and self.config.w_vposer != 0:
            prior = load_prior("kit")
        if prior is not None:
            prior.eval()  # batch norms on running statistics (B = 1 works), no dropout
            prior.requires_grad_(False)
        self.prior = prior
        self.register_buffer("joint_index", torch.tensor(BODY_25_FROM_SMPLX), persistent=False)

    def train(self, mode: bool = True) -> "FineTuneLoss":
        super().train(mode)
        if self.prior is not None:
            self.prior.eval()  # the prior is never trained here
        return self

    def keypoints3d(self, pred: Mapping[str, Tensor]) -> Tensor:
        """``(..., 25, 3)`` BODY_25 keypoints of the predicted bodies in each camera frame.

        Args:
            pred: phi (..., 3, 3), theta (..., 21, 3, 3), beta (..., 10), tau (..., 3).
        """
        joints = posed_joints_and_vertices(self.body_model, pred, joints_only=True)["joints"]
        return joints[..., self.joint_index, :].to(pred["theta"].dtype)

    def project(self, pred: Mapping[str, Tensor], K: Tensor) -> Tensor:
        """``(B, V, 25, 2)`` predicted BODY_25 keypoints in full-image pixels.

        Args:
            pred: phi (B, V, 3, 3), theta (B, V, 21, 3, 3), beta (B, V, 10), tau (B, V, 3).
            K: ``(V, 3, 3)`` or ``(B, V, 3, 3)`` intrinsics of the views.
        """
        X = self.keypoints3d(pred)  # (B, V, 25, 3)
        # (B, V, 25, 3) @ (V, 3, 3)^T or (B, V, 3, 3)^T: matmul broadcasts either form.
        return project_points(X, K.to(X.dtype), min_depth=self.config.min_depth)

    def latent(self, theta: Tensor) -> Tensor:
        """VPoser latent of body poses ``(..., 21, 3, 3)`` -> ``(..., 32)`` (sample or mean)."""
        lead = theta.shape[:-3]
        aa = matrix_to_axis_angle(theta).reshape(-1, 63)
        q = self.prior.encode(aa.to(next(self.prior.parameters()).dtype))
        z = q.rsample() if self.config.vposer_latent == "sample" else q.loc
        return z.reshape(*lead, -1).to(theta.dtype)

    def forward(self, pred: Mapping[str, Tensor], targets: Tensor, K: Tensor,
                pixel_scale: Tensor | None = None) -> dict[str, Tensor]:
        """Loss terms and their weighted total.

        Args:
            pred: camera-frame parameters per view (``airpose_lib.model.to_smplx_params``):
                phi (B, V, 3, 3), theta (B, V, 21, 3, 3), beta (B, V, 10), tau (B, V, 3).
            targets: ``(B, V, 25, 3)`` ``[x, y, w]`` BODY_25 targets, full-image pixels
                (:func:`~airpose_lib.finetune.keypoints.agreement_targets`); must be finite.
            K: ``(V, 3, 3)`` or ``(B, V, 3, 3)`` full-image intrinsics.
            pixel_scale: optional ``(V,)`` image width / reference width of each view
                (``keypoints.resolution_scales``); the 2D residuals are divided by it.

        Returns:
            ``{"total", "j2d", "beta", "vposer", "theta", "depth"}``: scalars; the terms are
            unweighted, ``total = total_scale * sum_k w_k term_k``.
        """
        c = self.config
        theta, beta, tau = pred["theta"], pred["beta"], pred["tau"]
        if theta.dim() != 5 or theta.shape[2:] != (21, 3, 3):
            raise ValueError(f"pred['theta'] must be (B, V, 21, 3, 3), got {tuple(theta.shape)}")
        B, V = theta.shape[:2]
        if tuple(targets.shape) != (B, V, 25, 3):
            raise ValueError(f"targets must be (B, V, 25, 3) = {(B, V, 25, 3)} [x, y, weight] (BODY_25), "
                             f"got {tuple(targets.shape)}")
        if not torch.isfinite(targets).all():
            raise ValueError("targets contain NaN or inf: build them with agreement_targets, which writes "
                             "(0, 0, 0) for dropped joints")
        if (targets[..., 2] < 0).any():
            raise ValueError("targets have negative weights")
        vr = c.view_reduction
        dtype = theta.dtype
        targets = targets.to(dtype)
        zero = theta.sum() * 0.0
        terms: dict[str, Tensor] = {}
        uv, xy = self.project(pred, K), targets[..., :2]
        if pixel_scale is not None:
            r = torch.as_tensor(pixel_scale, dtype=dtype, device=uv.device).reshape(-1, 1, 1)  # (V, 1, 1)
            if r.shape[0] != V or not bool((r > 0).all()):
                raise ValueError(f"pixel_scale must be ({V},) positive, got {tuple(r.shape)}")
            uv, xy = uv / r, xy / r
        terms["j2d"] = view_mse(uv, xy, targets[..., 2:], vr)
        terms["beta"] = view_mse(beta, torch.zeros_like(beta), view_reduction=vr)
        if c.cross_view_beta:
            terms["beta"] = terms["beta"] + cross_view_mse(beta)
        if c.w_vposer != 0:
            if self.prior is None:
                raise ValueError("w_vposer > 0 needs a pose prior")
            z = self.latent(theta)
            terms["vposer"] = view_mse(z, torch.zeros_like(z), view_reduction=vr)
        else:
            terms["vposer"] = zero
        # Cheap, so always computed: with weight 0 they are diagnostics in the log.
        terms["theta"] = cross_view_mse(theta)
        # exp(-tz) overflows for a body far behind the camera: clamp (the gradient there is huge anyway).
        e = torch.exp(-tau[..., 2:].clamp_min(-_DEPTH_CLAMP))
        terms["depth"] = view_mse(e, torch.zeros_like(e), view_reduction=vr)
        # Terms with weight 0 stay out of the sum (0 * inf would be NaN).
        total = sum(w * terms[k] for k, w in c.weights.items() if w != 0) + zero
        return {"total": c.total_scale * total, **terms}
