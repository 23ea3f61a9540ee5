"""The four variants: fc1 widths, regressor structure and initialisation, mean parameters, the
translation normalisation and the exchange of messages between views."""
from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from airpose_lib.geometry import axis_angle_to_matrix, rot6d_to_matrix
from airpose_lib.model import (
    MESSAGE_DIM,
    VARIANTS,
    AirPoseNet,
    build_model,
    convert_official_state_dict,
    fc1_input_width,
    fuse_messages,
    load_mean_params,
)

PAPER_FC1 = {"baseline": 2193, "multiview": 2329, "fullcam": 2196, "airpose": 2332}
S = 64


def _inputs(B=2, V=2, seed=0):
    g = torch.Generator().manual_seed(seed)
    images = torch.randn(B, V, 3, S, S, generator=g)
    P = torch.stack([0.2 * torch.randn(B, V, generator=g), 0.2 * torch.randn(B, V, generator=g),
                     0.5 + torch.rand(B, V, generator=g)], dim=-1)
    return images, P


@pytest.mark.parametrize("variant", sorted(PAPER_FC1))
def test_fc1_width_resnet50(variant):
    assert fc1_input_width(variant, 2048) == PAPER_FC1[variant]
    model = build_model(variant, "resnet50")
    assert model.regressor.fc1.in_features == PAPER_FC1[variant]
    assert model.regressor.fc1.out_features == 1024
    assert (model.regressor.fc2.in_features, model.regressor.fc2.out_features) == (1024, 1024)
    assert model.regressor.drop1.p == 0.5 and model.regressor.drop2.p == 0.5
    full = VARIANTS[variant].fullcam
    assert model.regressor.decpose.out_features == (135 if full else 132)
    assert model.regressor.decshape.out_features == 10
    assert (model.regressor.deccam is None) == full
    # ResNet-18: the same minus the 1536 feature channels ResNet-50 has more.
    assert fc1_input_width(variant, 512) == PAPER_FC1[variant] - 1536


def test_unknown_variant():
    with pytest.raises(ValueError, match="airpose"):
        AirPoseNet("airpose++", backbone="resnet18")


def test_regressor_is_affine_without_dropout():
    """No nonlinearity between fc1 and fc2: in eval mode the update is affine in the input."""
    torch.manual_seed(0)
    reg = build_model("airpose", "resnet18").regressor.double().eval()
    x, y = torch.randn(2, reg.in_features, dtype=torch.float64)
    a = 0.3
    for fx, fy, fm in zip(reg(x), reg(y), reg(a * x + (1 - a) * y)):
        if fx is not None:
            torch.testing.assert_close(fm, a * fx + (1 - a) * fy, rtol=1e-10, atol=1e-12)
    reg.train()  # and dropout is active in training
    torch.manual_seed(1)
    assert not torch.equal(reg(x)[0], reg(x)[0])


def test_relu_regressor_matches_hand_forward_and_keeps_the_keys():
    """activation="relu": ReLU after fc1 and after fc2 (eval mode: dropout off), the same state
    dict keys as the paper's trunk, so official checkpoints and the record load either way."""
    torch.manual_seed(0)
    plain = build_model("airpose", "resnet18").regressor.double().eval()
    relu = build_model("airpose", "resnet18", activation="relu").regressor.double().eval()
    assert plain.state_dict().keys() == relu.state_dict().keys()
    relu.load_state_dict(plain.state_dict())
    x = torch.randn(3, relu.in_features, dtype=torch.float64)
    h = torch.relu(relu.fc2(torch.relu(relu.fc1(x))))
    for got, head in zip(relu(x), (relu.decpose, relu.decshape)):
        torch.testing.assert_close(got, head(h), rtol=1e-12, atol=1e-12)
    assert not torch.allclose(relu(x)[0], plain(x)[0])  # the nonlinearity acts
    with pytest.raises(ValueError, match="relu"):
        build_model("airpose", "resnet18", activation="tanh")


