r"""AirPose+ (paper Sec. III-D): offline refinement of a whole two-view sequence.

Variables (for the kept frames t, views c):

* ``v_t`` (32): one VPoser latent per frame, shared by the views; ``theta_t = D(v_t)``;
* ``phi_{t,c}`` (6D, the kit's column convention) and ``tau_{t,c}`` (metres): the body's root
  rotation and translation in each camera (the paper's convention ``X_c = phi X_0 + tau`` about
  the model origin);
* ``beta`` (10): one shape for the whole sequence.

Loss, paper eq. (5) as written::

    L = sum_t [ w_j2d L_j2d + w_vposer ||v_t||^2 + w_temp L_temp ] + w_beta ||beta||^2

    L_j2d  = sum_{d, c, j} w^d_{t,c,j} [rho(u - u_hat) + rho(v - v_hat)]
             rho(x) = x^2 / (x^2 + sigma^2)   (Geman-McClure, sigma = 30 px, per coordinate)
             d runs over the detectors (BODY_25 and COCO-18), w = detector confidence,
             (u_hat, v_hat) = K_c (phi_{t,c} J(theta_t, beta) + tau_{t,c}) projected
    L_temp = a_pose ||theta_t - theta_{t-1}||^2
             + sum_c (a_root ||phi_{t,c} - phi_{t-1,c}||^2 + a_transl ||tau_{t,c} - tau_{t-1,c}||^2)

Choices the paper leaves open, and what the kit does:

* rotation differences in ``L_temp`` are squared Frobenius norms of rotation-matrix differences
  (``= 4 (1 - cos angle)``, per joint, summed over the 21 joints);
* the relative temporal weights ``a_pose, a_root, a_transl`` are 1 (the paper's equation);
  :meth:`AirPosePlusConfig.official_code` sets the official code's 10 / 100 / 100;
* the beta prior acts on the optimised ``beta``. (The official code applies it to a constant
  zero tensor, so its beta is unregularised; it also halves the hip confidences in place on
  every iteration. Neither bug is reproduced.);
* frame rule (paper: "we calculate sum_{j,c} w_j for each frame and ignore it if its value is
  below a threshold"): the summed confidence over both detectors and all views, NaN detections
  counting 0, is compared with ``min_frame_confidence`` (default 4: fewer than four fully
  confident keypoints over all views cannot fix the two root poses). An ignored frame is removed
  from the problem: it contributes no term, and the temporal terms link the kept frames on either
  side of it, so the loss of the other frames is exactly that of the sequence without it. Its
  output is the initialisation, and ``result.kept`` / ``result.skipped_frames`` say which frames
  these are;
* the loss is summed over frames (the paper's ``sum_t``), not averaged: ``w_beta`` then weighs
  one sequence-level term against the per-frame evidence;
* schedule (the official code's): Adam, lr 0.01, 300 iterations; during the first 100 only the
  root rotations, translations and beta move (the latents are frozen at the encoded
  initialisation), from iteration 100 the latents join.

Long sequences are processed in chunks of ``chunk_size`` frames per forward/backward pass whose
gradients are accumulated before each Adam step; each chunk also evaluates the last frame of the
previous chunk so that the temporal term across the boundary is counted once. The loss, the
gradients and therefore the result are those of the whole sequence (no seams, one beta); the
chunk size only bounds memory (the official code optimised 2,000-frame chunks independently).
"""
from __future__ import annotations

import math
import time
from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass, field, replace

import numpy as np
import roma
import torch
from torch import Tensor

from airpose_lib.body import BODY_25_FROM_SMPLX, COCO18_FROM_SMPLX, load_body_model
from airpose_lib.body.forward import BodyForward
from airpose_lib.config_fields import check_fields, ranged
from airpose_lib.devices import resolve_device
from airpose_lib.errors import ConfigError
from airpose_lib.geometry import (
    axis_angle_to_matrix,
    matrix_to_axis_angle,
    matrix_to_rot6d,
    project_points,
    relative_camera_pose,
    rot6d_to_matrix,
)
from airpose_lib.losses.robust import geman_mcclure
from airpose_lib.prior import VPoser, load_prior
from airpose_lib.progress import progress_bar

