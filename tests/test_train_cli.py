"""`airpose train` / `airpose eval`: argument parsing and dispatch (with a stand-in back end)."""

from __future__ import annotations

from pathlib import Path

import pandas as pd
import pytest

from airpose_lib import cli


def test_train_help_lists_variants(capsys):
    with pytest.raises(SystemExit) as exc:
        cli.main(["train", "--help"])
    assert exc.value.code == 0
    out = capsys.readouterr().out
    assert "--variant" in out and "airpose" in out and "--resume" in out and "--world-size" in out
    with pytest.raises(SystemExit):
        cli.main(["eval", "--help"])
    assert "--checkpoint" in capsys.readouterr().out


def test_train_dispatch_merges_profile_and_options(monkeypatch, tmp_path):
    import airpose_lib.train as T

    seen = {}

    def fake_train(variant, inputs, out_dir=None, resume=True, config=None):
        seen.update(variant=variant, inputs=inputs, out_dir=out_dir, resume=resume, config=config)
        return T.TrainResult(out_dir=Path(out_dir or "."), step=config.steps, checkpoint=None, train_loss=1.0)

    monkeypatch.setattr(T, "train", fake_train)
    rc = cli.main(["train", "--variant", "fullcam", "--profile", "smoke", "--seed", "5", "--no-resume",
                   "--steps", "7", "--out", str(tmp_path), "--set", "lr=1e-4", "model.dropout=0.0",
                   "loss.w_tau=3", "official_loss=true"])
    assert rc == 0
    cfg = seen["config"]
    assert (seen["variant"], seen["resume"], seen["out_dir"]) == ("fullcam", False, tmp_path)
    assert seen["inputs"].folders.name == "smoke" and seen["inputs"].section.config("fullcam").backbone == "resnet18"
    assert (cfg.variant, cfg.seed, cfg.steps, cfg.lr, cfg.official_loss) == ("fullcam", 5, 7, 1e-4, True)
    assert cfg.model == {"dropout": 0.0}
    assert cfg.loss == {"vertex_subsample": 2000, "w_tau": 3}  # merged into the profile's dict
    assert cfg.backbone == "resnet18"  # from the smoke profile
    assert cli.main(["train", "--variant", "airpose", "--set", "stepz=3"]) == 2  # typo: a clean error
    assert cli.main(["train", "--variant", "airpose", "--set", "nonsense"]) == 2


def test_eval_dispatch_writes_tables(monkeypatch, tmp_path, capsys):
    import airpose_lib.train as T

    frame = pd.DataFrame({"method": ["m", "m"], "sample": [0, 0], "view": [0, 1], "mpe_m": [0.1, 0.3],
                          "mpjpe_m": [0.05, 0.07], "pa_mpjpe_m": [0.03, 0.04]})
    monkeypatch.setattr(T, "evaluate_checkpoint", lambda *a, **k: {"per_view": frame, "per_joint": frame})
    assert cli.main(["eval", "--checkpoint", str(tmp_path / "x.pt")]) == 2  # no such file: clean error
    (tmp_path / "x.pt").write_bytes(b"")
    assert cli.main(["eval", "--checkpoint", str(tmp_path / "x.pt"), "--out", str(tmp_path / "ev")]) == 0
    assert (tmp_path / "ev" / "per_view.csv").exists() and (tmp_path / "ev" / "per_joint.csv").exists()
    out = capsys.readouterr().out
    assert "0.200" in out and "0.060" in out  # MPE and MPJPE means
