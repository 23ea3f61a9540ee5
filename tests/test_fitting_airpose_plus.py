"""AirPose+: keypoint kinematics, the loss terms, the frame rule, bad input and a synthetic fit."""
from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
import roma
import torch

from airpose_lib.body import BODY_25_FROM_SMPLX, COCO18_FROM_SMPLX, load_body_model
from airpose_lib.body.forward import BodyForward
from airpose_lib.fitting import (
    AirPosePlusConfig,
    AirPosePlusLoss,
    airpose_plus,
    fit_sequence,
    init_from_views,
)
from airpose_lib.geometry import matrix_to_rot6d, relative_camera_pose
from airpose_lib.prior import PriorTrainConfig, VPoser, train_prior
from airpose_lib.reproduce.configs import kit_configs

F_SEQ = 16
SIGMA = 30.0


@pytest.fixture(autouse=True)
def _one_thread():
    """Small problems: one intra-op thread is as fast, and far faster when other jobs load the
    cores (torch's waiting threads then spin against them)."""
    n = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(n)


@pytest.fixture(scope="module")
def body64(open_model_files):
    return load_body_model("open", dtype=torch.float64)


@pytest.fixture(scope="module")
def prior():
    """A prior trained briefly on the kit's pose sampler (the fit needs a meaningful decoder)."""
    from airpose_lib.data.still.poses import sample_body_pose

    n = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        poses = sample_body_pose(np.random.default_rng(0), 6000)
        model, _ = train_prior(poses, PriorTrainConfig(steps=400, batch_size=128, kl_anneal_steps=100, lr=2e-3))
    finally:
        torch.set_num_threads(n)
    return model


def _look_at(eye, target):
    eye, target = np.asarray(eye, float), np.asarray(target, float)
    z = (target - eye) / np.linalg.norm(target - eye)
    x = np.cross(z, [0.0, -1.0, 0.0])
    x /= np.linalg.norm(x)
    R = np.stack([x, np.cross(z, x), z])  # rows: camera axes (OpenCV) in world coordinates
    return R, -R @ eye


def _world_joints(body, theta, beta):
    return BodyForward(body, range(76), vertices=None)(theta, beta.reshape(1, -1))[0]  # (F, 76, 3), identity root


def _project_cv(X, K):
    """Reference projection with OpenCV (no rotation/translation: X is in the camera frame)."""
    import cv2

    pts, _ = cv2.projectPoints(X.reshape(-1, 3).numpy(), np.zeros(3), np.zeros(3), K.numpy(), None)
    return torch.as_tensor(pts.reshape(*X.shape[:-1], 2))


def _scene(body, F=F_SEQ, seed=0, noise_px=1.5):
    """Ground truth: sampler poses interpolated over F frames, a walking/turning root, two cameras
    ~10 m away (one high and behind), BODY_25 + COCO-18 keypoints projected with noise."""
    from airpose_lib.data.still.poses import sample_body_pose

    rng = np.random.default_rng(seed)
    keys = torch.as_tensor(sample_body_pose(rng, 2))
    s = torch.linspace(0, 1, F, dtype=torch.float64)[:, None, None]
    theta = roma.rotvec_to_rotmat((1 - s) * keys[0] + s * keys[1])  # (F, 21, 3, 3)
    beta = torch.as_tensor(rng.normal(0.0, 0.5, 10))
    heading = torch.linspace(0.0, 0.5, F, dtype=torch.float64)
    R_wb = roma.rotvec_to_rotmat(torch.stack([0 * heading, heading, 0 * heading], -1))
    t_wb = torch.stack([torch.linspace(-0.4, 0.4, F), torch.zeros(F), torch.linspace(0, 0.3, F)], -1).double()
    cams = [_look_at([1.0, 4.0, 9.0], [0.0, 1.0, 0.0]), _look_at([-7.0, 6.0, -6.0], [0.0, 1.0, 0.0])]
    R_cw = torch.as_tensor(np.stack([c[0] for c in cams]))
    t_cw = torch.as_tensor(np.stack([c[1] for c in cams]))
    phi = R_cw[None] @ R_wb[:, None]  # (F, V, 3, 3)
    tau = (R_cw[None] @ t_wb[:, None, :, None]).squeeze(-1) + t_cw[None]
    K = torch.tensor([[1475.0, 0, 960], [0, 1475.0, 540], [0, 0, 1]], dtype=torch.float64).expand(2, 3, 3)
    J0 = _world_joints(body, theta, beta)
    Xc = J0[:, None] @ phi.transpose(-1, -2) + tau[:, :, None]
    uv = torch.stack([_project_cv(Xc[:, c], K[c]) for c in range(2)], 1)  # (F, V, 76, 2)
    g = torch.Generator().manual_seed(seed)
    kps = {}
    for name, idx in (("body25", BODY_25_FROM_SMPLX), ("coco18", COCO18_FROM_SMPLX)):
        p = uv[:, :, list(idx)]
        p = p + noise_px * torch.randn(p.shape, generator=g, dtype=torch.float64)
        kps[name] = torch.cat([p, torch.full(p.shape[:-1] + (1,), 0.9, dtype=torch.float64)], -1).numpy()
    return kps, K, dict(theta=theta, beta=beta, phi=phi, tau=tau, J0=J0)


