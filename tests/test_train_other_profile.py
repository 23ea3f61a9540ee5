"""`pretrained: profile:<name>`: a training on one profile's data with another profile's backbone."""
from __future__ import annotations

import pytest
import yaml

from airpose_lib.errors import ConfigError
from airpose_lib.paths import RunFolders
from airpose_lib.reproduce.configs import kit_configs

SMALL = {"num_samples": 4, "shard_size": 2, "crop_size": 32, "seed": 0}
SECTION = {"steps": 1, "batch_size": 2, "backbone": "resnet18", "lr": 1e-3, "seed": 0, "checkpoint_every": 1,
           "val_every": None, "log_every": 1, "num_workers": 0, "model": {"n_heading_bins": 12}}


def test_the_name_is_read_and_checked():
    from airpose_lib.train.pretrain import other_profile

    assert other_profile("profile:cpu") == "cpu" and other_profile("profile:/x/p.yaml") == "/x/p.yaml"
    assert other_profile("profile") is None and other_profile(None) is None and other_profile("/b.pt") is None
    with pytest.raises(ConfigError, match="names no profile"):
        other_profile("profile:")


def test_another_profiles_backbone_is_found_without_making_its_data(tmp_path, monkeypatch):
    import airpose_lib.train.pretrain as pretrain
    from airpose_lib.data.still.generate import GenerationConfig
    from airpose_lib.train.pretrain import other_profile_backbone, own_backbone_key, pretrain_stages, stage_keys

    monkeypatch.setenv("AIRPOSE_CACHE", str(tmp_path / "cache"))
    base = tmp_path / "base.yaml"
    base.write_text(yaml.safe_dump({"data": {"still": SMALL}, "pretrain": {**SECTION, "continue_from": {"steps": 2}}}))
    fp = GenerationConfig(**SMALL).fingerprint()
    key = own_backbone_key(kit_configs(str(base)).pretrain)
    assert key == stage_keys(pretrain_stages(kit_configs(str(base)).pretrain), fp)[-1]  # the key its own data's training has
    monkeypatch.setattr(pretrain, "profile_backbone", lambda profile, progress=False: tmp_path / "made.pt")
    assert other_profile_backbone(kit_configs(str(base)).pretrain) == tmp_path / "made.pt"  # not at hand: made (data first)
    cached = tmp_path / "cache" / "backbones" / f"{key}.pt"
    cached.write_bytes(b"weights")
    monkeypatch.setattr(pretrain, "profile_backbone", lambda *a, **k: pytest.fail("made the data"))
    assert other_profile_backbone(kit_configs(str(base)).pretrain) == cached
    assert not RunFolders.of(str(base)).still.exists()


def test_the_paper_layout_profile_trains_on_cpus_backbone():

    cfg = kit_configs("cpu_paper_layout").train.config("airpose", 123)
    cpu = kit_configs("cpu").train.config("airpose", 123)
    assert cfg.pretrained == "profile:cpu" and cpu.pretrained == "profile"
    assert cfg.replace(pretrained="profile") == cpu  # no profile name in the config: equal otherwise


def test_a_finished_run_on_another_profiles_backbone_is_reused_only_with_that_backbone(tmp_path):
    import json

    from airpose_lib.train.ablation import _finished_run
    from airpose_lib.train.pretrain import own_backbone_key

    layout = kit_configs("cpu_paper_layout").train_inputs()
    assert set(layout.others) == {"cpu"}  # read at the entry, with the profile that names it
    cfg = layout.section.config("airpose", 7).to_dict()
    backbone = tmp_path / f"{own_backbone_key(layout.others['cpu'])}.pt"
    other = tmp_path / "0123456789abcdef.pt"
    ckpt = tmp_path / "last.pt"
    for f in (backbone, other, ckpt):
        f.write_bytes(b"x")
    result = {"out_dir": str(tmp_path), "step": cfg["steps"], "checkpoint": str(ckpt), "train_loss": 1.0,
              "val_losses": None, "tensorboard": False, "stopped_early": False,
              "config": {**cfg, "data": {"root": str(tmp_path)}, "progress": False, "pretrained": str(backbone)}}
    (tmp_path / "result.json").write_text(json.dumps(result))
    assert _finished_run(tmp_path, layout, "airpose", 7) is not None
    result["config"]["pretrained"] = str(other)
    (tmp_path / "result.json").write_text(json.dumps(result))
    assert _finished_run(tmp_path, layout, "airpose", 7) is None
