"""``airpose pretrain`` and ``airpose train``: the shared backbone and the four variants."""
from __future__ import annotations

import argparse
import contextlib
import json
from pathlib import Path

from airpose_lib.errors import DamagedFileError  # standard library only
from airpose_lib.folder_lock import folder_lock

from .common import VARIANTS, CLIError, add_profile_flag, parse_sets

__all__ = ['add_pretrain', 'add_train']

# Handlers import the library when they run, never at module level: the whole parser is built
# on every call (``airpose --help``, a drone's start-up) and must not import torch, ZeroMQ,
# smplx or papermill.


def _cmd_train(args: argparse.Namespace) -> int:
    from airpose_lib.engine.launch import launch_env
    from airpose_lib.reproduce.configs import kit_configs, train_inputs
    from airpose_lib.train import TrainConfig
    from airpose_lib.train.config import option_types
    from airpose_lib.train.loop import check_data_root

    # data: its keys depend on the dataset source, checked with the whole config
    overrides = parse_sets(args.set, TrainConfig, {name: option_types(name)[0] for name in ("model", "loss")})
    if args.quiet:
        overrides["progress"] = False
    for name in ("steps", "batch_size", "world_size", "num_workers", "device"):
        if getattr(args, name) is not None:
            overrides[name] = getattr(args, name)
    configs = kit_configs(args.profile)
    cfg = configs.train.config(args.variant, args.seed, **{k: v for k, v in overrides.items() if not isinstance(v, dict)})
    for k, v in overrides.items():  # dict fields: merge into the profile's dicts
        if isinstance(v, dict):
            cfg = cfg.replace(**{k: {**getattr(cfg, k), **v}})
    check_data_root(cfg)  # inputs before the run folder exists
    inputs = train_inputs(configs, cfg.pretrained)
    # The run folder and the checkpoint to resume from are checked before any data is prepared.
    out = args.out if args.out is not None else configs.folders.train(cfg.variant, cfg.seed)
    out.mkdir(parents=True, exist_ok=True)
    # A second training into this folder is refused at once (the loop takes the lock again,
    # re-entrant). Rank 0 is its one holder: under torchrun the launch's rank 0 (the environment
    # says which, the process group does not exist yet); with --world-size N the spawned rank 0.
    launch = launch_env()
    holder = launch[0] == 0 if launch is not None else cfg.world_size <= 1
    with folder_lock(out) if holder else contextlib.nullcontext():
        return _train_locked(args, cfg, inputs, out)


def _train_locked(args: argparse.Namespace, cfg, inputs, out: Path) -> int:
    from airpose_lib.engine.checkpoint import last_checkpoint, load_checkpoint
    from airpose_lib.train import train

    last = last_checkpoint(out) if args.resume else None
    if last is not None:
        try:
            load_checkpoint(last)
        except DamagedFileError as e:
            raise CLIError(f"cannot resume: {last} is damaged (cut short by a crash or a full disk?); copy the "
                           f"newest {last.parent}/step_*.pt over it, or start afresh with --no-resume") from e
    result = train(args.variant, inputs, out_dir=out, resume=args.resume, config=cfg)
    print(f"step {result.step}  train loss {result.train_loss}  checkpoint {result.checkpoint}")
    if result.val_losses:
        print(f"validation loss {result.val_losses.get('total')}")
    return 0


def _cmd_pretrain(args: argparse.Namespace) -> int:
    from airpose_lib.reproduce.configs import kit_configs
    from airpose_lib.train.pretrain import profile_backbone, write_reference_backbone

    configs = kit_configs(args.profile)
    path = profile_backbone(configs.pretrain, progress=not args.quiet)
    record = json.loads(path.with_suffix(".json").read_text())
    print(f"backbone {path}\n  key {record['key']}  sha256 {record['sha256']}\n  gate {record['gate']}")
    if args.write_reference:
        print(f"reference copy: {write_reference_backbone(configs.folders, path)}")
    return 0


def add_pretrain(sub) -> None:
    pr = sub.add_parser(
        "pretrain", help="pretrain the profile's shared backbone (the CPU protocol's starting point)",
        description="Train (or find in the cache / the committed results/<profile>/) the backbone every "
                    "variant of the profile starts from: the `pretrain:` section, variant-neutral objective, "
                    "gated on the validation split.")
    add_profile_flag(pr, "the `pretrain:` section")
    pr.add_argument("--write-reference", action="store_true",
                    help="also copy the backbone into results/<profile>/ (the committed reference)")
    pr.add_argument("--quiet", action="store_true", help="no progress bars")
    pr.set_defaults(func=_cmd_pretrain)


def add_train(sub) -> None:
    tr = sub.add_parser(
        "train", help="train a network variant with a profile's sizes",
        description="Train one of the four variants (Table I) on the still-frame dataset with the "
                    "profile's `train:` section: Adam (AMSGrad), deterministic seeds, checkpoints "
                    "every N steps in <out>/checkpoints/ (resumed automatically), <out>/log.csv. "
                    "--world-size N trains with N processes (PyTorch DDP) on this machine; under "
                    "`torchrun --nproc_per_node=N -m airpose_lib.cli train ...` the processes come from "
                    "torchrun (one per GPU, any number of nodes). Mixed precision: --set precision=bf16.")
    tr.add_argument("--variant", choices=VARIANTS, required=True)
    add_profile_flag(tr, "sizes from the `train:` section")
    tr.add_argument("--seed", type=int, default=None, help="(default: the profile's)")
    tr.add_argument("--out", type=Path, default=None,
                    help="run folder (default: <runs>/train/<profile>/<variant>/seed<seed>; <runs> is "
                         "$AIRPOSE_RUNS or runs/ at the checkout root, whatever the current folder)")
    tr.add_argument("--resume", action=argparse.BooleanOptionalAction, default=True,
                    help="continue from <out>/checkpoints/last.pt if present (default: yes)")
    tr.add_argument("--steps", type=int, default=None, help="override the profile's step count")
    tr.add_argument("--batch-size", type=int, default=None, help="override the global batch size")
    tr.add_argument("--world-size", type=int, default=None,
                    help="training processes (DDP) spawned here; not needed under torchrun")
    tr.add_argument("--num-workers", type=int, default=None, help="DataLoader workers per process")
    tr.add_argument("--device", default=None, help="auto, cpu, cuda (each process its own GPU) or cuda:N")
    tr.add_argument("--set", nargs="+", metavar="KEY=VALUE",
                    help="any other TrainConfig option, e.g. lr=1e-4 model.dropout=0 loss.vertex_subsample=2000 "
                         "(keys and value types are checked)")
    tr.add_argument("--quiet", action="store_true", help="no progress bar")
    tr.set_defaults(func=_cmd_train)