def _perturbed(gt, seed=1, rot_deg=8.0, theta_deg=10.0):
    g = torch.Generator().manual_seed(seed)
    F = gt["theta"].shape[0]

    def rot(*shape, deg):
        return roma.rotvec_to_rotmat(torch.randn(*shape, 3, generator=g, dtype=torch.float64)
                                     * math.radians(deg) / math.sqrt(3))

    return dict(
        phi=rot(F, 2, deg=rot_deg) @ gt["phi"],
        tau=gt["tau"] + torch.randn(F, 2, 3, generator=g, dtype=torch.float64) * torch.tensor([0.1, 0.1, 0.4]),
        theta=gt["theta"][:, None] @ rot(F, 2, 21, deg=theta_deg),
        beta=gt["beta"] + 0.5 * torch.randn(F, 2, 10, generator=g, dtype=torch.float64),
    )


# -- loss terms -----------------------------------------------------------------------------------
def _exact_problem(body, prior, offsets=None, **cfg):
    """Keypoints = exact projections of the ground truth (+ offsets); returns loss, variables."""
    kps, K, gt = _scene(body, F=3, noise_px=0.0)
    for (name, f, c, j, axis), d in (offsets or {}).items():
        kps[name][f, c, j, axis] += d
    loss = AirPosePlusLoss(kps, K, prior=prior, body=body, config=AirPosePlusConfig(**cfg))
    v = torch.zeros(3, 32)
    phi6d = matrix_to_rot6d(gt["phi"]).float().requires_grad_(True)
    tau = gt["tau"].float().requires_grad_(True)
    beta = gt["beta"].float().requires_grad_(True)
    return loss, (v, phi6d, tau, beta), gt["theta"].float()


def test_j2d_is_confidence_weighted_geman_mcclure_per_coordinate(body64):
    rho = lambda d: d * d / (d * d + SIGMA ** 2)  # noqa: E731
    prior = VPoser().eval()
    loss, args, theta = _exact_problem(body64, prior)
    _, parts = loss(*args, theta=theta)
    assert parts["j2d"] < 1e-6  # exact keypoints
    offs = {("body25", 0, 0, 4, 0): 10.0, ("body25", 0, 0, 4, 1): 10.0, ("coco18", 2, 1, 9, 0): 1000.0}
    loss, args, theta = _exact_problem(body64, prior, offs)
    _, parts = loss(*args, theta=theta)
    expected = 0.9 * (2 * rho(10.0) + rho(1000.0))  # per coordinate, not rho of the 2D distance
    assert parts["j2d"] == pytest.approx(expected, rel=1e-3, abs=1e-5)
    assert 0.9 * rho(1000.0) < 0.9  # bounded: an outlier costs at most its confidence per coordinate
    # Redescending: a far outlier pulls less on the root translation than a 30 px error.
    grads = []
    for d in (30.0, 3000.0):
        loss, (v, phi6d, tau, beta), theta = _exact_problem(body64, prior, {("body25", 1, 0, 4, 0): d})
        total, _ = loss(v, phi6d, tau, beta, theta=theta)
        total.backward()
        grads.append(tau.grad[1, 0].norm().item())
    assert grads[1] < 0.05 * grads[0]
    # sigma scales the penalty as documented.
    loss, args, theta = _exact_problem(body64, prior, {("body25", 0, 0, 4, 0): 10.0}, sigma=10.0)
    assert loss(*args, theta=theta)[1]["j2d"] == pytest.approx(0.9 * 0.5, rel=1e-3)


