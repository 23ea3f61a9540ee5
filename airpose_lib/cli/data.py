"""``airpose data generate | sequence | list | verify | fetch``: the kit's datasets and the external
assets (the last three from :mod:`.assets`)."""
from __future__ import annotations

import argparse
import os
from collections.abc import Callable
from pathlib import Path

from airpose_lib.folder_lock import folder_lock  # standard library only

from .assets import add_asset_commands
from .common import add_profile_flag

__all__ = ['add_data']

# Handlers import the library when they run, never at module level: the whole parser is built
# on every call (``airpose --help``, a drone's start-up) and must not import torch, ZeroMQ,
# smplx or papermill.


def _cmd_data_sequence(args: argparse.Namespace) -> int:
    from airpose_lib.data.sequences import ensure_sequences
    from airpose_lib.reproduce.configs import kit_configs

    configs = kit_configs(args.profile)
    recordings = configs.recordings(args.field)  # a bad setting: no folder made
    root = args.out if args.out is not None else configs.folders.sequences(args.field)
    with folder_lock(root, "recordings folder"):  # one writer; a killed one's temp files go
        paths = ensure_sequences(recordings, root, only=args.only, force=args.force, progress=not args.quiet)
    for name, path in paths.items():
        print(f"{name:<10} {path}")
    return 0


def _add_data_sequence(dsub) -> None:
    seq = dsub.add_parser(
        "sequence", help="generate the simulated two-drone recordings of a profile",
        description="Simulate the profile's recordings (a person moving, one hovering and one circling "
                    "drone, the paper's two camera calibrations), render the frames, simulate OpenPose- "
                    "and AlphaPose-like keypoints and store each recording in the official real-data "
                    "layout (machine_1/, machine_2/, ground_truth.npz). Complete identical recordings are "
                    "kept.")
    add_profile_flag(seq, "sizes from the profile's `sequences:` section")
    seq.add_argument("--out", type=Path, default=None,
                     help="parent folder of the recordings (default: <cache>/data/sequences_<profile>)")
    seq.add_argument("--only", nargs="+", metavar="NAME", help="only these recordings (e.g. person1)")
    seq.add_argument("--force", action="store_true", help="regenerate even if a complete copy exists")
    seq.add_argument("--field", action="store_true",
                     help="the profile's field recordings instead (`sequences: field_recordings:`; default "
                          "folder <cache>/data/sequences_<profile>_field)")
    seq.add_argument("--quiet", action="store_true", help="no progress bar")
    seq.set_defaults(func=_cmd_data_sequence)


def _cmd_data_generate(args: argparse.Namespace) -> int:
    from airpose_lib.data.still.generate import generate_still_dataset
    from airpose_lib.reproduce.configs import kit_configs

    configs = kit_configs(args.profile)
    config = configs.still
    root = args.out if args.out is not None else configs.folders.still
    workers = args.workers if args.workers is not None else (os.cpu_count() or 1)
    manifest = generate_still_dataset(config, root, workers=workers, label=args.profile,
                                      progress=not args.quiet, record=args.record_manifest)
    t = manifest["totals"]
    print(f"{root}: {t['train_samples']} train + {t.get('val_samples', 0)} val + {t['test_samples']} test samples "
          f"({config.scene.num_views} views, {config.crop_size} px), {t['dropped']} of "
          f"{t['attempts']} attempts dropped (person left a frame), {len(manifest['shards'])} shards, "
          f"{t['bytes'] / 1e6:.1f} MB")
    return 0


def _add_data_generate(dsub) -> None:
    gen = dsub.add_parser(
        "generate", help="generate (or resume, or verify) the still-frame dataset of a profile",
        description="Render the synthetic two-drone still-frame dataset (the paper's protocol with "
                    "the open body model): person crops of every view plus ground truth, in shards "
                    "with a manifest (SHA-256 per shard). Same profile, same bytes; an interrupted "
                    "run resumes, finished shards are verified and kept, damaged ones rebuilt.")
    add_profile_flag(gen, "sizes from the profile's `data: still:` section")
    gen.add_argument("--out", type=Path, default=None,
                     help="dataset folder (default: <cache>/data/still_<profile>)")
    gen.add_argument("--workers", type=int, default=None,
                     help="parallel rendering processes (default: number of CPU cores); the result "
                          "does not depend on it")
    gen.add_argument("--quiet", action="store_true", help="no progress bar")
    gen.add_argument("--record-manifest", action="store_true",
                     help="when complete, also copy the manifest to the checkout's "
                          "data_manifests/generated_<profile>.yaml (a tracked file; off by default)")
    gen.set_defaults(func=_cmd_data_generate)


# Builders of the `airpose data ...` subcommands, in help order; each adds its parser to the group.
_DATA_SUBCOMMANDS: tuple[Callable, ...] = (_add_data_generate, _add_data_sequence, add_asset_commands)


def add_data(sub) -> None:
    data = sub.add_parser("data", help="generate and inspect datasets",
                          description="Generate the kit's datasets (still frames, sequences).")
    dsub = data.add_subparsers(dest="data_command", metavar="COMMAND", required=True)
    for add in _DATA_SUBCOMMANDS:
        add(dsub)
