"""The generated result blocks of the README and the docs pages (airpose_lib.eval.readme_block,
scripts/readme_results.py): made from a bundle, never typed."""
from __future__ import annotations

import json
from pathlib import Path

import pandas as pd
import pytest

from airpose_lib.eval.readme_block import readme_block, recordings_block, replace_block, results_block, video_block

ROOT = Path(__file__).resolve().parents[1]


def _bundle(root: Path) -> None:
    ref = root / "toy"
    ref.mkdir(parents=True)
    pd.DataFrame({"MPE [m]": [1.0, 0.5], "MPE std [m]": [0.01, float("nan")], "MPE paper [m]": [0.5, float("nan")],
                  "MPJPE [m]": [0.1234, float("nan")], "MPJPE std [m]": [0.0, float("nan")],
                  "MPJPE paper [m]": [0.091, float("nan")], "root orient. median [deg]": [14.56, float("nan")]},
                 index=pd.Index(["Baseline", "Reference: neutral mean body (GT pose)"], name="method")
                 ).to_csv(ref / "table1.csv")
    pd.DataFrame([{"claim": "MPE: A > B", "difference [m]": 0.25, "CI low [m]": 0.2, "CI high [m]": 0.3,
                   "gain [%]": 12.34, "gain CI low [%]": 10.0, "gain CI high [%]": 15.0, "paper gain [%]": 32.0,
                   "verdict": "holds"}]).to_csv(ref / "claims.csv", index=False)
    (ref / "provenance.json").write_text(json.dumps({"git": {"commit": "abcdef0123", "dirty": False},
                                                     "created_at": "2026-12-04T17:00:00+00:00",
                                                     "command": "airpose reproduce", "seeds": [1, 2, 3]}))


def test_the_block_is_the_bundle(tmp_path):
    _bundle(tmp_path)
    block = results_block("toy", tmp_path).splitlines()
    assert block[0] == "<!-- results:toy -->" and block[-1] == "<!-- /results:toy -->"
    assert "3 seeds, commit abcdef0, 2026-12-04; `airpose reproduce`" in block[1]
    assert "| Baseline | 1.000 ± 0.010 | 0.500 | 0.123 ± 0.000 | 0.091 | 14.6 |" in block
    assert "| Reference: neutral mean body (GT pose) | 0.500 | - | - | - | - |" in block
    assert "| MPE: A > B | +0.2500 (+0.2000, +0.3000) | +12.3 (+10.0, +15.0) | 32.0 | 10.7 (met) | holds |" in block
    assert not any(line.startswith("Where a gain misses") for line in block)  # every gain met: no bound lines


