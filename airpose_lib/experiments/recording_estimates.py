"""The real-data experiment's estimates of one recording, each cached: a network's per-frame
parameters, AirPose+ refined from AirPose's, UAV 2 in UAV 1 from the ArUco markers, and the
camera-frame vertices of an estimate.
"""
from __future__ import annotations

import dataclasses
import hashlib
import json
from pathlib import Path

import numpy as np

from airpose_lib.data.official.real import MARKER_POSES_FILE, load_marker_poses
from airpose_lib.data.sequences.markers import marker_relative_cameras, sequence_marker_poses
from airpose_lib.eval.recordings import per_view_params
from airpose_lib.finetune.keypoints import resolution_scales
from airpose_lib.finetune.network import load_sized_network
from airpose_lib.finetune.predict import image_sizes, predict_sequence
from airpose_lib.fitting import AirPosePlusConfig, airpose_plus
from airpose_lib.model import posed_joints_and_vertices
from airpose_lib.model.official import load_official_checkpoint

from .recording_cache import cache_key, cached_arrays, file_stamp, save_arrays, sequence_stamp

__all__ = ["OFFICIAL_INPUT_SIZE", "network_estimate", "airpose_plus_estimate", "marker_truth", "body_vertices"]

#: Crop size of the official networks.
OFFICIAL_INPUT_SIZE = 224


#: Bumped when the estimates of an unchanged network and recording change (e.g. the camera rule).
_ESTIMATE_VERSION = 3  # 3: the box margin of data.network_input.network_box_margin


def network_estimate(checkpoint: Path, sequence, out: Path) -> dict:
    """A network's per-frame estimates of a recording (:func:`~airpose_lib.finetune.predict.predict_sequence`,
    cached in ``out``): per-view ``phi (F, V, 3, 3)``, ``tau (F, V, 3)``, ``theta``, ``beta``, ``valid
    (F, V)``. ``checkpoint``: a kit ``.pt`` or an official ``.ckpt`` (ResNet-50 at 224 px)."""
    key = cache_key("predict", _ESTIMATE_VERSION, file_stamp(checkpoint), str(sequence.root), sequence.frames.tolist(),
                    sequence_stamp(sequence))
    cached = cached_arrays(out, key)
    if cached is not None:
        return cached
    if Path(checkpoint).suffix == ".ckpt":  # an official Lightning checkpoint: ResNet-50 at 224 px
        model, size = load_official_checkpoint(checkpoint, backbone=None), OFFICIAL_INPUT_SIZE
    else:
        model, _, size = load_sized_network(checkpoint)
    pred = predict_sequence(model, sequence, input_size=size)
    arrays = {k: np.asarray(v) for k, v in pred.items() if k != "provenance"}
    save_arrays(out, key, arrays)
    return arrays


#: Bumped when the marker detection or pose of an unchanged recording changes.
_MARKER_VERSION = 1


def marker_truth(sequence, out: Path) -> dict | None:
    """UAV 2 in UAV 1 from the ArUco markers on a recording's ground, or None without markers.

    The official release ships each drone's marker pose per frame (``data.official.real``, marker
    ``"0"`` as the world frame, as the official loader); a generated recording with the
    ``markers`` option is searched for its markers frame by frame (``cv2.aruco``,
    :func:`~airpose_lib.data.sequences.markers.sequence_marker_poses`; cached, about 10 ms an image).

    Returns:
        ``R_12 (F, 3, 3)``, ``t_12 (F, 3)``, ``valid (F,)`` (both drones posed), and for
        generated recordings ``count (F, V)`` markers detected and ``rms_px (F, V)`` reprojection
        error (NaN where not posed).
    """
    root = Path(sequence.root) if sequence.root is not None else None
    if root is not None and (root / "machine_1" / MARKER_POSES_FILE).is_file():
        poses = load_marker_poses(root, sequence.frames, num_views=sequence.num_views)
        R_12, t_12, valid = marker_relative_cameras(poses)
        return {"R_12": R_12, "t_12": t_12, "valid": valid}
    if ((sequence.meta or {}).get("config") or {}).get("markers") is None:
        return None
    key = cache_key("markers", _MARKER_VERSION, str(sequence.root), sequence.frames.tolist(), sequence_stamp(sequence))
    cached = cached_arrays(out, key)
    if cached is not None:
        return cached
    poses, count, rms = sequence_marker_poses(sequence)
    R_12, t_12, valid = marker_relative_cameras(poses)
    arrays = {"R_12": R_12, "t_12": t_12, "valid": valid, "count": count, "rms_px": rms}
    save_arrays(out, key, arrays)
    return arrays


