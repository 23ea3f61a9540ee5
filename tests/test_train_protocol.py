"""The Table I protocol: weak-camera scale guard, official MPJPE, shared pretrained backbone and its
feature cache, heading classes."""
from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
import torch
from torch import nn

from airpose_lib.body.forward import BodyForward
from airpose_lib.eval.tables import per_view_table
from airpose_lib.geometry import axis_angle_to_matrix, matrix_to_rot6d, project_points
from airpose_lib.losses import BaselineLossConfig, SupervisedLoss
from airpose_lib.losses.pretrain import PretrainLoss, heading_bin, heading_of
from airpose_lib.model.pretrain import PretrainNet
from airpose_lib.paths import RunFolders, portable
from airpose_lib.reproduce.configs import kit_configs
from airpose_lib.train.evaluate import predict
from airpose_lib.train.features import feature_key
from airpose_lib.train.loop import MIN_WEAK_SCALE, _supervised_terms


@pytest.fixture(scope="module")
def bodies(open_model_files):
    from airpose_lib.body import load_body_model

    return {g: load_body_model("open", g) for g in ("neutral", "male", "female")}


def _batch(bodies, B=4, V=2, seed=0):
    """Ground truth of B samples seen by V cameras at about 10 m (float32, neutral bodies)."""
    g = torch.Generator().manual_seed(seed)
    theta = torch.randn(B, 21, 3, generator=g) * 0.2
    beta = torch.randn(B, 10, generator=g)
    # upright and facing the camera, turned about the vertical by a random heading
    yaw = (torch.rand(B, V, generator=g) - 0.5) * 2.0
    phi = axis_angle_to_matrix(torch.tensor([math.pi, 0.0, 0.0])) @ axis_angle_to_matrix(
        torch.stack([torch.zeros_like(yaw), yaw, torch.zeros_like(yaw)], -1))
    tau = torch.stack([torch.randn(B, V, generator=g) * 0.5, torch.randn(B, V, generator=g) * 0.5,
                       9.0 + 2 * torch.rand(B, V, generator=g)], -1)
    K = torch.tensor([[1475.0, 0, 959.5], [0, 1475, 539.5], [0, 0, 1]]).expand(B, V, 3, 3)
    body = BodyForward(bodies["neutral"])
    j3d, _ = body(axis_angle_to_matrix(theta).unsqueeze(1).expand(B, V, 21, 3, 3), beta.unsqueeze(1), phi, tau,
                  vertices=False)
    j2d = project_points(j3d, K)
    bbox = torch.cat((j2d.amin(-2) - 20, j2d.amax(-2) + 20), -1)
    side = torch.maximum(bbox[..., 2] - bbox[..., 0], bbox[..., 3] - bbox[..., 1])
    cc = 0.5 * (bbox[..., :2] + bbox[..., 2:])
    P = torch.stack([cc[..., 0] / 959.5 - 1, cc[..., 1] / 539.5 - 1, 224.0 / side], -1)
    return dict(theta=theta, beta=beta, phi=phi, tau=tau, K=K, j2d=j2d, j3d_cam=j3d, bbox=bbox, P=P,
                gender=torch.zeros(B, dtype=torch.long), index=torch.arange(B))


# -- the weak-camera scale guard ------------------------------------------------------------------
def _fit_weak_scale(bodies, w_cam_scale: float, steps: int = 150) -> float:
    """Optimise the Baseline's weak cameras on 2D targets mirrored through the box centre (what a
    negative depth shows): the 2D term then shrinks the body towards s_w = 0, and past it."""
    batch = _batch(bodies)
    cc = 0.5 * (batch["bbox"][..., None, :2] + batch["bbox"][..., None, 2:])
    batch["j2d"] = 2 * cc - batch["j2d"]
    loss_fn = SupervisedLoss(BaselineLossConfig(w_cam_scale=w_cam_scale), bodies)
    B, V = batch["phi"].shape[:2]
    theta = axis_angle_to_matrix(batch["theta"]).unsqueeze(1).expand(B, V, 21, 3, 3)
    cam = nn.Parameter(torch.tensor([0.5, 0.0, 0.0]).repeat(B, V, 1))
    opt = torch.optim.Adam([cam], lr=0.02)
    for _ in range(steps):
        out = {"phi6d": matrix_to_rot6d(batch["phi"]), "theta6d": matrix_to_rot6d(theta),
               "beta": batch["beta"].unsqueeze(1).expand(B, V, 10), "cam": cam}
        terms = _supervised_terms(out, loss_fn, batch, 224)
        opt.zero_grad()
        terms["total"].backward()
        opt.step()
    return float(cam.detach()[..., 0].min())


