"""Training loop: determinism, checkpoint/resume equality, logs, validation, config, data order.

Uses the real model package (ResNet-18 at 32 px) and the real supervised loss, with a small fake
still-frame dataset that follows the sample contract (random but consistent ground truth from the
open body model, noise images, a random view swap as augmentation).
"""

from __future__ import annotations

import json
import random

import numpy as np
import pytest
import torch
from torch.utils.data import Dataset

from airpose_lib.reproduce.configs import kit_configs
from airpose_lib.train import (
    ResumableBatchSampler,
    SeededDataset,
    TrainConfig,
    load_checkpoint,
    load_train_config,
    read_log,
    train,
)
from airpose_lib.train.sampling import epoch_permutation, sample_seed

S = 32  # crop size of the tiny training runs


_CACHE: dict = {}


def body_model(gender: str):
    """Open body models, loaded once per process."""
    from airpose_lib.body import load_body_model

    if ("body", gender) not in _CACHE:
        _CACHE[("body", gender)] = load_body_model("open", gender)
    return _CACHE[("body", gender)]


def make_samples(n: int, seed: int = 0, views: int = 2, genders: int = 3) -> dict[str, torch.Tensor]:
    """Ground truth of n two-view samples, consistent with the open body model (genders: 1 =
    neutral only, 3 = neutral, male and female at random)."""
    from airpose_lib.body.forward import BodyForward
    from airpose_lib.geometry import axis_angle_to_matrix, crop_vector, project_points

    g = torch.Generator().manual_seed(seed)
    theta = torch.randn(n, 21, 3, generator=g) * 0.2
    beta = torch.randn(n, 10, generator=g) * 0.5
    gender = torch.randint(0, genders, (n,), generator=g)
    # upright person (180 deg about x) turned about the camera's vertical axis, 7-12 m away
    yaw = (torch.rand(n, views, generator=g) - 0.5) * 2 * np.pi
    flip = axis_angle_to_matrix(torch.tensor([np.pi, 0.0, 0.0]))
    turn = axis_angle_to_matrix(torch.stack([torch.zeros_like(yaw), yaw, torch.zeros_like(yaw)], dim=-1))
    phi = turn @ flip
    tau = torch.stack([torch.randn(n, views, generator=g), torch.randn(n, views, generator=g) * 0.5,
                       7 + 5 * torch.rand(n, views, generator=g)], dim=-1)
    K = torch.tensor([[1475.0, 0, 960], [0, 1475, 540], [0, 0, 1]]).expand(n, views, 3, 3).clone()
    j3d = torch.empty(n, views, 22, 3)
    for code, name in enumerate(("neutral", "male", "female")):
        m = gender == code
        if m.any():
            body = BodyForward(body_model(name))
            j3d[m], _ = body(axis_angle_to_matrix(theta[m]).unsqueeze(1), beta[m].unsqueeze(1), phi[m], tau[m],
                             vertices=False)
    j2d = project_points(j3d, K)
    bbox = torch.cat([j2d.amin(dim=-2) - 20, j2d.amax(dim=-2) + 20], dim=-1)
    P = crop_vector(bbox, K, S)
    images = torch.randn(n, views, 3, S, S, generator=g)
    return dict(images=images, P=P, K=K, bbox=bbox, phi=phi, tau=tau, theta=theta, beta=beta, gender=gender,
                j2d=j2d, j3d_cam=j3d, index=torch.arange(n))


_PER_VIEW = ("images", "P", "K", "bbox", "phi", "tau", "j2d", "j3d_cam")


class FakeStillFrames(Dataset):
    """Contract-shaped still-frame samples; the train split swaps the views at random."""

    def __init__(self, n: int = 12, seed: int = 0, split: str = "train", genders: int = 3) -> None:
        self.data = make_samples(n, seed, genders=genders)
        self.split = split
        self.crop_size = S  # as every kit dataset: the checkpoints' network record takes it

    def __len__(self) -> int:
        return self.data["images"].shape[0]

    def __getitem__(self, i: int) -> dict:
        s = {k: v[i].clone() for k, v in self.data.items()}
        if self.split == "train" and torch.rand(()) < 0.5:  # augmentation through the global RNG
            for k in _PER_VIEW:
                s[k] = s[k].flip(0)
        s["images"] = s["images"] + 0.1 * torch.randn(s["images"].shape)  # and some noise
        return s


