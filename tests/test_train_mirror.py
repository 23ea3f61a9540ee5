"""The mirror augmentation from a profile: a pretraining stage's `data: {mirror: true}` reaches the
training dataset and the stage's key; the regressor task (cached features) refuses it."""
from __future__ import annotations

import numpy as np
import pytest
import yaml

from airpose_lib.errors import ConfigError, ProfileError
from airpose_lib.reproduce.configs import kit_configs

SECTION = {"steps": 1, "batch_size": 2, "backbone": "resnet18", "lr": 1e-3, "seed": 0, "checkpoint_every": 1,
           "val_every": None, "log_every": 1, "num_workers": 0, "model": {"n_heading_bins": 12}}


def _profile(tmp_path, name, pretrain):
    path = tmp_path / f"{name}.yaml"
    path.write_text(yaml.safe_dump({"pretrain": pretrain}))
    return str(path)


def test_a_pretraining_stage_mirrors_when_its_data_says_so(tmp_path, monkeypatch):
    import airpose_lib.train.loop as loop
    import airpose_lib.train.pretrain as pretrain
    from airpose_lib.train.pretrain import ensure_backbone, pretrain_stages, stage_keys

    plain = _profile(tmp_path, "plain", {**SECTION, "continue_from": {"steps": 2, "data": {}}})
    mirrored = _profile(tmp_path, "mirrored", {**SECTION, "data": {"mirror": True},
                                               "continue_from": {"steps": 2, "data": {}}})
    off = _profile(tmp_path, "off", {**SECTION, "data": {"mirror": False}, "continue_from": {"steps": 2, "data": {}}})
    stages = pretrain_stages(kit_configs(mirrored).pretrain)
    assert [c.data for c in stages] == [{}, {"mirror": True}]
    keys, plain_keys = stage_keys(stages, "fp"), stage_keys(pretrain_stages(kit_configs(plain).pretrain), "fp")
    assert keys[0] == plain_keys[0] and keys[1] != plain_keys[1]  # only the mirrored stage is another backbone
    assert stage_keys(pretrain_stages(kit_configs(off).pretrain), "fp") == plain_keys  # off: the keys of before the option

    # the stage's training sees the option (ensure_backbone -> its dataset -> StillFrameDataset(mirror=True))
    monkeypatch.setenv("AIRPOSE_CACHE", str(tmp_path / "cache"))
    seen = {}

    class Stop(Exception):
        pass

    def fake_training(cfg, out, *a, **k):
        seen["data"] = dict(cfg.data)
        raise Stop

    monkeypatch.setattr(pretrain, "check_data_root", lambda cfg: None)
    monkeypatch.setattr(pretrain, "start_training", fake_training)
    with pytest.raises(Stop):
        ensure_backbone(kit_configs(mirrored).pretrain, tmp_path / "data", "fp", out_root=tmp_path / "runs")
    assert seen["data"] == {"root": str(tmp_path / "data")}  # its first stage is trained first, unmirrored
    one = _profile(tmp_path, "one", {**SECTION, "data": {"mirror": True}})
    with pytest.raises(Stop):
        ensure_backbone(kit_configs(one).pretrain, tmp_path / "data", "fp", out_root=tmp_path / "runs")
    assert seen["data"] == {"root": str(tmp_path / "data"), "mirror": True}
    made = {}
    monkeypatch.setattr(loop, "StillFrameDataset", lambda root, split, **kw: made.setdefault(split, kw))
    cfg = pretrain_stages(kit_configs(one).pretrain)[-1].replace(data=seen["data"])
    loop.default_dataset_factory(cfg, "train")
    assert made["train"] == {"mirror": True}


def test_unknown_pretraining_data_options_and_a_mirrored_regressor_are_refused(tmp_path):
    from airpose_lib.train.features import FeatureDataset
    from airpose_lib.train.pretrain import pretrain_stages

    bad = _profile(tmp_path, "bad", {**SECTION, "data": {"flip": True}})
    with pytest.raises(ProfileError, match=r"takes only `still:`.*and mirror, not \['flip'\]"):
        pretrain_stages(kit_configs(bad).pretrain)
    with pytest.raises(ConfigError, match="data.mirror needs the crops"):
        FeatureDataset(tmp_path, "train", np.zeros((1, 2, 4)), mirror=True)