def test_scale_guard_keeps_the_weak_scale_positive(bodies):
    collapsed = _fit_weak_scale(bodies, w_cam_scale=0.0)
    guarded = _fit_weak_scale(bodies, w_cam_scale=1.0)
    print(f"weak scale after the run: {collapsed:.3f} without the guard, {guarded:.3f} with it")
    assert collapsed < 0.0  # without the guard s_w runs past zero (every depth behind the camera)
    assert guarded > 0.5 * MIN_WEAK_SCALE  # with it s_w stays positive, held near the loss's floor


# -- Table I's MPJPE (official definition) --------------------------------------------------------
class _ReturnsInput(nn.Module):
    """A 'regressor' that returns the parameters packed into its features (for an exact test)."""

    def regress(self, feat, P):
        return {"phi6d": feat[..., :6], "theta6d": feat[..., 6:132].unflatten(-1, (21, 6)),
                "beta": feat[..., 132:142], "tau": feat[..., 142:145]}


def test_official_mpjpe_ignores_shape_and_translation_but_scores_the_root(bodies):
    batch = _batch(bodies, B=3)
    B, V = batch["phi"].shape[:2]
    theta = axis_angle_to_matrix(batch["theta"]).unsqueeze(1).expand(B, V, 21, 3, 3)
    wrong_beta = batch["beta"].unsqueeze(1).expand(B, V, 10) + 2.0
    feat = torch.cat([matrix_to_rot6d(batch["phi"]), matrix_to_rot6d(theta).flatten(-2), wrong_beta,
                      batch["tau"] + torch.tensor([0.0, 0.0, 1.0])], -1)
    items = [{**{k: v[i] for k, v in batch.items()}, "features": feat[i], "crop_size": torch.tensor(224)}
             for i in range(B)]
    body = BodyForward(bodies["neutral"])
    pred, gt = predict(_ReturnsInput(), items, batch_size=B, body=body)
    table = per_view_table(pred, gt)
    assert table["mpjpe_m"].max() < 1e-5  # shape and depth are not scored
    assert table["mpjpe_shape_m"].min() > 0.01  # the kit's shape-aware MPJPE sees the betas
    assert table["mpe_m"].to_numpy() == pytest.approx(1.0, abs=1e-5)
    # a root rotated by 90 degrees about the vertical: hand-computed from the zero-beta joints
    R = axis_angle_to_matrix(torch.tensor([0.0, math.pi / 2, 0.0]))
    feat[..., :6] = matrix_to_rot6d(batch["phi"] @ R)
    items = [{**items[i], "features": feat[i]} for i in range(B)]
    pred, gt = predict(_ReturnsInput(), items, batch_size=B, body=body)
    J, _ = body(theta, torch.zeros(B, V, 10), vertices=False)
    Jp, Jg = J @ (batch["phi"] @ R).transpose(-1, -2), J @ batch["phi"].transpose(-1, -2)
    expected = ((Jp - Jp[..., :1, :]) - (Jg - Jg[..., :1, :])).norm(dim=-1).mean(-1)
    np.testing.assert_allclose(per_view_table(pred, gt)["mpjpe_m"], expected.reshape(-1).numpy(), atol=1e-5)


# -- the pretrained backbone ----------------------------------------------------------------------
def test_heading_classes():
    facing = axis_angle_to_matrix(torch.tensor([math.pi, 0.0, 0.0]))  # faces the camera
    assert abs(float(heading_of(facing))) == pytest.approx(math.pi, abs=1e-6)
    away = torch.eye(3)
    assert float(heading_of(away)) == pytest.approx(0.0, abs=1e-6)
    assert int(heading_bin(away, 12)) == 6 and int(heading_bin(facing, 12)) in (0, 11)
    turned = away @ axis_angle_to_matrix(torch.tensor([0.0, math.pi / 2, 0.0]))
    assert float(heading_of(turned)) == pytest.approx(math.pi / 2, abs=1e-6)
    assert int(heading_bin(turned, 12)) == 9


def test_pretrain_loss_is_zero_for_the_ground_truth(bodies):
    batch = _batch(bodies, B=2)
    B, V = batch["phi"].shape[:2]
    S = 64
    batch["images"] = torch.zeros(B, V, 3, S, S)
    loss = PretrainLoss(body_models=bodies)
    theta = axis_angle_to_matrix(batch["theta"])
    J0, _ = BodyForward(bodies["neutral"])(theta, batch["beta"], vertices=False)
    from airpose_lib.geometry import full_to_crop_pixels

    uv = full_to_crop_pixels(batch["j2d"], batch["bbox"], S) / (S / 2) - 1
    logits = torch.full((B * V, 12), -50.0)
    logits[torch.arange(B * V), heading_bin(batch["phi"].flatten(0, 1), 12)] = 50.0
    rep = lambda x: x.unsqueeze(1).expand(B, V, *x.shape[1:]).flatten(0, 1)  # noqa: E731
    out = {"heading": logits, "phi6d": matrix_to_rot6d(batch["phi"]).flatten(0, 1),
           "theta6d": rep(matrix_to_rot6d(theta)), "beta": rep(batch["beta"]), "j3d": rep(J0),
           "j2d": uv.flatten(0, 1)}
    terms = loss(out, batch, 12)
    for k in ("heading", "phi", "theta", "beta", "j3d", "j2d"):
        assert terms[k].item() == pytest.approx(0.0, abs=1e-5), k
    net = PretrainNet("resnet18", n_heading_bins=12)
    heads = net(torch.zeros(2, 3, 64, 64))
    assert heads["heading"].shape == (2, 12) and heads["theta6d"].shape == (2, 21, 6) and heads["j2d"].shape == (2, 22, 2)


