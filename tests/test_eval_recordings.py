"""Errors on recordings (airpose_lib.eval.recordings) against hand-computed values and smplx."""
from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
import torch

from airpose_lib.eval.recordings import (
    body_joints,
    per_view_params,
    recording_frame_table,
    recording_table,
    relative_camera_positions,
)


def _rot(rng, n):
    q = rng.normal(size=(n, 4))
    q /= np.linalg.norm(q, axis=-1, keepdims=True)
    w, x, y, z = q.T
    return np.stack([
        np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)], -1),
        np.stack([2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)], -1),
        np.stack([2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)], -1)], -2)


def _ground_truth(F=6, V=2, seed=0):
    rng = np.random.default_rng(seed)
    phi = _rot(rng, F * V).reshape(F, V, 3, 3)
    tau = rng.normal(size=(F, V, 3)) + [0, 0, 10]
    j0 = rng.normal(scale=0.4, size=(F, 22, 3))
    joints = np.einsum("fvij,fkj->fvki", phi, j0) + tau[:, :, None]
    theta = np.broadcast_to(np.eye(3), (F, V, 21, 3, 3)).copy()
    return {"phi": phi, "tau": tau, "theta": theta, "beta": np.zeros((F, V, 10)), "j3d_cam": joints}


def test_per_view_params_broadcasts_shared_theta_and_beta():
    gt = _ground_truth()
    est = {"phi": gt["phi"], "tau": gt["tau"], "theta": gt["theta"][:, 0], "beta": np.arange(10.0)}
    p = per_view_params(est, num_views=2)
    assert p["theta"].shape == (6, 2, 21, 3, 3) and p["beta"].shape == (6, 2, 10)
    assert np.array_equal(p["beta"][3, 1], np.arange(10.0))
    with pytest.raises(ValueError, match="tau must be"):
        per_view_params({**est, "tau": gt["tau"][:, :1]})
    with pytest.raises(KeyError, match="beta"):
        per_view_params({k: v for k, v in est.items() if k != "beta"})
    with pytest.raises(ValueError, match="expected 3"):
        per_view_params(est, num_views=3)


def test_translation_offset_in_one_view_gives_hand_computed_errors():
    gt = _ground_truth()
    d = np.array([0.3, 0.0, 0.4])  # |d| = 0.5
    est = {k: gt[k].copy() for k in ("phi", "tau", "theta", "beta")}
    est["tau"][:, 0] += d
    joints = gt["j3d_cam"].copy()
    joints[:, 0] += d  # the whole body moves with its origin
    t = recording_frame_table(est, gt, joints, "m")
    v0, v1 = t[t.view == 0], t[t.view == 1]
    np.testing.assert_allclose(v0["mpe_m"], 0.5, atol=1e-12)
    np.testing.assert_allclose(v1["mpe_m"], 0.0, atol=1e-12)
    np.testing.assert_allclose(t["mpjpe_m"], 0.0, atol=1e-12)  # pelvis aligned: a shift is no pose error
    np.testing.assert_allclose(v0["err_z_m"], 0.4, atol=1e-12)
    # UAV2's centre in UAV1 = tau1 - phi1 phi2^T tau2: moving tau1 by d moves it by d.
    np.testing.assert_allclose(t["rel_t_err_m"], 0.5, atol=1e-9)
    np.testing.assert_allclose(t["rel_rot_deg"], 0.0, atol=1e-5)


def test_relative_camera_positions_match_the_closed_form():
    gt = _ground_truth(F=4)
    _, t = relative_camera_positions(gt)
    expected = gt["tau"][:, 0] - np.einsum("fij,fkj,fk->fi", gt["phi"][:, 0], gt["phi"][:, 1], gt["tau"][:, 1])
    np.testing.assert_allclose(t, expected, atol=1e-9)


