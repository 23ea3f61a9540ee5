"""Tidy evaluation tables: shapes, values and summaries."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
import torch
from scipy.spatial.transform import Rotation

from airpose_lib.eval import (
    PER_VIEW_METRICS,
    paper_table,
    per_joint_table,
    per_view_table,
    relative_camera_table,
    sequence_table,
    summarize,
    to_long,
)


def _gt(N=3, V=2, seed=0):
    g = torch.Generator().manual_seed(seed)
    joints = torch.randn(N, V, 22, 3, generator=g, dtype=torch.float64)
    tau = torch.randn(N, V, 3, generator=g, dtype=torch.float64) + torch.tensor([0, 0, 10.0], dtype=torch.float64)
    phi = torch.eye(3, dtype=torch.float64).expand(N, V, 3, 3).clone()
    return dict(tau=tau, phi=phi, j3d_cam=joints)


def test_per_view_table_values():
    gt = _gt()
    pred = dict(tau=gt["tau"] + torch.tensor([0.0, 0.0, 0.5], dtype=torch.float64), phi=gt["phi"],
                joints=gt["j3d_cam"] + 1.0)
    t = per_view_table(pred, gt, method="airpose", sample_ids=[10, 11, 12])
    assert len(t) == 6 and list(t.columns) == ["method", "sample", "view", *PER_VIEW_METRICS]
    assert t["sample"].tolist() == [10, 10, 11, 11, 12, 12] and t["view"].tolist() == [0, 1] * 3
    assert np.allclose(t["mpe_m"], 0.5) and np.allclose(t["err_z_m"], 0.5) and np.allclose(t["err_x_m"], 0)
    assert np.allclose(t["mpjpe_m"], 0, atol=1e-12)  # a translated skeleton: pelvis aligned
    assert np.allclose(t["root_rot_deg"], 0, atol=1e-6)
    assert np.allclose(t[["root_yaw_deg", "root_tilt_deg"]], 0, atol=1e-6)
    # the bodies turned by 30 deg about their up axis (upright, facing away): all yaw, no tilt
    turn = torch.as_tensor(Rotation.from_euler("y", 30, degrees=True).as_matrix())
    t = per_view_table({**pred, "phi": gt["phi"] @ turn}, gt)
    np.testing.assert_allclose(t[["root_rot_deg", "root_yaw_deg"]], 30.0, atol=1e-9)
    np.testing.assert_allclose(t["root_tilt_deg"], 0.0, atol=1e-6)
    assert per_view_table({k: v for k, v in pred.items() if k != "phi"}, gt)["root_yaw_deg"].isna().all()
    # one view's joints perturbed: only that row changes
    pred["joints"] = gt["j3d_cam"].clone()
    pred["joints"][1, 1, 3, 0] += 0.22
    t = per_view_table(pred, gt)
    assert t.loc[(t["sample"] == 1) & (t["view"] == 1), "mpjpe_m"].item() == pytest.approx(0.01)
    assert t["mpjpe_m"].sum() == pytest.approx(0.01)


def test_true_root_mpjpe_scores_the_body_pose_alone():
    gt = _gt()
    gt["joints_zero_beta"] = gt["j3d_cam"] - gt["j3d_cam"][:, :, :1]
    half_turn = torch.diag(torch.tensor([-1.0, -1.0, 1.0], dtype=torch.float64))  # a root 180 deg off about z
    pred = dict(tau=gt["tau"], phi=gt["phi"] @ half_turn, joints=gt["j3d_cam"],
                joints_zero_beta=gt["joints_zero_beta"] @ half_turn.T,
                joints_zero_beta_true_root=gt["joints_zero_beta"].clone())
    pred["joints_zero_beta_true_root"][0, 1, 5, 1] += 0.22  # one joint of one view's pose wrong by 22 cm
    t = per_view_table(pred, gt)
    xy = gt["joints_zero_beta"][..., :2].norm(dim=-1).mean(-1).reshape(-1).numpy()  # |p - (-p)| = 2 |p_xy|
    np.testing.assert_allclose(t["mpjpe_m"], 2 * xy)
    want = np.zeros(6)
    want[1] = 0.01  # 0.22 m / 22 joints, only in sample 0 view 1
    np.testing.assert_allclose(t["mpjpe_true_root_m"], want, atol=1e-12)
    np.testing.assert_allclose(t["root_rot_deg"], 180.0, atol=1e-6)
    del pred["joints_zero_beta_true_root"]  # not predicted: NaN, never a made-up number
    assert per_view_table(pred, gt)["mpjpe_true_root_m"].isna().all()


def test_per_joint_table():
    gt = _gt(N=2)
    pred = dict(joints=gt["j3d_cam"].clone())
    pred["joints"][0, 1, 20, 2] += 0.3
    t = per_joint_table(pred, gt, method="m")
    assert len(t) == 2 * 2 * 22
    row = t[(t["sample"] == 0) & (t["view"] == 1) & (t["joint"] == "left_wrist")]
    assert row["error_m"].item() == pytest.approx(0.3)
    assert t["error_m"].sum() == pytest.approx(0.3)
    assert set(t["joint"]) == set(t["joint"].iloc[:22])


def test_relative_camera_table():
    gt = _gt(N=2)
    pred = dict(tau=gt["tau"].clone(), phi=gt["phi"])
    pred["tau"][:, 0, 0] += 0.2
    t = relative_camera_table(pred, gt, method="m")
    assert t["rel_t_err_m"].tolist() == pytest.approx([0.2, 0.2])
    assert np.allclose(t["rel_rot_deg"], 0, atol=1e-6)
    # with identity root rotations camera 2 in camera 1 is tau1 - tau2
    assert t["rel_tz_gt_m"].tolist() == pytest.approx((gt["tau"][:, 0, 2] - gt["tau"][:, 1, 2]).tolist())


def test_sequence_table():
    T = 5
    x = torch.zeros(T, 2, 22, 3, dtype=torch.float64)
    x[:, :, :, 0] = (0.1 * torch.arange(T, dtype=torch.float64) ** 2)[:, None, None]
    t = sequence_table(x, torch.zeros_like(x), method="m", fps=None)
    assert t["jitter"].tolist() == pytest.approx([0.2, 0.2]) and t["jitter_gt"].tolist() == [0.0, 0.0]
    assert t["accel_err"].tolist() == pytest.approx([0.2, 0.2])
    assert np.allclose(t["mpjpe_m"], 0)  # a rigid shift per frame: pelvis aligned


def test_summarize_and_paper_table():
    gt = _gt(N=4)
    rows = []
    for name, dz in (("baseline", 0.5), ("airpose", 0.1)):
        pred = dict(tau=gt["tau"] + torch.tensor([0.0, 0.0, dz], dtype=torch.float64), phi=gt["phi"],
                    joints=gt["j3d_cam"])
        rows.append(per_view_table(pred, gt, method=name))
    table = pd.concat(rows, ignore_index=True)
    s = summarize(table)
    assert set(s.columns) == {"method", "metric", "mean", "median", "std", "count"}
    mpe = s[s["metric"] == "mpe_m"].set_index("method")["mean"]
    assert mpe["baseline"] == pytest.approx(0.5) and mpe["airpose"] == pytest.approx(0.1)
    # every metric counts all 8 views; the true-root MPJPE was not predicted here (NaN, not counted)
    assert (s.loc[s["metric"] != "mpjpe_true_root_m", "count"] == 8).all()
    assert (s.loc[s["metric"] == "mpjpe_true_root_m", "count"] == 0).all()
    sv = summarize(table, by=("method", "view"), metrics=["mpe_m"])
    assert len(sv) == 4 and (sv["count"] == 4).all()
    long = to_long(table)
    assert set(long.columns) == {"method", "sample", "view", "metric", "value"}
    assert len(long) == len(table) * len(PER_VIEW_METRICS)
    s2 = summarize(long, metrics=["mpe_m"])
    assert s2.set_index("method")["mean"]["baseline"] == pytest.approx(0.5)
    p = paper_table(table, methods=["baseline", "airpose"])
    assert list(p.index) == ["baseline", "airpose"] and list(p.columns) == ["MPE [m]", "MPJPE [m]", "PA-MPJPE [m]"]
    assert p.loc["airpose", "MPE [m]"] == pytest.approx(0.1)
