"""scripts/backbone_spread.py: two backbones' Table I side by side, on a
hand-made case whose differences, seed-SD ratios and claim counts are computed by hand."""
import importlib.util
from pathlib import Path

import pandas as pd
import pytest


@pytest.fixture(scope="module")
def spread():
    path = Path(__file__).resolve().parents[1] / "scripts" / "backbone_spread.py"
    spec = importlib.util.spec_from_file_location("backbone_spread_script", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _per_seed(offset: float, scale: float = 1.0) -> pd.DataFrame:
    """Two variants x two seeds; each metric is the variant's base + offset, -+0.01*scale by seed."""
    rows = []
    for variant, method, base in (("baseline", "Baseline", 1.0), ("airpose", "AirPose", 0.5)):
        for seed, sign in ((123, -1), (124, 1)):
            row = {"variant": variant, "method": method, "seed": seed}
            for col in ("mpe_m", "mpjpe_m", "mpjpe_true_root_m", "root_rot_median_deg", "root_above90_pct"):
                row[col] = base + offset + sign * scale * 0.01
            rows.append(row)
    return pd.DataFrame(rows)


def _claims(verdicts, lows, highs) -> pd.DataFrame:
    return pd.DataFrame({"claim": ["A > B", "B > C"], "verdict": verdicts, "gain [%]": [2.0, 3.0],
                         "gain CI low [%]": lows, "gain CI high [%]": highs, "paper gain [%]": [8.0, 30.0]})


def test_differences_are_the_mean_shift_over_the_larger_seed_sd(spread):
    first, second = _per_seed(0.0), _per_seed(-0.1, scale=2.0)  # backbone 1: 0.1 lower, twice the seed spread
    d = spread.differences(first, second)
    assert len(d) == 2 * len(spread.METRICS) and list(d["method"].unique()) == ["Baseline", "AirPose"]
    sd = 2.0 * 0.01 * 2 ** 0.5  # SD (ddof=1) of base -+ 0.02: 0.02 * sqrt(2)
    assert d["difference"].to_numpy() == pytest.approx(-0.1)
    assert d["ratio"].to_numpy() == pytest.approx(-0.1 / sd)
    assert d["sd 0"].to_numpy() == pytest.approx(0.01 * 2 ** 0.5) and (d["seeds"] == "2 / 2").all()
    printed = spread.variant_table(d)
    assert printed.iloc[0]["difference"] == "-0.1000" and printed.iloc[0]["backbone 0"] == "1.0000 ± 0.0141"


def test_summary_counts_verdicts_and_overlapping_intervals(spread):
    first, second = _per_seed(0.0), _per_seed(-0.1)
    d = spread.differences(first, second)
    same = spread.summary(d, _claims(["holds", "holds"], [1.0, 2.0], [3.0, 4.0]),
                          _claims(["holds", "not significant"], [2.5, 4.5], [3.5, 5.0]))
    assert "all variants the same way" in same and "the variants differ in sign" not in same
    assert "1 of 2 keep their verdict" in same and "overlap for 1 of 2" in same  # [2, 4] and [4.5, 5] are apart
    # one variant up, the other down: the sign check says so
    mixed = second.copy()
    mixed.loc[mixed["variant"] == "airpose", "mpe_m"] += 0.2
    text = spread.summary(spread.differences(first, mixed), _claims(["holds"] * 2, [1, 2], [3, 4]),
                          _claims(["holds"] * 2, [1, 2], [3, 4]))
    mpe_line = next(line for line in text.splitlines() if line.startswith("- MPE [m]"))
    assert "the variants differ in sign" in mpe_line and "-0.1000 to +0.1000" in mpe_line
    assert "2 of 2 keep their verdict" in text and "overlap for 2 of 2" in text


def test_the_committed_spread_is_what_the_script_prints(spread, capsys, monkeypatch):
    """results/cpu_backbone_seed1/backbone_spread.md is the script's output on the two committed folders."""
    results = Path(__file__).resolve().parents[1] / "results"
    monkeypatch.chdir(results.parent)
    monkeypatch.setattr("sys.argv", ["backbone_spread.py", "results/cpu_four_stages", "results/cpu_backbone_seed1"])
    spread.main()
    assert capsys.readouterr().out == (results / "cpu_backbone_seed1" / "backbone_spread.md").read_text()
