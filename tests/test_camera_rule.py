"""One camera rule for any camera: crops and P formed in the network's virtual camera.

The same person (a textured board, 0.6 x 1.7 m, at the same place in each camera's frame) is
rendered by an independent pinhole ray caster through three cameras: the training camera
(f = 1475 px, 1920x1080), the paper's UAV1 camera at half resolution (960x540, f about 769 px)
and its UAV2 camera at full resolution (fx != fy). Through the virtual camera each gives the
training camera's network input and P; the plain rule (P from the camera's own K) does not.
"""
from __future__ import annotations

import numpy as np
import pytest
import torch

from airpose_lib.data.network_input import crop_input, network_camera
from airpose_lib.data.sequences import PAPER_CAMERAS
from airpose_lib.geometry import (
    crop_affine_matrix,
    crop_vector,
    project_points,
    virtual_camera_map,
    virtual_crop,
    weak_perspective_to_translation,
)

S = 64
TAU = np.array([0.9, -0.4, 12.0])  # the board's centre in every camera's frame, metres
BOARD = (0.6, 1.7)  # width, height in metres


def _cameras():
    K_train = network_camera()
    cam0, cam1 = PAPER_CAMERAS
    K0, size0 = cam0.scaled(0.5)
    return {"train": (K_train, (1920, 1080)), "uav1_half": (K0, size0), "uav2_full": (cam1.K, (1920, 1080))}


def _render(K: np.ndarray, size: tuple[int, int], ss: int = 3) -> np.ndarray:
    """Ray-cast the board (plane z = TAU_z, smooth texture, black elsewhere), ss x ss supersampled."""
    W, H = size
    fx, fy, cx, cy = K[0, 0], K[1, 1], K[0, 2], K[1, 2]
    o = (np.arange(ss) + 0.5) / ss - 0.5
    u = (np.arange(W)[:, None] + o[None]).reshape(-1)
    v = (np.arange(H)[:, None] + o[None]).reshape(-1)
    X = (u - cx) / fx * TAU[2] - TAU[0]  # board coordinates
    Y = (v - cy) / fy * TAU[2] - TAU[1]
    inside = (np.abs(Y)[:, None] <= BOARD[1] / 2) & (np.abs(X)[None] <= BOARD[0] / 2)
    tex = 128 + 90 * np.sin(2 * np.pi * Y[:, None] / 0.5) * np.cos(2 * np.pi * X[None] / 0.4)
    img = np.where(inside, tex, 0.0).reshape(H, ss, W, ss).mean((1, 3))
    rgb = np.stack((img, 0.8 * img, 255 - img * inside.reshape(H, ss, W, ss).mean((1, 3))), -1)
    return np.clip(rgb, 0, 255).round().astype(np.uint8)


def _box(K: np.ndarray) -> np.ndarray:
    """The board's exact box in camera K (its corners projected)."""
    w, h = BOARD
    corners = TAU + np.array([[-w / 2, -h / 2, 0], [w / 2, h / 2, 0]])
    uv = project_points(torch.as_tensor(corners), torch.as_tensor(K)).numpy()
    return np.concatenate((uv[0], uv[1]))


def _pixels(P: np.ndarray, K_net: np.ndarray) -> np.ndarray:
    """P as pixel quantities of the virtual camera: crop-centre offsets and the box side."""
    return np.array([P[0] * K_net[0, 2], P[1] * K_net[1, 2], S / P[2]])


def test_virtual_camera_map_is_the_pixel_map_between_the_two_cameras():
    K = torch.tensor(PAPER_CAMERAS[1].K)
    K_net = torch.tensor(network_camera())
    X = torch.tensor([[0.3, -0.2, 9.0], [-1.0, 0.5, 14.0]], dtype=torch.float64)
    uv = project_points(X, K)
    uv_net = project_points(X, K_net)
    H = virtual_camera_map(K, K_net)
    mapped = uv @ H[:2, :2].T + H[:2, 2]
    torch.testing.assert_close(mapped, uv_net)
    # K = K_net: the plain crop and P
    box = torch.tensor([100.0, 200.0, 300.0, 650.0], dtype=torch.float64)
    A, P = virtual_crop(box, K_net, K_net)
    torch.testing.assert_close(A, crop_affine_matrix(box))
    torch.testing.assert_close(P, crop_vector(box, K_net))