def fake_dataset_factory(cfg: TrainConfig, split: str):
    key = ("data", split, cfg.data.get("n", 12), cfg.data.get("genders", 3))
    if key not in _CACHE:
        _CACHE[key] = FakeStillFrames(n=key[2], seed=0 if split == "train" else 1, split=split, genders=key[3])
    return _CACHE[key]


def cached_loss_factory(cfg: TrainConfig):
    """The real loss of the variant, body models loaded once per process (the loss is stateless)."""
    from airpose_lib.losses import SupervisedLoss, loss_config

    genders = ("neutral", "male", "female")[: cfg.data.get("genders", 3)]
    key = ("loss", cfg.variant, tuple(sorted(cfg.loss.items())), genders)
    if key not in _CACHE:
        _CACHE[key] = SupervisedLoss(loss_config(cfg.variant, **cfg.loss), {g: body_model(g) for g in genders})
    return _CACHE[key]


FAKES = dict(dataset_factory=fake_dataset_factory, loss_factory=cached_loss_factory)


def tiny_config(**kw) -> TrainConfig:
    """ResNet-18 at 32 px with a frozen backbone (the regressor trains; keeps the tests fast), in
    fp32 on every CPU (``auto`` would pick bf16 on some: the tests compare exact numbers)."""
    base = dict(variant="airpose", steps=4, batch_size=4, backbone="resnet18", freeze_backbone=True, precision="fp32",
                checkpoint_every=2, keep_checkpoints=0, log_every=1, val_every=2, val_batches=1, seed=7,
                progress=False, data={"n": 12}, loss={"vertex_subsample": 300}, model={"num_iterations": 2})
    base.update(kw)
    return TrainConfig(**base)


def _weights(path):
    return load_checkpoint(path)["model"]


def _assert_same_state(a: dict, b: dict) -> None:
    assert a.keys() == b.keys()
    for k in a:
        assert torch.equal(a[k], b[k]), k


@pytest.fixture(scope="module")
def straight_run(module_tmp, open_model_files):
    out = module_tmp("straight")
    res = train("airpose", config=tiny_config(keep_checkpoints=2), out_dir=out, **FAKES)
    return out, res


def test_resume_after_interruption_equals_straight_run(straight_run, tmp_path):
    out_a, res_a = straight_run
    cfg = tiny_config()
    res1 = train("airpose", config=cfg, out_dir=tmp_path, **FAKES, stop_at=2)
    assert res1.stopped_early and res1.step == 2
    mid = load_checkpoint(res1.checkpoint)
    # mid-epoch: 12 samples / batch 4 = 3 batches per epoch
    assert (mid["epoch"], mid["batch_in_epoch"]) == (0, 2)
    assert not torch.equal(mid["model"]["regressor.fc1.weight"], _weights(res_a.checkpoint)["regressor.fc1.weight"])
    # resume (with a DataLoader worker process this time: per-sample seeding makes it irrelevant)
    res2 = train("airpose", config=cfg.replace(num_workers=1), out_dir=tmp_path, **FAKES)
    assert res2.step == 4 and not res2.stopped_early
    sa, sb = load_checkpoint(res_a.checkpoint), load_checkpoint(res2.checkpoint)
    _assert_same_state(sa["model"], sb["model"])
    for (ka, va), (_, vb) in zip(sa["optimizer"]["state"].items(), sb["optimizer"]["state"].items()):
        for name in va:
            assert torch.equal(va[name], vb[name]), (ka, name)
    assert (sa["epoch"], sa["batch_in_epoch"]) == (sb["epoch"], sb["batch_in_epoch"]) == (1, 1)
    # the logs agree row for row (the resumed log keeps the rows up to the checkpoint)
    la = [(r["step"], r["split"], r["total"]) for r in read_log(out_a / "log.csv")]
    lb = [(r["step"], r["split"], r["total"]) for r in read_log(tmp_path / "log.csv")]
    assert la == lb and len(la) == 4 + 2


def test_fresh_start_is_deterministic_and_seed_matters(straight_run, tmp_path):
    out_a, _ = straight_run
    cfg = tiny_config(steps=1, val_every=None)
    r1 = train("airpose", config=cfg, out_dir=tmp_path / "a", **FAKES)
    la = [r["total"] for r in read_log(out_a / "log.csv") if r["split"] == "train"][:1]
    assert la == [r["total"] for r in read_log(tmp_path / "a" / "log.csv")]  # = the straight run's step 1
    # resume=False on an existing run starts afresh, and lands on the same weights
    r2 = train("airpose", config=cfg, out_dir=tmp_path / "a", resume=False, **FAKES)
    _assert_same_state(_weights(r1.checkpoint), _weights(r2.checkpoint))
    r3 = train("airpose", config=cfg.replace(seed=8), out_dir=tmp_path / "c", **FAKES)
    assert not torch.equal(_weights(r1.checkpoint)["regressor.fc1.weight"],
                           _weights(r3.checkpoint)["regressor.fc1.weight"])


