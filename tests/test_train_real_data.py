"""End to end on a tiny generated still-frame dataset (airpose_lib.data): the data's ground truth
matches the losses' body convention, `airpose train` trains on it and `airpose eval` evaluates.

Slow (renders a few samples first): run with ``-m slow``.
"""

from __future__ import annotations

import pandas as pd
import pytest
import torch

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def tiny_root(module_tmp, open_model_files):
    from airpose_lib.data.still.generate import GenerationConfig, generate_still_dataset

    root = module_tmp("still")
    cfg = GenerationConfig(num_samples=8, shard_size=4, crop_size=32, seed=0)
    manifest = generate_still_dataset(cfg, root, workers=1, progress=False, record=False)
    assert manifest["status"] == "complete"
    return root


def test_ground_truth_matches_loss_convention(tiny_root):
    """The dataset's j3d_cam / j2d are phi J0(theta, beta) + tau of the gendered model, projected
    with K: a perfect prediction has zero supervised terms (up to float32 rounding)."""
    from airpose_lib.body import load_body_model
    from airpose_lib.body.forward import BodyForward
    from airpose_lib.body.genders import GENDER_NAMES
    from airpose_lib.data.still.dataset import StillFrameDataset
    from airpose_lib.geometry import axis_angle_to_matrix, project_points

    ds = StillFrameDataset(tiny_root, "all", augment=False)
    for i in range(len(ds)):
        s = ds[i]
        body = BodyForward(load_body_model("open", GENDER_NAMES[int(s["gender"])], dtype=torch.float64))
        j, _ = body(axis_angle_to_matrix(s["theta"].double()), s["beta"].double(), s["phi"].double(),
                    s["tau"].double(), vertices=False)
        torch.testing.assert_close(j, s["j3d_cam"].double(), atol=2e-5, rtol=0)
        uv = project_points(j, s["K"].double())
        torch.testing.assert_close(uv, s["j2d"].double(), atol=5e-3, rtol=0)


def test_cli_train_and_eval_on_generated_data(tiny_root, tmp_path, capsys):
    from airpose_lib import cli
    from airpose_lib.train import load_checkpoint, read_log

    out = tmp_path / "run"
    argv = ["train", "--variant", "airpose", "--profile", "smoke", "--steps", "2", "--batch-size", "2",
            "--out", str(out), "--set", f"data.root={tiny_root}", "backbone=resnet18", "checkpoint_every=1",
            "val_every=2", "val_batches=1", "progress=false", "loss.vertex_subsample=300"]
    assert cli.main(argv) == 0
    state = load_checkpoint(out / "checkpoints" / "last.pt")
    assert state["step"] == 2 and state["config"]["data"]["root"] == str(tiny_root)
    assert state["config"]["profile"] == "smoke"
    rows = read_log(out / "log.csv")
    assert [r["split"] for r in rows].count("val") == 1
    # resuming a finished run is a no-op; asking for more steps continues
    assert cli.main(argv[:6] + ["3"] + argv[7:]) == 0
    assert load_checkpoint(out / "checkpoints" / "last.pt")["step"] == 3

    assert cli.main(["eval", "--checkpoint", str(out / "checkpoints" / "last.pt"), "--split", "test",
                     "--out", str(tmp_path / "eval")]) == 0
    printed = capsys.readouterr().out
    assert "MPE [m]" in printed and "MPJPE [m]" in printed
    per_view = pd.read_csv(tmp_path / "eval" / "per_view.csv")
    assert len(per_view) == 4 * 2 and per_view["mpe_m"].notna().all()  # 4 test samples x 2 views
    assert (per_view["method"] == "airpose").all()
    rel = pd.read_csv(tmp_path / "eval" / "relative_camera.csv")
    assert len(rel) == 4