def test_recording_table_means_mask_and_jitter():
    F = 8
    gt = _ground_truth(F=F)
    time = np.arange(F) / 10.0
    # joints on a parabola x = a t^2 / 2: the acceleration is a everywhere
    a = 2.0
    gt["j3d_cam"] = np.zeros((F, 2, 22, 3))
    gt["j3d_cam"][..., 0] = 0.5 * a * time[:, None, None] ** 2
    est = {k: gt[k].copy() for k in ("phi", "tau", "theta", "beta")}
    est["tau"][:4, 1, 2] += 1.0  # depth error of 1 m in UAV2 on the first half only
    table = recording_table({"A": est}, gt, {"A": gt["j3d_cam"]}, fps=10.0, sequence="s")
    row = table.iloc[0]
    assert row["frames"] == F
    assert row["mpe_uav1_m"] == pytest.approx(0.0, abs=1e-12)
    assert row["mpe_uav2_m"] == pytest.approx(0.5)
    assert row["depth_err_m"] == pytest.approx(0.25)  # |z err| averaged over frames and both views
    assert row["jitter_mps2"] == pytest.approx(a)
    assert row["jitter_gt_mps2"] == pytest.approx(a)
    masked = recording_table({"A": est}, gt, {"A": gt["j3d_cam"]}, fps=10.0,
                             mask=np.arange(F) >= 4).iloc[0]
    assert masked["frames"] == 4 and masked["mpe_uav2_m"] == pytest.approx(0.0, abs=1e-12)


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_body_joints_match_a_smplx_forward(open_model_files, dtype):
    from airpose_lib.body import load_body_model
    from airpose_lib.geometry import axis_angle_to_matrix

    rng = np.random.default_rng(3)
    F, V = 3, 2
    model = load_body_model("open", "neutral", dtype=dtype, batch_size=F * V)
    aa = rng.normal(scale=0.3, size=(F, V, 21, 3))
    beta = rng.normal(size=(F, V, 10))
    phi = _rot(rng, F * V).reshape(F, V, 3, 3)
    tau = rng.normal(size=(F, V, 3)) + [0, 0, 8]
    est = {"phi": phi, "tau": tau, "theta": axis_angle_to_matrix(torch.as_tensor(aa)).numpy(), "beta": beta}
    J = body_joints(est, model)
    out = model(betas=torch.as_tensor(beta.reshape(-1, 10), dtype=dtype),
                body_pose=torch.as_tensor(aa.reshape(-1, 63), dtype=dtype),
                global_orient=torch.zeros(F * V, 3, dtype=dtype), transl=torch.zeros(F * V, 3, dtype=dtype),
                batch_size=F * V)
    J0 = out.joints[:, :22].detach().double().numpy().reshape(F, V, 22, 3)
    ref = np.einsum("fvij,fvkj->fvki", phi, J0) + tau[:, :, None]
    tol = 1e-5 if dtype == torch.float32 else 1e-10
    np.testing.assert_allclose(J, ref, atol=tol)


def test_depth_summary_and_checks():
    from airpose_lib.experiments.recording_tables import airpose_plus_checks, depth_summary
    from airpose_lib.experiments.recordings import RecordingExperiment

    class Seq:
        def __init__(self, gt):
            self.ground_truth = gt

    F = 5
    gt = {"tau": np.zeros((F, 2, 3))}
    gt["tau"][..., 2] = 10.0
    smooth = {"tau": gt["tau"].copy()}
    smooth["tau"][..., 2] += 0.2
    noisy = {"tau": gt["tau"].copy()}
    noisy["tau"][::2, :, 2] += 1.0  # z alternates 11, 10, 11, ...: |dz| = 1 every frame
    exp = RecordingExperiment("t", None, {"p": Seq(gt)}, {"p": {"A": smooth, "B": noisy}}, {}, pd.DataFrame(), {})
    t = depth_summary(exp, {"AirPose": "A", "SPIN-style": "B"}).set_index(["method", "view"])
    assert t.loc[("AirPose", "UAV1"), "z_err_m"] == pytest.approx(0.2)
    assert t.loc[("AirPose", "UAV2"), "dz_per_frame_m"] == pytest.approx(0.0)
    assert t.loc[("SPIN-style", "UAV1"), "dz_per_frame_m"] == pytest.approx(1.0)
    assert t.loc[("SPIN-style", "UAV1"), "z_err_m"] == pytest.approx(3 / 5)

    table = pd.DataFrame([
        {"sequence": "p", "method": "AirPose", "mpjpe_m": 0.2, "rel_t_err_m": 1.0},
        {"sequence": "p", "method": "AirPose+", "mpjpe_m": 0.1, "rel_t_err_m": 2.0}])
    checks = airpose_plus_checks(table).set_index("claim")
    assert bool(checks.loc["AirPose+ MPJPE < AirPose", "holds"]) is True
    assert bool(checks.loc["AirPose+ relative-camera translation error < AirPose", "holds"]) is False
    assert "AirPose+ jitter < AirPose" not in checks.index  # no column, no claim