def test_beta_prior_acts_on_the_optimised_beta(body64):
    prior = VPoser().eval()
    loss, (v, phi6d, tau, beta), theta = _exact_problem(body64, prior, w_j2d=0.0, w_temp=0.0, w_vposer=0.0)
    total, parts = loss(v, phi6d, tau, beta, theta=theta)
    assert parts["beta"] == pytest.approx(2000.0 * beta.detach().square().sum().item(), rel=1e-5)
    total.backward()
    torch.testing.assert_close(beta.grad, 2 * 2000.0 * beta.detach())


def test_a_large_beta_weight_shrinks_beta(body64, prior):
    kps, K, gt = _scene(body64, F=6)
    init = _perturbed(gt)
    # Start near the true shape, entries within +-0.4: Adam moves an entry by at most ~lr = 0.01
    # per step, so 200 steps can bring every entry to 0.
    init["beta"] = gt["beta"].clamp(-0.4, 0.4)
    kw = dict(prior=prior, body=body64, progress=False, iterations=200, latent_start=200)
    weak = airpose_plus(kps, K, init, w_beta=0.0, **kw)
    strong = airpose_plus(kps, K, init, w_beta=1e6, **kw)
    start = init["beta"].norm().item()
    assert strong.beta.norm().item() < 0.1 * start
    assert weak.beta.norm().item() > 0.5 * start
    assert not torch.allclose(weak.beta, init["beta"].float())  # the optimiser moves beta


def test_temporal_term_and_official_weights(body64):
    prior = VPoser().eval()
    cfg = AirPosePlusConfig.official_code()
    assert (cfg.temp_pose, cfg.temp_root, cfg.temp_transl) == (10.0, 100.0, 100.0)
    loss, (v, phi6d, tau, beta), theta = _exact_problem(body64, prior, w_j2d=0.0, w_beta=0.0, w_vposer=0.0,
                                                        temp_pose=2.0, temp_root=3.0, temp_transl=5.0)
    _, parts = loss(v, phi6d, tau, beta, theta=theta)
    phi = roma.special_gramschmidt(phi6d.detach().reshape(3, 2, 3, 2))  # first two columns given
    expected = (2.0 * (theta[1:] - theta[:-1]).square().sum() + 3.0 * (phi[1:] - phi[:-1]).square().sum()
                + 5.0 * (tau[1:] - tau[:-1]).detach().square().sum())
    assert parts["temp"] == pytest.approx(expected.item(), rel=1e-4)
    # Blocks of frames add up to the whole (what chunking relies on).
    whole = loss(v, phi6d, tau, beta, theta=theta)[0]
    parts_sum = loss(v, phi6d, tau, beta, theta=theta, stop=1)[0] + \
        loss(v, phi6d, tau, beta, theta=theta, start=1, with_beta=False)[0]
    torch.testing.assert_close(parts_sum, whole)