def test_pretrain_root_terms_geodesic_and_camera_frame(bodies):
    """phi_loss="geodesic" is the angle of the root error in radians; j3d_frame="camera" targets the
    pelvis-centred joints turned by each view's phi; both are zero for the ground truth."""
    from scipy.spatial.transform import Rotation

    from airpose_lib.errors import ConfigError
    from airpose_lib.losses.pretrain import PretrainLossConfig, camera_frame_joints

    J = torch.tensor([[[0.0, 1.0, 0.0], [1.0, 1.0, 0.0], [0.0, 2.0, 0.5]]], dtype=torch.float64)
    Ry = torch.tensor([[[0.0, 0.0, 1.0], [0.0, 1.0, 0.0], [-1.0, 0.0, 0.0]]], dtype=torch.float64)  # 90 deg about y
    assert torch.allclose(camera_frame_joints(J, Ry), torch.tensor([[[0.0, 0, 0], [0, 0, -1], [0.5, 1, 0]]],
                                                                   dtype=torch.float64))
    batch = _batch(bodies, B=2)
    B, V = batch["phi"].shape[:2]
    S = 64
    batch["images"] = torch.zeros(B, V, 3, S, S)
    cfg = PretrainLossConfig(phi_loss="geodesic", j3d_frame="camera")
    loss = PretrainLoss(cfg, body_models=bodies)
    theta = axis_angle_to_matrix(batch["theta"])
    J0, _ = BodyForward(bodies["neutral"])(theta, batch["beta"], vertices=False)
    phi = batch["phi"].flatten(0, 1)
    rep = lambda x: x.unsqueeze(1).expand(B, V, *x.shape[1:]).flatten(0, 1)  # noqa: E731
    from airpose_lib.geometry import full_to_crop_pixels

    uv = full_to_crop_pixels(batch["j2d"], batch["bbox"], S) / (S / 2) - 1
    out = {"heading": torch.zeros(B * V, 12), "phi6d": matrix_to_rot6d(phi),
           "theta6d": rep(matrix_to_rot6d(theta)), "beta": rep(batch["beta"]),
           "j3d": camera_frame_joints(rep(J0), phi), "j2d": uv.flatten(0, 1)}
    terms = loss(out, batch, 12)
    assert terms["phi"].item() == pytest.approx(0.0, abs=1e-5) and terms["j3d"].item() == pytest.approx(0.0, abs=1e-8)
    assert PretrainLoss(body_models=bodies)(out, batch, 12)["j3d"].item() > 1e-3  # model frame: not the target
    turn = torch.as_tensor(Rotation.from_rotvec([0.0, 0.0, np.deg2rad(30.0)]).as_matrix(), dtype=phi.dtype)
    out["phi6d"] = matrix_to_rot6d(phi @ turn)  # every view off by 30 deg
    assert loss(out, batch, 12)["phi"].item() == pytest.approx(np.deg2rad(30.0), rel=1e-4)
    with pytest.raises(ConfigError, match="phi_loss"):
        PretrainLossConfig(phi_loss="l1")
    with pytest.raises(ConfigError, match="j3d_frame"):
        PretrainLossConfig(j3d_frame="world")


def test_feature_key_changes_with_the_backbone_and_the_data(tmp_path):
    import yaml

    from airpose_lib.data.still.manifest import DATASET_KIND

    data = tmp_path / "data"
    data.mkdir()
    manifest = {"kind": DATASET_KIND, "fingerprint": "abc", "shards": [{"sha256": "1"}, {"sha256": "2"}]}
    (data / "manifest.yaml").write_text(yaml.safe_dump(manifest))
    b1, b2 = tmp_path / "b1.pt", tmp_path / "b2.pt"
    torch.save({"state_dict": {"w": torch.zeros(3)}, "meta_json": json.dumps({"backbone": "resnet18"})}, b1)
    torch.save({"state_dict": {"w": torch.ones(3)}, "meta_json": json.dumps({"backbone": "resnet18"})}, b2)
    k = feature_key(b1, data, "train", "jittered")
    assert feature_key(b1, data, "train", "jittered") == k  # same inputs, same key
    assert feature_key(b2, data, "train", "jittered") != k  # another backbone
    assert feature_key(b1, data, "test", "jittered") != k and feature_key(b1, data, "train", "tight") != k
    manifest["shards"][1]["sha256"] = "3"  # a regenerated shard
    (data / "manifest.yaml").write_text(yaml.safe_dump(manifest))
    assert feature_key(b1, data, "train", "jittered") != k


