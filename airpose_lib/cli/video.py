"""``airpose video``: two drone videos to SMPL-X per frame, UAV2 in UAV1 and overlays
(:mod:`airpose_lib.experiments.video` does the work)."""
from __future__ import annotations

import argparse
from pathlib import Path

from .common import CLIError, parse_profile

__all__ = ["add_video"]


def _cmd_video(args: argparse.Namespace) -> int:
    from airpose_lib.experiments.video import VideoConfig, run_video, video_networks
    from airpose_lib.reproduce.configs import kit_configs

    if args.intrinsics and len(args.intrinsics) > 2:
        raise CLIError("--intrinsics takes one file for both videos or one per video (UAV1 first)")
    intr = tuple(args.intrinsics or ()) or (None,)
    intr = (intr[0], intr[-1])
    cfg = VideoConfig(videos=(str(args.uav1), str(args.uav2)), out=str(args.out), intrinsics=intr,
                      fov_y_deg=args.fov, keypoints=None if args.keypoints is None else tuple(map(str, args.keypoints)),
                      offset=args.offset, max_offset_s=args.max_offset, fps=args.fps, start=args.start,
                      end=args.end, every=args.every, fit=not args.no_fit, overlays=not args.no_overlays)
    nets = video_networks(args.networks, args.checkpoint, args.baseline_checkpoint, args.prior_path)
    fit = kit_configs(args.profile).fitting if cfg.fit else None
    run = run_video(cfg, nets, fit_config=fit, progress=not args.quiet)
    total = sum(run.seconds.values())
    print(f"{run.frames} paired frames in {total:.0f} s ({100 * total / max(run.frames, 1):.0f} s per 100 frames: "
          + ", ".join(f"{k} {v:.0f} s" for k, v in run.seconds.items()) + ")")
    for name, path in run.files.items():
        print(f"  {name:18s} {path}")
    return 0


def add_video(sub) -> None:
    """``airpose video``: add the parser to the subcommand group ``sub``."""
    v = sub.add_parser(
        "video", help="two drone videos -> SMPL-X per frame, UAV2 in UAV1, overlays",
        description="Run the whole chain on two videos of one person filmed by two drones: decode the frames, "
                    "read the person's 2D keypoints, find the time offset between the videos, run the AirPose "
                    "network (the exchange between the views) and AirPose+ over the sequence, and write "
                    "smplx.npz, uav2_in_uav1.csv, an overlay video per drone and trajectory plots into --out. "
                    "A killed run resumes: finished stages are skipped. See docs/own_videos.md.")
    v.add_argument("uav1", type=Path, help="UAV1's video file, or a folder of its frames")
    v.add_argument("uav2", type=Path, help="UAV2's video file, or a folder of its frames")
    v.add_argument("--out", type=Path, required=True, help="output folder (one run at a time; resumed)")
    v.add_argument("--keypoints", type=Path, nargs=2, metavar=("UAV1_KP", "UAV2_KP"), default=None,
                   help="the person's BODY_25 keypoints per video: the kit's pickle {frame: (persons, 25, 3)} "
                        "(openpose_res.pkl) or OpenPose's --write_json folder, numbered by the video's frames "
                        "(default: MediaPipe Pose, from `bash scripts/setup_mediapipe.sh` in a checkout)")
    v.add_argument("--intrinsics", type=Path, nargs="+", metavar="FILE", default=None,
                   help="camera_calib.yml (OpenCV FileStorage with K), or YAML/JSON with fx, fy, cx, cy "
                        "[dist, width, height], one for both or one per video, or sections uav1/uav2 "
                        "(default: the principal point at the centre and --fov)")
    v.add_argument("--fov", type=float, default=48.0,
                   help="vertical field of view in degrees of the default camera (default: 48); depths scale "
                        "with the focal length it implies")
    v.add_argument("--offset", type=int, default=None,
                   help="frame i of UAV1 shows the instant of frame i + OFFSET of UAV2 (default: estimated from "
                        "the two views' body poses)")
    v.add_argument("--max-offset", type=float, default=10.0, help="largest offset estimated, seconds (default: 10)")
    v.add_argument("--fps", type=float, default=None, help="frame rate (required for frame folders)")
    v.add_argument("--start", type=int, default=0, help="UAV1's first frame (default: 0)")
    v.add_argument("--end", type=int, default=None, help="UAV1's frame to stop before (default: its end)")
    v.add_argument("--every", type=int, default=1, help="use every N-th frame (default: 1)")
    v.add_argument("--networks", default="cpu",
                   help="the profile whose shipped networks run (results/<profile>/networks; default: cpu)")
    v.add_argument("--checkpoint", type=Path, default=None,
                   help="the two-view AirPose network instead: a checkpoint of `airpose train` or the authors' .ckpt")
    v.add_argument("--baseline-checkpoint", type=Path, default=None,
                   help="the one-view network the offset is estimated with (default: the shipped Baseline)")
    v.add_argument("--prior-path", type=Path, default=None, help="AirPose+'s pose prior (default: the shipped one)")
    v.add_argument("--profile", type=parse_profile, default="cpu",
                   help="AirPose+'s settings from this profile's `fitting:` section (default: cpu)")
    v.add_argument("--no-fit", action="store_true", help="skip AirPose+")
    v.add_argument("--no-overlays", action="store_true", help="skip the overlay videos")
    v.add_argument("--quiet", action="store_true", help="no progress bars")
    v.set_defaults(func=_cmd_video)
