"""Table I helpers on hand-made per-view tables."""
import numpy as np
import pandas as pd
import pytest

from airpose_lib.eval.ablation import (
    PAPER_TABLE_I,
    ablation_findings,
    ablation_table,
    per_seed_table,
    table_to_latex,
    table_to_markdown,
)
from airpose_lib.eval.mean_body import GENDERED_LABEL, NEUTRAL_LABEL, PROPORTION_LABEL


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


def _full(mpe, mpjpe, rot, n=4):
    t = _per_view(mpe, mpjpe, n)
    t["sample"], t["view"] = np.arange(n) // 2, np.arange(n) % 2
    t["mpjpe_shape_m"] = mpjpe + 0.01
    t["root_rot_deg"] = [rot, rot, rot, 90.0][:n]  # the median ignores the one outlier
    return t


def test_extra_columns_reference_rows_and_tight_boxes():
    runs = {("baseline", 1): _full(0.6, 0.10, 10.0), ("baseline", 2): _full(0.4, 0.08, 20.0),
            ("airpose", 1): _full(0.2, 0.07, 5.0)}
    tight = {k: _per_view(2 * t["mpe_m"].iloc[0], 3 * t["mpjpe_m"].iloc[0]) for k, t in runs.items()}
    references = pd.DataFrame({"method": [GENDERED_LABEL, NEUTRAL_LABEL, NEUTRAL_LABEL], "mpe_m": [0.15, 0.1, 0.3]})
    t = ablation_table(runs, references=references, per_view_tight=tight)
    assert list(t.index) == ["Baseline", "AirPose", NEUTRAL_LABEL, GENDERED_LABEL]  # neutral first
    assert list(t.columns[:6]) == ["MPE [m]", "MPE std [m]", "MPE paper [m]", "MPJPE [m]", "MPJPE std [m]",
                                   "MPJPE paper [m]"]
    assert t.loc["Baseline", "MPJPE shape-aware [m]"] == pytest.approx(0.10)
    assert t.loc["Baseline", "root orient. median [deg]"] == pytest.approx(15.0)
    assert t.loc["Baseline", "MPE tight box [m]"] == pytest.approx(1.0)
    assert t.loc["AirPose", "MPJPE tight box [m]"] == pytest.approx(0.21)
    assert t.loc[NEUTRAL_LABEL, "MPE [m]"] == pytest.approx(0.2) and t.loc[GENDERED_LABEL, "MPE [m]"] == 0.15
    assert t.loc[NEUTRAL_LABEL].drop("MPE [m]").isna().all()  # MPE only
    md = table_to_markdown(t)
    assert f"| {NEUTRAL_LABEL} | 0.200 | - | - | - |" in md and "| 2 |" in md


def test_optional_columns_are_left_out_when_a_run_lacks_them():
    runs = {("baseline", 1): _full(0.6, 0.10, 10.0), ("fullcam", 1): _per_view(0.3, 0.09)}
    t = ablation_table(runs, per_view_tight={("baseline", 1): _per_view(1.0, 0.2)})
    assert "MPJPE shape-aware [m]" not in t and "MPE tight box [m]" not in t and "PA-MPJPE [m]" in t


def test_per_seed_rows_in_table_order_with_wall_times():
    runs = {("airpose", 2): _full(0.2, 0.07, 5.0), ("baseline", 2): _full(0.4, 0.08, 20.0),
            ("baseline", 1): _full(0.6, 0.10, 10.0)}
    p = per_seed_table(runs, wall_s={("baseline", 1): 12.5, ("airpose", 2): None})
    assert list(zip(p["variant"], p["seed"])) == [("baseline", 1), ("baseline", 2), ("airpose", 2)]
    assert p.loc[0, "mpe_m"] == pytest.approx(0.6) and p.loc[0, "root_rot_median_deg"] == pytest.approx(10.0)
    assert p.loc[0, "wall_s"] == 12.5 and np.isnan(p.loc[1, "wall_s"]) and np.isnan(p.loc[2, "wall_s"])
    assert (p["images"] == 4).all() and list(p["method"]) == ["Baseline", "Baseline", "AirPose"]


