"""Tidy evaluation tables (pandas): one row per sample x view, per joint, per sample pair of views
or per sequence, and summaries with one row per metric.

Predictions and ground truth are mappings of camera-frame tensors (or arrays) with N samples and
V views:

``tau (N, V, 3)``, ``phi (N, V, 3, 3)``, ``joints (N, V, 22, 3)`` -- for ground truth the joints may
also be given as ``j3d_cam`` (the still-frame sample's key).

Metric columns carry their unit: ``_m`` metres, ``_deg`` degrees.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np
import pandas as pd
import torch
from torch import Tensor

from airpose_lib.body.joint_sets import BODY22_NAMES
from airpose_lib.geometry import relative_camera_pose

from . import metrics as M

__all__ = [
    "PER_VIEW_METRICS",
    "per_view_table",
    "per_joint_table",
    "relative_camera_table",
    "sequence_table",
    "summarize",
    "paper_table",
    "to_long",
]

#: Metric columns of :func:`per_view_table`.
PER_VIEW_METRICS = ("mpe_m", "mpjpe_m", "mpjpe_shape_m", "mpjpe_true_root_m", "pa_mpjpe_m", "root_rot_deg",
                    "root_yaw_deg", "root_tilt_deg", "err_x_m", "err_y_m", "err_z_m")


def _t(x) -> Tensor:
    return x.detach().cpu().double() if isinstance(x, Tensor) else torch.as_tensor(np.asarray(x), dtype=torch.float64)


def _joints(d: Mapping) -> Tensor:
    return _t(d["joints"] if "joints" in d else d["j3d_cam"])


def _ids(sample_ids, n: int) -> np.ndarray:
    if sample_ids is None:
        return np.arange(n)
    ids = sample_ids.detach().cpu().numpy() if isinstance(sample_ids, Tensor) else np.asarray(sample_ids)
    if ids.shape != (n,):
        raise ValueError(f"sample_ids must have shape ({n},), got {ids.shape}")
    return ids


def per_view_table(pred: Mapping, gt: Mapping, method: str = "", sample_ids=None) -> pd.DataFrame:
    """One row per (sample, view): MPE, MPJPE (pelvis aligned), PA-MPJPE, root-orientation error
    (geodesic, and its yaw and tilt parts, :func:`airpose_lib.eval.metrics.root_yaw_tilt`) and the
    translation error per camera axis (signed, prediction - ground truth).

    ``mpjpe_m`` is Table I's MPJPE: when both sides have ``joints_zero_beta`` (the official
    evaluation's bodies: zero betas, root rotation, no translation) it is computed on those, and
    ``mpjpe_shape_m`` on ``joints`` (shape-aware); otherwise both are the MPJPE of ``joints``.
    ``mpjpe_true_root_m`` is Table I's MPJPE with the ground-truth root orientation
    (``pred["joints_zero_beta_true_root"]``: the predicted body pose, zero betas, the true ``phi``;
    NaN without it): the body pose alone, so ``mpjpe_m - mpjpe_true_root_m`` is what the root
    orientation error costs. PA-MPJPE is always on ``joints``.

    Args:
        pred, gt: ``tau (N, V, 3)``, ``phi (N, V, 3, 3)``, ``joints`` / ``j3d_cam (N, V, 22, 3)``,
            optionally ``joints_zero_beta (N, V, 22, 3)`` (and in ``pred``
            ``joints_zero_beta_true_root (N, V, 22, 3)``). ``phi`` is optional (the root columns are
            then NaN).
        method: value of the ``method`` column.
        sample_ids: ``(N,)`` identifiers (default ``0..N-1``).

    Returns:
        columns ``method, sample, view`` and :data:`PER_VIEW_METRICS`.
    """
    tau_p, tau_g = _t(pred["tau"]), _t(gt["tau"])
    jp, jg = _joints(pred), _joints(gt)
    N, V = tau_p.shape[:2]
    shape_aware = M.mpjpe(jp, jg)
    official = ("joints_zero_beta" in pred and "joints_zero_beta" in gt)
    cols = {
        "mpe_m": M.translation_error(tau_p, tau_g),
        "mpjpe_m": M.mpjpe(_t(pred["joints_zero_beta"]), _t(gt["joints_zero_beta"])) if official else shape_aware,
        "mpjpe_shape_m": shape_aware,
        "mpjpe_true_root_m": (M.mpjpe(_t(pred["joints_zero_beta_true_root"]), _t(gt["joints_zero_beta"]))
                              if official and "joints_zero_beta_true_root" in pred
                              else torch.full((N, V), float("nan"))),
        "pa_mpjpe_m": M.pa_mpjpe(jp, jg),
    }
    if "phi" in pred and "phi" in gt:
        phi_p, phi_g = _t(pred["phi"]), _t(gt["phi"])
        yaw, tilt = M.root_yaw_tilt(phi_p, phi_g)
        cols.update(root_rot_deg=torch.rad2deg(M.rotation_error(phi_p, phi_g)), root_yaw_deg=torch.rad2deg(yaw),
                    root_tilt_deg=torch.rad2deg(tilt))
    else:
        cols.update({k: torch.full((N, V), float("nan")) for k in ("root_rot_deg", "root_yaw_deg", "root_tilt_deg")})
    d = tau_p - tau_g
    cols.update(err_x_m=d[..., 0], err_y_m=d[..., 1], err_z_m=d[..., 2])
    frame = pd.DataFrame({
        "method": method,
        "sample": np.repeat(_ids(sample_ids, N), V),
        "view": np.tile(np.arange(V), N),
        **{k: v.reshape(-1).numpy() for k, v in cols.items()},
    })
    return frame


def per_joint_table(pred: Mapping, gt: Mapping, method: str = "", sample_ids=None,
                    joint_names: Sequence[str] = BODY22_NAMES) -> pd.DataFrame:
    """One row per (sample, view, joint): pelvis-aligned and Procrustes-aligned joint errors.

    Returns:
        columns ``method, sample, view, joint, error_m, pa_error_m``.
    """
    jp, jg = _joints(pred), _joints(gt)
    N, V, J = jp.shape[:3]
    if len(joint_names) != J:
        raise ValueError(f"{len(joint_names)} joint names for {J} joints")
    return pd.DataFrame({
        "method": method,
        "sample": np.repeat(_ids(sample_ids, N), V * J),
        "view": np.tile(np.repeat(np.arange(V), J), N),
        "joint": np.tile(np.asarray(joint_names, dtype=object), N * V),
        "error_m": M.joint_errors(jp, jg).reshape(-1).numpy(),
        "pa_error_m": M.pa_joint_errors(jp, jg).reshape(-1).numpy(),
    })


def relative_camera_table(pred: Mapping, gt: Mapping, method: str = "", sample_ids=None,
                          views: tuple[int, int] = (0, 1)) -> pd.DataFrame:
    """One row per sample: the error of camera 2's pose in camera 1 computed from the two per-view
    body poses (``geometry.relative_camera_pose``) against ground truth.

    Returns:
        columns ``method, sample, rel_t_err_m, rel_rot_deg`` and the predicted and ground-truth
        relative translation ``rel_t{x,y,z}_m`` / ``rel_t{x,y,z}_gt_m``.
    """
    phi_p, tau_p, phi_g, tau_g = (_t(pred["phi"]), _t(pred["tau"]), _t(gt["phi"]), _t(gt["tau"]))
    t_err, r_err = M.relative_camera_errors(phi_p, tau_p, phi_g, tau_g, views)
    i, j = views
    _, t_p = relative_camera_pose(phi_p[:, i], tau_p[:, i], phi_p[:, j], tau_p[:, j])
    _, t_g = relative_camera_pose(phi_g[:, i], tau_g[:, i], phi_g[:, j], tau_g[:, j])
    out = pd.DataFrame({"method": method, "sample": _ids(sample_ids, phi_p.shape[0]),
                        "rel_t_err_m": t_err.numpy(), "rel_rot_deg": torch.rad2deg(r_err).numpy()})
    for k, axis in enumerate("xyz"):
        out[f"rel_t{axis}_m"] = t_p[:, k].numpy()
        out[f"rel_t{axis}_gt_m"] = t_g[:, k].numpy()
    return out


def sequence_table(joints_pred, joints_gt=None, method: str = "", fps: float | None = None,
                   sequence: str = "") -> pd.DataFrame:
    """One row per view of a sequence: jitter (mean acceleration) of the prediction, and with
    ground truth its jitter, the acceleration error and the MPJPE over the sequence.

    Args:
        joints_pred, joints_gt: ``(T, V, J, 3)`` camera-frame joints over time.
        fps: frames per second (units m/s^2); None: m/frame^2.

    Returns:
        columns ``method, sequence, view, jitter, [jitter_gt, accel_err, mpjpe_m]``.
    """
    jp = _t(joints_pred).transpose(0, 1)  # (V, T, J, 3)
    out = pd.DataFrame({"method": method, "sequence": sequence, "view": np.arange(jp.shape[0]),
                        "jitter": M.jitter(jp, fps).numpy()})
    if joints_gt is not None:
        jg = _t(joints_gt).transpose(0, 1)
        out["jitter_gt"] = M.jitter(jg, fps).numpy()
        out["accel_err"] = M.acceleration_error(jp, jg, fps).numpy()
        out["mpjpe_m"] = M.mpjpe(jp, jg).mean(dim=-1).numpy()
    return out


def to_long(table: pd.DataFrame, id_vars: Sequence[str] | None = None) -> pd.DataFrame:
    """Melt a wide metric table into one row per (row, metric): ``id_vars..., metric, value``.

    ``id_vars`` defaults to the non-float columns (method, sample, view, joint ...).
    """
    if id_vars is None:
        id_vars = [c for c in table.columns if not pd.api.types.is_float_dtype(table[c])]
    return table.melt(id_vars=list(id_vars), var_name="metric", value_name="value")


def summarize(table: pd.DataFrame, by: Sequence[str] = ("method",), metrics: Sequence[str] | None = None
              ) -> pd.DataFrame:
    """One row per (group, metric): ``by..., metric, mean, median, std, count``.

    Args:
        table: any wide table of this module (or a long one with ``metric``/``value`` columns).
        by: grouping columns (e.g. ``("method", "view")`` for per-view results).
        metrics: metric columns (default: every float column not in ``by``).
    """
    if not {"metric", "value"} <= set(table.columns):
        if metrics is None:
            metrics = [c for c in table.columns if pd.api.types.is_float_dtype(table[c]) and c not in by]
        table = table.melt(id_vars=list(by), value_vars=list(metrics), var_name="metric", value_name="value")
    elif metrics is not None:
        table = table[table["metric"].isin(list(metrics))]
    keys = [*by, "metric"]
    grouped = table.groupby(keys, sort=False)["value"]
    return grouped.agg(["mean", "median", "std", "count"]).reset_index()


def paper_table(per_view: pd.DataFrame, methods: Sequence[str] | None = None) -> pd.DataFrame:
    """Table I layout: one row per method, columns ``MPE [m]``, ``MPJPE [m]``, ``PA-MPJPE [m]``
    (means over all images of all views), in the order of ``methods`` if given."""
    s = per_view.groupby("method", sort=False)[["mpe_m", "mpjpe_m", "pa_mpjpe_m"]].mean()
    s.columns = ["MPE [m]", "MPJPE [m]", "PA-MPJPE [m]"]
    if methods is not None:
        s = s.reindex(list(methods))
    return s
