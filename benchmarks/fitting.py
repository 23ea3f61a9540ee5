"""AirPose+ benchmark: a synthetic two-view sequence refined with the paper's loss and the code's
schedule (300 iterations, latents from 100), timed for 1,000 and 2,000 frames.

    python benchmarks/fitting.py                       # 1,000 and 2,000 frames, 1 thread
    python benchmarks/fitting.py --threads 1 2         # also with 2 intra-op threads
    python benchmarks/fitting.py --frames 200 --iterations 50

Target: 1,000 frames in at most 30 s on a 2-core machine. The sequence: key poses of the kit's
pose sampler interpolated over the frames, a walking and turning person, two cameras ~10 m away
(1920x1080, f = 1475 px), BODY_25 and COCO-18 keypoints with 2 px noise; the start is the ground
truth perturbed per view (root 8 deg, translation 0.1/0.1/0.4 m, joints 10 deg, shape 0.5), as
AirPose's per-frame outputs would be. The prior is the kit's trained one if present (else an
untrained VPoser: same speed, meaningless accuracy columns).

The machine may be shared: the 1-minute load average is printed before and after each run. On a
loaded machine torch's default of one thread per core is much slower (its threads wait for each
other by spinning), so ``--threads 1`` is the default here.
"""
from __future__ import annotations

import argparse
import math
import os
import time

import numpy as np
import torch


def _look_at(eye, target):
    eye, target = np.asarray(eye, float), np.asarray(target, float)
    z = (target - eye) / np.linalg.norm(target - eye)
    x = np.cross(z, [0.0, -1.0, 0.0])
    x /= np.linalg.norm(x)
    R = np.stack([x, np.cross(z, x), z])
    return R, -R @ eye


