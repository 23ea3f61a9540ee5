"""The shipped networks: a regressor file joined with its backbone is the network it came from,
the manifest refuses damaged or foreign files in one line, and the committed set is whole."""
from __future__ import annotations

import shutil
from pathlib import Path

import pytest
import torch
import yaml

from airpose_lib.engine.checkpoint import write_checkpoint
from airpose_lib.errors import DamagedFileError
from airpose_lib.model import build_model
from airpose_lib.model.record import network_record
from airpose_lib.paths import RunFolders
from airpose_lib.reproduce.configs import kit_configs
from airpose_lib.train.evaluate import load_network
from airpose_lib.zoo import (
    export_regressor,
    kit_checkpoint,
    read_manifest,
    sha256_file,
    verified,
    write_manifest,
    zoo_dir,
)

ROOT = Path(__file__).resolve().parents[1]


def _backbone_file(model, path: Path) -> Path:
    """A backbone file as ``train.pretrain.export_backbone`` writes one (fp16 weights, metadata)."""
    import json

    state = {k[len("backbone."):]: v.half() if v.is_floating_point() else v
             for k, v in model.state_dict().items() if k.startswith("backbone.")}
    torch.save({"state_dict": state, "meta_json": json.dumps({"backbone": "resnet18"})}, path)
    return path


@pytest.fixture()
def exported(tmp_path, monkeypatch):
    monkeypatch.setenv("AIRPOSE_CACHE", str(tmp_path / "cache"))
    torch.manual_seed(0)
    model = build_model("airpose", backbone="resnet18", dropout=0.0).eval()
    backbone = _backbone_file(model, tmp_path / "backbone.pt")
    # the network as it trains on the backbone file: its backbone is the file's (fp16-rounded) weights
    model.backbone.load_state_dict({k: v.float() for k, v in torch.load(backbone)["state_dict"].items()})
    K = [[200.0, 0, 64], [0, 200.0, 64], [0, 0, 1]]
    ckpt = write_checkpoint(tmp_path / "run.pt", {"model": model.state_dict(), "step": 7,
                                                  "config": {"variant": "airpose", "data": {"root": "/x"},
                                                             "pretrained": "/machine/backbone.pt"},
                                                  "network": network_record("airpose", "resnet18",
                                                                            {"dropout": 0.0}, 128, K)})
    shipped = export_regressor(ckpt, backbone, tmp_path / "zoo" / "airpose.pt")
    return model, backbone, shipped, tmp_path


def test_a_shipped_regressor_rebuilds_the_network_within_float16_rounding(exported):
    model, backbone, shipped, _ = exported
    blob = torch.load(shipped, weights_only=True)
    assert all(v.dtype == torch.float16 for v in blob["regressor"].values() if v.is_floating_point())
    assert not any(k.startswith("backbone.") for k in blob["regressor"])  # the backbone stays one file
    assert blob["config"]["pretrained"] == "shipped" and "root" not in blob["config"]["data"]  # no machine paths
    rebuilt, record, state = load_network(kit_checkpoint(shipped, backbone))
    assert record.variant == "airpose" and record.input_size == 128 and state["step"] == 7
    x, P = torch.randn(2, 2, 3, 128, 128), torch.randn(2, 2, 3) * 0.1
    with torch.no_grad():
        a, b = model(x, P), rebuilt(x, P)
    for k in ("tau", "beta"):
        scale = float(a[k].abs().max())
        assert torch.allclose(a[k], b[k], atol=2e-3 * max(scale, 1.0)), k  # float16 weights, float32 run
    assert kit_checkpoint(shipped, backbone) == kit_checkpoint(shipped, backbone)  # made once, then reused


def test_a_regressor_on_another_backbone_is_refused(exported):
    model, backbone, shipped, tmp_path = exported
    other = tmp_path / "other.pt"
    torch.manual_seed(1)
    _backbone_file(build_model("airpose", backbone="resnet18"), other)
    with pytest.raises(DamagedFileError, match="made on the backbone"):
        kit_checkpoint(shipped, other)
    with pytest.raises(ValueError, match="differs from"):  # a network that trained its backbone
        export_regressor(tmp_path / "run.pt", other, tmp_path / "x.pt")


