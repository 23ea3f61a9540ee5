"""Network output -> SMPL-X parameters -> posed body, against smplx's own forward."""
from __future__ import annotations

import pytest
import torch

from airpose_lib.body import joint_index
from airpose_lib.geometry import (
    axis_angle_to_rot6d,
    crop_to_full_pixels,
    project_points,
    rot6d_to_matrix,
    weak_perspective_to_translation,
)
from airpose_lib.model import build_model, posed_joints_and_vertices, to_smplx_params


def _rest(n, dtype):
    """Zero jaw/eye/hand poses and expression for an smplx call with batch n."""
    z = lambda k: torch.zeros(n, k, dtype=dtype)  # noqa: E731
    return dict(jaw_pose=z(3), leye_pose=z(3), reye_pose=z(3), left_hand_pose=z(45),
                right_hand_pose=z(45), expression=z(10))


def _params(B, V, dtype, seed=0):
    g = torch.Generator().manual_seed(seed)
    r = lambda *s, scale=1.0: (scale * torch.randn(*s, generator=g, dtype=torch.float64)).to(dtype)  # noqa: E731
    return {
        "aa_phi": r(B, V, 3),
        "aa_theta": r(B, V, 21, 3, scale=0.4),
        "beta": r(B, V, 10),
        "tau": r(B, V, 3, scale=2.0),
    }


# float64 tolerance: smplx's batch_rodrigues adds 1e-8 to the rotation vector before taking its norm.
@pytest.mark.parametrize("dtype,atol", [(torch.float64, 5e-8), (torch.float32, 2e-5)])
def test_posed_body_matches_smplx_forward(open_model, dtype, atol):
    """X = phi X0 + tau about the model origin, versus smplx, which rotates about the pelvis J0:
    X_smplx = phi (X0 - J0) + J0, so X = X_smplx - J0 + phi J0 + tau."""
    model = open_model.to(dtype)
    try:
        B, V = 2, 2
        p = _params(B, V, dtype)
        params = {
            "phi": rot6d_to_matrix(axis_angle_to_rot6d(p["aa_phi"])),
            "theta": rot6d_to_matrix(axis_angle_to_rot6d(p["aa_theta"])),
            "beta": p["beta"],
            "tau": p["tau"],
        }
        got = posed_joints_and_vertices(model, params)
        fast = posed_joints_and_vertices(model, params, joints_only=True)
        ref = model(betas=p["beta"].reshape(-1, 10), global_orient=p["aa_phi"].reshape(-1, 3),
                    body_pose=p["aa_theta"].reshape(-1, 63), transl=torch.zeros(B * V, 3, dtype=dtype),
                    **_rest(B * V, dtype))
        phi = params["phi"].reshape(-1, 3, 3)
        J0 = ref.joints[:, :1]
        shift = -J0 + J0 @ phi.transpose(-1, -2) + p["tau"].reshape(-1, 1, 3)
        nv = ref.vertices.shape[1]
        assert got["vertices"].shape == (B, V, nv, 3) and got["joints"].shape == (B, V, 76, 3)
        torch.testing.assert_close(got["vertices"].reshape(-1, nv, 3), ref.vertices + shift, rtol=0, atol=atol)
        torch.testing.assert_close(got["joints"].reshape(-1, 76, 3), ref.joints[:, :76] + shift, rtol=0, atol=atol)
        torch.testing.assert_close(fast["joints"], got["joints"], rtol=0, atol=atol)
        assert "vertices" not in fast
        # root-relative body (no phi, no tau): the model evaluated with identity global orientation
        rel = posed_joints_and_vertices(model, {"theta": params["theta"], "beta": p["beta"]}, joints_only=True)
        ref0 = model(betas=p["beta"].reshape(-1, 10), body_pose=p["aa_theta"].reshape(-1, 63),
                     global_orient=torch.zeros(B * V, 3, dtype=dtype), transl=torch.zeros(B * V, 3, dtype=dtype),
                     **_rest(B * V, dtype))
        torch.testing.assert_close(rel["joints"].reshape(-1, 76, 3), ref0.joints[:, :76], rtol=0, atol=atol)
    finally:
        open_model.to(torch.float64)