__all__ = [
    "AirPosePlusConfig",
    "AirPosePlusResult",
    "AirPosePlusLoss",
    "DETECTOR_JOINTS",
    "airpose_plus",
    "fit_sequence",
    "init_from_views",
    "frame_confidence",
]


DETECTOR_JOINTS: dict[str, tuple[int, ...]] = {
    "body25": BODY_25_FROM_SMPLX,
    "openpose": BODY_25_FROM_SMPLX,
    "coco18": COCO18_FROM_SMPLX,
    "alphapose": COCO18_FROM_SMPLX,
    "mediapipe": BODY_25_FROM_SMPLX,
}
"""Detector name -> index of each keypoint into the 76 SMPL-X output joints (-1: no counterpart).
``openpose`` / ``alphapose`` are the names the kit's sequences use for BODY_25 / COCO-18;
``mediapipe`` is MediaPipe Pose mapped onto BODY_25 (``data.sequences.mediapipe_pose``; the keypoints it
lacks have confidence 0)."""


@dataclass
class AirPosePlusConfig:
    """Weights and schedule of AirPose+ (defaults: the paper's weights, the code's schedule)."""

    w_j2d: float = ranged(1.0, ge=0)
    sigma: float = ranged(30.0, gt=0)  # Geman-McClure scale, pixels
    w_vposer: float = ranged(0.05, ge=0)
    w_temp: float = ranged(1.0, ge=0)
    temp_pose: float = ranged(1.0, ge=0)  # relative weights inside L_temp; official code: 10, 100, 100
    temp_root: float = ranged(1.0, ge=0)
    temp_transl: float = ranged(1.0, ge=0)
    w_beta: float = ranged(2000.0, ge=0)
    min_frame_confidence: float = ranged(4.0, ge=0)
    iterations: int = ranged(300, ge=0)
    latent_start: int = ranged(100, ge=0)  # iteration at which the latents join (before: roots, tau, beta)
    lr: float = ranged(0.01, gt=0)
    optimize_beta: bool = True
    chunk_size: int = ranged(2000, ge=1)
    min_depth: float = ranged(0.05, gt=0)  # metres; projected depths are clamped to this (keeps a wild start finite)
    num_threads: int | None = ranged(None, ge=1)  # torch intra-op threads during the fit (None: unchanged)
    device: str = "cpu"  # auto, cpu, cuda, cuda:N (airpose_lib.devices); results come back on the CPU
    history_every: int = ranged(10, ge=1)

    def __post_init__(self) -> None:
        check_fields(self, convert=False)  # types and declared ranges, before a fit starts

    @classmethod
    def official_code(cls, **overrides) -> AirPosePlusConfig:
        """The official code's relative temporal weights (10 x pose, 100 x root and translation)."""
        return cls(**{"temp_pose": 10.0, "temp_root": 100.0, "temp_transl": 100.0, **overrides})

    def to_dict(self) -> dict:
        return asdict(self)