def airpose_plus_estimate(sequence, init: dict, fitting: AirPosePlusConfig, prior, prior_info: dict, out: Path,
                          progress: bool) -> tuple[dict, dict]:
    """AirPose+ on a recording from the estimates ``init`` (:func:`network_estimate`'s arrays), with
    the profile's fitting settings, the Geman-McClure scale at the recording's resolution (cached in
    ``out``).

    Returns:
        the fit's arrays (:meth:`~airpose_lib.fitting.AirPosePlusResult.to_numpy`: ``phi (F, V, 3, 3)``,
        ``tau (F, V, 3)``, ``theta (F, 21, 3, 3)``, ``beta (10,)``, ``kept (F,)``) and the run summary
        (seconds, skipped frames, loss).
    """
    cfg = fitting
    # The Geman-McClure scale (30 px) is a full-resolution value: rho is a function of residual / sigma.
    scale = float(np.mean(resolution_scales(image_sizes(sequence))))
    cfg = dataclasses.replace(cfg, sigma=cfg.sigma * scale)
    start = {k: init[k] for k in ("phi", "tau", "theta", "beta")}
    digest = hashlib.sha256()
    for k in start:  # the whole initialisation, not just one of its arrays
        digest.update(np.ascontiguousarray(start[k]).tobytes())
    # The device (the profile's `fitting: device`) is in the key only when it is not the default
    # CPU, so that the caches written before the option existed stay valid.
    fit_key = {k: v for k, v in cfg.to_dict().items() if k != "device" or v != "cpu"}
    key = cache_key("airpose+", fit_key, prior_info.get("stamp"), str(sequence.root), sequence.frames.tolist(),
                    digest.hexdigest(), sequence_stamp(sequence))
    cached = cached_arrays(out, key)
    if cached is not None:
        info = json.loads(str(cached.pop("info")))
        return cached, info
    res = airpose_plus(sequence.keypoints, sequence.K, start, prior=prior, config=cfg, progress=progress)
    arrays = res.to_numpy()
    info = {"seconds": res.seconds, "iterations": cfg.iterations, "frames": int(len(arrays["kept"])),
            "skipped_frames": len(res.skipped_frames), "final_loss": float(res.history["loss"][-1]),
            "sigma_px": cfg.sigma, "prior": prior_info.get("source")}
    save_arrays(out, key, {**arrays, "info": np.array(json.dumps(info))})
    return arrays, info


def body_vertices(params: dict, body_model, index, view: int) -> np.ndarray:
    """Camera-frame vertices of an estimate at some frames of one view.

    Args:
        params: per-view parameters (see :class:`~airpose_lib.experiments.recordings.RecordingExperiment`).
        body_model: a neutral ``smplx.SMPLX``.
        index: frame positions (n,).
        view: the view.

    Returns:
        ``(n, N, 3)`` vertices, ``V = phi V0(theta, beta) + tau``.
    """
    import torch

    p = per_view_params(params)
    idx = np.asarray(index)
    part = {k: torch.as_tensor(np.ascontiguousarray(v[idx, view]), dtype=body_model.v_template.dtype)
            for k, v in p.items()}
    with torch.no_grad():
        return posed_joints_and_vertices(body_model, part)["vertices"].double().numpy()
