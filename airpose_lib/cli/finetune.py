"""``airpose finetune`` and ``airpose predict``: fine-tuning on a recording's 2D detections and
running a network over a recording (:mod:`airpose_lib.finetune` does the work)."""
from __future__ import annotations

import argparse
from pathlib import Path

from .common import (
    SEQUENCE_FOLDER,
    CLIError,
    add_profile_flag,
    parse_range,
    parse_sets,
    require_file,
    require_folder,
    require_path,
)

__all__ = ["add_finetune", "add_predict"]

# Handlers import the library when they run, never at module level: the whole parser is built
# on every call (``airpose --help``, a drone's start-up) and must not import torch.


# -- finetune -------------------------------------------------------------------------------------
def _cmd_finetune(args: argparse.Namespace) -> int:
    from airpose_lib.config_fields import field_types  # standard library only
    from airpose_lib.finetune.config import FineTuneConfig, finetune_config
    from airpose_lib.finetune.loss import FineTuneLossConfig
    from airpose_lib.finetune.train import finetune
    from airpose_lib.reproduce.configs import kit_configs

    overrides = parse_sets(args.set, FineTuneConfig, {"loss": field_types(FineTuneLossConfig)})
    for name, field in (("steps", "steps"), ("batch_size", "batch_size"), ("seed", "seed"), ("threads", "num_threads"),
                        ("prior", "prior"), ("input_size", "input_size"), ("device", "device")):
        if getattr(args, name) is not None:
            overrides[field] = getattr(args, name)
    if args.prior_path is not None:
        overrides["prior_path"] = str(args.prior_path)
    frames = parse_range(args.frames)
    if frames is not None:
        if None in frames:
            raise CLIError("--frames for fine-tuning needs both ends, e.g. 0:7000")
        overrides["frames"] = list(frames)
    cfg = finetune_config(kit_configs(args.profile).finetune, **{k: v for k, v in overrides.items() if not isinstance(v, dict)})
    for k, v in overrides.items():  # dict fields (loss.w_vposer=0.5): merge into the profile's
        if isinstance(v, dict):
            cfg = cfg.replace(**{k: {**getattr(cfg, k), **v}})
    require_file(args.checkpoint, "--checkpoint", "a checkpoints/*.pt of `airpose train`")
    require_folder(args.sequence, "--sequence", SEQUENCE_FOLDER)
    require_path(args.prior_path, "--prior-path", "a prior checkpoint file or folder")
    res = finetune(args.checkpoint, args.sequence, args.out, cfg, resume=args.resume, progress=not args.quiet)
    k = res.keypoints
    print(f"{res.num_frames} training frames; 2D targets kept {k['kept']}, dropped {k['disagree']} disagreeing, "
          f"{k['unconfirmed']} unconfirmed, {k['low_confidence'] + k['missing']} missing/low confidence")
    thr = ", ".join(f"{t:.0f}" for t in res.pixels.get("threshold_px", []))
    print(f"agreement threshold {thr} px per view (100 px at {res.pixels.get('reference_width', 1920):.0f} px wide)")
    if res.final is not None:
        print(f"step {res.step}: 2D loss {res.initial['j2d']:.4g} -> {res.final['j2d']:.4g} px^2 (at the reference "
              f"width), total {res.initial['total']:.4g} -> {res.final['total']:.4g} ({res.seconds:.0f} s)")
    print(f"checkpoint {res.checkpoint}")
    if res.best_checkpoint is not None:
        why = (f"; {', '.join(res.overfit_terms)} started overfitting at step {res.overfit_step}"
               if res.overfit_step is not None else "")
        print(f"selected step {res.best_step} by rule {res.config['selection']} (held-out 2D loss "
              f"{res.best_heldout_j2d:.4g} on {res.heldout_frames} frames{why}): {res.best_checkpoint}")
    return 0