@dataclass
class AirPosePlusResult:
    """Refined per-frame parameters (float32 CPU tensors, whatever ``config.device`` the fit ran on).

    Attributes:
        theta: ``(F, 21, 3, 3)`` body joint rotations.
        v: ``(F, 32)`` VPoser latents (``theta = D(v)`` on kept frames).
        beta: ``(10,)`` the sequence's shape.
        phi: ``(F, V, 3, 3)`` root rotation per view (body -> camera).
        tau: ``(F, V, 3)`` root translation per view, metres.
        R_body_cam: ``(F, V, 3, 3)``, t_body_cam ``(F, V, 3)``: each camera's pose in the person's
            (model) frame, ``x_body = R x_cam + t``; ``t`` is the camera centre.
        R_12: ``(F, 3, 3)``, t_12 ``(F, 3)``: camera (UAV) 2 in camera 1,
            :func:`airpose_lib.geometry.relative_camera_pose`; None with one view.
        kept: ``(F,)`` bool, the frames that were optimised (others hold the initialisation).
        frame_confidence: ``(F,)`` summed keypoint confidence of each frame.
        history: ``iteration``, ``loss``, ``j2d``, ``vposer``, ``temp``, ``beta`` every
            ``history_every`` iterations (loss terms weighted).
        seconds: wall time of the optimisation.
        config: the :class:`AirPosePlusConfig` used.
    """

    theta: Tensor
    v: Tensor
    beta: Tensor
    phi: Tensor
    tau: Tensor
    R_body_cam: Tensor
    t_body_cam: Tensor
    R_12: Tensor | None
    t_12: Tensor | None
    kept: Tensor
    frame_confidence: Tensor
    history: dict = field(default_factory=dict)
    seconds: float = 0.0
    config: AirPosePlusConfig | None = None

    @property
    def skipped_frames(self) -> list[int]:
        """Positions of the frames that were ignored (confidence below the threshold)."""
        return torch.nonzero(~self.kept).flatten().tolist()

    @property
    def theta_axis_angle(self) -> Tensor:
        """``(F, 21, 3)`` axis-angle body pose."""
        return matrix_to_axis_angle(self.theta)

    def relative_pose(self, i: int, j: int) -> tuple[Tensor, Tensor]:
        """Pose of camera ``j`` in camera ``i``: ``R (F, 3, 3)``, ``t (F, 3)``."""
        return relative_camera_pose(self.phi[:, i], self.tau[:, i], self.phi[:, j], self.tau[:, j])

    def to_numpy(self) -> dict[str, np.ndarray]:
        """Arrays for saving (``np.savez``)."""
        out = {k: getattr(self, k).numpy() for k in
               ("theta", "v", "beta", "phi", "tau", "R_body_cam", "t_body_cam", "kept", "frame_confidence")}
        if self.R_12 is not None:
            out.update(R_12=self.R_12.numpy(), t_12=self.t_12.numpy())
        return out


# -- inputs ---------------------------------------------------------------------------------------
def _tensor(x, name: str, dtype=torch.float32) -> Tensor:
    t = torch.as_tensor(np.asarray(x) if not isinstance(x, Tensor) else x)
    if not t.is_floating_point():
        t = t.double()
    return t.detach().to(dtype=dtype, device="cpu")


def _prepare_keypoints(keypoints: Mapping[str, object], joint_maps: Mapping[str, Sequence[int]] | None
                       ) -> tuple[Tensor, Tensor, Tensor, dict[str, int]]:
    """Concatenate the detectors: pixels ``(F, V, J, 2)``, weights ``(F, V, J)``, index ``(J,)``."""
    if not keypoints:
        raise ValueError("no keypoints given: pass {detector name: (F, V, J, 3) [x, y, confidence]}")
    maps = {**DETECTOR_JOINTS, **dict(joint_maps or {})}
    xy, w, idx, shape0, sizes = [], [], [], None, {}
    for name, arr in keypoints.items():
        if name not in maps:
            raise ValueError(f"unknown detector {name!r}: pass its joint map (joint_maps={{{name!r}: "
                             f"[index into the 76 SMPL-X outputs per keypoint]}}); known: {sorted(maps)}")
        kp = _tensor(arr, name, torch.float64)
        jmap = torch.as_tensor(maps[name], dtype=torch.long)
        if kp.ndim != 4 or kp.shape[-1] != 3:
            raise ValueError(f"keypoints[{name!r}] must be (F, V, J, 3) [x, y, confidence], got {tuple(kp.shape)}")
        if kp.shape[2] != len(jmap):
            raise ValueError(f"keypoints[{name!r}] has {kp.shape[2]} keypoints, its joint map {len(jmap)}")
        if shape0 is None:
            shape0 = (name, kp.shape[:2])
        elif kp.shape[:2] != shape0[1]:
            raise ValueError(f"detectors disagree on (frames, views): {shape0[0]} has {tuple(shape0[1])}, "
                             f"{name} has {tuple(kp.shape[:2])}")
        bad = ~torch.isfinite(kp).all(-1)  # a NaN anywhere in [x, y, c] drops the keypoint
        conf = torch.where(bad, 0.0, kp[..., 2])
        if (conf < 0).any():
            raise ValueError(f"keypoints[{name!r}] has negative confidences")
        conf = conf * (jmap >= 0)  # keypoints without an SMPL-X counterpart carry no weight
        xy.append(torch.where(bad[..., None], 0.0, kp[..., :2]).float())
        w.append(conf.float())
        idx.append(jmap.clamp_min(0))
        sizes[name] = len(jmap)
    return torch.cat(xy, 2), torch.cat(w, 2), torch.cat(idx), sizes


