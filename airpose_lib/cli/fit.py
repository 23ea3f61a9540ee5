"""``airpose fit``: AirPose+ over a recording (:mod:`airpose_lib.fitting` does the work)."""
from __future__ import annotations

import argparse
from pathlib import Path

from .common import SEQUENCE_FOLDER, CLIError, add_profile_flag, parse_range, require_file, require_folder, require_path

__all__ = ['add_fit']

# Handlers import the library when they run, never at module level: the whole parser is built
# on every call (``airpose --help``, a drone's start-up) and must not import torch, ZeroMQ,
# smplx or papermill.


def _cmd_fit(args: argparse.Namespace) -> int:
    from airpose_lib.data.sequences.layout import DETECTOR_FILES
    from airpose_lib.data.sequences.reader import load_sequence
    from airpose_lib.finetune.predict import frames_in_range
    from airpose_lib.fitting import fit_sequence
    from airpose_lib.fitting.recording import (
        fit_config,
        initialisation_for,
        open_initialisation,
        refined_path,
        save_refinement,
    )
    from airpose_lib.prior import load_prior

    detectors = tuple(d for d in args.detectors.split(",") if d)
    unknown = [d for d in detectors if d not in DETECTOR_FILES]
    if unknown or not detectors:
        raise CLIError(f"--detectors {args.detectors}: give one or more of {', '.join(DETECTOR_FILES)}, "
                       "comma-separated")
    from airpose_lib.reproduce.configs import kit_configs

    cfg = fit_config(kit_configs(args.profile).fitting, official_temporal=args.official_temporal, iterations=args.iterations,
                     threads=args.threads, device=args.device)
    require_folder(args.sequence, "--sequence", SEQUENCE_FOLDER)
    require_file(args.init, "--init", "the .npz of `airpose predict`")
    require_path(args.prior_path, "--prior-path", "a prior checkpoint file or folder")
    rng = parse_range(args.frames)
    pred = open_initialisation(args.init)
    frames = None if rng is None else frames_in_range(args.sequence, *rng)  # image numbers, as in `predict`
    seq = load_sequence(args.sequence, frames=frames, detectors=detectors, ground_truth=False)
    init = initialisation_for(pred, args.init, seq.frames)
    prior, prior_prov = load_prior(args.prior, args.prior_path, return_provenance=True)
    res = fit_sequence(seq, init, prior=prior, config=cfg, progress=not args.quiet)
    out = save_refinement(args.out or refined_path(args.init), seq.frames, res, sequence=args.sequence,
                          init=args.init, label=str(args.profile), prior=prior_prov)
    print(f"{len(seq.frames)} frames, {int(res.kept.sum())} fitted, {len(res.skipped_frames)} skipped "
          f"(confidence < {cfg.min_frame_confidence}); {cfg.iterations} iterations in {res.seconds:.1f} s")
    print(f"written {out}")
    return 0


def add_fit(sub) -> None:
    fit = sub.add_parser(
        "fit", help="AirPose+: refine a sequence offline",
        description="Run AirPose+ (paper Sec. III-D) on a sequence in the official layout "
                    "(machine_k/ with openpose_res.pkl and alphapose_res.json), starting from per-frame "
                    "network outputs in an .npz with phi (F,V,3,3), tau (F,V,3), theta (F,V,21,3,3) or "
                    "axis-angle (F,V,21,3), beta (F,V,10), and optionally frames (F,) image numbers. "
                    "Writes the refined parameters, camera poses and UAV2-in-UAV1 poses to an .npz.")
    fit.add_argument("--sequence", type=Path, required=True, help="sequence folder (official layout)")
    fit.add_argument("--init", type=Path, required=True, help="network outputs (.npz, see above)")
    fit.add_argument("--out", type=Path, default=None, help="(default: <init>_airpose_plus.npz)")
    add_profile_flag(fit, "iterations/weights from the profile's `fitting:` section")
    fit.add_argument("--frames", default=None, metavar="START:STOP",
                     help="only the images numbered START..STOP-1 (either end may be left out), "
                          "as in `predict` and `finetune`")
    fit.add_argument("--detectors", default="openpose,alphapose",
                     help="the keypoints AirPose+ fits, comma-separated: openpose, alphapose, mediapipe "
                          "(scripts/mediapipe_detect.py) (default: openpose,alphapose, the paper's)")
    fit.add_argument("--prior", choices=("kit", "vposer"), default="kit",
                     help="kit: trained by `airpose prior train`; vposer: official V02_05 (default: kit)")
    fit.add_argument("--prior-path", type=Path, default=None, help="a prior checkpoint file or folder")
    fit.add_argument("--iterations", type=int, default=None, help="override the profile's iterations")
    fit.add_argument("--official-temporal", action="store_true",
                     help="the official code's temporal weights (10 x pose, 100 x root/translation)")
    fit.add_argument("--threads", type=int, default=None,
                     help="torch threads; 1 is faster when other jobs share the CPU cores")
    fit.add_argument("--device", default=None,
                     help="auto (CUDA if available), cpu, cuda or cuda:N (default: the profile's, else cpu)")
    fit.add_argument("--quiet", action="store_true", help="no progress bar")
    fit.set_defaults(func=_cmd_fit)
