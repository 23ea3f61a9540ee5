"""The test persons' errors during fine-tuning: a diagnostic logged per checkpoint, never used to
select one (:mod:`airpose_lib.experiments.recording_finetune`).
"""
from __future__ import annotations

import numpy as np

from airpose_lib.body import load_body_model
from airpose_lib.body.joint_sets import BODY_25_FROM_SMPLX
from airpose_lib.eval import metrics as M
from airpose_lib.finetune.keypoints import resolution_scales
from airpose_lib.finetune.predict import image_sizes, network_camera_of, regress_features, sequence_features
from airpose_lib.model import posed_joints_and_vertices, to_smplx_params

__all__ = ["ground_truth_diagnostic"]


def ground_truth_diagnostic(model, sequence, *, input_size: int, features: dict | None = None,
                            cut: str | None = None):
    """A fine-tuning diagnostic on a recording with ground truth (the test person): ``f(model) ->
    {"mpjpe_m", "mpe_m", "j2d_px"}`` for ``finetune(..., diagnostic=f)``.

    The backbone is frozen during fine-tuning up to block ``cut`` (``FineTuneConfig.trainable_from``;
    None: all of it), so the recording's features up to there are computed once here (with
    ``model``'s backbone) and every call runs only the rest: the trainable blocks and the regressor. ``j2d_px`` is the mean
    distance of the predicted BODY_25 keypoints to the true ones, in pixels at the reference
    width (1920); ``mpjpe_m`` pelvis-aligned, 22 joints; ``mpe_m`` the position error.

    Args:
        features: precomputed :func:`~airpose_lib.finetune.predict.sequence_features` output
            (with the same ``cut``).
    """
    import torch

    gt = sequence.ground_truth
    if gt is None:
        raise ValueError(f"{sequence.root}: no ground truth for a diagnostic")
    feats = features if features is not None else sequence_features(model, sequence, input_size=input_size, cut=cut)
    K_net = network_camera_of(model)
    body = load_body_model("open", "neutral", dtype=torch.float32)
    f = torch.as_tensor(np.asarray(feats["features"]), dtype=torch.float32)
    P = torch.as_tensor(np.asarray(feats["P"]), dtype=torch.float32)
    pos = np.asarray(feats["positions"])
    F, V = P.shape[:2]
    K = torch.as_tensor(np.asarray(sequence.K), dtype=torch.float32)
    K_p = torch.as_tensor(K_net, dtype=torch.float32).expand(F, V, 3, 3)
    j3d = torch.as_tensor(np.asarray(gt["j3d_cam"])[pos], dtype=torch.float32)
    tau_gt = torch.as_tensor(np.asarray(gt["tau"])[pos], dtype=torch.float32)
    kp_gt = torch.as_tensor(np.asarray(gt["kp2d_body25"])[pos], dtype=torch.float32)
    r = torch.as_tensor(resolution_scales(image_sizes(sequence)), dtype=torch.float32).reshape(1, V, 1)
    idx = torch.as_tensor(BODY_25_FROM_SMPLX)

    def diagnostic(net) -> dict[str, float]:
        out = regress_features(net, f.to(net.init_beta.dtype), P.to(net.init_beta.dtype), input_size, cut=cut)
        pred = {k: v.float() for k, v in to_smplx_params(out, P, K_p, input_size).items()}
        flat = {k: v.reshape(F * V, *v.shape[2:]) for k, v in pred.items()}
        joints = posed_joints_and_vertices(body, flat, joints_only=True)["joints"].reshape(F, V, -1, 3)
        uv = (joints[:, :, idx] @ K.transpose(-1, -2)[None])
        uv = uv[..., :2] / uv[..., 2:].clamp_min(0.05)
        err2d = torch.linalg.norm(uv - kp_gt, dim=-1) / r
        return {"mpjpe_m": float(M.mpjpe(joints[:, :, :22], j3d).mean()),
                "mpe_m": float(M.translation_error(pred["tau"], tau_gt).mean()),
                "j2d_px": float(torch.nanmean(err2d))}

    return diagnostic