def add_finetune(sub) -> None:
    """``airpose finetune``: add the parser to the subcommand group ``sub``."""
    ft = sub.add_parser(
        "finetune", help="fine-tune a trained network on a recording's 2D detections",
        description="Fine-tune a checkpoint of `airpose train` on a recording in the official layout "
                    "(machine_k/ with openpose_res.pkl and alphapose_res.json), as the paper does on its "
                    "real data: OpenPose keypoints confirmed by AlphaPose (within 100 px), weighted by "
                    "confidence; frozen backbone (its features are computed once and cached in <out>), "
                    "regressor trained with the variant's paper weights (2D, beta prior, VPoser, "
                    "cross-view theta). Writes <out>/checkpoints/ (kit format, resumed automatically), "
                    "<out>/log.csv and <out>/result.json.")
    ft.add_argument("--checkpoint", type=Path, required=True, help="a checkpoints/*.pt of `airpose train`")
    ft.add_argument("--sequence", type=Path, required=True, help="recording folder (official layout)")
    ft.add_argument("--out", type=Path, required=True, help="run folder")
    add_profile_flag(ft, "sizes from the profile's `finetune:` section; defaults where it has none")
    ft.add_argument("--frames", default=None, metavar="START:STOP",
                    help="train on the images numbered START..STOP-1 (paper: 0:7000); default: the profile's or all")
    ft.add_argument("--steps", type=int, default=None, help="override the profile's step count")
    ft.add_argument("--batch-size", type=int, default=None, help="frames per step (paper: 30)")
    ft.add_argument("--seed", type=int, default=None, help="(default: the profile's, else 123)")
    ft.add_argument("--input-size", type=int, default=None,
                    help="crop size of the network, when its checkpoint does not record it")
    ft.add_argument("--prior", choices=("kit", "vposer"), default=None,
                    help="kit: trained by `airpose prior train`; vposer: official V02_05 (default: kit)")
    ft.add_argument("--prior-path", type=Path, default=None, help="a prior checkpoint file or folder")
    ft.add_argument("--device", default=None, help="auto, cpu or cuda (default: the profile's, else auto)")
    ft.add_argument("--threads", type=int, default=None,
                    help="torch threads; 1 is faster when other jobs share the CPU cores")
    ft.add_argument("--resume", action=argparse.BooleanOptionalAction, default=True,
                    help="continue from <out>/checkpoints/last.pt if present (default: yes)")
    ft.add_argument("--set", nargs="+", metavar="KEY=VALUE",
                    help="any other option of FineTuneConfig, e.g. lr=1e-4 threshold_px=50 loss.w_vposer=0.5 "
                         "(keys and value types are checked)")
    ft.add_argument("--quiet", action="store_true", help="no progress bars")
    ft.set_defaults(func=_cmd_finetune)


# -- predict --------------------------------------------------------------------------------------
def _cmd_predict(args: argparse.Namespace) -> int:
    from airpose_lib.data.sequences.layout import DETECTOR_FILES
    from airpose_lib.data.sequences.reader import load_sequence
    from airpose_lib.finetune.network import load_sized_network
    from airpose_lib.finetune.predict import frames_in_range, predict_sequence, save_predictions

    if args.detector not in DETECTOR_FILES:
        raise CLIError(f"--detector {args.detector}: unknown; give one of {', '.join(DETECTOR_FILES)}")
    require_file(args.checkpoint, "--checkpoint", "a checkpoint of `airpose train` or `airpose finetune`")
    require_folder(args.sequence, "--sequence", SEQUENCE_FOLDER)
    model, cfg, size = load_sized_network(args.checkpoint, args.device, args.input_size)
    if args.threads:
        import torch

        torch.set_num_threads(args.threads)
    rng = parse_range(args.frames)
    frames = None if rng is None else frames_in_range(args.sequence, *rng)
    seq = load_sequence(args.sequence, frames=frames, detectors=(args.detector,), ground_truth=False,
                        missing_detections="zero" if args.allow_missing_detections else "error")
    pred = predict_sequence(model, seq, input_size=size, detector=args.detector, batch_size=args.batch_size,
                            progress=not args.quiet,
                            provenance={"checkpoint": str(args.checkpoint), "backbone": cfg.backbone})
    out = save_predictions(args.out, pred)
    F, V = pred["valid"].shape
    print(f"{F} frames x {V} views ({cfg.variant}, {size} px crops); {int((~pred['valid']).sum())} view-frames "
          f"without a detection reused the previous box")
    print(f"written {out}")
    return 0


def add_predict(sub) -> None:
    """``airpose predict``: add the parser to the subcommand group ``sub``."""
    pr = sub.add_parser(
        "predict", help="run a network over a recording, write per-view parameters (.npz)",
        description="Run a checkpoint over a recording in the official layout: person boxes from the "
                    "detections (as the drones make them), crops, all views jointly (the variant's "
                    "exchange included). Writes phi (F,V,3,3), tau (F,V,3), theta (F,V,21,3,3), beta "
                    "(F,V,10), frames (F,), P, boxes, valid and provenance to an .npz that "
                    "`airpose fit --init` reads.")
    pr.add_argument("--checkpoint", type=Path, required=True, help="a checkpoint of `airpose train` or `finetune`")
    pr.add_argument("--sequence", type=Path, required=True, help="recording folder (official layout)")
    pr.add_argument("--out", type=Path, required=True, help="predictions file (.npz)")
    pr.add_argument("--frames", default=None, metavar="START:STOP",
                    help="only the images numbered START..STOP-1 (either end may be left out)")
    pr.add_argument("--detector", default="openpose",
                    help="keypoints the person boxes come from: openpose, alphapose or mediapipe "
                         "(scripts/mediapipe_detect.py) (default: openpose)")
    pr.add_argument("--batch-size", type=int, default=16, help="frames per backbone batch (default: 16)")
    pr.add_argument("--input-size", type=int, default=None,
                    help="crop size of the network, when its checkpoint does not record it")
    pr.add_argument("--allow-missing-detections", action="store_true",
                    help="treat frames a detector file lacks as undetected instead of failing")
    pr.add_argument("--device", default="auto", help="auto (CUDA if available), cpu, cuda or cuda:N (default: auto)")
    pr.add_argument("--threads", type=int, default=None, help="torch threads")
    pr.add_argument("--quiet", action="store_true", help="no progress bar")
    pr.set_defaults(func=_cmd_predict)