def test_a_missed_gain_gets_the_measured_bound_beside_it(tmp_path):
    _bundle(tmp_path)
    ref = tmp_path / "toy"
    claims = pd.read_csv(ref / "claims.csv")
    miss = claims.iloc[0].copy()
    miss["claim"], miss["gain [%]"] = "MPE: A > B", 9.0  # a third of 32 is 10.67: missed
    other = miss.copy()
    other["claim"], other["gain [%]"], other["paper gain [%]"] = "MPJPE: A > B", 1.0, 9.0
    pd.DataFrame([miss, other]).to_csv(ref / "claims.csv", index=False)
    (ref / "mechanism").mkdir()
    rows = [("c", "MPE [m]", "views' mean relative depth error (shared scalar)", "A", "gain over measured [%]",
             18.25, 17.0, 19.5),
            ("a", "stature [m]", "features + P", "ridge", "R2", 0.2, 0.18, 0.22),
            ("a", "stature [m]", "features + P", "ridge", "R2 of the views' mean", 0.28, 0.26, 0.3),
            ("a", "stature [m]", "features + P", "ridge", "view error correlation", 0.79, 0.78, 0.8)]
    pd.DataFrame(rows, columns=["part", "quantity", "input", "readout", "metric", "value", "CI low", "CI high"]
                 ).assign(samples=100).to_csv(ref / "mechanism" / "mechanism.csv", index=False)
    block = results_block("toy", tmp_path).splitlines()
    assert "| MPE: A > B | +0.2500 (+0.2000, +0.3000) | +9.0 (+10.0, +15.0) | 32.0 | 10.7 (missed) | holds |" in block
    assert any("would cut A's MPE by at most 18.2 % (17.0, 19.5); the exchange buys 9.0 %" in line for line in block)
    assert "- MPJPE: A > B: no bound measured; the measured reason is in docs/findings.md." in block
    assert any("R² 0.20 (0.18, 0.22)" in line and "correlate 0.79" in line for line in block)
    # part d of the table: the MPJPE ordering's gain with the body pose alone and an exact root
    table = pd.read_csv(ref / "mechanism" / "mechanism.csv")
    d = [("d", "MPJPE gain", "true root for both (the body pose alone)", "A > B", "gain [%]", -11.6, -12.4, -10.8),
         ("d", "MPJPE gain", "true root for the second (an exact root orientation)", "A > B", "gain [%]", 16.3,
          15.5, 17.0)]
    pd.concat([table, pd.DataFrame(d, columns=table.columns[:-1]).assign(samples=100)]).to_csv(
        ref / "mechanism" / "mechanism.csv", index=False)
    block = results_block("toy", tmp_path).splitlines()
    assert ("- MPJPE: A > B: scored with the true root orientation (the body pose alone) the gain is -11.6 % "
            "(-12.4, -10.8); with an exact root orientation B would gain +16.3 % (+15.5, +17.0); the ordering buys "
            "1.0 % against the paper's 9.0 %.") in block


def test_replace_block_swaps_only_the_block(tmp_path):
    _bundle(tmp_path)
    text = "intro\n<!-- results:toy -->\nold\n<!-- /results:toy -->\nrest\n"
    block = results_block("toy", tmp_path)
    new = replace_block(text, block, "toy")
    assert new.startswith("intro\n") and new.endswith("\nrest\n") and readme_block(new, "toy") == block
    with pytest.raises(ValueError, match="no <!-- results:other -->"):
        replace_block(text, block, "other")



def test_the_recordings_block_is_the_marker_tables(tmp_path):
    rec = tmp_path / "toy" / "recordings"
    rec.mkdir(parents=True)
    assert recordings_block("toy", tmp_path) is None  # no marker table: no block
    row = {"sequence": "person2", "method": "ArUco markers", "reference": "generated cameras", "frames": 850,
           "frames_share": 0.94, "rel_t_median_m": 0.04412, "rel_rot_median_deg": 0.1666, "rel_t_mean_m": 0.09,
           "rel_rot_mean_deg": 0.3}
    pd.DataFrame([row, {**row, "method": "AirPose+", "reference": "markers", "rel_t_median_m": 1.2345,
                        "rel_rot_median_deg": 12.345}]).to_csv(rec / "markers.csv", index=False)
    pd.DataFrame([{**row, "rel_t_median_m": float("nan")}]).to_csv(rec / "field_markers.csv", index=False)
    (rec / "provenance.json").write_text(json.dumps({"git": {"commit": "abcdef0123"}, "created_at": "2026-12-05T01:00",
                                                     "command": "airpose reproduce --profile toy"}))
    block = recordings_block("toy", tmp_path).splitlines()
    assert block[0] == "<!-- recordings:toy -->" and block[-1] == "<!-- /recordings:toy -->"
    assert "commit abcdef0, 2026-12-05; `airpose reproduce --profile toy`" in block[1]
    assert block[-4:-1] == ["| clean | person2 | ArUco markers | generated cameras | 850 | 0.044 | 0.17 |",
                            "| clean | person2 | AirPose+ | markers | 850 | 1.234 | 12.35 |",
                            "| field | person2 | ArUco markers | generated cameras | 850 | - | 0.17 |"]
    text = "a\n<!-- recordings:toy -->\nold\n<!-- /recordings:toy -->\n<!-- results:toy -->\nT\n<!-- /results:toy -->\n"
    new = replace_block(text, "\n".join(block), "toy", "recordings")
    assert readme_block(new, "toy", "recordings") == "\n".join(block) and readme_block(new, "toy") == readme_block(text, "toy")


