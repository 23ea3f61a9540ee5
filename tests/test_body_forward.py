"""The body evaluation of the kit (``body.forward``) against smplx's own forward pass.

smplx evaluates ``V0`` (identity root, zero translation, jaw/eyes/hands at rest); the paper's
``V = phi V0 + tau`` is applied here with numpy, independently of the module.
"""
from __future__ import annotations

import numpy as np
import pytest
import roma
import torch

from airpose_lib.body import BODY_25_FROM_SMPLX, COCO18_FROM_SMPLX, load_body_model
from airpose_lib.body.forward import BodyForward, axis_angle_rotations, rest_body


def _inputs(B: int, dtype, seed: int = 0):
    g = torch.Generator().manual_seed(seed)
    r = lambda *s, scale=1.0: (scale * torch.randn(*s, generator=g, dtype=torch.float64)).to(dtype)  # noqa: E731
    return r(B, 21, 3, scale=0.5), r(B, 10, scale=1.5), r(B, 3), r(B, 3, scale=3.0)


def _smplx_rest_body(model, theta_aa, beta):
    """smplx's forward with identity root and zero translation: vertices (B, V, 3), joints (B, 76, 3)."""
    B = len(beta)
    z = lambda n: torch.zeros(B, n, dtype=beta.dtype)  # noqa: E731
    with torch.no_grad():
        out = model(betas=beta, body_pose=theta_aa.reshape(B, 63), global_orient=z(3), transl=z(3),
                    jaw_pose=z(3), leye_pose=z(3), reye_pose=z(3), left_hand_pose=z(45),
                    right_hand_pose=z(45), expression=z(model.num_expression_coeffs))
    return out.vertices, out.joints[:, :76]


def _paper(X, phi, tau):
    """phi X + tau with numpy: X (B, N, 3), phi (B, 3, 3), tau (B, 3)."""
    return np.einsum("bij,bnj->bni", phi.numpy(), X.numpy()) + tau.numpy()[:, None]


# smplx's Rodrigues adds 1e-8 to every angle (also to the zero root rotation), hence not 1e-12
@pytest.mark.parametrize("dtype,atol", [(torch.float64, 1e-7), (torch.float32, 2e-5)])
def test_mesh_joints_and_keypoint_vertices_equal_smplx(open_model_files, dtype, atol):
    B = 5
    model = load_body_model("open", "female", dtype=dtype, batch_size=B)
    theta_aa, beta, phi_aa, tau = _inputs(B, dtype)
    phi = roma.rotvec_to_rotmat(phi_aa.double()).to(dtype)
    v_ref, j_ref = _smplx_rest_body(model, theta_aa, beta)
    v_ref, j_ref = _paper(v_ref.double(), phi.double(), tau.double()), _paper(j_ref.double(), phi.double(), tau.double())
    theta = axis_angle_rotations(theta_aa)

    joints, verts = BodyForward(model, range(76))(theta, beta, phi, tau)  # mesh + all 76 outputs
    assert joints.shape == (B, 76, 3) and verts.shape == (B, model.v_template.shape[0], 3)
    assert joints.dtype == dtype
    np.testing.assert_allclose(joints.numpy(), j_ref, atol=atol, rtol=0)
    np.testing.assert_allclose(verts.numpy(), v_ref, atol=atol, rtol=0)

    # the 22 body joints (the loss's default), a vertex subset, keypoint vertices alone, any order
    j22, vsub = BodyForward(model, vertices=[5, 17, 400, 9000, 13000])(theta, beta, phi, tau)
    np.testing.assert_allclose(j22.numpy(), j_ref[:, :22], atol=atol, rtol=0)
    np.testing.assert_allclose(vsub.numpy(), v_ref[:, [5, 17, 400, 9000, 13000]], atol=atol, rtol=0)
    pick = [70, 3, 55, 60, 30, 0]  # fingertip, spine, nose, heel, a finger joint, pelvis
    jk, none = BodyForward(model, pick, vertices=None)(theta, beta, phi, tau)
    assert none is None
    np.testing.assert_allclose(jk.numpy(), j_ref[:, pick], atol=atol, rtol=0)

    # without phi and tau: V0 itself; vertices=False skips the mesh
    j0, v0 = BodyForward(model, range(76))(theta, beta, vertices=False)
    assert v0 is None
    np.testing.assert_allclose(j0.numpy(), _smplx_rest_body(model, theta_aa, beta)[1].numpy(), atol=atol, rtol=0)

    # the numpy adapter of the data generators
    v_np, j_np = rest_body(model, beta.numpy(), theta_aa.numpy())
    v_sm, j_sm = _smplx_rest_body(model, theta_aa, beta)
    assert v_np.dtype == np.float64 and j_np.shape == (B, 76, 3)
    np.testing.assert_allclose(v_np, v_sm.numpy(), atol=atol, rtol=0)
    np.testing.assert_allclose(j_np, j_sm.numpy(), atol=atol, rtol=0)