def synthetic_sequence(body, F: int, seed: int = 0, noise_px: float = 2.0):
    """Ground truth and detections of a two-view sequence (see the module doc)."""
    import roma

    from airpose_lib.body import BODY_25_FROM_SMPLX, COCO18_FROM_SMPLX
    from airpose_lib.data.still.poses import sample_body_pose
    from airpose_lib.geometry import project_points

    rng = np.random.default_rng(seed)
    n_keys = max(2, F // 60 + 1)  # a new key pose every 2 s at 30 fps
    keys = torch.as_tensor(sample_body_pose(rng, n_keys))
    s = torch.linspace(0, n_keys - 1, F, dtype=torch.float64)
    i0 = s.floor().long().clamp(max=n_keys - 2)
    w = (s - i0)[:, None, None]
    theta = roma.rotvec_to_rotmat((1 - w) * keys[i0] + w * keys[i0 + 1])
    beta = torch.as_tensor(rng.normal(0.0, 0.5, 10))
    t = torch.arange(F, dtype=torch.float64) / 30.0
    heading = 0.3 * t
    R_wb = roma.rotvec_to_rotmat(torch.stack([0 * heading, heading, 0 * heading], -1))
    t_wb = torch.stack([1.5 * torch.sin(0.2 * t), 0 * t, 1.5 * torch.cos(0.2 * t) - 1.5], -1)
    R_cw, t_cw = [], []
    for k in range(F):  # UAV1 hovers, UAV2 circles the person
        a = 0.05 * t[k].item()
        cams = [_look_at([1.0, 4.0, 9.0], [0.0, 1.0, 0.0]),
                _look_at([9.0 * math.sin(a + 2.0), 6.0, 9.0 * math.cos(a + 2.0)], [0.0, 1.0, 0.0])]
        R_cw.append(np.stack([c[0] for c in cams]))
        t_cw.append(np.stack([c[1] for c in cams]))
    R_cw, t_cw = torch.as_tensor(np.stack(R_cw)), torch.as_tensor(np.stack(t_cw))
    phi = R_cw @ R_wb[:, None]
    tau = (R_cw @ t_wb[:, None, :, None]).squeeze(-1) + t_cw
    K = torch.tensor([[1475.0, 0, 960], [0, 1475.0, 540], [0, 0, 1]], dtype=torch.float64).expand(2, 3, 3)
    J0 = torch.cat([body(theta[a:a + 500], beta[None])[0] for a in range(0, F, 500)])
    uv = project_points(J0[:, None] @ phi.transpose(-1, -2) + tau[:, :, None], K[None])
    g = torch.Generator().manual_seed(seed)
    kps = {}
    for name, idx in (("body25", BODY_25_FROM_SMPLX), ("coco18", COCO18_FROM_SMPLX)):
        p = uv[:, :, list(idx)] + noise_px * torch.randn(F, 2, len(idx), 2, generator=g, dtype=torch.float64)
        kps[name] = torch.cat([p, torch.full(p.shape[:-1] + (1,), 0.9, dtype=torch.float64)], -1).numpy()

    def rnd_rot(*shape, deg):
        return roma.rotvec_to_rotmat(torch.randn(*shape, 3, generator=g, dtype=torch.float64)
                                     * math.radians(deg) / math.sqrt(3))

    init = dict(phi=rnd_rot(F, 2, deg=8.0) @ phi,
                tau=tau + torch.randn(F, 2, 3, generator=g, dtype=torch.float64) * torch.tensor([0.1, 0.1, 0.4]),
                theta=theta[:, None] @ rnd_rot(F, 2, 21, deg=10.0),
                beta=beta + 0.5 * torch.randn(F, 2, 10, generator=g, dtype=torch.float64))
    return kps, K.numpy(), init, dict(theta=theta, beta=beta, phi=phi, tau=tau, J0=J0)


def errors(body, theta, beta, phi, tau, gt) -> tuple[float, float]:
    """Root-aligned MPJPE (mm) of the 22 body joints and UAV2-in-UAV1 position error (m)."""
    from airpose_lib.geometry import relative_camera_pose

    F = theta.shape[0]
    betas = beta.double().reshape(1, -1)
    J = torch.cat([body(theta[a:a + 500].double(), betas)[0] for a in range(0, F, 500)])
    J, Jg = J[:, :22], gt["J0"][:, :22]
    mpjpe = ((J - J[:, :1]) - (Jg - Jg[:, :1])).norm(dim=-1).mean().item() * 1000
    _, t12 = relative_camera_pose(phi[:, 0].double(), tau[:, 0].double(), phi[:, 1].double(), tau[:, 1].double())
    _, t12g = relative_camera_pose(gt["phi"][:, 0], gt["tau"][:, 0], gt["phi"][:, 1], gt["tau"][:, 1])
    return mpjpe, (t12 - t12g).norm(dim=-1).mean().item()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--frames", type=int, nargs="+", default=[1000, 2000])
    parser.add_argument("--iterations", type=int, default=300)
    parser.add_argument("--threads", type=int, nargs="+", default=[1])
    parser.add_argument("--progress", action="store_true", help="tqdm bar per run")
    args = parser.parse_args()

    from airpose_lib.body import BodyForward, load_body_model
    from airpose_lib.fitting import AirPosePlusConfig, airpose_plus, init_from_views
    from airpose_lib.prior import PriorError, VPoser, load_prior

    try:
        prior, prov = load_prior("kit", return_provenance=True)
        prior_name = f"kit prior {prov['file']}"
    except PriorError:
        torch.manual_seed(0)
        prior = VPoser().eval()
        prior_name = "UNTRAINED VPoser (run `airpose prior train`): accuracy columns meaningless"
    model = load_body_model("open", dtype=torch.float64)
    body = BodyForward(model, range(76), vertices=None)  # ground truth and errors
    cfg = AirPosePlusConfig(iterations=args.iterations, latent_start=min(100, args.iterations))
    print(f"AirPose+ benchmark: {os.cpu_count()} CPU cores, torch {torch.__version__}; {prior_name}")
    print(f"schedule: {cfg.iterations} iterations, latents from {cfg.latent_start}, Adam lr {cfg.lr}, "
          f"chunks of {cfg.chunk_size} frames")
    print("NOTE: the machine may be shared with other jobs; see the load averages.\n")
    header = (f"{'frames':>6} {'iters':>5} {'threads':>7} {'seconds':>8} {'ms/iter':>8} {'load before':>11} "
              f"{'load after':>10} {'MPJPE mm init->fit':>19} {'UAV2 pos m init->fit':>21}")
    print(header)
    print("-" * len(header))
    for F in args.frames:
        kps, K, init, gt = synthetic_sequence(body, F)
        start = init_from_views(**init)
        e0 = errors(body, start["theta"], start["beta"], start["phi"], start["tau"], gt)
        for threads in args.threads:
            load0 = os.getloadavg()[0]
            t0 = time.perf_counter()
            res = airpose_plus(kps, K, init, prior=prior, body=model, config=cfg, num_threads=threads,
                               progress=args.progress)
            wall = time.perf_counter() - t0
            load1 = os.getloadavg()[0]
            e1 = errors(body, res.theta, res.beta, res.phi, res.tau, gt)
            print(f"{F:>6} {cfg.iterations:>5} {threads:>7} {wall:>8.1f} {1000 * res.seconds / cfg.iterations:>8.1f} "
                  f"{load0:>11.2f} {load1:>10.2f} {e0[0]:>8.1f} -> {e1[0]:>6.1f} {e0[1]:>10.3f} -> {e1[1]:>6.3f}",
                  flush=True)
    print("\nseconds: wall time of airpose_plus() (set-up included); ms/iter: optimisation loop only.")


if __name__ == "__main__":
    main()