def test_ddp_two_processes_match_single_process(tmp_path, open_model_files):
    """2 CPU processes (gloo), 2 samples each, equal the single process with the global batch of 4.

    Dropout off and BatchNorm frozen: both are per process by design (see train.loop)."""
    cfg = tiny_config(steps=2, val_every=None, keep_checkpoints=0, data={"n": 8, "genders": 1},
                      model={"num_iterations": 2, "dropout": 0.0}, device="cpu")  # gloo, also beside a GPU
    single = train("airpose", config=cfg, out_dir=tmp_path / "single", **FAKES)
    ddp = train("airpose", config=cfg.replace(world_size=2), out_dir=tmp_path / "ddp", **FAKES)
    assert ddp.step == 2 and ddp.config["world_size"] == 2
    state = load_checkpoint(ddp.checkpoint)
    assert state["world_size"] == 2 and len(state["rng"]) == 2
    a, b = _weights(single.checkpoint), state["model"]
    # Equal up to summation order (measured max difference ~1e-6). Adam normalises each update
    # to ~lr, so a coordinate whose gradient is ~0 may in principle differ by up to 2 lr per step;
    # allow that for a tiny fraction of coordinates only.
    diff = torch.cat([(a[k].double() - b[k].double()).abs().reshape(-1) for k in a])
    assert (diff <= 2e-6).double().mean() > 0.9999 and diff.max() <= 2 * cfg.steps * cfg.lr
    from airpose_lib.train import default_model_factory, seed_everything

    seed_everything(cfg.seed)
    init = default_model_factory(cfg).state_dict()
    step = (a["regressor.fc2.weight"] - init["regressor.fc2.weight"]).abs().max()
    assert 1e-5 < step < 3 * cfg.lr  # both runs moved by Adam steps of ~lr, far above the tolerance
    la = [float(r["total"]) for r in read_log(tmp_path / "single" / "log.csv")]
    lb = [float(r["total"]) for r in read_log(tmp_path / "ddp" / "log.csv")]
    np.testing.assert_allclose(la, lb, rtol=1e-5)  # logged losses are the all-reduced global mean


def test_checkpoint_contents_and_outputs(straight_run):
    out, res = straight_run
    files = sorted(p.name for p in (out / "checkpoints").iterdir())
    assert files == ["last.pt", "step_00000002.pt", "step_00000004.pt"]  # no temp files left
    state = load_checkpoint(res.checkpoint)
    assert {"model", "optimizer", "rng", "step", "epoch", "batch_in_epoch", "config", "kit_version",
            "world_size"} <= set(state)
    assert state["step"] == 4 and state["config"]["variant"] == "airpose" and len(state["rng"]) == 1
    group = state["optimizer"]["param_groups"][0]
    assert group["lr"] == 5e-5 and group["amsgrad"] is True  # paper: Adam (AMSGrad), lr 5e-5
    assert isinstance(state["kit_version"], str)
    from airpose_lib.data.still.scene import SceneConfig
    from airpose_lib.model import read_network

    net = read_network(state)  # the record alone rebuilds the network and forms its input
    assert (net.variant, net.backbone, net.model, net.input_size) == ("airpose", state["config"]["backbone"],
                                                                      state["config"]["model"], S)
    assert (net.normalisation, net.camera_rule) == ("imagenet", "virtual_crop")
    np.testing.assert_array_equal(net.camera_K, SceneConfig().K)
    result = json.loads((out / "result.json").read_text())
    assert result["step"] == 4 and result["val_losses"]["total"] > 0
    from airpose_lib.eval.reference import git_commit

    assert result["git"] == git_commit()  # the code that trained it (this checkout, or None outside git)
    assert json.loads((out / "config.json").read_text())["batch_size"] == 4
    rows = read_log(out / "log.csv")
    assert [r["step"] for r in rows if r["split"] == "val"] == ["2", "4"]
    assert {"total", "j2d", "j3d", "phi", "tau", "theta", "beta", "V"} <= set(rows[0])
    try:
        import torch.utils.tensorboard  # noqa: F401

        has_tb = True
    except Exception:  # noqa: BLE001
        has_tb = False
    assert res.tensorboard == has_tb