def frame_confidence(keypoints: Mapping[str, object],
                     joint_maps: Mapping[str, Sequence[int]] | None = None) -> Tensor:
    """``(F,)`` summed confidence over detectors, views and keypoints (NaN counts 0): the frame rule."""
    _, w, _, _ = _prepare_keypoints(keypoints, joint_maps)
    return w.sum(dim=(1, 2))


def _mean_rotation(R: Tensor, dim: int) -> Tensor:
    """Chordal L2 mean of rotations along ``dim`` (projection of the mean matrix onto SO(3))."""
    return roma.special_procrustes(R.mean(dim))


def _as_rotmat(x: Tensor, name: str) -> Tensor:
    if x.shape[-2:] == (3, 3):
        return x
    if x.shape[-1] == 6:
        return rot6d_to_matrix(x)
    if x.shape[-1] == 3:
        return axis_angle_to_matrix(x)
    raise ValueError(f"{name}: expected rotation matrices (..., 3, 3), 6D (..., 6) or axis-angle (..., 3), "
                     f"got {tuple(x.shape)}")


def init_from_views(phi, tau, theta, beta, num_frames: int | None = None,
                    weights: Tensor | None = None) -> dict[str, Tensor]:
    """The AirPose+ initialisation from per-view network outputs.

    Args:
        phi: ``(F, V, 3, 3)`` (or 6D ``(F, V, 6)``, axis-angle ``(F, V, 3)``) root rotation per view.
        tau: ``(F, V, 3)`` translation per view, metres.
        theta: body pose per view ``(F, V, 21, 3, 3)`` / ``(F, V, 21, 3)`` axis-angle, or already
            shared ``(F, 21, 3, 3)`` / ``(F, 21, 3)``; per-view poses are averaged over the views
            (chordal mean of each joint's rotations).
        beta: ``(F, V, 10)``, ``(F, 10)`` or ``(10,)``; averaged over frames and views.
        num_frames: F, checked if given.
        weights: optional ``(F,)`` frame weights for the beta mean (e.g. the kept frames).
    Returns:
        ``phi (F, V, 3, 3)``, ``tau (F, V, 3)``, ``theta (F, 21, 3, 3)``, ``beta (10,)`` float32.
    """
    phi = _as_rotmat(_tensor(phi, "phi"), "phi")
    tau = _tensor(tau, "tau")
    theta = _as_rotmat(_tensor(theta, "theta"), "theta")
    beta = _tensor(beta, "beta")
    if phi.ndim != 4:
        raise ValueError(f"phi must be per frame and view (F, V, 3, 3), got {tuple(phi.shape)}")
    F, V = phi.shape[:2]
    if tau.shape != (F, V, 3):
        raise ValueError(f"tau must be (F, V, 3) = {(F, V, 3)}, got {tuple(tau.shape)}")
    if num_frames is not None and F != num_frames:
        raise ValueError(f"the initialisation has {F} frames, the keypoints {num_frames}")
    if theta.ndim == 5:
        if theta.shape[:3] != (F, V, 21):
            raise ValueError(f"per-view theta must be (F, V, 21, 3, 3) = {(F, V, 21)}, got {tuple(theta.shape)}")
        theta = _mean_rotation(theta, 1)
    if theta.shape != (F, 21, 3, 3):
        raise ValueError(f"theta must have {F} frames of 21 joints, got {tuple(theta.shape)}")
    if beta.ndim == 3:
        beta = beta.mean(1)
    if beta.ndim == 2:
        if beta.shape[0] != F:
            raise ValueError(f"beta has {beta.shape[0]} frames, phi {F}")
        if weights is not None and weights.sum() > 0:
            beta = (beta * weights[:, None]).sum(0) / weights.sum()
        else:
            beta = beta.mean(0)
    if beta.ndim != 1:
        raise ValueError(f"beta must be (10,), (F, 10) or (F, V, 10), got {tuple(beta.shape)}")
    for name, t in (("phi", phi), ("tau", tau), ("theta", theta), ("beta", beta)):
        if not torch.isfinite(t).all():
            raise ValueError(f"the initialisation's {name} contains NaN or inf")
    return {"phi": phi, "tau": tau, "theta": theta, "beta": beta}


