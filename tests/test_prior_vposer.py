"""Pose prior: VPoser V02_05 layout, official-checkpoint loading, kit checkpoints, training."""
from __future__ import annotations

import argparse
import math
import warnings

import numpy as np
import pytest
import roma
import torch

from airpose_lib.prior import (
    PriorError,
    PriorTrainConfig,
    VPoser,
    evaluate_prior,
    find_vposer_checkpoint,
    load_prior,
    rotation_geodesic,
    save_prior,
    train_prior,
)


@pytest.fixture(autouse=True)
def _one_thread():
    """Small batches: one intra-op thread is as fast, and far faster when other jobs load the cores
    (torch's waiting threads then spin against them)."""
    n = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(n)


# The tensors of human_body_prior's VPoser (V02_05), written out by hand from the release's
# architecture (num_neurons 512, latentD 32): name -> shape.
OFFICIAL_LAYOUT = {
    "encoder_net.1.weight": (63,), "encoder_net.1.bias": (63,), "encoder_net.1.running_mean": (63,),
    "encoder_net.1.running_var": (63,), "encoder_net.1.num_batches_tracked": (),
    "encoder_net.2.weight": (512, 63), "encoder_net.2.bias": (512,),
    "encoder_net.4.weight": (512,), "encoder_net.4.bias": (512,), "encoder_net.4.running_mean": (512,),
    "encoder_net.4.running_var": (512,), "encoder_net.4.num_batches_tracked": (),
    "encoder_net.6.weight": (512, 512), "encoder_net.6.bias": (512,),
    "encoder_net.7.weight": (512, 512), "encoder_net.7.bias": (512,),
    "encoder_net.8.mu.weight": (32, 512), "encoder_net.8.mu.bias": (32,),
    "encoder_net.8.logvar.weight": (32, 512), "encoder_net.8.logvar.bias": (32,),
    "decoder_net.0.weight": (512, 32), "decoder_net.0.bias": (512,),
    "decoder_net.3.weight": (512, 512), "decoder_net.3.bias": (512,),
    "decoder_net.5.weight": (126, 512), "decoder_net.5.bias": (126,),
}


def _fake_official_state(seed: int) -> dict[str, torch.Tensor]:
    g = torch.Generator().manual_seed(seed)
    out = {}
    for k, shape in OFFICIAL_LAYOUT.items():
        if k.endswith("num_batches_tracked"):
            out[k] = torch.tensor(1000)
        elif k.endswith("running_var"):
            out[k] = 0.5 + torch.rand(shape, generator=g)
        else:
            out[k] = 0.05 * torch.randn(shape, generator=g)
    return out


def _write_fake_ckpt(path, seed: int, hparams=None) -> dict[str, torch.Tensor]:
    """A Lightning-style checkpoint as the release ships it: VAE tensors under ``vp_model.``, plus
    other entries the loader must ignore."""
    state = _fake_official_state(seed)
    blob = {
        "epoch": 13,
        "state_dict": {**{f"vp_model.{k}": v for k, v in state.items()},
                       "bm_train.v_template": torch.zeros(10, 3)},
        "hyper_parameters": hparams if hparams is not None else {"latentD": 32},
    }
    path.parent.mkdir(parents=True, exist_ok=True)
    torch.save(blob, path)
    return state


def _reference_decode(state: dict, z: torch.Tensor) -> torch.Tensor:
    """The release's decoder written with plain tensor ops (eval mode: dropout off)."""
    lrelu = torch.nn.functional.leaky_relu
    h = lrelu(z @ state["decoder_net.0.weight"].T + state["decoder_net.0.bias"])
    h = lrelu(h @ state["decoder_net.3.weight"].T + state["decoder_net.3.bias"])
    x = (h @ state["decoder_net.5.weight"].T + state["decoder_net.5.bias"]).reshape(-1, 3, 2)
    b1 = x[:, :, 0] / x[:, :, 0].norm(dim=1, keepdim=True)
    a2 = x[:, :, 1] - (b1 * x[:, :, 1]).sum(1, keepdim=True) * b1
    b2 = a2 / a2.norm(dim=1, keepdim=True)
    return torch.stack([b1, b2, torch.cross(b1, b2, dim=1)], dim=-1).reshape(z.shape[0], 21, 3, 3)


def _reference_encode_mean(state: dict, aa: torch.Tensor) -> torch.Tensor:
    """The release's encoder mean in eval mode (batch norms with running statistics)."""
    def bn(x, i):
        p = f"encoder_net.{i}."
        return (x - state[p + "running_mean"]) / torch.sqrt(state[p + "running_var"] + 1e-5) \
            * state[p + "weight"] + state[p + "bias"]

    x = bn(aa.reshape(aa.shape[0], -1), 1)
    x = torch.nn.functional.leaky_relu(x @ state["encoder_net.2.weight"].T + state["encoder_net.2.bias"])
    x = bn(x, 4)
    x = x @ state["encoder_net.6.weight"].T + state["encoder_net.6.bias"]
    x = x @ state["encoder_net.7.weight"].T + state["encoder_net.7.bias"]
    return x @ state["encoder_net.8.mu.weight"].T + state["encoder_net.8.mu.bias"]