def test_root_orientation_breakdown_per_seed_in_the_table_and_the_findings():
    t = _full(0.6, 0.10, 5.0)
    t["root_rot_deg"] = [5.0, 10.0, 100.0, 170.0]  # median 55; two of four above 90 deg (exactly 90: not)
    t["root_yaw_deg"] = [4.0, 9.0, 100.0, 170.0]  # median 54.5
    t["root_tilt_deg"] = [1.0, 2.0, 3.0, 4.0]  # median 2.5
    t["mpjpe_true_root_m"] = 0.08
    edge = t.assign(root_rot_deg=[90.0, 90.0, 90.0, 90.5])
    p = per_seed_table({("airpose", 1): t, ("airpose", 2): edge})
    assert list(p["root_above90_pct"]) == [50.0, 25.0]
    assert p.loc[0, "root_yaw_median_deg"] == 54.5 and p.loc[0, "root_tilt_median_deg"] == 2.5
    table = ablation_table({("airpose", 1): t})
    assert table.loc["AirPose", ["root orient. median [deg]", "root yaw median [deg]", "root tilt median [deg]",
                                 "root orient. > 90 deg [%]"]].tolist() == [55.0, 54.5, 2.5, 50.0]
    text = ablation_findings(table)
    assert ("(median root-orientation error 55.0 deg: yaw 54.5 deg and tilt 2.5 deg median, 50.0 % of the images "
            "above 90 deg)") in text


def test_markdown_and_latex_render_every_row():
    t = ablation_table({("baseline", 1): _per_view(0.5, 0.1), ("fullcam", 1): _per_view(0.25, 0.09)})
    md = table_to_markdown(t)
    assert md.count("\n") == 4 and "| Baseline | 0.500 | - | 0.500 |" in md and "| 1 |" in md
    tex = table_to_latex(t, caption="x_y")
    assert r"\toprule" in tex and "Baseline + Fullcam" in tex and r"x\_y" in tex


def test_a_finished_run_is_reused_only_with_the_same_config(tmp_path):
    import json

    import yaml

    from airpose_lib.data.still.manifest import DATASET_KIND
    from airpose_lib.reproduce.configs import kit_configs
    from airpose_lib.train.ablation import _finished_run
    from airpose_lib.train.pretrain import profile_backbone_key

    smoke = kit_configs("smoke").train_inputs()
    cfg = smoke.section.config("airpose", 7).to_dict()
    assert cfg["pretrained"] == "profile"  # resolved to the profile's backbone file when training
    data = tmp_path / "data"
    data.mkdir()
    (data / "manifest.yaml").write_text(yaml.safe_dump({"kind": DATASET_KIND, "fingerprint": "abc", "shards": []}))
    backbone = tmp_path / f"{profile_backbone_key(smoke.pretrain, data)}.pt"
    backbone.write_bytes(b"x")
    ckpt = tmp_path / "checkpoints" / "last.pt"
    ckpt.parent.mkdir()
    ckpt.write_bytes(b"x")
    result = {"out_dir": str(tmp_path), "step": cfg["steps"], "checkpoint": str(ckpt), "train_loss": 1.0,
              "val_losses": None, "tensorboard": False, "stopped_early": False,
              "config": {**cfg, "data": {"root": str(data)}, "progress": False, "pretrained": str(backbone)}}
    (tmp_path / "result.json").write_text(json.dumps(result))
    assert _finished_run(tmp_path, smoke, "airpose", 7) is not None
    # the device a run resolved `auto` to, or a parallel worker's own GPU, does not make it another run
    (tmp_path / "result.json").write_text(json.dumps({**result, "config": {**result["config"], "device": "cuda:1"}}))
    assert _finished_run(tmp_path, smoke, "airpose", 7) is not None
    other = tmp_path / "0123456789abcdef.pt"  # a backbone of other pretraining settings
    other.write_bytes(b"x")
    (tmp_path / "result.json").write_text(json.dumps({**result, "config": {**result["config"], "pretrained": str(other)}}))
    assert _finished_run(tmp_path, smoke, "airpose", 7) is None
    (tmp_path / "result.json").write_text(json.dumps(result))
    assert _finished_run(tmp_path, smoke, "airpose", 8) is None  # another seed
    (tmp_path / "result.json").write_text(json.dumps({**result, "step": cfg["steps"] - 1}))
    assert _finished_run(tmp_path, smoke, "airpose", 7) is None  # unfinished: resume instead