def test_pose_correctives_and_hand_mean_are_honoured(open_model_files):
    """The licensed model has non-zero posedirs and a hand mean: no folding of the hand joints."""
    B = 4
    model = load_body_model("open", dtype=torch.float64, batch_size=B, flat_hand_mean=False)
    g = torch.Generator().manual_seed(1)
    model.posedirs = 1e-3 * torch.randn(model.posedirs.shape, generator=g, dtype=torch.float64)
    model.pose_mean[66:] = 0.1 * torch.randn(99, generator=g, dtype=torch.float64)
    theta_aa, beta, phi_aa, tau = _inputs(B, torch.float64, seed=2)
    phi = roma.rotvec_to_rotmat(phi_aa)
    v_ref, j_ref = _smplx_rest_body(model, theta_aa, beta)
    joints, verts = BodyForward(model, range(76))(axis_angle_rotations(theta_aa), beta, phi, tau)
    np.testing.assert_allclose(joints.numpy(), _paper(j_ref, phi, tau), atol=1e-7, rtol=0)
    np.testing.assert_allclose(verts.numpy(), _paper(v_ref, phi, tau), atol=1e-7, rtol=0)
    idx = sorted(set(BODY_25_FROM_SMPLX) | set(COCO18_FROM_SMPLX) - {-1}) + [70, 30]
    jk, _ = BodyForward(model, idx, vertices=None)(axis_angle_rotations(theta_aa), beta[:1])  # shared beta
    _, j_shared = _smplx_rest_body(model, theta_aa, beta[:1].expand(B, -1))
    np.testing.assert_allclose(jk.numpy(), j_shared[:, idx].numpy(), atol=1e-7, rtol=0)


def test_leading_dims_shared_beta_gradients_and_errors(open_model_files):
    model = load_body_model("open", "neutral")
    body = BodyForward(model, range(76))
    theta = roma.rotvec_to_rotmat(0.2 * torch.randn(2, 3, 21, 3, generator=torch.Generator().manual_seed(4)))
    beta = torch.randn(2, 3, 10, generator=torch.Generator().manual_seed(5))
    j, v = body(theta, beta)
    assert j.shape == (2, 3, 76, 3) and v.shape == (2, 3, body.num_vertices, 3) and j.dtype == torch.float32
    j1, v1 = body(theta[1, 2], beta[1, 2])
    torch.testing.assert_close(j[1, 2], j1)
    torch.testing.assert_close(v[1, 2], v1)
    # one beta for every frame (a sequence) equals the beta repeated
    js, _ = body(theta[0], beta[0, 0], vertices=False)
    jr, _ = body(theta[0], beta[0, :1].expand(3, -1), vertices=False)
    torch.testing.assert_close(js, jr)
    # gradients reach theta and beta through the joints-only path
    th = theta[0].clone().requires_grad_()
    b = beta[0, 0].clone().requires_grad_()
    BodyForward(model, [0, 7, 60], vertices=None)(th, b)[0].sum().backward()
    assert th.grad is not None and torch.isfinite(th.grad).all() and b.grad.abs().sum() > 0
    with pytest.raises(ValueError):
        BodyForward(model, [-1, 3])
    with pytest.raises(ValueError):
        body(theta[0], torch.zeros(3, 11))