def test_resume_with_other_settings_refused(straight_run):
    out, _ = straight_run
    with pytest.raises(ValueError, match="lr"):
        train("airpose", config=tiny_config(lr=1e-3, steps=8), out_dir=out, **FAKES)


def test_every_variant_trains_one_step(tmp_path, open_model_files):
    for variant, frozen in (("baseline", False), ("multiview", True), ("fullcam", True)):
        cfg = tiny_config(variant=variant, steps=1, val_every=None, freeze_backbone=frozen)
        res = train(variant, config=cfg, out_dir=tmp_path / variant, **FAKES)
        assert res.step == 1 and np.isfinite(res.train_loss)
        state = load_checkpoint(res.checkpoint)
        assert state["config"]["variant"] == variant
        n_opt = len(state["optimizer"]["state"])
        assert (n_opt < 20) == frozen  # frozen: only the regressor's few tensors are optimised


# -- data order and seeding -----------------------------------------------------------------------
def test_sampler_shares_and_resume_position():
    full = list(ResumableBatchSampler(10, 4, seed=3, epoch=1))
    assert len(full) == 2 and all(len(b) == 4 for b in full)
    perm = epoch_permutation(10, 3, 1).tolist()
    assert [i for b in full for i, _ in b] == perm[:8]
    assert epoch_permutation(10, 3, 2).tolist() != perm
    # two processes: contiguous halves of every global batch, same sample seeds
    r0 = list(ResumableBatchSampler(10, 4, 3, 1, rank=0, world_size=2))
    r1 = list(ResumableBatchSampler(10, 4, 3, 1, rank=1, world_size=2))
    for b, x, y in zip(full, r0, r1):
        assert x + y == b
    assert list(ResumableBatchSampler(10, 4, 3, 1, start_batch=1)) == full[1:]
    assert len(list(ResumableBatchSampler(10, 4, 3, 1, drop_last=False))) == 3
    assert sample_seed(3, 1, 5) == sample_seed(3, 1, 5) != sample_seed(3, 2, 5)
    # any global batch over any number of processes: slices of ceil/floor sizes (30 over 4: 8, 8, 7, 7)
    shares = [list(ResumableBatchSampler(30, 30, 3, 1, rank=r, world_size=4)) for r in range(4)]
    assert [len(s[0]) for s in shares] == [8, 8, 7, 7]
    assert sum((s[0] for s in shares), []) == list(ResumableBatchSampler(30, 30, 3, 1))[0]
    with pytest.raises(ValueError, match="smaller than world_size"):
        ResumableBatchSampler(10, 3, 0, 0, world_size=4)


def test_seeded_dataset_is_reproducible_and_restores_rngs():
    class Rand(Dataset):
        def __len__(self):
            return 4

        def __getitem__(self, i):
            return torch.rand(2), np.random.rand(), random.random()

    ds = SeededDataset(Rand())
    torch.manual_seed(0)
    np.random.seed(0)
    random.seed(0)
    expected = (torch.rand(1), np.random.rand(), random.random())
    torch.manual_seed(0)
    np.random.seed(0)
    random.seed(0)
    a = ds[(1, 99)]
    b = ds[(2, 99)]
    assert torch.equal(a[0], b[0]) and a[1] == b[1] and a[2] == b[2]  # same seed, same draws
    assert not torch.equal(a[0], ds[(1, 98)][0])
    got = (torch.rand(1), np.random.rand(), random.random())
    assert torch.equal(got[0], expected[0]) and got[1:] == expected[1:]  # outer streams untouched