# -- frame rule and bad input ---------------------------------------------------------------------
def test_a_frame_without_confidence_is_skipped_and_changes_nothing(body64):
    prior = VPoser().eval()
    kps, K, gt = _scene(body64, F=7)
    init = _perturbed(gt)
    init["beta"] = init["beta"].mean((0, 1))  # one shape, so both runs start from identical values
    bad = 3
    kps_zero = {k: v.copy() for k, v in kps.items()}
    kps_zero["body25"][bad, ..., 2] = 0.0
    kps_zero["coco18"][bad] = np.nan  # NaN detections count as missing
    kw = dict(prior=prior, body=body64, progress=False, iterations=12, latent_start=4)
    with_bad = airpose_plus(kps_zero, K, init, **kw)
    keep = [i for i in range(7) if i != bad]
    without = airpose_plus({k: v[keep] for k, v in kps.items()}, K,
                           {k: v[keep] if k != "beta" else v for k, v in init.items()}, **kw)
    assert with_bad.skipped_frames == [bad] and with_bad.kept.tolist() == [i != bad for i in range(7)]
    assert with_bad.frame_confidence[bad] == 0
    for name in ("theta", "phi", "tau", "v"):
        torch.testing.assert_close(getattr(with_bad, name)[keep], getattr(without, name), atol=1e-6, rtol=0)
    torch.testing.assert_close(with_bad.beta, without.beta, atol=1e-6, rtol=0)
    torch.testing.assert_close(with_bad.history["loss"], without.history["loss"], rtol=1e-5, atol=0)
    # The skipped frame keeps its initialisation (views' mean), finite.
    start = init_from_views(**init)
    torch.testing.assert_close(with_bad.tau[bad], start["tau"][bad])
    assert all(torch.isfinite(getattr(with_bad, n)).all() for n in ("theta", "phi", "tau", "v"))


def test_bad_inputs_raise_clear_errors(body64):
    prior = VPoser().eval()
    kps, K, gt = _scene(body64, F=4)
    init = _perturbed(gt)
    kw = dict(prior=prior, body=body64, progress=False, iterations=1)
    with pytest.raises(ValueError, match="empty sequence"):
        airpose_plus({k: v[:0] for k, v in kps.items()}, K, {k: v[:0] for k, v in init.items()}, **kw)
    with pytest.raises(ValueError, match="disagree"):
        airpose_plus({"body25": kps["body25"], "coco18": kps["coco18"][:3]}, K, init, **kw)
    with pytest.raises(ValueError, match="frames"):
        airpose_plus(kps, K, {k: v[:3] for k, v in init.items()}, **kw)
    with pytest.raises(ValueError, match="K must be"):
        airpose_plus(kps, K[:1], init, **kw)
    with pytest.raises(ValueError, match="unknown detector"):
        airpose_plus({"hrnet": kps["body25"]}, K, init, **kw)
    with pytest.raises(ValueError, match="keypoints"):
        airpose_plus({"body25": kps["coco18"]}, K, init, **kw)
    with pytest.raises(ValueError, match="min_frame_confidence"):
        airpose_plus({k: v * np.array([1, 1, 0]) for k, v in kps.items()}, K, init, **kw)
    nan_init = dict(init, tau=init["tau"].clone())
    nan_init["tau"][0, 0, 0] = float("nan")
    with pytest.raises(ValueError, match="NaN"):
        airpose_plus(kps, K, nan_init, **kw)
    with pytest.raises(TypeError):
        fit_sequence(object(), init, **kw)


# -- the fit --------------------------------------------------------------------------------------
def _errors(body, res_theta, res_beta, phi, tau, gt):
    J = _world_joints(body, res_theta.double(), res_beta.double())[:, :22]
    Jg = gt["J0"][:, :22]
    mpjpe = ((J - J[:, :1]) - (Jg - Jg[:, :1])).norm(dim=-1).mean().item()
    R12, t12 = relative_camera_pose(phi[:, 0].double(), tau[:, 0].double(), phi[:, 1].double(), tau[:, 1].double())
    R12g, t12g = relative_camera_pose(gt["phi"][:, 0], gt["tau"][:, 0], gt["phi"][:, 1], gt["tau"][:, 1])
    rot = roma.rotmat_geodesic_distance(R12, R12g).mean().item()
    return mpjpe, (t12 - t12g).norm(dim=-1).mean().item(), rot


