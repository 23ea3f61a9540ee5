"""`airpose backbone import`: a torchvision ResNet state dict becomes a kit backbone file
that trainings start from (`train: pretrained: FILE`); checked on random weights with torchvision's
key names (the kit's ResNet uses them: tests/test_model_backbone.py)."""
from __future__ import annotations

import json

import pytest
import torch

from airpose_lib import cli
from airpose_lib.model import resnet18, resnet50
from airpose_lib.train import TrainConfig, default_model_factory
from airpose_lib.train.features import load_backbone_file


def _torchvision_like(net: torch.nn.Module, seed: int = 0) -> dict:
    """Random values under a torchvision ResNet's keys, the classifier included (as saved from
    ``torchvision.models.resnet50().state_dict()``)."""
    g = torch.Generator().manual_seed(seed)
    sd = {k: torch.randn(v.shape, generator=g) if v.is_floating_point() else v.clone()
          for k, v in net.state_dict().items()}
    sd["fc.weight"] = torch.randn(1000, net.feature_dim, generator=g)
    sd["fc.bias"] = torch.randn(1000, generator=g)
    return sd


def test_import_a_resnet50_state_dict_and_train_from_it(tmp_path, capsys):
    sd = _torchvision_like(resnet50())
    torch.save(sd, tmp_path / "resnet50.pth")
    out = tmp_path / "imagenet.pt"
    assert cli.main(["backbone", "import", str(tmp_path / "resnet50.pth"), "--out", str(out)]) == 0
    assert f"--set pretrained={out}" in capsys.readouterr().out
    net, meta = load_backbone_file(out)
    assert meta["backbone"] == "resnet50" and json.loads(out.with_suffix(".json").read_text())["sha256"]
    got = net.state_dict()
    assert set(got) == set(sd) - {"fc.weight", "fc.bias"}
    assert all(torch.equal(got[k], sd[k]) for k in got)  # float32, bit for bit
    # a variant built with `pretrained: FILE` starts from exactly these weights
    model = default_model_factory(TrainConfig(variant="airpose", backbone="resnet50", pretrained=str(out)))
    assert torch.equal(model.backbone.layer4[2].conv3.weight, sd["layer4.2.conv3.weight"])


def test_import_refuses_another_architecture_in_one_line(tmp_path, capsys):
    torch.save({"state_dict": _torchvision_like(resnet18())}, tmp_path / "r18.pth")  # wrapped: unwrapped first
    code = cli.main(["backbone", "import", str(tmp_path / "r18.pth"), "--out", str(tmp_path / "x.pt")])
    err = capsys.readouterr().err.strip()
    assert code == 2 and err.startswith("airpose: error:") and "not a torchvision resnet50 state dict" in err
    assert "\n" not in err and not (tmp_path / "x.pt").exists()
    assert cli.main(["backbone", "import", str(tmp_path / "r18.pth"), "--backbone", "resnet18",
                     "--out", str(tmp_path / "y.pt")]) == 0
    with pytest.raises(SystemExit):
        cli.main(["backbone", "import"])