def test_a_shipped_file_and_its_manifest_name_no_folder_of_this_machine(exported):
    """A fine-tuned network's record (its prior, recording, base network) and the manifest are
    committed: their paths are written portable, and the file still loads."""
    model, backbone, _, tmp_path = exported
    cache = tmp_path / "cache"
    state = torch.load(tmp_path / "run.pt", weights_only=True)
    state["finetune"] = {"sequence": str(cache / "data" / "sequences_cpu" / "person1"),
                         "base_checkpoint": "/work/runs6/train/cpu/airpose/seed123/checkpoints/last.pt",
                         "config": {"prior_path": str(cache / "prior" / "cpu" / "vposer.pt"), "lr": 1e-4}}
    tuned = export_regressor(write_checkpoint(tmp_path / "tuned.pt", state), backbone, tmp_path / "zoo" / "tuned.pt")
    blob = torch.load(tuned, weights_only=True)
    assert blob["finetune"] == {"sequence": "<cache>/data/sequences_cpu/person1",
                                "base_checkpoint": "<abs>/checkpoints/last.pt",
                                "config": {"prior_path": "<cache>/prior/cpu/vposer.pt", "lr": 1e-4}}
    assert load_network(kit_checkpoint(tuned, backbone))[2]["step"] == 7
    write_manifest(tuned.parent, [{"name": "tuned", "file": "tuned.pt", "made_by": f"recordings of {cache}/x"}],
                   {"profile": "x", "rebuild": "airpose zoo build --profile /tmp/p/x.yaml"})
    text = (tuned.parent / "manifest.yaml").read_text()
    assert str(tmp_path) not in text and "/tmp/" not in text
    assert read_manifest(tuned.parent)["tuned"]["made_by"] == "recordings of <cache>/x"


def test_the_manifest_refuses_a_damaged_or_foreign_file_in_one_line(exported):
    _, backbone, shipped, tmp_path = exported
    folder = shipped.parent
    entry = {"name": "airpose", "file": "airpose.pt", "bytes": shipped.stat().st_size, "sha256": sha256_file(shipped),
             "kind": "regressor", "seed": 123}
    write_manifest(folder, [entry], {"profile": "x", "rebuild": "airpose zoo build --profile x"})
    assert verified(folder, "airpose") == shipped
    data = shipped.read_bytes()
    shipped.write_bytes(data[:-10] + b"0123456789")  # same size, other bytes
    with pytest.raises(DamagedFileError, match="SHA-256") as err:
        verified(folder, "airpose")
    assert "\n" not in str(err.value) and "airpose.pt" in str(err.value) and "git checkout" in str(err.value)
    shipped.write_text("version https://git-lfs.github.com/spec/v1\n")  # a Git LFS pointer
    with pytest.raises(DamagedFileError, match="bytes"):
        verified(folder, "airpose")
    shipped.unlink()
    with pytest.raises(DamagedFileError, match="restore it"):
        verified(folder, "airpose")
    with pytest.raises(DamagedFileError, match="lists"):
        verified(folder, "prior")
    (tmp_path / "foreign.pt").write_bytes(b"not a torch file")
    with pytest.raises(DamagedFileError):
        kit_checkpoint(tmp_path / "foreign.pt", backbone)


def test_the_committed_cpu_set_is_whole_and_intact():
    folder = zoo_dir(RunFolders.of("cpu"))
    if not (folder / "manifest.yaml").is_file():
        pytest.skip("no shipped cpu networks in this checkout")
    entries = read_manifest(folder)
    expected = {"backbone", "baseline", "multiview", "fullcam", "airpose", "baseline_tuned", "airpose_tuned",
                "baseline_tuned_field", "airpose_tuned_field", "prior"}
    assert set(entries) == expected
    for name in entries:
        verified(folder, name)
    added = sum(int(e["bytes"]) for n, e in entries.items() if n != "backbone")
    assert added <= 40e6, f"the shipped networks add {added / 1e6:.1f} MB"
    about = yaml.safe_load((folder / "manifest.yaml").read_text())
    assert about["rebuild"] == "airpose zoo build --profile cpu"


def test_the_demo_profile_runs_the_cpu_networks_on_a_test_split_of_its_own():
    from airpose_lib.experiments.shipped import shipped_from

    demo, cpu = kit_configs("demo").still, kit_configs("cpu").still
    assert shipped_from(kit_configs("demo").networks) == "cpu" and shipped_from(kit_configs("cpu").networks) is None
    assert demo.seed != cpu.seed and demo.fingerprint() != cpu.fingerprint()
    assert demo.num_test_shards * demo.shard_size >= 1000  # two-view test samples


def test_a_copied_set_is_found_through_the_profile_folder(exported, tmp_path):
    """``networks: {shipped: cpu, folder: ...}`` points a profile at a set outside the checkout."""
    from airpose_lib.experiments.shipped import shipped_networks

    _, _, shipped, _ = exported
    folder = tmp_path / "set"
    shutil.copytree(shipped.parent, folder)
    entry = {"name": "airpose", "file": "airpose.pt", "bytes": shipped.stat().st_size,
             "sha256": sha256_file(shipped), "kind": "regressor", "seed": 5}
    write_manifest(folder, [entry], {"profile": "x"})
    profile = tmp_path / "mine.yaml"
    profile.write_text(yaml.safe_dump({"inherits": "smoke", "networks": {"shipped": "smoke", "folder": str(folder)}}))
    nets = shipped_networks(kit_configs(str(profile)).networks)
    assert nets.seed == 5 and nets.folder == folder