def test_initial_pose_is_upright_and_facing_camera(open_model):
    """The mean parameters put an upright person facing the camera, 10 m in front of it."""
    net = build_model("airpose", "resnet18")
    out = net.decode(net.initial_state((1, 1)))
    P = torch.tensor([[[0.0, 0.0, 1.0]]])
    K = torch.tensor([[1475.0, 0, 960], [0, 1475.0, 540], [0, 0, 1]])
    params = to_smplx_params(out, P, K)
    J = posed_joints_and_vertices(open_model, params, joints_only=True)["joints"][0, 0]
    head, pelvis, nose = J[joint_index("head")], J[joint_index("pelvis")], J[joint_index("nose")]
    assert head[1] < pelvis[1] - 0.3  # head above the pelvis in the image (y down)
    assert nose[2] < head[2] - 0.05  # the face is turned to the camera (nose nearer)
    assert J[joint_index("left_shoulder"), 0] > J[joint_index("right_shoulder"), 0]  # mirror view
    assert 9.0 < pelvis[2] < 11.0


def test_to_smplx_params_full_camera():
    torch.manual_seed(0)
    out = {"phi6d": torch.randn(2, 2, 6), "theta6d": torch.randn(2, 2, 21, 6),
           "beta": torch.randn(2, 2, 10), "tau": torch.randn(2, 2, 3)}
    P, K = torch.rand(2, 2, 3), torch.eye(3)
    got = to_smplx_params(out, P, K)
    assert got["theta"].shape == (2, 2, 21, 3, 3) and got["phi"].shape == (2, 2, 3, 3)
    torch.testing.assert_close(got["phi"], rot6d_to_matrix(out["phi6d"]))
    assert got["tau"] is out["tau"]
    RtR = got["theta"].transpose(-1, -2) @ got["theta"]
    torch.testing.assert_close(RtR, torch.eye(3).expand_as(RtR), atol=1e-5, rtol=0)


def test_to_smplx_params_weak_camera_projects_where_the_weak_camera_says():
    """The body origin at the converted tau projects, in the full image, to the pixel that the
    weak camera [s, tx, ty] assigns to it in the S-pixel crop."""
    S = 64
    cam = torch.tensor([[[0.8, 0.05, -0.1]]], dtype=torch.float64)
    out = {"phi6d": axis_angle_to_rot6d(torch.zeros(1, 1, 3, dtype=torch.float64)),
           "theta6d": torch.zeros(1, 1, 21, 6, dtype=torch.float64), "beta": torch.zeros(1, 1, 10, dtype=torch.float64),
           "cam": cam, "input_size": S}
    bbox = torch.tensor([[[700.0, 300.0, 900.0, 700.0]]], dtype=torch.float64)
    K = torch.tensor([[1475.0, 0, 960], [0, 1475.0, 540], [0, 0, 1]], dtype=torch.float64)
    from airpose_lib.geometry import crop_vector

    P = crop_vector(bbox, K, S)
    tau = to_smplx_params(out, P, K)["tau"]
    torch.testing.assert_close(tau, weak_perspective_to_translation(cam, P, K, S))
    uv = project_points(tau.reshape(1, 1, 3), K)[0, 0]
    uv_crop = (1 + cam[0, 0, 0] * cam[0, 0, 1:]) * S / 2  # weak camera: origin at s * t
    expected = crop_to_full_pixels(uv_crop.reshape(1, 2), bbox[0, 0], S)[0]
    torch.testing.assert_close(uv, expected, rtol=0, atol=1e-8)
    # input_size from the output matters: 224 would give another depth
    assert not torch.allclose(to_smplx_params(out, P, K, input_size=224)["tau"], tau)