@pytest.mark.parametrize("variant", ["baseline", "airpose"])
def test_decoder_init_xavier_gain(variant):
    torch.manual_seed(0)
    reg = build_model(variant, "resnet18").regressor
    for head in (reg.decpose, reg.decshape, reg.deccam):
        if head is None:
            continue
        fan_out, fan_in = head.weight.shape
        bound = 0.01 * math.sqrt(6.0 / (fan_in + fan_out))
        w = head.weight.detach()
        assert w.abs().max() <= bound * (1 + 1e-6)
        assert w.abs().max() > 0.9 * bound  # uniform, fills the range
        assert abs(w.std().item() - bound / math.sqrt(3)) < 0.1 * bound / math.sqrt(3)
    # fc1 keeps PyTorch's default init (much larger than the heads)
    assert reg.fc1.weight.abs().max() > 10 * bound


def test_mean_parameters():
    m = build_model("airpose", "resnet18")
    R = rot6d_to_matrix(m.init_phi6d.double())
    torch.testing.assert_close(R, axis_angle_to_matrix(torch.tensor([math.pi, 0.0, 0.0], dtype=torch.float64)))
    torch.testing.assert_close(R, torch.diag(torch.tensor([1.0, -1.0, -1.0], dtype=torch.float64)), atol=1e-7, rtol=0)
    # SMPL-X up (+Y) becomes image-up (-y in OpenCV), its facing direction (+Z) points at the
    # camera (-z), and the subject's left (+X) is on the image's right (+x), as for a person
    # facing the viewer.
    torch.testing.assert_close(R @ torch.tensor([0.0, 1.0, 0.0], dtype=torch.float64),
                               torch.tensor([0.0, -1.0, 0.0], dtype=torch.float64), atol=1e-7, rtol=0)
    torch.testing.assert_close(R @ torch.tensor([0.0, 0.0, 1.0], dtype=torch.float64),
                               torch.tensor([0.0, 0.0, -1.0], dtype=torch.float64), atol=1e-7, rtol=0)
    theta = rot6d_to_matrix(m.init_theta6d.reshape(21, 6))
    torch.testing.assert_close(theta, torch.eye(3).expand(21, 3, 3))
    assert torch.equal(m.init_beta, torch.zeros(10))
    torch.testing.assert_close(m.init_tau_n, torch.tensor([0.0, 0.0, 0.5]))
    torch.testing.assert_close(build_model("baseline", "resnet18").init_cam, torch.tensor([0.9, 0.0, 0.0]))


def test_mean_params_file(tmp_path):
    g = np.random.default_rng(0)
    pose = g.normal(size=144).astype(np.float32)  # SPIN layout: 24 x 6D
    shape = g.normal(size=10)
    np.savez(tmp_path / "mean.npz", pose=pose, shape=shape, cam=np.array([0.8, 0.1, -0.1]))
    mp = load_mean_params(tmp_path / "mean.npz")
    m = build_model("multiview", "resnet18", mean_params=tmp_path / "mean.npz")
    np.testing.assert_array_equal(m.init_phi6d.numpy(), pose[:6])
    np.testing.assert_array_equal(m.init_theta6d.numpy(), pose[6:132])
    np.testing.assert_allclose(m.init_beta.numpy(), shape, rtol=1e-6)
    np.testing.assert_allclose(m.init_cam.numpy(), [0.8, 0.1, -0.1], rtol=1e-6)
    np.testing.assert_array_equal(mp.tau, [0, 0, 10])
    np.savez(tmp_path / "short.npz", pose=pose[:100], shape=shape)
    with pytest.raises(ValueError, match="at least 132"):
        load_mean_params(tmp_path / "short.npz")


def _zero_heads(model):
    for head in (model.regressor.decpose, model.regressor.decshape, model.regressor.deccam):
        if head is not None:
            torch.nn.init.zeros_(head.weight)
            torch.nn.init.zeros_(head.bias)


