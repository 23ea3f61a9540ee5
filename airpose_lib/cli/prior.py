"""``airpose prior train | info``: the pose prior."""
from __future__ import annotations

import argparse
import json
from pathlib import Path

from .common import add_profile_flag, require_path

__all__ = ['add_prior']

# Handlers import the library when they run, never at module level: the whole parser is built
# on every call (``airpose --help``, a drone's start-up) and must not import torch, ZeroMQ,
# smplx or papermill.


def _cmd_prior_train(args: argparse.Namespace) -> int:
    import torch

    from airpose_lib.prior.build import train_and_save_prior
    from airpose_lib.reproduce.configs import kit_configs

    if args.threads:
        torch.set_num_threads(args.threads)
    out, val = train_and_save_prior(kit_configs(args.profile).prior, args.out, steps=args.steps, seed=args.seed,
                                    device=args.device, progress=not args.quiet)
    print(f"corpus: {val['train_poses']} training poses, {val['val_poses']} held out")
    print(f"trained {val['steps']} steps in {val['seconds']:.0f} s")
    print(f"held-out reconstruction: mean {val['rot_err_deg']:.2f} deg per joint "
          f"(median {val['rot_err_deg_median']:.2f}, p95 {val['rot_err_deg_p95']:.2f})"
          + (f", joints {val['joint_err_mm']:.1f} mm" if "joint_err_mm" in val else ""))
    print(f"N(0, I) samples within the joint limits (+5 deg): {100 * val['samples_within_joint_limits']:.1f} %")
    print(f"saved {out}")
    return 0


def _cmd_prior_info(args: argparse.Namespace) -> int:
    from airpose_lib.prior import load_prior

    require_path(args.path, "--path", "a prior checkpoint file or folder")
    _, prov = load_prior(args.source, args.path, tag=args.tag, return_provenance=True)
    print(json.dumps(prov, indent=1, default=str))
    return 0


def add_prior(sub) -> None:
    pr = sub.add_parser("prior", help="train and inspect the pose prior (VPoser architecture)",
                        description="The pose prior of fine-tuning and AirPose+: a VPoser-v2 VAE trained "
                                    "on the kit's pose generators, or the official V02_05 weights.")
    psub = pr.add_subparsers(dest="prior_command", metavar="COMMAND", required=True)
    tr = psub.add_parser(
        "train", help="train the kit's prior with a profile's `prior:` sizes",
        description="Train the prior on poses of airpose_lib.data.still.poses and data.sequences.motions, report the "
                    "held-out reconstruction error and the share of N(0, I) samples inside the joint "
                    "limits, and save <cache>/prior/<profile>/vposer.pt (atomic, with provenance).")
    add_profile_flag(tr, "sizes from the profile's `prior:` section (smoke: seconds; cpu: a few minutes; paper: longer)")
    tr.add_argument("--steps", type=int, default=None, help="override the profile's step count")
    tr.add_argument("--seed", type=int, default=None, help="(default: the profile's)")
    tr.add_argument("--threads", type=int, default=None,
                    help="torch threads; 1 is faster when other jobs share the CPU cores")
    tr.add_argument("--device", default=None,
                    help="auto (CUDA if available), cpu, cuda or cuda:N (default: the profile's, else cpu)")
    tr.add_argument("--out", type=Path, default=None, help="checkpoint file (default: the kit cache)")
    tr.add_argument("--quiet", action="store_true", help="no progress bar")
    tr.set_defaults(func=_cmd_prior_train)
    info = psub.add_parser("info", help="load a prior and print its provenance")
    info.add_argument("--source", choices=("kit", "vposer"), default="kit",
                      help="kit: trained by `airpose prior train`; vposer: the official V02_05 weights "
                           "from $AIRPOSE_VPOSER_DIR (default: kit)")
    info.add_argument("--tag", default=None, help="kit prior of this profile (default: the best present)")
    info.add_argument("--path", type=Path, default=None, help="a checkpoint file or folder")
    info.set_defaults(func=_cmd_prior_info)
