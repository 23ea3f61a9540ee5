"""Table I from official-format assets (airpose_lib.train.official) on fixtures the kit writes."""
from __future__ import annotations

import numpy as np
import pytest
import torch


@pytest.fixture(scope="module")
def official_assets(module_tmp, open_model_files):
    from official_fixtures import write_official_synthetic_fixture

    from airpose_lib.model import build_model, write_official_checkpoint
    from airpose_lib.train.official import OFFICIAL_CHECKPOINT_FOLDERS

    data = module_tmp("official_synthetic")
    write_official_synthetic_fixture(data, n_subjects=2, n_positions=2, num_test_subjects=1)
    ckpts = module_tmp("official_checkpoints")
    models = {}
    for variant, folder in OFFICIAL_CHECKPOINT_FOLDERS.items():
        torch.manual_seed(0)
        models[variant] = build_model(variant, backbone="resnet18").eval()
        write_official_checkpoint(models[variant], ckpts / folder / "checkpoints" / "epoch=1.ckpt")
    return data, ckpts, models


def test_official_ablation_evaluates_each_official_checkpoint_like_the_kit(official_assets):
    from airpose_lib.data.official.synthetic import OfficialSyntheticDataset
    from airpose_lib.eval.ablation import ablation_table
    from airpose_lib.train.evaluate import evaluate
    from airpose_lib.train.official import official_ablation

    data, ckpts, models = official_assets
    runs = official_ablation(ckpts, data, backbone="resnet18", body="open", input_size=64, draws=2)
    assert set(runs) == {(v, k) for v in models for k in (0, 1)}  # K = 2 seeded jitter draws
    # the same numbers as evaluating the in-memory kit model on the same crops: the official
    # loader's jittered test crops (draw k: jitter_seed k), and the tight ones as an extra table
    for k in (0, 1):
        test = OfficialSyntheticDataset(data, split="test", input_size=64, body_source="open", jitter=True,
                                        jitter_seed=k)
        ref = evaluate(models["airpose"], test, "AirPose", body="open")["per_view"]
        got = runs["airpose", k].tables["per_view"]
        np.testing.assert_allclose(got["mpjpe_m"].to_numpy(), ref["mpjpe_m"].to_numpy(), rtol=1e-6)
        np.testing.assert_allclose(got["mpe_m"].to_numpy(), ref["mpe_m"].to_numpy(), rtol=1e-6)
    tight = OfficialSyntheticDataset(data, split="test", input_size=64, body_source="open")
    ref = evaluate(models["airpose"], tight, "AirPose", body="open")["per_view"]
    np.testing.assert_allclose(runs["airpose", 1].tables["per_view_tight"]["mpe_m"].to_numpy(),
                               ref["mpe_m"].to_numpy(), rtol=1e-6)
    assert not np.allclose(runs["airpose", 0].tables["per_view"]["mpe_m"], ref["mpe_m"])  # jitter matters
    per_view = {k: r.tables["per_view"] for k, r in runs.items()}
    table = ablation_table(per_view, per_view_tight={k: r.tables["per_view_tight"] for k, r in runs.items()},
                           camera0=True)
    assert list(table.index) == ["Baseline", "Baseline + Multi-view", "Baseline + Fullcam", "AirPose"]
    assert (table["seeds"] == 2).all() and table["MPE std [m]"].notna().all()  # mean and spread over draws
    pv = per_view["airpose", 0]
    cam0 = np.mean([per_view["airpose", k].query("view == 0")["mpe_m"].mean() for k in (0, 1)])
    assert table.loc["AirPose", "MPE camera 0 [m]"] == pytest.approx(cam0)
    assert table.loc["AirPose", "MPE tight box [m]"] == pytest.approx(ref["mpe_m"].mean())
    assert set(pv["view"]) == {0, 1}

    # explicit checkpoints and the official batch drop (whole batches of 30; the fixture has fewer)
    other = {"airpose": ckpts / "copenet_twoview_synthetic_ckpt" / "checkpoints" / "epoch=1.ckpt"}
    with pytest.raises(ValueError, match="no test sample"):
        official_ablation(ckpts, data, variants=["airpose"], backbone="resnet18", body="open", input_size=64,
                          draws=1, drop_last=True, checkpoints=other)
    one = official_ablation(ckpts, data, variants=["airpose"], backbone="resnet18", body="open", input_size=64,
                            draws=1, tight=False, checkpoints=other)
    assert one["airpose", 0].checkpoint == other["airpose"] and "per_view_tight" not in one["airpose", 0].tables
    from airpose_lib.train.official import official_test_samples

    assert [official_test_samples(n, drop_last=True) for n in (29, 30, 59, 61)] == [0, 30, 30, 60]
    assert official_test_samples(61, max_samples=45, drop_last=True) == 30 and official_test_samples(61) == 61


def test_missing_checkpoint_names_the_folder_and_the_manifest(tmp_path):
    from airpose_lib.train.official import find_official_checkpoint

    with pytest.raises(FileNotFoundError, match="copenet_twoview_synthetic_ckpt.*official_checkpoints.yaml"):
        find_official_checkpoint(tmp_path, "airpose")


def test_training_config_switches_to_the_official_dataset(official_assets):
    from airpose_lib.data.official.synthetic import OfficialSyntheticDataset
    from airpose_lib.reproduce.configs import kit_configs
    from airpose_lib.train.loop import default_dataset_factory
    from airpose_lib.train.run import prepare_data

    data, _, _ = official_assets
    cfg = kit_configs("smoke").train.config("airpose", task="supervised", pretrained=None)  # end to end on the images
    official = cfg.replace(data={"source": "official_synthetic", "root": str(data), "input_size": 64,
                                 "body_source": "open"})
    with pytest.raises(ValueError, match="body_source='smplx'"):
        prepare_data(official)
    ds = default_dataset_factory(official.replace(body_source="smplx"), "test")
    assert isinstance(ds, OfficialSyntheticDataset) and len(ds) == 2


@pytest.mark.slow
def test_ablation_notebook_runs_on_official_assets(official_assets, tmp_path, monkeypatch):
    """Notebook 02 with data_source='official' evaluates the official checkpoints (fixtures here;
    the open model stands in for the licensed SMPL-X files, which share its format)."""
    import shutil

    import papermill as pm

    from airpose_lib.body.open_model import open_model_path

    data, ckpts, _ = official_assets
    smplx = tmp_path / "smplx"
    smplx.mkdir()
    for g in ("neutral", "male", "female"):
        shutil.copy(open_model_path(g), smplx / f"SMPLX_{g.upper()}.npz")
    monkeypatch.setenv("AIRPOSE_OFFICIAL_SYNTHETIC_DIR", str(data))
    monkeypatch.setenv("AIRPOSE_OFFICIAL_CHECKPOINTS_DIR", str(ckpts))
    monkeypatch.setenv("AIRPOSE_SMPLX_DIR", str(smplx))
    from pathlib import Path

    nb = Path(__file__).resolve().parents[1] / "notebooks" / "02_ablation_table.ipynb"
    out = tmp_path / "out"
    pm.execute_notebook(str(nb), str(tmp_path / "run.ipynb"), cwd=str(nb.parent), progress_bar=False,
                        parameters={"data_source": "official", "output_dir": str(out), "n_qualitative": 1})
    text = (out / "table1_ablation.md").read_text()
    assert "the official checkpoints on the official synthetic test split" in text
    assert (out / "ablation_qualitative.png").is_file()