# -- the fit --------------------------------------------------------------------------------------
def _keypoint_body(body, outputs: Sequence[int]) -> BodyForward:
    """Joints-only body of the requested outputs, in float32 (own copies: ``body``, an
    ``smplx.SMPLX``, default the open neutral model, keeps its dtype)."""
    if body is None:
        body = load_body_model("open", "neutral")
    return BodyForward(body, outputs, vertices=None).float()


class AirPosePlusLoss:
    """Eq. (5) over the given frames, evaluated on any contiguous block of them.

    Every frame given counts (apply the frame rule before: :func:`airpose_plus` passes only the
    kept frames). Built from the same inputs as :func:`airpose_plus`.

    Args:
        keypoints: detector name -> ``(F, V, J, 3)`` ``[x, y, confidence]``.
        K: ``(V, 3, 3)``.
        prior: the pose prior (its decoder maps ``v`` to ``theta``); moved to ``config.device``.
        body: an ``smplx.SMPLX`` (default: the open neutral model).
        config: the weights and the device (:class:`AirPosePlusConfig`); the variables passed to
            the loss must be on that device.
        joint_maps: extra detector maps.
    """

    def __init__(self, keypoints: Mapping[str, object], K, *, prior: VPoser, body=None,
                 config: AirPosePlusConfig | None = None,
                 joint_maps: Mapping[str, Sequence[int]] | None = None) -> None:
        xy, w, idx, _ = _prepare_keypoints(keypoints, joint_maps)
        K = _tensor(K, "K")
        if K.shape != (xy.shape[1], 3, 3):
            raise ValueError(f"K must be (V, 3, 3) = {(xy.shape[1], 3, 3)} for the {xy.shape[1]} views of "
                             f"the keypoints, got {tuple(K.shape)}")
        uniq, gather = torch.unique(idx, return_inverse=True)
        kbody = _keypoint_body(body, uniq.tolist())
        cfg = config or AirPosePlusConfig()
        dev = resolve_device(cfg.device)
        self._setup(cfg, prior.to(dev), kbody.to(dev), xy.to(dev), w.to(dev), gather.to(dev), K.to(dev))

    @classmethod
    def _prepared(cls, cfg, prior, kbody, xy, w, gather, K) -> AirPosePlusLoss:
        self = cls.__new__(cls)
        self._setup(cfg, prior, kbody, xy, w, gather, K)
        return self

    def _setup(self, cfg, prior, kbody, xy, w, gather, K) -> None:
        self.config, self.prior, self.body = cfg, prior, kbody
        self.xy, self.w, self.gather, self.K = xy, w, gather, K

    @property
    def num_frames(self) -> int:
        return self.xy.shape[0]

    def project(self, theta: Tensor, phi: Tensor, tau: Tensor, beta: Tensor) -> Tensor:
        """Model keypoints in the image: ``theta (F, 21, 3, 3)``, ``phi (F, V, 3, 3)``,
        ``tau (F, V, 3)``, ``beta (10,)`` -> ``(F, V, J, 2)`` pixels (J = all detectors' keypoints)."""
        J0 = self.body(theta, beta)[0][:, self.gather]  # (F, J, 3)
        X = J0[:, None] @ phi.transpose(-1, -2) + tau[:, :, None]  # (F, V, J, 3)
        return project_points(X, self.K[None], min_depth=self.config.min_depth)

    def __call__(self, v: Tensor, phi6d: Tensor, tau: Tensor, beta: Tensor, *, theta: Tensor | None = None,
                 start: int = 0, stop: int | None = None, with_beta: bool = True
                 ) -> tuple[Tensor, dict[str, float]]:
        """Loss of frames ``start..stop-1`` and of the temporal pairs ending in them.

        Args:
            v: ``(F, 32)`` latents; phi6d ``(F, V, 6)``; tau ``(F, V, 3)``; beta ``(10,)``.
            theta: ``(F, 21, 3, 3)`` to use instead of ``D(v)`` (the first stage, where the latents
                are frozen); ``||v||^2`` is still counted.
            start, stop: the block of frames (the pair (start - 1, start) is included, so the
                blocks of a partition of the frames add up to the whole loss).
            with_beta: add the sequence-level ``w_beta ||beta||^2`` (once per sequence).
        Returns:
            the scalar loss and its weighted terms ``j2d``, ``vposer``, ``temp``, ``beta`` (floats).
        """
        cfg = self.config
        a, b = start, self.num_frames if stop is None else stop
        s = max(a - 1, 0)
        own = slice(a - s, b - s)  # rows of the evaluated block that belong to [a, b)
        R = self.prior.decode_matrot(v[s:b]) if theta is None else theta[s:b]  # (n, 21, 3, 3)
        phi = rot6d_to_matrix(phi6d[s:b])  # (n, V, 3, 3)
        uv = self.project(R[own], phi[own], tau[a:b], beta)  # (m, V, J, 2)
        rho = geman_mcclure(uv - self.xy[a:b], cfg.sigma).sum(-1)  # per keypoint: rho(du) + rho(dv)
        j2d = cfg.w_j2d * (self.w[a:b] * rho).sum()
        vposer = cfg.w_vposer * v[a:b].square().sum()
        temp = R.new_zeros(())
        if b - s > 1 and cfg.w_temp > 0:
            d_pose = (R[1:] - R[:-1]).square().sum()
            d_root = (phi[1:] - phi[:-1]).square().sum()
            d_tau = (tau[s + 1:b] - tau[s:b - 1]).square().sum()
            temp = cfg.w_temp * (cfg.temp_pose * d_pose + cfg.temp_root * d_root + cfg.temp_transl * d_tau)
        prior_beta = cfg.w_beta * beta.square().sum() if with_beta else R.new_zeros(())
        loss = j2d + vposer + temp + prior_beta
        return loss, {"j2d": j2d.item(), "vposer": vposer.item(), "temp": temp.item(),
                      "beta": prior_beta.item()}