def test_a_second_pretraining_stage_starts_from_the_first(tmp_path, monkeypatch, private_cache):
    """`continue_from:` trains the earlier stage first (or finds it), then starts the later one from
    its backbone; the later key depends on the earlier one; a second call trains nothing."""
    import yaml

    import airpose_lib.train.pretrain as pretrain
    from airpose_lib.data.still.generate import GenerationConfig, generate_still_dataset
    from airpose_lib.data.still.manifest import load_manifest
    from airpose_lib.train.features import load_backbone_file
    from airpose_lib.train.pretrain import ensure_backbone, pretrain_stages, stage_keys

    root = tmp_path / "data"
    generate_still_dataset(GenerationConfig(num_samples=16, shard_size=4, crop_size=32, seed=0), root,
                           workers=1, progress=False, record=False)
    section = {"steps": 1, "batch_size": 2, "backbone": "resnet18", "lr": 1e-3, "seed": 0, "checkpoint_every": 1,
               "val_every": None, "log_every": 1, "num_workers": 0, "model": {"n_heading_bins": 12}}
    profile = tmp_path / "two.yaml"
    profile.write_text(yaml.safe_dump({"pretrain": {**section, "continue_from": {"steps": 2}}}))
    fp = load_manifest(root)["fingerprint"]
    stages = pretrain_stages(kit_configs(str(profile)).pretrain)
    assert [c.steps for c in stages] == [2, 1]
    keys = stage_keys(stages, fp)
    one = tmp_path / "one.yaml"
    one.write_text(yaml.safe_dump({"pretrain": {**section, "steps": 2}}))
    assert stage_keys(pretrain_stages(kit_configs(str(one)).pretrain), fp) == keys[:1]  # the first stage alone: same key
    other = tmp_path / "other.yaml"
    other.write_text(yaml.safe_dump({"pretrain": {**section, "continue_from": {"steps": 3}}}))
    assert stage_keys(pretrain_stages(kit_configs(str(other)).pretrain), fp)[-1] != keys[-1]  # another start, another key

    path = ensure_backbone(kit_configs(str(profile)).pretrain, root, fp, out_root=tmp_path / "runs")
    assert path.stem == keys[-1]
    record = json.loads(path.with_suffix(".json").read_text())
    assert record["steps"] == 1 and record["total_steps"] == 3
    assert record["continued_from"]["key"] == keys[0] and record["continued_from"]["steps"] == 2
    first, _ = load_backbone_file(path.with_name(f"{keys[0]}.pt"))
    second, _ = load_backbone_file(path)
    fresh = PretrainNet("resnet18").backbone
    w1, w2 = (m.conv1.weight.detach() for m in (first, second))
    step = float((w2 - w1).abs().max())
    assert 0 < step < 0.01  # one Adam step of lr 1e-3 (fp16 file) from the first stage's weights
    assert float((fresh.conv1.weight.detach() - w1).abs().max()) > 10 * step

    monkeypatch.setattr(pretrain, "start_training", lambda *a, **k: pytest.fail("trained again"))
    assert ensure_backbone(kit_configs(str(profile)).pretrain, root, fp, out_root=tmp_path / "runs") == path


