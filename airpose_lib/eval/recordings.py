"""Errors of per-frame estimates on a two-drone recording with ground truth.

The paper's real-data section could only plot its estimates; on the kit's generated recordings
every quantity it plots has a ground truth, so each method gets a row of numbers: MPJPE and
PA-MPJPE of the 22 body joints, the person's position error per view, the error of UAV2's pose
in UAV1 computed from the two per-view body poses, and jitter (mean acceleration).

Estimates are mappings of camera-frame parameters over F frames and V views, the format of
``airpose predict`` / ``airpose fit`` (:mod:`airpose_lib.finetune.predict`,
:class:`airpose_lib.fitting.AirPosePlusResult`):

``phi (F, V, 3, 3)``, ``tau (F, V, 3)`` metres, ``theta (F, V, 21, 3, 3)`` or shared over views
``(F, 21, 3, 3)``, ``beta (F, V, 10)``, ``(F, 10)`` or ``(10,)``.

Ground truth is the recording's ``ground_truth.npz`` (:attr:`Sequence.ground_truth`) with ``phi``,
``tau`` and ``j3d_cam (F, V, 22, 3)``.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np
import pandas as pd
import torch

from airpose_lib.geometry import relative_camera_pose
from airpose_lib.model.smplx_params import posed_joints_and_vertices

from . import metrics as M
from .significance import paired_bootstrap

__all__ = [
    "RECORDING_METRICS",
    "per_view_params",
    "body_joints",
    "person_positions",
    "relative_camera_positions",
    "relative_camera_errors_against",
    "recording_frame_table",
    "recording_table",
    "COMPARISON_METRICS",
    "compare_methods",
    "PAPER_CLAIMS",
    "paper_claims",
]

#: Columns of :func:`recording_table`, with their meaning.
RECORDING_METRICS: dict[str, str] = {
    "mpjpe_m": "MPJPE of the 22 body joints, pelvis aligned, mean over frames and views",
    "pa_mpjpe_m": "MPJPE after Procrustes alignment",
    "mpe_uav1_m": "person position (model origin) error in UAV1's camera frame",
    "mpe_uav2_m": "person position error in UAV2's camera frame",
    "depth_err_m": "mean |z error| of the person position over both views",
    "rel_t_err_m": "error of UAV2's position in UAV1 from the two body poses",
    "rel_rot_deg": "error of UAV2's orientation in UAV1",
    "rel_t_median_m": "median over frames of the UAV2-in-UAV1 position error",
    "rel_rot_median_deg": "median over frames of the UAV2-in-UAV1 orientation error",
    "jitter_mps2": "mean acceleration of the joints in the camera frame, m/s^2",
    "jitter_gt_mps2": "the same for the ground truth",
}


def _np(x) -> np.ndarray:
    if isinstance(x, torch.Tensor):
        x = x.detach().cpu().numpy()
    return np.asarray(x, dtype=np.float64)


def per_view_params(params: Mapping, num_views: int | None = None) -> dict[str, np.ndarray]:
    """Broadcast an estimate to per-frame, per-view arrays (float64).

    Args:
        params: ``phi (F, V, 3, 3)``, ``tau (F, V, 3)``, ``theta`` ``(F, V, 21, 3, 3)`` or
            ``(F, 21, 3, 3)``, ``beta`` ``(F, V, 10)``, ``(F, 10)`` or ``(10,)``.
        num_views: V, checked if given.

    Returns:
        ``phi (F, V, 3, 3)``, ``tau (F, V, 3)``, ``theta (F, V, 21, 3, 3)``, ``beta (F, V, 10)``.
    """
    missing = {"phi", "tau", "theta", "beta"} - set(params)
    if missing:
        raise KeyError(f"estimate lacks {sorted(missing)}; expected phi, tau, theta, beta")
    phi, tau, theta, beta = (_np(params[k]) for k in ("phi", "tau", "theta", "beta"))
    if phi.ndim != 4 or phi.shape[-2:] != (3, 3):
        raise ValueError(f"phi must be (F, V, 3, 3), got {phi.shape}")
    F, V = phi.shape[:2]
    if num_views is not None and V != num_views:
        raise ValueError(f"the estimate has {V} views, expected {num_views}")
    if tau.shape != (F, V, 3):
        raise ValueError(f"tau must be (F, V, 3) = {(F, V, 3)}, got {tau.shape}")
    if theta.shape == (F, 21, 3, 3):
        theta = np.broadcast_to(theta[:, None], (F, V, 21, 3, 3))
    if theta.shape != (F, V, 21, 3, 3):
        raise ValueError(f"theta must be (F, V, 21, 3, 3) or (F, 21, 3, 3), got {theta.shape}")
    if beta.ndim == 1:
        beta = np.broadcast_to(beta, (F, V, beta.shape[0]))
    elif beta.ndim == 2:
        beta = np.broadcast_to(beta[:, None], (F, V, beta.shape[1]))
    if beta.shape[:2] != (F, V):
        raise ValueError(f"beta must be (F, V, B), (F, B) or (B,), got {beta.shape}")
    return {"phi": phi, "tau": tau, "theta": np.ascontiguousarray(theta),
            "beta": np.ascontiguousarray(beta)}


def body_joints(params: Mapping, body_model, chunk: int = 4096) -> np.ndarray:
    """Camera-frame joints of an estimate: ``J = phi J0(theta, beta) + tau`` (model origin).

    Args:
        params: an estimate (see the module docstring).
        body_model: a neutral ``smplx.SMPLX`` (``airpose_lib.body.load_body_model``); its dtype is used.

    Returns:
        ``(F, V, 22, 3)`` joints in metres.
    """
    p = per_view_params(params)
    F, V = p["phi"].shape[:2]
    dtype = body_model.v_template.dtype
    flat = {k: torch.as_tensor(v.reshape(F * V, *v.shape[2:]), dtype=dtype) for k, v in p.items()}
    out = np.empty((F * V, 22, 3))
    with torch.no_grad():
        for s in range(0, F * V, chunk):
            part = {k: v[s:s + chunk] for k, v in flat.items()}
            out[s:s + chunk] = posed_joints_and_vertices(body_model, part, joints_only=True)["joints"][:, :22].double().numpy()
    return out.reshape(F, V, 22, 3)


def person_positions(params: Mapping) -> np.ndarray:
    """The person's position (model origin) in each camera frame: ``(F, V, 3)`` = ``tau``."""
    return _np(params["tau"])


