"""scripts/selection_rows.py: a validation row from a run's per-view errors, checked by hand."""
from __future__ import annotations

import importlib.util
import json
from pathlib import Path

import pandas as pd
import pytest


def _script():
    path = Path(__file__).resolve().parents[1] / "scripts" / "selection_rows.py"
    spec = importlib.util.spec_from_file_location("selection_rows_script", path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def _run(folder: Path, steps: int, root_deg: list[float]) -> Path:
    (folder / "eval_val").mkdir(parents=True)
    (folder / "config.json").write_text(json.dumps({"variant": "airpose", "seed": 7, "steps": steps,
                                                    "pretrained": "/c/backbones/42aee172a33ba052.pt"}))
    n = len(root_deg)
    pd.DataFrame({"mpe_m": [0.5 + i for i in range(n)], "mpjpe_m": [0.1] * n, "mpjpe_true_root_m": [0.05] * n,
                  "pa_mpjpe_m": [0.04] * n, "root_rot_deg": root_deg, "root_yaw_deg": root_deg,
                  "root_tilt_deg": [1.0] * n}).to_csv(folder / "eval_val" / "per_view.csv", index=False)
    return folder


def test_a_row_holds_the_settings_means_medians_and_flips(tmp_path):
    mod = _script()
    a = _run(tmp_path / "a", 3000, [10.0, 20.0, 100.0, 30.0])
    b = _run(tmp_path / "b", 6000, [5.0, 6.0, 7.0])
    out = tmp_path / "t.csv"
    assert mod.main([str(a), str(b), "--settings", "steps", "pretrained", "--out", str(out)]) == 0
    t = pd.read_csv(out)
    assert list(t["train.steps"]) == [3000, 6000] and set(t["train.pretrained"]) == {"42aee172a33ba052"}
    assert list(t["views"]) == [4, 3] and list(t["seed"]) == [7, 7]
    assert t["MPE [m]"].tolist() == pytest.approx([2.0, 1.5])  # means of 0.5..3.5 and 0.5..2.5
    assert t["root median [deg]"].tolist() == pytest.approx([25.0, 6.0])
    assert t["root > 90 deg [%]"].tolist() == pytest.approx([25.0, 0.0])
    assert mod.main([str(tmp_path / "none"), "--out", str(out)]) == 2