def test_earlier_stages_keep_their_dataset_when_the_profile_data_grow(tmp_path, private_cache):
    """Three stages; the first two pinned to a smaller dataset (`data: still:` changes) keep the
    keys they had when that was the profile's dataset, and are trained on it (generated in the
    cache when needed); the last stage trains on the dataset it is given."""
    import yaml

    from airpose_lib.data.still.generate import GenerationConfig, generate_still_dataset
    from airpose_lib.data.still.manifest import load_manifest
    from airpose_lib.train.pretrain import ensure_backbone, pretrain_stages, stage_keys

    small = {"num_samples": 8, "shard_size": 2, "crop_size": 32, "seed": 0}  # 2 train, 1 val, 1 test shards
    section = {"steps": 1, "batch_size": 2, "backbone": "resnet18", "lr": 1e-3, "seed": 0, "checkpoint_every": 1,
               "val_every": None, "log_every": 1, "num_workers": 0, "model": {"n_heading_bins": 12}}
    before = tmp_path / "grow.yaml"  # the profile when its dataset was the small one: two stages
    before.write_text(yaml.safe_dump({"data": {"still": small},
                                      "pretrain": {**section, "continue_from": {"steps": 2}}}))
    small_fp = GenerationConfig(**small).fingerprint()
    old_keys = stage_keys(pretrain_stages(kit_configs(str(before)).pretrain), small_fp)

    after = tmp_path / "grown" / "grow.yaml"  # the dataset grew; a third stage was added
    after.parent.mkdir()
    after.write_text(yaml.safe_dump({"data": {"still": {**small, "num_samples": 10}}, "pretrain": {
        **section, "continue_from": {"steps": 1, "data": {"still": {"num_samples": 8}}, "continue_from": {"steps": 2}}}}))
    stages = pretrain_stages(kit_configs(str(after)).pretrain)
    assert [c.steps for c in stages] == [2, 1, 1]
    assert [c.data.get("fingerprint") for c in stages] == [small_fp, small_fp, None]
    assert stages[0].data["root"] == str(RunFolders.of("grow").still.with_name(f"still_grow-{small_fp[:12]}"))
    root = tmp_path / "data"
    generate_still_dataset(GenerationConfig(**{**small, "num_samples": 10}), root, workers=1, progress=False,
                           record=False)
    fp = load_manifest(root)["fingerprint"]
    keys = stage_keys(stages, fp)
    assert keys[:2] == old_keys and keys[2] not in old_keys

    path = ensure_backbone(kit_configs(str(after)).pretrain, root, fp, out_root=tmp_path / "runs")
    assert path.stem == keys[-1]
    record = json.loads(path.with_suffix(".json").read_text())
    assert record["data_fingerprint"] == fp and record["total_steps"] == 4
    assert record["continued_from"]["key"] == keys[1]
    earlier = json.loads(path.with_name(f"{keys[1]}.json").read_text())
    # the record names the stage's dataset without this machine's folders
    assert earlier["data_fingerprint"] == small_fp
    assert earlier["config"]["data"]["root"] == portable(stages[0].data["root"])
    assert earlier["config"]["data"]["root"].startswith("<cache>/")
    assert load_manifest(Path(stages[0].data["root"]))["totals"]["samples"] == 8  # generated for them


def test_the_reference_backbone_names_no_folder_of_this_machine(tmp_path, monkeypatch):
    """A cache file an older kit wrote (its record names this machine's folders) becomes a
    reference whose record, in the file and beside it, is portable, with the reference's own
    SHA-256 (which the reference's check compares); a portable file is copied byte for byte."""
    import airpose_lib.train.pretrain as pretrain
    from airpose_lib.model.backbone import build_backbone
    from airpose_lib.train.features import load_backbone_file

    monkeypatch.setenv("AIRPOSE_CACHE", str(tmp_path / "cache"))
    monkeypatch.setattr(pretrain, "reference_backbone_path", lambda folders: tmp_path / "results" / "backbone.pt")
    sd = {k: v.half() if v.is_floating_point() else v for k, v in build_backbone("resnet18").state_dict().items()}
    meta = {"backbone": "resnet18", "key": "k1", "profile": "/work/sel/cpu_x.yaml",
            "command": "airpose pretrain --profile /work/sel/cpu_x.yaml",
            "config": {"data": {"root": str(tmp_path / "cache" / "data" / "still_cpu")}, "pretrained": None}}
    old = tmp_path / "cache" / "backbones" / "k1.pt"
    old.parent.mkdir(parents=True)
    torch.save({"state_dict": sd, "meta_json": json.dumps(meta)}, old)  # as the kit wrote it before
    old.with_suffix(".json").write_text(json.dumps(dict(meta, sha256=pretrain.sha256_file(old))))

    ref = pretrain.write_reference_backbone(RunFolders.of("cpu"), old)
    record = json.loads(ref.with_suffix(".json").read_text())
    _, inside = load_backbone_file(ref)
    expected = {"backbone": "resnet18", "key": "k1", "profile": "<abs>/sel/cpu_x.yaml",
                "command": "airpose pretrain --profile <abs>/sel/cpu_x.yaml",
                "config": {"data": {"root": "<cache>/data/still_cpu"}, "pretrained": None}}
    assert inside == expected
    assert record == dict(expected, sha256=pretrain.sha256_file(ref), bytes=ref.stat().st_size)
    assert pretrain._reference_if_valid(RunFolders.of("cpu"), "k1") == ref

    new = pretrain._write_backbone_file(sd, tmp_path / "cache" / "backbones" / "k2.pt", dict(meta, key="k2"))
    assert json.loads(new.with_suffix(".json").read_text())["profile"] == "<abs>/sel/cpu_x.yaml"  # written portable
    ref = pretrain.write_reference_backbone(RunFolders.of("cpu"), new)
    assert ref.read_bytes() == new.read_bytes()
    assert ref.with_suffix(".json").read_text() == new.with_suffix(".json").read_text()