def relative_camera_positions(params: Mapping, views: tuple[int, int] = (0, 1)) -> tuple[np.ndarray, np.ndarray]:
    """UAV ``views[1]``'s pose in UAV ``views[0]``'s camera frame from the two body poses.

    Returns:
        ``R (F, 3, 3)`` and ``t (F, 3)`` (the second camera's centre in the first camera frame).
    """
    phi, tau = torch.as_tensor(_np(params["phi"])), torch.as_tensor(_np(params["tau"]))
    i, j = views
    R, t = relative_camera_pose(phi[:, i], tau[:, i], phi[:, j], tau[:, j])
    return R.numpy(), t.numpy()


def relative_camera_errors_against(R: np.ndarray, t: np.ndarray, R_ref: np.ndarray,
                                   t_ref: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Errors of UAV 2's pose in UAV 1 against a reference of the same quantity (the generated
    cameras, or the ArUco markers' :func:`airpose_lib.data.sequences.markers.marker_relative_cameras`).

    Args:
        R, R_ref: ``(..., 3, 3)`` UAV 2's orientation in UAV 1's camera frame.
        t, t_ref: ``(..., 3)`` UAV 2's position in UAV 1's camera frame, metres.

    Returns:
        ``t_err (...)`` metres and ``rot_err (...)`` degrees (geodesic), float64.
    """
    t_err, R_err = M.relative_pose_errors(*(torch.as_tensor(_np(x), dtype=torch.float64) for x in (R, t, R_ref, t_ref)))
    return t_err.numpy(), torch.rad2deg(R_err).numpy()


def recording_frame_table(estimate: Mapping, ground_truth: Mapping, joints: np.ndarray,
                          method: str = "", frames: Sequence[int] | None = None) -> pd.DataFrame:
    """One row per (frame, view): the errors behind :func:`recording_table`.

    Args:
        estimate: per-view parameters (module docstring).
        ground_truth: ``phi (F, V, 3, 3)``, ``tau (F, V, 3)``, ``j3d_cam (F, V, 22, 3)``.
        joints: ``(F, V, 22, 3)`` the estimate's camera-frame joints (:func:`body_joints`).
        frames: ``(F,)`` frame numbers (default ``0..F-1``).

    Returns:
        columns ``method, frame, view, mpjpe_m, pa_mpjpe_m, mpe_m, err_{x,y,z}_m, rel_t_err_m,
        rel_rot_deg`` (the last two repeat per view: they belong to the frame).
    """
    p = per_view_params(estimate)
    F, V = p["phi"].shape[:2]
    jg = torch.as_tensor(_np(ground_truth["j3d_cam"]))
    jp = torch.as_tensor(_np(joints))
    if jp.shape != jg.shape:
        raise ValueError(f"joints {tuple(jp.shape)} and ground truth {tuple(jg.shape)} differ")
    tau_p, tau_g = torch.as_tensor(p["tau"]), torch.as_tensor(_np(ground_truth["tau"]))
    d = tau_p - tau_g
    cols = {
        "mpjpe_m": M.mpjpe(jp, jg),
        "pa_mpjpe_m": M.pa_mpjpe(jp, jg),
        "mpe_m": M.translation_error(tau_p, tau_g),
        "err_x_m": d[..., 0], "err_y_m": d[..., 1], "err_z_m": d[..., 2],
    }
    if V >= 2:
        t_err, r_err = M.relative_camera_errors(torch.as_tensor(p["phi"]), tau_p,
                                                torch.as_tensor(_np(ground_truth["phi"])), tau_g)
        cols["rel_t_err_m"] = t_err[:, None].expand(F, V)
        cols["rel_rot_deg"] = torch.rad2deg(r_err)[:, None].expand(F, V)
    ids = np.arange(F) if frames is None else np.asarray(frames)
    return pd.DataFrame({"method": method, "frame": np.repeat(ids, V), "view": np.tile(np.arange(V), F),
                         **{k: v.reshape(-1).numpy() for k, v in cols.items()}})


def recording_table(estimates: Mapping[str, Mapping], ground_truth: Mapping, joints: Mapping[str, np.ndarray],
                    fps: float, sequence: str = "", mask: np.ndarray | None = None) -> pd.DataFrame:
    """One row per method: the per-sequence numbers of :data:`RECORDING_METRICS`.

    Args:
        estimates: method -> per-view parameters over the same F frames.
        ground_truth: ``phi``, ``tau``, ``j3d_cam`` over the F frames.
        joints: method -> ``(F, V, 22, 3)`` camera-frame joints of that estimate.
        fps: frame rate (jitter in m/s^2).
        sequence: value of the ``sequence`` column.
        mask: optional ``(F,)`` bool, the frames to average the pose and position errors over
            (e.g. frames every method estimated); jitter always uses the whole sequence.
    """
    rows = []
    jg = torch.as_tensor(_np(ground_truth["j3d_cam"]))
    jit_gt = M.jitter(jg.transpose(0, 1), fps).mean().item()
    for method, est in estimates.items():
        t = recording_frame_table(est, ground_truth, joints[method], method)
        if mask is not None:
            keep = np.asarray(mask, bool)
            t = t[np.repeat(keep, t["view"].nunique())]
        jp = torch.as_tensor(_np(joints[method]))
        row = {"sequence": sequence, "method": method, "frames": int(t["frame"].nunique()),
               "mpjpe_m": t["mpjpe_m"].mean(), "pa_mpjpe_m": t["pa_mpjpe_m"].mean()}
        for v, g in t.groupby("view"):
            row[f"mpe_uav{v + 1}_m"] = g["mpe_m"].mean()
        row["depth_err_m"] = t["err_z_m"].abs().mean()
        if "rel_t_err_m" in t:
            per_frame = t[t["view"] == 0]
            row["rel_t_err_m"] = per_frame["rel_t_err_m"].mean()
            row["rel_rot_deg"] = per_frame["rel_rot_deg"].mean()
            row["rel_t_median_m"] = per_frame["rel_t_err_m"].median()
            row["rel_rot_median_deg"] = per_frame["rel_rot_deg"].median()
        row["jitter_mps2"] = M.jitter(jp.transpose(0, 1), fps).mean().item()
        row["jitter_gt_mps2"] = jit_gt
        rows.append(row)
    return pd.DataFrame(rows)


#: Per-frame errors :func:`compare_methods` tests (per-view ones averaged over the views of a frame).
COMPARISON_METRICS = ("mpjpe_m", "mpe_m", "rel_t_err_m", "rel_rot_deg")


def compare_methods(frame_tables: Mapping[str, pd.DataFrame], pairs: Sequence[tuple[str, str]],
                    metrics: Sequence[str] = COMPARISON_METRICS, block: int = 30, n_resamples: int = 2000,
                    confidence: float = 0.95, seed: int = 0) -> pd.DataFrame:
    """Is method A's error on a recording really lower than method B's? A paired block bootstrap.

    Per frame, the difference ``e_A - e_B`` of the two methods' errors (each the mean over the
    frame's views); the statistic is its mean over the frames both methods scored, and its interval
    comes from :func:`~airpose_lib.eval.significance.paired_bootstrap` with blocks of ``block``
    consecutive frames (errors along a recording are correlated in time: a detection, a pose or a
    depth error lasts many frames).

    Args:
        frame_tables: method -> :func:`recording_frame_table` rows (``frame``, ``view``, metrics).
        pairs: ``(A, B)`` methods, A compared against B.
        metrics: frame-table columns.
        block: frames per resampled block (e.g. one second).

    Returns:
        one row per pair and metric: ``method``, ``reference``, ``metric``, ``value`` and
        ``reference_value`` (means over the common frames), ``difference`` (A - B), ``low``,
        ``high``, ``frames`` and ``verdict``: ``lower`` (the interval is below zero), ``higher``
        or ``not significant``.
    """
    rows = []
    for a, b in pairs:
        for metric in metrics:
            if metric not in frame_tables[a] or metric not in frame_tables[b]:
                continue
            both = pd.concat({"a": frame_tables[a].groupby("frame")[metric].mean(),
                              "b": frame_tables[b].groupby("frame")[metric].mean()}, axis=1).dropna()
            if both.empty:
                continue
            both = both.sort_index()
            r = paired_bootstrap(both["a"].to_numpy() - both["b"].to_numpy(), n_resamples, confidence, seed,
                                 block=block)
            verdict = "lower" if r.high < 0 else ("higher" if r.low > 0 else "not significant")
            rows.append({"method": a, "reference": b, "metric": metric, "value": float(both["a"].mean()),
                         "reference_value": float(both["b"].mean()), "difference": r.mean, "low": r.low,
                         "high": r.high, "frames": len(both), "verdict": verdict})
    return pd.DataFrame(rows)


#: The paper's qualitative real-data claims (Sec. IV-C) that :func:`paper_claims` measures.
PAPER_CLAIMS: dict[str, str] = {
    "pose": "AirPose+ improves the articulated pose over AirPose (MPJPE, each person)",
    "uav2": "AirPose+ improves UAV2-in-UAV1 over AirPose (translation and rotation error, each person)",
    "uav2_twisting": "the UAV2-in-UAV1 improvement is larger for person 2's twisting poses than for person 1",
    "depth_smooth": "AirPose's depth is smoother than SPIN's (mean abs. frame-to-frame change of z, "
                    "each person and UAV)",
    "depth_real": "AirPose's depth is more realistic than SPIN's (mean abs. z error, each person and UAV)",
}


def _verdict(ok: list[bool]) -> str:
    if not ok:
        return "not measurable"
    return "holds" if all(ok) else ("partly" if any(ok) else "does not hold")


def paper_claims(table: pd.DataFrame, depth: pd.DataFrame, *, tuning: str = "person1", test: str = "person2",
                 airpose: str = "AirPose", plus: str = "AirPose+", spin: str = "SPIN-style") -> pd.DataFrame:
    """Each claim of :data:`PAPER_CLAIMS` with the measured numbers and a verdict.

    Args:
        table: :func:`recording_table` rows of every person (``sequence``, ``method``, ``mpjpe_m``,
            ``rel_t_err_m``, ``rel_rot_deg``); may be empty (no ground truth).
        depth: ``sequence, method, view, dz_per_frame_m`` and, with ground truth, ``z_err_m``
            (``experiments.recording_tables.depth_summary``) with methods ``airpose`` and ``spin``.
        tuning, test: the fine-tuning and the test person (the paper's person 1 and 2).

    Returns:
        one row per claim and person (or view): ``claim``, ``sequence``, ``measure``, ``value``
        (the claim's subject: AirPose+ or AirPose), ``reference`` (AirPose or SPIN-style),
        ``ratio`` (value / reference), ``holds``; and one ``overall`` row per claim with the
        verdict ``holds`` / ``partly`` / ``does not hold`` / ``not measurable``.
    """
    rows: list[dict] = []

    def add(claim, seq, measure, value, reference, holds):
        rows.append({"claim": claim, "sequence": seq, "measure": measure, "value": float(value),
                     "reference": float(reference),
                     "ratio": float(value) / float(reference) if reference else float("nan"),
                     "holds": bool(holds), "verdict": ""})

    def overall(claim):
        ok = [r["holds"] for r in rows if r["claim"] == claim and r["sequence"] != "overall"]
        rows.append({"claim": claim, "sequence": "overall", "measure": PAPER_CLAIMS[claim], "value": float("nan"),
                     "reference": float("nan"), "ratio": float("nan"), "holds": _verdict(ok) == "holds",
                     "verdict": _verdict(ok)})

    t = table.set_index(["sequence", "method"]) if not table.empty else None

    def get(seq, method, col):
        if t is None or (seq, method) not in t.index or col not in t.columns:
            return None
        v = float(t.loc[(seq, method), col])
        return v if np.isfinite(v) else None

    persons = list(dict.fromkeys(table["sequence"])) if not table.empty else []
    for p in persons:
        a, b = get(p, plus, "mpjpe_m"), get(p, airpose, "mpjpe_m")
        if a is not None and b is not None:
            add("pose", p, "MPJPE m (AirPose+ vs AirPose)", a, b, a < b)
    overall("pose")
    gain = {}
    for p in persons:
        for col, unit in (("rel_t_err_m", "m"), ("rel_rot_deg", "deg")):
            a, b = get(p, plus, col), get(p, airpose, col)
            if a is not None and b is not None:
                add("uav2", p, f"UAV2-in-UAV1 {col.split('_')[1]} error {unit} (AirPose+ vs AirPose)", a, b, a < b)
                gain[(p, col)] = b - a
    overall("uav2")
    for col, unit in (("rel_t_err_m", "m"), ("rel_rot_deg", "deg")):
        if (test, col) in gain and (tuning, col) in gain:
            g2, g1 = gain[(test, col)], gain[(tuning, col)]
            add("uav2_twisting", f"{test} vs {tuning}", f"error reduction by AirPose+, {unit} ({test} vs {tuning})",
                g2, g1, g2 > g1)
    overall("uav2_twisting")
    d = depth.set_index(["sequence", "view", "method"]) if not depth.empty else None
    keys = sorted({(s_, v) for s_, v, _ in d.index}) if d is not None else []
    for claim, col, label in (("depth_smooth", "dz_per_frame_m", "mean abs. dz per frame m"),
                              ("depth_real", "z_err_m", "mean abs. z error m")):
        for s_, v in keys:
            if (s_, v, airpose) in d.index and (s_, v, spin) in d.index and col in d.columns:
                a, b = float(d.loc[(s_, v, airpose), col]), float(d.loc[(s_, v, spin), col])
                if np.isfinite(a) and np.isfinite(b):
                    add(claim, f"{s_} {v}", f"{label} (AirPose vs {spin})", a, b, a < b)
        overall(claim)
    return pd.DataFrame(rows, columns=["claim", "sequence", "measure", "value", "reference", "ratio", "holds",
                                       "verdict"])
