"""Issue 28 probe (no choice is made on it): where AirPose's root-orientation error comes from.

One trained network, scored on the validation split and on as many training samples (the frames
its backbone and regressor were fitted to), each view's root error (geodesic, yaw, tilt) set
against what the crop shows:

- the person's span in the crop: the 22 body joints' extent over the crop box's longer side,
  times the crop side S (px of the network input). If the error were a matter of resolution,
  it would fall as the span grows, and person-centred crops (less box jitter) would lower it.
- the spine's bend: the angle of the composed spine1-spine3 rotations of theta. A bent torso
  shows the pelvis's heading less directly than an upright one.

Writes ``root_error_breakdown.{csv,md}`` into OUT:

    AIRPOSE_RUNS=/work/runs4 python results/cpu/selection/root_error_breakdown.py \\
        /work/runs4/train/cpu/airpose/seed123/checkpoints/last.pt OUT
"""
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import torch

from airpose_lib.data.still.dataset import StillFrameDataset
from airpose_lib.experiments.recording_tables import markdown_table
from airpose_lib.geometry import axis_angle_to_matrix, full_to_crop_pixels, matrix_to_axis_angle
from airpose_lib.train import evaluate_checkpoint, load_trained_model
from airpose_lib.train.run import prepare_data

SPAN_BINS = [0, 35, 45, 55, 65, 75, 130]
BEND_BINS = [0, 10, 20, 30, 45, 180]
SPINE = (2, 5, 8)  # spine1, spine2, spine3 in theta's 21 body joints


def view_covariates(ds: StillFrameDataset) -> pd.DataFrame:
    """One row per (sample index, view): the person's span in the crop [px] and the spine's bend [deg]."""
    a = ds.arrays
    uv = full_to_crop_pixels(torch.as_tensor(a["j2d"]), torch.as_tensor(a["bbox"]), ds.crop_size).numpy()
    span = (uv.max(-2) - uv.min(-2)).max(-1)  # (N, V)
    spine = torch.eye(3, dtype=torch.float64).expand(len(span), 3, 3)
    for j in SPINE:
        spine = spine @ axis_angle_to_matrix(torch.as_tensor(a["theta"][:, j], dtype=torch.float64))
    bend = np.degrees(matrix_to_axis_angle(spine).norm(dim=-1).numpy())
    N, V = span.shape
    return pd.DataFrame({"sample": np.repeat(a["index"], V), "view": np.tile(np.arange(V), N),
                         "span_px": span.reshape(-1), "bend_deg": np.repeat(bend, V)})


def summary(per_view: pd.DataFrame, by: str | None) -> pd.DataFrame:
    g = per_view.groupby(by, observed=True) if by else per_view.groupby(lambda _: "all")
    out = pd.DataFrame({
        "views": g.size(),
        "root_median_deg": g["root_rot_deg"].median(),
        "yaw_median_deg": g["root_yaw_deg"].apply(lambda x: x.abs().median()),
        "tilt_median_deg": g["root_tilt_deg"].apply(lambda x: x.abs().median()),
        "above_90_pct": g["root_rot_deg"].apply(lambda x: 100.0 * (x > 90).mean()),
        "mpjpe_m": g["mpjpe_m"].mean(),
    })
    out.index = out.index.astype(str)
    return out.rename_axis("group").reset_index().assign(by=by or "all")


def main(checkpoint: str, out: str) -> None:
    torch.set_num_threads(1)
    _, cfg = load_trained_model(checkpoint)
    cfg = prepare_data(cfg, progress=False)
    rows = []
    n_val = None
    for split in ("val", "train"):
        ds = StillFrameDataset(cfg.data["root"], split=split, augment=False, verify=False)
        n = len(ds) if split == "val" else n_val  # as many training samples as validation ones
        n_val = n
        pv = evaluate_checkpoint(checkpoint, split=split, max_samples=n)["per_view"]
        pv = pv.merge(view_covariates(ds), on=["sample", "view"], how="left", validate="one_to_one")
        pv["span"] = pd.cut(pv["span_px"], SPAN_BINS)
        pv["bend"] = pd.cut(pv["bend_deg"], BEND_BINS)
        for by in (None, "span", "bend"):
            rows.append(summary(pv, by).assign(split=split))
        print(split, len(pv), "views", flush=True)
    table = pd.concat(rows, ignore_index=True)
    table = table[["split", "by", "group", *[c for c in table.columns if c not in ("split", "by", "group")]]]
    out_dir = Path(out)
    out_dir.mkdir(parents=True, exist_ok=True)
    table.to_csv(out_dir / "root_error_breakdown.csv", index=False, float_format="%.4f", lineterminator="\n")
    head = (f"{cfg.variant}'s root-orientation error per view (profile {cfg.profile}, seed {cfg.seed}, "
            f"{cfg.steps} steps), on the validation split and on "
            "as many training samples, by the person's span in the crop [px of the network input] and "
            "by the spine's bend [deg].\n\n")
    (out_dir / "root_error_breakdown.md").write_text(head + markdown_table(table, digits=4))
    print(table.to_string())


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2])
