#!/usr/bin/env python
"""What the ground-truth skeleton alone tells of stature and gender (no image): the mechanism
table's probes (``airpose_lib.eval.mechanism``: ridge and a small MLP), fitted on a profile's
training split and scored per view on its validation split.

    python scripts/skeleton_probes.py [PROFILE]      # default cpu; prints one line per probe

Inputs per view: the 22 ground-truth 2D joints relative to the pelvis over the crop's side (the
skeleton's shape in the crop, no scale), the same with the crop vector P, and the pelvis-centred
3D joints in the camera's axes (metric: what the pretraining's j3d term asks for). An upper
reference for what a network could read from the 2D joints of a crop, not a bound (a stronger
reader of the same inputs may do better).
"""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from airpose_lib.data.still.dataset import split_arrays  # noqa: E402
from airpose_lib.eval.mean_body import rest_statures  # noqa: E402
from airpose_lib.eval.mechanism import fit_mlp, fit_ridge, r2_score, view_error_correlation  # noqa: E402
from airpose_lib.paths import RunFolders  # noqa: E402

NAMES = ("j2d", "bbox", "P", "j3d_cam", "beta", "gender")


def inputs(a: dict) -> dict[str, np.ndarray]:
    """Probe inputs ``(N, V, d)``."""
    j2d = a["j2d"].astype(np.float64)
    side = np.maximum(a["bbox"][..., 2] - a["bbox"][..., 0], a["bbox"][..., 3] - a["bbox"][..., 1])[..., None, None]
    rel = ((j2d - j2d[..., :1, :]) / side).reshape(*j2d.shape[:2], -1)
    j3 = a["j3d_cam"].astype(np.float64)[..., :22, :]
    return {"2D joints / crop side": rel,
            "2D joints / crop side + P": np.concatenate([rel, a["P"].astype(np.float64)], -1),
            "pelvis-centred 3D joints (camera)": (j3 - j3[..., :1, :]).reshape(*j3.shape[:2], -1)}


def targets(a: dict) -> dict[str, np.ndarray]:
    """Probe targets ``(N, V)``: stature of the T-posed gendered body, female = 1."""
    h, _ = rest_statures(a["beta"], a["gender"])
    V = a["j2d"].shape[1]
    return {"stature [m]": np.repeat(h[:, None], V, 1),
            "gender (female = 1)": np.repeat((a["gender"] == 2)[:, None].astype(float), V, 1)}


def main(name: str = "cpu") -> None:
    root = RunFolders(name).still
    tr, va = split_arrays(root, "train", NAMES), split_arrays(root, "val", NAMES)
    xt, xv, yt, yv = inputs(tr), inputs(va), targets(tr), targets(va)
    print("| quantity | input | readout | R2 | view error correlation / accuracy |\n|---|---|---|---|---|")
    for q in yt:
        for inp in xt:
            for name, fit in (("ridge", fit_ridge), ("MLP", lambda X, y: fit_mlp(X, y, steps=400))):
                probe = fit(xt[inp].reshape(-1, xt[inp].shape[-1]), yt[q].ravel())
                pred = probe(xv[inp].reshape(-1, xv[inp].shape[-1])).reshape(yv[q].shape)
                other = (view_error_correlation(pred - yv[q]) if q.startswith("stature")
                         else float(np.mean((pred > 0.5) == (yv[q] > 0.5))))
                print(f"| {q} | {inp} | {name} | {r2_score(yv[q], pred):.4f} | {other:.3f} |", flush=True)


if __name__ == "__main__":
    main(*sys.argv[1:])
