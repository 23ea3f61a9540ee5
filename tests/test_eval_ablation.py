"""Table I helpers on hand-made per-view tables."""
import numpy as np
import pandas as pd
import pytest

from airpose_lib.eval.ablation import (
    PAPER_TABLE_I,
    ablation_table,
    ordering_checks,
    table_to_latex,
    table_to_markdown,
)


def _per_view(mpe, mpjpe, n=4):
    return pd.DataFrame({"mpe_m": [mpe] * n, "mpjpe_m": [mpjpe] * n, "pa_mpjpe_m": [mpjpe / 2] * n})


def test_mean_and_std_over_seeds_next_to_the_paper():
    runs = {("baseline", 1): _per_view(0.6, 0.10), ("baseline", 2): _per_view(0.4, 0.08),
            ("airpose", 1): _per_view(0.2, 0.07)}
    t = ablation_table(runs)
    assert list(t.index) == ["Baseline", "AirPose"]  # Table I order, paper labels
    assert t.loc["Baseline", "MPE [m]"] == pytest.approx(0.5)
    assert t.loc["Baseline", "MPE std [m]"] == pytest.approx(np.std([0.6, 0.4], ddof=1))
    assert np.isnan(t.loc["AirPose", "MPE std [m]"])
    assert t.loc["AirPose", "MPE paper [m]"] == PAPER_TABLE_I.loc["AirPose", "MPE [m]"] == 0.15
    assert t.loc["Baseline", "MPJPE paper [m]"] == 0.091
    assert t.loc["Baseline", "seeds"] == 2


def test_unknown_variant_is_an_error():
    with pytest.raises(ValueError, match="unknown variants"):
        ablation_table({("hmr", 1): _per_view(1, 1)})


def test_ordering_checks_follow_the_numbers():
    paper_like = ablation_table({(v, 0): _per_view(m, j) for v, m, j in (
        ("baseline", 0.50, 0.091), ("multiview", 0.46, 0.084), ("fullcam", 0.22, 0.077), ("airpose", 0.15, 0.072))})
    assert ordering_checks(paper_like)["holds"].all()
    reversed_ = ablation_table({(v, 0): _per_view(m, j) for v, m, j in (
        ("baseline", 0.15, 0.07), ("multiview", 0.16, 0.08), ("fullcam", 0.30, 0.09), ("airpose", 0.50, 0.10))})
    checks = ordering_checks(reversed_)
    assert not checks.loc["MPE: Baseline > Fullcam > AirPose", "holds"]
    assert not checks.loc["MPJPE: AirPose < Baseline", "holds"]


def test_markdown_and_latex_render_every_row():
    t = ablation_table({("baseline", 1): _per_view(0.5, 0.1), ("fullcam", 1): _per_view(0.25, 0.09)})
    md = table_to_markdown(t)
    assert md.count("\n") == 4 and "| Baseline | 0.500 | - | 0.500 |" in md and "| 1 |" in md
    tex = table_to_latex(t, caption="x_y")
    assert r"\toprule" in tex and "Baseline + Fullcam" in tex and r"x\_y" in tex


def test_a_finished_run_is_reused_only_with_the_same_config(tmp_path):
    import json

    from airpose_lib.train.ablation import _finished_run
    from airpose_lib.train.config import load_train_config

    cfg = load_train_config("smoke", "airpose", 7).to_dict()
    ckpt = tmp_path / "checkpoints" / "last.pt"
    ckpt.parent.mkdir()
    ckpt.write_bytes(b"x")
    result = {"out_dir": str(tmp_path), "step": cfg["steps"], "checkpoint": str(ckpt), "train_loss": 1.0,
              "val_losses": None, "tensorboard": False, "stopped_early": False,
              "config": {**cfg, "data": {"root": "/somewhere"}, "progress": False}}
    (tmp_path / "result.json").write_text(json.dumps(result))
    assert _finished_run(tmp_path, "smoke", "airpose", 7) is not None
    assert _finished_run(tmp_path, "smoke", "airpose", 8) is None  # another seed
    (tmp_path / "result.json").write_text(json.dumps({**result, "step": cfg["steps"] - 1}))
    assert _finished_run(tmp_path, "smoke", "airpose", 7) is None  # unfinished: resume instead