def test_the_video_block_is_the_known_truth_table(tmp_path):
    ref = tmp_path / "toy" / "video"
    ref.mkdir(parents=True)
    rows = [{"recordings": rec, "route": route, "method": "AirPose+", "frames": 193, "mpjpe_median_m": m,
             "uav2_in_uav1_position_median_m": 1.5, "uav2_in_uav1_orientation_median_deg": 6.25,
             "offset_frames": -7 if route == "recording" else found}
            for rec, found in (("clean", -8), ("field", -7)) for route, m in (("video", 0.0712), ("recording", 0.07))]
    pd.DataFrame(rows).to_csv(ref / "known_truth.csv", index=False)
    (ref / "provenance.json").write_text(json.dumps({
        "git": {"commit": "abcdef0123"}, "created_at": "2026-12-07T01:00", "command": "python -c ...", "shift": 7,
        "recordings": {"clean": "person2", "field": "person2"},
        "timing": {"clean": {"seconds_per_100_frames": 61.4}, "field": {"seconds_per_100_frames": 40.0}}}))
    block = video_block("toy", tmp_path).splitlines()
    assert block[0] == "<!-- video:toy -->" and block[-1] == "<!-- /video:toy -->"
    assert "commit abcdef0, 2026-12-07; `python -c ...`" in block[1] and "started 7 frames late" in block[1]
    assert block[-3:-1] == ["| clean | AirPose+ | 193 | 0.0712 / 0.0700 | 1.500 / 1.500 | 6.25 / 6.25 | -8 (-7) | 61 |",
                            "| field | AirPose+ | 193 | 0.0712 / 0.0700 | 1.500 / 1.500 | 6.25 / 6.25 | given (-7) | 40 |"]
    assert video_block("toy", tmp_path / "elsewhere") is None


def _made(profile, kind):
    return {"results": results_block, "recordings": recordings_block, "video": video_block}[kind](profile)


@pytest.mark.parametrize(("page", "profile", "kind"), [("README.md", "cpu", "results"),
                                                     ("docs/findings.md", "cpu_paper_layout", "results"),
                                                     ("docs/recordings.md", "cpu", "recordings"),
                                                     ("docs/own_videos.md", "demo", "video")])
def test_the_blocks_match_the_committed_results(page, profile, kind):
    # `python scripts/readme_results.py` after a new results/<profile>/ (airpose reproduce --write-reference)
    block = readme_block((ROOT / page).read_text(), profile, kind)
    assert block is not None, f"{page} lost its <!-- {kind}:{profile} --> block"
    made = _made(profile, kind)
    assert block == made, f"{page}'s {profile} {kind} block differs from results/{profile}/: " \
                          "run python scripts/readme_results.py"


def test_the_writer_knows_every_block_the_tests_check():
    import importlib.util

    spec = importlib.util.spec_from_file_location("readme_results", ROOT / "scripts" / "readme_results.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    assert set(module.BLOCKS) == {("README.md", "cpu", "results"), ("docs/findings.md", "cpu_paper_layout", "results"),
                                  ("docs/recordings.md", "cpu", "recordings"), ("docs/model_zoo.md", "cpu", "zoo"),
                                  ("docs/own_videos.md", "demo", "video")}


def test_the_model_zoo_page_lists_every_shipped_file_with_its_hash():
    from airpose_lib.zoo import read_manifest

    folder = ROOT / "results" / "cpu" / "networks"
    block = readme_block((ROOT / "docs" / "model_zoo.md").read_text(), "cpu", "zoo")
    assert block is not None, "docs/model_zoo.md lost its <!-- zoo:cpu --> block"
    entries = read_manifest(folder).values()
    rows = [line for line in block.splitlines() if line.startswith("| `")]
    assert len(rows) == len(entries)  # one row a file, nothing stale
    for entry in entries:
        assert any(f"`{entry['file']}`" in r and entry["sha256"][:16] in r for r in rows), entry["name"]