def test_regressor_with_its_last_backbone_block_trainable(tmp_path, private_cache):
    """trainable_from: the features are the cut's input; the step on them equals the whole network
    on the crops; only the blocks from the cut and the regressor move, at their own rates."""
    import airpose_lib.train.loop as loop
    from airpose_lib.data.still.generate import GenerationConfig, generate_still_dataset
    from airpose_lib.train.config import TrainConfig
    from airpose_lib.train.features import FeatureDataset, ensure_features

    root = tmp_path / "data"
    generate_still_dataset(GenerationConfig(num_samples=16, shard_size=4, crop_size=32, seed=0), root,
                           workers=1, progress=False, record=False)
    torch.manual_seed(1)
    trunk = PretrainNet("resnet18").backbone
    bfile = tmp_path / "backbone.pt"
    torch.save({"state_dict": trunk.state_dict(), "meta_json": json.dumps({"backbone": "resnet18"})}, bfile)
    cfg = TrainConfig(variant="airpose", task="regressor", pretrained=str(bfile), backbone="resnet18",
                      trainable_from="layer4.1", backbone_lr_scale=0.1, steps=2, batch_size=2, lr=1e-3,
                      data={"root": str(root)}, val_every=None, checkpoint_every=1, log_every=1,
                      progress=False, loss={"vertex_subsample": 50})
    path = ensure_features(bfile, root, "train", cut="layer4.1")
    assert path != ensure_features(bfile, root, "train")  # another cut, another file
    assert np.load(path).shape[1:] == (2, 512, 1, 1)  # (V, C, h, w) at 32 px

    model = loop.default_model_factory(cfg).eval()
    trainable = {n for n, p in model.named_parameters() if p.requires_grad}
    assert any(n.startswith("backbone.layer4.1.") for n in trainable)
    assert not any(n.startswith("backbone.") and not n.startswith("backbone.layer4.1.") for n in trainable)
    loss_fn = loop.default_loss_factory(cfg)
    assert isinstance(loop.default_dataset_factory(cfg, "train"), FeatureDataset)
    feats = FeatureDataset(root, "train", path, augment=False)  # no view swap: item for item as the crops
    from airpose_lib.data.still.dataset import StillFrameDataset

    crops = StillFrameDataset(root, "train", augment=False)
    fb = {k: torch.stack([feats[i][k] for i in range(2)]) for k in feats[0]}
    ib = {k: torch.stack([crops[i][k] for i in range(2)]) for k in crops[0]}
    with torch.no_grad():
        on_feats = loop.task_forward(cfg)(model, loss_fn, fb)["total"]
        on_crops = loop.forward_loss(model, loss_fn, ib)["total"]
    assert float(on_feats) == pytest.approx(float(on_crops), rel=1e-4)

    from airpose_lib.train import train

    result = train("airpose", config=cfg, out_dir=tmp_path / "run", resume=False)
    state = torch.load(result.checkpoint, map_location="cpu", weights_only=False)["model"]
    start = model.state_dict()
    moved = lambda k: not torch.equal(state[k], start[k])  # noqa: E731
    assert moved("backbone.layer4.1.conv2.weight") and moved("regressor.fc1.weight")
    assert not moved("backbone.layer4.0.conv1.weight") and not moved("backbone.conv1.weight")
    assert torch.equal(state["backbone.layer4.1.bn1.running_mean"], start["backbone.layer4.1.bn1.running_mean"])
    # one Adam step moves a weight by about its rate: the trunk's is a tenth of the regressor's
    d_trunk = (state["backbone.layer4.1.conv2.weight"] - start["backbone.layer4.1.conv2.weight"]).abs().max()
    d_head = (state["regressor.fc1.weight"] - start["regressor.fc1.weight"]).abs().max()
    assert float(d_trunk) < 0.5 * float(d_head)
    # evaluated through the cached features, the trained block runs: the same tables as on the crops
    from airpose_lib.train.evaluate import evaluate, evaluate_features, load_trained_model

    on_features = evaluate_features(result.checkpoint, bfile, root, "x", split="train")["per_view"]
    trained, _ = load_trained_model(result.checkpoint)
    on_images = evaluate(trained, crops, "x", body=cfg.body_source)["per_view"]
    for col in ("mpe_m", "mpjpe_m", "mpjpe_true_root_m"):
        np.testing.assert_allclose(on_features[col], on_images[col], rtol=1e-4, atol=1e-6)


def test_the_committed_cpu_backbone_keeps_its_key():
    """A new TrainConfig field must not silently orphan the committed backbone (a new key would
    retrain both stages, hours on a 2-core machine, on a user's first cpu run)."""
    from airpose_lib.train.pretrain import pretrain_stages, reference_backbone_path, stage_keys

    record = json.loads(reference_backbone_path(RunFolders.of("cpu")).with_suffix(".json").read_text())
    keys = stage_keys(pretrain_stages(kit_configs("cpu").pretrain), record["data_fingerprint"])
    chain = []  # the committed record names the stages it continued, last to first
    while record:
        chain.append(record["key"])
        record = record.get("continued_from")
    assert keys == chain[::-1]