@pytest.mark.parametrize("variant", sorted(VARIANTS))
def test_zero_update_returns_mean_and_tau_scaling(variant):
    torch.manual_seed(0)
    model = build_model(variant, "resnet18").eval()
    _zero_heads(model)
    images, P = _inputs()
    with torch.no_grad():
        out = model(images, P)
    torch.testing.assert_close(out["phi6d"], model.init_phi6d.expand(2, 2, 6))
    torch.testing.assert_close(out["theta6d"], model.init_theta6d.reshape(21, 6).expand(2, 2, 21, 6))
    assert out["input_size"] == S and len(out["messages"]) == 3
    for msg in out["messages"]:
        assert msg.shape == (2, 2, MESSAGE_DIM) and msg.dtype == torch.float32
    if VARIANTS[variant].fullcam:
        torch.testing.assert_close(out["tau"], torch.tensor([0.0, 0.0, 10.0]).expand(2, 2, 3))
        assert "cam" not in out
        # a constant update of 0.05 on the normalised depth per iteration is 1 m per iteration
        model.regressor.decpose.bias.data[2] = 0.05
        with torch.no_grad():
            out = model(images, P)
        torch.testing.assert_close(out["tau"][..., 2], torch.full((2, 2), 13.0))
    else:
        torch.testing.assert_close(out["cam"], torch.tensor([0.9, 0.0, 0.0]).expand(2, 2, 3))
        assert "tau" not in out  # only with K


class _Fc1Recorder:
    def __init__(self, model):
        self.inputs = []
        model.regressor.fc1.register_forward_pre_hook(lambda mod, args: self.inputs.append(args[0].detach().clone()))


@pytest.mark.parametrize("variant", ["multiview", "airpose"])
@pytest.mark.parametrize("V", [2, 3])
def test_exchange_inputs(variant, V):
    """fc1 sees [feat, (P, tau) | cam, phi, theta, beta, other]; 'other' is the mean message in
    iteration 1 and the mean of the other views' previous messages afterwards."""
    torch.manual_seed(0)
    model = build_model(variant, "resnet18").eval()
    rec = _Fc1Recorder(model)
    images, P = _inputs(B=2, V=V)
    with torch.no_grad():
        out = model(images, P)
    C = model.backbone.feature_dim
    full = VARIANTS[variant].fullcam
    own = C + (6 if full else 3)  # start of phi
    assert len(rec.inputs) == 3
    for k, x in enumerate(rec.inputs):
        assert x.shape == (2, V, fc1_input_width(variant, C))
        other = x[..., own + 142:]
        if k == 0:
            expected = torch.cat((model.init_theta6d, model.init_beta)).expand(2, V, -1)
            torch.testing.assert_close(x[..., own + 6:own + 142], expected, rtol=0, atol=0)
        else:
            prev = out["messages"][k - 1]
            expected = torch.stack([prev[:, [u for u in range(V) if u != v]].mean(1) for v in range(V)], 1)
            torch.testing.assert_close(x[..., own + 6:own + 142], prev, rtol=0, atol=0)  # own state
        torch.testing.assert_close(other, expected, rtol=1e-6, atol=1e-7)
        if full:
            torch.testing.assert_close(x[..., C:C + 3], P, rtol=0, atol=0)
        if k == 0 and full:
            torch.testing.assert_close(x[..., C + 3:C + 6], torch.tensor([0.0, 0.0, 0.5]).expand(2, V, 3))
        if k == 0 and not full:
            torch.testing.assert_close(x[..., C:C + 3], torch.tensor([0.9, 0.0, 0.0]).expand(2, V, 3))


def test_fuse_messages_two_views_is_swap():
    m = torch.randn(4, 2, MESSAGE_DIM)
    assert torch.equal(fuse_messages(m), m.flip(1))
    m3 = torch.randn(1, 3, MESSAGE_DIM, dtype=torch.float64)
    torch.testing.assert_close(fuse_messages(m3)[:, 0], 0.5 * (m3[:, 1] + m3[:, 2]))
    with pytest.raises(ValueError):
        fuse_messages(m[:, :1])