def test_airpose_plus_reduces_pose_and_relative_camera_errors(body64, prior):
    kps, K, gt = _scene(body64, F=20)
    init = _perturbed(gt)
    start = init_from_views(**init)
    e0 = _errors(body64, start["theta"], start["beta"], start["phi"], start["tau"], gt)
    res = fit_sequence(type("Seq", (), {"keypoints": kps, "K": K})(), init, prior=prior, body=body64,
                       progress=False)  # the paper's weights, the code's schedule (300 / 100)
    e1 = _errors(body64, res.theta, res.beta, res.phi, res.tau, gt)
    assert e1[0] < 0.8 * e0[0], (e0, e1)  # MPJPE (root aligned)
    assert e1[1] < 0.5 * e0[1], (e0, e1)  # UAV2 position in UAV1
    assert e1[2] < 0.5 * e0[2], (e0, e1)  # UAV2 orientation in UAV1
    assert res.history["loss"][-1] < 0.2 * res.history["loss"][0]
    # Outputs are consistent with each other.
    R12, t12 = relative_camera_pose(res.phi[:, 0], res.tau[:, 0], res.phi[:, 1], res.tau[:, 1])
    torch.testing.assert_close(res.R_12, R12)
    torch.testing.assert_close(res.t_12, t12)
    eye = torch.eye(3).expand(20, 2, 3, 3)
    torch.testing.assert_close(res.R_body_cam @ res.phi, eye, atol=1e-5, rtol=0)
    torch.testing.assert_close((res.R_body_cam @ res.tau.unsqueeze(-1)).squeeze(-1) + res.t_body_cam,
                               torch.zeros(20, 2, 3), atol=1e-5, rtol=0)
    torch.testing.assert_close(res.theta, prior.decode_matrot(res.v), atol=1e-5, rtol=0)
    assert set(res.to_numpy()) >= {"theta", "beta", "phi", "tau", "R_12", "t_12", "kept"}


def test_chunking_gives_the_whole_sequence_result(body64):
    prior = VPoser().eval()
    kps, K, gt = _scene(body64, F=7)
    init = _perturbed(gt)
    kw = dict(prior=prior, body=body64, progress=False, iterations=8, latent_start=3)
    whole = airpose_plus(kps, K, init, **kw)
    chunked = airpose_plus(kps, K, init, chunk_size=3, **kw)
    for name in ("theta", "phi", "tau", "beta"):
        torch.testing.assert_close(getattr(chunked, name), getattr(whole, name), atol=2e-5, rtol=0)


def test_init_from_views_averages_the_views():
    F = 2
    axis = torch.tensor([0.0, 0.0, 1.0])
    a = roma.rotvec_to_rotmat(0.4 * axis).expand(F, 21, 3, 3)
    b = roma.rotvec_to_rotmat(0.2 * axis).expand(F, 21, 3, 3)
    theta = torch.stack([a, b], 1)  # (F, V, 21, 3, 3)
    out = init_from_views(torch.eye(3).expand(F, 2, 3, 3), torch.zeros(F, 2, 3), theta,
                          torch.arange(F * 2 * 10, dtype=torch.float32).reshape(F, 2, 10))
    torch.testing.assert_close(out["theta"], roma.rotvec_to_rotmat(0.3 * axis).expand(F, 21, 3, 3),
                               atol=1e-6, rtol=0)
    expected_beta = torch.arange(F * 2 * 10, dtype=torch.float32).reshape(F * 2, 10).mean(0)
    torch.testing.assert_close(out["beta"], expected_beta)
    # Axis-angle and 6D forms are accepted.
    out2 = init_from_views(matrix_to_rot6d(torch.eye(3).expand(F, 2, 3, 3)), torch.zeros(F, 2, 3),
                           roma.rotmat_to_rotvec(a), torch.zeros(10))
    torch.testing.assert_close(out2["theta"], a)


def test_profiles_have_fitting_sections():
    assert kit_configs("cpu").fitting.iterations == 300 and kit_configs("cpu").fitting.latent_start == 100
    assert kit_configs("smoke").fitting.iterations < 300
    assert dataclasses.replace(kit_configs("smoke").fitting, iterations=5).iterations == 5
    with pytest.raises(ValueError):
        kit_configs("nope")