def test_the_four_stage_lab_profile_undoes_the_fifth_stage():
    """lab/cpu_four_stages.yaml spells the fifth stage's shape terms at their defaults and cuts the
    chain: its stages are the committed backbone's first four, key for key."""
    from airpose_lib.profiles import PROFILES_DIR
    from airpose_lib.train.pretrain import pretrain_stages, reference_backbone_path, stage_keys

    record = json.loads(reference_backbone_path(RunFolders.of("cpu")).with_suffix(".json").read_text())
    four = kit_configs(str(PROFILES_DIR / "lab" / "cpu_four_stages.yaml")).pretrain
    chain = []
    while record:
        chain.append(record["key"])
        record = record.get("continued_from")
    assert len(chain) == 5
    assert stage_keys(pretrain_stages(four), json.loads(reference_backbone_path(RunFolders.of("cpu")).with_suffix(
        ".json").read_text())["data_fingerprint"]) == chain[::-1][:4]


def test_training_and_pretraining_never_read_the_test_split(tmp_path, monkeypatch, private_cache):
    """Never choose on the test split: a pretraining (its validation and gate) and a regressor
    training (its features and validation) open the train and val splits only, every profile's
    training and pretraining settings name no test split, and a config that does is refused."""
    import yaml

    from airpose_lib.data.still import dataset as dataset_module
    from airpose_lib.data.still.generate import GenerationConfig, generate_still_dataset
    from airpose_lib.data.still.manifest import load_manifest
    from airpose_lib.errors import ConfigError
    from airpose_lib.model.variants import VARIANTS
    from airpose_lib.profiles import profile_names
    from airpose_lib.train import train
    from airpose_lib.train.config import TrainConfig
    from airpose_lib.train.pretrain import ensure_backbone, pretrain_stages

    for name in profile_names():
        configs = [kit_configs(name).train.config(v) for v in VARIANTS] + pretrain_stages(kit_configs(name).pretrain)
        assert all("test" not in (c.train_split, c.val_split) for c in configs), name
    for field in ("train_split", "val_split"):
        with pytest.raises(ConfigError, match=field):
            TrainConfig(**{field: "test"})

    opened = []
    init = dataset_module.StillFrameDataset.__init__

    def recording(self, root, split="train", *args, **kwargs):
        opened.append(split)
        init(self, root, split, *args, **kwargs)

    monkeypatch.setattr(dataset_module.StillFrameDataset, "__init__", recording)
    root = tmp_path / "data"
    generate_still_dataset(GenerationConfig(num_samples=6, shard_size=2, crop_size=32, seed=0, val_fraction=0.3),
                           root, workers=1, progress=False, record=False)
    profile = tmp_path / "p.yaml"
    profile.write_text(yaml.safe_dump({"pretrain": {
        "steps": 1, "batch_size": 2, "backbone": "resnet18", "lr": 1e-3, "seed": 0, "checkpoint_every": 1,
        "val_every": 1, "log_every": 1, "num_workers": 0, "model": {"n_heading_bins": 12}}}))
    backbone = ensure_backbone(kit_configs(str(profile)).pretrain, root, load_manifest(root)["fingerprint"], out_root=tmp_path / "runs")
    assert json.loads(backbone.with_suffix(".json").read_text())["gate_split"] == "val"
    cfg = TrainConfig(variant="airpose", task="regressor", pretrained=str(backbone), backbone="resnet18", steps=1,
                      batch_size=2, lr=1e-3, data={"root": str(root)}, val_every=1, checkpoint_every=1, log_every=1,
                      progress=False, loss={"vertex_subsample": 50})
    train("airpose", config=cfg, out_dir=tmp_path / "run", resume=False)
    assert "val" in opened and "train" in opened and "test" not in opened, opened