def airpose_plus(
    keypoints: Mapping[str, object],
    K,
    init: Mapping[str, object],
    *,
    prior: VPoser | None = None,
    body=None,
    config: AirPosePlusConfig | None = None,
    joint_maps: Mapping[str, Sequence[int]] | None = None,
    progress: bool = True,
    **overrides,
) -> AirPosePlusResult:
    """Refine a sequence with AirPose+.

    Args:
        keypoints: detector name -> ``(F, V, J, 3)`` ``[x, y, confidence]`` full-frame pixels;
            names from :data:`DETECTOR_JOINTS` (``body25``/``openpose``, ``coco18``/``alphapose``)
            or given in ``joint_maps``. Missing keypoints: confidence 0 or NaN.
        K: ``(V, 3, 3)`` intrinsics of each view (the pixels of ``keypoints``).
        init: per-frame start, keys ``phi``, ``tau``, ``theta``, ``beta`` in any form
            :func:`init_from_views` takes (AirPose's per-view outputs, e.g.
            ``model.to_smplx_params`` over the sequence).
        prior: the pose prior (default ``load_prior("kit")``); moved to ``config.device`` (in place,
            as ``eval()``; a no-op on the default CPU).
        body: an ``smplx.SMPLX`` (default: the open neutral model, as the network predicts); the
            fit uses its own float32 copy on ``config.device``.
        config: weights, schedule and ``device`` (``auto``: CUDA when available); keyword
            ``overrides`` replace single fields.
        joint_maps: extra or replacement detector maps (index into the 76 SMPL-X outputs).
        progress: tqdm bar over the iterations.
    Returns:
        :class:`AirPosePlusResult`, on the CPU.
    Raises:
        ConfigError: a bad ``device`` (:func:`airpose_lib.devices.resolve_device`).
        ValueError: empty sequence, mismatched frame/view counts, NaN initialisation, or no frame
            above ``min_frame_confidence``.
    """
    cfg = replace(config or AirPosePlusConfig(), **overrides)  # replace checks the fields again (__post_init__)
    dev = resolve_device(cfg.device)
    xy, w, idx, _ = _prepare_keypoints(keypoints, joint_maps)
    F, V = xy.shape[:2]
    if F == 0:
        raise ValueError("empty sequence: the keypoints have 0 frames")
    K = _tensor(K, "K")
    if K.shape != (V, 3, 3):
        raise ValueError(f"K must be (V, 3, 3) = {(V, 3, 3)} for the {V} views of the keypoints, "
                         f"got {tuple(K.shape)}")
    conf = w.sum(dim=(1, 2))  # (F,)
    kept = conf >= cfg.min_frame_confidence
    if not kept.any():
        raise ConfigError(f"no frame reaches min_frame_confidence={cfg.min_frame_confidence} "
                          f"(largest summed confidence {conf.max().item():.3g}); nothing to fit")
    start = init_from_views(init["phi"], init["tau"], init["theta"], init["beta"], num_frames=F,
                            weights=kept.float())
    if prior is None:
        prior = load_prior("kit")
    if next(prior.parameters()).dtype != torch.float32:
        prior = prior.float()
    prior.eval()  # dropout off, batch-norm running statistics
    prior.requires_grad_(False)
    uniq, gather = torch.unique(idx, return_inverse=True)
    kbody = _keypoint_body(body, uniq.tolist())
    if start["beta"].shape[0] > kbody.num_betas:
        raise ValueError(f"beta has {start['beta'].shape[0]} entries, the body model {kbody.num_betas}")
    # Inputs are checked on the CPU above; the optimisation runs on ``dev``.
    prior, kbody = prior.to(dev), kbody.to(dev)
    start = {k: t.to(dev) for k, t in start.items()}

    threads = torch.get_num_threads()
    if cfg.num_threads:
        torch.set_num_threads(cfg.num_threads)
    try:
        result = _optimise(cfg, prior, kbody, xy[kept].to(dev), w[kept].to(dev), gather.to(dev), K.to(dev),
                           start, kept.to(dev), progress)
    finally:
        torch.set_num_threads(threads)
    result.frame_confidence = conf
    return result