# -- architecture ---------------------------------------------------------------------------------
def test_parameter_names_and_shapes_are_the_release_layout():
    got = {k: tuple(v.shape) for k, v in VPoser().state_dict().items()}
    assert got == OFFICIAL_LAYOUT


def test_decode_gives_rotations_and_matching_axis_angle():
    torch.manual_seed(0)
    model = VPoser().eval()
    z = torch.randn(16, 32)
    out = model.decode(z)
    R = out["pose_body_matrot"]
    assert R.shape == (16, 21, 3, 3) and out["pose_body"].shape == (16, 21, 3)
    eye = torch.eye(3).expand_as(R)
    torch.testing.assert_close(R.transpose(-1, -2) @ R, eye, atol=1e-5, rtol=0)
    torch.testing.assert_close(torch.linalg.det(R), torch.ones(16, 21), atol=1e-5, rtol=0)
    torch.testing.assert_close(roma.rotvec_to_rotmat(out["pose_body"]), R, atol=1e-5, rtol=0)


def test_encode_accepts_both_layouts_and_rejects_others():
    torch.manual_seed(0)
    model = VPoser().eval()
    aa = 0.3 * torch.randn(5, 21, 3)
    a, b = model.encode(aa), model.encode(aa.reshape(5, 63))
    torch.testing.assert_close(a.loc, b.loc)
    assert a.loc.shape == a.scale.shape == (5, 32) and (a.scale > 0).all()
    with pytest.raises(ValueError):
        model.encode(torch.zeros(5, 22, 3))
    with pytest.raises(ValueError):
        model.decode(torch.zeros(5, 16))


def test_sample_is_seeded_and_keeps_the_mode():
    model = VPoser().train()
    s1, s2, s3 = model.sample(8, seed=3), model.sample(8, seed=3), model.sample(8, seed=4)
    assert model.training
    torch.testing.assert_close(s1["pose_body"], s2["pose_body"])
    assert not torch.allclose(s1["pose_body"], s3["pose_body"])
    # Eval-mode decode of the same N(0, I) draw.
    z = torch.randn(8, 32, generator=torch.Generator().manual_seed(3))
    torch.testing.assert_close(model.eval().decode(z)["pose_body_matrot"], s1["pose_body_matrot"])


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_rotation_geodesic_matches_angle_and_has_finite_gradient(dtype):
    g = torch.Generator().manual_seed(0)
    R1 = roma.rotvec_to_rotmat(torch.randn(50, 3, generator=g, dtype=dtype))
    R2 = roma.rotvec_to_rotmat(torch.randn(50, 3, generator=g, dtype=dtype))
    ref = roma.rotmat_geodesic_distance(R1, R2)
    torch.testing.assert_close(rotation_geodesic(R1, R2), ref, atol=1e-3, rtol=0)
    X = R1.clone().requires_grad_(True)
    rotation_geodesic(X, R1).sum().backward()
    assert torch.isfinite(X.grad).all()


# -- official checkpoint --------------------------------------------------------------------------
def test_loads_a_fake_official_snapshot(tmp_path, monkeypatch):
    root = tmp_path / "vposer"
    _write_fake_ckpt(root / "V02_05" / "snapshots" / "V02_05_epoch=08_val_loss=0.03.ckpt", seed=1)
    state = _write_fake_ckpt(root / "V02_05" / "snapshots" / "V02_05_epoch=13_val_loss=0.03.ckpt", seed=2)
    monkeypatch.setenv("AIRPOSE_VPOSER_DIR", str(root))
    assert find_vposer_checkpoint().name.startswith("V02_05_epoch=13")
    model, prov = load_prior("vposer", return_provenance=True)
    assert not model.training and not any(p.requires_grad for p in model.parameters())
    assert prov["source"] == "vposer" and prov["file"].endswith(".ckpt")
    for k, v in state.items():
        torch.testing.assert_close(model.state_dict()[k], v)
    z = torch.randn(4, 32, generator=torch.Generator().manual_seed(0))
    torch.testing.assert_close(model.decode_matrot(z), _reference_decode(state, z), atol=1e-5, rtol=0)
    aa = 0.4 * torch.randn(6, 21, 3, generator=torch.Generator().manual_seed(1))
    torch.testing.assert_close(model.encode(aa).loc, _reference_encode_mean(state, aa), atol=1e-4, rtol=1e-4)
    # The V02_05 folder itself and the file are accepted too.
    load_prior("vposer", root / "V02_05")
    load_prior("vposer", find_vposer_checkpoint())


def test_non_tensor_hyper_parameters_load_without_running_their_classes(tmp_path):
    """The release pickles hyper-parameters of classes the kit does not import; they become inert
    placeholders (no code runs from a file) and the weights load."""
    ckpt = tmp_path / "V02_05" / "snapshots" / "x.ckpt"
    state = _write_fake_ckpt(ckpt, seed=3, hparams=argparse.Namespace(latentD=32))
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no "full unpickler" fallback any more
        model = load_prior("vposer", tmp_path)
    torch.testing.assert_close(model.state_dict()["decoder_net.5.bias"], state["decoder_net.5.bias"])


