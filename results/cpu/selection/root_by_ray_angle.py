"""Issue 28 probe (no choice is made on it): each variant's root error and MPJPE on the validation
split by the angle between the camera's optical axis and its ray to the person (the angle that
the crop vector P tells Fullcam and AirPose, and that Baseline and Multi-view must read from the crop).

    python results/cpu/selection/root_by_ray_angle.py PROFILE OUT.csv RUN...

RUN: run folders with ``eval_val/per_view.csv`` (``airpose eval --split val``); their
``config.json`` names the variant and the settings.
"""
from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
import pandas as pd

from airpose_lib.data import default_root, split_arrays

BINS = (0.0, 5.0, 10.0, 15.0, 90.0)


def ray_angles(profile: str) -> pd.DataFrame:
    """``sample, view, ray_deg``: the angle of tau to the optical axis (z), per validation view."""
    a = split_arrays(default_root(profile), "val", ("tau", "index"))
    tau = a["tau"].astype(np.float64)  # (N, V, 3)
    ray = np.degrees(np.arctan2(np.linalg.norm(tau[..., :2], axis=-1), tau[..., 2]))
    N, V = ray.shape
    return pd.DataFrame({"sample": np.repeat(a["index"], V), "view": np.tile(np.arange(V), N),
                         "ray_deg": ray.reshape(-1)})


def main(profile: str, out: str, runs: list[str]) -> None:
    ray = ray_angles(profile)
    rows = []
    for run in map(Path, runs):
        cfg = json.loads((run / "config.json").read_text())
        per_view = pd.read_csv(run / "eval_val" / "per_view.csv").merge(ray, on=["sample", "view"], validate="1:1")
        per_view["ray bin [deg]"] = pd.cut(per_view["ray_deg"], BINS)
        trunk = cfg.get("model", {}).get("activation", "linear")
        w_phi = cfg.get("loss", {}).get("w_phi", 1.0)
        for label, g in [("all", per_view), *per_view.groupby("ray bin [deg]", sort=True, observed=True)]:
            rows.append({"variant": cfg["variant"], "trunk": trunk, "w_phi": w_phi, "ray bin [deg]": str(label),
                         "views": len(g), "root median [deg]": g["root_rot_deg"].median(),
                         "MPJPE [m]": g["mpjpe_m"].mean(), "MPJPE true root [m]": g["mpjpe_true_root_m"].mean()})
    table = pd.DataFrame(rows)
    table.to_csv(out, index=False, float_format="%.4f")
    print(table.to_string(index=False, float_format=lambda x: f"{x:.4f}"))


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2], sys.argv[3:])