# -- configuration --------------------------------------------------------------------------------
def test_load_train_config_from_profile(tmp_path):
    prof = tmp_path / "p.yaml"
    prof.write_text("train:\n  steps: 11\n  batch_size: 6\n  lr: 1.0e-4\n"
                    "  variants:\n    baseline: {lr: 2.0e-4}\n")
    cfg = kit_configs(prof).train.config("airpose")
    assert (cfg.steps, cfg.batch_size, cfg.lr, cfg.amsgrad, cfg.seed) == (11, 6, 1e-4, True, 123)
    cfg = kit_configs(prof).train.config("baseline", seed=5, steps=3)
    assert (cfg.variant, cfg.lr, cfg.seed, cfg.steps) == ("baseline", 2e-4, 5, 3)
    assert load_train_config(None, "fullcam").lr == 5e-5
    prof.write_text("train:\n  stepz: 11\n")
    with pytest.raises(ValueError, match="stepz"):
        kit_configs(prof).train.config("airpose")
    TrainConfig(batch_size=5, world_size=2)  # an uneven split is fine
    with pytest.raises(ValueError, match="at least world_size"):
        TrainConfig(batch_size=2, world_size=3)
    with pytest.raises(ValueError, match="precision"):
        TrainConfig(precision="fp8")


@pytest.mark.parametrize("profile", ["smoke", "cpu", "paper"])
def test_kit_profiles_have_train_sections(profile):
    for variant in ("baseline", "multiview", "fullcam", "airpose"):
        cfg = kit_configs(profile).train.config(variant)
        assert cfg.steps > 0 and cfg.batch_size > 0
    paper = kit_configs("paper").train.config("airpose")
    if profile == "paper":
        assert (paper.lr, paper.batch_size, paper.seed, paper.backbone) == (5e-5, 30, 123, "resnet50")
        assert paper.grad_clip == 1.0 == kit_configs("cpu").train.config("multiview").grad_clip  # the cpu profile's evidence


def test_learning_rate_schedules_by_hand():
    import math

    from airpose_lib.train.config import TrainConfig

    const = TrainConfig(steps=10, lr=0.3)
    assert [const.lr_at(s) for s in (0, 5, 9)] == [0.3, 0.3, 0.3]
    cos = TrainConfig(steps=10, lr=1.0, lr_schedule="cosine", warmup_steps=2)
    expected = [0.5, 1.0] + [0.5 * (1 + math.cos(math.pi * (s - 2) / 8)) for s in range(2, 10)]
    assert [cos.lr_at(s) for s in range(10)] == pytest.approx(expected)
    assert cos.lr_at(6) == pytest.approx(0.5) and cos.lr_at(10) == pytest.approx(0.0)
    with pytest.raises(ValueError, match="lr_schedule"):
        TrainConfig(lr_schedule="step")


def test_a_resumed_cosine_run_follows_the_schedule(tmp_path, open_model_files):
    """The engine sets each step's rate from lr_at(step): the log shows it, and a run stopped
    half-way and resumed ends with the straight run's weights."""
    cfg = tiny_config(lr=1e-3, lr_schedule="cosine", warmup_steps=1)
    straight = train("airpose", config=cfg, out_dir=tmp_path / "a", **FAKES)
    logged = [float(r["lr"]) for r in read_log(tmp_path / "a" / "log.csv") if r["split"] == "train"]
    # the row of step s (1-based) is written after its update, whose rate was lr_at(s - 1)
    assert logged == pytest.approx([cfg.lr_at(s - 1) for s in range(1, cfg.steps + 1)])
    train("airpose", config=cfg, out_dir=tmp_path / "b", **FAKES, stop_at=2)
    resumed = train("airpose", config=cfg, out_dir=tmp_path / "b", **FAKES)
    _assert_same_state(_weights(straight.checkpoint), _weights(resumed.checkpoint))


def test_a_cosine_run_is_not_extended_by_resuming(tmp_path, open_model_files):
    """More steps on a cosine run would restart its decay midway (a straight run of the new
    length never sees a rate of 0 there): the folder is stale. A constant rate extends."""
    from airpose_lib.engine import StaleRunError

    cosine = tiny_config(lr=1e-3, lr_schedule="cosine", warmup_steps=1, steps=2)
    train("airpose", config=cosine, out_dir=tmp_path / "cos", **FAKES)
    with pytest.raises(StaleRunError, match="steps") as stale:
        train("airpose", config=cosine.replace(steps=4), out_dir=tmp_path / "cos", **FAKES)
    assert stale.value.fields == ["steps"]
    constant = tiny_config(lr=1e-3, steps=2)
    train("airpose", config=constant, out_dir=tmp_path / "const", **FAKES)
    longer = train("airpose", config=constant.replace(steps=4), out_dir=tmp_path / "const", **FAKES)
    straight = train("airpose", config=constant.replace(steps=4), out_dir=tmp_path / "straight", **FAKES)
    assert longer.step == 4
    _assert_same_state(_weights(straight.checkpoint), _weights(longer.checkpoint))