def test_missing_official_weights_say_where_they_go(tmp_path, monkeypatch):
    monkeypatch.delenv("AIRPOSE_VPOSER_DIR", raising=False)
    with pytest.raises(PriorError, match=r"V02_05/snapshots/\*\.ckpt") as e:
        load_prior("vposer")
    assert "https://smpl-x.is.tue.mpg.de" in str(e.value) and "AIRPOSE_VPOSER_DIR" in str(e.value)
    monkeypatch.setenv("AIRPOSE_VPOSER_DIR", str(tmp_path))
    with pytest.raises(PriorError, match="smpl-x.is.tue.mpg.de"):
        load_prior("vposer")


def test_wrong_layout_is_rejected(tmp_path):
    ckpt = tmp_path / "V02_05" / "snapshots" / "x.ckpt"
    state = _fake_official_state(0)
    del state["decoder_net.3.weight"]
    ckpt.parent.mkdir(parents=True)
    torch.save({"state_dict": {f"vp_model.{k}": v for k, v in state.items()}}, ckpt)
    with pytest.raises(PriorError, match="decoder_net.3.weight"):
        load_prior("vposer", tmp_path)
    torch.save({"state_dict": {"model.x": torch.zeros(1)}}, ckpt)
    with pytest.raises(PriorError, match="vp_model"):
        load_prior("vposer", tmp_path)


# -- kit checkpoints ------------------------------------------------------------------------------
def test_kit_checkpoint_round_trip_and_missing_message(tmp_path, monkeypatch):
    monkeypatch.setenv("AIRPOSE_CACHE", str(tmp_path / "cache"))
    with pytest.raises(PriorError, match="airpose prior train"):
        load_prior("kit")
    torch.manual_seed(0)
    model = VPoser().eval()
    from airpose_lib.prior import kit_prior_path

    save_prior(model, kit_prior_path("smoke"), {"seed": 5})
    loaded, prov = load_prior("kit", return_provenance=True)
    assert prov["seed"] == 5 and prov["source"] == "kit" and "kit_version" in prov
    z = torch.randn(3, 32)
    torch.testing.assert_close(loaded.decode_matrot(z), model.decode_matrot(z))
    with pytest.raises(PriorError):
        load_prior("kit", tag="paper")
    with pytest.raises(ValueError):
        load_prior("other")


# -- training -------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def corpus():
    from airpose_lib.data.still.poses import sample_body_pose

    return (sample_body_pose(np.random.default_rng(0), 6000).astype(np.float32),
            sample_body_pose(np.random.default_rng(1), 500).astype(np.float32))


def test_training_is_deterministic(corpus):
    cfg = PriorTrainConfig(steps=15, batch_size=64, kl_anneal_steps=5)
    m1, h1 = train_prior(corpus[0], cfg)
    m2, h2 = train_prior(corpus[0], cfg)
    assert h1["loss"] == h2["loss"]
    for (k, a), b in zip(m1.state_dict().items(), m2.state_dict().values()):
        assert torch.equal(a, b), k
    m3, _ = train_prior(corpus[0], PriorTrainConfig(steps=15, batch_size=64, seed=1))
    assert not torch.equal(m3.decoder_net[5].weight, m1.decoder_net[5].weight)


def test_short_training_reconstructs_held_out_poses(corpus):
    train, val = corpus
    untrained = evaluate_prior(VPoser(), val)
    model, hist = train_prior(train, PriorTrainConfig(steps=300, batch_size=128, kl_anneal_steps=100,
                                                       lr=2e-3), val_poses=val)
    ev = hist["val"]
    # Baseline: the typical joint rotation of these poses (error of predicting the rest pose).
    rest_err = math.degrees(np.linalg.norm(val, axis=-1).mean())
    # (measured: ~10.4 deg after 300 steps; rest pose 22.5 deg; untrained ~120 deg)
    assert ev["rot_err_deg"] < 13.0, ev["rot_err_deg"]
    assert ev["rot_err_deg"] < 0.6 * rest_err and ev["rot_err_deg"] < 0.2 * untrained["rot_err_deg"]
    assert len(ev["per_joint_rot_err_deg"]) == 21 and ev["n"] == len(val)
    assert not model.training
    # Decoded N(0, I) samples look like the corpus: inside the anatomical limits (+10 deg).
    from airpose_lib.data.still.poses import within_limits

    s = model.sample(200, seed=0)["pose_body"].numpy()
    assert within_limits(s, tol=np.deg2rad(10)).mean() > 0.9


def test_training_rejects_bad_corpora():
    with pytest.raises(ValueError):
        train_prior(np.zeros((10, 20, 3)), PriorTrainConfig(steps=1))
    with pytest.raises(ValueError):
        train_prior(np.full((10, 21, 3), np.nan), PriorTrainConfig(steps=1))
    with pytest.raises(ValueError):
        train_prior(np.zeros((1, 21, 3)), PriorTrainConfig(steps=1))