def test_paper_gaps_are_ratios_to_the_paper_and_the_references():
    from airpose_lib.eval.ablation import paper_gaps

    t = ablation_table({("airpose", 1): _per_view(0.3, 0.144), ("baseline", 1): _per_view(1.0, 0.091)},
                       references=pd.DataFrame({"method": [NEUTRAL_LABEL, GENDERED_LABEL], "mpe_m": [0.2, 0.15]}))
    g = paper_gaps(t)
    assert list(g.index) == ["Baseline", "AirPose"]
    assert g.loc["AirPose", "MPE kit / paper"] == pytest.approx(2.0)
    assert g.loc["AirPose", "MPJPE kit / paper"] == pytest.approx(2.0)
    assert g.loc["AirPose", "MPE kit / neutral mean body"] == pytest.approx(1.5)
    assert g.loc["AirPose", "MPE kit / true-gender mean body"] == pytest.approx(2.0)
    assert list(paper_gaps(ablation_table({("airpose", 1): _per_view(0.3, 0.1)}))) == ["MPE kit / paper",
                                                                                       "MPJPE kit / paper"]
    with_prop = ablation_table({("airpose", 1): _per_view(0.3, 0.144)},
                               references=pd.DataFrame({"method": [PROPORTION_LABEL, NEUTRAL_LABEL],
                                                        "mpe_m": [0.06, 0.2]}))
    assert list(with_prop.index) == ["AirPose", NEUTRAL_LABEL, PROPORTION_LABEL]  # table order
    assert paper_gaps(with_prop).loc["AirPose", "MPE kit / body at its proportions' stature"] == pytest.approx(5.0)


def test_findings_are_written_from_the_tables():
    """Notebook 02's summary: every number comes from the tables passed in."""
    runs = {("baseline", 1): _per_view(0.9, 0.12), ("airpose", 1): _per_view(0.75, 0.10)}
    references = pd.DataFrame({"method": [NEUTRAL_LABEL] * 2 + [GENDERED_LABEL],
                               "mpe_m": [0.5, 0.7, 0.5]})  # neutral 0.6 m, true gender 0.5 m
    claims = pd.DataFrame({"claim": ["MPE: Baseline > AirPose", "MPJPE: Baseline > AirPose"],
                           "difference [m]": [0.15, -0.002],
                           "verdict": ["holds", "not significant"]}).set_index("claim")  # as claims_table
    text = ablation_findings(ablation_table(runs, references=references), claims)
    assert "MPE 0.750 m (the paper's 0.150 m)" in text and "MPJPE 0.100 m (the paper's 0.072 m)" in text
    assert ("a stature-blind estimate with the ground-truth pose gets MPE 0.600 m with the neutral mean body and "
            "0.500 m with the true-gender mean body on this data, so AirPose's MPE is 1.25 x the neutral mean "
            "body's and 1.50 x the true-gender mean body's, and the paper's below the neutral mean body's and "
            "below the true-gender mean body's.") in text
    assert "floor" not in text and "proportions" not in text  # no such row: nothing said about it
    assert "1 of the paper's 2 orderings hold" in text
    with_prop = pd.concat([references, pd.DataFrame({"method": [PROPORTION_LABEL] * 2, "mpe_m": [0.04, 0.06]})])
    assert ("below the true-gender mean body's; the subject's own body at the stature a linear model reads from "
            "its proportions gets 0.050 m, so an estimate that read the body's proportions could come that "
            "close.") in ablation_findings(ablation_table(runs, references=with_prop), claims)
    assert "Not significant: MPJPE: Baseline > AirPose (-2.0 mm)" in text and "Reversed: none" in text
    assert "PA-MPJPE, which aligns rotation and scale away, is 0.050 m" in text
    assert "One seed" in text
    assert "true root" not in text  # no such column: nothing said about it
    assert "Effect sizes" not in text  # claims without gains (a claims.csv of before)
    claims["gain [%]"], claims["gain CI low [%]"], claims["gain CI high [%]"] = [16.7, -1.0], [15.0, -3.0], [18.0, 1.0]
    claims["paper gain [%]"], claims["of paper's size"] = [70.0, 20.9], [False, False]
    text = ablation_findings(ablation_table(runs, references=references), claims)
    assert ("0 of 2 reach a third of the paper's gain. MPE: Baseline > AirPose 16.7 % (15.0 to 18.0) against "
            "the paper's 70.0 %; MPJPE: Baseline > AirPose -1.0 % (-3.0 to 1.0) against the paper's 20.9 %.") in text


def test_findings_without_references_claims_or_extra_columns():
    runs = {("airpose", 1): _per_view(0.3, 0.08), ("airpose", 2): _per_view(0.5, 0.08)}
    table = ablation_table(runs).drop(columns=["PA-MPJPE [m]"])
    text = ablation_findings(table)
    assert text == "* **AirPose**: MPE 0.400 m (the paper's 0.150 m), MPJPE 0.080 m (the paper's 0.072 m)."