def test_same_person_through_any_camera_gives_the_training_input_and_P():
    cams = _cameras()
    K_net = cams["train"][0]
    ref_img = _render(*cams["train"])
    ref_crop, ref_P = crop_input(ref_img, _box(K_net), K_net, S, K_net)
    assert ref_crop.std() > 0.5  # the board fills the crop
    for name in ("uav1_half", "uav2_full"):
        K, size = cams[name]
        crop, P = crop_input(_render(K, size), _box(K), K, S)  # the default K_net is the training camera
        np.testing.assert_allclose(_pixels(P[0], K_net), _pixels(ref_P[0], K_net), atol=1.0, err_msg=name)
        # the same network input: on average about one grey level apart (after normalisation one
        # level ~ 0.017); inside the board (away from its anti-aliased border) a few levels at most
        diff = np.abs(crop - ref_crop)
        inner = diff[..., 4:60, 25:39]  # the board spans rows 0-63, columns 32 +- 11 of the crop
        assert diff.mean() < 0.02 and np.quantile(inner, 0.99) < 0.1, (name, diff.mean(), np.quantile(inner, 0.99))
        # the plain rule (P from the camera's own K) is far off: the box side differs by f / f_train
        _, P_plain = crop_input(_render(K, size), _box(K), K, S, K_net=K)
        ratio = P_plain[0, 2] / ref_P[0, 2]
        np.testing.assert_allclose(ratio, K_net[0, 0] / K[0, 0], rtol=0.02)
        assert abs(ratio - 1) > 0.05


def test_an_oracle_trained_on_the_training_camera_is_right_in_every_camera():
    """Depth from the box side for a network that learned the training camera exactly:
    ``z = f_train * height / side``; through the virtual camera it gives the true depth anywhere,
    through the plain rule f_train / f times too far."""
    cams = _cameras()
    K_net = cams["train"][0]
    for name, (K, _) in cams.items():
        box = torch.as_tensor(_box(K))
        _, P = virtual_crop(box, torch.as_tensor(K), torch.as_tensor(K_net), S)
        side = float(S / P[2])  # the board is taller than wide: side = its height in virtual pixels
        z = K_net[1, 1] * BOARD[1] / side
        assert abs(z - TAU[2]) < 1e-6, name
        z_plain = K_net[1, 1] * BOARD[1] / float(S / crop_vector(box, torch.as_tensor(K), S)[2])
        np.testing.assert_allclose(z_plain, TAU[2] * K_net[1, 1] / K[1, 1], rtol=1e-9)


@pytest.mark.parametrize("variant", ["airpose", "baseline"])
def test_the_network_predicts_the_same_translation_through_any_camera(variant):
    from airpose_lib.model import build_model, to_smplx_params

    cams = _cameras()
    K_net = cams["train"][0]
    torch.manual_seed(0)
    model = build_model(variant, "resnet18").eval()
    taus = {}
    for name, (K, size) in cams.items():
        crop, P = crop_input(_render(K, size), _box(K), K, S)
        x = torch.from_numpy(crop)[None].repeat(1, 2, 1, 1, 1)  # two identical views
        P_t = torch.from_numpy(P)[None].repeat(1, 2, 1)
        with torch.no_grad():
            out = model(x, P_t)
            # P refers to the virtual camera: a weak camera converts with K_net
            tau = to_smplx_params(out, P_t, torch.as_tensor(K_net, dtype=torch.float32).expand(1, 2, 3, 3), S)["tau"]
        taus[name] = tau[0, 0].numpy()
    for name in ("uav1_half", "uav2_full"):
        np.testing.assert_allclose(taus[name], taus["train"], rtol=0.01, atol=0.01, err_msg=name)


def test_weak_camera_translation_is_the_same_in_the_virtual_and_the_real_camera():
    """Square pixels: identical. (With fx != fy the virtual camera measures a tall box with fy,
    the plain formula with fx: they then differ by fy / fx.)"""
    K = torch.tensor(PAPER_CAMERAS[0].scaled(0.5)[0])
    K[1, 1] = K[0, 0]
    K_net = torch.tensor(network_camera())
    box = torch.tensor([400.0, 150.0, 460.0, 300.0], dtype=torch.float64)
    cam = torch.tensor([0.7, 0.05, -0.1], dtype=torch.float64)
    _, P_v = virtual_crop(box, K, K_net, S)
    tau_v = weak_perspective_to_translation(cam, P_v, K_net, S)
    tau = weak_perspective_to_translation(cam, crop_vector(box, K, S), K, S)
    torch.testing.assert_close(tau_v, tau)