def _optimise(cfg, prior, kbody, xy, w, gather, K, start, kept, progress) -> AirPosePlusResult:
    F = kept.shape[0]
    keep_idx = torch.nonzero(kept).flatten()
    with torch.no_grad():
        v0 = torch.cat([prior.encode(matrix_to_axis_angle(start["theta"][i:i + 4096])).loc
                        for i in range(0, F, 4096)])  # (F, 32)
    v = v0[keep_idx].clone().requires_grad_(True)
    phi6d = matrix_to_rot6d(start["phi"][keep_idx]).clone().requires_grad_(True)
    tau = start["tau"][keep_idx].clone().requires_grad_(True)
    beta = start["beta"].clone().requires_grad_(cfg.optimize_beta)
    params = [phi6d, tau, v] + ([beta] if cfg.optimize_beta else [])
    opt = torch.optim.Adam(params, lr=cfg.lr)
    problem = AirPosePlusLoss._prepared(cfg, prior, kbody, xy, w, gather, K)
    n = keep_idx.shape[0]
    chunks = [(a, min(a + cfg.chunk_size, n)) for a in range(0, n, cfg.chunk_size)]
    hist: dict[str, list] = {k: [] for k in ("iteration", "loss", "j2d", "vposer", "temp", "beta")}
    theta_fixed = None
    bar = None
    if progress:
        bar = progress_bar(total=cfg.iterations, desc=f"AirPose+ ({n} frames)", unit="it")
    t0 = time.perf_counter()
    for it in range(cfg.iterations + 1):  # the extra pass only records the final loss
        latent_on = it >= cfg.latent_start
        if not latent_on and theta_fixed is None:
            with torch.no_grad():
                theta_fixed = prior.decode_matrot(v.detach())
        opt.zero_grad(set_to_none=True)
        record = it % max(cfg.history_every, 1) == 0 or it == cfg.iterations
        terms = {"loss": 0.0, "j2d": 0.0, "vposer": 0.0, "temp": 0.0, "beta": 0.0}
        final = it == cfg.iterations
        for ci, (a, b) in enumerate(chunks):
            with torch.set_grad_enabled(not final):
                loss, parts = problem(v, phi6d, tau, beta, theta=None if latent_on else theta_fixed,
                                      start=a, stop=b, with_beta=ci == 0)
                if not final:
                    loss.backward()
            terms["loss"] += loss.item()
            for k, val in parts.items():
                terms[k] += val
        if record:
            hist["iteration"].append(it)
            for k, val in terms.items():
                hist[k].append(val)
        if final:
            break
        if not math.isfinite(terms["loss"]):
            raise FloatingPointError(f"AirPose+ loss became {terms['loss']} at iteration {it}")
        if not latent_on:
            v.grad = None  # Adam skips parameters without a gradient
        opt.step()
        if bar is not None:
            bar.update(1)
            if record:
                bar.set_postfix(loss=f"{terms['loss']:.4g}")
    seconds = time.perf_counter() - t0
    if bar is not None:
        bar.close()

    with torch.no_grad():
        theta = start["theta"].clone()
        v_out = v0.clone()
        phi = start["phi"].clone()
        tau_out = start["tau"].clone()
        theta[keep_idx] = torch.cat([prior.decode_matrot(v[i:i + 4096]) for i in range(0, n, 4096)])
        v_out[keep_idx] = v.detach()
        phi[keep_idx] = rot6d_to_matrix(phi6d.detach())
        tau_out[keep_idx] = tau.detach()
        R_bc = phi.transpose(-1, -2)
        t_bc = -(R_bc @ tau_out.unsqueeze(-1)).squeeze(-1)
        R_12 = t_12 = None
        if phi.shape[1] >= 2:
            R_12, t_12 = relative_camera_pose(phi[:, 0], tau_out[:, 0], phi[:, 1], tau_out[:, 1])
    cpu = {k: None if t is None else t.cpu() for k, t in
           dict(theta=theta, v=v_out, beta=beta.detach().clone(), phi=phi, tau=tau_out, R_body_cam=R_bc,
                t_body_cam=t_bc, R_12=R_12, t_12=t_12, kept=kept.clone()).items()}
    return AirPosePlusResult(**cpu, frame_confidence=torch.zeros(F), history=hist, seconds=seconds, config=cfg)


def fit_sequence(sequence, init: Mapping[str, object], **kwargs) -> AirPosePlusResult:
    """AirPose+ on a kit sequence (:class:`airpose_lib.data.sequences.reader.Sequence` or anything
    with ``keypoints`` {detector: (F, V, J, 3)} and ``K`` (V, 3, 3)); kwargs as :func:`airpose_plus`."""
    if not hasattr(sequence, "keypoints") or not hasattr(sequence, "K"):
        raise TypeError("fit_sequence needs an object with .keypoints {detector: (F, V, J, 3)} and .K (V, 3, 3)")
    return airpose_plus(sequence.keypoints, sequence.K, init, **kwargs)
