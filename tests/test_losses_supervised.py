"""Supervised losses (paper eq. 3-4): hand-computed terms, cross-view terms, weights, body evaluation."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import torch

from airpose_lib.body.forward import BodyForward
from airpose_lib.geometry import axis_angle_to_matrix, matrix_to_rot6d
from airpose_lib.losses import (
    AirPoseLossConfig,
    BaselineLossConfig,
    SupervisedLoss,
    cross_view_mse,
    limb_weights,
    loss_config,
    official_variations,
    view_mse,
)

F64 = torch.float64


@pytest.fixture(scope="module")
def bodies64(open_model_files):
    from airpose_lib.body import load_body_model

    return {g: load_body_model("open", g, dtype=F64) for g in ("neutral", "male", "female")}


def _rot(aa):
    return axis_angle_to_matrix(torch.as_tensor(aa, dtype=F64))


def make_batch(bodies, B=2, V=2, gender=0, seed=0):
    """Consistent ground truth: random body, root rotation and translation per view, 2D/3D joints
    from the gendered model (the same construction as the data package's samples)."""
    g = torch.Generator().manual_seed(seed)
    theta = torch.randn(B, 21, 3, generator=g, dtype=F64) * 0.3
    beta = torch.randn(B, 10, generator=g, dtype=F64)
    phi = _rot(torch.randn(B, V, 3, generator=g, dtype=F64))
    tau = torch.stack([torch.randn(B, V, generator=g, dtype=F64), torch.randn(B, V, generator=g, dtype=F64),
                       10 + torch.rand(B, V, generator=g, dtype=F64)], dim=-1)
    K = torch.tensor([[1475.0, 0, 960], [0, 1475, 540], [0, 0, 1]], dtype=F64).expand(B, V, 3, 3)
    genders = torch.full((B,), gender, dtype=torch.long) if isinstance(gender, int) else torch.tensor(gender)
    names = {0: "neutral", 1: "male", 2: "female"}
    j3d = torch.empty(B, V, 22, 3, dtype=F64)
    for b in range(B):
        body = BodyForward(bodies[names[int(genders[b])]])
        j3d[b], _ = body(axis_angle_to_matrix(theta[b]), beta[b], phi[b], tau[b], vertices=False)
    p = j3d @ K.transpose(-1, -2)
    j2d = p[..., :2] / p[..., 2:]
    bbox = torch.cat((j2d.amin(-2) - 20, j2d.amax(-2) + 20), dim=-1)  # the tight box, (B, V, 4)
    return dict(theta=theta, beta=beta, phi=phi, tau=tau, K=K, gender=genders, j2d=j2d, j3d_cam=j3d, bbox=bbox)


def perfect_pred(batch):
    V = batch["phi"].shape[1]
    theta = axis_angle_to_matrix(batch["theta"]).unsqueeze(1).expand(-1, V, -1, -1, -1)
    beta = batch["beta"].unsqueeze(1).expand(-1, V, -1)
    return dict(phi=batch["phi"].clone(), theta=theta.clone(), beta=beta.clone(), tau=batch["tau"].clone())


# -- term helpers on tiny tensors -----------------------------------------------------------------
def test_view_mse_hand_computed():
    pred = torch.tensor([[[1.0, 2.0], [0.0, 0.0]], [[3.0, 0.0], [1.0, 1.0]]], dtype=F64)  # (B=2, V=2, 2)
    target = torch.zeros_like(pred)
    # view 0: mean(1, 4, 9, 0) = 3.5; view 1: mean(0, 0, 1, 1) = 0.5
    assert view_mse(pred, target, view_reduction="sum").item() == pytest.approx(4.0)
    assert view_mse(pred, target, view_reduction="mean").item() == pytest.approx(2.0)
    w = torch.tensor([2.0, 0.0], dtype=F64)  # weight on the element axis
    # view 0: mean(2, 0, 18, 0) = 5; view 1: mean(0, 0, 2, 0) = 0.5
    assert view_mse(pred, target, w, "sum").item() == pytest.approx(5.5)


def test_cross_view_mse_hand_computed():
    x = torch.tensor([[[1.0, 2.0], [1.0, 0.0]], [[0.0, 0.0], [2.0, 2.0]]], dtype=F64)  # (B=2, V=2, 2)
    # differences: (0, 2), (-2, -2) -> squares 0, 4, 4, 4 -> mean 3
    assert cross_view_mse(x).item() == pytest.approx(3.0)
    same = torch.randn(4, 1, 5, dtype=F64).expand(4, 2, 5)
    assert cross_view_mse(same).item() == 0.0
    assert cross_view_mse(torch.randn(4, 1, 5)).item() == 0.0  # one view: no pair
    three = torch.zeros(1, 3, 1, dtype=F64)
    three[0, 2, 0] = 3.0  # pairs (0,1): 0, (0,2): 9, (1,2): 9 -> mean 6
    assert cross_view_mse(three).item() == pytest.approx(6.0)


def test_limb_weights():
    w = limb_weights(3.0)
    assert w.shape == (22,)
    assert w[[4, 5, 18, 19]].tolist() == [3.0] * 4 and w[[7, 8, 20, 21]].tolist() == [9.0] * 4
    assert w.sum().item() == 14 + 12 + 36
    wt = limb_weights(3.0, 21, offset=1)  # theta has no root: knees are entries 3 and 4
    assert wt[[3, 4, 17, 18]].tolist() == [3.0] * 4 and wt[[6, 7, 19, 20]].tolist() == [9.0] * 4


# -- configs --------------------------------------------------------------------------------------
def test_paper_weights_and_variants():
    b, a = BaselineLossConfig(), AirPoseLossConfig()
    assert (b.w_j2d, b.w_j3d, b.w_phi, b.w_theta, b.w_beta, b.w_V, b.w_tau) == (0.01, 1, 1, 100, 1, 100, 0)
    assert (a.w_j2d, a.w_j3d, a.w_phi, a.w_tau, a.w_theta, a.w_beta, a.w_V) == (0.002, 1, 1, 10, 50, 1, 50)
    assert a.cross_view and a.view_reduction == "sum" and a.vertices_with_phi
    assert not b.cross_view and b.view_reduction == "mean" and not b.vertices_with_phi
    assert loss_config("AirPose") == a and loss_config("baseline") == b
    assert loss_config("multiview").w_tau == 0 and loss_config("multiview").cross_view
    assert loss_config("fullcam").w_tau == 10 and not loss_config("fullcam").cross_view
    # the official Baseline (hmr.py): crop-pixel 2D term and the weak-camera scale guard
    assert (b.j2d_frame, b.w_cam_scale) == ("crop", 1.0) and (a.j2d_frame, a.w_cam_scale) == ("full", 0.0)
    # Multi-view = Baseline + the exchange's one consistency term (muhmr.py), nothing of AirPose's loss
    m = loss_config("multiview")
    assert dataclasses.asdict(dataclasses.replace(m, cross_view=False, cross_view_terms=b.cross_view_terms)) == \
        dataclasses.asdict(b)
    assert m.cross_view_terms == ("theta",) and m.w_j2d == 0.01 and not m.vertices_with_phi
    o = official_variations(a)
    assert (o.total_scale, o.limb_weight_j3d, o.j3d_cross_view, o.w_beta_gt, o.vertices_with_phi) == (
        60, 3, True, 0, False)
    assert official_variations(BaselineLossConfig()).j3d_cross_view is False
    assert loss_config("airpose", official=True, w_V=0).w_V == 0
    with pytest.raises(ValueError):
        loss_config("spin")
    with pytest.raises(ValueError):
        AirPoseLossConfig(view_reduction="max")


# -- the loss -------------------------------------------------------------------------------------
def test_perfect_prediction_zero_terms(bodies64):
    batch = make_batch(bodies64, gender=0)
    pred = perfect_pred(batch)
    for cfg in (BaselineLossConfig(), AirPoseLossConfig(), official_variations(AirPoseLossConfig())):
        loss = SupervisedLoss(cfg, bodies64)
        t = loss(pred, batch)
        for k in ("j2d", "j3d", "phi", "tau", "theta", "V", "beta_gt"):
            assert t[k].item() == pytest.approx(0.0, abs=1e-12), (k, cfg)
        # only the shape prior remains: mean(beta^2) per view (+0 cross term)
        prior = batch["beta"].square().mean().item()
        n_views = 2 if cfg.view_reduction == "sum" else 1
        assert t["beta"].item() == pytest.approx(n_views * prior)
        assert t["total"].item() == pytest.approx(cfg.total_scale * cfg.w_beta * n_views * prior)


def test_literal_cross_vertex_term_is_not_zero_for_perfect_prediction(bodies64):
    """The paper's cross term with each view's own phi penalises a perfect prediction (the views'
    root rotations differ); our default compares the bodies without root rotation."""
    batch = make_batch(bodies64, gender=0)
    pred = perfect_pred(batch)
    literal = SupervisedLoss(AirPoseLossConfig(cross_vertex_frame="own_phi"), bodies64)(pred, batch)
    default = SupervisedLoss(AirPoseLossConfig(), bodies64)(pred, batch)
    assert default["V"].item() == pytest.approx(0.0, abs=1e-12)
    assert literal["V"].item() > 1e-3
    # identical root rotations in both views: the literal term vanishes as well
    batch["phi"][:, 1] = batch["phi"][:, 0]
    pred = perfect_pred(batch)
    literal = SupervisedLoss(AirPoseLossConfig(cross_vertex_frame="own_phi"), bodies64)(pred, batch)
    assert literal["V"].item() == pytest.approx(0.0, abs=1e-12)


def test_j2d_tau_and_phi_hand_computed(bodies64):
    batch = make_batch(bodies64, B=1, V=2)
    pred = perfect_pred(batch)
    d = torch.tensor([0.1, -0.2, 0.5], dtype=F64)
    pred["tau"][0, 0] += d  # view 0 off by d
    cfg = AirPoseLossConfig()
    t = SupervisedLoss(cfg, bodies64)(pred, batch)
    # tau: view 0 mean(d^2), view 1 zero, summed over views
    assert t["tau"].item() == pytest.approx(d.square().mean().item())
    # j2d: project the GT camera-frame joints shifted by d with numpy
    X = batch["j3d_cam"][0, 0].numpy() + d.numpy()
    K = batch["K"][0, 0].numpy()
    uv = X[:, :2] * np.array([K[0, 0], K[1, 1]]) / X[:, 2:] + K[:2, 2]
    expected = np.mean((uv - batch["j2d"][0, 0].numpy()) ** 2)
    assert t["j2d"].item() == pytest.approx(expected, rel=1e-9)
    # the 3D joint, pose, shape and vertex terms ignore tau (no phi/tau for j3d; no tau for V)
    for k in ("j3d", "theta", "V", "phi"):
        assert t[k].item() == pytest.approx(0.0, abs=1e-12)
    # phi: a 90 degree error about z in view 1 -> ||R - I||_F^2 = 4, mean over 9 entries
    pred = perfect_pred(batch)
    Rz = _rot([0.0, 0.0, np.pi / 2])
    pred["phi"][0, 1] = batch["phi"][0, 1] @ Rz
    t = SupervisedLoss(cfg, bodies64)(pred, batch)
    assert t["phi"].item() == pytest.approx(4.0 / 9.0)
    assert t["V"].item() > 0 and t["j3d"].item() == pytest.approx(0.0, abs=1e-12)  # V includes phi
    tb = SupervisedLoss(BaselineLossConfig(), bodies64)(pred, batch)
    assert tb["V"].item() == pytest.approx(0.0, abs=1e-12)  # Baseline's L_V has no phi
    assert tb["phi"].item() == pytest.approx(4.0 / 9.0 / 2)  # mean over views


def test_theta_beta_cross_terms_and_limb_weights(bodies64):
    batch = make_batch(bodies64, B=2, V=2)
    pred = perfect_pred(batch)
    eps = 0.3
    pred["beta"][:, 1, 0] += eps  # view 1's first beta off by eps
    R = _rot([eps, 0.0, 0.0])
    pred["theta"][:, 1, 3] = pred["theta"][:, 1, 3] @ R  # view 1's left knee (theta entry 3)
    cfg = AirPoseLossConfig(w_V=0)
    t = SupervisedLoss(cfg, bodies64)(pred, batch)
    prior = batch["beta"].square().mean(dim=(0, 1))
    b1 = batch["beta"].clone()
    b1[:, 0] += eps
    # beta: sum_c mean(beta_c^2) + mean((1beta - 2beta)^2)
    assert t["beta"].item() == pytest.approx((prior + b1.square().mean() + eps**2 / 10).item())
    # theta: view-1 error and cross error are the same knee rotation difference
    se = (pred["theta"][:, 1, 3] - pred["theta"][:, 0, 3]).square().sum() / (2 * 21 * 9)
    assert t["theta"].item() == pytest.approx(2 * se.item())
    t3 = SupervisedLoss(dataclasses.replace(cfg, limb_weight_theta=3.0), bodies64)(pred, batch)
    assert t3["theta"].item() == pytest.approx(3 * 2 * se.item())  # knees x3
    # weighted 3D joints: recompute by hand from BodyForward
    cfgj = dataclasses.replace(cfg, limb_weight_j3d=3.0)
    tj = SupervisedLoss(cfgj, bodies64)(pred, batch)
    body = BodyForward(bodies64["neutral"])
    Jp, _ = body(pred["theta"][:, 1], pred["beta"][:, 1], vertices=False)
    Jg, _ = body(axis_angle_to_matrix(batch["theta"]), batch["beta"], vertices=False)
    w = limb_weights(3.0, dtype=F64)[:, None]
    assert tj["j3d"].item() == pytest.approx(((Jp - Jg).square() * w).mean().item())


def test_weights_scale_total(bodies64):
    batch = make_batch(bodies64, B=2, V=2, seed=3)
    g = torch.Generator().manual_seed(5)
    pred = perfect_pred(batch)
    pred["tau"] = pred["tau"] + 0.1 * torch.randn(pred["tau"].shape, generator=g, dtype=F64)
    pred["beta"] = pred["beta"] + 0.1 * torch.randn(pred["beta"].shape, generator=g, dtype=F64)
    pred["phi"] = pred["phi"] @ _rot(0.1 * torch.randn(2, 2, 3, generator=g, dtype=F64))
    cfg = AirPoseLossConfig()
    t = SupervisedLoss(cfg, bodies64)(pred, batch)
    assert t["total"].item() == pytest.approx(sum(w * t[k].item() for k, w in cfg.weights.items()))
    t2 = SupervisedLoss(dataclasses.replace(cfg, w_tau=20.0), bodies64)(pred, batch)
    assert t2["total"].item() - t["total"].item() == pytest.approx(10.0 * t["tau"].item())
    t60 = SupervisedLoss(dataclasses.replace(cfg, total_scale=60.0), bodies64)(pred, batch)
    assert t60["total"].item() == pytest.approx(60 * t["total"].item())
    tg = SupervisedLoss(dataclasses.replace(cfg, w_beta_gt=2.0), bodies64)(pred, batch)
    assert tg["total"].item() - t["total"].item() == pytest.approx(2.0 * t["beta_gt"].item())
    assert t["beta_gt"].item() == pytest.approx(2 * ((pred["beta"] - batch["beta"][:, None]) ** 2).mean().item())


def test_ground_truth_uses_gendered_model(bodies64):
    batch = make_batch(bodies64, B=3, V=2, gender=[1, 2, 0], seed=2)
    pred = perfect_pred(batch)  # same parameters, but predictions use the neutral model
    t = SupervisedLoss(AirPoseLossConfig(), bodies64)(pred, batch)
    body_n = BodyForward(bodies64["neutral"])
    theta = axis_angle_to_matrix(batch["theta"])
    jn, _ = body_n(theta, batch["beta"], vertices=False)
    jg = torch.stack([BodyForward(bodies64[n])(theta[i], batch["beta"][i], vertices=False)[0]
                      for i, n in enumerate(("male", "female", "neutral"))])
    assert t["j3d"].item() == pytest.approx(2 * (jn - jg).square().mean().item())
    assert t["j3d"].item() > 0 and t["j2d"].item() > 0 and t["V"].item() > 0
    # 2D: the sample's j2d (gendered) against the neutral model's projection
    assert torch.allclose(batch["j3d_cam"][2], body_n(theta[2], batch["beta"][2], batch["phi"][2],
                                                      batch["tau"][2], vertices=False)[0])


def test_vertex_subsample_and_6d(bodies64):
    batch = make_batch(bodies64, B=2, V=2, seed=4)
    pred = perfect_pred(batch)
    pred["theta"] = pred["theta"] @ _rot(0.05 * torch.ones(21, 3, dtype=F64))
    full = SupervisedLoss(AirPoseLossConfig(), bodies64)(pred, batch)
    sub = SupervisedLoss(AirPoseLossConfig(vertex_subsample=2000), bodies64)
    assert sub.bodies["neutral"].num_vertices == 2000
    ts = sub(pred, batch)
    assert ts["V"].item() == pytest.approx(full["V"].item(), rel=0.2)  # an unbiased estimate
    for k in ("j2d", "j3d", "theta"):
        assert ts[k].item() == pytest.approx(full[k].item())
    # 6D: an unnormalised 6D output decodes to the right matrix but is penalised in 6D space
    pred = perfect_pred(batch)
    pred["phi6d"] = 2 * matrix_to_rot6d(pred["phi"])
    pred["theta6d"] = matrix_to_rot6d(pred["theta"])
    t6 = SupervisedLoss(AirPoseLossConfig(rotation_space="6d"), bodies64)(pred, batch)
    tm = SupervisedLoss(AirPoseLossConfig(), bodies64)(pred, batch)
    assert tm["phi"].item() == pytest.approx(0.0, abs=1e-12)
    assert t6["phi"].item() == pytest.approx(2 * matrix_to_rot6d(batch["phi"]).square().mean().item())
    assert t6["theta"].item() == pytest.approx(0.0, abs=1e-12)


def test_float32_gradients(bodies64):
    batch64 = make_batch(bodies64, gender=[1, 2])
    batch = {k: (v.float() if v.is_floating_point() else v) for k, v in batch64.items()}
    pred = {k: v.float().requires_grad_(True) for k, v in perfect_pred(batch64).items()}
    with torch.no_grad():
        pred["tau"] += 0.2
    loss = SupervisedLoss(AirPoseLossConfig(vertex_subsample=500), bodies64).float()
    assert loss.bodies["male"].mesh_posedirs.dtype == torch.float32
    t = loss(pred, batch)
    assert t["total"].dtype == torch.float32
    t64 = SupervisedLoss(AirPoseLossConfig(vertex_subsample=500), bodies64)(perfect_pred(batch64) | {
        "tau": batch64["tau"] + 0.2}, batch64)
    for k in t:
        assert t[k].item() == pytest.approx(t64[k].item(), rel=1e-4, abs=1e-6), k
    t["total"].backward()
    for k, v in pred.items():
        assert v.grad is not None and torch.isfinite(v.grad).all(), k
    assert pred["tau"].grad.abs().sum() > 0


def test_crop_frame_j2d_is_full_frame_scaled_to_a_224_crop(bodies64):
    """Crop pixels are ``(224 / side) (uv - centre) + 112``: the squared error of each view scales by
    ``(224 / side)^2`` (hand-computed from the boxes)."""
    batch = make_batch(bodies64, B=1, V=2)
    pred = perfect_pred(batch)
    pred["tau"][0, :, 0] += 0.05  # both views off sideways
    full = SupervisedLoss(dataclasses.replace(BaselineLossConfig(), j2d_frame="full"), bodies64)(pred, batch)
    crop = SupervisedLoss(BaselineLossConfig(), bodies64)(pred, batch)
    box = batch["bbox"][0]
    side = torch.maximum(box[:, 2] - box[:, 0], box[:, 3] - box[:, 1])
    per_view_full = []
    for v in range(2):
        X = batch["j3d_cam"][0, v] + pred["tau"][0, v] - batch["tau"][0, v]
        uv = X[:, :2] * 1475.0 / X[:, 2:] + torch.tensor([960.0, 540.0], dtype=F64)
        per_view_full.append(((uv - batch["j2d"][0, v]) ** 2).mean())
    assert full["j2d"].item() == pytest.approx(float(sum(per_view_full)) / 2, rel=1e-9)
    expected = sum(per_view_full[v] * (224.0 / side[v]) ** 2 for v in range(2)) / 2
    assert crop["j2d"].item() == pytest.approx(float(expected), rel=1e-9)

