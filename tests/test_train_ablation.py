"""The ablation runner (airpose_lib.train.ablation): parallel single-thread training gives the
same checkpoints as sequential training, and finished runs are reused."""
from __future__ import annotations

import dataclasses

import pytest
import torch
import yaml

from airpose_lib.reproduce.configs import kit_configs


@pytest.fixture(scope="module")
def tiny_profile(module_tmp, open_model_files):
    from airpose_lib.data.still.generate import GenerationConfig, generate_still_dataset

    root = module_tmp("tiny_still")
    generate_still_dataset(GenerationConfig(num_samples=16, shard_size=4, crop_size=32, seed=0), root,
                           workers=1, progress=False, record=False)
    profile = module_tmp("profile") / "tiny.yaml"
    profile.write_text(yaml.safe_dump({"description": "test", "train": {
        "steps": 3, "batch_size": 2, "backbone": "resnet18", "seed": 1, "checkpoint_every": 3,
        "val_every": 100, "log_every": 1, "num_workers": 0, "data": {"root": str(root)},
        "loss": {"vertex_subsample": 200}}}))
    return kit_configs(profile).train_inputs()


def test_parallel_training_equals_sequential_and_is_reused(tiny_profile, tmp_path):
    from airpose_lib.engine.checkpoint import load_checkpoint
    from airpose_lib.train.ablation import _train_parallel, trained_checkpoint

    variants, seeds = ["baseline", "airpose"], [1]
    _train_parallel(tiny_profile, variants, seeds, tmp_path / "parallel", workers=2)
    threads = torch.get_num_threads()
    torch.set_num_threads(1)  # the workers' setting: same kernels, same bits
    try:
        for v in variants:
            seq = load_checkpoint(trained_checkpoint(tiny_profile, v, 1, tmp_path / "sequential"))["model"]
            par_path = trained_checkpoint(tiny_profile, v, 1, tmp_path / "parallel")  # finished: reused
            par = load_checkpoint(par_path)["model"]
            assert seq.keys() == par.keys()
            for k in seq:
                assert torch.equal(seq[k], par[k]), (v, k)
    finally:
        torch.set_num_threads(threads)
    mtime = par_path.stat().st_mtime_ns
    _train_parallel(tiny_profile, variants, seeds, tmp_path / "parallel", workers=2)  # nothing to do
    assert par_path.stat().st_mtime_ns == mtime


def test_a_run_left_by_other_settings_is_trained_afresh(tiny_profile, tmp_path, capsys):
    """E.g. a new committed backbone: the old run cannot be resumed, and must not stop a reproduction."""
    from airpose_lib.engine.checkpoint import load_checkpoint
    from airpose_lib.train.ablation import trained_checkpoint

    first = load_checkpoint(trained_checkpoint(tiny_profile, "baseline", 1, tmp_path))
    lr = first["config"]["lr"] * 2
    changed = dataclasses.replace(tiny_profile, section=dataclasses.replace(
        tiny_profile.section, values={**tiny_profile.section.values, "lr": lr}))
    again = load_checkpoint(trained_checkpoint(changed, "baseline", 1, tmp_path))
    assert again["config"]["lr"] == lr and again["step"] == 3
    assert "trained with other lr than the profile asks for now; training it afresh" in capsys.readouterr().out