@pytest.mark.parametrize("variant", ["baseline", "fullcam"])
def test_independent_views(variant):
    torch.manual_seed(0)
    model = build_model(variant, "resnet18").eval()
    images, P = _inputs()
    other = images.clone()
    other[:, 1] = torch.randn_like(other[:, 1])
    with torch.no_grad():
        a, b = model(images, P), model(other, P)
    for key in ("phi6d", "theta6d", "beta", "tau" if variant == "fullcam" else "cam"):
        torch.testing.assert_close(a[key][:, 0], b[key][:, 0], rtol=0, atol=1e-6)
    assert (a["theta6d"][:, 1] - b["theta6d"][:, 1]).abs().max() > 1e-6  # view 2 did change
    with torch.no_grad():  # a single view works as well
        single = model(images[:, :1], P[:, :1])
    torch.testing.assert_close(single["theta6d"][:, 0], a["theta6d"][:, 0], rtol=0, atol=1e-5)


def test_multiview_views_interact():
    torch.manual_seed(0)
    model = build_model("airpose", "resnet18").eval()
    images, P = _inputs()
    other = images.clone()
    other[:, 1] = torch.randn_like(other[:, 1])
    with torch.no_grad():
        a, b = model(images, P), model(other, P)
    assert (a["theta6d"][:, 0] - b["theta6d"][:, 0]).abs().max() > 1e-6


def test_weak_camera_tau_with_K():
    from airpose_lib.geometry import weak_perspective_to_translation

    torch.manual_seed(0)
    model = build_model("baseline", "resnet18").eval()
    images, P = _inputs()
    K = torch.tensor([[1475.0, 0, 960], [0, 1475.0, 540], [0, 0, 1]]).expand(2, 2, 3, 3)
    with torch.no_grad():
        out = model(images, P, K)
    torch.testing.assert_close(out["tau"], weak_perspective_to_translation(out["cam"], P, K, S))
    # cam ~ [0.9, 0, 0] on a 64 px crop: tz = 2 f / (L s_w) with L = 64 / s
    torch.testing.assert_close(out["tau"][..., 2], 2 * 1475.0 * P[..., 2] / (S * out["cam"][..., 0]))


def test_gradients_reach_backbone_through_messages():
    torch.manual_seed(0)
    model = build_model("airpose", "resnet18").train()
    images, P = _inputs()
    images.requires_grad_(True)
    out = model(images, P)
    out["theta6d"][:, 0].sum().backward()  # view 0's output depends on view 1's image
    assert images.grad[:, 1].abs().sum() > 0


@pytest.mark.parametrize("variant", ["baseline", "airpose"])
def test_convert_official_state_dict(variant):
    torch.manual_seed(0)
    ours = build_model(variant, "resnet18")
    official = {}
    for k, v in ours.state_dict().items():
        if k.startswith(("backbone.", "regressor.")):
            official["model." + k.split(".", 1)[1]] = torch.randn_like(v) if v.is_floating_point() else v
    official["model.init_pose"] = torch.randn(1, 144)
    official["model.init_shape"] = torch.randn(1, 10)
    official["model.init_cam"] = torch.randn(1, 3)
    official["body_only_mask"] = torch.ones(10475, 1)
    if VARIANTS[variant].fullcam:
        official["model.deccam.weight"] = torch.randn(3, 1024)  # present but unused there
        official["model.deccam.bias"] = torch.randn(3)
    target = build_model(variant, "resnet18")
    target.load_state_dict(convert_official_state_dict(official, variant), strict=True)
    assert torch.equal(target.regressor.fc1.weight, official["model.fc1.weight"])
    assert torch.equal(target.backbone.layer4[1].bn2.running_var, official["model.layer4.1.bn2.running_var"])
    assert torch.equal(target.init_theta6d, official["model.init_pose"][0, 6:132])