def test_gate_reports_the_root_error_as_yaw_tilt_and_flips():
    """The pretraining gate on a stub whose root head is the truth turned about the body's up axis
    (30 deg for most crops, 180 deg for a quarter): yaw median 30, tilt 0, a quarter above 90 deg."""
    from scipy.spatial.transform import Rotation

    from airpose_lib.train.pretrain import gate_metrics

    rng = np.random.default_rng(0)
    n, V = 8, 2
    # upright bodies (tilt is measured between up axes) with random headings in the camera
    phi = torch.as_tensor(Rotation.from_euler("y", rng.uniform(-np.pi, np.pi, (n * V, 1))).as_matrix(),
                          dtype=torch.float32).reshape(n, V, 3, 3)
    turns = np.where(np.arange(n * V) % 4 == 0, 180.0, 30.0)
    turn = torch.as_tensor(Rotation.from_euler("y", turns[:, None], degrees=True).as_matrix(), dtype=torch.float32)
    items = [{"images": torch.zeros(V, 3, 8, 8), "phi": phi[i], "theta": torch.zeros(21, 3)} for i in range(n)]

    class Stub(nn.Module):
        n_heading_bins = 12

        def __init__(self):
            super().__init__()
            self.k = 0

        def forward(self, images):
            N = images.shape[0]
            R = phi.flatten(0, 1)[self.k:self.k + N] @ turn[self.k:self.k + N]  # turn about the body's y
            self.k += N
            return {"phi6d": matrix_to_rot6d(R), "theta6d": matrix_to_rot6d(torch.eye(3).expand(N, 21, 3, 3)),
                    "heading": torch.zeros(N, 12)}

    gate = gate_metrics(Stub(), items, batch_size=4)
    assert gate["n"] == n * V and gate["root_rot_over_90"] == pytest.approx(0.25)
    assert gate["root_yaw_median_deg"] == pytest.approx(30.0, abs=1e-3)
    assert gate["root_tilt_median_deg"] == pytest.approx(0.0, abs=1e-3)
    assert gate["root_rot_median_deg"] == pytest.approx(30.0, abs=1e-3)


def test_pretrain_stature_and_gender_terms(bodies):
    """w_stature reads the T-posed gendered stature, standardised; w_gender is the female logit's
    cross-entropy; both off by default (no heads needed), and body_scalars adds the heads last."""
    from airpose_lib.body.genders import GENDER_CODES
    from airpose_lib.eval.mean_body import rest_statures
    from airpose_lib.losses.pretrain import PretrainLossConfig

    batch = _batch(bodies, B=2)
    batch["gender"] = torch.tensor([GENDER_CODES["male"], GENDER_CODES["female"]])
    B, V = batch["phi"].shape[:2]
    S = 64
    batch["images"] = torch.zeros(B, V, 3, S, S)
    theta = axis_angle_to_matrix(batch["theta"])
    rep = lambda x: x.unsqueeze(1).expand(B, V, *x.shape[1:]).flatten(0, 1)  # noqa: E731
    out = {"heading": torch.zeros(B * V, 12), "phi6d": matrix_to_rot6d(batch["phi"]).flatten(0, 1),
           "theta6d": rep(matrix_to_rot6d(theta)), "beta": rep(batch["beta"]),
           "j3d": torch.zeros(B * V, 22, 3), "j2d": torch.zeros(B * V, 22, 2),
           "stature": torch.zeros(B * V, 1), "female": torch.zeros(B * V, 1)}
    assert set(PretrainLoss(body_models=bodies)(out, batch, 12)) == {"total", "heading", "phi", "theta", "beta",
                                                                     "j3d", "j2d"}
    loss = PretrainLoss(PretrainLossConfig(w_stature=2.0, w_gender=3.0, stature_mean=1.7, stature_scale=0.1),
                        body_models=bodies)
    h = loss.rest_stature(batch["beta"], batch["gender"])
    expected, _ = rest_statures(batch["beta"].numpy(), batch["gender"].numpy(), body_models=bodies)
    assert np.allclose(h.numpy(), expected, atol=1e-4)
    terms = loss(out, batch, 12)
    # a head that reads 0 misses by (h - 1.7) / 0.1 in each view; logit 0 costs ln 2
    assert terms["stature"].item() == pytest.approx(float(np.mean(((expected - 1.7) / 0.1) ** 2)), rel=1e-4)
    assert terms["gender"].item() == pytest.approx(math.log(2.0), rel=1e-5)
    base = PretrainLoss(body_models=bodies)(out, batch, 12)["total"]
    assert (terms["total"] - base).item() == pytest.approx(2.0 * terms["stature"].item() + 3.0 * math.log(2.0),
                                                           rel=1e-4)
    out["stature"] = rep(((torch.as_tensor(expected) - 1.7) / 0.1).float()).unsqueeze(-1)
    out["female"] = rep(torch.tensor([-50.0, 50.0])).unsqueeze(-1)
    terms = loss(out, batch, 12)
    assert terms["stature"].item() == pytest.approx(0.0, abs=1e-6) and terms["gender"].item() < 1e-6
    torch.manual_seed(0)
    plain = PretrainNet("resnet18")
    torch.manual_seed(0)
    scalars = PretrainNet("resnet18", body_scalars=True)
    heads = scalars(torch.zeros(2, 3, 64, 64))
    assert heads["stature"].shape == (2, 1) and heads["female"].shape == (2, 1) and "stature" not in plain(
        torch.zeros(1, 3, 64, 64))
    assert all(torch.equal(a, b) for a, b in zip(plain.state_dict().values(), scalars.state_dict().values()))
