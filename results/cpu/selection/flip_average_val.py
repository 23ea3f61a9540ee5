"""Issue 28 probe (not a kit option): test-time flip averaging on the cpu validation split.

Each sample is run as stored and mirrored (``data.still.mirror.mirror_sample``: both views' crops
flipped, P mirrored), the mirrored prediction mapped back (phi, tau, theta), and the two averaged
(rotations: the chordal mean). Prints the root-orientation error and the zero-beta, pelvis-aligned
MPJPE of the three: as stored, averaged, and the mirrored run alone.

    AIRPOSE_RUNS=/work/runs3 python results/cpu/selection/flip_average_val.py \
        /work/runs3/train/cpu/airpose/seed123/checkpoints/last.pt 800

(the first 800 validation samples, one thread; output in flip_average_val.txt)."""
import sys
import time

import numpy as np
import torch

from airpose_lib.body import load_body_model
from airpose_lib.body.forward import BodyForward
from airpose_lib.data.still.dataset import StillFrameDataset
from airpose_lib.data.still.mirror import mirror_body_pose, mirror_rotation, mirror_sample
from airpose_lib.geometry import axis_angle_to_matrix, matrix_to_axis_angle
from airpose_lib.model import to_smplx_params
from airpose_lib.train import load_trained_model
from airpose_lib.train.run import prepare_data

torch.set_num_threads(1)
ckpt = sys.argv[1]
nmax = int(sys.argv[2]) if len(sys.argv) > 2 else 10**9
model, cfg = load_trained_model(ckpt)
model.eval()
cfg = prepare_data(cfg, progress=False)
kw = {k: v for k, v in cfg.data.items() if k not in ("root", "profile", "source")}
ds = StillFrameDataset(cfg.data["root"], split="val", crops=kw.get("crops", "jittered"))
body = BodyForward(load_body_model(cfg.body_source, "neutral"), vertices=None)
S = ds.crop_size
print("val samples", len(ds), "crop", S, flush=True)


def proj_so3(M):
    U, _, Vh = torch.linalg.svd(M)
    d = torch.det(U @ Vh)
    D = torch.diag_embed(torch.stack([torch.ones_like(d), torch.ones_like(d), d], -1))
    return U @ D @ Vh


def run(batch):
    out = model(batch["images"], batch["P"])
    return to_smplx_params(out, batch["P"], batch["K"], input_size=S)


def angle(Ra, Rb):
    c = ((Ra.transpose(-1, -2) @ Rb).diagonal(dim1=-2, dim2=-1).sum(-1) - 1) / 2
    return torch.rad2deg(torch.arccos(c.clamp(-1, 1)))


res = {"plain": {"root": [], "mpjpe": []}, "flip": {"root": [], "mpjpe": []}, "mirrored_only": {"root": [], "mpjpe": []}}
t0 = time.time()
B = 16
N = min(len(ds), nmax)
with torch.no_grad():
    for a in range(0, N, B):
        items = [ds[i] for i in range(a, min(a + B, N))]
        mir = [mirror_sample(it, S) for it in items]
        stack = lambda L: {k: torch.stack([x[k] for x in L]) for k in ("images", "P", "K", "phi", "theta")}
        b0, b1 = stack(items), stack(mir)
        p0 = run(b0)
        p1 = run(b1)
        # map the mirrored prediction back
        back = {"phi": mirror_rotation(p1["phi"]), "tau": p1["tau"] * torch.tensor([-1.0, 1.0, 1.0]),
                "beta": p1["beta"]}
        th = matrix_to_axis_angle(p1["theta"])  # (B, V, 21, 3)
        back["theta"] = axis_angle_to_matrix(mirror_body_pose(th))
        avg = {"phi": proj_so3(p0["phi"] + back["phi"]), "theta": proj_so3(p0["theta"] + back["theta"]),
               "tau": (p0["tau"] + back["tau"]) / 2, "beta": (p0["beta"] + back["beta"]) / 2}
        phi_gt = b0["phi"].to(p0["phi"].dtype)
        theta_gt = axis_angle_to_matrix(b0["theta"].to(p0["phi"].dtype)).unsqueeze(1).expand_as(p0["theta"])
        zero = torch.zeros_like(p0["beta"])
        gt_j, _ = body(theta_gt, zero, phi_gt, vertices=False)
        for name, p in (("plain", p0), ("flip", avg), ("mirrored_only", back)):
            j, _ = body(p["theta"], zero, p["phi"], vertices=False)
            d = ((j - j[..., :1, :]) - (gt_j - gt_j[..., :1, :])).norm(dim=-1).mean(-1)  # pelvis-aligned
            res[name]["mpjpe"].append(d.flatten())
            res[name]["root"].append(angle(p["phi"], phi_gt).flatten())
        if a % (B * 20) == 0:
            print(a, f"{time.time() - t0:.0f}s", flush=True)
for name, r in res.items():
    root = torch.cat(r["root"]).numpy()
    mp = torch.cat(r["mpjpe"]).numpy()
    print(f"{name:14s} views {len(root)} root median {np.median(root):.2f} mean {root.mean():.2f} "
          f">90 {100 * (root > 90).mean():.2f}%  MPJPE(pelvis) {mp.mean():.4f}", flush=True)