def test_paper_claims_measure_and_judge_each_claim():
    from airpose_lib.eval.recordings import PAPER_CLAIMS, paper_claims

    rows = []
    for p, (a_t, a_r, p_t, p_r) in {"person1": (2.0, 20.0, 1.5, 15.0), "person2": (4.0, 40.0, 2.0, 45.0)}.items():
        rows += [{"sequence": p, "method": "AirPose", "mpjpe_m": 0.2, "rel_t_err_m": a_t, "rel_rot_deg": a_r},
                 {"sequence": p, "method": "AirPose+", "mpjpe_m": 0.15 if p == "person1" else 0.25,
                  "rel_t_err_m": p_t, "rel_rot_deg": p_r}]
    depth = pd.DataFrame([
        {"sequence": s, "view": v, "method": m, "dz_per_frame_m": dz, "z_err_m": ze}
        for s in ("person1", "person2") for v in ("UAV1", "UAV2")
        for m, dz, ze in (("AirPose", 0.05, 0.5), ("SPIN-style", 0.4, 3.0))])
    c = paper_claims(pd.DataFrame(rows), depth)
    verdict = c[c["sequence"] == "overall"].set_index("claim")["verdict"]
    assert set(verdict.index) == set(PAPER_CLAIMS)
    assert verdict["pose"] == "partly"  # better on person 1, worse on person 2
    assert verdict["uav2"] == "partly"  # person 2's rotation error grew
    # translation gain 2.0 (person 2) > 0.5 (person 1); rotation gain -5 < 5: partly
    assert verdict["uav2_twisting"] == "partly"
    assert verdict["depth_smooth"] == "holds" and verdict["depth_real"] == "holds"
    smooth = c[(c["claim"] == "depth_smooth") & (c["sequence"] == "person2 UAV1")].iloc[0]
    assert smooth["value"] == pytest.approx(0.05) and smooth["ratio"] == pytest.approx(0.125)
    gain = c[(c["claim"] == "uav2_twisting") & c["measure"].str.contains(" m ")].iloc[0]
    assert (gain["value"], gain["reference"]) == (pytest.approx(2.0), pytest.approx(0.5))
    # no ground truth: only the smoothness claim can be measured
    c = paper_claims(pd.DataFrame(), depth[["sequence", "view", "method", "dz_per_frame_m"]])
    verdict = c[c["sequence"] == "overall"].set_index("claim")["verdict"]
    assert verdict["depth_smooth"] == "holds"
    assert (verdict.drop("depth_smooth") == "not measurable").all()


def test_recording_table_gives_the_median_uav2_errors_beside_the_means():
    gt = _ground_truth(F=8)
    est = {k: gt[k].copy() for k in ("phi", "tau", "theta", "beta")}
    est["tau"][:5, 1, 2] += 1.0  # UAV2's depth 1 m off in 5 of 8 frames: UAV2-in-UAV1 off by 1 m there
    row = recording_table({"A": est}, gt, {"A": gt["j3d_cam"]}, fps=10.0).iloc[0]
    assert row["rel_t_err_m"] == pytest.approx(5 / 8)
    assert row["rel_t_median_m"] == pytest.approx(1.0)
    assert row["rel_rot_median_deg"] == pytest.approx(0.0, abs=1e-5)


def test_compare_methods_tests_paired_frame_differences():
    """A is B minus 2 cm on every frame plus noise that averages out: lower, with the shift as the
    difference; C equals B up to zero-mean noise: not significant. Views are averaged per frame,
    frames only one method scored drop out."""
    from airpose_lib.eval.recordings import compare_methods

    rng = np.random.default_rng(3)
    F = 300
    base = 0.1 + 0.02 * rng.random((F, 2))

    def table(values):
        return pd.DataFrame({"frame": np.repeat(np.arange(F), 2), "view": np.tile([0, 1], F),
                             "mpjpe_m": values.reshape(-1)})

    noise = rng.normal(0, 0.001, (F, 2))
    noise -= noise.mean()
    a = base - 0.02 + noise
    a[5] = np.nan  # frame 5: A has no estimate
    t = compare_methods({"A": table(a), "B": table(base), "C": table(base + noise)}, [("A", "B"), ("C", "B")],
                        metrics=["mpjpe_m", "absent"], block=30).set_index("method")
    assert len(t) == 2 and t.loc["A", "frames"] == F - 1 and t.loc["C", "frames"] == F
    assert t.loc["A", "difference"] == pytest.approx(-0.02, abs=2e-4) and t.loc["A", "verdict"] == "lower"
    assert t.loc["A", "low"] < t.loc["A", "difference"] < t.loc["A", "high"] < 0
    assert t.loc["A", "reference_value"] == pytest.approx(np.delete(base, 5, 0).mean())
    assert t.loc["C", "verdict"] == "not significant" and t.loc["C", "difference"] == pytest.approx(0, abs=1e-12)
